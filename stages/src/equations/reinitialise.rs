//! Density re-initialisation (Colagrossi & Landrini 2003; docs/physics.md, "Density
//! re-initialisation"), by the Shepard filter
//!   rho_i = sum_j m_j W_ij / sum_j (m_j/rho_j) W_ij   (j over fluid, ghosts and i itself)
//! or the first-order MLS filter ([`crate::mls`]), which keeps a linear (hydrostatic)
//! density field and so does not lift a free surface when run often, or the density
//! summation with SPHinXsys's free-surface correction ([`FreeSurfaceDensity`]).
//! Run it every N steps with the stage's `every: N`; leave the stage out for "never".
//!
//! The free-surface summation can take its sums from the momentum pass of the step
//! (`sums: Forces`, the stage listed after `Forces`) instead of a pass of its own: the
//! step's pressures are then those of the density before the filter, and the filtered
//! density is what the integrator carries on. That moves the filter from before the
//! pressures to after them, by one step, for a pass less.

use crate::terms::{free_surface_density::FreeSurfaceDensity, mls::Mls, shepard::Shepard};
use crate::vocab::{refresh_ghost_density, GhostSettings, KernelSums};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Ghost, Mass, Position};
use sph_core::contract::Access;
use sph_core::kernel::Kernel;
use sph_core::pair::{with_records, PairTerm, Pass};
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{require_neighbours, HalfDensity, Neighbours};
use sph_core::world::{archetype, column, column_mut};
use sph_core::{with_kernel, StageRegistry};

/// The density filter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Filter {
    /// Zeroth order: sum m W / sum V W.
    #[default]
    Shepard,
    /// First-order moving least squares (exact for linear density fields).
    Mls,
    /// sum m W, with the share a free surface cuts from the kernel put back
    /// (SPHinXsys's free-surface density summation).
    FreeSurface,
}

/// Where the filter's kernel sums come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Sums {
    /// A pass of the stage's own over the neighbours, at the place it is listed.
    #[default]
    Own,
    /// The momentum pass of this step (`Forces`, listed before this stage), which sums
    /// m_j W_ij in the same loop (`vocab::KernelSums`). Only with `filter:
    /// FreeSurface`.
    Forces,
}

/// How often is the runner's `every: N` (default 1); the studied values are 1, 5, 20.
#[derive(Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Default Shepard (the paper's filter).
    pub filter: Filter,
    /// Default Own.
    pub sums: Sums,
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "reinitialise",
        "Shepard, MLS or free-surface summation density re-initialisation (use every: N)",
        |p: Params| {
            if p.sums == Sums::Forces && p.filter != Filter::FreeSurface {
                return Err(sph_core::ParamError::new(
                    "sums",
                    "Forces",
                    "Own with the Shepard and MLS filters; Forces only with filter: FreeSurface",
                ));
            }
            Ok(Reinitialise {
                filter: p.filter,
                sums: p.sums,
                inv_lattice_sum: f64::NAN,
            })
        },
    );
}

pub struct Reinitialise {
    filter: Filter,
    sums: Sums,
    /// 1 / (sigma_0 ds^2) for the free-surface summation, from the run's kernel.
    inv_lattice_sum: f64,
}

