//! Declared contracts: what each stage reads and writes, checked over the whole
//! pipeline when a scenario loads, whatever the list order.
//!
//! A stage declares its [`Access`] ([`crate::Stage::access`]) in terms of
//! [`Quantity`]s, typed keys: a particle component (`Position`, `DensityRate`: the
//! fluid particles' column), a resource or component of the shared vocabulary
//! (`Neighbours`, `HalfVelocity`, `ViscousDissipation`, `WallPose`, ...), the ghost
//! particles as a whole (`Ghost`), or the clock ([`Quantity::clock`]). Four kinds of
//! use:
//!
//! - **writes**: the stage produces the quantity. A quantity has one writer in a
//!   pipeline; a second one is refused.
//! - **reads**: the stage needs the quantity: the initial state must hold it
//!   ([`initial`]: the fluid particles' position, velocity, density, mass and pressure,
//!   the scene, the clock) or a stage *earlier in the list* must write it. A reader
//!   listed before its writer would read last step's value, or nothing on the first
//!   step: refused, unless the initial state provides the quantity (GhostWalls reads
//!   the positions Integrate writes at the end of the previous step).
//! - **updates**: the stage corrects in place a quantity another stage (or the initial
//!   state) provides: a filter, a damper. Checked like a read; any number of stages may
//!   update one quantity.
//! - **uses**: read or adjusted only when present (Integrate's rates when there is no
//!   Forces, Reinitialise's shift of the half-step density). Declared for the record;
//!   not checked.
//!
//! Only the stage that writes the clock may change it (time, step, dt): the runner
//! stops a run whose stage changes the clock without declaring it, and the loader
//! refuses a clock writer that does not run every step, or a pipeline without one.
//! The scene moves with the clock ([`crate::kinematics`]), so the clock's writer also
//! writes the wall and body poses.
//!
//! A stage that declares nothing (the trait's default, e.g. a plugin written before
//! contracts) is trusted as before: it takes part in no check, except that it may not
//! change the clock.
//!
//! An [`Access`] can also expose typed values of the stage's parameters that other
//! parts of the engine need ([`Access::exposes`]): a sweep asks the pipeline for the
//! artificial viscosity it ran with ([`crate::vocab::ArtificialViscosity`]) instead of
//! looking a stage up by name.

use crate::components::{
    BodyPose, Density, Mass, ParticleId, Position, Pressure, PressureSensor, Tank, Velocity, Wall,
    WallPose, WaveGauge,
};
use crate::sim::Clock;
use std::any::{Any, TypeId};
use std::fmt;
use std::sync::Arc;

/// A quantity stages share, keyed by type: a component, a vocabulary resource or the
/// clock. Two quantities are the same when their types are.
#[derive(Clone, Copy)]
pub struct Quantity {
    id: TypeId,
    name: &'static str,
}

impl Quantity {
    /// The quantity of type `T` (a component or resource type).
    pub fn of<T: 'static>() -> Self {
        let full = std::any::type_name::<T>();
        Self {
            id: TypeId::of::<T>(),
            name: full.rsplit("::").next().unwrap_or(full),
        }
    }
    /// The clock (time, step, dt): written by the one stage that advances it.
    pub fn clock() -> Self {
        Self::of::<Clock>()
    }
    /// The type's name without its path, e.g. `DensityRate`.
    pub fn name(&self) -> &'static str {
        self.name
    }
}

impl PartialEq for Quantity {
    fn eq(&self, other: &Self) -> bool {
        self.id == other.id
    }
}
impl Eq for Quantity {}

impl fmt::Debug for Quantity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

/// What the initial state provides, before any stage runs: the fluid particles'
/// position, velocity, density, mass, pressure and id, the scene (walls, tank,
/// pistons, sensors, gauges, with their poses at t = 0) and the clock.
pub fn initial() -> [Quantity; 13] {
    [
        Quantity::of::<Position>(),
        Quantity::of::<Velocity>(),
        Quantity::of::<Density>(),
        Quantity::of::<Mass>(),
        Quantity::of::<Pressure>(),
        Quantity::of::<ParticleId>(),
        Quantity::of::<Wall>(),
        Quantity::of::<WallPose>(),
        Quantity::of::<BodyPose>(),
        Quantity::of::<Tank>(),
        Quantity::of::<PressureSensor>(),
        Quantity::of::<WaveGauge>(),
        Quantity::clock(),
    ]
}

