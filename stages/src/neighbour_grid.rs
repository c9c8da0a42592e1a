//! Neighbour search: a cell-linked list with cells the size of the kernel support
//! (docs/physics.md, "Neighbour search"), over fluid and ghost particles together.
//!
//! Publishes [`Neighbours`] (in the shared vocabulary, `sph_core::vocab`): for every
//! fluid particle the list of particles within the support (joint numbering: fluid
//! `0..n_fluid`, then ghosts), in a fixed order — cells scanned row by row, indices
//! ascending within a cell — so every sum over neighbours is the same whatever the
//! thread count. The lists are reused by every later stage of the step.

use crate::scan::Scan;
use crate::sort_particles::{counting_sort, sort_by_cell, SortBuffers};
use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{Fluid, Ghost, NeighbourCount, Position};
use sph_core::contract::Access;
use sph_core::sim::Sim;
use sph_core::stage::{Stage, StepError};
use sph_core::vocab::{resize_by_eighths, CellGrid, NeighbourBlock, Neighbours, BLOCK, REACH};
use sph_core::world::{
    archetype, column, column_kinds, column_mut, count, ensure_component, ColumnKinds, Joined,
};
use sph_core::StageRegistry;

#[derive(Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Also store each fluid particle's neighbour count (for frames and statistics).
    /// Default true.
    pub count: bool,
    /// Reorder the fluid particles by grid cell every this many calls (0: never), so
    /// neighbours are near in memory (`sort_particles.rs`). Changes sums only by
    /// round-off (the order of terms); results stay identical for any thread count.
    /// Default 20.
    pub sort_every: u32,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            count: true,
            sort_every: 20,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register(
        "neighbour_grid",
        "cell-linked list; neighbour lists of the fluid particles",
        |p: Params| {
            Ok(NeighbourGrid {
                count: p.count,
                sort_every: p.sort_every,
                calls: 0,
            })
        },
    );
}

pub struct NeighbourGrid {
    count: bool,
    sort_every: u32,
    calls: u64,
}

// Cells per kernel support (`vocab::REACH`). With 2 (cells of half the support
// searched 5 x 5, an area of (2.5 r_s)^2 instead of (3 r_s)^2) about 30 % fewer
// candidates are distance-tested, but the grid has four times the cells, whose
// counting sort eats the gain: measured at 80k, 5 % less user time in this stage and
// 1 % overall, for about 15 more bytes per particle. So 1.

/// The most grid cells: the cell index array alone takes 4 bytes a cell.
const MAX_CELLS: f64 = 1e8;

/// Rebuilds `grid` for `positions` (joint numbering) by a counting sort, so each cell
/// lists its particles in ascending index order. Reuses its buffers.
fn rebuild(grid: &mut CellGrid, positions: Joined<Position>) {
    let _span = tracing::info_span!("grid_build").entered();
    let n = positions.len();
    let mut cells = std::mem::take(&mut grid.cells);
    resize_by_eighths(&mut cells, n, 0);
    cells
        .par_iter_mut()
        .enumerate()
        .for_each(|(j, c)| *c = grid.index_of(positions.get(j as u32).0) as u32);
    counting_sort(
        &cells,
        grid.nx * grid.ny,
        &mut grid.start,
        &mut grid.particles,
    );
    grid.cells = cells;
    resize_by_eighths(&mut grid.xs, n, 0.0);
    resize_by_eighths(&mut grid.ys, n, 0.0);
    (&mut grid.xs[..], &mut grid.ys[..], &grid.particles[..])
        .into_par_iter()
        .for_each(|(x, y, &j)| {
            let p = positions.get(j).0;
            (*x, *y) = (p.x, p.y);
        });
}

