//! What the density-diffusion terms share (docs/physics.md, "Density diffusion"): a
//! diffusive term D_i added to the continuity equation,
//!   d rho_i/dt = sum_j m_j v_ij . grad_i W_ij + D_i,
//!   D_i = delta h c_0 sum_j psi_ij . grad_i W_ij V_j,   V_j = m_j / rho_j,
//! whose flux psi_ij along x_ji = x_j - x_i differs between the schemes
//! ([`super::molteni_colagrossi`], [`super::delta_sph`], [`super::fourtakas`]). The
//! sums run over fluid and ghost particles, like the continuity equation's.

use serde::{Deserialize, Serialize};
use sph_core::pair::{dot, Field, Lane, Me, Pair};
use sph_core::sim::Constants;

/// The parameters of every density-diffusion term.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// The dimensionless coefficient delta. Default 0.1 (Antuono et al. 2010 and
    /// Marrone et al. 2011 use 0.1; DualSPHysics's default too).
    pub delta: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self { delta: 0.1 }
    }
}

impl Params {
    /// delta must be a finite number in [0, 1]: above 1 the term dominates the
    /// continuity equation and the time step would have to shrink with it.
    pub fn check(&self) -> Result<(), sph_core::ParamError> {
        if (0.0..=1.0).contains(&self.delta) {
            Ok(())
        } else {
            Err(sph_core::ParamError::new(
                "delta",
                self.delta,
                "a number from 0 to 1 (0.1 is usual)",
            ))
        }
    }
}

/// The coefficient and regularisation of a diffusion term for a run.
#[derive(Clone, Copy, Debug, Default)]
pub struct Scale {
    /// delta h c_0 [m^2/s].
    pub coef: f64,
    /// eta^2 = 0.01 h^2, which keeps 1/r_ij^2 finite for close pairs.
    pub eta2: f64,
}

impl Scale {
    pub fn new(p: &Params, c: &Constants) -> Self {
        Self {
            coef: p.delta * c.h * c.eos.c0,
            eta2: 0.01 * c.h * c.h,
        }
    }

    /// One pair's shares of D_i and D_j for the density differences d_ij (rho_j -
    /// rho_i, less what a scheme removes from it) and d_ji: delta h c_0 * 2 d_ij
    /// (x_ji . grad_i W_ij) / (r_ij^2 + eta^2) * V_j, and the same with i and j
    /// exchanged, where x_ij . grad_j W_ji = x_ji . grad_i W_ij. That factor is >= 0,
    /// so the flux runs from the denser particle to the lighter. One division for
    /// both (divisions bound the pair loop).
    #[inline(always)]
    pub fn fluxes<L: Lane>(&self, me: &Me, p: &Pair<L>, d_ij: L, d_ji: L) -> (L, L) {
        let c = L::splat;
        let (rho_i, rho_j) = (me.lanes::<L>(Field::Rho), p.j(Field::Rho));
        let x_grad = L::zero() - dot(p.x_ij(), p.grad());
        let t = c(2.0 * self.coef) * x_grad / ((p.r * p.r + c(self.eta2)) * rho_i * rho_j);
        (
            d_ij * p.j(Field::Mass) * rho_i * t,
            d_ji * me.lanes::<L>(Field::Mass) * rho_j * t,
        )
    }
}
