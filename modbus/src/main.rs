//! `modbus`: the cell's Modbus TCP server process. See the crate documentation.
//!
//! # Not real-time
//! This process runs under `SCHED_OTHER` (priority 0 in the default cell) and is not critical;
//! its cycle allocates (a snapshot of the registers per iobridge image, the client's address
//! in an event) and takes a lock shared with the server thread for as long as it takes to
//! swap one pointer. None of that reaches the real-time processes: they only see the samples
//! it publishes, as from any client.

use modbus::Action;
use modbus::map::{Registers, Samples};
use modbus::server::{self, Msg, Settings, Shared};
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, Cycle, SetupError, Task};
use shm_schema::event::code;
use shm_schema::{
    CellConfigV6, ControlKind, DigitalIoV1, EstopOrigin, EventV1, FieldbusImageV1, IoWriteV1,
    MotionControlV2, ServiceId, ServoStateV3, SetpointV2, str_of,
};
use std::net::SocketAddr;
use std::process::ExitCode;
use std::sync::mpsc::Receiver;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Write requests queued between two cycles at most.
const WRITE_QUEUE: usize = 64;

/// Servo states kept to find the one an image was taken from (as many as the subscriber
/// holds).
const RECENT: usize = 64;

struct Gateway {
    cell: CellConfigV6,
    index: u32,
    image: Sub<FieldbusImageV1>,
    servo: Sub<ServoStateV3>,
    setpoint: Sub<SetpointV2>,
    io: Sub<DigitalIoV1>,
    io_request: Pub<IoWriteV1>,
    control: Pub<MotionControlV2>,
    /// The newest servo states, by `seq % RECENT`.
    recent: [Option<ServoStateV3>; RECENT],
    samples: Samples,
    regs: Shared,
    rx: Receiver<Msg>,
    control_seq: u64,
}

impl Gateway {
    /// The server started on its own thread and the ports opened. Set-up only.
    fn new(ctx: &Context) -> Result<Self, SetupError> {
        let i = &ctx.instance;
        let m = &ctx.cell.modbus;
        let listen: SocketAddr = str_of(&m.listen).parse().map_err(|_| {
            SetupError::from(format!(
                "[modbus] listen = {:?} is not an IP:port address",
                str_of(&m.listen)
            ))
        })?;
        let settings = Settings {
            listen,
            max_connections: m.max_connections.clamp(1, 64) as usize,
            idle_timeout: Duration::from_nanos(m.idle_timeout_ns.max(100_000_000)),
            writes: m.writes != 0,
        };
        let regs: Shared = Arc::new(Mutex::new(Arc::new(Registers::default())));
        // Bounded: a client writing faster than the cycle takes writes gets exception 6.
        let (tx, rx) = std::sync::mpsc::sync_channel(WRITE_QUEUE);
        server::spawn(settings, regs.clone(), tx)
            .map_err(|e| SetupError::from(format!("cannot start the server: {e}")))?;
        Ok(Self {
            cell: ctx.cell,
            index: ctx.index as u32,
            image: Sub::new(&ctx.node, i, ServiceId::FieldbusOutput, 8)?,
            servo: Sub::new(&ctx.node, i, ServiceId::ServoState, 64)?,
            setpoint: Sub::new(&ctx.node, i, ServiceId::Setpoint, 16)?,
            io: Sub::new(&ctx.node, i, ServiceId::IoState, 8)?,
            io_request: Pub::new(&ctx.node, i, ServiceId::IoRequest)?,
            control: Pub::new(&ctx.node, i, ServiceId::MotionControl)?,
            recent: [None; RECENT],
            samples: Samples::default(),
            regs,
            rx,
            control_seq: 0,
        })
    }

