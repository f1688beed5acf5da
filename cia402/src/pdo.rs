//! The drive's objects on a fieldbus: their indices, the cell's process data mapping (what a
//! bus process writes into 0x1600/0x1A00 and what an emulated drive maps by default), the
//! packing of that mapping, and the scaling between the drive's units (counts, counts/s,
//! thousandths of the rated torque) and the axis' (unit, unit/s, effort).
//!
//! Shared by the EtherCAT bus process and the EtherCAT emulator's drive: one definition of
//! the wire on both sides. Constant time, no allocation; a value that does not fit its object
//! saturates, a value that is not finite becomes 0 (never undefined on the wire).

/// Subindices of the SyncManager synchronisation objects (0x1C32, 0x1C33; ETG.1020) and the
/// values of their sync mode.
pub mod sync {
    /// Sync mode (UNSIGNED16): [`FREE_RUN`], [`SM_EVENT`] or [`DC_SYNC0`].
    pub const MODE: u8 = 0x01;
    /// Cycle time (UNSIGNED32, ns).
    pub const CYCLE_TIME: u8 = 0x02;
    /// Shift time (UNSIGNED32, ns): of 0x1C33, how long after SYNC0 the inputs are latched.
    pub const SHIFT_TIME: u8 = 0x03;
    /// Sync modes supported (UNSIGNED16): bit 0 free run, bit 1 SM event, bits 2-3 = 01 DC
    /// SYNC0.
    pub const SUPPORTED: u8 = 0x04;
    /// The shortest cycle time (UNSIGNED32, ns).
    pub const MIN_CYCLE_TIME: u8 = 0x05;
    /// SM events missed (UNSIGNED16): SYNC0 events in OP that found no new outputs.
    pub const SM_EVENT_MISSED: u8 = 0x0B;
    /// Sync mode: free run, on the device's own timer.
    pub const FREE_RUN: u16 = 0;
    /// Sync mode: as the frame passes (the SyncManager event).
    pub const SM_EVENT: u16 = 1;
    /// Sync mode: on SYNC0 of Distributed Clocks.
    pub const DC_SYNC0: u16 = 2;
}

/// CiA 402 objects, and the ones the communication profile adds.
pub mod obj {
    /// Device type: 0x0192 (drive profile 402), servo (0x0002 in the high word).
    pub const DEVICE_TYPE: u16 = 0x1000;
    /// Device name.
    pub const NAME: u16 = 0x1008;
    /// Identity.
    pub const IDENTITY: u16 = 0x1018;
    /// The first RxPDO mapping (outputs).
    pub const RXPDO: u16 = 0x1600;
    /// The first TxPDO mapping (inputs).
    pub const TXPDO: u16 = 0x1A00;
    /// Each SyncManager's communication type (1, 2 mailbox; 3 outputs; 4 inputs).
    pub const SM_TYPES: u16 = 0x1C00;
    /// SM2's PDO assignment.
    pub const SM2_ASSIGN: u16 = 0x1C12;
    /// SM3's PDO assignment.
    pub const SM3_ASSIGN: u16 = 0x1C13;
    /// SM2's (the outputs') synchronisation parameters (ETG.1020 "SM output parameter"):
    /// subindices in [`super::sync`].
    pub const SM2_SYNC: u16 = 0x1C32;
    /// SM3's (the inputs') synchronisation parameters ("SM input parameter").
    pub const SM3_SYNC: u16 = 0x1C33;
    /// Error code.
    pub const ERROR_CODE: u16 = 0x603F;
    /// Controlword.
    pub const CONTROLWORD: u16 = 0x6040;
    /// Statusword.
    pub const STATUSWORD: u16 = 0x6041;
    /// Quick stop option code.
    pub const QUICK_STOP_OPTION: u16 = 0x605A;
    /// Modes of operation.
    pub const MODE: u16 = 0x6060;
    /// Modes of operation display.
    pub const MODE_DISPLAY: u16 = 0x6061;
    /// Position actual value (counts).
    pub const POSITION_ACTUAL: u16 = 0x6064;
    /// Velocity actual value (counts/s).
    pub const VELOCITY_ACTUAL: u16 = 0x606C;
    /// Target torque (‰ of the rated torque).
    pub const TARGET_TORQUE: u16 = 0x6071;
    /// Rated torque (mN·m: the axis' effort unit times 1000).
    pub const RATED_TORQUE: u16 = 0x6076;
    /// Torque actual value (‰).
    pub const TORQUE_ACTUAL: u16 = 0x6077;
    /// Target position (counts).
    pub const TARGET_POSITION: u16 = 0x607A;
    /// Quick stop deceleration (counts/s²).
    pub const QUICK_STOP_DECELERATION: u16 = 0x6085;
    /// Velocity offset (counts/s).
    pub const VELOCITY_OFFSET: u16 = 0x60B1;
    /// Torque offset (‰).
    pub const TORQUE_OFFSET: u16 = 0x60B2;
    /// Following error actual value (counts).
    pub const FOLLOWING_ERROR: u16 = 0x60F4;
    /// Target velocity (counts/s).
    pub const TARGET_VELOCITY: u16 = 0x60FF;
    /// Supported drive modes: CSP (bit 7), CSV (bit 8), CST (bit 9).
    pub const SUPPORTED_MODES: u16 = 0x6502;
}

