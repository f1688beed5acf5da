//! Servo: the axes' position loops (seed 003 §3). It runs at its own period at all times,
//! also when no setpoint comes (it holds the last one): its job is not to keep motion time
//! but to keep the axes stable.
//!
//! Each cycle, per axis: the reference is the latest trajgen setpoint extrapolated to now
//! (`p + v dt`: trajgen's trajectory is a function of real time, so a servo faster than
//! trajgen gets a smooth reference and a late setpoint costs nothing), for at most
//! `setpoint_timeout`, after which servo holds (`SETPOINT_STALE`). A PID on the position error
//! with velocity and acceleration feed-forward gives the effort.
//!
//! Safety rules:
//! - trajgen never moves an axis faster than its `vmax` (the blend interpolates monotonically
//!   between segment velocities), so a setpoint further from the previous one than
//!   `vmax * (stamp difference)` is a jump: it is refused and servo holds (`SETPOINT_JUMP`).
//!   The first setpoint servo sees must lie within the in-position band of where it holds;
//! - while the drives are disabled the reference follows the measured position and the
//!   integrator is cleared, so enabling is bumpless; enable is requested as a 0-to-1 edge.

use shm_schema::drive::servo_status as st;
use shm_schema::{
    AxisConfigV1, CellConfigV1, DriveCommandV1, DriveFeedbackV1, MAX_AXES, Role, ServoStateV1,
    SetpointV1,
};

/// Parameters of the controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Axes in use.
    pub axes: usize,
    /// Per-axis gains and limits, as configured.
    pub axis: [AxisConfigV1; MAX_AXES],
    /// Servo period (s).
    pub period_s: f64,
    /// Longest extrapolation of a setpoint (s), then servo holds.
    pub max_extrapolation_s: f64,
}

impl Params {
    /// From the cell configuration.
    pub fn from_cell(cell: &CellConfigV1) -> Self {
        Self {
            axes: cell.axes as usize,
            axis: cell.axis,
            period_s: cell.process[Role::Servo.index()].period_ns as f64 * 1e-9,
            max_extrapolation_s: cell.setpoint_timeout_ns as f64 * 1e-9,
        }
    }
}

/// The controller state. Construct at set-up; [`Controller::cycle`] runs every cycle.
#[derive(Clone, Debug)]
pub struct Controller {
    p: Params,
    setpoint: Option<SetpointV1>,
    reference: [f64; MAX_AXES],
    have_reference: bool,
    integral: [f64; MAX_AXES],
    last_ns: u64,
    enable_out: u32,
    seq: u64,
}

impl Controller {
    /// A controller that has seen nothing yet.
    pub fn new(p: Params) -> Self {
        Self {
            p,
            setpoint: None,
            reference: [0.0; MAX_AXES],
            have_reference: false,
            integral: [0.0; MAX_AXES],
            last_ns: 0,
            enable_out: 0,
            seq: 0,
        }
    }

    /// True if `sp` lies further from the previous setpoint than the axes can move between
    /// the two (or, for the first one, outside the in-position band of the held reference).
    fn is_jump(&self, sp: &SetpointV1, now_ns: u64, dt: f64) -> bool {
        let n = self.p.axes;
        match &self.setpoint {
            Some(prev) if prev.seq != sp.seq && sp.stamp_ns >= prev.stamp_ns => {
                let span = (sp.stamp_ns - prev.stamp_ns) as f64 * 1e-9;
                (0..n).any(|i| {
                    let reach = self.p.axis[i].vmax * span * 1.001 + 1e-9;
                    (sp.position[i] - prev.position[i]).abs() > reach
                })
            }
            // A new source (trajgen restarted: its clock stamps restart too) or the first
            // setpoint: it must start where servo holds.
            _ => {
                let age = ((now_ns as i128 - sp.stamp_ns as i128) as f64 * 1e-9)
                    .clamp(0.0, self.p.max_extrapolation_s);
                (0..n).any(|i| {
                    let g = &self.p.axis[i];
                    let at_now = sp.position[i] + sp.velocity[i] * age;
                    (at_now - self.reference[i]).abs() > g.vmax * dt * 1.5 + g.in_position
                })
            }
        }
    }

