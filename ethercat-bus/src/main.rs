//! `ethercat-bus`: the drives' process of a cell on EtherCAT. See the crate documentation.

use ethercat_bus::Drives;
use ethercat_bus::bringup;
use ethercat_bus::frame::{CyclicFrame, Reply};
use ethercat_wire::{Received, Wire};
use runtime::health::Freshness;
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, Cycle, LATENCY_PUBLISH_INTERVAL_NS, SetupError, Task};
use shm_schema::ethercat::MAX_SUBDEVICES;
use shm_schema::event::code;
use shm_schema::{
    DriveCommandV2, DriveFeedbackV2, EstopOrigin, EthercatConfigV1, EventQueue, EventV1,
    LatencyHistogramV1, ServiceId,
};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// A SubDevice's position as text, for events written in the cycle (no formatting there).
const POSITIONS: [&str; MAX_SUBDEVICES] = [
    "0", "1", "2", "3", "4", "5", "6", "7", "8", "9", "10", "11", "12", "13", "14", "15", "16",
    "17", "18", "19", "20", "21", "22", "23", "24", "25", "26", "27", "28", "29", "30", "31",
];

/// Events of a run of lost frames or working-counter mismatches: the first, then at most one
/// this often.
const REPEAT_NS: u64 = 1_000_000_000;

struct Bus {
    wire: Wire,
    interface: String,
    /// The first cycle announces the bus in OP.
    announced: bool,
    /// Each SubDevice's name, as the configuration gives it.
    names: [[u8; 16]; MAX_SUBDEVICES],
    /// Whether each SubDevice was in OP in the last reply.
    in_op: [bool; MAX_SUBDEVICES],
    frame: CyclicFrame,
    drives: Drives,
    /// Frames lost in a row.
    lost: u64,
    /// Frames lost in a row that make the bus lost (its SubDevices' watchdog).
    lost_limit: u64,
    last_lost_event_ns: u64,
    last_wkc_event_ns: u64,
    bus_lost_raised: bool,
    seq: u64,
    /// How long a cycle waits for its frame's reply: half a period.
    reply_wait_ns: u64,
    buf: [u8; 1536],
    /// Servo's commands arrive every servo period; older than the drives' command timeout
    /// and the bus quick-stops the drives by itself.
    command_fresh: Freshness,
    command_timeout_ns: u64,
    last_command_ns: Option<u64>,
    /// Servo's newest command.
    command: Option<DriveCommandV2>,
    last_applied_seq: u64,
    sense_to_command: Box<LatencyHistogramV1>,
    last_published_ns: u64,
    commands: Sub<DriveCommandV2>,
    feedback: Pub<DriveFeedbackV2>,
    sense_to_command_pub: Pub<LatencyHistogramV1>,
}

impl Bus {
    fn publish_latency(&mut self, now_ns: u64) {
        self.sense_to_command.stamp_ns = now_ns;
        self.sense_to_command_pub.send(&self.sense_to_command);
        self.last_published_ns = now_ns;
    }

    /// Waits for the reply to the frame just sent, until `deadline_ns`.
    ///
    /// # Real-time
    /// `recvfrom` on the bus' socket (its timeout set once): the process' IPC.
    fn await_reply(&mut self, deadline_ns: u64) -> Option<(u16, usize)> {
        loop {
            match self.wire.receive(&mut self.buf) {
                Ok(Received::Frame(n)) => {
                    if let Reply::Ours { wkc, al_read } = self.frame.take_reply(&self.buf[..n]) {
                        return Some((wkc, al_read));
                    }
                }
                Ok(Received::Nothing) | Err(_) => {}
            }
            if runtime::time::now_ns() >= deadline_ns {
                return None;
            }
        }
    }
}

