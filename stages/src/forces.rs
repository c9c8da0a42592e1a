//! Momentum equation (physics.md, "Governing equations"):
//! dv_i/dt = - sum_j m_j (p_i/rho_i^2 + p_j/rho_j^2 + Pi_ij + R f_ij^n) grad_i W_ij + g,
//! with Monaghan's artificial viscosity Pi_ij and, optionally, Monaghan's (2000)
//! artificial pressure R f_ij^n against the tensile instability.

use crate::continuity::require_neighbours;
use crate::neighbour_grid::Neighbours;
use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Acceleration, Density, Fluid, Mass, Position, Pressure, Velocity};
use sph_core::kernel::Kernel;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::world::{ensure_component, sum_fixed, Joined, Particles};
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
                sound: Vec::new(),
            })
        },
    );
}

pub struct Forces {
    params: Params,
    /// Per-particle sound speed c(rho) in the joint numbering, refreshed each step so the
    /// pair loop needs no powf.
    sound: Vec<f64>,
}

/// Work dissipated by the artificial viscosity: the forces stage stores its rate here
/// each step when a stage that reports energy has asked for it (by inserting it).
#[derive(Debug, Default, Clone, Copy)]
pub struct ViscousDissipation {
    /// Rate of dissipation this step [W per metre of depth].
    pub power: f64,
}

impl Stage for Forces {
    fn name(&self) -> &'static str {
        "forces"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        require_neighbours(sim, "forces")?;
        ensure_component::<Fluid, Acceleration>(&mut sim.world);
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let want_power = sim.resources.contains::<ViscousDissipation>();
        let power = self.accelerations(sim, want_power)?;
        if let Some(d) = sim.resources.get_mut::<ViscousDissipation>() {
            d.power = power;
        }
        Ok(())
    }
}

/// The fields a pair interaction reads, in the joint fluid+ghost numbering.
struct Fields<'a> {
    x: Joined<'a, Position>,
    v: Joined<'a, Velocity>,
    rho: Joined<'a, Density>,
    p: Joined<'a, Pressure>,
    m: Joined<'a, Mass>,
    /// Sound speed c(rho).
    c: Joined<'a, f64>,
}

impl Forces {
    /// Writes every fluid particle's acceleration; returns the viscous dissipation rate
    /// (1/2) sum_i m_i sum_j m_j Pi_ij v_ij . grad_i W_ij when asked (else 0).
    fn accelerations(&mut self, sim: &Sim, want_power: bool) -> Result<f64, StepError> {
        let Some(nb) = sim.resources.get::<Neighbours>() else {
            return Ok(0.0);
        };
        let Some(particles) = Particles::of(&sim.world) else {
            return Ok(0.0);
        };
        let (x, v, rho) = (
            particles.joined::<Position>()?,
            particles.joined::<Velocity>()?,
            particles.joined::<Density>()?,
        );
        let (p, m) = (particles.joined::<Pressure>()?, particles.joined::<Mass>()?);
        let c = &sim.constants;
        let (eos, g, h, ds) = (c.eos, c.gravity, c.h, c.spacing);
        let rho_all = rho.view();
        self.sound.resize(rho_all.len(), 0.0);
        self.sound
            .par_iter_mut()
            .enumerate()
            .for_each(|(j, s)| *s = eos.sound_speed(rho_all.get(j as u32).0));
        let sound = Joined::new(
            &self.sound[..rho_all.fluid.len()],
            &self.sound[rho_all.fluid.len()..],
        );
        let f = Fields {
            x: x.view(),
            v: v.view(),
            rho: rho.view(),
            p: p.view(),
            m: m.view(),
            c: sound,
        };
        let mut acc = particles.fluid_mut::<Acceleration>()?;
        let mut dissipation = vec![0.0; if want_power { acc.len() } else { 0 }];
        with_kernel!(c.kernel, h, |k| {
            let w_ds = k.w(ds);
            let prm = &self.params;
            let pair = |i: usize| sum_over_neighbours(prm, &k, &f, nb.of(i), i, h, w_ds);
            if want_power {
                acc.par_iter_mut()
                    .zip(dissipation.par_iter_mut())
                    .enumerate()
                    .for_each(|(i, (a, d))| {
                        let (sum, visc) = pair(i);
                        a.0 = sum + g;
                        *d = 0.5 * f.m.fluid[i].0 * visc;
                    });
            } else {
                acc.par_iter_mut()
                    .enumerate()
                    .for_each(|(i, a)| a.0 = pair(i).0 + g);
            }
        });
        Ok(sum_fixed(dissipation.len(), |i| dissipation[i]))
    }
}

/// Pressure and viscous acceleration of particle i, and sum_j m_j Pi_ij v_ij . grad W.
#[inline(always)]
fn sum_over_neighbours<K: Kernel>(
    prm: &Params,
    k: &K,
    f: &Fields,
    neighbours: &[u32],
    i: usize,
    h: f64,
    w_ds: f64,
) -> (DVec2, f64) {
    {
        let (xi, vi, rhoi, pi) = (
            f.x.fluid[i].0,
            f.v.fluid[i].0,
            f.rho.fluid[i].0,
            f.p.fluid[i].0,
        );
        let pi_r2 = pi / (rhoi * rhoi);
        let ci = f.c.fluid[i];
        let eta2 = 0.01 * h * h;
        let (mut acc, mut visc_power) = (DVec2::ZERO, 0.0);
        for &j in neighbours {
            let xij = xi - f.x.get(j).0;
            let r = xij.length();
            let grad = k.grad(xij, r);
            let (rhoj, pj, mj) = (f.rho.get(j).0, f.p.get(j).0, f.m.get(j).0);
            let pj_r2 = pj / (rhoj * rhoj);
            let mut term = pi_r2 + pj_r2;
            let vij = vi - f.v.get(j).0;
            let vx = vij.dot(xij);
            let mut visc = 0.0;
            if vx < 0.0 {
                let phi = h * vx / (r * r + eta2);
                let cbar = 0.5 * (ci + *f.c.get(j));
                visc = (-prm.alpha * cbar * phi + prm.beta * phi * phi) / (0.5 * (rhoi + rhoj));
                term += visc;
            }
            if prm.artificial_pressure {
                let fij = (k.w(r) / w_ds).powi(prm.exponent);
                let big_r = if pi > 0.0 && pj > 0.0 {
                    prm.epsilon_positive * (pi_r2 + pj_r2)
                } else {
                    let part = |p: f64, r2: f64| {
                        if p < 0.0 {
                            prm.epsilon * p.abs() * r2
                        } else {
                            0.0
                        }
                    };
                    part(pi, 1.0 / (rhoi * rhoi)) + part(pj, 1.0 / (rhoj * rhoj))
                };
                term += big_r * fij;
            }
            acc -= mj * term * grad;
            visc_power += mj * visc * vij.dot(grad);
        }
        (acc, visc_power)
    }
}
