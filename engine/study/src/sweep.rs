//! Frequency sweep of a rolling tank (`sweep: (...)` in a scenario): one run per
//! (filling, omega) case, the roll moment's amplitude and phase at the forcing
//! frequency fitted over the last periods, written to `response.csv` and plotted
//! against linear theory in `response.png`.
//!
//! Cases run side by side, one thread each: a sweep case is small (a few thousand
//! particles), where one thread per case keeps both cores busy without the
//! synchronisation cost of splitting a step, and each case's numbers are the same as a
//! single-threaded run of it.
//!
//! The fit is least squares of M(t) = a sin(omega t) + b cos(omega t) + c over the
//! window; amplitude sqrt(a^2 + b^2) and phase atan2(b, a), the lead of the moment over
//! the roll angle.
//!
//! Linear theory enters twice. The reference each case is judged against is the
//! linear moment for the same motion from the same start at rest
//! ([`RectangularTank::roll_moment_history`]), fitted over the same window: linear
//! theory has no damping, so the first mode excited by the start never dies out and
//! leaks into any finite-window fit; fitting theory and SPH alike compares like with
//! like. Both carry the damping the scheme's artificial viscosity implies (see
//! [`linear_tank`]). The plot also draws the steady-state linear amplitude against
//! omega.

use crate::linear_sloshing::RectangularTank;
use crate::StudyError;
use sph_core::vocab::ArtificialViscosity;
use sph_core::StageRegistry;
use sph_output::plot::{plot_series, Series, Style};
use sph_run::runner::{run, RunError, RunOptions, Summary};
use sph_scenario::overrides::Override;
use sph_scenario::Scenario;
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::Path;

/// One case of a sweep.
#[derive(Clone, Debug)]
pub struct Case {
    /// Still depth over tank width.
    pub filling: f64,
    /// Roll frequency [rad/s].
    pub omega: f64,
    /// Folder name under the sweep's output folder.
    pub name: String,
    /// The overrides that turn the base scenario into this case.
    pub overrides: Vec<Override>,
    /// Start of the fit window [s].
    pub fit_from: f64,
}

/// The fitted response of one case, with linear theory beside it.
#[derive(Clone, Debug)]
pub struct Response {
    pub case: Case,
    /// Roll moment amplitude [N m per m] and phase [deg] fitted from the run.
    pub amplitude: f64,
    pub phase_deg: f64,
    /// Linear theory from rest, fitted over the same window.
    pub linear_amplitude: f64,
    pub linear_phase_deg: f64,
    /// Steady-state linear amplitude and phase (lead over the roll) [deg].
    pub steady_amplitude: f64,
    pub steady_phase_deg: f64,
    /// sigma_1 of linear theory for this filling [rad/s].
    pub omega1: f64,
    pub summary: Summary,
}

/// The sweep's cases from a scenario that has `sweep: (...)`.
pub fn cases(scenario: &Scenario) -> Result<Vec<Case>, StudyError> {
    let spec = &scenario.spec;
    let sweep = spec
        .sweep
        .as_ref()
        .ok_or(StudyError::NotASweep("the scenario has no `sweep`"))?;
    let tank = spec
        .tank
        .as_ref()
        .ok_or(StudyError::NotASweep("a sweep needs a `tank`"))?;
    if tank.motion.as_ref().and_then(|m| m.roll.as_ref()).is_none() {
        return Err(StudyError::NotASweep(
            "a sweep varies the roll frequency: give `tank.motion.roll`",
        ));
    }
    let block = spec
        .fluid_blocks
        .first()
        .ok_or(StudyError::NotASweep("a sweep needs a fluid block"))?;
    let own = block.size.1 .0 / tank.width.0;
    let fillings: Vec<f64> = if sweep.filling.is_empty() {
        vec![own]
    } else {
        sweep.filling.iter().map(|f| f.0).collect()
    };
    let mut out = Vec::new();
    for &filling in &fillings {
        for omega in sweep.omega.iter().map(|w| w.0) {
            let period = 2.0 * PI / omega;
            let end = (sweep.settle_periods.0 + sweep.fit_periods.0) * period;
            let set = |s: String| s.parse::<Override>();
            let mut overrides = vec![
                set(format!("tank.motion.roll.period={period}"))?,
                set(format!("end_time={end}"))?,
            ];
            if !sweep.filling.is_empty() {
                overrides.push(set(format!(
                    "fluid_blocks.0.size=({}, {})",
                    block.size.0 .0,
                    filling * tank.width.0
                ))?);
            }
            out.push(Case {
                filling,
                omega,
                name: format!("filling{filling:.3}_omega{omega:.3}"),
                overrides,
                fit_from: sweep.settle_periods.0 * period,
            });
        }
    }
    Ok(out)
}

