//! Tait equation of state p = B [(rho/rho_0)^gamma - 1] (docs/physics.md, "Governing equations") for fluid and
//! ghost particles.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Ghost, Pressure};
use sph_core::contract::Access;
use sph_core::sim::{Sim, Tait};
use sph_core::stage::{Stage, StepError};
use sph_core::world::{archetype, column, column_mut};
use sph_core::{ParamError, StageRegistry};

/// rho_0, c_0 and gamma are the scenario's `fluid`.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Pressure floor [Pa]: lower pressures are raised to it (e.g. 0 suppresses tension
    /// in thin free-surface jets). Default None: the Tait EOS as it is.
    pub min_pressure: Option<f64>,
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "eos",
        "Tait equation of state: pressure from density",
        |p: Params| {
            // A NaN floor would compare false with every pressure and leave it NaN.
            if let Some(f) = p.min_pressure.filter(|f| !f.is_finite()) {
                return Err(ParamError::new(
                    "min_pressure",
                    f,
                    "Some(<Pa>), a finite number (0 suppresses tension)",
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

// 2D set-ups; the 3D build's own tests are in `tests3d` modules.
#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use crate::testing::sim;
    use glam::DVec2;
    use sph_core::components::Position;

    /// Tait by hand: B [(rho/rho_0)^7 - 1], B = rho_0 c_0^2 / 7 (relative 1e-12:
    /// round-off of the powers).
    fn tait(rho: f64) -> f64 {
        1000.0 * 20.0 * 20.0 / 7.0 * ((rho / 1000.0).powi(7) - 1.0)
    }

    /// The stage gives fluid and ghosts the Tait pressure of their density, raised to
    /// the floor when one is set.
    #[test]
    fn pressures_are_taits_of_the_density_above_the_floor() {
        let densities = [990.0, 1000.0, 1004.0, 1020.0];
        for floor in [None, Some(0.0)] {
            let mut world = hecs::World::new();
            for &rho in &densities {
                let at = Position(DVec2::ZERO);
                world.spawn((Fluid, at, Density(rho), Pressure(f64::NAN)));
                world.spawn((Ghost { source: 0 }, at, Density(rho), Pressure(f64::NAN)));
            }
            let mut sim = sim(world);
            let mut stage = Eos {
                floor: floor.unwrap_or(f64::NEG_INFINITY),
            };
            assert_eq!(stage.name(), "eos");
            stage.run(&mut sim).unwrap();
            let mut seen = 0;
            for (rho, p) in sim.world.query::<(&Density, &Pressure)>().iter() {
                let want = tait(rho.0).max(floor.unwrap_or(f64::NEG_INFINITY));
                assert!(
                    (p.0 - want).abs() <= 1e-12 * tait(1020.0),
                    "floor {floor:?}, rho {}: p {} against {want}",
                    rho.0,
                    p.0
                );
                seen += 1;
            }
            assert_eq!(seen, 2 * densities.len());
            // The tension at rho = 990 is kept without a floor and raised with one.
            let lowest = sim
                .world
                .query::<&Pressure>()
                .iter()
                .map(|p| p.0)
                .fold(f64::INFINITY, sph_core::extremes::nan_min);
            assert_eq!(lowest < 0.0, floor.is_none(), "lowest pressure {lowest}");
        }
    }

    /// The stage's contract: it reads the density and writes the pressure.
    #[test]
    fn the_stage_declares_what_it_reads_and_writes() {
        use sph_core::contract::Quantity;
        let a = Eos { floor: 0.0 }.access();
        assert!(a.reads.contains(&Quantity::of::<Density>()));
        assert!(a.writes.contains(&Quantity::of::<Pressure>()));
    }

    /// The registry builds the stage under its name from its parameters, and refuses
    /// a NaN floor (which every comparison would ignore) naming the field.
    #[test]
    fn the_registry_builds_it_and_refuses_a_nan_floor() {
        let registry = crate::standard_registry();
        let build = |text: &str| {
            let mut de = ron::Deserializer::from_str(text).unwrap();
            let mut erased = <dyn erased_serde::Deserializer>::erase(&mut de);
            let built = registry
                .build("eos", &mut erased)
                .expect("eos is registered");
            built.map(|b| b.stage.name()).map_err(|e| e.to_string())
        };
        assert_eq!(build("()"), Ok("eos"));
        assert_eq!(build("(min_pressure: Some(0.0))"), Ok("eos"));
        let e = build("(min_pressure: Some(NaN))").unwrap_err();
        assert!(e.contains("min_pressure"), "{e}");
    }
}
