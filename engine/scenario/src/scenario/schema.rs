//! The scenario file's schema: the fluid, the resolution, the tank, the blocks, sensors
//! and gauges, and their documented defaults (docs/scenario.md).

use super::*;

/// The largest particle count a scenario may ask for; checked before any allocation.
pub const MAX_PARTICLES: f64 = 20e6;

/// Smoothing length as a ratio to the particle spacing, accepted in [0.5, 3].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(transparent)]
pub struct HOverDx(pub f64);

impl<'de> Deserialize<'de> for HOverDx {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = f64::deserialize(d)?;
        if (0.5..=3.0).contains(&v) {
            Ok(HOverDx(v))
        } else {
            Err(de::Error::custom(format!(
                "{v} is out of range; accepted: 0.5 to 3.0 (0.7-0.9 for the Gaussian, about 1.2-1.33 for 2h-support kernels)"
            )))
        }
    }
}

/// Fluid properties.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FluidSpec {
    /// Reference density rho_0 [kg/m^3]. Default 1000.
    pub density: Positive,
    /// Tait exponent gamma. Default 7.
    pub gamma: Positive,
    /// Numerical speed of sound c_0 [m/s]. Default: derived as 10 sqrt(2 g H), H the
    /// tallest fluid block.
    pub sound_speed: Option<Positive>,
    /// Gravity [m/s^2]. Default (0, -9.81); in 3D (0, -9.81, 0).
    pub gravity: Coords,
}

impl Default for FluidSpec {
    fn default() -> Self {
        Self {
            density: Positive(1000.0),
            gamma: Positive(7.0),
            sound_speed: None,
            gravity: dim::xy(0.0, -9.81).into(),
        }
    }
}

/// Resolution: one number.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub enum Resolution {
    /// Particle spacing ds [m].
    Spacing(Positive),
    /// Number of particles across the width of the first fluid block.
    ParticlesAcross(#[serde(deserialize_with = "particles_across")] u32),
}

/// What `ParticlesAcross` accepts, for its errors.
pub(crate) const PARTICLES_ACROSS: &str =
    "a whole number of particles across the first fluid block, 2 or more, e.g. ParticlesAcross(40)";

/// `ParticlesAcross(n)`'s number: a whole number from 2 to `u32::MAX`, with an error
/// that says so for anything else (-100, 40.5, "40") instead of serde's bare "Integer
/// is out of bounds".
pub(crate) fn particles_across<'de, D: Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
    fn out_of_range<E: de::Error>(n: impl fmt::Display) -> E {
        E::custom(format!(
            "ParticlesAcross({n}) is out of range; ParticlesAcross takes {PARTICLES_ACROSS}"
        ))
    }
    struct Count;
    impl Visitor<'_> for Count {
        type Value = u32;
        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            write!(f, "{PARTICLES_ACROSS}")
        }
        fn visit_u64<E: de::Error>(self, n: u64) -> Result<u32, E> {
            self.visit_u128(n.into())
        }
        fn visit_i64<E: de::Error>(self, n: i64) -> Result<u32, E> {
            self.visit_i128(n.into())
        }
        fn visit_u128<E: de::Error>(self, n: u128) -> Result<u32, E> {
            u32::try_from(n)
                .ok()
                .filter(|&n| n >= 2)
                .ok_or_else(|| out_of_range(n))
        }
        fn visit_i128<E: de::Error>(self, n: i128) -> Result<u32, E> {
            u128::try_from(n).map_or_else(|_| Err(out_of_range(n)), |n| self.visit_u128(n))
        }
        fn visit_f64<E: de::Error>(self, x: f64) -> Result<u32, E> {
            if x.fract() == 0.0 {
                return Err(out_of_range(x));
            }
            Err(E::custom(format!(
                "ParticlesAcross({x}) is not a whole number; ParticlesAcross takes {PARTICLES_ACROSS}"
            )))
        }
    }
    d.deserialize_any(Count)
}

