//! The simulated machine: what servo would find behind a real fieldbus. It is its own
//! process, so the machine does not vanish (or jump) when servo restarts.
//!
//! **Drives.** Every axis has a CiA 402 drive ([`cia402::Device`], the state machine a real
//! drive bridge shares): it powers up in Not ready to switch on, reaches Switch on disabled by
//! itself (transition 1), and moves on only when the controlword asks (Shutdown, Switch on,
//! Enable operation). In Operation enabled it runs its mode of operation (0x6061 follows the
//! requested 0x6060 one cycle late):
//! - **CST** (cyclic synchronous torque): the effort is the target torque plus the torque
//!   offset; servo closes the position loop.
//! - **CSP** (cyclic synchronous position): the drive closes the loop itself with its own gains
//!   (`drive_kp`, `drive_ki`, `drive_kd`), on the target position micro-interpolated with the
//!   velocity offset, plus the torque offset as feed-forward.
//! - **CSV** (cyclic synchronous velocity): a PI velocity loop (`drive_kd`, `drive_ki`) on the
//!   target velocity plus the velocity offset.
//!
//! Quick stop and the fault reaction ramp the motor down at the drive's quick-stop
//! deceleration; with the power stage off the holding brake locks the axis. A fault condition
//! (the command watchdog, a target that is not a finite number, an injected over-current,
//! encoder loss or following error) takes the drive to Fault reaction active, then Fault, with
//! its error code (0x603F); only a fault-reset edge brings it back to Switch on disabled, and
//! only when the condition is gone. **No drive ever re-enables by itself.**
//!
//! **Mechanics.** Per axis, a rigid body driven by the drive's effort `u`:
//! `J dv/dt = u - b v - Fc sign(v)`, with stiction (at rest the axis stays put while
//! `|u| <= Fc`), the effort clamped to the drive's limit, and the position read through an
//! encoder of finite resolution. It integrates over real elapsed time (semi-implicit Euler,
//! `substeps` steps per machine period, the drive's own loop running at every step), so a
//! late cycle simulates the time that really passed, in more steps of the same size.

pub mod field;

use cia402::{Conditions, Device, Mode, QuickStopOption, State, error_code};
use shm_schema::event::{EventQueue, code};
use shm_schema::{
    AxisConfigV2, CellConfigV6, DriveCommandV2, DriveFeedbackV2, EventV1, FaultInjectionV1,
    MAX_AXES, str_of,
};

/// Longest time integrated in one cycle (s); a longer stall is simulated as this long.
pub const MAX_STEP_S: f64 = 0.05;

/// Mechanics of one axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Axis {
    /// Inertia (effort·s²/unit).
    pub inertia: f64,
    /// Viscous friction (effort·s/unit).
    pub viscous: f64,
    /// Coulomb friction (effort).
    pub coulomb: f64,
    /// Effort limit (effort).
    pub effort_limit: f64,
    /// Encoder resolution (unit/count).
    pub resolution: f64,
    /// Position (unit), exact.
    pub position: f64,
    /// Velocity (unit/s).
    pub velocity: f64,
}

impl Axis {
    /// An axis at rest at its configured start.
    pub fn from_config(a: &AxisConfigV2) -> Self {
        Self {
            inertia: a.inertia,
            viscous: a.viscous,
            coulomb: a.coulomb,
            effort_limit: a.effort_limit,
            resolution: a.encoder_resolution,
            position: a.start,
            velocity: 0.0,
        }
    }

    /// Integrates `dt` seconds under effort `u` (already limited); `braked` locks the axis.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn step(&mut self, u: f64, dt: f64, braked: bool) {
        if braked {
            self.velocity = 0.0;
            return;
        }
        let v = self.velocity;
        if v == 0.0 && u.abs() <= self.coulomb {
            return; // stiction
        }
        let dir = if v != 0.0 { v.signum() } else { u.signum() };
        let a = (u - self.viscous * v - self.coulomb * dir) / self.inertia;
        let mut v_new = v + a * dt;
        if v != 0.0 && v_new.signum() != v.signum() && u.abs() <= self.coulomb {
            v_new = 0.0; // friction stops the axis; it does not push it backwards
        }
        self.velocity = v_new;
        self.position += v_new * dt;
    }

    /// Brings the velocity towards 0 at `decel` (unit/s²) over `dt`, as a drive's
    /// quick-stop ramp does (its current loop holds the ramp). True once at rest.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn ramp_down(&mut self, decel: f64, dt: f64) -> bool {
        let dv = decel * dt;
        let v = self.velocity;
        let v_new = if v.abs() <= dv {
            0.0
        } else {
            v - dv * v.signum()
        };
        self.position += 0.5 * (v + v_new) * dt;
        self.velocity = v_new;
        v_new == 0.0
    }

    /// The encoder reading: the position quantised to the resolution.
    #[inline]
    pub fn encoder(&self) -> f64 {
        if self.resolution > 0.0 {
            (self.position / self.resolution).round() * self.resolution
        } else {
            self.position
        }
    }
}

