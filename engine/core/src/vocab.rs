//! The shared vocabulary: the quantities that several stages use, so that no stage
//! imports another stage's module. A stage (standard or plugin) that wants the
//! neighbour lists, the leapfrog's half-step state or the dissipation rate imports
//! them from here, whichever stage produces them.
//!
//! - [`Neighbours`]: the neighbour lists of one step and the cell grid they were built
//!   on (for point queries: sensors, gauges). Produced by the `NeighbourGrid` stage.
//! - [`HalfVelocity`], [`HalfDensity`]: the leapfrog's half-step state, per fluid
//!   particle. Produced by `Integrate`; `Reinitialise` shifts the density, `DampingZone`
//!   damps the velocity.
//! - [`Guarded`]: per fluid particle, which safeguards have acted on it (`Integrate`
//!   sets, `Probe` reads).
//! - [`ArtificialViscosity`]: the viscosity coefficients the momentum stage exposes
//!   (for a sweep's linear-theory damping).
//! - Keyed columns ([`crate::pair::Columns`]): per-particle quantities a stage computes
//!   for pair terms to read.
//! - [`require_neighbours`]: the setup check of the stages that sum over neighbours.
//!
//! - The scene as the world holds it, re-exported here: [`WallPose`] (each wall now),
//!   [`BodyPose`] (the tank's and each piston's pose now), both written by the
//!   kinematics when the clock advances; [`Walls`] (all walls at once, with their
//!   lines and corners); [`MirrorWall`] (the wall a ghost was mirrored across);
//!   [`Piston`] (the marker a stage finds the piston by).
//!
//! The particle components (`Position`, `Density`, ...) are in [`crate::components`].
//! What one scheme's stages share (the DFSPH factors, the ghosts' reflections and no-slip
//! velocities, the energy budget's rates) is in the physics crate's vocabulary,
//! `sph_stages::vocab`.

use crate::components::Position;
pub use crate::components::{BodyPose, MirrorWall, WallPose};
use crate::dim::Vector;
pub use crate::piston::Piston;
use crate::sim::Sim;
use crate::stage::{SetupError, StepError};
pub use crate::walls::Walls;
use rayon::prelude::*;

/// Fluid particles per block of neighbour lists (a power of two, so [`Neighbours::of`]
/// finds a particle's block with a shift).
pub const BLOCK_BITS: usize = 10;
/// `1 << BLOCK_BITS`.
pub const BLOCK: usize = 1 << BLOCK_BITS;

/// Cells per kernel support of the cell grid (see the `NeighbourGrid` stage for why 1).
pub const REACH: usize = 1;

/// Rows (and columns) of cells searched around a particle.
pub const ROWS: usize = 2 * REACH + 1;

/// The runs of cells searched around a particle ([`CellGrid::ranges_near`]): one per
/// row of cells in 2D, one per row and layer in 3D.
pub const RANGES: usize = if crate::dim::DIM == 2 {
    ROWS
} else {
    ROWS * ROWS
};

/// A cell's (column, row) in 2D, (column, row, layer) in 3D.
#[cfg(not(feature = "dim3"))]
pub type Cell = (usize, usize);
/// A cell's (column, row) in 2D, (column, row, layer) in 3D.
#[cfg(feature = "dim3")]
pub type Cell = (usize, usize, usize);

/// Resizes `v` to `n` elements; when its capacity must grow, to `n` and an eighth more,
/// not by doubling: buffers that keep their capacity from step to step would otherwise
/// hold up to twice the memory needed.
pub fn resize_by_eighths<T: Clone>(v: &mut Vec<T>, n: usize, value: T) {
    if n > v.capacity() {
        v.reserve_exact(n + n / 8 - v.len());
    }
    v.resize(n, value);
}

