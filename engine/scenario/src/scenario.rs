//! The scenario file: schema, loader and validation.
//!
//! A scenario is one RON struct (see docs/scenario.md). Its `pipeline` is a list of
//! stages written `Name(param: value, ...)`; each stage parses its own parameters
//! through the [`StageRegistry`], directly from the file, so every error — malformed
//! RON, unknown stage or field, wrong type, out-of-range value — carries
//! `file:line:column`, the field and what would be accepted.

use crate::lexer::{lex_lenient, Shape, Tok, Token};
use crate::overrides::{apply_overrides_traced, source_offset, Override, Patch};
use glam::DVec2;
use serde::de::{
    self, DeserializeSeed, Deserializer, EnumAccess, MapAccess, VariantAccess, Visitor,
};
use serde::{Deserialize, Serialize};
use sph_core::components::{BodyPose, Density, Position, Pressure, Velocity, Wall};
use sph_core::components::{Fluid, Mass, ParticleId, PressureSensor, Tank, WaveGauge};
use sph_core::contract::{Access, Breach};
use sph_core::kernel::KernelKind;
use sph_core::motion::{Motion, MotionSeries, MotionSpec, Pose, SHORTEST_TIME};
use sph_core::piston::{Piston, PistonSpec, PISTON_WALL};
use sph_core::registry::ron_options;
use sph_core::registry::{camel_case, did_you_mean, snake_case, StageRegistry};
use sph_core::sim::{Clock, Constants, Resources, Sim, Tait};
use sph_core::stage::Stage;
use sph_core::units::{shown, Positive};
use std::cell::{Cell, RefCell};
use std::fmt;
use std::path::{Path, PathBuf};

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
    /// Gravity [m/s^2]. Default (0, -9.81).
    pub gravity: (f64, f64),
}

impl Default for FluidSpec {
    fn default() -> Self {
        Self {
            density: Positive(1000.0),
            gamma: Positive(7.0),
            sound_speed: None,
            gravity: (0.0, -9.81),
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
const PARTICLES_ACROSS: &str =
    "a whole number of particles across the first fluid block, 2 or more, e.g. ParticlesAcross(40)";

/// `ParticlesAcross(n)`'s number: a whole number from 2 to `u32::MAX`, with an error
/// that says so for anything else (-100, 40.5, "40") instead of serde's bare "Integer
/// is out of bounds".
fn particles_across<'de, D: Deserializer<'de>>(d: D) -> Result<u32, D::Error> {
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
/// walls `left`, `bottom`, `right` and, unless `open_top`, `top`. The scenario's
/// geometry (walls, blocks, sensors, gauges) is written in the tank frame; with a
/// `motion` all of it rides with the tank.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TankSpec {
    /// Inner width [m].
    pub width: Positive,
    /// Inner height [m].
    pub height: Positive,
    /// No roof. Default true.
    #[serde(default = "yes")]
    pub open_top: bool,
    /// Prescribed motion (roll, sway, heave or a CSV series). Default: fixed.
    #[serde(default)]
    pub motion: Option<MotionSpec>,
}

impl TankSpec {
    /// The roll axis: the motion's pivot, or the centre of the bottom.
    pub fn pivot(&self) -> DVec2 {
        self.motion
            .as_ref()
            .and_then(|m| m.pivot)
            .map_or(DVec2::new(0.5 * self.width.0, 0.0), DVec2::from)
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

fn six() -> Positive {
    Positive(6.0)
}
fn four() -> Positive {
    Positive(4.0)
}

fn yes() -> bool {
    true
}

/// An extra straight wall; the fluid lies on the left of the direction `from` -> `to`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallSpec {
    pub name: String,
    pub from: (f64, f64),
    pub to: (f64, f64),
}

/// A rectangle of fluid at rest, filled on a square lattice of spacing ds with
/// hydrostatic density (docs/analytic.md section 1).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlockSpec {
    /// Bottom-left corner [m].
    pub min: (f64, f64),
    /// Width and height [m].
    pub size: (Positive, Positive),
}

/// A wall pressure sensor.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    pub name: String,
    /// Name of the wall it sits on.
    pub wall: String,
    /// Sensor centre [m]; must lie on the wall.
    pub at: (f64, f64),
    /// Width along the wall [m] used by Method III. Default: 2 h.
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
}

/// The scenario file's fields (docs/scenario.md documents each).
#[derive(Debug, Serialize, Deserialize)]
#[serde(rename = "Scenario", deny_unknown_fields)]
pub struct ScenarioSpec {
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
    /// The ordered stages; see [`PipelineEntry`].
    #[serde(skip_serializing)]
    pub pipeline: Vec<PipelineEntry>,
}

fn default_kernel() -> KernelKind {
    KernelKind::Wendland
}
fn default_h_over_dx() -> HOverDx {
    HOverDx(1.3)
}

/// One stage of the pipeline, as built from the file.
pub struct PipelineEntry {
    pub name: String,
    /// Run this stage every `every` steps (written `every: N` among the stage's
    /// parameters; default 1).
    pub every: u32,
    pub stage: Box<dyn Stage>,
    /// What the stage declared it reads and writes ([`Stage::access`], asked once).
    access: Access,
    resolved: String,
}

impl PipelineEntry {
    /// The stage's declared contract.
    pub fn access(&self) -> &Access {
        &self.access
    }
}

impl fmt::Debug for PipelineEntry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{}", camel_case(&self.name), self.resolved)
    }
}

thread_local! {
    /// The registry the pipeline entries of the file being loaded are built with.
    static REGISTRY: RefCell<Option<StageRegistry>> = const { RefCell::new(None) };
}

impl<'de> Deserialize<'de> for PipelineEntry {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_enum("Stage", &[], EntryVisitor)
    }
}

struct EntryVisitor;

impl<'de> Visitor<'de> for EntryVisitor {
    type Value = PipelineEntry;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(
            f,
            "a stage written `Name(param: value, ...)`, e.g. `NeighbourGrid()`"
        )
    }
    fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<PipelineEntry, A::Error> {
        let (written, variant) = data.variant_seed(Identifier)?;
        let name = snake_case(&written);
        let registry = REGISTRY
            .with(|r| r.borrow().clone())
            .ok_or_else(|| de::Error::custom("no stage registry"))?;
        if !registry.contains(&name) {
            return Err(de::Error::custom(registry.unknown_message(&written)));
        }
        let entered = Cell::new(false);
        let params = ParamsVisitor {
            name,
            registry,
            entered: &entered,
        };
        variant.struct_variant(&[], params).map_err(|e| {
            // Refused before the parameters were reached: the stage has no `(...)`.
            if !entered.get() && e.to_string().starts_with("Expected opening `(`") {
                de::Error::custom(format!(
                    "write `{written}()`: a stage takes parentheses even without parameters"
                ))
            } else {
                e
            }
        })
    }
}

