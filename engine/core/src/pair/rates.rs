//! Terms of the equations of motion: each adds its share of one pair's contribution to
//! dv_i/dt, d rho_i/dt and the dissipation rate, and the terms a scenario names run in
//! one neighbour loop ([`EquationsOfMotion`]).

use super::{Field, Fields, Lane, Layouts, Me, Pair, PairTerm, Share, SHARE};
use crate::dim::Vector;

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
    #[cfg(feature = "dim3")]
    pub az: L,
    /// d rho_i/dt [kg/m^3/s].
    pub drho: L,
    /// The viscous dissipation rate of particle i's pairs, P_i, such that the flow
    /// loses (1/2) sum_i m_i P_i [W per metre of depth].
    pub power: L,
    /// A density-diffusion term's share D_i of d rho_i/dt [kg/m^3/s], kept apart from
    /// `drho` for the energy budget (it is added to d rho_i/dt at the end).
    pub diffusion: L,
}

impl<L: Lane> Rates<L> {
    /// dv_i/dt += a, by component.
    #[inline(always)]
    pub fn add_acc(&mut self, a: [L; crate::dim::DIM]) {
        self.ax = self.ax + a[0];
        self.ay = self.ay + a[1];
        #[cfg(feature = "dim3")]
        {
            self.az = self.az + a[2];
        }
    }
    /// dv_i/dt -= a, by component.
    #[inline(always)]
    pub fn sub_acc(&mut self, a: [L; crate::dim::DIM]) {
        self.ax = self.ax - a[0];
        self.ay = self.ay - a[1];
        #[cfg(feature = "dim3")]
        {
            self.az = self.az - a[2];
        }
    }
    /// Every rate 0.
    #[inline(always)]
    pub fn zero() -> Self {
        let z = L::zero();
        Rates {
            coef: z,
            ax: z,
            ay: z,
            #[cfg(feature = "dim3")]
            az: z,
            drho: z,
            power: z,
            diffusion: z,
        }
    }
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
    /// Whether [`RateTerm::pair_both`] gives j's share too, so that each pair is
    /// computed once.
    const SYMMETRIC: bool = false;
    /// Adds i's contribution to `ri`, as [`RateTerm::pair`], and j's contribution of
    /// the same pairs to `rj` (zero on entry): the rates of j, whose neighbour i is,
    /// with x_ji = -x_ij, v_ji = -v_ij and grad_j W_ji = -grad_i W_ij. `rj.coef` is
    /// not read: a [`Rates::coef`] must be symmetric, C_ji = C_ij, and j gets
    /// + m_i C_ij grad_i W_ij. Only called when [`RateTerm::SYMMETRIC`].
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, ri: &mut Rates<L>, rj: &mut Rates<L>) {
        let _ = rj;
        self.pair(me, p, ri)
    }
}

/// The slots of a neighbour's [`super::Share`] in a pass of [`EquationsOfMotion`]:
/// dv_j/dt (x and y, and z in 3D, after the count's slot 3) and d rho_j/dt (density
/// diffusion included).
pub const SHARE_AX: usize = 0;
pub const SHARE_AY: usize = 1;
pub const SHARE_DRHO: usize = 2;
#[cfg(feature = "dim3")]
pub const SHARE_AZ: usize = 4;

/// One particle's rates, summed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RateSums {
    /// dv_i/dt from the pair terms (gravity not included) [m/s^2].
    pub acc: Vector,
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
    /// i's rates, and the energy rates of the neighbours' shares ([`PairTerm::pair_both`]).
    type Acc<L: Lane> = (Rates<L>, JEnergy<L>);
    type Out = RateSums;

    fn reads(&self) -> Fields {
        self.0.reads()
    }

    #[inline(always)]
    fn zero<L: Lane>(&self) -> Self::Acc<L> {
        (
            Rates::zero(),
            JEnergy {
                power: L::zero(),
                diffusion: L::zero(),
            },
        )
    }

    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, acc: &mut Self::Acc<L>) {
        let r = &mut acc.0;
        r.coef = L::zero();
        self.0.pair(me, p, r);
        if R::USES_COEF {
            let mt = p.j(Field::Mass) * r.coef;
            r.ax = r.ax - mt * p.gx;
            r.ay = r.ay - mt * p.gy;
            #[cfg(feature = "dim3")]
            {
                r.az = r.az - mt * p.gz;
            }
        }
    }

    #[inline(always)]
    fn finish<L: Lane>(&self, me: &Me, acc: Self::Acc<L>) -> RateSums {
        let r = acc.0;
        let diffusion = r.diffusion.sum();
        RateSums {
            #[cfg(not(feature = "dim3"))]
            acc: Vector::new(r.ax.sum(), r.ay.sum()),
            #[cfg(feature = "dim3")]
            acc: Vector::new(r.ax.sum(), r.ay.sum(), r.az.sum()),
            drho: r.drho.sum() + diffusion,
            power: 0.5 * me.get(Field::Mass) * r.power.sum(),
            diffusion: me.get(Field::Mass) * me.get(Field::PRho2) * diffusion,
        }
    }

    const SYMMETRIC: bool = R::SYMMETRIC;

    /// j gets + m_i C_ij grad_i W_ij of the coefficient terms and the terms' own
    /// shares ([`RateTerm::pair_both`]) in slots [`SHARE_AX`], [`SHARE_AY`] and
    /// [`SHARE_DRHO`]; its energy rates, (1/2) m_j P_j and m_j (p_j/rho_j^2) D_j, are
    /// summed here, since only their totals are reported.
    #[inline(always)]
    fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, acc: &mut Self::Acc<L>) -> Share<L> {
        let (r, e) = acc;
        let mut rj = Rates::zero();
        r.coef = L::zero();
        self.0.pair_both(me, p, r, &mut rj);
        if R::USES_COEF {
            let mt = p.j(Field::Mass) * r.coef;
            r.ax = r.ax - mt * p.gx;
            r.ay = r.ay - mt * p.gy;
            let mi = me.lanes::<L>(Field::Mass) * r.coef;
            rj.ax = rj.ax + mi * p.gx;
            rj.ay = rj.ay + mi * p.gy;
            #[cfg(feature = "dim3")]
            {
                r.az = r.az - mt * p.gz;
                rj.az = rj.az + mi * p.gz;
            }
        }
        let mj = p.j(Field::Mass);
        e.power = e.power + mj * rj.power;
        e.diffusion = e.diffusion + mj * p.j(Field::PRho2) * rj.diffusion;
        let mut share = [L::zero(); SHARE];
        share[SHARE_AX] = rj.ax;
        share[SHARE_AY] = rj.ay;
        share[SHARE_DRHO] = rj.drho + rj.diffusion;
        #[cfg(feature = "dim3")]
        {
            share[SHARE_AZ] = rj.az;
        }
        share
    }

    /// As [`PairTerm::finish`], with the neighbours' energy rates added to i's.
    #[inline(always)]
    fn finish_both<L: Lane>(&self, me: &Me, acc: Self::Acc<L>) -> RateSums {
        let e = acc.1;
        let own = self.finish(me, acc);
        RateSums {
            power: own.power + 0.5 * e.power.sum(),
            diffusion: own.diffusion + e.diffusion.sum(),
            ..own
        }
    }
}

/// The energy rates of the neighbours' shares of a particle's pairs, in lanes:
/// sum_j m_j P_j and sum_j m_j (p_j/rho_j^2) D_j over the pairs (see [`Rates`]).
#[derive(Clone, Copy)]
pub struct JEnergy<L> {
    power: L,
    diffusion: L,
}
