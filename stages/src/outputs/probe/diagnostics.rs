//! The flow's diagnostics that `Probe` samples beside its sensors and gauges: surge
//! front, column height, density fluctuation (flow and guarded particles), maximum
//! speed, neighbour counts, roll angle and moment, and the piston's displacement and
//! force, each behind its flag in [`Params`].

use super::methods::shepard;
use super::Params;
use glam::DVec2;
use sph_core::components::{
    Acceleration, Density, Mass, NeighbourCount, Position, Velocity, Wall, WallPose,
};
use sph_core::motion::Pose;
use sph_core::sim::Sim;
use sph_core::stage::StepError;
use sph_core::vocab::Guarded;
use sph_core::world::{column, Particles};

/// M = sum_i m_i (x_i - centre) x (g - a_i), counter-clockwise positive (`Probe`'s
/// module docs).
pub fn roll_moment(x: &[Position], a: &[Acceleration], m: &[Mass], centre: DVec2, g: DVec2) -> f64 {
    x.iter()
        .zip(a)
        .zip(m)
        .map(|((x, a), m)| m.0 * (x.0 - centre).perp_dot(g - a.0))
        .sum()
}

/// Appends the diagnostics `p` turns on to `row`, in `Probe::columns` order. `pose`
/// is the tank's, `piston` the piston's wall when `p.piston` is on.
pub(super) fn sample(
    p: &Params,
    piston: Option<hecs::Entity>,
    sim: &Sim,
    particles: Particles,
    pose: Pose,
    row: &mut Vec<f64>,
) -> Result<(), StepError> {
    let x = particles.fluid::<Position>()?;
    let ds = sim.constants.spacing;
    if p.front {
        let front = x
            .iter()
            .filter(|q| q.0.y < ds)
            .map(|q| q.0.x)
            .fold(0.0, f64::max);
        row.push(front + 0.5 * ds);
    }
    if p.column_height {
        let height = x
            .iter()
            .filter(|q| q.0.x < ds)
            .map(|q| q.0.y)
            .fold(0.0, f64::max);
        row.push(height + 0.5 * ds);
    }
    if p.density_fluctuation {
        let rho = particles.fluid::<Density>()?;
        let rho0 = sim.constants.eos.rho0;
        // Without an integrator's flags, no guard has acted.
        let flags = particles.fluid.get::<&Guarded>();
        let untouched = |i: usize| flags.as_ref().is_none_or(|f| f[i].untouched());
        let (mut flow, mut guarded, mut count) = (0.0_f64, 0.0_f64, 0usize);
        for (i, r) in rho.iter().enumerate() {
            let d = (r.0 / rho0 - 1.0).abs();
            if untouched(i) {
                flow = flow.max(d);
            } else {
                guarded = guarded.max(d);
                count += 1;
            }
        }
        // floored, reflected: filled in by `Probe::run` from the diagnostics.
        row.extend([flow, guarded, count as f64, 0.0, 0.0]);
    }
    if p.max_speed {
        let v = particles.fluid::<Velocity>()?;
        row.push(v.iter().map(|v| v.0.length()).fold(0.0, f64::max));
    }
    if p.neighbours {
        let n = column::<NeighbourCount>(particles.fluid)?;
        let min = n.iter().map(|c| c.0).min().unwrap_or(0) as f64;
        let max = n.iter().map(|c| c.0).max().unwrap_or(0) as f64;
        let mean = n.iter().map(|c| c.0 as f64).sum::<f64>() / n.len().max(1) as f64;
        row.extend([min, mean, max]);
    }
    if p.roll_moment {
        let (a, m) = (
            particles.fluid::<Acceleration>()?,
            particles.fluid::<Mass>()?,
        );
        row.push(pose.state.angle.to_degrees());
        row.push(roll_moment(
            &x,
            &a,
            &m,
            pose.centre(),
            sim.constants.gravity,
        ));
    }
    if let Some(piston) = piston {
        let wall = *sim
            .world
            .get::<&WallPose>(piston)
            .map_err(|_| StepError::Internal("a probed wall is not in the world".into()))?;
        let rest = sim.world.get::<&Wall>(piston).map_or(wall.a.x, |w| w.a.x);
        row.push(wall.a.x - rest);
        // F = n_x * integral of p along the wetted paddle (midpoint rule, steps of
        // about ds); dry points interpolate to 0.
        let steps = (wall.length() / ds).ceil().max(1.0) as usize;
        let step = wall.length() / steps as f64;
        let mut force = 0.0;
        for i in 0..steps {
            let at = wall.point((i as f64 + 0.5) * step);
            force += shepard(sim, particles, at)? * step;
        }
        row.push(force * -wall.normal().x);
    }
    Ok(())
}
