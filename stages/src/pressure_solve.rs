//! The Jacobi iteration the two DFSPH solves share (docs/physics.md, "DFSPH"; Bender &
//! Koschier 2017, Algorithms 2 and 3), written with the pressure-gradient and
//! continuity terms of the pair layer. Not a stage: `DivergenceSolve` and `DensitySolve`
//! run it with their own target.
//!
//! Given velocities v0 (the state before the pressure acts) and a step dt, it seeks
//! pressures p >= 0 such that the velocities v = v0 + dt a_p(p), with
//!   a_p,i = - sum_j m_j (p_i/rho_i^2 + p_j/rho_j^2) grad_i W_ij     (the `PressureGradient` term),
//! leave no particle compressed, r_i <= 0:
//! - divergence target: r_i = dt D rho_i/Dt (eq. 9, the velocity field divergence-free),
//! - density target:    r_i = rho_i - rho_0 + dt D rho_i/Dt (eq. 12, the predicted density
//!   rho*_i at rest density),
//!
//! with D rho_i/Dt = sum_j m_j v_ij . grad_i W_ij (the `Continuity` term). Each iteration
//! raises every p_i by omega alpha_i max(r_i, 0) / dt^2 (eq. 11 in pressure form:
//! alpha_i r_i / dt^2 is the pressure that cancels r_i if the neighbours' pressures stay
//! fixed) and recomputes a_p and v. Pressures only grow within a solve, and only
//! compression counts (a free surface is not pulled back: its particles sum to less
//! than rho_0); the solve starts from a fraction of the previous step's pressures (the
//! warm start) so that it never starts above what the step needs: a full warm start
//! pushed still water up every other step, since an expansion the pressure overshot
//! into is left to gravity. The relaxation omega = 0.5 is that of implicit
//! incompressible SPH: with omega = 1 the iteration diverged on still water (the
//! short-wave modes, in which every neighbour's update adds to i's, are amplified).
//! The error is the mean over the fluid of max(r_i, 0) / rho_0: the solve stops once it
//! is within the tolerance (after the least number of iterations) or at the cap.
//!
//! Ghosts take part as their sources' mirror images: a ghost's pressure is its source's
//! plus the ghost's carry (`DfsphFactors::ghost_offset`, the hydrostatic pressure
//! difference across the wall, or 0), clamped at 0, and its velocity is its velocity
//! at the start of the solve plus the mirror (`GhostReflections`) of its source's
//! velocity change. Ghosts get no equation of their own.
//!
//! Deterministic for any thread count: every particle's sums are gathers over its own
//! neighbour list, and the error is summed in fixed chunks (`world::sum_fixed`).

use glam::DVec2;
use rayon::prelude::*;
use sph_core::components::{Density, Fluid, Ghost, Pressure, Velocity};
use sph_core::kernel::Kernel;
use sph_core::pair::{with_records, EquationsOfMotion, Fields, PairTerm, Pass, RateSums};
use sph_core::sim::Sim;
use sph_core::stage::StepError;
use sph_core::vocab::{DfsphFactors, GhostReflections, Neighbours};
use sph_core::with_kernel;
use sph_core::world::{archetype, column, column_mut, sum_fixed};

use crate::terms::{continuity::Continuity, pressure_gradient::PressureGradient, Term};

/// What a solve drives to zero (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Target {
    /// r_i = dt D rho_i/Dt.
    Divergence,
    /// r_i = rho_i - rho_0 + dt D rho_i/Dt.
    Density,
}

/// A solve's stopping rule.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Limits {
    /// Mean error relative to rho_0 at which the solve stops.
    pub tolerance: f64,
    pub min_iterations: u32,
    pub max_iterations: u32,
    /// The Jacobi relaxation omega: each update adds omega alpha_i r_i / dt^2.
    pub relaxation: f64,
    /// The fraction of the previous pressures the solve starts from.
    pub warm_start: f64,
}

/// How a solve ended.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Outcome {
    /// Pressure updates made.
    pub iterations: u32,
    /// The mean error after them (relative to rho_0).
    pub error: f64,
    /// The error was still above the tolerance at the cap.
    pub capped: bool,
}

/// The solve's buffers, kept between steps.
#[derive(Default)]
pub(crate) struct Jacobi {
    /// Fluid and ghost velocities before the pressure acts.
    base: Vec<DVec2>,
    ghost_base: Vec<DVec2>,
    /// D rho/Dt of each fluid particle.
    rate: Vec<f64>,
    /// The pressure acceleration of each fluid particle.
    pub acc: Vec<DVec2>,
}

