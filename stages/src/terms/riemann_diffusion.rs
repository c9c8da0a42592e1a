//! The dissipation that Riemann-solver SPH adds to the continuity equation (Zhang, Hu
//! & Adams 2017, eqs. 11, 13 and 17; docs/physics.md, "Riemann-solver SPH"). The
//! interface velocity of a pair's Riemann problem differs from the pair's mean by
//! e_ij (p_i - p_j) / (2 rhobar cbar) (the limiter acts on the momentum equation
//! only), and the continuity equation 2 rho_i sum_j V_j (v_i - v*_ij) . grad_i W_ij
//! thereby gains a pressure-driven diffusion of density,
//!   D_i = sum_j rho_i V_j (p_i - p_j)^D / (rhobar_ij cbar_ij) (x_ij . grad_i W_ij) / r_ij,
//! which runs from the particle of higher pressure to the lower (x_ij . grad_i W_ij < 0).
//! With `remove_hydrostatic` (the default) the hydrostatic pressure difference
//! rho_0 g . x_ji is taken out of p_i - p_j, as Fourtakas et al. (2019) take it out of
//! the density difference, so that water at rest under a free surface stays at rest;
//! without it the term is the paper's. The mean part of the paper's continuity
//! equation is `Continuity()`'s sum_j m_j v_ij . grad_i W_ij (the paper's
//! 2 rho_i / (rho_i + rho_j) weight differs from 1 by |rho_i - rho_j| / (2 rho), below
//! 1 % in weakly compressible flow).

use super::riemann::states;
use super::Term;
use serde::{Deserialize, Serialize};
use sph_core::pair::{dot, splat, Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Take the hydrostatic part rho_0 g . x_ji out of the pressure difference.
    /// Default true; false is the paper's term.
    pub remove_hydrostatic: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            remove_hydrostatic: true,
        }
    }
}

#[derive(Clone, Copy, Debug, Default)]
pub struct RiemannDiffusion {
    /// rho_0 g, or 0 without the hydrostatic correction [kg/m^2/s^2].
    rho_g: [f64; sph_core::dim::DIM],
    /// See `RiemannPressure::tiny`.
    tiny: f64,
}

impl Term for RiemannDiffusion {
    const READS: Fields = Fields::of(&[Field::Rho, Field::PRho2, Field::Sound]);
    const DIFFUSION: bool = true;
    type Params = Params;
    fn build(p: &Params, c: &Constants) -> Self {
        let s = if p.remove_hydrostatic {
            c.eos.rho0
        } else {
            0.0
        };
        Self {
            rho_g: c.gravity.to_array().map(|g| s * g),
            tiny: 1e-9 * c.h,
        }
    }
}

impl RateTerm for RiemannDiffusion {
    fn reads(&self) -> Fields {
        <Self as Term>::READS
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        self.pair_both(me, p, r, &mut Rates::zero())
    }
    /// dp_ji = -dp_ij and x_ji . grad_j W_ji = x_ij . grad_i W_ij: j's share is
    /// -rho_j m_i dp_ij x_ij . grad_i W_ij / (rho_i rhobar cbar r), one division for
    /// both.
    const SYMMETRIC: bool = true;
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, ri: &mut Rates<L>, rj: &mut Rates<L>) {
        let c = L::splat;
        let s = states(me, p);
        // (p_i - p_j) less its hydrostatic part p_i - p_j = -rho_0 g . x_ji = rho_0 g . x_ij.
        let dp = s.p_i - s.p_j - dot(splat(self.rho_g), p.x_ij());
        let x_grad = dot(p.x_ij(), p.grad());
        let t = dp * x_grad / (s.rho_i * s.rho_j * s.rhobar * s.cbar * p.r.max(c(self.tiny)));
        ri.diffusion = ri.diffusion + s.rho_i * s.rho_i * p.j(Field::Mass) * t;
        rj.diffusion = rj.diffusion - s.rho_j * s.rho_j * me.lanes::<L>(Field::Mass) * t;
    }
}
