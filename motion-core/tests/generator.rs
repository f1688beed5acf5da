//! The generator against the formula, with regular, late and exact cycles.

mod common;

use motion_core::blend::{Axes, Segment};
use motion_core::generator::{Generator, Params};
use motion_program::{CellSpec, Op, Program, parse, segment_time};
use shm_schema::motion::trajgen_fault;
use shm_schema::{MotionCommandV2, MotionState, SetpointV2};

const TRIANGLE: &str = include_str!("../../examples/triangle.prog");
const START: [f64; 3] = [40.0, 40.0, 0.0];
const T0: u64 = 1_000_000_000_000; // an arbitrary CLOCK_MONOTONIC origin

fn params() -> Params {
    common::gantry_params()
}

fn commands(src: &str) -> Vec<MotionCommandV2> {
    program(src).commands(7).collect()
}

fn program(src: &str) -> Program {
    let cell = CellSpec::cartesian(&[("x", "mm"), ("y", "mm"), ("theta", "deg")]);
    parse(src.as_bytes(), &cell).expect("program parses")
}

/// The theoretical duration of a straight program (MOVE, STOP, END) from `START`, summed
/// independently of the generator: each MOVE and STOP is one segment; END adds a stopping
/// segment unless the axes are already coming to rest on the last target.
fn planned(src: &str) -> f64 {
    let (vmax, t_acc) = (params().vmax, params().t_acc);
    let mut b = START.to_vec();
    let (mut total, mut moving, mut resting) = (0.0, false, true);
    for ins in &program(src).instructions {
        match &ins.op {
            Op::Move {
                target,
                user_time_s,
                ..
            } => {
                total += segment_time(
                    &b,
                    &target[..3],
                    &vmax[..3],
                    t_acc,
                    user_time_s.unwrap_or(0.0),
                );
                resting = b[..] == target[..3];
                b.copy_from_slice(&target[..3]);
                moving = true;
            }
            Op::Stop if moving => {
                total += 2.0 * t_acc;
                resting = true;
            }
            Op::End if moving && !resting => total += 2.0 * t_acc,
            _ => {}
        }
    }
    total
}

fn loaded(src: &str) -> Generator {
    let mut g = Generator::new(params(), &START);
    for c in commands(src) {
        g.push_command(&c);
    }
    g
}

/// The trajectory of the triangle built offline, straight from seed 003 §2: each segment's
/// local time 0 lies T1 after the previous one's; (motion time of local 0, segment).
fn offline_triangle() -> Vec<(f64, Segment)> {
    let p = params();
    let pts: [[f64; 3]; 5] = [
        [40.0, 40.0, 0.0],
        [140.0, 40.0, 0.0],
        [90.0, 126.0, 0.0],
        [40.0, 40.0, 0.0],
        [40.0, 40.0, 0.0],
    ];
    let ax = |v: &[f64; 3]| {
        let mut a = Axes::zeros();
        a.as_mut_slice()[..3].copy_from_slice(v);
        a
    };
    let mut out: Vec<(f64, Segment)> = Vec::new();
    let mut b = ax(&START);
    let mut a = b;
    let mut origin = p.t_acc;
    for c in &pts {
        let t1 = motion_program::segment_time(&b.as_slice()[..3], c, &p.vmax[..3], p.t_acc, 0.0);
        let s = Segment {
            a,
            b,
            c: ax(c),
            t1,
            t_acc: p.t_acc,
        };
        out.push((origin, s));
        a = s.eval(s.transition_time()).0;
        b = s.c;
        origin += t1;
    }
    out
}

fn formula_at(plan: &[(f64, Segment)], mt: f64) -> (Axes, Axes) {
    let (o, s) = plan
        .iter()
        .rev()
        .find(|(o, s)| mt >= o - s.t_acc)
        .copied()
        .unwrap_or(plan[0]);
    s.eval(mt - o)
}

fn run(g: &mut Generator, times: impl Iterator<Item = u64>) -> Vec<SetpointV2> {
    let mut out = Vec::new();
    for t in times {
        let sp = g.step(t, None);
        let done = sp.state != MotionState::Moving as u32;
        out.push(sp);
        if done && out.len() > 1 {
            break;
        }
    }
    out
}

fn assert_close(a: &[f64], b: &[f64], tol: f64, what: &str) {
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!((x - y).abs() <= tol, "{what}: axis {i}: {x} vs {y}");
    }
}

