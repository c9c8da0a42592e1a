//! The pressure of the fixed wall particles (`WallParticles`), extrapolated from the
//! fluid (Adami, Hu & Adams 2012, eq. 27; docs/physics.md, "Walls: fixed wall
//! particles"):
//!
//!   p_w = [ sum_f p_f W_wf + (g - a_w) . sum_f rho_f (x_w - x_f) W_wf ] / sum_f W_wf
//!
//! over the fluid particles f within the kernel support of wall particle w, a_w the
//! acceleration of the wall's body at x_w. The second sum carries the pressure
//! gradient that the fluid's acceleration relative to the wall sets up (hydrostatic in
//! still water), so that the wall pushes back what the fluid would push on fluid
//! beyond it. The wall particle's density is the Tait density of p_w, so the
//! continuity and momentum pairs read one consistent state. A wall particle with no
//! fluid within its support is seen by no fluid particle; it keeps p = 0, rho = rho_0.
//! With `one_sided: true` each pair's acceleration term enters only where it raises
//! the wall's pressure, max(0, (g - a_w) . (x_w - x_f)) rho_f W_wf, as in SPHinXsys's
//! wall (Zhang, Hu & Adams 2017): a wall particle above the fluid beside it then reads
//! that fluid's pressure, not less, and does not pull it into the wall.
//!
//! The wall particles move with their wall (`WallParticles`): continuity and the
//! pressures read the wall's own velocity v_b, as Adami et al. prescribe (sec. 2.3),
//! so no fluid enters the wall. The viscous terms (and Riemann-solver SPH's
//! dissipation) read a second velocity (`vocab::NoSlipVelocity`), from the fluid's
//! velocity smoothed the same way, u_f = sum_f v_f W_wf / sum_f W_wf (their eq. 22):
//! with `slip: FreeSlip` v_b plus the tangential part of u_f - v_b (no shear: the
//! fluid slides along the wall undisturbed), with `slip: NoSlip` 2 v_b - u_f (their
//! eq. 23: zero velocity at the wall), with `slip: WallVelocity` v_b itself (every
//! term reads the wall's velocity, so a fluid sliding along the wall is braked by the
//! dissipation of each pair's approach). A wall particle in a corner takes the tangent
//! of the wall it was laid out for. With `mirror: true` continuity and the pressures
//! read v_b - ((u_f - v_b) . n) n, the mirror image of the fluid's normal velocity, and
//! the viscous velocity takes the same normal part: the wall state u_R = 2 u_w - u_L
//! along n of Zhang, Hu & Adams's (2017) one-sided Riemann problem, from u_f.
//!
//! Runs after `Eos` (the fluid's pressures) and before the rate stages. Each wall
//! particle sums the fluid particles whose neighbour lists hold it, in fluid order (the
//! lists inverted, kept until the grid rebuilds them), so the wall particles are summed
//! in parallel and the result is the same for any thread count. With `largest: true`
//! the pressure is the largest carried fluid pressure instead of the mean, and with
//! `single_velocity: true` every term reads the viscous velocity (their docs below).

use crate::vocab::{NoSlipSigns, NoSlipVelocity, WallNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Ghost, MirrorWall, Position, Pressure, Velocity};
use sph_core::contract::Access;
use sph_core::dim::Vector;
use sph_core::kernel::Kernel;
use sph_core::pair::{Columns, Scope};
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{require_neighbours, Neighbours, WallPose};
use sph_core::world::{archetype, column, column_mut};
use sph_core::{with_kernel, StageRegistry};

/// Tangential velocity condition at the walls, for the viscous terms.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Slip {
    /// No wall shear.
    #[default]
    FreeSlip,
    /// Zero velocity at the wall.
    NoSlip,
    /// The wall's own velocity, as continuity reads.
    WallVelocity,
}

