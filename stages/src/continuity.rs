//! Continuity equation d rho_i/dt = sum_j m_j v_ij . grad_i W_ij (physics.md,
//! "Governing equations"), summed over fluid and ghost neighbours.

use crate::packed::{with_packed, Fill};
use crate::pair_x8::WendlandX8;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{DensityRate, Fluid, Mass, Position, Velocity};
use sph_core::contract::Access;
use sph_core::kernel::Kernel;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{require_neighbours, ContinuityInPipeline, Neighbours};
use sph_core::world::ensure_component;
use sph_core::{with_kernel, StageRegistry};

#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {}

pub fn register(registry: &mut StageRegistry) {
    registry.register(
        "continuity",
        "density rate from the continuity equation",
        |_: Params| Ok(Continuity),
    );
}

pub struct Continuity;

impl Stage for Continuity {
    fn name(&self) -> &'static str {
        "continuity"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, "continuity")?;
        ensure_component::<Fluid, DensityRate>(sim);
        sim.resources.insert(ContinuityInPipeline);
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        with_packed(sim, Fill::Velocity, |sim, particles, all| {
            let Some(nb) = sim.resources.get::<Neighbours>() else {
                return Ok(());
            };
            let mut rate = particles.fluid_mut::<DensityRate>()?;
            let c = &sim.constants;
            let x8 = WendlandX8::detect(c.kernel, c.h);
            if x8.is_some() {
                nb.check_covers(all.len())?;
            }
            with_kernel!(c.kernel, c.h, |k| {
                rate.par_iter_mut().enumerate().for_each(|(i, out)| {
                    if let Some(x8) = x8 {
                        out.0 = x8.continuity(all, nb.of(i), i);
                        return;
                    }
                    let (xi, vi) = (all[i].x, all[i].v);
                    let mut sum = 0.0;
                    for &j in nb.of(i) {
                        let pj = &all[j as usize];
                        let xij = xi - pj.x;
                        let r = xij.length();
                        sum += pj.m * (vi - pj.v).dot(k.grad(xij, r));
                    }
                    out.0 = sum;
                })
            });
            Ok(())
        })?;
        Ok(())
    }

    /// The density rate from the neighbours' velocities.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Neighbours>()
            .reads::<Position>()
            .reads::<Velocity>()
            .reads::<Mass>()
            .writes::<DensityRate>()
    }
}
