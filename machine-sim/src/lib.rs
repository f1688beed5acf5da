//! The simulated machine: what servo would find behind a real fieldbus. It is its own
//! process, so the machine does not vanish (or jump) when servo restarts.
//!
//! Per axis, a rigid body driven by the drive's effort `u`:
//! `J dv/dt = u - b v - Fc sign(v)`, with stiction (at rest the axis stays put while
//! `|u| <= Fc`), the effort clamped to the drive's limit, and the position read through an
//! encoder of finite resolution. It integrates over real elapsed time (semi-implicit Euler,
//! `substeps` steps per machine cycle), so a late cycle simulates the time that really
//! passed.
//!
//! The drives behave as real ones do: they enable on a 0-to-1 edge of the command's `enable`,
//! and when no new command arrives for the configured timeout they drop enable and engage
//! the holding brakes (fault `COMMAND_TIMEOUT`) until enabled again.

use shm_schema::drive::drive_fault;
use shm_schema::{AxisConfigV1, CellConfigV1, DriveCommandV1, DriveFeedbackV1, MAX_AXES};

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
    pub fn from_config(a: &AxisConfigV1) -> Self {
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

/// The drives and mechanics of the whole machine.
#[derive(Clone, Debug)]
pub struct Machine {
    axes: usize,
    axis: [Axis; MAX_AXES],
    substeps: u32,
    timeout_ns: u64,
    enabled: bool,
    fault: u32,
    last_enable: u32,
    last_cmd_seq: u64,
    last_cmd_ns: u64,
    effort: [f64; MAX_AXES],
    last_ns: u64,
    seq: u64,
}

impl Machine {
    /// The machine of `cell`, at rest at the axes' start positions, drives disabled.
    pub fn new(cell: &CellConfigV1) -> Self {
        let idle = Axis::from_config(&AxisConfigV1::default());
        let mut axis = [idle; MAX_AXES];
        for (i, a) in cell.axes().iter().enumerate() {
            axis[i] = Axis::from_config(a);
        }
        Self {
            axes: cell.axes as usize,
            axis,
            substeps: cell.machine_substeps.max(1),
            timeout_ns: cell.drive_command_timeout_ns,
            enabled: false,
            fault: drive_fault::NONE,
            last_enable: 0,
            last_cmd_seq: 0,
            last_cmd_ns: 0,
            effort: [0.0; MAX_AXES],
            last_ns: 0,
            seq: 0,
        }
    }

    /// The axes (for tests).
    pub fn axes(&self) -> &[Axis] {
        &self.axis[..self.axes]
    }

    /// One machine cycle at `now_ns`: take the newest command (if one arrived), run the
    /// drive watchdog, integrate the time since the last cycle, sample the encoders.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn cycle(&mut self, now_ns: u64, command: Option<&DriveCommandV1>) -> DriveFeedbackV1 {
        if self.last_ns == 0 {
            self.last_ns = now_ns;
            self.last_cmd_ns = now_ns;
        }
        if let Some(c) = command.filter(|c| c.seq != self.last_cmd_seq) {
            self.last_cmd_seq = c.seq;
            self.last_cmd_ns = now_ns;
            if c.enable == 0 {
                self.enabled = false;
            } else if self.last_enable == 0 && !self.enabled {
                self.enabled = true;
                self.fault = drive_fault::NONE;
            }
            self.last_enable = c.enable;
            for i in 0..self.axes {
                let lim = self.axis[i].effort_limit;
                self.effort[i] = if c.effort[i].is_finite() {
                    c.effort[i].clamp(-lim, lim)
                } else {
                    0.0
                };
            }
        }
        if self.enabled && now_ns.saturating_sub(self.last_cmd_ns) > self.timeout_ns {
            self.enabled = false;
            self.fault = drive_fault::COMMAND_TIMEOUT;
        }
        if !self.enabled {
            self.effort = [0.0; MAX_AXES];
        }
        let elapsed = ((now_ns - self.last_ns) as f64 * 1e-9).min(MAX_STEP_S);
        self.last_ns = now_ns;
        let dt = elapsed / self.substeps as f64;
        let braked = !self.enabled;
        for _ in 0..self.substeps {
            for i in 0..self.axes {
                self.axis[i].step(self.effort[i], dt, braked);
            }
        }
        self.seq += 1;
        let mut fb = DriveFeedbackV1 {
            seq: self.seq,
            stamp_ns: now_ns,
            command_seq: self.last_cmd_seq,
            enabled: self.enabled as u32,
            brake: braked as u32,
            fault: self.fault,
            axes: self.axes as u32,
            position: [0.0; MAX_AXES],
            velocity: [0.0; MAX_AXES],
            effort: self.effort,
        };
        for i in 0..self.axes {
            fb.position[i] = self.axis[i].encoder();
            fb.velocity[i] = self.axis[i].velocity;
        }
        fb
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    fn cell() -> CellConfigV1 {
        let mut c = CellConfigV1 {
            axes: 1,
            machine_substeps: 4,
            drive_command_timeout_ns: 20_000_000,
            ..Default::default()
        };
        c.axis[0] = AxisConfigV1 {
            inertia: 0.01,
            coulomb: 0.0,
            effort_limit: 10.0,
            encoder_resolution: 0.001,
            ..Default::default()
        };
        c
    }

    fn command(seq: u64, enable: u32, effort: f64) -> DriveCommandV1 {
        let mut c = DriveCommandV1 {
            seq,
            stamp_ns: 0,
            enable,
            axes: 1,
            effort: [0.0; MAX_AXES],
        };
        c.effort[0] = effort;
        c
    }

    #[test]
    fn drives_enable_on_an_edge_and_brake_when_commands_stop() {
        let mut m = Machine::new(&cell());
        let ms = 1_000_000;
        // enable = 1 without a preceding 0 after start: a rising edge from the initial 0.
        let fb = m.cycle(ms, Some(&command(1, 1, 1.0)));
        assert_eq!(fb.enabled, 1);
        let fb = m.cycle(2 * ms, Some(&command(2, 1, 1.0)));
        assert!(fb.velocity[0] > 0.0);
        // No new command (same seq) for longer than 20 ms: enable drops, brakes engage.
        let mut t = 2 * ms;
        let mut fb = fb;
        while t < 30 * ms {
            t += ms;
            fb = m.cycle(t, Some(&command(2, 1, 1.0)));
        }
        assert_eq!(
            (fb.enabled, fb.brake, fb.fault),
            (0, 1, drive_fault::COMMAND_TIMEOUT)
        );
        assert_eq!(fb.velocity[0], 0.0);
        // Commands resume with enable held at 1: no re-enable without an edge.
        let fb = m.cycle(t + ms, Some(&command(3, 1, 1.0)));
        assert_eq!(fb.enabled, 0);
        m.cycle(t + 2 * ms, Some(&command(4, 0, 0.0)));
        let fb = m.cycle(t + 3 * ms, Some(&command(5, 1, 0.0)));
        assert_eq!((fb.enabled, fb.fault), (1, drive_fault::NONE));
    }

    #[test]
    fn a_late_cycle_integrates_the_time_that_really_passed() {
        let mut a = Machine::new(&cell());
        let mut b = Machine::new(&cell());
        let ms = 1_000_000;
        a.cycle(ms, Some(&command(1, 1, 1.0)));
        b.cycle(ms, Some(&command(1, 1, 1.0)));
        for k in 2..=11 {
            a.cycle(k * ms, Some(&command(k, 1, 1.0)));
        }
        b.cycle(11 * ms, Some(&command(2, 1, 1.0)));
        let (va, vb) = (a.axes()[0].velocity, b.axes()[0].velocity);
        assert!((va - vb).abs() < 1e-9, "{va} vs {vb}");
    }
}
