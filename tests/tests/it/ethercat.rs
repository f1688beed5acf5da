//! The cell on EtherCAT: the drives' process is `ethercat-bus` (ethercrab brings the bus up,
//! one frame a cycle), its SubDevices the emulator's. Each test runs in a network namespace of
//! its own (root, iproute2), so its veth pair and its Modbus port meet nothing else; the
//! namespace goes with the test.

use crate::up::{Up, io_of, latched};
use control_plane::Failure;
use control_plane::info::Life;
use integration_tests::{
    assert_clean, bin, examples, exited, instance, ip, json_of, needed, run_with_watchdog, scratch,
    succeeded_within,
};
use shm_schema::event::code;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

const WATCHDOG: Duration = Duration::from_secs(180);

/// A network namespace of the test's own, removed when dropped (with whatever is in it).
struct Netns(String);

impl Netns {
    fn new(test: &str) -> Self {
        let name = format!("rtc-{}-{test}", std::process::id());
        ip(&["netns", "add", &name]);
        ip(&["-n", &name, "link", "set", "lo", "up"]);
        Self(name)
    }

    /// `program` run inside the namespace.
    fn command(&self, program: &str) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.0]).arg(bin(program));
        c
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        let _ = Command::new("ip").args(["netns", "del", &self.0]).status();
    }
}

/// The example EtherCAT cell, with room for the host's stalls.
fn ethercat_cell() -> String {
    let src = std::fs::read_to_string(examples().join("gantry-ethercat.toml"))
        .expect("examples/gantry-ethercat.toml");
    integration_tests::with_stall_room(&src)
}

/// A network namespace of `test`'s own, and the file of the example cell ([`ethercat_cell`]).
fn bus_cell(test: &str) -> (Netns, PathBuf) {
    let ns = Netns::new(test);
    (ns, scratch(test, "cell.toml", &ethercat_cell()))
}

/// `supervisor run` of the triangle on `inst` with the configuration file `cfg`, in `ns`,
/// under the watchdog.
fn triangle_in(ns: &Netns, inst: &str, cfg: &Path) -> Output {
    run_with_watchdog(
        ns.command("supervisor")
            .args(["run", "--instance", inst, "--config"])
            .arg(cfg)
            .arg(examples().join("triangle.prog")),
        WATCHDOG,
    )
}

/// `out` of a run whose bus process refused the configuration, saying `says`, as a
/// configuration is refused (exit 2), before anything was enabled; `what` (the case) in the
/// messages. Its stderr.
fn refused_by_the_bus(out: &Output, says: &str, what: &str) -> String {
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{what}: {err}");
    // `run` refused before it started anything, with no data but its words: they are the
    // subject (what is where on the bus, in the bus process' own sentence).
    assert!(err.contains(says), "{what}: want {says:?} in\n{err}");
    assert!(err.contains("refused the configuration"), "{what}: {err}");
    // Nothing was enabled: the bus never reached its cycle.
    assert!(!err.contains("enabling"), "{what}: {err}");
    err
}

