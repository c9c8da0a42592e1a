//! Studies and sweeps of the WCSPH engine: a study's cases ([`study`]) and the
//! frequency sweep ([`sweep`]) run side by side ([`parallel`]), read their series back
//! ([`series`]) and compare them with linear sloshing theory ([`linear_sloshing`]) or,
//! for a wave maker, the first-order wave theory ([`waves`]). Their errors are
//! [`error::StudyError`].

pub use error::StudyError;

pub mod error;
pub mod linear_sloshing;
pub mod parallel;
pub mod reference;
pub mod series;
pub mod study;
pub mod sweep;
pub mod waves;
