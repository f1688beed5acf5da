//! `ethercat-bus`: the drives' process of a cell on EtherCAT. See the crate documentation.

use ethercat_bus::bringup::{BringUpError, Dc, Master, Mismatch, STATE_TRANSITION, Timing, Up};
use ethercat_bus::frame::{CyclicFrame, Layout, Reply, coe_emergency};
use ethercat_bus::{BusIo, Drives};
use ethercat_wire::{Received, Wire};
use runtime::health::Freshness;
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, Cycle, SetupError, Task};
use runtime::snapshot::SenseToCommand;
use shm_schema::ethercat::MAX_SUBDEVICES;
use shm_schema::event::code;
use shm_schema::{
    DigitalIoV1, DriveCommandV2, DriveFeedbackV2, EstopOrigin, EthercatConfigV1, EventQueue,
    EventV1, IoWriteV1, LatencyHistogramV1, ServiceId,
};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A SubDevice's position as text, for events written in the cycle (no formatting there).
const POSITIONS: [&str; MAX_SUBDEVICES] = [
    "0", "1", "2", "3", "4", "5", "6", "7", "8", "9", "10", "11", "12", "13", "14", "15", "16",
    "17", "18", "19", "20", "21", "22", "23", "24", "25", "26", "27", "28", "29", "30", "31",
];

/// Events of a run of lost frames or working-counter mismatches: the first, then at most one
/// this often.
const REPEAT_NS: u64 = 1_000_000_000;

/// Who has the bus' wire (`Bus::wire_owner`): the cycle, or the recovery thread bringing the
/// bus up again. The cycle hands it over (`RECOVERING`) and the thread hands it back (`BACK`)
/// with the bus in SAFE-OP; neither touches the socket while the other has it.
mod owner {
    pub const CYCLE: u8 = 0;
    pub const RECOVERING: u8 = 1;
    pub const BACK: u8 = 2;
}

/// The inputs on the bus are reported again at least this often (ns), so a restarted
/// iobridge learns them; iobridge's IO image older than this, and the outputs on the bus go
/// to 0 (as a terminal's own watchdog takes them).
const IO_REFRESH_NS: u64 = 100_000_000;

/// At most this many emergencies of the start-up are told as events in the first cycle.
const STARTUP_EMERGENCIES: usize = 8;

struct Bus {
    wire: Arc<Wire>,
    interface: String,
    /// What the bus reaching OP is announced as ("in OP", "back in OP").
    announce: &'static str,
    /// Since when the cycle's frames have asked every SubDevice for OP (the bus came up in
    /// SAFE-OP, at start-up or back from recovery); `None` once all are there.
    reaching_op: Option<u64>,
    /// Emergencies sent during start-up (position, code, register), told in the first cycle.
    startup_emergencies: [(usize, u16, u8); STARTUP_EMERGENCIES],
    startup_emergency_count: usize,
    /// See [`owner`].
    wire_owner: Arc<AtomicU8>,
    /// Ends the recovery thread.
    quit: Arc<AtomicBool>,
    recovery: Option<JoinHandle<()>>,
    /// Events of the recovery thread (why the bus is not back), published by the cycle.
    told: Receiver<EventV1>,
    /// Times the bus was handed to the recovery thread.
    recoveries: u64,
    /// Since when the bus has been degraded (a SubDevice out of OP, or a wrong working
    /// counter) with the e-stop latched.
    degraded_since_ns: Option<u64>,
    /// How long the e-stop must have been latched on a degraded bus before it is brought up
    /// again: the cell's `estop_stop_time` (every drive has ramped down by then).
    degraded_wait_ns: u64,
    /// The e-stop was seen latched while the bus was out of the cycle's hands: a reset then
    /// raises it again.
    latched_while_recovering: bool,
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
    sense_to_command: SenseToCommand,
    /// From sending the cycle's frame to taking its reply, every cycle that had one; told in
    /// the log when the process stops.
    round_trip: Box<LatencyHistogramV1>,
    /// The `[[io]]` entries on the bus.
    io: BusIo,
    /// iobridge's newest IO image: its values and when it was written.
    io_image: Option<(u64, u64)>,
    /// The inputs last reported, and when.
    io_reported: Option<(u64, u64)>,
    /// Distributed Clocks, when SubDevices run on SYNC0.
    dc: Option<Dc>,
    /// The recovery thread's new `Dc::epoch_ns` and `Dc::wake_ns` (the bus brought up again
    /// has new clocks), stored before it hands the wire back.
    dc_again: Arc<[AtomicU64; 2]>,
    /// The SYNC0 cycle the last frame came in.
    last_sync0_cycle: Option<u64>,
    /// SYNC0 events without a frame before them: in all, and since the last event told.
    sync0_late: u64,
    sync0_late_untold: u64,
    last_sync0_event_ns: u64,
    /// How long before the next SYNC0 each frame passed the reference clock.
    sync0_lead: Box<LatencyHistogramV1>,
    /// This process' index in the table (the source of its input reports).
    source: u32,
    io_state: Sub<DigitalIoV1>,
    field_inputs: Pub<IoWriteV1>,
    commands: Sub<DriveCommandV2>,
    feedback: Pub<DriveFeedbackV2>,
}

