//! Servo: the servo layer of seed 001 (Stäubli's low-level interface) on top of CiA 402
//! drives, and the axes' position loops (seed 003 §3). It runs at its own period at all
//! times, also when no setpoint comes: its job is not to keep motion time but to keep the axes
//! stable and safe.
//!
//! **Power** (seed 001's `LLI_enable`/`LLI_disable`, `LLI_state`). The arm starts disabled.
//! An enable request (`<i>/servo/request`) starts the enabling sequence in the next cycle:
//! every drive is stepped Shutdown → Switch on → Enable operation ([`cia402::enable_step`]);
//! the arm is enabled when every axis is in Operation enabled, and an error if that takes
//! longer than the enable timeout. A disable request starts the disabling sequence and aborts
//! a pending enable: an enabled arm first comes to rest along its path, then the drives take
//! Shutdown (transition 8). Servo follows setpoints only while
//! enabled; otherwise its reference follows the measured position (bumpless enable: the
//! drives' targets equal the actual position, the integrators are cleared).
//!
//! **Faults are latched.** Each of these cuts power (quick stop on every axis, then disable
//! voltage) and stays latched until a reset request, after which an enable request is needed:
//! - command validation every cycle (seed 001's rule for `LLI_set`): the commanded position
//!   outside the joint range, a commanded velocity over its limit, a position step or a
//!   velocity step per servo period over its limit (steps are scaled by the real time since
//!   the previous cycle, so a late cycle is not a step), a value that is not finite;
//! - feedback that is not finite (a lost encoder, an unstable simulation), or older than the
//!   feedback timeout while powered (the drives went silent);
//! - a following error over its limit (a device e-stop);
//! - a drive in Fault, or a drive leaving Operation enabled without being asked.
//!
//! A reset request resets the drives' faults (bit 7 edge, [`cia402::FaultReset`]) and clears
//! the latch once the cut has run its course (every drive at rest and without power, none in
//! Fault) and the feedback is fresh and valid; otherwise it is refused.
//! **No drive ever re-enables by itself**: power comes back only through reset, then enable.
//!
//! **Reference.** Each cycle the latest trajgen setpoint is extrapolated to now (constant
//! acceleration, the velocity never beyond vmax: trajgen's trajectory is a function of real
//! time, so a servo faster than trajgen gets a smooth reference and a late setpoint costs
//! nothing), for at most the setpoint timeout. When trajgen was late, the next setpoint differs
//! a little from the extrapolation; that difference is blended out over two trajgen periods
//! (a cubic offset), so the command never steps (a large difference is left to command
//! validation). After that the setpoint is stale (trajgen stalled or died): the
//! reference decelerates to rest at the axis' stop deceleration and holds, and only a new
//! setpoint that starts where it holds is taken again. The first setpoint of a source (after
//! enabling, after a stale spell, after trajgen restarted) must start where servo holds, or
//! it is refused and servo holds; after that, command validation judges every step.
//!
//! **Modes.** In CST (the default) servo closes the position loop: PID on the position error
//! with velocity and acceleration feed-forward, the effort as target torque. In CSP the drive
//! closes it: servo sends the reference as target position, its velocity as velocity offset
//! and the feed-forward effort as torque offset. In CSV servo closes the position loop with
//! `kp` in (unit/s)/unit and the drive closes the velocity loop.
//!
//! **Settled**: an axis is settled when |following error| ≤ `in_position` and |measured
//! velocity| ≤ `settle_velocity` have held for the settle time.

use cia402::{FaultReset, Mode, State, cw, disable_step, enable_step};
use shm_schema::drive::servo_status as st;
use shm_schema::event::{EventQueue, code};
use shm_schema::{
    AxisConfigV2, CellConfigV6, DriveCommandV2, DriveFeedbackV2, EstopReaction, EventV1, MAX_AXES,
    Power, RequestKind, ServoRequestV1, ServoStateV3, SetpointV2, bound, str_of,
};

/// Parameters of the controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Axes in use.
    pub axes: usize,
    /// Per-axis limits, gains and modes, as configured.
    pub axis: [AxisConfigV2; MAX_AXES],
    /// Servo period (s).
    pub period_s: f64,
    /// Longest extrapolation of a setpoint (s); then the reference comes to rest.
    pub max_extrapolation_s: f64,
    /// How long a late setpoint's small difference is blended out (s): two trajgen periods.
    pub rejoin_s: f64,
    /// Drive feedback older than this cuts power while powered (ns).
    pub feedback_timeout_ns: u64,
    /// Longest enabling sequence (ns).
    pub enable_timeout_ns: u64,
    /// Time within tolerance to be settled (ns).
    pub settle_time_ns: u64,
    /// On an e-stop every axis comes from its vmax to rest within this time (s).
    pub estop_stop_time_s: f64,
}

impl Params {
    /// From the cell configuration, for a servo of period `period_ns` fed setpoints every
    /// `trajgen_ns`.
    pub fn from_cell(cell: &CellConfigV6, period_ns: u64, trajgen_ns: u64) -> Self {
        Self {
            axes: cell.axes as usize,
            axis: cell.axis,
            period_s: period_ns as f64 * 1e-9,
            max_extrapolation_s: cell.setpoint_timeout_ns as f64 * 1e-9,
            rejoin_s: 2.0 * trajgen_ns as f64 * 1e-9,
            estop_stop_time_s: cell.estop_stop_time_ns as f64 * 1e-9,
            feedback_timeout_ns: cell.feedback_timeout_ns,
            enable_timeout_ns: cell.enable_timeout_ns,
            settle_time_ns: cell.settle_time_ns,
        }
    }
}

/// A latched fault: what cut power.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Latched {
    /// Event code of the cause.
    pub code: u32,
    /// Axis, -1 for the arm.
    pub axis: i32,
    /// The value that tripped it.
    pub value: f64,
    /// The limit it exceeded.
    pub limit: f64,
}

