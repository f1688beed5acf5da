//! A program checked whole before anything moves (`supervisor check`, `run`, `exec`):
//! parsed against the cell (its coordinates, joints and named IO), every target within the
//! axes' limits, then run through the same generator trajgen runs ([`motion_core::predict`])
//! from where the axes stand, so the prediction is trajgen's own motion time and every
//! reference of the path is checked against the joint limits and velocities.

use crate::error::RunError;
use cell_config::Config;
use motion_core::Params;
use motion_core::generator::{Generator, Kin};
use motion_core::predict::{Outcome, Prediction, simulate_program};
use motion_program::{Commands, Op, Program, Space};
use shm_schema::MAX_AXES;
use shm_schema::motion::trajgen_fault;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// The longest a program without `REPEAT` for ever may run (s): 24 h.
pub const MAX_PROGRAM_S: f64 = 86_400.0;

/// The validation samples the path at least this often (s).
pub const SAMPLE_S: f64 = 0.001;

/// A parsed program that passed the checks that need no start position.
#[derive(Clone, Debug)]
pub struct Checked {
    /// Its name as the user gave it (a file name).
    pub name: String,
    /// Its source, as text.
    pub src: String,
    /// The program.
    pub program: Arc<Program>,
}

/// What [`Checked::predict`] found: the motion time trajgen will take.
#[derive(Clone, Debug, PartialEq)]
pub struct Predicted {
    /// Motion time to `END` (s), `WAIT`s excluded; for a program that runs for ever, its
    /// first iteration and what precedes it.
    pub duration_s: f64,
    /// For a program that runs for ever: the time of one more iteration (s).
    pub iteration_s: Option<f64>,
    /// The outputs the program sets, and when (motion time): the IO timeline.
    pub outputs: Vec<motion_core::predict::OutputEvent>,
    /// Loop iterations that began as the one before and were passed over, not simulated.
    pub passed_over: u64,
}

/// The generator's parameters for this cell (trajgen builds the same from the shared
/// configuration).
pub fn params(cfg: &Config) -> Params {
    Params::from_cell(&cfg.to_shm())
}

/// The cell's kinematics as trajgen builds it (`None`: the gantry).
pub fn kin(cfg: &Config) -> Result<Option<Kin>, RunError> {
    Kin::of_cell(&cfg.to_shm()).map_err(|e| RunError::Input(format!("kinematics: {e}")))
}

impl Checked {
    /// Parses `bytes` (named `name` in messages) and checks every target against the axes'
    /// limits.
    pub fn new(cfg: &Config, name: &str, bytes: &[u8]) -> Result<Self, RunError> {
        let at = |line: u32, col: u32, message: &str| {
            RunError::Input(format!("{name}:{line}:{col}: {message}"))
        };
        let program = motion_program::parse(bytes, &cfg.cell_spec())
            .map_err(|e| at(e.line, e.col, &e.message))?;
        let kin = kin(cfg)?;
        let start: Vec<f64> = cfg.axis.iter().map(|a| a.start).collect();
        let limits: Vec<kinematics::JointLimit> = cfg
            .axis
            .iter()
            .map(|a| kinematics::JointLimit::new(a.min, a.max))
            .collect();
        for ins in program.flat() {
            let Op::Move {
                space,
                target,
                cols,
                ..
            } = &ins.op
            else {
                continue;
            };
            // A Cartesian target must have a joint solution within the limits (the path to
            // it is checked by the prediction); a joint target, the axes' limits.
            if let (Space::Cartesian, Some(k)) = (space, &kin) {
                let mut p = [0.0; kinematics::MAX_COORDS];
                let n = p.len().min(program.coords);
                p[..n].copy_from_slice(&target[..n]);
                let mut reference = [0.0; kinematics::MAX_JOINTS];
                reference[..start.len()].copy_from_slice(&start);
                if let Err(e) = kinematics::cartesian_to_axes(&*k.0, &p, &reference, &limits) {
                    return Err(at(ins.line, cols[0], &format!("out of reach: {e}")));
                }
                continue;
            }
            for (i, a) in cfg.axis.iter().enumerate() {
                let v = target[i];
                if v < a.min || v > a.max {
                    return Err(at(
                        ins.line,
                        cols[i],
                        &format!(
                            "{} = {} {} is outside the axis limits {} .. {} {}",
                            a.name, v, a.unit, a.min, a.max, a.unit
                        ),
                    ));
                }
            }
        }
        Ok(Self {
            name: name.to_string(),
            src: String::from_utf8_lossy(bytes).into_owned(),
            program: Arc::new(program),
        })
    }

    /// The commands trajgen runs (loops unrolled as drawn).
    pub fn commands(&self, program_id: u32) -> Commands {
        Commands::new(self.program.clone(), program_id)
    }

    /// Runs the program through trajgen's generator from `start` (joint positions): its
    /// motion time, and every reference checked against the joint limits and velocities.
    /// A loop runs until two of its iterations begin alike, and the rest are passed over
    /// ([`motion_core::predict::simulate_program`]); a long program without loops takes
    /// seconds (about one for each hour of motion): a running cell validates on a thread of
    /// its own ([`Validation`]).
    pub fn predict(&self, cfg: &Config, start: &[f64]) -> Result<Predicted, RunError> {
        self.predict_until(cfg, start, &AtomicBool::new(false))
    }

