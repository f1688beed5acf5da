//! The skeleton of every real-time process of a cell.
//!
//! `main` of trajgen, servo, machine-sim and iobridge is one call to [`run`]:
//!
//! 1. arguments: `--instance NAME` (default `gantry`), `--name NAME` (the process' entry in
//!    the cell's process table; default the binary's own name);
//! 2. SIGTERM/SIGINT handler, iceoryx2 node;
//! 3. the cell configuration from `<i>/cell/config` (published by the supervisor), and the
//!    process' own entry in its process table, found by name;
//! 4. the task's own set-up (`build`: opens ports, preallocates, validates) — may fail;
//! 5. real-time set-up ([`crate::rt::setup`]) with the entry's priority and CPU;
//! 6. the cycle ([`Runner::cycle`], one per wake-up of the process' clock; a test drives it
//!    cycle by cycle): read the e-stop ([`EstopWatch::poll`]); [`Task::cycle`]; the health
//!    detectors ([`Health`]); publish [`ProcessStatusV2`]; about every 100 ms the wake-up
//!    latency and execution-time histograms, half an interval apart, each copied into shared
//!    memory a slice per cycle ([`Snapshot`]: 30 KB whole cost about 2 µs from cold caches,
//!    `cargo bench -p runtime --bench publish`);
//! 7. on SIGTERM, or when the supervisor stops beating: the cycle goes on with an e-stop
//!    reaction until the task is safe (servo: axes at rest, drives disabled), at most the
//!    cell's e-stop stop time and a second; then a clean exit that removes the process'
//!    iceoryx2 resources.

use crate::cycle::{CycleClock, WaitError, Wake};
use crate::estop::{EstopView, EstopWatch};
use crate::events::EventSink;
use crate::health::Health;
use crate::ipc::{self, Ipc, Pub, Sub};
use crate::rt::{self, RtRequest};
use crate::signals;
use crate::snapshot::Snapshot;
use crate::time::now_ns;
use iceoryx2::prelude::Node;
use shm_schema::event::code;
use shm_schema::{
    CellConfigV6, EstopOrigin, EventQueue, EventV1, InstanceName, ProcState, ProcessConfigV2,
    ProcessName, ProcessStatusV2, ServiceId, estop_seen,
};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Instance used when no `--instance` is given.
pub const DEFAULT_INSTANCE: &str = "gantry";

pub use crate::snapshot::LATENCY_PUBLISH_INTERVAL_NS;

/// Overruns are reported as an event at most this often (ns).
pub const OVERRUN_EVENT_INTERVAL_NS: u64 = 1_000_000_000;

/// How long a process waits for the cell configuration before giving up.
pub const CONFIG_TIMEOUT: Duration = Duration::from_secs(10);

/// Beyond the cell's e-stop stop time, how long a leaving process waits for its task to be
/// safe before it exits anyway (ns).
pub const LEAVE_GRACE_NS: u64 = 1_000_000_000;

/// Everything a task's set-up may use.
#[derive(Debug)]
pub struct Context {
    /// Instance the process belongs to.
    pub instance: InstanceName,
    /// The process' name (its entry in the process table).
    pub name: ProcessName,
    /// Its index in the process table (the source of its events).
    pub index: usize,
    /// Its entry: period, phase, priority, CPU, e-stop reaction.
    pub own: ProcessConfigV2,
    /// The process' iceoryx2 node; open ports with [`Pub::new`] and [`Sub::new`].
    pub node: Node<Ipc>,
    /// The validated cell configuration.
    pub cell: CellConfigV6,
}

impl Context {
    /// The period (ns) of the process called `name`, one this process reads from or feeds
    /// (servo: `trajgen`, `drives`): a cell without it is refused at set-up, by name, never
    /// run on a guessed period.
    pub fn period_of(&self, name: &str) -> Result<u64, SetupError> {
        self.cell.period_of(name).ok_or_else(|| {
            format!(
                "the cell's process table has no process called {name:?}, whose period {} needs",
                self.name
            )
            .into()
        })
    }
}

