//! Issue 16, items 3-5: diagnostics that report the flow apart from the guards, an
//! energy budget that closes with the walls' work, and wave gauges that read the water
//! connected to the bottom rather than spray.

use serde::{Deserialize, Serialize};
use sph_core::components::{Fluid, Position, Velocity};
use sph_core::sim::Sim;
use sph_core::stage::{Stage, StepError};
use sph_core::world::{archetype, column, column_mut};
use sph_run::runner::{run_keeping_state, RunOptions};
use sph_scenario::overrides::Override;
use sph_scenario::Scenario;
use sph_tests::support::{load, nan_max, read_csv, run_completed, series, temp_out};

/// A still layer of water 0.1 m deep and, above it, a 9 x 9 block that `Burst` sets
/// flying apart at the first step: pressureless spray the density floor holds at
/// 0.9 rho_0 while the layer below keeps its hydrostatic density.
const SPRAY: &str = r#"
Scenario(
    name: "spray",
    end_time: 0.15,
    fluid: (density: 1000.0, gamma: 7.0, sound_speed: 10.0, gravity: (0.0, -9.81)),
    resolution: Spacing(0.01),
    kernel: Wendland,
    h_over_dx: 1.3,
    tank: (width: 0.6, height: 0.6, open_top: false),
    fluid_blocks: [
        (min: (0.0, 0.0), size: (0.6, 0.1)),
        (min: (0.255, 0.3), size: (0.09, 0.09)),
    ],
    pipeline: [
        Burst(rate: 10.0, above: 0.2),
        GhostWalls(slip: FreeSlip),
        NeighbourGrid(),
        Eos(min_pressure: 0.0),
        Forces(terms: [PressureGradient(), ArtificialViscosity(alpha: 0.03), Continuity()]),
        Probe(interval: 0.01, density_fluctuation: true),
        Integrate(courant: 0.25, density_floor: 0.9),
    ],
)
"#;

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct BurstParams {
    /// k [1/s]: v = k (x - centre) at the first step.
    rate: f64,
    /// Only particles above this height [m] (and the centre is theirs).
    above: f64,
}

/// Sets v = k (x - centre) on step 0 for the particles above a height.
struct Burst(BurstParams);

impl Stage for Burst {
    fn name(&self) -> &'static str {
        "burst"
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let Some(fluid) = archetype::<Fluid>(&sim.world).filter(|_| sim.clock.step == 0) else {
            return Ok(());
        };
        let x = column::<Position>(fluid)?;
        let up: Vec<usize> = (0..x.len()).filter(|&i| x[i].0.y > self.0.above).collect();
        let centre = up.iter().map(|&i| x[i].0).sum::<glam::DVec2>() / up.len() as f64;
        let mut v = column_mut::<Velocity>(fluid)?;
        for i in up {
            v[i].0 = self.0.rate * (x[i].0 - centre);
        }
        Ok(())
    }
}

