//! Turns source text into tokens with byte spans.
//!
//! The lexer never fails: characters it cannot read become [`TokenKind::Unknown`] tokens that
//! the parser reports with a hint (for example typographic quotes pasted from a document).

use super::Span;

/// What a token is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TokenKind {
    /// A number literal, already converted.
    Number(f64),
    /// A name: a variable, function or keyword; its text is in the source at the span.
    Ident,
    /// `+`
    Plus,
    /// `-`
    Minus,
    /// `*`
    Star,
    /// `/`
    Slash,
    /// `%`
    Percent,
    /// `^`
    Caret,
    /// `&` (intersection)
    Amp,
    /// `&&`
    AmpAmp,
    /// `|` (union)
    Pipe,
    /// `||`
    PipePipe,
    /// `\` (difference)
    Backslash,
    /// `!`
    Bang,
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
    /// `==`
    EqEq,
    /// `!=`
    Ne,
    /// `=`
    Assign,
    /// `;`
    Semi,
    /// `,`
    Comma,
    /// `(`
    LParen,
    /// `)`
    RParen,
    /// `{`
    LBrace,
    /// `}`
    RBrace,
    /// A character that is not part of the language.
    Unknown(char),
    /// The end of the text.
    Eof,
}

/// A token and where it stands.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Token {
    /// What it is.
    pub kind: TokenKind,
    /// Where it is.
    pub span: Span,
}

/// Dashes that documents print for a minus sign (thesis formulas use the en dash): read as
/// `-`, with a warning from the parser.
pub const PRINTED_MINUS: [char; 6] = [
    '\u{2010}', '\u{2011}', '\u{2012}', '\u{2013}', '\u{2014}', '\u{2212}',
];

/// Splits `source` into tokens, ending with [`TokenKind::Eof`].
///
/// Comments (`// ...` to the end of the line and `/* ... */`) and white space are skipped.
pub fn tokenize(source: &str) -> Vec<Token> {
    let bytes = source.as_bytes();
    let mut tokens = Vec::with_capacity(source.len() / 2 + 1);
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i];
        if c.is_ascii_whitespace() {
            i += 1;
            continue;
        }
        if c == b'/' && bytes.get(i + 1) == Some(&b'/') {
            while i < bytes.len() && bytes[i] != b'\n' {
                i += 1;
            }
            continue;
        }
        if c == b'/' && bytes.get(i + 1) == Some(&b'*') {
            let end = source[i + 2..]
                .find("*/")
                .map_or(bytes.len(), |e| i + 2 + e + 2);
            i = end;
            continue;
        }
        let start = i;
        let kind = if c.is_ascii_digit()
            || (c == b'.' && bytes.get(i + 1).is_some_and(u8::is_ascii_digit))
        {
            i = number_end(bytes, i);
            // The text is made of ASCII digits, '.', 'e' and signs, so it always parses, but a
            // literal like `1e999` becomes infinity, which the parser reports.
            TokenKind::Number(source[start..i].parse().unwrap_or(f64::NAN))
        } else if c.is_ascii_alphabetic() || c == b'_' {
            while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
                i += 1;
            }
            TokenKind::Ident
        } else if c.is_ascii() {
            let (kind, len) = punctuation(c, bytes.get(i + 1).copied());
            i += len;
            kind
        } else {
            // A multi-byte character: a dash printed for a minus sign reads as one (the parser
            // warns); anything else is reported whole.
            let ch = source[i..].chars().next().unwrap_or('\u{FFFD}');
            i += ch.len_utf8();
            if PRINTED_MINUS.contains(&ch) {
                TokenKind::Minus
            } else {
                TokenKind::Unknown(ch)
            }
        };
        tokens.push(Token {
            kind,
            span: Span::new(start, i),
        });
    }
    tokens.push(Token {
        kind: TokenKind::Eof,
        span: Span::new(bytes.len(), bytes.len()),
    });
    tokens
}

