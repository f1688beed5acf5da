//! Programs beyond the seed's triangle on the real binaries (docs/language.md): a
//! pick-and-place with IO, waits, a delay and a loop, its motion time against the prediction
//! `supervisor check` makes with trajgen's generator, and its IO timeline; `check` refusing a
//! bad program without starting anything.

use crate::drives::{WATCHDOG, events_named};
use integration_tests::{
    assert_clean, default_cell, instance, json_of, run_with_watchdog, same_motion_time, scratch,
    supervisor, with_stall_room,
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

/// `supervisor check PROG --config CFG`, its output.
fn check(cfg: &std::path::Path, prog: &std::path::Path) -> std::process::Output {
    run_with_watchdog(
        supervisor().arg("check").arg(prog).arg("--config").arg(cfg),
        WATCHDOG,
    )
}

/// What `supervisor check` prints of a program it accepts: the predicted motion time and
/// its text.
fn predicted_with_text(cfg: &std::path::Path, prog: &std::path::Path) -> (f64, String) {
    let out = check(cfg, prog);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let t = text
        .split("predicted motion time ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no prediction in {text}"));
    (t, text)
}

/// The predicted motion time `supervisor check` prints.
fn predicted(cfg: &std::path::Path, prog: &std::path::Path) -> f64 {
    predicted_with_text(cfg, prog).0
}

/// Runs `program` on the cell `cell` with `run --json`,
/// after `supervisor check` predicted it; the report, checked: done, its prediction check's
/// own, and its motion time (waits excluded) the prediction within the last cycle's rounding
/// (the trajectory runs on real time; each wait ends at the trajgen cycle that sees its input).
fn run_as_predicted(test: &str, cell: &str, program: &str) -> serde_json::Value {
    let inst = instance(test);
    let cfg = scratch(test, "cell.toml", &with_stall_room(cell));
    let prog = scratch(test, "p.prog", program);
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
    assert!(
        (f("predicted_s") - want).abs() < 1e-3,
        "{} vs {want}",
        f("predicted_s")
    );
    let (measured, period) = (f("measured_s"), f("trajgen_period_s"));
    // Each wait ends at the trajgen cycle that sees its input, the motion at the one after
    // its end: a stall the run measured delays either.
    let late = crate::cell::trajgen_stall_s(&j);
    assert!(
        measured >= want - 1e-6 && measured - want <= 2.0 * (period + late),
        "measured {measured} s (waits {} s excluded) vs predicted {want} s (trajgen's longest \
         wake-up latency and execution {late} s)",
        f("waited_s")
    );
    assert_clean(&inst);
    j
}

#[test]
fn a_pick_and_place_with_io_waits_and_a_loop_runs_as_predicted() {
    integration_tests::wall_clock(|| {
        let j = run_as_predicted("prog-pick", &default_cell(), PICK_AND_PLACE);
        let waited = j["waited_s"].as_f64().expect("waited_s");
        assert!(
            waited > 4.0 * 0.08,
            "four waits of at least the 80 ms switching time: {waited}"
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
    });
}

#[test]
fn the_prediction_is_the_generators_own_timing_exactly() {
    integration_tests::wall_clock(|| {
        // A move to where the axes rest, after a move in the other space: its 2 t_acc, no
        // extra stop (the prediction said 15.825 s, a run 14.775 s or, one in a few, 15.825).
        let j = run_as_predicted(
            "prog-rest",
            &default_cell(),
            "MOVE(140, 40, 0)\nMOVEJ(140, 40, 0)\nMOVE(90, 126, 0)\nEND\n",
        );
        let f = |k: &str| j[k].as_f64().unwrap_or_else(|| panic!("{k} in {j}"));
        assert!(same_motion_time(f("predicted_s"), 14.775), "{j}");
        assert!(
            same_motion_time(f("theoretical_s"), f("predicted_s")),
            "{j}"
        );
        // Holds that end at once take no time: 20 WAITs met and DELAY(0)s, then the OUT at
        // motion time 0 (it was predicted at 0.020 s, a cycle each).
        let program = "REPEAT 20\n  WAIT(estop_ok, 1)\n  DELAY(0)\nENDREPEAT\nOUT(gripper, 1)\nMOVE(60, 40, 0)\nEND\n";
        let prog = scratch("prog-zero", "p.prog", program);
        let out = run_with_watchdog(supervisor().arg("check").arg(&prog), WATCHDOG);
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.lines()
                .any(|l| l.split_whitespace().collect::<Vec<_>>()
                    == ["0.000", "s", "line", "5", "gripper", "=", "1"]),
            "{text}"
        );
        let j = run_as_predicted("prog-zero", &default_cell(), program);
        assert!(
            same_motion_time(
                j["theoretical_s"].as_f64().expect("t"),
                j["predicted_s"].as_f64().expect("p")
            ),
            "{j}"
        );
    });
}

