//! `supervisor run`: one program on one instance of the cell, start to clean exit.
//!
//! 1. Load and validate the configuration and the program (nothing starts on an error).
//! 2. Refuse an instance that is in use; clean dead nodes a killed run left behind.
//! 3. Create the services, publish the cell configuration, start every process.
//! 4. Wait until all are cyclic, trajgen publishes setpoints and the drives are enabled.
//! 5. Stream the program to trajgen (flow-controlled by its free queue places), watch every
//!    process' status and exit, trajgen's faults and servo's following error, record the trace.
//! 6. When the motion is done, wait until the axes settle in position.
//! 7. Stop every process (SIGTERM, then SIGKILL), drop our ports, check that no iceoryx2
//!    resource of the instance is left, and report.

use crate::config::Config;
use crate::events::{self, Axes};
use crate::launch::{Children, cpu_seconds};
use crate::report::{ProcessReport, Report, TraceRow};
use motion_program::{Op, Program};
use runtime::ipc::{self, Pub, Sub};
use runtime::rt::sched_of;
use runtime::signals;
use shm_schema::drive::servo_status as st;
use shm_schema::estop::{EstopKind, EstopState, HostStateV1};
use shm_schema::motion::trajgen_fault;
use shm_schema::{
    CellConfigV3, EstopOrigin, EstopV1, EventV1, FieldbusImageV1, InstanceName, LatencyHistogramV1,
    MAX_AXES, MotionCommandV1, MotionState, Power, ProcState, ProcessName, ProcessStatusV2,
    RequestKind, ServiceId, ServoRequestV1, ServoStateV2, SetpointV1, estop_seen, str_of,
};
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// What `supervisor run` was asked to do.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// The program file.
    pub program: PathBuf,
    /// The configuration file; `None` for the embedded default.
    pub config: Option<PathBuf>,
    /// Instance name.
    pub instance: String,
    /// Trace CSV to write.
    pub trace: Option<PathBuf>,
    /// Show progress on stderr.
    pub progress: bool,
}

/// Why a run failed.
#[derive(Debug)]
pub enum RunError {
    /// Bad input (program, configuration, instance): nothing was started. Exit code 2.
    Input(String),
    /// The run started and failed. Exit code 1.
    Failed {
        /// What went wrong.
        message: String,
        /// The events of the run up to the failure (`docs/events.md`).
        events: Vec<serde_json::Value>,
    },
    /// Ctrl-C / SIGTERM. Exit code 130.
    Interrupted,
}

impl RunError {
    /// A started run failed (its events are attached when the run ends).
    pub fn failed(message: impl Into<String>) -> Self {
        Self::Failed {
            message: message.into(),
            events: Vec::new(),
        }
    }

    /// The events the failed run recorded.
    pub fn events(&self) -> &[serde_json::Value] {
        match self {
            Self::Failed { events, .. } => events,
            _ => &[],
        }
    }
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Input(m) | RunError::Failed { message: m, .. } => f.write_str(m),
            RunError::Interrupted => f.write_str("interrupted; every process was stopped"),
        }
    }
}

pub(crate) const TICK: Duration = Duration::from_millis(10);

