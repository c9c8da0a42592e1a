//! All the walls at once, as the world holds them now: [`Walls::read`] copies the wall
//! entities' current poses ([`WallPose`], written by [`crate::kinematics`]) in spawn
//! order, with their lines (unit normal and tangent worked out once) for the
//! per-particle tests, and the pairs of walls that meet (corners). A read-only view:
//! it works out no motion, and a stage that keeps one re-reads it from the world each
//! time it uses it (reusing its buffers).

use crate::components::{Wall, WallPose};
use crate::dim::Vector;
use hecs::{Entity, World};

/// The walls now, in spawn order (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct Walls {
    entities: Vec<Entity>,
    /// The walls now (world frame).
    now: Vec<WallPose>,
    /// `now` as lines with unit normal and tangent, for per-particle tests.
    lines: Vec<WallLine>,
    /// Pairs of walls that meet (see [`Walls::corners`]).
    corners: Vec<Corner>,
    /// Scratch: (entity, rest geometry, pose now) while reading.
    read: Vec<(Entity, WallPose, WallPose)>,
}

/// Two walls that meet: an end of one lies on the other (a tank corner, or a piston
/// standing on the floor); in 3D an edge of one lies on the other (a tank's edge).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Corner {
    /// The two walls' indices, `first < second`.
    pub first: usize,
    pub second: usize,
    /// Whether the fluid side is the intersection of the two walls' fluid half-planes
    /// (inner angle below 180 degrees, e.g. a tank corner): a point behind both lines
    /// near the corner is then outside the fluid.
    pub convex: bool,
    /// The meeting point is this wall's end `a` (`at_a`) or `b`; in 3D the meeting
    /// edge is this wall's edge `edge` ([`WallPose::edge`]).
    end_of: usize,
    #[cfg(not(feature = "dim3"))]
    at_a: bool,
    #[cfg(feature = "dim3")]
    edge: usize,
}

impl Corner {
    /// The meeting edge (its two ends) in `walls`: the same walls in [`Walls`] order,
    /// at any pose (at rest, or now); None if `walls` is not that long (3D).
    #[cfg(feature = "dim3")]
    pub fn edge_in(&self, walls: &[WallPose]) -> Option<(Vector, Vector)> {
        walls.get(self.end_of).map(|w| w.edge(self.edge))
    }
}

/// Where a particle has crossed the walls (see [`Walls::crossed`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Crossing {
    /// Behind wall `k` while alongside it.
    Wall(usize),
    /// Past the meeting point of a convex corner, behind both its walls' lines while
    /// alongside neither (a particle going diagonally out through the corner).
    Corner(Corner),
}

/// A wall's line (3D: plane rectangle) at an instant with its unit normal and tangents
/// and its extents worked out once, so the per-particle tests (ghost placement, wall crossing) do not
/// normalise per call as [`Wall::distance`] does.
#[derive(Clone, Copy, Debug, Default)]
pub struct WallLine {
    pub a: Vector,
    /// Unit normal pointing into the fluid.
    pub normal: Vector,
    /// Unit tangent from a to b.
    pub tangent: Vector,
    pub length: f64,
    /// Unit tangent from a to c (3D).
    #[cfg(feature = "dim3")]
    pub across: Vector,
    /// |c - a| (3D).
    #[cfg(feature = "dim3")]
    pub breadth: f64,
}

impl WallLine {
    pub fn of(w: &WallPose) -> Self {
        Self {
            a: w.a,
            normal: w.normal(),
            tangent: w.tangent(),
            length: w.length(),
            #[cfg(feature = "dim3")]
            across: w.tangent_across(),
            #[cfg(feature = "dim3")]
            breadth: w.breadth(),
        }
    }
    /// Signed distance of `x` from the line, positive on the fluid side.
    #[inline(always)]
    pub fn distance(&self, x: Vector) -> f64 {
        (x - self.a).dot(self.normal)
    }
    /// Abscissa of the projection of `x`, 0 at `a`, `length` at `b`.
    #[inline(always)]
    pub fn abscissa(&self, x: Vector) -> f64 {
        (x - self.a).dot(self.tangent)
    }
    /// Whether `x` is behind the wall by less than `reach` while alongside it, end
    /// points included (it has crossed it). With the end points excluded a particle
    /// placed exactly on a corner, or sliding down a wall onto the corner, was behind
    /// neither wall there and left the tank unseen. The reach keeps a solid's far side
    /// from counting a particle across the solid as behind it (a box's faces): a
    /// particle crosses a wall by a fraction of a kernel support in a step.
    #[inline(always)]
    pub fn behind(&self, x: Vector, reach: f64) -> bool {
        let s = self.abscissa(x);
        let alongside = s >= 0.0 && s <= self.length;
        #[cfg(feature = "dim3")]
        let alongside = alongside && {
            let t = (x - self.a).dot(self.across);
            t >= 0.0 && t <= self.breadth
        };
        let d = self.distance(x);
        d < 0.0 && d > -reach && alongside
    }
    /// Mirror image of `x` across the line.
    #[inline(always)]
    pub fn mirror(&self, x: Vector) -> Vector {
        x - 2.0 * self.distance(x) * self.normal
    }
}

