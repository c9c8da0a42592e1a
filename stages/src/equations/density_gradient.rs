//! The renormalised density gradient of Randles & Libersky (1996), which the
//! delta-SPH diffusion term reads (Antuono et al. 2010; docs/physics.md, "Density
//! diffusion"):
//!   <grad rho>_i = L_i sum_j (rho_j - rho_i) grad_i W_ij V_j,
//!   L_i = [sum_j x_ji (x) grad_i W_ij V_j]^-1,   V_j = m_j / rho_j,
//! exact for a linear density field wherever L_i exists (also at a free surface,
//! where the plain sum is cut off). A particle whose matrix is near singular (a lone
//! drop: det < 1e-3, against 1 inside the fluid) keeps the plain sum; such
//! particle-steps are counted in the run's `gradient_unrenormalised` diagnostic.
//!
//! A ghost takes its source particle's gradient unchanged: with the hydrostatic
//! ghost density (`GhostWalls(hydrostatic: true)`) the density field continues across
//! the wall, and so does its gradient. `Forces` computes the gradients before its pair
//! sums when its terms include `DeltaSph()` (one pass more over the neighbours).

use crate::vocab::DensityGradient;
use crate::vocab::GradientUnrenormalised;
use rayon::prelude::*;
use sph_core::components::Ghost;
use sph_core::dim::{Vector, DIM};
use sph_core::pair::{
    with_records, Columns, Field, Fields, Lane, Layouts, Me, Pair, PairTerm, Pass, Scope,
};
use sph_core::sim::Counter;
use sph_core::sim::Sim;
use sph_core::stage::StepError;
use sph_core::vocab::Neighbours;
use sph_core::with_kernel;
use sph_core::world::{archetype, column};

/// The sums of one particle: the matrix sum_j x_ji (x) grad W V_j (symmetric: grad W
/// lies along x_ji), its upper triangle row by row, then sum_j (rho_j - rho_i) grad W
/// V_j.
#[derive(Clone)]
pub struct Renormalised;

/// Below this determinant of the matrix, its inverse is not used.
const SINGULAR: f64 = 1e-3;

/// The matrix's upper triangle, DIM (DIM + 1) / 2 entries.
const MATRIX: usize = DIM * (DIM + 1) / 2;

impl PairTerm for Renormalised {
    // Packed with (position, rho, m) by its stage.
    const LAYOUTS: Layouts = Layouts::FILTER;
    type Acc<L: Lane> = [L; MATRIX + DIM];
    /// The gradient, and whether the matrix was singular.
    type Out = (Vector, bool);
    fn reads(&self) -> Fields {
        Fields::of(&[Field::Rho])
    }
    #[inline(always)]
    fn zero<L: Lane>(&self) -> [L; MATRIX + DIM] {
        [L::zero(); MATRIX + DIM]
    }
    #[inline(always)]
    fn pair<L: Lane>(&self, me: &Me, p: &Pair<L>, acc: &mut [L; MATRIX + DIM]) {
        let v = p.j(Field::Mass) / p.j(Field::Rho);
        // V grad W, written as a loop: `array::map` is not inlined in the pair loop.
        let mut vg = p.grad();
        for g in &mut vg {
            *g = v * *g;
        }
        // x_ji = -x_ij.
        let x = p.x_ij();
        let mut k = 0;
        for a in 0..DIM {
            for &vg_b in &vg[a..] {
                acc[k] = acc[k] - x[a] * vg_b;
                k += 1;
            }
        }
        let d = p.j(Field::Rho) - me.lanes::<L>(Field::Rho);
        for (s, &vg_a) in acc[MATRIX..].iter_mut().zip(&vg) {
            *s = *s + d * vg_a;
        }
    }
    #[cfg(not(feature = "dim3"))]
    fn finish<L: Lane>(&self, _: &Me, acc: [L; MATRIX + DIM]) -> (Vector, bool) {
        let [a, b, c, gx, gy] = acc.map(L::sum);
        let det = a * c - b * b;
        if det.abs() < SINGULAR || !det.is_finite() {
            return (Vector::new(gx, gy), true);
        }
        (Vector::new(c * gx - b * gy, a * gy - b * gx) / det, false)
    }
    /// In 3D the same solve with the 3 x 3 matrix.
    #[cfg(feature = "dim3")]
    fn finish<L: Lane>(&self, _: &Me, acc: [L; MATRIX + DIM]) -> (Vector, bool) {
        let [a00, a01, a02, a11, a12, a22, gx, gy, gz] = acc.map(L::sum);
        let sum = Vector::new(gx, gy, gz);
        let m = glam::DMat3::from_cols_array(&[a00, a01, a02, a01, a11, a12, a02, a12, a22]);
        let det = m.determinant();
        if det.abs() < SINGULAR || !det.is_finite() {
            return (sum, true);
        }
        (m.inverse() * sum, false)
    }
}

/// Writes the renormalised density gradient of every fluid particle and ghost into the
/// sim's [`DensityGradient`] column, from the current state and neighbour lists.
pub(crate) fn compute(sim: &mut Sim) -> Result<(), StepError> {
    let _span = tracing::trace_span!("pair_sums").entered();
    let mut out = sim
        .resources
        .get_or_default::<Columns>()
        .remove::<DensityGradient>()
        .unwrap_or_default();
    let singular = with_records(sim, Renormalised.reads(), |sim, _, records| {
        let Some(nb) = sim.resources.get::<Neighbours>() else {
            return Ok(0);
        };
        let n = nb.n_fluid;
        out.clear();
        out.resize(records.len(), Vector::ZERO);
        let c = &sim.constants;
        let singular = with_kernel!(c.kernel, c.h, |k| {
            let pass = Pass::new(&Renormalised, k, records)
                .map_err(|e| StepError::Internal(e.to_string()))?;
            Ok::<usize, StepError>(
                out[..n]
                    .par_iter_mut()
                    .enumerate()
                    .map(|(i, g)| {
                        let (grad, singular) = pass.sum(i, nb.of(i));
                        *g = grad;
                        singular as usize
                    })
                    .sum(),
            )
        })?;
        if let Some(ghosts) = archetype::<Ghost>(&sim.world) {
            let sources = column::<Ghost>(ghosts)?;
            let (fluid, ghost) = out.split_at_mut(n);
            if ghost.len() != sources.len() {
                return Err(StepError::Internal(format!(
                    "{} records beyond the fluid's {n} for {} ghosts",
                    ghost.len(),
                    sources.len()
                )));
            }
            for (g, s) in ghost.iter_mut().zip(sources.iter()) {
                *g = fluid.get(s.source as usize).copied().unwrap_or_default();
            }
        }
        Ok(singular)
    })?;
    GradientUnrenormalised::add(&mut sim.diagnostics, singular.unwrap_or(0) as u64);
    sim.resources
        .get_or_default::<Columns>()
        .insert::<DensityGradient>(Scope::Particles, out)?;
    Ok(())
}
