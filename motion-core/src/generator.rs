//! The trajectory generator of seed 003 §2, driven by real elapsed time.
//!
//! Every reference is computed from `CLOCK_MONOTONIC` time since the start of the motion,
//! never from a cycle count: a late cycle evaluates the trajectory at the time it actually
//! runs, so it shortens nothing and lengthens nothing (seed 003's first fix). Segment
//! boundaries are exact: a segment's local time 0 is the previous one's plus its `T1`, and
//! `A` is the previous segment evaluated at exactly `T1 - t_acc`, however late the cycle that
//! notices the transition runs (several transitions are taken at once after a long stall).
//!
//! The generator is always in one [`Phase`]: at rest, moving along a segment, waiting for an
//! input (`WAIT`) or holding for a time (`DELAY`). Commands are taken into a fixed queue as
//! they arrive (validated one by one); the look-ahead reads the next one only when the motion
//! needs it, at `t = T1 - t_acc` of the running segment (docs/language.md says what each
//! instruction does then):
//!
//! - `MOVE`/`MOVEJ` in the same space: the next segment, blended;
//! - `OUT` and `SPEED` take effect at once and the look-ahead reads on;
//! - `STOP`: a stopping segment exactly on the target;
//! - `WAIT`, `DELAY`, `END`, and a move in the other space: the axes stop exactly on the
//!   target first, then it takes effect at rest;
//! - nothing queued: the axes stop on the target and wait (counted in `starved`).
//!
//! A pause, a resume, an abort or the live speed override ([`Generator::control`]) scales the
//! rate at which the path is travelled, never the path: path time runs at `speed` times real
//! time, and `speed` ramps linearly within `t_acc` (the blend's own acceleration time). At
//! speed 1 the path time is real elapsed time minus the time lost to pauses, exactly. A
//! program's `SPEED` instead sets the segment times of the moves that follow (their `T1`).

use crate::blend::{Axes, Segment};
use kinematics::{JointLimit, KinError, Kinematics, MAX_COORDS, cartesian_to_axes, joint_velocity};
pub use motion_program::Space;
use motion_program::segment_time;
use shm_schema::motion::{hold, trajgen_fault as fault};
use shm_schema::{
    CommandKind, ControlKind, MAX_AXES, MAX_IO, MotionCommandV2, MotionControlV2, MotionState,
    SetpointV2, TrajgenHandoverV2,
};
use std::sync::Arc;

/// Places in the command queue.
pub const QUEUE_CAP: usize = 256;

/// Lowest speed (share of the programmed one) of the override and of `SPEED`.
pub const MIN_SPEED: f64 = 0.01;

/// An instant within this of a transition (s) has reached it: the wake-up
/// [`Generator::next_transition_ns`] asks for is rounded up to the nanosecond, but the path
/// time computed back from it may fall short by a rounding error, and the transition would
/// wait a whole period.
const REACHED_S: f64 = 1e-9;

/// Phase changes at most in one step: holds that end at once (a WAIT met, a DELAY(0)) and
/// what they start.
const PHASE_CHANGES: usize = 64;

/// Per-cell parameters of the generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Joints (axes) in use.
    pub axes: usize,
    /// Cartesian coordinates in use.
    pub coords: usize,
    /// Largest velocity per joint (unit/s): `MOVEJ`'s segment times.
    pub vmax: [f64; MAX_AXES],
    /// Largest velocity per Cartesian coordinate (unit/s): `MOVE`'s segment times.
    pub coord_vmax: [f64; MAX_AXES],
    /// Lowest position per joint.
    pub min: [f64; MAX_AXES],
    /// Highest position per joint.
    pub max: [f64; MAX_AXES],
    /// Acceleration time (s).
    pub t_acc: f64,
}

impl Params {
    /// Parameters from the cell configuration: the joints' limits, and the Cartesian
    /// coordinates of its kinematics (the joints themselves for the gantry).
    pub fn from_cell(cell: &shm_schema::CellConfigV6) -> Self {
        let mut p = Params {
            axes: cell.axes as usize,
            coords: cell.axes as usize,
            vmax: [1.0; MAX_AXES],
            coord_vmax: [1.0; MAX_AXES],
            min: [0.0; MAX_AXES],
            max: [0.0; MAX_AXES],
            t_acc: cell.t_acc_s,
        };
        for (i, a) in cell.axes().iter().enumerate() {
            p.vmax[i] = a.vmax;
            p.coord_vmax[i] = a.vmax;
            p.min[i] = a.min;
            p.max[i] = a.max;
        }
        let k = &cell.kinematics;
        if k.coords > 0 {
            p.coords = (k.coords as usize).min(MAX_COORDS);
            p.coord_vmax = k.coord_vmax;
        }
        p
    }
}

/// The cell's kinematics, shared by trajgen's generator and the supervisor's prediction.
#[derive(Clone)]
pub struct Kin(pub Arc<dyn Kinematics + Send + Sync>);

impl core::fmt::Debug for Kin {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "Kin({})", self.0.name())
    }
}

impl Kin {
    /// The kinematics the cell's configuration selects (`[kinematics]`); `None` for the
    /// gantry, whose Cartesian coordinates are its joints. Set-up only: it allocates.
    pub fn of_cell(
        cell: &shm_schema::CellConfigV6,
    ) -> Result<Option<Self>, kinematics::BuildError> {
        let k = &cell.kinematics;
        let name = shm_schema::str_of(&k.type_name);
        if name.is_empty() || name == "gantry" {
            return Ok(None);
        }
        let params: Vec<(&str, f64)> = k.params[..(k.param_count as usize).min(k.params.len())]
            .iter()
            .map(|p| (shm_schema::str_of(&p.name), p.value))
            .collect();
        let built = kinematics::build(name, &kinematics::Params(&params))?;
        Ok(Some(Self(Arc::from(built))))
    }
}

