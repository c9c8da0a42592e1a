//! Command-line `--set path=value` overrides of a RON scenario, applied to its text.
//!
//! Patching the text (rather than a parsed value tree) keeps the loader's line:column error
//! positions meaningful and preserves the names of enum-like pipeline entries such as
//! `Reinitialise(every: 5)`, which a generic RON value tree would drop. Each patch's
//! place in the patched text is kept ([`Patch`]), so the loader can name the `--set`
//! argument an error comes from instead of a place in the file.

use crate::lexer::{lex, Shape, SyntaxError, Tok, Token};
use sph_core::registry::{did_you_mean, snake_case};
use std::ops::Range;
use std::str::FromStr;

/// Deepest bracket nesting accepted, so that hostile input cannot overflow the stack.
const MAX_DEPTH: usize = 128;

/// One `--set path=value` from the command line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Override {
    /// Dot-separated segments: field names, list indices, snake_case element names or map keys.
    pub path: Vec<String>,
    /// RON text that replaces (or is inserted as) the selected value.
    pub value: String,
    /// The argument as given, for error messages.
    pub raw: String,
}

/// Why an override could not be parsed or applied.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OverrideError {
    /// The argument is not `path=value`, or its value is not a single RON value.
    #[error("--set {raw}: {reason}")]
    Syntax { raw: String, reason: String },
    /// The path does not select anything in the scenario.
    #[error("--set {raw}: {reason}")]
    Path { raw: String, reason: String },
    /// The scenario text is not well-formed RON.
    #[error("--set {raw}: cannot patch the scenario, malformed at {line}:{column}: {reason}")]
    Malformed {
        raw: String,
        line: usize,
        column: usize,
        reason: String,
    },
}

impl FromStr for Override {
    type Err = OverrideError;

    /// Parses `a.b.c=value`; whitespace around the path segments and the value is ignored.
    fn from_str(raw: &str) -> Result<Self, Self::Err> {
        let Some((path, value)) = raw.split_once('=') else {
            return Err(OverrideError::Syntax {
                raw: raw.to_owned(),
                reason:
                    "expected `path=value`, e.g. `end_time=0.5` or `pipeline.reinitialise.every=5`"
                        .to_owned(),
            });
        };
        let parsed = Self {
            path: path.split('.').map(|s| s.trim().to_owned()).collect(),
            value: value.trim().to_owned(),
            raw: raw.to_owned(),
        };
        parsed.check()?;
        Ok(parsed)
    }
}

impl Override {
    /// Rejects empty path segments and values that are not exactly one RON value.
    fn check(&self) -> Result<(), OverrideError> {
        let reason = if self.path.iter().all(|s| !s.is_empty()) && !self.path.is_empty() {
            match single_value(&self.value) {
                Ok(()) => return Ok(()),
                Err(e) => format!(
                    "value `{}` is not a single RON value: {}",
                    self.value, e.reason
                ),
            }
        } else {
            "empty path segment".to_owned()
        };
        Err(OverrideError::Syntax {
            raw: self.raw.clone(),
            reason,
        })
    }
}

/// Where one override landed in the patched text (byte ranges of the final text).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Patch {
    /// The `--set` argument as given.
    pub raw: String,
    /// The text the override wrote: the new value, or `name: value, ` when inserted.
    pub span: Range<usize>,
    /// Each segment of the path that is not a list index, with the struct, list or map
    /// that holds it: for `pipeline.integrate.courant`, `pipeline` in the scenario,
    /// `integrate` in the list, `courant` in `Integrate(...)`.
    pub holders: Vec<(String, Range<usize>)>,
    /// The length of the text it replaced (0 when inserted); for a patch that no
    /// other patch holds, text of the file.
    pub replaced: usize,
}

impl Patch {
    /// The field (or element) the override sets: its last segment that is not a list
    /// index, e.g. `courant`, or `gravity` for `gravity.1`.
    pub fn field(&self) -> Option<&str> {
        self.holders.last().map(|(s, _)| s.as_str())
    }
}

