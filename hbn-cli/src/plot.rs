//! PNG plots (plotters, bitmap backend) with an embedded font (DejaVu Sans via `ab_glyph`), so
//! no system font libraries are needed. Rendered in memory, then written with the one atomic
//! writer of hbn-fs.

use std::ops::Range;
use std::path::Path;
use std::sync::OnceLock;

use anyhow::{Context, anyhow};
use image::ImageEncoder;
use plotters::coord::Shift;
use plotters::prelude::*;

/// DejaVu Sans (Bitstream Vera license, see `assets/DejaVuSans-LICENSE.txt`).
static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
static FONT: OnceLock<Result<(), String>> = OnceLock::new();

fn ensure_font() -> anyhow::Result<()> {
    FONT.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT_BYTES)
            .map_err(|_| "the embedded font could not be loaded".to_owned())
    })
    .clone()
    .map_err(|e| anyhow!(e))
}

fn pe<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("plotting failed: {e}")
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// Renders a `size` PNG with `draw` in memory, encodes it, and writes it to `file` with the
/// one atomic writer ([`hbn_fs::write_atomic`]).
pub fn render_png(
    file: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&Area<'_>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    ensure_font()?;
    let (w, h) = size;
    let mut rgb = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        root.fill(&WHITE).map_err(pe)?;
        draw(&root)?;
        root.present()
            .map_err(pe)
            .with_context(|| format!("cannot render `{}`", file.display()))?;
    }
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(&rgb, w, h, image::ColorType::Rgb8)
        .map_err(pe)
        .with_context(|| format!("cannot encode `{}`", file.display()))?;
    hbn_fs::write_atomic(file, &png)?;
    Ok(())
}

/// Finite range of some values, padded by 5% (a unit range when empty or constant).
pub fn range<'a>(values: impl IntoIterator<Item = &'a f64>) -> Range<f64> {
    let (lo, hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return 0.0..1.0;
    }
    let span = hi - lo;
    let pad = if span > 0.0 {
        0.05 * span
    } else {
        0.5 * lo.abs().max(1.0)
    };
    (lo - pad)..(hi + pad)
}

/// One estimate to plot.
pub struct Series<'a> {
    /// Legend label.
    pub label: &'a str,
    /// Estimate.
    pub x: &'a [f64],
    /// Its standard deviation (for the 2-sigma band), if any.
    pub x_std: Option<&'a [f64]>,
}

/// Data of the evaluation plot.
pub struct EvalPlot<'a> {
    /// Title.
    pub title: &'a str,
    /// Time (s).
    pub t: &'a [f64],
    /// Input.
    pub u: &'a [f64],
    /// Reference state.
    pub x_ref: &'a [f64],
    /// Sensor output.
    pub y: &'a [f64],
    /// Estimates; the band is drawn for the first one with `x_std`.
    pub estimates: &'a [Series<'a>],
}

const PALETTE: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(127, 127, 127),
    RGBColor(44, 160, 44),
];

fn color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

fn legend_line(c: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
}

/// Top: reference x, the estimates and the first estimate's 2-sigma band vs time.
/// Bottom: hysteresis loops x vs u and y vs x (reference and first estimate).
pub fn eval_plot(file: &Path, d: &EvalPlot<'_>) -> anyhow::Result<()> {
    render_png(file, (1400, 1000), |root| {
        let root = root.titled(d.title, ("sans-serif", 22)).map_err(pe)?;
        let (top, bottom) = root.split_vertically(520);
        let (bl, br) = bottom.split_horizontally(700);
        let band = d
            .estimates
            .iter()
            .enumerate()
            .find_map(|(i, s)| s.x_std.map(|sd| (i, s, sd)));
        // y range: reference, estimates and band.
        let mut all: Vec<f64> = d.x_ref.to_vec();
        for s in d.estimates {
            all.extend_from_slice(s.x);
        }
        if let Some((_, s, sd)) = band {
            all.extend(s.x.iter().zip(sd).map(|(x, s)| x + 2.0 * s));
            all.extend(s.x.iter().zip(sd).map(|(x, s)| x - 2.0 * s));
        }
        let mut c = ChartBuilder::on(&top)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(range(d.t), range(&all))
            .map_err(pe)?;
        c.configure_mesh()
            .x_desc("t [s]")
            .y_desc("state x")
            .label_style(("sans-serif", 15))
            .draw()
            .map_err(pe)?;
        if let Some((i, s, sd)) = band {
            let col = color(i);
            let mut pts: Vec<(f64, f64)> =
                d.t.iter()
                    .zip(s.x.iter().zip(sd))
                    .map(|(&t, (x, s))| (t, x + 2.0 * s))
                    .collect();
            pts.extend(
                d.t.iter()
                    .zip(s.x.iter().zip(sd))
                    .rev()
                    .map(|(&t, (x, s))| (t, x - 2.0 * s)),
            );
            c.draw_series(std::iter::once(Polygon::new(pts, col.mix(0.2).filled())))
                .map_err(pe)?
                .label(format!("{} +-2 sigma", s.label))
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 20, y + 5)], col.mix(0.2).filled())
                });
        }
        c.draw_series(LineSeries::new(
            d.t.iter().zip(d.x_ref).map(|(&t, &x)| (t, x)),
            BLACK.stroke_width(2),
        ))
        .map_err(pe)?
        .label("reference")
        .legend(legend_line(BLACK));
        for (i, s) in d.estimates.iter().enumerate() {
            let col = color(i);
            c.draw_series(LineSeries::new(
                d.t.iter().zip(s.x).map(|(&t, &x)| (t, x)),
                col.stroke_width(1),
            ))
            .map_err(pe)?
            .label(s.label)
            .legend(legend_line(col));
        }
        c.configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .draw()
            .map_err(pe)?;

        let first = d.estimates.first();
        let mut xs: Vec<f64> = d.x_ref.to_vec();
        if let Some(s) = first {
            xs.extend_from_slice(s.x);
        }
        loop_panel(
            &bl,
            ("actuator hysteresis: x vs u", "input u", "state x"),
            (range(d.u), range(&xs)),
            ("reference", d.u, d.x_ref),
            first.map(|s| (s.label.to_string(), d.u, s.x)),
        )?;
        loop_panel(
            &br,
            ("sensor hysteresis: y vs x", "state x", "sensor y"),
            (range(&xs), range(d.y)),
            ("reference x", d.x_ref, d.y),
            first.map(|s| (format!("{} x", s.label), s.x, d.y)),
        )?;
        Ok(())
    })
}