/// Reads a bare identifier (a stage name).
struct Identifier;

impl<'de> DeserializeSeed<'de> for Identifier {
    type Value = String;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<String, D::Error> {
        d.deserialize_identifier(self)
    }
}

impl Visitor<'_> for Identifier {
    type Value = String;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "a stage name")
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<String, E> {
        Ok(v.to_string())
    }
}

struct ParamsVisitor<'a> {
    name: String,
    registry: StageRegistry,
    /// Set once the parameter list has been opened.
    entered: &'a Cell<bool>,
}

impl<'de> Visitor<'de> for ParamsVisitor<'_> {
    type Value = PipelineEntry;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "the parameters of stage `{}`", camel_case(&self.name))
    }
    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<PipelineEntry, A::Error> {
        self.entered.set(true);
        let mut filtered = EveryFilter {
            inner: map,
            every: None,
        };
        let built = {
            let de = de::value::MapAccessDeserializer::new(&mut filtered);
            let mut erased = <dyn erased_serde::Deserializer>::erase(de);
            self.registry.build(&self.name, &mut erased)
        };
        let built = match built {
            Some(Ok(b)) => b,
            Some(Err(e)) => return Err(de::Error::custom(e)),
            None => return Err(de::Error::custom(self.registry.unknown_message(&self.name))),
        };
        let every = filtered.every.unwrap_or(1);
        Ok(PipelineEntry {
            name: self.name,
            every,
            access: built.stage.access(),
            stage: built.stage,
            resolved: built.resolved_params,
        })
    }
}

/// Passes a stage's parameters through, taking out the runner's own `every: N`.
struct EveryFilter<A> {
    inner: A,
    every: Option<u32>,
}

impl<'de, A: MapAccess<'de>> MapAccess<'de> for &mut EveryFilter<A> {
    type Error = A::Error;
    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, A::Error> {
        loop {
            let Some(key) = self.inner.next_key::<String>()? else {
                return Ok(None);
            };
            if key == "every" {
                let n: u32 = self.inner.next_value()?;
                if n == 0 {
                    return Err(de::Error::custom(
                        "`every` is out of range; accepted: 1 or more steps",
                    ));
                }
                self.every = Some(n);
                continue;
            }
            return seed
                .deserialize(de::value::StringDeserializer::new(key))
                .map(Some);
        }
    }
    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, A::Error> {
        self.inner.next_value_seed(seed)
    }
}

/// A scenario that failed to load: where, which field, what is accepted.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadError {
    pub file: String,
    /// 1-based; 0 when the error is not tied to a place in the file.
    pub line: usize,
    pub column: usize,
    /// The `--set` argument the error comes from (then line and column are 0): it wrote
    /// the offending text, or set the field the error names.
    pub set: Option<String>,
    pub field: Option<String>,
    pub message: String,
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if self.line > 0 {
            write!(f, ":{}:{}", self.line, self.column)?;
        }
        write!(f, ": ")?;
        if let Some(set) = &self.set {
            write!(f, "--set {set}: ")?;
        }
        if let Some(field) = &self.field {
            write!(f, "field `{field}`: ")?;
        }
        write!(f, "{}", self.message)
    }
}

impl std::error::Error for LoadError {}

/// A loaded, validated scenario with its derived constants.
#[derive(Debug)]
pub struct Scenario {
    pub spec: ScenarioSpec,
    /// Particle spacing ds [m].
    pub spacing: f64,
    /// Smoothing length h [m].
    pub h: f64,
    /// Speed of sound c_0 [m/s] (given or derived).
    pub sound_speed: f64,
    /// The tank's motion, with its series read, if the tank moves.
    pub motion: Option<Motion>,
    /// The piston's motion, if there is a piston.
    pub piston: Option<Motion>,
    /// The file it came from.
    pub source: PathBuf,
}

/// A RON parse error as a [`LoadError`]: `file:line:column`, the field it is about.
fn parse_error(doc: &Doc, file: &str, e: &ron::error::SpannedError) -> LoadError {
    let (line, column) = (e.span.start.line, e.span.start.col);
    let message = did_you_mean_in(e.code.to_string());
    let (field, message) = if matches!(e.code, ron::Error::Eof) {
        // Input ended early: about the unclosed whole, not the last field.
        (None, message)
    } else {
        name_field(doc, line, column, message)
    };
    LoadError {
        file: file.to_string(),
        line,
        column,
        set: None,
        field,
        message,
    }
}

/// Parses RON `text` (any file of the project's formats, e.g. a study) with the
/// scenario loader's options and error reporting.
pub fn parse_ron<T: serde::de::DeserializeOwned>(text: &str, file: &str) -> Result<T, LoadError> {
    ron_options()
        .from_str(text)
        .map_err(|e| parse_error(&Doc::new(text), file, &e))
}

