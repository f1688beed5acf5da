//! `supervisor status --json`: what the processes of a running cell publish about themselves
//! in shared memory (read by the `status` command, an observer) and the supervisor's own view
//! ([`Info`], over the control channel), as one document ([`Status`]). Its JSON Schema,
//! generated from these types, is `docs/schema/status.schema.json`.

use crate::info::Info;
/// Who raised an e-stop: declared with the supervisor's view of it ([`crate::info`]).
pub use crate::info::Origin;
use indexmap::IndexMap;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// `Serialize` and `Deserialize` for a type whose JSON form has no tag or a tag inside (the
/// documented `status --json`), which postcard (the control channel: [`crate::Reply::Status`])
/// cannot read, having no self-description: in JSON with the serde attributes given, in postcard
/// tagged outside. The variants are written once, as the type's own (serde remotes of it, in a
/// module of their own).
macro_rules! two_forms {
    ($t:ident, $remote:literal, $module:ident, [$($json:meta),*], { $($variants:tt)* }) => {
        mod $module {
            use super::*;

            #[allow(dead_code)] // Only its serde code is used.
            #[derive(Serialize, Deserialize)]
            #[serde(remote = $remote)]
            $(#[serde($json)])*
            pub(super) enum Json { $($variants)* }

            #[allow(dead_code)] // Only its serde code is used.
            #[derive(Serialize, Deserialize)]
            #[serde(remote = $remote)]
            pub(super) enum Tagged { $($variants)* }
        }

        impl Serialize for $t {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                if s.is_human_readable() {
                    $module::Json::serialize(self, s)
                } else {
                    $module::Tagged::serialize(self, s)
                }
            }
        }

        impl<'de> Deserialize<'de> for $t {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                if d.is_human_readable() {
                    $module::Json::deserialize(d)
                } else {
                    $module::Tagged::deserialize(d)
                }
            }
        }
    };
}

/// The document `supervisor status --json` prints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Status {
    /// The instance's name.
    pub instance: String,
    /// The cell's e-stop as the host state says; `null` before the supervisor's first.
    pub estop: Option<EstopStatus>,
    /// trajgen's program; `null` before trajgen's first setpoint.
    pub program: Option<ProgramStatus>,
    /// Every process that publishes a status, by name.
    pub processes: IndexMap<String, ProcessStatus>,
    /// Servo's state; `null` before servo's first.
    pub servo: Option<ServoStatus>,
    /// The named digital IO; `null` before the cell's configuration is published.
    pub io: Option<IoStatus>,
    /// From an encoder's sample to the drives applying the command computed from it (µs);
    /// `null` before the first.
    pub sense_to_command_us: Option<Percentiles>,
    /// The supervisor's own view.
    pub supervisor: Info,
}

/// The cell's e-stop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EstopStatus {
    /// Latched.
    pub latched: bool,
    /// Who raised it; `null` when clear.
    pub origin: Option<Origin>,
    /// The process, axis or input that raised it; `null` when clear.
    pub source: Option<String>,
    /// The raiser's words; `null` when clear.
    pub reason: Option<String>,
    /// Its event's name (`docs/events.md`); `null` when clear.
    pub cause: Option<String>,
    /// Resets since the cell started.
    pub resets: u64,
}

/// trajgen's program.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ProgramStatus {
    /// Where trajgen is.
    pub state: MotionState,
    /// The program's id (0: none yet).
    pub program_id: u32,
    /// Its line trajgen runs.
    pub line: u32,
    /// Its motion time so far (s).
    pub motion_time_s: f64,
    /// Time spent in `WAIT` and `DELAY` (s).
    pub waited_s: f64,
    /// What holds the program; `null` when nothing.
    pub holds: Option<Hold>,
    /// The path speed now (1 = programmed).
    pub path_speed: f64,
    /// The live speed override (1 = 100 %).
    pub speed_override: f64,
    /// The program's own speed (`SPEED`).
    pub program_speed: f64,
    /// The space the current segment moves in.
    pub space: Space,
    /// The tool's Cartesian position now.
    pub cartesian: Vec<f64>,
    /// trajgen's fault in words; `null` when none.
    pub fault: Option<String>,
}

