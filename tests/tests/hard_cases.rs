//! Hard cases (issue 5): runs that must finish without non-finite values or particles
//! leaving the tank, with density fluctuation and energy drift inside stated bounds,
//! or stop with a diagnostic naming when and where; none may panic.
//!
//! The default cases are coarse enough for CI (about 30 s of CPU together). The fine
//! variants are ignored; run them with
//! `cargo test --release -p sph-tests --test hard_cases -- --ignored --nocapture`
//! (`SPH_HARD_KERNELS=Wendland,Gaussian` limits the 80,000-particle dam break to those
//! kernels; docs/validation.md, "Hard cases", gives their cost and results).
//!
//! Energies are in units of M |g| H (see `Stability`). A still layer lifted uniformly
//! by d gains M g d of potential energy, so "mechanical gain <= ds / (4 H)" reads "the
//! water rose by less than a quarter of a particle spacing".

use sph_tests::stability::{run_hard_case, Bounds, Stability};

const DAM: &str = include_str!("../../scenarios/dam_break_paper.ron");
const HYDROSTATIC: &str = include_str!("../../scenarios/hydrostatic.ron");
const SLOSHING_HIGH: &str = include_str!("../../scenarios/sloshing_high.ron");
const THIN: &str = include_str!("../scenarios/thin_layer.ron");
const ON_WALLS: &str = include_str!("../scenarios/particles_on_walls.ron");
const CORNER: &str = include_str!("../scenarios/corner_particle.ron");

const G: f64 = 9.81;
const KERNELS: [&str; 5] = ["Gaussian", "Quadratic", "Cubic", "Quartic", "Wendland"];

/// Dam break (1.2 m x 0.6 m column) at c_0 = 12 m/s, a third of the shipped 34.3 m/s:
/// the Ritter front 2 sqrt(g H) = 4.85 m/s runs at Mach 0.4. `across` particles
/// across the column, to `end` s; the first impact on the right wall is at t ~ 0.62 s.
fn dam_break_c12(kernel: &str, artificial_pressure: bool, across: u32, end: f64) -> Stability {
    let terms = match artificial_pressure {
        true => "[PressureGradient(), ArtificialViscosity(), ArtificialPressure(), Continuity()]",
        false => "[PressureGradient(), ArtificialViscosity(), Continuity()]",
    };
    let overrides = [
        format!("resolution=ParticlesAcross({across})"),
        format!("end_time={end}"),
        "fluid.sound_speed=12.0".into(),
        format!("kernel={kernel}"),
        format!("pipeline.forces.terms={terms}"),
        "pipeline.probe.max_speed=true".into(),
    ];
    let overrides: Vec<&str> = overrides.iter().map(String::as_str).collect();
    run_hard_case(DAM, "scenarios/dam_break_paper.ron", &overrides)
}

/// Bounds for the c_0 = 12 m/s dam break to just past the first impact.
fn dam_break_bounds() -> Bounds {
    let (h, c0): (f64, f64) = (0.6, 12.0);
    let front = 2.0 * (G * h).sqrt();
    Bounds {
        // Water hammer of the front on the wall, Delta rho / rho_0 ~ U / c_0 with U the
        // Ritter front speed: 0.40. (The integrator stops the run at 0.5.)
        density: front / c0,
        // Fixed walls do no work: kinetic + potential can only draw on the initial
        // compression's internal energy, g H / (6 c_0^2) = 0.68 % of M g H; 1 % allows
        // for wall reflections. Shepard every step pumps energy into the thin front
        // (finding in docs/validation.md): 4.5 % at 20 across with the Gaussian kernel.
        mechanical_gain: 0.01,
        // Shepard every step and the ghost walls exchange energy outside the budget;
        // the paper's coarse runs lose a few percent by the first impact.
        total_drift: 0.05,
        // Below the speed of sound (Mach 1): beyond it the weakly compressible model
        // means nothing. Not a multiple of the front speed: the run-up jet at impact
        // outruns the front (1.3 x at 40 across, 1.6 x at 80,000 particles).
        max_speed: c0,
    }
}

/// Every kernel with artificial pressure on and off, 40 across (800 particles), to
/// t = 0.8 s (past the first impact).
macro_rules! dam_break_cases {
    ($($name:ident: $kernel:expr;)*) => {$(
        #[test]
        fn $name() {
            for ap in [true, false] {
                let case = format!("dam break c0 = 12, {}, artificial pressure {ap}", $kernel);
                dam_break_c12($kernel, ap, 40, 0.8).assert_finished_within(&case, &dam_break_bounds());
            }
        }
    )*};
}

dam_break_cases! {
    dam_break_c12_gaussian: "Gaussian";
    dam_break_c12_quadratic: "Quadratic";
    dam_break_c12_cubic: "Cubic";
    dam_break_c12_quartic: "Quartic";
    dam_break_c12_wendland: "Wendland";
}