/// Issue 21 item 15: what a `STOP` costs is what docs/language.md says, as `supervisor check`
/// (the generator's own timing) predicts it on the default cell. A move from rest to rest of
/// `d` takes `d / vmax + 2 t_acc`. A `STOP` before the first move costs nothing; after a move,
/// that move's deceleration to rest instead of a blend into the next move; right after
/// another `STOP`, a zone of `2 t_acc` (the blend rule counts a repeated target as a
/// segment). The figures language.md quotes (7.30, 8.35, 13.55 and 14.60 s) among them.
#[test]
fn a_stop_costs_what_the_language_document_says() {
    let cell = cell_config::Config::default_cell();
    let (t_acc, vmax) = (cell.motion.t_acc, cell.axis[0].vmax);
    let cfg = scratch("prog-stop", "cell.toml", &default_cell());
    // From the start (40, 40) along x: 100 mm there, 100 mm back.
    let (there, back) = ("MOVE(140,40,0)\n", "MOVE(40,40,0)\n");
    let one = 100.0 / vmax + 2.0 * t_acc;
    let blended = 200.0 / vmax + 2.0 * t_acc;
    for (k, (lines, want)) in [
        (vec![there], one),
        (vec!["STOP\n", there], one),
        (vec!["STOP\n", "STOP\n", there], one),
        (vec![there, "STOP\n"], one),
        (vec![there, "STOP\n", "STOP\n"], one + 2.0 * t_acc),
        (vec![there, "STOP\n", "STOP\n", "STOP\n"], one + 4.0 * t_acc),
        (vec![there, back], blended),
        (vec![there, "STOP\n", back], 2.0 * one),
        (
            vec![there, "STOP\n", "STOP\n", back],
            2.0 * one + 2.0 * t_acc,
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let src = lines.concat() + "END\n";
        let prog = scratch("prog-stop", &format!("p{k}.prog"), &src);
        let (t, text) = predicted_with_text(&cfg, &prog);
        assert!(
            (t - want).abs() < 5e-4,
            "predicted {t} s, language.md says {want} s:\n{src}\n{text}"
        );
    }
    // language.md's own figures.
    assert!((one - 7.30).abs() < 1e-9 && (one + 2.0 * t_acc - 8.35).abs() < 1e-9);
    assert!((blended - 13.55).abs() < 1e-9 && (2.0 * one - 14.60).abs() < 1e-9);
}

/// Issue 21 item 11: a loop is checked until two iterations begin alike, the rest passed over
/// (`check` of the triangle 39 000 times took 26 s; 5000 times, 8 s), and what `check`
/// predicts is what running every iteration gives: the triangle `n` times takes the time of
/// 4 and `n − 4` times what a fifth adds.
#[test]
fn a_long_loop_is_checked_from_its_first_iterations_alike() {
    let cfg = scratch("prog-loop", "cell.toml", &default_cell());
    let at = |n: u32| {
        let prog = scratch(
            "prog-loop",
            &format!("t{n}.prog"),
            &format!(
                "MOVE(40,40,0)\nREPEAT {n}\nMOVE(140,40,0)\nMOVE(90,126,0)\nMOVE(40,40,0)\n\
                 ENDREPEAT\nEND\n"
            ),
        );
        predicted_with_text(&cfg, &prog)
    };
    let ((four, text4), (five, _)) = (at(4), at(5));
    // `check` prints words only (no cell, no JSON): what it says is the subject.
    assert!(!text4.contains("passed over"), "{text4}");
    let (all, text) = at(5000);
    assert!(
        (all - (four + 4996.0 * (five - four))).abs() < 0.01,
        "{four} {five} {all}"
    );
    let passed: u64 = text
        .split("; ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no iterations passed over: {text}"));
    // All but those in trajgen's queue of 255 commands (85 iterations) and the first two.
    assert!(passed > 4800, "{text}");
}

