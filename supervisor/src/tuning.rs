//! A tuning session as a job of the supervisor's one loop ([`Tuning`], stepped by
//! [`crate::serve`]): the step, its response, the step back, the ramp, and the figures read
//! from them. The command that starts a cell for it and reports is [`crate::tune`].

use crate::cell::{Cell, Incident};
use crate::error::RunError;
use cell_config::Config;
use control_plane::Failure;
use control_plane::failure::TuningStage;
use runtime::time::Moment;
use serde::Serialize;
use shm_schema::drive::servo_status as st;
use shm_schema::{CommandKind, MAX_AXES, MotionCommandV2, MotionState, RequestKind, ServoStateV3};
use std::time::Duration;

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

/// What a tuning session measured: the step response from the step on, where the axis
/// stood before it, the ramp's figures.
#[derive(Debug)]
pub(crate) struct Measured {
    pub(crate) samples: Vec<Sample>,
    pub(crate) start: f64,
    pub(crate) ramp: Option<RampFigures>,
}

/// Longest wait for servo to take a step, or for the axes to settle.
const PATIENCE: Duration = Duration::from_secs(3);

/// How long the response is recorded after the axis settled.
const TAIL: Duration = Duration::from_millis(300);

/// A tuning session as a job of the supervisor's loop ([`crate::serve`]), stepped every tick
/// once the drives are enabled: the step, its response, the step back, the ramp (see the
/// module documentation). The loop answers the control channel meanwhile (`status`, `estop`;
/// what would change the cell is refused busy) and a signal or `down` ends it with a
/// controlled stop.
#[derive(Debug)]
pub(crate) struct Tuning {
    axis: usize,
    step: f64,
    ramp: Option<f64>,
    stage: Stage,
    /// When the stage began: its patience counts from there.
    since: Moment,
    /// The axis' commanded position at rest before the step.
    start: f64,
    /// Servo's states from the step on.
    log: Vec<ServoStateV3>,
    samples: Vec<Sample>,
    /// Makes the ramp's program id this session's own.
    salt: u64,
}

/// Where a tuning session stands; each stage ends on what servo (or trajgen) reports, or
/// fails when it waits longer than its patience.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Stage {
    /// Enabled: until servo says the axes are settled.
    Settling,
    /// The step requested: until servo's command moved by half of it.
    Stepping,
    /// The response, every state recorded, until the axis settles (or its patience ends).
    Responding,
    /// [`TAIL`] more of the response.
    Tail,
    /// The step back requested: until servo's command returned.
    Returning,
    /// Until the axis settles back.
    SettlingBack,
    /// The ramp's moves sent to trajgen: until it reports the program done.
    Ramping {
        program_id: u32,
        peak: f64,
        limit: Duration,
    },
    /// Until the axis settles after the ramp.
    RampSettling { end_ns: u64, peak: f64 },
}

impl Tuning {
    /// A session on axis `axis`: a step of `step`, then a ramp out by `ramp` and back.
    pub(crate) fn new(axis: usize, step: f64, ramp: Option<f64>) -> Self {
        Self {
            axis,
            step,
            ramp,
            stage: Stage::Settling,
            since: Moment::now(),
            start: 0.0,
            log: Vec::new(),
            samples: Vec::new(),
            salt: 0,
        }
    }

    /// Begins once the drives are enabled; `sp` is the first setpoint after.
    pub(crate) fn begin(&mut self, sp: &shm_schema::SetpointV2) {
        self.salt = sp.seq;
        self.to(Stage::Settling);
    }

    /// The axis being tuned.
    pub(crate) fn axis(&self) -> usize {
        self.axis
    }

    fn to(&mut self, stage: Stage) {
        self.stage = stage;
        self.since = Moment::now();
    }

    /// One tick: reads what servo and trajgen published and moves on; `Some` at the end.
    pub(crate) fn step(
        &mut self,
        cell: &mut Cell,
        cfg: &Config,
        incidents: &[Incident],
    ) -> Option<Result<Measured, RunError>> {
        if let Some(i) = incidents.first() {
            return Some(Err(i.error()));
        }
        if cell.estop.is_some() && !cell.reactions_pending() {
            let estop = cell.estop_failure().unwrap_or_else(|| Failure::System {
                what: "e-stop".into(),
            });
            return Some(Err(RunError::failed(estop)));
        }
        self.tick(cell, cfg).transpose()
    }

    fn tick(&mut self, cell: &mut Cell, cfg: &Config) -> Result<Option<Measured>, RunError> {
        while let Some(sp) = cell.setpoint_sub.next() {
            cell.last_sp = Some(sp);
            if let Stage::Ramping {
                program_id, peak, ..
            } = self.stage
                && sp.program_id == program_id
                && sp.state == MotionState::Done as u32
            {
                self.to(Stage::RampSettling {
                    end_ns: sp.motion_end_ns,
                    peak,
                });
            }
        }
        cell.drain_images(|_| {});
        while let Some(s) = cell.servo_sub.next() {
            cell.last_servo = Some(s);
            if s.status & st::FAULT_LATCHED != 0 {
                cell.take_events();
                return Err(RunError::failed(cell.fault(&s)));
            }
            if let Some(done) = self.see(cell, cfg, &s)? {
                return Ok(Some(done));
            }
        }
        let waited = self.since.elapsed();
        match self.stage {
            Stage::Settling if waited > PATIENCE => Err(tuning(TuningStage::Settling)),
            Stage::Stepping if waited > PATIENCE => {
                cell.take_events();
                Err(tuning(TuningStage::Step))
            }
            // A response that does not settle is measured all the same (its figures say so).
            Stage::Responding if waited > PATIENCE => {
                self.to(Stage::Tail);
                Ok(None)
            }
            Stage::Tail if waited > TAIL => {
                self.step_back(cell)?;
                Ok(None)
            }
            Stage::Returning if waited > PATIENCE => Err(tuning(TuningStage::StepBack)),
            Stage::SettlingBack if waited > PATIENCE => Err(tuning(TuningStage::SettlingBack)),
            Stage::Ramping { limit, .. } if waited > limit => Err(tuning(TuningStage::Ramp)),
            Stage::RampSettling { end_ns, peak } if waited > PATIENCE => {
                Ok(Some(self.measured(cfg, end_ns, peak, None)))
            }
            _ => Ok(None),
        }
    }

