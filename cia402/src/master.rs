//! Master-side helpers: which controlword to write next, given the state a drive reports.

use crate::{State, cw};

/// The controlword that moves a drive one step towards Operation enabled from `s`, as robust
/// masters do (0x06 → 0x07 → 0x0F, never the one-step 0x0F from Ready to switch on):
///
/// | `s` | word | transition |
/// |---|---|---|
/// | Switch on disabled | [`cw::SHUTDOWN`] | 2 |
/// | Ready to switch on | [`cw::SWITCH_ON_CMD`] | 3 |
/// | Switched on | [`cw::ENABLE_OPERATION_CMD`] | 4 |
/// | Operation enabled | [`cw::ENABLE_OPERATION_CMD`] | stay |
/// | Quick stop active | [`cw::DISABLE_VOLTAGE`] | 12, then up from Switch on disabled |
/// | Fault reaction active, Fault, Not ready | [`cw::DISABLE_VOLTAGE`] | none |
///
/// Never a fault reset: a drive never re-enables by itself after a fault; the master resets
/// it deliberately ([`FaultReset`]).
///
/// # Real-time
/// Constant time, no allocation, no system call: called in every cycle.
pub const fn enable_step(s: State) -> u16 {
    match s {
        State::SwitchOnDisabled => cw::SHUTDOWN,
        State::ReadyToSwitchOn => cw::SWITCH_ON_CMD,
        State::SwitchedOn | State::OperationEnabled => cw::ENABLE_OPERATION_CMD,
        State::QuickStopActive
        | State::FaultReactionActive
        | State::Fault
        | State::NotReadyToSwitchOn => cw::DISABLE_VOLTAGE,
    }
}

/// The controlword that takes power off in an orderly way (the drive stops per 0x605B /
/// 0x605C before it switches off):
///
/// | `s` | word | transition |
/// |---|---|---|
/// | Operation enabled | [`cw::SHUTDOWN`] | 8 |
/// | Switched on | [`cw::SHUTDOWN`] | 6 |
/// | Ready to switch on | [`cw::SHUTDOWN`] | stay |
/// | Switch on disabled | [`cw::SHUTDOWN`] | 2 (to Ready to switch on, power stage still off) |
/// | Quick stop active, Fault reaction active, Fault, Not ready | [`cw::DISABLE_VOLTAGE`] | 12 from Quick stop active, else none |
///
/// Repeated, it settles every drive that is not faulted in Ready to switch on, power stage
/// off, one Switch on away from high voltage.
///
/// # Real-time
/// Constant time, no allocation, no system call: called in every cycle.
pub const fn disable_step(s: State) -> u16 {
    match s {
        State::OperationEnabled
        | State::SwitchedOn
        | State::ReadyToSwitchOn
        | State::SwitchOnDisabled => cw::SHUTDOWN,
        State::QuickStopActive
        | State::FaultReactionActive
        | State::Fault
        | State::NotReadyToSwitchOn => cw::DISABLE_VOLTAGE,
    }
}

/// Fault reset as a master must do it: bit 7 low for at least one cycle, then high until the
/// drive leaves Fault (transition 15 acts on the 0→1 edge only).
///
/// A drive refuses the reset while its fault condition persists and consumes the edge; to
/// try again, start a new `FaultReset` (its first word drops bit 7 again).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultReset {
    /// The first word, bit 7 low, has been sent.
    low_sent: bool,
    /// Bit 7 has been sent high (the edge) at least once.
    edge_sent: bool,
}

impl FaultReset {
    /// A fault reset not yet started.
    pub const fn new() -> Self {
        FaultReset {
            low_sent: false,
            edge_sent: false,
        }
    }

    /// The controlword to write this cycle, given the state the drive reports: 0x0000 on the
    /// first call, then [`cw::FAULT_RESET_CMD`] while `s` is Fault, [`cw::DISABLE_VOLTAGE`]
    /// otherwise (also while the fault reaction still runs: the edge comes once in Fault).
    ///
    /// # Real-time
    /// Constant time, no allocation, no system call: called in every cycle.
    pub fn controlword(&mut self, s: State) -> u16 {
        if !self.low_sent {
            self.low_sent = true;
            cw::DISABLE_VOLTAGE
        } else if s == State::Fault {
            self.edge_sent = true;
            cw::FAULT_RESET_CMD
        } else {
            cw::DISABLE_VOLTAGE
        }
    }

    /// The reset worked: an edge was sent and the drive is out of Fault and Fault reaction
    /// active (in Switch on disabled, ready for [`enable_step`]).
    pub fn done(&self, s: State) -> bool {
        self.edge_sent && !matches!(s, State::Fault | State::FaultReactionActive)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_reset_words() {
        let mut r = FaultReset::new();
        assert_eq!(r, FaultReset::default());
        assert_eq!(r.controlword(State::Fault), 0x0000);
        assert!(!r.done(State::Fault));
        assert_eq!(r.controlword(State::Fault), 0x0080);
        assert_eq!(r.controlword(State::Fault), 0x0080);
        assert!(!r.done(State::Fault));
        assert_eq!(r.controlword(State::SwitchOnDisabled), 0x0000);
        assert!(r.done(State::SwitchOnDisabled));
    }

    #[test]
    fn fault_reset_waits_out_the_fault_reaction() {
        let mut r = FaultReset::new();
        assert_eq!(r.controlword(State::FaultReactionActive), 0x0000);
        assert_eq!(r.controlword(State::FaultReactionActive), 0x0000);
        assert!(!r.done(State::FaultReactionActive));
        assert_eq!(r.controlword(State::Fault), 0x0080);
    }

    #[test]
    fn neither_helper_ever_sets_bit_7() {
        for s in State::ALL {
            assert_eq!(enable_step(s) & cw::FAULT_RESET, 0, "{}", s.name());
            assert_eq!(disable_step(s) & cw::FAULT_RESET, 0, "{}", s.name());
        }
    }
}
