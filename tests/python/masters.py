"""Masters we did not write, against the emulated line: `masters.py pysoem|kickcat IFACE [IFACE2]`.

kickcat takes the line as a ring, with its second port on IFACE2 (the emulator's --ring):
without one it waits out its link timeout after each of its init's frames.

The line is an EK1100, an EL1008, an EL2008 and a CiA 402 drive. Each master scans it, reads
the drive's identity (0x1018), supported modes (0x6502), statusword (0x6041) and mode display
(0x6061) by SDO (pysoem also sets Distributed Clocks up and runs the drive on SYNC0; kickcat
leaves it SM-synchronous), brings the line to OP, writes 20 patterns to the EL2008 and reads them back
on the EL1008 (the emulator's --loopback test cable), then takes the drive through Shutdown,
Switch on and Enable operation in CSP, holding where it stands. It prints one JSON object:
what it found, every exchange's working counter (pysoem) and inputs, the drive's states, as
its last line of stdout (kickcat prints its own lines before it). The Rust test checks it.
"""
import datetime
import json
import struct
import sys
import time


TIMEOUT_US = 100_000
DRIVE = 3
# pysoem runs the drive on Distributed Clocks: SYNC0 every 500 µs.
SYNC0_NS = 500_000


def patterns():
    return [(k * 73 ^ 0xC3) & 0xFF for k in range(20)]


def sdo_u32(data):
    return int.from_bytes(bytes(data)[:4].ljust(4, b"\0"), "little")


def enable(exchange):
    """Shutdown, Switch on, Enable operation (CSP, the target where the axis stands) through
    `exchange(outputs) -> inputs`, each until the statusword shows its state: the states
    seen (statusword & 0x6F), in order, and the last statusword."""
    # Default mapping: 0x6040 u16, 0x6060 i8, 0x607A i32, 0x60FF i32, 0x6071 i16, 0x60B1 i32,
    # 0x60B2 i16 out; 0x6041 u16, 0x6061 i8, 0x603F u16, 0x6064 i32, ... in.
    inputs = exchange(struct.pack("<Hbiihih", 0, 8, 0, 0, 0, 0, 0))
    position = struct.unpack_from("<i", inputs, 5)[0]
    seen, statusword = [], None
    for controlword, want in [(0x06, 0x21), (0x07, 0x23), (0x0F, 0x27)]:
        for _ in range(200):
            inputs = exchange(struct.pack("<Hbiihih", controlword, 8, position, 0, 0, 0, 0))
            statusword = struct.unpack_from("<H", inputs, 0)[0]
            if statusword & 0x6F == want:
                break
        seen.append(statusword & 0x6F)
    mode = struct.unpack_from("<b", inputs, 2)[0]
    return {"states": seen, "statusword": statusword, "mode_display": mode, "position": position}


