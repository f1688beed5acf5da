//! `supervisor status`: what the processes of a running instance report about themselves,
//! their cycle counts, overruns and wake-up latency percentiles since they started.

use latency::report::Summary;
use runtime::ipc::{self, Sub};
use runtime::rt::policy_name;
use serde_json::{Map, Value, json};
use shm_schema::{InstanceName, LatencyHistogramV1, ProcState, ProcessStatusV1, Role, ServiceId};
use std::time::{Duration, Instant};

/// How long `status` listens for the processes' publications (the latency histogram comes
/// about every 100 ms).
pub const LISTEN: Duration = Duration::from_millis(600);

/// One process as seen by `status`.
#[derive(Clone, Debug)]
pub struct Seen {
    /// Its role.
    pub role: Role,
    /// Its latest status.
    pub status: ProcessStatusV1,
    /// Its latest latency histogram, if it publishes one.
    pub latency: Option<Box<LatencyHistogramV1>>,
}

/// Reads the status and latency of every process of `instance`. Errors when nothing of the
/// instance is running.
pub fn read(instance: &InstanceName) -> Result<Vec<Seen>, String> {
    ipc::quiet_iceoryx2_log();
    let live = ipc::live_node_pids(instance).unwrap_or_default();
    if live.is_empty() {
        return Err(format!(
            "no process of instance {instance} is running (start one with `supervisor run --instance {instance} PROGRAM`)"
        ));
    }
    let f = |e: ipc::IpcError| e.to_string();
    let node = ipc::node(instance, &format!("status-{}", std::process::id())).map_err(f)?;
    let mut ports = Vec::new();
    for role in Role::ALL {
        let status =
            Sub::<ProcessStatusV1>::new(&node, instance, ServiceId::Status(role), 4).map_err(f)?;
        let latency = Sub::<LatencyHistogramV1>::new(&node, instance, ServiceId::Latency(role), 1)
            .map_err(f)?;
        ports.push((role, status, latency));
    }
    let mut seen: Vec<(
        Role,
        Option<ProcessStatusV1>,
        Option<Box<LatencyHistogramV1>>,
    )> = Role::ALL.iter().map(|r| (*r, None, None)).collect();
    let start = Instant::now();
    while start.elapsed() < LISTEN {
        for ((_, status, latency), (_, s, l)) in ports.iter().zip(seen.iter_mut()) {
            if let Some(x) = status.latest() {
                *s = Some(x);
            }
            if let Some(x) = latency.latest() {
                *l = Some(Box::new(x));
            }
        }
        if seen.iter().all(|(_, s, l)| s.is_some() && l.is_some()) {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    drop(ports);
    drop(node);
    let out: Vec<Seen> = seen
        .into_iter()
        .filter_map(|(role, s, latency)| {
            s.map(|status| Seen {
                role,
                status,
                latency,
            })
        })
        .collect();
    if out.is_empty() {
        return Err(format!(
            "instance {instance} has live nodes (pids {live:?}) but no process published a status within {} ms",
            LISTEN.as_millis()
        ));
    }
    Ok(out)
}

fn state_name(state: u32) -> &'static str {
    match ProcState::from_u32(state) {
        Some(ProcState::Starting) => "starting",
        Some(ProcState::Cyclic) => "cyclic",
        Some(ProcState::Stopping) => "stopping",
        Some(ProcState::Fault) => "fault",
        None => "?",
    }
}

/// The JSON object of `supervisor status --json`.
pub fn to_json(instance: &InstanceName, seen: &[Seen]) -> Value {
    let mut procs = Map::new();
    for p in seen {
        let s = &p.status;
        procs.insert(
            p.role.name().into(),
            json!({
                "pid": s.pid,
                "state": state_name(s.state),
                "policy": policy_name(s.policy),
                "priority": s.priority,
                "cpu": s.cpu,
                "fault": s.fault,
                "period_us": s.stats.period_ns as f64 * 1e-3,
                "cycles": s.stats.cycles,
                "overruns": s.stats.overruns,
                "skipped": s.stats.skipped,
                "max_exec_us": s.stats.max_exec_ns as f64 * 1e-3,
                "wakeup_latency_us": p.latency.as_ref().map(|h| Summary::of(h).to_json()),
            }),
        );
    }
    json!({"instance": instance.as_str(), "processes": procs})
}

/// The table of `supervisor status`.
pub fn human(instance: &InstanceName, seen: &[Seen]) -> String {
    let mut out = format!(
        "instance {instance}: wake-up latency since each process started (µs)\n\
         process    pid      state     policy       prio    cycles  overruns       p50       p99     p99.9    p99.99       max\n"
    );
    for p in seen {
        let s = &p.status;
        out += &format!(
            "{:<9}  {:<7}  {:<8}  {:<11}  {:>4}  {:>8}  {:>8}",
            p.role.name(),
            s.pid,
            state_name(s.state),
            policy_name(s.policy),
            s.priority,
            s.stats.cycles,
            s.stats.overruns
        );
        match &p.latency {
            Some(h) => {
                let m = Summary::of(h);
                out += &format!(
                    "  {:>8.1}  {:>8.1}  {:>8.1}  {:>8.1}  {:>8.1}\n",
                    m.p50_us, m.p99_us, m.p99_9_us, m.p99_99_us, m.max_us
                );
            }
            None => out += "  (no latency histogram published)\n",
        }
    }
    out
}
