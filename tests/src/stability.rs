//! Hard-case runs (issue 5): run a scenario and report how it ended and how well it
//! behaved: finished, stopped with a diagnostic, or panicked; the largest density
//! fluctuation, the mechanical-energy gain and total-energy drift, particles outside
//! the walls or the domain and non-finite values at the end.

use crate::support::{load, nan_max, read_csv, temp_out};
use sph_core::components::{Density, Position, Velocity};
use sph_core::walls::Walls;
use sph_core::world::Particles;
use sph_run::runner::{run_keeping_state, RunOptions};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

/// How a run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// Reached its end time.
    Finished,
    /// Stopped early with this diagnostic (the runner's error message).
    Stopped(String),
    /// Panicked, with the panic message: always a failure.
    Panicked(String),
}

/// What a hard-case run measured. Energies are relative to `energy_scale` = M |g| H
/// (total mass, gravity, the tallest block's height): the potential energy the column
/// would lose falling its own height.
#[derive(Clone, Debug)]
pub struct Stability {
    pub outcome: Outcome,
    /// Simulated time reached [s] (the last energy sample's time if the run stopped).
    pub time: f64,
    /// Largest |rho/rho_0 - 1| over the probe samples (`max_density_fluctuation`).
    pub density_fluctuation: f64,
    /// Largest rise of kinetic + potential energy above its first sample, over
    /// `energy_scale`: a run without inflow of energy (fixed walls) must not gain any.
    pub mechanical_gain: f64,
    /// Largest |total - total(first sample)| over `energy_scale`, total = kinetic +
    /// potential + internal + dissipated by viscosity (energy.csv `total`).
    pub total_drift: f64,
    /// Largest speed over the probe samples [m/s] (`max_speed`; infinite if not probed,
    /// so that a finite bound on it fails).
    pub max_speed: f64,
    /// At the end: fluid particles behind a wall or past a corner, or outside the domain.
    pub outside: usize,
    /// At the end: fluid particles with a non-finite position, velocity or density.
    pub non_finite: usize,
    /// Particles reflected back across a wall (summary `wall_reflections`).
    pub reflections: f64,
    pub particles: usize,
    pub energy_scale: f64,
    pub out: PathBuf,
}

/// Overrides that keep a run's output cheap (no frames, pictures or plots), for the
/// stages the scenario text has.
pub fn quiet(text: &str) -> Vec<&'static str> {
    [
        ("VtkFrames(", "pipeline.vtk_frames.interval=1e9"),
        ("Snapshots(", "pipeline.snapshots.times=[]"),
        ("Probe(", "pipeline.probe.plots=false"),
        ("Energy(", "pipeline.energy.plots=false"),
    ]
    .into_iter()
    .filter(|(stage, _)| text.contains(stage))
    .map(|(_, o)| o)
    .collect()
}

/// Runs scenario `text` (`file` names it in messages) with `overrides` on two threads
/// and measures it. The scenario must have an `Energy` stage and a `Probe` with
/// `density_fluctuation: true` (checked).
pub fn run_hard_case(text: &str, file: &str, overrides: &[&str]) -> Stability {
    let mut all: Vec<&str> = overrides.to_vec();
    all.extend(quiet(text));
    let scenario = load(text, file, &all);
    let mass: f64 = scenario.initial_particles().iter().map(|p| p.2).sum();
    let g = glam::DVec2::from(scenario.spec.fluid.gravity).length();
    let energy_scale = mass * g * scenario.fluid_height();
    let particles = scenario.initial_particles().len();
    let out = temp_out(&scenario.spec.name);
    let opts = RunOptions::quiet(&out, 2);
    let result = catch_unwind(AssertUnwindSafe(|| run_keeping_state(scenario, &opts)));
    let (outcome, end, reflections) = match result {
        Err(panic) => {
            let message = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            (Outcome::Panicked(message), None, 0.0)
        }
        Ok(Err(e)) => (Outcome::Stopped(e.to_string()), None, 0.0),
        Ok(Ok((summary, sim))) => {
            let reflections = summary
                .diagnostics
                .get("wall_reflections")
                .copied()
                .unwrap_or(0.0);
            (Outcome::Finished, Some(final_state(&sim)), reflections)
        }
    };
    let (outside, non_finite) = end.unwrap_or((0, 0));
    let mut s = Stability {
        outcome,
        time: 0.0,
        density_fluctuation: 0.0,
        mechanical_gain: 0.0,
        total_drift: 0.0,
        max_speed: 0.0,
        outside,
        non_finite,
        reflections,
        particles,
        energy_scale,
        out,
    };
    if !matches!(s.outcome, Outcome::Panicked(_)) {
        s.read_outputs();
    }
    s
}

