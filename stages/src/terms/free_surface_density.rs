//! Density summation with the free-surface correction of SPHinXsys (Zhang, Rezavand &
//! Hu; docs/physics.md, "Density re-initialisation"):
//!   rho_sum = sum_j m_j W_ij / (sigma_0 ds^2)         (j over the neighbours and i),
//!   rho_i   = rho_sum + max(0, rho_i - rho_sum) rho_0 / rho_i,
//! sigma_0 the number density of a full neighbourhood at rest
//! ([`sph_core::kernel::lattice_sum`]), so that the starting lattice sums to rho_0 and
//! not to 1 % more (Wendland, h = 1.3 ds), which would swell the liquid by as much.
//! In the bulk the kernel is full and rho_sum >= rho_i there is the summation itself; at
//! a free surface the kernel is cut and rho_sum falls short by the missing share, which
//! the second term puts back in proportion to it: a particle that leaves the fluid at
//! rest density keeps it, so spray does not carry the tension a continuity equation
//! gives a particle that loses its neighbours.

use sph_core::pair::{Field, Fields, Lane, Layouts, Me, Pair, PairTerm};

/// The summed density, corrected where the kernel is cut by a free surface.
#[derive(Clone, Copy, Debug)]
pub struct FreeSurfaceDensity {
    /// W(0), for i's own contribution.
    pub w0: f64,
    /// Rest density rho_0 [kg/m^3].
    pub rho0: f64,
    /// 1 / (sigma_0 ds^2) [-]: the starting lattice's sum of W ds^2, inverted.
    pub inv_lattice_sum: f64,
}

impl PairTerm for FreeSurfaceDensity {
    // Packed with (x, y, rho, m) by its stage.
    const LAYOUTS: Layouts = Layouts::FILTER;
    /// sum m W.
    type Acc<L: Lane> = L;
    type Out = f64;
    fn reads(&self) -> Fields {
        Fields::of(&[Field::Rho])
    }
    fn zero<L: Lane>(&self) -> L {
        L::zero()
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, _: &Me, p: &Pair<L>, sum: &mut L) {
        *sum = *sum + p.j(Field::Mass) * p.w;
    }
    #[inline(always)]
    fn finish<L: Lane>(&self, me: &Me, sum: L) -> f64 {
        self.density(me.get(Field::Mass), me.get(Field::Rho), sum.sum())
    }
}

impl FreeSurfaceDensity {
    /// The corrected density of a particle of mass `m` and density `rho` whose
    /// neighbours sum to `sum` = sum_j m_j W_ij (i excluded).
    #[inline]
    pub fn density(&self, m: f64, rho: f64, sum: f64) -> f64 {
        let summed = (m * self.w0 + sum) * self.inv_lattice_sum;
        // `rho` is positive: the integrator stops a run whose density is not.
        summed + (rho - summed).max(0.0) * self.rho0 / rho
    }
}
