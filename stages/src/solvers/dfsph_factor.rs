//! DFSPH densities and factors (docs/physics.md, "DFSPH"; Bender & Koschier 2017,
//! eqs. 2 and 11): after the neighbour grid, every fluid particle's density by
//! summation, rho_i = sum_j m_j W_ij (i itself and the ghosts included), and its factor
//! alpha_i (`terms::dfsph_factor`), in one pass. The ghosts take their sources'
//! densities (a mirror image has its source's neighbourhood), and each ghost gets the
//! pressure it carries across its wall: with `GhostWalls(hydrostatic: true)` the
//! hydrostatic difference rho_0 (g - a_w) . (x_ghost - x_source), a_w the acceleration
//! of the wall's body at the source (as `vocab::ghost_density` carries it in
//! WCSPH), else 0. Both go to `vocab::DfsphFactors` for the two solves.

use crate::pressure_solve::lattice;
use crate::vocab::{DfsphFactors, GhostSettings, PairGradients};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Ghost, Mass, Position, Pressure};
use sph_core::contract::Access;
use sph_core::dim::{cell_volume, Vector, DIM};
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

    /// Sets every fluid particle's mass to rho_0 ds^DIM / S, S the kernel's sum over a
    /// square (3D: cubic) lattice of spacing ds (sum_k ds^DIM W(|k| ds)), so that a particle inside
    /// the initial lattice sums to rho_0 exactly and the fluid starts at rest density.
    /// The scenario's masses (rho(y) ds^DIM, the weakly-compressible hydrostatic profile)
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
            for n in lattice(-reach, reach) {
                sum += cell_volume(ds) * k.w(ds * n.length_squared().sqrt());
            }
            sum
        });
        // rho_0 ds ds (ds) / S, multiplied in that order (the 2D masses as they were).
        let m = (0..DIM).fold(c.eos.rho0, |m, _| m * ds) / sum;
        let rho0 = c.eos.rho0;
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
        gradients.grad.resize(start[n], Vector::ZERO);
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
                    let (mut rho, mut sum, mut s2) = (m.fluid[i].0 * w0, Vector::ZERO, 0.0);
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
                    .map_or(Vector::ZERO, |p| p.1.acceleration_at(xs));
                *off = rho0 * (g - a_w).dot(gx[k].0 - xs);
            });
        Ok(())
    }
}

