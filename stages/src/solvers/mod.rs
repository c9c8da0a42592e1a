//! DFSPH (Bender & Koschier 2015): the factor, the divergence and density solves, and
//! their shared Jacobi iteration.

pub mod density_solve;
pub mod dfsph_factor;
pub mod divergence_solve;
pub(crate) mod pressure_solve;
