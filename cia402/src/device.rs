//! The device (drive) side of the state machine: one [`Device::step`] per drive cycle.

use crate::{Command, QuickStopOption, State, cw, decode, error_code};

/// A transition the device took, with the profile's number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Transition {
    /// The profile's transition number, 1-16 (0, power-on, is [`Device::new`]).
    pub number: u8,
    /// State before the transition.
    pub from: State,
    /// State after the transition.
    pub to: State,
}

/// What the device's hardware reports this cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Conditions {
    /// 0 for none, else the error code ([`error_code`]) of a fault condition present now.
    pub fault: u16,
    /// The motor has stopped: ends a quick stop (transition 12) or a fault reaction (14).
    pub at_rest: bool,
}

/// The CiA 402 device state machine of one drive: state, fault reset edge detection, error
/// code 0x603F and quick stop option 0x605A. Copy, fixed size, constant-time [`Device::step`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Device {
    /// Current state.
    state: State,
    /// Controlword bit 7 as of the previous step (for its 0→1 edge).
    reset_bit: bool,
    /// 0x603F: code of the latest fault, until a successful fault reset.
    error_code: u16,
    /// 0x605A: how a quick stop ends.
    quick_stop: QuickStopOption,
}

impl Device {
    /// A device just powered on (transition 0): Not ready to switch on, no error, controlword
    /// bit 7 taken as low.
    pub const fn new(quick_stop: QuickStopOption) -> Self {
        Device {
            state: State::NotReadyToSwitchOn,
            reset_bit: false,
            error_code: error_code::NONE,
            quick_stop,
        }
    }

    /// Current state.
    pub fn state(&self) -> State {
        self.state
    }

    /// Error code 0x603F: the code of the fault that caused the latest transition 13, kept
    /// until a successful fault reset (transition 15); 0 for none.
    pub fn error_code(&self) -> u16 {
        self.error_code
    }

    /// The quick stop option code 0x605A the device was built with.
    pub fn quick_stop_option(&self) -> QuickStopOption {
        self.quick_stop
    }

    /// Statusword 0x6041: exactly [`State::statusword`]. Callers OR in the bits they report
    /// besides the state ([`crate::sw::VOLTAGE_ENABLED`], [`crate::sw::WARNING`],
    /// [`crate::sw::FOLLOWING_ERROR`], ...).
    pub fn statusword(&self) -> u16 {
        self.state.statusword()
    }

    /// One device cycle: applies the controlword the master wrote and the hardware
    /// conditions, returns the transition taken, if any (at most one per cycle).
    ///
    /// In priority order:
    /// 1. Not ready to switch on leaves by itself: to Switch on disabled (1), or to Fault
    ///    reaction active (13) if a fault is present.
    /// 2. A fault condition in any state but Fault reaction active and Fault: transition 13,
    ///    the error code becomes `c.fault`.
    /// 3. Fault reaction active → Fault (14) when `c.at_rest`.
    /// 4. Fault → Switch on disabled (15) on a 0→1 edge of controlword bit 7, only with no
    ///    fault condition left; the error code is cleared. The edge is tracked on every step
    ///    in every state, so holding bit 7 never resets twice, bit 7 held while entering
    ///    Fault is no edge, and an edge refused because the fault persists is consumed.
    /// 5. Otherwise the decoded command ([`decode`]: none while bit 7 is high), per state:
    ///    see [`crate`]'s transition table. A word that is not a listed command for the
    ///    current state is ignored; in Quick stop active the stop also ends by itself
    ///    (12) when the option returns to Switch on disabled.
    ///
    /// # Real-time
    /// Constant time, no allocation, no system call: called in every cycle.
    pub fn step(&mut self, controlword: u16, c: Conditions) -> Option<Transition> {
        let reset_edge = self.track_reset_bit(controlword);
        let (number, to) = self.next(controlword, reset_edge, c)?;
        let t = Transition {
            number,
            from: self.state,
            to,
        };
        self.state = to;
        match number {
            13 => self.error_code = c.fault,
            15 => self.error_code = error_code::NONE,
            _ => {}
        }
        Some(t)
    }

    /// Records controlword bit 7 and tells whether it rose (0→1) since the previous step.
    fn track_reset_bit(&mut self, controlword: u16) -> bool {
        let high = controlword & cw::FAULT_RESET != 0;
        let edge = high && !self.reset_bit;
        self.reset_bit = high;
        edge
    }

