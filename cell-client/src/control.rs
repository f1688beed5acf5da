//! One-shot commands to a running instance: fault injection into the simulated drives, the
//! user's e-stop, and the named digital IO.

use cell_config::FaultKind;
use control_plane::channel::{self, CallError};
use control_plane::status::{IoEntry, SafeValue};
use control_plane::{Reply, Request};
use iceoryx2::prelude::Node;
use runtime::events::EventSink;
use runtime::ipc::{self, Ipc, Pub, Sub};
use shm_schema::event::{SOURCE_SUPERVISOR, code};
use shm_schema::{
    CellConfigV6, DigitalIoV1, EstopOrigin, EstopV1, EventV1, FaultInjectionV1, InstanceName,
    IoDirection, IoWriteV1, ProcessStatusV2, ServiceId, estop_seen, str_of,
};
use std::time::{Duration, Instant};

/// How long `inject` waits for the running cell's configuration and for the drives'
/// acknowledgement.
const PATIENCE: Duration = Duration::from_secs(2);

/// How long a tool waits to learn where a virtual clock stands: the clock may stand a while
/// (a process it waits for, a program validated), and a tool learns it at the clock's next
/// look at its subscribers.
const CLOCK_PATIENCE: Duration = Duration::from_secs(10);

/// Why `inject` failed.
#[derive(Debug)]
pub enum ControlError {
    /// Bad input (instance, axis, fault name) or no such instance: nothing was sent. Exit 2.
    Input(String),
    /// Sent, but the drives did not take it. Exit 1.
    Failed(String),
    /// The supervisor took it and it failed (why, as the supervisor says). Exit 1.
    Cell(control_plane::Failure),
    /// The supervisor refused it (why, as the supervisor says): nothing changed. Exit 2.
    Refused(control_plane::Refusal),
}

impl std::error::Error for ControlError {}

impl std::fmt::Display for ControlError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Input(m) | Self::Failed(m) => f.write_str(m),
            Self::Cell(failure) => write!(f, "{failure}"),
            Self::Refused(refusal) => write!(f, "{refusal}"),
        }
    }
}

/// Runs `body` as a tool attached to the running `instance` (a node of its own, named after
/// `tool`), then removes the node and whatever is left of an instance that ended meanwhile.
/// An invalid instance name, or an instance with no live process, is bad input.
fn attached<T>(
    instance: &str,
    tool: &str,
    body: impl FnOnce(&InstanceName, &Node<Ipc>) -> Result<T, ControlError>,
) -> Result<T, ControlError> {
    let instance = InstanceName::new(instance)
        .map_err(|e| ControlError::Input(format!("--instance {instance:?}: {e}")))?;
    ipc::quiet_iceoryx2_log();
    // A listing that fails (out of descriptors) says why, not "not running".
    if ipc::live_node_pids(&instance)
        .map_err(|e| ControlError::Input(e.to_string()))?
        .is_empty()
    {
        return Err(ControlError::Input(format!(
            "no process of instance {instance} is running"
        )));
    }
    let node = ipc::node(&instance, &format!("{tool}-{}", std::process::id())).map_err(failed)?;
    let result = body(&instance, &node);
    drop(node);
    ipc::cleanup_after_client(&instance);
    result
}

fn failed(e: ipc::IpcError) -> ControlError {
    ControlError::Failed(e.to_string())
}