#[test]
fn triangle_setpoints_equal_the_formula_at_their_time() {
    let plan = offline_triangle();
    let mut g = loaded(TRIANGLE);
    let sps = run(&mut g, (0..).map(|k| T0 + k * 4_000_000));
    let first = sps[0];
    assert_eq!(first.motion_start_ns, T0);
    for sp in &sps {
        let mt = (sp.stamp_ns - T0) as f64 * 1e-9;
        if sp.state != MotionState::Moving as u32 {
            continue;
        }
        let (q, v) = formula_at(&plan, mt);
        assert_close(&sp.position[..3], &q.as_slice()[..3], 1e-9, "position");
        assert_close(&sp.velocity[..3], &v.as_slice()[..3], 1e-9, "velocity");
        assert!((sp.motion_time_s - mt).abs() < 1e-12);
    }
    let last = sps.last().expect("setpoints");
    assert_eq!(last.state, MotionState::Done as u32);
    assert!(
        (last.theoretical_s - 19.10).abs() < 1e-9,
        "{}",
        last.theoretical_s
    );
    let measured = (last.motion_end_ns - last.motion_start_ns) as f64 * 1e-9;
    assert!(
        (19.10 - 1e-9..19.10 + 0.004).contains(&measured),
        "measured {measured}"
    );
    assert_eq!(&last.position[..3], &START[..]);
    assert_eq!(&last.velocity[..3], &[0.0; 3][..]);
    // The program's line numbers are reported as the motion goes.
    assert!(sps.iter().any(|s| s.line == 6) && sps.iter().any(|s| s.line == 5));
}

#[test]
fn late_cycles_shorten_nothing_and_lengthen_nothing() {
    let plan = offline_triangle();
    // Irregular wake-ups: 1..9 ms, with a 300 ms stall in the middle of a blend zone and
    // another across a segment transition.
    let mut times = Vec::new();
    let mut t = T0;
    let mut k = 0u64;
    while t < T0 + 21_000_000_000 {
        times.push(t);
        k += 1;
        t += 1_000_000 + (k * 7_919 % 8) * 1_000_000;
        if k == 1500 || k == 2500 {
            t += 300_000_000;
        }
    }
    let mut g = loaded(TRIANGLE);
    let sps = run(&mut g, times.into_iter());
    for sp in sps.iter().filter(|s| s.state == MotionState::Moving as u32) {
        let (q, _) = formula_at(&plan, (sp.stamp_ns - T0) as f64 * 1e-9);
        assert_close(
            &sp.position[..3],
            &q.as_slice()[..3],
            1e-9,
            "position after late cycles",
        );
    }
    let last = sps.last().expect("setpoints");
    assert!((last.theoretical_s - 19.10).abs() < 1e-9);
    let measured = (last.motion_end_ns - T0) as f64 * 1e-9;
    // It ends at the first wake-up at or after 19.10 s, whatever happened before.
    assert!(
        (19.10 - 1e-9..=19.10 + 0.010).contains(&measured),
        "{measured}"
    );
}

#[test]
fn waking_at_the_requested_transitions_ends_exactly_on_time() {
    let mut g = loaded(TRIANGLE);
    let mut now = T0;
    let mut last = g.step(now, None);
    let period = 4_000_000;
    let mut transitions = 0;
    while last.state == MotionState::Moving as u32 {
        let grid = now + period;
        now = match g.next_transition_ns() {
            Some(t) if t < grid => {
                transitions += 1;
                t
            }
            _ => grid,
        };
        last = g.step(now, None);
    }
    assert!(transitions >= 4, "{transitions}");
    let measured = (last.motion_end_ns - T0) as f64 * 1e-9;
    assert!((measured - 19.10).abs() < 2e-9, "{measured}");
}

#[test]
fn theoretical_time_of_the_generator_matches_the_planner() {
    for src in [
        TRIANGLE,
        "MOVE(100,100,90)\nEND",
        "MOVE(50,50,0, T=9)\nMOVE(60,50,0)\nMOVE(60,50,0)\nEND",
    ] {
        let mut g = loaded(src);
        let sps = run(&mut g, (0..).map(|k| T0 + k * 1_000_000));
        let expected = planned(src);
        let last = sps.last().expect("setpoints");
        assert_eq!(last.state, MotionState::Done as u32, "{src}");
        assert!(
            (last.theoretical_s - expected).abs() < 1e-9,
            "{src}: {} vs {expected}",
            last.theoretical_s
        );
    }
}

