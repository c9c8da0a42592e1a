//! Density diffusion of Fourtakas et al. (2019) (docs/physics.md, "Density
//! diffusion"; DualSPHysics's "DDT 2"): Molteni & Colagrossi's flux with the
//! hydrostatic part of the density difference removed,
//!   psi_ij = 2 (rho_j - rho_i - rho^H_ji) x_ji / r_ij^2,
//!   rho^H_ji = rho_0 [(1 + (p_j - p_i)^H / B)^(1/gamma) - 1],
//!   (p_j - p_i)^H = rho_0 g . x_ji,
//! so that water at rest stays at rest near walls and under a free surface.
//!
//! (1 + u)^(1/gamma) - 1 is taken by its Taylor series to u^3: over one kernel support
//! u = rho_0 |g| r / B <= gamma |g| 2h / c_0^2, below 1e-2 for any scene the engine
//! runs (c_0 >= 10 sqrt(g H) makes it < 0.007 h/H), where the first omitted term,
//! |a (a-1)(a-2)(a-3)| u^4 / 24 with a = 1/gamma, is below 1e-9 of rho_0: round-off
//! against the density differences the term works on, and no `powf` in the pair loop.

use super::diffusion::{Params, Scale};
use super::Term;
use sph_core::pair::{dot, splat, Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;

/// `Fourtakas(delta: 0.1)`.
#[derive(Clone, Copy, Debug, Default)]
pub struct Fourtakas {
    scale: Scale,
    /// rho_0 g / B, so that u = (rho_0 g / B) . x_ji.
    g_b: [f64; sph_core::dim::DIM],
    /// rho_0 times the Taylor coefficients of (1+u)^a - 1: a, a(a-1)/2, a(a-1)(a-2)/6.
    c1: f64,
    c2: f64,
    c3: f64,
}

impl Term for Fourtakas {
    const READS: Fields = Fields::of(&[Field::Rho, Field::PRho2]);
    const DIFFUSION: bool = true;
    type Params = Params;
    fn check(p: &Params) -> Result<(), sph_core::ParamError> {
        p.check()
    }
    fn build(p: &Params, c: &Constants) -> Self {
        let (eos, g) = (&c.eos, c.gravity);
        let a = 1.0 / eos.gamma;
        Self {
            scale: Scale::new(p, c),
            g_b: g.to_array().map(|g| eos.rho0 * g / eos.b),
            c1: eos.rho0 * a,
            c2: eos.rho0 * a * (a - 1.0) / 2.0,
            c3: eos.rho0 * a * (a - 1.0) * (a - 2.0) / 6.0,
        }
    }
}

impl RateTerm for Fourtakas {
    fn reads(&self) -> Fields {
        <Self as Term>::READS
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        self.pair_both(me, p, r, &mut Rates::zero())
    }
    /// j's hydrostatic difference is rho^H at -u (the series is not odd in u).
    const SYMMETRIC: bool = true;
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>, rj: &mut Rates<L>) {
        let c = L::splat;
        // u = rho_0 g . x_ji / B, with x_ji = -(dx, dy).
        let u = L::zero() - dot(splat(self.g_b), p.x_ij());
        let rho_h = |u: L| u * (c(self.c1) + u * (c(self.c2) + u * c(self.c3)));
        let rho_ji = p.j(Field::Rho) - me.lanes::<L>(Field::Rho);
        let (d, d_ji) = (
            rho_ji - rho_h(u),
            (L::zero() - rho_ji) - rho_h(L::zero() - u),
        );
        let (fi, fj) = self.scale.fluxes(me, p, d, d_ji);
        r.diffusion = r.diffusion + fi;
        rj.diffusion = rj.diffusion + fj;
    }
}
