//! The figures of a program's run (`supervisor run --plot`, `exec --wait --plot`): the
//! commanded and measured path of the tool, the following error of every axis over the whole
//! run, and each process' wake-up latency histogram, drawn into one PNG by the `plot` crate.
//!
//! The supervisor gathers them as the program runs, in bounded memory whatever its length:
//! the path from the trace (thinned to what a figure can show), the following error as an
//! [`Envelope`] of servo's every state (the smallest and largest value per time bucket, so no
//! peak is lost however long the run), the histograms from the processes' own. [`Figures`]
//! travels to an `exec` client over the control channel; the client draws it.

use control_plane::figures::{Figures, PathFigure};
use motion_core::generator::Kin;
use plot::{Area, Bin, Figure, Histogram, Panel, PathLine};
use shm_schema::MAX_AXES;

/// Buckets an [`Envelope`] keeps at most; past it, their width doubles.
pub const ENVELOPE_BUCKETS: usize = 1024;

/// The smallest and largest value of each axis per time bucket, over a run of any length: the
/// first bucket starts at the first sample, buckets are `width_ns` wide, and when a sample
/// falls past the last of [`ENVELOPE_BUCKETS`], neighbours merge in pairs and the width
/// doubles. Peaks are exact; only where in its bucket one happened is lost. Non-finite values
/// are skipped. Fixed memory once full; no allocation after the buckets reach their count.
#[derive(Clone, Debug)]
pub struct Envelope {
    axes: usize,
    t0_ns: Option<u64>,
    width_ns: u64,
    /// Per bucket, per axis: (min, max); (inf, -inf) while empty.
    buckets: Vec<[(f64, f64); MAX_AXES]>,
}

const EMPTY: [(f64, f64); MAX_AXES] = [(f64::INFINITY, f64::NEG_INFINITY); MAX_AXES];

impl Envelope {
    /// An empty envelope of `axes` axes whose buckets start `width_ns` wide.
    pub fn new(axes: usize, width_ns: u64) -> Self {
        Self {
            axes: axes.min(MAX_AXES),
            t0_ns: None,
            width_ns: width_ns.max(1),
            buckets: Vec::new(),
        }
    }

    /// Makes the first bucket start at `t0_ns`, unless a sample or an earlier call already
    /// placed it.
    pub fn start_at(&mut self, t0_ns: u64) {
        self.t0_ns.get_or_insert(t0_ns);
    }

    /// Adds the values at time `stamp_ns`; a sample from before the first bucket is dropped.
    pub fn add(&mut self, stamp_ns: u64, values: &[f64; MAX_AXES]) {
        let t0 = *self.t0_ns.get_or_insert(stamp_ns);
        let Some(dt) = stamp_ns.checked_sub(t0) else {
            return;
        };
        let mut i = dt / self.width_ns;
        while i >= ENVELOPE_BUCKETS as u64 {
            self.merge_pairs();
            i = dt / self.width_ns;
        }
        let i = i as usize;
        if self.buckets.len() <= i {
            self.buckets.resize(i + 1, EMPTY);
        }
        for (b, &v) in self.buckets[i].iter_mut().zip(values).take(self.axes) {
            if v.is_finite() {
                *b = (b.0.min(v), b.1.max(v));
            }
        }
    }

    fn merge_pairs(&mut self) {
        let merged = self
            .buckets
            .chunks(2)
            .map(|pair| {
                let mut m = pair[0];
                if let Some(b) = pair.get(1) {
                    for (m, b) in m.iter_mut().zip(b) {
                        *m = (m.0.min(b.0), m.1.max(b.1));
                    }
                }
                m
            })
            .collect();
        self.buckets = merged;
        self.width_ns *= 2;
    }

    /// The width of a bucket now (ns).
    pub fn width_ns(&self) -> u64 {
        self.width_ns
    }

    /// Axis `k`'s buckets: (start, seconds from the first sample; min; max), empty ones left out.
    pub fn axis(&self, k: usize) -> Vec<(f64, f64, f64)> {
        let w = self.width_ns as f64 * 1e-9;
        self.buckets
            .iter()
            .enumerate()
            .filter_map(|(i, b)| {
                let (lo, hi) = *b.get(k)?;
                (lo <= hi).then_some((i as f64 * w, lo, hi))
            })
            .collect()
    }
}

/// The figure's size (pixels).
pub const WIDTH: u32 = 1280;
pub const HEIGHT: u32 = 960;