impl Scenario {
    /// Reads, patches with `--set` overrides, parses and validates a scenario file.
    pub fn load(
        path: &Path,
        overrides: &[Override],
        registry: &StageRegistry,
    ) -> Result<Self, LoadError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| LoadError {
            file: file.clone(),
            line: 0,
            column: 0,
            set: None,
            field: None,
            message: format!("cannot read the scenario file: {e}"),
        })?;
        Self::from_str(&text, &file, overrides, registry)
    }

    /// As [`Scenario::load`], from text; `file` names it in errors.
    pub fn from_str(
        text: &str,
        file: &str,
        overrides: &[Override],
        registry: &StageRegistry,
    ) -> Result<Self, LoadError> {
        let (patched, patches) =
            apply_overrides_traced(text, overrides).map_err(|e| LoadError {
                file: file.to_string(),
                line: 0,
                column: 0,
                set: None,
                field: None,
                message: e.to_string(),
            })?;
        REGISTRY.with(|r| *r.borrow_mut() = Some(registry.clone()));
        let parsed: Result<ScenarioSpec, _> = ron_options().from_str(&patched);
        REGISTRY.with(|r| *r.borrow_mut() = None);
        let doc = Doc::new(&patched);
        let at = Locator { file, doc: &doc };
        parsed
            .map_err(|e| parse_error(&doc, file, &e))
            .and_then(|spec| validate(spec, &at, PathBuf::from(file)))
            .map_err(|e| blame_override(e, &doc, &patches, text))
    }

    /// The scenario with every default filled in, as RON text.
    pub fn resolved_ron(&self) -> String {
        let pretty = ron::ser::PrettyConfig::new().struct_names(true);
        let body = ron::ser::to_string_pretty(&self.spec, pretty).unwrap_or_default();
        let stages: Vec<String> = self
            .spec
            .pipeline
            .iter()
            .map(|p| {
                let params = p.resolved.trim_start_matches('(').trim_end_matches(')');
                let every = if p.every != 1 {
                    format!("every: {}, ", p.every)
                } else {
                    String::new()
                };
                format!("        {}({every}{params}),", camel_case(&p.name))
            })
            .collect();
        let derived = format!(
            "// derived: spacing ds = {} m, smoothing length h = {} m, sound speed c_0 = {} m/s\n",
            self.spacing, self.h, self.sound_speed
        );
        match body.rfind(')') {
            Some(close) => format!(
                "{derived}{}    pipeline: [\n{}\n    ],\n)\n",
                &body[..close],
                stages.join("\n")
            ),
            None => body,
        }
    }

    /// The value of type `T` a stage of the pipeline exposes ([`Access::exposes`]), e.g.
    /// the artificial viscosity ([`sph_core::vocab::ArtificialViscosity`]): the first stage
    /// in the list that exposes one.
    pub fn exposed<T: std::any::Any>(&self) -> Option<&T> {
        self.spec
            .pipeline
            .iter()
            .find_map(|p| p.access.exposed::<T>())
    }

    /// Walls of the scenario: the tank's, the extra ones, then the piston.
    pub fn walls(&self) -> Vec<Wall> {
        let mut walls = Vec::new();
        if let Some(t) = &self.spec.tank {
            let (w, h) = (t.width.0, t.height.0);
            let wall = |name: &str, a: (f64, f64), b: (f64, f64)| Wall {
                name: name.to_string(),
                a: DVec2::new(a.0, a.1),
                b: DVec2::new(b.0, b.1),
                body: Pose::default(),
            };
            walls.push(wall("left", (0.0, h), (0.0, 0.0)));
            walls.push(wall("bottom", (0.0, 0.0), (w, 0.0)));
            walls.push(wall("right", (w, 0.0), (w, h)));
            if !t.open_top {
                walls.push(wall("top", (w, h), (0.0, h)));
            }
        }
        for s in &self.spec.walls {
            walls.push(Wall {
                name: s.name.clone(),
                a: s.from.into(),
                b: s.to.into(),
                body: Pose::default(),
            });
        }
        if let Some(p) = &self.spec.piston {
            let height = self.spec.tank.as_ref().map_or(0.0, |t| t.height.0);
            let (a, b) = p.ends(height);
            walls.push(Wall {
                name: PISTON_WALL.into(),
                a,
                b,
                body: Pose::at_rest(DVec2::new(p.x, 0.0)),
            });
        }
        walls
    }

    /// Initial fluid particles: each block filled on a square lattice of spacing ds,
    /// first row and column ds/2 inside the block, with hydrostatic density
    /// rho(y) = rho_0 [1 + rho_0 g (H - y)/B]^(1/gamma) and mass rho(y) ds^2 so the
    /// column starts in equilibrium (docs/analytic.md section 1).
    pub fn initial_particles(&self) -> Vec<(DVec2, f64, f64)> {
        let ds = self.spacing;
        let eos = self.eos();
        let g = DVec2::from(self.spec.fluid.gravity).length();
        let mut out = Vec::new();
        for b in &self.spec.fluid_blocks {
            // Whole lattice cells only: a rounded-up count would put the last row or
            // column closer than ds/2 to a wall.
            let nx = (b.size.0 .0 / ds + 1e-9).floor() as usize;
            let ny = (b.size.1 .0 / ds + 1e-9).floor() as usize;
            let top = b.min.1 + b.size.1 .0;
            for j in 0..ny {
                for i in 0..nx {
                    let x = DVec2::new(
                        b.min.0 + (i as f64 + 0.5) * ds,
                        b.min.1 + (j as f64 + 0.5) * ds,
                    );
                    let rho = eos.density(eos.rho0 * g * (top - x.y));
                    out.push((x, rho, rho * ds * ds));
                }
            }
        }
        out
    }

    /// Height of the tallest fluid block [m].
    pub fn fluid_height(&self) -> f64 {
        self.spec
            .fluid_blocks
            .iter()
            .map(|b| b.size.1 .0)
            .fold(0.0, f64::max)
    }

    pub fn eos(&self) -> Tait {
        Tait::new(
            self.spec.fluid.density.0,
            self.sound_speed,
            self.spec.fluid.gamma.0,
        )
    }

    /// The bounding box beyond which a particle has left the domain: the walls' box
    /// widened by four kernel supports, and for an open tank twice its height upward.
    /// For a moving tank, the box swept by that box over the motion: a disc about the
    /// pivot if it rolls, grown by the largest pivot displacement.
    pub fn domain(&self) -> (DVec2, DVec2) {
        let mut lo = DVec2::splat(f64::INFINITY);
        let mut hi = DVec2::splat(f64::NEG_INFINITY);
        for w in self.walls() {
            lo = lo.min(w.a).min(w.b);
            hi = hi.max(w.a).max(w.b);
        }
        for b in &self.spec.fluid_blocks {
            lo = lo.min(DVec2::from(b.min));
            hi = hi.max(DVec2::from(b.min) + DVec2::new(b.size.0 .0, b.size.1 .0));
        }
        let margin = 4.0 * self.spec.kernel.support_factor() * self.h;
        let open = self.spec.tank.as_ref().is_none_or(|t| t.open_top);
        let extra_up = if open { hi.y - lo.y } else { 0.0 };
        let (lo, hi) = (
            lo - DVec2::splat(margin),
            hi + DVec2::new(margin, margin + extra_up),
        );
        let Some(m) = &self.motion else {
            return (lo, hi);
        };
        let grow = DVec2::splat(m.max_offset());
        if m.max_angle() == 0.0 {
            return (lo - grow, hi + grow);
        }
        let corners = [lo, hi, DVec2::new(lo.x, hi.y), DVec2::new(hi.x, lo.y)];
        let r = corners
            .iter()
            .map(|c| (*c - m.pivot).length())
            .fold(0.0, f64::max);
        let reach = DVec2::splat(r) + grow;
        (m.pivot - reach, m.pivot + reach)
    }

    /// The tank's pose at t = 0 (at rest for a fixed tank).
    pub fn initial_pose(&self) -> Pose {
        let pivot = self.spec.tank.as_ref().map_or(DVec2::ZERO, |t| t.pivot());
        self.motion
            .as_ref()
            .map_or(Pose::at_rest(pivot), |m| m.pose(0.0))
    }

    /// Builds the simulation state: fluid particles, walls, sensors and gauges as
    /// entities, the run's constants and clock.
    pub fn build_sim(&self, out_dir: PathBuf) -> Sim {
        let mut world = hecs::World::new();
        let particles = self.initial_particles();
        // Particles are laid out in the tank frame and start moving with the tank.
        let pose = self.initial_pose();
        world.spawn_batch(particles.iter().enumerate().map(|(i, &(q, rho, m))| {
            let x = pose.to_world(q);
            (
                Fluid,
                ParticleId(i as u32),
                Position(x),
                Velocity(pose.velocity_at(x)),
                Density(rho),
                Pressure(0.0),
                Mass(m),
            )
        }));
        if let Some(t) = &self.spec.tank {
            let tank = Tank {
                width: t.width.0,
                height: t.height.0,
                pivot: t.pivot(),
            };
            let pose = BodyPose(Pose::at_rest(tank.pivot));
            match &self.motion {
                Some(m) => world.spawn((tank, pose, m.clone())),
                None => world.spawn((tank, pose)),
            };
        }
        // Walls in list order (tank walls, extra walls, the piston), each with its pose
        // now; the piston also carries its own motion and the `Piston` marker.
        let mut wall_entities = Vec::new();
        for w in self.walls() {
            let name = w.name.clone();
            let now = w.at_rest();
            let entity = match (&self.piston, w.name == PISTON_WALL) {
                (Some(m), true) => {
                    let body = BodyPose(w.body);
                    world.spawn((w, now, Piston, body, m.clone()))
                }
                _ => world.spawn((w, now)),
            };
            wall_entities.push((name, entity));
        }
        for s in &self.spec.pressure_sensors {
            // Validated: the sensor's wall exists.
            let Some(&(_, wall)) = wall_entities.iter().find(|(name, _)| *name == s.wall) else {
                continue;
            };
            let along = world
                .get::<&Wall>(wall)
                .map_or(0.0, |w| w.abscissa(s.at.into()));
            let width = s.width.map_or(2.0 * self.h, |w| w.0);
            world.spawn((PressureSensor {
                name: s.name.clone(),
                wall,
                along,
                width,
                diameter: s.diameter.map_or(0.0, |d| d.0),
                filter: s.filter.map_or(0.0, |f| f.0),
            },));
        }
        for g in &self.spec.wave_gauges {
            world.spawn((WaveGauge {
                name: g.name.clone(),
                x: g.x,
            },));
        }
        // Everything where its motion has it at t = 0.
        sph_core::kinematics::place(&world, 0.0);
        Sim {
            world,
            clock: Clock {
                end_time: self.spec.end_time.0,
                ..Clock::default()
            },
            constants: Constants {
                eos: self.eos(),
                gravity: self.spec.fluid.gravity.into(),
                spacing: self.spacing,
                h: self.h,
                kernel: self.spec.kernel,
                fluid_height: self.fluid_height(),
                domain: self.domain(),
            },
            resources: Resources::default(),
            out_dir,
            name: self.spec.name.clone(),
            diagnostics: Default::default(),
        }
    }
}