    /// One servo cycle at `now_ns` with the newest setpoint (if one arrived) and the newest
    /// drive feedback (if any ever arrived). Returns the drive command and the servo state.
    ///
    /// # Real-time
    /// Arithmetic only; no allocation, no system call.
    pub fn cycle(
        &mut self,
        now_ns: u64,
        new_setpoint: Option<&SetpointV1>,
        feedback: Option<&DriveFeedbackV1>,
    ) -> (DriveCommandV1, ServoStateV1) {
        let n = self.p.axes;
        self.seq += 1;
        let dt = if self.last_ns == 0 {
            self.p.period_s
        } else {
            ((now_ns.saturating_sub(self.last_ns)) as f64 * 1e-9).min(5.0 * self.p.period_s)
        };
        self.last_ns = now_ns;

        let mut cmd = DriveCommandV1 {
            seq: self.seq,
            stamp_ns: now_ns,
            axes: n as u32,
            ..Default::default()
        };
        let mut state = ServoStateV1 {
            seq: self.seq,
            stamp_ns: now_ns,
            setpoint_seq: self.setpoint.map_or(0, |s| s.seq),
            axes: n as u32,
            ..Default::default()
        };
        let Some(fb) = feedback else {
            state.status = st::NO_FEEDBACK;
            return (cmd, state);
        };
        state.measured_stamp_ns = fb.stamp_ns;
        state.act_position = fb.position;
        state.act_velocity = fb.velocity;

        if fb.enabled == 0 {
            // Disabled: follow the machine, clear the integrator, ask for enable as an edge.
            self.reference[..n].copy_from_slice(&fb.position[..n]);
            self.have_reference = true;
            self.integral = [0.0; MAX_AXES];
            // After enabling, the first setpoint must start where the machine is.
            self.setpoint = None;
            self.enable_out = if self.enable_out == 0 { 1 } else { 0 };
            cmd.enable = self.enable_out;
            state.status |= if fb.fault != 0 { st::DRIVE_FAULT } else { 0 };
            state.cmd_position = self.reference;
            if self.setpoint.is_none() {
                state.status |= st::NO_SETPOINT;
            }
            return (cmd, state);
        }
        self.enable_out = 1;
        cmd.enable = 1;
        state.status |= st::ENABLED;
        if !self.have_reference {
            self.reference[..n].copy_from_slice(&fb.position[..n]);
            self.have_reference = true;
        }

        // Take the new setpoint unless it jumps.
        if let Some(sp) = new_setpoint {
            if self.is_jump(sp, now_ns, dt) {
                state.status |= st::SETPOINT_JUMP;
            } else {
                self.setpoint = Some(*sp);
            }
        }
        state.setpoint_seq = self.setpoint.map_or(0, |s| s.seq);

        // The reference: the setpoint extrapolated to now, or hold.
        let mut target = self.reference;
        let mut target_vel = [0.0; MAX_AXES];
        let mut target_acc = [0.0; MAX_AXES];
        match self.setpoint {
            None => state.status |= st::NO_SETPOINT,
            Some(sp) => {
                let age = (now_ns as i128 - sp.stamp_ns as i128) as f64 * 1e-9;
                let stale = age > self.p.max_extrapolation_s;
                let h = age.clamp(0.0, self.p.max_extrapolation_s);
                for i in 0..n {
                    target[i] = sp.position[i] + sp.velocity[i] * h;
                    if !stale {
                        target_vel[i] = sp.velocity[i];
                        target_acc[i] = sp.acceleration[i];
                    }
                }
                if stale {
                    state.status |= st::SETPOINT_STALE;
                }
            }
        }
        self.reference = target;

        for i in 0..n {
            let g = &self.p.axis[i];
            let e = target[i] - fb.position[i];
            let ev = target_vel[i] - fb.velocity[i];
            self.integral[i] =
                (self.integral[i] + g.ki * e * dt).clamp(-g.integral_limit, g.integral_limit);
            let u = g.kp * e
                + self.integral[i]
                + g.kd * ev
                + g.kvff * target_vel[i]
                + g.kaff * target_acc[i];
            cmd.effort[i] = u.clamp(-g.effort_limit, g.effort_limit);
            state.following_error[i] = e;
            if e.abs() > g.following_error_limit {
                state.status |= st::FOLLOWING_ERROR;
            }
        }
        if fb.fault != 0 {
            state.status |= st::DRIVE_FAULT;
        }
        state.cmd_position = target;
        state.cmd_velocity = target_vel;
        state.effort = cmd.effort;
        (cmd, state)
    }
}
