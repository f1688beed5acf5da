//! The instructions beyond MOVE/STOP/END in the generator: when an OUT takes effect relative
//! to the blend, WAIT and DELAY at rest, a WAIT's timeout, SPEED, the live override, MOVEJ,
//! and the prediction the supervisor makes with the same generator.

mod common;

use motion_core::generator::{Generator, Params};
use motion_core::predict::{Outcome, simulate};
use motion_program::CellSpec;
use shm_schema::motion::{hold, trajgen_fault};
use shm_schema::{ControlKind, MotionCommandV2, MotionControlV2, MotionState, SetpointV2};

const START: [f64; 3] = [40.0, 40.0, 0.0];
const T0: u64 = 1_000_000_000_000;
const MS: u64 = 1_000_000;
use common::T_ACC;

fn params() -> Params {
    common::gantry_params()
}

fn cell() -> CellSpec {
    let mut c = CellSpec::cartesian(&[("x", "mm"), ("y", "mm"), ("theta", "deg")]);
    c.outputs = vec![("gripper".into(), 1)];
    c.inputs = vec![("gripper_closed".into(), 2)];
    c
}

fn commands(src: &str) -> Vec<MotionCommandV2> {
    motion_program::parse(src.as_bytes(), &cell())
        .expect("parses")
        .commands(3)
        .collect()
}

fn loaded(src: &str) -> Generator {
    let mut g = Generator::new(params(), &START);
    for c in commands(src) {
        g.push_command(&c);
    }
    g
}

fn motion_s(now: u64) -> f64 {
    (now - T0) as f64 * 1e-9
}

#[test]
fn an_out_between_moves_takes_effect_at_the_look_ahead_while_the_axes_move() {
    // 100 mm at 16 mm/s: T1 = 6.25 s; the look-ahead reads OUT at T1 - t_acc of the first
    // segment, whose local time 0 is t_acc after the start: motion time 6.25 s exactly.
    let mut g = loaded("MOVE(140,40,0)\nOUT(gripper, 1)\nMOVE(140,140,0)\nEND");
    let mut set_at = None;
    let mut k = 0;
    while set_at.is_none() {
        let now = T0 + k * MS;
        let sp = g.step(now, Some(0));
        if let Some(o) = g.take_outputs() {
            assert_eq!((o.mask, o.values, o.line), (2, 2, 2));
            assert!(sp.velocity[0].abs() > 1.0, "moving: {:?}", sp.velocity);
            set_at = Some(motion_s(now));
        }
        if let Some(t) = g.next_transition_ns().filter(|t| *t < now + MS) {
            let sp = g.step(t, Some(0));
            if let Some(o) = g.take_outputs() {
                assert_eq!(o.mask, 2);
                assert!(sp.velocity[0].abs() > 1.0);
                set_at = Some(motion_s(t));
            }
        }
        k += 1;
    }
    let t = set_at.expect("set");
    assert!((t - 6.25).abs() < 1e-6, "{t}");
}

/// Runs `g` with 1 ms cycles and the transitions it asks for, the inputs given by
/// `inputs(motion time)`, until the program ends; returns every setpoint.
fn run(g: &mut Generator, inputs: impl Fn(f64) -> u64) -> Vec<SetpointV2> {
    let mut out = Vec::new();
    let mut now = T0;
    loop {
        let sp = g.step(now, Some(inputs(motion_s(now))));
        let state = sp.state;
        out.push(sp);
        if state != MotionState::Moving as u32 || now > T0 + 600_000 * MS {
            return out;
        }
        let next = now + MS;
        now = g
            .next_transition_ns()
            .filter(|t| *t > now && *t < next)
            .unwrap_or(next);
    }
}