/// Least-squares fit of y = a sin(w t) + b cos(w t) + c; returns (amplitude, phase [rad]).
pub fn fit_harmonic(t: &[f64], y: &[f64], omega: f64) -> Option<(f64, f64)> {
    // Normal equations of the 3-parameter linear model, solved by Cramer's rule.
    let mut m = [[0.0; 3]; 3];
    let mut r = [0.0; 3];
    for (&t, &y) in t.iter().zip(y) {
        let f = [(omega * t).sin(), (omega * t).cos(), 1.0];
        for i in 0..3 {
            r[i] += f[i] * y;
            for j in 0..3 {
                m[i][j] += f[i] * f[j];
            }
        }
    }
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&m);
    if t.len() < 3 || d.abs() < 1e-12 {
        return None;
    }
    let solve = |k: usize| {
        let mut mk = m;
        for i in 0..3 {
            mk[i][k] = r[i];
        }
        det(&mk) / d
    };
    let (a, b) = (solve(0), solve(1));
    Some((a.hypot(b), b.atan2(a)))
}

/// Runs every case (`workers` at a time, one thread each) and writes response.csv and
/// response.png into `out_dir`. `overrides` (from the command line) apply to every case.
pub fn run_sweep(
    path: &Path,
    overrides: &[Override],
    registry: &StageRegistry,
    out_dir: &Path,
    workers: usize,
    report: &(dyn Fn(&str) + Sync),
) -> Result<Vec<Response>, StudyError> {
    let base = Scenario::load(path, overrides, registry)?;
    let cases = cases(&base)?;
    std::fs::create_dir_all(out_dir).map_err(|e| StudyError::file(out_dir, e))?;
    let results = crate::parallel::run_parallel(&cases, workers, |i, case| {
        let r = run_case(path, overrides, registry, out_dir, case);
        match &r {
            Ok(r) => report(&format!(
                "case {}/{} {}: amplitude {:.4} N m, phase {:.1} deg (linear theory {:.4} N m, {:.1} deg), {:.1} s wall",
                i + 1,
                cases.len(),
                case.name,
                r.amplitude,
                r.phase_deg,
                r.linear_amplitude,
                r.linear_phase_deg,
                r.summary.wall_seconds
            )),
            Err(e) => report(&format!("case {}/{} {}: {e}", i + 1, cases.len(), case.name)),
        }
        r
    });
    let mut responses = Vec::new();
    let mut failures = Vec::new();
    for r in results {
        match r {
            Ok(r) => responses.push(r),
            Err(e) => failures.push(e),
        }
    }
    write_response(out_dir, &base, &responses)?;
    if failures.is_empty() {
        Ok(responses)
    } else {
        Err(StudyError::CasesFailed {
            total: cases.len(),
            failures,
        })
    }
}

fn run_case(
    path: &Path,
    overrides: &[Override],
    registry: &StageRegistry,
    out_dir: &Path,
    case: &Case,
) -> Result<Response, StudyError> {
    let mut all = overrides.to_vec();
    all.extend(case.overrides.iter().cloned());
    let scenario = Scenario::load(path, &all, registry)?;
    let tank =
        (scenario.spec.tank.clone()).ok_or(StudyError::NotASweep("a sweep needs a `tank`"))?;
    let roll = tank
        .motion
        .as_ref()
        .and_then(|m| m.roll.clone())
        .ok_or(StudyError::NotASweep(
            "a sweep varies the roll frequency: give `tank.motion.roll`",
        ))?;
    let theta_a = roll.amplitude.to_radians();
    let linear = linear_tank(&scenario, case.filling);
    let motion = (scenario.motion.clone()).ok_or(StudyError::NotASweep(
        "a sweep varies the roll frequency: give `tank.motion.roll`",
    ))?;
    let axis_height = tank.pivot().y;
    let dir = out_dir.join(&case.name);
    let opts = RunOptions::quiet(&dir, 1);
    let summary = match run(scenario, &opts) {
        Ok(s) => s,
        Err(RunError::Step { error, .. }) => return Err(StudyError::Unstable { error, dir }),
        Err(e) => return Err(e.into()),
    };
    let (t, m): (Vec<f64>, Vec<f64>) =
        crate::series::read_series(&dir.join("probes.csv"), "roll_moment")
            .map_err(|e| StudyError::Missing {
                error: Box::new(e),
                hint: "add Probe(roll_moment: true)",
            })?
            .into_iter()
            .unzip();
    let theory = linear.roll_moment_history(
        axis_height,
        |s| {
            let st = motion.state(s);
            (st.angle, st.alpha, st.acceleration.x)
        },
        &t,
    );
    let window = t.partition_point(|&s| s < case.fit_from);
    let fit = |y: &[f64]| {
        fit_harmonic(&t[window..], &y[window..], case.omega).ok_or_else(|| {
            StudyError::TooFewSamples {
                path: dir.join("probes.csv"),
                what: "roll_moment".into(),
                from: case.fit_from,
                to: t.last().copied().unwrap_or(f64::NAN),
            }
        })
    };
    let (amplitude, phase) = fit(&m)?;
    let (linear_amplitude, linear_phase) = fit(&theory)?;
    let (re, im) = linear.roll_moment_response(case.omega, axis_height);
    Ok(Response {
        case: case.clone(),
        amplitude,
        phase_deg: phase.to_degrees(),
        linear_amplitude,
        linear_phase_deg: linear_phase.to_degrees(),
        steady_amplitude: theta_a * re.hypot(im),
        steady_phase_deg: im.atan2(re).to_degrees(),
        omega1: linear.natural_frequency(1),
        summary,
    })
}

