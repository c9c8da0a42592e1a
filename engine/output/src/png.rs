//! Particle snapshot pictures (PNG): particles as dots coloured by a value, walls, colour bar and title.

use std::path::Path;

use glam::DVec2;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::plot::{format_number, render_png, tick_label_width, PlotError, FONT_FAMILY};

/// What to draw in one snapshot.
pub struct Snapshot<'a> {
    pub positions: &'a [DVec2],
    /// Colour by this (e.g. pressure); one per position. Non-finite values are drawn grey.
    pub values: &'a [f64],
    /// Colour scale limits (min, max); if invalid, the finite data range is used.
    pub value_range: (f64, f64),
    /// World box to draw (min, max).
    pub bounds: (DVec2, DVec2),
    /// Wall segments drawn as dark lines.
    pub walls: &'a [(DVec2, DVec2)],
    /// E.g. "dam_break  t = 1.40 s".
    pub title: &'a str,
    /// E.g. "pressure \[Pa\]".
    pub colorbar_label: &'a str,
    /// Image width; the height follows from the aspect ratio of `bounds`.
    pub width_px: u32,
}

/// Smallest accepted `width_px`.
pub const MIN_WIDTH_PX: u32 = 240;

/// Viridis sampled at 9 evenly spaced points, interpolated linearly.
const VIRIDIS: [(u8, u8, u8); 9] = [
    (68, 1, 84),
    (71, 45, 123),
    (59, 82, 139),
    (44, 114, 142),
    (33, 144, 140),
    (39, 173, 129),
    (93, 200, 99),
    (170, 220, 50),
    (253, 231, 37),
];

const NAN_COLOR: RGBColor = RGBColor(160, 160, 160);
const WALL_COLOR: RGBColor = RGBColor(30, 30, 30);

/// Viridis colour at `t` in \[0, 1\] (clamped).
fn viridis(t: f64) -> RGBColor {
    let x = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) } * (VIRIDIS.len() - 1) as f64;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    let mix = |p: u8, q: u8| (f64::from(p) + (f64::from(q) - f64::from(p)) * f).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// Picture layout in pixels, derived from the width and the world aspect ratio.
struct Layout {
    size: (u32, u32),
    title_h: u32,
    title_fs: u32,
    fs: u32,
    margin: u32,
    x_label_h: u32,
    y_label_w: u32,
    plot: (u32, u32),
    bar_w: u32,
    bar_area_w: u32,
}

impl Layout {
    fn new(width: u32, (lo, hi): (DVec2, DVec2), (v0, v1): (f64, f64)) -> Option<Self> {
        let fs = (width / 55).clamp(11, 20);
        let title_fs = (width / 40).clamp(13, 28);
        let margin = 12;
        let title_h = title_fs * 2;
        let x_label_h = 3 * fs + 8;
        let y_label_w = tick_label_width(lo.y, hi.y, fs) + 2 * fs;
        let bar_w = (width / 50).clamp(10, 28);
        let bar_area_w = 10 + bar_w + 6 + tick_label_width(v0, v1, fs) + 2 * fs + 6;
        let plot_w = width.checked_sub(2 * margin + y_label_w + bar_area_w)?;
        if plot_w < 40 {
            return None;
        }
        let ext = hi - lo;
        let plot_h = (f64::from(plot_w) * ext.y / ext.x)
            .round()
            .clamp(40.0, 4.0 * f64::from(width)) as u32;
        let height = title_h + 2 * margin + plot_h + x_label_h;
        Some(Self {
            size: (width, height),
            title_h,
            title_fs,
            fs,
            margin,
            x_label_h,
            y_label_w,
            plot: (plot_w, plot_h),
            bar_w,
            bar_area_w,
        })
    }
}

