//! The `ethercat-emulator` process checked by two EtherCAT masters we did not write, from
//! PyPI: SOEM (pysoem) and kickcat (`tests/python/masters.py`), each on one end of a veth pair
//! in a network namespace of its own, the emulator on the other (kickcat on a ring: a second
//! veth pair from the line's end back to kickcat's second port). Needs root (CI is).

use integration_tests::{EmulatedLine, bin, needed};
use std::process::Command;

/// Runs `tests/python/masters.py MASTER PORTS` in the line's namespace; its JSON (the last
/// line of its stdout).
fn master(line: &EmulatedLine, name: &str, ports: &[&str]) -> serde_json::Value {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/python/masters.py");
    let out = needed(
        Command::new("ip")
            .args([
                "netns", "exec", &line.ns, "timeout", "120", "python3", script, name,
            ])
            .args(ports),
        "pip install pysoem==1.1.13 kickcat==2.5; .ci/run does",
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let last = stdout.lines().last().unwrap_or("");
    serde_json::from_str(last).unwrap_or_else(|e| {
        panic!(
            "{name}'s output is not JSON ({e}): {}\n{stderr}",
            String::from_utf8_lossy(&out.stdout)
        )
    })
}

/// Master `name` on an emulated line of its own ([`LINE`] and `args`, of test `test`), on
/// `ports` of it: its JSON; it found the line's four SubDevices.
fn scan(test: &str, name: &str, args: &[&str], ports: &[&str]) -> serde_json::Value {
    let args = [LINE, args].concat();
    let line = EmulatedLine::up(&bin("ethercat-emulator"), test, &args);
    let r = master(&line, name, ports);
    assert_eq!(r["found"], 4, "{r}");
    r
}

fn every_pattern_came_back(name: &str, r: &serde_json::Value) {
    let ex = r["exchanges"].as_array().expect("exchanges");
    assert_eq!(ex.len(), 20, "{name}: {r}");
    for e in ex {
        assert_eq!(
            e["read"], e["wrote"],
            "{name}: an output that did not come back: {r}"
        );
    }
}

/// The line the masters check: the IO terminals and a drive.
/// The ESCs' process data watchdog at 2 s: room for the host's stalls between two exchanges
/// of a master (this VM stalls a process for tens of ms now and then, rarely for a second).
const LINE: &[&str] = &[
    "--loopback",
    "--line",
    "ek1100,el1008,el2008,drive",
    "--pd-watchdog-ms",
    "2000",
];

/// What a master read of the drive by SDO before OP, and the CiA 402 states it took it
/// through in OP.
fn the_drive_answered_and_enabled(name: &str, r: &serde_json::Value) {
    let sdo = &r["sdo"];
    assert_eq!(
        sdo["vendor"],
        ethercat_emulator::drive::VENDOR,
        "{name}: {r}"
    );
    assert_eq!(
        sdo["product"],
        ethercat_emulator::drive::PRODUCT,
        "{name}: {r}"
    );
    assert_eq!(sdo["modes"], 0x0380, "{name}: CSP, CSV, CST: {r}");
    assert_eq!(
        sdo["statusword"].as_u64().map(|s| s & 0x4F),
        Some(0x40),
        "{name}: Switch on disabled before OP: {r}"
    );
    assert_eq!(sdo["mode_display"], 8, "{name}: CSP: {r}");
    let d = &r["drive"];
    assert_eq!(
        d["states"],
        serde_json::json!([0x21, 0x23, 0x27]),
        "{name}: Ready to switch on, Switched on, Operation enabled: {r}"
    );
    assert_eq!(d["mode_display"], 8, "{name}: {r}");
    assert_eq!(
        d["position"], 40_000,
        "{name}: the axis where it started: {r}"
    );
}

#[test]
fn soem_scans_the_emulated_line_reads_its_identities_and_exchanges_process_data() {
    integration_tests::wall_clock(|| {
        let r = scan("masters-soem", "pysoem", &[], &["m0"]);
        let expected = [
            ("EK1100", 2, 0x044C_2C52u32),
            ("EL1008", 2, 0x03F0_3052),
            ("EL2008", 2, 0x07D8_3052),
            (
                "RTC-EMU-402",
                ethercat_emulator::drive::VENDOR,
                ethercat_emulator::drive::PRODUCT,
            ),
        ];
        for (d, (name, vendor, product)) in r["devices"]
            .as_array()
            .expect("devices")
            .iter()
            .zip(expected)
        {
            assert_eq!(d["name"], name, "{r}");
            assert_eq!(d["vendor"], vendor, "{r}");
            assert_eq!(d["product"], product, "{r}");
        }
        assert_eq!(
            r["iomap"],
            2 + 19 + 19,
            "a byte each way for the IO, 19 for the drive: {r}"
        );
        // LRW: the EL2008 and the drive written (2 each), the EL1008 and the drive read (1 each).
        assert_eq!(r["expected_wkc"], 6, "{r}");
        assert_eq!(r["safe_op"], 4, "{r}");
        assert_eq!(r["op"], serde_json::json!([8, 8, 8, 8]), "{r}");
        for e in r["exchanges"].as_array().expect("exchanges") {
            assert_eq!(e["wkc"], 6, "{r}");
        }
        every_pattern_came_back("pysoem", &r);
        the_drive_answered_and_enabled("pysoem", &r);
        assert_eq!(r["drive"]["wkc"], serde_json::json!([6]), "{r}");
        // On SYNC0 (SOEM's DC set-up and SYNC0 start), enabled through outputs taken at SYNC0;
        // the line's DC time, which SOEM reads with every exchange, went on.
        let dc = &r["dc"];
        assert_eq!(dc["found"], true, "{r}");
        assert_eq!(dc["sync_mode"], 2, "{r}");
        let t = |k: usize| dc["time"][k].as_u64().unwrap_or(0);
        assert!(t(0) > 0 && t(1) > t(0), "{r}");
    });
}

#[test]
fn kickcat_maps_the_emulated_line_with_separate_logical_reads_and_writes() {
    integration_tests::wall_clock(|| {
        // As a ring: kickcat sends each frame out of both its ports and adds up the working
        // counters of the two copies it reads back. The line processes what enters from m0
        // and sends it on to m1; what enters from m1 comes back to m0 as it went in (a copy
        // processed twice would count twice, and kickcat refuses a wrong working counter).
        let r = scan(
            "masters-kickcat",
            "kickcat",
            &["--ring", "s1"],
            &["m0", "m1"],
        );
        assert_eq!(
            r["sizes"],
            serde_json::json!([[0, 0], [1, 0], [0, 1], [19, 19]]),
            "{r}"
        );
        assert_eq!(
            r["op"],
            serde_json::json!([
                "State.OPERATIONAL",
                "State.OPERATIONAL",
                "State.OPERATIONAL",
                "State.OPERATIONAL"
            ]),
            "{r}"
        );
        every_pattern_came_back("kickcat", &r);
        the_drive_answered_and_enabled("kickcat", &r);
    });
}
