//! `restart` and `swap`: one process of the cell replaced while the others keep running.
//!
//! - A process outside the motion path (iobridge, any other of the table): **make before
//!   break**. The new one starts beside the old one (the services allow two publishers);
//!   once it is cyclic, the old one is stopped, so its outputs (the fieldbus image) never
//!   miss more than a cycle or so.
//! - trajgen **during a program**: pause (the axes come to rest
//!   on the path within `t_acc`), the old trajgen's handover record (the segment and where on
//!   it), the new trajgen goes on from that record, the program's commands after the
//!   segment's are sent again, resume. No e-stop, the drives stay enabled; the motion time
//!   grows by the pause and the swap.
//! - servo, the drives' process (drives), and trajgen with no program: **with the brakes
//!   on**: the drives are disabled first, the process is replaced, and the caller re-enables
//!   the drives bumplessly (holding where the axes stand).
//!
//! Meanwhile the host state announces the handover (`HostStateV1::handover`), so the other
//! processes do not count the gap as pending-sequence overruns, and the supervisor does not
//! take the replaced process' silence for a stall.

//!
//! A [`Swap`] is a job of the supervisor's loop ([`crate::serve`]): [`Swap::begin`] takes the
//! first step, [`Swap::step`] one more every tick, and meanwhile the loop beats, watches the
//! processes and answers the control channel (a request that would change the cell waits
//! for the swap's end: it is refused "busy", `down` is kept for after it).
use crate::cell::{Cell, GapMeter, Incident, TICK};
use crate::job::Job;
use cell_config::Config;
use control_plane::Replaced;
use runtime::time::Moment;
use shm_schema::{ControlKind, Power, TrajgenHandoverV2};
use std::time::Duration;

/// A replacement in progress; see the module documentation.
#[derive(Debug)]
pub(crate) struct Swap {
    k: usize,
    name: String,
    /// `swap` (a new command, or a new build of it) or `restart`.
    swap: bool,
    /// The command line before; restored if the swap fails.
    previous: Option<Vec<String>>,
    /// The process is on the motion path (trajgen, servo, drives).
    motion: bool,
    /// The program trajgen carries through this swap (its name and id), if any.
    program: Option<(String, u32)>,
    old: Option<u32>,
    start: Moment,
    stage: Stage,
}

#[derive(Debug)]
enum Stage {
    /// Brakes on: servo disables the drives before the process goes.
    Disabling { since: Moment },
    /// Make before break: the new one started beside the old one; until it is cyclic.
    Beside { new: u32, since: Moment },
    /// The old one told to stop: until it has left, then a few ticks of the image from the
    /// new one alone.
    Alone { new: u32, since: Moment },
    /// On the motion path: the old one told to stop; until it has left, then the new one
    /// starts.
    Vacating { old: u32 },
    /// The old one gone and the new one started; until it is cyclic.
    Replacing { new: u32, since: Moment },
    /// trajgen during a program: until the path speed is 0 on the path.
    Pausing { seq: u64, since: Moment },
    /// Until the old trajgen's handover record of the program (the newest seen).
    Recording {
        since: Moment,
        seen: Option<TrajgenHandoverV2>,
    },
    /// The old trajgen told to stop, the record taken; until it has left, then the new one
    /// starts with the record.
    HandingOver { record: TrajgenHandoverV2, old: u32 },
    /// The new trajgen started with the record; until it holds the motion, paused.
    TakingOver {
        record: TrajgenHandoverV2,
        started_ns: u64,
        since: Moment,
    },
    /// The program's commands after the record's sent again, resumed; until trajgen took it.
    Resuming {
        record: TrajgenHandoverV2,
        seq: u64,
        since: Moment,
    },
}

/// Where a swap is after a step.
#[derive(Debug)]
pub(crate) enum Step {
    /// Not done yet.
    Going,
    /// Done; what was done.
    Done(Replaced),
    /// Failed; nothing was replaced, or the old process keeps running (why, for the user).
    Failed(String),
    /// trajgen during a program failed after the old one was gone: the program cannot go on.
    ProgramLost(String),
}

