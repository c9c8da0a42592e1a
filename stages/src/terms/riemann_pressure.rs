//! The momentum equation of Riemann-solver SPH (Zhang, Hu & Adams 2017, "A weakly
//! compressible SPH method based on a low-dissipation Riemann solver", J. Comput. Phys.
//! 335, eqs. 10, 14 and 18; docs/physics.md, "Riemann-solver SPH"): the pressure of a
//! pair is the solution P*_ij of a linearised 1D Riemann problem along the line of
//! centres, with the dissipation limited so that it vanishes for pairs that separate
//! and grows only quadratically with a slow approach:
//!   dv_i/dt = - sum_j m_j (2 P*_ij / (rho_i rho_j)) grad_i W_ij,
//!   P*_ij = (p_i + p_j)/2 + (1/2) rhobar_ij beta_ij U_ij,
//!   U_ij = (v_i - v_j) . e_ij,   e_ij = x_ji / r_ij (from i towards j),
//!   beta_ij = min(eta max(U_ij, 0), cbar_ij),
//! with rhobar and cbar the pair's mean density and sound speed. It replaces both
//! `PressureGradient` and `ArtificialViscosity`; the dissipative part
//! rhobar beta U / (rho_i rho_j) takes m_j (that) v_ij . grad_i W_ij of kinetic energy
//! per second from a pair, booked as viscous dissipation. The dissipation is the
//! scheme's viscosity: against a wall it reads the wall's viscous velocity
//! ([`Term::wall_shear`]: the ghosts' `NoSlipVelocity` column), so a free-slip wall of
//! fixed particles does not brake the fluid sliding along it; the pressures
//! p_i + p_j do not depend on it.

use super::riemann::states;
use super::Term;
use crate::vocab::{viscous_v_ij, wall_mirrored_v_ij};
use serde::{Deserialize, Serialize};
use sph_core::pair::{dot, Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// The limiter's slope eta in beta = min(eta max(U_ij, 0), cbar). Default 3 (the
    /// paper's value); 0 leaves no dissipation at all.
    pub limiter: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self { limiter: 3.0 }
    }
}

#[derive(Clone, Copy, Debug, Default)]
pub struct RiemannPressure {
    eta: f64,
    /// A length far below any pair distance, so that a pair at r = 0 (whose kernel
    /// gradient is 0) divides by no zero.
    tiny: f64,
    /// v_ij from the ghosts' viscous velocities ([`Term::wall_shear`]).
    shear: bool,
    /// Meet wall particles with i's mirror image ([`Term::wall_mirror`]).
    mirror: bool,
}

impl Term for RiemannPressure {
    const READS: Fields =
        Fields::of(&Field::VELOCITY).with(Fields::of(&[Field::Rho, Field::PRho2, Field::Sound]));
    type Params = Params;
    fn check(p: &Params) -> Result<(), sph_core::ParamError> {
        if p.limiter >= 0.0 && p.limiter <= 100.0 {
            Ok(())
        } else {
            Err(sph_core::ParamError::new(
                "limiter",
                p.limiter,
                "a number from 0 to 100 (3 is the paper's)",
            ))
        }
    }
    fn build(p: &Params, c: &Constants) -> Self {
        Self {
            eta: p.limiter,
            tiny: 1e-9 * c.h,
            shear: false,
            mirror: false,
        }
    }
    fn wall_shear(&mut self) {
        self.shear = true;
    }
    fn wall_mirror(&mut self) {
        self.mirror = true;
    }
}

impl RateTerm for RiemannPressure {
    fn reads(&self) -> Fields {
        let reads = super::with_wall_shear(<Self as Term>::READS, self.shear);
        super::with_wall_mirror(reads, self.mirror)
    }
    const USES_COEF: bool = true;
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        self.pair_both(me, p, r, &mut Rates::zero())
    }
    /// The coefficient is symmetric (u_ij, beta and the states' means are); j's
    /// dissipation rate m_i (...) v_ij . grad_i W_ij.
    const SYMMETRIC: bool = true;
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>, rj: &mut Rates<L>) {
        let c = L::splat;
        let s = states(me, p);
        let w = match self.mirror {
            true => wall_mirrored_v_ij(p, me),
            false => viscous_v_ij(p, me, self.shear),
        };
        // U_ij = v_ij . x_ji / r: positive when the pair approaches.
        let u = (L::zero() - dot(w, p.x_ij())) / p.r.max(c(self.tiny));
        // min(eta max(U, 0), cbar) as -max(-eta max(U, 0), -cbar): lanes have no min.
        let beta = L::zero() - (L::zero() - c(self.eta) * u.max(L::zero())).max(L::zero() - s.cbar);
        let inv = c(1.0) / (s.rho_i * s.rho_j);
        let dissipation = s.rhobar * beta * u * inv;
        r.coef = r.coef + (s.p_i + s.p_j) * inv + dissipation;
        let rate = dissipation * dot(w, p.grad());
        r.power = r.power + p.j(Field::Mass) * rate;
        rj.power = rj.power + me.lanes::<L>(Field::Mass) * rate;
    }
}
