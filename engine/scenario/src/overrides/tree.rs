//! The RON text as a tree of spans, just enough to find the value a `--set` path names
//! and splice a new one in its place.

use super::*;

/// A parsed value: its text span, its name if it is `Name(...)` or a unit `Name`, and its
/// entries if it is bracketed.
#[derive(Debug)]
pub(crate) struct Node<'a> {
    pub(crate) span: Range<usize>,
    pub(crate) name: Option<&'a str>,
    pub(crate) body: Option<Body<'a>>,
}

#[derive(Debug)]
pub(crate) struct Body<'a> {
    pub(crate) shape: Shape,
    /// Offset just after the opening bracket, where missing fields are inserted.
    pub(crate) open: usize,
    pub(crate) entries: Vec<Entry<'a>>,
}

/// A struct field or map entry (`key` set), or a list / tuple element.
#[derive(Debug)]
pub(crate) struct Entry<'a> {
    pub(crate) key: Option<&'a str>,
    pub(crate) value: Node<'a>,
}

/// Why a segment selected nothing.
pub(crate) enum Miss {
    Absent,
    OutOfRange(usize),
    Ambiguous(Vec<usize>),
}

impl<'a> Body<'a> {
    /// The entry a path segment selects: a key, a positional index or a snake_case element name.
    pub(crate) fn select(&self, seg: &str) -> Result<&Node<'a>, Miss> {
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
    pub(crate) fn labels(&self) -> Vec<String> {
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
    pub(crate) fn explain(&self, miss: Miss, here: &str, ov: &Override, i: usize) -> ResolveError {
        let (seg, item) = (ov.path[i].clone(), self.shape.item());
        let here = here.to_owned();
        match miss {
            Miss::OutOfRange(index) => ResolveError::OutOfRange {
                index,
                here,
                len: self.entries.iter().filter(|e| e.key.is_none()).count(),
                item,
            },
            Miss::Ambiguous(hits) => {
                let mut path = ov.path.clone();
                path[i] = hits.first().map(usize::to_string).unwrap_or_default();
                ResolveError::Ambiguous {
                    seg,
                    item,
                    hits,
                    here,
                    example: format!("{}={}", path.join("."), ov.value),
                }
            }
            Miss::Absent => {
                let labels = self.labels();
                if labels.is_empty() {
                    return ResolveError::Empty { seg, item, here };
                }
                let names = labels.iter().filter(|l| l.parse::<usize>().is_err());
                let nearest = did_you_mean(seg.as_str(), names.map(String::as_str));
                ResolveError::Absent {
                    nearest: nearest.map(str::to_owned),
                    seg,
                    item,
                    here,
                    labels,
                }
            }
        }
    }
}

/// Recursive-descent parser over the tokens of one RON text.
pub(crate) struct Parser<'a> {
    pub(crate) src: &'a str,
    pub(crate) tokens: Vec<Token>,
    pub(crate) pos: usize,
}

impl<'a> Parser<'a> {
    pub(crate) fn new(src: &'a str) -> Result<Self, SyntaxError> {
        Ok(Self {
            src,
            tokens: lex(src)?,
            pos: 0,
        })
    }

    pub(crate) fn peek(&self, ahead: usize) -> Option<Token> {
        self.tokens.get(self.pos + ahead).copied()
    }

    pub(crate) fn text(&self, t: Token) -> &'a str {
        &self.src[t.start..t.end]
    }

    /// Consumes the next token if it is `tok`.
    pub(crate) fn eat(&mut self, tok: Tok) -> Option<Token> {
        let t = self.peek(0).filter(|t| t.tok == tok)?;
        self.pos += 1;
        Some(t)
    }

    pub(crate) fn unexpected(&self, wanted: &str) -> SyntaxError {
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

    pub(crate) fn value(&mut self, depth: usize) -> Result<Node<'a>, SyntaxError> {
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
    pub(crate) fn group(
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
    pub(crate) fn field_name(&mut self) -> Option<&'a str> {
        let t = self.peek(0).filter(|t| t.tok.is_word())?;
        self.peek(1).filter(|c| c.tok == Tok::Colon)?;
        self.pos += 2;
        let name = self.text(t);
        Some(name.strip_prefix("r#").unwrap_or(name))
    }
}

/// Parses a whole scenario: `#![...]` attributes, then one struct `Name(...)` or `(...)`.
pub(crate) fn document(src: &str) -> Result<Node<'_>, SyntaxError> {
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
pub(crate) fn single_value(text: &str) -> Result<(), SyntaxError> {
    let mut p = Parser::new(text)?;
    p.value(0)?;
    match p.peek(0) {
        Some(_) => Err(p.unexpected("end of value")),
        None => Ok(()),
    }
}

/// What an override does to the text: the range it replaces, the replacement and, for
/// each path segment, the range of the struct, list or map that holds it.
pub(crate) type Edit = (Range<usize>, String, Vec<Range<usize>>);

/// Why an override's path selects nothing in the scenario; the message is the reason of
/// [`OverrideError::Path`]. `here` names the value searched: `the scenario` or a
/// path in backquotes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum ResolveError {
    /// A segment goes into a value that is not a struct, list or map (`text`).
    #[error("{here} is `{text}`, not a struct, list or map, so it has no `{seg}`")]
    NotAContainer {
        here: String,
        text: String,
        seg: String,
    },
    /// A list index at or past the end of the `len` positional entries.
    #[error("index {index} is out of range: {here} has {len} {item}s")]
    OutOfRange {
        index: usize,
        here: String,
        len: usize,
        item: &'static str,
    },
    /// An element name that several elements (indices `hits`) answer to; `example` is
    /// the override with the first of them, `path=value`.
    #[error(
        "`{seg}` matches {item}s {} of {here}; select one by index, e.g. `--set {example}`",
        hits.iter().map(usize::to_string).collect::<Vec<_>>().join(", ")
    )]
    Ambiguous {
        seg: String,
        item: &'static str,
        hits: Vec<usize>,
        here: String,
        example: String,
    },
    /// No entry of that name in an empty struct, list or map.
    #[error("no {item} `{seg}` in {here}, which is empty")]
    Empty {
        seg: String,
        item: &'static str,
        here: String,
    },
    /// No entry of that name; `labels` are the entries there, `nearest` the closest name.
    #[error(
        "no {item} `{seg}` in {here}; {item}s are: {}{}",
        labels.join(", "),
        nearest.as_ref().map(|l| format!("; did you mean `{l}`?")).unwrap_or_default()
    )]
    Absent {
        seg: String,
        item: &'static str,
        here: String,
        labels: Vec<String>,
        nearest: Option<String>,
    },
    /// The override has no path segment.
    #[error("empty path")]
    EmptyPath,
}

/// Finds the [`Edit`] of an override.
pub(crate) fn resolve(src: &str, root: &Node<'_>, ov: &Override) -> Result<Edit, ResolveError> {
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
                _ => Err(ResolveError::NotAContainer {
                    here,
                    text: src[node.span.clone()].to_owned(),
                    seg: seg.clone(),
                }),
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
    Err(ResolveError::EmptyPath)
}