impl Swap {
    /// Starts replacing process `k` (`swap` with `command`, or its configured command: a new
    /// build; or a restart as it runs). `job`: the program trajgen carries through the swap
    /// (trajgen only; the caller checked that it moves on a segment).
    pub(crate) fn begin(
        cell: &mut Cell,
        cfg: &Config,
        k: usize,
        command: Option<Vec<String>>,
        swap: bool,
        job: Option<&Job>,
    ) -> Result<Self, String> {
        let name = cell.procs[k].name.clone();
        let previous = cell.command_of(k);
        let motion = matches!(name.as_str(), "trajgen" | "servo" | "drives");
        let mut s = Self {
            k,
            name,
            swap,
            previous,
            motion,
            program: job.map(|j| (j.name.clone(), j.program_id)),
            old: cell.children.get(k).map(|p| p.pid()),
            start: Moment::now(),
            stage: Stage::Disabling {
                since: Moment::now(),
            },
        };
        if swap {
            cell.set_command(k, command);
        }
        let now = Moment::now();
        if s.program.is_some() {
            let seq = cell.motion_control(ControlKind::Pause);
            s.stage = Stage::Pausing { seq, since: now };
        } else if motion
            && cell
                .last_servo
                .is_some_and(|st| st.power != Power::Disabled as u8)
        {
            // Brakes on: the axes are at rest (no program runs); the drives are disabled
            // before the process goes.
            if let Err(e) = cell.request(shm_schema::RequestKind::Disable) {
                cell.set_command(k, s.previous.clone());
                return Err(e.to_string());
            }
            s.stage = Stage::Disabling { since: now };
        } else {
            s.stage = s.replace(cell, cfg)?;
        }
        if s.program.is_none() {
            cell.image_gaps = Some(GapMeter::default());
        }
        Ok(s)
    }

    /// The program this swap carries: the loop only records its setpoints meanwhile.
    pub(crate) fn carries_program(&self) -> bool {
        self.program.is_some()
    }

    /// The process being replaced.
    pub(crate) fn process(&self) -> &str {
        &self.name
    }

    /// The process is on the motion path: the caller re-enables the drives after it.
    pub(crate) fn on_motion_path(&self) -> bool {
        self.motion
    }

    /// Takes the next step, on this tick's `incidents`; `job` is the program it carries.
    /// Each stage waits for its condition, fails when the process is lost or its time is up,
    /// or goes on to the next stage.
    pub(crate) fn step(
        &mut self,
        cell: &mut Cell,
        cfg: &Config,
        incidents: &[Incident],
        job: Option<&mut Job>,
    ) -> Step {
        let t = Tick {
            lost: incidents
                .iter()
                .find(|i| concerns(i, &self.name))
                .map(ToString::to_string),
            motion_limit: Duration::from_secs_f64(cfg.motion.t_acc + 2.0),
            startup: Duration::from_secs_f64(cfg.supervisor.startup_timeout),
        };
        let stage = std::mem::replace(
            &mut self.stage,
            Stage::Disabling {
                since: Moment::now(),
            },
        );
        match stage {
            Stage::Disabling { since } => self.disabling(cell, cfg, t, since),
            Stage::Beside { new, since } => self.beside(cell, t, new, since),
            Stage::Alone { new, since } => {
                // The ticks alone count from the old one's exit.
                let gone = self.old.is_none_or(|old| !cell.children.is_leaving(old));
                let since = if gone { since } else { Moment::now() };
                if !gone || since.elapsed() < 5 * TICK {
                    self.stage = Stage::Alone { new, since };
                    return Step::Going;
                }
                self.done(cell, new)
            }
            Stage::Vacating { old } => {
                if cell.children.is_leaving(old) {
                    self.stage = Stage::Vacating { old };
                    return Step::Going;
                }
                match self.start_new(cell, cfg) {
                    Ok(stage) => {
                        self.stage = stage;
                        Step::Going
                    }
                    Err(e) => Step::Failed(e),
                }
            }
            Stage::Replacing { new, since } => {
                if t.lost.is_none() && cell.cyclic(self.k) {
                    return self.done(cell, new);
                }
                if let Some(why) = t.lost.or_else(|| late(since, t.startup)) {
                    return self.fail(
                        cell,
                        format!("the new {} did not become cyclic: {why}", self.name),
                    );
                }
                self.stage = Stage::Replacing { new, since };
                Step::Going
            }
            Stage::Pausing { seq, since } => self.pausing(cell, t, seq, since),
            Stage::Recording { since, seen } => self.recording(cell, t, since, seen),
            Stage::HandingOver { record, old } => self.handing_over(cell, cfg, record, old),
            Stage::TakingOver {
                record,
                started_ns,
                since,
            } => self.taking_over(cell, job, t, record, started_ns, since),
            Stage::Resuming { record, seq, since } => self.resuming(cell, t, record, seq, since),
        }
    }

