"""A foreign trajectory generator whose first setpoints jump: for the tests of servo's refusal.

    supervisor swap trajgen --instance I --command "python3 tests/python/jumping_generator.py \
        --instance {instance} --name {name} --jump x 2.0 0.0 --to 50"

examples/python/trapezoid.py in trajgen's place, except that until servo refuses one of its
setpoints as a jump (`ServoStateV3.status` SETPOINT_JUMP), every setpoint lies OFFSET off where
servo holds on AXIS and moves at VELOCITY there (its position not following that velocity:
`--jump x 0 1.0` is a velocity jump alone). Once refused, it starts again at rest where servo
holds, as trajgen does, and moves AXIS to `--to` in one plain trapezoid, then holds.

Needs `pip install iceoryx2==0.10.0`.
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                "..", "..", "examples", "python"))

import rtcell  # noqa: E402
import trapezoid  # noqa: E402


class Jumping(trapezoid.Generator):
    def __init__(self, instance, name, axis, offset, velocity, to):
        super().__init__(instance, name, 1, {axis: (to, to)}, 0.3)
        self.jump_axis, self.offset, self.jump_velocity = axis, offset, velocity
        self.refused = False

    def setup(self):
        rc = super().setup()
        if rc == 0:
            names = [self.cell.axis[k].name.decode() for k in range(self.axes)]
            self.jump_k = names.index(self.jump_axis)
        return rc

    def take(self, sub):
        got = rtcell.Process.take(sub)
        if (not self.refused and sub is getattr(self, "servo_sub", None)
                and any(s.status & rtcell.ST_JUMP for s in got)):
            self.refused = True
            trapezoid.log("servo refused a setpoint as a jump: on from where it holds")
        return got

    def reference(self, t_ns):
        p, v, a = super().reference(t_ns)
        if not self.refused:
            p[self.jump_k] += self.offset
            v[self.jump_k] += self.jump_velocity
        return p, v, a


def main():
    ap = rtcell.arguments(__doc__, "trajgen")
    ap.add_argument("--jump", nargs=3, required=True, metavar=("AXIS", "OFFSET", "VELOCITY"),
                    help="the axis, and how far off (axis unit) and how fast (unit/s) its "
                         "setpoints are until servo refuses one")
    ap.add_argument("--to", type=float, required=True,
                    help="where the axis then moves, once")
    args = rtcell.parse(ap)
    axis, offset, velocity = args.jump[0], float(args.jump[1]), float(args.jump[2])
    return rtcell.serve(Jumping(args.instance, args.name, axis, offset, velocity, args.to))


if __name__ == "__main__":
    sys.exit(main())
