//! The eight-lane types of the SIMD path: AVX-512 (one 512-bit vector) and AVX2 (two
//! 256-bit halves), and the pass's entry points compiled with their instructions.
//!
//! A value of either type exists only inside [`sum_avx512`] or [`sum_avx2`], which
//! [`super::Isa`] lets the pass call only on a processor with those instructions (the
//! types are private to this module and `Isa`'s constructors check the processor);
//! that is what makes their safe arithmetic sound.

use super::lane::{sealed::Gather, Lane};
use super::{Kernel, Me, Pair, PairTerm, Pass, PluginTerm, RateTerm, Rates, Share, Shares, SHARE};
use crate::kernel::KernelShape;
use std::any::Any;
use std::arch::x86_64::*;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// The pass's sum for particle `i` with AVX-512 lanes (`FIELDS`: see `Pass::drive`).
///
/// # Safety
/// The processor has AVX-512F and AVX-512VL.
#[target_feature(enable = "avx512f,avx512vl")]
pub(super) unsafe fn sum_avx512<T: PairTerm, K: Kernel, const FIELDS: u16, const BOTH: bool>(
    pass: &Pass<'_, T, K>,
    i: usize,
    js: &[u32],
    shares: Option<&mut Shares>,
) -> T::Out {
    // SAFETY: the caller's contract.
    unsafe { pass.drive::<Avx512, FIELDS, BOTH>(i, js, shares) }
}

/// A plugin term's pair function for lane type `L` ([`PluginTerm`]).
pub(super) type PluginFn<L> = unsafe fn(&dyn Any, &Me, &Pair<L>, &mut Rates<L>);

/// Plugin term `T`'s share of one group in AVX-512 lanes, compiled with those
/// instructions (so the term's lane arithmetic is inlined).
///
/// # Safety
/// The processor has AVX-512F and AVX-512VL.
#[target_feature(enable = "avx512f,avx512vl")]
pub(super) unsafe fn plugin_avx512<T: RateTerm + 'static>(
    t: &dyn Any,
    me: &Me,
    p: &Pair<Avx512>,
    r: &mut Rates<Avx512>,
) {
    if let Some(t) = t.downcast_ref::<T>() {
        t.pair(me, p, r)
    }
}

/// Shape function `F` of plugin kernel `K` in AVX-512 lanes, compiled with those
/// instructions.
///
/// # Safety
/// The processor has AVX-512F and AVX-512VL.
#[target_feature(enable = "avx512f,avx512vl")]
pub(super) unsafe fn shape_avx512<K: KernelShape, const F: u8>(q: Avx512) -> Avx512 {
    super::plugin::shape::<K, F, Avx512>(q)
}

/// The same in AVX2 lanes.
///
/// # Safety
/// The processor has AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn shape_avx2<K: KernelShape, const F: u8>(q: Avx2) -> Avx2 {
    super::plugin::shape::<K, F, Avx2>(q)
}

/// The same in AVX2 lanes.
///
/// # Safety
/// The processor has AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn plugin_avx2<T: RateTerm + 'static>(
    t: &dyn Any,
    me: &Me,
    p: &Pair<Avx2>,
    r: &mut Rates<Avx2>,
) {
    if let Some(t) = t.downcast_ref::<T>() {
        t.pair(me, p, r)
    }
}

/// The pass's sum for particle `i` with AVX2 lanes (`FIELDS`: see `Pass::drive`).
///
/// # Safety
/// The processor has AVX2.
#[target_feature(enable = "avx2")]
pub(super) unsafe fn sum_avx2<T: PairTerm, K: Kernel, const FIELDS: u16, const BOTH: bool>(
    pass: &Pass<'_, T, K>,
    i: usize,
    js: &[u32],
    shares: Option<&mut Shares>,
) -> T::Out {
    // SAFETY: the caller's contract.
    unsafe { pass.drive::<Avx2, FIELDS, BOTH>(i, js, shares) }
}

/// The element-wise operators of a lane type through its `each`.
macro_rules! operators {
    ($ty:ty: $($trait:ident $method:ident => $op:ident),*) => {$(
        impl $trait for $ty {
            type Output = Self;
            #[inline(always)]
            fn $method(self, b: Self) -> Self {
                // SAFETY: a value of this type exists only on a processor with its
                // instructions (module documentation).
                unsafe { self.each(b, |x, y| $op(x, y)) }
            }
        }
    )*};
}

