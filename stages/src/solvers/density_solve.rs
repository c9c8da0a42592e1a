//! The constant-density solve of DFSPH (docs/physics.md, "DFSPH"; Bender & Koschier
//! 2017, Algorithm 3, eqs. 11-12), with the step size:
//! 1. dt from the velocity CFL condition dt = C ds / max|v| (their eq. 13, with the
//!    particle spacing as the particle size), at most `max_dt`, the last step shortened
//!    to land on the end time; published as `vocab::StepSize` for `Advance`;
//! 2. the velocities predicted with the non-pressure accelerations `Forces` wrote
//!    (gravity, viscosity): v* = v + dt a (ghosts by their mirror);
//! 3. a projected Jacobi iteration (`pressure_solve`) for pressures p >= 0 that bring
//!    the predicted densities rho*_i = rho_i + dt D rho_i/Dt to rho_0 where p_i > 0 and
//!    to at most rho_0 where p_i = 0, warm-started
//!    from half the previous step's pressures (the `Pressure` column, which is
//!    checkpointed and sorted with the particles);
//! 4. `Acceleration` completed with the pressure acceleration, so the probes' roll
//!    moment (M = sum m (x - P) x (g - a)) sees the whole force, and the `Pressure`
//!    column left with the solve's pressures for the wall-pressure extraction.
//!
//! The error is the mean compression over the fluid, max(rho*_i - rho_0, 0) / rho_0.

use crate::pressure_solve::{cap_relaxation, limits, Jacobi, Limits, Report, Target};
use crate::vocab::{DfsphFactors, GhostReflections, NoSlipVelocity, StepSize};
use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{
    Acceleration, Density, Fluid, Ghost, Mass, Position, Pressure, Velocity,
};
use sph_core::contract::Access;
use sph_core::sim::{Clock, Sim};
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{require_neighbours, Neighbours};
use sph_core::world::{archetype, column, column_mut};
use sph_core::StageRegistry;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Mean density error at which the solve stops, relative to rho_0. Default 0.001
    /// (0.1 %).
    pub tolerance: f64,
    /// Least number of iterations. Default 1 (Bender & Koschier's Algorithm 3 makes
    /// two; with two, 45 % of the dam break's steps made no more than those).
    pub min_iterations: u32,
    /// Iteration cap; a step that reaches it above the tolerance is counted in
    /// `density_solve_unconverged`. Default 100.
    pub max_iterations: u32,
    /// Jacobi relaxation omega, 0 < omega <= 1. Default 0.5. Capped at setup at 85 % of
    /// the iteration's stability bound for the run's kernel and h/ds (0.60 for the
    /// Wendland kernel at h/ds 1.5, 0.35 at 2.0: docs/physics.md, "The relaxation's
    /// stability bound"); the value used is `<stage>_relaxation` in summary.json.
    pub relaxation: f64,
    /// The fraction of the previous step's pressures the solve starts from (Bender &
    /// Koschier's warm start; the projected update lowers what the step does not need;
    /// a full warm start makes still water bounce, see `pressure_solve`). Default 0.5.
    pub warm_start: f64,
    /// CFL number C of dt = C ds / max|v|. Default 0.4 (Bender & Koschier's).
    pub courant: f64,
    /// Largest step [s] (still water). Default 0.005.
    pub max_dt: f64,
    /// The start-up ramp: the most a step may grow over the step before. The first
    /// step is at most 0.25 sqrt(h / a_0), a_0 the largest acceleration of the
    /// starting state (the non-pressure forces and the initial pressures' gradient):
    /// at the foot of a dam's free face about g H / ds, in still water about 0. Without
    /// it the first step at rest is `max_dt`, and the corner's acceleration, which
    /// grows as 1/ds, kicks the front for a whole step: a front lead that grows with
    /// resolution (docs/validation.md, "The first steps of a DFSPH dam break").
    /// Default 1.2; at least 1.
    pub growth: f64,
    /// The run stops as unstable when dt falls below this fraction of the first step.
    /// Default 1e-3.
    pub collapse_fraction: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            tolerance: 1e-3,
            min_iterations: 1,
            max_iterations: 100,
            relaxation: 0.5,
            warm_start: 0.5,
            courant: 0.4,
            max_dt: 5e-3,
            growth: 1.2,
            collapse_fraction: 1e-3,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "density_solve",
        "DFSPH: step size by CFL, pressure solve to rest density (Jacobi iteration)",
        |p: Params| {
            let out = sph_core::ParamError::new;
            let limits = limits(
                p.tolerance,
                p.min_iterations,
                p.max_iterations,
                p.relaxation,
                p.warm_start,
            )?;
            if !(p.courant > 0.0 && p.courant <= 2.0) {
                return Err(out("courant", p.courant, "0 < C <= 2 (0.4 usual)"));
            }
            if !(p.max_dt > 0.0 && p.max_dt.is_finite()) {
                return Err(out("max_dt", p.max_dt, "a number of seconds > 0"));
            }
            if p.growth.is_nan() || p.growth < 1.0 {
                return Err(out(
                    "growth",
                    p.growth,
                    "a factor of at least 1 (1.2 usual)",
                ));
            }
            if !(p.collapse_fraction > 0.0 && p.collapse_fraction < 1.0) {
                return Err(out("collapse_fraction", p.collapse_fraction, "0 to 1"));
            }
            Ok(DensitySolve {
                params: p,
                limits,
                first_dt: None,
                jacobi: Jacobi::default(),
                report: Report::default(),
            })
        },
    );
}

