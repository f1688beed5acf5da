//! The servo-rate benchmark: the seed's triangle on the real processes with servo and the
//! drives at 1 kHz (the default cell) and at 4 kHz (both at 250 µs, phases 25 and 100 µs),
//! alternately, round after round, in one run.
//!
//! Per rate and round, from `supervisor run --json`: overruns per 10 000 cycles, wake-up
//! latency p99, execution time p99 and CPU time per process, the peak following error per
//! axis, the sense-to-command latency (p50/p99/max) and measured − theoretical motion time.
//! At the end, the medians over rounds and the ratios 4 kHz / 1 kHz of the execution time per
//! cycle (the goal: not above 1) and of the peak following error.
//!
//! Run it with `bash bench/rates.sh [--rounds N]` (it builds the supervisor first; root for
//! `SCHED_FIFO`).

mod common;

use integration_tests::median;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

const PROCESSES: [&str; 4] = ["drives", "servo", "trajgen", "iobridge"];
const AXES: [&str; 3] = ["x", "y", "theta"];

use common::root;

fn supervisor() -> PathBuf {
    common::binary("supervisor")
}

/// What one run measured.
#[derive(Clone, Debug, Default)]
struct Run {
    /// Per process: overruns per 10 000 cycles, wake-up p99 (µs), exec p99 (µs), CPU (s).
    procs: Vec<[f64; 4]>,
    /// Peak |following error| per axis.
    fe: Vec<f64>,
    /// Sense to command p50, p99, max (µs).
    s2c: [f64; 3],
    /// measured − theoretical (ms).
    diff_ms: f64,
}

fn one(config: &Path, instance: &str) -> Result<Run, String> {
    let out = Command::new(supervisor())
        .args(["run", "--json", "--instance", instance, "--config"])
        .arg(config)
        .arg(root().join("examples/triangle.prog"))
        .output()
        .map_err(|e| format!("supervisor: {e}"))?;
    let j: Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("not JSON ({e}): {}", String::from_utf8_lossy(&out.stderr)))?;
    if j["ok"] != true {
        return Err(format!("run failed: {}", j["error"]));
    }
    let f = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let procs = PROCESSES
        .iter()
        .map(|p| {
            let q = &j["processes"][p];
            [
                f(&q["overruns"]) / f(&q["cycles"]).max(1.0) * 1e4,
                f(&q["wakeup_latency_us"]["p99_us"]),
                f(&q["exec_time_us"]["p99_us"]),
                f(&q["cpu_s"]),
            ]
        })
        .collect();
    let s = &j["sense_to_command_us"];
    Ok(Run {
        procs,
        fe: AXES
            .iter()
            .map(|a| f(&j["max_following_error"][a]))
            .collect(),
        s2c: [f(&s["p50_us"]), f(&s["p99_us"]), f(&s["max_us"])],
        diff_ms: f(&j["difference_s"]) * 1e3,
    })
}

fn show(label: &str, r: &Run) {
    let p = |k: usize| -> String {
        PROCESSES
            .iter()
            .zip(&r.procs)
            .map(|(n, v)| format!("{n} {:.1}", v[k]))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!("{label}");
    println!("  overruns / 10k cycles   {}", p(0));
    println!("  wake-up p99 (µs)        {}", p(1));
    println!("  exec time p99 (µs)      {}", p(2));
    println!("  CPU (s)                 {}", p(3));
    println!(
        "  peak following error    {}",
        AXES.iter()
            .zip(&r.fe)
            .map(|(a, v)| format!("{a} {v:.4}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "  sense to command (µs)   p50 {:.0}, p99 {:.0}, max {:.0}",
        r.s2c[0], r.s2c[1], r.s2c[2]
    );
    println!("  measured − theoretical  {:+.3} ms", r.diff_ms);
}

fn median_run(runs: &[Run]) -> Run {
    let m = |f: &dyn Fn(&Run) -> f64| median(runs.iter().map(f).collect());
    Run {
        procs: (0..PROCESSES.len())
            .map(|p| std::array::from_fn(|k| m(&|r: &Run| r.procs[p][k])))
            .collect(),
        fe: (0..AXES.len()).map(|a| m(&|r: &Run| r.fe[a])).collect(),
        s2c: std::array::from_fn(|k| m(&|r: &Run| r.s2c[k])),
        diff_ms: m(&|r: &Run| r.diff_ms),
    }
}

fn main() {
    let rounds = common::rounds(
        "rates",
        "The servo-rate benchmark: the triangle at 1 kHz and at 4 kHz, alternating.",
    );
    let dir = std::env::temp_dir().join(format!("rtc-rates-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let rates = [(1000u64, "1 kHz"), (250, "4 kHz")];
    let configs: Vec<PathBuf> = rates
        .iter()
        .map(|(us, _)| {
            let p = dir.join(format!("cell-{us}us.toml"));
            std::fs::write(&p, integration_tests::cell_at_rate(*us)).expect("write config");
            p
        })
        .collect();
    let mut results: [Vec<Run>; 2] = [Vec::new(), Vec::new()];
    for round in 0..rounds {
        // Alternate which rate goes first.
        let order = if round % 2 == 0 { [0, 1] } else { [1, 0] };
        for k in order {
            let inst = format!("rates-{}-{round}-{k}", std::process::id());
            match one(&configs[k], &inst) {
                Ok(r) => {
                    show(&format!("round {} at {}", round + 1, rates[k].1), &r);
                    results[k].push(r);
                }
                Err(e) => println!("round {} at {}: {e}", round + 1, rates[k].1),
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    if results.iter().any(Vec::is_empty) {
        eprintln!("no complete result for one of the rates");
        std::process::exit(1);
    }
    let (slow, fast) = (median_run(&results[0]), median_run(&results[1]));
    println!("\nmedians over {rounds} rounds");
    show("1 kHz", &slow);
    show("4 kHz", &fast);
    println!("\nratios 4 kHz / 1 kHz (medians)");
    for (p, name) in PROCESSES.iter().enumerate() {
        println!(
            "  {name:<9} exec time p99 per cycle {:.2}, CPU {:.2}",
            fast.procs[p][2] / slow.procs[p][2],
            fast.procs[p][3] / slow.procs[p][3]
        );
    }
    for (a, name) in AXES.iter().enumerate() {
        if slow.fe[a] > 0.0 {
            println!(
                "  {name:<9} peak following error {:.2}",
                fast.fe[a] / slow.fe[a]
            );
        } else {
            println!("  {name:<9} peak following error — (the axis does not move)");
        }
    }
}
