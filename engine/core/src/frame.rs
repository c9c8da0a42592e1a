//! Writing the fluid particles' current state as a ParaView frame.

use crate::components::{Density, Fluid, NeighbourCount, ParticleId, Position, Pressure, Velocity};
use crate::output::vtk::{write_vtp, FrameFields};
use crate::sim::Sim;
use crate::stage::StepError;
use crate::world::{archetype, column};
use glam::DVec2;
use std::path::Path;

/// Writes the fluid particles (position, velocity, density, pressure, `particle_id`
/// and, where the neighbour grid stage counts them, neighbour count) to a `.vtp` file,
/// atomically.
pub fn write_fluid_frame(sim: &Sim, path: &Path) -> Result<(), StepError> {
    let Some(arch) = archetype::<Fluid>(&sim.world) else {
        return Ok(());
    };
    let pos = column::<Position>(arch)?;
    let vel = column::<Velocity>(arch)?;
    let rho = column::<Density>(arch)?;
    let p = column::<Pressure>(arch)?;
    let positions: Vec<DVec2> = pos.iter().map(|x| x.0).collect();
    let velocity: Vec<DVec2> = vel.iter().map(|v| v.0).collect();
    let density: Vec<f64> = rho.iter().map(|r| r.0).collect();
    let pressure: Vec<f64> = p.iter().map(|q| q.0).collect();
    let neighbours: Vec<u32> = arch
        .get::<&NeighbourCount>()
        .map(|c| c.iter().map(|n| n.0).collect())
        .unwrap_or_default();
    // Particles are reordered by the neighbour grid's cell sort, so the id (creation
    // index) is what follows a particle from frame to frame.
    let ids: Vec<f64> = arch
        .get::<&ParticleId>()
        .map(|c| c.iter().map(|id| f64::from(id.0)).collect())
        .unwrap_or_default();
    let extras = [("particle_id", &ids[..])];
    let fields = FrameFields {
        positions: &positions,
        velocity: &velocity,
        density: &density,
        pressure: &pressure,
        neighbours: &neighbours,
        extra_scalars: if ids.is_empty() { &[] } else { &extras },
    };
    write_vtp(path, &fields).map_err(|e| StepError::output(path, e))
}