impl Walls {
    /// The world's walls now.
    pub fn of(world: &World) -> Self {
        let mut walls = Self::default();
        walls.read(world);
        walls
    }

    /// Re-reads the walls from `world` (no allocation once the buffers have their
    /// size): the wall entities in spawn order, where they are now, and the corners
    /// their rest geometry forms.
    pub fn read(&mut self, world: &World) {
        self.read.clear();
        self.read.extend(
            world
                .query::<(Entity, &Wall, &WallPose)>()
                .iter()
                .map(|(e, rest, now)| (e, rest.at_rest(), *now)),
        );
        self.read.sort_by_key(|(e, _, _)| e.id());
        self.entities.clear();
        self.entities.extend(self.read.iter().map(|r| r.0));
        self.now.clear();
        self.now.extend(self.read.iter().map(|r| r.2));
        self.lines.clear();
        self.lines.extend(self.now.iter().map(WallLine::of));
        corners_of(self.read.iter().map(|r| r.1), &mut self.corners);
    }

    pub fn is_empty(&self) -> bool {
        self.now.is_empty()
    }
    pub fn len(&self) -> usize {
        self.now.len()
    }
    /// The wall entities, in the order of [`Walls::now`].
    pub fn entities(&self) -> &[Entity] {
        &self.entities
    }
    /// The walls now.
    pub fn now(&self) -> &[WallPose] {
        &self.now
    }
    /// [`Walls::now`] as lines.
    pub fn lines(&self) -> &[WallLine] {
        &self.lines
    }
    /// The pairs of walls that meet, in a fixed order (by first wall, then second).
    pub fn corners(&self) -> &[Corner] {
        &self.corners
    }
    /// The meeting point of `corner`'s walls where they are now.
    #[cfg(not(feature = "dim3"))]
    pub fn corner_point(&self, corner: &Corner) -> Vector {
        let w = &self.now[corner.end_of];
        if corner.at_a {
            w.a
        } else {
            w.b
        }
    }

    /// The meeting edge of `corner`'s walls where they are now (its two ends).
    #[cfg(feature = "dim3")]
    pub fn corner_edge(&self, corner: &Corner) -> (Vector, Vector) {
        self.now[corner.end_of].edge(corner.edge)
    }

    /// Whether `x` is, for every wall's line, on its fluid side or at least `reach`
    /// behind it (a NaN is neither): such a point has crossed no wall and no corner
    /// ([`Walls::crossed`] with the same reach), since both need it behind a line by
    /// less than the reach (a corner's edge lies on both lines). Inside a tank every
    /// point is in front of every line; beside a box, behind the far faces' lines.
    #[inline]
    pub fn clear_of_all(&self, x: Vector, reach: f64) -> bool {
        self.lines.iter().all(|l| {
            let d = l.distance(x);
            d >= 0.0 || d <= -reach
        })
    }

    /// Where `x` has crossed the walls as they are now: behind a wall by less than
    /// `reach` while alongside it (end points included), else past a convex corner (behind both lines, within
    /// `reach` of the meeting point); `None` if it has not.
    #[inline]
    pub fn crossed(&self, x: Vector, reach: f64) -> Option<Crossing> {
        if let Some(k) = (0..self.lines.len()).find(|&k| self.crossed_through(k, x, reach)) {
            return Some(Crossing::Wall(k));
        }
        self.corners
            .iter()
            .find(|c| self.past_corner(c, x, reach))
            .map(|c| Crossing::Corner(*c))
    }

    /// Whether `x` came in through wall `k`: behind it (within `reach`, alongside it)
    /// and behind no other wall by less (the earlier wall on a tie). Inside a solid
    /// (a box) a point is behind every face near it, and it came in through the
    /// nearest; inside a tank's corner it is alongside one wall only.
    #[inline]
    fn crossed_through(&self, k: usize, x: Vector, reach: f64) -> bool {
        let depth = |j: usize| -self.lines[j].distance(x);
        self.lines[k].behind(x, reach)
            && self.lines.iter().enumerate().all(|(j, l)| {
                j == k
                    || !l.behind(x, reach)
                    || depth(j) > depth(k)
                    || (depth(j) == depth(k) && j > k)
            })
    }

