//! The walls at an instant: the tank-frame [`Wall`] components carried to the world by
//! the tank's pose, each with the tank's velocity and acceleration. Stages that touch
//! walls keep a `WallSet` and call [`WallSet::at`] for the time they work at; for a
//! fixed tank it returns the stored walls unchanged.

use crate::components::{Tank, Wall};
use crate::motion::{Motion, Pose};
use hecs::World;

#[derive(Clone, Debug, Default)]
pub struct WallSet {
    /// Tank-frame geometry, in the order walls were spawned (sensors index it).
    rest: Vec<Wall>,
    motion: Option<Motion>,
    pose: Pose,
    now: Vec<Wall>,
}

impl WallSet {
    /// The world's walls and, if the tank moves, its motion.
    pub fn from_world(world: &World) -> Self {
        let mut walls: Vec<(hecs::Entity, Wall)> = world
            .query::<(hecs::Entity, &Wall)>()
            .iter()
            .map(|(e, w)| (e, w.clone()))
            .collect();
        walls.sort_by_key(|(e, _)| e.id());
        let rest: Vec<Wall> = walls.into_iter().map(|(_, w)| w).collect();
        let mut tank = world.query::<(&Tank, Option<&Motion>)>();
        let (pivot, motion) = tank
            .iter()
            .next()
            .map(|(t, m)| (t.pivot, m.cloned()))
            .unwrap_or_default();
        Self {
            now: rest.clone(),
            rest,
            motion,
            pose: Pose::at_rest(pivot),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }
    pub fn len(&self) -> usize {
        self.rest.len()
    }
    /// Whether the walls move.
    pub fn moving(&self) -> bool {
        self.motion.is_some()
    }
    /// Tank-frame geometry.
    pub fn rest(&self) -> &[Wall] {
        &self.rest
    }
    /// The walls as last computed by [`WallSet::at`].
    pub fn now(&self) -> &[Wall] {
        &self.now
    }
    /// The tank's pose as last computed.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// The walls in the world frame at time `t` (no allocation).
    pub fn at(&mut self, t: f64) -> &[Wall] {
        if let Some(m) = &self.motion {
            self.pose = m.pose(t);
            for (now, rest) in self.now.iter_mut().zip(&self.rest) {
                now.a = self.pose.to_world(rest.a);
                now.b = self.pose.to_world(rest.b);
                now.body = self.pose;
            }
        }
        &self.now
    }
}
