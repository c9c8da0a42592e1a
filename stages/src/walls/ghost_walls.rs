//! Mirrored ghost-particle walls (docs/physics.md, "Walls: mirrored ghost particles").
//!
//! Every fluid particle within one kernel support of a wall is mirrored across it; near
//! a corner where two walls meet it is also mirrored across both (the double mirror);
//! in 3D the same near an edge where two walls meet, and near a vertex where three
//! meet across all three (the triple mirror).
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
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{Density, Fluid, Ghost, Mass, Position, Pressure, Velocity};
use sph_core::contract::Access;
use sph_core::dim::{Vector, DIM};
use sph_core::pair::Columns;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{ListPlan, MirrorWall, Neighbours, WallPose, Walls};
use sph_core::walls::{Corner, WallLine};
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
    /// When the ghosts were found: the fluid count and the walls' corner points.
    built: Option<(usize, Vec<[Vector; POINTS]>)>,
}

/// A wall's corner points: its two ends in 2D, the rectangle's four vertices in 3D (a
/// rigid motion moves no point of a wall farther than the farthest of these).
const POINTS: usize = 2 * (sph_core::dim::DIM - 1);

/// `w`'s corner points ([`POINTS`]).
fn points(w: &WallPose) -> [Vector; POINTS] {
    #[cfg(not(feature = "dim3"))]
    return [w.a, w.b];
    #[cfg(feature = "dim3")]
    return [w.a, w.b, w.c, w.b + w.c - w.a];
}

/// A particle closer to a wall than this fraction of ds gets no ghost across it. A
/// particle placed exactly on a wall coincides with its mirror image, and the ghost
/// doubled the mass there: still water with a row of particles on the bottom was
/// pushed up by twice that row's pressure and sloshed at 1.2 m/s within 0.1 s
/// (docs/validation.md, "Hard cases").
const ON_WALL: f64 = 1e-6;

/// Fluid particles per parallel chunk when finding the ghosts.
const CHUNK: usize = 1024;

/// One ghost to place: its source and the walls it is mirrored across (a third at a
/// vertex, in 3D).
#[derive(Clone, Copy)]
struct Image {
    source: u32,
    first: u16,
    second: Option<u16>,
    #[cfg(feature = "dim3")]
    third: Option<u16>,
}

