//! The divergence-free SPH pipeline (docs/physics.md, "DFSPH") on still water
//! (scenarios/hydrostatic_dfsph.ron, docs/analytic.md section 1): the solved pressure
//! matches rho_0 g (H - y), the density stays within the solve's tolerance of rho_0,
//! the start-up transient decays and no particle reaches a wall. The thread-count and
//! resume tests of the pipeline are in threads.rs and restart.rs.

use sph_core::components::{Density, Position, Pressure};
use sph_core::world::Particles;
use sph_tests::support::{
    interpolate, load, nan_max, reference, run_completed, series, surge_front,
};

const SCENE: &str = include_str!("../../scenarios/hydrostatic_dfsph.ron");
const DAM_BREAK_DFSPH: &str = include_str!("../../scenarios/dam_break_dfsph.ron");
const DAM_BREAK: &str = include_str!("../../scenarios/dam_break.ron");

/// The surge front of Martin & Moyce's column (a = 0.3 m, n^2 = 2, 5,000 particles, to
/// t = 0.62 s, the outputs off) in `scene`, with `extra` overrides: the mean
/// |Z/Z_data - 1| over the data with 1 <= T, without a start delay, and the run's
/// density-solve steps (`density_solve.csv`: t, dt), empty for WCSPH.
fn column_front(scene: &str, path: &str, tag: &str, extra: &[&str]) -> (f64, Vec<(f64, f64)>) {
    let mut overrides = vec![
        "fluid_blocks=[(min: (0.0, 0.0), size: (0.3, 0.6))]",
        "resolution=ParticlesAcross(50)",
        "end_time=0.62",
        "pipeline.vtk_frames.interval=10.0",
        "pipeline.snapshots.times=[]",
        "pipeline.probe.plots=false",
    ];
    overrides.extend_from_slice(extra);
    let (_, _, out) = run_completed(load(scene, path, &overrides), tag, 2);
    let front = surge_front(&out, 0.3);
    let steps = match out.join("density_solve.csv").exists() {
        true => series(&out.join("density_solve.csv"), "dt"),
        false => Vec::new(),
    };
    let _ = std::fs::remove_dir_all(&out);
    let t_end = front.last().expect("front samples").0;
    let errors: Vec<f64> = reference("martin_moyce_1952_surge_n2-2_a2.25in_pysph.csv")
        .iter()
        .filter(|p| p.0 >= 1.0 && p.0 <= t_end)
        .map(|&(t, z)| (interpolate(&front, t) / z - 1.0).abs())
        .collect();
    assert!(errors.len() >= 5, "too few data points: {errors:?}");
    (errors.iter().sum::<f64>() / errors.len() as f64, steps)
}

/// The start-up ramp (`DensitySolve(growth)`, docs/validation.md, "The start-up ramp"):
/// the first step of a dam at rest is set by the acceleration at the foot of its free
/// face, 0.25 sqrt(h / a_0) with a_0 about g H / ds (0.71 ms here), not the 5 ms cap,
/// and each step grows by at most 1.2. With the first steps resolved, DFSPH's front
/// against Martin & Moyce is within 1 point of WCSPH's (issue 30's target): measured
/// 15.35 % against 15.87 %. Without the ramp DFSPH's first step kicks the front and it
/// reads 13.8 %, a gap that grows with resolution (27.3 % at 20,000 particles).
#[test]
fn dfsph_starts_a_dam_break_with_the_steps_its_free_face_needs() {
    let tolerance = ["pipeline.density_solve.tolerance=0.005"];
    let (dfsph, steps) = column_front(
        DAM_BREAK_DFSPH,
        "scenarios/dam_break_dfsph.ron",
        "dfsph-ramp-column",
        &tolerance,
    );
    let (wcsph, _) = column_front(
        DAM_BREAK,
        "scenarios/dam_break.ron",
        "dfsph-ramp-wcsph",
        &[],
    );
    let (h, g, height, ds): (f64, f64, f64, f64) = (1.3 * 0.006, 9.81, 0.6, 0.006);
    // The first step 0.25 sqrt(h / a_0) with a_0 within a factor 2 of g H / ds
    // (measured 0.747 ms: a_0 = 0.89 g H / ds).
    let first = steps[0].1;
    let at = |a0: f64| 0.25 * (h / a0).sqrt();
    let a_face = g * height / ds;
    assert!(
        first >= at(2.0 * a_face) && first <= at(0.5 * a_face),
        "first step {first} s, against {} s at g H / ds",
        at(a_face)
    );
    for w in steps.windows(2) {
        assert!(
            w[1].1 <= 1.2 * w[0].1 * (1.0 + 1e-12),
            "a step grew from {} to {} s at t = {}",
            w[0].1,
            w[1].1,
            w[1].0
        );
    }
    assert!(
        (dfsph - wcsph).abs() <= 0.01,
        "front error DFSPH {:.2} %, WCSPH {:.2} %",
        100.0 * dfsph,
        100.0 * wcsph
    );
}