/// A stage's declared contract (see the module docs). Built with the chained methods:
///
/// ```
/// # use sph_core::contract::Access;
/// # use sph_core::components::{Acceleration, Pressure};
/// # use sph_core::vocab::Neighbours;
/// let access = Access::new()
///     .reads::<Neighbours>()
///     .reads::<Pressure>()
///     .writes::<Acceleration>();
/// assert!(!access.writes_clock());
/// ```
#[derive(Clone, Default)]
pub struct Access {
    pub reads: Vec<Quantity>,
    pub writes: Vec<Quantity>,
    pub updates: Vec<Quantity>,
    pub uses: Vec<Quantity>,
    exposed: Vec<Arc<dyn Any + Send + Sync>>,
}

impl Access {
    pub fn new() -> Self {
        Self::default()
    }
    /// Needs `T`, from the initial state or an earlier stage.
    pub fn reads<T: 'static>(self) -> Self {
        self.reads_if::<T>(true)
    }
    /// [`Access::reads`] when `on` (e.g. with a parameter that needs it).
    pub fn reads_if<T: 'static>(mut self, on: bool) -> Self {
        if on {
            self.reads.push(Quantity::of::<T>());
        }
        self
    }
    /// Produces `T` (its one writer).
    pub fn writes<T: 'static>(self) -> Self {
        self.writes_if::<T>(true)
    }
    /// [`Access::writes`] when `on`.
    pub fn writes_if<T: 'static>(mut self, on: bool) -> Self {
        if on {
            self.writes.push(Quantity::of::<T>());
        }
        self
    }
    /// Advances the clock (and so moves the scene): writes [`Quantity::clock`].
    pub fn writes_clock(&self) -> bool {
        self.writes.contains(&Quantity::clock())
    }
    /// Corrects `T` in place after its writer (or the initial state) provided it.
    pub fn updates<T: 'static>(mut self) -> Self {
        self.updates.push(Quantity::of::<T>());
        self
    }
    /// Reads or adjusts `T` when it is present; not checked.
    pub fn uses<T: 'static>(mut self) -> Self {
        self.uses.push(Quantity::of::<T>());
        self
    }
    /// Exposes a typed value (a parameter other parts of the engine need), found with
    /// [`Access::exposed`].
    pub fn exposes<T: Any + Send + Sync>(mut self, value: T) -> Self {
        self.exposed.push(Arc::new(value));
        self
    }
    /// The exposed value of type `T`, if the stage exposes one.
    pub fn exposed<T: Any>(&self) -> Option<&T> {
        self.exposed.iter().find_map(|v| v.downcast_ref())
    }
    /// Whether the stage declares anything at all.
    pub fn is_empty(&self) -> bool {
        self.reads.is_empty()
            && self.writes.is_empty()
            && self.updates.is_empty()
            && self.uses.is_empty()
    }
}

impl fmt::Debug for Access {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Access")
            .field("reads", &self.reads)
            .field("writes", &self.writes)
            .field("updates", &self.updates)
            .field("uses", &self.uses)
            .field("exposed", &self.exposed.len())
            .finish()
    }
}

/// How a pipeline breaks the contracts; stages are given by their index in the list.
#[derive(Clone, Debug, PartialEq)]
pub enum Breach {
    /// Stage `second` writes `quantity`, which stage `first` (earlier) writes too.
    TwoWriters {
        quantity: Quantity,
        first: usize,
        second: usize,
    },
    /// Stage `reader` reads (or, with `update`, updates) `quantity`, which neither the
    /// initial state nor an earlier stage provides; `later` writes it after the reader.
    Unwritten {
        quantity: Quantity,
        reader: usize,
        update: bool,
        later: Option<usize>,
    },
    /// Stage `stage` writes the clock but runs only every `every` steps.
    ClockNotEveryStep { stage: usize, every: u32 },
    /// No stage writes the clock.
    NoClock,
}