    /// One of servo's states, in order; `Some` when the session is over.
    fn see(
        &mut self,
        cell: &mut Cell,
        cfg: &Config,
        s: &ServoStateV3,
    ) -> Result<Option<Measured>, RunError> {
        let i = self.axis;
        let settled = s.status & st::SETTLED != 0;
        match self.stage {
            Stage::Settling if settled => {
                self.start = s.cmd_position[i];
                cell.request_with(RequestKind::Step, i as u32, self.step)?;
                self.to(Stage::Stepping);
            }
            // The cycles before servo took the request are skipped.
            Stage::Stepping if (s.cmd_position[i] - self.start).abs() > self.step.abs() / 2.0 => {
                self.log.push(*s);
                self.to(Stage::Responding);
            }
            Stage::Responding => {
                self.log.push(*s);
                if settled {
                    self.to(Stage::Tail);
                }
            }
            Stage::Tail => self.log.push(*s),
            // Servo's states queued before it took the step back still say "settled": the
            // command returns first.
            Stage::Returning if (s.cmd_position[i] - self.start).abs() < self.step.abs() / 2.0 => {
                self.to(Stage::SettlingBack);
            }
            Stage::SettlingBack if settled => match self.ramp {
                None => return Ok(Some(self.measured(cfg, 0, 0.0, None))),
                Some(d) => self.send_ramp(cell, cfg, d)?,
            },
            Stage::Ramping {
                program_id,
                peak,
                limit,
            } => {
                self.stage = Stage::Ramping {
                    program_id,
                    peak: peak.max(s.following_error[i].abs()),
                    limit,
                };
            }
            Stage::RampSettling { end_ns, peak } => {
                let peak = peak.max(s.following_error[i].abs());
                if settled {
                    return Ok(Some(self.measured(cfg, end_ns, peak, Some(s))));
                }
                self.stage = Stage::RampSettling { end_ns, peak };
            }
            _ => {}
        }
        Ok(None)
    }

    /// The response recorded: its samples kept, the step taken back.
    fn step_back(&mut self, cell: &mut Cell) -> Result<(), RunError> {
        let i = self.axis;
        let t0 = self.log.first().map_or(0, |s| s.stamp_ns);
        self.samples = self
            .log
            .iter()
            .map(|s| Sample {
                t_s: s.stamp_ns.saturating_sub(t0) as f64 * 1e-9,
                command: s.cmd_position[i],
                position: s.act_position[i],
                effort: s.effort[i],
            })
            .collect();
        cell.request_with(RequestKind::Step, i as u32, 0.0)?;
        self.to(Stage::Returning);
        Ok(())
    }

    /// Out by `d` on the axis and back, through trajgen: a joint move, the step is one axis'
    /// own whatever the kinematics.
    fn send_ramp(&mut self, cell: &mut Cell, cfg: &Config, d: f64) -> Result<(), RunError> {
        let (i, n) = (self.axis, cfg.axis.len());
        let sp = cell.last_sp.ok_or_else(|| tuning(TuningStage::Setpoint))?;
        let mut home = [0.0; MAX_AXES];
        home[..n].copy_from_slice(&sp.position[..n]);
        let mut out = home;
        out[i] += d;
        let program_id = (std::process::id() ^ (self.salt as u32).rotate_left(8)) | 1;
        let cmd = |seq: u64, kind: CommandKind, target: [f64; MAX_AXES]| MotionCommandV2 {
            seq,
            program_id,
            line: seq as u32,
            kind: kind as u32,
            count: n as u32,
            target,
            ..MotionCommandV2::default()
        };
        for c in [
            cmd(1, CommandKind::MoveJ, out),
            cmd(2, CommandKind::MoveJ, home),
            cmd(3, CommandKind::End, home),
        ] {
            if !cell.command_pub.send(&c) {
                return Err(RunError::failed(Failure::ServiceRefused {
                    service: "trajgen's command service".into(),
                    sample: "a command".into(),
                }));
            }
        }
        let limit = Duration::from_secs_f64(
            2.0 * (d.abs() / cfg.axis[i].vmax + 4.0 * cfg.motion.t_acc) + 5.0,
        );
        self.to(Stage::Ramping {
            program_id,
            peak: 0.0,
            limit,
        });
        Ok(())
    }

    fn measured(
        &mut self,
        cfg: &Config,
        end_ns: u64,
        peak: f64,
        settled: Option<&ServoStateV3>,
    ) -> Measured {
        Measured {
            samples: std::mem::take(&mut self.samples),
            start: self.start,
            ramp: self.ramp.map(|distance| RampFigures {
                distance,
                peak_following_error: peak,
                settling_s: settled.map(|s| {
                    (s.stamp_ns.saturating_sub(end_ns) as f64 * 1e-9 - cfg.motion.settle_time)
                        .max(0.0)
                }),
            }),
        }
    }
}

/// The tuning session did not get through `stage`.
fn tuning(stage: TuningStage) -> RunError {
    RunError::failed(Failure::Tuning { stage })
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