/// What one cycle gets from the runtime and gives back to it.
#[derive(Debug)]
pub struct Cycle<'a> {
    /// The wake-up that started the cycle.
    pub wake: &'a Wake,
    /// The clock, to ask for an extra wake-up.
    pub clock: &'a mut CycleClock,
    /// Events to publish after the cycle.
    pub events: &'a mut EventQueue,
    /// The e-stop, as read at the start of this cycle.
    pub estop: EstopView,
    /// The supervisor is replacing a process of the cell (`HostStateV1::handover`): a
    /// process that starts now may be the successor (trajgen waits for its handover record).
    pub handover: bool,
    raise: Option<(EstopOrigin, u32, [u8; shm_schema::estop::REASON_LEN])>,
    pending: u64,
    transport: u64,
    safe: bool,
}

impl Cycle<'_> {
    /// The cycle's wake-up time (ns, `CLOCK_MONOTONIC`).
    pub fn now_ns(&self) -> u64 {
        self.wake.actual_ns
    }

    /// Raises an e-stop from this process (published after the cycle; this process reacts
    /// from its next cycle on). `code` is the cause's event code.
    ///
    /// # Real-time
    /// Copies only.
    pub fn raise_estop(&mut self, origin: EstopOrigin, code: u32, parts: &[&str]) {
        if self.raise.is_none() {
            self.raise = Some((origin, code, shm_schema::event::text_of(parts)));
        }
    }

    /// Counts `n` pending-sequence overruns (samples that did not arrive by this cycle).
    pub fn pending_overruns(&mut self, n: u64) {
        self.pending += n;
    }

    /// Counts `n` transport overruns of the task's own transport (a fieldbus frame lost or
    /// not taken by every device), beside the IPC calls that failed.
    pub fn transport_overruns(&mut self, n: u64) {
        self.transport += n;
    }

    /// Whether the task's e-stop reaction is complete this cycle (default: true; servo says
    /// false until the axes are at rest and the drives disabled).
    pub fn set_safe(&mut self, safe: bool) {
        self.safe = safe;
    }
}