#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use glam::DVec2;
    use sph_core::components::Velocity;
    use sph_core::kernel::Wendland;

    /// At setup every fluid particle takes the mass rho_0 ds^2 / S, S the lattice sum
    /// sum_ij ds^2 W(ds |(i, j)|) (so a particle of a full lattice sums to rho_0), the
    /// pressure of its starting density by Tait, and the density rho_0; without the
    /// grid, or without pressures, setup refuses the scene.
    #[test]
    fn the_setup_sets_the_lattice_mass_and_the_starting_pressures() {
        let mut world = hecs::World::new();
        for (k, rho) in [1000.0, 1001.5, 998.0].into_iter().enumerate() {
            world.spawn((
                Fluid,
                Position(DVec2::new(0.1 * k as f64, 0.1)),
                Density(rho),
                Pressure(0.0),
                Mass(0.5),
            ));
        }
        let mut sim = crate::testing::sim(world);
        crate::testing::pipeline(
            &mut sim,
            &[("neighbour_grid", "()"), ("dfsph_factor", "()")],
        );
        // The test sim: Wendland, h 0.013 m (support 0.026), ds 0.01 m, rho_0 1000,
        // c_0 20 m/s, gamma 7.
        let kernel = Wendland::new(0.013);
        let mut sum = 0.0;
        for i in -3i32..=3 {
            for j in -3i32..=3 {
                sum += 1e-4 * kernel.w(0.01 * ((i * i + j * j) as f64).sqrt());
            }
        }
        let m = 1000.0 * 1e-4 / sum;
        let tait = |rho: f64| 1000.0 * 400.0 / 7.0 * ((rho / 1000.0f64).powi(7) - 1.0);
        let fluid = archetype::<Fluid>(&sim.world).unwrap();
        let (mass, density) = (
            column::<Mass>(fluid).unwrap(),
            column::<Density>(fluid).unwrap(),
        );
        let p = column::<Pressure>(fluid).unwrap();
        for (k, rho) in [1000.0, 1001.5, 998.0].into_iter().enumerate() {
            assert!(
                (mass[k].0 - m).abs() < 1e-12 * m,
                "{} against {m}",
                mass[k].0
            );
            assert_eq!(density[k].0, 1000.0);
            assert!(
                (p[k].0 - tait(rho)).abs() < 1e-9 * 400.0,
                "{} against {}",
                p[k].0,
                tait(rho)
            );
        }
        let mut bare = crate::testing::sim(hecs::World::new());
        let e = crate::testing::stage("dfsph_factor", "()")
            .setup(&mut bare)
            .unwrap_err();
        assert!(e.message.contains("NeighbourGrid"), "{}", e.message);
        let mut world = hecs::World::new();
        world.spawn((Fluid, Position(DVec2::ZERO), Density(1000.0), Mass(0.1)));
        let mut sim = crate::testing::sim(world);
        crate::testing::pipeline(&mut sim, &[("neighbour_grid", "()")]);
        let e = crate::testing::stage("dfsph_factor", "()")
            .setup(&mut sim)
            .unwrap_err();
        assert!(e.message.contains("without pressure"), "{}", e.message);
    }

    /// The factor stage provides the factors and corrects the masses and densities.
    #[test]
    fn the_factor_stage_declares_the_factors() {
        use sph_core::contract::Quantity;
        let access = crate::testing::stage("dfsph_factor", "()").access();
        assert!(access.writes.contains(&Quantity::of::<DfsphFactors>()));
        assert!(access.updates.contains(&Quantity::of::<Mass>()));
    }

    /// A 6 x 4 block of water in the corner of a closed 0.2 m box whose walls ride on
    /// bodies accelerating each its own way (as a piston's wall does beside a tank's),
    /// after `GhostWalls(hydrostatic)`, `NeighbourGrid` and `DfsphFactor` (`factor`
    /// its parameters) have set up, the fluid's densities then set to `rho(k)`.
    fn cornered(
        hydrostatic: bool,
        factor: &str,
        rho: impl Fn(usize) -> f64,
    ) -> (Sim, Vec<Box<dyn Stage>>) {
        use sph_core::motion::{Pose, RigidState};
        let mut world = hecs::World::new();
        let corners = [(0.0, 0.0), (0.2, 0.0), (0.2, 0.2), (0.0, 0.2)];
        crate::testing::closed_polygon(&mut world, &corners, |k| Pose {
            pivot: DVec2::new(0.1, 0.1),
            state: RigidState {
                alpha: 1.5 - k as f64,
                omega: 0.3 * k as f64,
                acceleration: DVec2::new(2.0 * k as f64 - 3.0, 1.0 + k as f64),
                ..Default::default()
            },
        });
        for (_, _, x) in crate::testing::lattice(6, 4) {
            world.spawn((
                Fluid,
                Position(x),
                Velocity(DVec2::ZERO),
                Density(1000.0),
                Pressure(0.0),
                Mass(0.1),
            ));
        }
        let mut sim = crate::testing::sim(world);
        let ghosts = format!("(hydrostatic: {hydrostatic})");
        let stages = crate::testing::pipeline(
            &mut sim,
            &[
                ("ghost_walls", &ghosts),
                ("neighbour_grid", "()"),
                ("dfsph_factor", factor),
            ],
        );
        let fluid = archetype::<Fluid>(&sim.world).unwrap();
        for (k, r) in column_mut::<Density>(fluid).unwrap().iter_mut().enumerate() {
            r.0 = rho(k);
        }
        (sim, stages)
    }

    fn run_all(sim: &mut Sim, stages: &mut [Box<dyn Stage>]) -> Result<(), StepError> {
        stages.iter_mut().try_for_each(|s| s.run(sim))
    }

    /// Each ghost's pressure carry is rho_0 (g - a_w) . (x_ghost - x_source), a_w the
    /// acceleration at the source of the body of the wall it was mirrored across
    /// (0 without the hydrostatic correction); each ghost takes its source's density.
    #[test]
    fn the_ghost_carries_are_the_hydrostatic_difference_in_each_wall_s_frame() {
        for hydrostatic in [true, false] {
            let (mut sim, mut stages) = cornered(hydrostatic, "()", |_| 1000.0);
            run_all(&mut sim, &mut stages).unwrap();
            let all = crate::testing::everyone(&sim);
            let ghost = archetype::<Ghost>(&sim.world).unwrap();
            let (source, wall) = (
                column::<Ghost>(ghost).unwrap(),
                column::<MirrorWall>(ghost).unwrap(),
            );
            let n = all.len() - source.len();
            let carries = &sim.resources.get::<DfsphFactors>().unwrap().ghost_offset;
            assert_eq!(carries.len(), source.len());
            let accelerations: Vec<DVec2> = (0..source.len())
                .map(|k| {
                    let pose = sim.world.get::<&WallPose>(wall[k].0).unwrap().body;
                    pose.acceleration_at(all[source[k].source as usize].0)
                })
                .collect();
            // The walls' bodies differ: the ghosts see more than one acceleration.
            assert!(accelerations
                .iter()
                .any(|a| (*a - accelerations[0]).length() > 0.1));
            for k in 0..source.len() {
                let s = source[k].source as usize;
                let g_eff = DVec2::new(0.0, -9.81) - accelerations[k];
                let e = if hydrostatic {
                    1000.0 * g_eff.dot(all[n + k].0 - all[s].0)
                } else {
                    0.0
                };
                assert!(
                    (carries[k] - e).abs() < 1e-9,
                    "ghost {k}: {} against {e}",
                    carries[k]
                );
                assert_eq!(all[n + k].3, all[s].3, "ghost {k}'s density");
            }
        }
    }

    /// With the continuity floor each density is at least the one the column held
    /// (the last density solve's prediction); without it, the summation alone.
    #[test]
    fn the_continuity_floor_keeps_the_predicted_density() {
        let preset = |k: usize| match k {
            0 => 1100.0,
            1 => 500.0,
            _ => 1000.0,
        };
        let densities = |factor: &str| {
            let (mut sim, mut stages) = cornered(true, factor, preset);
            run_all(&mut sim, &mut stages).unwrap();
            let all = crate::testing::everyone(&sim);
            // The 24 fluid particles (the ghosts follow them).
            all.iter().take(24).map(|p| p.3).collect::<Vec<f64>>()
        };
        let summed = densities("(continuity_floor: false)");
        let floored = densities("(continuity_floor: true)");
        assert!(summed[0] < 1100.0 && summed[1] > 500.0);
        for k in 0..summed.len() {
            assert_eq!(floored[k], summed[k].max(preset(k)), "particle {k}");
        }
        assert_eq!(floored[0], 1100.0);
    }

    /// A stage that changed the particle count after the grid was built is caught
    /// before the lists are read.
    #[test]
    fn a_changed_particle_count_is_refused() {
        let (mut sim, mut stages) = cornered(true, "()", |_| 1000.0);
        stages[0].run(&mut sim).unwrap();
        stages[1].run(&mut sim).unwrap();
        let last = sim
            .world
            .query::<hecs::Entity>()
            .with::<&Ghost>()
            .iter()
            .last()
            .unwrap();
        sim.world.despawn(last).unwrap();
        let e = stages[2].run(&mut sim).unwrap_err().to_string();
        assert!(e.contains("changed the particle count"), "{e}");
    }
}