impl Stage for Reinitialise {
    fn name(&self) -> &'static str {
        "reinitialise"
    }

    /// It filters the density column in place and keeps nothing between calls.
    fn resumes_between_runs(&self) -> bool {
        true
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        let c = &sim.constants;
        self.inv_lattice_sum = 1.0 / sph_core::kernel::lattice_sum(c.kernel, c.h, c.spacing);
        if self.sums == Sums::Forces {
            sim.resources.insert(KernelSums::default());
        }
        require_neighbours(sim, "reinitialise")
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        if self.sums == Sums::Forces {
            return self.filter_with_kernel_sums(sim);
        }
        let _span = tracing::trace_span!("pair_sums").entered();
        let reads = Shepard { w0: 0.0 }.reads().with(Mls { w0: 0.0 }.reads());
        let (rho0, inv_lattice_sum) = (sim.constants.eos.rho0, self.inv_lattice_sum);
        // The sums read the densities packed before the pass, so each particle's new
        // density can go straight into its column (no second buffer).
        let filter = self.filter;
        let done = with_records(sim, reads, |sim, particles, records| {
            let Some(nb) = sim.resources.get::<Neighbours>() else {
                return Ok(false);
            };
            let c = &sim.constants;
            // Shift the leapfrog's half-step density by the same correction.
            let mut rho = particles.fluid_mut::<Density>()?;
            let mut half = particles.fluid.get::<&mut HalfDensity>();
            if rho.len() != nb.n_fluid {
                return Err(StepError::Internal(format!(
                    "the neighbour lists cover {} fluid particles but the world holds {}",
                    nb.n_fluid,
                    rho.len()
                )));
            }
            with_kernel!(c.kernel, c.h, |k| {
                let w0 = k.w(0.0);
                match filter {
                    Filter::Shepard => filter_all(
                        &Shepard { w0 },
                        k,
                        records,
                        nb,
                        &mut rho,
                        half.as_deref_mut(),
                    ),
                    Filter::Mls => {
                        filter_all(&Mls { w0 }, k, records, nb, &mut rho, half.as_deref_mut())
                    }
                    Filter::FreeSurface => filter_all(
                        &FreeSurfaceDensity {
                            w0,
                            rho0,
                            inv_lattice_sum,
                        },
                        k,
                        records,
                        nb,
                        &mut rho,
                        half.as_deref_mut(),
                    ),
                }
            })?;
            Ok(true)
        })?;
        if done != Some(true) {
            return Ok(());
        }
        refresh_ghost_density(sim)
    }

    fn access(&self) -> Access {
        Access::new()
            .reads_if::<KernelSums>(self.sums == Sums::Forces)
            .reads::<Neighbours>()
            .reads::<Position>()
            .reads::<Mass>()
            .updates::<Density>()
            .uses::<HalfDensity>()
            .uses::<Ghost>()
            .uses::<GhostSettings>()
    }
}

impl Reinitialise {
    /// The free-surface summation from the momentum pass's kernel sums.
    fn filter_with_kernel_sums(&self, sim: &mut Sim) -> Result<(), StepError> {
        let c = &sim.constants;
        let term = FreeSurfaceDensity {
            w0: with_kernel!(c.kernel, c.h, |k| k.w(0.0)),
            rho0: c.eos.rho0,
            inv_lattice_sum: self.inv_lattice_sum,
        };
        let Some(sums) = sim.resources.get::<KernelSums>() else {
            return Err(StepError::Internal(
                "Reinitialise(sums: Forces) found no kernel sums: Forces must run before it".into(),
            ));
        };
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(());
        };
        let (m, mut rho) = (column::<Mass>(fluid)?, column_mut::<Density>(fluid)?);
        let mut half = fluid.get::<&mut HalfDensity>();
        if sums.0.len() != rho.len() {
            return Err(StepError::Internal(format!(
                "the momentum pass summed {} fluid particles but the world holds {}: Forces must run before Reinitialise(sums: Forces) every step",
                sums.0.len(),
                rho.len()
            )));
        }
        let (m, sums) = (&m[..], &sums.0[..]);
        let filter = |(i, r): (usize, &mut Density)| {
            let f = term.density(m[i].0, r.0, sums[i]);
            std::mem::replace(&mut r.0, f)
        };
        match half.as_deref_mut() {
            Some(half) => {
                (&mut rho[..], half)
                    .into_par_iter()
                    .enumerate()
                    .for_each(|(i, (r, h))| {
                        let before = filter((i, r));
                        h.0 += r.0 - before;
                    })
            }
            None => rho.par_iter_mut().enumerate().for_each(|p| {
                filter(p);
            }),
        }
        drop((m, rho, half));
        refresh_ghost_density(sim)
    }
}

