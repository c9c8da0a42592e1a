//! Pair terms as a scenario names them: the [`Term`] trait every term of the equations
//! of motion implements (the shipped ones in `sph-stages`, and a plugin's), and the
//! [`TermRegistry`] through which a plugin crate adds a term to `Forces(terms: [...])`
//! without editing the engine. A registered term runs inside Forces' fused neighbour
//! loop ([`crate::pair::WithPlugins`]), after the shipped terms of the list.

use crate::contract::Access;
use crate::pair::{Fields, PluginTerm, RateTerm};
use crate::registry::ParamError;
use crate::sim::{Constants, Sim};
use crate::stage::StepError;
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Arc;

/// A pass a term needs before `Forces`' neighbour loop, each step (delta-SPH's
/// renormalised density gradient): it computes what the term then reads.
pub type PrePass = fn(&mut Sim) -> Result<(), StepError>;

/// A rate term built from its scenario parameters.
pub trait Term: RateTerm + Sized {
    /// The fields of i and j the term reads (its `RateTerm::reads`), known before the
    /// run's constants are, for the stage's declared contract.
    const READS: Fields;
    /// Whether the term is a density diffusion (it adds to the continuity equation, so
    /// it needs `Continuity()` in the same list, and a list takes one at most).
    const DIFFUSION: bool = false;
    /// The parameters a scenario gives it, with documented defaults. Give the struct
    /// `#[serde(default, deny_unknown_fields)]`.
    type Params: Clone + std::fmt::Debug + Default + Serialize + DeserializeOwned;
    /// Refuses out-of-range parameters, naming the field and what is accepted (run
    /// when the scenario is read, so the error has its position).
    fn check(_p: &Self::Params) -> Result<(), ParamError> {
        Ok(())
    }
    /// The term for a run with constants `c`, from checked parameters.
    fn build(p: &Self::Params, c: &Constants) -> Self;
    /// For a viscous term: read the ghosts' no-slip velocities (the physics crate's
    /// `NoSlipVelocity` column; the walls do not slip) instead of their `Vx`, `Vy`. Other terms
    /// ignore it.
    fn wall_shear(&mut self) {}
    /// For a term that reads the velocity of a pair: meet a fixed wall particle with
    /// i's own mirror image across its wall (the physics crate's `WallNormal` column;
    /// `WallPressure(pair_mirror: true)`). Other terms ignore it.
    fn wall_mirror(&mut self) {}
    /// The pass the term needs before the loop, if any; run once per step however
    /// many terms name the same one.
    const PRE_PASS: Option<PrePass> = None;
    /// What the term adds to `Forces`' declared contract beyond the particle fields it
    /// reads: a quantity its pre-pass writes, a parameter it exposes to the rest of the
    /// engine ([`Access::exposes`]).
    fn declare(_p: &Self::Params, access: Access) -> Access {
        access
    }
}

/// A registered term's parameters as a scenario gave them.
pub trait TermParams: erased_serde::Serialize + std::fmt::Debug + Send + Sync {
    /// The name the scenario wrote.
    fn name(&self) -> &'static str;
    /// The fields the term reads.
    fn reads(&self) -> Fields;
    /// Whether the term is a density diffusion ([`Term::DIFFUSION`]).
    fn diffusion(&self) -> bool;
    /// [`Term::check`].
    fn check(&self) -> Result<(), ParamError>;
    /// [`Term::PRE_PASS`].
    fn pre_pass(&self) -> Option<PrePass>;
    /// [`Term::declare`].
    fn declare(&self, access: Access) -> Access;
    /// The term for a run with constants `c` ([`Term::build`], then
    /// [`Term::wall_shear`] when the walls do not slip).
    fn build(&self, c: &Constants, wall_shear: bool) -> PluginTerm;
    fn clone_box(&self) -> Box<dyn TermParams>;
}

erased_serde::serialize_trait_object!(TermParams);

impl Clone for Box<dyn TermParams> {
    fn clone(&self) -> Self {
        self.clone_box()
    }
}

/// Term `T`'s parameters, under the name it was registered with.
struct Given<T: Term> {
    name: &'static str,
    params: T::Params,
}

impl<T: Term> std::fmt::Debug for Given<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}({:?})", self.name, self.params)
    }
}

impl<T: Term> Serialize for Given<T> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.params.serialize(s)
    }
}

impl<T: Term + Send + Sync + 'static> TermParams for Given<T>
where
    T::Params: Send + Sync + 'static,
{
    fn name(&self) -> &'static str {
        self.name
    }
    fn reads(&self) -> Fields {
        T::READS
    }
    fn diffusion(&self) -> bool {
        T::DIFFUSION
    }
    fn check(&self) -> Result<(), ParamError> {
        T::check(&self.params)
    }
    fn pre_pass(&self) -> Option<PrePass> {
        T::PRE_PASS
    }
    fn declare(&self, access: Access) -> Access {
        T::declare(&self.params, access)
    }
    fn build(&self, c: &Constants, wall_shear: bool) -> PluginTerm {
        let mut t = T::build(&self.params, c);
        if wall_shear {
            t.wall_shear();
        }
        PluginTerm::new(self.name, t)
    }
    fn clone_box(&self) -> Box<dyn TermParams> {
        Box::new(Given::<T> {
            name: self.name,
            params: self.params.clone(),
        })
    }
}

/// Reads a registered term's parameters.
type Reader = dyn Fn(&mut dyn erased_serde::Deserializer) -> Result<Box<dyn TermParams>, erased_serde::Error>
    + Send
    + Sync;

struct Entry {
    read: Box<Reader>,
    summary: &'static str,
}

/// The terms plugins add, by the name a scenario writes. Cloning is cheap.
#[derive(Clone, Default)]
pub struct TermRegistry {
    entries: BTreeMap<&'static str, Arc<Entry>>,
}

impl TermRegistry {
    /// Registers term `T` as `name`, written `Name(field: value, ...)` in a term list.
    ///
    /// # Panics
    /// If `name` is not a CamelCase identifier (a programming error of the plugin,
    /// found when its registration first runs).
    pub fn register<T>(&mut self, name: &'static str, summary: &'static str)
    where
        T: Term + Send + Sync + 'static,
        T::Params: Send + Sync + 'static,
    {
        assert!(
            name.starts_with(|c: char| c.is_ascii_uppercase())
                && name.chars().all(|c| c.is_ascii_alphanumeric()),
            "term name `{name}`: write it CamelCase, as a scenario names it"
        );
        let read: Box<Reader> = Box::new(move |de| {
            let params: T::Params = erased_serde::deserialize(de)?;
            Ok(Box::new(Given::<T> { name, params }) as Box<dyn TermParams>)
        });
        self.entries.insert(name, Arc::new(Entry { read, summary }));
    }

    pub fn contains(&self, name: &str) -> bool {
        self.entries.contains_key(name)
    }

    /// Registered names with their one-line summaries, sorted.
    pub fn list(&self) -> impl Iterator<Item = (&'static str, &'static str)> + '_ {
        self.entries.iter().map(|(k, v)| (*k, v.summary))
    }

    /// Reads the parameters of term `name` from `de`; None if no term has that name.
    pub fn read(
        &self,
        name: &str,
        de: &mut dyn erased_serde::Deserializer,
    ) -> Option<Result<Box<dyn TermParams>, erased_serde::Error>> {
        self.entries.get(name).map(|e| (e.read)(de))
    }
}