impl Task for Bus {
    /// # Real-time
    /// IPC calls (iceoryx2, and one frame sent and its reply received on the bus' socket),
    /// arithmetic, copies and a histogram record; nothing else.
    fn cycle(&mut self, cx: &mut Cycle<'_>) {
        let now = cx.now_ns();
        if !self.announced {
            self.announced = true;
            cx.events.push(EventV1::new(
                now,
                code::BUS_OP,
                -1,
                self.frame.layout().count as f64,
                f64::from(self.frame.layout().expected_wkc),
                &["in OP on ", &self.interface],
            ));
        }
        // The newest command, or the last one while servo's next has not come (the drives
        // hold it, as their outputs do between frames).
        if let Some(c) = self.commands.latest() {
            self.last_command_ns = Some(c.stamp_ns);
            self.command = Some(c);
        }
        cx.pending_overruns(self.command_fresh.check(now, self.last_command_ns));
        // Servo silent for the drives' command timeout: the bus stops the drives itself.
        let silent = self
            .last_command_ns
            .is_some_and(|t| now.saturating_sub(t) > self.command_timeout_ns);
        let command = self.command;
        self.drives.write(command.as_ref(), silent, &mut self.frame);
        let sent_ns = runtime::time::now_ns();
        let sent = self.wire.send(self.frame.next_frame()).is_ok();
        let reply = if sent {
            self.await_reply(sent_ns + self.reply_wait_ns)
        } else {
            None
        };
        let Some((wkc, _al_read)) = reply else {
            // No reply: no feedback this cycle (never a last good value); servo judges the
            // gap by its feedback timeout.
            self.lost += 1;
            if self.lost == 1 || now.saturating_sub(self.last_lost_event_ns) >= REPEAT_NS {
                self.last_lost_event_ns = now;
                cx.events.push(EventV1::new(
                    now,
                    code::BUS_FRAMES_LOST,
                    -1,
                    self.lost as f64,
                    self.lost_limit as f64,
                    &["no reply within half a period"],
                ));
            }
            if self.lost >= self.lost_limit && !self.bus_lost_raised {
                self.bus_lost_raised = true;
                cx.events.push(EventV1::new(
                    now,
                    code::BUS_LOST,
                    -1,
                    self.lost as f64,
                    self.lost_limit as f64,
                    &["no frame came back: the SubDevices' watchdog took their outputs safe"],
                ));
                cx.raise_estop(EstopOrigin::Device, code::BUS_LOST, &["EtherCAT bus lost"]);
            }
            if self.lost > self.lost_limit {
                // The bus is lost (its e-stop went out the cycle before): the drives cannot
                // be vouched for at all. Every position NaN and no state (statusword 0), so
                // servo cuts power at once rather than ramping against the last position it
                // saw.
                self.seq += 1;
                let fb = self
                    .drives
                    .read(now, self.seq, false, &self.frame, cx.events);
                self.feedback.send(&fb);
            }
            cx.set_safe(!self.drives.powered() || self.lost >= self.lost_limit);
            return;
        };
        self.lost = 0;
        if !cx.estop.latched {
            self.bus_lost_raised = false;
        }
        // Each SubDevice's AL state, read in the same frame: one leaving OP is named.
        for k in 0..self.frame.layout().count {
            let (status, code) = self.frame.al_status(k);
            let op = status & 0x0F == 0x08;
            if self.in_op[k] && !op {
                let name = &self.names[k];
                cx.events.push(EventV1::new(
                    now,
                    code::SUBDEVICE_LEFT_OP,
                    -1,
                    f64::from(status),
                    f64::from(code),
                    &[
                        "position ",
                        POSITIONS.get(k).copied().unwrap_or("?"),
                        " (",
                        shm_schema::str_of(name),
                        ") left OP",
                    ],
                ));
            }
            self.in_op[k] = op;
        }
        let expected = self.frame.layout().expected_wkc;
        let valid = wkc == expected;
        if !valid && now.saturating_sub(self.last_wkc_event_ns) >= REPEAT_NS {
            self.last_wkc_event_ns = now;
            cx.events.push(EventV1::new(
                now,
                code::BUS_WKC_MISMATCH,
                -1,
                f64::from(wkc),
                f64::from(expected),
                &["a SubDevice did not take its process data"],
            ));
        }
        self.seq += 1;
        let mut fb = self
            .drives
            .read(sent_ns, self.seq, valid, &self.frame, cx.events);
        if let Some(c) = command.filter(|c| c.seq != self.last_applied_seq) {
            self.last_applied_seq = c.seq;
            if c.feedback_stamp_ns > 0 {
                fb.sense_to_command_ns = sent_ns.saturating_sub(c.feedback_stamp_ns);
                self.sense_to_command.record(fb.sense_to_command_ns);
            }
        }
        cx.set_safe(!self.drives.powered());
        self.feedback.send(&fb);
        if now.saturating_sub(self.last_published_ns) >= LATENCY_PUBLISH_INTERVAL_NS {
            self.publish_latency(now);
        }
    }