const NAME: &str = "density_solve";

pub struct DensitySolve {
    params: Params,
    limits: Limits,
    /// The first step (the collapse reference).
    first_dt: Option<f64>,
    jacobi: Jacobi,
    report: Report,
}

impl Stage for DensitySolve {
    fn name(&self) -> &'static str {
        NAME
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, NAME)?;
        sim.resources.insert(GhostReflections::default());
        sim.resources.insert(StepSize(0.0));
        cap_relaxation(sim, NAME, &mut self.limits);
        self.report.open(sim, NAME, &["dt"])
    }

    fn save_state(&mut self, _sim: &Sim) -> Result<Vec<u8>, StepError> {
        self.report.flush()?;
        let mut e = Enc::default();
        e.opt_f64(self.first_dt);
        Ok(e.into_bytes())
    }

    fn load_state(&mut self, _sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        self.first_dt = d.opt_f64()?;
        d.end()
    }

    fn finish(&mut self, _sim: &mut Sim) -> Result<(), StepError> {
        self.report.flush()
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        // The start's acceleration, for the first step (`Params::growth`).
        let start = match sim.clock.dt > 0.0 {
            true => 0.0,
            false => self.start_acceleration(sim)?,
        };
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let dt = {
            let v = column::<Velocity>(fluid)?;
            let v: &[Velocity] = &v;
            let max_v2 = v
                .par_iter()
                .map(|v| v.0.length_squared())
                .reduce(|| 0.0, f64::max);
            self.step_size(sim, max_v2.sqrt(), start, v)?
        };
        // v* = v + dt a, the ghosts' by the mirror of their sources' change.
        {
            let a = column::<Acceleration>(fluid)?;
            let a: &[Acceleration] = &a;
            column_mut::<Velocity>(fluid)?
                .par_iter_mut()
                .zip(a.par_iter())
                .for_each(|(v, a)| v.0 += dt * a.0);
            if let (Some(ghost), Some(mirror)) = (
                archetype::<Ghost>(&sim.world),
                sim.resources.get::<GhostReflections>(),
            ) {
                let source = column::<Ghost>(ghost)?;
                let source: &[Ghost] = &source;
                if mirror.0.len() != source.len() {
                    return Err(StepError::Internal(format!(
                        "{} ghosts but {} velocity mirrors: GhostWalls must run before DensitySolve",
                        source.len(),
                        mirror.0.len()
                    )));
                }
                column_mut::<Velocity>(ghost)?
                    .par_iter_mut()
                    .enumerate()
                    .for_each(|(k, v)| v.0 += dt * mirror.apply(k, a[source[k].source as usize].0));
            }
        }
        {
            let a = column::<Acceleration>(fluid)?;
            let a: &[Acceleration] = &a;
            crate::pressure_solve::shift_no_slip(&sim.world, &mut sim.resources, |s| dt * a[s].0)?;
        }
        let solved = self
            .jacobi
            .solve_with_factors(sim, dt, Target::Density, self.limits, true);
        let outcome = solved?;
        let floor = sim
            .resources
            .get::<DfsphFactors>()
            .is_some_and(|f| f.continuity_floor);
        if floor {
            // The predicted density rho + dt D rho/Dt at the final velocities: the
            // continuity density the next step's DfsphFactor floors its sums with.
            if let Some(fluid) = archetype::<Fluid>(&sim.world) {
                column_mut::<Density>(fluid)?
                    .par_iter_mut()
                    .zip(self.jacobi.rate.par_iter())
                    .for_each(|(rho, rate)| rho.0 += dt * rate);
            }
        }
        let acc: &[DVec2] = &self.jacobi.acc;
        if let Some(fluid) = archetype::<Fluid>(&sim.world) {
            column_mut::<Acceleration>(fluid)?
                .par_iter_mut()
                .zip(acc.par_iter())
                .for_each(|(a, p)| a.0 += *p);
        }
        sim.resources.insert(StepSize(dt));
        let time = sim.clock.time;
        self.report.record(sim, NAME, time, outcome, &[dt])
    }

    fn access(&self) -> Access {
        Access::new()
            .reads::<Neighbours>()
            .reads::<DfsphFactors>()
            .reads::<GhostReflections>()
            .uses::<NoSlipVelocity>()
            .reads::<Position>()
            .reads::<Mass>()
            .updates::<Density>()
            .reads::<Clock>()
            .updates::<Acceleration>()
            .updates::<Velocity>()
            .uses::<Ghost>()
            .writes::<Pressure>()
            .writes::<StepSize>()
    }
}