#[test]
fn the_small_triangle_runs_over_the_emulated_bus_on_time_and_on_the_path() {
    integration_tests::wall_clock(|| {
        let inst = instance("ecat-triangle");
        let (ns, cfg) = bus_cell("ecat-tri");
        let out = run_with_watchdog(
            ns.command("supervisor")
                .args(["run", "--json", "--instance", &inst, "--config"])
                .arg(&cfg)
                .arg(integration_tests::small_triangle("ecat-triangle"))
                .env("RTC_LOG", "warn,ethercat_bus=info,ethercat_emulator=info"),
            WATCHDOG,
        );
        let err = exited(&out, 0);
        let j = json_of(&out);
        crate::cell::check_run(&j, [40.0, 40.0, 0.0]);
        // The drives ran on Distributed Clocks (their default): the EK1100 the reference
        // clock, SYNC0 every period in each drive through the whole (small) triangle (one
        // event a millisecond of its motion at least), and a command applied at SYNC0, half a period after the frame that brought
        // it: the loop from an encoder sample to its command applied is a period and a half
        // at the least (a drive taking its data as the frame passes: one period). (The log's
        // sentence is the subject: what the bus process says of its clocks.)
        assert!(
            err.contains("Distributed Clocks: reference clock position 0 (EK1100); SYNC0 every 1000 µs on position(s) 1, 2, 3"),
            "{err}"
        );
        // Each drive's SYNC0 count, told by the emulator as it stopped (its events are the
        // run's, those of the going down included).
        let motion_ms = j["measured_s"].as_f64().expect("measured") * 1e3;
        for name in ["x", "y", "theta"] {
            let e = j["events"]
                .as_array()
                .expect("the run's events")
                .iter()
                .find(|e| e["code"] == code::EMULATED_SYNC0 && e["axis"] == name)
                .unwrap_or_else(|| panic!("no emulated-sync0 event of {name}: {j}"));
            let events = e["value"].as_f64().expect("a count");
            assert!(events >= motion_ms, "{e}: {motion_ms} ms of motion");
        }
        let s2c = j["sense_to_command_us"]["p50_us"].as_f64();
        assert!(s2c.is_some_and(|us| us >= 1450.0), "{s2c:?}: {j}");
        // The drives were the bus': its start-up announced, the emulator answered.
        let op = crate::drives::events_named(&j, "bus-op");
        assert_eq!(op.len(), 1, "{err}");
        assert_eq!(
            op[0]["value"].as_f64(),
            Some(6.0),
            "EK1100, three drives, EL1008 and EL2008: {err}"
        );
        assert!(
            j["processes"]["emulator"]["cycles"]
                .as_u64()
                .is_some_and(|c| c > 0),
            "{j}"
        );
        assert!(
            crate::drives::events_named(&j, "bus-wkc-mismatch").is_empty(),
            "{err}"
        );
        assert_clean(&inst);
    });
}

/// The emulator alone on `s0` of a veth pair in `ns`, the bus' end `m0`.
fn standalone_line(ns: &Netns, line: &str) -> Child {
    ip(&[
        "-n", &ns.0, "link", "add", "m0", "type", "veth", "peer", "name", "s0",
    ]);
    ip(&["-n", &ns.0, "link", "set", "s0", "up"]);
    ip(&["-n", &ns.0, "link", "set", "m0", "up"]);
    ns.command("ethercat-emulator")
        .args(["--interface", "s0", "--line", line])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("the emulator")
}

/// The example cell on the test's own line: no emulator process, the bus on `m0`.
fn cell_on_m0() -> String {
    integration_tests::CellToml::parse(&ethercat_cell())
        .remove("process", "emulator")
        .set("ethercat.interface", "m0")
        .to_string()
}

#[test]
fn a_line_that_differs_from_the_configuration_is_refused_naming_the_position_and_identities() {
    integration_tests::wall_clock(|| {
        for (test, line, want) in [
            (
                "ecat-missing",
                "ek1100,drive,drive",
                "the bus on m0 has 3 SubDevice(s): position 3 should be theta (vendor 0xe1a00001, product 0x00000402, any revision), and nothing answers there",
            ),
            (
                "ecat-other",
                "ek1100,drive,el2008,drive",
                "position 2 of the bus on m0 should be y (vendor 0xe1a00001, product 0x00000402, any revision), and EL2008 (vendor 0x00000002, product 0x07d83052, revision 0x00100000) is there",
            ),
            (
                "ecat-extra",
                "ek1100,drive,drive,drive,el1008,el2008,el1008",
                "the bus on m0 has 7 SubDevice(s) where the configuration names 6: position 6 is EL1008 (vendor 0x00000002, product 0x03f03052, revision 0x00100000), which it does not name",
            ),
        ] {
            let inst = instance(test);
            let ns = Netns::new(test);
            let mut emulator = standalone_line(&ns, line);
            let cfg = scratch(test, "cell.toml", &cell_on_m0());
            let out = triangle_in(&ns, &inst, &cfg);
            let _ = emulator.kill();
            let _ = emulator.wait();
            // Refused as a configuration is (exit 2), the bus process' reason in the log (its
            // words, naming the positions and identities, are the subject).
            let err = refused_by_the_bus(&out, want, line);
            assert!(!err.contains("bus-op"), "{line}: {err}");
            assert_clean(&inst);
        }
    });
}

