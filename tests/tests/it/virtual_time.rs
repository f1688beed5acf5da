//! The cell on its virtual clock (`--virtual-time`, docs/virtual-time.md): the same run every
//! time, decided on typed reports, never on the wall clock.

use control_plane::report::RunReport;
use integration_tests::{
    assert_clean, examples, exited, instance, json_of, run_with_watchdog, scratch, success,
    supervisor,
};
use std::time::Duration;

const WATCHDOG: Duration = Duration::from_secs(120);

/// How a run is put on the virtual clock.
#[derive(Clone, Copy, Debug)]
enum Asked {
    /// `supervisor run --virtual-time`.
    Flag,
    /// `[cell] clock = "virtual"` in the configuration.
    Config,
}

/// A port that was free a moment ago, for a Modbus server that must listen on the same port
/// in two runs (its `listening` event names it).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// `supervisor run --json --trace` of `program` on the default cell (its Modbus server on
/// `port`) on the virtual clock as `asked`: the report, as its type, and the trace's bytes.
fn run_virtual(
    test: &str,
    asked: Asked,
    port: u16,
    program: &std::path::Path,
) -> (RunReport, Vec<u8>) {
    let run = format!("{asked:?}").to_lowercase();
    let inst = instance(&format!("{test}-{run}"));
    let trace = scratch(test, &format!("{run}.csv"), "");
    let mut cell =
        integration_tests::wall_cell_toml().set("modbus.listen", format!("127.0.0.1:{port}"));
    let mut cmd = supervisor();
    cmd.args(["run", "--json", "--instance", &inst]);
    match asked {
        Asked::Flag => {
            cmd.arg("--virtual-time");
        }
        Asked::Config => cell = cell.add("cell.clock", "virtual"),
    }
    let out = run_with_watchdog(
        cmd.arg("--config")
            .arg(cell.write(test, &format!("{run}.toml")))
            .arg("--trace")
            .arg(&trace)
            .arg(program),
        WATCHDOG,
    );
    let out = success(out, "supervisor run --virtual-time");
    let report: RunReport = serde_json::from_value(json_of(&out))
        .unwrap_or_else(|e| panic!("the run's JSON is not the documented report: {e}"));
    assert_clean(&inst);
    (report, std::fs::read(&trace).expect("the trace"))
}

/// Same in, same out: the seed's triangle twice on the virtual clock gives byte-identical
/// traces and the same events (codes, values, time stamps, in the same order), and its
/// motion time is the theory's to the nanosecond (no late cycle can stretch it).
#[test]
fn the_seed_triangle_runs_the_same_twice_on_the_virtual_clock() {
    let test = "vt-twice";
    let program = examples().join("triangle.prog");
    let port = free_port();
    let (first, first_trace) = run_virtual(test, Asked::Flag, port, &program);
    let (second, second_trace) = run_virtual(test, Asked::Config, port, &program);
    assert!(!first_trace.is_empty());
    assert!(
        first_trace == second_trace,
        "the two traces differ ({} and {} bytes)",
        first_trace.len(),
        second_trace.len()
    );
    assert_eq!(first.events, second.events, "the two runs' events differ");
    for r in [&first, &second] {
        assert!(
            integration_tests::same_motion_time(r.measured_s, r.theoretical_s),
            "measured {} s, theoretical {} s",
            r.measured_s,
            r.theoretical_s
        );
        assert_eq!(r.lost_setpoints, 0);
        let v = r
            .virtual_time
            .expect("a run on the virtual clock says how fast it ran");
        assert!(v.virtual_s > r.theoretical_s, "{v:?}");
        assert!(v.cycles > 0, "{v:?}");
        // On the virtual clock no cycle is late: every wake-up is at its deadline.
        for (name, p) in &r.processes {
            assert_eq!(p.max_wakeup_latency_us, 0.0, "{name}: {p:?}");
            assert_eq!(p.overruns, 0, "{name}: {p:?}");
        }
    }
    assert_eq!(
        (first.measured_s, first.max_following_error.clone()),
        (second.measured_s, second.max_following_error.clone())
    );
}