/// The offset in the file of `offset` in the patched text, when that lies outside
/// every patch: moved back by what the patches before it added or removed.
pub fn source_offset(offset: usize, patches: &[Patch]) -> usize {
    let outermost = patches.iter().filter(|p| {
        !patches
            .iter()
            .any(|q| q.span != p.span && q.span.start <= p.span.start && p.span.end <= q.span.end)
    });
    let before = outermost.filter(|p| p.span.end <= offset);
    let (added, removed) = before.fold((0, 0), |(a, r), p| (a + p.span.len(), r + p.replaced));
    (offset + removed).saturating_sub(added)
}

/// `r` after an edit that replaced the text at `edit` by `len` bytes: unchanged before
/// it, moved after it, grown around it; `None` when the edit overwrote (part of) it.
fn shifted(r: &Range<usize>, edit: &Range<usize>, len: usize) -> Option<Range<usize>> {
    if r.end <= edit.start {
        Some(r.clone())
    } else if r.start >= edit.end {
        Some(r.start - edit.len() + len..r.end - edit.len() + len)
    } else if edit.start <= r.start && r.end <= edit.end {
        None
    } else if r.start <= edit.start && edit.end <= r.end {
        Some(r.start..r.end - edit.len() + len)
    } else {
        None
    }
}

/// Applies overrides in order; returns the patched RON text.
pub fn apply_overrides(source: &str, overrides: &[Override]) -> Result<String, OverrideError> {
    apply_overrides_traced(source, overrides).map(|(text, _)| text)
}

/// As [`apply_overrides`], with where each override landed in the patched text (the
/// ones a later override overwrote left out).
pub fn apply_overrides_traced(
    source: &str,
    overrides: &[Override],
) -> Result<(String, Vec<Patch>), OverrideError> {
    let mut text = source.to_owned();
    let mut patches: Vec<Patch> = Vec::new();
    for ov in overrides {
        ov.check()?;
        let root = document(&text).map_err(|e| e.locate(&text, &ov.raw))?;
        let (range, replacement, holders) =
            resolve(&text, &root, ov).map_err(|reason| OverrideError::Path {
                raw: ov.raw.clone(),
                reason,
            })?;
        let len = replacement.len();
        text.replace_range(range.clone(), &replacement);
        patches.retain_mut(|p| {
            let Some(span) = shifted(&p.span, &range, len) else {
                return false;
            };
            p.span = span;
            p.holders
                .iter_mut()
                .all(|(_, r)| shifted(r, &range, len).map(|s| *r = s).is_some())
        });
        let span = range.start..range.start + len;
        let holders = ov
            .path
            .iter()
            .zip(holders)
            .filter(|(seg, _)| seg.parse::<usize>().is_err())
            .map(|(seg, r)| {
                (
                    seg.clone(),
                    shifted(&r, &range, len).unwrap_or(span.clone()),
                )
            })
            .collect();
        patches.push(Patch {
            raw: ov.raw.clone(),
            span,
            holders,
            replaced: range.len(),
        });
    }
    Ok((text, patches))
}

impl Shape {
    /// What one entry is called in messages.
    fn item(self) -> &'static str {
        match self {
            Shape::Struct => "field",
            Shape::List => "element",
            Shape::Map => "key",
        }
    }
}

impl SyntaxError {
    /// Converts the byte offset into a 1-based line:column (columns count characters).
    fn locate(self, text: &str, raw: &str) -> OverrideError {
        let before = &text.as_bytes()[..self.at.min(text.len())];
        let line_start = before
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |p| p + 1);
        OverrideError::Malformed {
            raw: raw.to_owned(),
            line: before.iter().filter(|&&b| b == b'\n').count() + 1,
            column: before[line_start..]
                .iter()
                .filter(|&&b| b & 0xC0 != 0x80)
                .count()
                + 1,
            reason: self.reason,
        }
    }
}