/// The cell's RxPDO (outputs, SM2), in this order: index and bits of each entry (subindex 0).
pub const RX_DEFAULT: [(u16, u8); 7] = [
    (obj::CONTROLWORD, 16),
    (obj::MODE, 8),
    (obj::TARGET_POSITION, 32),
    (obj::TARGET_VELOCITY, 32),
    (obj::TARGET_TORQUE, 16),
    (obj::VELOCITY_OFFSET, 32),
    (obj::TORQUE_OFFSET, 16),
];
/// The cell's TxPDO (inputs, SM3).
pub const TX_DEFAULT: [(u16, u8); 7] = [
    (obj::STATUSWORD, 16),
    (obj::MODE_DISPLAY, 8),
    (obj::ERROR_CODE, 16),
    (obj::POSITION_ACTUAL, 32),
    (obj::VELOCITY_ACTUAL, 32),
    (obj::TORQUE_ACTUAL, 16),
    (obj::FOLLOWING_ERROR, 32),
];

/// Bytes of [`RX_DEFAULT`] and of [`TX_DEFAULT`] on the wire.
pub const PDO_BYTES: usize = 19;

/// A PDO mapping entry: index, subindex, bits.
pub const fn mapping(index: u16, sub: u8, bits: u8) -> u32 {
    ((index as u32) << 16) | ((sub as u32) << 8) | bits as u32
}

/// One drive's outputs in [`RX_DEFAULT`], in the drive's units.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RxPdo {
    /// 0x6040.
    pub controlword: u16,
    /// 0x6060.
    pub mode: i8,
    /// 0x607A, counts.
    pub target_position: i32,
    /// 0x60FF, counts/s.
    pub target_velocity: i32,
    /// 0x6071, ‰.
    pub target_torque: i16,
    /// 0x60B1, counts/s.
    pub velocity_offset: i32,
    /// 0x60B2, ‰.
    pub torque_offset: i16,
}

impl RxPdo {
    /// Writes it into the first [`PDO_BYTES`] of `out` (nothing if `out` is shorter).
    pub fn write(&self, out: &mut [u8]) {
        let Some(o) = out.get_mut(..PDO_BYTES) else {
            return;
        };
        o[0..2].copy_from_slice(&self.controlword.to_le_bytes());
        o[2] = self.mode as u8;
        o[3..7].copy_from_slice(&self.target_position.to_le_bytes());
        o[7..11].copy_from_slice(&self.target_velocity.to_le_bytes());
        o[11..13].copy_from_slice(&self.target_torque.to_le_bytes());
        o[13..17].copy_from_slice(&self.velocity_offset.to_le_bytes());
        o[17..19].copy_from_slice(&self.torque_offset.to_le_bytes());
    }
}

/// One drive's inputs in [`TX_DEFAULT`], in the drive's units.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TxPdo {
    /// 0x6041.
    pub statusword: u16,
    /// 0x6061.
    pub mode_display: i8,
    /// 0x603F.
    pub error_code: u16,
    /// 0x6064, counts.
    pub position: i32,
    /// 0x606C, counts/s.
    pub velocity: i32,
    /// 0x6077, ‰.
    pub torque: i16,
    /// 0x60F4, counts.
    pub following_error: i32,
}

