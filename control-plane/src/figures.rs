//! The figures of a program's run (`supervisor run --plot`, `exec --wait --plot`) as data:
//! the commanded and measured path of the tool, the following error of every axis over the
//! whole run, and each process' wake-up latency histogram. The supervisor gathers them as the
//! program runs; they travel to an `exec` client in [`crate::Reply::Report`]; the client
//! draws them (the supervisor's `figures` module, with the `plot` crate).

use serde::{Deserialize, Serialize};
use shm_schema::LatencyHistogramV1;

/// The following error of one axis over the run: the smallest and largest value per time
/// bucket (the supervisor's `Envelope`), so no peak is lost however long the run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AxisEnvelope {
    pub axis: String,
    pub unit: String,
    /// Servo's own latch over the run (`ServoStateV3.peak_following_error`).
    pub peak: f64,
    /// Per bucket: its start (s from the program's first setpoint), min, max.
    pub buckets: Vec<(f64, f64, f64)>,
}

/// The tool's path in the plane of the cell's first two Cartesian coordinates (or, for a
/// cell with one, that coordinate over time).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PathFigure {
    /// Horizontal and vertical axis labels (`x (mm)`, `y (mm)`, or `time (s)`).
    pub labels: (String, String),
    pub commanded: Vec<(f64, f64)>,
    pub measured: Vec<(f64, f64)>,
}

/// One process' wake-up latency since it started (for `run`, the processes it launched: the
/// run; for `exec` on a long-running cell, the processes' whole life so far).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ProcessLatency {
    pub process: String,
    /// (lowest µs, highest µs, samples), ascending, empty bins left out.
    pub bins: Vec<(f64, f64, u64)>,
    pub p99_us: f64,
    pub max_us: f64,
}

impl ProcessLatency {
    /// The figure of `process`' histogram `h`.
    pub fn of(process: &str, h: &LatencyHistogramV1) -> Self {
        let m = crate::status::Percentiles::of(h);
        Self {
            process: process.to_string(),
            bins: latency_bins(h),
            p99_us: m.p99_us,
            max_us: m.max_us,
        }
    }
}

/// Everything `--plot` draws.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Figures {
    pub title: String,
    pub path: PathFigure,
    pub following_error: Vec<AxisEnvelope>,
    pub latency: Vec<ProcessLatency>,
}

/// The wake-up latency histogram `h` in bins of 1/8 octave (16 of its buckets each, all its
/// 1-ns buckets below 256 ns in one), µs, ascending, empty bins left out.
pub fn latency_bins(h: &LatencyHistogramV1) -> Vec<(f64, f64, u64)> {
    use shm_schema::latency::{BUCKETS, bucket_bounds};
    const FIRST: usize = 256;
    const GROUP: usize = 16;
    let groups = 1 + (BUCKETS - FIRST).div_ceil(GROUP);
    (0..groups)
        .filter_map(|g| {
            let (first, last) = if g == 0 {
                (0, FIRST - 1)
            } else {
                let first = FIRST + (g - 1) * GROUP;
                (first, (first + GROUP - 1).min(BUCKETS - 1))
            };
            let count: u64 = h.buckets[first..=last].iter().sum();
            (count > 0).then(|| {
                let (mut lo, hi) = (bucket_bounds(first).0, bucket_bounds(last).1 + 1);
                if g == 0 {
                    // Not from 0 ns: on a log axis that would stretch it decades to the left.
                    lo = h.min_ns.clamp(1, hi - 1);
                }
                (lo as f64 * 1e-3, hi as f64 * 1e-3, count)
            })
        })
        .collect()
}
