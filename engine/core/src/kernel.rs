//! Smoothing kernels in 2D and 3D (docs/physics.md, "Kernels"): one shape per kernel,
//! normalised for the dimension the crate is built for ([`crate::dim`]).
//!
//! Each kernel's shape is written once over [`Lane`], as a [`KernelShape`]: the scalar
//! path evaluates it on `f64`, the SIMD pair sums eight neighbours at a time
//! (`crate::pair`). A kernel for one smoothing length is a small `Copy` value built
//! once per pass from `h`, holding its normalisation. The hot loops are compiled
//! twice through [`with_kernel!`](crate::with_kernel) instead of branching per pair:
//! for the Wendland kernel ([`Native`], its shape inlined) and for [`DynKernel`], the
//! same arithmetic around a shape chosen at run time, which runs the other shipped
//! kernels (their shapes inlined behind a branch) and plugin kernels (their shape
//! functions called through pointers).

use crate::pair::lane::{whole_pow, Lane};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// A radially symmetric kernel W(r, h) with compact support, written once over
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
    fn grad(&self, x_ij: crate::dim::Vector, r: f64) -> crate::dim::Vector {
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
    /// The kernel as a [`DynKernel`] runs it: how the passes run every kernel but
    /// [`KernelKind::Wendland`] (`with_kernel!`). A shipped shape is inlined behind a
    /// branch, a plugin's called through pointers.
    pub fn dynamic(self) -> PluginKernel {
        let name = self.name();
        let (kernel, inline) = match self {
            KernelKind::Gaussian => (PluginKernel::new::<GaussianShape>(name), Inline::Gaussian),
            KernelKind::Quadratic => (PluginKernel::new::<QuadraticShape>(name), Inline::Quadratic),
            KernelKind::Cubic => (PluginKernel::new::<CubicShape>(name), Inline::Cubic),
            KernelKind::Quartic => (PluginKernel::new::<QuarticShape>(name), Inline::Quartic),
            // Through pointers, as a plugin's (the tests compare it with the native one).
            KernelKind::Wendland => (PluginKernel::new::<WendlandShape>(name), Inline::No),
            KernelKind::Plugin(p) => return p,
        };
        PluginKernel { inline, ..kernel }
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

/// A kernel's shape, once over [`Lane`], as the shipped kernels and plugins write it:
/// W(r, h) = NORM / h^2 w(q) in 2D and NORM_3D / h^3 w(q) in 3D, with q = r/h, zero
/// from q = SUPPORT on. `dw` is dw/dq and
/// `dw_over_q` is (dw/dq)/q, in closed form (finite at q = 0, but for the quadratic,
/// whose gradient does not vanish there; the kernel zeroes it at r = 0).
pub trait KernelShape: Send + Sync + 'static {
    /// The 2D normalisation: W integrates to 1 over the plane,
    /// 1 / NORM = int_0^SUPPORT 2 pi q w(q) dq.
    const NORM: f64;
    /// The 3D normalisation: W integrates to 1 over space,
    /// 1 / NORM_3D = int_0^SUPPORT 4 pi q^2 w(q) dq.
    const NORM_3D: f64;
    /// The support radius in units of h.
    const SUPPORT: f64;
    fn w<L: Lane>(q: L) -> L;
    fn dw<L: Lane>(q: L) -> L;
    fn dw_over_q<L: Lane>(q: L) -> L;
}

/// A kernel's name, support and shape: a plugin's (built once per process by the
/// registry), whose shape functions are called through pointers, or a shipped
/// kernel's ([`KernelKind::dynamic`]), whose shape is inlined behind a branch. A pass
/// gets the kernel for one smoothing length with [`PluginKernel::at`].
#[derive(Clone, Copy)]
pub struct PluginKernel {
    name: &'static str,
    support: f64,
    norm: f64,
    inline: Inline,
    w: crate::pair::ShapeFn,
    dw: crate::pair::ShapeFn,
    dw_over_q: crate::pair::ShapeFn,
}

/// The shipped shape a [`DynKernel`] evaluates inline, or `No` for the shape's
/// functions through pointers. The branch on it goes the same way for a whole pass,
/// so it costs next to nothing, where a call per group of lanes costs the pair loop
/// its registers (29 % of the cubic kernel's AVX-512 speed; docs/performance.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Inline {
    No,
    Gaussian,
    Quadratic,
    Cubic,
    Quartic,
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
            norm: crate::dim::pick(K::NORM, K::NORM_3D),
            inline: Inline::No,
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
        Scaled::with(*self, h)
    }
}

