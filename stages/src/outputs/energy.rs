//! Energy budget (docs/physics.md, "Energy budget"): kinetic sum m|v|^2/2, potential
//! -sum m g.x (zero at y = 0), internal sum m e(rho) with e the Tait internal energy;
//! the energy dissipated (`viscous`, the artificial and laminar viscosities) and the work
//! done on the fluid (`wall_work`, by the walls through the ghosts, moving or not;
//! `diffusion`, the internal energy a density-diffusion term adds or takes; `guards`,
//! what the wall reflections and the density floor add), each
//! the time integral of the rate the forces stage reported; `total` = kinetic +
//! potential + internal + dissipated, and `closure_error` = total - (total at t = 0 +
//! work in), which is zero for an energy-conserving scheme up to the time-integration
//! error (the guards, the density filter and the pressure floor show up in it).
//! Written to `energy.csv` and plotted. Place it after Integrate: it integrates the
//! rates the forces stage reported over the step just taken.
//!
//! The accumulated entries are a table ([`BUDGET`]): a new dissipation or work figure
//! is one more row, with the resource its rate comes from.

use crate::vocab::{DiffusionPower, GuardPower, ViscousDissipation, WallPower};
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc, Resuming};
use sph_core::components::{Density, Mass, Position, Velocity};
use sph_core::contract::Access;
use sph_core::series::SeriesWriter;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::world::{sum_fixed, Particles};
use sph_core::StageRegistry;
use sph_output::SeriesPlot;

/// Whether an accumulated entry is energy the fluid lost or work done on it.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// Energy taken out of kinetic + potential + internal (counted into `total`).
    Dissipated,
    /// Work done on the fluid from outside (subtracted in `closure_error`).
    WorkIn,
}

/// One time-integrated entry of the budget: its column, its kind, and where its rate
/// comes from this step.
struct Entry {
    column: &'static str,
    kind: Kind,
    /// The rate [W per metre of depth] a stage before Energy reported this step.
    rate: fn(&Sim) -> f64,
    /// Inserts the resource that asks the reporting stage for the rate.
    ask: fn(&mut Sim),
}

/// The accumulated entries, in column order (and checkpoint order).
const BUDGET: [Entry; 4] = [
    Entry {
        column: "viscous",
        kind: Kind::Dissipated,
        rate: |sim| {
            sim.resources
                .get::<ViscousDissipation>()
                .map_or(0.0, |d| d.power)
        },
        ask: |sim| sim.resources.insert(ViscousDissipation::default()),
    },
    Entry {
        column: "wall_work",
        kind: Kind::WorkIn,
        rate: |sim| sim.resources.get::<WallPower>().map_or(0.0, |w| w.power),
        ask: |sim| sim.resources.insert(WallPower::default()),
    },
    Entry {
        // The internal energy a density diffusion adds (negative: takes out),
        // sum_i m_i (p_i/rho_i^2) D_i: the diffusion is not a pair force, so nothing
        // else balances it.
        column: "diffusion",
        kind: Kind::WorkIn,
        rate: |sim| {
            sim.resources
                .get::<DiffusionPower>()
                .map_or(0.0, |d| d.power)
        },
        ask: |sim| sim.resources.insert(DiffusionPower::default()),
    },
    Entry {
        // What the safeguards outside the model add: wall reflections (off a moving
        // wall they change the kinetic energy), the density floor and densities
        // restored on reflection (the internal energy); `Integrate` reports it.
        column: "guards",
        kind: Kind::WorkIn,
        rate: |sim| sim.resources.get::<GuardPower>().map_or(0.0, |g| g.power),
        ask: |sim| sim.resources.insert(GuardPower::default()),
    },
];

/// The stored energies, in column order.
const STORED: [&str; 3] = ["kinetic", "potential", "internal"];

/// The columns of energy.csv after `time`.
fn columns() -> Vec<&'static str> {
    let mut c = STORED.to_vec();
    c.extend(BUDGET.iter().map(|e| e.column));
    c.extend(["total", "closure_error"]);
    c
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Sampling interval [s]; 0 samples every step. Default 0.01.
    pub interval: f64,
    /// Draw energy.png at the end. Default true.
    pub plots: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            interval: 0.01,
            plots: true,
        }
    }
}

pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        "energy",
        "kinetic, potential, internal, dissipated energy and wall work to energy.csv",
        |p: Params| {
            if !(p.interval >= 0.0 && p.interval.is_finite()) {
                return Err(sph_core::ParamError::new(
                    "interval",
                    p.interval,
                    "seconds >= 0",
                ));
            }
            Ok(Energy {
                params: p,
                accumulated: [0.0; BUDGET.len()],
                initial: 0.0,
                next: 0.0,
                out: None,
            })
        },
    );
}

