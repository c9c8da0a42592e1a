//! Probes: wall pressure sensors by Methods I, II and III, wave gauges, surge front,
//! column height, maximum density fluctuation and neighbour-count statistics, sampled
//! into `probes.csv` (column `time`, then `<sensor>.<method>`, `<gauge>`, `front`, ...)
//! and plotted at the end of the run.
//!
//! Pressure extraction: each sensor is read by the methods `methods` names, the
//! shipped Methods I, II and III (`Shepard`, `Nearest`, `Averaged`, in `probe/methods.rs`)
//! or a plugin's ([`sph_core::extraction`]). Wave gauges are in `probe/gauges.rs`, the
//! flow diagnostics (front, column height, density, speed, neighbours, roll moment,
//! piston) in `probe/diagnostics.rs`.
//!
//! In a moving tank, sensors ride on their walls, the hydrostatic carry uses the
//! effective gravity g - a_w of the tank frame, and gauges measure the elevation above
//! the tank bottom along the tank's vertical. The roll moment (`roll_moment: true`) is
//! the moment the liquid exerts on the tank about the pivot P, counter-clockwise
//! positive, per unit depth: M = sum_i m_i (x_i - P) x (g - a_i), a_i the particle
//! accelerations from Forces. It follows from each particle's momentum balance
//! m_i a_i = m_i g + F_i(tank) with the particle-particle forces cancelling in pairs
//! (they act along the line between the particles), so it equals the pressure moment
//! on the walls without needing a wall integration; at rest it is the moment of the
//! liquid's weight.

mod diagnostics;
mod gauges;
mod methods;
pub use diagnostics::roll_moment;
pub use methods::{Averaged, Nearest, Shepard};
use sph_core::sim::Counter;
/// Reads a counter from the sim's diagnostics.
type ReadCount = fn(&std::collections::BTreeMap<String, f64>) -> f64;
use crate::vocab::{DensityFloored, WallReflections};

use crate::transducer::{face_offsets, BoxFilter};
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{
    Acceleration, Density, Fluid, Ghost, Mass, NeighbourCount, Position, Pressure, PressureSensor,
    Tank, Velocity, Wall, WaveGauge,
};
use sph_core::contract::Access;
use sph_core::extraction::{
    Carry, ExtractionMethod, MethodFactory, MethodListSeed, MethodName, Site,
};
use sph_core::kinematics;
use sph_core::registry::read_with_seeded_field;
use sph_core::series::SeriesWriter;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::vocab::{BodyPose, Guarded, Neighbours, Piston, WallPose};
use sph_core::world::{archetype, Particles};
use sph_core::StageRegistry;
use sph_output::SeriesPlot;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Sampling interval [s]; 0 samples every step. Default 0.005.
    pub interval: f64,
    /// Extraction methods for every pressure sensor, each named once: the shipped
    /// `Shepard`, `Nearest`, `Averaged` (Methods I, II, III) or a plugin's. Default
    /// [Shepard, Nearest, Averaged].
    #[serde(skip_deserializing)]
    pub methods: Vec<MethodName>,
    /// Surge front: largest x of fluid touching the floor (y < ds), plus ds/2. Default false.
    pub front: bool,
    /// Column height: largest y of fluid at the left wall (x < ds), plus ds/2. Default false.
    pub column_height: bool,
    /// Maximum |rho/rho_0 - 1| over the fluid particles no safeguard has acted on
    /// (`max_density_fluctuation`: the flow's own), the same over the particles one has
    /// (`guarded_density_fluctuation`, 0 if none), how many those are
    /// (`guarded_particles`), and the guards' actions since the previous sample:
    /// particle-steps raised to the density floor (`floored`) and wall reflections
    /// (`reflected`). Default false.
    pub density_fluctuation: bool,
    /// Maximum fluid speed [m/s]. Default false.
    pub max_speed: bool,
    /// Minimum, mean and maximum neighbour count. Default false.
    pub neighbours: bool,
    /// Roll angle [deg] and the liquid's roll moment about the tank pivot [N m per m
    /// of depth]; needs a tank and Forces before Probe. Default false.
    pub roll_moment: bool,
    /// Piston displacement from its rest position [m] (`piston_x`) and the fluid's
    /// horizontal force on the paddle [N per m of depth] (`piston_force`): Method I
    /// pressure integrated over the paddle at ds intervals. Needs a `piston`. Default
    /// false.
    pub piston: bool,
    /// Draw PNG plots of the series at the end of the run. Default true.
    pub plots: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            interval: 0.005,
            methods: ["Shepard", "Nearest", "Averaged"].map(MethodName).into(),
            front: false,
            column_height: false,
            density_fluctuation: false,
            max_speed: false,
            neighbours: false,
            roll_moment: false,
            piston: false,
            plots: true,
        }
    }
}

