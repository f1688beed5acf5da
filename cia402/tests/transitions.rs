//! Every CiA 402 transition, allowed and refused, against `notes/cia402.md`.

use State::*;
use cia402::{
    Command, Conditions, Device, FaultReset, QuickStopOption, State, Transition, cw, decode,
    disable_step, enable_step, error_code, sw,
};

/// No fault, motor moving.
const NONE: Conditions = Conditions {
    fault: 0,
    at_rest: false,
};
/// No fault, motor at rest.
const AT_REST: Conditions = Conditions {
    fault: 0,
    at_rest: true,
};

/// A fault condition with this code, motor moving.
fn fault(code: u16) -> Conditions {
    Conditions {
        fault: code,
        at_rest: false,
    }
}

/// Steps `d` once and returns the transition number taken, if any.
fn step(d: &mut Device, controlword: u16, c: Conditions) -> Option<u8> {
    d.step(controlword, c).map(|t| t.number)
}

/// Steps `d` once with the word a master helper picks for its state, no fault, motor moving.
fn master(d: &mut Device, helper: fn(State) -> u16) -> Option<u8> {
    let word = helper(d.state());
    step(d, word, NONE)
}

/// The states the table starts from, each reached by a legal path from `Device::new`.
#[derive(Clone, Copy, Debug)]
enum Start {
    NotReady,
    Sod,
    Rtso,
    So,
    Oe,
    /// Quick stop active with 0x605A = 2 (returns to Switch on disabled).
    Qsa,
    /// Quick stop active with 0x605A = 6 (stays).
    QsaStay,
    Fra,
    Fault,
}

/// Builds a device in `start` by a legal path; every word on the path has bit 7 low.
fn reach(start: Start) -> Device {
    let option = match start {
        Start::QsaStay => QuickStopOption::StayAfterRamp,
        _ => QuickStopOption::QuickStopRamp,
    };
    let mut d = Device::new(option);
    let path: &[(u16, Conditions, u8)] = match start {
        Start::NotReady => &[],
        Start::Sod => &[(0x00, NONE, 1)],
        Start::Rtso => &[(0x00, NONE, 1), (0x06, NONE, 2)],
        Start::So => &[(0x00, NONE, 1), (0x06, NONE, 2), (0x07, NONE, 3)],
        Start::Oe => &[
            (0x00, NONE, 1),
            (0x06, NONE, 2),
            (0x07, NONE, 3),
            (0x0F, NONE, 4),
        ],
        Start::Qsa | Start::QsaStay => &[
            (0x00, NONE, 1),
            (0x06, NONE, 2),
            (0x07, NONE, 3),
            (0x0F, NONE, 4),
            (0x02, NONE, 11),
        ],
        Start::Fra => &[(0x00, NONE, 1), (0x00, fault(error_code::OVER_CURRENT), 13)],
        Start::Fault => &[
            (0x00, NONE, 1),
            (0x00, fault(error_code::OVER_CURRENT), 13),
            (0x00, AT_REST, 14),
        ],
    };
    for &(word, c, number) in path {
        assert_eq!(step(&mut d, word, c), Some(number), "path to {start:?}");
    }
    d
}

/// The command words of the table. 0x80, 0x86 and 0x8F are all applied right after a word
/// with bit 7 low, so each is a 0→1 edge of bit 7.
const WORDS: [u16; 8] = [0x00, 0x02, 0x06, 0x07, 0x0F, 0x80, 0x86, 0x8F];

