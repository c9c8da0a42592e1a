//! Momentum equation (physics.md, "Governing equations"):
//! dv_i/dt = - sum_j m_j (p_i/rho_i^2 + p_j/rho_j^2 + Pi_ij + R f_ij^n) grad_i W_ij + g,
//! with Monaghan's artificial viscosity Pi_ij and, optionally, Monaghan's (2000)
//! artificial pressure R f_ij^n against the tensile instability.
//!
//! With `with_continuity: true` the same neighbour loop also evaluates the continuity
//! equation (as the `Continuity` stage does, term for term in the same order, so the
//! result is bit-identical to `Continuity()` placed before `Forces()`): one pass over
//! the neighbours instead of two.

use crate::packed::{with_packed, Fill, Packed};
use crate::pair_x8::WendlandX8;
use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{
    Acceleration, Density, DensityRate, Fluid, Mass, Position, Pressure, Velocity,
};
use sph_core::contract::Access;
use sph_core::kernel::Kernel;
use sph_core::sim::{whole_pow, Sim};
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{
    require_neighbours, ArtificialViscosity, ContinuityInPipeline, Neighbours, ViscousDissipation,
};
use sph_core::world::{ensure_component, Particles};
use sph_core::{with_kernel, StageRegistry};

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Linear artificial-viscosity coefficient alpha. Default 0.03.
    pub alpha: f64,
    /// Quadratic coefficient beta. Default 0.
    pub beta: f64,
    /// Monaghan's artificial pressure term. Default false.
    pub artificial_pressure: bool,
    /// Its coefficient eps for negative pressures. Default 0.2.
    pub epsilon: f64,
    /// Its coefficient when both pressures are positive. Default 0.01.
    pub epsilon_positive: f64,
    /// Exponent n of f_ij = W(r)/W(ds). Default 4.
    pub exponent: i32,
    /// Also write the density rate d rho_i/dt = sum_j m_j v_ij . grad_i W_ij in the
    /// same neighbour loop (then leave `Continuity()` out). Default false.
    pub with_continuity: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            alpha: 0.03,
            beta: 0.0,
            artificial_pressure: false,
            epsilon: 0.2,
            epsilon_positive: 0.01,
            exponent: 4,
            with_continuity: false,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register(
        "forces",
        "pressure gradient, artificial viscosity and pressure, gravity",
        |p: Params| {
            for (field, v) in [
                ("alpha", p.alpha),
                ("beta", p.beta),
                ("epsilon", p.epsilon),
                ("epsilon_positive", p.epsilon_positive),
            ] {
                if !(v >= 0.0 && v.is_finite()) {
                    return Err(format!(
                        "field `{field}` = {v} is out of range; accepted: a finite number >= 0"
                    ));
                }
            }
            if !(1..=12).contains(&p.exponent) {
                return Err(format!(
                    "field `exponent` = {} is out of range; accepted: 1 to 12",
                    p.exponent
                ));
            }
            Ok(Forces {
                params: p,
                dissipation: Vec::new(),
            })
        },
    );
}

pub struct Forces {
    params: Params,
    /// Dissipation rate of each `CHUNK` of particles (summed in particle order), kept
    /// between steps; the total adds them in chunk order, so it is the same for any
    /// thread count.
    dissipation: Vec<f64>,
}

impl Stage for Forces {
    fn name(&self) -> &'static str {
        "forces"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, "forces")?;
        ensure_component::<Fluid, Acceleration>(sim);
        if self.params.with_continuity {
            if sim.resources.contains::<ContinuityInPipeline>() {
                return Err(SetupError::new(
                    "forces",
                    "`with_continuity: true` and a Continuity() stage both write the \
                     density rate; remove one of them",
                ));
            }
            ensure_component::<Fluid, DensityRate>(sim);
        }
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let want_power = sim.resources.contains::<ViscousDissipation>();
        let fill = Fill::Pressure(sim.constants.eos);
        let power = with_packed(sim, fill, |sim, particles, all| {
            self.accelerations(sim, particles, all, want_power)
        })?
        .unwrap_or(0.0);
        if let Some(d) = sim.resources.get_mut::<ViscousDissipation>() {
            d.power = power;
        }
        Ok(())
    }

    /// Accelerations (and, with `with_continuity`, the density rate) from the
    /// neighbours' state; exposes its artificial viscosity.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Neighbours>()
            .reads::<Position>()
            .reads::<Velocity>()
            .reads::<Density>()
            .reads::<Pressure>()
            .reads::<Mass>()
            .writes::<Acceleration>()
            .writes_if::<DensityRate>(self.params.with_continuity)
            .writes::<ViscousDissipation>()
            .exposes(ArtificialViscosity {
                alpha: self.params.alpha,
                beta: self.params.beta,
            })
    }
}

