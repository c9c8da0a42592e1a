//! The lane type the pair terms are written over: `f64` is one lane (the scalar path);
//! the eight-lane AVX-512 and AVX2 types of [`super::x86`] are the SIMD path. A term
//! is written once, generically over [`Lane`], and compiled for each.
//!
//! Every lane type does its arithmetic operation for operation (no fused multiply-add),
//! so a pair's terms are the same numbers on every path; only the order in which the
//! pairs of one particle are added differs (lane l sums neighbours l, l + 8, ..., then
//! [`Lane::sum`] adds the lanes in a fixed tree).

use std::ops::{Add, Div, Mul, Neg, Sub};

/// Numbers computed lane by lane. Sealed: the crate's lane types only, since the SIMD
/// ones may exist only on a processor that has their instructions.
pub trait Lane:
    sealed::Gather
    + Copy
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// Lanes per value.
    const WIDTH: usize;
    /// A lane-wise condition.
    type Mask: Copy;
    /// Every lane set to `x`.
    fn splat(x: f64) -> Self;
    fn sqrt(self) -> Self;
    /// Lane-wise maximum.
    fn max(self, b: Self) -> Self;
    /// e^x, lane by lane (the library's scalar exp, so every path gives its numbers).
    fn exp(self) -> Self;
    /// Lanes where self < b (false where either is NaN).
    fn lt(self, b: Self) -> Self::Mask;
    /// Both conditions.
    fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// self where `m`, else 0.
    fn keep(self, m: Self::Mask) -> Self;
    /// `yes` where `m`, else `no`.
    fn select(m: Self::Mask, yes: Self, no: Self) -> Self;
    /// The sum of the lanes in a fixed order: ((l0 + l1) + (l2 + l3)) + ((l4 + l5) +
    /// (l6 + l7)), the same for every eight-lane type; the value itself for `f64`.
    fn sum(self) -> f64;

    /// 0 in every lane.
    #[inline(always)]
    fn zero() -> Self {
        Self::splat(0.0)
    }
}

/// x^n by multiplication (n small): the usual exponents (4 for the artificial
/// pressure, 6 and 7 for Tait with gamma = 7) written out, others by repeated squaring.
#[inline(always)]
pub fn whole_pow<L: Lane>(x: L, n: u32) -> L {
    // Tests in this order rather than a `match`, which compiles to a jump table.
    if n == 4 {
        let x2 = x * x;
        return x2 * x2;
    }
    if n == 7 {
        let x3 = x * x * x;
        return x3 * x3 * x;
    }
    if n == 6 {
        let x3 = x * x * x;
        return x3 * x3;
    }
    let (mut base, mut e, mut out) = (x, n, L::splat(1.0));
    while e > 0 {
        if e & 1 == 1 {
            out = out * base;
        }
        base = base * base;
        e >>= 1;
    }
    out
}

impl Lane for f64 {
    const WIDTH: usize = 1;
    type Mask = bool;
    #[inline(always)]
    fn splat(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        f64::max(self, b)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        f64::exp(self)
    }
    #[inline(always)]
    fn lt(self, b: Self) -> bool {
        self < b
    }
    #[inline(always)]
    fn and(a: bool, b: bool) -> bool {
        a && b
    }
    #[inline(always)]
    fn keep(self, m: bool) -> Self {
        if m {
            self
        } else {
            0.0
        }
    }
    #[inline(always)]
    fn select(m: bool, yes: Self, no: Self) -> Self {
        if m {
            yes
        } else {
            no
        }
    }
    #[inline(always)]
    fn sum(self) -> f64 {
        self
    }
}