/// (start, word) → (state after, transition number), with conditions none (no fault, motor
/// not at rest). `None` = refused or ignored: the state must be unchanged.
#[rustfmt::skip]
const TABLE: &[(Start, u16, State, Option<u8>)] = &[
    // Not ready to switch on: leaves by itself (1) whatever the word.
    (Start::NotReady, 0x00, SwitchOnDisabled, Some(1)),
    (Start::NotReady, 0x02, SwitchOnDisabled, Some(1)),
    (Start::NotReady, 0x06, SwitchOnDisabled, Some(1)),
    (Start::NotReady, 0x07, SwitchOnDisabled, Some(1)),
    (Start::NotReady, 0x0F, SwitchOnDisabled, Some(1)),
    (Start::NotReady, 0x80, SwitchOnDisabled, Some(1)),
    (Start::NotReady, 0x86, SwitchOnDisabled, Some(1)),
    (Start::NotReady, 0x8F, SwitchOnDisabled, Some(1)),
    // Switch on disabled: only Shutdown (2).
    (Start::Sod, 0x00, SwitchOnDisabled, None),
    (Start::Sod, 0x02, SwitchOnDisabled, None),
    (Start::Sod, 0x06, ReadyToSwitchOn, Some(2)),
    (Start::Sod, 0x07, SwitchOnDisabled, None),
    (Start::Sod, 0x0F, SwitchOnDisabled, None),
    (Start::Sod, 0x80, SwitchOnDisabled, None),
    (Start::Sod, 0x86, SwitchOnDisabled, None),
    (Start::Sod, 0x8F, SwitchOnDisabled, None),
    // Ready to switch on: Disable voltage / Quick stop (7), Switch on (3), Enable op. (3).
    (Start::Rtso, 0x00, SwitchOnDisabled, Some(7)),
    (Start::Rtso, 0x02, SwitchOnDisabled, Some(7)),
    (Start::Rtso, 0x06, ReadyToSwitchOn, None),
    (Start::Rtso, 0x07, SwitchedOn, Some(3)),
    (Start::Rtso, 0x0F, SwitchedOn, Some(3)),
    (Start::Rtso, 0x80, ReadyToSwitchOn, None),
    (Start::Rtso, 0x86, ReadyToSwitchOn, None),
    (Start::Rtso, 0x8F, ReadyToSwitchOn, None),
    // Switched on: Disable voltage / Quick stop (10), Shutdown (6), Enable operation (4).
    (Start::So, 0x00, SwitchOnDisabled, Some(10)),
    (Start::So, 0x02, SwitchOnDisabled, Some(10)),
    (Start::So, 0x06, ReadyToSwitchOn, Some(6)),
    (Start::So, 0x07, SwitchedOn, None),
    (Start::So, 0x0F, OperationEnabled, Some(4)),
    (Start::So, 0x80, SwitchedOn, None),
    (Start::So, 0x86, SwitchedOn, None),
    (Start::So, 0x8F, SwitchedOn, None),
    // Operation enabled: Disable voltage (9), Quick stop (11), Shutdown (8),
    // Disable operation (5).
    (Start::Oe, 0x00, SwitchOnDisabled, Some(9)),
    (Start::Oe, 0x02, QuickStopActive, Some(11)),
    (Start::Oe, 0x06, ReadyToSwitchOn, Some(8)),
    (Start::Oe, 0x07, SwitchedOn, Some(5)),
    (Start::Oe, 0x0F, OperationEnabled, None),
    (Start::Oe, 0x80, OperationEnabled, None),
    (Start::Oe, 0x86, OperationEnabled, None),
    (Start::Oe, 0x8F, OperationEnabled, None),
    // Quick stop active, 0x605A = 2, still stopping: only Disable voltage (12).
    (Start::Qsa, 0x00, SwitchOnDisabled, Some(12)),
    (Start::Qsa, 0x02, QuickStopActive, None),
    (Start::Qsa, 0x06, QuickStopActive, None),
    (Start::Qsa, 0x07, QuickStopActive, None),
    (Start::Qsa, 0x0F, QuickStopActive, None),
    (Start::Qsa, 0x80, QuickStopActive, None),
    (Start::Qsa, 0x86, QuickStopActive, None),
    (Start::Qsa, 0x8F, QuickStopActive, None),
    // Quick stop active, 0x605A = 6: Disable voltage (12), Enable operation (16).
    (Start::QsaStay, 0x00, SwitchOnDisabled, Some(12)),
    (Start::QsaStay, 0x02, QuickStopActive, None),
    (Start::QsaStay, 0x06, QuickStopActive, None),
    (Start::QsaStay, 0x07, QuickStopActive, None),
    (Start::QsaStay, 0x0F, OperationEnabled, Some(16)),
    (Start::QsaStay, 0x80, QuickStopActive, None),
    (Start::QsaStay, 0x86, QuickStopActive, None),
    (Start::QsaStay, 0x8F, QuickStopActive, None),
    // Fault reaction active, motor still moving: nothing.
    (Start::Fra, 0x00, FaultReactionActive, None),
    (Start::Fra, 0x02, FaultReactionActive, None),
    (Start::Fra, 0x06, FaultReactionActive, None),
    (Start::Fra, 0x07, FaultReactionActive, None),
    (Start::Fra, 0x0F, FaultReactionActive, None),
    (Start::Fra, 0x80, FaultReactionActive, None),
    (Start::Fra, 0x86, FaultReactionActive, None),
    (Start::Fra, 0x8F, FaultReactionActive, None),
    // Fault, condition gone: any 0→1 edge of bit 7 resets (15), whatever the other bits;
    // no command leaves Fault.
    (Start::Fault, 0x00, Fault, None),
    (Start::Fault, 0x02, Fault, None),
    (Start::Fault, 0x06, Fault, None),
    (Start::Fault, 0x07, Fault, None),
    (Start::Fault, 0x0F, Fault, None),
    (Start::Fault, 0x80, SwitchOnDisabled, Some(15)),
    (Start::Fault, 0x86, SwitchOnDisabled, Some(15)),
    (Start::Fault, 0x8F, SwitchOnDisabled, Some(15)),
];

