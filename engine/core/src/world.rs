//! Borrowing component columns of the particle archetypes as slices.
//!
//! All fluid particles share one archetype, and all ghosts another, so a hot loop
//! borrows whole columns (`&[Position]`, `&mut [Acceleration]`) rather than looking
//! entities up one by one. hecs checks the borrows at run time: two stages' columns
//! can be borrowed together as long as no column is borrowed mutably twice.

use crate::stage::StepError;
use hecs::{Archetype, ArchetypeColumn, ArchetypeColumnMut, Component, World};

/// The non-empty archetype whose entities carry marker `M` (fluid or ghost), if any.
/// Stages that insert components at setup move particles to a new archetype; the
/// emptied one stays behind, hence the non-empty filter.
pub fn archetype<M: Component>(world: &World) -> Option<&Archetype> {
    world.archetypes().find(|a| a.has::<M>() && !a.is_empty())
}

/// Number of entities carrying marker `M`.
pub fn count<M: Component>(world: &World) -> usize {
    archetype::<M>(world).map_or(0, |a| a.len() as usize)
}

/// A shared column, or a setup error naming the missing component.
pub fn column<'a, T: Component>(arch: &'a Archetype) -> Result<ArchetypeColumn<'a, T>, StepError> {
    arch.get::<&T>().ok_or_else(|| missing::<T>())
}

/// A mutable column, or an error naming the missing component.
pub fn column_mut<'a, T: Component>(
    arch: &'a Archetype,
) -> Result<ArchetypeColumnMut<'a, T>, StepError> {
    arch.get::<&mut T>().ok_or_else(|| missing::<T>())
}

fn missing<T>() -> StepError {
    let full = std::any::type_name::<T>();
    let short = full.rsplit("::").next().unwrap_or(full);
    StepError::Internal(format!(
        "particles have no `{short}` component: the stage that provides it is missing from the pipeline"
    ))
}

/// Reorders column `T` of `arch` so that new entry k is old entry `order[k]` (a
/// permutation of `0..arch.len()`). Returns false when the archetype has no `T`.
/// Allocates one temporary column; callers sort every N steps, not every step.
pub fn permute<T: Component + Copy>(arch: &Archetype, order: &[u32]) -> Result<bool, StepError> {
    use rayon::prelude::*;
    let Some(mut col) = arch.get::<&mut T>() else {
        return Ok(false);
    };
    if order.len() != col.len() {
        return Err(StepError::Internal(format!(
            "permutation of {} entries applied to a column of {}",
            order.len(),
            col.len()
        )));
    }
    let old: Vec<T> = col.to_vec();
    col.par_iter_mut()
        .zip(order.par_iter())
        .for_each(|(new, &k)| *new = old[k as usize]);
    Ok(true)
}

/// Inserts component `T` (default value) into every entity carrying marker `M` that
/// lacks it. Stages call this at setup for the per-particle state they own, so a
/// scenario without the stage carries no such column.
///
/// hecs never frees an archetype's storage, so moving the particles one by one into
/// the archetype with `T` would leave a full copy of their columns allocated in the
/// emptied one, for every stage that adds a column (several hundred bytes per particle
/// in the dam break). The world is therefore rebuilt: every entity moves, under its
/// own handle and in the same order, into a fresh world, and the old one is dropped.
pub fn ensure_component<M: Component, T: Component + Default>(world: &mut World) {
    let missing = world
        .query::<()>()
        .with::<&M>()
        .without::<&T>()
        .iter()
        .count();
    if missing == 0 {
        return;
    }
    let mut old = std::mem::take(world);
    let entities: Vec<hecs::Entity> = old.iter().map(|e| e.entity()).collect();
    let mut builder = hecs::EntityBuilder::new();
    for e in entities {
        let needs = old.entity(e).is_ok_and(|r| r.has::<M>() && !r.has::<T>());
        // Listed from this world just above, so the entity exists.
        let Ok(taken) = old.take(e) else { continue };
        builder.add_bundle(taken);
        if needs {
            builder.add(T::default());
        }
        world.spawn_at(e, builder.build());
    }
}

/// A column of the fluid particles followed by the same column of the ghosts, indexed
/// in the neighbour grid's joint numbering: fluid `0..n_fluid`, then ghosts.
#[derive(Clone, Copy)]
pub struct Joined<'a, T> {
    pub fluid: &'a [T],
    pub ghost: &'a [T],
}

impl<'a, T> Joined<'a, T> {
    pub fn new(fluid: &'a [T], ghost: &'a [T]) -> Self {
        Self { fluid, ghost }
    }
    /// Element `j` of the joint numbering.
    #[inline(always)]
    pub fn get(&self, j: u32) -> &'a T {
        let j = j as usize;
        match self.fluid.get(j) {
            Some(v) => v,
            None => &self.ghost[j - self.fluid.len()],
        }
    }
    pub fn len(&self) -> usize {
        self.fluid.len() + self.ghost.len()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Sums `f(i)` over `0..n` deterministically: fixed chunks of 4096 summed in parallel,
/// then the chunk sums added in order, so the result does not depend on thread count.
pub fn sum_fixed<F: Fn(usize) -> f64 + Sync>(n: usize, f: F) -> f64 {
    use rayon::prelude::*;
    const CHUNK: usize = 4096;
    let chunks: Vec<f64> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| (c * CHUNK..((c + 1) * CHUNK).min(n)).map(&f).sum())
        .collect();
    chunks.iter().sum()
}

/// The fluid and ghost archetypes of a world, for borrowing columns of both.
#[derive(Clone, Copy)]
pub struct Particles<'a> {
    pub fluid: &'a Archetype,
    pub ghost: Option<&'a Archetype>,
}

impl<'a> Particles<'a> {
    /// None when the world has no fluid particles.
    pub fn of(world: &'a World) -> Option<Self> {
        Some(Self {
            fluid: archetype::<crate::components::Fluid>(world)?,
            ghost: archetype::<crate::components::Ghost>(world),
        })
    }
    /// Column `T` of the fluid particles.
    pub fn fluid<T: Component>(&self) -> Result<ArchetypeColumn<'a, T>, StepError> {
        column(self.fluid)
    }
    /// Column `T` of the fluid particles, mutably.
    pub fn fluid_mut<T: Component>(&self) -> Result<ArchetypeColumnMut<'a, T>, StepError> {
        column_mut(self.fluid)
    }
    /// Column `T` of fluid and ghosts together (view it with [`JoinedColumn::view`]).
    pub fn joined<T: Component>(&self) -> Result<JoinedColumn<'a, T>, StepError> {
        Ok(JoinedColumn {
            fluid: column(self.fluid)?,
            ghost: self.ghost.map(column).transpose()?,
        })
    }
}

/// Borrowed fluid and ghost columns of one component.
pub struct JoinedColumn<'a, T: Component> {
    fluid: ArchetypeColumn<'a, T>,
    ghost: Option<ArchetypeColumn<'a, T>>,
}

impl<T: Component> JoinedColumn<'_, T> {
    pub fn view(&self) -> Joined<'_, T> {
        Joined::new(&self.fluid, self.ghost.as_deref().unwrap_or(&[]))
    }
}

/// Copies of every `T` in the world (walls, sensors, gauges: the few non-particle
/// entities), in spawn order.
pub fn cloned<T: Component + Clone>(world: &World) -> Vec<T> {
    world.query::<&T>().iter().cloned().collect()
}