/// The configuration the running cell published (its axes and processes, not a file's).
/// On a cell on the virtual clock, this tool's time becomes the cell's (where its clock
/// stands): what it stamps and the stamps it waits for are then on one clock.
fn running_cell(node: &Node<Ipc>, instance: &InstanceName) -> Result<CellConfigV6, ControlError> {
    let config =
        Sub::<CellConfigV6>::new(node, instance, ServiceId::CellConfig, 1).map_err(failed)?;
    let start = Instant::now();
    loop {
        if let Some(c) = config.latest() {
            if c.clock == shm_schema::CellClock::Virtual as u32 {
                on_the_cells_clock(node, instance)?;
            }
            return Ok(c);
        }
        if start.elapsed() > PATIENCE {
            // Out of descriptors, the connection to the publisher is never made.
            let why = runtime::fds::shortage().map_or(String::new(), |w| format!(": {w}"));
            return Err(ControlError::Failed(format!(
                "instance {instance} published no cell configuration within {} s{why}",
                PATIENCE.as_secs()
            )));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Turns this tool to the virtual clock of `instance`, at the instant where it stands (the
/// clock's newest grant, which it publishes every tick).
fn on_the_cells_clock(node: &Node<Ipc>, instance: &InstanceName) -> Result<(), ControlError> {
    match runtime::vclock::where_it_stands(node, instance, CLOCK_PATIENCE).map_err(failed)? {
        Some(now) => {
            runtime::time::set_virtual_now(now);
            Ok(())
        }
        None => Err(ControlError::Failed(format!(
            "instance {instance} runs on the virtual clock, but its clock said nothing within \
             {} s",
            CLOCK_PATIENCE.as_secs()
        ))),
    }
}

/// `supervisor inject`: raises (or clears) `fault` on `axis` of the running `instance`, and
/// waits until the drives report it (`fault-injected`), resending while they have not.
pub fn inject(
    instance: &str,
    axis: &str,
    fault: &str,
    clear: bool,
) -> Result<String, ControlError> {
    let code_of = FaultKind::named(fault)
        .map(FaultKind::code)
        .ok_or_else(|| {
            ControlError::Input(format!(
                "fault {fault:?} is not one of {}",
                FaultKind::names()
            ))
        })?;
    attached(instance, "inject", |&instance, node| {
        let cell = running_cell(node, &instance)?;
        let names: Vec<&str> = cell.axes().iter().map(|a| str_of(&a.name)).collect();
        let index = names.iter().position(|n| *n == axis).ok_or_else(|| {
            ControlError::Input(format!(
                "--axis {axis:?}: the cell has axes {}",
                names.join(", ")
            ))
        })?;
        let port = Pub::<FaultInjectionV1>::new(node, &instance, ServiceId::FaultInjection)
            .map_err(failed)?;
        let acks = Sub::<EventV1>::new(node, &instance, ServiceId::Events, 256).map_err(failed)?;
        let mut events = EventSink::new(node, &instance, SOURCE_SUPERVISOR).map_err(failed)?;
        let sample = FaultInjectionV1 {
            // Unique per sender and increasing: the time.
            seq: runtime::time::now_ns(),
            axis: index as u32,
            code: code_of,
            active: u16::from(!clear),
        };
        let want = if clear { 0.0 } else { f64::from(code_of) };
        let what = if clear { "cleared" } else { "injected" };
        // Announced first (the fault may end a run before its acknowledgement arrives), and
        // only once this tool's own subscriber has received the announcement: then the
        // subscribers that were there before it (the supervisor's) have it too. A sample of a
        // brand-new publisher can be lost while its connections settle; it is sent again.
        let announce = EventV1::new(
            runtime::time::now_ns(),
            code::SUPERVISOR_ACTION,
            index as i32,
            f64::from(code_of),
            0.0,
            &[if clear { "clearing " } else { "injecting " }, fault],
        );
        let start = Instant::now();
        let mut heard = false;
        while !heard && start.elapsed() < PATIENCE {
            events.connect();
            events.emit(announce);
            let sent = Instant::now();
            while !heard && sent.elapsed() < Duration::from_millis(100) {
                while let Some(e) = acks.next() {
                    heard |= e.source == SOURCE_SUPERVISOR
                        && e.code == code::SUPERVISOR_ACTION
                        && e.stamp_ns == announce.stamp_ns;
                }
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        let start = Instant::now();
        let mut sent_at: Option<Instant> = None;
        loop {
            // (Re)send until the drives answer: a sample sent before their subscriber saw this
            // publisher is lost (history 0); the same `seq` is taken once.
            if sent_at.is_none_or(|t| t.elapsed() > Duration::from_millis(100)) {
                port.update_connections();
                if !port.send(&sample) {
                    return Err(ControlError::Failed(
                        "the drives' injection service refused the sample".into(),
                    ));
                }
                sent_at = Some(Instant::now());
            }
            while let Some(e) = acks.next() {
                // From the drives' process (machine-sim), or the emulator behind the bus
                // of an EtherCAT test cell.
                if e.code == code::FAULT_INJECTED && e.axis == index as i32 && e.value == want {
                    return Ok(format!(
                        "{what} {fault} on axis {axis} of instance {instance}"
                    ));
                }
            }
            if start.elapsed() > PATIENCE {
                return Err(ControlError::Failed(format!(
                    "the drives of instance {instance} did not report the injection within {} s \
                     (are its drives simulated: machine-sim, or the EtherCAT emulator?)",
                    PATIENCE.as_secs()
                )));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    })
}

/// How long `estop` waits for the supervisor's answer before it raises the e-stop on shared
/// memory itself.
const SUPERVISOR_PATIENCE: Duration = Duration::from_millis(500);

/// `supervisor estop`: raises the user's e-stop (seed 002's `trigger_estop`, origin external)
/// on the running `instance` and waits until a process of the cell reports it latched.
/// Through the supervisor ([`control_plane::Request::Estop`]: it publishes on its own port, so
/// no real-time process has a new publisher to connect to in its cycle); when no supervisor
/// serves the instance, or it does not answer within [`SUPERVISOR_PATIENCE`], straight on
/// `<i>/estop` ([`estop_on_shared_memory`]).
pub fn estop(instance: &str, reason: &str) -> Result<String, ControlError> {
    let name = InstanceName::new(instance)
        .map_err(|e| ControlError::Input(format!("--instance {instance:?}: {e}")))?;
    let req = Request::Estop {
        reason: reason.to_string(),
    };
    match channel::call_within(&name, &req, Some(SUPERVISOR_PATIENCE)) {
        Ok(Reply::Done(m)) => return Ok(m),
        Ok(Reply::Refused(r)) => return Err(ControlError::Refused(r)),
        Ok(Reply::Failed(failure)) => return Err(ControlError::Cell(failure)),
        Ok(other) => tracing::warn!("the supervisor answered the e-stop with {other:?}"),
        Err(CallError::NotUp(_)) => {}
        Err(e) => tracing::warn!("{e}: raising the e-stop on shared memory"),
    }
    estop_on_shared_memory(instance, reason)
}

/// The user's e-stop published straight on `<i>/estop` by this process (a supervisor that is
/// dead or hung does not hold it back), then waited for until a process of the cell reports
/// it latched, resending while none has (a brand-new publisher's first sample can be lost while
/// its connections settle). Each real-time process connects to this new publisher in a cycle.
pub fn estop_on_shared_memory(instance: &str, reason: &str) -> Result<String, ControlError> {
    attached(instance, "estop", |&instance, node| {
        let port = Pub::<EstopV1>::new(node, &instance, ServiceId::Estop).map_err(failed)?;
        let cell = running_cell(node, &instance)?;
        let mut statuses = Vec::new();
        for k in 0..cell.processes().len() {
            if let Some(name) = cell.process_name(k) {
                statuses.push(
                    Sub::<ProcessStatusV2>::new(node, &instance, ServiceId::Status(name), 4)
                        .map_err(failed)?,
                );
            }
        }
        let trigger = EstopV1::trigger(
            runtime::time::now_ns(),
            EstopOrigin::External,
            SOURCE_SUPERVISOR,
            code::ESTOP_RAISED,
            &[reason],
        );
        let start = Instant::now();
        let mut sent_at: Option<Instant> = None;
        loop {
            if sent_at.is_none_or(|t| t.elapsed() > Duration::from_millis(50)) {
                port.update_connections();
                port.send(&trigger);
                sent_at = Some(Instant::now());
            }
            let latched = statuses.iter().any(|s| {
                s.latest()
                    .is_some_and(|st| st.estop & estop_seen::LATCHED != 0)
            });
            if latched {
                return Ok(format!("e-stop raised on instance {instance}: {reason}"));
            }
            if start.elapsed() > PATIENCE {
                return Err(ControlError::Cell(
                    control_plane::Failure::EstopNotLatched {
                        instance: instance.to_string(),
                        within_s: PATIENCE.as_secs_f64(),
                    },
                ));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    })
}

/// `supervisor io`: without `name`, the named digital IO of the running `instance` and their
/// values. With `name` and `value` (0 or 1): an output is requested from iobridge, as a
/// program's `OUT` does; an input is reported as a field device of the simulated field would
/// (a button pressed, a sensor); either way it waits until iobridge's image shows the value.
pub fn io(instance: &str, name: Option<&str>, value: Option<&str>) -> Result<String, ControlError> {
    let value = match value {
        None => None,
        Some("0") => Some(false),
        Some("1") => Some(true),
        Some(v) => {
            let v: String = v.chars().take(20).collect();
            return Err(ControlError::Input(format!("value {v:?}: 0 or 1 expected")));
        }
    };
    attached(instance, "io", |&instance, node| {
        let cell = running_cell(node, &instance)?;
        let state =
            Sub::<DigitalIoV1>::new(node, &instance, ServiceId::IoState, 1).map_err(failed)?;
        let Some(name) = name else {
            let start = Instant::now();
            let image = loop {
                if let Some(s) = state.latest() {
                    break Some(s);
                }
                if start.elapsed() > PATIENCE {
                    break None;
                }
                std::thread::sleep(Duration::from_millis(5));
            };
            return Ok(io_table(&cell, image.as_ref()));
        };
        let names: Vec<&str> = cell.io().iter().map(|e| str_of(&e.name)).collect();
        let k = cell.io_named(name).ok_or_else(|| {
            let shown: String = name.chars().take(40).collect();
            ControlError::Input(if names.is_empty() {
                format!("IO {shown:?}: the cell has no `[[io]]`")
            } else {
                format!("IO {shown:?}: the cell has {}", names.join(", "))
            })
        })?;
        let Some(value) = value else {
            return Err(ControlError::Input(format!(
                "IO {name}: give a value, 0 or 1 (or no name to list the IO)"
            )));
        };
        let output = IoDirection::from_wire(cell.io[k].direction) == Some(IoDirection::Output);
        let port = Pub::<IoWriteV1>::new(
            node,
            &instance,
            if output {
                ServiceId::IoRequest
            } else {
                ServiceId::FieldInputs
            },
        )
        .map_err(failed)?;
        let write = IoWriteV1 {
            stamp_ns: runtime::time::now_ns(),
            mask: 1 << k,
            values: u64::from(value) << k,
            source: SOURCE_SUPERVISOR,
            line: 0,
        };
        let start = Instant::now();
        let mut sent_at: Option<Instant> = None;
        loop {
            // Resent until the image shows it: a brand-new publisher's first sample can be
            // lost while its connections settle.
            if sent_at.is_none_or(|t| t.elapsed() > Duration::from_millis(50)) {
                port.update_connections();
                port.send(&write);
                sent_at = Some(Instant::now());
            }
            if let Some(s) = state.latest().filter(|s| s.stamp_ns > write.stamp_ns) {
                // Refused even when the output already has the value: nothing was taken.
                if output && s.outputs_safe != 0 {
                    return Err(ControlError::Failed(format!(
                        "{name} not set: iobridge holds the outputs at their safe values while it \
                         reacts to the e-stop (`supervisor reset` first)"
                    )));
                }
                if (s.values >> k) & 1 == u64::from(value) {
                    let what = if output {
                        "output"
                    } else {
                        "input (simulated field)"
                    };
                    return Ok(format!(
                        "{name} = {} on instance {instance}: {what}",
                        u8::from(value)
                    ));
                }
            }
            if start.elapsed() > PATIENCE {
                return Err(ControlError::Failed(format!(
                    "iobridge of instance {instance} did not show {name} = {} within {} s",
                    u8::from(value),
                    PATIENCE.as_secs()
                )));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    })
}

/// The IO table as text: name, direction, value.
fn io_table(cell: &CellConfigV6, image: Option<&DigitalIoV1>) -> String {
    if cell.io().is_empty() {
        return "the cell has no named IO (`[[io]]`)".into();
    }
    let v = control_plane::compose::io_status(cell, image);
    let mut out = String::from("name                     direction  value  notes\n");
    for e in &v.entries {
        let (direction, notes) = match e {
            IoEntry::Output { safe, .. } => (
                "output",
                match safe {
                    SafeValue::Level(l) => format!("safe {l}"),
                    SafeValue::Hold(_) => "safe hold".into(),
                },
            ),
            IoEntry::Input { estop: true, .. } => ("input", "e-stop circuit (1 closed)".into()),
            IoEntry::Input { .. } => ("input", String::new()),
        };
        out += &format!(
            "{:<24} {:<10} {:<6} {notes}\n",
            e.name(),
            direction,
            e.value().map_or("?".into(), |v| v.to_string()),
        );
    }
    if image.is_none() {
        out += "(iobridge published no IO image: values unknown)\n";
    } else if v.outputs_safe == Some(true) {
        out += "outputs held at their safe values: iobridge reacts to the e-stop\n";
    }
    out.trim_end().to_string()
}
