//! Time-series line plots (PNG) and the shared plotting helpers: error type, embedded font, PNG rendering.

use std::error::Error as StdError;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::atomic::write_atomic_with;

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
/// A legend is drawn when there is more than one series.
pub fn plot_series(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<(), PlotError> {
    let finite = || {
        series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
    };
    let (x0, x1) = axis_range(finite().map(|p| p.0), 0.0);
    let (y0, y1) = axis_range(finite().map(|p| p.1), 0.05);

    let fs = 15;
    let y_label_w = tick_label_width(y0, y1, fs) + 2 * fs + 10;

    render_png(path, PLOT_SIZE, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FONT_FAMILY, 22))
            .margin(15)
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

        for (i, s) in series.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let mut segments = finite_segments(&s.points).into_iter();
            // The first (possibly empty) segment carries the legend entry.
            let first = segments.next().unwrap_or_default();
            let anno = match s.style {
                Style::Line => {
                    for seg in segments {
                        chart.draw_series(LineSeries::new(seg, color.stroke_width(2)))?;
                    }
                    chart.draw_series(LineSeries::new(first, color.stroke_width(2)))?
                }
                Style::Points => {
                    let pts = first.into_iter().chain(segments.flatten());
                    chart.draw_series(pts.map(|p| Circle::new(p, 3, color.filled())))?
                }
            };
            let style = s.style;
            anno.label(s.name.as_str())
                .legend(move |(x, y)| match style {
                    Style::Line => {
                        PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                            .into_dyn()
                    }
                    Style::Points => Circle::new((x + 10, y), 3, color.filled()).into_dyn(),
                });
        }
        if series.len() > 1 {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font((FONT_FAMILY, fs))
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(120, 120, 120))
                .draw()?;
        }
        Ok(())
    })
}

/// Splits points into runs of finite points (non-finite points break lines).
fn finite_segments(points: &[(f64, f64)]) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut current = Vec::new();
    for &(x, y) in points {
        if x.is_finite() && y.is_finite() {
            current.push((x, y));
        } else if !current.is_empty() {
            out.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() || out.is_empty() {
        out.push(current);
    }
    out
}

/// Range covering `values` (finite), padded by `pad` of the span; never empty or inverted.
pub(crate) fn axis_range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
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
pub(crate) fn format_number(v: f64, span: f64) -> String {
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
pub(crate) fn tick_label_width(lo: f64, hi: f64, font_px: u32) -> u32 {
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
pub(crate) const FONT_FAMILY: &str = "sans-serif";

static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// Registers the embedded font with plotters once; later calls return the first outcome.
fn ensure_font() -> bool {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, FONT).is_ok()
    })
}

pub(crate) type Root<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// Renders a `size` PNG with `draw` into a temporary file and renames it onto `path`.
pub(crate) fn render_png<F>(path: &Path, size: (u32, u32), draw: F) -> Result<(), PlotError>
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
pub(crate) mod tests {
    use super::*;
    use std::fs;

    pub(crate) fn test_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("sph_core_{name}_{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Asserts `path` is a PNG of the given size with some non-white pixels.
    pub(crate) fn assert_png(path: &Path, size: (u32, u32)) {
        let bytes = fs::read(path).unwrap();
        assert!(
            bytes.len() > 1000,
            "suspiciously small PNG: {} bytes",
            bytes.len()
        );
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        assert_eq!(&bytes[12..16], b"IHDR");
        let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
        let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
        assert_eq!((w, h), size);
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
        plot_series(&path, "dam_break: energy", "t [s]", "E [J]", &series).unwrap();
        assert_png(&path, PLOT_SIZE);
        assert_eq!(only_file(&dir), ["energy.png"]);
        if std::env::var_os("SPH_KEEP_TEST_OUTPUT").is_none() {
            fs::remove_dir_all(&dir).unwrap();
        }
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
