//! The pair terms: one file per term, each written once over the lane type of
//! `sph_core::pair` (so the scalar and the SIMD path are the same source).
//!
//! Terms of the equations of motion ([`RateTerm`]s) are named in a scenario's
//! `Forces(terms: [...])` and run in one neighbour loop. A new one is a file here with
//! its `Params` and a [`Term`] impl, and one line in the [`rate_terms!`] list below;
//! the list fixes the order in which the terms of one pair are added, whatever the
//! order the scenario names them in. The density filters ([`shepard`], [`mls`], [`free_surface_density`]) are
//! pair terms of their own, with their own accumulators.

pub mod artificial_pressure;
pub mod artificial_viscosity;
pub mod continuity;
pub mod delta_sph;
pub mod dfsph_factor;
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

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use sph_core::pair::{Fields, Lane, Me, Pair, RateTerm, Rates};
use sph_core::sim::Constants;

/// A rate term built from its scenario parameters.
pub trait Term: RateTerm + Sized {
    /// The fields of i and j the term reads (its `RateTerm::reads`), known before the
    /// run's constants are, for the stage's declared contract.
    const READS: Fields;
    /// Whether the term is a density diffusion (it adds to the continuity equation, so
    /// it needs `Continuity()` in the same list, and a list takes one at most).
    const DIFFUSION: bool = false;
    /// The parameters a scenario gives it, with documented defaults.
    type Params: Clone + std::fmt::Debug + Default + Serialize + DeserializeOwned;
    /// Refuses out-of-range parameters with a message naming the field and what is
    /// accepted (run when the scenario is read, so the error has its position).
    fn check(_p: &Self::Params) -> Result<(), String> {
        Ok(())
    }
    /// The term for a run with constants `c`, from checked parameters.
    fn build(p: &Self::Params, c: &Constants) -> Self;
    /// For a viscous term: read the ghosts' no-slip velocities (`Field::ShearVx`,
    /// `ShearVy`; the walls do not slip) instead of their `Vx`, `Vy`. Other terms
    /// ignore it.
    fn wall_shear(&mut self) {}
}

/// A viscous term's reads: `base`, and the ghosts' no-slip velocities when it reads
/// them ([`Term::wall_shear`]).
pub(crate) fn with_wall_shear(base: Fields, shear: bool) -> Fields {
    match shear {
        true => base.with(Fields::SHEAR),
        false => base,
    }
}

/// Checks that every `(field, value)` is a finite number >= 0.
pub(crate) fn check_non_negative(fields: &[(&str, f64)]) -> Result<(), String> {
    for &(field, v) in fields {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(format!(
                "field `{field}` = {v} is out of range; accepted: a finite number >= 0"
            ));
        }
    }
    Ok(())
}

/// Declares the rate terms a scenario can name: the [`TermSpec`] enum a term list is
/// read into, and [`RateTerms`], the chosen terms, summed in the order listed.
macro_rules! rate_terms {
    ($($module:ident :: $ty:ident),* $(,)?) => {
        /// A term as a scenario names it: `Name(field: value, ...)`.
        #[derive(Clone, Debug, Serialize, Deserialize)]
        pub enum TermSpec {
            $($ty(<$module::$ty as Term>::Params),)*
        }

        impl TermSpec {
            /// The name a scenario writes.
            pub fn name(&self) -> &'static str {
                match self {
                    $(TermSpec::$ty(_) => stringify!($ty),)*
                }
            }

            /// The fields the term reads.
            pub fn reads(&self) -> Fields {
                match self {
                    $(TermSpec::$ty(_) => <$module::$ty as Term>::READS,)*
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
        }

        impl RateTerms {
            /// Checks a term list: each term at most once, its parameters in range.
            pub fn check(specs: &[TermSpec]) -> Result<(), String> {
                for (k, spec) in specs.iter().enumerate() {
                    if specs[..k].iter().any(|s| s.name() == spec.name()) {
                        return Err(format!(
                            "field `terms`: {} is named twice; name each term once",
                            spec.name()
                        ));
                    }
                    let checked = match spec {
                        $(TermSpec::$ty(p) => $module::$ty::check(p),)*
                    };
                    checked.map_err(|e| format!("term {}: {e}", spec.name()))?;
                }
                let diffusions: Vec<&str> = specs
                    .iter()
                    .filter(|s| match s {
                        $(TermSpec::$ty(_) => <$module::$ty as Term>::DIFFUSION,)*
                    })
                    .map(|s| s.name())
                    .collect();
                if diffusions.len() > 1 {
                    return Err(format!(
                        "field `terms`: {} are all density diffusions; name one at most",
                        diffusions.join(", ")
                    ));
                }
                let continuity = specs.iter().any(|s| matches!(s, TermSpec::Continuity(_)));
                if let (Some(d), false) = (diffusions.first(), continuity) {
                    return Err(format!(
                        "field `terms`: {d} adds to the continuity equation's d rho/dt; name Continuity() in the same list"
                    ));
                }
                Ok(())
            }

            /// The terms present, bit k for the k-th term of the list ([`TermBit`]).
            pub fn set(&self) -> u16 {
                0 $(| if self.$module.is_some() { 1 << TermBit::$ty as u16 } else { 0 })*
            }

            /// The terms of a checked list for a run with constants `c`; with
            /// `wall_shear` the viscous terms read the ghosts' no-slip velocities
            /// ([`Term::wall_shear`]).
            pub fn build(specs: &[TermSpec], c: &Constants, wall_shear: bool) -> Self {
                let mut set = RateTerms::default();
                for spec in specs {
                    match spec {
                        $(TermSpec::$ty(p) => {
                            let mut t = $module::$ty::build(p, c);
                            if wall_shear {
                                t.wall_shear();
                            }
                            set.$module = Some(t);
                        })*
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
        }
    };
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

#[cfg(test)]
mod tests;
