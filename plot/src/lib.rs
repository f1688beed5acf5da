//! PNG figures drawn without a windowing system, for the reports of a cell.
//!
//! A [`Figure`] is a white canvas of any size; each plot is drawn into an [`Area`] of it, so
//! one figure composes several: a run's path, its following error and its processes' latency
//! histograms side by side ([`Figure::path`], [`Figure::series`], [`Figure::log_histogram`]).
//! [`png`] (cyclictest's 1-µs histograms, `supervisor latency`) and [`series_png`] (stacked
//! time series, `supervisor tune`) are the one-plot figures.
//!
//! Every plot has "nice" ticks (1, 2 or 5 times a power of ten) with labels, a light grid, a
//! frame and a legend; a point with a coordinate that is not a finite number is skipped and
//! breaks its line.

use embedded_graphics::mono_font::MonoTextStyle;
use embedded_graphics::mono_font::iso_8859_1::FONT_6X10;
use embedded_graphics::pixelcolor::Rgb888;
use embedded_graphics::prelude::*;
use embedded_graphics::primitives::{
    Circle, Line, PrimitiveStyle, PrimitiveStyleBuilder, Rectangle,
};
use embedded_graphics::text::{Alignment, Text};

/// The size of the one-plot figures ([`png`], [`series_png`]).
const W: u32 = 960;
const H: u32 = 540;
/// Room between an area's edges and its plot's frame: tick labels on the left and under it,
/// its title (or the first panel's label) above it.
const LEFT: i32 = 70;
const RIGHT: i32 = 20;
const TOP: i32 = 24;
const BOTTOM: i32 = 50;
/// The height of a figure's title line.
pub const TITLE_H: i32 = 16;

/// The colours of the lines, in order (the usual ten-colour palette's first eight).
pub const COLORS: [Rgb888; 8] = [
    Rgb888::new(31, 119, 180),
    Rgb888::new(255, 127, 14),
    Rgb888::new(44, 160, 44),
    Rgb888::new(214, 39, 40),
    Rgb888::new(148, 103, 189),
    Rgb888::new(140, 86, 75),
    Rgb888::new(227, 119, 194),
    Rgb888::new(127, 127, 127),
];

/// The colour of the `i`-th line, as [`Figure::pixel`] reads it.
pub fn color(i: usize) -> [u8; 3] {
    let c = COLORS[i % COLORS.len()];
    [c.r(), c.g(), c.b()]
}

/// A rectangle of a figure, in pixels (left and top inclusive, right and bottom exclusive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Area {
    pub left: i32,
    pub top: i32,
    pub right: i32,
    pub bottom: i32,
}

impl Area {
    /// The frame a plot draws in this area: `(x0, x1, y_bottom, y_top)`.
    fn frame(&self) -> (i32, i32, i32, i32) {
        let x0 = self.left + LEFT;
        let x1 = (self.right - RIGHT).max(x0 + 1);
        let y1 = self.top + TOP;
        let y0 = (self.bottom - BOTTOM).max(y1 + 1);
        (x0, x1, y0, y1)
    }
}

/// A white canvas to draw plots on, then encode as a PNG.
#[derive(Clone, Debug)]
pub struct Figure {
    w: u32,
    h: u32,
    rgb: Vec<u8>,
}

impl OriginDimensions for Figure {
    fn size(&self) -> Size {
        Size::new(self.w, self.h)
    }
}

impl DrawTarget for Figure {
    type Color = Rgb888;
    type Error = core::convert::Infallible;

    fn draw_iter<I: IntoIterator<Item = Pixel<Rgb888>>>(
        &mut self,
        pixels: I,
    ) -> Result<(), Self::Error> {
        for Pixel(p, c) in pixels {
            if (0..self.w as i32).contains(&p.x) && (0..self.h as i32).contains(&p.y) {
                let i = (p.y as usize * self.w as usize + p.x as usize) * 3;
                self.rgb[i..i + 3].copy_from_slice(&[c.r(), c.g(), c.b()]);
            }
        }
        Ok(())
    }
}

/// One line of a [`Figure::path`]: its label, its points and its width in pixels.
#[derive(Clone, Debug, Default)]
pub struct PathLine {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub width: u32,
}

/// Where [`Figure::path`] put its data: the same scale on both axes.
#[derive(Clone, Copy, Debug)]
pub struct PathScale {
    /// Pixels per data unit, on both axes.
    pub px_per_unit: f64,
    /// The data point at the pixel `origin_px`.
    origin: (f64, f64),
    origin_px: (i32, i32),
}

impl PathScale {
    /// The pixel of data point `(x, y)`.
    pub fn pixel(&self, x: f64, y: f64) -> (i32, i32) {
        // A point far outside (a wild measured value) lands far off the figure, never wraps.
        (
            self.origin_px
                .0
                .saturating_add(((x - self.origin.0) * self.px_per_unit).round() as i32),
            self.origin_px
                .1
                .saturating_sub(((y - self.origin.1) * self.px_per_unit).round() as i32),
        )
    }
}

/// One bin of a [`Histogram`]: the values from `lo` to `hi` and how many samples fell there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bin {
    pub lo: f64,
    pub hi: f64,
    pub count: u64,
}

/// One series of [`Figure::log_histogram`]: a label and its bins, in ascending order.
#[derive(Clone, Debug, Default)]
pub struct Histogram {
    pub label: String,
    pub bins: Vec<Bin>,
}

