//! A [`Document`] to canonical text: the `#VRML V2.0 utf8` header, two spaces of indentation
//! per level, one field per line, numbers in Rust's shortest round-trip form (so they read
//! back bit-identical), strings in straight quotes with `"`, `\` and the typographic quotes
//! `“` `”` escaped. Iterative, so any depth of document is written without recursion.

use std::fmt::Write as _;

use super::document::{Document, Node, NodeRef, Value};

/// The text of `doc`. For a document that passes [`Document::validate`],
/// [`parse`](super::parse) of this text gives back `doc`, and writing that again gives the
/// same text. Numbers that are not finite are written as `0`.
pub fn write(doc: &Document) -> String {
    let mut w = Writer {
        out: String::from("#VRML V2.0 utf8\n"),
        stack: Vec::new(),
    };
    for r in &doc.nodes {
        w.out.push('\n');
        w.open(r, 0);
        w.drain();
        w.out.push('\n');
    }
    w.out
}

/// A number as FVRML text: the shortest decimal that reads back to the same `f64`, with an
/// exponent only for very large or very small magnitudes. Not-finite values give `0`.
pub fn format_number(v: f64) -> String {
    if !v.is_finite() {
        return "0".into();
    }
    let a = v.abs();
    if a == 0.0 || (1e-5..1e16).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

enum Frame<'d> {
    Fields {
        node: &'d Node,
        next: usize,
        indent: usize,
    },
    Items {
        items: &'d [NodeRef],
        next: usize,
        indent: usize,
    },
}

struct Writer<'d> {
    out: String,
    stack: Vec<Frame<'d>>,
}

impl<'d> Writer<'d> {
    fn newline(&mut self, indent: usize) {
        self.out.push('\n');
        for _ in 0..indent {
            self.out.push_str("  ");
        }
    }

    /// Writes a node reference at the current position; a node with fields leaves a frame
    /// whose fields are indented at `indent + 1`.
    fn open(&mut self, r: &'d NodeRef, indent: usize) {
        match r {
            NodeRef::Null => self.out.push_str("NULL"),
            NodeRef::Use { name, .. } => {
                self.out.push_str("USE ");
                self.out.push_str(name);
            }
            NodeRef::Node(node) => {
                if let Some(def) = &node.def {
                    self.out.push_str("DEF ");
                    self.out.push_str(def);
                    self.out.push(' ');
                }
                self.out.push_str(&node.type_name);
                if node.fields.is_empty() {
                    self.out.push_str(" { }");
                } else {
                    self.out.push_str(" {");
                    self.stack.push(Frame::Fields {
                        node,
                        next: 0,
                        indent: indent + 1,
                    });
                }
            }
        }
    }

    fn drain(&mut self) {
        while let Some(frame) = self.stack.last_mut() {
            match frame {
                Frame::Fields { node, next, indent } => {
                    let (node, indent) = (*node, *indent);
                    if let Some(field) = node.fields.get(*next) {
                        *next += 1;
                        self.newline(indent);
                        self.out.push_str(&field.name);
                        self.out.push(' ');
                        self.value(&field.name, &field.value, indent);
                    } else {
                        self.stack.pop();
                        self.newline(indent - 1);
                        self.out.push('}');
                    }
                }
                Frame::Items {
                    items,
                    next,
                    indent,
                } => {
                    let (items, indent) = (*items, *indent);
                    if let Some(item) = items.get(*next) {
                        *next += 1;
                        self.newline(indent);
                        self.open(item, indent);
                    } else {
                        self.stack.pop();
                        self.newline(indent - 1);
                        self.out.push(']');
                    }
                }
            }
        }
    }

    fn value(&mut self, name: &str, value: &'d Value, indent: usize) {
        match value {
            Value::Bool(b) => self.out.push_str(if *b { "TRUE" } else { "FALSE" }),
            Value::Numbers(v) => self.numbers(v),
            Value::String(s) => self.string(s),
            Value::Node(r) => self.open(r, indent),
            Value::Bools(v) => {
                self.out.push('[');
                for (i, b) in v.iter().enumerate() {
                    if i > 0 {
                        self.out.push(' ');
                    }
                    self.out.push_str(if *b { "TRUE" } else { "FALSE" });
                }
                self.out.push(']');
            }
            Value::NumberList(v) => self.number_list(name, v, indent),
            Value::StringList(v) => {
                let long = v.len() > 1 && v.iter().map(String::len).sum::<usize>() > 60;
                self.out.push('[');
                for (i, s) in v.iter().enumerate() {
                    if long {
                        self.newline(indent + 1);
                    } else if i > 0 {
                        self.out.push(' ');
                    }
                    self.string(s);
                }
                if long {
                    self.newline(indent);
                }
                self.out.push(']');
            }
            Value::NodeList(items) if items.is_empty() => self.out.push_str("[]"),
            Value::NodeList(items) => {
                self.out.push('[');
                self.stack.push(Frame::Items {
                    items,
                    next: 0,
                    indent: indent + 1,
                });
            }
            Value::EmptyList => self.out.push_str("[]"),
        }
    }

    fn numbers(&mut self, v: &[f64]) {
        for (i, x) in v.iter().enumerate() {
            if i > 0 {
                self.out.push(' ');
            }
            self.out.push_str(&format_number(*x));
        }
    }

    fn number_list(&mut self, name: &str, v: &[f64], indent: usize) {
        if v.len() <= 12 {
            self.out.push('[');
            self.numbers(v);
            self.out.push(']');
            return;
        }
        let per_line = match name {
            "point" | "keyValue" | "color" | "vector" | "normal" => 3,
            _ => 8,
        };
        self.out.push('[');
        for (i, chunk) in v.chunks(per_line).enumerate() {
            if i > 0 {
                self.out.push(',');
            }
            self.newline(indent + 1);
            self.numbers(chunk);
        }
        self.newline(indent);
        self.out.push(']');
    }

    fn string(&mut self, s: &str) {
        self.out.reserve(s.len() + 2);
        self.out.push('"');
        for c in s.chars() {
            match c {
                '"' => self.out.push_str("\\\""),
                '\\' => self.out.push_str("\\\\"),
                // Typographic quotes close a string when read, so they are escaped too.
                '\u{201C}' | '\u{201D}' => {
                    self.out.push('\\');
                    self.out.push(c);
                }
                c => self.out.push(c),
            }
        }
        let _ = write!(self.out, "\"");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_read_back_bit_identical() {
        for v in [
            0.0,
            -0.0,
            1.0,
            -1.5,
            0.1,
            1.0 / 3.0,
            1e-5,
            9.99e-6,
            1e15,
            1e16,
            1e300,
            -2.5e-300,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            123_456_789.012_345_68,
        ] {
            let text = format_number(v);
            let back: f64 = text.parse().unwrap();
            assert_eq!(back.to_bits(), v.to_bits(), "{v} wrote {text}");
        }
        assert_eq!(format_number(1.0), "1");
        assert_eq!(format_number(0.35), "0.35");
        assert_eq!(format_number(1e300), "1e300");
        assert_eq!(format_number(f64::NAN), "0");
    }
}
