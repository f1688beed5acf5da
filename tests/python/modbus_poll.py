"""Reads the cell's Modbus server with pymodbus (an independent client) for the tests.

    python3 modbus_poll.py HOST PORT SECONDS AXES

Polls the input registers every 5 ms for SECONDS and prints one CSV row per new image:
image, measured_us, written_us, motion, line, then per axis position, command and following
error in axis units (docs/fieldbus.md). Says `ready` on stderr once connected (a test starts
the motion only then: under load, Python's start alone can take seconds). Exits 1 on any
exception response or lost connection.
"""

import sys
import time

from pymodbus.client import ModbusTcpClient

AXIS_BASE, AXIS_WORDS = 32, 8


def u(regs, at, words):
    v = 0
    for w in regs[at:at + words]:
        v = v << 16 | w
    return v


def i32(regs, at):
    v = u(regs, at, 2)
    return v - (1 << 32) if v >= 1 << 31 else v


def main():
    host, port, seconds, axes = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
    client = ModbusTcpClient(host, port=port, timeout=2)
    if not client.connect():
        print(f"cannot connect to {host}:{port}", file=sys.stderr)
        return 1
    n = AXIS_BASE + AXIS_WORDS * axes
    print("ready", file=sys.stderr, flush=True)
    last = None
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        r = client.read_input_registers(0, count=n, device_id=1)
        if r.isError():
            print(f"exception: {r}", file=sys.stderr)
            return 1
        regs = r.registers
        image = u(regs, 0, 4)
        if image != last:
            last = image
            row = [image, u(regs, 4, 4), u(regs, 8, 4), regs[17], u(regs, 20, 2)]
            for k in range(axes):
                b = AXIS_BASE + AXIS_WORDS * k
                row += [i32(regs, b) / 1000, i32(regs, b + 2) / 1000, i32(regs, b + 4) / 1000]
            print(",".join(str(v) for v in row), flush=True)
        time.sleep(0.005)
    client.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
