//! Modes of operation (0x6060 / 0x6061) and the quick stop option code (0x605A).

/// The modes of operation this crate's drives support, object 0x6502 (bit `mode - 1` per
/// mode): CSP 0x80, CSV 0x100, CST 0x200.
pub const SUPPORTED_MODES: u32 = Mode::SUPPORTED_MODES;

/// Mode of operation, 0x6060 (request) and 0x6061 (display), `i8`: the cyclic synchronous
/// modes this workspace uses, and "no mode".
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(i8)]
pub enum Mode {
    /// 0: no mode selected.
    NoMode = 0,
    /// 8: cyclic synchronous position; target 0x607A, feed-forwards 0x60B1 / 0x60B2.
    Csp = 8,
    /// 9: cyclic synchronous velocity; target 0x60FF, torque feed-forward 0x60B2.
    Csv = 9,
    /// 10: cyclic synchronous torque; target 0x6071 (‰ of rated torque), offset 0x60B2.
    Cst = 10,
}

impl Mode {
    /// Supported drive modes bitmap, object 0x6502: bit `mode - 1` for CSP, CSV and CST.
    pub const SUPPORTED_MODES: u32 = 0x80 | 0x100 | 0x200;

    /// The mode with this 0x6060 / 0x6061 value; `None` for a mode not supported here
    /// (profile modes 1-7, manufacturer modes < 0, reserved values).
    pub const fn from_i8(v: i8) -> Option<Mode> {
        match v {
            0 => Some(Mode::NoMode),
            8 => Some(Mode::Csp),
            9 => Some(Mode::Csv),
            10 => Some(Mode::Cst),
            _ => None,
        }
    }

    /// Short name: "none", "CSP", "CSV", "CST".
    pub const fn name(self) -> &'static str {
        match self {
            Mode::NoMode => "none",
            Mode::Csp => "CSP",
            Mode::Csv => "CSV",
            Mode::Cst => "CST",
        }
    }
}

/// Quick stop option code, 0x605A (`i16`): how transition 11 stops the motor and where the
/// drive goes afterwards. The subset this workspace supports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(i16)]
pub enum QuickStopOption {
    /// 0: disable the drive at once, the motor coasts; the drive returns to Switch on disabled
    /// on the next cycle (transition 12) without waiting for the motor to stop.
    Coast = 0,
    /// 1: slow-down ramp, then Switch on disabled (transition 12 when at rest).
    SlowDownRamp = 1,
    /// 2: quick-stop ramp (0x6085), then Switch on disabled (transition 12 when at rest).
    /// Beckhoff's default.
    QuickStopRamp = 2,
    /// 6: quick-stop ramp, then stay in Quick stop active; Enable operation resumes
    /// (transition 16), Disable voltage leaves (transition 12).
    StayAfterRamp = 6,
}

impl QuickStopOption {
    /// The option with this 0x605A value; `None` for values not supported here (3-5, 7, 8,
    /// manufacturer values < 0).
    pub const fn from_i16(v: i16) -> Option<QuickStopOption> {
        match v {
            0 => Some(QuickStopOption::Coast),
            1 => Some(QuickStopOption::SlowDownRamp),
            2 => Some(QuickStopOption::QuickStopRamp),
            6 => Some(QuickStopOption::StayAfterRamp),
            _ => None,
        }
    }

    /// The drive leaves Quick stop active by itself, to Switch on disabled (transition 12),
    /// once the stop ends: 0x605A values 0-4 (0 at once, 1-4 when the motor is at rest).
    /// Values 5-8 stay in Quick stop active.
    pub const fn returns_to_switch_on_disabled(self) -> bool {
        match self {
            QuickStopOption::Coast
            | QuickStopOption::SlowDownRamp
            | QuickStopOption::QuickStopRamp => true,
            QuickStopOption::StayAfterRamp => false,
        }
    }

    /// The quick stop has ended this cycle: at once for [`QuickStopOption::Coast`] (the power
    /// stage is off, nothing is left to wait for), when the motor is at rest otherwise.
    pub(crate) const fn stop_ended(self, at_rest: bool) -> bool {
        matches!(self, QuickStopOption::Coast) || at_rest
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn modes_round_trip_and_fill_the_bitmap() {
        let mut bitmap = 0;
        for m in [Mode::NoMode, Mode::Csp, Mode::Csv, Mode::Cst] {
            assert_eq!(Mode::from_i8(m as i8), Some(m), "{}", m.name());
            if m != Mode::NoMode {
                bitmap |= 1u32 << (m as i8 - 1);
            }
        }
        assert_eq!(bitmap, SUPPORTED_MODES);
        assert_eq!(SUPPORTED_MODES, 0x0380);
        assert_eq!(Mode::Csp.name(), "CSP");
        assert_eq!(Mode::NoMode.name(), "none");
        for v in [-1, 1, 2, 3, 4, 5, 6, 7, 11, i8::MIN, i8::MAX] {
            assert_eq!(Mode::from_i8(v), None, "{v}");
        }
    }

    #[test]
    fn quick_stop_options_round_trip() {
        for o in [
            QuickStopOption::Coast,
            QuickStopOption::SlowDownRamp,
            QuickStopOption::QuickStopRamp,
            QuickStopOption::StayAfterRamp,
        ] {
            assert_eq!(QuickStopOption::from_i16(o as i16), Some(o));
            assert_eq!(o.returns_to_switch_on_disabled(), (o as i16) <= 4);
        }
        for v in [-1, 3, 4, 5, 7, 8, 9] {
            assert_eq!(QuickStopOption::from_i16(v), None, "{v}");
        }
    }
}