#[test]
fn a_cable_pulled_mid_motion_is_a_lost_bus_an_estop_and_the_power_cut() {
    integration_tests::wall_clock(|| {
        let inst = instance("ecat-cable");
        let (ns, cfg) = bus_cell("ecat-cable");
        // Once the program has moved the axes for a second (its status), the cable goes.
        let pull = {
            let (ns, inst) = (ns.0.clone(), inst.clone());
            std::thread::spawn(move || {
                crate::up::until_moving(&inst, Some(&ns));
                ip(&["-n", &ns, "link", "set", "rtc-ecat0", "down"]);
            })
        };
        let out = run_with_watchdog(
            ns.command("supervisor")
                .args(["run", "--json", "--instance", &inst, "--config"])
                .arg(&cfg)
                .arg(examples().join("triangle.prog")),
            WATCHDOG,
        );
        pull.join().expect("the cable pulled");
        let err = exited(&out, 1);
        let run: control_plane::report::RunFailure = serde_json::from_slice(&out.stdout)
            .unwrap_or_else(|e| panic!("run --json: not a RunFailure ({e}): {err}"));
        // The run's event of `code` from `source` (any source: `None`).
        let event = |source: Option<&str>, code: u32| {
            run.events
                .iter()
                .find(|e| e.code == code && source.is_none_or(|s| e.source == s))
                .unwrap_or_else(|| panic!("no event {code} of {source:?}: {run:#?}\n{err}"))
        };
        // (value, limit, text) of an event.
        let reading = |e: &control_plane::event::Event| (e.value, e.limit, e.text.clone());
        // The frames lost, then the bus: 100 of them at 1 kHz (its 100 ms watchdog).
        let lost = event(None, code::BUS_FRAMES_LOST);
        assert_eq!((lost.value, lost.limit), (Some(1.0), 100.0), "{lost:?}");
        let lost = event(None, code::BUS_LOST);
        assert_eq!((lost.value, lost.limit), (Some(100.0), 100.0), "{lost:?}");
        // The e-stop before that, after 50 frames: each lost frame is a transport overrun
        // (seed 002), and the test's transport detector expires at 5 % of 1 kHz (the
        // example's at 0.5 %: 5 frames). Raised by the drives' process (origin host, 3), for
        // its health detector (604).
        assert_eq!(
            reading(event(Some("drives"), code::HEALTH_EXPIRED)),
            (Some(50.0), 50.0, "transport_overrun expired".to_string())
        );
        assert_eq!(
            reading(event(Some("drives"), code::ESTOP_RAISED)),
            (
                Some(3.0),
                f64::from(code::HEALTH_EXPIRED),
                "transport_overrun expired in drives".to_string()
            )
        );
        // Servo took the e-stop; the bus' feedback NaN from the next cycle on, it cuts power.
        // Why it disabled, in the event's words (its only record).
        let disabling = event(Some("servo"), code::DISABLING);
        assert!(disabling.text.starts_with("e-stop"), "{disabling:?}");
        event(Some("servo"), code::POWER_CUT);
        assert_clean(&inst);
    });
}

#[test]
fn another_device_in_a_drives_place_keeps_the_bus_down_until_the_right_one_is_back() {
    integration_tests::wall_clock(|| {
        let (ns, up) = cell_up("ecat-ident");
        let mut events = up.follow_events();
        // Another product at position 2 (y's drive swapped under power: it leaves OP, and its
        // EEPROM says another identity at the next scan).
        emulator_fault(&ns, &up, &["identity", "2", "0x00000999"]);
        emulator_fault(&ns, &up, &["leave-op", "2"]);
        let left = events.next(code::SUBDEVICE_LEFT_OP);
        assert!(left.text.contains("position 2 (y)"), "{left:?}");
        events.next(code::BUS_RECOVERING);
        // Every attempt to bring the bus up again is refused, saying what is where: the event
        // once (the product found and the one configured), the log the whole sentence.
        let mismatch = events.next(code::SUBDEVICE_MISMATCH);
        assert_eq!(
            (mismatch.value, mismatch.limit, mismatch.axis.as_deref()),
            (Some(f64::from(0x999)), f64::from(0x402), Some("y")),
            "{mismatch:?}"
        );
        assert!(
            mismatch.text.contains("position 2 should be y"),
            "{mismatch:?}"
        );
        // The right drive back: the bus in OP (not before), then reset, start and the
        // triangle.
        let back = runtime::time::now_ns();
        emulator_fault(&ns, &up, &["identity", "2", "0x00000402"]);
        let op = events.next(code::BUS_OP);
        assert!(op.text.contains("back in OP on rtc-ecat0"), "{op:?}");
        assert!(
            op.stamp_ns > back,
            "in OP before the right drive was back: {op:?}"
        );
        drop(events);
        // The log, whole once the cell is down (a process' lines reach it through the
        // supervisor, beside its events), says the whole sentence.
        let log = reset_start_and_run(up);
        assert!(
            log.contains("position 2 of the bus on rtc-ecat0 should be y (vendor 0xe1a00001, product 0x00000402"),
            "{log}"
        );
        assert!(log.contains("product 0x00000999"), "{log}");
    });
}

