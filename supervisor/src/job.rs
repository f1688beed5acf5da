//! What runs on a cell, a tick at a time: enabling the arm ([`Enabling`]) and a motion
//! program ([`Job`]). Neither blocks: the supervisor's loop calls `step` every tick and keeps
//! beating, serving its control channel and watching the processes meanwhile.

use crate::cell::TICK;
use crate::cell::{Cell, Incident};
use crate::error::RunError;
use crate::program::{Checked, Predicted};
use crate::report::{Report, TraceRow, per_axis};
use cell_client::figures::Envelope;
use cell_config::Config;
use control_plane::Failure;
use control_plane::failure::AxisValue;
use control_plane::figures::{AxisEnvelope, Figures};
use control_plane::report::{Delay, RunReport};
use indexmap::IndexMap;
use motion_program::Commands;
use runtime::time::Moment;
use shm_schema::drive::servo_status as st;
use shm_schema::event::code;
use shm_schema::motion::trajgen_fault;
use shm_schema::{
    MAX_AXES, MotionCommandV2, MotionState, Power, RequestKind, ServoStateV3, SetpointV2,
};
use std::collections::VecDeque;
use std::io::IsTerminal;
use std::time::Duration;

/// The longest stretch of a program the supervisor records for its trace and figures (s):
/// a program that runs for hours keeps bounded memory; the report says the trace was cut.
pub(crate) const MAX_RECORD_S: f64 = 600.0;

/// What the trace keeps of a servo state.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ServoSample {
    stamp_ns: u64,
    seq: u64,
    act_position: [f64; MAX_AXES],
}

/// Enabling the arm: every process cyclic, trajgen publishing, the drives initialized; then an
/// enable request, and a setpoint from after the arm is enabled (trajgen starts where servo
/// holds: bumpless).
#[derive(Debug)]
pub(crate) struct Enabling {
    start: Moment,
    timeout: Duration,
    sent_ns: Option<u64>,
    enabled_at: Option<u64>,
}

impl Enabling {
    pub(crate) fn new(cfg: &Config) -> Self {
        Self {
            start: Moment::now(),
            timeout: Duration::from_secs_f64(cfg.supervisor.startup_timeout),
            sent_ns: None,
            enabled_at: None,
        }
    }

    /// `None` while under way; the first setpoint from after the enable once done.
    pub(crate) fn step(&mut self, cell: &mut Cell) -> Option<Result<SetpointV2, RunError>> {
        if let Some(s) = cell.last_servo
            && s.status & st::FAULT_LATCHED != 0
        {
            return Some(Err(RunError::failed(cell.fault(&s))));
        }
        if let Some(t) = self.sent_ns
            && let Some(e) = cell
                .events
                .iter()
                .rev()
                .find(|e| e.code == code::REQUEST_REFUSED && e.stamp_ns >= t)
        {
            return Some(Err(RunError::Input(format!("servo: {}", e.text()))));
        }
        let initialized = cell
            .last_servo
            .is_some_and(|s| s.status & st::INITIALIZED != 0);
        if cell.critical_cyclic() && initialized && cell.last_sp.is_some() && self.sent_ns.is_none()
        {
            self.sent_ns = Some(runtime::time::now_ns());
            if let Err(e) = cell.request(RequestKind::Enable) {
                return Some(Err(e));
            }
        }
        if let Some(s) = cell.last_servo.filter(|s| s.status & st::ENABLED != 0)
            && self.sent_ns.is_some()
        {
            self.enabled_at.get_or_insert(s.stamp_ns);
        }
        if let (Some(t), Some(sp)) = (self.enabled_at, cell.last_sp)
            && sp.stamp_ns > t
        {
            return Some(Ok(sp));
        }
        if self.start.elapsed() > self.timeout {
            let mut missing: Vec<String> = (0..cell.procs.len())
                .filter(|k| !cell.cyclic(*k) && cell.critical(*k))
                .map(|k| format!("{} is not cyclic", cell.procs[k].name))
                .collect();
            if cell.last_sp.is_none() {
                missing.push("trajgen publishes no setpoint".into());
            }
            if !initialized {
                missing.push("the drives did not initialize".into());
            }
            if self.enabled_at.is_none() {
                missing.push("the arm is not enabled".into());
            }
            return Some(Err(RunError::failed(Failure::Startup {
                timeout_s: self.timeout.as_secs_f64(),
                missing,
            })));
        }
        None
    }
}

