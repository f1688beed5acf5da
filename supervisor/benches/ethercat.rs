//! The EtherCAT benchmark: the seed's triangle on the same cell (examples/gantry-ethercat.toml:
//! CSP drives, the same gains and periods) with its drives in shared memory (`machine-sim`),
//! on the emulated bus taking their data as the frame passes (`sync = "frame"`), and on the
//! emulated bus on Distributed Clocks (`sync = "dc"`, the example's), at 1 kHz and at 4 kHz
//! (the drives and servo at 250 µs), in turn, round after round, in one run. Each run is in
//! a network namespace of its own, the shared-memory one too, for the same conditions.
//!
//! Per run, from `supervisor run --json` and the bus process' log: the drives process'
//! wake-up latency and execution time (p50, p99, max), the frame round trip (p50, p99, max;
//! the bus only), on DC how long before SYNC0 the frame came (p50, least) and the SYNC0 events
//! no frame came before, sense to command (p50, p99, max), the peak following error per axis,
//! and measured − theoretical motion time. At the end, per rate, the medians over rounds and
//! the ratios bus / shared memory. Speeds are reported, never asserted.
//!
//! Run it with `bash bench/ethercat.sh [--rounds N]` (root: network namespaces, `SCHED_FIFO`).

mod common;

use integration_tests::median;
use serde_json::Value;
use std::path::Path;
use std::process::Command;

const AXES: [&str; 3] = ["x", "y", "theta"];

use common::{binary, root};

/// What one run measured (µs unless said).
#[derive(Clone, Debug, Default)]
struct Run {
    /// The drives process: wake-up p50, p99, max; execution time p50, p99, max.
    drives: [f64; 6],
    /// Frame round trip p50, p99, max (NaN in shared memory).
    round_trip: [f64; 3],
    /// On DC: how long before SYNC0 the frame came, p50 and least; SYNC0 events with no
    /// frame before them (NaN otherwise).
    sync0: [f64; 3],
    /// Sense to command p50, p99, max.
    s2c: [f64; 3],
    /// Peak |following error| per axis (the axis' unit).
    fe: [f64; 3],
    /// measured − theoretical (ms).
    diff_ms: f64,
}

/// Where the drives are.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// `machine-sim` in shared memory.
    Shm,
    /// On the bus, taking their data as the frame passes.
    Frame,
    /// On the bus, on SYNC0 of Distributed Clocks.
    Dc,
}

const KINDS: [(Kind, &str); 3] = [
    (Kind::Shm, "shared memory"),
    (Kind::Frame, "EtherCAT, as the frame passes"),
    (Kind::Dc, "EtherCAT, on SYNC0"),
];