    fn stop(&mut self, now_ns: u64, _events: &mut EventQueue) {
        self.publish_latency(now_ns);
    }
}

/// The bus' configuration, published by the supervisor.
fn bus_config(ctx: &Context) -> Result<EthercatConfigV1, SetupError> {
    process::wait_for(
        &ctx.node,
        &ctx.instance,
        ServiceId::EthercatConfig,
        "the cell has no [ethercat] section",
    )?
    .ok_or_else(|| "stopped before the bus configuration arrived".into())
}

/// Opens the bus' interface once its link is up (a cable plugged, a veth's peer up), for at
/// most the cell's start-up.
fn open_wire(interface: &str) -> Result<Wire, SetupError> {
    let start = Instant::now();
    loop {
        let carrier = std::fs::read_to_string(format!("/sys/class/net/{interface}/carrier"));
        if carrier.is_ok_and(|c| c.trim() == "1") {
            return Ok(Wire::open(interface, Duration::from_millis(1))?);
        }
        if runtime::signals::stop_requested() {
            return Err("stopped before the bus' link came up".into());
        }
        if start.elapsed() > process::CONFIG_TIMEOUT {
            return Err(format!(
                "interface {interface:?} has no link (no such interface, or no cable) after {} s",
                process::CONFIG_TIMEOUT.as_secs()
            )
            .into());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn main() -> ExitCode {
    process::run(
        "machine",
        "the cell's EtherCAT MainDevice: CiA 402 drives on a bus",
        |ctx: &Context| {
            let i = &ctx.instance;
            let bus = bus_config(ctx)?;
            let wire = open_wire(bus.interface())?;
            let axes = &ctx.cell.axis[..ctx.cell.axes as usize];
            let up = bringup::bring_up(&bus, axes, &wire, &runtime::signals::stop_requested)?;
            let frame = CyclicFrame::new(up.layout)?;
            // The cycle waits for its reply at most half a period.
            wire.set_timeout(
                Duration::from_nanos(ctx.own.period_ns / 4).max(Duration::from_micros(50)),
            )?;
            let modes: Vec<i8> = axes.iter().map(|a| a.mode as i8).collect();
            let watchdog_ns = if bus.pd_watchdog_ns > 0 {
                bus.pd_watchdog_ns
            } else {
                100_000_000
            };
            tracing::info!(
                "bus on {} in OP: {} (working counter {})",
                bus.interface(),
                up.names.join(", "),
                up.layout.expected_wkc
            );
            Ok::<_, SetupError>(Bus {
                wire,
                interface: bus.interface().to_string(),
                announced: false,
                names: {
                    let mut n = [[0u8; 16]; MAX_SUBDEVICES];
                    for (slot, s) in n.iter_mut().zip(bus.subdevices()) {
                        *slot = s.name;
                    }
                    n
                },
                in_op: [true; MAX_SUBDEVICES],
                frame,
                drives: Drives::new(&bus, ctx.cell.axes as usize, &modes),
                lost: 0,
                lost_limit: watchdog_ns.div_ceil(ctx.own.period_ns).max(1),
                last_lost_event_ns: 0,
                last_wkc_event_ns: 0,
                bus_lost_raised: false,
                seq: 0,
                reply_wait_ns: ctx.own.period_ns / 2,
                buf: [0; 1536],
                command_fresh: Freshness::new(
                    ctx.cell.period_of("servo").unwrap_or(ctx.own.period_ns),
                ),
                command_timeout_ns: ctx.cell.drive_command_timeout_ns,
                last_command_ns: None,
                command: None,
                last_applied_seq: 0,
                sense_to_command: Box::default(),
                last_published_ns: 0,
                commands: Sub::new(&ctx.node, i, ServiceId::DriveCommand, 8)?,
                feedback: Pub::new(&ctx.node, i, ServiceId::DriveFeedback)?,
                sense_to_command_pub: Pub::new(&ctx.node, i, ServiceId::SenseToCommand)?,
            })
        },
    )
}
