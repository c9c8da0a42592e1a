//! Density re-initialisation (Colagrossi & Landrini 2003; physics.md, "Density
//! re-initialisation"), by the Shepard filter
//!   rho_i = sum_j m_j W_ij / sum_j (m_j/rho_j) W_ij   (j over fluid, ghosts and i itself)
//! or the first-order MLS filter ([`crate::mls`]), which keeps a linear (hydrostatic)
//! density field and so does not lift a free surface when run often.
//! Run it every N steps with the stage's `every: N`; leave the stage out for "never".

use crate::mls::MlsSums;
use crate::packed::{with_packed, Fill, Packed};
use crate::pair_x8::WendlandX8;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Ghost, Mass, Position};
use sph_core::contract::Access;
use sph_core::kernel::Kernel;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{
    refresh_ghost_density, require_neighbours, GhostSettings, HalfDensity, Neighbours,
};
use sph_core::{with_kernel, StageRegistry};

/// The density filter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Filter {
    /// Zeroth order: sum m W / sum V W.
    #[default]
    Shepard,
    /// First-order moving least squares (exact for linear density fields).
    Mls,
}

/// How often is the runner's `every: N` (default 1); the studied values are 1, 5, 20.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Default Shepard (the paper's filter).
    pub filter: Filter,
}

pub fn register(registry: &mut StageRegistry) {
    registry.register(
        "reinitialise",
        "Shepard or MLS density re-initialisation (use every: N)",
        |p: Params| Ok(Reinitialise { filter: p.filter }),
    );
}

pub struct Reinitialise {
    filter: Filter,
}

impl Stage for Reinitialise {
    fn name(&self) -> &'static str {
        "reinitialise"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, "reinitialise")
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let filter = self.filter;
        // The sums read the densities packed before the pass, so each particle's new
        // density can go straight into its column (no second buffer).
        let done =
            with_packed(sim, Fill::Basic, |sim, particles, all| {
                let Some(nb) = sim.resources.get::<Neighbours>() else {
                    return Ok(false);
                };
                let c = &sim.constants;
                let x8 = WendlandX8::detect(c.kernel, c.h);
                if x8.is_some() {
                    nb.check_covers(all.len())?;
                }
                // Shift the leapfrog's half-step density by the same correction.
                let mut rho = particles.fluid_mut::<Density>()?;
                let mut half = particles.fluid.get::<&mut HalfDensity>();
                if rho.len() != nb.n_fluid {
                    return Err(StepError::Internal(format!(
                        "the neighbour lists cover {} fluid particles but the world holds {}",
                        nb.n_fluid,
                        rho.len()
                    )));
                }
                with_kernel!(c.kernel, c.h, |k| {
                    let filtered = |i: usize| filtered_density(&k, filter, x8, all, nb, i);
                    match half.as_deref_mut() {
                        Some(half) => (&mut rho[..], half).into_par_iter().enumerate().for_each(
                            |(i, (r, h))| {
                                let f = filtered(i);
                                h.0 += f - r.0;
                                r.0 = f;
                            },
                        ),
                        None => rho
                            .par_iter_mut()
                            .enumerate()
                            .for_each(|(i, r)| r.0 = filtered(i)),
                    }
                });
                Ok(true)
            })?;
        if done != Some(true) {
            return Ok(());
        }
        refresh_ghost_density(sim)
    }

    /// Filters the density in place (and shifts the half-step density and refreshes
    /// the ghosts' densities when there are such).
    fn access(&self) -> Access {
        Access::new()
            .reads::<Neighbours>()
            .reads::<Position>()
            .reads::<Mass>()
            .updates::<Density>()
            .uses::<HalfDensity>()
            .uses::<Ghost>()
            .uses::<GhostSettings>()
    }
}

/// Fluid particle `i`'s re-initialised density from the packed particles `all`: the
/// Shepard filter sum_j m_j W_ij / sum_j (m_j/rho_j) W_ij over i and its neighbours
/// (eight lanes at a time with `x8`), or the MLS filter.
fn filtered_density<K: Kernel>(
    k: &K,
    filter: Filter,
    x8: Option<WendlandX8>,
    all: &[Packed],
    nb: &Neighbours,
    i: usize,
) -> f64 {
    let Packed {
        x: xi,
        m: mi,
        rho: rhoi,
        ..
    } = all[i];
    if filter == Filter::Mls {
        let mut sums = MlsSums::default();
        sums.add(glam::DVec2::ZERO, k.w(0.0), mi, rhoi);
        for &j in nb.of(i) {
            let pj = &all[j as usize];
            let d = xi - pj.x;
            sums.add(d, k.w(d.length()), pj.m, pj.rho);
        }
        return sums.mls();
    }
    if let Some(x8) = x8 {
        return x8.shepard(all, nb.of(i), i);
    }
    let w0 = k.w(0.0);
    let (mut num, mut den) = (mi * w0, mi / rhoi * w0);
    for &j in nb.of(i) {
        let pj = &all[j as usize];
        let w = k.w((xi - pj.x).length());
        num += pj.m * w;
        den += pj.m / pj.rho * w;
    }
    num / den
}
