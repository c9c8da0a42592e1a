//! The DFSPH pipeline's time integration (docs/physics.md, "DFSPH"; Bender & Koschier
//! 2017, Algorithm 1): the positions move with the velocities the density solve left,
//! x^{n+1} = x^n + dt v*, dt the step it chose (`vocab::StepSize`); the clock advances
//! (and the scene with it). The velocities need no update here: the solves have
//! already applied every force (symplectic Euler). A particle that ends the step
//! behind a wall is reflected (`Walls::reflect`, counted in `wall_reflections`), as
//! `Integrate` does; a non-finite position or one outside the domain stops the run.

use crate::vocab::StepSize;
use crate::vocab::WallReflections;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Fluid, Position, Velocity};
use sph_core::contract::Access;
use sph_core::sim::Counter;
use sph_core::sim::{Clock, Sim};
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{BodyPose, WallPose, Walls};
use sph_core::world::{archetype, column_mut};
use sph_core::StageRegistry;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// A particle that ends a step behind a wall is reflected back (position mirrored,
    /// outward normal velocity relative to the wall reversed) and counted in the
    /// `wall_reflections` diagnostic; with `false` it stops the run. Default true.
    pub reflect_at_walls: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            reflect_at_walls: true,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "advance",
        "DFSPH: moves the particles by the solved velocities and advances the clock",
        |p: Params| {
            Ok(Advance {
                params: p,
                walls: Walls::default(),
            })
        },
    );
}

pub struct Advance {
    params: Params,
    /// The walls at the end of the step (re-read every step).
    walls: Walls,
}

impl Stage for Advance {
    fn name(&self) -> &'static str {
        "advance"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        if !sim.resources.contains::<StepSize>() {
            return Err(SetupError::new(
                "advance",
                "needs the step the pressure solve chose: put DensitySolve() before it",
            ));
        }
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let dt = sim.resources.get::<StepSize>().map_or(0.0, |s| s.0);
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            sim.clock.time = sim.clock.end_time;
            return Ok(());
        };
        if dt.is_nan() || dt <= 0.0 {
            return Err(StepError::Internal(format!(
                "the pressure solve chose no step (dt = {dt})"
            )));
        }
        sim.clock.advance(dt, &sim.world);
        self.walls.read(&sim.world);
        let _span = tracing::info_span!("advance").entered();
        let (reflect, reach) = (self.params.reflect_at_walls, sim.constants.support());
        let (lo, hi) = sim.constants.domain;
        let walls = &self.walls;
        let mut x = column_mut::<Position>(fluid)?;
        let mut v = column_mut::<Velocity>(fluid)?;
        let (reflected, bad) = (&mut x[..], &mut v[..])
            .into_par_iter()
            .enumerate()
            .map(|(i, (x, v))| {
                x.0 += dt * v.0;
                let hit = reflect && walls.reflect(reach, &mut x.0, [&mut v.0]);
                let p = x.0;
                let ok = p.is_finite()
                    && p.cmpge(lo).all()
                    && p.cmple(hi).all()
                    && walls.crossed(p, reach).is_none();
                (hit as usize, (!ok).then_some(i))
            })
            .reduce(
                || (0, None),
                |(h1, b1), (h2, b2)| (h1 + h2, b1.into_iter().chain(b2).min()),
            );
        WallReflections::add(&mut sim.diagnostics, reflected as u64);
        let Some(i) = bad else {
            return Ok(());
        };
        let p = x[i].0;
        let what = if !p.is_finite() {
            "non-finite position".to_string()
        } else if let Some(w) = walls.crossed(p, reach) {
            format!("particle passed through {}", walls.describe(&sim.world, w))
        } else {
            "particle left the domain".to_string()
        };
        Err(StepError::Unstable {
            what,
            particle: Some(i as u32),
            position: Some(p),
        })
    }

    /// Advances the positions and the clock (and with it the scene).
    fn access(&self) -> Access {
        Access::new()
            .reads::<StepSize>()
            .reads::<Position>()
            .reads::<WallPose>()
            .updates::<Velocity>()
            .writes::<Clock>()
            .writes::<WallPose>()
            .writes::<BodyPose>()
            .writes::<Position>()
            .writes::<WallReflections>()
    }
}
