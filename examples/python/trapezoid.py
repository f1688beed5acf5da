#!/usr/bin/env python3
"""A foreign trajectory generator in Python: plain trapezoids, rest to rest, in trajgen's place.

Written from docs/services.md, docs/payload-layouts.md, docs/drives.md ("What servo expects of
a setpoint stream") and docs/operations.md (`swap`), on the model of iobridge.py: the role's work is here, what every
process of the cell shares (payload layouts, iceoryx2 configuration, status and histograms,
e-stop) is in rtcell.py beside it.

It takes trajgen's role (`--instance I --name N`) but ignores motion commands: once servo
reports the drives enabled it moves the axes given by `--range` (default x and y between 60
and 120) with trapezoid profiles, rest to rest, at the cell's own vmax and a constant
acceleration vmax / t_acc (`<i>/cell/config`), `--moves` moves (default 6), starting where
servo holds (`ServoStateV3.cmd_position`: bumpless), then holds still at rest until SIGTERM.
Motion commands are ignored; `<i>/trajgen/control` pause, resume and abort scale the speed
along the path (to rest within t_acc; an abort then drops the moves, as `supervisor down`
uses it), and SIGTERM brings a move to rest on its path the same way before leaving.
Every cycle (trajgen's period) it publishes a `SetpointV2` on `<i>/trajgen/setpoint` (the exact
trajectory at its stamp), notifies the `<i>/trajgen/setpoint` event service, and publishes its
status; its latency and execution-time histograms about every 100 ms.

    supervisor swap trajgen --instance I \
        --command "python3 examples/python/trapezoid.py --instance {instance} --name {name}"

Needs `pip install iceoryx2==0.10.0`.
"""
import argparse
import math
import re
import sys

import iceoryx2 as iox2

import rtcell
from rtcell import (ABORT, DONE, ENABLED, FAULT, FAULT_ABORTED, FAULT_ESTOP, IDLE, MAX_AXES,
                    MOVING, PAUSE, RESUME, ST_ENABLED, ST_JUMP, ST_NO_SETPOINT, ST_STALE,
                    MotionControlV2, ServoStateV3, SetpointV2, TrajgenHandoverV2, now_ns)

HANDOVER_MAX_AGE_NS = 30_000_000_000
log = rtcell.logger("trapezoid")


# --- the trapezoid -------------------------------------------------------------------------
class Trapezoid:
    """Rest to rest from p0 to p1, peak velocity <= v, constant acceleration a."""

    def __init__(self, p0, p1, v, a):
        self.p0, self.p1 = p0, p1
        d = abs(p1 - p0)
        self.dir = 1.0 if p1 >= p0 else -1.0
        self.a = a
        if d <= 0.0:
            self.ta = self.tc = 0.0
            self.vp = 0.0
        elif d >= v * v / a:             # reaches v: ramp, cruise, ramp
            self.vp, self.ta = v, v / a
            self.tc = d / v - v / a
        else:                            # a triangle: never reaches v
            self.ta = math.sqrt(d / a)
            self.vp, self.tc = a * self.ta, 0.0
        self.duration = 2.0 * self.ta + self.tc

    def at(self, t):
        """(position, velocity, acceleration) at t seconds after the start."""
        a, ta, tc, vp, s = self.a, self.ta, self.tc, self.vp, self.dir
        if t <= 0.0 or self.duration == 0.0:
            return self.p0, 0.0, 0.0
        if t >= self.duration:
            return self.p1, 0.0, 0.0
        if t < ta:
            return self.p0 + s * 0.5 * a * t * t, s * a * t, s * a
        d_acc = 0.5 * a * ta * ta
        if t < ta + tc:
            return self.p0 + s * (d_acc + vp * (t - ta)), s * vp, 0.0
        r = self.duration - t            # time left, on the decelerating ramp
        return self.p1 - s * 0.5 * a * r * r, s * a * r, -s * a