/// The periodic work of a process.
pub trait Task {
    /// One cycle. May ask `cx.clock` for an extra wake-up, queue events, raise an e-stop,
    /// count pending-sequence overruns, and must react to `cx.estop.react`.
    ///
    /// # Real-time
    /// Implementations allocate nothing of their own, take no lock, log nothing, and make no
    /// system call but IPC calls.
    fn cycle(&mut self, cx: &mut Cycle<'_>);

    /// The process' fault code for its status (0 for none).
    fn fault(&self) -> u32 {
        0
    }

    /// Called once when the cycle ends, before the last status.
    fn stop(&mut self, _now_ns: u64, _events: &mut EventQueue) {}
}

/// Error type of a task's set-up.
pub type SetupError = Box<dyn std::error::Error + Send + Sync>;

/// Runs a real-time process; see the module documentation. `default_name` is its name in the
/// process table unless `--name` says otherwise. Exit code 0 after a requested stop, 1 after a
/// set-up failure or when the supervisor was lost, 2 on bad arguments or a [`Refused`]
/// configuration.
pub fn run<T: Task>(
    default_name: &str,
    about: &str,
    build: impl FnOnce(&Context) -> Result<T, SetupError>,
) -> ExitCode {
    crate::abort_on_panic();
    // /dev/shm full at start-up: the process says so and exits 1 (it died by signal 7).
    let _ = crate::signals::explain_sigbus();
    crate::fds::raise_limit();
    let (instance, name) = match parse_args(default_name, about) {
        Ok(a) => a,
        Err(code) => return code,
    };
    // A blocked stderr (a full pipe, a paused terminal) must never stall a process.
    let _log = init_logging_lossy();
    match run_inner(name, instance, build) {
        Ok(Exit::Stopped) => ExitCode::SUCCESS,
        Ok(Exit::SupervisorLost) => {
            tracing::error!(
                "{name} ({instance}): the supervisor stopped beating; left after bringing the process to a safe stop"
            );
            ExitCode::FAILURE
        }
        Err(e) => {
            tracing::error!("{name} ({instance}): {e}");
            if e.downcast_ref::<Refused>().is_some() {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// A set-up error that refuses the configuration against what the process found (the bus'
/// line differs from `[[ethercat.subdevice]]`): the process exits with code 2, which the
/// supervisor reports as the user's input, as a refused configuration.
#[derive(Debug)]
pub struct Refused(pub String);

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Refused {}

/// Logging to stderr, filtered by `RTC_LOG` (default `info`), blocking: for the commands of a
/// terminal (`supervisor status`).
pub fn init_logging() {
    init_logging_to(std::io::stderr);
}

/// Logging to stderr as [`init_logging`], through a lossy non-blocking writer (a thread of its
/// own writes the lines): a full pipe or a paused terminal loses lines and never stalls the
/// process. Every process of a cell logs this way; keep the guard until exit (it flushes).
pub fn init_logging_lossy() -> tracing_appender::non_blocking::WorkerGuard {
    let (writer, guard) = tracing_appender::non_blocking::NonBlockingBuilder::default()
        .lossy(true)
        .buffered_lines_limit(4096)
        .finish(std::io::stderr());
    init_logging_to(writer);
    guard
}

fn init_logging_to<W>(writer: W)
where
    W: for<'w> tracing_subscriber::fmt::MakeWriter<'w> + Send + Sync + 'static,
{
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    let _ = tracing_subscriber::registry()
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(writer)
                .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
                .with_target(false),
        )
        .with(log_filter())
        .try_init();
    ipc::quiet_iceoryx2_log();
}

/// What the log shows: `RTC_LOG` (`info` when unset), a level (`debug`) or a default level
/// and targets with their own (`info,supervisor=debug`), as `tracing_subscriber`'s
/// [`Targets`](tracing_subscriber::filter::Targets) reads it. A value it cannot read is said
/// on stderr, and `info` used.
pub fn log_filter() -> tracing_subscriber::filter::Targets {
    let info = || tracing_subscriber::filter::Targets::new().with_default(tracing::Level::INFO);
    match std::env::var("RTC_LOG") {
        Ok(v) => v.parse().unwrap_or_else(|e| {
            eprintln!("RTC_LOG={v:?} is not a level nor targets with levels ({e}): info");
            info()
        }),
        Err(_) => info(),
    }
}

/// The command line of every process of a cell; its name and words are the process' own.
#[derive(Debug, clap::Parser)]
struct Args {
    /// The cell's instance: the prefix of its services (as `supervisor up --instance`).
    #[arg(long, default_value = DEFAULT_INSTANCE, value_parser = instance_name)]
    instance: InstanceName,
    /// The process' entry in the cell's process table (default: the program's own name).
    #[arg(long, value_parser = process_name)]
    name: Option<ProcessName>,
}

fn instance_name(s: &str) -> Result<InstanceName, String> {
    InstanceName::new(s).map_err(|e| e.to_string())
}

fn process_name(s: &str) -> Result<ProcessName, String> {
    ProcessName::new(s).map_err(|e| e.to_string())
}

/// The instance and the process' name from the command line, or how to exit: 0 after
/// `--help`, 2 after an argument clap refused (its message names it).
fn parse_args(default_name: &str, about: &str) -> Result<(InstanceName, ProcessName), ExitCode> {
    use clap::{CommandFactory, FromArgMatches};
    let cmd = Args::command()
        .name(default_name.to_string())
        .about(about.to_string())
        .after_help(format!(
            "Started by the supervisor; reads its settings from the cell configuration the \
             supervisor publishes for the instance, in the process table entry called NAME \
             (default {default_name})."
        ));
    let args = cmd
        .try_get_matches()
        .and_then(|m| Args::from_arg_matches(&m))
        .map_err(|e| {
            let _ = e.print();
            ExitCode::from(if e.use_stderr() { 2 } else { 0 })
        })?;
    let name = match args.name {
        Some(n) => n,
        None => process_name(default_name).map_err(|e| {
            eprintln!("{default_name}: {e}");
            ExitCode::from(2)
        })?,
    };
    Ok((args.instance, name))
}

/// How a process' cycle ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Exit {
    /// A stop was asked (SIGTERM, SIGINT) and the task came to a safe stop.
    Stopped,
    /// The supervisor stopped beating: the task was brought to a safe stop.
    SupervisorLost,
}

fn run_inner<T: Task>(
    name: ProcessName,
    instance: InstanceName,
    build: impl FnOnce(&Context) -> Result<T, SetupError>,
) -> Result<Exit, SetupError> {
    signals::install()?;
    let node = ipc::node(&instance, name.as_str())?;
    let Some(cell) = wait_for_cell_config(&node, &instance)? else {
        return Ok(Exit::Stopped); // stopped before the cell configuration arrived
    };
    let ctx = Context::of(instance, name, node, cell)?;
    let (priority, cpu) = (ctx.own.priority, usize::try_from(ctx.own.cpu).ok());
    let mut runner = Runner::new(ctx, build)?;
    // The real-time set-up after the task's own (a bus' bring-up runs under SCHED_OTHER).
    let (rt, rt_guard) = rt::setup(RtRequest { priority, cpu });
    runner.start(rt);
    // The cycle. Nothing in it allocates, locks or logs (see `Task::cycle`, `Runner::cycle`).
    loop {
        let wake = match runner.clock.wait() {
            Ok(w) => w,
            Err(WaitError::Interrupted) => continue,
            Err(WaitError::Os(e)) => {
                return Err(format!("clock_nanosleep failed: errno {e}").into());
            }
        };
        if runner.cycle(&wake) == Flow::Leave {
            break;
        }
    }
    // Out of the cycle, out of real time: what follows (the task's stop, the last status,
    // the log's flush) runs under SCHED_OTHER (see `RtGuard`).
    drop(rt_guard);
    Ok(runner.finish())
}

impl Context {
    /// The context of process `name` in `cell`: its entry in the process table, found by name.
    pub fn of(
        instance: InstanceName,
        name: ProcessName,
        node: Node<Ipc>,
        cell: CellConfigV6,
    ) -> Result<Self, SetupError> {
        let Some((index, own)) = cell.process_named(name.as_str()).map(|(i, p)| (i, *p)) else {
            return Err(format!(
                "the cell configuration has no process called {name:?} (its process table: {})",
                cell.processes()
                    .iter()
                    .map(|p| shm_schema::str_of(&p.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
            .into());
        };
        Ok(Self {
            instance,
            name,
            index,
            own,
            node,
            cell,
        })
    }
}

/// What the loop does after a cycle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    /// Wait for the next wake-up.
    Next,
    /// The process is leaving (a stop was asked or the supervisor is lost) and its task is
    /// safe, or took longer than the e-stop stop time and [`LEAVE_GRACE_NS`]: end the loop.
    Leave,
}

/// A process of the cell once set up: its task, its clock, its ports (status, histograms,
/// events, e-stop) and its health detectors, one cycle at a time ([`Runner::cycle`]). [`run`]
/// is a loop over it; a test drives it cycle by cycle.
pub struct Runner<T: Task> {
    ctx: Context,
    task: T,
    /// The process' clock: [`CycleClock::wait`] gives the next wake-up.
    pub clock: CycleClock,
    status: ProcessStatusV2,
    status_pub: Pub<ProcessStatusV2>,
    latency: Snapshot,
    exec: Snapshot,
    events: EventSink,
    estop: EstopWatch,
    queue: EventQueue,
    health: Health,
    overruns: OverrunReporter,
    /// Cycles between two publications of a histogram, and the execution time's offset.
    latency_every: u64,
    exec_phase: u64,
    leave_limit_ns: u64,
    skipped: u64,
    transport: u64,
    leaving_since: Option<u64>,
    safe_reported: bool,
    /// On the virtual clock, its side until [`Runner::start`] hands it to the clock.
    virtual_clock: Option<crate::vclock::Participant>,
}

impl<T: Task> std::fmt::Debug for Runner<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Runner")
            .field("name", &self.ctx.name.as_str())
            .field("cycles", &self.clock.stats().cycles)
            .finish_non_exhaustive()
    }
}

impl<T: Task> Runner<T> {
    /// Opens the process' ports and builds its task; [`Runner::start`] then starts it.
    pub fn new(
        ctx: Context,
        build: impl FnOnce(&Context) -> Result<T, SetupError>,
    ) -> Result<Self, SetupError> {
        let (instance, name, own) = (ctx.instance, ctx.name, ctx.own);
        // On the virtual clock, everything from here on reads it.
        let virtual_clock = if ctx.cell.clock == shm_schema::CellClock::Virtual as u32 {
            Some(crate::vclock::Participant::new(
                &ctx.node,
                &instance,
                ctx.index as u32,
            )?)
        } else {
            None
        };
        let status_pub =
            Pub::<ProcessStatusV2>::new(&ctx.node, &instance, ServiceId::Status(name))?;
        let latency_every = LATENCY_PUBLISH_INTERVAL_NS.div_ceil(own.period_ns).max(1);
        // Each histogram's snapshot done within half an interval: the two never overlap.
        let slices = (latency_every / 2).max(1) as usize;
        let latency = Snapshot::new(&ctx.node, &instance, ServiceId::Latency(name), slices)?;
        let exec = Snapshot::new(&ctx.node, &instance, ServiceId::ExecTime(name), slices)?;
        let events = EventSink::new(&ctx.node, &instance, ctx.index as u32)?;
        let estop = EstopWatch::new(&ctx.node, &instance, &ctx.cell, ctx.index, now_ns())?;
        let task = build(&ctx)?;
        // Connect to the subscribers that exist now (the supervisor's), so the first event in
        // the cycle does not pay for it.
        events.connect();
        estop.connect();
        let status = ProcessStatusV2 {
            pid: std::process::id(),
            index: ctx.index as u32,
            state: ProcState::Starting as u32,
            name: name.field(),
            ..ProcessStatusV2::default()
        };
        let start_ns = now_ns();
        Ok(Self {
            clock: CycleClock::new(own.period_ns, own.phase_ns, start_ns),
            health: Health::new(&ctx.cell.health, own.period_ns, start_ns),
            leave_limit_ns: ctx.cell.estop_stop_time_ns.saturating_add(LEAVE_GRACE_NS),
            latency_every,
            // The execution-time histogram half an interval after the wake-up latency's.
            exec_phase: latency_every / 2,
            ctx,
            task,
            status,
            status_pub,
            latency,
            exec,
            events,
            estop,
            queue: EventQueue::default(),
            overruns: OverrunReporter::default(),
            skipped: 0,
            transport: ipc::transport_errors(),
            leaving_since: None,
            safe_reported: false,
            virtual_clock,
        })
    }

    /// Publishes the first status (state `Starting`, with what the real-time set-up `rt`
    /// got), says so in the log and starts the clock from now: the first wake-up is the next
    /// deadline on the process' grid.
    pub fn start(&mut self, rt: rt::RtReport) {
        let (name, instance, own) = (self.ctx.name, self.ctx.instance, self.ctx.own);
        self.status.policy = rt.policy;
        self.status.priority = rt.priority;
        self.status.cpu = rt.cpu;
        self.status.rt_flags = rt.flags;
        self.status_pub.send(&self.status);
        tracing::info!(
            "{name} ({instance}) cyclic: period {} µs, phase {} µs, {} priority {}{}",
            own.period_ns / 1000,
            own.phase_ns / 1000,
            rt::policy_name(rt.policy),
            rt.priority,
            if rt.cpu >= 0 {
                format!(", CPU {}", rt.cpu)
            } else {
                String::new()
            }
        );
        let start_ns = now_ns();
        self.clock = CycleClock::new(own.period_ns, own.phase_ns, start_ns);
        if let Some(p) = self.virtual_clock.take() {
            self.clock.on_virtual_clock(p);
        }
        self.health = Health::new(&self.ctx.cell.health, own.period_ns, start_ns);
        self.status.state = ProcState::Cyclic as u32;
    }

    /// The task.
    pub fn task(&self) -> &T {
        &self.task
    }

    /// One cycle from `wake`: the e-stop read, the task's cycle, an e-stop it raises, the
    /// health detectors, the status (every cycle), a histogram (one of the two every
    /// [`LATENCY_PUBLISH_INTERVAL_NS`] / 2), an overrun burst, the events; then the clock's
    /// execution time.
    ///
    /// # Real-time
    /// No allocation, lock or log of its own: arithmetic, copies and the IPC calls (each
    /// publish may allocate once inside iceoryx2: `ipc`; `tests/runner.rs` counts them).
    pub fn cycle(&mut self, wake: &Wake) -> Flow {
        let now = wake.actual_ns;
        let own_critical = self.ctx.own.critical();
        if signals::stop_requested() {
            self.estop.leave();
        }
        if self.estop.poll(now, &mut self.queue) {
            self.health.restart(now);
            self.safe_reported = false;
        }
        if self.estop.leaving() && self.leaving_since.is_none() {
            self.leaving_since = Some(now);
            self.status.state = ProcState::Stopping as u32;
        }
        let mut cx = Cycle {
            wake,
            clock: &mut self.clock,
            events: &mut self.queue,
            estop: *self.estop.view(),
            handover: self.estop.handover(),
            raise: None,
            pending: 0,
            transport: 0,
            safe: true,
        };
        self.task.cycle(&mut cx);
        let (raise, mut pending, safe) = (cx.raise, cx.pending, cx.safe);
        let own_transport = cx.transport;
        if let Some((origin, cause, reason)) = raise
            && !self.estop.raised()
        {
            self.estop.raise(
                now,
                origin,
                cause,
                &[shm_schema::str_of(&reason)],
                &mut self.queue,
            );
        }
        // Periods this process skipped: its outputs missed that many syncs.
        let s = self.clock.stats().skipped;
        pending += s - self.skipped;
        self.skipped = s;
        if self.estop.handover() {
            // A process of the cell is being replaced: its gap is announced, not a fault.
            pending = 0;
        }
        let t = ipc::transport_errors();
        let expired = self.health.cycle(
            now,
            wake.latency_ns(),
            pending,
            t - self.transport + own_transport,
        );
        self.transport = t;
        if let Some(d) = expired
            && (!own_critical || !self.estop.view().latched)
        {
            self.detector_expired(now, d, own_critical);
        }
        let view = *self.estop.view();
        if view.latched
            && view.react.is_some()
            && safe
            && !self.safe_reported
            && !self.estop.leaving()
        {
            self.safe_reported = true;
            self.queue.push(EventV1::new(
                now,
                code::ESTOP_SAFE,
                -1,
                now.saturating_sub(view.since_ns) as f64 * 1e-9,
                0.0,
                &["e-stop reaction complete"],
            ));
        }
        self.publish_status(now, &view, safe);
        if let Some(e) = self.overruns.check(now, self.clock.stats().overruns) {
            self.queue.push(e);
        }
        self.events.drain(&mut self.queue);
        self.clock.finish(wake, now_ns());
        match self.leaving_since {
            Some(since) if safe || now.saturating_sub(since) > self.leave_limit_ns => Flow::Leave,
            _ => Flow::Next,
        }
    }

    /// A health detector expired: an event; for a critical process an e-stop, for another
    /// a warning and the detectors start afresh.
    ///
    /// # Real-time
    /// Copies only.
    fn detector_expired(&mut self, now: u64, d: crate::health::Detector, critical: bool) {
        let r = self.health.bucket(d).report(now);
        let what = if critical {
            code::HEALTH_EXPIRED
        } else {
            code::NOT_CRITICAL_FAILED
        };
        let (level, limit) = (f64::from(r.level), f64::from(r.limit));
        self.queue.push(EventV1::new(
            now,
            what,
            -1,
            level,
            limit,
            &[d.name(), " expired"],
        ));
        if critical {
            self.estop.raise(
                now,
                EstopOrigin::Host,
                code::HEALTH_EXPIRED,
                &[d.name(), " expired in ", self.ctx.name.as_str()],
                &mut self.queue,
            );
        } else {
            self.health.restart(now);
        }
    }

    /// The status every cycle; the two histograms (30 KB each) half an interval apart, each
    /// a slice per cycle ([`Snapshot`]: its slices done within half an interval, 16 of them
    /// (1.9 KB each) at 1 kHz, 12 at 250 Hz).
    ///
    /// # Real-time
    /// Copies and the IPC calls only.
    fn publish_status(&mut self, now: u64, view: &EstopView, safe: bool) {
        let st = &mut self.status;
        st.stamp_ns = now;
        st.fault = self.task.fault();
        st.stats = *self.clock.stats();
        st.pending_sequence = self.health.pending.report(now);
        st.transport = self.health.transport.report(now);
        st.thread_offset = self.health.offset.report(now);
        let bit = |on: bool, b: u32| if on { b } else { 0 };
        let reacting = view.react.is_some();
        st.estop = bit(view.latched, estop_seen::LATCHED)
            | bit(reacting, estop_seen::REACTING)
            | bit(reacting && safe, estop_seen::SAFE)
            | bit(self.estop.raised(), estop_seen::RAISED);
        self.status_pub.send(st);
        let phase = st.stats.cycles % self.latency_every;
        if phase == 0 {
            self.latency.begin();
        }
        if phase == self.exec_phase {
            self.exec.begin();
        }
        let (latency, exec) = (st.stats.wakeup_latency_ns, st.stats.exec_ns);
        self.latency.step(self.clock.histogram(), latency);
        self.exec.step(self.clock.exec_histogram(), exec);
    }

    /// After the loop: the task's stop, its last events, the last status and histograms, and
    /// one line of figures; how the process ends.
    pub fn finish(mut self) -> Exit {
        let (name, instance) = (self.ctx.name, self.ctx.instance);
        self.task.stop(now_ns(), &mut self.queue);
        self.events.drain(&mut self.queue);
        self.status.state = ProcState::Stopping as u32;
        self.status_pub.send(&self.status);
        self.latency.send_whole(self.clock.histogram());
        self.exec.send_whole(self.clock.exec_histogram());
        let h = self.clock.histogram();
        let us = |v: Option<u64>| v.unwrap_or(0) as f64 * 1e-3;
        tracing::info!(
            "{name} ({instance}) stopped after {} cycles, {} overruns; wake-up latency p50 {:.1} µs, \
             p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs",
            self.clock.stats().cycles,
            self.clock.stats().overruns,
            us(h.percentile(1, 2)),
            us(h.percentile(99, 100)),
            us(h.percentile(999, 1000)),
            us(Some(h.max_ns)),
        );
        // Off the virtual clock once everything of the last cycle is out.
        self.clock.leave();
        if self.estop.supervisor_lost() && !signals::stop_requested() {
            Exit::SupervisorLost
        } else {
            Exit::Stopped
        }
    }
}

/// Turns the overrun counter into events: one at the first overrun of a burst, then at most
/// one per [`OVERRUN_EVENT_INTERVAL_NS`] while overruns go on, each with the overruns since the
/// previous event.
#[derive(Clone, Copy, Debug, Default)]
pub struct OverrunReporter {
    reported: u64,
    last_event_ns: u64,
}

impl OverrunReporter {
    /// The event to publish at `now_ns` given the process' overrun count, if any.
    ///
    /// # Real-time
    /// Arithmetic only.
    pub fn check(&mut self, now_ns: u64, overruns: u64) -> Option<EventV1> {
        if overruns <= self.reported
            || (self.last_event_ns > 0
                && now_ns.saturating_sub(self.last_event_ns) < OVERRUN_EVENT_INTERVAL_NS)
        {
            return None;
        }
        let new = overruns - self.reported;
        self.reported = overruns;
        self.last_event_ns = now_ns;
        Some(EventV1::new(
            now_ns,
            code::OVERRUN_BURST,
            -1,
            new as f64,
            0.0,
            &["cycle ran past its next deadline"],
        ))
    }
}

/// Waits (set-up only, polling every 2 ms) for the cell configuration and validates it;
/// `None` if a stop was requested meanwhile.
fn wait_for_cell_config(
    node: &Node<Ipc>,
    instance: &InstanceName,
) -> Result<Option<CellConfigV6>, SetupError> {
    let Some(cell) = wait_for::<CellConfigV6>(
        node,
        instance,
        ServiceId::CellConfig,
        &format!("is `supervisor up --instance {instance}` running?"),
    )?
    else {
        return Ok(None);
    };
    validate_cell(&cell)?;
    Ok(Some(cell))
}

/// The sample a service keeps for late joiners (a configuration the supervisor published
/// with history 1), waited for at most [`CONFIG_TIMEOUT`]; `None` when a stop was requested
/// meanwhile. Set-up only. `missing` ends the error when nothing came.
pub fn wait_for<T: ipc::Payload>(
    node: &Node<Ipc>,
    instance: &InstanceName,
    id: ServiceId,
    missing: &str,
) -> Result<Option<T>, SetupError> {
    let sub = Sub::<T>::new(node, instance, id, 1)?;
    let start = Instant::now();
    loop {
        if let Some(sample) = sub.latest() {
            return Ok(Some(sample));
        }
        if signals::stop_requested() {
            return Ok(None);
        }
        if start.elapsed() > CONFIG_TIMEOUT {
            return Err(format!(
                "nothing on {} after {} s: {missing}",
                instance.service(id),
                CONFIG_TIMEOUT.as_secs()
            )
            .into());
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Checks what a process relies on; the supervisor validated everything else.
pub fn validate_cell(cell: &CellConfigV6) -> Result<(), String> {
    if cell.axes == 0 || cell.axes as usize > shm_schema::MAX_AXES {
        return Err(format!(
            "cell configuration has {} axes, 1..={} allowed",
            cell.axes,
            shm_schema::MAX_AXES
        ));
    }
    if cell.process_count == 0 || cell.process_count as usize > shm_schema::MAX_PROCESSES {
        return Err(format!(
            "cell configuration has {} processes, 1..={} allowed",
            cell.process_count,
            shm_schema::MAX_PROCESSES
        ));
    }
    for p in cell.processes() {
        if p.period_ns == 0 {
            return Err(format!(
                "cell configuration: period of {} is 0",
                shm_schema::str_of(&p.name)
            ));
        }
    }
    if shm_schema::CellClock::from_wire(cell.clock).is_none() {
        return Err(format!(
            "cell configuration: clock {} is neither 0 (the wall clock) nor 1 (the virtual clock)",
            cell.clock
        ));
    }
    if !(cell.t_acc_s.is_finite() && cell.t_acc_s > 0.0) {
        return Err(format!(
            "cell configuration: t_acc {} s is not positive",
            cell.t_acc_s
        ));
    }
    Ok(())
}