/// (outside, non-finite) fluid particles in the final state.
fn final_state(sim: &sph_core::Sim) -> (usize, usize) {
    let Some(particles) = Particles::of(&sim.world) else {
        return (0, 0);
    };
    let (x, v, rho) = (
        particles.fluid::<Position>().expect("positions"),
        particles.fluid::<Velocity>().expect("velocities"),
        particles.fluid::<Density>().expect("densities"),
    );
    // The walls where the world has them at the final time.
    let walls = Walls::of(&sim.world);
    let (lo, hi) = sim.constants.domain;
    let reach = sim.constants.support();
    let outside = x
        .iter()
        .filter(|p| {
            walls.crossed(p.0, reach).is_some() || p.0.cmplt(lo).any() || p.0.cmpgt(hi).any()
        })
        .count();
    let non_finite = (0..x.len())
        .filter(|&i| !(x[i].0.is_finite() && v[i].0.is_finite() && rho[i].0.is_finite()))
        .count();
    (outside, non_finite)
}

impl Stability {
    fn read_outputs(&mut self) {
        let column = |path: &Path, name: &str| -> Option<Vec<(f64, f64)>> {
            let (header, rows) = read_csv(path);
            let k = header.iter().position(|h| h == name)?;
            Some(rows.iter().map(|r| (r[0], r[k])).collect())
        };
        let energy = self.out.join("energy.csv");
        let (kinetic, potential, total) = (
            column(&energy, "kinetic").expect("the scenario needs an Energy stage"),
            column(&energy, "potential").expect("potential"),
            column(&energy, "total").expect("total"),
        );
        let probes = self.out.join("probes.csv");
        let rho = column(&probes, "max_density_fluctuation")
            .expect("the scenario needs Probe(density_fluctuation: true)");
        // The bound is on every particle: the flow's figure and the guarded particles'.
        let guarded = column(&probes, "guarded_density_fluctuation").unwrap_or_default();
        // NaN-propagating: a NaN sample makes the measure NaN (then infinite, below).
        let max = |s: &[(f64, f64)]| s.iter().map(|p| p.1).fold(0.0, nan_max);
        self.density_fluctuation = nan_max(max(&rho), max(&guarded));
        // A missing column is no measurement: NaN, so unbounded below (a finite bound on
        // it fails, naming the speed, rather than passing on a zero).
        self.max_speed = column(&probes, "max_speed").map_or(f64::NAN, |s| max(&s));
        self.time = total.last().map_or(0.0, |p| p.0);
        let mechanical: Vec<f64> = kinetic
            .iter()
            .zip(&potential)
            .map(|(k, p)| k.1 + p.1)
            .collect();
        if let (Some(&m0), Some(&t0)) = (mechanical.first(), total.first()) {
            self.mechanical_gain = mechanical
                .iter()
                .map(|m| (m - m0) / self.energy_scale)
                .fold(0.0, nan_max);
            self.total_drift = total
                .iter()
                .map(|t| ((t.1 - t0.1) / self.energy_scale).abs())
                .fold(0.0, nan_max);
        }
        // A non-finite sample counts as unbounded (and fails any finite bound).
        for v in [
            &mut self.density_fluctuation,
            &mut self.mechanical_gain,
            &mut self.total_drift,
            &mut self.max_speed,
        ] {
            if v.is_nan() {
                *v = f64::INFINITY;
            }
        }
    }

