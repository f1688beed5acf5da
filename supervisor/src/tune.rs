//! `supervisor tune`: commissioning help on the real processes of the cell, as a job of the
//! supervisor's one loop ([`Tuning`]).
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

use crate::cell::{Mode, open_cell};
use crate::error::RunError;
use crate::serve::{End, First, serve};
use crate::tuning::{Measured, RampFigures, Sample, StepFigures, Tuning, step_figures};
use cell_config::Config;
use control_plane::Failure;
use plot::{Panel, series_png};
use serde::Serialize;
use shm_schema::InstanceName;
use std::path::PathBuf;

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
    let (mut cell, mut server, _) = open_cell(&cfg, instance, Mode::Run, None)?;
    let first = First::Tune(Tuning::new(i, opts.step, opts.ramp));
    let end = serve(&cfg, &mut cell, &mut server, Some(first), None).end;
    let closed = cell.close(server);
    let measured = match end {
        End::Tuned(m) => *m,
        End::Interrupted => Err(RunError::Interrupted),
        End::Failed(e) => Err(*e),
        End::Down | End::Program(_) => Err(RunError::failed(Failure::Down {
            job: "the tuning".into(),
        })),
    };
    let Measured {
        samples,
        start,
        ramp,
    } = match measured {
        Ok(m) => m,
        // A failed session still reports its events.
        Err(RunError::Failed { failure, .. }) => {
            return Err(RunError::Failed {
                failure,
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
        servo_period_us: cfg
            .process_named("servo")
            .expect("a validated configuration has its required processes")
            .period_us,
        step: opts.step,
        step_response: step_figures(&samples, start, opts.step, a.in_position),
        ramp,
        samples,
        events,
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