#[test]
fn wait_holds_exactly_on_the_target_until_the_input_then_goes_on() {
    // The input arrives at motion time 20 s, long after the axes came to rest: the look-ahead
    // reads WAIT at 6.25 s (T1 - t_acc of the MOVE), the stop it implies ends 2 t_acc later.
    let src = "MOVE(140,40,0)\nWAIT(gripper_closed, 1)\nMOVE(140,140,0)\nEND";
    let mut g = loaded(src);
    let sps = run(&mut g, |t| if t >= 20.0 { 4 } else { 0 });
    let waiting: Vec<&SetpointV2> = sps.iter().filter(|s| s.hold == hold::WAIT).collect();
    let first = waiting.first().expect("waited");
    assert_eq!(first.hold_io, 2);
    assert_eq!(first.line, 2);
    assert!(
        waiting
            .iter()
            .all(|s| s.position[..3] == [140.0, 40.0, 0.0] && s.velocity[..3] == [0.0; 3]),
        "at rest on the target"
    );
    // It came to rest at 6.25 + 2 t_acc (the stop segment's end) and waited until 20 s.
    let rest = 6.25 + 2.0 * T_ACC;
    assert!(
        (first.motion_time_s - rest).abs() < 2e-3,
        "{}",
        first.motion_time_s
    );
    let done = sps.last().expect("done");
    assert_eq!(done.state, MotionState::Done as u32);
    assert!(
        (done.waited_s - (20.0 - rest)).abs() < 2e-3,
        "{}",
        done.waited_s
    );
    // The motion after the wait is the prediction's: total = predicted + waited.
    let predicted = simulate(params(), &START, commands(src), 0.004, 3600.0, &mut |_| {});
    assert_eq!(predicted.outcome, Outcome::Done);
    let motion = done.motion_time_s - done.waited_s;
    assert!(
        (motion - predicted.duration_s).abs() < 2e-3,
        "{motion} vs {}",
        predicted.duration_s
    );
}

#[test]
fn a_wait_that_times_out_is_a_program_fault_naming_its_line() {
    let mut g = loaded("MOVE(140,40,0)\nWAIT(gripper_closed, 1, 1.5)\nMOVE(140,140,0)\nEND");
    let sps = run(&mut g, |_| 0);
    let last = sps.last().expect("ended");
    assert_eq!(last.state, MotionState::Fault as u32);
    assert_eq!(
        (last.fault, last.fault_line),
        (trajgen_fault::WAIT_TIMEOUT, 2)
    );
    assert_eq!(
        &last.position[..3],
        &[140.0, 40.0, 0.0],
        "at rest where it waited"
    );
    assert!((last.waited_s - 1.5).abs() < 2e-3, "{}", last.waited_s);
}

#[test]
fn delay_holds_at_rest_for_its_time_and_counts_in_the_theoretical_time() {
    let src = "MOVE(140,40,0)\nDELAY(2.5)\nMOVE(40,40,0)\nEND";
    let plain = simulate(
        params(),
        &START,
        commands("MOVE(140,40,0)\nSTOP\nMOVE(40,40,0)\nEND"),
        0.004,
        3600.0,
        &mut |_| {},
    );
    let mut g = loaded(src);
    let sps = run(&mut g, |_| 0);
    let delayed: Vec<&SetpointV2> = sps.iter().filter(|s| s.hold == hold::DELAY).collect();
    let span = delayed.last().expect("held").motion_time_s - delayed[0].motion_time_s;
    assert!((span - 2.5).abs() < 2e-3, "{span}");
    assert!(delayed.iter().all(|s| s.velocity[..3] == [0.0; 3]));
    let done = sps.last().expect("done");
    // STOP and the stop a DELAY implies are the same segment: the DELAY adds its time.
    assert!((done.motion_time_s - plain.duration_s - 2.5).abs() < 2e-3);
    assert!((done.theoretical_s - plain.theoretical_s - 2.5).abs() < 1e-9);
}

