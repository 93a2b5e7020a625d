//! Plots (PNG) for bench results: a bar chart (one value per method, the value printed above
//! each bar) and a line chart (one line per series, e.g. time against resolution).
//!
//! Drawn with `plotters`' bitmap backend into an RGB buffer of 800x500 pixels, then saved
//! with `image` through `film::io::write_atomic`, so a failed run leaves no half-written file.
//! Text uses `plotters`' pure-Rust `ab_glyph` renderer rather than its `ttf` feature, which
//! links fontconfig and freetype: the font is a TrueType file loaded once at run time —
//! `$LODTRACE_FONT` if set, else DejaVu Sans (Debian's `fonts-dejavu-core`, installed by
//! `tools/setup`) at the usual places. Without a font the plot functions return an error.

use crate::error::{Error, Result};
use crate::film::io;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

pub const WIDTH: u32 = 800;
pub const HEIGHT: u32 = 500;
const FAMILY: &str = "sans-serif";

/// Where the font is looked for when `$LODTRACE_FONT` is not set.
const FONT_PATHS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf", // Debian, Ubuntu
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",          // Fedora
    "/usr/share/fonts/TTF/DejaVuSans.ttf",             // Arch
    "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
];

/// Registers the font with plotters once per process; later calls return the first outcome.
fn ensure_font() -> Result<()> {
    static FONT: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    FONT.get_or_init(|| {
        let candidates: Vec<PathBuf> = match std::env::var_os("LODTRACE_FONT") {
            Some(p) if !p.is_empty() => vec![PathBuf::from(p)],
            _ => FONT_PATHS.iter().map(PathBuf::from).collect(),
        };
        for p in &candidates {
            let Ok(bytes) = std::fs::read(p) else { continue };
            // plotters keeps `&'static` font data; this is loaded once per process.
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            return plotters::style::register_font(FAMILY, FontStyle::Normal, bytes)
                .map_err(|_| format!("plot: {} is not a usable TrueType font", p.display()));
        }
        let tried: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
        Err(format!(
            "plot: no font found (tried {}); install fonts-dejavu-core (tools/setup) or set LODTRACE_FONT to a .ttf file",
            tried.join(", ")
        ))
    })
    .clone()
    .map_err(Error::Image)
}

/// Draws into an 800x500 RGB buffer with `draw`, then writes it to `path` as PNG, atomically.
fn render(path: &Path, draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> std::result::Result<(), String>) -> Result<()> {
    ensure_font()?;
    let mut buf = vec![0u8; (WIDTH * HEIGHT * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)
            .map_err(|e| e.to_string())
            .and_then(|_| draw(&root))
            .and_then(|_| root.present().map_err(|e| e.to_string()))
            .map_err(|e| Error::Image(format!("{}: plot: {e}", path.display())))?;
    }
    let img = image::RgbImage::from_raw(WIDTH, HEIGHT, buf).ok_or_else(|| Error::Image("plot: buffer size".into()))?;
    io::write_rgb8_png(path, &img)
}

/// Short, readable number for a bar label.
fn fmt_value(v: f64) -> String {
    let a = v.abs();
    if !v.is_finite() {
        "n/a".into()
    } else if a == 0.0 {
        "0".into()
    } else if a >= 1000.0 {
        format!("{v:.0}")
    } else if a >= 100.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else if a >= 0.001 {
        format!("{v:.3}")
    } else {
        format!("{v:.2e}")
    }
}

/// Axis tick label: no trailing zeros ("64", "0.25", "1.5e-5").
pub fn fmt_axis(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e6).contains(&a) {
        return format!("{v:.1e}");
    }
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.to_string()
    }
}

