//! DFSPH densities and factors (docs/physics.md, "DFSPH"; Bender & Koschier 2017,
//! eqs. 2 and 11): after the neighbour grid, every fluid particle's density by
//! summation, rho_i = sum_j m_j W_ij (i itself and the ghosts included), and its factor
//! alpha_i (`terms::dfsph_factor`), in one pass. The ghosts take their sources'
//! densities (a mirror image has its source's neighbourhood), and each ghost gets the
//! pressure it carries across its wall: with `GhostWalls(hydrostatic: true)` the
//! hydrostatic difference rho_0 (g - a_w) . (x_ghost - x_source), a_w the acceleration
//! of the wall's body at the source (as `vocab::ghost_density` carries it in
//! WCSPH), else 0. Both go to `vocab::DfsphFactors` for the two solves.

use crate::vocab::{DfsphFactors, GhostSettings, PairGradients};
use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Ghost, Mass, Position, Pressure};
use sph_core::contract::Access;
use sph_core::kernel::Kernel;
use sph_core::motion::Pose;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{require_neighbours, MirrorWall, Neighbours, WallPose};
use sph_core::world::{archetype, column, column_mut, Particles};
use sph_core::{with_kernel, StageRegistry};

/// `DfsphFactor(continuity_floor: true)`.
#[derive(Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// The density the solves use is max(rho_sum, rho_c): the summation density, floored
    /// by the continuity density rho_c = rho + dt D rho/Dt that the last step's density
    /// solve predicted (its final velocities). Near a free surface the kernel reaches
    /// past the water, so rho_sum falls short of rho_0 by up to a third; with the solves'
    /// p >= 0 those particles then carry no pressure until they have closed the gap, and
    /// every close is an inelastic contact. That damped the small rolling tank's
    /// resonant response to 38 % of linear theory's; with the floor it is 112 % (WCSPH
    /// 110 %), and still water at h/ds 2.0 stays still (docs/physics.md, "DFSPH"). In the
    /// bulk rho_c tracks rho_sum, and a compression that summation sees still counts.
    /// Default true; false is Bender & Koschier's summation density alone.
    pub continuity_floor: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            continuity_floor: true,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "dfsph_factor",
        "DFSPH: summation density and the solver factor alpha_i",
        |p: Params| {
            Ok(DfsphFactor {
                out: Vec::new(),
                continuity_floor: p.continuity_floor,
            })
        },
    );
}

pub struct DfsphFactor {
    /// (rho_i, alpha_i) per fluid particle (kept between steps).
    out: Vec<(f64, f64)>,
    /// See [`Params::continuity_floor`].
    continuity_floor: bool,
}

