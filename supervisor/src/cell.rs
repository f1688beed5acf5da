//! The long-lived cell: the supervisor's ports, the processes of the table and what the
//! supervisor knows of each, the latched e-stop and the heartbeat.
//!
//! [`Cell::tick`] runs every supervisor tick (10 ms, or at once when a child exits): it beats,
//! notices a dead child (its pidfd) or a stalled one (its cycle count), raises the host
//! e-stop for it and restarts it per its policy, and latches the e-stops it sees. It never
//! ends the cell: what a job makes of an incident is the job's business ([`crate::job`]).

use crate::error::RunError;
use crate::launch::Children;
use cell_config::{Config, RestartPolicy};
use control_plane::Failure;
use control_plane::channel as ctl;
use control_plane::compose::{Seen, Snapshot};
use control_plane::event::{self as events, Axes};
use control_plane::info::{self, Info};
use runtime::stall::StallWatch;

/// A heartbeat gap this long (s) is reported, whatever room `supervisor_timeout` gives: the
/// processes' own timing suffers from such a stall (a following error of vmax times it).
const STALL_REPORTED_S: f64 = 0.1;
use control_plane::event::Event;
use runtime::ipc::{self, Pub, Sub};
use runtime::signals;
use runtime::time::Moment;
use shm_schema::drive::servo_status as st;
use shm_schema::estop::{EstopKind, EstopState, HostStateV1};
use shm_schema::event::{SOURCE_SUPERVISOR, code};
use shm_schema::{
    CellConfigV6, ControlKind, DigitalIoV1, EstopOrigin, EstopV1, EventV1, FieldbusImageV1,
    InstanceName, LatencyHistogramV1, MotionCommandV2, MotionControlV2, ProcState, ProcessName,
    ProcessStatusV2, RequestKind, ServiceId, ServoRequestV1, ServoStateV3, SetpointV2,
    TrajgenHandoverV2, estop_seen, str_of,
};
use std::time::Duration;

/// How the cell is run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// `supervisor run`: one program; any incident ends it. Events print on stderr.
    Run,
    /// `supervisor up`: until `down`; lost processes restart per their policy.
    Up,
}

/// Something that happened to a process of the cell in a tick.
#[derive(Clone, Debug, PartialEq)]
pub enum Incident {
    /// It exited.
    Exited {
        /// Its name.
        name: String,
        /// Its pid.
        pid: u32,
        /// Its exit status, in words.
        status: String,
        /// It exited with code 2: it refused its arguments or what it found against the
        /// configuration (the bus' line), and said why in its log.
        refused: bool,
    },
    /// Its cycle count stopped advancing for `heartbeat_timeout`.
    Stalled {
        /// Its name.
        name: String,
        /// For how long (s).
        for_s: f64,
    },
    /// It reported the fault state.
    Fault {
        /// Its name.
        name: String,
        /// Its fault code.
        fault: u32,
    },
}

impl Incident {
    /// The error that ends a job: a refused configuration is the user's input (exit 2).
    pub(crate) fn error(&self) -> RunError {
        match self {
            Incident::Exited { refused: true, .. } => RunError::Input(self.to_string()),
            Incident::Exited {
                name, pid, status, ..
            } => RunError::failed(Failure::Exited {
                process: name.clone(),
                pid: *pid,
                status: status.clone(),
            }),
            Incident::Stalled { name, for_s } => RunError::failed(Failure::Stalled {
                process: name.clone(),
                for_s: *for_s,
            }),
            Incident::Fault { name, fault } => RunError::failed(Failure::ProcessFault {
                process: name.clone(),
                fault: *fault,
            }),
        }
    }
}

impl std::fmt::Display for Incident {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Incident::Exited {
                name,
                pid,
                status,
                refused: false,
            } => write!(f, "{name} (pid {pid}) exited unexpectedly: {status}"),
            Incident::Exited {
                name,
                pid,
                refused: true,
                ..
            } => write!(
                f,
                "{name} (pid {pid}) refused the configuration (exit code 2; its log above says why)"
            ),
            Incident::Stalled { name, for_s } => write!(
                f,
                "{name} stopped cycling: its status has not advanced for {for_s:.2} s"
            ),
            Incident::Fault { name, fault } => write!(f, "{name} reports fault {fault}"),
        }
    }
}

/// Where a process of the table stands, as the supervisor sees it.
#[derive(Clone, Debug, PartialEq)]
pub enum Life {
    /// Started; cyclic once its status says so.
    Running,
    /// Lost; starts again at the instant (its restart policy).
    Restarting(Moment),
    /// Lost for good (policy `never`, or the restart limit); the reason.
    Down(String),
}

/// The supervisor's tick: its loop runs at least this often (at once when a child exits or
/// a client connects), and so does its heartbeat.
pub(crate) const TICK: std::time::Duration = std::time::Duration::from_millis(10);

/// How long (wall time) a process on the virtual clock may take to finish a granted cycle
/// before the clock leaves it out (the supervisor then finds it stalled); to join it, at least
/// `runtime::vclock::START_PATIENCE`.
const CLOCK_WATCHDOG: Duration = Duration::from_secs(10);

/// How often (wall time) the heartbeat goes while the virtual clock stands.
const STANDING_BEAT: Duration = Duration::from_secs(1);

/// The virtual time that passes per look while the supervisor waits for processes to leave.
const LEAVE_STEP: Duration = Duration::from_millis(5);

/// What closing a cell left: its events as JSON, and why the close failed (a process that
/// would not stop, resources left behind), if it did.
pub(crate) struct Closed {
    pub(crate) events: Vec<Event>,
    pub(crate) problem: Option<RunError>,
}

/// [`open_cell`] with a recording of the cell into `record` when one is asked for: the
/// recorder starts before the processes, and a recorder that cannot start closes the cell
/// again.
pub(crate) fn open_recorded(
    cfg: &Config,
    instance: InstanceName,
    mode: Mode,
    record: Option<&std::path::Path>,
) -> Result<(Cell, ctl::Server, Option<recorder::Background>), RunError> {
    open_cell(cfg, instance, mode, record)
}

