//! Seed 002's e-stop and health on the real binaries: a user's e-stop from another shell,
//! the propagation rules, a stalled process caught by the health detectors, and the supervisor
//! killed mid-motion (`docs/operations.md`).

use crate::drives::{
    Client, WATCHDOG, events_named, pid_of, program_in_background_as, triangle_in_background_as,
    wait_for,
};
use control_plane::Failure;
use control_plane::info::Origin;
use control_plane::report::RunFailure;
use integration_tests::{
    assert_clean, default_cell, exited, instance, json_of, pids_with, scratch, succeeded,
    supervisor, with_stall_room,
};
use shm_schema::Power;
use std::time::{Duration, Instant};

/// The default cell with `[behaviour]` set as given, and room for the host's stalls (these
/// tests are about the e-stop, not about the cell's tolerance of a stall).
fn cell_with_behaviour(test: &str, propagate: bool, external: bool) -> std::path::PathBuf {
    integration_tests::default_cell_toml()
        .set("behaviour.propagate_estop", propagate)
        .set("behaviour.propagate_external_estop", external)
        .write(test, "cell.toml")
}

/// Runs the small triangle of `test` on its instance, the cell's `[behaviour]` set as given
/// ([`cell_with_behaviour`]), and raises the user's e-stop (`supervisor estop`) mid-motion;
/// returns the run's stderr, its JSON report and the same typed.
fn user_estop_mid_motion(
    test: &str,
    propagate: bool,
    external: bool,
) -> (String, serde_json::Value, RunFailure) {
    let inst = &instance(test);
    let cfg = cell_with_behaviour(test, propagate, external);
    // The e-stop comes as soon as it moves: a small program is enough, and one that is not
    // stopped by it (without propagation) completes in a few seconds.
    let small = integration_tests::small_triangle(inst);
    let mut run = program_in_background_as(inst, Some(&cfg), true, &small);
    let client = Client::when_moving(inst, &mut run);
    succeeded(supervisor().args(["estop", "--instance", inst, "--reason", "test e-stop"]));
    let out = wait_for(run);
    client.leave();
    let err = exited(&out, 1);
    let j = json_of(&out);
    let failed = run_failure(&j, &err);
    // The e-stop, whether it stopped the motion or stayed latched after it.
    let cause = match &failed.cause {
        Failure::LatchedAfterMotion { estop } => estop.as_ref(),
        cause => cause,
    };
    match cause {
        Failure::Estop {
            origin, by, reason, ..
        } => assert_eq!(
            (*origin, by.as_str(), reason.as_str()),
            (Origin::External, "supervisor", "test e-stop"),
            "{err}\n{j}"
        ),
        other => panic!("not the user's e-stop: {other:?}\n{err}"),
    }
    assert_clean(inst);
    (err, j, failed)
}

/// The failed run's document `j`, typed (`err`: its stderr, for the message).
fn run_failure(j: &serde_json::Value, err: &str) -> RunFailure {
    serde_json::from_value(j.clone())
        .unwrap_or_else(|e| panic!("not the documented RunFailure ({e}): {j}\n{err}"))
}

#[test]
fn a_user_estop_from_another_shell_brings_the_axes_to_rest_and_disables_the_drives() {
    integration_tests::wall_clock(|| {
        let (_, j, _) = user_estop_mid_motion("estop-user", true, false);
        // Every process reacted in its own cycle; servo's reaction ended with the axes at rest
        // and the drives disabled, after the e-stop was raised.
        let safe = events_named(&j, "estop-safe");
        for p in ["servo", "trajgen", "iobridge", "drives"] {
            assert!(safe.iter().any(|e| e["source"] == p), "{p}: {safe:?}");
        }
        let servo = safe
            .iter()
            .find(|e| e["source"] == "servo")
            .expect("servo safe");
        let to_rest = servo["value"].as_f64().expect("seconds");
        assert!(to_rest > 0.0, "{servo}");
        let disabled = events_named(&j, "disabled");
        assert!(
            disabled
                .iter()
                .any(|e| e["t_s"].as_f64() <= servo["t_s"].as_f64()),
            "servo was safe before its drives were disabled: {disabled:?}"
        );
        let refused = events_named(&j, "motion-command-refused");
        assert!(
            refused
                .iter()
                .any(|e| e["text"] == "an e-stop dropped the program"),
            "{refused:?}"
        );
        println!(
            "e-stop to axes at rest and drives disabled: {:.1} ms",
            to_rest * 1e3
        );
    });
}