impl Stage for NeighbourGrid {
    fn name(&self) -> &'static str {
        "neighbour_grid"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), sph_core::SetupError> {
        // The cell sort permutes the registered columns.
        column_kinds(&mut sim.resources);
        if self.count {
            ensure_component::<Fluid, NeighbourCount>(sim);
        }
        let support = sim.constants.support();
        let (lo, hi) = sim.constants.domain;
        let cells = ((hi.x - lo.x) / support + 3.0) * ((hi.y - lo.y) / support + 3.0);
        if cells > MAX_CELLS {
            return Err(sph_core::SetupError::new(
                "neighbour_grid",
                format!(
                    "the domain spans {cells:.0} grid cells of one kernel support ({support:.3e} m); accepted: at most {MAX_CELLS:.0} (the tank is too large for the resolution: use a coarser `resolution` or a smaller tank)"
                ),
            ));
        }
        sim.resources.insert(Neighbours::default());
        Ok(())
    }

    /// The call counter, which decides when the particles are next sorted.
    fn save_state(&mut self, _sim: &Sim) -> Result<Vec<u8>, StepError> {
        let mut e = Enc::default();
        e.u64(self.calls);
        Ok(e.into_bytes())
    }

    fn load_state(&mut self, _sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        self.calls = d.u64()?;
        d.end()
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let mut nb = sim.resources.take::<Neighbours>().unwrap_or_default();
        let result = self.build(sim, &mut nb);
        sim.resources.insert(nb);
        result
    }

    /// Lists every fluid particle's neighbours among fluid and ghosts (the periodic
    /// cell sort reorders the fluid columns; it changes no value).
    fn access(&self) -> Access {
        Access::new()
            .reads::<Position>()
            .uses::<Ghost>()
            .writes::<Neighbours>()
            .writes_if::<NeighbourCount>(self.count)
    }
}

impl NeighbourGrid {
    fn build(&mut self, sim: &mut Sim, nb: &mut Neighbours) -> Result<(), StepError> {
        let support = sim.constants.support();
        // The grid must also cover ghosts, which lie up to one support outside the walls.
        let (lo, hi) = sim.constants.domain;
        let pad = DVec2::splat(support);
        nb.grid.shape((lo - pad, hi + pad), support / REACH as f64);
        if self.sort_every > 0 && self.calls.is_multiple_of(self.sort_every as u64) {
            let _span = tracing::info_span!("sort").entered();
            let kinds = sim
                .resources
                .get::<ColumnKinds>()
                .ok_or_else(|| StepError::Internal("NeighbourGrid ran without its setup".into()))?;
            // The sort borrows the grid's buffers, which `rebuild` overwrites below; sized
            // first for the rebuild (fluid and ghosts), or the sort's fluid-only size
            // and the rebuild's growth would double them.
            let grid = &mut nb.grid;
            let joint = count::<Fluid>(&sim.world) + count::<Ghost>(&sim.world);
            for buffer in [&mut grid.cells, &mut grid.particles] {
                buffer.reserve_exact(joint.saturating_sub(buffer.len()));
            }
            let (mut cells, mut start, mut order) = (
                std::mem::take(&mut grid.cells),
                std::mem::take(&mut grid.start),
                std::mem::take(&mut grid.particles),
            );
            let shape = &*grid;
            let sorted = sort_by_cell(
                &sim.world,
                kinds,
                shape.nx * shape.ny,
                |x| shape.index_of(x),
                SortBuffers {
                    cells: &mut cells,
                    start: &mut start,
                    order: &mut order,
                },
            );
            (grid.cells, grid.start, grid.particles) = (cells, start, order);
            let sorted = sorted?;
            if !sorted {
                sim.diagnostics.insert("cell_sort_skipped".into(), 1.0);
            }
        }
        self.calls += 1;
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let ghost = archetype::<Ghost>(&sim.world);
        let fpos = column::<Position>(fluid)?;
        let gpos = ghost.map(column::<Position>).transpose()?;
        let positions = Joined::new(&fpos[..], gpos.as_deref().unwrap_or(&[]));
        nb.n_fluid = fpos.len();
        nb.n_ghost = positions.len() - fpos.len();
        nb.support = support;
        rebuild(&mut nb.grid, positions);

        let fpos: &[Position] = &fpos;
        let r2max = support * support;
        let grid = &nb.grid;
        let n = nb.n_fluid;
        nb.blocks
            .resize_with(n.div_ceil(BLOCK), NeighbourBlock::default);
        let scan = Scan::detect();
        tracing::info_span!("scan").in_scope(|| {
            nb.blocks.par_iter_mut().enumerate().for_each(|(b, block)| {
                let range = b * BLOCK..((b + 1) * BLOCK).min(n);
                scan.build_block(grid, fpos, r2max, range, block);
            })
        });
        nb.blocks.truncate(n.div_ceil(BLOCK));
        if self.count {
            let _span = tracing::info_span!("count").entered();
            let mut counts = column_mut::<NeighbourCount>(fluid)?;
            counts
                .par_chunks_mut(BLOCK)
                .zip(nb.blocks.par_iter())
                .for_each(|(counts, block)| {
                    for (c, w) in counts.iter_mut().zip(block.offsets.windows(2)) {
                        c.0 = w[1] - w[0];
                    }
                });
        }
        Ok(())
    }
}
