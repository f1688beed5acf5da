//! The figures of a latency run as text (cyclictest's lines, plus percentiles) and JSON.

use crate::measure::{Options, Results, Running, Series, Test};
use serde_json::{Value, json};
use shm_schema::status::rt_flags;
use std::sync::atomic::Ordering;

/// The figures of one histogram (the control plane's type, shared with `status` and the
/// reports).
pub use control_plane::status::Percentiles as Summary;

fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// One line per series, cyclictest's fields first:
/// `T: 0 (tid) P:80 I:1000 C: 10000 Min: 3.1 Act: 5.0 Avg: 6.2 Max: 120.4 | p50 ... Ovf: 0`.
pub fn line(s: &Series) -> String {
    let m = Summary::of(&s.hist);
    let tag = match s.test {
        Test::Timer => "T",
        Test::Ipc => "I",
        Test::Pipe => "P",
        Test::Unix => "U",
    };
    let cpus = match s.tx_cpu {
        Some(tx) => format!(" CPU {tx}->{}", s.cpu),
        None => format!(" CPU {}", s.cpu),
    };
    format!(
        "{tag}:{:2} ({:5}) P:{:2} I:{} C:{:8} Min:{:7.1} Act:{:7.1} Avg:{:7.1} Max:{:9.1} | \
         p50:{:7.1} p99:{:7.1} p99.9:{:8.1} p99.99:{:9.1} Ovf:{:5}{cpus}",
        s.index,
        s.tid,
        s.priority,
        s.interval_us,
        m.samples,
        m.min_us,
        s.act_ns as f64 * 1e-3,
        m.avg_us,
        m.max_us,
        m.p50_us,
        m.p99_us,
        m.p99_9_us,
        m.p99_99_us,
        s.overflows,
    )
}

/// The text report: a header per test, one line per series, notes.
pub fn text(r: &Results, opts: &Options) -> String {
    let histogram_us = opts.histogram_us;
    let mut out = format!(
        "# interval {} µs, phase {} µs on CLOCK_MONOTONIC, priority {}\n",
        opts.interval_us, opts.phase_us, opts.priority
    );
    if r.process_flags & rt_flags::DMA_LATENCY != 0 {
        out += "# /dev/cpu_dma_latency set to 0us\n";
    }
    if r.process_flags & rt_flags::MLOCK == 0 {
        out += "# warning: mlockall refused, pages may fault in\n";
    }
    for (test, secs) in &r.elapsed_s {
        out += &format!(
            "# {}: {} ({secs:.1} s); µs; Ovf = samples >= {histogram_us} µs\n",
            test.name(),
            test.describe()
        );
        for s in r.series.iter().filter(|s| s.test == *test) {
            out += &line(s);
            out.push('\n');
            if s.rt_flags & rt_flags::SCHED == 0 {
                out += "#   warning: SCHED_FIFO refused for this thread\n";
            }
        }
    }
    for n in &r.notes {
        out += &format!("# note: {n}\n");
    }
    if r.interrupted {
        out += "# interrupted: figures so far\n";
    }
    out
}

/// The JSON report: options, then per test the series with their figures.
pub fn to_json(r: &Results, opts: &Options) -> Value {
    let mut tests = serde_json::Map::new();
    for (test, secs) in &r.elapsed_s {
        let series: Vec<Value> = r
            .series
            .iter()
            .filter(|s| s.test == *test)
            .map(|s| {
                let mut v = serde_json::to_value(Summary::of(&s.hist)).unwrap_or_default();
                let o = v.as_object_mut().expect("an object");
                o.insert("index".into(), json!(s.index));
                o.insert("label".into(), json!(s.label()));
                o.insert("tid".into(), json!(s.tid));
                o.insert("cpu".into(), json!(s.cpu));
                if let Some(tx) = s.tx_cpu {
                    o.insert("tx_cpu".into(), json!(tx));
                }
                o.insert("priority".into(), json!(s.priority));
                o.insert("act_us".into(), json!(round3(s.act_ns as f64 * 1e-3)));
                o.insert("overflows".into(), json!(s.overflows));
                o.insert(
                    "sched_fifo".into(),
                    json!(s.rt_flags & rt_flags::SCHED != 0 && s.priority > 0),
                );
                v
            })
            .collect();
        tests.insert(
            test.name().into(),
            json!({"what": test.describe(), "seconds": round3(*secs), "series": series}),
        );
    }
    json!({
        "interval_us": opts.interval_us,
        "phase_us": opts.phase_us,
        "priority": opts.priority,
        "histogram_us": opts.histogram_us,
        "mlockall": r.process_flags & rt_flags::MLOCK != 0,
        "cpu_dma_latency_0": r.process_flags & rt_flags::DMA_LATENCY != 0,
        "interrupted": r.interrupted,
        "notes": r.notes,
        "tests": tests,
    })
}

/// One progress line: elapsed time and, per series, samples, min, avg and max (µs).
pub fn progress_line(running: &[Running], elapsed_s: f64) -> String {
    let mut out = format!("{elapsed_s:6.1} s");
    for r in running {
        let l = &r.live;
        let n = l.cycles.load(Ordering::Relaxed);
        let us = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed) as f64 * 1e-3;
        if n == 0 {
            out += &format!(" | {} -", r.label);
        } else {
            out += &format!(
                " | {} C:{n} Min:{:.1} Avg:{:.1} Max:{:.1}",
                r.label,
                us(&l.min_ns),
                us(&l.sum_ns) / n as f64,
                us(&l.max_ns)
            );
        }
    }
    out
}