impl DensitySolve {
    /// The largest |a_np + a_p| of the fluid at the step's start: the non-pressure
    /// acceleration `Forces` wrote and the gradient of the pressures the column holds
    /// (0 without fluid). A non-finite state is left to stop the run in the solve.
    fn start_acceleration(&mut self, sim: &mut Sim) -> Result<f64, StepError> {
        let a_p = self.jacobi.acceleration_now(sim)?;
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(0.0);
        };
        let a = column::<Acceleration>(fluid)?;
        Ok(a.par_iter()
            .zip(a_p.par_iter())
            .map(|(a, p)| (a.0 + *p).length())
            .reduce(|| 0.0, f64::max))
    }

    /// The CFL step for the largest speed `max_v`, capped, ramped up from the start
    /// (whose largest acceleration is `start`), landing on the end time; an error if
    /// it collapsed.
    fn step_size(
        &mut self,
        sim: &Sim,
        max_v: f64,
        start: f64,
        v: &[Velocity],
    ) -> Result<f64, StepError> {
        let p = &self.params;
        if let Some(i) = v.par_iter().position_first(|v| !v.0.is_finite()) {
            return Err(unstable("non-finite velocity", sim, i));
        }
        let mut dt = p.max_dt;
        if max_v > 0.0 {
            dt = dt.min(p.courant * sim.constants.spacing / max_v);
        }
        // The start-up ramp (`Params::growth`): the step last taken is the clock's, so
        // a resumed run ramps as the uninterrupted one did.
        let last = sim.clock.dt;
        dt = if last > 0.0 {
            dt.min(p.growth * last)
        } else if start > 0.0 {
            dt.min(0.25 * (sim.constants.h / start).sqrt())
        } else {
            dt
        };
        let first = *self.first_dt.get_or_insert(dt);
        if dt < p.collapse_fraction * first {
            let i = v.iter().position(|v| v.0.length() == max_v).unwrap_or(0);
            return Err(unstable(
                &format!("time step collapsed to {dt:.3e} s (first step {first:.3e} s)"),
                sim,
                i,
            ));
        }
        let remaining = sim.clock.end_time - sim.clock.time;
        if remaining < 1.5 * dt {
            dt = dt.min(remaining);
        }
        Ok(dt)
    }
}

fn unstable(what: &str, sim: &Sim, i: usize) -> StepError {
    let x = archetype::<Fluid>(&sim.world).and_then(|f| column::<Position>(f).ok().map(|x| x[i].0));
    StepError::Unstable {
        what: what.to_string(),
        particle: Some(i as u32),
        position: x,
    }
}
