//! Time-series line plots (PNG) and the shared plotting helpers: error type, embedded font, PNG rendering.

use std::error::Error as StdError;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use sph_core::atomic::write_atomic_with;

/// Default plot size in pixels.
pub const PLOT_SIZE: (u32, u32) = (800, 500);

/// Failure to produce a plot or snapshot picture.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// Writing the file failed.
    #[error("cannot write {}: {source}", path.display())]
    File {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    /// Plotters failed while drawing or encoding.
    #[error("cannot draw {}: {message}", path.display())]
    Draw { path: PathBuf, message: String },
    /// The input cannot be drawn (mismatched lengths, empty bounds, too small an image...).
    #[error("invalid input for {}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },
    /// An I/O error with no file attached.
    #[error("plot I/O error: {0}")]
    Io(#[from] io::Error),
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    Line,
    Points,
}

/// One named data series; non-finite points are skipped (and break a line).
#[derive(Debug, Clone)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub style: Style,
}

/// Distinct series colours (Tableau 10).
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Writes an 800x500 PNG line/point plot of `series`, atomically.
///
/// Axis ranges cover the finite data; empty or constant data get a default or padded range.
/// Lines are drawn as a per-pixel-column envelope ([`Envelope`]): however many samples
/// fall in a column, their lowest and highest values appear at their true heights, so a
/// spike of one sample among 100,000 is drawn to its full height. A legend is drawn
/// above the plotting area (never over the data) when there is more than one series.
pub fn plot_series(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<(), PlotError> {
    draw_series_plot(path, title, x_label, y_label, series).map(|_| ())
}

/// Where [`plot_series`] put the data: the axis ranges and the plotting area's first
/// and last pixel column and row (inclusive; `bottom` is where `y.0` lies).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub left: i32,
    pub right: i32,
    pub top: i32,
    pub bottom: i32,
}

impl Frame {
    /// The (fractional) pixel column of `x`: `left` at `x.0`, `right` at `x.1`.
    pub fn column(&self, x: f64) -> f64 {
        let t = (x - self.x.0) / (self.x.1 - self.x.0);
        f64::from(self.left) + t * f64::from(self.right - self.left)
    }

    /// The (fractional) pixel row of `y`: `bottom` at `y.0`, `top` at `y.1`.
    pub fn row(&self, y: f64) -> f64 {
        let t = (y - self.y.0) / (self.y.1 - self.y.0);
        f64::from(self.bottom) - t * f64::from(self.bottom - self.top)
    }
}