/// A motion program running on the cell.
pub(crate) struct Job {
    /// Its name as the user gave it.
    pub(crate) name: String,
    /// The program id its commands and setpoints carry.
    pub(crate) program_id: u32,
    /// The program's commands, drawn as trajgen takes them (loops unrolled lazily).
    commands: Commands,
    /// The commands sent lately, for a new trajgen that goes on from one of them (a swap).
    sent_log: VecDeque<MotionCommandV2>,
    /// The sequence number of the last command sent.
    sent_seq: u64,
    start_pos: Vec<f64>,
    predicted: Predicted,
    rows: Vec<SetpointV2>,
    servo_log: Vec<ServoSample>,
    /// Servo's following error in every state from the program's first setpoint on, for the
    /// figures: bounded however long the program runs, every peak kept.
    fe: Envelope,
    /// Most rows and servo samples recorded ([`MAX_RECORD_S`]); beyond, the trace is cut.
    record_cap: (usize, usize),
    truncated: bool,
    /// Fieldbus images: count, sum of delays, max delay (ns).
    images: (u64, u64, u64),
    done: Option<SetpointV2>,
    done_at: Option<Moment>,
    settled_at: Option<(u64, ServoStateV3)>,
    in_pos_since: Option<u64>,
    progress: Progress,
    /// An e-stop stops the motion: the job ends once the reactions complete.
    ending: Option<Moment>,
    /// The newest setpoint of this program.
    pub(crate) last: Option<SetpointV2>,
    /// Build the figures at the end (someone asked for them: `--plot`).
    pub(crate) plot: bool,
}

impl Job {
    /// A job for `program` (checked, and predicted from `start`), starting from `start` (a
    /// setpoint from after the arm was enabled).
    pub(crate) fn new(
        cfg: &Config,
        program: &Checked,
        predicted: Predicted,
        start: &SetpointV2,
        progress: bool,
    ) -> Self {
        let n = cfg.axis.len();
        let start_pos: Vec<f64> = start.position[..n].to_vec();
        // Unlike any program's before it: the setpoint's number, and on the wall clock this
        // supervisor's pid (a trajgen may have seen another supervisor's programs); on the
        // virtual clock the same in every run.
        let salt = if runtime::time::is_virtual() {
            0
        } else {
            std::process::id()
        };
        let program_id = (salt ^ (start.seq as u32).rotate_left(16)) | 1;
        let per_s = |name: &str| (MAX_RECORD_S / cfg.period_s(name).max(1e-5)) as usize;
        Self {
            name: program.name.clone(),
            program_id,
            commands: program.commands(program_id),
            sent_log: VecDeque::new(),
            sent_seq: 0,
            start_pos,
            progress: Progress::new(progress, &predicted, &program.src),
            predicted,
            rows: Vec::new(),
            servo_log: Vec::new(),
            fe: Envelope::new(n, (cfg.period_s("servo") * 1e9) as u64),
            // Setpoints come at trajgen's period and at its transitions.
            record_cap: (2 * per_s("trajgen"), per_s("servo")),
            truncated: false,
            images: (0, 0, 0),
            done: None,
            done_at: None,
            settled_at: None,
            in_pos_since: None,
            ending: None,
            last: None,
            plot: false,
        }
    }

    /// A new trajgen goes on with the program after the command `seq` (a swap): the commands
    /// after it are sent again.
    pub(crate) fn rewind_to(&mut self, seq: u64) {
        self.sent_seq = seq.min(self.sent_seq);
    }