#[test]
fn every_state_and_command_word() {
    assert_eq!(TABLE.len(), 9 * WORDS.len());
    for (i, &(start, word, after, number)) in TABLE.iter().enumerate() {
        // The table lists the words in the order of WORDS, every start once.
        assert_eq!(word, WORDS[i % WORDS.len()], "row {i}");
        let mut d = reach(start);
        let before = d.state();
        let t = d.step(word, NONE);
        let case = format!("{start:?} + {word:#06x}");
        assert_eq!(t.map(|t| t.number), number, "{case}: transition");
        assert_eq!(d.state(), after, "{case}: state");
        assert_eq!(d.statusword(), after.statusword(), "{case}: statusword");
        match t {
            Some(t) => assert_eq!(
                t,
                Transition {
                    number: t.number,
                    from: before,
                    to: after
                }
            ),
            None => assert_eq!(before, after, "{case}: refused but moved"),
        }
        // The fault code stays until a reset clears it.
        let code = if matches!(start, Start::Fra | Start::Fault) && number.is_none() {
            error_code::OVER_CURRENT
        } else {
            error_code::NONE
        };
        assert_eq!(d.error_code(), code, "{case}: error code");
    }
}

#[test]
fn transition_1_is_automatic_on_the_first_step() {
    let mut d = Device::new(QuickStopOption::QuickStopRamp);
    assert_eq!(d.state(), NotReadyToSwitchOn);
    assert_eq!(
        d.step(0x00, NONE),
        Some(Transition {
            number: 1,
            from: NotReadyToSwitchOn,
            to: SwitchOnDisabled
        })
    );
    assert_eq!(step(&mut d, 0x00, NONE), None);
}

#[test]
fn transition_13_from_every_state_but_the_fault_states() {
    for start in [
        Start::NotReady,
        Start::Sod,
        Start::Rtso,
        Start::So,
        Start::Oe,
        Start::Qsa,
        Start::QsaStay,
    ] {
        // Whatever the master commands, the fault wins.
        for word in WORDS {
            let mut d = reach(start);
            let before = d.state();
            let t = d.step(word, fault(error_code::FOLLOWING_ERROR));
            assert_eq!(
                t,
                Some(Transition {
                    number: 13,
                    from: before,
                    to: FaultReactionActive
                }),
                "{start:?} + {word:#06x}"
            );
            assert_eq!(d.error_code(), error_code::FOLLOWING_ERROR);
            assert_eq!(d.statusword(), 0x000F);
        }
    }
    // No 13 out of Fault reaction active or Fault: the fault code of the first fault stays.
    for start in [Start::Fra, Start::Fault] {
        let mut d = reach(start);
        let before = d.state();
        assert_eq!(
            step(&mut d, 0x00, fault(error_code::POSITION_SENSOR)),
            None,
            "{start:?}"
        );
        assert_eq!(d.state(), before);
        assert_eq!(d.error_code(), error_code::OVER_CURRENT);
    }
}

