//! Particle shifting (docs/physics.md, "Particle shifting"): after `Integrate` has
//! advanced the positions, each fluid particle is moved down the gradient of the
//! particle concentration, Fick's law as in Lind et al. (2012), with the coefficient
//! and the free-surface treatment of Sun et al. (2017) and, optionally (R > 0), their
//! anti-clumping factor:
//!   delta r_i = -A h^2 grad C_i,
//!   grad C_i  = sum_j V_j [1 + R (W_ij / W(ds))^4] grad_i W_ij,   V_j = m_j / rho_j,
//! over fluid neighbours and ghosts (the mirrored ghosts complete the kernel at a wall,
//! so a particle beside a wall is not pushed towards or away from it by the wall's
//! truncation). A = 4 CFL Ma in Sun et al. (2017): with the engine's Courant number
//! 0.25 and Mach number 0.1 (c_0 = 10 U), A = 0.1, the default.
//!
//! Free surface (Marrone et al. 2010): a particle whose divergence of position
//!   div r_i = sum_j V_j (x_j - x_i) . grad_i W_ij
//! (2 inside the fluid in 2D and 3 in 3D, about half that on a flat surface) is below
//! `surface_threshold`
//! is a surface particle and is not shifted; every other fluid particle with a surface
//! particle in its neighbour list (its kernel is still cut by the surface) keeps only
//! the tangential part of its shift, delta r - (delta r . n) n, with the normal of
//! Marrone et al. (2010), n = -L_i sum_j V_j grad_i W_ij / |...|,
//! L_i = [sum_j V_j x_ji (x) grad_i W_ij]^-1 (the plain sum where L_i is near
//! singular). Without this the truncated kernel at the surface gives a large grad C
//! pointing into the fluid, and the shift would push the surface particles out of it.
//! Surface particles get no tangential shift either: at the tip of a thin jet the
//! normal of the layer is not the tip's, and the "tangential" part pushed the dam
//! break's surge front ahead (with R = 0.2 it reached the far wall at t sqrt(g/H) =
//! 2.41 instead of 2.47 without shifting, with a spurious impact spike; 2.49 without
//! the tip's shift).
//!
//! A shift longer than `max_shift` ds is cut to that length (the direction kept) and
//! counted in the `shifts_capped` diagnostic. Velocities and densities are not
//! corrected (no Taylor correction): the shift is a small, O(h^2 |grad C|) move of the
//! interpolation point. The neighbour lists and ghosts are the step's (built before
//! `Integrate` moved the particles by at most a Courant fraction of h), so pairs that
//! came within the support during the step are missed; their kernel values are those
//! at the edge of the support, near zero.
//!
//! Stateless (nothing to checkpoint); every particle's shift is computed from the
//! packed records before any position is written, so the result does not depend on
//! the number of threads.

use crate::vocab::ShiftsCapped;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Density, Fluid, Ghost, Mass, Position};
use sph_core::contract::Access;
use sph_core::dim::{Vector, DIM};
use sph_core::kernel::Kernel;
use sph_core::pair::{with_records, Field, Fields, Lane, Layouts, Me, Pair, PairTerm, Pass};
use sph_core::sim::Counter;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{require_neighbours, Neighbours};
use sph_core::with_kernel;
use sph_core::world::{archetype, column, column_mut};
use sph_core::StageRegistry;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// A in delta r = -A h^2 grad C, per step. Default 0.1 (Sun et al. 2017: 4 CFL Ma
    /// with CFL 0.25, Ma 0.1); Lind et al. (2012) use 0.5 with incompressible SPH's
    /// larger steps.
    pub coefficient: f64,
    /// R of the anti-clumping factor 1 + R (W_ij / W(ds))^4 (Sun et al. 2017 use 0.2,
    /// after Monaghan's tensile correction). Default 0: the plain concentration
    /// gradient of Lind et al. (2012). With 0.2 the factor's cut-off sum under a
    /// still free surface drew the near-surface particles together into a hump in
    /// the middle of the tank (0.12 ds in 0.5 s in the test of tests/tests/shifting.rs;
    /// none with 0).
    pub anti_clump: f64,
    /// Largest shift per step, as a fraction of ds; longer shifts are cut to it and
    /// counted in the `shifts_capped` diagnostic. Default 0.2.
    pub max_shift: f64,
    /// Detect the free surface (div r below `surface_threshold`): surface particles are
    /// not shifted, their neighbours only along the surface. `false` shifts
    /// every particle fully: only for a fluid without a free surface. Default true.
    pub free_surface: bool,
    /// A particle with div r below this is on the free surface (DIM inside the fluid,
    /// about half of it on a flat surface). Default 1.5 in 2D, 2.25 in 3D: three
    /// quarters of the inside's value.
    pub surface_threshold: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            coefficient: 0.1,
            anti_clump: 0.0,
            max_shift: 0.2,
            free_surface: true,
            surface_threshold: 0.75 * DIM as f64,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "shifting",
        "particle shifting down the concentration gradient, free surface kept (after Integrate)",
        |p: Params| {
            let out = sph_core::ParamError::new;
            if !(p.coefficient >= 0.0 && p.coefficient <= 1.0) {
                return Err(out(
                    "coefficient",
                    p.coefficient,
                    "0 <= A <= 1 (0.1 usual, 0.5 Lind et al. 2012)",
                ));
            }
            if !(p.anti_clump >= 0.0 && p.anti_clump <= 1.0) {
                return Err(out(
                    "anti_clump",
                    p.anti_clump,
                    "0 <= R <= 1 (0 default, 0.2 Sun et al. 2017)",
                ));
            }
            if !(p.max_shift > 0.0 && p.max_shift <= 0.5) {
                return Err(out(
                    "max_shift",
                    p.max_shift,
                    "a fraction of ds with 0 < f <= 0.5 (0.2 usual)",
                ));
            }
            if !(p.surface_threshold > 0.0 && p.surface_threshold < DIM as f64) {
                return Err(out(
                    "surface_threshold",
                    p.surface_threshold,
                    if DIM == 2 {
                        "0 < t < 2 (div r is 2 inside the fluid in 2D; 1.5 usual)"
                    } else {
                        "0 < t < 3 (div r is 3 inside the fluid in 3D; 2.25 usual)"
                    },
                ));
            }
            Ok(Shifting {
                params: p,
                sums: Vec::new(),
                surface: Vec::new(),
                shifts: Vec::new(),
            })
        },
    );
}