/// Where each plot goes: the path top left, the histograms top right, the following error
/// across the bottom.
pub fn areas() -> (Area, Area, Area) {
    let (w, h) = (WIDTH as i32, HEIGHT as i32);
    let top = plot::TITLE_H;
    let split = top + (h - top) * 11 / 20;
    (
        Area {
            left: 0,
            top,
            right: w / 2,
            bottom: split,
        },
        Area {
            left: w / 2,
            top,
            right: w,
            bottom: split,
        },
        Area {
            left: 0,
            top: split,
            right: w,
            bottom: h,
        },
    )
}

/// Line widths: the commanded path wide under the measured one, so both show where they agree.
const COMMANDED_WIDTH: u32 = 5;
const MEASURED_WIDTH: u32 = 1;

/// `figures` drawn (not yet encoded); the path's scale for whoever checks it.
pub fn draw(figures: &Figures) -> (Figure, plot::PathScale) {
    let mut f = Figure::new(WIDTH, HEIGHT);
    f.title(&figures.title);
    let (path_area, lat_area, fe_area) = areas();
    let p = &figures.path;
    let scale = f.path(
        path_area,
        "tool path, o at the start",
        (&p.labels.0, &p.labels.1),
        &[
            PathLine {
                label: "commanded".into(),
                points: p.commanded.clone(),
                width: COMMANDED_WIDTH,
            },
            PathLine {
                label: "measured".into(),
                points: p.measured.clone(),
                width: MEASURED_WIDTH,
            },
        ],
    );
    let hist: Vec<Histogram> = figures
        .latency
        .iter()
        .map(|l| Histogram {
            label: format!(
                "{} p99 {:.0} \u{b5}s, max {:.0} \u{b5}s",
                l.process, l.p99_us, l.max_us
            ),
            bins: l
                .bins
                .iter()
                .map(|&(lo, hi, count)| Bin { lo, hi, count })
                .collect(),
        })
        .collect();
    f.log_histogram(
        lat_area,
        "wake-up latency per process, since it started",
        "wake-up latency (\u{b5}s, log)",
        &hist,
    );
    // One panel per unit (mm and deg do not share a scale); each axis' envelope drawn as
    // a band: its min and max alternate along the line.
    let mut panels: Vec<Panel> = Vec::new();
    for a in &figures.following_error {
        // Servo's own latch (every cycle); the envelope's when servo latched another
        // program (a failure before this one's first state).
        let peak = if a.peak.is_finite() {
            a.peak
        } else {
            a.buckets
                .iter()
                .flat_map(|&(_, lo, hi)| [lo, hi])
                .fold(0.0, |p: f64, v| if v.abs() > p.abs() { v } else { p })
        };
        let label = format!("{} (peak {peak:.4} {})", a.axis, a.unit);
        let band: Vec<(f64, f64)> = a
            .buckets
            .iter()
            .flat_map(|&(t, lo, hi)| [(t, lo), (t, hi)])
            .collect();
        let y_label = format!("following error ({})", a.unit);
        match panels.iter_mut().find(|p| p.y_label == y_label) {
            Some(p) => p.lines.push((label, band)),
            None => panels.push(Panel {
                y_label,
                lines: vec![(label, band)],
            }),
        }
    }
    f.series(
        fe_area,
        "time from the program's first setpoint (s); every servo cycle, min and max per bucket",
        &panels,
    );
    (f, scale)
}

/// `figures` as a PNG.
pub fn png(figures: &Figures) -> Result<Vec<u8>, String> {
    draw(figures).0.png()
}

/// Draws `figures` and writes the PNG to `path`.
pub fn write_png(figures: &Figures, path: &std::path::Path) -> Result<(), String> {
    let png = png(figures).map_err(|e| format!("--plot {}: {e}", path.display()))?;
    std::fs::write(path, png).map_err(|e| format!("--plot {}: {e}", path.display()))
}

