//! The momentum equation, and with it any other rate of the equations of motion
//! (docs/physics.md, "Governing equations"): the pair terms the scenario names, summed
//! in one pass over the neighbours, plus gravity:
//!   dv_i/dt = - sum_j m_j (p_i/rho_i^2 + p_j/rho_j^2 + Pi_ij + R f_ij^n) grad_i W_ij + ... + g,
//! and, with the `Continuity()` term, d rho_i/dt = sum_j m_j v_ij . grad_i W_ij in the
//! same loop (one pass over the neighbours instead of two).

use crate::rates::{self, Outputs, Pairs};
use crate::terms::{
    artificial_viscosity, plugin_terms, pressure_gradient, term_list_seed, PrePass, RateTerms,
    TermRegistry, TermSpec,
};
use crate::vocab::{
    wall_mirror_in, DiffusionPower, KernelSums, NoSlipVelocity, ViscousDissipation, WallNormal,
    WallPower,
};
use serde::de::{self, DeserializeSeed, MapAccess, Visitor};
use serde::{Deserializer, Serialize};
use sph_core::components::{Acceleration, DensityRate, Fluid, NeighbourCount};
use sph_core::contract::Access;
use sph_core::pair::Columns;
use sph_core::pair::{PluginTerm, WithPlugins};
use sph_core::registry::Identifier;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{require_neighbours, NeighbourCountsInPass, Neighbours};
use sph_core::world::{archetype, ensure_component};
use sph_core::StageRegistry;

#[derive(Debug, Clone, Serialize)]
pub struct Params {
    /// The pair terms, each at most once, e.g. `[PressureGradient(),
    /// ArtificialViscosity(alpha: 0.03), ArtificialPressure(), Continuity()]`; the
    /// shipped ones are added in a fixed order whatever the order written, then any a
    /// plugin registered, in the order written. Default `[PressureGradient(),
    /// ArtificialViscosity()]` (alpha 0.03, beta 0).
    pub terms: Vec<TermSpec>,
    /// How each fluid pair is computed: `Auto` (default) once for both particles on
    /// the scalar path and from each side on the SIMD paths (where each side is
    /// faster: docs/performance.md, "Each pair once"); `Once` or `Twice` to choose.
    pub pairs: Pairs,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            terms: vec![
                TermSpec::PressureGradient(pressure_gradient::Params::default()),
                TermSpec::ArtificialViscosity(artificial_viscosity::Params::default()),
            ],
            pairs: Pairs::Auto,
        }
    }
}

/// Reads [`Params`] with the terms plugins registered: `(terms: [...], pairs: ...)`,
/// every field optional, none other accepted.
struct ParamsSeed<'a>(&'a TermRegistry);

const FIELDS: &[&str] = &["terms", "pairs"];

impl<'de> DeserializeSeed<'de> for ParamsSeed<'_> {
    type Value = Params;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Params, D::Error> {
        d.deserialize_struct("Params", FIELDS, self)
    }
}

impl<'de> Visitor<'de> for ParamsSeed<'_> {
    type Value = Params;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("Forces' parameters, (terms: [...])")
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Params, A::Error> {
        let (mut terms, mut pairs) = (None, None);
        while let Some(key) = map.next_key_seed(Identifier("a field name"))? {
            match key.as_str() {
                "terms" if terms.is_some() => return Err(de::Error::duplicate_field("terms")),
                "terms" => terms = Some(map.next_value_seed(term_list_seed(self.0))?),
                "pairs" if pairs.is_some() => return Err(de::Error::duplicate_field("pairs")),
                "pairs" => pairs = Some(map.next_value()?),
                other => return Err(de::Error::unknown_field(other, FIELDS)),
            }
        }
        let default = Params::default();
        Ok(Params {
            terms: terms.unwrap_or(default.terms),
            pairs: pairs.unwrap_or(default.pairs),
        })
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_read(
        "forces",
        "dv/dt (and d rho/dt) from the pair terms it names, plus gravity",
        |registry, de| ParamsSeed(registry.terms()).deserialize(de),
        |p: Params| -> Result<Forces, crate::terms::TermListError> {
            RateTerms::check(&p.terms)?;
            Ok(Forces {
                params: p,
                terms: RateTerms::default(),
                plugins: Vec::new(),
                pre_passes: Vec::new(),
                scratch: Default::default(),
                wall_shear: false,
                wall_mirror: false,
                counts: false,
            })
        },
    );
}

pub struct Forces {
    params: Params,
    terms: RateTerms,
    /// The plugins' terms, summed after `terms` in the same loop.
    plugins: Vec<PluginTerm>,
    /// The passes the terms need before the loop ([`crate::terms::Term::PRE_PASS`]), in
    /// list order.
    pre_passes: Vec<PrePass>,
    /// The energy rates of each chunk of particles, kept between steps.
    scratch: rates::Scratch,
    /// The viscous terms read the ghosts' no-slip velocities (`NoSlipVelocity`).
    wall_shear: bool,
    /// The terms meet wall particles with i's mirror image (`WallNormal`).
    wall_mirror: bool,
    /// The fluid has a `NeighbourCount` column, which this pass fills in while the
    /// lists have a skin (`vocab::NeighbourCountsInPass`).
    counts: bool,
}

