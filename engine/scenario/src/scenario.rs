//! The scenario file: schema, loader and validation.
//!
//! A scenario is one RON struct (see docs/scenario.md). Its `pipeline` is a list of
//! stages written `Name(param: value, ...)`; each stage parses its own parameters
//! through the [`StageRegistry`], directly from the file, so every error — malformed
//! RON, unknown stage or field, wrong type, out-of-range value — carries
//! `file:line:column`, the field and what would be accepted.

mod schema;
pub use schema::*;
mod entry;
pub use entry::*;
mod validate;
pub use validate::*;
mod positions;
pub(crate) use positions::*;

use crate::lexer::{lex_lenient, Shape, Tok, Token};
use crate::overrides::{apply_overrides_traced, source_offset, Override, Patch};
use serde::de::{
    self, DeserializeSeed, Deserializer, EnumAccess, MapAccess, VariantAccess, Visitor,
};
use serde::{Deserialize, Serialize};
use sph_core::components::{BodyPose, Density, Position, Pressure, Velocity, Wall};
use sph_core::components::{Fluid, Mass, ParticleId, PressureSensor, Tank, WaveGauge};
use sph_core::contract::{Access, Breach};
use sph_core::dim::{self, Coords, Vector};
use sph_core::kernel::KernelKind;
use sph_core::motion::{Motion, MotionSeries, MotionSpec, Pose, SHORTEST_TIME};
use sph_core::piston::{Piston, PistonSpec, PISTON_WALL};
use sph_core::registry::{camel_case, did_you_mean, snake_case, StageRegistry};
use sph_core::registry::{ron_options, Identifier, SeqOf};
use sph_core::sim::{Clock, Constants, Resources, Sim, Tait};
use sph_core::stage::Stage;
use sph_core::units::{shown, Positive};
use std::cell::Cell;
use std::fmt;
use std::path::{Path, PathBuf};

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