/// An axis-aligned tank with its bottom-left inner corner at the origin; generates the
/// walls `left`, `bottom`, `right` (3D: then `back` at z = 0 and `front` at z =
/// breadth) and, unless `open_top`, `top`. The scenario's
/// geometry (walls, blocks, sensors, gauges) is written in the tank frame; with a
/// `motion` all of it rides with the tank.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TankSpec {
    /// Inner width [m].
    pub width: Positive,
    /// Inner height [m].
    pub height: Positive,
    /// Inner breadth along z [m] (3D only).
    #[cfg(feature = "dim3")]
    pub breadth: Positive,
    /// No roof. Default true.
    #[serde(default = "yes")]
    pub open_top: bool,
    /// Prescribed motion (roll, sway, heave or a CSV series). Default: fixed.
    #[serde(default)]
    pub motion: Option<MotionSpec>,
}

impl TankSpec {
    /// The roll axis: the motion's pivot, or the centre of the bottom (in 3D the
    /// axis is the line through it along z). A pitching 3D tank turns about the line
    /// along x through it, at the middle of the tank's breadth.
    pub fn pivot(&self) -> Vector {
        let (x, y) = self
            .motion
            .as_ref()
            .and_then(|m| m.pivot)
            .unwrap_or((0.5 * self.width.0, 0.0));
        #[cfg(feature = "dim3")]
        if self.motion.as_ref().is_some_and(|m| m.pitch.is_some()) {
            return Vector::new(x, y, 0.5 * self.breadth.0);
        }
        dim::xy(x, y)
    }
}

/// A sweep over the roll frequency (and filling) of a rolling tank: one run per case,
/// each `settle_periods + fit_periods` roll periods long, with the roll moment's
/// amplitude and phase at the forcing frequency fitted over the last `fit_periods`
/// (see `engine::sweep`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepSpec {
    /// Roll frequencies omega [rad/s].
    pub omega: Vec<Positive>,
    /// Filling ratios h/b (still depth over tank width) applied to the first fluid
    /// block. Default: the scenario's own filling only.
    #[serde(default)]
    pub filling: Vec<Positive>,
    /// Roll periods run before the fit window (they include the ramp). Default 6.
    #[serde(default = "six")]
    pub settle_periods: Positive,
    /// Roll periods fitted. Default 4.
    #[serde(default = "four")]
    pub fit_periods: Positive,
}

pub(crate) fn six() -> Positive {
    Positive(6.0)
}
pub(crate) fn four() -> Positive {
    Positive(4.0)
}

pub(crate) fn yes() -> bool {
    true
}

/// An extra straight wall; the fluid lies on the left of the direction `from` -> `to`.
/// In 3D a rectangle with corners `from`, `to` and `across` (its edges run from `from`
/// to each of the other two), the fluid on the side of (across - from) x (to - from):
/// the left of `from` -> `to` seen from +z when `across` lies towards +z.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallSpec {
    pub name: String,
    pub from: Coords,
    pub to: Coords,
    /// The rectangle's third corner (3D only).
    #[cfg(feature = "dim3")]
    pub across: Coords,
}

/// Width, height (and in 3D breadth) of a block or box [m], each > 0.
#[cfg(not(feature = "dim3"))]
pub type Extent = (Positive, Positive);
/// Width, height (and in 3D breadth) of a block or box [m], each > 0.
#[cfg(feature = "dim3")]
pub type Extent = (Positive, Positive, Positive);

/// `size` as a vector.
pub(crate) fn extent(size: &Extent) -> Vector {
    #[cfg(not(feature = "dim3"))]
    return Vector::new(size.0 .0, size.1 .0);
    #[cfg(feature = "dim3")]
    return Vector::new(size.0 .0, size.1 .0, size.2 .0);
}

/// A rectangle (3D: a cuboid) of fluid at rest, filled on a square lattice of spacing
/// ds with hydrostatic density (docs/analytic.md section 1).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlockSpec {
    /// The corner of least coordinates [m].
    pub min: Coords,
    /// Width and height (3D: and breadth) [m].
    pub size: Extent,
}

/// A fixed solid box the fluid flows around (an obstacle): its faces are walls facing
/// out, named `<name>_left` (x = min), `_right`, `_bottom` (y = min), `_top` and in 3D
/// `_back` (z = min) and `_front`. A face lying on the tank's wall (a box standing on
/// the floor) is left out: no fluid reaches it.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    pub name: String,
    /// The corner of least coordinates [m].
    pub min: Coords,
    /// Width and height (3D: and breadth) [m].
    pub size: Extent,
}

