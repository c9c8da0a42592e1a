//! The pair terms: one file per term, each written once over the lane type of
//! `sph_core::pair` (so the scalar and the SIMD path are the same source).
//!
//! Terms of the equations of motion ([`RateTerm`]s) are named in a scenario's
//! `Forces(terms: [...])` and run in one neighbour loop. A shipped one is a file here
//! with its `Params` and a [`Term`] impl, and one line in the [`rate_terms!`] list
//! below; the list fixes the order in which the terms of one pair are added, whatever
//! the order the scenario names them in. A plugin's term implements the same [`Term`]
//! in its own crate and is registered with `StageRegistry::register_term`; it is
//! added after the shipped ones, in list order (`plugins/cohesion`). The density filters ([`shepard`], [`mls`], [`free_surface_density`]) are
//! pair terms of their own, with their own accumulators.

pub mod artificial_pressure;
pub mod artificial_viscosity;
pub mod continuity;
pub mod delta_sph;
pub mod diffusion;
pub mod fourtakas;
pub mod free_surface_density;
pub mod laminar_viscosity;
pub mod mls;
pub mod molteni_colagrossi;
pub mod pressure_gradient;
pub mod riemann;
pub mod riemann_diffusion;
pub mod riemann_pressure;
pub mod shepard;

use crate::vocab::{NoSlipVelocity, WallNormal};
use serde::de::{self, DeserializeSeed, EnumAccess, VariantAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use sph_core::contract::Access;
use sph_core::pair::{Fields, Lane, Layouts, Me, Pair, PluginTerm, RateTerm, Rates};
use sph_core::registry::{Identifier, ParamError, SeqOf};
use sph_core::sim::Constants;
pub use sph_core::terms::{PrePass, Term, TermParams, TermRegistry};

/// The term set of `list`: bit k for the k-th term of the list ([`TermBit`], as
/// [`RateTerms::set`]).
pub(crate) const fn set_of(list: &[TermBit]) -> u16 {
    let (mut set, mut k) = (0, 0);
    while k < list.len() {
        set |= 1 << list[k] as u16;
        k += 1;
    }
    set
}

/// A viscous term's reads: `base`, and the ghosts' no-slip velocities when it reads
/// them ([`Term::wall_shear`]).
pub(crate) fn with_wall_shear(base: Fields, shear: bool) -> Fields {
    match shear {
        true => base.with(NoSlipVelocity::FIELDS),
        false => base,
    }
}

/// `base` with the wall particles' normals, for a term that meets them with i's own
/// mirror image ([`Term::wall_mirror`], [`crate::vocab::wall_mirrored_v_ij`]).
pub(crate) const fn with_wall_mirror(base: Fields, mirror: bool) -> Fields {
    match mirror {
        true => base.with(WallNormal::FIELDS),
        false => base,
    }
}

/// Checks that every `(field, value)` is a finite number >= 0.
pub(crate) fn check_non_negative(fields: &[(&'static str, f64)]) -> Result<(), ParamError> {
    for &(field, v) in fields {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(ParamError::new(field, v, "a finite number >= 0"));
        }
    }
    Ok(())
}

/// A term list refused: the messages name the field `terms` (or, for a term's own
/// parameter, the term and its field) and what is accepted.
#[derive(Debug, thiserror::Error)]
pub enum TermListError {
    #[error("field `terms`: {0} is named twice; name each term once")]
    Twice(&'static str),
    #[error("term {term}: {error}")]
    Param {
        term: &'static str,
        error: ParamError,
    },
    #[error("field `terms`: {} are all density diffusions; name one at most", .0.join(", "))]
    Diffusions(Vec<&'static str>),
    #[error("field `terms`: {0} adds to the continuity equation's d rho/dt; name Continuity() in the same list")]
    NoContinuity(&'static str),
}

/// Reads one term of a list, `Name(field: value, ...)`: a shipped one, or one a plugin
/// registered in `terms`.
#[derive(Clone, Copy)]
pub struct TermSeed<'a>(pub &'a TermRegistry);

/// Reads a term list, `[Name(...), ...]` ([`TermSeed`] for each).
pub fn term_list_seed(terms: &TermRegistry) -> SeqOf<TermSeed<'_>> {
    SeqOf(
        TermSeed(terms),
        "a list of pair terms, e.g. [PressureGradient(), Continuity()]",
    )
}

/// Reads a registered term's parameters through the erased deserializer.
struct PluginSeed<'a> {
    terms: &'a TermRegistry,
    name: &'a str,
}

impl<'de> DeserializeSeed<'de> for PluginSeed<'_> {
    type Value = Box<dyn TermParams>;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        let mut erased = <dyn erased_serde::Deserializer>::erase(d);
        match self.terms.read(self.name, &mut erased) {
            Some(read) => read.map_err(de::Error::custom),
            None => Err(de::Error::custom(format!("unknown term `{}`", self.name))),
        }
    }
}

