//! Wall-pressure extraction methods: how a pressure sensor turns the particles near a
//! point on a wall into a pressure (docs/physics.md, "Wall-pressure extraction"). The
//! shipped Methods I, II and III (`Shepard`, `Nearest`, `Averaged`, in `sph-stages`) and
//! a plugin's are written against the same trait, [`ExtractionMethod`], registered by
//! name ([`crate::StageRegistry::register_extraction`]) and named in a scenario's
//! `Probe(methods: [...])`. Each method writes the column `<sensor>.<snake_case name>`
//! of `probes.csv` (and `<sensor>.<name>.transducer` for a sensor with a face or a
//! filter, the same method averaged over the face).

use crate::components::WallPose;
use crate::dim::Vector;
use crate::sim::Sim;
use crate::stage::StepError;
use crate::world::Particles;
use std::collections::BTreeMap;

/// Hydrostatic carry of a pressure in the (possibly accelerating) tank frame:
/// p(to) = p(from) + rho_0 g_eff . (to - from), with g_eff = g - a_wall the effective
/// gravity in the frame of the sensor's wall.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Carry {
    pub rho0: f64,
    pub g: Vector,
}

impl Carry {
    /// Pressure `p` read at `from`, carried to `to`.
    pub fn carry(self, p: f64, from: Vector, to: Vector) -> f64 {
        p + self.rho0 * self.g.dot(to - from)
    }
}

/// Where one reading is taken: a point on a wall, and the sensor's width along it.
#[derive(Clone, Copy, Debug)]
pub struct Site<'a> {
    /// The sensor's wall, where it is now.
    pub wall: &'a WallPose,
    /// The reading's abscissa along the wall [m] (the sensor's centre, or a point of
    /// its face).
    pub along: f64,
    /// The reading's abscissa along the wall's second edge (a->c) [m] (3D).
    #[cfg(feature = "dim3")]
    pub across: f64,
    /// The sensor's width S along the wall [m] (the face Method III averages over).
    pub width: f64,
    /// The hydrostatic carry in the wall's frame.
    pub carry: Carry,
}

impl Site<'_> {
    /// The reading's point, in the world frame.
    pub fn point(&self) -> Vector {
        #[cfg(not(feature = "dim3"))]
        return self.wall.point(self.along);
        #[cfg(feature = "dim3")]
        return self.wall.point(self.along) + self.across * self.wall.tangent_across();
    }
}

/// A wall-pressure extraction method. One value is built per `Probe` stage and method
/// (so it may keep scratch buffers between readings); it reads every sensor.
pub trait ExtractionMethod: Send + 'static {
    /// Whether it reads the neighbour grid (`sph_core::vocab::Neighbours`, indexing fluid
    /// then ghost particles): the probe then refuses a pipeline without `NeighbourGrid`
    /// before it. Default false.
    fn needs_grid(&self) -> bool {
        false
    }
    /// The pressure [Pa] at `site`; 0 where the sensor is dry (no fluid within reach).
    /// `particles` are the world's fluid and ghosts now. Must not return NaN for a
    /// finite flow: the probe writes what it returns.
    fn pressure(&mut self, sim: &Sim, particles: Particles, site: &Site) -> Result<f64, StepError>;
}

/// Builds a method for a run.
pub type MethodFactory = fn() -> Box<dyn ExtractionMethod>;

/// The registered extraction methods: name (CamelCase, as a scenario writes it) to its
/// factory and one-line summary.
#[derive(Clone, Default)]
pub struct ExtractionRegistry(pub(crate) BTreeMap<&'static str, (MethodFactory, &'static str)>);

impl ExtractionRegistry {
    /// The registered method named `name`, with the name's `'static` text.
    pub fn get(&self, name: &str) -> Option<(&'static str, MethodFactory)> {
        self.0.get_key_value(name).map(|(n, e)| (*n, e.0))
    }
    /// Registered names with their summaries, sorted.
    pub fn list(&self) -> impl Iterator<Item = (&'static str, &'static str)> + '_ {
        self.0.iter().map(|(n, e)| (*n, e.1))
    }
}

/// A method as a scenario names it, e.g. `Averaged`; serialised as that bare name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MethodName(pub &'static str);

impl MethodName {
    /// The `probes.csv` column suffix: the name in snake_case (`Averaged` -> `averaged`).
    pub fn suffix(self) -> String {
        crate::registry::snake_case(self.0)
    }
}

impl serde::Serialize for MethodName {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_unit_variant("Method", 0, self.0)
    }
}

/// Reads a method's name from a scenario: a registered one, else refused with the list
/// of known names (and the nearest, through the loader's "did you mean").
#[derive(Clone, Copy)]
pub struct MethodSeed<'a>(pub &'a ExtractionRegistry);

impl<'de> serde::de::DeserializeSeed<'de> for MethodSeed<'_> {
    type Value = MethodName;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<MethodName, D::Error> {
        d.deserialize_enum("Method", &[], self)
    }
}

impl<'de> serde::de::Visitor<'de> for MethodSeed<'_> {
    type Value = MethodName;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("an extraction method, e.g. Averaged")
    }
    fn visit_enum<A: serde::de::EnumAccess<'de>>(self, data: A) -> Result<MethodName, A::Error> {
        use serde::de::{Error, VariantAccess};
        let (name, variant) =
            data.variant_seed(crate::registry::Identifier("an extraction method's name"))?;
        let (name, _) = self.0.get(&name).ok_or_else(|| {
            let known: Vec<String> = self.0.list().map(|(n, _)| format!("`{n}`")).collect();
            A::Error::custom(format!(
                "unknown variant `{name}`, expected one of {}",
                known.join(", ")
            ))
        })?;
        variant.unit_variant()?;
        Ok(MethodName(name))
    }
}

