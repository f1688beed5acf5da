//! The line's load benchmark: the real-time processes' wake-up latency with and without a busy
//! remote client of the cell's gateway, in one run, alternating (`integration_tests::load`).
//!
//! It brings the default cell up with its gateway on loopback (its own instance, a free port),
//! then per round measures a quiet window and a loaded one: loaded, `--clients` threads of one
//! Zenoh session ask back to back, in turn, for the cell's status (answered by the gateway
//! from its latest) and for a signed `status` command (judged by the gateway, then composed by
//! the supervisor on the control channel), while a subscriber takes every event. Prints every
//! window, then per process the median over rounds of the ratios loaded / quiet.
//!
//! Run it with `bash bench/line.sh [--rounds N] [--duration S] [--clients N]` (root, for
//! `SCHED_FIFO`, as a controller runs).

use gateway::auth::{Envelope, now_ms};
use gateway::command::Command;
use gateway::keys::{CellKeys, CellName};
use gateway::link::Link;
use integration_tests::load::{Cell, Load, alternate};
use std::os::unix::fs::PermissionsExt;
use std::sync::atomic::Ordering;
use std::time::Duration;
use zenoh::Wait;

/// The line's load benchmark: wake-up latency with and without a busy remote client.
#[derive(clap::Parser)]
#[command(name = "line")]
struct Args {
    /// Rounds, each a quiet and a loaded window.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    rounds: u32,
    /// Each window's length (s).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    duration: u64,
    /// Client threads asking back to back.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u16).range(1..=64))]
    clients: u16,
    // `cargo bench` passes it.
    #[arg(long, hide = true)]
    bench: bool,
}

const SECRET: &str = "bench-viewer-secret-0123456789";

/// The default cell with its gateway listening on `port` of loopback, up.
fn bring_up(port: u16) -> Cell {
    let inst = format!("bench-line-{}", std::process::id());
    let dir = std::env::temp_dir().join(&inst);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let users = dir.join("users.toml");
    std::fs::write(
        &users,
        format!("[[user]]\nname = \"bench\"\nrole = \"viewer\"\nsecret = \"{SECRET}\"\n"),
    )
    .expect("users");
    std::fs::set_permissions(&users, std::fs::Permissions::from_mode(0o600)).expect("chmod");
    // The wall clock: the benchmark measures the real-time processes' wake-up latency.
    let cell = integration_tests::wall_cell()
        .replace("listen = \"127.0.0.1:1502\"", "listen = \"127.0.0.1:0\"")
        + &format!(
            "\n[[process]]\nname = \"gateway\"\ncommand = [\"gateway\", \"--instance\", \"{{instance}}\"]\n\
         period_us = 20000\npriority = 0\ncritical = false\nnetwork_estop_config = \"ignore\"\n\n\
         [network]\nname = \"bench\"\nlisten = [\"tcp/127.0.0.1:{port}\"]\nplain = true\n\
         users = \"{}\"\n",
            users.display()
        );
    let cfg = dir.join("cell.toml");
    std::fs::write(&cfg, cell).expect("config");
    Cell::up(&inst, &cfg, |s| s["supervisor"]["arm"]["enabled"] == true).0
}

/// A signed `status` command of the bench's viewer.
fn signed_status(cell: &CellName, nonce: u64) -> (Vec<u8>, String) {
    Envelope {
        user: "bench".into(),
        cell: cell.to_string(),
        time_ms: now_ms(),
        nonce,
        command: Command::Status {},
    }
    .signed(SECRET.as_bytes())
}

fn main() {
    let a = <Args as clap::Parser>::parse();
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let cell = bring_up(port);
    let name = CellName::new("bench").expect("name");
    let connect = [format!("tcp/127.0.0.1:{port}")];
    let session = Link {
        mode: cell_config::network::Mode::Peer,
        listen: &[],
        connect: &connect,
        multicast: false,
        lease_s: 3.0,
        tls: None,
        login: None,
        access: gateway::link::Access::Open,
    }
    .open()
    .expect("join the line");
    std::thread::sleep(Duration::from_secs(1));
    println!(
        "line load: {} rounds of {} s quiet and {} s with {} clients of the gateway on {}",
        a.rounds, a.duration, a.duration, a.clients, connect[0]
    );
    let mut nonce = 0u64;
    alternate(
        &cell.inst,
        a.rounds,
        Duration::from_secs(a.duration),
        || {
            let mut load = Load::default();
            let gets = load.counter("status gets/s");
            let commands = load.counter("status commands/s");
            for k in 0..a.clients {
                let (stop, gets, commands) = (load.stop_flag(), gets.clone(), commands.clone());
                let (session, name) = (session.clone(), name.clone());
                nonce += 1 << 32;
                let base = nonce + (u64::from(k) << 24);
                load.spawn(move || {
                    let mut n = base;
                    while !stop.load(Ordering::Relaxed) {
                        if let Ok(r) = session.get(name.status()).wait() {
                            while r.recv().is_ok() {}
                            gets.fetch_add(1, Ordering::Relaxed);
                        }
                        n += 1;
                        let (payload, signature) = signed_status(&name, n);
                        if let Ok(r) = session
                            .get(name.control())
                            .payload(payload)
                            .attachment(signature)
                            .wait()
                        {
                            while r.recv().is_ok() {}
                            commands.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                });
            }
            let (stop, events) = (load.stop_flag(), load.counter("events/s"));
            let sub = session
                .declare_subscriber(name.events())
                .wait()
                .expect("events");
            load.spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    if let Ok(Some(_)) = sub.recv_timeout(Duration::from_millis(100)) {
                        events.fetch_add(1, Ordering::Relaxed);
                    }
                }
            });
            load
        },
    );
    drop(session);
    drop(cell);
}
