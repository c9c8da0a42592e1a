//! 2D smoothing kernels (docs/physics.md, "Kernels").
//!
//! Each kernel is a small `Copy` value built once per run from the smoothing length
//! `h`, holding its normalisation, so the hot loops are monomorphised over the kernel
//! type through [`with_kernel!`](crate::with_kernel) instead of branching per pair.
//! Its shape is written once over [`Lane`]: the scalar path evaluates it on `f64`,
//! the SIMD pair sums eight neighbours at a time (`crate::pair`).

use crate::pair::lane::{whole_pow, Lane};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// A radially symmetric 2D kernel W(r, h) with compact support, written once over
/// [`Lane`] so the scalar and the SIMD pair sums evaluate the same definition.
pub trait Kernel: Copy + Send + Sync + 'static {
    /// Support radius in metres: W = 0 for r >= support.
    fn support(&self) -> f64;
    /// 1 / h.
    fn inv_h(&self) -> f64;
    /// W at q = r/h (0 from the support on).
    fn w_at<L: Lane>(&self, q: L) -> L;
    /// dW/dr at q = r/h (<= 0 inside the support for the usual kernels).
    fn dw_dr_at<L: Lane>(&self, q: L) -> L;
    /// (dW/dr)/r at q = r/h, in closed form (no division for most kernels), so that
    /// grad_i W_ij = x_ij (dW/dr)/r; 0 at r = 0 (where grad W = 0 by symmetry) and
    /// beyond the support.
    fn grad_factor_at<L: Lane>(&self, q: L, r: L) -> L;

    /// W(r).
    #[inline(always)]
    fn w(&self, r: f64) -> f64 {
        self.w_at(r * self.inv_h())
    }
    /// dW/dr at r.
    #[inline(always)]
    fn dw_dr(&self, r: f64) -> f64 {
        self.dw_dr_at(r * self.inv_h())
    }
    /// (dW/dr)/r at r (0 at r = 0).
    #[inline(always)]
    fn grad_factor(&self, r: f64) -> f64 {
        self.grad_factor_at(r * self.inv_h(), r)
    }
    /// grad_i W_ij for x_ij = x_i - x_j at distance r: (dW/dr) x_ij / r (0 at r = 0).
    #[inline(always)]
    fn grad(&self, x_ij: glam::DVec2, r: f64) -> glam::DVec2 {
        x_ij * self.grad_factor(r)
    }
}

/// The kernel a scenario selects: a shipped one, or one a plugin registered
/// ([`PluginKernel`], through `StageRegistry::register_kernel`).
#[derive(Clone, Copy, Debug)]
pub enum KernelKind {
    /// Gaussian truncated at R = 3: W = exp(-R^2) / (pi h^2).
    Gaussian,
    /// Johnson & Beissel (1996) quadratic: W = 2/(pi h^2) (3/16 R^2 - 3/4 R + 3/4), R <= 2.
    Quadratic,
    /// Monaghan's cubic B-spline, 15/(7 pi h^2) normalisation, R < 2.
    Cubic,
    /// Liu et al. quartic: 15/(7 pi h^2) (2/3 - 9/8 R^2 + 19/24 R^3 - 5/32 R^4), R < 2.
    Quartic,
    /// Wendland C2: 7/(4 pi h^2) (1 - R/2)^4 (2R + 1), R <= 2.
    Wendland,
    /// A plugin's kernel.
    Plugin(PluginKernel),
}

impl KernelKind {
    /// Support radius as a multiple of h.
    pub fn support_factor(self) -> f64 {
        match self {
            KernelKind::Gaussian => 3.0,
            KernelKind::Plugin(p) => p.support,
            _ => 2.0,
        }
    }
    /// The name a scenario writes.
    pub fn name(self) -> &'static str {
        match self {
            KernelKind::Gaussian => "Gaussian",
            KernelKind::Quadratic => "Quadratic",
            KernelKind::Cubic => "Cubic",
            KernelKind::Quartic => "Quartic",
            KernelKind::Wendland => "Wendland",
            KernelKind::Plugin(p) => p.name,
        }
    }
    /// The shipped kernel named `name`.
    pub fn shipped(name: &str) -> Option<KernelKind> {
        KernelKind::ALL.into_iter().find(|k| k.name() == name)
    }
    /// All shipped kernels, for tests and studies.
    pub const ALL: [KernelKind; 5] = [
        KernelKind::Gaussian,
        KernelKind::Quadratic,
        KernelKind::Cubic,
        KernelKind::Quartic,
        KernelKind::Wendland,
    ];
}

