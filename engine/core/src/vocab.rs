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
//! - [`ViscousDissipation`]: the artificial viscosity's dissipation rate, asked for by
//!   `Energy` and filled in by `Forces`.
//! - [`DensityGradients`]: the renormalised density gradients of fluid and ghosts,
//!   written by `Forces` for its delta-SPH term.
//! - [`DiffusionPower`]: the internal-energy change rate of a density diffusion,
//!   asked for by `Energy` and filled in by `Forces`.
//! - [`WallPower`]: the rate of work the walls do on the fluid through the ghosts,
//!   asked for by `Energy` and filled in by `Forces`.
//! - [`GuardPower`]: the energy the safeguards (reflections, density floor) add,
//!   asked for by `Energy` and filled in by `Integrate`.
//! - [`Guarded`]: per fluid particle, which safeguards have acted on it (`Integrate`
//!   sets, `Probe` reads).
//! - [`ArtificialViscosity`]: the viscosity coefficients the momentum stage exposes
//!   (for a sweep's linear-theory damping).
//! - [`ContinuityInPipeline`]: marks that a continuity stage writes the density rate.
//! - [`GhostSettings`], [`refresh_ghost_density`]: how ghost densities follow their
//!   sources (for a stage that changes fluid densities after the ghosts were placed).
//! - [`GhostReflections`], [`NoSlipVelocities`]: how ghost velocities follow their
//!   sources', and the ghosts' no-slip velocities for the viscous terms.
//! - [`require_neighbours`]: the setup check of the stages that sum over neighbours.
//!
//! - The scene as the world holds it, re-exported here: [`WallPose`] (each wall now),
//!   [`BodyPose`] (the tank's and each piston's pose now), both written by the
//!   kinematics when the clock advances; [`Walls`] (all walls at once, with their
//!   lines and corners); [`MirrorWall`] (the wall a ghost was mirrored across);
//!   [`Piston`] (the marker a stage finds the piston by).
//!
//! The particle components (`Position`, `Density`, ...) are in [`crate::components`].

pub use crate::components::{BodyPose, MirrorWall, WallPose};
use crate::components::{Density, Fluid, Ghost, Position};
use crate::motion::Pose;
pub use crate::piston::Piston;
use crate::sim::{Sim, Tait};
use crate::stage::{SetupError, StepError};
pub use crate::walls::Walls;
use crate::world::{archetype, column, column_mut};
use glam::DVec2;
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
    pub origin: DVec2,
    /// Cell size [m].
    pub cell: f64,
    pub nx: usize,
    pub ny: usize,
    /// `start[c]..start[c+1]` indexes `particles` (and `xs`) for cell c.
    pub start: Vec<u32>,
    /// Joint indices, cell by cell, ascending within a cell.
    pub particles: Vec<u32>,
    /// x and y of the positions in the order of `particles` (separate arrays), so a
    /// candidate scan reads contiguous memory and its distance test vectorises.
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    /// Each particle's cell (scratch kept between steps).
    pub cells: Vec<u32>,
}

impl CellGrid {
    /// Sets the grid geometry: cells of size `cell` covering `domain`.
    pub fn shape(&mut self, domain: (DVec2, DVec2), cell: f64) {
        self.origin = domain.0;
        self.cell = cell;
        let extent = domain.1 - domain.0;
        self.nx = ((extent.x / cell).ceil() as usize).max(1);
        self.ny = ((extent.y / cell).ceil() as usize).max(1);
    }

    /// The cell (column, row) holding `x`, clamped to the grid.
    #[inline(always)]
    pub fn cell_of(&self, x: DVec2) -> (usize, usize) {
        // floor by truncation (a positive number truncates to its floor; anything
        // else, NaN included, goes to cell 0 as the clamp did): `f64::floor` is a
        // library call on baseline x86-64.
        let c = (x - self.origin) / self.cell;
        let index = |c: f64, n: usize| if c > 0.0 { (c as usize).min(n - 1) } else { 0 };
        (index(c.x, self.nx), index(c.y, self.ny))
    }

    /// The index of the cell holding `x`.
    #[inline(always)]
    pub fn index_of(&self, x: DVec2) -> usize {
        let (cx, cy) = self.cell_of(x);
        cy * self.nx + cx
    }

