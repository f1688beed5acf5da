#!/usr/bin/env python3
"""A Python iobridge for the cell, written from docs/services.md and docs/payload-layouts.md.

Every cycle: read the e-stop (I/estop, I/host/state), copy servo's newest measured position
into the fieldbus image (I/iobridge/output) and publish the status (I/N/status).
Run by the supervisor as `python3 iobridge.py --instance {instance} --name {name}`.
Needs `pip install iceoryx2==0.10.0`.
"""
import argparse
import ctypes as C
import math
import os
import re
import signal
import struct
import sys
import time

import iceoryx2 as iox2

u8, u16, u32, u64 = C.c_uint8, C.c_uint16, C.c_uint32, C.c_uint64
i32, f32, f64 = C.c_int32, C.c_float, C.c_double


def payload(type_name, size, fields):
    """A ctypes struct with its iceoryx2 type name, checked against payload-layouts.md."""
    cls = type(type_name[5:], (C.Structure,), {"_fields_": fields})
    cls.type_name = staticmethod(lambda: type_name)
    assert C.sizeof(cls) == size, (type_name, C.sizeof(cls), size)
    return cls


ProcessConfigV2 = payload("rtc::ProcessConfigV2", 48, [
    ("name", C.c_char * 16), ("period_ns", u64), ("phase_ns", u64), ("priority", i32),
    ("cpu", i32), ("network_estop_config", u32), ("flags", u32)])
CellConfigV6 = payload("rtc::CellConfigV6", 6904, [
    ("axes", u32), ("machine_substeps", u32), ("t_acc_s", f64),
    ("drive_command_timeout_ns", u64), ("setpoint_timeout_ns", u64),
    ("feedback_timeout_ns", u64), ("enable_timeout_ns", u64), ("settle_time_ns", u64),
    ("estop_stop_time_ns", u64), ("supervisor_timeout_ns", u64),
    ("propagate_estop", u32), ("propagate_external_estop", u32), ("process_count", u32),
    ("reserved", u32), ("health", f64 * 9), ("process", ProcessConfigV2 * 16),
    ("axis", u8 * (8 * 240)), ("inject", u8 * (4 * 24)),  # axes/faults unused here
    ("io_count", u32), ("reserved2", u32), ("io", u8 * (64 * 56)),  # IO unused here
    ("kinematics", u8 * 288), ("modbus", u8 * 80)])  # unused here
ServoStateV3 = payload("rtc::ServoStateV3", 584, [
    ("seq", u64), ("stamp_ns", u64), ("measured_stamp_ns", u64), ("setpoint_seq", u64),
    ("request_seq", u64), ("status", u32), ("axes", u32), ("power", u8),
    ("axis_power", u8 * 8), ("reserved", u8 * 7), ("settled_axes", u32), ("fault_code", u32),
    ("fault_axis", i32), ("reserved2", u32), ("fault_value", f64), ("fault_limit", f64),
    ("controlword", u16 * 8), ("statusword", u16 * 8)] + [(n, f64 * 8) for n in (
        "cmd_position", "cmd_velocity", "act_position", "act_velocity", "following_error",
        "effort")] + [("peak_program", u32), ("reserved3", u32),
                      ("peak_following_error", f64 * 8)])
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

CYCLIC, STOPPING = 1, 2                              # ProcessStatusV2.state
LATCHED, REACTING, SAFE, RAISED = 1, 2, 4, 8        # ProcessStatusV2.estop
TRIGGER, RESET = 1, 2                                # EstopV1.kind
DEVICE, EXTERNAL, HOST = 1, 2, 3                     # EstopV1.origin
IGNORE = 2                                           # network_estop_config
EV_ESTOP_RAISED, EV_ESTOP_SAFE, EV_SUPERVISOR_LOST = 601, 603, 605
INFO, WARNING, ERROR = 0, 1, 2
# (publishers, subscribers, history, subscriber buffer, nodes): the table of services.md
QOS = {"cell/config": (1, 24, 1, 1024, 40), "servo/state": (2, 8, 0, 1024, 40),
       "iobridge/output": (2, 8, 0, 1024, 40), "events": (32, 16, 0, 1024, 40),
       "estop": (32, 24, 0, 1024, 40), "host/state": (1, 24, 1, 1024, 32),
       "status": (2, 8, 0, 1024, 40)}

now_ns = time.monotonic_ns  # CLOCK_MONOTONIC


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