/// Reads [`Params`], `methods` through the registry's extraction methods; returns the
/// methods' factories beside them, in list order.
fn read_params(
    registry: &StageRegistry,
    de: &mut dyn erased_serde::Deserializer,
) -> Result<(Params, Vec<MethodFactory>), erased_serde::Error> {
    use serde::de::Error;
    let known = registry.extractions();
    let (mut p, named): (Params, _) = read_with_seeded_field(de, "methods", MethodListSeed(known))?;
    if let Some(named) = named {
        p.methods = named;
    }
    let factories = p
        .methods
        .iter()
        .map(|m| {
            known.get(m.0).map(|(_, make)| make).ok_or_else(|| {
                Error::custom(format!(
                    "field `methods`: no extraction method `{}` is registered",
                    m.0
                ))
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((p, factories))
}

/// The parameters with the methods' factories, as `read_params` returns them; written
/// to the resolved scenario as the parameters alone.
struct Read(Params, Vec<MethodFactory>);

impl Serialize for Read {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.0.serialize(s)
    }
}

/// Registers the probe stage and the shipped extraction methods.
pub fn register(registry: &mut StageRegistry) {
    methods::register(registry);
    registry.register_read(
        "probe",
        "pressure sensors, wave gauges, front, column height, statistics",
        |registry, de| read_params(registry, de).map(|(p, f)| Read(p, f)),
        |Read(p, factories)| {
            if !(p.interval >= 0.0 && p.interval.is_finite()) {
                return Err(sph_core::ParamError::new(
                    "interval",
                    p.interval,
                    "seconds >= 0",
                ));
            }
            let methods = p
                .methods
                .iter()
                .map(|m| m.suffix())
                .zip(factories.iter().map(|make| make()))
                .collect();
            Ok(Probe {
                params: p,
                methods,
                sensors: Vec::new(),
                gauges: Vec::new(),
                moving: false,
                piston: None,
                next: 0.0,
                filters: Vec::new(),
                guard_counts: [0.0; 2],
                out: None,
            })
        },
    );
}

pub struct Probe {
    params: Params,
    /// The extraction methods, with their column suffixes, in `params.methods` order.
    methods: Vec<(String, Box<dyn ExtractionMethod>)>,
    sensors: Vec<PressureSensor>,
    gauges: Vec<WaveGauge>,
    /// Something in the scene moves (gauges then measure in the tank frame).
    moving: bool,
    /// The piston's wall entity (found by its `Piston` component).
    piston: Option<hecs::Entity>,
    next: f64,
    /// The time filters of the sensors that have one, a filter per method, in sensor
    /// then method order.
    filters: Vec<BoxFilter>,
    /// The guard diagnostics ([`GUARD_COUNTS`]) at the previous sample.
    guard_counts: [f64; 2],
    out: Option<SeriesWriter>,
}

/// The guards' counters (written by `Integrate` or `Advance`) and the probes.csv
/// columns that give their increase over each sampling interval.
const GUARD_COUNTS: [(ReadCount, &str); 2] = [
    (DensityFloored::counted, "floored"),
    (WallReflections::counted, "reflected"),
];

impl Stage for Probe {
    fn name(&self) -> &'static str {
        "probe"
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        let err = |m: String| SetupError::new("probe", m);
        self.sensors = sph_core::world::cloned::<PressureSensor>(&sim.world);
        self.filters = self
            .sensors
            .iter()
            .filter(|s| s.filter > 0.0)
            .flat_map(|s| self.methods.iter().map(|_| BoxFilter::new(s.filter)))
            .collect();
        self.gauges = sph_core::world::cloned::<WaveGauge>(&sim.world);
        self.moving = kinematics::moving(&sim.world);
        self.piston = sim
            .world
            .query::<hecs::Entity>()
            .with::<(&Piston, &Wall)>()
            .iter()
            .next();
        let needs_grid = self
            .methods
            .iter()
            .zip(&self.params.methods)
            .find(|(m, _)| m.1.needs_grid());
        if let Some((_, name)) = needs_grid.filter(|_| !self.sensors.is_empty()) {
            if !sim.resources.contains::<Neighbours>() {
                return Err(err(format!(
                    "method `{}` needs the neighbour grid: put NeighbourGrid() before Probe()",
                    name.0
                )));
            }
        }
        if !self.gauges.is_empty() && !sim.resources.contains::<Neighbours>() {
            return Err(err(
                "wave gauges need the neighbour grid (the fluid fraction along the gauge line): put NeighbourGrid() before Probe()"
                    .into(),
            ));
        }
        if self.params.neighbours
            && archetype::<Fluid>(&sim.world).is_some_and(|a| !a.has::<NeighbourCount>())
        {
            return Err(err(
                "neighbour statistics need NeighbourGrid(count: true) before Probe()".into(),
            ));
        }
        if self.params.roll_moment {
            if sim.world.query::<&Tank>().iter().next().is_none() {
                return Err(err(
                    "roll_moment needs a `tank` (the moment is taken about its pivot)".into(),
                ));
            }
            if archetype::<Fluid>(&sim.world).is_some_and(|a| !a.has::<Acceleration>()) {
                return Err(err(
                    "roll_moment needs the particle accelerations: put Forces() before Probe()"
                        .into(),
                ));
            }
        }
        if self.params.piston && self.piston.is_none() {
            return Err(err("piston: true needs a `piston` in the scenario".into()));
        }
        if self.params.piston && !sim.resources.contains::<Neighbours>() {
            return Err(err(
                "the piston force needs the neighbour grid: put NeighbourGrid() before Probe()"
                    .into(),
            ));
        }
        let columns = self.columns();
        if columns.is_empty() {
            return Err(err("nothing to probe: add pressure_sensors or wave_gauges to the scenario, or turn on front, column_height, density_fluctuation or neighbours".into()));
        }
        let path = sim.out_dir.join("probes.csv");
        let out = SeriesWriter::open_sampled(sim, &path, columns, self.params.interval);
        self.out = Some(out.map_err(|e| err(e.to_string()))?);
        Ok(())
    }

    /// Flushes probes.csv; keeps the next sample time and the guard counts at the last
    /// sample.
    fn save_state(&mut self, _sim: &Sim) -> Result<Vec<u8>, StepError> {
        if let Some(out) = &mut self.out {
            out.flush()?;
        }
        let mut e = Enc::default();
        e.f64(self.next);
        e.u64(self.filters.len() as u64);
        for f in &self.filters {
            let readings: Vec<(f64, f64, f64)> = f.readings().collect();
            e.u64(readings.len() as u64);
            for (t, w, r) in readings {
                e.f64(t);
                e.f64(w);
                e.f64(r);
            }
        }
        for c in self.guard_counts {
            e.f64(c);
        }
        Ok(e.into_bytes())
    }

    fn load_state(&mut self, _sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        self.next = d.f64()?;
        let n = d.len(8)?;
        if n != self.filters.len() {
            return Err(sph_core::StateError::Mismatch(format!(
                "the checkpoint holds {n} sensor filters, the scenario {}",
                self.filters.len()
            )));
        }
        for f in &mut self.filters {
            let k = d.len(24)?;
            let mut readings = Vec::with_capacity(k);
            for _ in 0..k {
                readings.push((d.f64()?, d.f64()?, d.f64()?));
            }
            f.restore(readings);
        }
        for c in &mut self.guard_counts {
            *c = d.f64()?;
        }
        d.end()
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        if !self.filters.is_empty() {
            let readings = self.filtered_readings(sim)?;
            for (f, r) in self.filters.iter_mut().zip(readings) {
                f.push(sim.clock.time, r);
            }
        }
        if sim.clock.time + 1e-12 < self.next {
            return Ok(());
        }
        self.next = sim.clock.time + self.params.interval;
        let mut row = self.sample(sim)?;
        if self.params.density_fluctuation {
            // The guards' actions since the previous sample, after the guard columns
            // `sample` wrote (the counters only grow).
            let at = self.columns().iter().position(|c| c == "floored");
            for (k, (counted, _)) in GUARD_COUNTS.iter().enumerate() {
                let now = counted(&sim.diagnostics);
                if let Some(cell) = at.and_then(|at| row.get_mut(at + k)) {
                    *cell = now - self.guard_counts[k];
                }
                self.guard_counts[k] = now;
            }
        }
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
        if !self.params.plots {
            return Ok(());
        }
        let dir = &sim.out_dir;
        let title = |what: &str| format!("{}: {what}", sim.name);
        for s in &self.sensors {
            let names: Vec<String> = self
                .methods
                .iter()
                .map(|(suffix, _)| format!("{}.{suffix}", s.name))
                .collect();
            let refs: Vec<&str> = names.iter().map(String::as_str).collect();
            out.plot(
                &dir.join(format!("probe_{}.png", s.name)),
                &title(&format!("pressure at {}", s.name)),
                "pressure [Pa]",
                &refs,
            )?;
        }
        let gauges: Vec<&str> = self.gauges.iter().map(|g| g.name.as_str()).collect();
        if !gauges.is_empty() {
            out.plot(
                &dir.join("probe_gauges.png"),
                &title("wave gauges"),
                "free-surface elevation [m]",
                &gauges,
            )?;
        }
        let mut lengths = Vec::new();
        if self.params.front {
            lengths.push("front");
        }
        if self.params.column_height {
            lengths.push("column_height");
        }
        if !lengths.is_empty() {
            out.plot(
                &dir.join("probe_front.png"),
                &title("surge front and column height"),
                "length [m]",
                &lengths,
            )?;
        }
        if self.params.density_fluctuation {
            out.plot(
                &dir.join("probe_density.png"),
                &title("largest density fluctuation: flow and guarded particles"),
                "max |rho/rho_0 - 1|",
                &["max_density_fluctuation", "guarded_density_fluctuation"],
            )?;
            out.plot(
                &dir.join("probe_guards.png"),
                &title("safeguards: actions per sampling interval, particles touched"),
                "count",
                &["floored", "reflected", "guarded_particles"],
            )?;
        }
        if self.params.max_speed {
            out.plot(
                &dir.join("probe_speed.png"),
                &title("maximum speed"),
                "speed [m/s]",
                &["max_speed"],
            )?;
        }
        if self.params.roll_moment {
            out.plot(
                &dir.join("probe_roll_angle.png"),
                &title("roll angle"),
                "roll angle [deg]",
                &["roll_angle"],
            )?;
            out.plot(
                &dir.join("probe_roll_moment.png"),
                &title("liquid roll moment about the pivot"),
                "moment [N m / m]",
                &["roll_moment"],
            )?;
        }
        if self.params.piston {
            out.plot(
                &dir.join("probe_piston_x.png"),
                &title("piston displacement"),
                "x [m]",
                &["piston_x"],
            )?;
            out.plot(
                &dir.join("probe_piston_force.png"),
                &title("force on the piston"),
                "force [N / m]",
                &["piston_force"],
            )?;
        }
        if self.params.neighbours {
            let names = ["neighbours_min", "neighbours_mean", "neighbours_max"];
            out.plot(
                &dir.join("probe_neighbours.png"),
                &title("neighbour count"),
                "neighbours",
                &names,
            )?;
        }
        Ok(())
    }

    /// Samples the fluid and the walls where the world has them; the neighbour grid
    /// for Method I (when there are sensors), the wave gauges and the piston force.
    fn access(&self) -> Access {
        let access = Access::new()
            .reads::<Position>()
            .reads::<Velocity>()
            .reads::<Density>()
            .reads::<Pressure>()
            .reads::<Mass>()
            .reads::<WallPose>()
            .reads::<BodyPose>()
            .reads_if::<Neighbours>(self.params.piston)
            .reads_if::<NeighbourCount>(self.params.neighbours)
            .reads_if::<Acceleration>(self.params.roll_moment)
            .uses::<Guarded>()
            .uses::<Ghost>()
            .uses::<DensityFloored>()
            .uses::<WallReflections>();
        // The gauges (read from the world at setup) need the grid too; setup checks.
        if !self.params.piston {
            access.uses::<Neighbours>()
        } else {
            access
        }
    }
}

impl Probe {
    fn columns(&self) -> Vec<String> {
        let mut c = Vec::new();
        for s in &self.sensors {
            for (suffix, _) in &self.methods {
                c.push(format!("{}.{suffix}", s.name));
                if s.transducer() {
                    c.push(format!("{}.{suffix}.transducer", s.name));
                }
            }
        }
        c.extend(self.gauges.iter().map(|g| g.name.clone()));
        let flags = [
            (self.params.front, &["front"][..]),
            (self.params.column_height, &["column_height"][..]),
            (
                self.params.density_fluctuation,
                &[
                    "max_density_fluctuation",
                    "guarded_density_fluctuation",
                    "guarded_particles",
                    "floored",
                    "reflected",
                ][..],
            ),
            (self.params.max_speed, &["max_speed"][..]),
            (
                self.params.neighbours,
                &["neighbours_min", "neighbours_mean", "neighbours_max"][..],
            ),
            (self.params.roll_moment, &["roll_angle", "roll_moment"][..]),
            (self.params.piston, &["piston_x", "piston_force"][..]),
        ];
        for (on, names) in flags {
            if on {
                c.extend(names.iter().map(|n| n.to_string()));
            }
        }
        c
    }

    fn sample(&mut self, sim: &Sim) -> Result<Vec<f64>, StepError> {
        let _span = tracing::info_span!("sample").entered();
        let Some(particles) = Particles::of(&sim.world) else {
            return Ok(vec![0.0; self.columns().len()]);
        };
        // The tank's pose now (at rest at the origin without a tank).
        let pose = kinematics::tank_pose(&sim.world).unwrap_or_default();
        let mut row = Vec::new();
        let mut filters = self.filters.iter();
        for s in &self.sensors {
            for (_, m) in &mut self.methods {
                row.push(reading(sim, particles, s, m.as_mut(), 0.0)?);
                if s.filter > 0.0 {
                    row.push(filters.next().map_or(0.0, BoxFilter::mean));
                } else if s.transducer() {
                    row.push(face(sim, particles, s, m.as_mut())?);
                }
            }
        }
        let frame = self.moving.then_some(pose);
        for g in &self.gauges {
            row.push(gauges::elevation(sim, particles, g.x, frame)?);
        }
        let piston = self.piston.filter(|_| self.params.piston);
        diagnostics::sample(&self.params, piston, sim, particles, pose, &mut row)?;
        Ok(row)
    }

    /// The face readings of the sensors with a time filter, in the filters' order.
    fn filtered_readings(&mut self, sim: &Sim) -> Result<Vec<f64>, StepError> {
        let Some(particles) = Particles::of(&sim.world) else {
            return Ok(vec![0.0; self.filters.len()]);
        };
        let mut out = Vec::with_capacity(self.filters.len());
        for s in self.sensors.iter().filter(|s| s.filter > 0.0) {
            for (_, m) in &mut self.methods {
                out.push(face(sim, particles, s, m.as_mut())?);
            }
        }
        Ok(out)
    }
}

/// Sensor `s`'s pressure by method `m` at `offset` along the wall from its centre.
fn reading(
    sim: &Sim,
    particles: Particles,
    s: &PressureSensor,
    m: &mut dyn ExtractionMethod,
    offset: f64,
) -> Result<f64, StepError> {
    let wall = &*sim
        .world
        .get::<&WallPose>(s.wall)
        .map_err(|_| StepError::Internal("a probed wall is not in the world".into()))?;
    let along = s.along + offset;
    let at = wall.point(along);
    let site = Site {
        wall,
        along,
        width: s.width,
        carry: Carry {
            rho0: sim.constants.eos.rho0,
            g: sim.constants.gravity - wall.body.acceleration_at(at),
        },
    };
    m.pressure(sim, particles, &site)
}

/// Sensor `s`'s pressure by method `m`, averaged over its face.
fn face(
    sim: &Sim,
    particles: Particles,
    s: &PressureSensor,
    m: &mut dyn ExtractionMethod,
) -> Result<f64, StepError> {
    let offsets = face_offsets(s.diameter, sim.constants.spacing);
    let mut sum = 0.0;
    for &o in &offsets {
        sum += reading(sim, particles, s, m, o)?;
    }
    Ok(sum / offsets.len() as f64)
}