    /// Takes what arrived; true when the registers should be rebuilt.
    fn take_samples(&mut self, cx: &Cycle<'_>) -> bool {
        let mut fresh = false;
        while let Some(s) = self.servo.next() {
            self.recent[s.seq as usize % RECENT] = Some(s);
        }
        if let Some(img) = self.image.latest() {
            // The servo state the image's positions came from, so that command, following
            // error and position are of one servo cycle. When it is gone (a stall held this
            // process or iobridge past RECENT servo cycles) the image is skipped: the
            // registers keep the last one whose state they have, until the next image. (No
            // servo state at all: the positions alone.)
            let same =
                self.recent[img.source_seq as usize % RECENT].filter(|s| s.seq == img.source_seq);
            if same.is_some() || self.recent.iter().all(Option::is_none) {
                self.samples.servo = same;
                self.samples.image = Some(img);
                fresh = true;
            }
        }
        if let Some(sp) = self.setpoint.latest() {
            self.samples.setpoint = Some(sp);
            fresh = true;
        }
        if let Some(io) = self.io.latest() {
            self.samples.io = Some(io);
            fresh = true;
        }
        let estop = cx.estop.latched.then_some(cx.estop.cause).flatten();
        if estop != self.samples.estop {
            self.samples.estop = estop;
            fresh = true;
        }
        fresh
    }

    /// Applies one cycle's writes, merged: the outputs in one request (the last write of each
    /// bit wins), one e-stop, the last speed override, one event each.
    fn apply(&mut self, cx: &mut Cycle<'_>, writes: &Writes) {
        let now = cx.now_ns();
        if writes.mask != 0 {
            self.io_request.send(&IoWriteV1 {
                stamp_ns: now,
                mask: writes.mask,
                values: writes.values,
                source: self.index,
                line: 0,
            });
        }
        if let Some(peer) = &writes.estop {
            let client = peer.to_string();
            let why = ["e-stop asked over Modbus by ", &client];
            cx.events
                .push(EventV1::new(now, code::FIELDBUS_WRITE, -1, 1.0, 0.0, &why));
            cx.raise_estop(EstopOrigin::External, code::FIELDBUS_WRITE, &why);
        }
        if let Some((percent, peer)) = &writes.speed {
            // Numbers increase across senders: the time of the send (the supervisor's are
            // times too).
            self.control_seq = (self.control_seq + 1).max(runtime::time::now_ns());
            self.control.send(&MotionControlV2 {
                seq: self.control_seq,
                kind: ControlKind::Speed as u32,
                reserved: 0,
                value: f64::from(*percent) / 100.0,
            });
            let client = peer.to_string();
            cx.events.push(EventV1::new(
                now,
                code::FIELDBUS_WRITE,
                -1,
                f64::from(*percent),
                0.0,
                &["speed override % from ", &client],
            ));
        }
    }
}

/// The writes of one cycle, merged.
#[derive(Debug, Default)]
struct Writes {
    mask: u64,
    values: u64,
    estop: Option<SocketAddr>,
    speed: Option<(u16, SocketAddr)>,
}

impl Writes {
    fn add(&mut self, a: Action, peer: SocketAddr) {
        match a {
            Action::Io { mask, values } => {
                self.values = (self.values & !mask) | (values & mask);
                self.mask |= mask;
            }
            Action::Estop => {
                self.estop.get_or_insert(peer);
            }
            Action::Speed(p) => self.speed = Some((p, peer)),
        }
    }
}

impl Task for Gateway {
    fn cycle(&mut self, cx: &mut Cycle<'_>) {
        if self.take_samples(cx) {
            let regs = Arc::new(Registers::build(&self.cell, &self.samples));
            match self.regs.lock() {
                Ok(mut g) => *g = regs,
                Err(p) => *p.into_inner() = regs,
            }
        }
        let mut writes = Writes::default();
        while let Ok(msg) = self.rx.try_recv() {
            let now = cx.now_ns();
            match msg {
                Msg::Listening(a) => {
                    tracing::info!("modbus: listening on {a}");
                    cx.events.push(EventV1::new(
                        now,
                        code::LISTENING,
                        -1,
                        0.0,
                        0.0,
                        &[&a.to_string()],
                    ));
                }
                Msg::ListenFailed(why) => {
                    tracing::warn!("modbus: cannot listen on {why}; trying again every second");
                    cx.events.push(EventV1::new(
                        now,
                        code::LISTEN_FAILED,
                        -1,
                        0.0,
                        0.0,
                        &[&why],
                    ));
                }
                Msg::Act(actions, peer) => {
                    for a in actions {
                        writes.add(a, peer);
                    }
                }
            }
        }
        self.apply(cx, &writes);
    }
}

fn main() -> ExitCode {
    process::run(
        "modbus",
        "the cell's Modbus TCP server: positions with their measurement time, the cell's state and the named IO",
        Gateway::new,
    )
}
