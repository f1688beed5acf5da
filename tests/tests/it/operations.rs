//! The long-running cell on the real binaries (docs/operations.md): `up`, the control CLI from
//! other shells, e-stop and recovery, processes killed and stalled mid-motion and restarted by
//! their policy, hot swap, another user refused, nothing left after `down`.

use crate::drives::{WATCHDOG, pid_of};
use crate::up::{
    Up, arm_enabled, cell, enabled, estop_of, io_of, latched, moving_typed as moving, process_of,
};
use control_plane::info::{Life, Origin};
use control_plane::report::{RunDocument, RunFailure, RunReport};
use control_plane::status::Status;
use control_plane::{Failure, Refusal};
use integration_tests::{
    assert_clean, exited, instance, run_with_watchdog, scratch, succeeded_within, supervisor,
    wait_output,
};
use shm_schema::event::code;
use std::process::Stdio;
use std::time::{Duration, Instant};

/// A short program: out and back on x (2 segments, about 13 s from the default start), for a
/// test that acts on the cell several times while it moves.
const SHORT: &str = "MOVE(140, 40, 0)\nMOVE(40, 40, 0)\nEND\n";
/// Out and back on x, half as far (about 7 s): a program that must still move several seconds
/// after a test saw it moving, and that a test then waits to complete.
const MID: &str = "MOVE(90, 40, 0)\nMOVE(40, 40, 0)\nEND\n";
/// A brief program (about 3 s from the default start): the cell runs a program again.
const BRIEF: &str = "MOVE(60, 40, 0)\nMOVE(40, 40, 0)\nEND\n";

fn program(test: &str, src: &str) -> String {
    scratch(test, "p.prog", src).display().to_string()
}

fn all_running(s: &Status) -> bool {
    s.supervisor
        .processes
        .iter()
        .all(|p| p.life == Life::Running)
}

/// The program's path speed, in the typed status `s` (`None`: no program, or none yet).
fn path_speed(s: &Status) -> Option<f64> {
    s.supervisor.job.as_ref().and_then(|j| j.path_speed)
}