#[test]
fn the_prediction_leaps_a_delay_and_ends_where_the_generator_stepping_through_it_does() {
    // Five minutes' DELAY between two moves: the generator stepped every millisecond, as
    // trajgen steps it, against the prediction, which goes from the DELAY's first step
    // straight to its end (nothing moves in between).
    let src = "MOVE(140,40,0)\nDELAY(300)\nMOVE(40,40,0)\nEND";
    let mut g = loaded(src);
    let stepped = run(&mut g, |_| 0);
    let done = stepped.last().expect("done");
    assert_eq!(done.state, MotionState::Done as u32);
    let mut seen: Vec<SetpointV2> = Vec::new();
    let p = simulate(params(), &START, commands(src), 0.001, 3600.0, &mut |sp| {
        seen.push(*sp)
    });
    assert_eq!(p.outcome, Outcome::Done);
    assert_eq!(p.duration_s, done.motion_time_s);
    assert_eq!(p.theoretical_s, done.theoretical_s);
    let last = seen.last().expect("setpoints");
    assert_eq!(last.position, done.position);
    // The setpoints are the stepped run's but for those inside the DELAY: each of the
    // prediction's is one of the run's, at the same time.
    let at: std::collections::HashMap<u64, &SetpointV2> = stepped
        .iter()
        .map(|s| (s.motion_time_s.to_bits(), s))
        .collect();
    for s in &seen {
        let twin = at
            .get(&s.motion_time_s.to_bits())
            .expect("a step of the run");
        assert_eq!((s.position, s.velocity), (twin.position, twin.velocity));
    }
    assert!(
        seen.len() * 10 < stepped.len(),
        "{} steps predicted, {} stepped",
        seen.len(),
        stepped.len()
    );
}

#[test]
fn speed_stretches_the_segment_times_that_follow() {
    let full = simulate(
        params(),
        &START,
        commands("MOVE(140,40,0)\nEND"),
        0.004,
        3600.0,
        &mut |_| {},
    );
    let half = simulate(
        params(),
        &START,
        commands("SPEED(50)\nMOVE(140,40,0)\nEND"),
        0.004,
        3600.0,
        &mut |_| {},
    );
    // 100 mm: 6.25 s at 16 mm/s, 12.5 s at 8 mm/s; the stop (2 t_acc) does not stretch.
    assert!((full.theoretical_s - (6.25 + 2.0 * T_ACC)).abs() < 1e-9);
    assert!(
        (half.theoretical_s - (12.5 + 2.0 * T_ACC)).abs() < 1e-9,
        "{}",
        half.theoretical_s
    );
    // A user's T stretches too.
    let t = simulate(
        params(),
        &START,
        commands("SPEED(50)\nMOVE(41,40,0, T=4)\nEND"),
        0.004,
        3600.0,
        &mut |_| {},
    );
    assert!(
        (t.theoretical_s - (8.0 + 2.0 * T_ACC)).abs() < 1e-9,
        "{}",
        t.theoretical_s
    );
}

#[test]
fn the_live_override_slows_the_path_without_leaving_it() {
    let src = "MOVE(140,40,0)\nMOVE(140,140,0)\nEND";
    let mut reference = loaded(src);
    let full = run(&mut reference, |_| 0);
    let mut g = loaded(src);
    let mut now = T0;
    let mut out = Vec::new();
    for k in 0.. {
        if k == 2000 {
            g.control(
                &MotionControlV2 {
                    seq: 1,
                    kind: ControlKind::Speed as u32,
                    reserved: 0,
                    value: 0.5,
                },
                now,
            );
        }
        let sp = g.step(now, Some(0));
        let state = sp.state;
        out.push(sp);
        if state != MotionState::Moving as u32 {
            break;
        }
        now += MS;
    }
    let done = out.last().expect("done");
    let base = full.last().expect("done");
    assert_eq!(&done.position[..3], &base.position[..3]);
    // From 2 s on the path runs at half speed: about (duration - 2) s longer, less the ramp.
    let extra = done.motion_time_s - base.motion_time_s;
    let rest = base.motion_time_s - 2.0;
    assert!((extra - rest).abs() < T_ACC, "{extra} vs {rest}");
    assert!(
        out.iter()
            .all(|s| s.speed_override == if s.control_seq == 1 { 0.5 } else { 1.0 })
    );
    let fastest = out[3000..]
        .iter()
        .map(|s| s.velocity[0].abs())
        .fold(0.0, f64::max);
    assert!(fastest <= 8.0 + 1e-9, "{fastest}");
    // Every point lies on the unslowed path (its x, y pairs).
    for s in out.iter().step_by(50) {
        let on = full.iter().any(|f| {
            (f.position[0] - s.position[0]).abs() < 0.02
                && (f.position[1] - s.position[1]).abs() < 0.02
        });
        assert!(on, "{:?} is off the path", &s.position[..2]);
    }
}

