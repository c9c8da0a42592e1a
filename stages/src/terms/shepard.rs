//! The Shepard filter's sums (docs/physics.md, "Density re-initialisation"):
//!   rho_i = sum_j m_j W_ij / sum_j (m_j/rho_j) W_ij,   j over the neighbours and i.

use sph_core::pair::{Field, Fields, Lane, Layouts, Me, Pair, PairTerm};

/// The Shepard-filtered density, with W(0) for i's own contribution.
#[derive(Clone, Copy, Debug)]
pub struct Shepard {
    pub w0: f64,
}

impl PairTerm for Shepard {
    // Packed with (x, y, rho, m) by its stage.
    const LAYOUTS: Layouts = Layouts::FILTER;
    /// sum m W and sum (m/rho) W.
    type Acc<L: Lane> = [L; 2];
    type Out = f64;
    fn reads(&self) -> Fields {
        Fields::of(&[Field::Rho])
    }
    fn zero<L: Lane>(&self) -> [L; 2] {
        [L::zero(); 2]
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, _: &Me, p: &Pair<L>, [num, den]: &mut [L; 2]) {
        let m = p.j(Field::Mass);
        *num = *num + m * p.w;
        *den = *den + m / p.j(Field::Rho) * p.w;
    }
    #[inline(always)]
    fn finish<L: Lane>(&self, me: &Me, [num, den]: [L; 2]) -> f64 {
        let (m, rho) = (me.get(Field::Mass), me.get(Field::Rho));
        (m * self.w0 + num.sum()) / (m / rho * self.w0 + den.sum())
    }
}