    /// The transition (number, target) this step takes, in the priority order of
    /// [`Device::step`].
    fn next(&self, controlword: u16, reset_edge: bool, c: Conditions) -> Option<(u8, State)> {
        let faulted = c.fault != error_code::NONE;
        match self.state {
            // 13: self-test found a fault; 1: self-test done, communication up.
            State::NotReadyToSwitchOn if faulted => Some((13, State::FaultReactionActive)),
            State::NotReadyToSwitchOn => Some((1, State::SwitchOnDisabled)),
            // 14: the fault reaction has stopped the motor.
            State::FaultReactionActive => c.at_rest.then_some((14, State::Fault)),
            // 15: fault reset edge, refused while the condition persists.
            State::Fault => (reset_edge && !faulted).then_some((15, State::SwitchOnDisabled)),
            // 13: a fault in any other state.
            _ if faulted => Some((13, State::FaultReactionActive)),
            State::QuickStopActive => self.quick_stop_next(decode(controlword), c.at_rest),
            s => commanded(s, decode(controlword)?),
        }
    }

    /// Quick stop active: Disable voltage (12), Enable operation (16, only if the option stays
    /// in Quick stop active), or the stop ending by itself (12, if the option returns to
    /// Switch on disabled).
    fn quick_stop_next(&self, command: Option<Command>, at_rest: bool) -> Option<(u8, State)> {
        let returns = self.quick_stop.returns_to_switch_on_disabled();
        match command {
            Some(Command::DisableVoltage) => Some((12, State::SwitchOnDisabled)),
            Some(Command::EnableOperation) if !returns => Some((16, State::OperationEnabled)),
            _ if returns && self.quick_stop.stop_ended(at_rest) => {
                Some((12, State::SwitchOnDisabled))
            }
            _ => None,
        }
    }
}

/// The commanded transitions out of the states that leave only on a command (Switch on
/// disabled, Ready to switch on, Switched on, Operation enabled); `None` for a command the
/// state does not list (ignored).
const fn commanded(state: State, command: Command) -> Option<(u8, State)> {
    use Command::*;
    use State::*;
    match (state, command) {
        (SwitchOnDisabled, Shutdown) => Some((2, ReadyToSwitchOn)),
        // 3; Enable operation takes 3 now and 4 on a later cycle if still commanded.
        (ReadyToSwitchOn, SwitchOn | DisableOperation | EnableOperation) => Some((3, SwitchedOn)),
        (ReadyToSwitchOn, DisableVoltage | QuickStop) => Some((7, SwitchOnDisabled)),
        (SwitchedOn, EnableOperation) => Some((4, OperationEnabled)),
        (SwitchedOn, Shutdown) => Some((6, ReadyToSwitchOn)),
        (SwitchedOn, DisableVoltage | QuickStop) => Some((10, SwitchOnDisabled)),
        (OperationEnabled, SwitchOn | DisableOperation) => Some((5, SwitchedOn)),
        (OperationEnabled, Shutdown) => Some((8, ReadyToSwitchOn)),
        (OperationEnabled, DisableVoltage) => Some((9, SwitchOnDisabled)),
        (OperationEnabled, QuickStop) => Some((11, QuickStopActive)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_device_is_not_ready_without_error() {
        let d = Device::new(QuickStopOption::QuickStopRamp);
        assert_eq!(d.state(), State::NotReadyToSwitchOn);
        assert_eq!(d.statusword(), 0x0000);
        assert_eq!(d.error_code(), error_code::NONE);
        assert_eq!(d.quick_stop_option(), QuickStopOption::QuickStopRamp);
    }

    #[test]
    fn fault_reset_held_from_power_on_is_no_edge_after_it_drops() {
        // Bit 7 held high through power-on and a fault: only a fresh edge resets.
        let mut d = Device::new(QuickStopOption::QuickStopRamp);
        let fault = Conditions {
            fault: error_code::PARAMETER,
            at_rest: false,
        };
        assert_eq!(d.step(0x80, fault).map(|t| t.number), Some(13));
        assert_eq!(d.error_code(), error_code::PARAMETER);
        let rest = Conditions {
            fault: 0,
            at_rest: true,
        };
        assert_eq!(d.step(0x80, rest).map(|t| t.number), Some(14));
        assert_eq!(d.step(0x80, Conditions::default()), None);
        assert_eq!(d.step(0x00, Conditions::default()), None);
        assert_eq!(
            d.step(0x80, Conditions::default()).map(|t| t.number),
            Some(15)
        );
        assert_eq!(d.error_code(), error_code::NONE);
    }
}
