//! A run against its scenario's reference data (`reference` in the scenario file):
//! each compared column's normalised mean absolute error over the window, and for an
//! impact its arrival and first peak in both series; `reference.md` and one
//! `reference_<probe>.png` with both curves, beside `probes.csv` (docs/validation.md).

use crate::series::read_series;
use crate::study::metrics::{arrival, nmae, peak};
use crate::StudyError;
use sph_output::plot::{plot_series, Series, Style};
use sph_scenario::scenario::ReferenceSpec;
use sph_scenario::Scenario;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// One column of a run against the reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    /// The `probes.csv` column and the reference file's.
    pub probe: String,
    pub data: String,
    /// [`nmae`] over the window (NaN where the run has no samples in it).
    pub nmae: f64,
    /// Arrival times (run, reference) [s], when the column has an arrival level and
    /// both series reach it.
    pub arrival: Option<(f64, f64)>,
    /// First-impact peaks (run, reference), within `peak_within` of each arrival.
    pub peak: Option<(f64, f64)>,
}

impl Comparison {
    /// The run's arrival relative to the reference's, minus 1.
    pub fn arrival_error(&self) -> Option<f64> {
        self.arrival.map(|(s, r)| s / r - 1.0)
    }
    /// The run's first peak relative to the reference's, minus 1.
    pub fn peak_error(&self) -> Option<f64> {
        self.peak.map(|(s, r)| s / r - 1.0)
    }
}

/// What a `probes.csv` column measures, for a plot's axis: the scenario's pressure
/// sensors and wave gauges, by name.
#[derive(Clone, Debug, Default)]
pub struct ColumnUnits {
    sensors: Vec<String>,
    gauges: Vec<String>,
}

impl ColumnUnits {
    /// The pressure sensors and wave gauges named.
    pub fn new(sensors: Vec<String>, gauges: Vec<String>) -> Self {
        Self { sensors, gauges }
    }

    /// Those of `scenario`.
    pub fn of(scenario: &Scenario) -> Self {
        Self::new(
            scenario
                .spec
                .pressure_sensors
                .iter()
                .map(|s| s.name.clone())
                .collect(),
            scenario
                .spec
                .wave_gauges
                .iter()
                .map(|g| g.name.clone())
                .collect(),
        )
    }

    /// `column` with its unit: a pressure sensor's columns (`P1`, `P1.shepard`,
    /// `P1.shepard.transducer`) in Pa, a wave gauge's (its free-surface elevation) in
    /// m; any other column as named.
    pub fn label(&self, column: &str) -> String {
        let name = column.split('.').next().unwrap_or(column);
        if self.sensors.iter().any(|s| s == name) {
            format!("{column} [Pa]")
        } else if self.gauges.iter().any(|g| g == name) {
            format!("{column} [m]")
        } else {
            column.to_string()
        }
    }
}

/// What a run's `probes.csv` shows against the scenario's reference.
#[derive(Clone, Debug)]
pub struct ReferenceReport {
    pub file: PathBuf,
    pub window: (f64, f64),
    pub rows: Vec<Comparison>,
}

/// Compares `probes` (a run's `probes.csv`) with the reference of `scenario`; None if
/// the scenario names none.
pub fn compare(scenario: &Scenario, probes: &Path) -> Result<Option<ReferenceReport>, StudyError> {
    let (Some(spec), Some(file)) = (&scenario.spec.reference, scenario.reference_file()) else {
        return Ok(None);
    };
    compare_files(spec, &file, probes).map(Some)
}

/// [`compare`] with the reference `spec` and its `file` given.
pub fn compare_files(
    spec: &ReferenceSpec,
    file: &Path,
    probes: &Path,
) -> Result<ReferenceReport, StudyError> {
    let (t0, t1) = spec.window;
    let mut rows = Vec::new();
    for c in &spec.compare {
        let sim = read_series(probes, &c.probe)?;
        let data = read_series(file, &c.data)?;
        let impact = c.arrival.and_then(|level| {
            let s = arrival(&sim, level, t0).filter(|t| *t <= t1)?;
            let r = arrival(&data, level, t0).filter(|t| *t <= t1)?;
            let within = c.peak_within.0;
            Some((
                (s, r),
                (peak(&sim, s, s + within).1, peak(&data, r, r + within).1),
            ))
        });
        rows.push(Comparison {
            probe: c.probe.clone(),
            data: c.data.clone(),
            nmae: nmae(&sim, &data, t0, t1),
            arrival: impact.map(|i| i.0),
            peak: impact.map(|i| i.1),
        });
    }
    Ok(ReferenceReport {
        file: file.to_path_buf(),
        window: spec.window,
        rows,
    })
}

