//! Mirrored ghost-particle walls (docs/physics.md, "Walls: mirrored ghost particles").
//!
//! Every fluid particle within one kernel support of a wall is mirrored across it; near
//! a corner where two walls meet it is also mirrored across both (the double mirror).
//! A ghost carries the mirrored position, the source's mass, a mirrored velocity and the
//! source's density, optionally corrected hydrostatically so the ghost's pressure is
//! p_i + rho_0 (g - a_w) . (x_ghost - x_i). Ghost entities are kept in their own
//! archetype and reused from step to step: only the difference in count is spawned or
//! despawned.
//!
//! With lasting neighbour lists (`NeighbourGrid(skin)`), the ghosts are found only
//! when the lists are rebuilt, for the particles within the support and the skin of a
//! wall (and up to a skin past its ends), and each keeps its slot (its place in the
//! lists) until the next rebuild: every step re-mirrors it from its source, with the
//! source's mass while the source is near the wall by the rule above and zero mass
//! otherwise, so it weighs exactly as the ghosts found every step would. The lists are
//! rebuilt when a particle or ghost has moved half the skin, or a wall has: this stage
//! takes that decision for the grid (`vocab::ListPlan`), as it must renew the ghosts
//! then.
//!
//! Moving walls (a rolling tank): walls are mirrored where they are at the current
//! time, and velocities are mirrored relative to the wall's own velocity v_w at the
//! foot of the particle on the wall: a ghost's `Velocity` reverses the normal
//! component of v - v_w (no flow through the wall) whatever the slip, and with
//! `slip: NoSlip` the viscous terms read 2 v_w - v instead (`vocab::NoSlipVelocity`;
//! Adami, Hu & Adams 2012, sec. 2.3). The hydrostatic correction uses the effective
//! gravity g - a_w of the tank frame, a_w the tank's rigid acceleration at the source.

use crate::vocab::{ghost_density, GhostReflections, GhostSettings, NoSlipSigns, NoSlipVelocity};
use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{Density, Fluid, Ghost, Mass, Position, Pressure, Velocity};
use sph_core::contract::Access;
use sph_core::pair::Columns;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{ListPlan, MirrorWall, Neighbours, WallPose, Walls};
use sph_core::walls::WallLine;
use sph_core::world::{archetype, column, column_mut, count};
use sph_core::StageRegistry;

/// Tangential velocity condition at the walls, for the viscous terms (continuity and
/// the pressure solves see the normal component mirrored either way).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Slip {
    /// Tangential velocity mirrored unchanged (no wall shear).
    FreeSlip,
    /// Tangential velocity reversed in the viscous terms (zero velocity at the wall).
    NoSlip,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Default FreeSlip.
    pub slip: Slip,
    /// Correct ghost pressure (and density) by rho_0 g . (x_ghost - x_source).
    /// Default true.
    pub hydrostatic: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            slip: Slip::FreeSlip,
            hydrostatic: true,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "ghost_walls",
        "mirror fluid particles across the walls as ghost particles",
        |p: Params| Ok(GhostWalls::new(p)),
    );
}

pub struct GhostWalls {
    params: Params,
    /// The walls as the world holds them, re-read every step (a reused buffer); the
    /// pairs of walls sharing an end point (its corners) get double mirrors.
    walls: Walls,
    /// This step's ghosts, and the per-chunk lists they are gathered from (both kept
    /// between steps: no per-step allocation once they have reached their size).
    images: Vec<Image>,
    chunks: Vec<Vec<Image>>,
    /// When the ghosts were found: the fluid count and the walls' end points.
    built: Option<(usize, Vec<(DVec2, DVec2)>)>,
}

/// A particle closer to a wall than this fraction of ds gets no ghost across it. A
/// particle placed exactly on a wall coincides with its mirror image, and the ghost
/// doubled the mass there: still water with a row of particles on the bottom was
/// pushed up by twice that row's pressure and sloshed at 1.2 m/s within 0.1 s
/// (docs/validation.md, "Hard cases").
const ON_WALL: f64 = 1e-6;

