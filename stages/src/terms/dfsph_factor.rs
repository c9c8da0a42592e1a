//! The DFSPH density and factor sums (docs/physics.md, "DFSPH"; Bender & Koschier 2017,
//! eqs. 2 and 11): in one pass over the neighbours,
//!   rho_i   = m_i W(0) + sum_j m_j W_ij,
//!   alpha_i = rho_i^2 / ( |sum_j m_j grad_i W_ij|^2 + sum_j |m_j grad_i W_ij|^2 ),
//! the factor in the pressure form p_i = alpha_i (rho*_i - rho_0) / dt^2 of their
//! kappa_i = (rho*_i - rho_0) / dt^2 alpha_i / rho_i (the paper's alpha_i is ours
//! divided by rho_i).

use sph_core::pair::{Fields, Lane, Layouts, Me, Pair, PairTerm};

/// Summation density and the DFSPH factor of particle i, with W(0) for its own mass.
#[derive(Clone, Copy, Debug)]
pub struct DensityFactor {
    pub w0: f64,
}

impl PairTerm for DensityFactor {
    // The solve packs its records with (x, y, rho, m).
    const LAYOUTS: Layouts = Layouts::FILTER;
    /// sum m W, sum m grad W (x, y), sum m^2 |grad W|^2.
    type Acc<L: Lane> = [L; 4];
    /// (rho_i, alpha_i).
    type Out = (f64, f64);
    fn reads(&self) -> Fields {
        // Geometry and mass only (always packed).
        Fields::default()
    }
    fn zero<L: Lane>(&self) -> [L; 4] {
        [L::zero(); 4]
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, _: &Me, p: &Pair<L>, [rho, sx, sy, s2]: &mut [L; 4]) {
        let m = p.j(sph_core::pair::Field::Mass);
        let (gx, gy) = (m * p.gx, m * p.gy);
        *rho = *rho + m * p.w;
        *sx = *sx + gx;
        *sy = *sy + gy;
        *s2 = *s2 + gx * gx + gy * gy;
    }
    #[inline(always)]
    fn finish<L: Lane>(&self, me: &Me, [rho, sx, sy, s2]: [L; 4]) -> (f64, f64) {
        let rho = me.get(sph_core::pair::Field::Mass) * self.w0 + rho.sum();
        let (sx, sy) = (sx.sum(), sy.sum());
        let d = sx * sx + sy * sy + s2.sum();
        // A particle without neighbours has no gradient: no pressure can act on it.
        let alpha = if d > 0.0 { rho * rho / d } else { 0.0 };
        (rho, alpha)
    }
}
