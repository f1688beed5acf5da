//! The result of a run: JSON for tools, a summary for people.

use control_plane::event::{Event, Severity};
use control_plane::report::{Delay, ProcessReport, RunReport};
use indexmap::IndexMap;
use latency::report::Summary;
use runtime::rt::policy_name;
use shm_schema::{MAX_AXES, ProcessStatusV2};

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

/// Everything a run measured.
#[derive(Clone, Debug)]
pub struct Report {
    /// Success.
    pub ok: bool,
    /// Program file.
    pub program: String,
    /// Instance name.
    pub instance: String,
    /// Cell name.
    pub cell: String,
    /// Axis names.
    pub axes: Vec<String>,
    /// Axis units.
    pub units: Vec<String>,
    /// vmax per axis.
    pub vmax: Vec<f64>,
    /// t_acc (s).
    pub t_acc: f64,
    /// Position the motion started from.
    pub start: Vec<f64>,
    /// Period per process (µs).
    pub periods_us: Vec<(String, u64)>,
    /// Sum of segment times, from trajgen (s).
    pub theoretical_s: f64,
    /// The same, predicted by the supervisor before the motion with trajgen's generator (s).
    pub predicted_s: f64,
    /// Wall-clock time from the first setpoint of the motion to its last, less the time
    /// spent in `WAIT`s (s).
    pub measured_s: f64,
    /// Real time the program spent in `WAIT`s (s).
    pub waited_s: f64,
    /// trajgen's period (s).
    pub trajgen_period_s: f64,
    /// From the last setpoint until the axes were in position (s).
    pub settle_s: f64,
    /// Measured position once settled.
    pub final_position: Vec<f64>,
    /// Final position minus the last target.
    pub final_error: Vec<f64>,
    /// Largest |following error| per axis during the motion and settling, as servo latched it
    /// in every one of its cycles (`ServoStateV3.peak_following_error`).
    pub max_following_error: Vec<f64>,
    /// Setpoints recorded.
    pub setpoints: usize,
    /// Setpoints missing from the record (sequence gaps).
    pub lost_setpoints: u64,
    /// The trace covers only the program's first [`crate::job::MAX_RECORD_S`] seconds.
    pub trace_truncated: bool,
    /// servo states the supervisor did not receive (sequence gaps: it was stalled, or its
    /// buffer overflowed). The trace misses them; the following-error figures and the verdict
    /// do not, since servo judges and latches every cycle itself.
    pub lost_servo_states: u64,
    /// Times trajgen's queue ran empty.
    pub starved: u32,
    /// iobridge: mean and max age of the position in the fieldbus image (µs).
    pub iobridge_delay_us: Option<(f64, f64)>,
    /// Per process.
    pub processes: Vec<ProcessReport>,
    /// The trace.
    pub trace: Vec<TraceRow>,
    /// Every event of the run (`docs/events.md`).
    pub events: Vec<Event>,
    /// Sense-to-command latency the drives measured over the run: sampling the encoders to
    /// applying the command computed from that sample.
    pub sense_to_command: Option<Summary>,
    /// What `--plot` draws (the path, the following error over the run, the latency
    /// histograms), when it was asked for: built at the program's end only then.
    pub figures: Option<Box<control_plane::figures::Figures>>,
}

/// `values` keyed by the axes' `names`, in their order.
fn per_axis<T: Clone>(names: &[String], values: &[T]) -> IndexMap<String, T> {
    names.iter().cloned().zip(values.iter().cloned()).collect()
}

impl Report {
    /// measured − theoretical (s).
    pub fn difference_s(&self) -> f64 {
        self.measured_s - self.theoretical_s
    }

