//! Tait equation of state p = B [(rho/rho_0)^gamma - 1] (docs/physics.md, "Governing equations") for fluid and
//! ghost particles.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Ghost, Pressure};
use sph_core::contract::Access;
use sph_core::sim::{Sim, Tait};
use sph_core::stage::{Stage, StepError};
use sph_core::world::{archetype, column, column_mut};
use sph_core::StageRegistry;

/// rho_0, c_0 and gamma are the scenario's `fluid`.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Pressure floor [Pa]: lower pressures are raised to it (e.g. 0 suppresses tension
    /// in thin free-surface jets). Default None: the Tait EOS as it is.
    pub min_pressure: Option<f64>,
}

pub fn register(registry: &mut StageRegistry) {
    registry.register(
        "eos",
        "Tait equation of state: pressure from density",
        |p: Params| {
            // A NaN floor would compare false with every pressure and leave it NaN.
            if let Some(f) = p.min_pressure.filter(|f| !f.is_finite()) {
                return Err(format!(
                    "field `min_pressure` = {f} is out of range; accepted: Some(<Pa>), a finite number (0 suppresses tension)"
                ));
            }
            Ok(Eos {
                floor: p.min_pressure.unwrap_or(f64::NEG_INFINITY),
            })
        },
    );
}

pub struct Eos {
    floor: f64,
}

impl Stage for Eos {
    fn name(&self) -> &'static str {
        "eos"
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let eos = sim.constants.eos;
        for arch in [
            archetype::<Fluid>(&sim.world),
            archetype::<Ghost>(&sim.world),
        ]
        .into_iter()
        .flatten()
        {
            apply(
                &eos,
                self.floor,
                &column::<Density>(arch)?,
                &mut column_mut::<Pressure>(arch)?,
            );
        }
        Ok(())
    }

    /// Pressure from density, for fluid and ghosts.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Density>()
            .uses::<Ghost>()
            .writes::<Pressure>()
    }
}

fn apply(eos: &Tait, floor: f64, rho: &[Density], p: &mut [Pressure]) {
    p.par_iter_mut()
        .zip(rho.par_iter())
        .for_each(|(p, rho)| p.0 = eos.pressure(rho.0).max(floor));
}
