//! An example plugin kernel: the Wendland C4 kernel (Wendland 1995; Dehnen &
//! Aly 2012, table 1), which a scenario selects as `kernel: WendlandC4` once the
//! registry knows it:
//!
//!   W(r, h) = 9 / (4 pi h^2) (1 - q/2)^6 (35/12 q^2 + 3 q + 1),   q = r/h <= 2
//! in 2D, and 495 / (256 pi h^3) times the same shape in 3D.
//!
//! Smoother than the shipped Wendland C2 (two more continuous derivatives), it resists
//! pairing at larger h/ds (Dehnen & Aly 2012). Written once over the lane type, as a
//! shipped kernel is: the engine runs it in every pass on the scalar and the SIMD
//! paths, with no edit to the engine (docs/architecture.md, "Plugins: adding a
//! kernel").

use sph_core::kernel::KernelShape;
use sph_core::pair::{whole_pow, Lane};
use sph_core::StageRegistry;
use std::f64::consts::PI;

/// The Wendland C4 shape of q = r/h.
pub struct WendlandC4;

impl KernelShape for WendlandC4 {
    /// 9 / (4 pi): W integrates to 1 over the plane (tested).
    const NORM: f64 = 9.0 / (4.0 * PI);
    /// 495 / (256 pi): W integrates to 1 over space (tested).
    const NORM_3D: f64 = 495.0 / (256.0 * PI);
    const SUPPORT: f64 = 2.0;
    /// (1 - q/2)^6 (35/12 q^2 + 3 q + 1).
    #[inline(always)]
    fn w<L: Lane>(q: L) -> L {
        let c = L::splat;
        let t = c(1.0) - c(0.5) * q;
        whole_pow(t, 6) * (c(35.0 / 12.0) * q * q + c(3.0) * q + c(1.0))
    }
    /// dw/dq = -(14/3) q (1 - q/2)^5 (1 + 5q/2).
    #[inline(always)]
    fn dw<L: Lane>(q: L) -> L {
        let c = L::splat;
        let t = c(1.0) - c(0.5) * q;
        c(-14.0 / 3.0) * q * whole_pow(t, 5) * (c(1.0) + c(2.5) * q)
    }
    /// (dw/dq)/q = -(14/3) (1 - q/2)^5 (1 + 5q/2), finite at q = 0.
    #[inline(always)]
    fn dw_over_q<L: Lane>(q: L) -> L {
        let c = L::splat;
        let t = c(1.0) - c(0.5) * q;
        c(-14.0 / 3.0) * whole_pow(t, 5) * (c(1.0) + c(2.5) * q)
    }
}

/// The name a scenario writes: `kernel: WendlandC4`.
pub const NAME: &str = "WendlandC4";

/// Registers the kernel.
pub fn register(registry: &mut StageRegistry) {
    registry.register_kernel::<WendlandC4>(NAME, "Wendland C4 (Dehnen & Aly 2012), support 2h");
}
