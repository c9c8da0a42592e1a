//! The momentum equation, and with it any other rate of the equations of motion
//! (docs/physics.md, "Governing equations"): the pair terms the scenario names, summed
//! in one pass over the neighbours, plus gravity:
//!   dv_i/dt = - sum_j m_j (p_i/rho_i^2 + p_j/rho_j^2 + Pi_ij + R f_ij^n) grad_i W_ij + ... + g,
//! and, with the `Continuity()` term, d rho_i/dt = sum_j m_j v_ij . grad_i W_ij in the
//! same loop (one pass over the neighbours instead of two).

use crate::rates::{self, Outputs};
use crate::terms::{artificial_viscosity, pressure_gradient, RateTerms, TermSpec};
use serde::{Deserialize, Serialize};
use sph_core::components::{Acceleration, DensityRate, Fluid, NeighbourCount};
use sph_core::contract::Access;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{
    require_neighbours, ArtificialViscosity, DensityGradients, DiffusionPower,
    NeighbourCountsInPass, Neighbours, NoSlipVelocities, ViscousDissipation, WallPower,
};
use sph_core::world::{archetype, ensure_component};
use sph_core::StageRegistry;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// The pair terms, each at most once, e.g. `[PressureGradient(),
    /// ArtificialViscosity(alpha: 0.03), ArtificialPressure(), Continuity()]`; they are
    /// added in a fixed order whatever the order written. Default
    /// `[PressureGradient(), ArtificialViscosity()]` (alpha 0.03, beta 0).
    pub terms: Vec<TermSpec>,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            terms: vec![
                TermSpec::PressureGradient(pressure_gradient::Params::default()),
                TermSpec::ArtificialViscosity(artificial_viscosity::Params::default()),
            ],
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register(
        "forces",
        "dv/dt (and d rho/dt) from the pair terms it names, plus gravity",
        |p: Params| {
            RateTerms::check(&p.terms)?;
            Ok(Forces {
                params: p,
                terms: RateTerms::default(),
                chunk_power: Vec::new(),
                wall_shear: false,
                counts: false,
            })
        },
    );
}

pub struct Forces {
    params: Params,
    terms: RateTerms,
    /// The energy rates of each chunk of particles, kept between steps.
    chunk_power: Vec<rates::Power>,
    /// The viscous terms read the ghosts' no-slip velocities (`NoSlipVelocities`).
    wall_shear: bool,
    /// The fluid has a `NeighbourCount` column, which this pass fills in while the
    /// lists have a skin (`vocab::NeighbourCountsInPass`).
    counts: bool,
}

impl Stage for Forces {
    fn name(&self) -> &'static str {
        "forces"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, "forces")?;
        let no_slip = sim.resources.contains::<NoSlipVelocities>();
        self.terms = RateTerms::build(&self.params.terms, &sim.constants, no_slip);
        self.wall_shear = no_slip;
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
        let no_slip = sim.resources.contains::<NoSlipVelocities>();
        if no_slip != self.wall_shear {
            self.terms = RateTerms::build(&self.params.terms, &sim.constants, no_slip);
            self.wall_shear = no_slip;
        }
        // The walls' work on the fluid, for the energy budget: in the same pass when
        // the terms include continuity, else a pass over the ghost neighbours only
        // (stages/src/wall_work.rs).
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
        };
        if self.terms.delta_sph.is_some() {
            crate::density_gradient::compute(sim)?;
        }
        let power = rates::run(sim, &self.terms, out, &mut self.chunk_power)?;
        if let Some(d) = sim.resources.get_mut::<ViscousDissipation>() {
            d.power = power.viscous;
        }
        if let Some(d) = sim.resources.get_mut::<DiffusionPower>() {
            d.power = power.diffusion;
        }
        if wall {
            let power = match fused {
                true => power.wall,
                false => crate::wall_work::power(sim, &self.terms)?,
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
        let viscosity = terms.iter().find_map(|t| match t {
            TermSpec::ArtificialViscosity(p) => Some(ArtificialViscosity {
                alpha: p.alpha,
                beta: p.beta,
            }),
            _ => None,
        });
        let gradient = terms.iter().any(|t| matches!(t, TermSpec::DeltaSph(_)));
        let access = rates::declare_reads(Access::new(), reads)
            .writes_if::<DensityGradients>(gradient)
            .writes::<Acceleration>()
            .writes_if::<DensityRate>(continuity)
            .writes::<ViscousDissipation>()
            .writes::<DiffusionPower>()
            .writes::<WallPower>()
            .uses::<NeighbourCount>()
            .uses::<NoSlipVelocities>();
        match viscosity {
            Some(v) => access.exposes(v),
            None => access,
        }
    }
}