/// Writes every fluid particle's filtered density (the pair term `term`) into `rho`,
/// and shifts the half-step density `half`, if any, by the same correction.
fn filter_all<T: PairTerm<Out = f64>, K: Kernel>(
    term: &T,
    k: K,
    records: &sph_core::pair::Records,
    nb: &Neighbours,
    rho: &mut [Density],
    half: Option<&mut [HalfDensity]>,
) -> Result<(), StepError> {
    let pass = Pass::new(term, k, records).map_err(|e| StepError::Internal(e.to_string()))?;
    let filtered = |i: usize| pass.sum(i, nb.of(i));
    match half {
        Some(half) => (rho, half)
            .into_par_iter()
            .enumerate()
            .for_each(|(i, (r, h))| {
                let f = filtered(i);
                h.0 += f - r.0;
                r.0 = f;
            }),
        None => rho
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, r)| r.0 = filtered(i)),
    }
    Ok(())
}

// 2D set-ups; the 3D build's own tests are in `tests3d` modules.
#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use crate::vocab::KernelSums;
    use sph_core::components::{Density, Fluid, Ghost, Mass, Position, Pressure, Velocity};
    use sph_core::vocab::{HalfDensity, Neighbours};
    use sph_core::world::{archetype, column};

    /// A 0.2 m box lined with wall particles, and a 10 x 6 block of water on its floor
    /// whose densities vary by 2 % from particle to particle (a free surface on top, where
    /// the kernel is cut), each with a half-step density 3 kg/m^3 above its density:
    /// the sim after `stages` have run once.
    fn after(stages: &[(&str, &str)]) -> sph_core::Sim {
        let mut world = hecs::World::new();
        crate::testing::closed_box(&mut world, 0.2, 0.2);
        for a in 0..10 {
            for b in 0..6 {
                let k = (7 * a + 3 * b) % 11;
                world.spawn((
                    Fluid,
                    Position(glam::DVec2::new(
                        0.005 + 0.01 * a as f64,
                        0.005 + 0.01 * b as f64,
                    )),
                    Velocity(glam::DVec2::new(0.01 * k as f64, 0.0)),
                    Density(990.0 + 2.0 * k as f64),
                    HalfDensity(993.0 + 2.0 * k as f64),
                    Pressure(0.0),
                    Mass(0.1),
                ));
            }
        }
        crate::testing::after_one_step(world, stages)
    }

    /// The fluid's densities after `stages` (see [`after`]).
    fn filtered(stages: &[(&str, &str)]) -> Vec<f64> {
        let sim = after(stages);
        let fluid = archetype::<Fluid>(&sim.world).unwrap();
        let rho = column::<Density>(fluid).unwrap();
        rho.iter().map(|r| r.0).collect()
    }

    /// The free-surface summation writes its formula (`free_surface_density.rs`):
    /// rho_sum = sum_j m_j W_ij / (sigma_0 ds^2) over every particle within the support,
    /// i itself, the fluid and the wall particles, summed here by a plain loop with
    /// sigma_0 ds^2 from `kernel::lattice_sum`, then rho_sum + max(0, rho_i - rho_sum)
    /// rho_0 / rho_i (relative 1e-12: the order of addition). Every filter, with its own
    /// pass or the momentum pass's sums, shifts the half-step density by the correction
    /// it makes to the density (to 1e-9 kg/m^3, the round-off of a difference of
    /// values near 1,000), so the leapfrog carries the filtered state on.
    #[test]
    fn the_free_surface_summation_writes_its_formula_and_shifts_the_half_step_density() {
        let walls = [("wall_particles", "()"), ("neighbour_grid", "()")];
        let start = after(&walls);
        let c = &start.constants;
        let (kind, h, rho0) = (c.kernel, c.h, c.eos.rho0);
        let inv_lattice_sum = 1.0 / sph_core::kernel::lattice_sum(kind, h, c.spacing);
        let mut all: Vec<(glam::DVec2, f64)> = Vec::new();
        for (x, m) in start.world.query::<(&Position, &Mass)>().iter() {
            all.push((x.0, m.0));
        }
        let fluid = archetype::<Fluid>(&start.world).unwrap();
        let (x0, rho_0) = (
            column::<Position>(fluid).unwrap(),
            column::<Density>(fluid).unwrap(),
        );
        let expected: Vec<f64> = (0..x0.len())
            .map(|i| {
                let sum: f64 = all
                    .iter()
                    .map(|(x, m)| m * sph_core::kernel::w(kind, h, (*x - x0[i].0).length()))
                    .sum();
                let summed = sum * inv_lattice_sum;
                summed + (rho_0[i].0 - summed).max(0.0) * rho0 / rho_0[i].0
            })
            .collect();
        let own = filtered(&[
            walls[0],
            walls[1],
            ("reinitialise", "(filter: FreeSurface)"),
        ]);
        for (i, (a, b)) in own.iter().zip(&expected).enumerate() {
            assert!((a - b).abs() <= 1e-12 * b, "particle {i}: {a} against {b}");
        }
        for filter in [
            vec![
                walls[0],
                walls[1],
                ("reinitialise", "(filter: FreeSurface)"),
            ],
            vec![walls[0], walls[1], ("reinitialise", "(filter: Shepard)")],
            vec![
                walls[0],
                walls[1],
                ("eos", "()"),
                ("wall_pressure", "()"),
                (
                    "forces",
                    "(terms: [RiemannPressure(), Continuity(), RiemannDiffusion()])",
                ),
                ("reinitialise", "(filter: FreeSurface, sums: Forces)"),
            ],
        ] {
            let sim = after(&filter);
            let fluid = archetype::<Fluid>(&sim.world).unwrap();
            let rho = column::<Density>(fluid).unwrap();
            let half = column::<HalfDensity>(fluid).unwrap();
            for i in 0..rho.len() {
                // The half-step density started 3 above the density.
                let shift = half[i].0 - (rho_0[i].0 + 3.0);
                let change = rho[i].0 - rho_0[i].0;
                assert!(
                    (shift - change).abs() <= 1e-9,
                    "{:?}: particle {i}: half-step density moved {shift}, density {change}",
                    filter.last()
                );
            }
        }
    }

    /// The free-surface summation from the momentum pass's sums (`sums: Forces`, after
    /// `Forces`) writes the densities its own pass writes before the pressures: the same
    /// positions, masses and densities enter both, and only the order of addition
    /// differs (fluid then wall neighbours), so they agree to 1e-13. Checked for the
    /// Riemann set (a loop compiled with the sums) and a set that runs the generic loop.
    /// The filter moves at least a third of the densities by more than 0.1 %.
    #[test]
    fn the_summation_from_the_momentum_pass_writes_what_its_own_pass_writes() {
        let before = filtered(&[("wall_particles", "()"), ("neighbour_grid", "()")]);
        let own = filtered(&[
            ("wall_particles", "()"),
            ("neighbour_grid", "()"),
            ("reinitialise", "(filter: FreeSurface)"),
        ]);
        let moved = own
            .iter()
            .zip(&before)
            .filter(|(a, b)| (*a - *b).abs() > 1.0)
            .count();
        assert!(moved >= 20, "{moved} of {} densities moved", own.len());
        for terms in [
            "(terms: [RiemannPressure(), Continuity(), RiemannDiffusion()])",
            "(terms: [PressureGradient(), Continuity()])",
        ] {
            let fused = filtered(&[
                ("wall_particles", "()"),
                ("neighbour_grid", "()"),
                ("eos", "()"),
                ("wall_pressure", "()"),
                ("forces", terms),
                ("reinitialise", "(filter: FreeSurface, sums: Forces)"),
            ]);
            for (i, (a, b)) in fused.iter().zip(&own).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-13 * b,
                    "{terms}: particle {i}: {a} against {b}"
                );
            }
        }
    }

    /// The stage declares what it reads: the neighbour lists always, and the momentum
    /// pass's kernel sums only with `sums: Forces`, so the contract check refuses it
    /// before `NeighbourGrid`, and with `sums: Forces` before `Forces`, and lets the
    /// own pass run without a `Forces` at all (the lists then lack only a clock).
    #[test]
    fn the_filter_declares_the_lists_and_the_momentum_pass_sums_it_reads() {
        use sph_core::contract::{check, Breach, Quantity};
        let access = |name: &str, params: &str| crate::testing::stage(name, params).access();
        let grid = access("neighbour_grid", "()");
        let forces = access("forces", "(terms: [RiemannPressure(), Continuity()])");
        let fused = access("reinitialise", "(filter: FreeSurface, sums: Forces)");
        let own = access("reinitialise", "(filter: FreeSurface)");
        let unwritten = |list: &[&sph_core::contract::Access], q: Quantity, reader: usize| {
            matches!(
                check(list.iter().map(|a| (*a, 1))),
                Err(Breach::Unwritten { quantity, reader: r, .. }) if quantity == q && r == reader
            )
        };
        let sums = Quantity::of::<KernelSums>();
        assert!(unwritten(&[&own, &grid], Quantity::of::<Neighbours>(), 0));
        assert!(unwritten(&[&grid, &fused, &forces], sums, 1));
        // Past the filter the lists lack only a clock writer.
        assert_eq!(
            check([(&grid, 1), (&forces, 1), (&fused, 1)]),
            Err(Breach::NoClock)
        );
        assert_eq!(check([(&grid, 1), (&own, 1)]), Err(Breach::NoClock));
    }

    /// After the Shepard filter, every mirrored ghost carries its source's filtered
    /// density (`GhostWalls` without the hydrostatic correction: the ghosts hold their
    /// sources' densities), not the density it was mirrored with.
    #[test]
    fn mirrored_ghosts_take_their_sources_filtered_density() {
        let mirrors = [
            ("ghost_walls", "(hydrostatic: false)"),
            ("neighbour_grid", "()"),
        ];
        let before = filtered(&mirrors);
        let sim = after(&[
            mirrors[0],
            mirrors[1],
            ("reinitialise", "(filter: Shepard)"),
        ]);
        let fluid = archetype::<Fluid>(&sim.world).unwrap();
        let rho: Vec<f64> = column::<Density>(fluid)
            .unwrap()
            .iter()
            .map(|r| r.0)
            .collect();
        let moved = rho
            .iter()
            .zip(&before)
            .filter(|(a, b)| (*a - *b).abs() > 1.0)
            .count();
        assert!(moved >= 10, "the filter moved {moved} densities");
        let ghost = archetype::<Ghost>(&sim.world).unwrap();
        let (gs, gr) = (
            column::<Ghost>(ghost).unwrap(),
            column::<Density>(ghost).unwrap(),
        );
        assert!(gs.len() >= 20, "{} ghosts", gs.len());
        for (g, r) in gs.iter().zip(gr.iter()) {
            assert_eq!(
                r.0, rho[g.source as usize],
                "a ghost of particle {}",
                g.source
            );
        }
    }

    /// Only the free-surface summation takes its sums from the momentum pass.
    #[test]
    fn the_shepard_filter_refuses_the_momentum_pass_sums() {
        let registry = crate::standard_registry();
        for filter in ["Shepard", "Mls"] {
            let text = format!("(filter: {filter}, sums: Forces)");
            let mut de = ron::Deserializer::from_str(&text).unwrap();
            let mut erased = <dyn erased_serde::Deserializer>::erase(&mut de);
            let err = match registry.build("reinitialise", &mut erased).unwrap() {
                Ok(_) => panic!("{text} accepted"),
                Err(e) => e.to_string(),
            };
            assert!(err.contains("sums") && err.contains("FreeSurface"), "{err}");
        }
    }
}
