//! The delta-SPH density diffusion of Antuono et al. (2010, 2012) (docs/physics.md,
//! "Density diffusion"): Molteni & Colagrossi's flux less its first-order part,
//!   psi_ij = 2 (rho_j - rho_i) x_ji / r_ij^2 - (<grad rho>_i + <grad rho>_j),
//! with the renormalised gradients ([`crate::density_gradient`]), computed in a pass of
//! their own before the pair sums (the term's [`Term::PRE_PASS`]). The correction
//! makes the term vanish on any linear density field (the hydrostatic one included),
//! also where the kernel is cut off, so it is consistent at the free surface.

use super::diffusion::{Params, Scale};
use super::Term;
use crate::vocab::DensityGradient;
use crate::vocab::GradientUnrenormalised;
use sph_core::contract::Access;
use sph_core::pair::{ColumnKey, Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;

/// `DeltaSph(delta: 0.1)`.
#[derive(Clone, Copy, Debug, Default)]
pub struct DeltaSph {
    scale: Scale,
}

impl Term for DeltaSph {
    const READS: Fields = Fields::of(&[Field::Rho, Field::PRho2]).with(DensityGradient::FIELDS);
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
    const PRE_PASS: Option<super::PrePass> = Some(crate::density_gradient::compute);
    fn declare(_: &Params, access: Access) -> Access {
        access
            .writes::<DensityGradient>()
            .writes::<GradientUnrenormalised>()
    }
}

impl RateTerm for DeltaSph {
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
        // (rho_j - rho_i) - (1/2)(G_i + G_j) . x_ji, with x_ji = -x_ij: the flux of
        // 2 d x_ji / r^2 . grad W is then psi_ij . grad W.
        let x = p.x_ij();
        let g = |a: usize| {
            let slot = DensityGradient::SLOTS[a];
            me.lanes::<L>(slot) + p.j(slot)
        };
        let mut g_dot_x = g(0) * x[0];
        for (a, &x_a) in x.iter().enumerate().skip(1) {
            g_dot_x = g_dot_x + g(a) * x_a;
        }
        let half = L::splat(0.5);
        let d = p.j(Field::Rho) - me.lanes::<L>(Field::Rho) + half * g_dot_x;
        let (fi, fj) = self.scale.fluxes(me, p, d, L::zero() - d);
        r.diffusion = r.diffusion + fi;
        rj.diffusion = rj.diffusion + fj;
    }
}
