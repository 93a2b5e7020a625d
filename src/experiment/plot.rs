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
use plotters::coord::combinators::BindKeyPoints;
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

/// The largest font file read (DejaVuSans.ttf is 0.7 MB).
const MAX_FONT_BYTES: u64 = 64 << 20;

/// Registers the font with plotters once per process; later calls return the first outcome.
fn ensure_font() -> Result<()> {
    static FONT: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    FONT.get_or_init(|| {
        let (candidates, from_env): (Vec<PathBuf>, bool) = match std::env::var_os("LODTRACE_FONT") {
            Some(p) if !p.is_empty() => (vec![PathBuf::from(p)], true),
            _ => (FONT_PATHS.iter().map(PathBuf::from).collect(), false),
        };
        for p in &candidates {
            // Only a regular file of a font's size is read: `LODTRACE_FONT=/dev/zero` filled
            // the memory, and a FIFO blocked the run forever (its tables and images already
            // written).
            let Ok(meta) = std::fs::metadata(p) else { continue };
            if !meta.is_file() || meta.len() > MAX_FONT_BYTES {
                if from_env {
                    return Err(format!(
                        "plot: LODTRACE_FONT={} is not a font file (a regular file of at most {} MB)",
                        p.display(),
                        MAX_FONT_BYTES >> 20
                    ));
                }
                continue;
            }
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

/// Fails now, with the error a plot would give later, when no font can be loaded.
pub fn check_font() -> Result<()> {
    ensure_font()
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

/// Axis tick label: no trailing zeros ("64", "0.25", "1.5e-5"). From 10⁴ up, thousands,
/// millions and billions carry a suffix ("950k", "1.05M"): a tests-per-frame axis reads
/// alike on both sides of a million (it mixed "950000" with "1e6"), and neighbouring ticks
/// keep the digits that tell them apart (up to three decimals of the suffix's unit).
pub fn fmt_axis(v: f64) -> String {
    let a = v.abs();
    let trim = |s: String| if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s };
    if (1e4..1e12).contains(&a) {
        let (d, u) = if a >= 1e9 {
            (1e9, "G")
        } else if a >= 1e6 {
            (1e6, "M")
        } else {
            (1e3, "k")
        };
        return format!("{}{u}", trim(format!("{:.3}", v / d)));
    }
    if a != 0.0 && !(1e-3..1e12).contains(&a) {
        let s = format!("{v:.3e}");
        let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
        return format!("{}e{e}", trim(m.to_string()));
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

/// A labelled point of a [`scatter_chart`]: `(group, label, x, y)`.
pub type ScatterPoint = (String, String, f64, f64);

/// A scatter chart of labelled points `(group, label, x, y)`: one colour per group (as named
/// in the legend, outside the plot area, below it), each point's label beside it. For
/// measurements that are not a curve (one point per method): joining them by lines would
/// suggest a trade-off that is not there. Non-finite points are skipped.
pub fn scatter_chart(path: &Path, title: &str, xlabel: &str, ylabel: &str, points: &[ScatterPoint]) -> Result<()> {
    let pts: Vec<&ScatterPoint> = points.iter().filter(|p| p.2.is_finite() && p.3.is_finite()).collect();
    if pts.is_empty() {
        return Err(Error::Usage(format!("{}: scatter chart needs at least one finite point", path.display())));
    }
    let mut groups: Vec<&str> = Vec::new();
    for p in &pts {
        if !groups.contains(&p.0.as_str()) {
            groups.push(&p.0);
        }
    }
    let lohi = |f: &dyn Fn(&ScatterPoint) -> f64| {
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
            // Own ticks, as in `line_chart_fmt`: plotters' crowded 4–9 at the right end of a
            // sub-decade span and left everything below 1 unlabelled (stop 56).
            let ticks = log_ticks(x0, x1);
            draw!(builder.build_cartesian_2d((x0..x1).log_scale().with_key_points(ticks), y0..y1).map_err(|x| e(&x))?);
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

/// Line colours: Tableau 10 (distinct on white; `Palette99`'s third colour, a pale yellow,
/// was unreadable on white), then `Palette99` beyond ten series.
pub fn series_color(k: usize) -> RGBAColor {
    const T10: [(u8, u8, u8); 10] = [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (214, 39, 40),
        (148, 103, 189),
        (140, 86, 75),
        (227, 119, 194),
        (127, 127, 127),
        (188, 189, 34),
        (23, 190, 207),
    ];
    match T10.get(k) {
        Some(&(r, g, b)) => RGBColor(r, g, b).to_rgba(),
        None => Palette99::pick(k).to_rgba(),
    }
}

/// Legend layout below a plot `width` pixels wide: (columns, rows) for `labels`, each column
/// as wide as the longest label needs (about 7.5 pixels a character at 14 px, plus the
/// 30-pixel swatch).
pub fn legend_grid(labels: &[&str], width: u32) -> (u32, u32) {
    if labels.is_empty() {
        return (0, 0);
    }
    let longest = labels.iter().map(|l| l.chars().count()).max().unwrap_or(1) as u32;
    let col = longest * 15 / 2 + 40;
    let cols = ((width.saturating_sub(60)) / col).clamp(1, labels.len() as u32);
    (cols, (labels.len() as u32).div_ceil(cols))
}

/// Ticks of a logarithmic axis over `lo..hi` (both > 0): 1, 2, 5 times the powers of ten,
/// or every power of ten where that gives more than 12.
pub fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return Vec::new();
    }
    let (a, b) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let mults: &[f64] = if 3 * (b - a) > 12 { &[1.0] } else { &[1.0, 2.0, 5.0] };
    (a..=b)
        .flat_map(|k| mults.iter().map(move |m| m * 10f64.powi(k)))
        .filter(|&t| t >= lo * (1.0 - 1e-9) && t <= hi * (1.0 + 1e-9))
        .collect()
}

/// A line chart, one line (with point markers and a legend entry) per named series.
/// Non-finite points are skipped.
pub fn line_chart(path: &Path, title: &str, xlabel: &str, ylabel: &str, series: &[(String, Vec<(f64, f64)>)]) -> Result<()> {
    line_chart_fmt(path, title, xlabel, ylabel, series, false, &fmt_axis, None)
}

/// [`line_chart`] with a logarithmic x axis (`log_x`, positive x only), the x-axis labels from
/// `xfmt` ([`fmt_axis`], or e.g. x = log₂ n labelled as n), and a dashed horizontal line at
/// `hline` = (y, label), e.g. a paper's target. The legend sits below the plot area, never
/// over the curves (inside it, it hid the curves it named); the image stays 800×500.
/// A one-point series (a single measurement) gets a marker in the legend, not a line.
#[allow(clippy::too_many_arguments)]
pub fn line_chart_fmt(
    path: &Path,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    series: &[(String, Vec<(f64, f64)>)],
    log_x: bool,
    xfmt: &dyn Fn(f64) -> String,
    hline: Option<(f64, &str)>,
) -> Result<()> {
    let pts = || series.iter().flat_map(|s| s.1.iter()).filter(|p| p.0.is_finite() && p.1.is_finite() && (!log_x || p.0 > 0.0));
    if pts().next().is_none() {
        return Err(Error::Usage(format!("{}: line chart needs at least one finite point", path.display())));
    }
    let lohi = |f: fn(&(f64, f64)) -> f64| (pts().map(f).fold(f64::INFINITY, f64::min), pts().map(f).fold(f64::NEG_INFINITY, f64::max));
    let pad = |(lo, hi): (f64, f64)| {
        let pad = if hi > lo { 0.05 * (hi - lo) } else { lo.abs().max(1.0) * 0.5 };
        (lo - pad, hi + pad)
    };
    let (x0, x1) = if log_x {
        let (a, b) = pad(lohi(|p| p.0.ln()));
        (a.exp(), b.exp())
    } else {
        pad(lohi(|p| p.0))
    };
    let (mut ylo, mut yhi) = lohi(|p| p.1);
    if let Some((y, _)) = hline.filter(|h| h.0.is_finite()) {
        (ylo, yhi) = (ylo.min(y), yhi.max(y));
    }
    let (y0, y1) = pad((ylo, yhi));
    // Whole-number x (frame indices): at most one label per unit, so a three-frame curve is
    // not labelled at frames 0.2, 0.4, ...
    let x_labels = if !log_x && pts().all(|p| p.0.fract() == 0.0) { ((x1 - x0).floor() as usize + 1).clamp(2, 10) } else { 10 };
    let labels: Vec<&str> = series.iter().map(|s| s.0.as_str()).filter(|l| !l.is_empty()).collect();
    let (cols, rows) = legend_grid(&labels, WIDTH);
    let legend_h = if rows == 0 { 0 } else { 12 + 20 * rows };
    render(path, |root| {
        let e = |e: &dyn std::fmt::Display| e.to_string();
        let (plot, legend) = root.split_vertically(HEIGHT - legend_h);
        let mut builder = ChartBuilder::on(&plot);
        builder.caption(title, (FAMILY, 24)).margin(15).x_label_area_size(50).y_label_area_size(70);
        macro_rules! draw {
            ($chart:expr) => {{
                let mut chart = $chart;
                chart
                    .configure_mesh()
                    .max_light_lines(2)
                    .x_desc(if log_x { format!("{xlabel}, log scale") } else { xlabel.to_string() })
                    .y_desc(ylabel)
                    .x_labels(x_labels)
                    .x_label_formatter(&|v| xfmt(*v))
                    .y_label_formatter(&|v| fmt_axis(*v))
                    .label_style((FAMILY, 14))
                    .axis_desc_style((FAMILY, 16))
                    .draw()
                    .map_err(|x| e(&x))?;
                if let Some((y, label)) = hline.filter(|h| h.0.is_finite()) {
                    let grey = RGBColor(90, 90, 90);
                    let n = 60;
                    let dashes = (0..n).step_by(2).map(|i| {
                        let a =
                            |j: usize| if log_x { x0 * (x1 / x0).powf(j as f64 / n as f64) } else { x0 + (x1 - x0) * j as f64 / n as f64 };
                        PathElement::new(vec![(a(i), y), (a(i + 1), y)], grey.stroke_width(1))
                    });
                    chart.draw_series(dashes).map_err(|x| e(&x))?;
                    let style = TextStyle::from((FAMILY, 13).into_font()).color(&grey).pos(Pos::new(HPos::Left, VPos::Bottom));
                    // Above its line and clear of the y axis: anchored on the line itself, the
                    // dashes struck through the label's descenders and it touched the axis.
                    chart
                        .draw_series(std::iter::once(EmptyElement::at((x0, y)) + Text::new(label.to_string(), (6, -5), style)))
                        .map_err(|x| e(&x))?;
                }
                for (k, (_, data)) in series.iter().enumerate() {
                    let color = series_color(k);
                    let data: Vec<(f64, f64)> =
                        data.iter().copied().filter(|p| p.0.is_finite() && p.1.is_finite() && (!log_x || p.0 > 0.0)).collect();
                    chart.draw_series(LineSeries::new(data.clone(), color.stroke_width(2))).map_err(|x| e(&x))?;
                    chart.draw_series(data.iter().map(|&p| Circle::new(p, 4, color.filled()))).map_err(|x| e(&x))?;
                }
            }};
        }
        if log_x {
            // plotters' own log-axis ticks left everything below 1 unlabelled.
            let ticks = log_ticks(x0, x1);
            draw!(builder.build_cartesian_2d((x0..x1).log_scale().with_key_points(ticks), y0..y1).map_err(|x| e(&x))?);
        } else {
            draw!(builder.build_cartesian_2d(x0..x1, y0..y1).map_err(|x| e(&x))?);
        }
        if let Some(col_w) = (WIDTH - 60).checked_div(cols) {
            let mut k_label = 0u32;
            for (k, (name, data)) in series.iter().enumerate() {
                if name.is_empty() {
                    continue;
                }
                let color = series_color(k);
                let (cx, cy) = (40 + col_w as i32 * (k_label % cols) as i32, 10 + 20 * (k_label / cols) as i32);
                k_label += 1;
                if data.len() == 1 {
                    legend.draw(&Circle::new((cx + 10, cy), 4, color.filled())).map_err(|x| e(&x))?;
                } else {
                    legend.draw(&PathElement::new(vec![(cx, cy), (cx + 20, cy)], color.stroke_width(2))).map_err(|x| e(&x))?;
                }
                let style = TextStyle::from((FAMILY, 14).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
                legend.draw(&Text::new(name.clone(), (cx + 28, cy), style)).map_err(|x| e(&x))?;
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legend_grid_fits_the_labels() {
        assert_eq!(legend_grid(&[], 800), (0, 0));
        assert_eq!(legend_grid(&["a", "b"], 800), (2, 1));
        // Eight raw deforming-sequence specs: one per row would take half the image.
        let long = ["surfel:update=lazy-cache:ordered=0:cache_up=8:frames=8:detail=0.15"; 8];
        assert_eq!(legend_grid(&long, 800), (1, 8));
        let short = ["naive", "lazy", "lazy-cache", "refit", "lazy, unordered", "lazy-cache, unordered, cache 8 up"];
        let (c, r) = legend_grid(&short, 800);
        assert!(c >= 2 && r <= 3, "{c}x{r}");
    }

    /// Tick labels of large and small values keep the digits that tell neighbouring ticks
    /// apart: a tests-per-frame axis ticked every 50,000 read "1.0e6" at both 1,000,000 and
    /// 1,050,000 (`heads-sphere-tests.png` of the demo).
    #[test]
    fn axis_labels_tell_large_ticks_apart() {
        assert_eq!(fmt_axis(1_000_000.0), "1M");
        assert_eq!(fmt_axis(1_050_000.0), "1.05M");
        assert_eq!(fmt_axis(1_100_000.0), "1.1M");
        assert_eq!(fmt_axis(-2_500_000.0), "-2.5M");
        assert_eq!(fmt_axis(1.5e-5), "1.5e-5");
        assert_eq!(fmt_axis(950_000.0), "950k");
        assert_eq!(fmt_axis(12_500.0), "12.5k");
        assert_eq!(fmt_axis(9_000.0), "9000");
        assert_eq!(fmt_axis(3.2e9), "3.2G");
        assert_eq!(fmt_axis(2e13), "2e13");
        assert_eq!(fmt_axis(0.25), "0.25");
        assert_eq!(fmt_axis(0.0), "0");
    }

    /// The legend no longer covers the curves: a series running through the top-left and
    /// top-right corners of the data (where the legend box used to sit) shows there.
    #[test]
    fn legend_leaves_the_curves_visible() {
        let d = std::env::temp_dir().join(format!("lodtrace-plot-legend-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let p = d.join("l.png");
        let series = vec![
            ("top".to_string(), vec![(0.0, 10.0), (5.0, 10.0), (10.0, 10.0)]),
            ("bottom".to_string(), vec![(0.0, 0.0), (10.0, 0.0)]),
            ("a measurement".to_string(), vec![(5.0, 5.0)]),
        ];
        line_chart_fmt(&p, "t", "x", "y", &series, false, &fmt_axis, Some((2.0, "target"))).unwrap();
        let img = image::open(&p).unwrap().into_rgb8();
        assert_eq!(img.dimensions(), (WIDTH, HEIGHT));
        let c = series_color(0).rgb();
        let blue = |x0: u32, x1: u32, y0: u32, y1: u32| {
            (x0..x1).flat_map(|x| (y0..y1).map(move |y| (x, y))).filter(|&(x, y)| img.get_pixel(x, y).0 == [c.0, c.1, c.2]).count()
        };
        // The top line runs at the top of the plot area, across its whole width.
        assert!(blue(90, 250, 40, 120) > 100, "left part hidden");
        assert!(blue(600, 780, 40, 120) > 100, "right part hidden");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn log_ticks_label_below_one() {
        let t = log_ticks(0.16, 9.0);
        assert_eq!(t.len(), 5, "{t:?}");
        for (a, b) in t.iter().zip([0.2, 0.5, 1.0, 2.0, 5.0]) {
            assert!((a - b).abs() < 1e-12, "{t:?}");
        }
        assert_eq!(log_ticks(1.0, 1e9).len(), 10, "powers of ten only over many decades");
        assert!(log_ticks(0.0, 1.0).is_empty());
    }

    #[test]
    fn log_x_chart_draws() {
        let d = std::env::temp_dir().join(format!("lodtrace-plot-log-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let s = vec![("s".to_string(), vec![(0.05, 0.1), (0.5, 0.05), (5.0, 0.02)]), ("p".to_string(), vec![(0.1, 0.09)])];
        line_chart_fmt(&d.join("g.png"), "t", "time (s)", "y", &s, true, &fmt_axis, None).unwrap();
        assert!(d.join("g.png").is_file());
        std::fs::remove_dir_all(&d).unwrap();
    }
}
