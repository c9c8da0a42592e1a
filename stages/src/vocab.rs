//! The physics crate's shared vocabulary: what the stages of one scheme pass each
//! other (so that no stage imports another stage's file), apart from the engine's own
//! in `sph_core::vocab`.
//!
//! - [`ViscousDissipation`], [`DiffusionPower`], [`WallPower`], [`GuardPower`]: the
//!   energy budget's rates, asked for by `Energy` and filled in by `Forces` and
//!   `Integrate`.
//! - [`DensityGradient`]: delta-SPH's renormalised density gradient, a keyed column
//!   the momentum stage's pre-pass writes.
//! - [`GhostSettings`], [`refresh_ghost_density`]: how ghost densities follow their
//!   sources (for a stage that changes fluid densities after the ghosts were placed).
//! - [`GhostReflections`], [`NoSlipVelocity`], [`NoSlipSigns`]: how ghost velocities
//!   follow their sources', and the ghosts' no-slip velocities for the viscous terms.
//! - [`DfsphFactors`], [`StepSize`]: what the DFSPH stages pass each other.

use rayon::prelude::*;
use sph_core::components::{Density, Fluid, Ghost, MirrorWall, Position, WallPose};
use sph_core::dim::{Vector, DIM};
use sph_core::motion::Pose;
use sph_core::pair::{ColumnKey, Field, Fields, Lane, Me, Pair, Scope};
use sph_core::sim::{Counter, Sim, Tait};
use sph_core::stage::StepError;
use sph_core::world::{archetype, column, column_mut};

/// Work dissipated by the artificial viscosity: the forces stage stores its rate here
/// each step when a stage that reports energy has asked for it (by inserting it).
#[derive(Debug, Default, Clone, Copy)]
pub struct ViscousDissipation {
    /// Rate of dissipation this step [W per metre of depth].
    pub power: f64,
}

/// The renormalised density gradient of every particle, fluid then ghosts (the joint
/// numbering of the neighbour lists): a keyed column in slots 0 and 1 (and 2 in 3D), written each
/// step by the momentum stage before its pair sums when its terms include delta-SPH's
/// diffusion (docs/physics.md, "Density diffusion").
pub struct DensityGradient;

impl ColumnKey for DensityGradient {
    const NAME: &'static str = "DensityGradient";
    /// One slot per component: x, y[, z].
    #[cfg(not(feature = "dim3"))]
    const SLOTS: &'static [Field] = &[Field::Slot0, Field::Slot1];
    #[cfg(feature = "dim3")]
    const SLOTS: &'static [Field] = &[Field::Slot0, Field::Slot1, Field::Slot2];
}

impl DensityGradient {
    /// Its components [kg/m^4] in the records, x, y[, z].
    pub const FIELDS: Fields = Fields::of(<Self as ColumnKey>::SLOTS);
}

// delta-SPH's pair reads one slot per component of x_ij.
const _: () = assert!(<DensityGradient as ColumnKey>::SLOTS.len() == DIM);

/// Each fluid particle's sum_j m_j W_ij over its neighbours (fluid and ghosts, i
/// excluded) [kg/m^2], in fluid order, at this step's positions: summed in the
/// momentum stage's pass when a stage has asked for it (by inserting it), so that a
/// density summation after that stage (`Reinitialise(sums: Forces)`) needs no pass of
/// its own.
#[derive(Debug, Default, Clone)]
pub struct KernelSums(pub Vec<f64>);

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
    source: Vector,
    ghost: Vector,
    correction: Option<((Tait, Vector), Pose)>,
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

/// The linear part of each ghost's velocity mirror, fluid-to-ghost, one DIM x DIM
/// matrix row by row (`[xx, xy, yx, yy]` in 2D) per ghost in archetype order: a change dv of a source's velocity
/// changes its ghost's by L dv (I - 2 n n^T per wall crossed: a ghost's `Velocity`
/// mirrors the normal component whatever the walls' slip, see [`NoSlipVelocity`]).
/// Asked for by a stage that changes fluid velocities after the ghosts were placed
/// (the DFSPH solves, which keep the ghosts' velocities mirrored during their
/// iterations) by inserting it; filled in by `GhostWalls` every step.
#[derive(Debug, Default, Clone)]
pub struct GhostReflections(pub Vec<[f64; DIM * DIM]>);