/// A "nice" tick step of at least 1 (1, 2 or 5 times a power of ten) giving about `n` ticks
/// over `span`: the histogram's bins are whole microseconds.
fn tick_step(span: f64, n: f64) -> f64 {
    nice_step(span, n).max(1.0)
}

/// A "nice" tick step (1, 2 or 5 times a power of ten, negative powers included) giving about
/// `n` ticks over `span`; 1 when `span / n` is not a positive finite number.
fn nice_step(span: f64, n: f64) -> f64 {
    let raw = span / n;
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let e = raw.log10().floor() as i32;
    // Dividing by a positive power of ten keeps 0.2, 0.05, … the closest doubles to themselves.
    let scaled = |m: f64, e: i32| {
        if e >= 0 {
            m * 10f64.powi(e)
        } else {
            m / 10f64.powi(-e)
        }
    };
    [1.0, 2.0, 5.0]
        .into_iter()
        .map(|m| scaled(m, e))
        .find(|s| *s >= raw)
        .unwrap_or_else(|| scaled(1.0, e + 1))
}

/// The decimals a multiple of `step` needs (0 for a step of 1 or more).
fn decimals(step: f64) -> usize {
    (-step.log10().floor()).max(0.0) as usize
}

/// A tick label for `v`, a multiple of `step`: fixed point with as few decimals as the step
/// needs, or scientific notation when that would be too long (tiny steps, huge values).
fn tick_label(v: f64, step: f64) -> String {
    let v = if v.abs() < step * 1e-6 { 0.0 } else { v };
    let d = decimals(step);
    if d <= 6 && v.abs() < 1e9 {
        return format!("{v:.d$}");
    }
    // Mantissa digits: as many as separate the value's magnitude from the step's.
    let p = if v == 0.0 {
        0
    } else {
        (v.abs().log10().floor() - step.log10().floor()).clamp(0.0, 12.0) as usize
    };
    format!("{v:.p$e}")
}

/// The multiples of `step` within `lo..=hi` (at most 100, none if `step` is unusable).
fn ticks(lo: f64, hi: f64, step: f64) -> impl Iterator<Item = f64> {
    let ok = step.is_finite() && step > 0.0 && lo.is_finite() && hi.is_finite();
    let (a, b) = if ok {
        (
            (lo / step - 1e-9).ceil() as i64,
            (hi / step + 1e-9).floor() as i64,
        )
    } else {
        (1, 0)
    };
    (a..=b).take(100).map(move |k| k as f64 * step)
}

/// `lo..hi` widened to ±1 around the value when degenerate (or absent: around 0).
fn widen(lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        (-1.0, 1.0)
    } else if hi - lo > 0.0 {
        (lo, hi)
    } else {
        (lo - 1.0, lo + 1.0)
    }
}

/// The min and max of `values`, ignoring non-finite ones (`(inf, -inf)` if none is finite).
fn min_max(values: impl Iterator<Item = f64>) -> (f64, f64) {
    values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        })
}

/// Draws the histograms `series` (label, counts per 1-µs bin) under `title` and encodes a PNG.
pub fn png(title: &str, series: &[(String, Vec<u64>)]) -> Result<Vec<u8>, String> {
    let mut f = Figure::new(W, H);
    f.title(title);
    let area = f.below_title();
    f.histogram_1us(area, series);
    f.png()
}

/// Draws `panels` stacked vertically, sharing the x axis (`x_label`), under `title`; encodes a
/// PNG (same size W×H as [`png`]). See [`Figure::series`]. Errors only if encoding fails.
pub fn series_png(title: &str, x_label: &str, panels: &[Panel]) -> Result<Vec<u8>, String> {
    let mut f = Figure::new(W, H);
    f.title(title);
    let area = f.below_title();
    f.series(area, x_label, panels);
    f.png()
}

impl Figure {
    /// A white canvas of `w` × `h` pixels.
    pub fn new(w: u32, h: u32) -> Self {
        Figure {
            w,
            h,
            rgb: vec![255; (w * h * 3) as usize],
        }
    }

    /// The whole figure under its title line.
    pub fn below_title(&self) -> Area {
        Area {
            left: 0,
            top: TITLE_H,
            right: self.w as i32,
            bottom: self.h as i32,
        }
    }

    /// The figure's title, centred on its first line.
    pub fn title(&mut self, text: &str) {
        let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
        let _ = Text::with_alignment(
            text,
            Point::new(self.w as i32 / 2, 12),
            black,
            Alignment::Center,
        )
        .draw(self);
    }