/// Two kernels are the same when their names are.
impl PartialEq for KernelKind {
    fn eq(&self, other: &Self) -> bool {
        self.name() == other.name()
    }
}
impl Eq for KernelKind {}

impl Serialize for KernelKind {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_unit_variant("KernelKind", 0, self.name())
    }
}

/// Reads a shipped kernel's name; a plugin's needs the registry
/// (`sph_core::registry::KernelSeed`).
impl<'de> Deserialize<'de> for KernelKind {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::DeserializeSeed;
        crate::registry::KernelSeed(&Default::default()).deserialize(d)
    }
}

/// A kernel's shape as a plugin writes it, once over [`Lane`]: W(r, h) = NORM / h^2
/// w(q) with q = r/h, zero from q = SUPPORT on. `dw` is dw/dq and `dw_over_q` is
/// (dw/dq)/q, in closed form (finite at q = 0), as for the shipped kernels.
pub trait KernelShape: Send + Sync + 'static {
    /// The 2D normalisation: W integrates to 1 over the plane.
    const NORM: f64;
    /// The support radius in units of h.
    const SUPPORT: f64;
    fn w<L: Lane>(q: L) -> L;
    fn dw<L: Lane>(q: L) -> L;
    fn dw_over_q<L: Lane>(q: L) -> L;
}

/// A registered plugin kernel: its name, support and shape functions. Built once
/// per process by the registry; a pass gets the kernel for one smoothing length
/// with [`PluginKernel::at`].
#[derive(Clone, Copy)]
pub struct PluginKernel {
    name: &'static str,
    support: f64,
    norm: f64,
    w: crate::pair::ShapeFn,
    dw: crate::pair::ShapeFn,
    dw_over_q: crate::pair::ShapeFn,
}

impl std::fmt::Debug for PluginKernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PluginKernel")
            .field("name", &self.name)
            .finish()
    }
}

impl PluginKernel {
    /// Shape `K` under `name`.
    pub fn new<K: KernelShape>(name: &'static str) -> Self {
        Self {
            name,
            support: K::SUPPORT,
            norm: K::NORM,
            w: crate::pair::shape_fn::<K, 0>(),
            dw: crate::pair::shape_fn::<K, 1>(),
            dw_over_q: crate::pair::shape_fn::<K, 2>(),
        }
    }
    pub fn name(&self) -> &'static str {
        self.name
    }
    /// The kernel for smoothing length `h`.
    pub fn at(&self, h: f64) -> DynKernel {
        let (inv_h, norm) = (1.0 / h, self.norm / (h * h));
        DynKernel {
            inv_h,
            norm,
            norm_dw: norm * inv_h,
            norm_grad: norm * inv_h * inv_h,
            support_q: self.support,
            support: self.support * h,
            shape: *self,
        }
    }
}

/// A plugin kernel for one smoothing length: the same arithmetic as a shipped
/// kernel's around the plugin's shape, which is one indirect call per evaluation
/// and group of lanes.
#[derive(Clone, Copy, Debug)]
pub struct DynKernel {
    inv_h: f64,
    norm: f64,
    norm_dw: f64,
    norm_grad: f64,
    support_q: f64,
    support: f64,
    shape: PluginKernel,
}

impl Kernel for DynKernel {
    #[inline(always)]
    fn support(&self) -> f64 {
        self.support
    }
    #[inline(always)]
    fn inv_h(&self) -> f64 {
        self.inv_h
    }
    #[inline(always)]
    fn w_at<L: Lane>(&self, q: L) -> L {
        (L::splat(self.norm) * L::shape(&self.shape.w, q)).keep(q.lt(L::splat(self.support_q)))
    }
    #[inline(always)]
    fn dw_dr_at<L: Lane>(&self, q: L) -> L {
        (L::splat(self.norm_dw) * L::shape(&self.shape.dw, q)).keep(q.lt(L::splat(self.support_q)))
    }
    #[inline(always)]
    fn grad_factor_at<L: Lane>(&self, q: L, r: L) -> L {
        let inside = L::and(q.lt(L::splat(self.support_q)), L::zero().lt(r));
        (L::splat(self.norm_grad) * L::shape(&self.shape.dw_over_q, q)).keep(inside)
    }
}

