//! Density re-initialisation (Colagrossi & Landrini 2003; docs/physics.md, "Density
//! re-initialisation"), by the Shepard filter
//!   rho_i = sum_j m_j W_ij / sum_j (m_j/rho_j) W_ij   (j over fluid, ghosts and i itself)
//! or the first-order MLS filter ([`crate::mls`]), which keeps a linear (hydrostatic)
//! density field and so does not lift a free surface when run often, or the density
//! summation with SPHinXsys's free-surface correction ([`FreeSurfaceDensity`]).
//! Run it every N steps with the stage's `every: N`; leave the stage out for "never".

use crate::terms::{free_surface_density::FreeSurfaceDensity, mls::Mls, shepard::Shepard};
use crate::vocab::{refresh_ghost_density, GhostSettings};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Ghost, Mass, Position};
use sph_core::contract::Access;
use sph_core::kernel::Kernel;
use sph_core::pair::{with_records, PairTerm, Pass};
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{require_neighbours, HalfDensity, Neighbours};
use sph_core::{with_kernel, StageRegistry};

/// The density filter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Filter {
    /// Zeroth order: sum m W / sum V W.
    #[default]
    Shepard,
    /// First-order moving least squares (exact for linear density fields).
    Mls,
    /// sum m W, with the share a free surface cuts from the kernel put back
    /// (SPHinXsys's free-surface density summation).
    FreeSurface,
}

/// How often is the runner's `every: N` (default 1); the studied values are 1, 5, 20.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Default Shepard (the paper's filter).
    pub filter: Filter,
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "reinitialise",
        "Shepard, MLS or free-surface summation density re-initialisation (use every: N)",
        |p: Params| {
            Ok(Reinitialise {
                filter: p.filter,
                inv_lattice_sum: f64::NAN,
            })
        },
    );
}

pub struct Reinitialise {
    filter: Filter,
    /// 1 / (sigma_0 ds^2) for the free-surface summation, from the run's kernel.
    inv_lattice_sum: f64,
}

impl Stage for Reinitialise {
    fn name(&self) -> &'static str {
        "reinitialise"
    }

    /// It filters the density column in place and keeps nothing between calls.
    fn resumes_between_runs(&self) -> bool {
        true
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        let c = &sim.constants;
        self.inv_lattice_sum = 1.0 / sph_core::kernel::lattice_sum(c.kernel, c.h, c.spacing);
        require_neighbours(sim, "reinitialise")
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let _span = tracing::trace_span!("pair_sums").entered();
        let reads = Shepard { w0: 0.0 }.reads().with(Mls { w0: 0.0 }.reads());
        let (rho0, inv_lattice_sum) = (sim.constants.eos.rho0, self.inv_lattice_sum);
        // The sums read the densities packed before the pass, so each particle's new
        // density can go straight into its column (no second buffer).
        let filter = self.filter;
        let done = with_records(sim, reads, |sim, particles, records| {
            let Some(nb) = sim.resources.get::<Neighbours>() else {
                return Ok(false);
            };
            let c = &sim.constants;
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
                let w0 = k.w(0.0);
                match filter {
                    Filter::Shepard => filter_all(
                        &Shepard { w0 },
                        k,
                        records,
                        nb,
                        &mut rho,
                        half.as_deref_mut(),
                    ),
                    Filter::Mls => {
                        filter_all(&Mls { w0 }, k, records, nb, &mut rho, half.as_deref_mut())
                    }
                    Filter::FreeSurface => filter_all(
                        &FreeSurfaceDensity {
                            w0,
                            rho0,
                            inv_lattice_sum,
                        },
                        k,
                        records,
                        nb,
                        &mut rho,
                        half.as_deref_mut(),
                    ),
                }
            })?;
            Ok(true)
        })?;
        if done != Some(true) {
            return Ok(());
        }
        refresh_ghost_density(sim)
    }

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

/// Writes every fluid particle's filtered density (the pair term `term`) into `rho`,
/// and shifts the half-step density `half`, if any, by the same correction.
fn filter_all<T: PairTerm<Out = f64>, K: Kernel>(
    term: &T,
    k: K,
    records: &sph_core::pair::Records,
    nb: &Neighbours,
    rho: &mut [Density],
    half: Option<&mut [HalfDensity]>,
) -> Result<(), StepError> {
    let pass = Pass::new(term, k, records).map_err(|e| StepError::Internal(e.to_string()))?;
    let filtered = |i: usize| pass.sum(i, nb.of(i));
    match half {
        Some(half) => (rho, half)
            .into_par_iter()
            .enumerate()
            .for_each(|(i, (r, h))| {
                let f = filtered(i);
                h.0 += f - r.0;
                r.0 = f;
            }),
        None => rho
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, r)| r.0 = filtered(i)),
    }
    Ok(())
}