/// Fluid particles per parallel chunk when finding the ghosts.
const CHUNK: usize = 1024;

/// One ghost to place: its source and the walls it is mirrored across.
#[derive(Clone, Copy)]
struct Image {
    source: u32,
    first: u16,
    second: Option<u16>,
}

impl Stage for GhostWalls {
    fn name(&self) -> &'static str {
        "ghost_walls"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        self.walls.read(&sim.world);
        if self.walls.is_empty() {
            return Err(SetupError::new(
                "ghost_walls",
                "the scenario has no walls; remove GhostWalls() or add a `tank` or `walls`",
            ));
        }
        sim.resources.insert(GhostSettings {
            hydrostatic: self.params.hydrostatic,
        });
        if self.params.slip == Slip::NoSlip {
            sim.resources.insert(NoSlipSigns::default());
            sim.resources
                .get_or_default::<Columns>()
                .insert::<NoSlipVelocity>(NoSlipVelocity::SCOPE, Vec::new())
                .map_err(|e| SetupError::new("ghost_walls", e.to_string()))?;
        }
        Ok(())
    }

    /// The ghosts' walls and the state of their last finding, so a resumed run keeps
    /// the uninterrupted run's ghosts (their sources are in the ghost columns).
    fn save_state(&mut self, _sim: &Sim) -> Result<Vec<u8>, StepError> {
        let mut e = Enc::default();
        e.u64(self.images.len() as u64);
        for img in &self.images {
            e.u32(img.first as u32);
            e.u32(img.second.map_or(u32::MAX, u32::from));
        }
        let (n_fluid, walls) = self
            .built
            .as_ref()
            .map_or((u64::MAX, &[][..]), |(n, w)| (*n as u64, &w[..]));
        e.u64(n_fluid);
        e.u64(walls.len() as u64);
        for (a, b) in walls {
            for v in [a.x, a.y, b.x, b.y] {
                e.f64(v);
            }
        }
        Ok(e.into_bytes())
    }

    fn load_state(&mut self, _sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        let n = d.len(8)?;
        self.images.clear();
        for _ in 0..n {
            let first = d.u32()?;
            let second = d.u32()?;
            let wall = |w: u32| {
                u16::try_from(w)
                    .map_err(|_| sph_core::StateError::Mismatch(format!("ghost wall {w}")))
            };
            self.images.push(Image {
                source: 0,
                first: wall(first)?,
                second: (second != u32::MAX).then(|| wall(second)).transpose()?,
            });
        }
        let n_fluid = d.u64()?;
        let count = d.len(32)?;
        let mut walls = Vec::with_capacity(count);
        for _ in 0..count {
            let (ax, ay, bx, by) = (d.f64()?, d.f64()?, d.f64()?, d.f64()?);
            walls.push((DVec2::new(ax, ay), DVec2::new(bx, by)));
        }
        self.built = (n_fluid != u64::MAX).then_some((n_fluid as usize, walls));
        d.end()
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        // The walls where the world has them now (the scene moves with the clock).
        self.walls.read(&sim.world);
        let skin = sim.resources.get::<Neighbours>().map_or(0.0, |nb| nb.skin);
        // While the lists last, the ghosts keep their slots.
        if skin > 0.0 && self.kept(sim, skin) {
            self.mirror(sim, false)?;
            let fluid = archetype::<Fluid>(&sim.world);
            let ghost = archetype::<Ghost>(&sim.world);
            let fpos = fluid.map(column::<Position>).transpose()?;
            let gpos = ghost.map(column::<Position>).transpose()?;
            let (fpos, gpos) = (
                fpos.as_deref().unwrap_or(&[]),
                gpos.as_deref().unwrap_or(&[]),
            );
            if let Some(nb) = sim.resources.get_mut::<Neighbours>() {
                if !nb.outdated(fpos, gpos) {
                    nb.plan = ListPlan::Keep;
                    return Ok(());
                }
            }
        }
        self.find_images(sim, skin)?;
        resize_pool(&mut sim.world, self.images.len());
        self.mirror(sim, true)?;
        self.built = Some((
            count::<Fluid>(&sim.world),
            self.walls.now().iter().map(|w| (w.a, w.b)).collect(),
        ));
        if let Some(nb) = sim.resources.get_mut::<Neighbours>().filter(|_| skin > 0.0) {
            nb.plan = ListPlan::Rebuild;
        }
        Ok(())
    }

    /// Mirrors the fluid's positions, velocities, densities and masses across the
    /// walls where the world has them: writes the ghost particles (with the wall each
    /// was mirrored across) and the ghost settings.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Position>()
            .reads::<Velocity>()
            .reads::<Density>()
            .reads::<Mass>()
            .reads::<WallPose>()
            .uses::<Neighbours>()
            .writes::<Ghost>()
            .writes::<MirrorWall>()
            .writes::<GhostSettings>()
            .writes::<GhostReflections>()
            .writes::<NoSlipVelocity>()
            .writes::<NoSlipSigns>()
    }
}