    /// Keeps a setpoint of this program for the trace (up to the record's cap).
    fn keep(&mut self, sp: SetpointV2) {
        // Once either log is full both stop: no row is paired with a stale measurement.
        if self.truncated {
            return;
        }
        if self.rows.len() < self.record_cap.0 {
            self.rows.push(sp);
        } else {
            self.truncated = true;
        }
    }

    /// Keeps a servo state for the trace (up to the record's cap) and its following error
    /// for the figures (all of them).
    fn keep_servo(&mut self, s: &ServoStateV3) {
        if let Some(first) = self.rows.first() {
            self.fe.start_at(first.stamp_ns);
            self.fe.add(s.stamp_ns, &s.following_error);
        }
        if self.truncated {
            return;
        }
        if self.servo_log.len() < self.record_cap.1 {
            self.servo_log.push(ServoSample {
                stamp_ns: s.stamp_ns,
                seq: s.seq,
                act_position: s.act_position,
            });
        } else {
            self.truncated = true;
        }
    }

    /// Sends up to `credit` commands: again those after a rewind, then new ones.
    fn send(&mut self, cell: &mut Cell, credit: usize) -> Result<(), RunError> {
        for _ in 0..credit {
            let next = self.sent_seq + 1;
            let c = match self.sent_log.iter().find(|c| c.seq == next) {
                Some(c) => *c,
                None => match self.commands.next() {
                    Some(c) => {
                        self.sent_log.push_back(c);
                        // Enough for a successor: trajgen holds at most its queue.
                        while self.sent_log.len() > 2 * motion_core::generator::QUEUE_CAP {
                            self.sent_log.pop_front();
                        }
                        c
                    }
                    None => return Ok(()),
                },
            };
            if !cell.command_pub.send(&c) {
                return Err(RunError::failed(Failure::ServiceRefused {
                    service: "trajgen's command service".into(),
                    sample: "a command".into(),
                }));
            }
            self.sent_seq = c.seq;
        }
        Ok(())
    }

    /// Records what arrived without acting on it (while a swap holds the loop): the
    /// program's setpoints and servo's states, so the trace and the following-error figures
    /// cover the swap too.
    pub(crate) fn record(&mut self, cell: &mut Cell) {
        while let Some(sp) = cell.setpoint_sub.next() {
            cell.last_sp = Some(sp);
            if sp.program_id == self.program_id && sp.state == MotionState::Moving as u32 {
                self.last = Some(sp);
                self.keep(sp);
            }
        }
        while let Some(s) = cell.servo_sub.next() {
            cell.last_servo = Some(s);
            if self.last.is_some() {
                self.keep_servo(&s);
            }
        }
    }

    /// True once the motion has ended (the axes settle): too late to pause.
    pub(crate) fn motion_done(&self) -> bool {
        self.done.is_some()
    }

    /// The predicted duration (s).
    pub(crate) fn predicted(&self) -> f64 {
        self.predicted.duration_s
    }

    /// One tick: `None` while the program runs; its report, or why it failed, at its end.
    /// `incidents` are the cell's of this tick: any of them ends the job.
    pub(crate) fn step(
        &mut self,
        cell: &mut Cell,
        cfg: &Config,
        incidents: &[Incident],
    ) -> Option<Result<Report, RunError>> {
        match self.step_inner(cell, cfg, incidents) {
            Ok(None) => None,
            Ok(Some(r)) => Some(Ok(r)),
            Err(e) => {
                self.progress.finish();
                Some(Err(e))
            }
        }
    }