/// One axis' drive: the CiA 402 device, its mode, targets and own control loop.
#[derive(Clone, Copy, Debug)]
pub struct Drive {
    device: Device,
    /// Mode requested by the latest command (0x6060).
    mode_request: i8,
    /// Mode in effect (0x6061), one cycle behind the request.
    mode_display: i8,
    target_position: f64,
    target_velocity: f64,
    target_torque: f64,
    velocity_offset: f64,
    torque_offset: f64,
    /// Time the current targets were applied (ns), for micro-interpolation.
    targets_ns: u64,
    integral: f64,
    kp: f64,
    ki: f64,
    kd: f64,
    quick_stop_decel: f64,
    /// Fault condition injected by command (0: none).
    injected: u16,
    /// The command of this cycle was refused (not finite): a fault condition for one cycle.
    refused: bool,
    effort: f64,
    following_error: f64,
    /// Time the drive first reached Operation enabled (ns), 0 before.
    first_enabled_ns: u64,
    /// The fault condition present in the latest cycle (0: none).
    condition: u16,
    /// A configured fault is present.
    configured_active: bool,
    /// The requested mode is not supported (reported once).
    mode_refused: bool,
}

impl Drive {
    fn new(a: &AxisConfigV2) -> Self {
        let option = QuickStopOption::from_i16(a.quick_stop_option as i16)
            .unwrap_or(QuickStopOption::QuickStopRamp);
        Self {
            device: Device::new(option),
            mode_request: Mode::Cst as i8,
            mode_display: Mode::NoMode as i8,
            target_position: a.start,
            target_velocity: 0.0,
            target_torque: 0.0,
            velocity_offset: 0.0,
            torque_offset: 0.0,
            targets_ns: 0,
            integral: 0.0,
            kp: a.drive_kp,
            ki: a.drive_ki,
            kd: a.drive_kd,
            quick_stop_decel: a.quick_stop_deceleration,
            injected: 0,
            refused: false,
            effort: 0.0,
            following_error: 0.0,
            first_enabled_ns: 0,
            condition: 0,
            configured_active: false,
            mode_refused: false,
        }
    }

    /// The drive's CiA 402 state.
    pub fn state(&self) -> State {
        self.device.state()
    }

    /// The effort its loop asks for at `t_ns` (before the effort limit).
    fn demand(&mut self, axis: &Axis, t_ns: u64, dt: f64) -> f64 {
        match Mode::from_i8(self.mode_display) {
            Some(Mode::Cst) => self.target_torque + self.torque_offset,
            Some(Mode::Csp) => {
                // Micro-interpolation between two commands (seed 001: position and velocity
                // are interpolated in the drives).
                let tau = t_ns.saturating_sub(self.targets_ns) as f64 * 1e-9;
                let target = self.target_position + self.velocity_offset * tau.min(MAX_STEP_S);
                let e = target - axis.position;
                self.following_error = e;
                self.integral += self.ki * e * dt;
                self.kp * e
                    + self.integral
                    + self.kd * (self.velocity_offset - axis.velocity)
                    + self.torque_offset
            }
            Some(Mode::Csv) => {
                let ev = self.target_velocity + self.velocity_offset - axis.velocity;
                self.integral += self.ki * ev * dt;
                self.kd * ev + self.integral + self.torque_offset
            }
            _ => 0.0,
        }
    }
}

/// The drives and mechanics of the whole machine.
#[derive(Clone, Debug)]
pub struct Machine {
    axes: usize,
    axis: [Axis; MAX_AXES],
    drive: [Drive; MAX_AXES],
    names: [[u8; 16]; MAX_AXES],
    substeps: u32,
    /// The machine's period (s): the integration step is `period_s / substeps`.
    period_s: f64,
    timeout_ns: u64,
    inject: [shm_schema::ConfiguredFaultV1; shm_schema::config::MAX_CONFIGURED_FAULTS],
    controlword: [u16; MAX_AXES],
    last_cmd_seq: u64,
    last_cmd_ns: u64,
    last_inject_seq: u64,
    watchdog_tripped: bool,
    /// A command for another number of axes was refused (reported once).
    axes_refused: bool,
    last_ns: u64,
    seq: u64,
}

