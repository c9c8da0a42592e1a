//! Density diffusion of Molteni & Colagrossi (2009) (docs/physics.md, "Density
//! diffusion"): psi_ij = 2 (rho_j - rho_i) x_ji / r_ij^2 in
//!   D_i = delta h c_0 sum_j psi_ij . grad_i W_ij V_j.
//! The simplest scheme; it also diffuses the hydrostatic density gradient, which near
//! a wall or at the free surface drives a slow spurious flow (what the other two
//! schemes correct).

use super::diffusion::{Params, Scale};
use super::Term;
use sph_core::pair::{Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;

/// `MolteniColagrossi(delta: 0.1)`.
#[derive(Clone, Copy, Debug, Default)]
pub struct MolteniColagrossi {
    scale: Scale,
}

impl Term for MolteniColagrossi {
    const READS: Fields = Fields::of(&[Field::Rho, Field::PRho2]);
    const DIFFUSION: bool = true;
    type Params = Params;
    fn check(p: &Params) -> Result<(), sph_core::ParamError> {
        p.check()
    }
    fn build(p: &Params, c: &Constants) -> Self {
        Self {
            scale: Scale::new(p, c),
        }
    }
}

impl RateTerm for MolteniColagrossi {
    fn reads(&self) -> Fields {
        <Self as Term>::READS
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        self.pair_both(me, p, r, &mut Rates::zero())
    }
    /// The density difference is antisymmetric, d_ji = -d_ij.
    const SYMMETRIC: bool = true;
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>, rj: &mut Rates<L>) {
        let d = p.j(Field::Rho) - me.lanes::<L>(Field::Rho);
        let (fi, fj) = self.scale.fluxes(me, p, d, L::zero() - d);
        r.diffusion = r.diffusion + fi;
        rj.diffusion = rj.diffusion + fj;
    }
}