/// Runs a program; see the module documentation.
pub fn run(opts: &RunOptions) -> Result<Report, RunError> {
    let cfg = Config::load(opts.config.as_deref()).map_err(|e| RunError::Input(e.to_string()))?;
    let src = std::fs::read_to_string(&opts.program)
        .map_err(|e| RunError::Input(format!("{}: cannot read: {e}", opts.program.display())))?;
    let program = motion_program::parse(&src, cfg.axis.len())
        .and_then(|p| p.check_limits(&cfg.axis_specs()).map(|()| p))
        .map_err(|e| {
            RunError::Input(format!(
                "{}:{}:{}: {}",
                opts.program.display(),
                e.line,
                e.col,
                e.message
            ))
        })?;
    let instance = InstanceName::new(&opts.instance)
        .map_err(|e| RunError::Input(format!("--instance {:?}: {e}", opts.instance)))?;
    let mut session = open_cell(&cfg, instance, opts.progress)?;
    let outcome = session.drive(&cfg, &program, &src, opts);
    let cpu: Vec<Option<f64>> = session
        .children
        .iter()
        .map(|p| cpu_seconds(p.pid()))
        .collect();
    let pids: Vec<(usize, String, u32)> = session
        .children
        .iter()
        .map(|p| (p.index, p.name.clone(), p.pid()))
        .collect();
    let sched: Vec<Option<(u32, i32)>> = pids
        .iter()
        .map(|(_, _, pid)| sched_of(*pid as i32))
        .collect();
    session.refresh_latency();
    let stop_problems = session.stop_children();
    session.take_events();
    let statuses = std::mem::take(&mut session.statuses);
    let latencies = std::mem::take(&mut session.latencies);
    let exec_times = std::mem::take(&mut session.exec_times);
    let sense_to_command = session.sense_to_command.take();
    let events: Vec<serde_json::Value> = session
        .events
        .iter()
        .map(|e| events::to_json(e, &session.axes, session.t0_ns))
        .collect();
    drop(session);
    // A client (status, events, inject) may be finishing: give it a second to go.
    let leftovers = ipc::remove_instance_waiting(&instance, Duration::from_secs(1));

    let mut report = match outcome {
        Ok(r) => r,
        Err(RunError::Failed { message, .. }) => {
            return Err(RunError::Failed { message, events });
        }
        Err(e) => return Err(e),
    };
    report.events = events;
    report.sense_to_command = sense_to_command
        .as_deref()
        .filter(|h| h.count > 0)
        .map(latency::report::Summary::of);
    for (i, (index, name, pid)) in pids.iter().enumerate() {
        let status = statuses[*index].unwrap_or_default();
        let (policy, priority) = sched[i].unwrap_or((status.policy, status.priority));
        let mut p = ProcessReport::new(name, *pid, policy, priority, &status, cpu[i]);
        p.wakeup_latency = latencies[*index]
            .as_deref()
            .map(latency::report::Summary::of);
        p.exec_time = exec_times[*index]
            .as_deref()
            .filter(|h| h.count > 0)
            .map(latency::report::Summary::of);
        report.processes.push(p);
    }
    if let Some((name, why)) = stop_problems.first() {
        return Err(RunError::failed(format!("{name} {why}")));
    }
    if let Some(e) = leftover_error(&instance, &leftovers) {
        return Err(e);
    }
    if let Some(path) = &opts.trace {
        write_trace(path, &report)
            .map_err(|e| RunError::failed(format!("{}: {e}", path.display())))?;
    }
    Ok(report)
}

/// What is left of `instance` after its processes stopped is a failure, unless a client
/// (a tool of another shell: `status`, `events`, a foreign process) still holds it: then the
/// client's files are its own, and a warning names it (the next run of the instance, or the
/// client's own exit, removes them).
fn leftover_error(instance: &InstanceName, leftovers: &[String]) -> Option<RunError> {
    if leftovers.is_empty() {
        return None;
    }
    let clients = ipc::live_node_pids(instance).unwrap_or_default();
    if clients.is_empty() {
        return Some(RunError::failed(format!(
            "iceoryx2 resources left behind: {}",
            leftovers.join(", ")
        )));
    }
    tracing::warn!(
        "instance {instance}: {} iceoryx2 file(s) are still held by client process(es) {clients:?}; \
         they go when those clients exit or with the next run of the instance",
        leftovers.len()
    );
    None
}

/// Starts the cell of `cfg` on `instance`: signal handlers, a refusal if the instance is in
/// use, the services, the configuration, every process. Whatever a failure started is stopped
/// and removed.
pub(crate) fn open_cell(
    cfg: &Config,
    instance: InstanceName,
    print_events: bool,
) -> Result<Session, RunError> {
    signals::install()
        .map_err(|e| RunError::failed(format!("cannot install signal handlers: {e}")))?;
    ipc::quiet_iceoryx2_log();
    let _ = ipc::remove_dead_nodes(&instance);
    let live = ipc::live_node_pids(&instance).unwrap_or_default();
    if !live.is_empty() {
        return Err(RunError::Input(format!(
            "instance {instance} is in use by process(es) {live:?}; choose another --instance"
        )));
    }
    Session::open(cfg, instance, print_events).inspect_err(|_| {
        // Whatever was started is stopped (Children's drop); remove what it created.
        ipc::remove_instance(&instance);
    })
}

