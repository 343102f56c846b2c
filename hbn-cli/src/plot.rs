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

/// One filter mode's estimate to plot.
pub struct ModeSeries<'a> {
    /// Legend label (the mode's name, marked when it is the model's default).
    pub label: String,
    /// Estimate.
    pub x: &'a [f64],
    /// Its standard deviation (the band is `x +- 2 x_std`).
    pub x_std: &'a [f64],
    /// nRMSE against the reference.
    pub nrmse: f64,
    /// Share of samples whose reference lies inside the band.
    pub coverage_2sigma: f64,
}

/// Data of the evaluation plot.
pub struct EvalPlot<'a> {
    /// Title: what is compared with what.
    pub title: String,
    /// Time (s).
    pub t: &'a [f64],
    /// Input.
    pub u: &'a [f64],
    /// Reference state.
    pub x_ref: &'a [f64],
    /// Sensor output.
    pub y: &'a [f64],
    /// Axis label of the input (signal name, path, unit).
    pub input_label: String,
    /// Axis label of the state.
    pub state_label: String,
    /// Axis label of the sensor output.
    pub output_label: String,
    /// One panel per mode, in order.
    pub modes: Vec<ModeSeries<'a>>,
    /// The mode the hysteresis loops show (an index into `modes`).
    pub loops_mode: usize,
    /// The open-loop GP simulation (its own panel).
    pub open_loop: &'a [f64],
    /// Its nRMSE.
    pub open_loop_nrmse: f64,
}

/// Colours of the modes (tab10 without grey), in order; the open loop is grey.
pub const MODE_COLORS: [RGBColor; 5] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(214, 39, 40),
];

/// Opacity of the 2-sigma bands.
pub const BAND_ALPHA: f64 = 0.3;

const OPEN_LOOP: RGBColor = RGBColor(127, 127, 127);

/// Colour of mode `i`.
pub fn color(i: usize) -> RGBColor {
    MODE_COLORS[i % MODE_COLORS.len()]
}

/// The colour of mode `i`'s band where it lies on white: what the PNG holds there (to within the
/// backend's rounding, a level or two per channel).
pub fn band_pixel(i: usize) -> [u8; 3] {
    let c = color(i);
    let mix = |v: u8| (BAND_ALPHA * f64::from(v) + (1.0 - BAND_ALPHA) * 255.0).round() as u8;
    [mix(c.0), mix(c.1), mix(c.2)]
}

fn legend_line(c: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
}

/// `12.3%`, or `-` when not a number.
fn percent(v: f64) -> String {
    if v.is_finite() {
        format!("{:.1}%", 100.0 * v)
    } else {
        "-".to_owned()
    }
}

/// One entry of a panel's legend.
pub enum LegendEntry {
    /// A line of a colour.
    Line(RGBColor, String),
    /// A shaded band of a colour.
    Band(RGBColor, String),
    /// Text alone.
    Text(String),
}

impl LegendEntry {
    /// The entry's text.
    pub fn text(&self) -> &str {
        match self {
            LegendEntry::Line(_, t) | LegendEntry::Band(_, t) | LegendEntry::Text(t) => t,
        }
    }
}

/// The legend of mode `i`'s panel: reference, estimate with its nRMSE, band with its coverage.
pub fn mode_legend(d: &EvalPlot<'_>, i: usize) -> Vec<LegendEntry> {
    let Some(m) = d.modes.get(i) else {
        return Vec::new();
    };
    let c = color(i);
    vec![
        LegendEntry::Line(BLACK, format!("logged {}", d.state_label)),
        LegendEntry::Line(c, format!("{} estimate", m.label)),
        LegendEntry::Text(format!("    nRMSE {:.4}", m.nrmse)),
        LegendEntry::Band(c, "\u{b1}2\u{3c3} band (2 standard deviations)".to_owned()),
        LegendEntry::Text(format!(
            "    holds the logged value {}",
            percent(m.coverage_2sigma)
        )),
        LegendEntry::Text("    of the time (95% if honest)".to_owned()),
    ]
}

/// The legend of the open-loop panel.
pub fn open_loop_legend(d: &EvalPlot<'_>) -> Vec<LegendEntry> {
    vec![
        LegendEntry::Line(BLACK, format!("logged {}", d.state_label)),
        LegendEntry::Line(OPEN_LOOP, "open-loop GP (no sensor)".to_owned()),
        LegendEntry::Text(format!("    nRMSE {:.4}", d.open_loop_nrmse)),
    ]
}