/// Thins a path to what a figure shows, in one pass (Reumann-Witkam): a run of points that
/// stays within `tol` of the line through its first two becomes its ends, so a straight
/// stretch of any length is two points and an arc keeps a point every few `tol`s. A point
/// that turns back along the line (a reversal) ends the run too. Corners and the ends
/// survive; a path that stands still becomes one point. A point that is not finite (a pose
/// the kinematics could not give) breaks the line: one `(NaN, NaN)` in its place.
pub fn thin(points: impl IntoIterator<Item = (f64, f64)>, tol: f64) -> Vec<(f64, f64)> {
    let gap = (f64::NAN, f64::NAN);
    let mut out: Vec<(f64, f64)> = Vec::new();
    // The run: its first point, its direction (unit) once a point left the tolerance, the
    // farthest it went along it, and its newest point.
    let mut anchor: Option<(f64, f64)> = None;
    let mut dir: Option<(f64, f64)> = None;
    let mut far = 0.0f64;
    let mut prev = (0.0, 0.0);
    for p in points {
        if !(p.0.is_finite() && p.1.is_finite()) {
            if let Some(a) = anchor.take() {
                if prev != a {
                    out.push(prev);
                }
                out.push(gap);
            }
            continue;
        }
        let Some(mut a) = anchor else {
            out.push(p);
            (anchor, dir, far, prev) = (Some(p), None, 0.0, p);
            continue;
        };
        let inside = |a: (f64, f64), d: (f64, f64), far: f64| {
            let v = (p.0 - a.0, p.1 - a.1);
            let along = v.0 * d.0 + v.1 * d.1;
            let across = (v.0 * d.1 - v.1 * d.0).abs();
            (across <= tol && along >= far - tol).then_some(along)
        };
        if let Some(d) = dir {
            match inside(a, d, far) {
                Some(along) => far = far.max(along),
                None => {
                    // The run ends at the point before: a new run from there.
                    out.push(prev);
                    a = prev;
                    anchor = Some(a);
                    dir = None;
                    far = 0.0;
                }
            }
        }
        if dir.is_none() {
            let v = (p.0 - a.0, p.1 - a.1);
            let len = v.0.hypot(v.1);
            if len > tol {
                dir = Some((v.0 / len, v.1 / len));
                far = len;
            }
        }
        prev = p;
    }
    if let Some(a) = anchor
        && prev != a
    {
        out.push(prev);
    }
    if out.last().is_some_and(|p| p.0.is_nan()) {
        out.pop();
    }
    out
}

/// The tool's pose for joints `q` (the first `n`): through the cell's kinematics, or the
/// joints themselves for the gantry.
pub fn tool_of(kin: Option<&Kin>, q: &[f64; MAX_AXES], n: usize) -> Option<Vec<f64>> {
    match kin {
        None => Some(q[..n].to_vec()),
        Some(k) => {
            let mut j = [0.0; kinematics::MAX_JOINTS];
            for (d, v) in j.iter_mut().zip(&q[..n]) {
                *d = *v;
            }
            let p = k.0.axes_to_cartesian(&j).ok()?;
            Some(p[..k.0.coords().len()].to_vec())
        }
    }
}

/// One row of a path: its time (s), the commanded and the measured joints, and the
/// commanded tool when the setpoint carries it (trajgen's own; a foreign trajgen may leave it
/// out, and then it comes through the kinematics like the measured tool).
pub type PathRow = (
    f64,
    [f64; MAX_AXES],
    [f64; MAX_AXES],
    Option<[f64; MAX_AXES]>,
);