impl Bus {
    /// The bus brought up to SAFE-OP, the cycle's frames to take it to OP. Set-up only.
    fn new(ctx: &Context) -> Result<Self, SetupError> {
        let i = &ctx.instance;
        let bus = bus_config(ctx)?;
        let wire = Arc::new(open_wire(bus.interface())?);
        let axes = &ctx.cell.axis[..ctx.cell.axes as usize];
        let mut master = Master::new()?;
        let timing = Timing {
            period_ns: ctx.own.period_ns,
            phase_ns: ctx.own.phase_ns,
        };
        let up = master
            .bring_up(&bus, axes, timing, &wire, &runtime::signals::stop_requested)
            .map_err(|e| -> SetupError {
                match e {
                    BringUpError::Line(m) => Box::new(process::Refused(m.to_string())),
                    BringUpError::Refused(m) => Box::new(process::Refused(m)),
                    BringUpError::Failed(m) => m.into(),
                }
            })?;
        tell_emergencies(&up);
        let frame = CyclicFrame::new(up.layout, up.dc.map(|d| d.station))?;
        if let Some(dc) = &up.dc {
            let positions: Vec<String> = (0..MAX_SUBDEVICES)
                .filter(|k| dc.on_sync0 & (1 << k) != 0)
                .map(|k| k.to_string())
                .collect();
            tracing::info!(
                "Distributed Clocks: reference clock position {} ({}); SYNC0 every {} µs on position(s) {}, the first {} µs after the bus process wakes",
                dc.reference,
                up.names.get(dc.reference).map_or("?", String::as_str),
                dc.cycle_ns / 1000,
                positions.join(", "),
                dc.shift_ns / 1000
            );
        }
        let dc_again = Arc::new([AtomicU64::new(0), AtomicU64::new(0)]);
        let io = BusIo::new(&bus, ctx.cell.io(), &up.layout)
            .map_err(|m| -> SetupError { Box::new(process::Refused(m)) })?;
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
            "bus on {} in SAFE-OP: {} (working counter {}); the cycle asks for OP",
            bus.interface(),
            up.names.join(", "),
            up.layout.expected_wkc
        );
        let wire_owner = Arc::new(AtomicU8::new(owner::CYCLE));
        let quit = Arc::new(AtomicBool::new(false));
        let (tell, told) = sync_channel(4);
        // Spawned before the process takes its real-time priority: the thread keeps the
        // ordinary one.
        let recovery = std::thread::Builder::new()
            .name("bus-recovery".into())
            .spawn({
                let r = Recovery {
                    master,
                    wire: wire.clone(),
                    bus,
                    axes: axes.to_vec(),
                    timing,
                    layout: up.layout,
                    dc: up.dc,
                    dc_again: dc_again.clone(),
                    owner: wire_owner.clone(),
                    quit: quit.clone(),
                    tell,
                };
                move || r.run()
            })?;
        let mut startup_emergencies = [(0, 0, 0); STARTUP_EMERGENCIES];
        for (slot, e) in startup_emergencies.iter_mut().zip(&up.emergencies) {
            *slot = *e;
        }
        let mut bus = Bus {
            wire,
            interface: bus.interface().to_string(),
            announce: "",
            reaching_op: None,
            startup_emergencies,
            startup_emergency_count: up.emergencies.len().min(STARTUP_EMERGENCIES),
            wire_owner,
            quit,
            recovery: Some(recovery),
            told,
            recoveries: 0,
            degraded_since_ns: None,
            degraded_wait_ns: ctx.cell.estop_stop_time_ns,
            latched_while_recovering: false,
            names: {
                let mut n = [[0u8; 16]; MAX_SUBDEVICES];
                for (slot, s) in n.iter_mut().zip(bus.subdevices()) {
                    *slot = s.name;
                }
                n
            },
            in_op: [false; MAX_SUBDEVICES],
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
            command_fresh: Freshness::new(ctx.period_of("servo")?),
            command_timeout_ns: ctx.cell.drive_command_timeout_ns,
            last_command_ns: None,
            command: None,
            last_applied_seq: 0,
            sense_to_command: SenseToCommand::new(&ctx.node, i)?,
            round_trip: Box::default(),
            io,
            io_image: None,
            io_reported: None,
            dc: up.dc,
            dc_again,
            last_sync0_cycle: None,
            sync0_late: 0,
            sync0_late_untold: 0,
            last_sync0_event_ns: 0,
            sync0_lead: Box::default(),
            source: ctx.index as u32,
            io_state: Sub::new(&ctx.node, i, ServiceId::IoState, 1)?,
            field_inputs: Pub::new(&ctx.node, i, ServiceId::FieldInputs)?,
            commands: Sub::new(&ctx.node, i, ServiceId::DriveCommand, 8)?,
            feedback: Pub::new(&ctx.node, i, ServiceId::DriveFeedback)?,
        };
        // In SAFE-OP: the cycle's frames take the bus to OP.
        bus.ask_for_op(runtime::time::now_ns(), "in OP on ");
        Ok(bus)
    }

    /// Publishes feedback with every position NaN and no state: the drives cannot be vouched
    /// for (the bus is lost, or being brought up again).
    ///
    /// # Real-time
    /// Copies and an IPC call.
    fn publish_unknown(&mut self, now: u64, cx: &mut Cycle<'_>) {
        self.seq += 1;
        let fb = self
            .drives
            .read(now, self.seq, false, &self.frame, cx.events);
        self.feedback.send(&fb);
    }

    /// Gives the wire to the recovery thread, which brings the bus up again from the scan.
    ///
    /// # Real-time
    /// An atomic store and an event.
    fn hand_over(&mut self, now: u64, cx: &mut Cycle<'_>) {
        self.recoveries += 1;
        self.latched_while_recovering = cx.estop.latched;
        cx.events.push(EventV1::new(
            now,
            code::BUS_RECOVERING,
            -1,
            self.recoveries as f64,
            0.0,
            &[
                "bringing the bus on ",
                &self.interface,
                " up again from the scan",
            ],
        ));
        self.wire_owner.store(owner::RECOVERING, Ordering::Release);
    }

    /// The cycle while the recovery thread has the wire: feedback without positions, the
    /// e-stop raised again if someone resets it, and the bus taken back once it is in OP.
    /// True while the thread still has it.
    ///
    /// # Real-time
    /// Atomic loads and stores, copies and IPC calls.
    fn recovering(&mut self, now: u64, cx: &mut Cycle<'_>) -> bool {
        // A bounded channel of `Copy` events: `try_recv` takes one without a lock or an
        // allocation.
        while let Ok(e) = self.told.try_recv() {
            cx.events.push(e);
        }
        match self.wire_owner.load(Ordering::Acquire) {
            owner::RECOVERING => {
                if cx.estop.latched {
                    self.latched_while_recovering = true;
                } else if self.latched_while_recovering {
                    // A reset while the bus is not back: nothing may be enabled on it.
                    self.latched_while_recovering = false;
                    cx.raise_estop(
                        EstopOrigin::Device,
                        code::BUS_RECOVERING,
                        &["EtherCAT bus not back in OP yet"],
                    );
                }
                self.publish_unknown(now, cx);
                cx.set_safe(true);
                true
            }
            owner::BACK => {
                // The same line in the same layout (the thread checked it): the cycle goes on
                // with its frame, the drives' states read afresh, and the clocks as the
                // thread set them up.
                if let Some(dc) = self.dc.as_mut() {
                    dc.epoch_ns = self.dc_again[0].load(Ordering::Acquire);
                    dc.wake_ns = self.dc_again[1].load(Ordering::Acquire);
                }
                self.last_sync0_cycle = None;
                self.lost = 0;
                self.degraded_since_ns = None;
                self.drives.forget();
                self.ask_for_op(now, "back in OP on ");
                self.wire_owner.store(owner::CYCLE, Ordering::Release);
                false
            }
            _ => false,
        }
    }

    /// Makes the cycle's frames ask every SubDevice for OP, from SAFE-OP, until all are
    /// there ([`Bus::reach_op`]); `announce` says so then.
    ///
    /// # Real-time
    /// Stores only.
    fn ask_for_op(&mut self, now: u64, announce: &'static str) {
        self.in_op = [false; MAX_SUBDEVICES];
        self.reaching_op = Some(now);
        self.announce = announce;
        self.frame.request_op(true);
    }

    /// While the frames ask for OP: once every SubDevice is there, the bus is announced in OP
    /// (with the start-up's emergencies) and the frames stop asking; a SubDevice that refused
    /// (its error bit) or is not there after [`STATE_TRANSITION`] is named, and the bus goes to
    /// the recovery thread. True once the bus is in OP.
    ///
    /// # Real-time
    /// Reads of the last reply, copies, events and an atomic store.
    fn reach_op(&mut self, now: u64, since: u64, cx: &mut Cycle<'_>) -> bool {
        let n = self.frame.layout().count;
        let late = now.saturating_sub(since) > STATE_TRANSITION.as_nanos() as u64;
        let mut all = true;
        for k in 0..n {
            let (status, code) = self.frame.al_status(k);
            let op = status & 0x1F == 0x08;
            self.in_op[k] = op;
            all &= op;
            if !op && (status & 0x10 != 0 || late) {
                let what = ") did not reach OP";
                self.tell(
                    now,
                    k,
                    code::SUBDEVICE_NOT_OP,
                    (f64::from(status), f64::from(code)),
                    what,
                    cx,
                );
                self.frame.request_op(false);
                self.reaching_op = None;
                self.hand_over(now, cx);
                return false;
            }
        }
        if !all {
            return false;
        }
        self.frame.request_op(false);
        self.reaching_op = None;
        cx.events.push(EventV1::new(
            now,
            code::BUS_OP,
            -1,
            n as f64,
            f64::from(self.frame.layout().expected_wkc),
            &[self.announce, &self.interface],
        ));
        for &(k, code, register) in
            &self.startup_emergencies[..std::mem::take(&mut self.startup_emergency_count)]
        {
            self.emergency(now, k, code, register, cx);
        }
        true
    }

    /// Tells SubDevice `k`'s CoE emergency.
    ///
    /// # Real-time
    /// Copies only.
    fn emergency(&self, now: u64, k: usize, code: u16, register: u8, cx: &mut Cycle<'_>) {
        let what = ") sent an emergency";
        self.tell(
            now,
            k,
            code::SUBDEVICE_EMERGENCY,
            (f64::from(code), f64::from(register)),
            what,
            cx,
        );
    }

    /// The event `code` about SubDevice `k` with its `(value, limit)`: "position k (name)" and
    /// `what`.
    ///
    /// # Real-time
    /// Copies only.
    fn tell(
        &self,
        now: u64,
        k: usize,
        code: u32,
        reading: (f64, f64),
        what: &str,
        cx: &mut Cycle<'_>,
    ) {
        let (value, limit) = reading;
        cx.events.push(EventV1::new(
            now,
            code,
            -1,
            value,
            limit,
            &[
                "position ",
                POSITIONS.get(k).copied().unwrap_or("?"),
                " (",
                shm_schema::str_of(&self.names[k.min(MAX_SUBDEVICES - 1)]),
                what,
            ],
        ));
    }

    /// With Distributed Clocks: from the reference clock's time in the reply, the host times
    /// of the last input latch before the frame and of the SYNC0 after it, which applies
    /// the frame's outputs (`None` before the first latch, or without DC); records
    /// how long before the next SYNC0 the frame came, and counts the SYNC0 events no frame
    /// came before (`sync0-late`).
    ///
    /// # Real-time
    /// Arithmetic, a histogram record and an event.
    fn sync0_check(&mut self, now: u64, cx: &mut Cycle<'_>) -> Option<(u64, u64)> {
        let dc = self.dc?;
        let (r, _) = self.frame.reference_time()?;
        let (last, lead) = dc.around(r)?;
        self.sync0_lead.record(lead);
        let cycle = dc.cycle_of(r);
        if let Some(before) = self.last_sync0_cycle
            && cycle > before + 1
        {
            let late = cycle - before - 1;
            self.sync0_late += late;
            self.sync0_late_untold += late;
        }
        self.last_sync0_cycle = Some(cycle);
        if self.sync0_late_untold > 0 && now.saturating_sub(self.last_sync0_event_ns) >= REPEAT_NS {
            self.last_sync0_event_ns = now;
            cx.events.push(EventV1::new(
                now,
                code::SYNC0_LATE,
                -1,
                std::mem::take(&mut self.sync0_late_untold) as f64,
                0.0,
                &["SYNC0 came with no new frame before it"],
            ));
        }
        Some((
            last.wrapping_sub(dc.epoch_ns),
            r.wrapping_add(lead).wrapping_sub(dc.epoch_ns),
        ))
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
        if self.recovering(now, cx) {
            return;
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
        if !self.io.is_empty() {
            if let Some(s) = self.io_state.latest() {
                self.io_image = Some((s.values, s.stamp_ns));
            }
            let outputs = self
                .io_image
                .filter(|&(_, t)| now.saturating_sub(t) <= IO_REFRESH_NS)
                .map_or(0, |(v, _)| v);
            self.io.write(outputs, &mut self.frame);
        }
        let sent_ns = runtime::time::now_ns();
        if let Some(dc) = &self.dc {
            // The reference clock follows the host's (its drift control, every frame).
            self.frame
                .set_master_time(sent_ns.wrapping_add(dc.epoch_ns));
        }
        let sent = self.wire.send(self.frame.next_frame()).is_ok();
        let reply = if sent {
            self.await_reply(sent_ns + self.reply_wait_ns)
        } else {
            None
        };
        if reply.is_some() {
            self.round_trip
                .record(runtime::time::now_ns().saturating_sub(sent_ns));
        }
        let Some((wkc, _al_read)) = reply else {
            // No reply: no feedback this cycle (never a last good value); servo judges the
            // gap by its feedback timeout. A transport overrun (seed 002: the bus' errors).
            self.lost += 1;
            if self.lost <= self.lost_limit {
                cx.transport_overruns(1);
            }
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
                // saw; and the recovery thread brings the bus up again once it answers.
                self.publish_unknown(now, cx);
                self.hand_over(now, cx);
            }
            cx.set_safe(!self.drives.powered() || self.lost >= self.lost_limit);
            return;
        };
        self.lost = 0;
        if !cx.estop.latched {
            self.bus_lost_raised = false;
        }
        // On the way to OP: nothing is published (servo has no feedback, nothing can be
        // enabled) until every SubDevice is there.
        if let Some(since) = self.reaching_op
            && !self.reach_op(now, since, cx)
        {
            cx.set_safe(true);
            return;
        }
        // Each SubDevice's AL state, read in the same frame: one leaving OP is named.
        for k in 0..self.frame.layout().count {
            let (status, code) = self.frame.al_status(k);
            let op = status & 0x0F == 0x08;
            if self.in_op[k] && !op {
                // Nothing on the bus may run on without it: its process data is not taken
                // (an input terminal in SAFE-OP would not even change the working counter).
                cx.raise_estop(
                    EstopOrigin::Device,
                    code::SUBDEVICE_LEFT_OP,
                    &["an EtherCAT SubDevice left OP"],
                );
                let reading = (f64::from(status), f64::from(code));
                self.tell(now, k, code::SUBDEVICE_LEFT_OP, reading, ") left OP", cx);
            }
            self.in_op[k] = op;
        }
        // A CoE emergency in the mailbox this frame read; the next frame reads the next full
        // one (not the one just read: its status was read before it was emptied).
        let just_read = self.frame.mailbox_read();
        if let Some((k, mailbox)) = self.frame.mailbox()
            && let Some((code, register)) = coe_emergency(mailbox)
        {
            self.emergency(now, k, code, register, cx);
        }
        let full = self.frame.full_mailboxes().find(|&k| Some(k) != just_read);
        if let Some(k) = full {
            self.frame.read_mailbox(k);
        }
        let expected = self.frame.layout().expected_wkc;
        let valid = wkc == expected;
        // A bus degraded while the e-stop is latched: once every drive has ramped down, the
        // bus is brought up again.
        let degraded = !valid || self.in_op[..self.frame.layout().count].contains(&false);
        // Degraded with the e-stop latched: the bus is known bad and waits to be brought up
        // again; its frames are not counted again as transport overruns.
        let degraded_latched = degraded && cx.estop.latched;
        if degraded_latched {
            let since = *self.degraded_since_ns.get_or_insert(now);
            if now.saturating_sub(since) >= self.degraded_wait_ns {
                self.publish_unknown(now, cx);
                self.hand_over(now, cx);
                cx.set_safe(true);
                return;
            }
        } else {
            self.degraded_since_ns = None;
        }
        if !valid && !degraded_latched {
            cx.transport_overruns(1);
        }
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
        if valid && !self.io.is_empty() {
            let (mask, values) = self.io.read(&self.frame);
            let due = self
                .io_reported
                .is_none_or(|(v, t)| v != values || now.saturating_sub(t) >= IO_REFRESH_NS);
            if due {
                self.io_reported = Some((values, now));
                self.field_inputs.send(&IoWriteV1 {
                    stamp_ns: sent_ns,
                    mask,
                    values,
                    source: self.source,
                    line: 0,
                });
            }
        }
        // On SYNC0 the inputs were latched before the frame (the feedback's time) and the
        // command applies at the next SYNC0; else both as the frame passes.
        let (latched_ns, applied_ns) = self.sync0_check(now, cx).unwrap_or((sent_ns, sent_ns));
        self.seq += 1;
        let mut fb = self
            .drives
            .read(latched_ns, self.seq, valid, &self.frame, cx.events);
        let mut sample = None;
        if let Some(c) = command.filter(|c| c.seq != self.last_applied_seq) {
            self.last_applied_seq = c.seq;
            if c.feedback_stamp_ns > 0 {
                fb.sense_to_command_ns = applied_ns.saturating_sub(c.feedback_stamp_ns);
                sample = Some(fb.sense_to_command_ns);
            }
        }
        cx.set_safe(!self.drives.powered());
        self.feedback.send(&fb);
        self.sense_to_command.step(now, sample);
    }

    fn stop(&mut self, now_ns: u64, _events: &mut EventQueue) {
        self.sense_to_command.finish(now_ns);
        // A percentile of a histogram, in µs.
        let us_of = |h: &LatencyHistogramV1, q: u64| {
            h.percentile(q, 1000).map_or(f64::NAN, |v| v as f64 / 1e3)
        };
        let us = |q: u64| us_of(&self.round_trip, q);
        tracing::info!(
            "frame round trip over {} frames: p50 {:.1} µs, p99 {:.1} µs, max {:.1} µs",
            self.round_trip.count,
            us(500),
            us(990),
            self.round_trip.max_ns as f64 / 1e3
        );
        if let Some(dc) = &self.dc {
            let lead = |q: u64| us_of(&self.sync0_lead, q);
            tracing::info!(
                "SYNC0 every {} µs, {} µs after the wake-up: the frame came p50 {:.1} µs, p1 {:.1} µs, least {:.1} µs before it over {} frames; {} SYNC0 events with no new frame before them",
                dc.cycle_ns / 1000,
                dc.shift_ns / 1000,
                lead(500),
                lead(10),
                self.sync0_lead.min_ns as f64 / 1e3,
                self.sync0_lead.count,
                self.sync0_late
            );
        }
        self.quit.store(true, Ordering::Release);
        if let Some(t) = self.recovery.take() {
            let _ = t.join();
        }
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

/// The recovery thread: while the cycle has handed it the wire ([`owner::RECOVERING`]),
/// brings the bus up again from the scan to SAFE-OP, once a second until it answers as the
/// configuration says and in the layout the cycle's frame was built for, then hands the wire
/// back ([`owner::BACK`]): the cycle asks for OP. Not real-time (the process' ordinary priority); it logs why an attempt
/// failed when the reason changes.
struct Recovery {
    master: Master,
    wire: Arc<Wire>,
    bus: EthercatConfigV1,
    axes: Vec<shm_schema::AxisConfigV2>,
    timing: Timing,
    layout: Layout,
    /// The bus' clocks as first brought up: a bus back must have the same reference clock
    /// and SubDevices on SYNC0; its new epoch and wake-up go to the cycle through `dc_again`.
    dc: Option<Dc>,
    dc_again: Arc<[AtomicU64; 2]>,
    owner: Arc<AtomicU8>,
    quit: Arc<AtomicBool>,
    /// Events for the cycle to publish (`Bus::told`).
    tell: SyncSender<EventV1>,
}

impl Recovery {
    fn run(mut self) {
        let quit = self.quit.clone();
        let owner = self.owner.clone();
        let give_up = move || {
            quit.load(Ordering::Acquire)
                || runtime::signals::stop_requested()
                || owner.load(Ordering::Acquire) != owner::RECOVERING
        };
        let mut last_failure = String::new();
        while !self.quit.load(Ordering::Acquire) && !runtime::signals::stop_requested() {
            if self.owner.load(Ordering::Acquire) != owner::RECOVERING {
                std::thread::sleep(Duration::from_millis(20));
                continue;
            }
            let attempt = Instant::now();
            let same_clocks = |dc: Option<Dc>| {
                dc.map(|d| (d.reference, d.station, d.cycle_ns, d.shift_ns, d.on_sync0))
            };
            let failure = match self.master.bring_up(
                &self.bus,
                &self.axes,
                self.timing,
                &self.wire,
                &give_up,
            ) {
                Ok(up)
                    if up.layout == self.layout && same_clocks(up.dc) == same_clocks(self.dc) =>
                {
                    tell_emergencies(&up);
                    if let Some(dc) = up.dc {
                        self.dc_again[0].store(dc.epoch_ns, Ordering::Release);
                        self.dc_again[1].store(dc.wake_ns, Ordering::Release);
                    }
                    tracing::info!(
                        "bus on {} back in SAFE-OP: {}; the cycle asks for OP",
                        self.bus.interface(),
                        up.names.join(", ")
                    );
                    last_failure.clear();
                    self.owner.store(owner::BACK, Ordering::Release);
                    continue;
                }
                Ok(up) if up.layout == self.layout => BringUpError::Failed(format!(
                    "the bus on {} came back with other clocks ({:?}, where the cycle has {:?}): `supervisor restart drives`",
                    self.bus.interface(),
                    up.dc,
                    self.dc
                )),
                Ok(up) => BringUpError::Failed(format!(
                    "the bus on {} came back with another process image ({:?}, where the cycle has {:?}): `supervisor restart drives`",
                    self.bus.interface(),
                    up.layout,
                    self.layout
                )),
                Err(e) => e,
            };
            let said = failure.to_string();
            if said != last_failure {
                tracing::warn!("the bus is not back: {said} (trying again every second)");
                if let BringUpError::Line(m) = &failure {
                    self.say(mismatch_event(m));
                }
                last_failure = said;
            }
            let rest = Duration::from_secs(1).saturating_sub(attempt.elapsed());
            let until = Instant::now() + rest;
            while Instant::now() < until && !give_up() {
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }

    /// Gives `e` to the cycle to publish; dropped if the cycle has not taken the last few
    /// (it takes them every cycle while the thread has the wire).
    fn say(&self, e: EventV1) {
        if let Err(TrySendError::Full(_)) = self.tell.try_send(e) {
            tracing::warn!(
                "event {} not published: the cycle has not taken the last ones",
                e.code
            );
        }
    }
}

/// `subdevice-mismatch` for `m`: value the product found, limit the one configured, the axis
/// the configured SubDevice drives; the text names the position and the SubDevice configured
/// there.
fn mismatch_event(m: &Mismatch) -> EventV1 {
    let configured = m.expected.as_ref();
    let text = match configured {
        Some(e) => format!("position {} should be {}", m.position, e.name),
        None => format!("position {} is not in the configuration", m.position),
    };
    EventV1::new(
        runtime::time::now_ns(),
        code::SUBDEVICE_MISMATCH,
        configured.and_then(|e| e.axis).map_or(-1, |a| a as i32),
        m.there.as_ref().map_or(0.0, |t| f64::from(t.product)),
        configured.map_or(0.0, |e| f64::from(e.product)),
        &[&text],
    )
}

/// Logs the emergencies a bring-up read.
fn tell_emergencies(up: &Up) {
    for &(k, code, register) in &up.emergencies {
        tracing::warn!(
            "position {k} ({}) sent emergency {code:#06x} (error register {register:#04x}) during start-up",
            up.names.get(k).map_or("?", String::as_str)
        );
    }
}

fn main() -> ExitCode {
    process::run(
        "drives",
        "the cell's EtherCAT MainDevice: CiA 402 drives on a bus",
        Bus::new,
    )
}
