//! The momentum and continuity sums of [`crate::forces`] and the Shepard filter of
//! [`crate::reinitialise`] eight neighbours at a time, for the Wendland kernel (every
//! shipped scenario's), with AVX-512 or, on processors without it, AVX2:
//!   dv_i/dt   = - sum_j m_j (p_i/rho_i^2 + p_j/rho_j^2 + Pi_ij + R f_ij^n) grad_i W_ij
//!   drho_i/dt =   sum_j m_j v_ij . grad_i W_ij
//!   rho_i     =   sum_j m_j W_ij / sum_j (m_j/rho_j) W_ij
//!
//! Each lane does the scalar loop's arithmetic for one neighbour, operation for
//! operation (no fused multiply-add), so a pair's terms are the scalar ones; only the
//! order of the additions differs: lane l sums neighbours l, l + 8, ..., and the eight
//! lanes are added in a fixed tree at the end. Results therefore differ from the
//! scalar path by round-off, but are the same for any thread count and on AVX2 and
//! AVX-512 processors alike (one lane algebra, [`x86::Lanes`], two implementations).
//! The fields of a neighbour's [`Packed`] record are read with gathers; unused lanes
//! of the last group read a padding particle of zero mass beyond the support.

use crate::forces::{Pair, Sums};
use crate::packed::Packed;
use glam::DVec2;
use sph_core::kernel::{Kernel, KernelKind, Wendland};

/// The instruction set of the eight-lane sums.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// One 512-bit vector per quantity.
    Avx512,
    /// Two 256-bit vectors per quantity.
    Avx2,
}

impl Isa {
    /// The widest the processor supports; None without AVX2 or with `SPH_NO_SIMD` set.
    /// `SPH_SIMD=avx2` keeps to AVX2 on an AVX-512 processor (to measure that path).
    pub fn detect() -> Option<Self> {
        static ISA: std::sync::OnceLock<Option<Isa>> = std::sync::OnceLock::new();
        *ISA.get_or_init(Self::probe)
    }

    /// [`Isa::detect`]'s answer, worked out once per process.
    fn probe() -> Option<Self> {
        #[cfg(target_arch = "x86_64")]
        if crate::scan::simd_allowed() {
            use std::arch::is_x86_feature_detected as has;
            let avx2_only = std::env::var_os("SPH_SIMD").is_some_and(|v| v == "avx2");
            if has!("avx512f") && has!("avx512vl") && !avx2_only {
                return Some(Isa::Avx512);
            }
            if has!("avx2") {
                return Some(Isa::Avx2);
            }
        }
        None
    }

    /// Every one this processor can run (for tests comparing them).
    pub fn available() -> Vec<Self> {
        match Self::detect() {
            Some(Isa::Avx512) => vec![Isa::Avx512, Isa::Avx2],
            Some(Isa::Avx2) => vec![Isa::Avx2],
            None => vec![],
        }
    }
}

/// The Wendland C2 kernel's constants, taken from `sph_core::kernel::Wendland`, and
/// the instruction set to sum with.
#[derive(Clone, Copy, Debug)]
pub struct WendlandX8 {
    isa: Isa,
    inv_h: f64,
    /// 7 / (4 pi h^2).
    norm: f64,
    /// norm / h^2, for (dW/dr)/r.
    grad_norm: f64,
    support: f64,
}

impl WendlandX8 {
    /// The eight-lane sums for this kernel and smoothing length, where the processor
    /// has AVX2 or AVX-512; None for other kernels or processors, or with
    /// `SPH_NO_SIMD` set (use the scalar loop).
    pub fn detect(kernel: KernelKind, h: f64) -> Option<Self> {
        if kernel != KernelKind::Wendland {
            return None;
        }
        Isa::detect().map(|isa| Self::with_isa(isa, h))
    }