/// Eight lanes in one AVX-512 vector.
#[derive(Clone, Copy)]
pub(super) struct Avx512(__m512d);

impl Avx512 {
    #[inline(always)]
    unsafe fn each(self, b: Self, f: impl Fn(__m512d, __m512d) -> __m512d) -> Self {
        Self(f(self.0, b.0))
    }
}

operators!(Avx512: Add add => _mm512_add_pd, Sub sub => _mm512_sub_pd,
           Mul mul => _mm512_mul_pd, Div div => _mm512_div_pd);

impl Neg for Avx512 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        // SAFETY: as for the operators. The sign bit flipped, as scalar negation does.
        unsafe {
            let sign = _mm512_set1_epi64(i64::MIN);
            Self(_mm512_castsi512_pd(_mm512_xor_si512(
                _mm512_castpd_si512(self.0),
                sign,
            )))
        }
    }
}

impl Lane for Avx512 {
    const WIDTH: usize = 8;
    type Mask = __mmask8;
    // SAFETY (every method): a value of this type exists only on a processor with
    // AVX-512F and AVX-512VL (module documentation); `splat` is only called there too.
    #[inline(always)]
    fn splat(x: f64) -> Self {
        unsafe { Self(_mm512_set1_pd(x)) }
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        unsafe { Self(_mm512_sqrt_pd(self.0)) }
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        unsafe { Self(_mm512_max_pd(self.0, b.0)) }
    }
    #[inline(always)]
    fn exp(self) -> Self {
        unsafe { Self(_mm512_loadu_pd(to_array(self).map(f64::exp).as_ptr())) }
    }
    #[inline(always)]
    fn lt(self, b: Self) -> __mmask8 {
        unsafe { _mm512_cmp_pd_mask::<_CMP_LT_OQ>(self.0, b.0) }
    }
    #[inline(always)]
    fn and(a: __mmask8, b: __mmask8) -> __mmask8 {
        a & b
    }
    #[inline(always)]
    fn keep(self, m: __mmask8) -> Self {
        unsafe { Self(_mm512_maskz_mov_pd(m, self.0)) }
    }
    #[inline(always)]
    fn select(m: __mmask8, yes: Self, no: Self) -> Self {
        unsafe { Self(_mm512_mask_blend_pd(m, no.0, yes.0)) }
    }
    #[inline(always)]
    fn sum(self) -> f64 {
        reduce(to_array(self))
    }
}

#[inline(always)]
fn to_array(v: Avx512) -> [f64; 8] {
    let mut a = [0.0; 8];
    // SAFETY: as for the operators; the store writes the local array.
    unsafe { _mm512_storeu_pd(a.as_mut_ptr(), v.0) };
    a
}

/// The fixed lane order of [`Lane::sum`].
#[inline(always)]
fn reduce(a: [f64; 8]) -> f64 {
    ((a[0] + a[1]) + (a[2] + a[3])) + ((a[4] + a[5]) + (a[6] + a[7]))
}

