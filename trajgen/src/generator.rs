//! The trajectory generator of seed 003 §2, driven by real elapsed time.
//!
//! Every reference is computed from `CLOCK_MONOTONIC` time since the start of the motion,
//! never from a cycle count: a late cycle evaluates the trajectory at the time it actually
//! runs, so it shortens nothing and lengthens nothing (seed 003's first fix). Segment
//! boundaries are exact: a segment's local time 0 is the previous one's plus its `T1`, and
//! `A` is the previous segment evaluated at exactly `T1 - t_acc`, however late the cycle that
//! notices the transition runs (several transitions are taken at once after a long stall).
//!
//! A pause, a resume or an abort ([`Generator::control`]) scales the rate at which the path
//! is travelled, never the path: the path time runs at `speed` times real time, and `speed`
//! ramps linearly between 1 and 0 within `t_acc` (the blend's own acceleration time). At
//! speed 1 the path time is real elapsed time minus the time lost to pauses, exactly.
//!
//! Commands are taken into a fixed queue as they arrive (validated one by one); the next one
//! is read only when the motion reaches `t = T1 - t_acc`. With the queue empty at that moment
//! the axes stop exactly on the current target and wait (counted in `starved`); `END` stops
//! them on the last target and ends the motion.

use crate::blend::{Axes, Segment};
use motion_program::segment_time;
use shm_schema::motion::trajgen_fault as fault;
use shm_schema::{
    CommandKind, ControlKind, MAX_AXES, MotionCommandV1, MotionControlV1, MotionState, SetpointV1,
    TrajgenHandoverV1,
};

/// Places in the command queue.
pub const QUEUE_CAP: usize = 256;

/// Per-cell parameters of the generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Axes in use.
    pub axes: usize,
    /// Largest velocity per axis (unit/s).
    pub vmax: [f64; MAX_AXES],
    /// Lowest position per axis.
    pub min: [f64; MAX_AXES],
    /// Highest position per axis.
    pub max: [f64; MAX_AXES],
    /// Acceleration time (s).
    pub t_acc: f64,
}

impl Params {
    /// Parameters from the cell configuration.
    pub fn from_cell(cell: &shm_schema::CellConfigV4) -> Self {
        let mut p = Params {
            axes: cell.axes as usize,
            vmax: [1.0; MAX_AXES],
            min: [0.0; MAX_AXES],
            max: [0.0; MAX_AXES],
            t_acc: cell.t_acc_s,
        };
        for (i, a) in cell.axes().iter().enumerate() {
            p.vmax[i] = a.vmax;
            p.min[i] = a.min;
            p.max[i] = a.max;
        }
        p
    }
}

/// A fixed-capacity FIFO of commands (no allocation after construction).
#[derive(Clone, Debug)]
struct Queue {
    items: [MotionCommandV1; QUEUE_CAP],
    head: usize,
    len: usize,
}

impl Queue {
    fn new() -> Self {
        Self {
            items: [MotionCommandV1::default(); QUEUE_CAP],
            head: 0,
            len: 0,
        }
    }
    fn push(&mut self, c: MotionCommandV1) -> bool {
        if self.len == QUEUE_CAP {
            return false;
        }
        self.items[(self.head + self.len) % QUEUE_CAP] = c;
        self.len += 1;
        true
    }
    fn front(&self) -> Option<&MotionCommandV1> {
        (self.len > 0).then(|| &self.items[self.head])
    }
    fn pop(&mut self) -> Option<MotionCommandV1> {
        let c = *self.front()?;
        self.head = (self.head + 1) % QUEUE_CAP;
        self.len -= 1;
        Some(c)
    }
    fn clear(&mut self) {
        self.len = 0;
    }
}

