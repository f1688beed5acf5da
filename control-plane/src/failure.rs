//! Why a started job (a program, an enabling, a tuning session, a swap) failed: the cause as
//! data, one variant each, and `Display` the line a user reads. The supervisor builds it, the
//! control channel carries it ([`crate::Reply::Failed`]), `run --json` prints it
//! ([`crate::report::RunFailure::cause`]), and a caller decides on the variant, never on the
//! words.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::fmt;

/// Why a started job failed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
// Externally tagged (`{"servo-fault": {...}}`, `"setpoint-jump"`): the control channel's
// postcard cannot carry an internally tagged enum.
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Failure {
    /// Servo latched a fault and cut power.
    ServoFault {
        /// The fault's event name (`docs/events.md`), e.g. `following-error-over-limit`.
        fault: String,
        /// Its event code.
        code: u32,
        /// The axis it names, if any.
        axis: Option<String>,
        /// The event that explains it, as `supervisor events` prints it.
        event: Option<String>,
    },
    /// The e-stop was raised by a process of the cell, the host or a user.
    Estop {
        /// Its origin (`external`, `device`, `host`).
        origin: crate::info::Origin,
        /// Who raised it: a process' name, or `supervisor`.
        by: String,
        /// The event code of its cause (`docs/events.md`: 502 `process-lost` for a process the
        /// supervisor lost, 604 `health-expired`, 702 `estop-input`, ...).
        code: u32,
        /// Its reason.
        reason: String,
        /// The event that explains it, as `supervisor events` prints it.
        event: Option<String>,
    },
    /// An e-stop latched during the motion, to which by the cell's propagation rules
    /// (`[behaviour]`) neither servo nor trajgen reacts: the motion completed, the e-stop
    /// stays latched.
    LatchedAfterMotion {
        /// The e-stop (a [`Failure::Estop`] or a [`Failure::ServoFault`]).
        estop: Box<Failure>,
    },
    /// The program was aborted (`supervisor abort`, Modbus): the axes rest on the path.
    Aborted {
        /// The program's name.
        program: String,
        /// The line it was at.
        line: u32,
        /// Motion time until then (s).
        motion_s: f64,
    },
    /// trajgen refused a command of the program: the axes stopped.
    TrajgenRefused {
        /// The program's name.
        program: String,
        /// The command's line.
        line: u32,
        /// trajgen's fault code (`shm_schema::motion::trajgen_fault`).
        fault: u32,
        /// The fault in words.
        what: String,
    },
    /// The arm was disabled by a request of another client during the run.
    Disabled {
        /// Servo's power state then.
        power: String,
    },
    /// Servo refused a setpoint as a jump (the `setpoint-jump` or `setpoint-velocity-jump`
    /// event says which test and by how much).
    SetpointJump,
    /// The axes did not settle after the motion's end.
    NotSettled {
        /// The settle timeout (s).
        timeout_s: f64,
        /// Each axis' following error then.
        following_error: Vec<AxisValue>,
    },
    /// `supervisor down` stopped the cell before the job ended.
    Down {
        /// What was under way: a program's name, "the tuning", "the enabling", ...
        job: String,
    },
    /// A signal (SIGTERM, SIGINT) stopped the supervisor, and the cell, before the job ended.
    Interrupted {
        /// What was under way.
        job: String,
    },
    /// No process of the cell reported the e-stop latched in time.
    EstopNotLatched {
        /// The instance.
        instance: String,
        /// How long it waited (s).
        within_s: f64,
    },
    /// A reset did not clear everything: each item what stays latched (a fault whose cause
    /// is still there, an e-stop raised again, processes that still show it).
    ResetIncomplete {
        /// What stays, one line each.
        left: Vec<String>,
    },
    /// trajgen did not complete a pause, resume, speed change or abort in time.
    ControlNotTaken {
        /// Which (`Pause`, `Resume`, `Speed`, `Abort`).
        control: String,
        /// How long it was given (s).
        within_s: f64,
    },
    /// The cell did not come up within `startup_timeout`.
    Startup {
        /// The timeout (s).
        timeout_s: f64,
        /// What was missing, one item each.
        missing: Vec<String>,
    },
    /// A process of the cell exited.
    Exited {
        /// Its name.
        process: String,
        /// Its pid.
        pid: u32,
        /// Its exit status, in words.
        status: String,
    },
    /// A process of the cell stopped cycling for `heartbeat_timeout`.
    Stalled {
        /// Its name.
        process: String,
        /// For how long (s).
        for_s: f64,
    },
    /// A process reported its fault state.
    ProcessFault {
        /// Its name.
        process: String,
        /// Its fault code.
        fault: u32,
    },
    /// A process of the cell did not stop when asked (`supervisor down`), or was not brought
    /// to rest by its own stop.
    NotStopped {
        /// Its name.
        process: String,
        /// What happened, in words.
        what: String,
    },
    /// A service of the cell did not take what the supervisor sent (its subscriber's buffer
    /// full, or gone).
    ServiceRefused {
        /// The service, e.g. `trajgen's command service`.
        service: String,
        /// What it did not take, e.g. `a command`.
        sample: String,
    },
    /// A tuning session did not get through a stage.
    Tuning {
        /// The stage that did not complete.
        stage: TuningStage,
    },
    /// A swap or a restart of a process did not complete.
    Swap {
        /// What went wrong, in words.
        what: String,
    },
    /// The supervisor's own means failed: shared memory, its control channel, a file, a
    /// signal handler; the words are the system's.
    System {
        /// What failed, with the system's error.
        what: String,
    },
    /// A critical process of a cell that is up was lost for good (its restart policy
    /// `never`, or its restart limit reached): the cell ran on without it until `down`.
    LostForGood {
        /// Its name.
        process: String,
        /// Why, in words (its last exit and the policy).
        why: String,
    },
}