    /// The colour of pixel `(x, y)` (white outside the figure).
    pub fn pixel(&self, x: i32, y: i32) -> [u8; 3] {
        if !((0..self.w as i32).contains(&x) && (0..self.h as i32).contains(&y)) {
            return [255; 3];
        }
        let i = (y as usize * self.w as usize + x as usize) * 3;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// Encodes the figure as an 8-bit RGB PNG.
    pub fn png(&self) -> Result<Vec<u8>, String> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.w, self.h);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().map_err(|e| e.to_string())?;
            w.write_image_data(&self.rgb).map_err(|e| e.to_string())?;
        }
        Ok(out)
    }

    /// A plot's frame, its title (`above`, at the area's left) and its x label (under the
    /// tick labels).
    fn decorate(&mut self, area: Area, above: &str, x_label: &str) {
        let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
        let (x0, x1, y0, y1) = area.frame();
        let _ = Rectangle::with_corners(Point::new(x0, y1), Point::new(x1, y0))
            .into_styled(PrimitiveStyle::with_stroke(Rgb888::BLACK, 1))
            .draw(self);
        let _ = Text::new(above, Point::new(area.left + 6, y1 - 8), black).draw(self);
        let _ = Text::with_alignment(
            x_label,
            Point::new((x0 + x1) / 2, y0 + 34),
            black,
            Alignment::Center,
        )
        .draw(self);
    }

    /// Histograms of 1-µs bins (label, counts), latency on a linear x axis (µs), sample
    /// counts on a log y axis, one step line per series, as the usual cyclictest plots.
    pub fn histogram_1us(&mut self, area: Area, series: &[(String, Vec<u64>)]) {
        let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
        let axis = PrimitiveStyle::with_stroke(Rgb888::BLACK, 1);
        let grid = PrimitiveStyle::with_stroke(Rgb888::new(225, 225, 225), 1);
        let (x0, x1, y0, y1) = area.frame();

        // Ranges: up to the last non-empty bin; counts in decades.
        let last = series
            .iter()
            .filter_map(|(_, b)| b.iter().rposition(|&v| v > 0))
            .max()
            .unwrap_or(0);
        let xmax = (last + 2).max(10) as f64;
        let cmax = series
            .iter()
            .flat_map(|(_, b)| b.iter().copied())
            .max()
            .unwrap_or(1)
            .max(1);
        let decades = (cmax as f64).log10().ceil().max(1.0);
        let px = |us: f64| x0 + ((us / xmax) * (x1 - x0) as f64).round() as i32;
        let py = log_count_scale(decades, y0, y1);

        // Grid and ticks.
        self.count_ticks(decades, (x0, x1), &py);
        let step = tick_step(xmax, 10.0);
        let mut t = 0.0;
        while t <= xmax {
            let x = px(t);
            let _ = Line::new(Point::new(x, y0), Point::new(x, y1))
                .into_styled(grid)
                .draw(self);
            let _ = Text::with_alignment(
                &format!("{t}"),
                Point::new(x, y0 + 14),
                black,
                Alignment::Center,
            )
            .draw(self);
            t += step;
        }
        let _ = Rectangle::with_corners(Point::new(x0, y1), Point::new(x1, y0))
            .into_styled(axis)
            .draw(self);
        let _ = Text::with_alignment(
            "latency (\u{b5}s, 1-\u{b5}s bins)",
            Point::new((x0 + x1) / 2, y0 + 34),
            black,
            Alignment::Center,
        )
        .draw(self);
        let _ = Text::new("samples (log)", Point::new(area.left + 6, y1 - 10), black).draw(self);

        // One step line per series; the legend in the top right corner.
        for (k, (_, bins)) in series.iter().enumerate() {
            let style = PrimitiveStyle::with_stroke(COLORS[k % COLORS.len()], 2);
            let mut prev = Point::new(px(0.0), py(0));
            for (i, &v) in bins.iter().enumerate().take(last + 2) {
                let (xa, xb, y) = (px(i as f64), px(i as f64 + 1.0), py(v));
                let _ = Line::new(prev, Point::new(xa, y))
                    .into_styled(style)
                    .draw(self);
                let _ = Line::new(Point::new(xa, y), Point::new(xb, y))
                    .into_styled(style)
                    .draw(self);
                prev = Point::new(xb, y);
            }
        }
        let labels: Vec<&str> = series.iter().map(|(l, _)| l.as_str()).collect();
        draw_legend(self, Point::new(x1 - 6, y1 + 6), &labels);
    }

    /// The horizontal grid lines and labels of a log count axis with `decades` decades.
    fn count_ticks(&mut self, decades: f64, (x0, x1): (i32, i32), py: &impl Fn(u64) -> i32) {
        let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
        let grid = PrimitiveStyle::with_stroke(Rgb888::new(225, 225, 225), 1);
        for d in 0..=decades as i32 {
            let y = py(10u64.pow(d as u32));
            let _ = Line::new(Point::new(x0, y), Point::new(x1, y))
                .into_styled(grid)
                .draw(self);
            let label = format!("1e{d}");
            let _ =
                Text::with_alignment(&label, Point::new(x0 - 6, y + 3), black, Alignment::Right)
                    .draw(self);
        }
    }

    /// `panels` stacked vertically in `area`, sharing the x axis (`x_label`). Each panel has
    /// its own y range (min..max over its lines, padded 5 %, a degenerate range widened to ±1
    /// around the value), "nice" ticks on both axes with labels (x labels under the bottom
    /// panel only), a light grid, a frame, its y label above it, a legend in its top-right
    /// corner, and one polyline per line in the [`COLORS`] order. Points with a non-finite
    /// coordinate break the line (a new segment starts after them).
    pub fn series(&mut self, area: Area, x_label: &str, panels: &[Panel]) {
        let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
        let (x0, x1, bottom, top) = area.frame();

        // The shared x range: over every finite point of every panel.
        let finite = |&&(x, y): &&(f64, f64)| x.is_finite() && y.is_finite();
        let all = || {
            panels.iter().flat_map(|p| {
                p.lines
                    .iter()
                    .flat_map(|(_, pts)| pts.iter().filter(finite))
            })
        };
        let (xlo, xhi) = min_max(all().map(|p| p.0));
        let (xlo, xhi) = widen(xlo, xhi);
        let px = |x: f64| x0 + ((x - xlo) / (xhi - xlo) * (x1 - x0) as f64).round() as i32;
        let xstep = nice_step(xhi - xlo, ((x1 - x0) / 90).clamp(2, 10) as f64);

        let n = panels.len().max(1) as i32;
        let h = ((bottom - top - PANEL_GAP * (n - 1)) / n).max(1);
        for (k, panel) in panels.iter().enumerate() {
            let y1 = top + k as i32 * (h + PANEL_GAP);
            let y0 = y1 + h;
            let pts = || {
                panel
                    .lines
                    .iter()
                    .flat_map(|(_, p)| p.iter().filter(finite))
            };
            let (lo, hi) = min_max(pts().map(|p| p.1));
            let (lo, hi) = if lo.is_finite() {
                let pad = 0.05 * (hi - lo);
                widen(lo - pad, hi + pad)
            } else {
                widen(lo, hi)
            };
            let py = |y: f64| y0 - ((y - lo) / (hi - lo) * (y0 - y1) as f64).round() as i32;
            let last = k + 1 == panels.len();
            draw_x_ticks(self, (y0, y1), xlo, xhi, xstep, px, last);
            draw_y_ticks(self, (x0, x1), lo, hi, h, py);
            let _ = Rectangle::with_corners(Point::new(x0, y1), Point::new(x1, y0))
                .into_styled(PrimitiveStyle::with_stroke(Rgb888::BLACK, 1))
                .draw(self);
            let _ = Text::new(&panel.y_label, Point::new(area.left + 6, y1 - 8), black).draw(self);

            for (i, (_, points)) in panel.lines.iter().enumerate() {
                let style = PrimitiveStyle::with_stroke(COLORS[i % COLORS.len()], 2);
                let pixels = points.iter().map(|&(x, y)| {
                    (x.is_finite() && y.is_finite()).then(|| Point::new(px(x), py(y)))
                });
                draw_polyline(self, pixels, style);
            }
            let labels: Vec<&str> = panel.lines.iter().map(|(l, _)| l.as_str()).collect();
            draw_legend(self, Point::new(x1 - 6, y1 + 6), &labels);
        }

        let _ = Text::with_alignment(
            x_label,
            Point::new((x0 + x1) / 2, bottom + 34),
            black,
            Alignment::Center,
        )
        .draw(self);
    }

    /// `lines` in the plane, at the same scale on both axes (a circle stays a circle), centred
    /// in `area`'s frame with 5 % of room; each line's first point marked with a dot. Returns
    /// the scale, so a caller (a test) can find a data point's pixel.
    pub fn path(
        &mut self,
        area: Area,
        title: &str,
        (x_label, y_label): (&str, &str),
        lines: &[PathLine],
    ) -> PathScale {
        let (x0, x1, y0, y1) = area.frame();
        let finite = |&&(x, y): &&(f64, f64)| x.is_finite() && y.is_finite();
        let pts = || lines.iter().flat_map(|l| l.points.iter().filter(finite));
        let (xlo, xhi) = widen_or_unit(min_max(pts().map(|p| p.0)));
        let (ylo, yhi) = widen_or_unit(min_max(pts().map(|p| p.1)));
        let (w, h) = (f64::from(x1 - x0), f64::from(y0 - y1));
        let scale = (w / ((xhi - xlo) * 1.1)).min(h / ((yhi - ylo) * 1.1));
        let ps = PathScale {
            px_per_unit: scale,
            origin: ((xlo + xhi) / 2.0, (ylo + yhi) / 2.0),
            origin_px: ((x0 + x1) / 2, (y0 + y1) / 2),
        };
        // The data range the frame shows, for the ticks.
        let (dx, dy) = (w / 2.0 / scale, h / 2.0 / scale);
        let (cx, cy) = ps.origin;
        let xstep = nice_step(2.0 * dx, ((x1 - x0) / 70).clamp(2, 10) as f64);
        draw_x_ticks(
            self,
            (y0, y1),
            cx - dx,
            cx + dx,
            xstep,
            |x| ps.pixel(x, cy).0,
            true,
        );
        let n = ((y0 - y1) / 35).clamp(3, 10);
        let ystep = nice_step(2.0 * dy, f64::from(n)).max(xstep);
        draw_y_ticks_at(self, (x0, x1), cy - dy, cy + dy, ystep, |y| {
            ps.pixel(cx, y).1
        });
        self.decorate(area, &format!("{title}   (vertical: {y_label})"), x_label);
        for (i, line) in lines.iter().enumerate() {
            let color = COLORS[i % COLORS.len()];
            let style = PrimitiveStyle::with_stroke(color, line.width.max(1));
            let pixels = line.points.iter().map(|&(x, y)| {
                (x.is_finite() && y.is_finite()).then(|| {
                    let (a, b) = ps.pixel(x, y);
                    Point::new(a, b)
                })
            });
            draw_polyline(self, pixels, style);
            if let Some(&(x, y)) = line.points.iter().find(|p| finite(p)) {
                let (a, b) = ps.pixel(x, y);
                let _ = Circle::with_center(Point::new(a, b), 7 + line.width)
                    .into_styled(PrimitiveStyle::with_stroke(color, 1))
                    .draw(self);
            }
        }
        // The legend above the frame, on the title's line: inside, it would hide a path
        // that fills the frame.
        let labels: Vec<&str> = lines.iter().map(|l| l.label.as_str()).collect();
        draw_legend_row(self, Point::new(x1, y1 - 8), &labels);
        ps
    }

    /// Histograms with a log x axis (`x_label`, decades) and sample counts on a log y axis:
    /// one step line per series over its bins, a bin without samples at the bottom. Made for
    /// latency histograms whose bins widen with the value (a fixed number per octave), which
    /// have the same width on a log axis.
    pub fn log_histogram(&mut self, area: Area, title: &str, x_label: &str, series: &[Histogram]) {
        let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
        let grid = PrimitiveStyle::with_stroke(Rgb888::new(225, 225, 225), 1);
        let (x0, x1, y0, y1) = area.frame();
        let used = || {
            series
                .iter()
                .flat_map(|s| s.bins.iter())
                .filter(|b| b.count > 0 && b.lo.is_finite() && b.hi.is_finite() && b.hi > 0.0)
        };
        let (lo, _) = min_max(used().map(|b| b.lo.max(b.hi * 1e-3)));
        let (_, hi) = min_max(used().map(|b| b.hi));
        let (dlo, dhi) = if lo.is_finite() && hi.is_finite() {
            let a = lo.log10().floor();
            (a, hi.log10().ceil().max(a + 1.0))
        } else {
            (0.0, 3.0)
        };
        let px = |v: f64| {
            let l = if v > 0.0 { v.log10() } else { dlo };
            x0 + ((l.clamp(dlo, dhi) - dlo) / (dhi - dlo) * f64::from(x1 - x0)).round() as i32
        };
        let cmax = used().map(|b| b.count).max().unwrap_or(1).max(1);
        let decades = (cmax as f64).log10().ceil().max(1.0);
        let py = log_count_scale(decades, y0, y1);
        self.count_ticks(decades, (x0, x1), &py);
        for d in dlo as i32..=dhi as i32 {
            for m in [1.0, 2.0, 5.0] {
                let v = m * 10f64.powi(d);
                if v.log10() > dhi + 1e-9 {
                    break;
                }
                let x = px(v);
                let _ = Line::new(Point::new(x, y0), Point::new(x, y1))
                    .into_styled(grid)
                    .draw(self);
                if m == 1.0 || dhi - dlo <= 3.0 {
                    let label = tick_label(v, 10f64.powi(d));
                    let _ = Text::with_alignment(
                        &label,
                        Point::new(x, y0 + 14),
                        black,
                        Alignment::Center,
                    )
                    .draw(self);
                }
            }
        }
        self.decorate(
            area,
            &format!("{title}   (vertical: samples, log)"),
            x_label,
        );
        for (k, s) in series.iter().enumerate() {
            let style = PrimitiveStyle::with_stroke(COLORS[k % COLORS.len()], 2);
            let floor = py(0);
            let mut prev: Option<(f64, Point)> = None;
            for b in &s.bins {
                if !(b.lo.is_finite() && b.hi.is_finite()) {
                    continue;
                }
                let (xa, xb, y) = (px(b.lo), px(b.hi), py(b.count));
                let from = match prev {
                    // Contiguous with the previous bin: a vertical step.
                    Some((end, p)) if (b.lo - end).abs() <= 1e-9 * b.lo.abs().max(1.0) => p,
                    // A gap: the previous bin falls to the floor, this one rises from it.
                    Some((_, p)) => {
                        let _ = Line::new(p, Point::new(p.x, floor))
                            .into_styled(style)
                            .draw(self);
                        let _ = Line::new(Point::new(p.x, floor), Point::new(xa, floor))
                            .into_styled(style)
                            .draw(self);
                        Point::new(xa, floor)
                    }
                    None => Point::new(xa, floor),
                };
                let _ = Line::new(from, Point::new(xa, y))
                    .into_styled(style)
                    .draw(self);
                let _ = Line::new(Point::new(xa, y), Point::new(xb, y))
                    .into_styled(style)
                    .draw(self);
                prev = Some((b.hi, Point::new(xb, y)));
            }
            if let Some((_, p)) = prev {
                let _ = Line::new(p, Point::new(p.x, floor))
                    .into_styled(style)
                    .draw(self);
            }
        }
        let labels: Vec<&str> = series.iter().map(|s| s.label.as_str()).collect();
        draw_legend(self, Point::new(x1 - 6, y1 + 6), &labels);
    }
}

