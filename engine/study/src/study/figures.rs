//! A study's figures: speed against each error metric (one point per case, the Pareto
//! front of the completed cases marked) and overlays of time histories, one line per
//! case (a fallback run named `<case> (<label>)`). Returns (title, file) pairs for
//! report.md.

use super::metrics::pareto_front;
use super::{scales, Row, Study};
use crate::series::read_series;
use crate::StudyError;
use sph_core::StageRegistry;
use sph_output::plot::{draw_series_plot, plot_series, Frame, Series, Style};
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
) -> Result<Vec<(String, String)>, StudyError> {
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
    for m in &study.spec.metrics {
        if let super::Metric::ImpactBand {
            column, reference, ..
        } = m
        {
            let b = super::base(column);
            let file = format!("impacts_{}.png", b.replace(['.', '*', '+'], "_"));
            let title = format!(
                "{}: {b} impact peaks against the measured band",
                study.spec.name
            );
            impacts_against_band(
                &out_dir.join(&file),
                &title,
                rows,
                b,
                &study.resolve(reference),
            )?;
            out.push((title, file));
        }
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
            .map_err(StudyError::from)?;
        out.push((title, file));
    }
    Ok(out)
}

/// Each case's impact peaks `<b>_impact<k>` [kPa] as points over impact k (the cases
/// side by side within each k), drawn over the measured statistics of `reference`
/// (rows k: mean, std, median, min, max, ..., band low, band high in mbar) as lines:
/// mean, mean +- 2 std, and the smallest and largest peak of any repetition.
fn impacts_against_band(
    path: &Path,
    title: &str,
    rows: &[Row],
    b: &str,
    reference: &Path,
) -> Result<Frame, StudyError> {
    let table = crate::series::read_table(reference)
        .map(|(_, rows)| rows)
        .unwrap_or_default();
    let n = table.len();
    // A level per impact, drawn across k +- 0.4 (a NaN point breaks the line between
    // impacts); mbar to kPa.
    let line = |name: &str, col: usize| Series {
        name: name.into(),
        points: table
            .iter()
            .enumerate()
            .flat_map(|(k, r)| {
                let (x, v) = ((k + 1) as f64, r.get(col).map_or(f64::NAN, |v| 0.1 * v));
                [(x - 0.4, v), (x + 0.4, v), (f64::NAN, f64::NAN)]
            })
            .collect(),
        style: Style::Line,
    };
    let mut series = vec![
        line("measured mean", 1),
        line("measured mean - 2 std", 7),
        line("measured mean + 2 std", 8),
        line("measured min", 4),
        line("measured max", 5),
    ];
    let cases = rows.len().max(1) as f64;
    for (c, r) in rows.iter().enumerate() {
        // Spread the cases over +-0.3 about each impact number.
        let dx = if cases > 1.0 {
            0.6 * (c as f64 / (cases - 1.0) - 0.5)
        } else {
            0.0
        };
        series.push(Series {
            name: legend(r),
            points: (1..=n)
                .map(|k| {
                    let p = r.metric(&format!("{b}_impact{k}")).unwrap_or(f64::NAN);
                    (k as f64 + dx, 1e-3 * p)
                })
                .collect(),
            style: Style::Points,
        });
    }
    draw_series_plot(path, title, "impact", &format!("{b} peak [kPa]"), &series)
        .map_err(StudyError::from)
}

/// Wall seconds against |metric|: one point series per case (its name in the legend),
/// stopped cases marked, and the Pareto front of the completed cases as a line.
fn speed_vs_error(path: &Path, title: &str, rows: &[Row], metric: &str) -> Result<(), StudyError> {
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
    .map_err(StudyError::from)
}

/// The cases' snapshot pictures at one time in one PNG, two per row, each under its
/// case name (free surfaces side by side, e.g. per kernel). Cases without the picture
/// (stopped before that time) are left out; returns false if none had it.
pub fn snapshot_grid(
    path: &Path,
    panels: &[(String, std::path::PathBuf)],
) -> Result<bool, StudyError> {
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
    .map_err(StudyError::from)?;
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::Case;

    /// A case's impact peaks are drawn where they lie against the band: the first
    /// case's colour (the sixth series: five band lines come first; Tableau 10's sixth,
    /// (140, 86, 75)) appears at impact 1 above the row of the band's top
    /// (10 kPa against 5.17) and at impact 2 inside the band (4 kPa in 1.81-7.82).
    #[test]
    fn impact_peaks_are_drawn_against_the_band() {
        let dir = std::env::temp_dir().join(format!("sph_impacts_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let reference = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../tests/data/spheric_test10_lateral_water_peak_statistics.csv");
        let row = Row {
            case: Case {
                name: "a".into(),
                labels: vec![],
                overrides: vec![],
                scheme: None,
                fallback: false,
            },
            status: "completed".into(),
            fluid_particles: 1.0,
            steps: 1.0,
            simulated_time: 1.0,
            wall_seconds: 1.0,
            particle_steps_per_second: 1.0,
            ran: true,
            metrics: vec![
                ("S1_impact1".into(), 10_000.0),
                ("S1_impact2".into(), 4_000.0),
                ("S1_impact3".into(), f64::NAN),
                ("S1_impact4".into(), 20_000.0),
            ],
        };
        let path = dir.join("impacts.png");
        let frame = impacts_against_band(&path, "t", &[row], "S1", &reference).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        let at = |x: f64| {
            let c = frame.column(x).round() as i32;
            (c - 4..=c + 4)
                .flat_map(|x| (frame.top..=frame.bottom).map(move |y| (x, y)))
                .filter(|&(x, y)| img.get_pixel(x as u32, y as u32).0 == [140, 86, 75])
                .map(|p| p.1)
                .collect::<Vec<i32>>()
        };
        let (one, two) = (at(1.0), at(2.0));
        assert!(!one.is_empty() && !two.is_empty(), "no case point drawn");
        assert!(
            one.iter().all(|&y| f64::from(y) < frame.row(5.17)),
            "impact 1 (10 kPa) not above the band's top"
        );
        assert!(
            two.iter()
                .all(|&y| f64::from(y) < frame.row(1.81) && f64::from(y) > frame.row(7.82)),
            "impact 2 (4 kPa) not inside the band"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