impl Gather for Avx512 {
    /// The four slots transposed into one 256-bit record per neighbour in registers
    /// (four unpacks, four two-source permutes), each added to its record whole.
    #[inline(always)]
    unsafe fn scatter(js: &[u32], share: &Share<Self>, shares: &mut Shares) {
        const _: () = assert!(SHARE.is_multiple_of(4));
        debug_assert!((1..=8).contains(&js.len()));
        // Four slots at a time (one quad in 2D, two in 3D).
        for quad in 0..SHARE / 4 {
            let [a, b, c, d] = [0, 1, 2, 3].map(|k| share[4 * quad + k].0);
            // SAFETY: the features (caller); each record written is checked to be in the
            // window (`record`), and holds SHARE f64s, so its quad `quad` is inside it.
            unsafe {
                let (t0, t1) = (_mm512_unpacklo_pd(a, b), _mm512_unpackhi_pd(a, b));
                let (t2, t3) = (_mm512_unpacklo_pd(c, d), _mm512_unpackhi_pd(c, d));
                // (a_l b_l c_l d_l) for lanes 0 and 2, 4 and 6 (from t0, t2), 1 and 3,
                // 5 and 7 (from t1, t3).
                let lo = _mm512_set_epi64(11, 10, 3, 2, 9, 8, 1, 0);
                let hi = _mm512_set_epi64(15, 14, 7, 6, 13, 12, 5, 4);
                let pick = |x, idx, y| _mm512_permutex2var_pd(x, idx, y);
                let pairs = [
                    pick(t0, lo, t2),
                    pick(t1, lo, t3),
                    pick(t0, hi, t2),
                    pick(t1, hi, t3),
                ];
                for (l, &j) in js.iter().enumerate() {
                    // Lane l is half (l >> 1) & 1 of pairs[(l & 1) + 2 (l >> 2)].
                    let v = pairs[(l & 1) + 2 * (l >> 2)];
                    let v = match (l >> 1) & 1 {
                        0 => _mm512_castpd512_pd256(v),
                        _ => _mm512_extractf64x4_pd::<1>(v),
                    };
                    let r = record(shares, j).add(4 * quad);
                    _mm256_storeu_pd(r, _mm256_add_pd(_mm256_loadu_pd(r), v));
                }
            }
        }
    }
    #[inline(always)]
    fn plugin_pair(t: &PluginTerm, me: &Me, p: &Pair<Self>, r: &mut Rates<Self>) {
        // SAFETY: a value of this type (here `p`'s lanes) exists only on a processor
        // with its instructions (module documentation).
        unsafe { (t.fns.avx512)(t.term(), me, p, r) }
    }
    #[inline(always)]
    fn shape(f: &super::ShapeFn, q: Self) -> Self {
        // SAFETY: as for `plugin_pair` (`q` is a value of this type).
        unsafe { (f.avx512)(q) }
    }
    type Index = (__m256i, __mmask8);
    #[inline(always)]
    unsafe fn index(js: &[u32], stride: usize, len: usize) -> Self::Index {
        debug_assert!((1..=8).contains(&js.len()) && stride.is_power_of_two());
        let lanes = ((1u16 << js.len()) - 1) as u8;
        // SAFETY: the features (caller); the masked load reads js[..js.len()] only.
        unsafe {
            let j = _mm256_maskz_loadu_epi32(lanes, js.as_ptr() as *const i32);
            let beyond = _mm256_mask_cmpge_epu32_mask(lanes, j, _mm256_set1_epi32(len as i32));
            assert!(
                beyond == 0,
                "a neighbour index beyond the {len} packed particles"
            );
            let shift = _mm_cvtsi32_si128(stride.trailing_zeros() as i32);
            (_mm256_sll_epi32(j, shift), lanes)
        }
    }
    #[inline(always)]
    unsafe fn gather(index: Self::Index, base: *const f64, offset: usize, pad: f64) -> Self {
        let (offsets, lanes) = index;
        // SAFETY: the caller's contract: every used lane's record is in the buffer.
        unsafe {
            let src = _mm512_set1_pd(pad);
            Self(_mm512_mask_i32gather_pd::<8>(
                src,
                lanes,
                offsets,
                base.add(offset),
            ))
        }
    }