/// Where trajgen is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum MotionState {
    /// No program.
    Idle,
    /// A program runs.
    Moving,
    /// The program ended.
    Done,
    /// trajgen stopped the program on a fault.
    Fault,
    /// A value this version does not know.
    #[serde(rename = "?")]
    Unknown,
}

/// What holds a program.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Hold {
    /// `wait` (an input) or `delay`.
    #[serde(rename = "for")]
    pub what: HoldKind,
    /// The input waited for (`wait` only; `null` for a `delay`).
    pub input: Option<String>,
}

/// What a program waits for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum HoldKind {
    /// `WAIT(input, value)`.
    Wait,
    /// `DELAY(s)`.
    Delay,
}

/// The space a segment moves in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Space {
    /// `MOVE`: straight in Cartesian space.
    Cartesian,
    /// `MOVEJ`: in joint space.
    Joint,
}

/// A process as it describes itself.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ProcessStatus {
    /// Its pid.
    pub pid: u32,
    /// Where its runtime is.
    pub state: ProcState,
    /// What it saw of the e-stop.
    pub estop: EstopSeen,
    /// Its health detectors (seed 002).
    pub health: Health,
    /// Its scheduling policy (`SCHED_FIFO`, `SCHED_OTHER`).
    pub policy: String,
    /// Its real-time priority.
    pub priority: i32,
    /// The CPU it is pinned to (-1: none).
    pub cpu: i32,
    /// Its latched fault code (0: none).
    pub fault: u32,
    /// Its period (µs).
    pub period_us: f64,
    /// Cycles run.
    pub cycles: u64,
    /// Cycles whose work ran past the next period.
    pub overruns: u64,
    /// Periods skipped to catch up.
    pub skipped: u64,
    /// The longest cycle's work (µs).
    pub max_exec_us: f64,
    /// Wake-up latency since it started (µs); `null` when it publishes no histogram.
    pub wakeup_latency_us: Option<Percentiles>,
    /// Its cycles' execution time (µs); `null` when it publishes none.
    pub exec_time_us: Option<Percentiles>,
}

/// Where a process' runtime is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ProcState {
    /// Setting up.
    Starting,
    /// In its cycle.
    Cyclic,
    /// Leaving.
    Stopping,
    /// Stopped on a fault.
    Fault,
    /// A value this version does not know.
    #[serde(rename = "?")]
    Unknown,
}

/// What a process saw of the e-stop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EstopSeen {
    /// It sees the e-stop latched.
    pub latched: bool,
    /// It is reacting (bringing its part to rest).
    pub reacting: bool,
    /// Its part is safe.
    pub safe: bool,
    /// It raised the e-stop.
    pub raised: bool,
}

/// A process' health detectors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Health {
    /// Samples it expected and did not get.
    pub pending_sequence_overrun: Detector,
    /// Frames lost or wrong on its transport.
    pub transport_overrun: Detector,
    /// Wake-ups later than the configured share of the period.
    pub thread_offset_variance: Detector,
}

/// One health detector: a leaky bucket that expires at its limit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Detector {
    /// Its level now.
    pub level: f32,
    /// The level at which it expires (an e-stop); 0 while snoozed after a start.
    pub limit: f32,
    /// Overruns counted since the process started.
    pub total: u64,
}

