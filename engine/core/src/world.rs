//! Borrowing component columns of the particle archetypes as slices.
//!
//! All fluid particles share one archetype, and all ghosts another, so a hot loop
//! borrows whole columns (`&[Position]`, `&mut [Acceleration]`) rather than looking
//! entities up one by one. hecs checks the borrows at run time: two stages' columns
//! can be borrowed together as long as no column is borrowed mutably twice.

use crate::components::{
    Acceleration, Density, DensityRate, Fluid, Ghost, Mass, MirrorWall, NeighbourCount, ParticleId,
    Position, Pressure, Velocity,
};
use crate::sim::{Resources, Sim};
use crate::stage::StepError;
use hecs::{
    Archetype, ArchetypeColumn, ArchetypeColumnMut, ColumnBatchBuilder, ColumnBatchType, Component,
    World,
};
use std::any::TypeId;

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
    StepError::MissingComponent(full.rsplit("::").next().unwrap_or(full))
}

/// Reorders column `T` of `arch` so that new entry k is old entry `order[k]` (a
/// permutation of `0..arch.len()`). Returns false when the archetype has no `T`.
/// Allocates one temporary column; callers sort every N steps, not every step.
pub fn permute<T: Component + Clone>(arch: &Archetype, order: &[u32]) -> Result<bool, StepError> {
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
        .for_each(|(new, &k)| *new = old[k as usize].clone());
    Ok(true)
}

/// How one component type's column is copied into a [`hecs::ColumnBatch`] and
/// reordered; see [`ColumnKinds`].
#[derive(Clone, Copy)]
struct ColumnKind {
    id: TypeId,
    add: fn(&mut ColumnBatchType),
    copy: fn(&Archetype, &ColumnBatchBuilder),
    permute: fn(&Archetype, &[u32]) -> Result<bool, StepError>,
}

impl ColumnKind {
    fn of<T: Component + Clone>() -> Self {
        Self {
            id: TypeId::of::<T>(),
            add: |batch| {
                batch.add::<T>();
            },
            copy: |from, to| {
                if let (Some(column), Some(mut writer)) = (from.get::<&T>(), to.writer::<T>()) {
                    for x in column.iter() {
                        // The batch was sized for this archetype: every push fits.
                        let _ = writer.push(x.clone());
                    }
                }
            },
            permute: permute::<T>,
        }
    }
}

/// The component types whose columns the engine can copy and reorder as whole columns:
/// [`ensure_component`] rebuilds an archetype of such types at exactly its size, and
/// the cell sort (`NeighbourGrid(sort_every)`) permutes them. A resource of the [`Sim`]
/// ([`column_kinds`] creates it with the core's per-particle components); every type a stage
/// adds through [`ensure_component`] joins it. An archetype with any other column (a
/// plugin's own per-particle state added some other way) is moved entity by entity and
/// left unsorted, correct but slower.
///
/// [`Sim`]: crate::sim::Sim
pub struct ColumnKinds(Vec<ColumnKind>);

impl Default for ColumnKinds {
    fn default() -> Self {
        let mut kinds = Self(Vec::new());
        kinds.register::<Fluid>();
        kinds.register::<Ghost>();
        kinds.register::<MirrorWall>();
        kinds.register::<ParticleId>();
        kinds.register::<Position>();
        kinds.register::<Velocity>();
        kinds.register::<Density>();
        kinds.register::<Pressure>();
        kinds.register::<Mass>();
        kinds.register::<Acceleration>();
        kinds.register::<DensityRate>();
        kinds.register::<NeighbourCount>();
        kinds
    }
}

impl ColumnKinds {
    /// Adds `T` (once).
    pub fn register<T: Component + Clone>(&mut self) {
        if self.get(TypeId::of::<T>()).is_none() {
            self.0.push(ColumnKind::of::<T>());
        }
    }

    fn get(&self, id: TypeId) -> Option<&ColumnKind> {
        self.0.iter().find(|k| k.id == id)
    }

    /// The kinds of `arch`'s columns, or None when one is not registered.
    fn kinds_of(&self, arch: &Archetype) -> Option<Vec<&ColumnKind>> {
        arch.component_types().map(|id| self.get(id)).collect()
    }

    /// Whether every column of `arch` is of a registered type.
    pub fn knows(&self, arch: &Archetype) -> bool {
        arch.component_types().all(|id| self.get(id).is_some())
    }