/// The name of axis `i`.
fn name_of(names: &[[u8; 16]; MAX_AXES], i: usize) -> &str {
    str_of(&names[i])
}

impl Machine {
    /// The machine of `cell`, at rest at the axes' start positions, every drive in Not ready
    /// to switch on.
    /// The machine of `cell`, cycling every `period_ns`.
    pub fn new(cell: &CellConfigV6, period_ns: u64) -> Self {
        let idle = AxisConfigV2::default();
        let mut axis = [Axis::from_config(&idle); MAX_AXES];
        let mut drive = [Drive::new(&idle); MAX_AXES];
        let mut names = [[0u8; 16]; MAX_AXES];
        for (i, a) in cell.axes().iter().enumerate() {
            axis[i] = Axis::from_config(a);
            drive[i] = Drive::new(a);
            names[i] = a.name;
        }
        Self {
            axes: cell.axes as usize,
            axis,
            drive,
            names,
            substeps: cell.machine_substeps.max(1),
            period_s: (period_ns as f64 * 1e-9).max(1e-6),
            timeout_ns: cell.drive_command_timeout_ns,
            inject: cell.inject,
            controlword: [0; MAX_AXES],
            last_cmd_seq: 0,
            last_cmd_ns: 0,
            last_inject_seq: 0,
            watchdog_tripped: false,
            axes_refused: false,
            last_ns: 0,
            seq: 0,
        }
    }

    /// True while a drive has its power stage on (it may produce torque).
    pub fn powered(&self) -> bool {
        self.drive[..self.axes]
            .iter()
            .any(|d| d.device.state().power_stage_on())
    }

    /// The axes (for tests).
    pub fn axes(&self) -> &[Axis] {
        &self.axis[..self.axes]
    }

    /// The drives (for tests).
    pub fn drives(&self) -> &[Drive] {
        &self.drive[..self.axes]
    }

    /// Takes a new command: controlwords, modes, and the targets if they are finite.
    fn take_command(&mut self, now_ns: u64, c: &DriveCommandV2, events: &mut EventQueue) -> u64 {
        self.last_cmd_seq = c.seq;
        self.last_cmd_ns = now_ns;
        for i in 0..self.axes {
            let d = &mut self.drive[i];
            self.controlword[i] = c.controlword[i];
            d.mode_request = c.mode[i];
            let values = [
                c.target_position[i],
                c.target_velocity[i],
                c.target_torque[i],
                c.velocity_offset[i],
                c.torque_offset[i],
            ];
            if values.iter().all(|v| v.is_finite()) {
                d.target_position = c.target_position[i];
                d.target_velocity = c.target_velocity[i];
                d.target_torque = c.target_torque[i];
                d.velocity_offset = c.velocity_offset[i];
                d.torque_offset = c.torque_offset[i];
                d.targets_ns = now_ns;
                d.refused = false;
            } else if !d.refused {
                d.refused = true;
                events.push(EventV1::new(
                    now_ns,
                    code::DRIVE_COMMAND_REFUSED,
                    i as i32,
                    c.mode[i] as f64,
                    0.0,
                    &[name_of(&self.names, i), ": target is not a finite number"],
                ));
            }
        }
        if c.feedback_stamp_ns > 0 && c.feedback_stamp_ns <= now_ns {
            now_ns - c.feedback_stamp_ns
        } else {
            0
        }
    }

    /// Applies a commanded fault injection.
    fn take_injection(&mut self, now_ns: u64, f: &FaultInjectionV1, events: &mut EventQueue) {
        self.last_inject_seq = f.seq;
        let i = f.axis as usize;
        if i >= self.axes {
            return;
        }
        self.drive[i].injected = if f.active != 0 { f.code } else { 0 };
        events.push(EventV1::new(
            now_ns,
            code::FAULT_INJECTED,
            i as i32,
            self.drive[i].injected as f64,
            0.0,
            &[
                name_of(&self.names, i),
                ": ",
                if f.active != 0 {
                    error_code::name(f.code)
                } else {
                    "injected fault cleared"
                },
            ],
        ));
    }

    /// The configured fault (`[[drives.inject]]`) present on axis `i` at `now_ns` (0: none).
    fn configured(&self, i: usize, now_ns: u64, period_ns: u64) -> u16 {
        let d = &self.drive[i];
        if d.first_enabled_ns == 0 {
            return 0;
        }
        self.inject
            .iter()
            .filter(|f| f.code != 0 && f.axis as usize == i)
            .find(|f| {
                let from = d.first_enabled_ns.saturating_add(f.at_ns);
                now_ns >= from && now_ns < from.saturating_add(f.duration_ns.max(period_ns))
            })
            .map_or(0, |f| f.code as u16)
    }