/// The y pixel of a sample count on a log axis of `decades` decades from `y0` (bottom) to
/// `y1` (top); the bottom is half a sample, so a single sample stands above it.
fn log_count_scale(decades: f64, y0: i32, y1: i32) -> impl Fn(u64) -> i32 {
    let bottom = -0.3;
    move |count: u64| {
        let v = if count == 0 {
            bottom
        } else {
            (count as f64).log10()
        };
        y0 - (((v - bottom) / (decades - bottom)) * f64::from(y0 - y1)).round() as i32
    }
}

/// `lo..hi` as [`widen`] makes it, but a range of ±0.5 around a single value (a path that
/// never moved on an axis is a point, not a line 2 units long).
fn widen_or_unit((lo, hi): (f64, f64)) -> (f64, f64) {
    if lo.is_finite() && hi.is_finite() && hi - lo <= 0.0 {
        (lo - 0.5, lo + 0.5)
    } else {
        widen(lo, hi)
    }
}

/// One panel of [`series_png`]: a y-axis label and its lines (label, points (x, y)).
#[derive(Clone, Debug, Default)]
pub struct Panel {
    pub y_label: String,
    pub lines: Vec<(String, Vec<(f64, f64)>)>,
}

/// Vertical room between stacked panels, for the next panel's y label.
const PANEL_GAP: i32 = 26;

