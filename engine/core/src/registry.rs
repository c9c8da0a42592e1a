//! The stage registry: stage names mapped to constructors that parse their own typed
//! parameters straight from the scenario file, so a parameter error carries the
//! file's line and column. Plugins add stages with [`StageRegistry::register`].

use crate::extraction::{ExtractionMethod, ExtractionRegistry};
use crate::kernel::{KernelKind, KernelShape, PluginKernel};
use crate::stage::Stage;
use crate::terms::{Term, TermRegistry};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Arc;

/// Builds a stage from its parameters; also returns the parameters, resolved (every
/// default filled in), as RON text for the run's resolved scenario copy.
type Constructor = Box<
    dyn Fn(
            &StageRegistry,
            &mut dyn erased_serde::Deserializer,
        ) -> Result<(Box<dyn Stage>, String), erased_serde::Error>
        + Send
        + Sync,
>;

struct Entry {
    build: Constructor,
    summary: &'static str,
}

/// A stage parameter out of range: the field, the value given and what is accepted.
/// Shown as "field `x` = v is out of range; accepted: ...", the form the scenario loader
/// takes the field from.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("field `{field}` = {value} is out of range; accepted: {accepted}")]
pub struct ParamError {
    pub field: &'static str,
    /// The value as written in messages.
    pub value: String,
    pub accepted: String,
}

impl ParamError {
    pub fn new(
        field: &'static str,
        value: impl std::fmt::Display,
        accepted: impl Into<String>,
    ) -> Self {
        Self {
            field,
            value: value.to_string(),
            accepted: accepted.into(),
        }
    }
}

/// Maps snake_case stage names to constructors. Cloning is cheap (entries are shared).
#[derive(Default, Clone)]
pub struct StageRegistry {
    entries: BTreeMap<String, Arc<Entry>>,
    /// The pair terms plugins add to `Forces(terms: [...])`.
    terms: TermRegistry,
    /// The kernels plugins add to a scenario's `kernel:`.
    kernels: KernelRegistry,
    /// The wall-pressure extraction methods `Probe(methods: [...])` names.
    extractions: ExtractionRegistry,
}

/// A stage built from a scenario's pipeline entry.
pub struct BuiltStage {
    pub stage: Box<dyn Stage>,
    /// The stage's parameters with every default filled in, as a RON struct `(..)`.
    pub resolved_params: String,
}

impl StageRegistry {
    pub fn new() -> Self {
        Self::default()
    }

    /// Registers stage `name` (snake_case; written `CamelCase(...)` in scenario files).
    /// `P` is the stage's parameter struct: give it `#[serde(default, deny_unknown_fields)]`
    /// so omitted fields take documented defaults and misspelt ones are refused.
    /// `build` may refuse out-of-range values with a [`ParamError`], which names the
    /// field (the scenario loader points at it in the file).
    pub fn register_checked<P, S>(
        &mut self,
        name: &str,
        summary: &'static str,
        build: impl Fn(P) -> Result<S, ParamError> + Send + Sync + 'static,
    ) where
        P: DeserializeOwned + Serialize + 'static,
        S: Stage + 'static,
    {
        self.register_read(name, summary, |_, de| erased_serde::deserialize(de), build);
    }

    /// As [`StageRegistry::register_checked`], for parameters read with the registry
    /// at hand: `read` parses them from the scenario (through a
    /// `serde::de::DeserializeSeed` that carries what it needs of the registry, e.g.
    /// [`StageRegistry::terms`]).
    pub fn register_read<P, S, E>(
        &mut self,
        name: &str,
        summary: &'static str,
        read: impl Fn(
                &StageRegistry,
                &mut dyn erased_serde::Deserializer,
            ) -> Result<P, erased_serde::Error>
            + Send
            + Sync
            + 'static,
        build: impl Fn(P) -> Result<S, E> + Send + Sync + 'static,
    ) where
        P: Serialize + 'static,
        S: Stage + 'static,
        E: std::fmt::Display,
    {
        let ctor: Constructor = Box::new(move |registry, de| {
            let params: P = read(registry, de)?;
            // As the loader reads them: a term list's `Name(field: value)` without the
            // newtype's inner parentheses.
            let resolved = ron_options()
                .to_string(&params)
                .map_err(serde::de::Error::custom)?;
            let stage = build(params).map_err(serde::de::Error::custom)?;
            Ok((Box::new(stage) as Box<dyn Stage>, resolved))
        });
        self.entries.insert(
            name.to_string(),
            Arc::new(Entry {
                build: ctor,
                summary,
            }),
        );
    }