/// Where a kernel for one smoothing length ([`Scaled`]) gets its shape: compiled in
/// ([`Static`]) or chosen at run time ([`PluginKernel`]).
pub trait ShapeSource: Copy + std::fmt::Debug + Send + Sync + 'static {
    /// [`KernelShape::NORM`] in 2D, [`KernelShape::NORM_3D`] in 3D.
    fn norm(&self) -> f64;
    /// [`KernelShape::SUPPORT`].
    fn support(&self) -> f64;
    /// Shape function `F` (0 w, 1 dw/dq, 2 (dw/dq)/q) at `q`.
    fn shape<const F: u8, L: Lane>(&self, q: L) -> L;
}

/// Shape `S`, compiled in.
pub struct Static<S>(std::marker::PhantomData<fn() -> S>);

impl<S> Clone for Static<S> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<S> Copy for Static<S> {}

impl<S> std::fmt::Debug for Static<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(std::any::type_name::<S>())
    }
}

impl<S: KernelShape> ShapeSource for Static<S> {
    #[inline(always)]
    fn norm(&self) -> f64 {
        crate::dim::pick(S::NORM, S::NORM_3D)
    }
    #[inline(always)]
    fn support(&self) -> f64 {
        S::SUPPORT
    }
    #[inline(always)]
    fn shape<const F: u8, L: Lane>(&self, q: L) -> L {
        crate::pair::shape::<S, F, L>(q)
    }
}

impl ShapeSource for PluginKernel {
    #[inline(always)]
    fn norm(&self) -> f64 {
        self.norm
    }
    #[inline(always)]
    fn support(&self) -> f64 {
        self.support
    }
    #[inline(always)]
    fn shape<const F: u8, L: Lane>(&self, q: L) -> L {
        use crate::pair::shape;
        match self.inline {
            Inline::Gaussian => shape::<GaussianShape, F, L>(q),
            Inline::Quadratic => shape::<QuadraticShape, F, L>(q),
            Inline::Cubic => shape::<CubicShape, F, L>(q),
            Inline::Quartic => shape::<QuarticShape, F, L>(q),
            Inline::No => L::shape([&self.w, &self.dw, &self.dw_over_q][F as usize], q),
        }
    }
}

/// A kernel for one smoothing length around the shape of `E`: W = norm w(q) with
/// norm = NORM / h^2, dW/dr = norm/h dw/dq, (dW/dr)/r = norm/h^2 (dw/dq)/q, the same
/// arithmetic whether the shape is compiled in ([`Native`]) or chosen at run time
/// ([`DynKernel`]).
#[derive(Clone, Copy, Debug)]
pub struct Scaled<E> {
    inv_h: f64,
    /// Normalisation divided by h^DIM (W = norm w(q)).
    norm: f64,
    /// norm / h, for dW/dr = norm/h dw/dq.
    norm_dw: f64,
    /// norm / h^2, for (dW/dr)/r = norm/h^2 (dw/dq)/q, since r = q h.
    norm_grad: f64,
    support: f64,
    shape: E,
}

/// A kernel compiled around its shape `S` (inlined in every loop that uses it).
pub type Native<S> = Scaled<Static<S>>;

/// A [`PluginKernel`] for one smoothing length: one indirect call per evaluation and
/// group of lanes for a plugin's shape, a branch for a shipped one's.
pub type DynKernel = Scaled<PluginKernel>;

impl<E: ShapeSource> Scaled<E> {
    /// The kernel of `shape` for smoothing length `h`.
    pub fn with(shape: E, h: f64) -> Self {
        let (inv_h, norm) = (1.0 / h, shape.norm() / crate::dim::h_pow(h));
        Self {
            inv_h,
            norm,
            norm_dw: norm * inv_h,
            norm_grad: norm * inv_h * inv_h,
            support: shape.support() * h,
            shape,
        }
    }
    /// The normalisation divided by h^DIM (W = norm w(q)).
    pub fn norm(&self) -> f64 {
        self.norm
    }
}