/// response.csv (one row per case) and response.png (amplitude against omega, one
/// colour per filling, with the linear-theory curves).
fn write_response(
    out_dir: &Path,
    base: &Scenario,
    responses: &[Response],
) -> Result<(), StudyError> {
    let mut csv = String::from(
        "filling,omega,omega_over_omega1,amplitude,phase_deg,linear_amplitude,linear_phase_deg,amplitude_error,steady_amplitude,steady_phase_deg,wall_seconds,steps,particle_steps_per_second\n",
    );
    for r in responses {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.case.filling,
            r.case.omega,
            r.case.omega / r.omega1,
            r.amplitude,
            r.phase_deg,
            r.linear_amplitude,
            r.linear_phase_deg,
            r.amplitude / r.linear_amplitude - 1.0,
            r.steady_amplitude,
            r.steady_phase_deg,
            r.summary.wall_seconds,
            r.summary.steps,
            r.summary.particle_steps_per_second
        );
    }
    let csv_path = out_dir.join("response.csv");
    sph_core::atomic::write_atomic(&csv_path, csv.as_bytes())
        .map_err(|e| StudyError::file(&csv_path, e))?;
    if responses.is_empty() {
        return Ok(());
    }
    let mut series = Vec::new();
    let mut fillings: Vec<f64> = responses.iter().map(|r| r.case.filling).collect();
    fillings.dedup();
    let (lo, hi) = responses
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), r| {
            (lo.min(r.case.omega), hi.max(r.case.omega))
        });
    let top = responses.iter().map(|r| r.amplitude).fold(0.0, f64::max);
    for f in fillings {
        let these: Vec<&Response> = responses.iter().filter(|r| r.case.filling == f).collect();
        series.push(Series {
            name: format!("SPH, h/b = {f:.3}"),
            points: these.iter().map(|r| (r.case.omega, r.amplitude)).collect(),
            style: Style::Points,
        });
        series.push(Series {
            name: format!("linear theory from rest, same window, h/b = {f:.3}"),
            points: these
                .iter()
                .map(|r| (r.case.omega, r.linear_amplitude))
                .collect(),
            style: Style::Points,
        });
        series.push(Series {
            name: format!("linear theory, steady state, h/b = {f:.3}"),
            points: theory_curve(base, f, lo, hi, 2.0 * top),
            style: Style::Line,
        });
    }
    let png = out_dir.join("response.png");
    plot_series(
        &png,
        &format!("{}: roll moment amplitude", base.spec.name),
        "roll frequency omega [rad/s]",
        "moment amplitude [N m / m]",
        &series,
    )
    .map_err(StudyError::from)
}

/// Linear-theory amplitude against omega for filling `f`, cut off above `cap` (it
/// diverges at resonance; NaN breaks the line there).
fn theory_curve(base: &Scenario, f: f64, lo: f64, hi: f64, cap: f64) -> Vec<(f64, f64)> {
    let Some(tank) = &base.spec.tank else {
        return Vec::new();
    };
    let theta_a = tank
        .motion
        .as_ref()
        .and_then(|m| m.roll.as_ref())
        .map_or(0.0, |r| r.amplitude.to_radians());
    let linear = linear_tank(base, f);
    let (lo, hi) = (0.9 * lo, 1.1 * hi);
    (0..=400)
        .map(|i| {
            let w = lo + (hi - lo) * i as f64 / 400.0;
            let (re, im) = linear.roll_moment_response(w, tank.pivot().y);
            let a = theta_a * re.hypot(im);
            (w, if a <= cap { a } else { f64::NAN })
        })
        .collect()
}

/// The linear-theory tank of a case: the depth the particle lattice actually fills
/// (whole rows of ds, see `Scenario::initial_particles`) at filling `f`.
///
/// It is damped by the artificial viscosity's equivalent kinematic viscosity
/// nu = alpha h c_0 / 8 (Monaghan 2005; docs/analytic.md section 4), alpha as the pipeline's
/// momentum stage exposes it ([`ArtificialViscosity`]): the damping the SPH scheme
/// itself applies, so that the transient left by the start decays in theory as it does
/// in the run.
pub fn linear_tank(scenario: &Scenario, f: f64) -> RectangularTank {
    let width = scenario.spec.tank.as_ref().map_or(1.0, |t| t.width.0);
    let ds = scenario.spacing;
    let alpha = scenario
        .exposed::<ArtificialViscosity>()
        .map_or(0.0, |v| v.alpha);
    RectangularTank {
        breadth: width,
        depth: (f * width / ds + 1e-9).floor() * ds,
        density: scenario.spec.fluid.density.0,
        gravity: sph_core::dim::Vector::from(scenario.spec.fluid.gravity).length(),
        viscosity: alpha * scenario.h * scenario.sound_speed / 8.0,
    }
}
