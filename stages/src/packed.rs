//! Particles packed for the pair loops (docs/performance.md): what a neighbour sum
//! reads of particle j, in one 64-byte record (one cache line) in the joint fluid +
//! ghost numbering, instead of five or six separate columns each reached through the
//! fluid/ghost branch of `Joined::get`.
//!
//! One buffer is shared by the pair stages (`Reinitialise`, `Continuity`, `Forces`)
//! as the [`PackedParticles`] resource, so a run holds one such buffer rather than
//! one per stage. A stage refills the fields it reads at the start of its own run (the
//! state changes between stages: re-initialisation changes densities, `Eos`
//! pressures), so the contents are never relied on across stages.

use glam::DVec2;
use rayon::prelude::*;
use sph_core::components::{Density, Mass, Position, Pressure, Velocity};
use sph_core::sim::{Sim, Tait};
use sph_core::stage::StepError;
use sph_core::world::Particles;

/// One particle as the pair loops read it.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(64))]
pub struct Packed {
    /// Position [m].
    pub x: DVec2,
    /// Velocity [m/s] (filled with [`Fill::Velocity`] or [`Fill::Pressure`]).
    pub v: DVec2,
    /// Density [kg/m^3].
    pub rho: f64,
    /// Mass [kg].
    pub m: f64,
    /// p / rho^2 [Pa m^6/kg^2] (filled with [`Fill::Pressure`]).
    pub p_rho2: f64,
    /// Sound speed c(rho) [m/s] (filled with [`Fill::Pressure`]).
    pub c: f64,
}

/// The shared buffer (a resource; see the module documentation).
#[derive(Default)]
pub struct PackedParticles(pub Vec<Packed>);

/// Which fields to fill besides x, rho and m.
#[derive(Clone, Copy)]
pub enum Fill {
    /// x, rho, m.
    Basic,
    /// x, v, rho, m.
    Velocity,
    /// everything, with c from this equation of state.
    Pressure(Tait),
}

/// Runs `f` with the shared buffer filled from the current state; returns None when
/// the world has no fluid.
pub fn with_packed<R>(
    sim: &mut Sim,
    fill: Fill,
    f: impl FnOnce(&Sim, &Particles, &[Packed]) -> Result<R, StepError>,
) -> Result<Option<R>, StepError> {
    let mut buffer = sim.resources.take::<PackedParticles>().unwrap_or_default();
    let result = match Particles::of(&sim.world) {
        Some(particles) => pack(&particles, fill, &mut buffer.0)
            .and_then(|()| f(sim, &particles, &buffer.0))
            .map(Some),
        None => Ok(None),
    };
    sim.resources.insert(buffer);
    result
}

/// Fills `out` (resized to fluid + ghosts) from the columns.
fn pack(particles: &Particles, fill: Fill, out: &mut Vec<Packed>) -> Result<(), StepError> {
    let (x, rho, m) = (
        particles.joined::<Position>()?,
        particles.joined::<Density>()?,
        particles.joined::<Mass>()?,
    );
    let (x, rho, m) = (x.view(), rho.view(), m.view());
    let v = match fill {
        Fill::Basic => None,
        _ => Some(particles.joined::<Velocity>()?),
    };
    let p = match fill {
        Fill::Pressure(_) => Some(particles.joined::<Pressure>()?),
        _ => None,
    };
    let (v, p) = (v.as_ref().map(|c| c.view()), p.as_ref().map(|c| c.view()));
    let n_fluid = x.fluid.len();
    out.resize(x.len(), Packed::default());
    let (fluid, ghost) = out.split_at_mut(n_fluid);
    for (part, offset) in [(fluid, 0usize), (ghost, n_fluid)] {
        part.par_iter_mut().enumerate().for_each(|(k, out)| {
            let j = (k + offset) as u32;
            out.x = x.get(j).0;
            out.rho = rho.get(j).0;
            out.m = m.get(j).0;
            if let Some(v) = &v {
                out.v = v.get(j).0;
            }
            if let (Some(p), Fill::Pressure(eos)) = (&p, fill) {
                out.p_rho2 = p.get(j).0 / (out.rho * out.rho);
                out.c = eos.sound_speed(out.rho);
            }
        });
    }
    Ok(())
}