/// The supervisor's ports and the processes of one run.
pub(crate) struct Session {
    instance: InstanceName,
    pub(crate) children: Children,
    /// Per process of the table: its latest status, latency and execution-time histograms.
    statuses: Vec<Option<ProcessStatusV2>>,
    latencies: Vec<Option<Box<LatencyHistogramV1>>>,
    exec_times: Vec<Option<Box<LatencyHistogramV1>>>,
    /// Per process: the cycle count last seen and when it last advanced.
    beats: Vec<(u64, Instant)>,
    names: Vec<String>,
    /// The first e-stop trigger seen, and when.
    estop: Option<(EstopV1, Instant)>,
    host: HostStateV1,
    sense_to_command: Option<Box<LatencyHistogramV1>>,
    /// Every event of the run, in the order they arrived.
    events: Vec<EventV1>,
    axes: Axes,
    t0_ns: u64,
    print_events: bool,
    request_seq: u64,
    // Field order is drop order: ports before the node.
    config_pub: Pub<CellConfigV3>,
    pub(crate) command_pub: Pub<MotionCommandV1>,
    request_pub: Pub<ServoRequestV1>,
    events_sub: Sub<EventV1>,
    estop_sub: Sub<EstopV1>,
    host_pub: Pub<HostStateV1>,
    sense_sub: Sub<LatencyHistogramV1>,
    pub(crate) setpoint_sub: Sub<SetpointV1>,
    pub(crate) servo_sub: Sub<ServoStateV2>,
    image_sub: Sub<FieldbusImageV1>,
    status_subs: Vec<Sub<ProcessStatusV2>>,
    latency_subs: Vec<Sub<LatencyHistogramV1>>,
    exec_subs: Vec<Sub<LatencyHistogramV1>>,
    _node: iceoryx2::prelude::Node<ipc::Ipc>,
}

impl Session {
    /// Creates every service, publishes the configuration and starts the processes.
    fn open(cfg: &Config, instance: InstanceName, print_events: bool) -> Result<Self, RunError> {
        let f = |e: ipc::IpcError| RunError::failed(e.to_string());
        let node = ipc::node(&instance, "supervisor").map_err(f)?;
        let i = &instance;
        let config_pub = Pub::new(&node, i, ServiceId::CellConfig).map_err(f)?;
        let command_pub = Pub::new(&node, i, ServiceId::MotionCommand).map_err(f)?;
        let request_pub = Pub::new(&node, i, ServiceId::ServoRequest).map_err(f)?;
        let events_sub = Sub::new(&node, i, ServiceId::Events, 1024).map_err(f)?;
        let estop_sub = Sub::new(&node, i, ServiceId::Estop, 64).map_err(f)?;
        let host_pub = Pub::new(&node, i, ServiceId::HostState).map_err(f)?;
        let sense_sub = Sub::new(&node, i, ServiceId::SenseToCommand, 1).map_err(f)?;
        let setpoint_sub = Sub::new(&node, i, ServiceId::Setpoint, 1024).map_err(f)?;
        let servo_sub = Sub::new(&node, i, ServiceId::ServoState, 1024).map_err(f)?;
        let image_sub = Sub::new(&node, i, ServiceId::FieldbusOutput, 256).map_err(f)?;
        let mut status_subs = Vec::new();
        let mut latency_subs = Vec::new();
        let mut exec_subs = Vec::new();
        for p in &cfg.process {
            let name = ProcessName::new(&p.name).map_err(|e| RunError::Input(e.to_string()))?;
            exec_subs.push(Sub::new(&node, i, ServiceId::ExecTime(name), 1).map_err(f)?);
            status_subs.push(Sub::new(&node, i, ServiceId::Status(name), 64).map_err(f)?);
            latency_subs.push(Sub::new(&node, i, ServiceId::Latency(name), 1).map_err(f)?);
        }
        let cell = cfg.to_shm();
        config_pub.send(&cell);
        let host = HostStateV1 {
            stamp_ns: runtime::time::now_ns(),
            pid: std::process::id(),
            ..HostStateV1::default()
        };
        host_pub.send(&host);
        let mut children = Children::new(Duration::from_secs_f64(cfg.supervisor.stop_timeout));
        for (index, p) in cfg.process.iter().enumerate() {
            children
                .spawn(p, index, None, &instance)
                .map_err(RunError::failed)?;
        }
        let n = cfg.process.len();
        Ok(Self {
            instance,
            children,
            statuses: vec![None; n],
            latencies: vec![None; n],
            exec_times: vec![None; n],
            beats: vec![(0, Instant::now()); n],
            names: cfg.process.iter().map(|p| p.name.clone()).collect(),
            estop: None,
            host,
            sense_to_command: None,
            events: Vec::new(),
            axes: Axes::of_cell(&cell),
            t0_ns: runtime::time::now_ns(),
            print_events,
            request_seq: 0,
            config_pub,
            command_pub,
            request_pub,
            events_sub,
            estop_sub,
            host_pub,
            sense_sub,
            setpoint_sub,
            servo_sub,
            image_sub,
            status_subs,
            latency_subs,
            exec_subs,
            _node: node,
        })
    }

