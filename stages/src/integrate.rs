//! Time integration: Monaghan's leapfrog with one force evaluation per step, and the
//! adaptive step dt = C min( h / (c_max + max|v|), sqrt(h / max|a|) ) (physics.md,
//! "Time step"). It also watches for instability.
//!
//! Velocity and density are carried at half steps (`HalfVelocity`, `HalfDensity`):
//!   v^{n+1/2} = v^{n-1/2} + (dt_{n-1} + dt_n)/2 a^n      (v^{1/2} = v^0 + dt_0/2 a^0)
//!   x^{n+1}   = x^n + dt_n v^{n+1/2}
//! and the integer-time values the next force evaluation uses are predicted as
//! v^{n+1} = v^{n+1/2} + dt_n/2 a^n (likewise rho). Second order for a constant step.

use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::components::{Acceleration, Density, DensityRate, Fluid, Position, Velocity, Wall};
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::walls::WallSet;
use sph_core::world::{archetype, column_mut, ensure_component};
use sph_core::StageRegistry;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Courant number C. Default 0.25.
    pub courant: f64,
    /// Largest step [s]. Default 1e-3.
    pub max_dt: f64,
    /// The run stops as unstable when dt falls below this fraction of the first step.
    /// Default 1e-3.
    pub collapse_fraction: f64,
    /// The run stops when any |rho/rho_0 - 1| exceeds this. Default 0.5.
    pub density_limit: f64,
    /// A particle that ends a step behind a wall is reflected back (position mirrored,
    /// normal velocity relative to the wall reversed) and counted in the `wall_reflections` diagnostic of
    /// summary.json; mirror ghosts cannot stop a lone fast particle because the kernel
    /// gradient vanishes as it meets its own ghost. With `false` such a particle stops
    /// the run as unstable. Default true.
    pub reflect_at_walls: bool,
    /// A reflected particle's density is raised to at least rho_0. Meant with
    /// `Eos(min_pressure: 0)`: a pressureless spray particle gets through its ghosts,
    /// and continuity would keep rarefying it as it leaves the wall it crossed (the
    /// sloshing runs' roof spray). Default false.
    pub restore_density_on_reflection: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            courant: 0.25,
            max_dt: 1e-3,
            collapse_fraction: 1e-3,
            density_limit: 0.5,
            reflect_at_walls: true,
            restore_density_on_reflection: false,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register(
        "integrate",
        "leapfrog time step with adaptive dt and stability checks",
        |p: Params| {
            if !(p.courant > 0.0 && p.courant <= 1.0) {
                return Err(format!(
                    "field `courant` = {} is out of range; accepted: 0 < C <= 1 (0.2-0.3 usual)",
                    p.courant
                ));
            }
            if !(p.max_dt > 0.0 && p.max_dt.is_finite()) {
                return Err(format!(
                    "field `max_dt` = {} is out of range; accepted: a number > 0",
                    p.max_dt
                ));
            }
            if !(p.collapse_fraction > 0.0 && p.collapse_fraction < 1.0) {
                return Err(format!(
                    "field `collapse_fraction` = {} is out of range; accepted: 0 to 1",
                    p.collapse_fraction
                ));
            }
            if p.density_limit.is_nan() || p.density_limit <= 0.0 {
                return Err(format!(
                    "field `density_limit` = {} is out of range; accepted: a number > 0",
                    p.density_limit
                ));
            }
            Ok(Integrate {
                params: p,
                first_dt: None,
                walls: WallSet::default(),
            })
        },
    );
}

/// v at the last half step (leapfrog state).
#[derive(Clone, Copy, Debug, Default)]
pub struct HalfVelocity(pub DVec2);
/// rho at the last half step (leapfrog state).
#[derive(Clone, Copy, Debug, Default)]
pub struct HalfDensity(pub f64);

pub struct Integrate {
    params: Params,
    first_dt: Option<f64>,
    /// Walls where they are at the end of the step.
    walls: WallSet,
}

