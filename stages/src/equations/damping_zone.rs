//! A wave absorber: a damping zone at the end of a flume. After each step, fluid
//! velocities in the zone `from <= x <= to` relax towards rest,
//!   v <- v (1 - dt s xi^2),  xi = (x - from) / (to - from),
//! both the integer-time and the leapfrog's half-step velocity. The rate s xi^2 grows
//! smoothly from zero at the zone's start, so the incoming wave meets no sudden change
//! of medium to reflect from; a zone about one wavelength long with s dt_wave of a few
//! absorbs most of the wave (measure it: docs/validation.md, wave maker).
//!
//! Why a damping zone and not a sloping beach: a beach absorbs by breaking, which at
//! flume resolutions of 20-30 particles per depth is under-resolved and reflects a
//! resolution-dependent part of the wave, and it needs several wavelengths of flume.
//! Sloping walls still work (any straight wall segment can be given in `walls`).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Fluid, Position, Velocity};
use sph_core::contract::Access;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::HalfVelocity;
use sph_core::world::{archetype, column, column_mut};
use sph_core::StageRegistry;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Start of the zone [m] (no damping here).
    pub from: f64,
    /// End of the zone [m] (full damping rate here); beyond it the rate stays at s.
    pub to: f64,
    /// Largest relaxation rate s [1/s]. Default 10.
    #[serde(default = "ten")]
    pub strength: f64,
}

fn ten() -> f64 {
    10.0
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "damping_zone",
        "wave absorber: velocities relax to rest in a zone (after Integrate)",
        |p: Params| {
            let out = sph_core::ParamError::new;
            if !p.from.is_finite() {
                return Err(out("from", p.from, "a finite position [m]"));
            }
            if !(p.to.is_finite() && p.to > p.from) {
                let accepted = format!("a finite position beyond `from` = {} [m]", p.from);
                return Err(out("to", p.to, accepted.as_str()));
            }
            if !(p.strength >= 0.0 && p.strength.is_finite()) {
                return Err(out("strength", p.strength, "a rate >= 0 [1/s]"));
            }
            Ok(DampingZone { params: p })
        },
    );
}

pub struct DampingZone {
    params: Params,
}

impl Stage for DampingZone {
    fn name(&self) -> &'static str {
        "damping_zone"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        if archetype::<Fluid>(&sim.world).is_some_and(|a| !a.has::<HalfVelocity>()) {
            return Err(SetupError::new(
                "damping_zone",
                "put DampingZone() after Integrate() (it damps the integrator's velocities)",
            ));
        }
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let x = column::<Position>(fluid)?;
        let mut v = column_mut::<Velocity>(fluid)?;
        let mut vh = column_mut::<HalfVelocity>(fluid)?;
        let Params { from, to, strength } = self.params;
        let dt = sim.clock.dt;
        (&x[..], &mut v[..], &mut vh[..])
            .into_par_iter()
            .for_each(|(x, v, vh)| {
                if x.0.x > from {
                    let xi = ((x.0.x - from) / (to - from)).min(1.0);
                    let keep = (1.0 - dt * strength * xi * xi).max(0.0);
                    v.0 *= keep;
                    vh.0 *= keep;
                }
            });
        Ok(())
    }

    /// Damps the velocities Integrate produced, in place.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Position>()
            .updates::<Velocity>()
            .updates::<HalfVelocity>()
    }
}