impl<S: KernelShape> Native<S> {
    pub fn new(h: f64) -> Self {
        Self::with(Static(std::marker::PhantomData), h)
    }
}

impl<E: ShapeSource> Kernel for Scaled<E> {
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
        let within = q.lt(L::splat(self.shape.support()));
        (L::splat(self.norm) * self.shape.shape::<0, L>(q)).keep(within)
    }
    #[inline(always)]
    fn dw_dr_at<L: Lane>(&self, q: L) -> L {
        let within = q.lt(L::splat(self.shape.support()));
        (L::splat(self.norm_dw) * self.shape.shape::<1, L>(q)).keep(within)
    }
    #[inline(always)]
    fn grad_factor_at<L: Lane>(&self, q: L, r: L) -> L {
        let inside = L::and(q.lt(L::splat(self.shape.support())), L::zero().lt(r));
        (L::splat(self.norm_grad) * self.shape.shape::<2, L>(q)).keep(inside)
    }
}

/// The Gaussian's shape, truncated at q = 3: W = 1/(pi h^2) exp(-q^2)
/// (docs/physics.md, "Kernels").
#[derive(Clone, Copy, Debug)]
pub struct GaussianShape;

impl KernelShape for GaussianShape {
    const NORM: f64 = 1.0 / PI;
    /// In 3D: 1 / pi^(3/2) = (2 / sqrt(pi)) / (2 pi), the untruncated Gaussian's, as
    /// in 2D (the tail beyond q = 3 holds 4e-4 of it).
    const NORM_3D: f64 = std::f64::consts::FRAC_2_SQRT_PI / (2.0 * PI);
    const SUPPORT: f64 = 3.0;
    #[inline(always)]
    fn w<L: Lane>(q: L) -> L {
        (-q * q).exp()
    }
    #[inline(always)]
    fn dw<L: Lane>(q: L) -> L {
        L::splat(-2.0) * q * (-q * q).exp()
    }
    #[inline(always)]
    fn dw_over_q<L: Lane>(q: L) -> L {
        L::splat(-2.0) * (-q * q).exp()
    }
}

/// Johnson & Beissel's (1996) quadratic: W = 2/(pi h^2) (3/16 q^2 - 3/4 q + 3/4),
/// q <= 2 (docs/physics.md, "Kernels").
#[derive(Clone, Copy, Debug)]
pub struct QuadraticShape;

impl KernelShape for QuadraticShape {
    const NORM: f64 = 2.0 / PI;
    /// In 3D: 5 / (4 pi).
    const NORM_3D: f64 = 5.0 / (4.0 * PI);
    const SUPPORT: f64 = 2.0;
    #[inline(always)]
    fn w<L: Lane>(q: L) -> L {
        let c = L::splat;
        c(0.1875) * q * q - c(0.75) * q + c(0.75)
    }
    #[inline(always)]
    fn dw<L: Lane>(q: L) -> L {
        let c = L::splat;
        c(0.375) * q - c(0.75)
    }
    /// 3/8 - 3/4 / q: unbounded at q = 0, where the caller's mask zeroes it.
    #[inline(always)]
    fn dw_over_q<L: Lane>(q: L) -> L {
        let c = L::splat;
        c(0.375) - c(0.75) / q
    }
}

/// Monaghan & Lattanzio's (1985) cubic B-spline: W = 15/(7 pi h^2) (2/3 - q^2 + q^3/2)
/// for q < 1, 15/(7 pi h^2) (2 - q)^3/6 for 1 <= q < 2 (docs/physics.md, "Kernels").
#[derive(Clone, Copy, Debug)]
pub struct CubicShape;