/// A cell with an EtherCAT bus cannot be stepped: `[cell] clock = "virtual"` beside
/// `[ethercat]` is refused by check-config, on the key's line.
#[test]
fn an_ethercat_cell_on_the_virtual_clock_is_refused_naming_the_key() {
    let test = "vt-ethercat";
    let example =
        std::fs::read_to_string(examples().join("gantry-ethercat.toml")).expect("example");
    let mut cell = integration_tests::CellToml::parse(&example);
    cell = cell.add("cell.clock", "virtual");
    let cfg = cell.write(test, "cell.toml");
    let out = run_with_watchdog(supervisor().args(["check-config"]).arg(&cfg), WATCHDOG);
    let said = exited(&out, 2);
    // Placed on the line of the key.
    let line = 1 + std::fs::read_to_string(&cfg)
        .expect("the configuration")
        .lines()
        .position(|l| l.starts_with("clock = "))
        .expect("the clock's line");
    assert!(said.contains(&format!("cell.toml:{line}:")), "{said}");
}

/// A process in another language on the virtual clock (docs/virtual-time.md, "A process in
/// another language"): the default cell's iobridge replaced by the Python one
/// (`examples/python/iobridge.py`, on stock iceoryx2 bindings: it polls the grants and
/// reports without notifying). The seed's triangle still takes the theory's time to the
/// nanosecond, the Python process ran its cycles at their deadlines and its fieldbus images
/// reached the supervisor.
#[test]
fn a_python_iobridge_polling_the_virtual_clock_takes_part_in_the_seed_triangle() {
    integration_tests::require_python_iceoryx2();
    let test = "vt-python";
    let cfg = integration_tests::with_python_iobridge(integration_tests::wall_cell_toml())
        .write(test, "cell.toml");
    let inst = instance(test);
    let out = run_with_watchdog(
        supervisor()
            .args(["run", "--virtual-time", "--json", "--instance", &inst])
            .arg("--config")
            .arg(&cfg)
            .arg(examples().join("triangle.prog")),
        WATCHDOG,
    );
    let out = success(out, "supervisor run --virtual-time, the Python iobridge");
    let r: RunReport = serde_json::from_value(json_of(&out))
        .unwrap_or_else(|e| panic!("the run's JSON is not the documented report: {e}"));
    assert!(
        integration_tests::same_motion_time(r.measured_s, r.theoretical_s),
        "measured {} s, theoretical {} s",
        r.measured_s,
        r.theoretical_s
    );
    assert!(
        r.virtual_time.is_some(),
        "a run on the virtual clock says how fast it ran"
    );
    let iobridge = r
        .processes
        .get("iobridge")
        .unwrap_or_else(|| panic!("no iobridge in the report: {:?}", r.processes.keys()));
    assert!(iobridge.cycles > 0, "{iobridge:?}");
    // Woken by the clock's grant of its deadline, never late.
    assert_eq!(iobridge.max_wakeup_latency_us, 0.0, "{iobridge:?}");
    assert!(
        r.iobridge_delay_us.is_some(),
        "no fieldbus image reached the supervisor: {iobridge:?}"
    );
    assert_clean(&inst);
}

/// `supervisor run --virtual-time --json --fault FAULT` of the seed's triangle on the default
/// cell, expected to fail: its failure, as its type.
fn run_failing_with(test: &str, run: &str, fault: &str) -> control_plane::report::RunFailure {
    let inst = instance(&format!("{test}-{run}"));
    let out = run_with_watchdog(
        supervisor()
            .args(["run", "--virtual-time", "--json", "--instance", &inst])
            .args(["--fault", fault, "--config"])
            .arg(integration_tests::wall_cell_file(test))
            .arg(examples().join("triangle.prog")),
        WATCHDOG,
    );
    exited(&out, 1);
    let failure = serde_json::from_value(json_of(&out))
        .unwrap_or_else(|e| panic!("the run's JSON is not the documented failure: {e}"));
    assert_clean(&inst);
    failure
}

/// The stamp of the first event of `source` with `code`.
fn stamp_of(events: &[control_plane::event::Event], source: &str, code: u32) -> u64 {
    events
        .iter()
        .find(|e| e.source == source && e.code == code)
        .unwrap_or_else(|| panic!("no event {code} of {source} in {events:?}"))
        .stamp_ns
}

