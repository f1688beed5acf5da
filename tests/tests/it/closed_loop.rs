//! Servo's controller against the machine model, in one process at the default gains: the
//! default cell is stable and follows the blended triangle within its limits.

use machine_sim::Machine;
use servo::{Controller, Params as ServoParams};
use shm_schema::{MotionState, Role};
use supervisor::config::Config;
use trajgen::generator::{Generator, Params};

#[test]
fn the_default_gains_follow_the_triangle_and_settle() {
    let cfg = Config::default_cell();
    let cell = cfg.to_shm();
    let mut machine = Machine::new(&cell);
    let mut servo = Controller::new(ServoParams::from_cell(&cell));
    let start: Vec<f64> = cfg.axis.iter().map(|a| a.start).collect();
    let mut generator = Generator::new(Params::from_cell(&cell), &start);
    let prog =
        motion_program::parse(include_str!("../../../examples/triangle.prog"), 3).expect("parses");
    for c in prog.to_commands(1, 1) {
        generator.push_command(&c);
    }
    let ms = 1_000_000u64;
    let tg = cell.process[Role::Trajgen.index()].period_ns / ms;
    let mut fb = None;
    let mut sp = None;
    let mut max_fe = [0.0f64; 3];
    let mut done_at = None;
    for k in 1..30_000u64 {
        let now = 1_000_000_000 + k * ms;
        let fresh = if k % tg == 0 {
            let s = generator.step(now);
            sp = Some(s);
            Some(s)
        } else {
            None
        };
        let (cmd, state) = servo.cycle(now, fresh.as_ref(), fb.as_ref());
        fb = Some(machine.cycle(now + ms / 2, Some(&cmd)));
        if k > 10 {
            for (m, e) in max_fe.iter_mut().zip(&state.following_error) {
                *m = m.max(e.abs());
            }
            assert_eq!(
                state.status & !shm_schema::drive::servo_status::ENABLED,
                0,
                "status {:#x} at {k} ms",
                state.status
            );
        }
        if sp.is_some_and(|s| s.state == MotionState::Done as u32) && done_at.is_none() {
            done_at = Some(k);
        }
        if done_at.is_some_and(|d| k > d + 1000) {
            break;
        }
    }
    assert!(done_at.is_some(), "motion never finished");
    for (i, a) in cfg.axis.iter().enumerate() {
        assert!(
            max_fe[i] < a.following_error_limit / 5.0,
            "{}: max following error {}",
            a.name,
            max_fe[i]
        );
        let p = machine.axes()[i].encoder();
        assert!(
            (p - start[i]).abs() <= a.in_position,
            "{}: ends at {p}",
            a.name
        );
    }
}
