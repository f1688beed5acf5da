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

/// What the sender is told.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Args {
    /// [`Test::Ipc`], [`Test::Pipe`] or [`Test::Unix`].
    pub transport: Test,
    /// Instance of the IPC hop's services.
    pub instance: String,
    /// Period (µs).
    pub interval_us: u64,
    /// Phase on the grid (µs).
    pub phase_us: u64,
    /// CPU to pin to.
    pub cpu: usize,
    /// `SCHED_FIFO` priority (0: `SCHED_OTHER`).
    pub priority: i32,
}

impl Args {
    /// As command-line arguments (what [`Args::parse`] reads back).
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

    /// Reads the arguments of [`Args::to_args`].
    pub fn parse(args: &[String]) -> Result<Self, String> {
        let mut it = args.iter();
        let (mut transport, mut instance, mut interval_us, mut cpu, mut priority) =
            (None, None, None, None, None);
        let mut phase_us = 0;
        while let Some(flag) = it.next() {
            let value = it.next().ok_or_else(|| format!("{flag} needs a value"))?;
            let bad = |what: &str| format!("{flag} {value:?}: {what}");
            match flag.as_str() {
                "--transport" => {
                    transport = Some(
                        Test::from_name(value)
                            .filter(|t| *t != Test::Timer)
                            .ok_or_else(|| bad("not ipc, pipe or unix"))?,
                    )
                }
                "--instance" => instance = Some(value.clone()),
                "--interval-us" => {
                    interval_us = Some(value.parse().map_err(|_| bad("not a number"))?)
                }
                "--phase-us" => phase_us = value.parse().map_err(|_| bad("not a number"))?,
                "--cpu" => cpu = Some(value.parse().map_err(|_| bad("not a CPU number"))?),
                "--priority" => priority = Some(value.parse().map_err(|_| bad("not a number"))?),
                _ => return Err(format!("unknown argument {flag:?}")),
            }
        }
        let missing = |what: &str| format!("missing {what}");
        Ok(Self {
            transport: transport.ok_or_else(|| missing("--transport"))?,
            instance: instance.ok_or_else(|| missing("--instance"))?,
            interval_us: interval_us
                .filter(|i| *i > 0)
                .ok_or_else(|| missing("a positive --interval-us"))?,
            phase_us,
            cpu: cpu.ok_or_else(|| missing("--cpu"))?,
            priority: priority.ok_or_else(|| missing("--priority"))?,
        })
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
        assert_eq!(Args::parse(&a.to_args()), Ok(a));
        assert!(Args::parse(&["--transport".into(), "timer".into()]).is_err());
    }
}
