//! `supervisor tune`: commissioning help on the real processes of the cell.
//!
//! 1. Start the cell of the configuration (as `run` does), enable, wait until the axes settle.
//! 2. **Step**: a `Step` request offsets the reference of one axis by the amplitude (servo
//!    takes it as the one position step command validation lets through, at most half the
//!    axis' following-error limit); servo's state is recorded every servo cycle until the axis
//!    settles again (at most 3 s), then the offset is removed.
//! 3. Optionally, **ramp**: a move of the given distance on that axis and back, through trajgen
//!    at the axis' vmax, with its blends; the peak following error while moving and the
//!    settling after it.
//! 4. Stop the cell and report: rise time (10 % to 90 % of the step), overshoot, settling time
//!    (until the error stays within the larger of 2 % of the step and the in-position band),
//!    peak following error and peak effort; a PNG of command, position and effort.

use crate::cell::TICK;
use crate::cell::{Cell, Mode, open_cell};
use crate::error::RunError;
use cell_config::Config;
use plot::{Panel, series_png};
use serde::Serialize;
use shm_schema::drive::servo_status as st;
use shm_schema::{
    CommandKind, InstanceName, MAX_AXES, MotionCommandV2, MotionState, RequestKind, ServoStateV3,
};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// What `supervisor tune` was asked to do.
#[derive(Clone, Debug)]
pub struct TuneOptions {
    /// The configuration file; `None` for the embedded default.
    pub config: Option<PathBuf>,
    /// Instance name.
    pub instance: String,
    /// Axis name.
    pub axis: String,
    /// Step amplitude (axis unit).
    pub step: f64,
    /// Ramp distance (axis unit), if a ramp is wanted.
    pub ramp: Option<f64>,
    /// PNG to write.
    pub plot: Option<PathBuf>,
    /// Print events as they happen.
    pub progress: bool,
}

/// One recorded servo cycle of the axis.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Sample {
    /// Time since the step (s).
    pub t_s: f64,
    /// Commanded position.
    pub command: f64,
    /// Measured position.
    pub position: f64,
    /// Effort.
    pub effort: f64,
}

/// Figures of a step response.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct StepFigures {
    /// 10 % to 90 % of the step (s); `None` if the axis never got there.
    pub rise_s: Option<f64>,
    /// Largest excursion beyond the target, in % of the step.
    pub overshoot_pct: f64,
    /// From the step until the error stays within `band` (s); `None` if it never did.
    pub settling_s: Option<f64>,
    /// The settling band (axis unit): the larger of 2 % of the step and the in-position band.
    pub band: f64,
    /// Largest |command − position| after the step (the step itself, at its instant).
    pub peak_following_error: f64,
    /// Largest |effort| after the step.
    pub peak_effort: f64,
}

/// Figures of the ramp.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct RampFigures {
    /// Distance moved out and back (axis unit).
    pub distance: f64,
    /// Largest |following error| while moving.
    pub peak_following_error: f64,
    /// From the end of the motion until the axis settled (s), as servo judges it.
    pub settling_s: Option<f64>,
}

/// What `supervisor tune` measured.
#[derive(Clone, Debug, Serialize)]
pub struct TuneReport {
    /// Instance.
    pub instance: String,
    /// Axis name.
    pub axis: String,
    /// Its unit.
    pub unit: String,
    /// Servo period (µs).
    pub servo_period_us: u64,
    /// Step amplitude.
    pub step: f64,
    /// The step response.
    pub step_response: StepFigures,
    /// The ramp, if asked for.
    pub ramp: Option<RampFigures>,
    /// The recorded step response.
    #[serde(skip)]
    pub samples: Vec<Sample>,
    /// Every event of the session.
    pub events: Vec<control_plane::event::Event>,
}

