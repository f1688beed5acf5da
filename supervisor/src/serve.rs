//! The supervisor's loop over a running cell, for `up` and `run` alike.
//!
//! Every tick (10 ms, or at once when a child exits or a client connects: the loop waits in
//! `poll` on the children's pidfds and the control channel), it:
//! 1. runs [`Cell::tick`]: the heartbeat, lost and stalled processes, restarts, the e-stop;
//! 2. advances what runs on the cell: the recorder's start (`--record`), enabling the arm,
//!    the program job;
//! 3. takes the control channel's requests and answers those that are complete.
//!
//! `run` is this loop with one program queued at the start, ending with it; `tune` the same
//! with a tuning session ([`crate::tuning::Tuning`]); `up` is this loop until `down` or a signal.
//!
//! Going down (`down`, SIGTERM, SIGINT) is a controlled stop, never a stop through a fault: a
//! program that moves comes to rest along its path first (as `abort` does), then servo disables
//! the drives at rest ([`Stopping`]); then the recorder finishes its file, the heartbeat
//! beating and the channel answering, and only then does the loop end and the processes stop.

use crate::cell::TICK;
use crate::cell::{Cell, Incident, Mode};
use crate::error::RunError;
use crate::job::{Enabling, Job};
use crate::launch::cpu_seconds;
use crate::program::{Checked, Predicted, Validation};
use crate::report::{Report, process_report};
use crate::swap::{Step, Swap};
use crate::tuning::{Measured, Tuning};
use cell_config::Config;
use control_plane::channel::{ConnId, Server};
use control_plane::event as events;
use control_plane::event::Event;
use control_plane::info::{Info, JobInfo, LastJob};
use control_plane::report::Outcome;
use control_plane::report::ProcessReport;
use control_plane::{Failure, Refusal, Reply, Request};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use runtime::rt::sched_of;
use runtime::signals;
use runtime::time::Moment;
use shm_schema::drive::servo_status as st;
use shm_schema::event::code;
use shm_schema::{ControlKind, EstopOrigin};
use std::time::Duration;

/// A program to run.
pub(crate) struct ProgramJob {
    /// Parsed and checked against the cell's limits.
    pub program: Checked,
    /// Print progress on stderr.
    pub progress: bool,
    /// Build the figures at its end (`run --plot`).
    pub plot: bool,
}

/// What `run` and `tune` queue for once the drives are enabled.
pub(crate) enum First {
    /// `run`'s program.
    Program(ProgramJob),
    /// `tune`'s session.
    Tune(Tuning),
}

/// How the loop ended, and the recording's summary (`--record`; none when it never
/// recorded).
pub(crate) struct Served {
    pub(crate) end: End,
    pub(crate) recorded: Option<Result<String, recorder::RecordError>>,
}

/// Why the loop ended.
pub(crate) enum End {
    /// `supervisor down`.
    Down,
    /// SIGINT or SIGTERM.
    Interrupted,
    /// `run`: the program ended (or the cell failed before it could start).
    Program(Box<Result<Report, RunError>>),
    /// `tune`: the session ended (or the cell failed before it could start).
    Tuned(Box<Result<Measured, RunError>>),
    /// `up`: the cell could not come up (a critical process exited, stalled or never cycled
    /// before every one of them had cycled once): a restart would not mend a configuration.
    Failed(Box<RunError>),
}

/// How long the user's e-stop waits for a process to report it latched.
const ESTOP_PATIENCE: Duration = Duration::from_secs(2);

/// A request whose answer waits for the cell.
enum Pending {
    Reset {
        conn: ConnId,
        since: Moment,
    },
    /// The user's e-stop, until a process reports it latched.
    Estop {
        conn: ConnId,
        reason: String,
        since: Moment,
    },
    Control {
        conn: ConnId,
        seq: u64,
        kind: ControlKind,
        since: Moment,
    },
}

impl Pending {
    /// Who waits for the answer.
    fn conn(&self) -> ConnId {
        match *self {
            Self::Reset { conn, .. } | Self::Estop { conn, .. } | Self::Control { conn, .. } => {
                conn
            }
        }
    }
}

/// The cell going down: where it stands on the way (see the module documentation).
struct Stopping {
    end: End,
    stage: StopStage,
    since: Moment,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum StopStage {
    /// trajgen was asked to abort: the path speed ramps to 0 within `t_acc`.
    Resting,
    /// servo was asked to disable: the drives power down at rest. `said_from`: how many
    /// times servo had said `disabled` when it was asked (`None`: the drives were not
    /// powered, nothing was asked).
    Disabling { said_from: Option<u64> },
}

/// A client waiting for a program's end (`exec --wait`), and what its report must carry.
#[derive(Clone, Copy, Debug)]
struct Waiter {
    conn: ConnId,
    trace: bool,
    figures: bool,
}

/// The program running now, who waits for it, and where its events start.
struct Running {
    job: Job,
    waiters: Vec<Waiter>,
    events_from: usize,
    started: Moment,
}

struct Loop<'a> {
    cfg: &'a Config,
    cell: &'a mut Cell,
    server: &'a mut Server,
    enabling: Option<(Enabling, Vec<ConnId>)>,
    queued: Option<First>,
    /// `tune`'s session, once the drives are enabled.
    tuning: Option<Tuning>,
    running: Option<Running>,
    pending: Vec<Pending>,
    /// The last program's end, for `status`.
    last_job: Option<LastJob>,
    down: bool,
    stopping: Option<Stopping>,
    /// A `swap` or `restart` in progress, who asked, and whether the drives were enabled.
    swapping: Option<Swapping>,
    /// A program being validated (on a thread of its own), and what follows.
    validating: Option<Validating>,
    /// Every critical process has cycled once: the cell came up.
    came_up: bool,
    /// `--record`'s recorder, and whether it records (the enabling waits for it).
    recorder: Option<recorder::Background>,
    recording: bool,
    /// How the loop ends, once it does: the recorder finishes its file meanwhile.
    ending: Option<End>,
}