#[test]
fn an_empty_queue_stops_the_axes_exactly_on_the_target_and_waits() {
    let mut g = Generator::new(params(), &START);
    let cmds = commands("MOVE(100,40,0)\nMOVE(100,100,0)\nEND");
    g.push_command(&cmds[0]);
    let sps = run(&mut g, (0..12_000).map(|k| T0 + k * 1_000_000));
    let last = sps.last().expect("setpoints");
    assert_eq!(last.state, MotionState::Moving as u32);
    assert_eq!(last.starved, 1);
    assert_eq!(&last.position[..3], &[100.0, 40.0, 0.0][..]);
    assert_eq!(&last.velocity[..3], &[0.0; 3][..]);
    // The rest of the program arrives late; the motion resumes from rest and completes.
    g.push_command(&cmds[1]);
    g.push_command(&cmds[2]);
    let sps = run(&mut g, (12_000..30_000).map(|k| T0 + k * 1_000_000));
    let last = sps.last().expect("setpoints");
    assert_eq!(last.state, MotionState::Done as u32);
    assert_eq!(&last.position[..3], &[100.0, 100.0, 0.0][..]);
}

#[test]
fn a_repeated_target_stops_exactly_on_the_point() {
    let mut g = loaded("MOVE(100,40,0)\nMOVE(100,40,0)\nMOVE(100,100,0)\nEND");
    let t_first = 60.0 / 16.0; // segment 1 (T1)
    let mut at_rest = None;
    for k in 0..20_000u64 {
        let sp = g.step(T0 + k * 1_000_000, None);
        // During the repeated-target segment the axes reach the point and rest.
        let mt = k as f64 * 1e-3;
        if (mt - (t_first + 0.525 * 2.0)).abs() < 0.0005 {
            at_rest = Some(sp);
        }
    }
    // At the instant the repeated-target segment ends the axes are on the point and at
    // rest (to rounding: the quartic's velocity there is O(1e-29)).
    let sp = at_rest.expect("sampled");
    assert_close(
        &sp.position[..3],
        &[100.0, 40.0, 0.0],
        1e-12,
        "position at the point",
    );
    assert_close(&sp.velocity[..3], &[0.0; 3], 1e-12, "velocity at the point");
}

fn fault_of(src_cmds: Vec<MotionCommandV2>) -> (SetpointV2, Generator) {
    let mut g = Generator::new(params(), &START);
    for c in &src_cmds {
        g.push_command(c);
    }
    let sps = run(&mut g, (0..40_000).map(|k| T0 + k * 1_000_000));
    (*sps.last().expect("setpoints"), g)
}

#[test]
fn refused_commands_fault_and_nothing_moves_beyond_the_current_target() {
    // Out of limits (y = 500) in a program queued whole: nothing moves at all.
    let mut cmds = commands("MOVE(100,40,0)\nMOVE(100,140,0)\nEND");
    cmds[1].target[1] = 500.0;
    let (sp, _) = fault_of(cmds.clone());
    assert_eq!(sp.fault, trajgen_fault::TARGET_OUT_OF_LIMITS);
    assert_eq!(sp.fault_line, 2);
    assert_eq!(sp.state, MotionState::Fault as u32);
    assert_eq!(&sp.position[..3], &START[..], "nothing moved");

    // The same command arriving mid-motion: the axes stop exactly on the current target.
    let mut g = Generator::new(params(), &START);
    g.push_command(&cmds[0]);
    run(&mut g, (0..1000).map(|k| T0 + k * 1_000_000));
    g.push_command(&cmds[1]);
    let sps = run(&mut g, (1000..40_000).map(|k| T0 + k * 1_000_000));
    let sp = sps.last().expect("setpoints");
    assert_eq!(
        (sp.fault, sp.state),
        (
            trajgen_fault::TARGET_OUT_OF_LIMITS,
            MotionState::Fault as u32
        )
    );
    assert_eq!(
        &sp.position[..3],
        &[100.0, 40.0, 0.0][..],
        "stopped on the last good target"
    );
    assert_eq!(sp.starved, 0, "a fault stop is not starvation");

    let mut cmds = commands("MOVE(100,40,0)\nEND");
    cmds[1].seq = 5;
    assert_eq!(fault_of(cmds).0.fault, trajgen_fault::SEQUENCE_GAP);

    let mut cmds = commands("MOVE(100,40,0)\nEND");
    cmds[0].count = 2;
    let (sp, _) = fault_of(cmds);
    assert_eq!(sp.fault, trajgen_fault::AXES_MISMATCH);
    assert_eq!(&sp.position[..3], &START[..], "nothing moved");

    let mut cmds = commands("MOVE(100,40,0)\nEND");
    cmds[0].target[2] = f64::NAN;
    assert_eq!(fault_of(cmds).0.fault, trajgen_fault::BAD_COMMAND);

    // A new session (seq 1) clears the fault and runs.
    let (_, mut g) = fault_of({
        let mut c = commands("MOVE(100,40,0)\nEND");
        c[0].count = 1;
        c
    });
    for c in commands("MOVE(60,40,0)\nEND") {
        g.push_command(&c);
    }
    let sps = run(&mut g, (40_000..80_000).map(|k| T0 + k * 1_000_000));
    let last = sps.last().expect("setpoints");
    assert_eq!(last.fault, 0);
    assert_eq!(last.state, MotionState::Done as u32);
    assert_eq!(&last.position[..3], &[60.0, 40.0, 0.0][..]);
}