/// A parsed value: its text span, its name if it is `Name(...)` or a unit `Name`, and its
/// entries if it is bracketed.
#[derive(Debug)]
struct Node<'a> {
    span: Range<usize>,
    name: Option<&'a str>,
    body: Option<Body<'a>>,
}

#[derive(Debug)]
struct Body<'a> {
    shape: Shape,
    /// Offset just after the opening bracket, where missing fields are inserted.
    open: usize,
    entries: Vec<Entry<'a>>,
}

/// A struct field or map entry (`key` set), or a list / tuple element.
#[derive(Debug)]
struct Entry<'a> {
    key: Option<&'a str>,
    value: Node<'a>,
}

/// Why a segment selected nothing.
enum Miss {
    Absent,
    OutOfRange(usize),
    Ambiguous(Vec<usize>),
}

impl<'a> Body<'a> {
    /// The entry a path segment selects: a key, a positional index or a snake_case element name.
    fn select(&self, seg: &str) -> Result<&Node<'a>, Miss> {
        if let Some(e) = self.entries.iter().find(|e| e.key == Some(seg)) {
            return Ok(&e.value);
        }
        let positional: Vec<&Node<'a>> = self
            .entries
            .iter()
            .filter(|e| e.key.is_none())
            .map(|e| &e.value)
            .collect();
        if let (Ok(n), false) = (seg.parse::<usize>(), positional.is_empty()) {
            return positional.get(n).copied().ok_or(Miss::OutOfRange(n));
        }
        let hits: Vec<usize> = (0..positional.len())
            .filter(|&i| {
                positional[i]
                    .name
                    .is_some_and(|n| n == seg || snake_case(n) == seg)
            })
            .collect();
        match hits.as_slice() {
            [] => Err(Miss::Absent),
            &[i] => Ok(positional[i]),
            _ => Err(Miss::Ambiguous(hits)),
        }
    }

    /// Human-readable names of the entries: keys, snake_case element names or indices.
    fn labels(&self) -> Vec<String> {
        let mut next_index = 0..;
        let label = |e: &Entry| match e.key {
            Some(key) => key.to_owned(),
            None => {
                let index = next_index.next().unwrap_or_default();
                e.value.name.map_or_else(|| index.to_string(), snake_case)
            }
        };
        self.entries.iter().map(label).collect()
    }

    /// Explains a failed selection of `ov.path[i]` within `here`.
    fn explain(&self, miss: Miss, here: &str, ov: &Override, i: usize) -> String {
        let (seg, item) = (&ov.path[i], self.shape.item());
        match miss {
            Miss::OutOfRange(n) => {
                let len = self.entries.iter().filter(|e| e.key.is_none()).count();
                format!("index {n} is out of range: {here} has {len} {item}s")
            }
            Miss::Ambiguous(hits) => {
                let mut path = ov.path.clone();
                path[i] = hits[0].to_string();
                let hits: Vec<String> = hits.iter().map(usize::to_string).collect();
                format!(
                    "`{seg}` matches {item}s {} of {here}; select one by index, e.g. `--set {}={}`",
                    hits.join(", "),
                    path.join("."),
                    ov.value
                )
            }
            Miss::Absent => {
                let labels = self.labels();
                if labels.is_empty() {
                    return format!("no {item} `{seg}` in {here}, which is empty");
                }
                let names = labels.iter().filter(|l| l.parse::<usize>().is_err());
                let nearest = did_you_mean(seg, names.map(String::as_str))
                    .map(|l| format!("; did you mean `{l}`?"))
                    .unwrap_or_default();
                format!(
                    "no {item} `{seg}` in {here}; {item}s are: {}{nearest}",
                    labels.join(", ")
                )
            }
        }
    }
}

/// Recursive-descent parser over the tokens of one RON text.
struct Parser<'a> {
    src: &'a str,
    tokens: Vec<Token>,
    pos: usize,
}