impl GhostWalls {
    /// The stage with `params`, before its first step: no ghosts found yet.
    fn new(params: Params) -> Self {
        Self {
            params,
            walls: Walls::default(),
            images: Vec::new(),
            chunks: Vec::new(),
            built: None,
        }
    }

    /// Whether the ghosts found last can serve this step: the fluid and ghost counts
    /// are those of the finding, and no wall end has moved half the `skin` since (a
    /// segment moved rigidly moves no point farther than its ends).
    fn kept(&self, sim: &Sim, skin: f64) -> bool {
        let Some((n_fluid, walls)) = &self.built else {
            return false;
        };
        let half = 0.5 * skin;
        *n_fluid == count::<Fluid>(&sim.world)
            && self.images.len() == count::<Ghost>(&sim.world)
            && walls.len() == self.walls.now().len()
            && walls
                .iter()
                .zip(self.walls.now())
                .all(|((a, b), w)| a.distance(w.a) <= half && b.distance(w.b) <= half)
    }

    /// Places every ghost at its source's mirror image across its walls, with the
    /// mirrored velocity, the (corrected) density and the source's mass, or zero mass
    /// when the source is not near the walls by the rule of a finding without skin.
    /// `renew`: the ghosts were just found; their sources and walls are written first.
    fn mirror(&self, sim: &mut Sim, renew: bool) -> Result<(), StepError> {
        let _span = tracing::info_span!("mirror").entered();
        let images = &self.images[..];
        // Only when a stage asked for them (the DFSPH solves); the walls move with the
        // tank, so every step.
        if let Some(r) = sim.resources.get_mut::<GhostReflections>() {
            let lines = self.walls.lines();
            r.0.clear();
            r.0.extend(images.iter().map(|img| reflection(lines, img)));
        }
        // The no-slip velocities (written below), one per ghost.
        if let Some(signs) = sim.resources.get_mut::<NoSlipSigns>() {
            signs.0.clear();
            signs.0.extend(
                images
                    .iter()
                    .map(|img| if img.second.is_some() { 1.0 } else { -1.0 }),
            );
        }
        let columns = sim.resources.get_mut::<Columns>();
        let mut no_slip = columns.and_then(|c| c.remove::<NoSlipVelocity>());
        if let Some(ns) = &mut no_slip {
            ns.resize(images.len(), DVec2::ZERO);
        }
        let result = self.mirror_into(sim, renew, no_slip.as_deref_mut());
        if let Some(ns) = no_slip {
            sim.resources
                .get_or_default::<Columns>()
                .insert::<NoSlipVelocity>(NoSlipVelocity::SCOPE, ns)?;
        }
        result
    }