#[test]
fn a_stalled_trajgen_trips_servo_pending_sequence_detector() {
    integration_tests::wall_clock(|| {
        let inst = instance("estop-stall");
        // The supervisor's heartbeat watch is made slower than the detector, so the detector is
        // what catches the stall; nor do the processes take a supervisor held off a CPU by
        // the tests beside it for lost.
        let cfg = integration_tests::wall_cell_toml()
            .set("supervisor.heartbeat_timeout", 30.0)
            .set("supervisor.supervisor_timeout", 2.0)
            .write("estop-stall", "cell.toml");
        let mut run = triangle_in_background_as(&inst, Some(&cfg), true);
        let client = Client::when_moving(&inst, &mut run);
        let trajgen = pid_of("trajgen", &inst);
        // SAFETY: kill(2) on a process this test's supervisor started.
        unsafe { libc::kill(trajgen, libc::SIGSTOP) };
        let out = wait_for(run);
        // SAFETY: as above (it may be gone already).
        unsafe { libc::kill(trajgen, libc::SIGCONT) };
        client.leave();
        let err = exited(&out, 1);
        let j = json_of(&out);
        match run_failure(&j, &err).cause {
            Failure::Estop {
                origin, by, reason, ..
            } => assert_eq!(
                (origin, by.as_str(), reason.as_str()),
                (
                    Origin::Host,
                    "servo",
                    "pending_sequence_overrun expired in servo"
                ),
                "{err}\n{j}"
            ),
            other => panic!("not servo's detector: {other:?}\n{err}"),
        }
        assert_clean(&inst);
    });
}

#[test]
fn when_the_supervisor_is_killed_the_processes_bring_the_axes_to_rest_and_exit() {
    integration_tests::wall_clock(|| {
        let inst = instance("estop-orphan");
        let cfg = scratch(
            "estop-orphan",
            "cell.toml",
            &with_stall_room(&default_cell()),
        );
        let small = integration_tests::small_triangle(&inst);
        let mut run = program_in_background_as(&inst, Some(&cfg), false, &small);
        let client = Client::when_moving(&inst, &mut run);
        let cell = pids_with(&["--instance", &inst]);
        run.kill().expect("SIGKILL the supervisor");
        let _ = run.wait();
        // Servo brings the axes to rest and disables the drives before it leaves.
        let start = Instant::now();
        let mut last = None;
        loop {
            while let Some(s) = client.state.next() {
                last = Some(s);
            }
            if pids_with(&["--instance", &inst]).is_empty() {
                break;
            }
            assert!(
                start.elapsed() < WATCHDOG,
                "processes still running: {cell:?}"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        // What servo published between the last read and its exit (its last state, disabled,
        // comes just before it leaves).
        while let Some(s) = client.state.next() {
            last = Some(s);
        }
        let last = last.expect("servo published");
        assert_eq!(last.power, Power::Disabled as u8, "{last:?}");
        assert!(
            last.act_velocity[..3].iter().all(|v| v.abs() < 0.1),
            "{last:?}"
        );
        client.leave();
        // The next run of the instance starts, cleaning what the killed supervisor left.
        succeeded(
            supervisor()
                .args(["run", "--instance", &inst, "--config"])
                .arg(&cfg)
                .arg(&small),
        );
        assert_clean(&inst);
    });
}

/// The user's e-stop on a cell that does not propagate it (`propagate_estop = false`): it
/// stops the motion, servo bringing the axes to rest, only with `propagate_external_estop`;
/// without, it stays latched after the motion and no process reacts.
fn a_user_estop_without_propagate_estop(test: &str, external: bool) {
    let (err, j, failed) = user_estop_mid_motion(test, false, external);
    let safe = events_named(&j, "estop-safe");
    if external {
        assert!(matches!(failed.cause, Failure::Estop { .. }), "{err}\n{j}");
        assert!(safe.iter().any(|e| e["source"] == "servo"), "{j}");
    } else {
        assert!(
            matches!(failed.cause, Failure::LatchedAfterMotion { .. }),
            "{err}\n{j}"
        );
        assert!(safe.is_empty(), "no process reacts: {safe:?}");
    }
}

#[test]
fn without_propagation_a_user_estop_latches_but_the_motion_goes_on() {
    integration_tests::wall_clock(|| {
        a_user_estop_without_propagate_estop("estop-nopropagate", false);
    });
}

#[test]
fn propagate_external_estop_stops_the_motion_without_propagate_estop() {
    integration_tests::wall_clock(|| {
        a_user_estop_without_propagate_estop("estop-external", true);
    });
}
