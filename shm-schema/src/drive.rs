//! Servo, drives and the fieldbus image.

use crate::MAX_AXES;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Effort command from servo to the drives, `<i>/servo/drive_command`, every servo cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::DriveCommandV1")]
pub struct DriveCommandV1 {
    /// +1 per command; the drives use its advance as their command watchdog.
    pub seq: u64,
    /// Servo cycle that produced it (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// 1 asks the drives to be enabled. After a drive fault, enable must go 0 then 1.
    pub enable: u32,
    /// Number of axes in use.
    pub axes: u32,
    /// Effort per axis: N for linear axes, N·m for rotary ones.
    pub effort: [f64; MAX_AXES],
}

/// Drive fault codes in [`DriveFeedbackV1::fault`].
pub mod drive_fault {
    /// No fault.
    pub const NONE: u32 = 0;
    /// No new command for longer than the configured command timeout: enable dropped, brakes on.
    pub const COMMAND_TIMEOUT: u32 = 1;
}

/// What the drives measure, `<i>/machine/feedback`, every machine cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::DriveFeedbackV1")]
pub struct DriveFeedbackV1 {
    /// +1 per sample.
    pub seq: u64,
    /// Time the encoders were sampled (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// `seq` of the last drive command applied, 0 for none.
    pub command_seq: u64,
    /// 1 while the drives are enabled (power on the motors).
    pub enabled: u32,
    /// 1 while the holding brakes are engaged.
    pub brake: u32,
    /// [`drive_fault`] code, 0 for none.
    pub fault: u32,
    /// Number of axes in use.
    pub axes: u32,
    /// Encoder position per axis, quantised to the encoder resolution (axis unit).
    pub position: [f64; MAX_AXES],
    /// Velocity per axis (unit/s).
    pub velocity: [f64; MAX_AXES],
    /// Effort actually applied per axis, after the limit (N or N·m).
    pub effort: [f64; MAX_AXES],
}

/// Servo status bits in [`ServoStateV1::status`].
pub mod servo_status {
    /// The drives report enabled.
    pub const ENABLED: u32 = 1;
    /// No setpoint has arrived yet: servo holds the position it found.
    pub const NO_SETPOINT: u32 = 2;
    /// The latest setpoint is older than two trajgen periods: servo holds it.
    pub const SETPOINT_STALE: u32 = 4;
    /// A setpoint jumped further than the axes can move in one cycle and was refused.
    pub const SETPOINT_JUMP: u32 = 8;
    /// An axis' following error exceeded its limit.
    pub const FOLLOWING_ERROR: u32 = 16;
    /// The drives report a fault.
    pub const DRIVE_FAULT: u32 = 32;
    /// No drive feedback has arrived yet.
    pub const NO_FEEDBACK: u32 = 64;
}

/// What servo publishes on `<i>/servo/state` every cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::ServoStateV1")]
pub struct ServoStateV1 {
    /// +1 per servo cycle.
    pub seq: u64,
    /// Wake-up time of this servo cycle (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// Time the measured values were sampled by the drives (ns, `CLOCK_MONOTONIC`).
    pub measured_stamp_ns: u64,
    /// `seq` of the setpoint this cycle used, 0 for none.
    pub setpoint_seq: u64,
    /// [`servo_status`] bits.
    pub status: u32,
    /// Number of axes in use.
    pub axes: u32,
    /// Commanded position per axis (axis unit).
    pub cmd_position: [f64; MAX_AXES],
    /// Commanded velocity per axis (unit/s).
    pub cmd_velocity: [f64; MAX_AXES],
    /// Measured position per axis (axis unit).
    pub act_position: [f64; MAX_AXES],
    /// Measured velocity per axis (unit/s).
    pub act_velocity: [f64; MAX_AXES],
    /// Following error, commanded minus measured position (axis unit).
    pub following_error: [f64; MAX_AXES],
    /// Effort commanded per axis (N or N·m).
    pub effort: [f64; MAX_AXES],
}

/// Size of the simulated fieldbus output image, bytes.
pub const FIELDBUS_IMAGE_LEN: usize = 64;

/// The fieldbus output image iobridge writes every cycle, `<i>/iobridge/output`.
///
/// `image` is what goes on the wire (little-endian), as the CS9 example of seed 000 §5 does:
/// bytes 0..8 the measurement time in µs (`u64`, `CLOCK_MONOTONIC`), then one `i32` per axis,
/// the measured position in thousandths of the axis unit (µm, millidegrees).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("rtc::FieldbusImageV1")]
pub struct FieldbusImageV1 {
    /// +1 per written image.
    pub seq: u64,
    /// Time the image was written (ns, `CLOCK_MONOTONIC`).
    pub written_ns: u64,
    /// Time the position in it was measured (ns, `CLOCK_MONOTONIC`).
    pub measured_ns: u64,
    /// `seq` of the servo state it was taken from.
    pub source_seq: u64,
    /// Bytes of `image` in use.
    pub len: u32,
    /// Number of axes in the image.
    pub axes: u32,
    /// The output image, see the type's documentation.
    pub image: [u8; FIELDBUS_IMAGE_LEN],
}