/// Starts the cell of `cfg` on `instance`: takes the instance's control channel (refused if
/// another supervisor serves it), waits for the processes a killed supervisor left to leave,
/// removes what is left of the instance, creates the services, publishes the configuration,
/// starts every process. Whatever a failure started is stopped and removed.
pub(crate) fn open_cell(
    cfg: &Config,
    instance: InstanceName,
    mode: Mode,
    record: Option<&std::path::Path>,
) -> Result<(Cell, ctl::Server, Option<recorder::Background>), RunError> {
    signals::install()
        .map_err(|e| RunError::system(format!("cannot install signal handlers: {e}")))?;
    ipc::quiet_iceoryx2_log();
    let server = ctl::Server::bind(&instance).map_err(|e| {
        if e.kind() == std::io::ErrorKind::AddrInUse {
            RunError::Input(format!(
                "instance {instance} is in use: another supervisor serves it \
                 (`supervisor status --instance {instance}`; `supervisor down --instance {instance}` stops it)"
            ))
        } else {
            RunError::system(format!("instance {instance}: control channel: {e}"))
        }
    })?;
    // We hold the instance now: no other supervisor creates or removes anything of it.
    await_orphans(cfg, &instance)?;
    let removed = if ipc::live_node_pids(&instance)
        .unwrap_or_default()
        .is_empty()
    {
        // Nothing of the instance is alive: whatever is left (a half-created service, a
        // half-created or half-removed node of a supervisor killed while starting) goes, as
        // files, before any iceoryx2 call walks structures a killed process left half made.
        ipc::purge_instance(&instance)
    } else {
        // Observers are attached: only what can belong to no one goes.
        let _ = ipc::remove_dead_nodes(&instance);
        ipc::remove_unfinished_services(&instance, Duration::from_secs(1))
    };
    if !removed.is_empty() {
        tracing::warn!(
            "instance {instance}: removed {} iceoryx2 file(s) that processes killed part-way left",
            removed.len()
        );
        tracing::debug!("removed: {}", removed.join(", "));
    }
    let (cell, recorder) = Cell::open(cfg, instance, mode, record).inspect_err(|_| {
        ipc::remove_instance(&instance);
    })?;
    Ok((cell, server, recorder))
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
        return Some(RunError::system(format!(
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

/// Waits for the processes of a previous supervisor of the instance (killed: its processes
/// bring the axes to rest and leave once its heartbeat stops) to go. Observers (a status, a
/// recorder, a foreign tool) are welcome and not waited for.
fn await_orphans(cfg: &Config, instance: &InstanceName) -> Result<(), RunError> {
    let ours = |name: &str| name == "supervisor" || cfg.process.iter().any(|p| p.name == name);
    let patience = Duration::from_secs_f64(
        cfg.supervisor.supervisor_timeout
            + cfg.motion.estop_stop_time
            + cfg.supervisor.stop_timeout
            + 1.0,
    );
    let start = Moment::now();
    loop {
        let orphans: Vec<(u32, String)> = ipc::live_nodes(instance)
            .unwrap_or_default()
            .into_iter()
            .filter(|(_, n)| ours(n))
            .collect();
        if orphans.is_empty() {
            return Ok(());
        }
        if start.elapsed() > patience {
            let list: Vec<String> = orphans
                .iter()
                .map(|(pid, n)| format!("{n} (pid {pid})"))
                .collect();
            return Err(RunError::Input(format!(
                "instance {instance} is in use by {} that did not leave within {:.1} s; \
                 stop them or choose another --instance",
                list.join(", "),
                patience.as_secs_f64()
            )));
        }
        std::thread::sleep(TICK);
    }
}

/// How long a process that is not critical must run after a restart for its restart count
/// to start again from 0.
const STABLE: Duration = Duration::from_secs(60);

/// One process of the table, as the supervisor keeps it.
pub(crate) struct Proc {
    pub(crate) name: String,
    /// Whether the cell's safety depends on it (`critical`). A process that is not critical
    /// is restarted on a loss without an e-stop and never ends a job.
    critical: bool,
    /// Its latest status, latency and execution-time histograms.
    pub(crate) status: Option<ProcessStatusV2>,
    pub(crate) latency: Option<Box<LatencyHistogramV1>>,
    pub(crate) exec_time: Option<Box<LatencyHistogramV1>>,
    /// The cycle count last seen and when it last advanced.
    beat: (u64, Moment),
    pub(crate) life: Life,
    pub(crate) restarts: u32,
    /// Restarts since the operator last reset the e-stop (the limit's count).
    streak: u32,
    /// The pid whose statuses are ignored (the old one, during a swap).
    ignore_pid: Option<u32>,
    /// The command it runs now (`swap --command`), `None` for the configured.
    command: Option<Vec<String>>,
    /// An incident (stall, fault) already reported for its current life.
    flagged: bool,
    /// The network address it announced it serves on (`listening` events).
    pub(crate) listening: Option<String>,
    /// Why it cannot listen (the last `listen-failed` event's text), until it does.
    pub(crate) listen_failed: Option<String>,
    /// When it was last started.
    started: Moment,
    status_sub: Sub<ProcessStatusV2>,
    latency_sub: Sub<LatencyHistogramV1>,
    exec_sub: Sub<LatencyHistogramV1>,
}

/// The supervisor's ports and the processes of the cell.
pub(crate) struct Cell {
    pub(crate) instance: InstanceName,
    pub(crate) mode: Mode,
    pub(crate) children: Children,
    /// The first e-stop trigger since the last reset, and when it was seen.
    pub(crate) estop: Option<(EstopV1, Moment)>,
    host: HostStateV1,
    pub(crate) sense_to_command: Option<Box<LatencyHistogramV1>>,
    /// Every event since the cell came up (run) or since the current job began (up).
    pub(crate) events: Vec<EventV1>,
    /// How many times servo said `disabled` (every axis without power).
    pub(crate) disabled_said: u64,
    pub(crate) axes: Axes,
    pub(crate) t0_ns: u64,
    pub(crate) last_sp: Option<SetpointV2>,
    pub(crate) last_servo: Option<ServoStateV3>,
    /// iobridge's newest image of the named IO (for `status`).
    io: Option<DigitalIoV1>,
    /// The configuration as published (for `status`: names, units, the IO table).
    shm: Box<CellConfigV6>,
    request_seq: u64,
    control_seq: u64,
    event_seq: u64,
    // Field order is drop order: ports before the node.
    config_pub: Pub<CellConfigV6>,
    /// `[ethercat]`, for the bus process (history 1), when the cell has a bus.
    ethercat_pub: Option<Pub<shm_schema::EthercatConfigV1>>,
    pub(crate) command_pub: Pub<MotionCommandV2>,
    control_pub: Pub<MotionControlV2>,
    request_pub: Pub<ServoRequestV1>,
    events_sub: Sub<EventV1>,
    events_pub: Pub<EventV1>,
    estop_sub: Sub<EstopV1>,
    estop_pub: Pub<EstopV1>,
    host_pub: Pub<HostStateV1>,
    sense_sub: Sub<LatencyHistogramV1>,
    pub(crate) setpoint_sub: Sub<SetpointV2>,
    pub(crate) servo_sub: Sub<ServoStateV3>,
    pub(crate) image_sub: Sub<FieldbusImageV1>,
    /// While a swap measures the fieldbus image's gaps: every image read is seen by it.
    pub(crate) image_gaps: Option<GapMeter>,
    pub(crate) handover_sub: Sub<TrajgenHandoverV2>,
    /// The supervisor hands a paused motion to a new trajgen (the old one's publisher, and
    /// its history, die with it).
    handover_pub: Pub<TrajgenHandoverV2>,
    io_sub: Sub<DigitalIoV1>,
    /// Gaps between heartbeats, and where they went.
    stalls: StallWatch,
    /// When (wall time) the last heartbeat was published.
    beaten: std::time::Instant,
    /// The process table, in its order: what the supervisor keeps of each process, its
    /// ports among it (before the node: field order is drop order).
    pub(crate) procs: Vec<Proc>,
    /// The cell's virtual clock (`[cell] clock = "virtual"`), stepped by the loop.
    pub(crate) clock: Option<runtime::vclock::Coordinator>,
    /// The user's e-stops scheduled on the virtual clock (`--fault AT:estop`): their instants.
    scheduled_estops: Vec<u64>,
    _node: iceoryx2::prelude::Node<ipc::Ipc>,
    /// The loop's scheduling as the kernel granted it (`status`).
    sched: runtime::rt::RtReport,
    /// This thread's `SCHED_FIFO` priority (`[supervisor] priority`), given back when the
    /// cell is closed: a supervisor that leaves must not spin at it (`runtime::rt::RtGuard`).
    _fifo: runtime::rt::RtGuard,
}

impl Cell {
    /// Creates every service, publishes the configuration and starts the processes.
    fn open(
        cfg: &Config,
        instance: InstanceName,
        mode: Mode,
        record: Option<&std::path::Path>,
    ) -> Result<(Self, Option<recorder::Background>), RunError> {
        let f = |e: ipc::IpcError| RunError::system(e.to_string());
        let node = ipc::node(&instance, "supervisor").map_err(f)?;
        let i = &instance;
        // On the virtual clock from here on: every time the supervisor reads is the clock's.
        let clock = match cfg.cell.clock {
            cell_config::Clock::Wall => None,
            cell_config::Clock::Virtual if cfg.ethercat.is_some() => {
                return Err(RunError::Input(
                    "a cell with [ethercat] runs on the wall clock: its bus cannot be stepped \
                     by a virtual clock"
                        .into(),
                ));
            }
            cell_config::Clock::Virtual => {
                let mut c =
                    runtime::vclock::Coordinator::new(&node, i, CLOCK_WATCHDOG).map_err(f)?;
                // `run` as fast as the CPUs allow, `up` (watched by its clients) in real time.
                c.set_pace(cfg.cell.pace.unwrap_or(match mode {
                    Mode::Run => 0.0,
                    Mode::Up => 1.0,
                }));
                Some(c)
            }
        };
        let config_pub = Pub::new(&node, i, ServiceId::CellConfig).map_err(f)?;
        let command_pub = Pub::new(&node, i, ServiceId::MotionCommand).map_err(f)?;
        let control_pub = Pub::new(&node, i, ServiceId::MotionControl).map_err(f)?;
        let request_pub = Pub::new(&node, i, ServiceId::ServoRequest).map_err(f)?;
        let events_sub = Sub::new(&node, i, ServiceId::Events, 1024).map_err(f)?;
        let events_pub = Pub::new(&node, i, ServiceId::Events).map_err(f)?;
        let estop_sub = Sub::new(&node, i, ServiceId::Estop, 64).map_err(f)?;
        let estop_pub = Pub::new(&node, i, ServiceId::Estop).map_err(f)?;
        let host_pub = Pub::new(&node, i, ServiceId::HostState).map_err(f)?;
        let sense_sub = Sub::new(&node, i, ServiceId::SenseToCommand, 1).map_err(f)?;
        let setpoint_sub = Sub::new(&node, i, ServiceId::Setpoint, 1024).map_err(f)?;
        let servo_sub = Sub::new(&node, i, ServiceId::ServoState, 1024).map_err(f)?;
        let image_sub = Sub::new(&node, i, ServiceId::FieldbusOutput, 256).map_err(f)?;
        let handover_sub = Sub::new(&node, i, ServiceId::TrajgenHandover, 1).map_err(f)?;
        let handover_pub = Pub::new(&node, i, ServiceId::TrajgenHandover).map_err(f)?;
        let io_sub = Sub::new(&node, i, ServiceId::IoState, 1).map_err(f)?;
        let mut procs = Vec::new();
        for p in &cfg.process {
            let name = ProcessName::new(&p.name).map_err(|e| RunError::Input(e.to_string()))?;
            procs.push(Proc {
                name: p.name.clone(),
                critical: p.critical,
                status: None,
                latency: None,
                exec_time: None,
                beat: (0, Moment::now()),
                life: Life::Running,
                restarts: 0,
                streak: 0,
                ignore_pid: None,
                command: None,
                flagged: false,
                listening: None,
                listen_failed: None,
                started: Moment::now(),
                exec_sub: Sub::new(&node, i, ServiceId::ExecTime(name), 1).map_err(f)?,
                status_sub: Sub::new(&node, i, ServiceId::Status(name), 64).map_err(f)?,
                latency_sub: Sub::new(&node, i, ServiceId::Latency(name), 1).map_err(f)?,
            });
        }
        let cell = cfg.to_shm();
        config_pub.send(&cell);
        let ethercat_pub = match &cfg.ethercat {
            Some(bus) => {
                let p = Pub::new(&node, i, ServiceId::EthercatConfig).map_err(f)?;
                p.send(&bus.to_shm(&cfg.axis, &cfg.io));
                Some(p)
            }
            None => None,
        };
        let host = HostStateV1 {
            stamp_ns: runtime::time::now_ns(),
            pid: std::process::id(),
            ..HostStateV1::default()
        };
        host_pub.send(&host);
        // The heartbeat's thread above ordinary work from the first process on; what it
        // starts starts under SCHED_OTHER.
        let (sched, fifo) = runtime::rt::setup_watching_thread(cfg.supervisor.priority);
        if sched.policy == 1 {
            tracing::info!(
                "the supervisor's loop runs under SCHED_FIFO {}; what it starts, under SCHED_OTHER",
                sched.priority
            );
        }
        let mut clock = clock;
        // The recorder before the processes: it reads each from its first message (and on
        // the virtual clock it has joined the clock before any process runs).
        let recorder = match record {
            None => None,
            Some(file) => {
                let mut r = recorder::Background::spawn(&instance, file, recorder::Group::Own)?;
                if let (Some(c), Some(pid)) = (clock.as_mut(), r.pid()) {
                    c.expect(pid);
                }
                // It needs the configuration's history (and the clock's).
                while !r.started()? {
                    config_pub.update_connections();
                    host_pub.update_connections();
                    if let Some(c) = &clock {
                        c.update_connections();
                    }
                    std::thread::sleep(Duration::from_millis(5));
                }
                Some(r)
            }
        };
        let mut children = Children::new(Duration::from_secs_f64(cfg.supervisor.stop_timeout));
        for (index, p) in cfg.process.iter().enumerate() {
            let pid = children
                .spawn(p, index, None, &instance)
                .map_err(RunError::system)?;
            if let Some(c) = clock.as_mut() {
                c.expect(pid);
            }
        }
        let cell = Self {
            instance,
            mode,
            children,
            estop: None,
            host,
            sense_to_command: None,
            events: Vec::new(),
            disabled_said: 0,
            axes: Axes::of_cell(&cell),
            t0_ns: runtime::time::now_ns(),
            last_sp: None,
            last_servo: None,
            io: None,
            shm: Box::new(cell),
            request_seq: 0,
            control_seq: 0,
            event_seq: 0,
            config_pub,
            ethercat_pub,
            command_pub,
            control_pub,
            request_pub,
            events_sub,
            events_pub,
            estop_sub,
            estop_pub,
            host_pub,
            sense_sub,
            setpoint_sub,
            servo_sub,
            image_sub,
            image_gaps: None,
            handover_sub,
            handover_pub,
            io_sub,
            stalls: StallWatch::new(Duration::from_secs_f64(
                (cfg.supervisor.supervisor_timeout / 4.0).min(STALL_REPORTED_S),
            )),
            beaten: std::time::Instant::now(),
            procs,
            clock,
            scheduled_estops: Vec::new(),
            _node: node,
            sched,
            _fifo: fifo,
        };
        Ok((cell, recorder))
    }

    /// Stops every process, takes the events that came meanwhile (the drives' fault
    /// reactions arrive after a verdict), removes the instance, and only then lets go of its
    /// lock (`server`): the next supervisor of the instance never meets this one's cleanup.
    pub(crate) fn close(mut self, server: ctl::Server) -> Closed {
        // The dead nodes (a client killed as it attached) cleaned while the processes run, not
        // by each of them as it goes (`ipc::config_for`).
        let _ = ipc::remove_dead_nodes(&self.instance);
        let stopped = self.stop_children();
        self.take_events();
        let events = self
            .events
            .iter()
            .map(|e| events::event(e, &self.axes, self.t0_ns))
            .collect();
        let instance = self.instance;
        drop(self);
        // A client (status, events, inject) may be finishing: give it a second to go.
        let leftovers = ipc::remove_instance_waiting(&instance, Duration::from_secs(1));
        drop(server);
        let problem = match stopped.first() {
            Some((name, why)) => Some(RunError::failed(Failure::NotStopped {
                process: name.clone(),
                what: why.clone(),
            })),
            None => leftover_error(&instance, &leftovers),
        };
        Closed { events, problem }
    }

    /// Index of process `name` in the table.
    pub(crate) fn index_of(&self, name: &str) -> Option<usize> {
        self.procs.iter().position(|p| p.name == name)
    }

    /// Takes the newest latency histogram of every process (they publish about every 100 ms)
    /// and the drives' sense-to-command histogram.
    pub(crate) fn refresh_latency(&mut self) {
        for p in &mut self.procs {
            if let Some(h) = p.latency_sub.latest() {
                p.latency = Some(Box::new(h));
            }
            if let Some(h) = p.exec_sub.latest() {
                p.exec_time = Some(Box::new(h));
            }
        }
        if let Some(h) = self.sense_sub.latest() {
            self.sense_to_command = Some(Box::new(h));
        }
    }

    /// The newest of what the processes publish, for `status`: the processes that run and
    /// reported (a process lost or restarting is not shown: its last status is old), servo's
    /// state, the setpoint, the IO image, the histograms (taken now).
    pub(crate) fn snapshot(&mut self) -> Snapshot {
        self.refresh_latency();
        if let Some(io) = self.io_sub.latest() {
            self.io = Some(io);
        }
        let processes = (0..self.procs.len())
            .filter(|&k| matches!(self.procs[k].life, Life::Running))
            .filter_map(|k| {
                Some(Seen {
                    name: self.procs[k].name.clone(),
                    status: self.procs[k].status?,
                    latency: self.procs[k].latency.clone(),
                    exec_time: self.procs[k].exec_time.clone(),
                })
            })
            .collect();
        Snapshot {
            processes,
            servo: self.last_servo,
            cell: Some(self.shm.clone()),
            sense_to_command: self.sense_to_command.clone(),
            host: Some(self.host),
            setpoint: self.last_sp,
            io: self.io,
        }
    }

    /// Takes the events that arrived: printed on stderr as they happen (`run`), or logged
    /// (`up`).
    pub(crate) fn take_events(&mut self) {
        // In the order they happened, whatever order their publishers' queues are read in
        // (on the virtual clock: the same order every run).
        let mut taken = Vec::new();
        while let Some(e) = self.events_sub.next() {
            taken.push(e);
        }
        taken.sort_by_key(|e| (e.stamp_ns, e.source, e.seq));
        for e in taken {
            let line = events::line(&e, &self.axes, self.t0_ns);
            match self.mode {
                Mode::Run => crate::out::line(&line),
                Mode::Up => match e.severity {
                    s if s >= shm_schema::event::Severity::Error as u32 => {
                        tracing::error!("{line}")
                    }
                    s if s >= shm_schema::event::Severity::Warning as u32 => {
                        tracing::warn!("{line}")
                    }
                    _ => tracing::info!("{line}"),
                },
            }
            if e.code == code::DISABLED {
                self.disabled_said += 1;
            }
            if let Some(p) = self.procs.get_mut(e.source as usize) {
                match e.code {
                    code::LISTENING => {
                        p.listening = Some(e.text().to_string());
                        p.listen_failed = None;
                    }
                    code::LISTEN_FAILED => {
                        p.listening = None;
                        p.listen_failed = Some(e.text().to_string());
                    }
                    _ => {}
                }
            }
            if self.events.len() < 1_000_000 {
                self.events.push(e);
            }
        }
    }

    /// Publishes an event of the supervisor's own.
    pub(crate) fn event(&mut self, code: u32, value: f64, parts: &[&str]) {
        self.event_seq += 1;
        let mut e = EventV1::new(runtime::time::now_ns(), code, -1, value, 0.0, parts);
        e.seq = self.event_seq;
        e.source = SOURCE_SUPERVISOR;
        self.events_pub.send(&e);
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
            Err(RunError::failed(Failure::ServiceRefused {
                service: "servo's request service".into(),
                sample: "a request".into(),
            }))
        }
    }

    /// Asks trajgen to pause, resume or abort; returns the request's sequence number
    /// (trajgen echoes it in `SetpointV2::control_seq` once taken).
    pub(crate) fn motion_control(&mut self, kind: ControlKind) -> u64 {
        self.motion_control_with(kind, 0.0)
    }

    /// Like [`Cell::motion_control`], with a value (the speed override).
    pub(crate) fn motion_control_with(&mut self, kind: ControlKind, value: f64) -> u64 {
        // The time (ns) makes the number increase across senders (the Modbus server sends
        // the speed override too), so `control_seq >= seq` still means "taken".
        self.control_seq = (self.control_seq + 1).max(runtime::time::now_ns());
        self.control_pub.send(&MotionControlV2 {
            seq: self.control_seq,
            kind: kind as u32,
            reserved: 0,
            value,
        });
        self.control_seq
    }

    /// The heartbeat: the host state with the latched e-stop, every tick.
    /// A gap since the last one of over 100 ms (or a quarter of `supervisor_timeout`, if
    /// that is shorter) is an event that says where the time went (see [`runtime::stall`]).
    pub(crate) fn beat(&mut self) {
        // On the virtual clock a beat per tick of the cell's time; while the clock stands (a
        // validation, a process joining, the recorder finishing its file), one a second of
        // wall time, which keeps the cell alive to its observers without a count of beats
        // that depends on the wall clock.
        if self.clock.is_some()
            && self.host.beat > 0
            && self.host.stamp_ns == runtime::time::now_ns()
            && self.beaten.elapsed() < STANDING_BEAT
        {
            return;
        }
        self.beaten = std::time::Instant::now();
        self.host.beat += 1;
        self.host.stamp_ns = runtime::time::now_ns();
        self.host_pub.send(&self.host);
        // On the virtual clock the wall time between two beats is the cell's work, not a stall.
        if self.clock.is_none()
            && let Some(s) = self.stalls.beat()
        {
            let cause = s.cause();
            tracing::warn!(
                "the supervisor's heartbeat paused {:.0} ms: {cause}",
                s.gap.as_secs_f64() * 1e3
            );
            self.event(code::SUPERVISOR_STALLED, s.gap.as_secs_f64(), &[&cause]);
        }
    }

    /// Reads `<i>/estop` and latches the first trigger in it (every tick, and again where a
    /// verdict depends on whether one arrived since: servo reacts to an e-stop in the cycle
    /// it sees it, maybe before this tick read it).
    pub(crate) fn poll_estop(&mut self) {
        while let Some(e) = self.estop_sub.next() {
            if e.kind == EstopKind::Trigger as u32 {
                self.latch(e);
            }
        }
    }

    /// Latches `e` (the first trigger since the last reset wins).
    fn latch(&mut self, e: EstopV1) {
        if self.estop.is_none() {
            self.estop = Some((e, Moment::now()));
            self.host.estop = EstopState::Latched as u32;
            self.host.cause = e;
            let origin = EstopOrigin::from_wire(e.origin).map_or("?", EstopOrigin::name);
            tracing::warn!(
                "e-stop ({origin}) raised by {}: {}",
                self.axes.source_name(e.source),
                str_of(&e.reason)
            );
        }
    }

    /// Raises an e-stop from the supervisor: `Host` for a process lost, `External` for the
    /// user's (`supervisor estop`, as a button's). Published to every process on the
    /// supervisor's own port, latched here.
    pub(crate) fn raise(&mut self, origin: EstopOrigin, cause: u32, parts: &[&str]) {
        let e = EstopV1::trigger(
            runtime::time::now_ns(),
            origin,
            SOURCE_SUPERVISOR,
            cause,
            parts,
        );
        self.estop_pub.send(&e);
        self.latch(e);
        // The host state carries it too, so a process started later sees it at once.
        self.beat();
    }

    /// A process was lost: the host e-stop, its resources, its restart.
    fn lost(&mut self, k: usize, cfg: &Config, why: &str, exit_code: f64) {
        let name = self.procs[k].name.clone();
        self.procs[k].listening = None;
        self.procs[k].listen_failed = None;
        if !self.procs[k].critical {
            // Its last status must not hold a reset back while it restarts.
            self.procs[k].status = None;
        }
        if self.procs[k].critical {
            self.event(code::PROCESS_LOST, exit_code, &[&name, ": ", why]);
            self.raise(EstopOrigin::Host, code::PROCESS_LOST, &[&name, " lost"]);
        } else {
            self.event(code::NOT_CRITICAL_FAILED, exit_code, &[&name, ": ", why]);
        }
        let _ = ipc::remove_dead_nodes(&self.instance);
        let p = &cfg.process[k];
        // A run ends with a lost critical process; one that is not critical restarts.
        self.procs[k].life = if self.mode == Mode::Run && self.procs[k].critical {
            Life::Down(format!("lost: {why}"))
        } else if p.restart == RestartPolicy::Never {
            Life::Down(format!("lost: {why}; restart = \"never\""))
        } else if self.procs[k].streak >= cfg.supervisor.restart_limit {
            Life::Down(format!(
                "lost: {why}; restart limit of {} reached",
                cfg.supervisor.restart_limit
            ))
        } else {
            let backoff =
                cfg.supervisor.restart_backoff * f64::from(1u32 << self.procs[k].streak.min(6));
            Life::Restarting(Moment::now() + Duration::from_secs_f64(backoff))
        };
        match &self.procs[k].life {
            Life::Down(why) => tracing::error!("{name} {why}"),
            Life::Restarting(at) => tracing::warn!(
                "{name} lost ({why}); restarting in {:.2} s",
                at.saturating_duration_since(Moment::now()).as_secs_f64()
            ),
            Life::Running => {}
        }
    }

    /// Starts process `k` (again), with its current command.
    pub(crate) fn start_process(&mut self, k: usize, cfg: &Config) -> Result<u32, String> {
        let command = self.procs[k].command.clone();
        let pid = self
            .children
            .spawn(&cfg.process[k], k, command.as_deref(), &self.instance)?;
        if let Some(c) = self.clock.as_mut() {
            c.expect(pid);
        }
        self.procs[k].life = Life::Running;
        self.procs[k].started = Moment::now();
        self.procs[k].beat = (0, Moment::now());
        self.procs[k].status = None;
        self.procs[k].flagged = false;
        Ok(pid)
    }

    /// One supervisor tick; see the module documentation. Returns what happened to the
    /// processes in it.
    pub(crate) fn tick(&mut self, cfg: &Config) -> Vec<Incident> {
        let mut out = Vec::new();
        self.beat();
        let now = runtime::time::now_ns();
        if self.scheduled_estops.iter().any(|&at| at <= now) {
            self.scheduled_estops.retain(|&at| at > now);
            self.raise(
                EstopOrigin::External,
                code::ESTOP_RAISED,
                &["scheduled e-stop"],
            );
        }
        self.reap(cfg, &mut out);
        self.update_connections();
        self.take_events();
        self.poll_estop();
        self.watch(cfg, &mut out);
        self.forgive_stable();
        self.restart_due(cfg);
        out
    }

    /// The processes that exited since the last tick: a critical one an incident; each lost
    /// (restarted by its policy), but one of two during a swap.
    fn reap(&mut self, cfg: &Config, out: &mut Vec<Incident>) {
        // The ones told to stop (a swap's old process), as they leave: expected, no incident.
        for left in self.children.reap() {
            match left.problem {
                Some(problem) => tracing::warn!("{} (pid {}) {problem}", left.name, left.pid),
                None => tracing::debug!("{} (pid {}) left", left.name, left.pid),
            }
        }
        while let Some((p, status)) = self.children.exited() {
            let k = p.index;
            let text = status.to_string();
            if self.procs[k].critical {
                out.push(Incident::Exited {
                    name: p.name.clone(),
                    pid: p.pid(),
                    status: text.clone(),
                    refused: status.code() == Some(2),
                });
            }
            if self.host.handover & (1 << k) != 0 && self.children.get(k).is_some() {
                // One of two during a swap (make before break): the other one still runs,
                // nothing is lost; the swap reports it.
                continue;
            }
            self.lost(
                k,
                cfg,
                &format!("exited: {text}"),
                status.code().map_or(-1.0, f64::from),
            );
        }
    }

    /// History for subscribers that connected since the last tick.
    fn update_connections(&self) {
        self.config_pub.update_connections();
        if let Some(p) = &self.ethercat_pub {
            p.update_connections();
        }
        self.host_pub.update_connections();
        self.handover_pub.update_connections();
    }

    /// Each process' status since the last tick: its heartbeat (its cycle count going on), a
    /// fault it reports, a stall beyond the heartbeat timeout (the e-stop if it is critical;
    /// ended, to be restarted, by its policy).
    fn watch(&mut self, cfg: &Config, out: &mut Vec<Incident>) {
        let timeout = Duration::from_secs_f64(cfg.supervisor.heartbeat_timeout);
        for k in 0..self.procs.len() {
            while let Some(s) = self.procs[k].status_sub.next() {
                if self.procs[k].ignore_pid == Some(s.pid) {
                    continue;
                }
                let b = &mut self.procs[k].beat;
                if s.stats.cycles != b.0 {
                    *b = (s.stats.cycles, Moment::now());
                }
                self.procs[k].status = Some(s);
            }
            if self.procs[k].life != Life::Running || self.procs[k].flagged {
                continue;
            }
            if let Some(s) = self.procs[k].status
                && ProcState::from_wire(s.state) == Some(ProcState::Fault)
            {
                self.procs[k].flagged = true;
                if self.procs[k].critical {
                    out.push(Incident::Fault {
                        name: self.procs[k].name.clone(),
                        fault: s.fault,
                    });
                }
            }
            let (cycles, at) = self.procs[k].beat;
            if cycles > 0 && at.elapsed() > timeout && self.host.handover & (1 << k) == 0 {
                self.procs[k].flagged = true;
                let for_s = at.elapsed().as_secs_f64();
                let name = self.procs[k].name.clone();
                if self.procs[k].critical {
                    out.push(Incident::Stalled {
                        name: name.clone(),
                        for_s,
                    });
                    self.event(code::PROCESS_LOST, -1.0, &[&name, ": stalled"]);
                    self.raise(EstopOrigin::Host, code::PROCESS_LOST, &[&name, " stalled"]);
                } else {
                    self.event(code::NOT_CRITICAL_FAILED, -1.0, &[&name, ": stalled"]);
                }
                if (self.mode == Mode::Up || !self.procs[k].critical)
                    && cfg.process[k].restart == RestartPolicy::OnFailure
                {
                    // Alive but not cycling: end it; its exit restarts it.
                    self.children.kill(k);
                }
            }
        }
    }

    /// A process that is not critical and has run a while since its last restart starts its
    /// restart count afresh (no e-stop reset does it for such a process).
    fn forgive_stable(&mut self) {
        for k in 0..self.procs.len() {
            if !self.procs[k].critical
                && self.procs[k].streak > 0
                && self.cyclic(k)
                && self.procs[k].started.elapsed() > STABLE
            {
                self.procs[k].streak = 0;
            }
        }
    }

    /// The restarts that are due, each said in the log and in an event.
    fn restart_due(&mut self, cfg: &Config) {
        for k in 0..self.procs.len() {
            if let Life::Restarting(at) = self.procs[k].life
                && Moment::now() >= at
            {
                self.procs[k].restarts += 1;
                self.procs[k].streak += 1;
                match self.start_process(k, cfg) {
                    Ok(pid) => {
                        let name = self.procs[k].name.clone();
                        tracing::warn!(
                            "{name} restarted (pid {pid}, restart {})",
                            self.procs[k].restarts
                        );
                        self.event(
                            code::PROCESS_RESTARTED,
                            f64::from(self.procs[k].restarts),
                            &[&name, " restarted"],
                        );
                    }
                    Err(e) => {
                        tracing::error!("{e}");
                        self.procs[k].life = Life::Down(e);
                    }
                }
            }
        }
    }

    /// Takes the setpoints, servo states and images that arrived, keeping the newest (when
    /// no job reads them).
    pub(crate) fn drain_motion(&mut self) {
        while let Some(s) = self.setpoint_sub.next() {
            self.last_sp = Some(s);
        }
        while let Some(s) = self.servo_sub.next() {
            self.last_servo = Some(s);
        }
        self.drain_images(|_| {});
    }

    /// Takes the fieldbus images that arrived: a swap's gap meter sees each, then `each`.
    pub(crate) fn drain_images(&mut self, mut each: impl FnMut(&FieldbusImageV1)) {
        while let Some(img) = self.image_sub.next() {
            if let Some(g) = &mut self.image_gaps {
                g.see(img.written_ns);
            }
            each(&img);
        }
    }

    /// Schedules `planned` faults on the cell's virtual clock ([`crate::schedule::plan`]
    /// checked them: the cell is on it).
    pub(crate) fn schedule(&mut self, planned: &[crate::schedule::Planned]) {
        use crate::schedule::Planned;
        let Some(clock) = self.clock.as_mut() else {
            return;
        };
        for p in planned {
            match *p {
                Planned::Hold {
                    index,
                    from_ns,
                    until_ns,
                } => clock.hold(index, from_ns, until_ns),
                Planned::Kill { index, at_ns } => clock.kill_at(index, at_ns),
                Planned::Estop { at_ns } => self.scheduled_estops.push(at_ns),
            }
        }
    }

    /// On the virtual clock: runs it to the next multiple of `TICK` (every process' cycles up
    /// to then granted, in order); on the wall clock nothing (the loop's wait sleeps).
    pub(crate) fn advance_clock(&mut self) {
        let tick = TICK.as_nanos() as u64;
        self.advance_clock_to((runtime::time::now_ns() / tick + 1) * tick);
    }

    /// Lets `d` pass: on the virtual clock, its processes run that long; on the wall clock,
    /// nothing (the caller sleeps).
    pub(crate) fn pass(&mut self, d: Duration) {
        self.advance_clock_to(runtime::time::now_ns() + d.as_nanos() as u64);
    }

    fn advance_clock_to(&mut self, t: u64) {
        let Some(mut c) = self.clock.take() else {
            return;
        };
        // Processes starting meanwhile need the configuration's history.
        c.advance_to(&self._node, t, &mut || self.update_connections());
        let lost = c.take_lost();
        self.clock = Some(c);
        for lost in lost {
            let name = self
                .children
                .iter()
                .find(|r| r.pid() == lost.pid)
                .map_or_else(|| format!("pid {}", lost.pid), |r| r.name.clone());
            let (what, within) = match lost.why {
                runtime::vclock::LostWhy::NeverDone => ("did not finish its cycle", CLOCK_WATCHDOG),
                runtime::vclock::LostWhy::NeverJoined => (
                    "did not join it",
                    CLOCK_WATCHDOG.max(runtime::vclock::START_PATIENCE),
                ),
            };
            tracing::error!(
                "virtual clock: {name} {what} within {} s of wall time: left out of the clock",
                within.as_secs()
            );
        }
    }

    /// Runs `f` on the children with a tick that keeps the heartbeat going (every 10 ms), so
    /// that no process takes the supervisor for lost while it waits for one to stop.
    fn beating<R>(&mut self, f: impl FnOnce(&mut Children, &mut dyn FnMut()) -> R) -> R {
        let mut children = std::mem::take(&mut self.children);
        let mut last = Moment::now();
        let r = f(&mut children, &mut || {
            // On the virtual clock the processes leave on its time: it runs as the loop waits.
            self.pass(LEAVE_STEP);
            if last.elapsed() >= TICK {
                last = Moment::now();
                self.beat();
            }
        });
        self.children = children;
        r
    }

    /// Stops every process; returns those that did not stop cleanly.
    pub(crate) fn stop_children(&mut self) -> Vec<(String, String)> {
        self.beating(|c, tick| c.stop_all(tick))
    }

    /// The command process `k` runs now (`None`: the configured one).
    pub(crate) fn command_of(&self, k: usize) -> Option<Vec<String>> {
        self.procs[k].command.clone()
    }

    /// Offers `h` to a new trajgen (history 1); `valid` 0 withdraws the offer.
    pub(crate) fn offer_handover(&mut self, h: &TrajgenHandoverV2) {
        self.handover_pub.send(h);
    }

    /// Marks process `k` as being replaced (or not): consumers do not count its gap.
    pub(crate) fn set_handover(&mut self, k: usize, on: bool) {
        if on {
            self.host.handover |= 1 << k;
        } else {
            self.host.handover &= !(1 << k);
        }
        self.beat();
    }

    /// Ignores the statuses of `pid` for process `k` (the old one during a swap).
    pub(crate) fn ignore_statuses_of(&mut self, k: usize, pid: Option<u32>) {
        self.procs[k].ignore_pid = pid;
    }

    /// Sets the command process `k` runs from its next start.
    pub(crate) fn set_command(&mut self, k: usize, command: Option<Vec<String>>) {
        self.procs[k].command = command;
    }

    /// Whether the cell's safety depends on process `k` (`critical`).
    pub(crate) fn critical(&self, k: usize) -> bool {
        self.procs[k].critical
    }

    /// E-stop resets since the cell started.
    pub(crate) fn resets(&self) -> u64 {
        self.host.resets
    }

    /// The first critical process lost for good (restart policy `never`, or its restart
    /// limit reached), and why.
    pub(crate) fn lost_for_good(&self) -> Option<(String, String)> {
        (0..self.procs.len()).find_map(|k| match &self.procs[k].life {
            Life::Down(why) if self.procs[k].critical => {
                Some((self.procs[k].name.clone(), why.clone()))
            }
            _ => None,
        })
    }

    /// Every critical process is cyclic (one that is not critical, the Modbus server, is not
    /// waited for).
    pub(crate) fn critical_cyclic(&self) -> bool {
        (0..self.procs.len()).all(|k| self.cyclic(k) || !self.procs[k].critical)
    }

    /// True when process `k` is cyclic and its cycles advance.
    pub(crate) fn cyclic(&self, k: usize) -> bool {
        self.procs[k].life == Life::Running
            && self.procs[k]
                .status
                .is_some_and(|s| s.state == ProcState::Cyclic as u32 && s.stats.cycles > 0)
    }

    /// The reasons the e-stop cannot be cleared now (empty: it can).
    pub(crate) fn reset_blockers(&self) -> Vec<String> {
        let mut out = Vec::new();
        for (k, p) in self.procs.iter().enumerate() {
            let name = &p.name;
            if !p.critical {
                continue; // the e-stop does not wait for it
            }
            match &self.procs[k].life {
                Life::Down(why) => out.push(format!(
                    "{name} is not running ({why}): `supervisor restart {name}` first"
                )),
                Life::Restarting(_) => out.push(format!("{name} is restarting")),
                Life::Running if !self.cyclic(k) => {
                    out.push(format!("{name} is not cyclic yet"));
                }
                Life::Running => {}
            }
        }
        out
    }

    /// Clears the e-stop: the host state first (so a process that reads it cannot take the
    /// reset for stale), then the reset record on `<i>/estop`, then servo's latched fault.
    pub(crate) fn reset(&mut self) -> Result<u64, RunError> {
        self.host.resets += 1;
        self.host.estop = EstopState::Clear as u32;
        self.host.cause = EstopV1::default();
        self.estop = None;
        self.beat();
        let mut r = EstopV1::reset(runtime::time::now_ns(), SOURCE_SUPERVISOR);
        r.code = self.host.resets as u32;
        self.estop_pub.send(&r);
        self.event(code::ESTOP_RESET, self.host.resets as f64, &["reset"]);
        self.procs.iter_mut().for_each(|p| p.streak = 0);
        self.request(RequestKind::Reset)?;
        Ok(self.host.resets)
    }

    /// The processes still showing the e-stop latched after a reset.
    pub(crate) fn still_latched(&self) -> Vec<String> {
        // A process that is not critical is not waited for (its status may be a lost one's).
        (0..self.procs.len())
            .filter(|&k| self.procs[k].critical && self.procs[k].life == Life::Running)
            .filter(|&k| {
                self.procs[k]
                    .status
                    .is_some_and(|s| s.estop & estop_seen::LATCHED != 0)
            })
            .map(|k| self.procs[k].name.clone())
            .collect()
    }

    /// True while a process that reacts to the e-stop has not completed its reaction.
    pub(crate) fn reactions_pending(&self) -> bool {
        (0..self.procs.len())
            .filter(|&k| self.procs[k].critical)
            .any(|k| {
                self.procs[k].status.is_some_and(|s| {
                    s.estop & estop_seen::REACTING != 0 && s.estop & estop_seen::SAFE == 0
                })
            })
    }

    /// True when process `name` reacts to the e-stop.
    pub(crate) fn reacting(&self, name: &str) -> bool {
        self.index_of(name).is_some_and(|k| {
            self.procs[k]
                .status
                .is_some_and(|s| s.estop & estop_seen::REACTING != 0)
        })
    }

    /// True for servo's own device e-stop: a latched fault, which servo's state explains.
    pub(crate) fn is_servo_fault(&self, e: &EstopV1) -> bool {
        e.origin == EstopOrigin::Device as u32
            && self
                .procs
                .get(e.source as usize)
                .is_some_and(|p| p.name == "servo")
    }

    /// The latched fault servo reports, with the event that explains it.
    pub(crate) fn fault(&self, s: &ServoStateV3) -> Failure {
        let cause = self.events.iter().rev().find(|e| e.code == s.fault_code);
        self.servo_cut(s.fault_code, s.fault_axis, cause)
    }

    /// The latched fault servo reports, in words.
    pub(crate) fn fault_text(&self, s: &ServoStateV3) -> String {
        self.fault(s).to_string()
    }

    /// Servo cut power by fault `code` on `axis`, explained by event `cause`.
    fn servo_cut(&self, code: u32, axis: i32, cause: Option<&EventV1>) -> Failure {
        Failure::ServoFault {
            fault: shm_schema::event::info(code)
                .map_or("unknown fault", |i| i.name)
                .to_string(),
            code,
            axis: usize::try_from(axis)
                .ok()
                .and_then(|i| self.axes.axes.get(i))
                .map(|(a, _)| a.to_string()),
            event: cause.map(|ev| events::line(ev, &self.axes, self.t0_ns)),
        }
    }

    /// The latched e-stop (servo's own fault as [`Failure::ServoFault`]).
    pub(crate) fn estop_failure(&self) -> Option<Failure> {
        let (e, _) = self.estop?;
        let cause = self
            .events
            .iter()
            .rev()
            .find(|ev| ev.code == e.code && ev.source == e.source);
        if self.is_servo_fault(&e) {
            let axis = cause.map_or(-1, |ev| ev.axis);
            return Some(self.servo_cut(e.code, axis, cause));
        }
        Some(Failure::Estop {
            origin: e.origin.into(),
            by: self.axes.source_name(e.source).to_string(),
            code: e.code,
            reason: str_of(&e.reason).to_string(),
            event: cause.map(|ev| events::line(ev, &self.axes, self.t0_ns)),
        })
    }

    /// The latched e-stop, in words.
    pub(crate) fn estop_text(&self) -> Option<String> {
        self.estop_failure().map(|f| f.to_string())
    }

    /// The supervisor's view for `status --json`: per process its pid, life and restarts;
    /// the arm; the e-stop. The loop adds what runs on the cell ([`crate::serve`]).
    pub(crate) fn info(&self) -> Info {
        let processes = (0..self.procs.len())
            .map(|k| {
                let (life, why) = match &self.procs[k].life {
                    Life::Running if self.cyclic(k) => (info::Life::Running, None),
                    Life::Running => (info::Life::Starting, None),
                    Life::Restarting(_) => (info::Life::Restarting, None),
                    Life::Down(w) => (info::Life::Down, Some(w.clone())),
                };
                info::ProcessInfo {
                    name: self.procs[k].name.clone(),
                    pid: self.children.get(k).map(|p| p.pid()),
                    life,
                    why,
                    restarts: self.procs[k].restarts,
                    command: self.procs[k].command.clone(),
                    critical: self.procs[k].critical,
                    listening: self.procs[k].listening.clone(),
                    listen_failed: self.procs[k].listen_failed.clone(),
                }
            })
            .collect();
        let estop = self.estop.map(|(e, _)| info::EstopInfo {
            origin: e.origin.into(),
            source: self.axes.source_name(e.source),
            code: e.code,
            reason: str_of(&e.reason).to_string(),
            text: self.estop_text(),
        });
        let arm = self.last_servo.map(|s| info::ArmInfo {
            enabled: s.status & st::ENABLED != 0,
            fault_latched: s.status & st::FAULT_LATCHED != 0,
            fault: (s.status & st::FAULT_LATCHED != 0).then(|| self.fault_text(&s)),
        });
        Info {
            pid: std::process::id(),
            mode: match self.mode {
                Mode::Run => info::Mode::Run,
                Mode::Up => info::Mode::Up,
            },
            policy: runtime::rt::policy_name(self.sched.policy).to_string(),
            priority: self.sched.priority,
            resets: self.host.resets,
            estop,
            arm,
            processes,
            job: None,
            validating: None,
            last_job: None,
            enabling: false,
            swapping: None,
            tuning: None,
            going_down: false,
        }
    }
}

/// The largest interval between consecutive fieldbus images seen (ns), and their count.
#[derive(Debug, Default)]
pub(crate) struct GapMeter {
    last_ns: Option<u64>,
    max_ns: u64,
    count: u64,
}

impl GapMeter {
    /// An image written at `written_ns`.
    pub(crate) fn see(&mut self, written_ns: u64) {
        if let Some(t) = self.last_ns
            && written_ns > t
        {
            self.max_ns = self.max_ns.max(written_ns - t);
        }
        self.last_ns = Some(self.last_ns.map_or(written_ns, |t| t.max(written_ns)));
        self.count += 1;
    }

    pub(crate) fn result(&self) -> Option<(u64, u64)> {
        (self.count > 1).then_some((self.max_ns, self.count))
    }
}