fn draw_legend(area: &Area<'_>, entries: &[LegendEntry]) -> anyhow::Result<()> {
    let font = ("sans-serif", 16).into_font();
    let mut y = 34;
    for e in entries {
        match e {
            LegendEntry::Line(c, _) => area
                .draw(&PathElement::new(vec![(8, y), (36, y)], c.stroke_width(3)))
                .map_err(pe)?,
            LegendEntry::Band(c, _) => area
                .draw(&Rectangle::new(
                    [(8, y - 7), (36, y + 7)],
                    c.mix(BAND_ALPHA).filled(),
                ))
                .map_err(pe)?,
            LegendEntry::Text(_) => {}
        }
        let x = if matches!(e, LegendEntry::Text(_)) {
            8
        } else {
            44
        };
        area.draw(&Text::new(e.text().to_owned(), (x, y - 9), font.clone()))
            .map_err(pe)?;
        y += 24;
    }
    Ok(())
}

/// Panel height of each time series (pixels).
const PANEL_H: u32 = 250;
/// Height of the hysteresis-loop row.
const LOOPS_H: u32 = 460;
/// Width of the plot and of each panel's legend column.
const WIDTH: u32 = 1500;
const LEGEND_W: u32 = 380;

/// One time panel: the reference, a line and optionally its 2-sigma band.
fn time_panel(
    area: &Area<'_>,
    d: &EvalPlot<'_>,
    (x, std, col): (&[f64], Option<&[f64]>, RGBColor),
    legend: &[LegendEntry],
) -> anyhow::Result<()> {
    let (chart_area, legend_area) = area.split_horizontally(WIDTH - LEGEND_W);
    let mut all: Vec<f64> = d.x_ref.to_vec();
    all.extend_from_slice(x);
    if let Some(sd) = std {
        all.extend(x.iter().zip(sd).map(|(x, s)| x + 2.0 * s));
        all.extend(x.iter().zip(sd).map(|(x, s)| x - 2.0 * s));
    }
    let mut c = ChartBuilder::on(&chart_area)
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(range(d.t), range(&all))
        .map_err(pe)?;
    c.configure_mesh()
        .x_desc("time [s]")
        .y_desc(d.state_label.as_str())
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 16))
        .draw()
        .map_err(pe)?;
    if let Some(sd) = std {
        // The band: upper edge forwards, lower edge backwards, as one filled polygon (split
        // where a value is not finite).
        let finite = |k: usize| x[k].is_finite() && sd[k].is_finite();
        let mut k = 0;
        while k < d.t.len().min(x.len()).min(sd.len()) {
            if !finite(k) {
                k += 1;
                continue;
            }
            let start = k;
            while k < d.t.len().min(x.len()).min(sd.len()) && finite(k) {
                k += 1;
            }
            let mut pts: Vec<(f64, f64)> =
                (start..k).map(|j| (d.t[j], x[j] + 2.0 * sd[j])).collect();
            pts.extend((start..k).rev().map(|j| (d.t[j], x[j] - 2.0 * sd[j])));
            c.draw_series(std::iter::once(Polygon::new(
                pts,
                col.mix(BAND_ALPHA).filled(),
            )))
            .map_err(pe)?;
        }
    }
    // The estimate under the reference, so that the reference is seen where it leaves the band.
    c.draw_series(LineSeries::new(
        d.t.iter().zip(x).map(|(&t, &x)| (t, x)),
        col.stroke_width(2),
    ))
    .map_err(pe)?;
    c.draw_series(LineSeries::new(
        d.t.iter().zip(d.x_ref).map(|(&t, &x)| (t, x)),
        BLACK.stroke_width(1),
    ))
    .map_err(pe)?;
    draw_legend(&legend_area, legend)
}

/// The plot's size for `modes` modes.
pub fn eval_plot_size(modes: usize) -> (u32, u32) {
    (WIDTH, 50 + (modes as u32 + 1) * PANEL_H + LOOPS_H)
}