/// The controller state. Construct at set-up; [`Controller::cycle`] runs every cycle.
#[derive(Clone, Debug)]
pub struct Controller {
    p: Params,
    /// Each axis' configured mode of operation, as sent (0x6060) and decoded (set-up).
    mode_word: [i8; MAX_AXES],
    mode: [Option<Mode>; MAX_AXES],
    power: Power,
    power_since_ns: u64,
    latched: Option<Latched>,
    /// A reset request is in progress since this time.
    resetting_since: Option<u64>,
    fault_reset: [FaultReset; MAX_AXES],
    request_seq: u64,
    setpoint: Option<SetpointV2>,
    /// The reference of the last cycle: position, velocity.
    ref_pos: [f64; MAX_AXES],
    ref_vel: [f64; MAX_AXES],
    integral: [f64; MAX_AXES],
    in_tolerance_since: [u64; MAX_AXES],
    feedback_seq: u64,
    feedback_new_ns: u64,
    stale_setpoint: bool,
    jump_reported: bool,
    rejoin: Rejoin,
    /// A disable request found the arm enabled: the reference comes to rest before power
    /// goes off.
    stopping: bool,
    /// The e-stop this process reacts to, as the runtime read it.
    estop: Option<EstopReaction>,
    /// Every axis' measured velocity within its settle velocity (latest feedback).
    measured_at_rest: bool,
    /// Tuning offsets of the reference (axis unit).
    tune_offset: [f64; MAX_AXES],
    /// The offset of this axis changed this cycle: its position step is the requested one.
    tune_step: [bool; MAX_AXES],
    /// The tuning offsets the reference of the last cycle includes.
    applied_offset: [f64; MAX_AXES],
    last_ns: u64,
    /// Real time since the previous cycle (s).
    elapsed_s: f64,
    seq: u64,
    peak: Peak,
}

/// The largest |following error| per axis since a program's first setpoint, latched by servo
/// in every cycle so a run's verdict never depends on which states a reader saw.
#[derive(Clone, Copy, Debug, Default)]
struct Peak {
    program: u32,
    fe: [f64; MAX_AXES],
}

impl Peak {
    /// Takes the following errors of a cycle that follows program `program`'s setpoints.
    ///
    /// # Real-time
    /// Arithmetic only.
    fn note(&mut self, program: u32, fe: &[f64]) {
        if program != self.program {
            *self = Self {
                program,
                ..Self::default()
            };
        }
        for (m, e) in self.fe.iter_mut().zip(fe) {
            // A NaN never lowers the figure (f64::max ignores it): it is a fault elsewhere.
            *m = m.max(e.abs());
        }
    }

    fn publish(&self, state: &mut ServoStateV3) {
        state.peak_program = self.program;
        state.peak_following_error = self.fe;
    }
}

/// The setpoint `sp` of axis `i` extrapolated `h` seconds (back in time when negative):
/// constant acceleration, forward never beyond `vmax` (trajgen's velocity never is). Returns
/// position, velocity, acceleration.
///
/// # Real-time
/// Arithmetic only; never panics (no clamp with crossed bounds).
fn extrapolate(sp: &SetpointV2, i: usize, h: f64, vmax: f64) -> (f64, f64, f64) {
    let (p, v, a) = (sp.position[i], sp.velocity[i], sp.acceleration[i]);
    let v_end = v + a * h;
    // Backwards (h < 0, a setpoint newer than servo's cycle) the trajectory was within vmax.
    if v_end.abs() <= vmax || a == 0.0 || h <= 0.0 {
        return (p + v * h + 0.5 * a * h * h, v_end, a);
    }
    let lim = vmax.copysign(v_end);
    let t1 = bound((lim - v) / a, 0.0, h);
    (p + v * t1 + 0.5 * a * t1 * t1 + lim * (h - t1), lim, 0.0)
}

/// The share of the acceleration command validation allows (the velocity step limit per
/// period) that a re-join's offset may add to the new setpoint's own acceleration.
const REJOIN_SHARE: f64 = 0.8;

/// The shortest time a re-join from offset `p0`, `v0` may take so that its acceleration
/// stays within `budget`: the Hermite offset's acceleration is largest at its ends, at most
/// `(6 |p0| / d + 4 |v0|) / d`.
///
/// # Real-time
/// Arithmetic only.
fn rejoin_time(p0: f64, v0: f64, budget: f64) -> f64 {
    let (p, v) = (p0.abs(), v0.abs());
    if budget <= 0.0 || (p == 0.0 && v == 0.0) {
        return 0.0;
    }
    (4.0 * v + (16.0 * v * v + 24.0 * p * budget).sqrt()) / (2.0 * budget)
}

/// A re-join in progress: an offset of the reference from the newest setpoint's
/// extrapolation that starts at (`p0`, `v0`) and goes to 0 along a cubic (Hermite) curve over
/// `duration_s`, so taking a late setpoint never steps the command.
#[derive(Clone, Copy, Debug, Default)]
struct Rejoin {
    start_ns: u64,
    duration_s: f64,
    p0: [f64; MAX_AXES],
    v0: [f64; MAX_AXES],
}

impl Rejoin {
    /// The offset (position, velocity) per axis at `now_ns`.
    fn offset(&self, now_ns: u64) -> ([f64; MAX_AXES], [f64; MAX_AXES]) {
        let mut p = [0.0; MAX_AXES];
        let mut v = [0.0; MAX_AXES];
        let t = now_ns.saturating_sub(self.start_ns) as f64 * 1e-9;
        if self.duration_s <= 0.0 || t >= self.duration_s {
            return (p, v);
        }
        let d = self.duration_s;
        let s = t / d;
        let (h00, h10) = (
            2.0 * s * s * s - 3.0 * s * s + 1.0,
            s * s * s - 2.0 * s * s + s,
        );
        let (d00, d10) = (6.0 * s * s - 6.0 * s, 3.0 * s * s - 4.0 * s + 1.0);
        for i in 0..MAX_AXES {
            p[i] = h00 * self.p0[i] + h10 * d * self.v0[i];
            v[i] = (d00 * self.p0[i]) / d + d10 * self.v0[i];
        }
        (p, v)
    }
}

/// What one cycle decided for the drives and for servo's state (internal).
struct Out {
    cmd: DriveCommandV2,
    state: ServoStateV3,
}

