//! The drive boundary across the real processes: a configured drive fault cuts power and fails
//! the run with its events; a fault injected from another shell is reported as it happens; an
//! absurd axis is refused before anything starts; CSP axes follow the triangle.

use control_plane::channel::call;
use control_plane::status::Power;
use control_plane::{Refusal, Reply, Request};
use iceoryx2::prelude::Node;
use integration_tests::{
    assert_clean, assert_gone, examples, exited, instance, json_of, pids_with, run_with_watchdog,
    scratch, succeeded, succeeded_within, success, supervisor,
};
use runtime::ipc::{Ipc, Sub};
use shm_schema::drive::servo_status as st;
use shm_schema::{InstanceName, ServoStateV3};
use std::path::Path;
use std::process::{Child, Output, Stdio};
use std::time::{Duration, Instant};

pub(crate) const WATCHDOG: Duration = Duration::from_secs(180);

/// Runs the small triangle (a fifth of the seed's: its corners, its blends, 5 s instead of 19)
/// of `test` with the configuration file `cfg` on `inst`, `--json`; it must succeed.
fn small_triangle_json(test: &str, inst: &str, cfg: &Path) -> serde_json::Value {
    let out = succeeded_within(
        supervisor()
            .args(["run", "--json", "--instance", inst, "--config"])
            .arg(cfg)
            .arg(integration_tests::small_triangle(test)),
        WATCHDOG,
    );
    json_of(&out)
}

/// The run ended on the (small) triangle's start, every axis within the following-error limit.
fn on_target(j: &serde_json::Value) {
    for (axis, want) in [("x", 40.0), ("y", 40.0), ("theta", 0.0)] {
        let got = j["final_position"][axis].as_f64().expect("final");
        assert!((got - want).abs() <= 0.01, "{axis}: {got}");
        assert!(j["max_following_error"][axis].as_f64().expect("fe") < 1.0);
    }
}

/// `supervisor run` of the triangle on `inst` with a configuration file, in the background,
/// its stderr captured.
pub(crate) fn triangle_in_background_with(inst: &str, cfg: Option<&Path>) -> std::process::Child {
    triangle_in_background_as(inst, cfg, false)
}

/// The same, optionally with `--json` on stdout (captured).
pub(crate) fn triangle_in_background_as(
    inst: &str,
    cfg: Option<&Path>,
    json: bool,
) -> std::process::Child {
    program_in_background_as(inst, cfg, json, &examples().join("triangle.prog"))
}

/// `supervisor run` of `program` on `inst`, in the background, its stderr captured (stdout
/// too with `json`).
pub(crate) fn program_in_background_as(
    inst: &str,
    cfg: Option<&Path>,
    json: bool,
    program: &Path,
) -> std::process::Child {
    let mut cmd = supervisor();
    cmd.args(["run", "--instance", inst]);
    if json {
        cmd.arg("--json").stdout(Stdio::piped());
    } else {
        cmd.stdout(Stdio::null());
    }
    match cfg {
        Some(c) => cmd.arg("--config").arg(c),
        None => cmd
            .arg("--config")
            .arg(integration_tests::default_cell_file(inst)),
    };
    cmd.arg(program)
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn supervisor")
}

/// Waits (under the watchdog) for a background run to end.
pub(crate) fn wait_for(run: Child) -> Output {
    integration_tests::wait_output(run, WATCHDOG, "run did not end")
}

/// Waits (under the watchdog) for a background run `--json`, which must fail (exit 1): its
/// stderr and its report.
fn failed_run(run: Child) -> (String, serde_json::Value) {
    let out = wait_for(run);
    (exited(&out, 1), json_of(&out))
}

