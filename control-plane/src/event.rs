//! An event as reports and `supervisor events --json` give it: `docs/events.md` documents each
//! code; the fields are named here.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use shm_schema::event::{self as shm_event, CodeInfo, SOURCE_SUPERVISOR, Unit};
use shm_schema::{CellConfigV6, EventV1, str_of};

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
        match S::from_wire(v) {
            Some(S::Info) => Self::Info,
            Some(S::Warning) => Self::Warning,
            Some(S::Error) => Self::Error,
            None => Self::Unknown,
        }
    }
}

/// Axis names and units, to name an event's axis and the unit of its value, and the process
/// names, to name its source.
#[derive(Clone, Debug, Default)]
pub struct Axes {
    /// (name, unit) per axis index.
    pub axes: Vec<(String, String)>,
    /// Process names by index in the process table.
    pub processes: Vec<String>,
}

impl Axes {
    /// From the configuration every process reads.
    pub fn of_cell(cell: &CellConfigV6) -> Self {
        Self {
            axes: cell
                .axes()
                .iter()
                .map(|a| (str_of(&a.name).to_string(), str_of(&a.unit).to_string()))
                .collect(),
            processes: cell
                .processes()
                .iter()
                .map(|p| str_of(&p.name).to_string())
                .collect(),
        }
    }

    /// The name of an event's source.
    pub fn source_name(&self, source: u32) -> String {
        if source == SOURCE_SUPERVISOR {
            return "supervisor".into();
        }
        self.processes
            .get(source as usize)
            .cloned()
            .unwrap_or_else(|| format!("source {source}"))
    }

    fn get(&self, axis: i32) -> Option<&(String, String)> {
        usize::try_from(axis).ok().and_then(|i| self.axes.get(i))
    }
}

/// A value in the unit its code gives it.
fn value_text(info: Option<&CodeInfo>, v: f64, unit: &str) -> String {
    match info.map_or(Unit::Number(""), |i| i.unit) {
        Unit::Axis => format!("{v:.4} {unit}"),
        Unit::AxisPerSecond => format!("{v:.4} {unit}/s"),
        Unit::AxisPerPeriod => format!("{v:.5} {unit}"),
        Unit::AxisPerSecondPerPeriod => format!("{v:.4} {unit}/s"),
        Unit::Hex(_) => format!("{:#06x}", v as u64),
        Unit::EventCode => shm_event::info(v as u32).map_or(format!("{v}"), |i| i.name.to_string()),
        Unit::Seconds => format!("{:.1} ms", v * 1e3),
        Unit::None => String::new(),
        Unit::Number(_) => format!("{v}"),
    }
}

/// One line: time since `t0_ns`, severity, source, code name, axis, value against limit, text.
pub fn line(e: &EventV1, axes: &Axes, t0_ns: u64) -> String {
    let info = shm_event::info(e.code);
    let sev = shm_schema::Severity::from_wire(e.severity).map_or("?", shm_schema::Severity::name);
    let t = (e.stamp_ns as i128 - t0_ns as i128) as f64 * 1e-9;
    let (axis, unit) = axes
        .get(e.axis)
        .map_or(("", ""), |(n, u)| (n.as_str(), u.as_str()));
    let mut s = format!(
        "[{t:9.3} s] {sev:<7} {:<9} {}",
        axes.source_name(e.source),
        info.map_or_else(|| format!("code {}", e.code), |i| i.name.to_string())
    );
    if !axis.is_empty() {
        s += &format!(" axis {axis}");
    }
    let value = value_text(info, e.value, unit);
    if !value.is_empty() {
        s += &format!(": {value}");
        if e.limit != 0.0 {
            s += &format!(" (limit {})", value_text(info, e.limit, unit));
        }
    }
    if !e.text().is_empty() {
        s += &format!(" — {}", e.text());
    }
    s
}

/// The event as reports and `--json` give it (`docs/events.md` documents the codes).
pub fn event(e: &EventV1, axes: &Axes, t0_ns: u64) -> Event {
    Event {
        t_s: (e.stamp_ns as i128 - t0_ns as i128) as f64 * 1e-9,
        stamp_ns: e.stamp_ns,
        source: axes.source_name(e.source),
        seq: e.seq,
        severity: e.severity.into(),
        code: e.code,
        name: shm_event::info(e.code)
            .map_or("unknown", |i| i.name)
            .to_string(),
        axis: axes.get(e.axis).map(|(n, _)| n.clone()),
        value: e.value.is_finite().then_some(e.value),
        limit: e.limit,
        text: e.text().to_string(),
    }
}
