//! The drive boundary (CiA 402), servo's state, its requests, and the fieldbus image.
//!
//! The drives speak the CiA 402 device profile (IEC 61800-7-201), as EtherCAT and CANopen
//! drives do: per axis a controlword (object 0x6040) and a mode of operation (0x6060) go down
//! with the cyclic targets of the mode, a statusword (0x6041), the mode display (0x6061), the
//! error code (0x603F) and the actual values come back. The `cia402` crate holds the state
//! machine both ends share and `docs/drives.md` explains the boundary.
//!
//! The values are in the axis' units as `f64` (not the profile's integer increments and ‰ of
//! rated torque): a bridge to a real drive converts them with the drive's scaling.

use crate::MAX_AXES;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// The command of one servo cycle to every drive, `<i>/servo/drive_command`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::DriveCommandV2")]
pub struct DriveCommandV2 {
    /// +1 per command; the drives' command watchdog watches its advance.
    pub seq: u64,
    /// Servo cycle that produced it (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// `seq` of the [`DriveFeedbackV2`] sample this command was computed from, 0 for none.
    pub feedback_seq: u64,
    /// `stamp_ns` of that sample: the drives measure the sense-to-command latency from it.
    pub feedback_stamp_ns: u64,
    /// Number of axes in use.
    pub axes: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// Controlword per axis (CiA 402 object 0x6040).
    pub controlword: [u16; MAX_AXES],
    /// Mode of operation per axis (0x6060): 8 CSP, 9 CSV, 10 CST.
    pub mode: [i8; MAX_AXES],
    /// Target position per axis (0x607A, CSP; axis unit).
    pub target_position: [f64; MAX_AXES],
    /// Target velocity per axis (0x60FF, CSV; unit/s).
    pub target_velocity: [f64; MAX_AXES],
    /// Target torque per axis (0x6071, CST; N for linear axes, N·m for rotary ones).
    pub target_torque: [f64; MAX_AXES],
    /// Velocity offset per axis (0x60B1: velocity feed-forward in CSP, added in CSV; unit/s).
    pub velocity_offset: [f64; MAX_AXES],
    /// Torque offset per axis (0x60B2: torque feed-forward in CSP/CSV, added in CST; effort).
    pub torque_offset: [f64; MAX_AXES],
}

/// What the drives measure, `<i>/drives/feedback`, every drive cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::DriveFeedbackV2")]
pub struct DriveFeedbackV2 {
    /// +1 per sample.
    pub seq: u64,
    /// Time the encoders were sampled (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// `seq` of the last drive command applied, 0 for none.
    pub command_seq: u64,
    /// Sense-to-command latency of the command applied this cycle: the time it was applied
    /// minus the sampling time of the feedback it was computed from (ns); 0 when no new
    /// command was applied this cycle.
    pub sense_to_command_ns: u64,
    /// Number of axes in use.
    pub axes: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// Statusword per axis (0x6041). Decode it with the profile's masks (`cia402`).
    pub statusword: [u16; MAX_AXES],
    /// Mode of operation display per axis (0x6061): the mode requested by the previous
    /// command (a change takes effect one drive cycle after it arrives).
    pub mode_display: [i8; MAX_AXES],
    /// Error code per axis (0x603F): the latest fault, 0 for none; kept until a fault reset.
    pub error_code: [u16; MAX_AXES],
    /// Position actual value per axis (0x6064), quantised to the encoder (axis unit).
    pub position: [f64; MAX_AXES],
    /// Velocity actual value per axis (0x606C; unit/s).
    pub velocity: [f64; MAX_AXES],
    /// Torque actual value per axis (0x6077): the effort applied after the limit.
    pub torque: [f64; MAX_AXES],
    /// Following error actual value per axis (0x60F4): in CSP, the drive's target minus the
    /// actual position; 0 in the other modes.
    pub following_error: [f64; MAX_AXES],
}

