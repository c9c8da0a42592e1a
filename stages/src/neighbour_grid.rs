//! Neighbour search: a cell-linked list with cells the size of the kernel support
//! (physics.md, "Neighbour search"), over fluid and ghost particles together.
//!
//! Publishes [`Neighbours`]: for every fluid particle the list of particles within the
//! support (joint numbering: fluid `0..n_fluid`, then ghosts), in a fixed order — cells
//! scanned row by row, indices ascending within a cell — so every sum over neighbours is
//! the same whatever the thread count. The lists are reused by every later stage of the
//! step.

use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Fluid, Ghost, NeighbourCount, Position};
use sph_core::sim::Sim;
use sph_core::stage::{Stage, StepError};
use sph_core::world::{archetype, column, column_mut, ensure_component, Joined};
use sph_core::StageRegistry;

/// Fluid particles per parallel block when building the lists.
const BLOCK: usize = 1024;

#[derive(Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Also store each fluid particle's neighbour count (for frames and statistics).
    /// Default true.
    pub count: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self { count: true }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register(
        "neighbour_grid",
        "cell-linked list; neighbour lists of the fluid particles",
        |p: Params| Ok(NeighbourGrid { count: p.count }),
    );
}

pub struct NeighbourGrid {
    count: bool,
}

/// A uniform grid of cells over the domain, each listing the particles inside it.
#[derive(Default)]
pub struct CellGrid {
    origin: DVec2,
    cell: f64,
    nx: usize,
    ny: usize,
    /// `start[c]..start[c+1]` indexes `particles` for cell c.
    start: Vec<u32>,
    particles: Vec<u32>,
}

impl CellGrid {
    fn cell_of(&self, x: DVec2) -> (usize, usize) {
        let c = ((x - self.origin) / self.cell).floor();
        (
            c.x.clamp(0.0, (self.nx - 1) as f64) as usize,
            c.y.clamp(0.0, (self.ny - 1) as f64) as usize,
        )
    }

    /// Rebuilds the grid for `positions` (joint numbering) by a counting sort, so each
    /// cell lists its particles in ascending index order.
    fn rebuild(&mut self, positions: Joined<Position>, domain: (DVec2, DVec2), cell: f64) {
        self.origin = domain.0;
        self.cell = cell;
        let extent = domain.1 - domain.0;
        self.nx = ((extent.x / cell).ceil() as usize).max(1);
        self.ny = ((extent.y / cell).ceil() as usize).max(1);
        let n = positions.len();
        let cells: Vec<u32> = (0..n)
            .into_par_iter()
            .map(|j| {
                let (cx, cy) = self.cell_of(positions.get(j as u32).0);
                (cy * self.nx + cx) as u32
            })
            .collect();
        self.start.clear();
        self.start.resize(self.nx * self.ny + 1, 0);
        for &c in &cells {
            self.start[c as usize + 1] += 1;
        }
        for c in 0..self.nx * self.ny {
            self.start[c + 1] += self.start[c];
        }
        self.particles.resize(n, 0);
        let mut fill = self.start.clone();
        for (j, &c) in cells.iter().enumerate() {
            self.particles[fill[c as usize] as usize] = j as u32;
            fill[c as usize] += 1;
        }
    }

    /// Calls `f(j)` for every particle in the 3x3 cells around `x`, in the fixed order.
    #[inline]
    pub fn for_each_near(&self, x: DVec2, mut f: impl FnMut(u32)) {
        if self.start.is_empty() {
            return;
        }
        let (cx, cy) = self.cell_of(x);
        for y in cy.saturating_sub(1)..=(cy + 1).min(self.ny - 1) {
            let row = y * self.nx;
            let lo = self.start[row + cx.saturating_sub(1)] as usize;
            let hi = self.start[row + (cx + 1).min(self.nx - 1) + 1] as usize;
            for &j in &self.particles[lo..hi] {
                f(j);
            }
        }
    }
}

/// The neighbour lists of one step.
#[derive(Default)]
pub struct Neighbours {
    pub n_fluid: usize,
    pub n_ghost: usize,
    /// Kernel support radius the lists were built for [m].
    pub support: f64,
    /// `list[offsets[i]..offsets[i+1]]` are fluid particle i's neighbours (self excluded).
    pub offsets: Vec<u32>,
    pub list: Vec<u32>,
    /// The cell grid, for point queries (sensors, gauges).
    pub grid: CellGrid,
}

impl Neighbours {
    /// Neighbours of fluid particle `i`.
    #[inline(always)]
    pub fn of(&self, i: usize) -> &[u32] {
        &self.list[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

impl Stage for NeighbourGrid {
    fn name(&self) -> &'static str {
        "neighbour_grid"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), sph_core::SetupError> {
        if self.count {
            ensure_component::<Fluid, NeighbourCount>(&mut sim.world);
        }
        sim.resources.insert(Neighbours::default());
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let mut nb = sim.resources.take::<Neighbours>().unwrap_or_default();
        let result = self.build(sim, &mut nb);
        sim.resources.insert(nb);
        result
    }
}

impl NeighbourGrid {
    fn build(&self, sim: &Sim, nb: &mut Neighbours) -> Result<(), StepError> {
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let ghost = archetype::<Ghost>(&sim.world);
        let fpos = column::<Position>(fluid)?;
        let gpos = ghost.map(column::<Position>).transpose()?;
        let positions = Joined::new(&fpos[..], gpos.as_deref().unwrap_or(&[]));
        let support = sim.constants.support();
        nb.n_fluid = fpos.len();
        nb.n_ghost = positions.len() - fpos.len();
        nb.support = support;
        // The grid must also cover ghosts, which lie up to one support outside the walls.
        let (lo, hi) = sim.constants.domain;
        let pad = DVec2::splat(support);
        nb.grid.rebuild(positions, (lo - pad, hi + pad), support);

        let fpos: &[Position] = &fpos;
        let r2max = support * support;
        let grid = &nb.grid;
        let n = nb.n_fluid;
        let blocks: Vec<(Vec<u32>, Vec<u32>)> = (0..n.div_ceil(BLOCK))
            .into_par_iter()
            .map(|b| {
                let mut counts = Vec::with_capacity(BLOCK);
                let mut list = Vec::with_capacity(BLOCK * 24);
                let first = b * BLOCK;
                for (i, xi) in fpos
                    .iter()
                    .enumerate()
                    .take(((b + 1) * BLOCK).min(n))
                    .skip(first)
                {
                    let xi = xi.0;
                    let before = list.len();
                    grid.for_each_near(xi, |j| {
                        if j as usize != i && (xi - positions.get(j).0).length_squared() < r2max {
                            list.push(j);
                        }
                    });
                    counts.push((list.len() - before) as u32);
                }
                (counts, list)
            })
            .collect();
        nb.offsets.clear();
        nb.offsets.reserve(n + 1);
        nb.offsets.push(0);
        nb.list.clear();
        let mut total = 0u32;
        for (counts, list) in &blocks {
            for c in counts {
                total += c;
                nb.offsets.push(total);
            }
            nb.list.extend_from_slice(list);
        }
        if self.count {
            let mut counts = column_mut::<NeighbourCount>(fluid)?;
            for (i, c) in counts.iter_mut().enumerate() {
                c.0 = nb.offsets[i + 1] - nb.offsets[i];
            }
        }
        Ok(())
    }
}
