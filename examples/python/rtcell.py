"""The cell's shared memory from Python, for a process written from the documents.

What every process that takes a role in the cell needs, whatever its role:
- the payload layouts of docs/payload-layouts.md (ctypes structs, each checked against its size
  and carrying its iceoryx2 type name) and the values of their fields;
- the iceoryx2 configuration and the services' settings of docs/services.md (its table);
- the status (`<i>/<name>/status`, `ProcessStatusV2`) and the latency and execution-time
  histograms (`<i>/<name>/latency`, `<i>/<name>/exec_time`, `LatencyHistogramV1`) a process
  publishes, and the cycle they describe (period and phase of its `[[process]]`);
- the e-stop as a process sees it (`<i>/estop`, `<i>/host/state`, the propagation rules and
  the supervisor's heartbeat of services.md);
- the cell's virtual clock (docs/virtual-time.md, `clock` = 1 in the cell configuration): the
  cycle waits for the clock's grants instead of sleeping, and the cell's time (`now_ns`) is
  the instant granted;
- the command line and the SIGTERM handling the supervisor expects of a process.

A role's script (iobridge.py, trapezoid.py) subclasses `Process` with its own `setup()` and
`run()` and imports this module from its own folder. Needs `pip install iceoryx2==0.10.0`.
"""
import argparse
import ctypes as C
import os
import re
import signal
import sys
import time

import iceoryx2 as iox2

u8, u16, u32, u64 = C.c_uint8, C.c_uint16, C.c_uint32, C.c_uint64
i32, f32, f64 = C.c_int32, C.c_float, C.c_double
MAX_AXES = 8                                         # the length of every per-axis array


def payload(type_name, size, fields):
    """A ctypes struct with its iceoryx2 type name, checked against payload-layouts.md."""
    cls = type(type_name[5:], (C.Structure,), {"_fields_": fields})
    if "type_name" not in dict(fields):  # KinematicsConfigV1 has a field of that name
        cls.type_name = staticmethod(lambda: type_name)
    assert C.sizeof(cls) == size, (type_name, C.sizeof(cls), size)
    return cls


# --- the payload layouts (payload-layouts.md) ----------------------------------------------
ProcessConfigV2 = payload("rtc::ProcessConfigV2", 48, [
    ("name", C.c_char * 16), ("period_ns", u64), ("phase_ns", u64), ("priority", i32),
    ("cpu", i32), ("network_estop_config", u32), ("flags", u32)])
AxisConfigV2 = payload("rtc::AxisConfigV2", 240, [
    ("name", C.c_char * 16), ("unit", C.c_char * 8)] + [(n, f64) for n in (
        "min", "max", "vmax", "start", "following_error_limit", "in_position",
        "settle_velocity", "velocity_limit", "position_step_limit", "velocity_step_limit",
        "stop_deceleration", "kp", "ki", "kd", "kvff", "kaff", "integral_limit")] + [
    ("mode", i32), ("quick_stop_option", i32)] + [(n, f64) for n in (
        "drive_kp", "drive_ki", "drive_kd", "quick_stop_deceleration", "inertia", "viscous",
        "coulomb", "effort_limit", "encoder_resolution")])
KinematicsConfigV1 = payload("rtc::KinematicsConfigV1", 288, [
    ("type_name", C.c_char * 24), ("param_count", u32), ("coords", u32),
    ("params", u8 * (8 * 24)), ("coord_vmax", f64 * 8)])
CellConfigV6 = payload("rtc::CellConfigV6", 6904, [
    ("axes", u32), ("machine_substeps", u32), ("t_acc_s", f64),
    ("drive_command_timeout_ns", u64), ("setpoint_timeout_ns", u64),
    ("feedback_timeout_ns", u64), ("enable_timeout_ns", u64), ("settle_time_ns", u64),
    ("estop_stop_time_ns", u64), ("supervisor_timeout_ns", u64),
    ("propagate_estop", u32), ("propagate_external_estop", u32), ("process_count", u32),
    ("clock", u32), ("health", f64 * 9), ("process", ProcessConfigV2 * 16),
    ("axis", AxisConfigV2 * 8), ("inject", u8 * (4 * 24)),  # injections: not laid out here
    ("io_count", u32), ("reserved2", u32), ("io", u8 * (64 * 56)),  # IO: not laid out here
    ("kinematics", KinematicsConfigV1), ("modbus", u8 * 80)])  # Modbus: not laid out here