#[test]
fn transition_14_when_the_fault_reaction_ends() {
    let mut d = reach(Start::Fra);
    // Still stopping, fault still present or not: stay.
    assert_eq!(step(&mut d, 0x00, fault(error_code::OVER_CURRENT)), None);
    assert_eq!(step(&mut d, 0x0F, NONE), None);
    assert_eq!(
        d.step(0x00, AT_REST),
        Some(Transition {
            number: 14,
            from: FaultReactionActive,
            to: Fault
        })
    );
    assert_eq!(d.statusword(), 0x0008);
    assert_eq!(d.error_code(), error_code::OVER_CURRENT);
    // At rest in Fault: nothing more happens by itself.
    assert_eq!(step(&mut d, 0x00, AT_REST), None);
    // At rest with the fault still present also ends the reaction.
    let mut d = reach(Start::Fra);
    let c = Conditions {
        fault: error_code::OVER_CURRENT,
        at_rest: true,
    };
    assert_eq!(step(&mut d, 0x00, c), Some(14));
}

#[test]
fn transition_15_on_an_edge_only() {
    let mut d = reach(Start::Fault);
    // Holding bit 7 resets once; the held bit does nothing more.
    assert_eq!(
        d.step(0x80, NONE),
        Some(Transition {
            number: 15,
            from: Fault,
            to: SwitchOnDisabled
        })
    );
    assert_eq!(d.error_code(), error_code::NONE);
    // Back into Fault with bit 7 still held: not an edge.
    assert_eq!(
        step(&mut d, 0x80, fault(error_code::OVER_CURRENT)),
        Some(13)
    );
    assert_eq!(step(&mut d, 0x80, AT_REST), Some(14));
    for _ in 0..3 {
        assert_eq!(step(&mut d, 0x80, NONE), None);
        assert_eq!(d.state(), Fault);
    }
    // Low for one cycle, then high: reset.
    assert_eq!(step(&mut d, 0x00, NONE), None);
    assert_eq!(step(&mut d, 0x80, NONE), Some(15));
}

#[test]
fn transition_15_refused_while_the_fault_persists() {
    let mut d = reach(Start::Fault);
    let present = fault(error_code::OVER_CURRENT);
    // The edge while the condition remains is refused and consumed.
    assert_eq!(step(&mut d, 0x80, present), None);
    assert_eq!(d.state(), Fault);
    assert_eq!(d.error_code(), error_code::OVER_CURRENT);
    // The condition clears while bit 7 is held: still no reset (no new edge).
    assert_eq!(step(&mut d, 0x80, NONE), None);
    assert_eq!(d.state(), Fault);
    // A later edge after it cleared succeeds.
    assert_eq!(step(&mut d, 0x00, NONE), None);
    assert_eq!(step(&mut d, 0x80, NONE), Some(15));
    assert_eq!(d.state(), SwitchOnDisabled);
    assert_eq!(d.error_code(), error_code::NONE);
}

#[test]
fn transition_12_automatic_when_the_stop_ends() {
    for option in [
        QuickStopOption::SlowDownRamp,
        QuickStopOption::QuickStopRamp,
    ] {
        let mut d = reach_qsa(option);
        // Still stopping: stay, whatever the (non-Disable-voltage) word.
        assert_eq!(step(&mut d, 0x02, NONE), None);
        assert_eq!(step(&mut d, 0x0F, NONE), None, "no 16 with {option:?}");
        assert_eq!(d.state(), QuickStopActive);
        assert_eq!(
            d.step(0x02, AT_REST),
            Some(Transition {
                number: 12,
                from: QuickStopActive,
                to: SwitchOnDisabled
            })
        );
    }
    // Stay after the ramp: at rest is not the end.
    let mut d = reach_qsa(QuickStopOption::StayAfterRamp);
    for _ in 0..3 {
        assert_eq!(step(&mut d, 0x02, AT_REST), None);
    }
    assert_eq!(d.state(), QuickStopActive);
    assert_eq!(step(&mut d, 0x00, AT_REST), Some(12));
    // Coast: the power stage goes off at once, no wait for rest.
    let mut d = reach_qsa(QuickStopOption::Coast);
    assert_eq!(step(&mut d, 0x02, NONE), Some(12));
}