/// A uniform grid of cells over the domain, each listing the particles inside it
/// (joint numbering). The `NeighbourGrid` stage shapes and fills it; other stages use
/// it for point queries ([`CellGrid::for_each_near`]).
#[derive(Default)]
pub struct CellGrid {
    pub origin: Vector,
    /// Cell size [m].
    pub cell: f64,
    pub nx: usize,
    pub ny: usize,
    /// Layers of cells along z (3D).
    #[cfg(feature = "dim3")]
    pub nz: usize,
    /// `start[c]..start[c+1]` indexes `particles` (and `xs`) for cell c.
    pub start: Vec<u32>,
    /// Joint indices, cell by cell, ascending within a cell.
    pub particles: Vec<u32>,
    /// x and y (and z in 3D) of the positions in the order of `particles` (separate
    /// arrays), so a candidate scan reads contiguous memory and its distance test
    /// vectorises.
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    #[cfg(feature = "dim3")]
    pub zs: Vec<f64>,
    /// Each particle's cell (scratch kept between steps).
    pub cells: Vec<u32>,
}

impl CellGrid {
    /// Sets the grid geometry: cells of size `cell` covering `domain`.
    pub fn shape(&mut self, domain: (Vector, Vector), cell: f64) {
        self.origin = domain.0;
        self.cell = cell;
        let extent = domain.1 - domain.0;
        self.nx = ((extent.x / cell).ceil() as usize).max(1);
        self.ny = ((extent.y / cell).ceil() as usize).max(1);
        #[cfg(feature = "dim3")]
        {
            self.nz = ((extent.z / cell).ceil() as usize).max(1);
        }
    }

    /// The number of cells.
    pub fn cell_count(&self) -> usize {
        #[cfg(not(feature = "dim3"))]
        return self.nx * self.ny;
        #[cfg(feature = "dim3")]
        return self.nx * self.ny * self.nz;
    }

    /// The cell holding `x`, clamped to the grid.
    #[inline(always)]
    pub fn cell_of(&self, x: Vector) -> Cell {
        // floor by truncation (a positive number truncates to its floor; anything
        // else, NaN included, goes to cell 0 as the clamp did): `f64::floor` is a
        // library call on baseline x86-64.
        let c = (x - self.origin) / self.cell;
        let index = |c: f64, n: usize| if c > 0.0 { (c as usize).min(n - 1) } else { 0 };
        #[cfg(not(feature = "dim3"))]
        return (index(c.x, self.nx), index(c.y, self.ny));
        #[cfg(feature = "dim3")]
        return (
            index(c.x, self.nx),
            index(c.y, self.ny),
            index(c.z, self.nz),
        );
    }

    /// The index of the cell holding `x` (x fastest, then y, then z).
    #[inline(always)]
    pub fn index_of(&self, x: Vector) -> usize {
        #[cfg(not(feature = "dim3"))]
        {
            let (cx, cy) = self.cell_of(x);
            cy * self.nx + cx
        }
        #[cfg(feature = "dim3")]
        {
            let (cx, cy, cz) = self.cell_of(x);
            (cz * self.ny + cy) * self.nx + cx
        }
    }

    /// The index ranges (into `particles` / `xs`) of the `ROWS` x `ROWS` (3D: x
    /// `ROWS`) cells around `x`, one per row of cells, in the fixed order (rows bottom
    /// to top; in 3D layer by layer, front to back).
    #[inline(always)]
    pub fn ranges_near(&self, x: Vector) -> [std::ops::Range<usize>; RANGES] {
        #[cfg(not(feature = "dim3"))]
        let ((cx, cy), layer) = (self.cell_of(x), |_: usize| Some(0));
        #[cfg(feature = "dim3")]
        let ((cx, cy), layer) = {
            let (cx, cy, cz) = self.cell_of(x);
            let nz = self.nz;
            ((cx, cy), move |k: usize| {
                let z = cz + k / ROWS;
                (z >= REACH && z - REACH < nz).then(|| (z - REACH) * self.ny)
            })
        };
        let (x0, x1) = (cx.saturating_sub(REACH), (cx + REACH).min(self.nx - 1));
        std::array::from_fn(|k| {
            let y = cy + k % ROWS;
            let Some(rows_below) = layer(k) else {
                return 0..0;
            };
            if y < REACH || y - REACH >= self.ny {
                return 0..0;
            }
            let r = (rows_below + y - REACH) * self.nx;
            self.start[r + x0] as usize..self.start[r + x1 + 1] as usize
        })
    }

