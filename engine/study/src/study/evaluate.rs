//! A finished case's metrics, read from its output folder.

use super::*;

/// The row of a case from its folder: summary.json, probes.csv, energy.csv,
/// final_particles.csv. `failure`: why the case could not run at all.
pub fn evaluate(
    study: &Study,
    case: &Case,
    dir: &Path,
    ran: bool,
    failure: Option<String>,
    registry: &StageRegistry,
) -> Row {
    let summary: serde_json::Value = std::fs::read_to_string(dir.join("summary.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    let num = |k: &str| {
        summary
            .get(k)
            .and_then(serde_json::Value::as_f64)
            .unwrap_or(f64::NAN)
    };
    let status = failure.unwrap_or_else(|| {
        summary
            .get("status")
            .and_then(|s| s.as_str())
            .unwrap_or("no summary.json")
            .to_string()
    });
    let mut row = Row {
        case: case.clone(),
        status,
        fluid_particles: num("fluid_particles"),
        steps: num("steps"),
        simulated_time: num("simulated_time"),
        wall_seconds: num("wall_seconds"),
        particle_steps_per_second: num("particle_steps_per_second"),
        ran,
        metrics: Vec::new(),
    };
    let scenario = Scenario::load(&study.scenario, &case.overrides, registry).ok();
    let reflections = summary
        .get("diagnostics")
        .and_then(|d| d.get("wall_reflections"))
        .and_then(serde_json::Value::as_f64)
        .unwrap_or(0.0);
    for m in &study.spec.metrics {
        row.metrics
            .extend(metric_values(study, m, dir, scenario.as_ref(), reflections));
    }
    row
}

/// Reference data: the first two columns, sorted by the first.
pub(crate) fn reference(path: &Path) -> Vec<(f64, f64)> {
    let mut points: Vec<(f64, f64)> = crate::series::read_table(path)
        .map(|(_, rows)| {
            rows.iter()
                .filter(|r| r.len() >= 2)
                .map(|r| (r[0], r[1]))
                .collect()
        })
        .unwrap_or_default();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points
}

/// The column's name in study.csv: `P1.*` gives `P1`, `P1.shepard` stays.
pub(crate) fn base(column: &str) -> &str {
    column.strip_suffix(".*").unwrap_or(column)
}

/// Scales of a scenario: (rho_0, |g|, H the fluid top).
pub(crate) fn scales(s: &Scenario) -> (f64, f64, f64) {
    let top = s
        .spec
        .fluid_blocks
        .iter()
        .map(|b| b.min.1 + b.size.1 .0)
        .fold(0.0, f64::max);
    (
        s.spec.fluid.density.0,
        sph_core::dim::Vector::from(s.spec.fluid.gravity).length(),
        top,
    )
}

/// The tank's roll (period [s], phase [deg]); NaNs if the scenario has no roll.
pub(crate) fn roll(scenario: Option<&Scenario>) -> (f64, f64) {
    scenario
        .and_then(|s| s.spec.tank.as_ref())
        .and_then(|t| t.motion.as_ref())
        .and_then(|m| m.roll.as_ref())
        .map_or((f64::NAN, f64::NAN), |r| (r.period.0, r.phase))
}

/// The final fluid positions a completed case wrote.
pub(crate) fn final_positions(dir: &Path) -> Option<Vec<DVec2>> {
    let (_, rows) = crate::series::read_table(&dir.join("final_particles.csv")).ok()?;
    Some(rows.iter().map(|r| DVec2::new(r[0], r[1])).collect())
}

pub(crate) fn metric_values(
    study: &Study,
    metric: &Metric,
    dir: &Path,
    scenario: Option<&Scenario>,
    reflections: f64,
) -> Vec<(String, f64)> {
    let probes = |c: &str| read_series(&dir.join("probes.csv"), c).unwrap_or_default();
    let (rho0, g, height) = scenario.map_or((f64::NAN, f64::NAN, f64::NAN), scales);
    let p_scale = rho0 * g * height;
    match metric {
        Metric::SurgeFront {
            reference: r,
            delay,
            from,
            to,
        } => {
            let a = scenario
                .and_then(|s| s.spec.fluid_blocks.first())
                .map_or(f64::NAN, |b| b.size.0 .0);
            let scale = (2.0 * g / a).sqrt();
            let front: Vec<(f64, f64)> = probes("front")
                .iter()
                .map(|&(t, x)| (t * scale + delay, x / a))
                .collect();
            let data = reference(&study.resolve(r));
            vec![(
                "surge_front_error".into(),
                metrics::rms_relative(&front, &data, *from, *to),
            )]
        }
        Metric::Pressure {
            column,
            reference: r,
            from,
            to,
            peak,
            name,
        } => {
            let (p0, p1) = peak.unwrap_or((*from, *to));
            let t_scale = (g / height).sqrt();
            let sim: Vec<(f64, f64)> = probes(column)
                .iter()
                .map(|&(t, p)| (t * t_scale, p / p_scale))
                .collect();
            let data = reference(&study.resolve(r));
            let (ts, ps) = metrics::peak(&sim, p0, p1);
            let (tr, pr) = metrics::peak(&data, p0, p1);
            let b = name.as_deref().unwrap_or(base(column));
            vec![
                (
                    format!("{b}_rms_error"),
                    metrics::rms_difference(&sim, &data, *from, *to),
                ),
                (format!("{b}_peak"), ps),
                (format!("{b}_peak_time"), ts),
                (format!("{b}_peak_error"), ps / pr - 1.0),
                (format!("{b}_peak_time_error"), ts - tr),
            ]
        }
        Metric::WaveGauge {
            column,
            reference: r,
            from,
            to,
        } => {
            let data = reference(&study.resolve(r));
            let height = probes(column);
            let still = height.first().map_or(0.0, |p| p.1);
            let eta: Vec<(f64, f64)> = height.iter().map(|&(t, h)| (t, h - still)).collect();
            vec![(
                format!("{}_rms_error", base(column)),
                metrics::rms_difference(&eta, &data, *from, *to),
            )]
        }
        Metric::Hydrostatic { column, from } => {
            let name = column.split('.').next().unwrap_or(column);
            let y = scenario
                .and_then(|s| s.spec.pressure_sensors.iter().find(|p| p.name == name))
                .map_or(f64::NAN, |p| p.at.1);
            let expected = rho0 * g * (height - y);
            vec![(
                format!("{}_hydrostatic_error", base(column)),
                metrics::mean_abs_error(&probes(column), expected, *from) / p_scale,
            )]
        }
        Metric::NaturalFrequency { column, from, mode } => {
            let omega = metrics::crossing_frequency(&probes(column), *from);
            let theory = scenario.map_or(f64::NAN, |s| {
                let width = s.spec.tank.as_ref().map_or(f64::NAN, |t| t.width.0);
                crate::sweep::linear_tank(s, height / width).natural_frequency(*mode)
            });
            let b = base(column);
            vec![
                (format!("{b}_omega"), omega),
                (format!("{b}_omega_error"), omega / theory - 1.0),
            ]
        }
        Metric::RollHarmonic { column, from } => {
            let (period, phase) = roll(scenario);
            let (a, lag) = metrics::forced_harmonic(&probes(column), period, phase, *from);
            let b = base(column);
            vec![(format!("{b}_amplitude"), a), (format!("{b}_lag_deg"), lag)]
        }
        Metric::PeriodPeaks { column, from } => {
            let (period, _) = roll(scenario);
            let (median, max) = metrics::period_peaks(&probes(column), period, *from);
            let b = base(column);
            vec![
                (format!("{b}_peak_median"), median),
                (format!("{b}_peak_max"), max),
            ]
        }
        Metric::ImpactBand {
            column,
            reference,
            from,
        } => {
            let (period, _) = roll(scenario);
            let peaks = metrics::period_peak_list(&probes(column), period, *from);
            let rows = crate::series::read_table(&study.resolve(reference))
                .map(|(_, rows)| rows)
                .unwrap_or_default();
            let b = base(column);
            let mut out = Vec::new();
            let (mut sum, mut above) = (0.0, 0.0);
            // 1 mbar = 100 Pa; a row without its nine columns gives NaNs.
            let cell = |r: &[f64], k: usize| r.get(k).map_or(f64::NAN, |v| 100.0 * v);
            for (k, row) in rows.iter().enumerate() {
                let p = peaks.get(k).copied().unwrap_or(f64::NAN);
                let d = metrics::band_distance(p, cell(row, 7), cell(row, 8));
                sum += d.abs();
                // A NaN peak or maximum counts as above: it is no measured impact.
                let within = matches!(
                    p.partial_cmp(&cell(row, 5)),
                    Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
                );
                above += f64::from(!within);
                out.push((format!("{b}_impact{}", k + 1), p));
                out.push((format!("{b}_impact{}_band", k + 1), d));
            }
            let mut later: Vec<f64> = peaks.iter().skip(1).take(3).copied().collect();
            let median = match later.len() {
                3 if later.iter().all(|p| p.is_finite()) => {
                    later.sort_by(f64::total_cmp);
                    later[1]
                }
                _ => f64::NAN,
            };
            let error = match rows.len() {
                0 => f64::NAN,
                n => sum / n as f64,
            };
            out.push((format!("{b}_band_error"), error));
            out.push((format!("{b}_impacts_median_2_4"), median));
            out.push((format!("{b}_above_measured_max"), above));
            out
        }
        Metric::EnergyLoss { times } => {
            let e = read_series(&dir.join("energy.csv"), "kinetic+potential").unwrap_or_default();
            times
                .iter()
                .map(|&t| (format!("energy_loss_t{t}"), metrics::energy_loss(&e, t)))
                .collect()
        }
        Metric::DensityFluctuation => vec![(
            "max_density_fluctuation".into(),
            metrics::extreme(&probes("max_density_fluctuation"), 0.0, f64::INFINITY, true),
        )],
        Metric::DensityFluctuationWindow { from, to } => vec![(
            format!("max_density_fluctuation_t{from}-{to}"),
            metrics::extreme(&probes("max_density_fluctuation"), *from, *to, true),
        )],
        Metric::Spatter {
            radius,
            min_neighbours,
        } => {
            let ds = scenario.map_or(f64::NAN, |s| s.spacing);
            let n = final_positions(dir).map_or(f64::NAN, |x| {
                metrics::spattered(&x, radius * ds, *min_neighbours) as f64
            });
            vec![("spattered".into(), n)]
        }
        Metric::Roughness { column, from, to } => vec![(
            format!("{}_total_variation", base(column)),
            metrics::total_variation(&probes(column), *from, *to) / p_scale,
        )],
        Metric::NeighbourRange => vec![
            (
                "neighbours_min".into(),
                metrics::extreme(&probes("neighbours_min"), 0.0, f64::INFINITY, false),
            ),
            (
                "neighbours_max".into(),
                metrics::extreme(&probes("neighbours_max"), 0.0, f64::INFINITY, true),
            ),
        ],
        Metric::Lost => {
            let tank = scenario.and_then(|s| s.spec.tank.as_ref());
            let lost = match (tank, final_positions(dir)) {
                (Some(t), Some(x)) => {
                    let top = if t.open_top {
                        f64::INFINITY
                    } else {
                        t.height.0
                    };
                    metrics::outside(&x, DVec2::ZERO, DVec2::new(t.width.0, top)) as f64
                }
                _ => f64::NAN,
            };
            vec![
                ("lost".into(), lost),
                ("wall_reflections".into(), reflections),
            ]
        }
    }
}
