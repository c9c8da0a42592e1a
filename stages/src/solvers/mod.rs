//! DFSPH (Bender & Koschier 2015): the factor, the divergence and density solves, and
//! their shared Jacobi iteration.

// Not yet built in 3D (docs/architecture.md, "Two and three dimensions").
#[cfg(not(feature = "dim3"))]
pub mod density_solve;
// Not yet built in 3D (docs/architecture.md, "Two and three dimensions").
#[cfg(not(feature = "dim3"))]
pub mod dfsph_factor;
// Not yet built in 3D (docs/architecture.md, "Two and three dimensions").
#[cfg(not(feature = "dim3"))]
pub mod divergence_solve;
// Not yet built in 3D (docs/architecture.md, "Two and three dimensions").
#[cfg(not(feature = "dim3"))]
pub(crate) mod pressure_solve;
