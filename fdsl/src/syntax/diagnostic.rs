//! Diagnostics: a span, a plain message and an optional hint, rendered with the source line and
//! a caret.

use std::fmt::Write as _;

/// A byte range `start..end` in the source text.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Span {
    /// Offset of the first byte.
    pub start: u32,
    /// Offset one past the last byte.
    pub end: u32,
}

impl Span {
    /// A span from byte offsets.
    pub fn new(start: usize, end: usize) -> Span {
        let clamp = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        Span {
            start: clamp(start),
            end: clamp(end.max(start)),
        }
    }

    /// The smallest span covering both.
    pub fn to(self, other: Span) -> Span {
        Span {
            start: self.start.min(other.start),
            end: self.end.max(other.end),
        }
    }

    /// The span as a `usize` range, clamped to a text of `len` bytes.
    pub fn range(self, len: usize) -> std::ops::Range<usize> {
        let start = (self.start as usize).min(len);
        let end = (self.end as usize).clamp(start, len);
        start..end
    }
}

/// How serious a diagnostic is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// The text was understood; this is advice.
    Warning,
    /// The text cannot be compiled.
    Error,
}

/// One problem found in a source text.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostic {
    /// Error or warning.
    pub severity: Severity,
    /// Where in the source.
    pub span: Span,
    /// What is wrong, in plain words.
    pub message: String,
    /// What to do about it, when we can tell.
    pub hint: Option<String>,
}

impl Diagnostic {
    /// An error at `span`.
    pub fn error(span: Span, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            severity: Severity::Error,
            span,
            message: message.into(),
            hint: None,
        }
    }

    /// A warning at `span`.
    pub fn warning(span: Span, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            severity: Severity::Warning,
            span,
            message: message.into(),
            hint: None,
        }
    }

    /// The same diagnostic with a hint.
    pub fn with_hint(mut self, hint: impl Into<String>) -> Diagnostic {
        self.hint = Some(hint.into());
        self
    }

    /// Whether this is an error (as opposed to a warning).
    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }

    /// One-based line and column (in characters) of the span's start.
    pub fn line_col(&self, source: &str) -> (usize, usize) {
        let start = self.span.range(source.len()).start;
        let start = floor_char_boundary(source, start);
        let before = &source[..start];
        let line = before.matches('\n').count() + 1;
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        let col = source[line_start..start].chars().count() + 1;
        (line, col)
    }

    /// Renders the diagnostic with its line of source and a caret under the span:
    ///
    /// ```text
    /// error: unknown function `sni`
    ///  --> 1:3
    ///   |
    /// 1 | 1+sni(x)
    ///   |   ^^^
    ///   = hint: did you mean `sin`?
    /// ```
    pub fn render(&self, source: &str) -> String {
        let range = self.span.range(source.len());
        let start = floor_char_boundary(source, range.start);
        let end = floor_char_boundary(source, range.end).max(start);
        let (line, col) = self.line_col(source);
        let line_start = source[..start].rfind('\n').map_or(0, |i| i + 1);
        let line_end = source[start..]
            .find('\n')
            .map_or(source.len(), |i| start + i);
        let text = &source[line_start..line_end];
        let width = source[start..end.min(line_end)].chars().count().max(1);
        let gutter = line.to_string().len();
        let kind = match self.severity {
            Severity::Error => "error",
            Severity::Warning => "warning",
        };
        let mut out = String::new();
        let _ = writeln!(out, "{kind}: {}", self.message);
        let _ = writeln!(out, "{:gutter$}--> {line}:{col}", "");
        let _ = writeln!(out, "{:gutter$} |", "");
        let _ = writeln!(out, "{line} | {text}");
        // Padded by repetition, not a `{:pad$}` width: widths past `u16::MAX` panic, and a
        // line of the text can be longer.
        let _ = writeln!(
            out,
            "{:gutter$} | {}{}",
            "",
            " ".repeat(col - 1),
            "^".repeat(width)
        );
        if let Some(hint) = &self.hint {
            let _ = writeln!(out, "{:gutter$} = hint: {hint}", "");
        }
        out
    }
}

fn floor_char_boundary(s: &str, mut i: usize) -> usize {
    i = i.min(s.len());
    while !s.is_char_boundary(i) {
        i -= 1;
    }
    i
}

/// Renders every diagnostic in order, separated by blank lines.
pub fn render_all(diagnostics: &[Diagnostic], source: &str) -> String {
    diagnostics
        .iter()
        .map(|d| d.render(source))
        .collect::<Vec<_>>()
        .join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_line_and_caret() {
        let src = "a=1;\nb = sni(x);";
        let d = Diagnostic::error(Span::new(9, 12), "unknown function `sni`")
            .with_hint("did you mean `sin`?");
        let text = d.render(src);
        assert_eq!(d.line_col(src), (2, 5));
        assert_eq!(
            text,
            "error: unknown function `sni`\n --> 2:5\n  |\n2 | b = sni(x);\n  |     ^^^\n  = hint: did you mean `sin`?\n"
        );
    }

    #[test]
    fn a_column_past_u16_max_renders() {
        let src = "x".repeat(70_000);
        let d = Diagnostic::error(Span::new(69_999, 70_000), "far");
        let text = d.render(&src);
        assert!(
            text.contains(&format!("{}^\n", " ".repeat(69_999))),
            "{}",
            &text[..80]
        );
    }

    #[test]
    fn spans_past_the_end_and_inside_characters_are_clamped() {
        let src = "x “";
        let d = Diagnostic::error(Span::new(3, 100), "quote");
        assert!(d.render(src).contains("1 | x “"));
        let d = Diagnostic::error(Span::new(50, 60), "end");
        assert_eq!(d.line_col(src), (1, 4));
    }
}