impl Stage for Integrate {
    fn name(&self) -> &'static str {
        "integrate"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        ensure_component::<Fluid, HalfVelocity>(&mut sim.world);
        ensure_component::<Fluid, HalfDensity>(&mut sim.world);
        self.walls = WallSet::from_world(&sim.world);
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            sim.clock.time = sim.clock.end_time;
            return Ok(());
        };
        let zero_a = vec![Acceleration::default(); fluid.len() as usize];
        let zero_r = vec![DensityRate::default(); fluid.len() as usize];
        // A pipeline without forces (or continuity) integrates with zero rates.
        let acc_col = fluid.get::<&Acceleration>();
        let rate_col = fluid.get::<&DensityRate>();
        let acc: &[Acceleration] = acc_col.as_deref().unwrap_or(&zero_a);
        let rate: &[DensityRate] = rate_col.as_deref().unwrap_or(&zero_r);
        let mut x = column_mut::<Position>(fluid)?;
        let mut v = column_mut::<Velocity>(fluid)?;
        let mut rho = column_mut::<Density>(fluid)?;
        let mut vh = column_mut::<HalfVelocity>(fluid)?;
        let mut rh = column_mut::<HalfDensity>(fluid)?;

        if let Some(i) = acc.iter().position(|a| !a.0.is_finite()) {
            return Err(unstable("non-finite acceleration", i, x[i].0));
        }
        if let Some(i) = rate.iter().position(|r| !r.0.is_finite()) {
            return Err(unstable("non-finite density rate", i, x[i].0));
        }
        let c = &sim.constants;
        let max_v2 = v
            .par_iter()
            .map(|v| v.0.length_squared())
            .reduce(|| 0.0, f64::max);
        let max_a2 = acc
            .par_iter()
            .map(|a| a.0.length_squared())
            .reduce(|| 0.0, f64::max);
        let max_rho = rho.par_iter().map(|r| r.0).reduce(|| 0.0, f64::max);
        let c_max = c.eos.sound_speed(max_rho.max(c.eos.rho0));
        let mut dt = self.params.courant * (c.h / (c_max + max_v2.sqrt()));
        if max_a2 > 0.0 {
            dt = dt.min(self.params.courant * (c.h / max_a2.sqrt()).sqrt());
        }
        dt = dt.min(self.params.max_dt);
        let first = *self.first_dt.get_or_insert(dt);
        if dt < self.params.collapse_fraction * first {
            let i = acc
                .iter()
                .enumerate()
                .max_by(|a, b| a.1 .0.length_squared().total_cmp(&b.1 .0.length_squared()));
            let i = i.map_or(0, |(i, _)| i);
            return Err(unstable(
                &format!("time step collapsed to {dt:.3e} s (first step {first:.3e} s)"),
                i,
                x[i].0,
            ));
        }
        // Land exactly on the end time.
        let remaining = sim.clock.end_time - sim.clock.time;
        if remaining < 1.5 * dt {
            dt = dt.min(remaining);
        }
        let kick = if sim.clock.step == 0 {
            0.5 * dt
        } else {
            0.5 * (sim.clock.dt + dt)
        };
        (
            &mut x[..],
            &mut v[..],
            &mut rho[..],
            &mut vh[..],
            &mut rh[..],
            acc,
            rate,
        )
            .into_par_iter()
            .for_each(|(x, v, rho, vh, rh, a, r)| {
                let (vhalf, rhalf) = if sim.clock.step == 0 {
                    (v.0, rho.0)
                } else {
                    (vh.0, rh.0)
                };
                vh.0 = vhalf + kick * a.0;
                rh.0 = rhalf + kick * r.0;
                x.0 += dt * vh.0;
                v.0 = vh.0 + 0.5 * dt * a.0;
                rho.0 = rh.0 + 0.5 * dt * r.0;
            });
        sim.clock.dt = dt;
        sim.clock.time += dt;
        sim.clock.step += 1;
        self.walls.at(sim.clock.time);
        if self.params.reflect_at_walls {
            let floor = if self.params.restore_density_on_reflection {
                sim.constants.eos.rho0
            } else {
                0.0
            };
            let reflected = self.reflect(floor, &mut x, &mut v, &mut vh, &mut rho, &mut rh);
            if reflected > 0 {
                *sim.diagnostics
                    .entry("wall_reflections".into())
                    .or_insert(0.0) += reflected as f64;
            }
        }
        self.check(sim, &x, &rho)
    }
}