#[test]
fn transition_16_only_when_the_option_stays() {
    let mut d = reach_qsa(QuickStopOption::StayAfterRamp);
    assert_eq!(step(&mut d, 0x02, AT_REST), None);
    assert_eq!(
        d.step(0x0F, AT_REST),
        Some(Transition {
            number: 16,
            from: QuickStopActive,
            to: OperationEnabled
        })
    );
    // Refused with the quick-stop ramp option, stopping or at rest (at rest it ends by 12).
    let mut d = reach_qsa(QuickStopOption::QuickStopRamp);
    assert_eq!(step(&mut d, 0x0F, NONE), None);
    assert_eq!(d.state(), QuickStopActive);
    assert_eq!(step(&mut d, 0x0F, AT_REST), Some(12));
}

#[test]
fn transitions_3_then_4_with_enable_operation_from_ready_to_switch_on() {
    let mut d = reach(Start::Rtso);
    assert_eq!(
        d.step(0x0F, NONE),
        Some(Transition {
            number: 3,
            from: ReadyToSwitchOn,
            to: SwitchedOn
        })
    );
    assert_eq!(
        d.step(0x0F, NONE),
        Some(Transition {
            number: 4,
            from: SwitchedOn,
            to: OperationEnabled
        })
    );
    assert_eq!(step(&mut d, 0x0F, NONE), None);
    // Not from Switch on disabled: 0x0F is not Shutdown there.
    let mut d = reach(Start::Sod);
    for _ in 0..3 {
        assert_eq!(step(&mut d, 0x0F, NONE), None);
    }
    assert_eq!(d.state(), SwitchOnDisabled);
}

#[test]
fn commands_ignore_halt_mode_and_vendor_bits() {
    let mut d = reach(Start::Sod);
    assert_eq!(
        step(&mut d, 0xF976 & !0x0081, NONE),
        Some(2),
        "Shutdown with extra bits"
    );
    assert_eq!(
        step(&mut d, cw::SWITCH_ON_CMD | cw::HALT | 0x0070, NONE),
        Some(3)
    );
    assert_eq!(
        step(&mut d, cw::ENABLE_OPERATION_CMD | cw::HALT, NONE),
        Some(4)
    );
    assert_eq!(step(&mut d, 0x0003, NONE), Some(11), "0x0003 is Quick stop");
}

#[test]
fn statusword_round_trip_for_every_state() {
    let expected = [
        0x0000, 0x0040, 0x0021, 0x0023, 0x0027, 0x0007, 0x000F, 0x0008,
    ];
    for (s, word) in State::ALL.into_iter().zip(expected) {
        assert_eq!(s.statusword(), word, "{}", s.name());
        assert_eq!(State::from_statusword(word), Some(s), "{}", s.name());
        // Every bit outside the state bits is ignored.
        let extra = sw::VOLTAGE_ENABLED
            | sw::WARNING
            | 0x0100
            | sw::REMOTE
            | sw::TARGET_REACHED
            | sw::INTERNAL_LIMIT
            | sw::FOLLOWS_COMMAND
            | sw::FOLLOWING_ERROR
            | 0xC000;
        assert_eq!(
            State::from_statusword(word | extra),
            Some(s),
            "{} with vendor bits",
            s.name()
        );
    }
    // Bit 5 is "don't care" in the 0x004F states only.
    for s in [
        NotReadyToSwitchOn,
        SwitchOnDisabled,
        FaultReactionActive,
        Fault,
    ] {
        assert_eq!(
            State::from_statusword(s.statusword() | sw::QUICK_STOP),
            Some(s),
            "{}",
            s.name()
        );
    }
    // ...and tells Operation enabled from Quick stop active.
    assert_eq!(State::from_statusword(0x0027), Some(OperationEnabled));
    assert_eq!(State::from_statusword(0x0007), Some(QuickStopActive));
}

#[test]
fn statusword_decoding_with_vendor_bits_uses_masks() {
    assert_eq!(
        State::from_statusword(0x12B7),
        Some(OperationEnabled),
        "eRob in OE"
    );
    assert_eq!(
        State::from_statusword(0x9238),
        Some(Fault),
        "faulted drive, bit 5 set"
    );
    assert_eq!(State::from_statusword(0x0060), Some(SwitchOnDisabled));
    assert_eq!(State::from_statusword(0x0231), Some(ReadyToSwitchOn));
    assert_eq!(State::from_statusword(0x0233), Some(SwitchedOn));
    assert_eq!(State::from_statusword(0x0217), Some(QuickStopActive));
    assert_eq!(State::from_statusword(0x022F), Some(FaultReactionActive));
    // Words that match no state.
    for word in [
        0x0001, 0x0003, 0x0011, 0x0048, 0x0041, 0x0022, 0x0025, 0x0004, 0x0029,
    ] {
        assert_eq!(State::from_statusword(word), None, "{word:#06x}");
    }
}