impl<'de> Deserialize<'de> for TermSpec {
    /// A shipped term (no plugin's).
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<TermSpec, D::Error> {
        TermSeed(&TermRegistry::default()).deserialize(d)
    }
}

/// Declares the rate terms a scenario can name: the [`TermSpec`] enum a term list is
/// read into, and [`RateTerms`], the chosen terms, summed in the order listed.
macro_rules! rate_terms {
    ($($module:ident :: $ty:ident),* $(,)?) => {
        /// A term as a scenario names it: `Name(field: value, ...)`.
        #[derive(Clone, Debug)]
        pub enum TermSpec {
            $($ty(<$module::$ty as Term>::Params),)*
            /// A term a plugin registered ([`TermRegistry`]).
            Plugin(Box<dyn TermParams>),
        }

        /// The shipped terms' names, in summing order.
        pub const SHIPPED: &[&str] = &[$(stringify!($ty)),*];

        impl TermSpec {
            /// The name a scenario writes.
            pub fn name(&self) -> &'static str {
                match self {
                    $(TermSpec::$ty(_) => stringify!($ty),)*
                    TermSpec::Plugin(p) => p.name(),
                }
            }

            /// The fields the term reads.
            pub fn reads(&self) -> Fields {
                match self {
                    $(TermSpec::$ty(_) => <$module::$ty as Term>::READS,)*
                    TermSpec::Plugin(p) => p.reads(),
                }
            }

            /// Whether the term is a density diffusion ([`Term::DIFFUSION`]).
            pub fn is_diffusion(&self) -> bool {
                match self {
                    $(TermSpec::$ty(_) => <$module::$ty as Term>::DIFFUSION,)*
                    TermSpec::Plugin(p) => p.diffusion(),
                }
            }

            fn check(&self) -> Result<(), ParamError> {
                match self {
                    $(TermSpec::$ty(p) => $module::$ty::check(p),)*
                    TermSpec::Plugin(p) => p.check(),
                }
            }

            /// The pass the term needs before the loop ([`Term::PRE_PASS`]).
            pub fn pre_pass(&self) -> Option<PrePass> {
                match self {
                    $(TermSpec::$ty(_) => <$module::$ty as Term>::PRE_PASS,)*
                    TermSpec::Plugin(p) => p.pre_pass(),
                }
            }

            /// `access` with what the term declares ([`Term::declare`]).
            pub fn declare(&self, access: Access) -> Access {
                match self {
                    $(TermSpec::$ty(p) => $module::$ty::declare(p, access),)*
                    TermSpec::Plugin(p) => p.declare(access),
                }
            }
        }

        impl Serialize for TermSpec {
            /// As a scenario writes it (with the variant newtypes unwrapped).
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let (name, k) = (self.name(), SHIPPED.len() as u32);
                let k = SHIPPED.iter().position(|n| *n == name).map_or(k, |i| i as u32);
                match self {
                    $(TermSpec::$ty(p) => s.serialize_newtype_variant("TermSpec", k, name, p),)*
                    TermSpec::Plugin(p) => s.serialize_newtype_variant("TermSpec", k, name, p),
                }
            }
        }

        impl<'de> DeserializeSeed<'de> for TermSeed<'_> {
            type Value = TermSpec;
            fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<TermSpec, D::Error> {
                d.deserialize_enum("TermSpec", SHIPPED, self)
            }
        }

        impl<'de> Visitor<'de> for TermSeed<'_> {
            type Value = TermSpec;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a pair term, e.g. PressureGradient()")
            }
            fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<TermSpec, A::Error> {
                let (name, variant) = data.variant_seed(Identifier("a pair term's name"))?;
                match name.as_str() {
                    $(stringify!($ty) => variant.newtype_variant().map(TermSpec::$ty),)*
                    _ if self.0.contains(&name) => variant
                        .newtype_variant_seed(PluginSeed { terms: self.0, name: &name })
                        .map(TermSpec::Plugin),
                    _ => {
                        let known: Vec<String> = SHIPPED
                            .iter()
                            .copied()
                            .chain(self.0.list().map(|(n, _)| n))
                            .map(|n| format!("`{n}`"))
                            .collect();
                        Err(de::Error::custom(format!(
                            "unknown variant `{name}`, expected one of {}",
                            known.join(", ")
                        )))
                    }
                }
            }
        }

        /// The terms of one pair stage, each at most once.
        #[derive(Clone, Copy, Debug, Default)]
        pub struct RateTerms {
            $(pub $module: Option<$module::$ty>,)*
        }

        /// Each term's bit in a [`RateTerms::set`].
        #[derive(Clone, Copy)]
        #[repr(u16)]
        pub enum TermBit {
            $($ty,)*
        }

        /// A term set with the terms known at compile time: bit k of `SET` for the
        /// k-th term of the list. The loop of a set that a stage runs often is compiled
        /// for it: no test per term and pair, no code for the absent terms (whose
        /// slots hold unused defaults).
        #[derive(Clone, Copy, Default)]
        pub struct Fixed<const SET: u16> {
            $($module: $module::$ty,)*
        }

        impl<const SET: u16> Fixed<SET> {
            /// The terms of `terms`, whose set must be `SET` (else None).
            pub fn of(terms: &RateTerms) -> Option<Self> {
                (terms.set() == SET).then(|| Self {
                    $($module: terms.$module.unwrap_or_default(),)*
                })
            }
        }

        impl<const SET: u16> RateTerm for Fixed<SET> {
            const USES_COEF: bool =
                false $(|| (SET & (1 << TermBit::$ty as u16) != 0 && <$module::$ty as RateTerm>::USES_COEF))*;
            // The records are packed with the set's reads, and with the walls'
            // no-slip velocities when a viscous term reads them (wall particles, or
            // mirrors that do not slip): a loop for each that is a compiled layout.
            const LAYOUTS: Layouts = {
                let reads = Fields::of(&[]) $(.with(match SET & (1 << TermBit::$ty as u16) {
                    0 => Fields::of(&[]),
                    _ => <$module::$ty as Term>::READS,
                }))*;
                let layouts =
                    Layouts::of(reads).with(Layouts::of(reads.with(NoSlipVelocity::FIELDS)));
                // With the wall particles' normals (the pair mirror) for Riemann-solver
                // SPH in 3D, as SPHERIC Test 2 runs it; elsewhere the pair mirror runs
                // the generic loop, which no shipped file needs.
                #[cfg(feature = "dim3")]
                let layouts = match SET & (1 << TermBit::RiemannPressure as u16) {
                    0 => layouts,
                    _ => layouts.with(Layouts::of(with_wall_mirror(reads, true))),
                };
                layouts
            };
            fn reads(&self) -> Fields {
                let mut f = Fields::default();
                $(if SET & (1 << TermBit::$ty as u16) != 0 {
                    f = f.with(self.$module.reads());
                })*
                f
            }
            #[inline(always)]
            fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
                $(if SET & (1 << TermBit::$ty as u16) != 0 {
                    self.$module.pair(me, p, r);
                })*
            }
            const SYMMETRIC: bool =
                true $(&& (SET & (1 << TermBit::$ty as u16) == 0 || <$module::$ty as RateTerm>::SYMMETRIC))*;
            #[inline(always)]
            fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, ri: &mut Rates<L>, rj: &mut Rates<L>) {
                $(if SET & (1 << TermBit::$ty as u16) != 0 {
                    self.$module.pair_both(me, p, ri, rj);
                })*
            }
        }

        impl RateTerms {
            /// Checks a term list: each term at most once, its parameters in range.
            pub fn check(specs: &[TermSpec]) -> Result<(), TermListError> {
                for (k, spec) in specs.iter().enumerate() {
                    if specs[..k].iter().any(|s| s.name() == spec.name()) {
                        return Err(TermListError::Twice(spec.name()));
                    }
                    spec.check().map_err(|error| TermListError::Param {
                        term: spec.name(),
                        error,
                    })?;
                }
                let diffusions: Vec<&'static str> = specs
                    .iter()
                    .filter(|s| s.is_diffusion())
                    .map(|s| s.name())
                    .collect();
                if diffusions.len() > 1 {
                    return Err(TermListError::Diffusions(diffusions));
                }
                let continuity = specs.iter().any(|s| matches!(s, TermSpec::Continuity(_)));
                if let (Some(&d), false) = (diffusions.first(), continuity) {
                    return Err(TermListError::NoContinuity(d));
                }
                Ok(())
            }

            /// The terms present, bit k for the k-th term of the list ([`TermBit`]).
            pub fn set(&self) -> u16 {
                0 $(| if self.$module.is_some() { 1 << TermBit::$ty as u16 } else { 0 })*
            }

            /// The shipped terms of a checked list for a run with constants `c`; with
            /// `wall_shear` the viscous terms read the ghosts' no-slip velocities
            /// ([`Term::wall_shear`]). The plugins' terms are [`plugin_terms`].
            pub fn build(specs: &[TermSpec], c: &Constants, wall_shear: bool) -> Self {
                Self::build_walls(specs, c, wall_shear, false)
            }

            /// [`RateTerms::build`], and with `wall_mirror` the terms that read a pair's
            /// velocity meet wall particles with i's mirror image ([`Term::wall_mirror`]).
            pub fn build_walls(specs: &[TermSpec], c: &Constants, wall_shear: bool, wall_mirror: bool) -> Self {
                let mut set = RateTerms::default();
                for spec in specs {
                    match spec {
                        $(TermSpec::$ty(p) => {
                            let mut t = $module::$ty::build(p, c);
                            if wall_shear {
                                t.wall_shear();
                            }
                            if wall_mirror {
                                t.wall_mirror();
                            }
                            set.$module = Some(t);
                        })*
                        TermSpec::Plugin(_) => {}
                    }
                }
                set
            }
        }

        impl RateTerm for RateTerms {
            fn reads(&self) -> Fields {
                let mut f = Fields::default();
                $(if let Some(t) = &self.$module { f = f.with(t.reads()); })*
                f
            }
            // Any set: multiplied out always (C_ij = 0 adds nothing).
            const USES_COEF: bool = true;
            #[inline(always)]
            fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, r: &mut Rates<L>) {
                $(if let Some(t) = &self.$module { t.pair(me, p, r); })*
            }
            const SYMMETRIC: bool = true $(&& <$module::$ty as RateTerm>::SYMMETRIC)*;
            #[inline(always)]
            fn pair_both<L: Lane>(&self, me: &Me, p: &Pair<L>, ri: &mut Rates<L>, rj: &mut Rates<L>) {
                $(if let Some(t) = &self.$module { t.pair_both(me, p, ri, rj); })*
            }
        }
    };
}