impl Jacobi {
    /// [`Jacobi::solve`] with the step's `DfsphFactors`: the factors, and the ghosts'
    /// pressure carries if `carry` (else none).
    pub(crate) fn solve_with_factors(
        &mut self,
        sim: &mut Sim,
        dt: f64,
        target: Target,
        limits: Limits,
        carry: bool,
    ) -> Result<Outcome, StepError> {
        let factors = sim.resources.take::<DfsphFactors>().unwrap_or_default();
        let zeros = match carry {
            true => Vec::new(),
            false => vec![0.0; factors.ghost_offset.len()],
        };
        let offsets = if carry { &factors.ghost_offset } else { &zeros };
        let solved = self.solve(sim, dt, target, limits, &factors.alpha, offsets);
        sim.resources.insert(factors);
        solved
    }

    /// Solves for the pressures in the `Pressure` column, starting from the fluid's
    /// pressures there (a warm start; zeros for none), and leaves the corrected
    /// velocities in `Velocity` (fluid and ghosts) and the final pressure acceleration
    /// in `self.acc`. `alpha` and `offsets` are `DfsphFactors`' columns.
    pub(crate) fn solve(
        &mut self,
        sim: &mut Sim,
        dt: f64,
        target: Target,
        limits: Limits,
        alpha: &[f64],
        offsets: &[f64],
    ) -> Result<Outcome, StepError> {
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(Outcome::default());
        };
        let n = fluid.len() as usize;
        if alpha.len() != n {
            return Err(StepError::Internal(format!(
                "{} DFSPH factors for {n} fluid particles: put DfsphFactor() after NeighbourGrid and before the solves",
                alpha.len()
            )));
        }
        self.base.clear();
        self.base
            .extend(column::<Velocity>(fluid)?.iter().map(|v| v.0));
        self.ghost_base.clear();
        if let Some(ghost) = archetype::<Ghost>(&sim.world) {
            self.ghost_base
                .extend(column::<Velocity>(ghost)?.iter().map(|v| v.0));
        }
        let ghosts = self.ghost_base.len();
        let reflections = sim
            .resources
            .get::<GhostReflections>()
            .map_or(0, |r| r.0.len());
        if reflections != ghosts || offsets.len() != ghosts {
            return Err(StepError::Internal(format!(
                "{ghosts} ghosts but {reflections} velocity mirrors and {} pressure carries: GhostWalls must run before DfsphFactor and the solves",
                offsets.len()
            )));
        }
        self.rate.resize(n, 0.0);
        self.acc.clear();
        self.acc.resize(n, DVec2::ZERO);
        let rho0 = sim.constants.eos.rho0;
        let inv_dt2 = 1.0 / (dt * dt);
        let omega = limits.relaxation;
        // Warm start: a fraction of the pressures the column holds, where the velocities
        // before the pressure acts compress the particle (elsewhere none).
        let warm = limits.warm_start;
        if warm > 0.0 {
            self.divergence(sim)?;
        }
        if let Some(fluid) = archetype::<Fluid>(&sim.world) {
            let rho = column::<Density>(fluid)?;
            let rate = &self.rate;
            column_mut::<Pressure>(fluid)?
                .iter_mut()
                .enumerate()
                .for_each(|(i, p)| {
                    let compressed =
                        warm > 0.0 && residual(target, dt, rho0, rho[i].0, rate[i]) > 0.0;
                    p.0 = if compressed { warm * p.0 } else { 0.0 };
                });
        }
        sync_ghost_pressures(sim, offsets)?;
        if warm > 0.0 {
            self.pressure_acceleration(sim)?;
            self.set_velocities(sim, dt)?;
        }
        let mut iterations = 0;
        loop {
            self.divergence(sim)?;
            let Some(fluid) = archetype::<Fluid>(&sim.world) else {
                return Ok(Outcome::default());
            };
            let rho_col = column::<Density>(fluid)?;
            let mut p_col = column_mut::<Pressure>(fluid)?;
            let rho: &[Density] = &rho_col;
            let rate = &self.rate;
            let residual = |i: usize| residual(target, dt, rho0, rho[i].0, rate[i]);
            let error = sum_fixed(n, |i| residual(i).max(0.0)) / (n.max(1) as f64 * rho0);
            if !error.is_finite() {
                let i = (0..n).find(|&i| !residual(i).is_finite()).unwrap_or(0);
                let x = column::<sph_core::components::Position>(fluid)?[i].0;
                return Err(StepError::Unstable {
                    what: format!("the {target:?} solve diverged (non-finite density error)")
                        .to_lowercase(),
                    particle: Some(i as u32),
                    position: Some(x),
                });
            }
            let done = iterations >= limits.min_iterations && error <= limits.tolerance;
            if done || iterations >= limits.max_iterations {
                return Ok(Outcome {
                    iterations,
                    error,
                    capped: !done,
                });
            }
            p_col.par_iter_mut().enumerate().for_each(|(i, p)| {
                p.0 += omega * alpha[i] * residual(i).max(0.0) * inv_dt2;
            });
            drop((p_col, rho_col));
            sync_ghost_pressures(sim, offsets)?;
            self.pressure_acceleration(sim)?;
            self.set_velocities(sim, dt)?;
            iterations += 1;
        }
    }

    /// D rho/Dt of every fluid particle from the velocities in the columns.
    fn divergence(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let term = EquationsOfMotion(Continuity);
        let fields = <Continuity as Term>::READS;
        each(sim, &term, fields, &mut self.rate, |s: RateSums| s.drho)
    }

    /// The pressure acceleration of every fluid particle from the pressures in the
    /// columns.
    fn pressure_acceleration(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let term = EquationsOfMotion(PressureGradient);
        let fields = <PressureGradient as Term>::READS;
        each(sim, &term, fields, &mut self.acc, |s: RateSums| s.acc)
    }

    /// v = v0 + dt a_p for the fluid, and the mirror of the change for the ghosts.
    fn set_velocities(&self, sim: &Sim, dt: f64) -> Result<(), StepError> {
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let (base, acc) = (&self.base, &self.acc);
        column_mut::<Velocity>(fluid)?
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, v)| v.0 = base[i] + dt * acc[i]);
        let (Some(ghost), Some(mirror)) = (
            archetype::<Ghost>(&sim.world),
            sim.resources.get::<GhostReflections>(),
        ) else {
            return Ok(());
        };
        let source = column::<Ghost>(ghost)?;
        let source: &[Ghost] = &source;
        let gbase = &self.ghost_base;
        column_mut::<Velocity>(ghost)?
            .par_iter_mut()
            .enumerate()
            .for_each(|(k, v)| {
                let s = source[k].source as usize;
                v.0 = gbase[k] + dt * mirror.apply(k, acc[s]);
            });
        Ok(())
    }
}

