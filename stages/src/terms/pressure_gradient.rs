//! The pressure gradient of the momentum equation (docs/physics.md, "Governing
//! equations"), in the symmetric form that conserves momentum:
//!   dv_i/dt = - sum_j m_j (p_i/rho_i^2 + p_j/rho_j^2) grad_i W_ij.

use super::Term;
use serde::{Deserialize, Serialize};
use sph_core::pair::{Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;

/// `PressureGradient()`: no parameters.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {}

#[derive(Clone, Copy, Debug, Default)]
pub struct PressureGradient;

impl Term for PressureGradient {
    const READS: Fields = Fields::of(&[Field::PRho2]);
    type Params = Params;
    fn build(_: &Params, _: &Constants) -> Self {
        PressureGradient
    }
}

impl RateTerm for PressureGradient {
    fn reads(&self) -> Fields {
        <Self as Term>::READS
    }
    const USES_COEF: bool = true;
    /// Only the symmetric coefficient C_ij.
    const SYMMETRIC: bool = true;
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        r.coef = r.coef + (me.lanes::<L>(Field::PRho2) + p.j(Field::PRho2));
    }
}