ServoStateV3 = payload("rtc::ServoStateV3", 584, [
    ("seq", u64), ("stamp_ns", u64), ("measured_stamp_ns", u64), ("setpoint_seq", u64),
    ("request_seq", u64), ("status", u32), ("axes", u32), ("power", u8),
    ("axis_power", u8 * 8), ("reserved", u8 * 7), ("settled_axes", u32), ("fault_code", u32),
    ("fault_axis", i32), ("reserved2", u32), ("fault_value", f64), ("fault_limit", f64),
    ("controlword", u16 * 8), ("statusword", u16 * 8)] + [(n, f64 * 8) for n in (
        "cmd_position", "cmd_velocity", "act_position", "act_velocity", "following_error",
        "effort")] + [("peak_program", u32), ("reserved3", u32),
                      ("peak_following_error", f64 * 8)])
SetpointV2 = payload("rtc::SetpointV2", 472, [
    ("seq", u64), ("stamp_ns", u64), ("motion_start_ns", u64), ("motion_end_ns", u64),
    ("motion_time_s", f64), ("theoretical_s", f64), ("segment_time_s", f64),
    ("program_id", u32), ("line", u32), ("state", u32), ("axes", u32), ("fault", u32),
    ("fault_line", u32), ("commands_taken", u64), ("queue_free", u32), ("starved", u32),
    ("path_speed", f64), ("control_seq", u64), ("speed_override", f64),
    ("program_speed", f64), ("hold", u32), ("hold_io", u32), ("space", u32), ("coords", u32),
    ("waited_s", f64)] + [(n, f64 * 8) for n in (
        "position", "velocity", "acceleration", "cartesian", "cartesian_velocity")])
MotionControlV2 = payload("rtc::MotionControlV2", 24, [
    ("seq", u64), ("kind", u32), ("reserved", u32), ("value", f64)])
TrajgenHandoverV2 = payload("rtc::TrajgenHandoverV2", 304, [
    ("stamp_ns", u64), ("command_seq", u64), ("motion_start_ns", u64), ("program_id", u32),
    ("line", u32), ("valid", u32), ("starved", u32), ("local_s", f64), ("lost_s", f64),
    ("theoretical_s", f64), ("t1_s", f64), ("t_acc_s", f64), ("a", f64 * 8), ("b", f64 * 8),
    ("c", f64 * 8), ("speed_override", f64), ("program_speed", f64), ("waited_s", f64),
    ("space", u32), ("reserved", u32)])
FieldbusImageV1 = payload("rtc::FieldbusImageV1", 104, [
    ("seq", u64), ("written_ns", u64), ("measured_ns", u64), ("source_seq", u64),
    ("len", u32), ("axes", u32), ("image", u8 * 64)])
EventV1 = payload("rtc::EventV1", 112, [
    ("seq", u64), ("stamp_ns", u64), ("value", f64), ("limit", f64), ("source", u32),
    ("severity", u32), ("code", u32), ("axis", i32), ("text", C.c_char * 64)])
EstopV1 = payload("rtc::EstopV1", 88, [
    ("stamp_ns", u64), ("kind", u32), ("origin", u32), ("source", u32), ("code", u32),
    ("reason", C.c_char * 64)])
HostStateV1 = payload("rtc::HostStateV1", 128, [
    ("stamp_ns", u64), ("beat", u64), ("resets", u64), ("pid", u32), ("estop", u32),
    ("cause", EstopV1), ("handover", u32), ("reserved", u32)])
CycleStatsV1 = payload("rtc::CycleStatsV1", 72, [(n, u64) for n in (
    "period_ns", "cycles", "overruns", "skipped", "wakeup_latency_ns",
    "max_wakeup_latency_ns", "exec_ns", "max_exec_ns")] + [("overrun_flag", u32),
                                                           ("reserved", u32)])
