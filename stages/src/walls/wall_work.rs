//! The rate of work the walls do on the fluid through the ghost particles
//! (docs/physics.md, "Energy budget"), summed by `Forces` when `Energy` asks for it
//! (`vocab::WallPower`).
//!
//! Every pair of fluid particles conserves E = kinetic + potential + internal +
//! dissipated: the pressure force's work on the pair is what the pair's continuity
//! takes from the internal energy, and the artificial viscosity's is what it adds to the
//! dissipated energy. A ghost neighbour is not integrated, so its pair with a fluid
//! particle i changes E by
//!
//!   m_i a_i^g . v_i  +  m_i (p_i / rho_i^2) (d rho_i/dt)^g  +  D_i^g
//!
//! with a^g, (d rho/dt)^g and D^g the acceleration, the density rate and the
//! dissipation rate the pair terms give from i's ghost neighbours alone, and p_i the
//! Tait pressure of rho_i (the slope of the internal energy). Summed over the fluid,
//! that is the power the walls put in: zero for a still wall up to the mirror's
//! imperfections, the pressure times the wall's normal speed for a moving one. The
//! terms are the forces' own. When they include continuity, the forces' pass sums each
//! particle's ghost neighbours (last in its list) apart and adds them to the rest, so
//! these sums cost no pass of their own ([`particle_power`]); otherwise (a
//! `Continuity()` stage sums the density rate) [`power`] runs the terms with continuity
//! added over the ghost neighbours alone.

use crate::terms::{continuity, RateTerms};
use sph_core::components::{Density, Mass, Velocity};
use sph_core::dim::Vector;
use sph_core::pair::{
    with_records, EquationsOfMotion, Pass, PluginTerm, RateSums, RateTerm, WithPlugins,
};
use sph_core::sim::Sim;
use sph_core::sim::Tait;
use sph_core::stage::StepError;
use sph_core::vocab::Neighbours;
use sph_core::with_kernel;
use sph_core::world::sum_fixed;

/// The walls' power on the fluid [W per metre of depth] from the state the forces just
/// used; 0 without ghosts. Summed in fixed chunks in order ([`sum_fixed`]), so the
/// same for any thread count.
pub(crate) fn power(
    sim: &mut Sim,
    terms: &RateTerms,
    plugins: &[PluginTerm],
) -> Result<f64, StepError> {
    // Continuity as the density rate read it: with the pair mirror, the image.
    let terms = RateTerms {
        continuity: Some(continuity::Continuity::for_walls(sim)),
        ..*terms
    };
    match plugins.is_empty() {
        true => power_of(sim, terms),
        false => power_of(
            sim,
            WithPlugins {
                base: terms,
                plugins,
            },
        ),
    }
}

/// [`power`] for a term set holding continuity.
fn power_of<R: RateTerm + Copy>(sim: &mut Sim, terms: R) -> Result<f64, StepError> {
    let eom = EquationsOfMotion(terms);
    let power = with_records(sim, terms.reads(), |sim, particles, records| {
        let Some(nb) = sim.resources.get::<Neighbours>() else {
            return Ok(0.0);
        };
        if nb.n_ghost == 0 {
            return Ok(0.0);
        }
        let n = nb.n_fluid;
        let (v, rho, m) = (
            particles.fluid::<Velocity>()?,
            particles.fluid::<Density>()?,
            particles.fluid::<Mass>()?,
        );
        let (v, rho, m): (&[Velocity], &[Density], &[Mass]) = (&v, &rho, &m);
        if [v.len(), rho.len(), m.len()].iter().any(|&len| len != n) {
            return Err(StepError::Internal(format!(
                "the neighbour lists cover {n} fluid particles but the world holds {}",
                v.len()
            )));
        }
        let c = &sim.constants;
        let eos = c.eos;
        with_kernel!(c.kernel, c.h, |k| {
            let pass =
                Pass::new(&eom, k, records).map_err(|e| StepError::Internal(e.to_string()))?;
            Ok::<f64, StepError>(sum_fixed(n, |i| {
                // Most particles have no ghost neighbour: test before gathering, and
                // gather into a stack buffer (a list longer than it, which no kernel
                // support holds at the shipped h/ds, goes to the heap).
                let list = nb.of(i);
                if !list.iter().any(|&j| j as usize >= n) {
                    return 0.0;
                }
                let mut stack = [0u32; 128];
                let mut heap = Vec::new();
                let ghosts: &[u32] = if list.len() <= stack.len() {
                    let mut k = 0;
                    for &j in list.iter().filter(|&&j| j as usize >= n) {
                        stack[k] = j;
                        k += 1;
                    }
                    &stack[..k]
                } else {
                    heap.extend(list.iter().copied().filter(|&j| j as usize >= n));
                    &heap
                };
                particle_power(&eos, m[i].0, v[i].0, rho[i].0, &pass.sum(i, ghosts))
            }))
        })
    })?;
    Ok(power.unwrap_or(0.0))
}

/// The walls' power on fluid particle i (mass `m`, velocity `v`, density `rho`) from
/// `s`, the rates its ghost neighbours alone give (continuity included).
#[inline]
pub(crate) fn particle_power(eos: &Tait, m: f64, v: Vector, rho: f64, s: &RateSums) -> f64 {
    // A density diffusion's share of the ghost pairs is booked apart
    // (`vocab::DiffusionPower`), so it is taken out here.
    m * (s.acc.dot(v) + eos.pressure(rho) / (rho * rho) * s.drho) + s.power - s.diffusion
}