impl GhostReflections {
    /// L v for ghost `k` (L row by row).
    #[inline(always)]
    pub fn apply(&self, k: usize, v: Vector) -> Vector {
        let l = &self.0[k];
        let mut out = Vector::ZERO;
        for r in 0..DIM {
            let row = &l[r * DIM..(r + 1) * DIM];
            // Summed from the first product (not from 0.0): the sign of a zero is kept.
            out[r] = (1..DIM).fold(row[0] * v[0], |s, c| s + row[c] * v[c]);
        }
        out
    }
}

/// With walls that do not slip (`GhostWalls(slip: NoSlip)`): every ghost's no-slip
/// velocity 2 v_w - v of its source (applied across each wall it was mirrored across),
/// a keyed column of the ghosts in slots 2 and 3 (a fluid particle's slots hold its
/// own velocity), which the viscous terms read ([`viscous_v_ij`]); the ghost's
/// `Velocity`, which continuity and the pressure solves read, mirrors the normal
/// component only. Reversing the tangential velocity in the continuity equation makes
/// a flow along the wall that speeds up or slows down (du/dx != 0) look compressed or
/// stretched at the wall; a dam break's surge then blew up (Adami, Hu & Adams 2012,
/// sec. 2.3, use the no-slip velocity in the viscous term only). Stored by
/// `GhostWalls` at setup, filled every step; a stage that changes fluid velocities
/// after the ghosts were placed changes ghost k's by [`NoSlipSigns`] times its
/// source's change.
pub struct NoSlipVelocity;

impl ColumnKey for NoSlipVelocity {
    const NAME: &'static str = "NoSlipVelocity";
    const SLOTS: &'static [Field] = &[Self::X, Self::Y];
}

impl NoSlipVelocity {
    /// The velocity's x component [m/s] in the records.
    pub const X: Field = Field::Slot2;
    /// Its y component.
    pub const Y: Field = Field::Slot3;
    /// Where a fluid particle's slots come from: its own velocity.
    pub const SCOPE: Scope = Scope::Ghosts {
        fluid: &[Field::Vx, Field::Vy],
    };
    /// The record fields a viscous term reads for it.
    pub const FIELDS: Fields = Fields::of(Self::SLOTS);
}

/// The linear part of each ghost's no-slip mirror, (-1)^(walls crossed), in ghost
/// archetype order (+-I on the velocity): with walls that do not slip, written by
/// `GhostWalls` with [`NoSlipVelocity`].
#[derive(Debug, Default, Clone)]
pub struct NoSlipSigns(pub Vec<f64>);

/// v_ij as a viscous term sees it: with `wall_shear`, j's [`NoSlipVelocity`] (a
/// ghost's no-slip mirror with walls that do not slip) against i's own velocity (the
/// term must then read [`NoSlipVelocity::FIELDS`] too), else [`Pair::velocity_ij`].
/// In 3D walls that do not slip are not yet built (`GhostWalls` refuses them), so
/// there is no `wall_shear`.
#[inline(always)]
pub fn viscous_v_ij<L: Lane>(p: &Pair<L>, me: &Me, wall_shear: bool) -> [L; DIM] {
    #[cfg(not(feature = "dim3"))]
    if wall_shear {
        return [
            me.lanes::<L>(Field::Vx) - p.j(NoSlipVelocity::X),
            me.lanes::<L>(Field::Vy) - p.j(NoSlipVelocity::Y),
        ];
    }
    #[cfg(feature = "dim3")]
    debug_assert!(!wall_shear, "no-slip ghost velocities are 2D only");
    p.velocity_ij(me)
}

/// With `WallPressure(pair_mirror: true)`: each wall particle's unit normal, zero for
/// the fluid and for mirrored ghosts, a keyed column of every particle (fluid then
/// ghosts) in slots 0 and 1 (and 2 in 3D). Continuity and Riemann-solver SPH then meet
/// a wall particle in the state of Zhang, Hu & Adams's (2017) one-sided Riemann
/// problem built from i itself: u_R = u_L - 2 ((u_L - v_b) . n) n ([`wall_mirrored_v_ij`]).
pub struct WallNormal;

impl ColumnKey for WallNormal {
    const NAME: &'static str = "WallNormal";
    #[cfg(not(feature = "dim3"))]
    const SLOTS: &'static [Field] = &[Field::Slot0, Field::Slot1];
    #[cfg(feature = "dim3")]
    const SLOTS: &'static [Field] = &[Field::Slot0, Field::Slot1, Field::Slot2];
}

impl WallNormal {
    /// Its components in the records.
    pub const FIELDS: Fields = Fields::of(<Self as ColumnKey>::SLOTS);
}

