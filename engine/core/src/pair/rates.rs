//! Terms of the equations of motion: each adds its share of one pair's contribution to
//! dv_i/dt, d rho_i/dt and the dissipation rate, and the terms a scenario names run in
//! one neighbour loop ([`EquationsOfMotion`]).

use super::{Field, Fields, Lane, Layouts, Me, Pair, PairTerm};
use glam::DVec2;

/// One particle's rates in lanes, summed over its neighbours.
#[derive(Clone, Copy)]
pub struct Rates<L> {
    /// This pair's coefficient C_ij of -m_j grad_i W_ij in dv_i/dt (reset for each
    /// pair): the pressure gradient, the artificial viscosity and the artificial
    /// pressure are all of the form dv_i/dt = - sum_j m_j C_ij grad_i W_ij, so they
    /// add to C_ij and are multiplied out once.
    pub coef: L,
    /// dv_i/dt, other than through `coef` [m/s^2].
    pub ax: L,
    pub ay: L,
    /// d rho_i/dt [kg/m^3/s].
    pub drho: L,
    /// The viscous dissipation rate of particle i's pairs, P_i, such that the flow
    /// loses (1/2) sum_i m_i P_i [W per metre of depth].
    pub power: L,
    /// A density-diffusion term's share D_i of d rho_i/dt [kg/m^3/s], kept apart from
    /// `drho` for the energy budget (it is added to d rho_i/dt at the end).
    pub diffusion: L,
}

/// A term of the equations of motion, written over the lane type.
pub trait RateTerm: Sync {
    /// The fields of i and j the term reads.
    fn reads(&self) -> Fields;
    /// Whether the term adds to [`Rates::coef`] (known at compile time, so a loop
    /// without such terms does not multiply it out).
    const USES_COEF: bool = false;
    /// The record layouts the loop of this term (or set) is compiled for
    /// ([`PairTerm::LAYOUTS`]).
    const LAYOUTS: Layouts = Layouts::COMMON;
    /// Adds this term's contribution of one group of neighbours.
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>);
}

/// One particle's rates, summed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RateSums {
    /// dv_i/dt from the pair terms (gravity not included) [m/s^2].
    pub acc: DVec2,
    /// d rho_i/dt [kg/m^3/s].
    pub drho: f64,
    /// Particle i's share of the dissipation rate, (1/2) m_i P_i (see
    /// [`Rates::power`]) [W per metre of depth].
    pub power: f64,
    /// The rate at which density diffusion changes particle i's internal energy,
    /// m_i (p_i/rho_i^2) D_i (see [`Rates::diffusion`]; 0 unless the terms read
    /// `PRho2`, as the diffusion terms do) [W per metre of depth].
    pub diffusion: f64,
}

impl std::ops::Add for RateSums {
    type Output = Self;
    /// The sums over two parts of a particle's neighbours.
    fn add(self, b: Self) -> Self {
        Self {
            acc: self.acc + b.acc,
            drho: self.drho + b.drho,
            power: self.power + b.power,
            diffusion: self.diffusion + b.diffusion,
        }
    }
}

/// The pair term that sums a set of rate terms in one neighbour loop.
#[derive(Clone, Copy)]
pub struct EquationsOfMotion<R: RateTerm>(pub R);

impl<R: RateTerm + Clone> PairTerm for EquationsOfMotion<R> {
    const LAYOUTS: Layouts = R::LAYOUTS;
    type Acc<L: Lane> = Rates<L>;
    type Out = RateSums;

    fn reads(&self) -> Fields {
        self.0.reads()
    }

    #[inline(always)]
    fn zero<L: Lane>(&self) -> Rates<L> {
        let z = L::zero();
        Rates {
            coef: z,
            ax: z,
            ay: z,
            drho: z,
            power: z,
            diffusion: z,
        }
    }

    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        r.coef = L::zero();
        self.0.pair(me, p, r);
        if R::USES_COEF {
            let mt = p.j(Field::Mass) * r.coef;
            r.ax = r.ax - mt * p.gx;
            r.ay = r.ay - mt * p.gy;
        }
    }

    #[inline(always)]
    fn finish<L: Lane>(&self, me: &Me, r: Rates<L>) -> RateSums {
        let diffusion = r.diffusion.sum();
        RateSums {
            acc: DVec2::new(r.ax.sum(), r.ay.sum()),
            drho: r.drho.sum() + diffusion,
            power: 0.5 * me.get(Field::Mass) * r.power.sum(),
            diffusion: me.get(Field::Mass) * me.get(Field::PRho2) * diffusion,
        }
    }
}
