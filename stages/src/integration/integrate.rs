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
use glam::DVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{get_column, put_column, Dec, Enc};
use sph_core::components::{Acceleration, Density, DensityRate, Fluid, Mass, Position, Velocity};
use sph_core::contract::Access;
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
        let remaining = sim.clock.end_time - sim.clock.time;
        if remaining < 1.5 * dt {
            dt = dt.min(remaining);
        }
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
    g: DVec2,
    lo: DVec2,
    hi: DVec2,
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
        // A particle in front of every wall line has crossed none and needs no
        // reflection (both tests need it behind a line); most take this way.
        let clear = self.walls.in_front_of_all(x.0);
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
            let e = |x: DVec2, v: DVec2, rho: f64| {
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
            && (clear || self.walls.crossed(p, self.reach).is_none());
        (hit, raised, de, ok)
    }
}

impl Integrate {
    /// Why particle `i` (at `p`, density `r`) failed the end-of-step check.
    fn diagnose(&self, sim: &Sim, i: usize, p: DVec2, r: f64) -> StepError {
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

fn unstable(what: &str, i: usize, x: DVec2) -> StepError {
    StepError::Unstable {
        what: what.to_string(),
        particle: Some(i as u32),
        position: Some(x),
    }
}
