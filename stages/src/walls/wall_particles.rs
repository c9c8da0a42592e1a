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

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Ghost, Mass, MirrorWall, Position, Pressure, Velocity, Wall};
use sph_core::contract::Access;
use sph_core::dim::Vector;
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
    rest: Vector,
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

/// The wall particles' sites and volumes [m^DIM] (docs/physics.md, "Walls: fixed wall
/// particles"):
/// - for each wall a band of `layers` rows behind it, round(length / ds) particles
///   along it (spaced length / n, so the band ends at the wall's ends; in 3D the same
///   across its breadth);
/// - for each convex corner of two walls on one body the `layers` x `layers`
///   parallelogram behind both, on the spacing ds along each normal (in 3D a prism of
///   them along the meeting edge);
/// - in 3D, for each vertex where three walls on one body meet pairwise convex, the
///   `layers`^3 parallelepiped behind all three.
///
/// At a reentrant corner (a step, or a box's edge seen from the water: inner angle
/// above 180 degrees) the two bands overlap behind both walls; the second wall's band
/// leaves that overlap to the first's, so it is filled once. Where the bands of two
/// walls of one body that do not meet overlap (the opposite faces of a solid thinner
/// than two bands), a site is left to the wall whose plane it is nearer, and a band
/// that would reach through a solid thinner than itself stops at its far face. A corner's
/// site that lies in a wall's band (the floor under a box standing on it) is left to
/// the band.
fn lay_out(rest: &[WallPose], walls: &Walls, ds: f64, layers: usize) -> (Vec<Site>, Vec<f64>) {
    let (mut sites, mut volumes) = (Vec::new(), Vec::new());
    let lines: Vec<WallLine> = rest.iter().map(WallLine::of).collect();
    let depth = layers as f64 * ds;
    let same_body = |j: usize, k: usize| rest[j].body == rest[k].body;
    // In wall k's band: behind its line (plane), within the band's depth, alongside it.
    let in_band = |k: usize, x: Vector| lines[k].behind(x, depth);
    let in_any_band =
        |k: usize, x: Vector| (0..lines.len()).any(|j| same_body(j, k) && in_band(j, x));
    let meet = |j: usize, k: usize| {
        let (first, second) = (j.min(k), j.max(k));
        walls
            .corners()
            .iter()
            .any(|c| c.first == first && c.second == second)
    };
    for (k, line) in lines.iter().enumerate() {
        let n = ((line.length / ds).round() as usize).max(1);
        let along = line.length / n as f64;
        #[cfg(not(feature = "dim3"))]
        let (m, volume) = (1, along * ds);
        #[cfg(feature = "dim3")]
        let (m, across) = {
            let m = ((line.breadth / ds).round() as usize).max(1);
            (m, line.breadth / m as f64)
        };
        #[cfg(feature = "dim3")]
        let volume = along * across * ds;
        // The earlier walls this one meets at a reentrant corner on the same body.
        let yields: Vec<usize> = walls
            .corners()
            .iter()
            .filter(|c| !c.convex && c.second == k && same_body(c.first, k))
            .map(|c| c.first)
            .collect();
        // The walls of the same body this one does not meet (a solid's far faces).
        let facing: Vec<usize> = (0..lines.len())
            .filter(|&j| j != k && same_body(j, k) && !meet(j, k))
            .collect();
        for i in 0..n {
            for _j in 0..m {
                for l in 0..layers {
                    let x = line.a + (i as f64 + 0.5) * along * line.tangent
                        - (l as f64 + 0.5) * ds * line.normal;
                    #[cfg(feature = "dim3")]
                    let x = x + (_j as f64 + 0.5) * across * line.across;
                    if yields.iter().any(|&f| in_band(f, x)) {
                        continue;
                    }
                    // Nearer f's plane (both distances negative behind), or as near
                    // (to round-off) and f the earlier wall.
                    let nearer = |f: usize| {
                        let (df, dk) = (lines[f].distance(x), line.distance(x));
                        df > dk + 1e-9 * ds || (df >= dk - 1e-9 * ds && f < k)
                    };
                    if facing.iter().any(|&f| in_band(f, x) && nearer(f)) {
                        continue;
                    }
                    // Through a solid thinner than the band, out in front of its far
                    // face: in the water.
                    let foot = x + (l as f64 + 0.5) * ds * line.normal;
                    if facing
                        .iter()
                        .any(|&f| lines[f].behind(foot, depth) && lines[f].distance(x) >= 0.0)
                    {
                        continue;
                    }
                    sites.push(Site { wall: k, rest: x });
                    volumes.push(volume);
                }
            }
        }
    }
    let convex: Vec<_> = walls
        .corners()
        .iter()
        .filter(|c| c.convex && same_body(c.first, c.second))
        .collect();
    for c in &convex {
        let (a, b) = (&lines[c.first], &lines[c.second]);
        // Where the corner's parallelogram starts, and how many stand along the edge
        // (3D), each how far apart.
        #[cfg(not(feature = "dim3"))]
        let (start, edge, m, along, volume) = {
            let Some(meet) = intersection(a, b) else {
                continue;
            };
            let area = ds * ds * a.normal.perp_dot(b.normal).abs();
            (meet, Vector::ZERO, 1, 0.0, area)
        };
        #[cfg(feature = "dim3")]
        let (start, edge, m, along, volume) = {
            let Some((p, q)) = c.edge_in(rest) else {
                continue;
            };
            let length = p.distance(q);
            let m = ((length / ds).round() as usize).max(1);
            let along = length / m as f64;
            let volume = ds * ds * along * a.normal.cross(b.normal).length();
            (p, (q - p).normalize_or_zero(), m, along, volume)
        };
        for e in 0..m {
            for i in 0..layers {
                for j in 0..layers {
                    let x = start + (e as f64 + 0.5) * along * edge
                        - (i as f64 + 0.5) * ds * a.normal
                        - (j as f64 + 0.5) * ds * b.normal;
                    if in_any_band(c.first, x) {
                        continue;
                    }
                    sites.push(Site {
                        wall: c.first,
                        rest: x,
                    });
                    volumes.push(volume);
                }
            }
        }
    }
    #[cfg(feature = "dim3")]
    for (f, g, h) in vertices(&convex) {
        let (a, b, c) = (&lines[f], &lines[g], &lines[h]);
        let Some(at) = vertex(a, b, c) else {
            continue;
        };
        let volume = ds * ds * ds * a.normal.dot(b.normal.cross(c.normal)).abs();
        for i in 0..layers {
            for j in 0..layers {
                for l in 0..layers {
                    let x = at
                        - (i as f64 + 0.5) * ds * a.normal
                        - (j as f64 + 0.5) * ds * b.normal
                        - (l as f64 + 0.5) * ds * c.normal;
                    if in_any_band(f, x) {
                        continue;
                    }
                    sites.push(Site { wall: f, rest: x });
                    volumes.push(volume);
                }
            }
        }
    }
    (sites, volumes)
}