/// Servo status bits in [`ServoStateV3::status`].
pub mod servo_status {
    /// Every axis is in Operation enabled and servo follows setpoints.
    pub const ENABLED: u32 = 1;
    /// No setpoint has been taken since the arm was enabled: servo holds where it is.
    pub const NO_SETPOINT: u32 = 2;
    /// The latest setpoint is older than the setpoint timeout: servo brings the reference
    /// to rest along its path and holds.
    pub const SETPOINT_STALE: u32 = 4;
    /// The first setpoint of a new source did not start where servo holds and was refused;
    /// servo holds.
    pub const SETPOINT_JUMP: u32 = 8;
    /// A fault is latched (see [`super::ServoStateV3::fault_code`]): power was cut and stays
    /// off until a reset request.
    pub const FAULT_LATCHED: u32 = 16;
    /// No drive feedback has arrived yet.
    pub const NO_FEEDBACK: u32 = 64;
    /// Every axis is settled: following error and velocity under their tolerances for the
    /// settle time.
    pub const SETTLED: u32 = 128;
    /// The drives have finished their start-up (no axis is in Not ready to switch on).
    pub const INITIALIZED: u32 = 256;
}

wire_enum! {
    /// Power state of the arm and of each axis (seed 001's `LLI_state`), in
    /// [`ServoStateV3::power`] and [`ServoStateV3::axis_power`].
    pub enum Power: u8 {
        /// No torque: the drive's power stage is off (or its motor not controlled).
        Disabled = 0 as "disabled",
        /// An enable request is stepping the drive through its states.
        Enabling = 1 as "enabling",
        /// Operation enabled: the axis follows servo.
        Enabled = 2 as "enabled",
        /// A disable request or a cut is taking power off.
        Disabling = 3 as "disabling",
    }
}

/// What servo publishes on `<i>/servo/state` every cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::ServoStateV3")]
pub struct ServoStateV3 {
    /// +1 per servo cycle.
    pub seq: u64,
    /// Wake-up time of this servo cycle (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// Time the measured values were sampled by the drives (ns, `CLOCK_MONOTONIC`).
    pub measured_stamp_ns: u64,
    /// `seq` of the setpoint this cycle used, 0 for none.
    pub setpoint_seq: u64,
    /// `seq` of the last [`ServoRequestV1`] taken, 0 for none.
    pub request_seq: u64,
    /// [`servo_status`] bits.
    pub status: u32,
    /// Number of axes in use.
    pub axes: u32,
    /// Power state of the arm, [`Power`] as `u8`: enabled only when every axis is.
    pub power: u8,
    /// Power state per axis, [`Power`] as `u8`.
    pub axis_power: [u8; MAX_AXES],
    /// Reserved, 0.
    pub reserved: [u8; 7],
    /// Bit `i` set: axis `i` is settled.
    pub settled_axes: u32,
    /// Event code of the latched fault (`crate::event::code`), 0 for none.
    pub fault_code: u32,
    /// Axis of the latched fault, -1 for none or the whole arm.
    pub fault_axis: i32,
    /// Reserved, 0.
    pub reserved2: u32,
    /// The value that tripped the latched fault (its unit is the code's).
    pub fault_value: f64,
    /// The limit it exceeded.
    pub fault_limit: f64,
    /// Controlword sent per axis this cycle.
    pub controlword: [u16; MAX_AXES],
    /// Statusword the drives reported per axis.
    pub statusword: [u16; MAX_AXES],
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
    /// Effort per axis: commanded (CST) or reported by the drive (CSP, CSV) (N or N·m).
    pub effort: [f64; MAX_AXES],
    /// `program_id` of the setpoints `peak_following_error` covers, 0 for none yet.
    pub peak_program: u32,
    /// Reserved, 0.
    pub reserved3: u32,
    /// Largest |following error| per axis (axis unit) servo found in any of its cycles since
    /// the first setpoint of program `peak_program`: the figure a run's verdict takes, since
    /// servo sees every cycle and a reader of this service may miss states.
    pub peak_following_error: [f64; MAX_AXES],
}