/// The vertical grid lines of a panel spanning `y0` (bottom) to `y1` (top), at multiples of
/// `step` within `lo..=hi`, and their labels under the panel if it is the `last` one.
fn draw_x_ticks(
    c: &mut Figure,
    (y0, y1): (i32, i32),
    lo: f64,
    hi: f64,
    step: f64,
    px: impl Fn(f64) -> i32,
    last: bool,
) {
    let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
    let grid = PrimitiveStyle::with_stroke(Rgb888::new(225, 225, 225), 1);
    for t in ticks(lo, hi, step) {
        let x = px(t);
        let _ = Line::new(Point::new(x, y0), Point::new(x, y1))
            .into_styled(grid)
            .draw(c);
        if last {
            let label = tick_label(t, step);
            let _ = Text::with_alignment(&label, Point::new(x, y0 + 14), black, Alignment::Center)
                .draw(c);
        }
    }
}

/// The horizontal grid lines and labels of a panel `h` pixels high spanning `x0` to `x1`, at
/// nice multiples within `lo..=hi` (about one per 35 pixels, at least three).
fn draw_y_ticks(
    c: &mut Figure,
    (x0, x1): (i32, i32),
    lo: f64,
    hi: f64,
    h: i32,
    py: impl Fn(f64) -> i32,
) {
    // A nice step may be up to 2.5 times the asked one: ask for more ticks until 3 fit.
    let mut n = (h / 35).clamp(3, 10);
    let mut step = nice_step(hi - lo, f64::from(n));
    while ticks(lo, hi, step).count() < 3 && n < 20 {
        n += 1;
        step = nice_step(hi - lo, f64::from(n));
    }
    draw_y_ticks_at(c, (x0, x1), lo, hi, step, py);
}