/// An e-stop scheduled at 5 s of the triangle: servo begins its reaction within one servo
/// period, brings the reference to rest in `estop_stop_time` and has the drives disabled one
/// servo period later: the same instants in two runs.
#[test]
fn a_scheduled_estop_is_reacted_to_at_the_same_instants_every_run() {
    use shm_schema::event::code;
    let test = "vt-estop";
    let cfg = cell_config::Config::default_cell();
    let servo_period_ns = (cfg.period_s("servo") * 1e9).round() as u64;
    let stop_ns = (cfg.motion.estop_stop_time * 1e9).round() as u64;
    let at = runtime::vclock::EPOCH_NS + 5_000_000_000;
    let mut instants = Vec::new();
    for run in ["a", "b"] {
        let f = run_failing_with(test, run, "5:estop");
        assert!(
            matches!(f.cause, control_plane::Failure::Estop { .. }),
            "{:?}",
            f.cause
        );
        let disabling = stamp_of(&f.events, "servo", code::DISABLING);
        let disabled = stamp_of(&f.events, "servo", code::DISABLED);
        assert!(
            (at..=at + servo_period_ns).contains(&disabling),
            "servo began its reaction at {disabling} ns, the e-stop was at {at} ns"
        );
        assert_eq!(disabled - disabling, stop_ns + servo_period_ns);
        instants.push((disabling, disabled));
    }
    assert_eq!(instants[0], instants[1]);
}

/// A process killed at an instant: the supervisor finds it lost at that instant (its
/// process-lost event stamped with it), and the run fails naming it.
#[test]
fn a_process_killed_at_an_instant_is_lost_at_that_instant() {
    use shm_schema::event::code;
    let test = "vt-kill";
    let f = run_failing_with(test, "a", "5:kill:trajgen");
    assert!(
        matches!(&f.cause, control_plane::Failure::Exited { process, .. } if process == "trajgen"),
        "{:?}",
        f.cause
    );
    let lost = stamp_of(&f.events, "supervisor", code::PROCESS_LOST);
    assert_eq!(lost, runtime::vclock::EPOCH_NS + 5_000_000_000);
}

/// A hold of trajgen longer than `setpoint_timeout` mid-motion: servo brings the reference to
/// rest when the setpoints stop (its setpoint-stale event, 50 ms after the last), trajgen's
/// held cycle is counted an overrun, and the setpoint that comes after the hold is refused as
/// a jump (the generator's time went on): every instant the same in two runs.
#[test]
fn a_held_trajgen_is_met_by_servo_at_the_same_instants_every_run() {
    use shm_schema::event::code;
    let test = "vt-hold";
    let mut seen = Vec::new();
    for run in ["a", "b"] {
        let f = run_failing_with(test, run, "5:hold:trajgen:100");
        let stale = stamp_of(&f.events, "servo", code::SETPOINT_STALE);
        let overrun = stamp_of(&f.events, "trajgen", code::OVERRUN_BURST);
        let jump = stamp_of(&f.events, "servo", code::SETPOINT_JUMP);
        let at = runtime::vclock::EPOCH_NS + 5_000_000_000;
        assert!(at < stale && stale < at + 100_000_000, "{stale}");
        assert!(
            overrun >= at + 100_000_000 && overrun < jump,
            "{overrun} {jump}"
        );
        seen.push((stale, overrun, jump));
    }
    assert_eq!(seen[0], seen[1]);
}

