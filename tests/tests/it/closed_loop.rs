//! Servo's controller against the machine model, in one process at the default gains: the
//! default cell is stable and follows the blended triangle within its limits, in CST (servo
//! closes the loop) and in CSP (the drives close it), at 1 kHz and at 4 kHz.

use crate::loop_sim::{Loop, MS};
use cell_config::Config;
use motion_core::generator::{Generator, Params};
use shm_schema::MotionState;
use shm_schema::drive::servo_status as st;

/// Runs the triangle; returns the largest |following error| per axis.
fn triangle(cfg: &Config) -> [f64; 3] {
    let cell = cfg.to_shm();
    let mut lp = Loop::enabled(&cell);
    let start: Vec<f64> = cfg.axis.iter().map(|a| a.start).collect();
    let mut generator = Generator::new(Params::from_cell(&cell), &start);
    let prog = crate::gantry_commands(include_str!("../../../examples/triangle.prog"), 1);
    for c in prog {
        generator.push_command(&c);
    }
    let tg = cell.period_of("trajgen").expect("trajgen") / lp.period;
    let mut max_fe = [0.0f64; 3];
    let mut done_at = None;
    let mut sp = None;
    for k in 1..(30_000 * MS / lp.period) {
        let fresh = (k % tg == 0).then(|| generator.step(lp.now + 100_000, None));
        if fresh.is_some() {
            sp = fresh;
        }
        let state = lp.step_with(None, fresh.as_ref(), None);
        for (m, e) in max_fe.iter_mut().zip(&state.following_error) {
            *m = m.max(e.abs());
        }
        let mut allowed = st::ENABLED | st::SETTLED | st::INITIALIZED;
        if sp.is_none() || k <= tg {
            allowed |= st::NO_SETPOINT; // before the first setpoint
        }
        let unexpected = state.status & !allowed;
        assert_eq!(
            unexpected,
            0,
            "status {:#x} at {k}: {:?}",
            state.status,
            lp.codes()
        );
        if sp.is_some_and(|s| s.state == MotionState::Done as u32) && done_at.is_none() {
            done_at = Some(k);
        }
        if done_at.is_some_and(|d| k > d + 1000 * MS / lp.period) {
            assert!(
                state.status & st::SETTLED != 0,
                "not settled a second after the end"
            );
            break;
        }
    }
    assert!(done_at.is_some(), "motion never finished");
    for (i, a) in cfg.axis.iter().enumerate() {
        let p = lp.machine.axes()[i].encoder();
        assert!(
            (p - start[i]).abs() <= a.in_position,
            "{}: ends at {p}",
            a.name
        );
    }
    max_fe
}

/// Runs the triangle ([`triangle`]) on `cfg`: every axis follows within a fifth of its
/// following-error limit.
fn follows_the_triangle(cfg: &Config) {
    let fe = triangle(cfg);
    for (i, a) in cfg.axis.iter().enumerate() {
        assert!(
            fe[i] < a.following_error_limit / 5.0,
            "{}: {}",
            a.name,
            fe[i]
        );
    }
}

#[test]
fn the_default_gains_follow_the_triangle_and_settle() {
    integration_tests::wall_clock(|| {
        follows_the_triangle(&Config::default_cell());
    });
}

#[test]
fn csp_axes_follow_the_triangle_with_the_drives_closing_the_loop() {
    integration_tests::wall_clock(|| {
        let cfg =
            Config::parse(&integration_tests::cell_in_csp(), "csp").expect("valid csp config");
        follows_the_triangle(&cfg);
    });
}

/// The default cell with the machine and servo at `period_us`.
pub fn at_rate(period_us: u64) -> Config {
    Config::parse(&integration_tests::cell_at_rate(period_us), "rate").expect("valid")
}

#[test]
fn at_4_khz_the_following_error_is_no_worse_than_at_1_khz() {
    integration_tests::wall_clock(|| {
        let slow = triangle(&Config::default_cell());
        let fast = triangle(&at_rate(250));
        for i in 0..3 {
            assert!(
                fast[i] <= slow[i] * 1.05 + 1e-4,
                "axis {i}: {} at 4 kHz vs {} at 1 kHz",
                fast[i],
                slow[i]
            );
        }
    });
}
