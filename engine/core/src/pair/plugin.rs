//! Rate terms chosen at run time: a term a plugin crate registers ([`crate::terms`])
//! runs inside the same fused neighbour loop as the compiled terms, behind one pointer.
//!
//! A [`PluginTerm`] holds the term and, for each lane type, a function compiled for it
//! (the SIMD ones with their instructions enabled, so the term's lane arithmetic is
//! inlined as in a compiled set). [`WithPlugins`] adds a list of them after a compiled
//! term set, pair group by pair group: one indirect call per term and group of eight
//! neighbours. The shipped scenarios' sets do not go through it.

use super::{Fields, Lane, Me, Pair, RateTerm, Rates};
use std::any::Any;
use std::sync::Arc;

/// A rate term behind a pointer, callable for every lane type.
#[derive(Clone)]
pub struct PluginTerm {
    name: &'static str,
    reads: Fields,
    term: Arc<dyn Any + Send + Sync>,
    pub(super) fns: Fns,
}

/// One function per lane type; each downcasts the term to the type it was made for.
#[derive(Clone, Copy)]
pub(super) struct Fns {
    pub scalar: fn(&dyn Any, &Me, &Pair<f64>, &mut Rates<f64>),
    /// # Safety
    /// The processor has AVX-512F and AVX-512VL.
    #[cfg(target_arch = "x86_64")]
    pub avx512: super::x86::PluginFn<super::x86::Avx512>,
    /// # Safety
    /// The processor has AVX2.
    #[cfg(target_arch = "x86_64")]
    pub avx2: super::x86::PluginFn<super::x86::Avx2>,
}

impl PluginTerm {
    /// `term`, registered as `name` (the name is for messages and the profile).
    pub fn new<T: RateTerm + Send + Sync + 'static>(name: &'static str, term: T) -> Self {
        Self {
            name,
            reads: term.reads(),
            term: Arc::new(term),
            fns: Fns {
                scalar: scalar::<T>,
                #[cfg(target_arch = "x86_64")]
                avx512: super::x86::plugin_avx512::<T>,
                #[cfg(target_arch = "x86_64")]
                avx2: super::x86::plugin_avx2::<T>,
            },
        }
    }

    pub fn name(&self) -> &'static str {
        self.name
    }

    /// The fields the term reads.
    pub fn reads(&self) -> Fields {
        self.reads
    }

    /// The term as it was built, or None if it is not a `T`.
    pub fn downcast<T: 'static>(&self) -> Option<&T> {
        self.term.downcast_ref()
    }

    /// Adds the term's share of one pair group.
    #[inline(always)]
    pub(super) fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        L::plugin_pair(self, me, p, r)
    }

    /// The term, for the lane types' dispatch.
    pub(super) fn term(&self) -> &(dyn Any + Send + Sync) {
        &*self.term
    }
}

impl std::fmt::Debug for PluginTerm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PluginTerm")
            .field("name", &self.name)
            .field("reads", &self.reads)
            .finish()
    }
}

fn scalar<T: RateTerm + 'static>(t: &dyn Any, me: &Me, p: &Pair<f64>, r: &mut Rates<f64>) {
    if let Some(t) = t.downcast_ref::<T>() {
        t.pair(me, p, r)
    }
}

/// A compiled term set followed by terms chosen at run time, summed in one loop: the
/// set's terms first, then each plugin term in list order (so a particle's sums are
/// added in the same order on every run and thread count).
#[derive(Clone, Copy)]
pub struct WithPlugins<'a, R> {
    pub base: R,
    pub plugins: &'a [PluginTerm],
}

impl<R: RateTerm> RateTerm for WithPlugins<'_, R> {
    fn reads(&self) -> Fields {
        self.plugins
            .iter()
            .fold(self.base.reads(), |f, t| f.with(t.reads()))
    }
    // A plugin term may add to the coefficient; unknown at compile time.
    const USES_COEF: bool = true;
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
        self.base.pair(me, p, r);
        for t in self.plugins {
            t.pair(me, p, r);
        }
    }
}

/// No term: the base of a loop that sums plugin terms only.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoTerms;

impl RateTerm for NoTerms {
    fn reads(&self) -> Fields {
        Fields::default()
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, _: &Me, _: &Pair<L>, _: &mut Rates<L>) {}
}

/// One kernel shape function ([`crate::kernel::KernelShape`]: `F` 0 for w, 1 for
/// dw/dq, 2 for (dw/dq)/q) compiled for each lane type, the SIMD ones with their
/// instructions enabled so the shape is inlined in them.
#[derive(Clone, Copy)]
pub struct ShapeFn {
    pub(super) scalar: fn(f64) -> f64,
    /// # Safety
    /// The processor has AVX-512F and AVX-512VL.
    #[cfg(target_arch = "x86_64")]
    pub(super) avx512: unsafe fn(super::x86::Avx512) -> super::x86::Avx512,
    /// # Safety
    /// The processor has AVX2.
    #[cfg(target_arch = "x86_64")]
    pub(super) avx2: unsafe fn(super::x86::Avx2) -> super::x86::Avx2,
}

/// Shape function `F` of kernel `K` for every lane type.
pub(crate) fn shape_fn<K: crate::kernel::KernelShape, const F: u8>() -> ShapeFn {
    ShapeFn {
        scalar: shape::<K, F, f64>,
        #[cfg(target_arch = "x86_64")]
        avx512: super::x86::shape_avx512::<K, F>,
        #[cfg(target_arch = "x86_64")]
        avx2: super::x86::shape_avx2::<K, F>,
    }
}

/// Shape function `F` of `K` at `q`.
#[inline(always)]
pub(crate) fn shape<K: crate::kernel::KernelShape, const F: u8, L: Lane>(q: L) -> L {
    match F {
        0 => K::w(q),
        1 => K::dw(q),
        _ => K::dw_over_q(q),
    }
}
