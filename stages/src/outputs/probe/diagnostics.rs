//! The flow's diagnostics that `Probe` samples beside its sensors and gauges: surge
//! front, column height, density fluctuation (flow and guarded particles), maximum
//! speed, neighbour counts, roll angle and moment, and the piston's displacement and
//! force, each behind its flag in [`Params`].

use super::methods::shepard;
use super::Params;
use sph_core::components::{
    Acceleration, Density, Mass, NeighbourCount, Position, Velocity, Wall, WallPose,
};
use sph_core::dim::Vector;
use sph_core::motion::Pose;
use sph_core::sim::Sim;
use sph_core::stage::StepError;
use sph_core::vocab::Guarded;
use sph_core::world::{column, Particles};

/// M = sum_i m_i (x_i - centre) x (g - a_i), counter-clockwise positive (`Probe`'s
/// module docs).
pub fn roll_moment(
    x: &[Position],
    a: &[Acceleration],
    m: &[Mass],
    centre: Vector,
    g: Vector,
) -> f64 {
    moment(x, a, m, centre, g, sph_core::dim::cross_z)
}

/// sum_i m_i c(x_i - centre, g - a_i): the component `c` of (r x F) the moment is of.
fn moment(
    x: &[Position],
    a: &[Acceleration],
    m: &[Mass],
    centre: Vector,
    g: Vector,
    c: impl Fn(Vector, Vector) -> f64,
) -> f64 {
    x.iter()
        .zip(a)
        .zip(m)
        .map(|((x, a), m)| m.0 * c(x.0 - centre, g - a.0))
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
    // Setup refuses `pitch_moment` in 2D.
    #[cfg(feature = "dim3")]
    if p.pitch_moment {
        let (a, m) = (
            particles.fluid::<Acceleration>()?,
            particles.fluid::<Mass>()?,
        );
        row.push(pose.state.pitch.values()[0].to_degrees());
        // M_x = sum_i m_i ((x_i - P) x (g - a_i)).x: about the x axis through the
        // pivot, positive as a positive pitch turns (+y towards +z).
        let g = sim.constants.gravity;
        row.push(moment(&x, &a, &m, pose.centre(), g, |r, f| r.cross(f).x));
    }
    if let Some(piston) = piston {
        let wall = *sim
            .world
            .get::<&WallPose>(piston)
            .map_err(|_| StepError::Internal("a probed wall is not in the world".into()))?;
        let rest = sim.world.get::<&Wall>(piston).map_or(wall.a.x, |w| w.a.x);
        row.push(wall.a.x - rest);
        // F = n_x * integral of p over the wetted paddle (midpoint rule, cells of
        // about ds; in 2D along its length, per m of depth, in 3D over its breadth
        // too, in N); dry points interpolate to 0.
        let cells = |extent: f64| {
            let n = (extent / ds).ceil().max(1.0) as usize;
            (n, extent / n as f64)
        };
        let (steps, step) = cells(wall.length());
        #[cfg(not(feature = "dim3"))]
        let (rows, width, across) = (1, 1.0, Vector::ZERO);
        #[cfg(feature = "dim3")]
        let ((rows, width), across) = (cells(wall.breadth()), wall.tangent_across());
        let mut force = 0.0;
        for i in 0..steps {
            let foot = wall.point((i as f64 + 0.5) * step);
            for k in 0..rows {
                let at = foot + (k as f64 + 0.5) * width * across;
                force += shepard(sim, particles, at)? * step * width;
            }
        }
        row.push(force * -wall.normal().x);
    }
    Ok(())
}