/// Checks that need more than one field, and derives ds, h and c_0.
fn validate(spec: ScenarioSpec, at: &Locator, source: PathBuf) -> Result<Scenario, LoadError> {
    let first = spec.fluid_blocks.first().ok_or_else(|| {
        at.field(
            "fluid_blocks",
            "no fluid: give at least one block `(min: (x, y), size: (w, h))`".into(),
        )
    })?;
    let spacing = match spec.resolution {
        Resolution::Spacing(ds) => ds.0,
        Resolution::ParticlesAcross(n) if n >= 2 => first.size.0 .0 / n as f64,
        Resolution::ParticlesAcross(n) => {
            return Err(at.field(
                "resolution",
                format!("ParticlesAcross({n}) is out of range; accepted: 2 or more"),
            ))
        }
    };
    let count: f64 = spec
        .fluid_blocks
        .iter()
        .map(|b| (b.size.0 .0 / spacing + 1e-9).floor() * (b.size.1 .0 / spacing + 1e-9).floor())
        .sum();
    if count > MAX_PARTICLES {
        return Err(at.field(
            "resolution",
            format!("{count:.0} fluid particles would not fit; accepted: at most {MAX_PARTICLES:.0} (use a coarser resolution)"),
        ));
    }
    if count < 1.0 {
        return Err(at.field(
            "resolution",
            format!("spacing {spacing} m leaves the fluid blocks empty; use a finer resolution"),
        ));
    }
    let gravity = DVec2::from(spec.fluid.gravity);
    // Where the errors that gravity causes point.
    let gravity_place = at
        .doc
        .key(&["fluid", "gravity"])
        .or_else(|| at.doc.key(&["fluid"]));
    if !gravity.is_finite() {
        return Err(at.error(
            "gravity",
            gravity_place,
            format!(
                "({}, {}) is out of range; accepted: two finite numbers [m/s^2], e.g. (0.0, -9.81)",
                gravity.x, gravity.y
            ),
        ));
    }
    let g = gravity.length();
    let tallest = spec
        .fluid_blocks
        .iter()
        .map(|b| b.size.1 .0)
        .fold(0.0, f64::max);
    let sound_speed = match spec.fluid.sound_speed {
        Some(c) => c.0,
        None if g > 0.0 => 10.0 * (2.0 * g * tallest).sqrt(),
        None => {
            // The cause is the zero gravity: point there.
            return Err(at.error(
                "sound_speed",
                gravity_place,
                "cannot be derived without gravity; give `sound_speed: <m/s>`".into(),
            ));
        }
    };
    if !sound_speed.is_finite() {
        // Only a derived speed can be infinite (a given one is checked finite): the
        // gravity is too large for 10 sqrt(2 g H).
        return Err(at.error(
            "gravity",
            gravity_place,
            format!(
                "|g| = {g} m/s^2 gives the derived sound speed 10 sqrt(2 g H) = {sound_speed} m/s; give `sound_speed: <m/s>` or a smaller gravity"
            ),
        ));
    }
    // The Tait equation p = B ((rho/rho_0)^gamma - 1): gamma from the gas-like 1 to
    // beyond water's 7, and a stiffness B = rho_0 c_0^2 / gamma that is a number (a
    // density or sound speed near the largest float made it infinite, and the
    // pressures NaN).
    let fluid_place = |key: &str| {
        at.doc
            .key(&["fluid", key])
            .or_else(|| at.doc.key(&["fluid"]))
    };
    let gamma = spec.fluid.gamma.0;
    if !(1.0..=20.0).contains(&gamma) {
        return Err(at.error(
            "gamma",
            fluid_place("gamma"),
            format!(
                "{} is out of range; accepted: 1 to 20 (7 for water)",
                shown(gamma)
            ),
        ));
    }
    let stiffness = spec.fluid.density.0 * sound_speed * sound_speed / gamma;
    if !(stiffness.is_finite() && stiffness > 0.0) {
        return Err(at.error(
            "sound_speed",
            fluid_place("sound_speed"),
            format!(
                "density {} kg/m^3 and sound speed {} m/s give the Tait stiffness rho_0 c_0^2 / gamma = {} Pa; accepted: a finite, positive stiffness (water: 998 kg/m^3, 10-100 m/s)",
                shown(spec.fluid.density.0),
                shown(sound_speed),
                shown(stiffness)
            ),
        ));
    }
    let motion = match spec
        .tank
        .as_ref()
        .and_then(|t| t.motion.as_ref().map(|m| (t, m)))
    {
        Some((tank, m)) => Some(motion(tank, m, at, &source)?),
        None => None,
    };
    let piston = match &spec.piston {
        Some(p) => Some(piston(&spec, p, at, &source)?),
        None => None,
    };
    let scenario = Scenario {
        h: spec.h_over_dx.0 * spacing,
        spacing,
        sound_speed,
        motion,
        piston,
        spec,
        source,
    };
    let walls = scenario.walls();
    // The tank's walls come first, then the `walls` list's elements, then the piston.
    let piston_walls = scenario.spec.piston.is_some() as usize;
    let tank_walls = walls.len() - scenario.spec.walls.len() - piston_walls;
    let wall_place = |i: usize, key: &str| {
        if i + piston_walls >= walls.len() && piston_walls > 0 {
            return at.doc.key(&["piston"]);
        }
        match i.checked_sub(tank_walls) {
            Some(k) => at.element("walls", k, key),
            None => at.doc.key(&["walls"]),
        }
    };
    for (i, w) in walls.iter().enumerate() {
        if w.length() == 0.0 {
            return Err(at.error(
                "walls",
                wall_place(i, "to"),
                format!("wall `{}` has zero length", w.name),
            ));
        }
        if walls[..i].iter().any(|o| o.name == w.name) {
            return Err(at.error(
                "walls",
                wall_place(i, "name"),
                format!("two walls are named `{}`; names must be unique", w.name),
            ));
        }
    }
    for (i, b) in scenario.spec.fluid_blocks.iter().enumerate() {
        if !(b.min.0.is_finite() && b.min.1.is_finite()) {
            return Err(at.error(
                "min",
                at.element("fluid_blocks", i, "min"),
                format!(
                    "({}, {}) is out of range; accepted: two finite coordinates [m]",
                    b.min.0, b.min.1
                ),
            ));
        }
    }
    // Every particle must start on the fluid side of every wall it lies alongside.
    for (x, _, _) in scenario.initial_particles() {
        for w in &walls {
            let s = w.abscissa(x);
            if w.distance(x) < 0.0 && s >= 0.0 && s <= w.length() {
                return Err(at.field(
                    "fluid_blocks",
                    format!(
                        "particle at ({:.4}, {:.4}) m starts outside wall `{}`; blocks must lie inside the walls",
                        x.x, x.y, w.name
                    ),
                ));
            }
        }
        if let Some(t) = &scenario.spec.tank {
            if x.x < 0.0 || x.x > t.width.0 || x.y < 0.0 || x.y > t.height.0 {
                return Err(at.field(
                    "fluid_blocks",
                    format!(
                        "particle at ({:.4}, {:.4}) m lies outside the tank (0..{} m by 0..{} m)",
                        x.x, x.y, t.width.0, t.height.0
                    ),
                ));
            }
        }
    }
    let names: Vec<&str> = walls.iter().map(|w| w.name.as_str()).collect();
    for (i, s) in scenario.spec.pressure_sensors.iter().enumerate() {
        let Some(w) = walls.iter().find(|w| w.name == s.wall) else {
            return Err(at.error(
                "pressure_sensors",
                at.element("pressure_sensors", i, "wall"),
                format!(
                    "sensor `{}` is on wall `{}`, which does not exist; walls are: {}",
                    s.name,
                    s.wall,
                    names.join(", ")
                ),
            ));
        };
        let p = DVec2::from(s.at);
        // Written so that a NaN coordinate fails it.
        let on_wall =
            w.distance(p).abs() <= 1e-6 && w.abscissa(p) >= 0.0 && w.abscissa(p) <= w.length();
        if !on_wall {
            return Err(at.error(
                "pressure_sensors",
                at.element("pressure_sensors", i, "at"),
                format!(
                    "sensor `{}` at ({}, {}) is not on wall `{}`; put `at` on the wall",
                    s.name, p.x, p.y, w.name
                ),
            ));
        }
    }
    for (i, g) in scenario.spec.wave_gauges.iter().enumerate() {
        if !g.x.is_finite() {
            return Err(at.error(
                "x",
                at.element("wave_gauges", i, "x"),
                format!(
                    "gauge `{}` at x = {} is out of range; accepted: a finite abscissa [m]",
                    g.name, g.x
                ),
            ));
        }
    }
    if let Some(sweep) = &scenario.spec.sweep {
        let place = |key: &str| {
            at.doc
                .key(&["sweep", key])
                .or_else(|| at.doc.key(&["sweep"]))
        };
        let rolls = scenario
            .spec
            .tank
            .as_ref()
            .and_then(|t| t.motion.as_ref())
            .is_some_and(|m| m.roll.is_some());
        if !rolls {
            return Err(at.error(
                "sweep",
                place("omega"),
                "a sweep varies the roll frequency; give the tank a `motion: (roll: (amplitude: <deg>, period: <s>))`".into(),
            ));
        }
        if sweep.omega.is_empty() {
            return Err(at.error(
                "omega",
                place("omega"),
                "no frequencies; accepted: a list of roll frequencies [rad/s], e.g. [2.0, 2.5, 3.0]".into(),
            ));
        }
    }
    if scenario.spec.pipeline.is_empty() {
        return Err(at.field(
            "pipeline",
            "the pipeline is empty; list the stages to run".into(),
        ));
    }
    check_contracts(&scenario.spec.pipeline, at)?;
    // A number still NaN or infinite (a field without a range check of its own) is
    // refused at the first such token of the text, naming the field it stands in.
    if non_finite_number(&scenario.resolved_ron()) {
        // `NaN`, `inf`, or a literal beyond f64's range (1e309 reads as inf).
        let token = (0..at.doc.toks.len()).find(|&i| {
            let n = at.doc.name(i);
            matches!(n, "NaN" | "inf") || n.parse::<f64>().is_ok_and(|v| v.is_infinite())
        });
        let field = token
            .and_then(|i| at.doc.field_before(at.doc.toks[i].start))
            .unwrap_or_else(|| "fluid".into());
        let value = token.map_or("a non-finite number", |i| at.doc.name(i));
        return Err(at.error(
            &field,
            token,
            format!("{value} is out of range; accepted: a finite number"),
        ));
    }
    Ok(scenario)
}

