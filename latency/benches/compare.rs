//! The latency benchmark: ours against the baselines, alternating, in one run.
//!
//! Per round (the order inside a pair alternates from round to round):
//! - `cyclictest -m -S -d 0 -p P -i I -D S` against `supervisor latency --test timer` at the
//!   same interval and priority; both write cyclictest's 1-µs histogram file, and both are
//!   summarised by the same code from it.
//! - `supervisor latency --test pipe` (a raw pipe) against `--test ipc` (iceoryx2 publish +
//!   notify, Listener wait), both one way, across CPUs and on one CPU; summarised from the
//!   tool's JSON (sub-µs percentiles of the same histogram type).
//!
//! Prints every round and the median over rounds of the ratios ours/baseline for the median,
//! p99 and p99.9. Run it with `bash bench/latency.sh` (it builds the supervisor first).
//!
//! Options: `--rounds N` (3), `--duration S` (10), `--interval-us N` (1000), `--priority P` (80).

use integration_tests::median;
use latency::histfile;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The latency benchmark: ours against cyclictest and a raw pipe, alternating.
#[derive(clap::Parser)]
#[command(name = "compare")]
struct Args {
    /// Rounds, each one pair of runs per comparison.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    rounds: u32,
    /// Each run's length (s).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    duration: u64,
    /// The timer's interval (µs).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(50..))]
    interval_us: u64,
    /// The SCHED_FIFO priority of both.
    #[arg(long, default_value_t = 80, value_parser = clap::value_parser!(i32).range(1..=99))]
    priority: i32,
    // `cargo bench` passes it.
    #[arg(long, hide = true)]
    bench: bool,
}

/// Median, p99, p99.9 (µs).
type Figures = [f64; 3];

/// Nearest-rank percentiles of 1-µs bins (all columns together); the overflows count as
/// samples above the range (a percentile among them reads as the range, flagged by `+`).
fn from_histfile(path: &Path) -> Result<(Figures, u64, bool), String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let cols = histfile::parse(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    let bins = cols.first().map_or(0, |c| c.bins.len());
    let merged: Vec<u64> = (0..bins)
        .map(|i| cols.iter().map(|c| c.bins[i]).sum())
        .collect();
    let overflows: u64 = cols.iter().map(|c| c.overflows).sum();
    let total = merged.iter().sum::<u64>() + overflows;
    let mut clipped = false;
    let mut pct = |num: u64, den: u64| {
        let rank = (total * num).div_ceil(den).max(1);
        let mut seen = 0;
        for (i, c) in merged.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return i as f64;
            }
        }
        clipped = true;
        bins as f64
    };
    Ok(([pct(1, 2), pct(99, 100), pct(999, 1000)], total, clipped))
}

