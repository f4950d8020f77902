//! What the text formats (ASCII STL, OBJ) share: a tokenizer over bytes that knows each
//! token's line and column, and number formatting that reads back to the same `f32`.

use std::fmt;
use std::io::Write;

/// A whitespace-separated token and where it starts (1-based line and byte column).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Token<'a> {
    pub(crate) text: &'a [u8],
    pub(crate) line: usize,
    pub(crate) column: usize,
}

impl Token<'_> {
    /// The token for messages: lossy UTF-8, shortened to 32 characters.
    pub(crate) fn shown(&self) -> String {
        let text = String::from_utf8_lossy(self.text);
        match text.char_indices().nth(32) {
            Some((cut, _)) => format!("{}...", &text[..cut]),
            None => text.into_owned(),
        }
    }

    /// Whether the token is `word`, ignoring ASCII case.
    pub(crate) fn is(&self, word: &str) -> bool {
        self.text.eq_ignore_ascii_case(word.as_bytes())
    }

    /// The token as an `f32`, if it is a number (infinities and NaN included).
    pub(crate) fn number(&self) -> Option<f32> {
        std::str::from_utf8(self.text).ok()?.parse().ok()
    }
}

/// Splits bytes into tokens separated by ASCII whitespace, tracking lines.
pub(crate) struct Tokens<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
    line_start: usize,
    /// Whether `#` starts a comment that runs to the end of the line.
    comments: bool,
}

impl<'a> Tokens<'a> {
    pub(crate) fn new(bytes: &'a [u8], comments: bool) -> Tokens<'a> {
        Tokens {
            bytes,
            pos: 0,
            line: 1,
            line_start: 0,
            comments,
        }
    }

    /// The current line and column (where the next token or the end would be reported).
    pub(crate) fn here(&self) -> (usize, usize) {
        (self.line, self.pos - self.line_start + 1)
    }

    /// The next token on any line.
    pub(crate) fn next_token(&mut self) -> Option<Token<'a>> {
        loop {
            self.skip_blanks();
            match self.bytes.get(self.pos) {
                None => return None,
                Some(b'\n') => self.newline(),
                Some(b'#') if self.comments => self.skip_line(),
                Some(_) => return Some(self.take()),
            }
        }
    }

    /// The next token on the current line, or `None` at its end.
    pub(crate) fn next_on_line(&mut self) -> Option<Token<'a>> {
        self.skip_blanks();
        match self.bytes.get(self.pos) {
            None | Some(b'\n') => None,
            Some(b'#') if self.comments => None,
            Some(_) => Some(self.take()),
        }
    }

    /// Skips to the start of the next line.
    pub(crate) fn skip_line(&mut self) {
        match self.bytes[self.pos..].iter().position(|&b| b == b'\n') {
            Some(n) => {
                self.pos += n;
                self.newline();
            }
            None => self.pos = self.bytes.len(),
        }
    }

    fn newline(&mut self) {
        self.pos += 1;
        self.line += 1;
        self.line_start = self.pos;
    }

    fn skip_blanks(&mut self) {
        while let Some(&b) = self.bytes.get(self.pos) {
            if b == b'\n' || !b.is_ascii_whitespace() {
                break;
            }
            self.pos += 1;
        }
    }

    fn take(&mut self) -> Token<'a> {
        let (line, column) = self.here();
        let start = self.pos;
        while let Some(&b) = self.bytes.get(self.pos) {
            if b.is_ascii_whitespace() {
                break;
            }
            self.pos += 1;
        }
        Token {
            text: &self.bytes[start..self.pos],
            line,
            column,
        }
    }
}

/// Appends formatted text to a byte buffer.
pub(crate) fn push_fmt(out: &mut Vec<u8>, args: fmt::Arguments<'_>) {
    // Writing into a Vec cannot fail.
    let _ = out.write_fmt(args);
}

/// An `f32` in the shortest text that parses back to it: plain for ordinary magnitudes,
/// with an exponent otherwise (plain `Display` would print 1e30 with 30 zeros).
pub(crate) struct F32(pub(crate) f32);

impl fmt::Display for F32 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let magnitude = self.0.abs();
        if magnitude == 0.0 || (1e-4..1e7).contains(&magnitude) {
            write!(f, "{}", self.0)
        } else {
            write!(f, "{:e}", self.0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_know_their_lines_and_columns() {
        let mut t = Tokens::new(b"v 1 2 # c\r\n\n  f\t3", true);
        let v = t.next_token().unwrap();
        assert_eq!((v.text, v.line, v.column), (&b"v"[..], 1, 1));
        let one = t.next_on_line().unwrap();
        assert_eq!((one.number(), one.column), (Some(1.0), 3));
        assert_eq!(t.next_on_line().unwrap().text, b"2");
        assert!(t.next_on_line().is_none(), "comment ends the line");
        let f = t.next_token().unwrap();
        assert_eq!((f.text, f.line, f.column), (&b"f"[..], 3, 3));
        assert_eq!(t.next_on_line().unwrap().column, 5);
        assert!(t.next_token().is_none());
        assert_eq!(t.here(), (3, 6));
    }

    #[test]
    fn numbers_read_back_exactly() {
        for x in [
            0.0f32,
            -0.0,
            1.0,
            0.1,
            -3.25e-9,
            1e30,
            f32::MAX,
            f32::MIN_POSITIVE,
            1e-45,
            123456.79,
        ] {
            let text = F32(x).to_string();
            let back: f32 = text.parse().unwrap();
            assert_eq!(back.to_bits(), x.to_bits(), "{x} -> {text}");
            assert!(text.len() < 16, "{text}");
        }
    }
}