    /// Brakes on: until servo reports the drives disabled, then the process is replaced.
    fn disabling(&mut self, cell: &mut Cell, cfg: &Config, t: Tick, since: Moment) -> Step {
        let off = cell
            .last_servo
            .is_some_and(|s| s.power == Power::Disabled as u8);
        let limit = Duration::from_secs_f64(cfg.motion.estop_stop_time + 2.0);
        if let Some(why) = t
            .lost
            .or_else(|| (!off).then(|| late(since, limit)).flatten())
        {
            return self.fail(
                cell,
                format!("{}: the drives did not disable: {why}", self.name),
            );
        }
        if !off {
            self.stage = Stage::Disabling { since };
            return Step::Going;
        }
        match self.replace(cell, cfg) {
            Ok(stage) => self.stage = stage,
            Err(e) => return self.fail(cell, e),
        }
        Step::Going
    }

    /// Make before break: until the new process is cyclic, then the old one stops.
    fn beside(&mut self, cell: &mut Cell, t: Tick, new: u32, since: Moment) -> Step {
        let k = self.k;
        let why = t.lost.or_else(|| {
            if cell.cyclic(k) {
                None
            } else {
                late(since, t.startup)
            }
        });
        if let Some(why) = why {
            // Break nothing: the new one goes, the old one stays.
            cell.children.dismiss(new);
            let old = self.old.map_or(0, |p| p);
            return self.fail(
                cell,
                format!(
                    "the new {} did not become cyclic ({why}); the old one (pid {old}) keeps running",
                    self.name
                ),
            );
        }
        if !cell.cyclic(k) {
            self.stage = Stage::Beside { new, since };
            return Step::Going;
        }
        if let Some(old) = self.old {
            // It leaves in the background; the loop goes on meanwhile (the cell's tick reaps
            // it, and warns if it does not stop cleanly).
            cell.children.dismiss(old);
        }
        self.stage = Stage::Alone {
            new,
            since: Moment::now(),
        };
        Step::Going
    }

    /// trajgen during a program: until the path speed is 0 on the path.
    fn pausing(&mut self, cell: &mut Cell, t: Tick, seq: u64, since: Moment) -> Step {
        let paused = cell
            .last_sp
            .is_some_and(|sp| sp.control_seq >= seq && sp.path_speed == 0.0);
        if t.lost.is_none() && paused {
            self.stage = Stage::Recording {
                since: Moment::now(),
                seen: None,
            };
            return Step::Going;
        }
        match t.lost.or_else(|| late(since, t.motion_limit)) {
            Some(why) => self.not_paused(cell, why),
            None => {
                self.stage = Stage::Pausing { seq, since };
                Step::Going
            }
        }
    }

