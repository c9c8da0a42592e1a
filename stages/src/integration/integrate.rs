//! Time integration: Monaghan's leapfrog with one force evaluation per step, and the
//! adaptive step dt = C min( h / (c_max + max|v|), sqrt(h / max|a|) ) (docs/physics.md,
//! "Time step"). It also watches for instability.
//!
//! Velocity and density are carried at half steps (`HalfVelocity`, `HalfDensity`):
//!   v^{n+1/2} = v^{n-1/2} + (dt_{n-1} + dt_n)/2 a^n      (v^{1/2} = v^0 + dt_0/2 a^0)
//!   x^{n+1}   = x^n + dt_n v^{n+1/2}
//! and the integer-time values the next force evaluation uses are predicted as
//! v^{n+1} = v^{n+1/2} + dt_n/2 a^n (likewise rho). Second order for a constant step.

use crate::vocab::GuardPower;
use crate::vocab::{DensityFloored, WallReflections};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{get_column, put_column, Dec, Enc};
use sph_core::components::{Acceleration, Density, DensityRate, Fluid, Mass, Position, Velocity};
use sph_core::contract::Access;
use sph_core::dim::Vector;
use sph_core::sim::Counter;
use sph_core::sim::{Clock, Sim, Tait};
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{BodyPose, Guarded, HalfDensity, HalfVelocity, WallPose, Walls};
use sph_core::world::{archetype, column, column_mut, ensure_component};
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
    /// Least density, as a fraction f of rho_0: after every step a fluid particle's
    /// density (and its half-step density) below f rho_0 is raised to f rho_0, and the
    /// particle-steps so raised are counted in the `density_floored` diagnostic (and the
    /// particle flagged `Guarded::FLOORED`, so probes report it apart). Meant
    /// with `Eos(min_pressure: 0)` and f < 1: every density below rho_0 then has zero
    /// pressure, so the floor changes no pressure, only the volume m/rho a thinned
    /// particle brings to the Shepard sums and the mean density of the viscosity. It
    /// stops spray from thinning without bound (the continuity equation rarefies a
    /// particle its neighbours move away from, and nothing pushes back on a pressureless
    /// particle); the density guard still catches a compression beyond
    /// rho_0 (1 + `density_limit`). Not part of the model (docs/physics.md, "Safeguards outside the model"). Default None: no floor.
    pub density_floor: Option<f64>,
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
            density_floor: None,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "integrate",
        "leapfrog time step with adaptive dt and stability checks",
        |p: Params| {
            let out = sph_core::ParamError::new;
            if !(p.courant > 0.0 && p.courant <= 1.0) {
                return Err(out("courant", p.courant, "0 < C <= 1 (0.2-0.3 usual)"));
            }
            if !(p.max_dt > 0.0 && p.max_dt.is_finite()) {
                return Err(out("max_dt", p.max_dt, "a number > 0"));
            }
            if !(p.collapse_fraction > 0.0 && p.collapse_fraction < 1.0) {
                return Err(out("collapse_fraction", p.collapse_fraction, "0 to 1"));
            }
            if !(p.density_limit > 0.0 && p.density_limit.is_finite()) {
                return Err(out(
                    "density_limit",
                    p.density_limit,
                    "a finite number > 0 (a large one, e.g. 1e9, leaves the guard off)",
                ));
            }
            if let Some(f) = p.density_floor {
                if !(f > 0.0 && f <= 1.0) {
                    return Err(out(
                        "density_floor",
                        f,
                        "a fraction of rho_0 with 0 < f <= 1 (below 1 with Eos(min_pressure: 0), e.g. 0.9)",
                    ));
                }
            }
            Ok(Integrate {
                params: p,
                first_dt: None,
                walls: Walls::default(),
                zero_a: Vec::new(),
                zero_r: Vec::new(),
            })
        },
    );
}

pub struct Integrate {
    params: Params,
    first_dt: Option<f64>,
    /// The walls where the world has them at the end of the step (the clock's advance
    /// moves them), re-read every step (a reused buffer).
    walls: Walls,
    /// Zero rates for a pipeline without forces or continuity.
    zero_a: Vec<Acceleration>,
    zero_r: Vec<DensityRate>,
}