pub(crate) mod sealed {
    /// How a lane type reads a field of a group of particle records. Crate-private:
    /// terms see gathered values only through [`crate::pair::Pair::j`].
    pub trait Gather: Copy {
        /// Adds plugin term `t`'s share of one pair group, through the function
        /// compiled for this lane type ([`crate::pair::PluginTerm`]).
        fn plugin_pair(
            t: &crate::pair::PluginTerm,
            me: &crate::pair::Me,
            p: &crate::pair::Pair<Self>,
            r: &mut crate::pair::Rates<Self>,
        ) where
            Self: super::Lane;
        /// A plugin kernel's shape function at `q`, through the function compiled
        /// for this lane type ([`crate::kernel::PluginKernel`]).
        fn shape(f: &crate::pair::ShapeFn, q: Self) -> Self;
        /// Adds lane l of each slot of `share` to neighbour `js[l]`'s record in
        /// `shares`, for each neighbour of the group (1 to `WIDTH`).
        ///
        /// # Panics
        /// If a neighbour is outside the window of `shares`.
        ///
        /// # Safety
        /// The lane type's instructions exist on this processor.
        unsafe fn scatter(
            js: &[u32],
            share: &crate::pair::Share<Self>,
            shares: &mut crate::pair::Shares,
        );
        /// Record offsets of a group of neighbours, with the lanes in use.
        type Index: Copy;
        /// The group `js` (1 to `WIDTH` joint indices) of a buffer of `len` records of
        /// `stride` f64s.
        ///
        /// # Panics
        /// If an index is `len` or more (the gathers rely on it).
        ///
        /// # Safety
        /// The lane type's instructions exist on this processor.
        unsafe fn index(js: &[u32], stride: usize, len: usize) -> Self::Index;
        /// The f64 at `offset` in each record of `index`, `pad` in unused lanes.
        ///
        /// # Safety
        /// The lane type's instructions exist on this processor, `index` came from
        /// [`Gather::index`] with the `len` and `stride` of the buffer at `base`, and
        /// `offset < stride`.
        unsafe fn gather(index: Self::Index, base: *const f64, offset: usize, pad: f64) -> Self;
        /// The whole records of the group `js` in a buffer of `len` records of eight
        /// f64s: element k of the result holds the f64 at offset k of each record,
        /// `pad[k]` in unused lanes; the same values as eight [`Gather::gather`]s.
        /// A lane type may load the records whole and transpose them instead (one
        /// load per neighbour rather than one per field and neighbour).
        ///
        /// # Panics
        /// If an index is `len` or more.
        ///
        /// # Safety
        /// The lane type's instructions exist on this processor, and `base` holds
        /// `8 len` f64s, 64-byte aligned.
        #[inline(always)]
        unsafe fn records8(js: &[u32], base: *const f64, len: usize, pad: &[f64; 8]) -> [Self; 8] {
            // SAFETY: the caller's contract; `index` checks the indices.
            unsafe {
                let index = Self::index(js, 8, len);
                std::array::from_fn(|k| Self::gather(index, base, k, pad[k]))
            }
        }
    }

    impl Gather for f64 {
        #[inline(always)]
        unsafe fn scatter(
            js: &[u32],
            share: &crate::pair::Share<f64>,
            shares: &mut crate::pair::Shares,
        ) {
            shares.add(js[0] as usize, *share);
        }
        #[inline(always)]
        fn plugin_pair(
            t: &crate::pair::PluginTerm,
            me: &crate::pair::Me,
            p: &crate::pair::Pair<f64>,
            r: &mut crate::pair::Rates<f64>,
        ) {
            (t.fns.scalar)(t.term(), me, p, r)
        }
        #[inline(always)]
        fn shape(f: &crate::pair::ShapeFn, q: f64) -> f64 {
            (f.scalar)(q)
        }
        type Index = usize;
        #[inline(always)]
        unsafe fn index(js: &[u32], stride: usize, len: usize) -> usize {
            let j = js[0] as usize;
            assert!(
                j < len,
                "neighbour index {j} beyond the {len} packed particles"
            );
            j * stride
        }
        #[inline(always)]
        unsafe fn gather(index: usize, base: *const f64, offset: usize, _pad: f64) -> f64 {
            // SAFETY: `index` = j stride with j < len (checked by `index`), offset <
            // stride, and the buffer holds len * stride f64s (the caller's contract).
            unsafe { *base.add(index + offset) }
        }
    }
}
