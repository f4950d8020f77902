//! Function length: a function does one thing, which fits on a screen. None runs over
//! [`MAX_FUNCTION_LINES`]; one over [`MAX_PLAIN_FUNCTION_LINES`] must be a table (a match over
//! every opcode, a list of fields) and say so in a comment line `// tidy:table: <what the table
//! is>` among the lines just above it. Test code is left out.

use std::path::{Path, PathBuf};

use super::source::{code_only, line_of, matching_brace, test_modules, without};

/// The most lines any function outside tests may take, signature to closing brace.
pub const MAX_FUNCTION_LINES: usize = 100;
/// The most lines a function may take without being marked as a table.
pub const MAX_PLAIN_FUNCTION_LINES: usize = 70;
/// The mark that says a long function is a table.
pub const TABLE_MARK: &str = "tidy:table:";

/// A function's place and size.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Function {
    /// Its name.
    pub name: String,
    /// The line of its `fn` (from 1).
    pub line: usize,
    /// Lines from its `fn` to its closing brace, both included.
    pub n_lines: usize,
    /// Whether the lines just above it carry [`TABLE_MARK`].
    pub table: bool,
}

/// Every function with a body in a source text, test modules left out.
pub fn functions(source: &str) -> Vec<Function> {
    let code = code_only(source);
    let code = without(&code, &test_modules(&code));
    let lines: Vec<&str> = source.lines().collect();
    let mut out = Vec::new();
    for (at, _) in code.match_indices("fn ") {
        let before = code[..at].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue;
        }
        let rest = &code[at + 3..];
        let name_len = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        if name_len == 0 {
            continue; // a function pointer type, `fn(u8) -> u8`
        }
        let Some(open) = body_start(&code, at) else {
            continue;
        };
        let end = matching_brace(&code, open).unwrap_or(code.len());
        let line = line_of(&code, at);
        out.push(Function {
            name: rest[..name_len].to_string(),
            line,
            n_lines: line_of(&code, end.saturating_sub(1)) - line + 1,
            table: marked_as_table(&lines, line),
        });
    }
    out
}

/// The offset of the `{` that opens the body of the `fn` at `at`, or `None` for a declaration
/// without one (`fn f();` in a trait).
fn body_start(code: &str, at: usize) -> Option<usize> {
    let mut depth = 0i32;
    for (i, b) in code.bytes().enumerate().skip(at) {
        match b {
            b'(' | b'[' => depth += 1,
            b')' | b']' => depth -= 1,
            b'{' if depth == 0 => return Some(i),
            b';' if depth == 0 => return None,
            _ => {}
        }
    }
    None
}

/// Whether the comment and attribute lines just above line `line` (from 1) carry the mark.
fn marked_as_table(lines: &[&str], line: usize) -> bool {
    for above in lines[..line.saturating_sub(1)].iter().rev() {
        let t = above.trim();
        if t.is_empty() || t.ends_with('}') || t.ends_with(';') || t.ends_with('{') {
            return false;
        }
        if t.contains(TABLE_MARK) {
            return true;
        }
    }
    false
}

/// The functions of `files` that break the rule, as `path:line: name is N lines` lines.
pub fn too_long(files: &[PathBuf]) -> Vec<String> {
    let mut out = Vec::new();
    for file in files {
        if is_test_file(file) {
            continue;
        }
        let Ok(source) = std::fs::read_to_string(file) else {
            continue;
        };
        for f in functions(&source) {
            let over = f.n_lines > MAX_FUNCTION_LINES
                || (f.n_lines > MAX_PLAIN_FUNCTION_LINES && !f.table);
            if over {
                let why = if f.n_lines > MAX_FUNCTION_LINES {
                    format!("over {MAX_FUNCTION_LINES}")
                } else {
                    format!("over {MAX_PLAIN_FUNCTION_LINES} and not marked `{TABLE_MARK}`")
                };
                out.push(format!(
                    "{}:{}: `{}` is {} lines ({why})",
                    file.display(),
                    f.line,
                    f.name,
                    f.n_lines
                ));
            }
        }
    }
    out
}

fn is_test_file(file: &Path) -> bool {
    file.file_name().is_some_and(|n| n == "tests.rs")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body(n: usize) -> String {
        (0..n).map(|i| format!("    let _ = {i};\n")).collect()
    }

    #[test]
    fn lengths_count_from_fn_to_the_closing_brace_and_skip_declarations() {
        let source = format!(
            "trait T {{ fn decl(&self); }}\nfn short() {{}}\npub(crate) fn long(x: [u8; 2]) -> u8 {{\n{}    let s = \"}}\";\n    x[0]\n}}\n",
            body(3)
        );
        let found = functions(&source);
        let names: Vec<_> = found.iter().map(|f| (f.name.as_str(), f.n_lines)).collect();
        assert_eq!(names, [("short", 1), ("long", 7)]);
    }

    #[test]
    fn a_long_function_passes_only_as_a_marked_table_and_never_over_the_hard_limit() {
        let long =
            |mark: &str, n: usize| format!("{mark}/// Doc.\n#[inline]\nfn f() {{\n{}}}\n", body(n));
        let check = |source: String| {
            let found = functions(&source);
            let f = found.iter().find(|f| f.name == "f").expect("f is found");
            f.n_lines > MAX_FUNCTION_LINES || (f.n_lines > MAX_PLAIN_FUNCTION_LINES && !f.table)
        };
        assert!(!check(long("", 60)));
        assert!(check(long("", 80)));
        assert!(!check(long("// tidy:table: one arm per opcode.\n", 80)));
        assert!(check(long("// tidy:table: one arm per opcode.\n", 120)));
        // A mark above the previous item does not count.
        assert!(check(format!(
            "// tidy:table: x.\nfn g() {{}}\n{}",
            long("", 80)
        )));
    }

    #[test]
    fn test_modules_are_left_out() {
        let source = format!(
            "#[cfg(test)]\nmod tests {{\n    fn huge() {{\n{}    }}\n}}\n",
            body(200)
        );
        assert!(functions(&source).is_empty());
    }
}
