#!/usr/bin/env python3
"""A client of a line of cells, written from docs/network.md alone (no Rust source read).

    line_client.py --connect tcp/HOST:PORT [--connect ...] --user NAME --secret-file PATH CMD
    CMD: cells | status CELL | pause CELL

Needs only the standard library and eclipse-zenoh 1.10.2. Exit codes as docs/network.md says:
0 done, 2 refused, 1 failed or no answer.
"""
import argparse
import hashlib
import hmac
import json
import secrets
import sys
import time

import zenoh

TIMEOUT_S = 5.0


def open_session(endpoints):
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("connect/endpoints", json.dumps(endpoints))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def linked(session, patience_s=15.0):
    """Whether the session has a peer or a router: the links come up after it opens, so
    asked until one is there, or `patience_s` passed."""
    end = time.monotonic() + patience_s
    while True:
        if list(session.info.peers_zid()) + list(session.info.routers_zid()):
            return True
        if time.monotonic() > end:
            return False
        time.sleep(0.05)


def get_json(session, key, **kw):
    """Every reply of a get, as (key, parsed JSON); error replies are skipped."""
    out = []
    for reply in session.get(key, timeout=TIMEOUT_S, **kw):
        if reply.ok is not None:
            out.append((str(reply.ok.key_expr), json.loads(reply.ok.payload.to_bytes())))
    return out


def cells(session):
    alive = sorted({str(r.ok.key_expr).split("/")[2]
                    for r in session.liveliness().get("rtc/v1/*/alive", timeout=TIMEOUT_S)
                    if r.ok is not None})
    statuses = {m["cell"]: m for _, m in get_json(session, "rtc/v1/*/status")}
    rows = []
    for name in alive:
        m = statuses.get(name, {})
        estop = (m.get("status") or {}).get("estop")
        rows.append({"cell": name, "host": m.get("host"),
                     "estop": estop["latched"] if estop else None})
    print(json.dumps(rows))
    return 0


def reachable(session, cell, patience_s=15.0):
    """The cell's status once its gateway answers (our links come up one by one: the first
    peer linked need not be this cell's), or none after `patience_s`."""
    end = time.monotonic() + patience_s
    while True:
        replies = get_json(session, f"rtc/v1/{cell}/status")
        if replies or time.monotonic() > end:
            return replies
        time.sleep(0.2)


def status(session, cell):
    replies = reachable(session, cell)
    if not replies:
        print(json.dumps({"answer": "failed", "reason": f"no status from {cell!r}"}))
        return 1
    print(json.dumps(replies[0][1]["status"]))
    return 0


def command(session, cell, user, secret, cmd):
    # Sent once the cell is linked: a command that reaches no one is not sent twice.
    reachable(session, cell)
    envelope = {"user": user, "cell": cell, "time_ms": int(time.time() * 1000),
                "nonce": secrets.randbelow(2**53), "command": cmd}
    payload = json.dumps(envelope).encode()
    signature = hmac.new(secret.encode(), payload, hashlib.sha256).hexdigest()
    replies = get_json(session, f"rtc/v1/{cell}/control", payload=payload, attachment=signature)
    if not replies:
        print(json.dumps({"answer": "failed", "reason": f"no answer from {cell!r}"}))
        return 1
    answer = replies[0][1]
    print(json.dumps(answer))
    return {"done": 0, "refused": 2}.get(answer.get("answer"), 1)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--connect", action="append", required=True, help="a Zenoh endpoint")
    p.add_argument("--user", required=True)
    p.add_argument("--secret-file", required=True)
    p.add_argument("cmd", choices=["cells", "status", "pause"])
    p.add_argument("cell", nargs="?")
    a = p.parse_args()
    if a.cmd != "cells" and not a.cell:
        p.error(f"{a.cmd} needs a CELL")
    with open(a.secret_file, encoding="utf-8") as f:
        secret = f.readline().rstrip("\r\n")
    with open_session(a.connect) as session:
        if not linked(session):
            print(json.dumps({"answer": "failed", "reason": "no endpoint of the line let us in"}))
            return 1
        if a.cmd == "cells":
            return cells(session)
        if a.cmd == "status":
            return status(session, a.cell)
        return command(session, a.cell, a.user, secret, {"op": "pause"})


if __name__ == "__main__":
    sys.exit(main())
