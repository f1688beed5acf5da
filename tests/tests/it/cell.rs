//! The whole cell as separate real-time processes, each test on its own instance.

use integration_tests::{
    assert_clean, assert_gone, bin, examples, exited, instance, json_of, pids_with,
    run_with_watchdog, scratch, succeeded_within, success, supervisor,
};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

const WATCHDOG: Duration = Duration::from_secs(180);

/// Runs the triangle on `inst` with the configuration file `cfg`.
fn run_triangle_with(inst: &str, cfg: &Path) -> std::process::Output {
    run_with_watchdog(
        supervisor()
            .args(["run", "--instance", inst, "--config"])
            .arg(cfg)
            .arg(examples().join("triangle.prog")),
        WATCHDOG,
    )
}

/// Checks a successful `--json` run: on time, on target, every process reported.
pub(crate) fn check_run(j: &serde_json::Value, target: [f64; 3]) {
    // The document is the one its type (and JSON Schema) describes: every key known, none
    // missing.
    if let Err(e) = serde_json::from_value::<control_plane::report::RunReport>(j.clone()) {
        panic!("the run's JSON is not the documented report ({e}): {j}");
    }
    let f = |k: &str| {
        j[k].as_f64()
            .unwrap_or_else(|| panic!("{k} missing in {j}"))
    };
    let (measured, theoretical, period) =
        (f("measured_s"), f("theoretical_s"), f("trajgen_period_s"));
    assert!(
        integration_tests::same_motion_time(f("predicted_s"), theoretical),
        "{j}"
    );
    // The seed's bar: the measured motion time equals the theoretical one, within one
    // trajgen period (never shorter: the last setpoint is at or after the end), and the
    // stall trajgen measured, if any (the end is seen by the first cycle after it: a host
    // stall there delays it; on an idle machine that is tens of microseconds).
    let late = trajgen_stall_s(j);
    assert!(
        measured >= theoretical - 1e-6 && measured - theoretical <= period + late,
        "measured {measured} s vs theoretical {theoretical} s (period {period} s, trajgen's \
         longest wake-up latency and execution {late} s)"
    );
    for (axis, want) in ["x", "y", "theta"].iter().zip(target) {
        let got = j["final_position"][axis].as_f64().expect("final position");
        assert!((got - want).abs() <= 0.01, "{axis}: {got} vs {want}");
        // Servo's own latch, for the program that ran: an axis that moves (x does) has some
        // following error, within its limit.
        let fe = j["max_following_error"][axis].as_f64().expect("fe");
        assert!(fe < 1.0 && (*axis != "x" || fe > 0.0), "{axis}: {fe}");
    }
    for p in ["trajgen", "servo", "iobridge", "drives"] {
        let proc_ = &j["processes"][p];
        assert!(
            proc_["cycles"].as_u64().expect("cycles") > 0,
            "{p}: {proc_}"
        );
        assert!(proc_["pid"].as_u64().is_some());
        assert!(proc_["cpu_s"].as_f64().is_some(), "{p}: {proc_}");
        // The process' own latency histogram, over the run: sane, non-empty percentiles.
        let l = &proc_["wakeup_latency_us"];
        let v = |k: &str| l[k].as_f64().unwrap_or_else(|| panic!("{p}: {k} in {l}"));
        assert!(l["samples"].as_u64().expect("samples") > 0, "{p}: {l}");
        assert!(
            v("min_us") <= v("p50_us")
                && v("p50_us") <= v("p99_us")
                && v("p99_us") <= v("p99_9_us")
                && v("p99_9_us") <= v("p99_99_us")
                && v("p99_99_us") <= v("max_us"),
            "{p}: {l}"
        );
    }
    assert_eq!(j["lost_setpoints"].as_u64(), Some(0), "{j}");
}

/// The longest stall trajgen measured in a run (`j`, its report): its largest wake-up
/// latency and its largest execution time (s). Room for the host's stalls in a bound on a
/// motion's time, attributed to what the run measured.
pub(crate) fn trajgen_stall_s(j: &serde_json::Value) -> f64 {
    let p = &j["processes"]["trajgen"];
    let us = |k: &str| {
        p[k].as_f64()
            .unwrap_or_else(|| panic!("trajgen's {k} in {j}"))
    };
    (us("max_wakeup_latency_us") + us("max_exec_us")) * 1e-6
}

