"""Compares two recordings of the same cell with the `mcap` package from PyPI (an
independent reader): a local one (`supervisor record` on the cell's host) and a remote one
(`supervisor record --remote`, written in the control room), the remote started after the
local one and stopped before it.

    python3 mcap_compare.py LOCAL REMOTE

Prints one JSON object:
- "channels_local", "channels_remote": each file's channels as [topic, schema name,
  schema encoding, message encoding, schema text], sorted;
- "topics": per topic, "local" and "remote" (message counts), "run": whether the remote's
  messages, byte for byte, are one unbroken run of the local's, "matched": how many of the
  remote's messages the local one has, in order, "contained": how many of them it has in any
  order (a topic several processes publish on reaches two readers in orders of their own),
  and "max_log_time_ns": the largest
  difference of log time between a remote message and its local copy;
- "programs": per program id, the setpoints of that program's motion (state Moving) in
  each file.
"""

import json
import sys

from mcap.reader import make_reader


def read(path):
    channels = []
    messages = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        for ch in summary.channels.values():
            sc = summary.schemas[ch.schema_id]
            channels.append([ch.topic, sc.name, sc.encoding, ch.message_encoding,
                             sc.data.decode()])
            messages.setdefault(ch.topic, [])
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            messages[channel.topic].append((message.log_time, bytes(message.data)))
    return sorted(channels), messages


def compare(local, remote):
    """(run, matched, largest log time difference) of `remote` against `local`."""
    if not remote:
        return True, 0, 0
    datas = [d for _, d in local]
    try:
        start = datas.index(remote[0][1])
    except ValueError:
        start = None
    run = start is not None and datas[start:start + len(remote)] == [d for _, d in remote]
    # In order, whatever the gaps on either side: how many of the remote's the local one has
    # after the one before (a message the local one lost is passed over).
    matched, i, worst = 0, 0, 0
    for t, d in remote:
        j = i
        while j < len(local) and local[j][1] != d:
            j += 1
        if j == len(local):
            continue
        matched += 1
        worst = max(worst, abs(local[j][0] - t))
        i = j + 1
    return run, matched, worst


def main():
    local_channels, local = read(sys.argv[1])
    remote_channels, remote = read(sys.argv[2])
    topics = {}
    programs = {}
    for topic in sorted(set(local) | set(remote)):
        l, r = local.get(topic, []), remote.get(topic, [])
        run, matched, worst = compare(l, r)
        pool = {}
        for _, d in l:
            pool[d] = pool.get(d, 0) + 1
        contained = 0
        for _, d in r:
            if pool.get(d, 0) > 0:
                pool[d] -= 1
                contained += 1
        topics[topic] = {"local": len(l), "remote": len(r), "run": run, "matched": matched,
                         "contained": contained, "max_log_time_ns": worst}
    for name, msgs in (("local", local), ("remote", remote)):
        for _, d in msgs.get("/trajgen/setpoint", []):
            m = json.loads(d)
            if m["state"] != 1:
                continue
            p = m["program_id"]
            programs.setdefault(str(p), {"local": 0, "remote": 0})[name] += 1
    print(json.dumps({"channels_local": local_channels, "channels_remote": remote_channels,
                      "topics": topics, "programs": programs}))


if __name__ == "__main__":
    main()