DetectorV1 = payload("rtc::DetectorV1", 16, [("level", f32), ("limit", f32), ("total", u64)])
ProcessStatusV2 = payload("rtc::ProcessStatusV2", 184, [
    ("pid", u32), ("index", u32), ("state", u32), ("policy", u32), ("priority", i32),
    ("cpu", i32), ("rt_flags", u32), ("fault", u32), ("stamp_ns", u64),
    ("stats", CycleStatsV1), ("name", C.c_char * 16), ("pending_sequence", DetectorV1),
    ("transport", DetectorV1), ("thread_offset", DetectorV1), ("estop", u32),
    ("reserved", u32)])
# The virtual clock's (virtual-time.md, the field meanings in shm-schema/src/clock.rs).
ClockGrantV1 = payload("rtc::ClockGrantV1", 24, [
    ("now_ns", u64), ("seq", u64), ("pid", u32), ("reserved", u32)])
ClockReportV1 = payload("rtc::ClockReportV1", 32, [
    ("next_ns", u64), ("seq", u64), ("pid", u32), ("index", u32), ("kind", u32),
    ("reserved", u32)])
HIST_BUCKETS = 3712
LatencyHistogramV1 = payload("rtc::LatencyHistogramV1", 29744, [
    ("count", u64), ("sum_ns", u64), ("min_ns", u64), ("max_ns", u64), ("overflows", u64),
    ("stamp_ns", u64), ("buckets", u64 * HIST_BUCKETS)])

# --- the values of their fields ------------------------------------------------------------
CYCLIC, STOPPING = 1, 2                              # ProcessStatusV2.state
LATCHED, REACTING, SAFE, RAISED = 1, 2, 4, 8        # ProcessStatusV2.estop
TRIGGER, RESET = 1, 2                                # EstopV1.kind
DEVICE, EXTERNAL, HOST = 1, 2, 3                     # EstopV1.origin
IGNORE = 2                                           # network_estop_config
IDLE, MOVING, DONE, FAULT = 0, 1, 2, 3               # SetpointV2.state
FAULT_ESTOP, FAULT_ABORTED = 6, 7                    # SetpointV2.fault (trajgen_fault)
PAUSE, RESUME, ABORT = 1, 2, 3                       # MotionControlV2.kind
ENABLED = 2                                          # ServoStateV3.power
# ServoStateV3.status bits (docs/fieldbus.md, register `servo_status`)
ST_ENABLED, ST_NO_SETPOINT, ST_STALE, ST_JUMP, ST_FAULT = 1, 2, 4, 8, 16
EV_ESTOP_RAISED, EV_ESTOP_SAFE, EV_SUPERVISOR_LOST = 601, 603, 605  # EventV1.code
INFO, WARNING, ERROR = 0, 1, 2                       # EventV1.severity
WALL, VIRTUAL = 0, 1                                 # CellConfigV6.clock (shm-schema CellClock)
CLOCK_JOIN, CLOCK_DONE, CLOCK_LEAVE = 1, 2, 3        # ClockReportV1.kind (ClockReport)

# --- the services (services.md) ------------------------------------------------------------
# (publishers, subscribers, history, subscriber buffer, nodes): the table of services.md, for
# the services these examples open; `status` and `histogram` are the rows of `<i>/<name>/…`.
QOS = {"cell/config": (1, 24, 1, 1024, 40), "servo/state": (2, 8, 0, 1024, 40),
       "trajgen/setpoint": (2, 8, 0, 1024, 40), "trajgen/control": (8, 8, 0, 1024, 40),
       "trajgen/handover": (2, 8, 1, 1024, 40), "iobridge/output": (2, 8, 0, 1024, 40),
       "events": (32, 16, 0, 1024, 40), "estop": (32, 24, 0, 1024, 40),
       "host/state": (1, 24, 1, 1024, 32), "status": (2, 8, 0, 1024, 40),
       "histogram": (2, 8, 1, 2, 40), "clock/grant": (1, 24, 1, 2, 32),
       "clock/report": (32, 2, 0, 1024, 40)}

