//! Neighbour search: a cell-linked list with cells the size of the kernel support
//! (docs/physics.md, "Neighbour search"), over fluid and ghost particles together.
//!
//! Publishes [`Neighbours`] (in the shared vocabulary, `sph_core::vocab`): for every
//! fluid particle the list of particles within the support and a skin beyond it
//! (joint numbering: fluid `0..n_fluid`, then ghosts), in a fixed order — cells
//! scanned row by row, indices ascending within a cell — so every sum over neighbours
//! is the same whatever the thread count. The lists last while no particle (fluid or
//! ghost) has moved more than half the skin since they were built (Verlet lists):
//! every pair within the support is then in them. That decision depends on the
//! positions alone; the positions at the build go into the checkpoint, from which a
//! resumed run rebuilds exactly the lists of the uninterrupted one.

use crate::scan::Scan;
use crate::sort_particles::{counting_sort, sort_by_cell, SortBuffers};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{Fluid, Ghost, NeighbourCount, Position};
use sph_core::contract::Access;
use sph_core::dim::Vector;
use sph_core::sim::Sim;
use sph_core::stage::{Stage, StepError};
use sph_core::vocab::{
    resize_by_eighths, CellGrid, ListPlan, NeighbourBlock, NeighbourCountsInPass, Neighbours,
    BLOCK, REACH,
};
use sph_core::world::{
    archetype, column, column_kinds, column_mut, count, ensure_component, ColumnKinds, Joined,
};
use sph_core::{ParamError, StageRegistry};

#[derive(Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Also store each fluid particle's neighbour count (for frames and statistics).
    /// Default true.
    pub count: bool,
    /// Reorder the fluid particles by grid cell every this many calls (0: never), so
    /// neighbours are near in memory (`sort_particles.rs`). Changes sums only by
    /// round-off (the order of terms); results stay identical for any thread count.
    /// Default 20. With a skin, the sort waits for the first rebuild of the lists at
    /// least this many calls after the last sort (it renumbers the particles, so it can
    /// only run when the lists are rebuilt).
    pub sort_every: u32,
    /// The lists' skin, in particle spacings ds: they hold the pairs within the kernel
    /// support plus the skin and are rebuilt once a particle has moved half the skin
    /// (0: rebuilt every step). Default 0.3: on the 80,000-particle dam break a wider
    /// skin lengthens every pair loop by more than the rarer rebuilds save
    /// (docs/performance.md, "Sixth round").
    pub skin: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            count: true,
            sort_every: 20,
            skin: 0.3,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "neighbour_grid",
        "cell-linked list; neighbour lists of the fluid particles",
        |p: Params| {
            if !(p.skin >= 0.0 && p.skin <= 10.0) {
                return Err(ParamError::new("skin", p.skin, "0 to 10 particle spacings"));
            }
            Ok(NeighbourGrid {
                count: p.count,
                sort_every: p.sort_every,
                skin: p.skin,
                calls: 0,
                last_sort: None,
            })
        },
    );
}

pub struct NeighbourGrid {
    count: bool,
    sort_every: u32,
    /// In particle spacings.
    skin: f64,
    calls: u64,
    /// The call at which the particles were last sorted.
    last_sort: Option<u64>,
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
        grid.cell_count(),
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
    #[cfg(feature = "dim3")]
    {
        resize_by_eighths(&mut grid.zs, n, 0.0);
        (&mut grid.zs[..], &grid.particles[..])
            .into_par_iter()
            .for_each(|(z, &j)| *z = positions.get(j).0.z);
    }
}

/// Puts a neighbour list's fluid particles in ascending order and its ghosts (indices
/// from `n_fluid` on) after them, in their order: a pass sums the ghost neighbours
/// apart (the walls' work) without a second loop, and finds the fluid neighbours of
/// higher index, whose pairs it computes once for both particles, by a binary search
/// ([`Neighbours::upper`]).
fn ghosts_last(list: &mut [u32], n_fluid: u32) {
    let fluid = ghosts_after(list, n_fluid);
    list[..fluid].sort_unstable();
}

