//! What the two Riemann-solver terms ([`super::riemann_pressure`],
//! [`super::riemann_diffusion`]) read of a pair: the left (i) and right (j) states of
//! its Riemann problem and their means (docs/physics.md, "Riemann-solver SPH").

use sph_core::pair::{Field, Lane, Me, Pair};

/// The two states of a pair's Riemann problem, lane by lane.
pub struct States<L> {
    pub rho_i: L,
    pub rho_j: L,
    pub p_i: L,
    pub p_j: L,
    /// (rho_i + rho_j) / 2.
    pub rhobar: L,
    /// (c_i + c_j) / 2, from the equation of state.
    pub cbar: L,
}

/// The states of `p`'s pairs with `me` (the term must read `Rho`, `PRho2` and `Sound`).
#[inline(always)]
pub fn states<L: Lane>(me: &Me, p: &Pair<L>) -> States<L> {
    let half = L::splat(0.5);
    let rho_i = me.lanes::<L>(Field::Rho);
    let rho_j = p.j(Field::Rho);
    States {
        rho_i,
        rho_j,
        p_i: me.lanes::<L>(Field::PRho2) * rho_i * rho_i,
        p_j: p.j(Field::PRho2) * rho_j * rho_j,
        rhobar: half * (rho_i + rho_j),
        cbar: half * (me.lanes::<L>(Field::Sound) + p.j(Field::Sound)),
    }
}
