//! What a run reports: sensors, gauges and the roll moment (with the transducer model),
//! the energy budget, ParaView frames and PNG snapshots.

pub mod energy;
pub mod probe;
pub mod snapshots;
pub mod transducer;
pub mod vtk_frames;