/// The figures of one latency histogram, in µs; as JSON (`status --json`, reports,
/// `latency --json`) to the nanosecond.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Percentiles {
    /// Samples.
    pub samples: u64,
    /// Smallest.
    #[serde(serialize_with = "ns")]
    pub min_us: f64,
    /// Mean.
    #[serde(serialize_with = "ns")]
    pub avg_us: f64,
    /// Median.
    #[serde(serialize_with = "ns")]
    pub p50_us: f64,
    /// 99th percentile.
    #[serde(serialize_with = "ns")]
    pub p99_us: f64,
    /// 99.9th percentile.
    #[serde(serialize_with = "ns")]
    pub p99_9_us: f64,
    /// 99.99th percentile.
    #[serde(serialize_with = "ns")]
    pub p99_99_us: f64,
    /// Largest.
    #[serde(serialize_with = "ns")]
    pub max_us: f64,
}

/// Microseconds written to the nanosecond.
fn ns<S: serde::Serializer>(us: &f64, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_f64((*us * 1000.0).round() / 1000.0)
}

impl Percentiles {
    /// The figures of `h` (all 0 when it is empty).
    pub fn of(h: &shm_schema::LatencyHistogramV1) -> Self {
        let us = |v: Option<u64>| v.unwrap_or(0) as f64 * 1e-3;
        Self {
            samples: h.count,
            min_us: us(Some(h.min_ns)),
            avg_us: h.mean_ns().unwrap_or(0.0) * 1e-3,
            p50_us: us(h.percentile(1, 2)),
            p99_us: us(h.percentile(99, 100)),
            p99_9_us: us(h.percentile(999, 1000)),
            p99_99_us: us(h.percentile(9999, 10000)),
            max_us: us(Some(h.max_ns)),
        }
    }
}

/// Servo's state: the arm and every axis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ServoStatus {
    /// The arm's power.
    pub power: Power,
    /// Servo took the axes' positions at start.
    pub initialized: bool,
    /// The drives are enabled.
    pub enabled: bool,
    /// Every axis is settled.
    pub settled: bool,
    /// Servo's latched fault; `null` when none.
    pub fault: Option<ServoFault>,
    /// Per axis, by name.
    pub axes: IndexMap<String, AxisStatus>,
}

/// Power of the arm or of an axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Power {
    /// Off.
    Disabled,
    /// Being switched on.
    Enabling,
    /// On.
    Enabled,
    /// Being switched off.
    Disabling,
    /// A value this version does not know.
    #[serde(rename = "?")]
    Unknown,
}

impl From<u8> for Power {
    fn from(v: u8) -> Self {
        use shm_schema::Power as P;
        match P::from_wire(v) {
            Some(P::Disabled) => Self::Disabled,
            Some(P::Enabling) => Self::Enabling,
            Some(P::Enabled) => Self::Enabled,
            Some(P::Disabling) => Self::Disabling,
            None => Self::Unknown,
        }
    }
}

/// Servo's latched fault.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ServoFault {
    /// Its event code (`docs/events.md`).
    pub code: u32,
    /// Its event's name.
    pub name: String,
    /// The axis it concerns; `null` for the arm.
    pub axis: Option<String>,
    /// The value that tripped it; not a number (`null` in JSON) for a value that was not
    /// one (feedback-not-finite).
    #[serde(deserialize_with = "nan_as_null")]
    #[schemars(with = "Option<f64>")]
    pub value: f64,
    /// The limit it passed.
    #[serde(deserialize_with = "nan_as_null")]
    #[schemars(with = "Option<f64>")]
    pub limit: f64,
}

/// One axis as servo sees it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AxisStatus {
    /// Its power.
    pub power: Power,
    /// Its drive's CiA 402 state, by name.
    pub drive_state: String,
    /// Its drive's statusword.
    pub statusword: u16,
    /// Settled (in position).
    pub settled: bool,
    /// Its measured position; not a number (`null` in JSON) while it is not a valid
    /// measurement (an encoder lost).
    #[serde(deserialize_with = "nan_as_null")]
    #[schemars(with = "Option<f64>")]
    pub position: f64,
    /// Its following error; not a number (`null` in JSON) likewise.
    #[serde(deserialize_with = "nan_as_null")]
    #[schemars(with = "Option<f64>")]
    pub following_error: f64,
}