/// The fine variant: 400 x 200 = 80,000 particles to t = 0.7 s (first impact at
/// 0.62 s), every kernel, artificial pressure on and off (ten runs; see
/// docs/validation.md for the cost). The sharper impact may compress beyond the
/// integrator's density limit: stopping with a located diagnostic is then the
/// required outcome.
#[test]
#[ignore = "fine: ten 80,000-particle runs of 5-40 min each; last measured: all ten (five kernels, artificial pressure on and off) finished within the bounds (docs/validation.md, Fine runs)"]
fn fine_dam_break_c12_80k_every_kernel() {
    // SPH_HARD_KERNELS=Wendland,Gaussian runs a subset.
    let only = std::env::var("SPH_HARD_KERNELS").unwrap_or_default();
    let chosen = |k: &&str| only.is_empty() || only.split(',').any(|o| o.trim() == *k);
    for kernel in KERNELS.into_iter().filter(chosen) {
        for ap in [true, false] {
            let case = format!("dam break c0 = 12, 80k, {kernel}, artificial pressure {ap}");
            dam_break_c12(kernel, ap, 400, 0.7)
                .assert_finished_within_or_stopped(&case, &dam_break_bounds());
        }
    }
}

/// Still water 20 s; `spacing` divides the 1 m tank and the 0.6 m depth.
fn hydrostatic_20s(spacing: f64) -> Stability {
    let resolution = format!("resolution=Spacing({spacing})");
    run_hard_case(
        HYDROSTATIC,
        "scenarios/hydrostatic.ron",
        &[&resolution, "end_time=20.0"],
    )
}

fn hydrostatic_bounds(spacing: f64) -> Bounds {
    let (h, c0) = (0.6, 10.0 * (2.0 * G * 0.6_f64).sqrt());
    Bounds {
        // The bottom's hydrostatic compression, g H / c_0^2 = 0.5 %, twice over for
        // the acoustic ringing.
        density: 2.0 * G * h / (c0 * c0),
        // Shepard every 20 steps slowly lifts the surface (docs/validation.md): less
        // than a quarter of ds over the run.
        mechanical_gain: spacing / (4.0 * h),
        total_drift: spacing / (4.0 * h),
        // hydrostatic.rs's "still": below 1 % of sqrt(g H).
        max_speed: 0.01 * (G * h).sqrt(),
    }
}

/// H/ds = 12 (20 x 12 = 240 particles).
#[test]
fn hydrostatic_tank_20s() {
    hydrostatic_20s(0.05)
        .assert_finished_within("hydrostatic 20 s, ds = 0.05", &hydrostatic_bounds(0.05));
}

/// H/ds = 48, the shipped resolution (3,840 particles). At h/ds = 1.5 it failed on
/// speed: at t ~ 2.6-3.3 s whole rows near the bottom slid sideways, alternating in
/// direction every two or three rows, a shear wave that grows on the square starting
/// lattice under pressure (docs/validation.md, finding 6 and "Why the rows slide";
/// tests/lattice_stability.rs). The scenario now runs at h/ds = 2.0, where that lattice
/// is stable; the bound is the one the failing runs were held to.
#[test]
#[ignore = "fine: 20 s at 3,840 particles (5 min on 2 threads); last measured at the shipped h/ds = 2.0 with Fourtakas: passes, max speed 0.0014 m/s at t = 0.05 s (start-up; bound 0.0243), 2.8e-5 m/s at 20 s, max |rho/rho0-1| 0.49 %, gain 6.2e-5 (pressures, measured but not asserted here: within 0.22 % of rho g (H - y) at 20 s) (at h/ds = 1.5 it failed, 0.0254 m/s at t = 2.93 s, rows sliding; docs/validation.md, Why the rows slide)"]
fn fine_hydrostatic_tank_20s() {
    hydrostatic_20s(0.0125)
        .assert_finished_within("hydrostatic 20 s, ds = 0.0125", &hydrostatic_bounds(0.0125));
}

/// SPHERIC Test 10 at 70 % filling rolled at its first natural period (resonance,
/// roof impacts) for 60 s, `across` particles across the tank.
fn sloshing_resonance_60s(across: u32) -> Stability {
    let resolution = format!("resolution=ParticlesAcross({across})");
    run_hard_case(
        SLOSHING_HIGH,
        "scenarios/sloshing_high.ron",
        &[
            &resolution,
            "end_time=60.0",
            "pipeline.probe.interval=0.01",
            "pipeline.probe.max_speed=true",
        ],
    )
}

fn sloshing_bounds() -> Bounds {
    Bounds {
        // Roof spray thins to 0.44 rho_0 in the shipped run (the scenario's comment on
        // density_limit), a fluctuation of 0.56; the run itself stops at 0.8.
        density: 0.56,
        // The rolling tank does work on the water: its energy is not conserved and
        // not bounded here.
        mechanical_gain: f64::INFINITY,
        total_drift: f64::INFINITY,
        // Twice the ~4 m/s roof jets c_0 = 40 m/s was chosen for.
        max_speed: 8.0,
    }
}

/// 18 across (ds = 50 mm, H/ds = 7, 126 particles): coarse, but sixty seconds.
#[test]
fn sloshing_at_resonance_60s() {
    sloshing_resonance_60s(18).assert_finished_within(
        "sloshing 70 % at resonance, 60 s, 18 across",
        &sloshing_bounds(),
    );
}