impl KernelShape for CubicShape {
    const NORM: f64 = 15.0 / (7.0 * PI);
    /// In 3D: 3 / (2 pi).
    const NORM_3D: f64 = 3.0 / (2.0 * PI);
    const SUPPORT: f64 = 2.0;
    #[inline(always)]
    fn w<L: Lane>(q: L) -> L {
        let c = L::splat;
        let t = c(2.0) - q;
        L::select(
            q.lt(c(1.0)),
            c(2.0 / 3.0) - q * q + c(0.5) * q * q * q,
            t * t * t / c(6.0),
        )
    }
    #[inline(always)]
    fn dw<L: Lane>(q: L) -> L {
        let c = L::splat;
        let t = c(2.0) - q;
        L::select(
            q.lt(c(1.0)),
            c(-2.0) * q + c(1.5) * q * q,
            c(-0.5) * (t * t),
        )
    }
    #[inline(always)]
    fn dw_over_q<L: Lane>(q: L) -> L {
        let c = L::splat;
        let t = c(2.0) - q;
        L::select(q.lt(c(1.0)), c(-2.0) + c(1.5) * q, c(-0.5) * (t * t) / q)
    }
}

/// Liu, Liu & Lam's (2003) quartic: W = 15/(7 pi h^2) (2/3 - 9/8 q^2 + 19/24 q^3
/// - 5/32 q^4), q < 2 (docs/physics.md, "Kernels").
#[derive(Clone, Copy, Debug)]
pub struct QuarticShape;

impl KernelShape for QuarticShape {
    const NORM: f64 = 15.0 / (7.0 * PI);
    /// In 3D: 315 / (208 pi).
    const NORM_3D: f64 = 315.0 / (208.0 * PI);
    const SUPPORT: f64 = 2.0;
    #[inline(always)]
    fn w<L: Lane>(q: L) -> L {
        let c = L::splat;
        c(2.0 / 3.0) - c(9.0 / 8.0) * q * q + c(19.0 / 24.0) * q * q * q
            - c(5.0 / 32.0) * whole_pow(q, 4)
    }
    #[inline(always)]
    fn dw<L: Lane>(q: L) -> L {
        let c = L::splat;
        c(-9.0 / 4.0) * q + c(19.0 / 8.0) * q * q - c(5.0 / 8.0) * q * q * q
    }
    #[inline(always)]
    fn dw_over_q<L: Lane>(q: L) -> L {
        let c = L::splat;
        c(-9.0 / 4.0) + c(19.0 / 8.0) * q - c(5.0 / 8.0) * q * q
    }
}

/// Wendland's (1995) C2 kernel: W = 7/(4 pi h^2) (1 - q/2)^4 (2q + 1), q <= 2
/// (docs/physics.md, "Kernels").
#[derive(Clone, Copy, Debug)]
pub struct WendlandShape;

impl KernelShape for WendlandShape {
    const NORM: f64 = 7.0 / (4.0 * PI);
    /// In 3D: 21 / (16 pi).
    const NORM_3D: f64 = 21.0 / (16.0 * PI);
    const SUPPORT: f64 = 2.0;
    #[inline(always)]
    fn w<L: Lane>(q: L) -> L {
        let c = L::splat;
        whole_pow(c(1.0) - c(0.5) * q, 4) * (c(2.0) * q + c(1.0))
    }
    #[inline(always)]
    fn dw<L: Lane>(q: L) -> L {
        let c = L::splat;
        let t = c(1.0) - c(0.5) * q;
        c(-5.0) * q * (t * t * t)
    }
    #[inline(always)]
    fn dw_over_q<L: Lane>(q: L) -> L {
        let c = L::splat;
        let t = c(1.0) - c(0.5) * q;
        c(-5.0) * (t * t * t)
    }
}

/// The Gaussian kernel for one smoothing length, compiled natively (the passes run it
/// as a [`DynKernel`]; see [`with_kernel!`](crate::with_kernel)).
pub type Gaussian = Native<GaussianShape>;
/// The quadratic kernel for one smoothing length, compiled natively.
pub type Quadratic = Native<QuadraticShape>;
/// The cubic B-spline for one smoothing length, compiled natively.
pub type Cubic = Native<CubicShape>;
/// The quartic kernel for one smoothing length, compiled natively.
pub type Quartic = Native<QuarticShape>;
/// The Wendland C2 kernel for one smoothing length, compiled natively: the one kernel
/// the passes are compiled for.
pub type Wendland = Native<WendlandShape>;