    /// Whether `x` lies behind both lines of the convex `corner`, within `reach` of
    /// its meeting point (3D: edge).
    #[inline]
    pub fn past_corner(&self, corner: &Corner, x: Vector, reach: f64) -> bool {
        #[cfg(not(feature = "dim3"))]
        let near = (x - self.corner_point(corner)).length_squared() < reach * reach;
        #[cfg(feature = "dim3")]
        let near = {
            let (p, q) = self.corner_edge(corner);
            segment_distance_squared(x, p, q) < reach * reach
        };
        corner.convex
            && self.lines[corner.first].distance(x) < 0.0
            && self.lines[corner.second].distance(x) < 0.0
            && near
    }

    /// Reflects a particle at `x` that ended a step behind a wall: its position is
    /// mirrored across the wall, and the outward normal component of each velocity in
    /// `vs` (relative to the wall's velocity at the particle's foot) reversed; past a
    /// convex corner within `reach` of it, across both walls. Returns whether it did.
    /// The integrators' wall safeguard (docs/architecture.md, "Instability handling").
    #[inline]
    pub fn reflect<const N: usize>(
        &self,
        reach: f64,
        x: &mut Vector,
        mut vs: [&mut Vector; N],
    ) -> bool {
        let mut hit = false;
        let mut bounce = |k: usize, x: &mut Vector| {
            let (d, n) = (self.lines[k].distance(*x), self.lines[k].normal);
            let vw = self.now[k].velocity_at(*x - d * n);
            *x -= 2.0 * d * n;
            for v in vs.iter_mut() {
                **v -= 2.0 * (**v - vw).dot(n).min(0.0) * n;
            }
            hit = true;
        };
        for k in 0..self.lines.len() {
            if self.crossed_through(k, *x, reach) {
                bounce(k, x);
            }
        }
        // Out through a corner: behind both lines but alongside neither wall.
        for c in &self.corners {
            if self.past_corner(c, *x, reach) {
                bounce(c.first, x);
                bounce(c.second, x);
            }
        }
        hit
    }

    /// What [`Walls::crossed`] found, in words: ``wall `right` `` or ``the corner of
    /// walls `left` and `bottom` `` (the names are the world's `Wall` components).
    pub fn describe(&self, world: &World, crossing: Crossing) -> String {
        let name = |k: usize| {
            world
                .get::<&Wall>(self.entities[k])
                .map_or_else(|_| format!("#{k}"), |w| w.name.clone())
        };
        match crossing {
            Crossing::Wall(k) => format!("wall `{}`", name(k)),
            Crossing::Corner(c) => format!(
                "the corner of walls `{}` and `{}`",
                name(c.first),
                name(c.second)
            ),
        }
    }
}

/// The pairs of walls where an end (3D: an edge) of one lies on the other, from the
/// rest geometry, into `out`.
fn corners_of(walls: impl Iterator<Item = WallPose> + Clone, out: &mut Vec<Corner>) {
    let on = |p: Vector, w: &WallPose| {
        let s = w.abscissa(p);
        let alongside = s > -1e-9 && s < w.length() + 1e-9;
        #[cfg(feature = "dim3")]
        let alongside = alongside && {
            let t = w.abscissa_across(p);
            t > -1e-9 && t < w.breadth() + 1e-9
        };
        w.distance(p).abs() < 1e-9 && alongside
    };
    out.clear();
    for (i, u) in walls.clone().enumerate() {
        for (j, v) in walls.clone().enumerate().skip(i + 1) {
            let (u, v) = (&u, &v);
            #[cfg(not(feature = "dim3"))]
            {
                // The meeting point: an end of one wall lying on the other.
                let ends = [
                    (i, true, u.a, v),
                    (i, false, u.b, v),
                    (j, true, v.a, u),
                    (j, false, v.b, u),
                ];
                let Some(&(end_of, at_a, meet, _)) = ends.iter().find(|(_, _, p, w)| on(*p, w))
                else {
                    continue;
                };
                // Convex when each wall's far end is on the other's fluid side.
                let far = |w: &WallPose| {
                    if (w.a - meet).length() > (w.b - meet).length() {
                        w.a
                    } else {
                        w.b
                    }
                };
                let convex = u.distance(far(v)) > 0.0 && v.distance(far(u)) > 0.0;
                out.push(Corner {
                    first: i,
                    second: j,
                    convex,
                    end_of,
                    at_a,
                });
            }
            #[cfg(feature = "dim3")]
            {
                // The meeting edge: an edge of one wall lying on the other (both ends),
                // the walls not parallel.
                if u.normal().cross(v.normal()).length_squared() < 1e-18 {
                    continue;
                }
                let meeting = (0..4)
                    .map(|e| (i, e, u.edge(e), v))
                    .chain((0..4).map(|e| (j, e, v.edge(e), u)));
                let Some((end_of, edge, _, _)) = meeting
                    .clone()
                    .find(|(_, _, (p, q), w)| on(*p, w) && on(*q, w))
                else {
                    continue;
                };
                // Convex when part of each wall lies on the other's fluid side (the
                // water's angle at the edge below 180 degrees): a tank's edge, or a box's
                // foot on a floor that runs on past it; not a box's own edges, where
                // each face lies wholly behind the other's plane. (The walls' centres
                // would call three feet of a box off the floor's centre reentrant.)
                let in_front = |w: &WallPose, of: &WallPose| {
                    [w.a, w.b, w.c, w.b + w.c - w.a]
                        .iter()
                        .any(|&x| of.distance(x) > 1e-9)
                };
                let convex = in_front(v, u) && in_front(u, v);
                out.push(Corner {
                    first: i,
                    second: j,
                    convex,
                    end_of,
                    edge,
                });
            }
        }
    }
}