/// A number that JSON writes `null` when it is not a number (serde_json's way with NaN):
/// read back as NaN. Binary formats (the control channel's postcard) carry the number itself.
fn nan_as_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    if d.is_human_readable() {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    } else {
        f64::deserialize(d)
    }
}

/// The named digital IO.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct IoStatus {
    /// Every entry, in the configuration's order.
    pub entries: Vec<IoEntry>,
    /// The e-stop holds the outputs at their safe values; `null` before iobridge's first
    /// image.
    pub outputs_safe: Option<bool>,
    /// Output requests iobridge took; `null` before its first image.
    pub requests_taken: Option<u64>,
    /// Output writes iobridge refused; `null` before its first image.
    pub writes_refused: Option<u64>,
}

/// One named input or output. In JSON tagged inside (`"direction": "output"`); in postcard
/// (the control channel), which cannot read an inner tag, tagged outside.
#[derive(Clone, Debug, PartialEq, JsonSchema)]
#[schemars(tag = "direction", rename_all = "lowercase", deny_unknown_fields)]
pub enum IoEntry {
    /// An output.
    Output {
        /// Its name.
        name: String,
        /// 0 or 1; `null` before iobridge's first image.
        value: Option<u8>,
        /// What the e-stop sets it to.
        safe: SafeValue,
    },
    /// An input.
    Input {
        /// Its name.
        name: String,
        /// 0 or 1; `null` before iobridge's first image.
        value: Option<u8>,
        /// It is an e-stop circuit.
        estop: bool,
    },
}

two_forms!(
    IoEntry,
    "IoEntry",
    io_entry,
    [tag = "direction", rename_all = "lowercase", deny_unknown_fields],
    {
        Output { name: String, value: Option<u8>, safe: SafeValue },
        Input { name: String, value: Option<u8>, estop: bool },
    }
);

impl IoEntry {
    /// Its name.
    pub fn name(&self) -> &str {
        match self {
            Self::Output { name, .. } | Self::Input { name, .. } => name,
        }
    }

    /// Its value; `None` before iobridge's first image.
    pub fn value(&self) -> Option<u8> {
        match self {
            Self::Output { value, .. } | Self::Input { value, .. } => *value,
        }
    }
}

/// What the e-stop sets an output to: 0, 1, or `"hold"` (as it was). In JSON without a tag
/// (`0`, `1`, `"hold"`); in postcard (the control channel), which cannot read a value without
/// a tag, tagged.
#[derive(Clone, Copy, Debug, PartialEq, Eq, JsonSchema)]
#[schemars(untagged)]
pub enum SafeValue {
    /// 0 or 1.
    Level(u8),
    /// Kept as it was.
    Hold(HoldWord),
}

two_forms!(SafeValue, "SafeValue", safe_value, [untagged], {
    Level(u8),
    Hold(HoldWord),
});

/// The word `"hold"`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum HoldWord {
    /// `"hold"`.
    Hold,
}

#[cfg(test)]
mod nan {
    use super::AxisStatus;

    /// A position that is not a number goes out as `null` in JSON and comes back as NaN; over
    /// postcard as the number itself.
    #[test]
    fn a_lost_measurement_round_trips_through_json_and_postcard() {
        let a = AxisStatus {
            power: super::Power::Disabled,
            drive_state: "Fault".into(),
            statusword: 8,
            settled: false,
            position: f64::NAN,
            following_error: 0.5,
        };
        let json = serde_json::to_value(&a).expect("JSON");
        assert!(json["position"].is_null(), "{json}");
        let back: AxisStatus = serde_json::from_value(json).expect("read back");
        assert!(back.position.is_nan());
        assert_eq!(back.following_error, 0.5);
        let bytes = postcard::to_allocvec(&a).expect("postcard");
        let back: AxisStatus = postcard::from_bytes(&bytes).expect("read back");
        assert!(back.position.is_nan());
    }
}