/// Particle i's density error r_i (see the module docs) for density `rho` and
/// D rho/Dt `rate`.
#[inline]
fn residual(target: Target, dt: f64, rho0: f64, rho: f64, rate: f64) -> f64 {
    match target {
        Target::Divergence => dt * rate,
        Target::Density => rho - rho0 + dt * rate,
    }
}

/// Sets every ghost's pressure to its source's plus its carry, at least 0.
pub(crate) fn sync_ghost_pressures(sim: &Sim, offsets: &[f64]) -> Result<(), StepError> {
    let (Some(fluid), Some(ghost)) = (
        archetype::<Fluid>(&sim.world),
        archetype::<Ghost>(&sim.world),
    ) else {
        return Ok(());
    };
    let (fp, source) = (column::<Pressure>(fluid)?, column::<Ghost>(ghost)?);
    let (fp, source): (&[Pressure], &[Ghost]) = (&fp, &source);
    column_mut::<Pressure>(ghost)?
        .par_iter_mut()
        .enumerate()
        .for_each(|(k, p)| {
            let s = source[k].source as usize;
            p.0 = (fp[s].0 + offsets[k]).max(0.0);
        });
    Ok(())
}

/// Runs `term` over every fluid particle's neighbours (records packed with `fields`)
/// and stores `pick` of each particle's sum in `out`.
pub(crate) fn each<T: PairTerm, O: Send>(
    sim: &mut Sim,
    term: &T,
    fields: Fields,
    out: &mut [O],
    pick: impl Fn(T::Out) -> O + Sync,
) -> Result<(), StepError> {
    with_records(sim, fields, |sim, _, records| {
        let Some(nb) = sim.resources.get::<Neighbours>() else {
            return Err(StepError::Internal("no neighbour lists".into()));
        };
        if nb.n_fluid != out.len() {
            return Err(StepError::Internal(format!(
                "the neighbour lists cover {} fluid particles but the world holds {}",
                nb.n_fluid,
                out.len()
            )));
        }
        let c = &sim.constants;
        with_kernel!(c.kernel, c.h, |k| run(term, k, records, nb, out, &pick))
    })?;
    Ok(())
}