    /// The index ranges (into `particles` / `xs`) of the `ROWS` x `ROWS` cells around
    /// `x`, one per row of cells, in the fixed order (rows bottom to top).
    #[inline(always)]
    pub fn ranges_near(&self, x: DVec2) -> [std::ops::Range<usize>; ROWS] {
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
    pub built_at: Vec<DVec2>,
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
        let moved = |now: &[Position], then: &[DVec2]| {
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
pub struct HalfVelocity(pub DVec2);
/// rho at the last half step (leapfrog state), per fluid particle.
#[derive(Clone, Copy, Debug, Default)]
pub struct HalfDensity(pub f64);

crate::checkpoint_newtype!(HalfVelocity(DVec2), HalfDensity(f64), Guarded(u8));

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

/// Work dissipated by the artificial viscosity: the forces stage stores its rate here
/// each step when a stage that reports energy has asked for it (by inserting it).
#[derive(Debug, Default, Clone, Copy)]
pub struct ViscousDissipation {
    /// Rate of dissipation this step [W per metre of depth].
    pub power: f64,
}

/// The renormalised density gradient of every particle, fluid then ghosts (the joint
/// numbering of the neighbour lists), written each step by the momentum stage before
/// its pair sums when its terms include delta-SPH's diffusion (docs/physics.md,
/// "Density diffusion").
#[derive(Debug, Default, Clone)]
pub struct DensityGradients(pub Vec<glam::DVec2>);

/// The rate at which a density-diffusion term changes the internal energy,
/// sum_i m_i (p_i/rho_i^2) D_i, each step when a stage that reports energy has asked
/// for it (by inserting it); filled in by the momentum stage whose terms include a
/// density diffusion (docs/physics.md, "Density diffusion").
#[derive(Debug, Default, Clone, Copy)]
pub struct DiffusionPower {
    /// Rate of internal-energy change this step [W per metre of depth].
    pub power: f64,
}

/// The energy the safeguards outside the model add to the fluid (wall reflections, the
/// density floor, densities restored on reflection): the integrator stores the change
/// of kinetic + potential + internal energy its guards made this step, divided by the
/// step, when a stage that reports energy has asked for it (by inserting it), so that
/// energy.csv books it apart from the flow (docs/physics.md, "Energy budget").
#[derive(Debug, Default, Clone, Copy)]
pub struct GuardPower {
    /// The guards' energy change this step over the step [W per metre of depth].
    pub power: f64,
}

/// Work the walls do on the fluid through the ghost particles: the forces stage stores
/// its rate here each step when a stage that reports energy has asked for it (by
/// inserting it). It is the rate at which the ghost pairs change the fluid's energy
/// E = kinetic + potential + internal + dissipated (docs/physics.md, "Energy budget"):
/// sum_i [ m_i a_i^g . v_i + m_i (p_i/rho_i^2) (d rho_i/dt)^g + D_i^g ], with a^g,
/// (d rho/dt)^g and D^g the acceleration, density rate and dissipation rate from the
/// ghost neighbours alone.
#[derive(Debug, Default, Clone, Copy)]
pub struct WallPower {
    /// Rate of work done on the fluid this step [W per metre of depth].
    pub power: f64,
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

/// Marks that a `Continuity()` stage writes the density rate (so `Forces` refuses to
/// write it too).
pub struct ContinuityInPipeline;

/// How the ghost-wall stage sets ghost densities, for a later stage that refreshes
/// them ([`refresh_ghost_density`]). What each ghost needs is on the ghost: its source
/// (`Ghost`) and the wall it was mirrored across ([`MirrorWall`]).
#[derive(Clone, Debug, Default)]
pub struct GhostSettings {
    /// The hydrostatic correction is on.
    pub hydrostatic: bool,
}

/// Ghost density: the source's, or with the hydrostatic correction the density whose
/// pressure is p_source + rho_0 (g - a_w) . (x_ghost - x_source), a_w the acceleration
/// at the source of the body (tank or piston) whose wall it was mirrored across.
#[inline]
pub fn ghost_density(
    rho_source: f64,
    source: DVec2,
    ghost: DVec2,
    correction: Option<((Tait, DVec2), Pose)>,
) -> f64 {
    match correction {
        Some(((eos, g), pose)) => {
            let g_eff = g - pose.acceleration_at(source);
            eos.density(eos.pressure(rho_source) + eos.rho0 * g_eff.dot(ghost - source))
        }
        None => rho_source,
    }
}

/// Re-copies every ghost's density from its source (after a stage changed the fluid
/// densities, e.g. re-initialisation), with the hydrostatic correction if enabled: the
/// acceleration is that of the body whose wall the ghost was mirrored across, as the
/// world holds it now (the walls have not moved since the ghosts were placed this step).
pub fn refresh_ghost_density(sim: &Sim) -> Result<(), StepError> {
    let (Some(fluid), Some(ghost)) = (
        archetype::<Fluid>(&sim.world),
        archetype::<Ghost>(&sim.world),
    ) else {
        return Ok(());
    };
    let hydrostatic = sim
        .resources
        .get::<GhostSettings>()
        .is_some_and(|s| s.hydrostatic);
    // The few walls' body poses, looked up by entity for each ghost.
    let poses: Vec<(hecs::Entity, Pose)> = if hydrostatic {
        sim.world
            .query::<(hecs::Entity, &WallPose)>()
            .iter()
            .map(|(e, w)| (e, w.body))
            .collect()
    } else {
        Vec::new()
    };
    let eos_g = (sim.constants.eos, sim.constants.gravity);
    let (fx, fr) = (column::<Position>(fluid)?, column::<Density>(fluid)?);
    let (gs, gx) = (column::<Ghost>(ghost)?, column::<Position>(ghost)?);
    let walls = if hydrostatic {
        Some(column::<MirrorWall>(ghost)?)
    } else {
        None
    };
    let mut gr = column_mut::<Density>(ghost)?;
    let (fx, fr): (&[Position], &[Density]) = (&fx, &fr);
    let walls: Option<&[MirrorWall]> = walls.as_deref();
    (&mut gr[..], &gs[..], &gx[..])
        .into_par_iter()
        .enumerate()
        .for_each(|(k, (rho, g, x))| {
            // A wall particle's density follows from its extrapolated pressure.
            if g.is_wall_particle() {
                return;
            }
            let s = g.source as usize;
            let body = walls.and_then(|w| {
                let wall = w[k].0;
                poses.iter().find(|(e, _)| *e == wall).map(|p| p.1)
            });
            rho.0 = ghost_density(fr[s].0, fx[s].0, x.0, body.map(|b| (eos_g, b)));
        });
    Ok(())
}

/// The linear part of each ghost's velocity mirror, fluid-to-ghost, one 2x2 matrix
/// `[xx, xy, yx, yy]` per ghost in archetype order: a change dv of a source's velocity
/// changes its ghost's by L dv (I - 2 n n^T per wall crossed: a ghost's `Velocity`
/// mirrors the normal component whatever the walls' slip, see [`NoSlipVelocities`]).
/// Asked for by a stage that changes fluid velocities after the ghosts were placed
/// (the DFSPH solves, which keep the ghosts' velocities mirrored during their
/// iterations) by inserting it; filled in by `GhostWalls` every step.
#[derive(Debug, Default, Clone)]
pub struct GhostReflections(pub Vec<[f64; 4]>);

impl GhostReflections {
    /// L v for ghost `k`.
    #[inline(always)]
    pub fn apply(&self, k: usize, v: DVec2) -> DVec2 {
        let l = self.0[k];
        DVec2::new(l[0] * v.x + l[1] * v.y, l[2] * v.x + l[3] * v.y)
    }
}

/// With walls that do not slip (`GhostWalls(slip: NoSlip)`): every ghost's no-slip
/// velocity 2 v_w - v of its source (applied across each wall it was mirrored across),
/// in ghost archetype order, which the viscous terms read (`pair::Field::ShearVx`);
/// the ghost's `Velocity`, which continuity and the pressure solves read, mirrors the
/// normal component only. Reversing the tangential velocity in the continuity equation
/// makes a flow along the wall that speeds up or slows down (du/dx != 0) look
/// compressed or stretched at the wall; a dam break's surge then blew up (Adami, Hu &
/// Adams 2012, sec. 2.3, use the no-slip velocity in the viscous term only).
/// Inserted by `GhostWalls` at setup, filled every step; a stage that changes fluid
/// velocities after the ghosts were placed changes ghost k's by `sign[k]` times its
/// source's change (the linear part of the mirror, +-I).
#[derive(Debug, Default, Clone)]
pub struct NoSlipVelocities {
    /// [m/s]
    pub velocity: Vec<DVec2>,
    /// (-1)^(walls crossed).
    pub sign: Vec<f64>,
}

/// The divergence-free SPH factors of one step (Bender & Koschier 2017, eq. 11, in
/// pressure form): for every fluid particle
/// alpha_i = rho_i^2 / ( |sum_j m_j grad W_ij|^2 + sum_j |m_j grad W_ij|^2 ),
/// so a pressure p_i = alpha_i (rho*_i - rho_0) / dt^2 removes particle i's predicted
/// density error rho*_i - rho_0 when its neighbours' pressures are held fixed (the
/// Jacobi step of both DFSPH solves); and for every ghost the pressure it adds to its
/// source's (the hydrostatic carry rho_0 (g - a_w) . (x_ghost - x_source) with the
/// ghost walls' `hydrostatic: true`, else 0). Written by `DfsphFactor` after the
/// neighbour grid, read by `DivergenceSolve` and `DensitySolve`.
#[derive(Debug, Default, Clone)]
pub struct DfsphFactors {
    /// alpha_i per fluid particle [m^2].
    pub alpha: Vec<f64>,
    /// Pressure carried to each ghost [Pa], archetype order.
    pub ghost_offset: Vec<f64>,
    /// `DfsphFactor(continuity_floor: true)`: the density solve leaves each fluid
    /// particle's predicted density rho_i + dt D rho_i/Dt (final velocities) in the
    /// `Density` column, the continuity density the next step's factor stage floors the
    /// summation density with.
    pub continuity_floor: bool,
}

/// The step the pressure solve chose (from the velocity CFL condition), for the stage
/// that advances the clock by it: written by `DensitySolve`, read by `Advance`.
#[derive(Debug, Default, Clone, Copy)]
pub struct StepSize(pub f64);