# --- the cell's time (virtual-time.md: "Everything that reads time reads the clock") --------
wall_ns = time.monotonic_ns  # CLOCK_MONOTONIC: what is measured on the CPU (execution times)
_virtual_now = None          # on the virtual clock: the instant it last granted this process


def now_ns():
    """The cell's time (ns): CLOCK_MONOTONIC, or on the virtual clock the instant it granted
    (the cycle's deadline): stamps of statuses, events, images, the heartbeat's watch."""
    return wall_ns() if _virtual_now is None else _virtual_now


def set_virtual_now(t):
    """The cell's time is t from now on (the virtual clock's instant)."""
    global _virtual_now
    _virtual_now = t


def logger(prefix=None):
    """A function that prints its arguments to stderr, after `prefix:` if given."""
    head = (f"{prefix}:",) if prefix else ()

    def log(*a):
        print(*head, *a, file=sys.stderr, flush=True)
    return log


# --- the latency histogram (services.md: exact below 256 ns, then 128 buckets per power of
# two up to 2^35 ns: 256 + 27 * 128 = 3712 buckets) ----------------------------------------
def bucket_of(v):
    if v < 256:
        return v
    e = v.bit_length() - 1          # 2^e <= v < 2^(e+1), e >= 8
    if e >= 35:
        return None                 # beyond the last bucket: an overflow
    return 256 + (e - 8) * 128 + ((v >> (e - 7)) & 127)


class Histogram:
    def __init__(self):
        self.h = LatencyHistogramV1()
        self.h.min_ns = 0

    def add(self, v):
        h, v = self.h, max(0, int(v))
        h.min_ns = v if h.count == 0 else min(h.min_ns, v)
        h.max_ns = max(h.max_ns, v)
        h.count += 1
        h.sum_ns += v
        b = bucket_of(v)
        if b is None:
            h.overflows += 1
        else:
            h.buckets[b] += 1


