//! Plots (PNG) for bench results: a horizontal bar chart (one value per method, the value
//! printed at each bar's end) and a line chart (one line per series, e.g. time against
//! resolution).
//!
//! Drawn with `plotters`' bitmap backend into an RGB buffer (800x500 pixels; bar charts as
//! large as their labels need), then saved
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
    render_sized(path, (WIDTH, HEIGHT), draw)
}

/// [`render`] into a buffer of `size` pixels.
fn render_sized(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> std::result::Result<(), String>,
) -> Result<()> {
    ensure_font()?;
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE)
            .map_err(|e| e.to_string())
            .and_then(|_| draw(&root))
            .and_then(|_| root.present().map_err(|e| e.to_string()))
            .map_err(|e| Error::Image(format!("{}: plot: {e}", path.display())))?;
    }
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| Error::Image("plot: buffer size".into()))?;
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

/// A horizontal bar chart, one bar per `(label, value)` from top to bottom, the label left
/// of its bar and the value at its end; the value axis is titled `xlabel`. The image is as
/// tall as the bars need (26 pixels each) and as wide as the longest label needs, so that
/// long method specs stay readable (a vertical chart's labels ran into each other).
/// Non-finite values get no bar and the value "n/a".
pub fn bar_chart(path: &Path, title: &str, xlabel: &str, bars: &[(String, f64)]) -> Result<()> {
    if bars.is_empty() {
        return Err(Error::Usage(format!("{}: bar chart needs at least one bar", path.display())));
    }
    let finite = bars.iter().map(|b| b.1).filter(|v| v.is_finite());
    let lo = finite.clone().fold(0.0f64, f64::min);
    let hi = finite.fold(0.0f64, f64::max);
    let (lo, hi) = if lo == hi { (0.0, 1.0) } else { (lo, hi) };
    // Room for the value labels at the bars' ends.
    let span = hi - lo;
    let (x0, x1) = (if lo < 0.0 { lo - 0.15 * span } else { 0.0 }, if hi > 0.0 { hi + 0.15 * span } else { 0.0 });
    let n = bars.len();
    const ROW: u32 = 26;
    // 13-pixel DejaVu Sans averages about 7.5 pixels a character.
    let longest = bars.iter().map(|b| b.0.chars().count()).max().unwrap_or(1) as u32;
    let label_w = (longest * 15 / 2 + 16).clamp(80, 1200);
    let size = (label_w + 560, (100 + ROW * n as u32).max(220));
    render_sized(path, size, |root| {
        let e = |e: &dyn std::fmt::Display| e.to_string();
        // Bar i is centred on y = n-1-i (the first bar on top); asking for n ticks over the
        // span n makes plotters' 1-2-5 tick search settle on step 1, i.e. the bar centres.
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FAMILY, 22))
            .margin(12)
            .x_label_area_size(42)
            .y_label_area_size(label_w)
            .build_cartesian_2d(x0..x1, -0.5..n as f64 - 0.5)
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .disable_y_mesh()
            .x_max_light_lines(2)
            .x_desc(xlabel)
            .x_label_formatter(&|v| fmt_axis(*v))
            .y_labels(n)
            .y_label_style((FAMILY, 13))
            .x_label_style((FAMILY, 13))
            .axis_desc_style((FAMILY, 15))
            .y_label_formatter(&|v| {
                let i = v.round();
                if i >= 0.0 && (v - i).abs() < 1e-6 && (i as usize) < n {
                    bars[n - 1 - i as usize].0.clone()
                } else {
                    String::new()
                }
            })
            .draw()
            .map_err(|x| e(&x))?;
        let fill = RGBColor(70, 110, 180).filled();
        let y = |i: usize| (n - 1 - i) as f64;
        chart
            .draw_series(
                bars.iter()
                    .enumerate()
                    .filter(|(_, b)| b.1.is_finite())
                    .map(|(i, b)| Rectangle::new([(0.0, y(i) - 0.36), (b.1, y(i) + 0.36)], fill)),
            )
            .map_err(|x| e(&x))?;
        chart
            .draw_series(bars.iter().enumerate().map(|(i, b)| {
                let v = if b.1.is_finite() { b.1 } else { 0.0 };
                let (dx, hpos) = if v < 0.0 { (-5, HPos::Right) } else { (5, HPos::Left) };
                let style = TextStyle::from((FAMILY, 13).into_font()).pos(Pos::new(hpos, VPos::Center));
                EmptyElement::at((v, y(i))) + Text::new(fmt_value(b.1), (dx, 0), style)
            }))
            .map_err(|x| e(&x))?;
        Ok(())
    })
}