/// A value of one axis, with its unit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AxisValue {
    /// The axis' name.
    pub axis: String,
    /// The value.
    pub value: f64,
    /// The axis' unit.
    pub unit: String,
}

/// The stage of a tuning session that did not complete ([`Failure::Tuning`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum TuningStage {
    /// Settling after enabling.
    Settling,
    /// Servo taking the step.
    Step,
    /// Servo taking the step back.
    StepBack,
    /// Settling after the step back.
    SettlingBack,
    /// The ramp's end.
    Ramp,
    /// trajgen's first setpoint (where the ramp starts).
    Setpoint,
}

impl fmt::Display for TuningStage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Settling => "the axes did not settle after enabling",
            Self::Step => "servo did not take the step (see the request-refused event)",
            Self::StepBack => "servo did not take the step back",
            Self::SettlingBack => "the axis did not settle after the step back",
            Self::Ramp => "the ramp did not end",
            Self::Setpoint => "trajgen publishes no setpoint",
        })
    }
}

/// "\n  <event>" when there is one.
fn event_line(event: &Option<String>) -> String {
    event.as_ref().map_or(String::new(), |e| format!("\n  {e}"))
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::ServoFault {
                fault, axis, event, ..
            } => {
                let axis = axis
                    .as_ref()
                    .map_or(String::new(), |a| format!(" on axis {a}"));
                write!(f, "servo cut power: {fault}{axis}{}", event_line(event))
            }
            Self::Estop {
                origin,
                by,
                reason,
                event,
                code: _,
            } => write!(
                f,
                "e-stop ({}) raised by {by}: {reason}{}",
                crate::word(origin),
                event_line(event)
            ),
            Self::LatchedAfterMotion { estop } => write!(
                f,
                "{estop}\n  the motion completed: by this cell's propagation rules \
                 (`[behaviour]`) neither servo nor trajgen reacts to it, but it stays latched"
            ),
            Self::Aborted {
                program,
                line,
                motion_s,
            } => write!(
                f,
                "{program}: aborted at line {line} after {motion_s:.2} s of motion; the axes \
                 rest on the path"
            ),
            Self::TrajgenRefused {
                program,
                line,
                fault,
                what,
            } => write!(
                f,
                "trajgen refused {program}:{line}: {what} (fault {fault}); the axes stopped"
            ),
            Self::Disabled { power } => write!(
                f,
                "the arm is no longer enabled (servo power {power}): a disable request from \
                 another client stopped the run"
            ),
            Self::SetpointJump => f.write_str(
                "servo refused a setpoint as a jump (see the setpoint-jump or \
                 setpoint-velocity-jump event)",
            ),
            Self::NotSettled {
                timeout_s,
                following_error,
            } => {
                let errs: Vec<String> = following_error
                    .iter()
                    .map(|e| format!("{} {:.4} {}", e.axis, e.value, e.unit))
                    .collect();
                write!(
                    f,
                    "the axes did not settle within {timeout_s} s of the end of the motion \
                     (following error {})",
                    errs.join(", ")
                )
            }
            Self::Down { job } => {
                write!(f, "`supervisor down` stopped the cell before {job} ended")
            }
            Self::Interrupted { job } => write!(
                f,
                "the supervisor was stopped by a signal before {job} ended"
            ),
            Self::EstopNotLatched { instance, within_s } => write!(
                f,
                "no process of instance {instance} reported the e-stop latched within {within_s} s"
            ),
            Self::ResetIncomplete { left } => write!(
                f,
                "reset did not clear everything:\n  {}",
                left.join("\n  ")
            ),
            Self::ControlNotTaken { control, within_s } => write!(
                f,
                "trajgen did not complete the {control} within {within_s:.1} s"
            ),
            Self::Startup { timeout_s, missing } => write!(
                f,
                "startup did not complete within {timeout_s:.1} s: {}",
                missing.join(", ")
            ),
            Self::Exited {
                process,
                pid,
                status,
            } => write!(f, "{process} (pid {pid}) exited unexpectedly: {status}"),
            Self::Stalled { process, for_s } => write!(
                f,
                "{process} stopped cycling: its status has not advanced for {for_s:.2} s"
            ),
            Self::ProcessFault { process, fault } => {
                write!(f, "{process} reports fault {fault}")
            }
            Self::NotStopped { process, what } => write!(f, "{process} {what}"),
            Self::ServiceRefused { service, sample } => write!(f, "{service} refused {sample}"),
            Self::Tuning { stage } => write!(f, "{stage}"),
            Self::Swap { what } | Self::System { what } => f.write_str(what),
            Self::LostForGood { process, why } => write!(
                f,
                "{process} was lost for good and the cell ran without it ({why})"
            ),
        }
    }
}

impl std::error::Error for Failure {}