# --- a process of the cell -------------------------------------------------------------------
class Process:
    """A process of the cell: its iceoryx2 node and ports, its place in the cell configuration,
    its real-time set-up, its events and the e-stop as it sees it. A role subclasses it with
    `setup()` (0 to run, None or an exit status not to) and `run()` (the exit status)."""

    def __init__(self, instance, name, log=None):
        self.instance, self.name, self.stop, self.stop_since = instance, name, False, 0
        self.log = log or logger()
        cfg = iox2.config.default()  # not global_config(): no iceoryx2.toml is read
        cfg.global_cfg.prefix = iox2.FileName.new(f"iox2_{instance}_")
        cfg.global_cfg.root_path = iox2.Path.new(f"/tmp/iceoryx2/{instance}/")
        # SIGTERM is ours (signal module); iceoryx2 must not install its own handler.
        self.node = (iox2.NodeBuilder.new().config(cfg).name(iox2.NodeName.new(name))
                     .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
                     .create(iox2.ServiceType.Ipc))
        self.ports = []
        self.clock = None  # VirtualClock in a cell on the virtual clock (Process.join)

    def request_stop(self):
        """SIGTERM (or SIGINT): leave, safely; stop_since is when leaving began."""
        if not self.stop:
            self.stop_since = now_ns()
        self.stop = True

    # --- services and ports ---------------------------------------------------------------
    def service(self, name, T, qos_key=None):
        pubs, subs, hist, buf, nodes = QOS[qos_key or name]
        return (self.node.service_builder(iox2.ServiceName.new(f"{self.instance}/{name}"))
                .publish_subscribe(T).max_publishers(pubs).max_subscribers(subs)
                .history_size(hist).subscriber_max_buffer_size(buf).max_nodes(nodes)
                .enable_safe_overflow(True).open_or_create())

    def sub(self, name, T, buffer=None):
        b = self.service(name, T).subscriber_builder()
        port = (b.buffer_size(buffer) if buffer else b).create()
        self.ports.append(port)
        return port, T

    def pub(self, name, T, qos_key=None):
        port = self.service(name, T, qos_key).publisher_builder().create()
        self.ports.append(port)
        return port

    @staticmethod
    def take(sub):
        """Every waiting sample, oldest first, copied out (the sample is released at once)."""
        port, T = sub
        out = []
        while (s := port.receive()) is not None:
            out.append(T.from_buffer_copy(C.string_at(s.payload_ptr, C.sizeof(T))))
            s.delete()
        return out

    def close(self):
        if self.clock is not None:  # virtual-time.md 6: a process that leaves says so
            self.clock.leave()
        for p in reversed(self.ports):
            try:
                p.delete()
            except Exception:
                pass
        self.ports.clear()
        self.node = None  # the node goes with its last reference

    # --- setup ------------------------------------------------------------------------------
    def join(self):
        """Waits (10 s at most) for the cell configuration (self.cell) and finds this process in
        it (self.index, self.me); in a cell on the virtual clock (`clock` = 1) opens its side of
        the clock (self.clock) and reads where the clock stands: 0, 1 if it has no process of
        this name (or the clock is not there), None if no configuration came (or the process
        was stopped first)."""
        config_sub = self.sub("cell/config", CellConfigV6)
        deadline = now_ns() + 10_000_000_000
        while not (got := self.take(config_sub)):
            if self.stop or now_ns() > deadline:
                return None
            time.sleep(0.005)
        cell = self.cell = got[-1]
        self.names = [cell.process[i].name.decode() for i in range(cell.process_count)]
        if self.name not in self.names:
            self.log(f"{self.name}: no [[process]] of that name in the cell configuration "
                     f"(it has: {', '.join(self.names)})")
            return 1
        self.index = self.names.index(self.name)
        self.me = self.cell.process[self.index]
        if cell.clock == VIRTUAL:
            self.clock = VirtualClock(self)
            if not self.clock.stands():
                self.log(f"{self.name}: the cell runs on the virtual clock but nothing is on "
                         f"{self.instance}/clock/grant")
                return None if self.stop else 1
        elif cell.clock != WALL:
            self.log(f"{self.name}: unknown clock {cell.clock} in the cell configuration")
            return 1
        return 0

    def open_cell_ports(self, histograms=False):
        """The ports every process has: the e-stop (`estop`, `host/state`), its status (and,
        if asked, its latency and execution-time histograms), its events."""
        self.estop_sub = self.sub("estop", EstopV1, buffer=64)
        self.host_sub = self.sub("host/state", HostStateV1)
        self.status_pub = self.pub(f"{self.name}/status", ProcessStatusV2, "status")
        if histograms:
            self.latency_pub = self.pub(f"{self.name}/latency", LatencyHistogramV1, "histogram")
            self.exec_pub = self.pub(f"{self.name}/exec_time", LatencyHistogramV1, "histogram")
        self.estop_pub = self.pub("estop", EstopV1)
        self.event_pub = self.pub("events", EventV1)

    def realtime(self):
        """The policy, priority and CPU of its [[process]], as far as the host grants them."""
        self.policy, self.priority, self.cpu, self.rt_flags = 0, 0, -1, 0
        try:
            if self.me.priority > 0:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.me.priority))
                self.policy, self.priority, self.rt_flags = 1, self.me.priority, 1
        except OSError as e:
            self.log(f"{self.name}: SCHED_FIFO refused ({e}), running under SCHED_OTHER")
        try:
            if self.me.cpu >= 0:
                os.sched_setaffinity(0, {self.me.cpu})
                self.cpu, self.rt_flags = self.me.cpu, self.rt_flags | 8
        except OSError as e:
            self.log(f"{self.name}: cannot pin to CPU {self.me.cpu} ({e})")

    # --- events and the e-stop ------------------------------------------------------------
    def watch(self):
        """From now on: no e-stop seen, no event sent, the supervisor's heartbeat watched."""
        self.event_seq = 0
        self.latched = self.reacting = self.raised = self.safe_reported = False
        self.cause, self.resets_seen, self.beat, self.exit_code = None, 0, None, 0
        self.host = None
        self.beat_changed = now_ns()

    def event(self, code, severity, text, value=0.0, limit=0.0):
        self.event_seq += 1
        self.event_pub.send_copy(EventV1(self.event_seq, now_ns(), value, limit, self.index,
                                         severity, code, -1, text.encode()[:64]))

    def concerns_me(self, rec):
        if self.me.network_estop_config == IGNORE:
            return False
        if rec.source == self.index or rec.origin == HOST:
            return True
        if rec.origin in (DEVICE, EXTERNAL) and self.cell.propagate_estop:
            return True
        return rec.origin == EXTERNAL and bool(self.cell.propagate_external_estop)

    def trigger(self, rec):
        if not self.latched:
            self.latched, self.cause = True, rec
        if self.concerns_me(rec):
            self.reacting = True

    def clear(self, resets):
        self.resets_seen = resets
        self.latched = self.reacting = self.raised = self.safe_reported = False
        self.cause = None

    def raise_estop(self, origin, code, reason):
        rec = EstopV1(now_ns(), TRIGGER, origin, self.index, code, reason.encode()[:64])
        self.estop_pub.send_copy(rec)
        if not self.latched:
            self.event(EV_ESTOP_RAISED, WARNING, reason, value=origin, limit=code)
        self.raised = True
        self.trigger(rec)
        self.reacting = True

    def poll_estop(self, now):
        """The e-stops and resets since the last cycle, the supervisor's state (self.host);
        a supervisor lost raises a host e-stop and makes the process leave with status 1."""
        for rec in self.take(self.estop_sub):
            if rec.kind == TRIGGER:
                self.trigger(rec)
            elif rec.kind == RESET and rec.code > self.resets_seen:
                self.clear(rec.code)
        hosts = self.take(self.host_sub)
        if hosts:
            h = self.host = hosts[-1]
            if h.beat != self.beat:
                self.beat, self.beat_changed = h.beat, now
            if h.resets > self.resets_seen:
                self.clear(h.resets)
            if h.estop == 1 and not self.latched:
                self.trigger(h.cause)
        if self.exit_code == 0 and now - self.beat_changed > self.cell.supervisor_timeout_ns:
            self.supervisor_lost(now)

    def supervisor_lost(self, now):
        """Raises a host e-stop and makes the process leave with status 1 (services.md 6)."""
        self.event(EV_SUPERVISOR_LOST, ERROR, "supervisor lost")
        self.raise_estop(HOST, EV_SUPERVISOR_LOST, f"{self.name}: supervisor lost")
        self.exit_code = 1
        self.stop_since = self.stop_since or now

    def report_safe(self, now):
        """The event of a complete e-stop reaction, once per e-stop (call it when it is)."""
        if self.reacting and self.latched and not self.safe_reported:
            self.safe_reported = True
            self.event(EV_ESTOP_SAFE, INFO, "e-stop reaction complete",
                       value=(now - self.cause.stamp_ns) / 1e9)

    def estop_bits(self, leaving, safe):
        """ProcessStatusV2.estop; safe: the reaction (to an e-stop, or to leaving) is complete."""
        reacting = self.reacting or leaving
        return ((LATCHED if self.latched else 0) | (RAISED if self.raised else 0) |
                (REACTING if reacting else 0) | (SAFE if reacting and safe else 0))