    /// Takes the newest latency histogram of every process (they publish about every 100 ms)
    /// and the drives' sense-to-command histogram.
    fn refresh_latency(&mut self) {
        for (k, sub) in self.latency_subs.iter().enumerate() {
            if let Some(h) = sub.latest() {
                self.latencies[k] = Some(Box::new(h));
            }
        }
        for (k, sub) in self.exec_subs.iter().enumerate() {
            if let Some(h) = sub.latest() {
                self.exec_times[k] = Some(Box::new(h));
            }
        }
        if let Some(h) = self.sense_sub.latest() {
            self.sense_to_command = Some(Box::new(h));
        }
    }

    /// Stops every process and removes the instance; fails if a process would not stop or
    /// something of the instance is left. Returns the run's events as JSON.
    pub(crate) fn close(mut self) -> Result<Vec<serde_json::Value>, RunError> {
        let stop_problems = self.stop_children();
        self.take_events();
        let events = self
            .events
            .iter()
            .map(|e| events::to_json(e, &self.axes, self.t0_ns))
            .collect();
        let instance = self.instance;
        drop(self);
        let leftovers = ipc::remove_instance_waiting(&instance, Duration::from_secs(1));
        if let Some((name, why)) = stop_problems.first() {
            return Err(RunError::failed(format!("{name} {why}")));
        }
        match leftover_error(&instance, &leftovers) {
            Some(e) => Err(e),
            None => Ok(events),
        }
    }

    /// Takes the events that arrived, printing them as they happen.
    pub(crate) fn take_events(&mut self) {
        while let Some(e) = self.events_sub.next() {
            if self.print_events {
                eprintln!("{}", events::line(&e, &self.axes, self.t0_ns));
            }
            self.events.push(e);
        }
    }

    /// Asks servo for `kind` (it takes effect in servo's next cycle).
    pub(crate) fn request(&mut self, kind: RequestKind) -> Result<(), RunError> {
        self.request_with(kind, 0, 0.0)
    }

    /// Asks servo for `kind` with an axis and a value (a tuning step).
    pub(crate) fn request_with(
        &mut self,
        kind: RequestKind,
        axis: u32,
        value: f64,
    ) -> Result<(), RunError> {
        self.request_seq += 1;
        let r = ServoRequestV1 {
            seq: self.request_seq,
            kind: kind as u32,
            axis,
            value,
        };
        if self.request_pub.send(&r) {
            Ok(())
        } else {
            Err(RunError::failed(
                "servo's request service refused a request",
            ))
        }
    }

    /// The latched fault servo reports, in words, with the event that explains it.
    pub(crate) fn fault_text(&self, s: &ServoStateV2) -> String {
        let cause = self.events.iter().rev().find(|e| e.code == s.fault_code);
        self.servo_cut_text(s.fault_code, s.fault_axis, cause)
    }

    /// "servo cut power: <cause> on axis <a>", and the event that explains it.
    fn servo_cut_text(&self, code: u32, axis: i32, cause: Option<&EventV1>) -> String {
        let name = shm_schema::event::info(code).map_or("unknown fault", |i| i.name);
        let axis = usize::try_from(axis)
            .ok()
            .and_then(|i| self.axes.axes.get(i))
            .map_or(String::new(), |(a, _)| format!(" on axis {a}"));
        let line = cause.map_or(String::new(), |ev| {
            format!("\n  {}", events::line(ev, &self.axes, self.t0_ns))
        });
        format!("servo cut power: {name}{axis}{line}")
    }

    /// Stops every process (the heartbeat goes on meanwhile, so none of them takes the
    /// supervisor for lost); returns those that did not stop cleanly.
    pub(crate) fn stop_children(&mut self) -> Vec<(String, String)> {
        let mut children = std::mem::take(&mut self.children);
        let mut last = Instant::now();
        let problems = children.stop_all(&mut || {
            if last.elapsed() >= TICK {
                last = Instant::now();
                self.beat();
            }
        });
        self.children = children;
        problems
    }

    /// The heartbeat: the host state with the latched e-stop, every tick.
    pub(crate) fn beat(&mut self) {
        self.host.beat += 1;
        self.host.stamp_ns = runtime::time::now_ns();
        self.host_pub.send(&self.host);
    }