/// `--plot`'s PNG: its size, and in each of its three plots the lines of the run's data (not
/// only their legend's swatches, a few dozen pixels): the commanded and measured path, one
/// histogram per process, the following error of x and y.
pub(crate) fn check_figures(path: &Path, processes: usize) {
    use cell_client::figures::{HEIGHT, WIDTH, areas};
    let file = std::fs::File::open(path).expect("the PNG was written");
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .expect("a PNG");
    let mut rgb = vec![0; reader.output_buffer_size().expect("fits")];
    let info = reader.next_frame(&mut rgb).expect("a frame");
    assert_eq!((info.width, info.height), (WIDTH, HEIGHT));
    assert_eq!(info.color_type, png::ColorType::Rgb);
    let count = |a: plot::Area, color: [u8; 3]| {
        let mut n = 0;
        for y in a.top.max(0)..a.bottom.min(HEIGHT as i32) {
            for x in a.left.max(0)..a.right.min(WIDTH as i32) {
                let i = (y as usize * WIDTH as usize + x as usize) * 3;
                n += usize::from(rgb[i..i + 3] == color);
            }
        }
        n
    };
    let (path_area, latency_area, fe_area) = areas();
    let drawn = |what: &str, a: plot::Area, k: usize| {
        let n = count(a, plot::color(k));
        println!("{}: {what}: {n} pixels of colour {k}", path.display());
        assert!(n > 250, "{}: {what}: {n} pixels", path.display());
    };
    drawn("commanded path", path_area, 0);
    drawn("measured path", path_area, 1);
    for k in 0..processes {
        drawn("latency histogram", latency_area, k);
    }
    // The following error's first panel (mm: x and y; theta has a panel of its own below,
    // in the same colours), the upper half of its area.
    let mm_panel = plot::Area {
        bottom: (fe_area.top + fe_area.bottom) / 2,
        ..fe_area
    };
    drawn("following error of x", mm_panel, 0);
    drawn("following error of y", mm_panel, 1);
}

#[test]
fn the_seed_triangle_takes_its_theoretical_19_10_s_and_cleans_up() {
    integration_tests::wall_clock_default_limits(|| {
        let inst = instance("triangle");
        let trace = integration_tests::test_dir().join(format!("{inst}.csv"));
        let plot = integration_tests::test_dir().join(format!("{inst}.png"));
        let out = succeeded_within(
            supervisor()
                .args(["run", "--json", "--instance", &inst, "--trace"])
                .arg(&trace)
                .arg("--plot")
                .arg(&plot)
                .arg(examples().join("triangle.prog")),
            WATCHDOG,
        );
        let j = json_of(&out);
        assert!(
            (j["theoretical_s"].as_f64().expect("t") - 19.10).abs() < 1e-9,
            "{j}"
        );
        check_run(&j, [40.0, 40.0, 0.0]);
        assert_eq!(j["t_acc"].as_f64(), Some(0.525));
        assert_eq!(j["vmax"]["x"].as_f64(), Some(16.0));
        assert_eq!(j["periods_us"]["servo"].as_u64(), Some(1000));
        assert_eq!(
            j["processes"]["trajgen"]["period_us"].as_f64(),
            Some(4000.0)
        );

        // The trace: a header, one row per setpoint, t_s rising from 0 to the measured time.
        let csv = std::fs::read_to_string(&trace).expect("trace written");
        let mut lines = csv.lines();
        assert_eq!(
            lines.next(),
            Some("t_s,cmd_x,cmd_y,cmd_theta,act_x,act_y,act_theta")
        );
        let rows: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|v| v.parse().expect("number")).collect())
            .collect();
        assert_eq!(
            rows.len() as u64,
            j["setpoints"].as_u64().expect("setpoints")
        );
        assert_eq!(rows[0][0], 0.0);
        assert!(rows.windows(2).all(|w| w[1][0] > w[0][0]));
        // The triangle's corner (140, 40) is blended: x passes near it, never beyond 140.
        let max_x = rows.iter().map(|r| r[1]).fold(f64::MIN, f64::max);
        assert!(max_x < 140.0 && max_x > 135.0, "{max_x}");
        // The machine followed: measured within the following error limit of commanded.
        assert!(
            rows.iter()
                .all(|r| (r[1] - r[4]).abs() < 1.0 && (r[2] - r[5]).abs() < 1.0)
        );
        let _ = std::fs::remove_file(&trace);
        // The figures: every process of the default cell has its histogram.
        check_figures(&plot, j["processes"].as_object().expect("processes").len());
        let _ = std::fs::remove_file(&plot);
        assert_clean(&inst);
    });
}

