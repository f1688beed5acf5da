//! `supervisor latency` and `supervisor status` as a user runs them: real processes, each test
//! on its own instance, no timing bounds (only a watchdog against a stuck run).

use integration_tests::{assert_clean, bin, instance, json_of, run_with_watchdog, wait_output};
use latency::histfile;
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const WATCHDOG: Duration = Duration::from_secs(120);

/// Below every process of a cell (iobridge runs at 60): the cell tests running alongside
/// must not wait for a measuring thread.
const PRIORITY: &str = "50";

fn supervisor() -> Command {
    Command::new(bin("supervisor"))
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Sane figures: samples, and min <= p50 <= p99 <= p99.9 <= p99.99 <= max.
fn check_figures(what: &str, s: &Value) -> u64 {
    let v = |k: &str| {
        s[k].as_f64()
            .unwrap_or_else(|| panic!("{what}: {k} missing in {s}"))
    };
    let n = s["samples"].as_u64().expect("samples");
    assert!(n > 0, "{what}: no samples: {s}");
    let chain = [
        "min_us",
        "p50_us",
        "p99_us",
        "p99_9_us",
        "p99_99_us",
        "max_us",
    ];
    for w in chain.windows(2) {
        assert!(v(w[0]) <= v(w[1]), "{what}: {} > {}: {s}", w[0], w[1]);
    }
    assert!(
        v("min_us") <= v("avg_us") && v("avg_us") <= v("max_us"),
        "{what}: {s}"
    );
    n
}

fn cpus() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

#[test]
fn a_short_latency_run_gives_sane_figures_and_files_and_leaves_nothing() {
    integration_tests::wall_clock(|| {
        let inst = instance("latency");
        let dir = integration_tests::test_dir().join(&inst);
        std::fs::create_dir_all(&dir).expect("temp dir");
        let (hist, png) = (dir.join("lat.hist"), dir.join("lat.png"));
        let out = run_with_watchdog(
            supervisor()
                .args([
                    "latency",
                    "--duration",
                    "1",
                    "--test",
                    "timer,ipc,pipe",
                    "--json",
                ])
                .args(["--priority", PRIORITY])
                .args([
                    "--interval-us",
                    "500",
                    "--histogram-us",
                    "2000",
                    "--instance",
                    &inst,
                ])
                .arg("--histfile")
                .arg(&hist)
                .arg("--plot")
                .arg(&png),
            WATCHDOG,
        );
        assert!(out.status.success(), "{}", stderr(&out));
        let j = json_of(&out);
        assert_eq!(j["interval_us"].as_u64(), Some(500));
        assert_eq!(j["interrupted"].as_bool(), Some(false));
        let mut samples = Vec::new();
        for (test, expected) in [
            ("timer", cpus()),
            ("ipc", cpus().min(2)),
            ("pipe", cpus().min(2)),
        ] {
            let series = j["tests"][test]["series"]
                .as_array()
                .unwrap_or_else(|| panic!("{test} missing: {j}"));
            assert_eq!(series.len(), expected, "{test}: {j}");
            for s in series {
                let n = check_figures(test, s);
                samples.push((n, s["overflows"].as_u64().expect("overflows")));
                assert!(
                    s["cpu"].as_i64().expect("cpu") >= 0,
                    "{test} not pinned: {s}"
                );
            }
        }
        // The cross-CPU hop goes from the first CPU to the last, the other stays on one.
        if cpus() > 1 {
            let ipc = &j["tests"]["ipc"]["series"];
            assert_ne!(ipc[0]["cpu"], ipc[0]["tx_cpu"]);
            assert_eq!(ipc[1]["cpu"], ipc[1]["tx_cpu"]);
        }

        // The histogram file: one column per series in the same order, every sample in a bin
        // or counted as an overflow.
        let cols =
            histfile::parse(&std::fs::read_to_string(&hist).expect("histfile")).expect("parses");
        assert_eq!(cols.len(), samples.len());
        for (c, (n, ovf)) in cols.iter().zip(&samples) {
            assert_eq!(c.bins.len(), 2000);
            assert_eq!(c.overflows, *ovf);
            assert_eq!(c.total + c.overflows, *n);
        }
        let png_bytes = std::fs::read(&png).expect("plot written");
        assert_eq!(&png_bytes[..8], b"\x89PNG\r\n\x1a\n");
        let _ = std::fs::remove_dir_all(&dir);
        assert_clean(&inst);
    });
}

#[test]
fn ctrl_c_prints_the_figures_so_far() {
    integration_tests::wall_clock(|| {
        let inst = instance("latint");
        // Interrupted once it says every timer thread measured (READY=1).
        let ready = integration_tests::Readiness::new("latint");
        let mut child = ready
            .tell(&mut supervisor())
            .args(["latency", "--test", "timer,ipc", "--instance", &inst])
            .args(["--priority", PRIORITY])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn");
        ready.wait(&mut child, WATCHDOG);
        // SAFETY: kill(2) on our own child.
        unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
        let out = wait_output(child, WATCHDOG, "latency did not stop on SIGINT");
        assert!(out.status.success(), "{}", stderr(&out));
        let text = String::from_utf8_lossy(&out.stdout);
        // cyclictest's text format is the subject: what it says, line by line.
        assert!(text.contains("# interrupted: figures so far"), "{text}");
        let line = text
            .lines()
            .find(|l| l.starts_with("T: 0"))
            .expect("thread 0 line");
        let count: u64 = line
            .split("C:")
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|c| c.parse().ok())
            .expect("a sample count");
        assert!(count > 0, "{line}");
        // Interrupted during the timer test: the IPC hop never ran.
        assert!(!text.contains("\nI:"), "{text}");
        assert_clean(&inst);
    });
}