fn run(cmd: &mut Command) -> Result<String, String> {
    let out = cmd
        .output()
        .map_err(|e| format!("{:?}: {e}", cmd.get_program()))?;
    if !out.status.success() {
        return Err(format!(
            "{:?} failed ({}): {}",
            cmd.get_program(),
            out.status,
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

fn supervisor() -> PathBuf {
    if let Some(p) = std::env::var_os("SUPERVISOR_BIN") {
        return p.into();
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target"));
    target.join("release/supervisor")
}

const RANGE_US: u32 = 20_000;

fn main() {
    if let Err(e) = bench() {
        eprintln!("bench: {e}");
        std::process::exit(1);
    }
}

fn ratios(ours: &Figures, base: &Figures) -> Figures {
    [0, 1, 2].map(|i| ours[i] / base[i].max(1e-9))
}

fn hop_figures(json: &str, test: &str) -> Result<Vec<(String, Figures)>, String> {
    let v: Value = serde_json::from_str(json).map_err(|e| format!("latency JSON: {e}"))?;
    let series = v["tests"][test]["series"]
        .as_array()
        .ok_or(format!("no {test} series in the JSON"))?;
    Ok(series
        .iter()
        .map(|s| {
            let f = |k: &str| s[k].as_f64().unwrap_or(f64::NAN);
            let kind = if s["cpu"] == s["tx_cpu"] {
                "same CPU"
            } else {
                "cross CPU"
            };
            (kind.to_string(), [f("p50_us"), f("p99_us"), f("p99_9_us")])
        })
        .collect())
}

fn bench() -> Result<(), String> {
    let a = <Args as clap::Parser>::parse();
    let sup = supervisor();
    if !sup.is_file() {
        return Err(format!(
            "{} not found: run bash bench/latency.sh (it builds it) or set SUPERVISOR_BIN",
            sup.display()
        ));
    }
    let version = run(Command::new("cyclictest").arg("--help"))
        .or_else(|e| {
            if e.contains("No such file") || e.contains("not found") {
                Err("cyclictest not found: apt-get install rt-tests".to_string())
            } else {
                Ok(e) // cyclictest --help exits non-zero but prints its version
            }
        })?
        .lines()
        .find(|l| l.contains("cyclictest V"))
        .unwrap_or("cyclictest")
        .trim()
        .to_string();
    let dir = std::env::temp_dir().join(format!("rtc-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let (i, p, d) = (
        a.interval_us.to_string(),
        a.priority.to_string(),
        a.duration.to_string(),
    );
    println!(
        "# latency bench: {} rounds, {} s per measurement, interval {} µs, SCHED_FIFO {}; {version}",
        a.rounds, a.duration, a.interval_us, a.priority
    );
    println!(
        "# figures in µs: median / p99 / p99.9; timer from 1-µs histograms (cyclictest's file format)"
    );
    let mut timer_ratios = Vec::new();
    let mut hop_ratios: Vec<(String, Figures)> = Vec::new();
    let show = |name: &str, f: &Figures, clipped: bool| {
        println!(
            "  {name:<28} {:>8.1} {:>8.1} {:>8.1}{}",
            f[0],
            f[1],
            f[2],
            if clipped {
                "  (p99.9 beyond the range)"
            } else {
                ""
            }
        );
    };
    for round in 1..=a.rounds {
        println!("round {round}");
        let ct_file = dir.join("cyclictest.hist");
        let ours_file = dir.join("ours.hist");
        // Quiet, the same priority, interval and duration for both.
        let same = ["-q", "-p", &p, "-i", &i, "-D", &d];
        let cyclictest = || {
            run(Command::new("cyclictest")
                .args(["-m", "-S", "-d", "0"])
                .args(same)
                .args(["-h", &RANGE_US.to_string()])
                .arg(format!("--histfile={}", ct_file.display())))
        };
        let ours = || {
            run(Command::new(&sup)
                .args(["latency", "--test", "timer"])
                .args(same)
                .args(["--histogram-us", &RANGE_US.to_string()])
                .arg("--histfile")
                .arg(&ours_file))
        };
        if round % 2 == 1 {
            cyclictest()?;
            ours()?;
        } else {
            ours()?;
            cyclictest()?;
        }
        let (ct, ct_n, ct_clip) = from_histfile(&ct_file)?;
        let (us, us_n, us_clip) = from_histfile(&ours_file)?;
        show(&format!("cyclictest ({ct_n} samples)"), &ct, ct_clip);
        show(&format!("timer, ours ({us_n} samples)"), &us, us_clip);
        timer_ratios.push(ratios(&us, &ct));

        let order = if round % 2 == 1 {
            "pipe,ipc"
        } else {
            "ipc,pipe"
        };
        let json = run(Command::new(&sup).args([
            "latency", "--test", order, "-q", "--json", "-p", &p, "-i", &i, "-D", &d,
        ]))?;
        let pipe = hop_figures(&json, "pipe")?;
        let ipc = hop_figures(&json, "ipc")?;
        for (kind, base) in &pipe {
            if let Some((_, ours)) = ipc.iter().find(|(k, _)| k == kind) {
                show(&format!("pipe hop, {kind}"), base, false);
                show(&format!("ipc hop, ours, {kind}"), ours, false);
                hop_ratios.push((kind.clone(), ratios(ours, base)));
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    println!("\nratios ours / baseline, median over {} rounds:", a.rounds);
    println!("  {:<28} {:>8} {:>8} {:>8}", "", "median", "p99", "p99.9");
    let line = |name: &str, rs: Vec<Figures>, goal: &str| {
        let m = [0, 1, 2].map(|k| median(rs.iter().map(|r| r[k]).collect()));
        println!(
            "  {name:<28} {:>8.2} {:>8.2} {:>8.2}   {goal}",
            m[0], m[1], m[2]
        );
    };
    line("timer / cyclictest", timer_ratios, "goal: p99 <= 1.2");
    for kind in ["cross CPU", "same CPU"] {
        let rs: Vec<Figures> = hop_ratios
            .iter()
            .filter(|(k, _)| k == kind)
            .map(|(_, r)| *r)
            .collect();
        if !rs.is_empty() {
            line(&format!("ipc / pipe, {kind}"), rs, "goal: median <= 1.5");
        }
    }
    Ok(())
}