pub(crate) fn events_named<'a>(j: &'a serde_json::Value, name: &str) -> Vec<&'a serde_json::Value> {
    // A run's document (it says `ok`; a tuning report does not) is the one its type (and JSON
    // Schema) describes, completed or failed.
    if j.get("ok").is_some()
        && let Err(e) = serde_json::from_value::<control_plane::report::RunDocument>(j.clone())
    {
        panic!("the run's JSON is not the documented report ({e}): {j}");
    }
    j["events"]
        .as_array()
        .unwrap_or_else(|| panic!("no events in {j}"))
        .iter()
        .filter(|e| e["name"] == name)
        .collect()
}

#[test]
fn a_configured_drive_fault_cuts_power_and_fails_the_run_with_its_events() {
    integration_tests::wall_clock(|| {
        let inst = instance("inject-cfg");
        let mut inject = toml_edit::Table::new();
        inject.insert("axis", toml_edit::value("y"));
        inject.insert("fault", toml_edit::value("over-current"));
        inject.insert("at", toml_edit::value(2.0));
        let cfg = // The wall clock: its plot shows the wake-up latency histogram (empty on the virtual clock).
        integration_tests::wall_cell_with_room()
            .push("drives.inject", inject)
            .write("inject-cfg", "cell.toml");
        let plot = scratch("inject-cfg", "failed.png", "");
        let out = run_with_watchdog(
            supervisor()
                .args(["run", "--json", "--instance", &inst, "--config"])
                .arg(&cfg)
                .arg("--plot")
                .arg(&plot)
                .arg(examples().join("triangle.prog")),
            WATCHDOG,
        );
        let err = exited(&out, 1);
        // Why, as data: servo cut power on the drive's fault, on axis y.
        let j = json_of(&out);
        let cause = &j["cause"]["servo-fault"];
        assert_eq!(
            (cause["fault"].as_str(), cause["axis"].as_str()),
            (Some("drive-reports-fault"), Some("y")),
            "{j}"
        );
        // The figures up to the failure: x's first 2 s of motion, the processes' latency. (The
        // words are the subject: they name the file written.)
        assert!(
            err.contains(&format!("figures up to the failure: {}", plot.display())),
            "{err}"
        );
        crate::cell::check_figures(&plot, 4);
        // Printed as they happened (the words on stderr are the subject), and in the report.
        assert!(err.contains("fault-injected axis y"), "{err}");
        assert_eq!(j["ok"], false);
        let fault = events_named(&j, "drive-fault");
        assert!(
            fault.iter().any(|e| e["axis"] == "y"
                && e["value"].as_f64() == Some(0x2310 as f64)
                && e["source"] == "drives"),
            "{j}"
        );
        let cut = events_named(&j, "power-cut");
        assert_eq!(cut.len(), 1, "{j}");
        assert_eq!(cut[0]["source"], "servo");
        // Every axis lost power: the drive of y by its fault reaction (13), the others by
        // servo's quick stop (11).
        let transitions = events_named(&j, "drive-transition");
        for (axis, number) in [("y", 13), ("x", 11), ("theta", 11)] {
            assert!(
                transitions
                    .iter()
                    .any(|e| e["axis"] == axis && e["value"].as_f64() == Some(number as f64)),
                "{axis}: transition {number} missing in {transitions:?}"
            );
        }
        assert_gone(&inst);
    });
}