class Generator(rtcell.Process):
    def __init__(self, instance, name, moves, ranges, dwell, silence=(0.0, 0.5)):
        super().__init__(instance, name, log)
        self.moves, self.ranges, self.dwell_ns = moves, ranges, int(dwell * 1e9)
        self.silence_ns, self.silence_every_ns = (int(x * 1e9) for x in silence)
        self.silences, self.was_silent = 0, False
        self.notifier = None

    def open_notifier(self):
        """The `<i>/trajgen/setpoint` event service (trajgen's RtIpc flavour: semaphore event).
        Opened, never created: a stock binding would create it with the default event flavour.
        Its waiters use the semaphore, so a stock notifier reaches none of them (services.md);
        we notify anyway, as trajgen does."""
        try:
            svc = (self.node.service_builder(
                iox2.ServiceName.new(f"{self.instance}/trajgen/setpoint")).event().open())
            self.notifier = svc.notifier_builder().create()
            self.ports.append(self.notifier)
        except Exception as e:  # absent or full: the setpoints go on without it
            self.notifier = None
            if not getattr(self, "_notifier_warned", False):
                self._notifier_warned = True
                log(f"event service {self.instance}/trajgen/setpoint not opened: {e!r}")

    def close(self):
        super().close()
        self.notifier = None

    # --- setup -------------------------------------------------------------------------
    def setup(self):
        rc = self.join()
        if rc != 0:
            return rc
        cell, names = self.cell, self.names
        self.axes = min(cell.axes, MAX_AXES)
        servo_period = (cell.process[names.index("servo")].period_ns
                        if "servo" in names else 1_000_000) / 1e9
        # The motion of each axis: the cell's vmax, acceleration vmax / t_acc, both kept
        # within what command validation allows (limits.velocity, limits.velocity_step per
        # servo period: drives.md, "What servo expects of a setpoint stream").
        self.vmax, self.acc, self.targets = [], [], {}
        axis_names = [cell.axis[k].name.decode() for k in range(self.axes)]
        for k in range(self.axes):
            ax = cell.axis[k]
            v = ax.vmax
            if ax.velocity_limit > 0.0:
                v = min(v, ax.velocity_limit)
            a = ax.vmax / cell.t_acc_s
            if ax.velocity_step_limit > 0.0:
                a = min(a, 0.9 * ax.velocity_step_limit / servo_period)
            self.vmax.append(v)
            self.acc.append(a)
        for axis, (lo, hi) in self.ranges.items():
            if axis not in axis_names:
                log(f"--range {axis}: the cell has no such axis (it has: "
                    f"{', '.join(axis_names)})")
                return 2
            k = axis_names.index(axis)
            ax = cell.axis[k]
            if not (ax.min <= lo <= ax.max and ax.min <= hi <= ax.max):
                log(f"--range {axis}={lo}:{hi}: outside the axis' limits "
                    f"[{ax.min}, {ax.max}]")
                return 2
            self.targets[k] = (lo, hi)
        # Gantry kinematics (an empty name or `gantry`): the Cartesian coordinates are the
        # axes (kinematics.md); for any other kinematics the Cartesian half is left at 0.
        kin = cell.kinematics.type_name.decode()
        self.gantry = kin in ("", "gantry")
        self.coords = min(cell.kinematics.coords, MAX_AXES) if cell.kinematics.coords else (
            self.axes if self.gantry else 0)
        self.servo_sub = self.sub("servo/state", ServoStateV3)
        self.handover_sub = self.sub("trajgen/handover", TrajgenHandoverV2)
        self.control_sub = self.sub("trajgen/control", MotionControlV2)
        self.setpoint_pub = self.pub("trajgen/setpoint", SetpointV2)
        self.open_cell_ports(histograms=True)
        self.open_notifier()
        self.realtime()
        return 0

    # --- the motion ---------------------------------------------------------------------
    # The moves are travelled at a path speed sigma (1 normally) that pause, abort and
    # leaving ramp linearly to 0 within t_acc, and resume back to 1: the path never changes,
    # only the speed along it (services.md, trajgen's contract). tau is the move's own time.
    def rest_at(self, pos):
        """A new session, at rest at pos (servo's cmd_position)."""
        self.profile = None                      # list of per-axis profiles, or None: at rest
        self.rest = list(pos)
        self.tau0, self.sig0, self.sig_t0 = 0.0, self.sigma_target, 0

    def tau_sigma(self, t_ns):
        """(tau, sigma, dsigma/dt) at t_ns."""
        dt = max(0.0, (t_ns - self.sig_t0) / 1e9)
        s0, s1 = self.sig0, self.sigma_target
        if s0 == s1:
            return self.tau0 + s0 * dt, s0, 0.0
        r = (1.0 if s1 > s0 else -1.0) / self.t_acc
        tr = (s1 - s0) / r
        if dt < tr:
            return self.tau0 + s0 * dt + 0.5 * r * dt * dt, s0 + r * dt, r
        return self.tau0 + s0 * tr + 0.5 * r * tr * tr + s1 * (dt - tr), s1, 0.0

    def set_speed(self, t_ns, target):
        """Ramp the path speed to target from t_ns on."""
        self.tau0, self.sig0, _ = self.tau_sigma(t_ns)
        self.sig_t0, self.sigma_target = t_ns, target

    def reference(self, t_ns):
        """(positions, velocities, accelerations) at t_ns."""
        if self.profile is None:
            return list(self.rest), [0.0] * self.axes, [0.0] * self.axes
        tau, sig, dsig = self.tau_sigma(t_ns)
        p, v, a = [], [], []
        for prof in self.profile:
            x, xd, xdd = prof.at(tau)
            p.append(x)
            v.append(xd * sig)
            a.append(xdd * sig * sig + xd * dsig)
        return p, v, a

    def at_rest(self, t_ns):
        """No move, or its path speed is 0 for good."""
        if self.profile is None:
            return True
        _, sig, dsig = self.tau_sigma(t_ns)
        return sig == 0.0 and dsig == 0.0

    def profile_done(self, t_ns):
        return self.profile is None or (
            self.tau_sigma(t_ns)[0] >= max(pr.duration for pr in self.profile))

    def finish_profile(self, t_ns=None):
        """The move ends (at its end, or where it rests, t_ns): the reference rests there."""
        if self.profile is not None:
            self.rest = ([pr.p1 for pr in self.profile] if t_ns is None
                         else self.reference(t_ns)[0])
            self.profile = None

    def silent(self, t_ns, moving):
        """--silence: during a move, no setpoint for that long once every so often (a stalled
        generator, as a garbage collection or the host makes one now and then)."""
        quiet = (moving and self.silence_ns > 0
                 and (t_ns - self.sig_t0) % self.silence_every_ns < self.silence_ns)
        if quiet and not self.was_silent:
            self.silences += 1
        self.was_silent = quiet
        return quiet

    def start_move(self, t_ns):
        """The next move: every axis of --range to its next target, the others hold."""
        k_move = self.moves_done
        profs = []
        for k in range(self.axes):
            p0 = self.rest[k]
            if k in self.targets:
                lo, hi = self.targets[k]
                p1 = lo if k_move % 2 == 0 else hi
            else:
                p1 = p0
            profs.append(Trapezoid(p0, p1, self.vmax[k], self.acc[k]))
        self.profile = profs
        self.tau0, self.sig0, self.sig_t0 = 0.0, self.sigma_target, t_ns
        self.move_line = k_move + 1
        if self.motion_start_ns == 0:
            self.motion_start_ns = t_ns
        self.theoretical_s += max(pr.duration for pr in profs)
        log(f"move {k_move + 1}/{self.moves}: " + ", ".join(
            f"{self.cell.axis[k].name.decode()} {pr.p0:.3f} -> {pr.p1:.3f} in "
            f"{pr.duration:.3f} s" for k, pr in enumerate(profs) if pr.p1 != pr.p0))

    def take_controls(self, t_ns):
        """MotionControlV2s, at once: 1 pause, 2 resume, 3 abort (others: echoed, ignored)."""
        for c in self.take(self.control_sub):
            self.control_seq = c.seq
            if c.kind == PAUSE and not self.aborting:
                self.set_speed(t_ns, 0.0)
                log("pause")
            elif c.kind == RESUME and not self.aborting and not self.stop:
                self.set_speed(t_ns, 1.0)
                log("resume")
            elif c.kind == ABORT and not self.aborting:
                self.aborting = True
                self.set_speed(t_ns, 0.0)
                log("abort: coming to rest along the path, then dropping the moves")

    # --- the cycle ----------------------------------------------------------------------
    def run(self):
        self.watch()
        self.setpoint_seq = 0
        self.moves_done, self.move_line, self.session = 0, 0, False
        self.session_start = 0
        self.motion_start_ns = self.motion_end_ns = 0
        self.theoretical_s = 0.0
        self.estop_fault = self.abort_fault = self.aborting = self.stopping_motion = False
        self.sigma_target, self.t_acc, self.control_seq = 1.0, self.cell.t_acc_s, 0
        self.rest_at([0.0] * self.axes)
        newest = None
        handover_wait_since = now_ns()
        handover_seen, handover_logged = False, 0
        sp = SetpointV2(axes=self.axes, coords=self.coords, path_speed=1.0,
                        speed_override=1.0, program_speed=1.0)
        my_bit = 1 << self.index
        cycle = rtcell.Cycle(self, histograms=True)
        while True:
            wake, leaving = cycle.wait()

            # Where servo holds, and whether it follows.
            states = self.take(self.servo_sub)
            if states:
                if newest is None:
                    # Number on from the last setpoint servo took (a predecessor's), so that
                    # servo's `setpoint_seq` tells this generator's setpoints apart.
                    self.setpoint_seq = max(self.setpoint_seq, states[-1].setpoint_seq)
                newest = states[-1]
            for rec in self.take(self.handover_sub):
                if not handover_seen:
                    log(f"handover record: valid {rec.valid}, "
                        f"{(wake - rec.stamp_ns) / 1e9:.3f} s old")
                handover_seen = True
                if rec.valid == 1 and wake - rec.stamp_ns < HANDOVER_MAX_AGE_NS:
                    # A predecessor paused on a program segment: this generator runs no
                    # program; it starts at rest where servo holds all the same.
                    log(f"handover record (program {rec.program_id}, line {rec.line}) "
                        "taken: programs are not run here, starting at rest")
            # A trajgen that starts during a swap waits for its predecessor's handover record
            # before it publishes (services.md, HostStateV1.handover).
            waiting = (self.host is not None and self.host.handover & my_bit
                       and not handover_seen and wake - handover_wait_since < 2_000_000_000)

            if waiting and not handover_logged:
                handover_logged = 1
                log("a swap is under way: waiting for the predecessor's handover record")
            elif handover_logged == 1 and not waiting:
                handover_logged = 2
                log("handover: " + ("record seen" if handover_seen else
                                    "bit cleared" if not self.host.handover & my_bit
                                    else "no record within 2 s") + ", publishing")
            publish = newest is not None and not waiting
            if publish:
                enabled = newest.power == ENABLED and bool(newest.status & ST_ENABLED)
                cmd = [newest.cmd_position[k] for k in range(self.axes)]
                if self.reacting:
                    # e-stop: drop the moves; the reference rests where servo brings the axes.
                    if self.session or not self.estop_fault:
                        log("e-stop: the moves are dropped")
                    self.estop_fault, self.session, self.aborting = True, False, False
                    self.moves_done = self.moves
                    self.sigma_target = 1.0
                    self.rest_at(cmd)
                elif not enabled or newest.status & ST_JUMP:
                    # Servo does not follow (or refused us as a jump): start again, at rest,
                    # from its commanded position.
                    if self.session and self.profile is not None:
                        log("servo stopped following: starting again at rest from "
                            f"{[round(c, 4) for c in cmd]}")
                    if self.aborting:
                        self.aborting, self.abort_fault = False, True
                        self.moves_done = self.moves
                    self.session = False
                    self.sigma_target = 1.0
                    self.rest_at(cmd)
                elif not self.session:
                    self.session, self.session_start = True, wake
                    self.first_seq = self.setpoint_seq + 1
                    self.estop_fault = self.abort_fault = False
                    self.rest_at(cmd)
                    log(f"servo enabled: at rest at {[round(c, 4) for c in cmd]}")
                self.take_controls(wake)
                if self.session:
                    if leaving and not self.stopping_motion:
                        self.stopping_motion = True    # the stop reaction: rest on the path
                        self.set_speed(wake, 0.0)
                    if self.profile is not None and self.profile_done(wake):
                        self.finish_profile()
                        self.moves_done += 1
                        self.last_move_end = wake
                        if self.moves_done >= self.moves:
                            self.motion_end_ns = wake
                            log(f"{self.moves} moves done, holding at "
                                f"{[round(r, 4) for r in self.rest]}"
                                + (f" ({self.silences} silences)" if self.silence_ns else ""))
                    elif (self.profile is not None and (self.aborting or leaving)
                          and self.at_rest(wake)):
                        self.finish_profile(wake)      # at rest on the path: the move ends
                        if self.aborting:
                            self.aborting, self.abort_fault = False, True
                            self.moves_done, self.motion_end_ns = self.moves, wake
                            log(f"aborted, at rest at {[round(r, 4) for r in self.rest]}")
                    if self.aborting and self.profile is None:
                        self.aborting, self.abort_fault = False, True
                        self.moves_done = self.moves
                    if (not leaving and self.profile is None and self.sigma_target == 1.0
                            and self.moves_done < self.moves
                            and newest.setpoint_seq >= self.first_seq
                            and not newest.status & (ST_NO_SETPOINT | ST_STALE | ST_JUMP)):
                        # servo follows this session's setpoints: move after the dwell.
                        since = max(self.session_start, getattr(self, "last_move_end", 0))
                        if wake - since >= self.dwell_ns:
                            self.start_move(wake)

                # The setpoint: the exact trajectory at its stamp.
                stamp = now_ns()
                p, v, a = self.reference(stamp)
                self.setpoint_seq += 1
                sp.seq, sp.stamp_ns = self.setpoint_seq, stamp
                moving = self.profile is not None
                sp.state = (FAULT if self.estop_fault or self.abort_fault else
                            MOVING if moving else
                            DONE if self.moves_done >= self.moves else IDLE)
                sp.fault = (FAULT_ESTOP if self.estop_fault else
                            FAULT_ABORTED if self.abort_fault else 0)
                sp.control_seq = self.control_seq
                sp.line = self.move_line
                sp.motion_start_ns, sp.motion_end_ns = self.motion_start_ns, self.motion_end_ns
                sp.motion_time_s = ((min(stamp, self.motion_end_ns or stamp)
                                     - self.motion_start_ns) / 1e9
                                    if self.motion_start_ns else 0.0)
                sp.theoretical_s = self.theoretical_s
                tau, sigma, _ = self.tau_sigma(stamp)
                sp.segment_time_s = tau if moving else 0.0
                sp.path_speed = sigma if moving else self.sigma_target
                for k in range(self.axes):
                    sp.position[k], sp.velocity[k], sp.acceleration[k] = p[k], v[k], a[k]
                    if self.gantry and k < self.coords:
                        sp.cartesian[k], sp.cartesian_velocity[k] = p[k], v[k]
                if not self.silent(stamp, moving):
                    self.setpoint_pub.send_copy(sp)
                if self.notifier is None and self.setpoint_seq % 250 == 0:
                    self.open_notifier()
                if self.notifier is not None:
                    try:
                        self.notifier.notify()
                    except Exception:
                        pass

            at_rest = self.at_rest(wake)
            self.report_safe(wake)          # the program is dropped at once: safe
            done_leaving = leaving and (at_rest or not self.session or wake - self.stop_since
                                        > self.cell.estop_stop_time_ns + 1_000_000_000)
            # SAFE: at rest (the reaction to an e-stop or to leaving is complete).
            cycle.publish_status(leaving, safe=at_rest)
            if cycle.status.stats.cycles % 25 == 0 or done_leaving:  # about every 100 ms,
                cycle.publish_histograms()                           # and on stopping
            if done_leaving:
                log(f"leaving (exit status {self.exit_code}), the reference at rest at "
                    f"{[round(r, 4) for r in self.reference(now_ns())[0]]}")
                return self.exit_code
            cycle.next()