/// The horizontal grid lines and labels at the multiples of `step` within `lo..=hi`.
fn draw_y_ticks_at(
    c: &mut Figure,
    (x0, x1): (i32, i32),
    lo: f64,
    hi: f64,
    step: f64,
    py: impl Fn(f64) -> i32,
) {
    let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
    let grid = PrimitiveStyle::with_stroke(Rgb888::new(225, 225, 225), 1);
    for t in ticks(lo, hi, step) {
        let y = py(t);
        let _ = Line::new(Point::new(x0, y), Point::new(x1, y))
            .into_styled(grid)
            .draw(c);
        let label = tick_label(t, step);
        let _ = Text::with_alignment(&label, Point::new(x0 - 6, y + 3), black, Alignment::Right)
            .draw(c);
    }
}

/// Joins consecutive `points` with lines; a `None` ends the segment, and a lone point between
/// two breaks is still drawn as a dot.
fn draw_polyline(
    c: &mut Figure,
    points: impl Iterator<Item = Option<Point>>,
    style: PrimitiveStyle<Rgb888>,
) {
    let mut prev: Option<Point> = None;
    for p in points {
        match (prev, p) {
            (Some(a), Some(b)) if a == b => continue,
            (Some(a), Some(b)) => {
                let _ = Line::new(a, b).into_styled(style).draw(c);
            }
            (None, Some(b)) => {
                let _ = Line::new(b, b).into_styled(style).draw(c);
            }
            (_, None) => {}
        }
        prev = p;
    }
}

/// The legend of lines labelled `labels` on one row ending at `end` (its text's baseline):
/// a swatch and a label each, in the [`COLORS`] order.
fn draw_legend_row(c: &mut Figure, end: Point, labels: &[&str]) {
    let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
    let width: i32 = labels
        .iter()
        .map(|l| 6 * l.chars().count() as i32 + 40)
        .sum();
    let mut x = end.x - width;
    for (i, label) in labels.iter().enumerate() {
        let style = PrimitiveStyle::with_stroke(COLORS[i % COLORS.len()], 3);
        let _ = Line::new(Point::new(x, end.y - 3), Point::new(x + 25, end.y - 3))
            .into_styled(style)
            .draw(c);
        let _ = Text::new(label, Point::new(x + 30, end.y), black).draw(c);
        x += 6 * label.chars().count() as i32 + 40;
    }
}

/// The size of the legend box of `labels` (pixels).
fn legend_size(labels: &[&str]) -> (i32, i32) {
    let chars = labels.iter().map(|l| l.chars().count()).max().unwrap_or(0);
    (6 * chars as i32 + 45, 14 * labels.len() as i32 + 6)
}