    /// Waits (beating) until every process that reacts to the e-stop reports its reaction
    /// complete (servo: axes at rest, drives disabled), at most the e-stop stop time and a
    /// second, so that the run stops a cell at rest and reports how long that took.
    fn await_estop_reactions(&mut self, cfg: &Config) {
        let limit = Duration::from_secs_f64(cfg.motion.estop_stop_time + 1.0);
        let start = Instant::now();
        while start.elapsed() < limit {
            self.beat();
            self.take_events();
            for (k, sub) in self.status_subs.iter().enumerate() {
                if let Some(s) = sub.latest() {
                    self.statuses[k] = Some(s);
                }
            }
            let pending =
                self.statuses.iter().flatten().any(|s| {
                    s.estop & estop_seen::REACTING != 0 && s.estop & estop_seen::SAFE == 0
                });
            if !pending {
                break;
            }
            std::thread::sleep(TICK);
        }
        self.take_events();
    }

    /// True for servo's own device e-stop: a latched fault, which servo's state explains.
    fn is_servo_fault(&self, e: &EstopV1) -> bool {
        e.origin == EstopOrigin::Device as u32
            && self
                .names
                .get(e.source as usize)
                .is_some_and(|n| n == "servo")
    }

    /// The e-stop that stopped the run, in words (servo's own fault as "servo cut power").
    pub(crate) fn estop_text(&self) -> Option<String> {
        let (e, _) = self.estop?;
        let cause = self
            .events
            .iter()
            .rev()
            .find(|ev| ev.code == e.code && ev.source == e.source);
        if self.is_servo_fault(&e) {
            let axis = cause.map_or(-1, |ev| ev.axis);
            return Some(self.servo_cut_text(e.code, axis, cause));
        }
        let line = cause.map_or(String::new(), |ev| {
            format!("\n  {}", events::line(ev, &self.axes, self.t0_ns))
        });
        let origin = EstopOrigin::from_u32(e.origin).map_or("?", EstopOrigin::name);
        Some(format!(
            "e-stop ({origin}) raised by {}: {}{line}",
            self.axes.source_name(e.source),
            str_of(&e.reason),
        ))
    }

    /// Fails if a process exited or stopped cycling, or the e-stop was raised (unless servo's
    /// own latched fault explains it: the caller reports that); refreshes the statuses and
    /// beats.
    pub(crate) fn check_health(&mut self, cfg: &Config) -> Result<(), RunError> {
        if signals::stop_requested() {
            return Err(RunError::Interrupted);
        }
        self.beat();
        if let Some((p, status)) = self.children.exited() {
            return Err(RunError::failed(format!(
                "{} (pid {}) exited unexpectedly: {status}",
                p.name,
                p.pid()
            )));
        }
        self.config_pub.update_connections();
        self.host_pub.update_connections();
        self.take_events();
        while let Some(e) = self.estop_sub.next() {
            if e.kind == EstopKind::Trigger as u32 && self.estop.is_none() {
                self.estop = Some((e, Instant::now()));
                self.host.estop = EstopState::Latched as u32;
                self.host.cause = e;
            }
        }
        for (k, sub) in self.status_subs.iter().enumerate() {
            if let Some(s) = sub.latest() {
                if ProcState::from_u32(s.state) == Some(ProcState::Fault) {
                    return Err(RunError::failed(format!(
                        "{} reports fault {}",
                        self.names[k], s.fault
                    )));
                }
                let b = &mut self.beats[k];
                if s.stats.cycles != b.0 {
                    *b = (s.stats.cycles, Instant::now());
                }
                self.statuses[k] = Some(s);
            }
        }
        let timeout = Duration::from_secs_f64(cfg.supervisor.heartbeat_timeout);
        for (k, (cycles, at)) in self.beats.iter().enumerate() {
            if *cycles > 0 && at.elapsed() > timeout {
                return Err(RunError::failed(format!(
                    "{} stopped cycling: its status has not advanced for {:.2} s",
                    self.names[k],
                    at.elapsed().as_secs_f64()
                )));
            }
        }
        // An e-stop ends the run once it stops the motion: servo or trajgen reacts to it
        // (servo's own fault is reported by the caller with its cause, unless its state does
        // not explain it within a few ticks). One that no process of the motion reacts to
        // (the cell's propagation rules) lets the motion finish; the run fails at its end.
        if let Some((e, at)) = self.estop {
            let reacting = |name: &str| {
                self.names.iter().position(|n| n == name).is_some_and(|k| {
                    self.statuses[k].is_some_and(|s| s.estop & estop_seen::REACTING != 0)
                })
            };
            let from_servo = self.is_servo_fault(&e);
            let stops_motion = reacting("trajgen") || (reacting("servo") && !from_servo);
            if stops_motion || (from_servo && at.elapsed() > 20 * TICK) {
                self.await_estop_reactions(cfg);
                return Err(RunError::failed(
                    self.estop_text().unwrap_or_else(|| "e-stop".into()),
                ));
            }
        }
        Ok(())
    }

