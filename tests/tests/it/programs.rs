//! Programs beyond the seed's triangle on the real binaries (docs/language.md): a
//! pick-and-place with IO, waits, a delay and a loop, its motion time against the prediction
//! `supervisor check` makes with trajgen's generator, and its IO timeline; `check` refusing a
//! bad program without starting anything.

use crate::drives::{WATCHDOG, events_named};
use integration_tests::{
    assert_clean, default_cell, instance, json_of, run_with_watchdog, scratch, supervisor,
    with_stall_room,
};

/// Picks at P1, places at P2, twice: the gripper is an output, its position sensor an input
/// the simulated machine switches 80 ms after the output (the default cell's `[[io]]`).
const PICK_AND_PLACE: &str = "\
// pick and place, twice
P1 = (80, 40, 0)
P2 = (80, 80, 0)
REPEAT 2
  MOVE(P1)
  STOP
  OUT(gripper, 1)
  WAIT(gripper_closed, 1, 2)
  MOVEJ(P2)
  STOP
  OUT(gripper, 0)
  WAIT(gripper_closed, 0, 2)
  DELAY(0.2)
ENDREPEAT
MOVE(40, 40, 0)
END
";

/// The predicted motion time `supervisor check` prints.
fn predicted(cfg: &std::path::Path, prog: &std::path::Path) -> f64 {
    let out = run_with_watchdog(
        supervisor().arg("check").arg(prog).arg("--config").arg(cfg),
        WATCHDOG,
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text.split("predicted motion time ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no prediction in {text}"))
}

#[test]
fn a_pick_and_place_with_io_waits_and_a_loop_runs_as_predicted() {
    let test = "prog-pick";
    let inst = instance(test);
    let cfg = scratch(test, "cell.toml", &with_stall_room(&default_cell()));
    let prog = scratch(test, "pick.prog", PICK_AND_PLACE);
    let want = predicted(&cfg, &prog);
    let out = run_with_watchdog(
        supervisor()
            .args(["run", "--json", "--instance", &inst, "--config"])
            .arg(&cfg)
            .arg(&prog),
        WATCHDOG,
    );
    let j = json_of(&out);
    assert_eq!(j["ok"], true, "{j}");
    let f = |k: &str| j[k].as_f64().unwrap_or_else(|| panic!("{k} in {j}"));
    // The run's prediction is check's (the same generator, from the same start).
    assert!(
        (f("predicted_s") - want).abs() < 1e-3,
        "{} vs {want}",
        f("predicted_s")
    );
    // Measured less the waits: the prediction, within the last cycle's rounding (the
    // trajectory runs on real time; each wait ends at the trajgen cycle that sees the input).
    let period = f("trajgen_period_s");
    let (measured, waited) = (f("measured_s"), f("waited_s"));
    assert!(
        waited > 4.0 * 0.08,
        "four waits of at least the 80 ms switching time: {waited}"
    );
    assert!(
        measured >= want - 1e-6 && measured - want <= 2.0 * period,
        "measured {measured} s (waits {waited} s excluded) vs predicted {want} s"
    );
    // The IO timeline: each OUT, then the sensor following it, in order, twice.
    let changes: Vec<(f64, String)> = events_named(&j, "io-changed")
        .iter()
        .map(|e| {
            (
                e["t_s"].as_f64().expect("t_s"),
                e["text"].as_str().expect("text").to_string(),
            )
        })
        .collect();
    let texts: Vec<&str> = changes.iter().map(|(_, t)| t.as_str()).collect();
    let cycle = [
        "gripper = 1",
        "gripper_closed = 1",
        "gripper = 0",
        "gripper_closed = 0",
    ];
    assert_eq!(texts, [cycle, cycle].concat(), "{changes:?}");
    for pair in changes.chunks(2) {
        let dt = pair[1].0 - pair[0].0;
        assert!(
            dt >= 0.08 - 0.005,
            "the sensor switched {dt} s after the output"
        );
    }
    // Servo followed: its own latched figure, within the limit.
    let fe = j["max_following_error"]["x"].as_f64().expect("fe");
    assert!(fe > 0.0 && fe < 1.0, "{fe}");
    assert_clean(&inst);
}

#[test]
fn check_refuses_a_bad_program_naming_line_and_column_and_starts_nothing() {
    let test = "prog-check";
    let cases = [
        (
            "MOVE(40,40,0)\nOUT(gripper_closed, 1)\nEND\n",
            "2:5: gripper_closed is an input, not an output",
        ),
        (
            "MOVE(40,40,0)\nMOVE(40,400,0)\nEND\n",
            "2:9: y = 400 mm is outside the axis limits 0 .. 150 mm",
        ),
        (
            "MOVE(40,40,0, T=1e9)\nEND\n",
            "1:17: the segment time T (s) = 1000000000",
        ),
        (
            "DELAY(86400)\nDELAY(86400)\nEND\n",
            "the program runs longer than 24 h",
        ),
    ];
    for (k, (src, want)) in cases.iter().enumerate() {
        let prog = scratch(test, &format!("p{k}.prog"), src);
        let out = run_with_watchdog(supervisor().arg("check").arg(&prog), WATCHDOG);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{src}: {err}");
        assert!(err.contains(want), "{src}: {err}");
    }
    // Not UTF-8: the place of the first bad byte.
    let prog = scratch(test, "bin.prog", "");
    std::fs::write(&prog, b"MOVE(40,40,0)\nMO\xffVE(1,2,3)\nEND\n").expect("write");
    let out = run_with_watchdog(supervisor().arg("check").arg(&prog), WATCHDOG);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("bin.prog:2:3: byte 0xFF is not UTF-8 text"),
        "{err}"
    );
}