#[test]
fn statusword_decoding_over_all_words_against_the_mask_table() {
    // The profile's state table, written out: (mask, value, state).
    let table = [
        (0x004F, 0x0000, NotReadyToSwitchOn),
        (0x004F, 0x0040, SwitchOnDisabled),
        (0x006F, 0x0021, ReadyToSwitchOn),
        (0x006F, 0x0023, SwitchedOn),
        (0x006F, 0x0027, OperationEnabled),
        (0x006F, 0x0007, QuickStopActive),
        (0x004F, 0x000F, FaultReactionActive),
        (0x004F, 0x0008, Fault),
    ];
    let mut decoded = 0;
    for word in 0..=u16::MAX {
        let mut matches = table
            .iter()
            .filter(|(mask, value, _)| word & mask == *value);
        let reference = matches.next().map(|&(_, _, s)| s);
        assert!(matches.next().is_none(), "{word:#06x} matches two states");
        assert_eq!(State::from_statusword(word), reference, "{word:#06x}");
        decoded += usize::from(reference.is_some());
    }
    // 4 states fix 5 bits (2^11 words each), 4 fix 6 bits (2^10 words each).
    assert_eq!(decoded, 4 * 2048 + 4 * 1024);
}

#[test]
fn decode_over_all_words_against_the_mask_table() {
    // The profile's command table, written out: (mask, value, command). Switch on and
    // Disable operation share a row; decode names it Switch on.
    let table = [
        (0x0087, 0x0006, Command::Shutdown),
        (0x008F, 0x0007, Command::SwitchOn),
        (0x0082, 0x0000, Command::DisableVoltage),
        (0x0086, 0x0002, Command::QuickStop),
        (0x008F, 0x000F, Command::EnableOperation),
    ];
    for word in 0..=u16::MAX {
        let mut matches = table
            .iter()
            .filter(|(mask, value, _)| word & mask == *value);
        let reference = matches.next().map(|&(_, _, c)| c);
        assert!(matches.next().is_none(), "{word:#06x} matches two commands");
        assert_eq!(decode(word), reference, "{word:#06x}");
        // Bit 7 high: no command; bit 7 low: every word is exactly one command.
        assert_eq!(
            reference.is_none(),
            word & cw::FAULT_RESET != 0,
            "{word:#06x}"
        );
    }
    // The brief's words one by one: `command::tests::the_words_named_in_the_brief`.
    assert_eq!(decode(cw::DISABLE_OPERATION), Some(Command::SwitchOn));
}

#[test]
fn enable_step_drives_a_device_from_sod_to_oe_in_three_steps() {
    let mut d = reach(Start::Sod);
    let mut numbers = Vec::new();
    for _ in 0..3 {
        let word = enable_step(d.state());
        numbers.extend(step(&mut d, word, NONE));
    }
    assert_eq!(numbers, [2, 3, 4]);
    assert_eq!(d.state(), OperationEnabled);
    // It keeps the drive there.
    assert_eq!(master(&mut d, enable_step), None);
    assert_eq!(enable_step(SwitchOnDisabled), cw::SHUTDOWN);
    assert_eq!(enable_step(ReadyToSwitchOn), cw::SWITCH_ON_CMD);
    assert_eq!(enable_step(SwitchedOn), cw::ENABLE_OPERATION_CMD);
    assert_eq!(enable_step(OperationEnabled), cw::ENABLE_OPERATION_CMD);
}

#[test]
fn enable_step_leaves_quick_stop_through_sod() {
    let mut d = reach(Start::Qsa);
    let mut numbers = Vec::new();
    for _ in 0..4 {
        let word = enable_step(d.state());
        numbers.extend(step(&mut d, word, NONE));
    }
    assert_eq!(numbers, [12, 2, 3, 4]);
}