/// A scatter chart of labelled points `(group, label, x, y)`: one colour per group (as named
/// in the legend, outside the plot area, below it), each point's label beside it. For
/// measurements that are not a curve (one point per method): joining them by lines would
/// suggest a trade-off that is not there. Non-finite points are skipped.
pub fn scatter_chart(path: &Path, title: &str, xlabel: &str, ylabel: &str, points: &[(String, String, f64, f64)]) -> Result<()> {
    let pts: Vec<&(String, String, f64, f64)> = points.iter().filter(|p| p.2.is_finite() && p.3.is_finite()).collect();
    if pts.is_empty() {
        return Err(Error::Usage(format!("{}: scatter chart needs at least one finite point", path.display())));
    }
    let mut groups: Vec<&str> = Vec::new();
    for p in &pts {
        if !groups.contains(&p.0.as_str()) {
            groups.push(&p.0);
        }
    }
    let lohi = |f: &dyn Fn(&(String, String, f64, f64)) -> f64| {
        (pts.iter().map(|p| f(p)).fold(f64::INFINITY, f64::min), pts.iter().map(|p| f(p)).fold(f64::NEG_INFINITY, f64::max))
    };
    let ((xl, xh), (yl, yh)) = (lohi(&|p| p.2), lohi(&|p| p.3));
    let pad = |lo: f64, hi: f64, left: f64, right: f64| {
        let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
        (lo - left * span, hi + right * span)
    };
    // Times spanning more than a decade go on a log axis (fast methods would otherwise
    // crowd at the left edge); the right margin leaves room for the labels.
    let log_x = xl > 0.0 && xh / xl > 8.0;
    let (x0, x1) = if log_x {
        let (a, b) = pad(xl.ln(), xh.ln(), 0.06, 0.5);
        (a.exp(), b.exp())
    } else {
        pad(xl, xh, 0.06, 0.45)
    };
    let (y0, y1) = pad(yl, yh, 0.06, 0.08);
    let rows = groups.len().div_ceil(4) as u32;
    render_sized(path, (WIDTH, HEIGHT + 22 * rows), |root| {
        let e = |e: &dyn std::fmt::Display| e.to_string();
        let (plot, legend) = root.split_vertically(HEIGHT);
        let mut builder = ChartBuilder::on(&plot);
        builder.caption(title, (FAMILY, 22)).margin(15).x_label_area_size(50).y_label_area_size(70);
        // Pixel positions of the points, for placing their labels apart.
        let px: Vec<(i32, i32)>;
        macro_rules! draw {
            ($chart:expr) => {{
                let mut chart = $chart;
                chart
                    .configure_mesh()
                    .max_light_lines(2)
                    .x_desc(if log_x { format!("{xlabel}, log scale") } else { xlabel.to_string() })
                    .y_desc(ylabel)
                    .x_label_formatter(&|v| fmt_axis(*v))
                    .y_label_formatter(&|v| fmt_axis(*v))
                    .label_style((FAMILY, 14))
                    .axis_desc_style((FAMILY, 16))
                    .draw()
                    .map_err(|x| e(&x))?;
                for (k, g) in groups.iter().enumerate() {
                    let color = Palette99::pick(k).to_rgba();
                    chart
                        .draw_series(pts.iter().filter(|p| p.0 == *g).map(|p| Circle::new((p.2, p.3), 4, color.filled())))
                        .map_err(|x| e(&x))?;
                }
                px = pts.iter().map(|p| chart.backend_coord(&(p.2, p.3))).collect();
            }};
        }
        if log_x {
            draw!(builder.build_cartesian_2d((x0..x1).log_scale(), y0..y1).map_err(|x| e(&x))?);
        } else {
            draw!(builder.build_cartesian_2d(x0..x1, y0..y1).map_err(|x| e(&x))?);
        }
        // Labels right of their points, top to bottom; one that would overlap a label
        // already placed moves down a line.
        let mut order: Vec<usize> = (0..pts.len()).collect();
        order.sort_by_key(|&i| (px[i].1, px[i].0));
        let mut placed: Vec<(i32, i32, i32)> = Vec::new(); // (x0, x1, y) of placed labels
        for i in order {
            let (x, mut y) = (px[i].0 + 7, px[i].1);
            let w = 7 * pts[i].1.chars().count() as i32;
            while placed.iter().any(|&(a, b, py)| (py - y).abs() < 13 && a < x + w && x < b) {
                y += 13;
            }
            placed.push((x, x + w, y));
            let k = groups.iter().position(|g| *g == pts[i].0).unwrap_or(0);
            let color = Palette99::pick(k).to_rgba();
            let style = TextStyle::from((FAMILY, 12).into_font()).color(&color).pos(Pos::new(HPos::Left, VPos::Center));
            plot.draw(&Text::new(pts[i].1.clone(), (x, y), style)).map_err(|x| e(&x))?;
        }
        for (k, g) in groups.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            let (cx, cy) = (80 + 180 * (k % 4) as i32, 8 + 22 * (k / 4) as i32);
            legend.draw(&Circle::new((cx, cy + 6), 5, color.filled())).map_err(|x| e(&x))?;
            legend.draw(&Text::new(g.to_string(), (cx + 10, cy), TextStyle::from((FAMILY, 14).into_font()))).map_err(|x| e(&x))?;
        }
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
