//! Neighbour search: a cell-linked list with cells the size of the kernel support
//! (docs/physics.md, "Neighbour search"), over fluid and ghost particles together.
//!
//! Publishes [`Neighbours`]: for every fluid particle the list of particles within the
//! support (joint numbering: fluid `0..n_fluid`, then ghosts), in a fixed order — cells
//! scanned row by row, indices ascending within a cell — so every sum over neighbours is
//! the same whatever the thread count. The lists are reused by every later stage of the
//! step.

use crate::scan::Scan;
use crate::sort_particles::{counting_sort, sort_by_cell, SortBuffers};
use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{Fluid, Ghost, NeighbourCount, Position};
use sph_core::sim::Sim;
use sph_core::stage::{Stage, StepError};
use sph_core::world::{
    archetype, column, column_kinds, column_mut, count, ensure_component, ColumnKinds, Joined,
};
use sph_core::StageRegistry;

/// Fluid particles per parallel block when building the lists (a power of two, so
/// [`Neighbours::of`] finds a particle's block with a shift).
const BLOCK_BITS: usize = 10;
const BLOCK: usize = 1 << BLOCK_BITS;

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

/// Cells per kernel support. With 2 (cells of half the support searched 5 x 5, an
/// area of (2.5 r_s)^2 instead of (3 r_s)^2) about 30 % fewer candidates are
/// distance-tested, but the grid has four times the cells, whose counting sort eats
/// the gain: measured at 80k, 5 % less user time in this stage and 1 % overall, for
/// about 15 more bytes per particle. So 1.
const REACH: usize = 1;
/// The most grid cells: the cell index array alone takes 4 bytes a cell.
const MAX_CELLS: f64 = 1e8;

/// Rows (and columns) of cells searched around a particle.
const ROWS: usize = 2 * REACH + 1;

/// Resizes `v` to `n` elements; when its capacity must grow, to `n` and an eighth more,
/// not by doubling: these buffers keep their capacity from step to step, so doubling
/// would hold up to twice the memory needed.
pub(crate) fn resize_by_eighths<T: Clone>(v: &mut Vec<T>, n: usize, value: T) {
    if n > v.capacity() {
        v.reserve_exact(n + n / 8 - v.len());
    }
    v.resize(n, value);
}

/// A uniform grid of cells over the domain, each listing the particles inside it.
#[derive(Default)]
pub struct CellGrid {
    origin: DVec2,
    cell: f64,
    nx: usize,
    ny: usize,
    /// `start[c]..start[c+1]` indexes `particles` (and `xs`) for cell c.
    start: Vec<u32>,
    /// Joint indices, cell by cell, ascending within a cell.
    pub(crate) particles: Vec<u32>,
    /// x and y of the positions in the order of `particles` (separate arrays), so a
    /// candidate scan reads contiguous memory and its distance test vectorises.
    pub(crate) xs: Vec<f64>,
    pub(crate) ys: Vec<f64>,
    /// Each particle's cell (scratch kept between steps).
    cells: Vec<u32>,
}

impl CellGrid {
    /// Sets the grid geometry: cells of size `cell` covering `domain`.
    fn shape(&mut self, domain: (DVec2, DVec2), cell: f64) {
        self.origin = domain.0;
        self.cell = cell;
        let extent = domain.1 - domain.0;
        self.nx = ((extent.x / cell).ceil() as usize).max(1);
        self.ny = ((extent.y / cell).ceil() as usize).max(1);
    }

    #[inline(always)]
    fn cell_of(&self, x: DVec2) -> (usize, usize) {
        // floor by truncation (a positive number truncates to its floor; anything
        // else, NaN included, goes to cell 0 as the clamp did): `f64::floor` is a
        // library call on baseline x86-64.
        let c = (x - self.origin) / self.cell;
        let index = |c: f64, n: usize| if c > 0.0 { (c as usize).min(n - 1) } else { 0 };
        (index(c.x, self.nx), index(c.y, self.ny))
    }

    #[inline(always)]
    fn index_of(&self, x: DVec2) -> usize {
        let (cx, cy) = self.cell_of(x);
        cy * self.nx + cx
    }