/// [`plot_series`], returning where the data went (for the tests that read the
/// drawing back).
pub fn draw_series_plot(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<Frame, PlotError> {
    let finite = || {
        series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
    };
    // Time series end where their data end; a plot with point markers (a study's
    // cases) gets the y axis's 5 % either side, so that a marker at the extremes is
    // drawn whole rather than cut in half by the frame.
    let x_pad = match series.iter().any(|s| s.style == Style::Points) {
        true => 0.05,
        false => 0.0,
    };
    let (x0, x1) = axis_range(finite().map(|p| p.0), x_pad);
    let (y0, y1) = axis_range(finite().map(|p| p.1), 0.05);

    let fs = 15;
    let y_label_w = tick_label_width(y0, y1, fs) + 2 * fs + 10;
    let mut frame = None;

    render_png(path, PLOT_SIZE, |root| {
        let below_title = root
            .margin(15, 15, 15, 15)
            .titled(title, (FONT_FAMILY, 22))?;
        let chart_area = if series.len() > 1 {
            let legend = legend_rows(&below_title, series, fs)?;
            let (legend_area, rest) =
                below_title.split_vertically(legend.len() as u32 * (fs + 8) + 6);
            draw_legend(&legend_area, series, &legend, fs)?;
            rest
        } else {
            below_title
        };
        let mut chart = ChartBuilder::on(&chart_area)
            .x_label_area_size(2 * fs + 25)
            .y_label_area_size(y_label_w)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        let x_fmt = |v: &f64| format_number(*v, x1 - x0);
        let y_fmt = |v: &f64| format_number(*v, y1 - y0);
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .x_label_formatter(&x_fmt)
            .y_label_formatter(&y_fmt)
            .label_style((FONT_FAMILY, fs))
            .axis_desc_style((FONT_FAMILY, fs + 1))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(205, 205, 205))
            .draw()?;

        // The same pixel range plotters maps the axes onto (its mesh and ticks).
        let (xs, ys) = chart.plotting_area().get_pixel_range();
        let f = Frame {
            x: (x0, x1),
            y: (y0, y1),
            left: xs.start,
            right: xs.end - 1,
            top: ys.start,
            bottom: ys.end - 1,
        };
        frame = Some(f);
        for (i, s) in series.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            match s.style {
                Style::Line => {
                    for (c, top, bottom) in Envelope::of(&s.points, &f).spans() {
                        // Two pixels wide, clipped to the plotting area.
                        for x in c..=(c + 1).min(f.right) {
                            for y in top..=bottom {
                                root.draw_pixel((x, y), &color)?;
                            }
                        }
                    }
                }
                Style::Points => {
                    let pts = s
                        .points
                        .iter()
                        .filter(|(x, y)| x.is_finite() && y.is_finite());
                    chart.draw_series(pts.map(|&p| Circle::new(p, 3, color.filled())))?;
                }
            }
        }
        Ok(())
    })?;
    frame.ok_or_else(|| PlotError::Draw {
        path: path.to_path_buf(),
        message: "the plotting area was not laid out".to_owned(),
    })
}

/// A polyline drawn one pixel column at a time: for each column of the plotting area,
/// the highest and lowest row the line passes through in it. A segment is split at
/// the columns' edges (half a pixel either side of a column's centre), so a line
/// crossing many columns stays connected, and every sample lies on its column's span:
/// the drawn extremes are the samples' extremes, to the rounding of one pixel.
/// Non-finite points break the line (a lone finite point is one pixel).
pub struct Envelope {
    left: i32,
    top: i32,
    bottom: i32,
    /// Per column from `left`: (least, greatest) fractional row, if any.
    rows: Vec<Option<(f64, f64)>>,
}

impl Envelope {
    pub fn of(points: &[(f64, f64)], frame: &Frame) -> Self {
        let mut e = Self {
            left: frame.left,
            top: frame.top,
            bottom: frame.bottom,
            rows: vec![None; (frame.right - frame.left + 1).max(0) as usize],
        };
        // Fractional pixel coordinates, held a pixel outside the area at most (data
        // beyond f64's range can fall outside the axis range).
        let (lo_x, hi_x) = (f64::from(frame.left) - 1.0, f64::from(frame.right) + 1.0);
        let (lo_y, hi_y) = (f64::from(frame.top) - 1.0, f64::from(frame.bottom) + 1.0);
        let pixel = |&(x, y): &(f64, f64)| {
            (x.is_finite() && y.is_finite()).then(|| {
                let (c, r) = (frame.column(x), frame.row(y));
                // NaN (an infinite span) goes to the area's edge.
                (
                    if c.is_nan() {
                        lo_x
                    } else {
                        c.clamp(lo_x, hi_x)
                    },
                    if r.is_nan() {
                        hi_y
                    } else {
                        r.clamp(lo_y, hi_y)
                    },
                )
            })
        };
        let mut previous: Option<(f64, f64)> = None;
        for p in points {
            let current = pixel(p);
            match (previous, current) {
                (Some(a), Some(b)) => e.segment(a, b),
                (None, Some(b)) => e.extend(b.0.round(), b.1, b.1),
                _ => {}
            }
            previous = current;
        }
        e
    }

