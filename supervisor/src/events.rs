//! Events as people read them: one line per event for the terminal, one JSON object per
//! event for reports, and `supervisor events --follow`.

use control_plane::event::Event;
use runtime::ipc::{self, Sub};
use runtime::signals;
use shm_schema::event::{self, CodeInfo, SOURCE_SUPERVISOR};
use shm_schema::{CellConfigV6, EventV1, InstanceName, ServiceId, Severity, str_of};
use std::time::Duration;

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
    match info.map_or("", |i| i.unit) {
        "axis unit" => format!("{v:.4} {unit}"),
        "axis unit/s" => format!("{v:.4} {unit}/s"),
        "axis unit per servo period" => format!("{v:.5} {unit}"),
        "axis unit/s per servo period" => format!("{v:.4} {unit}/s"),
        u if u.starts_with("error code") || u == "statusword" => {
            format!("{:#06x}", v as u64)
        }
        "event code" => event::info(v as u32).map_or(format!("{v}"), |i| i.name.to_string()),
        "s" => format!("{:.1} ms", v * 1e3),
        "" => String::new(),
        _ => format!("{v}"),
    }
}

/// One line: time since `t0_ns`, severity, source, code name, axis, value against limit, text.
pub fn line(e: &EventV1, axes: &Axes, t0_ns: u64) -> String {
    let info = event::info(e.code);
    let sev = Severity::from_u32(e.severity).map_or("?", Severity::name);
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
        name: event::info(e.code)
            .map_or("unknown", |i| i.name)
            .to_string(),
        axis: axes.get(e.axis).map(|(n, _)| n.clone()),
        value: e.value.is_finite().then_some(e.value),
        limit: e.limit,
        text: e.text().to_string(),
    }
}

/// `supervisor events --instance NAME [--follow] [--json]`: prints the events of a running
/// instance as they happen (with `--follow`, until Ctrl-C; without, for `listen`).
pub fn follow(instance: &InstanceName, forever: bool, json: bool) -> Result<(), String> {
    ipc::quiet_iceoryx2_log();
    if ipc::live_node_pids(instance).unwrap_or_default().is_empty() {
        return Err(format!("no process of instance {instance} is running"));
    }
    signals::install().map_err(|e| format!("cannot install signal handlers: {e}"))?;
    let f = |e: ipc::IpcError| e.to_string();
    let node = ipc::node(instance, &format!("events-{}", std::process::id())).map_err(f)?;
    let config = Sub::<CellConfigV6>::new(&node, instance, ServiceId::CellConfig, 1).map_err(f)?;
    let events = Sub::<EventV1>::new(&node, instance, ServiceId::Events, 1024).map_err(f)?;
    let mut axes = Axes::default();
    let t0 = runtime::time::now_ns();
    let listen = Duration::from_millis(500);
    let start = std::time::Instant::now();
    while forever || start.elapsed() < listen {
        if signals::stop_requested() {
            break;
        }
        if let Some(c) = config.latest() {
            axes = Axes::of_cell(&c);
        }
        while let Some(e) = events.next() {
            if json {
                let doc = serde_json::to_string(&event(&e, &axes, t0));
                println!("{}", doc.unwrap_or_default());
            } else {
                println!("{}", line(&e, &axes, t0));
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    drop((config, events));
    drop(node);
    ipc::cleanup_after_client(instance);
    Ok(())
}
