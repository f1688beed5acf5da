//! The result of a run: JSON for tools, a summary for people.

use control_plane::event::Severity;
use control_plane::report::{Delay, ProcessReport, RunReport};
use control_plane::status::Percentiles as Summary;
use indexmap::IndexMap;
use runtime::rt::policy_name;
use shm_schema::{LatencyHistogramV1, MAX_AXES, ProcessStatusV2};

/// One process' figures from the last status it published (its percentiles are added from
/// its histograms).
pub fn process_report(
    name: &str,
    pid: u32,
    policy: u32,
    priority: i32,
    s: &ProcessStatusV2,
    cpu_s: Option<f64>,
) -> ProcessReport {
    ProcessReport {
        name: name.into(),
        pid,
        policy: policy_name(policy).into(),
        priority,
        period_us: s.stats.period_ns as f64 * 1e-3,
        cycles: s.stats.cycles,
        overruns: s.stats.overruns,
        skipped: s.stats.skipped,
        max_wakeup_latency_us: s.stats.max_wakeup_latency_ns as f64 * 1e-3,
        max_exec_us: s.stats.max_exec_ns as f64 * 1e-3,
        cpu_s,
        wakeup_latency_us: None,
        exec_time_us: None,
    }
}

/// One trace row.
#[derive(Clone, Copy, Debug)]
pub struct TraceRow {
    /// Motion time (s).
    pub t_s: f64,
    /// Commanded position.
    pub cmd: [f64; MAX_AXES],
    /// Measured position at the servo cycle that used this setpoint.
    pub act: [f64; MAX_AXES],
}

/// Everything a run measured: the document `supervisor run --json` prints, and what stays
/// with whoever ran it (the trace, the figures).
#[derive(Clone, Debug)]
pub struct Report {
    /// The run's document.
    pub run: RunReport,
    /// The trace (the program's first [`crate::job::MAX_RECORD_S`] seconds).
    pub trace: Vec<TraceRow>,
    /// What `--plot` draws (the path, the following error over the run, the latency
    /// histograms), when it was asked for: built at the program's end only then.
    pub figures: Option<Box<control_plane::figures::Figures>>,
}

/// `values` keyed by the axes' `names`, in their order.
pub(crate) fn per_axis<T: Clone>(names: &[String], values: &[T]) -> IndexMap<String, T> {
    names.iter().cloned().zip(values.iter().cloned()).collect()
}

impl Report {
    /// The cell's own figures over the run, added once the program ended: each process' report
    /// (`processes`, in the table's order), their wake-up latency histograms (to the figures,
    /// when drawn) and the drives' sense-to-command latency.
    pub(crate) fn add_cell_figures(
        &mut self,
        processes: Vec<ProcessReport>,
        latency: Vec<control_plane::figures::ProcessLatency>,
        sense_to_command: Option<&LatencyHistogramV1>,
    ) {
        self.run.processes = processes.into_iter().map(|p| (p.name.clone(), p)).collect();
        if let Some(f) = &mut self.figures {
            f.latency = latency;
        }
        self.run.sense_to_command_us = sense_to_command.filter(|h| h.count > 0).map(Summary::of);
    }

    /// [`Report::run`] as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string(&self.run).unwrap_or_default()
    }

    /// The human summary.
    pub fn human(&self) -> String {
        let r = &self.run;
        let mut s = String::new();
        let ax = |v: &IndexMap<String, f64>, prec: usize| -> String {
            r.axes
                .iter()
                .map(|a| {
                    let x = v.get(a).copied().unwrap_or(f64::NAN);
                    let u = r.units.get(a).map_or("", String::as_str);
                    format!("{a} {x:.prec$} {u}")
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        s += &format!(
            "{} on {} (instance {}): done\n",
            r.program, r.cell, r.instance
        );
        s += &format!(
            "  motion time        {:.4} s measured, {:.4} s theoretical ({:+.2} ms; trajgen period {:.1} ms)\n",
            r.measured_s,
            r.theoretical_s,
            r.difference_s * 1e3,
            r.trajgen_period_s * 1e3
        );
        if r.waited_s > 0.0 {
            s += &format!(
                "  waited             {:.4} s in WAITs (not in the motion time above)\n",
                r.waited_s
            );
        }
        if let Some(v) = &r.virtual_time {
            s += &format!(
                "  virtual clock      {:.3} s of the cell in {:.3} s of wall time: {:.1} times real time ({} cycles granted)\n",
                v.virtual_s, v.wall_s, v.speed_up, v.cycles
            );
        }
        s += &format!(
            "  settled            {:.3} s after the last setpoint\n",
            r.settle_s
        );
        s += &format!("  final position     {}\n", ax(&r.final_position, 4));
        s += &format!("  max following err  {}\n", ax(&r.max_following_error, 4));
        if let Some(Delay { mean, max }) = r.iobridge_delay_us {
            s += &format!(
                "  fieldbus image age {mean:.0} µs mean, {max:.0} µs max (measurement to write)\n"
            );
        }
        if let Some(m) = r.sense_to_command_us {
            s += &format!(
                "  sense to command   {:.0} µs p50, {:.0} µs p99, {:.0} µs max (encoder sample to the drives applying its command)\n",
                m.p50_us, m.p99_us, m.max_us
            );
        }
        let worst = r
            .events
            .iter()
            .filter(|e| e.severity != Severity::Info)
            .count();
        s += &format!(
            "  events             {} ({} warnings or errors)\n",
            r.events.len(),
            worst
        );
        s += &format!(
            "  trace              {} setpoints, {} lost\n",
            r.setpoints, r.lost_setpoints
        );
        if r.lost_servo_states > 0 {
            s += &format!(
                "  servo states       {} not received: the trace misses them (servo latched its figures itself)\n",
                r.lost_servo_states
            );
        }
        s += "  process    pid      policy       prio  period   cycles   overruns  wake-up µs: p50    p99  p99.9      max  exec µs p99     max   cpu\n";
        for p in r.processes.values() {
            let m = p.wakeup_latency_us.unwrap_or_default();
            s += &format!(
                "  {:<9}  {:<7}  {:<11}  {:>4}  {:>5.0} µs {:>7}  {:>8}  {:>16.1} {:>6.1} {:>6.1} {:>8.1}  {:>11.1} {:>7.0}   {}\n",
                p.name,
                p.pid,
                p.policy,
                p.priority,
                p.period_us,
                p.cycles,
                p.overruns,
                m.p50_us,
                m.p99_us,
                m.p99_9_us,
                p.max_wakeup_latency_us,
                p.exec_time_us.map_or(f64::NAN, |e| e.p99_us),
                p.max_exec_us,
                p.cpu_s.map_or("-".to_string(), |c| format!("{c:.2} s"))
            );
        }
        s
    }
}

/// The trace as CSV: `t_s, cmd_<axis>..., act_<axis>...`, one row per setpoint.
pub(crate) fn trace_csv(report: &Report) -> String {
    use std::fmt::Write as _;
    let n = report.run.axes.len();
    let mut out = String::new();
    let mut header = vec!["t_s".to_string()];
    header.extend(report.run.axes.iter().map(|a| format!("cmd_{a}")));
    header.extend(report.run.axes.iter().map(|a| format!("act_{a}")));
    let _ = writeln!(out, "{}", header.join(","));
    for r in &report.trace {
        let _ = write!(out, "{:.6}", r.t_s);
        for v in &r.cmd[..n] {
            let _ = write!(out, ",{v:.6}");
        }
        for v in &r.act[..n] {
            let _ = write!(out, ",{v:.6}");
        }
        let _ = writeln!(out);
    }
    out
}