    /// One line for test output and docs/validation.md.
    pub fn report(&self, case: &str) -> String {
        let outcome = match &self.outcome {
            Outcome::Finished => "finished".to_string(),
            Outcome::Stopped(m) => format!("stopped: {m}"),
            Outcome::Panicked(m) => format!("PANICKED: {m}"),
        };
        format!(
            "{case}: {} particles, t = {:.3} s, max |rho/rho0-1| = {:.4}, mechanical gain = {:.2e}, \
             total drift = {:.2e} (of M g H = {:.4} J/m), max speed = {:.3} m/s, reflections = {}, \
             outside = {}, non-finite = {}; {outcome}",
            self.particles,
            self.time,
            self.density_fluctuation,
            self.mechanical_gain,
            self.total_drift,
            self.energy_scale,
            self.max_speed,
            self.reflections,
            self.outside,
            self.non_finite,
        )
    }

    /// Asserts the run finished with every particle inside and finite, and within the
    /// bounds; leaves the output folder for inspection on failure, removes it otherwise.
    pub fn assert_finished_within(&self, case: &str, bounds: &Bounds) {
        let report = self.report(case);
        eprintln!("{report}");
        assert_eq!(self.outcome, Outcome::Finished, "{report}");
        assert_eq!(self.outside, 0, "{report}");
        assert_eq!(self.non_finite, 0, "{report}");
        self.assert_bounds(&report, bounds);
        let _ = std::fs::remove_dir_all(&self.out);
    }

    fn assert_bounds(&self, report: &str, b: &Bounds) {
        let checks = [
            ("max |rho/rho0 - 1|", self.density_fluctuation, b.density),
            ("mechanical gain", self.mechanical_gain, b.mechanical_gain),
            ("total drift", self.total_drift, b.total_drift),
            ("max speed", self.max_speed, b.max_speed),
        ];
        for (what, value, bound) in checks {
            assert!(
                value <= bound,
                "{what} = {value:.4e} exceeds {bound:.4e}\n{report}\n(outputs in {})",
                self.out.display()
            );
        }
    }

    /// Asserts either of the acceptable ends: finished within `bounds` (as
    /// [`Stability::assert_finished_within`]), or stopped with a located diagnostic.
    pub fn assert_finished_within_or_stopped(&self, case: &str, bounds: &Bounds) {
        match self.outcome {
            Outcome::Stopped(_) => {
                self.assert_stopped_with_diagnostic(case);
            }
            _ => self.assert_finished_within(case, bounds),
        }
    }

    /// Asserts the run stopped with the foundation issue's diagnostic: it names when
    /// (step and time) and where (particle and position, or wall) it stopped.
    pub fn assert_stopped_with_diagnostic(&self, case: &str) -> &str {
        let report = self.report(case);
        eprintln!("{report}");
        let Outcome::Stopped(message) = &self.outcome else {
            panic!("expected a stop with a diagnostic: {report}");
        };
        for part in ["step ", ", t = ", " s, stage `", " at x = ", " m, y = "] {
            assert!(
                message.contains(part),
                "diagnostic lacks `{part}`: {message}"
            );
        }
        let _ = std::fs::remove_dir_all(&self.out);
        message
    }
}

/// Upper bounds for [`Stability`]'s measures (`f64::INFINITY`: not bounded).
#[derive(Clone, Copy, Debug)]
pub struct Bounds {
    pub density: f64,
    pub mechanical_gain: f64,
    pub total_drift: f64,
    pub max_speed: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run's outputs with a NaN in one probe or energy sample among finite ones.
    fn with_nan_in(file: &str, column: usize) -> Stability {
        with_outputs(file, column, true)
    }