#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Default FreeSlip.
    pub slip: Slip,
    /// Let the fluid leave the wall: where the fluid near a wall particle moves away
    /// from the wall, continuity and the pressures read the wall particle moving with
    /// it along the normal, so the wall does not stretch (and pull back) fluid that
    /// separates. Default false.
    pub separation: bool,
    /// Add each fluid particle's acceleration term only where it raises the wall
    /// particle's pressure (SPHinXsys's wall), so the wall beside and above a free
    /// surface never pulls. Default false (Adami's eq. 27 as written).
    pub one_sided: bool,
    /// Give each wall particle the mirror image of the nearby fluid's velocity along
    /// the wall's normal, v_b - ((u_f - v_b) . n) n, in continuity and the pressures,
    /// and the same normal part in the viscous velocity: the wall state of a
    /// one-sided Riemann problem, u_R = 2 u_w - u_L along n (Zhang, Hu & Adams
    /// 2017), as a mirrored ghost has it, on a fixed lattice whose push does not
    /// vanish at the wall. Not with `separation`. Default false.
    pub mirror: bool,
    /// Raise each wall particle's pressure to at least minus the lowest fluid pressure
    /// within its support, so that p_f + p_w >= 0 in every fluid-wall pair: the wall
    /// never pulls a fluid particle in, even one in tension (a contact that carries no
    /// tension). Default false.
    pub no_pull: bool,
    /// Give every term the one velocity `slip` and `mirror` set for the viscous
    /// terms, instead of the wall's own to continuity and the pressures: with
    /// `slip: FreeSlip` and `mirror: true`, the mirror image of the nearby fluid's
    /// velocity in the moving wall, as a mirrored ghost of a free-slip wall has it. The
    /// records then carry no second velocity, and the momentum pass costs what it
    /// costs with mirrors. Default false.
    pub single_velocity: bool,
    /// Take the largest, over the fluid within the support, of the fluid particle's
    /// pressure carried to the wall particle, p_f + rho_f (g - a_w) . (x_w - x_f) (the
    /// carry one-sided with `one_sided`), instead of the kernel-weighted mean: the
    /// wall then pushes every fluid particle near it at least as hard as the hardest
    /// pushed of them would be by its own mirror image. Default false.
    pub largest: bool,
    /// Meet each fluid particle i, in continuity and Riemann-solver SPH, with its own
    /// mirror image across the wall particle's wall, v_i - 2 ((v_i - v_b) . n) n (the
    /// wall state of Zhang, Hu & Adams's 2017 one-sided Riemann problem built pair by
    /// pair, as SPHinXsys's wall has it), instead of the mirror of the nearby fluid's
    /// mean velocity: the wall particles keep their wall's velocity v_b and carry
    /// their normal in a keyed column (`WallNormal`). With `single_velocity`, not
    /// with `mirror` or `separation`. Default false.
    pub pair_mirror: bool,
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "wall_pressure",
        "extrapolate the fluid's pressure to the wall particles (Adami et al. 2012)",
        |p: Params| {
            if p.single_velocity && p.separation {
                return Err(sph_core::ParamError::new(
                    "single_velocity",
                    true,
                    "false when `separation` is true: separation sets the wall particles' normal velocity for continuity alone",
                ));
            }
            #[cfg(feature = "dim3")]
            if !p.single_velocity {
                return Err(sph_core::ParamError::new(
                    "single_velocity",
                    false,
                    "true in 3D: the wall particles' second velocity for the viscous terms is a keyed column in record slots 2 and 3, built in 2D only (in 3D a vector takes three slots, and delta-SPH's gradient holds slot 2), so in 3D every term reads the one velocity `slip` and `mirror` set",
                ));
            }
            if p.mirror && p.separation {
                return Err(sph_core::ParamError::new(
                    "mirror",
                    true,
                    "false when `separation` is true: the two set the wall particles' normal velocity differently",
                ));
            }
            if p.pair_mirror
                && (p.mirror || p.separation || !p.single_velocity || p.slip != Slip::FreeSlip)
            {
                return Err(sph_core::ParamError::new(
                    "pair_mirror",
                    true,
                    "false unless `single_velocity` is true, `slip` is FreeSlip and `mirror` and `separation` are false: each pair's image sets the wall's velocity itself, free of shear",
                ));
            }
            Ok(WallPressure {
                pair_mirror: p.pair_mirror,
                slip: p.slip,
                separation: p.separation,
                one_sided: p.one_sided,
                mirror: p.mirror,
                no_pull: p.no_pull,
                single_velocity: p.single_velocity,
                largest: p.largest,
                sums: Vec::new(),
                pull: Vec::new(),
                seen: Vec::new(),
                start: Vec::new(),
                inverted: None,
            })
        },
    );
}

/// Per wall particle: sum W, sum p W, sum rho (x_w - x_f) W, sum v W, with
/// `one_sided` sum max(0, (g - a_w) . rho (x_w - x_f)) W, and the largest tension
/// max(0, -p_f) of the fluid within the support.
#[derive(Clone, Copy, Default)]
struct Sums {
    w: f64,
    pw: f64,
    rho_r: Vector,
    vw: Vector,
    raised: f64,
    tension: f64,
    /// With `largest`: the largest carried pressure (-inf before any).
    carried: f64,
}

pub struct WallPressure {
    slip: Slip,
    separation: bool,
    one_sided: bool,
    mirror: bool,
    no_pull: bool,
    single_velocity: bool,
    largest: bool,
    pair_mirror: bool,
    sums: Vec<Sums>,
    /// g - a_w per ghost, for the one-sided sums (zero elsewhere); kept between
    /// steps only to reuse its allocation.
    pull: Vec<Vector>,
    /// The fluid particles each wall particle sees, in fluid order (those of ghost g
    /// at `seen[start[g]..start[g + 1]]`); kept only to reuse the allocations.
    seen: Vec<u32>,
    start: Vec<u32>,
    /// The lists `seen` inverts: the grid's build count and the fluid and ghost counts.
    inverted: Option<(u64, usize, usize)>,
}