impl Stage for Integrate {
    fn name(&self) -> &'static str {
        "integrate"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        ensure_component::<Fluid, HalfVelocity>(sim);
        ensure_component::<Fluid, HalfDensity>(sim);
        ensure_component::<Fluid, Guarded>(sim);
        Ok(())
    }

    /// The first step (the collapse reference), the half-step columns and the guard
    /// flags; the walls follow the clock.
    fn save_state(&mut self, sim: &Sim) -> Result<Vec<u8>, StepError> {
        let mut e = Enc::default();
        e.opt_f64(self.first_dt);
        let fluid = archetype::<Fluid>(&sim.world);
        put_column::<HalfVelocity>(&mut e, fluid);
        put_column::<HalfDensity>(&mut e, fluid);
        put_column::<Guarded>(&mut e, fluid);
        Ok(e.into_bytes())
    }

    fn load_state(&mut self, sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        self.first_dt = d.opt_f64()?;
        let fluid = archetype::<Fluid>(&sim.world);
        get_column::<HalfVelocity>(&mut d, fluid)?;
        get_column::<HalfDensity>(&mut d, fluid)?;
        get_column::<Guarded>(&mut d, fluid)?;
        d.end()
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let Some(fluid) = archetype::<Fluid>(&sim.world) else {
            sim.clock.time = sim.clock.end_time;
            return Ok(());
        };
        let n = fluid.len() as usize;
        // A pipeline without forces (or continuity) integrates with zero rates; the
        // zeros are kept between steps rather than allocated each step.
        let acc_col = fluid.get::<&Acceleration>();
        let rate_col = fluid.get::<&DensityRate>();
        if acc_col.is_none() && self.zero_a.len() != n {
            self.zero_a = vec![Acceleration::default(); n];
        }
        if rate_col.is_none() && self.zero_r.len() != n {
            self.zero_r = vec![DensityRate::default(); n];
        }
        let acc: &[Acceleration] = acc_col.as_deref().unwrap_or(&self.zero_a);
        let rate: &[DensityRate] = rate_col.as_deref().unwrap_or(&self.zero_r);
        let mut x = column_mut::<Position>(fluid)?;
        let mut v = column_mut::<Velocity>(fluid)?;
        let mut rho = column_mut::<Density>(fluid)?;
        let mut vh = column_mut::<HalfVelocity>(fluid)?;
        let mut rh = column_mut::<HalfDensity>(fluid)?;
        let mut guarded = column_mut::<Guarded>(fluid)?;
        let mass = column::<Mass>(fluid)?;

        let ext = tracing::info_span!("time_step").in_scope(|| Extremes::of(&v, acc, rate, &rho));
        if !ext.finite {
            let bad = |i: &usize| !(acc[*i].0.is_finite() && rate[*i].0.is_finite());
            let i = (0..acc.len()).find(bad).unwrap_or(0);
            let what = if !acc[i].0.is_finite() {
                "non-finite acceleration"
            } else {
                "non-finite density rate"
            };
            return Err(unstable(what, i, x[i].0));
        }
        let c = &sim.constants;
        let c_max = c.eos.sound_speed(ext.max_rho.max(c.eos.rho0));
        let mut dt = self.params.courant * (c.h / (c_max + ext.max_v2.sqrt()));
        if ext.max_a2 > 0.0 {
            dt = dt.min(self.params.courant * (c.h / ext.max_a2.sqrt()).sqrt());
        }
        dt = dt.min(self.params.max_dt);
        let first = *self.first_dt.get_or_insert(dt);
        if dt < self.params.collapse_fraction * first {
            let a2 = |i: usize| acc[i].0.length_squared();
            let i = (0..acc.len()).find(|&i| a2(i) == ext.max_a2).unwrap_or(0);
            return Err(unstable(
                &format!("time step collapsed to {dt:.3e} s (first step {first:.3e} s)"),
                i,
                x[i].0,
            ));
        }
        // Land exactly on the end time.
        dt = dt.min(sim.clock.end_time - sim.clock.time);
        let first_step = sim.clock.step == 0;
        let kick = if first_step {
            0.5 * dt
        } else {
            0.5 * (sim.clock.dt + dt)
        };
        // The clock advances, and the scene with it: the walls where they are at the
        // end of the step, which is where the particles are checked against them.
        sim.clock.advance(dt, &sim.world);
        self.walls.read(&sim.world);
        let floor = if self.params.restore_density_on_reflection {
            c.eos.rho0
        } else {
            0.0
        };
        let (lo, hi) = c.domain;
        let (rho0, limit) = (c.eos.rho0, self.params.density_limit);
        let reach = c.support();
        let least = self.params.density_floor.map(|f| f * rho0);
        let (eos, g) = (c.eos, c.gravity);
        let _span = tracing::info_span!("advance").entered();
        let step = Kick {
            first_step,
            kick,
            dt,
            reflect: self.params.reflect_at_walls,
            floor,
            reach,
            least,
            eos,
            g,
            lo,
            hi,
            // |rho/rho_0 - 1| <= limit, as a band (no division per particle).
            rho_band: (rho0 * (1.0 - limit), rho0 * (1.0 + limit)),
            walls: &self.walls,
        };
        // One pass in chunks of particles (a plain loop inside each, no call per
        // particle): kick, drift, reflect at the walls (at their end-of-step place),
        // raise densities to the floor, then check. The sums are of integers and the
        // bad index a minimum, so the outcome is the same for any thread count.
        let tally = (
            x.par_chunks_mut(ADVANCE_CHUNK),
            v.par_chunks_mut(ADVANCE_CHUNK),
            rho.par_chunks_mut(ADVANCE_CHUNK),
            vh.par_chunks_mut(ADVANCE_CHUNK),
            rh.par_chunks_mut(ADVANCE_CHUNK),
            guarded.par_chunks_mut(ADVANCE_CHUNK),
            acc.par_chunks(ADVANCE_CHUNK),
            rate.par_chunks(ADVANCE_CHUNK),
            mass.par_chunks(ADVANCE_CHUNK),
        )
            .into_par_iter()
            .enumerate()
            .map(|(c, (x, v, rho, vh, rh, guarded, a, r, m))| {
                let mut t = Tally::default();
                for k in 0..x.len() {
                    let (hit, raised, de, ok) = step.particle(
                        &mut x[k],
                        &mut v[k],
                        &mut rho[k],
                        &mut vh[k],
                        &mut rh[k],
                        &mut guarded[k],
                        a[k],
                        r[k],
                        m[k],
                    );
                    t.reflected += hit as usize;
                    t.floored += raised as usize;
                    t.energy = t.energy.saturating_add(de);
                    if !ok && t.bad.is_none() {
                        t.bad = Some(c * ADVANCE_CHUNK + k);
                    }
                }
                t
            })
            .reduce(Tally::default, Tally::merge);
        let Tally {
            reflected,
            floored,
            energy: guard_energy,
            bad,
        } = tally;
        if let Some(p) = sim.resources.get_mut::<GuardPower>() {
            p.power = guard_energy as f64 / FIXED_POINT / dt;
        }
        WallReflections::add(&mut sim.diagnostics, reflected as u64);
        DensityFloored::add(&mut sim.diagnostics, floored as u64);
        match bad {
            Some(i) => Err(self.diagnose(sim, i, x[i].0, rho[i].0)),
            None => Ok(()),
        }
    }

    /// Advances the fluid state and the clock (and with it the scene: the walls' and
    /// bodies' poses); integrates with zero rates when no stage writes them.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Position>()
            .reads::<Velocity>()
            .reads::<Density>()
            .reads::<Mass>()
            .reads::<WallPose>()
            .uses::<Acceleration>()
            .uses::<DensityRate>()
            .writes::<Clock>()
            .writes::<WallPose>()
            .writes::<BodyPose>()
            .writes::<Position>()
            .writes::<Velocity>()
            .writes::<Density>()
            .writes::<HalfVelocity>()
            .writes::<HalfDensity>()
            .writes::<Guarded>()
            .writes::<WallReflections>()
            .writes::<DensityFloored>()
    }
}