    /// [`Checked::predict`], cut short once `cancel` is set (its caller has let it go).
    fn predict_until(
        &self,
        cfg: &Config,
        start: &[f64],
        cancel: &AtomicBool,
    ) -> Result<Predicted, RunError> {
        let forever = self.program.forever();
        let once = self.simulate(cfg, start, forever.then_some(1), cancel)?;
        let iteration_s = if forever {
            let twice = self.simulate(cfg, start, Some(2), cancel)?;
            Some(twice.duration_s - once.duration_s)
        } else {
            None
        };
        Ok(Predicted {
            duration_s: once.duration_s,
            iteration_s,
            outputs: once.outputs,
            passed_over: once.passed_over,
        })
    }

    fn simulate(
        &self,
        cfg: &Config,
        start: &[f64],
        forever_as: Option<u32>,
        cancel: &AtomicBool,
    ) -> Result<Prediction, RunError> {
        let p = params(cfg);
        let generator = Generator::with_kinematics(p, kin(cfg)?, start);
        let n = cfg.axis.len();
        // Every millisecond at most (between two samples a joint moves at most vmax × 1 ms),
        // and at every transition the generator asks for.
        let dt = cfg.period_s("trajgen").clamp(1e-4, SAMPLE_S);
        let mut violation: Option<String> = None;
        let mut check = |sp: &shm_schema::SetpointV2| {
            if violation.is_some() {
                return;
            }
            for (i, a) in cfg.axis.iter().enumerate().take(n.min(MAX_AXES)) {
                let (q, v) = (sp.position[i], sp.velocity[i]);
                if !(q.is_finite() && v.is_finite()) || q < a.min - 1e-9 || q > a.max + 1e-9 {
                    violation = Some(format!(
                        "{}:{}: the path reaches {} = {q:.4} {}, outside the axis limits {} .. {} {} \
                         (motion time {:.3} s)",
                        self.name, sp.line, a.name, a.unit, a.min, a.max, a.unit, sp.motion_time_s
                    ));
                    return;
                }
                if v.abs() > a.vmax * (1.0 + 1e-9) {
                    violation = Some(format!(
                        "{}:{}: {} reaches {v:.4} {}/s, above its vmax {} {}/s (motion time {:.3} s)",
                        self.name, sp.line, a.name, a.unit, a.vmax, a.unit, sp.motion_time_s
                    ));
                    return;
                }
            }
        };
        let commands = Commands::bounded(self.program.clone(), 1, forever_as);
        let go_on = || !cancel.load(Ordering::Relaxed);
        let prediction =
            simulate_program(generator, commands, dt, MAX_PROGRAM_S, &mut check, &go_on);
        if let Some(v) = violation {
            return Err(RunError::Input(v));
        }
        match prediction.outcome {
            Outcome::Done => Ok(prediction),
            Outcome::Fault { code, line } => Err(RunError::Input(match prediction.kin_error {
                Some(e) if code == trajgen_fault::UNREACHABLE => {
                    format!(
                        "{}:{line}: the path leaves the kinematics' reach: {e}",
                        self.name
                    )
                }
                _ => format!(
                    "{}:{line}: trajgen would refuse it: {}",
                    self.name,
                    trajgen_fault::text(code)
                ),
            })),
            Outcome::TooLong => Err(RunError::Input(format!(
                "{}: the program runs longer than {} h; a program that runs for hours is a \
                 REPEAT without a count",
                self.name,
                MAX_PROGRAM_S / 3600.0
            ))),
            Outcome::Stopped => Err(RunError::system(format!(
                "{}: the validation was let go",
                self.name
            ))),
        }
    }
}

/// A program's prediction ([`Checked::predict`]) computed on a thread of its own, so that the
/// supervisor's loop goes on meanwhile: the heartbeat, the health checks and the control
/// channel (`status`, `estop`, `down`) are never blind while a long program is validated.
pub(crate) struct Validation {
    /// The program.
    pub(crate) program: Checked,
    /// The joint positions it is validated from.
    pub(crate) start: Vec<f64>,
    thread: Option<std::thread::JoinHandle<Result<Predicted, RunError>>>,
    /// Set when it is let go (dropped: the cell goes down, an incident): the thread stops
    /// within a few commands instead of running on to the program's end, a core busy.
    cancel: Arc<AtomicBool>,
}

impl Drop for Validation {
    fn drop(&mut self) {
        self.cancel.store(true, Ordering::Relaxed);
    }
}

impl Validation {
    /// Starts validating `program` from `start` (joint positions).
    pub(crate) fn start(cfg: &Config, program: Checked, start: &[f64]) -> Result<Self, RunError> {
        let (cfg, p, from) = (cfg.clone(), program.clone(), start.to_vec());
        let cancel = Arc::new(AtomicBool::new(false));
        let stop = cancel.clone();
        let thread = std::thread::Builder::new()
            .name("validation".into())
            .spawn(move || p.predict_until(&cfg, &from, &stop))
            .map_err(|e| RunError::system(format!("cannot start the validation: {e}")))?;
        Ok(Self {
            program,
            start: start.to_vec(),
            thread: Some(thread),
            cancel,
        })
    }

    /// The prediction once it is done. (A panic in it aborts the supervisor, as any panic of
    /// ours does: `runtime::abort_on_panic`.)
    pub(crate) fn done(&mut self) -> Option<Result<Predicted, RunError>> {
        if !self.thread.as_ref()?.is_finished() {
            return None;
        }
        let thread = self.thread.take()?;
        Some(
            thread
                .join()
                .unwrap_or_else(|_| Err(RunError::system("the validation panicked"))),
        )
    }
}
