//! Seed 001's servo layer over the CiA 402 drives, in one process (servo's controller and the
//! machine model, `loop_sim`): power requests, command validation that cuts power and
//! latches, no re-enable without reset, injected drive faults, stale feedback, and a servo
//! that keeps the axes still when trajgen dies.

use crate::loop_sim::{Loop, MS};
use cell_config::Config;
use cia402::{State, cw};
use motion_core::generator::{Generator, Params};
use shm_schema::drive::{injected, servo_status as st};
use shm_schema::event::code;
use shm_schema::{FaultInjectionV1, MotionState, Power, RequestKind, ServoStateV3, SetpointV2};

/// The default cell with the key at `path` set to `value`.
fn cfg_with(path: &str, value: f64) -> Config {
    let src = integration_tests::CellToml::parse(cell_config::DEFAULT_TOML)
        .set(path, value)
        .to_string();
    Config::parse(&src, "test").expect("valid")
}

/// A trajectory generator at the default start with `program` queued.
fn generator(cell: &shm_schema::CellConfigV6, program: &str) -> Generator {
    let mut g = Generator::new(Params::from_cell(cell), &[40.0, 40.0, 0.0]);
    for c in crate::gantry_commands(program, 1) {
        g.push_command(&c);
    }
    g
}

/// `cell`'s servo and machine, enabled, and trajgen with `program` queued: the loop, the
/// generator, and trajgen's period in servo cycles.
fn enabled_with(cell: &shm_schema::CellConfigV6, program: &str) -> (Loop, Generator, u64) {
    let lp = Loop::enabled(cell);
    let tg = cell.period_of("trajgen").expect("trajgen") / lp.period;
    (lp, generator(cell, program), tg)
}

/// [`enabled_with`] on the default cell with the drives and servo at 4 kHz; the cell too.
fn at_4_khz_with(program: &str) -> (shm_schema::CellConfigV6, Loop, Generator, u64) {
    let cell = crate::closed_loop::at_rate(250).to_shm();
    let (lp, g, tg) = enabled_with(&cell, program);
    (cell, lp, g, tg)
}

/// One period of `lp`, with `g`'s next setpoint if `due` (stamped 100 µs after the machine's
/// phase, as trajgen's are): servo's state.
fn follow(lp: &mut Loop, g: &mut Generator, due: bool) -> ServoStateV3 {
    let sp = due.then(|| g.step(lp.now + 100_000, None));
    lp.step_with(None, sp.as_ref(), None)
}

/// The default cell, enabled, two seconds into a move of every axis (`MOVE(140,90,90)`), x
/// at full speed: the loop and the generator.
fn two_seconds_into_a_move() -> (Loop, Generator) {
    let cell = Config::default_cell().to_shm();
    let (mut lp, mut g, tg) = enabled_with(&cell, "MOVE(140,90,90)\nEND");
    for k in 0..2000 {
        follow(&mut lp, &mut g, k % tg == 0);
    }
    let v = lp.state.cmd_velocity[0];
    assert!(v > 10.0, "moving at {v}");
    (lp, g)
}

/// The default cell whose x cannot produce the force to follow (its effort barely beats
/// friction), moving x until servo latches: the loop and the state that latched.
fn an_axis_that_cannot_follow() -> (Loop, ServoStateV3) {
    let cell = cfg_with("axis[x].sim.effort_limit", 3.1).to_shm();
    let (mut lp, mut g, tg) = enabled_with(&cell, "MOVE(140,40,0)\nEND");
    for k in 0..20_000u64 {
        let s = follow(&mut lp, &mut g, k % tg == 0);
        if s.status & st::FAULT_LATCHED != 0 {
            return (lp, s);
        }
    }
    panic!("no fault: {:?}", lp.codes());
}

/// Every drive of `s` without power.
fn powered_off(s: &ServoStateV3) -> bool {
    (0..3).all(|i| State::from_statusword(s.statusword[i]).is_some_and(|s| !s.power_stage_on()))
}

/// The CiA 402 transitions the drives reported (of axis `axis` only, if given), in order.
fn transitions(lp: &Loop, axis: Option<i32>) -> Vec<f64> {
    lp.events
        .iter()
        .filter(|e| e.code == code::DRIVE_TRANSITION && axis.is_none_or(|a| e.axis == a))
        .map(|e| e.value)
        .collect()
}

fn states(lp: &Loop) -> Vec<State> {
    let fb = lp.fb.expect("feedback");
    (0..3)
        .map(|i| State::from_statusword(fb.statusword[i]).expect("state"))
        .collect()
}

/// A setpoint at servo's next cycle, at `pos` with `vel` on x (y, theta at their start).
fn setpoint(lp: &Loop, seq: u64, x: f64, vx: f64) -> SetpointV2 {
    let mut sp = SetpointV2 {
        seq,
        stamp_ns: lp.now + 300_000,
        axes: 3,
        state: MotionState::Moving as u32,
        ..Default::default()
    };
    sp.position[..3].copy_from_slice(&[x, 40.0, 0.0]);
    sp.velocity[0] = vx;
    sp
}

