//! The divergence-free solve of DFSPH (docs/physics.md, "DFSPH"; Bender & Koschier 2017,
//! Algorithm 2, eqs. 9-11): at the start of a step, after the particles have moved and
//! `DfsphFactor` has computed their densities and factors at the new positions, the
//! velocities are corrected so that D rho/Dt = sum_j m_j v_ij . grad_i W_ij vanishes
//! (no compression where the pressure acts): a Jacobi iteration on a pressure of its
//! own (`pressure_solve`), which leaves the density solve's pressure in the `Pressure`
//! column untouched. The error is the mean max(D rho/Dt, 0) dt / rho_0 over the fluid,
//! dt the step just taken (the paper's convention); the first step (no step taken yet)
//! keeps the initial velocities.

use crate::pressure_solve::{cap_relaxation, limits, Jacobi, Limits, Report, Target};
use crate::vocab::{DfsphFactors, GhostReflections, NoSlipVelocity};
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Ghost, Mass, Position, Pressure, Velocity};
use sph_core::contract::Access;
use sph_core::sim::{Clock, Sim};
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{require_neighbours, Neighbours};
use sph_core::world::{archetype, column_mut};
use sph_core::StageRegistry;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Mean divergence error at which the solve stops, |D rho/Dt| dt / rho_0 averaged
    /// over the fluid. Default 0.001 (0.1 %).
    pub tolerance: f64,
    /// Least number of iterations. Default 0: a velocity field already within the
    /// tolerance is left as it is (one continuity pass to check; the paper makes one
    /// update regardless; on the dam break one step in 827 needed one).
    pub min_iterations: u32,
    /// Iteration cap; a step that reaches it above the tolerance is counted in
    /// `divergence_solve_unconverged`. Default 100.
    pub max_iterations: u32,
    /// Jacobi relaxation omega, 0 < omega <= 1. Default 0.5. Capped at setup at 85 % of
    /// the iteration's stability bound for the run's kernel and h/ds (0.60 for the
    /// Wendland kernel at h/ds 1.5, 0.35 at 2.0: docs/physics.md, "The relaxation's
    /// stability bound"); the value used is `<stage>_relaxation` in summary.json.
    pub relaxation: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            tolerance: 1e-3,
            min_iterations: 0,
            max_iterations: 100,
            relaxation: 0.5,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "divergence_solve",
        "DFSPH: makes the velocity field divergence-free (Jacobi iteration)",
        |p: Params| {
            Ok(DivergenceSolve {
                limits: limits(
                    p.tolerance,
                    p.min_iterations,
                    p.max_iterations,
                    p.relaxation,
                    0.0,
                )?,
                jacobi: Jacobi::default(),
                kept: Vec::new(),
                report: Report::default(),
            })
        },
    );
}

const NAME: &str = "divergence_solve";

pub struct DivergenceSolve {
    limits: Limits,
    jacobi: Jacobi,
    /// The density solve's pressures, set aside while this solve uses the column.
    kept: Vec<Pressure>,
    report: Report,
}

impl Stage for DivergenceSolve {
    fn name(&self) -> &'static str {
        NAME
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, NAME)?;
        // The ghosts' velocity mirrors, filled in by GhostWalls.
        sim.resources.insert(GhostReflections::default());
        cap_relaxation(sim, NAME, &mut self.limits);
        self.report.open(sim, NAME, &[])
    }

    fn save_state(&mut self, _sim: &Sim) -> Result<Vec<u8>, StepError> {
        self.report.flush()?;
        Ok(Vec::new())
    }

    fn finish(&mut self, _sim: &mut Sim) -> Result<(), StepError> {
        self.report.flush()
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let dt = sim.clock.dt;
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        if sim.clock.step == 0 || dt <= 0.0 {
            return Ok(());
        }
        // The column holds this solve's pressure (from zero: no warm start) while it
        // runs.
        self.kept.clear();
        self.kept.extend_from_slice(&column_mut::<Pressure>(fluid)?);
        // The carries are hydrostatic pressure, not part of this solve's pressure.
        let solved =
            self.jacobi
                .solve_with_factors(sim, dt, Target::Divergence, self.limits, false);
        if let Some(fluid) = archetype::<Fluid>(&sim.world) {
            column_mut::<Pressure>(fluid)?.copy_from_slice(&self.kept);
        }
        let outcome = solved?;
        let time = sim.clock.time;
        self.report.record(sim, NAME, time, outcome, &[])
    }

    fn access(&self) -> Access {
        Access::new()
            .reads::<Neighbours>()
            .reads::<DfsphFactors>()
            .reads::<GhostReflections>()
            .uses::<NoSlipVelocity>()
            .reads::<Position>()
            .reads::<Mass>()
            .reads::<Density>()
            .reads::<Clock>()
            .updates::<Velocity>()
            .uses::<Ghost>()
            .uses::<Pressure>()
    }
}

