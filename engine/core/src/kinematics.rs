//! The scene's kinematics: puts the tank, its walls and the pistons where their
//! prescribed motions have them at a time, on their entities. It is the one place the
//! walls' motion is worked out; every stage reads wall poses from the world
//! ([`WallPose`], [`BodyPose`], or [`crate::walls::Walls`] for all walls at once).
//!
//! The scene follows the clock: [`crate::sim::Clock::advance`] moves it to the new time
//! whenever the clock advances (once per step, by the one stage that writes the
//! clock), the scenario places it at t = 0 when it builds the world, and the runner
//! places it at the checkpoint's time when a run resumes. So wall poses always belong
//! to `clock.time`. Not a stage of its own, nor a runner call at the start of a step:
//! `Integrate` checks the particles against the walls where they are at the *end* of
//! its step, a time that exists only once it has chosen dt; the walls must move then,
//! in the middle of its run, and they then stand where every later stage of the step
//! (and the next step's first stages) expect them.

use crate::components::{BodyPose, Tank, Wall, WallPose};
use crate::motion::Motion;
use hecs::World;

/// Moves every moving body to time `t`: a moving tank's [`BodyPose`] and the
/// [`WallPose`] of every wall (all ride on the tank), then each wall with a motion of
/// its own (a piston): its pose and its wall. A fixed tank and its walls stay as
/// spawned (their rest geometry, exactly). Needs no mutable world: it writes the
/// scene's components only, which no particle loop borrows.
pub fn place(world: &World, t: f64) {
    let mut tank = None;
    for (motion, pose) in world
        .query::<(&Motion, &mut BodyPose)>()
        .with::<&Tank>()
        .iter()
    {
        pose.0 = motion.pose(t);
        tank = Some(pose.0);
    }
    if let Some(pose) = tank {
        for (wall, now) in world.query::<(&Wall, &mut WallPose)>().iter() {
            *now = wall.placed(pose);
        }
    }
    for (wall, motion, body, now) in world
        .query::<(&Wall, &Motion, &mut BodyPose, &mut WallPose)>()
        .iter()
    {
        body.0 = motion.pose(t);
        *now = wall.placed(body.0);
    }
}

/// Whether anything in the scene moves (a tank or a wall with a [`Motion`]).
pub fn moving(world: &World) -> bool {
    world.query::<&Motion>().iter().next().is_some()
}

/// The tank's pose now, if there is a tank.
pub fn tank_pose(world: &World) -> Option<crate::motion::Pose> {
    world
        .query::<&BodyPose>()
        .with::<&Tank>()
        .iter()
        .next()
        .map(|p| p.0)
}