/// What the pass gives for one particle.
#[derive(Clone, Copy, Default)]
pub struct Sums {
    /// grad C_i with the anti-clumping term [1/m].
    pub grad_c: Vector,
    /// The surface normal of Marrone et al. (2010) (unit, outward; zero if undefined).
    pub normal: Vector,
    /// div r_i.
    pub div_r: f64,
}

/// The pair term: sum_j V_j [1 + R (W/W(ds))^4] grad W, sum_j V_j grad W, the matrix
/// sum_j V_j x_ji (x) grad W (symmetric: grad W is along x_ij) and its trace div r.
#[derive(Clone)]
pub struct Concentration {
    /// R.
    anti_clump: f64,
    /// 1 / W(ds).
    inv_w_ds: f64,
}

/// Below this determinant (1 inside the fluid) the matrix is not inverted.
const SINGULAR: f64 = 1e-3;

/// The accumulator's length: two vectors and the symmetric matrix's upper triangle.
const ACC: usize = 2 * DIM + DIM * (DIM + 1) / 2;

impl PairTerm for Concentration {
    // Packed with (x, y, rho, m) by its stage.
    const LAYOUTS: Layouts = Layouts::FILTER;
    type Acc<L: Lane> = [L; ACC];
    type Out = Sums;
    fn reads(&self) -> Fields {
        Fields::of(&[Field::Rho])
    }
    #[inline(always)]
    fn zero<L: Lane>(&self) -> [L; ACC] {
        [L::zero(); ACC]
    }
    /// [f V grad W; V grad W; the matrix's upper triangle, row by row (xx, xy, yy in
    /// 2D; xx, xy, xz, yy, yz, zz in 3D)].
    #[inline(always)]
    fn pair<L: Lane>(&self, _: &Me, p: &Pair<L>, acc: &mut [L; ACC]) {
        let c = L::splat;
        // Zero in the padding lanes (zero mass).
        let v = p.j(Field::Mass) / p.j(Field::Rho);
        // V grad W, written as a loop: `array::map` is not inlined in the pair loop.
        let mut g = p.grad();
        for gk in &mut g {
            *gk = v * *gk;
        }
        let w = p.w * c(self.inv_w_ds);
        let w2 = w * w;
        let f = c(1.0) + c(self.anti_clump) * w2 * w2;
        for k in 0..DIM {
            acc[k] = acc[k] + f * g[k];
            acc[DIM + k] = acc[DIM + k] + g[k];
        }
        // x_ji = -x_ij.
        let d = p.x_ij();
        let mut m = 2 * DIM;
        for (a, &da) in d.iter().enumerate() {
            for &gb in &g[a..] {
                acc[m] = acc[m] - da * gb;
                m += 1;
            }
        }
    }
    #[cfg(not(feature = "dim3"))]
    fn finish<L: Lane>(&self, _: &Me, acc: [L; ACC]) -> Sums {
        let [gx, gy, px, py, a, b, d] = acc.map(L::sum);
        let det = a * d - b * b;
        let plain = Vector::new(px, py);
        let renormalised = if det.abs() < SINGULAR || !det.is_finite() {
            plain
        } else {
            Vector::new(d * px - b * py, a * py - b * px) / det
        };
        Sums {
            grad_c: Vector::new(gx, gy),
            normal: (-renormalised).normalize_or_zero(),
            div_r: a + d,
        }
    }
    #[cfg(feature = "dim3")]
    fn finish<L: Lane>(&self, _: &Me, acc: [L; ACC]) -> Sums {
        let [gx, gy, gz, px, py, pz, xx, xy, xz, yy, yz, zz] = acc.map(L::sum);
        let m = glam::DMat3::from_cols(
            Vector::new(xx, xy, xz),
            Vector::new(xy, yy, yz),
            Vector::new(xz, yz, zz),
        );
        let det = m.determinant();
        let plain = Vector::new(px, py, pz);
        let renormalised = if det.abs() < SINGULAR || !det.is_finite() {
            plain
        } else {
            m.inverse() * plain
        };
        Sums {
            grad_c: Vector::new(gx, gy, gz),
            normal: (-renormalised).normalize_or_zero(),
            div_r: xx + yy + zz,
        }
    }
}

