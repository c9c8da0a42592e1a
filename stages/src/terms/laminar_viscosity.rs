//! Laminar viscosity of Morris, Fox & Zhu (1997), eq. (8), for a constant dynamic
//! viscosity mu = rho_0 nu:
//!   dv_i/dt = sum_j m_j (mu_i + mu_j) / (rho_i rho_j)
//!                  x_ij . grad_i W_ij / (r_ij^2 + eta^2) v_ij,   eta^2 = 0.01 h^2,
//! a second-derivative estimate of (mu/rho) laplacian(v) that needs no second
//! derivative of the kernel. With K_ij the factor before v_ij (<= 0, since
//! x_ij . grad_i W_ij <= 0), the flow loses -(1/2) sum_i m_i sum_j m_j K_ij |v_ij|^2
//! of kinetic energy per second, which this term reports as dissipation.

use super::Term;
use crate::vocab::viscous_v_ij;
use serde::{Deserialize, Serialize};
use sph_core::pair::{dot, scale, Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Kinematic viscosity nu [m^2/s]. Default 1e-6 (water at 20 C).
    pub nu: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self { nu: 1e-6 }
    }
}

#[derive(Clone, Copy, Debug, Default)]
pub struct LaminarViscosity {
    /// mu_i + mu_j = 2 rho_0 nu [Pa s].
    mu_sum: f64,
    /// eta^2 = 0.01 h^2.
    eta2: f64,
    /// v_ij from the ghosts' no-slip velocities ([`Term::wall_shear`]).
    shear: bool,
}

impl Term for LaminarViscosity {
    const READS: Fields = Fields::of(&Field::VELOCITY).with(Fields::of(&[Field::Rho]));
    type Params = Params;
    fn check(p: &Params) -> Result<(), sph_core::ParamError> {
        super::check_non_negative(&[("nu", p.nu)])
    }
    fn build(p: &Params, c: &Constants) -> Self {
        Self {
            mu_sum: 2.0 * c.eos.rho0 * p.nu,
            eta2: 0.01 * c.h * c.h,
            shear: false,
        }
    }
    fn wall_shear(&mut self) {
        self.shear = true;
    }
}

impl RateTerm for LaminarViscosity {
    fn reads(&self) -> Fields {
        super::with_wall_shear(<Self as Term>::READS, self.shear)
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        self.pair_both(me, p, r, &mut Rates::zero())
    }
    /// k is symmetric and v_ji = -v_ij: j gets -m_i k v_ij, and the same dissipation
    /// per unit mass.
    const SYMMETRIC: bool = true;
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>, rj: &mut Rates<L>) {
        let c = L::splat;
        let w = viscous_v_ij(p, me, self.shear);
        let x_grad = dot(p.x_ij(), p.grad());
        let rho_ij = me.lanes::<L>(Field::Rho) * p.j(Field::Rho);
        let k = c(self.mu_sum) * x_grad / (rho_ij * (p.r * p.r + c(self.eta2)));
        let mk = p.j(Field::Mass) * k;
        r.add_acc(scale(mk, w));
        let w2 = dot(w, w);
        r.power = r.power - mk * w2;
        let mki = me.lanes::<L>(Field::Mass) * k;
        rj.sub_acc(scale(mki, w));
        rj.power = rj.power - mki * w2;
    }
}