impl Stage for DfsphFactor {
    fn name(&self) -> &'static str {
        "dfsph_factor"
    }

    /// Sets every fluid particle's mass to rho_0 ds^2 / S, S the kernel's sum over a
    /// square lattice of spacing ds (sum_k ds^2 W(|k| ds)), so that a particle inside
    /// the initial lattice sums to rho_0 exactly and the fluid starts at rest density.
    /// The scenario's masses (rho(y) ds^2, the weakly-compressible hydrostatic profile)
    /// would start the column 0.2-0.8 % off rest density (the lattice sum of the
    /// Wendland kernel at h/ds = 1.3-1.5 is not 1, and the bottom particles carry the
    /// Tait compression), which the solve would then spend its first steps expanding.
    /// The pressures start hydrostatic, p = rho_0 g (H - y) (the pressure of the
    /// scenario's initial densities): the Jacobi iteration carries a pressure change
    /// one neighbourhood per iteration, so from zero a 50-particle column would fall
    /// and compress for hundreds of iterations before its weight is carried.
    /// A resumed run then restores the checkpoint's particles over these.
    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, "dfsph_factor")?;
        sim.resources.insert(DfsphFactors::default());
        let c = &sim.constants;
        let ds = c.spacing;
        let reach = (c.support() / ds).ceil() as i64;
        let sum = with_kernel!(c.kernel, c.h, |k| {
            let mut sum = 0.0;
            for i in -reach..=reach {
                for j in -reach..=reach {
                    sum += ds * ds * k.w(ds * ((i * i + j * j) as f64).sqrt());
                }
            }
            sum
        });
        let (m, rho0) = (c.eos.rho0 * ds * ds / sum, c.eos.rho0);
        if let Some(fluid) = archetype::<Fluid>(&sim.world) {
            let (Ok(mut mass), Ok(mut rho)) =
                (column_mut::<Mass>(fluid), column_mut::<Density>(fluid))
            else {
                return Err(SetupError::new(
                    "dfsph_factor",
                    "fluid particles without mass or density",
                ));
            };
            let Ok(mut p) = column_mut::<Pressure>(fluid) else {
                return Err(SetupError::new(
                    "dfsph_factor",
                    "fluid particles without pressure",
                ));
            };
            let eos = c.eos;
            mass.iter_mut().for_each(|x| x.0 = m);
            // The scenario's densities are the hydrostatic profile through the Tait
            // equation: their pressure rho_0 g (H - y) starts the solve's warm start.
            for (p, rho) in p.iter_mut().zip(rho.iter_mut()) {
                p.0 = eos.pressure(rho.0);
                rho.0 = rho0;
            }
        }
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let _span = tracing::trace_span!("pair_sums").entered();
        if archetype::<Fluid>(&sim.world).is_none() {
            return Ok(());
        }
        // The resource keeps its buffers from step to step; it goes back on every path.
        let mut factors = sim.resources.take::<DfsphFactors>().unwrap_or_default();
        let result = self
            .sums(sim, &mut factors.gradients)
            .and_then(|()| self.floor(sim))
            .and_then(|()| self.write(sim, &mut factors));
        sim.resources.insert(factors);
        result
    }

    fn access(&self) -> Access {
        Access::new()
            .reads::<sph_core::vocab::Neighbours>()
            .reads::<Position>()
            .updates::<Mass>()
            .reads::<WallPose>()
            .uses::<Ghost>()
            .uses::<GhostSettings>()
            .updates::<Density>()
            .writes::<DfsphFactors>()
    }
}

impl DfsphFactor {
    /// With the continuity floor, each density at least the last density solve's
    /// prediction, which the column holds (rho_0 at the start).
    fn floor(&mut self, sim: &Sim) -> Result<(), StepError> {
        if let (true, Some(fluid)) = (self.continuity_floor, archetype::<Fluid>(&sim.world)) {
            let rho_c = column::<Density>(fluid)?;
            self.out
                .par_iter_mut()
                .zip(rho_c.par_iter())
                .for_each(|(o, r)| o.0 = o.0.max(r.0));
        }
        Ok(())
    }