    /// Eight loads of whole 64-byte records and an 8 x 8 transpose in registers (24
    /// shuffles): on this path a gather costs about one load per element, so eight
    /// gathers of eight fields cost eight times the loads. The values are the same.
    #[inline(always)]
    unsafe fn records8(js: &[u32], base: *const f64, len: usize, pad: &[f64; 8]) -> [Self; 8] {
        debug_assert!((1..=8).contains(&js.len()));
        // SAFETY: the features (caller); each record read is one of the `len` records
        // of the buffer at `base` (every index checked below), 64-byte aligned
        // (caller); the padding is read from the caller's array.
        unsafe {
            let padding = _mm512_loadu_pd(pad.as_ptr());
            let mut rows = [padding; 8];
            for (row, &j) in rows.iter_mut().zip(js) {
                assert!(
                    (j as usize) < len,
                    "neighbour index {j} beyond the {len} packed particles"
                );
                *row = _mm512_load_pd(base.add(8 * j as usize));
            }
            let [r0, r1, r2, r3, r4, r5, r6, r7] = rows;
            // Pairs of rows: t0 = (r0_0 r1_0 r0_2 r1_2 r0_4 r1_4 r0_6 r1_6), t1 the odd
            // elements; likewise t2, t3 of r2, r3 and so on.
            let (t0, t1) = (_mm512_unpacklo_pd(r0, r1), _mm512_unpackhi_pd(r0, r1));
            let (t2, t3) = (_mm512_unpacklo_pd(r2, r3), _mm512_unpackhi_pd(r2, r3));
            let (t4, t5) = (_mm512_unpacklo_pd(r4, r5), _mm512_unpackhi_pd(r4, r5));
            let (t6, t7) = (_mm512_unpacklo_pd(r6, r7), _mm512_unpackhi_pd(r6, r7));
            // Quads of rows: u0 = (r0_0 r1_0 r2_0 r3_0 r0_4 r1_4 r2_4 r3_4), ...
            let lo = _mm512_set_epi64(13, 12, 5, 4, 9, 8, 1, 0);
            let hi = _mm512_set_epi64(15, 14, 7, 6, 11, 10, 3, 2);
            let pick = |a, idx, b| _mm512_permutex2var_pd(a, idx, b);
            let (u0, u2) = (pick(t0, lo, t2), pick(t0, hi, t2));
            let (u1, u3) = (pick(t1, lo, t3), pick(t1, hi, t3));
            let (u4, u6) = (pick(t4, lo, t6), pick(t4, hi, t6));
            let (u5, u7) = (pick(t5, lo, t7), pick(t5, hi, t7));
            // All eight rows: element k of every record.
            let low = _mm512_set_epi64(11, 10, 9, 8, 3, 2, 1, 0);
            let high = _mm512_set_epi64(15, 14, 13, 12, 7, 6, 5, 4);
            [
                Self(pick(u0, low, u4)),
                Self(pick(u1, low, u5)),
                Self(pick(u2, low, u6)),
                Self(pick(u3, low, u7)),
                Self(pick(u0, high, u4)),
                Self(pick(u1, high, u5)),
                Self(pick(u2, high, u6)),
                Self(pick(u3, high, u7)),
            ]
        }
    }
}

/// Eight lanes as two AVX2 vectors: lanes 0-3 and 4-7.
#[derive(Clone, Copy)]
pub(super) struct Avx2([__m256d; 2]);

impl Avx2 {
    #[inline(always)]
    unsafe fn each(self, b: Self, f: impl Fn(__m256d, __m256d) -> __m256d) -> Self {
        Self([f(self.0[0], b.0[0]), f(self.0[1], b.0[1])])
    }
}

operators!(Avx2: Add add => _mm256_add_pd, Sub sub => _mm256_sub_pd,
           Mul mul => _mm256_mul_pd, Div div => _mm256_div_pd);

impl Neg for Avx2 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        // SAFETY: as for the operators. The sign bit flipped, as scalar negation does.
        unsafe {
            let sign = _mm256_set1_pd(-0.0);
            self.each(Self([sign; 2]), |x, s| _mm256_xor_pd(x, s))
        }
    }
}

impl Lane for Avx2 {
    const WIDTH: usize = 8;
    /// All ones in the lanes that are set.
    type Mask = [__m256d; 2];
    // SAFETY (every method): a value of this type exists only on a processor with AVX2
    // (module documentation); `splat` is only called there too.
    #[inline(always)]
    fn splat(x: f64) -> Self {
        unsafe { Self([_mm256_set1_pd(x); 2]) }
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        unsafe { Self([_mm256_sqrt_pd(self.0[0]), _mm256_sqrt_pd(self.0[1])]) }
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        unsafe { self.each(b, |x, y| _mm256_max_pd(x, y)) }
    }
    #[inline(always)]
    fn exp(self) -> Self {
        let a = avx2_array(self).map(f64::exp);
        unsafe {
            Self([
                _mm256_loadu_pd(a.as_ptr()),
                _mm256_loadu_pd(a.as_ptr().add(4)),
            ])
        }
    }
    #[inline(always)]
    fn lt(self, b: Self) -> Self::Mask {
        unsafe { self.each(b, |x, y| _mm256_cmp_pd::<_CMP_LT_OQ>(x, y)).0 }
    }
    #[inline(always)]
    fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask {
        unsafe { Self(a).each(Self(b), |x, y| _mm256_and_pd(x, y)).0 }
    }
    #[inline(always)]
    fn keep(self, m: Self::Mask) -> Self {
        unsafe { Self(m).each(self, |m, x| _mm256_and_pd(m, x)) }
    }
    #[inline(always)]
    fn select(m: Self::Mask, yes: Self, no: Self) -> Self {
        unsafe {
            Self([
                _mm256_blendv_pd(no.0[0], yes.0[0], m[0]),
                _mm256_blendv_pd(no.0[1], yes.0[1], m[1]),
            ])
        }
    }
    #[inline(always)]
    fn sum(self) -> f64 {
        reduce(avx2_array(self))
    }
}

