//! Dam break validation against measured data (tests/data/SOURCES.md).

use sph_tests::support::{
    interpolate, load, nan_max, nan_min, reference, run_completed, series, surge_front,
};

const SCENE: &str = include_str!("../../scenarios/dam_break.ron");
const QUIET: [&str; 4] = [
    "pipeline.vtk_frames.interval=10.0",
    "pipeline.snapshots.times=[]",
    "pipeline.probe.plots=false",
    "pipeline.energy.plots=false",
];

/// Surge front of a column of the data's shape (width a = 0.3 m, height 2a: Martin &
/// Moyce's n^2 = 2) in the same 3.22 m tank, against the a = 2.25 in series, whose
/// normalisation SOURCES.md states: T = t sqrt(2g/a), Z = z/a.
///
/// The experiment's gate took time to open, so, as Lethe does, the simulation is
/// delayed by Lethe's 0.175 (in T units) before comparing. Tolerance: +-10 % for
/// 1 <= T <= 3 (digitised data scatter ~1 % of full scale; early T is very sensitive to
/// the gate). Without the delay the front leads the data by 15-20 %.
#[test]
fn surge_front_follows_martin_and_moyce() {
    let mut overrides = vec![
        "fluid_blocks=[(min: (0.0, 0.0), size: (0.3, 0.6))]",
        "resolution=ParticlesAcross(30)",
        "end_time=0.4",
    ];
    overrides.extend(QUIET);
    let (_, _, out) = run_completed(
        load(SCENE, "scenarios/dam_break.ron", &overrides),
        "front",
        2,
    );
    let front = surge_front(&out, 0.3);
    let delay = 0.175;
    let data = reference("martin_moyce_1952_surge_n2-2_a2.25in_pysph.csv");
    let compared: Vec<(f64, f64, f64)> = data
        .iter()
        .filter(|p| (1.0..=3.0).contains(&p.0))
        .map(|&(t, z)| (t, z, interpolate(&front, t - delay)))
        .collect();
    assert!(compared.len() >= 3, "too few data points in the window");
    for (t, z, sim) in compared {
        let err = sim / z - 1.0;
        assert!(
            err.abs() < 0.10,
            "T = {t}: Z = {sim:.3} against {z:.3} ({:+.1} %)",
            100.0 * err
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// The 5,000-particle dam break is chaotic after the impact: time steps that differ by
/// one part in 10^9 give first-impact peaks of 0.84-1.12 rho g H and plateau means
/// that move by 0.1 (docs/validation.md, "P1 realisations"). A single run is one draw,
/// so the P1 checks hold the median over `REALISATIONS` runs whose Courant numbers
/// differ by k 10^-9 (k = 0, 1, ...), a round-off-sized perturbation.
const REALISATIONS: usize = 5;

/// The shipped time-step factor the realisations perturb.
const COURANT: f64 = 0.25;

/// P1 of one realisation, in t* = t sqrt(g/H) and p* = p/(rho g H).
struct P1Run {
    /// First time above p* = 0.1, per method (Shepard, nearest, averaged).
    rise: [f64; 3],
    /// Mean over t* 2.7-3.3, per method.
    plateau: [f64; 3],
    /// Largest 5 ms transducer mean of Method I over t* 2.3-3.5.
    peak: f64,
    /// First time the 5 ms transducer mean of Method I is above p* = 0.1.
    transducer_rise: f64,
}

const METHODS: [&str; 3] = ["shepard", "nearest", "averaged"];

/// Samples of `points` with t* in `window`.
fn within(points: &[(f64, f64)], window: std::ops::RangeInclusive<f64>) -> Vec<f64> {
    points
        .iter()
        .filter(|p| window.contains(&p.0))
        .map(|p| p.1)
        .collect()
}

/// Largest value; NaN if any is NaN, -inf if there is none (either fails a bound).
fn largest(values: &[f64]) -> f64 {
    values.iter().copied().fold(f64::NEG_INFINITY, nan_max)
}

/// The median (NaN if any value is NaN).
fn median(mut values: Vec<f64>) -> f64 {
    if values.is_empty() || values.iter().any(|v| v.is_nan()) {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// Runs the shipped dam break to t* = 3.5 (t = 0.867 s) `REALISATIONS` times.
fn p1_realisations() -> Vec<P1Run> {
    assert!(
        SCENE.contains("Integrate(courant: 0.25)"),
        "COURANT must be the shipped value"
    );
    let (g, h): (f64, f64) = (9.81, 0.6);
    let (t_scale, p_scale) = ((g / h).sqrt(), 1000.0 * g * h);
    (0..REALISATIONS)
        .map(|k| {
            let courant = format!(
                "pipeline.integrate.courant={:?}",
                COURANT * (1.0 + k as f64 * 1e-9)
            );
            let mut overrides = vec!["end_time=0.87", courant.as_str()];
            overrides.extend(QUIET);
            let tag = format!("p1-{k}");
            let (_, _, out) =
                run_completed(load(SCENE, "scenarios/dam_break.ron", &overrides), &tag, 2);
            let p1 = |column: &str| -> Vec<(f64, f64)> {
                series(&out.join("probes.csv"), column)
                    .iter()
                    .map(|&(t, p)| (t * t_scale, p / p_scale))
                    .collect()
            };
            let transducer = p1("P1.shepard.transducer");
            let mut run = P1Run {
                rise: [f64::NAN; 3],
                plateau: [f64::NAN; 3],
                peak: largest(&within(&transducer, 2.3..=3.5)),
                transducer_rise: transducer
                    .iter()
                    .find(|p| p.1 > 0.1)
                    .map_or(f64::NAN, |p| p.0),
            };
            for (m, method) in METHODS.iter().enumerate() {
                let points = p1(&format!("P1.{method}"));
                run.rise[m] = points.iter().find(|p| p.1 > 0.1).map_or(f64::NAN, |p| p.0);
                let samples = within(&points, 2.7..=3.3);
                assert!(
                    samples.len() >= 10,
                    "P1.{method}: too few samples in t* 2.7-3.3"
                );
                run.plateau[m] = samples.iter().sum::<f64>() / samples.len() as f64;
            }
            let _ = std::fs::remove_dir_all(&out);
            run
        })
        .collect()
}

/// Buchner's P1 record (t*, p*).
fn buchner_p1() -> Vec<(f64, f64)> {
    reference("buchner_2002_P1_pressure_trixi.csv")
}

/// P1 on the right wall at y = 0.16 H = 0.096 m (Buchner's sensor; an earlier version put
/// it at 0.16 m, where no weakly compressible run, this one included, reads the measured
/// plateau) in the Zhou/Buchner tank at 5,000 particles, t* = t sqrt(g/H), p* = p/(rho g H);
/// medians over the realisations (see `REALISATIONS`).
///
/// First rise above p* = 0.1 at Buchner's t* ~ 2.49 (the three digitisations agree to
/// ~1 %):
/// - the sensor's own channel, the 5 ms transducer mean of Method I, which takes every
///   step's reading, within 2 % (the acceptance; measured 2.472, -0.7 %, with the
///   shipped Riemann-solver SPH);
/// - the raw samples of every method within +-0.1 (4 %): they are taken every 0.005 s
///   (0.02 in t*) and miss an arrival between two samples (measured 2.574 / 2.533 /
///   2.554, +1.7 % to +3.4 %).
///
/// Plateau after the impact: the mean p* over t* 2.7-3.3 must lie within the range the
/// measured P1 itself spans over that window (0.55-0.69 in the TrixiParticles
/// digitisation). The reason: the record is one experiment, digitised to ~1 % of full
/// scale, whose pressure moves by about +-0.07 about its mean there; a simulated mean
/// inside that band is as close as the data resolve the plateau's level. At 0.16 m the
/// same run reads 0.11, so the check tells the two heights apart. Measured medians
/// 0.590 / 0.597 / 0.576.
#[test]
fn p1_rise_and_plateau_match_buchner() {
    let data = buchner_p1();
    let measured = data.iter().find(|p| p.1 > 0.1).expect("data rise").0;
    assert!((measured - 2.49).abs() < 0.03, "reference rise {measured}");
    let data_plateau = within(&data, 2.7..=3.3);
    assert!(data_plateau.len() >= 5, "too few data points in t* 2.7-3.3");
    let low = data_plateau.iter().copied().fold(f64::INFINITY, nan_min);
    let high = largest(&data_plateau);
    let runs = p1_realisations();
    let rise = median(runs.iter().map(|r| r.transducer_rise).collect());
    assert!(
        (rise / measured - 1.0).abs() < 0.02,
        "P1.shepard.transducer median first rise at t* = {rise:.3}, Buchner {measured:.3}"
    );
    for (m, method) in METHODS.iter().enumerate() {
        let rise = median(runs.iter().map(|r| r.rise[m]).collect());
        assert!(
            (rise - measured).abs() < 0.1,
            "P1.{method} median first rise at t* = {rise:.3}, Buchner {measured:.3}"
        );
        let mean = median(runs.iter().map(|r| r.plateau[m]).collect());
        assert!(
            (low..=high).contains(&mean),
            "P1.{method} median mean p* over t* 2.7-3.3 = {mean:.3}, Buchner spans {low:.3}-{high:.3}"
        );
    }
}

/// First-impact peak: the 5 ms transducer mean of Method I (`P1.shepard.transducer`,
/// the probe interval; the data are digitised at 5-20 ms) peaks over t* 2.3-3.5 within
/// 20 % of Buchner's 0.69, as the median over the realisations. Measured with the
/// shipped Riemann-solver SPH: median 0.776 (+12.5 %; realisations 0.758-0.852); the
/// bound leaves room for the realisations' spread on another instruction set (their
/// median moves with the round-off draws), not for the +41 % (0.97) of Fourtakas's
/// diffusion, which fails it. Issue 27's 10 % is not met (docs/validation.md, "Dam
/// break P1"). Methods II and III read one particle's acoustic noise and the plateau's
/// ringing and are reported, not held to it.
#[test]
fn p1_first_impact_peak_within_a_fifth_of_buchner() {
    let data = buchner_p1();
    let measured_peak = largest(&within(&data, 2.3..=3.5));
    assert!(
        (measured_peak - 0.69).abs() < 0.01,
        "reference peak {measured_peak}"
    );
    let peaks: Vec<f64> = p1_realisations().iter().map(|r| r.peak).collect();
    let peak = median(peaks.clone());
    assert!(
        (peak / measured_peak - 1.0).abs() < 0.20,
        "P1.shepard.transducer median first-impact peak {peak:.3} (realisations {peaks:.3?}), Buchner {measured_peak:.3}"
    );
}
