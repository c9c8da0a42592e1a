//! Monaghan's artificial viscosity (docs/physics.md, "Artificial viscosity"): for
//! approaching pairs (v_ij . x_ij < 0),
//!   Pi_ij = (-alpha cbar_ij phi_ij + beta phi_ij^2) / rhobar_ij,
//!   phi_ij = h v_ij . x_ij / (r_ij^2 + eta^2),  eta^2 = 0.01 h^2,
//! with cbar and rhobar the pair's mean sound speed and density, added to the
//! momentum equation as dv_i/dt = - sum_j m_j Pi_ij grad_i W_ij. It dissipates
//! (1/2) sum_i m_i sum_j m_j Pi_ij v_ij . grad_i W_ij of kinetic energy per second.

use super::{check_non_negative, Term};
use crate::vocab::viscous_v_ij;
use serde::{Deserialize, Serialize};
use sph_core::contract::Access;
use sph_core::pair::{dot, Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Linear coefficient alpha. Default 0.03 (the paper's dam break).
    pub alpha: f64,
    /// Quadratic coefficient beta (for shocks). Default 0.
    pub beta: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            alpha: 0.03,
            beta: 0.0,
        }
    }
}

#[derive(Clone, Copy, Debug, Default)]
pub struct ArtificialViscosity {
    alpha: f64,
    beta: f64,
    h: f64,
    /// eta^2 = 0.01 h^2.
    eta2: f64,
    /// v_ij from the ghosts' no-slip velocities ([`Term::wall_shear`]).
    shear: bool,
}

impl Term for ArtificialViscosity {
    const READS: Fields =
        Fields::of(&Field::VELOCITY).with(Fields::of(&[Field::Rho, Field::Sound]));
    type Params = Params;
    fn check(p: &Params) -> Result<(), sph_core::ParamError> {
        check_non_negative(&[("alpha", p.alpha), ("beta", p.beta)])
    }
    /// Exposes (alpha, beta) to the rest of the engine (a study's metrics name them).
    fn declare(p: &Params, access: Access) -> Access {
        access.exposes(sph_core::vocab::ArtificialViscosity {
            alpha: p.alpha,
            beta: p.beta,
        })
    }
    fn build(p: &Params, c: &Constants) -> Self {
        Self {
            alpha: p.alpha,
            beta: p.beta,
            h: c.h,
            eta2: 0.01 * c.h * c.h,
            shear: false,
        }
    }
    fn wall_shear(&mut self) {
        self.shear = true;
    }
}

impl RateTerm for ArtificialViscosity {
    fn reads(&self) -> Fields {
        super::with_wall_shear(<Self as Term>::READS, self.shear)
    }
    const USES_COEF: bool = true;
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        self.pair_both(me, p, r, &mut Rates::zero())
    }
    /// Pi_ij is symmetric; j's dissipation rate m_i Pi_ij v_ij . grad_i W_ij.
    const SYMMETRIC: bool = true;
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>, rj: &mut Rates<L>) {
        let c = L::splat;
        let w = viscous_v_ij(p, me, self.shear);
        let vx = dot(w, p.x_ij());
        let d = p.r * p.r + c(self.eta2);
        let cbar = c(0.5) * (me.lanes::<L>(Field::Sound) + p.j(Field::Sound));
        let rhobar = c(0.5) * (me.lanes::<L>(Field::Rho) + p.j(Field::Rho));
        // Divisions bound the pair loop (a vector division costs as much as a dozen
        // multiplications): without the quadratic term, Pi_ij = -alpha cbar h v.x /
        // ((r^2 + eta^2) rhobar) takes one, the same up to round-off.
        let visc = if self.beta == 0.0 {
            c(-self.alpha * self.h) * cbar * vx / (d * rhobar)
        } else {
            let phi = c(self.h) * vx / d;
            (c(-self.alpha) * cbar * phi + c(self.beta) * phi * phi) / rhobar
        };
        let visc = visc.keep(vx.lt(L::zero()));
        r.coef = r.coef + visc;
        let vij_grad = dot(w, p.grad());
        let dissipation = visc * vij_grad;
        r.power = r.power + p.j(Field::Mass) * dissipation;
        rj.power = rj.power + me.lanes::<L>(Field::Mass) * dissipation;
    }
}