    /// Calls `f(j)` for every particle within one support of `x` or a little farther
    /// (the cells around it), in the fixed order.
    #[inline]
    pub fn for_each_near(&self, x: Vector, mut f: impl FnMut(u32)) {
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
    pub offsets: Vec<u32>,
    pub list: Vec<u32>,
}

/// The neighbour lists: for every fluid particle the particles within the kernel
/// support and a skin beyond it at the lists' build (joint numbering: fluid
/// `0..n_fluid`, then ghosts), in a fixed order, kept in blocks of [`BLOCK`] particles
/// that are built in parallel and reused from step to step. A resource of the [`Sim`],
/// produced by the `NeighbourGrid` stage.
///
/// The lists last while no particle has moved more than half the skin since their
/// build ([`Neighbours::outdated`]): every pair now within the support is then in them.
/// They also hold pairs beyond the support, which add nothing to a pair sum (every
/// kernel and its gradient vanish there); a loop that is not weighted by the kernel
/// must test the distance itself.
#[derive(Default)]
pub struct Neighbours {
    pub n_fluid: usize,
    pub n_ghost: usize,
    /// Kernel support radius [m].
    pub support: f64,
    /// How far beyond the support the lists reach at their build [m]; 0: rebuilt every
    /// step (`NeighbourGrid(skin)`).
    pub skin: f64,
    /// The joint positions (fluid, then ghosts) the lists were built from.
    pub built_at: Vec<Vector>,
    /// This step's decision, when a stage before the grid (`GhostWalls`, which must
    /// keep or renew its ghosts with the lists) has taken it.
    pub plan: ListPlan,
    /// Steps the lists have served and builds since the start of the run (or resume):
    /// their mean age is `calls / builds`.
    pub calls: u64,
    pub builds: u64,
    /// Steps the current lists have served before this one (0 on a build step).
    pub age: u64,
    /// The lists, block by block (filled by the grid stage; read them with
    /// [`Neighbours::of`]).
    pub blocks: Vec<NeighbourBlock>,
    /// The cell grid, for point queries (sensors, gauges).
    pub grid: CellGrid,
    /// Each particle's fluid neighbours are in ascending order (before its ghosts, as
    /// always), so those of higher index are a tail ([`Neighbours::parts`]): the pair
    /// stages then compute each fluid pair once, for both particles. Set by the grid
    /// stage at each build.
    pub fluid_ascending: bool,
}

/// Whether the lists are rebuilt this step, when decided before the grid stage runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ListPlan {
    /// The grid stage decides ([`Neighbours::outdated`]).
    #[default]
    Undecided,
    /// The lists stay (checked on this step's positions).
    Keep,
    /// The lists are rebuilt (the ghosts were renewed).
    Rebuild,
}

impl Neighbours {
    /// The radius the lists were built with, support and skin [m].
    pub fn reach(&self) -> f64 {
        self.support + self.skin
    }

    /// Whether the lists no longer hold every pair within the support of particles at
    /// `fluid` and `ghost`: true without a skin, when the particle counts differ from
    /// the build's, or when a particle has moved more than half the skin since it. A
    /// function of the positions alone, so the same for any thread count.
    pub fn outdated(&self, fluid: &[Position], ghost: &[Position]) -> bool {
        if self.skin.is_nan()
            || self.skin <= 0.0
            || self.n_fluid != fluid.len()
            || self.n_ghost != ghost.len()
            || self.built_at.len() != fluid.len() + ghost.len()
        {
            return true;
        }
        let limit = (0.5 * self.skin).powi(2);
        let (f0, g0) = self.built_at.split_at(fluid.len());
        let moved = |now: &[Position], then: &[Vector]| {
            now.par_chunks(4096)
                .zip(then.par_chunks(4096))
                .any(|(a, b)| {
                    // Without an early exit, so that the chunk's loop vectorises;
                    // a non-finite position is outdated too.
                    a.iter().zip(b).fold(false, |out, (a, b)| {
                        let d = a.0.distance_squared(*b);
                        out | d.is_nan() | (d > limit)
                    })
                })
        };
        moved(fluid, f0) || moved(ghost, g0)
    }

