//! Pipeline entries: a stage's name and its typed parameters, read straight from the
//! scenario text through the stage registry, so parameter errors keep their position.

use super::*;
use sph_core::registry::KernelSeed;

/// One stage of the pipeline, as built from the file.
pub struct PipelineEntry {
    pub name: String,
    /// Run this stage every `every` steps (written `every: N` among the stage's
    /// parameters; default 1).
    pub every: u32,
    pub stage: Box<dyn Stage>,
    /// What the stage declared it reads and writes ([`Stage::access`], asked once).
    pub(crate) access: Access,
    pub(crate) resolved: String,
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

/// Reads a scenario file's fields, building each pipeline entry's stage through the
/// registry as it goes, so that a stage's parameter errors keep their place in the file.
/// (A hand-written visitor, where the other structs derive theirs: a derived one could
/// not carry the registry.)
#[derive(Clone, Copy)]
pub(crate) struct ScenarioSeed<'a>(pub(crate) &'a StageRegistry);

/// The scenario's fields, as written.
#[derive(Deserialize)]
#[serde(field_identifier, rename_all = "snake_case")]
enum Key {
    Dimensions,
    Name,
    EndTime,
    Fluid,
    Resolution,
    Kernel,
    HOverDx,
    Tank,
    Walls,
    Boxes,
    Piston,
    FluidBlocks,
    PressureSensors,
    WaveGauges,
    Sweep,
    Reference,
    Pipeline,
}

const FIELDS: &[&str] = &[
    "dimensions",
    "name",
    "end_time",
    "fluid",
    "resolution",
    "kernel",
    "h_over_dx",
    "tank",
    "walls",
    "boxes",
    "piston",
    "fluid_blocks",
    "pressure_sensors",
    "wave_gauges",
    "sweep",
    "reference",
    "pipeline",
];

impl<'de> DeserializeSeed<'de> for ScenarioSeed<'_> {
    type Value = ScenarioSpec;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<ScenarioSpec, D::Error> {
        d.deserialize_struct("Scenario", FIELDS, self)
    }
}

impl<'de> Visitor<'de> for ScenarioSeed<'_> {
    type Value = ScenarioSpec;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "a scenario, `Scenario(name: ..., ...)`")
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<ScenarioSpec, A::Error> {
        /// Each field once: the value read into its slot, or the duplicate refused.
        macro_rules! take {
            ($slot:ident, $field:literal, $read:expr) => {{
                if $slot.is_some() {
                    return Err(de::Error::duplicate_field($field));
                }
                $slot = Some($read);
            }};
        }
        let (mut name, mut end_time, mut fluid, mut resolution, mut kernel) =
            (None, None, None, None, None);
        let (mut h_over_dx, mut tank, mut walls, mut piston, mut fluid_blocks) =
            (None, None, None, None, None);
        let (mut pressure_sensors, mut wave_gauges, mut sweep, mut pipeline) =
            (None, None, None, None);
        let (mut dimensions, mut boxes, mut reference) = (None, None, None);
        while let Some(key) = map.next_key::<Key>()? {
            match key {
                Key::Dimensions => take!(dimensions, "dimensions", map.next_value()?),
                Key::Name => take!(name, "name", map.next_value()?),
                Key::EndTime => take!(end_time, "end_time", map.next_value()?),
                Key::Fluid => take!(fluid, "fluid", map.next_value()?),
                Key::Resolution => take!(resolution, "resolution", map.next_value()?),
                Key::Kernel => take!(
                    kernel,
                    "kernel",
                    map.next_value_seed(KernelSeed(self.0.kernels()))?
                ),
                Key::HOverDx => take!(h_over_dx, "h_over_dx", map.next_value()?),
                Key::Tank => take!(tank, "tank", map.next_value()?),
                Key::Walls => take!(walls, "walls", map.next_value()?),
                Key::Boxes => take!(boxes, "boxes", map.next_value()?),
                Key::Piston => take!(piston, "piston", map.next_value()?),
                Key::FluidBlocks => take!(fluid_blocks, "fluid_blocks", map.next_value()?),
                Key::PressureSensors => {
                    take!(pressure_sensors, "pressure_sensors", map.next_value()?)
                }
                Key::WaveGauges => take!(wave_gauges, "wave_gauges", map.next_value()?),
                Key::Sweep => take!(sweep, "sweep", map.next_value()?),
                Key::Reference => take!(reference, "reference", map.next_value()?),
                Key::Pipeline => take!(
                    pipeline,
                    "pipeline",
                    map.next_value_seed(SeqOf(
                        EntryVisitor(self.0),
                        "a list of stages, `[NeighbourGrid(), ...]`",
                    ))?
                ),
            }
        }
        let required = |field: &'static str| move || de::Error::missing_field(field);
        Ok(ScenarioSpec {
            dimensions: dimensions.unwrap_or(2),
            name: name.ok_or_else(required("name"))?,
            end_time: end_time.ok_or_else(required("end_time"))?,
            fluid: fluid.unwrap_or_default(),
            resolution: resolution.ok_or_else(required("resolution"))?,
            kernel: kernel.unwrap_or_else(default_kernel),
            h_over_dx: h_over_dx.unwrap_or_else(default_h_over_dx),
            tank: tank.unwrap_or_default(),
            walls: walls.unwrap_or_default(),
            boxes: boxes.unwrap_or_default(),
            piston: piston.unwrap_or_default(),
            fluid_blocks: fluid_blocks.ok_or_else(required("fluid_blocks"))?,
            pressure_sensors: pressure_sensors.unwrap_or_default(),
            wave_gauges: wave_gauges.unwrap_or_default(),
            sweep: sweep.unwrap_or_default(),
            reference: reference.unwrap_or_default(),
            pipeline: pipeline.ok_or_else(required("pipeline"))?,
        })
    }
}

/// Reads one pipeline entry, `Name(param: value, ...)`.
#[derive(Clone, Copy)]
pub(crate) struct EntryVisitor<'a>(&'a StageRegistry);

impl<'de> DeserializeSeed<'de> for EntryVisitor<'_> {
    type Value = PipelineEntry;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_enum("Stage", &[], self)
    }
}

impl<'de> Visitor<'de> for EntryVisitor<'_> {
    type Value = PipelineEntry;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(
            f,
            "a stage written `Name(param: value, ...)`, e.g. `NeighbourGrid()`"
        )
    }
    fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<PipelineEntry, A::Error> {
        let (written, variant) = data.variant_seed(Identifier("a stage name"))?;
        let name = snake_case(&written);
        let registry = self.0;
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

pub(crate) struct ParamsVisitor<'a> {
    pub(crate) name: String,
    pub(crate) registry: &'a StageRegistry,
    /// Set once the parameter list has been opened.
    pub(crate) entered: &'a Cell<bool>,
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
pub(crate) struct EveryFilter<A> {
    pub(crate) inner: A,
    pub(crate) every: Option<u32>,
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