    /// Registers pair term `T` as `name` (CamelCase, as a scenario writes it in
    /// `Forces(terms: [...])`); it runs in Forces' fused neighbour loop after the
    /// shipped terms of the list. See [`TermRegistry::register`].
    pub fn register_term<T>(&mut self, name: &'static str, summary: &'static str)
    where
        T: Term + Send + Sync + 'static,
        T::Params: Send + Sync + 'static,
    {
        self.terms.register::<T>(name, summary);
    }

    /// The pair terms registered by plugins.
    pub fn terms(&self) -> &TermRegistry {
        &self.terms
    }

    /// Registers kernel shape `K` under `name`, which a scenario then names as
    /// `kernel: Name` (docs/architecture.md, "Plugins: adding a kernel").
    ///
    /// # Panics
    /// If `name` is not a CamelCase identifier or is a shipped kernel's.
    pub fn register_kernel<K: KernelShape>(&mut self, name: &'static str, summary: &'static str) {
        assert!(
            name.starts_with(|c: char| c.is_ascii_uppercase())
                && name.chars().all(|c| c.is_ascii_alphanumeric())
                && KernelKind::shipped(name).is_none(),
            "kernel name `{name}`: write it CamelCase, and not a shipped kernel's"
        );
        self.kernels
            .0
            .insert(name, (PluginKernel::new::<K>(name), summary));
    }

    /// The kernels registered by plugins.
    pub fn kernels(&self) -> &KernelRegistry {
        &self.kernels
    }

    /// Registers wall-pressure extraction method `M` under `name`, which a scenario then
    /// names in `Probe(methods: [...])`; its `probes.csv` columns end in the name in
    /// snake_case (docs/architecture.md, "Plugins: adding an extraction method").
    ///
    /// # Panics
    /// If `name` is not a CamelCase identifier or is already registered.
    pub fn register_extraction<M: ExtractionMethod + Default>(
        &mut self,
        name: &'static str,
        summary: &'static str,
    ) {
        fn make<M: ExtractionMethod + Default>() -> Box<dyn ExtractionMethod> {
            Box::new(M::default())
        }
        assert!(
            name.starts_with(|c: char| c.is_ascii_uppercase())
                && name.chars().all(|c| c.is_ascii_alphanumeric())
                && self.extractions.get(name).is_none(),
            "extraction method `{name}`: write it CamelCase, once"
        );
        self.extractions.0.insert(name, (make::<M>, summary));
    }

    /// The registered wall-pressure extraction methods.
    pub fn extractions(&self) -> &ExtractionRegistry {
        &self.extractions
    }

    pub fn contains(&self, name: &str) -> bool {
        self.entries.contains_key(name)
    }

    /// Registered names with their one-line summaries, sorted.
    pub fn list(&self) -> impl Iterator<Item = (&str, &'static str)> {
        self.entries.iter().map(|(k, v)| (k.as_str(), v.summary))
    }

    /// Builds stage `name` from a deserializer positioned at its parameters (the
    /// scenario loader, `sph-scenario`, calls it for each pipeline entry).
    pub fn build(
        &self,
        name: &str,
        de: &mut dyn erased_serde::Deserializer,
    ) -> Option<Result<BuiltStage, erased_serde::Error>> {
        self.entries.get(name).map(|e| {
            (e.build)(self, de).map(|(stage, resolved_params)| BuiltStage {
                stage,
                resolved_params,
            })
        })
    }

    /// The message for an unknown stage: the known ones and the nearest name.
    pub fn unknown_message(&self, written: &str) -> String {
        let snake = snake_case(written);
        let known: Vec<String> = self.entries.keys().map(|k| camel_case(k)).collect();
        let nearest = did_you_mean(&snake, self.entries.keys().map(String::as_str))
            .map(|k| format!(" did you mean `{}`?", camel_case(k)))
            .unwrap_or_default();
        format!(
            "unknown stage `{written}`;{nearest} known stages: {}",
            known.join(", ")
        )
    }
}

/// The name of `names` nearest to a misspelt `written` one (edit distance), if it is
/// close enough to offer as "did you mean": within a third of `written`'s length, at
/// least 2 edits. Ties go to the first name.
pub fn did_you_mean<'a>(
    written: &str,
    names: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    let limit = (written.chars().count() / 3).max(2);
    names
        .into_iter()
        .map(|n| (strsim::levenshtein(written, n), n))
        .filter(|&(d, _)| d <= limit)
        .min_by_key(|&(d, _)| d)
        .map(|(_, n)| n)
}

