//! The walls at an instant: the tank-frame [`Wall`] components carried to the world by
//! the tank's pose, each with the tank's velocity and acceleration; a wall entity with
//! its own [`Motion`] (a piston) moves by that motion instead. Stages that touch walls
//! keep a `WallSet` and call [`WallSet::at`] for the time they work at; when nothing
//! moves it returns the stored walls unchanged.

use crate::components::{Tank, Wall};
use crate::motion::{Motion, Pose};
use glam::DVec2;
use hecs::World;

#[derive(Clone, Debug, Default)]
pub struct WallSet {
    /// Tank-frame geometry, in the order walls were spawned (sensors index it).
    rest: Vec<Wall>,
    /// The tank's motion and pose.
    motion: Option<Motion>,
    pose: Pose,
    /// Walls with a motion of their own (a piston): (index, motion).
    own: Vec<(usize, Motion)>,
    now: Vec<Wall>,
    /// `now` as lines with unit normal and tangent, for per-particle tests.
    lines: Vec<WallLine>,
    /// Pairs of walls that meet (see [`WallSet::corners`]).
    corners: Vec<Corner>,
}

/// Two walls that meet: an end of one lies on the other (a tank corner, or a piston
/// standing on the floor).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Corner {
    /// The two walls' indices, `first < second`.
    pub first: usize,
    pub second: usize,
    /// Whether the fluid side is the intersection of the two walls' fluid half-planes
    /// (inner angle below 180 degrees, e.g. a tank corner): a point behind both lines
    /// near the corner is then outside the fluid.
    pub convex: bool,
    /// The meeting point is this wall's end `a` (`at_a`) or `b`.
    end_of: usize,
    at_a: bool,
}

/// Where a particle has crossed the walls (see [`WallSet::crossed`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Crossing {
    /// Behind wall `k` while alongside it.
    Wall(usize),
    /// Past the meeting point of a convex corner, behind both its walls' lines while
    /// alongside neither (a particle going diagonally out through the corner).
    Corner(Corner),
}

/// A wall's line at an instant with its unit normal and tangent and its length worked
/// out once, so the per-particle tests (ghost placement, wall crossing) do not
/// normalise per call as [`Wall::distance`] does.
#[derive(Clone, Copy, Debug, Default)]
pub struct WallLine {
    pub a: DVec2,
    /// Unit normal pointing into the fluid.
    pub normal: DVec2,
    /// Unit tangent from a to b.
    pub tangent: DVec2,
    pub length: f64,
}

impl WallLine {
    pub fn of(w: &Wall) -> Self {
        Self {
            a: w.a,
            normal: w.normal(),
            tangent: w.tangent(),
            length: w.length(),
        }
    }
    /// Signed distance of `x` from the line, positive on the fluid side.
    #[inline(always)]
    pub fn distance(&self, x: DVec2) -> f64 {
        (x - self.a).dot(self.normal)
    }
    /// Abscissa of the projection of `x`, 0 at `a`, `length` at `b`.
    #[inline(always)]
    pub fn abscissa(&self, x: DVec2) -> f64 {
        (x - self.a).dot(self.tangent)
    }
    /// Whether `x` is behind the wall while alongside it, end points included (it has
    /// crossed it). With the end points excluded a particle placed exactly on a
    /// corner, or sliding down a wall onto the corner, was behind neither wall there
    /// and left the tank unseen.
    #[inline(always)]
    pub fn behind(&self, x: DVec2) -> bool {
        let s = self.abscissa(x);
        self.distance(x) < 0.0 && s >= 0.0 && s <= self.length
    }
    /// Mirror image of `x` across the line.
    #[inline(always)]
    pub fn mirror(&self, x: DVec2) -> DVec2 {
        x - 2.0 * self.distance(x) * self.normal
    }
}

impl WallSet {
    /// The world's walls and, if the tank moves, its motion.
    pub fn from_world(world: &World) -> Self {
        let mut walls: Vec<(hecs::Entity, Wall, Option<Motion>)> = world
            .query::<(hecs::Entity, &Wall, Option<&Motion>)>()
            .iter()
            .map(|(e, w, m)| (e, w.clone(), m.cloned()))
            .collect();
        walls.sort_by_key(|(e, _, _)| e.id());
        let own = walls
            .iter()
            .enumerate()
            .filter_map(|(i, (_, _, m))| m.clone().map(|m| (i, m)))
            .collect();
        let rest: Vec<Wall> = walls.into_iter().map(|(_, w, _)| w).collect();
        let mut tank = world.query::<(&Tank, Option<&Motion>)>();
        let (pivot, motion) = tank
            .iter()
            .next()
            .map(|(t, m)| (t.pivot, m.cloned()))
            .unwrap_or_default();
        let mut set = Self {
            corners: corners_of(&rest),
            lines: rest.iter().map(WallLine::of).collect(),
            now: rest.clone(),
            rest,
            motion,
            pose: Pose::at_rest(pivot),
            own,
        };
        set.at(0.0);
        set
    }