/// The step-size inputs, from one parallel pass; the rare diagnostics (which particle
/// is non-finite, which accelerates most) are looked up only when needed.
#[derive(Clone, Copy)]
struct Extremes {
    max_v2: f64,
    max_a2: f64,
    max_rho: f64,
    /// Every acceleration and density rate is finite.
    finite: bool,
}

impl Extremes {
    fn of(v: &[Velocity], a: &[Acceleration], r: &[DensityRate], rho: &[Density]) -> Self {
        let none = || Self {
            max_v2: 0.0,
            max_a2: 0.0,
            max_rho: 0.0,
            finite: true,
        };
        // max and && are order-independent: the same result for any thread count.
        // Chunks with a plain loop inside (no call per particle).
        const CHUNK: usize = 4096;
        (
            v.par_chunks(CHUNK),
            a.par_chunks(CHUNK),
            r.par_chunks(CHUNK),
            rho.par_chunks(CHUNK),
        )
            .into_par_iter()
            .map(|(v, a, r, rho)| {
                let mut e = none();
                for k in 0..v.len().min(a.len()).min(r.len()).min(rho.len()) {
                    e.max_v2 = e.max_v2.max(v[k].0.length_squared());
                    e.max_a2 = e.max_a2.max(a[k].0.length_squared());
                    e.max_rho = e.max_rho.max(rho[k].0);
                    e.finite &= a[k].0.is_finite() & r[k].0.is_finite();
                }
                e
            })
            .reduce(none, |p, q| Self {
                max_v2: p.max_v2.max(q.max_v2),
                max_a2: p.max_a2.max(q.max_a2),
                max_rho: p.max_rho.max(q.max_rho),
                finite: p.finite & q.finite,
            })
    }
}

/// Particles per chunk of the advance pass.
const ADVANCE_CHUNK: usize = 2048;

/// What the advance pass counts: reflections, floored particles, the guards' energy
/// (fixed point) and the lowest index that failed the end-of-step check.
#[derive(Default)]
struct Tally {
    reflected: usize,
    floored: usize,
    energy: i128,
    bad: Option<usize>,
}

impl Tally {
    fn merge(self, o: Self) -> Self {
        Self {
            reflected: self.reflected + o.reflected,
            floored: self.floored + o.floored,
            energy: self.energy.saturating_add(o.energy),
            bad: self.bad.into_iter().chain(o.bad).min(),
        }
    }
}

/// One step's constants for the per-particle update.
struct Kick<'a> {
    first_step: bool,
    kick: f64,
    dt: f64,
    reflect: bool,
    floor: f64,
    reach: f64,
    least: Option<f64>,
    eos: Tait,
    g: Vector,
    lo: Vector,
    hi: Vector,
    rho_band: (f64, f64),
    walls: &'a Walls,
}

impl Kick<'_> {
    /// Kick, drift, guards and check of one particle (the leapfrog of the module
    /// docs); returns (reflected, floored, the guards' energy in fixed point, passed
    /// the check).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn particle(
        &self,
        x: &mut Position,
        v: &mut Velocity,
        rho: &mut Density,
        vh: &mut HalfVelocity,
        rh: &mut HalfDensity,
        guarded: &mut Guarded,
        a: Acceleration,
        r: DensityRate,
        m: Mass,
    ) -> (bool, bool, i128, bool) {
        let (vhalf, rhalf) = if self.first_step {
            (v.0, rho.0)
        } else {
            (vh.0, rh.0)
        };
        let dt = self.dt;
        vh.0 = vhalf + self.kick * a.0;
        rh.0 = rhalf + self.kick * r.0;
        x.0 += dt * vh.0;
        v.0 = vh.0 + 0.5 * dt * a.0;
        rho.0 = rh.0 + 0.5 * dt * r.0;
        // A particle in front of every wall line (or far behind it) has crossed none
        // and needs no reflection; most take this way.
        let clear = self.walls.clear_of_all(x.0, self.reach);
        let before = (x.0, v.0, rho.0, vh.0, rh.0);
        let hit = self.reflect && !clear && {
            let hit = self
                .walls
                .reflect(self.reach, &mut x.0, [&mut v.0, &mut vh.0]);
            if hit {
                rho.0 = rho.0.max(self.floor);
                rh.0 = rh.0.max(self.floor);
            }
            hit
        };
        let raised = self
            .least
            .is_some_and(|least| raise_to_floor(least, rho, rh));
        // The energy a guard added: kinetic + potential + internal after it acted
        // minus before (a reflection off a moving wall changes the kinetic energy;
        // the floor and a restored density the internal one). The half-step velocity
        // and density are the state carried on (the integer-time ones are
        // predictions from them), so their changes are what the guard adds for good.
        let de = if hit || raised {
            let e = |x: Vector, v: Vector, rho: f64| {
                m.0 * (0.5 * v.length_squared() - self.g.dot(x) + self.eos.internal_energy(rho))
            };
            let (v1, rho1) = (before.1 + (vh.0 - before.3), before.2 + (rh.0 - before.4));
            fixed_point(e(x.0, v1, rho1) - e(before.0, before.1, before.2))
        } else {
            0
        };
        guarded.0 |= ((hit as u8) * Guarded::REFLECTED) | ((raised as u8) * Guarded::FLOORED);
        let p = x.0;
        let ok = p.is_finite()
            && rho.0 >= self.rho_band.0
            && rho.0 <= self.rho_band.1
            && p.cmpge(self.lo).all()
            && p.cmple(self.hi).all()
            // A reflection pass that bounced nothing has already found no crossing.
            && (clear || (self.reflect && !hit) || self.walls.crossed(p, self.reach).is_none());
        (hit, raised, de, ok)
    }
}