    /// Adds the rows from `r0` to `r1` to column `c` (ignored outside the area).
    fn extend(&mut self, c: f64, r0: f64, r1: f64) {
        let k = c - f64::from(self.left);
        if !(k >= 0.0 && k < self.rows.len() as f64) {
            return;
        }
        let (lo, hi) = (r0.min(r1), r0.max(r1));
        let span = &mut self.rows[k as usize];
        *span = Some(span.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))));
    }

    /// Adds the segment from `a` to `b` (fractional pixel coordinates).
    fn segment(&mut self, a: (f64, f64), b: (f64, f64)) {
        let (a, b) = if a.0 <= b.0 { (a, b) } else { (b, a) };
        let (ca, cb) = (a.0.round(), b.0.round());
        if ca == cb {
            self.extend(ca, a.1, b.1);
            return;
        }
        let slope = (b.1 - a.1) / (b.0 - a.0);
        let at = |x: f64| a.1 + slope * (x - a.0);
        let mut c = ca;
        while c <= cb {
            let (x0, x1) = ((c - 0.5).max(a.0), (c + 0.5).min(b.0));
            // The end points themselves, not the interpolation, at the segment's ends.
            let r0 = if c == ca { a.1 } else { at(x0) };
            let r1 = if c == cb { b.1 } else { at(x1) };
            self.extend(c, r0, r1);
            c += 1.0;
        }
    }

    /// (column, top row, bottom row) of every column the line passes through, rows
    /// rounded to pixels and clipped to the area.
    pub fn spans(&self) -> impl Iterator<Item = (i32, i32, i32)> + '_ {
        self.rows.iter().enumerate().filter_map(move |(k, span)| {
            let (lo, hi) = (*span)?;
            let clip = |r: f64| (r.round() as i32).clamp(self.top, self.bottom);
            Some((self.left + k as i32, clip(lo), clip(hi)))
        })
    }
}

/// Legend entries by row: (index into the series, entry width in pixels).
type LegendRows = Vec<Vec<(usize, i32)>>;

/// The legend's entries laid out in rows that fit the area's width.
fn legend_rows(
    area: &Root<'_>,
    series: &[Series],
    fs: u32,
) -> Result<LegendRows, Box<dyn StdError>> {
    let style = TextStyle::from((FONT_FAMILY, fs).into_font());
    let width = area.dim_in_pixel().0 as i32;
    let mut rows: LegendRows = vec![Vec::new()];
    let mut used = 0;
    for (i, s) in series.iter().enumerate() {
        let (text_w, _) = area.estimate_text_size(&s.name, &style)?;
        let w = LEGEND_SWATCH + 6 + text_w as i32;
        let row = rows.last_mut().expect("a row");
        if !row.is_empty() && used + LEGEND_GAP + w > width {
            rows.push(vec![(i, w)]);
            used = w;
        } else {
            used += if row.is_empty() { w } else { LEGEND_GAP + w };
            row.push((i, w));
        }
    }
    Ok(rows)
}

/// Swatch length and the gap between legend entries [px].
const LEGEND_SWATCH: i32 = 24;
const LEGEND_GAP: i32 = 22;

