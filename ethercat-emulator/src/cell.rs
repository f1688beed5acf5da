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
use runtime::ipc::{Pub, Sub};
use runtime::process::{self, Context, Cycle, SetupError, Task};
use runtime::rt::{self, RtRequest};
use shm_schema::ethercat::emulator_fault as kind;
use shm_schema::event::code;
use shm_schema::{
    EmulatorFaultV1, EthercatConfigV1, EventV1, FaultInjectionV1, InstanceName, ServiceId,
};
use std::process::{Command, ExitCode};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError};
use std::thread::JoinHandle;
use std::time::Duration;

/// The emulator's end of the pair: the bus' interface with this suffix.
pub const PEER_SUFFIX: &str = "-sd";

/// What the frames thread is told to do.
#[derive(Clone, Copy, Debug)]
enum Order {
    /// A fault of the bus (`<i>/ethercat/emulator/fault`).
    Fault(EmulatorFaultV1),
    /// A fault condition of the drive at `position` (`<i>/drives/inject`).
    Inject {
        position: usize,
        injection: FaultInjectionV1,
    },
}

struct Emulator {
    stop: Arc<AtomicBool>,
    answered: Arc<AtomicU64>,
    /// The frames' thread; it returns each drive's SYNC0 counts as it ends.
    thread: Option<JoinHandle<Vec<Sync0Count>>>,
    interface: String,
    faults: Sub<EmulatorFaultV1>,
    injections: Sub<FaultInjectionV1>,
    orders: SyncSender<Order>,
    /// The newest fault taken (`EmulatorFaultV1::seq`).
    last_fault_seq: u64,
    /// The position of each cell axis' drive on the line.
    drive_of_axis: [Option<usize>; shm_schema::MAX_AXES],
}

impl Emulator {
    /// Hands `order` to the frames thread (unless `apply` is false: a repeat) and tells it
    /// was taken (`fault-injected`).
    fn order(&self, order: Order, apply: bool, cx: &mut Cycle<'_>) {
        let (axis, value, limit, text) = match order {
            Order::Fault(f) => (
                -1,
                f64::from(f.code),
                f64::from(f.kind),
                match f.kind {
                    kind::CABLE_PULLED => "bus: the cable pulled",
                    kind::CABLE_BACK => "bus: the cable back",
                    kind::LEAVE_OP => "bus: a SubDevice leaves OP",
                    kind::EMERGENCY => "bus: a drive sends an emergency",
                    kind::IDENTITY => "bus: another product code at a position",
                    kind::INPUT => "bus: an input forced",
                    _ => "bus: an unknown fault, ignored",
                },
            ),
            Order::Inject { injection, .. } => (
                injection.axis as i32,
                if injection.active != 0 {
                    f64::from(injection.code)
                } else {
                    0.0
                },
                0.0,
                "the emulated drive: a fault condition",
            ),
        };
        // Not taken (the frames thread busy or gone): told with limit -1, which no sender
        // takes for its acknowledgement.
        let sent = if apply {
            self.orders.try_send(order)
        } else {
            Ok(())
        };
        let (limit, taken) = match sent {
            Ok(()) => (limit, ""),
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                (-1.0, " (not taken: busy)")
            }
        };
        cx.events.push(EventV1::new(
            cx.now_ns(),
            code::FAULT_INJECTED,
            axis,
            value,
            limit,
            &[text, taken],
        ));
    }
}