/// The squared distance from `x` to the segment p-q (3D corners' edges).
#[cfg(feature = "dim3")]
fn segment_distance_squared(x: Vector, p: Vector, q: Vector) -> f64 {
    let d = q - p;
    let len2 = d.length_squared();
    let s = if len2 > 0.0 {
        ((x - p).dot(d) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (x - (p + s * d)).length_squared()
}

#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use crate::motion::Pose;
    use glam::DVec2;

    fn wall(name: &str, a: (f64, f64), b: (f64, f64)) -> Wall {
        Wall {
            name: name.into(),
            a: a.into(),
            b: b.into(),
            body: Pose::default(),
        }
    }

    use super::tests_any::world_of;

    /// An open tank 1 m wide (left, bottom, right as the scenario builds them).
    fn tank() -> World {
        world_of([
            wall("left", (0.0, 1.0), (0.0, 0.0)),
            wall("bottom", (0.0, 0.0), (1.0, 0.0)),
            wall("right", (1.0, 0.0), (1.0, 1.0)),
        ])
    }

    #[test]
    fn tank_corners_are_found_and_convex() {
        let set = Walls::of(&tank());
        let c = set.corners();
        assert_eq!(c.len(), 2, "{c:?}");
        assert!(c.iter().all(|c| c.convex));
        assert_eq!(set.corner_point(&c[0]), DVec2::ZERO);
        assert_eq!(set.corner_point(&c[1]), DVec2::new(1.0, 0.0));
    }

    #[test]
    fn a_point_past_a_corner_or_on_a_wall_end_has_crossed() {
        let world = tank();
        let set = Walls::of(&world);
        let reach = 0.1;
        // Inside, and exactly on the corner: not crossed.
        assert_eq!(set.crossed(DVec2::new(0.5, 0.5), reach), None);
        assert_eq!(set.crossed(DVec2::ZERO, reach), None);
        // Straight below the corner: behind the bottom at its end point.
        assert_eq!(
            set.crossed(DVec2::new(0.0, -1e-6), reach),
            Some(Crossing::Wall(1))
        );
        // Diagonally out through the corner: behind both, alongside neither.
        let out = set.crossed(DVec2::new(-1e-6, -1e-6), reach);
        assert!(matches!(out, Some(Crossing::Corner(c)) if (c.first, c.second) == (0, 1)));
        assert_eq!(
            set.describe(&world, out.unwrap()),
            "the corner of walls `left` and `bottom`"
        );
        // Above an open tank's side wall (spilled over it): not a crossing.
        assert_eq!(set.crossed(DVec2::new(-0.05, 1.05), reach), None);
        // Far outside beyond the reach: left to the domain check.
        assert_eq!(set.crossed(DVec2::new(-0.5, -0.5), reach), None);
    }

    #[test]
    fn a_wall_standing_on_the_floor_makes_a_corner() {
        // A piston-like wall from (0.2, 1) down to the floor at (0.2, 0), fluid on
        // its right: convex with the bottom (fluid in x > 0.2, y > 0).
        let world = world_of([
            wall("bottom", (0.0, 0.0), (1.0, 0.0)),
            wall("piston", (0.2, 1.0), (0.2, 0.0)),
        ]);
        let set = Walls::of(&world);
        let c = set.corners();
        assert_eq!(c.len(), 1, "{c:?}");
        assert!(c[0].convex);
        assert_eq!(set.corner_point(&c[0]), DVec2::new(0.2, 0.0));
    }

    #[test]
    fn walls_are_read_in_spawn_order_and_follow_the_kinematics() {
        use crate::components::{BodyPose, Tank};
        use crate::motion::{HarmonicSpec, Motion, MotionSpec};
        use crate::units::Positive;
        let mut world = tank();
        let spec = MotionSpec {
            sway: Some(HarmonicSpec {
                amplitude: 0.1,
                period: Positive(1.0),
                phase: 0.0,
            }),
            ramp: Some(0.0),
            ..MotionSpec::default()
        };
        let pivot = DVec2::new(0.5, 0.0);
        world.spawn((
            Tank {
                width: 1.0,
                height: 1.0,
                pivot,
            },
            Motion::new(&spec, pivot, None),
            BodyPose(Pose::at_rest(pivot)),
        ));
        crate::kinematics::place(&world, 0.25);
        let set = Walls::of(&world);
        let names: Vec<String> = set
            .entities()
            .iter()
            .map(|&e| world.get::<&Wall>(e).unwrap().name.clone())
            .collect();
        assert_eq!(names, ["left", "bottom", "right"]);
        // A quarter period: swayed by the full amplitude.
        assert!((set.now()[0].a - DVec2::new(0.1, 1.0)).length() < 1e-12);
        assert!((set.lines()[2].a - DVec2::new(1.1, 0.0)).length() < 1e-12);
    }
}

/// The 3D walls: planes with edges (`corner_edge`) where 2D has corner points.
#[cfg(all(test, feature = "dim3"))]
mod tests3d {
    use super::*;
    use crate::motion::Pose;

    fn wall(name: &str, a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Wall {
        Wall {
            name: name.into(),
            a: a.into(),
            b: b.into(),
            c: c.into(),
            body: Pose::default(),
        }
    }

    /// An open 1 m box tank: floor, left, right, back (z = 0), front (z = 1), each
    /// with (c - a) x (b - a) pointing into the water.
    fn tank() -> World {
        let mut world = World::new();
        for w in [
            wall("bottom", [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            wall("left", [0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 1.0]),
            wall("right", [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 1.0]),
            wall("back", [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]),
            wall("front", [0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]),
        ] {
            let now = w.at_rest();
            world.spawn((w, now));
        }
        world
    }

    #[test]
    fn the_walls_face_the_water_and_meet_at_eight_convex_edges() {
        let set = Walls::of(&tank());
        let inside = Vector::splat(0.5);
        for (k, line) in set.lines().iter().enumerate() {
            assert!((line.distance(inside) - 0.5).abs() < 1e-15, "wall {k}");
        }
        let c = set.corners();
        // Floor with each side, left and right with back and front; the parallel
        // pairs do not meet.
        assert_eq!(c.len(), 8, "{c:?}");
        assert!(c.iter().all(|c| c.convex));
        let (p, q) = set.corner_edge(&c[0]);
        assert_eq!((c[0].first, c[0].second), (0, 1));
        let ends = [p, q].map(|v| v.to_array());
        assert!(
            ends.contains(&[0.0, 0.0, 0.0]) && ends.contains(&[0.0, 0.0, 1.0]),
            "{ends:?}"
        );
    }

    /// A box standing on the floor of the tank, off the floor's centre (x 0.6-0.8, z
    /// 0.4-0.6): its four feet meet the floor convex (the water's angle there is 90
    /// degrees, whichever side of the box the floor's centre lies), its own eight
    /// edges reentrant, and the tank's eight edges stay convex. Judged by the walls'
    /// centres, the feet on the far side of the floor's centre came out reentrant.
    #[test]
    fn a_box_s_feet_on_the_floor_are_convex_and_its_own_edges_are_not() {
        let mut world = tank();
        let (lo, hi) = (Vector::new(0.6, 0.0, 0.4), Vector::new(0.8, 0.2, 0.6));
        let centre = 0.5 * (lo + hi);
        let v = Vector::new;
        for (name, a, b, c) in [
            (
                "box_top",
                v(lo.x, hi.y, lo.z),
                v(hi.x, hi.y, lo.z),
                v(lo.x, hi.y, hi.z),
            ),
            (
                "box_left",
                v(lo.x, 0.0, lo.z),
                v(lo.x, hi.y, lo.z),
                v(lo.x, 0.0, hi.z),
            ),
            (
                "box_right",
                v(hi.x, 0.0, lo.z),
                v(hi.x, hi.y, lo.z),
                v(hi.x, 0.0, hi.z),
            ),
            (
                "box_back",
                v(lo.x, 0.0, lo.z),
                v(hi.x, 0.0, lo.z),
                v(lo.x, hi.y, lo.z),
            ),
            (
                "box_front",
                v(lo.x, 0.0, hi.z),
                v(hi.x, 0.0, hi.z),
                v(lo.x, hi.y, hi.z),
            ),
        ] {
            // Each face's normal (c - a) x (b - a) out of the box, into the water.
            let out = (c - a).cross(b - a).dot(0.5 * (b + c) - centre) > 0.0;
            let (b, c) = if out { (b, c) } else { (c, b) };
            let w = wall(name, a.into(), b.into(), c.into());
            let now = w.at_rest();
            world.spawn((w, now));
        }
        let set = Walls::of(&world);
        let corners = set.corners();
        let is_box = |k: usize| k >= 5;
        let feet: Vec<_> = corners
            .iter()
            .filter(|c| c.first == 0 && is_box(c.second))
            .collect();
        assert_eq!(feet.len(), 4, "{corners:?}");
        assert!(feet.iter().all(|c| c.convex), "{feet:?}");
        let own: Vec<_> = corners
            .iter()
            .filter(|c| is_box(c.first) && is_box(c.second))
            .collect();
        assert_eq!(own.len(), 8, "{corners:?}");
        assert!(own.iter().all(|c| !c.convex), "{own:?}");
        let tank: Vec<_> = corners
            .iter()
            .filter(|c| !is_box(c.first) && !is_box(c.second))
            .collect();
        assert_eq!(tank.len(), 8);
        assert!(tank.iter().all(|c| c.convex));
    }

    #[test]
    fn a_point_past_an_edge_or_behind_a_wall_has_crossed() {
        let world = tank();
        let set = Walls::of(&world);
        let reach = 0.1;
        assert_eq!(set.crossed(Vector::splat(0.5), reach), None);
        assert_eq!(set.crossed(Vector::ZERO, reach), None);
        assert_eq!(
            set.crossed(Vector::new(0.5, -1e-6, 0.5), reach),
            Some(Crossing::Wall(0))
        );
        assert_eq!(
            set.crossed(Vector::new(0.5, 0.5, 1.0 + 1e-6), reach),
            Some(Crossing::Wall(4))
        );
        let out = set.crossed(Vector::new(-1e-6, -1e-6, 0.5), reach);
        assert!(matches!(out, Some(Crossing::Corner(c)) if (c.first, c.second) == (0, 1)));
        assert_eq!(
            set.describe(&world, out.unwrap()),
            "the corner of walls `bottom` and `left`"
        );
        // Beyond the reach of the edge: left to the domain check.
        assert_eq!(set.crossed(Vector::new(-0.5, -0.5, 0.5), reach), None);
    }

    #[test]
    fn a_particle_behind_the_floor_is_reflected_with_its_velocity() {
        let set = Walls::of(&tank());
        let (mut x, mut v) = (Vector::new(0.5, -0.01, 0.25), Vector::new(0.2, -1.0, 0.3));
        assert!(set.reflect(0.1, &mut x, [&mut v]));
        assert!((x - Vector::new(0.5, 0.01, 0.25)).length() < 1e-15, "{x}");
        assert!((v - Vector::new(0.2, 1.0, 0.3)).length() < 1e-15, "{v}");
        let mut inside = Vector::splat(0.5);
        assert!(!set.reflect(0.1, &mut inside, [&mut v]));
    }
}

/// What both builds share: a wall line's own geometry, the set's accessors, the reach
/// of a corner (3D: of an edge, which ends), and the reflection off a moving wall.
#[cfg(test)]
mod tests_any {
    use super::*;
    use crate::dim::{self, DIM};
    use crate::motion::{Pose, RigidState};

    /// Where the scene's origin is: away from the world's, so that a sign slip in
    /// `x - a` shows.
    fn origin() -> Vector {
        let mut o = dim::xy(0.3, 0.2);
        if DIM == 3 {
            o[DIM - 1] = 0.1;
        }
        o
    }

    /// The point (x, y) (and z in 3D) of the scene.
    fn at(x: f64, y: f64, z: f64) -> Vector {
        let mut p = dim::xy(x, y);
        if DIM == 3 {
            p[DIM - 1] = z;
        }
        origin() + p
    }

    /// A wall of the scene from `a` to `b` (3D: and along z from 0 to 1), riding on
    /// `body`.
    fn wall(name: &str, a: (f64, f64), b: (f64, f64), body: Pose) -> Wall {
        Wall {
            name: name.into(),
            a: at(a.0, a.1, 0.0),
            b: at(b.0, b.1, 0.0),
            #[cfg(feature = "dim3")]
            c: at(a.0, a.1, 1.0),
            body,
        }
    }

    /// The floor y = 0 from x = 0 to 1 (in 3D z from 0 to 1 too), riding on `body`.
    fn floor(body: Pose) -> Wall {
        wall("floor", (0.0, 0.0), (1.0, 0.0), body)
    }

    /// The left wall x = 0, from y = 1 down to the floor.
    fn left() -> Wall {
        wall("left", (0.0, 1.0), (0.0, 0.0), Pose::default())
    }

    /// A world with these walls at rest, as the scenario spawns them.
    pub(super) fn world_of(walls: impl IntoIterator<Item = Wall>) -> World {
        let mut world = World::new();
        for w in walls {
            let now = w.at_rest();
            world.spawn((w, now));
        }
        world
    }

    #[test]
    fn a_wall_line_measures_mirrors_and_knows_behind() {
        let line = WallLine::of(&floor(Pose::default()).at_rest());
        let x = at(0.3, 0.2, 0.4);
        assert!((line.distance(x) - 0.2).abs() < 1e-15);
        assert!((line.abscissa(x) - 0.3).abs() < 1e-15);
        assert!((line.mirror(x) - at(0.3, -0.2, 0.4)).length() < 1e-15);
        assert!(line.behind(at(0.3, -0.01, 0.4), 0.1));
        assert!(line.behind(at(1.0, -0.01, 0.0), 0.1), "end points included");
        assert!(!line.behind(at(1.01, -0.01, 0.4), 0.1), "past the end");
        assert!(!line.behind(at(-0.01, -0.01, 0.4), 0.1), "before the start");
        assert!(!line.behind(x, 0.1), "in front");
        if DIM == 3 {
            assert!(
                !line.behind(at(0.3, -0.01, 1.01), 0.1),
                "beyond the far edge"
            );
            assert!(
                !line.behind(at(0.3, -0.01, -0.01), 0.1),
                "before the near edge"
            );
        }
        // Within the reach only: deeper is across a solid, not through its face.
        assert!(line.behind(at(0.3, -0.099, 0.4), 0.1));
        assert!(!line.behind(at(0.3, -0.101, 0.4), 0.1), "beyond the reach");
    }

    #[test]
    fn the_set_counts_its_walls_and_who_is_clear() {
        let set = Walls::of(&world_of([floor(Pose::default()), left()]));
        assert_eq!((set.len(), set.is_empty()), (2, false));
        assert!(Walls::of(&World::new()).is_empty());
        let reach = 0.1;
        assert!(set.clear_of_all(at(0.5, 0.5, 0.5), reach));
        assert!(set.clear_of_all(at(0.0, 0.0, 0.5), reach), "on both walls");
        assert!(!set.clear_of_all(at(0.5, -1e-9, 0.5), reach));
        assert!(!set.clear_of_all(at(-1e-9, 0.5, 0.5), reach));
        // Behind by the reach or more: beyond what a step crosses.
        assert!(!set.clear_of_all(at(0.5, -0.0999, 0.5), reach));
        assert!(set.clear_of_all(at(0.5, -0.1, 0.5), reach));
        assert!(!set.clear_of_all(at(f64::NAN, 0.5, 0.5), reach));
        // Whatever is clear has crossed nothing.
        for p in [at(0.5, -0.1, 0.5), at(-0.3, -0.2, 0.5), at(0.5, 0.5, 0.5)] {
            assert_eq!(set.crossed(p, reach), None, "{p}");
        }
    }

    /// Behind both walls near where they meet: a corner crossing within the reach of
    /// the meeting point (3D: of the meeting edge, whose ends bound it), none beyond.
    #[test]
    fn a_corner_reaches_as_far_as_it_says() {
        let set = Walls::of(&world_of([floor(Pose::default()), left()]));
        let reach = 0.1;
        let c = set.corners()[0];
        assert!(set.past_corner(&c, at(-0.07, -0.07, 0.5), reach));
        assert!(
            !set.past_corner(&c, at(-0.071, -0.071, 0.5), reach),
            "beyond the reach"
        );
        assert!(
            !set.past_corner(&c, at(0.01, -0.07, 0.5), reach),
            "in front of one"
        );
        if DIM == 3 {
            // Past the edge's end at z = 1: the distance to the end, not to the line.
            assert!(set.past_corner(&c, at(-0.05, -0.05, 1.05), reach));
            assert!(!set.past_corner(&c, at(-0.05, -0.05, 1.1), reach));
            assert!(!set.past_corner(&c, at(-0.05, -0.05, -0.1), reach));
        }
    }

    /// Walls meet only where an end (3D: an edge) of one lies on the other, not on its
    /// line beyond it; a step down (the fluid on the outside of the bend) is a corner
    /// that is not convex.
    #[test]
    fn corners_are_found_only_where_walls_touch_and_know_their_side() {
        let apart = wall("apart", (-0.5, 1.0), (-0.5, 0.0), Pose::default());
        assert!(Walls::of(&world_of([floor(Pose::default()), apart]))
            .corners()
            .is_empty());
        // The floor, then a wall down from its end at x = 1 to y = -1: water above
        // the floor flows over the step.
        let down = wall("down", (1.0, 0.0), (1.0, -1.0), Pose::default());
        let set = Walls::of(&world_of([floor(Pose::default()), down]));
        assert_eq!(set.corners().len(), 1);
        assert!(!set.corners()[0].convex);
        let set = Walls::of(&world_of([floor(Pose::default()), left()]));
        assert!(set.corners()[0].convex);
    }

    /// A particle behind a floor that turns about the scene's origin: its position is
    /// mirrored, and its velocity's normal part relative to the floor's velocity at
    /// the particle's foot reversed.
    #[test]
    fn the_reflection_is_relative_to_the_wall_at_the_particle_s_foot() {
        let body = Pose {
            pivot: origin(),
            state: RigidState {
                omega: 2.0,
                ..RigidState::default()
            },
        };
        let set = Walls::of(&world_of([floor(body)]));
        let vector = |x, y, z| at(x, y, z) - origin();
        let (mut x, mut v) = (at(0.5, -0.01, 0.3), vector(0.1, -0.3, 0.2));
        assert!(set.reflect(0.1, &mut x, [&mut v]));
        assert!((x - at(0.5, 0.01, 0.3)).length() < 1e-15, "{x}");
        // The foot (0.5, 0) moves at omega z x r = (0, 1): v_n = -0.3 - 1 = -1.3
        // relative, reversed: -0.3 + 2.6.
        assert!((v - vector(0.1, 2.3, 0.2)).length() < 1e-12, "{v}");
    }

    /// Inside a box (its faces facing out) a point is behind every face within the
    /// reach; it came in through the nearest, and goes back out through it alone.
    #[test]
    fn a_point_inside_a_box_leaves_through_the_nearest_face() {
        let rest = Pose::default();
        let world = world_of([
            wall("box_left", (0.4, 0.0), (0.4, 0.2), rest),
            wall("box_top", (0.4, 0.2), (0.6, 0.2), rest),
            wall("box_right", (0.6, 0.2), (0.6, 0.0), rest),
        ]);
        let set = Walls::of(&world);
        let reach = 0.1;
        let v0 = at(1.0, -1.0, 0.0) - at(0.0, 0.0, 0.0);
        // Near the left face, deep below the top: out to the left.
        let (mut x, mut v) = (at(0.41, 0.15, 0.5), v0);
        assert_eq!(set.crossed(x, reach), Some(Crossing::Wall(0)));
        assert!(set.reflect(reach, &mut x, [&mut v]));
        assert!((x - at(0.39, 0.15, 0.5)).length() < 1e-12, "{x}");
        assert!((v - (at(-1.0, -1.0, 0.0) - at(0.0, 0.0, 0.0))).length() < 1e-12);
        // Just under the top, near the left face: out through the top.
        let (mut x, mut v) = (at(0.45, 0.19, 0.5), v0);
        assert_eq!(set.crossed(x, reach), Some(Crossing::Wall(1)));
        assert!(set.reflect(reach, &mut x, [&mut v]));
        assert!((x - at(0.45, 0.21, 0.5)).length() < 1e-12, "{x}");
        assert!((v - (at(1.0, 1.0, 0.0) - at(0.0, 0.0, 0.0))).length() < 1e-12);
        // Near the right face: out to the right.
        assert_eq!(
            set.crossed(at(0.58, 0.1, 0.5), reach),
            Some(Crossing::Wall(2))
        );
        // Beyond the reach of every face (the box's middle is 0.1 from each): none.
        assert_eq!(set.crossed(at(0.5, 0.05, 0.5), 0.04), None);
    }
}
