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
//! Only components registered in the sim's [`ColumnKinds`] (the core's particle
//! columns and every column a stage adds with `ensure_component`) can be permuted. A
//! fluid archetype that carries any other component (a plugin's per-particle state
//! inserted some other way) is left unsorted, and the `cell_sort_skipped` diagnostic
//! says so, rather than scrambling that column.

use rayon::prelude::*;
use sph_core::components::{Fluid, Ghost, Position};
use sph_core::stage::StepError;
use sph_core::vocab::resize_by_eighths;
use sph_core::world::{archetype, column, column_mut, ColumnKinds};

/// The sort's working buffers. `NeighbourGrid` lends it the grid's own (cell per
/// particle, cell starts, particle order), which the grid rebuild overwrites right
/// after, so sorting holds no memory of its own.
pub struct SortBuffers<'a> {
    /// Each particle's cell, then (once sorted) the inverse permutation: old index ->
    /// new index.
    pub cells: &'a mut Vec<u32>,
    pub start: &'a mut Vec<u32>,
    /// New position k holds the particle that was at `order[k]`.
    pub order: &'a mut Vec<u32>,
}

/// Reorders the fluid particles by `cell_of` (a cell index below `n_cells`), stably, so
/// within a cell the previous order is kept and the result is the same on any thread
/// count. Returns false (and changes nothing) when the fluid carries a component the
/// sort does not know.
pub fn sort_by_cell(
    world: &hecs::World,
    kinds: &ColumnKinds,
    n_cells: usize,
    cell_of: impl Fn(sph_core::dim::Vector) -> usize + Sync,
    scratch: SortBuffers,
) -> Result<bool, StepError> {
    let Some(fluid) = archetype::<Fluid>(world) else {
        return Ok(true);
    };
    if !kinds.knows(fluid) {
        return Ok(false);
    }
    let n = fluid.len() as usize;
    {
        let x = column::<Position>(fluid)?;
        resize_by_eighths(scratch.cells, n, 0);
        scratch
            .cells
            .par_iter_mut()
            .zip(x.par_iter())
            .for_each(|(c, x)| *c = cell_of(x.0) as u32);
    }
    counting_sort(scratch.cells, n_cells, scratch.start, scratch.order);
    // The cells are no longer needed: their buffer takes the inverse permutation.
    let inverse = scratch.cells;
    for (new, &old) in scratch.order.iter().enumerate() {
        inverse[old as usize] = new as u32;
    }
    kinds.permute(fluid, scratch.order)?;
    if let Some(ghost) = archetype::<Ghost>(world) {
        column_mut::<Ghost>(ghost)?
            .par_iter_mut()
            .filter(|g| !g.is_wall_particle())
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
    resize_by_eighths(order, keys.len(), 0);
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
