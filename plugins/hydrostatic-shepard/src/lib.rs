//! An example plugin extraction method, `HydrostaticShepard`: a wall-pressure sensor
//! reading written outside the engine, against `sph_core::extraction`, and named in a
//! scenario's probe like the shipped methods:
//!
//! ```ron
//! Probe(methods: [Shepard, HydrostaticShepard]),
//! ```
//!
//! It writes the `probes.csv` column `<sensor>.hydrostatic_shepard`.
//!
//! # The method
//! Shepard interpolation at the sensor point x_s of the fluid particles' pressures,
//! each first carried hydrostatically from the particle to the sensor (in the wall's
//! frame, with the effective gravity g - a_wall):
//!
//!   p(x_s) = sum_j [p_j + rho_0 g_eff . (x_s - x_j)] W_sj V_j / sum_j W_sj V_j,
//!   V_j = m_j / rho_j, over fluid particles j only.
//!
//! Method I interpolates fluid and ghost pressures, so it reads whatever the wall model
//! gives its ghosts; this one reads the fluid alone. At a wall only half the support
//! holds fluid, and a plain fluid-only Shepard average would then read the pressure of
//! the weighted fluid, about a fifth of a support above a floor sensor (3.5 % low in
//! the still-water test); the carry removes that bias exactly for a hydrostatic field (Method II applies the same carry to one
//! particle). A sensor with no fluid within the support reads 0 (dry).
//!
//! # Adding an extraction method, step by step
//! 1. Write a type implementing [`ExtractionMethod`] (with `Default`): `pressure` gets
//!    the sim, the fluid and ghost columns ([`Particles`]) and the [`Site`] (the wall,
//!    the abscissa along it, the sensor's width, the hydrostatic [`Carry`]); return 0
//!    for a dry sensor. Say in `needs_grid` whether it reads the neighbour grid.
//! 2. Register it: `registry.register_extraction::<M>("Name", "summary")`.
//! 3. A scenario names it in `Probe(methods: [...])`; an engine without the plugin
//!    refuses the name at its line, listing the methods it knows.

use sph_core::components::{Density, Mass, Position, Pressure};
use sph_core::extraction::{Carry, ExtractionMethod, Site};
use sph_core::kernel;
use sph_core::sim::Sim;
use sph_core::stage::StepError;
use sph_core::vocab::Neighbours;
use sph_core::world::Particles;
use sph_core::StageRegistry;

/// The name a scenario writes.
pub const NAME: &str = "HydrostaticShepard";

/// Registers the method as `HydrostaticShepard`.
pub fn register(registry: &mut StageRegistry) {
    registry.register_extraction::<HydrostaticShepard>(
        NAME,
        "Shepard interpolation of the fluid's pressures, each carried hydrostatically to the sensor",
    );
}

/// The method (module docs).
#[derive(Default)]
pub struct HydrostaticShepard;

impl ExtractionMethod for HydrostaticShepard {
    fn needs_grid(&self) -> bool {
        true
    }

    fn pressure(&mut self, sim: &Sim, particles: Particles, site: &Site) -> Result<f64, StepError> {
        let Some(nb) = sim.resources.get::<Neighbours>() else {
            return Ok(0.0);
        };
        let (x, p) = (
            particles.fluid::<Position>()?,
            particles.fluid::<Pressure>()?,
        );
        let (rho, m) = (particles.fluid::<Density>()?, particles.fluid::<Mass>()?);
        let at = site.point();
        let c = &sim.constants;
        let carry: Carry = site.carry;
        let (mut num, mut den) = (0.0, 0.0);
        // The grid indexes the fluid first, then the ghosts: only the fluid is read.
        nb.grid.for_each_near(at, |j| {
            let j = j as usize;
            if j < x.len() {
                let w = kernel::w(c.kernel, c.h, (at - x[j].0).length());
                let vol = m[j].0 / rho[j].0;
                num += carry.carry(p[j].0, x[j].0, at) * w * vol;
                den += w * vol;
            }
        });
        Ok(if den > 0.0 { num / den } else { 0.0 })
    }
}
