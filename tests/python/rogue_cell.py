"""A rogue host on a line of cells, for the tests: it holds the line's certificate authority
and a room's password (a compromised host), its certificate names it OWN, and it publishes
events under another cell's name (VICTIM) as well as under its own, every 100 ms.

    python3 rogue_cell.py --listen tls/127.0.0.1:7450 --ca CA --cert CERT --key KEY \
        --dictionary FILE --victim press-0 --own press-9

Prints "ready" once it publishes; runs until killed. Each forged event's text is
"forged by OWN", each of its own "OWN's own".
"""

import argparse
import json
import time

import zenoh


def event(seq, text):
    return json.dumps({
        "gateway_started_ms": 1, "seq": seq, "lost": 0,
        "event": {"t_s": 0.0, "stamp_ns": 0, "source": "servo", "seq": seq,
                  "severity": "info", "code": 303, "name": "disabling", "axis": None,
                  "value": 0.0, "limit": 0.0, "text": text},
    })


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--listen", required=True)
    p.add_argument("--ca", required=True)
    p.add_argument("--cert", required=True)
    p.add_argument("--key", required=True)
    p.add_argument("--dictionary", required=True)
    p.add_argument("--victim", required=True)
    p.add_argument("--own", required=True)
    a = p.parse_args()
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("listen/endpoints", json.dumps([a.listen]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/shared_memory/enabled", "false")
    conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(a.ca))
    conf.insert_json5("transport/link/tls/listen_certificate", json.dumps(a.cert))
    conf.insert_json5("transport/link/tls/listen_private_key", json.dumps(a.key))
    conf.insert_json5("transport/link/tls/connect_certificate", json.dumps(a.cert))
    conf.insert_json5("transport/link/tls/connect_private_key", json.dumps(a.key))
    conf.insert_json5("transport/link/tls/enable_mtls", "true")
    conf.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(a.dictionary))
    session = zenoh.open(conf)
    forged = session.declare_publisher(f"rtc/v1/{a.victim}/events")
    own = session.declare_publisher(f"rtc/v1/{a.own}/events")
    tokens = [session.liveliness().declare_token(f"rtc/v1/{n}/alive") for n in (a.victim, a.own)]
    print("ready", flush=True)
    seq = 0
    while True:
        seq += 1
        forged.put(event(seq, f"forged by {a.own}"))
        own.put(event(seq, f"{a.own}'s own"))
        time.sleep(0.1)
    del tokens


if __name__ == "__main__":
    main()
