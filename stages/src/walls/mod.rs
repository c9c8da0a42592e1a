//! The walls: mirrored ghost particles, fixed wall particles and their pressure, and
//! the walls' work on the fluid.

pub mod ghost_walls;
// Not yet built in 3D (docs/architecture.md, "Two and three dimensions").
#[cfg(not(feature = "dim3"))]
pub mod wall_particles;
// Not yet built in 3D (docs/architecture.md, "Two and three dimensions").
#[cfg(not(feature = "dim3"))]
pub mod wall_pressure;
pub(crate) mod wall_work;
