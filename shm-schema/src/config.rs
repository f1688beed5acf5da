//! The cell configuration as every process reads it from `<i>/cell/config`.
//!
//! The supervisor loads the TOML file (or the embedded default), validates it and publishes
//! this once, with history 1. A process finds its own entry of the process table by its name
//! (`--name`), and reads the axes; it needs no TOML parser, so a process in any language can
//! take part.

use crate::MAX_AXES;
use crate::io::{IoConfigV1, MAX_IO};
use crate::status::{MAX_PROCESSES, PROCESS_NAME_LEN, ProcessName};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// One entry of the process table: a process' name and its real-time settings.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::ProcessConfigV2")]
pub struct ProcessConfigV2 {
    /// The process' name, NUL-padded (`"servo"`): see [`ProcessName`].
    pub name: [u8; PROCESS_NAME_LEN],
    /// Cycle period (ns).
    pub period_ns: u64,
    /// Offset of the cycle's deadlines from multiples of the period (ns), to order the
    /// processes within a period.
    pub phase_ns: u64,
    /// `SCHED_FIFO` priority, 1..=99; 0 runs under `SCHED_OTHER`.
    pub priority: i32,
    /// CPU to pin the process to, -1 for none.
    pub cpu: i32,
    /// Its reaction to a propagated e-stop (seed 002's `network_estop_config`):
    /// [`EstopReaction`] as `u32`.
    pub network_estop_config: u32,
    /// [`process_flags`]: bits of the process' role in the cell (0: a critical process).
    pub flags: u32,
}

/// Bits of [`ProcessConfigV2::flags`].
pub mod process_flags {
    /// `critical = false`: the process is not part of the cell's safety (a fieldbus server
    /// for an HMI, a logger). Its loss, its stall or the expiry of one of its health
    /// detectors is a warning and a restart (per its policy), never an e-stop, and never
    /// ends a program.
    pub const NOT_CRITICAL: u32 = 1;
}

impl ProcessConfigV2 {
    /// Whether the cell's safety depends on it (the `critical` key; see
    /// [`process_flags::NOT_CRITICAL`]).
    pub fn critical(&self) -> bool {
        self.flags & process_flags::NOT_CRITICAL == 0
    }
}

/// Bytes of [`ModbusConfigV1::listen`].
pub const LISTEN_LEN: usize = 64;

/// The cell's Modbus TCP server (`[modbus]`), read by the process that serves it
/// (`docs/fieldbus.md`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("rtc::ModbusConfigV1")]
pub struct ModbusConfigV1 {
    /// The address to listen on, NUL-padded text (`"127.0.0.1:1502"`; port 0: any free port,
    /// announced in an event and in `supervisor status`).
    pub listen: [u8; LISTEN_LEN],
    /// Connections served at once; one more is closed as soon as it is accepted.
    pub max_connections: u32,
    /// 1: the writable coils and holding registers take writes; 0: every write gets an
    /// exception (a read-only fieldbus).
    pub writes: u32,
    /// A connection that sends no request for this long is closed (ns).
    pub idle_timeout_ns: u64,
}

impl Default for ModbusConfigV1 {
    fn default() -> Self {
        Self {
            listen: [0; LISTEN_LEN],
            max_connections: 0,
            writes: 0,
            idle_timeout_ns: 0,
        }
    }
}

wire_enum! {
    /// A process' reaction to an e-stop it did not raise itself (`network_estop_config`).
    pub enum EstopReaction: u32 {
        /// Its safe reaction: servo brakes the axes to rest within the e-stop stop time and
        /// disables the drives; trajgen drops the program; iobridge sets its outputs to their safe
        /// values. The default.
        Stop = 0 as "stop",
        /// servo brakes the axes to rest and holds them, drives enabled (a stop of category 2);
        /// any other process reacts as with `Stop`.
        Hold = 1 as "hold",
        /// No reaction: the process sees the e-stop and goes on (a logger, a monitor).
        Ignore = 2 as "ignore",
    }
}