/// The generator. Construct once at set-up; [`Generator::step`] runs every cycle.
#[derive(Clone, Debug)]
pub struct Generator {
    p: Params,
    queue: Queue,
    /// The active segment, or `None` at rest on `rest`.
    seg: Option<Segment>,
    /// Motion time (s) at which the active segment's local time is 0.
    origin_s: f64,
    rest: Axes,
    state: MotionState,
    motion_start_ns: u64,
    motion_end_ns: u64,
    end_motion_s: f64,
    theoretical_s: f64,
    program_id: u32,
    line: u32,
    fault: u32,
    fault_line: u32,
    commands_taken: u64,
    starved: u32,
    seq: u64,
    /// Path speed as a share of the programmed one (0..=1), and where it ramps to.
    speed: f64,
    target_speed: f64,
    /// An abort is decelerating: at speed 0 the program is dropped.
    aborting: bool,
    /// Real time lost to pauses in the current motion (s): path time = motion time − this.
    lost_s: f64,
    /// When `lost_s` was last brought up to date (ns).
    path_ns: u64,
    control_seq: u64,
    /// Sequence number of the command whose segment runs.
    exec_seq: u64,
}

impl Generator {
    /// A generator at rest on `start`.
    pub fn new(p: Params, start: &[f64]) -> Self {
        let mut rest = Axes::zeros();
        for (i, v) in start.iter().take(p.axes).enumerate() {
            rest[i] = *v;
        }
        Self {
            p,
            queue: Queue::new(),
            seg: None,
            origin_s: 0.0,
            rest,
            state: MotionState::Idle,
            motion_start_ns: 0,
            motion_end_ns: 0,
            end_motion_s: 0.0,
            theoretical_s: 0.0,
            program_id: 0,
            line: 0,
            fault: fault::NONE,
            fault_line: 0,
            commands_taken: 0,
            starved: 0,
            seq: 0,
            speed: 1.0,
            target_speed: 1.0,
            aborting: false,
            lost_s: 0.0,
            path_ns: 0,
            control_seq: 0,
            exec_seq: 0,
        }
    }

    /// The paused motion for a successor (`None` unless paused on a segment).
    ///
    /// # Real-time
    /// Arithmetic and copies only.
    pub fn handover(&self, now_ns: u64) -> Option<TrajgenHandoverV1> {
        let seg = self.seg.as_ref().filter(|_| self.paused())?;
        let mut h = TrajgenHandoverV1 {
            stamp_ns: now_ns,
            command_seq: self.exec_seq,
            motion_start_ns: self.motion_start_ns,
            program_id: self.program_id,
            line: self.line,
            valid: 1,
            starved: self.starved,
            local_s: self.path_s_at_path_ns() - self.origin_s,
            lost_s: self.lost_s,
            theoretical_s: self.theoretical_s,
            t1_s: seg.t1,
            t_acc_s: seg.t_acc,
            ..TrajgenHandoverV1::default()
        };
        h.a.copy_from_slice(seg.a.as_slice());
        h.b.copy_from_slice(seg.b.as_slice());
        h.c.copy_from_slice(seg.c.as_slice());
        Some(h)
    }

    /// A generator that goes on with a predecessor's paused motion `h` at `now_ns`: paused on
    /// the same point of the same segment, expecting the commands after `h.command_seq`.
    pub fn resume_from(p: Params, h: &TrajgenHandoverV1, now_ns: u64) -> Self {
        let seg = Segment {
            a: axes_of(&p, &h.a),
            b: axes_of(&p, &h.b),
            c: axes_of(&p, &h.c),
            t1: h.t1_s,
            t_acc: h.t_acc_s,
        };
        let mut g = Self::new(p, &[]);
        g.rest = seg.eval(h.local_s).0;
        g.state = MotionState::Moving;
        g.motion_start_ns = h.motion_start_ns;
        g.program_id = h.program_id;
        g.line = h.line;
        g.theoretical_s = h.theoretical_s;
        g.starved = h.starved;
        g.commands_taken = h.command_seq;
        g.exec_seq = h.command_seq;
        g.lost_s = h.lost_s;
        g.path_ns = now_ns;
        g.speed = 0.0;
        g.target_speed = 0.0;
        g.origin_s = g.path_s_at_path_ns() - h.local_s;
        g.seg = Some(seg);
        g
    }