class Bridge:
    def __init__(self, instance, name):
        self.instance, self.name, self.stop = instance, name, False
        cfg = iox2.config.default()  # not global_config(): no iceoryx2.toml is read
        cfg.global_cfg.prefix = iox2.FileName.new(f"iox2_{instance}_")
        cfg.global_cfg.root_path = iox2.Path.new(f"/tmp/iceoryx2/{instance}/")
        # SIGTERM is ours (signal module); iceoryx2 must not install its own handler.
        self.node = (iox2.NodeBuilder.new().config(cfg).name(iox2.NodeName.new(name))
                     .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
                     .create(iox2.ServiceType.Ipc))
        self.ports = []

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
        for p in self.ports:
            p.delete()
        self.ports.clear()
        self.node = None  # the node goes with its last reference

    # --- setup -------------------------------------------------------------------------
    def setup(self):
        config_sub = self.sub("cell/config", CellConfigV6)
        deadline = now_ns() + 10_000_000_000
        while not (got := self.take(config_sub)):
            if self.stop or now_ns() > deadline:
                return None
            time.sleep(0.005)
        cell = self.cell = got[-1]
        names = [cell.process[i].name.decode() for i in range(cell.process_count)]
        if self.name not in names:
            print(f"{self.name}: no [[process]] of that name in the cell configuration "
                  f"(it has: {', '.join(names)})", file=sys.stderr)
            return 1
        self.index = names.index(self.name)
        self.me = cell.process[self.index]
        self.servo_sub = self.sub("servo/state", ServoStateV3)
        self.estop_sub = self.sub("estop", EstopV1, buffer=64)
        self.host_sub = self.sub("host/state", HostStateV1)
        self.image_pub = self.pub("iobridge/output", FieldbusImageV1)
        self.status_pub = self.pub(f"{self.name}/status", ProcessStatusV2, "status")
        self.estop_pub = self.pub("estop", EstopV1)
        self.event_pub = self.pub("events", EventV1)
        self.policy, self.priority, self.cpu, self.rt_flags = 0, 0, -1, 0
        try:
            if self.me.priority > 0:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.me.priority))
                self.policy, self.priority, self.rt_flags = 1, self.me.priority, 1
        except OSError as e:
            print(f"{self.name}: SCHED_FIFO refused ({e}), running under SCHED_OTHER",
                  file=sys.stderr)
        try:
            if self.me.cpu >= 0:
                os.sched_setaffinity(0, {self.me.cpu})
                self.cpu, self.rt_flags = self.me.cpu, self.rt_flags | 8
        except OSError as e:
            print(f"{self.name}: cannot pin to CPU {self.me.cpu} ({e})", file=sys.stderr)
        return 0

    # --- events and the e-stop ------------------------------------------------------------
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
        for rec in self.take(self.estop_sub):
            if rec.kind == TRIGGER:
                self.trigger(rec)
            elif rec.kind == RESET and rec.code > self.resets_seen:
                self.clear(rec.code)
        hosts = self.take(self.host_sub)
        if hosts:
            h = hosts[-1]
            if h.beat != self.beat:
                self.beat, self.beat_changed = h.beat, now
            if h.resets > self.resets_seen:
                self.clear(h.resets)
            if h.estop == 1 and not self.latched:
                self.trigger(h.cause)
        if self.exit_code == 0 and now - self.beat_changed > self.cell.supervisor_timeout_ns:
            self.event(EV_SUPERVISOR_LOST, ERROR, "supervisor lost")
            self.raise_estop(HOST, EV_SUPERVISOR_LOST, f"{self.name}: supervisor lost")
            self.exit_code = 1

    # --- the cycle ----------------------------------------------------------------------
    def run(self):
        period, phase = self.me.period_ns, self.me.phase_ns
        self.event_seq = self.image_seq = 0
        self.latched = self.reacting = self.raised = self.safe_reported = False
        self.cause, self.resets_seen, self.beat, self.exit_code = None, 0, None, 0
        self.beat_changed = now_ns()
        newest = None
        st = ProcessStatusV2(pid=os.getpid(), index=self.index, policy=self.policy,
                             priority=self.priority, cpu=self.cpu, rt_flags=self.rt_flags,
                             name=self.name.encode())
        st.stats.period_ns = period
        deadline = ((now_ns() - phase) // period + 1) * period + phase
        while True:
            delay = deadline - now_ns()
            if delay > 0:
                time.sleep(delay / 1e9)
            wake = now_ns()
            self.poll_estop(wake)
            leaving = self.stop or self.exit_code != 0
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
            if self.reacting and self.latched and not self.safe_reported:
                self.safe_reported = True
                self.event(EV_ESTOP_SAFE, INFO, "e-stop reaction complete",
                           value=(wake - self.cause.stamp_ns) / 1e9)
            st.state = STOPPING if leaving else CYCLIC
            st.estop = ((LATCHED if self.latched else 0) | (RAISED if self.raised else 0) |
                        (REACTING | SAFE if self.reacting or leaving else 0))
            st.stamp_ns = wake
            s = st.stats
            s.cycles += 1
            s.wakeup_latency_ns = max(0, wake - deadline)
            s.max_wakeup_latency_ns = max(s.max_wakeup_latency_ns, s.wakeup_latency_ns)
            s.exec_ns = now_ns() - wake
            s.max_exec_ns = max(s.max_exec_ns, s.exec_ns)
            self.status_pub.send_copy(st)
            if leaving:  # safe at once: nothing to bring to rest
                return self.exit_code
            deadline += period
            end = now_ns()
            s.overrun_flag = int(end > deadline)
            if end > deadline:
                s.overruns += 1
                missed = (end - deadline) // period + 1
                s.skipped += missed
                deadline += missed * period


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--instance", default="gantry")
    ap.add_argument("--name", default="iobridge")
    args = ap.parse_args()  # exit status 2 on a bad argument
    if not re.fullmatch(r"[A-Za-z0-9_-]{1,32}", args.instance):
        ap.error(f"bad instance name {args.instance!r}")
    if not re.fullmatch(r"[a-z][a-z0-9_-]{0,14}", args.name):
        ap.error(f"bad process name {args.name!r}")
    bridge = Bridge(args.instance, args.name)

    def on_term(signum, frame):
        bridge.stop = True
    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, on_term)
    try:
        rc = bridge.setup()
        if rc is None:
            rc = 0 if bridge.stop else 1
        elif rc == 0:
            rc = bridge.run()
    finally:
        bridge.close()
    return rc


if __name__ == "__main__":
    sys.exit(main())