/// The example cell at `period_us` (the drives and servo; their phases scaled as
/// `integration_tests::at_rate` does), its drives as `kind` says.
fn cell(period_us: u64, kind: Kind) -> String {
    let src = std::fs::read_to_string(root().join("examples/gantry-ethercat.toml"))
        .expect("examples/gantry-ethercat.toml");
    let mut src = integration_tests::at_rate(&src, period_us)
        .replace("listen = \"127.0.0.1:1503\"", "listen = \"127.0.0.1:0\"");
    if kind == Kind::Frame {
        // Each drive's entry (the only entries with an `axis` key).
        src = src.replace("\naxis = \"", "\nsync = \"frame\"\naxis = \"");
    }
    if kind == Kind::Shm {
        // The same cell in shared memory: machine-sim as the drives, no emulator, no bus.
        let at = src
            .find("[[process]]\nname = \"emulator\"")
            .expect("the emulator's entry");
        let end = at + src[at..].find("\n\n").expect("its end") + 2;
        src.replace_range(at..end, "");
        src = src.replace(
            "command = [\"ethercat-bus\", \"--instance\", \"{instance}\"]",
            "command = [\"machine-sim\", \"--instance\", \"{instance}\"]",
        );
        let at = src.find("\n[ethercat]\n").expect("[ethercat]");
        src.truncate(at + 1);
        src = src
            .lines()
            .filter(|l| !l.starts_with("ethercat = {"))
            .collect::<Vec<_>>()
            .join("\n");
    }
    src
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {args:?}: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// A number after `key` in `text` ("p50 12.3 µs").
fn after(text: &str, key: &str) -> f64 {
    text.find(key)
        .and_then(|at| {
            text[at + key.len()..]
                .split_whitespace()
                .next()?
                .trim_end_matches(',')
                .parse()
                .ok()
        })
        .unwrap_or(f64::NAN)
}

fn one(config: &Path, instance: &str) -> Result<Run, String> {
    let ns = format!("rtc-bench-{instance}");
    ip(&["netns", "add", &ns])?;
    let out = ip(&["-n", &ns, "link", "set", "lo", "up"]).and_then(|()| {
        Command::new("ip")
            .args(["netns", "exec", &ns])
            .arg(binary("supervisor"))
            // The bus process tells its frames' round trip at info when it stops.
            .env("RTC_LOG", "warn,ethercat_bus=info")
            .args(["run", "--json", "--instance", instance, "--config"])
            .arg(config)
            .arg(root().join("examples/triangle.prog"))
            .output()
            .map_err(|e| format!("supervisor: {e}"))
    });
    let _ = ip(&["netns", "del", &ns]);
    let out = out?;
    let log = String::from_utf8_lossy(&out.stderr);
    let j: Value =
        serde_json::from_slice(&out.stdout).map_err(|e| format!("not JSON ({e}): {log}"))?;
    if j["ok"] != true {
        return Err(format!("run failed: {}", j["error"]));
    }
    let f = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let d = &j["processes"]["drives"];
    let (w, e) = (&d["wakeup_latency_us"], &d["exec_time_us"]);
    let s = &j["sense_to_command_us"];
    let trip = log
        .lines()
        .find(|l| l.contains("frame round trip over"))
        .unwrap_or_default();
    let sync0 = log
        .lines()
        .find(|l| l.contains("SYNC0 events with no new frame"))
        .unwrap_or_default();
    Ok(Run {
        drives: [
            f(&w["p50_us"]),
            f(&w["p99_us"]),
            f(&w["max_us"]),
            f(&e["p50_us"]),
            f(&e["p99_us"]),
            f(&e["max_us"]),
        ],
        round_trip: [after(trip, "p50"), after(trip, "p99"), after(trip, "max")],
        sync0: [
            after(sync0, "came p50"),
            after(sync0, "least"),
            after(sync0, "frames;"),
        ],
        s2c: [f(&s["p50_us"]), f(&s["p99_us"]), f(&s["max_us"])],
        fe: std::array::from_fn(|a| f(&j["max_following_error"][AXES[a]])),
        diff_ms: f(&j["difference_s"]) * 1e3,
    })
}

fn median_run(runs: &[Run]) -> Run {
    let m = |f: &dyn Fn(&Run) -> f64| median(runs.iter().map(f).collect());
    Run {
        drives: std::array::from_fn(|k| m(&|r: &Run| r.drives[k])),
        round_trip: std::array::from_fn(|k| m(&|r: &Run| r.round_trip[k])),
        sync0: std::array::from_fn(|k| m(&|r: &Run| r.sync0[k])),
        s2c: std::array::from_fn(|k| m(&|r: &Run| r.s2c[k])),
        fe: std::array::from_fn(|k| m(&|r: &Run| r.fe[k])),
        diff_ms: m(&|r: &Run| r.diff_ms),
    }
}

fn show(label: &str, r: &Run) {
    let three = |v: &[f64]| format!("p50 {:.1}, p99 {:.1}, max {:.1}", v[0], v[1], v[2]);
    println!("{label}");
    println!("  drives wake-up (µs)     {}", three(&r.drives[..3]));
    println!("  drives exec time (µs)   {}", three(&r.drives[3..]));
    if r.round_trip[0].is_finite() {
        println!("  frame round trip (µs)   {}", three(&r.round_trip));
    }
    if r.sync0[0].is_finite() {
        println!(
            "  frame before SYNC0 (µs) p50 {:.1}, least {:.1}; {} SYNC0 with no frame before",
            r.sync0[0], r.sync0[1], r.sync0[2]
        );
    }
    println!("  sense to command (µs)   {}", three(&r.s2c));
    println!(
        "  peak following error    x {:.4} mm, y {:.4} mm, theta {:.4} deg",
        r.fe[0], r.fe[1], r.fe[2]
    );
    println!("  measured − theoretical  {:+.3} ms", r.diff_ms);
}

fn main() {
    let rounds = common::rounds(
        "ethercat",
        "The EtherCAT benchmark: the triangle with its drives in shared memory and on the bus.",
    );
    let dir = std::env::temp_dir().join(format!("rtc-ecat-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let rates = [(1000u64, "1 kHz"), (250, "4 kHz")];
    let n = KINDS.len();
    let mut results: Vec<Vec<Run>> = vec![Vec::new(); rates.len() * n];
    for round in 0..rounds {
        for (r, &(us, rate)) in rates.iter().enumerate() {
            // Each round starts with the next kind.
            for j in 0..n {
                let k = (round + j) % n;
                let (kind, label) = KINDS[k];
                let cfg = dir.join(format!("cell-{us}-{k}.toml"));
                std::fs::write(&cfg, cell(us, kind)).expect("write config");
                let inst = format!("b{}-{round}{r}{k}", std::process::id());
                match one(&cfg, &inst) {
                    Ok(run) => {
                        show(&format!("round {} at {rate}, {label}", round + 1), &run);
                        results[n * r + k].push(run);
                    }
                    Err(e) => println!("round {} at {rate}, {label}: {e}", round + 1),
                }
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    if results.iter().any(Vec::is_empty) {
        eprintln!("no complete result for one of the runs");
        std::process::exit(1);
    }
    println!("\nmedians over {rounds} rounds, and the ratios EtherCAT / shared memory");
    for (r, &(us, rate)) in rates.iter().enumerate() {
        let shm = median_run(&results[n * r]);
        show(&format!("{rate}, shared memory"), &shm);
        for (k, &(_, label)) in KINDS.iter().enumerate().skip(1) {
            let bus = median_run(&results[n * r + k]);
            show(&format!("{rate}, {label}"), &bus);
            println!("  ratios at {rate}, {label} / shared memory:");
            println!(
                "    drives exec time p99 {:.2}, wake-up p99 {:.2}",
                bus.drives[4] / shm.drives[4],
                bus.drives[1] / shm.drives[1]
            );
            println!(
                "    sense to command p50 {:.2}, p99 {:.2}; the bus adds {:+.1} µs at p50, {:+.1} µs at p99 (one drive period: {us} µs)",
                bus.s2c[0] / shm.s2c[0],
                bus.s2c[1] / shm.s2c[1],
                bus.s2c[0] - shm.s2c[0],
                bus.s2c[1] - shm.s2c[1]
            );
            println!(
                "    peak following error x {:.2}, y {:.2}; difference x {:+.4} mm, y {:+.4} mm (encoder resolution 0.001 mm)",
                bus.fe[0] / shm.fe[0],
                bus.fe[1] / shm.fe[1],
                bus.fe[0] - shm.fe[0],
                bus.fe[1] - shm.fe[1]
            );
        }
    }
}
