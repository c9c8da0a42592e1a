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
pub mod tests {
    use super::*;
    use std::fs;

    pub fn test_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("sph_core_{name}_{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Decodes `path`, asserting it is a PNG of the given size with something drawn on
    /// its white background.
    pub fn assert_png(path: &Path, size: (u32, u32)) -> image::RgbImage {
        let bytes = fs::read(path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", path.display());
        let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .to_rgb8();
        assert_eq!(img.dimensions(), size, "{}", path.display());
        let drawn = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
        assert!(drawn > 0, "{}: blank picture", path.display());
        img
    }

    /// The pixels of exactly `colour` inside `frame`'s plotting area, as (column, row).
    pub fn pixels_of(img: &image::RgbImage, frame: &Frame, colour: RGBColor) -> Vec<(i32, i32)> {
        let mut out = Vec::new();
        for x in frame.left..=frame.right {
            for y in frame.top..=frame.bottom {
                if img.get_pixel(x as u32, y as u32).0 == [colour.0, colour.1, colour.2] {
                    out.push((x, y));
                }
            }
        }
        out
    }

    fn only_file(dir: &Path) -> Vec<String> {
        let mut v: Vec<_> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn plots_several_series() {
        let dir = test_dir("plot");
        let n = 200;
        let t: Vec<f64> = (0..n).map(|i| f64::from(i) * 0.01).collect();
        let series = [
            Series {
                name: "kinetic energy".into(),
                points: t.iter().map(|&t| (t, 1000.0 * (-t).exp())).collect(),
                style: Style::Line,
            },
            Series {
                name: "reference".into(),
                points: t
                    .iter()
                    .step_by(10)
                    .map(|&t| (t, 1000.0 * (-t).exp() + 30.0))
                    .collect(),
                style: Style::Points,
            },
            Series {
                name: "with gap".into(),
                points: t
                    .iter()
                    .map(|&t| {
                        (
                            t,
                            if (0.8..1.0).contains(&t) {
                                f64::NAN
                            } else {
                                500.0 + 200.0 * t
                            },
                        )
                    })
                    .collect(),
                style: Style::Line,
            },
        ];
        let path = dir.join("energy.png");
        let frame =
            draw_series_plot(&path, "dam_break: energy", "t [s]", "E [J]", &series).unwrap();
        let img = assert_png(&path, PLOT_SIZE);
        // Every series is drawn in the plotting area, in its colour.
        for (i, s) in series.iter().enumerate() {
            let n = pixels_of(&img, &frame, PALETTE[i]).len();
            assert!(n > 100, "series `{}`: {n} pixels of its colour", s.name);
        }
        // The gap in the third series is left blank: no green between t = 0.8 and 1.0
        // (0.81 to 0.99, clear of the line's last and first columns).
        let gap = (frame.column(0.81).ceil() as i32)..=(frame.column(0.99).floor() as i32);
        assert!(pixels_of(&img, &frame, PALETTE[2])
            .iter()
            .all(|p| !gap.contains(&p.0)));
        assert_eq!(only_file(&dir), ["energy.png"]);
        if std::env::var_os("SPH_KEEP_TEST_OUTPUT").is_none() {
            fs::remove_dir_all(&dir).unwrap();
        }
    }

    /// Reads the drawn line of colour `colour` back: per pixel column, the top and
    /// bottom row holding that colour.
    fn drawn_columns(
        img: &image::RgbImage,
        frame: &Frame,
        colour: RGBColor,
    ) -> Vec<(i32, i32, i32)> {
        let mut columns = std::collections::BTreeMap::<i32, (i32, i32)>::new();
        for (x, y) in pixels_of(img, frame, colour) {
            let e = columns.entry(x).or_insert((y, y));
            *e = (e.0.min(y), e.1.max(y));
        }
        columns.into_iter().map(|(x, (t, b))| (x, t, b)).collect()
    }

    /// A long noisy series with one spike and one dip of known size (the sloshing
    /// probes' case): the drawn line reaches the spike's and the dip's values at their
    /// times, to within a pixel, stays inside the plotting area, has no gaps, and passes
    /// through every sample's pixel.
    #[test]
    fn long_series_are_drawn_with_their_true_extremes() {
        let dir = test_dir("plot_spikes");
        let n = 100_000;
        let (spike_at, spike) = (61_803, 97_500.0);
        let (dip_at, dip) = (23_456, -140.0);
        let mut seed = 12_345u64;
        let mut noise = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let points: Vec<(f64, f64)> = (0..n)
            .map(|i| {
                let t = f64::from(i) * 1.6295e-4;
                let y = match i {
                    _ if i == spike_at => spike,
                    _ if i == dip_at => dip,
                    // Hydrostatic-like base with noise and, every 10,000 samples, a
                    // burst of impacts up to 60 kPa.
                    _ if i % 10_000 < 40 => 1000.0 + 60_000.0 * noise(),
                    _ => 1000.0 + 300.0 * (t * 4.0).sin() + 200.0 * noise(),
                };
                (t, y)
            })
            .collect();
        let (data_lo, data_hi) = (dip, spike);
        let series = [Series {
            name: "S1.shepard".into(),
            points: points.clone(),
            style: Style::Line,
        }];
        let path = dir.join("spikes.png");
        let f = draw_series_plot(&path, "spikes", "time [s]", "pressure [Pa]", &series).unwrap();
        let img = assert_png(&path, PLOT_SIZE);

        // The axes cover the data's true extremes.
        let t_end = points.last().unwrap().0;
        assert!(f.x.0 <= 0.0 && f.x.1 >= t_end, "{f:?}");
        assert!(f.y.0 < data_lo && f.y.1 > data_hi, "{f:?}");

        let value_of_row = |r: i32| {
            f.y.0 + f64::from(f.bottom - r) / f64::from(f.bottom - f.top) * (f.y.1 - f.y.0)
        };
        let time_of_column =
            |c: i32| f.x.0 + f64::from(c - f.left) / f64::from(f.right - f.left) * (f.x.1 - f.x.0);
        let value_px = (f.y.1 - f.y.0) / f64::from(f.bottom - f.top);
        let time_px = (f.x.1 - f.x.0) / f64::from(f.right - f.left);

        let line = PALETTE[0];
        let columns = drawn_columns(&img, &f, line);
        let top = columns.iter().map(|c| c.1).min().unwrap();
        let bottom = columns.iter().map(|c| c.2).max().unwrap();
        let drawn_max = value_of_row(top);
        let drawn_min = value_of_row(bottom);
        assert!(
            (drawn_max - data_hi).abs() <= value_px,
            "drawn max {drawn_max:.0} Pa, data max {data_hi} Pa (one pixel = {value_px:.0} Pa)"
        );
        assert!(
            (drawn_min - data_lo).abs() <= value_px,
            "drawn min {drawn_min:.0} Pa, data min {data_lo} Pa (one pixel = {value_px:.0} Pa)"
        );
        // The spike's column (the first reaching the top row) is at its time.
        let spike_column = columns.iter().find(|c| c.1 == top).unwrap().0;
        let (t_spike, t_drawn) = (points[spike_at as usize].0, time_of_column(spike_column));
        assert!(
            (t_drawn - t_spike).abs() <= time_px,
            "spike drawn at t = {t_drawn:.4} s, data at {t_spike:.4} s (one pixel = {time_px:.4} s)"
        );
        let dip_column = columns.iter().find(|c| c.2 == bottom).unwrap().0;
        let (t_dip, t_drawn) = (points[dip_at as usize].0, time_of_column(dip_column));
        assert!(
            (t_drawn - t_dip).abs() <= time_px,
            "dip drawn at t = {t_drawn:.4} s, data at {t_dip:.4} s"
        );

        // One connected line: every column from the first sample's to the last's.
        let (first, last) = (f.column(0.0).round() as i32, f.column(t_end).round() as i32);
        let drawn: std::collections::BTreeSet<i32> = columns.iter().map(|c| c.0).collect();
        let missing: Vec<i32> = (first..=last).filter(|c| !drawn.contains(c)).collect();
        assert!(missing.is_empty(), "columns without the line: {missing:?}");
        // Every sample's own pixel is on the line.
        let on_line = |&(t, y): &(f64, f64)| {
            let (c, r) = (f.column(t).round(), f.row(y).round());
            img.get_pixel(c as u32, r as u32).0 == [line.0, line.1, line.2]
        };
        let off: Vec<_> = points.iter().filter(|p| !on_line(p)).take(5).collect();
        assert!(off.is_empty(), "samples off the drawn line: {off:?}");
        if std::env::var_os("SPH_KEEP_TEST_OUTPUT").is_none() {
            fs::remove_dir_all(&dir).unwrap();
        }
    }

    /// A few samples far apart: the segments between them are drawn (connected, at
    /// most a pixel's step between neighbouring columns) and no higher or lower than
    /// their end points.
    #[test]
    fn sparse_series_are_connected_and_bounded_by_their_samples() {
        let dir = test_dir("plot_sparse");
        let points = vec![
            (0.0, 0.0),
            (1.0, 10.0),
            (1.5, -3.0),
            (4.0, 2.0),
            (4.01, 9.0),
        ];
        let series = [Series {
            name: "zigzag".into(),
            points: points.clone(),
            style: Style::Line,
        }];
        let path = dir.join("sparse.png");
        let f = draw_series_plot(&path, "sparse", "x", "y", &series).unwrap();
        let img = assert_png(&path, PLOT_SIZE);
        let columns = drawn_columns(&img, &f, PALETTE[0]);
        for w in columns.windows(2) {
            let ((c0, t0, b0), (c1, t1, b1)) = (w[0], w[1]);
            assert_eq!(c1, c0 + 1, "gap between columns {c0} and {c1}");
            // Neighbouring spans touch or overlap (8-connected).
            assert!(t1 <= b0 + 1 && t0 <= b1 + 1, "{:?} {:?}", w[0], w[1]);
        }
        let top = columns.iter().map(|c| c.1).min().unwrap();
        let bottom = columns.iter().map(|c| c.2).max().unwrap();
        assert_eq!(top, f.row(10.0).round() as i32);
        assert_eq!(bottom, f.row(-3.0).round() as i32);
        fs::remove_dir_all(&dir).unwrap();
    }

    /// Point markers at the data's extremes are drawn whole, inside the plotting area
    /// (the x axis is padded for point series), while a line's x axis ends at its data.
    #[test]
    fn markers_at_the_extremes_are_drawn_whole() {
        let dir = test_dir("plot_markers");
        let series = [
            Series {
                name: "cases".into(),
                points: vec![(1.0, 0.27), (4.4, 0.267), (17.7, 0.27)],
                style: Style::Points,
            },
            Series {
                name: "front".into(),
                points: vec![(1.0, 0.27), (4.4, 0.267)],
                style: Style::Line,
            },
        ];
        let path = dir.join("markers.png");
        let f = draw_series_plot(&path, "markers", "wall time [s]", "error", &series).unwrap();
        let img = assert_png(&path, PLOT_SIZE);
        let columns: Vec<i32> = pixels_of(&img, &f, PALETTE[0])
            .into_iter()
            .map(|p| p.0)
            .collect();
        for x in [1.0, 17.7] {
            let c = f.column(x).round() as i32;
            // The marker's radius is 3 px: columns c - 2 and c + 2 both drawn.
            for d in [-2, 2] {
                assert!(
                    columns.contains(&(c + d)),
                    "marker at x = {x}: column {} not drawn (frame {:?})",
                    c + d,
                    f.x
                );
            }
        }
        let line = [Series {
            name: "line".into(),
            points: vec![(1.0, 0.0), (17.7, 1.0)],
            style: Style::Line,
        }];
        let f = draw_series_plot(&dir.join("line.png"), "line", "t", "y", &line).unwrap();
        assert_eq!(f.x, (1.0, 17.7));
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn degenerate_inputs_do_not_panic() {
        let dir = test_dir("plot_degenerate");
        let cases: Vec<Vec<Series>> = vec![
            vec![],
            vec![Series {
                name: "empty".into(),
                points: vec![],
                style: Style::Line,
            }],
            vec![Series {
                name: "one".into(),
                points: vec![(1.0, 2.0)],
                style: Style::Line,
            }],
            vec![Series {
                name: "constant".into(),
                points: (0..10).map(|i| (f64::from(i), 3.0)).collect(),
                style: Style::Points,
            }],
            vec![Series {
                name: "zeros".into(),
                points: vec![(0.0, 0.0), (0.0, 0.0)],
                style: Style::Line,
            }],
            vec![Series {
                name: "nan".into(),
                points: vec![
                    (f64::NAN, 1.0),
                    (1.0, f64::INFINITY),
                    (f64::NEG_INFINITY, 0.0),
                ],
                style: Style::Line,
            }],
            vec![Series {
                name: "huge".into(),
                points: vec![(0.0, -f64::MAX), (1.0, f64::MAX), (2.0, 1e-300)],
                style: Style::Line,
            }],
        ];
        for (i, series) in cases.iter().enumerate() {
            let path = dir.join(format!("case{i}.png"));
            plot_series(&path, "degenerate", "x", "y", series).unwrap();
            assert_png(&path, PLOT_SIZE);
        }
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_folder_error_names_the_file() {
        let path = std::env::temp_dir().join("sph_core_no_such_dir_plot/p.png");
        let err = plot_series(&path, "t", "x", "y", &[]).unwrap_err();
        assert!(err.to_string().contains("p.png"), "{err}");
    }

    #[test]
    fn ranges_and_numbers() {
        assert_eq!(axis_range([].into_iter(), 0.1), (0.0, 1.0));
        assert_eq!(axis_range([2.0, 2.0].into_iter(), 0.1), (1.8, 2.2));
        assert_eq!(axis_range([0.0].into_iter(), 0.1), (-1.0, 1.0));
        assert_eq!(
            axis_range([0.0, 10.0, f64::NAN].into_iter(), 0.1),
            (-1.0, 11.0)
        );
        let (lo, hi) = axis_range([-f64::MAX, f64::MAX].into_iter(), 0.05);
        assert!(lo.is_finite() && hi.is_finite() && lo < hi);

        assert_eq!(format_number(0.5, 1.0), "0.5");
        assert_eq!(format_number(250.0, 1000.0), "250");
        assert_eq!(format_number(-1e-17, 1.0), "0");
        assert_eq!(format_number(-0.0001, 1.0), "0.0");
        assert_eq!(format_number(0.012, 0.02), "0.012");
        assert_eq!(format_number(250000.0, 1e6), "2.5e5");
        assert_eq!(format_number(2e-5, 1e-4), "2.0e-5");
    }
}
