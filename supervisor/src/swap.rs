//! `restart` and `swap`: one process of the cell replaced while the others keep running.
//!
//! - A process outside the motion path (iobridge, any other of the table): **make before
//!   break**. The new one starts beside the old one (the services allow two publishers);
//!   once it is cyclic, the old one is stopped, so its outputs (the fieldbus image) never
//!   miss more than a cycle or so.
//! - trajgen **during a program**: [`trajgen_during_program`]: pause (the axes come to rest
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

use crate::cell::{Cell, Incident};
use crate::job::Job;
use crate::run::TICK;
use cell_config::Config;
use shm_schema::Power;
use std::time::{Duration, Instant};

/// Replaces process `k`: `swap` with `command` (or its configured command: a new build),
/// or restarts it as it runs. Returns what was done, with the swap's duration and, for the
/// processes that publish the fieldbus image, its largest gap.
pub(crate) fn replace(
    cell: &mut Cell,
    cfg: &Config,
    k: usize,
    command: Option<Vec<String>>,
    swap: bool,
) -> Result<String, String> {
    let name = cell.names[k].clone();
    let previous = cell.command_of(k);
    if swap {
        cell.set_command(k, command);
    }
    let motion = matches!(name.as_str(), "trajgen" | "servo" | "drives");
    let start = Instant::now();
    if motion
        && cell
            .last_servo
            .is_some_and(|s| s.power != Power::Disabled as u8)
    {
        // Brakes on: the axes come to rest (they are at rest: no program runs) and the
        // drives are disabled before the process goes.
        cell.request(shm_schema::RequestKind::Disable)
            .map_err(|e| e.to_string())?;
        let limit = Duration::from_secs_f64(cfg.motion.estop_stop_time + 2.0);
        wait_until(
            cell,
            cfg,
            k,
            limit,
            &mut GapMeter::default(),
            &mut Cell::drain_motion,
            |c| {
                c.last_servo
                    .is_some_and(|s| s.power == Power::Disabled as u8)
            },
        )
        .map_err(|e| format!("{name}: the drives did not disable: {e}"))?;
    }
    cell.set_handover(k, true);
    let result = handover(cell, cfg, k, motion);
    cell.set_handover(k, false);
    cell.ignore_statuses_of(k, None);
    let (old, new, gap) = result.inspect_err(|_| cell.set_command(k, previous))?;
    cell.restarts[k] += 1;
    let what = if swap { "swapped" } else { "restarted" };
    let gap = gap.map_or(String::new(), |(g, n)| {
        format!(
            "; fieldbus image: {n} images during the handover, largest gap {:.2} ms",
            g as f64 * 1e-6
        )
    });
    tracing::info!("{name} {what} (pid {old:?} → {new})");
    Ok(format!(
        "{name} {what} in {:.0} ms (pid {} → {new}){gap}",
        start.elapsed().as_secs_f64() * 1e3,
        old.map_or("-".to_string(), |p| p.to_string())
    ))
}

/// Why a swap of trajgen during a program failed, and whether the program survived it.
#[derive(Debug)]
pub(crate) struct TrajgenSwapError {
    /// What went wrong.
    pub message: String,
    /// The program cannot go on (the old trajgen is gone and the new one did not take it
    /// over): the caller ends it.
    pub program_lost: bool,
}