impl Controller {
    /// A controller that has seen nothing yet: the arm disabled.
    pub fn new(p: Params) -> Self {
        let mode_word = core::array::from_fn(|i| p.axis[i].mode as i8);
        Self {
            p,
            mode_word,
            mode: mode_word.map(Mode::from_i8),
            power: Power::Disabled,
            power_since_ns: 0,
            latched: None,
            resetting_since: None,
            fault_reset: [FaultReset::new(); MAX_AXES],
            request_seq: 0,
            setpoint: None,
            ref_pos: [0.0; MAX_AXES],
            ref_vel: [0.0; MAX_AXES],
            integral: [0.0; MAX_AXES],
            in_tolerance_since: [0; MAX_AXES],
            feedback_seq: 0,
            feedback_new_ns: 0,
            stale_setpoint: false,
            jump_reported: false,
            rejoin: Rejoin::default(),
            stopping: false,
            estop: None,
            measured_at_rest: true,
            tune_offset: [0.0; MAX_AXES],
            tune_step: [false; MAX_AXES],
            applied_offset: [0.0; MAX_AXES],
            last_ns: 0,
            elapsed_s: 0.0,
            peak: Peak::default(),
            seq: 0,
        }
    }

    /// The e-stop this cycle, as the runtime read it (call before [`Controller::cycle`]).
    /// `Stop`: the axes come to rest at the e-stop deceleration (from vmax to rest within the
    /// e-stop stop time, never slower than the axis' stop deceleration), then the drives are
    /// disabled; `Hold`: they come to rest the same way and stay enabled, holding. Either way
    /// no setpoint is followed and no enable or step is taken until the e-stop is reset
    /// (`None`); after a `Stop`, power returns only through an enable request.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn set_estop(
        &mut self,
        now_ns: u64,
        react: Option<EstopReaction>,
        events: &mut EventQueue,
    ) {
        let react = react.filter(|r| *r != EstopReaction::Ignore);
        if react == self.estop {
            return;
        }
        if react.is_some() {
            self.setpoint = None;
        }
        if react == Some(EstopReaction::Stop)
            && matches!(self.power, Power::Enabling | Power::Enabled)
        {
            self.stopping = self.power == Power::Enabled && self.latched.is_none();
            self.set_power(Power::Disabling, now_ns);
            events.push(EventV1::new(
                now_ns,
                code::DISABLING,
                -1,
                0.0,
                0.0,
                &["e-stop"],
            ));
        }
        self.estop = react;
    }

    /// True when the e-stop reaction is complete: the axes at rest (reference and measured)
    /// and, unless holding, every drive disabled.
    pub fn estop_safe(&self) -> bool {
        let at_rest =
            self.measured_at_rest && self.ref_vel[..self.p.axes].iter().all(|v| *v == 0.0);
        match self.estop {
            Some(EstopReaction::Hold) => at_rest || self.power == Power::Disabled,
            _ => self.power == Power::Disabled && self.measured_at_rest,
        }
    }

    /// The latched fault, if any.
    pub fn latched(&self) -> Option<Latched> {
        self.latched
    }

    /// The deceleration that brings axis `i` to rest when no setpoint is followed.
    fn stop_deceleration(&self, i: usize) -> f64 {
        let a = &self.p.axis[i];
        if self.estop.is_some() && self.p.estop_stop_time_s > 0.0 {
            a.stop_deceleration.max(a.vmax / self.p.estop_stop_time_s)
        } else {
            a.stop_deceleration
        }
    }

    /// Latches a fault (the first cause wins), cuts power and reports both.
    fn latch(&mut self, now_ns: u64, l: Latched, text: &[&str], events: &mut EventQueue) {
        if self.latched.is_some() {
            return;
        }
        self.latched = Some(l);
        self.resetting_since = None;
        self.stopping = false;
        events.push(EventV1::new(now_ns, l.code, l.axis, l.value, l.limit, text));
        events.push(EventV1::new(
            now_ns,
            code::POWER_CUT,
            l.axis,
            l.code as f64,
            0.0,
            &["quick stop, then disable voltage; latched until reset"],
        ));
        if self.power != Power::Disabled {
            self.set_power(Power::Disabling, now_ns);
        }
        self.setpoint = None;
    }

    fn set_power(&mut self, p: Power, now_ns: u64) {
        self.power = p;
        self.power_since_ns = now_ns;
        if p != Power::Disabling {
            // Not while disabling: the reference still holds the offset as it comes to rest.
            self.tune_offset = [0.0; MAX_AXES];
            self.applied_offset = [0.0; MAX_AXES];
        }
    }

    /// Takes a request (seed 001: it takes effect in this cycle).
    fn request(
        &mut self,
        now_ns: u64,
        r: &ServoRequestV1,
        feedback_ok: bool,
        events: &mut EventQueue,
    ) {
        self.request_seq = r.seq;
        let refuse = |why: &str, events: &mut EventQueue| {
            events.push(EventV1::new(
                now_ns,
                code::REQUEST_REFUSED,
                -1,
                r.kind as f64,
                0.0,
                &[why],
            ));
        };
        match RequestKind::from_wire(r.kind) {
            Some(RequestKind::Enable) => {
                if self.estop.is_some() {
                    refuse("enable refused: the e-stop is latched, reset first", events);
                } else if self.latched.is_some() {
                    refuse("enable refused: a fault is latched, reset first", events);
                } else if !feedback_ok {
                    refuse("enable refused: no valid drive feedback", events);
                } else if matches!(self.power, Power::Disabled | Power::Disabling) {
                    self.set_power(Power::Enabling, now_ns);
                    events.push(EventV1::new(now_ns, code::ENABLING, -1, 0.0, 0.0, &[]));
                }
            }
            Some(RequestKind::Disable) => {
                if matches!(self.power, Power::Enabling | Power::Enabled) {
                    // An enabled arm first comes to rest along its path (the setpoint is
                    // dropped, the reference decelerates), then powers down (Shutdown).
                    self.stopping = self.power == Power::Enabled;
                    self.setpoint = None;
                    self.set_power(Power::Disabling, now_ns);
                    events.push(EventV1::new(now_ns, code::DISABLING, -1, 0.0, 0.0, &[]));
                }
            }
            Some(RequestKind::Reset) => {
                if self.latched.is_some() {
                    self.resetting_since = Some(now_ns);
                    self.fault_reset = [FaultReset::new(); MAX_AXES];
                }
            }
            Some(RequestKind::Step) => match self.step_refusal(r) {
                Some(why) => refuse(why, events),
                None => {
                    let i = r.axis as usize;
                    self.tune_step[i] = true;
                    self.tune_offset[i] = r.value;
                    events.push(EventV1::new(
                        now_ns,
                        code::TUNE_STEP,
                        i as i32,
                        r.value,
                        0.0,
                        &[],
                    ));
                }
            },
            None => refuse("unknown request kind", events),
        }
    }

    /// Why a `Step` request cannot be taken now, if it cannot.
    fn step_refusal(&self, r: &ServoRequestV1) -> Option<&'static str> {
        let i = r.axis as usize;
        if i >= self.p.axes {
            return Some("step refused: no such axis");
        }
        let a = &self.p.axis[i];
        let at_rest = self.ref_vel[..self.p.axes].iter().all(|v| *v == 0.0)
            && self
                .setpoint
                .is_none_or(|sp| sp.velocity[..self.p.axes].iter().all(|v| *v == 0.0));
        let target = self.ref_pos[i] - self.tune_offset[i] + r.value;
        if self.power != Power::Enabled || self.latched.is_some() || self.estop.is_some() {
            Some("step refused: the arm is not enabled")
        } else if !at_rest {
            Some("step refused: the axes are moving")
        } else if !(r.value.is_finite() && r.value.abs() <= a.following_error_limit / 2.0) {
            Some("step refused: larger than half the following-error limit")
        } else if target < a.min || target > a.max {
            Some("step refused: it would leave the axis range")
        } else {
            None
        }
    }

    /// Checks the feedback; latches what is wrong with it. True when it can be used.
    fn check_feedback(&mut self, now_ns: u64, fb: &DriveFeedbackV2, ev: &mut EventQueue) -> bool {
        let n = self.p.axes;
        if fb.seq != self.feedback_seq {
            self.feedback_seq = fb.seq;
            self.feedback_new_ns = now_ns;
        }
        if fb.axes as usize != n {
            let l = Latched {
                code: code::FEEDBACK_MISMATCH,
                axis: -1,
                value: f64::from(fb.axes),
                limit: n as f64,
            };
            self.latch(now_ns, l, &["the drives report another number of axes"], ev);
            return false;
        }
        for i in 0..n {
            let bad = [fb.position[i], fb.velocity[i], fb.torque[i]]
                .iter()
                .any(|v| !v.is_finite());
            if bad {
                let l = Latched {
                    code: code::FEEDBACK_NOT_FINITE,
                    axis: i as i32,
                    value: fb.position[i],
                    limit: 0.0,
                };
                let nb = self.p.axis[i].name;
                self.latch(
                    now_ns,
                    l,
                    &[str_of(&nb), ": feedback is not a finite number"],
                    ev,
                );
                return false;
            }
        }
        let age = now_ns.saturating_sub(self.feedback_new_ns);
        let powered = (0..n)
            .any(|i| State::from_statusword(fb.statusword[i]).is_some_and(|s| s.power_stage_on()));
        if age > self.p.feedback_timeout_ns {
            if powered || self.power != Power::Disabled {
                let l = Latched {
                    code: code::FEEDBACK_STALE,
                    axis: -1,
                    value: age as f64 * 1e-9,
                    limit: self.p.feedback_timeout_ns as f64 * 1e-9,
                };
                self.latch(now_ns, l, &["no new drive feedback"], ev);
            }
            return false;
        }
        for i in 0..n {
            let s = State::from_statusword(fb.statusword[i]);
            let nb = self.p.axis[i].name;
            let name = str_of(&nb);
            if matches!(s, Some(State::Fault | State::FaultReactionActive)) {
                if self.resetting_since.is_none() {
                    let l = Latched {
                        code: code::DRIVE_REPORTS_FAULT,
                        axis: i as i32,
                        value: fb.error_code[i] as f64,
                        limit: 0.0,
                    };
                    let why = cia402::error_code::name(fb.error_code[i]);
                    self.latch(now_ns, l, &[name, ": ", why], ev);
                }
            } else if self.power == Power::Enabled && fb.mode_display[i] != self.mode_word[i] {
                let l = Latched {
                    code: code::FEEDBACK_MISMATCH,
                    axis: i as i32,
                    value: f64::from(fb.mode_display[i]),
                    limit: f64::from(self.p.axis[i].mode),
                };
                self.latch(now_ns, l, &[name, ": the drive runs another mode"], ev);
            } else if self.power == Power::Enabled && s != Some(State::OperationEnabled) {
                let l = Latched {
                    code: code::DRIVE_LOST_ENABLE,
                    axis: i as i32,
                    value: fb.statusword[i] as f64,
                    limit: 0.0,
                };
                let now_in = s.map_or("an unknown state", State::name);
                self.latch(now_ns, l, &[name, ": ", now_in], ev);
            }
        }
        true
    }

    /// The reference at `now_ns` from the held setpoint, or coming to rest without one.
    /// Returns (position, velocity, acceleration) per axis.
    fn reference(
        &mut self,
        now_ns: u64,
        dt: f64,
        events: &mut EventQueue,
    ) -> ([f64; MAX_AXES], [f64; MAX_AXES], [f64; MAX_AXES]) {
        let n = self.p.axes;
        let (mut pos, mut vel, mut acc) = (self.ref_pos, [0.0; MAX_AXES], [0.0; MAX_AXES]);
        if let Some(sp) = self.setpoint {
            let h = (now_ns as i128 - sp.stamp_ns as i128) as f64 * 1e-9;
            if h <= self.p.max_extrapolation_s {
                let (off_p, off_v) = self.rejoin.offset(now_ns);
                for i in 0..n {
                    let (p, v, a) = extrapolate(&sp, i, self.bounded_age(h), self.p.axis[i].vmax);
                    pos[i] = p + off_p[i] + self.tune_offset[i];
                    vel[i] = v + off_v[i];
                    acc[i] = a;
                }
                self.stale_setpoint = false;
                self.applied_offset = self.tune_offset;
                return (pos, vel, acc);
            }
            // Stale: trajgen stalled or died. Come to rest from here; only a setpoint that
            // starts where the reference holds is taken again.
            self.setpoint = None;
            if !self.stale_setpoint {
                self.stale_setpoint = true;
                events.push(EventV1::new(
                    now_ns,
                    code::SETPOINT_STALE,
                    -1,
                    h,
                    self.p.max_extrapolation_s,
                    &["trajgen is silent; the reference comes to rest"],
                ));
            }
        }
        for i in 0..n {
            let v = self.ref_vel[i];
            let dv = self.stop_deceleration(i) * dt;
            let v_new = if v.abs() <= dv {
                0.0
            } else {
                v - dv * v.signum()
            };
            pos[i] = self.ref_pos[i] + 0.5 * (v + v_new) * dt + self.tune_offset[i]
                - self.applied_offset[i];
            vel[i] = v_new;
            acc[i] = (v_new - v) / dt.max(1e-9);
        }
        self.applied_offset = self.tune_offset;
        (pos, vel, acc)
    }

    /// Before taking `sp` from the same source: the reference it gives now differs from the
    /// one the held setpoint (and a re-join in progress) gives by the extrapolation's error
    /// over the time trajgen was late, or since the trajectory's acceleration last changed (a
    /// trapezoid's acceleration jumps; servo extrapolates the last one). A difference a
    /// trajectory within the limits can make is blended out ([`Rejoin`]); a larger one is
    /// left for command validation to judge (it is a step, not a late setpoint), and only the
    /// offset already being blended goes on.
    ///
    /// Within the limits: the acceleration command validation allows, `a_lim` (the velocity
    /// step limit per period), for as long as the held setpoint was extrapolated, `g`: the two
    /// extrapolations then differ by at most `2 a_lim g` in velocity and `a_lim g²` in
    /// position (or by the in-position band and 5 % of vmax, whichever is larger). The blend
    /// lasts two trajgen periods, or longer where that would make the command accelerate by
    /// more than [`REJOIN_SHARE`] of `a_lim` beside the new setpoint's own acceleration
    /// ([`rejoin_time`]): the command then never steps by more than validation allows.
    fn rejoin_to(&mut self, sp: &SetpointV2, now_ns: u64) {
        let Some(prev) = self.setpoint else {
            self.rejoin = Rejoin::default();
            return;
        };
        let (off_p, off_v) = self.rejoin.offset(now_ns);
        let age =
            |s: &SetpointV2| self.bounded_age((now_ns as i128 - s.stamp_ns as i128) as f64 * 1e-9);
        let g = age(&prev).max(0.0);
        let mut d_p = [0.0; MAX_AXES];
        let mut d_v = [0.0; MAX_AXES];
        let mut small = true;
        let mut budget = [0.0; MAX_AXES];
        for i in 0..self.p.axes {
            let a = &self.p.axis[i];
            let (po, vo, _) = extrapolate(&prev, i, age(&prev), a.vmax);
            let (pn, vn, an) = extrapolate(sp, i, age(sp), a.vmax);
            // The new difference is judged; the offset still being blended was judged before.
            d_p[i] = po - pn;
            d_v[i] = vo - vn;
            let a_lim = a.velocity_step_limit / self.p.period_s;
            small &= d_p[i].abs() <= a.in_position.max(a_lim * g * g)
                && d_v[i].abs() <= (0.05 * a.vmax).max(2.0 * a_lim * g);
            budget[i] = (REJOIN_SHARE * a_lim - an.abs()).max(0.1 * a_lim);
        }
        // A step (not small) is left in the command; the offset in progress goes on.
        let mut duration = self.p.rejoin_s;
        for i in 0..self.p.axes {
            if small {
                d_p[i] += off_p[i];
                d_v[i] += off_v[i];
            } else {
                d_p[i] = off_p[i];
                d_v[i] = off_v[i];
            }
            duration = duration.max(rejoin_time(d_p[i], d_v[i], budget[i]));
        }
        self.rejoin = Rejoin {
            start_ns: now_ns,
            duration_s: duration,
            p0: d_p,
            v0: d_v,
        };
    }

    /// The age of a setpoint at servo's time, as used to evaluate it. It can be negative: servo
    /// takes its time when it wakes, and a host stall between that and reading the setpoint
    /// lets trajgen publish one stamped after it; servo then evaluates the trajectory back at
    /// its own time (clamping to the setpoint's stamp would step the reference ahead by the
    /// stall). Bounded by the setpoint timeout either way.
    fn bounded_age(&self, h: f64) -> f64 {
        bound(h, -self.p.max_extrapolation_s, self.p.max_extrapolation_s)
    }

    /// A setpoint from a new source (the first one, one after a stale spell, or one whose
    /// stamp goes back: trajgen restarted) must start where servo holds: within the
    /// in-position band plus what the axis can move in 1.5 cycles, and at the reference's
    /// velocity within one velocity step. Returns the first test it fails: its axis, the
    /// event code (position or velocity), the value and the limit. Setpoints of the same
    /// source are checked by command validation instead (a step too large cuts power).
    fn jump(&self, sp: &SetpointV2, now_ns: u64, dt: f64) -> Option<(usize, u32, f64, f64)> {
        if self
            .setpoint
            .is_some_and(|prev| prev.seq != sp.seq && sp.stamp_ns >= prev.stamp_ns)
        {
            return None;
        }
        let age = self.bounded_age((now_ns as i128 - sp.stamp_ns as i128) as f64 * 1e-9);
        let scale = (dt / self.p.period_s).max(1.0);
        (0..self.p.axes).find_map(|i| {
            let at_now = sp.position[i] + sp.velocity[i] * age;
            let d = (at_now - self.ref_pos[i]).abs();
            let dv = (sp.velocity[i] - self.ref_vel[i]).abs();
            let (d_max, dv_max) = (
                self.start_tolerance(i, dt),
                self.p.axis[i].velocity_step_limit * scale,
            );
            if d > d_max {
                Some((i, code::SETPOINT_JUMP, d, d_max))
            } else if dv > dv_max {
                Some((i, code::SETPOINT_VELOCITY_JUMP, dv, dv_max))
            } else {
                None
            }
        })
    }

    /// How far a new source's first setpoint may lie from where servo holds: what the axis
    /// moves in 1.5 cycles plus the in-position band, but never more than one position step
    /// command validation allows (so a setpoint it takes is never a step it would refuse).
    fn start_tolerance(&self, i: usize, dt: f64) -> f64 {
        let g = &self.p.axis[i];
        let scale = (dt / self.p.period_s).max(1.0);
        (g.vmax * dt * 1.5 + g.in_position).min(g.position_step_limit * scale)
    }

    /// Command validation (seed 001's rule for `LLI_set`): the first rule the command breaks.
    fn validate(
        &self,
        pos: &[f64; MAX_AXES],
        vel: &[f64; MAX_AXES],
    ) -> Option<(Latched, &'static str)> {
        // A late cycle is not a step: the limits scale with the real time since the
        // previous cycle (never below one period).
        let scale = (self.elapsed_s / self.p.period_s).max(1.0);
        for i in 0..self.p.axes {
            let a = &self.p.axis[i];
            let at = |code, value, limit| Latched {
                code,
                axis: i as i32,
                value,
                limit,
            };
            if !(pos[i].is_finite() && vel[i].is_finite()) {
                return Some((at(code::COMMAND_NOT_FINITE, pos[i], 0.0), "not a number"));
            }
            let tol = a.encoder_resolution;
            if pos[i] < a.min - tol {
                return Some((at(code::POSITION_OUT_OF_RANGE, pos[i], a.min), "below min"));
            }
            if pos[i] > a.max + tol {
                return Some((at(code::POSITION_OUT_OF_RANGE, pos[i], a.max), "above max"));
            }
            if vel[i].abs() > a.velocity_limit {
                let l = at(code::VELOCITY_OVER_LIMIT, vel[i], a.velocity_limit);
                return Some((l, "velocity"));
            }
            let step = pos[i] - self.ref_pos[i];
            // A requested tuning step is the one step let through (bounded when requested).
            if !self.tune_step[i] && step.abs() > a.position_step_limit * scale {
                let l = at(
                    code::POSITION_STEP_OVER_LIMIT,
                    step / scale,
                    a.position_step_limit,
                );
                return Some((l, "position step"));
            }
            let vstep = vel[i] - self.ref_vel[i];
            if vstep.abs() > a.velocity_step_limit * scale {
                let l = at(
                    code::VELOCITY_STEP_OVER_LIMIT,
                    vstep / scale,
                    a.velocity_step_limit,
                );
                return Some((l, "velocity step"));
            }
        }
        None
    }

    /// One servo cycle at `now_ns`: the newest request, setpoint and drive feedback (each if
    /// one arrived; `feedback` is the newest ever received). Events go to `events`.
    ///
    /// # Real-time
    /// Arithmetic and copies only; no allocation, no system call.
    pub fn cycle(
        &mut self,
        now_ns: u64,
        request: Option<&ServoRequestV1>,
        new_setpoint: Option<&SetpointV2>,
        feedback: Option<&DriveFeedbackV2>,
        events: &mut EventQueue,
    ) -> (DriveCommandV2, ServoStateV3) {
        let n = self.p.axes;
        self.seq += 1;
        // The real time since the previous cycle (command validation scales its step limits
        // by it), and the same bounded to 5 periods for the integrators.
        self.elapsed_s = if self.last_ns == 0 {
            self.p.period_s
        } else {
            now_ns.saturating_sub(self.last_ns) as f64 * 1e-9
        };
        let dt = self.elapsed_s.min(5.0 * self.p.period_s);
        self.last_ns = now_ns;
        let mut out = Out {
            cmd: DriveCommandV2 {
                seq: self.seq,
                stamp_ns: now_ns,
                axes: n as u32,
                ..Default::default()
            },
            state: ServoStateV3 {
                seq: self.seq,
                stamp_ns: now_ns,
                axes: n as u32,
                fault_axis: -1,
                ..Default::default()
            },
        };
        out.cmd.mode[..n].copy_from_slice(&self.mode_word[..n]);
        let Some(fb) = feedback else {
            out.state.status = st::NO_FEEDBACK;
            if let Some(r) = request.filter(|r| r.seq != self.request_seq) {
                self.request(now_ns, r, false, events);
            }
            out.state.request_seq = self.request_seq;
            self.peak.publish(&mut out.state);
            return (out.cmd, out.state);
        };
        out.cmd.feedback_seq = fb.seq;
        out.cmd.feedback_stamp_ns = fb.stamp_ns;
        out.state.measured_stamp_ns = fb.stamp_ns;
        out.state.act_position = fb.position;
        out.state.act_velocity = fb.velocity;
        out.state.statusword = fb.statusword;

        let feedback_ok = self.check_feedback(now_ns, fb, events);
        self.measured_at_rest =
            (0..n).all(|i| fb.velocity[i].abs() <= self.p.axis[i].settle_velocity);
        if let Some(r) = request.filter(|r| r.seq != self.request_seq) {
            self.request(now_ns, r, feedback_ok, events);
        }
        let states: [Option<State>; MAX_AXES] =
            core::array::from_fn(|i| State::from_statusword(fb.statusword[i]));
        self.advance_power(now_ns, &states[..n], fb, events);

        if self.stopping && self.latched.is_none() && feedback_ok {
            // Disabling at speed: the reference comes to rest first, power stays on.
            self.follow(now_ns, dt, None, fb, &mut out, events);
            let at_rest = (0..n).all(|i| {
                self.ref_vel[i] == 0.0 && fb.velocity[i].abs() <= self.p.axis[i].settle_velocity
            });
            if at_rest {
                self.stopping = false;
            }
        } else if self.power == Power::Enabled && feedback_ok {
            // Under an e-stop that holds, no setpoint is taken: the reference comes to rest.
            let sp = new_setpoint.filter(|_| self.estop.is_none());
            self.follow(now_ns, dt, sp, fb, &mut out, events);
        } else {
            // Not following: the reference is where the axes are (bumpless enable; a CSP
            // drive gets its actual position as target), the integrators are cleared.
            for i in 0..n {
                if fb.position[i].is_finite() {
                    self.ref_pos[i] = fb.position[i];
                }
                self.ref_vel[i] = 0.0;
                out.cmd.target_position[i] = self.ref_pos[i];
            }
            self.integral = [0.0; MAX_AXES];
            self.setpoint = None;
            out.state.cmd_position = self.ref_pos;
            out.state.effort = fb.torque;
            out.state.status |= st::NO_SETPOINT;
        }
        self.controlwords(&states[..n], fb, &mut out);
        self.publishable(now_ns, &states[..n], fb, &mut out);
        self.peak.publish(&mut out.state);
        (out.cmd, out.state)
    }

    /// Moves the arm's power state on from what the drives report.
    fn advance_power(
        &mut self,
        now_ns: u64,
        states: &[Option<State>],
        fb: &DriveFeedbackV2,
        events: &mut EventQueue,
    ) {
        let all = |f: fn(State) -> bool| states.iter().all(|s| s.is_some_and(f));
        match self.power {
            Power::Enabling
                if all(|s| s == State::OperationEnabled)
                    && fb.mode_display[..self.p.axes] == self.mode_word[..self.p.axes] =>
            {
                let took = now_ns.saturating_sub(self.power_since_ns) as f64 * 1e-9;
                self.set_power(Power::Enabled, now_ns);
                self.setpoint = None;
                self.stale_setpoint = false;
                self.jump_reported = false;
                events.push(EventV1::new(now_ns, code::ENABLED, -1, took, 0.0, &[]));
            }
            Power::Enabling
                if now_ns.saturating_sub(self.power_since_ns) > self.p.enable_timeout_ns =>
            {
                let took = now_ns.saturating_sub(self.power_since_ns) as f64 * 1e-9;
                self.set_power(Power::Disabling, now_ns);
                let why = if all(|s| s == State::OperationEnabled) {
                    "a drive does not run the configured mode of operation (0x6061)"
                } else {
                    "a drive did not reach Operation enabled"
                };
                events.push(EventV1::new(
                    now_ns,
                    code::ENABLE_TIMEOUT,
                    -1,
                    took,
                    self.p.enable_timeout_ns as f64 * 1e-9,
                    &[why],
                ));
            }
            Power::Disabling if all(|s| !s.power_stage_on()) => {
                self.set_power(Power::Disabled, now_ns);
                events.push(EventV1::new(now_ns, code::DISABLED, -1, 0.0, 0.0, &[]));
            }
            _ => {}
        }
        if let Some(since) = self.resetting_since {
            let faulted = states
                .iter()
                .any(|s| matches!(s, Some(State::Fault | State::FaultReactionActive)));
            let fresh = now_ns.saturating_sub(self.feedback_new_ns) <= self.p.feedback_timeout_ns;
            let valid = fresh && (0..self.p.axes).all(|i| fb.position[i].is_finite());
            // The cut must have run its course first: every drive stopped and without power
            // (a reset never cancels a quick stop or a fault reaction under way).
            let stopped = states
                .iter()
                .all(|s| s.is_some_and(|s| !s.power_stage_on()))
                && (0..self.p.axes).all(|i| fb.velocity[i] == 0.0);
            if !faulted && valid && stopped {
                let l = self.latched.take();
                self.resetting_since = None;
                events.push(EventV1::new(
                    now_ns,
                    code::FAULT_CLEARED,
                    -1,
                    l.map_or(0.0, |l| l.code as f64),
                    0.0,
                    &["power stays off until an enable request"],
                ));
            } else if now_ns.saturating_sub(since) > self.p.enable_timeout_ns {
                self.resetting_since = None;
                let why = if faulted {
                    "reset refused: a drive is still in Fault (its fault condition persists)"
                } else if !valid {
                    "reset refused: the drive feedback is still stale or not a number"
                } else {
                    "reset refused: the drives are still stopping"
                };
                events.push(EventV1::new(
                    now_ns,
                    code::REQUEST_REFUSED,
                    -1,
                    RequestKind::Reset as u32 as f64,
                    0.0,
                    &[why],
                ));
            }
        }
    }

    /// Follows the setpoints while enabled: reference, validation, the loop, the following
    /// error.
    fn follow(
        &mut self,
        now_ns: u64,
        dt: f64,
        new_setpoint: Option<&SetpointV2>,
        fb: &DriveFeedbackV2,
        out: &mut Out,
        events: &mut EventQueue,
    ) {
        let n = self.p.axes;
        // Should this cycle latch a fault and return early, the drives still get a sane
        // target (the last reference), never 0.
        out.cmd.target_position[..n].copy_from_slice(&self.ref_pos[..n]);
        if let Some(sp) = new_setpoint {
            let finite = (0..n).all(|i| {
                sp.position[i].is_finite()
                    && sp.velocity[i].is_finite()
                    && sp.acceleration[i].is_finite()
            });
            if !finite {
                let l = Latched {
                    code: code::COMMAND_NOT_FINITE,
                    axis: -1,
                    value: f64::NAN,
                    limit: 0.0,
                };
                self.latch(now_ns, l, &["setpoint is not a finite number"], events);
                return;
            }
            match self.jump(sp, now_ns, dt) {
                Some((i, test, value, limit)) => {
                    out.state.status |= st::SETPOINT_JUMP;
                    if !self.jump_reported {
                        self.jump_reported = true;
                        let a = &self.p.axis[i];
                        let what = if test == code::SETPOINT_JUMP {
                            ": setpoint refused (its position), servo holds"
                        } else {
                            ": setpoint refused (its velocity), servo holds"
                        };
                        events.push(EventV1::new(
                            now_ns,
                            test,
                            i as i32,
                            value,
                            limit,
                            &[str_of(&a.name), what],
                        ));
                    }
                }
                None => {
                    self.rejoin_to(sp, now_ns);
                    self.setpoint = Some(*sp);
                    self.jump_reported = false;
                }
            }
        }
        out.state.setpoint_seq = self.setpoint.map_or(0, |s| s.seq);
        let (pos, vel, acc) = self.reference(now_ns, dt, events);
        if self.setpoint.is_none() {
            out.state.status |= if self.stale_setpoint {
                st::SETPOINT_STALE
            } else {
                st::NO_SETPOINT
            };
        }
        let validation = self.validate(&pos, &vel);
        self.tune_step = [false; MAX_AXES];
        if let Some((l, what)) = validation {
            let nb = if l.axis >= 0 {
                self.p.axis[l.axis as usize].name
            } else {
                shm_schema::fixed_str("arm")
            };
            let name = str_of(&nb);
            self.latch(now_ns, l, &[name, ": command ", what, " refused"], events);
            return;
        }
        self.ref_pos = pos;
        self.ref_vel = vel;
        for i in 0..n {
            let g = self.p.axis[i];
            let e = pos[i] - fb.position[i];
            let ev = vel[i] - fb.velocity[i];
            let ff = g.kvff * vel[i] + g.kaff * acc[i];
            out.state.following_error[i] = e;
            match self.mode[i] {
                Some(Mode::Csp) => {
                    out.cmd.target_position[i] = pos[i];
                    out.cmd.velocity_offset[i] = vel[i];
                    out.cmd.torque_offset[i] = ff;
                    out.state.effort[i] = fb.torque[i];
                }
                Some(Mode::Csv) => {
                    out.cmd.target_position[i] = pos[i];
                    out.cmd.target_velocity[i] = vel[i] + g.kp * e;
                    out.cmd.torque_offset[i] = g.kaff * acc[i];
                    out.state.effort[i] = fb.torque[i];
                }
                _ => {
                    self.integral[i] = bound(
                        self.integral[i] + g.ki * e * dt,
                        -g.integral_limit,
                        g.integral_limit,
                    );
                    let u = g.kp * e + self.integral[i] + g.kd * ev + ff;
                    let limit = g.effort_limit;
                    out.cmd.target_position[i] = pos[i];
                    out.cmd.target_torque[i] = bound(u, -limit, limit);
                    out.state.effort[i] = out.cmd.target_torque[i];
                }
            }
            if e.abs() > g.following_error_limit {
                let l = Latched {
                    code: code::FOLLOWING_ERROR,
                    axis: i as i32,
                    value: e,
                    limit: g.following_error_limit,
                };
                self.latch(now_ns, l, &[str_of(&g.name), ": following error"], events);
            }
        }
        let program = self.setpoint.map_or(self.peak.program, |s| s.program_id);
        self.peak.note(program, &out.state.following_error[..n]);
        out.state.cmd_position = pos;
        out.state.cmd_velocity = vel;
        if self.power == Power::Enabled {
            out.state.status |= st::ENABLED;
        }
    }

    /// The controlword of every axis for the power state and the latch.
    fn controlwords(&mut self, states: &[Option<State>], fb: &DriveFeedbackV2, out: &mut Out) {
        for (i, s) in states.iter().enumerate() {
            let s = s.unwrap_or(State::NotReadyToSwitchOn);
            out.cmd.controlword[i] = if self.latched.is_some() {
                match s {
                    _ if self.resetting_since.is_some() && s == State::Fault => {
                        self.fault_reset[i].controlword(s)
                    }
                    // Cut: quick stop a drive that produces torque (11); once it is at rest
                    // (or it has no power), disable voltage (12, 7, 10).
                    State::OperationEnabled => cw::QUICK_STOP_CMD,
                    State::QuickStopActive if fb.velocity[i] != 0.0 => cw::QUICK_STOP_CMD,
                    _ => cw::DISABLE_VOLTAGE,
                }
            } else {
                match self.power {
                    Power::Enabling | Power::Enabled => enable_step(s),
                    // Still bringing the axes to rest: keep the drives enabled.
                    Power::Disabling if self.stopping => enable_step(s),
                    Power::Disabling | Power::Disabled => disable_step(s),
                }
            };
        }
    }

    /// Fills the published state: power per axis, settled, the latch.
    fn publishable(
        &mut self,
        now_ns: u64,
        states: &[Option<State>],
        fb: &DriveFeedbackV2,
        out: &mut Out,
    ) {
        let s = &mut out.state;
        s.request_seq = self.request_seq;
        s.power = self.power as u8;
        s.controlword = out.cmd.controlword;
        if states
            .iter()
            .all(|s| s.is_some_and(|s| s != State::NotReadyToSwitchOn))
        {
            s.status |= st::INITIALIZED;
        }
        let mut all_settled = !states.is_empty();
        for (i, state) in states.iter().enumerate() {
            let oe = *state == Some(State::OperationEnabled);
            let powered = state.is_some_and(State::power_stage_on);
            s.axis_power[i] = match self.power {
                Power::Enabled | Power::Enabling if oe => Power::Enabled,
                Power::Enabling => Power::Enabling,
                Power::Disabling if powered => Power::Disabling,
                _ if oe => Power::Enabled,
                _ => Power::Disabled,
            } as u8;
            let a = &self.p.axis[i];
            let inside = self.power == Power::Enabled
                && s.following_error[i].abs() <= a.in_position
                && fb.velocity[i].abs() <= a.settle_velocity;
            if !inside {
                self.in_tolerance_since[i] = 0;
            } else if self.in_tolerance_since[i] == 0 {
                self.in_tolerance_since[i] = now_ns;
            }
            let settled = inside
                && now_ns.saturating_sub(self.in_tolerance_since[i]) >= self.p.settle_time_ns;
            if settled {
                s.settled_axes |= 1 << i;
            } else {
                all_settled = false;
            }
        }
        if all_settled {
            s.status |= st::SETTLED;
        }
        if let Some(l) = self.latched {
            s.status |= st::FAULT_LATCHED;
            s.fault_code = l.code;
            s.fault_axis = l.axis;
            s.fault_value = l.value;
            s.fault_limit = l.limit;
        }
    }
}
