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

use crate::transducer::{face_points, BoxFilter};
use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::{
    Acceleration, Density, Fluid, Ghost, Mass, NeighbourCount, Position, Pressure, PressureSensor,
    Tank, Velocity, Wall, WaveGauge,
};
use sph_core::contract::Access;
use sph_core::dim::Vector;
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
    /// Roll angle [deg] and the liquid's roll moment about the tank pivot (2D: N m per
    /// m of depth, 3D: N m); needs a tank and Forces before Probe. Default false.
    pub roll_moment: bool,
    /// Pitch angle [deg] and the liquid's moment about the pitch axis (the x axis
    /// through the tank pivot) [N m], positive as a positive pitch turns; 3D only;
    /// needs a tank and Forces before Probe. Default false (and then left out of a
    /// resolved scenario, so that 2D files read as before).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub pitch_moment: bool,
    /// Piston displacement from its rest position [m] (`piston_x`) and the fluid's
    /// horizontal force on the paddle (`piston_force`; 2D: N per m of depth, 3D: N):
    /// Method I pressure integrated over the paddle in cells of about ds. Needs a
    /// `piston`. Default false.
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
            pitch_moment: false,
            piston: false,
            plots: true,
        }
    }
}

/// The unit suffix of an integrated load: a 2D scene has a unit depth, so its forces
/// and moments are per metre of it; a 3D scene's are whole.
pub(crate) const PER_DEPTH: &str = if sph_core::dim::DIM == 2 { " / m" } else { "" };

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
        if self.params.pitch_moment && sph_core::dim::DIM == 2 {
            return Err(err(
                "pitch_moment is the moment about a 3D tank's x axis; a 2D tank rolls: use roll_moment, or give the scene `dimensions: 3`".into(),
            ));
        }
        for (on, name) in [
            (self.params.roll_moment, "roll_moment"),
            (self.params.pitch_moment, "pitch_moment"),
        ] {
            if !on {
                continue;
            }
            if sim.world.query::<&Tank>().iter().next().is_none() {
                return Err(err(format!(
                    "{name} needs a `tank` (the moment is taken about its pivot)"
                )));
            }
            if archetype::<Fluid>(&sim.world).is_some_and(|a| !a.has::<Acceleration>()) {
                return Err(err(format!(
                    "{name} needs the particle accelerations: put Forces() before Probe()"
                )));
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
        // Each turn's angle and the liquid's moment about its axis.
        for (on, turn, unit) in [
            (self.params.roll_moment, "roll", PER_DEPTH),
            (self.params.pitch_moment, "pitch", ""),
        ] {
            if !on {
                continue;
            }
            let (angle, moment) = (format!("{turn}_angle"), format!("{turn}_moment"));
            out.plot(
                &dir.join(format!("probe_{angle}.png")),
                &title(&format!("{turn} angle")),
                &format!("{turn} angle [deg]"),
                &[angle.as_str()],
            )?;
            out.plot(
                &dir.join(format!("probe_{moment}.png")),
                &title(&format!("liquid {turn} moment about the pivot")),
                &format!("moment [N m{unit}]"),
                &[moment.as_str()],
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
                &format!("force [N{PER_DEPTH}]"),
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
            .reads_if::<Acceleration>(self.params.roll_moment || self.params.pitch_moment)
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
            (
                self.params.pitch_moment && sph_core::dim::DIM == 3,
                &["pitch_angle", "pitch_moment"][..],
            ),
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
                row.push(reading(sim, particles, s, m.as_mut(), (0.0, 0.0))?);
                if s.filter > 0.0 {
                    row.push(filters.next().map_or(0.0, BoxFilter::mean));
                } else if s.transducer() {
                    row.push(face(sim, particles, s, m.as_mut())?);
                }
            }
        }
        let frame = self.moving.then_some(pose);
        for g in &self.gauges {
            #[cfg(not(feature = "dim3"))]
            let foot = Vector::new(g.x, 0.0);
            #[cfg(feature = "dim3")]
            let foot = Vector::new(g.x, 0.0, g.z);
            row.push(gauges::elevation(sim, particles, foot, frame)?);
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

/// Sensor `s`'s pressure by method `m` at `offset` = (along, across) on the wall from
/// its centre (across is 0 in 2D).
fn reading(
    sim: &Sim,
    particles: Particles,
    s: &PressureSensor,
    m: &mut dyn ExtractionMethod,
    offset: (f64, f64),
) -> Result<f64, StepError> {
    let wall = &*sim
        .world
        .get::<&WallPose>(s.wall)
        .map_err(|_| StepError::Internal("a probed wall is not in the world".into()))?;
    let along = s.along + offset.0;
    #[cfg(not(feature = "dim3"))]
    let _ = offset.1;
    let mut site = Site {
        wall,
        along,
        #[cfg(feature = "dim3")]
        across: s.across + offset.1,
        width: s.width,
        carry: Carry {
            rho0: sim.constants.eos.rho0,
            g: Vector::ZERO,
        },
    };
    site.carry.g = sim.constants.gravity - wall.body.acceleration_at(site.point());
    m.pressure(sim, particles, &site)
}

/// Sensor `s`'s pressure by method `m`, averaged over its face ([`face_points`]).
fn face(
    sim: &Sim,
    particles: Particles,
    s: &PressureSensor,
    m: &mut dyn ExtractionMethod,
) -> Result<f64, StepError> {
    let points = face_points(s.diameter, sim.constants.spacing);
    let mut sum = 0.0;
    for &o in &points {
        sum += reading(sim, particles, s, m, o)?;
    }
    Ok(sum / points.len() as f64)
}

// 2D set-ups; the 3D build's own tests are in `tests3d` modules.
#[cfg(all(test, not(feature = "dim3")))]
pub(super) mod tests {
    use super::*;
    use crate::testing::out_dir;
    use crate::transducer::face_offsets;
    use glam::DVec2;
    use sph_core::world::{column, column_mut};

    /// The fluid particles of [`scene`].
    pub(in crate::outputs) const N_FLUID: usize = 98;

    /// A 0.3 m x 0.2 m closed box at rest with a 12 x 8 block of fluid in its lower
    /// left corner (spacing 0.01 m): hydrostatic pressures with a ripple from particle
    /// to particle, and densities, velocities, accelerations and guard flags that vary;
    /// two drops apart from it;
    /// its ghosts (pressures their sources' plus 50 Pa, so that they count apart) and
    /// the neighbour grid built, with neighbour counts, unsorted.
    pub(in crate::outputs) fn scene() -> Sim {
        let mut world = hecs::World::new();
        crate::testing::closed_box(&mut world, 0.3, 0.2);
        for (a, b, x) in crate::testing::lattice(12, 8) {
            let k = ((7 * a + 3 * b) % 11) as f64;
            world.spawn((
                Fluid,
                Position(x),
                Velocity(DVec2::new(0.1 * k - 0.4, 0.03 * k - 0.1)),
                Density(995.0 + k),
                Pressure(9810.0 * (0.08 - x.y) + 30.0 * k - 150.0),
                Mass(0.1 + 0.001 * k),
                Acceleration(DVec2::new(0.5 * k - 2.0, 0.2 * k)),
                Guarded(if k == 3.0 { Guarded::REFLECTED } else { 0 }),
            ));
        }
        // Two drops: one ahead of the block's front, one above its left column.
        for x in [DVec2::new(0.2, 0.05), DVec2::new(0.05, 0.15)] {
            world.spawn((
                Fluid,
                Position(x),
                Velocity(DVec2::new(0.3, -0.5)),
                Density(1000.0),
                Pressure(0.0),
                Mass(0.1),
                Acceleration(DVec2::new(0.0, -9.81)),
                Guarded(0),
            ));
        }
        let mut sim = crate::testing::sim(world);
        let stages = [
            ("ghost_walls", "()"),
            ("neighbour_grid", "(sort_every: 0, skin: 0.0)"),
        ];
        for mut stage in crate::testing::pipeline(&mut sim, &stages) {
            stage.run(&mut sim).unwrap();
        }
        let fluid = archetype::<Fluid>(&sim.world).unwrap();
        let ghost = archetype::<Ghost>(&sim.world).unwrap();
        let fp = column::<Pressure>(fluid).unwrap();
        let sources = column::<Ghost>(ghost).unwrap();
        let mut gp = column_mut::<Pressure>(ghost).unwrap();
        for (p, g) in gp.iter_mut().zip(sources.iter()) {
            p.0 = fp[g.source as usize].0 + 50.0;
        }
        drop((fp, gp, sources));
        sim
    }

    /// Every particle, fluid then ghosts: position, pressure, density, mass.
    pub(in crate::outputs) fn all(sim: &Sim) -> Vec<(DVec2, f64, f64, f64)> {
        let all = crate::testing::everyone(sim);
        all.into_iter()
            .map(|(x, _, m, rho, p)| (x, p, rho, m))
            .collect()
    }

    /// Method I's sum over every particle (fluid and ghosts), p at `at` =
    /// sum_j p_j W_j V_j / sum_j W_j V_j with V_j = m_j / rho_j, 0 where dry; the test
    /// sim's kernel (Wendland, h 0.013 m).
    pub(in crate::outputs) fn shepard_sum(sim: &Sim, at: DVec2) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for (x, p, rho, m) in all(sim) {
            let w = sph_core::kernel::w(
                sph_core::kernel::KernelKind::Wendland,
                0.013,
                (at - x).length(),
            );
            num += p * w * m / rho;
            den += w * m / rho;
        }
        if den > 0.0 {
            num / den
        } else {
            0.0
        }
    }

    /// Wall `k` of the box (0 the floor, then counter-clockwise) where it is now.
    pub(in crate::outputs) fn wall(sim: &Sim, k: usize) -> WallPose {
        sph_core::walls::Walls::of(&sim.world).now()[k]
    }

    /// [`scene`] with three sensors (a point on the floor; a 10 mm face on the left
    /// wall; an 8 mm face on the floor with a 3 ms time filter) and a gauge, the box
    /// accelerating, writing into a fresh folder.
    fn probed(name: &str) -> Sim {
        let mut sim = scene();
        let walls = sph_core::walls::Walls::of(&sim.world).entities().to_vec();
        for (name, wall, along, width, diameter, filter) in [
            ("s1", walls[0], 0.0625, 0.03, 0.0, 0.0),
            ("s2", walls[3], 0.17, 0.02, 0.01, 0.0),
            ("s3", walls[0], 0.04, 0.02, 0.008, 0.003),
        ] {
            sim.world.spawn((PressureSensor {
                name: name.into(),
                wall,
                along,
                width,
                diameter,
                filter,
            },));
        }
        sim.world.spawn((WaveGauge {
            name: "g1".into(),
            x: 0.05,
        },));
        // At its rest place this instant, but accelerating: the carries take g - a_w.
        for wall in sim.world.query_mut::<&mut WallPose>() {
            wall.body.state.acceleration = DVec2::new(1.5, 2.0);
        }
        sim.out_dir = out_dir(name);
        sim.clock.end_time = 1.0;
        sim
    }

    /// Adds `dp` to every particle's pressure (fluid and ghosts): each method's
    /// reading moves by `dp` (each is a weighted mean of carried pressures).
    fn raise_pressures(sim: &Sim, dp: f64) {
        for a in [
            archetype::<Fluid>(&sim.world),
            archetype::<Ghost>(&sim.world),
        ]
        .into_iter()
        .flatten()
        {
            for p in column_mut::<Pressure>(a).unwrap().iter_mut() {
                p.0 += dp;
            }
        }
    }

    /// Sensor `s`'s reading by `method` at `offset` from its centre, and over its face
    /// (the mean over `face_offsets`), the methods called directly.
    fn direct(sim: &Sim, s: &PressureSensor, method: &str, face: bool) -> f64 {
        let offsets = if face {
            face_offsets(s.diameter, 0.01)
        } else {
            vec![0.0]
        };
        let wall = *sim.world.get::<&WallPose>(s.wall).unwrap();
        let particles = Particles::of(&sim.world).unwrap();
        let mut m: Box<dyn ExtractionMethod> = match method {
            "shepard" => Box::new(Shepard),
            "nearest" => Box::new(Nearest),
            _ => Box::new(Averaged::default()),
        };
        let mut sum = 0.0;
        for o in &offsets {
            let site = Site {
                wall: &wall,
                along: s.along + o,
                width: s.width,
                carry: Carry {
                    rho0: 1000.0,
                    g: DVec2::new(0.0, -9.81) - wall.body.acceleration_at(wall.point(s.along + o)),
                },
            };
            sum += m.pressure(sim, particles, &site).unwrap();
        }
        sum / offsets.len() as f64
    }

    /// probes.csv: the header, and a row per sample (every 10 ms of simulated time,
    /// the steps between skipped), each column what its method, face, filter, gauge or
    /// diagnostic reads then. The pressures rise 100 Pa a step, so the readings and
    /// the time filter's window show which step each comes from; the guards' counts are
    /// their increase since the previous sample.
    #[test]
    fn probes_csv_holds_each_column_at_each_sample() {
        let mut sim = probed("csv");
        let params = "{\"interval\": 0.01, \"front\": true, \"density_fluctuation\": true, \"plots\": false}";
        let mut probe = crate::testing::pipeline(&mut sim, &[("probe", params)]).remove(0);
        let sensors = sph_core::world::cloned::<PressureSensor>(&sim.world);
        let methods = ["shepard", "nearest", "averaged"];
        let base: Vec<Vec<(f64, f64)>> = sensors
            .iter()
            .map(|s| {
                let face = |m| direct(&sim, s, m, true);
                methods
                    .iter()
                    .map(|m| (direct(&sim, s, m, false), face(m)))
                    .collect()
            })
            .collect();
        let gauge = gauges::elevation(
            &sim,
            Particles::of(&sim.world).unwrap(),
            glam::DVec2::new(0.05, 0.0),
            None,
        )
        .unwrap();
        let times = [0.0, 0.004, 0.008, 0.01, 0.013, 0.019, 0.02, 0.021];
        let mut filters = vec![BoxFilter::new(0.003); 3];
        let mut expected = Vec::new();
        for (n, &t) in times.iter().enumerate() {
            if n > 0 {
                raise_pressures(&sim, 100.0);
            }
            if t == 0.01 {
                WallReflections::add(&mut sim.diagnostics, 3);
                DensityFloored::add(&mut sim.diagnostics, 2);
            }
            let lift = 100.0 * n as f64;
            for (k, f) in filters.iter_mut().enumerate() {
                f.push(t, base[2][k].1 + lift);
            }
            sim.clock.time = t;
            probe.run(&mut sim).unwrap();
            if [0.0, 0.01, 0.02].contains(&t) {
                let mut row = vec![t];
                for (s, readings) in sensors.iter().zip(&base) {
                    for (k, (point, face)) in readings.iter().enumerate() {
                        row.push(point + lift);
                        if s.filter > 0.0 {
                            row.push(filters[k].mean());
                        } else if s.diameter > 0.0 {
                            row.push(face + lift);
                        }
                    }
                }
                row.push(gauge);
                row.push(0.12); // the front
                let guards = if t == 0.01 { [2.0, 3.0] } else { [0.0, 0.0] };
                expected.push((row, guards));
            }
        }
        probe.finish(&mut sim).unwrap();
        let text = std::fs::read_to_string(sim.out_dir.join("probes.csv")).unwrap();
        let mut lines = text.lines();
        assert_eq!(
            lines.next().unwrap(),
            "time,s1.shepard,s1.nearest,s1.averaged,\
             s2.shepard,s2.shepard.transducer,s2.nearest,s2.nearest.transducer,\
             s2.averaged,s2.averaged.transducer,\
             s3.shepard,s3.shepard.transducer,s3.nearest,s3.nearest.transducer,\
             s3.averaged,s3.averaged.transducer,g1,front,\
             max_density_fluctuation,guarded_density_fluctuation,guarded_particles,\
             floored,reflected"
        );
        let rows: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), 3);
        for (row, (want, guards)) in rows.iter().zip(&expected) {
            assert_eq!(row.len(), want.len() + 5);
            for (k, (got, want)) in row.iter().zip(want).enumerate() {
                assert!(
                    (got - want).abs() <= 1e-9 * want.abs().max(1.0),
                    "t {}, column {k}: {got} against {want}",
                    row[0]
                );
            }
            assert_eq!(row[row.len() - 2..], guards[..], "t {}", row[0]);
        }
        // At 20 ms the filter's 3 ms window holds the steps at 19 and 20 ms (+500 and
        // +600 Pa, weighted 6 and 1 ms, the times since the steps before them): it
        // lags the face's reading then.
        let filtered = expected[2].0[11];
        let lagged = base[2][0].1 + (0.006 * 500.0 + 0.001 * 600.0) / 0.007;
        assert!(
            (lagged - filtered).abs() < 1e-9,
            "{filtered} against {lagged}"
        );
        std::fs::remove_dir_all(&sim.out_dir).unwrap();
    }

    /// A probe's checkpoint: the next sample time, the filters' readings and the
    /// guard counts at the last sample, so a resumed probe writes what the whole run
    /// would; a checkpoint with another number of filters is refused.
    #[test]
    fn a_probe_resumes_its_samples_filters_and_guard_counts() {
        let params = "{\"interval\": 0.01, \"density_fluctuation\": true, \"plots\": false}";
        let rows = |resume: bool| -> Vec<String> {
            let mut sim = probed(if resume { "resumed" } else { "whole" });
            let mut probe = crate::testing::pipeline(&mut sim, &[("probe", params)]).remove(0);
            for (n, t) in [0.0, 0.004, 0.008, 0.012, 0.016].into_iter().enumerate() {
                if n > 0 {
                    raise_pressures(&sim, 100.0);
                }
                WallReflections::add(&mut sim.diagnostics, n as u64);
                if n == 2 && resume {
                    let state = probe.save_state(&sim).unwrap();
                    probe = crate::testing::pipeline(&mut sim, &[("probe", params)]).remove(0);
                    probe.load_state(&mut sim, &state).unwrap();
                }
                sim.clock.time = t;
                probe.run(&mut sim).unwrap();
            }
            probe.finish(&mut sim).unwrap();
            let text = std::fs::read_to_string(sim.out_dir.join("probes.csv")).unwrap();
            std::fs::remove_dir_all(&sim.out_dir).unwrap();
            text.lines().skip(1).map(String::from).collect()
        };
        let whole = rows(false);
        assert_eq!(whole.len(), 2);
        // A new probe opens probes.csv afresh: only the rows after the checkpoint.
        assert_eq!(rows(true)[..], whole[1..]);
        let mut sim = probed("mismatch");
        let mut probe = crate::testing::pipeline(&mut sim, &[("probe", params)]).remove(0);
        let state = probe.save_state(&sim).unwrap();
        sim.world.spawn((PressureSensor {
            name: "s4".into(),
            wall: sph_core::walls::Walls::of(&sim.world).entities()[0],
            along: 0.1,
            width: 0.01,
            diameter: 0.0,
            filter: 0.002,
        },));
        let mut other = crate::testing::pipeline(&mut sim, &[("probe", params)]).remove(0);
        let e = other.load_state(&mut sim, &state).unwrap_err().to_string();
        assert!(e.contains("holds 3 sensor filters, the scenario 6"), "{e}");
        std::fs::remove_dir_all(&sim.out_dir).unwrap();
    }

    /// What a probe reads follows its options: the grid for the piston force, the
    /// neighbour counts for their statistics, the accelerations for the roll moment.
    #[test]
    fn the_probe_declares_what_its_options_read() {
        use sph_core::contract::Quantity;
        let reads = |params: &str| crate::testing::stage("probe", params).access().reads;
        let base = reads("{}");
        for q in [
            Quantity::of::<Position>(),
            Quantity::of::<Pressure>(),
            Quantity::of::<WallPose>(),
        ] {
            assert!(base.contains(&q), "{q:?}");
        }
        for (params, q) in [
            ("{\"piston\": true}", Quantity::of::<Neighbours>()),
            ("{\"neighbours\": true}", Quantity::of::<NeighbourCount>()),
            ("{\"roll_moment\": true}", Quantity::of::<Acceleration>()),
        ] {
            assert!(!base.contains(&q) && reads(params).contains(&q), "{params}");
        }
    }

    /// At the end of the run each series is drawn once: a plot per sensor (its
    /// methods), one of the gauges, and one per diagnostic group turned on; none with
    /// `plots: false`. (What is drawn is checked by sph-output's plot tests.)
    #[test]
    fn the_end_of_the_run_plots_each_series() {
        let pngs = |plots: bool| -> Vec<String> {
            let mut sim = probed(&format!("plots_{plots}"));
            sim.world.spawn((Tank {
                width: 0.3,
                height: 0.2,
                pivot: DVec2::ZERO,
            },));
            let paddle = sph_core::walls::Walls::of(&sim.world).entities()[3];
            sim.world.insert_one(paddle, Piston).unwrap();
            let params = format!(
                "{{\"front\": true, \"column_height\": true, \"density_fluctuation\": true, \
                 \"max_speed\": true, \"neighbours\": true, \"roll_moment\": true, \
                 \"piston\": true, \"interval\": 0.0, \"plots\": {plots}}}"
            );
            let mut probe = crate::testing::pipeline(&mut sim, &[("probe", &params)]).remove(0);
            for t in [0.0, 0.01] {
                sim.clock.time = t;
                probe.run(&mut sim).unwrap();
            }
            probe.finish(&mut sim).unwrap();
            let mut names: Vec<String> = std::fs::read_dir(&sim.out_dir)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".png"))
                .collect();
            names.sort();
            std::fs::remove_dir_all(&sim.out_dir).unwrap();
            names
        };
        let mut expected = [
            "probe_s1",
            "probe_s2",
            "probe_s3",
            "probe_gauges",
            "probe_front",
            "probe_density",
            "probe_guards",
            "probe_speed",
            "probe_roll_angle",
            "probe_roll_moment",
            "probe_piston_x",
            "probe_piston_force",
            "probe_neighbours",
        ]
        .map(|n| format!("{n}.png"));
        expected.sort();
        assert_eq!(pngs(true), expected);
        assert!(pngs(false).is_empty());
    }

    /// Takes component `T` off every fluid particle.
    fn strip<T: hecs::Component>(sim: &mut Sim) {
        let fluid: Vec<hecs::Entity> = sim
            .world
            .query::<hecs::Entity>()
            .with::<&Fluid>()
            .iter()
            .collect();
        for e in fluid {
            sim.world.remove_one::<T>(e).unwrap();
        }
    }

    /// What each option needs is checked at setup, with what to do in the message.
    /// (The probe's parameters are read as a map, as the scenario loader hands them
    /// over: `{"field": value}` in these tests.)
    #[test]
    fn setup_names_what_a_probe_lacks() {
        let refused = |sim: &mut Sim, params: &str, says: &str| {
            let mut probe = crate::testing::stage("probe", params);
            let e = probe.setup(sim).err().map(|e| e.message);
            let e = e.unwrap_or_else(|| panic!("{params}: accepted"));
            assert!(e.contains(says), "{params}: {e}");
        };
        let mut sim = probed("setup");
        let grid = sim.resources.take::<Neighbours>().unwrap();
        refused(&mut sim, "{}", "method `Shepard` needs the neighbour grid");
        refused(
            &mut sim,
            "{\"methods\": [Nearest]}",
            "wave gauges need the neighbour grid",
        );
        sim.resources.insert(grid);
        refused(
            &mut sim,
            "{\"roll_moment\": true}",
            "roll_moment needs a `tank`",
        );
        refused(
            &mut sim,
            "{\"piston\": true}",
            "piston: true needs a `piston`",
        );
        let mut bare = crate::testing::sim(hecs::World::new());
        bare.out_dir = out_dir("setup_bare");
        refused(&mut bare, "{}", "nothing to probe");
        crate::testing::stage("probe", "{\"front\": true}")
            .setup(&mut bare)
            .unwrap();
        // Roll moment: a tank, but no accelerations.
        let mut sim = probed("setup_tank");
        sim.world.spawn((Tank {
            width: 0.3,
            height: 0.2,
            pivot: DVec2::ZERO,
        },));
        strip::<Acceleration>(&mut sim);
        refused(
            &mut sim,
            "{\"roll_moment\": true}",
            "put Forces() before Probe()",
        );
        // A piston, but no grid (and no sensors or gauges, which would ask first).
        let mut sim = scene();
        sim.out_dir = out_dir("setup_piston");
        let paddle = sph_core::walls::Walls::of(&sim.world).entities()[3];
        sim.world.insert_one(paddle, Piston).unwrap();
        sim.resources.take::<Neighbours>();
        refused(
            &mut sim,
            "{\"methods\": [Nearest], \"piston\": true}",
            "the piston force needs the neighbour grid",
        );
        // Neighbour statistics without counts.
        let mut sim = probed("setup_counts");
        strip::<NeighbourCount>(&mut sim);
        refused(
            &mut sim,
            "{\"neighbours\": true}",
            "NeighbourGrid(count: true)",
        );
        for dir in [
            "setup",
            "setup_bare",
            "setup_tank",
            "setup_piston",
            "setup_counts",
        ] {
            std::fs::remove_dir_all(out_dir(dir)).unwrap();
        }
        // The interval.
        for bad in ["-0.001", "inf", "NaN"] {
            let e = crate::testing::built("probe", &format!("{{\"interval\": {bad}}}")).err();
            assert!(e.is_some_and(|e| e.contains("interval")), "{bad}");
        }
    }

    /// A 2D scene has a unit depth: its load plots read per metre of it, as the
    /// columns (docs/scenario.md, `Probe`).
    #[test]
    fn the_2d_load_plots_are_per_metre_of_depth() {
        assert_eq!(super::PER_DEPTH, " / m");
    }
}