/// Whether the wall particles meet the fluid with its own mirror image this run (the
/// [`WallNormal`] column is stored: `WallPressure(pair_mirror: true)`).
pub fn wall_mirror_in(sim: &Sim) -> bool {
    sim.resources
        .get::<sph_core::pair::Columns>()
        .is_some_and(|c| c.contains::<WallNormal>())
}

/// v_ij with j's velocity, where j is a wall particle (its [`WallNormal`] n is a unit
/// vector), replaced by i's mirror image across the wall moving at j's velocity v_b:
/// v_i - v_R = 2 ((v_i - v_b) . n) n; unchanged where n = 0 (the factor n . n is 0 or 1),
/// and for a group of fluid neighbours not computed at all ([`Pair::fluid_only`]).
#[inline(always)]
pub fn wall_mirrored_v_ij<L: Lane>(p: &Pair<L>, me: &Me) -> [L; DIM] {
    let w = p.velocity_ij(me);
    if p.fluid_only() {
        return w;
    }
    // Written out, not `array::from_fn`: its closures are not inlined into the SIMD
    // loop and so are compiled without its instruction set, a call per lane operation
    // (it made the AVX2 pair sums 4 times slower).
    const S: &[Field] = <WallNormal as ColumnKey>::SLOTS;
    #[cfg(not(feature = "dim3"))]
    let n = [p.j(S[0]), p.j(S[1])];
    #[cfg(feature = "dim3")]
    let n = [p.j(S[0]), p.j(S[1]), p.j(S[2])];
    let nn = sph_core::pair::dot(n, n);
    let a = L::splat(2.0) * sph_core::pair::dot(w, n);
    #[cfg(not(feature = "dim3"))]
    return [w[0] + nn * (a * n[0] - w[0]), w[1] + nn * (a * n[1] - w[1])];
    #[cfg(feature = "dim3")]
    return [
        w[0] + nn * (a * n[0] - w[0]),
        w[1] + nn * (a * n[1] - w[1]),
        w[2] + nn * (a * n[2] - w[2]),
    ];
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
    /// m_j grad_i W_ij of every fluid particle's listed pairs at this step's positions
    /// (`DfsphFactor`), which the solves' passes sum against velocities or pressures.
    pub gradients: PairGradients,
}

/// Per-pair kernel gradients in the neighbour lists' order: the pairs of fluid particle
/// i are `grad[start[i]..start[i + 1]]`, one per entry of its list, each
/// m_j grad_i W_ij. Valid while the positions and the lists stay as they were filled.
#[derive(Debug, Default, Clone)]
pub struct PairGradients {
    pub start: Vec<usize>,
    pub grad: Vec<Vector>,
}

impl PairGradients {
    /// Particle i's gradients.
    ///
    /// # Panics
    /// If i is not below the fluid count the gradients were filled for.
    #[inline]
    pub fn row(&self, i: usize) -> &[Vector] {
        &self.grad[self.start[i]..self.start[i + 1]]
    }

    /// Whether these were filled for `lists`: the same fluid count and the same length
    /// of every list.
    pub fn fits(&self, lists: &sph_core::vocab::Neighbours) -> bool {
        let n = lists.n_fluid;
        self.start.len() == n + 1
            && (0..n).all(|i| self.start[i + 1] - self.start[i] == lists.of(i).len())
    }
}

/// The step the pressure solve chose (from the velocity CFL condition), for the stage
/// that advances the clock by it: written by `DensitySolve`, read by `Advance`.
#[derive(Debug, Default, Clone, Copy)]
pub struct StepSize(pub f64);

/// Fluid particles reflected back through a wall by the integrator's guard
/// (docs/physics.md, "Safeguards outside the model"), counted by `Integrate` or
/// `Advance`; `Probe` reports the count per sampling interval.
pub struct WallReflections;
impl Counter for WallReflections {
    const NAME: &'static str = "wall_reflections";
}

/// Densities (or half-step densities) the integrator's floor raised, counted by
/// `Integrate`; `Probe` reports the count per sampling interval.
pub struct DensityFloored;
impl Counter for DensityFloored {
    const NAME: &'static str = "density_floored";
}

/// Particle shifts `Shifting` cut to its cap.
pub struct ShiftsCapped;
impl Counter for ShiftsCapped {
    const NAME: &'static str = "shifts_capped";
}

/// Particle-steps whose density gradient kept the plain sum (a near-singular
/// renormalisation matrix), counted by delta-SPH's pre-pass.
pub struct GradientUnrenormalised;
impl Counter for GradientUnrenormalised {
    const NAME: &'static str = "gradient_unrenormalised";
}