impl TxPdo {
    /// Reads it from the first [`PDO_BYTES`] of `i` (`None` if `i` is shorter).
    pub fn read(i: &[u8]) -> Option<Self> {
        let i = i.get(..PDO_BYTES)?;
        let u16_at = |k: usize| u16::from_le_bytes([i[k], i[k + 1]]);
        let i32_at = |k: usize| i32::from_le_bytes([i[k], i[k + 1], i[k + 2], i[k + 3]]);
        Some(Self {
            statusword: u16_at(0),
            mode_display: i[2] as i8,
            error_code: u16_at(3),
            position: i32_at(5),
            velocity: i32_at(9),
            torque: u16_at(13) as i16,
            following_error: i32_at(15),
        })
    }
}

/// The drive's units against the axis': counts per axis unit (position and velocity) and the
/// rated torque in the axis' effort unit (1000 ‰).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scaling {
    /// Encoder counts per axis unit.
    pub counts_per_unit: f64,
    /// The rated torque, in the axis' effort unit.
    pub rated_effort: f64,
}

impl Scaling {
    /// A count value of `units`, rounded and saturated to i32 (a non-finite value is 0).
    pub fn counts(&self, units: f64) -> i32 {
        round_i32(units * self.counts_per_unit)
    }

    /// Axis units of `counts`.
    pub fn units(&self, counts: i32) -> f64 {
        f64::from(counts) / self.counts_per_unit
    }

    /// Thousandths of the rated torque of `effort`, rounded and saturated to i16 (a
    /// non-finite value is 0).
    pub fn permille(&self, effort: f64) -> i16 {
        let v = round_i32(effort / self.rated_effort * 1000.0);
        v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16
    }

    /// The effort of `permille`.
    pub fn effort(&self, permille: i16) -> f64 {
        f64::from(permille) * self.rated_effort / 1000.0
    }
}

/// `v` rounded half away from zero, saturated to i32; NaN is 0 (Rust's `as` saturates and
/// takes NaN to 0).
fn round_i32(v: f64) -> i32 {
    let half = if v < 0.0 { -0.5 } else { 0.5 };
    (v + half) as i32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_saturate_and_never_leave_the_type() {
        let s = Scaling {
            counts_per_unit: 1000.0,
            rated_effort: 10.0,
        };
        assert_eq!(s.counts(40.0004), 40_000);
        assert_eq!(s.counts(40.0005), 40_001);
        assert_eq!(s.counts(-40.0005), -40_001);
        assert_eq!(s.counts(f64::NAN), 0);
        assert_eq!(s.counts(f64::INFINITY), i32::MAX);
        assert_eq!(s.counts(-1e300), i32::MIN);
        assert_eq!(s.permille(2.5), 250);
        assert_eq!(s.permille(1e9), i16::MAX);
        assert_eq!(s.permille(-1e9), i16::MIN);
        assert_eq!(s.permille(f64::NAN), 0);
        assert_eq!(s.units(s.counts(12.345)), 12.345);
        assert_eq!(s.effort(250), 2.5);
    }

    #[test]
    fn the_packing_follows_the_mapping() {
        let bytes = |m: &[(u16, u8)]| m.iter().map(|&(_, b)| usize::from(b) / 8).sum::<usize>();
        assert_eq!(bytes(&RX_DEFAULT), PDO_BYTES);
        assert_eq!(bytes(&TX_DEFAULT), PDO_BYTES);
        let rx = RxPdo {
            controlword: 0x000F,
            mode: 8,
            target_position: -2,
            target_velocity: 0x0102_0304,
            target_torque: -300,
            velocity_offset: 7,
            torque_offset: 9,
        };
        let mut out = [0u8; PDO_BYTES];
        rx.write(&mut out);
        assert_eq!(&out[..3], &[0x0F, 0, 8]);
        assert_eq!(&out[3..7], &(-2i32).to_le_bytes());
        assert_eq!(&out[11..13], &(-300i16).to_le_bytes());
        let mut i = [0u8; PDO_BYTES];
        i[0..2].copy_from_slice(&0x0237u16.to_le_bytes());
        i[2] = 8;
        i[3..5].copy_from_slice(&0xFF01u16.to_le_bytes());
        i[5..9].copy_from_slice(&40_000i32.to_le_bytes());
        i[13..15].copy_from_slice(&(-5i16).to_le_bytes());
        let tx = TxPdo::read(&i).expect("19 bytes");
        assert_eq!(
            (
                tx.statusword,
                tx.mode_display,
                tx.error_code,
                tx.position,
                tx.torque
            ),
            (0x0237, 8, 0xFF01, 40_000, -5)
        );
        assert_eq!(TxPdo::read(&i[..18]), None);
    }
}