/// A program being validated before it starts ([`Validation`]).
struct Validating {
    validation: Validation,
    then: Then,
    /// The cell's e-stop resets when it began: an e-stop latched and reset meanwhile drops
    /// the program (nobody asked for it after the stop).
    resets: u64,
}

/// What starts once a program is validated.
#[derive(Clone, Copy)]
enum Then {
    /// `exec`: answer who asked (at once, or at the program's end with `--wait`).
    Exec {
        conn: ConnId,
        waiter: Option<Waiter>,
    },
    /// `run`'s program.
    Run { progress: bool, plot: bool },
}

/// A replacement the loop steps ([`crate::swap`]).
struct Swapping {
    swap: Swap,
    conn: ConnId,
    was_enabled: bool,
}

/// Runs the loop; see the module documentation. `first` is `run`'s program; `recorder`,
/// spawned, records the cell (`--record`).
pub(crate) fn serve(
    cfg: &Config,
    cell: &mut Cell,
    server: &mut Server,
    first: Option<First>,
    recorder: Option<recorder::Background>,
) -> Served {
    let mut l = Loop {
        cfg,
        cell,
        server,
        enabling: Some((Enabling::new(cfg), Vec::new())),
        queued: first,
        tuning: None,
        running: None,
        pending: Vec::new(),
        last_job: None,
        down: false,
        stopping: None,
        swapping: None,
        validating: None,
        came_up: false,
        recorder,
        recording: false,
        ending: None,
    };
    loop {
        if let Some(end) = l.ending.take() {
            if let Some(recorded) = l.recorder_stopped() {
                l.server.drain(Duration::from_millis(200));
                return Served { end, recorded };
            }
            // The recorder finishes its file: the tick goes on (the heartbeat, the children
            // that exit reaped; nothing acts on an incident now), the channel answers
            // (whatever would change the cell is refused: it is going down).
            l.ending = Some(end);
            l.wait();
            let _ = l.cell.tick(cfg);
            l.cell.drain_motion();
            for (conn, req) in l.server.poll() {
                l.handle(conn, req);
            }
            continue;
        }
        l.wait();
        // Going down waits for a swap in progress to end (its steps are bounded).
        if signals::stop_requested() && l.stopping.is_none() && l.swapping.is_none() {
            l.go_down(End::Interrupted);
        }
        let cfg = l.cfg;
        let incidents = l.cell.tick(cfg);
        if l.stopping.is_some() {
            l.cell.drain_motion();
        } else if let Some(end) = l.advance(&incidents) {
            l.end(end);
            continue;
        }
        if l.stopping.is_none() {
            l.swap_step(&incidents);
        }
        let requests = l.server.poll();
        for (conn, req) in requests {
            l.handle(conn, req);
        }
        l.pending_step();
        if l.down && l.stopping.is_none() && l.swapping.is_none() {
            l.go_down(End::Down);
        }
        if let Some(end) = l.stop_step() {
            l.end(end);
        }
    }
}

