//! Colagrossi & Landrini's (2003) first-order moving-least-squares density filter
//! (docs/physics.md, "Density re-initialisation", the more accurate alternative to Shepard):
//!
//!   rho_i = sum_j m_j W^MLS_ij,   W^MLS_ij = (b_0 + b_1 (x_i - x_j) + b_2 (y_i - y_j)) W_ij,
//!   (b_0, b_1, b_2) = A^-1 (1, 0, 0),   A = sum_j W_ij V_j [1 d^T; d d d^T],  d = x_i - x_j,
//!
//! with V_j = m_j / rho_j and j over the neighbours and i itself (in 3D with the z term:
//! A is 4 x 4 and its first column of the inverse comes from glam's `DMat4`). It
//! reproduces a linear density field exactly, so unlike the Shepard filter it does not
//! raise the density of free-surface particles towards the denser water below them (a
//! Shepard filter every step lifts a still free surface; see docs/validation.md). Where
//! the neighbourhood is too one-sided or too sparse for A to be well conditioned (lone
//! spray particles), the Shepard value is used instead.

use sph_core::dim::{Vector, DIM};
use sph_core::pair::{Field, Fields, Lane, Layouts, Me, Pair, PairTerm};

/// Smallest accepted det(A) / (A_00 A_11 ... A_DD): below it A is near singular.
const MIN_CONDITION: f64 = 1e-3;

/// The entries of A's upper triangle: A is (DIM + 1) x (DIM + 1).
const N_A: usize = (DIM + 1) * (DIM + 2) / 2;

/// Running sums for one particle's filtered density.
#[derive(Clone, Copy, Debug, Default)]
pub struct MlsSums {
    /// Upper triangle of A, row by row: a00 (= sum V W, the Shepard denominator), a01,
    /// a02, (a03,) a11, a12, (a13,) a22 (, a23, a33).
    a: [f64; N_A],
    /// Mass moments sum m W (the Shepard numerator) and sum m W d, which give
    /// sum m W^MLS once A is known.
    m0: f64,
    m1: Vector,
}

/// (1, d): the basis of the linear fit at offset d.
#[inline(always)]
fn basis(d: Vector) -> [f64; DIM + 1] {
    let mut e = [1.0; DIM + 1];
    e[1..].copy_from_slice(&d.to_array());
    e
}

impl MlsSums {
    /// Adds neighbour j (or i itself with d = 0): d = x_i - x_j, kernel value w.
    #[inline(always)]
    pub fn add(&mut self, d: Vector, w: f64, m: f64, rho: f64) {
        let vw = m / rho * w;
        let e = basis(d);
        let mut k = 0;
        for r in 0..=DIM {
            for c in r..=DIM {
                // vw e_r e_c: multiplying by the basis' 1 is exact.
                self.a[k] += vw * e[r] * e[c];
                k += 1;
            }
        }
        self.m0 += m * w;
        self.m1 += m * w * d;
    }

    /// The Shepard-filtered density sum m W / sum V W.
    pub fn shepard(&self) -> f64 {
        self.m0 / self.a[0]
    }

    /// The MLS density, or the Shepard one where A is ill conditioned.
    #[cfg(not(feature = "dim3"))]
    pub fn mls(&self) -> f64 {
        let [a00, a01, a02, a11, a12, a22] = self.a;
        // First column of A^-1 by cofactors (A symmetric).
        let c00 = a11 * a22 - a12 * a12;
        let c01 = -(a01 * a22 - a12 * a02);
        let c02 = a01 * a12 - a11 * a02;
        let det = a00 * c00 + a01 * c01 + a02 * c02;
        let scale = a00 * a11 * a22;
        if scale.is_nan() || scale <= 0.0 || det / scale < MIN_CONDITION {
            return self.shepard();
        }
        let b = Vector::new(c01, c02) / det;
        // sum_j m_j (b0 + b . d) W = b0 sum m W + b . sum m W d
        c00 / det * self.m0 + b.dot(self.m1)
    }

    /// The MLS density, or the Shepard one where A is ill conditioned.
    #[cfg(feature = "dim3")]
    pub fn mls(&self) -> f64 {
        let [a00, a01, a02, a03, a11, a12, a13, a22, a23, a33] = self.a;
        let det3 = |c0: [f64; 3], c1: [f64; 3], c2: [f64; 3]| {
            glam::DMat3::from_cols_array_2d(&[c0, c1, c2]).determinant()
        };
        // First row of A^-1 (= its first column, A symmetric) by cofactors: row 0's
        // minors are rows 1-3 with one column left out; k_j is column j of those rows.
        let (k0, k1) = ([a01, a02, a03], [a11, a12, a13]);
        let (k2, k3) = ([a12, a22, a23], [a13, a23, a33]);
        let c0 = det3(k1, k2, k3);
        let c1 = -det3(k0, k2, k3);
        let c2 = det3(k0, k1, k3);
        let c3 = -det3(k0, k1, k2);
        let det = a00 * c0 + a01 * c1 + a02 * c2 + a03 * c3;
        let scale = a00 * a11 * a22 * a33;
        if scale.is_nan() || scale <= 0.0 || det / scale < MIN_CONDITION {
            return self.shepard();
        }
        let b = Vector::new(c1, c2, c3) / det;
        // sum_j m_j (b0 + b . d) W = b0 sum m W + b . sum m W d
        c0 / det * self.m0 + b.dot(self.m1)
    }
}

/// The MLS-filtered density as a pair term, with W(0) for i's own contribution.
#[derive(Clone, Copy, Debug)]
pub struct Mls {
    pub w0: f64,
}

/// The lanes' sums: A's upper triangle, sum m W, sum m W d.
const N_ACC: usize = N_A + 1 + DIM;

