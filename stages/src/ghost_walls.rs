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
//! Moving walls (a rolling tank): walls are mirrored where they are at the current
//! time, and velocities are mirrored relative to the wall's own velocity v_w at the
//! foot of the particle on the wall: free slip reverses the normal component of
//! v - v_w, no slip gives 2 v_w - v. The hydrostatic correction uses the effective
//! gravity g - a_w of the tank frame, a_w the tank's rigid acceleration at the source.

use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Ghost, Mass, Position, Pressure, Velocity};
use sph_core::contract::Access;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{
    ghost_density, GhostReflections, GhostSettings, MirrorWall, WallPose, Walls,
};
use sph_core::walls::WallLine;
use sph_core::world::{archetype, column, column_mut, count};
use sph_core::StageRegistry;

/// Tangential velocity condition at the walls.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Slip {
    /// Tangential velocity mirrored unchanged (no wall shear).
    FreeSlip,
    /// Tangential velocity reversed (zero velocity at the wall).
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
    registry.register(
        "ghost_walls",
        "mirror fluid particles across the walls as ghost particles",
        |p: Params| {
            Ok(GhostWalls {
                params: p,
                walls: Walls::default(),
                images: Vec::new(),
                chunks: Vec::new(),
            })
        },
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
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        // The walls where the world has them now (the scene moves with the clock).
        self.walls.read(&sim.world);
        self.find_images(sim)?;
        let _span = tracing::info_span!("mirror").entered();
        let images = &self.images[..];
        // Only when a stage asked for them (the DFSPH solves).
        if let Some(r) = sim.resources.get_mut::<GhostReflections>() {
            let (lines, slip) = (self.walls.lines(), self.params.slip);
            r.0.clear();
            r.0.extend(images.iter().map(|img| reflection(lines, img, slip)));
        }
        resize_pool(&mut sim.world, images.len());
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
        let correction = self
            .params
            .hydrostatic
            .then_some((sim.constants.eos, sim.constants.gravity));
        let (walls, lines) = (self.walls.now(), self.walls.lines());
        let entities = self.walls.entities();
        let slip = self.params.slip;
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
                let s = img.source as usize;
                let (mut pos, mut vel) = (fx[s].0, fv[s].0);
                for k in std::iter::once(img.first).chain(img.second) {
                    let k = k as usize;
                    vel = mirror_velocity(&lines[k], &walls[k], pos, vel, slip);
                    pos = lines[k].mirror(pos);
                }
                *g = Ghost { source: img.source };
                *wall = MirrorWall(entities[img.first as usize]);
                x.0 = pos;
                v.0 = vel;
                m.0 = fm[s].0;
                let body = walls[img.first as usize].body;
                rho.0 = ghost_density(fr[s].0, fx[s].0, pos, correction.map(|c| (c, body)));
            });
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
            .writes::<Ghost>()
            .writes::<MirrorWall>()
            .writes::<GhostSettings>()
            .writes::<GhostReflections>()
    }
}

impl GhostWalls {
    /// Fills `images` with the ghosts this step needs, in a fixed order (by source,
    /// then wall), reusing the per-chunk buffers from step to step.
    fn find_images(&mut self, sim: &Sim) -> Result<(), StepError> {
        let _span = tracing::info_span!("find_images").entered();
        self.images.clear();
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let pos = column::<Position>(fluid)?;
        let support = sim.constants.support();
        let on_wall = ON_WALL * sim.constants.spacing;
        let lines = self.walls.lines();
        let corners = self.walls.corners();
        // A particle on the wall (closer than `on_wall`) is its own mirror image: a
        // ghost there would count its mass twice for its neighbours.
        let near = |w: &WallLine, x: DVec2| {
            let (d, s) = (w.distance(x), w.abscissa(x));
            d > on_wall && d < support && s >= 0.0 && s <= w.length
        };
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

/// The linear part of a ghost's velocity mirror (see [`GhostReflections`]): the
/// product of each crossed wall's, I - 2 n n^T for free slip and -I for no slip, the
/// linear parts of [`mirror_velocity`].
fn reflection(lines: &[WallLine], img: &Image, slip: Slip) -> [f64; 4] {
    let mut m = [1.0, 0.0, 0.0, 1.0];
    for k in std::iter::once(img.first).chain(img.second) {
        let n = lines[k as usize].normal;
        let l = match slip {
            Slip::FreeSlip => [
                1.0 - 2.0 * n.x * n.x,
                -2.0 * n.x * n.y,
                -2.0 * n.y * n.x,
                1.0 - 2.0 * n.y * n.y,
            ],
            Slip::NoSlip => [-1.0, 0.0, 0.0, -1.0],
        };
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