/// The shipped resolution, 81 across (2,592 particles).
#[test]
#[ignore = "fine: 60 s at 2,592 particles, 746,702 steps (22 min on 1 thread); last measured: finished inside the bounds, max |rho/rho0 - 1| 0.461 (bound 0.56), max speed 5.65 m/s (bound 8), 20 wall reflections (docs/validation.md, Fine runs)"]
fn fine_sloshing_at_resonance_60s() {
    sloshing_resonance_60s(81).assert_finished_within(
        "sloshing 70 % at resonance, 60 s, 81 across",
        &sloshing_bounds(),
    );
}

/// A still layer `rows` particles deep (ds = 10 mm) for 2 s, with extra overrides.
fn thin_layer(rows: u32, extra: &[&str]) -> (Stability, Bounds) {
    let (ds, depth) = (0.01, 0.01 * rows as f64);
    let block = format!("fluid_blocks=[(min: (0.0, 0.0), size: (0.5, {depth}))]");
    let mut overrides = vec![block.as_str()];
    overrides.extend(extra);
    let bounds = Bounds {
        // Hydrostatic compression g H / c_0^2 is 1e-5; 1 % allows for start-up ringing
        // near the free surface.
        density: 0.01,
        // Particles stay in their rows: the layer rises or sinks by less than ds / 4.
        mechanical_gain: ds / (4.0 * depth),
        total_drift: ds / (4.0 * depth),
        // Still: below 5 % of the layer's long-wave speed sqrt(g H).
        max_speed: 0.05 * (G * depth).sqrt(),
    };
    let s = run_hard_case(THIN, "tests/scenarios/thin_layer.ron", &overrides);
    (s, bounds)
}

#[test]
fn thin_layer_one_particle_deep() {
    let (s, b) = thin_layer(1, &[]);
    s.assert_finished_within("thin layer, 1 deep, Shepard every 20", &b);
}

#[test]
fn thin_layer_two_particles_deep() {
    let (s, b) = thin_layer(2, &[]);
    s.assert_finished_within("thin layer, 2 deep, Shepard every 20", &b);
}

/// The first-order MLS filter every step keeps a thin layer in place (Shepard every
/// step lifts a one-deep layer by 1.6 H in 2 s: docs/validation.md).
#[test]
fn thin_layer_mls_every_step() {
    for rows in [1, 2] {
        let (s, b) = thin_layer(
            rows,
            &[
                "pipeline.reinitialise.every=1",
                "pipeline.reinitialise.filter=Mls",
            ],
        );
        s.assert_finished_within(&format!("thin layer, {rows} deep, MLS every step"), &b);
    }
}

/// Particles exactly on the left, bottom and right walls and on both bottom corners
/// (tests/scenarios/particles_on_walls.ron): the water stays still. Before the fix in
/// ghost_walls.rs (no ghost for a particle on its wall) it reached 1.2 m/s.
#[test]
fn particles_on_walls_stay_still() {
    let (ds, h) = (0.01, 0.205);
    let bounds = Bounds {
        // Hydrostatic compression g H / c_0^2 = 0.5 %, twice over for ringing.
        density: 2.0 * G * h / (20.0 * 20.0),
        mechanical_gain: ds / (4.0 * h),
        total_drift: ds / (4.0 * h),
        // Still: below 5 % of sqrt(g H).
        max_speed: 0.05 * (G * h).sqrt(),
    };
    run_hard_case(ON_WALLS, "tests/scenarios/particles_on_walls.ron", &[])
        .assert_finished_within("particles on the walls and corners", &bounds);
}

/// A particle exactly on a corner and one falling diagonally into it
/// (tests/scenarios/corner_particle.ron) stay in the box. Before the fix in walls.rs
/// the corner particle was behind neither wall and fell out of the tank.
#[test]
fn corner_particles_stay_in_the_box() {
    let bounds = Bounds {
        // Two lone particles: continuity changes their density only while they touch.
        density: 0.1,
        // Reflections are elastic in the normal direction and viscosity only removes
        // energy: no gain beyond 1 % of M |g| H (H = one particle spacing here).
        mechanical_gain: 0.01,
        total_drift: f64::INFINITY,
        // Falling 0.028 m diagonally at 9.81 m/s^2: sqrt(2 g d) = 0.74 m/s; 1 m/s.
        max_speed: 1.0,
    };
    run_hard_case(CORNER, "tests/scenarios/corner_particle.ron", &[])
        .assert_finished_within("particles on and into a corner", &bounds);
}

/// Without reflection at the walls, a particle leaving through the corner stops the
/// run with the diagnostic: step, time, the walls it crossed, particle and position.
#[test]
fn corner_crossing_without_reflection_stops_with_a_diagnostic() {
    let s = run_hard_case(
        CORNER,
        "tests/scenarios/corner_particle.ron",
        &["pipeline.integrate.reflect_at_walls=false"],
    );
    let message = s.assert_stopped_with_diagnostic("corner, no reflection");
    assert!(
        message.contains("particle passed through wall `")
            || message.contains("particle passed through the corner of walls `left` and `bottom`"),
        "{message}"
    );
}
