//! The one RON lexer of the scenario format. The `--set` overrides parse its tokens
//! strictly ([`lex`]: an unterminated string, char literal, raw string or block comment
//! is an error at its first byte); the loader's error positions use it leniently
//! ([`lex_lenient`]: any text tokenizes, such literals and comments run to the end of
//! the text, and a `'` that starts no char literal is a token of its own).
//!
//! Whitespace and comments (`//`, nested `/* */`) are skipped; strings (plain, byte and
//! raw) and char literals are single tokens; any other run of characters up to a
//! delimiter is one word: an identifier (`name`, raw `r#name`) or another word (a
//! number, `#!`, ...).

/// Kind of bracketed group.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Shape {
    /// `Name(...)` or `(...)`: a struct, tuple or enum variant.
    Struct,
    /// `[...]`
    List,
    /// `{...}`
    Map,
}

impl Shape {
    /// The closing bracket.
    pub(crate) fn close(self) -> char {
        match self {
            Shape::Struct => ')',
            Shape::List => ']',
            Shape::Map => '}',
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Tok {
    Open(Shape),
    Close(Shape),
    Comma,
    Colon,
    /// String or byte string, plain or raw.
    Str,
    /// Char or byte literal.
    Char,
    /// An identifier, `name` or raw `r#name`.
    Ident,
    /// A number or any other run of non-delimiter characters.
    Word,
}

impl Tok {
    /// An identifier or another word (what is neither a bracket, punctuation nor a
    /// literal).
    pub(crate) fn is_word(self) -> bool {
        matches!(self, Tok::Ident | Tok::Word)
    }
}

/// A token: its byte range and nesting depth (the number of groups open around it; an
/// opening or closing bracket has the depth outside its group).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Token {
    pub tok: Tok,
    pub start: usize,
    pub end: usize,
    pub depth: usize,
}

/// A syntax error at a byte offset.
#[derive(Debug)]
pub(crate) struct SyntaxError {
    pub at: usize,
    pub reason: String,
}

impl SyntaxError {
    pub(crate) fn new(at: usize, reason: impl Into<String>) -> Self {
        Self {
            at,
            reason: reason.into(),
        }
    }
}

/// The tokens of `src`; an unterminated literal or block comment is an error.
pub(crate) fn lex(src: &str) -> Result<Vec<Token>, SyntaxError> {
    scan(src, true)
}

/// The tokens of any text: an unterminated literal or block comment runs to the end.
pub(crate) fn lex_lenient(src: &str) -> Vec<Token> {
    scan(src, false).unwrap_or_default()
}

fn scan(src: &str, strict: bool) -> Result<Vec<Token>, SyntaxError> {
    let b = src.as_bytes();
    let mut tokens = Vec::new();
    let (mut i, mut depth) = (0, 0usize);
    while let Some(&c) = b.get(i) {
        let start = i;
        let tok = match c {
            _ if c.is_ascii_whitespace() => {
                i += 1;
                continue;
            }
            b'/' if b.get(i + 1) == Some(&b'/') => {
                i = b[i..]
                    .iter()
                    .position(|&c| c == b'\n')
                    .map_or(b.len(), |p| i + p);
                continue;
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                i = match block_comment_end(b, i) {
                    Ok(end) => end,
                    Err(e) if strict => return Err(e),
                    Err(_) => b.len(),
                };
                continue;
            }
            b'(' | b'[' | b'{' | b')' | b']' | b'}' => {
                i += 1;
                let shape = match c {
                    b'(' | b')' => Shape::Struct,
                    b'[' | b']' => Shape::List,
                    _ => Shape::Map,
                };
                if matches!(c, b'(' | b'[' | b'{') {
                    Tok::Open(shape)
                } else {
                    Tok::Close(shape)
                }
            }
            b',' => {
                i += 1;
                Tok::Comma
            }
            b':' => {
                i += 1;
                Tok::Colon
            }
            _ => match literal(b, i) {
                Ok(Some((tok, end))) => {
                    i = end;
                    tok
                }
                Ok(None) => {
                    i += 1;
                    while i < b.len() && !is_delimiter(b, i) {
                        i += 1;
                    }
                    if is_identifier(&b[start..i]) {
                        Tok::Ident
                    } else {
                        Tok::Word
                    }
                }
                Err(e) if strict => return Err(e),
                // Lenient: a string runs to the end of the text; a `'` that starts no
                // char literal is a token of its own.
                Err(_) if b[i + usize::from(c == b'b')] == b'\'' => {
                    i += 1;
                    Tok::Word
                }
                Err(_) => {
                    i = b.len();
                    Tok::Str
                }
            },
        };
        let token_depth = match tok {
            Tok::Open(_) => {
                depth += 1;
                depth - 1
            }
            Tok::Close(_) => {
                depth = depth.saturating_sub(1);
                depth
            }
            _ => depth,
        };
        tokens.push(Token {
            tok,
            start,
            end: i,
            depth: token_depth,
        });
    }
    Ok(tokens)
}

/// Whether `word` is an identifier: `name` or `r#name`, `name` ASCII letters, digits
/// and `_`, not starting with a digit.
fn is_identifier(word: &[u8]) -> bool {
    let name = word.strip_prefix(b"r#").unwrap_or(word);
    name.first()
        .is_some_and(|c| c.is_ascii_alphabetic() || *c == b'_')
        && name.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_')
}

/// Whether the byte at `i` ends a word.
fn is_delimiter(b: &[u8], i: usize) -> bool {
    let c = b[i];
    c.is_ascii_whitespace()
        || b"()[]{},:\"'".contains(&c)
        || (c == b'/' && matches!(b.get(i + 1), Some(b'/' | b'*')))
}

/// End offset of the (nested) block comment starting at `start`.
fn block_comment_end(b: &[u8], start: usize) -> Result<usize, SyntaxError> {
    let (mut depth, mut i) = (0usize, start);
    while i < b.len() {
        if b[i..].starts_with(b"/*") {
            depth += 1;
            i += 2;
        } else if b[i..].starts_with(b"*/") {
            depth -= 1;
            i += 2;
            if depth == 0 {
                return Ok(i);
            }
        } else {
            i += 1;
        }
    }
    Err(SyntaxError::new(start, "unterminated block comment"))
}

/// Recognises a string, raw string or char literal (optionally `b`-prefixed) at `i`.
fn literal(b: &[u8], i: usize) -> Result<Option<(Tok, usize)>, SyntaxError> {
    let p = i + usize::from(b[i] == b'b');
    match b.get(p) {
        Some(&quote @ (b'"' | b'\'')) => {
            // `'''` is the char `'` in RON, so a char's first character never closes it.
            let mut j = p + 1 + usize::from(quote == b'\'' && b.get(p + 1) == Some(&b'\''));
            while let Some(&c) = b.get(j) {
                if c == quote {
                    let tok = if quote == b'"' { Tok::Str } else { Tok::Char };
                    return Ok(Some((tok, j + 1)));
                }
                j += if c == b'\\' { 2 } else { 1 };
            }
            let what = if quote == b'"' {
                "string"
            } else {
                "char literal"
            };
            Err(SyntaxError::new(i, format!("unterminated {what}")))
        }
        Some(b'r') => {
            let hashes = b[p + 1..].iter().take_while(|&&c| c == b'#').count();
            let body = p + 2 + hashes;
            if b.get(body - 1) != Some(&b'"') {
                return Ok(None);
            }
            let mut close = vec![b'"'];
            close.resize(hashes + 1, b'#');
            match b[body..].windows(close.len()).position(|w| w == close) {
                Some(k) => Ok(Some((Tok::Str, body + k + close.len()))),
                None => Err(SyntaxError::new(i, "unterminated raw string")),
            }
        }
        _ => Ok(None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinds(src: &str) -> Vec<(Tok, &str, usize)> {
        lex_lenient(src)
            .into_iter()
            .map(|t| (t.tok, &src[t.start..t.end], t.depth))
            .collect()
    }

    #[test]
    fn one_lexer_strict_and_lenient() {
        let src = "#![x] A(r#b: -1.5e3, c: [\"s\", 'q', br#\"r\"#], /* /* */ */ d: {1: ()})";
        let toks = kinds(src);
        assert_eq!(lex(src).unwrap().len(), toks.len());
        assert!(toks.contains(&(Tok::Word, "#!", 0)));
        assert!(toks.contains(&(Tok::Ident, "r#b", 1)));
        assert!(toks.contains(&(Tok::Word, "-1.5e3", 1)));
        assert!(toks.contains(&(Tok::Str, "br#\"r\"#", 2)));
        assert!(toks.contains(&(Tok::Char, "'q'", 2)));
        assert!(toks.contains(&(Tok::Close(Shape::Map), "}", 1)));
        assert_eq!(toks.last(), Some(&(Tok::Close(Shape::Struct), ")", 0)));
        // Unterminated: an error in strict mode, to the end (or one `'`) in lenient.
        for (src, reason, last) in [
            (
                "(a: \"x, b: 1)",
                "unterminated string",
                (Tok::Str, "\"x, b: 1)", 1),
            ),
            (
                "(a: 'x, b: 1)",
                "unterminated char literal",
                (Tok::Close(Shape::Struct), ")", 0),
            ),
            (
                "(a: r#\"x\")",
                "unterminated raw string",
                (Tok::Str, "r#\"x\")", 1),
            ),
        ] {
            assert_eq!(lex(src).unwrap_err().reason, reason);
            assert_eq!(kinds(src).last(), Some(&last), "{src}");
        }
        assert_eq!(lex("(/* x").unwrap_err().at, 1);
        assert_eq!(kinds("(/* x").len(), 1);
    }
}
