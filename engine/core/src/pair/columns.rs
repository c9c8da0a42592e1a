//! Keyed columns: per-particle quantities that a stage computes and pair terms read
//! from the packed records, beyond the world's components (delta-SPH's density
//! gradient, the ghosts' no-slip velocities, a plugin's wall normal). A column is
//! keyed by a type ([`ColumnKey`]), so a stage declares it in its
//! [`crate::contract::Access`] like any other quantity, and it is packed into as many
//! of the records' four column slots ([`Field::SLOTS`]) as it has components (one for
//! a scalar, at most DIM for a vector), which its key names.
//!
//! The sim's [`Columns`] resource holds them. It refuses a column whose slots another
//! key holds, so at any time a slot has one meaning; a term reads its key's slots.
//! The slots are bound by the key's author, not assigned per pass: a term's field
//! reads are then constants in its compiled loop (docs/architecture.md, "Keyed
//! columns").

use super::record::Field;
use crate::dim::{Vector, DIM};
use crate::stage::StepError;
use std::any::TypeId;

/// The type that names a keyed column.
pub trait ColumnKey: 'static {
    /// The name errors give.
    const NAME: &'static str;
    /// The record slots it is packed into: one for a scalar (the values' `x`), one per
    /// component up to the dimension's for a vector (`x`, `y`[, `z`]), among
    /// [`Field::SLOTS`].
    const SLOTS: &'static [Field];
}

/// Which particles a column holds values for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scope {
    /// Every particle, fluid then ghosts (the joint numbering of the neighbour lists).
    Particles,
    /// The ghosts only, in archetype order; a fluid particle's slots hold these fields
    /// of its own record (as many as the key's slots, none of them a slot), e.g. its
    /// velocity for the ghosts' no-slip velocity.
    Ghosts { fluid: &'static [Field] },
}

/// One column in the store.
#[derive(Clone, Debug)]
struct Entry {
    key: TypeId,
    name: &'static str,
    slots: &'static [Field],
    scope: Scope,
    values: Vec<Vector>,
}

/// The keyed columns of the current step (a resource of the sim).
#[derive(Clone, Debug, Default)]
pub struct Columns {
    entries: Vec<Entry>,
}

/// A column cannot be stored.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ColumnError {
    /// Another key's column holds one of its slots.
    #[error("the column {new} needs slot {slot:?}, which the column {held} holds: two keyed columns of one run must use different slots")]
    Clash {
        new: &'static str,
        held: &'static str,
        slot: Field,
    },
    /// The key names no slot, more than the dimension's count, or a field that is not a slot; or its
    /// fluid fields are not as many as its slots, or include a slot.
    #[error("the column {name} is declared wrongly: {why}")]
    Declaration {
        name: &'static str,
        why: &'static str,
    },
}

impl From<ColumnError> for StepError {
    fn from(e: ColumnError) -> Self {
        StepError::Internal(e.to_string())
    }
}

impl Columns {
    /// Stores `values` as column `K` (replacing `K`'s earlier values).
    ///
    /// # Errors
    /// Another key holds one of `K`'s slots, or `K` or `scope` is declared wrongly.
    pub fn insert<K: ColumnKey>(
        &mut self,
        scope: Scope,
        values: Vec<Vector>,
    ) -> Result<(), ColumnError> {
        let declared = |why| ColumnError::Declaration { name: K::NAME, why };
        if K::SLOTS.is_empty() || K::SLOTS.len() > DIM {
            return Err(declared(
                "a column has one slot (a scalar) or one per component of a vector, at most one per dimension",
            ));
        }
        if !K::SLOTS.iter().all(|f| f.is_slot()) {
            return Err(declared("its slots must be among Field::SLOTS"));
        }
        if let Scope::Ghosts { fluid } = scope {
            if fluid.len() != K::SLOTS.len() || fluid.iter().any(|f| f.is_slot()) {
                return Err(declared(
                    "a ghosts-only column names one record field per slot for the fluid, none of them a slot",
                ));
            }
        }
        let key = TypeId::of::<K>();
        for e in self.entries.iter().filter(|e| e.key != key) {
            if let Some(&slot) = K::SLOTS.iter().find(|s| e.slots.contains(s)) {
                return Err(ColumnError::Clash {
                    new: K::NAME,
                    held: e.name,
                    slot,
                });
            }
        }
        let entry = Entry {
            key,
            name: K::NAME,
            slots: K::SLOTS,
            scope,
            values,
        };
        match self.entries.iter_mut().find(|e| e.key == key) {
            Some(e) => *e = entry,
            None => self.entries.push(entry),
        }
        Ok(())
    }