impl<'a> Parser<'a> {
    fn new(src: &'a str) -> Result<Self, SyntaxError> {
        Ok(Self {
            src,
            tokens: lex(src)?,
            pos: 0,
        })
    }

    fn peek(&self, ahead: usize) -> Option<Token> {
        self.tokens.get(self.pos + ahead).copied()
    }

    fn text(&self, t: Token) -> &'a str {
        &self.src[t.start..t.end]
    }

    /// Consumes the next token if it is `tok`.
    fn eat(&mut self, tok: Tok) -> Option<Token> {
        let t = self.peek(0).filter(|t| t.tok == tok)?;
        self.pos += 1;
        Some(t)
    }

    fn unexpected(&self, wanted: &str) -> SyntaxError {
        match self.peek(0) {
            Some(t) => {
                let found: String = self.text(t).chars().take(24).collect();
                SyntaxError::new(t.start, format!("expected {wanted}, found `{found}`"))
            }
            None => SyntaxError::new(
                self.src.len(),
                format!("expected {wanted}, found end of input"),
            ),
        }
    }

    fn value(&mut self, depth: usize) -> Result<Node<'a>, SyntaxError> {
        let Some(t) = self.peek(0) else {
            return Err(self.unexpected("a value"));
        };
        if depth > MAX_DEPTH {
            return Err(SyntaxError::new(t.start, "brackets nested too deeply"));
        }
        let text = self.text(t);
        let named = self
            .peek(1)
            .is_some_and(|n| n.tok == Tok::Open(Shape::Struct));
        match t.tok {
            Tok::Open(_) => self.group(t.start, None, depth),
            _ if t.tok.is_word() && named => {
                self.pos += 1;
                self.group(t.start, Some(text), depth)
            }
            Tok::Ident | Tok::Word | Tok::Str | Tok::Char => {
                self.pos += 1;
                let unit = text.starts_with(|c: char| c.is_ascii_uppercase())
                    && text.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
                Ok(Node {
                    span: t.start..t.end,
                    name: unit.then_some(text),
                    body: None,
                })
            }
            _ => Err(self.unexpected("a value")),
        }
    }

    /// Parses a bracketed group whose opening bracket is the next token.
    fn group(
        &mut self,
        start: usize,
        name: Option<&'a str>,
        depth: usize,
    ) -> Result<Node<'a>, SyntaxError> {
        let Some(Token {
            tok: Tok::Open(shape),
            end: open,
            ..
        }) = self.peek(0)
        else {
            return Err(self.unexpected("`(`, `[` or `{`"));
        };
        self.pos += 1;
        let mut entries = Vec::new();
        let end = loop {
            if let Some(t) = self.eat(Tok::Close(shape)) {
                break t.end;
            }
            let key = match shape {
                Shape::List => None,
                Shape::Struct => self.field_name(),
                Shape::Map => {
                    let key = self.value(depth + 1)?;
                    if self.eat(Tok::Colon).is_none() {
                        return Err(self.unexpected("`:`"));
                    }
                    let text = &self.src[key.span];
                    Some(
                        text.strip_prefix('"')
                            .and_then(|s| s.strip_suffix('"'))
                            .unwrap_or(text),
                    )
                }
            };
            let value = self.value(depth + 1)?;
            entries.push(Entry { key, value });
            if let Some(t) = self.eat(Tok::Close(shape)) {
                break t.end;
            }
            if self.eat(Tok::Comma).is_none() {
                return Err(self.unexpected(&format!("`,` or `{}`", shape.close())));
            }
        };
        Ok(Node {
            span: start..end,
            name,
            body: Some(Body {
                shape,
                open,
                entries,
            }),
        })
    }

    /// Consumes `name:` if it comes next.
    fn field_name(&mut self) -> Option<&'a str> {
        let t = self.peek(0).filter(|t| t.tok.is_word())?;
        self.peek(1).filter(|c| c.tok == Tok::Colon)?;
        self.pos += 2;
        let name = self.text(t);
        Some(name.strip_prefix("r#").unwrap_or(name))
    }
}

