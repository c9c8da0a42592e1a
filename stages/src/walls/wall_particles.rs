//! Fixed wall particles (Adami, Hu & Adams 2012, "A generalized wall boundary condition
//! for smoothed particle hydrodynamics", J. Comput. Phys. 231; docs/physics.md, "Walls:
//! fixed wall particles").
//!
//! Layers of particles on the lattice spacing ds fill a band behind every wall, one
//! kernel support deep, and the square behind both walls of every convex corner where
//! the two ride the same body. They ride with their wall's body (a rolling tank, a
//! piston): each step they are placed where the body now carries them and take its
//! velocity there. Their pressure is extrapolated from the fluid by `WallPressure`
//! (`wall_pressure.rs`, Adami et al. eq. 27).
//!
//! Why not mirror images: a mirror coincides with its source on the wall, where every
//! kernel gradient vanishes, so a particle that reaches a mirrored wall with speed
//! along its normal passes through. A wall particle stays half a spacing behind the
//! wall, where the gradient is near its largest, whatever the fluid particle does.
//!
//! Wall particles live in the ghost archetype, so every pair term sees them as it sees
//! mirrored ghosts; they have no source (`Ghost::WALL_PARTICLE`). Walls with fluid on
//! both sides (a thin baffle) are not supported: the band fills the back side. The
//! DFSPH solves carry pressures and velocities through their ghosts' sources and read
//! `GhostReflections`, which only `GhostWalls` writes, so the loader refuses them with
//! wall particles.

use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Ghost, Mass, MirrorWall, Position, Pressure, Velocity, Wall};
use sph_core::contract::Access;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{WallPose, Walls};
use sph_core::walls::WallLine;
use sph_core::world::{archetype, column_mut, count};
use sph_core::{ParamError, StageRegistry};

#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Layers of wall particles behind each wall. Default (None): as many as fill one
    /// kernel support, ceil(support / ds), so a fluid particle on the wall sees a full
    /// kernel.
    pub layers: Option<u32>,
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "wall_particles",
        "fixed wall particles behind the walls, riding with them (Adami et al. 2012)",
        |p: Params| {
            if p.layers == Some(0) {
                return Err(ParamError::new(
                    "layers",
                    0,
                    "a whole number of at least 1, or leave it out for one kernel support",
                ));
            }
            Ok(WallParticles {
                layers: p.layers,
                sites: Vec::new(),
                walls: Walls::default(),
            })
        },
    );
}

/// Where one wall particle sits: on wall `wall` (index in [`Walls`] order), at `rest`
/// in the frame of the body that wall rides on.
#[derive(Clone, Copy, Debug)]
struct Site {
    wall: usize,
    rest: DVec2,
}

pub struct WallParticles {
    layers: Option<u32>,
    sites: Vec<Site>,
    /// The walls now (re-read every step; a reused buffer).
    walls: Walls,
}

impl Stage for WallParticles {
    fn name(&self) -> &'static str {
        "wall_particles"
    }

    /// The particles are laid out again from the scene at setup; a checkpoint holds
    /// their columns (the ghost archetype), and their places follow from the clock.
    fn resumes_between_runs(&self) -> bool {
        true
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        self.walls.read(&sim.world);
        if self.walls.is_empty() {
            return Err(SetupError::new(
                "wall_particles",
                "the scenario has no walls; remove WallParticles() or add a `tank` or `walls`",
            ));
        }
        if count::<Ghost>(&sim.world) > 0 {
            return Err(SetupError::new(
                "wall_particles",
                "the world already holds ghost particles: use either GhostWalls() or WallParticles(), not both",
            ));
        }
        let c = &sim.constants;
        let ds = c.spacing;
        let layers = match self.layers {
            Some(n) => n as usize,
            None => (c.support() / ds).ceil() as usize,
        };
        let rest = rest_walls(&sim.world);
        let (sites, volumes) = lay_out(&rest, &self.walls, ds, layers);
        self.sites = sites;
        let rho0 = c.eos.rho0;
        let entities = self.walls.entities().to_vec();
        sim.world
            .spawn_batch(self.sites.iter().zip(volumes).map(|(s, v)| {
                (
                    Ghost {
                        source: Ghost::WALL_PARTICLE,
                    },
                    Position(s.rest),
                    Velocity::default(),
                    Density(rho0),
                    Pressure(0.0),
                    Mass(rho0 * v),
                    MirrorWall(entities[s.wall]),
                )
            }));
        self.place(sim)
            .map_err(|e| SetupError::new("wall_particles", e.to_string()))
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        self.place(sim)
    }

    /// Places the wall particles where their walls' bodies now carry them, with the
    /// bodies' velocity there.
    fn access(&self) -> Access {
        Access::new().reads::<WallPose>().writes::<Ghost>()
    }
}

impl WallParticles {
    fn place(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        self.walls.read(&sim.world);
        let Some(ghost) = archetype::<Ghost>(&sim.world) else {
            return Ok(());
        };
        let mut x = column_mut::<Position>(ghost)?;
        let mut v = column_mut::<Velocity>(ghost)?;
        if x.len() != self.sites.len() {
            return Err(StepError::Internal(format!(
                "{} ghost particles for {} wall particles: WallParticles owns the ghosts",
                x.len(),
                self.sites.len()
            )));
        }
        let now: &[WallPose] = self.walls.now();
        let placed: Vec<_> = now.iter().map(|w| w.body.placement()).collect();
        (&mut x[..], &mut v[..], &self.sites[..])
            .into_par_iter()
            .for_each(|(x, v, s)| {
                x.0 = placed[s.wall].to_world(s.rest);
                v.0 = now[s.wall].body.velocity_at(x.0);
            });
        Ok(())
    }
}