/// The path figure of a trace: each row mapped to the tool, in the plane of the first two
/// coordinates `coords` (name, unit).
pub fn path_of(
    rows: impl Iterator<Item = PathRow> + Clone,
    kin: Option<&Kin>,
    n: usize,
    coords: &[(String, String)],
) -> PathFigure {
    let plane = coords.len() >= 2;
    let pick = |t: f64, p: Option<&[f64]>| -> (f64, f64) {
        match p {
            Some(p) if plane => (p[0], p[1]),
            Some(p) => (t, p.first().copied().unwrap_or(f64::NAN)),
            None => (f64::NAN, f64::NAN),
        }
    };
    let cmd: Vec<(f64, f64)> = rows
        .clone()
        .map(|(t, c, _, tool)| match tool {
            Some(tool) => pick(t, Some(&tool[..])),
            None => pick(t, tool_of(kin, &c, n).as_deref()),
        })
        .collect();
    let act: Vec<(f64, f64)> = rows
        .map(|(t, _, a, _)| pick(t, tool_of(kin, &a, n).as_deref()))
        .collect();
    // A tolerance of 1/1200 of the path's extent: a point stays within about twice that of
    // the line drawn, about a pixel of the figure.
    let extent = |pts: &[(f64, f64)]| {
        let f = pts.iter().filter(|p| p.0.is_finite() && p.1.is_finite());
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in f {
            (x0, x1, y0, y1) = (x0.min(p.0), x1.max(p.0), y0.min(p.1), y1.max(p.1));
        }
        ((x1 - x0).max(y1 - y0)).max(0.0)
    };
    let tol = extent(&cmd) / 1200.0;
    let label = |(name, unit): &(String, String)| format!("{name} ({unit})");
    let labels = if plane {
        (label(&coords[0]), label(&coords[1]))
    } else {
        (
            "time (s)".into(),
            coords.first().map(label).unwrap_or_default(),
        )
    };
    PathFigure {
        labels,
        commanded: thin(cmd, tol),
        measured: thin(act, tol),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control_plane::figures::{AxisEnvelope, ProcessLatency};

    fn one(v: f64) -> [f64; MAX_AXES] {
        let mut a = [0.0; MAX_AXES];
        a[0] = v;
        a[1] = -v;
        a
    }

    /// The distance from `p` to the nearest segment of `line` (its breaks skipped).
    fn off_line(p: (f64, f64), line: &[(f64, f64)]) -> f64 {
        line.windows(2)
            .filter(|w| w[0].0.is_finite() && w[1].0.is_finite())
            .map(|w| {
                let (a, b) = (w[0], w[1]);
                let (dx, dy) = (b.0 - a.0, b.1 - a.1);
                let l2 = dx * dx + dy * dy;
                let t = if l2 > 0.0 {
                    (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / l2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                (p.0 - a.0 - t * dx).hypot(p.1 - a.1 - t * dy)
            })
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn an_envelope_keeps_every_peak_however_long_the_run() {
        // 20 000 samples at 1 ms into 1024 buckets: the widths double five times.
        let mut e = Envelope::new(2, 1_000_000);
        let mut peak = (0.0f64, 0.0f64);
        for i in 0..20_000u64 {
            let v = ((i as f64) * 0.37).sin() * (1.0 + (i % 997) as f64 * 1e-3);
            let v = if i == 12_345 { 7.5 } else { v };
            peak = (peak.0.min(v), peak.1.max(v));
            e.add(1_000 + i * 1_000_000, &one(v));
        }
        assert_eq!(e.width_ns(), 32_000_000);
        let a = e.axis(0);
        assert!(a.len() <= ENVELOPE_BUCKETS);
        let lo = a.iter().map(|b| b.1).fold(f64::INFINITY, f64::min);
        let hi = a.iter().map(|b| b.2).fold(f64::NEG_INFINITY, f64::max);
        assert_eq!((lo, hi), peak);
        // The spike is in the bucket of its time.
        let spike = a.iter().find(|b| b.2 == 7.5).expect("the spike");
        assert!(spike.0 <= 12.345 && 12.345 < spike.0 + 0.032, "{spike:?}");
        // The second axis (the negated values) too.
        let b = e.axis(1);
        let hi = b.iter().map(|b| b.2).fold(f64::NEG_INFINITY, f64::max);
        assert_eq!(hi, -peak.0);
    }

    #[test]
    fn an_envelope_skips_what_is_not_a_number_and_leaves_gaps_empty() {
        let mut e = Envelope::new(1, 10);
        e.add(100, &one(1.0));
        e.add(105, &one(f64::NAN));
        e.add(150, &one(-2.0));
        e.add(50, &one(99.0)); // before the first: dropped
        let a = e.axis(0);
        assert_eq!(a.len(), 2);
        assert_eq!((a[0].1, a[0].2), (1.0, 1.0));
        assert_eq!((a[1].1, a[1].2), (-2.0, -2.0));
        assert!((a[1].0 - 50e-9).abs() < 1e-15);
    }

    #[test]
    fn thinning_keeps_the_corners_the_ends_and_the_reversals() {
        // Along x, up, and back down the same line: 3001 points.
        let mut pts = Vec::new();
        for i in 0..=1000 {
            pts.push((f64::from(i) * 0.1, 0.0));
        }
        for i in 1..=1000 {
            pts.push((100.0, f64::from(i) * 0.1));
        }
        for i in 1..=1000 {
            pts.push((100.0, 100.0 - f64::from(i) * 0.05));
        }
        pts.push((100.0, 50.0)); // standing still at the end
        let t = thin(pts.clone(), 0.01);
        assert_eq!(
            t,
            vec![(0.0, 0.0), (100.0, 0.0), (100.0, 100.0), (100.0, 50.0)]
        );
        assert_eq!(thin([(1.0, 1.0); 10], 0.5), vec![(1.0, 1.0)]);
    }

    #[test]
    fn a_thinned_arc_stays_within_the_tolerance_and_a_gap_breaks_it() {
        // A circle of radius 100 in 10 000 points, a gap (no pose) in the middle.
        let tol = 0.05;
        let pts: Vec<(f64, f64)> = (0..=10_000)
            .map(|i| {
                if (5000..5010).contains(&i) {
                    return (f64::NAN, f64::NAN);
                }
                let a = f64::from(i) * std::f64::consts::TAU / 10_000.0;
                (100.0 * a.cos(), 100.0 * a.sin())
            })
            .collect();
        let t = thin(pts.clone(), tol);
        assert!(t.len() < 400, "{}", t.len());
        assert_eq!(t.iter().filter(|p| p.0.is_nan()).count(), 1, "one break");
        let worst = pts
            .iter()
            .filter(|p| p.0.is_finite())
            .map(|&p| off_line(p, &t))
            .fold(0.0, f64::max);
        assert!(worst <= 2.0 * tol, "{worst}");
        // Nothing drawn across the gap: the points on either side are not joined.
        let k = t.iter().position(|p| p.0.is_nan()).expect("a break");
        assert!(k > 0 && t[k - 1].1 > 0.0 && t[k + 1].1 < 0.0);
        assert_eq!(t.first(), Some(&pts[0]));
        assert_eq!(t.last(), pts.last());
    }

    #[test]
    fn a_figure_draws_the_path_where_the_trace_went() {
        let mut rows = Vec::new();
        // A square, the measured path 0.05 off to the side.
        for i in 0..400 {
            let s = f64::from(i) / 100.0;
            let (x, y) = match i / 100 {
                0 => (40.0 + 100.0 * s, 40.0),
                1 => (140.0, 40.0 + 100.0 * (s - 1.0)),
                2 => (140.0 - 100.0 * (s - 2.0), 140.0),
                _ => (40.0, 140.0 - 100.0 * (s - 3.0)),
            };
            let mut c = [0.0; MAX_AXES];
            c[0] = x;
            c[1] = y;
            let mut a = c;
            a[0] += 0.05;
            rows.push((s, c, a, None));
        }
        let coords = vec![
            ("x".to_string(), "mm".to_string()),
            ("y".into(), "mm".into()),
        ];
        let path = path_of(rows.iter().copied(), None, 3, &coords);
        assert_eq!(path.labels, ("x (mm)".into(), "y (mm)".into()));
        let mut e = Envelope::new(2, 1_000_000);
        for i in 0..4000u64 {
            e.add(i * 1_000_000, &one(0.04 * ((i as f64) * 0.01).sin()));
        }
        let figures = Figures {
            title: "square".into(),
            path,
            following_error: vec![AxisEnvelope {
                axis: "x".into(),
                unit: "mm".into(),
                peak: 0.04,
                buckets: e.axis(0),
            }],
            latency: vec![ProcessLatency {
                process: "servo".into(),
                bins: vec![(10.0, 11.0, 100), (11.0, 12.0, 5)],
                p99_us: 11.0,
                max_us: 12.0,
            }],
        };
        let (f, scale) = draw(&figures);
        // The commanded path, 5 pixels wide under the measured one, at each corner.
        let near = |(px, py): (i32, i32), c: [u8; 3]| {
            (-2..=2).any(|dx| (-2..=2).any(|dy| f.pixel(px + dx, py + dy) == c))
        };
        for (x, y) in [(40.0, 40.0), (140.0, 40.0), (140.0, 140.0), (40.0, 140.0)] {
            assert!(near(scale.pixel(x, y), plot::color(0)), "corner ({x}, {y})");
        }
        // The middle of the square is not on the path (a grid line may cross it).
        let (px, py) = scale.pixel(90.0, 90.0);
        assert_ne!(f.pixel(px, py), plot::color(0));
        // The measured path (second colour) is drawn along the commanded one.
        assert!(near(scale.pixel(90.0, 40.0), plot::color(1)));
        // Round trip through the control channel's encoding.
        let bytes = postcard::to_allocvec(&figures).expect("encodes");
        let back: Figures = postcard::from_bytes(&bytes).expect("decodes");
        assert_eq!(back, figures);
        assert_eq!(&png(&figures).expect("png")[1..4], b"PNG");
    }
}