def with_pysoem(ifname):
    import pysoem

    # SOEM's timeouts are made for a wire: a frame back within 2 ms, an EEPROM word within
    # 20 ms. The emulator answers on a veth of a noisy 2-vCPU VM running the whole suite,
    # whose stalls reach hundreds of ms: a late answer made SOEM map the EL1008 without its
    # inputs (a CI run under load). Generous here; what is checked is unchanged.
    t = pysoem.settings.timeouts
    t.ret = 200_000
    t.safe = 200_000
    t.eeprom = 500_000
    t.tx_mailbox = 500_000

    m = pysoem.Master()
    m.open(ifname)
    found = m.config_init()
    devices = [
        {"name": s.name, "vendor": s.man, "product": s.id, "revision": s.rev}
        for s in m.slaves
    ]
    drive = m.slaves[DRIVE]
    sdo = {
        "vendor": sdo_u32(drive.sdo_read(0x1018, 1)),
        "product": sdo_u32(drive.sdo_read(0x1018, 2)),
        "modes": sdo_u32(drive.sdo_read(0x6502, 0)),
        "statusword": sdo_u32(drive.sdo_read(0x6041, 0)),
        "mode_display": sdo_u32(drive.sdo_read(0x6061, 0)),
    }
    # Distributed Clocks (SOEM's ecx_configdc: the receive times latched and read, offsets
    # and delays written), the drive asked for SYNC0 (0x1C32:01 = 2, refused in SAFE-OP
    # without SYNC0 active) and SYNC0 started by SOEM (ecx_dcsync0: the drive's system time
    # read, start time, cycle, activation).
    has_dc = bool(m.config_dc())
    drive.sdo_write(0x1C32, 1, struct.pack("<H", 2))
    drive.dc_sync(True, SYNC0_NS)
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
    dc_time = m.dc_time
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
    wkcs = []

    def exchange(outputs):
        drive.output = outputs
        for _ in range(50):
            m.send_processdata()
            wkc = m.receive_processdata(TIMEOUT_US)
            if wkc == m.expected_wkc:
                break
        wkcs.append(wkc)
        return bytes(drive.input)

    # SOEM starts SYNC0 100 ms after its set-up; outputs wait for it.
    until = time.monotonic() + 0.3
    while time.monotonic() < until:
        m.send_processdata()
        m.receive_processdata(TIMEOUT_US)
        time.sleep(0.001)
    enabled = enable(exchange)
    enabled["wkc"] = sorted(set(wkcs))
    dc = {
        "found": has_dc,
        "sync_mode": sdo_u32(drive.sdo_read(0x1C32, 1)),
        "time": [dc_time, m.dc_time],
    }
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
        "sdo": sdo,
        "drive": enabled,
        "dc": dc,
    }


def with_kickcat(ifname, ring):
    import kickcat

    ms = lambda n: datetime.timedelta(milliseconds=n)
    # Cable redundancy: kickcat sends every frame out of both ports and reads both. Without a
    # second port its `writeThenRead` (the init's broadcasts) waits out the link timeout on
    # the port that has nothing to read: 70 s of a 72-s test at 500 ms.
    link = kickcat.create_link(ifname, ring)
    # Room for the host's stalls, in each frame's answer and in the whole init: at 100 ms (and once at 200 ms) a
    # frame and 2 s the init, a CI run with both cores loaded timed out in init (kickcat makes
    # the init's timeout the drives' watchdog too, 16 bits of 100 µs: at most 6.5 s, or
    # "Invalid watchdog"). Longer still once mapped, so a stall does not pass for a lost frame.
    link.set_timeout(ms(500))
    bus = kickcat.Bus(link)
    bus.init(ms(5000))
    slaves = bus.slaves()
    drive = slaves[DRIVE]
    read = lambda index, sub, size: sdo_u32(
        bus.read_sdo(drive, index, sub, kickcat.Access.PARTIAL, size, ms(1000))
    )
    sdo = {
        "vendor": read(0x1018, 1, 4),
        "product": read(0x1018, 2, 4),
        "modes": read(0x6502, 0, 4),
        "statusword": read(0x6041, 0, 2),
        "mode_display": read(0x6061, 0, 1),
    }
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
    errors = [0]

    def exchange(outputs):
        drive.set_output_bytes(outputs)
        for _ in range(50):
            try:
                bus.process_data()
                break
            except RuntimeError:
                errors[0] += 1
        return bytes(drive.input_data)

    enabled = enable(exchange)
    enabled["errors"] = errors[0]
    bus.request_state(kickcat.State.INIT)
    return {
        "found": len(slaves),
        "addresses": [s.address for s in slaves],
        "sizes": sizes,
        "op": op,
        "exchanges": exchanges,
        "sdo": sdo,
        "drive": enabled,
    }


if __name__ == "__main__":
    master, ifname = sys.argv[1], sys.argv[2]
    if master == "pysoem":
        result = with_pysoem(ifname)
    else:
        result = with_kickcat(ifname, sys.argv[3] if len(sys.argv) > 3 else "")
    print(json.dumps(result))