impl Integrate {
    /// Why particle `i` (at `p`, density `r`) failed the end-of-step check.
    fn diagnose(&self, sim: &Sim, i: usize, p: Vector, r: f64) -> StepError {
        let (lo, hi) = sim.constants.domain;
        let limit = self.params.density_limit;
        let what = if !p.is_finite() || !r.is_finite() {
            "non-finite position or density".to_string()
        } else if let Some(w) = self.walls.crossed(p, sim.constants.support()) {
            format!(
                "particle passed through {}",
                self.walls.describe(&sim.world, w)
            )
        } else if p.cmplt(lo).any() || p.cmpgt(hi).any() {
            "particle left the domain".to_string()
        } else {
            format!("density {r:.1} kg/m^3 is beyond rho_0 (1 +- {limit})")
        };
        unstable(&what, i, p)
    }
}

/// Units per joule of [`fixed_point`].
const FIXED_POINT: f64 = (1u64 << 60) as f64;

/// An energy [J/m] as a fixed-point integer (2^-60 J/m, about 1e-18): integer sums do not
/// depend on the order of the terms, so the guards' energy, summed in whatever order the
/// parallel reduction takes, is the same for any thread count. Saturates beyond about
/// 1e20 J/m; a non-finite energy (a particle the check then reports) counts as 0.
fn fixed_point(e: f64) -> i128 {
    if e.is_finite() {
        (e * FIXED_POINT).round() as i128
    } else {
        0
    }
}

/// Raises a density (and the half-step density) below `least` to it; returns whether
/// it did. A non-finite density is left as it is, for the check to report.
#[inline]
fn raise_to_floor(least: f64, rho: &mut Density, rh: &mut HalfDensity) -> bool {
    let below = |r: f64| r > f64::NEG_INFINITY && r < least;
    let low = below(rho.0) || below(rh.0);
    if below(rho.0) {
        rho.0 = least;
    }
    if below(rh.0) {
        rh.0 = least;
    }
    low
}

fn unstable(what: &str, i: usize, x: Vector) -> StepError {
    StepError::Unstable {
        what: what.to_string(),
        particle: Some(i as u32),
        position: Some(x),
    }
}

// 2D set-ups; the 3D build's own tests are in `tests3d` modules.
#[cfg(all(test, not(feature = "dim3")))]
mod tests {
    use super::*;
    use crate::testing::{closed_box, fluid_column, pipeline, sim};
    use glam::DVec2;
    use sph_core::sim::Counter;

    /// One fluid particle's state: position, velocity, density, and the rates the
    /// force and continuity stages would have written.
    #[derive(Clone, Copy)]
    struct Particle {
        x: DVec2,
        v: DVec2,
        rho: f64,
        a: DVec2,
        r: f64,
    }

    fn at(x: (f64, f64), v: (f64, f64)) -> Particle {
        Particle {
            x: DVec2::new(x.0, x.1),
            v: DVec2::new(v.0, v.1),
            rho: 1000.0,
            a: DVec2::ZERO,
            r: 0.0,
        }
    }

    const MASS: f64 = 0.1;

    /// A sim with `particles` (mass 0.1 kg/m, with their rate columns) and, if `boxed`,
    /// the walls of a closed 1 m x 1 m box at rest from the origin; the integrator
    /// built from `params` and set up on it.
    fn world(particles: &[Particle], boxed: bool, params: &str) -> (Sim, Box<dyn Stage>) {
        let mut world = hecs::World::new();
        if boxed {
            closed_box(&mut world, 1.0, 1.0);
        }
        for p in particles {
            world.spawn((
                Fluid,
                Position(p.x),
                Velocity(p.v),
                Density(p.rho),
                Mass(MASS),
                Acceleration(p.a),
                DensityRate(p.r),
            ));
        }
        let mut sim = sim(world);
        sim.clock.end_time = 10.0;
        let stage = pipeline(&mut sim, &[("integrate", params)]).remove(0);
        (sim, stage)
    }

    fn positions(sim: &Sim) -> Vec<DVec2> {
        fluid_column(sim, |p: &Position| p.0)
    }
    fn velocities(sim: &Sim) -> Vec<DVec2> {
        fluid_column(sim, |v: &Velocity| v.0)
    }
    fn densities(sim: &Sim) -> Vec<f64> {
        fluid_column(sim, |r: &Density| r.0)
    }
    fn guards(sim: &Sim) -> Vec<u8> {
        fluid_column(sim, |g: &Guarded| g.0)
    }

    /// The failure of one step: what, which particle, where.
    fn failure(sim: &mut Sim, stage: &mut Box<dyn Stage>) -> (String, Option<u32>) {
        match stage.run(sim) {
            Err(StepError::Unstable { what, particle, .. }) => (what, particle),
            other => panic!("expected an instability, got {other:?}"),
        }
    }

