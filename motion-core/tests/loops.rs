//! A program's loops in the prediction: iterations that begin alike are passed over
//! (`simulate_program`), and what is predicted is what running every iteration predicts.

mod common;

use motion_core::generator::{Generator, Kin, Params};
use motion_core::predict::{Outcome, Prediction, simulate_program, simulate_while};
use motion_program::{CellSpec, Commands};
use shm_schema::{MAX_AXES, SetpointV2};
use std::sync::Arc;

const DT: f64 = 0.001;

fn gantry() -> CellSpec {
    let mut c = CellSpec::cartesian(&[("x", "mm"), ("y", "mm"), ("theta", "deg")]);
    c.outputs = vec![("gripper".into(), 1)];
    c.inputs = vec![("gripper_closed".into(), 2)];
    c
}

/// The five-bar of seed 004 and its cell's names.
fn five_bar() -> (Params, Kin, CellSpec) {
    let (p, kin) = common::five_bar();
    let cell = CellSpec {
        coords: vec![("x".into(), "mm".into()), ("y".into(), "mm".into())],
        joints: vec![("a0".into(), "deg".into()), ("a1".into(), "deg".into())],
        ..CellSpec::default()
    };
    (p, kin, cell)
}

/// The envelope of a run: per axis the lowest and highest position and the fastest speed.
#[derive(Debug)]
struct Envelope {
    lo: [f64; MAX_AXES],
    hi: [f64; MAX_AXES],
    speed: [f64; MAX_AXES],
}

impl Envelope {
    fn new() -> Self {
        Self {
            lo: [f64::INFINITY; MAX_AXES],
            hi: [f64::NEG_INFINITY; MAX_AXES],
            speed: [0.0; MAX_AXES],
        }
    }
    fn add(&mut self, sp: &SetpointV2) {
        for i in 0..sp.axes as usize {
            self.lo[i] = self.lo[i].min(sp.position[i]);
            self.hi[i] = self.hi[i].max(sp.position[i]);
            self.speed[i] = self.speed[i].max(sp.velocity[i].abs());
        }
    }
}

/// The program predicted both ways: every iteration run, and alike ones passed over.
fn both(
    src: &str,
    spec: &CellSpec,
    make: &dyn Fn() -> Generator,
    max_s: f64,
) -> ((Prediction, Envelope), (Prediction, Envelope)) {
    let program = Arc::new(motion_program::parse(src.as_bytes(), spec).expect("parses"));
    let mut all = Envelope::new();
    let full = simulate_while(
        make(),
        Commands::new(program.clone(), 1),
        DT,
        max_s,
        &mut |sp| all.add(sp),
        &|| true,
    );
    let mut some = Envelope::new();
    let fast = simulate_program(
        make(),
        Commands::new(program, 1),
        DT,
        max_s,
        &mut |sp| some.add(sp),
        &|| true,
    );
    ((full, all), (fast, some))
}

/// What both ways predict is the same: the outcome, the motion and theoretical times, every
/// output (its line, bits, and time within a step), and the envelope of the path (within what
/// a step moves).
fn assert_same(src: &str, full: &(Prediction, Envelope), fast: &(Prediction, Envelope), vmax: f64) {
    let ((f, fe), (s, se)) = (full, fast);
    assert_eq!(f.outcome, s.outcome, "{src}");
    assert!(
        (f.duration_s - s.duration_s).abs() < 1e-6,
        "{src}: {} vs {}",
        f.duration_s,
        s.duration_s
    );
    assert!(
        (f.theoretical_s - s.theoretical_s).abs() < 1e-6,
        "{src}: {} vs {}",
        f.theoretical_s,
        s.theoretical_s
    );
    assert_eq!(f.outputs.len(), s.outputs.len(), "{src}");
    for (a, b) in f.outputs.iter().zip(&s.outputs) {
        assert_eq!(
            (a.line, a.mask, a.values),
            (b.line, b.mask, b.values),
            "{src}"
        );
        assert!(
            (a.t_s - b.t_s).abs() <= DT + 1e-6,
            "{src}: output at {} vs {}",
            a.t_s,
            b.t_s
        );
    }
    for i in 0..MAX_AXES {
        if fe.lo[i].is_finite() {
            let near = |a: f64, b: f64| (a - b).abs() <= vmax * DT;
            assert!(
                near(fe.lo[i], se.lo[i]) && near(fe.hi[i], se.hi[i]),
                "{src}: {fe:?} vs {se:?}"
            );
            assert!(
                (fe.speed[i] - se.speed[i]).abs() <= 1e-3 * vmax,
                "{src}: {fe:?} vs {se:?}"
            );
        }
    }
    assert_eq!(f.passed_over, 0);
}