impl Emulator {
    /// The emulated line answering on its interface's peer: the bus configuration waited
    /// for, the SubDevices built, the frames' thread started. Set-up only.
    fn new(ctx: &Context) -> Result<Self, SetupError> {
        let Some(bus_config) = process::wait_for::<EthercatConfigV1>(
            &ctx.node,
            &ctx.instance,
            ServiceId::EthercatConfig,
            "the cell has no [ethercat] section",
        )?
        else {
            return Err("stopped before the bus configuration arrived".into());
        };
        let terminals = line(&bus_config, ctx)?;
        let interface = bus_config.interface().to_string();
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
        // An EtherCAT link carries nothing else: no IPv6 neighbour or router discovery
        // (what a real bus' interface should be set to as well, docs/ethercat.md).
        for end in [&interface, &peer] {
            let knob = format!("/proc/sys/net/ipv6/conf/{end}/disable_ipv6");
            if std::path::Path::new(&knob).exists() {
                std::fs::write(&knob, "1").map_err(|e| format!("{knob}: {e}"))?;
            }
        }
        ip(&["link", "set", &peer, "up"])?;
        ip(&["link", "set", &interface, "up"])?;
        let stop = Arc::new(AtomicBool::new(false));
        let answered = Arc::new(AtomicU64::new(0));
        let (orders, orders_rx) = std::sync::mpsc::sync_channel(32);
        let wiring = Wiring::new(&bus_config, &ctx.cell, ctx.index as u32);
        let mut drive_of_axis = [None; shm_schema::MAX_AXES];
        for (k, s) in bus_config.subdevices().iter().enumerate() {
            if let Some(slot) = s.axis().and_then(|a| drive_of_axis.get_mut(a)) {
                *slot = Some(k);
            }
        }
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
                    answer(&wire, bus, wiring, &stop, &answered, &orders_rx)
                })?
        };
        tracing::info!("answering on {peer} for the bus on {interface}");
        Ok(Self {
            stop,
            answered,
            thread: Some(thread),
            interface,
            faults: Sub::new(&ctx.node, &ctx.instance, ServiceId::EmulatorFault, 32)?,
            injections: Sub::new(&ctx.node, &ctx.instance, ServiceId::FaultInjection, 32)?,
            orders,
            last_fault_seq: 0,
            drive_of_axis,
        })
    }
}

impl Task for Emulator {
    /// Hands the faults it is told to make to the frames thread (a test device: the frames
    /// are answered by that thread).
    fn cycle(&mut self, cx: &mut Cycle<'_>) {
        while let Some(f) = self.faults.next() {
            // A sender repeats its fault until it hears it was taken: each is made once.
            if f.seq > self.last_fault_seq {
                self.last_fault_seq = f.seq;
                self.order(Order::Fault(f), true, cx);
            } else if f.seq == self.last_fault_seq {
                // Its acknowledgement was missed: told again, made once.
                self.order(Order::Fault(f), false, cx);
            }
        }
        while let Some(injection) = self.injections.next() {
            if let Some(position) = self
                .drive_of_axis
                .get(injection.axis as usize)
                .copied()
                .flatten()
            {
                self.order(
                    Order::Inject {
                        position,
                        injection,
                    },
                    true,
                    cx,
                );
            }
        }
    }

    fn stop(&mut self, now_ns: u64, events: &mut shm_schema::EventQueue) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            // Each drive's SYNC0 counts, as events (the process is leaving: not the cycle).
            for c in t.join().unwrap_or_default() {
                let position = c.position.to_string();
                events.push(EventV1::new(
                    now_ns,
                    code::EMULATED_SYNC0,
                    (self.drive_of_axis.iter())
                        .position(|d| *d == Some(c.position))
                        .map_or(-1, |a| a as i32),
                    c.sync0 as f64,
                    c.missed as f64,
                    &["position ", &position, " (", &c.name, "): SYNC0 events"],
                ));
            }
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

/// The field wired to the IO terminals: the cell's `[[io]]` entries on the bus, the simulated
/// devices behind them (`machine_sim::field`: an input that `follows` an output, one model
/// with `machine-sim`'s), the other inputs at their `sim` value, and inputs forced by a fault.
struct Wiring {
    field: machine_sim::field::Field,
    /// (entry, position, bit, input) per `[[io]]` entry on the bus.
    map: Vec<(usize, usize, u16, bool)>,
    /// The inputs' values as the field and the `sim` values give them (bit `k`: entry `k`).
    inputs: u64,
    /// Inputs a fault forced: (position, bit, value).
    forced: Vec<(usize, u16, bool)>,
}

impl Wiring {
    fn new(bus: &EthercatConfigV1, cell: &shm_schema::CellConfigV6, source: u32) -> Self {
        let io = cell.io();
        let mut inputs = 0;
        let map = bus
            .ios()
            .iter()
            .filter_map(|m| {
                let e = io.get(usize::from(m.entry))?;
                let input = shm_schema::IoDirection::from_wire(e.direction)
                    == Some(shm_schema::IoDirection::Input);
                if input && e.sim != 0 {
                    inputs |= 1 << m.entry;
                }
                Some((usize::from(m.entry), usize::from(m.position), m.bit, input))
            })
            .collect();
        Self {
            field: machine_sim::field::Field::new(cell, source),
            map,
            inputs,
            forced: Vec::new(),
        }
    }