fn run<T: PairTerm, K: Kernel, O: Send>(
    term: &T,
    k: K,
    records: &sph_core::pair::Records,
    nb: &Neighbours,
    out: &mut [O],
    pick: &(impl Fn(T::Out) -> O + Sync),
) -> Result<(), StepError> {
    let pass = Pass::new(term, k, records).map_err(|e| StepError::Internal(e.to_string()))?;
    out.par_iter_mut()
        .enumerate()
        .for_each(|(i, o)| *o = pick(pass.sum(i, nb.of(i))));
    Ok(())
}

/// The parameters both solves take, checked.
pub(crate) fn limits(
    tolerance: f64,
    min_iterations: u32,
    max_iterations: u32,
    relaxation: f64,
    warm_start: f64,
) -> Result<Limits, sph_core::ParamError> {
    if !(0.0..=1.0).contains(&warm_start) {
        return Err(sph_core::ParamError::new(
            "warm_start",
            warm_start,
            "a fraction from 0 to 1 (0.5 usual)",
        ));
    }
    let out = sph_core::ParamError::new;
    if !(relaxation > 0.0 && relaxation <= 1.0) {
        return Err(out("relaxation", relaxation, "0 < omega <= 1 (0.5 usual)"));
    }
    if !(tolerance > 0.0 && tolerance < 1.0) {
        return Err(out(
            "tolerance",
            tolerance,
            "a fraction of rho_0 with 0 < tolerance < 1 (e.g. 0.001 for 0.1 %)",
        ));
    }
    if max_iterations == 0 || max_iterations > 10_000 {
        return Err(out(
            "max_iterations",
            max_iterations as f64,
            "a whole number from 1 to 10000",
        ));
    }
    if min_iterations > max_iterations {
        return Err(out(
            "min_iterations",
            min_iterations as f64,
            "a whole number no larger than max_iterations",
        ));
    }
    Ok(Limits {
        tolerance,
        min_iterations,
        max_iterations,
        relaxation,
        warm_start,
    })
}

/// Where a solve reports: a row per step in `<name>.csv` (iterations, final error and
/// the step's extra columns), and in summary.json's diagnostics `<name>_steps`,
/// `<name>_iterations` (totals) and `<name>_unconverged` (steps that ended at the cap
/// above the tolerance).
#[derive(Default)]
pub(crate) struct Report {
    out: Option<sph_core::series::SeriesWriter>,
}

impl Report {
    /// Opens (or, on a resumed run, continues) `<name>.csv` with the columns
    /// `iterations`, `error` and `extra`.
    pub(crate) fn open(
        &mut self,
        sim: &Sim,
        name: &'static str,
        extra: &[&str],
    ) -> Result<(), sph_core::stage::SetupError> {
        let columns = ["iterations", "error"]
            .iter()
            .chain(extra)
            .map(|c| c.to_string())
            .collect();
        let path = sim.out_dir.join(format!("{name}.csv"));
        let out = sph_core::series::SeriesWriter::open(sim, &path, columns)
            .map_err(|e| sph_core::stage::SetupError::new(name, e.to_string()))?;
        self.out = Some(out);
        Ok(())
    }

    /// Records one step's outcome at time `time`.
    pub(crate) fn record(
        &mut self,
        sim: &mut Sim,
        name: &str,
        time: f64,
        o: Outcome,
        extra: &[f64],
    ) -> Result<(), StepError> {
        let d = &mut sim.diagnostics;
        *d.entry(format!("{name}_steps")).or_insert(0.0) += 1.0;
        *d.entry(format!("{name}_iterations")).or_insert(0.0) += o.iterations as f64;
        *d.entry(format!("{name}_unconverged")).or_insert(0.0) += o.capped as u8 as f64;
        if let Some(out) = &mut self.out {
            let mut row = vec![o.iterations as f64, o.error];
            row.extend_from_slice(extra);
            out.push(time, row)?;
        }
        Ok(())
    }

    /// Flushes the file (checkpoints, the end of the run).
    pub(crate) fn flush(&mut self) -> Result<(), StepError> {
        match &mut self.out {
            Some(out) => out.flush(),
            None => Ok(()),
        }
    }
}
