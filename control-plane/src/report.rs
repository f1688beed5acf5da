//! A program's end as `supervisor run --json` and `exec --wait --json` print it: a
//! [`RunReport`] when it completed and settled, a [`RunFailure`] when it did not. Their JSON
//! Schema, generated from [`RunDocument`], is `docs/schema/report.schema.json`.

use crate::Failure;
use crate::event::Event;
use crate::status::Percentiles;
use indexmap::IndexMap;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Everything a completed run measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RunReport {
    /// Always true: the program completed and the axes settled.
    pub ok: bool,
    /// The program as the user named it.
    pub program: String,
    /// The instance.
    pub instance: String,
    /// The cell's name (`[cell] name`).
    pub cell: String,
    /// The sum of the segment times, from trajgen (s): seed 003's theoretical motion time.
    pub theoretical_s: f64,
    /// The same, predicted before the motion with trajgen's generator (s).
    pub predicted_s: f64,
    /// From the motion's first setpoint to its last on trajgen's clock, less the `WAIT`s (s).
    pub measured_s: f64,
    /// Time spent in `WAIT`s (s).
    pub waited_s: f64,
    /// `measured_s − theoretical_s` (s).
    pub difference_s: f64,
    /// trajgen's period (s).
    pub trajgen_period_s: f64,
    /// From the last setpoint until the axes were in position (s).
    pub settle_s: f64,
    /// The measured position once settled, per axis.
    pub final_position: IndexMap<String, f64>,
    /// The final position less the last target, per axis.
    pub final_error: IndexMap<String, f64>,
    /// The largest |following error| per axis, as servo latched it every cycle.
    pub max_following_error: IndexMap<String, f64>,
    /// The axes, in the configuration's order.
    pub axes: Vec<String>,
    /// Each axis' unit.
    pub units: IndexMap<String, String>,
    /// Each axis' vmax (unit/s).
    pub vmax: IndexMap<String, f64>,
    /// The acceleration time (s).
    pub t_acc: f64,
    /// Where the motion started, per axis.
    pub start: IndexMap<String, f64>,
    /// Each process' period (µs).
    pub periods_us: IndexMap<String, u64>,
    /// Setpoints recorded.
    pub setpoints: u64,
    /// Setpoints missing from the record (sequence gaps).
    pub lost_setpoints: u64,
    /// servo states the supervisor did not receive (the trace misses them; servo latched its
    /// figures itself).
    pub lost_servo_states: u64,
    /// The trace covers only the program's first ten minutes.
    pub trace_truncated: bool,
    /// Times trajgen's queue ran empty.
    pub starved: u32,
    /// The age of the position in the fieldbus image when iobridge wrote it (µs); `null`
    /// without an image.
    pub iobridge_delay_us: Option<Delay>,
    /// Per process, by name.
    pub processes: IndexMap<String, ProcessReport>,
    /// From an encoder's sample to the drives applying its command, over the run (µs).
    pub sense_to_command_us: Option<Percentiles>,
    /// Every event of the run.
    pub events: Vec<Event>,
    /// On the virtual clock (`--virtual-time`), how fast it ran; `null` on the wall clock.
    pub virtual_time: Option<VirtualTime>,
}

/// How fast a cell on the virtual clock ran: from the clock's start to the run's report.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VirtualTime {
    /// Virtual seconds the cell lived.
    pub virtual_s: f64,
    /// Wall seconds they took.
    pub wall_s: f64,
    /// Virtual seconds per wall second.
    pub speed_up: f64,
    /// Cycles the clock granted.
    pub cycles: u64,
}

/// Mean and largest of a delay (µs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Delay {
    /// Mean.
    pub mean: f64,
    /// Largest.
    pub max: f64,
}

/// One process' figures over the run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ProcessReport {
    /// Its name.
    pub name: String,
    /// Its pid.
    pub pid: u32,
    /// Its scheduling policy, as the kernel reports it.
    pub policy: String,
    /// Its real-time priority.
    pub priority: i32,
    /// Its period (µs).
    pub period_us: f64,
    /// Cycles run.
    pub cycles: u64,
    /// Overruns (the CS9 rule).
    pub overruns: u64,
    /// Periods skipped after overruns.
    pub skipped: u64,
    /// The largest wake-up latency (µs).
    pub max_wakeup_latency_us: f64,
    /// The longest cycle's work (µs).
    pub max_exec_us: f64,
    /// CPU time used (s); `null` when the kernel did not say.
    pub cpu_s: Option<f64>,
    /// Wake-up latency percentiles from the process' own histogram (µs).
    pub wakeup_latency_us: Option<Percentiles>,
    /// Execution-time percentiles from the process' own histogram (µs).
    pub exec_time_us: Option<Percentiles>,
}

/// A program that did not complete.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RunFailure {
    /// Always false.
    pub ok: bool,
    /// Why, in words (`cause`'s).
    pub error: String,
    /// Why, as data: a caller decides on this, never on `error`'s words.
    pub cause: Failure,
    /// The events up to the failure.
    pub events: Vec<Event>,
}

/// How a program ended, as it travels on the control channel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Outcome {
    /// It completed and settled.
    Completed(Box<RunReport>),
    /// It did not.
    Failed(RunFailure),
}

impl Outcome {
    /// It completed.
    pub fn ok(&self) -> bool {
        matches!(self, Self::Completed(_))
    }

    /// Its JSON document (`run --json`).
    pub fn json(&self) -> String {
        match self {
            Self::Completed(r) => serde_json::to_string(r),
            Self::Failed(f) => serde_json::to_string(f),
        }
        .unwrap_or_default()
    }
}

/// The document `run --json` prints, either way: what its JSON Schema describes and what a
/// client parses it into.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum RunDocument {
    /// It completed and settled.
    Completed(Box<RunReport>),
    /// It did not.
    Failed(RunFailure),
}

/// What `supervisor up --json` prints on its standard output as it ends: how the cell went
/// down and every event of its life, those of its going down included (the drives' last
/// reactions come after the processes were told to stop). Its JSON Schema is
/// `docs/schema/up.schema.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct UpEnded {
    /// The instance.
    pub instance: String,
    /// True when it went down as asked (`supervisor down`, SIGTERM, SIGINT) with every
    /// process stopped cleanly; false when it did not come up, or a critical process was lost
    /// for good.
    pub ok: bool,
    /// What ended it, or what went wrong, in words.
    pub ended: String,
    /// Every event since the cell came up, oldest first.
    pub events: Vec<crate::event::Event>,
}