/// Writes a PNG of the particles coloured by `values`, atomically.
pub fn write_snapshot(path: &Path, s: &Snapshot) -> Result<(), PlotError> {
    let invalid = |message: String| PlotError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    if s.values.len() != s.positions.len() {
        return Err(invalid(format!(
            "{} values for {} positions",
            s.values.len(),
            s.positions.len()
        )));
    }
    let (lo, hi) = s.bounds;
    if !(lo.is_finite() && hi.is_finite() && hi.x > lo.x && hi.y > lo.y) {
        return Err(invalid(format!("empty or non-finite bounds {lo} .. {hi}")));
    }
    let (v0, v1) = colour_range(s.value_range, s.values);
    let too_narrow = || {
        invalid(format!(
            "width {} px is too small (min {MIN_WIDTH_PX})",
            s.width_px
        ))
    };
    if s.width_px < MIN_WIDTH_PX {
        return Err(too_narrow());
    }
    let layout = Layout::new(s.width_px, s.bounds, (v0, v1)).ok_or_else(too_narrow)?;
    let spacing_px =
        typical_spacing(s.positions).map(|d| d * f64::from(layout.plot.0) / (hi.x - lo.x));
    let radius = spacing_px
        .map_or(2.0, |d| ((d - 1.0) / 2.0).round())
        .clamp(1.0, 40.0) as i32;

    render_png(path, layout.size, |root| {
        let (w, _) = layout.size;
        let (title_area, rest) = root.split_vertically(layout.title_h);
        let (chart_area, bar_area) = rest.split_horizontally(w - layout.bar_area_w);

        let title_style = TextStyle::from((FONT_FAMILY, layout.title_fs).into_font())
            .pos(Pos::new(HPos::Center, VPos::Center));
        title_area.draw_text(
            s.title,
            &title_style,
            (
                (w / 2) as i32,
                (layout.title_h / 2 + layout.margin / 2) as i32,
            ),
        )?;

        let mut chart = ChartBuilder::on(&chart_area)
            .margin(layout.margin)
            .x_label_area_size(layout.x_label_h)
            .y_label_area_size(layout.y_label_w)
            .build_cartesian_2d(lo.x..hi.x, lo.y..hi.y)?;
        let x_fmt = |v: &f64| format_number(*v, hi.x - lo.x);
        let y_fmt = |v: &f64| format_number(*v, hi.y - lo.y);
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x [m]")
            .y_desc("y [m]")
            .x_label_formatter(&x_fmt)
            .y_label_formatter(&y_fmt)
            .label_style((FONT_FAMILY, layout.fs))
            .axis_desc_style((FONT_FAMILY, layout.fs))
            .draw()?;

        let colour = |v: f64| {
            if v.is_finite() {
                viridis((v - v0) / (v1 - v0))
            } else {
                NAN_COLOR
            }
        };
        chart.draw_series(
            s.positions
                .iter()
                .zip(s.values)
                .filter(|(p, _)| p.is_finite())
                .map(|(p, &v)| Circle::new((p.x, p.y), radius, colour(v).filled())),
        )?;
        let wall_px = (w / 400).max(2);
        for &(a, b) in s.walls {
            if a.is_finite() && b.is_finite() {
                chart.draw_series(LineSeries::new(
                    [(a.x, a.y), (b.x, b.y)],
                    WALL_COLOR.stroke_width(wall_px),
                ))?;
            }
        }
        // Frame around the plotting area, drawn last so particles do not cover it.
        let frame = chart.plotting_area().strip_coord_spec();
        let (fw, fh) = frame.dim_in_pixel();
        frame.draw(&Rectangle::new(
            [(0, 0), (fw as i32 - 1, fh as i32 - 1)],
            BLACK,
        ))?;

        draw_colour_bar(&bar_area, &layout, (v0, v1), s.colorbar_label)?;
        Ok(())
    })
}

