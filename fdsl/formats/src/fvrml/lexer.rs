//! FVRML text to tokens, one at a time, each with its [`Pos`].
//!
//! White space is VRML's (space, tab, line breaks, commas) plus the no-break space and a
//! byte-order mark. Comments run from `#` or `//` to the end of the line (the thesis's
//! figures use `//`). Strings are `"..."` with `\"`, `\\`, `\“` and `\”` escapes, or the
//! typographic `“...”` the thesis prints (opened by `“` or `”`, closed by either), and the
//! mixed `"0.8”` it also prints (a straight quote closed by a typographic one); they may span
//! lines.
//! Never fails: what cannot be read becomes an [`Tok::Error`] token with a message.

use super::document::Pos;
use fdsl::syntax::Span;

/// A token.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Tok<'a> {
    /// A name or keyword.
    Ident(&'a str),
    /// A finite number.
    Number(f64),
    /// A string, unescaped.
    Str(String),
    /// `{`
    LBrace,
    /// `}`
    RBrace,
    /// `[`
    LBracket,
    /// `]`
    RBracket,
    /// `:` (the thesis writes `definition: "1"`).
    Colon,
    /// `.` (in `ROUTE a.b TO c.d`).
    Dot,
    /// Something that cannot be read, and why.
    Error(String),
    /// The end of the text.
    Eof,
}

/// A token and where it is.
#[derive(Clone, Debug)]
pub(super) struct Token<'a> {
    pub(super) tok: Tok<'a>,
    pub(super) pos: Pos,
}

const LEFT_QUOTE: char = '\u{201C}';
const RIGHT_QUOTE: char = '\u{201D}';

/// Whether `c` can start an identifier.
pub(super) fn is_ident_start(c: char) -> bool {
    c.is_ascii_alphabetic()
        || c == '_'
        || (!c.is_ascii() && !is_space(c) && c != LEFT_QUOTE && c != RIGHT_QUOTE)
}

/// Whether `c` can continue an identifier.
pub(super) fn is_ident_continue(c: char) -> bool {
    is_ident_start(c) || c.is_ascii_digit() || c == '+' || c == '-'
}

fn is_space(c: char) -> bool {
    matches!(c, ' ' | '\t' | '\n' | '\r' | ',' | '\u{A0}' | '\u{FEFF}')
}

/// The lexer: a cursor over the text that tracks line and column.
pub(super) struct Lexer<'a> {
    text: &'a str,
    offset: usize,
    line: u32,
    column: u32,
    /// Where the first typographic quote was seen, for one warning per file.
    pub(super) typographic_quote: Option<Pos>,
}

impl<'a> Lexer<'a> {
    pub(super) fn new(text: &'a str) -> Lexer<'a> {
        Lexer {
            text,
            offset: 0,
            line: 1,
            column: 1,
            typographic_quote: None,
        }
    }

    fn peek_char(&self) -> Option<char> {
        self.text[self.offset..].chars().next()
    }

    fn bump(&mut self) -> Option<char> {
        let c = self.peek_char()?;
        self.offset += c.len_utf8();
        if c == '\n' {
            self.line = self.line.saturating_add(1);
            self.column = 1;
        } else {
            self.column = self.column.saturating_add(1);
        }
        Some(c)
    }

    fn here(&self) -> Pos {
        Pos {
            line: self.line,
            column: self.column,
            span: Span::new(self.offset, self.offset),
        }
    }

    fn skip_trivia(&mut self) {
        loop {
            let rest = &self.text[self.offset..];
            match self.peek_char() {
                Some(c) if is_space(c) => {
                    self.bump();
                }
                Some('#') => self.skip_line(),
                Some('/') if rest.starts_with("//") => self.skip_line(),
                _ => return,
            }
        }
    }

    fn skip_line(&mut self) {
        let rest = &self.text[self.offset..];
        let len = rest.find('\n').unwrap_or(rest.len());
        // A comment has no line break inside, so only the column moves.
        let n_chars = rest[..len].chars().count();
        self.offset += len;
        self.column = self
            .column
            .saturating_add(u32::try_from(n_chars).unwrap_or(u32::MAX));
    }

    /// The next token.
    pub(super) fn next_token(&mut self) -> Token<'a> {
        self.skip_trivia();
        let mut pos = self.here();
        let start = self.offset;
        let tok = match self.peek_char() {
            None => Tok::Eof,
            Some(c) => self.token(c),
        };
        pos.span = Span::new(start, self.offset);
        Token { tok, pos }
    }