#[test]
fn movej_blends_in_joint_space_and_a_change_of_space_stops_between() {
    let p = simulate(
        params(),
        &START,
        commands("MOVE(140,40,0)\nMOVEJ(140,140,0)\nEND"),
        0.004,
        3600.0,
        &mut |_| {},
    );
    let blended = simulate(
        params(),
        &START,
        commands("MOVE(140,40,0)\nMOVE(140,140,0)\nEND"),
        0.004,
        3600.0,
        &mut |_| {},
    );
    // The change of space inserts an exact stop: the stop segment (2 t_acc) more.
    assert!((p.theoretical_s - blended.theoretical_s - 2.0 * T_ACC).abs() < 1e-9);
    let mut spaces = Vec::new();
    simulate(
        params(),
        &START,
        commands("MOVEJ(140,40,0)\nMOVEJ(140,140,0)\nEND"),
        0.004,
        3600.0,
        &mut |sp| spaces.push(sp.space),
    );
    assert!(
        spaces.iter().skip(1).all(|s| *s == 1),
        "joint space throughout"
    );
}

#[test]
fn the_prediction_is_the_generators_own_run() {
    let triangle = include_str!("../../examples/triangle.prog");
    let p = simulate(
        params(),
        &START,
        commands(triangle),
        0.004,
        3600.0,
        &mut |_| {},
    );
    assert_eq!(p.outcome, Outcome::Done);
    assert!((p.duration_s - 19.10).abs() < 1e-6, "{}", p.duration_s);
    assert!((p.theoretical_s - 19.10).abs() < 1e-9);
    // A target outside the limits is refused, as trajgen refuses it, naming the line.
    let bad = simulate(
        params(),
        &START,
        commands("MOVE(140,40,0)\nMOVE(140,400,0)\nEND"),
        0.004,
        3600.0,
        &mut |_| {},
    );
    assert_eq!(
        bad.outcome,
        Outcome::Fault {
            code: trajgen_fault::TARGET_OUT_OF_LIMITS,
            line: 2
        }
    );
    // A program longer than the limit is said so.
    let long = simulate(
        params(),
        &START,
        commands("DELAY(100)\nEND"),
        0.004,
        50.0,
        &mut |_| {},
    );
    assert_eq!(long.outcome, Outcome::TooLong);
}

