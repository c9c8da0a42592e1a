//! The momentum and continuity sums of [`crate::forces`] eight neighbours at a time
//! with AVX-512, for the Wendland kernel (every shipped scenario's):
//!   dv_i/dt   = - sum_j m_j (p_i/rho_i^2 + p_j/rho_j^2 + Pi_ij + R f_ij^n) grad_i W_ij
//!   drho_i/dt =   sum_j m_j v_ij . grad_i W_ij
//!
//! Each lane does the scalar loop's arithmetic for one neighbour, operation for
//! operation (no fused multiply-add), so a pair's terms are the scalar ones; only the
//! order of the additions differs: lane l sums neighbours l, l + 8, ..., and the lanes
//! are added at the end. Results therefore differ from the scalar path by round-off,
//! but do not depend on the thread count (the order is fixed by the neighbour list).
//! The eight fields of a neighbour's [`Packed`] record are read with gathers; unused
//! lanes of the last group read a padding particle of zero mass beyond the support.

use crate::forces::{Pair, Sums};
use crate::packed::Packed;
use glam::DVec2;
use sph_core::kernel::KernelKind;
use std::f64::consts::PI;

/// The Wendland C2 kernel's constants, as `sph_core::kernel::Wendland` computes them.
#[derive(Clone, Copy, Debug)]
pub struct WendlandX8 {
    inv_h: f64,
    /// 7 / (4 pi h^2).
    norm: f64,
    /// norm / h^2, for (dW/dr)/r.
    grad_norm: f64,
    support: f64,
}

impl WendlandX8 {
    /// The eight-lane sums for this kernel and smoothing length, where the processor
    /// has AVX-512F and VL; None for other kernels or processors, or with
    /// `SPH_NO_SIMD` set (use the scalar loop).
    pub fn detect(kernel: KernelKind, h: f64) -> Option<Self> {
        if kernel != KernelKind::Wendland || !available() {
            return None;
        }
        let (inv_h, norm) = (1.0 / h, 7.0 / (4.0 * PI) / (h * h));
        Some(Self {
            inv_h,
            norm,
            grad_norm: norm * inv_h * inv_h,
            support: 2.0 * h,
        })
    }

    /// The sums of particle `i` over `neighbours` (joint indices into `all`): the
    /// momentum terms with `FORCES` (artificial pressure with `ART`), the continuity
    /// sum with `RATE`.
    #[inline]
    pub(crate) fn sums<const FORCES: bool, const ART: bool, const RATE: bool>(
        &self,
        prm: &Pair,
        all: &[Packed],
        neighbours: &[u32],
        i: usize,
    ) -> Sums {
        #[cfg(target_arch = "x86_64")]
        {
            assert!(all.len() < (i32::MAX / 8) as usize);
            // SAFETY: `detect` found AVX-512F and VL; every index in `neighbours` is a joint
            // index of the particles `all` was packed from (NeighbourGrid builds them
            // from the same world in the same step), checked below in debug builds.
            debug_assert!(neighbours.iter().all(|&j| (j as usize) < all.len()));
            unsafe { x86::sums::<FORCES, ART, RATE>(self, prm, all, neighbours, i) }
        }
        #[cfg(not(target_arch = "x86_64"))]
        unreachable!("WendlandX8::detect returns None off x86-64")
    }
}

impl WendlandX8 {
    /// The continuity equation's sum_j m_j v_ij . grad_i W_ij alone, term for term as
    /// `sums` evaluates it with `RATE` (so a separate `Continuity()` stage and
    /// `Forces(with_continuity: true)` agree bit for bit).
    #[inline]
    pub fn continuity(&self, all: &[Packed], neighbours: &[u32], i: usize) -> f64 {
        let unused = Pair {
            alpha: 0.0,
            beta: 0.0,
            epsilon: 0.0,
            epsilon_positive: 0.0,
            exponent: 1,
            inv_w_ds: 0.0,
            h: 0.0,
            eta2: 0.0,
        };
        self.sums::<false, false, true>(&unused, all, neighbours, i)
            .rate
    }

    /// The Shepard-filtered density of particle `i` (physics.md, "Density
    /// re-initialisation"): sum_j m_j W_ij / sum_j (m_j/rho_j) W_ij over i itself
    /// and `neighbours`.
    #[inline]
    pub fn shepard(&self, all: &[Packed], neighbours: &[u32], i: usize) -> f64 {
        #[cfg(target_arch = "x86_64")]
        {
            assert!(all.len() < (i32::MAX / 8) as usize);
            debug_assert!(neighbours.iter().all(|&j| (j as usize) < all.len()));
            // SAFETY: as for `sums`.
            unsafe { x86::shepard(self, all, neighbours, i) }
        }
        #[cfg(not(target_arch = "x86_64"))]
        unreachable!("WendlandX8::detect returns None off x86-64")
    }
}