impl ReferenceReport {
    /// One line for the terminal.
    pub fn summary(&self) -> String {
        let parts: Vec<String> = self
            .rows
            .iter()
            .map(|r| {
                let mut s = format!("{} NMAE {:.1} %", r.probe, 100.0 * r.nmae);
                if let (Some(a), Some(p)) = (r.arrival_error(), r.peak_error()) {
                    write!(s, ", arrival {:+.1} %, peak {:+.1} %", 100.0 * a, 100.0 * p).ok();
                }
                s
            })
            .collect();
        format!(
            "against {} over {}-{} s: {}",
            self.file
                .file_name()
                .map_or_else(String::new, |f| f.to_string_lossy().into()),
            self.window.0,
            self.window.1,
            parts.join("; ")
        )
    }

    /// The table of `reference.md`.
    pub fn markdown(&self) -> String {
        let mut md = format!(
            "# Against the reference\n\n{} over {} <= t <= {} s. NMAE: mean |run - reference| over the reference's samples, divided by the reference's largest |value| in the window. Arrival: the first time a series reaches the level; peak: its largest value within the stated time after its arrival.\n\n",
            self.file.display(),
            self.window.0,
            self.window.1
        );
        md.push_str("| probe | reference | NMAE | arrival run / ref [s] | error | first peak run / ref | error |\n|---|---|---|---|---|---|---|\n");
        for r in &self.rows {
            let pair = |p: Option<(f64, f64)>, digits: usize| {
                p.map_or("-".into(), |(s, r)| format!("{s:.digits$} / {r:.digits$}"))
            };
            let pct = |e: Option<f64>| e.map_or("-".into(), |e| format!("{:+.1} %", 100.0 * e));
            writeln!(
                md,
                "| {} | {} | {:.1} % | {} | {} | {} | {} |",
                r.probe,
                r.data,
                100.0 * r.nmae,
                pair(r.arrival, 4),
                pct(r.arrival_error()),
                pair(r.peak, 0),
                pct(r.peak_error())
            )
            .ok();
        }
        md
    }

    /// `reference.md` and `reference_<probe>.png` (run and reference over the window,
    /// the y axis labelled by `units`) into `dir`, which holds the run's `probes.csv`.
    pub fn write(&self, dir: &Path, units: &ColumnUnits) -> Result<(), StudyError> {
        let md = dir.join("reference.md");
        sph_core::atomic::write_atomic(&md, self.markdown().as_bytes())
            .map_err(|e| StudyError::file(&md, e))?;
        let (t0, t1) = self.window;
        let inside = |s: Vec<(f64, f64)>| -> Vec<(f64, f64)> {
            s.into_iter().filter(|p| p.0 >= t0 && p.0 <= t1).collect()
        };
        for r in &self.rows {
            let sim = inside(read_series(&dir.join("probes.csv"), &r.probe)?);
            let data = inside(read_series(&self.file, &r.data)?);
            let png = dir.join(format!("reference_{}.png", r.probe.replace('.', "_")));
            plot_series(
                &png,
                &format!(
                    "{} against {} (NMAE {:.1} %)",
                    r.probe,
                    r.data,
                    100.0 * r.nmae
                ),
                "t [s]",
                &units.label(&r.probe),
                // The reference drawn last, over the run's (often noisier) curve.
                &[
                    Series {
                        name: format!("run {}", r.probe),
                        points: sim,
                        style: Style::Line,
                    },
                    Series {
                        name: format!("reference {}", r.data),
                        points: data,
                        style: Style::Line,
                    },
                ],
            )
            .map_err(|e| StudyError::file(&png, e))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::ColumnUnits;

    /// A sensor's columns read in Pa, a gauge's in m, by the name before the first
    /// dot; a name that only starts like one, or any other column, has no unit.
    #[test]
    fn sensors_read_in_pascals_and_gauges_in_metres() {
        let units = ColumnUnits::new(vec!["P1".into(), "P10".into()], vec!["H2".into()]);
        assert_eq!(units.label("P1"), "P1 [Pa]");
        assert_eq!(
            units.label("P1.shepard.transducer"),
            "P1.shepard.transducer [Pa]"
        );
        assert_eq!(units.label("P10.nearest"), "P10.nearest [Pa]");
        assert_eq!(units.label("H2"), "H2 [m]");
        assert_eq!(units.label("P100"), "P100");
        assert_eq!(units.label("front"), "front");
        assert_eq!(ColumnUnits::default().label("P1"), "P1");
    }
}
