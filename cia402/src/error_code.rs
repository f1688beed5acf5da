//! Error code 0x603F (`u16`): the code of the most recent fault, 0 for none.

/// No error.
pub const NONE: u16 = 0x0000;
/// Continuous over-current.
pub const OVER_CURRENT: u16 = 0x2310;
/// Parameter error (a configuration value the drive refuses).
pub const PARAMETER: u16 = 0x6320;
/// Position sensor error: encoder signal lost.
pub const POSITION_SENSOR: u16 = 0x7320;
/// Following error: outside the window 0x6065 for longer than the time-out 0x6066.
pub const FOLLOWING_ERROR: u16 = 0x8611;
/// Manufacturer-specific (0xFF00-0xFFFF range): no new command from the master within the
/// command watchdog.
pub const COMMAND_TIMEOUT: u16 = 0xFF01;

/// First code of the manufacturer-specific range.
const MANUFACTURER_FIRST: u16 = 0xFF00;

/// A short description of an error code, for logs and the operator.
pub const fn name(code: u16) -> &'static str {
    match code {
        NONE => "none",
        OVER_CURRENT => "over-current",
        PARAMETER => "parameter error",
        POSITION_SENSOR => "position sensor (encoder) error",
        FOLLOWING_ERROR => "following error",
        COMMAND_TIMEOUT => "command watchdog expired",
        MANUFACTURER_FIRST.. => "manufacturer-specific",
        _ => "unknown",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        assert_eq!(name(NONE), "none");
        assert_eq!(name(OVER_CURRENT), "over-current");
        assert_eq!(name(PARAMETER), "parameter error");
        assert_eq!(name(POSITION_SENSOR), "position sensor (encoder) error");
        assert_eq!(name(FOLLOWING_ERROR), "following error");
        assert_eq!(name(COMMAND_TIMEOUT), "command watchdog expired");
        assert_eq!(name(0xFF00), "manufacturer-specific");
        assert_eq!(name(0xFFFF), "manufacturer-specific");
        assert_eq!(name(0x3210), "unknown");
    }
}
