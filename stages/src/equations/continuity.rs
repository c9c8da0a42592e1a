//! Continuity equation d rho_i/dt = sum_j m_j v_ij . grad_i W_ij (docs/physics.md,
//! "Governing equations"), summed over fluid and ghost neighbours in a pass of its
//! own. `Forces(terms: [..., Continuity()])` sums the same term in the forces' loop
//! instead (one pass fewer), with the same result bit for bit.

use crate::rates::{self, Outputs};
use crate::terms::{continuity, RateTerms};
use crate::vocab::WallNormal;
use serde::{Deserialize, Serialize};
use sph_core::components::{DensityRate, Fluid};
use sph_core::contract::Access;
use sph_core::pair::RateTerm;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::require_neighbours;
use sph_core::world::ensure_component;
use sph_core::StageRegistry;

#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "continuity",
        "density rate from the continuity equation, in a pass of its own",
        |_: Params| {
            Ok(ContinuityStage {
                terms: RateTerms {
                    continuity: Some(continuity::Continuity::default()),
                    ..RateTerms::default()
                },
                scratch: Default::default(),
            })
        },
    );
}

pub struct ContinuityStage {
    terms: RateTerms,
    scratch: rates::Scratch,
}

impl Stage for ContinuityStage {
    fn name(&self) -> &'static str {
        "continuity"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, "continuity")?;
        ensure_component::<Fluid, DensityRate>(sim);
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let _span = tracing::trace_span!("pair_sums").entered();
        let out = Outputs {
            acceleration: false,
            density_rate: true,
            power: false,
            wall: false,
            counts: false,
            once: rates::Pairs::Auto.once(),
        };
        // With the pair mirror, continuity meets the wall particles as it does in
        // `Forces`.
        self.terms.continuity = Some(continuity::Continuity::for_walls(sim));
        rates::run(sim, &self.terms, out, &mut self.scratch, None).map(|_| ())
    }

    fn access(&self) -> Access {
        rates::declare_reads(Access::new(), self.terms.reads())
            .writes::<DensityRate>()
            .uses::<WallNormal>()
    }
}