/// Checks a pipeline, given each stage's access and `every`, in list order; returns the
/// first breach (in list order).
pub fn check<'a>(stages: impl IntoIterator<Item = (&'a Access, u32)>) -> Result<(), Breach> {
    let initial = initial();
    let list: Vec<(&Access, u32)> = stages.into_iter().collect();
    let writer = |q: &Quantity, mut range: std::ops::Range<usize>| {
        range.find(|&k| list[k].0.writes.contains(q))
    };
    for (k, (access, every)) in list.iter().enumerate() {
        for (q, update) in access
            .reads
            .iter()
            .map(|q| (q, false))
            .chain(access.updates.iter().map(|q| (q, true)))
        {
            if !initial.contains(q) && writer(q, 0..k).is_none() {
                return Err(Breach::Unwritten {
                    quantity: *q,
                    reader: k,
                    update,
                    later: writer(q, k + 1..list.len()),
                });
            }
        }
        for q in &access.writes {
            if let Some(first) = writer(q, 0..k) {
                return Err(Breach::TwoWriters {
                    quantity: *q,
                    first,
                    second: k,
                });
            }
        }
        if access.writes_clock() && *every != 1 {
            return Err(Breach::ClockNotEveryStep {
                stage: k,
                every: *every,
            });
        }
    }
    if !list.iter().any(|(a, _)| a.writes_clock()) {
        return Err(Breach::NoClock);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::components::{Acceleration, DensityRate};
    use crate::vocab::{HalfVelocity, Neighbours};

    fn integrate() -> Access {
        Access::new()
            .reads::<Position>()
            .writes::<Position>()
            .writes::<HalfVelocity>()
            .writes::<Clock>()
    }

    #[test]
    fn a_pipeline_in_order_passes_and_breaches_are_found_in_either_order() {
        let grid = Access::new().reads::<Position>().writes::<Neighbours>();
        let forces = Access::new()
            .reads::<Neighbours>()
            .writes::<Acceleration>()
            .writes::<DensityRate>();
        let continuity = Access::new().reads::<Neighbours>().writes::<DensityRate>();
        let damper = Access::new().updates::<HalfVelocity>();
        let nothing = Access::new();
        let ok = [&grid, &forces, &nothing, &integrate(), &damper];
        assert_eq!(check(ok.iter().map(|a| (*a, 1))), Ok(()));

        // Two writers of the density rate, in either order: refused at the second.
        for (a, b) in [(&continuity, &forces), (&forces, &continuity)] {
            let i = integrate();
            let list = [&grid, a, b, &i];
            assert_eq!(
                check(list.iter().map(|a| (*a, 1))),
                Err(Breach::TwoWriters {
                    quantity: Quantity::of::<DensityRate>(),
                    first: 1,
                    second: 2
                })
            );
        }
        // A reader before its writer; an updater before its writer.
        let i = integrate();
        let list = [&forces, &grid, &i];
        assert_eq!(
            check(list.iter().map(|a| (*a, 1))),
            Err(Breach::Unwritten {
                quantity: Quantity::of::<Neighbours>(),
                reader: 0,
                update: false,
                later: Some(1)
            })
        );
        let list = [&damper, &i];
        assert!(matches!(
            check(list.iter().map(|a| (*a, 1))),
            Err(Breach::Unwritten {
                update: true,
                later: Some(1),
                ..
            })
        ));
        // The clock: written every step, by someone.
        assert_eq!(
            check([(&i, 2)]),
            Err(Breach::ClockNotEveryStep { stage: 0, every: 2 })
        );
        assert_eq!(check([(&grid, 1)]), Err(Breach::NoClock));
    }

    #[test]
    fn exposed_values_are_found_by_type() {
        #[derive(Debug, PartialEq)]
        struct Alpha(f64);
        let a = Access::new().exposes(Alpha(0.03));
        assert_eq!(a.exposed::<Alpha>(), Some(&Alpha(0.03)));
        assert_eq!(a.exposed::<f64>(), None);
        assert_eq!(Quantity::of::<DensityRate>().name(), "DensityRate");
    }
}