wire_enum! {
    /// What a [`ServoRequestV1`] asks for (seed 001's `LLI_enable`, `LLI_disable`).
    pub enum RequestKind: u32 {
        /// Start the enabling sequence of every axis.
        Enable = 1,
        /// Start the disabling sequence; aborts a pending enable.
        Disable = 2,
        /// Clear a latched fault (and reset the drives' faults) if its cause is gone. Power
        /// stays off: an enable must follow.
        Reset = 3,
        /// Commissioning: offset the reference of `axis` by `value` (axis unit) from the next
        /// cycle, a step; 0 removes the offset (a step back). Taken only while enabled, at rest,
        /// with |value| at most half the axis' following-error limit and the result within its
        /// range: the one position step command validation lets through. Any power change or
        /// fault clears the offset.
        Step = 4,
    }
}

/// A request to servo, `<i>/servo/request`; servo takes it in its next cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::ServoRequestV1")]
pub struct ServoRequestV1 {
    /// Increasing per requester; servo acts on every new value and echoes it in
    /// [`ServoStateV3::request_seq`].
    pub seq: u64,
    /// [`RequestKind`] as `u32`.
    pub kind: u32,
    /// Axis index (`Step`); 0 otherwise.
    pub axis: u32,
    /// The step (`Step`, axis unit); 0 otherwise.
    pub value: f64,
}

/// Faults the simulated drives can be told to raise.
pub mod injected {
    /// Over-current (CiA 402 error code 0x2310).
    pub const OVER_CURRENT: u16 = 0x2310;
    /// Encoder loss: position sensor error (0x7320); the position reads as not a number.
    pub const ENCODER_LOSS: u16 = 0x7320;
    /// Following error (0x8611), as the drive's own monitor would raise it.
    pub const FOLLOWING_ERROR: u16 = 0x8611;
}

/// A commanded fault injection, `<i>/drives/inject`: the simulated drive of `axis` sees the
/// fault condition `code` from the next drive cycle until a later injection on the same axis
/// clears it (`active` 0).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::FaultInjectionV1")]
pub struct FaultInjectionV1 {
    /// Increasing per sender.
    pub seq: u64,
    /// Axis index.
    pub axis: u32,
    /// One of [`injected`].
    pub code: u16,
    /// 1 raises the condition, 0 clears it.
    pub active: u16,
}

/// Size of the simulated fieldbus output image, bytes.
pub const FIELDBUS_IMAGE_LEN: usize = 64;

/// Value of a position in the fieldbus image when there is no valid measurement (the drive's
/// feedback was not a finite number).
pub const IMAGE_INVALID: i32 = i32::MIN;

/// Encodes a position in thousandths of the axis unit (saturating at the `i32` range just
/// inside it); a value that is not finite (no valid measurement) is [`IMAGE_INVALID`], never
/// a believable number.
#[inline]
pub fn milli_units(v: f64) -> i32 {
    if !v.is_finite() {
        return IMAGE_INVALID;
    }
    crate::bound(
        libm::round(v * 1000.0),
        IMAGE_INVALID as f64 + 1.0,
        i32::MAX as f64,
    ) as i32
}

/// The fieldbus output image iobridge writes every cycle, `<i>/iobridge/output`.
///
/// `image` is what goes on the wire (little-endian), as the CS9 example of seed 000 §5 does:
/// bytes 0..8 the measurement time in µs (`u64`, `CLOCK_MONOTONIC`), then one `i32` per axis,
/// the measured position in thousandths of the axis unit (µm, millidegrees), or
/// [`IMAGE_INVALID`] when there is no valid measurement.
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

impl FieldbusImageV1 {
    /// Axis `k`'s position as written (thousandths of the axis unit, [`IMAGE_INVALID`] for
    /// no valid measurement); `None` for an axis the image does not have.
    pub fn milli_position(&self, k: usize) -> Option<i32> {
        if k >= self.axes as usize {
            return None;
        }
        let at = 8 + 4 * k;
        let bytes: [u8; 4] = self.image.get(at..at + 4)?.try_into().ok()?;
        Some(i32::from_le_bytes(bytes))
    }

    /// Axis `k`'s position in axis units; `None` for an axis the image does not have or
    /// no valid measurement.
    pub fn position(&self, k: usize) -> Option<f64> {
        self.milli_position(k)
            .filter(|&raw| raw != IMAGE_INVALID)
            .map(|raw| f64::from(raw) / 1000.0)
    }
}