    fn token(&mut self, c: char) -> Tok<'a> {
        let single = |lexer: &mut Lexer<'a>, tok: Tok<'a>| {
            lexer.bump();
            tok
        };
        match c {
            '{' => single(self, Tok::LBrace),
            '}' => single(self, Tok::RBrace),
            '[' => single(self, Tok::LBracket),
            ']' => single(self, Tok::RBracket),
            ':' => single(self, Tok::Colon),
            '"' => self.string('"'),
            LEFT_QUOTE | RIGHT_QUOTE => {
                if self.typographic_quote.is_none() {
                    self.typographic_quote = Some(self.here());
                }
                self.string(c)
            }
            '0'..='9' | '+' | '-' => self.number(),
            '.' => {
                let next = self.text[self.offset + 1..].chars().next();
                if next.is_some_and(|n| n.is_ascii_digit()) {
                    self.number()
                } else {
                    single(self, Tok::Dot)
                }
            }
            c if is_ident_start(c) => {
                let start = self.offset;
                while self.peek_char().is_some_and(is_ident_continue) {
                    self.bump();
                }
                Tok::Ident(&self.text[start..self.offset])
            }
            c => {
                self.bump();
                Tok::Error(format!("unexpected character `{}`", c.escape_debug()))
            }
        }
    }

    fn string(&mut self, open: char) -> Tok<'a> {
        self.bump();
        let typographic = open != '"';
        let mut out = String::new();
        loop {
            match self.bump() {
                None => {
                    return Tok::Error(
                        "this string is never closed (no closing quote before the end)".into(),
                    );
                }
                Some('"') => return Tok::Str(out),
                // The thesis mixes straight and typographic quotes in one string (`"0.8”`):
                // either closes it. A typographic quote inside a straight-quoted string is
                // therefore not possible; no field of the dialect needs one.
                Some(LEFT_QUOTE | RIGHT_QUOTE) => {
                    if !typographic && self.typographic_quote.is_none() {
                        self.typographic_quote = Some(self.here());
                    }
                    return Tok::Str(out);
                }
                Some('\\') => match self.peek_char() {
                    Some(e @ ('"' | '\\' | LEFT_QUOTE | RIGHT_QUOTE)) => {
                        self.bump();
                        out.push(e);
                    }
                    _ => out.push('\\'),
                },
                Some(c) => out.push(c),
            }
        }
    }

    fn number(&mut self) -> Tok<'a> {
        let start = self.offset;
        let bytes = self.text.as_bytes();
        let mut i = start;
        if matches!(bytes[i], b'+' | b'-') {
            i += 1;
        }
        let digits_from = i;
        if bytes.get(i) == Some(&b'0') && matches!(bytes.get(i + 1), Some(b'x' | b'X')) {
            return self.hex(start, i + 2);
        }
        while bytes.get(i).is_some_and(u8::is_ascii_digit) {
            i += 1;
        }
        if bytes.get(i) == Some(&b'.') {
            i += 1;
            while bytes.get(i).is_some_and(u8::is_ascii_digit) {
                i += 1;
            }
        }
        let mantissa_digits = self.text[digits_from..i]
            .bytes()
            .any(|b| b.is_ascii_digit());
        if !mantissa_digits {
            // A lone sign (or sign and dot).
            self.advance_to(i.max(start + 1));
            return Tok::Error(format!(
                "`{}` is not a number",
                &self.text[start..self.offset]
            ));
        }
        if matches!(bytes.get(i), Some(b'e' | b'E')) {
            let mut j = i + 1;
            if matches!(bytes.get(j), Some(b'+' | b'-')) {
                j += 1;
            }
            if bytes.get(j).is_some_and(u8::is_ascii_digit) {
                while bytes.get(j).is_some_and(u8::is_ascii_digit) {
                    j += 1;
                }
                i = j;
            }
        }
        self.advance_to(i);
        let text = &self.text[start..i];
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Tok::Number(v),
            _ => Tok::Error(format!("the number `{}` is out of range", clip(text))),
        }
    }

    fn hex(&mut self, start: usize, digits_from: usize) -> Tok<'a> {
        let bytes = self.text.as_bytes();
        let mut i = digits_from;
        while bytes.get(i).is_some_and(u8::is_ascii_hexdigit) {
            i += 1;
        }
        self.advance_to(i);
        let text = &self.text[start..i];
        let negative = text.starts_with('-');
        match u64::from_str_radix(&self.text[digits_from..i], 16) {
            // Hexadecimal integers are exact up to 2^53; larger ones round like decimals.
            Ok(v) => Tok::Number(if negative { -(v as f64) } else { v as f64 }),
            Err(_) => Tok::Error(format!("`{}` is not a hexadecimal number", clip(text))),
        }
    }

    /// Moves to byte `end` on the same line (numbers have no line breaks).
    fn advance_to(&mut self, end: usize) {
        let n = self.text[self.offset..end].chars().count();
        self.offset = end;
        self.column = self
            .column
            .saturating_add(u32::try_from(n).unwrap_or(u32::MAX));
    }
}