/// Seed 002's health detectors (`[health_config]`), the same for every process of the cell.
/// Each is a leaky bucket: +1 per overrun, -1 per leak time; it expires (a host e-stop naming
/// the detector and the process) when the count reaches `percent_limit` % of the process'
/// rate (cycles per second).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::HealthConfigV1")]
pub struct HealthConfigV1 {
    /// `pending_sequence_overrun_percent_limit` (%).
    pub pending_sequence_overrun_percent_limit: f64,
    /// `pending_sequence_overrun_leak_time_s` (s).
    pub pending_sequence_overrun_leak_time_s: f64,
    /// `pending_sequence_overrun_start_snooze_s` (s).
    pub pending_sequence_overrun_start_snooze_s: f64,
    /// `transport_overrun_percent_limit` (%).
    pub transport_overrun_percent_limit: f64,
    /// `transport_overrun_leak_time_s` (s).
    pub transport_overrun_leak_time_s: f64,
    /// `thread_offset_variance_percent` (% of the period): a wake-up later than this counts.
    pub thread_offset_variance_percent: f64,
    /// `thread_offset_variance_overrun_percent_limit` (%).
    pub thread_offset_variance_overrun_percent_limit: f64,
    /// `thread_offset_variance_overrun_leak_time_s` (s).
    pub thread_offset_variance_overrun_leak_time_s: f64,
    /// `thread_offset_variance_start_snooze_s` (s).
    pub thread_offset_variance_start_snooze_s: f64,
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

/// Parameters of a kinematics a configuration may give.
pub const MAX_KIN_PARAMS: usize = 8;

/// One numeric parameter of the kinematics (`l1 = 200.0`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::KinParamV1")]
pub struct KinParamV1 {
    /// Its name, NUL-padded.
    pub name: [u8; 16],
    /// Its value.
    pub value: f64,
}

/// The cell's kinematics (`[kinematics]`, `docs/kinematics.md`): which one, with which
/// parameters, and the Cartesian speed limits of `MOVE`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::KinematicsConfigV1")]
pub struct KinematicsConfigV1 {
    /// Its name in the registry (`"gantry"`, `"scara"`, `"five-bar"`), NUL-padded; empty
    /// for the gantry.
    pub type_name: [u8; 24],
    /// Entries of `params` in use.
    pub param_count: u32,
    /// Cartesian coordinates of the kinematics.
    pub coords: u32,
    /// The parameters.
    pub params: [KinParamV1; MAX_KIN_PARAMS],
    /// Largest velocity per Cartesian coordinate (unit/s): `MOVE`'s segment times.
    pub coord_vmax: [f64; MAX_AXES],
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

/// Capacity of [`CellConfigV6::inject`].
pub const MAX_CONFIGURED_FAULTS: usize = 4;

/// The whole cell.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("rtc::CellConfigV6")]
pub struct CellConfigV6 {
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
    /// On an e-stop, servo brings every axis from its vmax to rest within this time, then
    /// disables the drives (ns).
    pub estop_stop_time_ns: u64,
    /// A process whose supervisor has not beaten for this long reacts as to an e-stop of the
    /// host, brings the axes to rest and exits (ns).
    pub supervisor_timeout_ns: u64,
    /// Seed 002's `propagate_estop`: 1 when a process' own e-stop is propagated to every
    /// process, 0 when only that process reacts.
    pub propagate_estop: u32,
    /// Seed 002's `propagate_external_estop`: 1 when a user's e-stop (`supervisor estop`, an
    /// e-stop input) is propagated even with `propagate_estop` 0.
    pub propagate_external_estop: u32,
    /// Entries of `process` in use.
    pub process_count: u32,
    /// The clock the cell runs on: [`crate::CellClock`] as `u32` (0 the wall clock, 1 the
    /// supervisor's virtual clock, `shm_schema::clock`).
    pub clock: u32,
    /// The health detectors.
    pub health: HealthConfigV1,
    /// The process table, in start order; the first `process_count` are in use.
    pub process: [ProcessConfigV2; MAX_PROCESSES],
    /// Axes; the first `axes` are in use.
    pub axis: [AxisConfigV2; MAX_AXES],
    /// Configured fault injections; entries with `code` 0 are unused.
    pub inject: [ConfiguredFaultV1; MAX_CONFIGURED_FAULTS],
    /// Entries of `io` in use.
    pub io_count: u32,
    /// Reserved, 0.
    pub reserved2: u32,
    /// The named digital IO; entry `k` is bit `k` of [`crate::DigitalIoV1`]'s masks.
    pub io: [IoConfigV1; MAX_IO],
    /// The kinematics.
    pub kinematics: KinematicsConfigV1,
    /// The Modbus TCP server's settings (`[modbus]`).
    pub modbus: ModbusConfigV1,
}

impl Default for CellConfigV6 {
    fn default() -> Self {
        Self {
            axes: 0,
            machine_substeps: 0,
            t_acc_s: 0.0,
            drive_command_timeout_ns: 0,
            setpoint_timeout_ns: 0,
            feedback_timeout_ns: 0,
            enable_timeout_ns: 0,
            settle_time_ns: 0,
            estop_stop_time_ns: 0,
            supervisor_timeout_ns: 0,
            propagate_estop: 0,
            propagate_external_estop: 0,
            process_count: 0,
            clock: 0,
            health: HealthConfigV1::default(),
            process: [ProcessConfigV2::default(); MAX_PROCESSES],
            axis: [AxisConfigV2::default(); MAX_AXES],
            inject: [ConfiguredFaultV1::default(); MAX_CONFIGURED_FAULTS],
            io_count: 0,
            reserved2: 0,
            io: [IoConfigV1::default(); MAX_IO],
            kinematics: KinematicsConfigV1::default(),
            modbus: ModbusConfigV1::default(),
        }
    }
}

impl CellConfigV6 {
    /// The axes in use.
    pub fn axes(&self) -> &[AxisConfigV2] {
        &self.axis[..(self.axes as usize).min(MAX_AXES)]
    }

    /// The process table entries in use.
    pub fn processes(&self) -> &[ProcessConfigV2] {
        &self.process[..(self.process_count as usize).min(MAX_PROCESSES)]
    }

    /// The IO entries in use.
    pub fn io(&self) -> &[IoConfigV1] {
        &self.io[..(self.io_count as usize).min(MAX_IO)]
    }

    /// Index of the IO entry called `name`.
    pub fn io_named(&self, name: &str) -> Option<usize> {
        self.io()
            .iter()
            .position(|e| crate::str_of(&e.name) == name)
    }

    /// Index and entry of the process called `name`.
    pub fn process_named(&self, name: &str) -> Option<(usize, &ProcessConfigV2)> {
        self.processes()
            .iter()
            .enumerate()
            .find(|(_, p)| crate::str_of(&p.name) == name)
    }

    /// The period of the process called `name` (ns), if the table has one.
    pub fn period_of(&self, name: &str) -> Option<u64> {
        self.process_named(name).map(|(_, p)| p.period_ns)
    }

    /// The name of process `index`, if it is a valid one.
    pub fn process_name(&self, index: usize) -> Option<ProcessName> {
        self.processes()
            .get(index)
            .and_then(|p| ProcessName::from_field(&p.name))
    }
}