    /// One tick of the job: the e-stop's reaction waited for, the incidents, the setpoints
    /// and servo's states read, commands sent as trajgen has room, the settling judged.
    fn step_inner(
        &mut self,
        cell: &mut Cell,
        cfg: &Config,
        incidents: &[Incident],
    ) -> Result<Option<Report>, RunError> {
        if let Some(since) = self.ending {
            return self.end_on_estop(cell, cfg, since);
        }
        if let Some(i) = incidents.first() {
            return Err(i.error());
        }
        // An e-stop ends the job once it stops the motion: servo or trajgen reacts to it
        // (servo's own fault is reported below with its cause, unless its state does not
        // explain it within a few ticks). One that no process of the motion reacts to (the
        // cell's propagation rules) lets the motion finish; the job fails at its end.
        if let Some((e, at)) = cell.estop {
            let from_servo = cell.is_servo_fault(&e);
            let stops_motion = cell.reacting("trajgen") || (cell.reacting("servo") && !from_servo);
            if stops_motion || (from_servo && at.elapsed() > 20 * TICK) {
                self.ending = Some(Moment::now());
                return Ok(None);
            }
        }
        if let Some(newest) = self.take_setpoints(cell)? {
            self.feed(cell, &newest)?;
        }
        self.take_servo_states(cell, cfg)?;
        if self.ending.is_some() {
            // servo's states began the job's ending on the e-stop.
            return Ok(None);
        }
        let (moving, im) = (self.last.is_some(), &mut self.images);
        cell.drain_images(|img| {
            if moving {
                let d = img.written_ns.saturating_sub(img.measured_ns);
                *im = (im.0 + 1, im.1 + d, im.2.max(d));
            }
        });
        if let Some(t) = self.done_at
            && self.settled_at.is_none()
            && t.elapsed().as_secs_f64() > cfg.motion.settle_timeout
        {
            let following_error = cell.last_servo.map_or(Vec::new(), |s| {
                cfg.axis
                    .iter()
                    .zip(s.following_error)
                    .map(|(a, value)| AxisValue {
                        axis: a.name.clone(),
                        value,
                        unit: a.unit.clone(),
                    })
                    .collect()
            });
            return Err(RunError::failed(Failure::NotSettled {
                timeout_s: cfg.motion.settle_timeout,
                following_error,
            }));
        }
        let Some((settle_start, final_state)) = self.settled_at else {
            return Ok(None);
        };
        self.progress.finish();
        if let Some(estop) = cell.estop_failure() {
            cell.take_events();
            return Err(RunError::failed(Failure::LatchedAfterMotion {
                estop: Box::new(estop),
            }));
        }
        Ok(Some(self.report(cell, cfg, settle_start, &final_state)))
    }

    /// The job ends on the e-stop: waited for (the loop beats meanwhile) until every process
    /// that reacts to it completed its reaction (servo: axes at rest, drives disabled), at
    /// most the e-stop stop time and a second, so that the job ends on a cell at rest.
    fn end_on_estop(
        &mut self,
        cell: &mut Cell,
        cfg: &Config,
        since: Moment,
    ) -> Result<Option<Report>, RunError> {
        let limit = Duration::from_secs_f64(cfg.motion.estop_stop_time + 1.0);
        // The stop itself belongs on the figures: the axes braking to rest.
        self.record(cell);
        if cell.reactions_pending() && since.elapsed() < limit {
            return Ok(None);
        }
        Err(RunError::failed(cell.estop_failure().unwrap_or_else(
            || Failure::System {
                what: "e-stop".into(),
            },
        )))
    }

    /// The setpoints trajgen published since the last tick: this program's kept for the
    /// figures, its end noted, its abort or trajgen's refusal an error. The newest of all.
    fn take_setpoints(&mut self, cell: &mut Cell) -> Result<Option<SetpointV2>, RunError> {
        let mut newest = None;
        while let Some(sp) = cell.setpoint_sub.next() {
            newest = Some(sp);
            cell.last_sp = Some(sp);
            if sp.program_id != self.program_id {
                continue;
            }
            self.last = Some(sp);
            if sp.fault == trajgen_fault::ESTOP {
                // The e-stop's own report (servo's fault, or the trigger) says why.
                continue;
            }
            if sp.fault == trajgen_fault::ABORTED {
                return Err(RunError::failed(Failure::Aborted {
                    program: self.name.clone(),
                    line: sp.fault_line,
                    motion_s: sp.motion_time_s,
                }));
            }
            if sp.fault != trajgen_fault::NONE || sp.state == MotionState::Fault as u32 {
                return Err(RunError::failed(Failure::TrajgenRefused {
                    program: self.name.clone(),
                    line: sp.fault_line,
                    fault: sp.fault,
                    what: trajgen_fault::text(sp.fault).to_string(),
                }));
            }
            match MotionState::from_wire(sp.state) {
                Some(MotionState::Moving) => self.keep(sp),
                Some(MotionState::Done) if self.done.is_none() => {
                    self.keep(sp);
                    self.done = Some(sp);
                    self.done_at = Some(Moment::now());
                }
                _ => {}
            }
        }
        Ok(newest)
    }