#[test]
fn check_refuses_a_bad_program_naming_line_and_column_and_starts_nothing() {
    integration_tests::wall_clock(|| {
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
        // `check` asks no cell and has no JSON: its words, which name the line and the column,
        // are the subject.
        for (k, (src, want)) in cases.iter().enumerate() {
            let prog = scratch(test, &format!("p{k}.prog"), src);
            let out = run_with_watchdog(supervisor().arg("check").arg(&prog), WATCHDOG);
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{src}: {err}");
            assert!(err.contains(want), "{src}: {err}");
        }
        // A path whose joint speed exceeds an axis' vmax (the polar arm's radial axis, 16 mm/s,
        // with the tool allowed 40 mm/s): found through the kinematics, before anything moves.
        let cfg = integration_tests::CellToml::example("polar.toml")
            .set(
                "kinematics.vmax",
                toml_edit::Value::Array([40.0, 40.0].into_iter().collect()),
            )
            .write(test, "polar.toml");
        let prog = scratch(
            test,
            "polar.prog",
            "MOVE(120, 90)\nMOVE(60, 160)\nMOVE(150, 0)\nEND\n",
        );
        let out = check(&cfg, &prog);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        // `check`'s words again (the axis and its limit named): the subject.
        assert!(
            err.contains("r reaches") && err.contains("above its vmax 16 mm/s"),
            "{err}"
        );
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
    });
}

/// The same pick-and-place on seed 004's five-bar (examples/five-bar.toml): Cartesian moves
/// mapped to the two joints every cycle, a joint move, IO, waits and a loop.
const FIVE_BAR_PICK: &str = "\
P1 = (-170, -130)
P2 = (-225, -160)
REPEAT 2
  MOVE(P1)
  STOP
  OUT(gripper, 1)
  WAIT(gripper_closed, 1, 2)
  MOVE(P2)
  STOP
  OUT(gripper, 0)
  WAIT(gripper_closed, 0, 2)
ENDREPEAT
MOVEJ(0, 0)
END
";

#[test]
fn the_five_bar_runs_a_pick_and_place_through_its_kinematics_as_predicted() {
    integration_tests::wall_clock(|| {
        let five_bar = std::fs::read_to_string(integration_tests::examples().join("five-bar.toml"))
            .expect("examples/five-bar.toml");
        let j = run_as_predicted("prog-fivebar", &five_bar, FIVE_BAR_PICK);
        let texts: Vec<String> = events_named(&j, "io-changed")
            .iter()
            .map(|e| e["text"].as_str().expect("text").to_string())
            .collect();
        assert_eq!(
            texts.iter().filter(|t| *t == "gripper = 1").count(),
            2,
            "{texts:?}"
        );
        assert_eq!(
            texts.iter().filter(|t| *t == "gripper_closed = 0").count(),
            2,
            "{texts:?}"
        );
        // Back at the null posture: both joints at 0.
        for joint in ["a0", "a1"] {
            let q = j["final_position"][joint].as_f64().expect("final");
            assert!(q.abs() < 0.01, "{joint} = {q}");
            let fe = j["max_following_error"][joint].as_f64().expect("fe");
            assert!(fe > 0.0 && fe < 1.0, "{joint}: {fe}");
        }
    });
}

#[test]
fn every_example_cell_and_its_program_pass_check() {
    integration_tests::wall_clock(|| {
        // The gantry's triangle on the embedded default, and each other cell's own program.
        let examples = integration_tests::examples();
        for (cell, prog) in [
            ("gantry-uba.toml", "triangle.prog"),
            ("five-bar.toml", "five-bar.prog"),
            ("scara.toml", "scara.prog"),
            ("polar.toml", "polar.prog"),
        ] {
            let out = run_with_watchdog(
                supervisor()
                    .arg("check")
                    .arg(examples.join(prog))
                    .arg("--config")
                    .arg(examples.join(cell)),
                WATCHDOG,
            );
            assert!(
                out.status.success(),
                "{cell} {prog}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
    });
}
