"""Reads an MCAP file with the `mcap` package from PyPI (an independent reader) for the tests.

    python3 mcap_read.py FILE [FILE...]

Prints one JSON object: per topic its message count, schema name and encoding and message
encoding, whether every message's log time is in order and the first one (ns), and every setpoint of
`/trajgen/setpoint` as [program_id, motion_time_s, state, position by axis name...]; the
code of every event of `/events` in order ("event_codes"); "channels": each channel as
[topic, schema name, schema encoding, message encoding, schema text], sorted; and per topic
two SHA-256 digests, of its messages' data in order ("data_digest") and of their log times
and data in order ("timed_digest"), for comparing two recordings.
"""

import hashlib
import json
import sys

from mcap.reader import make_reader


def main():
    topics = {}
    setpoints = []
    event_codes = []
    channels = set()
    for path in sys.argv[1:]:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            for ch in summary.channels.values():
                sc = summary.schemas[ch.schema_id]
                t = topics.setdefault(ch.topic, {"count": 0, "schema": sc.name,
                                                  "schema_encoding": sc.encoding,
                                                  "encoding": ch.message_encoding,
                                                  "in_order": True, "last": 0,
                                                  "first_log_time": None,
                                                  "data": hashlib.sha256(),
                                                  "timed": hashlib.sha256()})
                json.loads(sc.data)  # the schema is JSON
                channels.add((ch.topic, sc.name, sc.encoding, ch.message_encoding,
                              sc.data.decode()))
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                t = topics[channel.topic]
                t["count"] += 1
                if message.log_time < t["last"]:
                    t["in_order"] = False
                t["last"] = message.log_time
                if t["first_log_time"] is None:
                    t["first_log_time"] = message.log_time
                t["data"].update(len(message.data).to_bytes(8, "little") + message.data)
                t["timed"].update(message.log_time.to_bytes(8, "little")
                                  + len(message.data).to_bytes(8, "little") + message.data)
                if channel.topic == "/trajgen/setpoint":
                    m = json.loads(message.data)
                    setpoints.append([m["program_id"], m["motion_time_s"], m["state"],
                                      m["position"]])
                if channel.topic == "/events":
                    event_codes.append(json.loads(message.data)["code"])
    for t in topics.values():
        del t["last"]
        t["data_digest"] = t.pop("data").hexdigest()
        t["timed_digest"] = t.pop("timed").hexdigest()
    print(json.dumps({"topics": topics, "setpoints": setpoints, "event_codes": event_codes,
                      "channels": sorted(channels)}))


if __name__ == "__main__":
    main()