impl Stage for WallPressure {
    fn name(&self) -> &'static str {
        "wall_pressure"
    }

    fn resumes_between_runs(&self) -> bool {
        true
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, "wall_pressure")?;
        sim.resources.insert(NoSlipSigns::default());
        if self.pair_mirror {
            sim.resources
                .get_or_default::<Columns>()
                .insert::<WallNormal>(Scope::Particles, Vec::new())
                .map_err(|e| SetupError::new("wall_pressure", e.to_string()))?;
        }
        if !self.single_velocity {
            sim.resources
                .get_or_default::<Columns>()
                .insert::<NoSlipVelocity>(NoSlipVelocity::SCOPE, Vec::new())
                .map_err(|e| SetupError::new("wall_pressure", e.to_string()))?;
        }
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let (Some(fluid), Some(ghost)) = (
            archetype::<Fluid>(&sim.world),
            archetype::<Ghost>(&sim.world),
        ) else {
            // No wall particle meets any fluid: every normal is zero.
            if self.pair_mirror {
                let count = |a: Option<&hecs::Archetype>| a.map_or(0, |a| a.len() as usize);
                let all =
                    count(archetype::<Fluid>(&sim.world)) + count(archetype::<Ghost>(&sim.world));
                sim.resources
                    .get_or_default::<Columns>()
                    .insert::<WallNormal>(Scope::Particles, vec![Vector::ZERO; all])?;
            }
            return Ok(());
        };
        let Some(nb) = sim.resources.get::<Neighbours>() else {
            return Err(StepError::Internal(
                "WallPressure needs the neighbour lists: NeighbourGrid must run before it".into(),
            ));
        };
        let (fx, fp, fr, fv) = (
            column::<Position>(fluid)?,
            column::<Pressure>(fluid)?,
            column::<Density>(fluid)?,
            column::<Velocity>(fluid)?,
        );
        let (gx, gs, gw) = (
            column::<Position>(ghost)?,
            column::<Ghost>(ghost)?,
            column::<MirrorWall>(ghost)?,
        );
        let n = fx.len();
        if nb.n_fluid != n || nb.n_ghost != gx.len() {
            return Err(StepError::Internal(format!(
                "the neighbour lists cover {} fluid and {} ghost particles but the world holds {n} and {}",
                nb.n_fluid,
                nb.n_ghost,
                gx.len()
            )));
        }
        self.sums.clear();
        self.sums.resize(
            gx.len(),
            Sums {
                carried: f64::NEG_INFINITY,
                ..Sums::default()
            },
        );
        // The few walls now, looked up by entity for each wall particle.
        let walls: Vec<(hecs::Entity, WallPose)> = sim
            .world
            .query::<(hecs::Entity, &WallPose)>()
            .iter()
            .map(|(e, w)| (e, *w))
            .collect();
        let wall_of = |k: usize| -> Result<&WallPose, StepError> {
            match walls.iter().find(|(e, _)| *e == gw[k].0) {
                Some((_, wall)) => Ok(wall),
                None => Err(StepError::Internal(format!(
                    "wall particle {k} rides on a wall the world no longer holds"
                ))),
            }
        };
        let c = &sim.constants;
        let (eos, gravity) = (c.eos, c.gravity);
        // The fluid particles each wall particle sees, in fluid order: the fluid's
        // lists inverted by a counting sort, so that each wall particle adds its fluid
        // neighbours in the order of a loop over the fluid, on any number of threads.
        // The lists change only when the grid rebuilds them (every few steps, with a
        // skin), so the inversion is kept until then.
        let lists = (nb.builds, n, gx.len());
        let (seen, start) = (&mut self.seen, &mut self.start);
        let passes = if self.inverted == Some(lists) { 0 } else { 2 };
        if passes > 0 {
            seen.clear();
            start.clear();
            start.resize(gx.len() + 1, 0);
        }
        for pass in 0..passes {
            for i in 0..n {
                let list = nb.of(i);
                // The ghosts are last in each list; most particles have none.
                if list.last().is_none_or(|&j| (j as usize) < n) {
                    continue;
                }
                let first = list.partition_point(|&j| (j as usize) < n);
                for &j in &list[first..] {
                    let g = j as usize - n;
                    if !gs[g].is_wall_particle() {
                        continue;
                    }
                    match pass {
                        0 => start[g + 1] += 1,
                        _ => {
                            seen[start[g] as usize] = i as u32;
                            start[g] += 1;
                        }
                    }
                }
            }
            if pass == 0 {
                // start[g] = where wall particle g's fluid begin; the second pass moves
                // each to where the next begin, so shift back by one after it.
                for g in 0..gx.len() {
                    start[g + 1] += start[g];
                }
                seen.resize(start[gx.len()] as usize, 0);
            } else {
                start.rotate_right(1);
                start[0] = 0;
            }
        }
        self.inverted = Some(lists);
        // The wall's pull (gravity less its own acceleration), where fluid is near.
        let pull = &mut self.pull;
        pull.clear();
        pull.resize(gx.len(), Vector::ZERO);
        if self.one_sided || self.largest {
            for (k, pull) in pull.iter_mut().enumerate() {
                if gs[k].is_wall_particle() && start[k + 1] > start[k] {
                    *pull = gravity - wall_of(k)?.body.acceleration_at(gx[k].0);
                }
            }
        }
        let (support, one_sided) = (c.support(), self.one_sided);
        let (seen, start, pull) = (&self.seen[..], &self.start[..], &self.pull[..]);
        let (fx, fp, fr, fv, gx) = (&fx[..], &fp[..], &fr[..], &fv[..], &gx[..]);
        with_kernel!(c.kernel, c.h, |k| {
            self.sums.par_iter_mut().enumerate().for_each(|(g, s)| {
                for &i in &seen[start[g] as usize..start[g + 1] as usize] {
                    let i = i as usize;
                    let r = gx[g].0 - fx[i].0;
                    let d = r.length();
                    if d >= support {
                        continue;
                    }
                    let w = k.w(d);
                    s.w += w;
                    s.pw += fp[i].0 * w;
                    s.rho_r += fr[i].0 * w * r;
                    s.vw += w * fv[i].0;
                    s.raised += (pull[g].dot(r) * fr[i].0).max(0.0) * w;
                    s.tension = s.tension.max(-fp[i].0);
                    let carry = pull[g].dot(r) * fr[i].0;
                    let carry = if one_sided { carry.max(0.0) } else { carry };
                    s.carried = s.carried.max(fp[i].0 + carry);
                }
            });
        });
        let mut gp = column_mut::<Pressure>(ghost)?;
        let mut gr = column_mut::<Density>(ghost)?;
        let mut gv = column_mut::<Velocity>(ghost)?;
        // The second velocity's column, where the terms read one (2D only: in 3D
        // `single_velocity` is required when the stage is built), starting from the
        // ghosts' velocities; with one velocity it is written straight into them.
        #[cfg(not(feature = "dim3"))]
        let mut viscous = (!self.single_velocity).then(|| {
            let mut column = sim
                .resources
                .get_or_default::<Columns>()
                .take_emptied::<NoSlipVelocity>();
            column.extend(gv.iter().map(|v| v.0));
            column
        });
        #[cfg(feature = "dim3")]
        let mut viscous: Option<Vec<Vector>> = None;
        // No stage changes fluid velocities between here and the forces (the DFSPH
        // solves, which would, refuse wall particles).
        let signs = sim.resources.get_or_default::<NoSlipSigns>();
        signs.0.clear();
        signs.0.resize(gv.len(), 0.0);
        let rest = eos.density(0.0);
        let mut normals = self.pair_mirror.then(|| {
            let mut column = sim
                .resources
                .get_or_default::<Columns>()
                .take_emptied::<WallNormal>();
            column.resize(n + gv.len(), Vector::ZERO);
            column
        });
        for (k, s) in self.sums.iter().enumerate() {
            if !gs[k].is_wall_particle() {
                continue;
            }
            // Most wall particles have no fluid near: no pressure, and no fluid
            // particle reads their velocities.
            if s.w <= 0.0 || s.w.is_nan() {
                gp[k].0 = 0.0;
                gr[k].0 = rest;
                continue;
            }
            let wall = wall_of(k)?;
            let x = gx[k].0;
            gp[k].0 = match self.one_sided {
                _ if self.largest => s.carried,
                true => (s.pw + s.raised) / s.w,
                false => (s.pw + (gravity - wall.body.acceleration_at(x)).dot(s.rho_r)) / s.w,
            };
            if self.no_pull {
                gp[k].0 = gp[k].0.max(s.tension);
            }
            let (v_b, u) = (wall.body.velocity_at(x), s.vw / s.w);
            let mut visc = match self.slip {
                Slip::FreeSlip => v_b + along_wall(wall, u - v_b),
                Slip::NoSlip => 2.0 * v_b - u,
                Slip::WallVelocity => v_b,
            };
            let n = wall.normal();
            if let Some(normals) = normals.as_mut() {
                normals[fx.len() + k] = n;
                gv[k].0 = v_b;
                gr[k].0 = eos.density(gp[k].0);
                continue;
            }
            if self.mirror {
                let away = (u - v_b).dot(n);
                gv[k].0 = v_b - away * n;
                visc -= ((visc - v_b).dot(n) + away) * n;
            } else if self.separation {
                gv[k].0 = v_b + (u - v_b).dot(n).max(0.0) * n;
            }
            match viscous.as_mut() {
                Some(column) => column[k] = visc,
                None => gv[k].0 = visc,
            }
            gr[k].0 = eos.density(gp[k].0);
        }
        if let Some(normals) = normals {
            sim.resources
                .get_or_default::<Columns>()
                .insert::<WallNormal>(Scope::Particles, normals)?;
        }
        #[cfg(not(feature = "dim3"))]
        if let Some(viscous) = viscous {
            sim.resources
                .get_or_default::<Columns>()
                .insert::<NoSlipVelocity>(NoSlipVelocity::SCOPE, viscous)?;
        }
        Ok(())
    }

    /// Reads the fluid's pressures, densities and velocities and the wall particles'
    /// places; updates the wall particles' pressure and density and writes their
    /// viscous velocities.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Neighbours>()
            .reads::<Position>()
            .reads::<Pressure>()
            .reads::<Density>()
            .reads::<Velocity>()
            .reads::<WallPose>()
            .updates::<Ghost>()
            .writes::<NoSlipVelocity>()
            .writes::<NoSlipSigns>()
            .writes::<WallNormal>()
    }
}