    /// The outputs the MainDevice wrote move the devices; their sensors (and the forced
    /// inputs) go into the input terminals.
    fn step(&mut self, bus: &mut Bus, now_ns: u64) {
        if self.map.is_empty() {
            return;
        }
        let mut outputs = 0u64;
        for &(entry, position, bit, input) in &self.map {
            if let (false, Some(Terminal::El2008 { outputs: o })) =
                (input, bus.devices.get(position).map(|d| &d.terminal))
                && o & (1 << (bit % 8)) != 0
            {
                outputs |= 1 << entry;
            }
        }
        if let Some(w) = self.field.step(now_ns, Some(outputs)) {
            self.inputs = (self.inputs & !w.mask) | (w.values & w.mask);
        }
        for &(entry, position, bit, input) in &self.map {
            let forced = self
                .forced
                .iter()
                .find(|f| f.0 == position && f.1 == bit)
                .map(|f| f.2);
            let on = forced.unwrap_or(self.inputs & (1 << entry) != 0);
            if let (true, Some(Terminal::El1008 { inputs })) = (
                input,
                bus.devices.get_mut(position).map(|d| &mut d.terminal),
            ) {
                if on {
                    *inputs |= 1 << (bit % 8);
                } else {
                    *inputs &= !(1 << (bit % 8));
                }
            }
        }
    }
}

/// Carries out a fault it was told to make; false: the cable is pulled from now on.
fn carry_out(bus: &mut Bus, wiring: &mut Wiring, order: Order, cable: &mut bool) {
    fn device(bus: &mut Bus, k: u32) -> Option<&mut crate::bus::SubDevice> {
        bus.devices.get_mut(k as usize)
    }
    match order {
        Order::Fault(f) => match f.kind {
            kind::CABLE_PULLED => *cable = false,
            kind::CABLE_BACK => *cable = true,
            kind::LEAVE_OP => {
                if let Some(d) = device(bus, f.position) {
                    d.esc.leave_op(f.code as u16);
                }
            }
            kind::EMERGENCY => {
                if let Some(d) = device(bus, f.position)
                    && let Terminal::Drive(drive) = &mut d.terminal
                {
                    drive.send_emergency(f.code as u16);
                }
            }
            kind::IDENTITY => {
                if let Some(d) = device(bus, f.position) {
                    d.esc.set_product(f.code);
                }
            }
            kind::CLOCK_DRIFT => {
                if let Some(d) = device(bus, f.position) {
                    d.esc.set_drift(f64::from(f.code as i32));
                }
            }
            kind::INPUT => {
                let at = (f.position as usize, f.bit as u16);
                wiring.forced.retain(|x| (x.0, x.1) != at);
                wiring.forced.push((at.0, at.1, f.code != 0));
                if let Some(d) = device(bus, f.position)
                    && let Terminal::El1008 { inputs } = &mut d.terminal
                {
                    if f.code != 0 {
                        *inputs |= 1 << (f.bit % 8);
                    } else {
                        *inputs &= !(1 << (f.bit % 8));
                    }
                }
            }
            _ => {}
        },
        Order::Inject {
            position,
            injection,
        } => {
            if let Some(d) = bus.devices.get_mut(position)
                && let Terminal::Drive(drive) = &mut d.terminal
            {
                drive.inject(injection.code, injection.active != 0, injection.seq);
            }
        }
    }
}

/// A drive's SYNC0 events over the emulator's life, as its frames' thread ends.
#[derive(Debug)]
struct Sync0Count {
    position: usize,
    name: String,
    /// SYNC0 events it took.
    sync0: u64,
    /// Those that found no new outputs (0x1C32:0B).
    missed: u64,
}

/// Answers frames on `wire` until `stop`; between frames the drives' models run on. With
/// the cable pulled (told so) frames are taken and not answered. Returns each drive's SYNC0
/// counts.
fn answer(
    wire: &Wire,
    mut bus: Bus,
    mut wiring: Wiring,
    stop: &AtomicBool,
    answered: &AtomicU64,
    orders: &Receiver<Order>,
) -> Vec<Sync0Count> {
    let mut buf = vec![0u8; 9216];
    let mut cable = true;
    while !stop.load(Ordering::Relaxed) {
        while let Ok(order) = orders.try_recv() {
            carry_out(&mut bus, &mut wiring, order, &mut cable);
        }
        wiring.step(&mut bus, crate::now_ns());
        match wire.receive(&mut buf) {
            Ok(Received::Frame(_)) if !cable => bus.idle(),
            Ok(Received::Frame(n)) => {
                let frame = &mut buf[..n];
                if bus.handle(frame).is_ok() && wire.send(frame).is_ok() {
                    answered.fetch_add(1, Ordering::Relaxed);
                }
            }
            Ok(Received::Nothing) => bus.idle(),
            Err(e) => {
                tracing::error!("{e}");
                break;
            }
        }
    }
    let mut counts = Vec::new();
    for (k, d) in bus.devices.iter().enumerate() {
        if let Terminal::Drive(drive) = &d.terminal {
            tracing::info!(
                "position {k} ({}): {} SYNC0 events, {} without new outputs (0x1C32:0B)",
                drive.name(),
                drive.sync0_events(),
                drive.sm_events_missed()
            );
            counts.push(Sync0Count {
                position: k,
                name: drive.name().to_string(),
                sync0: drive.sync0_events(),
                missed: u64::from(drive.sm_events_missed()),
            });
        }
    }
    counts
}

/// `main` in a cell.
pub fn main() -> ExitCode {
    process::run(
        "emulator",
        "emulated EtherCAT SubDevices for a cell without hardware",
        Emulator::new,
    )
}

/// `ethercat-emulator fault --instance NAME KIND [POSITION] [CODE]`: tells the emulator of a
/// running test cell to make a fault, and waits until it says it took it.
#[derive(clap::Parser, Debug)]
#[command(name = "ethercat-emulator fault")]
struct FaultArgs {
    /// The cell's instance.
    #[arg(long)]
    instance: String,
    /// cable-pulled, cable-back, leave-op, emergency, identity, input, clock-drift.
    kind: String,
    /// The SubDevice's position on the line (leave-op, emergency, identity, input,
    /// clock-drift).
    position: Option<u32>,
    /// The AL status code (leave-op, default 0x001B), the emergency's error code, the
    /// product code (identity), the input's value (input: 0 or 1); decimal or 0x
    /// hexadecimal. The drift of its clock's quartz (clock-drift: ppm, -1000..=1000).
    #[arg(allow_hyphen_values = true)]
    code: Option<String>,
    /// The input bit of the terminal at POSITION (input).
    #[arg(long)]
    bit: Option<u32>,
}

fn number(text: &str) -> Result<u32, String> {
    let t = text.trim();
    match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16),
        None => t.parse(),
    }
    .map_err(|_| format!("{text:?} is not a number (decimal, or hexadecimal with 0x)"))
}