/// Parses a whole scenario: `#![...]` attributes, then one struct `Name(...)` or `(...)`.
fn document(src: &str) -> Result<Node<'_>, SyntaxError> {
    let mut p = Parser::new(src)?;
    while p
        .peek(0)
        .is_some_and(|t| t.tok.is_word() && p.text(t).starts_with('#'))
    {
        p.pos += 1;
        if p.peek(0).map(|t| t.tok) != Some(Tok::Open(Shape::List)) {
            return Err(p.unexpected("`[` after `#`"));
        }
        p.value(0)?;
    }
    let root = p.value(0)?;
    if !matches!(&root.body, Some(b) if b.shape == Shape::Struct) {
        return Err(SyntaxError::new(
            root.span.start,
            "expected the scenario struct `Name(...)` or `(...)`",
        ));
    }
    if p.peek(0).is_some() {
        return Err(p.unexpected("end of input after the scenario struct"));
    }
    Ok(root)
}

/// Checks that `text` is exactly one RON value.
fn single_value(text: &str) -> Result<(), SyntaxError> {
    let mut p = Parser::new(text)?;
    p.value(0)?;
    match p.peek(0) {
        Some(_) => Err(p.unexpected("end of value")),
        None => Ok(()),
    }
}

/// What an override does to the text: the range it replaces, the replacement and, for
/// each path segment, the range of the struct, list or map that holds it.
type Edit = (Range<usize>, String, Vec<Range<usize>>);