fn available() -> bool {
    #[cfg(target_arch = "x86_64")]
    return crate::scan::simd_allowed()
        && std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::*;
    use std::arch::x86_64::*;

    /// Field offsets in a [`Packed`] record, in f64s.
    const X: usize = 0;
    const Y: usize = 1;
    const VX: usize = 2;
    const VY: usize = 3;
    const RHO: usize = 4;
    const M: usize = 5;
    const P_RHO2: usize = 6;
    const C: usize = 7;
    const _: () = assert!(std::mem::size_of::<Packed>() == 8 * 8);

    /// x^n with the multiplications of `sph_core::sim::whole_pow`, lane by lane.
    #[target_feature(enable = "avx512f")]
    fn whole_pow(x: __m512d, n: u32) -> __m512d {
        let mul = |a, b| _mm512_mul_pd(a, b);
        match n {
            4 => {
                let x2 = mul(x, x);
                mul(x2, x2)
            }
            6 => {
                let x3 = mul(mul(x, x), x);
                mul(x3, x3)
            }
            7 => {
                let x3 = mul(mul(x, x), x);
                mul(mul(x3, x3), x)
            }
            _ => {
                let (mut base, mut e, mut out) = (x, n, _mm512_set1_pd(1.0));
                while e > 0 {
                    if e & 1 == 1 {
                        out = mul(out, base);
                    }
                    base = mul(base, base);
                    e >>= 1;
                }
                out
            }
        }
    }

    /// W(r) of the Wendland C2 kernel, lane by lane, with q = r/h:
    /// norm t^4 (2q + 1), t = 1 - q/2, and 0 from q = 2 on.
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn w(k: &WendlandX8, q: __m512d, t: __m512d) -> __m512d {
        let (set, mul) = (_mm512_set1_pd, _mm512_mul_pd);
        let t2 = mul(t, t);
        let inside = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(q, set(2.0));
        let poly = mul(mul(t2, t2), _mm512_add_pd(mul(set(2.0), q), set(1.0)));
        _mm512_maskz_mov_pd(inside, mul(set(k.norm), poly))
    }

    /// The padding record of particle `me`'s sums: zero mass, beyond the support, at
    /// rest relative to it, as an array of the record's fields.
    fn padding(k: &WendlandX8, me: &Packed) -> [f64; 8] {
        let p = Packed {
            x: me.x + DVec2::new(4.0 * k.support, 0.0),
            m: 0.0,
            p_rho2: 0.0,
            c: 0.0,
            ..*me
        };
        [p.x.x, p.x.y, p.v.x, p.v.y, p.rho, p.m, p.p_rho2, p.c]
    }

    /// # Safety
    /// AVX-512F and VL, and every index in `neighbours` below `all.len()`.
    #[target_feature(enable = "avx512f,avx512vl")]
    pub(super) unsafe fn shepard(
        k: &WendlandX8,
        all: &[Packed],
        neighbours: &[u32],
        i: usize,
    ) -> f64 {
        let me = all[i];
        let (set, sub, mul) = (_mm512_set1_pd, _mm512_sub_pd, _mm512_mul_pd);
        let pad = padding(k, &me);
        let base = all.as_ptr() as *const f64;
        let (xi, yi) = (set(me.x.x), set(me.x.y));
        let (mut num, mut den) = (_mm512_setzero_pd(), _mm512_setzero_pd());
        for js in neighbours.chunks(8) {
            let lanes: __mmask8 = ((1u16 << js.len()) - 1) as u8;
            // SAFETY: as in `sums`.
            let offsets = unsafe { offsets(js, lanes) };
            let g = |field: usize| unsafe { gather(&pad, base, offsets, lanes, field) };
            let (dx, dy) = (sub(xi, g(X)), sub(yi, g(Y)));
            let r = _mm512_sqrt_pd(_mm512_add_pd(mul(dx, dx), mul(dy, dy)));
            let q = mul(r, set(k.inv_h));
            let w = w(k, q, sub(set(1.0), mul(set(0.5), q)));
            let mj = g(M);
            num = _mm512_add_pd(num, mul(mj, w));
            den = _mm512_add_pd(den, mul(_mm512_div_pd(mj, g(RHO)), w));
        }
        // i itself: W(0) = norm.
        let w0 = k.norm;
        let num = me.m * w0 + _mm512_reduce_add_pd(num);
        let den = me.m / me.rho * w0 + _mm512_reduce_add_pd(den);
        num / den
    }

    /// Offsets (in f64s) of the records of `js`, in the lanes `lanes`.
    ///
    /// # Safety
    /// `lanes` covers at most `js.len()` lanes.
    #[target_feature(enable = "avx512f,avx512vl")]
    #[inline]
    unsafe fn offsets(js: &[u32], lanes: __mmask8) -> __m256i {
        let j = unsafe { _mm256_maskz_loadu_epi32(lanes, js.as_ptr() as *const i32) };
        _mm256_slli_epi32::<3>(j)
    }

    /// Field `field` of the records at `offsets` (f64s from `base`) in `lanes`, and
    /// the padding record's in the others.
    ///
    /// # Safety
    /// Every offset in `lanes` addresses a record within the packed buffer at `base`.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn gather(
        pad: &[f64; 8],
        base: *const f64,
        offsets: __m256i,
        lanes: __mmask8,
        field: usize,
    ) -> __m512d {
        let src = _mm512_set1_pd(pad[field]);
        unsafe { _mm512_mask_i32gather_pd::<8>(src, lanes, offsets, base.add(field)) }
    }

    /// # Safety
    /// AVX-512F and VL, and every index in `neighbours` below `all.len()`.
    #[target_feature(enable = "avx512f,avx512vl")]
    pub(super) unsafe fn sums<const FORCES: bool, const ART: bool, const RATE: bool>(
        k: &WendlandX8,
        prm: &Pair,
        all: &[Packed],
        neighbours: &[u32],
        i: usize,
    ) -> Sums {
        let me = all[i];
        let set = _mm512_set1_pd;
        let (add, sub, mul, div) = (_mm512_add_pd, _mm512_sub_pd, _mm512_mul_pd, _mm512_div_pd);
        let pad = padding(k, &me);
        let base = all.as_ptr() as *const f64;
        let (xi, yi, vxi, vyi) = (set(me.x.x), set(me.x.y), set(me.v.x), set(me.v.y));
        let (rhoi, pi_r2, ci) = (set(me.rho), set(me.p_rho2), set(me.c));
        let zero = _mm512_setzero_pd();
        let (mut ax, mut ay, mut power, mut rate) = (zero, zero, zero, zero);
        for js in neighbours.chunks(8) {
            let lanes: __mmask8 = ((1u16 << js.len()) - 1) as u8;
            // SAFETY: the masked load reads js[..js.len()]; the gathers read fields of
            // the records all[j] for those j (below all.len() by the caller's
            // contract), and nothing for the masked-off lanes.
            let offsets = unsafe { offsets(js, lanes) };
            let g = |field: usize| unsafe { gather(&pad, base, offsets, lanes, field) };
            let (xj, yj, vxj, vyj) = (g(X), g(Y), g(VX), g(VY));
            let (rhoj, mj) = (g(RHO), g(M));
            let (dx, dy) = (sub(xi, xj), sub(yi, yj));
            let r = _mm512_sqrt_pd(add(mul(dx, dx), mul(dy, dy)));
            // Wendland C2: t = 1 - q/2, W = norm t^4 (2q + 1), (dW/dr)/r = norm/h^2 (-5 t^3),
            // both zero from q = 2 on; grad W = 0 at r = 0.
            let q = mul(r, set(k.inv_h));
            let t = sub(set(1.0), mul(set(0.5), q));
            let t2 = mul(t, t);
            let inside = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(q, set(2.0));
            let positive = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(r, zero);
            let gf = mul(set(k.grad_norm), mul(set(-5.0), mul(t2, t)));
            let gf = _mm512_maskz_mov_pd(inside & positive, gf);
            let (gx, gy) = (mul(dx, gf), mul(dy, gf));
            let (wx, wy) = (sub(vxi, vxj), sub(vyi, vyj));
            let vij_grad = add(mul(wx, gx), mul(wy, gy));
            if RATE {
                rate = add(rate, mul(mj, vij_grad));
            }
            if !FORCES {
                continue;
            }
            let (pj_r2, cj) = (g(P_RHO2), g(C));
            let mut term = add(pi_r2, pj_r2);
            // Monaghan's artificial viscosity, for approaching pairs (v_ij . x_ij < 0).
            let vx = add(mul(wx, dx), mul(wy, dy));
            let phi = div(mul(set(prm.h), vx), add(mul(r, r), set(prm.eta2)));
            let cbar = mul(set(0.5), add(ci, cj));
            let num = add(
                mul(mul(set(-prm.alpha), cbar), phi),
                mul(mul(set(prm.beta), phi), phi),
            );
            let pi = div(num, mul(set(0.5), add(rhoi, rhoj)));
            let approaching = _mm512_cmp_pd_mask::<_CMP_LT_OQ>(vx, zero);
            let visc = _mm512_maskz_mov_pd(approaching, pi);
            term = add(term, visc);
            if ART {
                let fij = whole_pow(mul(w(k, q, t), set(prm.inv_w_ds)), prm.exponent);
                let both_positive = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(pi_r2, zero)
                    & _mm512_cmp_pd_mask::<_CMP_GT_OQ>(pj_r2, zero);
                let tension = mul(
                    set(prm.epsilon),
                    add(
                        _mm512_max_pd(sub(zero, pi_r2), zero),
                        _mm512_max_pd(sub(zero, pj_r2), zero),
                    ),
                );
                let compression = mul(set(prm.epsilon_positive), add(pi_r2, pj_r2));
                let big_r = _mm512_mask_blend_pd(both_positive, tension, compression);
                term = add(term, mul(big_r, fij));
            }
            let mt = mul(mj, term);
            ax = sub(ax, mul(mt, gx));
            ay = sub(ay, mul(mt, gy));
            power = add(power, mul(mul(mj, visc), vij_grad));
        }
        Sums {
            acc: DVec2::new(_mm512_reduce_add_pd(ax), _mm512_reduce_add_pd(ay)),
            visc_power: _mm512_reduce_add_pd(power),
            rate: _mm512_reduce_add_pd(rate),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::forces::{sum_over_neighbours, Params};
    use sph_core::kernel::{Kernel, Wendland};

    /// A jittered lattice of particles (spacing 1 cm, h = 1.3 cm) with random
    /// velocities, densities and pressures of either sign, and the neighbour list of
    /// particle `i` within the support.
    fn cloud(seed: u64) -> (Vec<Packed>, Vec<u32>, usize, f64) {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let (ds, h) = (0.01, 0.013);
        let mut all = Vec::new();
        for a in 0..9 {
            for b in 0..9 {
                let rho = 1000.0 * (0.97 + 0.06 * next());
                let p = 2000.0 * (next() - 0.3);
                all.push(Packed {
                    x: DVec2::new(a as f64 * ds, b as f64 * ds)
                        + 0.3 * ds * DVec2::new(next() - 0.5, next() - 0.5),
                    v: DVec2::new(next() - 0.5, next() - 0.5),
                    rho,
                    m: 0.1,
                    p_rho2: p / (rho * rho),
                    c: 30.0 + next(),
                });
            }
        }
        let i = 40;
        let near = (0..all.len() as u32)
            .filter(|&j| j as usize != i && (all[i].x - all[j as usize].x).length() < 2.0 * h)
            .collect();
        (all, near, i, h)
    }

    /// The eight-lane sums agree with the scalar loop to round-off (they add the same
    /// terms in another order: relative 1e-12 of the largest term's scale is far
    /// above double round-off over ~20 terms, far below any physical effect).
    #[test]
    fn eight_lanes_match_the_scalar_sums() {
        let Some(x8) = WendlandX8::detect(KernelKind::Wendland, 0.013) else {
            eprintln!("no AVX-512 here (or SPH_NO_SIMD set): nothing to compare");
            return;
        };
        let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-12 * scale;
        for seed in 0..50 {
            let (all, near, i, h) = cloud(seed);
            let k = Wendland::new(h);
            let params = Params {
                artificial_pressure: true,
                beta: 0.1,
                ..Params::default()
            };
            let prm = Pair::new(&params, k.w(0.01), h);
            let a = x8.sums::<true, true, true>(&prm, &all, &near, i);
            let b = sum_over_neighbours::<_, true, true>(&prm, &k, &all, &near, i);
            let scale = b.acc.length().max(1.0);
            assert!(
                close(a.acc.x, b.acc.x, scale) && close(a.acc.y, b.acc.y, scale),
                "seed {seed}: {:?} vs {:?}",
                a.acc,
                b.acc
            );
            assert!(close(a.rate, b.rate, b.rate.abs().max(1.0)), "seed {seed}");
            assert!(
                close(a.visc_power, b.visc_power, b.visc_power.abs().max(1e-6)),
                "seed {seed}"
            );
            assert_eq!(x8.continuity(&all, &near, i), a.rate, "seed {seed}");
            let (mut num, mut den) = (all[i].m * k.w(0.0), all[i].m / all[i].rho * k.w(0.0));
            for &j in &near {
                let pj = &all[j as usize];
                let w = k.w((all[i].x - pj.x).length());
                num += pj.m * w;
                den += pj.m / pj.rho * w;
            }
            let shepard = x8.shepard(&all, &near, i);
            assert!(
                close(shepard, num / den, 1000.0),
                "seed {seed}: {shepard} vs {}",
                num / den
            );
            // Fewer than eight neighbours: the padding lanes add nothing.
            let few = &near[..5];
            let (a, b) = (
                x8.sums::<true, true, true>(&prm, &all, few, i),
                sum_over_neighbours::<_, true, true>(&prm, &k, &all, few, i),
            );
            assert!(close(a.acc.x, b.acc.x, scale) && close(a.rate, b.rate, b.rate.abs().max(1.0)));
        }
    }
}