    /// Startup: every process cyclic, trajgen publishing, the drives initialized; then an
    /// enable request, and a setpoint from after the arm is enabled (trajgen starts where
    /// servo holds). Returns that setpoint.
    pub(crate) fn startup(&mut self, cfg: &Config) -> Result<SetpointV1, RunError> {
        let start = Instant::now();
        let startup = Duration::from_secs_f64(cfg.supervisor.startup_timeout);
        let (mut last_sp, mut last_servo) = (None::<SetpointV1>, None::<ServoStateV2>);
        let mut enable_sent = false;
        let mut enabled_at: Option<u64> = None;
        loop {
            self.check_health(cfg)?;
            if let Some(s) = self.setpoint_sub.latest() {
                last_sp = Some(s);
            }
            if let Some(s) = self.servo_sub.latest() {
                last_servo = Some(s);
            }
            if let Some(s) = last_servo
                && s.status & st::FAULT_LATCHED != 0
            {
                self.take_events();
                return Err(RunError::failed(self.fault_text(&s)));
            }
            let statuses = self.statuses.clone();
            let cyclic = |k: usize| {
                statuses[k]
                    .is_some_and(|s| s.state == ProcState::Cyclic as u32 && s.stats.cycles > 0)
            };
            let initialized = last_servo.is_some_and(|s| s.status & st::INITIALIZED != 0);
            let all_cyclic = (0..self.names.len()).all(cyclic);
            if all_cyclic && initialized && last_sp.is_some() && !enable_sent {
                self.request(RequestKind::Enable)?;
                enable_sent = true;
            }
            if let Some(s) = last_servo.filter(|s| s.status & st::ENABLED != 0) {
                enabled_at.get_or_insert(s.stamp_ns);
            }
            if let (Some(t), Some(sp)) = (enabled_at, last_sp)
                && sp.stamp_ns > t
            {
                break;
            }
            if start.elapsed() > startup {
                let mut missing: Vec<String> = (0..self.names.len())
                    .filter(|k| !cyclic(*k))
                    .map(|k| format!("{} is not cyclic", self.names[k]))
                    .collect();
                if last_sp.is_none() {
                    missing.push("trajgen publishes no setpoint".into());
                }
                if !initialized {
                    missing.push("the drives did not initialize".into());
                }
                if enabled_at.is_none() {
                    missing.push("the arm is not enabled".into());
                }
                return Err(RunError::failed(format!(
                    "startup did not complete within {:.1} s: {}",
                    startup.as_secs_f64(),
                    missing.join(", ")
                )));
            }
            std::thread::sleep(TICK);
        }
        Ok(last_sp.expect("checked above"))
    }

