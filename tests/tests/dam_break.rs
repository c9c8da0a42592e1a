//! Dam break validation against measured data (tests/data/SOURCES.md).

use sph_tests::support::{interpolate, load, reference, run_completed, series};

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
    let a: f64 = 0.3;
    let scale = (2.0 * 9.81 / a).sqrt();
    let front: Vec<(f64, f64)> = series(&out.join("probes.csv"), "front")
        .iter()
        .map(|&(t, x)| (t * scale, x / a))
        .collect();
    // Monotone: the front never moves back.
    assert!(
        front.windows(2).all(|w| w[1].1 >= w[0].1 - 1e-9),
        "front moved back"
    );
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
}

/// P1 on the right wall at y = 0.16 H = 0.096 m (Buchner's sensor; an earlier version put
/// it at 0.16 m, where no weakly compressible run, this one included, reads the measured
/// plateau) in the Zhou/Buchner tank at 5,000 particles, t* = t sqrt(g/H), p* = p/(rho g H).
///
/// First rise: above p* = 0.1 at Buchner's t* ~ 2.49 (the three digitisations agree to
/// ~1 %), within +-0.1 (4 %; the probe samples every 0.005 s, i.e. 0.02 in t*, and the
/// arrival time depends on the thin tip's resolution).
///
/// Plateau after the impact: the mean p* over t* 2.7-3.3 must lie within the range the
/// measured P1 itself spans over that window (0.55-0.69 in the TrixiParticles
/// digitisation). The reason: the record is one experiment, digitised to ~1 % of full
/// scale, whose pressure moves by about +-0.07 about its mean there; a simulated mean
/// inside that band is as close as the data resolve the plateau's level. Measured at
/// 0.096 m: 0.57-0.58 for the three methods; at 0.16 m the same run reads 0.11, so the
/// check tells the two heights apart.
///
/// First-impact peak: with the shipped scheme (Fourtakas's density diffusion) the
/// 5 ms transducer mean of Method I (`P1.shepard.transducer`, the probe interval; the
/// data are digitised at 5-20 ms) peaks within 25 % of Buchner's 0.69 over t* 2.3-3.5
/// (the acceptance; measured 0.84 at t* 3.19). Methods II and III miss it
/// (0.99 at 2.84, one particle's acoustic noise; 0.88 at 3.19, the plateau's
/// ringing) and are reported, not held to it (docs/validation.md, "Density
/// treatment").
#[test]
fn p1_rise_and_plateau_match_buchner() {
    // t* = 3.5 is t = 0.867 s.
    let mut overrides = vec!["end_time=0.87"];
    overrides.extend(QUIET);
    let (_, _, out) = run_completed(load(SCENE, "scenarios/dam_break.ron", &overrides), "p1", 2);
    let (g, h): (f64, f64) = (9.81, 0.6);
    let (t_scale, p_scale) = ((g / h).sqrt(), 1000.0 * g * h);
    let rise = |points: &[(f64, f64)]| points.iter().find(|p| p.1 > 0.1).map(|p| p.0);
    let plateau = |points: &[(f64, f64)]| -> Vec<f64> {
        points
            .iter()
            .filter(|p| (2.7..=3.3).contains(&p.0))
            .map(|p| p.1)
            .collect()
    };
    let data = reference("buchner_2002_P1_pressure_trixi.csv");
    let measured = rise(&data).expect("data rise");
    assert!((measured - 2.49).abs() < 0.03, "reference rise {measured}");
    let data_plateau = plateau(&data);
    assert!(data_plateau.len() >= 5, "too few data points in t* 2.7-3.3");
    let low = data_plateau.iter().copied().fold(f64::INFINITY, f64::min);
    let high = data_plateau
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    for method in ["shepard", "nearest", "averaged"] {
        let p1: Vec<(f64, f64)> = series(&out.join("probes.csv"), &format!("P1.{method}"))
            .iter()
            .map(|&(t, p)| (t * t_scale, p / p_scale))
            .collect();
        let simulated =
            rise(&p1).unwrap_or_else(|| panic!("P1.{method} never rose above 0.1 rho g H"));
        assert!(
            (simulated - measured).abs() < 0.1,
            "P1.{method} first rise at t* = {simulated:.3}, Buchner {measured:.3}"
        );
        let samples = plateau(&p1);
        assert!(
            samples.len() >= 10,
            "P1.{method}: too few samples in t* 2.7-3.3"
        );
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        assert!(
            (low..=high).contains(&mean),
            "P1.{method} mean p* over t* 2.7-3.3 = {mean:.3}, Buchner spans {low:.3}-{high:.3}"
        );
    }
    let first_peak = |points: &[(f64, f64)]| {
        points
            .iter()
            .filter(|p| (2.3..=3.5).contains(&p.0))
            .map(|p| p.1)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let measured_peak = first_peak(&data);
    assert!(
        (measured_peak - 0.69).abs() < 0.01,
        "reference peak {measured_peak}"
    );
    {
        let method = "shepard";
        let p1: Vec<(f64, f64)> =
            series(&out.join("probes.csv"), &format!("P1.{method}.transducer"))
                .iter()
                .map(|&(t, p)| (t * t_scale, p / p_scale))
                .collect();
        let peak = first_peak(&p1);
        assert!(
            (peak / measured_peak - 1.0).abs() < 0.25,
            "P1.{method}.transducer first-impact peak {peak:.3}, Buchner {measured_peak:.3}"
        );
    }
}
