//! The supervisor's own view of its cell ([`Info`]): the answer to [`crate::Request::Info`], and
//! the `supervisor` part of `status --json`. The processes' own view (their cycle counts,
//! latency, servo's axes) is read from shared memory: [`crate::status`].

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// What the supervisor knows of its cell.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Info {
    /// The supervisor's pid.
    pub pid: u32,
    /// `supervisor up` or `supervisor run`.
    pub mode: Mode,
    /// The scheduling policy of the supervisor's loop, which publishes the heartbeat
    /// (`SCHED_FIFO` as `[supervisor] priority` asks, where the host grants it; else
    /// `SCHED_OTHER`).
    pub policy: String,
    /// Its `SCHED_FIFO` priority; 0 under `SCHED_OTHER`.
    pub priority: i32,
    /// E-stop resets since the cell started.
    pub resets: u64,
    /// The latched e-stop; `null` when clear.
    pub estop: Option<EstopInfo>,
    /// The arm as servo last reported it; `null` before its first state.
    pub arm: Option<ArmInfo>,
    /// Every process of the table, in its order.
    pub processes: Vec<ProcessInfo>,
    /// The program running now; `null` when none.
    pub job: Option<JobInfo>,
    /// The program being validated before it starts (`exec`); `null` when none.
    pub validating: Option<String>,
    /// The last program's end; `null` before the first.
    pub last_job: Option<LastJob>,
    /// The drives are being enabled.
    pub enabling: bool,
    /// The process being replaced (`swap`, `restart`); `null` when none.
    pub swapping: Option<String>,
    /// The axis being tuned (`supervisor tune`); `null` when none.
    pub tuning: Option<String>,
    /// The cell is going down (`down`, a signal): the axes come to rest, then the processes
    /// stop.
    pub going_down: bool,
}

/// Which command keeps the cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// `supervisor run`: one program, then down.
    Run,
    /// `supervisor up`: until `supervisor down`.
    Up,
}

/// Who raised an e-stop (seed 002's three origins).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Origin {
    /// A process of the cell, about itself.
    Device,
    /// The user, an e-stop input.
    External,
    /// The host: a process lost or stalled, a health detector, the supervisor's heartbeat.
    Host,
    /// A value this version does not know.
    #[serde(rename = "?")]
    Unknown,
}

impl From<u32> for Origin {
    fn from(v: u32) -> Self {
        use shm_schema::EstopOrigin as O;
        match O::from_wire(v) {
            Some(O::Device) => Self::Device,
            Some(O::External) => Self::External,
            Some(O::Host) => Self::Host,
            None => Self::Unknown,
        }
    }
}

/// The latched e-stop as the supervisor saw it raised.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EstopInfo {
    /// Who raised it.
    pub origin: Origin,
    /// The process, axis or input that raised it.
    pub source: String,
    /// Its event code (`docs/events.md`).
    pub code: u32,
    /// The raiser's own words.
    pub reason: String,
    /// All of it in words, with the event that explains it.
    pub text: Option<String>,
}

/// The arm: powered, and servo's latched fault.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ArmInfo {
    /// Servo holds the drives enabled.
    pub enabled: bool,
    /// Servo latched a fault (and cut power).
    pub fault_latched: bool,
    /// The fault in words; `null` when none is latched.
    pub fault: Option<String>,
}

/// One process of the table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ProcessInfo {
    /// Its name in the table.
    pub name: String,
    /// Its pid; `null` while it does not run.
    pub pid: Option<u32>,
    /// Where it is in its life.
    pub life: Life,
    /// Why it is down; `null` otherwise.
    pub why: Option<String>,
    /// Restarts, swaps included, since the cell started.
    pub restarts: u32,
    /// The command line a swap gave it; `null`: the configured one.
    pub command: Option<Vec<String>>,
    /// Its loss is an e-stop.
    pub critical: bool,
    /// The network address it announced it serves on; `null` when none.
    pub listening: Option<String>,
    /// Why it cannot listen on its address (its last `listen-failed` event's text) while it
    /// cannot; `null` otherwise.
    pub listen_failed: Option<String>,
}

/// Where a process is in its life.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Life {
    /// Started, not yet cyclic.
    Starting,
    /// Cyclic.
    Running,
    /// Lost; starts again after its back-off (its restart policy).
    Restarting,
    /// Lost for good (policy `never`, or the restart limit).
    Down,
}

/// The program running now.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct JobInfo {
    /// Its name as the user gave it.
    pub program: String,
    /// Its line trajgen runs; `null` before trajgen's first setpoint of it.
    pub line: Option<u32>,
    /// The motion time so far (s).
    pub motion_time_s: Option<f64>,
    /// The predicted motion time (s).
    pub predicted_s: f64,
    /// The path speed now (1 = programmed).
    pub path_speed: Option<f64>,
    /// Paused (the path speed is 0).
    pub paused: bool,
}

/// How the last program ended.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LastJob {
    /// Its name.
    pub program: String,
    /// It completed and settled.
    pub ok: bool,
    /// Why not; `null` when it did.
    pub error: Option<String>,
    /// Its measured motion time (s); `null` when it failed.
    pub measured_s: Option<f64>,
    /// Its theoretical motion time (s); `null` when it failed.
    pub theoretical_s: Option<f64>,
    /// From its start to its end on the supervisor's clock (s).
    pub ran_s: f64,
}

impl Info {
    /// The supervisor's part of `supervisor status`: the e-stop, the program, and per process
    /// its life and restarts.
    pub fn lines(&self) -> String {
        let mut out = format!(
            "supervisor pid {} ({}, loop {} {}), e-stop resets {}\n",
            self.pid,
            crate::word(&self.mode),
            self.policy,
            self.priority,
            self.resets
        );
        match &self.estop {
            None => out += "e-stop: clear\n",
            Some(e) => {
                out += &format!(
                    "e-stop: LATCHED: {}\n  `supervisor reset`, then `supervisor start`\n",
                    e.text.as_deref().unwrap_or("?")
                )
            }
        }
        match (&self.job, &self.validating) {
            (None, Some(v)) => out += &format!("program: {v} being validated\n"),
            (None, None) => {
                out += "program: none";
                if let Some(l) = &self.last_job {
                    out += &format!(
                        " (last: {} {})",
                        l.program,
                        if l.ok { "done" } else { "failed" }
                    );
                }
                out += "\n";
            }
            (Some(j), _) => {
                out += &format!(
                    "program: {} line {} motion {:.2} / {:.2} s{}\n",
                    j.program,
                    j.line.map_or("-".into(), |l| l.to_string()),
                    j.motion_time_s.unwrap_or(0.0),
                    j.predicted_s,
                    if j.paused { " PAUSED" } else { "" }
                )
            }
        }
        for p in &self.processes {
            out += &format!(
                "  {:<9} {:<10} pid {:<8} restarts {}{}{}{}{}\n",
                p.name,
                crate::word(&p.life),
                p.pid.map_or("-".into(), |p| p.to_string()),
                p.restarts,
                if p.critical { "" } else { "  not critical" },
                p.listening
                    .as_deref()
                    .map_or(String::new(), |a| format!("  listening on {a}")),
                p.listen_failed
                    .as_deref()
                    .map_or(String::new(), |w| format!("  not listening: {w}")),
                p.why
                    .as_deref()
                    .map_or(String::new(), |w| format!("  ({w})"))
            );
        }
        out
    }
}
