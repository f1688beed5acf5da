"""Masters we did not write, against the emulated line: `masters.py pysoem|kickcat IFACE`.

Each scans the line, brings it to OP, writes 20 patterns to the EL2008 and reads them back
on the EL1008 (the emulator's --loopback test cable), and prints one JSON object: what it
found and every exchange's working counter (pysoem) and inputs, as its last line of stdout
(kickcat prints its own lines before it). The Rust test checks it.
"""
import datetime
import json
import sys


TIMEOUT_US = 100_000


def patterns():
    return [(k * 73 ^ 0xC3) & 0xFF for k in range(20)]


def with_pysoem(ifname):
    import pysoem

    m = pysoem.Master()
    m.open(ifname)
    found = m.config_init()
    devices = [
        {"name": s.name, "vendor": s.man, "product": s.id, "revision": s.rev}
        for s in m.slaves
    ]
    iomap = m.config_map()
    # Timeouts in µs, generous: the test host is a noisy 2-vCPU VM whose stalls reach 1 s.
    safe_op = m.state_check(pysoem.SAFEOP_STATE, 5_000_000)
    m.state = pysoem.OP_STATE
    m.send_processdata()
    m.receive_processdata(TIMEOUT_US)
    m.write_state()
    for _ in range(200):
        m.send_processdata()
        m.receive_processdata(TIMEOUT_US)
        if m.state_check(pysoem.OP_STATE, 50_000) == pysoem.OP_STATE:
            break
    m.read_state()  # refreshes every SubDevice's state
    op = [s.state for s in m.slaves]
    exchanges = []
    for p in patterns():
        m.slaves[2].output = bytes([p])
        seen, wkc, late = None, None, 0
        # A reply later than the timeout comes back as a bad working counter: counted, and
        # the exchange is done again (the test checks the one that completed).
        for _ in range(50):
            m.send_processdata()
            wkc = m.receive_processdata(TIMEOUT_US)
            seen = m.slaves[1].input[0]
            if wkc == m.expected_wkc and seen == p:
                break
            late += wkc != m.expected_wkc
        exchanges.append({"wrote": p, "read": seen, "wkc": wkc, "late": late})
    m.state = pysoem.INIT_STATE
    m.write_state()
    m.close()
    return {
        "found": found,
        "devices": devices,
        "iomap": iomap,
        "expected_wkc": m.expected_wkc,
        "safe_op": safe_op,
        "op": op,
        "exchanges": exchanges,
    }


def with_kickcat(ifname):
    import kickcat

    ms = lambda n: datetime.timedelta(milliseconds=n)
    link = kickcat.create_link(ifname, "")
    # Its scan waits out the timeout on probes nothing answers: short there; longer once
    # mapped, so a host stall does not pass for a lost frame.
    link.set_timeout(ms(100))
    bus = kickcat.Bus(link)
    bus.init(ms(2000))
    slaves = bus.slaves()
    bus.create_mapping()
    link.set_timeout(ms(1000))
    sizes = [[s.input_size, s.output_size] for s in slaves]
    bus.request_state(kickcat.State.SAFE_OP)
    bus.wait_for_state(kickcat.State.SAFE_OP, ms(2000))
    slaves[2].set_output_bytes(bytes([0]))
    bus.process_data()
    bus.request_state(kickcat.State.OPERATIONAL)
    bus.wait_for_state(kickcat.State.OPERATIONAL, ms(2000), lambda: bus.process_data())
    op = [str(bus.get_state(s)) for s in slaves]
    exchanges = []
    for p in patterns():
        slaves[2].set_output_bytes(bytes([p]))
        seen, errors = None, 0
        for _ in range(50):
            try:
                # Raises on a working counter other than expected (LRD and LWR apart).
                bus.process_data()
            except RuntimeError:
                errors += 1
                continue
            seen = slaves[1].input_data[0]
            if seen == p:
                break
        exchanges.append({"wrote": p, "read": seen, "errors": errors})
    bus.request_state(kickcat.State.INIT)
    return {
        "found": len(slaves),
        "addresses": [s.address for s in slaves],
        "sizes": sizes,
        "op": op,
        "exchanges": exchanges,
    }


if __name__ == "__main__":
    master, ifname = sys.argv[1], sys.argv[2]
    result = with_pysoem(ifname) if master == "pysoem" else with_kickcat(ifname)
    print(json.dumps(result))