/// After a latch: power goes off on every axis and stays off; enable is refused until a
/// reset; the reset brings nothing back by itself; enable then works again.
fn check_latched_then_recover(lp: &mut Loop, want: u32) {
    let s = lp.until(None, 500, |s| s.power == Power::Disabled as u8);
    assert_eq!(s.fault_code, want, "events {:?}", lp.codes());
    assert_ne!(s.status & st::FAULT_LATCHED, 0);
    assert!(lp.codes().contains(&want));
    assert!(lp.codes().contains(&code::POWER_CUT));
    // Quick stop first (11), then disable voltage: every drive ends without power.
    let transitions = transitions(lp, None);
    assert!(
        transitions.contains(&11.0) || transitions.contains(&13.0),
        "quick stop or fault reaction: {transitions:?}"
    );
    lp.until(None, 500, powered_off);
    // Latched: enable is refused, for as long as we wait.
    let before = lp.events.len();
    lp.step_with(Some(RequestKind::Enable), None, None);
    for _ in 0..300 {
        let s = lp.step();
        assert_ne!(s.status & st::FAULT_LATCHED, 0);
        assert_eq!(s.power, Power::Disabled as u8);
        assert!(states(lp).iter().all(|s| *s != State::OperationEnabled));
    }
    assert!(
        lp.events[before..]
            .iter()
            .any(|e| e.code == code::REQUEST_REFUSED)
    );
    // Reset clears the latch; power stays off until an enable request.
    lp.until(Some(RequestKind::Reset), 50, |s| {
        s.status & st::FAULT_LATCHED == 0
    });
    assert!(lp.codes().contains(&code::FAULT_CLEARED));
    for _ in 0..300 {
        assert_eq!(lp.step().power, Power::Disabled as u8);
    }
    lp.until(Some(RequestKind::Enable), 50, |s| {
        s.status & st::ENABLED != 0
    });
    assert!(states(lp).iter().all(|s| *s == State::OperationEnabled));
}

#[test]
fn enable_and_disable_take_effect_in_the_next_cycle_and_a_disable_aborts_an_enable() {
    integration_tests::wall_clock(|| {
        let cell = Config::default_cell().to_shm();
        let mut lp = Loop::new(&cell);
        let s = lp.until(None, 10, |s| s.status & st::INITIALIZED != 0);
        assert_eq!(s.power, Power::Disabled as u8);
        // The drives sit without power until asked.
        for _ in 0..100 {
            let s = lp.step();
            assert_eq!(s.status & st::ENABLED, 0);
        }
        assert!(states(&lp).iter().all(|s| !s.power_stage_on()));
        let s = lp.step_with(Some(RequestKind::Enable), None, None);
        assert_eq!(s.power, Power::Enabling as u8);
        assert!(s.controlword[..3].iter().all(|w| *w == cw::SWITCH_ON_CMD));
        let s = lp.step_with(Some(RequestKind::Disable), None, None);
        assert_eq!(
            s.power,
            Power::Disabling as u8,
            "the disable aborts the pending enable"
        );
        let s = lp.until(None, 50, |s| s.power == Power::Disabled as u8);
        assert_eq!(s.status & st::ENABLED, 0);
        assert!(lp.codes().contains(&code::DISABLING) && !lp.codes().contains(&code::ENABLED));
        let s = lp.enable();
        assert!(s.axis_power[..3].iter().all(|p| *p == Power::Enabled as u8));
        let s = lp.step_with(Some(RequestKind::Disable), None, None);
        assert!(
            s.controlword[..3].iter().all(|w| *w == cw::SHUTDOWN),
            "transition 8"
        );
        lp.until(None, 50, |s| s.power == Power::Disabled as u8);
        assert!(states(&lp).iter().all(|s| *s == State::ReadyToSwitchOn));
    });
}

#[test]
fn servo_does_not_follow_setpoints_unless_enabled() {
    integration_tests::wall_clock(|| {
        let cell = Config::default_cell().to_shm();
        let mut lp = Loop::new(&cell);
        lp.until(None, 10, |s| s.status & st::INITIALIZED != 0);
        for k in 1..200 {
            let sp = setpoint(&lp, k, 40.0 + k as f64 * 0.01, 10.0);
            let s = lp.step_with(None, Some(&sp), None);
            assert_eq!(s.setpoint_seq, 0);
        }
        assert_eq!(lp.machine.axes()[0].position, 40.0, "the axis never moved");
    });
}