/// Whether RON `text` holds a NaN or an infinity as a number (the tokens `NaN` and
/// `inf` outside string quotes), e.g. [`Scenario::resolved_ron`]'s.
pub fn non_finite_number(text: &str) -> bool {
    let mut quoted = false;
    let mut token = String::new();
    for c in text.chars().chain(std::iter::once(' ')) {
        if c == '"' {
            quoted = !quoted;
        }
        if !quoted && (c.is_ascii_alphanumeric() || c == '_' || c == '.') {
            token.push(c);
            continue;
        }
        if token == "NaN" || token == "inf" {
            return true;
        }
        token.clear();
    }
    false
}

/// The declared contracts over the whole pipeline ([`sph_core::contract::check`]), as an
/// error placed at the offending stage's entry.
fn check_contracts(pipeline: &[PipelineEntry], at: &Locator) -> Result<(), LoadError> {
    let stages = pipeline.iter().map(|e| (&e.access, e.every));
    let Err(breach) = sph_core::contract::check(stages) else {
        return Ok(());
    };
    let entry = |k: usize| at.doc.element(&["pipeline"], k, "");
    let name = |k: usize| camel_case(&pipeline[k].name);
    let line = |k: usize| entry(k).map_or(0, |t| at.doc.line_col(t).0);
    let (k, field, message) = match breach {
        Breach::TwoWriters {
            quantity,
            first,
            second,
        } => (
            Some(second),
            "pipeline",
            format!(
                "{} writes `{}`, which {} (line {}) writes too; a quantity has one writer: remove one of them",
                name(second),
                quantity.name(),
                name(first),
                line(first)
            ),
        ),
        Breach::Unwritten {
            quantity,
            reader,
            update,
            later,
        } => {
            let how = if update { "updates" } else { "reads" };
            let fix = match later {
                Some(w) => format!(
                    "{} (line {}) writes it later in the step: put {} before {}",
                    name(w),
                    line(w),
                    name(w),
                    name(reader)
                ),
                None => format!(
                    "no stage of the pipeline writes it: add the stage that does before {}",
                    name(reader)
                ),
            };
            (
                Some(reader),
                "pipeline",
                format!(
                    "{} {how} `{}`, which no stage before it writes; {fix}",
                    name(reader),
                    quantity.name()
                ),
            )
        }
        Breach::ClockNotEveryStep { stage, every } => {
            let place = at.doc.element(&["pipeline"], stage, "every");
            return Err(at.error(
                "every",
                place.or_else(|| at.doc.key(&["pipeline"])),
                format!(
                    "{0}(every: {every}) would leave the clock standing on the other steps; accepted: {0} runs every step (every: 1), as the stage that advances the clock",
                    name(stage)
                ),
            ));
        }
        Breach::NoClock => (
            None,
            "pipeline",
            "no stage advances the clock (none declares it among its writes): add Integrate() to the pipeline".into(),
        ),
    };
    let place = k.and_then(entry).or_else(|| at.doc.key(&["pipeline"]));
    Err(at.error(field, place, message))
}