/// Vertical colour bar aligned with the plotting area, with 5 tick labels and a rotated label.
fn draw_colour_bar(
    area: &crate::plot::Root<'_>,
    layout: &Layout,
    (v0, v1): (f64, f64),
    label: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let x0 = 10;
    let x1 = x0 + layout.bar_w as i32;
    let top = layout.margin as i32;
    let bottom = top + layout.plot.1 as i32 - 1;
    let h = (bottom - top).max(1);
    for y in top..=bottom {
        let t = f64::from(bottom - y) / f64::from(h);
        area.draw(&Rectangle::new([(x0, y), (x1, y + 1)], viridis(t).filled()))?;
    }
    area.draw(&Rectangle::new([(x0, top), (x1, bottom)], BLACK))?;

    let tick_style = TextStyle::from((FONT_FAMILY, layout.fs).into_font())
        .pos(Pos::new(HPos::Left, VPos::Center));
    for i in 0..=4 {
        let t = f64::from(i) / 4.0;
        let y = bottom - (t * f64::from(h)).round() as i32;
        area.draw(&PathElement::new(vec![(x1, y), (x1 + 4, y)], BLACK))?;
        let text = format_number(v0 + t * (v1 - v0), v1 - v0);
        area.draw_text(&text, &tick_style, (x1 + 7, y))?;
    }

    let label_style = TextStyle::from((FONT_FAMILY, layout.fs).into_font())
        .transform(FontTransform::Rotate270)
        .pos(Pos::new(HPos::Center, VPos::Center));
    let label_x = layout.bar_area_w as i32 - layout.fs as i32 - 4;
    area.draw_text(label, &label_style, (label_x, (top + bottom) / 2))?;
    Ok(())
}

/// The default colour scale of a pressure picture: from 0 (or the 1st percentile of
/// the finite `values`, if that is below 0) to their 99th percentile, so at most 1 % of
/// the particles saturate at either end whatever the flow (a sloshing tank whose water
/// piles up against one wall, a dam break's impact); `fallback` if that range is empty
/// (no finite values, or all at or below 0).
pub fn pressure_colour_range(values: &[f64], fallback: (f64, f64)) -> (f64, f64) {
    let mut finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        return fallback;
    }
    let mut percentile = |q: f64| {
        let k = ((finite.len() - 1) as f64 * q).round() as usize;
        *finite.select_nth_unstable_by(k, f64::total_cmp).1
    };
    let (lo, hi) = (percentile(0.01).min(0.0), percentile(0.99));
    if hi > lo && (hi - lo).is_finite() {
        (lo, hi)
    } else {
        fallback
    }
}

/// The colour scale: `requested` if finite and increasing, else the finite data range; never empty.
fn colour_range(requested: (f64, f64), values: &[f64]) -> (f64, f64) {
    let (a, b) = requested;
    if a.is_finite() && b.is_finite() && b > a && (b - a).is_finite() {
        return (a, b);
    }
    crate::plot::axis_range(values.iter().copied(), 0.0)
}