#[test]
fn dfsph_still_water_holds_hydrostatic_pressure_at_rest_density() {
    let scenario = load(
        SCENE,
        "scenarios/hydrostatic_dfsph.ron",
        &[
            "end_time=3.0",
            "pipeline.vtk_frames.interval=10.0",
            "pipeline.probe.plots=false",
        ],
    );
    let (rho0, g, h): (f64, f64, f64) = (1000.0, 9.81, 0.6);
    let support = scenario.spec.kernel.support_factor() * scenario.h;
    let (summary, sim, out) = run_completed(scenario, "dfsph-hydrostatic", 2);
    let d = &summary.diagnostics;
    assert_eq!(d.get("wall_reflections"), None, "{d:?}");

    // Pressure: below the surface layer (two supports deep), the mean pressure of each
    // 5 cm layer within 1 % of rho_0 g H of rho_0 g (H - y) at the layer's mean depth,
    // the tolerance. (The kernel's discrete gradient moment, 0.997 for
    // Wendland at h/ds = 1.5 and 0.9992 at 2.0, biases the equilibrium by ~0.3 % or
    // less.) The layers, not each
    // particle: the Jacobi solve stops at a mean density error of 0.1 %, which leaves
    // each particle's pressure scattered about the profile (RMS ~1 %, the worst 2 % of
    // rho_0 g H, docs/validation.md, "DFSPH"); that scatter is checked below 2 %.
    let particles = Particles::of(&sim.world).expect("fluid");
    let (x, p, rho) = (
        particles.fluid::<Position>().unwrap(),
        particles.fluid::<Pressure>().unwrap(),
        particles.fluid::<Density>().unwrap(),
    );
    let scale = rho0 * g * h;
    let layers = 10;
    let mut bins = vec![(0.0, 0.0, 0usize); layers];
    let (mut square, mut excess, mut inside) = (0.0, 0.0, 0);
    for ((x, p), rho) in x.iter().zip(p.iter()).zip(rho.iter()) {
        let y = x.0.y;
        if y < h - 2.0 * support {
            let b = ((y / 0.05) as usize).min(layers - 1);
            bins[b] = (bins[b].0 + p.0, bins[b].1 + y, bins[b].2 + 1);
            square += ((p.0 - rho0 * g * (h - y)) / scale).powi(2);
            inside += 1;
        }
        excess += (rho.0 / rho0 - 1.0).max(0.0);
    }
    for (k, &(p, y, n)) in bins.iter().enumerate().filter(|b| b.1 .2 > 0) {
        let (p, y) = (p / n as f64, y / n as f64);
        let err = (p - rho0 * g * (h - y)).abs() / scale;
        assert!(
            err < 0.01,
            "layer {k} (mean y = {y:.3} m, {n} particles): mean pressure {p:.1} Pa, error {:.2} % of rho g H",
            100.0 * err
        );
    }
    let scatter = (square / inside as f64).sqrt();
    assert!(
        scatter < 0.02,
        "per-particle pressure scatter {:.2} % of rho g H",
        100.0 * scatter
    );
    // Density: the mean compression max(rho/rho_0 - 1, 0) over the fluid (the solve's
    // own error measure, applied to the summation densities the last step started
    // from, after the step before moved the particles; the under-dense free surface
    // counts 0) within the solve's tolerance, 0.1 %; and hardly a step left at the
    // iteration cap.
    let mean = excess / x.len() as f64;
    assert!(mean < 1e-3, "mean density error {:.3} %", 100.0 * mean);
    // Every step after the start-up (the first 0.05 s, while the halved warm start
    // rebuilds the hydrostatic pressure) converged within the cap, to the tolerance.
    let solve = out.join("density_solve.csv");
    let capped = d["density_solve_unconverged"];
    // Still water's pressures balance gravity, so the start-up ramp (which sizes the
    // first step by the starting state's largest acceleration) starts it at the cap.
    let first = series(&solve, "dt")[0].1;
    assert_eq!(first, 0.005, "first step {first} s");
    for ((t, iterations), (_, error)) in series(&solve, "iterations")
        .into_iter()
        .zip(series(&solve, "error"))
    {
        if t > 0.05 {
            assert!(
                iterations < 100.0 && error <= 1e-3,
                "t = {t}: {iterations} iterations, error {error} ({capped} steps capped)"
            );
        }
    }

    // The bottom and side sensors after the start-up (0.3 s): the time mean within 1 %
    // of rho_0 g H by every method; each sample within 2 %, since the sensors also
    // read the particles' scatter (Methods I and III average it over a few particles,
    // Method II reads the nearest one; the samples stray up to 1-1.5 %,
    // docs/validation.md, "DFSPH").
    let probes = out.join("probes.csv");
    for (sensor, depth) in [("bottom", h), ("side", h - 0.3)] {
        for method in ["shepard", "nearest", "averaged"] {
            let samples: Vec<(f64, f64)> = series(&probes, &format!("{sensor}.{method}"))
                .into_iter()
                .filter(|s| s.0 > 0.3)
                .collect();
            let mean = samples.iter().map(|s| s.1).sum::<f64>() / samples.len() as f64;
            let err = (mean - rho0 * g * depth).abs() / scale;
            assert!(
                err < 0.01,
                "{sensor}.{method}: mean {mean} Pa, error {:.2} %",
                100.0 * err
            );
            for (t, value) in samples {
                let err = (value - rho0 * g * depth).abs() / scale;
                assert!(
                    err < 0.02,
                    "{sensor}.{method} at t = {t}: {value} Pa, error {:.2} %",
                    100.0 * err
                );
            }
        }
    }

    // Speeds: the start-up transient (the lattice settling under the solved pressure)
    // decays tenfold within 0.2 s, and the water stays still to 0.1 % of sqrt(g H)
    // (2.4 mm/s) after it, for the 3 s (measured 0.2 mm/s). This bound fails for the
    // modes that grow from round-off and show from about 2.4 s: at h/ds 1.5 (rows
    // sliding, 0.025 m/s by 3 s), and without the continuity floor (the surface rows,
    // 0.033 m/s by 3 s; docs/validation.md, "DFSPH").
    let speed = series(&probes, "max_speed");
    let peak = |from: f64, to: f64| {
        speed
            .iter()
            .filter(|s| s.0 >= from && s.0 <= to)
            .map(|s| s.1)
            .fold(0.0, nan_max)
    };
    let (start, settled) = (peak(0.0, 0.05), peak(0.15, 0.25));
    assert!(
        settled < 0.1 * start,
        "start-up speed {start} m/s decayed only to {settled} m/s"
    );
    let bound = 0.001 * (g * h).sqrt();
    let later = peak(0.15, 10.0);
    assert!(later < bound, "max speed {later} m/s exceeds {bound} m/s");
    let _ = std::fs::remove_dir_all(&out);
}

