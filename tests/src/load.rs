//! The load benchmarks' harness (`bench/modbus.sh`, `bench/line.sh`): a running cell's
//! real-time processes' wake-up latency in quiet windows and in windows under a load,
//! alternating round after round (the order swapped every round), each window the difference
//! of the processes' own histograms (`<i>/<name>/latency`) between its start and its end; at
//! the end, per process, the medians over rounds of the ratios loaded / quiet. Speeds are
//! reported, never asserted.

use crate::median;
use runtime::ipc::{self, InstanceName, Ipc, Node, ServiceId, Sub};
use serde_json::Value;
use shm_schema::{LatencyHistogramV1, ProcessName};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The real-time processes measured.
pub const PROCESSES: [&str; 4] = ["drives", "servo", "trajgen", "iobridge"];

/// The supervisor built beside the running bench (its script builds the workspace's binaries
/// first: no build here).
pub fn supervisor() -> Command {
    let exe = std::env::current_exe().expect("the bench's path");
    let dir = exe.parent().and_then(Path::parent).expect("target/release");
    Command::new(dir.join("supervisor"))
}

/// A cell brought up for a bench by `supervisor up`; down on drop.
#[derive(Debug)]
pub struct Cell {
    /// Its instance.
    pub inst: String,
    child: Child,
}

impl Cell {
    /// `supervisor up` of `cfg` on instance `inst`, once its `status --json` satisfies
    /// `ready` (at most a minute, a panic then); that status.
    pub fn up(inst: &str, cfg: &Path, ready: impl Fn(&Value) -> bool) -> (Self, Value) {
        let child = supervisor()
            .args(["up", "--instance", inst, "--config"])
            .arg(cfg)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("supervisor up");
        let cell = Self {
            inst: inst.into(),
            child,
        };
        let start = Instant::now();
        loop {
            let status = supervisor()
                .args(["status", "--json", "--instance", inst])
                .output()
                .ok()
                .and_then(|o| serde_json::from_slice::<Value>(&o.stdout).ok());
            if let Some(s) = status.filter(&ready) {
                return (cell, s);
            }
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "the cell never came up"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Cell {
    fn drop(&mut self) {
        let _ = supervisor()
            .args(["down", "--instance", &self.inst])
            .status();
        let _ = self.child.wait();
    }
}

/// A load, running until it is stopped: its threads and what they count.
#[derive(Debug, Default)]
pub struct Load {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    counters: Vec<(&'static str, Arc<AtomicU64>)>,
}

impl Load {
    /// Set when the load must stop: each thread checks it between its requests.
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// A counter reported per second after the window, as `<n> <what>`.
    pub fn counter(&mut self, what: &'static str) -> Arc<AtomicU64> {
        let c = Arc::new(AtomicU64::new(0));
        self.counters.push((what, c.clone()));
        c
    }

    /// Runs `f` on a thread of the load.
    pub fn spawn(&mut self, f: impl FnOnce() + Send + 'static) {
        self.threads.push(std::thread::spawn(f));
    }

    /// Stops and joins the threads; what they counted, per second of `secs`.
    fn end(self, secs: f64) -> String {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads {
            let _ = t.join();
        }
        self.counters
            .iter()
            .map(|(what, c)| format!("{:.0} {what}", c.load(Ordering::Relaxed) as f64 / secs))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The processes' latency histograms of one instance.
struct Subs {
    subs: Vec<Sub<LatencyHistogramV1>>,
    _node: Node<Ipc>,
}

impl Subs {
    fn new(inst: &str) -> Self {
        let i = InstanceName::new(inst).expect("instance");
        let node = ipc::node(&i, "bench").expect("node");
        let subs = PROCESSES
            .iter()
            .map(|p| {
                let name = ProcessName::new(p).expect("name");
                Sub::new(&node, &i, ServiceId::Latency(name), 2).expect("latency service")
            })
            .collect();
        Self { subs, _node: node }
    }

    /// Each process' newest histogram (published about every 100 ms).
    fn snapshot(&self) -> Vec<LatencyHistogramV1> {
        std::thread::sleep(Duration::from_millis(250));
        self.subs
            .iter()
            .map(|s| s.latest().expect("a histogram"))
            .collect()
    }
}

/// The samples of `b` that are not in `a`.
fn window(a: &LatencyHistogramV1, b: &LatencyHistogramV1) -> Box<LatencyHistogramV1> {
    let mut d = Box::new(*b);
    d.count = b.count - a.count;
    d.overflows = b.overflows - a.overflows;
    d.min_ns = 0;
    d.max_ns = u64::MAX;
    for (x, y) in d.buckets.iter_mut().zip(a.buckets.iter()) {
        *x -= y;
    }
    d
}

/// (p99, p99.9, max) in µs.
fn figures(h: &LatencyHistogramV1) -> [f64; 3] {
    let us = |v: Option<u64>| v.unwrap_or(0) as f64 / 1000.0;
    [
        us(h.percentile(99, 100)),
        us(h.percentile(999, 1000)),
        us(h.value_at_rank(h.count)),
    ]
}

/// Alternates, on instance `inst`, `rounds` rounds of a quiet window and a loaded one of
/// `duration` each (the load `start` starts, stopped at the window's end); prints every window
/// and then, per process, the medians over rounds of the ratios loaded / quiet.
pub fn alternate(inst: &str, rounds: u32, duration: Duration, mut start: impl FnMut() -> Load) {
    let subs = Subs::new(inst);
    // Per process, per round: [quiet, loaded] figures.
    let mut results: Vec<Vec<[[f64; 3]; 2]>> = vec![Vec::new(); PROCESSES.len()];
    for round in 0..rounds {
        let mut pair = [[[0.0; 3]; 2]; PROCESSES.len()];
        for step in 0..2 {
            let loaded = (round + step) % 2 == 1;
            let load = loaded.then(&mut start);
            let before = subs.snapshot();
            std::thread::sleep(duration);
            let after = subs.snapshot();
            let counted = load.map(|l| l.end(duration.as_secs_f64() + 0.5));
            let label = if loaded { "loaded" } else { "quiet " };
            let mut line = format!("round {} {label}", round + 1);
            for (k, p) in PROCESSES.iter().enumerate() {
                let f = figures(&window(&before[k], &after[k]));
                pair[k][usize::from(loaded)] = f;
                line += &format!("  {p} p99 {:.1} max {:.1}", f[0], f[2]);
            }
            if let Some(c) = counted {
                line += &format!("  ({c})");
            }
            println!("{line}");
        }
        for (k, p) in pair.into_iter().enumerate() {
            results[k].push(p);
        }
    }
    println!("\nwake-up latency, loaded / quiet (median over rounds; 1.00 = unchanged):");
    println!("process     p99    p99.9   max     (quiet p99 / max µs, loaded p99 / max µs)");
    for (k, p) in PROCESSES.iter().enumerate() {
        let r = &results[k];
        let ratio = |i: usize| median(r.iter().map(|x| x[1][i] / x[0][i].max(1e-3)).collect());
        let med = |l: usize, i: usize| median(r.iter().map(|x| x[l][i]).collect());
        println!(
            "{p:<10} {:>5.2}  {:>6.2}  {:>5.2}    ({:.1} / {:.1}, {:.1} / {:.1})",
            ratio(0),
            ratio(1),
            ratio(2),
            med(0, 0),
            med(0, 2),
            med(1, 0),
            med(1, 2)
        );
    }
}