/// At most 40 characters of `text`, for messages.
pub(super) fn clip(text: &str) -> String {
    let mut out: String = text.chars().take(40).collect();
    if out.len() < text.len() {
        out.push('…');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toks(text: &str) -> Vec<Tok<'_>> {
        let mut lexer = Lexer::new(text);
        let mut out = Vec::new();
        loop {
            let t = lexer.next_token();
            if t.tok == Tok::Eof {
                return out;
            }
            out.push(t.tok);
        }
    }

    #[test]
    fn reads_the_thesis_forms() {
        assert_eq!(
            toks("definition: “(1-x^2)” # c\n// d\nbbox 0 -0.5 .25 1e3, 0x1F"),
            vec![
                Tok::Ident("definition"),
                Tok::Colon,
                Tok::Str("(1-x^2)".into()),
                Tok::Ident("bbox"),
                Tok::Number(0.0),
                Tok::Number(-0.5),
                Tok::Number(0.25),
                Tok::Number(1000.0),
                Tok::Number(31.0),
            ]
        );
        assert_eq!(
            toks("a”x\n;}” \"q\\\"\\\\\""),
            vec![
                Tok::Ident("a"),
                Tok::Str("x\n;}".into()),
                Tok::Str("q\"\\".into())
            ]
        );
        assert!(matches!(toks("1e999")[0], Tok::Error(_)));
        assert!(matches!(toks("- x")[0], Tok::Error(_)));
        assert!(matches!(toks("\"open")[0], Tok::Error(_)));
    }

    #[test]
    fn tracks_lines_and_columns() {
        let mut lexer = Lexer::new("a\n  “é”  b");
        let a = lexer.next_token();
        let s = lexer.next_token();
        let b = lexer.next_token();
        assert_eq!((a.pos.line, a.pos.column), (1, 1));
        assert_eq!((s.pos.line, s.pos.column), (2, 3));
        assert_eq!((b.pos.line, b.pos.column), (2, 8));
        assert_eq!(b.pos.span, Span::new(14, 15));
    }
}