pub struct Shifting {
    params: Params,
    /// Reused buffers: the sums, the surface flags and the shifts of the fluid.
    sums: Vec<Sums>,
    surface: Vec<bool>,
    shifts: Vec<Vector>,
}

impl Shifting {
    /// The shift of every fluid particle into `self.shifts` from the current state;
    /// returns how many were capped.
    fn compute(&mut self, sim: &mut Sim) -> Result<usize, StepError> {
        let c = &sim.constants;
        let term = with_kernel!(c.kernel, c.h, |k| Concentration {
            anti_clump: self.params.anti_clump,
            inv_w_ds: 1.0 / k.w(c.spacing),
        });
        let sums = &mut self.sums;
        let done = with_records(sim, term.reads(), |sim, _, records| {
            let nb = sim
                .resources
                .get::<Neighbours>()
                .ok_or_else(|| StepError::Internal("no neighbour lists".into()))?;
            nb.check_covers(records.len())?;
            sums.clear();
            sums.resize(nb.n_fluid, Sums::default());
            let c = &sim.constants;
            with_kernel!(c.kernel, c.h, |k| {
                let pass =
                    Pass::new(&term, k, records).map_err(|e| StepError::Internal(e.to_string()))?;
                sums.par_iter_mut()
                    .enumerate()
                    .for_each(|(i, s)| *s = pass.sum(i, nb.of(i)));
                Ok::<(), StepError>(())
            })
        })?;
        if done.is_none() {
            self.shifts.clear();
            return Ok(0);
        }
        let Some(nb) = sim.resources.get::<Neighbours>() else {
            return Ok(0);
        };
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            return Ok(0);
        };
        let x = column::<Position>(fluid)?;
        let x: &[Position] = &x;
        // The lists may hold pairs beyond the support (their skin).
        let support2 = nb.support * nb.support;
        let n = self.sums.len();
        let p = &self.params;
        self.surface.clear();
        self.surface.extend(
            self.sums
                .iter()
                .map(|s| p.free_surface && s.div_r < p.surface_threshold),
        );
        let c = &sim.constants;
        let d = p.coefficient * c.h * c.h;
        let cap = p.max_shift * c.spacing;
        let (sums, surface) = (&self.sums, &self.surface);
        self.shifts.resize(n, Vector::ZERO);
        let capped = self
            .shifts
            .par_iter_mut()
            .enumerate()
            .map(|(i, shift)| {
                let s = &sums[i];
                let mut dr = -d * s.grad_c;
                // A surface particle stays; one whose kernel the surface cuts moves
                // only along the surface.
                if surface[i] {
                    dr = Vector::ZERO;
                } else if nb.of(i).iter().any(|&j| {
                    let j = j as usize;
                    j < n && surface[j] && x[i].0.distance_squared(x[j].0) < support2
                }) {
                    dr -= dr.dot(s.normal) * s.normal;
                }
                let len = dr.length();
                let over = len > cap;
                if over {
                    dr *= cap / len;
                }
                *shift = if dr.is_finite() { dr } else { Vector::ZERO };
                over as usize
            })
            .sum();
        Ok(capped)
    }
}

impl Stage for Shifting {
    fn name(&self) -> &'static str {
        "shifting"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, "shifting")
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let _span = tracing::trace_span!("pair_sums").entered();
        let capped = self.compute(sim)?;
        if let Some(fluid) = archetype::<Fluid>(&sim.world) {
            let mut x = column_mut::<Position>(fluid)?;
            if x.len() != self.shifts.len() {
                return Err(StepError::Internal(format!(
                    "{} shifts for {} fluid particles",
                    self.shifts.len(),
                    x.len()
                )));
            }
            x.par_iter_mut()
                .zip(self.shifts.par_iter())
                .for_each(|(x, dr)| x.0 += *dr);
        }
        if capped > 0 {
            ShiftsCapped::add(&mut sim.diagnostics, capped as u64);
        }
        Ok(())
    }

    /// Moves the positions Integrate produced, in place, from the step's neighbour
    /// lists and ghosts.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Neighbours>()
            .reads::<Density>()
            .reads::<Mass>()
            .updates::<Position>()
            .uses::<Ghost>()
            .writes::<ShiftsCapped>()
    }
}