    /// [`GhostWalls::mirror`] into the world's ghost columns, and each ghost's no-slip
    /// velocity into `no_slip` when given.
    fn mirror_into(
        &self,
        sim: &mut Sim,
        renew: bool,
        no_slip: Option<&mut [DVec2]>,
    ) -> Result<(), StepError> {
        let images = &self.images[..];
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let Some(ghost) = archetype::<Ghost>(&sim.world) else {
            return Ok(());
        };
        let (fx, fv) = (column::<Position>(fluid)?, column::<Velocity>(fluid)?);
        let (fr, fm) = (column::<Density>(fluid)?, column::<Mass>(fluid)?);
        let (mut gs, mut gw) = (
            column_mut::<Ghost>(ghost)?,
            column_mut::<MirrorWall>(ghost)?,
        );
        let (mut gx, mut gv) = (
            column_mut::<Position>(ghost)?,
            column_mut::<Velocity>(ghost)?,
        );
        let (mut gr, mut gm) = (column_mut::<Density>(ghost)?, column_mut::<Mass>(ghost)?);
        let (fx, fv, fr, fm): (&[Position], &[Velocity], &[Density], &[Mass]) =
            (&fx, &fv, &fr, &fm);
        if gs.len() != images.len() {
            return Err(StepError::Internal(format!(
                "{} ghosts for {} images",
                gs.len(),
                images.len()
            )));
        }
        let correction = self
            .params
            .hydrostatic
            .then_some((sim.constants.eos, sim.constants.gravity));
        let (walls, lines) = (self.walls.now(), self.walls.lines());
        let entities = self.walls.entities();
        let near = near_rule(sim, 0.0);
        (
            (&mut gs[..], &mut gw[..]),
            &mut gx[..],
            &mut gv[..],
            &mut gr[..],
            &mut gm[..],
            images,
        )
            .into_par_iter()
            .for_each(|((g, wall), x, v, rho, m, img)| {
                if renew {
                    *g = Ghost { source: img.source };
                    *wall = MirrorWall(entities[img.first as usize]);
                }
                let s = g.source as usize;
                let (mut pos, mut vel) = (fx[s].0, fv[s].0);
                let mut active = true;
                for k in std::iter::once(img.first).chain(img.second) {
                    let k = k as usize;
                    active &= near(&lines[k], fx[s].0);
                    vel = mirror_velocity(&lines[k], &walls[k], pos, vel, Slip::FreeSlip);
                    pos = lines[k].mirror(pos);
                }
                x.0 = pos;
                v.0 = vel;
                m.0 = if active { fm[s].0 } else { 0.0 };
                let body = walls[img.first as usize].body;
                rho.0 = ghost_density(fr[s].0, fx[s].0, pos, correction.map(|c| (c, body)));
            });
        if let Some(ns) = no_slip {
            // The source from the ghost column: a particle sort renumbers it there
            // (`sort_particles`), not in `images`, while the ghosts are kept.
            let sources: &[Ghost] = &gs;
            ns.par_iter_mut()
                .zip(sources)
                .zip(images)
                .for_each(|((out, g), img)| {
                    let s = g.source as usize;
                    let (mut pos, mut vel) = (fx[s].0, fv[s].0);
                    for k in std::iter::once(img.first).chain(img.second) {
                        let k = k as usize;
                        vel = mirror_velocity(&lines[k], &walls[k], pos, vel, Slip::NoSlip);
                        pos = lines[k].mirror(pos);
                    }
                    *out = vel;
                });
        }
        Ok(())
    }