/// Where two walls' lines cross; None for parallel lines.
#[cfg(not(feature = "dim3"))]
fn intersection(a: &WallLine, b: &WallLine) -> Option<Vector> {
    // a.a + s a.t on b's line: (a.a + s a.t - b.a) . b.n = 0.
    let denom = a.tangent.dot(b.normal);
    (denom.abs() > 1e-12).then(|| a.a + ((b.a - a.a).dot(b.normal) / denom) * a.tangent)
}

/// The triples of walls (f < g < h) that meet pairwise at the convex corners
/// `convex` of one body: a box tank's vertices (3D).
#[cfg(feature = "dim3")]
fn vertices(convex: &[&sph_core::walls::Corner]) -> Vec<(usize, usize, usize)> {
    let pair = |f: usize, g: usize| convex.iter().any(|c| c.first == f && c.second == g);
    let mut out = Vec::new();
    for c in convex {
        for d in convex {
            // c = (f, g), d = (f, h) with g < h, and (g, h) a convex corner too.
            if d.first == c.first && d.second > c.second && pair(c.second, d.second) {
                out.push((c.first, c.second, d.second));
            }
        }
    }
    out
}

/// The point on all three planes; None where they do not meet in one point (3D).
#[cfg(feature = "dim3")]
fn vertex(a: &WallLine, b: &WallLine, c: &WallLine) -> Option<Vector> {
    // x . n_k = a_k . n_k for each plane: Cramer's rule by triple products.
    let det = a.normal.dot(b.normal.cross(c.normal));
    let (da, db, dc) = (a.a.dot(a.normal), b.a.dot(b.normal), c.a.dot(c.normal));
    (det.abs() > 1e-12).then(|| {
        (da * b.normal.cross(c.normal)
            + db * c.normal.cross(a.normal)
            + dc * a.normal.cross(b.normal))
            / det
    })
}