/// The figures of a recorded step of `amplitude` from `start` (samples from the step on).
pub fn step_figures(
    samples: &[Sample],
    start: f64,
    amplitude: f64,
    in_position: f64,
) -> StepFigures {
    let target = start + amplitude;
    let y = |s: &Sample| (s.position - start) / amplitude;
    let first = |frac: f64| samples.iter().find(|s| y(s) >= frac).map(|s| s.t_s);
    let rise_s = match (first(0.1), first(0.9)) {
        (Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    let overshoot_pct = samples
        .iter()
        .map(|s| (y(s) - 1.0).max(0.0) * 100.0)
        .fold(0.0, f64::max);
    let band = (0.02 * amplitude.abs()).max(in_position);
    let last_out = samples
        .iter()
        .rposition(|s| (s.position - target).abs() > band);
    let settling_s = match last_out {
        None => samples.first().map(|s| s.t_s),
        Some(i) if i + 1 < samples.len() => Some(samples[i + 1].t_s),
        Some(_) => None,
    };
    StepFigures {
        rise_s,
        overshoot_pct,
        settling_s,
        band,
        peak_following_error: samples
            .iter()
            .map(|s| (s.command - s.position).abs())
            .fold(0.0, f64::max),
        peak_effort: samples.iter().map(|s| s.effort.abs()).fold(0.0, f64::max),
    }
}

/// Runs the tuning session; see the module documentation.
pub fn tune(opts: &TuneOptions) -> Result<TuneReport, RunError> {
    let cfg = Config::load(opts.config.as_deref()).map_err(|e| RunError::Input(e.to_string()))?;
    let i = cfg
        .axis
        .iter()
        .position(|a| a.name == opts.axis)
        .ok_or_else(|| {
            let names: Vec<&str> = cfg.axis.iter().map(|a| a.name.as_str()).collect();
            RunError::Input(format!(
                "--axis {:?}: the cell has axes {}",
                opts.axis,
                names.join(", ")
            ))
        })?;
    let a = cfg.axis[i].clone();
    let half = a.following_error_limit / 2.0;
    if !(opts.step.is_finite() && opts.step != 0.0 && opts.step.abs() <= half) {
        return Err(RunError::Input(format!(
            "--step {}: the step must be non-zero and at most half the following-error limit of axis {} ({half} {})",
            opts.step, a.name, a.unit
        )));
    }
    if !(a.min..=a.max).contains(&(a.start + opts.step)) {
        return Err(RunError::Input(format!(
            "--step {}: axis {} would leave its range {} .. {} from its start {}",
            opts.step, a.name, a.min, a.max, a.start
        )));
    }
    if let Some(d) = opts.ramp
        && !(d.is_finite() && d != 0.0 && (a.min..=a.max).contains(&(a.start + d)))
    {
        return Err(RunError::Input(format!(
            "--ramp {d}: axis {} would leave its range {} .. {} from its start {}",
            a.name, a.min, a.max, a.start
        )));
    }
    let instance = InstanceName::new(&opts.instance)
        .map_err(|e| RunError::Input(format!("--instance {:?}: {e}", opts.instance)))?;
    let (mut session, server) = open_cell(&cfg, instance, Mode::Run)?;
    let measured = measure(&mut session, &cfg, i, opts);
    let closed = session.close(server);
    let (samples, start, ramp) = match measured {
        Ok(m) => m,
        // A failed session still reports its events.
        Err(RunError::Failed { message, .. }) => {
            return Err(RunError::Failed {
                message,
                events: closed.events,
                figures: None,
            });
        }
        Err(e) => return Err(e),
    };
    if let Some(e) = closed.problem {
        return Err(e);
    }
    let events = closed.events;
    Ok(TuneReport {
        instance: instance.to_string(),
        axis: a.name.clone(),
        unit: a.unit.clone(),
        servo_period_us: cfg.process_named("servo").map_or(1000, |p| p.period_us),
        step: opts.step,
        step_response: step_figures(&samples, start, opts.step, a.in_position),
        ramp,
        samples,
        events,
    })
}

type Measured = (Vec<Sample>, f64, Option<RampFigures>);

/// Longest wait for servo to take a step, or for the axes to settle.
const PATIENCE: Duration = Duration::from_secs(3);

/// Reads servo's states as they come, for at most `limit`, handing each to `stop` until it
/// returns true (then true). Fails on a process failure or a latched fault.
fn watch(
    session: &mut Cell,
    cfg: &Config,
    limit: Duration,
    mut stop: impl FnMut(&ServoStateV3) -> bool,
) -> Result<bool, RunError> {
    let start = Instant::now();
    while start.elapsed() < limit {
        session.check_health(cfg)?;
        while let Some(s) = session.servo_sub.next() {
            if s.status & st::FAULT_LATCHED != 0 {
                session.take_events();
                return Err(RunError::failed(session.fault_text(&s)));
            }
            if stop(&s) {
                return Ok(true);
            }
        }
        std::thread::sleep(TICK);
    }
    Ok(false)
}

/// Waits (at most `limit`) until servo says the arm is settled; records every servo state on
/// the way into `log` when given. Returns the settled state.
fn until_settled(
    session: &mut Cell,
    cfg: &Config,
    limit: Duration,
    mut log: Option<&mut Vec<ServoStateV3>>,
) -> Result<Option<ServoStateV3>, RunError> {
    let mut settled = None;
    watch(session, cfg, limit, |s| {
        if let Some(l) = log.as_deref_mut() {
            l.push(*s);
        }
        if s.status & st::SETTLED != 0 {
            settled = Some(*s);
        }
        settled.is_some()
    })?;
    Ok(settled)
}

fn measure(
    session: &mut Cell,
    cfg: &Config,
    i: usize,
    opts: &TuneOptions,
) -> Result<Measured, RunError> {
    let start_sp = session.startup(cfg)?;
    let settled = until_settled(session, cfg, PATIENCE, None)?
        .ok_or_else(|| RunError::failed("the axes did not settle after enabling"))?;
    let start = settled.cmd_position[i];

    // The step: record until settled again, plus a little, at most 3 s.
    session.request_with(RequestKind::Step, i as u32, opts.step)?;
    let mut log = Vec::new();
    // Skip the cycles before servo took the request.
    let taken = watch(session, cfg, PATIENCE, |s| {
        let stepped = (s.cmd_position[i] - start).abs() > opts.step.abs() / 2.0;
        if stepped {
            log.push(*s);
        }
        stepped
    })?;
    if !taken {
        session.take_events();
        return Err(RunError::failed(
            "servo did not take the step (see the request-refused event)",
        ));
    }
    until_settled(session, cfg, PATIENCE, Some(&mut log))?;
    watch(session, cfg, Duration::from_millis(300), |s| {
        log.push(*s);
        false
    })?;
    let t0 = log[0].stamp_ns;
    let samples: Vec<Sample> = log
        .iter()
        .map(|s| Sample {
            t_s: (s.stamp_ns - t0) as f64 * 1e-9,
            command: s.cmd_position[i],
            position: s.act_position[i],
            effort: s.effort[i],
        })
        .collect();
    session.request_with(RequestKind::Step, i as u32, 0.0)?;
    // Servo's states queued before it took the step back still say "settled": wait for the
    // command to return first.
    let returned = watch(session, cfg, PATIENCE, |s| {
        (s.cmd_position[i] - start).abs() < opts.step.abs() / 2.0
    })?;
    if !returned {
        return Err(RunError::failed("servo did not take the step back"));
    }
    until_settled(session, cfg, PATIENCE, None)?
        .ok_or_else(|| RunError::failed("the axis did not settle after the step back"))?;

    let ramp = match opts.ramp {
        None => None,
        Some(d) => Some(ramp(session, cfg, i, d, start_sp.seq)?),
    };
    Ok((samples, start, ramp))
}

/// Out by `d` on axis `i` and back, through trajgen.
fn ramp(
    session: &mut Cell,
    cfg: &Config,
    i: usize,
    d: f64,
    salt: u64,
) -> Result<RampFigures, RunError> {
    let n = cfg.axis.len();
    let mut home = [0.0; MAX_AXES];
    let sp = session
        .setpoint_sub
        .latest()
        .ok_or_else(|| RunError::failed("trajgen publishes no setpoint"))?;
    home[..n].copy_from_slice(&sp.position[..n]);
    let mut out = home;
    out[i] += d;
    let program_id = (std::process::id() ^ (salt as u32).rotate_left(8)) | 1;
    let cmd = |seq: u64, kind: CommandKind, target: [f64; MAX_AXES]| MotionCommandV2 {
        seq,
        program_id,
        line: seq as u32,
        kind: kind as u32,
        count: n as u32,
        target,
        ..MotionCommandV2::default()
    };
    // A joint move: the step is one axis' own, whatever the kinematics.
    for c in [
        cmd(1, CommandKind::MoveJ, out),
        cmd(2, CommandKind::MoveJ, home),
        cmd(3, CommandKind::End, home),
    ] {
        if !session.command_pub.send(&c) {
            return Err(RunError::failed(
                "trajgen's command service refused a command",
            ));
        }
    }
    let mut peak = 0.0f64;
    let mut end_ns = None;
    let start = Instant::now();
    let limit =
        Duration::from_secs_f64(2.0 * (d.abs() / cfg.axis[i].vmax + 4.0 * cfg.motion.t_acc) + 5.0);
    while end_ns.is_none() {
        if start.elapsed() > limit {
            return Err(RunError::failed("the ramp did not end"));
        }
        session.check_health(cfg)?;
        while let Some(sp) = session.setpoint_sub.next() {
            if sp.program_id == program_id && sp.state == MotionState::Done as u32 {
                end_ns = Some(sp.motion_end_ns);
            }
        }
        while let Some(s) = session.servo_sub.next() {
            if s.status & st::FAULT_LATCHED != 0 {
                session.take_events();
                return Err(RunError::failed(session.fault_text(&s)));
            }
            peak = peak.max(s.following_error[i].abs());
        }
        std::thread::sleep(TICK);
    }
    let mut log = Vec::new();
    let settled = until_settled(session, cfg, PATIENCE, Some(&mut log))?;
    for s in &log {
        peak = peak.max(s.following_error[i].abs());
    }
    let end = end_ns.unwrap_or(0);
    Ok(RampFigures {
        distance: d,
        peak_following_error: peak,
        settling_s: settled.map(|s| {
            (s.stamp_ns.saturating_sub(end) as f64 * 1e-9 - cfg.motion.settle_time).max(0.0)
        }),
    })
}

impl TuneReport {
    /// The JSON object of `supervisor tune --json`.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or(serde_json::Value::Null)
    }

    /// The human summary.
    pub fn human(&self) -> String {
        let u = &self.unit;
        let f = &self.step_response;
        let opt = |v: Option<f64>| v.map_or("never".to_string(), |v| format!("{:.1} ms", v * 1e3));
        let mut s = format!(
            "tune axis {} (instance {}, servo period {} µs): step {} {u}\n",
            self.axis, self.instance, self.servo_period_us, self.step
        );
        s += &format!("  rise time (10-90 %)    {}\n", opt(f.rise_s));
        s += &format!("  overshoot              {:.1} %\n", f.overshoot_pct);
        s += &format!(
            "  settling time          {} (within {:.4} {u})\n",
            opt(f.settling_s),
            f.band
        );
        s += &format!(
            "  peak following error   {:.4} {u}\n",
            f.peak_following_error
        );
        s += &format!("  peak effort            {:.3}\n", f.peak_effort);
        if let Some(r) = &self.ramp {
            s += &format!(
                "  ramp {} {u} and back: peak following error {:.4} {u}, settled {} after the motion\n",
                r.distance,
                r.peak_following_error,
                opt(r.settling_s)
            );
        }
        s
    }

    /// The PNG of the step response: command and position, and effort.
    pub fn plot(&self) -> Result<Vec<u8>, String> {
        let pts = |f: fn(&Sample) -> f64| -> Vec<(f64, f64)> {
            self.samples.iter().map(|s| (s.t_s * 1e3, f(s))).collect()
        };
        series_png(
            &format!(
                "step {} {} on axis {} (servo period {} \u{b5}s)",
                self.step, self.unit, self.axis, self.servo_period_us
            ),
            "time since the step (ms)",
            &[
                Panel {
                    y_label: format!("position ({})", self.unit),
                    lines: vec![
                        ("command".into(), pts(|s| s.command)),
                        ("position".into(), pts(|s| s.position)),
                    ],
                },
                Panel {
                    y_label: "effort".into(),
                    lines: vec![("effort".into(), pts(|s| s.effort))],
                },
            ],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_s: f64, position: f64) -> Sample {
        Sample {
            t_s,
            command: 1.0,
            position,
            effort: 0.0,
        }
    }

    #[test]
    fn step_figures_read_rise_overshoot_and_settling() {
        // 0 → 1: 10 % at 2 ms, 90 % at 6 ms, overshoot to 1.1, inside 2 % from 12 ms on.
        let pos = [
            0.0, 0.05, 0.12, 0.4, 0.7, 0.85, 0.95, 1.05, 1.1, 1.06, 1.03, 1.021, 1.01, 1.0, 0.995,
        ];
        let s: Vec<Sample> = pos
            .iter()
            .enumerate()
            .map(|(k, p)| sample(k as f64 * 1e-3, *p))
            .collect();
        let f = step_figures(&s, 0.0, 1.0, 0.001);
        assert!((f.rise_s.expect("rise") - 0.004).abs() < 1e-12);
        assert!((f.overshoot_pct - 10.0).abs() < 1e-9);
        assert_eq!(f.band, 0.02);
        assert!((f.settling_s.expect("settles") - 0.012).abs() < 1e-12);
        assert_eq!(f.peak_following_error, 1.0);
        // A negative step reads the same way.
        let neg: Vec<Sample> = s
            .iter()
            .map(|x| Sample {
                position: -x.position,
                command: -1.0,
                ..*x
            })
            .collect();
        let g = step_figures(&neg, 0.0, -1.0, 0.001);
        assert_eq!(g.rise_s, f.rise_s);
        assert!((g.overshoot_pct - 10.0).abs() < 1e-9);
    }

    #[test]
    fn a_response_that_never_settles_says_so() {
        let s: Vec<Sample> = (0..10).map(|k| sample(k as f64 * 1e-3, 0.5)).collect();
        let f = step_figures(&s, 0.0, 1.0, 0.001);
        assert_eq!((f.rise_s, f.settling_s), (None, None));
    }
}