impl Loop<'_> {
    /// Sleeps until the next tick, a child's exit or a client's request; on the virtual
    /// clock, runs the cell to its next tick instead (a client's request or a child's exit
    /// is taken at the tick: the same run every time), except while a program is validated:
    /// a validation takes no virtual time (the program starts at the same instant in every
    /// run), the clock stands and the loop waits as on the wall clock, answering its clients.
    fn wait(&mut self) {
        // The virtual clock stands while a program is validated and while the recorder
        // finishes its file (the same samples end it in every run).
        if self.cell.clock.is_some() && self.validating.is_none() && self.ending.is_none() {
            self.cell.advance_clock();
            return;
        }
        let server_fds = self.server.fds();
        let child_fds = self.cell.children.fds();
        let mut fds: Vec<PollFd> = server_fds
            .iter()
            .chain(child_fds.iter())
            .map(|fd| PollFd::new(*fd, PollFlags::POLLIN))
            .collect();
        let _ = poll(&mut fds, PollTimeout::from(TICK.as_millis() as u16));
    }

    /// Enabling, the job; `Some` when `run` is over.
    fn advance(&mut self, incidents: &[Incident]) -> Option<End> {
        let run = self.cell.mode == Mode::Run;
        // A tuning session reads every state itself.
        if self.running.is_none() && self.tuning.is_none() {
            self.cell.drain_motion();
            // Hours up: keep the newest events only (a job's own are kept whole).
            if self.cell.events.len() > 20_000 {
                self.cell.events.drain(..10_000);
            }
        }
        if !self.came_up {
            self.came_up = self.cell.critical_cyclic();
            // `run` ends on any incident below; `up` on one before it came up.
            if !run
                && !self.came_up
                && let Some(i) = incidents.first()
            {
                return Some(self.failed_to_come_up(i.error()));
            }
        }
        let recording = match self.recorder_started() {
            Ok(recording) => recording,
            Err(e) => return Some(self.failed_to_come_up(e)),
        };
        if let Some(end) = self.step_enabling(incidents, run, recording) {
            return Some(end);
        }
        // A process lost, stalled or in fault while a program is validated: it does not
        // start (a running job would fail on the same incident).
        if let Some(i) = incidents.first()
            && let Some(v) = self.validating.take()
            && let Some(end) = self.not_started(v.then, Err(i.error()))
        {
            return Some(end);
        }
        if let Some(v) = &mut self.validating
            && let Some(result) = v.validation.done()
        {
            let v = self.validating.take().expect("checked");
            if let Some(end) = self.validated(v, result) {
                return Some(end);
            }
        }
        if let Some(t) = &mut self.tuning
            && let Some(result) = t.step(self.cell, self.cfg, incidents)
        {
            self.tuning = None;
            return Some(End::Tuned(Box::new(result)));
        }
        // A swap that carries the program: its setpoints are recorded, nothing is sent.
        if let Some(r) = &mut self.running
            && self
                .swapping
                .as_ref()
                .is_some_and(|s| s.swap.carries_program())
        {
            r.job.record(self.cell);
            return None;
        }
        self.step_job(incidents, run)
    }

    /// Whether the recorder (`--record`) records, a step of its start: the enabling waits
    /// for it (nothing moves unrecorded). An error when it could not start.
    fn recorder_started(&mut self) -> Result<bool, RunError> {
        let Some(r) = self.recorder.as_mut() else {
            return Ok(true);
        };
        if self.recording {
            return Ok(true);
        }
        match r.started() {
            Ok(false) => Ok(false),
            Ok(true) => {
                self.recording = true;
                // The enabling's time counts from here.
                if let Some((en, _)) = &mut self.enabling {
                    *en = Enabling::new(self.cfg);
                }
                Ok(true)
            }
            Err(e) => {
                self.recorder = None;
                Err(RunError::from(e))
            }
        }
    }

    /// The recorder's stop, a step (it is asked to end the first time): `Some` once it
    /// ended, with its summary if it had started recording, or at once without one.
    fn recorder_stopped(&mut self) -> Option<Option<Result<String, recorder::RecordError>>> {
        let Some(r) = self.recorder.as_mut() else {
            return Some(None);
        };
        let ended = r.stopped()?;
        Some(self.recording.then_some(ended))
    }

    /// The loop ends with `end` once the recorder has finished its file; whoever still waits
    /// (a request, a swap) is told the cell goes down.
    fn end(&mut self, end: End) {
        self.abandon(|job: &str| Failure::Down {
            job: job.to_string(),
        });
        if let Some(s) = self.swapping.take() {
            let job = format!("the swap of {}", s.swap.process());
            self.server
                .reply(s.conn, &Reply::Failed(Failure::Down { job }));
        }
        self.ending = Some(end);
    }

    /// Whether the cell is going down: on its way to rest, or the loop ending.
    fn going_down(&self) -> bool {
        self.stopping.is_some() || self.ending.is_some()
    }

    /// The enabling, a step; once it is over, whoever asked is told and what waited for it
    /// (a tuning session, a program) begins. `Some` when `run` or `up` is over. It begins
    /// once the recorder (`--record`) records; `run` ends on an incident before that too.
    fn step_enabling(&mut self, incidents: &[Incident], run: bool, recording: bool) -> Option<End> {
        let (en, waiters) = self.enabling.as_mut()?;
        let outcome = if run && let Some(i) = incidents.first() {
            Some(Err(i.error()))
        } else if !recording {
            None
        } else {
            en.step(self.cell)
        };
        let result = outcome?;
        let waiters = std::mem::take(waiters);
        self.enabling = None;
        let result = match result {
            Err(e) if !run && !self.came_up => {
                for c in waiters {
                    self.server.reply(c, &Reply::Failed(e.cause()));
                }
                return Some(self.failed_to_come_up(e));
            }
            r => r,
        };
        let reply = match &result {
            Ok(_) => {
                tracing::info!("the drives are enabled, holding");
                Reply::Done("the drives are enabled, holding".into())
            }
            Err(e) => {
                tracing::error!("the arm is not enabled: {e}");
                match e {
                    RunError::Input(m) => Reply::Refused(Refusal::Enable { error: m.clone() }),
                    e => Reply::Failed(e.cause()),
                }
            }
        };
        for c in waiters {
            self.server.reply(c, &reply);
        }
        match (result, self.queued.take()) {
            (Ok(sp), Some(First::Tune(mut t))) => {
                t.begin(&sp);
                self.tuning = Some(t);
                None
            }
            (Ok(sp), Some(First::Program(p))) => {
                let n = self.cfg.axis.len();
                let then = Then::Run {
                    progress: p.progress,
                    plot: p.plot,
                };
                let e = self.validate(p.program, &sp.position[..n], then).err()?;
                Some(End::Program(Box::new(Err(self.with_events(e, 0)))))
            }
            (Err(e), Some(First::Tune(_))) => {
                Some(End::Tuned(Box::new(Err(self.with_events(e, 0)))))
            }
            (Err(e), Some(_)) => Some(End::Program(Box::new(Err(self.with_events(e, 0))))),
            (_, None) => None,
        }
    }

    /// The running job, a step; once it is over, its report (or its failure, with the events
    /// and figures) to whoever waits. `Some` when `run` is over.
    fn step_job(&mut self, incidents: &[Incident], run: bool) -> Option<End> {
        let r = self.running.as_mut()?;
        let result = r.job.step(self.cell, self.cfg, incidents)?;
        let r = self.running.take().expect("running: stepped above");
        let result = match result {
            Ok(mut report) => {
                self.cell.take_events();
                report.run.events = self.events_json(r.events_from);
                if !run {
                    self.cell.refresh_latency();
                    report.add_cell_figures(
                        process_reports(self.cell),
                        latency_figures(self.cell),
                        self.cell.sense_to_command.as_deref(),
                    );
                }
                Ok(report)
            }
            Err(e) => {
                // trajgen must not go on with a program nobody follows any more (its
                // OUTs, its queue): it comes to rest along the path and drops it.
                if self
                    .cell
                    .last_sp
                    .is_some_and(|sp| sp.state == shm_schema::MotionState::Moving as u32)
                {
                    self.cell.motion_control(ControlKind::Abort);
                }
                let e = self.with_events(e, r.events_from);
                Err(self.with_figures(e, &r.job))
            }
        };
        self.finish(&r, &result);
        run.then(|| End::Program(Box::new(result)))
    }

    /// Starts going down: whoever waits is told; a moving program comes to rest along its
    /// path (trajgen aborts it), or, at rest, the drives are disabled.
    fn go_down(&mut self, end: End) {
        // A program sent but not yet moving is dropped too (an abort empties trajgen's queue).
        let had_program = self.running.is_some() || self.tuning.take().is_some();
        let signal = matches!(end, End::Interrupted);
        self.abandon(|job: &str| {
            let job = job.to_string();
            if signal {
                Failure::Interrupted { job }
            } else {
                Failure::Down { job }
            }
        });
        let moving = had_program
            || self
                .cell
                .last_sp
                .is_some_and(|sp| sp.state == shm_schema::MotionState::Moving as u32);
        let stage = if moving && self.cell.estop.is_none() {
            tracing::info!("going down: the program comes to rest along its path");
            self.cell.motion_control(ControlKind::Abort);
            StopStage::Resting
        } else {
            StopStage::Disabling {
                said_from: self.disable(),
            }
        };
        self.stopping = Some(Stopping {
            end,
            stage,
            since: Moment::now(),
        });
    }

    /// `up`'s cell could not come up: how the loop ends, with the events that tell why.
    fn failed_to_come_up(&mut self, e: RunError) -> End {
        tracing::error!("the cell did not come up: {e}");
        let cause = e.cause();
        self.abandon(|_| cause.clone());
        End::Failed(Box::new(self.with_events(e, 0)))
    }

    /// Asks servo to disable the drives if they are powered (it brings its reference to rest
    /// along its path, then powers down); how many times it had said `disabled` when it was
    /// asked.
    fn disable(&mut self) -> Option<u64> {
        let powered = self.cell.last_servo.is_some_and(|s| {
            s.status & st::ENABLED != 0 || s.power != shm_schema::Power::Disabled as u8
        });
        if !powered {
            return None;
        }
        tracing::info!("going down: disabling the drives");
        if let Err(e) = self.cell.request(shm_schema::RequestKind::Disable) {
            tracing::warn!("going down: {e}");
        }
        Some(self.cell.disabled_said)
    }

    /// The next step of going down; `Some` once the processes may be stopped.
    fn stop_step(&mut self) -> Option<End> {
        let stage = self.stopping.as_ref()?.stage;
        let since = self.stopping.as_ref()?.since;
        let m = &self.cfg.motion;
        match stage {
            StopStage::Resting => {
                let at_rest = self
                    .cell
                    .last_sp
                    .is_none_or(|sp| sp.state != shm_schema::MotionState::Moving as u32);
                let limit = Duration::from_secs_f64(m.t_acc + 2.0);
                // An e-stop on the way: the cell's own reactions bring it to rest.
                if at_rest || self.cell.estop.is_some() || since.elapsed() > limit {
                    if !at_rest && self.cell.estop.is_none() {
                        tracing::warn!(
                            "going down: trajgen did not bring the program to rest within {:.1} s; \
                             servo brings its reference to rest",
                            limit.as_secs_f64()
                        );
                    }
                    let said_from = self.disable();
                    let s = self.stopping.as_mut()?;
                    s.stage = StopStage::Disabling { said_from };
                    s.since = Moment::now();
                }
                None
            }
            StopStage::Disabling { said_from } => {
                let off = self.cell.last_servo.is_none_or(|s| {
                    s.status & st::ENABLED == 0 && s.power == shm_schema::Power::Disabled as u8
                });
                // servo's `disabled` follows the state that shows it (published after its
                // cycle): waited for, so that it is among the cell's events (and its line in
                // the log) before the processes are told to stop. (A servo that never says
                // it costs `down` the limit below.)
                let said = said_from.is_none_or(|from| self.cell.disabled_said > from);
                let limit = Duration::from_secs_f64(m.estop_stop_time + 1.0);
                if !(off && said) && since.elapsed() <= limit {
                    return None;
                }
                if !off {
                    tracing::warn!(
                        "going down: the drives were not disabled within {:.1} s; the processes \
                         stop (each brings its part to rest as it leaves)",
                        limit.as_secs_f64()
                    );
                }
                self.stopping.take().map(|s| s.end)
            }
        }
    }

    /// The cell goes down (`why` of what was under way): whoever waits gets told, not
    /// dropped.
    fn abandon(&mut self, why: impl Fn(&str) -> Failure) {
        if let Some(v) = self.validating.take()
            && let Then::Exec { conn, .. } = v.then
        {
            self.server.reply(
                conn,
                &Reply::Failed(why(&format!(
                    "the validation of {}",
                    v.validation.program.name
                ))),
            );
        }
        if let Some(r) = self.running.take() {
            let e = self.with_events(RunError::failed(why(&r.job.name)), r.events_from);
            let e = self.with_figures(e, &r.job);
            self.finish(&r, &Err(e));
        }
        if let Some((_, waiters)) = self.enabling.take() {
            for c in waiters {
                self.server
                    .reply(c, &Reply::Failed(why("the drives were enabled")));
            }
        }
        for p in std::mem::take(&mut self.pending) {
            self.server
                .reply(p.conn(), &Reply::Failed(why("the request was answered")));
        }
    }

    fn events_json(&self, from: usize) -> Vec<Event> {
        self.cell.events[from.min(self.cell.events.len())..]
            .iter()
            .map(|e| events::event(e, &self.cell.axes, self.cell.t0_ns))
            .collect()
    }

    fn with_events(&mut self, e: RunError, from: usize) -> RunError {
        self.cell.take_events();
        match e {
            RunError::Failed {
                failure, figures, ..
            } => RunError::Failed {
                failure,
                events: self.events_json(from),
                figures,
            },
            e => e,
        }
    }

    /// A failed program's figures up to the failure, for `--plot` (when it was asked for).
    fn with_figures(&mut self, mut e: RunError, job: &Job) -> RunError {
        if let RunError::Failed { figures, .. } = &mut e
            && job.plot
        {
            self.cell.refresh_latency();
            let mut f = job.figures_so_far(self.cfg, self.cell);
            f.latency = latency_figures(self.cell);
            *figures = Some(Box::new(f));
        }
        e
    }

    fn begin(&mut self, job: Job, waiters: Vec<Waiter>) {
        tracing::info!("running {} (predicted {:.2} s)", job.name, job.predicted());
        self.running = Some(Running {
            job,
            waiters,
            events_from: self.cell.events.len(),
            started: Moment::now(),
        });
    }

    /// A program ended: its waiters get the report; `status` keeps a summary.
    fn finish(&mut self, r: &Running, result: &Result<Report, RunError>) {
        // The CSV trace only for a waiter that asked for it (it may be long).
        let wants_trace = r.waiters.iter().any(|w| w.trace);
        let (outcome, text, csv) = match result {
            Ok(rep) => (
                Outcome::Completed(Box::new(rep.run.clone())),
                rep.human(),
                wants_trace.then(|| crate::report::trace_csv(rep)),
            ),
            Err(e) => (Outcome::Failed(e.document()), e.to_string(), None),
        };
        let ok = outcome.ok();
        match result {
            Ok(rep) => tracing::info!(
                "{} done: {:.3} s measured, {:.3} s theoretical",
                r.job.name,
                rep.run.measured_s,
                rep.run.theoretical_s
            ),
            Err(e) => tracing::error!("{} failed: {e}", r.job.name),
        }
        self.last_job = Some(LastJob {
            program: r.job.name.clone(),
            ok,
            error: (!ok).then(|| text.clone()),
            measured_s: result.as_ref().ok().map(|r| r.run.measured_s),
            theoretical_s: result.as_ref().ok().map(|r| r.run.theoretical_s),
            ran_s: r.started.elapsed().as_secs_f64(),
        });
        for w in &r.waiters {
            let figures = match result {
                Ok(rep) if w.figures => rep.figures.clone(),
                Err(RunError::Failed {
                    figures: Some(f), ..
                }) if w.figures => Some(f.clone()),
                _ => None,
            };
            self.server.reply(
                w.conn,
                &Reply::Report {
                    outcome: outcome.clone(),
                    text: text.clone(),
                    trace_csv: if w.trace { csv.clone() } else { None },
                    figures,
                },
            );
        }
    }

    fn handle(&mut self, conn: ConnId, req: Request) {
        // The e-stop is taken whatever the cell is doing.
        if let Request::Estop { reason } = req {
            self.cell
                .raise(EstopOrigin::External, code::ESTOP_RAISED, &[&reason]);
            if self.going_down() {
                let done = format!(
                    "e-stop raised on instance {} (going down): {reason}",
                    self.cell.instance
                );
                self.server.reply(conn, &Reply::Done(done));
            } else {
                self.pending.push(Pending::Estop {
                    conn,
                    reason,
                    since: Moment::now(),
                });
            }
            return;
        }
        if self.going_down() && !matches!(req, Request::Info | Request::Status | Request::Network) {
            let reply = match req {
                Request::Down => Reply::Done(format!(
                    "instance {}: already going down",
                    self.cell.instance
                )),
                _ => Reply::Refused(Refusal::GoingDown {
                    instance: self.cell.instance.to_string(),
                }),
            };
            self.server.reply(conn, &reply);
            return;
        }
        // A tuning session or a swap in progress: what would change the cell waits for its
        // end; `down` ends a tuning session, and is kept for after a swap.
        if !matches!(
            req,
            Request::Info | Request::Status | Request::Network | Request::Down
        ) && let Some(busy) = self.busy()
        {
            self.server.reply(conn, &Reply::Refused(busy));
            return;
        }
        let reply = match req {
            Request::Info => Some(Reply::Info(Box::new(self.info()))),
            Request::Network => Some(Reply::Network(self.cfg.network.as_ref().map(|n| {
                let mut n = n.clone();
                n.name = n.line_name(&self.cfg.cell.name).ok();
                Box::new(n)
            }))),
            Request::Status => {
                let info = self.info();
                let snap = self.cell.snapshot();
                let status = control_plane::compose::status(&self.cell.instance, &snap, info);
                Some(Reply::Status(Box::new(status)))
            }
            Request::Exec {
                name,
                source,
                wait,
                trace,
                figures,
            } => {
                let waiter = wait.then_some(Waiter {
                    conn,
                    trace,
                    figures,
                });
                self.exec(conn, name, &source, waiter)
            }
            Request::Pause => self.control(conn, ControlKind::Pause),
            Request::Resume => self.control(conn, ControlKind::Resume),
            Request::Abort => self.control(conn, ControlKind::Abort),
            Request::Speed { percent } => self.speed(conn, percent),
            Request::Reset => self.reset(conn),
            Request::Start => self.start(conn),
            Request::Restart { process } => self.replace(conn, &process, None, false),
            Request::Swap { process, command } => self.replace(conn, &process, command, true),
            Request::Down => {
                self.down = true;
                Some(Reply::Done(format!(
                    "instance {}: going down",
                    self.cell.instance
                )))
            }
            Request::Estop { .. } => None, // taken above
        };
        if let Some(r) = reply {
            self.server.reply(conn, &r);
        }
    }

    /// Why the cell takes no change now: a tuning session or a swap holds it.
    fn busy(&self) -> Option<Refusal> {
        if let Some(t) = &self.tuning {
            return Some(Refusal::Tuning {
                axis: self.cfg.axis[t.axis()].name.clone(),
            });
        }
        self.swapping.as_ref().map(|s| Refusal::Replacing {
            process: s.swap.process().to_string(),
        })
    }

    fn info(&self) -> Info {
        let mut info = self.cell.info();
        info.job = self.running.as_ref().map(|r| {
            let sp = r.job.last;
            JobInfo {
                program: r.job.name.clone(),
                line: sp.map(|s| s.line),
                motion_time_s: sp.map(|s| s.motion_time_s),
                predicted_s: r.job.predicted(),
                path_speed: sp.map(|s| s.path_speed),
                paused: sp.is_some_and(|s| s.path_speed == 0.0),
            }
        });
        info.validating = self
            .validating
            .as_ref()
            .map(|v| v.validation.program.name.clone());
        info.last_job = self.last_job.clone();
        info.enabling = self.enabling.is_some();
        info.swapping = self.swapping.as_ref().map(|s| s.swap.process().to_string());
        info.tuning = self
            .tuning
            .as_ref()
            .map(|t| self.cfg.axis[t.axis()].name.clone());
        info.going_down = self.going_down();
        info
    }

    /// Why a program cannot start now, if it cannot.
    fn not_ready(&self) -> Option<Refusal> {
        if self.down {
            return Some(Refusal::GoingDown {
                instance: self.cell.instance.to_string(),
            });
        }
        if let Some(busy) = self.busy() {
            return Some(busy);
        }
        if let Some(v) = &self.validating {
            return Some(Refusal::Validating {
                program: v.validation.program.name.clone(),
            });
        }
        if let Some(r) = &self.running {
            return Some(Refusal::ProgramRunning {
                program: r.job.name.clone(),
            });
        }
        if let Some(sp) = self
            .cell
            .last_sp
            .filter(|sp| sp.state == shm_schema::MotionState::Moving as u32)
        {
            return Some(Refusal::Settling { line: sp.line });
        }
        if self.enabling.is_some() {
            return Some(Refusal::Enabling);
        }
        if let Some(estop) = self.cell.estop_failure() {
            return Some(Refusal::EstopLatched {
                estop: Box::new(estop),
            });
        }
        let enabled = self
            .cell
            .last_servo
            .is_some_and(|s| s.status & st::ENABLED != 0);
        if !enabled {
            return Some(Refusal::Disabled);
        }
        None
    }

    /// `exec`: the program is parsed and checked against the limits at once, then validated
    /// from where the axes stand on a thread of its own ([`Validation`]); it starts (and `exec`
    /// is answered) once that is done ([`Loop::validated`]).
    fn exec(
        &mut self,
        conn: ConnId,
        name: String,
        src: &[u8],
        waiter: Option<Waiter>,
    ) -> Option<Reply> {
        let program = match Checked::new(self.cfg, &name, src) {
            Ok(p) => p,
            Err(e) => {
                return Some(Reply::Refused(Refusal::Program {
                    error: e.to_string(),
                }));
            }
        };
        if let Some(why) = self.not_ready() {
            return Some(Reply::Refused(why));
        }
        let Some(sp) = self.cell.last_sp else {
            return Some(Reply::Refused(Refusal::NoSetpoint));
        };
        let n = self.cfg.axis.len();
        match self.validate(program, &sp.position[..n], Then::Exec { conn, waiter }) {
            Ok(()) => None,
            Err(e) => Some(Reply::Failed(e.cause())),
        }
    }

    /// Starts validating `program` from `start` (joint positions); `then` follows when done.
    fn validate(&mut self, program: Checked, start: &[f64], then: Then) -> Result<(), RunError> {
        self.validating = Some(Validating {
            validation: Validation::start(self.cfg, program, start)?,
            then,
            resets: self.cell.resets(),
        });
        Ok(())
    }

    /// A program being validated does not start: `run` ends with `why`, `exec` is answered
    /// with it (a refusal, or the failure). `Some` when `run` is over.
    fn not_started(&mut self, then: Then, why: Result<Refusal, RunError>) -> Option<End> {
        match then {
            Then::Run { .. } => {
                let e = match why {
                    Ok(Refusal::EstopLatched { estop }) => RunError::failed(*estop),
                    Ok(Refusal::FaultLatched { fault }) => RunError::failed(*fault),
                    Ok(refusal) => RunError::Input(refusal.to_string()),
                    Err(e) => e,
                };
                Some(End::Program(Box::new(Err(self.with_events(e, 0)))))
            }
            Then::Exec { conn, .. } => {
                let reply = match why {
                    Ok(refusal) => Reply::Refused(refusal),
                    Err(e) => Reply::Failed(e.cause()),
                };
                self.server.reply(conn, &reply);
                None
            }
        }
    }

    /// A validation is done: the program starts if the cell is still ready and the axes stand
    /// where it was validated from; else who asked is told why. `Some` when `run` is over.
    fn validated(&mut self, v: Validating, result: Result<Predicted, RunError>) -> Option<End> {
        let name = v.validation.program.name.clone();
        let n = self.cfg.axis.len();
        // Why it does not start: the validation's error, or the cell's state now (typed).
        let start: Result<_, Result<Refusal, RunError>> =
            match (result, self.not_ready(), self.cell.last_sp) {
                (Err(RunError::Input(error)), ..) => Err(Ok(Refusal::Program { error })),
                (Err(e), ..) => Err(Err(e)),
                (Ok(_), Some(why), _) => Err(Ok(why)),
                (Ok(_), None, None) => Err(Ok(Refusal::NoSetpoint)),
                (Ok(_), None, Some(_)) if self.cell.resets() != v.resets => {
                    Err(Ok(Refusal::StoppedMeanwhile {
                        program: name.clone(),
                    }))
                }
                (Ok(predicted), None, Some(sp)) => {
                    if sp.position[..n] == v.validation.start[..] {
                        Ok((predicted, sp))
                    } else {
                        Err(Ok(Refusal::MovedMeanwhile {
                            program: name.clone(),
                        }))
                    }
                }
            };
        let (predicted, sp) = match start {
            Ok(ok) => ok,
            Err(why) => return self.not_started(v.then, why),
        };
        let text = match predicted.iteration_s {
            Some(i) => format!(
                "started {name}: predicted {:.2} s, then {i:.2} s per iteration, for ever",
                predicted.duration_s
            ),
            None => format!("started {name}: predicted {:.2} s", predicted.duration_s),
        };
        let program = &v.validation.program;
        match v.then {
            Then::Run { progress, plot } => {
                let mut job = Job::new(self.cfg, program, predicted, &sp, progress);
                job.plot = plot;
                self.begin(job, Vec::new());
            }
            Then::Exec { conn, waiter } => {
                let mut job = Job::new(self.cfg, program, predicted, &sp, false);
                job.plot = waiter.is_some_and(|w| w.figures);
                self.cell.events.clear();
                self.begin(job, waiter.into_iter().collect());
                if waiter.is_none() {
                    self.server.reply(conn, &Reply::Done(text));
                }
            }
        }
        None
    }

    /// The live speed override: taken by trajgen at once, running program or not (it stays
    /// until changed).
    fn speed(&mut self, conn: ConnId, percent: f64) -> Option<Reply> {
        if !(percent.is_finite() && (1.0..=100.0).contains(&percent)) {
            return Some(Reply::Refused(Refusal::Speed { percent }));
        }
        let seq = self
            .cell
            .motion_control_with(ControlKind::Speed, percent / 100.0);
        self.pending.push(Pending::Control {
            conn,
            seq,
            kind: ControlKind::Speed,
            since: Moment::now(),
        });
        None
    }

    fn control(&mut self, conn: ConnId, kind: ControlKind) -> Option<Reply> {
        let Some(r) = &self.running else {
            return Some(Reply::Refused(Refusal::NoProgram));
        };
        if r.job.motion_done() {
            return Some(Reply::Refused(Refusal::MotionEnded));
        }
        let seq = self.cell.motion_control(kind);
        self.pending.push(Pending::Control {
            conn,
            seq,
            kind,
            since: Moment::now(),
        });
        None
    }

    fn reset(&mut self, conn: ConnId) -> Option<Reply> {
        let fault = self
            .cell
            .last_servo
            .is_some_and(|s| s.status & st::FAULT_LATCHED != 0);
        if self.cell.estop.is_none() && !fault && self.cell.still_latched().is_empty() {
            return Some(Reply::Done("nothing to reset: the e-stop is clear".into()));
        }
        let blockers = self.cell.reset_blockers();
        if !blockers.is_empty() {
            return Some(Reply::Refused(Refusal::Reset { blockers }));
        }
        if let Err(e) = self.cell.reset() {
            return Some(Reply::Failed(e.cause()));
        }
        tracing::info!("e-stop reset");
        self.pending.push(Pending::Reset {
            conn,
            since: Moment::now(),
        });
        None
    }

    fn start(&mut self, conn: ConnId) -> Option<Reply> {
        if let Some(estop) = self.cell.estop_failure() {
            return Some(Reply::Refused(Refusal::EstopLatched {
                estop: Box::new(estop),
            }));
        }
        if let Some(s) = self.cell.last_servo {
            if s.status & st::FAULT_LATCHED != 0 {
                return Some(Reply::Refused(Refusal::FaultLatched {
                    fault: Box::new(self.cell.fault(&s)),
                }));
            }
            if s.status & st::ENABLED != 0 {
                return Some(Reply::Done("the drives are enabled, holding".into()));
            }
        }
        match &mut self.enabling {
            Some((_, waiters)) => waiters.push(conn),
            None => self.enabling = Some((Enabling::new(self.cfg), vec![conn])),
        }
        None
    }

    /// Answers the requests whose effect has come (or not in time).
    fn pending_step(&mut self) {
        let pending = std::mem::take(&mut self.pending);
        for p in pending {
            match self.pending_done(&p) {
                Some(reply) => self.server.reply(p.conn(), &reply),
                None => self.pending.push(p),
            }
        }
    }

    fn pending_done(&self, p: &Pending) -> Option<Reply> {
        match *p {
            Pending::Estop {
                ref reason, since, ..
            } => {
                if !self.cell.still_latched().is_empty() {
                    return Some(Reply::Done(format!(
                        "e-stop raised on instance {}: {reason}",
                        self.cell.instance
                    )));
                }
                (since.elapsed() > ESTOP_PATIENCE).then(|| {
                    Reply::Failed(Failure::EstopNotLatched {
                        instance: self.cell.instance.to_string(),
                        within_s: ESTOP_PATIENCE.as_secs_f64(),
                    })
                })
            }
            Pending::Reset { since, .. } => {
                let fault = self
                    .cell
                    .last_servo
                    .filter(|s| s.status & st::FAULT_LATCHED != 0);
                let latched = self.cell.still_latched();
                if fault.is_none() && latched.is_empty() {
                    return Some(Reply::Done(
                        "the e-stop is clear; `supervisor start` enables the drives".into(),
                    ));
                }
                // A new e-stop since the reset (its cause is still there: an e-stop input still
                // open) fails the reset at once; the rest gets two seconds to clear.
                if self.cell.estop.is_none() && since.elapsed() < Duration::from_secs(2) {
                    return None;
                }
                let mut left = Vec::new();
                if let Some(s) = fault {
                    left.push(format!(
                        "{}: its cause is still present, so it stays latched",
                        self.cell.fault_text(&s)
                    ));
                }
                match self.cell.estop_text() {
                    Some(t) => left.push(format!("the e-stop was raised again: {t}")),
                    None if !latched.is_empty() => left.push(format!(
                        "{} still show the e-stop latched",
                        latched.join(", ")
                    )),
                    None => {}
                }
                Some(Reply::Failed(Failure::ResetIncomplete { left }))
            }
            Pending::Control {
                seq, kind, since, ..
            } => {
                let sp = self.cell.last_sp?;
                let taken = sp.control_seq >= seq;
                let reply = match kind {
                    ControlKind::Pause if taken && sp.path_speed == 0.0 => Some(format!(
                        "paused at rest on the path, line {}, motion time {:.2} s",
                        sp.line, sp.motion_time_s
                    )),
                    ControlKind::Resume if taken => Some("resumed along the path".into()),
                    ControlKind::Speed if taken => Some(format!(
                        "speed override {:.0} %: the path speed ramps to it within t_acc",
                        sp.speed_override * 100.0
                    )),
                    ControlKind::Abort if taken && self.running.is_none() => Some(
                        "aborted: the axes rest on the path; the rest of the program is dropped"
                            .into(),
                    ),
                    _ => None,
                };
                if let Some(text) = reply {
                    return Some(Reply::Done(text));
                }
                let limit = Duration::from_secs_f64(self.cfg.motion.t_acc + 2.0);
                (since.elapsed() > limit).then(|| {
                    Reply::Failed(Failure::ControlNotTaken {
                        control: format!("{kind:?}"),
                        within_s: limit.as_secs_f64(),
                    })
                })
            }
        }
    }

    /// `restart` and `swap`: checked here, then stepped by the loop ([`crate::swap`]); the
    /// answer comes when the swap ends.
    fn replace(
        &mut self,
        conn: ConnId,
        process: &str,
        command: Option<Vec<String>>,
        swap: bool,
    ) -> Option<Reply> {
        // A program being validated starts once it is done: no process is replaced under it.
        if let Some(v) = &self.validating {
            return Some(Reply::Refused(Refusal::Validating {
                program: v.validation.program.name.clone(),
            }));
        }
        let Some(k) = self.cell.index_of(process) else {
            return Some(Reply::Refused(Refusal::NoSuchProcess {
                process: process.to_string(),
                known: self.cell.procs.iter().map(|p| p.name.clone()).collect(),
            }));
        };
        if let Some(c) = &command {
            let Some(first) = c.first() else {
                return Some(Reply::Refused(Refusal::Command {
                    error: "it is empty".into(),
                }));
            };
            if let Err(e) = crate::launch::find_program(first) {
                return Some(Reply::Refused(Refusal::Command {
                    error: e.to_string(),
                }));
            }
        }
        let motion = matches!(process, "trajgen" | "servo" | "drives");
        let mut carried = None;
        if process == "trajgen"
            && let Some(r) = &self.running
        {
            if r.job.last.is_some_and(|sp| sp.path_speed == 0.0) {
                return Some(Reply::Refused(Refusal::Paused));
            }
            if r.job.motion_done() {
                return Some(Reply::Refused(Refusal::MotionEnded));
            }
            // The handover record describes a segment; a WAIT or a DELAY has none.
            if let Some(sp) = r
                .job
                .last
                .filter(|sp| sp.hold != shm_schema::motion::hold::NONE)
            {
                let instruction = if sp.hold == shm_schema::motion::hold::WAIT {
                    "WAIT"
                } else {
                    "DELAY"
                };
                return Some(Reply::Refused(Refusal::Holding {
                    instruction: instruction.into(),
                    line: sp.line,
                }));
            }
            carried = Some(&r.job);
        } else if motion && let Some(r) = &self.running {
            return Some(Reply::Refused(Refusal::MotionPath {
                process: process.to_string(),
                program: r.job.name.clone(),
            }));
        }
        if self.enabling.is_some() {
            return Some(Reply::Refused(Refusal::Enabling));
        }
        let was_enabled = self
            .cell
            .last_servo
            .is_some_and(|s| s.status & st::ENABLED != 0);
        match Swap::begin(self.cell, self.cfg, k, command, swap, carried) {
            Ok(swap) => {
                self.swapping = Some(Swapping {
                    swap,
                    conn,
                    was_enabled,
                });
                None
            }
            Err(what) => Some(Reply::Failed(Failure::Swap { what })),
        }
    }

    /// The next step of a swap in progress; its answer when it ends.
    fn swap_step(&mut self, incidents: &[Incident]) {
        let Some(s) = &mut self.swapping else {
            return;
        };
        let job = match &mut self.running {
            Some(r) if s.swap.carries_program() => Some(&mut r.job),
            _ => None,
        };
        let reply = match s.swap.step(self.cell, self.cfg, incidents, job) {
            Step::Going => return,
            Step::Done(mut replaced) => {
                replaced.reenabling = s.swap.on_motion_path()
                    && !s.swap.carries_program()
                    && s.was_enabled
                    && self.cell.estop.is_none();
                if replaced.reenabling {
                    // The new process re-enables bumplessly, holding where the axes stand.
                    self.enabling = Some((Enabling::new(self.cfg), Vec::new()));
                }
                Reply::Replaced(Box::new(replaced))
            }
            Step::Failed(what) => Reply::Failed(Failure::Swap { what }),
            Step::ProgramLost(what) => {
                let failure = Failure::Swap { what };
                if let Some(r) = self.running.take() {
                    let err = self.with_events(RunError::failed(failure.clone()), r.events_from);
                    self.finish(&r, &Err(err));
                }
                Reply::Failed(failure)
            }
        };
        if let Some(s) = self.swapping.take() {
            self.server.reply(s.conn, &reply);
        }
    }
}