    /// Flow control: sends the next commands, never more in flight than trajgen has free
    /// places by its `newest` setpoint.
    fn feed(&mut self, cell: &mut Cell, newest: &SetpointV2) -> Result<(), RunError> {
        // Until trajgen runs this program, its count may be a previous session's: take
        // everything sent as in flight (never more than the queue holds).
        let in_flight = if self.last.is_some() {
            self.sent_seq - newest.commands_taken.min(self.sent_seq)
        } else {
            self.sent_seq
        };
        let credit = (newest.queue_free as u64).saturating_sub(in_flight) as usize;
        self.send(cell, credit)?;
        if newest.program_id == self.program_id {
            self.progress.show(newest);
        }
        Ok(())
    }

    /// servo's states since the last tick, once the program runs: kept for the figures; a
    /// latched fault, the drives off or a setpoint jump an error (the drives off by the
    /// e-stop begins the job's ending instead); the settling judged after the motion's end.
    fn take_servo_states(&mut self, cell: &mut Cell, cfg: &Config) -> Result<(), RunError> {
        let settle_ns = (cfg.motion.settle_time * 1e9) as u64;
        while let Some(s) = cell.servo_sub.next() {
            cell.last_servo = Some(s);
            if self.last.is_none() {
                continue;
            }
            // Before the checks: the state that ends the run is on its figures too.
            self.keep_servo(&s);
            if s.status & st::FAULT_LATCHED != 0 {
                cell.take_events();
                return Err(RunError::failed(cell.fault(&s)));
            }
            if s.power != Power::Enabled as u8 {
                // The e-stop's reaction: servo's state can come before its status says it
                // reacts, and before this tick read the e-stop (published after the tick
                // polled it): the job ends as the e-stop's, once the reactions complete.
                cell.poll_estop();
                if cell.estop.is_some() {
                    self.ending = Some(Moment::now());
                    return Ok(());
                }
                cell.take_events();
                return Err(RunError::failed(Failure::Disabled {
                    power: Power::from_wire(s.power)
                        .map_or("?", Power::name)
                        .to_string(),
                }));
            }
            if s.status & st::SETPOINT_JUMP != 0 {
                cell.take_events();
                return Err(RunError::failed(Failure::SetpointJump));
            }
            if let Some(d) = &self.done {
                let inside = cfg.axis.iter().enumerate().all(|(i, a)| {
                    s.following_error[i].abs() <= a.in_position
                        && s.act_velocity[i].abs() <= a.settle_velocity()
                });
                let used_final = s.setpoint_seq >= d.seq;
                match (inside && used_final, self.in_pos_since) {
                    (true, None) => self.in_pos_since = Some(s.stamp_ns),
                    (true, Some(t0)) if s.stamp_ns - t0 >= settle_ns => {
                        self.settled_at = Some((t0, s))
                    }
                    (false, _) => self.in_pos_since = None,
                    _ => {}
                }
            }
        }
        Ok(())
    }