/// `NeighbourGrid` -> `neighbour_grid`, `EOSForce` -> `eos_force` (a run of capitals
/// is one word); already snake_case names pass through. The one conversion the loader,
/// the registry and `--set` paths share.
pub fn snake_case(name: &str) -> String {
    let chars: Vec<char> = name.chars().collect();
    let mut out = String::with_capacity(name.len() + 4);
    for (i, &c) in chars.iter().enumerate() {
        if c.is_uppercase() && i > 0 {
            let prev = chars[i - 1];
            let next_lower = chars.get(i + 1).is_some_and(|n| n.is_lowercase());
            if prev.is_lowercase() || prev.is_ascii_digit() || (prev.is_uppercase() && next_lower) {
                out.push('_');
            }
        }
        out.extend(c.to_lowercase());
    }
    out
}

/// `neighbour_grid` -> `NeighbourGrid`.
pub fn camel_case(name: &str) -> String {
    name.split('_')
        .map(|part| {
            let mut c = part.chars();
            c.next().map_or(String::new(), |f| {
                f.to_ascii_uppercase().to_string() + c.as_str()
            })
        })
        .collect()
}

/// The kernels plugins registered, by name, with their one-line summaries.
#[derive(Clone, Debug, Default)]
pub struct KernelRegistry(BTreeMap<&'static str, (PluginKernel, &'static str)>);

impl KernelRegistry {
    /// The registered kernel named `name`.
    pub fn get(&self, name: &str) -> Option<PluginKernel> {
        self.0.get(name).map(|k| k.0)
    }
    /// Registered names with their summaries, sorted.
    pub fn list(&self) -> impl Iterator<Item = (&'static str, &'static str)> + '_ {
        self.0.iter().map(|(n, k)| (*n, k.1))
    }
}

/// Reads a scenario's `kernel: Name`: a shipped kernel, or one in the registry; an
/// unknown name is refused with the list of known ones.
#[derive(Clone, Copy)]
pub struct KernelSeed<'a>(pub &'a KernelRegistry);

impl<'de> serde::de::DeserializeSeed<'de> for KernelSeed<'_> {
    type Value = KernelKind;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<KernelKind, D::Error> {
        const SHIPPED: &[&str] = &["Gaussian", "Quadratic", "Cubic", "Quartic", "Wendland"];
        d.deserialize_enum("KernelKind", SHIPPED, self)
    }
}

impl<'de> serde::de::Visitor<'de> for KernelSeed<'_> {
    type Value = KernelKind;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a kernel, e.g. Wendland")
    }
    fn visit_enum<A: serde::de::EnumAccess<'de>>(self, data: A) -> Result<KernelKind, A::Error> {
        use serde::de::{Error, VariantAccess};
        let (name, variant) = data.variant_seed(Identifier("a kernel's name"))?;
        let kind = KernelKind::shipped(&name)
            .or_else(|| self.0.get(&name).map(KernelKind::Plugin))
            .ok_or_else(|| {
                let known: Vec<String> = KernelKind::ALL
                    .iter()
                    .map(|k| k.name())
                    .chain(self.0.list().map(|(n, _)| n))
                    .map(|n| format!("`{n}`"))
                    .collect();
                A::Error::custom(format!(
                    "unknown variant `{name}`, expected one of {}",
                    known.join(", ")
                ))
            })?;
        variant.unit_variant()?;
        Ok(kind)
    }
}

/// Reads a bare identifier (a stage's name, a pair term's, a field's) as text; the
/// `&str` says what is expected, for the message when something else is there.
#[derive(Clone, Copy)]
pub struct Identifier(pub &'static str);

impl<'de> serde::de::DeserializeSeed<'de> for Identifier {
    type Value = String;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<String, D::Error> {
        d.deserialize_identifier(self)
    }
}

impl serde::de::Visitor<'_> for Identifier {
    type Value = String;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(self.0)
    }
    fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<String, E> {
        Ok(v.to_string())
    }
}

/// Reads a list `[a, b, ...]` with `seed` for each element (a stateful element reader:
/// a pipeline entry through the stage registry, a pair term through the term
/// registry). `.1` says what is expected, for the message when something else is there.
#[derive(Clone, Copy)]
pub struct SeqOf<S>(pub S, pub &'static str);

impl<'de, S: serde::de::DeserializeSeed<'de> + Copy> serde::de::DeserializeSeed<'de> for SeqOf<S> {
    type Value = Vec<S::Value>;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de, S: serde::de::DeserializeSeed<'de> + Copy> serde::de::Visitor<'de> for SeqOf<S> {
    type Value = Vec<S::Value>;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(self.1)
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut list = Vec::new();
        while let Some(x) = seq.next_element_seed(self.0)? {
            list.push(x);
        }
        Ok(list)
    }
}