fn fault_of(a: &FaultArgs) -> Result<EmulatorFaultV1, String> {
    let position = || {
        a.position
            .ok_or_else(|| format!("{} needs the SubDevice's position", a.kind))
    };
    let code = |default: Option<u32>| match (&a.code, default) {
        (Some(c), _) => number(c),
        (None, Some(d)) => Ok(d),
        (None, None) => Err(format!("{} needs a code", a.kind)),
    };
    let (kind, position, code) = match a.kind.as_str() {
        "cable-pulled" => (kind::CABLE_PULLED, 0, 0),
        "cable-back" => (kind::CABLE_BACK, 0, 0),
        "leave-op" => (kind::LEAVE_OP, position()?, code(Some(0x001B))?),
        "emergency" => (kind::EMERGENCY, position()?, code(None)?),
        "identity" => (kind::IDENTITY, position()?, code(None)?),
        "input" => (kind::INPUT, position()?, code(None)?),
        "clock-drift" => {
            let text = a
                .code
                .as_deref()
                .ok_or("clock-drift needs the drift in ppm")?;
            let ppm: i32 = text
                .trim()
                .parse()
                .ok()
                .filter(|p: &i32| p.abs() <= 1000)
                .ok_or_else(|| format!("clock drift {text:?} must be -1000..=1000 ppm"))?;
            (kind::CLOCK_DRIFT, position()?, ppm as u32)
        }
        other => {
            return Err(format!(
                "{other:?} is not a fault the emulator makes (cable-pulled, cable-back, leave-op, emergency, identity, input, clock-drift)"
            ));
        }
    };
    if matches!(kind, kind::LEAVE_OP | kind::EMERGENCY) && code > u32::from(u16::MAX) {
        return Err(format!("code {code:#x} is over 16 bits"));
    }
    if kind == kind::INPUT && code > 1 {
        return Err(format!("input {code} must be 0 or 1"));
    }
    let bit = match (kind, a.bit) {
        // The emulator's input terminal, the EL1008, has 8.
        (kind::INPUT, Some(b)) if b < 8 => b,
        (kind::INPUT, Some(b)) => return Err(format!("--bit {b}: an EL1008 has inputs 0 to 7")),
        (kind::INPUT, None) => return Err("input needs --bit".into()),
        (_, Some(_)) => return Err(format!("--bit is for input, not {}", a.kind)),
        (_, None) => 0,
    };
    Ok(EmulatorFaultV1 {
        seq: runtime::time::now_ns(),
        kind,
        position,
        code,
        bit,
    })
}