#[inline(always)]
fn avx2_array(v: Avx2) -> [f64; 8] {
    let mut a = [0.0; 8];
    // SAFETY: as for the operators; the stores write the local array.
    unsafe {
        _mm256_storeu_pd(a.as_mut_ptr(), v.0[0]);
        _mm256_storeu_pd(a.as_mut_ptr().add(4), v.0[1]);
    }
    a
}

impl Gather for Avx2 {
    /// The four slots transposed into one 256-bit record per neighbour in registers
    /// (a 4 x 4 transpose per half), each added to its record whole.
    #[inline(always)]
    unsafe fn scatter(js: &[u32], share: &Share<Self>, shares: &mut Shares) {
        const _: () = assert!(SHARE.is_multiple_of(4));
        debug_assert!((1..=8).contains(&js.len()));
        // Four slots at a time (one quad in 2D, two in 3D).
        for quad in 0..SHARE / 4 {
            for (half, js) in js.chunks(4).enumerate() {
                let [a, b, c, d] = [0, 1, 2, 3].map(|k| share[4 * quad + k].0[half]);
                // SAFETY: the features (caller); each record written is checked to be in
                // the window (`record`).
                unsafe {
                    let (t0, t1) = (_mm256_unpacklo_pd(a, b), _mm256_unpackhi_pd(a, b));
                    let (t2, t3) = (_mm256_unpacklo_pd(c, d), _mm256_unpackhi_pd(c, d));
                    let rows = [
                        _mm256_insertf128_pd::<1>(t0, _mm256_castpd256_pd128(t2)),
                        _mm256_insertf128_pd::<1>(t1, _mm256_castpd256_pd128(t3)),
                        _mm256_permute2f128_pd::<0x31>(t0, t2),
                        _mm256_permute2f128_pd::<0x31>(t1, t3),
                    ];
                    for (&v, &j) in rows.iter().zip(js) {
                        let r = record(shares, j).add(4 * quad);
                        _mm256_storeu_pd(r, _mm256_add_pd(_mm256_loadu_pd(r), v));
                    }
                }
            }
        }
    }
    #[inline(always)]
    fn plugin_pair(t: &PluginTerm, me: &Me, p: &Pair<Self>, r: &mut Rates<Self>) {
        // SAFETY: a value of this type (here `p`'s lanes) exists only on a processor
        // with its instructions (module documentation).
        unsafe { (t.fns.avx2)(t.term(), me, p, r) }
    }
    #[inline(always)]
    fn shape(f: &super::ShapeFn, q: Self) -> Self {
        // SAFETY: as for `plugin_pair` (`q` is a value of this type).
        unsafe { (f.avx2)(q) }
    }
    /// Record offsets, and the lanes in use as a mask.
    type Index = ([__m128i; 2], [__m256d; 2]);
    #[inline(always)]
    unsafe fn index(js: &[u32], stride: usize, len: usize) -> Self::Index {
        debug_assert!((1..=8).contains(&js.len()) && stride.is_power_of_two());
        let shift = stride.trailing_zeros();
        // Unused lanes gather nothing (masked off); their offset 0 is never read.
        let mut j = [0i32; 8];
        for (o, &x) in j.iter_mut().zip(js) {
            assert!(
                (x as usize) < len,
                "neighbour index {x} beyond the {len} packed particles"
            );
            *o = (x << shift) as i32;
        }
        let used = |l: usize| if l < js.len() { -1i64 } else { 0 };
        // SAFETY: the features (caller); the loads read the local array.
        unsafe {
            let lanes = |l: usize| {
                _mm256_castsi256_pd(_mm256_set_epi64x(
                    used(l + 3),
                    used(l + 2),
                    used(l + 1),
                    used(l),
                ))
            };
            let (lo, hi) = (
                _mm_loadu_si128(j.as_ptr() as *const __m128i),
                _mm_loadu_si128(j.as_ptr().add(4) as *const __m128i),
            );
            ([lo, hi], [lanes(0), lanes(4)])
        }
    }

