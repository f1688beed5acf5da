//! The cell configuration as every process reads it from `<i>/cell/config`.
//!
//! The supervisor loads the TOML file (or the embedded default), validates it and publishes
//! this once, with history 1. A process reads its own `process[role]` entry and the axes; it
//! needs no TOML parser, so a process in any language can take part.

use crate::MAX_AXES;
use crate::status::ROLE_COUNT;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Real-time settings of one process.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::ProcessConfigV1")]
pub struct ProcessConfigV1 {
    /// Cycle period (ns).
    pub period_ns: u64,
    /// Offset of the cycle's deadlines from multiples of the period (ns), to order the
    /// processes within a period.
    pub phase_ns: u64,
    /// `SCHED_FIFO` priority, 1..=99; 0 runs under `SCHED_OTHER`.
    pub priority: i32,
    /// CPU to pin the process to, -1 for none.
    pub cpu: i32,
}

/// One axis: limits, motion parameters, servo gains and the simulated mechanics.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::AxisConfigV1")]
pub struct AxisConfigV1 {
    /// Axis name, NUL-padded UTF-8 (`"x"`).
    pub name: [u8; 16],
    /// Unit name, NUL-padded UTF-8 (`"mm"`, `"deg"`).
    pub unit: [u8; 8],
    /// Lowest allowed position (unit).
    pub min: f64,
    /// Highest allowed position (unit).
    pub max: f64,
    /// Largest velocity (unit/s): the `vmax_i` of T1.
    pub vmax: f64,
    /// Position the simulated machine starts at (unit).
    pub start: f64,
    /// Following error beyond which servo reports a fault (unit).
    pub following_error_limit: f64,
    /// The axis is in position when |following error| stays below this (unit).
    pub in_position: f64,
    /// Proportional gain (effort/unit).
    pub kp: f64,
    /// Integral gain (effort/(unit·s)).
    pub ki: f64,
    /// Derivative gain on the velocity error (effort·s/unit).
    pub kd: f64,
    /// Velocity feed-forward (effort·s/unit).
    pub kvff: f64,
    /// Acceleration feed-forward (effort·s²/unit).
    pub kaff: f64,
    /// Largest effort the integral term may contribute (effort).
    pub integral_limit: f64,
    /// Simulated inertia (effort·s²/unit: kg/1000 for mm axes).
    pub inertia: f64,
    /// Simulated viscous friction (effort·s/unit).
    pub viscous: f64,
    /// Simulated Coulomb friction (effort).
    pub coulomb: f64,
    /// Largest effort the drive delivers (effort).
    pub effort_limit: f64,
    /// Encoder resolution (unit per count).
    pub encoder_resolution: f64,
}

/// The whole cell.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::CellConfigV1")]
pub struct CellConfigV1 {
    /// Number of axes in use, 1..=[`MAX_AXES`].
    pub axes: u32,
    /// Integration steps of the simulated machine per machine cycle.
    pub machine_substeps: u32,
    /// Acceleration time `t_acc` (s): blend zones last `2 t_acc`.
    pub t_acc_s: f64,
    /// The drives drop enable and brake when no new command came for this long (ns).
    pub drive_command_timeout_ns: u64,
    /// Servo extrapolates the latest setpoint at most this long, then holds (ns).
    pub setpoint_timeout_ns: u64,
    /// Real-time settings per process, indexed by [`crate::Role`].
    pub process: [ProcessConfigV1; ROLE_COUNT],
    /// Axes; the first `axes` are in use.
    pub axis: [AxisConfigV1; MAX_AXES],
}

impl CellConfigV1 {
    /// The axes in use.
    pub fn axes(&self) -> &[AxisConfigV1] {
        &self.axis[..(self.axes as usize).min(MAX_AXES)]
    }
}
