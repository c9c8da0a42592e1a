//! Wave gauges: the free-surface elevation on a vertical line of the tank frame.

use sph_core::components::{Density, Mass, Position};
use sph_core::dim::Vector;
use sph_core::kernel;
use sph_core::motion::Pose;
use sph_core::sim::Sim;
use sph_core::stage::StepError;
use sph_core::vocab::Neighbours;
use sph_core::world::Particles;

/// Wave gauge on the tank-frame vertical line through `foot` (its y is ignored; in 2D
/// the abscissa x, in 3D the point (x, z)) (`frame`: the tank's pose when the tank
/// moves, None when the tank frame is the world's): the free surface is the lowest
/// height y above the bottom (in the tank frame, along the tank's vertical) where the
/// kernel-interpolated fluid fraction along the vertical line,
///   phi(y) = sum_j (m_j / rho_j) W(|(x, y) - x_j|)   (fluid and ghosts),
/// falls below 1/2, marching up from half a spacing above the bottom in steps of
/// ds/4 and interpolating linearly between the last two points. It is the surface of
/// the water connected to the bottom: drops and spray above it do not count, a wet
/// patch at the gauge too thin to reach phi = 1/2 reads 0 (dry), and so does a
/// gauge with phi < 1/2 at its foot (docs/physics.md, "Other probes").
pub(super) fn elevation(
    sim: &Sim,
    particles: Particles,
    foot: Vector,
    frame: Option<Pose>,
) -> Result<f64, StepError> {
    let Some(nb) = sim.resources.get::<Neighbours>() else {
        return Ok(0.0);
    };
    let (xj, rho, m) = (
        particles.joined::<Position>()?,
        particles.joined::<Density>()?,
        particles.joined::<Mass>()?,
    );
    let (xj, rho, m) = (xj.view(), rho.view(), m.view());
    let c = &sim.constants;
    let fraction = |y: f64| {
        let mut at = foot;
        at.y = y;
        let at = match frame {
            Some(pose) => pose.to_world(at),
            None => at,
        };
        let mut phi = 0.0;
        nb.grid.for_each_near(at, |j| {
            let w = kernel::w(c.kernel, c.h, (at - xj.get(j).0).length());
            phi += m.get(j).0 / rho.get(j).0 * w;
        });
        phi
    };
    let (step, top) = (0.25 * c.spacing, (c.domain.1 - c.domain.0).length());
    let mut y = 0.5 * c.spacing;
    let mut phi = fraction(y);
    // Dry, or a non-finite fraction (the guard stops such a run).
    if phi.is_nan() || phi < 0.5 {
        return Ok(0.0);
    }
    while y < top {
        let (y1, phi1) = (y + step, fraction(y + step));
        if phi1 < 0.5 {
            return Ok(y + step * (phi - 0.5) / (phi - phi1));
        }
        (y, phi) = (y1, phi1);
    }
    Ok(y)
}

// 2D set-ups; the 3D build's own tests are in `tests3d` modules.
#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use crate::outputs::probe::tests::{all, scene};
    use glam::DVec2;
    use sph_core::motion::RigidState;

    /// The gauge's march, written out: the fluid fraction phi(y) = sum_j V_j W_j over
    /// every particle on the line x (world point `to_world(x, y)`), from y = ds/2 up in
    /// steps of ds/4 until phi < 1/2, interpolated linearly; 0 if phi < 1/2 at the foot.
    fn marched(sim: &Sim, to_world: impl Fn(f64) -> DVec2) -> f64 {
        let particles = all(sim);
        let phi = |y: f64| -> f64 {
            let at = to_world(y);
            particles
                .iter()
                .map(|&(x, _, rho, m)| {
                    let w = kernel::w(kernel::KernelKind::Wendland, 0.013, (at - x).length());
                    m / rho * w
                })
                .sum()
        };
        let (mut y, mut f) = (0.005, phi(0.005));
        if f < 0.5 {
            return 0.0;
        }
        loop {
            let f1 = phi(y + 0.0025);
            if f1 < 0.5 {
                return y + 0.0025 * (f - 0.5) / (f - f1);
            }
            (y, f) = (y + 0.0025, f1);
        }
    }

    fn elevation_at(sim: &Sim, x: f64, frame: Option<Pose>) -> f64 {
        elevation(
            sim,
            Particles::of(&sim.world).unwrap(),
            DVec2::new(x, 0.0),
            frame,
        )
        .unwrap()
    }

    /// The gauge is its march ([`marched`]) in the world frame and in a displaced,
    /// turned tank frame; over the block it reads the water's depth, 0.08 m, to within
    /// 0.1 ds; dry beyond the block and without the grid.
    #[test]
    fn a_gauge_reads_where_the_fluid_fraction_falls_to_one_half() {
        let mut sim = scene();
        for x in [0.005, 0.05, 0.1149, 0.2] {
            let e = marched(&sim, |y| DVec2::new(x, y));
            let got = elevation_at(&sim, x, None);
            assert!((got - e).abs() < 1e-12, "x {x}: {got} against {e}");
        }
        // The block's surface: its top row at 0.075 m, a half spacing below the
        // surface of the water it stands for.
        let depth = elevation_at(&sim, 0.05, None);
        assert!((depth - 0.08).abs() < 1e-3, "{depth}");
        assert_eq!(elevation_at(&sim, 0.2, None), 0.0);
        let pose = Pose {
            pivot: DVec2::new(0.05, 0.0),
            state: RigidState {
                angle: 0.05,
                offset: DVec2::new(0.003, 0.01),
                ..Default::default()
            },
        };
        for x in [0.03, 0.06] {
            let e = marched(&sim, |y| pose.to_world(DVec2::new(x, y)));
            let got = elevation_at(&sim, x, Some(pose));
            assert!((got - e).abs() < 1e-12, "x {x}: {got} against {e}");
            assert!((got - elevation_at(&sim, x, None)).abs() > 1e-4);
        }
        sim.resources.take::<Neighbours>();
        assert_eq!(elevation_at(&sim, 0.05, None), 0.0);
    }

    /// A non-finite fluid fraction at the gauge's foot reads dry (the run's guard
    /// reports the particle).
    #[test]
    fn a_non_finite_fraction_reads_dry() {
        let sim = scene();
        {
            let fluid = sph_core::world::archetype::<sph_core::components::Fluid>(&sim.world);
            let mut rho = sph_core::world::column_mut::<Density>(fluid.unwrap()).unwrap();
            rho[0].0 = f64::NAN;
        }
        assert_eq!(elevation_at(&sim, 0.005, None), 0.0);
        assert!(elevation_at(&sim, 0.1, None) > 0.07);
    }
}
