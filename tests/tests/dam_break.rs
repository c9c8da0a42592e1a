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
/// The experiment's gate took time to open, so, as Lethe does and analytic.md
/// section 2 allows, the simulation is delayed by Lethe's 0.175 (in T units) before
/// comparing. Tolerance: analytic.md's suggested +-10 % for 1 <= T <= 3 (digitised data
/// scatter ~1 % of full scale; early T is very sensitive to the gate). Without the
/// delay the front leads the data by 15-20 %.
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

/// P1 (right wall, y = 0.16 m) in the Zhou/Buchner tank at 5,000 particles: the first
/// rise above p/(rho g H) = 0.1 must come at Buchner's t sqrt(g/H) ~ 2.49 (the three
/// digitisations agree to ~1 %), within +-0.1 (4 %; the probe samples every 0.005 s,
/// i.e. 0.02 in t*, and the arrival time depends on the thin tip's resolution).
#[test]
fn p1_first_rise_matches_buchner() {
    let mut overrides = vec!["end_time=0.72"];
    overrides.extend(QUIET);
    let (_, _, out) = run_completed(load(SCENE, "scenarios/dam_break.ron", &overrides), "p1", 2);
    let (g, h): (f64, f64) = (9.81, 0.6);
    let (t_scale, p_scale) = ((g / h).sqrt(), 1000.0 * g * h);
    let rise = |points: &[(f64, f64)]| points.iter().find(|p| p.1 > 0.1).map(|p| p.0);
    let measured = rise(&reference("buchner_2002_P1_pressure_trixi.csv")).expect("data rise");
    assert!((measured - 2.49).abs() < 0.03, "reference rise {measured}");
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
    }
}