impl Forces {
    /// The terms for the run, the viscous ones reading the ghosts' no-slip velocities
    /// with `no_slip`.
    fn build_terms(&mut self, sim: &Sim, no_slip: bool) {
        self.wall_mirror = wall_mirror_in(sim);
        self.terms = RateTerms::build_walls(
            &self.params.terms,
            &sim.constants,
            no_slip,
            self.wall_mirror,
        );
        self.plugins = plugin_terms(&self.params.terms, &sim.constants, no_slip);
        self.wall_shear = no_slip;
        self.pre_passes.clear();
        for pass in self.params.terms.iter().filter_map(TermSpec::pre_pass) {
            // Once each, however many terms need it.
            if !self
                .pre_passes
                .iter()
                .any(|&p| std::ptr::fn_addr_eq(p, pass))
            {
                self.pre_passes.push(pass);
            }
        }
    }
}

/// Whether the walls store the ghosts' no-slip velocities (walls that do not slip).
fn has_no_slip(sim: &Sim) -> bool {
    sim.resources
        .get::<Columns>()
        .is_some_and(|c| c.contains::<NoSlipVelocity>())
}

impl Stage for Forces {
    fn name(&self) -> &'static str {
        "forces"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, "forces")?;
        let no_slip = has_no_slip(sim);
        self.build_terms(sim, no_slip);
        ensure_component::<Fluid, Acceleration>(sim);
        if self.terms.continuity.is_some() {
            ensure_component::<Fluid, DensityRate>(sim);
        }
        self.counts = archetype::<Fluid>(&sim.world).is_some_and(|a| a.has::<NeighbourCount>());
        if self.counts {
            sim.resources.insert(NeighbourCountsInPass);
        }
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let _span = tracing::trace_span!("pair_sums").entered();
        // Ghost walls set up after this stage (a pipeline that lists them later) are
        // known only now.
        let no_slip = has_no_slip(sim);
        if no_slip != self.wall_shear || wall_mirror_in(sim) != self.wall_mirror {
            self.build_terms(sim, no_slip);
        }
        // The walls' work on the fluid, for the energy budget: in the same pass when
        // the terms include continuity, else a pass over the ghost neighbours only
        // (stages/src/walls/wall_work.rs).
        let wall = sim.resources.contains::<WallPower>();
        let fused = wall && self.terms.continuity.is_some();
        let out = Outputs {
            acceleration: true,
            density_rate: self.terms.continuity.is_some(),
            power: sim.resources.contains::<ViscousDissipation>()
                || sim.resources.contains::<DiffusionPower>(),
            wall: fused,
            // Without a skin the grid counts the lists themselves.
            counts: self.counts
                && sim
                    .resources
                    .get::<Neighbours>()
                    .is_some_and(|nb| nb.skin > 0.0),
            once: self.params.pairs.once(),
        };
        for pass in &self.pre_passes {
            pass(sim)?;
        }
        // A density summation after this stage asked for the kernel sums.
        let mut sums = sim
            .resources
            .get_mut::<KernelSums>()
            .map(|s| std::mem::take(&mut s.0));
        let power = match self.plugins.is_empty() {
            true => rates::run(sim, &self.terms, out, &mut self.scratch, sums.as_mut()),
            false => {
                let terms = WithPlugins {
                    base: self.terms,
                    plugins: &self.plugins,
                };
                rates::run_set_with(sim, terms, out, &mut self.scratch, sums.as_mut())
            }
        };
        if let (Some(sums), Some(kept)) = (sums, sim.resources.get_mut::<KernelSums>()) {
            kept.0 = sums;
        }
        let power = power?;
        if let Some(d) = sim.resources.get_mut::<ViscousDissipation>() {
            d.power = power.viscous;
        }
        if let Some(d) = sim.resources.get_mut::<DiffusionPower>() {
            d.power = power.diffusion;
        }
        if wall {
            let power = match fused {
                true => power.wall,
                false => crate::wall_work::power(sim, &self.terms, &self.plugins)?,
            };
            if let Some(w) = sim.resources.get_mut::<WallPower>() {
                w.power = power;
            }
        }
        Ok(())
    }

    fn access(&self) -> Access {
        let terms = &self.params.terms;
        let reads = terms
            .iter()
            .fold(Default::default(), |f, t| t.reads().with(f));
        let continuity = terms.iter().any(|t| matches!(t, TermSpec::Continuity(_)));
        let access = rates::declare_reads(Access::new(), reads)
            .writes::<Acceleration>()
            .writes_if::<DensityRate>(continuity)
            .writes::<ViscousDissipation>()
            .writes::<DiffusionPower>()
            .writes::<WallPower>()
            .writes::<KernelSums>()
            .uses::<NeighbourCount>()
            .uses::<NoSlipVelocity>()
            .uses::<WallNormal>();
        terms.iter().fold(access, |a, t| t.declare(a))
    }
}
