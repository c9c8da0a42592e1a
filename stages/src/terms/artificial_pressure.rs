//! Monaghan's (2000) artificial pressure against the tensile instability
//! (docs/physics.md, "Artificial pressure"): dv_i/dt = - sum_j m_j R_ij f_ij^n
//! grad_i W_ij with f_ij = W(r_ij)/W(ds), and R_ij = eps (|p_i|/rho_i^2 +
//! |p_j|/rho_j^2) over the negative pressures, or eps_+ (p_i/rho_i^2 + p_j/rho_j^2)
//! when both are positive.

use super::{check_non_negative, Term};
use serde::{Deserialize, Serialize};
use sph_core::kernel::w;
use sph_core::pair::{whole_pow, Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// eps, for negative pressures. Default 0.2.
    pub epsilon: f64,
    /// eps_+, when both pressures are positive. Default 0.01.
    pub epsilon_positive: f64,
    /// The exponent n of f_ij^n. Default 4.
    pub exponent: u32,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            epsilon: 0.2,
            epsilon_positive: 0.01,
            exponent: 4,
        }
    }
}

#[derive(Clone, Copy, Debug, Default)]
pub struct ArtificialPressure {
    epsilon: f64,
    epsilon_positive: f64,
    exponent: u32,
    /// 1 / W(ds).
    inv_w_ds: f64,
}

impl Term for ArtificialPressure {
    const READS: Fields = Fields::of(&[Field::PRho2]);
    type Params = Params;
    fn check(p: &Params) -> Result<(), sph_core::ParamError> {
        check_non_negative(&[
            ("epsilon", p.epsilon),
            ("epsilon_positive", p.epsilon_positive),
        ])?;
        if !(1..=12).contains(&p.exponent) {
            return Err(sph_core::ParamError::new("exponent", p.exponent, "1 to 12"));
        }
        Ok(())
    }
    fn build(p: &Params, c: &Constants) -> Self {
        Self {
            epsilon: p.epsilon,
            epsilon_positive: p.epsilon_positive,
            exponent: p.exponent,
            inv_w_ds: 1.0 / w(c.kernel, c.h, c.spacing),
        }
    }
}

impl RateTerm for ArtificialPressure {
    fn reads(&self) -> Fields {
        <Self as Term>::READS
    }
    const USES_COEF: bool = true;
    /// Only the symmetric coefficient C_ij.
    const SYMMETRIC: bool = true;
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        let (c, zero) = (L::splat, L::zero());
        let (pi, pj) = (me.lanes::<L>(Field::PRho2), p.j(Field::PRho2));
        let x = p.w * c(self.inv_w_ds);
        // The default exponent on its own, so the loop does not branch through a table.
        let fij = match self.exponent {
            4 => (x * x) * (x * x),
            n => whole_pow(x, n),
        };
        let both_positive = L::and(zero.lt(pi), zero.lt(pj));
        let tension = c(self.epsilon) * ((zero - pi).max(zero) + (zero - pj).max(zero));
        let compression = c(self.epsilon_positive) * (pi + pj);
        r.coef = r.coef + L::select(both_positive, compression, tension) * fij;
    }
}
