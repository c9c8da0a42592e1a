//! Where an error is in the scenario text: the field's line and column, the `--set`
//! argument that set it, and the nearest known name.

use super::*;

/// Builds the errors of [`validate`]: each names its field and points at a token of
/// the file (or nowhere, line 0, when there is none to point at).
pub(crate) struct Locator<'a> {
    pub(crate) file: &'a str,
    pub(crate) doc: &'a Doc<'a>,
}

impl Locator<'_> {
    /// An error about `field`, placed at token `place`.
    pub(crate) fn error(&self, field: &str, place: Option<usize>, message: String) -> LoadError {
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
    pub(crate) fn field(&self, field: &str, message: String) -> LoadError {
        self.error(field, self.doc.key(&[field]), message)
    }

    /// Where field `key` of element `i` of the top-level list `list` is, else the
    /// list's own `list:`.
    pub(crate) fn element(&self, list: &str, i: usize, key: &str) -> Option<usize> {
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
pub(crate) fn blame_override(
    mut e: LoadError,
    doc: &Doc,
    patches: &[Patch],
    source: &str,
) -> LoadError {
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
pub(crate) fn name_field(
    doc: &Doc,
    line: usize,
    column: usize,
    message: String,
) -> (Option<String>, String) {
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
pub(crate) fn leading_field(message: &str) -> Option<(String, String)> {
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
pub(crate) fn unknown_field(message: &str) -> Option<String> {
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
pub(crate) fn did_you_mean_in(message: String) -> String {
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
pub(crate) struct Doc<'a> {
    pub(crate) text: &'a str,
    pub(crate) toks: Vec<Token>,
}

impl<'a> Doc<'a> {
    pub(crate) fn new(text: &'a str) -> Self {
        Self {
            text,
            toks: lex_lenient(text),
        }
    }

    /// The text of token `i`.
    pub(crate) fn name(&self, i: usize) -> &str {
        let t = self.toks[i];
        let name = self.text.get(t.start..t.end).unwrap_or("");
        name.strip_prefix("r#").unwrap_or(name)
    }

    /// Whether token `i` is a field name: an identifier followed by `:`.
    pub(crate) fn is_key(&self, i: usize) -> bool {
        self.toks[i].tok == Tok::Ident && self.toks.get(i + 1).is_some_and(|t| t.tok == Tok::Colon)
    }

    /// Token of the field `path[last]` inside ... inside the top-level `path[0]`.
    pub(crate) fn key(&self, path: &[&str]) -> Option<usize> {
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
    pub(crate) fn value_end(&self, from: usize, depth: usize) -> usize {
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
    pub(crate) fn element(&self, path: &[&str], n: usize, key: &str) -> Option<usize> {
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
    pub(crate) fn key_within(&self, start: usize, key: &str) -> Option<usize> {
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
    pub(crate) fn field_before(&self, offset: usize) -> Option<String> {
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
    pub(crate) fn offset(&self, line: usize, column: usize) -> usize {
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
    pub(crate) fn line_col(&self, i: usize) -> (usize, usize) {
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
