//! Controlword commands and their decoding.

use crate::cw;

/// A device-control command of the controlword 0x6040 (the fault reset is not one: it is the
/// 0→1 edge of bit 7, which [`crate::Device::step`] tracks itself).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// Shutdown, mask 0x0087 value 0x0006: transitions 2, 6, 8.
    Shutdown,
    /// Switch on, mask 0x008F value 0x0007: transition 3 (in Ready to switch on), and 5 (in
    /// Operation enabled, where the same word means Disable operation).
    SwitchOn,
    /// Disable voltage, mask 0x0082 value 0x0000: transitions 7, 9, 10, 12.
    DisableVoltage,
    /// Quick stop, mask 0x0086 value 0x0002: transitions 7, 10, 11.
    QuickStop,
    /// Disable operation: the same word as [`Command::SwitchOn`] (0x0007). [`decode`] never
    /// returns it (it returns `SwitchOn`, which the device interprets per state); it exists so
    /// a master can name its intent.
    DisableOperation,
    /// Enable operation, mask 0x008F value 0x000F: transitions 4, 16; 3 in Ready to switch on.
    EnableOperation,
}

impl Command {
    /// The canonical controlword of this command (the [`cw`] command constants).
    pub const fn word(self) -> u16 {
        match self {
            Command::Shutdown => cw::SHUTDOWN,
            Command::SwitchOn => cw::SWITCH_ON_CMD,
            Command::DisableVoltage => cw::DISABLE_VOLTAGE,
            Command::QuickStop => cw::QUICK_STOP_CMD,
            Command::DisableOperation => cw::DISABLE_OPERATION,
            Command::EnableOperation => cw::ENABLE_OPERATION_CMD,
        }
    }

    /// The command's name as the profile spells it.
    pub const fn name(self) -> &'static str {
        match self {
            Command::Shutdown => "Shutdown",
            Command::SwitchOn => "Switch on",
            Command::DisableVoltage => "Disable voltage",
            Command::QuickStop => "Quick stop",
            Command::DisableOperation => "Disable operation",
            Command::EnableOperation => "Enable operation",
        }
    }
}

/// Decodes a controlword into its command, `None` while bit 7 (fault reset) is high: every
/// command mask includes bit 7 = 0.
///
/// With bit 7 low the five masks of the profile partition the words, so no precedence is
/// needed and the decision reads bit by bit:
///
/// | bit 1 | bit 2 | bit 0 | bit 3 | command (mask, value) |
/// |---|---|---|---|---|
/// | 0 | – | – | – | Disable voltage (0x0082, 0x0000) |
/// | 1 | 0 | – | – | Quick stop (0x0086, 0x0002) |
/// | 1 | 1 | 0 | – | Shutdown (0x0087, 0x0006) |
/// | 1 | 1 | 1 | 0 | Switch on / Disable operation (0x008F, 0x0007) |
/// | 1 | 1 | 1 | 1 | Enable operation (0x008F, 0x000F) |
///
/// So 0x0000 and 0x0004 are Disable voltage, 0x0002 and 0x0003 Quick stop, 0x0006 and 0x000E
/// Shutdown. Bits 4-6 and 8-15 (mode-specific, halt, manufacturer) never change the command.
///
/// # Real-time
/// Constant time, no allocation, no system call: called in every cycle.
pub const fn decode(controlword: u16) -> Option<Command> {
    if set(controlword, cw::FAULT_RESET) {
        None
    } else if !set(controlword, cw::ENABLE_VOLTAGE) {
        Some(Command::DisableVoltage)
    } else if !set(controlword, cw::QUICK_STOP) {
        Some(Command::QuickStop)
    } else if !set(controlword, cw::SWITCH_ON) {
        Some(Command::Shutdown)
    } else if !set(controlword, cw::ENABLE_OPERATION) {
        Some(Command::SwitchOn)
    } else {
        Some(Command::EnableOperation)
    }
}

/// `bit` is set in `word`.
const fn set(word: u16, bit: u16) -> bool {
    word & bit != 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn canonical_words_decode_to_their_command() {
        for c in [
            Command::Shutdown,
            Command::SwitchOn,
            Command::DisableVoltage,
            Command::QuickStop,
            Command::EnableOperation,
        ] {
            assert_eq!(decode(c.word()), Some(c), "{}", c.name());
        }
        assert_eq!(
            decode(Command::DisableOperation.word()),
            Some(Command::SwitchOn)
        );
    }

    #[test]
    fn the_words_named_in_the_brief() {
        assert_eq!(decode(0x0000), Some(Command::DisableVoltage));
        assert_eq!(decode(0x0004), Some(Command::DisableVoltage));
        assert_eq!(decode(0x0002), Some(Command::QuickStop));
        assert_eq!(decode(0x0003), Some(Command::QuickStop));
        assert_eq!(decode(0x0006), Some(Command::Shutdown));
        assert_eq!(decode(0x0007), Some(Command::SwitchOn));
        assert_eq!(decode(0x000F), Some(Command::EnableOperation));
        assert_eq!(
            decode(0x010F),
            Some(Command::EnableOperation),
            "halt is not a command"
        );
        assert_eq!(decode(0x0080), None);
        assert_eq!(decode(0x008F), None);
    }
}