    /// Whether column `K` is stored.
    pub fn contains<K: ColumnKey>(&self) -> bool {
        self.find(TypeId::of::<K>()).is_some()
    }

    /// Column `K`'s values.
    pub fn get<K: ColumnKey>(&self) -> Option<&[Vector]> {
        self.find(TypeId::of::<K>()).map(|e| &e.values[..])
    }

    /// Column `K`'s values, to change in place (a solve that changes velocities
    /// between passes keeps a velocity column in step).
    pub fn get_mut<K: ColumnKey>(&mut self) -> Option<&mut Vec<Vector>> {
        let key = TypeId::of::<K>();
        self.entries
            .iter_mut()
            .find(|e| e.key == key)
            .map(|e| &mut e.values)
    }

    /// Removes column `K`, giving its values back (to reuse their buffer).
    pub fn remove<K: ColumnKey>(&mut self) -> Option<Vec<Vector>> {
        let key = TypeId::of::<K>();
        let k = self.entries.iter().position(|e| e.key == key)?;
        Some(self.entries.swap_remove(k).values)
    }

    /// Removes column `K` and gives its buffer back emptied, to be filled again and
    /// stored (a new empty one where `K` was not stored): a stage that writes a column
    /// each step keeps one allocation.
    pub fn take_emptied<K: ColumnKey>(&mut self) -> Vec<Vector> {
        let mut values = self.remove::<K>().unwrap_or_default();
        values.clear();
        values
    }

    /// Bytes held, for memory accounting.
    pub fn heap_bytes(&self) -> usize {
        self.entries
            .iter()
            .map(|e| e.values.capacity() * std::mem::size_of::<Vector>())
            .sum()
    }

    fn find(&self, key: TypeId) -> Option<&Entry> {
        self.entries.iter().find(|e| e.key == key)
    }

    /// What fills each slot of `wanted` for `len` particles of which `n_fluid` are
    /// fluid: per slot, the values and their scope.
    pub(crate) fn sources(
        &self,
        wanted: super::Fields,
        len: usize,
        n_fluid: usize,
    ) -> Result<[Option<SlotSource<'_>>; 4], StepError> {
        let mut out = [None; 4];
        for (k, slot) in Field::SLOTS.into_iter().enumerate() {
            if !wanted.contains(slot) {
                continue;
            }
            let Some((e, c)) = self.entries.iter().find_map(|e| {
                let c = e.slots.iter().position(|&s| s == slot)?;
                Some((e, c))
            }) else {
                return Err(StepError::Internal(format!(
                    "a pair term reads column slot {slot:?}, but no stage wrote a column there this step"
                )));
            };
            let expected = match e.scope {
                Scope::Particles => len,
                Scope::Ghosts { .. } => len.saturating_sub(n_fluid),
            };
            if e.values.len() != expected {
                return Err(StepError::Internal(format!(
                    "the column {} holds {} values where {expected} are needed: it was computed for another state",
                    e.name,
                    e.values.len()
                )));
            }
            out[k] = Some(SlotSource {
                values: &e.values,
                component: c,
                fluid: match e.scope {
                    Scope::Particles => None,
                    Scope::Ghosts { fluid } => Some(fluid[c]),
                },
            });
        }
        Ok(out)
    }
}

/// Where a slot's values come from when records are packed.
#[derive(Clone, Copy)]
pub(crate) struct SlotSource<'a> {
    /// The column's values (per particle, or per ghost).
    values: &'a [Vector],
    /// 0 for `x`, 1 for `y`, 2 for `z` (below the key's slot count, at most DIM).
    component: usize,
    /// For a ghosts-only column, the record field the fluid's slot holds.
    fluid: Option<Field>,
}

impl SlotSource<'_> {
    /// Whether the fluid's values are field `f` of their own records.
    pub(crate) fn fluid_reads(&self, f: Field) -> bool {
        self.fluid == Some(f)
    }

    /// The slot's value for particle `j` of the joint numbering (`n_fluid` fluid
    /// particles first), `own(f)` giving field `f` of j's own record.
    #[inline(always)]
    pub(crate) fn value(&self, j: usize, n_fluid: usize, own: impl Fn(Field) -> f64) -> f64 {
        let v = match self.fluid {
            None => self.values[j],
            Some(f) if j < n_fluid => return own(f),
            Some(_) => self.values[j - n_fluid],
        };
        v[self.component]
    }
}