    /// Applies `order` (new row k holds old row `order[k]`) to every column of `arch`,
    /// whose types must all be registered ([`ColumnKinds::knows`]).
    pub fn permute(&self, arch: &Archetype, order: &[u32]) -> Result<(), StepError> {
        // Checked before any column moves, so an error leaves the archetype as it was.
        let kinds = self.kinds_of(arch).ok_or_else(|| {
            StepError::Internal("permuting a column of an unregistered type".into())
        })?;
        for kind in kinds {
            (kind.permute)(arch, order)?;
        }
        Ok(())
    }

    /// A batch of exactly `arch.len()` rows holding `arch`'s columns plus `extra`'s
    /// (filled by the caller), or None when a column's type is not registered.
    fn copy(&self, arch: &Archetype, extra: Option<&ColumnKind>) -> Option<ColumnBatchBuilder> {
        let kinds = self.kinds_of(arch)?;
        let mut ty = ColumnBatchType::new();
        for kind in kinds.iter().copied().chain(extra) {
            (kind.add)(&mut ty);
        }
        let batch = ty.into_batch(arch.len());
        for kind in &kinds {
            (kind.copy)(arch, &batch);
        }
        Some(batch)
    }
}

/// The sim's [`ColumnKinds`], created with the core's particle components on first use.
pub fn column_kinds(resources: &mut Resources) -> &mut ColumnKinds {
    if !resources.contains::<ColumnKinds>() {
        resources.insert(ColumnKinds::default());
    }
    resources
        .get_mut::<ColumnKinds>()
        .expect("the column kinds were inserted just above")
}

/// Inserts component `T` (default value) into every entity carrying marker `M` that
/// lacks it. Stages call this at setup for the per-particle state they own, so a
/// scenario without the stage carries no such column; `T` joins the sim's
/// [`ColumnKinds`].
///
/// hecs never frees an archetype's storage, and moving entities one by one grows an
/// archetype by doubling (up to twice the particle columns; 1.64 times, ~70 bytes per
/// particle, at the bench's sizes). The world is therefore rebuilt: every archetype is copied,
/// column by column and at exactly its size, into a fresh world under the same entity
/// handles and in the same order, with `T` added where it was missing, and the old
/// world is dropped. Archetypes with an unregistered column move entity by entity.
pub fn ensure_component<M: Component, T: Component + Clone + Default>(sim: &mut Sim) {
    let Sim {
        world, resources, ..
    } = sim;
    let kinds = column_kinds(resources);
    kinds.register::<T>();
    let missing = world
        .query::<()>()
        .with::<&M>()
        .without::<&T>()
        .iter()
        .count();
    if missing > 0 {
        *world = rebuilt_with::<M, T>(std::mem::take(world), kinds);
    }
}

/// `old`'s entities in a fresh world, with `T` (default) added to those with `M`.
fn rebuilt_with<M: Component, T: Component + Clone + Default>(
    mut old: World,
    kinds: &ColumnKinds,
) -> World {
    let handles: std::collections::HashMap<u32, hecs::Entity> =
        old.iter().map(|e| (e.entity().id(), e.entity())).collect();
    let t = kinds.get(TypeId::of::<T>()).copied();
    let mut world = World::new();
    let mut leftover = Vec::new();
    for arch in old.archetypes().filter(|a| !a.is_empty()) {
        let ids: Vec<hecs::Entity> = arch.ids().iter().map(|id| handles[id]).collect();
        let adds = arch.has::<M>() && !arch.has::<T>();
        let batch = kinds.copy(arch, if adds { t.as_ref() } else { None });
        let Some(batch) = batch else {
            leftover.extend(ids);
            continue;
        };
        if adds {
            if let Some(mut writer) = batch.writer::<T>() {
                for _ in 0..arch.len() {
                    let _ = writer.push(T::default());
                }
            }
        }
        match batch.build() {
            Ok(batch) => world.spawn_column_batch_at(&ids, batch),
            Err(_) => leftover.extend(ids),
        }
    }
    let mut builder = hecs::EntityBuilder::new();
    for e in leftover {
        let needs = old.entity(e).is_ok_and(|r| r.has::<M>() && !r.has::<T>());
        // Listed from this world just above, so the entity exists.
        let Ok(taken) = old.take(e) else { continue };
        builder.add_bundle(taken);
        if needs {
            builder.add(T::default());
        }
        world.spawn_at(e, builder.build());
    }
    world
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