/// `main` of `ethercat-emulator fault`. Exit 0 when the emulator took the fault, 2 on bad
/// arguments, 1 when no emulator answered.
pub fn fault_main(args: impl Iterator<Item = String>) -> ExitCode {
    use clap::Parser;
    runtime::process::init_logging();
    let a = match FaultArgs::try_parse_from(args) {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(2);
        }
    };
    let (fault, instance) = match fault_of(&a).and_then(|f| {
        InstanceName::new(&a.instance)
            .map(|i| (f, i))
            .map_err(|e| format!("--instance: {e}"))
    }) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    match send_fault(&instance, fault) {
        Ok(()) => {
            println!("the emulator of {instance} took {}", a.kind);
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Sends `fault` until the emulator's `fault-injected` for it arrives (a sample sent before
/// its subscriber saw this publisher is lost), for at most 10 s.
fn send_fault(instance: &InstanceName, fault: EmulatorFaultV1) -> Result<(), String> {
    let node = runtime::ipc::node(instance, "emulator-fault").map_err(|e| e.to_string())?;
    let port = Pub::<EmulatorFaultV1>::new(&node, instance, ServiceId::EmulatorFault)
        .map_err(|e| e.to_string())?;
    let acks =
        Sub::<EventV1>::new(&node, instance, ServiceId::Events, 256).map_err(|e| e.to_string())?;
    let start = std::time::Instant::now();
    let mut sent = false;
    while start.elapsed() < Duration::from_secs(10) {
        if !sent {
            port.update_connections();
            port.send(&fault);
        }
        let round = std::time::Instant::now();
        while round.elapsed() < Duration::from_millis(200) {
            while let Some(e) = acks.next() {
                if e.code == code::FAULT_INJECTED
                    && e.axis == -1
                    && e.limit == f64::from(fault.kind)
                    && e.value == f64::from(fault.code)
                    && e.stamp_ns >= fault.seq
                {
                    return Ok(());
                }
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        sent = false;
    }
    Err(format!(
        "no emulator of instance {instance} took the fault within 10 s (is it a test cell with an `ethercat-emulator` process?)"
    ))
}
