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
    /// Whether `x` is behind the wall while strictly alongside it (it has crossed it).
    #[inline(always)]
    pub fn behind(&self, x: DVec2) -> bool {
        let s = self.abscissa(x);
        self.distance(x) < 0.0 && s > 0.0 && s < self.length
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