/// Item 3: with the floor acting on the spray, `max_density_fluctuation` is the flow's
/// (the layer's hydrostatic compression, about g H / c_0^2 = 1 %), not the floor's
/// 1 - 0.9 = 0.1, which `guarded_density_fluctuation` reports apart; the floor's
/// actions are counted per sampling interval and add up to the run's diagnostic.
#[test]
fn the_density_floor_is_reported_apart_from_the_flow() {
    let mut registry = sph_stages::standard_registry();
    registry.register_checked(
        "burst",
        "test: radial velocity at step 0",
        |p: BurstParams| Ok(Burst(p)),
    );
    let scenario = Scenario::from_str(SPRAY, "spray.ron", &[] as &[Override], &registry)
        .unwrap_or_else(|e| panic!("{e}"));
    let out = temp_out("spray-guards");
    let (summary, _) =
        run_keeping_state(scenario, &RunOptions::quiet(&out, 2)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(summary.status, "completed");
    let probes = out.join("probes.csv");
    let col = |name: &str| -> Vec<f64> { series(&probes, name).iter().map(|p| p.1).collect() };
    let max = |s: &[f64]| s.iter().copied().fold(0.0, nan_max);
    let (flow, guarded) = (
        col("max_density_fluctuation"),
        col("guarded_density_fluctuation"),
    );
    let (floored, particles) = (col("floored"), col("guarded_particles"));
    let total = summary.diagnostics["density_floored"];
    eprintln!(
        "flow {:.4}, guarded {:.4}, floored per interval up to {}, sum {} of {total}, guarded particles {}",
        max(&flow),
        max(&guarded),
        max(&floored),
        floored.iter().sum::<f64>(),
        max(&particles)
    );
    // The layer: hydrostatic 1 % plus the start-up acoustics, which rarefy its surface
    // particles (measured 0.074); the old column read the floor's 0.1 throughout once
    // the spray was floored. 0.09 keeps a tenth of the floor's value between them.
    assert!(max(&flow) < 0.09, "flow figure {}", max(&flow));
    // Floored particles sit on the floor at the samples after their flooring (up to
    // the round-off of 0.9 rho_0 / rho_0).
    assert!((max(&guarded) - 0.1).abs() < 1e-9, "{}", max(&guarded));
    // The spray block is 81 particles; the layer is not touched.
    let touched = max(&particles);
    assert!(touched > 0.0 && touched <= 81.0, "{touched}");
    // Every floor action up to the last sample is in some interval's count.
    let counted: f64 = floored.iter().sum();
    assert!(counted > 0.0 && counted <= total, "{counted} of {total}");
    let _ = std::fs::remove_dir_all(&out);
}

/// A still column 0.2 m deep and a 4 x 4 drop above it, on the gauge line.
const DROP: &str = r#"
Scenario(
    name: "drop",
    end_time: 0.001,
    fluid: (density: 1000.0, gamma: 7.0, sound_speed: 20.0, gravity: (0.0, -9.81)),
    resolution: Spacing(0.01),
    kernel: Wendland,
    h_over_dx: 1.3,
    tank: (width: 0.4, height: 0.5, open_top: false),
    fluid_blocks: [
        (min: (0.0, 0.0), size: (0.4, 0.2)),
        (min: (0.18, 0.35), size: (0.04, 0.04)),
    ],
    wave_gauges: [(name: "G", x: 0.2), (name: "dry", x: 0.2)],
    pipeline: [
        GhostWalls(slip: FreeSlip),
        NeighbourGrid(),
        Eos(),
        Forces(),
        Probe(interval: 0.0),
        Integrate(),
    ],
)
"#;

/// Item 5: the gauge reads the column (0.2 m), not the drop's top (0.39 m) that the
/// highest-particle rule read. Tolerance: the phi = 1/2 level of a lattice of spacing
/// ds lies at its top row + ds/2 up to the kernel sum's departure from 1 near a free
/// surface and the ds/4 march with linear interpolation: a quarter of a spacing.
#[test]
fn a_gauge_reads_the_column_under_a_drop() {
    let scenario = load(DROP, "drop.ron", &[]);
    let (_, _, out) = run_completed(scenario, "gauge-drop", 1);
    let first = series(&out.join("probes.csv"), "G")[0];
    eprintln!("gauge under a drop: {:.5} m (column 0.2 m)", first.1);
    assert!((first.1 - 0.2).abs() < 0.25 * 0.01, "{first:?}");
    // The drop alone, over a dry floor, reads dry.
    let scenario = load(
        DROP,
        "drop.ron",
        &["fluid_blocks=[(min: (0.0, 0.0), size: (0.1, 0.2)), (min: (0.18, 0.35), size: (0.04, 0.04))]"],
    );
    let (_, _, dry) = run_completed(scenario, "gauge-drop-dry", 1);
    assert_eq!(series(&dry.join("probes.csv"), "dry")[0].1, 0.0);
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&dry);
}

/// A rolling tank without guards, filter or pressure floor: the energy the fluid holds
/// and dissipates changes only by the walls' work.
const ROLL: &str = r#"
Scenario(
    name: "roll",
    end_time: 2.0,
    fluid: (density: 1000.0, gamma: 7.0, sound_speed: 20.0, gravity: (0.0, -9.81)),
    resolution: Spacing(0.01),
    kernel: Wendland,
    h_over_dx: 1.5,
    tank: (
        width: 0.5, height: 0.3, open_top: false,
        motion: (roll: (amplitude: 4.0, period: 1.0), ramp: 0.25),
    ),
    fluid_blocks: [(min: (0.0, 0.0), size: (0.5, 0.1))],
    pipeline: [
        GhostWalls(slip: FreeSlip, hydrostatic: true),
        NeighbourGrid(),
        Eos(),
        Forces(terms: [PressureGradient(), ArtificialViscosity(alpha: 0.03), Continuity()]),
        Integrate(courant: 0.25),
        Energy(interval: 0.01),
    ],
)
"#;