#[test]
fn each_validation_rule_cuts_power_and_stays_latched_until_reset() {
    integration_tests::wall_clock(|| {
        // (what, configuration change, setpoint x and x velocity relative to the start, code)
        type Case<'a> = (&'a str, Option<(&'a str, f64)>, f64, f64, u32);
        let cases: [Case; 5] = [
            (
                "range",
                Some(("axis[x].max", 40.005)),
                0.02,
                0.0,
                code::POSITION_OUT_OF_RANGE,
            ),
            ("velocity", None, 0.0, 20.0, code::VELOCITY_OVER_LIMIT),
            (
                "position step",
                None,
                0.03,
                0.0,
                code::POSITION_STEP_OVER_LIMIT,
            ),
            (
                "velocity step",
                None,
                0.0,
                1.0,
                code::VELOCITY_STEP_OVER_LIMIT,
            ),
            ("not finite", None, f64::NAN, 0.0, code::COMMAND_NOT_FINITE),
        ];
        for (what, change, dx, vx, want) in cases {
            let cfg = match change {
                None => Config::default_cell(),
                Some((path, value)) => cfg_with(path, value),
            };
            let mut lp = Loop::enabled(&cfg.to_shm());
            // Hold with a valid setpoint for a while, then the bad one.
            for k in 1..50 {
                let sp = setpoint(&lp, k, 40.0, 0.0);
                let s = lp.step_with(None, Some(&sp), None);
                assert_eq!(s.status & st::FAULT_LATCHED, 0, "{what}: {:?}", lp.codes());
            }
            let sp = setpoint(&lp, 50, 40.0 + dx, vx);
            let s = lp.step_with(None, Some(&sp), None);
            // The cycle that latches still sends the last good targets, never 0.
            let cmd = lp.cmd.expect("command");
            assert_eq!(cmd.target_position[..3], [40.0, 40.0, 0.0], "{what}");
            assert_ne!(s.status & st::FAULT_LATCHED, 0, "{what}: {:?}", lp.codes());
            assert_eq!(s.fault_code, want, "{what}");
            let e = lp
                .events
                .iter()
                .find(|e| e.code == want)
                .expect("the rule's event");
            if want != code::COMMAND_NOT_FINITE {
                assert_eq!(e.axis, 0, "{what}: names the axis");
                assert!(
                    e.limit > 0.0 && e.value.abs() > e.limit.abs() * 0.99,
                    "{what}: {e:?}"
                );
            }
            check_latched_then_recover(&mut lp, want);
        }
    });
}

#[test]
fn a_following_error_latches_like_a_device_estop() {
    integration_tests::wall_clock(|| {
        let (mut lp, s) = an_axis_that_cannot_follow();
        assert_eq!(s.fault_code, code::FOLLOWING_ERROR, "{:?}", lp.codes());
        assert_eq!(s.fault_axis, 0);
        assert!(s.fault_value.abs() > 1.0 && s.fault_limit == 1.0);
        check_latched_then_recover(&mut lp, code::FOLLOWING_ERROR);
    });
}

#[test]
fn an_injected_drive_fault_is_reported_and_recovered_by_reset_once_it_clears() {
    integration_tests::wall_clock(|| {
        let mut lp = Loop::enabled(&Config::default_cell().to_shm());
        let inject = |seq, active| FaultInjectionV1 {
            seq,
            axis: 1,
            code: injected::OVER_CURRENT,
            active,
        };
        lp.step_with(None, None, Some(&inject(1, 1)));
        let s = lp.until(None, 50, |s| s.status & st::FAULT_LATCHED != 0);
        assert_eq!(s.fault_code, code::DRIVE_REPORTS_FAULT);
        assert_eq!((s.fault_axis, s.fault_value), (1, 0x2310 as f64));
        let fault = lp
            .events
            .iter()
            .find(|e| e.code == code::DRIVE_FAULT)
            .expect("drive event");
        assert_eq!(
            (fault.axis, fault.value, fault.text()),
            (1, 0x2310 as f64, "y: over-current")
        );
        lp.until(None, 500, |s| {
            State::from_statusword(s.statusword[1]) == Some(State::Fault)
        });
        // The condition persists: a reset is refused and the drive stays in Fault.
        let before = lp.events.len();
        lp.step_with(Some(RequestKind::Reset), None, None);
        for _ in 0..700 {
            lp.step();
        }
        assert_eq!(states(&lp)[1], State::Fault);
        assert_ne!(lp.state.status & st::FAULT_LATCHED, 0);
        // Refused: the request's kind its value; why, in the event's words (servo's events
        // carry no other cause), is the subject.
        assert!(
            lp.events[before..]
                .iter()
                .any(|e| e.code == code::REQUEST_REFUSED
                    && e.value == f64::from(RequestKind::Reset as u32)
                    && e.text().contains("still in Fault"))
        );
        // Cleared: the reset works (transition 15), power stays off until enable.
        lp.step_with(None, None, Some(&inject(2, 0)));
        check_latched_then_recover(&mut lp, code::DRIVE_REPORTS_FAULT);
        assert!(
            lp.events
                .iter()
                .any(|e| e.code == code::DRIVE_TRANSITION && e.value == 15.0)
        );
    });
}

#[test]
fn a_lost_encoder_is_a_fault_at_once_and_never_a_believable_number() {
    integration_tests::wall_clock(|| {
        let mut lp = Loop::enabled(&Config::default_cell().to_shm());
        let f = FaultInjectionV1 {
            seq: 1,
            axis: 0,
            code: injected::ENCODER_LOSS,
            active: 1,
        };
        lp.step_with(None, None, Some(&f));
        let s = lp.step();
        assert_eq!(s.fault_code, code::FEEDBACK_NOT_FINITE);
        assert!(s.act_position[0].is_nan());
        let image = iobridge::write_image(1, 0, &s);
        assert!(
            iobridge::read_image(&image).1[0].is_nan(),
            "the image marks it invalid"
        );
    });
}

#[test]
fn no_drive_re_enables_after_a_command_timeout_without_reset() {
    integration_tests::wall_clock(|| {
        let mut lp = Loop::enabled(&Config::default_cell().to_shm());
        // Servo goes silent for longer than the drives' watchdog (0.1 s): the machine runs alone.
        let mut q = shm_schema::EventQueue::default();
        for _ in 0..150 {
            lp.machine.cycle(lp.now, None, None, &mut q);
            lp.now += lp.period;
        }
        assert!(
            lp.machine
                .drives()
                .iter()
                .all(|d| d.state() == State::Fault)
        );
        assert!(q.as_slice().iter().any(|e| e.code == code::COMMAND_TIMEOUT));
        lp.events.extend_from_slice(q.as_slice());
        // Servo comes back: it sees the faults, latches, and nothing powers up by itself.
        for _ in 0..500 {
            let s = lp.step();
            assert_eq!(s.status & st::ENABLED, 0);
        }
        assert_eq!(lp.state.fault_code, code::DRIVE_REPORTS_FAULT);
        assert_eq!(
            lp.fb.expect("fb").error_code[0],
            cia402::error_code::COMMAND_TIMEOUT
        );
        check_latched_then_recover(&mut lp, code::DRIVE_REPORTS_FAULT);
    });
}

#[test]
fn servo_notices_stale_feedback_and_cuts_power() {
    integration_tests::wall_clock(|| {
        let cell = Config::default_cell().to_shm();
        let mut lp = Loop::enabled(&cell);
        // The drives' feedback stops (the machine process stalls or died); servo keeps cycling.
        let fb = lp.fb;
        let mut q = shm_schema::EventQueue::default();
        let mut s = lp.state;
        for k in 0..200 {
            let t = lp.now + k * MS;
            s = lp.servo.cycle(t, None, None, fb.as_ref(), &mut q).1;
            if s.status & st::FAULT_LATCHED != 0 {
                // Within the feedback timeout (0.1 s) plus a cycle.
                assert!(k * MS <= cell.feedback_timeout_ns + 2 * MS, "after {k} ms");
                break;
            }
        }
        assert_eq!(s.fault_code, code::FEEDBACK_STALE);
        let e = q
            .as_slice()
            .iter()
            .find(|e| e.code == code::FEEDBACK_STALE)
            .expect("event");
        assert!(e.value > e.limit && e.limit == 0.1, "{e:?}");
        let (cmd, _) = lp
            .servo
            .cycle(lp.now + 201 * MS, None, None, fb.as_ref(), &mut q);
        assert!(
            cmd.controlword[..3]
                .iter()
                .all(|w| *w == cw::QUICK_STOP_CMD)
        );
        // A reset while the feedback is still stale is refused; the fault stays latched.
        let reset = shm_schema::ServoRequestV1 {
            seq: 9,
            kind: RequestKind::Reset as u32,
            axis: 0,
            value: 0.0,
        };
        let mut q = shm_schema::EventQueue::default();
        let mut s = lp.state;
        let (mut refused, mut cleared) = (false, false);
        for k in 0..700u64 {
            let r = (k == 0).then_some(&reset);
            s = lp
                .servo
                .cycle(lp.now + (202 + k) * MS, r, None, fb.as_ref(), &mut q)
                .1;
            refused |= q.as_slice().iter().any(|e| e.code == code::REQUEST_REFUSED);
            cleared |= q.as_slice().iter().any(|e| e.code == code::FAULT_CLEARED);
            q.clear();
        }
        assert!(refused && !cleared, "refused {refused}, cleared {cleared}");
        assert_ne!(s.status & st::FAULT_LATCHED, 0);
        assert_eq!(s.fault_code, code::FEEDBACK_STALE);
    });
}

#[test]
fn servo_keeps_the_axes_still_when_trajgen_dies_mid_motion() {
    integration_tests::wall_clock(|| {
        // 2 s of motion at full speed, then trajgen dies.
        let (mut lp, _) = two_seconds_into_a_move();
        let mut max_fe = [0.0f64; 3];
        for _ in 0..2000 {
            let s = lp.step();
            for (m, e) in max_fe.iter_mut().zip(&s.following_error) {
                *m = m.max(e.abs());
            }
        }
        let s = lp.state;
        assert_eq!(s.status & st::FAULT_LATCHED, 0, "{:?}", lp.codes());
        assert_ne!(s.status & st::ENABLED, 0);
        assert_ne!(s.status & st::SETPOINT_STALE, 0);
        assert!(lp.codes().contains(&code::SETPOINT_STALE));
        for (i, fe) in max_fe.iter().enumerate() {
            assert!(*fe < 0.5, "axis {i}: following error {fe}");
            assert_eq!(s.cmd_velocity[i], 0.0);
        }
        // At rest, and no drift: another 5 s change nothing beyond the in-position band.
        let held = lp
            .machine
            .axes()
            .iter()
            .map(|a| a.position)
            .collect::<Vec<_>>();
        for _ in 0..5000 {
            lp.step();
        }
        for (i, a) in lp.machine.axes().iter().enumerate() {
            assert!((a.position - held[i]).abs() <= 0.01, "axis {i} drifted");
            assert!(lp.state.following_error[i].abs() <= 0.01);
        }
        assert_ne!(lp.state.status & st::SETTLED, 0);
    });
}

#[test]
fn a_late_setpoint_rejoins_without_a_step_at_4_khz() {
    integration_tests::wall_clock(|| {
        // trajgen silent for 30 ms in the middle of an acceleration and for 40 ms later (host
        // stalls of its CPU, below the 50 ms setpoint timeout): the next setpoint differs from
        // servo's extrapolation; the command must not step.
        let (cell, mut lp, mut g, tg) = at_4_khz_with("MOVE(140,90,90)\nEND");
        let (mut max_dp, mut max_dv) = ([0.0f64; 3], [0.0f64; 3]);
        let mut prev = lp.state;
        for k in 0..8000u64 {
            let silent = (1000..1120).contains(&k) || (3000..3160).contains(&k);
            let s = follow(&mut lp, &mut g, k % tg == 0 && !silent);
            assert_eq!(s.status & st::FAULT_LATCHED, 0, "at {k}: {:?}", lp.codes());
            if k > 10 {
                for i in 0..3 {
                    max_dp[i] = max_dp[i].max((s.cmd_position[i] - prev.cmd_position[i]).abs());
                    max_dv[i] = max_dv[i].max((s.cmd_velocity[i] - prev.cmd_velocity[i]).abs());
                }
            }
            prev = s;
        }
        for (i, a) in cell.axes().iter().enumerate() {
            assert!(
                max_dp[i] <= a.position_step_limit,
                "axis {i}: step {}",
                max_dp[i]
            );
            assert!(
                max_dv[i] <= a.velocity_step_limit,
                "axis {i}: velocity step {}",
                max_dv[i]
            );
        }
    });
}

#[test]
fn a_late_servo_cycle_is_not_a_step() {
    integration_tests::wall_clock(|| {
        // Servo itself stalls 3 ms (12 periods at 4 kHz) with the axes at full speed: the command
        // moves 48 µm in one cycle, which the real elapsed time explains; nothing is refused.
        let (_, mut lp, mut g, tg) = at_4_khz_with("MOVE(140,90,90)\nEND");
        for k in 0..6000u64 {
            if k == 4000 {
                assert!(lp.state.cmd_velocity[0] > 15.0);
                lp.servo_stalls(12);
            }
            let s = follow(&mut lp, &mut g, k % tg == 0);
            assert_eq!(s.status & st::FAULT_LATCHED, 0, "at {k}: {:?}", lp.codes());
        }
    });
}

#[test]
fn a_tuning_step_is_taken_at_rest_only_and_within_half_the_following_error_limit() {
    integration_tests::wall_clock(|| {
        let mut lp = Loop::enabled(&Config::default_cell().to_shm());
        let step = |lp: &mut Loop, seq: u64, value: f64| {
            let r = shm_schema::ServoRequestV1 {
                seq,
                kind: RequestKind::Step as u32,
                axis: 0,
                value,
            };
            let fb = lp.fb;
            lp.servo_only(Some(&r), fb.as_ref())
        };
        // Too large: refused, nothing moves.
        let s = step(&mut lp, 100, 0.6);
        assert_eq!(s.cmd_position[0], 40.0);
        // Refused (the request's kind its value), saying why in words (servo's events carry no
        // other cause): the words are the subject.
        assert!(lp.events.iter().any(|e| e.code == code::REQUEST_REFUSED
            && e.value == f64::from(RequestKind::Step as u32)
            && e.text().contains("half the following-error limit")));
        // Within the limit: the command steps at once, with no fault, and the axis follows.
        let s = step(&mut lp, 101, 0.4);
        assert!(
            (s.cmd_position[0] - 40.4).abs() < 1e-12,
            "{}",
            s.cmd_position[0]
        );
        assert_eq!(s.status & st::FAULT_LATCHED, 0);
        let s = lp.until(None, 2000, |s| s.status & st::SETTLED != 0);
        assert!((s.act_position[0] - 40.4).abs() <= 0.01);
        assert!(lp.codes().contains(&code::TUNE_STEP));
    });
}

#[test]
fn a_reset_never_cancels_a_quick_stop_under_way() {
    integration_tests::wall_clock(|| {
        // A following error at speed cuts power; a reset sent at once waits until every drive
        // has stopped (the quick-stop ramp ran its course) and is without power.
        let (mut lp, _) = an_axis_that_cannot_follow();
        assert!(
            lp.machine.axes()[0].velocity.abs() > 1.0,
            "moving when power was cut"
        );
        let s = lp.step_with(Some(RequestKind::Reset), None, None);
        assert_ne!(
            s.status & st::FAULT_LATCHED,
            0,
            "not cleared while x still ramps down"
        );
        let s = lp.until(None, 2000, |s| s.status & st::FAULT_LATCHED == 0);
        assert!(lp.machine.axes().iter().all(|a| a.velocity == 0.0));
        assert!(powered_off(&s));
        // The ramp ran: x went through Quick stop active (11), then Switch on disabled (12).
        let x = transitions(&lp, Some(0));
        assert!(x.ends_with(&[11.0, 12.0]), "{x:?}");
    });
}

#[test]
fn feedback_that_is_not_the_cells_latches() {
    integration_tests::wall_clock(|| {
        // Servo's state after a cycle, enabled, on the feedback as `alter` changes it.
        let cell = Config::default_cell().to_shm();
        let on = |alter: fn(&mut shm_schema::DriveFeedbackV2)| {
            let mut lp = Loop::enabled(&cell);
            let mut fb = lp.fb.expect("feedback");
            alter(&mut fb);
            fb.seq += 1;
            lp.servo_only(None, Some(&fb))
        };
        // A drives' process for another machine (2 axes for a 3-axis cell) is refused at once.
        let s = on(|fb| fb.axes = 2);
        assert_eq!(
            (s.fault_code, s.fault_value, s.fault_limit),
            (code::FEEDBACK_MISMATCH, 2.0, 3.0)
        );
        // A drive that runs another mode than configured (CSP for a CST axis) while enabled.
        let s = on(|fb| fb.mode_display[1] = cia402::Mode::Csp as i8);
        assert_eq!((s.fault_code, s.fault_axis), (code::FEEDBACK_MISMATCH, 1));
        assert_eq!((s.fault_value, s.fault_limit), (8.0, 10.0));
    });
}

#[test]
fn a_disable_at_speed_brings_the_axes_to_rest_before_power_goes_off() {
    integration_tests::wall_clock(|| {
        let (mut lp, _g) = two_seconds_into_a_move();
        let v0 = lp.state.cmd_velocity[0];
        let s = lp.step_with(Some(RequestKind::Disable), None, None);
        assert_eq!(s.power, Power::Disabling as u8);
        assert!(
            s.controlword[..3]
                .iter()
                .all(|w| *w == cw::ENABLE_OPERATION_CMD)
        );
        // Power stays on while the reference decelerates; Shutdown only at rest.
        let mut cycles = 0u64;
        let mut max_fe = 0.0f64;
        loop {
            let s = lp.step();
            max_fe = max_fe.max(s.following_error[0].abs());
            if s.controlword[0] == cw::SHUTDOWN {
                assert!(lp.machine.axes()[0].velocity.abs() <= 0.1, "still moving");
                break;
            }
            cycles += 1;
            assert!(cycles < 5000, "never powered down");
        }
        // From v0 at vmax / t_acc: about t_acc.
        let ramp_s = cycles as f64 * 1e-3;
        assert!(ramp_s > 0.8 * v0 / (16.0 / 0.525), "{ramp_s} s");
        assert!(max_fe < 0.5, "{max_fe}");
        let s = lp.until(None, 100, |s| s.power == Power::Disabled as u8);
        assert_eq!(s.status & st::FAULT_LATCHED, 0, "{:?}", lp.codes());
        assert!(states(&lp).iter().all(|s| *s == State::ReadyToSwitchOn));
    });
}

#[test]
fn a_setpoint_stamped_after_servo_woke_is_evaluated_at_servo_time() {
    integration_tests::wall_clock(|| {
        // Servo takes its time when it wakes; a host stall before it reads the setpoint lets
        // trajgen publish one stamped 6 ms later. At 16 mm/s, taking it at its stamp would step
        // the command 0.1 mm in one cycle (found at 4 kHz on this VM); servo evaluates it back at
        // its own time instead.
        let (_, mut lp, mut g, tg) = at_4_khz_with("MOVE(140,40,0)\nEND");
        for k in 0..12_000u64 {
            // One setpoint from the future of servo's cycle, at full speed.
            let ahead = if k == 10_000 { 6_000_000 } else { 0 };
            let sp = (k % tg == 0 || k == 10_000).then(|| g.step(lp.now + 100_000 + ahead, None));
            let s = lp.step_with(None, sp.as_ref(), None);
            assert_eq!(s.status & st::FAULT_LATCHED, 0, "at {k}: {:?}", lp.codes());
        }
    });
}

#[test]
fn servo_latches_the_peak_following_error_of_each_program_in_every_cycle() {
    integration_tests::wall_clock(|| {
        let cell = Config::default_cell().to_shm();
        let (mut lp, mut g, tg) = enabled_with(&cell, "MOVE(140,40,0)\nEND");
        // A reader that sees every state finds exactly servo's latched figure.
        let mut seen = [0.0f64; 3];
        let mut last = None;
        for k in 0..12_000u64 {
            let s = follow(&mut lp, &mut g, k % tg == 0);
            for (m, e) in seen.iter_mut().zip(&s.following_error[..3]) {
                *m = m.max(e.abs());
            }
            last = Some(s);
        }
        let s = last.expect("states");
        assert_eq!(s.peak_program, 1);
        assert!(seen[0] > 1e-4, "x moved: {seen:?}");
        assert_eq!(&s.peak_following_error[..3], &seen[..]);
        // The next program's first setpoint starts a new figure.
        for c in crate::gantry_commands("MOVE(141,40,0)\nEND", 2) {
            g.push_command(&c);
        }
        let mut first = None;
        for k in 0..4_000u64 {
            let s = follow(&mut lp, &mut g, k % tg == 0);
            if s.peak_program == 2 && first.is_none() {
                first = Some(s);
            }
        }
        let first = first.expect("program 2 followed");
        for i in 0..3 {
            assert_eq!(
                first.peak_following_error[i],
                first.following_error[i].abs()
            );
        }
    });
}

/// Issue 21 item 16: a new source's first setpoint refused says which test refused it, with
/// that test's own value and limit: its position (`setpoint-jump`, axis unit) or its velocity
/// (`setpoint-velocity-jump`, axis unit/s). An event had reported the position within its
/// limit when the velocity was what refused the setpoint.
#[test]
fn a_refused_first_setpoint_names_the_test_that_refused_it() {
    integration_tests::wall_clock(|| {
        let cell = Config::default_cell().to_shm();
        let refused = |x: f64, vx: f64| {
            let mut lp = Loop::enabled(&cell);
            let sp = setpoint(&lp, 1, x, vx);
            let s = lp.step_with(None, Some(&sp), None);
            assert_ne!(s.status & st::SETPOINT_JUMP, 0, "{x}, {vx}: not refused");
            *lp.events
                .iter()
                .find(|e| e.code == code::SETPOINT_JUMP || e.code == code::SETPOINT_VELOCITY_JUMP)
                .unwrap_or_else(|| panic!("{x}, {vx}: no event in {:?}", lp.codes()))
        };
        // Where servo holds (x = 40), at 5 mm/s: the velocity refuses it.
        let e = refused(40.0, 5.0);
        assert_eq!((e.code, e.axis), (code::SETPOINT_VELOCITY_JUMP, 0));
        assert!(e.value > e.limit && (e.value - 5.0).abs() < 1e-6, "{e:?}");
        // The event's words name the test too (what a user reads): the subject.
        assert!(e.text().contains("velocity"), "{}", e.text());
        // 2 mm away at rest: the position refuses it.
        let e = refused(42.0, 0.0);
        assert_eq!((e.code, e.axis), (code::SETPOINT_JUMP, 0));
        assert!(e.value > e.limit && e.value > 1.9, "{e:?}");
        assert!(e.text().contains("position"), "{}", e.text());
    });
}

/// A foreign trajectory generator's plain trapezoid, rest to rest from `from` to `to`, all
/// axes together: each accelerates for `t_acc` at a constant rate, cruises, and decelerates
/// for `t_acc`, its speed within its `vmax` (no blend: the acceleration jumps between 0 and
/// ± its value at four instants).
struct Trapezoid {
    start_ns: u64,
    from: [f64; 3],
    to: [f64; 3],
    /// Its duration (s): the slowest axis' distance over its vmax, plus `t_acc`.
    t: f64,
    t_acc: f64,
}

impl Trapezoid {
    fn new(cell: &shm_schema::CellConfigV6, start_ns: u64, from: [f64; 3], to: [f64; 3]) -> Self {
        let t_acc = cell.t_acc_s;
        let cruise = (0..3)
            .map(|i| (to[i] - from[i]).abs() / cell.axis[i].vmax)
            .fold(t_acc, f64::max);
        Self {
            start_ns,
            from,
            to,
            t: cruise + t_acc,
            t_acc,
        }
    }

    fn end_ns(&self) -> u64 {
        self.start_ns + (self.t * 1e9) as u64
    }

    /// Its setpoint at `now_ns`.
    fn at(&self, seq: u64, now_ns: u64) -> SetpointV2 {
        let t = (now_ns.saturating_sub(self.start_ns) as f64 * 1e-9).min(self.t);
        let (ta, tt) = (self.t_acc, self.t);
        let mut sp = SetpointV2 {
            seq,
            stamp_ns: now_ns,
            axes: 3,
            state: MotionState::Moving as u32,
            ..SetpointV2::default()
        };
        for i in 0..3 {
            let v = (self.to[i] - self.from[i]) / (tt - ta);
            let a = v / ta;
            let (p, vel, acc) = if t < ta {
                (0.5 * a * t * t, a * t, a)
            } else if t < tt - ta {
                (0.5 * a * ta * ta + v * (t - ta), v, 0.0)
            } else if t < tt {
                let r = tt - t;
                (self.to[i] - self.from[i] - 0.5 * a * r * r, a * r, -a)
            } else {
                (self.to[i] - self.from[i], 0.0, 0.0)
            };
            sp.position[i] = self.from[i] + p;
            sp.velocity[i] = vel;
            sp.acceleration[i] = acc;
        }
        sp
    }
}

/// Runs trapezoids through `targets` from the default start, a setpoint each trajgen period
/// except while `silent(k)` (servo cycle k); fails on a latched fault. The largest change of
/// the commanded velocity per servo period over the run, per axis.
fn trapezoids(targets: &[[f64; 3]], silent: impl Fn(u64) -> bool) -> [f64; 3] {
    let cell = Config::default_cell().to_shm();
    let mut lp = Loop::enabled(&cell);
    let tg = cell.period_of("trajgen").expect("trajgen") / lp.period;
    let mut from = [40.0, 40.0, 0.0];
    let mut max_dv = [0.0f64; 3];
    let mut prev = lp.state;
    let mut seq = 0;
    let mut k = 0u64;
    for &to in targets {
        let move_ = Trapezoid::new(&cell, lp.now + 100_000 + tg * lp.period, from, to);
        // The move, then 100 ms at rest on its target.
        while lp.now < move_.end_ns() + 100 * MS {
            let sp = (k.is_multiple_of(tg) && !silent(k)).then(|| {
                seq += 1;
                move_.at(seq, lp.now + 100_000)
            });
            let s = lp.step_with(None, sp.as_ref(), None);
            assert_eq!(
                s.status & st::FAULT_LATCHED,
                0,
                "towards {to:?}, at {k}: {:?}",
                lp.events
                    .iter()
                    .rev()
                    .take(3)
                    .map(|e| (e.code, e.axis, e.value, e.limit, e.text()))
                    .collect::<Vec<_>>()
            );
            for (i, m) in max_dv.iter_mut().enumerate() {
                *m = m.max((s.cmd_velocity[i] - prev.cmd_velocity[i]).abs());
            }
            prev = s;
            k += 1;
        }
        // Followed to the end: every setpoint taken, the axes on the target.
        for (i, a) in lp.machine.axes().iter().enumerate().take(3) {
            assert!(
                (a.position - to[i]).abs() < 0.05,
                "axis {i} at {} towards {to:?}: {:?}",
                a.position,
                lp.codes()
            );
        }
        from = to;
    }
    for c in [
        code::SETPOINT_JUMP,
        code::SETPOINT_VELOCITY_JUMP,
        code::SETPOINT_STALE,
    ] {
        assert!(!lp.codes().contains(&c), "{:?}", lp.codes());
    }
    eprintln!("{k} servo cycles, {seq} setpoints; largest velocity steps {max_dv:?}");
    max_dv
}

#[test]
fn a_foreign_generators_trapezoids_within_the_limits_are_never_refused() {
    integration_tests::wall_clock(|| {
        // Issue 21's moves, then distances whose acceleration changes fall at every phase of
        // the 4-ms setpoints (0.1 ms apart), and a move of theta alone.
        let mut targets = vec![[140.0, 40.0, 0.0], [90.0, 126.0, 0.0], [40.0, 40.0, 0.0]];
        for j in 0..40 {
            let d = 8.0 + 0.0016 * f64::from(j) * 16.0;
            let last = *targets.last().expect("one");
            let x = if last[0] < 100.0 {
                last[0] + d
            } else {
                last[0] - d
            };
            targets.push([x, last[1] + if j % 2 == 0 { 1.0 } else { -1.0 }, 0.0]);
        }
        targets.push([40.0, 40.0, 90.0]);
        let cell = Config::default_cell().to_shm();
        // On time, and with the generator stalled 30 and 40 ms now and then (with the setpoint
        // before, below the 50 ms setpoint timeout), in its accelerations and its cruises.
        let stalled = |k: u64| matches!(k % 1700, 300..330 | 1000..1040);
        for (run, max_dv) in [
            ("on time", trapezoids(&targets, |_| false)),
            ("stalled", trapezoids(&targets, stalled)),
        ] {
            for (i, a) in cell.axes().iter().enumerate() {
                assert!(
                    max_dv[i] <= a.velocity_step_limit,
                    "{run}: axis {i}: velocity step {} over {}",
                    max_dv[i],
                    a.velocity_step_limit
                );
            }
        }
    });
}