/// The piston's motion, checked against the tank.
fn piston(
    spec: &ScenarioSpec,
    p: &PistonSpec,
    at: &Locator,
    source: &Path,
) -> Result<Motion, LoadError> {
    let place = |key: &str| {
        at.doc
            .key(&["piston", key])
            .or_else(|| at.doc.key(&["piston"]))
    };
    let Some(tank) = &spec.tank else {
        return Err(at.error(
            "piston",
            place("x"),
            "a piston needs a `tank` (it stands on the tank's floor)".into(),
        ));
    };
    if tank.motion.is_some() {
        return Err(at.error(
            "piston",
            place("x"),
            "a piston in a moving tank is not supported; remove the tank's `motion` or the piston"
                .into(),
        ));
    }
    if !(p.x > 0.0 && p.x < tank.width.0) {
        return Err(at.error(
            "x",
            place("x"),
            format!(
                "{} is out of range; accepted: inside the tank, 0 < x < {} m",
                p.x, tank.width.0
            ),
        ));
    }
    if p.height.is_some_and(|h| h.0 > tank.height.0) {
        return Err(at.error(
            "height",
            place("height"),
            format!("accepted: up to the tank's height, {} m", tank.height.0),
        ));
    }
    let m = p
        .motion(source)
        .map_err(|(field, message)| at.error(field, place(field), message))?;
    // The paddle must stay in the tank: behind it is the tank's left wall.
    if m.max_offset() >= p.x {
        return Err(at.error(
            "stroke",
            place("stroke"),
            format!(
                "the paddle would travel {:.4} m back from x = {} m, through the tank's left wall; move `x` right or reduce the stroke",
                m.max_offset(),
                p.x
            ),
        ));
    }
    Ok(m)
}

/// The tank's motion, with its CSV series read (relative to the scenario file).
fn motion(
    tank: &TankSpec,
    m: &MotionSpec,
    at: &Locator,
    source: &Path,
) -> Result<Motion, LoadError> {
    let place = |key: &str| {
        at.doc
            .key(&["tank", "motion", key])
            .or_else(|| at.doc.key(&["tank", "motion"]))
    };
    let series = match &m.series {
        Some(file) => {
            if m.roll.is_some() || m.sway.is_some() || m.heave.is_some() || m.tilt != 0.0 {
                return Err(at.error(
                    "series",
                    place("series"),
                    "a motion series replaces tilt, roll, sway and heave; give either the series or the harmonics".into(),
                ));
            }
            let path = source.parent().unwrap_or(Path::new(".")).join(file);
            Some(
                MotionSeries::read(&path, false)
                    .map_err(|e| at.error("series", place("series"), e))?,
            )
        }
        None => None,
    };
    if let Some(r) = m.ramp {
        if !(r == 0.0 || (r >= SHORTEST_TIME && r.is_finite())) {
            return Err(at.error(
                "ramp",
                place("ramp"),
                format!(
                    "{} is out of range; accepted: 0 (no ramp) or seconds from {}",
                    shown(r),
                    shown(SHORTEST_TIME)
                ),
            ));
        }
    }
    for (key, h) in [("roll", &m.roll), ("sway", &m.sway), ("heave", &m.heave)] {
        if h.as_ref()
            .is_some_and(|h| !h.amplitude.is_finite() || !h.phase.is_finite())
        {
            return Err(at.error(
                key,
                place(key),
                "amplitude and phase must be finite numbers".into(),
            ));
        }
        if let Some(period) = h
            .as_ref()
            .map(|h| h.period.0)
            .filter(|p| *p < SHORTEST_TIME)
        {
            return Err(at.error(
                key,
                place(key),
                format!(
                    "period {} s is out of range; accepted: seconds from {}",
                    shown(period),
                    shown(SHORTEST_TIME)
                ),
            ));
        }
    }
    if !m.tilt.is_finite() || m.tilt.abs() >= 90.0 {
        return Err(at.error(
            "tilt",
            place("tilt"),
            format!(
                "{} is out of range; accepted: degrees between -90 and 90",
                m.tilt
            ),
        ));
    }
    Ok(Motion::new(m, tank.pivot(), series))
}