/// A wall pressure sensor.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    pub name: String,
    /// Name of the wall it sits on.
    pub wall: String,
    /// Sensor centre [m]; must lie on the wall.
    pub at: Coords,
    /// Width along the wall [m] used by Method III (in 3D the side of its square
    /// face). Default: 2 h.
    #[serde(default)]
    pub width: Option<Positive>,
    /// A transducer's face diameter [m]: the `<sensor>.<method>.transducer` column
    /// averages each method over the face. Default: none (a point).
    #[serde(default)]
    pub diameter: Option<Positive>,
    /// A transducer's time-filter window [s]: that column is also the mean of every
    /// step's reading over the window before each sample. Default: none.
    #[serde(default)]
    pub filter: Option<Positive>,
}

/// A wave gauge measuring the free-surface elevation on a vertical line.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GaugeSpec {
    pub name: String,
    pub x: f64,
    /// The line's z [m] (3D only).
    #[cfg(feature = "dim3")]
    pub z: f64,
}

/// Measured (or converged) series the run is compared with when it ends: `reference.md`
/// with each compared column's error, and `reference_<probe>.png` with both curves,
/// beside `probes.csv` (docs/validation.md).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceSpec {
    /// The CSV file, relative to the scenario file: time [s] in the first column, a
    /// header line naming the columns, `#` lines (its source notes) skipped.
    pub file: String,
    /// The times compared, t0 <= t <= t1 [s].
    pub window: (f64, f64),
    /// The columns compared.
    pub compare: Vec<CompareSpec>,
}

/// One `probes.csv` column against one column of the reference file.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompareSpec {
    /// The `probes.csv` column, e.g. `H2` or `P1.shepard.transducer`.
    pub probe: String,
    /// The reference file's column.
    pub data: String,
    /// An impact's arrival level, in the column's unit: the arrival is the first time
    /// each series reaches it, and the first-impact peak the largest value within
    /// `peak_within` of that. Default: none (the mean error only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arrival: Option<f64>,
    /// Seconds after the arrival the first-impact peak is sought in. Default 0.1.
    #[serde(default = "tenth")]
    pub peak_within: Positive,
}

pub(crate) fn tenth() -> Positive {
    Positive(0.1)
}

/// The scenario file's fields (docs/scenario.md documents each).
/// Read through the stage registry (`ScenarioSeed`), so it derives `Serialize` only.
#[derive(Debug, Serialize)]
#[serde(rename = "Scenario")]
pub struct ScenarioSpec {
    /// The space dimensions the scene is written for: 2 (default) or 3. The `engine`
    /// command runs the build of that dimension; a build refuses the other's scenes.
    #[serde(skip_serializing_if = "is_two")]
    pub dimensions: u32,
    pub name: String,
    /// Simulated end time [s].
    pub end_time: Positive,
    #[serde(default)]
    pub fluid: FluidSpec,
    pub resolution: Resolution,
    /// Default: Wendland.
    #[serde(default = "default_kernel")]
    pub kernel: KernelKind,
    /// h / ds. Default 1.3.
    #[serde(default = "default_h_over_dx")]
    pub h_over_dx: HOverDx,
    #[serde(default)]
    pub tank: Option<TankSpec>,
    #[serde(default)]
    pub walls: Vec<WallSpec>,
    /// Fixed solid boxes (obstacles).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub boxes: Vec<BoxSpec>,
    /// A piston wave maker (a moving vertical wall named `piston`).
    #[serde(default)]
    pub piston: Option<PistonSpec>,
    pub fluid_blocks: Vec<BlockSpec>,
    #[serde(default)]
    pub pressure_sensors: Vec<SensorSpec>,
    #[serde(default)]
    pub wave_gauges: Vec<GaugeSpec>,
    /// A frequency sweep, run by the `engine` command instead of a single run.
    #[serde(default)]
    pub sweep: Option<SweepSpec>,
    /// Reference data the run is compared with when it ends. Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<ReferenceSpec>,
    /// The ordered stages; see [`PipelineEntry`].
    #[serde(skip)]
    pub pipeline: Vec<PipelineEntry>,
}

pub(crate) fn is_two(n: &u32) -> bool {
    *n == 2
}

pub(crate) fn default_kernel() -> KernelKind {
    KernelKind::Wendland
}
pub(crate) fn default_h_over_dx() -> HOverDx {
    HOverDx(1.3)
}