pub struct Energy {
    params: Params,
    /// The time integral of each [`BUDGET`] entry's rate so far [J/m].
    accumulated: [f64; BUDGET.len()],
    /// `total` at t = 0 [J/m].
    initial: f64,
    next: f64,
    out: Option<SeriesWriter>,
}

/// The four energies per metre of depth [J/m].
pub fn energies(sim: &Sim) -> Result<[f64; 3], StepError> {
    let Some(particles) = Particles::of(&sim.world) else {
        return Ok([0.0; 3]);
    };
    let (x, v) = (
        particles.fluid::<Position>()?,
        particles.fluid::<Velocity>()?,
    );
    let (rho, m) = (particles.fluid::<Density>()?, particles.fluid::<Mass>()?);
    let (x, v, rho, m): (&[Position], &[Velocity], &[Density], &[Mass]) = (&x, &v, &rho, &m);
    let (g, eos) = (sim.constants.gravity, sim.constants.eos);
    let n = x.len();
    Ok([
        sum_fixed(n, |i| 0.5 * m[i].0 * v[i].0.length_squared()),
        sum_fixed(n, |i| -m[i].0 * g.dot(x[i].0)),
        sum_fixed(n, |i| m[i].0 * eos.internal_energy(rho[i].0)),
    ])
}

impl Stage for Energy {
    fn name(&self) -> &'static str {
        "energy"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        for entry in &BUDGET {
            (entry.ask)(sim);
        }
        let columns = columns().iter().map(|c| c.to_string()).collect();
        let path = sim.out_dir.join("energy.csv");
        let mut out = SeriesWriter::open_sampled(sim, &path, columns, self.params.interval)
            .map_err(|e| SetupError::new("energy", e.to_string()))?;
        // The initial state is the first row (t = 0, nothing dissipated yet); a resumed
        // run has it already.
        if sim.resources.get::<Resuming>().is_none() {
            let setup_err = |e: StepError| SetupError::new("energy", e.to_string());
            let stored = energies(sim).map_err(setup_err)?;
            self.initial = stored.iter().sum();
            out.push(sim.clock.time, self.row(stored))
                .map_err(setup_err)?;
            self.next = sim.clock.time + self.params.interval;
        }
        self.out = Some(out);
        Ok(())
    }

    /// Flushes energy.csv; keeps the dissipated work and the next sample time.
    fn save_state(&mut self, _sim: &Sim) -> Result<Vec<u8>, StepError> {
        if let Some(out) = &mut self.out {
            out.flush()?;
        }
        let mut e = Enc::default();
        for a in self.accumulated {
            e.f64(a);
        }
        e.f64(self.initial);
        e.f64(self.next);
        Ok(e.into_bytes())
    }

    fn load_state(&mut self, _sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        for a in &mut self.accumulated {
            *a = d.f64()?;
        }
        self.initial = d.f64()?;
        self.next = d.f64()?;
        d.end()
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        // The rates belong to the state at the start of the step just taken.
        for (a, entry) in self.accumulated.iter_mut().zip(&BUDGET) {
            *a += (entry.rate)(sim) * sim.clock.dt;
        }
        if sim.clock.time + 1e-12 < self.next {
            return Ok(());
        }
        self.next = sim.clock.time + self.params.interval;
        let row = self.row(energies(sim)?);
        if let Some(out) = &mut self.out {
            out.push(sim.clock.time, row)?;
        }
        Ok(())
    }

    fn finish(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let Some(out) = &mut self.out else {
            return Ok(());
        };
        out.flush()?;
        if self.params.plots {
            let title = format!("{}: energy budget", sim.name);
            out.plot(
                &sim.out_dir.join("energy.png"),
                &title,
                "energy [J/m]",
                &columns(),
            )?;
        }
        Ok(())
    }

    /// The energies of the fluid state; the dissipation rate when a stage writes it.
    fn access(&self) -> Access {
        Access::new()
            .reads::<Position>()
            .reads::<Velocity>()
            .reads::<Density>()
            .reads::<Mass>()
            .uses::<ViscousDissipation>()
            .uses::<WallPower>()
    }
}

impl Energy {
    /// A row of energy.csv from the stored energies now and the accumulated entries:
    /// total = stored + dissipated, closure_error = total - (initial + work in).
    fn row(&self, stored: [f64; 3]) -> Vec<f64> {
        let mut total: f64 = stored.iter().sum();
        let mut work = 0.0;
        for (a, entry) in self.accumulated.iter().zip(&BUDGET) {
            match entry.kind {
                Kind::Dissipated => total += a,
                Kind::WorkIn => work += a,
            }
        }
        let mut row = stored.to_vec();
        row.extend(self.accumulated);
        row.extend([total, total - (self.initial + work)]);
        row
    }
}