    /// Neighbours of fluid particle `i` (joint numbering, self excluded).
    #[inline(always)]
    pub fn of(&self, i: usize) -> &[u32] {
        let b = &self.blocks[i >> BLOCK_BITS];
        let k = i & (BLOCK - 1);
        &b.list[b.offsets[k] as usize..b.offsets[k + 1] as usize]
    }

    /// Fluid particle `i`'s list in three parts: its fluid neighbours of lower index,
    /// those of higher index, and its ghosts (which follow the fluid ones). The first
    /// two are the fluid neighbours below and above `i` only when
    /// [`Neighbours::fluid_ascending`].
    #[inline(always)]
    pub fn parts(&self, i: usize) -> [&[u32]; 3] {
        let list = self.of(i);
        let n = self.n_fluid as u64;
        let fluid = match list.last() {
            Some(&j) if u64::from(j) >= n => list.partition_point(|&j| u64::from(j) < n),
            _ => list.len(),
        };
        let (fluid, ghosts) = list.split_at(fluid);
        let (lower, upper) = fluid.split_at(fluid.partition_point(|&j| (j as usize) < i));
        [lower, upper, ghosts]
    }

    /// Checks that a buffer of `len` particles (joint numbering) holds every index in
    /// the lists, which are below `n_fluid + n_ghost`: the SIMD pair sums gather
    /// without bounds checks.
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

    /// Total number of neighbour pairs (i, j) in the lists (within the support and
    /// skin at the build): the interactions one pass over all neighbours evaluates.
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
            + 16 * self.built_at.capacity()
            + 4 * (g.start.capacity() + g.particles.capacity() + g.cells.capacity())
            + 8 * (g.xs.capacity() + g.ys.capacity())
    }
}

/// Marks that a pair stage (`Forces`) writes every fluid particle's `NeighbourCount`
/// (neighbours within the support) from its own neighbour loop each step, so the grid
/// stage need not count the lists, which with a skin hold pairs beyond the support.
/// Inserted at setup by that stage.
#[derive(Clone, Copy, Debug, Default)]
pub struct NeighbourCountsInPass;

/// Setup check shared by the stages that sum over neighbours.
pub fn require_neighbours(sim: &Sim, stage: &'static str) -> Result<(), SetupError> {
    if sim.resources.contains::<Neighbours>() {
        Ok(())
    } else {
        Err(SetupError::new(
            stage,
            "needs neighbour lists: put NeighbourGrid() before it in the pipeline",
        ))
    }
}

/// v at the last half step (leapfrog state), per fluid particle.
#[derive(Clone, Copy, Debug, Default)]
pub struct HalfVelocity(pub Vector);
/// rho at the last half step (leapfrog state), per fluid particle.
#[derive(Clone, Copy, Debug, Default)]
pub struct HalfDensity(pub f64);

crate::checkpoint_newtype!(HalfVelocity(Vector), HalfDensity(f64), Guarded(u8));

/// What the safeguards outside the model have done to a fluid particle so far in the
/// run (docs/physics.md, "Safeguards outside the model"): bit flags, [`Guarded::FLOORED`]
/// and [`Guarded::REFLECTED`], set by the integrator and never cleared, so diagnostics
/// can report the flow apart from what the guards did (`Probe`'s
/// `max_density_fluctuation` is over particles with no flag).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Guarded(pub u8);

impl Guarded {
    /// The density floor raised the particle's density (or half-step density).
    pub const FLOORED: u8 = 1;
    /// The particle was reflected at a wall (and its density restored, if asked).
    pub const REFLECTED: u8 = 2;
    /// No guard has acted on the particle.
    pub fn untouched(self) -> bool {
        self.0 == 0
    }
}

/// Monaghan's artificial viscosity coefficients a momentum stage runs with, exposed in
/// its declared contract ([`crate::contract::Access::exposes`]): a sweep damps its
/// linear-theory reference by the viscosity they imply
/// (`sph_scenario::Scenario::exposed`).
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct ArtificialViscosity {
    /// Linear coefficient alpha.
    pub alpha: f64,
    /// Quadratic coefficient beta.
    pub beta: f64,
}
