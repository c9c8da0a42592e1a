//! Energy budget (docs/physics.md, "Energy budget"): kinetic sum m|v|^2/2, potential
//! -sum m g.x (zero at y = 0), internal sum m e(rho) with e the Tait internal energy,
//! and viscous, the work dissipated by the artificial viscosity integrated over time.
//! Written to `energy.csv` (time, kinetic, potential, internal, viscous, total) and
//! plotted. Place it after Integrate: it integrates the dissipation rate the forces
//! stage reported over the step just taken. Energy exchanged with the walls through the
//! ghosts is not tracked, so `total` drifts by that work (a diagnostic, not a bug).

use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc, Resuming};
use sph_core::components::{Density, Mass, Position, Velocity};
use sph_core::contract::Access;
use sph_core::series::SeriesWriter;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::ViscousDissipation;
use sph_core::world::{sum_fixed, Particles};
use sph_core::StageRegistry;
use sph_output::SeriesPlot;

const COLUMNS: [&str; 5] = ["kinetic", "potential", "internal", "viscous", "total"];

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
        "kinetic, potential, internal and viscous energy to energy.csv",
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
                viscous: 0.0,
                next: 0.0,
                out: None,
            })
        },
    );
}

pub struct Energy {
    params: Params,
    viscous: f64,
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
        sim.resources.insert(ViscousDissipation::default());
        let columns = COLUMNS.iter().map(|c| c.to_string()).collect();
        let path = sim.out_dir.join("energy.csv");
        let mut out = SeriesWriter::open_sampled(sim, &path, columns, self.params.interval)
            .map_err(|m| SetupError::new("energy", m))?;
        // The initial state is the first row (t = 0, nothing dissipated yet); a resumed
        // run has it already.
        if sim.resources.get::<Resuming>().is_none() {
            let setup_err = |e: StepError| SetupError::new("energy", e.to_string());
            let [k, p, i] = energies(sim).map_err(setup_err)?;
            out.push(sim.clock.time, vec![k, p, i, 0.0, k + p + i])
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
        e.f64(self.viscous);
        e.f64(self.next);
        Ok(e.into_bytes())
    }

    fn load_state(&mut self, _sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        self.viscous = d.f64()?;
        self.next = d.f64()?;
        d.end()
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let power = sim
            .resources
            .get::<ViscousDissipation>()
            .map_or(0.0, |d| d.power);
        self.viscous += power * sim.clock.dt;
        if sim.clock.time + 1e-12 < self.next {
            return Ok(());
        }
        self.next = sim.clock.time + self.params.interval;
        let [k, p, i] = energies(sim)?;
        if let Some(out) = &mut self.out {
            out.push(
                sim.clock.time,
                vec![k, p, i, self.viscous, k + p + i + self.viscous],
            )?;
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
                &COLUMNS,
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
    }
}
