//! The sending side of a hop, a process of its own: trajgen's side.
//!
//! Every interval (a [`CycleClock`] of the cycle runtime, at the given phase) it stamps a setpoint with
//! `CLOCK_MONOTONIC` and sends it: for the IPC hop `Pub::send` then `Notifier::notify` (what
//! trajgen does each cycle), for the pipe and Unix-socket baselines an 8-byte `write` of the
//! stamp to stdout (a pipe or a datagram socket).
//! It stops on SIGTERM/SIGINT, when the pipe's reader is gone, or when the thread that
//! started it exits (`PR_SET_PDEATHSIG`).

use crate::Test;
use runtime::cycle::{CycleClock, WaitError};
use runtime::ipc::{self, Notifier, Pub};
use runtime::rt::{self, RtRequest};
use runtime::signals;
use runtime::time::now_ns;
use shm_schema::{InstanceName, ServiceId, SetpointV2};

/// What the sender is told (`supervisor latency-peer`'s arguments).
#[derive(Clone, Debug, PartialEq, Eq, clap::Args)]
pub struct Args {
    /// ipc, pipe or unix.
    #[arg(long, value_parser = transport)]
    pub transport: Test,
    /// Instance of the IPC hop's services.
    #[arg(long)]
    pub instance: String,
    /// Period (µs).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub interval_us: u64,
    /// Phase on the grid (µs).
    #[arg(long, default_value_t = 0)]
    pub phase_us: u64,
    /// CPU to pin to.
    #[arg(long)]
    pub cpu: usize,
    /// `SCHED_FIFO` priority (0: `SCHED_OTHER`).
    #[arg(long)]
    pub priority: i32,
}

fn transport(name: &str) -> Result<Test, String> {
    Test::from_name(name)
        .filter(|t| *t != Test::Timer)
        .ok_or_else(|| format!("{name:?} is not ipc, pipe or unix"))
}

impl Args {
    /// As command-line arguments (what clap reads back).
    pub fn to_args(&self) -> Vec<String> {
        vec![
            "--transport".into(),
            self.transport.name().into(),
            "--instance".into(),
            self.instance.clone(),
            "--interval-us".into(),
            self.interval_us.to_string(),
            "--phase-us".into(),
            self.phase_us.to_string(),
            "--cpu".into(),
            self.cpu.to_string(),
            "--priority".into(),
            self.priority.to_string(),
        ]
    }
}

/// Runs the sender until stopped. Errors are set-up failures.
pub fn run(args: &Args) -> Result<(), String> {
    signals::install().map_err(|e| format!("signal handlers: {e}"))?;
    // SAFETY: plain system call; ends this process if the thread that started it exits.
    unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) };
    let instance = InstanceName::new(&args.instance).map_err(|e| e.to_string())?;
    let ports = match args.transport {
        Test::Ipc => {
            let f = |e: ipc::IpcError| e.to_string();
            let node = ipc::node(&instance, "latency-tx").map_err(f)?;
            let setpoints =
                Pub::<SetpointV2>::new(&node, &instance, ServiceId::Setpoint).map_err(f)?;
            let ready = Notifier::new(&node, &instance, ServiceId::SetpointReady).map_err(f)?;
            Some((setpoints, ready, node))
        }
        _ => None,
    };
    let (_report, _guard) = rt::setup(RtRequest {
        priority: args.priority,
        cpu: Some(args.cpu),
    });
    let mut clock = CycleClock::new(args.interval_us * 1000, args.phase_us * 1000, now_ns());
    let mut sp = SetpointV2::default();
    // The cycle: wait, stamp, send (+ notify). No allocation of ours, no lock, no log.
    while !signals::stop_requested() {
        let wake = match clock.wait() {
            Ok(w) => w,
            Err(WaitError::Interrupted) => continue,
            Err(WaitError::Os(e)) => return Err(format!("clock_nanosleep failed: errno {e}")),
        };
        sp.seq += 1;
        sp.stamp_ns = now_ns();
        match &ports {
            Some((setpoints, ready, _)) => {
                setpoints.send(&sp);
                ready.notify();
            }
            None => {
                let bytes = sp.stamp_ns.to_ne_bytes();
                // SAFETY: writes 8 bytes from a live buffer to stdout.
                let n = unsafe { libc::write(1, bytes.as_ptr().cast(), bytes.len()) };
                if n != 8 {
                    break; // the reader is gone (EPIPE) or we were interrupted: stop
                }
            }
        }
        clock.finish(&wake, now_ns());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arguments_round_trip() {
        let a = Args {
            transport: Test::Pipe,
            instance: "lat-1".into(),
            interval_us: 250,
            phase_us: 100,
            cpu: 1,
            priority: 80,
        };
        use clap::Parser;
        #[derive(Debug, Parser)]
        struct Peer {
            #[command(flatten)]
            args: Args,
        }
        let parse = |args: Vec<String>| {
            Peer::try_parse_from(std::iter::once("latency-peer".to_string()).chain(args))
                .map(|p| p.args)
        };
        assert_eq!(parse(a.to_args()).ok(), Some(a.clone()));
        let mut timer = a.to_args();
        timer[1] = "timer".into();
        assert!(parse(timer).is_err());
    }
}