/// The legend of lines labelled `labels` (a colour swatch and the label, in the [`COLORS`]
/// order) on a white box whose top-right corner is `corner`.
fn draw_legend(c: &mut Figure, corner: Point, labels: &[&str]) {
    if labels.is_empty() {
        return;
    }
    let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
    let (w, h) = legend_size(labels);
    let left = corner.x - w;
    let _ = Rectangle::new(Point::new(left, corner.y), Size::new(w as u32, h as u32))
        .into_styled(
            PrimitiveStyleBuilder::new()
                .fill_color(Rgb888::WHITE)
                .stroke_color(Rgb888::new(190, 190, 190))
                .stroke_width(1)
                .build(),
        )
        .draw(c);
    for (i, label) in labels.iter().enumerate() {
        let style = PrimitiveStyle::with_stroke(COLORS[i % COLORS.len()], 2);
        let ly = corner.y + 14 + 14 * i as i32;
        let _ = Line::new(Point::new(left + 8, ly - 3), Point::new(left + 33, ly - 3))
            .into_styled(style)
            .draw(c);
        let _ = Text::new(label, Point::new(left + 40, ly), black).draw(c);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plot_is_a_png_of_the_right_size() {
        let bins: Vec<u64> = (0..100).map(|i| if i < 50 { i * i } else { 0 }).collect();
        let png = png(
            "test",
            &[("timer 0".into(), bins.clone()), ("ipc 0->1".into(), bins)],
        )
        .expect("encodes");
        assert_eq!(&png[1..4], b"PNG");
        let decoder = png::Decoder::new(std::io::Cursor::new(&png));
        let reader = decoder.read_info().expect("decodes");
        assert_eq!((reader.info().width, reader.info().height), (W, H));
    }

    /// Decodes `png` into its width, height and RGB bytes.
    fn decode(png: &[u8]) -> (u32, u32, Vec<u8>) {
        let mut reader = png::Decoder::new(std::io::Cursor::new(png))
            .read_info()
            .expect("decodes");
        let mut buf = vec![0; reader.output_buffer_size().expect("fits")];
        let info = reader.next_frame(&mut buf).expect("a frame");
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf)
    }

    /// A step response: command, measured position, effort.
    fn step_response() -> Vec<Panel> {
        let t: Vec<f64> = (0..400).map(|i| f64::from(i) * 0.0025).collect();
        let cmd = t.iter().map(|&t| (t, if t < 0.1 { 0.0 } else { 12.5 }));
        let pos = t.iter().map(|&t| {
            let s = (t - 0.1).max(0.0) * 40.0;
            (t, 12.5 * (1.0 - (-s).exp() * (s * 1.5).cos()))
        });
        let effort = t.iter().map(|&t| {
            let s = (t - 0.1).max(0.0) * 40.0;
            let u = if t < 0.1 { 0.0 } else { 2000.0 * (-s).exp() };
            (t, u)
        });
        vec![
            Panel {
                y_label: "position (mm)".into(),
                lines: vec![
                    ("command".into(), cmd.collect()),
                    ("measured".into(), pos.collect()),
                ],
            },
            Panel {
                y_label: "effort (mA)".into(),
                lines: vec![("effort".into(), effort.collect())],
            },
        ]
    }

    #[test]
    fn a_series_plot_is_a_png_of_the_right_size() {
        let png = series_png("step", "time (s)", &step_response()).expect("encodes");
        let (w, h, _) = decode(&png);
        assert_eq!((w, h), (W, H));
        let (w, h, _) = decode(&series_png("none", "x", &[]).expect("encodes"));
        assert_eq!((w, h), (W, H));
    }

    #[test]
    fn a_constant_line_is_drawn() {
        let panel = Panel {
            y_label: "constant".into(),
            lines: vec![("c".into(), (0..50).map(|i| (f64::from(i), 3.0)).collect())],
        };
        let (_, _, rgb) = decode(&series_png("flat", "x", &[panel]).expect("encodes"));
        let c = COLORS[0];
        // In the panel, away from the legend: the line's colour somewhere.
        let drawn = (TOP + 1..H as i32 - BOTTOM).any(|y| {
            (LEFT + 1..W as i32 / 2).any(|x| {
                let i = (y as usize * W as usize + x as usize) * 3;
                rgb[i..i + 3] == [c.r(), c.g(), c.b()]
            })
        });
        assert!(drawn);
    }

    #[test]
    fn non_finite_points_are_skipped() {
        let pts = vec![
            (0.0, 1.0),
            (1.0, f64::NAN),
            (f64::INFINITY, 2.0),
            (2.0, 3.0),
            (3.0, f64::NEG_INFINITY),
            (4.0, 0.5),
            (5.0, 1.5),
        ];
        let nan_only = vec![(f64::NAN, f64::NAN)];
        let panels = [
            Panel {
                y_label: "gappy".into(),
                lines: vec![("a".into(), pts), ("nan".into(), nan_only.clone())],
            },
            Panel {
                y_label: "nothing finite".into(),
                lines: vec![("nan".into(), nan_only), ("empty".into(), vec![])],
            },
            Panel::default(),
        ];
        let (w, h, _) = decode(&series_png("gaps", "x", &panels).expect("encodes"));
        assert_eq!((w, h), (W, H));
    }

    /// Whether `f` has colour `c` within 1 pixel of `(x, y)`.
    fn has(f: &Figure, (x, y): (i32, i32), c: Rgb888) -> bool {
        (-1..=1).any(|dx| (-1..=1).any(|dy| f.pixel(x + dx, y + dy) == [c.r(), c.g(), c.b()]))
    }

    #[test]
    fn a_path_is_drawn_at_the_same_scale_on_both_axes() {
        // A 100 x 40 rectangle in a square area: its corners where the scale says, and the
        // scale the same on both axes (100 units across are 2.5 times 40 units up).
        let rect = vec![
            (0.0, 0.0),
            (100.0, 0.0),
            (100.0, 40.0),
            (0.0, 40.0),
            (0.0, 0.0),
        ];
        let mut f = Figure::new(500, 500);
        let area = f.below_title();
        let line = PathLine {
            label: "commanded".into(),
            points: rect.clone(),
            width: 3,
        };
        let s = f.path(area, "path", ("x (mm)", "y (mm)"), &[line]);
        for &(x, y) in &rect {
            assert!(has(&f, s.pixel(x, y), COLORS[0]), "corner ({x}, {y})");
        }
        let (a, b, c) = (s.pixel(0.0, 0.0), s.pixel(100.0, 0.0), s.pixel(0.0, 40.0));
        assert_eq!(a.1, b.1);
        assert_eq!(a.0, c.0);
        // Each end within half a pixel of the true place.
        let ratio = f64::from(b.0 - a.0) / f64::from(a.1 - c.1);
        assert!(
            (ratio - 2.5).abs() < 2.5 * 2.0 / f64::from(a.1 - c.1),
            "{ratio}"
        );
        // Inside the frame: the rectangle is 110 % of the frame's width at most.
        let (x0, x1, _, _) = area.frame();
        assert!(a.0 > x0 && b.0 < x1);
        // The middle of the rectangle is not drawn on (a grid line may cross it).
        assert!(!has(&f, ((a.0 + b.0) / 2, (a.1 + c.1) / 2), COLORS[0]));
    }

    #[test]
    fn a_log_histogram_puts_each_bin_at_its_value_and_count() {
        let mut f = Figure::new(800, 400);
        let area = f.below_title();
        let h = Histogram {
            label: "servo".into(),
            bins: vec![
                Bin {
                    lo: 10.0,
                    hi: 20.0,
                    count: 1000,
                },
                Bin {
                    lo: 20.0,
                    hi: 40.0,
                    count: 10,
                },
                // A gap, then one sample far out.
                Bin {
                    lo: 1000.0,
                    hi: 1100.0,
                    count: 1,
                },
            ],
        };
        f.log_histogram(area, "wake-up latency", "\u{b5}s (log)", &[h]);
        let (x0, x1, y0, y1) = area.frame();
        // 10 to 10 000 µs: 3 decades across the frame; counts 1e0..1e3 up it.
        let px = |v: f64| x0 + ((f64::log10(v) - 1.0) / 3.0 * f64::from(x1 - x0)).round() as i32;
        let py = log_count_scale(3.0, y0, y1);
        assert_eq!(py(1000), y1);
        assert!(has(&f, ((px(10.0) + px(20.0)) / 2, py(1000)), COLORS[0]));
        assert!(has(&f, ((px(20.0) + px(40.0)) / 2, py(10)), COLORS[0]));
        assert!(has(&f, ((px(1000.0) + px(1100.0)) / 2, py(1)), COLORS[0]));
        // Between the bins, on the floor; nothing above it.
        let mid = px(200.0);
        assert!(has(&f, (mid, py(0)), COLORS[0]));
        assert!(!has(&f, (mid, py(10)), COLORS[0]));
    }

    #[test]
    fn an_empty_log_histogram_still_draws_its_frame() {
        let mut f = Figure::new(400, 300);
        let area = f.below_title();
        f.log_histogram(area, "none", "x", &[Histogram::default()]);
        let (x0, _, y0, _) = area.frame();
        assert_eq!(f.pixel(x0, y0), [0, 0, 0]);
        assert_eq!(&f.png().expect("encodes")[1..4], b"PNG");
    }

    #[test]
    fn nice_steps_are_round_at_any_scale() {
        assert_eq!(nice_step(0.003, 10.0), 0.0005);
        assert_eq!(nice_step(1.0, 10.0), 0.1);
        assert_eq!(nice_step(37.0, 10.0), 5.0);
        assert_eq!(nice_step(2500.0, 10.0), 500.0);
        for span in [0.003, 1.0, 37.0, 2500.0, 1e-7, 123_456.0] {
            for n in [2.0, 3.0, 5.0, 10.0] {
                let s = nice_step(span, n);
                let m = s / 10f64.powf(s.log10().floor());
                assert!(
                    [1.0, 2.0, 5.0].iter().any(|r| (m - r).abs() < 1e-9),
                    "{span}/{n} -> {s}"
                );
                assert!(
                    s >= span / n && s < span / n * 5.0 + 1e-12,
                    "{span}/{n} -> {s}"
                );
            }
        }
        assert_eq!(nice_step(0.0, 10.0), 1.0);
        assert_eq!(nice_step(f64::NAN, 10.0), 1.0);
    }

    #[test]
    fn tick_labels_have_the_decimals_the_step_needs() {
        assert_eq!(tick_label(0.0005, 0.0005), "0.0005");
        assert_eq!(tick_label(12.5, 0.5), "12.5");
        assert_eq!(tick_label(2000.0, 500.0), "2000");
        assert_eq!(tick_label(-0.2, 0.2), "-0.2");
        assert_eq!(tick_label(0.30000000000000004, 0.1), "0.3");
        assert_eq!(tick_label(2e-8, 1e-8), "2e-8");
        assert_eq!(tick_label(2.5e9, 5e8), "2.5e9");
    }

    /// Writes a demo plot to look at: `cargo test -p plot -- --ignored`.
    #[test]
    #[ignore]
    fn write_series_demo() {
        let png =
            series_png("step response, axis 0", "time (s)", &step_response()).expect("encodes");
        let path = std::env::temp_dir().join("series_demo.png");
        std::fs::write(&path, png).expect("writes");
        eprintln!("wrote {}", path.display());
    }

    #[test]
    fn ticks_are_round_numbers() {
        assert_eq!(tick_step(100.0, 10.0), 10.0);
        assert_eq!(tick_step(1000.0, 10.0), 100.0);
        assert_eq!(tick_step(35.0, 10.0), 5.0);
        assert_eq!(tick_step(3.0, 10.0), 1.0);
    }
}
