//! The continuity equation (docs/physics.md, "Governing equations"):
//!   d rho_i/dt = sum_j m_j v_ij . grad_i W_ij.

use super::Term;
use crate::vocab::{wall_mirror_in, wall_mirrored_v_ij};
use serde::{Deserialize, Serialize};
use sph_core::pair::{dot, Field, Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::{Constants, Sim};

/// `Continuity()`: no parameters.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {}

#[derive(Clone, Copy, Debug, Default)]
pub struct Continuity {
    /// Meet wall particles with i's mirror image ([`Term::wall_mirror`]).
    mirror: bool,
}

impl Continuity {
    /// Continuity as this run's walls need it: meeting the wall particles with i's
    /// mirror image where `WallPressure(pair_mirror: true)` stores their normals
    /// ([`wall_mirror_in`]), as `Forces` does.
    pub fn for_walls(sim: &Sim) -> Self {
        Continuity {
            mirror: wall_mirror_in(sim),
        }
    }
}

impl Term for Continuity {
    const READS: Fields = Fields::of(&Field::VELOCITY);
    type Params = Params;
    fn build(_: &Params, _: &Constants) -> Self {
        Continuity { mirror: false }
    }
    fn wall_mirror(&mut self) {
        self.mirror = true;
    }
}

impl RateTerm for Continuity {
    fn reads(&self) -> Fields {
        super::with_wall_mirror(<Self as Term>::READS, self.mirror)
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        self.pair_both(me, p, r, &mut Rates::zero())
    }
    /// j's share m_i v_ji . grad_j W_ji = m_i v_ij . grad_i W_ij.
    const SYMMETRIC: bool = true;
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, ri: &mut Rates<L>, rj: &mut Rates<L>) {
        let v_ij = match self.mirror {
            true => wall_mirrored_v_ij(p, me),
            false => p.velocity_ij(me),
        };
        let v_grad = dot(v_ij, p.grad());
        ri.drho = ri.drho + p.j(Field::Mass) * v_grad;
        rj.drho = rj.drho + me.lanes::<L>(Field::Mass) * v_grad;
    }
}
