//! The Modbus load benchmark: the real-time processes' wake-up latency with and without
//! Modbus clients hammering the server, in one run, alternating.
//!
//! It brings the default cell up (its own instance, the server on any free port), then per
//! round measures a quiet window and a loaded one (the order alternates from round to round):
//! loaded, `--clients` threads on loopback each send read requests of the whole input register
//! table back to back (as fast as the server answers), and one more thread opens and closes
//! connections beyond `max_connections` all along. Each window's wake-up latency per process
//! is the difference of the process' own histograms (`<i>/<name>/latency`) between its start
//! and its end. Prints every window, then per process the median over rounds of the ratios
//! loaded/quiet for p99, p99.9 and the maximum.
//!
//! Run it with `bash bench/modbus.sh [--rounds N] [--duration S] [--clients N]
//! [--interval-ms N]` (root, for `SCHED_FIFO`, as a controller runs); `--interval-ms` paces
//! each client as an HMI polls (0, the default: back to back, the worst a client can do).

use integration_tests::median;
use runtime::ipc::Sub;
use shm_schema::{InstanceName, LatencyHistogramV1, ProcessName, ServiceId};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

const PROCESSES: [&str; 4] = ["drives", "servo", "trajgen", "iobridge"];

/// The Modbus load benchmark: the real-time processes' wake-up latency with and without clients.
#[derive(clap::Parser)]
#[command(name = "load")]
struct Args {
    /// Rounds, each a quiet and a loaded window.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    rounds: u32,
    /// Each window's length (s).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    duration: u64,
    /// Client threads reading back to back (or paced by --interval-ms).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u16).range(1..=64))]
    clients: u16,
    /// Between a client's requests (ms); 0: back to back.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u64).range(..=10_000))]
    interval_ms: u64,
    // `cargo bench` passes it.
    #[arg(long, hide = true)]
    bench: bool,
}

fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("exe");
    exe.parent()
        .and_then(|p| p.parent())
        .expect("target/release")
        .to_path_buf()
}

fn supervisor() -> Command {
    Command::new(bin_dir().join("supervisor"))
}

/// `supervisor up` on a default cell whose server takes any free port; down on drop.
struct Cell {
    inst: String,
    child: Child,
}

impl Drop for Cell {
    fn drop(&mut self) {
        let _ = supervisor()
            .args(["down", "--instance", &self.inst])
            .status();
        let _ = self.child.wait();
    }
}

fn status(inst: &str) -> Option<serde_json::Value> {
    let out = supervisor()
        .args(["status", "--json", "--instance", inst])
        .output()
        .ok()?;
    serde_json::from_slice(&out.stdout).ok()
}

