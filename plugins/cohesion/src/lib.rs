//! An example plugin pair term: the cohesion force of Akinci, Akinci & Teschner (2013),
//! "Versatile surface tension and adhesion for SPH fluids", ACM Trans. Graph. 32(6),
//! eqs. (1), (2) and (4), written in a crate of its own and summed inside `Forces`'
//! fused neighbour loop, with no edit to the engine.
//!
//! A scenario names it like a shipped term, once the program's registry knows it
//! ([`register`]):
//!
//! ```ron
//! Forces(terms: [PressureGradient(), ArtificialViscosity(), Continuity(), Cohesion(gamma: 2.0)]),
//! ```
//!
//! # Adding a pair term, step by step
//!
//! 1. **Parameters.** A struct deriving `Serialize`, `Deserialize`, `Default` with
//!    `#[serde(default, deny_unknown_fields)]`, each field documented with its unit
//!    and default (as [`Params`]).
//! 2. **The term.** Implement [`RateTerm`] once over the lane type `L`: `reads` names
//!    the particle fields it needs of i and j ([`Field`]), and `pair` adds one group
//!    of neighbours' share to `Rates` (`ax`, `ay` for dv/dt, `drho` for d rho/dt,
//!    `coef` for a term of the form -m_j C_ij grad_i W_ij). `Pair` holds x_ij, r_ij,
//!    W_ij and grad_i W_ij; unused lanes hold a particle of zero mass beyond the
//!    support, so weight by m_j (or W) and they add nothing. The same source runs on
//!    the scalar path and in AVX-512 and AVX2 lanes.
//! 3. **Building.** Implement [`Term`]: `READS` (the same fields, known before the run),
//!    `check` (refuse out-of-range parameters with a [`ParamError`] naming the field;
//!    the loader adds file, line and column), and `build` (the term for the run's
//!    [`Constants`]: h, the kernel's support, the equation of state).
//! 4. **Registration.** `registry.register_term::<T>("Name", "one line")` in the
//!    crate's `register`, called by the program after `sph_stages::standard_registry()`.
//!    The term is summed after the shipped terms of the list, in the order written,
//!    through one indirect call per group of eight neighbours.

use serde::{Deserialize, Serialize};
use sph_core::pair::{Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;
use sph_core::terms::Term;
use sph_core::{ParamError, StageRegistry};
use std::f64::consts::PI;

/// Registers [`Cohesion`] as the pair term `Cohesion(gamma: ...)`.
pub fn register(registry: &mut StageRegistry) {
    registry.register_term::<Cohesion>(
        "Cohesion",
        "Akinci et al. (2013) cohesion: pairs attract beyond half the support, repel within",
    );
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// The cohesion coefficient gamma of eq. (1) [m^4 s^-2 kg^-1 in 2D, with masses
    /// per metre of depth]: the paper's parameter, not the surface tension sigma
    /// [N/m]. The acceleration scales as gamma / ds at a fixed shape, so set it for
    /// the resolution at hand. Default 0.01, which rounds a 0.05 m square of water at
    /// ds = 2.5 mm into a disc in about 0.1 s (`square.ron`).
    pub gamma: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self { gamma: 0.01 }
    }
}

/// The cohesion acceleration of particle i, eqs. (1) and (4):
///   a_i = - gamma sum_j m_j K_ij C(r_ij) x_ij / r_ij,   K_ij = 2 rho_0 / (rho_i + rho_j),
/// with the spline of eq. (2) over the kernel's support radius h_s:
///   C(r) = 32 / (pi h_s^9) (h_s - r)^3 r^3               for h_s/2 < r <= h_s,
///   C(r) = 32 / (pi h_s^9) (2 (h_s - r)^3 r^3 - h_s^6/64) for 0 < r <= h_s/2,
///   C(r) = 0 otherwise.
/// C is negative below r = h_s/4 (a repulsion that keeps particles apart) and largest,
/// 1 / (2 pi h_s^3), at r = h_s/2. The normalisation is the paper's (3D); in 2D it only
/// scales gamma. The pair force is antisymmetric, so momentum is conserved.
#[derive(Clone, Copy, Debug, Default)]
pub struct Cohesion {
    gamma: f64,
    /// 2 rho_0 [kg/m^3].
    two_rho0: f64,
    /// The support radius h_s [m].
    support: f64,
}

impl Cohesion {
    /// C(r) of eq. (2), one lane at a time (for tests and plots).
    pub fn spline(&self, r: f64) -> f64 {
        let h = self.support;
        if !(r > 0.0 && r <= h) {
            return 0.0;
        }
        let s = (h - r).powi(3) * r.powi(3);
        let c = if 2.0 * r > h {
            s
        } else {
            2.0 * s - h.powi(6) / 64.0
        };
        32.0 / (PI * h.powi(9)) * c
    }
}

impl Term for Cohesion {
    const READS: Fields = Fields::of(&[Field::Rho]);
    type Params = Params;
    fn check(p: &Params) -> Result<(), ParamError> {
        if p.gamma >= 0.0 && p.gamma.is_finite() {
            Ok(())
        } else {
            Err(ParamError::new("gamma", p.gamma, "a finite number >= 0"))
        }
    }
    fn build(p: &Params, c: &Constants) -> Self {
        Self {
            gamma: p.gamma,
            two_rho0: 2.0 * c.eos.rho0,
            support: c.support(),
        }
    }
}

impl RateTerm for Cohesion {
    fn reads(&self) -> Fields {
        <Self as Term>::READS
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        let h = self.support;
        let norm = L::splat(32.0 / (PI * h.powi(9)));
        let hr = L::splat(h) - p.r;
        let s = hr * hr * hr * p.r * p.r * p.r;
        let inner = L::splat(2.0) * s - L::splat(h.powi(6) / 64.0);
        // Where 2r < h: the inner branch (the two agree at 2r = h).
        let c = norm * L::select((L::splat(2.0) * p.r).lt(L::splat(h)), inner, s);
        let k = L::splat(self.two_rho0) / (me.lanes::<L>(Field::Rho) + p.j(Field::Rho));
        let f = L::splat(self.gamma) * p.j(Field::Mass) * k * c / p.r;
        // 0 < r < h_s: a coincident pair (r = 0, no direction) and the padding lanes
        // (beyond the support) add nothing.
        let f = f.keep(L::and(L::zero().lt(p.r), p.r.lt(L::splat(h))));
        r.ax = r.ax - f * p.dx;
        r.ay = r.ay - f * p.dy;
    }
}