    /// The leapfrog of the module docs integrates a constant acceleration and density
    /// rate exactly, whatever the steps: x = x0 + v0 t + a t^2/2, v = v0 + a t,
    /// rho = rho0 + r t. The steps here vary (the density, and so the sound speed,
    /// rises), which checks the kick (dt_{n-1} + dt_n)/2 between half steps. Bound:
    /// round-off of 60 steps (1e-12 relative).
    #[test]
    fn the_leapfrog_is_exact_under_constant_rates() {
        let mut ps = [
            at((0.1, 0.2), (0.5, -0.3)),
            at((-0.2, 0.4), (-0.1, 0.2)),
            at((0.3, -0.1), (0.0, 0.0)),
        ];
        for (k, p) in ps.iter_mut().enumerate() {
            p.a = DVec2::new(0.3 - 0.2 * k as f64, -9.81 + k as f64);
            p.r = 300.0 + 100.0 * k as f64;
            p.rho = 1000.0 + k as f64;
        }
        let (mut sim, mut stage) = world(&ps, false, "()");
        let mut steps = Vec::new();
        for _ in 0..60 {
            stage.run(&mut sim).unwrap();
            steps.push(sim.clock.dt);
        }
        assert!(steps[59] < 0.99 * steps[0], "the steps vary: {steps:?}");
        let t = sim.clock.time;
        assert_eq!(sim.clock.step, 60);
        assert!((t - steps.iter().sum::<f64>()).abs() < 1e-15);
        let (x, v, rho) = (positions(&sim), velocities(&sim), densities(&sim));
        for (k, p) in ps.iter().enumerate() {
            let close = |a: DVec2, b: DVec2| (a - b).length() <= 1e-12 * (1.0 + b.length());
            let xe = p.x + p.v * t + 0.5 * p.a * t * t;
            assert!(close(x[k], xe), "x {k}: {} against {xe}", x[k]);
            let ve = p.v + p.a * t;
            assert!(close(v[k], ve), "v {k}: {} against {ve}", v[k]);
            let re = p.rho + p.r * t;
            assert!(
                (rho[k] - re).abs() <= 1e-12 * re,
                "rho {k}: {} against {re}",
                rho[k]
            );
        }
    }

    /// Without force or continuity stages the particles drift at their velocities.
    #[test]
    fn without_rates_the_particles_drift() {
        let mut world = hecs::World::new();
        world.spawn((
            Fluid,
            Position(DVec2::new(0.1, 0.2)),
            Velocity(DVec2::new(0.5, -0.25)),
            Density(1000.0),
            Mass(MASS),
        ));
        let mut sim = sim(world);
        sim.clock.end_time = 1.0;
        let mut stage = pipeline(&mut sim, &[("integrate", "()")]).remove(0);
        for _ in 0..3 {
            stage.run(&mut sim).unwrap();
        }
        let t = sim.clock.time;
        assert!(t > 0.0);
        let xe = DVec2::new(0.1 + 0.5 * t, 0.2 - 0.25 * t);
        assert!((positions(&sim)[0] - xe).length() < 1e-15);
        assert_eq!(densities(&sim)[0], 1000.0);
    }

    /// dt = C min( h / (c_max + max|v|), sqrt(h / max|a|) ), at most `max_dt`, with
    /// c_max the sound speed at the largest density (at least rho_0): each limit in
    /// turn, the extremes held by the last of 5,000 particles (beyond the first
    /// parallel chunk). The test sim: h 0.013 m, c_0 20 m/s, gamma 7.
    #[test]
    fn the_step_is_the_smallest_of_its_limits() {
        let (h, c0, courant) = (0.013, 20.0, 0.3);
        // c(rho) = c_0 (rho/rho_0)^((gamma-1)/2) for Tait (c^2 = dp/drho).
        let c = |rho: f64| c0 * (rho / 1000.0f64).powf(3.0);
        let step = |v: f64, a: f64, rho: f64, quiet_rho: f64, max_dt: f64| {
            let mut ps = vec![at((0.0, 0.0), (0.01, 0.0)); 5000];
            for p in &mut ps {
                p.a = DVec2::new(0.0, -1.0);
                p.rho = quiet_rho;
            }
            ps[4500].v = DVec2::new(0.6 * v, -0.8 * v);
            ps[4500].a = DVec2::new(-0.6 * a, 0.8 * a);
            ps[4500].rho = rho;
            let params = format!("(courant: {courant}, max_dt: {max_dt})");
            let (mut sim, mut stage) = world(&ps, false, &params);
            stage.run(&mut sim).unwrap();
            sim.clock.dt
        };
        let rel = |a: f64, b: f64| ((a - b) / b).abs();
        // The sound-speed limit, at a density above rho_0.
        let dt = step(2.0, 1.0, 1020.0, 1000.0, 1.0);
        let expected = courant * h / (c(1020.0) + 2.0);
        assert!(rel(dt, expected) < 1e-14, "{dt} against {expected}");
        // Densities below rho_0 take c_0.
        let dt = step(2.0, 1.0, 990.0, 995.0, 1.0);
        let expected = courant * h / (c0 + 2.0);
        assert!(rel(dt, expected) < 1e-14, "{dt} against {expected}");
        // The acceleration limit.
        let dt = step(2.0, 5e5, 1000.0, 1000.0, 1.0);
        let expected = courant * (h / 5e5f64).sqrt();
        assert!(rel(dt, expected) < 1e-14, "{dt} against {expected}");
        // The largest step.
        let dt = step(2.0, 1.0, 1000.0, 1000.0, 1e-5);
        assert_eq!(dt, 1e-5);
    }

