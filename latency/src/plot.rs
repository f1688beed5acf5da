//! A PNG of the 1-µs histograms: latency on x (µs), sample count on a log scale on y, one
//! step line per series, as the usual cyclictest plots; and a PNG of time series in stacked
//! panels sharing the x axis ([`series_png`]), e.g. a servo's step response.

use embedded_graphics::mono_font::MonoTextStyle;
use embedded_graphics::mono_font::iso_8859_1::FONT_6X10;
use embedded_graphics::pixelcolor::Rgb888;
use embedded_graphics::prelude::*;
use embedded_graphics::primitives::{Line, PrimitiveStyle, PrimitiveStyleBuilder, Rectangle};
use embedded_graphics::text::{Alignment, Text};

const W: u32 = 960;
const H: u32 = 540;
const LEFT: i32 = 70;
const RIGHT: i32 = 20;
const TOP: i32 = 40;
const BOTTOM: i32 = 50;
const COLORS: [Rgb888; 8] = [
    Rgb888::new(31, 119, 180),
    Rgb888::new(255, 127, 14),
    Rgb888::new(44, 160, 44),
    Rgb888::new(214, 39, 40),
    Rgb888::new(148, 103, 189),
    Rgb888::new(140, 86, 75),
    Rgb888::new(227, 119, 194),
    Rgb888::new(127, 127, 127),
];

struct Canvas {
    rgb: Vec<u8>,
}

impl OriginDimensions for Canvas {
    fn size(&self) -> Size {
        Size::new(W, H)
    }
}

impl DrawTarget for Canvas {
    type Color = Rgb888;
    type Error = core::convert::Infallible;

    fn draw_iter<I: IntoIterator<Item = Pixel<Rgb888>>>(
        &mut self,
        pixels: I,
    ) -> Result<(), Self::Error> {
        for Pixel(p, c) in pixels {
            if (0..W as i32).contains(&p.x) && (0..H as i32).contains(&p.y) {
                let i = (p.y as usize * W as usize + p.x as usize) * 3;
                self.rgb[i..i + 3].copy_from_slice(&[c.r(), c.g(), c.b()]);
            }
        }
        Ok(())
    }
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
    let mut c = Canvas::new();
    let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
    let axis = PrimitiveStyle::with_stroke(Rgb888::BLACK, 1);
    let grid = PrimitiveStyle::with_stroke(Rgb888::new(225, 225, 225), 1);
    let (x0, x1, y0, y1) = (LEFT, W as i32 - RIGHT, H as i32 - BOTTOM, TOP);

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
    // The bottom of the y axis is half a sample, so a single sample stands above it.
    let bottom = -0.3;
    let px = |us: f64| x0 + ((us / xmax) * (x1 - x0) as f64).round() as i32;
    let py = |count: u64| {
        let v = if count == 0 {
            bottom
        } else {
            (count as f64).log10()
        };
        y0 - (((v - bottom) / (decades - bottom)) * (y0 - y1) as f64).round() as i32
    };

    // Grid and ticks.
    for d in 0..=decades as i32 {
        let y = py(10u64.pow(d as u32));
        let _ = Line::new(Point::new(x0, y), Point::new(x1, y))
            .into_styled(grid)
            .draw(&mut c);
        let label = format!("1e{d}");
        let _ = Text::with_alignment(&label, Point::new(x0 - 6, y + 3), black, Alignment::Right)
            .draw(&mut c);
    }
    let step = tick_step(xmax, 10.0);
    let mut t = 0.0;
    while t <= xmax {
        let x = px(t);
        let _ = Line::new(Point::new(x, y0), Point::new(x, y1))
            .into_styled(grid)
            .draw(&mut c);
        let _ = Text::with_alignment(
            &format!("{t}"),
            Point::new(x, y0 + 14),
            black,
            Alignment::Center,
        )
        .draw(&mut c);
        t += step;
    }
    let _ = Rectangle::with_corners(Point::new(x0, y1), Point::new(x1, y0))
        .into_styled(axis)
        .draw(&mut c);
    let _ = Text::with_alignment(
        "latency (\u{b5}s, 1-\u{b5}s bins)",
        Point::new((x0 + x1) / 2, y0 + 34),
        black,
        Alignment::Center,
    )
    .draw(&mut c);
    let _ = Text::new("samples (log)", Point::new(6, y1 - 10), black).draw(&mut c);
    let _ = Text::with_alignment(
        title,
        Point::new((x0 + x1) / 2, 18),
        black,
        Alignment::Center,
    )
    .draw(&mut c);

    // One step line per series; the legend in the top right corner.
    for (k, (label, bins)) in series.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let style = PrimitiveStyle::with_stroke(color, 2);
        let mut prev = Point::new(px(0.0), py(0));
        for (i, &v) in bins.iter().enumerate().take(last + 2) {
            let (xa, xb, y) = (px(i as f64), px(i as f64 + 1.0), py(v));
            let _ = Line::new(prev, Point::new(xa, y))
                .into_styled(style)
                .draw(&mut c);
            let _ = Line::new(Point::new(xa, y), Point::new(xb, y))
                .into_styled(style)
                .draw(&mut c);
            prev = Point::new(xb, y);
        }
        let ly = y1 + 14 + 14 * k as i32;
        let _ = Line::new(Point::new(x1 - 170, ly - 3), Point::new(x1 - 145, ly - 3))
            .into_styled(style)
            .draw(&mut c);
        let _ = Text::new(label, Point::new(x1 - 138, ly), black).draw(&mut c);
    }

    c.encode()
}