    /// Sixteen-byte loads of record pairs of elements, joined into 256-bit vectors and
    /// interleaved (`unpacklo`/`unpackhi`, which stay within 128-bit halves): gathers
    /// are microcoded on AMD's Zen 1-3 and cost about one load per element, so
    /// eight gathers of four fields each ran at about half the speed of this. The
    /// values are the same.
    #[inline(always)]
    unsafe fn records8(js: &[u32], base: *const f64, len: usize, pad: &[f64; 8]) -> [Self; 8] {
        debug_assert!((1..=8).contains(&js.len()));
        let mut at = [pad.as_ptr(); 8];
        for (p, &j) in at.iter_mut().zip(js) {
            assert!(
                (j as usize) < len,
                "neighbour index {j} beyond the {len} packed particles"
            );
            // SAFETY: j < len, and the buffer holds 8 len f64s (caller).
            *p = unsafe { base.add(8 * j as usize) };
        }
        let mut out = [Self::zero(); 8];
        for k in (0..8).step_by(2) {
            // SAFETY: the features (caller); each pointer is a record of the buffer or
            // the caller's padding array, eight f64s, and k + 1 < 8.
            let ((lo0, lo1), (hi0, hi1)) = unsafe {
                (
                    avx2_columns(at[0], at[1], at[2], at[3], k),
                    avx2_columns(at[4], at[5], at[6], at[7], k),
                )
            };
            out[k] = Self([lo0, hi0]);
            out[k + 1] = Self([lo1, hi1]);
        }
        out
    }
    #[inline(always)]
    unsafe fn gather(index: Self::Index, base: *const f64, offset: usize, pad: f64) -> Self {
        let (offsets, lanes) = index;
        // SAFETY: the caller's contract; masked-off lanes are not read.
        unsafe {
            let src = _mm256_set1_pd(pad);
            let p = base.add(offset);
            Self([
                _mm256_mask_i32gather_pd::<8>(src, p, offsets[0], lanes[0]),
                _mm256_mask_i32gather_pd::<8>(src, p, offsets[1], lanes[1]),
            ])
        }
    }
}

/// Elements k and k + 1 of four records a, b, c, d as two vectors, (a_k b_k c_k d_k)
/// and (a_k+1 b_k+1 c_k+1 d_k+1).
///
/// # Safety
/// The processor has AVX2; each pointer has two readable f64s at k.
#[inline(always)]
unsafe fn avx2_columns(
    a: *const f64,
    b: *const f64,
    c: *const f64,
    d: *const f64,
    k: usize,
) -> (__m256d, __m256d) {
    // SAFETY: the caller's contract.
    unsafe {
        let x = _mm256_insertf128_pd::<1>(
            _mm256_castpd128_pd256(_mm_loadu_pd(a.add(k))),
            _mm_loadu_pd(c.add(k)),
        );
        let y = _mm256_insertf128_pd::<1>(
            _mm256_castpd128_pd256(_mm_loadu_pd(b.add(k))),
            _mm_loadu_pd(d.add(k)),
        );
        (_mm256_unpacklo_pd(x, y), _mm256_unpackhi_pd(x, y))
    }
}

/// Particle `j`'s record in `shares`, as a pointer to its four f64s.
///
/// # Panics
/// If `j` is outside the window.
#[inline(always)]
fn record(shares: &mut Shares, j: u32) -> *mut f64 {
    shares.records[(j as usize).wrapping_sub(shares.start)].as_mut_ptr()
}
