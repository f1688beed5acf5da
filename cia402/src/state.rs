//! The eight states of the device state machine and their statusword encoding.

/// Statusword mask of the states whose bit 5 (quick stop) is "don't care".
const MASK_WITHOUT_QUICK_STOP: u16 = 0x004F;
/// Statusword mask of the states that include bit 5 (quick stop).
const MASK_WITH_QUICK_STOP: u16 = 0x006F;

/// A state of the CiA 402 device state machine, as the statusword 0x6041 reports it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    /// Booting or self-test; no power stage. Left automatically (transition 1).
    NotReadyToSwitchOn,
    /// Idle, power stage off; only Shutdown is accepted.
    SwitchOnDisabled,
    /// Waiting for Switch on; power stage off.
    ReadyToSwitchOn,
    /// High voltage applied, no torque, set-points ignored.
    SwitchedOn,
    /// Closed loop: the drive follows its set-points.
    OperationEnabled,
    /// Stopping (or stopped) as the quick stop option code 0x605A says.
    QuickStopActive,
    /// Stopping as the fault reaction option code 0x605E says, after a fault.
    FaultReactionActive,
    /// Power stage off, waiting for a fault reset.
    Fault,
}

impl State {
    /// Every state, in the order of the profile's table.
    pub const ALL: [State; 8] = [
        State::NotReadyToSwitchOn,
        State::SwitchOnDisabled,
        State::ReadyToSwitchOn,
        State::SwitchedOn,
        State::OperationEnabled,
        State::QuickStopActive,
        State::FaultReactionActive,
        State::Fault,
    ];

    /// The statusword a device emits in this state: exactly the profile's table values, bit 5
    /// clear in the four states that ignore it, no other bit set. A device ORs in the bits it
    /// reports besides the state ([`crate::sw::VOLTAGE_ENABLED`], [`crate::sw::WARNING`],
    /// [`crate::sw::FOLLOWING_ERROR`], ...).
    pub const fn statusword(self) -> u16 {
        match self {
            State::NotReadyToSwitchOn => 0x0000,
            State::SwitchOnDisabled => 0x0040,
            State::ReadyToSwitchOn => 0x0021,
            State::SwitchedOn => 0x0023,
            State::OperationEnabled => 0x0027,
            State::QuickStopActive => 0x0007,
            State::FaultReactionActive => 0x000F,
            State::Fault => 0x0008,
        }
    }

    /// The statusword bits that identify this state: 0x004F where bit 5 is "don't care",
    /// 0x006F where it tells Operation enabled from Quick stop active.
    const fn mask(self) -> u16 {
        match self {
            State::NotReadyToSwitchOn
            | State::SwitchOnDisabled
            | State::FaultReactionActive
            | State::Fault => MASK_WITHOUT_QUICK_STOP,
            State::ReadyToSwitchOn
            | State::SwitchedOn
            | State::OperationEnabled
            | State::QuickStopActive => MASK_WITH_QUICK_STOP,
        }
    }

    /// Decodes a statusword with the profile's masks: bits outside a state's mask (voltage
    /// enabled, warning, remote, target reached, mode-specific and vendor bits, and bit 5 in the
    /// 0x004F states) are ignored. `None` for a word that matches no state (the masks are
    /// disjoint, so at most one matches).
    ///
    /// # Real-time
    /// Constant time, no allocation, no system call: called in every cycle.
    pub fn from_statusword(sw: u16) -> Option<State> {
        State::ALL
            .into_iter()
            .find(|s| sw & s.mask() == s.statusword())
    }

    /// The state's name as the profile spells it.
    pub const fn name(self) -> &'static str {
        match self {
            State::NotReadyToSwitchOn => "Not ready to switch on",
            State::SwitchOnDisabled => "Switch on disabled",
            State::ReadyToSwitchOn => "Ready to switch on",
            State::SwitchedOn => "Switched on",
            State::OperationEnabled => "Operation enabled",
            State::QuickStopActive => "Quick stop active",
            State::FaultReactionActive => "Fault reaction active",
            State::Fault => "Fault",
        }
    }

    /// High voltage is applied to the power stage: Switched on, Operation enabled, Quick stop
    /// active, Fault reaction active.
    pub const fn power_stage_on(self) -> bool {
        matches!(
            self,
            State::SwitchedOn
                | State::OperationEnabled
                | State::QuickStopActive
                | State::FaultReactionActive
        )
    }

    /// The drive produces torque (runs its control loop, a set-point or a stop ramp):
    /// Operation enabled, Quick stop active, Fault reaction active.
    pub const fn drives_motor(self) -> bool {
        matches!(
            self,
            State::OperationEnabled | State::QuickStopActive | State::FaultReactionActive
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_distinct_and_match_the_profile() {
        assert_eq!(State::NotReadyToSwitchOn.name(), "Not ready to switch on");
        assert_eq!(State::QuickStopActive.name(), "Quick stop active");
        for (i, a) in State::ALL.iter().enumerate() {
            for b in &State::ALL[i + 1..] {
                assert_ne!(a.name(), b.name());
                assert_ne!(a.statusword(), b.statusword());
            }
        }
    }

    #[test]
    fn every_state_word_lies_inside_its_own_mask() {
        for s in State::ALL {
            assert_eq!(s.statusword() & !s.mask(), 0, "{}", s.name());
        }
    }

    #[test]
    fn power_and_torque_flags() {
        let powered: Vec<State> = State::ALL
            .into_iter()
            .filter(|s| s.power_stage_on())
            .collect();
        assert_eq!(
            powered,
            [
                State::SwitchedOn,
                State::OperationEnabled,
                State::QuickStopActive,
                State::FaultReactionActive
            ]
        );
        let torque: Vec<State> = State::ALL
            .into_iter()
            .filter(|s| s.drives_motor())
            .collect();
        assert_eq!(
            torque,
            [
                State::OperationEnabled,
                State::QuickStopActive,
                State::FaultReactionActive
            ]
        );
        // Torque needs the power stage.
        for s in State::ALL {
            assert!(!s.drives_motor() || s.power_stage_on(), "{}", s.name());
        }
    }
}
