//! The virtual clock's benchmark: the seed's triangle on the real processes on the wall clock
//! and on the virtual clock, alternately, round after round, in one run.
//!
//! Per round and clock: the wall time `supervisor run` took (start-up and stop included) and
//! the motion time it measured. At the end, the speed-up (the median wall time on the wall
//! clock over that on the virtual clock: the goal is at least 20) and how far the virtual
//! run's setpoints are from the real-time run's: each setpoint of a real-time run against the
//! virtual run's path at the same motion time (linear between its setpoints, which on the
//! triangle's lines is exact and in its blends within a∙dt²/8).
//!
//! Run it with `bash bench/virtual-time.sh [--rounds N]` (it builds the supervisor first; root
//! for `SCHED_FIFO`).

mod common;

use integration_tests::{median, trace_rows};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use common::root;

fn supervisor() -> PathBuf {
    common::binary("supervisor")
}

/// One run: its wall time (s), its measured motion time (s) and its trace's rows.
fn one(
    config: &Path,
    instance: &str,
    trace: &Path,
    virtual_time: bool,
) -> Result<(f64, f64, Vec<Vec<f64>>), String> {
    let mut cmd = Command::new(supervisor());
    cmd.args(["run", "--json", "--instance", instance, "--config"])
        .arg(config)
        .arg("--trace")
        .arg(trace);
    if virtual_time {
        cmd.arg("--virtual-time");
    }
    let start = Instant::now();
    let out = cmd
        .arg(root().join("examples/triangle.prog"))
        .output()
        .map_err(|e| format!("supervisor: {e}"))?;
    let wall = start.elapsed().as_secs_f64();
    let j: Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("not JSON ({e}): {}", String::from_utf8_lossy(&out.stderr)))?;
    if j["ok"] != true {
        return Err(format!("run failed: {}", j["error"]));
    }
    Ok((
        wall,
        j["measured_s"].as_f64().unwrap_or(f64::NAN),
        trace_rows(trace),
    ))
}

/// The largest difference of a commanded position between `real`'s rows and `virt`'s path
/// at the same motion time (rows: t_s, then cmd and act per axis; `axes` commands).
fn largest_difference(real: &[Vec<f64>], virt: &[Vec<f64>], axes: usize) -> f64 {
    let mut worst: f64 = 0.0;
    for r in real {
        let t = r[0];
        let k = virt.partition_point(|v| v[0] < t);
        if k == 0 || k >= virt.len() {
            continue;
        }
        let (a, b) = (&virt[k - 1], &virt[k]);
        let w = if b[0] > a[0] {
            (t - a[0]) / (b[0] - a[0])
        } else {
            0.0
        };
        for i in 1..=axes {
            let v = a[i] + (b[i] - a[i]) * w;
            worst = worst.max((r[i] - v).abs());
        }
    }
    worst
}

fn main() {
    let rounds = common::rounds(
        "virtual_time",
        "The triangle on the wall clock and on the virtual clock, alternating.",
    );
    let dir = std::env::temp_dir().join(format!("rtc-virtual-time-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let config = dir.join("cell.toml");
    std::fs::write(&config, integration_tests::wall_cell()).expect("write config");
    let axes = 3;
    let (mut wall_runs, mut virtual_runs, mut diffs) = (Vec::new(), Vec::new(), Vec::new());
    for round in 0..rounds {
        let order = if round % 2 == 0 {
            [false, true]
        } else {
            [true, false]
        };
        let mut traces: [Vec<Vec<f64>>; 2] = [Vec::new(), Vec::new()];
        for virtual_time in order {
            let which = if virtual_time { "virtual" } else { "wall" };
            let inst = format!("vt-bench-{}-{round}-{which}", std::process::id());
            let trace = dir.join(format!("{which}-{round}.csv"));
            match one(&config, &inst, &trace, virtual_time) {
                Ok((wall, measured, rows)) => {
                    println!(
                        "round {} on the {which} clock: {wall:.3} s of wall time, motion {measured:.4} s",
                        round + 1
                    );
                    if virtual_time {
                        virtual_runs.push(wall);
                    } else {
                        wall_runs.push(wall);
                    }
                    traces[usize::from(virtual_time)] = rows;
                }
                Err(e) => println!("round {} on the {which} clock: {e}", round + 1),
            }
        }
        if traces.iter().all(|t| !t.is_empty()) {
            let d = largest_difference(&traces[0], &traces[1], axes);
            println!(
                "  setpoints: the real-time run's differ from the virtual path by {d:.2e} at most"
            );
            diffs.push(d);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    if wall_runs.is_empty() || virtual_runs.is_empty() {
        eprintln!("no complete result for one of the clocks");
        std::process::exit(1);
    }
    let (w, v) = (median(wall_runs), median(virtual_runs));
    println!("\nmedians over {rounds} rounds");
    println!("  wall clock     {w:.3} s of wall time");
    println!("  virtual clock  {v:.3} s of wall time");
    println!("  speed-up       {:.1} (the goal: at least 20)", w / v);
    if let Some(worst) = diffs.iter().copied().reduce(f64::max) {
        println!("  setpoints      differ by {worst:.2e} at most (units of the axes)");
    }
}