#[test]
fn a_fault_injected_from_another_shell_is_reported_as_it_happens() {
    integration_tests::wall_clock(|| {
        let inst = instance("inject-cmd");
        let run = triangle_in_background_as(&inst, None, true);
        // Wait until the arm is enabled, reading the instance's events from this shell.
        let start = Instant::now();
        loop {
            assert!(start.elapsed() < WATCHDOG, "the cell never enabled");
            let status = supervisor()
                .args(["status", "--json", "--instance", &inst])
                .output()
                .expect("status");
            let s = serde_json::from_slice::<control_plane::status::Status>(&status.stdout);
            if s.is_ok_and(|s| s.servo.is_some_and(|v| v.power == Power::Enabled)) {
                break;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        // A bad injection is refused by name (the axes of the running cell) and changes nothing.
        // `inject` asks no cell (it writes to the drives itself): its words, which name the
        // flag the user typed and the cell's axes, are the subject.
        let bad = supervisor()
            .args(["inject", "--instance", &inst, "--axis", "w", "over-current"])
            .output()
            .expect("inject");
        let why = exited(&bad, 2);
        assert!(
            why.contains("--axis \"w\": the cell has axes x, y, theta"),
            "{why}"
        );
        let out = succeeded(supervisor().args([
            "inject",
            "--instance",
            &inst,
            "--axis",
            "x",
            "encoder-loss",
        ]));
        assert_eq!(
            String::from_utf8_lossy(&out.stdout).trim(),
            format!("injected encoder-loss on axis x of instance {inst}")
        );
        let (err, j) = failed_run(run);
        let cause = &j["cause"]["servo-fault"];
        assert_eq!(
            (cause["fault"].as_str(), cause["axis"].as_str()),
            (Some("feedback-not-finite"), Some("x")),
            "{err}\n{j}"
        );
        // The drives acknowledged it (the tool waits for their event before it says so): in
        // the report, and printed as it happened (those words are the subject too).
        assert!(
            events_named(&j, "fault-injected")
                .iter()
                .any(|e| e["axis"] == "x"
                    && e["value"].as_f64() == Some(0x7320 as f64)
                    && e["source"] == "drives"),
            "{j}"
        );
        assert!(err.contains("fault-injected axis x: 0x7320"), "{err}");
        assert_clean(&inst);
    });
}

#[test]
fn an_absurd_inertia_is_refused_before_anything_starts() {
    integration_tests::wall_clock(|| {
        let inst = instance("inertia");
        let cfg = // The example file as it is (the error names its line).
        integration_tests::wall_cell_toml()
            .set("axis[x].sim.inertia", 1e-300)
            .write("inertia", "cell.toml");
        let out = run_with_watchdog(
            supervisor()
                .args(["run", "--instance", &inst, "--config"])
                .arg(&cfg)
                .arg(examples().join("triangle.prog")),
            WATCHDOG,
        );
        let err = exited(&out, 2);
        // The words are the subject: they name the file, the line and the column.
        assert!(
            err.contains(
                "cell.toml:32:9: axis x: sim inertia 1e-300 makes servo's position loop unstable"
            ),
            "{err}"
        );
        assert_gone(&inst);
    });
}

#[test]
fn csp_axes_follow_the_small_triangle_on_the_real_processes() {
    integration_tests::wall_clock(|| {
        let inst = instance("csp");
        // Room for stalls: the test is about CSP, not the cell's tolerance of them (a
        // supervisor held off a CPU 500 ms by the tests beside it failed it once).
        let cfg = integration_tests::with_stall_room(&integration_tests::cell_in_csp());
        let cfg = scratch("csp", "cell.toml", &cfg);
        let j = small_triangle_json("csp", &inst, &cfg);
        on_target(&j);
        assert!(j["sense_to_command_us"]["p50_us"].as_f64().expect("sense") > 0.0);
        assert_clean(&inst);
    });
}

#[test]
fn tune_steps_an_axis_of_the_real_cell_and_reports_its_response() {
    integration_tests::wall_clock(|| {
        let inst = instance("tune");
        let png = integration_tests::test_dir().join(format!("{inst}.png"));
        let out = succeeded_within(
            supervisor()
                .args([
                    "tune",
                    "--json",
                    "--instance",
                    &inst,
                    "--axis",
                    "y",
                    "--step",
                    "-0.2",
                    "--ramp",
                    "5",
                    "--plot",
                ])
                .arg(&png)
                // On the virtual clock: the test is about tune's figures, not the host's
                // stalls.
                .arg("--config")
                .arg(integration_tests::default_cell_file(&inst)),
            WATCHDOG,
        );
        let j = json_of(&out);
        let f = &j["step_response"];
        let rise = f["rise_s"].as_f64().expect("the axis rose");
        assert!(rise > 0.0, "{j}");
        assert!(f["settling_s"].as_f64().expect("it settled") >= rise, "{j}");
        assert!(
            f["overshoot_pct"].as_f64().expect("overshoot") < 50.0,
            "{j}"
        );
        assert!((f["peak_following_error"].as_f64().expect("fe") - 0.2).abs() < 0.01);
        let ramp = j["ramp"]["peak_following_error"].as_f64().expect("ramp");
        assert!(ramp > 0.0 && ramp < 1.0, "{j}");
        assert!(
            events_named(&j, "tune-step").len() == 2,
            "step and step back: {j}"
        );
        let bytes = std::fs::read(&png).expect("plot written");
        assert_eq!(&bytes[1..4], b"PNG");
        let _ = std::fs::remove_file(&png);
        assert_clean(&inst);

        // Bad requests are refused by name before anything starts (no cell is asked: the
        // words, which name the flag or the limit, are the subject).
        for (args, want) in [
            (
                vec!["--axis", "y", "--step", "0.8"],
                "at most half the following-error limit",
            ),
            (
                vec!["--axis", "w", "--step", "0.1"],
                "--axis \"w\": the cell has axes x, y, theta",
            ),
            (
                vec!["--axis", "x", "--step", "0.1", "--ramp", "500"],
                "would leave its range",
            ),
        ] {
            let out = supervisor()
                .args(["tune", "--instance", &inst])
                .args(&args)
                .output()
                .expect("tune");
            assert_eq!(out.status.code(), Some(2), "{args:?}");
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(err.contains(want), "{args:?}: {err}");
        }
        assert_clean(&inst);
    });
}

/// `tune` is a job of the supervisor's one loop: while it steps and ramps an axis, the control
/// channel answers (`status`) and refuses what would change the cell, saying why; `down` ends
/// the session with a controlled stop.
#[test]
fn while_tune_runs_the_control_channel_answers_and_refuses_changes_busy() {
    integration_tests::wall_clock(|| {
        let inst = instance("tune-busy");
        // On the virtual clock: no detector may trip on the way down (on the wall clock the
        // drives' pending-sequence detector tripped once, the machine loaded by the tests
        // beside it), and this test is about the control channel.
        let mut tune = supervisor()
            .args([
                "tune",
                "--json",
                "--instance",
                &inst,
                "--axis",
                "x",
                "--step",
                "0.2",
            ])
            .args(["--ramp", "30", "--config"])
            .arg(integration_tests::default_cell_file(&inst))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("tune");
        let start = Instant::now();
        let name = InstanceName::new(&inst).expect("an instance name");
        let mut busy = None;
        while busy.is_none() && tune.try_wait().expect("tune").is_none() {
            assert!(start.elapsed() < WATCHDOG, "tune did not end");
            // Before the session has the cell, a pause is refused for other causes (the
            // drives being enabled, no program): the variant says which.
            if let Ok(Reply::Refused(r @ Refusal::Tuning { .. })) = call(&name, &Request::Pause) {
                assert_eq!(r, Refusal::Tuning { axis: "x".into() });
                let words =
                    "busy: axis x is being tuned (`supervisor tune`); `supervisor down` ends it";
                assert_eq!(r.to_string(), words);
                busy = Some(r);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        assert!(busy.is_some(), "no request was refused busy while tune ran");
        // The channel answers meanwhile (tune may have ended since: then nothing is up).
        let status = supervisor()
            .args(["status", "--json", "--instance", &inst])
            .output()
            .expect("status");
        if tune.try_wait().expect("tune").is_none() {
            let j: control_plane::status::Status = serde_json::from_slice(&status.stdout)
                .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&status.stdout)));
            assert!(
                j.supervisor.arm.as_ref().is_some_and(|a| a.enabled),
                "{j:?}"
            );
            assert_eq!(j.supervisor.tuning.as_deref(), Some("x"), "{j:?}");
            // The CLI says a refusal with exit status 2, and with --json which (none when tune
            // ended meanwhile: the cell is then not up).
            let out = supervisor()
                .args(["pause", "--json", "--instance", &inst])
                .output()
                .expect("pause");
            assert_eq!(out.status.code(), Some(2), "{out:?}");
            if !out.stdout.is_empty() {
                let reply: Reply = serde_json::from_slice(&out.stdout).expect("a Reply");
                assert_eq!(reply, Reply::Refused(Refusal::Tuning { axis: "x".into() }));
            }
            // `down` ends the session: a controlled stop, not a fault; tune fails saying so.
            succeeded(supervisor().args(["down", "--instance", &inst]));
            let out = tune.wait_with_output().expect("tune");
            let err = exited(&out, 1);
            let failed: control_plane::report::RunFailure = serde_json::from_slice(&out.stdout)
                .unwrap_or_else(|e| panic!("tune --json: not a RunFailure ({e}): {err}"));
            assert!(
                matches!(failed.cause, control_plane::Failure::Down { .. }),
                "{failed:?}\n{err}"
            );
            // No fault on the way down: among the session's events (its closing included),
            // none is an error.
            assert!(!failed.events.is_empty(), "no events: {failed:?}");
            let errors = crate::up::errors(&failed.events);
            assert!(
                errors.is_empty(),
                "a fault on the way down: {errors:#?}\n{err}"
            );
        } else {
            success(tune.wait_with_output().expect("tune"), "tune");
        }
        assert_clean(&inst);
    });
}

#[test]
fn the_small_triangle_completes_with_servo_and_the_drives_at_4_khz() {
    integration_tests::wall_clock(|| {
        let inst = instance("4khz");
        // With room for the host's stalls and the other tests' cells beside it: once in a
        // CI run, iobridge's pending-sequence detector expired at its default limit while
        // five other tests ran (a browser among them).
        let cfg = integration_tests::at_rate(
            &integration_tests::with_stall_room(&integration_tests::default_cell()),
            250,
        );
        let cfg = scratch("4khz", "cell.toml", &cfg);
        let j = small_triangle_json("4khz", &inst, &cfg);
        assert_eq!(j["processes"]["servo"]["period_us"].as_f64(), Some(250.0));
        on_target(&j);
        // The drives measured it (its figures belong to the benchmark, not to a test).
        let s2c = j["sense_to_command_us"]["p50_us"].as_f64().expect("sense");
        assert!(s2c > 0.0, "{s2c}");
        assert_clean(&inst);
    });
}

#[test]
fn a_disable_request_from_another_process_stops_the_run_with_that_reason() {
    integration_tests::wall_clock(|| {
        use runtime::ipc::Pub;
        use shm_schema::{RequestKind, ServiceId, ServoRequestV1};
        let inst = instance("disable");
        let run = triangle_in_background_as(&inst, None, true);
        // Connect once the cell is up (an instance with a live client is refused by `run`).
        let (name, node) = client_of(&inst);
        let start = Instant::now();
        let requests =
            Pub::<ServoRequestV1>::new(&node, &name, ServiceId::ServoRequest).expect("pub");
        let state = Sub::<ServoStateV3>::new(&node, &name, ServiceId::ServoState, 64).expect("sub");
        // Wait until the arm is enabled and moving, then ask servo to disable it.
        loop {
            assert!(start.elapsed() < WATCHDOG, "the arm never moved");
            if state
                .latest()
                .is_some_and(|s| s.cmd_velocity[0].abs() > 1.0)
            {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let seq = 1_000_000 + u64::from(std::process::id());
        requests.update_connections();
        assert!(requests.send(&ServoRequestV1 {
            seq,
            kind: RequestKind::Disable as u32,
            axis: 0,
            value: 0.0,
        }));
        // Servo echoes the request and goes disabling, then disabled.
        let mut echoed = false;
        while !echoed {
            assert!(start.elapsed() < WATCHDOG, "servo never took the request");
            echoed = state.latest().is_some_and(|s| s.request_seq == seq);
            std::thread::sleep(Duration::from_millis(5));
        }
        let (err, j) = failed_run(run);
        assert_eq!(j["cause"]["disabled"]["power"], "disabling", "{err}\n{j}");
        // This test's node outlived the run: the files of the instance go with the last client.
        leave((requests, state), node, &name);
        assert_clean(&inst);
    });
}

/// The default cell with a supervisor heartbeat of 5 s, so a test can stall one process for
/// a while without the supervisor ending the run first.
fn patient_config(test: &str) -> std::path::PathBuf {
    // The stall is for servo's own rules to catch, not for the supervisor's heartbeat (either
    // way: a supervisor held off a CPU by the tests beside it stops no process) or the
    // health detectors (tested on their own in `health`).
    integration_tests::wall_cell_toml()
        .set("supervisor.heartbeat_timeout", 5.0)
        .set("supervisor.supervisor_timeout", 2.0)
        .set(
            "health_config.pending_sequence_overrun_percent_limit",
            100.0,
        )
        .write(test, "cell.toml")
}

/// Pid of `role`'s process of the run on `inst`, by its program's name (the supervisor's own
/// command line may hold the role's name too), waiting for it under the watchdog.
pub(crate) fn pid_of(role: &str, inst: &str) -> i32 {
    let start = Instant::now();
    loop {
        let pids: Vec<i32> = pids_with(&["--instance", inst])
            .into_iter()
            .filter(|pid| {
                std::fs::read(format!("/proc/{pid}/cmdline")).is_ok_and(|c| {
                    let argv0 = c.split(|b| *b == 0).next().unwrap_or_default();
                    Path::new(std::str::from_utf8(argv0).unwrap_or_default())
                        .file_name()
                        .is_some_and(|n| n == role)
                })
            })
            .collect();
        if let [pid] = pids[..] {
            return pid;
        }
        assert!(
            start.elapsed() < WATCHDOG,
            "{role} of {inst} not found: {pids:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits until servo of `inst` follows a motion (x faster than 1 mm/s); returns the port.
/// A run that ends first fails the test with its output.
fn until_moving(node: &Node<Ipc>, name: &InstanceName, run: &mut Child) -> Sub<ServoStateV3> {
    let state =
        Sub::<ServoStateV3>::new(node, name, shm_schema::ServiceId::ServoState, 1024).expect("sub");
    let start = Instant::now();
    while !state
        .latest()
        .is_some_and(|s| s.cmd_velocity[0].abs() > 1.0)
    {
        assert!(start.elapsed() < WATCHDOG, "the arm never moved");
        if let Some(status) = run.try_wait().expect("wait") {
            let mut err = String::new();
            if let Some(e) = run.stderr.as_mut() {
                let _ = std::io::Read::read_to_string(e, &mut err);
            }
            panic!("the run ended ({status}) before the arm moved:\n{err}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    state
}

/// Connects a node to `inst` once its cell is up (the supervisor and the five processes of
/// the default cell).
fn client_of(inst: &str) -> (InstanceName, Node<Ipc>) {
    let name = InstanceName::new(inst).expect("instance");
    let start = Instant::now();
    while runtime::ipc::live_node_pids(&name)
        .unwrap_or_default()
        .len()
        < 6
    {
        assert!(start.elapsed() < WATCHDOG, "the cell never came up");
        std::thread::sleep(Duration::from_millis(20));
    }
    let node = runtime::ipc::node(&name, "test-client").expect("node");
    (name, node)
}

/// This test's client leaves the instance `name`: its `ports`, then its `node`, then the
/// files of the instance that go with the last client.
fn leave<P>(ports: P, node: Node<Ipc>, name: &InstanceName) {
    drop(ports);
    drop(node);
    runtime::ipc::cleanup_after_client(name);
}

/// A node of this test's own on a running cell, reading servo's state.
pub(crate) struct Client {
    pub(crate) state: Sub<ServoStateV3>,
    node: Node<Ipc>,
    name: InstanceName,
}

impl Client {
    /// Connects once the cell of `inst` is up, then waits until servo follows a motion of
    /// `run` (which fails the test if it ends first).
    pub(crate) fn when_moving(inst: &str, run: &mut Child) -> Self {
        let (name, node) = client_of(inst);
        let state = until_moving(&node, &name, run);
        Self { state, node, name }
    }

    /// Leaves the instance (see [`leave`]).
    pub(crate) fn leave(self) {
        leave(self.state, self.node, &self.name);
    }
}

#[test]
fn servo_cuts_power_when_the_drives_process_stalls() {
    integration_tests::wall_clock(|| {
        let inst = instance("stall-machine");
        let mut run =
            triangle_in_background_as(&inst, Some(&patient_config("stall-machine")), true);
        let client = Client::when_moving(&inst, &mut run);
        // The drives' process stops (as a hung fieldbus would): its feedback stops coming.
        let machine = pid_of("machine-sim", &inst);
        // SAFETY: kill(2) on a process this test's supervisor started.
        unsafe { libc::kill(machine, libc::SIGSTOP) };
        let start = Instant::now();
        let mut latched = None;
        while latched.is_none() {
            assert!(start.elapsed() < WATCHDOG, "servo never noticed");
            latched = std::iter::from_fn(|| client.state.next())
                .find(|s| s.status & st::FAULT_LATCHED != 0);
            std::thread::sleep(Duration::from_millis(5));
        }
        // SAFETY: as above.
        unsafe { libc::kill(machine, libc::SIGCONT) };
        let s = latched.expect("latched");
        assert_eq!(s.fault_code, shm_schema::event::code::FEEDBACK_STALE);
        assert!(s.fault_value > s.fault_limit, "{s:?}");
        let (err, j) = failed_run(run);
        assert_eq!(
            j["cause"]["servo-fault"]["fault"], "feedback-stale",
            "{err}\n{j}"
        );
        client.leave();
        assert_clean(&inst);
    });
}

#[test]
fn servo_holds_the_axes_when_trajgen_stalls_mid_motion() {
    integration_tests::wall_clock(|| {
        let inst = instance("stall-trajgen");
        let mut run = triangle_in_background_with(&inst, Some(&patient_config("stall-trajgen")));
        let client = Client::when_moving(&inst, &mut run);
        // trajgen stops publishing in the middle of a move; servo must bring the axes to rest
        // along their path and hold, enabled, with nothing latched. (The supervisor ends the run
        // after its heartbeat timeout, here 5 s.)
        let trajgen = pid_of("trajgen", &inst);
        // SAFETY: kill(2) on a process this test's supervisor started.
        unsafe { libc::kill(trajgen, libc::SIGSTOP) };
        let start = Instant::now();
        let mut log = Vec::new();
        loop {
            assert!(start.elapsed() < WATCHDOG, "servo never came to rest");
            while let Some(s) = client.state.next() {
                log.push(s);
            }
            if log.last().is_some_and(|s| {
                s.status & st::SETPOINT_STALE != 0 && s.cmd_velocity[..3] == [0.0; 3]
            }) {
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        // SAFETY: as above.
        unsafe { libc::kill(trajgen, libc::SIGCONT) };
        assert!(
            log.iter().all(|s| s.status & st::FAULT_LATCHED == 0),
            "servo cut power"
        );
        let last = log.last().expect("states");
        assert_ne!(last.status & st::ENABLED, 0);
        for i in 0..3 {
            assert!(log.iter().all(|s| s.following_error[i].abs() < 1.0));
        }
        exited(&wait_for(run), 1);
        client.leave();
        assert_clean(&inst);
    });
}