/// Builds the errors of [`validate`]: each names its field and points at a token of
/// the file (or nowhere, line 0, when there is none to point at).
struct Locator<'a> {
    file: &'a str,
    doc: &'a Doc<'a>,
}

impl Locator<'_> {
    /// An error about `field`, placed at token `place`.
    fn error(&self, field: &str, place: Option<usize>, message: String) -> LoadError {
        let (line, column) = place.map_or((0, 0), |t| self.doc.line_col(t));
        LoadError {
            file: self.file.to_string(),
            line,
            column,
            set: None,
            field: Some(field.to_string()),
            message,
        }
    }

    /// An error about the top-level `field`, placed at its `field:`.
    fn field(&self, field: &str, message: String) -> LoadError {
        self.error(field, self.doc.key(&[field]), message)
    }

    /// Where field `key` of element `i` of the top-level list `list` is, else the
    /// list's own `list:`.
    fn element(&self, list: &str, i: usize, key: &str) -> Option<usize> {
        self.doc
            .element(&[list], i, key)
            .or_else(|| self.doc.key(&[list]))
    }
}

/// An error an override caused, told as the override's (`--set ARG: ...`, no place in
/// the file, which does not hold that text): the newest override whose text holds the
/// error's place; else the newest that set the field the error names, when the error
/// points inside what holds that field (a stage's range check points at the end of the
/// stage's parentheses) or nowhere; else the newest whose path passes through the
/// field the error names (a term's check names `terms`), pointing inside what holds
/// it, when the message names what the override set. Any other error's place in the
/// patched text is moved back to its place in `source`, the file.
fn blame_override(mut e: LoadError, doc: &Doc, patches: &[Patch], source: &str) -> LoadError {
    let at = (e.line > 0).then(|| doc.offset(e.line, e.column));
    let field = e.field.as_deref();
    let inside = |r: &std::ops::Range<usize>| at.is_some_and(|o| r.start <= o && o < r.end);
    let names = |p: &Patch| {
        p.field().is_some_and(|f| {
            e.message.contains(&format!("`{f}`")) || e.message.contains(&camel_case(f))
        })
    };
    let sets_field = |p: &&Patch| {
        p.holders.iter().enumerate().any(|(i, (seg, holder))| {
            let last = i + 1 == p.holders.len();
            field == Some(seg.as_str())
                && (inside(holder) || (last && at.is_none()))
                && (last || names(p))
        })
    };
    let patch = patches
        .iter()
        .rev()
        .find(|p| inside(&p.span))
        .or_else(|| patches.iter().rev().find(sets_field));
    match (patch, at) {
        (Some(p), _) => {
            e.set = Some(p.raw.clone());
            (e.line, e.column) = (0, 0);
        }
        (None, Some(at)) if !patches.is_empty() => {
            let offset = source_offset(at, patches).min(source.len());
            let before = source.get(..offset).unwrap_or(source);
            let line_start = before.rfind('\n').map_or(0, |n| n + 1);
            e.line = before.matches('\n').count() + 1;
            e.column = before[line_start..].chars().count() + 1;
        }
        _ => {}
    }
    e
}

/// The field a RON error is about, and its message without a duplicated field name.
fn name_field(doc: &Doc, line: usize, column: usize, message: String) -> (Option<String>, String) {
    if let Some((field, rest)) = leading_field(&message) {
        return (Some(field), rest);
    }
    if let Some(field) = unknown_field(&message) {
        return (Some(field), message);
    }
    (doc.field_before(doc.offset(line, column)), message)
}

/// A message written "field `x` = v is out of range; ..." (or "field `x`: ...") as
/// (`x`, "v is out of range; ...").
fn leading_field(message: &str) -> Option<(String, String)> {
    let rest = message.strip_prefix("field `")?;
    let end = rest.find('`')?;
    let name = &rest[..end];
    if name.is_empty() || !name.chars().all(|c| c.is_alphanumeric() || c == '_') {
        return None;
    }
    let after = &rest[end + 1..];
    let after = after
        .strip_prefix(" = ")
        .or_else(|| after.strip_prefix(": "))
        .unwrap_or(after)
        .trim_start();
    if after.is_empty() {
        return None;
    }
    Some((name.to_string(), after.to_string()))
}

/// The field named by an unknown-field message: ron's "Unexpected field named `x`
/// ..." or serde's "unknown field `x`, ...".
fn unknown_field(message: &str) -> Option<String> {
    let rest = ["Unexpected field named `", "unknown field `"]
        .iter()
        .find_map(|p| message.strip_prefix(p))?;
    let name = &rest[..rest.find('`')?];
    let name = name.strip_prefix("r#").unwrap_or(name);
    (!name.is_empty()).then(|| name.to_string())
}

/// An unknown-name message (ron's "Unexpected field named `alfa`, expected either
/// `alpha` or `beta` instead", "Unexpected variant named ...", serde's "unknown field
/// `x`, expected one of ...") with the nearest expected name offered:
/// "...; did you mean `alpha`?". Other messages, and names nowhere near any expected
/// one, are returned unchanged.
fn did_you_mean_in(message: String) -> String {
    let written = unknown_field(&message).or_else(|| {
        let rest = [
            "Unexpected variant named `",
            "Unexpected enum variant named `",
            "unknown variant `",
        ]
        .iter()
        .find_map(|p| message.strip_prefix(p))?;
        Some(rest[..rest.find('`')?].to_string())
    });
    let (Some(written), Some(at)) = (written, message.find(", expected")) else {
        return message;
    };
    let expected = message[at..].split('`').skip(1).step_by(2);
    match did_you_mean(&written, expected.filter(|n| !n.is_empty())) {
        Some(name) => format!("{message}; did you mean `{name}`?"),
        None => message,
    }
}

/// The scenario text as tokens, comments and whitespace left out, so that places in it
/// can be found by structure: the `name:` of a field, the n-th element of a list.
/// Lenient: any text tokenizes (unterminated strings and comments run to the end).
struct Doc<'a> {
    text: &'a str,
    toks: Vec<Token>,
}

impl<'a> Doc<'a> {
    fn new(text: &'a str) -> Self {
        Self {
            text,
            toks: lex_lenient(text),
        }
    }

    /// The text of token `i`.
    fn name(&self, i: usize) -> &str {
        let t = self.toks[i];
        let name = self.text.get(t.start..t.end).unwrap_or("");
        name.strip_prefix("r#").unwrap_or(name)
    }

    /// Whether token `i` is a field name: an identifier followed by `:`.
    fn is_key(&self, i: usize) -> bool {
        self.toks[i].tok == Tok::Ident && self.toks.get(i + 1).is_some_and(|t| t.tok == Tok::Colon)
    }