/// Moves the ghosts after the fluid particles, each part in its order; returns the
/// fluid count.
fn ghosts_after(list: &mut [u32], n_fluid: u32) -> usize {
    let mut ghosts = [0u32; 64];
    if list.iter().filter(|&&j| j >= n_fluid).count() > ghosts.len() {
        // More ghosts than the buffer holds (no kernel support does at the shipped
        // h/ds): on the heap.
        let (mut fluid, ghosts): (Vec<u32>, Vec<u32>) = list.iter().partition(|&&j| j < n_fluid);
        let n = fluid.len();
        fluid.extend(ghosts);
        list.copy_from_slice(&fluid);
        return n;
    }
    let (mut fluid, mut g) = (0, 0);
    for k in 0..list.len() {
        let j = list[k];
        if j < n_fluid {
            list[fluid] = j;
            fluid += 1;
        } else {
            ghosts[g] = j;
            g += 1;
        }
    }
    list[fluid..].copy_from_slice(&ghosts[..g]);
    fluid
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
        #[cfg(feature = "dim3")]
        let cells = cells * ((hi.z - lo.z) / support + 3.0);
        if cells > MAX_CELLS {
            return Err(sph_core::SetupError::new(
                "neighbour_grid",
                format!(
                    "the domain spans {cells:.0} grid cells of one kernel support ({support:.3e} m); accepted: at most {MAX_CELLS:.0} (the tank is too large for the resolution: use a coarser `resolution` or a smaller tank)"
                ),
            ));
        }
        sim.resources.insert(Neighbours {
            support,
            skin: self.skin * sim.constants.spacing,
            ..Default::default()
        });
        Ok(())
    }

    /// The call counter and the last sort, which decide when the particles are next
    /// sorted, and the positions the lists were built from.
    fn save_state(&mut self, sim: &Sim) -> Result<Vec<u8>, StepError> {
        let mut e = Enc::default();
        e.u64(self.calls);
        e.u64(self.last_sort.map_or(u64::MAX, |c| c));
        let (n_fluid, built) = sim
            .resources
            .get::<Neighbours>()
            .map_or((0, &[][..]), |nb| (nb.n_fluid, &nb.built_at[..]));
        e.u64(n_fluid as u64);
        e.u64(built.len() as u64);
        for p in built {
            for c in p.to_array() {
                e.f64(c);
            }
        }
        Ok(e.into_bytes())
    }

    /// Restores the counters and rebuilds the lists from the positions of their last
    /// build, so they are the uninterrupted run's.
    fn load_state(&mut self, sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        self.calls = d.u64()?;
        self.last_sort = Some(d.u64()?).filter(|&c| c != u64::MAX);
        let n_fluid = d.u64()? as usize;
        let n = d.len(8 * sph_core::dim::DIM)?;
        if n_fluid > n {
            return Err(sph_core::StateError::Mismatch(format!(
                "the neighbour lists' build holds {n} particles, fewer than its {n_fluid} fluid particles"
            )));
        }
        let mut built = Vec::with_capacity(n);
        for _ in 0..n {
            let mut p = Vector::ZERO;
            for k in 0..sph_core::dim::DIM {
                p[k] = d.f64()?;
            }
            built.push(Position(p));
        }
        d.end()?;
        let mut nb = sim.resources.take::<Neighbours>().unwrap_or_default();
        if n > 0 {
            let (f, g) = built.split_at(n_fluid);
            self.lists(sim, &mut nb, f, g);
        }
        sim.resources.insert(nb);
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let mut nb = sim.resources.take::<Neighbours>().unwrap_or_default();
        let result = self.step(sim, &mut nb);
        nb.plan = ListPlan::Undecided;
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
    /// Rebuilds the lists when they are outdated (sorting the particles first when a
    /// sort is due), and counts the neighbours within the support.
    fn step(&mut self, sim: &mut Sim, nb: &mut Neighbours) -> Result<(), StepError> {
        let rebuild = match nb.plan {
            ListPlan::Rebuild => true,
            ListPlan::Keep => false,
            ListPlan::Undecided => {
                let fluid = archetype::<Fluid>(&sim.world);
                let ghost = archetype::<Ghost>(&sim.world);
                let fpos = fluid.map(column::<Position>).transpose()?;
                let gpos = ghost.map(column::<Position>).transpose()?;
                nb.outdated(
                    fpos.as_deref().unwrap_or(&[]),
                    gpos.as_deref().unwrap_or(&[]),
                )
            }
        };
        let call = self.calls;
        self.calls += 1;
        nb.calls += 1;
        nb.age += 1;
        if rebuild {
            let due = self.sort_every > 0
                && self
                    .last_sort
                    .is_none_or(|last| call - last >= self.sort_every as u64);
            if due {
                self.last_sort = Some(call);
                self.sort(sim, nb)?;
            }
        }
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let ghost = archetype::<Ghost>(&sim.world);
        let fpos = column::<Position>(fluid)?;
        let gpos = ghost.map(column::<Position>).transpose()?;
        let gpos = gpos.as_deref().unwrap_or(&[]);
        if rebuild {
            self.lists(sim, nb, &fpos, gpos);
        }
        // With a skin, `Forces` counts the neighbours within the support in its own
        // loop when it is in the pipeline (`NeighbourCountsInPass`).
        let skin = nb.skin > 0.0;
        if self.count && !(skin && sim.resources.contains::<NeighbourCountsInPass>()) {
            let _span = tracing::info_span!("count").entered();
            let mut counts = column_mut::<NeighbourCount>(fluid)?;
            let fpos: &[Position] = &fpos;
            let within = Joined::new(fpos, gpos);
            let r2 = nb.support * nb.support;
            counts
                .par_chunks_mut(BLOCK)
                .zip(nb.blocks.par_iter())
                .enumerate()
                .for_each(|(b, (counts, block))| {
                    for (k, (c, w)) in counts.iter_mut().zip(block.offsets.windows(2)).enumerate() {
                        let list = &block.list[w[0] as usize..w[1] as usize];
                        // Without a skin every listed pair is within the support.
                        c.0 = if skin {
                            let x = fpos[b * BLOCK + k].0;
                            list.iter()
                                .filter(|&&j| x.distance_squared(within.get(j).0) < r2)
                                .count() as u32
                        } else {
                            list.len() as u32
                        };
                    }
                });
        }
        Ok(())
    }

    /// Reorders the fluid particles by the cells of the grid about to be built.
    fn sort(&self, sim: &mut Sim, nb: &mut Neighbours) -> Result<(), StepError> {
        let _span = tracing::info_span!("sort").entered();
        self.shape(sim, nb);
        let kinds = sim
            .resources
            .get::<ColumnKinds>()
            .ok_or_else(|| StepError::Internal("NeighbourGrid ran without its setup".into()))?;
        // The sort borrows the grid's buffers, which the rebuild overwrites; sized
        // first for the rebuild (fluid and ghosts), or the sort's fluid-only size and
        // the rebuild's growth would double them.
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
            shape.cell_count(),
            |x| shape.index_of(x),
            SortBuffers {
                cells: &mut cells,
                start: &mut start,
                order: &mut order,
            },
        );
        (grid.cells, grid.start, grid.particles) = (cells, start, order);
        if !sorted? {
            sim.diagnostics.insert("cell_sort_skipped".into(), 1.0);
        }
        Ok(())
    }

    /// Shapes the grid: cells of the lists' reach (support and skin) over the domain
    /// and the ghosts beyond its walls.
    fn shape(&self, sim: &Sim, nb: &mut Neighbours) {
        nb.support = sim.constants.support();
        nb.skin = self.skin * sim.constants.spacing;
        let reach = nb.reach();
        let (lo, hi) = sim.constants.domain;
        let pad = Vector::splat(reach);
        nb.grid.shape((lo - pad, hi + pad), reach / REACH as f64);
    }

    /// Builds the grid and the lists of the particles at `fpos` and `gpos` (fluid and
    /// ghosts), and records the positions.
    fn lists(&self, sim: &Sim, nb: &mut Neighbours, fpos: &[Position], gpos: &[Position]) {
        self.shape(sim, nb);
        nb.builds += 1;
        nb.age = 0;
        nb.n_fluid = fpos.len();
        nb.n_ghost = gpos.len();
        nb.fluid_ascending = true;
        let positions = Joined::new(fpos, gpos);
        rebuild(&mut nb.grid, positions);
        let reach = nb.reach();
        let r2max = reach * reach;
        let grid = &nb.grid;
        let n = nb.n_fluid;
        nb.blocks
            .resize_with(n.div_ceil(BLOCK), NeighbourBlock::default);
        let scan = Scan::detect();
        tracing::info_span!("scan").in_scope(|| {
            nb.blocks.par_iter_mut().enumerate().for_each(|(b, block)| {
                let range = b * BLOCK..((b + 1) * BLOCK).min(n);
                scan.build_block(grid, fpos, r2max, range, block);
                for w in block.offsets.windows(2) {
                    ghosts_last(&mut block.list[w[0] as usize..w[1] as usize], n as u32);
                }
            })
        });
        nb.blocks.truncate(n.div_ceil(BLOCK));
        if nb.skin > 0.0 {
            // Lists that last need the scan's position copies and the cell scratch only
            // at their rebuilds: freed between them (20 bytes a particle, about what
            // the positions of the build take).
            let g = &mut nb.grid;
            (g.xs, g.ys, g.cells) = (Vec::new(), Vec::new(), Vec::new());
            #[cfg(feature = "dim3")]
            {
                g.zs = Vec::new();
            }
        }
        let joint = fpos.len() + gpos.len();
        resize_by_eighths(&mut nb.built_at, joint, Vector::ZERO);
        let (f, g) = nb.built_at.split_at_mut(fpos.len());
        f.par_iter_mut().zip(fpos).for_each(|(b, p)| *b = p.0);
        g.par_iter_mut().zip(gpos).for_each(|(b, p)| *b = p.0);
    }
}

#[cfg(test)]
mod tests {
    use super::ghosts_last;

    #[test]
    fn fluid_ascend_and_ghosts_go_last_in_their_order() {
        let mut list = [7, 12, 3, 10, 1, 11];
        ghosts_last(&mut list, 10);
        assert_eq!(list, [1, 3, 7, 12, 10, 11]);
        // More ghosts than the stack buffer.
        let mut long: Vec<u32> = (0..200)
            .map(|k| if k % 3 == 0 { 1000 + k } else { 200 - k })
            .collect();
        let (mut fluid, ghosts): (Vec<u32>, Vec<u32>) = long.iter().partition(|&&j| j < 1000);
        fluid.sort_unstable();
        fluid.extend(ghosts);
        ghosts_last(&mut long, 1000);
        assert_eq!(long, fluid);
    }
}