    /// Until the old trajgen's handover record of the program; then the old one is told to
    /// stop.
    fn recording(
        &mut self,
        cell: &mut Cell,
        t: Tick,
        since: Moment,
        seen: Option<TrajgenHandoverV2>,
    ) -> Step {
        let k = self.k;
        let program_id = self.program.as_ref().map_or(0, |p| p.1);
        let seen = cell.handover_sub.latest().or(seen);
        let record = seen.filter(|h| h.valid == 1 && h.program_id == program_id);
        let record = match (t.lost, record) {
            (None, Some(record)) => record,
            (lost, _) => {
                return match lost.or_else(|| late(since, t.motion_limit)) {
                    Some(why) => self.not_paused(cell, why),
                    None => {
                        self.stage = Stage::Recording { since, seen };
                        Step::Going
                    }
                };
            }
        };
        cell.set_handover(k, true);
        let old = cell.children.get(k).map_or(0, |p| p.pid());
        cell.children.dismiss(old);
        self.stage = Stage::HandingOver { record, old };
        Step::Going
    }

    /// Until the old trajgen has left; then the new one starts with the record.
    fn handing_over(
        &mut self,
        cell: &mut Cell,
        cfg: &Config,
        record: TrajgenHandoverV2,
        old: u32,
    ) -> Step {
        if cell.children.is_leaving(old) {
            self.stage = Stage::HandingOver { record, old };
            return Step::Going;
        }
        let started_ns = runtime::time::now_ns();
        cell.offer_handover(&record);
        if let Err(e) = cell.start_process(self.k, cfg) {
            return self.program_lost(
                cell,
                format!("the new trajgen did not take the motion over: {e}"),
            );
        }
        self.stage = Stage::TakingOver {
            record,
            started_ns,
            since: Moment::now(),
        };
        Step::Going
    }

    /// Until the new trajgen holds the motion, paused; then the program's commands after the
    /// record are sent again and the motion resumed.
    fn taking_over(
        &mut self,
        cell: &mut Cell,
        job: Option<&mut Job>,
        t: Tick,
        record: TrajgenHandoverV2,
        started_ns: u64,
        since: Moment,
    ) -> Step {
        let k = self.k;
        let program_id = record.program_id;
        let holds = t.lost.is_none()
            && cell.cyclic(k)
            && cell.last_sp.is_some_and(|sp| {
                sp.stamp_ns > started_ns && sp.program_id == program_id && sp.path_speed == 0.0
            });
        if !holds {
            if let Some(why) = t.lost.or_else(|| late(since, t.startup)) {
                return self.program_lost(
                    cell,
                    format!("the new trajgen did not take the motion over: {why}"),
                );
            }
            self.stage = Stage::TakingOver {
                record,
                started_ns,
                since,
            };
            return Step::Going;
        }
        cell.set_handover(k, false);
        // Withdrawn: a trajgen started later (a restart) must not take an old motion over.
        cell.offer_handover(&TrajgenHandoverV2::default());
        if let Some(job) = job {
            job.rewind_to(record.command_seq);
        }
        let seq = cell.motion_control(ControlKind::Resume);
        self.stage = Stage::Resuming {
            record,
            seq,
            since: Moment::now(),
        };
        Step::Going
    }

    /// Until trajgen took the resume: the swap is done.
    fn resuming(
        &mut self,
        cell: &mut Cell,
        t: Tick,
        record: TrajgenHandoverV2,
        seq: u64,
        since: Moment,
    ) -> Step {
        if t.lost.is_none() && cell.last_sp.is_some_and(|sp| sp.control_seq >= seq) {
            cell.procs[self.k].restarts += 1;
            let new = cell.children.get(self.k).map_or(0, |p| p.pid());
            let program = self.program.as_ref().map_or("", |p| p.0.as_str());
            tracing::info!(
                "trajgen {} during {program} (pid {:?} → {new})",
                self.what(),
                self.old
            );
            return Step::Done(Replaced {
                process: self.name.clone(),
                swapped: self.swap,
                took_ms: self.start.elapsed().as_secs_f64() * 1e3,
                old_pid: self.old,
                new_pid: new,
                image: None,
                program: Some((program.to_string(), record.line)),
                reenabling: false,
            });
        }
        if let Some(why) = t.lost.or_else(|| late(since, t.motion_limit)) {
            return Step::Failed(format!("the new trajgen did not resume: {why}"));
        }
        self.stage = Stage::Resuming { record, seq, since };
        Step::Going
    }