/// The part of `v` along the wall: along its tangent in 2D, in its plane in 3D.
#[inline]
fn along_wall(wall: &WallPose, v: Vector) -> Vector {
    #[cfg(not(feature = "dim3"))]
    return v.dot(wall.tangent()) * wall.tangent();
    #[cfg(feature = "dim3")]
    return v - v.dot(wall.normal()) * wall.normal();
}

#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use glam::DVec2;
    use sph_core::components::Mass;

    /// A closed 0.2 m box lined with wall particles and a row of five fluid particles
    /// 0.005 m above its floor (x = 0.08-0.12 m), particle k at pressure `pressure(k)`,
    /// all moving at `u`, after `WallParticles`, `NeighbourGrid` and
    /// `WallPressure` with `params` have run once.
    fn row_on_the_floor(pressure: impl Fn(usize) -> f64, u: DVec2, params: &str) -> Sim {
        let mut world = hecs::World::new();
        crate::testing::closed_box(&mut world, 0.2, 0.2);
        for k in 0..5 {
            world.spawn((
                Fluid,
                Position(DVec2::new(0.08 + 0.01 * k as f64, 0.005)),
                Velocity(u),
                Density(1000.0),
                Pressure(pressure(k)),
                Mass(0.1),
            ));
        }
        lined(world, "()", params)
    }

    /// `world` after `WallParticles(layers)`, `NeighbourGrid()` and
    /// `WallPressure(params)` have been set up and run once.
    fn lined(world: hecs::World, layers: &str, params: &str) -> Sim {
        crate::testing::after_one_step(
            world,
            &[
                ("wall_particles", layers),
                ("neighbour_grid", "()"),
                ("wall_pressure", params),
            ],
        )
    }

    /// A closed 0.2 m box lined with wall particles, and a row of five fluid particles
    /// 0.005 m above its floor, the middle one in tension (-500 Pa) and the others at
    /// +100 Pa, after `WallPressure(one_sided: true, no_pull: ...)`: the wall particles'
    /// pressures, with each one's distance from the particle in tension.
    fn floor_pressures(no_pull: bool) -> Vec<(f64, f64)> {
        let pressure = |k| if k == 2 { -500.0 } else { 100.0 };
        let params = format!("(one_sided: true, no_pull: {no_pull})");
        let sim = row_on_the_floor(pressure, DVec2::ZERO, &params);
        let ghost = archetype::<Ghost>(&sim.world).unwrap();
        let (x, p) = (
            column::<Position>(ghost).unwrap(),
            column::<Pressure>(ghost).unwrap(),
        );
        let tense = DVec2::new(0.1, 0.005);
        x.iter()
            .zip(p.iter())
            .map(|(x, p)| ((x.0 - tense).length(), p.0))
            .collect()
    }

    /// A closed 0.2 m box lined with wall particles, a 6 x 4 block of fluid in its
    /// lower left corner whose pressures (-300 to +1,700 Pa), densities and velocities
    /// vary from particle to particle, after `WallParticles`, `NeighbourGrid` and
    /// `WallPressure` with `params` have run once.
    fn block_in_the_corner(params: &str, moving: bool) -> Sim {
        let mut world = hecs::World::new();
        crate::testing::closed_box(&mut world, 0.2, 0.2);
        if moving {
            // At its rest place this instant, but translating, turning and
            // accelerating both ways: v_b and a_w differ from one wall particle to
            // the next.
            for wall in world.query_mut::<&mut WallPose>() {
                wall.body.state = sph_core::motion::RigidState {
                    omega: 0.7,
                    alpha: -3.0,
                    velocity: DVec2::new(0.25, -0.15),
                    acceleration: DVec2::new(1.5, 2.0),
                    ..Default::default()
                };
            }
        }
        for a in 0..6 {
            for b in 0..4 {
                let k = (7 * a + 3 * b) % 11;
                world.spawn((
                    Fluid,
                    Position(DVec2::new(0.005 + 0.01 * a as f64, 0.005 + 0.01 * b as f64)),
                    Velocity(DVec2::new(
                        0.1 * k as f64 - 0.4,
                        0.05 * (k % 4) as f64 - 0.07,
                    )),
                    Density(995.0 + k as f64),
                    Pressure(200.0 * k as f64 - 300.0),
                    Mass(0.1),
                ));
            }
        }
        lined(world, "()", params)
    }

    /// Each wall particle's pressure, density and two velocities are the formulas of
    /// the module's comment, summed here by a plain loop over the fluid within the
    /// support, in a box at rest and in one that moves (v_b and a_w the rigid
    /// velocity and acceleration of the box at the wall particle), for Adami et al.'s eq. 27, the
    /// one-sided carry, each slip, `mirror` and `separation`: W the kernel, u_f =
    /// sum v_f W / sum W, t and n the wall's tangent and normal; the density is Tait's
    /// of the pressure. Relative 1e-9 (the order of addition); a wall particle with no
    /// fluid near keeps p = 0 and rho_0. Both walls of the corner are wetted, so a
    /// wall particle that took the other wall's tangent would fail.
    #[test]
    fn the_wall_pressure_and_velocities_are_their_formulas() {
        for (params, moving) in [
            "()",
            "(one_sided: true)",
            "(slip: NoSlip)",
            "(slip: WallVelocity)",
            "(mirror: true)",
            "(mirror: true, slip: NoSlip)",
            "(separation: true)",
        ]
        .into_iter()
        .flat_map(|p| [(p, false), (p, true)])
        {
            let sim = block_in_the_corner(params, moving);
            let c = &sim.constants;
            let (support, g, eos, kind, h) = (c.support(), c.gravity, c.eos, c.kernel, c.h);
            let fluid = archetype::<Fluid>(&sim.world).unwrap();
            let (fx, fp, fr, fv) = (
                column::<Position>(fluid).unwrap(),
                column::<Pressure>(fluid).unwrap(),
                column::<Density>(fluid).unwrap(),
                column::<Velocity>(fluid).unwrap(),
            );
            let ghost = archetype::<Ghost>(&sim.world).unwrap();
            let (gx, gp, gr, gv, gw) = (
                column::<Position>(ghost).unwrap(),
                column::<Pressure>(ghost).unwrap(),
                column::<Density>(ghost).unwrap(),
                column::<Velocity>(ghost).unwrap(),
                column::<MirrorWall>(ghost).unwrap(),
            );
            let columns = sim.resources.get::<Columns>().unwrap();
            let viscous = columns.get::<NoSlipVelocity>().unwrap();
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + b.abs());
            let (mut floor, mut side) = (0, 0);
            for k in 0..gx.len() {
                let wall = sim.world.get::<&WallPose>(gw[k].0).unwrap();
                let (t, n) = (wall.tangent(), wall.normal());
                let (v_b, a_w) = (
                    wall.body.velocity_at(gx[k].0),
                    wall.body.acceleration_at(gx[k].0),
                );
                assert_eq!(moving, v_b != DVec2::ZERO && a_w != DVec2::ZERO);
                let (mut sw, mut spw, mut carry, mut raised, mut svw) =
                    (0.0, 0.0, 0.0, 0.0, DVec2::ZERO);
                for f in 0..fx.len() {
                    let r = gx[k].0 - fx[f].0;
                    if r.length() >= support {
                        continue;
                    }
                    let w = sph_core::kernel::w(kind, h, r.length());
                    sw += w;
                    spw += fp[f].0 * w;
                    carry += fr[f].0 * (g - a_w).dot(r) * w;
                    raised += (fr[f].0 * (g - a_w).dot(r)).max(0.0) * w;
                    svw += fv[f].0 * w;
                }
                if sw == 0.0 {
                    assert_eq!((gp[k].0, gr[k].0), (0.0, eos.density(0.0)), "{params}");
                    continue;
                }
                match n.y > 0.5 {
                    true => floor += 1,
                    false => side += 1,
                }
                let p = match params {
                    "(one_sided: true)" => (spw + raised) / sw,
                    _ => (spw + carry) / sw,
                };
                assert!(close(gp[k].0, p), "{params}: {} Pa against {p}", gp[k].0);
                assert!(close(gr[k].0, eos.density(p)), "{params}: density");
                let u = svw / sw;
                let mut visc = match params {
                    "(slip: NoSlip)" | "(mirror: true, slip: NoSlip)" => 2.0 * v_b - u,
                    "(slip: WallVelocity)" => v_b,
                    _ => v_b + (u - v_b).dot(t) * t,
                };
                let mut v = v_b;
                if params.starts_with("(mirror") {
                    v = v_b - (u - v_b).dot(n) * n;
                    visc = visc - ((visc - v_b).dot(n) + (u - v_b).dot(n)) * n;
                } else if params == "(separation: true)" {
                    v = v_b + (u - v_b).dot(n).max(0.0) * n;
                }
                let near = |a: DVec2, b: DVec2| close(a.x, b.x) && close(a.y, b.y);
                assert!(
                    near(gv[k].0, v),
                    "{params}: velocity {} against {v}",
                    gv[k].0
                );
                assert!(
                    near(viscous[k], visc),
                    "{params}: viscous {} against {visc}",
                    viscous[k]
                );
            }
            assert!(
                floor >= 10 && side >= 8,
                "{params}: {floor} floor, {side} side wall particles wetted"
            );
        }
    }

    /// One wall particle (a wall one spacing long, one layer) and one fluid particle
    /// above it, whose only wall neighbour is therefore the first ghost: the wall
    /// particle takes Adami's eq. 27 of that one particle, p_f + rho_f g . (x_w - x_f).
    #[test]
    fn a_lone_wall_particle_takes_its_lone_fluid_neighbour_s_pressure() {
        let mut world = hecs::World::new();
        let rest = sph_core::components::Wall {
            name: "floor".into(),
            a: DVec2::ZERO,
            b: DVec2::new(0.01, 0.0),
            body: Default::default(),
        };
        let now = rest.at_rest();
        world.spawn((rest, now));
        let xf = DVec2::new(0.005, 0.005);
        world.spawn((
            Fluid,
            Position(xf),
            Velocity(DVec2::ZERO),
            Density(1000.0),
            Pressure(700.0),
            Mass(0.1),
        ));
        let sim = lined(world, "(layers: 1)", "()");
        let ghost = archetype::<Ghost>(&sim.world).unwrap();
        let (x, p) = (
            column::<Position>(ghost).unwrap(),
            column::<Pressure>(ghost).unwrap(),
        );
        assert_eq!(x.len(), 1);
        let expected = 700.0 + 1000.0 * sim.constants.gravity.dot(x[0].0 - xf);
        assert!(
            (p[0].0 - expected).abs() < 1e-9 * expected,
            "{} against {expected}",
            p[0].0
        );
    }

    /// The stage needs the neighbour lists: set up without the grid it is refused by
    /// name, and the contract check refuses it listed before the grid. With two
    /// velocities it declares the walls' no-slip velocities as a column from setup on
    /// (a stage set up after it reads the column to pick its pair layout), and with
    /// `single_velocity` none.
    #[test]
    fn the_wall_pressure_needs_the_lists_and_declares_its_second_velocity() {
        use sph_core::contract::{check, Breach, Quantity};
        let boxed = || {
            let mut world = hecs::World::new();
            crate::testing::closed_box(&mut world, 0.2, 0.2);
            crate::testing::sim(world)
        };
        let mut sim = boxed();
        crate::testing::pipeline(&mut sim, &[("wall_particles", "()")]);
        let e = crate::testing::stage("wall_pressure", "()")
            .setup(&mut sim)
            .unwrap_err();
        assert!(e.to_string().contains("wall_pressure"), "{e}");
        let (grid, walls) = (
            crate::testing::stage("neighbour_grid", "()").access(),
            crate::testing::stage("wall_pressure", "()").access(),
        );
        assert!(matches!(
            check([(&walls, 1), (&grid, 1)]),
            Err(Breach::Unwritten { quantity, reader: 0, .. }) if quantity == Quantity::of::<Neighbours>()
        ));
        for single in [false, true] {
            let mut sim = boxed();
            let params = format!("(single_velocity: {single})");
            crate::testing::pipeline(
                &mut sim,
                &[
                    ("wall_particles", "()"),
                    ("neighbour_grid", "()"),
                    ("wall_pressure", &params),
                ],
            );
            let column = sim
                .resources
                .get::<Columns>()
                .is_some_and(|c| c.contains::<NoSlipVelocity>());
            assert_eq!(column, !single, "{params}");
            assert!(sim.resources.get::<NoSlipSigns>().is_some());
        }
    }

    /// With `single_velocity`, `mirror` and free slip, a wall particle beside fluid that
    /// moves at u (uniform, so the smoothed u_f is u) moves at u's mirror image in the
    /// fixed floor, (u_x, -u_y), and the records get no second (no-slip) velocity; with
    /// two velocities it moves at (0, -u_y), the wall's own tangential velocity.
    #[test]
    fn a_single_velocity_wall_moves_as_the_fluid_s_mirror_image() {
        let u = DVec2::new(0.3, -0.2);
        let run = |single: bool| {
            let params = format!("(mirror: true, single_velocity: {single})");
            let sim = row_on_the_floor(|_| 100.0, u, &params);
            let ghost = archetype::<Ghost>(&sim.world).unwrap();
            let (x, v, p) = (
                column::<Position>(ghost).unwrap(),
                column::<Velocity>(ghost).unwrap(),
                column::<Pressure>(ghost).unwrap(),
            );
            let floor: Vec<DVec2> = (0..x.len())
                .filter(|&k| p[k].0 > 0.0 && x[k].0.y < 0.0 && x[k].0.x > 0.0)
                .map(|k| v[k].0)
                .collect();
            let column = sim
                .resources
                .get::<Columns>()
                .is_some_and(|c| c.contains::<NoSlipVelocity>());
            (floor, column)
        };
        let (single, column) = run(true);
        assert!(single.len() >= 5 && !column);
        for v in single {
            assert!((v - DVec2::new(u.x, -u.y)).length() < 1e-12, "{v}");
        }
        let (two, column) = run(false);
        assert!(two.len() >= 5 && column);
        for v in two {
            assert!((v - DVec2::new(0.0, -u.y)).length() < 1e-12, "{v}");
        }
    }

    /// The `WallNormal` column the pair mirror wrote (fluid, then wall particles).
    fn normals(sim: &Sim) -> &[DVec2] {
        sim.resources
            .get::<Columns>()
            .unwrap()
            .get::<WallNormal>()
            .unwrap()
    }

    /// With `pair_mirror` every wall particle near the fluid keeps its wall's velocity
    /// (the fixed box's: 0) and carries its wall's unit normal in the `WallNormal`
    /// column, the fluid and the wall particles beyond its reach a zero there (the
    /// terms then meet only wall particles with i's image); the other forms' mirrored
    /// velocity is not written, and the form is refused beside the settings that set
    /// the wall's velocity otherwise.
    #[test]
    fn the_pair_mirror_gives_the_wall_particles_their_normals() {
        let u = DVec2::new(0.3, -0.2);
        let sim = row_on_the_floor(|_| 100.0, u, "(single_velocity: true, pair_mirror: true)");
        let ghost = archetype::<Ghost>(&sim.world).unwrap();
        let (x, v, p) = (
            column::<Position>(ghost).unwrap(),
            column::<Velocity>(ghost).unwrap(),
            column::<Pressure>(ghost).unwrap(),
        );
        let fluid = archetype::<Fluid>(&sim.world).unwrap().len() as usize;
        let normals = normals(&sim);
        assert_eq!(normals.len(), fluid + x.len());
        assert!(normals[..fluid].iter().all(|n| *n == DVec2::ZERO));
        let mut floor = 0;
        for k in 0..x.len() {
            let n = normals[fluid + k];
            if p[k].0 > 0.0 && x[k].0.y < 0.0 && x[k].0.x > 0.0 {
                floor += 1;
                assert_eq!((n, v[k].0), (DVec2::Y, DVec2::ZERO), "at {}", x[k].0);
            } else if p[k].0 == 0.0 {
                assert_eq!(n, DVec2::ZERO, "at {}", x[k].0);
            }
        }
        assert!(floor >= 5, "{floor} floor particles near the fluid");
        for refused in [
            "(single_velocity: false, pair_mirror: true)",
            "(single_velocity: true, mirror: true, pair_mirror: true)",
            "(single_velocity: true, slip: NoSlip, pair_mirror: true)",
            "(single_velocity: false, separation: true, pair_mirror: true)",
        ] {
            let registry = crate::standard_registry();
            let mut de = ron::Deserializer::from_str(refused).unwrap();
            let mut erased = <dyn erased_serde::Deserializer>::erase(&mut de);
            let err = match registry.build("wall_pressure", &mut erased).unwrap() {
                Ok(_) => panic!("{refused} accepted"),
                Err(e) => e.to_string(),
            };
            assert!(err.contains("pair_mirror"), "{refused}: {err}");
        }
    }

    /// With `pair_mirror` and no wall particle at all, the normals are a zero for
    /// each fluid particle, so the terms read every pair as a fluid pair.
    #[test]
    fn the_pair_mirror_without_walls_gives_zero_normals() {
        let mut world = hecs::World::new();
        for k in 0..3 {
            world.spawn((
                Fluid,
                Position(DVec2::new(0.1 + 0.01 * k as f64, 0.1)),
                Velocity(DVec2::ZERO),
                Density(1000.0),
                Pressure(0.0),
                Mass(0.1),
            ));
        }
        let sim = crate::testing::after_one_step(
            world,
            &[
                ("neighbour_grid", "()"),
                (
                    "wall_pressure",
                    "(single_velocity: true, pair_mirror: true)",
                ),
            ],
        );
        let normals = normals(&sim);
        assert_eq!(normals, &[DVec2::ZERO; 3]);
    }

    /// With `pair_mirror` the `Continuity` stage (a pass of its own) sums what
    /// `Forces(terms: [Continuity()])` sums, bit for bit, and both differ from the
    /// sums against the wall particles' own velocity: the stage reads the image too.
    #[test]
    fn the_continuity_stage_reads_the_pair_mirror_as_forces_does() {
        use sph_core::components::DensityRate;
        let rates = |wall: &str, pass: (&str, &str)| {
            let sim = crate::testing::after_one_step(
                {
                    let mut world = hecs::World::new();
                    crate::testing::closed_box(&mut world, 0.2, 0.2);
                    for k in 0..5 {
                        world.spawn((
                            Fluid,
                            Position(DVec2::new(0.08 + 0.01 * k as f64, 0.005)),
                            Velocity(DVec2::new(0.1 * k as f64, -0.2 - 0.05 * k as f64)),
                            Density(1000.0),
                            Pressure(100.0),
                            Mass(0.1),
                        ));
                    }
                    world
                },
                &[
                    ("wall_particles", "()"),
                    ("neighbour_grid", "()"),
                    ("wall_pressure", wall),
                    pass,
                ],
            );
            let fluid = archetype::<Fluid>(&sim.world).unwrap();
            let rate = column::<DensityRate>(fluid).unwrap();
            rate.iter().map(|r| r.0).collect::<Vec<f64>>()
        };
        let pair = "(single_velocity: true, pair_mirror: true)";
        let stage = rates(pair, ("continuity", "()"));
        let forces = rates(pair, ("forces", "(terms: [Continuity()])"));
        let own = rates("(single_velocity: true)", ("continuity", "()"));
        assert_eq!(
            stage.iter().map(|r| r.to_bits()).collect::<Vec<_>>(),
            forces.iter().map(|r| r.to_bits()).collect::<Vec<_>>()
        );
        assert!(stage
            .iter()
            .zip(&own)
            .all(|(a, b)| (a - b).abs() > 1e-6 * b.abs()));
    }

    /// With `largest` a wall particle's pressure is the largest over the fluid within its
    /// support of p_f + rho_f g . (x_w - x_f) (a fixed box: a_w = 0), summed here by
    /// hand; a wall particle with no fluid near keeps 0.
    #[test]
    fn the_largest_carried_pressure_is_what_the_wall_takes() {
        // A mixed row, and one wholly in tension (the largest is then below 0).
        for pressure in [
            |k| [300.0, -500.0, 100.0, 2000.0, 50.0][k],
            |k| [-300.0, -500.0, -800.0, -2000.0, -650.0][k],
        ] {
            largest_carried(pressure);
        }
    }

    fn largest_carried(pressure: fn(usize) -> f64) {
        let sim = row_on_the_floor(pressure, DVec2::ZERO, "(largest: true)");
        let support = sim.constants.support();
        let g = sim.constants.gravity;
        let fluid = archetype::<Fluid>(&sim.world).unwrap();
        let (fx, fp, fr) = (
            column::<Position>(fluid).unwrap(),
            column::<Pressure>(fluid).unwrap(),
            column::<Density>(fluid).unwrap(),
        );
        let ghost = archetype::<Ghost>(&sim.world).unwrap();
        let (gx, gp) = (
            column::<Position>(ghost).unwrap(),
            column::<Pressure>(ghost).unwrap(),
        );
        let mut wetted = 0;
        for (x, p) in gx.iter().zip(gp.iter()) {
            let carried = (0..fx.len())
                .filter(|&f| (x.0 - fx[f].0).length() < support)
                .map(|f| fp[f].0 + fr[f].0 * g.dot(x.0 - fx[f].0))
                .fold(None, |m: Option<f64>, c| {
                    Some(m.map_or(c, |m| sph_core::extremes::nan_max(m, c)))
                });
            match carried {
                Some(c) => {
                    wetted += 1;
                    assert!(
                        (p.0 - c).abs() <= 1e-9 * c.abs(),
                        "{} Pa against {c} Pa",
                        p.0
                    );
                }
                None => assert_eq!(p.0, 0.0),
            }
        }
        assert!(wetted >= 10, "{wetted} wall particles near the fluid");
    }

    /// With `no_pull` every wall particle within the support of the particle in tension
    /// pushes it at least as hard as it pulls (p_w >= 500 Pa, so p_f + p_w >= 0);
    /// without it, the wall's extrapolated pressure there is below that (the Shepard
    /// mean of -500 and +100 Pa), so the wall pulls. The wall particles beyond every
    /// fluid particle's reach keep p = 0 either way.
    #[test]
    fn a_wall_that_does_not_pull_holds_no_fluid_in_tension() {
        let support = crate::testing::sim(hecs::World::new()).constants.support();
        let (held, pulled) = (floor_pressures(true), floor_pressures(false));
        let near: Vec<_> = held.iter().filter(|(d, _)| *d < support).collect();
        assert!(
            near.len() >= 4,
            "wall particles near the tension: {}",
            near.len()
        );
        for (d, p) in &near {
            assert!(*p >= 500.0, "a wall particle {d:.4} m away at {p:.1} Pa");
        }
        assert!(
            pulled.iter().any(|(d, p)| *d < support && *p < 0.0),
            "without no_pull the wall beside the tension reads below zero"
        );
        let far = |v: &[(f64, f64)]| v.iter().filter(|(d, _)| *d > 0.1).all(|(_, p)| *p == 0.0);
        assert!(far(&held) && far(&pulled));
    }
}
