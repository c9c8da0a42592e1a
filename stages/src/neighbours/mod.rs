//! Finding neighbours: the cell grid and its lists, the SIMD distance scan, and the
//! cell-order sort of the particles.

pub mod neighbour_grid;
pub mod scan;
pub mod sort_particles;
