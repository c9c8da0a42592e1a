//! Output writers: ParaView frames, PNG snapshots and plots, atomic file writes.
pub mod atomic;
pub mod plot;
pub mod png;
pub mod vtk;
