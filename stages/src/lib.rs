//! The standard stages (WCSPH, and the DFSPH pipeline's `DfsphFactor`, `DivergenceSolve`,
//! `DensitySolve`, `Advance`) (docs/physics.md). One stage per file; each registers under its
//! snake_case name with a typed parameter struct whose fields document their defaults.
//!
//! A usual step, in pipeline order:
//! `GhostWalls` mirror the fluid across the walls, `NeighbourGrid` finds every
//! particle's neighbours, `Reinitialise` (every N steps) Shepard-filters the density,
//! `Eos` gives pressures, `Continuity` and `Forces` the rates, `Probe` samples sensors,
//! `Integrate` advances the state (`Shifting` may then regularise the positions), then `Energy`, `VtkFrames` and `Snapshots` report.

pub mod advance;
pub mod continuity;
pub mod damping_zone;
pub mod density_gradient;
pub mod density_solve;
pub mod dfsph_factor;
pub mod divergence_solve;
pub mod energy;
pub mod eos;
pub mod forces;
pub mod ghost_walls;
pub mod integrate;
pub mod neighbour_grid;
pub(crate) mod pressure_solve;
pub mod probe;
pub(crate) mod rates;
pub mod reinitialise;
pub mod scan;
pub mod shifting;
pub mod snapshots;
pub mod sort_particles;
pub mod terms;
pub mod transducer;
pub mod vtk_frames;
pub mod wall_particles;
pub mod wall_pressure;
pub(crate) mod wall_work;

use sph_core::StageRegistry;

/// Registers every standard stage.
pub fn register_standard(registry: &mut StageRegistry) {
    ghost_walls::register(registry);
    wall_particles::register(registry);
    wall_pressure::register(registry);
    neighbour_grid::register(registry);
    reinitialise::register(registry);
    eos::register(registry);
    continuity::register(registry);
    forces::register(registry);
    dfsph_factor::register(registry);
    divergence_solve::register(registry);
    density_solve::register(registry);
    advance::register(registry);
    probe::register(registry);
    integrate::register(registry);
    damping_zone::register(registry);
    shifting::register(registry);
    energy::register(registry);
    vtk_frames::register(registry);
    snapshots::register(registry);
}

/// A registry holding the standard stages.
pub fn standard_registry() -> StageRegistry {
    let mut registry = StageRegistry::new();
    register_standard(&mut registry);
    registry
}