    fn drive(
        &mut self,
        cfg: &Config,
        program: &Program,
        src: &str,
        opts: &RunOptions,
    ) -> Result<Report, RunError> {
        let n = cfg.axis.len();
        let start_sp = self.startup(cfg)?;
        let start_pos: Vec<f64> = start_sp.position[..n].to_vec();
        let vmax: Vec<f64> = cfg.axis.iter().map(|a| a.vmax).collect();
        let predicted =
            motion_program::theoretical_time(program, &start_pos, &vmax, cfg.motion.t_acc);

        // Motion.
        let program_id = (std::process::id() ^ (start_sp.seq as u32).rotate_left(16)) | 1;
        let commands = program.to_commands(program_id, 1);
        let mut sent = 0usize;
        let mut rows: Vec<SetpointV1> = Vec::new();
        let mut servo_log: Vec<ServoStateV2> = Vec::new();
        let mut images = (0u64, 0u64, 0u64); // count, sum of delays, max delay (ns)
        let mut done: Option<SetpointV1> = None;
        let mut settled_at: Option<(u64, ServoStateV2)> = None;
        let mut in_pos_since: Option<u64> = None;
        let mut progress = Progress::new(opts.progress, predicted, src);
        let settle_ns = (cfg.motion.settle_time * 1e9) as u64;
        let mut done_at = None::<Instant>;
        let last_target = program.instructions.iter().rev().find_map(|i| match i.op {
            Op::Move { target, .. } => Some(target),
            _ => None,
        });

        while settled_at.is_none() {
            self.check_health(cfg)?;
            // Setpoints of our motion.
            let mut newest = None;
            while let Some(sp) = self.setpoint_sub.next() {
                newest = Some(sp);
                if sp.program_id != program_id {
                    continue;
                }
                if sp.fault == trajgen_fault::ESTOP {
                    // The e-stop's own report (servo's fault, or the trigger) says why.
                    continue;
                }
                if sp.fault != trajgen_fault::NONE || sp.state == MotionState::Fault as u32 {
                    return Err(RunError::failed(trajgen_fault_text(&sp, &opts.program)));
                }
                match MotionState::from_u32(sp.state) {
                    Some(MotionState::Moving) => rows.push(sp),
                    Some(MotionState::Done) if done.is_none() => {
                        rows.push(sp);
                        done = Some(sp);
                        done_at = Some(Instant::now());
                    }
                    _ => {}
                }
            }
            // Flow control: never more in flight than trajgen has free places.
            if let Some(sp) = newest {
                let in_flight = sent as u64 - sp.commands_taken.min(sent as u64);
                let credit = (sp.queue_free as u64).saturating_sub(in_flight) as usize;
                for c in commands.iter().skip(sent).take(credit) {
                    if !self.command_pub.send(c) {
                        return Err(RunError::failed(
                            "trajgen's command service refused a command",
                        ));
                    }
                    sent += 1;
                }
                progress.show(&sp);
            }
            // Servo: following error, drive faults, settling.
            while let Some(s) = self.servo_sub.next() {
                if rows.is_empty() {
                    continue;
                }
                if s.status & st::FAULT_LATCHED != 0 {
                    self.take_events();
                    return Err(RunError::failed(self.fault_text(&s)));
                }
                if s.power != Power::Enabled as u8 {
                    self.take_events();
                    return Err(RunError::failed(format!(
                        "the arm is no longer enabled (servo power {}): a disable request from \
                         another client stopped the run",
                        Power::from_u8(s.power).map_or("?", Power::name)
                    )));
                }
                if s.status & st::SETPOINT_JUMP != 0 {
                    self.take_events();
                    return Err(RunError::failed(
                        "servo refused a setpoint as a jump (see the setpoint-jump event)",
                    ));
                }
                servo_log.push(s);
                if let Some(d) = &done {
                    let inside = (0..n).all(|i| {
                        s.following_error[i].abs() <= cfg.axis[i].in_position
                            && s.act_velocity[i].abs() <= cfg.axis[i].settle_velocity()
                    });
                    let used_final = s.setpoint_seq >= d.seq;
                    match (inside && used_final, in_pos_since) {
                        (true, None) => in_pos_since = Some(s.stamp_ns),
                        (true, Some(t0)) if s.stamp_ns - t0 >= settle_ns => {
                            settled_at = Some((t0, s))
                        }
                        (false, _) => in_pos_since = None,
                        _ => {}
                    }
                }
            }
            while let Some(img) = self.image_sub.next() {
                if !rows.is_empty() {
                    let d = img.written_ns.saturating_sub(img.measured_ns);
                    images = (images.0 + 1, images.1 + d, images.2.max(d));
                }
            }
            if let Some(t) = done_at
                && t.elapsed().as_secs_f64() > cfg.motion.settle_timeout
            {
                let s = servo_log.last().copied();
                let errs = s.map_or(String::new(), |s| {
                    (0..n)
                        .map(|i| {
                            format!(
                                "{} {:.4} {}",
                                cfg.axis[i].name, s.following_error[i], cfg.axis[i].unit
                            )
                        })
                        .collect::<Vec<_>>()
                        .join(", ")
                });
                return Err(RunError::failed(format!(
                    "the axes did not settle within {} s of the end of the motion (following error {errs})",
                    cfg.motion.settle_timeout
                )));
            }
            if settled_at.is_none() {
                std::thread::sleep(TICK);
            }
        }
        progress.finish();
        if let Some(text) = self.estop_text() {
            self.take_events();
            return Err(RunError::failed(format!(
                "{text}\n  the motion completed: by this cell's propagation rules (`[behaviour]`) \
                 neither servo nor trajgen reacts to it, but it stays latched"
            )));
        }

        let done = done.expect("settling needs done");
        let (settle_start, final_state) = settled_at.expect("loop exit");
        let motion_servo: Vec<&ServoStateV2> = servo_log
            .iter()
            .filter(|s| s.stamp_ns <= final_state.stamp_ns)
            .collect();
        let mut max_fe = [0.0f64; MAX_AXES];
        for s in &motion_servo {
            for (m, e) in max_fe.iter_mut().zip(&s.following_error[..n]) {
                *m = m.max(e.abs());
            }
        }
        let trace = trace_rows(&rows, &servo_log);
        let lost = lost_setpoints(&rows);
        Ok(Report {
            ok: true,
            program: opts.program.display().to_string(),
            instance: self.instance.to_string(),
            cell: cfg.cell.name.clone(),
            axes: cfg.axis.iter().map(|a| a.name.clone()).collect(),
            units: cfg.axis.iter().map(|a| a.unit.clone()).collect(),
            vmax,
            t_acc: cfg.motion.t_acc,
            start: start_pos,
            periods_us: cfg
                .process
                .iter()
                .map(|p| (p.name.clone(), p.period_us))
                .collect(),
            theoretical_s: done.theoretical_s,
            predicted_s: predicted,
            measured_s: (done.motion_end_ns - done.motion_start_ns) as f64 * 1e-9,
            trajgen_period_s: cfg.period_s("trajgen"),
            settle_s: settle_start.saturating_sub(done.motion_end_ns) as f64 * 1e-9,
            final_position: final_state.act_position[..n].to_vec(),
            final_error: last_target.map_or(vec![0.0; n], |t| {
                (0..n).map(|i| final_state.act_position[i] - t[i]).collect()
            }),
            max_following_error: max_fe[..n].to_vec(),
            setpoints: rows.len(),
            lost_setpoints: lost,
            starved: done.starved,
            iobridge_delay_us: if images.0 > 0 {
                Some((
                    images.1 as f64 / images.0 as f64 * 1e-3,
                    images.2 as f64 * 1e-3,
                ))
            } else {
                None
            },
            processes: Vec::new(),
            trace,
            events: Vec::new(),
            sense_to_command: None,
        })
    }
}