    /// The document of `supervisor run --json`.
    pub fn document(&self) -> RunReport {
        RunReport {
            ok: self.ok,
            program: self.program.clone(),
            instance: self.instance.clone(),
            cell: self.cell.clone(),
            theoretical_s: self.theoretical_s,
            predicted_s: self.predicted_s,
            measured_s: self.measured_s,
            waited_s: self.waited_s,
            difference_s: self.difference_s(),
            trajgen_period_s: self.trajgen_period_s,
            settle_s: self.settle_s,
            final_position: per_axis(&self.axes, &self.final_position),
            final_error: per_axis(&self.axes, &self.final_error),
            max_following_error: per_axis(&self.axes, &self.max_following_error),
            axes: self.axes.clone(),
            units: per_axis(&self.axes, &self.units),
            vmax: per_axis(&self.axes, &self.vmax),
            t_acc: self.t_acc,
            start: per_axis(&self.axes, &self.start),
            periods_us: self.periods_us.iter().cloned().collect(),
            setpoints: self.setpoints as u64,
            lost_setpoints: self.lost_setpoints,
            lost_servo_states: self.lost_servo_states,
            trace_truncated: self.trace_truncated,
            starved: self.starved,
            iobridge_delay_us: self
                .iobridge_delay_us
                .map(|(mean, max)| Delay { mean, max }),
            processes: self
                .processes
                .iter()
                .map(|p| (p.name.clone(), p.clone()))
                .collect(),
            sense_to_command_us: self.sense_to_command,
            events: self.events.clone(),
        }
    }

    /// [`Report::document`] as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string(&self.document()).unwrap_or_default()
    }

    /// The human summary.
    pub fn human(&self) -> String {
        let mut s = String::new();
        let ax = |v: &[f64], prec: usize| -> String {
            self.axes
                .iter()
                .zip(v)
                .zip(&self.units)
                .map(|((a, x), u)| format!("{a} {x:.prec$} {u}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        s += &format!(
            "{} on {} (instance {}): done\n",
            self.program, self.cell, self.instance
        );
        s += &format!(
            "  motion time        {:.4} s measured, {:.4} s theoretical ({:+.2} ms; trajgen period {:.1} ms)\n",
            self.measured_s,
            self.theoretical_s,
            self.difference_s() * 1e3,
            self.trajgen_period_s * 1e3
        );
        if self.waited_s > 0.0 {
            s += &format!(
                "  waited             {:.4} s in WAITs (not in the motion time above)\n",
                self.waited_s
            );
        }
        s += &format!(
            "  settled            {:.3} s after the last setpoint\n",
            self.settle_s
        );
        s += &format!("  final position     {}\n", ax(&self.final_position, 4));
        s += &format!(
            "  max following err  {}\n",
            ax(&self.max_following_error, 4)
        );
        if let Some((mean, max)) = self.iobridge_delay_us {
            s += &format!(
                "  fieldbus image age {mean:.0} µs mean, {max:.0} µs max (measurement to write)\n"
            );
        }
        if let Some(m) = self.sense_to_command {
            s += &format!(
                "  sense to command   {:.0} µs p50, {:.0} µs p99, {:.0} µs max (encoder sample to the drives applying its command)\n",
                m.p50_us, m.p99_us, m.max_us
            );
        }
        let worst = self
            .events
            .iter()
            .filter(|e| e.severity != Severity::Info)
            .count();
        s += &format!(
            "  events             {} ({} warnings or errors)\n",
            self.events.len(),
            worst
        );
        s += &format!(
            "  trace              {} setpoints, {} lost\n",
            self.setpoints, self.lost_setpoints
        );
        if self.lost_servo_states > 0 {
            s += &format!(
                "  servo states       {} not received: the trace misses them (servo latched its figures itself)\n",
                self.lost_servo_states
            );
        }
        s += "  process    pid      policy       prio  period   cycles   overruns  wake-up µs: p50    p99  p99.9      max  exec µs p99     max   cpu\n";
        for p in &self.processes {
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
    let n = report.axes.len();
    let mut out = String::new();
    let mut header = vec!["t_s".to_string()];
    header.extend(report.axes.iter().map(|a| format!("cmd_{a}")));
    header.extend(report.axes.iter().map(|a| format!("act_{a}")));
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