    /// One pass over the neighbour lists (Bender & Koschier 2017, eqs. 2 and 11):
    ///   rho_i   = m_i W(0) + sum_j m_j W_ij,
    ///   alpha_i = rho_i^2 / ( |sum_j m_j grad_i W_ij|^2 + sum_j |m_j grad_i W_ij|^2 ),
    /// the factor in the pressure form p_i = alpha_i (rho*_i - rho_0) / dt^2 of their
    /// kappa_i = (rho*_i - rho_0) / dt^2 alpha_i / rho_i (the paper's alpha_i is ours
    /// divided by rho_i), into `self.out`; and every pair's m_j grad_i W_ij into
    /// `gradients`, which the solves' passes reuse at these positions. A pair at
    /// r = 0 has no gradient, and a particle without one no factor (alpha_i = 0: no
    /// pressure can act on it).
    fn sums(&mut self, sim: &Sim, gradients: &mut PairGradients) -> Result<(), StepError> {
        let Some(nb) = sim.resources.get::<Neighbours>() else {
            return Err(StepError::Internal(
                "DfsphFactor needs the neighbour lists: NeighbourGrid must run before it".into(),
            ));
        };
        let Some(particles) = Particles::of(&sim.world) else {
            return Ok(());
        };
        let (x, m) = (particles.joined::<Position>()?, particles.joined::<Mass>()?);
        let (x, m) = (x.view(), m.view());
        let n = x.fluid.len();
        nb.check_covers(n + x.ghost.len())?;
        if nb.n_fluid != n {
            return Err(StepError::Internal(format!(
                "the neighbour lists cover {} fluid particles but the world holds {n}",
                nb.n_fluid
            )));
        }
        let start = &mut gradients.start;
        start.clear();
        start.push(0);
        for i in 0..n {
            start.push(start[i] + nb.of(i).len());
        }
        gradients.grad.clear();
        gradients.grad.resize(start[n], DVec2::ZERO);
        // Each particle's row of the flat buffer, to fill them in parallel.
        let mut rows = Vec::with_capacity(n);
        let mut rest = &mut gradients.grad[..];
        for i in 0..n {
            let (row, tail) = rest.split_at_mut(nb.of(i).len());
            rows.push(row);
            rest = tail;
        }
        let at = |j: usize| match j.checked_sub(n) {
            None => (x.fluid[j].0, m.fluid[j].0),
            Some(g) => (x.ghost[g].0, m.ghost[g].0),
        };
        self.out.resize(n, (0.0, 0.0));
        let c = &sim.constants;
        with_kernel!(c.kernel, c.h, |k| {
            let w0 = k.w(0.0);
            rows.into_par_iter()
                .zip(self.out.par_iter_mut())
                .enumerate()
                .for_each(|(i, (row, out))| {
                    let xi = x.fluid[i].0;
                    let (mut rho, mut sum, mut s2) = (m.fluid[i].0 * w0, DVec2::ZERO, 0.0);
                    for (g, &j) in row.iter_mut().zip(nb.of(i)) {
                        let (xj, mj) = at(j as usize);
                        let d = xi - xj;
                        let r = d.length();
                        *g = mj * k.grad(d, r);
                        rho += mj * k.w(r);
                        sum += *g;
                        s2 += g.length_squared();
                    }
                    let d = sum.length_squared() + s2;
                    *out = (rho, if d > 0.0 { rho * rho / d } else { 0.0 });
                })
        });
        Ok(())
    }

    /// Writes the densities (fluid, then ghosts from their sources), the factors and
    /// the ghosts' pressure carries into `factors`.
    fn write(&self, sim: &Sim, factors: &mut DfsphFactors) -> Result<(), StepError> {
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let out = &self.out;
        column_mut::<Density>(fluid)?
            .par_iter_mut()
            .zip(out.par_iter())
            .for_each(|(rho, o)| rho.0 = o.0);
        factors.continuity_floor = self.continuity_floor;
        factors.alpha.clear();
        factors.alpha.extend(out.iter().map(|o| o.1));
        factors.ghost_offset.clear();
        let Some(ghost) = archetype::<Ghost>(&sim.world) else {
            return Ok(());
        };
        let source_col = column::<Ghost>(ghost)?;
        let source: &[Ghost] = &source_col;
        column_mut::<Density>(ghost)?
            .par_iter_mut()
            .zip(source.par_iter())
            .for_each(|(rho, g)| rho.0 = out[g.source as usize].0);
        let hydrostatic = sim
            .resources
            .get::<GhostSettings>()
            .is_some_and(|s| s.hydrostatic);
        if !hydrostatic {
            factors.ghost_offset.resize(source.len(), 0.0);
            return Ok(());
        }
        // The few walls' body poses, looked up by entity for each ghost.
        let poses: Vec<(hecs::Entity, Pose)> = sim
            .world
            .query::<(hecs::Entity, &WallPose)>()
            .iter()
            .map(|(e, w)| (e, w.body))
            .collect();
        let (rho0, g) = (sim.constants.eos.rho0, sim.constants.gravity);
        let (fx, gx) = (column::<Position>(fluid)?, column::<Position>(ghost)?);
        let walls = column::<MirrorWall>(ghost)?;
        let (fx, gx, walls): (&[Position], &[Position], &[MirrorWall]) = (&fx, &gx, &walls);
        factors.ghost_offset.resize(source.len(), 0.0);
        factors
            .ghost_offset
            .par_iter_mut()
            .enumerate()
            .for_each(|(k, off)| {
                let xs = fx[source[k].source as usize].0;
                let a_w = poses
                    .iter()
                    .find(|(e, _)| *e == walls[k].0)
                    .map_or(glam::DVec2::ZERO, |p| p.1.acceleration_at(xs));
                *off = rho0 * (g - a_w).dot(gx[k].0 - xs);
            });
        Ok(())
    }
}