#[test]
fn queue_overflow_is_refused_not_lost_silently() {
    let mut g = Generator::new(params(), &START);
    let mut cmds = Vec::new();
    for i in 0..(motion_core::generator::QUEUE_CAP as u64 + 1) {
        let mut c = commands("MOVE(50,50,0)\nEND")[0];
        c.seq = i + 1;
        cmds.push(c);
    }
    for c in &cmds {
        g.push_command(c);
    }
    assert_eq!(g.step(T0, None).fault, trajgen_fault::QUEUE_OVERFLOW);
}

fn control(seq: u64, kind: shm_schema::ControlKind) -> shm_schema::MotionControlV2 {
    shm_schema::MotionControlV2 {
        seq,
        kind: kind as u32,
        reserved: 0,
        value: 0.0,
    }
}

/// Distance of `p` from the offline path: the nearest of its samples (1 ms apart).
fn off_path(plan: &[(f64, Segment)], p: &[f64]) -> f64 {
    (0..20_000)
        .map(|k| {
            let q = formula_at(plan, k as f64 * 1e-3).0;
            (0..3).map(|i| (q[i] - p[i]).powi(2)).sum::<f64>().sqrt()
        })
        .fold(f64::INFINITY, f64::min)
}

/// The next cycle after `t` with trajgen's 4 ms period, or the exact instant the generator
/// asks for, whichever comes first (as the process does).
fn next_wake(g: &Generator, t: u64) -> u64 {
    let period = 4_000_000u64;
    g.next_transition_ns()
        .filter(|w| *w > t)
        .map_or(t + period, |w| w.min(t + period))
}

#[test]
fn a_pause_comes_to_rest_on_the_path_within_t_acc_and_resume_goes_on_along_it() {
    let plan = offline_triangle();
    let mut g = loaded(TRIANGLE);
    let mut t = T0;
    let mut trace = Vec::new();
    // Into the first blend zone, then pause.
    while t < T0 + 6_500_000_000 {
        trace.push(g.step(t, None));
        t = next_wake(&g, t);
    }
    g.control(&control(1, shm_schema::ControlKind::Pause), t);
    let paused_at = t;
    let mut rest_at = None;
    while t < paused_at + 3_000_000_000 {
        let sp = g.step(t, None);
        assert_eq!(sp.state, MotionState::Moving as u32, "a pause is no end");
        assert_eq!(sp.control_seq, 1);
        if rest_at.is_none() && sp.velocity[..3].iter().all(|v| *v == 0.0) {
            rest_at = Some(t);
        }
        trace.push(sp);
        t = next_wake(&g, t);
    }
    let rest_at = rest_at.expect("the axes come to rest");
    let t_acc_ns = (params().t_acc * 1e9) as u64;
    assert!(
        rest_at - paused_at <= t_acc_ns + 1,
        "rest {} ms after the pause, t_acc {} ms",
        (rest_at - paused_at) / 1_000_000,
        t_acc_ns / 1_000_000
    );
    assert!(g.paused());
    g.control(&control(2, shm_schema::ControlKind::Resume), t);
    loop {
        let sp = g.step(t, None);
        trace.push(sp);
        if sp.state == MotionState::Done as u32 {
            break;
        }
        t = next_wake(&g, t);
        assert!(t < T0 + 60_000_000_000, "the program ends");
    }
    let done = trace.last().expect("setpoints");
    // The motion took longer by the pause (3 s, less what the ramps travelled), never less.
    let theoretical = done.theoretical_s;
    assert!(done.motion_time_s > theoretical + 2.0 && done.motion_time_s < theoretical + 3.1);
    // Every reference lies on the offline path (what a pause changes is when, not where).
    for sp in trace.iter().step_by(20) {
        let d = off_path(&plan, &sp.position[..3]);
        assert!(d < 0.02, "{:?} is {d} mm off the path", &sp.position[..3]);
    }
    assert_close(&done.position[..3], &START, 1e-9, "ends on the last target");
    // What servo sees: each setpoint extrapolated with its acceleration meets the next one's
    // velocity (no velocity step beyond servo's default limit, 3·vmax/t_acc per ms).
    for w in trace.windows(2) {
        let dt = (w[1].stamp_ns - w[0].stamp_ns) as f64 * 1e-9;
        for i in 0..3 {
            let expected = w[0].velocity[i] + w[0].acceleration[i] * dt;
            let step = (w[1].velocity[i] - expected).abs();
            let limit = 3.0 * params().vmax[i] / params().t_acc * 1e-3;
            assert!(
                step < limit / 4.0,
                "axis {i} at {:.4} s: velocity step {step} (limit {limit})",
                (w[1].stamp_ns - T0) as f64 * 1e-9
            );
        }
    }
}