impl PairTerm for Mls {
    // Packed with (x, y, rho, m) by its stage.
    const LAYOUTS: Layouts = Layouts::FILTER;
    /// The sums of [`MlsSums`] in lanes: A's upper triangle, sum m W, sum m W d.
    type Acc<L: Lane> = [L; N_ACC];
    type Out = f64;
    fn reads(&self) -> Fields {
        Fields::of(&[Field::Rho])
    }
    fn zero<L: Lane>(&self) -> [L; N_ACC] {
        [L::zero(); N_ACC]
    }
    /// A's upper triangle over the basis (1, d), row by row, then m W (1, d).
    #[inline(always)]
    fn pair<L: Lane>(&self, _: &Me, p: &Pair<L>, s: &mut [L; N_ACC]) {
        let (m, w) = (p.j(Field::Mass), p.w);
        let vw = m / p.j(Field::Rho) * w;
        let mw = m * w;
        let d = p.x_ij();
        // Row 0 of A: vw (1, d).
        s[0] = s[0] + vw;
        for (k, &dk) in d.iter().enumerate() {
            s[1 + k] = s[1 + k] + vw * dk;
        }
        // The other rows: vw d_r d_c, c >= r.
        let mut k = 1 + DIM;
        for (r, &dr) in d.iter().enumerate() {
            for &dc in &d[r..] {
                s[k] = s[k] + vw * dr * dc;
                k += 1;
            }
        }
        s[N_A] = s[N_A] + mw;
        for (k, &dk) in d.iter().enumerate() {
            s[N_A + 1 + k] = s[N_A + 1 + k] + mw * dk;
        }
    }
    #[inline(always)]
    fn finish<L: Lane>(&self, me: &Me, s: [L; N_ACC]) -> f64 {
        let s = s.map(L::sum);
        let mut a = [0.0; N_A];
        a.copy_from_slice(&s[..N_A]);
        let mut sums = MlsSums {
            a,
            m0: s[N_A],
            m1: Vector::from_slice(&s[N_A + 1..]),
        };
        sums.add(
            Vector::ZERO,
            self.w0,
            me.get(Field::Mass),
            me.get(Field::Rho),
        );
        sums.mls()
    }
}

#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use glam::DVec2;
    use sph_core::kernel::{Kernel, Wendland};

    /// A jittered lattice patch around the origin with a linear density field, cut
    /// along the diagonal x + 2 y = cut (a free surface through or above the particle),
    /// so that no sum of A vanishes by symmetry.
    fn filtered(cut: f64) -> (f64, f64, f64) {
        let (ds, h) = (0.01, 0.013);
        let k = Wendland::new(h);
        let rho = |p: DVec2| 1000.0 - 3000.0 * p.y + 500.0 * p.x; // denser below
        let xi = DVec2::ZERO;
        let mut s = MlsSums::default();
        s.add(DVec2::ZERO, k.w(0.0), rho(xi) * ds * ds, rho(xi));
        let mut state = 7u64;
        let mut jitter = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.3 * ds
        };
        for i in -4i32..=4 {
            for j in -4i32..=4 {
                let p = DVec2::new(i as f64, j as f64) * ds + DVec2::new(jitter(), jitter());
                if (i, j) == (0, 0) || p.x + 2.0 * p.y > cut + 1e-12 {
                    continue;
                }
                let r = rho(p);
                s.add(xi - p, k.w(p.length()), r * ds * ds, r);
            }
        }
        (s.mls(), s.shepard(), rho(xi))
    }

    #[test]
    fn reproduces_a_linear_density_inside_and_at_a_free_surface() {
        for cut in [1.0, 0.0] {
            let (mls, shepard, exact) = filtered(cut);
            assert!(
                (mls - exact).abs() < 1e-9 * exact,
                "cut {cut}: {mls} vs {exact}"
            );
            if cut == 0.0 {
                // Shepard averages the denser water below: biased upward.
                assert!(shepard > exact + 1.0, "{shepard} vs {exact}");
            }
        }
    }

    #[test]
    fn a_lone_particle_keeps_its_shepard_value() {
        let mut s = MlsSums::default();
        s.add(DVec2::ZERO, 1.0, 0.1, 990.0);
        assert_eq!(s.mls(), 990.0);
    }

    /// Neighbours nearly on a slanted line (a thin jet): A is near singular, det(A) /
    /// (A_00 A_11 A_22) below the threshold but above 0, and the Shepard value is
    /// kept; spread out a little more, above the threshold, MLS takes over.
    #[test]
    fn a_nearly_collinear_neighbourhood_keeps_its_shepard_value() {
        let condition = |spread: f64| {
            let mut s = MlsSums::default();
            for (k, x) in [-0.02, -0.01, 0.0, 0.01, 0.02].into_iter().enumerate() {
                let y = 0.5 * x + spread * [1.0, -1.0, 0.0, 1.0, -1.0][k];
                let rho = 990.0 + 10.0 * k as f64;
                s.add(DVec2::new(x, y), 1.0 - 20.0 * x.abs(), 0.1, rho);
            }
            let [a00, a01, a02, a11, a12, a22] = s.a;
            let det = a00 * (a11 * a22 - a12 * a12) - a01 * (a01 * a22 - a12 * a02)
                + a02 * (a01 * a12 - a11 * a02);
            (det / (a00 * a11 * a22), s.mls(), s.shepard())
        };
        let (thin, mls, shepard) = condition(1e-4);
        assert!(thin > 0.0 && thin < MIN_CONDITION, "{thin}");
        assert_eq!(mls, shepard);
        let (wide, mls, shepard) = condition(5e-3);
        assert!(wide > MIN_CONDITION, "{wide}");
        assert!((mls - shepard).abs() > 1e-6, "{mls} against {shepard}");
    }
}