#[test]
fn a_loop_predicted_from_its_first_iterations_is_the_loop_run_whole() {
    let make = || Generator::new(common::gantry_params(), &[40.0, 40.0, 0.0]);
    for src in [
        // The triangle of the figures, then home.
        "REPEAT 200\nMOVE(140,40,0)\nMOVE(140,120,0)\nMOVE(40,120,0)\nENDREPEAT\nMOVE(40,40,0)\nEND",
        // Every instruction, loops within a loop, the inner one run again in each outer
        // iteration; a WAIT (met at once), a DELAY, a SPEED, a STOP and a MOVEJ in it.
        "REPEAT 8\nSPEED(50)\nREPEAT 50\nMOVE(50,40,0)\nOUT(gripper,1)\nMOVE(50,45,9)\n\
             WAIT(gripper_closed,1)\nDELAY(0.2)\nMOVEJ(40,40,0)\nOUT(gripper,0)\nENDREPEAT\n\
             SPEED(100)\nMOVE(60,60,0)\nSTOP\nENDREPEAT\nEND",
        // A loop whose iterations blend into each other without stopping.
        "MOVE(20,20,0)\nREPEAT 300\nMOVE(60,20,0)\nMOVE(60,30,0)\nMOVE(20,30,0)\nMOVE(20,20,0)\nENDREPEAT\nEND",
    ] {
        let (full, fast) = both(src, &gantry(), &make, 86_400.0);
        assert_same(src, &full, &fast, 30.0);
        // Iterations were passed over: most of the simulation (the queue of commands
        // trajgen takes ahead, 255, holds the loop's last iterations, which run).
        assert!(
            fast.0.passed_over > 0 && fast.0.steps * 2 < full.0.steps,
            "{src}: {} passed over, {} steps of {}",
            fast.0.passed_over,
            fast.0.steps,
            full.0.steps
        );
    }
}

#[test]
fn a_cartesian_loop_through_the_kinematics_is_passed_over_alike() {
    let (p, kin, cell) = five_bar();
    let make = || Generator::with_kinematics(p, Some(kin.clone()), &[0.0, 0.0]);
    let src =
        "REPEAT 150\nMOVE(-160,-120)\nMOVE(-235,-110)\nMOVE(-200,-190)\nENDREPEAT\nMOVEJ(0,0)\nEND";
    let (full, fast) = both(src, &cell, &make, 86_400.0);
    assert_same(src, &full, &fast, 30.0);
    assert!(fast.0.passed_over > 50, "{}", fast.0.passed_over);
}

#[test]
fn a_loop_too_long_is_said_so_without_running_it() {
    // A million iterations of 4.3 s: 50 days, past the day a program may run.
    let make = || Generator::new(common::gantry_params(), &[40.0, 40.0, 0.0]);
    let src = "REPEAT 1000000\nMOVE(100,40,0)\nMOVE(40,40,0)\nENDREPEAT\nEND";
    let program = Arc::new(motion_program::parse(src.as_bytes(), &gantry()).expect("parses"));
    let p = simulate_program(
        make(),
        Commands::new(program, 1),
        DT,
        86_400.0,
        &mut |_| {},
        &|| true,
    );
    assert_eq!(p.outcome, Outcome::TooLong);
    // Every iteration but the few simulated was passed over, and no further than the limit.
    assert!(p.passed_over > 10_000, "{}", p.passed_over);
    assert!(
        p.duration_s > 86_400.0 && p.duration_s < 86_400.0 + 60.0,
        "{}",
        p.duration_s
    );
    assert!(p.steps < 86_400_000 / 100, "{} steps", p.steps);
}
