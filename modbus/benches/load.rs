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

use integration_tests::load::Cell;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

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

/// The default cell, its server on any free port, up: the cell and the server's address.
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
    let listening = |s: &serde_json::Value| -> Option<SocketAddr> {
        s["supervisor"]["processes"]
            .as_array()?
            .iter()
            .find(|p| p["name"] == "modbus")?["listening"]
            .as_str()?
            .parse()
            .ok()
    };
    let (cell, s) = Cell::up(&inst, &cfg, |s| {
        s["supervisor"]["arm"]["enabled"] == true && listening(s).is_some()
    });
    let addr = listening(&s).expect("listening");
    (cell, addr)
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

fn main() {
    let a = <Args as clap::Parser>::parse();
    let (cell, addr) = bring_up(a.clients.into());
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
    integration_tests::load::alternate(
        &cell.inst,
        a.rounds,
        Duration::from_secs(a.duration),
        || {
            let mut load = integration_tests::load::Load::default();
            let served = load.counter("requests/s served");
            for _ in 0..a.clients {
                let (s, n) = (load.stop_flag(), served.clone());
                let every = Duration::from_millis(a.interval_ms);
                load.spawn(move || client(addr, every, s, n));
            }
            let (s, n) = (load.stop_flag(), load.counter("connections/s refused"));
            load.spawn(move || churn(addr, s, n));
            load
        },
    );
    drop(cell);
}