/// A program's document (`exec --wait --json`, `run --json`) in `out`'s stdout, typed.
fn document(out: &std::process::Output) -> RunDocument {
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.trim()).unwrap_or_else(|e| {
        panic!(
            "not the documented report ({e}): {text}{}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

/// A program's document in `out`'s stdout, which must be a failure.
fn failure_of(out: &std::process::Output) -> RunFailure {
    match document(out) {
        RunDocument::Failed(f) => f,
        RunDocument::Completed(r) => panic!("completed: {r:?}"),
    }
}

/// A program's document in `out`'s stdout, which must be a completed run's report.
fn report_of(out: &std::process::Output) -> RunReport {
    match document(out) {
        RunDocument::Completed(r) => *r,
        RunDocument::Failed(f) => panic!("failed: {f:?}"),
    }
}

/// Sends `sig` to the process of `inst` that runs `program`.
fn signal(program: &str, inst: &str, sig: nix::sys::signal::Signal) {
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid_of(program, inst)), sig).expect("kill");
}

/// Runs the brief program of `test` on `up` to its end.
fn brief(up: &Up, test: &str) {
    up.ok(&["exec", &program(test, BRIEF), "--wait"]);
}

#[test]
fn a_cell_stays_up_runs_programs_pauses_and_aborts_and_goes_down_clean() {
    integration_tests::wall_clock(|| {
        let test = "ops-up";
        // The wall clock: its plot shows the wake-up latency histogram (empty on the virtual clock).
        let cfg = crate::up::wall_cell(test, &[]);
        let up = Up::start(test, &cfg);
        // A second supervisor of the instance is refused, whether `up` or `run`. No cell
        // answers them (they are refused before they ask one): their words are all they say.
        let err = up.refused(&["up", "--config", cfg.to_str().expect("utf-8")]);
        assert!(err.contains("is in use"), "{err}");
        let triangle = integration_tests::examples().join("triangle.prog");
        let tri = triangle.to_str().expect("utf-8");
        let err = up.refused(&["run", tri]);
        assert!(err.contains("is in use"), "{err}");
        // A bad program is refused with its line and column; nothing moves. (The words are
        // the subject: they name the file and the line.)
        let bad = program(test, "MOVE(140, 40)\nEND\n");
        match up.refusal(&["exec", &bad]) {
            Refusal::Program { error } => assert!(error.contains("p.prog:1:"), "{error}"),
            other => panic!("a bad program: {other:?}"),
        }
        // exec --wait prints run's report and draws its figures; an output where none can be
        // written is refused before anything moves (by the client, before it asks the cell:
        // its words, which name the flag the user typed, are the subject).
        let err = up.refused(&["exec", tri, "--wait", "--plot", "/nonexistent/dir/p.png"]);
        assert!(err.contains("--plot /nonexistent/dir/p.png"), "{err}");
        let plot = integration_tests::scratch(test, "exec.png", "");
        let plot_arg = plot.to_str().expect("utf-8");
        let small = integration_tests::small_triangle(test);
        let r = up.report(&small, &["--plot", plot_arg]);
        assert_eq!(r["ok"], true);
        crate::cell::check_figures(&plot, r["processes"].as_object().expect("processes").len());
        let diff = r["difference_s"].as_f64().expect("difference");
        println!("exec --wait: measured - theoretical = {:.3} ms", diff * 1e3);
        assert!(diff >= 0.0, "{r}");
        for p in ["drives", "servo", "trajgen", "iobridge"] {
            assert!(r["processes"][p]["cycles"].as_u64().unwrap_or(0) > 0, "{p}");
        }
        // Pause: the axes come to rest on the path and hold; resume goes on; abort drops it.
        up.done(&["exec", tri]);
        up.until_typed("moving", moving);
        // Done: trajgen took the pause and the path speed is 0.
        up.done(&["pause"]);
        let s = up.status_typed();
        let job = s.supervisor.job.as_ref().expect("the program runs");
        assert!(job.paused, "{s:?}");
        assert_eq!(s.supervisor.estop, None, "a pause is no e-stop: {s:?}");
        let line = job.line;
        std::thread::sleep(Duration::from_millis(500));
        let s2 = up.status_typed();
        assert_eq!(
            s2.supervisor.job.as_ref().map(|j| j.line),
            Some(line),
            "held while paused"
        );
        assert_eq!(
            up.refusal(&["exec", tri]),
            Refusal::ProgramRunning {
                program: tri.to_string()
            }
        );
        up.done(&["resume"]);
        up.until_typed("moving again", |s| path_speed(s) == Some(1.0));
        // The live override: the path speed ramps to it and stays, along the same path.
        up.done(&["speed", "40"]);
        let s = up.until_typed("at 40 %", |s| path_speed(s) == Some(0.4));
        let program_status = s.program.as_ref().expect("trajgen's program");
        assert_eq!(program_status.speed_override, 0.4, "{s:?}");
        assert_eq!(up.refusal(&["speed", "0"]), Refusal::Speed { percent: 0.0 });
        assert_eq!(
            up.refusal(&["speed", "250"]),
            Refusal::Speed { percent: 250.0 }
        );
        up.done(&["speed", "100"]);
        // Done: trajgen took the abort and the program is over.
        up.done(&["abort"]);
        let s = up.status_typed();
        assert_eq!(s.supervisor.job, None, "{s:?}");
        let last = s.supervisor.last_job.as_ref().expect("the last program");
        assert!(!last.ok, "{s:?}");
        assert_eq!(s.supervisor.estop, None, "an abort is no e-stop: {s:?}");
        assert!(arm_enabled(&s), "{s:?}");
        // The next program starts where the abort left the axes.
        brief(&up, test);
        // `down` while a client waits for a program: the client is told, not dropped.
        let waiting = supervisor()
            .args(["exec", "--wait", "--json", "--instance", &up.inst])
            .arg(program(test, SHORT))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("exec");
        up.until_typed("moving", moving);
        let inst = up.inst.clone();
        up.down();
        let out = waiting.wait_with_output().expect("exec");
        let err = exited(&out, 1);
        let failed = failure_of(&out);
        assert!(
            matches!(failed.cause, Failure::Down { .. }),
            "{failed:?}\n{err}"
        );
        assert_clean(&inst);
        // A command to an instance that is not up says so. No cell answered: the client's
        // words are all there is.
        let out = supervisor()
            .args(["status", "--instance", &instance(test)])
            .output()
            .expect("status");
        assert!(exited(&out, 2).contains("is not up"));
    });
}

#[test]
fn estop_then_reset_and_start_recover_and_a_fault_whose_cause_remains_is_named() {
    integration_tests::wall_clock(|| {
        let test = "ops-reset";
        let up = Up::default_cell(test);
        up.done(&["estop", "--reason", "ops test"]);
        let s = up.until_typed("latched and safe", |s| latched(s) && !arm_enabled(s));
        let e = estop_of(&s);
        assert_eq!(
            (e.origin, e.code, e.reason.as_str()),
            (Origin::External, code::ESTOP_RAISED, "ops test"),
            "{s:?}"
        );
        // Nothing runs and nothing enables while it is latched.
        let latched_estop = |r: Refusal| match r {
            Refusal::EstopLatched { estop } => match *estop {
                Failure::Estop { origin, reason, .. } => {
                    assert_eq!((origin, reason.as_str()), (Origin::External, "ops test"))
                }
                other => panic!("not the user's e-stop: {other:?}"),
            },
            other => panic!("not refused for the e-stop: {other:?}"),
        };
        latched_estop(up.refusal(&["exec", &program(test, SHORT)]));
        latched_estop(up.refusal(&["start"]));
        up.done(&["reset"]);
        // Drives never re-enable by themselves.
        std::thread::sleep(Duration::from_millis(500));
        assert!(!arm_enabled(&up.status_typed()));
        up.done(&["start"]);
        brief(&up, test);
        // A fault whose cause is still there: reset clears the e-stop and says what stays,
        // naming it (the words are the subject: they say which fault and why).
        up.ok(&["inject", "--axis", "x", "encoder-loss"]);
        up.until_typed("servo's fault", |s| {
            let i = &s.supervisor;
            i.estop.is_some() && i.arm.as_ref().is_some_and(|a| a.fault_latched)
        });
        match up.failure(&["reset"]) {
            Failure::ResetIncomplete { left } => assert!(
                left.iter()
                    .any(|l| l.contains("its cause is still present")),
                "{left:?}"
            ),
            other => panic!("reset with the fault's cause present: {other:?}"),
        }
        up.ok(&["inject", "--axis", "x", "encoder-loss", "--clear"]);
        up.reset_and_start();
        brief(&up, test);
        up.down();
    });
}

#[test]
fn each_process_killed_mid_motion_raises_the_estop_and_restarts_and_the_cell_recovers() {
    integration_tests::wall_clock(|| {
        let test = "ops-kill";
        let up = Up::default_cell(test);
        let long = program(
            test,
            "MOVE(140, 40, 0)\nMOVE(40, 40, 0)\nMOVE(140, 40, 0)\nEND\n",
        );
        for (victim, program) in [
            ("trajgen", "trajgen"),
            ("servo", "servo"),
            ("iobridge", "iobridge"),
            ("drives", "machine-sim"),
        ] {
            up.done(&["exec", &long]);
            up.until_typed("moving", moving);
            signal(program, &up.inst, nix::sys::signal::Signal::SIGKILL);
            // The host e-stop names the process; the axes come to rest with the drives off; the
            // supervisor stays up and restarts the process (restart = "on-failure").
            let s = up.until_typed("restarted and at rest", |s| {
                let p = process_of(s, victim);
                latched(s)
                    && s.supervisor.job.is_none()
                    && !arm_enabled(s)
                    && p.life == Life::Running
                    && p.restarts == 1
            });
            let e = estop_of(&s);
            assert_eq!(
                (e.origin, e.code, e.reason.as_str()),
                (
                    Origin::Host,
                    code::PROCESS_LOST,
                    format!("{victim} lost").as_str()
                ),
                "{s:?}"
            );
            let last = s.supervisor.last_job.as_ref().expect("the last program");
            assert!(!last.ok, "{s:?}");
            up.until_typed("all cyclic", all_running);
            up.reset_and_start();
        }
        brief(&up, test);
        up.down();
    });
}

#[test]
fn a_stalled_process_is_found_by_its_heartbeat_and_replaced() {
    integration_tests::wall_clock(|| {
        let test = "ops-stall";
        let up = Up::on_the_wall_clock(test);
        signal("iobridge", &up.inst, nix::sys::signal::Signal::SIGSTOP);
        let s = up.until_typed("stall found, iobridge restarted", |s| {
            let p = process_of(s, "iobridge");
            latched(s) && p.restarts == 1 && p.life == Life::Running
        });
        // Found by its heartbeat: the supervisor's host e-stop for a stalled process.
        let e = estop_of(&s);
        assert_eq!(
            (e.origin, e.code, e.reason.as_str()),
            (Origin::Host, code::PROCESS_LOST, "iobridge stalled"),
            "{s:?}"
        );
        up.until_typed("cyclic", all_running);
        up.reset_and_start();
        up.down();
    });
}

#[test]
fn iobridge_and_trajgen_swap_during_motion_and_at_rest_without_an_estop() {
    integration_tests::wall_clock(|| {
        let test = "ops-swap";
        let up = // The wall clock: the test catches the swap under way by the wall clock's pace.
        Up::on_the_wall_clock(test);
        // The gripper holds a part: no swap may open it.
        up.ok(&["io", "gripper", "1"]);
        // Two swaps while it moves: the program lasts 13 s.
        let run = up.exec_in_background(program(test, SHORT));
        up.until_typed("moving", moving);
        let replaced = up.replaced(&["swap", "iobridge"]);
        println!("{}", replaced.text());
        // The fieldbus image during the handover: its images and their largest gap.
        assert!(replaced.image.is_some(), "{replaced:?}");
        let s = up.status_typed();
        assert_eq!(io_of(&s, "gripper"), Some(1), "{s:?}");
        // trajgen carries the motion: swapped during it, the program goes on along the path.
        // (Asked on the control channel itself: the answer's data, not its words.)
        let instance = shm_schema::InstanceName::new(&up.inst).expect("instance");
        let swap = control_plane::Request::Swap {
            process: "trajgen".into(),
            command: None,
        };
        let replaced = match control_plane::channel::call(&instance, &swap) {
            Ok(control_plane::Reply::Replaced(r)) => r,
            other => panic!(
                "swap trajgen during the program: {other:?}\nlog:\n{}",
                up.log()
            ),
        };
        println!("{}", replaced.text());
        assert!(replaced.program.is_some(), "{replaced:?}");
        let swap_ms = replaced.took_ms;
        // servo cannot be swapped under a moving arm.
        match up.refusal(&["swap", "servo"]) {
            Refusal::MotionPath { process, .. } => assert_eq!(process, "servo"),
            other => panic!("swap servo during a program: {other:?}"),
        }
        let out = up.succeeded(
            wait_output(run, WATCHDOG, "the program did not end"),
            "exec --wait",
        );
        // No e-stop, the following error within its limit (or servo would have cut power), and
        // the motion time grew by about what the swap took (the pause's ramps included).
        let r = report_of(&out);
        let opened = r
            .events
            .iter()
            .filter(|e| e.text == "gripper = 0" || e.text == "gripper_closed = 0")
            .count();
        assert_eq!(opened, 0, "the new iobridge took over the gripper: {r:?}");
        let extra_ms = r.difference_s * 1e3;
        println!(
            "motion time grew by {extra_ms:.0} ms; the trajgen swap took {swap_ms:.0} ms; max following error {:?}",
            r.max_following_error
        );
        // The pause's ramps (t_acc), and any stall trajgen measured besides the swap's own.
        let r = serde_json::to_value(&r).expect("the report as JSON");
        let late_ms = crate::cell::trajgen_stall_s(&r) * 1e3;
        assert!(
            extra_ms > 0.0 && extra_ms < swap_ms + 525.0 + late_ms,
            "{extra_ms} vs {swap_ms} (trajgen's longest stall {late_ms} ms)"
        );
        // At rest: trajgen swapped for the same build, with a command of its own.
        let trajgen = integration_tests::bin("trajgen");
        let cmd = format!(
            "{} --instance {{instance}} --name {{name}}",
            trajgen.display()
        );
        // The swap is a job of the supervisor's loop: the control channel answers meanwhile,
        // and refuses what would change the cell until the swap has ended.
        let swap = up
            .command()
            .args(["swap", "trajgen", "--command", &cmd, "--instance", &up.inst])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("swap");
        match up.during_swap_of("trajgen", &control_plane::Request::Start) {
            Ok(control_plane::Reply::Refused(why)) => assert_eq!(
                why,
                control_plane::Refusal::Replacing {
                    process: "trajgen".into()
                }
            ),
            other => panic!("start during a swap: {other:?}"),
        }
        let out = up.succeeded(swap.wait_with_output().expect("swap"), "swap trajgen");
        let out = String::from_utf8_lossy(&out.stdout).to_string();
        println!("{}", out.trim());
        up.until_typed("enabled again", enabled);
        let s = up.status_typed();
        assert_eq!(s.supervisor.estop, None, "no e-stop: {s:?}");
        brief(&up, test);
        // A bad command changes nothing (a refusal: nothing was changed).
        let refusal = up.refusal(&["swap", "trajgen", "--command", "/nonexistent/trajgen"]);
        assert!(matches!(refusal, Refusal::Command { .. }), "{refusal:?}");
        match up.refusal(&["swap", "nosuch"]) {
            Refusal::NoSuchProcess { process, known } => {
                assert_eq!(process, "nosuch");
                assert!(known.iter().any(|k| k == "trajgen"), "{known:?}");
            }
            other => panic!("swap nosuch: {other:?}"),
        }
        up.down();
    });
}

/// A process of the table that takes 6 s to leave after SIGTERM (its shell waits that long
/// once it ended), swapped: the old one leaves in the background, and the control channel
/// answers meanwhile (it was deaf until the old process had gone, up to `stop_timeout`).
#[test]
fn the_control_channel_answers_while_a_swapped_process_takes_its_time_to_leave() {
    integration_tests::wall_clock(|| {
        let test = "ops-slow-leave";
        let iobridge = integration_tests::bin("iobridge");
        let slow = format!(
            "trap 'sleep 6' TERM; {} --instance {{instance}}",
            iobridge.display()
        );
        let command = toml_edit::Array::from_iter(["sh", "-c", slow.as_str()]);
        let up = Up::start(
            test,
            // The wall clock: the old process takes 6 s of the wall clock to leave.
            &crate::up::wall_cell(
                test,
                &[
                    ("process[iobridge].command", command.into()),
                    ("supervisor.stop_timeout", 20.0.into()),
                ],
            ),
        );
        let instance = shm_schema::InstanceName::new(&up.inst).expect("instance");
        let info = || match control_plane::channel::call(&instance, &control_plane::Request::Info) {
            Ok(control_plane::Reply::Info(info)) => info,
            other => panic!("Info: {other:?}"),
        };
        let pid = |i: &control_plane::Info| {
            let p = i.processes.iter().find(|p| p.name == "iobridge");
            p.and_then(|p| p.pid).expect("iobridge runs")
        };
        let old = pid(&info());
        // Alive, not a zombie waiting to be reaped.
        let alive = |pid: u32| {
            std::fs::read_to_string(format!("/proc/{pid}/stat"))
                .ok()
                .and_then(|s| s.rsplit(") ").next().map(|r| !r.starts_with('Z')))
                .unwrap_or(false)
        };
        let mut swap = up.spawn(&["swap", "iobridge"]);
        let start = Instant::now();
        let mut answered = None;
        while answered.is_none() && swap.try_wait().expect("swap").is_none() {
            assert!(start.elapsed() < WATCHDOG, "the swap never ended");
            let i = info();
            // The new one in the table, the swap not over, the old one still leaving.
            if i.swapping.as_deref() == Some("iobridge") && pid(&i) != old && alive(old) {
                answered = Some(pid(&i));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let out = swap.wait_with_output().expect("swap");
        assert!(out.status.success(), "swap: {out:?}\nlog:\n{}", up.log());
        assert!(
            answered.is_some(),
            "no answer while the old iobridge (pid {old}) was leaving\nlog:\n{}",
            up.log()
        );
        assert!(
            !alive(old),
            "the old iobridge is gone once the swap is done"
        );
        up.down();
    });
}

#[test]
fn another_user_is_refused_by_the_control_channel() {
    integration_tests::wall_clock(|| {
        if !nix::unistd::geteuid().is_root() {
            eprintln!("skipped: needs root to run a command as another user");
            return;
        }
        let test = "ops-user";
        let up = Up::default_cell(test);
        let out = std::process::Command::new("setpriv")
            .args(["--reuid", "65534", "--regid", "65534", "--clear-groups"])
            .arg(integration_tests::bin("supervisor"))
            .args(["down", "--json", "--instance", &up.inst])
            .output()
            .expect("setpriv");
        let err = exited(&out, 2);
        let reply: control_plane::Reply =
            serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{e}: {err}"));
        let owner = nix::unistd::geteuid().as_raw();
        assert_eq!(
            reply,
            control_plane::Reply::Refused(Refusal::ForeignUser { owner, uid: 65534 }),
            "{err}"
        );
        // Nothing changed: the cell is still up.
        assert!(arm_enabled(&up.status_typed()));
        up.down();
    });
}

#[test]
fn after_the_supervisor_of_an_up_cell_is_killed_the_next_up_works() {
    integration_tests::wall_clock(|| {
        let test = "ops-sigkill";
        let cfg = cell(test, &[]);
        let mut up = Up::start(test, &cfg);
        // A client waits for a program's end: told that the supervisor broke off, exit 1 (its
        // request was taken).
        let waiting = up.exec_in_background(program(test, SHORT));
        up.until_typed("moving", moving);
        let mut child = up.child.take().expect("running");
        child.kill().expect("SIGKILL");
        let _ = child.wait();
        // No answer came (no reply, no report): the client's own words are all it says.
        let out = waiting.wait_with_output().expect("exec");
        let err = exited(&out, 1);
        assert!(out.stdout.is_empty(), "{err}");
        assert!(err.contains("control channel broke"), "{err}");
        let inst = up.inst.clone();
        drop(up);
        // Its processes notice (the heartbeat stops), bring the axes to rest and exit.
        let start = Instant::now();
        while !integration_tests::pids_with(&["--instance", &inst]).is_empty() {
            assert!(start.elapsed() < WATCHDOG, "processes left running");
            std::thread::sleep(Duration::from_millis(50));
        }
        // The same instance comes up again and works.
        succeeded_within(
            supervisor()
                .args(["run", "--instance", &inst, "--config"])
                .arg(&cfg)
                .arg(program(test, BRIEF)),
            WATCHDOG,
        );
        assert_clean(&inst);
    });
}

#[test]
fn a_python_iobridge_written_from_the_documents_takes_the_role() {
    integration_tests::wall_clock(|| {
        integration_tests::require_python_iceoryx2();
        let test = "ops-python";
        let cfg = integration_tests::with_python_iobridge(integration_tests::default_cell_toml())
            .write(test, "cell.toml");
        let inst = instance(test);
        let out = succeeded_within(
            supervisor()
                .args(["run", "--json", "--instance", &inst, "--config"])
                .arg(&cfg)
                .arg(program(test, BRIEF)),
            WATCHDOG,
        );
        let r = report_of(&out);
        // The Python process was cyclic, and its fieldbus images reached the supervisor.
        assert!(
            r.processes.get("iobridge").is_some_and(|p| p.cycles > 100),
            "{r:?}"
        );
        assert!(r.iobridge_delay_us.is_some(), "no fieldbus image: {r:?}");
        assert_clean(&inst);
    });
}

/// Stops process `program` of `inst` for `ms` milliseconds (SIGSTOP, then SIGCONT), timed by
/// a thread of the test at `SCHED_FIFO` 90 (above every process of a cell) where it may: the
/// test's ordinary thread, under the suite's load, woke 300 ms late for its SIGCONT, and the
/// 20 ms stall below the detector's limit became one above it.
fn stall(program: &str, inst: &str, ms: u64) {
    use nix::sys::signal::{Signal, kill};
    let pid = nix::unistd::Pid::from_raw(pid_of(program, inst));
    std::thread::spawn(move || {
        let param = libc::sched_param { sched_priority: 90 };
        // SAFETY: plain system call on this thread with a valid parameter block; refused
        // (not root), the thread stays ordinary.
        let _ = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
        kill(pid, Signal::SIGSTOP).expect("SIGSTOP");
        std::thread::sleep(Duration::from_millis(ms));
        kill(pid, Signal::SIGCONT).expect("SIGCONT");
    })
    .join()
    .expect("the stall's thread");
}

#[test]
fn a_swap_keeps_the_outputs_while_the_old_iobridge_is_held_off_the_cpu() {
    integration_tests::wall_clock(|| {
        // Found by CI: a host stall of the old iobridge longer than its successor's wait for
        // its image (50 ms) made the successor start with every output at 0, the gripper's
        // part dropped. The detectors widened: the stall is not what this test is about.
        let test = "ops-swap-held";
        // The wall clock: the old iobridge is held off the CPU (SIGSTOP), a stall of the wall
        // clock (on the virtual clock the whole cell would wait for it).
        let cfg = integration_tests::wall_cell_toml()
            .set("supervisor.heartbeat_timeout", 30.0)
            .set(
                "health_config.pending_sequence_overrun_percent_limit",
                100.0,
            )
            .set(
                "health_config.thread_offset_variance_overrun_percent_limit",
                100.0,
            )
            .write(test, "cell.toml");
        let up = Up::start(test, &cfg);
        up.ok(&["io", "gripper", "1"]);
        up.until_typed("the gripper closed", |s| io_of(s, "gripper") == Some(1));
        // The old iobridge held off the CPU for 600 ms from the moment the swap is asked: its
        // successor starts while it publishes nothing.
        let inst = up.inst.clone();
        let held = std::thread::spawn(move || stall("iobridge", &inst, 600));
        let replaced = up.replaced(&["swap", "iobridge"]);
        held.join().expect("the stall");
        let s = up.status_typed();
        assert_eq!(io_of(&s, "gripper"), Some(1), "{replaced:?}\n{s:?}");
        assert!(!latched(&s), "{s:?}");
        up.down();
    });
}

#[test]
fn an_iobridge_stall_counts_as_pending_sequence_and_trips_only_above_its_limit() {
    integration_tests::wall_clock(|| {
        // The embedded cell's pending-sequence detector, unwidened: iobridge at 4 ms forgives
        // 30 % of its rate, 75 missed periods, leaking one every 50 ms. The supervisor's
        // heartbeat watch is made slower than the detector, so the detector is what catches
        // the stall; the wake-up detector gets room for the host's stalls (it tripped servo
        // on a busy host, which is not what this test is about), and the processes' watch of
        // the supervisor too.
        let test = "ops-iostall";
        let cfg = integration_tests::wall_cell_toml()
            .set("supervisor.heartbeat_timeout", 30.0)
            .set("supervisor.supervisor_timeout", 2.0)
            .set(
                "health_config.thread_offset_variance_overrun_percent_limit",
                100.0,
            )
            .write(test, "cell.toml");
        let up = Up::start(test, &cfg);
        let pending = |s: &Status| {
            s.processes
                .get("iobridge")
                .map_or(0, |p| p.health.pending_sequence_overrun.total)
        };
        let before = pending(&up.status_typed());
        // 20 ms: 5 periods missed, below the limit: counted, no trip.
        stall("iobridge", &up.inst, 20);
        let s = up.until_typed("the gap counted", |s| pending(s) > before);
        std::thread::sleep(Duration::from_millis(500));
        let s2 = up.status_typed();
        assert!(!latched(&s2), "a 20 ms gap tripped: {s2:?}\nbefore: {s:?}");
        // 1 s: 250 periods, three times the limit: a host e-stop naming the detector, raised
        // by iobridge's own detector.
        stall("iobridge", &up.inst, 1000);
        let s = up.until_typed("the trip", latched);
        let e = estop_of(&s);
        assert_eq!(
            (e.origin, e.code, e.source.as_str(), e.reason.as_str()),
            (
                Origin::Host,
                code::HEALTH_EXPIRED,
                "iobridge",
                "pending_sequence_overrun expired in iobridge"
            ),
            "{s:?}"
        );
        up.until_typed("at rest, drives off", |s| !arm_enabled(s));
        up.reset_and_start();
        up.down();
    });
}

/// A pipe already full, its write end blocking: whoever writes to it without care blocks for
/// good (a paused terminal, a log reader that stopped reading).
fn full_pipe() -> (std::os::fd::OwnedFd, std::os::fd::OwnedFd) {
    use nix::fcntl::{FcntlArg, OFlag, fcntl};
    let (r, w) = nix::unistd::pipe().expect("pipe");
    fcntl(&w, FcntlArg::F_SETFL(OFlag::O_NONBLOCK)).expect("non-blocking");
    let chunk = [b'x'; 4096];
    while nix::unistd::write(&w, &chunk).is_ok() {}
    fcntl(&w, FcntlArg::F_SETFL(OFlag::empty())).expect("blocking again");
    (r, w)
}

#[test]
fn a_blocked_stderr_never_blocks_the_supervisor_nor_its_verdict() {
    integration_tests::wall_clock(|| {
        // Found by fault injection: with its stderr blocked, the supervisor blocked in a write and
        // missed a killed servo. Now its lines are dropped, and it still sees everything.
        let test = "ops-stderr";
        let inst = instance(test);
        let (_r, w) = full_pipe();
        let triangle = integration_tests::examples().join("triangle.prog");
        let run = supervisor()
            .args(["run", "--json", "--instance", &inst, "--config"])
            .arg(cell(test, &[]))
            .arg(&triangle)
            .stdout(Stdio::piped())
            .stderr(Stdio::from(w))
            .spawn()
            .expect("run");
        // While it moves, servo dies.
        let start = Instant::now();
        loop {
            let mut cmd = supervisor();
            cmd.args(["status", "--json", "--instance", &inst]);
            let out = run_with_watchdog(&mut cmd, WATCHDOG);
            if serde_json::from_slice::<Status>(&out.stdout).is_ok_and(|s| moving(&s)) {
                break;
            }
            assert!(start.elapsed() < WATCHDOG, "never moved");
            std::thread::sleep(Duration::from_millis(50));
        }
        signal("servo", &inst, nix::sys::signal::Signal::SIGKILL);
        let out = wait_output(run, WATCHDOG, "the supervisor is stuck");
        assert_eq!(out.status.code(), Some(1));
        let j = failure_of(&out);
        assert!(!j.ok);
        // Ended by servo's loss: its exit, or the host e-stop its loss raised, which names it.
        match &j.cause {
            Failure::Exited { process, .. } => assert_eq!(process, "servo", "{j:?}"),
            Failure::Estop { code, reason, .. } => assert_eq!(
                (*code, reason.as_str()),
                (code::PROCESS_LOST, "servo lost"),
                "{j:?}"
            ),
            other => panic!("not ended by servo's loss: {other:?}"),
        }
        assert_clean(&inst);
    });
}

/// An e-stop input opened mid-motion on a cell whose devices' own e-stops are not propagated
/// (`propagate_estop = false`): the user's e-stop it raises stops the motion only with
/// `propagate_external_estop`; iobridge, which raised it, sets its outputs safe either way;
/// reset refuses while the input stays open, and the cell recovers once it closes.
fn an_estop_input_mid_motion(test: &str, external: bool) {
    let cfg = integration_tests::default_cell_toml()
        .set("behaviour.propagate_estop", false)
        .set("behaviour.propagate_external_estop", external)
        .write(test, "cell.toml");
    let up = Up::start(test, &cfg);
    up.ok(&["io", "gripper", "1"]);
    up.ok(&["io", "cycle_lamp", "1"]);
    let s = up.until_typed("the gripper closed", |s| {
        io_of(s, "gripper_closed") == Some(1)
    });
    assert_eq!(io_of(&s, "cycle_lamp"), Some(1), "{s:?}");
    let run = up.exec_in_background(program(test, MID));
    up.until_typed("moving", moving);
    up.ok(&["io", "estop_ok", "0"]);
    let s = up.until_typed("latched, outputs safe", |s| {
        latched(s) && s.io.as_ref().and_then(|io| io.outputs_safe) == Some(true)
    });
    let e = estop_of(&s);
    assert_eq!(
        (e.origin, e.code, e.source.as_str(), e.reason.as_str()),
        (
            Origin::External,
            code::ESTOP_INPUT,
            "iobridge",
            "e-stop input estop_ok is open"
        ),
        "{s:?}"
    );
    // Each output at its safe value: the lamp off, the gripper holding its part.
    assert_eq!(io_of(&s, "cycle_lamp"), Some(0), "{s:?}");
    assert_eq!(io_of(&s, "gripper"), Some(1), "{s:?}");
    // `io` is no request to the cell (it writes to iobridge itself): its words are all it
    // says, and they are the subject (why the output was not set).
    let err = up.fails(&["io", "cycle_lamp", "1"]);
    assert!(err.contains("safe values"), "{err}");
    let out = run.wait_with_output().expect("exec");
    let err = exited(&out, 1);
    let report = failure_of(&out);
    let servo_safe = report
        .events
        .iter()
        .any(|e| e.code == code::ESTOP_SAFE && e.source == "servo");
    assert_eq!(
        matches!(report.cause, Failure::LatchedAfterMotion { .. }),
        !external,
        "{err}\n{report:?}"
    );
    assert_eq!(servo_safe, external, "{report:?}");
    // Reset fails at once while the input is open, and says which and why (the words are the
    // subject: they name the input).
    match up.failure(&["reset"]) {
        Failure::ResetIncomplete { left } => assert!(
            left.iter()
                .any(|l| l.contains("e-stop input estop_ok is open")),
            "{left:?}"
        ),
        other => panic!("reset with the input open: {other:?}"),
    }
    up.ok(&["io", "estop_ok", "1"]);
    up.done(&["reset"]);
    // The outputs stay where the e-stop put them; requests are taken again.
    let s = up.status_typed();
    assert_eq!(io_of(&s, "cycle_lamp"), Some(0), "{s:?}");
    up.ok(&["io", "cycle_lamp", "1"]);
    up.done(&["start"]);
    brief(&up, test);
    up.down();
}

#[test]
fn an_estop_input_stops_the_motion_with_propagate_external_estop() {
    integration_tests::wall_clock(|| {
        an_estop_input_mid_motion("ops-input-ext", true);
    });
}

#[test]
fn an_estop_input_without_propagate_external_estop_only_sets_the_outputs_safe() {
    integration_tests::wall_clock(|| {
        an_estop_input_mid_motion("ops-input-noext", false);
    });
}