/// `ethercat-emulator fault --instance <up's> ARGS` in `ns`, which must succeed.
fn emulator_fault(ns: &Netns, up: &Up, args: &[&str]) {
    succeeded_within(
        ns.command("ethercat-emulator")
            .args(["fault", "--instance", &up.inst])
            .args(args),
        WATCHDOG,
    );
}

/// Whether `file`, a pcapng capture (little-endian, as this host writes it), holds an
/// Enhanced Packet Block: its blocks walked by their lengths, a block cut short not counted.
fn pcapng_has_a_packet(file: &[u8]) -> bool {
    const SECTION_HEADER: u32 = 0x0A0D_0D0A;
    const ENHANCED_PACKET: u32 = 6;
    let word = |at: usize| {
        file.get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    if word(0) != Some(SECTION_HEADER) || word(8) != Some(0x1A2B_3C4D) {
        return false;
    }
    let mut at = 0;
    while let (Some(kind), Some(len)) = (word(at), word(at + 4)) {
        let len = len as usize;
        if len < 12 || at + len > file.len() {
            return false;
        }
        if kind == ENHANCED_PACKET {
            return true;
        }
        at += len;
    }
    false
}

/// The example cell, with room for the host's stalls, up in a network namespace of the
/// test's own (every command of the test runs there), its drives enabled. (Bound as
/// `let (ns, up)`, the cell goes down before its namespace goes.)
fn cell_up(test: &str) -> (Netns, Up) {
    let (ns, cfg) = bus_cell(test);
    let up = Up::start_in(test, &cfg, Some(&ns.0));
    (ns, up)
}

/// `reset`, `start`, a small triangle to its end on time and on target, then `down`; its log.
fn reset_start_and_run(up: Up) -> String {
    up.reset_and_start();
    small_triangle_runs(&up);
    up.down()
}

/// The small triangle on the cell, which must run to its end on time and on target; its
/// report.
fn small_triangle_runs(up: &Up) -> serde_json::Value {
    let j = up.report(&integration_tests::small_triangle(&up.inst), &[]);
    crate::cell::check_run(&j, [40.0, 40.0, 0.0]);
    j
}

#[test]
fn after_the_cable_comes_back_the_bus_is_back_in_op_and_reset_and_start_run_the_next_program() {
    integration_tests::wall_clock(|| {
        let (ns, up) = cell_up("ecat-back");
        let mut events = up.follow_events();
        let run = up.exec_in_background(examples().join("triangle.prog"));
        // Mid-motion (the triangle takes 19 s), the cable goes.
        up.until_typed("moving", crate::up::moving_typed);
        ip(&["-n", &ns.0, "link", "set", "rtc-ecat0", "down"]);
        let out = run.wait_with_output().expect("exec");
        assert_eq!(out.status.code(), Some(1), "the run ended by the lost bus");
        events.next(code::BUS_LOST);
        events.next(code::BUS_RECOVERING);
        // Latched (by the bus, or by servo's own fault on the feedback it lost first).
        up.until_typed("the e-stop latched", |s| s.supervisor.estop.is_some());
        // A reset before the bus is back: the e-stop comes back at once, nothing enabled; what
        // stays says why (its words are the subject: the bus not back).
        match up.failure(&["reset"]) {
            Failure::ResetIncomplete { left } => assert!(
                left.iter()
                    .any(|l| l.contains("EtherCAT bus not back in OP yet")),
                "{left:?}"
            ),
            other => panic!("a reset on a lost bus: {other:?}"),
        }
        assert!(!up.ctl(&["start"]).status.success(), "start on a lost bus");
        // The cable back: the bus process brings the bus up again by itself.
        ip(&["-n", &ns.0, "link", "set", "rtc-ecat0", "up"]);
        events.next(code::BUS_OP);
        drop(events);
        let log = reset_start_and_run(up);
        // The log's event lines: no working counter mismatched on the way.
        assert!(!log.contains("bus-wkc-mismatch"), "{log}");
    });
}

#[test]
fn a_subdevice_leaving_op_and_an_emergency_are_named_and_the_bus_comes_back() {
    integration_tests::wall_clock(|| {
        let (ns, up) = cell_up("ecat-safeop");
        let mut events = up.follow_events();
        // A drive's emergency, read from its mailbox in OP: named, and nothing else happens.
        emulator_fault(&ns, &up, &["emergency", "2", "0x8611"]);
        let e = events.next(code::SUBDEVICE_EMERGENCY);
        assert_eq!(e.value, Some(f64::from(0x8611)), "its code: {e:?}");
        assert!(
            e.text.contains("position 2 (y)"),
            "the emergency names its SubDevice: {e:?}"
        );
        // A drive's own fault (the encoder lost: `supervisor inject` on the emulated drive):
        // its emergency and servo's power cut.
        let faulted = runtime::time::now_ns();
        up.ok(&["inject", "--axis", "x", "encoder-loss"]);
        let e = events.next(code::SUBDEVICE_EMERGENCY);
        assert!(e.text.contains("position 1 (x)"), "{e:?}");
        up.ok(&["inject", "--axis", "x", "encoder-loss", "--clear"]);
        // The x drive's SubDevice drops to SAFE-OP (its own fault, AL status code 0x001A).
        emulator_fault(&ns, &up, &["leave-op", "1", "0x001A"]);
        let left = events.next(code::SUBDEVICE_LEFT_OP);
        assert_eq!(
            left.limit,
            f64::from(0x001A),
            "its AL status code: {left:?}"
        );
        assert!(left.text.contains("position 1 (x)"), "{left:?}");
        // The e-stop latched, the bus is brought up again once the drives have ramped down.
        events.next(code::BUS_RECOVERING);
        events.next(code::BUS_OP);
        // The e-stops came of the drive's own fault and its leaving OP, none of the emergency.
        let raised = events.all(code::ESTOP_RAISED);
        assert!(
            raised.iter().all(|e| e.stamp_ns > faulted),
            "an e-stop before the drive's fault: {raised:?}"
        );
        drop(events);
        // The log, whole once the cell is down, names the emergency's SubDevice and code.
        let log = reset_start_and_run(up);
        assert!(log.contains("position 2 (y) sent an emergency"), "{log}");
        assert!(log.contains("subdevice-emergency: 0x8611"), "{log}");
    });
}

#[test]
fn the_bus_process_killed_is_restarted_and_reset_and_start_recover() {
    integration_tests::wall_clock(|| {
        let (_ns, up) = cell_up("ecat-kill");
        let mut events = up.follow_events();
        let bus = integration_tests::pids_with(&["ethercat-bus", &up.inst]);
        assert_eq!(bus.len(), 1, "one bus process: {bus:?}");
        // SIGKILL: no goodbye; the drives' SyncManager watchdogs take their outputs down.
        unsafe { libc::kill(bus[0], libc::SIGKILL) };
        let lost = events.next(code::PROCESS_LOST);
        assert_eq!(lost.source, "supervisor", "{lost:?}");
        // How it ended, in the event's words (its only record): the subject.
        assert!(
            lost.text.contains("exited: signal: 9 (SIGKILL)"),
            "{lost:?}"
        );
        // Restarted by its policy: it brings the bus up from the scan.
        up.until_typed("the bus process back", |s| {
            let i = &s.supervisor;
            i.processes
                .iter()
                .any(|p| p.name == "drives" && p.restarts >= 1 && p.life == Life::Running)
        });
        let again = integration_tests::pids_with(&["ethercat-bus", &up.inst]);
        assert!(again.len() == 1 && again[0] != bus[0], "{again:?}");
        events.next(code::BUS_OP);
        drop(events);
        up.until_typed("the new bus process cyclic", |s| {
            s.processes.get("drives").is_some_and(|p| p.cycles > 100)
        });
        reset_start_and_run(up);
    });
}

/// `tshark` (Debian's Wireshark) with `args`, its stdout.
fn tshark(args: &[&str]) -> String {
    let out = needed(
        Command::new("tshark").args(args),
        "this test needs tshark (apt-get install tshark)",
    );
    String::from_utf8_lossy(&out.stdout).to_string()
}

#[test]
fn wiresharks_dissector_decodes_a_programs_bus_traffic_with_no_malformed_frame() {
    integration_tests::wall_clock(|| {
        let (ns, up) = cell_up("ecat-tshark");
        let capture = integration_tests::scratch("ecat-tshark", "bus.pcapng", "");
        // dumpcap (tshark's capture engine) on the bus' end of the pair, ready once its file
        // holds a frame (a pcapng Enhanced Packet Block: the bus runs, frames pass).
        let mut dumpcap = Command::new("ip")
            .args([
                "netns",
                "exec",
                &ns.0,
                "dumpcap",
                "-q",
                "-i",
                "rtc-ecat0",
                "-w",
            ])
            .arg(&capture)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("this test needs tshark's dumpcap: {e}"));
        let start = std::time::Instant::now();
        while !pcapng_has_a_packet(&std::fs::read(&capture).unwrap_or_default()) {
            assert!(
                matches!(dumpcap.try_wait(), Ok(None)),
                "dumpcap ended before capturing"
            );
            assert!(
                start.elapsed() < WATCHDOG,
                "no frame captured in {WATCHDOG:?}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        let report = small_triangle_runs(&up);
        nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(dumpcap.id() as i32),
            nix::sys::signal::Signal::SIGINT,
        )
        .expect("SIGINT to dumpcap");
        assert!(dumpcap.wait().expect("dumpcap").success());
        up.down();
        let file = capture.to_str().expect("path");
        // Every frame EtherCAT, none malformed, none with an expert error.
        let frames = tshark(&["-r", file, "-T", "fields", "-e", "frame.number"]);
        let ecat = tshark(&[
            "-r",
            file,
            "-Y",
            "ecat",
            "-T",
            "fields",
            "-e",
            "frame.number",
        ]);
        let bad = tshark(&[
            "-r",
            file,
            "-Y",
            "_ws.malformed || _ws.expert.severity == error",
        ]);
        let (n, n_ecat) = (frames.lines().count(), ecat.lines().count());
        // A frame and its reply a cycle at 1 kHz, for the program's motion time at least (a
        // quarter of them left for the host's stalls).
        let cycles = report["measured_s"].as_f64().expect("measured_s") * 1000.0;
        assert!(
            n as f64 > 1.5 * cycles,
            "{n} frames captured in {cycles} cycles"
        );
        assert_eq!(n_ecat, n, "frames that are not EtherCAT");
        assert!(bad.is_empty(), "malformed or in error:\n{bad}");
        // The cycle's frames as the dissector reads them: an LRW (0x0c), the reference
        // clock's system time written (FPWR, 0x05) and distributed (FRMW, 0x0e), and nine
        // FPRDs (6 AL statuses, 3 send mailboxes' status); every reply with the LRW's working
        // counter 12 (the EK1100 has no data; three drives, each read and written: 3 × 3; the
        // EL1008 read, 1; the EL2008 written, 2), 1 for the FPWR, 4 for the FRMW (the EK1100
        // and the three drives have DC) and 1 for each FPRD.
        let cmds = tshark(&[
            "-r", file, "-T", "fields", "-e", "ecat.cmd", "-e", "ecat.cnt",
        ]);
        let cyclic = "0x0c,0x05,0x0e,0x04,0x04,0x04,0x04,0x04,0x04,0x04,0x04,0x04";
        let (mut sent, mut replies) = (0, 0);
        for line in cmds.lines().filter(|l| l.starts_with(cyclic)) {
            let wkc = line.split('\t').nth(1).unwrap_or_default();
            if wkc == "0,0,0,0,0,0,0,0,0,0,0,0" {
                sent += 1;
            } else {
                assert_eq!(wkc, "12,1,4,1,1,1,1,1,1,1,1,1", "a cyclic reply: {line}");
                replies += 1;
            }
        }
        assert!(
            sent as f64 > 0.75 * cycles && replies + 10 >= sent,
            "{sent} sent, {replies} replies in {cycles} cycles"
        );
        // The summary, kept as the test's artefact.
        let summary = tshark(&["-r", file, "-q", "-z", "io,phs", "-z", "expert"]);
        let artefacts =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/artefacts");
        std::fs::create_dir_all(&artefacts).expect("target/artefacts");
        let kept = artefacts.join("ethercat-triangle-capture.txt");
        std::fs::write(
            &kept,
            format!(
                "{n} frames, {n_ecat} EtherCAT, 0 malformed; cyclic: {sent} sent, {replies} replies, \
                 every reply with working counters 12,1,4,1,1,1,1,1,1,1,1,1\n\n{summary}"
            ),
        )
        .expect("the summary");
        eprintln!("capture summary ({}):\n{summary}", kept.display());
        let _ = std::fs::remove_file(&capture);
    });
}

#[test]
fn the_cells_io_rides_the_bus_an_output_its_sensor_back_and_the_estop_circuit() {
    integration_tests::wall_clock(|| {
        let (ns, up) = cell_up("ecat-io");
        // The inputs as the terminal reads them: the e-stop circuit closed (its sim value).
        let s = up.until_typed("the inputs from the bus", |s| {
            io_of(s, "estop_ok") == Some(1)
        });
        assert_eq!(io_of(&s, "gripper_closed"), Some(0), "{s:?}");
        // The gripper's output through the EL2008, the emulated solenoid, its sensor back
        // through the EL1008 80 ms later.
        up.ok(&["io", "gripper", "1"]);
        up.until_typed("the gripper's sensor closed", |s| {
            io_of(s, "gripper_closed") == Some(1)
        });
        up.ok(&["io", "gripper", "0"]);
        up.until_typed("the gripper's sensor open", |s| {
            io_of(s, "gripper_closed") == Some(0)
        });
        // The e-stop button on the bus pressed (the EL1008's bit 0 at position 4 opens):
        // iobridge raises the e-stop from it.
        emulator_fault(&ns, &up, &["input", "4", "0", "--bit", "0"]);
        let s = up.until_typed("the e-stop latched by its circuit", latched);
        assert_eq!(io_of(&s, "estop_ok"), Some(0), "{s:?}");
        // Released: reset and start, and the triangle runs.
        emulator_fault(&ns, &up, &["input", "4", "1", "--bit", "0"]);
        up.until_typed("the circuit closed", |s| io_of(s, "estop_ok") == Some(1));
        reset_start_and_run(up);
    });
}

#[test]
fn an_io_bit_beyond_its_terminal_is_refused_before_anything_is_enabled() {
    // Valid on paper (the bit's range is the terminal's process data, known on the bus).
    refused_on_the_bus(
        "ecat-iobit",
        |c| c.set("io[part_present].ethercat.bit", 9),
        "io \"part_present\": bit 9 of position 4 (di) does not exist: its inputs are 8 bits",
    );
}

#[test]
fn a_subdevice_on_sync0_without_distributed_clocks_is_refused_before_anything_is_enabled() {
    // Valid on paper (whether an ESC has DC is known on the bus): the EL1008 has none.
    refused_on_the_bus(
        "ecat-nodc",
        |c| c.add("ethercat.subdevice[di].sync", "dc"),
        "position 4 (di) is configured on SYNC0 (sync = \"dc\", a drive's default) and its ESC has no Distributed Clocks (register 0x0008)",
    );
}

/// The example cell as `edit` makes it, which `check-config` accepts: `run` exits 2 saying
/// `says`, before anything is enabled, and leaves nothing behind.
fn refused_on_the_bus(
    test: &str,
    edit: impl Fn(integration_tests::CellToml) -> integration_tests::CellToml,
    says: &str,
) {
    integration_tests::wall_clock(|| {
        let inst = instance(test);
        let ns = Netns::new(test);
        let cfg =
            edit(integration_tests::CellToml::parse(&ethercat_cell())).write(test, "cell.toml");
        succeeded_within(
            integration_tests::supervisor()
                .arg("check-config")
                .arg(&cfg),
            WATCHDOG,
        );
        refused_by_the_bus(&triangle_in(&ns, &inst, &cfg), says, test);
        assert_clean(&inst);
    });
}
