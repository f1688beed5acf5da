//! The CiA 402 (IEC 61800-7-201) drive profile: the device state machine and the master side.
//!
//! The device side, [`Device`], is shared by the simulated drive (`machine-sim`) and a future
//! real-drive bridge (EtherCAT through ethercrab); the master-side helpers ([`enable_step`],
//! [`disable_step`], [`FaultReset`]) are what servo (and such a bridge) uses to drive a drive
//! through the states. No allocation, no I/O, constant time: every function runs inside a
//! real-time cycle.
//!
//! Reference: `notes/cia402.md` (cross-checked public sources). Objects, all little-endian on
//! the wire:
//!
//! | Object | Name | Here |
//! |---|---|---|
//! | 0x6040 | controlword, `u16` | [`cw`], [`decode`], [`Command`] |
//! | 0x6041 | statusword, `u16` | [`sw`], [`State::statusword`], [`State::from_statusword`] |
//! | 0x603F | error code, `u16` | [`error_code`], [`Device::error_code`] |
//! | 0x605A | quick stop option code, `i16` | [`QuickStopOption`] |
//! | 0x6060 / 0x6061 | modes of operation (display), `i8` | [`Mode`] |
//! | 0x6502 | supported drive modes, `u32` | [`SUPPORTED_MODES`] |
//!
//! Transitions carry the profile's numbers, in [`Transition::number`] and in the comments of
//! the code that takes them (SOD = Switch on disabled, RTSO = Ready to switch on, SO = Switched
//! on, OE = Operation enabled, QSA = Quick stop active, FRA = Fault reaction active):
//!
//! | # | From → to | Trigger |
//! |---|---|---|
//! | 0 | power-on → Not ready to switch on | [`Device::new`] |
//! | 1 | Not ready to switch on → SOD | automatic, on the first [`Device::step`] |
//! | 2 | SOD → RTSO | Shutdown |
//! | 3 | RTSO → SO | Switch on (or Enable operation: 3 now, 4 on a later cycle) |
//! | 4 | SO → OE | Enable operation |
//! | 5 | OE → SO | Disable operation (the Switch on word, 0x07) |
//! | 6 | SO → RTSO | Shutdown |
//! | 7 | RTSO → SOD | Disable voltage or Quick stop |
//! | 8 | OE → RTSO | Shutdown |
//! | 9 | OE → SOD | Disable voltage |
//! | 10 | SO → SOD | Disable voltage or Quick stop |
//! | 11 | OE → QSA | Quick stop |
//! | 12 | QSA → SOD | Disable voltage, or automatic when the stop ends and 0x605A is 0-4 |
//! | 13 | any but FRA and Fault → FRA | automatic, a fault condition is present |
//! | 14 | FRA → Fault | automatic, the fault reaction ended (motor at rest) |
//! | 15 | Fault → SOD | 0→1 edge of controlword bit 7, only with no fault condition left |
//! | 16 | QSA → OE | Enable operation, only if 0x605A is 5-8 |
//!
//! Every command mask includes bit 7 = 0: while bit 7 is high no command matches. A
//! controlword that is not a listed command for the current state is ignored.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]

mod command;
mod device;
pub mod error_code;
mod master;
mod mode;
pub mod pdo;
mod state;

pub use command::{Command, decode};
pub use device::{Conditions, Device, Transition};
pub use master::{FaultReset, disable_step, enable_step};
pub use mode::{Mode, QuickStopOption, SUPPORTED_MODES};
pub use state::State;

/// Statusword 0x6041 bits (`u16`).
///
/// The state bits (0, 1, 2, 3, 5, 6) are decoded together with masks, see
/// [`State::from_statusword`]; never compare a whole statusword with `==`.
pub mod sw {
    /// Bit 0: ready to switch on.
    pub const READY_TO_SWITCH_ON: u16 = 1 << 0;
    /// Bit 1: switched on.
    pub const SWITCHED_ON: u16 = 1 << 1;
    /// Bit 2: operation enabled.
    pub const OPERATION_ENABLED: u16 = 1 << 2;
    /// Bit 3: fault.
    pub const FAULT: u16 = 1 << 3;
    /// Bit 4: voltage enabled (high, DC-link, voltage is applied).
    pub const VOLTAGE_ENABLED: u16 = 1 << 4;
    /// Bit 5: quick stop, **active low**: 1 = no quick stop running.
    pub const QUICK_STOP: u16 = 1 << 5;
    /// Bit 6: switch on disabled.
    pub const SWITCH_ON_DISABLED: u16 = 1 << 6;
    /// Bit 7: warning present (the state is unchanged).
    pub const WARNING: u16 = 1 << 7;
    /// Bit 9: remote, the controlword is being processed.
    pub const REMOTE: u16 = 1 << 9;
    /// Bit 10: target reached (profile modes); optional status toggle in the cyclic modes.
    pub const TARGET_REACHED: u16 = 1 << 10;
    /// Bit 11: internal limit active (a limit is clamping the command).
    pub const INTERNAL_LIMIT: u16 = 1 << 11;
    /// Bit 12 in CSP/CSV/CST: the drive follows the command value.
    pub const FOLLOWS_COMMAND: u16 = 1 << 12;
    /// Bit 13 in CSP: following error.
    pub const FOLLOWING_ERROR: u16 = 1 << 13;
}

/// Controlword 0x6040 bits and the command words (`u16`).
///
/// The command words are the canonical values of the profile's commands; a device decodes a
/// controlword with masks ([`decode`]), so other bits (halt, mode-specific) may be ORed in.
pub mod cw {
    /// Bit 0: switch on.
    pub const SWITCH_ON: u16 = 1 << 0;
    /// Bit 1: enable voltage.
    pub const ENABLE_VOLTAGE: u16 = 1 << 1;
    /// Bit 2: quick stop, **active low**: 0 = quick stop.
    pub const QUICK_STOP: u16 = 1 << 2;
    /// Bit 3: enable operation.
    pub const ENABLE_OPERATION: u16 = 1 << 3;
    /// Bit 7: fault reset, acts on its 0→1 edge only (transition 15).
    pub const FAULT_RESET: u16 = 1 << 7;
    /// Bit 8: halt.
    pub const HALT: u16 = 1 << 8;

    /// Shutdown: transitions 2, 6, 8.
    pub const SHUTDOWN: u16 = 0x0006;
    /// Switch on: transition 3 (in Ready to switch on).
    pub const SWITCH_ON_CMD: u16 = 0x0007;
    /// Disable operation: transition 5 (in Operation enabled). Same word as [`SWITCH_ON_CMD`].
    pub const DISABLE_OPERATION: u16 = 0x0007;
    /// Enable operation: transitions 4 and 16; 3 then 4 from Ready to switch on.
    pub const ENABLE_OPERATION_CMD: u16 = 0x000F;
    /// Disable voltage: transitions 7, 9, 10, 12.
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Quick stop: transitions 7, 10, 11.
    pub const QUICK_STOP_CMD: u16 = 0x0002;
    /// Fault reset: transition 15 on the 0→1 edge of bit 7 (send 0x0000 for a cycle first).
    pub const FAULT_RESET_CMD: u16 = 0x0080;
}
