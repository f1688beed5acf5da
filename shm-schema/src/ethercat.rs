//! The cell's EtherCAT bus (`[ethercat]`, `docs/ethercat.md`): the interface the bus process
//! owns, the SubDevices it must find on the wire in order, and how each drive's objects map to
//! an axis of the cell. Published once by the supervisor on `<i>/ethercat/config` (history 1)
//! when the cell has a bus; the bus process (and the emulator of a test cell) read it.

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Capacity of [`EthercatConfigV1::subdevice`].
pub const MAX_SUBDEVICES: usize = 32;

/// Bytes of [`EthercatConfigV1::interface`] (a Linux interface name has at most 15).
pub const INTERFACE_LEN: usize = 16;

/// Bits of [`EthercatSubDeviceV1::flags`].
pub mod subdevice_flags {
    /// The revision found must equal [`super::EthercatSubDeviceV1::revision`] (else any).
    pub const CHECK_REVISION: u32 = 1;
    /// The SubDevice takes its outputs and latches its inputs on SYNC0 of Distributed Clocks
    /// (its ESC must have them), every drives' period, [`super::EthercatSubDeviceV1::sync0_shift_ns`]
    /// after the bus process wakes; without it, as the cycle's frame passes.
    pub const SYNC0: u32 = 2;
}

/// One SubDevice the bus must have at its place on the line.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::EthercatSubDeviceV1")]
pub struct EthercatSubDeviceV1 {
    /// Its name in the configuration (shown in events and errors), NUL-padded.
    pub name: [u8; 16],
    /// Vendor ID (0x1018:1, the SII's identity).
    pub vendor: u32,
    /// Product code (0x1018:2).
    pub product: u32,
    /// Revision number (0x1018:3); checked only with [`subdevice_flags::CHECK_REVISION`].
    pub revision: u32,
    /// [`subdevice_flags`].
    pub flags: u32,
    /// The axis this CiA 402 drive moves (an index into the cell's axes), -1 for a SubDevice
    /// that is no drive (a coupler, an IO terminal).
    pub axis: i32,
    /// With [`subdevice_flags::SYNC0`]: how long after the bus process' wake-up its SYNC0
    /// comes (ns, less than the drives' period); 0: half the period.
    pub sync0_shift_ns: u32,
    /// A drive's position unit: counts (0x6064, 0x607A) per axis unit; velocities (0x606C,
    /// 0x60FF, 0x60B1) are counts/s per unit/s.
    pub counts_per_unit: f64,
    /// A drive's rated torque (0x6076) in the axis' effort unit (N, N·m): torques (0x6071,
    /// 0x6077, 0x60B2) are thousandths of it.
    pub rated_effort: f64,
}

/// The cell's bus, `<i>/ethercat/config`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("rtc::EthercatConfigV1")]
pub struct EthercatConfigV1 {
    /// The network interface the bus process owns, NUL-padded.
    pub interface: [u8; INTERFACE_LEN],
    /// SubDevices in use, in wire order.
    pub count: u32,
    /// Entries of `io` in use.
    pub io_count: u32,
    /// The process data watchdog the bus process sets in every SubDevice (ns, a multiple of
    /// 100 µs; 0 leaves the SubDevice's own): when frames stop (the process died, the cable
    /// came out) the outputs go safe by themselves after this long.
    pub pd_watchdog_ns: u64,
    /// The SubDevices, first `count` used, position 0 nearest the MainDevice.
    pub subdevice: [EthercatSubDeviceV1; MAX_SUBDEVICES],
    /// The cell's `[[io]]` entries that are bits of IO terminals on the bus, first
    /// `io_count` used.
    pub io: [EthercatIoV1; crate::MAX_IO],
}

/// An `[[io]]` entry carried by the bus: a bit of a SubDevice's inputs (an input entry) or
/// outputs (an output entry) in its process image.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("rtc::EthercatIoV1")]
pub struct EthercatIoV1 {
    /// The entry's index in the cell's IO table (`CellConfigV6::io`).
    pub entry: u16,
    /// The SubDevice's position on the line.
    pub position: u16,
    /// The bit of its inputs or outputs, bit 0 the lowest of its first byte.
    pub bit: u16,
    /// Zero.
    pub reserved: u16,
}

impl Default for EthercatConfigV1 {
    fn default() -> Self {
        Self {
            interface: [0; INTERFACE_LEN],
            count: 0,
            io_count: 0,
            pd_watchdog_ns: 0,
            subdevice: [EthercatSubDeviceV1::default(); MAX_SUBDEVICES],
            io: [EthercatIoV1::default(); crate::MAX_IO],
        }
    }
}

impl EthercatConfigV1 {
    /// The SubDevices in use.
    pub fn subdevices(&self) -> &[EthercatSubDeviceV1] {
        &self.subdevice[..(self.count as usize).min(MAX_SUBDEVICES)]
    }

    /// The IO entries on the bus.
    pub fn ios(&self) -> &[EthercatIoV1] {
        &self.io[..(self.io_count as usize).min(crate::MAX_IO)]
    }

    /// The interface's name.
    pub fn interface(&self) -> &str {
        crate::str_of(&self.interface)
    }
}

impl EthercatSubDeviceV1 {
    /// The axis this drive moves, if it is one.
    pub fn axis(&self) -> Option<usize> {
        usize::try_from(self.axis).ok()
    }

    /// Its name.
    pub fn name(&self) -> &str {
        crate::str_of(&self.name)
    }
}

/// What [`EmulatorFaultV1::kind`] tells the emulator of a test cell to do.
pub mod emulator_fault {
    /// The cable pulled: no frame is answered (the SubDevices' watchdogs run on).
    pub const CABLE_PULLED: u32 = 1;
    /// The cable back: frames are answered again.
    pub const CABLE_BACK: u32 = 2;
    /// SubDevice `position` drops from OP to SAFE-OP with the error flag and AL status code
    /// `code` (as its own fault would take it).
    pub const LEAVE_OP: u32 = 3;
    /// SubDevice `position` (a drive) sends a CoE emergency of error code `code`.
    pub const EMERGENCY: u32 = 4;
    /// SubDevice `position` has product code `code` from now on (another device in its
    /// place; a MainDevice sees it at its next scan).
    pub const IDENTITY: u32 = 5;
    /// Input `bit` of SubDevice `position` (an input terminal) reads `code` (0 or 1) from now
    /// on, whatever the emulated field says: a button pressed, a sensor stuck.
    pub const INPUT: u32 = 6;
    /// The quartz of SubDevice `position`'s Distributed Clock runs `code` (an `i32`, parts per
    /// million, positive fast) off from now on; a SubDevice without DC ignores it.
    pub const CLOCK_DRIFT: u32 = 7;
}

/// A fault the emulated bus of a test cell is told to make, `<i>/ethercat/emulator/fault`
/// (`ethercat-emulator fault`); the emulator tells it was done by event `fault-injected`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("rtc::EmulatorFaultV1")]
pub struct EmulatorFaultV1 {
    /// Increasing per sender.
    pub seq: u64,
    /// One of [`emulator_fault`].
    pub kind: u32,
    /// The SubDevice's position on the line (where the kind has one).
    pub position: u32,
    /// The AL status code, emergency code, product code, input value or clock drift (where
    /// the kind has one).
    pub code: u32,
    /// The input bit ([`emulator_fault::INPUT`]), else 0.
    pub bit: u32,
}