#[test]
fn bad_latency_options_are_refused_by_name() {
    integration_tests::wall_clock(|| {
        for (args, needle) in [
            (vec!["--test", "timer,bogus"], "--test \"bogus\""),
            (vec!["--interval-us", "5"], "--interval-us 5"),
            (vec!["--duration", "0"], "--duration \"0\""),
            (vec!["--priority", "120"], "--priority 120"),
            (vec!["--phase-us", "1000"], "--phase-us 1000"),
            (vec!["--histfile", "/no/such/folder/h.txt"], "--histfile"),
        ] {
            let out = run_with_watchdog(supervisor().arg("latency").args(&args), WATCHDOG);
            assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
            // Refused by name: the words, which name the option the user typed, are the
            // subject.
            assert!(stderr(&out).contains(needle), "{args:?}: {}", stderr(&out));
            assert!(out.stdout.is_empty(), "{args:?} measured something");
        }
    });
}

#[test]
fn status_reports_the_running_cell_and_its_latency() {
    integration_tests::wall_clock(|| {
        let inst = instance("status");
        let none = run_with_watchdog(supervisor().args(["status", "--instance", &inst]), WATCHDOG);
        assert_eq!(none.status.code(), Some(2));
        // No cell answered: the client's words are all there is.
        assert!(stderr(&none).contains("is not up"), "{}", stderr(&none));

        let prog = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/triangle.prog");
        let mut run = supervisor()
            .args(["run", "--instance", &inst, "--config"])
            // The wall clock: the latency it reports is the wall clock's.
            .arg(integration_tests::wall_cell_with_room().write("status", "cell.toml"))
            .arg(&prog)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn supervisor run");
        let start = Instant::now();
        let j = loop {
            assert!(start.elapsed() < WATCHDOG, "status never showed the cell");
            assert!(
                run.try_wait().expect("wait").is_none(),
                "the run ended early"
            );
            let out = run_with_watchdog(
                supervisor().args(["status", "--json", "--instance", &inst]),
                WATCHDOG,
            );
            if out.status.success() {
                let j = json_of(&out);
                let ready = ["drives", "servo", "trajgen", "iobridge"].iter().all(|p| {
                    j["processes"][p]["state"] == "cyclic"
                        && j["processes"][p]["wakeup_latency_us"]["samples"].as_u64() > Some(0)
                }) && j["processes"]["modbus"]["state"] == "cyclic";
                if ready {
                    break j;
                }
            }
            std::thread::sleep(Duration::from_millis(200));
        };
        // The document is the one its type (and so its JSON Schema) describes.
        let typed: control_plane::status::Status =
            serde_json::from_value(j.clone()).expect("status --json is the documented Status");
        assert_eq!(typed.instance, inst);
        for p in ["drives", "servo", "trajgen", "iobridge"] {
            assert_eq!(typed.processes[p].policy, "SCHED_FIFO");
            let proc_ = &j["processes"][p];
            assert_eq!(proc_["policy"], "SCHED_FIFO", "{p}: {proc_}");
            assert!(proc_["cycles"].as_u64() > Some(0), "{p}: {proc_}");
            check_figures(p, &proc_["wakeup_latency_us"]);
        }
        // The supervisor's loop, which publishes the heartbeat, runs above ordinary work
        // (`[supervisor] priority`, 10), where the host grants it; modbus (priority 0),
        // started from that loop, runs under SCHED_OTHER all the same (SCHED_RESET_ON_FORK).
        let me = runtime::rt::sched_of(run.id() as i32);
        assert_eq!(
            me,
            Some((1, 10)),
            "the supervisor's loop: (policy, priority)"
        );
        let loop_ = (typed.supervisor.policy.as_str(), typed.supervisor.priority);
        assert_eq!(loop_, ("SCHED_FIFO", 10), "status says so");
        assert_eq!(typed.processes["modbus"].policy, "SCHED_OTHER");
        let modbus = typed.processes["modbus"].pid as i32;
        assert_eq!(runtime::rt::sched_of(modbus), Some((0, 0)), "modbus");
        let table = run_with_watchdog(supervisor().args(["status", "--instance", &inst]), WATCHDOG);
        let text = String::from_utf8_lossy(&table.stdout);
        // The table for people: its words are the subject (the JSON's figures are checked
        // above through their type).
        assert!(
            text.contains("p99.99") && text.lines().any(|l| l.starts_with("servo")),
            "{text}"
        );
        assert!(
            text.contains("loop SCHED_FIFO 10), e-stop resets"),
            "{text}"
        );

        // SAFETY: kill(2) on our own child.
        unsafe { libc::kill(run.id() as i32, libc::SIGINT) };
        while run.try_wait().expect("wait").is_none() {
            assert!(start.elapsed() < WATCHDOG, "run did not stop on SIGINT");
            std::thread::sleep(Duration::from_millis(20));
        }
        let out = run.wait_with_output().expect("output");
        assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
        assert_clean(&inst);
    });
}