def parse_range(text):
    m = re.fullmatch(r"([A-Za-z0-9_]+)=(-?[0-9.]+):(-?[0-9.]+)", text)
    if not m:
        raise argparse.ArgumentTypeError(f"{text!r}: expected AXIS=LOW:HIGH, e.g. x=60:120")
    return m.group(1), (float(m.group(2)), float(m.group(3)))


def main():
    ap = rtcell.arguments(__doc__, "trajgen")
    ap.add_argument("--moves", type=int, default=6, help="moves before holding (default 6)")
    ap.add_argument("--range", type=parse_range, action="append", dest="ranges",
                    metavar="AXIS=LOW:HIGH",
                    help="an axis to move and its two targets (repeatable; default "
                         "x=60:120 and y=60:120); odd moves go to LOW, even ones to HIGH")
    ap.add_argument("--dwell", type=float, default=0.3,
                    help="seconds at rest before each move (default 0.3)")
    ap.add_argument("--silence", type=float, nargs=2, default=(0.0, 0.5),
                    metavar=("SECONDS", "EVERY"),
                    help="during a move, publish no setpoint for SECONDS once every EVERY "
                         "seconds, as a stalled generator (default: never)")
    args = rtcell.parse(ap)
    if args.moves < 0:
        ap.error("--moves must be 0 or more")
    if not args.dwell >= 0.0:
        ap.error("--dwell must be 0 or more")
    if not (0.0 <= args.silence[0] < args.silence[1]):
        ap.error("--silence SECONDS EVERY: 0 <= SECONDS < EVERY")
    ranges = dict(args.ranges or [("x", (60.0, 120.0)), ("y", (60.0, 120.0))])
    return rtcell.serve(Generator(args.instance, args.name, args.moves, ranges, args.dwell,
                                  tuple(args.silence)))


if __name__ == "__main__":
    sys.exit(main())
