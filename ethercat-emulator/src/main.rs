//! `ethercat-emulator`: a line of emulated EtherCAT SubDevices answering on a network
//! interface (docs/ethercat.md). Stops on SIGTERM or SIGINT.

use clap::Parser;
use ethercat_emulator::bus::Bus;
use ethercat_emulator::terminals::Terminal;
use ethercat_emulator::wire::{Received, Wire};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Emulated EtherCAT SubDevices on an interface (one end of a veth pair, never a host's own
/// interface).
#[derive(Parser, Debug)]
#[command(name = "ethercat-emulator", version)]
struct Args {
    /// The interface to answer on.
    #[arg(long)]
    interface: String,
    /// The SubDevices in wire order: ek1100, el1008, el2008, drive (a CiA 402 drive moving
    /// the standalone axis of `drive::standalone`; the k-th drive is named `axis<k>`).
    #[arg(long, value_delimiter = ',', default_value = "ek1100,el1008,el2008")]
    line: Vec<String>,
    /// Wire the first EL2008's outputs to the first EL1008's inputs (a test cable): what a
    /// MainDevice writes comes back in a later exchange.
    #[arg(long)]
    loopback: bool,
    /// The process data watchdog every ESC starts with (ms; 0: off; at most 6553), until a
    /// MainDevice writes its own (registers 0x0400, 0x0420). A real ESC starts with 100.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u16).range(0..=6553))]
    pd_watchdog_ms: u16,
    /// Cable redundancy: the interface the line's last SubDevice is cabled to, whose other end
    /// is a MainDevice's second port. A frame that passed the line leaves there instead of
    /// going back out of `--interface`; a frame the MainDevice sends into it passes back
    /// through the line unprocessed (an ESC processes only what enters its port 0) and leaves
    /// on `--interface`.
    #[arg(long, value_name = "IFACE")]
    ring: Option<String>,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

fn terminal(name: &str, drives: &mut usize, watchdog_ns: u64) -> Option<Terminal> {
    Some(match name.trim().to_ascii_lowercase().as_str() {
        "ek1100" => Terminal::Ek1100,
        "el1008" => Terminal::El1008 { inputs: 0 },
        "el2008" => Terminal::El2008 { outputs: 0 },
        "drive" => {
            let (axis, scaling) = ethercat_emulator::drive::standalone();
            *drives += 1;
            Terminal::Drive(Box::new(ethercat_emulator::drive::Drive::new(
                &format!("axis{drives}"),
                &axis,
                scaling,
                watchdog_ns,
            )))
        }
        _ => return None,
    })
}

/// The shortest command watchdog of a drive: without a frame writing its outputs this long
/// while powered, it faults and ramps down (it is never shorter than the ESC's watchdog).
const DRIVE_WATCHDOG_MIN_NS: u64 = 100_000_000;

/// The test cable of `--loopback`: the first EL2008's outputs on the first EL1008's inputs.
fn loop_back(bus: &mut Bus) {
    let driven = bus.devices.iter().find_map(|d| match d.terminal {
        Terminal::El2008 { outputs } => Some(outputs),
        _ => None,
    });
    if let Some(level) = driven
        && let Some(Terminal::El1008 { inputs }) = bus
            .devices
            .iter_mut()
            .map(|d| &mut d.terminal)
            .find(|t| matches!(t, Terminal::El1008 { .. }))
    {
        *inputs = level;
    }
}

fn main() -> ExitCode {
    runtime::abort_on_panic();
    // In a cell (started by the supervisor with --instance) everything comes from the cell's
    // configuration.
    if std::env::args().nth(1).as_deref() == Some("fault") {
        return ethercat_emulator::cell::fault_main(std::env::args().skip(1));
    }
    if std::env::args().any(|a| a == "--instance" || a.starts_with("--instance=")) {
        return ethercat_emulator::cell::main();
    }
    runtime::process::init_logging();
    let args = Args::parse();
    let mut line = Vec::new();
    let mut drives = 0;
    let watchdog_ns = (u64::from(args.pd_watchdog_ms) * 1_000_000).max(DRIVE_WATCHDOG_MIN_NS);
    for (k, name) in args.line.iter().enumerate() {
        match terminal(name, &mut drives, watchdog_ns) {
            Some(t) => line.push(t),
            None => {
                eprintln!(
                    "error: --line entry {} ({name:?}) is not a SubDevice this emulator has \
                     (ek1100, el1008, el2008, drive)",
                    k + 1
                );
                return ExitCode::from(2);
            }
        }
    }
    let handler = nix::sys::signal::SigHandler::Handler(on_signal);
    for sig in [
        nix::sys::signal::Signal::SIGTERM,
        nix::sys::signal::Signal::SIGINT,
    ] {
        // SAFETY: the handler only stores to an atomic.
        if let Err(e) = unsafe { nix::sys::signal::signal(sig, handler) } {
            eprintln!("error: cannot handle {sig}: {e}");
            return ExitCode::FAILURE;
        }
    }
    // A short receive timeout: between frames the drives' models run on (their watchdog).
    let wire = match Wire::open(&args.interface, Duration::from_millis(5)) {
        Ok(w) => w,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    if args.ring.as_deref() == Some(args.interface.as_str()) {
        eprintln!(
            "error: --ring {} is --interface: a ring needs a second interface",
            args.interface
        );
        return ExitCode::from(2);
    }
    let ring = match args
        .ring
        .as_deref()
        .map(|i| Wire::open(i, Duration::from_millis(5)))
    {
        None => None,
        Some(Ok(w)) => Some(w),
        Some(Err(e)) => {
            eprintln!("error: --ring: {e}");
            return ExitCode::from(2);
        }
    };
    let names: Vec<String> = line.iter().map(|t| t.name().to_string()).collect();
    let mut bus = Bus::new(line);
    if ring.is_some() {
        bus.close_ring();
    }
    for d in &mut bus.devices {
        // Increments of 100 µs (the default divider).
        d.esc.write(
            ethercat_emulator::esc::reg::WATCHDOG_TIME_PD,
            &(args.pd_watchdog_ms * 10).to_le_bytes(),
        );
    }
    tracing::info!(
        "answering on {}{}: {} SubDevice(s): {}",
        args.interface,
        args.ring
            .as_deref()
            .map_or(String::new(), |r| format!(" (a ring back on {r})")),
        names.len(),
        names.join(", ")
    );
    if let Err(e) = runtime::notify::ready() {
        tracing::warn!("cannot say it is ready: {e}");
    }
    std::thread::scope(|s| {
        let back = ring.as_ref().map(|ring| s.spawn(|| pass_back(ring, &wire)));
        let code = answer(
            &wire,
            ring.as_ref().unwrap_or(&wire),
            &mut bus,
            args.loopback,
        );
        match back.map(|b| b.join()) {
            Some(Ok(false) | Err(_)) => ExitCode::FAILURE,
            _ => code,
        }
    })
}

/// Answers the frames that come in on `wire`: each passes the line and leaves on `out` (the
/// same wire, or the ring's). Until SIGTERM or SIGINT.
fn answer(wire: &Wire, out: &Wire, bus: &mut Bus, loopback: bool) -> ExitCode {
    let mut buf = vec![0u8; 9216];
    let (mut answered, mut refused) = (0u64, 0u64);
    while !STOP.load(Ordering::SeqCst) {
        let n = match wire.receive(&mut buf) {
            Ok(Received::Frame(n)) => n,
            Ok(Received::Nothing) => {
                bus.idle();
                continue;
            }
            Err(e) => {
                tracing::error!("{e}");
                STOP.store(true, Ordering::SeqCst);
                return ExitCode::FAILURE;
            }
        };
        // Every EtherCAT frame that arrives is processed, whatever its source address (as
        // an ESC does; masters differ: kickcat's has the locally administered bit). Our own
        // replies never come back here: the socket leaves out what this host sent.
        let frame = &mut buf[..n];
        match bus.handle(frame) {
            Ok(_) => {
                if loopback {
                    loop_back(bus);
                }
                if let Err(e) = out.send(frame) {
                    tracing::warn!("{e}");
                }
                answered += 1;
            }
            Err(e) => {
                refused += 1;
                tracing::debug!("dropped a frame: {e}");
            }
        }
    }
    tracing::info!("stopped: {answered} frames answered, {refused} dropped");
    ExitCode::SUCCESS
}

/// The ring's way back: what the MainDevice's second port sends into the line's last
/// SubDevice comes out of the first one's port 0 as it went in. Until the emulator stops;
/// false if the ring's interface failed (the emulator stops then).
fn pass_back(ring: &Wire, wire: &Wire) -> bool {
    let mut buf = vec![0u8; 9216];
    let mut passed = 0u64;
    while !STOP.load(Ordering::SeqCst) {
        match ring.receive(&mut buf) {
            Ok(Received::Frame(n)) => match wire.send(&buf[..n]) {
                Ok(()) => passed += 1,
                Err(e) => tracing::warn!("{e}"),
            },
            Ok(Received::Nothing) => {}
            Err(e) => {
                tracing::error!("{e}");
                STOP.store(true, Ordering::SeqCst);
                return false;
            }
        }
    }
    tracing::info!("ring: {passed} frames passed back unprocessed");
    true
}