#[test]
fn a_cartesian_blend_maps_to_continuous_joints_through_the_five_bar() {
    let (p, kin) = common::five_bar();
    let cell = CellSpec {
        coords: vec![("x".into(), "mm".into()), ("y".into(), "mm".into())],
        joints: vec![("a0".into(), "deg".into()), ("a1".into(), "deg".into())],
        ..CellSpec::default()
    };
    let src = "MOVE(-160,-120)\nMOVE(-235,-110)\nMOVE(-200,-190)\nMOVEJ(0,0)\nEND";
    let cmds: Vec<MotionCommandV2> = motion_program::parse(src.as_bytes(), &cell)
        .expect("parses")
        .commands(1)
        .collect();
    let g = Generator::with_kinematics(p, Some(kin.clone()), &[0.0, 0.0]);
    let mut trace: Vec<SetpointV2> = Vec::new();
    let pr = motion_core::predict::simulate_with(g, cmds, 0.001, 600.0, &mut |sp| trace.push(*sp));
    assert_eq!(pr.outcome, Outcome::Done, "{:?}", pr.kin_error);
    let mut cartesian_steps = 0;
    for w in trace.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let dt = (b.stamp_ns - a.stamp_ns) as f64 * 1e-9;
        if dt <= 0.0 {
            continue;
        }
        for i in 0..2 {
            // Continuous joints, within their vmax, their velocity the derivative of their
            // position (the mean of the two ends, to second order).
            let dq = b.position[i] - a.position[i];
            assert!(
                dq.abs() <= 30.0 * dt * (1.0 + 1e-6) + 1e-9,
                "joint {i} jumps {dq} in {dt} s"
            );
            let mean_v = (a.velocity[i] + b.velocity[i]) / 2.0;
            assert!(
                (dq / dt - mean_v).abs() < 0.05,
                "joint {i}: {} vs {mean_v}",
                dq / dt
            );
            assert!((-40.0..=40.0).contains(&b.position[i]));
        }
        // The Cartesian half is the forward kinematics of the joint half.
        let mut q = [0.0; kinematics::MAX_JOINTS];
        q[..2].copy_from_slice(&b.position[..2]);
        let c = kin.0.axes_to_cartesian(&q).expect("forward");
        assert!((c[0] - b.cartesian[0]).abs() < 1e-6 && (c[1] - b.cartesian[1]).abs() < 1e-6);
        cartesian_steps += usize::from(b.space == 0);
    }
    assert!(cartesian_steps > 1000);
    // Ends where MOVEJ(0, 0) put it: the null posture, tool at (-200, -150).
    let last = trace.last().expect("done");
    assert!(last.position[..2].iter().all(|v| v.abs() < 1e-9));
    assert!((last.cartesian[0] + 200.0).abs() < 1e-6 && (last.cartesian[1] + 150.0).abs() < 1e-6);
}

#[test]
fn a_path_that_leaves_the_workspace_is_refused_by_the_prediction_with_its_reason() {
    let (p, kin) = common::five_bar();
    let cell = CellSpec {
        coords: vec![("x".into(), "mm".into()), ("y".into(), "mm".into())],
        joints: vec![("a0".into(), "deg".into()), ("a1".into(), "deg".into())],
        ..CellSpec::default()
    };
    // (-400, -150) is beyond every link's reach.
    let cmds: Vec<MotionCommandV2> =
        motion_program::parse(b"MOVE(-180,-140)\nMOVE(-400,-150)\nEND", &cell)
            .expect("parses")
            .commands(1)
            .collect();
    let g = Generator::with_kinematics(p, Some(kin), &[0.0, 0.0]);
    let pr = motion_core::predict::simulate_with(g, cmds, 0.004, 600.0, &mut |_| {});
    assert_eq!(
        pr.outcome,
        Outcome::Fault {
            code: trajgen_fault::UNREACHABLE,
            line: 2
        }
    );
    assert!(pr.kin_error.is_some());
}

fn control(seq: u64, kind: ControlKind) -> MotionControlV2 {
    MotionControlV2 {
        seq,
        kind: kind as u32,
        reserved: 0,
        value: 0.0,
    }
}