/// The walls at rest, in the body frames, in [`Walls`] order (by entity).
fn rest_walls(world: &hecs::World) -> Vec<WallPose> {
    let mut rest: Vec<(hecs::Entity, WallPose)> = world
        .query::<(hecs::Entity, &Wall)>()
        .iter()
        .map(|(e, w)| (e, w.at_rest()))
        .collect();
    rest.sort_by_key(|(e, _)| e.id());
    rest.into_iter().map(|(_, w)| w).collect()
}

/// The wall particles' sites and volumes [m^2]: for each wall a band of `layers`
/// rows behind it, round(length / ds) particles along it (spaced length / n, so the
/// band ends at the wall's ends), and for each convex corner of two walls on one body
/// the `layers` x `layers` parallelogram behind both, on the spacing ds along each
/// normal.
fn lay_out(rest: &[WallPose], walls: &Walls, ds: f64, layers: usize) -> (Vec<Site>, Vec<f64>) {
    let (mut sites, mut volumes) = (Vec::new(), Vec::new());
    let lines: Vec<WallLine> = rest.iter().map(WallLine::of).collect();
    for (k, line) in lines.iter().enumerate() {
        let n = ((line.length / ds).round() as usize).max(1);
        let along = line.length / n as f64;
        for i in 0..n {
            for l in 0..layers {
                sites.push(Site {
                    wall: k,
                    rest: line.a + (i as f64 + 0.5) * along * line.tangent
                        - (l as f64 + 0.5) * ds * line.normal,
                });
                volumes.push(along * ds);
            }
        }
    }
    for c in walls.corners() {
        let (a, b) = (&lines[c.first], &lines[c.second]);
        if !c.convex || rest[c.first].body != rest[c.second].body {
            continue;
        }
        let Some(meet) = intersection(a, b) else {
            continue;
        };
        let area = ds * ds * a.normal.perp_dot(b.normal).abs();
        for i in 0..layers {
            for j in 0..layers {
                sites.push(Site {
                    wall: c.first,
                    rest: meet
                        - (i as f64 + 0.5) * ds * a.normal
                        - (j as f64 + 0.5) * ds * b.normal,
                });
                volumes.push(area);
            }
        }
    }
    (sites, volumes)
}

/// Where two walls' lines cross; None for parallel lines.
fn intersection(a: &WallLine, b: &WallLine) -> Option<DVec2> {
    // a.a + s a.t on b's line: (a.a + s a.t - b.a) . b.n = 0.
    let denom = a.tangent.dot(b.normal);
    (denom.abs() > 1e-12).then(|| a.a + ((b.a - a.a).dot(b.normal) / denom) * a.tangent)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(a: (f64, f64), b: (f64, f64)) -> WallPose {
        WallPose {
            a: DVec2::new(a.0, a.1),
            b: DVec2::new(b.0, b.1),
            body: Default::default(),
        }
    }

    #[test]
    fn the_band_behind_a_box_is_filled_once_on_the_lattice() {
        let mut world = hecs::World::new();
        crate::testing::closed_box(&mut world, 0.9, 0.5);
        let walls = Walls::of(&world);
        let (ds, layers) = (0.1, 3);
        let depth = ds * layers as f64;
        let (sites, volumes) = lay_out(&rest_walls(&world), &walls, ds, layers);
        // 9 + 5 + 9 + 5 sites along the walls, 3 deep, and 3 x 3 in each corner.
        assert_eq!(sites.len(), 28 * 3 + 4 * 9);
        // The volumes tile the band exactly: (0.9 + 2 d)(0.5 + 2 d) - 0.9 x 0.5.
        let band = (0.9 + 2.0 * depth) * (0.5 + 2.0 * depth) - 0.45;
        let total: f64 = volumes.iter().sum();
        assert!((total - band).abs() < 1e-12, "{total} vs {band}");
        for (s, v) in sites.iter().zip(&volumes) {
            let x = s.rest;
            // Outside the box, within the band, half a spacing from the band's edges
            // and from the walls (cell centres of the ds lattice).
            let out = (-x.x).max(x.x - 0.9).max(-x.y).max(x.y - 0.5);
            assert!(
                out >= 0.5 * ds - 1e-12 && out <= depth - 0.5 * ds + 1e-12,
                "{x}"
            );
            assert!((v - ds * ds).abs() < 1e-15, "{x}: volume {v}");
        }
        // No two sites closer than the spacing: the corners are not filled twice.
        for (i, a) in sites.iter().enumerate() {
            for b in &sites[i + 1..] {
                assert!(a.rest.distance(b.rest) > ds - 1e-9, "{} {}", a.rest, b.rest);
            }
        }
    }

    #[test]
    fn two_lines_cross_where_both_pass() {
        let (a, b) = (
            WallLine::of(&line((0.0, 0.0), (1.0, 0.0))),
            WallLine::of(&line((0.3, 2.0), (0.3, -1.0))),
        );
        let x = intersection(&a, &b).unwrap();
        assert!((x - DVec2::new(0.3, 0.0)).length() < 1e-12, "{x}");
        let c = WallLine::of(&line((0.0, 1.0), (1.0, 1.0)));
        assert!(intersection(&a, &c).is_none());
    }
}