    /// The same, with or without the `max_speed` column in probes.csv.
    fn with_outputs(file: &str, column: usize, speed: bool) -> Stability {
        let out = temp_out("stability-nan");
        std::fs::create_dir_all(&out).unwrap();
        let mut energy = vec![
            "time,kinetic,potential,internal,viscous,total".to_string(),
            "0,0,10,0,0,10".into(),
            "0.1,1,9,0,0,10".into(),
            "0.2,0.5,9.5,0,0,10".into(),
        ];
        let mut probes = vec![
            "time,max_density_fluctuation,max_speed".to_string(),
            "0,0.01,0".into(),
            "0.1,0.02,1".into(),
            "0.2,0.01,0.5".into(),
        ];
        let rows = match file {
            "energy.csv" => Some(&mut energy),
            "probes.csv" => Some(&mut probes),
            _ => None,
        };
        if let Some(rows) = rows {
            let mut cells: Vec<String> = rows[2].split(',').map(str::to_string).collect();
            cells[column] = "NaN".into();
            rows[2] = cells.join(",");
        }
        std::fs::write(out.join("energy.csv"), energy.join("\n") + "\n").unwrap();
        if !speed {
            for row in &mut probes {
                *row = row
                    .rsplit_once(',')
                    .map_or(row.clone(), |r| r.0.to_string());
            }
        }
        std::fs::write(out.join("probes.csv"), probes.join("\n") + "\n").unwrap();
        let mut s = Stability {
            outcome: Outcome::Finished,
            time: 0.0,
            density_fluctuation: 0.0,
            mechanical_gain: 0.0,
            total_drift: 0.0,
            max_speed: 0.0,
            outside: 0,
            non_finite: 0,
            reflections: 0.0,
            particles: 1,
            energy_scale: 10.0,
            out,
        };
        s.read_outputs();
        let _ = std::fs::remove_dir_all(&s.out);
        s
    }

    /// The NaN guard fires: a NaN sample in any measured column makes its measure
    /// infinite, and the bound check fails on it (`f64::max` dropped such a NaN and
    /// the measure came out as the other samples' largest).
    #[test]
    fn a_nan_sample_fails_the_bounds() {
        let finite = with_nan_in("neither", 0);
        assert_eq!(finite.density_fluctuation, 0.02);
        assert_eq!(finite.max_speed, 1.0);
        let bounds = Bounds {
            density: 1.0,
            mechanical_gain: 1.0,
            total_drift: 1.0,
            max_speed: 10.0,
        };
        finite.assert_bounds("finite", &bounds);
        let cases = [
            ("probes.csv", 1, "max |rho/rho0 - 1|"),
            ("probes.csv", 2, "max speed"),
            ("energy.csv", 1, "mechanical gain"),
            ("energy.csv", 5, "total drift"),
        ];
        for (file, column, measure) in cases {
            let s = with_nan_in(file, column);
            let failed = std::panic::catch_unwind(|| s.assert_bounds("nan", &bounds)).expect_err(
                &format!("a NaN in {file} column {column} passed the bounds"),
            );
            let message = failed.downcast_ref::<String>().cloned().unwrap_or_default();
            assert!(
                message.starts_with(&format!("{measure} = inf")),
                "{file} column {column}: {message}"
            );
        }
    }

    /// A probes.csv without `max_speed` is no measurement of the speed: a finite bound
    /// on it fails (it read 0 and always passed), an infinite one does not.
    #[test]
    fn a_missing_speed_column_fails_a_speed_bound() {
        let s = with_outputs("neither", 0, false);
        assert_eq!(s.density_fluctuation, 0.02);
        assert_eq!(s.max_speed, f64::INFINITY);
        let mut bounds = Bounds {
            density: 1.0,
            mechanical_gain: 1.0,
            total_drift: 1.0,
            max_speed: 10.0,
        };
        let failed = std::panic::catch_unwind(|| s.assert_bounds("missing", &bounds))
            .expect_err("a missing max_speed column passed a speed bound");
        let message = failed.downcast_ref::<String>().cloned().unwrap_or_default();
        assert!(message.starts_with("max speed = inf"), "{message}");
        bounds.max_speed = f64::INFINITY;
        s.assert_bounds("unbounded", &bounds);
    }
}