impl Forces {
    /// Writes every fluid particle's acceleration from the packed particles `all`;
    /// returns the viscous dissipation rate
    /// (1/2) sum_i m_i sum_j m_j Pi_ij v_ij . grad_i W_ij when asked (else 0).
    fn accelerations(
        &mut self,
        sim: &Sim,
        particles: &Particles,
        all: &[Packed],
        want_power: bool,
    ) -> Result<f64, StepError> {
        let Some(nb) = sim.resources.get::<Neighbours>() else {
            return Ok(0.0);
        };
        let c = &sim.constants;
        let (g, h, ds) = (c.gravity, c.h, c.spacing);
        let mut acc = particles.fluid_mut::<Acceleration>()?;
        let mut rate = if self.params.with_continuity {
            Some(particles.fluid_mut::<DensityRate>()?)
        } else {
            None
        };
        let n = acc.len();
        let mut dissipation = std::mem::take(&mut self.dissipation);
        let chunks = n.div_ceil(CHUNK);
        dissipation.resize(if want_power { chunks } else { 0 }, 0.0);
        let (art, with_rate) = (self.params.artificial_pressure, rate.is_some());
        // Per-particle outputs as optional slices, so one parallel loop serves every
        // combination; the pair sum itself is monomorphised on the options.
        let rate_out: &mut [DensityRate] = rate.as_deref_mut().unwrap_or(&mut []);
        let x8 = WendlandX8::detect(c.kernel, h);
        if x8.is_some() {
            nb.check_covers(all.len())?;
        }
        with_kernel!(c.kernel, h, |k| {
            let prm = Pair::new(&self.params, k.w(ds), h);

            let pair = |i: usize| match (x8, art, with_rate) {
                (Some(x8), true, true) => x8.sums::<true, true, true>(&prm, all, nb.of(i), i),
                (Some(x8), true, false) => x8.sums::<true, true, false>(&prm, all, nb.of(i), i),
                (Some(x8), false, true) => x8.sums::<true, false, true>(&prm, all, nb.of(i), i),
                (Some(x8), false, false) => x8.sums::<true, false, false>(&prm, all, nb.of(i), i),
                (None, true, true) => {
                    sum_over_neighbours::<_, true, true>(&prm, &k, all, nb.of(i), i)
                }
                (None, true, false) => {
                    sum_over_neighbours::<_, true, false>(&prm, &k, all, nb.of(i), i)
                }
                (None, false, true) => {
                    sum_over_neighbours::<_, false, true>(&prm, &k, all, nb.of(i), i)
                }
                (None, false, false) => {
                    sum_over_neighbours::<_, false, false>(&prm, &k, all, nb.of(i), i)
                }
            };
            acc.par_chunks_mut(CHUNK)
                .zip(optional_chunks(rate_out, n))
                .zip(optional_outputs(&mut dissipation[..], chunks, 1))
                .enumerate()
                .for_each(|(c, ((acc, mut rate), diss))| {
                    let mut power = 0.0;
                    for (k, a) in acc.iter_mut().enumerate() {
                        let i = c * CHUNK + k;
                        let s = pair(i);
                        a.0 = s.acc + g;
                        if let Some(r) = rate.as_deref_mut() {
                            r[k].0 = s.rate;
                        }
                        power += 0.5 * all[i].m * s.visc_power;
                    }
                    if let Some(d) = diss {
                        d[0] = power;
                    }
                });
        });
        let power = dissipation.iter().sum();
        self.dissipation = dissipation;
        Ok(power)
    }
}

/// Fluid particles per parallel chunk of the force loop.
const CHUNK: usize = 256;

/// `CHUNK`-sized chunks of an optional per-particle output: the slice's own chunks if
/// it holds all `n` particles, else as many `None`s (the output is not wanted).
fn optional_chunks<T: Send>(
    out: &mut [T],
    n: usize,
) -> impl IndexedParallelIterator<Item = Option<&mut [T]>> {
    optional_outputs(out, n, CHUNK)
}