#[test]
fn an_abort_comes_to_rest_on_the_path_and_drops_the_program() {
    let plan = offline_triangle();
    let mut g = loaded(TRIANGLE);
    let mut t = T0;
    while t < T0 + 3_000_000_000 {
        g.step(t, None);
        t += 1_000_000;
    }
    g.control(&control(1, shm_schema::ControlKind::Abort), t);
    // A resume cannot undo an abort.
    g.control(&control(2, shm_schema::ControlKind::Resume), t);
    let mut last = g.step(t, None);
    for _ in 0..2000 {
        t += 1_000_000;
        last = g.step(t, None);
    }
    assert_eq!(last.state, MotionState::Fault as u32);
    assert_eq!(last.fault, trajgen_fault::ABORTED);
    assert!(last.velocity[..3].iter().all(|v| *v == 0.0));
    assert!(off_path(&plan, &last.position[..3]) < 0.02);
    // A new program starts from where the abort left the axes.
    let mut cmds = commands("MOVE(100, 100, 0)\nEND\n");
    for c in &mut cmds {
        c.program_id = 9;
    }
    for c in &cmds {
        g.push_command(c);
    }
    let sp = g.step(t + 1_000_000, None);
    assert_eq!(sp.state, MotionState::Moving as u32);
    assert_eq!(sp.fault, trajgen_fault::NONE);
    assert_close(
        &sp.position[..3],
        &last.position[..3],
        1e-6,
        "starts where it rested",
    );
}

#[test]
fn a_successor_goes_on_from_a_paused_motion_along_the_same_path() {
    let plan = offline_triangle();
    let cmds = commands(TRIANGLE);
    let mut g = loaded(TRIANGLE);
    let mut t = T0;
    // Pause inside the second segment's blend zone.
    while t < T0 + 7_000_000_000 {
        g.step(t, None);
        t = next_wake(&g, t);
    }
    g.control(&control(1, shm_schema::ControlKind::Pause), t);
    while !g.paused() {
        g.step(t, None);
        t = next_wake(&g, t);
    }
    let last_old = g.step(t, None);
    let h = g.handover(t).expect("paused on a segment");
    assert_eq!(h.valid, 1);
    // The old process goes; a new one starts 300 ms later from the record alone.
    t += 300_000_000;
    let mut n = Generator::resume_from(params(), None, &h, t, &last_old.position[..3]);
    let first = n.step(t, None);
    assert_close(
        &first.position[..3],
        &last_old.position[..3],
        1e-9,
        "same point",
    );
    assert!(
        first.velocity[..3].iter().all(|v| *v == 0.0),
        "still paused"
    );
    assert_eq!(first.program_id, last_old.program_id);
    for c in cmds.iter().filter(|c| c.seq > h.command_seq) {
        n.push_command(c);
    }
    assert_eq!(
        n.step(t, None).fault,
        trajgen_fault::NONE,
        "the commands after it are taken"
    );
    n.control(&control(2, shm_schema::ControlKind::Resume), t);
    let mut trace = Vec::new();
    loop {
        let sp = n.step(t, None);
        trace.push(sp);
        if sp.state == MotionState::Done as u32 {
            break;
        }
        t = next_wake(&n, t);
        assert!(t < T0 + 60_000_000_000, "the program ends");
    }
    for sp in trace.iter().step_by(20) {
        let d = off_path(&plan, &sp.position[..3]);
        assert!(d < 0.02, "{:?} is {d} mm off the path", &sp.position[..3]);
    }
    let done = trace.last().expect("done");
    assert_close(&done.position[..3], &START, 1e-9, "ends on the last target");
    let theoretical = planned(TRIANGLE);
    assert!(
        (done.theoretical_s - theoretical).abs() < 1e-9,
        "the same segments"
    );
    // The motion time grew by the pause and the 300 ms gap, no more.
    let extra = done.motion_time_s - done.theoretical_s;
    assert!(extra > 0.3 && extra < 0.3 + 2.0 * params().t_acc, "{extra}");
}