/// Swaps trajgen (process `k`) while `job` runs; see the module documentation. `command`
/// (checked by the caller) replaces its command line when `swap`.
pub(crate) fn trajgen_during_program(
    cell: &mut Cell,
    cfg: &Config,
    k: usize,
    command: Option<Vec<String>>,
    swap: bool,
    job: &mut Job,
) -> Result<String, TrajgenSwapError> {
    let kept = |message: String| TrajgenSwapError {
        message,
        program_lost: false,
    };
    let start = Instant::now();
    let limit = Duration::from_secs_f64(cfg.motion.t_acc + 2.0);
    let mut gaps = GapMeter::default();
    let seq = cell.motion_control(shm_schema::ControlKind::Pause);
    let paused = wait_until(
        cell,
        cfg,
        k,
        limit,
        &mut gaps,
        &mut |c: &mut Cell| job.record(c),
        |c| {
            c.last_sp
                .is_some_and(|sp| sp.control_seq >= seq && sp.path_speed == 0.0)
        },
    );
    let program_id = job.program_id;
    let record = std::cell::Cell::new(None);
    let recorded = paused.and_then(|()| {
        wait_until(
            cell,
            cfg,
            k,
            limit,
            &mut gaps,
            &mut |c: &mut Cell| job.record(c),
            |c| {
                if let Some(h) = c.handover_sub.latest() {
                    record.set(Some(h));
                }
                record
                    .get()
                    .is_some_and(|h| h.valid == 1 && h.program_id == program_id)
            },
        )
    });
    let h = match (recorded, record.get()) {
        (Ok(()), Some(h)) => h,
        (r, _) => {
            // Nothing was replaced: the program goes on with the old trajgen.
            cell.motion_control(shm_schema::ControlKind::Resume);
            let why = r.err().unwrap_or_else(|| "no handover record".into());
            return Err(kept(format!(
                "trajgen was not swapped: it did not pause on a segment ({why}); the program goes on"
            )));
        }
    };
    let previous = cell.command_of(k);
    if swap {
        cell.set_command(k, command);
    }
    cell.set_handover(k, true);
    let old = cell.children.get(k).map(|p| p.pid());
    if let Some(problem) = cell.stop_process(k) {
        tracing::warn!("the old trajgen {problem}");
    }
    let started = runtime::time::now_ns();
    cell.offer_handover(&h);
    let resumed = cell.start_process(k, cfg).and_then(|_| {
        let startup = Duration::from_secs_f64(cfg.supervisor.startup_timeout);
        wait_until(
            cell,
            cfg,
            k,
            startup,
            &mut gaps,
            &mut |c: &mut Cell| job.record(c),
            |c| {
                c.cyclic(k)
                    && c.last_sp.is_some_and(|sp| {
                        sp.stamp_ns > started && sp.program_id == program_id && sp.path_speed == 0.0
                    })
            },
        )
        .map_err(|e| format!("the new trajgen did not take the motion over: {e}"))
    });
    cell.set_handover(k, false);
    // Withdrawn: a trajgen started later (a restart) must not take an old motion over.
    cell.offer_handover(&shm_schema::TrajgenHandoverV2::default());
    if let Err(e) = resumed {
        cell.set_command(k, previous);
        return Err(TrajgenSwapError {
            message: format!("{e}; the program is lost, the axes rest on its path"),
            program_lost: true,
        });
    }
    let new = cell.children.get(k).map_or(0, |p| p.pid());
    job.rewind_to(h.command_seq);
    let seq = cell.motion_control(shm_schema::ControlKind::Resume);
    wait_until(
        cell,
        cfg,
        k,
        limit,
        &mut gaps,
        &mut |c: &mut Cell| job.record(c),
        |c| c.last_sp.is_some_and(|sp| sp.control_seq >= seq),
    )
    .map_err(|e| kept(format!("the new trajgen did not resume: {e}")))?;
    cell.restarts[k] += 1;
    let what = if swap { "swapped" } else { "restarted" };
    tracing::info!("trajgen {what} during {} (pid {old:?} → {new})", job.name);
    Ok(format!(
        "trajgen {what} during {} in {:.0} ms (pid {} → {new}): paused at line {} on the path, resumed from there",
        job.name,
        start.elapsed().as_secs_f64() * 1e3,
        old.map_or("-".to_string(), |p| p.to_string()),
        h.line
    ))
}

/// What a handover did: the old and new pids, the fieldbus image's largest gap (ns) and
/// how many images arrived meanwhile.
type Handover = (Option<u32>, u32, Option<(u64, u64)>);