/// The paper's failure was a motion that took longer when the processor was busy. Two
/// busy threads (both cores) for the whole run must change nothing.
#[test]
fn motion_time_holds_with_both_cores_loaded() {
    integration_tests::wall_clock_default_limits(|| {
        let inst = instance("loaded");
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let hogs: Vec<_> = (0..2)
            .map(|_| {
                let stop = stop.clone();
                std::thread::spawn(move || {
                    let mut x = 0u64;
                    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                        x = std::hint::black_box(
                            x.wrapping_mul(6364136223846793005).wrapping_add(1),
                        );
                    }
                })
            })
            .collect();
        // A square of 20 mm that turns theta on one side (about 7 s): every kind of segment
        // and blend, each cycle of each process as exposed to the load as in a longer one.
        let prog = scratch(
            "loaded",
            "square.prog",
            "MOVE(60,40,0)\nMOVE(60,60,45)\nMOVE(40,60,0)\nMOVE(40,40,0)\nSTOP\nEND\n",
        );
        let out = run_with_watchdog(
            supervisor()
                .args(["run", "--json", "--instance", &inst, "--config"])
                .arg(integration_tests::wall_cell_file("loaded"))
                .arg(&prog),
            WATCHDOG,
        );
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        for h in hogs {
            let _ = h.join();
        }
        let out = success(out, "supervisor run");
        check_run(&json_of(&out), [40.0, 40.0, 0.0]);
        assert_clean(&inst);
    });
}

/// `run` (a `supervisor run` on `inst`), which must be refused with exit code 2 before any
/// process started: its stderr.
fn refused_run(inst: &str, run: &mut Command) -> String {
    let err = exited(&run_with_watchdog(run, WATCHDOG), 2);
    assert!(
        pids_with(&["--instance", inst]).is_empty(),
        "a process was started: {err}"
    );
    err
}

/// Runs `program` on a fresh instance; it must be refused with exit code 2 and `message`,
/// before any process started.
fn refused(test: &str, program: &str, message: &str) {
    let inst = instance(test);
    let prog = scratch(test, "p.prog", program);
    let err = refused_run(
        &inst,
        supervisor().args(["run", "--instance", &inst]).arg(&prog),
    );
    assert!(err.contains(&format!("p.prog:{message}")), "{err}");
    assert_clean(&inst);
}

#[test]
fn a_program_error_names_line_and_column_and_starts_nothing() {
    integration_tests::wall_clock(|| {
        refused(
            "badprog",
            "MOVE(40,40,0)\nMOVE(140,40)\nEND\n",
            "2:12: MOVE has 2 coordinates; the cell has 3 (x, y, theta)",
        );
    });
}

#[test]
fn a_target_outside_the_limits_is_refused_before_anything_moves() {
    integration_tests::wall_clock(|| {
        refused(
            "limits",
            "MOVE(40,40,0)\nMOVE(40,400,0)\nEND\n",
            "2:9: y = 400 mm is outside the axis limits 0 .. 150 mm",
        );
    });
}

