//! Writing the fluid particles' current state as a ParaView frame.

use crate::vtk::{write_vtp, FrameFields};
use sph_core::components::{
    Density, Fluid, NeighbourCount, ParticleId, Position, Pressure, Velocity,
};
use sph_core::sim::Sim;
use sph_core::stage::StepError;
use sph_core::vocab::Guarded;
use sph_core::world::{archetype, column};
use std::path::Path;

/// Writes the fluid particles (position, velocity, density, pressure, `particle_id`,
/// `guarded` (the [`Guarded`] flags: 1 floored, 2 reflected at a wall, 3 both) and,
/// where the neighbour grid stage counts them, neighbour count) to a `.vtp` file,
/// atomically.
pub fn write_fluid_frame(sim: &Sim, path: &Path) -> Result<(), StepError> {
    let Some(arch) = archetype::<Fluid>(&sim.world) else {
        return Ok(());
    };
    let pos = column::<Position>(arch)?;
    let vel = column::<Velocity>(arch)?;
    let rho = column::<Density>(arch)?;
    let p = column::<Pressure>(arch)?;
    let neighbours = arch.get::<&NeighbourCount>();
    // Particles are reordered by the neighbour grid's cell sort, so the id (creation
    // index) is what follows a particle from frame to frame.
    let ids: Vec<f64> = arch
        .get::<&ParticleId>()
        .map(|c| c.iter().map(|id| f64::from(id.0)).collect())
        .unwrap_or_default();
    // Which safeguards have acted on each particle, to find them in ParaView.
    let guarded: Vec<f64> = arch
        .get::<&Guarded>()
        .map(|c| c.iter().map(|g| f64::from(g.0)).collect())
        .unwrap_or_default();
    let extras: Vec<(&str, &[f64])> = [("particle_id", &ids[..]), ("guarded", &guarded[..])]
        .into_iter()
        .filter(|(_, v)| !v.is_empty())
        .collect();
    let fields = FrameFields {
        positions: Position::values(&pos),
        velocity: Velocity::values(&vel),
        density: Density::values(&rho),
        pressure: Pressure::values(&p),
        neighbours: neighbours.as_deref().map_or(&[], NeighbourCount::values),
        extra_scalars: &extras,
    };
    write_vtp(path, &fields).map_err(|e| StepError::output(path, e))
}