/// At h/ds = 2.0 the Wendland kernel reaches 44 neighbours, and the relaxed Jacobi
/// update with the scenarios' omega = 0.5 diverges: on the square lattice the solve's
/// largest eigenvalue (relative to alpha_i's diagonal) is 5.68, so omega must stay below
/// 2 / 5.68 = 0.352 (`pressure_solve::jacobi_bound`; its unit test checks that figure
/// against a power iteration). Without the cap this run stopped at step 2 with a
/// particle thrown out of the tank. With it the solves use 0.85 x 0.352 = 0.299 and
/// the still water holds its pressure.
#[test]
fn dfsph_still_water_runs_at_h_over_ds_2_with_the_relaxation_capped() {
    let scenario = load(
        SCENE,
        "scenarios/hydrostatic_dfsph.ron",
        &[
            "h_over_dx=2.0",
            "end_time=0.5",
            "pipeline.vtk_frames.interval=10.0",
            "pipeline.probe.plots=false",
        ],
    );
    let (rho0, g, h): (f64, f64, f64) = (1000.0, 9.81, 0.6);
    let (summary, _, out) = run_completed(scenario, "dfsph-hydrostatic-h2", 2);
    let d = &summary.diagnostics;
    for solve in ["density_solve", "divergence_solve"] {
        let omega = d[&format!("{solve}_relaxation")];
        // 0.85 of the bound 0.3524 computed for this kernel and h/ds (to 3 digits).
        assert!((omega - 0.2995).abs() < 5e-4, "{solve}: omega {omega}");
    }
    assert_eq!(d.get("wall_reflections"), None, "{d:?}");
    // The bottom sensor after the start-up: the time mean within 1 % of rho_0 g H (the
    // tolerance of the test above; measured -0.2 to +0.6 %).
    let probes = out.join("probes.csv");
    for method in ["shepard", "nearest", "averaged"] {
        let samples: Vec<f64> = series(&probes, &format!("bottom.{method}"))
            .into_iter()
            .filter(|s| s.0 > 0.3)
            .map(|s| s.1)
            .collect();
        let mean = samples.iter().sum::<f64>() / samples.len() as f64;
        let err = (mean / (rho0 * g * h) - 1.0).abs();
        assert!(
            err < 0.01,
            "bottom.{method}: mean {mean} Pa, error {:.2} %",
            100.0 * err
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// The DFSPH solves carry each ghost's pressure and velocity from its mirrored source
/// (`GhostReflections`, which `GhostWalls` writes); fixed wall particles have none, and
/// the loader refuses the pipeline with the solve's line.
#[test]
fn dfsph_refuses_fixed_wall_particles_at_load() {
    let text = include_str!("../../scenarios/dam_break_dfsph.ron").replace(
        "GhostWalls(slip: FreeSlip, hydrostatic: true),",
        "WallParticles(),",
    );
    assert!(text.contains("WallParticles()"));
    let Err(e) = sph_scenario::Scenario::from_str(
        &text,
        "scenarios/dam_break_dfsph.ron",
        &[],
        &sph_stages::standard_registry(),
    ) else {
        panic!("a DFSPH pipeline on wall particles loaded");
    };
    let shown = e.to_string();
    assert!(
        shown.starts_with("scenarios/dam_break_dfsph.ron:40:9:")
            && shown.contains("DivergenceSolve reads `GhostReflections`"),
        "{shown}"
    );
}