#[test]
fn an_output_that_cannot_be_written_is_refused_before_anything_starts() {
    integration_tests::wall_clock(|| {
        let inst = instance("badout");
        let tri = examples().join("triangle.prog");
        let dir = integration_tests::test_dir();
        for (flag, path, why) in [
            (
                "--plot",
                "/nonexistent/dir/p.png",
                "the directory /nonexistent/dir does not exist",
            ),
            ("--trace", dir.to_str().expect("utf-8"), "is a directory"),
            (
                "--record",
                "/nonexistent/r.mcap",
                "the directory /nonexistent does not exist",
            ),
        ] {
            let err = refused_run(
                &inst,
                supervisor()
                    .args(["run", "--instance", &inst, flag, path])
                    .arg(&tri),
            );
            assert!(err.contains(&format!("{flag} {path}: {why}")), "{err}");
        }
        assert_clean(&inst);
    });
}

#[test]
fn a_bad_config_names_file_line_and_reason() {
    integration_tests::wall_clock(|| {
        let inst = instance("badcfg");
        let cfg = integration_tests::default_cell_toml()
            .add("motion.t_dec", 1)
            .write("badcfg", "cell.toml");
        let line = std::fs::read_to_string(&cfg)
            .expect("written")
            .lines()
            .position(|l| l.starts_with("t_dec"))
            .expect("t_dec")
            + 1;
        let err = exited(&run_triangle_with(&inst, &cfg), 2);
        assert!(
            err.contains(&format!("cell.toml:{line}:1: unknown field `t_dec`")),
            "{err}"
        );
        assert_clean(&inst);
    });
}

/// Any process can be replaced by another command line; here iobridge runs through a shell
/// wrapper, as a process in another language would be started.
#[test]
fn a_process_killed_mid_motion_fails_the_run_and_leaves_nothing() {
    integration_tests::wall_clock(|| {
        let inst = instance("kill");
        let wrapped = format!("exec {} --instance {{instance}}", bin("iobridge").display());
        let cfg = integration_tests::default_cell_toml()
            .set(
                "process[iobridge].command",
                integration_tests::toml::strings(&["sh", "-c", &wrapped]),
            )
            .write("kill", "cell.toml");
        let prog = scratch("kill", "long.prog", "MOVE(190,140,0)\nMOVE(10,10,0)\nEND\n");
        let child = supervisor()
            .args(["run", "--instance", &inst, "--config"])
            .arg(&cfg)
            .arg(&prog)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn supervisor");
        // Wait until servo runs and the motion has started, then kill servo the hard way.
        let mut servo = Vec::new();
        for _ in 0..500 {
            servo = pids_with(&["servo", "--instance", &inst]);
            if !servo.is_empty() && !pids_with(&["iobridge", "--instance", &inst]).is_empty() {
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        assert_eq!(servo.len(), 1, "servo not found");
        crate::up::until_moving(&inst, None);
        // SAFETY: kill(2) on a process this test's supervisor started.
        unsafe { libc::kill(servo[0], libc::SIGKILL) };
        let out =
            integration_tests::wait_output(child, WATCHDOG, "supervisor stuck after servo died");
        let err = exited(&out, 1);
        assert!(
            err.contains(&format!("servo (pid {}) exited unexpectedly", servo[0])),
            "{err}"
        );
        assert_gone(&inst);
    });
}

#[test]
fn a_process_that_cannot_start_fails_the_run_and_leaves_nothing() {
    integration_tests::wall_clock(|| {
        let inst = instance("nostart");
        let cfg = integration_tests::default_cell_toml()
            .set(
                "process[iobridge].command",
                integration_tests::toml::strings(&["no-such-iobridge", "--instance", "{instance}"]),
            )
            .write("nostart", "cell.toml");
        // Refused before anything starts, as `check-config` refuses it.
        let err = exited(&run_triangle_with(&inst, &cfg), 2);
        assert!(
            err.contains(
                "process iobridge: \"no-such-iobridge\" is neither next to the supervisor nor in PATH"
            ),
            "{err}"
        );
        let check = supervisor()
            .arg("check-config")
            .arg(&cfg)
            .output()
            .expect("check-config runs");
        assert_eq!(check.status.code(), Some(2), "check-config refuses it too");
        assert_gone(&inst);
    });
}