impl Canvas {
    /// A white canvas.
    fn new() -> Self {
        Canvas {
            rgb: vec![255; (W * H * 3) as usize],
        }
    }

    /// Encodes the canvas as an 8-bit RGB PNG.
    fn encode(&self) -> Result<Vec<u8>, String> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, W, H);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().map_err(|e| e.to_string())?;
            w.write_image_data(&self.rgb).map_err(|e| e.to_string())?;
        }
        Ok(out)
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

/// Draws `panels` stacked vertically, sharing the x axis (`x_label`), under `title`; encodes a
/// PNG (same size W×H as [`png`]). Each panel has its own y range (min..max over its lines,
/// padded 5 %, a degenerate range widened to ±1 around the value), "nice" ticks on both axes
/// with labels (x labels under the bottom panel only), a light grid, a frame, its y label above
/// it, a legend in its top-right corner, and one polyline per line in the [`COLORS`] order.
/// Points with a non-finite coordinate break the line (a new segment starts after them).
/// Errors only if encoding fails.
pub fn series_png(title: &str, x_label: &str, panels: &[Panel]) -> Result<Vec<u8>, String> {
    let mut c = Canvas::new();
    let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
    let (x0, x1) = (LEFT, W as i32 - RIGHT);
    let bottom = H as i32 - BOTTOM;

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
    let xstep = nice_step(xhi - xlo, 10.0);

    let n = panels.len().max(1) as i32;
    let h = ((bottom - TOP - PANEL_GAP * (n - 1)) / n).max(1);
    for (k, panel) in panels.iter().enumerate() {
        let y1 = TOP + k as i32 * (h + PANEL_GAP);
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
        draw_x_ticks(&mut c, (y0, y1), xlo, xhi, xstep, px, last);
        draw_y_ticks(&mut c, (x0, x1), lo, hi, h, py);
        let _ = Rectangle::with_corners(Point::new(x0, y1), Point::new(x1, y0))
            .into_styled(PrimitiveStyle::with_stroke(Rgb888::BLACK, 1))
            .draw(&mut c);
        let _ = Text::new(&panel.y_label, Point::new(6, y1 - 8), black).draw(&mut c);

        for (i, (_, points)) in panel.lines.iter().enumerate() {
            let style = PrimitiveStyle::with_stroke(COLORS[i % COLORS.len()], 2);
            let pixels = points
                .iter()
                .map(|&(x, y)| (x.is_finite() && y.is_finite()).then(|| Point::new(px(x), py(y))));
            draw_polyline(&mut c, pixels, style);
        }
        draw_legend(&mut c, Point::new(x1 - 6, y1 + 6), &panel.lines);
    }

    let _ = Text::with_alignment(
        x_label,
        Point::new((x0 + x1) / 2, bottom + 34),
        black,
        Alignment::Center,
    )
    .draw(&mut c);
    let _ = Text::with_alignment(
        title,
        Point::new((x0 + x1) / 2, 14),
        black,
        Alignment::Center,
    )
    .draw(&mut c);
    c.encode()
}

/// The vertical grid lines of a panel spanning `y0` (bottom) to `y1` (top), at multiples of
/// `step` within `lo..=hi`, and their labels under the panel if it is the `last` one.
fn draw_x_ticks(
    c: &mut Canvas,
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
    c: &mut Canvas,
    (x0, x1): (i32, i32),
    lo: f64,
    hi: f64,
    h: i32,
    py: impl Fn(f64) -> i32,
) {
    let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
    let grid = PrimitiveStyle::with_stroke(Rgb888::new(225, 225, 225), 1);
    // A nice step may be up to 2.5 times the asked one: ask for more ticks until 3 fit.
    let mut n = (h / 35).clamp(3, 10);
    let mut step = nice_step(hi - lo, f64::from(n));
    while ticks(lo, hi, step).count() < 3 && n < 20 {
        n += 1;
        step = nice_step(hi - lo, f64::from(n));
    }
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
    c: &mut Canvas,
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

/// The legend of `lines` (a colour swatch and the label, in the [`COLORS`] order) on a white
/// box whose top-right corner is `corner`.
fn draw_legend(c: &mut Canvas, corner: Point, lines: &[(String, Vec<(f64, f64)>)]) {
    if lines.is_empty() {
        return;
    }
    let black = MonoTextStyle::new(&FONT_6X10, Rgb888::BLACK);
    let chars = lines
        .iter()
        .map(|(l, _)| l.chars().count())
        .max()
        .unwrap_or(0);
    let (w, h) = (6 * chars as i32 + 45, 14 * lines.len() as i32 + 6);
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
    for (i, (label, _)) in lines.iter().enumerate() {
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

    /// Writes a demo plot to look at: `cargo test -p latency --lib plot -- --ignored`.
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