/// Reads a list of methods, `[Shepard, Averaged]`, each through [`MethodSeed`]; a name
/// given twice is refused where it stands (it would write two columns of one name).
#[derive(Clone, Copy)]
pub struct MethodListSeed<'a>(pub &'a ExtractionRegistry);

impl<'de> serde::de::DeserializeSeed<'de> for MethodListSeed<'_> {
    type Value = Vec<MethodName>;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> serde::de::Visitor<'de> for MethodListSeed<'_> {
    type Value = Vec<MethodName>;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a list of extraction methods, e.g. `[Shepard, Averaged]`")
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut list: Vec<MethodName> = Vec::new();
        while let Some(m) = seq.next_element_seed(MethodSeed(self.0))? {
            if list.contains(&m) {
                return Err(serde::de::Error::custom(format!(
                    "`{}` is listed twice; name each method once",
                    m.0
                )));
            }
            list.push(m);
        }
        Ok(list)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dim;

    struct Zero;
    impl ExtractionMethod for Zero {
        fn pressure(&mut self, _: &Sim, _: Particles, _: &Site) -> Result<f64, StepError> {
            Ok(0.0)
        }
    }

    fn registry() -> ExtractionRegistry {
        let mut r = ExtractionRegistry::default();
        r.0.insert("PeakHold", (|| Box::new(Zero), "test"));
        r
    }

    #[test]
    fn names_read_through_the_registry_and_write_back_bare() {
        use serde::de::DeserializeSeed;
        let r = registry();
        let mut de = ron::Deserializer::from_str("PeakHold").unwrap();
        let name = MethodSeed(&r).deserialize(&mut de).unwrap();
        assert_eq!(name, MethodName("PeakHold"));
        assert_eq!(name.suffix(), "peak_hold");
        assert_eq!(ron::to_string(&name).unwrap(), "PeakHold");
        let mut de = ron::Deserializer::from_str("PeakHlod").unwrap();
        let err = MethodSeed(&r).deserialize(&mut de).unwrap_err().to_string();
        assert!(
            err.contains("unknown variant `PeakHlod`, expected one of `PeakHold`"),
            "{err}"
        );
    }

    /// A list reads each name once, in order; a name twice, a bare name and a wrong
    /// element are refused saying what was expected.
    #[test]
    fn method_lists_read_each_name_once() {
        use serde::de::DeserializeSeed;
        let mut r = registry();
        r.0.insert("Averaged", (|| Box::new(Zero), "test"));
        let read = |text: &str| {
            let mut de = ron::Deserializer::from_str(text).unwrap();
            MethodListSeed(&r)
                .deserialize(&mut de)
                .map_err(|e| e.to_string())
        };
        assert_eq!(
            read("[Averaged, PeakHold]"),
            Ok(vec![MethodName("Averaged"), MethodName("PeakHold")])
        );
        assert_eq!(read("[]"), Ok(vec![]));
        let twice = read("[PeakHold, Averaged, PeakHold]").unwrap_err();
        assert!(twice.contains("`PeakHold` is listed twice"), "{twice}");
        assert!(read("PeakHold").is_err());
        assert!(read("[3]").is_err());
        // RON words these itself; a format that asks the visitor what it expected
        // (serde's own value deserializer here) gets the seeds' words.
        use serde::de::value::{Error, U32Deserializer};
        let three = || U32Deserializer::<Error>::new(3);
        let list = MethodListSeed(&r).deserialize(three()).unwrap_err();
        assert!(
            list.to_string()
                .ends_with("expected a list of extraction methods, e.g. `[Shepard, Averaged]`"),
            "{list}"
        );
        let truth = serde::de::value::BoolDeserializer::<Error>::new(true);
        let one = MethodSeed(&r).deserialize(truth).unwrap_err();
        assert!(
            one.to_string()
                .ends_with("expected an extraction method, e.g. Averaged"),
            "{one}"
        );
    }

    /// A site's point lies `along` the wall from its end `a`; a method reads no grid
    /// unless it says so.
    #[test]
    fn a_site_is_a_point_along_its_wall() {
        let wall = WallPose {
            a: dim::xy(1.0, 2.0),
            b: dim::xy(4.0, 6.0),
            #[cfg(feature = "dim3")]
            c: Vector::new(1.0, 2.0, 2.0),
            body: Default::default(),
        };
        let site = Site {
            wall: &wall,
            along: 2.5,
            #[cfg(feature = "dim3")]
            across: 0.5,
            width: 0.01,
            carry: Carry {
                rho0: 1000.0,
                g: Vector::ZERO,
            },
        };
        // 2.5 m along a->b (a 3-4-5 triangle), in 3D also 0.5 m along a->c.
        let mut want = dim::xy(2.5, 4.0);
        if dim::DIM == 3 {
            want[dim::DIM - 1] = 0.5;
        }
        assert!((site.point() - want).length() < 1e-15);
        assert!(!Zero.needs_grid());
    }

    #[test]
    fn the_carry_adds_the_hydrostatic_difference() {
        let c = Carry {
            rho0: 1000.0,
            g: dim::xy(0.0, -9.81),
        };
        // 0.1 m deeper reads rho g 0.1 more.
        let p = c.carry(50.0, dim::xy(0.3, 0.2), dim::xy(0.0, 0.1));
        assert!((p - (50.0 + 981.0)).abs() < 1e-9, "{p}");
    }
}