#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use glam::DVec2;
    use sph_core::world::column;

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
        apart(&sites, ds);
    }

    /// Laid out at rest, and after the box has turned and moved, each wall particle
    /// sits where the body carries its rest place and moves with the body's rigid
    /// velocity there; by default the band is one kernel support deep, ceil(2h / ds)
    /// = 3 layers at h = 1.3 ds.
    #[test]
    fn the_wall_particles_ride_with_their_body() {
        let mut world = hecs::World::new();
        crate::testing::closed_box(&mut world, 0.2, 0.1);
        let mut sim = crate::testing::sim(world);
        let mut stages = crate::testing::pipeline(&mut sim, &[("wall_particles", "()")]);
        let rest: Vec<DVec2> = {
            let ghost = archetype::<Ghost>(&sim.world).unwrap();
            column::<Position>(ghost)
                .unwrap()
                .iter()
                .map(|x| x.0)
                .collect()
        };
        // 20 + 10 + 20 + 10 sites along the walls, 3 deep, and 3 x 3 in each corner.
        assert_eq!(rest.len(), 60 * 3 + 4 * 9);
        let pose = sph_core::motion::Pose {
            pivot: DVec2::new(0.1, 0.0),
            state: sph_core::motion::RigidState {
                angle: 0.3,
                omega: -0.8,
                offset: DVec2::new(0.02, -0.01),
                velocity: DVec2::new(0.3, 0.1),
                ..Default::default()
            },
        };
        for wall in sim.world.query_mut::<&mut WallPose>() {
            (wall.a, wall.b, wall.body) = (pose.to_world(wall.a), pose.to_world(wall.b), pose);
        }
        stages[0].run(&mut sim).unwrap();
        let ghost = archetype::<Ghost>(&sim.world).unwrap();
        let (x, v) = (
            column::<Position>(ghost).unwrap(),
            column::<Velocity>(ghost).unwrap(),
        );
        let ghost = archetype::<Ghost>(&sim.world).unwrap();
        for m in column::<Mass>(ghost).unwrap().iter() {
            // rho_0 times the site's volume, ds^2 in a box.
            assert!((m.0 - 1000.0 * 1e-4).abs() < 1e-12, "{}", m.0);
        }
        for k in 0..rest.len() {
            let at = pose.to_world(rest[k]);
            assert!((x[k].0 - at).length() < 1e-12, "{} against {at}", x[k].0);
            let u = pose.velocity_at(at);
            assert!((v[k].0 - u).length() < 1e-12, "{} against {u}", v[k].0);
        }
    }

    /// The stage refuses zero layers (at the field), a scene without walls, and a
    /// world that already holds ghosts (mirrors), each with what to do instead; and
    /// the contract check refuses it beside `GhostWalls`, the other writer of ghosts.
    #[test]
    fn the_stage_refuses_no_layers_no_walls_and_mirrors_already_there() {
        use sph_core::contract::{check, Breach, Quantity};
        let (walls, mirrors) = (
            crate::testing::stage("wall_particles", "()").access(),
            crate::testing::stage("ghost_walls", "()").access(),
        );
        assert!(matches!(
            check([(&mirrors, 1), (&walls, 1)]),
            Err(Breach::TwoWriters { quantity, first: 0, second: 1 }) if quantity == Quantity::of::<Ghost>()
        ));
        let e = crate::testing::built("wall_particles", "(layers: 0)")
            .err()
            .unwrap();
        assert!(e.contains("layers") && e.contains("at least 1"), "{e}");
        let mut sim = crate::testing::sim(hecs::World::new());
        let e = crate::testing::stage("wall_particles", "()")
            .setup(&mut sim)
            .unwrap_err();
        assert!(e.to_string().contains("no walls"), "{e}");
        let mut world = hecs::World::new();
        crate::testing::closed_box(&mut world, 0.2, 0.1);
        world.spawn((Ghost { source: 0 }, Position(DVec2::new(0.1, -0.005))));
        let mut sim = crate::testing::sim(world);
        let e = crate::testing::stage("wall_particles", "()")
            .setup(&mut sim)
            .unwrap_err();
        assert!(e.to_string().contains("not both"), "{e}");
    }

    /// The walls of a closed polygon through `corners` (counter-clockwise, so the
    /// fluid is inside), wall k on the body `body(k)`, with the sites and volumes
    /// `lay_out` gives them at spacing `ds`, 3 layers deep.
    fn polygon(
        corners: &[(f64, f64)],
        body: impl Fn(usize) -> sph_core::motion::Pose,
        ds: f64,
    ) -> (Vec<Site>, Vec<f64>, Walls) {
        let mut world = hecs::World::new();
        crate::testing::closed_polygon(&mut world, corners, body);
        let walls = Walls::of(&world);
        let (sites, volumes) = lay_out(&rest_walls(&world), &walls, ds, 3);
        (sites, volumes, walls)
    }

    /// No two sites closer than the spacing (nothing laid twice).
    fn apart(sites: &[Site], ds: f64) {
        for (i, a) in sites.iter().enumerate() {
            for b in &sites[i + 1..] {
                assert!(a.rest.distance(b.rest) > ds - 1e-9, "{} {}", a.rest, b.rest);
            }
        }
    }

    /// A step in the floor (an L-shaped tank): at the reentrant corner the two walls'
    /// bands overlap behind both, and the overlap is laid once; the convex corners get
    /// their 3 x 3 squares, the reentrant one none.
    #[test]
    fn a_reentrant_corner_is_filled_once() {
        let ds = 0.01;
        let corners = [
            (0.0, 0.0),
            (0.3, 0.0),
            (0.3, 0.2),
            (0.1, 0.2),
            (0.1, 0.1),
            (0.0, 0.1),
        ];
        let (sites, _, walls) = polygon(&corners, |_| Default::default(), ds);
        assert_eq!(walls.corners().iter().filter(|c| !c.convex).count(), 1);
        apart(&sites, ds);
        // 30 + 20 + 20 + 10 + 10 + 10 sites along the walls, 3 deep, less the 3 x 3
        // overlap, and 3 x 3 behind each of the five convex corners.
        assert_eq!(sites.len(), 100 * 3 - 9 + 5 * 9);
    }

    /// A corner where walls of two bodies meet (a piston standing on the floor) is not
    /// filled: its parallelogram would ride with neither.
    #[test]
    fn a_corner_of_two_bodies_is_not_filled() {
        let piston = sph_core::motion::Pose::at_rest(DVec2::new(0.3, 0.0));
        let box_ = [(0.0, 0.0), (0.2, 0.0), (0.2, 0.1), (0.0, 0.1)];
        let (sites, _, _) = polygon(
            &box_,
            |k| if k == 3 { piston } else { Default::default() },
            0.01,
        );
        // The left wall (k = 3) meets the floor and the top: two corners left out.
        assert_eq!(sites.len(), 60 * 3 + 2 * 9);
    }

    /// At a corner that is not square each corner site holds ds^2 |n_a x n_b|, the
    /// parallelogram its two normals span (a parallelogram tank, walls at 63.4 and
    /// 116.6 degrees).
    #[test]
    fn a_slanted_corner_s_sites_hold_their_parallelogram() {
        let ds = 0.01;
        let corners = [(0.0, 0.0), (0.2, 0.0), (0.25, 0.1), (0.05, 0.1)];
        let (_, volumes, walls) = polygon(&corners, |_| Default::default(), ds);
        let sine = 0.1 / 0.05f64.hypot(0.1);
        let along: usize = walls
            .lines()
            .iter()
            .map(|l| (l.length / ds).round() as usize * 3)
            .sum();
        assert_eq!(volumes.len(), along + 4 * 9);
        for v in &volumes[along..] {
            assert!(
                (v - ds * ds * sine).abs() < 1e-15,
                "{v} against {}",
                ds * ds * sine
            );
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
        // A slanted line crosses at y = 0 half-way up its rise.
        let slant = WallLine::of(&line((0.3, -1.0), (0.8, 1.0)));
        let x = intersection(&a, &slant).unwrap();
        assert!((x - DVec2::new(0.55, 0.0)).length() < 1e-12, "{x}");
        let c = WallLine::of(&line((0.0, 1.0), (1.0, 1.0)));
        assert!(intersection(&a, &c).is_none());
    }
}