    /// The fault condition axis `i` sees (0 for none), given its configured one.
    fn condition(&self, i: usize, configured: u16) -> u16 {
        let d = &self.drive[i];
        if d.injected != 0 {
            d.injected
        } else if d.refused {
            error_code::PARAMETER
        } else if self.watchdog_tripped {
            error_code::COMMAND_TIMEOUT
        } else {
            configured
        }
    }

    /// One machine cycle at `now_ns`: integrate the time since the last cycle under the
    /// drives' previous state and targets, then take the newest command and fault injection
    /// (if any arrived; they act from now on), run the drives' watchdog and state machines,
    /// sample the encoders. Events go to `events`.
    ///
    /// # Real-time
    /// Arithmetic and copies only; no allocation.
    pub fn cycle(
        &mut self,
        now_ns: u64,
        command: Option<&DriveCommandV2>,
        injection: Option<&FaultInjectionV1>,
        events: &mut EventQueue,
    ) -> DriveFeedbackV2 {
        if self.last_ns == 0 {
            self.last_ns = now_ns;
            self.last_cmd_ns = now_ns;
        }
        let period_ns = now_ns.saturating_sub(self.last_ns).max(1);
        // First the time that passed since the last cycle, under what the drives were
        // doing then (their state, mode and targets): a command takes effect from the cycle
        // that receives it on, never retroactively, so the plant sees the real
        // sense-to-command delay.
        let elapsed = (now_ns.saturating_sub(self.last_ns) as f64 * 1e-9).min(MAX_STEP_S);
        // The integration step keeps its nominal size: a late cycle runs more steps, so the
        // drive's own loop (CSP, CSV) never integrates a host stall in one stride.
        let nominal = self.period_s / self.substeps as f64;
        let steps = ((elapsed / nominal).ceil() as u32).max(self.substeps);
        let dt = elapsed / steps as f64;
        let dt_ns = (dt * 1e9) as u64;
        for k in 0..steps {
            let t_ns = self.last_ns + k as u64 * dt_ns;
            for i in 0..self.axes {
                let (d, a) = (&mut self.drive[i], &mut self.axis[i]);
                match d.state() {
                    State::OperationEnabled => {
                        let u = d.demand(a, t_ns, dt);
                        d.effort = shm_schema::bound(u, -a.effort_limit, a.effort_limit);
                        a.step(d.effort, dt, false);
                    }
                    State::QuickStopActive | State::FaultReactionActive => {
                        d.effort = 0.0;
                        a.ramp_down(d.quick_stop_decel, dt);
                    }
                    // Power stage off: the holding brake locks the axis.
                    _ => {
                        d.effort = 0.0;
                        a.step(0.0, dt, true);
                    }
                }
            }
        }
        self.last_ns = now_ns;

        // 0x6061 shows the mode requested by the previous command: a mode change takes
        // effect one drive cycle after it arrives. A mode the drive does not support is not
        // taken.
        for (i, d) in self.drive[..self.axes].iter_mut().enumerate() {
            if Mode::from_i8(d.mode_request).is_some() {
                d.mode_display = d.mode_request;
                d.mode_refused = false;
            } else if !d.mode_refused {
                d.mode_refused = true;
                events.push(EventV1::new(
                    now_ns,
                    code::DRIVE_COMMAND_REFUSED,
                    i as i32,
                    f64::from(d.mode_request),
                    0.0,
                    &[name_of(&self.names, i), ": mode of operation not supported"],
                ));
            }
        }
        let mut sense_to_command_ns = 0;
        if let Some(c) = command.filter(|c| c.seq != self.last_cmd_seq) {
            if c.axes as usize == self.axes {
                sense_to_command_ns = self.take_command(now_ns, c, events);
                self.watchdog_tripped = false;
                self.axes_refused = false;
            } else if !self.axes_refused {
                // A command for another machine: not taken (the watchdog keeps counting).
                self.axes_refused = true;
                events.push(EventV1::new(
                    now_ns,
                    code::DRIVE_COMMAND_REFUSED,
                    -1,
                    f64::from(c.axes),
                    self.axes as f64,
                    &["command for another number of axes"],
                ));
            }
        }
        if let Some(f) = injection.filter(|f| f.seq != self.last_inject_seq) {
            self.take_injection(now_ns, f, events);
        }
        // The command watchdog guards a powered drive: silence from the master while the
        // power stage is on is a fault (0xFF01), never a silent brake and a later re-enable.
        let silent_ns = now_ns.saturating_sub(self.last_cmd_ns);
        let powered = self.drive[..self.axes]
            .iter()
            .any(|d| d.state().power_stage_on());
        if powered && silent_ns > self.timeout_ns && !self.watchdog_tripped {
            self.watchdog_tripped = true;
            events.push(EventV1::new(
                now_ns,
                code::COMMAND_TIMEOUT,
                -1,
                silent_ns as f64 * 1e-9,
                self.timeout_ns as f64 * 1e-9,
                &["no new drive command"],
            ));
        }

        for i in 0..self.axes {
            let configured = self.configured(i, now_ns, period_ns);
            let fault = self.condition(i, configured);
            if configured != 0 && !self.drive[i].configured_active {
                events.push(EventV1::new(
                    now_ns,
                    code::FAULT_INJECTED,
                    i as i32,
                    configured as f64,
                    0.0,
                    &[
                        name_of(&self.names, i),
                        ": ",
                        error_code::name(configured),
                        " (configured)",
                    ],
                ));
            }
            self.drive[i].configured_active = configured != 0;
            let d = &mut self.drive[i];
            d.condition = fault;
            let before = d.state();
            let t = d.device.step(
                self.controlword[i],
                Conditions {
                    fault,
                    at_rest: self.axis[i].velocity == 0.0,
                },
            );
            if let Some(t) = t {
                events.push(EventV1::new(
                    now_ns,
                    code::DRIVE_TRANSITION,
                    i as i32,
                    t.number as f64,
                    0.0,
                    &[name_of(&self.names, i), ": ", t.to.name()],
                ));
                if t.to == State::FaultReactionActive {
                    events.push(EventV1::new(
                        now_ns,
                        code::DRIVE_FAULT,
                        i as i32,
                        d.device.error_code() as f64,
                        0.0,
                        &[
                            name_of(&self.names, i),
                            ": ",
                            error_code::name(d.device.error_code()),
                        ],
                    ));
                }
                if t.to == State::OperationEnabled && before != State::OperationEnabled {
                    // Transition 4 (or 16): clear the internal set-points; the drive starts
                    // from where the axis is.
                    d.target_position = self.axis[i].position;
                    d.targets_ns = now_ns;
                    d.integral = 0.0;
                    if d.first_enabled_ns == 0 {
                        d.first_enabled_ns = now_ns;
                    }
                }
            }
        }

        self.seq += 1;
        let mut fb = DriveFeedbackV2 {
            seq: self.seq,
            stamp_ns: now_ns,
            command_seq: self.last_cmd_seq,
            sense_to_command_ns,
            axes: self.axes as u32,
            ..Default::default()
        };
        for i in 0..self.axes {
            let (d, a) = (&self.drive[i], &self.axis[i]);
            fb.statusword[i] = d.device.statusword();
            fb.mode_display[i] = d.mode_display;
            fb.error_code[i] = d.device.error_code();
            fb.position[i] = if d.condition == error_code::POSITION_SENSOR {
                f64::NAN // the encoder is lost: there is no measurement
            } else {
                a.encoder()
            };
            fb.velocity[i] = a.velocity;
            fb.torque[i] = d.effort;
            fb.following_error[i] = if d.mode_display == Mode::Csp as i8 {
                d.following_error
            } else {
                0.0
            };
        }
        fb
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cia402::cw;

    fn axis() -> Axis {
        Axis {
            inertia: 0.01,
            viscous: 0.02,
            coulomb: 2.0,
            effort_limit: 100.0,
            resolution: 0.001,
            position: 0.0,
            velocity: 0.0,
        }
    }

    #[test]
    fn stiction_holds_below_coulomb_and_breaks_above() {
        let mut a = axis();
        a.step(1.9, 0.001, false);
        assert_eq!((a.position, a.velocity), (0.0, 0.0));
        a.step(3.0, 0.001, false);
        // a = (3 - 2) / 0.01 = 100 unit/s², v = 0.1 unit/s after 1 ms.
        assert!((a.velocity - 0.1).abs() < 1e-12);
    }

    #[test]
    fn friction_stops_a_coasting_axis_without_reversing_it() {
        let mut a = axis();
        a.velocity = 1.0;
        for _ in 0..10_000 {
            a.step(0.0, 0.0001, false);
        }
        assert_eq!(a.velocity, 0.0);
        assert!(a.position > 0.0);
    }

    #[test]
    fn encoder_quantises() {
        let mut a = axis();
        a.position = 1.23456;
        assert!((a.encoder() - 1.235).abs() < 1e-12);
    }

    #[test]
    fn the_quick_stop_ramp_ends_at_rest() {
        let mut a = axis();
        a.velocity = 1.0;
        let mut steps = 1;
        while !a.ramp_down(100.0, 0.001) {
            steps += 1;
        }
        // 1 unit/s at 100 unit/s² takes 10 ms and 0.005 unit (one step more for rounding).
        assert!((10..=11).contains(&steps), "{steps}");
        assert!((a.position - 0.005).abs() < 1e-6, "{}", a.position);
    }

    const MS: u64 = 1_000_000;

    fn cell(mode: Mode) -> CellConfigV6 {
        let mut c = CellConfigV6 {
            axes: 1,
            machine_substeps: 4,
            drive_command_timeout_ns: 20 * MS,
            ..Default::default()
        };
        c.axis[0] = AxisConfigV2 {
            name: shm_schema::fixed_str("x"),
            inertia: 0.01,
            effort_limit: 10.0,
            encoder_resolution: 0.001,
            mode: mode as i32,
            quick_stop_option: 2,
            quick_stop_deceleration: 100.0,
            drive_kp: 50.0,
            drive_kd: 1.0,
            ..Default::default()
        };
        c
    }

    fn command(seq: u64, controlword: u16, mode: Mode, torque: f64, pos: f64) -> DriveCommandV2 {
        let mut c = DriveCommandV2 {
            seq,
            axes: 1,
            ..Default::default()
        };
        c.controlword[0] = controlword;
        c.mode[0] = mode as i8;
        c.target_torque[0] = torque;
        c.target_position[0] = pos;
        c
    }

    /// Runs one cycle at `k` ms with a new command `cw` (CST, `torque`).
    fn at(m: &mut Machine, k: u64, cw: u16, torque: f64) -> (DriveFeedbackV2, EventQueue) {
        let mut q = EventQueue::default();
        let fb = m.cycle(
            k * MS,
            Some(&command(k, cw, Mode::Cst, torque, 0.0)),
            None,
            &mut q,
        );
        (fb, q)
    }

    fn state(fb: &DriveFeedbackV2) -> State {
        State::from_statusword(fb.statusword[0]).expect("a state")
    }

    /// Steps a fresh machine to Operation enabled the way a robust master does.
    fn enabled(m: &mut Machine) -> u64 {
        let mut k = 1;
        for w in [
            cw::DISABLE_VOLTAGE,
            cw::SHUTDOWN,
            cw::SWITCH_ON_CMD,
            cw::ENABLE_OPERATION_CMD,
        ] {
            at(m, k, w, 0.0);
            k += 1;
        }
        let (fb, _) = at(m, k, cw::ENABLE_OPERATION_CMD, 0.0);
        assert_eq!(state(&fb), State::OperationEnabled);
        k + 1
    }

    #[test]
    fn a_drive_steps_through_the_states_only_when_asked() {
        let mut m = Machine::new(&cell(Mode::Cst), MS);
        let (fb, q) = at(&mut m, 1, cw::ENABLE_OPERATION_CMD, 5.0);
        // Transition 1 by itself; 0x0F in Switch on disabled does nothing.
        assert_eq!(state(&fb), State::SwitchOnDisabled);
        assert_eq!(q.as_slice()[0].code, code::DRIVE_TRANSITION);
        assert_eq!(q.as_slice()[0].value, 1.0);
        let (fb, _) = at(&mut m, 2, cw::ENABLE_OPERATION_CMD, 5.0);
        assert_eq!(state(&fb), State::SwitchOnDisabled);
        assert_eq!(fb.position[0], 0.0, "no torque without Operation enabled");
        let mut m = Machine::new(&cell(Mode::Cst), MS);
        let k = enabled(&mut m);
        let (fb, _) = at(&mut m, k, cw::ENABLE_OPERATION_CMD, 5.0);
        assert_eq!(fb.mode_display[0], Mode::Cst as i8);
        // A command acts from the cycle that takes it on, never on the time before it.
        assert_eq!((fb.velocity[0], fb.torque[0]), (0.0, 0.0));
        let (fb, _) = at(&mut m, k + 1, cw::ENABLE_OPERATION_CMD, 5.0);
        assert!(fb.velocity[0] > 0.0 && fb.torque[0] == 5.0);
    }

    #[test]
    fn a_silent_master_faults_the_drive_and_it_never_re_enables_by_itself() {
        let mut m = Machine::new(&cell(Mode::Cst), MS);
        let k = enabled(&mut m);
        at(&mut m, k, cw::ENABLE_OPERATION_CMD, 0.5);
        // No new command for 60 ms (> 20 ms): fault 0xFF01, ramp, Fault.
        let mut q = EventQueue::default();
        let mut fb = DriveFeedbackV2::default();
        for j in 1..=60 {
            fb = m.cycle((k + j) * MS, None, None, &mut q);
        }
        assert_eq!(state(&fb), State::Fault);
        assert_eq!(fb.error_code[0], error_code::COMMAND_TIMEOUT);
        assert!(q.as_slice().iter().any(|e| e.code == code::COMMAND_TIMEOUT));
        assert_eq!(fb.velocity[0], 0.0);
        // Commands resume asking for Operation enabled: the drive stays in Fault.
        let k = k + 61;
        for j in 0..5 {
            let (fb, _) = at(&mut m, k + j, cw::ENABLE_OPERATION_CMD, 5.0);
            assert_eq!(state(&fb), State::Fault);
        }
        // Fault reset edge: Switch on disabled (15), and still no power.
        at(&mut m, k + 5, cw::DISABLE_VOLTAGE, 0.0);
        let (fb, _) = at(&mut m, k + 6, cw::FAULT_RESET_CMD, 0.0);
        assert_eq!(state(&fb), State::SwitchOnDisabled);
        assert_eq!(fb.error_code[0], 0);
    }

    #[test]
    fn an_injected_encoder_loss_faults_and_reset_waits_for_the_condition_to_clear() {
        let mut m = Machine::new(&cell(Mode::Cst), MS);
        let k = enabled(&mut m);
        let mut q = EventQueue::default();
        let inject = |seq, active| FaultInjectionV1 {
            seq,
            axis: 0,
            code: shm_schema::drive::injected::ENCODER_LOSS,
            active,
        };
        let fb = m.cycle(
            k * MS,
            Some(&command(k, 0x0F, Mode::Cst, 0.0, 0.0)),
            Some(&inject(1, 1)),
            &mut q,
        );
        assert!(fb.position[0].is_nan(), "no measurement without an encoder");
        assert_eq!(state(&fb), State::FaultReactionActive);
        let codes: Vec<u32> = q.as_slice().iter().map(|e| e.code).collect();
        assert!(codes.contains(&code::FAULT_INJECTED) && codes.contains(&code::DRIVE_FAULT));
        let (fb, _) = at(&mut m, k + 1, cw::DISABLE_VOLTAGE, 0.0);
        assert_eq!(state(&fb), State::Fault);
        let (fb, _) = at(&mut m, k + 2, cw::FAULT_RESET_CMD, 0.0);
        assert_eq!(state(&fb), State::Fault, "the condition is still present");
        m.cycle(
            (k + 3) * MS,
            Some(&command(k + 3, 0, Mode::Cst, 0.0, 0.0)),
            Some(&inject(2, 0)),
            &mut q,
        );
        let (fb, _) = at(&mut m, k + 4, cw::FAULT_RESET_CMD, 0.0);
        assert_eq!(state(&fb), State::SwitchOnDisabled);
        assert!(fb.position[0].is_finite());
    }

    #[test]
    fn commands_for_another_machine_or_an_unsupported_mode_are_refused_with_an_event() {
        let mut m = Machine::new(&cell(Mode::Cst), MS);
        let k = enabled(&mut m);
        let mut c = command(k, cw::ENABLE_OPERATION_CMD, Mode::Cst, 5.0, 0.0);
        c.axes = 2;
        let mut q = EventQueue::default();
        m.cycle(k * MS, Some(&c), None, &mut q);
        let fb = m.cycle((k + 1) * MS, Some(&c), None, &mut q);
        assert_eq!(fb.torque[0], 0.0, "not taken");
        let refused: Vec<_> = q
            .as_slice()
            .iter()
            .filter(|e| e.code == code::DRIVE_COMMAND_REFUSED)
            .collect();
        assert_eq!(refused.len(), 1, "reported once");
        assert_eq!((refused[0].value, refused[0].limit), (2.0, 1.0));
        let mut c = command(k + 2, cw::ENABLE_OPERATION_CMD, Mode::Cst, 0.0, 0.0);
        c.mode[0] = 4; // profile torque: not supported
        let mut q = EventQueue::default();
        m.cycle((k + 2) * MS, Some(&c), None, &mut q);
        let fb = m.cycle((k + 3) * MS, Some(&c), None, &mut q);
        assert_eq!(
            fb.mode_display[0],
            Mode::Cst as i8,
            "the mode in effect stays"
        );
        assert!(
            q.as_slice()
                .iter()
                .any(|e| e.code == code::DRIVE_COMMAND_REFUSED && e.value == 4.0)
        );
    }

    #[test]
    fn a_target_that_is_not_finite_is_refused_and_faults_the_drive() {
        let mut m = Machine::new(&cell(Mode::Cst), MS);
        let k = enabled(&mut m);
        let (fb, q) = at(&mut m, k, cw::ENABLE_OPERATION_CMD, f64::NAN);
        assert_eq!(state(&fb), State::FaultReactionActive);
        assert_eq!(fb.torque[0], 0.0);
        assert!(
            q.as_slice()
                .iter()
                .any(|e| e.code == code::DRIVE_COMMAND_REFUSED)
        );
        assert_eq!(fb.error_code[0], error_code::PARAMETER);
    }

    /// Steps a fresh machine to Operation enabled in CSP; the next cycle's number.
    fn enabled_csp(m: &mut Machine) -> u64 {
        let mut k = 1;
        for w in [0, cw::SHUTDOWN, cw::SWITCH_ON_CMD, cw::ENABLE_OPERATION_CMD] {
            let mut q = EventQueue::default();
            m.cycle(
                k * MS,
                Some(&command(k, w, Mode::Csp, 0.0, 0.0)),
                None,
                &mut q,
            );
            k += 1;
        }
        k
    }

    #[test]
    fn in_csp_the_drive_closes_the_loop_on_its_target() {
        let mut m = Machine::new(&cell(Mode::Csp), MS);
        let k = enabled_csp(&mut m);
        let mut fb = DriveFeedbackV2::default();
        let mut q = EventQueue::default();
        for j in 0..2000 {
            fb = m.cycle(
                (k + j) * MS,
                Some(&command(k + j, 0x0F, Mode::Csp, 0.0, 1.0)),
                None,
                &mut q,
            );
        }
        assert_eq!(fb.mode_display[0], Mode::Csp as i8);
        assert!((fb.position[0] - 1.0).abs() <= 0.002, "{}", fb.position[0]);
        assert!(fb.following_error[0].abs() <= 0.002);
    }

    #[test]
    fn a_late_cycle_integrates_the_time_that_really_passed() {
        let mut a = Machine::new(&cell(Mode::Cst), MS);
        let mut b = Machine::new(&cell(Mode::Cst), MS);
        let ka = enabled(&mut a);
        let kb = enabled(&mut b);
        assert_eq!(ka, kb);
        at(&mut a, ka, 0x0F, 1.0);
        at(&mut b, kb, 0x0F, 1.0);
        for j in 1..=10 {
            at(&mut a, ka + j, 0x0F, 1.0);
        }
        at(&mut b, kb + 10, 0x0F, 1.0);
        let (va, vb) = (a.axes()[0].velocity, b.axes()[0].velocity);
        assert!((va - vb).abs() < 1e-9, "{va} vs {vb}");
    }

    #[test]
    fn a_host_stall_does_not_destabilise_the_drives_own_loop() {
        // The default x axis' CSP gains: kd dt / J = 3 at a 10 ms step, 0.08 at 250 µs.
        let mut c = cell(Mode::Csp);
        c.axis[0].inertia = 0.008;
        c.axis[0].effort_limit = 100.0;
        (c.axis[0].drive_kp, c.axis[0].drive_kd) = (300.0, 2.5);
        let mut m = Machine::new(&c, MS);
        let k = enabled_csp(&mut m);
        let mut q = EventQueue::default();
        for j in 0..500 {
            m.cycle(
                (k + j) * MS,
                Some(&command(k + j, 0x0F, Mode::Csp, 0.0, 0.5)),
                None,
                &mut q,
            );
        }
        // A 40 ms stall as the target moves on: four substeps would be 10 ms each.
        let k = k + 540;
        let fb = m.cycle(
            k * MS,
            Some(&command(k, 0x0F, Mode::Csp, 0.0, 0.6)),
            None,
            &mut q,
        );
        assert!((0.45..0.7).contains(&fb.position[0]), "{}", fb.position[0]);
        assert!(fb.velocity[0].abs() < 10.0, "{}", fb.velocity[0]);
    }

    #[test]
    fn the_sense_to_command_latency_is_measured_from_the_sample() {
        let mut m = Machine::new(&cell(Mode::Cst), MS);
        let mut q = EventQueue::default();
        let mut c = command(1, 0, Mode::Cst, 0.0, 0.0);
        c.feedback_stamp_ns = 7 * MS + 100_000;
        let fb = m.cycle(8 * MS + 100_000, Some(&c), None, &mut q);
        assert_eq!(fb.sense_to_command_ns, MS);
        let fb = m.cycle(9 * MS + 100_000, Some(&c), None, &mut q);
        assert_eq!(fb.sense_to_command_ns, 0, "no new command this cycle");
    }
}