    fn report(
        &self,
        cell: &Cell,
        cfg: &Config,
        settle_start: u64,
        final_state: &ServoStateV3,
    ) -> Report {
        let n = cfg.axis.len();
        let done = self.done.expect("settling needs done");
        // Servo's own latch, never the states this loop happened to read: it saw every cycle.
        let max_fe = if final_state.peak_program == self.program_id {
            final_state.peak_following_error
        } else {
            [f64::NAN; MAX_AXES]
        };
        let images = self.images;
        let trace = trace_rows(&self.rows, &self.servo_log);
        let measured_s = (done.motion_end_ns - done.motion_start_ns) as f64 * 1e-9 - done.waited_s;
        let title = format!(
            "{} on {}: {measured_s:.3} s measured, {:.3} s theoretical",
            self.name, cfg.cell.name, done.theoretical_s
        );
        let figures = self
            .plot
            .then(|| Box::new(self.figures(cfg, title, &trace, &max_fe)));
        let axes: Vec<String> = cfg.axis.iter().map(|a| a.name.clone()).collect();
        let of_axes = |v: &[f64]| per_axis(&axes, v);
        let run = RunReport {
            ok: true,
            program: self.name.clone(),
            instance: cell.instance.to_string(),
            cell: cfg.cell.name.clone(),
            theoretical_s: done.theoretical_s,
            predicted_s: self.predicted.duration_s,
            measured_s,
            waited_s: done.waited_s,
            difference_s: measured_s - done.theoretical_s,
            trajgen_period_s: cfg.period_s("trajgen"),
            settle_s: settle_start.saturating_sub(done.motion_end_ns) as f64 * 1e-9,
            final_position: of_axes(&final_state.act_position[..n]),
            // The generator's resting point at the end is the last target.
            final_error: of_axes(
                &(0..n)
                    .map(|i| final_state.act_position[i] - done.position[i])
                    .collect::<Vec<_>>(),
            ),
            max_following_error: of_axes(&max_fe[..n]),
            units: cfg
                .axis
                .iter()
                .map(|a| (a.name.clone(), a.unit.clone()))
                .collect(),
            vmax: cfg.axis.iter().map(|a| (a.name.clone(), a.vmax)).collect(),
            t_acc: cfg.motion.t_acc,
            start: of_axes(&self.start_pos),
            periods_us: cfg
                .process
                .iter()
                .map(|p| (p.name.clone(), p.period_us))
                .collect(),
            setpoints: self.rows.len() as u64,
            lost_setpoints: lost_setpoints(&self.rows),
            lost_servo_states: self
                .servo_log
                .windows(2)
                .map(|w| w[1].seq.saturating_sub(w[0].seq + 1))
                .sum(),
            trace_truncated: self.truncated,
            starved: done.starved,
            iobridge_delay_us: (images.0 > 0).then(|| Delay {
                mean: images.1 as f64 / images.0 as f64 * 1e-3,
                max: images.2 as f64 * 1e-3,
            }),
            processes: IndexMap::new(),
            sense_to_command_us: None,
            virtual_time: None,
            events: Vec::new(),
            axes,
        };
        Report {
            run,
            trace,
            figures,
        }
    }

    /// The figures of a program that failed, up to the failure: its path and following
    /// error so far (the peak is servo's latch in its newest state).
    pub(crate) fn figures_so_far(&self, cfg: &Config, cell: &Cell) -> Figures {
        let trace = trace_rows(&self.rows, &self.servo_log);
        let peak = match cell.last_servo {
            Some(s) if s.peak_program == self.program_id => s.peak_following_error,
            _ => [f64::NAN; MAX_AXES],
        };
        let title = format!(
            "{} on {}: FAILED after {:.3} s of motion",
            self.name,
            cfg.cell.name,
            self.last.map_or(0.0, |sp| sp.motion_time_s)
        );
        self.figures(cfg, title, &trace, &peak)
    }