/// One hysteresis-loop panel: the reference loop in black and, if given, the estimate's.
fn loop_panel(
    area: &Area<'_>,
    (title, x_desc, y_desc): (&str, &str, &str),
    (x_range, y_range): (Range<f64>, Range<f64>),
    (ref_label, ref_x, ref_y): (&str, &[f64], &[f64]),
    estimate: Option<(String, &[f64], &[f64])>,
) -> anyhow::Result<()> {
    let mut c = ChartBuilder::on(area)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .caption(title, ("sans-serif", 18))
        .build_cartesian_2d(x_range, y_range)
        .map_err(pe)?;
    c.configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(pe)?;
    c.draw_series(LineSeries::new(
        ref_x.iter().zip(ref_y).map(|(&a, &b)| (a, b)),
        BLACK.stroke_width(1),
    ))
    .map_err(pe)?
    .label(ref_label)
    .legend(legend_line(BLACK));
    if let Some((label, ex, ey)) = estimate {
        c.draw_series(LineSeries::new(
            ex.iter().zip(ey).map(|(&a, &b)| (a, b)),
            color(0).mix(0.8).stroke_width(1),
        ))
        .map_err(pe)?
        .label(label)
        .legend(legend_line(color(0)));
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(pe)?;
    Ok(())
}

/// A tick label of a log axis: 3 significant digits, no float noise.
fn log_tick(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    if digits > 6 {
        format!("{v:.2e}")
    } else {
        let s = format!("{v:.digits$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_owned()
        } else {
            s
        }
    }
}

/// One line of the experiment plot: mean nRMSE per noise gain.
pub struct GainLine {
    /// Method label.
    pub label: &'static str,
    /// `(noise gain, mean nRMSE)`, sorted by gain.
    pub points: Vec<(f64, f64)>,
}

/// nRMSE vs noise gain, one panel per system, log-scale y.
pub fn experiment_plot(file: &Path, panels: &[(String, Vec<GainLine>)]) -> anyhow::Result<()> {
    let n = panels.len().max(1) as u32;
    render_png(file, (560 * n, 480), |root| {
        let areas = root.split_evenly((1, n as usize));
        for (area, (system, lines)) in areas.iter().zip(panels) {
            let vals: Vec<f64> = lines
                .iter()
                .flat_map(|l| l.points.iter().map(|p| p.1))
                .filter(|v| v.is_finite() && *v > 0.0)
                .collect();
            let lo = vals.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = vals.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let (lo, hi) = if lo.is_finite() && hi.is_finite() {
                (lo / 1.5, hi * 1.5)
            } else {
                (1e-3, 1.0)
            };
            let gains: Vec<f64> = lines
                .iter()
                .flat_map(|l| l.points.iter().map(|p| p.0))
                .collect();
            let mut c = ChartBuilder::on(area)
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .caption(system, ("sans-serif", 20))
                .build_cartesian_2d(range(&gains), (lo..hi).log_scale())
                .map_err(pe)?;
            c.configure_mesh()
                .x_desc("noise gain")
                .y_desc("nRMSE")
                .y_label_formatter(&|v| log_tick(*v))
                .light_line_style(WHITE)
                .label_style(("sans-serif", 14))
                .draw()
                .map_err(pe)?;
            for (i, l) in lines.iter().enumerate() {
                let col = color(i);
                let pts: Vec<(f64, f64)> = l
                    .points
                    .iter()
                    .copied()
                    .filter(|p| p.1.is_finite() && p.1 > 0.0)
                    .collect();
                c.draw_series(LineSeries::new(pts.clone(), col.stroke_width(2)))
                    .map_err(pe)?
                    .label(l.label)
                    .legend(legend_line(col));
                c.draw_series(pts.into_iter().map(|p| Circle::new(p, 4, col.filled())))
                    .map_err(pe)?;
            }
            c.configure_series_labels()
                .position(SeriesLabelPosition::UpperLeft)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 14))
                .draw()
                .map_err(pe)?;
        }
        Ok(())
    })
}