    /// Token of the field `path[last]` inside ... inside the top-level `path[0]`.
    fn key(&self, path: &[&str]) -> Option<usize> {
        let (mut lo, mut hi, mut depth) = (0, self.toks.len(), 1);
        let mut found = None;
        for name in path {
            let i = (lo..hi).find(|&i| {
                self.toks[i].depth == depth && self.is_key(i) && self.name(i) == *name
            })?;
            found = Some(i);
            lo = i + 2;
            hi = self.value_end(lo, depth);
            depth += 1;
        }
        found
    }

    /// End (exclusive token index) of the value starting at token `from`, at `depth`.
    fn value_end(&self, from: usize, depth: usize) -> usize {
        (from..self.toks.len())
            .find(|&j| {
                let t = self.toks[j];
                (t.tok == Tok::Comma && t.depth == depth)
                    || (matches!(t.tok, Tok::Close(_)) && t.depth < depth)
            })
            .unwrap_or(self.toks.len())
    }

    /// Token of field `key` in element `n` of the list at `path`, or else of the
    /// element itself.
    fn element(&self, path: &[&str], n: usize, key: &str) -> Option<usize> {
        let open = self.key(path)? + 2;
        let list = self.toks.get(open)?;
        if list.tok != Tok::Open(Shape::List) {
            return None;
        }
        let depth = list.depth + 1;
        let (mut count, mut at_start) = (0, true);
        for j in open + 1..self.toks.len() {
            let t = self.toks[j];
            if t.depth < depth {
                return None;
            }
            if t.tok == Tok::Comma && t.depth == depth {
                count += 1;
                at_start = true;
            } else if at_start {
                if count == n {
                    return Some(self.key_within(j, key).unwrap_or(j));
                }
                at_start = false;
            }
        }
        None
    }

    /// Token of field `key` directly inside the struct starting at token `start`
    /// (`(...)` or `Name(...)`).
    fn key_within(&self, start: usize, key: &str) -> Option<usize> {
        let open = match self.toks[start].tok {
            Tok::Open(_) => start,
            Tok::Ident if matches!(self.toks.get(start + 1)?.tok, Tok::Open(_)) => start + 1,
            _ => return None,
        };
        let depth = self.toks[open].depth + 1;
        (open + 1..self.toks.len())
            .take_while(|&j| self.toks[j].depth >= depth)
            .find(|&j| self.toks[j].depth == depth && self.is_key(j) && self.name(j) == key)
    }

    /// The field whose value byte `offset` falls in: the last `name:` before it at
    /// the same or an enclosing level (a `,` ends a field's value; groups closed
    /// before `offset` are skipped).
    fn field_before(&self, offset: usize) -> Option<String> {
        let mut stack: Vec<Option<usize>> = vec![None];
        for (i, t) in self.toks.iter().enumerate() {
            if t.start >= offset {
                break;
            }
            match t.tok {
                Tok::Open(_) => stack.push(None),
                Tok::Close(_) if stack.len() > 1 => {
                    stack.pop();
                }
                Tok::Comma => {
                    if let Some(top) = stack.last_mut() {
                        *top = None;
                    }
                }
                Tok::Ident if self.is_key(i) => {
                    if let Some(top) = stack.last_mut() {
                        *top = Some(i);
                    }
                }
                _ => {}
            }
        }
        let key = stack.iter().rev().find_map(|k| *k)?;
        Some(self.name(key).to_string())
    }

    /// Byte offset of a 1-based line and column (columns count characters, as ron's
    /// do); the end of the text when past it.
    fn offset(&self, line: usize, column: usize) -> usize {
        let mut offset = 0;
        for (i, l) in self.text.split_inclusive('\n').enumerate() {
            if i + 1 == line {
                let col = column.saturating_sub(1);
                return offset + l.char_indices().nth(col).map_or(l.len(), |(b, _)| b);
            }
            offset += l.len();
        }
        self.text.len()
    }

    /// 1-based line and column (in characters) of token `i` (of the name of a raw
    /// identifier `r#name`).
    fn line_col(&self, i: usize) -> (usize, usize) {
        let t = self.toks[i];
        let raw = self
            .text
            .get(t.start..t.end)
            .is_some_and(|s| s.starts_with("r#"));
        let start = t.start + if raw { 2 } else { 0 };
        let before = self.text.get(..start).unwrap_or("");
        let line = before.matches('\n').count() + 1;
        let line_start = before.rfind('\n').map_or(0, |n| n + 1);
        (line, before[line_start..].chars().count() + 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DAM: &str = include_str!("../../../scenarios/dam_break.ron");

    #[test]
    fn places_skip_comments_strings_and_other_levels() {
        let text = "// a: 1\n(\n  /* b: /* nested */ 2 */ a: \"c: (\", b: [(x: 1), (x: 2, y: 'x')],\n  c: r#\"d: ]\"#,\n)";
        let doc = Doc::new(text);
        assert_eq!(doc.key(&["a"]).map(|t| doc.line_col(t)), Some((3, 27)));
        assert_eq!(doc.key(&["c"]).map(|t| doc.line_col(t)), Some((4, 3)));
        assert_eq!(doc.key(&["x"]), None);
        let y = doc.element(&["b"], 1, "y").map(|t| doc.line_col(t));
        assert_eq!(y, Some((3, 57)));
        // Inside the second element, after `x: 2,`: the enclosing field is `b`.
        let at = text.find("y:").unwrap();
        assert_eq!(doc.field_before(at).as_deref(), Some("b"));
        assert_eq!(doc.field_before(at - 2).as_deref(), Some("x"));
    }

    #[test]
    fn leading_field_is_not_repeated() {
        let (field, message) = leading_field("field `courant` = 2 is out of range").unwrap();
        assert_eq!(
            (field.as_str(), message.as_str()),
            ("courant", "2 is out of range")
        );
        assert_eq!(
            unknown_field("Unexpected field named `alfa`, expected `alpha`").as_deref(),
            Some("alfa")
        );
    }

    /// No prefix of the shipped scenario, nor of odd text, panics the loader.
    #[test]
    fn truncated_and_odd_input_never_panics() {
        let registry = StageRegistry::new();
        let odd = "(a: \"\\\", b: r##\"x\"#, c: 'é', d: '\\'', e: /* /* */ é: [(, ]}} ) r#ü: b\"";
        for text in [DAM, odd] {
            for (end, _) in text.char_indices() {
                let part = &text[..end];
                let _ = Scenario::from_str(part, "t.ron", &[], &registry);
                let doc = Doc::new(part);
                for (line, column) in [(1, 1), (3, 200), (500, 1), (0, 0)] {
                    let _ = doc.field_before(doc.offset(line, column));
                }
                let _ = doc.element(&["pressure_sensors"], 1, "wall");
                let _ = doc.key(&["fluid", "gravity"]);
            }
        }
    }
}