/// The step of the jacobian's rate of change `J̇ q̇ ≈ (J(q + h q̇) − J(q − h q̇)) / 2h` (s).
const JDOT_STEP_S: f64 = 1e-3;

/// What the generator is doing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    /// At rest on the resting point: before a program, after one, or within one waiting for
    /// its next command.
    AtRest,
    /// Travelling a segment (its blend zone included).
    Moving(Segment),
    /// At rest within a program until input `io` reads `value` (`WAIT`); past `deadline_ns`
    /// (0: none) the program faults.
    Waiting {
        /// Index of the input in the IO table.
        io: u32,
        /// The value waited for.
        value: bool,
        /// Real time the wait times out (ns), 0 for never.
        deadline_ns: u64,
        /// When the wait began (ns).
        since_ns: u64,
    },
    /// At rest within a program until path time `until_s` (`DELAY`).
    Delaying {
        /// Path time the delay ends.
        until_s: f64,
    },
}

/// A fixed-capacity FIFO of commands (no allocation after construction).
#[derive(Clone, Debug)]
struct Queue {
    items: [MotionCommandV2; QUEUE_CAP],
    head: usize,
    len: usize,
}

impl Queue {
    fn new() -> Self {
        Self {
            items: [MotionCommandV2::default(); QUEUE_CAP],
            head: 0,
            len: 0,
        }
    }
    fn push(&mut self, c: MotionCommandV2) -> bool {
        if self.len == QUEUE_CAP {
            return false;
        }
        self.items[(self.head + self.len) % QUEUE_CAP] = c;
        self.len += 1;
        true
    }
    fn front(&self) -> Option<&MotionCommandV2> {
        (self.len > 0).then(|| &self.items[self.head])
    }
    fn pop(&mut self) -> Option<MotionCommandV2> {
        let c = *self.front()?;
        self.head = (self.head + 1) % QUEUE_CAP;
        self.len -= 1;
        Some(c)
    }
    fn clear(&mut self) {
        self.len = 0;
    }
}

/// Outputs the program set since they were last taken ([`Generator::take_outputs`]): the
/// bits written, their values, and the line of the last `OUT`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Outputs {
    /// Bit `k`: output `k` was written.
    pub mask: u64,
    /// The values written.
    pub values: u64,
    /// Program line of the last `OUT`.
    pub line: u32,
}

/// One period of a loop whose iterations are alike ([`Generator::period_since`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Period {
    /// Path time one iteration takes (s).
    pub path_s: f64,
    /// The segment and delay times it adds (s).
    pub theoretical_s: f64,
    /// Time lost to the speed override in it (s).
    pub lost_s: f64,
    /// Time spent in `WAIT`s in it (s).
    pub waited_s: f64,
    /// Times it ran out of commands.
    pub starved: u32,
    /// The largest difference of the joint positions the two states were taken at: the
    /// inverse kinematics starts from them, so a caller checks they are no further apart than
    /// the states' sampling instants allow.
    pub joints_apart: f64,
}

/// The generator. Construct once at set-up; [`Generator::step`] runs every cycle.
#[derive(Clone, Debug)]
pub struct Generator {
    p: Params,
    queue: Queue,
    phase: Phase,
    /// The space of the running segment, or of `rest`.
    space: Space,
    /// Motion time (s) at which the running segment's local time is 0.
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
    /// The live override: where the speed goes when not paused.
    speed_override: f64,
    /// `SPEED`: the share of vmax of the moves that follow.
    program_speed: f64,
    /// An abort is decelerating: at speed 0 the program is dropped.
    aborting: bool,
    /// Real time lost to pauses and overrides in the current motion (s): path time = motion
    /// time − this.
    lost_s: f64,
    /// Real time spent in `WAIT`s in the current motion (s).
    waited_s: f64,
    /// When `lost_s` was last brought up to date (ns).
    path_ns: u64,
    control_seq: u64,
    /// Sequence number of the command whose segment runs.
    exec_seq: u64,
    outputs: Outputs,
    /// The kinematics; `None`: the Cartesian coordinates are the joints (the gantry).
    kin: Option<Kin>,
    /// The joint limits, for the inverse kinematics.
    limits: [JointLimit; MAX_AXES],
    /// The joint position of the latest setpoint (the inverse kinematics' reference).
    joints: Axes,
    /// The last error of the kinematics (a target or a path out of reach).
    kin_error: Option<KinError>,
}

impl Generator {
    /// A generator at rest on `start` (joint positions), for a cell whose Cartesian
    /// coordinates are its joints.
    pub fn new(p: Params, start: &[f64]) -> Self {
        Self::with_kinematics(p, None, start)
    }

