//! A PNG of the 1-µs histograms: latency on x (µs), sample count on a log scale on y, one
//! step line per series, as the usual cyclictest plots.

use embedded_graphics::mono_font::MonoTextStyle;
use embedded_graphics::mono_font::iso_8859_1::FONT_6X10;
use embedded_graphics::pixelcolor::Rgb888;
use embedded_graphics::prelude::*;
use embedded_graphics::primitives::{Line, PrimitiveStyle, Rectangle};
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

/// A "nice" tick step (1, 2 or 5 times a power of ten) giving about `n` ticks over `span`.
fn tick_step(span: f64, n: f64) -> f64 {
    let raw = (span / n).max(1.0);
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag)
}

/// Draws the histograms `series` (label, counts per 1-µs bin) under `title` and encodes a PNG.
pub fn png(title: &str, series: &[(String, Vec<u64>)]) -> Result<Vec<u8>, String> {
    let mut c = Canvas {
        rgb: vec![255; (W * H * 3) as usize],
    };
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

    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, W, H);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().map_err(|e| e.to_string())?;
        w.write_image_data(&c.rgb).map_err(|e| e.to_string())?;
    }
    Ok(out)
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

    #[test]
    fn ticks_are_round_numbers() {
        assert_eq!(tick_step(100.0, 10.0), 10.0);
        assert_eq!(tick_step(1000.0, 10.0), 100.0);
        assert_eq!(tick_step(35.0, 10.0), 5.0);
    }
}
