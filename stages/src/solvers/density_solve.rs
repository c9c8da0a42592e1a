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
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{
    Acceleration, Density, Fluid, Ghost, Mass, Position, Pressure, Velocity,
};
use sph_core::contract::Access;
use sph_core::dim::Vector;
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
        let acc: &[Vector] = &self.jacobi.acc;
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
        // Land exactly on the end time.
        Ok(dt.min(sim.clock.end_time - sim.clock.time))
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

#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use crate::pressure_solve::limits;
    use glam::DVec2;
    use sph_core::extremes::nan_max;
    use sph_core::kernel::Kernel;

    fn solve_with(p: Params) -> DensitySolve {
        DensitySolve {
            limits: limits(
                p.tolerance,
                p.min_iterations,
                p.max_iterations,
                p.relaxation,
                p.warm_start,
            )
            .unwrap(),
            params: p,
            first_dt: None,
            jacobi: Jacobi::default(),
            report: Report::default(),
        }
    }

    /// A fluid particle at rest at the origin and one at `v`.
    fn velocities(v: DVec2) -> [Velocity; 2] {
        [Velocity(DVec2::ZERO), Velocity(v)]
    }

    /// dt = C ds / max|v|, at most `max_dt`; the first step at most 0.25 sqrt(h / a_0),
    /// each later one at most `growth` times the step before; the last shortened to
    /// land on the end time. The test sim: ds 0.01 m, h 0.013 m.
    #[test]
    fn the_step_is_the_cfl_step_ramped_capped_and_landing() {
        let mut sim = crate::testing::sim(hecs::World::new());
        sim.clock.end_time = 10.0;
        let step = |sim: &Sim, v: f64, start: f64| {
            let mut solve = solve_with(Params::default());
            let vs = velocities(DVec2::new(0.6 * v, -0.8 * v));
            solve.step_size(sim, v, start, &vs).unwrap()
        };
        let rel = |a: f64, b: f64| ((a - b) / b).abs() < 1e-14;
        // CFL: 0.4 x 0.01 / 2 = 2 ms.
        assert!(rel(step(&sim, 2.0, 0.0), 0.4 * 0.01 / 2.0));
        // At rest: the largest step.
        assert_eq!(step(&sim, 0.0, 0.0), 5e-3);
        // The first step from a start accelerating at 100 m/s^2: 0.25 sqrt(h / a_0).
        assert!(rel(
            step(&sim, 0.0, 100.0),
            0.25 * (0.013f64 / 100.0).sqrt()
        ));
        assert!(rel(step(&sim, 2.0, 100.0), 0.002));
        // After a step of 1 ms: at most 1.2 ms, the start no longer counts.
        sim.clock.dt = 1e-3;
        assert!(rel(step(&sim, 0.0, 1e6), 1.2e-3));
        assert!(rel(step(&sim, 2.0, 0.0), 1.2e-3));
        assert!(rel(step(&sim, 4.0, 0.0), 1e-3));
        // 0.7 of a step left: taken whole; 1.2 steps: a full step first.
        sim.clock.time = 10.0 - 0.7e-3;
        assert_eq!(step(&sim, 4.0, 0.0), sim.clock.end_time - sim.clock.time);
        sim.clock.time = 10.0 - 1.2e-3;
        assert!(rel(step(&sim, 4.0, 0.0), 1e-3));
        sim.clock.time = 10.0 - 2e-3;
        assert!(rel(step(&sim, 4.0, 0.0), 1e-3));
    }

    /// A step below `collapse_fraction` of the first stops the run naming the fastest
    /// particle; so does a non-finite velocity, naming its particle.
    #[test]
    fn a_collapsed_step_or_a_non_finite_velocity_stops_the_run() {
        let mut world = hecs::World::new();
        for x in [0.1, 0.2] {
            world.spawn((Fluid, Position(DVec2::new(x, 0.5))));
        }
        let mut sim = crate::testing::sim(world);
        sim.clock.end_time = 10.0;
        let mut solve = solve_with(Params {
            collapse_fraction: 0.01,
            ..Params::default()
        });
        let vs = velocities(DVec2::new(0.0, 1.0));
        assert!((solve.step_size(&sim, 1.0, 0.0, &vs).unwrap() - 4e-3).abs() < 1e-15);
        // 0.4 x 0.01 / 100 = 4e-5 s: 1 % of the first step, allowed.
        let fast = velocities(DVec2::new(0.0, 100.0));
        solve.step_size(&sim, 100.0, 0.0, &fast).unwrap();
        let faster = velocities(DVec2::new(0.0, 101.0));
        match solve.step_size(&sim, 101.0, 0.0, &faster) {
            Err(StepError::Unstable {
                what,
                particle,
                position,
            }) => {
                assert!(what.starts_with("time step collapsed"), "{what}");
                assert!(what.contains("first step 4.000e-3 s"), "{what}");
                assert_eq!(particle, Some(1));
                assert_eq!(position, Some(DVec2::new(0.2, 0.5)));
            }
            other => panic!("{other:?}"),
        }
        let bad = [Velocity(DVec2::new(f64::NAN, 0.0)), Velocity(DVec2::ZERO)];
        match solve.step_size(&sim, 0.0, 0.0, &bad) {
            Err(StepError::Unstable { what, particle, .. }) => {
                assert_eq!((what.as_str(), particle), ("non-finite velocity", Some(0)));
            }
            other => panic!("{other:?}"),
        }
        // The first step is the state a resumed run keeps.
        let saved = solve.save_state(&sim).unwrap();
        let mut resumed = solve_with(Params {
            collapse_fraction: 0.01,
            ..Params::default()
        });
        resumed.load_state(&mut sim, &saved).unwrap();
        assert!(resumed.step_size(&sim, 101.0, 0.0, &faster).is_err());
    }

    /// The density solve publishes the step and leaves the pressures.
    #[test]
    fn the_solve_declares_the_step_and_the_pressures() {
        use sph_core::contract::Quantity;
        let writes = crate::testing::stage("density_solve", "()").access().writes;
        assert!(writes.contains(&Quantity::of::<StepSize>()));
        assert!(writes.contains(&Quantity::of::<Pressure>()));
    }

    /// The parameters' ranges, each end.
    #[test]
    fn parameters_out_of_range_are_refused() {
        let refused = |params: &str, field: &str| {
            let e = crate::testing::built("density_solve", params).err();
            let e = e.unwrap_or_else(|| panic!("{params} was accepted"));
            assert!(e.contains(field), "{params}: {e}");
        };
        for bad in ["0.0", "2.01", "NaN"] {
            refused(&format!("(courant: {bad})"), "courant");
        }
        crate::testing::stage("density_solve", "(courant: 2.0)");
        for bad in ["0.0", "inf", "NaN"] {
            refused(&format!("(max_dt: {bad})"), "max_dt");
        }
        for bad in ["0.99", "NaN"] {
            refused(&format!("(growth: {bad})"), "growth");
        }
        crate::testing::stage("density_solve", "(growth: 1.0)");
        for bad in ["0.0", "1.0", "NaN"] {
            refused(&format!("(collapse_fraction: {bad})"), "collapse_fraction");
        }
        refused("(relaxation: 0.0)", "relaxation");
    }

    /// The largest |a_np + a_p| of the fluid before the first step, by brute force
    /// over every particle within the support: a_np the `Acceleration` column,
    /// a_p,i = - sum_j m_j (p_i/rho_i^2 + p_j/rho_j^2) grad W_ij with the pressures the
    /// column holds, a ghost's its source's plus its carry (at least 0).
    fn start_by_hand(sim: &Sim) -> f64 {
        let carries = &sim.resources.get::<DfsphFactors>().unwrap().ghost_offset;
        let sources = crate::testing::ghost_sources(sim);
        let mut all = crate::testing::everyone(sim);
        let n = all.len() - sources.len();
        for (k, &s) in sources.iter().enumerate() {
            all[n + k].4 = (all[s].4 + carries[k]).max(0.0);
        }
        let f = archetype::<Fluid>(&sim.world).unwrap();
        let a_np = column::<Acceleration>(f).unwrap();
        let kernel = sph_core::kernel::Wendland::new(0.013);
        (0..n)
            .map(|i| {
                let (xi, _, _, rhoi, pi) = all[i];
                let mut a = a_np[i].0;
                for (j, &(xj, _, mj, rhoj, pj)) in all.iter().enumerate() {
                    let d = xi - xj;
                    if j != i && d.length() < 0.026 {
                        a -= mj
                            * (pi / (rhoi * rhoi) + pj / (rhoj * rhoj))
                            * kernel.grad(d, d.length());
                    }
                }
                a.length()
            })
            .fold(0.0, nan_max)
    }

    /// One DFSPH step's density solve on a block of water falling in a box corner:
    /// the step published is the first step's rule; each fluid particle's new velocity
    /// is its old one plus dt times the completed acceleration (gravity and the
    /// pressure's); the ghosts' velocities (and no-slip velocities) move by the mirror
    /// of their sources' change; the densities are the predicted ones; the row of density_solve.csv and the
    /// counters record the solve.
    #[test]
    fn a_step_completes_the_acceleration_and_reports() {
        let mut world = hecs::World::new();
        crate::testing::closed_box(&mut world, 0.2, 0.2);
        for (_, b, x) in crate::testing::lattice(6, 5) {
            world.spawn((
                Fluid,
                Position(x),
                Velocity(DVec2::new(0.05 * b as f64, -0.1)),
                Density(1000.0),
                Pressure(0.0),
                Mass(0.1),
                // Gravity and a sideways push of 50 m/s^2 (a tank accelerating).
                Acceleration(DVec2::new(50.0, -9.81)),
            ));
        }
        let mut sim = crate::testing::sim(world);
        sim.clock.end_time = 1.0;
        sim.out_dir = crate::testing::out_dir("density_solve");
        let mut stages = crate::testing::pipeline(
            &mut sim,
            &[
                ("ghost_walls", "(slip: NoSlip)"),
                ("neighbour_grid", "()"),
                ("dfsph_factor", "()"),
                ("density_solve", "(max_iterations: 50)"),
            ],
        );
        for stage in &mut stages[..3] {
            stage.run(&mut sim).unwrap();
        }
        let fluid_v = |sim: &Sim| -> Vec<DVec2> {
            let f = archetype::<Fluid>(&sim.world).unwrap();
            column::<Velocity>(f).unwrap().iter().map(|v| v.0).collect()
        };
        let ghost_v = |sim: &Sim| -> Vec<DVec2> {
            let g = archetype::<Ghost>(&sim.world).unwrap();
            column::<Velocity>(g).unwrap().iter().map(|v| v.0).collect()
        };
        let no_slip = |sim: &Sim| -> Vec<DVec2> {
            let columns = sim.resources.get::<sph_core::pair::Columns>().unwrap();
            columns.get::<NoSlipVelocity>().unwrap().to_vec()
        };
        let (v0, g0, ns0) = (fluid_v(&sim), ghost_v(&sim), no_slip(&sim));
        let rho0: Vec<f64> = crate::testing::everyone(&sim).iter().map(|p| p.3).collect();
        let a0 = start_by_hand(&sim);
        stages[3].run(&mut sim).unwrap();
        let dt = sim.resources.get::<StepSize>().unwrap().0;
        // The first step's rule, 0.25 sqrt(h / a_0) with a_0 about 50 m/s^2 (the push
        // and the pressures' gradient): about 4 ms, below max_dt (5 ms) and the CFL
        // step (0.4 ds / 0.22 m/s = 18 ms).
        let first = 0.25 * (0.013 / a0).sqrt();
        assert!(
            (dt - first).abs() < 1e-9 * first,
            "{dt} against {first}, a_0 {a0}"
        );
        assert!(dt < 4.5e-3 && dt > 2e-3, "{dt}");
        let (v1, g1) = (fluid_v(&sim), ghost_v(&sim));
        let f = archetype::<Fluid>(&sim.world).unwrap();
        let a: Vec<DVec2> = column::<Acceleration>(f)
            .unwrap()
            .iter()
            .map(|a| a.0)
            .collect();
        let mut pressed = 0;
        for i in 0..v0.len() {
            let e = v0[i] + dt * a[i];
            assert!(
                (v1[i] - e).length() < 1e-12,
                "particle {i}: {} against {e}",
                v1[i]
            );
            pressed += ((a[i] - DVec2::new(50.0, -9.81)).length() > 1e-6) as usize;
        }
        assert!(pressed > 10, "{pressed}");
        // With the continuity floor (DfsphFactor's default) the density column is left
        // at the predicted rho + dt D rho/Dt, the rate summed here by brute force
        // over every particle within the support at the final velocities.
        let all = crate::testing::everyone(&sim);
        for i in 0..v0.len() {
            let e = rho0[i] + dt * crate::testing::continuity_by_hand(&all, i);
            assert!(
                (all[i].3 - e).abs() < 1e-9,
                "rho {i}: {} against {e}",
                all[i].3
            );
        }
        {
            let mirror = sim.resources.get::<GhostReflections>().unwrap();
            let g = archetype::<Ghost>(&sim.world).unwrap();
            let sources = column::<Ghost>(g).unwrap();
            for k in 0..g0.len() {
                let s = sources[k].source as usize;
                let e = g0[k] + mirror.apply(k, v1[s] - v0[s]);
                assert!(
                    (g1[k] - e).length() < 1e-12,
                    "ghost {k}: {} against {e}",
                    g1[k]
                );
                // The no-slip velocity 2 v_w - v (or +v across a corner) follows
                // its source's change with its sign.
                let sign = sim.resources.get::<crate::vocab::NoSlipSigns>().unwrap().0[k];
                let e = ns0[k] + sign * (v1[s] - v0[s]);
                let ns = no_slip(&sim)[k];
                assert!((ns - e).length() < 1e-12, "no-slip {k}: {ns} against {e}");
            }
        }
        stages[3].finish(&mut sim).unwrap();
        let text = std::fs::read_to_string(sim.out_dir.join("density_solve.csv")).unwrap();
        let rows: Vec<&str> = text.lines().collect();
        assert_eq!(rows[0], "time,iterations,error,dt");
        let row: Vec<f64> = rows[1].split(',').map(|v| v.parse().unwrap()).collect();
        assert_eq!(row[3], dt);
        assert!(row[1] >= 1.0 && row[2] <= 1e-3, "{row:?}");
        assert_eq!(sim.diagnostics["density_solve_steps"], 1.0);
        assert_eq!(sim.diagnostics["density_solve_iterations"], row[1]);
        assert_eq!(sim.diagnostics["density_solve_unconverged"], 0.0);
        std::fs::remove_dir_all(&sim.out_dir).unwrap();
    }
}