/// Finds the [`Edit`] of an override.
fn resolve(src: &str, root: &Node<'_>, ov: &Override) -> Result<Edit, String> {
    let value = &ov.value;
    let mut node = root;
    let mut holders = Vec::new();
    for (i, seg) in ov.path.iter().enumerate() {
        let here = match i {
            0 => "the scenario".to_owned(),
            _ => format!("`{}`", ov.path[..i].join(".")),
        };
        let last = i + 1 == ov.path.len();
        holders.push(node.span.clone());
        let Some(body) = &node.body else {
            return match node.name {
                Some(name) if last => Ok((
                    node.span.clone(),
                    format!("{name}({seg}: {value})"),
                    holders,
                )),
                _ => Err(format!(
                    "{here} is `{}`, not a struct, list or map, so it has no `{seg}`",
                    &src[node.span.clone()]
                )),
            };
        };
        match body.select(seg) {
            Ok(child) if last => return Ok((child.span.clone(), value.clone(), holders)),
            Ok(child) => node = child,
            Err(Miss::Absent)
                if last
                    && body.shape != Shape::List
                    && body.entries.iter().all(|e| e.key.is_some()) =>
            {
                let key = match body.shape {
                    Shape::Map => format!("{seg:?}"),
                    _ => seg.clone(),
                };
                return Ok((body.open..body.open, format!("{key}: {value}, "), holders));
            }
            Err(miss) => return Err(body.explain(miss, &here, ov, i)),
        }
    }
    Err("empty path".to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = r##"#![enable(implicit_some)]
// Dam break (2D), with ) ] } , in a comment.
Scenario(
    name: "dam \"break\", (v2) ]", /* tricky /* nested ) */ , ] */
    dt: 1e-4,
    gravity: (0.0, -9.81),
    marker: 'x',
    escaped: '\'',
    quote: ''',
    materials: { "water": (density: 1000.0), "oil": (density: 900.0) },
    pipeline: [
        NeighbourGrid(cell: 0.02),
        GhostWalls(),
        Density(),
        Eos(gamma: 7.0, c0: 20.0),
        Forces(viscosity: 0.01 // ), ]
        ),
        Integrate,
        Reinitialise(every: 20),
        Probe(path: r#"out/"probe", (1).csv"#, every: 10),
    ],
)
"##;

    fn set(src: &str, args: &[&str]) -> Result<String, OverrideError> {
        let overrides: Vec<Override> = args.iter().map(|a| a.parse().unwrap()).collect();
        apply_overrides(src, &overrides)
    }

    /// Applies the overrides, checks the result is still RON, and returns it.
    fn patched(src: &str, args: &[&str]) -> String {
        let out = set(src, args).unwrap_or_else(|e| panic!("{e}"));
        if let Err(e) = ron::from_str::<ron::Value>(&out) {
            panic!("patched text is not RON ({e}):\n{out}");
        }
        out
    }

    fn error(src: &str, args: &[&str]) -> String {
        set(src, args).expect_err("expected an error").to_string()
    }

    #[test]
    fn sample_is_ron() {
        ron::from_str::<ron::Value>(SAMPLE).unwrap();
    }

    #[test]
    fn parses_override_arguments() {
        let ov: Override = " pipeline.3.gamma = 7.5 ".parse().unwrap();
        assert_eq!(ov.path, ["pipeline", "3", "gamma"]);
        assert_eq!(ov.value, "7.5");
        assert!("dt".parse::<Override>().is_err());
        assert!("a..b=1".parse::<Override>().is_err());
        assert!("=1".parse::<Override>().is_err());
        let e = "dt=1, x: 2".parse::<Override>().unwrap_err().to_string();
        assert!(e.contains("not a single RON value"), "{e}");
        assert!("dt=(1".parse::<Override>().is_err());
    }

    #[test]
    fn replaces_top_level_number() {
        let out = patched(SAMPLE, &["dt=2.5e-5"]);
        assert!(out.contains("dt: 2.5e-5,"));
        assert_eq!(out.len(), SAMPLE.len() + 2);
    }

    #[test]
    fn replaces_nested_field_in_named_element() {
        let out = patched(
            SAMPLE,
            &[
                "pipeline.reinitialise.every=5",
                "pipeline.neighbour_grid.cell=0.1",
            ],
        );
        assert!(out.contains("Reinitialise(every: 5)"));
        assert!(out.contains("NeighbourGrid(cell: 0.1)"));
        let out = patched(SAMPLE, &["pipeline.forces.viscosity=0.5"]);
        assert!(out.contains("Forces(viscosity: 0.5 // ), ]"), "{out}");
    }

    #[test]
    fn inserts_missing_field() {
        let out = patched(SAMPLE, &["pipeline.density.every=5", "pipeline.eos.b=3"]);
        assert!(out.contains("Density(every: 5, )"));
        assert!(out.contains("Eos(b: 3, gamma: 7.0"));
        let out = patched(SAMPLE, &["pipeline.integrate.scheme=Euler", "steps=10"]);
        assert!(out.contains("Integrate(scheme: Euler),"));
        assert!(out.contains("Scenario(steps: 10, "));
        let out = patched(SAMPLE, &["materials.mud=(density: 1500.0)"]);
        assert!(out.contains(r#"{"mud": (density: 1500.0),  "water""#));
        assert_eq!(patched("(/* empty */)", &["a=1"]), "(a: 1, /* empty */)");
    }

    #[test]
    fn numeric_index_and_tuple() {
        let out = patched(
            SAMPLE,
            &[
                "pipeline.3.gamma=1.4",
                "gravity.1=-1.62",
                "pipeline.5=Integrate(dt: 1)",
            ],
        );
        assert!(out.contains("Eos(gamma: 1.4, c0"));
        assert!(out.contains("gravity: (0.0, -1.62)"));
        assert!(out.contains("Integrate(dt: 1),"));
        let out = patched(
            SAMPLE,
            &[
                "pipeline.ghost_walls=GhostWalls(layers: 3)",
                "materials.oil.density=800",
            ],
        );
        assert!(out.contains("GhostWalls(layers: 3),"));
        assert!(out.contains(r#""oil": (density: 800)"#));
    }

    #[test]
    fn comments_and_strings_do_not_confuse() {
        let out = patched(
            SAMPLE,
            &["name=\"x\"", "pipeline.probe.every=1", "marker='y'"],
        );
        assert!(out.contains(r#"name: "x", /* tricky"#));
        assert!(out.contains(r##"Probe(path: r#"out/"probe", (1).csv"#, every: 1)"##));
        assert!(out.contains("marker: 'y',"));
        let out = patched(SAMPLE, &["escaped='z'", "pipeline.probe.path=\"p.csv\""]);
        assert!(out.contains("escaped: 'z',"));
        assert!(out.contains(r#"Probe(path: "p.csv", every"#));
    }

    #[test]
    fn unknown_names_suggest_nearest() {
        let e = error(SAMPLE, &["pipeline.reinitialize.every=5"]);
        assert_eq!(
            e,
            "--set pipeline.reinitialize.every=5: no element `reinitialize` in `pipeline`; elements are: \
             neighbour_grid, ghost_walls, density, eos, forces, integrate, reinitialise, probe; \
             did you mean `reinitialise`?"
        );
        let e = error(SAMPLE, &["pipelin.density.every=5"]);
        assert!(
            e.contains("no field `pipelin` in the scenario; fields are: name, dt,"),
            "{e}"
        );
        assert!(e.contains("; did you mean `pipeline`?"), "{e}");
        let e = error(SAMPLE, &["pipeline.eos.gama.x=1"]);
        assert!(
            e.contains(
                "no field `gama` in `pipeline.eos`; fields are: gamma, c0; did you mean `gamma`?"
            ),
            "{e}"
        );
        let e = error(SAMPLE, &["pipeline.9.every=1"]);
        assert!(
            e.contains("index 9 is out of range: `pipeline` has 8 elements"),
            "{e}"
        );
        let e = error(SAMPLE, &["dt.x=1"]);
        assert!(e.contains("`dt` is `1e-4`, not a struct"), "{e}");
        let e = error(SAMPLE, &["gravity.z=1"]);
        assert!(e.contains("fields are: 0, 1"), "{e}");
    }

    #[test]
    fn patches_record_where_each_override_landed() {
        let args: Vec<Override> = [
            "pipeline.reinitialise.every=5",
            "pipeline.eos.b=3",
            "dt=2.5e-5",
            "pipeline.integrate.scheme=Euler",
        ]
        .iter()
        .map(|a| a.parse().unwrap())
        .collect();
        let (text, patches) = apply_overrides_traced(SAMPLE, &args).unwrap();
        let written: Vec<&str> = patches.iter().map(|p| &text[p.span.clone()]).collect();
        assert_eq!(
            written,
            ["5", "b: 3, ", "2.5e-5", "Integrate(scheme: Euler)"]
        );
        let eos = &patches[1];
        assert_eq!(eos.field(), Some("b"));
        let holders: Vec<(&str, &str)> = eos
            .holders
            .iter()
            .map(|(s, r)| (s.as_str(), &text[r.clone()]))
            .collect();
        assert_eq!(holders[1].0, "eos");
        assert!(
            holders[1].1.starts_with("[\n        NeighbourGrid"),
            "{holders:?}"
        );
        assert_eq!(holders[2], ("b", "Eos(b: 3, gamma: 7.0, c0: 20.0)"));
        // Text outside the patches maps back to the file: `gamma` after the insertion.
        let gamma = text.find("gamma: 7.0").unwrap();
        assert_eq!(
            source_offset(gamma, &patches),
            SAMPLE.find("gamma: 7.0").unwrap()
        );
        let probe = text.find("Probe(").unwrap();
        assert_eq!(
            source_offset(probe, &patches),
            SAMPLE.find("Probe(").unwrap()
        );
    }

    #[test]
    fn overwritten_patches_are_dropped_and_holders_grow() {
        let args: Vec<Override> = [
            "pipeline.eos.gamma=1.4",
            "pipeline.eos=Eos(c0: 30.0)",
            "pipeline.eos.c0=40.0",
            "gravity.1=-1.62",
        ]
        .iter()
        .map(|a| a.parse().unwrap())
        .collect();
        let (text, patches) = apply_overrides_traced(SAMPLE, &args).unwrap();
        let written: Vec<(&str, &str)> = patches
            .iter()
            .map(|p| (p.raw.as_str(), &text[p.span.clone()]))
            .collect();
        // The first is overwritten by the second; the third lies inside the second.
        assert_eq!(
            written,
            [
                ("pipeline.eos=Eos(c0: 30.0)", "Eos(c0: 40.0)"),
                ("pipeline.eos.c0=40.0", "40.0"),
                ("gravity.1=-1.62", "-1.62"),
            ]
        );
        assert_eq!(patches[2].field(), Some("gravity"));
        let forces = text.find("Forces(").unwrap();
        assert_eq!(
            source_offset(forces, &patches),
            SAMPLE.find("Forces(").unwrap()
        );
    }

    #[test]
    fn ambiguous_element_suggests_index() {
        let src = "(pipeline: [Density(every: 1), Eos(), Density()])";
        let e = error(src, &["pipeline.density.every=5"]);
        assert!(
            e.contains("`density` matches elements 0, 2 of `pipeline`"),
            "{e}"
        );
        assert!(e.contains("--set pipeline.0.every=5"), "{e}");
        assert!(patched(src, &["pipeline.2.every=5"]).contains("Density(every: 5, )"));
    }

    #[test]
    fn malformed_input_errors() {
        for src in [
            "Scenario(dt: 1",
            "Scenario(dt: 1))",
            "Scenario(a: [1, 2)",
            "(a: \"open)",
            "(a: 1) /* open",
            "[1, 2]",
            "",
            "(a: r#\"x\")",
            "(a: 'x)",
            "(a: 1 2)",
            "(a: {1 2})",
            "#! (a: 1)",
        ] {
            match set(src, &["a=2"]) {
                Err(OverrideError::Malformed { .. }) => {}
                other => panic!("{src:?} gave {other:?}"),
            }
        }
        let e = error("Scenario(\n  dt: 1,\n  x: ]\n)", &["dt=2"]);
        assert!(
            e.contains("malformed at 3:6: expected a value, found `]`"),
            "{e}"
        );
        let deep = format!("(a: {}{})", "[".repeat(10_000), "]".repeat(10_000));
        assert!(set(&deep, &["a=1"]).is_err());
    }

    #[test]
    fn random_mutations_never_panic() {
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut rand = |n: usize| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % n as u64) as usize
        };
        let pieces = [
            "(", ")", "[", "]", "{", "}", ",", ":", "\"", "'", "/*", "*/", "//", "\n", "r#\"",
            "\\", "#", "é", "x",
        ];
        let args: Vec<Override> = [
            "pipeline.density.every=5",
            "dt=1",
            "pipeline.3.gamma=2",
            "materials.water.density=1",
            "gravity.0=1",
        ]
        .iter()
        .map(|a| a.parse().unwrap())
        .collect();
        for round in 0..600 {
            let mut text = SAMPLE.to_owned();
            for _ in 0..1 + round % 4 {
                let mut at = rand(text.len() + 1);
                while !text.is_char_boundary(at) {
                    at -= 1;
                }
                match rand(3) {
                    0 => text.truncate(at),
                    1 => text.insert_str(at, pieces[rand(pieces.len())]),
                    _ => {
                        let end = (at + 1..=text.len())
                            .find(|&e| text.is_char_boundary(e))
                            .unwrap_or(at);
                        text.replace_range(at..end, "");
                    }
                }
            }
            if let Ok((out, patches)) = apply_overrides_traced(&text, &args[rand(args.len())..]) {
                for p in &patches {
                    assert!(out.get(p.span.clone()).is_some(), "{p:?} in {out:?}");
                    for (_, r) in &p.holders {
                        assert!(r.start <= p.span.start && p.span.end <= r.end, "{p:?}");
                    }
                }
            }
        }
    }
}