    /// Takes a pause, resume or abort at `now_ns` (the ramp starts exactly then: call
    /// [`Generator::step`] with the same instant). A pause or an abort while no motion runs
    /// does nothing but is acknowledged.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn control(&mut self, c: &MotionControlV1, now_ns: u64) {
        self.control_seq = c.seq;
        if self.state == MotionState::Moving {
            // The ramp starts now, not at the previous cycle.
            self.path_time(now_ns);
        }
        match ControlKind::from_u32(c.kind) {
            Some(ControlKind::Pause) if self.state == MotionState::Moving => {
                self.target_speed = 0.0
            }
            Some(ControlKind::Resume) if !self.aborting => self.target_speed = 1.0,
            Some(ControlKind::Abort) if self.state == MotionState::Moving => {
                self.target_speed = 0.0;
                self.aborting = true;
            }
            _ => {}
        }
    }

    /// Where the reference rests when no segment runs (or where a resumed one was paused).
    pub fn rest_position(&self) -> [f64; MAX_AXES] {
        let mut p = [0.0; MAX_AXES];
        p.copy_from_slice(self.rest.as_slice());
        p
    }

    /// True while paused at rest on the path (speed 0, a motion running).
    pub fn paused(&self) -> bool {
        self.state == MotionState::Moving && self.speed == 0.0
    }

    /// Moves the resting point to `pos` when no segment runs (servo holds elsewhere, e.g.
    /// after a restart of servo or of the machine). Ignored while moving.
    pub fn resync(&mut self, pos: &[f64]) {
        if self.seg.is_none() {
            for (i, v) in pos.iter().take(self.p.axes).enumerate() {
                self.rest[i] = *v;
            }
        }
    }

    /// Drops the program at once (an e-stop): no segment, an empty queue, the reference at
    /// rest on `pos` (where servo brings the axes), and, if a motion was running, the fault
    /// [`fault::ESTOP`] (none when idle: no program was dropped). The fault clears when a new
    /// client session starts, as any other.
    ///
    /// # Real-time
    /// Arithmetic and copies only.
    pub fn abort(&mut self, pos: &[f64]) {
        self.seg = None;
        self.queue.clear();
        self.aborting = false;
        self.speed = 1.0;
        self.target_speed = 1.0;
        for (i, v) in pos.iter().take(self.p.axes).enumerate() {
            self.rest[i] = *v;
        }
        if self.state == MotionState::Moving {
            self.fault = fault::ESTOP;
            self.fault_line = self.line;
            self.state = MotionState::Fault;
        }
    }

    /// Validates `c` and queues it. A refused command sets the fault, empties the queue and
    /// brings the axes to rest on their current target; the fault clears when a new client
    /// session starts (a command with `seq` 1) at rest.
    ///
    /// # Real-time
    /// No allocation; arithmetic and a copy into the fixed queue.
    pub fn push_command(&mut self, c: &MotionCommandV1) {
        if c.seq == 1 && self.seg.is_none() {
            // A new client session: the sequence restarts and a past fault is cleared.
            self.commands_taken = 0;
            self.fault = fault::NONE;
            self.fault_line = 0;
            if self.state == MotionState::Fault {
                self.state = MotionState::Done;
            }
        }
        if self.fault != fault::NONE {
            return; // Refuse everything until a new session starts.
        }
        let code = self.check(c);
        if code != fault::NONE {
            self.fault = code;
            self.fault_line = c.line;
            self.queue.clear();
            return;
        }
        if !self.queue.push(*c) {
            self.fault = fault::QUEUE_OVERFLOW;
            self.fault_line = c.line;
            self.queue.clear();
            return;
        }
        self.commands_taken = c.seq;
    }

    fn check(&self, c: &MotionCommandV1) -> u32 {
        if c.seq != self.commands_taken + 1 {
            return fault::SEQUENCE_GAP;
        }
        if c.axes as usize != self.p.axes {
            return fault::AXES_MISMATCH;
        }
        match CommandKind::from_u32(c.kind) {
            None => fault::BAD_COMMAND,
            Some(CommandKind::Move) => {
                if !(c.user_time_s.is_finite() && c.user_time_s >= 0.0) {
                    return fault::BAD_COMMAND;
                }
                for i in 0..self.p.axes {
                    let v = c.target[i];
                    if !v.is_finite() {
                        return fault::BAD_COMMAND;
                    }
                    if v < self.p.min[i] || v > self.p.max[i] {
                        return fault::TARGET_OUT_OF_LIMITS;
                    }
                }
                fault::NONE
            }
            Some(_) => fault::NONE,
        }
    }

    fn target_of(&self, c: &MotionCommandV1) -> Axes {
        axes_of(&self.p, &c.target)
    }

    fn time_between(&self, b: &Axes, c: &Axes, user: f64) -> f64 {
        let n = self.p.axes;
        segment_time(
            &b.as_slice()[..n],
            &c.as_slice()[..n],
            &self.p.vmax[..n],
            self.p.t_acc,
            user,
        )
    }

    /// Starts a segment towards `c` from rest.
    fn start_from_rest(&mut self, now_ns: u64, cmd: &MotionCommandV1) {
        if self.state != MotionState::Moving {
            self.motion_start_ns = now_ns;
            self.motion_end_ns = 0;
            self.theoretical_s = 0.0;
            self.program_id = cmd.program_id;
            self.state = MotionState::Moving;
            self.lost_s = 0.0;
            self.path_ns = now_ns;
            if !self.aborting {
                self.speed = self.target_speed;
            }
        }
        let c = self.target_of(cmd);
        let t1 = self.time_between(&self.rest, &c, cmd.user_time_s);
        let origin = self.path_time(now_ns) + self.p.t_acc;
        self.exec_seq = cmd.seq;
        let rest = self.rest;
        self.begin(
            Segment {
                a: rest,
                b: rest,
                c,
                t1,
                t_acc: self.p.t_acc,
            },
            origin,
            cmd.line,
        );
    }

    fn motion_time(&self, now_ns: u64) -> f64 {
        (now_ns as i128 - self.motion_start_ns as i128) as f64 * 1e-9
    }

    /// Brings the speed ramp and the time lost to it up to `now_ns`; returns the path time.
    /// The speed moves towards its target at `1 / t_acc` per second; the path advances by
    /// the integral of the speed (exact for the linear ramp).
    fn path_time(&mut self, now_ns: u64) -> f64 {
        if now_ns > self.path_ns {
            let dt = (now_ns - self.path_ns) as f64 * 1e-9;
            self.path_ns = now_ns;
            if self.speed != 1.0 || self.target_speed != 1.0 {
                let rate = 1.0 / self.p.t_acc.max(1e-3);
                let gap = self.target_speed - self.speed;
                let ramp = (gap.abs() / rate).min(dt);
                let end = self.speed + gap.signum() * rate * ramp;
                let advance = (self.speed + end) / 2.0 * ramp + end * (dt - ramp);
                self.speed = if ramp < dt { self.target_speed } else { end };
                self.lost_s += dt - advance;
            }
        }
        self.motion_time(now_ns) - self.lost_s
    }

    /// Absolute time (ns) of the next instant the reference changes its law — a segment
    /// transition, or the end of a speed ramp — for an exact extra wake-up: servo
    /// extrapolates each setpoint with its acceleration, so a change between two setpoints
    /// would show as a velocity step.
    pub fn next_transition_ns(&self) -> Option<u64> {
        let seg = self.seg.as_ref()?;
        let to_transition = self.origin_s + seg.transition_time() - self.path_s_at_path_ns();
        let rate = 1.0 / self.p.t_acc.max(1e-3);
        let gap = self.target_speed - self.speed;
        let dt = if gap == 0.0 {
            // Constant speed: at 0 (paused) nothing changes until a resume.
            (self.speed > 0.0).then(|| to_transition / self.speed)?
        } else {
            // Along the ramp the path advances s·τ + r·τ²/2: the transition, if it comes
            // before the ramp ends, else the ramp's end.
            let r = gap.signum() * rate;
            let ramp_end = gap.abs() / rate;
            let disc = self.speed * self.speed + 2.0 * r * to_transition;
            let at = if disc >= 0.0 && to_transition >= 0.0 {
                (-self.speed + disc.sqrt()) / r
            } else {
                f64::INFINITY
            };
            if at.is_finite() && at >= 0.0 && at < ramp_end {
                at
            } else {
                ramp_end
            }
        };
        Some(self.path_ns + (dt.max(0.0) * 1e9).ceil() as u64)
    }

    /// The path time at `path_ns` (the last instant the speed ramp was brought up to).
    fn path_s_at_path_ns(&self) -> f64 {
        self.motion_time(self.path_ns) - self.lost_s
    }

    /// Advances to `now_ns` and returns the setpoint for it.
    ///
    /// # Real-time
    /// No allocation, no system call: arithmetic on stack vectors and the fixed queue.
    pub fn step(&mut self, now_ns: u64) -> SetpointV1 {
        // At rest: a MOVE starts a segment; STOP does nothing; END ends the motion.
        if self.seg.is_none() {
            self.take_at_rest(now_ns);
        }
        // Take every transition the path time has passed, each at its exact instant.
        let mt = self.path_time(now_ns);
        while let Some(seg) = self.seg {
            if mt - self.origin_s < seg.transition_time() {
                break;
            }
            self.transition(seg, now_ns);
        }
        if self.aborting && self.speed == 0.0 {
            self.drop_program(mt, now_ns);
        }
        let (pos, vel, acc) = match &self.seg {
            Some(seg) => {
                let (p, v) = seg.eval(mt - self.origin_s);
                let a = seg.accel(mt - self.origin_s);
                // d/dt of p(s(t)): v·speed, and a·speed² + v·speed' while the speed ramps.
                let ramp = if self.speed == self.target_speed {
                    0.0
                } else {
                    (self.target_speed - self.speed).signum() / self.p.t_acc.max(1e-3)
                };
                (p, v * self.speed, a * (self.speed * self.speed) + v * ramp)
            }
            None => (self.rest, Axes::zeros(), Axes::zeros()),
        };
        self.seq += 1;
        let motion_time_s = match self.state {
            MotionState::Moving => self.motion_time(now_ns),
            MotionState::Done | MotionState::Fault => self.end_motion_s,
            MotionState::Idle => 0.0,
        };
        let mut sp = SetpointV1 {
            seq: self.seq,
            stamp_ns: now_ns,
            motion_start_ns: self.motion_start_ns,
            motion_end_ns: self.motion_end_ns,
            motion_time_s,
            theoretical_s: self.theoretical_s,
            segment_time_s: self.seg.map_or(0.0, |s| s.t1),
            program_id: self.program_id,
            line: self.line,
            state: self.state as u32,
            axes: self.p.axes as u32,
            fault: self.fault,
            fault_line: self.fault_line,
            commands_taken: self.commands_taken,
            queue_free: (QUEUE_CAP - self.queue.len) as u32,
            starved: self.starved,
            path_speed: self.speed,
            control_seq: self.control_seq,
            position: [0.0; MAX_AXES],
            velocity: [0.0; MAX_AXES],
            acceleration: [0.0; MAX_AXES],
        };
        sp.acceleration.copy_from_slice(acc.as_slice());
        sp.position.copy_from_slice(pos.as_slice());
        sp.velocity.copy_from_slice(vel.as_slice());
        sp
    }

    fn take_at_rest(&mut self, now_ns: u64) {
        while let Some(cmd) = self.queue.pop() {
            match CommandKind::from_u32(cmd.kind) {
                Some(CommandKind::Move) => {
                    self.start_from_rest(now_ns, &cmd);
                    return;
                }
                Some(CommandKind::End) => {
                    if self.state != MotionState::Moving {
                        // A program without motion: done at once.
                        self.motion_start_ns = now_ns;
                        self.theoretical_s = 0.0;
                        self.program_id = cmd.program_id;
                    }
                    self.finish(now_ns, MotionState::Done);
                    self.line = cmd.line;
                    return;
                }
                _ => {}
            }
        }
        if self.fault != fault::NONE && self.state != MotionState::Fault {
            // Refused before or between motions: nothing moves.
            self.finish(now_ns, MotionState::Fault);
        }
    }

    /// The end of an abort: at rest on the path at path time `mt`, the program dropped.
    fn drop_program(&mut self, mt: f64, now_ns: u64) {
        if let Some(seg) = self.seg.take() {
            self.rest = seg.eval(mt - self.origin_s).0;
        }
        self.queue.clear();
        self.aborting = false;
        self.speed = 1.0;
        self.target_speed = 1.0;
        self.fault = fault::ABORTED;
        self.fault_line = self.line;
        self.finish(now_ns, MotionState::Fault);
    }

    fn finish(&mut self, now_ns: u64, state: MotionState) {
        self.speed = 1.0;
        self.target_speed = 1.0;
        self.state = state;
        self.motion_end_ns = now_ns;
        self.end_motion_s = self.motion_time(now_ns);
    }

    /// Makes `seg` the active segment, its local time 0 at motion time `origin`.
    fn begin(&mut self, seg: Segment, origin: f64, line: u32) {
        self.seg = Some(seg);
        self.origin_s = origin;
        self.theoretical_s += seg.t1;
        self.line = line;
    }

    /// The transition at local `T1 - t_acc` of `seg` (seed 003: `A` = current position,
    /// `B` = `C`, `t = -t_acc`, `T1 = T2`).
    fn transition(&mut self, seg: Segment, now_ns: u64) {
        let a = seg.eval(seg.transition_time()).0;
        let origin = self.origin_s + seg.t1;
        let t_acc = self.p.t_acc;
        let stop = Segment {
            a,
            b: seg.c,
            c: seg.c,
            t1: 2.0 * t_acc,
            t_acc,
        };
        let next = self.queue.front().copied();
        match next.map(|c| (c, CommandKind::from_u32(c.kind))) {
            Some((cmd, Some(CommandKind::Move))) => {
                self.queue.pop();
                self.exec_seq = cmd.seq;
                let c = self.target_of(&cmd);
                let t1 = self.time_between(&seg.c, &c, cmd.user_time_s);
                self.begin(
                    Segment {
                        a,
                        b: seg.c,
                        c,
                        t1,
                        t_acc,
                    },
                    origin,
                    cmd.line,
                );
            }
            Some((cmd, Some(CommandKind::Stop))) => {
                self.queue.pop();
                self.exec_seq = cmd.seq;
                self.begin(stop, origin, cmd.line);
            }
            Some((cmd, _)) if seg.stops() => {
                // END with the axes at rest on the last target: the motion ends now.
                self.queue.pop();
                self.rest = seg.c;
                self.seg = None;
                self.finish(now_ns, MotionState::Done);
                self.line = cmd.line;
            }
            // END while moving: stop on the last target first; END stays queued.
            Some(_) => self.begin(stop, origin, self.line),
            None if seg.stops() => {
                // Queue empty, axes at rest: wait here (after a fault, the motion ends here).
                self.rest = seg.c;
                self.seg = None;
                if self.fault != fault::NONE {
                    self.finish(now_ns, MotionState::Fault);
                }
            }
            None => {
                if self.fault == fault::NONE {
                    self.starved = self.starved.saturating_add(1);
                }
                self.begin(stop, origin, self.line);
            }
        }
    }
}

/// The axes in use of a wire array (the rest zero).
fn axes_of(p: &Params, v: &[f64; MAX_AXES]) -> Axes {
    let mut t = Axes::zeros();
    t.as_mut_slice()[..p.axes].copy_from_slice(&v[..p.axes]);
    t
}