    /// Fills `images` with the ghosts this step needs (within the support and `skin`
    /// of a wall), in a fixed order (by source, then wall), reusing the per-chunk
    /// buffers from step to step.
    fn find_images(&mut self, sim: &Sim, skin: f64) -> Result<(), StepError> {
        let _span = tracing::info_span!("find_images").entered();
        self.images.clear();
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let pos = column::<Position>(fluid)?;
        let lines = self.walls.lines();
        let corners = self.walls.corners();
        let near = near_rule(sim, skin);
        self.chunks.resize_with(pos.len().div_ceil(CHUNK), Vec::new);
        self.chunks.truncate(pos.len().div_ceil(CHUNK));
        pos.par_chunks(CHUNK)
            .zip(self.chunks.par_iter_mut())
            .enumerate()
            .for_each(|(c, (chunk, out))| {
                out.clear();
                for (k, x) in chunk.iter().enumerate() {
                    let source = (c * CHUNK + k) as u32;
                    for (w, line) in lines.iter().enumerate() {
                        if near(line, x.0) {
                            out.push(Image {
                                source,
                                first: w as u16,
                                second: None,
                            });
                        }
                    }
                    for c in corners {
                        let (a, b) = (c.first, c.second);
                        if near(&lines[a], x.0) && near(&lines[b], x.0) {
                            out.push(Image {
                                source,
                                first: a as u16,
                                second: Some(b as u16),
                            });
                        }
                    }
                }
            });
        for chunk in &self.chunks {
            self.images.extend_from_slice(chunk);
        }
        Ok(())
    }
}

/// Whether a particle at x gets a ghost across wall w: within the support of the wall
/// and over it, with a `skin` of margin (0 for the rule itself). A particle on the
/// wall (closer than `ON_WALL` ds) is its own mirror image: a ghost there would count
/// its mass twice for its neighbours.
fn near_rule(sim: &Sim, skin: f64) -> impl Fn(&WallLine, DVec2) -> bool + Sync {
    let support = sim.constants.support();
    let on_wall = ON_WALL * sim.constants.spacing;
    move |w: &WallLine, x: DVec2| {
        let (d, s) = (w.distance(x), w.abscissa(x));
        d > on_wall - skin && d < support + skin && s >= -skin && s <= w.length + skin
    }
}

/// Velocity of the ghost of a particle at `x` moving at `v`, mirrored across wall `w`
/// (`line` its geometry) relative to the wall's velocity at the particle's foot on it.
fn mirror_velocity(line: &WallLine, w: &WallPose, x: DVec2, v: DVec2, slip: Slip) -> DVec2 {
    let n = line.normal;
    let vw = w.velocity_at(x - line.distance(x) * n);
    match slip {
        Slip::FreeSlip => v - 2.0 * (v - vw).dot(n) * n,
        Slip::NoSlip => 2.0 * vw - v,
    }
}

/// The linear part of a ghost's `Velocity` mirror (see [`GhostReflections`]): the
/// product of each crossed wall's I - 2 n n^T, the linear part of [`mirror_velocity`]
/// with free slip.
fn reflection(lines: &[WallLine], img: &Image) -> [f64; 4] {
    let mut m = [1.0, 0.0, 0.0, 1.0];
    for k in std::iter::once(img.first).chain(img.second) {
        let n = lines[k as usize].normal;
        let l = [
            1.0 - 2.0 * n.x * n.x,
            -2.0 * n.x * n.y,
            -2.0 * n.y * n.x,
            1.0 - 2.0 * n.y * n.y,
        ];
        m = [
            l[0] * m[0] + l[1] * m[2],
            l[0] * m[1] + l[1] * m[3],
            l[2] * m[0] + l[3] * m[2],
            l[2] * m[1] + l[3] * m[3],
        ];
    }
    m
}