    /// Stops the old process and starts the new one: beside it outside the motion path
    /// (make before break), in its place on it.
    fn replace(&self, cell: &mut Cell, cfg: &Config) -> Result<Stage, String> {
        let k = self.k;
        cell.set_handover(k, true);
        let since = Moment::now();
        if !self.motion && self.old.is_some() {
            cell.ignore_statuses_of(k, self.old);
            let new = cell
                .start_process(k, cfg)
                .inspect_err(|_| self.undo(cell))?;
            return Ok(Stage::Beside { new, since });
        }
        // On the motion path the old one leaves first, in the background.
        if let Some(old) = cell.children.get(k).map(|p| p.pid()) {
            cell.children.dismiss(old);
            return Ok(Stage::Vacating { old });
        }
        self.start_new(cell, cfg)
    }

    /// The old one gone: the new one starts in its place.
    fn start_new(&self, cell: &mut Cell, cfg: &Config) -> Result<Stage, String> {
        let new = cell
            .start_process(self.k, cfg)
            .inspect_err(|_| self.undo(cell))?;
        Ok(Stage::Replacing {
            new,
            since: Moment::now(),
        })
    }

    fn what(&self) -> &'static str {
        if self.swap { "swapped" } else { "restarted" }
    }

    /// The new process is cyclic: done.
    fn done(&mut self, cell: &mut Cell, new: u32) -> Step {
        let k = self.k;
        cell.set_handover(k, false);
        cell.ignore_statuses_of(k, None);
        cell.procs[k].restarts += 1;
        let image = cell
            .image_gaps
            .take()
            .and_then(|g| g.result())
            .map(|(gap_ns, images)| (images, gap_ns as f64 * 1e-6));
        tracing::info!("{} {} (pid {:?} → {new})", self.name, self.what(), self.old);
        Step::Done(Replaced {
            process: self.name.clone(),
            swapped: self.swap,
            took_ms: self.start.elapsed().as_secs_f64() * 1e3,
            old_pid: self.old,
            new_pid: new,
            image,
            program: None,
            reenabling: false,
        })
    }

    /// The handover is over and the command line as it was.
    fn undo(&self, cell: &mut Cell) {
        cell.set_handover(self.k, false);
        cell.ignore_statuses_of(self.k, None);
        cell.set_command(self.k, self.previous.clone());
        cell.image_gaps = None;
    }

    fn fail(&self, cell: &mut Cell, why: String) -> Step {
        self.undo(cell);
        Step::Failed(why)
    }

    /// trajgen did not pause on a segment: nothing was replaced; the program goes on with the
    /// old trajgen.
    fn not_paused(&self, cell: &mut Cell, why: String) -> Step {
        cell.motion_control(ControlKind::Resume);
        cell.set_command(self.k, self.previous.clone());
        Step::Failed(format!(
            "trajgen was not swapped: it did not pause on a segment ({why}); the program goes on"
        ))
    }

    fn program_lost(&self, cell: &mut Cell, why: String) -> Step {
        self.undo(cell);
        cell.offer_handover(&TrajgenHandoverV2::default());
        Step::ProgramLost(format!(
            "{why}; the program is lost, the axes rest on its path"
        ))
    }
}

/// What a step sees of its tick: the incident that concerns the process, if any, and the
/// stages' time limits.
struct Tick {
    lost: Option<String>,
    motion_limit: Duration,
    startup: Duration,
}

/// `Some(why)` once `limit` has passed since `since`.
fn late(since: Moment, limit: Duration) -> Option<String> {
    (since.elapsed() > limit).then(|| format!("not within {:.1} s", limit.as_secs_f64()))
}

fn concerns(i: &Incident, name: &str) -> bool {
    match i {
        Incident::Exited { name: n, .. }
        | Incident::Stalled { name: n, .. }
        | Incident::Fault { name: n, .. } => n == name,
    }
}