/// A kernel type for one smoothing length: its normalisation and its shape functions
/// of q = r/h, each an expression over the lane type with constants written `c(x)`:
/// `w` the shape of W, `dw` of dW/dq, `dw_over_q` of (dW/dq)/q.
macro_rules! kernel_type {
    ($name:ident, $norm:expr, $support:expr,
     |$q:ident, $c:ident| w = $w:expr, dw = $dw:expr, dw_over_q = $f:expr) => {
        #[doc = concat!("The ", stringify!($name), " kernel for one smoothing length.")]
        #[derive(Clone, Copy, Debug)]
        pub struct $name {
            inv_h: f64,
            /// Normalisation divided by h^2 (W = norm w(q)).
            norm: f64,
            /// norm / h, for dW/dr = norm/h dw/dq.
            norm_dw: f64,
            /// norm / h^2, for (dW/dr)/r = norm/h^2 (dw/dq)/q, since r = q h.
            norm_grad: f64,
            support: f64,
        }
        impl $name {
            pub fn new(h: f64) -> Self {
                let (inv_h, norm) = (1.0 / h, $norm / (h * h));
                Self {
                    inv_h,
                    norm,
                    norm_dw: norm * inv_h,
                    norm_grad: norm * inv_h * inv_h,
                    support: $support * h,
                }
            }
            /// The normalisation divided by h^2 (W = norm w(q)).
            pub fn norm(&self) -> f64 {
                self.norm
            }
        }
        impl Kernel for $name {
            #[inline(always)]
            fn support(&self) -> f64 {
                self.support
            }
            #[inline(always)]
            fn inv_h(&self) -> f64 {
                self.inv_h
            }
            #[inline(always)]
            fn w_at<L: Lane>(&self, $q: L) -> L {
                let $c = L::splat;
                ($c(self.norm) * $w).keep($q.lt($c($support)))
            }
            #[inline(always)]
            fn dw_dr_at<L: Lane>(&self, $q: L) -> L {
                let $c = L::splat;
                ($c(self.norm_dw) * $dw).keep($q.lt($c($support)))
            }
            #[inline(always)]
            fn grad_factor_at<L: Lane>(&self, $q: L, r: L) -> L {
                let $c = L::splat;
                let inside = L::and($q.lt($c($support)), L::zero().lt(r));
                ($c(self.norm_grad) * $f).keep(inside)
            }
        }
    };
}

kernel_type!(
    Gaussian,
    1.0 / PI,
    3.0,
    |q, c| w = (-q * q).exp(),
    dw = c(-2.0) * q * (-q * q).exp(),
    dw_over_q = c(-2.0) * (-q * q).exp()
);
kernel_type!(
    Quadratic,
    2.0 / PI,
    2.0,
    |q, c| w = c(0.1875) * q * q - c(0.75) * q + c(0.75),
    dw = c(0.375) * q - c(0.75),
    dw_over_q = c(0.375) - c(0.75) / q
);
kernel_type!(
    Cubic,
    15.0 / (7.0 * PI),
    2.0,
    |q, c| w = {
        let t = c(2.0) - q;
        L::select(
            q.lt(c(1.0)),
            c(2.0 / 3.0) - q * q + c(0.5) * q * q * q,
            t * t * t / c(6.0),
        )
    },
    dw = {
        let t = c(2.0) - q;
        L::select(
            q.lt(c(1.0)),
            c(-2.0) * q + c(1.5) * q * q,
            c(-0.5) * (t * t),
        )
    },
    dw_over_q = {
        let t = c(2.0) - q;
        L::select(q.lt(c(1.0)), c(-2.0) + c(1.5) * q, c(-0.5) * (t * t) / q)
    }
);
kernel_type!(
    Quartic,
    15.0 / (7.0 * PI),
    2.0,
    |q, c| w = c(2.0 / 3.0) - c(9.0 / 8.0) * q * q + c(19.0 / 24.0) * q * q * q
        - c(5.0 / 32.0) * whole_pow(q, 4),
    dw = c(-9.0 / 4.0) * q + c(19.0 / 8.0) * q * q - c(5.0 / 8.0) * q * q * q,
    dw_over_q = c(-9.0 / 4.0) + c(19.0 / 8.0) * q - c(5.0 / 8.0) * q * q
);
kernel_type!(
    Wendland,
    7.0 / (4.0 * PI),
    2.0,
    |q, c| w = whole_pow(c(1.0) - c(0.5) * q, 4) * (c(2.0) * q + c(1.0)),
    dw = {
        let t = c(1.0) - c(0.5) * q;
        c(-5.0) * q * (t * t * t)
    },
    dw_over_q = {
        let t = c(1.0) - c(0.5) * q;
        c(-5.0) * (t * t * t)
    }
);