/// Reads a parameter struct `P` (deriving `Deserialize`, with
/// `#[serde(default, deny_unknown_fields)]`) of which one field, `field`, needs the
/// registry: that field's value is read with `seed` (give the field
/// `#[serde(skip_deserializing)]` in `P`), every other by `P`'s own derived code, in
/// one pass over the text, so every error keeps its position. Returns `P` and the
/// seeded value, if the field was written.
pub fn read_with_seeded_field<'de, P, S, D>(
    d: D,
    field: &'static str,
    seed: S,
) -> Result<(P, Option<S::Value>), D::Error>
where
    P: serde::Deserialize<'de>,
    S: serde::de::DeserializeSeed<'de>,
    D: serde::Deserializer<'de>,
{
    use serde::de::{value::MapAccessDeserializer, Error, MapAccess, Visitor};
    use std::marker::PhantomData;

    /// Passes the keys through to `P`, all but `field`, whose value it reads with the seed.
    struct Filter<'a, A, S, V> {
        inner: &'a mut A,
        field: &'static str,
        seed: &'a mut Option<S>,
        value: &'a mut Option<V>,
    }
    impl<'de, A, S> MapAccess<'de> for Filter<'_, A, S, S::Value>
    where
        A: MapAccess<'de>,
        S: serde::de::DeserializeSeed<'de>,
    {
        type Error = A::Error;
        fn next_key_seed<K: serde::de::DeserializeSeed<'de>>(
            &mut self,
            key_seed: K,
        ) -> Result<Option<K::Value>, A::Error> {
            loop {
                let Some(key) = self.inner.next_key::<String>()? else {
                    return Ok(None);
                };
                if key != self.field {
                    return key_seed
                        .deserialize(serde::de::value::StringDeserializer::new(key))
                        .map(Some);
                }
                let Some(seed) = self.seed.take() else {
                    return Err(A::Error::duplicate_field(self.field));
                };
                *self.value = Some(self.inner.next_value_seed(seed)?);
            }
        }
        fn next_value_seed<V: serde::de::DeserializeSeed<'de>>(
            &mut self,
            seed: V,
        ) -> Result<V::Value, A::Error> {
            self.inner.next_value_seed(seed)
        }
    }
    struct Reader<P, S> {
        field: &'static str,
        seed: S,
        p: PhantomData<P>,
    }
    impl<'de, P, S> Visitor<'de> for Reader<P, S>
    where
        P: serde::Deserialize<'de>,
        S: serde::de::DeserializeSeed<'de>,
    {
        type Value = (P, Option<S::Value>);
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a stage's parameters, `(field: value, ...)`")
        }
        fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
            let (mut seed, mut value) = (Some(self.seed), None);
            let filter = Filter {
                inner: &mut map,
                field: self.field,
                seed: &mut seed,
                value: &mut value,
            };
            let p = P::deserialize(MapAccessDeserializer::new(filter))?;
            Ok((p, value))
        }
    }
    d.deserialize_map(Reader {
        field,
        seed,
        p: PhantomData,
    })
}

/// RON options: `IMPLICIT_SOME` lets optional fields be written without `Some(..)`;
/// `UNWRAP_VARIANT_NEWTYPES` lets a variant holding a parameter struct be written
/// `Name(field: value)` (a pair term in `Forces(terms: [...])`), not `Name((..))`.
pub fn ron_options() -> ron::Options {
    use ron::extensions::Extensions;
    ron::Options::default()
        .with_default_extension(Extensions::IMPLICIT_SOME | Extensions::UNWRAP_VARIANT_NEWTYPES)
}

#[cfg(test)]
mod case_tests {
    use super::{camel_case, snake_case};

    #[test]
    fn one_snake_case_for_stage_names_and_paths() {
        for (camel, snake) in [
            ("NeighbourGrid", "neighbour_grid"),
            ("EOSForce", "eos_force"),
            ("Eos", "eos"),
            ("VtkFrames", "vtk_frames"),
            ("Probe2D", "probe2_d"),
            ("neighbour_grid", "neighbour_grid"),
        ] {
            assert_eq!(snake_case(camel), snake, "{camel}");
        }
        assert_eq!(camel_case("neighbour_grid"), "NeighbourGrid");
        assert_eq!(
            snake_case(&camel_case("laminar_viscosity")),
            "laminar_viscosity"
        );
    }
}