impl Image {
    /// The walls it is mirrored across, in order.
    fn walls(&self) -> impl Iterator<Item = u16> {
        let more = self.second;
        #[cfg(feature = "dim3")]
        let more = more.into_iter().chain(self.third);
        std::iter::once(self.first).chain(more)
    }
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
        #[cfg(feature = "dim3")]
        if self.params.slip == Slip::NoSlip {
            return Err(SetupError::new(
                "ghost_walls",
                "`slip: NoSlip` is not yet built in 3D: use `slip: FreeSlip`",
            ));
        }
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
            #[cfg(feature = "dim3")]
            e.u32(img.third.map_or(u32::MAX, u32::from));
        }
        let (n_fluid, walls) = self
            .built
            .as_ref()
            .map_or((u64::MAX, &[][..]), |(n, w)| (*n as u64, &w[..]));
        e.u64(n_fluid);
        e.u64(walls.len() as u64);
        for corners in walls {
            for v in corners.iter().flat_map(|p| p.to_array()) {
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
            #[cfg(feature = "dim3")]
            let third = d.u32()?;
            let wall = |w: u32| {
                u16::try_from(w)
                    .map_err(|_| sph_core::StateError::Mismatch(format!("ghost wall {w}")))
            };
            self.images.push(Image {
                source: 0,
                first: wall(first)?,
                second: (second != u32::MAX).then(|| wall(second)).transpose()?,
                #[cfg(feature = "dim3")]
                third: (third != u32::MAX).then(|| wall(third)).transpose()?,
            });
        }
        let n_fluid = d.u64()?;
        let count = d.len(8 * sph_core::dim::DIM * POINTS)?;
        let mut walls = Vec::with_capacity(count);
        for _ in 0..count {
            let mut corners = [Vector::ZERO; POINTS];
            for p in &mut corners {
                for k in 0..sph_core::dim::DIM {
                    p[k] = d.f64()?;
                }
            }
            walls.push(corners);
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
            self.walls.now().iter().map(points).collect(),
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
            && walls.iter().zip(self.walls.now()).all(|(then, w)| {
                then.iter()
                    .zip(points(w))
                    .all(|(p, q)| p.distance(q) <= half)
            })
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
            ns.resize(images.len(), Default::default());
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
        no_slip: Option<&mut [Vector]>,
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
        let corners = self.walls.corners();
        // A solid's edges the fluid flows around (a box's): see `owned`.
        let edges = corners.iter().any(|c| !c.convex);
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
                for k in img.walls() {
                    let k = k as usize;
                    active &= near(&lines[k], fx[s].0);
                    vel = mirror_velocity(&lines[k], &walls[k], pos, vel, Slip::FreeSlip);
                    pos = lines[k].mirror(pos);
                }
                active &= !edges || owned(lines, corners, img, pos);
                x.0 = pos;
                v.0 = vel;
                m.0 = if active { fm[s].0 } else { 0.0 };
                let body = walls[img.first as usize].body;
                rho.0 = ghost_density(fr[s].0, fx[s].0, pos, correction.map(|c| (c, body)));
            });
        // 3D: refused at setup.
        #[cfg(not(feature = "dim3"))]
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
                    for k in img.walls() {
                        let k = k as usize;
                        vel = mirror_velocity(&lines[k], &walls[k], pos, vel, Slip::NoSlip);
                        pos = lines[k].mirror(pos);
                    }
                    *out = vel;
                });
        }
        #[cfg(feature = "dim3")]
        let _ = no_slip;
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
        // In 3D, the vertices: three walls each pair of which meets at an edge.
        #[cfg(feature = "dim3")]
        let vertices: Vec<[usize; 3]> = corners
            .iter()
            .flat_map(|c| {
                corners.iter().filter_map(move |d| {
                    let meets = |u: usize, v: usize| {
                        corners
                            .iter()
                            .any(|e| (e.first, e.second) == (u.min(v), u.max(v)))
                    };
                    (d.first == c.first && d.second > c.second && meets(c.second, d.second))
                        .then_some([c.first, c.second, d.second])
                })
            })
            .collect();
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
                                #[cfg(feature = "dim3")]
                                third: None,
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
                                #[cfg(feature = "dim3")]
                                third: None,
                            });
                        }
                    }
                    #[cfg(feature = "dim3")]
                    for &[a, b, v] in &vertices {
                        if [a, b, v].iter().all(|&k| near(&lines[k], x.0)) {
                            out.push(Image {
                                source,
                                first: a as u16,
                                second: Some(b as u16),
                                third: Some(v as u16),
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
fn near_rule(sim: &Sim, skin: f64) -> impl Fn(&WallLine, Vector) -> bool + Sync {
    let support = sim.constants.support();
    let on_wall = ON_WALL * sim.constants.spacing;
    move |w: &WallLine, x: Vector| {
        let (d, s) = (w.distance(x), w.abscissa(x));
        let over = s >= -skin && s <= w.length + skin;
        #[cfg(feature = "dim3")]
        let over = over && {
            let t = (x - w.a).dot(w.across);
            t >= -skin && t <= w.breadth + skin
        };
        d > on_wall - skin && d < support + skin && over
    }
}

/// Whether a ghost at `g`, mirrored across `img`'s walls, lies in the part of the solid
/// those walls own. Inside a solid's edge that the fluid flows around (two walls
/// meeting with the fluid outside the angle, a [`Corner`] that is not convex: a box's
/// edge) the mirror images of both walls' fluid overlap, and filled by both the edge's
/// inside weighed twice: each point of it is kept for the wall whose plane is nearer
/// (the bisector splits it; on it, the first wall's), so it is filled once.
fn owned(lines: &[WallLine], corners: &[Corner], img: &Image, g: Vector) -> bool {
    let across = |w: usize| img.walls().any(|k| k as usize == w);
    corners.iter().filter(|c| !c.convex).all(|c| {
        let (a, b) = (c.first, c.second);
        let (da, db) = (lines[a].distance(g), lines[b].distance(g));
        match (across(a), across(b)) {
            // On the bisector itself, the first wall's.
            (true, false) => !(db < 0.0 && db > da),
            (false, true) => !(da < 0.0 && da >= db),
            _ => true,
        }
    })
}

/// Velocity of the ghost of a particle at `x` moving at `v`, mirrored across wall `w`
/// (`line` its geometry) relative to the wall's velocity at the particle's foot on it.
fn mirror_velocity(line: &WallLine, w: &WallPose, x: Vector, v: Vector, slip: Slip) -> Vector {
    let n = line.normal;
    let vw = w.velocity_at(x - line.distance(x) * n);
    match slip {
        Slip::FreeSlip => v - 2.0 * (v - vw).dot(n) * n,
        Slip::NoSlip => 2.0 * vw - v,
    }
}

/// The linear part of a ghost's `Velocity` mirror (see [`GhostReflections`]): the
/// product of each crossed wall's I - 2 n n^T, the linear part of [`mirror_velocity`]
/// with free slip, row by row.
fn reflection(lines: &[WallLine], img: &Image) -> [f64; DIM * DIM] {
    let mut m = [0.0; DIM * DIM];
    for r in 0..DIM {
        m[r * DIM + r] = 1.0;
    }
    for k in img.walls() {
        let n = lines[k as usize].normal;
        // L = I - 2 n n^T, then m = L m (each entry summed from its first product, as
        // written out by hand before: the 2D products are unchanged).
        let l = |r: usize, c: usize| match r == c {
            true => 1.0 - 2.0 * n[r] * n[c],
            false => -2.0 * n[r] * n[c],
        };
        let mut next = [0.0; DIM * DIM];
        for r in 0..DIM {
            for c in 0..DIM {
                next[r * DIM + c] =
                    (1..DIM).fold(l(r, 0) * m[c], |s, q| s + l(r, q) * m[q * DIM + c]);
            }
        }
        m = next;
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

#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use glam::DVec2;

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

    /// Fluid particles in the middle of [`turning_box`] ahead of the others, so that
    /// those near the walls are beyond the first parallel chunk.
    const PAD: usize = CHUNK + 76;

    /// A 0.3 m x 0.2 m box turned 0.3 rad, displaced, and translating, turning and
    /// accelerating both ways, with fluid particles (given in the tank frame) by its
    /// walls and corners, one on the floor, one just off it, one beyond the support and
    /// within the support and the skin of the floor; [`PAD`] particles in the middle
    /// first.
    fn turning_box() -> (Sim, sph_core::motion::Pose) {
        use sph_core::motion::{Pose, RigidState};
        let pose = Pose {
            pivot: DVec2::new(0.15, 0.0),
            state: RigidState {
                angle: 0.3,
                omega: -0.8,
                alpha: 2.5,
                offset: DVec2::new(0.02, -0.01),
                velocity: DVec2::new(0.3, 0.1),
                acceleration: DVec2::new(-1.2, 0.7),
            },
        };
        let mut world = hecs::World::new();
        crate::testing::closed_polygon(
            &mut world,
            &[(0.0, 0.0), (0.3, 0.0), (0.3, 0.2), (0.0, 0.2)],
            |_| pose,
        );
        for wall in world.query_mut::<&mut WallPose>() {
            (wall.a, wall.b) = (pose.to_world(wall.a), pose.to_world(wall.b));
        }
        let at = [
            (0.005, 0.006), // the bottom left corner
            (0.15, 0.004),  // the floor
            (0.296, 0.1),   // the right wall
            (0.004, 0.197), // the top left corner
            (0.15, 0.1),    // far from every wall
            (0.15, 5e-9),   // on the floor: no ghost
            (0.12, 0.027),  // 0.001 beyond the support (0.026) of the floor
            (0.291, 0.185), // the top right corner, across both walls
            (0.2, 5e-5),    // 5e-3 ds off the floor: a ghost
        ];
        let middle = std::iter::repeat_n(&(0.15, 0.1), PAD);
        for (k, &(x, y)) in middle.chain(&at).enumerate() {
            let k = (k % 11) as f64;
            world.spawn((
                Fluid,
                Position(pose.to_world(DVec2::new(x, y))),
                Velocity(DVec2::new(0.1 * k - 0.3, 0.2 - 0.05 * k)),
                Density(995.0 + 2.0 * k),
                Pressure(0.0),
                Mass(0.1 + 0.01 * k),
            ));
        }
        (crate::testing::sim(world), pose)
    }

    /// What one ghost should be, from the module docs' formulas: the source mirrored
    /// across each wall in turn (x - 2 d n, n the wall's unit normal into the fluid),
    /// the velocity's normal part relative to the wall's velocity v_w at the foot
    /// reversed (no slip: 2 v_w - v), the source's density carried to p_source +
    /// rho_0 (g - a_w) . (x_ghost - x_source) on Tait (a_w the body's acceleration at
    /// the source), the source's mass.
    struct Expected {
        source: usize,
        walls: Vec<usize>,
        x: DVec2,
        v: DVec2,
        no_slip: DVec2,
        rho: f64,
        /// The product of the walls' I - 2 n n^T.
        reflection: [f64; 4],
    }

    fn expected(sim: &Sim, pose: &sph_core::motion::Pose, hydrostatic: bool) -> Vec<Expected> {
        let fluid = archetype::<Fluid>(&sim.world).unwrap();
        let fx = column::<Position>(fluid).unwrap();
        let fv = column::<Velocity>(fluid).unwrap();
        let fr = column::<Density>(fluid).unwrap();
        let walls: Vec<(DVec2, DVec2)> = {
            let mut w: Vec<(hecs::Entity, DVec2, DVec2)> = sim
                .world
                .query::<(hecs::Entity, &WallPose)>()
                .iter()
                .map(|(e, w)| (e, w.a, w.b))
                .collect();
            w.sort_by_key(|w| w.0.id());
            w.iter().map(|w| (w.1, w.2)).collect()
        };
        let normal = |k: usize| (walls[k].1 - walls[k].0).perp().normalize();
        let support = 0.026;
        let near = |k: usize, x: DVec2| {
            let (a, b) = walls[k];
            let d = (x - a).dot(normal(k));
            let s = (x - a).dot((b - a).normalize());
            d > 1e-8 && d < support && s >= 0.0 && s <= (b - a).length()
        };
        // Tait with the test sim's water: B = rho_0 c_0^2 / gamma.
        let (rho0, gamma) = (1000.0, 7.0);
        let b = rho0 * 400.0 / gamma;
        let pressure = |rho: f64| b * ((rho / rho0).powf(gamma) - 1.0);
        let density = |p: f64| rho0 * (1.0 + p / b).powf(1.0 / gamma);
        let g = DVec2::new(0.0, -9.81);
        let mut out = Vec::new();
        for s in 0..fx.len() {
            let singles = (0..4).filter(|&k| near(k, fx[s].0)).map(|k| vec![k]);
            // The box's corners, by first wall then second.
            let doubles = [(0, 1), (0, 3), (1, 2), (2, 3)]
                .into_iter()
                .filter(|&(a, b)| near(a, fx[s].0) && near(b, fx[s].0))
                .map(|(a, b)| vec![a, b]);
            for ws in singles.chain(doubles).collect::<Vec<_>>() {
                let (mut x, mut v, mut no_slip) = (fx[s].0, fv[s].0, fv[s].0);
                let mut reflection = [1.0, 0.0, 0.0, 1.0];
                for &k in &ws {
                    let n = normal(k);
                    let d = (x - walls[k].0).dot(n);
                    let vw = pose.velocity_at(x - d * n);
                    v -= 2.0 * (v - vw).dot(n) * n;
                    no_slip = 2.0 * vw - no_slip;
                    x -= 2.0 * d * n;
                    let l = [
                        1.0 - 2.0 * n.x * n.x,
                        -2.0 * n.x * n.y,
                        -2.0 * n.x * n.y,
                        1.0 - 2.0 * n.y * n.y,
                    ];
                    let m = reflection;
                    reflection = [
                        l[0] * m[0] + l[1] * m[2],
                        l[0] * m[1] + l[1] * m[3],
                        l[2] * m[0] + l[3] * m[2],
                        l[2] * m[1] + l[3] * m[3],
                    ];
                }
                let g_eff = g - pose.acceleration_at(fx[s].0);
                let rho = if hydrostatic {
                    density(pressure(fr[s].0) + rho0 * g_eff.dot(x - fx[s].0))
                } else {
                    fr[s].0
                };
                out.push(Expected {
                    source: s,
                    walls: ws,
                    x,
                    v,
                    no_slip,
                    rho,
                    reflection,
                });
            }
        }
        out
    }

    /// Checks the world's ghosts against [`expected`]; `skin`: the ghosts were found
    /// with lasting lists, so a source beyond the support (but within the skin) has a
    /// weightless ghost.
    fn check_ghosts(sim: &Sim, pose: &sph_core::motion::Pose, hydrostatic: bool, no_slip: bool) {
        let want = expected(sim, pose, hydrostatic);
        let ghost = archetype::<Ghost>(&sim.world).unwrap();
        let fluid = archetype::<Fluid>(&sim.world).unwrap();
        let fm = column::<Mass>(fluid).unwrap();
        let (gs, gw) = (
            column::<Ghost>(ghost).unwrap(),
            column::<MirrorWall>(ghost).unwrap(),
        );
        let (gx, gv) = (
            column::<Position>(ghost).unwrap(),
            column::<Velocity>(ghost).unwrap(),
        );
        let (gr, gm) = (
            column::<Density>(ghost).unwrap(),
            column::<Mass>(ghost).unwrap(),
        );
        assert_eq!(gs.len(), want.len());
        let entities = Walls::of(&sim.world).entities().to_vec();
        let close = |a: DVec2, b: DVec2| (a - b).length() < 1e-12;
        let reflections = sim.resources.get::<GhostReflections>().unwrap();
        let signs = sim.resources.get::<NoSlipSigns>();
        let columns = sim.resources.get::<Columns>();
        let ns = columns.and_then(|c| c.get::<NoSlipVelocity>());
        assert_eq!(ns.is_some(), no_slip);
        assert_eq!(signs.is_some(), no_slip);
        for (k, e) in want.iter().enumerate() {
            assert_eq!(gs[k].source as usize, e.source, "ghost {k}");
            assert_eq!(gw[k].0, entities[e.walls[0]], "ghost {k}");
            assert!(
                close(gx[k].0, e.x),
                "ghost {k}: x {} against {}",
                gx[k].0,
                e.x
            );
            assert!(
                close(gv[k].0, e.v),
                "ghost {k}: v {} against {}",
                gv[k].0,
                e.v
            );
            assert!(
                (gr[k].0 - e.rho).abs() < 1e-9,
                "ghost {k}: rho {} against {}",
                gr[k].0,
                e.rho
            );
            assert_eq!(gm[k].0, fm[e.source].0, "ghost {k}");
            for (a, b) in reflections.0[k].iter().zip(e.reflection) {
                assert!((a - b).abs() < 1e-12, "ghost {k}: {:?}", reflections.0[k]);
            }
            if let (Some(ns), Some(signs)) = (ns, signs) {
                assert!(
                    close(ns[k], e.no_slip),
                    "ghost {k}: {} against {}",
                    ns[k],
                    e.no_slip
                );
                let sign = if e.walls.len() == 2 { 1.0 } else { -1.0 };
                assert_eq!(signs.0[k], sign);
            }
        }
    }

    /// Every ghost is its formula (see [`Expected`]) in a moving, turned box, for each
    /// slip and with and without the hydrostatic correction; a step on which fewer are
    /// needed drops the surplus, and the rest are still their formulas.
    #[test]
    fn the_ghosts_are_their_formulas() {
        for (slip, hydrostatic) in [("FreeSlip", true), ("NoSlip", true), ("NoSlip", false)] {
            let (mut sim, pose) = turning_box();
            sim.resources.insert(GhostReflections::default());
            let params = format!("(slip: {slip}, hydrostatic: {hydrostatic})");
            let mut stages = crate::testing::pipeline(&mut sim, &[("ghost_walls", &params)]);
            stages[0].run(&mut sim).unwrap();
            let no_slip = slip == "NoSlip";
            check_ghosts(&sim, &pose, hydrostatic, no_slip);
            let want = expected(&sim, &pose, hydrostatic);
            let doubles = want.iter().filter(|e| e.walls.len() == 2).count();
            // The three corners' 2 + 1 each, and one for each of the two particles by
            // the floor and the one by the right wall.
            assert_eq!((want.len(), doubles), (12, 3));
            // The corner particle moves to the middle: its three ghosts go.
            {
                let fluid = archetype::<Fluid>(&sim.world).unwrap();
                column_mut::<Position>(fluid).unwrap()[PAD].0 = pose.to_world(DVec2::new(0.1, 0.1));
            }
            stages[0].run(&mut sim).unwrap();
            assert_eq!(count::<Ghost>(&sim.world), 9);
            check_ghosts(&sim, &pose, hydrostatic, no_slip);
        }
    }

    /// With lasting lists the ghosts are found within the support and the skin: a
    /// source beyond the support gets a ghost without mass, which takes the source's
    /// mass once it comes within the support (on a step that keeps the ghosts).
    #[test]
    fn a_ghost_found_within_the_skin_weighs_once_its_source_is_near() {
        let (mut sim, pose) = turning_box();
        // By the floor's start, 0.002 from the left wall's end (the floor's corner),
        // within the skin of it along that wall.
        sim.world.spawn((
            Fluid,
            Position(pose.to_world(DVec2::new(0.006, 0.002))),
            Velocity(DVec2::ZERO),
            Density(1000.0),
            Pressure(0.0),
            Mass(0.1),
        ));
        sim.resources.insert(Neighbours {
            skin: 0.004,
            ..Default::default()
        });
        let mut walls = stage();
        walls.setup(&mut sim).unwrap();
        walls.run(&mut sim).unwrap();
        let ghost_of = |sim: &Sim, s: u32| -> (usize, f64) {
            let ghost = archetype::<Ghost>(&sim.world).unwrap();
            let gs = column::<Ghost>(ghost).unwrap();
            let k = gs.iter().position(|g| g.source == s).unwrap();
            (k, column::<Mass>(ghost).unwrap()[k].0)
        };
        // Particle 6, 0.001 beyond the floor's support, within its skin.
        // The 12 of a finding without skin, particle 6's and the one on the floor's
        // (closer than the on-wall distance), both weightless, and the last one's
        // three (the floor, the left wall and their corner).
        let (five, six) = (PAD as u32 + 5, PAD as u32 + 6);
        assert_eq!(ghost_of(&sim, six).1, 0.0);
        assert_eq!(ghost_of(&sim, five).1, 0.0);
        assert_eq!(
            ghost_of(&sim, PAD as u32 + 8).1,
            0.1 + 0.01 * ((PAD + 8) % 11) as f64
        );
        assert_eq!(count::<Ghost>(&sim.world), 17);
        // It comes 0.0015 closer, within the support (less than half the skin: the
        // ghosts are kept), and its ghost now weighs its mass at the mirrored place.
        let fluid = archetype::<Fluid>(&sim.world).unwrap();
        let fpos: Vec<DVec2> = column::<Position>(fluid)
            .unwrap()
            .iter()
            .map(|p| p.0)
            .collect();
        let gpos: Vec<DVec2> = {
            let ghost = archetype::<Ghost>(&sim.world).unwrap();
            column::<Position>(ghost)
                .unwrap()
                .iter()
                .map(|p| p.0)
                .collect()
        };
        let nb = sim.resources.get_mut::<Neighbours>().unwrap();
        (nb.n_fluid, nb.n_ghost) = (fpos.len(), gpos.len());
        nb.built_at = fpos.iter().chain(&gpos).copied().collect();
        nb.plan = ListPlan::Undecided;
        let moved = pose.to_world(DVec2::new(0.12, 0.0255));
        column_mut::<Position>(fluid).unwrap()[PAD + 6].0 = moved;
        walls.run(&mut sim).unwrap();
        assert_eq!(
            sim.resources.get::<Neighbours>().unwrap().plan,
            ListPlan::Keep
        );
        let (k, m) = ghost_of(&sim, six);
        assert_eq!(m, 0.1 + 0.01 * ((PAD + 6) % 11) as f64);
        let ghost = archetype::<Ghost>(&sim.world).unwrap();
        let x = column::<Position>(ghost).unwrap()[k].0;
        let floor = Walls::of(&sim.world).lines()[0];
        assert!((x - floor.mirror(moved)).length() < 1e-12);
    }

    /// The ghosts found last serve while the fluid and ghost counts and the walls are
    /// those of the finding, and no wall end has moved half the skin.
    #[test]
    fn the_ghosts_are_kept_only_while_nothing_changed() {
        let mut sim = boxed();
        let skin = 0.004;
        let mut walls = stage();
        walls.setup(&mut sim).unwrap();
        assert!(!walls.kept(&sim, skin), "nothing found yet");
        walls.run(&mut sim).unwrap();
        let kept = |walls: &mut GhostWalls, sim: &Sim| {
            walls.walls.read(&sim.world);
            walls.kept(sim, skin)
        };
        assert!(kept(&mut walls, &sim));
        // A wall's end moved just under and just over half the skin, either end.
        let floor = Walls::of(&sim.world).entities()[0];
        for (by, kept_then) in [(0.0019, true), (0.0021, false)] {
            for end in [0, 1] {
                let mut w = sim.world.get::<&mut WallPose>(floor).unwrap();
                let at = if end == 0 { &mut w.a } else { &mut w.b };
                at.x += by;
                drop(w);
                assert_eq!(kept(&mut walls, &sim), kept_then, "end {end} by {by}");
                let mut w = sim.world.get::<&mut WallPose>(floor).unwrap();
                let at = if end == 0 { &mut w.a } else { &mut w.b };
                at.x -= by;
            }
        }
        assert!(kept(&mut walls, &sim));
        // One more fluid particle, one more ghost, one more wall: found anew.
        let extra = sim.world.spawn((
            Fluid,
            Position(DVec2::new(0.2, 0.2)),
            Velocity(DVec2::ZERO),
            Density(1000.0),
            Pressure(0.0),
            Mass(0.1),
        ));
        assert!(!kept(&mut walls, &sim));
        sim.world.despawn(extra).unwrap();
        assert!(kept(&mut walls, &sim));
        resize_pool(&mut sim.world, walls.images.len() + 1);
        assert!(!kept(&mut walls, &sim));
        resize_pool(&mut sim.world, walls.images.len());
        assert!(kept(&mut walls, &sim));
        crate::testing::closed_polygon(
            &mut sim.world,
            &[(0.1, 0.1), (0.2, 0.1), (0.2, 0.2)],
            |_| Default::default(),
        );
        assert!(!kept(&mut walls, &sim));
    }

    /// Setup refuses a scene without walls, shares the hydrostatic setting, and with
    /// walls that do not slip provides the no-slip velocities and signs.
    #[test]
    fn setup_shares_the_settings_and_the_no_slip_columns() {
        let mut sim = crate::testing::sim(hecs::World::new());
        let e = stage().setup(&mut sim).unwrap_err().to_string();
        assert!(e.contains("no walls"), "{e}");
        for (slip, hydrostatic) in [(Slip::FreeSlip, false), (Slip::NoSlip, true)] {
            let mut sim = boxed();
            GhostWalls::new(Params { slip, hydrostatic })
                .setup(&mut sim)
                .unwrap();
            let settings = sim.resources.get::<GhostSettings>().unwrap();
            assert_eq!(settings.hydrostatic, hydrostatic);
            let no_slip = slip == Slip::NoSlip;
            assert_eq!(sim.resources.contains::<NoSlipSigns>(), no_slip);
            let columns = sim.resources.get::<Columns>();
            assert_eq!(
                columns.is_some_and(|c| c.contains::<NoSlipVelocity>()),
                no_slip
            );
        }
    }
}
