//! The walls: mirrored ghost particles, fixed wall particles and their pressure, and
//! the walls' work on the fluid.

pub mod ghost_walls;
pub mod wall_particles;
pub mod wall_pressure;
pub(crate) mod wall_work;
