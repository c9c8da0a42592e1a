//! `Integrate(density_floor)`: pressureless spray must not end a run by thinning, and
//! the density guard must still stop a genuine blow-up.
//!
//! A 9 x 9 block of water without gravity is given the velocity v = k (x - centre) at
//! the first step (the `Burst` stage below) and left to fly apart (k > 0) or to
//! collapse on itself (k < 0). With `Eos(min_pressure: 0)` the burst is purely
//! kinematic: no pressure (every density is below rho_0), no viscosity (the pairs
//! separate), no artificial pressure. The continuity equation then takes from each
//! particle the density its neighbours brought, sum_j m W_ij at the start: the centre
//! particle ends at its own share m W(0), about a third of rho_0. That is what a spray
//! particle in the sloshing tank's roof corners does (docs/validation.md), and what
//! stopped `scenarios/sloshing.ron` at t = 4.91 s.

use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Position, Velocity};
use sph_core::sim::Sim;
use sph_core::stage::{Stage, StepError};
use sph_core::world::{archetype, column, column_mut};
use sph_core::StageRegistry;
use sph_run::runner::{run_keeping_state, RunError, RunOptions};
use sph_scenario::overrides::Override;
use sph_scenario::Scenario;
use sph_tests::support::{nan_min, temp_out};

const RHO0: f64 = 1000.0;

const BURST: &str = r#"
Scenario(
    name: "burst",
    end_time: 0.3,
    fluid: (density: 1000.0, gamma: 7.0, sound_speed: 10.0, gravity: (0.0, 0.0)),
    resolution: Spacing(0.01),
    kernel: Wendland,
    h_over_dx: 1.3,
    tank: (width: 0.4, height: 0.4, open_top: false),
    fluid_blocks: [(min: (0.155, 0.155), size: (0.09, 0.09))],
    pipeline: [
        Burst(rate: 10.0),
        GhostWalls(slip: FreeSlip),
        NeighbourGrid(),
        Eos(min_pressure: 0.0),
        Forces(terms: [PressureGradient(), ArtificialViscosity(alpha: 0.03), Continuity()]),
        Integrate(courant: 0.25),
    ],
)
"#;

/// Parameters of `Burst(rate: k)`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct Params {
    /// k [1/s]: v = k (x - centre of the fluid) at the first step.
    rate: f64,
}

/// Sets v = k (x - centre) on step 0; does nothing afterwards.
struct Burst {
    rate: f64,
}

impl Stage for Burst {
    fn name(&self) -> &'static str {
        "burst"
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        if sim.clock.step > 0 {
            return Ok(());
        }
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let x = column::<Position>(fluid)?;
        let centre = x.iter().map(|p| p.0).sum::<glam::DVec2>() / x.len() as f64;
        let mut v = column_mut::<Velocity>(fluid)?;
        for (v, x) in v.iter_mut().zip(x.iter()) {
            v.0 = self.rate * (x.0 - centre);
        }
        Ok(())
    }
}

fn registry() -> StageRegistry {
    let mut registry = sph_stages::standard_registry();
    registry.register_checked("burst", "test: radial velocity at step 0", |p: Params| {
        Ok(Burst { rate: p.rate })
    });
    registry
}

/// The burst with `overrides`: the run's status, its densities at the end (none if it
/// stopped) and its `density_floored` diagnostic.
fn burst(tag: &str, overrides: &[&str]) -> (String, Vec<f64>, f64) {
    let overrides: Vec<Override> = overrides.iter().map(|o| o.parse().unwrap()).collect();
    let scenario = Scenario::from_str(BURST, "burst.ron", &overrides, &registry())
        .unwrap_or_else(|e| panic!("{e}"));
    let out = temp_out(tag);
    let (summary, rho) = match run_keeping_state(scenario, &RunOptions::quiet(&out, 2)) {
        Ok((summary, sim)) => {
            let fluid = archetype::<Fluid>(&sim.world).unwrap();
            let rho = column::<Density>(fluid)
                .unwrap()
                .iter()
                .map(|r| r.0)
                .collect();
            (summary, rho)
        }
        // An unstable stop: the summary says why; no final state.
        Err(RunError::Step { summary, .. }) => (*summary, Vec::new()),
        Err(e) => panic!("{tag}: {e}"),
    };
    let floored = summary
        .diagnostics
        .get("density_floored")
        .copied()
        .unwrap_or(0.0);
    let _ = std::fs::remove_dir_all(&out);
    eprintln!("{tag}: {} steps, {}", summary.steps, summary.status);
    (summary.status, rho, floored)
}

/// The density named by a run stopped on the default density guard (panics on any
/// other status).
fn guard_density(status: &str) -> f64 {
    assert!(
        status.starts_with("stopped at step") && status.contains("is beyond rho_0 (1 +- 0.5)"),
        "{status}"
    );
    status
        .split("density ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no density in {status}"))
}

/// Without a floor the centre of the burst thins below 0.5 rho_0 and the default
/// density guard stops the run: the failure the sloshing tank met.
#[test]
fn a_pressureless_burst_thins_through_the_density_guard() {
    let (status, _, floored) = burst("burst-no-floor", &[]);
    assert!(guard_density(&status) < 0.5 * RHO0, "{status}");
    assert_eq!(floored, 0.0);
}

/// With `density_floor: 0.9` the same burst finishes: densities are held at
/// 0.9 rho_0 (with p = 0 below rho_0 this changes no pressure) and the floored
/// particle-steps are counted.
#[test]
fn a_density_floor_lets_the_burst_finish() {
    let (status, rho, floored) = burst("burst-floor", &["pipeline.integrate.density_floor=0.9"]);
    assert_eq!(status, "completed");
    let least = rho.iter().copied().fold(f64::INFINITY, nan_min);
    assert!(
        (least - 0.9 * RHO0).abs() < 1e-9,
        "least density {least}, expected the floor 900"
    );
    // Every particle has lost a neighbour's share by now: all of them sit on the floor.
    assert!(
        rho.iter().all(|&r| (r - 0.9 * RHO0).abs() < 1e-9),
        "{rho:?}"
    );
    assert!(floored > 0.0);
}

/// The floor does not hide a blow-up: the block collapsing on itself at Mach 0.8
/// (v = -200 1/s (x - centre)) is compressed beyond 1.5 rho_0 before its pressure
/// can stop it, and the density guard stops the run, floor or not.
#[test]
fn the_density_guard_still_stops_a_collapse_with_a_floor() {
    for (tag, floor) in [("collapse-no-floor", None), ("collapse-floor", Some(0.9))] {
        let mut overrides = vec!["pipeline.burst.rate=-200.0"];
        if floor.is_some() {
            overrides.push("pipeline.integrate.density_floor=0.9");
        }
        let (status, _, _) = burst(tag, &overrides);
        assert!(
            guard_density(&status) > 1.5 * RHO0,
            "floor {floor:?}: {status}"
        );
    }
}

/// A floor outside (0, 1] is refused, naming the field.
#[test]
fn a_density_floor_out_of_range_is_refused() {
    for bad in ["0.0", "1.5", "-0.2"] {
        let o = format!("pipeline.integrate.density_floor={bad}");
        let overrides: Vec<Override> = vec![o.parse().unwrap()];
        let e = Scenario::from_str(BURST, "burst.ron", &overrides, &registry())
            .err()
            .unwrap_or_else(|| panic!("density_floor = {bad} was accepted"));
        let text = e.to_string();
        assert!(
            text.contains("density_floor") && text.contains("0 < f <= 1"),
            "{text}"
        );
    }
}
