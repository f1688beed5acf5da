//! An event as reports and `supervisor events --json` give it: `docs/events.md` documents each
//! code; the fields are named here.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// One event of the cell.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Event {
    /// When, from the run's (or the observer's) start (s).
    pub t_s: f64,
    /// When, on `CLOCK_MONOTONIC` (ns).
    pub stamp_ns: u64,
    /// The process that raised it (`supervisor` for the supervisor).
    pub source: String,
    /// Its number in its source's sequence.
    pub seq: u64,
    /// How much it matters.
    pub severity: Severity,
    /// Its code (`docs/events.md`).
    pub code: u32,
    /// Its code's name (`following-error`); `unknown` for a code this version does not know.
    pub name: String,
    /// The axis it concerns; `null` for none.
    pub axis: Option<String>,
    /// The value that tripped it (in the code's unit); `null` when not finite.
    pub value: Option<f64>,
    /// The limit the value passed; 0 when none.
    pub limit: f64,
    /// Its source's words.
    pub text: String,
}

/// How much an event matters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    /// Something changed as asked.
    Info,
    /// Something to look at; nothing was stopped by it.
    Warning,
    /// A refusal or a fault.
    Error,
    /// A value this version does not know.
    #[serde(rename = "?")]
    Unknown,
}

impl From<u32> for Severity {
    fn from(v: u32) -> Self {
        use shm_schema::Severity as S;
        match S::from_u32(v) {
            Some(S::Info) => Self::Info,
            Some(S::Warning) => Self::Warning,
            Some(S::Error) => Self::Error,
            None => Self::Unknown,
        }
    }
}