/// Item 4: energy.csv closes, total = initial + wall work, in a rolling tank. Measured:
/// the walls put in 7.37 J/m over 2 s and the closure error stays under 0.0020 J/m
/// (0.027 %; 0.0040 before the two wall reflections' energy was booked in `guards`). Tolerance 0.5 % of the work: the rates are taken at the start of each
/// step (first order in dt, dt ~ 1e-4 s against a 1 s roll) and the leapfrog's energy
/// error is bounded, so the error is a small fraction of the work; a budget without the
/// work would miss by 100 %.
#[test]
fn the_energy_budget_closes_with_the_walls_work() {
    let scenario = load(ROLL, "roll.ron", &[]);
    let (_, _, out) = run_completed(scenario, "energy-roll", 2);
    let (header, rows) = read_csv(&out.join("energy.csv"));
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (work, error, total) = (col("wall_work"), col("closure_error"), col("total"));
    let max_abs = |k: usize| rows.iter().map(|r| r[k].abs()).fold(0.0, nan_max);
    let gain = rows
        .iter()
        .map(|r| (r[total] - rows[0][total]).abs())
        .fold(0.0, nan_max);
    eprintln!(
        "roll: wall work up to {:.4} J/m, total change up to {gain:.4}, closure error up to {:.5} J/m",
        max_abs(work),
        max_abs(error)
    );
    assert!(
        max_abs(error) < 0.005 * max_abs(work),
        "closure error {}",
        max_abs(error)
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// Item 4: what the guards add is booked apart (`guards` in energy.csv). In the rolling
/// tank above two particles are reflected off the moving walls: measured +0.0021 J/m,
/// which takes the closure error from 0.0040 to 0.0019 J/m. With a density floor at
/// 0.999 rho_0 the floor raises the bulk's acoustic rarefactions, each time lowering
/// the internal energy (e(rho) > 0 below rho_0, 0 at rho_0): measured -0.083 J/m against
/// 7.26 J/m of wall work, with a closure error of +0.027 J/m that would be -0.056 without
/// the column; the floor also changes the pressures the next force evaluation sees,
/// which no column books (docs/physics.md, "Energy budget").
#[test]
fn the_guards_energy_is_booked_apart() {
    let col = |out: &std::path::Path, name: &str| -> Vec<f64> {
        let (header, rows) = read_csv(&out.join("energy.csv"));
        let k = header.iter().position(|h| h == name).unwrap();
        rows.iter().map(|r| r[k]).collect()
    };
    let (summary, _, free) = run_completed(load(ROLL, "roll.ron", &[]), "energy-guards", 1);
    let reflections = summary
        .diagnostics
        .get("wall_reflections")
        .copied()
        .unwrap_or(0.0);
    let booked = *col(&free, "guards").last().unwrap();
    eprintln!("{reflections} reflections add {booked:.5} J/m");
    // Every reflection off a moving wall changes the particle's kinetic energy; none,
    // no change.
    assert_eq!(
        booked != 0.0,
        reflections > 0.0,
        "{booked} J/m, {reflections} reflections"
    );
    let floored = load(
        ROLL,
        "roll.ron",
        &["pipeline.integrate.density_floor=0.999"],
    );
    let (summary, _, out) = run_completed(floored, "energy-guards-floor", 1);
    let last = *col(&out, "guards").last().unwrap();
    let actions = summary.diagnostics["density_floored"];
    eprintln!("floor acted {actions} particle-steps; guards {last:.4} J/m");
    // Negative by the end: each of the floor's thousands of actions raises a density
    // below rho_0 towards it (the run's few reflections add or take a little kinetic
    // energy, either sign).
    assert!(
        actions > 1000.0 && last < 0.0,
        "{actions} actions, {last} J/m"
    );
    for dir in [free, out] {
        let _ = std::fs::remove_dir_all(&dir);
    }
}
