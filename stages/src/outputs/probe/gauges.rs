//! Wave gauges: the free-surface elevation on a vertical line of the tank frame.

use glam::DVec2;
use sph_core::components::{Density, Mass, Position};
use sph_core::kernel;
use sph_core::motion::Pose;
use sph_core::sim::Sim;
use sph_core::stage::StepError;
use sph_core::vocab::Neighbours;
use sph_core::world::Particles;

/// Wave gauge at tank-frame abscissa `x` (`frame`: the tank's pose when the tank
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
    x: f64,
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
        let at = match frame {
            Some(pose) => pose.to_world(DVec2::new(x, y)),
            None => DVec2::new(x, y),
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