/// While a program is validated the virtual clock stands (a validation takes no virtual
/// time) but the supervisor goes on answering: `status` says what it validates, a second
/// program is refused, and `down` ends the validation.
#[test]
fn the_virtual_clock_stands_while_a_program_is_validated_and_the_cell_answers() {
    use crate::up::Up;
    let test = "vt-validation";
    let up = Up::start(
        test,
        &integration_tests::virtual_cell_toml().write(test, "cell.toml"),
    );
    // 23 hours of motion without a loop: seconds of validation, ended by `down`.
    let mut src = String::from("MOVE(40,40,0)\n");
    for k in 0..23 {
        src += &format!("MOVE({},40,0,T=3600)\n", if k % 2 == 0 { 140 } else { 40 });
    }
    src += "END\n";
    let prog = scratch(test, "long.prog", &src);
    let mut exec = integration_tests::Reaped::spawn(
        supervisor()
            .args(["exec"])
            .arg(&prog)
            .args(["--instance", &up.inst])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null()),
        "exec",
    );
    let instance = shm_schema::InstanceName::new(&up.inst).expect("instance");
    let status = || match control_plane::channel::call(&instance, &control_plane::Request::Status) {
        Ok(control_plane::Reply::Status(s)) => s,
        other => panic!("status: {other:?}"),
    };
    let servo_cycles = |s: &control_plane::status::Status| s.processes["servo"].cycles;
    let start = std::time::Instant::now();
    let first = loop {
        let s = status();
        if s.supervisor.validating.is_some() {
            break s;
        }
        assert!(
            start.elapsed() < WATCHDOG,
            "the program was never validated"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let busy = up.refused(&[
        "exec",
        examples().join("triangle.prog").to_str().expect("path"),
    ]);
    assert!(busy.contains("long.prog is being validated"), "{busy}");
    std::thread::sleep(Duration::from_millis(200));
    let second = status();
    assert!(
        second.supervisor.validating.is_some(),
        "the validation ended before the test could look"
    );
    // A status is read once per supervisor tick; the clock stands, so no cycle ran between.
    assert_eq!(
        servo_cycles(&first),
        servo_cycles(&second),
        "the cell's clock moved while the program was validated"
    );
    up.down();
    let _ = exec.wait();
}

/// Same in, same out, recorded: the small triangle recorded twice on the virtual clock at full
/// speed. The recorder takes part in the clock, so none of its samples is lost however fast
/// the clock runs, and the two files hold the same messages at the same log times on every
/// topic but those that carry what only the machine knows (the processes' pids and the CPU
/// time their cycles took: the status, execution-time and heartbeat topics), which still hold
/// as many messages at the same log times.
#[test]
fn two_recordings_of_a_run_on_the_virtual_clock_hold_the_same_messages() {
    let test = "vt-rec";
    let port = free_port();
    let program = integration_tests::small_triangle(test);
    let record = |run: &str| -> serde_json::Value {
        let inst = instance(&format!("{test}-{run}"));
        let mcap = scratch(test, &format!("{run}.mcap"), "");
        let cell =
            integration_tests::wall_cell_toml().set("modbus.listen", format!("127.0.0.1:{port}"));
        let out = run_with_watchdog(
            supervisor()
                .args([
                    "run",
                    "--json",
                    "--virtual-time",
                    "--instance",
                    &inst,
                    "--config",
                ])
                .arg(cell.write(test, &format!("{run}.toml")))
                .arg("--record")
                .arg(&mcap)
                .arg(&program),
            WATCHDOG,
        );
        let out = success(out, "supervisor run --virtual-time --record");
        let report: RunReport = serde_json::from_value(json_of(&out))
            .unwrap_or_else(|e| panic!("the run's JSON is not the documented report: {e}"));
        assert!(report.virtual_time.is_some(), "{report:?}");
        assert_clean(&inst);
        crate::recording::read_back(&[mcap])
    };
    let (first, second) = (record("first"), record("second"));
    let topics = |r: &serde_json::Value| {
        r["topics"]
            .as_object()
            .expect("topics")
            .iter()
            .map(|(t, v)| (t.clone(), v.clone()))
            .collect::<std::collections::BTreeMap<_, _>>()
    };
    let (a, b) = (topics(&first), topics(&second));
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "the same topics"
    );
    let machine_only =
        |t: &str| t.ends_with("/status") || t.ends_with("/exec_time") || t == "/host/state";
    let mut compared = 0;
    for (t, x) in &a {
        let y = &b[t];
        assert_eq!(x["count"], y["count"], "{t}: as many messages");
        if !machine_only(t) {
            assert_eq!(
                x["timed_digest"], y["timed_digest"],
                "{t}: the same messages at the same log times"
            );
            compared += 1;
        }
    }
    for t in [
        "/trajgen/setpoint",
        "/servo/state",
        "/drives/feedback",
        "/io/state",
    ] {
        assert!(a[t]["count"].as_u64().unwrap_or(0) > 100, "{t}: {}", a[t]);
    }
    assert!(compared >= 15, "{compared} topics compared");
    // Log times on the cell's clock: from its epoch, one second after the Unix epoch, and
    // within the run's few seconds of the cell's time.
    for t in ["/trajgen/setpoint", "/servo/state", "/host/state"] {
        let at = a[t]["first_log_time"].as_u64().expect("a log time");
        assert!(
            (runtime::vclock::EPOCH_NS..runtime::vclock::EPOCH_NS + 60_000_000_000).contains(&at),
            "{t}: first logged at {at} ns"
        );
    }
}