/// A bar chart, one bar per `(label, value)`, the value printed above each bar.
/// Non-finite values get no bar and the label "n/a".
pub fn bar_chart(path: &Path, title: &str, ylabel: &str, bars: &[(String, f64)]) -> Result<()> {
    if bars.is_empty() {
        return Err(Error::Usage(format!("{}: bar chart needs at least one bar", path.display())));
    }
    let finite = bars.iter().map(|b| b.1).filter(|v| v.is_finite());
    let lo = finite.clone().fold(0.0f64, f64::min);
    let hi = finite.fold(0.0f64, f64::max);
    let (lo, hi) = if lo == hi { (0.0, 1.0) } else { (lo, hi) };
    // Head room for the value labels.
    let span = hi - lo;
    let (y0, y1) = (if lo < 0.0 { lo - 0.12 * span } else { 0.0 }, if hi > 0.0 { hi + 0.12 * span } else { 0.0 });
    let n = bars.len() as u32;
    let label_px = if n > 12 {
        11
    } else if n > 6 {
        14
    } else {
        16
    };
    render(path, |root| {
        let e = |e: &dyn std::fmt::Display| e.to_string();
        // Bar i is centred on x = i. Asking for n ticks over the span n makes plotters' 1-2-5
        // tick search settle on step 1, i.e. exactly the bar centres, which get the names.
        // (plotters' segmented/slice coordinates are degenerate for a single bar.)
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FAMILY, 24))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.5..n as f64 - 0.5, y0..y1)
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .y_max_light_lines(2)
            .y_desc(ylabel)
            .y_label_formatter(&|v| fmt_axis(*v))
            .x_labels(n as usize)
            .x_label_style((FAMILY, label_px))
            .y_label_style((FAMILY, 14))
            .axis_desc_style((FAMILY, 16))
            .x_label_formatter(&|v| {
                let i = v.round();
                if i >= 0.0 && (v - i).abs() < 1e-6 {
                    bars.get(i as usize).map(|b| b.0.clone()).unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .draw()
            .map_err(|x| e(&x))?;
        let fill = RGBColor(70, 110, 180).filled();
        chart
            .draw_series(
                bars.iter()
                    .enumerate()
                    .filter(|(_, b)| b.1.is_finite())
                    .map(|(i, b)| Rectangle::new([(i as f64 - 0.4, 0.0), (i as f64 + 0.4, b.1)], fill)),
            )
            .map_err(|x| e(&x))?;
        chart
            .draw_series(bars.iter().enumerate().map(|(i, b)| {
                let v = if b.1.is_finite() { b.1 } else { 0.0 };
                let (dy, vpos) = if v < 0.0 { (4, VPos::Top) } else { (-4, VPos::Bottom) };
                let style = TextStyle::from((FAMILY, 15).into_font()).pos(Pos::new(HPos::Center, vpos));
                EmptyElement::at((i as f64, v)) + Text::new(fmt_value(b.1), (0, dy), style)
            }))
            .map_err(|x| e(&x))?;
        Ok(())
    })
}

/// A line chart, one line (with point markers and a legend entry) per named series.
/// Non-finite points are skipped.
pub fn line_chart(path: &Path, title: &str, xlabel: &str, ylabel: &str, series: &[(String, Vec<(f64, f64)>)]) -> Result<()> {
    line_chart_fmt(path, title, xlabel, ylabel, series, SeriesLabelPosition::UpperLeft, &fmt_axis)
}

/// [`line_chart`] with the legend box at `legend` (where the data leaves room) and the x-axis
/// labels from `xfmt` ([`fmt_axis`], or e.g. x = log₂ n labelled as n for a logarithmic axis).
pub fn line_chart_fmt(
    path: &Path,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    series: &[(String, Vec<(f64, f64)>)],
    legend: SeriesLabelPosition,
    xfmt: &dyn Fn(f64) -> String,
) -> Result<()> {
    let pts = || series.iter().flat_map(|s| s.1.iter()).filter(|p| p.0.is_finite() && p.1.is_finite());
    if pts().next().is_none() {
        return Err(Error::Usage(format!("{}: line chart needs at least one finite point", path.display())));
    }
    let range = |f: fn(&(f64, f64)) -> f64| {
        let lo = pts().map(f).fold(f64::INFINITY, f64::min);
        let hi = pts().map(f).fold(f64::NEG_INFINITY, f64::max);
        let pad = if hi > lo { 0.05 * (hi - lo) } else { lo.abs().max(1.0) * 0.5 };
        (lo - pad, hi + pad)
    };
    let (x0, x1) = range(|p| p.0);
    let (y0, y1) = range(|p| p.1);
    render(path, |root| {
        let e = |e: &dyn std::fmt::Display| e.to_string();
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FAMILY, 24))
            .margin(15)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .max_light_lines(2)
            .x_desc(xlabel)
            .y_desc(ylabel)
            .x_label_formatter(&|v| xfmt(*v))
            .y_label_formatter(&|v| fmt_axis(*v))
            .label_style((FAMILY, 14))
            .axis_desc_style((FAMILY, 16))
            .draw()
            .map_err(|x| e(&x))?;
        for (k, (name, data)) in series.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            let data: Vec<(f64, f64)> = data.iter().copied().filter(|p| p.0.is_finite() && p.1.is_finite()).collect();
            chart
                .draw_series(LineSeries::new(data.clone(), color.stroke_width(2)))
                .map_err(|x| e(&x))?
                .label(name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            chart.draw_series(data.iter().map(|&p| Circle::new(p, 3, color.filled()))).map_err(|x| e(&x))?;
        }
        if series.iter().any(|s| !s.0.is_empty()) {
            chart
                .configure_series_labels()
                .label_font((FAMILY, 14))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(legend)
                .draw()
                .map_err(|x| e(&x))?;
        }
        Ok(())
    })
}