/// Per process, its wake-up latency histogram over its life, for the run's figures.
pub(crate) fn latency_figures(cell: &Cell) -> Vec<control_plane::figures::ProcessLatency> {
    cell.procs
        .iter()
        .enumerate()
        .filter(|(k, _)| cell.children.get(*k).is_some())
        .filter_map(|(_, p)| {
            let h = p.latency.as_deref().filter(|h| h.count > 0)?;
            Some(control_plane::figures::ProcessLatency::of(&p.name, h))
        })
        .collect()
}

/// Per process, its figures from the cell's view (for the report).
pub(crate) fn process_reports(cell: &Cell) -> Vec<ProcessReport> {
    let mut out = Vec::new();
    for k in 0..cell.procs.len() {
        let Some(p) = cell.children.get(k) else {
            continue;
        };
        let pid = p.pid();
        let status = cell.procs[k].status.unwrap_or_default();
        let (policy, priority) = sched_of(pid as i32).unwrap_or((status.policy, status.priority));
        let mut r = process_report(
            &cell.procs[k].name,
            pid,
            policy,
            priority,
            &status,
            cpu_seconds(pid),
        );
        r.wakeup_latency_us = cell.procs[k]
            .latency
            .as_deref()
            .map(control_plane::status::Percentiles::of);
        r.exec_time_us = cell.procs[k]
            .exec_time
            .as_deref()
            .filter(|h| h.count > 0)
            .map(control_plane::status::Percentiles::of);
        out.push(r);
    }
    out
}