/// Brings the ghost pool to `needed` entities: spawns the shortfall or despawns the
/// surplus from the end of the archetype (which keeps the others' order).
fn resize_pool(world: &mut hecs::World, needed: usize) {
    let have = count::<Ghost>(world);
    if needed > have {
        world.spawn_batch((have..needed).map(|_| {
            (
                Ghost::default(),
                Position::default(),
                Velocity::default(),
                Density(1.0),
                Pressure(0.0),
                Mass(0.0),
                MirrorWall::default(),
            )
        }));
    } else if needed < have {
        let surplus: Vec<hecs::Entity> = world
            .query::<hecs::Entity>()
            .with::<&Ghost>()
            .iter()
            .skip(needed)
            .collect();
        for e in surplus.into_iter().rev() {
            let _ = world.despawn(e);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stage() -> GhostWalls {
        GhostWalls::new(Params::default())
    }

    /// A closed 0.5 m x 0.3 m box with three fluid particles: one in a corner (two
    /// single images and a double), one near the floor, one far from every wall.
    fn boxed() -> Sim {
        let mut world = hecs::World::new();
        crate::testing::closed_box(&mut world, 0.5, 0.3);
        for (x, y) in [(0.005, 0.006), (0.25, 0.004), (0.25, 0.15)] {
            world.spawn((
                Fluid,
                Position(DVec2::new(x, y)),
                Velocity(DVec2::new(0.1, -0.2)),
                Density(1000.0),
                Pressure(0.0),
                Mass(0.1),
            ));
        }
        crate::testing::sim(world)
    }

    /// With lasting neighbour lists (a skin), a step on which nothing has moved keeps
    /// the ghosts found last and tells the grid to keep its lists; the first step finds
    /// them and asks for a rebuild.
    #[test]
    fn unmoved_ghosts_keep_the_neighbour_lists() {
        let mut sim = boxed();
        sim.resources.insert(Neighbours {
            skin: 0.004,
            ..Default::default()
        });
        let mut walls = stage();
        walls.setup(&mut sim).unwrap();
        walls.run(&mut sim).unwrap();
        let plan = |sim: &Sim| sim.resources.get::<Neighbours>().unwrap().plan;
        assert_eq!(plan(&sim), ListPlan::Rebuild);
        // The grid's build: the lists hold these positions.
        let at = |sim: &Sim, ghosts: bool| -> Vec<DVec2> {
            let a = if ghosts {
                archetype::<Ghost>(&sim.world)
            } else {
                archetype::<Fluid>(&sim.world)
            };
            column::<Position>(a.unwrap())
                .unwrap()
                .iter()
                .map(|p| p.0)
                .collect()
        };
        let (fluid, ghosts) = (at(&sim, false), at(&sim, true));
        assert_eq!(ghosts.len(), 4);
        let nb = sim.resources.get_mut::<Neighbours>().unwrap();
        (nb.n_fluid, nb.n_ghost) = (fluid.len(), ghosts.len());
        nb.built_at = fluid.iter().chain(&ghosts).copied().collect();
        nb.plan = ListPlan::Undecided;
        walls.run(&mut sim).unwrap();
        assert_eq!(plan(&sim), ListPlan::Keep);
        assert_eq!(at(&sim, true), ghosts);
    }

    /// A checkpoint holds the ghosts as they were found (which walls each mirrors
    /// across, a corner's two) and when: a stage loaded from it saves the same bytes,
    /// and a stage that loads nothing does not.
    #[test]
    fn the_ghosts_found_come_back_from_a_checkpoint() {
        let mut sim = boxed();
        let mut found = stage();
        found.setup(&mut sim).unwrap();
        found.run(&mut sim).unwrap();
        let (singles, doubles) = (
            found.images.iter().filter(|i| i.second.is_none()).count(),
            found.images.iter().filter(|i| i.second.is_some()).count(),
        );
        assert_eq!(
            (singles, doubles),
            (3, 1),
            "the corner's 2 + 1, the floor's 1"
        );
        let saved = found.save_state(&sim).unwrap();
        let mut loaded = stage();
        loaded.load_state(&mut sim, &saved).unwrap();
        assert_eq!(loaded.save_state(&sim).unwrap(), saved);
        assert_ne!(stage().save_state(&sim).unwrap(), saved);
        let walls = |s: &GhostWalls| -> Vec<(u16, Option<u16>)> {
            s.images.iter().map(|i| (i.first, i.second)).collect()
        };
        assert_eq!(walls(&loaded), walls(&found));
        assert_eq!(loaded.built, found.built);
        // A checkpoint keys each stage's state by its name, the registered one.
        assert_eq!(found.name(), "ghost_walls");
    }
}