/// The space dimensions scenario `text` (with `overrides` applied) is written for: its
/// top-level `dimensions` field, or 2 without one. Lenient: text that does not parse
/// reads as 2, and the loader of that build reports what is wrong with it.
pub fn dimensions_of(text: &str, overrides: &[Override]) -> u32 {
    let patched =
        apply_overrides_traced(text, overrides).map_or_else(|_| text.to_string(), |p| p.0);
    let doc = Doc::new(&patched);
    doc.key(&["dimensions"])
        .and_then(|k| (k + 2 < doc.toks.len()).then(|| doc.name(k + 2).parse().ok()))
        .flatten()
        .unwrap_or(2)
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
        let doc = Doc::new(&patched);
        let at = Locator { file, doc: &doc };
        // Before the rest: a scene of the other dimension fails on its first vector.
        let dimensions = dimensions_of(&patched, &[]);
        if dimensions as usize != dim::DIM {
            let how = match dimensions {
                2 | 3 => format!(
                    "this is the {}D build; the `engine` command runs each scene in the build its `dimensions` names",
                    dim::DIM
                ),
                _ => "accepted: 2 or 3".into(),
            };
            let e = at.field(
                "dimensions",
                format!("{dimensions} is not {}: {how}", dim::DIM),
            );
            return Err(blame_override(e, &doc, &patches, text));
        }
        let parsed = ron_options().from_str_seed(&patched, ScenarioSeed(registry));
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

    /// Walls of the scenario: the tank's, the extra ones, the boxes' faces, then the
    /// piston.
    pub fn walls(&self) -> Vec<Wall> {
        let mut walls = Vec::new();
        if let Some(t) = &self.spec.tank {
            walls.extend(tank_walls(t));
        }
        for s in &self.spec.walls {
            walls.push(Wall {
                name: s.name.clone(),
                a: s.from.into(),
                b: s.to.into(),
                #[cfg(feature = "dim3")]
                c: s.across.into(),
                body: Pose::default(),
            });
        }
        for b in &self.spec.boxes {
            walls.extend(box_faces(b, self.spec.tank.as_ref()));
        }
        if let Some(p) = &self.spec.piston {
            let height = self.spec.tank.as_ref().map_or(0.0, |t| t.height.0);
            let (a, b) = p.ends(height);
            walls.push(Wall {
                name: PISTON_WALL.into(),
                a,
                b,
                // 3D: across the tank's breadth, from its z = 0 wall, with the fluid
                // on the side of (c - a) x (b - a) = +x, as in 2D.
                #[cfg(feature = "dim3")]
                c: a + Vector::new(
                    0.0,
                    0.0,
                    self.spec.tank.as_ref().map_or(0.0, |t| t.breadth.0),
                ),
                body: Pose::at_rest(dim::xy(p.x, 0.0)),
            });
        }
        walls
    }

    /// Initial fluid particles: each block filled on a square (3D: cubic) lattice of
    /// spacing ds, first row and column ds/2 inside the block, with hydrostatic density
    /// rho(y) = rho_0 [1 + rho_0 g (H - y)/B]^(1/gamma) and mass rho(y) ds^DIM so the
    /// column starts in equilibrium (docs/analytic.md section 1).
    pub fn initial_particles(&self) -> Vec<(Vector, f64, f64)> {
        let ds = self.spacing;
        let eos = self.eos();
        let g = Vector::from(self.spec.fluid.gravity).length();
        let mut out = Vec::new();
        for b in &self.spec.fluid_blocks {
            // Whole lattice cells only: a rounded-up count would put the last row or
            // column closer than ds/2 to a wall.
            let size = extent(&b.size);
            let n = |k: usize| (size[k] / ds + 1e-9).floor() as usize;
            let min = Vector::from(b.min);
            let top = min.y + size.y;
            let layers = if dim::DIM == 3 { n(dim::DIM - 1) } else { 1 };
            for l in 0..layers {
                for j in 0..n(1) {
                    for i in 0..n(0) {
                        let mut x = min + dim::xy((i as f64 + 0.5) * ds, (j as f64 + 0.5) * ds);
                        if dim::DIM == 3 {
                            x[dim::DIM - 1] += (l as f64 + 0.5) * ds;
                        }
                        let rho = eos.density(eos.rho0 * g * (top - x.y));
                        // rho ds ds (ds) in this order: 2D's masses as they always were.
                        let mass = rho * ds * ds;
                        let mass = if dim::DIM == 3 { mass * ds } else { mass };
                        out.push((x, rho, mass));
                    }
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
    /// pivot if it rolls (a ball if it pitches), grown by the largest pivot
    /// displacement.
    pub fn domain(&self) -> (Vector, Vector) {
        let mut lo = Vector::splat(f64::INFINITY);
        let mut hi = Vector::splat(f64::NEG_INFINITY);
        for w in self.walls() {
            lo = lo.min(w.a).min(w.b);
            hi = hi.max(w.a).max(w.b);
            #[cfg(feature = "dim3")]
            {
                let far = w.b + w.c - w.a;
                (lo, hi) = (lo.min(w.c).min(far), hi.max(w.c).max(far));
            }
        }
        for b in &self.spec.fluid_blocks {
            lo = lo.min(Vector::from(b.min));
            hi = hi.max(Vector::from(b.min) + extent(&b.size));
        }
        let margin = 4.0 * self.spec.kernel.support_factor() * self.h;
        let open = self.spec.tank.as_ref().is_none_or(|t| t.open_top);
        let extra_up = if open { hi.y - lo.y } else { 0.0 };
        let mut up = Vector::splat(margin);
        up.y += extra_up;
        let (lo, hi) = (lo - Vector::splat(margin), hi + up);
        let Some(m) = &self.motion else {
            return (lo, hi);
        };
        let grow = Vector::splat(m.max_offset());
        #[cfg(feature = "dim3")]
        if m.max_pitch() > 0.0 {
            // Turned about two axes through the pivot: the box's farthest corner from it.
            let r = farthest_corner(lo, hi, m.pivot, 3);
            return (
                m.pivot - Vector::splat(r) - grow,
                m.pivot + Vector::splat(r) + grow,
            );
        }
        if m.max_angle() == 0.0 {
            return (lo - grow, hi + grow);
        }
        // A roll about z: the x-y rectangle's corners' farthest reach from the axis.
        let r = farthest_corner(lo, hi, m.pivot, 2);
        let reach = dim::xy(r, r) + grow;
        #[cfg(feature = "dim3")]
        let (lo, hi) = (
            Vector::new(m.pivot.x, m.pivot.y, lo.z) - reach,
            Vector::new(m.pivot.x, m.pivot.y, hi.z) + reach,
        );
        #[cfg(not(feature = "dim3"))]
        let (lo, hi) = (m.pivot - reach, m.pivot + reach);
        (lo, hi)
    }

    /// The reference data file (`reference.file`, relative to the scenario file).
    pub fn reference_file(&self) -> Option<PathBuf> {
        let r = self.spec.reference.as_ref()?;
        Some(self.source.parent().unwrap_or(Path::new(".")).join(&r.file))
    }

    /// The tank's pose at t = 0 (at rest for a fixed tank).
    pub fn initial_pose(&self) -> Pose {
        let pivot = self.spec.tank.as_ref().map_or(Vector::ZERO, |t| t.pivot());
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
                #[cfg(feature = "dim3")]
                breadth: t.breadth.0,
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
            let at: Vector = s.at.into();
            let along = world.get::<&Wall>(wall).map_or(0.0, |w| w.abscissa(at));
            #[cfg(feature = "dim3")]
            let across = world
                .get::<&Wall>(wall)
                .map_or(0.0, |w| w.at_rest().abscissa_across(at));
            let width = s.width.map_or(2.0 * self.h, |w| w.0);
            world.spawn((PressureSensor {
                name: s.name.clone(),
                wall,
                along,
                #[cfg(feature = "dim3")]
                across,
                width,
                diameter: s.diameter.map_or(0.0, |d| d.0),
                filter: s.filter.map_or(0.0, |f| f.0),
            },));
        }
        for g in &self.spec.wave_gauges {
            world.spawn((WaveGauge {
                name: g.name.clone(),
                x: g.x,
                #[cfg(feature = "dim3")]
                z: g.z,
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

/// The walls of tank `t`, facing in: `left`, `bottom`, `right`, in 3D `back` (z = 0)
/// and `front` (z = breadth), then `top` unless it is open.
fn tank_walls(t: &TankSpec) -> Vec<Wall> {
    #[cfg(not(feature = "dim3"))]
    let size = Vector::new(t.width.0, t.height.0);
    #[cfg(feature = "dim3")]
    let size = Vector::new(t.width.0, t.height.0, t.breadth.0);
    let mut faces = faces(Vector::ZERO, size, true);
    if t.open_top {
        faces.retain(|w| w.name != "top");
    }
    faces
}

/// The faces of box `b` facing out, named `<name>_<face>`, without those lying on the
/// tank's walls (see [`BoxSpec`]).
pub(crate) fn box_faces(b: &BoxSpec, tank: Option<&TankSpec>) -> Vec<Wall> {
    let (min, size) = (Vector::from(b.min), extent(&b.size));
    let on_tank = |w: &Wall| {
        tank.is_some_and(|t| {
            tank_walls(t).iter().any(|tw| {
                let rest = tw.at_rest();
                #[cfg(not(feature = "dim3"))]
                let corners = [w.a, w.b];
                #[cfg(feature = "dim3")]
                let corners = [w.a, w.b, w.c];
                corners.iter().all(|&p| rest.distance(p).abs() < 1e-12)
            })
        })
    };
    let mut faces = faces(min, size, false);
    faces.retain(|w| !on_tank(w));
    for w in &mut faces {
        w.name = format!("{}_{}", b.name, w.name);
    }
    faces
}

/// The faces of the box from `min` of `size`, facing in (`inward`) or out: in 2D
/// `left`, `bottom`, `right`, `top` as segments whose fluid side is on the left; in 3D
/// `left`, `bottom`, `right`, `back`, `front`, `top` as rectangles a, b, c whose fluid
/// side is that of (c - a) x (b - a).
fn faces(min: Vector, size: Vector, inward: bool) -> Vec<Wall> {
    let wall = |name: &str, a: Vector, b: Vector, _c: Vector| {
        let (a, b, _c) = (min + a, min + b, min + _c);
        // Facing out: the same rectangle with its edges swapped (2D: reversed).
        #[cfg(not(feature = "dim3"))]
        let (a, b) = if inward { (a, b) } else { (b, a) };
        #[cfg(feature = "dim3")]
        let (b, _c) = if inward { (b, _c) } else { (_c, b) };
        Wall {
            name: name.to_string(),
            a,
            b,
            #[cfg(feature = "dim3")]
            c: _c,
            body: Pose::default(),
        }
    };
    let (w, h) = (size.x, size.y);
    let o = Vector::ZERO;
    #[cfg(not(feature = "dim3"))]
    {
        let v = Vector::new;
        vec![
            wall("left", v(0.0, h), o, o),
            wall("bottom", o, v(w, 0.0), o),
            wall("right", v(w, 0.0), v(w, h), o),
            wall("top", v(w, h), v(0.0, h), o),
        ]
    }
    #[cfg(feature = "dim3")]
    {
        let (v, d) = (Vector::new, size.z);
        vec![
            wall("left", v(0.0, h, 0.0), o, v(0.0, h, d)),
            wall("bottom", o, v(w, 0.0, 0.0), v(0.0, 0.0, d)),
            wall("right", v(w, 0.0, 0.0), v(w, h, 0.0), v(w, 0.0, d)),
            wall("back", o, v(0.0, h, 0.0), v(w, 0.0, 0.0)),
            wall("front", v(0.0, 0.0, d), v(w, 0.0, d), v(0.0, h, d)),
            wall("top", v(0.0, h, 0.0), v(0.0, h, d), v(w, h, 0.0)),
        ]
    }
}

/// The largest distance from `centre` of the box [lo, hi]'s corners, in their first
/// `axes` components (2: the x-y rectangle's, the reach of a roll about z; 3: the
/// box's, the reach of a turn about any axis through `centre`).
fn farthest_corner(lo: Vector, hi: Vector, centre: Vector, axes: usize) -> f64 {
    let axes = axes.min(dim::DIM);
    (0..1usize << axes)
        .map(|k| {
            let square = |i: usize| {
                let c = if k >> i & 1 == 0 { lo[i] } else { hi[i] };
                (c - centre[i]).powi(2)
            };
            (0..axes).map(square).sum::<f64>().sqrt()
        })
        .fold(0.0, f64::max)
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