/// Median nearest-neighbour distance of (a sample of) the finite positions, via a uniform grid.
fn typical_spacing(positions: &[DVec2]) -> Option<f64> {
    let pts: Vec<DVec2> = positions
        .iter()
        .copied()
        .filter(|p| p.is_finite())
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let lo = pts.iter().copied().fold(DVec2::INFINITY, DVec2::min);
    let hi = pts.iter().copied().fold(DVec2::NEG_INFINITY, DVec2::max);
    let ext = hi - lo;
    let n = pts.len() as f64;
    // At least the mean spacing if the points filled their bounding box, so neighbours are within 1 cell.
    let cell = (ext.x * ext.y / n).sqrt().max(ext.max_element() / n);
    if !(cell.is_finite() && cell > 0.0) {
        return None;
    }
    let nx = (ext.x / cell) as usize + 1;
    let ny = (ext.y / cell) as usize + 1;
    let cell_of = |p: DVec2| {
        let c = ((p - lo) / cell).floor();
        ((c.x as usize).min(nx - 1), (c.y as usize).min(ny - 1))
    };
    // Counting sort of point indices by cell.
    let mut start = vec![0usize; nx * ny + 1];
    for &p in &pts {
        let (i, j) = cell_of(p);
        start[j * nx + i + 1] += 1;
    }
    for k in 1..start.len() {
        start[k] += start[k - 1];
    }
    let mut fill = start.clone();
    let mut order = vec![0usize; pts.len()];
    for (idx, &p) in pts.iter().enumerate() {
        let (i, j) = cell_of(p);
        order[fill[j * nx + i]] = idx;
        fill[j * nx + i] += 1;
    }

    let stride = (pts.len() / 1000).max(1);
    let mut nearest: Vec<f64> = pts
        .iter()
        .step_by(stride)
        .filter_map(|&p| {
            let (i, j) = cell_of(p);
            let mut best = f64::INFINITY;
            for cj in j.saturating_sub(1)..=(j + 1).min(ny - 1) {
                for ci in i.saturating_sub(1)..=(i + 1).min(nx - 1) {
                    let k = cj * nx + ci;
                    for &q in &order[start[k]..start[k + 1]] {
                        let d = p.distance_squared(pts[q]);
                        if d > 0.0 && d < best {
                            best = d;
                        }
                    }
                }
            }
            best.is_finite().then(|| best.sqrt())
        })
        .collect();
    if nearest.is_empty() {
        return Some(cell);
    }
    let mid = nearest.len() / 2;
    let (_, median, _) = nearest.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*median)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot::tests::{assert_png, test_dir};
    use std::fs;

    /// A dam-break-like block of particles on a 0.02 m lattice in a 4 x 2 m tank.
    fn block() -> (Vec<DVec2>, Vec<f64>) {
        let dx = 0.02;
        let mut pos = Vec::new();
        let mut val = Vec::new();
        for i in 0..50 {
            for j in 0..50 {
                let p = DVec2::new(0.01 + dx * f64::from(i), 0.01 + dx * f64::from(j));
                pos.push(p);
                val.push(1000.0 * 9.81 * (1.0 - p.y));
            }
        }
        (pos, val)
    }

    #[test]
    fn writes_a_snapshot() {
        let dir = test_dir("snapshot");
        let (pos, val) = block();
        let walls = [
            (DVec2::new(0.0, 0.0), DVec2::new(4.0, 0.0)),
            (DVec2::new(0.0, 0.0), DVec2::new(0.0, 2.0)),
            (DVec2::new(4.0, 0.0), DVec2::new(4.0, 2.0)),
        ];
        let snap = Snapshot {
            positions: &pos,
            values: &val,
            value_range: (0.0, 9810.0),
            bounds: (DVec2::new(-0.1, -0.1), DVec2::new(4.1, 2.1)),
            walls: &walls,
            title: "dam_break  t = 1.40 s",
            colorbar_label: "pressure [Pa]",
            width_px: 900,
        };
        let path = dir.join("snap.png");
        write_snapshot(&path, &snap).unwrap();
        let layout = Layout::new(900, snap.bounds, snap.value_range).unwrap();
        let img = assert_png(&path, layout.size);
        // The particles are drawn: coloured (not grey) pixels beyond the colour bar's,
        // at least a quarter of the block's share of the plotting area (1 m x 1 m of
        // 4.2 x 2.2 m; dots of radius 1 px on a 3.2 px lattice cover about half of it).
        let coloured = img
            .pixels()
            .filter(|p| !(p[0] == p[1] && p[1] == p[2]))
            .count();
        let bar = (layout.bar_w + 1) * layout.plot.1;
        let block = layout.plot.0 * layout.plot.1 / 40;
        assert!(
            coloured as u32 > bar + block,
            "{coloured} coloured pixels, colour bar {bar}, plot {:?}",
            layout.plot
        );
        assert_eq!(
            fs::read_dir(&dir).unwrap().count(),
            1,
            "temporary file left behind"
        );
        if std::env::var_os("SPH_KEEP_TEST_OUTPUT").is_none() {
            fs::remove_dir_all(&dir).unwrap();
        }
    }

    #[test]
    fn degenerate_snapshots() {
        let dir = test_dir("snapshot_degenerate");
        let bounds = (DVec2::ZERO, DVec2::new(1.0, 1.0));
        let base = Snapshot {
            positions: &[],
            values: &[],
            value_range: (0.0, 1.0),
            bounds,
            walls: &[],
            title: "",
            colorbar_label: "",
            width_px: 400,
        };
        let path = dir.join("s.png");
        write_snapshot(&path, &base).unwrap();

        let pos = [
            DVec2::new(0.5, 0.5),
            DVec2::new(f64::NAN, 0.0),
            DVec2::new(0.5, 0.5),
        ];
        let val = [f64::NAN, 1.0, 2.0];
        let odd = Snapshot {
            positions: &pos,
            values: &val,
            value_range: (f64::NAN, 0.0),
            ..base
        };
        write_snapshot(&path, &odd).unwrap();

        let mismatch = Snapshot {
            values: &val[..1],
            ..odd
        };
        assert!(matches!(
            write_snapshot(&path, &mismatch),
            Err(PlotError::Invalid { .. })
        ));
        let empty_box = Snapshot {
            bounds: (DVec2::ZERO, DVec2::new(1.0, 0.0)),
            ..base
        };
        assert!(matches!(
            write_snapshot(&path, &empty_box),
            Err(PlotError::Invalid { .. })
        ));
        let narrow = Snapshot {
            width_px: 50,
            ..base
        };
        assert!(matches!(
            write_snapshot(&path, &narrow),
            Err(PlotError::Invalid { .. })
        ));
        // Tall, thin world boxes are capped in height.
        let tall = Snapshot {
            bounds: (DVec2::ZERO, DVec2::new(0.001, 1000.0)),
            ..base
        };
        write_snapshot(&path, &tall).unwrap();
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn default_pressure_scale_spans_the_1st_to_99th_percentile() {
        let fallback = (0.0, 912.0);
        // 1,000 pressures 0..2,997 Pa (a tank deeper on one side than the fallback's H)
        // and 5 impact spikes: the spikes and the top 1 % saturate, nothing else.
        let mut p: Vec<f64> = (0..1000).map(|i| 3.0 * f64::from(i)).collect();
        p.extend([5e4, 6e4, 7e4, 8e4, f64::NAN]);
        let (lo, hi) = pressure_colour_range(&p, fallback);
        assert_eq!(lo, 0.0);
        let saturated = p.iter().filter(|&&v| v > hi).count();
        assert!((5..=11).contains(&saturated), "{hi}: {saturated} above");
        assert!(hi > 2900.0 && hi < 3000.0, "{hi}");
        // Tension below 0 widens the scale downwards; degenerate frames fall back.
        let mut q: Vec<f64> = (0..1000).map(|i| f64::from(i) - 100.0).collect();
        q.reverse();
        assert_eq!(pressure_colour_range(&q, fallback), (-90.0, 889.0));
        assert_eq!(pressure_colour_range(&[], fallback), fallback);
        assert_eq!(pressure_colour_range(&[0.0, 0.0], fallback), fallback);
        assert_eq!(pressure_colour_range(&[f64::NAN], fallback), fallback);
        assert_eq!(pressure_colour_range(&[-5.0], fallback), fallback);
    }

    #[test]
    fn spacing_and_colours() {
        let (pos, _) = block();
        let d = typical_spacing(&pos).unwrap();
        assert!((d - 0.02).abs() < 1e-9, "{d}");
        // A block in a much larger box still finds the lattice spacing.
        let mut sparse = pos.clone();
        sparse.push(DVec2::new(100.0, 100.0));
        assert!((typical_spacing(&sparse).unwrap() - 0.02).abs() < 1e-9);
        assert_eq!(typical_spacing(&[DVec2::ONE]), None);
        assert_eq!(typical_spacing(&[DVec2::ONE, DVec2::ONE]), None);
        let line: Vec<_> = (0..10)
            .map(|i| DVec2::new(f64::from(i) * 0.5, 0.0))
            .collect();
        assert!((typical_spacing(&line).unwrap() - 0.5).abs() < 1e-12);

        assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
        assert_eq!(viridis(1.0), RGBColor(253, 231, 37));
        assert_eq!(viridis(2.0), viridis(1.0));
        assert_eq!(viridis(f64::NAN), viridis(0.0));
        assert_eq!(colour_range((1.0, 1.0), &[5.0, 7.0]), (5.0, 7.0));
        assert_eq!(colour_range((0.0, 2.0), &[5.0]), (0.0, 2.0));
    }
}