/// Runs `$body` with `$k` bound to the concrete kernel of `$kind` for smoothing length
/// `$h`, so the body is compiled once per kernel type.
#[macro_export]
macro_rules! with_kernel {
    ($kind:expr, $h:expr, |$k:ident| $body:expr) => {{
        use $crate::kernel::{Cubic, Gaussian, KernelKind, Quadratic, Quartic, Wendland};
        match $kind {
            KernelKind::Gaussian => {
                let $k = Gaussian::new($h);
                $body
            }
            KernelKind::Quadratic => {
                let $k = Quadratic::new($h);
                $body
            }
            KernelKind::Cubic => {
                let $k = Cubic::new($h);
                $body
            }
            KernelKind::Quartic => {
                let $k = Quartic::new($h);
                $body
            }
            KernelKind::Wendland => {
                let $k = Wendland::new($h);
                $body
            }
            KernelKind::Plugin(p) => {
                let $k = p.at($h);
                $body
            }
        }
    }};
}

/// The kernel summed over a square lattice of spacing `ds` centred on a node, times
/// ds^2: sigma_0 ds^2, with sigma_0 = sum_k W(|k| ds) the reference number density of
/// a full neighbourhood at rest (1.0105 for the Wendland kernel at h = 1.3 ds; it tends
/// to the kernel's integral, 1, as h/ds grows). Beyond 1,000 spacings per support the
/// lattice sum equals 1 to round-off and 1 is returned; NaN for a non-positive or
/// non-finite `h` or `ds`.
pub fn lattice_sum(kind: KernelKind, h: f64, ds: f64) -> f64 {
    if !(h > 0.0 && ds > 0.0 && h.is_finite() && ds.is_finite()) {
        return f64::NAN;
    }
    let reach = kind.support_factor() * h / ds;
    if reach > 1000.0 {
        return 1.0;
    }
    let n = reach.ceil() as i64;
    let mut sum = 0.0;
    for i in -n..=n {
        for j in -n..=n {
            sum += w(kind, h, (i as f64).hypot(j as f64) * ds);
        }
    }
    sum * ds * ds
}

/// Evaluates W(r) for a runtime-chosen kernel (for cold code: probes, setup, tests).
pub fn w(kind: KernelKind, h: f64, r: f64) -> f64 {
    with_kernel!(kind, h, |k| k.w(r))
}