fn trajgen_fault_text(sp: &SetpointV1, program: &std::path::Path) -> String {
    let why = trajgen_fault::text(sp.fault);
    format!(
        "trajgen refused {}:{}: {why} (fault {}); the axes stopped",
        program.display(),
        sp.fault_line,
        sp.fault
    )
}

/// One row per setpoint: its command, and the measured position at the servo cycle that used
/// it (the first servo cycle whose setpoint is this one or a later one).
fn trace_rows(rows: &[SetpointV1], servo: &[ServoStateV2]) -> Vec<TraceRow> {
    rows.iter()
        .map(|sp| {
            let idx = servo.partition_point(|s| s.setpoint_seq < sp.seq);
            let act = servo
                .get(idx)
                .or(servo.last())
                .map_or(sp.position, |s| s.act_position);
            TraceRow {
                t_s: sp.motion_time_s,
                cmd: sp.position,
                act,
            }
        })
        .collect()
}

fn lost_setpoints(rows: &[SetpointV1]) -> u64 {
    rows.windows(2)
        .map(|w| w[1].seq.saturating_sub(w[0].seq + 1))
        .sum()
}

fn write_trace(path: &std::path::Path, report: &Report) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    let n = report.axes.len();
    let mut header = vec!["t_s".to_string()];
    header.extend(report.axes.iter().map(|a| format!("cmd_{a}")));
    header.extend(report.axes.iter().map(|a| format!("act_{a}")));
    writeln!(out, "{}", header.join(","))?;
    for r in &report.trace {
        write!(out, "{:.6}", r.t_s)?;
        for v in &r.cmd[..n] {
            write!(out, ",{v:.6}")?;
        }
        for v in &r.act[..n] {
            write!(out, ",{v:.6}")?;
        }
        writeln!(out)?;
    }
    out.flush()
}

/// Progress on stderr: motion time against the total and the current program line.
struct Progress<'a> {
    on: bool,
    tty: bool,
    total: f64,
    lines: Vec<&'a str>,
    last: Option<Instant>,
}

impl<'a> Progress<'a> {
    fn new(on: bool, total: f64, src: &'a str) -> Self {
        Self {
            on,
            tty: std::io::stderr().is_terminal(),
            total,
            lines: src.lines().collect(),
            last: None,
        }
    }

    fn show(&mut self, sp: &SetpointV1) {
        let every = if self.tty { 0.2 } else { 1.0 };
        if !self.on
            || sp.state != MotionState::Moving as u32
            || self.last.is_some_and(|t| t.elapsed().as_secs_f64() < every)
        {
            return;
        }
        self.last = Some(Instant::now());
        let text = self
            .lines
            .get(sp.line.saturating_sub(1) as usize)
            .map_or("", |l| l.split("//").next().unwrap_or("").trim());
        let msg = format!(
            "motion {:6.2} / {:.2} s   line {}: {}",
            sp.motion_time_s, self.total, sp.line, text
        );
        if self.tty {
            eprint!("\r\x1b[2K{msg}");
        } else {
            eprintln!("{msg}");
        }
    }

    fn finish(&self) {
        if self.on && self.tty && self.last.is_some() {
            eprintln!();
        }
    }
}
