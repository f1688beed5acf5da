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

/// One axis: limits, command validation, servo gains, the drive and the simulated mechanics.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::AxisConfigV2")]
pub struct AxisConfigV2 {
    /// Axis name, NUL-padded UTF-8 (`"x"`).
    pub name: [u8; 16],
    /// Unit name, NUL-padded UTF-8 (`"mm"`, `"deg"`).
    pub unit: [u8; 8],
    /// Lowest allowed position (unit): the joint range of command validation.
    pub min: f64,
    /// Highest allowed position (unit).
    pub max: f64,
    /// Largest velocity (unit/s): the `vmax_i` of T1.
    pub vmax: f64,
    /// Position the simulated machine starts at (unit).
    pub start: f64,
    /// Following error beyond which servo cuts power and latches the fault (unit).
    pub following_error_limit: f64,
    /// Settled: |following error| at most this (unit)...
    pub in_position: f64,
    /// ...and |measured velocity| at most this (unit/s), for the cell's settle time.
    pub settle_velocity: f64,
    /// Command validation: largest |commanded velocity| (unit/s).
    pub velocity_limit: f64,
    /// Command validation: largest change of the commanded position in one servo period
    /// (unit), scaled by the real time since the previous cycle.
    pub position_step_limit: f64,
    /// Command validation: largest change of the commanded velocity in one servo period
    /// (unit/s), scaled the same way.
    pub velocity_step_limit: f64,
    /// Deceleration servo uses to bring the reference to rest when setpoints stop (unit/s²).
    pub stop_deceleration: f64,
    /// Servo's proportional gain (effort/unit; in CSV: (unit/s)/unit).
    pub kp: f64,
    /// Servo's integral gain (effort/(unit·s)).
    pub ki: f64,
    /// Servo's derivative gain on the velocity error (effort·s/unit).
    pub kd: f64,
    /// Velocity feed-forward (effort·s/unit).
    pub kvff: f64,
    /// Acceleration feed-forward (effort·s²/unit).
    pub kaff: f64,
    /// Largest effort the integral term may contribute (effort).
    pub integral_limit: f64,
    /// Mode of operation of the axis' drive (CiA 402 0x6060): 8 CSP (the drive closes the
    /// position loop), 9 CSV, 10 CST (servo closes it and commands torque; the default).
    pub mode: i32,
    /// Quick stop option code of the drive (0x605A): 0 coast, 1 slow-down ramp, 2 quick-stop
    /// ramp (default), 6 ramp and stay in Quick stop active.
    pub quick_stop_option: i32,
    /// The drive's own position gain (CSP; effort/unit).
    pub drive_kp: f64,
    /// The drive's own integral gain (CSP, CSV; effort/(unit·s), effort/unit in CSV).
    pub drive_ki: f64,
    /// The drive's own velocity gain (CSP, CSV; effort·s/unit).
    pub drive_kd: f64,
    /// The drive's quick-stop deceleration (0x6085; unit/s²).
    pub quick_stop_deceleration: f64,
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

/// A fault the simulated drives raise by configuration (`[[drives.inject]]`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::ConfiguredFaultV1")]
pub struct ConfiguredFaultV1 {
    /// Time after the drive first reaches Operation enabled (ns).
    pub at_ns: u64,
    /// How long the condition stays present (ns); 0: one drive cycle.
    pub duration_ns: u64,
    /// Axis index.
    pub axis: u32,
    /// CiA 402 error code (`crate::drive::injected`); 0 for an unused entry.
    pub code: u32,
}

/// Capacity of [`CellConfigV2::inject`].
pub const MAX_CONFIGURED_FAULTS: usize = 4;

/// The whole cell.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::CellConfigV2")]
pub struct CellConfigV2 {
    /// Number of axes in use, 1..=[`MAX_AXES`].
    pub axes: u32,
    /// Integration steps of the simulated machine per machine cycle.
    pub machine_substeps: u32,
    /// Acceleration time `t_acc` (s): blend zones last `2 t_acc`.
    pub t_acc_s: f64,
    /// A drive faults (0xFF01) when no new command came for this long (ns).
    pub drive_command_timeout_ns: u64,
    /// Servo extrapolates the latest setpoint at most this long, then brings the reference
    /// to rest (ns).
    pub setpoint_timeout_ns: u64,
    /// Servo cuts power when the drive feedback is older than this (ns).
    pub feedback_timeout_ns: u64,
    /// Longest enabling sequence (ns).
    pub enable_timeout_ns: u64,
    /// Time the axes must stay within their tolerances to be settled (ns).
    pub settle_time_ns: u64,
    /// Real-time settings per process, indexed by [`crate::Role`].
    pub process: [ProcessConfigV1; ROLE_COUNT],
    /// Axes; the first `axes` are in use.
    pub axis: [AxisConfigV2; MAX_AXES],
    /// Configured fault injections; entries with `code` 0 are unused.
    pub inject: [ConfiguredFaultV1; MAX_CONFIGURED_FAULTS],
}

impl CellConfigV2 {
    /// The axes in use.
    pub fn axes(&self) -> &[AxisConfigV2] {
        &self.axis[..(self.axes as usize).min(MAX_AXES)]
    }
}