    /// The run lands on the end time exactly: the step is min(dt, remaining), so a
    /// remainder below a step is taken whole, and 1.2 steps left are a full step and
    /// then the rest.
    #[test]
    fn the_last_step_lands_on_the_end_time() {
        let ps = [at((0.0, 0.0), (1.0, 0.0))];
        let (mut sim, mut stage) = world(&ps, false, "()");
        stage.run(&mut sim).unwrap();
        let dt = sim.clock.dt;
        // Less than a step left: it is taken whole.
        sim.clock.end_time = sim.clock.time + 0.7 * dt;
        let end = sim.clock.end_time;
        stage.run(&mut sim).unwrap();
        assert_eq!(sim.clock.time, end);
        // 1.2 steps left: a full step, then the 0.2.
        sim.clock.end_time = sim.clock.time + 1.2 * dt;
        let end = sim.clock.end_time;
        stage.run(&mut sim).unwrap();
        assert!(
            (sim.clock.dt - dt).abs() < 1e-12 * dt,
            "{} against {dt}",
            sim.clock.dt
        );
        stage.run(&mut sim).unwrap();
        assert_eq!(sim.clock.time, end);
        // Two steps left: untouched.
        sim.clock.end_time = sim.clock.time + 2.0 * dt;
        stage.run(&mut sim).unwrap();
        assert!((sim.clock.dt - dt).abs() < 1e-12 * dt);
    }

    /// A step below `collapse_fraction` of the first stops the run, naming the particle
    /// that accelerates most.
    #[test]
    fn a_collapsing_step_stops_the_run() {
        let mut ps = vec![at((0.0, 0.0), (0.0, 0.0)); 4];
        for p in &mut ps {
            p.a = DVec2::new(0.0, -9.81);
        }
        let (mut sim, mut stage) = world(&ps, false, "(collapse_fraction: 0.01)");
        stage.run(&mut sim).unwrap();
        let first = sim.clock.dt;
        // The first step is the sound-speed limit C h / c_0 = 1.6e-4 s; an acceleration
        // of 1e10 m/s^2 allows C sqrt(h / a) = 2.9e-7 s, 0.18 % of it.
        set_acceleration(&mut sim, 2, DVec2::new(0.0, -1e10));
        let (what, particle) = failure(&mut sim, &mut stage);
        assert!(what.starts_with("time step collapsed"), "{what}");
        assert!(what.contains(&format!("{first:.3e}")), "{what}");
        assert_eq!(particle, Some(2));
        // 1e8 m/s^2: 2.9e-6 s, 1.8 %, above the fraction.
        let (mut sim, mut stage) = world(&ps, false, "(collapse_fraction: 0.01)");
        stage.run(&mut sim).unwrap();
        set_acceleration(&mut sim, 2, DVec2::new(0.0, -1e8));
        stage.run(&mut sim).unwrap();
        assert!(sim.clock.dt < 0.02 * first);
    }

    fn set_acceleration(sim: &mut Sim, i: usize, a: DVec2) {
        let fluid = archetype::<Fluid>(&sim.world).unwrap();
        column_mut::<Acceleration>(fluid).unwrap()[i].0 = a;
    }

    /// A non-finite rate stops the run before anything moves, naming the rate and the
    /// particle.
    #[test]
    fn a_non_finite_rate_stops_the_run() {
        let mut ps = vec![at((0.0, 0.0), (0.1, 0.0)); 5];
        ps[3].a = DVec2::new(f64::NAN, 0.0);
        let (mut sim, mut stage) = world(&ps, false, "()");
        assert_eq!(
            failure(&mut sim, &mut stage),
            ("non-finite acceleration".to_string(), Some(3))
        );
        assert_eq!(positions(&sim)[0], DVec2::ZERO);
        assert_eq!(sim.clock.step, 0);
        let mut ps = vec![at((0.0, 0.0), (0.1, 0.0)); 5];
        ps[1].r = f64::INFINITY;
        let (mut sim, mut stage) = world(&ps, false, "()");
        assert_eq!(
            failure(&mut sim, &mut stage),
            ("non-finite density rate".to_string(), Some(1))
        );
    }