    pub fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }
    pub fn len(&self) -> usize {
        self.rest.len()
    }
    /// Whether any wall moves.
    pub fn moving(&self) -> bool {
        self.motion.is_some() || !self.own.is_empty()
    }
    /// Tank-frame geometry.
    pub fn rest(&self) -> &[Wall] {
        &self.rest
    }
    /// The walls as last computed by [`WallSet::at`].
    pub fn now(&self) -> &[Wall] {
        &self.now
    }
    /// [`WallSet::now`] as lines.
    pub fn lines(&self) -> &[WallLine] {
        &self.lines
    }
    /// The pairs of walls that meet, in a fixed order (by first wall, then second).
    pub fn corners(&self) -> &[Corner] {
        &self.corners
    }
    /// The meeting point of `corner`'s walls where they are now.
    pub fn corner_point(&self, corner: &Corner) -> DVec2 {
        let w = &self.now[corner.end_of];
        if corner.at_a {
            w.a
        } else {
            w.b
        }
    }

    /// Where `x` has crossed the walls as they are now: behind a wall while alongside
    /// it (end points included), else past a convex corner (behind both lines, within
    /// `reach` of the meeting point); `None` if it has not.
    #[inline]
    pub fn crossed(&self, x: DVec2, reach: f64) -> Option<Crossing> {
        if let Some(k) = self.lines.iter().position(|l| l.behind(x)) {
            return Some(Crossing::Wall(k));
        }
        self.corners
            .iter()
            .find(|c| self.past_corner(c, x, reach))
            .map(|c| Crossing::Corner(*c))
    }

    /// Whether `x` lies behind both lines of the convex `corner`, within `reach` of
    /// its meeting point.
    #[inline]
    pub fn past_corner(&self, corner: &Corner, x: DVec2, reach: f64) -> bool {
        corner.convex
            && self.lines[corner.first].distance(x) < 0.0
            && self.lines[corner.second].distance(x) < 0.0
            && (x - self.corner_point(corner)).length_squared() < reach * reach
    }

    /// What [`WallSet::crossed`] found, in words: ``wall `right` `` or ``the corner of
    /// walls `left` and `bottom` ``.
    pub fn describe(&self, crossing: Crossing) -> String {
        match crossing {
            Crossing::Wall(k) => format!("wall `{}`", self.now[k].name),
            Crossing::Corner(c) => format!(
                "the corner of walls `{}` and `{}`",
                self.now[c.first].name, self.now[c.second].name
            ),
        }
    }

    /// The tank's pose as last computed.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// The walls in the world frame at time `t` (no allocation).
    pub fn at(&mut self, t: f64) -> &[Wall] {
        if let Some(m) = &self.motion {
            self.pose = m.pose(t);
            for k in 0..self.rest.len() {
                self.place(k, self.pose);
            }
        }
        for j in 0..self.own.len() {
            let (k, pose) = (self.own[j].0, self.own[j].1.pose(t));
            self.place(k, pose);
        }
        &self.now
    }

    /// Puts wall `k` where `pose` carries its rest geometry.
    fn place(&mut self, k: usize, pose: Pose) {
        let (now, rest) = (&mut self.now[k], &self.rest[k]);
        now.a = pose.to_world(rest.a);
        now.b = pose.to_world(rest.b);
        now.body = pose;
        self.lines[k] = WallLine::of(now);
    }
}

/// The pairs of walls where an end of one lies on the other, from the rest geometry.
fn corners_of(walls: &[Wall]) -> Vec<Corner> {
    let on = |p: DVec2, w: &Wall| {
        let s = w.abscissa(p);
        w.distance(p).abs() < 1e-9 && s > -1e-9 && s < w.length() + 1e-9
    };
    let mut out = Vec::new();
    for i in 0..walls.len() {
        for j in i + 1..walls.len() {
            let (u, v) = (&walls[i], &walls[j]);
            // The meeting point: an end of one wall lying on the other.
            let ends = [
                (i, true, u.a, v),
                (i, false, u.b, v),
                (j, true, v.a, u),
                (j, false, v.b, u),
            ];
            let Some(&(end_of, at_a, meet, _)) = ends.iter().find(|(_, _, p, w)| on(*p, w)) else {
                continue;
            };
            // Convex when each wall's far end is on the other's fluid side.
            let far = |w: &Wall| {
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
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wall(name: &str, a: (f64, f64), b: (f64, f64)) -> Wall {
        Wall {
            name: name.into(),
            a: a.into(),
            b: b.into(),
            body: Pose::default(),
        }
    }

    /// An open tank 1 m wide (left, bottom, right as the scenario builds them).
    fn tank() -> WallSet {
        let mut world = World::new();
        for w in [
            wall("left", (0.0, 1.0), (0.0, 0.0)),
            wall("bottom", (0.0, 0.0), (1.0, 0.0)),
            wall("right", (1.0, 0.0), (1.0, 1.0)),
        ] {
            world.spawn((w,));
        }
        WallSet::from_world(&world)
    }

    #[test]
    fn tank_corners_are_found_and_convex() {
        let set = tank();
        let c = set.corners();
        assert_eq!(c.len(), 2, "{c:?}");
        assert!(c.iter().all(|c| c.convex));
        assert_eq!(set.corner_point(&c[0]), DVec2::ZERO);
        assert_eq!(set.corner_point(&c[1]), DVec2::new(1.0, 0.0));
    }

    #[test]
    fn a_point_past_a_corner_or_on_a_wall_end_has_crossed() {
        let set = tank();
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
            set.describe(out.unwrap()),
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
        let mut world = World::new();
        world.spawn((wall("bottom", (0.0, 0.0), (1.0, 0.0)),));
        world.spawn((wall("piston", (0.2, 1.0), (0.2, 0.0)),));
        let set = WallSet::from_world(&world);
        let c = set.corners();
        assert_eq!(c.len(), 1, "{c:?}");
        assert!(c[0].convex);
        assert_eq!(set.corner_point(&c[0]), DVec2::new(0.2, 0.0));
    }
}
