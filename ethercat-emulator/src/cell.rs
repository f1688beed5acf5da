//! The emulator as a process of a test cell (`ethercat-emulator --instance NAME`): it reads the
//! cell's `[ethercat]` and axes, makes the SubDevices of `[[ethercat.subdevice]]` by their
//! identities (the drives moving the cell's own axes, with their mechanics from `[[axis]]`
//! `sim`: one physics with `machine-sim`), makes a veth pair whose one end is the bus'
//! interface and answers on the other (`<interface>-sd`), and removes the pair when it stops.
//!
//! Meant for a cell of its own network namespace (the tests') or a machine without EtherCAT
//! hardware; it refuses an interface that exists and is not its own pair.

use crate::bus::Bus;
use crate::drive::{self, Drive, Scaling};
use crate::terminals::{BECKHOFF, Terminal};
use crate::wire::{Received, Wire};
use runtime::process::{self, Context, Cycle, SetupError, Task};
use runtime::rt::{self, RtRequest};
use shm_schema::{EthercatConfigV1, ServiceId};
use std::process::{Command, ExitCode};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// The emulator's end of the pair: the bus' interface with this suffix.
pub const PEER_SUFFIX: &str = "-sd";

struct Emulator {
    stop: Arc<AtomicBool>,
    answered: Arc<AtomicU64>,
    thread: Option<JoinHandle<()>>,
    interface: String,
}

impl Task for Emulator {
    /// # Real-time
    /// Nothing: the frames are answered by the emulator's own thread.
    fn cycle(&mut self, _cx: &mut Cycle<'_>) {}

    fn stop(&mut self, _now_ns: u64, _events: &mut shm_schema::EventQueue) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        tracing::info!(
            "emulator stopped: {} frames answered; removing {}",
            self.answered.load(Ordering::Relaxed),
            self.interface
        );
        let _ = ip(&["link", "del", &self.interface]);
    }
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip {}: {e} (iproute2 is needed)", args.join(" ")))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

fn exists(interface: &str) -> bool {
    std::path::Path::new("/sys/class/net")
        .join(interface)
        .exists()
}

/// The line of `bus`, its drives moving the axes of `ctx`'s cell.
fn line(bus: &EthercatConfigV1, ctx: &Context) -> Result<Vec<Terminal>, String> {
    let watchdog_ns = ctx
        .cell
        .drive_command_timeout_ns
        .max(bus.pd_watchdog_ns)
        .max(100_000_000);
    bus.subdevices()
        .iter()
        .enumerate()
        .map(|(k, s)| {
            Ok(match (s.vendor, s.product) {
                (BECKHOFF, 0x044C_2C52) => Terminal::Ek1100,
                (BECKHOFF, 0x03F0_3052) => Terminal::El1008 { inputs: 0 },
                (BECKHOFF, 0x07D8_3052) => Terminal::El2008 { outputs: 0 },
                (drive::VENDOR, drive::PRODUCT) => {
                    let axis = s
                        .axis()
                        .and_then(|a| ctx.cell.axis.get(a).filter(|_| a < ctx.cell.axes as usize))
                        .ok_or_else(|| format!("subdevice {k} ({}): a drive without an axis", s.name()))?;
                    Terminal::Drive(Box::new(Drive::new(
                        s.name(),
                        axis,
                        Scaling {
                            counts_per_unit: s.counts_per_unit,
                            rated_effort: s.rated_effort,
                        },
                        watchdog_ns,
                    )))
                }
                (v, p) => {
                    return Err(format!(
                        "subdevice {k} ({}): vendor {v:#010x}, product {p:#010x} is no device this emulator has (EK1100, EL1008, EL2008, its CiA 402 drive)",
                        s.name()
                    ));
                }
            })
        })
        .collect()
}

/// Answers frames on `wire` until `stop`; between frames the drives' models run on.
fn answer(wire: &Wire, mut bus: Bus, stop: &AtomicBool, answered: &AtomicU64) {
    let mut buf = vec![0u8; 9216];
    while !stop.load(Ordering::Relaxed) {
        match wire.receive(&mut buf) {
            Ok(Received::Frame(n)) => {
                let frame = &mut buf[..n];
                if bus.handle(frame).is_ok() && wire.send(frame).is_ok() {
                    answered.fetch_add(1, Ordering::Relaxed);
                }
            }
            Ok(Received::Nothing) => bus.idle(),
            Err(e) => {
                tracing::error!("{e}");
                return;
            }
        }
    }
}

/// `main` in a cell.
pub fn main() -> ExitCode {
    process::run(
        "emulator",
        "emulated EtherCAT SubDevices for a cell without hardware",
        |ctx: &Context| {
            let Some(bus) = process::wait_for::<EthercatConfigV1>(
                &ctx.node,
                &ctx.instance,
                ServiceId::EthercatConfig,
                "the cell has no [ethercat] section",
            )?
            else {
                return Err("stopped before the bus configuration arrived".into());
            };
            let terminals = line(&bus, ctx)?;
            let interface = bus.interface().to_string();
            let peer = format!("{interface}{PEER_SUFFIX}");
            if peer.len() > 15 {
                return Err(format!(
                    "interface {interface:?}: the emulator's end {peer:?} would be over 15 bytes"
                )
                .into());
            }
            match (exists(&interface), exists(&peer)) {
                (false, _) => {
                    if exists(&peer) {
                        ip(&["link", "del", &peer])?;
                    }
                    ip(&[
                        "link", "add", &interface, "type", "veth", "peer", "name", &peer,
                    ])?;
                }
                // Our own pair, left by an emulator that was killed.
                (true, true) => {}
                (true, false) => {
                    return Err(format!(
                        "interface {interface:?} exists and is not the emulator's veth pair: the emulator makes its own"
                    )
                    .into());
                }
            }
            let wire = Wire::open(&peer, Duration::from_millis(5))?;
            // The ESCs start with an ET1100's 100 ms process data watchdog; the bus process
            // writes its own.
            let bus = Bus::new(terminals);
            ip(&["link", "set", &peer, "up"])?;
            ip(&["link", "set", &interface, "up"])?;
            let stop = Arc::new(AtomicBool::new(false));
            let answered = Arc::new(AtomicU64::new(0));
            let priority = ctx.own.priority;
            let thread = {
                let (stop, answered) = (stop.clone(), answered.clone());
                std::thread::Builder::new()
                    .name("frames".into())
                    .spawn(move || {
                        // The SubDevices answer as hardware does: at once, whatever else runs.
                        rt::setup_thread(RtRequest {
                            priority,
                            cpu: None,
                        });
                        answer(&wire, bus, &stop, &answered);
                    })?
            };
            tracing::info!("answering on {peer} for the bus on {interface}");
            Ok::<_, SetupError>(Emulator {
                stop,
                answered,
                thread: Some(thread),
                interface,
            })
        },
    )
}