    /// A generator at rest on `start` (joint positions) with the cell's kinematics: `MOVE`
    /// is blended in its Cartesian coordinates and every reference mapped to the joints
    /// (nearest the previous joint position, within the limits).
    pub fn with_kinematics(p: Params, kin: Option<Kin>, start: &[f64]) -> Self {
        let mut rest = Axes::zeros();
        for (i, v) in start.iter().take(p.axes).enumerate() {
            rest[i] = *v;
        }
        let mut limits = [JointLimit::NONE; MAX_AXES];
        for (i, l) in limits.iter_mut().enumerate().take(p.axes) {
            *l = JointLimit::new(p.min[i], p.max[i]);
        }
        Self {
            kin,
            limits,
            joints: rest,
            kin_error: None,
            p,
            queue: Queue::new(),
            phase: Phase::AtRest,
            space: Space::Joint,
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
            speed_override: 1.0,
            program_speed: 1.0,
            aborting: false,
            lost_s: 0.0,
            waited_s: 0.0,
            path_ns: 0,
            control_seq: 0,
            exec_seq: 0,
            outputs: Outputs::default(),
        }
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The kinematics' last error (why a fault [`fault::UNREACHABLE`] was raised).
    pub fn kin_error(&self) -> Option<KinError> {
        self.kin_error
    }

    /// The space of the running segment or of the resting point.
    pub fn space(&self) -> Space {
        self.space
    }

    /// The paused motion for a successor (`None` unless paused on a segment).
    ///
    /// # Real-time
    /// Arithmetic and copies only.
    pub fn handover(&self, now_ns: u64) -> Option<TrajgenHandoverV2> {
        let Phase::Moving(seg) = self.phase else {
            return None;
        };
        if !self.paused() {
            return None;
        }
        let mut h = TrajgenHandoverV2 {
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
            speed_override: self.speed_override,
            program_speed: self.program_speed,
            waited_s: self.waited_s,
            space: self.space as u32,
            ..TrajgenHandoverV2::default()
        };
        h.a.copy_from_slice(seg.a.as_slice());
        h.b.copy_from_slice(seg.b.as_slice());
        h.c.copy_from_slice(seg.c.as_slice());
        Some(h)
    }

    /// A generator that goes on with a predecessor's paused motion `h` at `now_ns`: paused on
    /// the same point of the same segment, expecting the commands after `h.command_seq`;
    /// `joints` is where servo holds (the inverse kinematics' reference).
    pub fn resume_from(
        p: Params,
        kin: Option<Kin>,
        h: &TrajgenHandoverV2,
        now_ns: u64,
        joints: &[f64],
    ) -> Self {
        let seg = Segment {
            a: axes_of(&p, &h.a),
            b: axes_of(&p, &h.b),
            c: axes_of(&p, &h.c),
            t1: h.t1_s,
            t_acc: h.t_acc_s,
        };
        let mut g = Self::with_kinematics(p, kin, joints);
        g.rest = seg.eval(h.local_s).0;
        g.state = MotionState::Moving;
        g.space = if h.space == Space::Cartesian as u32 {
            Space::Cartesian
        } else {
            Space::Joint
        };
        g.motion_start_ns = h.motion_start_ns;
        g.program_id = h.program_id;
        g.line = h.line;
        g.theoretical_s = h.theoretical_s;
        g.starved = h.starved;
        g.commands_taken = h.command_seq;
        g.exec_seq = h.command_seq;
        g.lost_s = h.lost_s;
        g.waited_s = h.waited_s;
        g.speed_override = bounded_speed(h.speed_override);
        g.program_speed = bounded_speed(h.program_speed);
        g.path_ns = now_ns;
        g.speed = 0.0;
        g.target_speed = 0.0;
        g.origin_s = g.path_s_at_path_ns() - h.local_s;
        g.phase = Phase::Moving(seg);
        // Where the paused reference is, in joints.
        let rest = g.rest;
        if let Ok((q, ..)) = g.map(&rest, &Axes::zeros(), &Axes::zeros()) {
            g.joints = q;
        }
        g
    }

    /// Takes a pause, resume, abort or speed override at `now_ns` (the ramp starts exactly
    /// then: call [`Generator::step`] with the same instant). A pause or an abort while no
    /// program runs does nothing but is acknowledged.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn control(&mut self, c: &MotionControlV2, now_ns: u64) {
        // The largest taken: numbers grow across senders, so `>=` tells a sender its own was.
        self.control_seq = self.control_seq.max(c.seq);
        if self.state == MotionState::Moving {
            // The ramp starts now, not at the previous cycle.
            self.path_time(now_ns);
        }
        // A program whose commands are queued but not begun counts as running: a pause sent
        // with its first commands starts it paused.
        let begun = self.state == MotionState::Moving;
        let running = begun || self.queue.len > 0;
        match ControlKind::from_wire(c.kind) {
            Some(ControlKind::Pause) if running => self.target_speed = 0.0,
            Some(ControlKind::Resume) if !self.aborting => self.target_speed = self.speed_override,
            Some(ControlKind::Abort) if begun => {
                self.target_speed = 0.0;
                self.aborting = true;
            }
            Some(ControlKind::Abort) if running => {
                // Not begun: nothing moves, the program is dropped at once.
                if let Some(front) = self.queue.front() {
                    self.program_id = front.program_id;
                    self.line = front.line;
                }
                self.queue.clear();
                self.fault = fault::ABORTED;
                self.fault_line = self.line;
                self.motion_start_ns = now_ns;
                self.finish(now_ns, MotionState::Fault);
            }
            Some(ControlKind::Speed) if c.value.is_finite() => {
                self.speed_override = bounded_speed(c.value);
                // Paused (or aborting) stays so; otherwise the path speed ramps to it.
                if !self.aborting && (self.target_speed > 0.0 || !running) {
                    self.target_speed = self.speed_override;
                }
            }
            _ => {}
        }
    }

    /// The joint position of the reference: where it rests when no segment runs (or where a
    /// resumed one was paused).
    pub fn rest_position(&self) -> [f64; MAX_AXES] {
        let mut p = [0.0; MAX_AXES];
        p.copy_from_slice(self.joints.as_slice());
        p
    }

    /// True while paused at rest on the path (speed 0, a program running).
    pub fn paused(&self) -> bool {
        self.state == MotionState::Moving && self.speed == 0.0
    }

    /// Moves the resting point to `pos` (joint positions) when no segment runs (servo holds
    /// elsewhere, e.g. after a restart of servo or of the machine). Ignored while moving.
    pub fn resync(&mut self, pos: &[f64]) {
        if !matches!(self.phase, Phase::Moving(_)) {
            for (i, v) in pos.iter().take(self.p.axes).enumerate() {
                self.rest[i] = *v;
            }
            self.joints = self.rest;
            self.space = Space::Joint;
        }
    }