impl Integrate {
    /// Non-finite state, particles outside the domain or through a wall, density out of
    /// bounds: the first offending particle (lowest index) is reported.
    fn check(&self, sim: &Sim, x: &[Position], rho: &[Density]) -> Result<(), StepError> {
        let (lo, hi) = sim.constants.domain;
        let rho0 = sim.constants.eos.rho0;
        let limit = self.params.density_limit;
        let bad = (0..x.len()).into_par_iter().find_first(|&i| {
            let p = x[i].0;
            !p.is_finite()
                || !rho[i].0.is_finite()
                || p.cmplt(lo).any()
                || p.cmpgt(hi).any()
                || (rho[i].0 / rho0 - 1.0).abs() > limit
                || self.crossed_wall(p).is_some()
        });
        let Some(i) = bad else { return Ok(()) };
        let p = x[i].0;
        let what = if !p.is_finite() || !rho[i].0.is_finite() {
            "non-finite position or density".to_string()
        } else if let Some(w) = self.crossed_wall(p) {
            format!("particle passed through wall `{w}`")
        } else if p.cmplt(lo).any() || p.cmpgt(hi).any() {
            "particle left the domain".to_string()
        } else {
            format!(
                "density {:.1} kg/m^3 is beyond rho_0 (1 +- {limit})",
                rho[i].0
            )
        };
        Err(unstable(&what, i, p))
    }

    /// Reflects particles that ended the step behind a wall; returns how many. With
    /// `restore_density_on_reflection`, `floor` (rho_0) is the reflected particle's
    /// least density; otherwise `floor` is 0 and densities are kept.
    fn reflect(
        &self,
        floor: f64,
        x: &mut [Position],
        v: &mut [Velocity],
        vh: &mut [HalfVelocity],
        rho: &mut [Density],
        rh: &mut [HalfDensity],
    ) -> usize {
        (x, v, vh, rho, rh)
            .into_par_iter()
            .map(|(x, v, vh, rho, rh)| {
                let mut hit = 0;
                for w in self.walls.now() {
                    let s = w.abscissa(x.0);
                    let d = w.distance(x.0);
                    if d < 0.0 && s > 0.0 && s < w.length() {
                        let n = w.normal();
                        let vw = w.velocity_at(x.0 - d * n);
                        x.0 -= 2.0 * d * n;
                        v.0 -= 2.0 * (v.0 - vw).dot(n).min(0.0) * n;
                        vh.0 -= 2.0 * (vh.0 - vw).dot(n).min(0.0) * n;
                        rho.0 = rho.0.max(floor);
                        rh.0 = rh.0.max(floor);
                        hit = 1;
                    }
                }
                hit
            })
            .sum()
    }

    /// The wall whose line the particle is behind while alongside the wall.
    fn crossed_wall(&self, p: DVec2) -> Option<&str> {
        self.walls
            .now()
            .iter()
            .find(|w: &&Wall| {
                let s = w.abscissa(p);
                w.distance(p) < 0.0 && s > 0.0 && s < w.length()
            })
            .map(|w| w.name.as_str())
    }
}

fn unstable(what: &str, i: usize, x: DVec2) -> StepError {
    StepError::Unstable {
        what: what.to_string(),
        particle: Some(i as u32),
        position: Some(x),
    }
}
