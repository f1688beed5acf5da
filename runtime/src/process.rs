//! The skeleton of every real-time process of a cell.
//!
//! `main` of trajgen, servo, machine-sim and iobridge is one call to [`run`]:
//!
//! 1. arguments: `--instance NAME` (default `gantry`);
//! 2. SIGTERM/SIGINT handler, iceoryx2 node;
//! 3. the cell configuration from `<i>/cell/config` (published by the supervisor);
//! 4. the task's own set-up (`build`: opens ports, preallocates, validates) — may fail;
//! 5. real-time set-up ([`crate::rt::setup`]) with the role's priority and CPU;
//! 6. the cycle until SIGTERM: wait, [`Task::cycle`], publish [`ProcessStatusV1`], finish;
//!    about every 100 ms, and once more on stopping, publish the wake-up latency histogram
//!    ([`LatencyHistogramV1`] on `<i>/<role>/latency`);
//! 7. a clean exit that removes the process' iceoryx2 resources.

use crate::cycle::{CycleClock, WaitError, Wake};
use crate::events::EventSink;
use crate::ipc::{self, Ipc, Pub, Sub};
use crate::rt::{self, RtRequest};
use crate::signals;
use crate::time::now_ns;
use iceoryx2::prelude::Node;
use shm_schema::event::code;
use shm_schema::{
    CellConfigV2, EventQueue, EventV1, InstanceName, LatencyHistogramV1, ProcState,
    ProcessStatusV1, Role, ServiceId,
};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Instance used when no `--instance` is given.
pub const DEFAULT_INSTANCE: &str = "gantry";

/// How often a process publishes its latency histogram (at most; once per cycle if slower).
pub const LATENCY_PUBLISH_INTERVAL_NS: u64 = 100_000_000;

/// Overruns are reported as an event at most this often (ns).
pub const OVERRUN_EVENT_INTERVAL_NS: u64 = 1_000_000_000;

/// How long a process waits for the cell configuration before giving up.
pub const CONFIG_TIMEOUT: Duration = Duration::from_secs(10);

/// Everything a task's set-up may use.
#[derive(Debug)]
pub struct Context {
    /// Instance the process belongs to.
    pub instance: InstanceName,
    /// Role of the process.
    pub role: Role,
    /// The process' iceoryx2 node; open ports with [`Pub::new`] and [`Sub::new`].
    pub node: Node<Ipc>,
    /// The validated cell configuration.
    pub cell: CellConfigV2,
}

/// The periodic work of a process.
pub trait Task {
    /// One cycle, started by `wake`. May ask `clock` for an extra wake-up, and queue events
    /// in `events` (the runtime publishes them on `<i>/events` after the cycle).
    ///
    /// # Real-time
    /// Implementations allocate nothing of their own, take no lock, log nothing, and make no
    /// system call but IPC calls.
    fn cycle(&mut self, wake: &Wake, clock: &mut CycleClock, events: &mut EventQueue);

    /// The process' fault code for its status (0 for none).
    fn fault(&self) -> u32 {
        0
    }

    /// Called once when the cycle ends (a stop was requested), before the last status.
    fn stop(&mut self, _now_ns: u64, _events: &mut EventQueue) {}
}

/// Error type of a task's set-up.
pub type SetupError = Box<dyn std::error::Error + Send + Sync>;

/// Runs a real-time process; see the module documentation. Exit code 0 after a requested
/// stop, 1 after a set-up failure, 2 on bad arguments.
pub fn run<T: Task>(
    role: Role,
    about: &str,
    build: impl FnOnce(&Context) -> Result<T, SetupError>,
) -> ExitCode {
    init_logging();
    let instance = match parse_args(role, about) {
        Ok(Some(i)) => i,
        Ok(None) => return ExitCode::SUCCESS,
        Err(msg) => {
            eprintln!(
                "{}: {msg}\nusage: {} [--instance NAME]",
                role.name(),
                role.name()
            );
            return ExitCode::from(2);
        }
    };
    match run_inner(role, instance, build) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{} ({instance}): {e}", role.name());
            ExitCode::FAILURE
        }
    }
}

/// Logging to stderr, filtered by `RTC_LOG` (default `info`). Used by every binary.
pub fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_env("RTC_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_target(false)
        .try_init();
    ipc::quiet_iceoryx2_log();
}

fn parse_args(role: Role, about: &str) -> Result<Option<InstanceName>, String> {
    let mut instance = DEFAULT_INSTANCE.to_string();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--instance" => instance = args.next().ok_or("--instance needs a NAME")?,
            s if s.starts_with("--instance=") => instance = s["--instance=".len()..].to_string(),
            "-h" | "--help" => {
                println!(
                    "{} — {about}\n\nusage: {} [--instance NAME]\n\nStarted by `supervisor run`; \
                     reads its settings from the cell configuration the supervisor publishes \
                     for instance NAME (default {DEFAULT_INSTANCE}).",
                    role.name(),
                    role.name()
                );
                return Ok(None);
            }
            other => return Err(format!("unknown argument {other:?}")),
        }
    }
    InstanceName::new(&instance)
        .map(Some)
        .map_err(|e| e.to_string())
}

