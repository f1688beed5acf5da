//! The MCAP recorder on the real binaries (docs/recording.md): a run recorded with `--record`
//! read back by an independent reader (the `mcap` package from PyPI) has every setpoint of
//! the trace; `supervisor record` attaches to a cell that is up, rotates its files, and an
//! observer that stays to the end of a run neither fails it nor is left behind; the cell
//! answers and beats while its recorder finishes its file.

use crate::drives::WATCHDOG;
use crate::up::{Up, cell};
use integration_tests::{
    assert_clean, exited, first_line, instance, json_of, needed, run_with_watchdog, scratch,
    succeeded_within, success, supervisor, trace_rows,
};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// `tests/python/mcap_read.py` over `files`: topics and setpoints.
pub(crate) fn read_back(files: &[PathBuf]) -> Value {
    let out = succeeded_within(
        Command::new("python3")
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("python/mcap_read.py"))
            .args(files),
        WATCHDOG,
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

#[test]
fn a_recorded_run_has_every_setpoint_of_its_trace_with_schemas_an_independent_reader_decodes() {
    integration_tests::wall_clock(|| {
        let test = "rec-run";
        let inst = instance(test);
        let mcap = scratch(test, "run.mcap", "");
        let trace = scratch(test, "trace.csv", "");
        let out = run_with_watchdog(
            supervisor()
                .args(["run", "--json", "--instance", &inst, "--config"])
                .arg(crate::up::cell(test, &[]))
                .arg("--record")
                .arg(&mcap)
                .arg("--trace")
                .arg(&trace)
                .arg(integration_tests::small_triangle(test)),
            WATCHDOG,
        );
        let report = json_of(&out);
        assert_eq!(report["ok"], true, "{report}");
        // The recorder's summary, per topic (the setpoints' loss is checked below, one to one).
        let stderr = String::from_utf8_lossy(&out.stderr);
        let line = stderr
            .lines()
            .find(|l| l.trim_start().starts_with("/trajgen/setpoint"))
            .unwrap_or_else(|| panic!("no summary: {stderr}"));
        println!("recorder: {}", line.trim());
        assert_clean(&inst);
        let file = read_back(&[mcap]);
        let topics = file["topics"].as_object().expect("topics");
        for t in [
            "/trajgen/setpoint",
            "/servo/state",
            "/drives/feedback",
            "/servo/drive_command",
            "/iobridge/output",
            "/io/state",
            "/events",
            "/host/state",
            "/servo/status",
            "/servo/latency",
            "/modbus/status",
        ] {
            let topic = &topics[t];
            assert!(topic["count"].as_u64().unwrap_or(0) > 0, "{t}: {topic}");
            assert_eq!(topic["schema_encoding"], "jsonschema", "{t}");
            assert_eq!(topic["encoding"], "json", "{t}");
            if t != "/events" {
                assert_eq!(topic["in_order"], true, "{t}: log times from the samples");
            }
        }
        // Every setpoint of the program, as the trace has it (one trace row per setpoint).
        let rows = trace_rows(&trace);
        let setpoints = file["setpoints"].as_array().expect("setpoints");
        let program = setpoints
            .iter()
            .filter_map(|s| s[0].as_u64())
            .max()
            .expect("a program");
        let ours: Vec<&Value> = setpoints.iter().filter(|s| s[0] == program).collect();
        println!(
            "{} setpoints of program {program} recorded, {} trace rows",
            ours.len(),
            rows.len()
        );
        // The trace holds the job's setpoints (trajgen goes on publishing after it while the
        // axes settle): over the trace's span the recording has exactly its rows, one to one.
        let same = |s: &Value, r: &[f64]| {
            let p = &s[3];
            let pos = [&p["x"], &p["y"], &p["theta"]].map(|v| v.as_f64().unwrap_or(f64::NAN));
            (s[1].as_f64().unwrap_or(f64::NAN) - r[0]).abs() <= 1e-6
                && (0..3).all(|k| (pos[k] - r[1 + k]).abs() <= 1e-6)
        };
        let first = ours
            .iter()
            .position(|s| same(s, &rows[0]))
            .expect("the trace's first setpoint is recorded");
        assert!(
            ours.len() - first >= rows.len(),
            "too few setpoints recorded"
        );
        for (k, r) in rows.iter().enumerate() {
            let s = ours[first + k];
            assert!(
                same(s, r),
                "setpoint {k} of the trace: recorded {s}, traced {r:?}"
            );
        }
    });
}

#[test]
fn record_attaches_to_a_cell_that_is_up_and_rotates_its_files() {
    integration_tests::wall_clock(|| {
        let test = "rec-up";
        let up = Up::default_cell(test);
        let base = scratch(test, "cell.mcap", "");
        // Rotated every second: stopped once its third file is there (however long the host's
        // stalls make that).
        let recorder = supervisor()
            .args(["record", "--instance", &up.inst, "--out"])
            .arg(&base)
            .args(["--rotate-time", "1"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("supervisor record");
        let start = Instant::now();
        while !base.with_file_name("cell-002.mcap").exists() {
            assert!(start.elapsed() < WATCHDOG, "no third file");
            std::thread::sleep(Duration::from_millis(50));
        }
        nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(recorder.id() as i32),
            nix::sys::signal::Signal::SIGINT,
        )
        .expect("stop the recorder");
        let out = integration_tests::wait_output(recorder, WATCHDOG, "the recorder stops");
        assert!(out.status.success(), "{out:?}");
        let text = String::from_utf8_lossy(&out.stdout).to_string();
        assert!(text.contains("(stopped)"), "{text}");
        let files: Vec<PathBuf> = (0..10)
            .map(|k| base.with_file_name(format!("cell-{k:03}.mcap")))
            .filter(|f| f.exists())
            .collect();
        assert!(files.len() >= 3, "rotated every second: {files:?}\n{text}");
        let read = read_back(&files);
        let servo = read["topics"]["/servo/state"]["count"]
            .as_u64()
            .unwrap_or(0);
        assert!(servo > 1000, "{}", read["topics"]);
        // The cell noticed nothing; it goes down clean.
        let s = up.status();
        assert!(s["supervisor"]["estop"].is_null(), "{s}");
        // A cell that is not up: exit 2 and a clear word.
        let gone = run_with_watchdog(
            supervisor()
                .args(["record", "--instance", "nobody-here", "--out"])
                .arg(&base),
            WATCHDOG,
        );
        assert!(exited(&gone, 2).contains("is not up"));
        let inst = up.inst.clone();
        up.down();
        // `up --record` where no file can be written: refused before anything starts (exit 2,
        // the flag named), nothing of the instance left.
        let refused = run_with_watchdog(
            supervisor()
                .args([
                    "up",
                    "--instance",
                    &inst,
                    "--record",
                    "/nonexistent/dir/c.mcap",
                ])
                .arg("--config")
                .arg(crate::up::cell(test, &[])),
            WATCHDOG,
        );
        let err = exited(&refused, 2);
        assert!(err.contains("--record /nonexistent/dir/c.mcap"), "{err}");
        integration_tests::assert_clean(&inst);
    });
}

#[test]
fn an_observer_that_stays_to_the_end_of_a_run_neither_fails_it_nor_is_left_behind() {
    integration_tests::wall_clock(|| {
        let test = "rec-observer";
        let inst = instance(test);
        // Killed if the test fails before they end (the program waits for a part).
        let run = integration_tests::Reaped::spawn(
            supervisor()
                .args(["run", "--json", "--instance", &inst, "--config"])
                .arg(cell(test, &[]))
                .arg(scratch(
                    test,
                    "p.prog",
                    "WAIT(part_present, 1)\nMOVE(60, 40, 0)\nEND\n",
                ))
                .stdout(Stdio::piped())
                .stderr(Stdio::piped()),
            "run",
        );
        // Attach once the cell is up.
        let start = Instant::now();
        while !supervisor()
            .args(["status", "--json", "--instance", &inst])
            .output()
            .is_ok_and(|o| o.status.success())
        {
            assert!(start.elapsed() < WATCHDOG, "the cell never came up");
            std::thread::sleep(Duration::from_millis(50));
        }
        let file = scratch(test, "observer.mcap", "");
        let mut observer = integration_tests::Reaped::spawn(
            supervisor()
                .args(["record", "--instance", &inst, "--out"])
                .arg(&file)
                .stdout(Stdio::piped())
                .stderr(Stdio::piped()),
            "record",
        );
        // The program waits for the part until the observer records.
        let first = first_line(&mut observer);
        assert!(first.starts_with("recording"), "{first}");
        succeeded_within(
            supervisor().args(["io", "part_present", "1", "--instance", &inst]),
            WATCHDOG,
        );
        let out = run.into_child().wait_with_output().expect("run");
        let report = json_of(&out);
        assert_eq!(out.status.code(), Some(0), "{report}");
        assert_eq!(report["ok"], true, "{report}");
        // The observer ends by itself once the cell is gone, and leaves nothing.
        let obs = success(
            observer.into_child().wait_with_output().expect("record"),
            "record",
        );
        let text = String::from_utf8_lossy(&obs.stdout);
        assert!(text.contains("went down"), "{text}");
        assert_clean(&inst);
    });
}

/// A tmpfs of `kib` KiB mounted on a directory of the test's own (root), unmounted when
/// dropped: a full disk, without touching the host's.
struct SmallDisk(PathBuf);

impl SmallDisk {
    fn new(test: &str, kib: u32) -> Self {
        let dir = integration_tests::test_dir().join(format!("{test}-disk"));
        std::fs::create_dir_all(&dir).expect("mount point");
        needed(
            Command::new("mount")
                .args(["-t", "tmpfs", "-o", &format!("size={kib}k"), "tmpfs"])
                .arg(&dir),
            "this test mounts a tmpfs: it needs root and mount(8)",
        );
        Self(dir)
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
        let _ = std::fs::remove_dir(&self.0);
    }
}

#[test]
fn a_recording_onto_a_full_disk_says_so_and_fails_its_command() {
    integration_tests::wall_clock(|| {
        let test = "rec-full";
        let up = Up::default_cell(test);
        let disk = SmallDisk::new(test, 64);
        // `exec --wait --record`: the program runs to its end; the recording fills the disk,
        // which the command says in the system's words, and it exits 1 (it exited 0).
        let program = scratch(test, "p.prog", "MOVE(60, 40, 0)\nMOVE(40, 40, 0)\nEND\n");
        let file = disk.0.join("run.mcap");
        let out = up.exec_wait(&program, &["--record", file.to_str().expect("utf-8")]);
        let err = exited(&out, 1);
        assert!(
            err.contains(&format!("{}: No space left on device", file.display())),
            "{err}"
        );
        let report: Value = serde_json::from_slice(&out.stdout).expect("the run's report");
        assert_eq!(report["ok"], true, "the program itself completed: {report}");
        // `record` alone: the same words, exit 1.
        std::fs::remove_file(&file).expect("room again");
        let filler = disk.0.join("filler");
        let _ = std::fs::write(&filler, vec![0u8; 60 * 1024]);
        let out = run_with_watchdog(
            supervisor()
                .args(["record", "--instance", &up.inst, "--duration", "2", "--out"])
                .arg(disk.0.join("alone.mcap")),
            WATCHDOG,
        );
        let err = exited(&out, 1);
        assert!(err.contains("No space left on device"), "{err}");
        drop(disk);
        up.down();
    });
}

/// Whether process `pid` is stopped (a SIGSTOP sent to it takes effect once it runs: a
/// process waiting for a CPU is not stopped yet, and a SIGTERM sent meanwhile is taken
/// first, the lower number, by its handler).
fn is_stopped(pid: i32) -> bool {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // `PID (COMM) STATE …`: the state follows the last parenthesis.
    stat.rsplit_once(')')
        .is_some_and(|(_, rest)| rest.trim_start().starts_with('T'))
}

/// Whether process `pid` has SIGTERM pending (it is stopped: it takes it once continued).
fn sigterm_pending(pid: i32) -> bool {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status.lines().any(|l| {
        l.strip_prefix("ShdPnd:")
            .or_else(|| l.strip_prefix("SigPnd:"))
            .and_then(|m| u64::from_str_radix(m.trim(), 16).ok())
            .is_some_and(|m| m & (1 << (libc::SIGTERM - 1)) != 0)
    })
}

/// The recorder's stop is a step of the serve loop: while it finishes its file (here held off
/// the CPU for longer than the processes wait for a heartbeat), the heartbeat beats, the
/// control channel answers and refuses what would change the cell; once the recorder is
/// back, it finishes its file and `up` goes down clean.
#[test]
fn the_cell_answers_and_beats_while_its_recorder_finishes_its_file() {
    integration_tests::wall_clock(|| {
        let test = "rec-stop";
        let file = scratch(test, "cell.mcap", "");
        let patience = 2.0;
        let cfg = cell(test, &[("supervisor.supervisor_timeout", patience.into())]);
        let up = Up::start_recording(test, &cfg, &file);
        let recorder = integration_tests::pids_with(&["record", &up.inst]);
        assert_eq!(recorder.len(), 1, "one recorder: {recorder:?}");
        let pid = nix::unistd::Pid::from_raw(recorder[0]);
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGSTOP).expect("SIGSTOP");
        let start = Instant::now();
        while !is_stopped(recorder[0]) {
            assert!(start.elapsed() < WATCHDOG, "the recorder never stopped");
            std::thread::sleep(Duration::from_millis(5));
        }
        let down = up.spawn(&["down"]);
        // The drives disabled, the supervisor has asked the recorder to end.
        let start = Instant::now();
        while !sigterm_pending(recorder[0]) {
            assert!(
                start.elapsed() < WATCHDOG,
                "the recorder was never asked to end"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        let asked = Instant::now();
        // Asked on the control channel from here (no process to start: the hold stays far
        // below the 10 s the supervisor gives the recorder before it kills it).
        let instance = shm_schema::InstanceName::new(&up.inst).expect("instance");
        let call = |req: control_plane::Request| control_plane::channel::call(&instance, &req);
        match call(control_plane::Request::Start) {
            Ok(control_plane::Reply::Refused(control_plane::Refusal::GoingDown { .. })) => {}
            other => panic!("start while the cell goes down: {other:?}"),
        }
        // Held past the processes' patience for a heartbeat (`supervisor_timeout`).
        std::thread::sleep(
            Duration::from_secs_f64(patience * 1.25).saturating_sub(asked.elapsed()),
        );
        let info = match call(control_plane::Request::Info) {
            Ok(control_plane::Reply::Info(i)) => i,
            other => panic!("info while the recorder finishes: {other:?}"),
        };
        assert!(info.going_down, "{info:?}");
        for p in &info.processes {
            assert_eq!(
                p.life,
                control_plane::info::Life::Running,
                "a process left: {info:?}"
            );
        }
        println!(
            "the recorder held {:?} after it was asked to end",
            asked.elapsed()
        );
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGCONT).expect("SIGCONT");
        assert!(
            integration_tests::wait_output(down, WATCHDOG, "down")
                .status
                .success()
        );
        let (log, events) = up.ended_events();
        let errors = crate::up::errors(&events);
        assert!(errors.is_empty(), "{errors:#?}");
        // The recorder finished its file itself (`up` only logs a recording that failed).
        assert!(!log.contains("the recording failed"), "{log}");
        // The file is whole: its summary (the index), read back.
        let read = read_back(&[file]);
        assert!(
            read["topics"]["/servo/state"]["count"]
                .as_u64()
                .is_some_and(|n| n > 0),
            "{read}"
        );
    });
}

/// A terminal's Ctrl-C (SIGINT to the foreground process group: `up`'s, and whatever shares
/// it) stops the cell the controlled way, and the recording has all of it: the recorder is
/// in a group of its own and ends when the supervisor asks it, once the drives are disabled.
#[test]
fn ctrl_c_on_up_record_records_the_controlled_stop_to_its_end() {
    integration_tests::wall_clock(|| {
        use std::os::unix::process::CommandExt;
        let test = "rec-ctrlc";
        let inst = instance(test);
        let file = scratch(test, "cell.mcap", "");
        let log = scratch(test, "up.log", "");
        let child = supervisor()
            .args(["up", "--instance", &inst, "--record"])
            .arg(&file)
            .arg("--config")
            .arg(crate::up::cell(test, &[]))
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).expect("log"))
            .process_group(0)
            .spawn()
            .expect("supervisor up");
        let group = nix::unistd::Pid::from_raw(child.id() as i32);
        let up = Up::adopt(inst, child, log);
        nix::sys::signal::killpg(group, nix::sys::signal::Signal::SIGINT).expect("Ctrl-C");
        up.wait_ended();
        let read = read_back(&[file]);
        let codes: Vec<u64> = read["event_codes"]
            .as_array()
            .expect("event codes")
            .iter()
            .filter_map(Value::as_u64)
            .collect();
        let at = |code: u32| codes.iter().position(|&c| c == u64::from(code));
        let enabled = at(shm_schema::event::code::ENABLED);
        let disabled = at(shm_schema::event::code::DISABLED);
        assert!(
            enabled.is_some() && disabled > enabled,
            "the enable, then the disable, recorded: {codes:?}"
        );
    });
}