/// Draws the legend rows centred in `area`: a swatch in the series' colour and style,
/// then its name.
fn draw_legend(
    area: &Root<'_>,
    series: &[Series],
    rows: &LegendRows,
    fs: u32,
) -> Result<(), Box<dyn StdError>> {
    let style =
        TextStyle::from((FONT_FAMILY, fs).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    let width = area.dim_in_pixel().0 as i32;
    for (r, row) in rows.iter().enumerate() {
        let total: i32 = row.iter().map(|e| e.1).sum::<i32>() + LEGEND_GAP * (row.len() as i32 - 1);
        let mut x = ((width - total) / 2).max(0);
        let y = r as i32 * (fs as i32 + 8) + (fs as i32 + 8) / 2 + 3;
        for &(i, w) in row {
            let color = PALETTE[i % PALETTE.len()];
            match series[i].style {
                Style::Line => area.draw(&Rectangle::new(
                    [(x, y - 1), (x + LEGEND_SWATCH - 1, y)],
                    color.filled(),
                ))?,
                Style::Points => {
                    area.draw(&Circle::new((x + LEGEND_SWATCH / 2, y), 3, color.filled()))?
                }
            }
            area.draw_text(&series[i].name, &style, (x + LEGEND_SWATCH + 6, y))?;
            x += w + LEGEND_GAP;
        }
    }
    Ok(())
}

/// Range covering `values` (finite), padded by `pad` of the span; never empty or inverted.
pub fn axis_range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if !(span.is_finite() && span > f64::EPSILON * lo.abs().max(hi.abs()).max(f64::MIN_POSITIVE)) {
        // Constant (or span overflowing): centre the value in a small window.
        let half = if lo == 0.0 {
            1.0
        } else {
            (lo.abs() * 0.1).min(f64::MAX / 4.0)
        };
        let mid = if span.is_finite() { lo } else { 0.0 };
        return (mid - half, mid + half);
    }
    (lo - pad * span, hi + pad * span)
}

/// Formats a tick value for an axis spanning `span`: fixed decimals, or scientific for very large/small magnitudes.
pub fn format_number(v: f64, span: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    let span = if span.is_finite() && span > 0.0 {
        span
    } else {
        v.abs().max(1.0)
    };
    let step = span / 10.0;
    if v.abs() < step * 1e-9 {
        return "0".to_owned();
    }
    let mag = v.abs().max(span);
    let s = if !(1e-3..1e5).contains(&mag) {
        let digits = ((mag / step).log10().ceil() + 1.0).clamp(2.0, 7.0) as usize;
        format!("{:.*e}", digits - 1, v)
    } else {
        let decimals = (-step.log10().floor()).clamp(0.0, 8.0) as usize;
        format!("{v:.decimals$}")
    };
    match s.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| matches!(b, b'0' | b'.')) => rest.to_owned(),
        _ => s,
    }
}

/// Rough pixel width of the widest tick label on an axis from `lo` to `hi`.
pub fn tick_label_width(lo: f64, hi: f64, font_px: u32) -> u32 {
    let chars = (0..=10)
        .map(|i| {
            format_number(lo + (hi - lo) * f64::from(i) / 10.0, hi - lo)
                .chars()
                .count()
        })
        .max()
        .unwrap_or(1);
    (chars as f64 * f64::from(font_px) * 0.62).ceil() as u32 + 8
}

/// Font family name the embedded DejaVu Sans is registered under.
pub const FONT_FAMILY: &str = "sans-serif";

static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// Registers the embedded font with plotters once; later calls return the first outcome.
fn ensure_font() -> bool {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, FONT).is_ok()
    })
}

pub type Root<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// Renders a `size` PNG with `draw` into a temporary file and renames it onto `path`.
pub fn render_png<F>(path: &Path, size: (u32, u32), draw: F) -> Result<(), PlotError>
where
    F: FnOnce(&Root<'_>) -> Result<(), Box<dyn StdError>>,
{
    let draw_error = |message: String| PlotError::Draw {
        path: path.to_path_buf(),
        message,
    };
    if !ensure_font() {
        return Err(draw_error("embedded font could not be loaded".to_owned()));
    }
    write_atomic_with(path, |tmp| {
        let root = BitMapBackend::new(tmp, size).into_drawing_area();
        let drawn = root
            .fill(&WHITE)
            .map_err(Box::<dyn StdError>::from)
            .and_then(|()| draw(&root))
            .and_then(|()| root.present().map_err(Box::<dyn StdError>::from));
        drawn.map_err(|e| draw_error(e.to_string()))
    })
    .map_err(|e| match e {
        PlotError::Io(source) => PlotError::File {
            path: path.to_path_buf(),
            source,
        },
        other => other,
    })
}

#[cfg(test)]
pub mod tests;