    /// The path and the following error of the figures (the latency histograms are the
    /// processes', added with their reports).
    fn figures(
        &self,
        cfg: &Config,
        title: String,
        trace: &[TraceRow],
        peak: &[f64; MAX_AXES],
    ) -> Figures {
        let n = cfg.axis.len();
        // The trace and so the path stop at the record's cap; the following error does not.
        let title = if self.truncated {
            format!("{title}  (path: the first {MAX_RECORD_S:.0} s)")
        } else {
            title
        };
        let kin = crate::program::kin(cfg).ok().flatten();
        let coords: Vec<(String, String)> = match &kin {
            Some(k) => {
                k.0.coords()
                    .iter()
                    .map(|c| (c.name.to_string(), c.unit.symbol().to_string()))
                    .collect()
            }
            None => cfg
                .axis
                .iter()
                .map(|a| (a.name.clone(), a.unit.clone()))
                .collect(),
        };
        // The commanded tool is trajgen's own (no kinematics to run again), when it gave it.
        let rows = trace.iter().zip(&self.rows).map(|(r, sp)| {
            let tool = (sp.coords as usize >= coords.len().min(2) && sp.coords > 0)
                .then_some(sp.cartesian);
            (r.t_s, r.cmd, r.act, tool)
        });
        Figures {
            title,
            path: cell_client::figures::path_of(rows, kin.as_ref(), n, &coords),
            following_error: cfg
                .axis
                .iter()
                .enumerate()
                .map(|(k, a)| AxisEnvelope {
                    axis: a.name.clone(),
                    unit: a.unit.clone(),
                    peak: peak[k],
                    buckets: self.fe.axis(k),
                })
                .collect(),
            latency: Vec::new(),
        }
    }
}

/// One row per setpoint: its command, and the measured position at the servo cycle that used
/// it (the first servo cycle at or after its time: servo takes the newest setpoint). By time,
/// not by sequence number: a swapped trajgen numbers its setpoints from 1 again.
fn trace_rows(rows: &[SetpointV2], servo: &[ServoSample]) -> Vec<TraceRow> {
    rows.iter()
        .map(|sp| {
            let idx = servo.partition_point(|s| s.stamp_ns < sp.stamp_ns);
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

fn lost_setpoints(rows: &[SetpointV2]) -> u64 {
    rows.windows(2)
        .map(|w| w[1].seq.saturating_sub(w[0].seq + 1))
        .sum()
}

/// Progress on stderr: motion time against the total and the current program line.
struct Progress {
    on: bool,
    tty: bool,
    total: String,
    lines: Vec<String>,
    last: Option<Moment>,
}

/// The most of a program line a progress line shows.
const PROGRESS_TEXT: usize = 60;

impl Progress {
    fn new(on: bool, predicted: &Predicted, src: &str) -> Self {
        Self {
            on,
            tty: std::io::stderr().is_terminal(),
            total: match predicted.iteration_s {
                Some(i) => format!(
                    "{:.2} s + {i:.2} s per iteration, for ever",
                    predicted.duration_s
                ),
                None => format!("{:.2} s", predicted.duration_s),
            },
            lines: if on {
                src.lines()
                    .map(|l| {
                        motion_program::cut(
                            l.split("//").next().unwrap_or("").trim(),
                            PROGRESS_TEXT,
                        )
                    })
                    .collect()
            } else {
                Vec::new()
            },
            last: None,
        }
    }

    fn show(&mut self, sp: &SetpointV2) {
        let every = if self.tty { 0.2 } else { 1.0 };
        if !self.on
            || sp.state != MotionState::Moving as u32
            || self.last.is_some_and(|t| t.elapsed().as_secs_f64() < every)
        {
            return;
        }
        self.last = Some(Moment::now());
        let text = self
            .lines
            .get(sp.line.saturating_sub(1) as usize)
            .map_or("", String::as_str);
        let msg = format!(
            "motion {:6.2} s / {}   line {}: {}",
            sp.motion_time_s, self.total, sp.line, text
        );
        if self.tty {
            crate::out::text(&format!("\r\x1b[2K{msg}"));
        } else {
            crate::out::line(&msg);
        }
    }

    fn finish(&mut self) {
        if self.on && self.tty && self.last.is_some() {
            crate::out::line("");
        }
        self.on = false;
    }
}