class VirtualClock:
    """A process' side of the cell's virtual clock (virtual-time.md, "How it works" 2, 3 and 6,
    and "A process in another language"). The clock's wake-up (`<i>/clock/go/<pid>`) and the
    notification after a report are the cell's semaphore events, which a stock iceoryx2
    binding cannot wait on (services.md, "The iceoryx2 event service"), so this side polls
    `<i>/clock/grant` and publishes its reports without notifying (the clock looks for them at
    least every millisecond): slower, never different."""

    POLL_S = 150e-6  # between two looks at the grants: a grant is seen within about 0.2 ms
                     # (the clock itself looks for an unnotified report every millisecond)

    def __init__(self, proc):
        """Opens `<i>/clock/grant` and `<i>/clock/report` (services.md, the table; the
        subscriber's buffer is the service's 2)."""
        self.proc, self.pid, self.parent = proc, os.getpid(), os.getppid()
        self.grants = proc.sub("clock/grant", ClockGrantV1, buffer=2)
        self.report_pub = proc.pub("clock/report", ClockReportV1)
        self.newest = None  # the newest grant read so far (reading takes it off the buffer)
        self.seq = 0        # the grant of the last cycle it ran
        self.joined = self.owes = self.gone = False

    def poll(self):
        """The newest grant, from every one that came since the last look."""
        got = self.proc.take(self.grants)
        if got:
            self.newest = got[-1]
        return self.newest

    def stands(self):
        """Reads where the clock stands (history 1: a grant with `pid` 0 says it; it comes once
        the supervisor's publisher sees the new subscriber, so it is waited for, 10 s at most
        as the clock waits for a join) and turns the process to that instant: the cell's
        time from now on. False if none came (or the process was stopped first)."""
        deadline = wall_ns() + 10_000_000_000
        while self.poll() is None:
            if self.proc.stop or wall_ns() > deadline:
                return False
            time.sleep(0.001)
        # Grants to this process are numbered after the one it read.
        self.seq = self.newest.seq
        set_virtual_now(self.newest.now_ns)
        return True

    def report(self, kind, next_ns):
        """A ClockReportV1 on `<i>/clock/report`: its pid, its index in the process table
        (which orders processes due at the same instant), the grant it ends (0 for a join)."""
        seq = 0 if kind == CLOCK_JOIN else self.seq
        self.report_pub.send_copy(ClockReportV1(next_ns, seq, self.pid, self.proc.index, kind))

    def join(self, first_ns):
        """Takes part from the deadline first_ns on (virtual-time.md 2)."""
        self.report(CLOCK_JOIN, first_ns)
        self.joined = True

    def wait(self, next_ns):
        """Reports the granted cycle done (if one was granted) with the next deadline next_ns,
        then waits for the clock's next grant of this process (the newest grant has its pid
        and a `seq` above the last one it ran, virtual-time.md 3): its instant, the cell's time
        from now on. If the supervisor is gone (its clock with it; SIGTERM is the process'
        parent-death signal, services.md 1), no grant will ever come: self.gone, and the
        process runs its last cycles on its own time, one deadline after the other."""
        if self.owes:
            self.report(CLOCK_DONE, next_ns)
            self.owes = False
        while not self.gone:
            g = self.poll()
            if g is not None and g.pid == self.pid and g.seq > self.seq:
                self.seq, self.owes = g.seq, True
                set_virtual_now(g.now_ns)
                return g.now_ns
            if self.proc.stop and os.getppid() != self.parent:
                self.gone = True
                break
            time.sleep(self.POLL_S)
        set_virtual_now(next_ns)
        return next_ns

    def leave(self):
        """Leaves the clock, ending a granted cycle if one was (virtual-time.md 6): the
        process exits. Once."""
        if self.joined:
            self.report(CLOCK_LEAVE, 0)
        self.joined = self.owes = False