    /// Rebuilds the grid for `positions` (joint numbering) by a counting sort, so each
    /// cell lists its particles in ascending index order. Reuses its buffers.
    fn rebuild(&mut self, positions: Joined<Position>) {
        let _span = tracing::info_span!("grid_build").entered();
        let n = positions.len();
        let mut cells = std::mem::take(&mut self.cells);
        resize_by_eighths(&mut cells, n, 0);
        cells
            .par_iter_mut()
            .enumerate()
            .for_each(|(j, c)| *c = self.index_of(positions.get(j as u32).0) as u32);
        counting_sort(
            &cells,
            self.nx * self.ny,
            &mut self.start,
            &mut self.particles,
        );
        self.cells = cells;
        resize_by_eighths(&mut self.xs, n, 0.0);
        resize_by_eighths(&mut self.ys, n, 0.0);
        (&mut self.xs[..], &mut self.ys[..], &self.particles[..])
            .into_par_iter()
            .for_each(|(x, y, &j)| {
                let p = positions.get(j).0;
                (*x, *y) = (p.x, p.y);
            });
    }

    /// The index ranges (into `particles` / `xs`) of the `ROWS` x `ROWS` cells around
    /// `x`, one per row of cells, in the fixed order (rows bottom to top).
    #[inline(always)]
    pub(crate) fn ranges_near(&self, x: DVec2) -> [std::ops::Range<usize>; ROWS] {
        let (cx, cy) = self.cell_of(x);
        let (x0, x1) = (cx.saturating_sub(REACH), (cx + REACH).min(self.nx - 1));
        std::array::from_fn(|k| {
            let y = cy + k;
            if y < REACH || y - REACH >= self.ny {
                return 0..0;
            }
            let r = (y - REACH) * self.nx;
            self.start[r + x0] as usize..self.start[r + x1 + 1] as usize
        })
    }

    /// Calls `f(j)` for every particle within one support of `x` or a little farther
    /// (the cells around it), in the fixed order.
    #[inline]
    pub fn for_each_near(&self, x: DVec2, mut f: impl FnMut(u32)) {
        if self.start.is_empty() {
            return;
        }
        for range in self.ranges_near(x) {
            for &j in &self.particles[range] {
                f(j);
            }
        }
    }
}

/// Neighbour lists of [`BLOCK`] consecutive fluid particles.
#[derive(Default)]
pub struct NeighbourBlock {
    /// `list[offsets[k]..offsets[k+1]]` are the neighbours of the block's k-th particle.
    pub(crate) offsets: Vec<u32>,
    pub(crate) list: Vec<u32>,
}

/// The neighbour lists of one step, kept in blocks of [`BLOCK`] particles that are
/// built in parallel and reused from step to step (no per-step allocation once the
/// lists have reached their size).
#[derive(Default)]
pub struct Neighbours {
    pub n_fluid: usize,
    pub n_ghost: usize,
    /// Kernel support radius the lists were built for [m].
    pub support: f64,
    blocks: Vec<NeighbourBlock>,
    /// The cell grid, for point queries (sensors, gauges).
    pub grid: CellGrid,
}

impl Neighbours {
    /// Neighbours of fluid particle `i` (joint numbering, self excluded).
    #[inline(always)]
    pub fn of(&self, i: usize) -> &[u32] {
        let b = &self.blocks[i >> BLOCK_BITS];
        let k = i & (BLOCK - 1);
        &b.list[b.offsets[k] as usize..b.offsets[k + 1] as usize]
    }

    /// Checks that a buffer of `len` particles (joint numbering) holds every index in
    /// the lists, which are below `n_fluid + n_ghost`: the SIMD pair sums gather
    /// without bounds checks (`crate::pair_x8`).
    pub fn check_covers(&self, len: usize) -> Result<(), StepError> {
        if self.n_fluid + self.n_ghost <= len {
            Ok(())
        } else {
            Err(StepError::Internal(format!(
                "the neighbour lists index {} particles but the particle buffer holds {len}: \
                 a stage between NeighbourGrid and the pair sums changed the particle count",
                self.n_fluid + self.n_ghost
            )))
        }
    }

    /// Total number of neighbour pairs (i, j) in the lists: the interactions one
    /// pass over all neighbours evaluates.
    pub fn interactions(&self) -> usize {
        self.blocks.iter().map(|b| b.list.len()).sum()
    }

    /// Bytes held by the lists and the grid (capacity), for memory accounting.
    pub fn heap_bytes(&self) -> usize {
        let blocks: usize = self
            .blocks
            .iter()
            .map(|b| 4 * (b.offsets.capacity() + b.list.capacity()))
            .sum();
        let g = &self.grid;
        blocks
            + 4 * (g.start.capacity() + g.particles.capacity() + g.cells.capacity())
            + 8 * (g.xs.capacity() + g.ys.capacity())
    }
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
        nb.grid.rebuild(positions);

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