/// The plugins' terms of a checked list, in list order, for a run with constants `c`
/// (`wall_shear` as for [`RateTerms::build`]); they are summed after the shipped ones.
pub fn plugin_terms(specs: &[TermSpec], c: &Constants, wall_shear: bool) -> Vec<PluginTerm> {
    specs
        .iter()
        .filter_map(|s| match s {
            TermSpec::Plugin(p) => Some(p.build(c, wall_shear)),
            _ => None,
        })
        .collect()
}

rate_terms! {
    pressure_gradient::PressureGradient,
    artificial_viscosity::ArtificialViscosity,
    artificial_pressure::ArtificialPressure,
    laminar_viscosity::LaminarViscosity,
    continuity::Continuity,
    molteni_colagrossi::MolteniColagrossi,
    fourtakas::Fourtakas,
    delta_sph::DeltaSph,
    riemann_pressure::RiemannPressure,
    riemann_diffusion::RiemannDiffusion,
}

// On the 2D lattices of `tests`; 3D: `crate::tests3d`.
#[cfg(all(test, not(feature = "dim3")))]
mod each_pair_once_tests;
#[cfg(all(test, not(feature = "dim3")))]
mod generic_tests;
// 2D formulas written out by hand.
#[cfg(all(test, not(feature = "dim3")))]
mod tests;
