//! Rolling tank (docs/scenes.md `sloshing`, docs/analytic.md section 4): a tilted tank at rest,
//! sensors riding with the tank, and the roll response against linear theory.

use glam::DVec2;
use sph_core::components::WallPose;
use sph_core::components::{Mass, PressureSensor};
use sph_core::kinematics;
use sph_core::world::Particles;
use sph_study::linear_sloshing::{tilted_tank_moment, RectangularTank};
use sph_tests::stability::{run_hard_case, Bounds, Outcome};
use sph_tests::support::{load, nan_max, run_completed, series};

const TANK: &str = include_str!("../scenarios/rolling_tank.ron");
const FILE: &str = "tests/scenarios/rolling_tank.ron";

/// Mean of a probe column over [from, to].
fn mean(column: &[(f64, f64)], from: f64, to: f64) -> f64 {
    let v: Vec<f64> = column
        .iter()
        .filter(|p| p.0 >= from && p.0 <= to)
        .map(|p| p.1)
        .collect();
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn tilted_tank_at_rest_has_a_level_surface_hydrostatic_sensors_and_the_static_moment() {
    let scenario = load(TANK, FILE, &[]);
    let theta = 6f64.to_radians();
    let (l, ds, rho0, g) = (0.5, scenario.spacing, 1000.0, 9.81);
    let h = 16.0 * ds; // 16 whole rows of ds = 12.5 mm fill the 0.2 m block
    let t1 = 2.0 * std::f64::consts::PI
        / RectangularTank {
            breadth: l,
            depth: h,
            density: rho0,
            gravity: g,
            viscosity: 0.0,
        }
        .natural_frequency(1);
    let (summary, sim, out) = run_completed(scenario, "tilted_tank", 2);
    assert_eq!(summary.diagnostics.get("wall_reflections"), None);
    let probes = out.join("probes.csv");
    // Averages over the last natural period: the tilt is complete at 2.6 s (3 T1), and
    // averaging over T1 removes what is left of the first mode's oscillation.
    let (from, to) = (4.0 - t1, 4.0);
    let avg = |name: &str| mean(&series(&probes, name), from, to);

    // Level surface in the world frame: the gauges (tank frame, 0.46 m apart) differ by
    // tan(theta) * 0.46 = 48 mm. Tolerance 5 % of that (2.4 mm, a fifth of ds): the
    // gauge reads the top particle, whose height settles to within a fraction of ds.
    let rise = avg("eta_left") - avg("eta_right");
    let expected = theta.tan() * 0.46;
    eprintln!("surface rise {rise:.5} m, level surface {expected:.5} m");
    assert!(
        (rise / expected - 1.0).abs() < 0.05,
        "surface rise across the tank {rise:.4} m, level surface needs {expected:.4} m"
    );

    // Sensors against rho_0 g depth, depth below the level surface through the tank
    // centre line at height h (area conservation). 3 % of the local pressure: the
    // hydrostatic test holds 2 % of rho g H with the same kernel; the remaining
    // sloshing adds ~1 % (its amplitude after the smooth ramp is ~3 % of the tilt).
    // The tank and the sensors' walls where the world has them at the final time.
    let pose = kinematics::tank_pose(&sim.world).expect("a tank");
    let level = pose.to_world(DVec2::new(l / 2.0, h)).y;
    for s in sim.world.query::<&PressureSensor>().iter() {
        let at = sim.world.get::<&WallPose>(s.wall).unwrap().point(s.along);
        let exact = rho0 * g * (level - at.y);
        for method in ["shepard", "nearest", "averaged"] {
            let p = avg(&format!("{}.{method}", s.name));
            eprintln!("{} {method}: {p:.1} Pa, rho g depth {exact:.1} Pa", s.name);
            assert!(
                (p / exact - 1.0).abs() < 0.03,
                "{} by {method}: {p:.1} Pa against rho g depth = {exact:.1} Pa",
                s.name
            );
        }
    }

    // Static roll moment about the pivot against the exact moment of the tilted
    // liquid, scaled to the particles' total mass (hydrostatic start densities make it
    // 0.25 % above rho_0 L h). 2 %: the moment is an integral of the weight's lever
    // arm, insensitive to pressure noise, so what is left is the residual sloshing.
    let particles = Particles::of(&sim.world).expect("fluid");
    let mass: f64 = particles.fluid::<Mass>().unwrap().iter().map(|m| m.0).sum();
    let exact = tilted_tank_moment(l, h, theta, 0.0, rho0, g) * mass / (rho0 * l * h);
    let moment = avg("roll_moment");
    eprintln!("roll moment {moment:.4} N m, static {exact:.4} N m");
    assert!(
        (moment / exact - 1.0).abs() < 0.02,
        "roll moment {moment:.3} N m against the static {exact:.3} N m"
    );
    assert!((avg("roll_angle") - 6.0).abs() < 1e-9);
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn sensors_ride_with_the_tank() {
    // A sensor's world position is its tank-frame position carried by the tank's pose:
    // rotated about the pivot and displaced by sway and heave.
    let scenario = load(
        TANK,
        FILE,
        &["tank.motion=(roll: (amplitude: 10.0, period: 1.0), sway: (amplitude: 0.05, period: 2.0), heave: (amplitude: 0.02, period: 0.5), ramp: 0.0)"],
    );
    let sim = scenario.build_sim(std::env::temp_dir());
    let rest: Vec<(String, DVec2)> = scenario
        .spec
        .pressure_sensors
        .iter()
        .map(|s| (s.name.clone(), DVec2::from(s.at)))
        .collect();
    for t in [0.0, 0.13, 0.37, 0.8] {
        kinematics::place(&sim.world, t);
        let (angle, sway, heave) = (
            10f64.to_radians() * (2.0 * std::f64::consts::PI * t).sin(),
            0.05 * (std::f64::consts::PI * t).sin(),
            0.02 * (4.0 * std::f64::consts::PI * t).sin(),
        );
        let pivot = DVec2::new(0.25, 0.0);
        for s in sim.world.query::<&PressureSensor>().iter() {
            let q = rest.iter().find(|r| r.0 == s.name).unwrap().1;
            let expected =
                pivot + DVec2::new(sway, heave) + DVec2::from_angle(angle).rotate(q - pivot);
            let got = sim.world.get::<&WallPose>(s.wall).unwrap().point(s.along);
            assert!(
                (got - expected).length() < 1e-12,
                "{} at t = {t}: {got} vs {expected}",
                s.name
            );
        }
    }
}

/// The first mode where linear theory puts it: the SPH response's vertex within 2 %
/// of linear theory's vertex for the same motion and window, sampled every 0.01
/// sigma_1 around the peak. Measured +1.52 % at this test's h/ds = 12 (the same
/// sweep every 0.01 from 0.90 to 1.10; thinned to 0.02 or 0.03, +1.49 to +1.68 %).
/// Issue 28's acceptance is 1 %: the gap shrinks with resolution, +0.93 % at h/ds 24
/// and +0.59 % at 48 (docs/validation.md), so 1 % is held at h/ds 24 by the ignored
/// `small_roll_response_at_h_over_ds_24_peaks_within_1_percent_of_linear_theory`
/// (9 minutes on 2 shared cores), and this test holds what h/ds 12 reaches.
#[test]
fn small_roll_response_peaks_at_the_first_natural_frequency_and_matches_linear_theory_off_it() {
    small_roll_response("roll_sweep", None, 12, Some(0.02));
}

/// Issue 28's 1 % at h/ds 24: measured +0.93 % (SPH 0.9938 sigma_1, linear theory
/// 0.9847, sampled every 0.01).
#[test]
#[ignore = "long: 11 cases of 40-60 s at h/ds 24 (9 min on 2 shared cores); last measured 2026-12-03: passes, +0.93 %"]
fn small_roll_response_at_h_over_ds_24_peaks_within_1_percent_of_linear_theory() {
    small_roll_response("roll_sweep_24", None, 24, Some(0.01));
}

/// The same sweep with the DFSPH pipeline (docs/physics.md, "DFSPH") in place of the
/// tank's weakly-compressible one: the same walls, viscosity and roll-moment probe.
/// Measured: peak at 0.999 sigma_1, resonant amplitude 17.96 N m (linear theory 16.05,
/// WCSPH 17.7). With `DfsphFactor(continuity_floor: false)` (summation density alone)
/// it fails: the under-dense surface rows carry no pressure, the mode is over-damped
/// (resonant amplitude 6.4 N m) and the fitted peak moves to 0.961 sigma_1
/// (docs/validation.md, "DFSPH").
#[test]
fn small_roll_response_with_dfsph_peaks_at_the_first_natural_frequency() {
    let pipeline = "pipeline=[GhostWalls(slip: FreeSlip, hydrostatic: true), NeighbourGrid(), \
        DfsphFactor(), DivergenceSolve(), Forces(terms: [ArtificialViscosity(alpha: 0.03)]), \
        DensitySolve(), Probe(interval: 0.005, roll_moment: true, plots: false), Advance()]";
    small_roll_response("roll_sweep_dfsph", Some(pipeline), 12, None);
}

/// Roll of 0.5 deg (linear), water depth over ds = `depth_over_ds` (12 or 24), swept
/// across the first mode (sigma_1 = 7.239 rad/s for L = 0.5 m, h = 0.2 m) every 0.01
/// sigma_1 from 0.96 to 1.04 and at 0.7 and 1.3, with `pipeline` replacing the tank's
/// if given. Each case: one-period smooth start, 5 periods to settle, 5 fitted. With
/// `vertex_bound`, the SPH vertex must be within it (a fraction) of linear theory's.
fn small_roll_response(
    tag: &str,
    pipeline: Option<&str>,
    depth_over_ds: u32,
    vertex_bound: Option<f64>,
) {
    let sigma1 = 7.238827;
    let ratios = [
        0.7, 0.96, 0.97, 0.98, 0.99, 1.0, 1.01, 1.02, 1.03, 1.04, 1.3,
    ];
    let omegas: Vec<String> = ratios.iter().map(|r| format!("{}", r * sigma1)).collect();
    let overrides: Vec<sph_scenario::overrides::Override> = [
        format!("resolution=Spacing({})", 0.2 / depth_over_ds as f64),
        "tank.motion=(roll: (amplitude: 0.5, period: 1.0))".to_string(),
        format!(
            "sweep=(omega: [{}], settle_periods: 5.0, fit_periods: 5.0)",
            omegas.join(", ")
        ),
    ]
    .into_iter()
    .chain(pipeline.map(String::from))
    .collect::<Vec<_>>()
    .iter()
    .map(|o| o.parse().unwrap())
    .collect();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/rolling_tank.ron");
    let out = sph_tests::support::temp_out(tag);
    let responses = sph_study::sweep::run_sweep(
        &path,
        &overrides,
        &sph_stages::standard_registry(),
        &out,
        2,
        &|line| eprintln!("{line}"),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(responses.len(), ratios.len());
    assert!(out.join("response.csv").exists() && out.join("response.png").exists());
    let _ = std::fs::remove_dir_all(&out);
    let omega1 = responses[0].omega1;
    assert!((omega1 / sigma1 - 1.0).abs() < 1e-5);

    // Peak of the fitted amplitude: the vertex of the parabola through the largest
    // sample and its neighbours. Within 3 % of sigma_1 (the criterion); the
    // same estimate on linear theory (same start and window) is printed beside it.
    let peak = |amp: &dyn Fn(&sph_study::sweep::Response) -> f64| {
        let k = (1..responses.len() - 1)
            .max_by(|&a, &b| amp(&responses[a]).total_cmp(&amp(&responses[b])))
            .unwrap();
        let (w, a) = (
            [-1, 0, 1].map(|d| responses[(k as i64 + d) as usize].case.omega),
            [-1, 0, 1].map(|d| amp(&responses[(k as i64 + d) as usize])),
        );
        // Vertex of the parabola through three points.
        let num = (w[1] - w[0]).powi(2) * (a[1] - a[2]) - (w[1] - w[2]).powi(2) * (a[1] - a[0]);
        let den = (w[1] - w[0]) * (a[1] - a[2]) - (w[1] - w[2]) * (a[1] - a[0]);
        w[1] - 0.5 * num / den
    };
    let sph_peak = peak(&|r| r.amplitude);
    let linear_peak = peak(&|r| r.linear_amplitude);
    eprintln!(
        "response peak: SPH {:.4} sigma_1, linear theory (same window) {:.4} sigma_1",
        sph_peak / sigma1,
        linear_peak / sigma1
    );
    assert!(
        (sph_peak / sigma1 - 1.0).abs() < 0.03,
        "SPH response peaks at {:.4} sigma_1",
        sph_peak / sigma1
    );
    if let Some(bound) = vertex_bound {
        assert!(
            (sph_peak / linear_peak - 1.0).abs() < bound,
            "SPH vertex {:.4} sigma_1 against linear theory's {:.4}: {:+.2} %",
            sph_peak / sigma1,
            linear_peak / sigma1,
            100.0 * (sph_peak / linear_peak - 1.0)
        );
    }

    // Off resonance (|sigma/sigma_1 - 1| = 0.3, outside docs/analytic.md's +-0.15 band):
    // amplitude within 10 % of linear theory for the same motion, start and fit window
    // (damped by the scheme's equivalent viscosity), phase within 10 degrees.
    // The 10 %: at h/ds = 12 the first-mode frequency is good to ~2 % (the peak above),
    // and the linear amplitude moves 2/|1 - r^2| = 4x (r = 0.7) and 3x (r = 1.3) as
    // fast as sigma_1, so 6-8 %; the fit of the decaying start-up transient adds ~2 %.
    // docs/analytic.md's 5 % presumes h/ds >= 40.
    for r in responses
        .iter()
        .filter(|r| (r.case.omega / sigma1 - 1.0).abs() > 0.25)
    {
        let error = r.amplitude / r.linear_amplitude - 1.0;
        eprintln!(
            "omega {:.3}: amplitude {:.4} vs linear {:.4} N m ({:+.1} %), phase {:.1} vs {:.1} deg",
            r.case.omega,
            r.amplitude,
            r.linear_amplitude,
            100.0 * error,
            r.phase_deg,
            r.linear_phase_deg
        );
        assert!(
            error.abs() < 0.10,
            "omega {}: amplitude error {:.1} %",
            r.case.omega,
            100.0 * error
        );
        assert!((r.phase_deg - r.linear_phase_deg).abs() < 10.0);
    }
}

#[test]
fn a_roll_series_from_csv_drives_the_tank_like_the_harmonic_it_samples() {
    // 4 deg at 1 s period, sampled at 100 Hz; the spline between samples is within
    // 1e-3 deg of the sine, and the run it drives matches the harmonic run's moment.
    let dir = sph_tests::support::temp_out("roll_series");
    std::fs::create_dir_all(&dir).unwrap();
    let mut csv = String::from("# time [s], angle [deg]\ntime,angle\n");
    for i in 0..=100 {
        let t = i as f64 * 0.01;
        csv += &format!("{t},{}\n", 4.0 * (2.0 * std::f64::consts::PI * t).sin());
    }
    std::fs::write(dir.join("roll.csv"), csv).unwrap();
    let scenario_file = dir.join("scenario.ron");
    let common = [
        "resolution=Spacing(0.025)",
        "end_time=0.4",
        "pipeline.probe.interval=0.01",
    ];
    let run = |motion: &str, tag: &str| {
        let mut o: Vec<&str> = common.to_vec();
        o.push(motion);
        let s = load(TANK, scenario_file.to_str().unwrap(), &o);
        let (_, _, out) = run_completed(s, tag, 1);
        let read = (
            series(&out.join("probes.csv"), "roll_angle"),
            series(&out.join("probes.csv"), "roll_moment"),
        );
        let _ = std::fs::remove_dir_all(&out);
        read
    };
    let (angle, moment) = run("tank.motion=(series: \"roll.csv\")", "series_run");
    let (_, harmonic) = run(
        "tank.motion=(roll: (amplitude: 4.0, period: 1.0), ramp: 0.0)",
        "harmonic_run",
    );
    for (t, a) in &angle {
        let exact = 4.0 * (2.0 * std::f64::consts::PI * t).sin();
        assert!((a - exact).abs() < 1e-3, "t = {t}: {a} vs {exact}");
    }
    // Moments agree to 2 % of their range: the series' velocity and acceleration come
    // from the spline (its acceleration is piecewise linear), which the ghosts feel.
    let range = harmonic.iter().map(|p| p.1.abs()).fold(0.0, nan_max);
    for ((t, a), (_, b)) in moment.iter().zip(&harmonic) {
        assert!((a - b).abs() < 0.02 * range, "t = {t}: {a} vs {b}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The long run at resonance: `cargo test --release -p sph-tests --test sloshing -- --ignored --nocapture`.
#[test]
#[ignore = "long: 60 s of simulated time at 810 particles (5.5 min on 2 shared cores); last measured: finished, max |rho/rho0 - 1| 0.100 (the density floor), max speed 4.1 m/s, 18 wall reflections, none outside, none non-finite"]
fn sixty_seconds_at_resonance_stay_stable_and_inside_the_tank() {
    // SPHERIC Test 10 low filling at a coarse ds = 10 mm (9 rows of water), rolled at
    // the first natural period of that depth for 60 s, with the paper's scheme and its
    // patches (scenarios/sloshing_paper.ron: floor, no tension) and the wall treatment:
    // ghosts, plus reflection of the pressureless spray that gets through them
    // (counted in wall_reflections and printed). With `reflect_at_walls: false` a
    // particle passes through the right wall at t = 3.38 s: ghosts alone do not hold
    // spray at resonance (reported in the closing note).
    let ds = 0.9 / 90.0;
    let depth = 9.0 * ds;
    let t1 = 2.0 * std::f64::consts::PI
        / RectangularTank {
            breadth: 0.9,
            depth,
            density: 998.0,
            gravity: 9.81,
            viscosity: 0.0,
        }
        .natural_frequency(1);
    let period = format!("tank.motion.roll.period={t1}");
    let ramp = format!("tank.motion.ramp={t1}");
    let s = run_hard_case(
        include_str!("../../scenarios/sloshing_paper.ron"),
        "scenarios/sloshing_paper.ron",
        &[
            "resolution=ParticlesAcross(90)",
            "end_time=60.0",
            "pipeline.probe.interval=0.01",
            "pipeline.probe.max_speed=true",
            &period,
            &ramp,
        ],
    );
    // The roll moment stays finite throughout (read before the folder is removed).
    if s.outcome == Outcome::Finished {
        let moment = series(&s.out.join("probes.csv"), "roll_moment");
        let bad = moment.iter().find(|p| !p.1.is_finite());
        assert!(bad.is_none(), "roll moment {bad:?}");
    }
    // Finished, every particle inside the tank with finite values, and:
    let bounds = Bounds {
        // Impacts compress the water to 1.12 rho_0 in the shipped 16-row run (the
        // scenario's comment); twice that at resonance. The floor holds rarefied spray
        // at 0.9 rho_0 (the measured 0.100 is that floor).
        density: 0.25,
        // The rolling tank does work on the water: energy is not bounded.
        mechanical_gain: f64::INFINITY,
        total_drift: f64::INFINITY,
        // Three times the ~3 m/s run-up jets c_0 = 30 m/s was chosen for (Mach 0.3).
        max_speed: 9.0,
    };
    s.assert_finished_within(
        &format!("sloshing 18 % at resonance (T1 = {t1:.4} s), 60 s, 90 across"),
        &bounds,
    );
}