    /// Drops the program at once (an e-stop): no segment, an empty queue, the reference at
    /// rest on `pos` (joint positions, where servo brings the axes), and, if a program was
    /// running, the fault [`fault::ESTOP`] (none when idle: no program was dropped). The
    /// fault clears when a new client session starts, as any other.
    ///
    /// # Real-time
    /// Arithmetic and copies only.
    pub fn abort(&mut self, pos: &[f64]) {
        self.phase = Phase::AtRest;
        self.queue.clear();
        self.aborting = false;
        self.speed = self.speed_override;
        self.target_speed = self.speed_override;
        for (i, v) in pos.iter().take(self.p.axes).enumerate() {
            self.rest[i] = *v;
        }
        self.joints = self.rest;
        self.space = Space::Joint;
        self.program_speed = 1.0;
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
    pub fn push_command(&mut self, c: &MotionCommandV2) {
        if c.seq == 1 && !matches!(self.phase, Phase::Moving(_)) {
            // A new client session: the sequence restarts and a past fault is cleared. A
            // program its client left (at rest, starved, waiting or delaying) ends here: the
            // new one starts afresh.
            if self.state == MotionState::Moving {
                self.queue.clear();
                self.phase = Phase::AtRest;
                self.finish(self.path_ns, MotionState::Done);
            }
            self.commands_taken = 0;
            self.fault = fault::NONE;
            self.fault_line = 0;
            self.phase = Phase::AtRest;
            if self.state == MotionState::Fault {
                self.state = MotionState::Done;
            }
        }
        if self.fault != fault::NONE {
            return; // Refuse everything until a new session starts.
        }
        let code = self.check(c);
        if code != fault::NONE {
            self.refuse(code, c.line);
            return;
        }
        if !self.queue.push(*c) {
            self.refuse(fault::QUEUE_OVERFLOW, c.line);
            return;
        }
        self.commands_taken = c.seq;
    }

    fn refuse(&mut self, code: u32, line: u32) {
        self.fault = code;
        self.fault_line = line;
        self.queue.clear();
    }

    fn check(&self, c: &MotionCommandV2) -> u32 {
        if c.seq != self.commands_taken + 1 {
            return fault::SEQUENCE_GAP;
        }
        let time_ok = |t: f64, max: f64| t.is_finite() && (0.0..=max).contains(&t);
        match CommandKind::from_wire(c.kind) {
            None => fault::BAD_COMMAND,
            Some(k @ (CommandKind::Move | CommandKind::MoveJ)) => {
                // A Cartesian target's joints depend on the path to it: the supervisor's
                // prediction checks them, and the cycle refuses one it cannot reach.
                let joint = k == CommandKind::MoveJ || self.kin.is_none();
                let n = if k == CommandKind::MoveJ {
                    self.p.axes
                } else {
                    self.p.coords
                };
                if c.count as usize != n {
                    return fault::AXES_MISMATCH;
                }
                if !time_ok(c.time_s, motion_program::MAX_SEGMENT_TIME_S) {
                    return fault::BAD_COMMAND;
                }
                for i in 0..n {
                    let v = c.target[i];
                    if !v.is_finite() {
                        return fault::BAD_COMMAND;
                    }
                    if joint && (v < self.p.min[i] || v > self.p.max[i]) {
                        return fault::TARGET_OUT_OF_LIMITS;
                    }
                }
                fault::NONE
            }
            Some(CommandKind::Out | CommandKind::Wait)
                if c.io as usize >= MAX_IO
                    || c.value > 1
                    || !time_ok(c.time_s, motion_program::MAX_WAIT_S) =>
            {
                fault::BAD_COMMAND
            }
            Some(CommandKind::Delay) if !time_ok(c.time_s, motion_program::MAX_WAIT_S) => {
                fault::BAD_COMMAND
            }
            Some(CommandKind::Speed)
                if !(c.speed.is_finite() && (MIN_SPEED..=1.0).contains(&c.speed)) =>
            {
                fault::BAD_COMMAND
            }
            Some(_) => fault::NONE,
        }
    }

    fn space_of(kind: Option<CommandKind>) -> Space {
        if kind == Some(CommandKind::MoveJ) {
            Space::Joint
        } else {
            Space::Cartesian
        }
    }

    /// `T1` from `b` to `c` in `space` at the program's `SPEED`: the per-axis times at
    /// `SPEED` × vmax, the user's `T` stretched by `1 / SPEED`, never below `2 t_acc`.
    fn time_between(&self, space: Space, b: &Axes, c: &Axes, user: f64) -> f64 {
        let (n, vmax) = match space {
            Space::Joint => (self.p.axes, &self.p.vmax),
            Space::Cartesian => (self.p.coords, &self.p.coord_vmax),
        };
        let k = self.program_speed;
        let mut scaled = [0.0; MAX_AXES];
        for (s, v) in scaled.iter_mut().zip(vmax) {
            *s = v * k;
        }
        segment_time(
            &b.as_slice()[..n],
            &c.as_slice()[..n],
            &scaled[..n],
            self.p.t_acc,
            user / k,
        )
    }

    /// A program's first command taken at rest: the motion starts now. Returns false when
    /// a program was running already.
    fn begin_program(&mut self, now_ns: u64, cmd: &MotionCommandV2) -> bool {
        if self.state == MotionState::Moving {
            return false;
        }
        {
            self.motion_start_ns = now_ns;
            self.motion_end_ns = 0;
            self.theoretical_s = 0.0;
            self.starved = 0;
            self.program_id = cmd.program_id;
            self.state = MotionState::Moving;
            self.lost_s = 0.0;
            self.waited_s = 0.0;
            self.path_ns = now_ns;
            if !self.aborting {
                self.speed = self.target_speed;
            }
        }
        true
    }

    /// The path time a hold or a move taken at rest starts at: `rest_s` (the exact instant
    /// the axes came to rest, when known) within a running program, now otherwise.
    fn rest_time(&mut self, now_ns: u64, rest_s: Option<f64>, new_program: bool) -> f64 {
        match rest_s {
            Some(t) if !new_program => t,
            _ => self.path_time(now_ns),
        }
    }

    /// Starts a segment towards `cmd`'s target from rest (at path time `rest_s` if given).
    fn start_from_rest(&mut self, now_ns: u64, rest_s: Option<f64>, cmd: &MotionCommandV2) {
        let new = self.begin_program(now_ns, cmd);
        let at = self.rest_time(now_ns, rest_s, new);
        let space = Self::space_of(CommandKind::from_wire(cmd.kind));
        if space != self.space {
            // At rest, the resting point changes space: the same point, other coordinates.
            match self.convert_rest(space) {
                Ok(rest) => self.rest = rest,
                Err(e) => {
                    self.unreachable(now_ns, e, cmd.line);
                    return;
                }
            }
            self.space = space;
        }
        let c = axes_of(&self.p, &cmd.target);
        let t1 = self.time_between(space, &self.rest, &c, cmd.time_s);
        let origin = at + self.p.t_acc;
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

    /// The resting point in `space`'s coordinates, from the exact resting point in the
    /// current space (`rest`, the stopping segment's target): the joints of the latest
    /// setpoint would do only if it had been computed at the instant of the rest, and a cycle
    /// before it they differ from it by a hair, which made a move to where the axes rest one
    /// that does not stop on its target (an extra stopping segment of `2 t_acc`, one run in
    /// a few, and always in the prediction).
    fn convert_rest(&self, space: Space) -> Result<Axes, KinError> {
        if self.kin.is_none() {
            return Ok(self.rest);
        }
        let (q, _, _, cartesian, _) = self.map(&self.rest, &Axes::zeros(), &Axes::zeros())?;
        Ok(match space {
            Space::Joint => q,
            Space::Cartesian => cartesian,
        })
    }

    /// The kinematics cannot follow (a target or a path out of reach, a singularity): the
    /// program faults at `line`, the reference rests on the last joint position.
    fn unreachable(&mut self, now_ns: u64, e: KinError, line: u32) {
        self.kin_error = Some(e);
        self.refuse(fault::UNREACHABLE, line);
        self.phase = Phase::AtRest;
        self.rest = self.joints;
        self.space = Space::Joint;
        self.finish(now_ns, MotionState::Fault);
    }

    /// The reference (position, velocity, acceleration in the running space) as joint
    /// position, velocity and acceleration, and Cartesian position and velocity.
    ///
    /// # Real-time
    /// Arithmetic and the kinematics' (allocation-free) calls.
    #[allow(clippy::type_complexity)]
    fn map(
        &self,
        pos: &Axes,
        vel: &Axes,
        acc: &Axes,
    ) -> Result<(Axes, Axes, Axes, Axes, Axes), KinError> {
        let Some(k) = &self.kin else {
            return Ok((*pos, *vel, *acc, *pos, *vel));
        };
        let k = &*k.0;
        let n = self.p.axes;
        match self.space {
            Space::Joint => {
                let q = joints_of(pos);
                let c = k.axes_to_cartesian(&q)?;
                let j = k.jacobian(&q)?;
                let mut cv = Axes::zeros();
                for r in 0..self.p.coords.min(MAX_COORDS) {
                    cv[r] = (0..n).map(|i| j[(r, i)] * vel[i]).sum();
                }
                let mut cp = Axes::zeros();
                cp.as_mut_slice()[..MAX_COORDS].copy_from_slice(&c);
                Ok((*pos, *vel, *acc, cp, cv))
            }
            Space::Cartesian => {
                let p = pose_of(pos);
                let q = cartesian_to_axes(k, &p, &joints_of(&self.joints), &self.limits[..n])?;
                let qd = joint_velocity(k, &q, &pose_of(vel))?;
                // q̈ = J⁻¹ (ẍ − J̇ q̇), J̇ q̇ by a central difference along q̇.
                let h = JDOT_STEP_S;
                let shifted = |sign: f64| {
                    let mut s = q;
                    for i in 0..n {
                        s[i] += sign * h * qd[i];
                    }
                    s
                };
                let (jp, jm) = (k.jacobian(&shifted(1.0))?, k.jacobian(&shifted(-1.0))?);
                let mut rhs = pose_of(acc);
                for (r, v) in rhs
                    .iter_mut()
                    .enumerate()
                    .take(self.p.coords.min(MAX_COORDS))
                {
                    let jdot_qd: f64 = (0..n)
                        .map(|i| (jp[(r, i)] - jm[(r, i)]) / (2.0 * h) * qd[i])
                        .sum();
                    *v -= jdot_qd;
                }
                let qdd = joint_velocity(k, &q, &rhs)?;
                Ok((axes_from(&q), axes_from(&qd), axes_from(&qdd), *pos, *vel))
            }
        }
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
    /// transition, the end of a speed ramp or of a `DELAY`, a `WAIT`'s timeout — for an exact
    /// extra wake-up: servo extrapolates each setpoint with its acceleration, so a change
    /// between two setpoints would show as a velocity step.
    pub fn next_transition_ns(&self) -> Option<u64> {
        let to_path = |target_s: f64| -> Option<f64> {
            let ahead = target_s - self.path_s_at_path_ns();
            let rate = 1.0 / self.p.t_acc.max(1e-3);
            let gap = self.target_speed - self.speed;
            if gap == 0.0 {
                // Constant speed: at 0 (paused) nothing changes until a resume.
                return (self.speed > 0.0).then(|| ahead / self.speed);
            }
            // Along the ramp the path advances s·τ + r·τ²/2: the instant, if it comes
            // before the ramp ends, else the ramp's end.
            let r = gap.signum() * rate;
            let ramp_end = gap.abs() / rate;
            let disc = self.speed * self.speed + 2.0 * r * ahead;
            let at = if disc >= 0.0 && ahead >= 0.0 {
                (-self.speed + disc.sqrt()) / r
            } else {
                f64::INFINITY
            };
            Some(if at.is_finite() && at >= 0.0 && at < ramp_end {
                at
            } else {
                ramp_end
            })
        };
        let at_path = |dt: f64| self.path_ns + (dt.max(0.0) * 1e9).ceil() as u64;
        match self.phase {
            Phase::Moving(seg) => to_path(self.origin_s + seg.transition_time()).map(at_path),
            Phase::Delaying { until_s } => to_path(until_s).map(at_path),
            Phase::Waiting { deadline_ns, .. } if deadline_ns > 0 => Some(deadline_ns),
            _ => None,
        }
    }

    /// The path time at `path_ns` (the last instant the speed ramp was brought up to).
    fn path_s_at_path_ns(&self) -> f64 {
        self.motion_time(self.path_ns) - self.lost_s
    }

    /// The outputs the program set since the last call (trajgen sends them to iobridge).
    ///
    /// # Real-time
    /// A copy.
    pub fn take_outputs(&mut self) -> Option<Outputs> {
        let o = core::mem::take(&mut self.outputs);
        (o.mask != 0).then_some(o)
    }

    /// Advances to `now_ns` with the inputs `inputs` (bit `k`: input `k` of the IO table, as
    /// iobridge last reported them; `None` when unknown) and returns the setpoint for it, in
    /// the running segment's space (the caller maps a Cartesian one to the joints).
    ///
    /// # Real-time
    /// No allocation, no system call: arithmetic on stack vectors and the fixed queue.
    pub fn step(&mut self, now_ns: u64, inputs: Option<u64>) -> SetpointV2 {
        let mut mt = self.path_time(now_ns);
        // Instructions that take no time (a WAIT met, a DELAY(0), an OUT) follow each other in
        // the same cycle, at most `PHASE_CHANGES` of them (a loop of them that never moves
        // goes on in the next cycle: bounded work).
        for _ in 0..PHASE_CHANGES {
            match self.phase {
                Phase::AtRest => {
                    self.take_at_rest(now_ns, None);
                    if !matches!(self.phase, Phase::AtRest | Phase::Moving(_)) {
                        mt = self.path_time(now_ns);
                        continue;
                    }
                }
                Phase::Waiting {
                    io,
                    value,
                    deadline_ns,
                    since_ns,
                } => {
                    let met = inputs.is_some_and(|v| (v >> io) & 1 == u64::from(value));
                    if met {
                        self.waited_s += now_ns.saturating_sub(since_ns) as f64 * 1e-9;
                        self.phase = Phase::AtRest;
                        continue;
                    }
                    if deadline_ns > 0 && now_ns >= deadline_ns {
                        self.waited_s += now_ns.saturating_sub(since_ns) as f64 * 1e-9;
                        self.phase = Phase::AtRest;
                        let line = self.line;
                        self.refuse(fault::WAIT_TIMEOUT, line);
                        self.finish(now_ns, MotionState::Fault);
                    }
                }
                Phase::Delaying { until_s } if mt >= until_s - REACHED_S => {
                    // What follows starts at the delay's exact end, however late this cycle.
                    self.phase = Phase::AtRest;
                    self.take_at_rest(now_ns, Some(until_s));
                    continue;
                }
                _ => {}
            }
            break;
        }
        // Take every transition the path time has passed, each at its exact instant.
        mt = self.path_time(now_ns);
        while let Phase::Moving(seg) = self.phase {
            if mt - self.origin_s < seg.transition_time() - REACHED_S {
                break;
            }
            self.transition(seg, now_ns);
        }
        if self.aborting && self.speed == 0.0 {
            self.drop_program(mt, now_ns);
        }
        let (pos, vel, acc) = match &self.phase {
            Phase::Moving(seg) => {
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
            _ => (self.rest, Axes::zeros(), Axes::zeros()),
        };
        let (q, qd, qdd, cp, cv) = match self.map(&pos, &vel, &acc) {
            Ok(m) => m,
            Err(e) => {
                // Out of the kinematics' reach mid-path (the prediction refuses such a
                // program): the program faults, the reference rests where it was.
                let line = self.line;
                self.unreachable(now_ns, e, line);
                let rest = self.joints;
                (rest, Axes::zeros(), Axes::zeros(), pos, Axes::zeros())
            }
        };
        self.joints = q;
        self.seq += 1;
        let motion_time_s = match self.state {
            MotionState::Moving => self.motion_time(now_ns),
            MotionState::Done | MotionState::Fault => self.end_motion_s,
            MotionState::Idle => 0.0,
        };
        let (hold_kind, hold_io) = match self.phase {
            Phase::Waiting { io, .. } => (hold::WAIT, io),
            Phase::Delaying { .. } => (hold::DELAY, 0),
            _ => (hold::NONE, 0),
        };
        let mut sp = SetpointV2 {
            seq: self.seq,
            stamp_ns: now_ns,
            motion_start_ns: self.motion_start_ns,
            motion_end_ns: self.motion_end_ns,
            motion_time_s,
            theoretical_s: self.theoretical_s,
            segment_time_s: match self.phase {
                Phase::Moving(s) => s.t1,
                _ => 0.0,
            },
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
            speed_override: self.speed_override,
            program_speed: self.program_speed,
            hold: hold_kind,
            hold_io,
            space: self.space as u32,
            coords: self.p.coords as u32,
            waited_s: self.waited_s,
            ..SetpointV2::default()
        };
        sp.position.copy_from_slice(q.as_slice());
        sp.velocity.copy_from_slice(qd.as_slice());
        sp.acceleration.copy_from_slice(qdd.as_slice());
        sp.cartesian.copy_from_slice(cp.as_slice());
        sp.cartesian_velocity.copy_from_slice(cv.as_slice());
        sp
    }

    /// The parameters it was built with.
    pub fn params(&self) -> Params {
        self.p
    }

    /// Commands read from the queue so far (the `seq` of the last one taken).
    pub fn commands_read(&self) -> u64 {
        self.commands_taken - self.queue.len as u64
    }

    /// How this generator is `earlier` moved on by one period of a loop of `commands`
    /// commands: `Some` when every part of its state that decides what it does next is
    /// `earlier`'s, but for the time (everything ahead by [`Period::path_s`]), the sequence
    /// numbers (ahead by `commands`) and the sums it keeps (motion time, time waited). Then
    /// what it does next is what `earlier` did, that much later: the prediction of a loop
    /// whose iterations are alike need not run them all ([`Generator::fast_forward`]).
    ///
    /// At rest, waiting or with the speed ramping, `None`: only a moving or delaying
    /// generator's time is its segment's (or its delay's) own.
    pub fn period_since(&self, earlier: &Generator, commands: u64) -> Option<Period> {
        // Every field named, so that a new one must be placed here: compared, or shifted.
        let Generator {
            p,
            queue,
            phase,
            space,
            origin_s,
            rest,
            state,
            motion_start_ns,
            motion_end_ns,
            end_motion_s,
            theoretical_s,
            program_id,
            line,
            fault,
            fault_line,
            commands_taken,
            starved,
            seq: _,
            speed,
            target_speed,
            speed_override,
            program_speed,
            aborting,
            lost_s,
            waited_s,
            path_ns: _,
            control_seq,
            exec_seq,
            outputs,
            kin: _,
            limits,
            joints,
            kin_error,
        } = self;
        let e = earlier;
        let path_s = match (phase, e.phase) {
            (Phase::Moving(s), Phase::Moving(t)) if *s == t => origin_s - e.origin_s,
            (Phase::Delaying { until_s }, Phase::Delaying { until_s: u }) => until_s - u,
            _ => return None,
        };
        let same = *p == e.p
            && *space == e.space
            && *rest == e.rest
            && *state == MotionState::Moving
            && e.state == MotionState::Moving
            && (*motion_start_ns, *motion_end_ns, *end_motion_s)
                == (e.motion_start_ns, e.motion_end_ns, e.end_motion_s)
            && (*program_id, *line, *fault, *fault_line)
                == (e.program_id, e.line, e.fault, e.fault_line)
            && *fault == fault::NONE
            && *commands_taken == e.commands_taken + commands
            && *exec_seq == e.exec_seq + commands
            // Path time is real time only at full speed, not ramping.
            && [*speed, *target_speed, e.speed, e.target_speed] == [1.0; 4]
            && (*speed_override, *program_speed, *aborting)
                == (e.speed_override, e.program_speed, e.aborting)
            && *control_seq == e.control_seq
            && *outputs == e.outputs
            && *limits == e.limits
            && kin_error.is_none()
            && e.kin_error.is_none()
            && queue.len == e.queue.len
            && (0..queue.len).all(|k| {
                let (mut a, b) = (
                    queue.items[(queue.head + k) % QUEUE_CAP],
                    e.queue.items[(e.queue.head + k) % QUEUE_CAP],
                );
                a.seq = a.seq.wrapping_sub(commands);
                a == b
            });
        let mut joints_apart: f64 = 0.0;
        for i in 0..p.axes {
            joints_apart = joints_apart.max((joints[i] - e.joints[i]).abs());
        }
        (same && path_s.is_finite() && path_s > 0.0).then_some(Period {
            path_s,
            theoretical_s: theoretical_s - e.theoretical_s,
            lost_s: lost_s - e.lost_s,
            waited_s: waited_s - e.waited_s,
            starved: starved.saturating_sub(e.starved),
            joints_apart,
        })
    }

    /// Moves the generator on by `n` periods of a loop of `commands` commands each
    /// ([`Generator::period_since`]), the time by `path_ns` (`n` times the period, to the
    /// nanosecond): as if it had run them. The caller's clock moves on by `path_ns` too, and
    /// the commands it sends next are numbered after the ones passed over.
    pub fn fast_forward(&mut self, period: &Period, n: u32, commands: u64, path_ns: u64) {
        let k = f64::from(n);
        let dt = path_ns as f64 * 1e-9;
        for i in 0..self.queue.len {
            self.queue.items[(self.queue.head + i) % QUEUE_CAP].seq += commands;
        }
        self.commands_taken += commands;
        self.exec_seq += commands;
        self.origin_s += dt;
        if let Phase::Delaying { until_s } = &mut self.phase {
            *until_s += dt;
        }
        self.path_ns += path_ns;
        self.theoretical_s += k * period.theoretical_s;
        self.lost_s += k * period.lost_s;
        self.waited_s += k * period.waited_s;
        self.starved = self
            .starved
            .saturating_add(period.starved.saturating_mul(n));
    }

    /// Executes the commands that take effect at once (`OUT`, `SPEED`) at the front of the
    /// queue; returns the next one that does not, without taking it.
    fn look_ahead(&mut self) -> Option<(MotionCommandV2, Option<CommandKind>)> {
        while let Some(c) = self.queue.front().copied() {
            let kind = CommandKind::from_wire(c.kind);
            match kind {
                Some(CommandKind::Out) => {
                    let bit = 1u64 << c.io;
                    self.outputs.mask |= bit;
                    if c.value == 1 {
                        self.outputs.values |= bit;
                    } else {
                        self.outputs.values &= !bit;
                    }
                    self.outputs.line = c.line;
                }
                Some(CommandKind::Speed) => self.program_speed = bounded_speed(c.speed),
                _ => return Some((c, kind)),
            }
            self.queue.pop();
            self.exec_seq = c.seq;
        }
        None
    }

    /// At rest (since path time `rest_s`, if known): takes the commands that follow.
    fn take_at_rest(&mut self, now_ns: u64, rest_s: Option<f64>) {
        while let Some((cmd, kind)) = self.look_ahead() {
            self.queue.pop();
            match kind {
                Some(CommandKind::Move | CommandKind::MoveJ) => {
                    self.start_from_rest(now_ns, rest_s, &cmd);
                    return;
                }
                Some(CommandKind::End) => {
                    if self.state != MotionState::Moving {
                        // A program without motion: done at once.
                        self.begin_program(now_ns, &cmd);
                    }
                    self.finish(now_ns, MotionState::Done);
                    self.line = cmd.line;
                    return;
                }
                Some(CommandKind::Wait) => {
                    self.begin_program(now_ns, &cmd);
                    self.exec_seq = cmd.seq;
                    self.line = cmd.line;
                    let timeout_ns = (cmd.time_s * 1e9) as u64;
                    self.phase = Phase::Waiting {
                        io: cmd.io,
                        value: cmd.value == 1,
                        deadline_ns: if timeout_ns > 0 {
                            now_ns + timeout_ns
                        } else {
                            0
                        },
                        since_ns: now_ns,
                    };
                    return;
                }
                Some(CommandKind::Delay) => {
                    let new = self.begin_program(now_ns, &cmd);
                    let at = self.rest_time(now_ns, rest_s, new);
                    self.exec_seq = cmd.seq;
                    self.line = cmd.line;
                    self.theoretical_s += cmd.time_s;
                    self.phase = Phase::Delaying {
                        until_s: at + cmd.time_s,
                    };
                    return;
                }
                // STOP at rest: nothing to do.
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
        if let Phase::Moving(seg) = self.phase {
            self.rest = seg.eval(mt - self.origin_s).0;
        }
        self.phase = Phase::AtRest;
        self.queue.clear();
        self.aborting = false;
        self.fault = fault::ABORTED;
        self.fault_line = self.line;
        self.finish(now_ns, MotionState::Fault);
    }

    fn finish(&mut self, now_ns: u64, state: MotionState) {
        // The next program starts at full programmed speed, and no abort carries over to it
        // (one that was ramping when the program reached its END, or a fault, is done).
        self.program_speed = 1.0;
        self.aborting = false;
        self.speed = self.speed_override;
        self.target_speed = self.speed_override;
        self.state = state;
        self.motion_end_ns = now_ns;
        self.end_motion_s = self.motion_time(now_ns);
    }

    /// Makes `seg` the running segment, its local time 0 at motion time `origin`.
    fn begin(&mut self, seg: Segment, origin: f64, line: u32) {
        self.phase = Phase::Moving(seg);
        self.origin_s = origin;
        self.theoretical_s += seg.t1;
        self.line = line;
    }

    /// At rest on `seg`'s target: the resting point, and the phase.
    fn come_to_rest(&mut self, seg: &Segment) {
        self.rest = seg.c;
        self.phase = Phase::AtRest;
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
        match self.look_ahead() {
            Some((cmd, kind @ Some(CommandKind::Move | CommandKind::MoveJ)))
                if Self::space_of(kind) == self.space =>
            {
                self.queue.pop();
                self.exec_seq = cmd.seq;
                let c = axes_of(&self.p, &cmd.target);
                let t1 = self.time_between(self.space, &seg.c, &c, cmd.time_s);
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
            // END, WAIT, DELAY or a move in the other space, with the axes at rest on the
            // target: it takes effect at rest, now (at the exact instant of the rest).
            Some(_) if seg.stops() => {
                let rest_s = self.origin_s + seg.transition_time();
                self.come_to_rest(&seg);
                self.take_at_rest(now_ns, Some(rest_s));
            }
            // …while moving: stop on the target first; the command stays queued.
            Some(_) => self.begin(stop, origin, self.line),
            None if seg.stops() => {
                // Queue empty, axes at rest: wait here (after a fault, the motion ends here).
                self.come_to_rest(&seg);
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

/// A speed share bounded to `MIN_SPEED..=1` (1 for anything not finite).
fn bounded_speed(v: f64) -> f64 {
    if v.is_finite() {
        shm_schema::bound(v, MIN_SPEED, 1.0)
    } else {
        1.0
    }
}

/// The kinematics' joint array of `v`.
fn joints_of(v: &Axes) -> kinematics::Joints {
    let mut q = [0.0; kinematics::MAX_JOINTS];
    q.copy_from_slice(v.as_slice());
    q
}

/// The kinematics' pose of `v` (its first coordinates).
fn pose_of(v: &Axes) -> kinematics::Pose {
    let mut p = [0.0; MAX_COORDS];
    p.copy_from_slice(&v.as_slice()[..MAX_COORDS]);
    p
}

/// `q` as stack axes.
fn axes_from(q: &kinematics::Joints) -> Axes {
    Axes::from_column_slice(q)
}

/// The axes in use of a wire array (the rest zero).
fn axes_of(p: &Params, v: &[f64; MAX_AXES]) -> Axes {
    let n = p.axes.max(p.coords).min(MAX_AXES);
    let mut t = Axes::zeros();
    t.as_mut_slice()[..n].copy_from_slice(&v[..n]);
    t
}
