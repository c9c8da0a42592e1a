//! The standard stages (WCSPH, and the DFSPH pipeline's `DfsphFactor`, `DivergenceSolve`,
//! `DensitySolve`, `Advance`) (docs/physics.md). One stage per file; each registers under its
//! snake_case name with a typed parameter struct whose fields document their defaults.
//!
//! A usual step, in pipeline order:
//! `GhostWalls` mirror the fluid across the walls, `NeighbourGrid` finds every
//! particle's neighbours, `Reinitialise` (every N steps) Shepard-filters the density,
//! `Eos` gives pressures, `Continuity` and `Forces` the rates, `Probe` samples sensors,
//! `Integrate` advances the state (`Shifting` may then regularise the positions), then `Energy`, `VtkFrames` and `Snapshots` report.

pub mod terms;
pub mod vocab;

pub mod neighbours;
pub use neighbours::{neighbour_grid, scan, sort_particles};

#[cfg(test)]
mod testing;
#[cfg(all(test, feature = "dim3"))]
mod tests3d;
pub mod walls;
pub use walls::ghost_walls;
pub(crate) use walls::wall_work;
pub use walls::{wall_particles, wall_pressure};

pub mod equations;
pub use equations::density_gradient;
pub(crate) use equations::rates;
pub use equations::shifting;
pub use equations::{continuity, damping_zone, eos, forces, reinitialise};

pub mod solvers;
pub(crate) use solvers::pressure_solve;
pub use solvers::{density_solve, dfsph_factor, divergence_solve};

pub mod integration;
pub use integration::{advance, integrate};

pub mod outputs;
pub use outputs::{energy, probe, snapshots, transducer, vtk_frames};

use sph_core::StageRegistry;

/// Registers every standard stage.
pub fn register_standard(registry: &mut StageRegistry) {
    ghost_walls::register(registry);
    neighbour_grid::register(registry);
    reinitialise::register(registry);
    eos::register(registry);
    continuity::register(registry);
    forces::register(registry);
    advance::register(registry);
    probe::register(registry);
    integrate::register(registry);
    damping_zone::register(registry);
    energy::register(registry);
    vtk_frames::register(registry);
    dfsph_factor::register(registry);
    divergence_solve::register(registry);
    density_solve::register(registry);
    snapshots::register(registry);
    wall_particles::register(registry);
    wall_pressure::register(registry);
    shifting::register(registry);
}

/// A registry holding the standard stages.
pub fn standard_registry() -> StageRegistry {
    let mut registry = StageRegistry::new();
    register_standard(&mut registry);
    registry
}

#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    /// Every standard stage answers to the name it is registered under, as
    /// `Stage::name` promises: the tracing spans, the `--profile` table and the errors
    /// name a stage by it.
    #[test]
    fn every_standard_stage_is_named_as_registered() {
        let registry = crate::standard_registry();
        let names: Vec<String> = registry.list().map(|(n, _)| n.to_string()).collect();
        assert!(names.len() >= 19, "{names:?}");
        for name in &names {
            // The one stage without defaults for every parameter.
            let params = match name.as_str() {
                "damping_zone" => "(from: 1.0, to: 2.0)",
                // Read through a seeded map, as the scenario loader hands it over.
                "probe" => "{}",
                _ => "()",
            };
            let stage = crate::testing::stage(name, params);
            assert_eq!(stage.name(), name, "stage registered as {name}");
        }
    }
}