class Cycle:
    """A process' cycle: its deadlines (period and phase of its [[process]]), its status
    (ProcessStatusV2, published every cycle) and, if asked, its latency and execution-time
    histograms (published when the process says). In a cell on the virtual clock it waits for
    the clock's grants (VirtualClock) instead of sleeping: every wake-up is at its deadline,
    the execution time is still measured on the CPU, and no cycle overruns (virtual-time.md).
    """

    def __init__(self, proc, histograms=False):
        self.proc, self.period = proc, proc.me.period_ns
        st = self.status = ProcessStatusV2(
            pid=os.getpid(), index=proc.index, policy=proc.policy, priority=proc.priority,
            cpu=proc.cpu, rt_flags=proc.rt_flags, name=proc.name.encode())
        st.stats.period_ns = self.period
        self.latency, self.exec_time = (Histogram(), Histogram()) if histograms else (None, None)
        phase = proc.me.phase_ns
        self.deadline = ((now_ns() - phase) // self.period + 1) * self.period + phase
        # On the virtual clock: the first deadline as on the wall clock (from where the clock
        # stands), then the join (virtual-time.md 2).
        self.clock = proc.clock
        if self.clock is not None:
            self.clock.join(self.deadline)

    def wait(self):
        """Sleeps to the deadline (on the virtual clock: waits for its grant), then reads the
        e-stop (Process.poll_estop): the actual wake-up time, and whether the process leaves
        (SIGTERM, or the supervisor lost)."""
        if self.clock is not None:
            self.clock.wait(self.deadline)
        else:
            delay = self.deadline - now_ns()
            if delay > 0:
                time.sleep(delay / 1e9)
        wake = self.wake = now_ns()
        # The execution time is measured on the CPU whatever the clock (virtual-time.md).
        self.wake_wall = wake if self.clock is None else wall_ns()
        self.proc.poll_estop(wake)
        if self.clock is not None and self.clock.gone and self.proc.exit_code == 0:
            self.proc.supervisor_lost(wake)
        return wake, self.proc.stop or self.proc.exit_code != 0

    def publish_status(self, leaving, safe):
        """The status of this cycle, whose work ends now (see Process.estop_bits)."""
        st, wake = self.status, self.wake
        st.state = STOPPING if leaving else CYCLIC
        st.estop = self.proc.estop_bits(leaving, safe)
        st.stamp_ns = wake
        s = st.stats
        s.cycles += 1
        s.wakeup_latency_ns = max(0, wake - self.deadline)
        s.max_wakeup_latency_ns = max(s.max_wakeup_latency_ns, s.wakeup_latency_ns)
        if self.latency is not None:
            self.latency.add(s.wakeup_latency_ns)
        s.exec_ns = wall_ns() - self.wake_wall
        s.max_exec_ns = max(s.max_exec_ns, s.exec_ns)
        if self.exec_time is not None:
            self.exec_time.add(s.exec_ns)
        self.proc.status_pub.send_copy(st)

    def publish_histograms(self):
        for pub, h in ((self.proc.latency_pub, self.latency),
                       (self.proc.exec_pub, self.exec_time)):
            h.h.stamp_ns = self.wake
            pub.send_copy(h.h)

    def next(self):
        """On to the next deadline; after an overrun, the next one still in the future."""
        s = self.status.stats
        self.deadline += self.period
        if self.clock is not None:  # on the virtual clock no cycle is late (virtual-time.md)
            return
        end = now_ns()
        s.overrun_flag = int(end > self.deadline)
        if end > self.deadline:
            s.overruns += 1
            missed = (end - self.deadline) // self.period + 1
            s.skipped += missed
            self.deadline += missed * self.period


# --- the command line and the process' life ------------------------------------------------
def arguments(doc, name):
    """The command line of a process (`--instance I --name N`), described by doc's first line;
    the role adds its own options."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--instance", default="gantry")
    ap.add_argument("--name", default=name)
    return ap


def parse(ap):
    """The arguments, the instance's and the process' names checked (exit status 2 if bad)."""
    args = ap.parse_args()  # exit status 2 on a bad argument
    if not re.fullmatch(r"[A-Za-z0-9_-]{1,32}", args.instance):
        ap.error(f"bad instance name {args.instance!r}")
    if not re.fullmatch(r"[a-z][a-z0-9_-]{0,14}", args.name):
        ap.error(f"bad process name {args.name!r}")
    return args


def serve(proc):
    """Runs proc as the supervisor expects: SIGTERM (or SIGINT) asks it to leave; setup(),
    then run(); its ports closed whatever happens. The exit status."""
    def on_term(signum, frame):
        proc.request_stop()
    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, on_term)
    try:
        rc = proc.setup()
        if rc is None:
            rc = 0 if proc.stop else 1
        elif rc == 0:
            rc = proc.run()
    finally:
        proc.close()
    return rc