fn run_inner<T: Task>(
    role: Role,
    instance: InstanceName,
    build: impl FnOnce(&Context) -> Result<T, SetupError>,
) -> Result<(), SetupError> {
    signals::install()?;
    let node = ipc::node(&instance, role.name())?;
    let Some(cell) = wait_for_cell_config(&node, &instance)? else {
        return Ok(()); // stopped before the cell configuration arrived: nothing to do
    };
    let pc = cell.process[role.index()];
    let ctx = Context {
        instance,
        role,
        node,
        cell,
    };
    let status_pub = Pub::<ProcessStatusV1>::new(&ctx.node, &instance, ServiceId::Status(role))?;
    let latency_pub =
        Pub::<LatencyHistogramV1>::new(&ctx.node, &instance, ServiceId::Latency(role))?;
    let exec_pub = Pub::<LatencyHistogramV1>::new(&ctx.node, &instance, ServiceId::ExecTime(role))?;
    let mut events = EventSink::new(&ctx.node, &instance, role as u32)?;
    let mut queue = EventQueue::default();
    let mut task = build(&ctx)?;
    // Connect to the subscribers that exist now (the supervisor's), so the first event in the
    // cycle does not pay for it.
    events.connect();

    let (report, _rt_guard) = rt::setup(RtRequest {
        priority: pc.priority,
        cpu: usize::try_from(pc.cpu).ok(),
    });
    let mut status = ProcessStatusV1 {
        pid: std::process::id(),
        role: role as u32,
        state: ProcState::Starting as u32,
        policy: report.policy,
        priority: report.priority,
        cpu: report.cpu,
        rt_flags: report.flags,
        ..ProcessStatusV1::default()
    };
    status_pub.send(&status);
    tracing::info!(
        "{} ({instance}) cyclic: period {} µs, phase {} µs, {} priority {}{}",
        role.name(),
        pc.period_ns / 1000,
        pc.phase_ns / 1000,
        rt::policy_name(report.policy),
        report.priority,
        if report.cpu >= 0 {
            format!(", CPU {}", report.cpu)
        } else {
            String::new()
        }
    );

    let mut clock = CycleClock::new(pc.period_ns, pc.phase_ns, now_ns());
    let latency_every = LATENCY_PUBLISH_INTERVAL_NS.div_ceil(pc.period_ns).max(1);
    let mut overruns = OverrunReporter::default();
    status.state = ProcState::Cyclic as u32;
    // The cycle. Nothing in this loop allocates, locks or logs (see `Task::cycle`).
    while !signals::stop_requested() {
        let wake = match clock.wait() {
            Ok(w) => w,
            Err(WaitError::Interrupted) => continue,
            Err(WaitError::Os(e)) => {
                return Err(format!("clock_nanosleep failed: errno {e}").into());
            }
        };
        task.cycle(&wake, &mut clock, &mut queue);
        status.stamp_ns = wake.actual_ns;
        status.fault = task.fault();
        status.stats = *clock.stats();
        status_pub.send(&status);
        if status.stats.cycles.is_multiple_of(latency_every) {
            latency_pub.send(clock.histogram());
            exec_pub.send(clock.exec_histogram());
        }
        if let Some(e) = overruns.check(wake.actual_ns, clock.stats().overruns) {
            queue.push(e);
        }
        events.drain(&mut queue);
        clock.finish(&wake, now_ns());
    }
    task.stop(now_ns(), &mut queue);
    events.drain(&mut queue);
    status.state = ProcState::Stopping as u32;
    status_pub.send(&status);
    latency_pub.send(clock.histogram());
    exec_pub.send(clock.exec_histogram());
    let h = clock.histogram();
    let us = |v: Option<u64>| v.unwrap_or(0) as f64 * 1e-3;
    tracing::info!(
        "{} ({instance}) stopped after {} cycles, {} overruns; wake-up latency p50 {:.1} µs, \
         p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs",
        role.name(),
        clock.stats().cycles,
        clock.stats().overruns,
        us(h.percentile(1, 2)),
        us(h.percentile(99, 100)),
        us(h.percentile(999, 1000)),
        us(Some(h.max_ns)),
    );
    Ok(())
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
) -> Result<Option<CellConfigV2>, SetupError> {
    let sub = Sub::<CellConfigV2>::new(node, instance, ServiceId::CellConfig, 1)?;
    let start = Instant::now();
    loop {
        if let Some(cell) = sub.latest() {
            validate_cell(&cell)?;
            return Ok(Some(cell));
        }
        if signals::stop_requested() {
            return Ok(None);
        }
        if start.elapsed() > CONFIG_TIMEOUT {
            return Err(format!(
                "no cell configuration on {} after {} s: is `supervisor run --instance {instance}` running?",
                instance.service(ServiceId::CellConfig),
                CONFIG_TIMEOUT.as_secs()
            )
            .into());
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Checks what a process relies on; the supervisor validated everything else.
pub fn validate_cell(cell: &CellConfigV2) -> Result<(), String> {
    if cell.axes == 0 || cell.axes as usize > shm_schema::MAX_AXES {
        return Err(format!(
            "cell configuration has {} axes, 1..={} allowed",
            cell.axes,
            shm_schema::MAX_AXES
        ));
    }
    for role in Role::ALL {
        if cell.process[role.index()].period_ns == 0 {
            return Err(format!(
                "cell configuration: period of {} is 0",
                role.name()
            ));
        }
    }
    if !(cell.t_acc_s.is_finite() && cell.t_acc_s > 0.0) {
        return Err(format!(
            "cell configuration: t_acc {} s is not positive",
            cell.t_acc_s
        ));
    }
    Ok(())
}