// 2D set-ups; the 3D build's own tests are in `tests3d` modules.
#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use crate::outputs::probe::tests::{scene, shepard_sum};
    use glam::DVec2;
    use sph_core::extremes::{nan_max, nan_min};
    use sph_core::motion::RigidState;

    /// The fluid's column `T` as a plain vector.
    fn fluid<T: hecs::Component + Copy>(sim: &Sim) -> Vec<T> {
        crate::testing::fluid_column(sim, |x: &T| *x)
    }

    /// Every diagnostic at once, each against its definition in `Params`, summed
    /// here: front and column height, the density fluctuations of the flow and of the
    /// guarded particles, the speed, the neighbour counts, the roll angle and moment
    /// about a turned, displaced pivot, and the piston's displacement and force (the
    /// left wall, moved and leaning, as the paddle). Bound: round-off.
    #[test]
    fn each_diagnostic_is_its_definition() {
        let sim = scene();
        let all_on = Params {
            front: true,
            column_height: true,
            density_fluctuation: true,
            max_speed: true,
            neighbours: true,
            roll_moment: true,
            piston: true,
            ..Params::default()
        };
        let paddle = sph_core::walls::Walls::of(&sim.world).entities()[3];
        // The paddle now: its foot 2 mm and its top 12 mm right of the wall's place,
        // which is 10 mm right of its rest place (its top's rest x -0.01 m).
        sim.world.get::<&mut WallPose>(paddle).unwrap().a.x += 0.012;
        sim.world.get::<&mut WallPose>(paddle).unwrap().b.x += 0.002;
        sim.world
            .get::<&mut sph_core::components::Wall>(paddle)
            .unwrap()
            .a
            .x = -0.01;
        let pose = Pose {
            pivot: DVec2::new(0.15, 0.1),
            state: RigidState {
                angle: 0.1,
                offset: DVec2::new(0.01, -0.02),
                ..Default::default()
            },
        };
        let particles = Particles::of(&sim.world).unwrap();
        let mut row = vec![-1.0];
        sample(&all_on, Some(paddle), &sim, particles, pose, &mut row).unwrap();

        let x: Vec<Position> = fluid(&sim);
        let ds = 0.01;
        let mut e = vec![-1.0];
        // The bottom row's last particle at 0.115 m, the left column's top at 0.075 m
        // (the drop ahead of the front is off the floor, the one above the column
        // away from the wall).
        let front = x.iter().filter(|q| q.0.y < ds).map(|q| q.0.x);
        e.push(front.fold(f64::NEG_INFINITY, nan_max) + 0.5 * ds);
        assert!((e[1] - 0.12).abs() < 1e-15);
        let height = x.iter().filter(|q| q.0.x < ds).map(|q| q.0.y);
        e.push(height.fold(f64::NEG_INFINITY, nan_max) + 0.5 * ds);
        assert!((e[2] - 0.08).abs() < 1e-15);
        let (rho, flags) = (fluid::<Density>(&sim), fluid::<Guarded>(&sim));
        let dev = |i: usize| (rho[i].0 / 1000.0 - 1.0).abs();
        let of = |guarded: bool| {
            let picked = (0..x.len()).filter(|&i| flags[i].untouched() != guarded);
            picked.map(dev).fold(f64::NEG_INFINITY, nan_max)
        };
        let guarded = flags.iter().filter(|f| !f.untouched()).count();
        assert!(guarded > 0 && guarded < x.len());
        e.extend([of(false), of(true), guarded as f64, 0.0, 0.0]);
        // The largest fluctuations differ (the flagged particles' density is 998).
        assert!(e[3] != e[4]);
        let v = fluid::<Velocity>(&sim);
        e.push(
            v.iter()
                .map(|v| v.0.length())
                .fold(f64::NEG_INFINITY, nan_max),
        );
        let n: Vec<f64> = fluid::<sph_core::components::NeighbourCount>(&sim)
            .iter()
            .map(|c| c.0 as f64)
            .collect();
        let mean = n.iter().sum::<f64>() / n.len() as f64;
        e.extend([
            n.iter().copied().fold(f64::INFINITY, nan_min),
            mean,
            n.iter().copied().fold(f64::NEG_INFINITY, nan_max),
        ]);
        assert!(e[9] < e[10] && e[10] < e[11], "{:?}", &e[9..12]);
        let (a, m) = (fluid::<Acceleration>(&sim), fluid::<Mass>(&sim));
        let centre = pose.to_world(pose.pivot);
        let g = DVec2::new(0.0, -9.81);
        let mut moment = 0.0;
        for i in 0..x.len() {
            let (r, f) = (x[i].0 - centre, m[i].0 * (g - a[i].0));
            moment += r.x * f.y - r.y * f.x;
        }
        e.extend([0.1f64.to_degrees(), moment]);
        // The paddle: x its top's displacement from rest, and F = -n_x times the
        // integral of p over its length (n its unit normal into the fluid, tilted
        // from +x by the paddle's lean), by the midpoint rule in steps of about ds.
        let wall = *sim.world.get::<&WallPose>(paddle).unwrap();
        let length = (wall.b - wall.a).length();
        let steps = (length / ds).ceil();
        assert_eq!(steps, 21.0);
        let force: f64 = (0..21)
            .map(|i| shepard_sum(&sim, wall.point((i as f64 + 0.5) * length / steps)))
            .sum::<f64>()
            * (length / steps);
        assert!(force > 0.0);
        let n = (wall.b - wall.a).perp().normalize();
        assert!(n.x > 0.99 && n.x < 0.999);
        e.extend([0.012 + 0.01, -n.x * force]);
        assert_eq!(row.len(), e.len());
        for (k, (got, want)) in row.iter().zip(&e).enumerate() {
            assert!(
                (got - want).abs() <= 1e-9 * want.abs().max(1.0),
                "column {k}: {got} against {want}"
            );
        }
        // Each flag alone writes its own columns only.
        let alone = |p: Params, piston| {
            let mut row = Vec::new();
            sample(&p, piston, &sim, particles, pose, &mut row).unwrap();
            row
        };
        let none = Params {
            methods: Vec::new(),
            ..Params::default()
        };
        assert!(alone(none.clone(), None).is_empty());
        let only = |f: fn(&mut Params)| {
            let mut p = none.clone();
            f(&mut p);
            p
        };
        assert_eq!(alone(only(|p| p.front = true), None), e[1..2]);
        assert_eq!(alone(only(|p| p.column_height = true), None), e[2..3]);
        assert_eq!(alone(only(|p| p.max_speed = true), None), e[8..9]);
        assert_eq!(alone(only(|p| p.roll_moment = true), None).len(), 2);
        assert_eq!(alone(only(|p| p.piston = true), Some(paddle)).len(), 2);
    }

    /// M = sum_i m_i (x_i - P) x (g - a_i): a particle straight right of the pivot
    /// under gravity alone turns clockwise (negative), one on the left the other way.
    #[test]
    fn the_roll_moment_is_counter_clockwise_positive() {
        let m = roll_moment(
            &[
                Position(DVec2::new(1.0, 0.0)),
                Position(DVec2::new(-0.5, 2.0)),
            ],
            &[
                Acceleration(DVec2::ZERO),
                Acceleration(DVec2::new(1.0, 0.0)),
            ],
            &[Mass(2.0), Mass(3.0)],
            DVec2::ZERO,
            DVec2::new(0.0, -10.0),
        );
        // 2 (1 x -10) + 3 ((-0.5)(-10) - 2(-1)) = -20 + 21.
        assert!((m - 1.0).abs() < 1e-12, "{m}");
    }
}
