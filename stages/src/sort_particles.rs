//! Cell-sorted particle order: a permutation applied to every fluid column so particles
//! that are neighbours in space are also near in memory (docs/performance.md).
//!
//! This is not a stage of its own: `NeighbourGrid(sort_every: N)` calls [`sort_by_cell`]
//! every N steps, just before it rebuilds the grid, because the sort must use the same
//! cells and must be followed by a grid rebuild. Particles keep their `ParticleId`, so
//! outputs can still follow a particle; the ghosts' `Ghost { source }` indices are
//! remapped through the inverse permutation so they stay consistent until `GhostWalls`
//! rebuilds them at the next step.
//!
//! Only components listed in [`permute_fluid`] can be permuted. A fluid archetype that
//! carries any other component (a plugin's per-particle state) is left unsorted, and
//! the `cell_sort_skipped` diagnostic says so, rather than scrambling that column.

use crate::integrate::{HalfDensity, HalfVelocity};
use rayon::prelude::*;
use sph_core::components::{
    Acceleration, Density, DensityRate, Fluid, Ghost, Mass, NeighbourCount, ParticleId, Position,
    Pressure, Velocity,
};
use sph_core::stage::StepError;
use sph_core::world::{archetype, column, column_mut, permute};
use std::any::TypeId;

/// Component types the sort knows how to permute; any other type in the fluid archetype
/// disables sorting (see the module documentation).
fn known(id: TypeId) -> bool {
    [
        TypeId::of::<Fluid>(),
        TypeId::of::<ParticleId>(),
        TypeId::of::<Position>(),
        TypeId::of::<Velocity>(),
        TypeId::of::<Density>(),
        TypeId::of::<Pressure>(),
        TypeId::of::<Mass>(),
        TypeId::of::<Acceleration>(),
        TypeId::of::<DensityRate>(),
        TypeId::of::<NeighbourCount>(),
        TypeId::of::<HalfVelocity>(),
        TypeId::of::<HalfDensity>(),
    ]
    .contains(&id)
}

/// Reusable buffers of the sort (no allocation after the first sort of a run).
#[derive(Default)]
pub struct SortScratch {
    cells: Vec<u32>,
    start: Vec<u32>,
    /// New position k holds the particle that was at `order[k]`.
    order: Vec<u32>,
    /// Inverse of `order`: old index -> new index.
    inverse: Vec<u32>,
}

/// Reorders the fluid particles by `cell_of` (a cell index below `n_cells`), stably, so
/// within a cell the previous order is kept and the result is the same on any thread
/// count. Returns false (and changes nothing) when the fluid carries a component the
/// sort does not know.
pub fn sort_by_cell(
    world: &hecs::World,
    n_cells: usize,
    cell_of: impl Fn(glam::DVec2) -> usize + Sync,
    scratch: &mut SortScratch,
) -> Result<bool, StepError> {
    let Some(fluid) = archetype::<Fluid>(world) else {
        return Ok(true);
    };
    if !fluid.component_types().all(known) {
        return Ok(false);
    }
    let n = fluid.len() as usize;
    {
        let x = column::<Position>(fluid)?;
        scratch.cells.resize(n, 0);
        scratch
            .cells
            .par_iter_mut()
            .zip(x.par_iter())
            .for_each(|(c, x)| *c = cell_of(x.0) as u32);
    }
    counting_sort(
        &scratch.cells,
        n_cells,
        &mut scratch.start,
        &mut scratch.order,
    );
    scratch.inverse.resize(n, 0);
    for (new, &old) in scratch.order.iter().enumerate() {
        scratch.inverse[old as usize] = new as u32;
    }
    permute_fluid(fluid, &scratch.order)?;
    if let Some(ghost) = archetype::<Ghost>(world) {
        let inverse = &scratch.inverse;
        column_mut::<Ghost>(ghost)?
            .par_iter_mut()
            .for_each(|g| g.source = inverse[g.source as usize]);
    }
    Ok(true)
}

/// Stable counting sort of indices `0..keys.len()` by key: `order` lists the indices
/// key by key, ascending within a key; `start[c]..start[c+1]` is key c's range.
pub fn counting_sort(keys: &[u32], n_keys: usize, start: &mut Vec<u32>, order: &mut Vec<u32>) {
    start.clear();
    start.resize(n_keys + 1, 0);
    for &c in keys {
        start[c as usize + 1] += 1;
    }
    for c in 0..n_keys {
        start[c + 1] += start[c];
    }
    order.resize(keys.len(), 0);
    // `start[c]` is advanced while filling and restored afterwards, so no second
    // buffer is needed.
    for (j, &c) in keys.iter().enumerate() {
        let slot = &mut start[c as usize];
        order[*slot as usize] = j as u32;
        *slot += 1;
    }
    for c in (1..=n_keys).rev() {
        start[c] = start[c - 1];
    }
    start[0] = 0;
}

/// Applies `order` to every known fluid column (missing ones are skipped).
fn permute_fluid(fluid: &hecs::Archetype, order: &[u32]) -> Result<(), StepError> {
    permute::<ParticleId>(fluid, order)?;
    permute::<Position>(fluid, order)?;
    permute::<Velocity>(fluid, order)?;
    permute::<Density>(fluid, order)?;
    permute::<Pressure>(fluid, order)?;
    permute::<Mass>(fluid, order)?;
    permute::<Acceleration>(fluid, order)?;
    permute::<DensityRate>(fluid, order)?;
    permute::<NeighbourCount>(fluid, order)?;
    permute::<HalfVelocity>(fluid, order)?;
    permute::<HalfDensity>(fluid, order)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counting_sort_is_stable_and_restores_starts() {
        let keys = [2, 0, 2, 1, 0, 2];
        let (mut start, mut order) = (Vec::new(), Vec::new());
        counting_sort(&keys, 4, &mut start, &mut order);
        assert_eq!(order, [1, 4, 3, 0, 2, 5]);
        assert_eq!(start, [0, 2, 3, 6, 6]);
    }
}
