//! Tait equation of state p = B [(rho/rho_0)^gamma - 1] (physics.md) for fluid and
//! ghost particles.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Ghost, Pressure};
use sph_core::sim::{Sim, Tait};
use sph_core::stage::{Stage, StepError};
use sph_core::world::{archetype, column, column_mut};
use sph_core::StageRegistry;

/// The EOS has no parameters of its own: rho_0, c_0 and gamma are the scenario's `fluid`.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {}

pub fn register(registry: &mut StageRegistry) {
    registry.register(
        "eos",
        "Tait equation of state: pressure from density",
        |_: Params| Ok(Eos),
    );
}

pub struct Eos;

impl Stage for Eos {
    fn name(&self) -> &'static str {
        "eos"
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let eos = sim.constants.eos;
        if let Some(a) = archetype::<Fluid>(&sim.world) {
            apply(
                &eos,
                &column::<Density>(a)?,
                &mut column_mut::<Pressure>(a)?,
            );
        }
        if let Some(a) = archetype::<Ghost>(&sim.world) {
            apply(
                &eos,
                &column::<Density>(a)?,
                &mut column_mut::<Pressure>(a)?,
            );
        }
        Ok(())
    }
}

fn apply(eos: &Tait, rho: &[Density], p: &mut [Pressure]) {
    p.par_iter_mut()
        .zip(rho.par_iter())
        .for_each(|(p, rho)| p.0 = eos.pressure(rho.0));
}