/// The token an ASCII character `c` (not a letter, digit or white space) starts, followed by
/// `next`, and its length in bytes.
fn punctuation(c: u8, next: Option<u8>) -> (TokenKind, usize) {
    match (c, next) {
        (b'&', Some(b'&')) => (TokenKind::AmpAmp, 2),
        (b'|', Some(b'|')) => (TokenKind::PipePipe, 2),
        (b'<', Some(b'=')) => (TokenKind::Le, 2),
        (b'>', Some(b'=')) => (TokenKind::Ge, 2),
        (b'=', Some(b'=')) => (TokenKind::EqEq, 2),
        (b'!', Some(b'=')) => (TokenKind::Ne, 2),
        (b'+', _) => (TokenKind::Plus, 1),
        (b'-', _) => (TokenKind::Minus, 1),
        (b'*', _) => (TokenKind::Star, 1),
        (b'/', _) => (TokenKind::Slash, 1),
        (b'%', _) => (TokenKind::Percent, 1),
        (b'^', _) => (TokenKind::Caret, 1),
        (b'&', _) => (TokenKind::Amp, 1),
        (b'|', _) => (TokenKind::Pipe, 1),
        (b'\\', _) => (TokenKind::Backslash, 1),
        (b'!', _) => (TokenKind::Bang, 1),
        (b'<', _) => (TokenKind::Lt, 1),
        (b'>', _) => (TokenKind::Gt, 1),
        (b'=', _) => (TokenKind::Assign, 1),
        (b';', _) => (TokenKind::Semi, 1),
        (b',', _) => (TokenKind::Comma, 1),
        (b'(', _) => (TokenKind::LParen, 1),
        (b')', _) => (TokenKind::RParen, 1),
        (b'{', _) => (TokenKind::LBrace, 1),
        (b'}', _) => (TokenKind::RBrace, 1),
        _ => (TokenKind::Unknown(c as char), 1),
    }
}

fn number_end(bytes: &[u8], mut i: usize) -> usize {
    while i < bytes.len() && bytes[i].is_ascii_digit() {
        i += 1;
    }
    if i < bytes.len() && bytes[i] == b'.' {
        i += 1;
        while i < bytes.len() && bytes[i].is_ascii_digit() {
            i += 1;
        }
    }
    if i < bytes.len() && (bytes[i] == b'e' || bytes[i] == b'E') {
        let mut j = i + 1;
        if j < bytes.len() && (bytes[j] == b'+' || bytes[j] == b'-') {
            j += 1;
        }
        if j < bytes.len() && bytes[j].is_ascii_digit() {
            while j < bytes.len() && bytes[j].is_ascii_digit() {
                j += 1;
            }
            i = j;
        }
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinds(src: &str) -> Vec<TokenKind> {
        tokenize(src).into_iter().map(|t| t.kind).collect()
    }

    #[test]
    fn numbers_in_usual_notations() {
        for (src, value) in [
            ("1", 1.0),
            ("1.5", 1.5),
            (".5", 0.5),
            ("2.", 2.0),
            ("1e3", 1e3),
            ("1.5E-2", 0.015),
            ("3e+2", 300.0),
        ] {
            assert_eq!(
                kinds(src),
                vec![TokenKind::Number(value), TokenKind::Eof],
                "{src}"
            );
        }
        // `2e` is the number 2 followed by the name `e`.
        assert_eq!(
            kinds("2e"),
            vec![TokenKind::Number(2.0), TokenKind::Ident, TokenKind::Eof]
        );
    }

    #[test]
    fn operators_and_comments() {
        use TokenKind::*;
        assert_eq!(
            kinds("a&&b || c <= d != e // tail\n/* block */ \\ & | ^ %"),
            vec![
                Ident, AmpAmp, Ident, PipePipe, Ident, Le, Ident, Ne, Ident, Backslash, Amp, Pipe,
                Caret, Percent, Eof
            ]
        );
    }

    #[test]
    fn unknown_characters_keep_their_span() {
        let tokens = tokenize("x “y”");
        assert_eq!(tokens[1].kind, TokenKind::Unknown('“'));
        assert_eq!(tokens[1].span, Span::new(2, 5));
        assert_eq!(tokens[3].kind, TokenKind::Unknown('”'));
    }
}