/// Stops the old process and starts the new one (make before break outside the motion
/// path).
fn handover(cell: &mut Cell, cfg: &Config, k: usize, motion: bool) -> Result<Handover, String> {
    let name = cell.names[k].clone();
    let old = cell.children.get(k).map(|p| p.pid());
    let startup = Duration::from_secs_f64(cfg.supervisor.startup_timeout);
    let mut gaps = GapMeter::default();
    let new = if !motion && old.is_some() {
        cell.ignore_statuses_of(k, old);
        let new = cell.start_process(k, cfg)?;
        if let Err(e) = wait_until(
            cell,
            cfg,
            k,
            startup,
            &mut gaps,
            &mut Cell::drain_motion,
            |c| c.cyclic(k),
        ) {
            // Break nothing: the new one goes, the old one stays.
            let _ = cell.stop_pid(new);
            return Err(format!(
                "the new {name} did not become cyclic ({e}); the old one (pid {}) keeps running",
                old.map_or(0, |p| p)
            ));
        }
        if let Some(problem) = cell.stop_process(k) {
            tracing::warn!("the old {name} {problem}");
        }
        // A few more ticks: the image keeps flowing from the new one alone.
        let _ = wait_until(
            cell,
            cfg,
            k,
            5 * TICK,
            &mut gaps,
            &mut Cell::drain_motion,
            |_| false,
        );
        new
    } else {
        if let Some(problem) = cell.stop_process(k) {
            tracing::warn!("the old {name} {problem}");
        }
        let new = cell.start_process(k, cfg)?;
        wait_until(
            cell,
            cfg,
            k,
            startup,
            &mut gaps,
            &mut Cell::drain_motion,
            |c| c.cyclic(k),
        )
        .map_err(|e| format!("the new {name} did not become cyclic: {e}"))?;
        new
    };
    Ok((old, new, gaps.result()))
}

/// The largest interval between consecutive fieldbus images seen (ns), and their count.
#[derive(Default)]
struct GapMeter {
    last_ns: Option<u64>,
    max_ns: u64,
    count: u64,
}

impl GapMeter {
    fn take(&mut self, cell: &mut Cell) {
        while let Some(img) = cell.image_sub.next() {
            if let Some(t) = self.last_ns
                && img.written_ns > t
            {
                self.max_ns = self.max_ns.max(img.written_ns - t);
            }
            self.last_ns = Some(
                self.last_ns
                    .map_or(img.written_ns, |t| t.max(img.written_ns)),
            );
            self.count += 1;
        }
    }

    fn result(&self) -> Option<(u64, u64)> {
        (self.count > 1).then_some((self.max_ns, self.count))
    }
}

/// Ticks the cell until `done` holds (Ok), process `k` is lost, or `limit` passes; `sink`
/// takes the setpoints and servo states that arrive.
fn wait_until(
    cell: &mut Cell,
    cfg: &Config,
    k: usize,
    limit: Duration,
    gaps: &mut GapMeter,
    sink: &mut dyn FnMut(&mut Cell),
    done: impl Fn(&Cell) -> bool,
) -> Result<(), String> {
    let start = Instant::now();
    loop {
        std::thread::sleep(TICK);
        let incidents = cell.tick(cfg);
        gaps.take(cell);
        sink(cell);
        if let Some(i) = incidents.iter().find(|i| concerns(i, &cell.names[k])) {
            return Err(i.to_string());
        }
        if done(cell) {
            return Ok(());
        }
        if start.elapsed() > limit {
            return Err(format!("not within {:.1} s", limit.as_secs_f64()));
        }
    }
}

fn concerns(i: &Incident, name: &str) -> bool {
    match i {
        Incident::Exited { name: n, .. }
        | Incident::Stalled { name: n, .. }
        | Incident::Fault { name: n, .. } => n == name,
    }
}
