//! An EtherCAT SubDevice emulator: the SubDevices of a bus as a MainDevice sees them on the
//! wire, so the cell's EtherCAT process (and masters we did not write) can be tested without
//! hardware.
//!
//! - [`frame`]: EtherCAT frames and datagrams, walked in place (never panics on any bytes);
//! - [`esc`]: one SubDevice controller: registers, AL state machine, SII interface, FMMUs,
//!   SyncManagers and their process data watchdog, Distributed Clocks (a clock with a quartz'
//!   drift, the drift control, SYNC0);
//! - [`coe`]: CANopen over EtherCAT: the object dictionary, SDO upload and download, aborts;
//! - [`sii`]: the EEPROM image (identity, strings, general, FMMU, SyncManager and PDO
//!   categories, its checksum);
//! - [`drive`]: a CiA 402 servo drive (its objects, the PDO mapping written in PRE-OP, SYNC0 or
//!   SM-synchronous) moving `machine-sim`'s drive and mechanics model;
//! - [`terminals`]: EK1100, EL1008, EL2008, and the drive;
//! - [`bus`]: a line of SubDevices a frame passes through;
//! - [`wire`]: the line on a network interface (a raw packet socket), for the
//!   `ethercat-emulator` binary.
//!
//! What it does not do yet is in docs/ethercat.md ("Not yet").

pub mod bus;
pub mod cell;
pub mod coe;
pub mod drive;
pub mod esc;
pub mod frame;
pub mod sii;
pub mod terminals;
pub use ethercat_wire as wire;

/// Nanoseconds on the emulator's clock (`CLOCK_MONOTONIC`), for the DC registers.
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec it is given.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}