/// Evaluates dW/dr for a runtime-chosen kernel.
pub fn dw_dr(kind: KernelKind, h: f64, r: f64) -> f64 {
    with_kernel!(kind, h, |k| k.dw_dr(r))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    /// Sum of W over a square lattice of spacing dx, times dx^2: a midpoint-rule
    /// integral of W over the plane. With dx = h/20 the rule's error is far below 1e-3
    /// for these smooth kernels, so 1e-3 tests the normalisation constants.
    fn lattice_integral(kind: KernelKind, h: f64, dx: f64, offset: DVec2) -> (f64, DVec2) {
        let n = (kind.support_factor() * h / dx).ceil() as i64 + 1;
        let (mut s, mut g) = (0.0, DVec2::ZERO);
        for i in -n..=n {
            for j in -n..=n {
                let x = DVec2::new(i as f64, j as f64) * dx + offset;
                let r = x.length();
                s += w(kind, h, r) * dx * dx;
                g += with_kernel!(kind, h, |k| k.grad(x, r)) * dx * dx;
            }
        }
        (s, g)
    }

    /// The lattice sum: Wendland at h = 1.3 ds by hand (its 21 nodes within 2h, by
    /// distance), and the continuum's 1 as h/ds grows; no input panics.
    #[test]
    fn the_lattice_sum_is_the_rest_neighbourhood_s_number_density() {
        let (h, ds) = (1.3, 1.0);
        let by_hand: f64 = [
            (0.0, 1.0),
            (1.0, 4.0),
            (2f64.sqrt(), 4.0),
            (2.0, 4.0),
            (5f64.sqrt(), 8.0),
        ]
        .iter()
        .map(|&(r, count)| count * w(KernelKind::Wendland, h, r))
        .sum();
        let sum = lattice_sum(KernelKind::Wendland, h, ds);
        assert!((sum - by_hand).abs() < 1e-14, "{sum} against {by_hand}");
        assert!((sum - 1.0105).abs() < 1e-4, "{sum}");
        // It depends on h/ds alone.
        let scaled = lattice_sum(KernelKind::Wendland, 13.0, 10.0);
        assert!((scaled - sum).abs() < 1e-12, "{scaled} against {sum}");
        for kind in KernelKind::ALL {
            let fine = lattice_sum(kind, 0.1, 0.005);
            assert!((fine - 1.0).abs() < 1e-3, "{kind:?}: {fine}");
        }
        assert_eq!(lattice_sum(KernelKind::Wendland, 1.0, 1e-9), 1.0);
        for (h, ds) in [
            (0.0, 1.0),
            (1.0, 0.0),
            (f64::NAN, 1.0),
            (1.0, f64::INFINITY),
            (-1.0, 1.0),
        ] {
            assert!(
                lattice_sum(KernelKind::Wendland, h, ds).is_nan(),
                "{h} {ds}"
            );
        }
    }

    #[test]
    fn every_kernel_integrates_to_one() {
        for kind in KernelKind::ALL {
            let (s, g) = lattice_integral(kind, 0.1, 0.005, DVec2::new(0.0013, 0.0007));
            assert!((s - 1.0).abs() < 1e-3, "{kind:?}: integral {s}");
            // The gradient integrates to zero by symmetry (tolerance: lattice offset
            // breaks the symmetry at O(dx^2)).
            assert!(g.length() < 1e-2, "{kind:?}: gradient integral {g}");
        }
    }

    /// The runtime-chosen `dw_dr` (cold code: probes, setup, tests) is the slope of the
    /// runtime-chosen `w`: a central difference of `w` with e = 1e-7 h (truncation
    /// O(e^2), round-off O(eps W / e), both far below 1e-5 of the peak slope), away from
    /// the cubic's kink at R = 1 and the support edge.
    #[test]
    fn the_runtime_slope_is_the_derivative_of_the_runtime_kernel() {
        let h = 0.05;
        for kind in KernelKind::ALL {
            let e = 1e-7 * h;
            let scale = dw_dr(kind, h, 0.9 * h).abs();
            assert!(scale > 1.0, "{kind:?}: slope scale {scale}");
            for r in [0.3 * h, 0.7 * h, 1.3 * h, 1.8 * h] {
                let fd = (w(kind, h, r + e) - w(kind, h, r - e)) / (2.0 * e);
                assert!(
                    (fd - dw_dr(kind, h, r)).abs() < 1e-5 * scale,
                    "{kind:?} r = {r}: dw_dr {} against the difference {fd}",
                    dw_dr(kind, h, r)
                );
            }
        }
    }

    #[test]
    fn gradient_is_antisymmetric_and_matches_finite_differences() {
        let h = 0.02;
        for kind in KernelKind::ALL {
            with_kernel!(kind, h, |k| {
                let support = k.support();
                for step in 1..60 {
                    let r = support * step as f64 / 60.0;
                    let x = DVec2::new(r * 0.6, r * 0.8);
                    assert_eq!(k.grad(x, r), -k.grad(-x, r), "{kind:?} antisymmetry");
                    // Central difference with e = 1e-7 h: truncation error O(e^2) and
                    // round-off O(eps W / e) are both far below 1e-5 of the peak slope.
                    let e = 1e-7 * h;
                    let fd = (k.w(r + e) - k.w(r - e)) / (2.0 * e);
                    let scale = k.dw_dr(0.9 * h).abs().max(k.dw_dr(0.3 * h).abs());
                    // Skip points within e of a kink (cubic at R = 1) or the support edge.
                    if (r / h - 1.0).abs() > 1e-6 && (support - r) > 2.0 * e {
                        assert!(
                            (fd - k.dw_dr(r)).abs() < 1e-5 * scale,
                            "{kind:?} r={r}: fd {fd} vs {}",
                            k.dw_dr(r)
                        );
                    }
                }
                assert_eq!(k.w(support * 1.0001), 0.0);
                // The closed-form (dW/dr)/r agrees with dW/dr divided by r, to round-off
                // relative to the kernel's slope scale (the quartic's dW/dr nearly
                // cancels near its support edge, so a relative test would not do).
                let scale = k.dw_dr(0.9 * h).abs().max(k.dw_dr(0.3 * h).abs()) / h;
                for step in 1..60 {
                    let r = support * step as f64 / 60.0;
                    let (f, reference) = (k.grad_factor(r), k.dw_dr(r) / r);
                    assert!(
                        (f - reference).abs() <= 1e-12 * scale,
                        "{kind:?} r={r}: (dW/dr)/r {f} vs {reference}"
                    );
                }
            });
        }
    }
}