/// Pieces of `per` elements of an optional output of `len` elements: the slice's own
/// pieces if it holds exactly `len`, else as many `None`s (the output is not wanted).
fn optional_outputs<T: Send>(
    out: &mut [T],
    len: usize,
    per: usize,
) -> impl IndexedParallelIterator<Item = Option<&mut [T]>> {
    use rayon::iter::Either;
    if out.len() == len && len > 0 {
        Either::Left(out.par_chunks_mut(per).map(Some))
    } else {
        Either::Right((0..len.div_ceil(per)).into_par_iter().map(|_| None))
    }
}

/// The constants of the pair loop, derived once per step from the parameters.
pub(crate) struct Pair {
    pub alpha: f64,
    pub beta: f64,
    pub epsilon: f64,
    pub epsilon_positive: f64,
    pub exponent: u32,
    /// 1 / W(ds), for f_ij = (W(r_ij)/W(ds))^n.
    pub inv_w_ds: f64,
    pub h: f64,
    /// eta^2 = 0.01 h^2 in phi_ij = h v_ij.x_ij / (r^2 + eta^2).
    pub eta2: f64,
}

impl Pair {
    pub(crate) fn new(p: &Params, w_ds: f64, h: f64) -> Self {
        Self {
            alpha: p.alpha,
            beta: p.beta,
            epsilon: p.epsilon,
            epsilon_positive: p.epsilon_positive,
            exponent: p.exponent as u32,
            inv_w_ds: 1.0 / w_ds,
            h,
            eta2: 0.01 * h * h,
        }
    }
}

/// One fluid particle's sums over its neighbours.
#[derive(Clone, Copy)]
pub(crate) struct Sums {
    /// Pressure, viscous and artificial-pressure acceleration (gravity not included).
    pub acc: DVec2,
    /// sum_j m_j Pi_ij v_ij . grad W (for the dissipation rate).
    pub visc_power: f64,
    /// d rho_i/dt by the continuity equation (0 unless asked for).
    pub rate: f64,
}

/// Pressure and viscous acceleration of particle i, sum_j m_j Pi_ij v_ij . grad W and,
/// with `RATE`, the continuity equation's sum_j m_j v_ij . grad W. `ART` selects
/// Monaghan's artificial pressure at compile time.
#[inline(always)]
pub(crate) fn sum_over_neighbours<K: Kernel, const ART: bool, const RATE: bool>(
    prm: &Pair,
    k: &K,
    all: &[Packed],
    neighbours: &[u32],
    i: usize,
) -> Sums {
    let Packed {
        x: xi,
        v: vi,
        rho: rhoi,
        p_rho2: pi_r2,
        c: ci,
        ..
    } = all[i];
    let (mut acc, mut visc_power, mut rate) = (DVec2::ZERO, 0.0, 0.0);
    for &j in neighbours {
        let pj = &all[j as usize];
        let xij = xi - pj.x;
        let r = xij.length();
        let grad = k.grad(xij, r);
        let (rhoj, mj, pj_r2, cj) = (pj.rho, pj.m, pj.p_rho2, pj.c);
        let mut term = pi_r2 + pj_r2;
        let vij = vi - pj.v;
        let vx = vij.dot(xij);
        let mut visc = 0.0;
        if vx < 0.0 {
            // Monaghan's artificial viscosity Pi_ij = (-alpha cbar phi + beta phi^2) / rhobar.
            let phi = prm.h * vx / (r * r + prm.eta2);
            let cbar = 0.5 * (ci + cj);
            visc = (-prm.alpha * cbar * phi + prm.beta * phi * phi) / (0.5 * (rhoi + rhoj));
            term += visc;
        }
        if ART {
            // R f_ij^n: R = eps (|p_i|/rho_i^2 + |p_j|/rho_j^2) over the negative
            // pressures, or eps_+ (p_i/rho_i^2 + p_j/rho_j^2) when both are positive.
            let fij = whole_pow(k.w(r) * prm.inv_w_ds, prm.exponent);
            let big_r = if pi_r2 > 0.0 && pj_r2 > 0.0 {
                prm.epsilon_positive * (pi_r2 + pj_r2)
            } else {
                prm.epsilon * ((-pi_r2).max(0.0) + (-pj_r2).max(0.0))
            };
            term += big_r * fij;
        }
        let vij_grad = vij.dot(grad);
        acc -= mj * term * grad;
        visc_power += mj * visc * vij_grad;
        if RATE {
            rate += mj * vij_grad;
        }
    }
    Sums {
        acc,
        visc_power,
        rate,
    }
}