    /// The end-of-step check: a density outside rho_0 (1 +- limit), a particle out of
    /// the domain, a NaN density, one behind a wall with reflection off; the lowest
    /// failing index is named, across the parallel chunks.
    #[test]
    fn the_end_of_step_check_names_what_failed() {
        // Density: 1,000 +- 50 % (the default limit) is allowed; the band's ends.
        let mut ps = vec![at((0.5, 0.5), (0.0, 0.0)); 4200];
        ps[3000].rho = 1501.0;
        ps[4100].rho = 1502.0;
        let (mut sim, mut stage) = world(&ps, false, "()");
        let (what, particle) = failure(&mut sim, &mut stage);
        assert_eq!(what, "density 1501.0 kg/m^3 is beyond rho_0 (1 +- 0.5)");
        assert_eq!(particle, Some(3000));
        for (rho, ok) in [(1499.0, true), (501.0, true), (499.0, false)] {
            let mut ps = vec![at((0.5, 0.5), (0.0, 0.0)); 3];
            ps[1].rho = rho;
            let (mut sim, mut stage) = world(&ps, false, "()");
            assert_eq!(stage.run(&mut sim).is_ok(), ok, "rho {rho}");
        }
        let (mut sim, mut stage) = world(&ps, false, "(density_limit: 0.6)");
        stage.run(&mut sim).unwrap();
        // The domain (the test sim's is -1 to 1 m on both axes).
        for (dx, dy) in [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)] {
            let mut ps = vec![at((0.0, 0.0), (0.0, 0.0)); 3];
            // 1.3 cm in the step C h / (c_0 + |v|): out through the domain's side.
            ps[1] = at((0.999 * dx, 0.999 * dy), (1000.0 * dx, 1000.0 * dy));
            let (mut sim, mut stage) = world(&ps, false, "(courant: 1.0)");
            let v = (dx, dy);
            assert_eq!(
                failure(&mut sim, &mut stage),
                ("particle left the domain".to_string(), Some(1)),
                "{v:?}"
            );
        }
        // A non-finite density at a finite place.
        let mut ps = vec![at((0.5, 0.5), (0.0, 0.0)); 3];
        ps[2].rho = f64::NAN;
        let (mut sim, mut stage) = world(&ps, false, "()");
        assert_eq!(
            failure(&mut sim, &mut stage),
            ("non-finite position or density".to_string(), Some(2))
        );
        // A wall, with reflection off: through the floor.
        let ps = [at((0.5, 0.5), (0.0, 0.0)), at((0.5, 0.0002), (0.2, -3.0))];
        let (mut sim, mut stage) = world(&ps, true, "(reflect_at_walls: false)");
        assert_eq!(
            failure(&mut sim, &mut stage),
            ("particle passed through wall `w0`".to_string(), Some(1))
        );
    }

    /// A particle behind a wall at the end of its step is mirrored back across it, its
    /// velocities' normal parts (relative to the wall's) reversed; counted once per
    /// particle, flagged, its energy change (the potential energy of the mirrored
    /// height, m g 2|y|, and the kinetic energy a moving wall gives) reported as the
    /// guards' power; with `restore_density_on_reflection` its density is raised to
    /// rho_0. Three such particles in three parallel chunks.
    #[test]
    fn a_particle_behind_a_wall_is_reflected_and_counted() {
        // The box at rest, and moving up at 1 m/s (at its rest place this instant):
        // the normal velocity is reversed relative to the wall's, -3 - 1 to 4 + 1.
        for (restore, lift) in [(false, 0.0), (true, 0.0), (false, 1.0)] {
            let mut ps = vec![at((0.5, 0.5), (0.0, 0.0)); 4500];
            for k in [10, 2100, 4400] {
                ps[k] = at((0.5, 0.0002), (0.2, -3.0));
                ps[k].rho = 990.0;
            }
            let params = format!("(restore_density_on_reflection: {restore})");
            let (mut sim, mut stage) = world(&ps, true, &params);
            for wall in sim.world.query_mut::<&mut WallPose>() {
                wall.body.state.velocity = DVec2::new(0.0, lift);
            }
            sim.resources.insert(GuardPower { power: 0.0 });
            stage.run(&mut sim).unwrap();
            let dt = sim.clock.dt;
            let (x, v, rho, g) = (
                positions(&sim),
                velocities(&sim),
                densities(&sim),
                guards(&sim),
            );
            let behind = 0.0002 - 3.0 * dt;
            assert!(behind < 0.0);
            for k in [10, 2100, 4400] {
                let xe = DVec2::new(0.5 + 0.2 * dt, -behind);
                assert!((x[k] - xe).length() < 1e-15, "{} against {xe}", x[k]);
                let ve = DVec2::new(0.2, 3.0 + 2.0 * lift);
                assert!((v[k] - ve).length() < 1e-12, "{} against {ve}", v[k]);
                assert_eq!(rho[k], if restore { 1000.0 } else { 990.0 });
                assert_eq!(g[k], Guarded::REFLECTED);
            }
            assert_eq!(g[11], 0);
            assert_eq!(WallReflections::counted(&sim.diagnostics), 3.0);
            // Potential m g 2|y| each, the kinetic energy the moving wall gave, and
            // with the density restored the internal energy m (e(1000) - e(990)) =
            // -m e(990).
            let kinetic = 0.5 * ((3.0 + 2.0 * lift).powi(2) - 9.0);
            let mut de = 3.0 * MASS * (9.81 * 2.0 * (-behind) + kinetic);
            if restore {
                de -= 3.0 * MASS * internal_energy(990.0);
            }
            let power = sim.resources.get::<GuardPower>().unwrap().power;
            assert!(
                (power - de / dt).abs() < 1e-9 * (de / dt).abs(),
                "{power} against {}",
                de / dt
            );
        }
    }

    /// Tait's specific internal energy, e = integral from rho_0 to rho of p/rho^2, for
    /// the test sim's water (B = rho_0 c_0^2 / gamma).
    fn internal_energy(rho: f64) -> f64 {
        let (r0, g) = (1000.0f64, 7.0);
        let b = r0 * 400.0 / g;
        b * (((rho / r0).powf(g - 1.0) - 1.0) / ((g - 1.0) * r0) + 1.0 / rho - 1.0 / r0)
    }

    /// The density floor raises a density below f rho_0 (and its half step) to it,
    /// counts and flags the particle, and reports the internal energy it added.
    #[test]
    fn the_density_floor_raises_counts_and_reports() {
        let mut ps = vec![at((0.5, 0.5), (0.0, 0.0)); 3];
        ps[1].rho = 850.0;
        ps[2].rho = 900.0; // at the floor: untouched
        let (mut sim, mut stage) = world(&ps, false, "(density_floor: Some(0.9))");
        sim.resources.insert(GuardPower { power: 0.0 });
        stage.run(&mut sim).unwrap();
        let dt = sim.clock.dt;
        assert_eq!(densities(&sim), vec![1000.0, 900.0, 900.0]);
        assert_eq!(guards(&sim), vec![0, Guarded::FLOORED, 0]);
        assert_eq!(DensityFloored::counted(&sim.diagnostics), 1.0);
        let de = MASS * (internal_energy(900.0) - internal_energy(850.0));
        let power = sim.resources.get::<GuardPower>().unwrap().power;
        // Raising a density below rho_0 lowers e (e is least at rho_0).
        assert!(de < 0.0);
        assert!(
            (power - de / dt).abs() < 1e-9 * (de / dt).abs(),
            "{power} against {}",
            de / dt
        );
        // The half step was raised too: with no rate the next step keeps 900.
        stage.run(&mut sim).unwrap();
        assert_eq!(densities(&sim)[1], 900.0);
        assert_eq!(DensityFloored::counted(&sim.diagnostics), 1.0);
        // raise_to_floor on its own: the half-step alone below, and a NaN left for the
        // check.
        let (mut rho, mut rh) = (Density(950.0), HalfDensity(890.0));
        assert!(raise_to_floor(900.0, &mut rho, &mut rh));
        assert_eq!((rho.0, rh.0), (950.0, 900.0));
        let (mut rho, mut rh) = (Density(f64::NAN), HalfDensity(950.0));
        assert!(!raise_to_floor(900.0, &mut rho, &mut rh));
        assert!(rho.0.is_nan());
        let (mut rho, mut rh) = (Density(f64::NEG_INFINITY), HalfDensity(950.0));
        assert!(!raise_to_floor(900.0, &mut rho, &mut rh));
    }

    /// The fixed-point energies: rounding to 2^-60 J/m, and 0 for a non-finite energy.
    #[test]
    fn energies_in_fixed_point() {
        assert_eq!(fixed_point(1.0), 1i128 << 60);
        assert_eq!(fixed_point(-0.5), -(1i128 << 59));
        assert_eq!(fixed_point(1.4 / FIXED_POINT), 1);
        assert_eq!(fixed_point(1.6 / FIXED_POINT), 2);
        assert_eq!(fixed_point(f64::NAN), 0);
        assert_eq!(fixed_point(f64::INFINITY), 0);
    }

    /// A checkpoint after 3 steps resumes bit-identically with a new integrator, the
    /// half-step columns and guard flags cleared first (they come from the state).
    #[test]
    fn a_checkpoint_resumes_bit_identically() {
        let mut ps = vec![at((0.5, 0.5), (0.1, -0.2)); 3];
        for (k, p) in ps.iter_mut().enumerate() {
            p.a = DVec2::new(0.1 * k as f64, -9.81);
            p.r = 50.0 * k as f64;
            p.rho = 860.0 + 10.0 * k as f64;
        }
        let params = "(density_floor: Some(0.88))";
        let (mut whole, mut a) = world(&ps, false, params);
        for _ in 0..5 {
            a.run(&mut whole).unwrap();
        }
        let (mut sim, mut b) = world(&ps, false, params);
        for _ in 0..3 {
            b.run(&mut sim).unwrap();
        }
        let state = b.save_state(&sim).unwrap();
        {
            let fluid = archetype::<Fluid>(&sim.world).unwrap();
            for h in column_mut::<HalfVelocity>(fluid).unwrap().iter_mut() {
                h.0 = DVec2::ZERO;
            }
            for h in column_mut::<HalfDensity>(fluid).unwrap().iter_mut() {
                h.0 = 0.0;
            }
            for g in column_mut::<Guarded>(fluid).unwrap().iter_mut() {
                g.0 = 0;
            }
        }
        let mut c = pipeline(&mut sim, &[("integrate", params)]).remove(0);
        c.load_state(&mut sim, &state).unwrap();
        for _ in 0..2 {
            c.run(&mut sim).unwrap();
        }
        assert_eq!(sim.clock.time.to_bits(), whole.clock.time.to_bits());
        assert_eq!(positions(&sim), positions(&whole));
        assert_eq!(velocities(&sim), velocities(&whole));
        assert_eq!(densities(&sim), densities(&whole));
        assert_eq!(guards(&sim), guards(&whole));
        assert_eq!(guards(&sim)[0], Guarded::FLOORED);
        // The first step is part of the state: the collapse check measures from it.
        let mut d = pipeline(&mut sim, &[("integrate", "(collapse_fraction: 0.5)")]).remove(0);
        d.load_state(&mut sim, &state).unwrap();
        // C sqrt(h / a) = 9e-6 s at 1e7 m/s^2, below half the first step (1.6e-4 s).
        set_acceleration(&mut sim, 1, DVec2::new(0.0, -1e7));
        assert!(failure(&mut sim, &mut d)
            .0
            .starts_with("time step collapsed"));
    }

    /// The integrator advances the clock, and says so (the contract check allows one
    /// such stage per pipeline).
    #[test]
    fn the_integrator_declares_the_clock() {
        assert!(crate::testing::stage("integrate", "()")
            .access()
            .writes_clock());
    }

    /// A world without fluid has nothing to integrate: the run ends.
    #[test]
    fn without_fluid_the_run_ends() {
        let (mut sim, mut stage) = world(&[], true, "()");
        sim.clock.end_time = 2.5;
        stage.run(&mut sim).unwrap();
        assert_eq!(sim.clock.time, 2.5);
    }

    /// The parameters' ranges, each end.
    #[test]
    fn parameters_out_of_range_are_refused() {
        let refused = |params: &str, field: &str| {
            let e = crate::testing::built("integrate", params).err();
            let e = e.unwrap_or_else(|| panic!("{params} was accepted"));
            assert!(e.contains(field), "{params}: {e}");
        };
        for bad in ["0.0", "-0.1", "1.01", "NaN"] {
            refused(&format!("(courant: {bad})"), "courant");
        }
        crate::testing::stage("integrate", "(courant: 1.0)");
        for bad in ["0.0", "-1e-3", "inf", "NaN"] {
            refused(&format!("(max_dt: {bad})"), "max_dt");
        }
        for bad in ["0.0", "1.0", "NaN"] {
            refused(&format!("(collapse_fraction: {bad})"), "collapse_fraction");
        }
        for bad in ["0.0", "inf", "NaN"] {
            refused(&format!("(density_limit: {bad})"), "density_limit");
        }
        for bad in ["0.0", "1.01", "NaN"] {
            refused(&format!("(density_floor: Some({bad}))"), "density_floor");
        }
        crate::testing::stage("integrate", "(density_floor: Some(1.0))");
    }
}