#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use glam::DVec2;
    use sph_core::extremes::nan_max;
    use sph_core::world::column;

    /// A block of water in a box corner whose velocities converge on a point inside
    /// it, after `GhostWalls`, `NeighbourGrid` and `DfsphFactor`, with the divergence
    /// solve set up in a fresh output folder; the step just taken 2 ms.
    fn converging(name: &str) -> (Sim, Vec<Box<dyn Stage>>) {
        let mut world = hecs::World::new();
        crate::testing::closed_box(&mut world, 0.2, 0.2);
        for (a, _, x) in crate::testing::lattice(6, 5) {
            world.spawn((
                Fluid,
                Position(x),
                Velocity(2.0 * (DVec2::new(0.03, 0.02) - x)),
                Density(1000.0),
                Pressure(100.0 + a as f64),
                Mass(0.1),
            ));
        }
        let mut sim = crate::testing::sim(world);
        sim.out_dir = crate::testing::out_dir(&format!("divergence_{name}"));
        let mut stages = crate::testing::pipeline(
            &mut sim,
            &[
                ("ghost_walls", "()"),
                ("neighbour_grid", "()"),
                ("dfsph_factor", "(continuity_floor: false)"),
                ("divergence_solve", "()"),
            ],
        );
        for stage in &mut stages[..3] {
            stage.run(&mut sim).unwrap();
        }
        (sim.clock.step, sim.clock.dt) = (1, 2e-3);
        (sim, stages)
    }

    /// The mean of max(dt D rho_i/Dt, 0) / rho_0 over the fluid, by brute force over
    /// every particle within the support.
    fn divergence_error(sim: &Sim, dt: f64) -> f64 {
        let all = crate::testing::everyone(sim);
        let n = archetype::<Fluid>(&sim.world).unwrap().len() as usize;
        let compression = |i| nan_max(dt * crate::testing::continuity_by_hand(&all, i), 0.0);
        (0..n).map(compression).sum::<f64>() / (n as f64 * 1000.0)
    }

    /// The solve brings a converging flow within its tolerance (checked by brute
    /// force), leaves the density solve's pressures in the column as they were, and
    /// records its iterations (flushed at a checkpoint); on the first step (no step
    /// taken yet) it does nothing.
    #[test]
    fn the_solve_removes_the_divergence_and_keeps_the_pressures() {
        let (mut sim, mut stages) = converging("solve");
        let pressures = |sim: &Sim| -> Vec<f64> {
            let f = archetype::<Fluid>(&sim.world).unwrap();
            column::<Pressure>(f).unwrap().iter().map(|p| p.0).collect()
        };
        let before = pressures(&sim);
        // div v = -4 /s: D rho/Dt = 4,000 kg/m^3/s inside, 0.8 % of rho_0 over the
        // step (measured 0.41 % on the mean: the sums by the free surface are short).
        let start = divergence_error(&sim, 2e-3);
        assert!(start > 3e-3, "{start}");
        stages[3].run(&mut sim).unwrap();
        let after = divergence_error(&sim, 2e-3);
        assert!(after <= 1e-3, "{after}");
        assert_eq!(pressures(&sim), before);
        let iterations = sim.diagnostics["divergence_solve_iterations"];
        assert!(iterations >= 1.0);
        assert_eq!(sim.diagnostics["divergence_solve_steps"], 1.0);
        // A checkpoint holds no state of its own, but flushes the solve's rows.
        assert!(stages[3].save_state(&sim).unwrap().is_empty());
        let text = std::fs::read_to_string(sim.out_dir.join("divergence_solve.csv")).unwrap();
        let row: Vec<f64> = text
            .lines()
            .nth(1)
            .unwrap()
            .split(',')
            .map(|v| v.parse().unwrap())
            .collect();
        assert_eq!(row[1], iterations);
        assert!((row[2] - after).abs() < 1e-9, "{row:?} against {after}");
        std::fs::remove_dir_all(&sim.out_dir).unwrap();

        let (mut sim, mut stages) = converging("first");
        sim.clock.step = 0;
        let v = |sim: &Sim| -> Vec<DVec2> {
            let f = archetype::<Fluid>(&sim.world).unwrap();
            column::<Velocity>(f).unwrap().iter().map(|v| v.0).collect()
        };
        let start = v(&sim);
        stages[3].run(&mut sim).unwrap();
        assert_eq!(v(&sim), start);
        assert!(!sim.diagnostics.contains_key("divergence_solve_steps"));
        std::fs::remove_dir_all(&sim.out_dir).unwrap();
    }

    /// The solve corrects the velocities with the factors the factor stage wrote.
    #[test]
    fn the_solve_declares_what_it_reads_and_corrects() {
        use sph_core::contract::Quantity;
        let access = crate::testing::stage("divergence_solve", "()").access();
        assert!(access.reads.contains(&Quantity::of::<DfsphFactors>()));
        assert!(access.updates.contains(&Quantity::of::<Velocity>()));
    }
}