#[test]
fn an_abort_that_ends_at_the_programs_end_does_not_carry_over_to_the_next_program() {
    // Abort in the last moments before END (the move and its stop take 4 t_acc; the ramp to
    // rest covers t_acc / 2 of path): the program reaches END while the speed ramps down.
    let mut g = loaded("MOVE(41,40,0)\nEND");
    let mut now = T0;
    let mut sp = g.step(now, Some(0));
    while sp.motion_time_s < 4.0 * T_ACC - 0.15 {
        now += MS;
        sp = g.step(now, Some(0));
    }
    g.control(&control(1, ControlKind::Abort), now);
    while sp.state == MotionState::Moving as u32 {
        now += MS;
        sp = g.step(now, Some(0));
    }
    assert_eq!(
        sp.state,
        MotionState::Done as u32,
        "END came before the abort's rest"
    );
    // The next program: a pause is a pause (not an abort), a resume goes on to its end.
    let cmds = motion_program::parse(b"MOVE(60,40,0)\nEND", &cell())
        .expect("parses")
        .commands(4)
        .collect::<Vec<_>>();
    for c in &cmds {
        g.push_command(c);
    }
    for _ in 0..500 {
        now += MS;
        g.step(now, Some(0));
    }
    g.control(&control(2, ControlKind::Pause), now);
    for _ in 0..2000 {
        now += MS;
        sp = g.step(now, Some(0));
    }
    assert_eq!(sp.state, MotionState::Moving as u32, "paused, not dropped");
    assert_eq!(sp.fault, trajgen_fault::NONE);
    g.control(&control(3, ControlKind::Resume), now);
    while sp.state == MotionState::Moving as u32 && now < T0 + 60_000 * MS {
        now += MS;
        sp = g.step(now, Some(0));
    }
    assert_eq!(sp.state, MotionState::Done as u32);
    assert_eq!(&sp.position[..3], &[60.0, 40.0, 0.0]);
}

#[test]
fn a_new_session_ends_a_program_its_client_left_and_starts_afresh() {
    // A program without END is left by its client (starved at rest); a new one arrives.
    let mut g = Generator::new(params(), &START);
    for c in commands("MOVE(50,40,0)\nEND").iter().take(1) {
        g.push_command(c);
    }
    let mut now = T0;
    for _ in 0..3000 {
        now += MS;
        g.step(now, Some(0));
    }
    let cmds = motion_program::parse(b"MOVE(60,40,0)\nEND", &cell())
        .expect("parses")
        .commands(9)
        .collect::<Vec<_>>();
    for c in &cmds {
        g.push_command(c);
    }
    let mut sp = g.step(now, Some(0));
    assert_eq!(sp.program_id, 9, "the new program, from its own start");
    while sp.state == MotionState::Moving as u32 && now < T0 + 60_000 * MS {
        now += MS;
        sp = g.step(now, Some(0));
    }
    assert_eq!(sp.state, MotionState::Done as u32);
    assert_eq!(sp.starved, 0);
    assert_eq!(&sp.position[..3], &[60.0, 40.0, 0.0]);
}

#[test]
fn a_pause_or_an_abort_sent_with_the_first_commands_is_not_lost() {
    // Paused before it began: it starts at rest, paused, and goes on when resumed.
    let mut g = Generator::new(params(), &START);
    for c in commands("MOVE(60,40,0)\nEND") {
        g.push_command(&c);
    }
    g.control(&control(1, ControlKind::Pause), T0);
    let mut now = T0;
    let mut sp = g.step(now, Some(0));
    for _ in 0..2000 {
        now += MS;
        sp = g.step(now, Some(0));
    }
    assert_eq!(sp.state, MotionState::Moving as u32);
    assert!(
        sp.path_speed == 0.0 && (sp.position[0] - 40.0).abs() < 0.1,
        "{:?}",
        &sp.position[..3]
    );
    g.control(&control(2, ControlKind::Resume), now);
    while sp.state == MotionState::Moving as u32 && now < T0 + 60_000 * MS {
        now += MS;
        sp = g.step(now, Some(0));
    }
    assert_eq!(sp.state, MotionState::Done as u32);
    // Aborted before it began: dropped at once under its own program id, nothing moved.
    let mut g = Generator::new(params(), &START);
    for c in commands("MOVE(60,40,0)\nEND") {
        g.push_command(&c);
    }
    g.control(&control(1, ControlKind::Abort), T0);
    let sp = g.step(T0, Some(0));
    assert_eq!(
        (sp.state, sp.fault, sp.program_id),
        (MotionState::Fault as u32, trajgen_fault::ABORTED, 3)
    );
    assert_eq!(&sp.position[..3], &START);
}