/// One panel per mode: the logged state, the mode's estimate and its 2-sigma band against
/// time, the legend with the nRMSE and the share of samples inside the band; a panel of the
/// open-loop GP; then the hysteresis loops x vs u and y vs x (reference and the mode
/// `loops_mode`).
pub fn eval_plot(file: &Path, d: &EvalPlot<'_>) -> anyhow::Result<()> {
    let size = eval_plot_size(d.modes.len());
    render_png(file, size, |root| {
        let root = root.titled(&d.title, ("sans-serif", 22)).map_err(pe)?;
        let (series, loops) = root.split_vertically((d.modes.len() as u32 + 1) * PANEL_H);
        let panels = series.split_evenly((d.modes.len() + 1, 1));
        for (i, (m, area)) in d.modes.iter().zip(&panels).enumerate() {
            time_panel(area, d, (m.x, Some(m.x_std), color(i)), &mode_legend(d, i))?;
        }
        if let Some(area) = panels.last() {
            time_panel(
                area,
                d,
                (d.open_loop, None, OPEN_LOOP),
                &open_loop_legend(d),
            )?;
        }

        let (bl, br) = loops.split_horizontally(WIDTH / 2);
        let first = d.modes.get(d.loops_mode);
        let col = color(d.loops_mode);
        let mut xs: Vec<f64> = d.x_ref.to_vec();
        if let Some(s) = first {
            xs.extend_from_slice(s.x);
        }
        loop_panel(
            &bl,
            (
                "actuator hysteresis: state vs input",
                d.input_label.as_str(),
                d.state_label.as_str(),
            ),
            (range(d.u), range(&xs)),
            ("logged", d.u, d.x_ref),
            first.map(|s| (format!("{} estimate", s.label), d.u, s.x, col)),
        )?;
        loop_panel(
            &br,
            (
                "sensor hysteresis: sensor vs state",
                d.state_label.as_str(),
                d.output_label.as_str(),
            ),
            (range(&xs), range(d.y)),
            ("logged", d.x_ref, d.y),
            first.map(|s| (format!("{} estimate", s.label), s.x, d.y, col)),
        )?;
        Ok(())
    })
}

/// One panel per component and mode (a vector model): each component's logged values, the
/// mode's estimate and its 2-sigma band against time, with the nRMSE and the share inside the
/// band in the legend.
pub fn components_plot(file: &Path, components: &[EvalPlot<'_>]) -> anyhow::Result<()> {
    let rows: usize = components.iter().map(|c| c.modes.len()).sum();
    let size = (WIDTH, 50 + rows.max(1) as u32 * PANEL_H);
    let title = components
        .first()
        .map(|c| {
            c.title
                .split(": state component")
                .next()
                .unwrap_or("")
                .to_owned()
        })
        .unwrap_or_default();
    render_png(file, size, |root| {
        let root = root.titled(&title, ("sans-serif", 22)).map_err(pe)?;
        let panels = root.split_evenly((rows.max(1), 1));
        let mut next = panels.iter();
        for c in components {
            for (i, m) in c.modes.iter().enumerate() {
                let Some(area) = next.next() else { break };
                let mut legend = mode_legend(c, i);
                legend.insert(0, LegendEntry::Text(format!("{} ", c.state_label)));
                time_panel(area, c, (m.x, Some(m.x_std), color(i)), &legend)?;
            }
        }
        Ok(())
    })
}

/// One hysteresis-loop panel: the reference loop in black and, if given, the estimate's.
fn loop_panel(
    area: &Area<'_>,
    (title, x_desc, y_desc): (&str, &str, &str),
    (x_range, y_range): (Range<f64>, Range<f64>),
    (ref_label, ref_x, ref_y): (&str, &[f64], &[f64]),
    estimate: Option<(String, &[f64], &[f64], RGBColor)>,
) -> anyhow::Result<()> {
    let mut c = ChartBuilder::on(area)
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(70)
        .caption(title, ("sans-serif", 18))
        .build_cartesian_2d(x_range, y_range)
        .map_err(pe)?;
    c.configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 16))
        .draw()
        .map_err(pe)?;
    c.draw_series(LineSeries::new(
        ref_x.iter().zip(ref_y).map(|(&a, &b)| (a, b)),
        BLACK.stroke_width(1),
    ))
    .map_err(pe)?
    .label(ref_label)
    .legend(legend_line(BLACK));
    if let Some((label, ex, ey, col)) = estimate {
        c.draw_series(LineSeries::new(
            ex.iter().zip(ey).map(|(&a, &b)| (a, b)),
            col.mix(0.8).stroke_width(2),
        ))
        .map_err(pe)?
        .label(label)
        .legend(legend_line(col));
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
