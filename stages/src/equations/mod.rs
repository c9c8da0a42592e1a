//! The WCSPH equations: the equation of state, the density filters, the rate stages and
//! their shared neighbour loop, the density gradient, shifting and the damping zone.

pub mod continuity;
pub mod damping_zone;
pub mod density_gradient;
pub mod eos;
pub mod forces;
pub(crate) mod rates;
pub mod reinitialise;
pub mod shifting;