#[test]
fn enable_step_never_leaves_fault() {
    for start in [Start::Fra, Start::Fault] {
        let mut d = reach(start);
        for _ in 0..10 {
            let word = enable_step(d.state());
            assert_eq!(word, cw::DISABLE_VOLTAGE);
            // Even with the fault gone and the motor at rest, only Fault is reached.
            let t = step(&mut d, word, AT_REST);
            assert!(t.is_none() || t == Some(14), "{start:?}: {t:?}");
        }
        assert_eq!(d.state(), Fault, "{start:?}");
    }
}

#[test]
fn disable_step_takes_power_off_in_order() {
    let cases = [
        (Start::Oe, 8),
        (Start::So, 6),
        (Start::Qsa, 12),
        (Start::QsaStay, 12),
        (Start::Sod, 2),
    ];
    for (start, first) in cases {
        let mut d = reach(start);
        assert_eq!(master(&mut d, disable_step), Some(first), "{start:?}");
        for _ in 0..3 {
            let word = disable_step(d.state());
            step(&mut d, word, NONE);
        }
        assert_eq!(d.state(), ReadyToSwitchOn, "{start:?}");
        assert!(!d.state().power_stage_on());
        assert_eq!(master(&mut d, disable_step), None, "settled");
    }
    for s in [
        QuickStopActive,
        FaultReactionActive,
        Fault,
        NotReadyToSwitchOn,
    ] {
        assert_eq!(disable_step(s), cw::DISABLE_VOLTAGE, "{}", s.name());
    }
    let mut d = reach(Start::Fault);
    assert_eq!(master(&mut d, disable_step), None);
}

#[test]
fn fault_reset_takes_a_device_out_of_fault() {
    let mut d = reach(Start::Oe);
    // The master was holding bit 7 high before the fault: FaultReset still makes an edge.
    assert_eq!(
        step(&mut d, 0x8F, fault(error_code::FOLLOWING_ERROR)),
        Some(13)
    );
    assert_eq!(step(&mut d, 0x80, AT_REST), Some(14));
    let mut r = FaultReset::new();
    let mut numbers = Vec::new();
    for _ in 0..4 {
        let word = r.controlword(d.state());
        numbers.extend(step(&mut d, word, NONE));
    }
    assert_eq!(numbers, [15]);
    assert!(r.done(d.state()));
    assert_eq!(d.state(), SwitchOnDisabled);
    assert_eq!(d.error_code(), error_code::NONE);
}

#[test]
fn fault_reset_is_refused_while_the_condition_persists() {
    let mut d = reach(Start::Fault);
    let present = fault(error_code::OVER_CURRENT);
    let mut r = FaultReset::new();
    for _ in 0..5 {
        let word = r.controlword(d.state());
        assert_eq!(step(&mut d, word, present), None);
    }
    assert_eq!(d.state(), Fault);
    assert!(!r.done(d.state()));
    assert_eq!(d.error_code(), error_code::OVER_CURRENT);
    // The condition clears: the held bit is no new edge, a new FaultReset is.
    let word = r.controlword(d.state());
    assert_eq!(step(&mut d, word, NONE), None);
    let mut r = FaultReset::new();
    let mut numbers = Vec::new();
    for _ in 0..3 {
        let word = r.controlword(d.state());
        numbers.extend(step(&mut d, word, NONE));
    }
    assert_eq!(numbers, [15]);
    assert!(r.done(d.state()));
}

#[test]
fn fault_reset_then_enable_reaches_operation_enabled() {
    let mut d = reach(Start::Fault);
    let mut r = FaultReset::new();
    while !r.done(d.state()) {
        let word = r.controlword(d.state());
        d.step(word, NONE);
    }
    for _ in 0..3 {
        let word = enable_step(d.state());
        d.step(word, NONE);
    }
    assert_eq!(d.state(), OperationEnabled);
}

/// Builds a device in Quick stop active with this quick stop option.
fn reach_qsa(option: QuickStopOption) -> Device {
    let mut d = Device::new(option);
    for (word, number) in [(0x00, 1), (0x06, 2), (0x07, 3), (0x0F, 4), (0x02, 11)] {
        assert_eq!(step(&mut d, word, NONE), Some(number));
    }
    d
}
