//! A study's figures: speed against each error metric (one point per case, the Pareto
//! front of the completed cases marked) and overlays of time histories, one line per
//! case (a fallback run named `<case> (<label>)`). Returns (title, file) pairs for
//! report.md.

use super::metrics::pareto_front;
use super::{scales, Row, Study};
use crate::series::read_series;
use sph_core::StageRegistry;
use sph_output::plot::{plot_series, Series, Style};
use sph_scenario::Scenario;
use std::path::Path;

/// A row's name in a legend: the case, `(<label>)` for a fallback run, `(stopped)` for
/// a run that stopped early.
fn legend(r: &Row) -> String {
    if r.completed() {
        r.case.legend()
    } else {
        format!("{} (stopped)", r.case.legend())
    }
}

/// Draws every figure into `out_dir`.
pub fn draw(
    study: &Study,
    out_dir: &Path,
    rows: &[Row],
    registry: &StageRegistry,
) -> Result<Vec<(String, String)>, String> {
    let mut out = Vec::new();
    let errors: Vec<String> = rows
        .first()
        .map(|r| {
            r.metrics
                .iter()
                .map(|m| m.0.clone())
                .filter(|m| m.ends_with("_error"))
                .collect()
        })
        .unwrap_or_default();
    for metric in errors {
        let file = format!("speed_vs_{metric}.png");
        let title = format!("wall time against |{metric}|");
        speed_vs_error(&out_dir.join(&file), &title, rows, &metric)?;
        out.push((title, file));
    }
    for (i, o) in study.spec.overlays.iter().enumerate() {
        let file = format!(
            "overlay{}_{}.png",
            i + 1,
            o.column.replace(['.', '*', '+'], "_")
        );
        let mut series = Vec::new();
        for r in rows {
            let dir = out_dir.join(&r.case.name);
            let Ok(points) = read_series(&dir.join(&o.file), &o.column) else {
                continue;
            };
            let points = if o.nondimensional {
                let Ok(s) = Scenario::load(&study.scenario, &r.case.overrides, registry) else {
                    continue;
                };
                let (rho0, g, h) = scales(&s);
                let t_scale = (g / h).sqrt();
                points
                    .iter()
                    .map(|&(t, p)| (t * t_scale, p / (rho0 * g * h)))
                    .collect()
            } else {
                points
            };
            let points = match o.y_limits {
                Some((lo, hi)) => points.iter().map(|&(t, v)| (t, v.clamp(lo, hi))).collect(),
                None => points,
            };
            series.push(Series {
                name: legend(r),
                points,
                style: Style::Line,
            });
        }
        if let Some(reference) = &o.reference {
            series.push(Series {
                name: "reference data".into(),
                points: super::reference(&study.resolve(reference)),
                style: Style::Points,
            });
        }
        let (x_label, y_label) = if o.nondimensional {
            ("t sqrt(g/H)", format!("{} / (rho0 g H)", o.column))
        } else {
            ("time [s]", o.label.clone())
        };
        let title = format!("{}: {} per case", study.spec.name, o.column);
        plot_series(&out_dir.join(&file), &title, x_label, &y_label, &series)
            .map_err(|e| e.to_string())?;
        out.push((title, file));
    }
    Ok(out)
}

/// Wall seconds against |metric|: one point series per case (its name in the legend),
/// stopped cases marked, and the Pareto front of the completed cases as a line.
fn speed_vs_error(path: &Path, title: &str, rows: &[Row], metric: &str) -> Result<(), String> {
    let point = |r: &Row| (r.wall_seconds, r.metric(metric).map_or(f64::NAN, f64::abs));
    let mut series: Vec<Series> = rows
        .iter()
        .map(|r| Series {
            name: legend(r),
            points: vec![point(r)],
            style: Style::Points,
        })
        .collect();
    let completed: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| {
            if r.completed() {
                point(r)
            } else {
                (f64::NAN, f64::NAN)
            }
        })
        .collect();
    series.push(Series {
        name: "Pareto front (completed cases)".into(),
        points: pareto_front(&completed)
            .into_iter()
            .map(|i| completed[i])
            .collect(),
        style: Style::Line,
    });
    plot_series(
        path,
        title,
        "wall time [s]",
        &format!("|{metric}|"),
        &series,
    )
    .map_err(|e| e.to_string())
}

/// The cases' snapshot pictures at one time in one PNG, two per row, each under its
/// case name (free surfaces side by side, e.g. per kernel). Cases without the picture
/// (stopped before that time) are left out; returns false if none had it.
pub fn snapshot_grid(path: &Path, panels: &[(String, std::path::PathBuf)]) -> Result<bool, String> {
    use plotters::prelude::*;
    let images: Vec<(&String, image::RgbImage)> = panels
        .iter()
        .filter_map(|(name, p)| Some((name, image::open(p).ok()?.to_rgb8())))
        .collect();
    if images.is_empty() {
        return Ok(false);
    }
    let (w, h) = images.iter().fold((0, 0), |(w, h), (_, im)| {
        (w.max(im.width()), h.max(im.height()))
    });
    let label = 36;
    let cols = images.len().min(2) as u32;
    let rows = (images.len() as u32).div_ceil(cols);
    sph_output::plot::render_png(path, (cols * w, rows * (h + label)), |root| {
        let style = TextStyle::from((sph_output::plot::FONT_FAMILY, 26).into_font());
        for (k, (name, im)) in images.iter().enumerate() {
            let (x0, y0) = ((k as u32 % cols) * w, (k as u32 / cols) * (h + label));
            root.draw_text(name, &style, (x0 as i32 + 12, y0 as i32 + 6))?;
            for (x, y, p) in im.enumerate_pixels() {
                let at = ((x0 + x) as i32, (y0 + label + y) as i32);
                root.draw_pixel(at, &RGBColor(p[0], p[1], p[2]))?;
            }
        }
        Ok(())
    })
    .map_err(|e| e.to_string())?;
    Ok(true)
}
