//! The cell's named digital IO (`[[io]]` in the configuration, `docs/io.md`).
//!
//! Entry `k` of the configuration's IO table is bit `k` of every mask and value here; an entry
//! is an input or an output. iobridge owns the IO: it takes the field's inputs
//! (`<i>/field/inputs`, published by whatever drives them — the simulated machine, a test, a
//! real fieldbus driver), takes output requests (`<i>/io/request`, from trajgen's `OUT`, the
//! CLI, the Modbus server), sets the outputs to their safe values when it reacts to an e-stop,
//! raises the e-stop when an e-stop input opens, and publishes the image every cycle
//! (`<i>/io/state`).

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Entries of the IO table: one bit each in a `u64`.
pub const MAX_IO: usize = 64;

/// Bytes of an IO name, NUL included.
pub const IO_NAME_LEN: usize = 24;

wire_enum! {
    /// Whether an IO entry is read from the field or written to it.
    pub enum IoDirection: u32 {
        /// Read from the field (a sensor, the e-stop circuit).
        Input = 1,
        /// Written to the field (a solenoid, a lamp).
        Output = 2,
    }
}

wire_enum! {
    /// What an output becomes when iobridge reacts to an e-stop.
    pub enum SafeValue: u32 {
        /// Switched off (a conveyor, a lamp): the default.
        Off = 0,
        /// Switched on (a brake that holds when energised).
        On = 1,
        /// Kept as it is (a gripper holding a part must not drop it).
        Hold = 2,
    }
}

/// One entry of the IO table.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::IoConfigV1")]
pub struct IoConfigV1 {
    /// The name the motion language and the tools use, NUL-padded (`"gripper"`).
    pub name: [u8; IO_NAME_LEN],
    /// [`IoDirection`] as `u32`.
    pub direction: u32,
    /// Outputs: [`SafeValue`] as `u32`.
    pub safe: u32,
    /// Inputs: 1 for an e-stop circuit (normally closed: 1 while closed; 0, pressed or a
    /// broken wire, raises the e-stop).
    pub estop: u32,
    /// Inputs: the value the simulated field gives until a field device drives it.
    pub sim: u32,
    /// Inputs: index of the output this input follows in the simulated field (a gripper's
    /// position sensor), -1 for none.
    pub follows: i32,
    /// Reserved, 0.
    pub reserved: u32,
    /// Inputs that follow an output: the switching time of the simulated device (ns).
    pub switch_time_ns: u64,
}

/// A write of some bits of the IO: an output request (`<i>/io/request`) or what a field device
/// reads (`<i>/field/inputs`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::IoWriteV1")]
pub struct IoWriteV1 {
    /// When it was written (ns, `CLOCK_MONOTONIC`).
    pub stamp_ns: u64,
    /// Bit `k` set: entry `k` is written.
    pub mask: u64,
    /// The values of the written bits (others ignored).
    pub values: u64,
    /// Who writes: a process index, or [`crate::event::SOURCE_SUPERVISOR`] for the supervisor
    /// and its tools.
    pub source: u32,
    /// The program line that asked, 0 for none.
    pub line: u32,
}

/// The IO image iobridge publishes every cycle on `<i>/io/state`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::DigitalIoV1")]
pub struct DigitalIoV1 {
    /// +1 per iobridge cycle.
    pub seq: u64,
    /// The cycle's wake-up time (ns).
    pub stamp_ns: u64,
    /// Bit `k`: the value of entry `k` (inputs as read, outputs as written).
    pub values: u64,
    /// Bit `k` set: entry `k` changed in this cycle.
    pub changed: u64,
    /// Output requests taken since iobridge started.
    pub taken: u64,
    /// Writes refused since iobridge started (an input written as an output or the reverse,
    /// a bit beyond the table, an output request while the e-stop holds the outputs safe).
    pub refused: u64,
    /// Entries in use.
    pub count: u32,
    /// 1 while iobridge holds the outputs at their safe values (it reacts to an e-stop); output
    /// requests are refused meanwhile.
    pub outputs_safe: u32,
}