fn bring_up(clients: usize) -> (Cell, SocketAddr) {
    let inst = format!("bench-mb-{}", std::process::id());
    let src = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples/gantry-uba.toml"),
    )
    .expect("default cell")
    .replace("listen = \"127.0.0.1:1502\"", "listen = \"127.0.0.1:0\"")
    .replace(
        "max_connections = 8",
        &format!("max_connections = {clients}"),
    );
    let cfg = std::env::temp_dir().join(format!("{inst}.toml"));
    std::fs::write(&cfg, src).expect("config");
    let child = supervisor()
        .args(["up", "--instance", &inst, "--config"])
        .arg(&cfg)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("supervisor up");
    let cell = Cell { inst, child };
    let start = Instant::now();
    loop {
        if let Some(s) = status(&cell.inst)
            && s["supervisor"]["arm"]["enabled"] == true
            && let Some(a) = s["supervisor"]["processes"]
                .as_array()
                .and_then(|p| p.iter().find(|p| p["name"] == "modbus"))
                .and_then(|p| p["listening"].as_str())
                .and_then(|a| a.parse().ok())
        {
            return (cell, a);
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the cell never came up"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// One client: reads the whole input register table back to back until `stop`.
fn client(a: SocketAddr, interval: Duration, stop: Arc<AtomicBool>, served: Arc<AtomicU64>) {
    let Ok(mut s) = TcpStream::connect(a) else {
        return;
    };
    let _ = s.set_nodelay(true);
    let mut resp = [0u8; 260];
    let mut tid = 0u16;
    while !stop.load(Ordering::Relaxed) {
        tid = tid.wrapping_add(1);
        let [t0, t1] = tid.to_be_bytes();
        if s.write_all(&[t0, t1, 0, 0, 0, 6, 1, 4, 0, 0, 0, 56])
            .is_err()
        {
            return;
        }
        if s.read_exact(&mut resp[..9 + 112]).is_err() {
            return;
        }
        served.fetch_add(1, Ordering::Relaxed);
        if !interval.is_zero() {
            std::thread::sleep(interval);
        }
    }
}

/// Connects and drops connections beyond the limit until `stop`; the number refused.
fn churn(a: SocketAddr, stop: Arc<AtomicBool>, refused: Arc<AtomicU64>) {
    while !stop.load(Ordering::Relaxed) {
        if let Ok(mut s) = TcpStream::connect(a) {
            // Served (a place was free): it sends nothing and leaves.
            let _ = s.set_read_timeout(Some(Duration::from_millis(100)));
            let mut b = [0u8; 1];
            if matches!(s.read(&mut b), Ok(0)) {
                refused.fetch_add(1, Ordering::Relaxed);
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

struct Subs {
    subs: Vec<Sub<LatencyHistogramV1>>,
    _node: iceoryx2::prelude::Node<runtime::ipc::Ipc>,
}

impl Subs {
    fn new(inst: &str) -> Self {
        let i = InstanceName::new(inst).expect("instance");
        let node = runtime::ipc::node(&i, "bench").expect("node");
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

fn main() {
    let a = <Args as clap::Parser>::parse();
    let (cell, addr) = bring_up(a.clients.into());
    let subs = Subs::new(&cell.inst);
    println!(
        "Modbus load: {} rounds of {} s quiet and {} s with {} clients on {addr}, each {} (and connections beyond the limit)",
        a.rounds,
        a.duration,
        a.duration,
        a.clients,
        if a.interval_ms == 0 {
            "reading back to back".to_string()
        } else {
            format!("reading every {} ms", a.interval_ms)
        }
    );
    // Per process, per round: [quiet, loaded] figures.
    let mut results: Vec<Vec<[[f64; 3]; 2]>> = vec![Vec::new(); PROCESSES.len()];
    for round in 0..a.rounds {
        let mut pair = [[[0.0; 3]; 2]; PROCESSES.len()];
        for step in 0..2 {
            let loaded = (round + step) % 2 == 1;
            let stop = Arc::new(AtomicBool::new(false));
            let served = Arc::new(AtomicU64::new(0));
            let refused = Arc::new(AtomicU64::new(0));
            let mut threads = Vec::new();
            if loaded {
                for _ in 0..a.clients {
                    let (s, n) = (stop.clone(), served.clone());
                    let every = Duration::from_millis(a.interval_ms);
                    threads.push(std::thread::spawn(move || client(addr, every, s, n)));
                }
                let (s, n) = (stop.clone(), refused.clone());
                threads.push(std::thread::spawn(move || churn(addr, s, n)));
            }
            let before = subs.snapshot();
            std::thread::sleep(Duration::from_secs(a.duration));
            let after = subs.snapshot();
            stop.store(true, Ordering::Relaxed);
            for t in threads {
                let _ = t.join();
            }
            let label = if loaded { "loaded" } else { "quiet " };
            let mut line = format!("round {} {label}", round + 1);
            for (k, p) in PROCESSES.iter().enumerate() {
                let f = figures(&window(&before[k], &after[k]));
                pair[k][usize::from(loaded)] = f;
                line += &format!("  {p} p99 {:.1} max {:.1}", f[0], f[2]);
            }
            if loaded {
                let secs = a.duration as f64 + 0.5;
                line += &format!(
                    "  ({:.0} requests/s served, {:.0} connections/s refused)",
                    served.load(Ordering::Relaxed) as f64 / secs,
                    refused.load(Ordering::Relaxed) as f64 / secs
                );
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
    drop(subs);
    drop(cell);
}