/// Runs `$body` with `$k` bound to the kernel of `$kind` for smoothing length `$h`.
/// The body is compiled twice: for [`Wendland`], the shipped scenarios' kernel, with
/// its shape inlined, and for [`DynKernel`], which serves the other shipped kernels
/// (their shapes inlined behind a branch) and plugin kernels (their shape functions
/// compiled per lane type, one indirect call per evaluation and group of lanes).
#[macro_export]
macro_rules! with_kernel {
    ($kind:expr, $h:expr, |$k:ident| $body:expr) => {{
        match $kind {
            $crate::kernel::KernelKind::Wendland => {
                let $k = $crate::kernel::Wendland::new($h);
                $body
            }
            kind => {
                let $k = kind.dynamic().at($h);
                $body
            }
        }
    }};
}

/// The kernel summed over a square (3D: cubic) lattice of spacing `ds` centred on a
/// node, times ds^DIM: sigma_0 ds^DIM, with sigma_0 = sum_k W(|k| ds) the reference number density of
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
    // The third index runs only in 3D; 2D sums in the order it always has.
    let depth = if crate::dim::DIM == 3 { -n..=n } else { 0..=0 };
    let mut sum = 0.0;
    for i in -n..=n {
        for j in -n..=n {
            for k in depth.clone() {
                let r = if crate::dim::DIM == 2 {
                    (i as f64).hypot(j as f64)
                } else {
                    ((i * i + j * j + k * k) as f64).sqrt()
                };
                sum += w(kind, h, r * ds);
            }
        }
    }
    sum * crate::dim::cell_volume(ds)
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
    use crate::dim::{self, Vector, DIM};

    /// Sum of W over a square (3D: cubic) lattice of spacing dx, times dx^DIM: a
    /// midpoint-rule integral of W over the plane (space). With dx = h/20 the rule's
    /// error is far below 1e-3 for these smooth kernels, so 1e-3 tests the
    /// normalisation constants.
    fn lattice_integral(kind: KernelKind, h: f64, dx: f64, offset: Vector) -> (f64, Vector) {
        let n = (kind.support_factor() * h / dx).ceil() as i64 + 1;
        let depth = if DIM == 3 { -n..=n } else { 0..=0 };
        let (mut s, mut g) = (0.0, Vector::ZERO);
        for i in -n..=n {
            for j in -n..=n {
                for l in depth.clone() {
                    let mut x = dim::xy(i as f64, j as f64);
                    if DIM == 3 {
                        x[DIM - 1] = l as f64;
                    }
                    let x = x * dx + offset;
                    let r = x.length();
                    s += w(kind, h, r) * dim::cell_volume(dx);
                    g += with_kernel!(kind, h, |k| k.grad(x, r)) * dim::cell_volume(dx);
                }
            }
        }
        (s, g)
    }

    /// The lattice sum: Wendland at h = 1.3 ds by hand (its 21 nodes within 2h, by
    /// distance), and the continuum's 1 as h/ds grows; no input panics.
    #[cfg(not(feature = "dim3"))]
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

    /// Each shipped kernel as the passes run it but the Wendland (`DynKernel`, the
    /// shape inlined behind a branch) and through its shape's pointers (as a plugin's)
    /// is the kernel compiled in (`Native`), bit for bit, in W, dW/dr and (dW/dr)/r,
    /// within the support, at its edge and beyond.
    #[test]
    fn a_dynamic_kernel_is_the_compiled_kernel_bit_for_bit() {
        fn check<S: KernelShape>(kind: KernelKind) {
            let native = Native::<S>::new(0.02);
            let dynamic = kind.dynamic().at(0.02);
            let pointers = PluginKernel::new::<S>("Shape").at(0.02);
            assert_eq!(native.support(), dynamic.support(), "{kind:?}");
            for step in 0..=700 {
                let r = native.support() * step as f64 / 600.0;
                for k in [dynamic, pointers] {
                    for (a, b) in [
                        (native.w(r), k.w(r)),
                        (native.dw_dr(r), k.dw_dr(r)),
                        (native.grad_factor(r), k.grad_factor(r)),
                    ] {
                        assert_eq!(a.to_bits(), b.to_bits(), "{kind:?} r = {r}: {a} vs {b}");
                    }
                }
            }
        }
        check::<GaussianShape>(KernelKind::Gaussian);
        check::<QuadraticShape>(KernelKind::Quadratic);
        check::<CubicShape>(KernelKind::Cubic);
        check::<QuarticShape>(KernelKind::Quartic);
        check::<WendlandShape>(KernelKind::Wendland);
    }

    /// 1 / NORM = int 2 pi q w(q) dq and 1 / NORM_3D = int 4 pi q^2 w(q) dq over the
    /// support, by the midpoint rule on 200,000 intervals (error below 1e-9 for these
    /// smooth shapes), whichever dimension the crate is built for: so the 3D constants
    /// hold in the 2D build's tests too. The Gaussian is normalised untruncated: its
    /// tail beyond q = 3 holds 1.2e-4 (2D) and 4.4e-4 (3D) of it, hence 1e-3 there.
    #[test]
    fn every_shape_is_normalised_in_two_and_three_dimensions() {
        fn check<S: KernelShape>(tolerance: f64) {
            let n = 200_000;
            let dq = S::SUPPORT / n as f64;
            let (mut plane, mut space) = (0.0, 0.0);
            for k in 0..n {
                let q = (k as f64 + 0.5) * dq;
                plane += 2.0 * PI * q * S::w(q) * dq;
                space += 4.0 * PI * q * q * S::w(q) * dq;
            }
            let name = std::any::type_name::<S>();
            assert!(
                (S::NORM * plane - 1.0).abs() < tolerance,
                "{name} 2D: {plane}"
            );
            assert!(
                (S::NORM_3D * space - 1.0).abs() < tolerance,
                "{name} 3D: {space}"
            );
        }
        check::<GaussianShape>(1e-3);
        check::<QuadraticShape>(1e-9);
        check::<CubicShape>(1e-9);
        check::<QuarticShape>(1e-9);
        check::<WendlandShape>(1e-9);
    }

    /// In 3D: Wendland at h = 1.3 ds by hand (the 81 nodes within 2h = 2.6 ds: 1, 6 at
    /// 1, 12 at sqrt 2, 8 at sqrt 3, 6 at 2, 24 at sqrt 5, 24 at sqrt 6), and the
    /// continuum's 1 as h/ds grows; no input panics.
    #[cfg(feature = "dim3")]
    #[test]
    fn the_lattice_sum_is_the_rest_neighbourhood_s_number_density() {
        let (h, ds) = (1.3, 1.0);
        let by_hand: f64 = [
            (0.0, 1.0),
            (1.0, 6.0),
            (2f64.sqrt(), 12.0),
            (3f64.sqrt(), 8.0),
            (2.0, 6.0),
            (5f64.sqrt(), 24.0),
            (6f64.sqrt(), 24.0),
        ]
        .iter()
        .map(|&(r, count)| count * w(KernelKind::Wendland, h, r))
        .sum();
        let sum = lattice_sum(KernelKind::Wendland, h, ds);
        assert!((sum - by_hand).abs() < 1e-14, "{sum} against {by_hand}");
        let scaled = lattice_sum(KernelKind::Wendland, 13.0, 10.0);
        assert!((scaled - sum).abs() < 1e-12, "{scaled} against {sum}");
        for kind in KernelKind::ALL {
            let fine = lattice_sum(kind, 0.1, 0.01);
            assert!((fine - 1.0).abs() < 1e-3, "{kind:?}: {fine}");
        }
        assert!(lattice_sum(KernelKind::Wendland, 0.0, 1.0).is_nan());
    }

    #[test]
    fn every_kernel_integrates_to_one() {
        for kind in KernelKind::ALL {
            let mut offset = dim::xy(0.0013, 0.0007);
            offset[DIM - 1] += dim::pick(0.0, 0.0011);
            let (s, g) = lattice_integral(kind, 0.1, 0.005, offset);
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
                    let x = dim::xy(r * 0.6, r * 0.8);
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
