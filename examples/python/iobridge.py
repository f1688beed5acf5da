#!/usr/bin/env python3
"""A Python iobridge for the cell, written from docs/services.md and docs/payload-layouts.md.

Every cycle: read the e-stop (I/estop, I/host/state), copy servo's newest measured position
into the fieldbus image (I/iobridge/output) and publish the status (I/N/status).
Run by the supervisor as `python3 iobridge.py --instance {instance} --name {name}`.
The role's work is here; what every process of the cell shares (payload layouts, iceoryx2
configuration, status, e-stop) is in rtcell.py beside it, written from the same documents.
Needs `pip install iceoryx2==0.10.0`.
"""
import ctypes as C
import math
import struct
import sys

import rtcell
from rtcell import FieldbusImageV1, ServoStateV3, now_ns


def round_half_away(x):
    r = math.trunc(x)
    return r + (1 if x > 0 else -1) if abs(x - r) >= 0.5 else r


def encode_image(state):
    """Fieldbus image (found by observing the Rust iobridge, see the report): little-endian
    u64 measured time in µs, then per axis an i32 position in thousandths of the axis unit,
    rounded half away from zero; NaN/inf is i32::MIN."""
    axes = min(state.axes, 8)
    counts = []
    for k in range(axes):
        p = state.act_position[k]
        counts.append(-2**31 if not math.isfinite(p) else
                      max(-2**31, min(2**31 - 1, round_half_away(p * 1000.0))))
    data = struct.pack(f"<Q{axes}i", state.measured_stamp_ns // 1000, *counts)
    return data, axes


class Bridge(rtcell.Process):
    # --- setup -------------------------------------------------------------------------
    def setup(self):
        rc = self.join()
        if rc != 0:
            return rc
        self.servo_sub = self.sub("servo/state", ServoStateV3)
        self.image_pub = self.pub("iobridge/output", FieldbusImageV1)
        self.open_cell_ports()
        self.realtime()
        return 0

    # --- the cycle ----------------------------------------------------------------------
    def run(self):
        self.watch()
        self.image_seq = 0
        newest = None
        cycle = rtcell.Cycle(self)
        while True:
            wake, leaving = cycle.wait()
            # The work: iobridge never changes its output on an e-stop (safe at once).
            states = self.take(self.servo_sub)
            if states:
                newest = states[-1]
            if newest is not None:
                data, axes = encode_image(newest)
                self.image_seq += 1
                img = FieldbusImageV1(self.image_seq, now_ns(), newest.measured_stamp_ns,
                                      newest.seq, len(data), axes)
                C.memmove(img.image, data, len(data))
                self.image_pub.send_copy(img)
            self.report_safe(wake)
            cycle.publish_status(leaving, safe=True)
            if leaving:  # safe at once: nothing to bring to rest
                return self.exit_code
            cycle.next()


def main():
    ap = rtcell.arguments(__doc__, "iobridge")
    args = rtcell.parse(ap)
    return rtcell.serve(Bridge(args.instance, args.name))


if __name__ == "__main__":
    sys.exit(main())