    /// The sums with a given instruction set, which the processor must have (see
    /// [`Isa::available`]).
    pub fn with_isa(isa: Isa, h: f64) -> Self {
        let k = Wendland::new(h);
        let (inv_h, norm) = (k.inv_h(), k.norm());
        Self {
            isa,
            inv_h,
            norm,
            // As Wendland::grad_factor forms it.
            grad_norm: norm * inv_h * inv_h,
            support: k.support(),
        }
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
        check(all, neighbours);
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the instruction set was found on this processor (`Isa::detect`), and
        // every index in `neighbours` is below `all.len()` (the callers check
        // `Neighbours::check_covers` each step; `check` re-checks in debug builds).
        unsafe {
            match self.isa {
                Isa::Avx512 => x86::sums_avx512::<FORCES, ART, RATE>(self, prm, all, neighbours, i),
                Isa::Avx2 => x86::sums_avx2::<FORCES, ART, RATE>(self, prm, all, neighbours, i),
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        unreachable!("no instruction set is detected off x86-64")
    }

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
        check(all, neighbours);
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `sums`.
        unsafe {
            match self.isa {
                Isa::Avx512 => x86::shepard_avx512(self, all, neighbours, i),
                Isa::Avx2 => x86::shepard_avx2(self, all, neighbours, i),
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        unreachable!("no instruction set is detected off x86-64")
    }
}

/// What the gathers rely on: record offsets fit an i32, and every neighbour is a
/// particle of `all` (the callers check `Neighbours::check_covers` once per step; per
/// neighbour only in debug builds).
#[inline(always)]
fn check(all: &[Packed], neighbours: &[u32]) {
    assert!(all.len() < (i32::MAX / 8) as usize);
    debug_assert!(neighbours.iter().all(|&j| (j as usize) < all.len()));
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod x86 {
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

    /// Eight f64 lanes and the operations the sums need. Every method is
    /// `#[inline(always)]` and is only called from functions compiled with the
    /// implementation's target features, where its intrinsics inline.
    ///
    /// # Safety
    /// Callers must run on a processor with the implementation's features.
    pub(crate) trait Lanes: Copy {
        type Mask: Copy;
        /// The lanes in use for a group of `js` (the first `js.len()` of eight), with
        /// the record offsets of `js`.
        type Index: Copy;
        unsafe fn splat(x: f64) -> Self;
        unsafe fn add(self, b: Self) -> Self;
        unsafe fn sub(self, b: Self) -> Self;
        unsafe fn mul(self, b: Self) -> Self;
        unsafe fn div(self, b: Self) -> Self;
        unsafe fn sqrt(self) -> Self;
        unsafe fn max(self, b: Self) -> Self;
        /// Lanes where self < b (ordered, quiet).
        unsafe fn lt(self, b: Self) -> Self::Mask;
        unsafe fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask;
        /// self where `m`, else 0.
        unsafe fn keep(self, m: Self::Mask) -> Self;
        /// `yes` where `m`, else `no`.
        unsafe fn select(m: Self::Mask, yes: Self, no: Self) -> Self;
        /// # Safety
        /// `js.len()` is 1 to 8.
        unsafe fn index(js: &[u32]) -> Self::Index;
        /// Field `field` of the records of `index` (f64s from `base`), `pad` elsewhere.
        ///
        /// # Safety
        /// Every record of `index` lies within the buffer at `base`.
        unsafe fn gather(index: Self::Index, base: *const f64, field: usize, pad: f64) -> Self;
        unsafe fn to_array(self) -> [f64; 8];
    }

    /// The sum of the lanes in a fixed order (the same for every implementation).
    #[inline(always)]
    unsafe fn reduce<V: Lanes>(v: V) -> f64 {
        let a = unsafe { v.to_array() };
        ((a[0] + a[1]) + (a[2] + a[3])) + ((a[4] + a[5]) + (a[6] + a[7]))
    }

    /// The element-wise arithmetic of a [`Lanes`] type, each operation by the given
    /// intrinsic through the type's `each`.
    macro_rules! arithmetic {
        ($($name:ident => $op:ident),*) => {$(
            #[inline(always)]
            unsafe fn $name(self, b: Self) -> Self {
                unsafe { self.each(b, |x, y| $op(x, y)) }
            }
        )*};
    }

    #[derive(Clone, Copy)]
    pub(crate) struct Avx512(__m512d);

    impl Avx512 {
        #[inline(always)]
        unsafe fn each(self, b: Self, f: impl Fn(__m512d, __m512d) -> __m512d) -> Self {
            Self(f(self.0, b.0))
        }
    }

    impl Lanes for Avx512 {
        type Mask = __mmask8;
        type Index = (__m256i, __mmask8);
        arithmetic!(add => _mm512_add_pd, sub => _mm512_sub_pd, mul => _mm512_mul_pd,
                    div => _mm512_div_pd, max => _mm512_max_pd);
        #[inline(always)]
        unsafe fn splat(x: f64) -> Self {
            Self(_mm512_set1_pd(x))
        }
        #[inline(always)]
        unsafe fn sqrt(self) -> Self {
            Self(_mm512_sqrt_pd(self.0))
        }
        #[inline(always)]
        unsafe fn lt(self, b: Self) -> __mmask8 {
            _mm512_cmp_pd_mask::<_CMP_LT_OQ>(self.0, b.0)
        }
        #[inline(always)]
        unsafe fn and(a: __mmask8, b: __mmask8) -> __mmask8 {
            a & b
        }
        #[inline(always)]
        unsafe fn keep(self, m: __mmask8) -> Self {
            Self(_mm512_maskz_mov_pd(m, self.0))
        }
        #[inline(always)]
        unsafe fn select(m: __mmask8, yes: Self, no: Self) -> Self {
            Self(_mm512_mask_blend_pd(m, no.0, yes.0))
        }
        #[inline(always)]
        unsafe fn index(js: &[u32]) -> Self::Index {
            let lanes = ((1u16 << js.len()) - 1) as u8;
            // SAFETY: the masked load reads js[..js.len()] only.
            let j = unsafe { _mm256_maskz_loadu_epi32(lanes, js.as_ptr() as *const i32) };
            (_mm256_slli_epi32::<3>(j), lanes)
        }
        #[inline(always)]
        unsafe fn gather(index: Self::Index, base: *const f64, field: usize, pad: f64) -> Self {
            let (offsets, lanes) = index;
            let src = _mm512_set1_pd(pad);
            Self(unsafe { _mm512_mask_i32gather_pd::<8>(src, lanes, offsets, base.add(field)) })
        }
        #[inline(always)]
        unsafe fn to_array(self) -> [f64; 8] {
            let mut a = [0.0; 8];
            unsafe { _mm512_storeu_pd(a.as_mut_ptr(), self.0) };
            a
        }
    }

    /// Lanes 0-3 and 4-7.
    #[derive(Clone, Copy)]
    pub(crate) struct Avx2([__m256d; 2]);

    impl Avx2 {
        #[inline(always)]
        unsafe fn each(self, b: Self, f: impl Fn(__m256d, __m256d) -> __m256d) -> Self {
            Self([f(self.0[0], b.0[0]), f(self.0[1], b.0[1])])
        }
    }

    impl Lanes for Avx2 {
        /// All ones in the lanes that are set.
        type Mask = [__m256d; 2];
        /// Record offsets, and the lanes in use as a mask.
        type Index = ([__m128i; 2], [__m256d; 2]);
        arithmetic!(add => _mm256_add_pd, sub => _mm256_sub_pd, mul => _mm256_mul_pd,
                    div => _mm256_div_pd, max => _mm256_max_pd);
        #[inline(always)]
        unsafe fn splat(x: f64) -> Self {
            Self([_mm256_set1_pd(x); 2])
        }
        #[inline(always)]
        unsafe fn sqrt(self) -> Self {
            Self([_mm256_sqrt_pd(self.0[0]), _mm256_sqrt_pd(self.0[1])])
        }
        #[inline(always)]
        unsafe fn lt(self, b: Self) -> Self::Mask {
            unsafe { self.each(b, |x, y| _mm256_cmp_pd::<_CMP_LT_OQ>(x, y)) }.0
        }
        #[inline(always)]
        unsafe fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask {
            unsafe { Self(a).each(Self(b), |x, y| _mm256_and_pd(x, y)) }.0
        }
        #[inline(always)]
        unsafe fn keep(self, m: Self::Mask) -> Self {
            unsafe { Self(m).each(self, |m, x| _mm256_and_pd(m, x)) }
        }
        #[inline(always)]
        unsafe fn select(m: Self::Mask, yes: Self, no: Self) -> Self {
            Self([
                _mm256_blendv_pd(no.0[0], yes.0[0], m[0]),
                _mm256_blendv_pd(no.0[1], yes.0[1], m[1]),
            ])
        }
        #[inline(always)]
        unsafe fn index(js: &[u32]) -> Self::Index {
            // Unused lanes gather nothing (masked off); their offset 0 is never read.
            let mut j = [0i32; 8];
            for (o, &x) in j.iter_mut().zip(js) {
                *o = (x as i32) << 3;
            }
            let used = |l: usize| if l < js.len() { -1i64 } else { 0 };
            let lanes = |l: usize| {
                _mm256_castsi256_pd(_mm256_set_epi64x(
                    used(l + 3),
                    used(l + 2),
                    used(l + 1),
                    used(l),
                ))
            };
            // SAFETY: reads of the local array.
            let (lo, hi) = unsafe {
                (
                    _mm_loadu_si128(j.as_ptr() as *const __m128i),
                    _mm_loadu_si128(j.as_ptr().add(4) as *const __m128i),
                )
            };
            ([lo, hi], [lanes(0), lanes(4)])
        }
        #[inline(always)]
        unsafe fn gather(index: Self::Index, base: *const f64, field: usize, pad: f64) -> Self {
            let (offsets, lanes) = index;
            let src = _mm256_set1_pd(pad);
            // SAFETY: the caller's contract; masked-off lanes are not read.
            unsafe {
                let p = base.add(field);
                Self([
                    _mm256_mask_i32gather_pd::<8>(src, p, offsets[0], lanes[0]),
                    _mm256_mask_i32gather_pd::<8>(src, p, offsets[1], lanes[1]),
                ])
            }
        }
        #[inline(always)]
        unsafe fn to_array(self) -> [f64; 8] {
            let mut a = [0.0; 8];
            unsafe {
                _mm256_storeu_pd(a.as_mut_ptr(), self.0[0]);
                _mm256_storeu_pd(a.as_mut_ptr().add(4), self.0[1]);
            }
            a
        }
    }

    /// x^n with the multiplications of `sph_core::sim::whole_pow`, lane by lane.
    #[inline(always)]
    unsafe fn whole_pow<V: Lanes>(x: V, n: u32) -> V {
        unsafe {
            match n {
                4 => {
                    let x2 = x.mul(x);
                    x2.mul(x2)
                }
                6 => {
                    let x3 = x.mul(x).mul(x);
                    x3.mul(x3)
                }
                7 => {
                    let x3 = x.mul(x).mul(x);
                    x3.mul(x3).mul(x)
                }
                _ => {
                    let (mut base, mut e, mut out) = (x, n, V::splat(1.0));
                    while e > 0 {
                        if e & 1 == 1 {
                            out = out.mul(base);
                        }
                        base = base.mul(base);
                        e >>= 1;
                    }
                    out
                }
            }
        }
    }

    /// W(r) of the Wendland C2 kernel with q = r/h and t = 1 - q/2:
    /// norm t^4 (2q + 1), and 0 from q = 2 on.
    #[inline(always)]
    unsafe fn w<V: Lanes>(k: &WendlandX8, q: V, t: V) -> V {
        unsafe {
            let t2 = t.mul(t);
            let poly = t2.mul(t2).mul(V::splat(2.0).mul(q).add(V::splat(1.0)));
            V::splat(k.norm).mul(poly).keep(q.lt(V::splat(2.0)))
        }
    }

    /// One group of up to eight neighbours of particle i: the geometry every sum
    /// needs, and the gather of any other field.
    struct Group<V: Lanes> {
        index: V::Index,
        base: *const f64,
        /// The padding record (zero mass, beyond the support, at rest relative to i)
        /// read by the unused lanes.
        pad: [f64; 8],
        /// x_ij, y_ij, r_ij, q = r/h and t = 1 - q/2.
        dx: V,
        dy: V,
        r: V,
        q: V,
        t: V,
    }

    impl<V: Lanes> Group<V> {
        /// Field `field` of the group's records.
        #[inline(always)]
        unsafe fn get(&self, field: usize) -> V {
            // SAFETY: the records of `index` are particles of the buffer at `base`
            // (the caller's contract of `for_each_group`).
            unsafe { V::gather(self.index, self.base, field, self.pad[field]) }
        }
    }

    /// Calls `f` for each group of eight of particle `i`'s neighbours.
    ///
    /// # Safety
    /// `V`'s features, and every index in `neighbours` below `all.len()`.
    #[inline(always)]
    unsafe fn for_each_group<V: Lanes>(
        k: &WendlandX8,
        all: &[Packed],
        neighbours: &[u32],
        i: usize,
        mut f: impl FnMut(&Group<V>),
    ) {
        let me = all[i];
        let p = Packed {
            x: me.x + DVec2::new(4.0 * k.support, 0.0),
            m: 0.0,
            p_rho2: 0.0,
            c: 0.0,
            ..me
        };
        let pad = [p.x.x, p.x.y, p.v.x, p.v.y, p.rho, p.m, p.p_rho2, p.c];
        let base = all.as_ptr() as *const f64;
        unsafe {
            let s = V::splat;
            let (xi, yi) = (s(me.x.x), s(me.x.y));
            for js in neighbours.chunks(8) {
                let index = V::index(js);
                let (xj, yj) = (
                    V::gather(index, base, X, pad[X]),
                    V::gather(index, base, Y, pad[Y]),
                );
                let (dx, dy) = (xi.sub(xj), yi.sub(yj));
                let r = dx.mul(dx).add(dy.mul(dy)).sqrt();
                let q = r.mul(s(k.inv_h));
                let t = s(1.0).sub(s(0.5).mul(q));
                f(&Group {
                    index,
                    base,
                    pad,
                    dx,
                    dy,
                    r,
                    q,
                    t,
                });
            }
        }
    }

    /// See [`WendlandX8::shepard`].
    ///
    /// # Safety
    /// `V`'s features, and every index in `neighbours` below `all.len()`.
    #[inline(always)]
    unsafe fn shepard<V: Lanes>(
        k: &WendlandX8,
        all: &[Packed],
        neighbours: &[u32],
        i: usize,
    ) -> f64 {
        let me = all[i];
        unsafe {
            let (mut num, mut den) = (V::splat(0.0), V::splat(0.0));
            for_each_group::<V>(k, all, neighbours, i, |g| {
                let w = w(k, g.q, g.t);
                let mj = g.get(M);
                num = num.add(mj.mul(w));
                den = den.add(mj.div(g.get(RHO)).mul(w));
            });
            // i itself: W(0) = norm.
            let w0 = k.norm;
            let num = me.m * w0 + reduce(num);
            let den = me.m / me.rho * w0 + reduce(den);
            num / den
        }
    }

    /// See [`WendlandX8::sums`].
    ///
    /// # Safety
    /// `V`'s features, and every index in `neighbours` below `all.len()`.
    #[inline(always)]
    unsafe fn sums<V: Lanes, const FORCES: bool, const ART: bool, const RATE: bool>(
        k: &WendlandX8,
        prm: &Pair,
        all: &[Packed],
        neighbours: &[u32],
        i: usize,
    ) -> Sums {
        let me = all[i];
        unsafe {
            let s = V::splat;
            let (vxi, vyi) = (s(me.v.x), s(me.v.y));
            let (rhoi, pi_r2, ci) = (s(me.rho), s(me.p_rho2), s(me.c));
            let zero = s(0.0);
            let (mut ax, mut ay, mut power, mut rate) = (zero, zero, zero, zero);
            for_each_group::<V>(k, all, neighbours, i, |grp| {
                let Group {
                    dx, dy, r, q, t, ..
                } = *grp;
                let g = |field: usize| grp.get(field);
                // Wendland C2: (dW/dr)/r = norm/h^2 (-5 t^3), zero from q = 2 on and
                // at r = 0 (grad W = 0 there).
                let inside = V::and(q.lt(s(2.0)), zero.lt(r));
                let gf = s(k.grad_norm)
                    .mul(s(-5.0).mul(t.mul(t).mul(t)))
                    .keep(inside);
                let (gx, gy) = (dx.mul(gf), dy.mul(gf));
                let (wx, wy) = (vxi.sub(g(VX)), vyi.sub(g(VY)));
                let vij_grad = wx.mul(gx).add(wy.mul(gy));
                let mj = g(M);
                if RATE {
                    rate = rate.add(mj.mul(vij_grad));
                }
                if !FORCES {
                    return;
                }
                let (pj_r2, cj, rhoj) = (g(P_RHO2), g(C), g(RHO));
                let mut term = pi_r2.add(pj_r2);
                // Monaghan's artificial viscosity, for approaching pairs (v_ij . x_ij < 0).
                let vx = wx.mul(dx).add(wy.mul(dy));
                let phi = s(prm.h).mul(vx).div(r.mul(r).add(s(prm.eta2)));
                let cbar = s(0.5).mul(ci.add(cj));
                let num = s(-prm.alpha)
                    .mul(cbar)
                    .mul(phi)
                    .add(s(prm.beta).mul(phi).mul(phi));
                let visc = num.div(s(0.5).mul(rhoi.add(rhoj))).keep(vx.lt(zero));
                term = term.add(visc);
                if ART {
                    // R = eps (|p_i|/rho_i^2 + |p_j|/rho_j^2) over the negative
                    // pressures, or eps_+ (p_i/rho_i^2 + p_j/rho_j^2) when both are
                    // positive; f_ij = (W/W(ds))^n.
                    let fij = whole_pow(w(k, q, t).mul(s(prm.inv_w_ds)), prm.exponent);
                    let both_positive = V::and(zero.lt(pi_r2), zero.lt(pj_r2));
                    let tension = s(prm.epsilon)
                        .mul(zero.sub(pi_r2).max(zero).add(zero.sub(pj_r2).max(zero)));
                    let compression = s(prm.epsilon_positive).mul(pi_r2.add(pj_r2));
                    term = term.add(V::select(both_positive, compression, tension).mul(fij));
                }
                let mt = mj.mul(term);
                ax = ax.sub(mt.mul(gx));
                ay = ay.sub(mt.mul(gy));
                power = power.add(mj.mul(visc).mul(vij_grad));
            });
            Sums {
                acc: DVec2::new(reduce(ax), reduce(ay)),
                visc_power: reduce(power),
                rate: reduce(rate),
            }
        }
    }

    /// The entry points, one per instruction set, each compiled with its features.
    macro_rules! compiled_for {
        ($features:literal, $lanes:ty, $sums:ident, $shepard:ident) => {
            /// # Safety
            /// The processor has the features; every neighbour index is below `all.len()`.
            #[target_feature(enable = $features)]
            pub(super) unsafe fn $sums<const FORCES: bool, const ART: bool, const RATE: bool>(
                k: &WendlandX8,
                prm: &Pair,
                all: &[Packed],
                neighbours: &[u32],
                i: usize,
            ) -> Sums {
                unsafe { sums::<$lanes, FORCES, ART, RATE>(k, prm, all, neighbours, i) }
            }

            /// # Safety
            /// As for the sums.
            #[target_feature(enable = $features)]
            pub(super) unsafe fn $shepard(
                k: &WendlandX8,
                all: &[Packed],
                neighbours: &[u32],
                i: usize,
            ) -> f64 {
                unsafe { shepard::<$lanes>(k, all, neighbours, i) }
            }
        };
    }
    compiled_for!("avx512f,avx512vl", Avx512, sums_avx512, shepard_avx512);
    compiled_for!("avx2", Avx2, sums_avx2, shepard_avx2);
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
        let mut next = crate::scan::test_numbers(seed);
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
        if Isa::available().is_empty() {
            eprintln!("no AVX2 here (or SPH_NO_SIMD set): nothing to compare");
        }
        for isa in Isa::available() {
            compare_with_scalar(WendlandX8::with_isa(isa, 0.013));
        }
    }

    /// AVX2 and AVX-512 give the same numbers, bit for bit.
    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        let all_isa = Isa::available();
        if all_isa.len() < 2 {
            eprintln!("fewer than two instruction sets here: nothing to compare");
            return;
        }
        for seed in 0..50 {
            let (all, near, i, h) = cloud(seed);
            let prm = Pair::new(
                &Params {
                    artificial_pressure: true,
                    beta: 0.1,
                    ..Params::default()
                },
                Wendland::new(h).w(0.01),
                h,
            );
            let results: Vec<[f64; 5]> = all_isa
                .iter()
                .map(|&isa| {
                    let x8 = WendlandX8::with_isa(isa, h);
                    let a = x8.sums::<true, true, true>(&prm, &all, &near, i);
                    let shepard = x8.shepard(&all, &near, i);
                    [a.acc.x, a.acc.y, a.rate, a.visc_power, shepard]
                        .map(f64::to_bits)
                        .map(f64::from_bits)
                })
                .collect();
            for r in &results[1..] {
                assert_eq!(
                    r.map(f64::to_bits),
                    results[0].map(f64::to_bits),
                    "seed {seed}: {r:?} vs {:?}",
                    results[0]
                );
            }
        }
    }

    fn compare_with_scalar(x8: WendlandX8) {
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
