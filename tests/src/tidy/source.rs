//! Rust source reduced to its code: comments and the insides of string and character literals
//! blanked out, line for line, so that the checks can look for braces, paths and names without
//! a parser and still report the right line.
//!
//! This is a scanner, not a parser: it knows comments (line, block, nested), strings (plain,
//! byte, raw with any number of `#`), character literals and lifetimes, which is all the checks
//! need to count braces and find `crate::` paths; it never fails, whatever the text.

/// The text with every comment and the inside of every string and character literal replaced
/// by spaces; newlines are kept, so line numbers and the byte length stay those of `source`.
pub fn code_only(source: &str) -> String {
    let bytes = source.as_bytes();
    let mut out = bytes.to_vec();
    let mut i = 0;
    while i < bytes.len() {
        let rest = &bytes[i..];
        if rest.starts_with(b"//") {
            let end = find_from(bytes, i, b'\n').unwrap_or(bytes.len());
            blank(&mut out, i, end);
            i = end;
        } else if rest.starts_with(b"/*") {
            let end = block_comment_end(bytes, i);
            blank(&mut out, i, end);
            i = end;
        } else if let Some(hashes) = raw_string_start(bytes, i) {
            let open = i + bytes[i..].iter().position(|&b| b == b'"').unwrap_or(0) + 1;
            let end = raw_string_end(bytes, open, hashes);
            blank(&mut out, open, end.saturating_sub(1 + hashes).max(open));
            i = end;
        } else if bytes[i] == b'"' {
            let end = string_end(bytes, i + 1);
            blank(&mut out, i + 1, end.saturating_sub(1).max(i + 1));
            i = end;
        } else if bytes[i] == b'\'' {
            match char_literal_end(bytes, i) {
                Some(end) => {
                    blank(&mut out, i + 1, end - 1);
                    i = end;
                }
                None => i += 1,
            }
        } else {
            i += 1;
        }
    }
    String::from_utf8(out).unwrap_or_default()
}

/// Replaces `out[from..to]` with spaces, keeping newlines; a multi-byte character becomes as
/// many spaces as it had bytes, so the result stays valid UTF-8.
fn blank(out: &mut [u8], from: usize, to: usize) {
    let to = to.min(out.len());
    for b in &mut out[from.min(to)..to] {
        if *b != b'\n' {
            *b = b' ';
        }
    }
}

fn find_from(bytes: &[u8], from: usize, byte: u8) -> Option<usize> {
    bytes[from..]
        .iter()
        .position(|&b| b == byte)
        .map(|p| from + p)
}

/// The end (exclusive) of the block comment opening at `start`; block comments nest.
fn block_comment_end(bytes: &[u8], start: usize) -> usize {
    let mut depth = 0usize;
    let mut i = start;
    while i + 1 < bytes.len() {
        if bytes[i] == b'/' && bytes[i + 1] == b'*' {
            depth += 1;
            i += 2;
        } else if bytes[i] == b'*' && bytes[i + 1] == b'/' {
            depth -= 1;
            i += 2;
            if depth == 0 {
                return i;
            }
        } else {
            i += 1;
        }
    }
    bytes.len()
}

/// The number of `#`s when a raw string (`r"`, `r#"`, `br##"`...) opens at `i`, not inside
/// an identifier.
fn raw_string_start(bytes: &[u8], i: usize) -> Option<usize> {
    if i > 0 && (bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_') {
        return None;
    }
    let mut j = i;
    if bytes.get(j) == Some(&b'b') {
        j += 1;
    }
    if bytes.get(j) != Some(&b'r') {
        return None;
    }
    j += 1;
    let hashes = bytes[j..].iter().take_while(|&&b| b == b'#').count();
    (bytes.get(j + hashes) == Some(&b'"')).then_some(hashes)
}

/// The end (exclusive) of a raw string whose body starts at `open`.
fn raw_string_end(bytes: &[u8], open: usize, hashes: usize) -> usize {
    let mut i = open;
    while i < bytes.len() {
        if bytes[i] == b'"'
            && bytes[i + 1..]
                .iter()
                .take(hashes)
                .filter(|&&b| b == b'#')
                .count()
                == hashes
        {
            return i + 1 + hashes;
        }
        i += 1;
    }
    bytes.len()
}

/// The end (exclusive) of a string whose body starts at `open`, after its closing quote.
fn string_end(bytes: &[u8], open: usize) -> usize {
    let mut i = open;
    while i < bytes.len() {
        match bytes[i] {
            b'\\' => i += 2,
            b'"' => return i + 1,
            _ => i += 1,
        }
    }
    bytes.len()
}

/// The end (exclusive) of the character literal opening at `start`, or `None` when the quote
/// opens a lifetime or a label (`'a`, `'outer:`).
fn char_literal_end(bytes: &[u8], start: usize) -> Option<usize> {
    let next = *bytes.get(start + 1)?;
    if next == b'\\' {
        let close = find_from(bytes, start + 2, b'\'')?;
        return Some(close + 1);
    }
    // One character, which may take up to four bytes, then the closing quote.
    let width = match next {
        0x00..=0x7f => 1,
        0xc0..=0xdf => 2,
        0xe0..=0xef => 3,
        _ => 4,
    };
    (bytes.get(start + 1 + width) == Some(&b'\'')).then_some(start + 2 + width)
}

/// The byte range of every `#[cfg(test)]` module written inline (`mod name { ... }`) in a
/// code-only text: test code is not the architecture, so the checks leave it out.
pub fn test_modules(code: &str) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(at) = code[from..].find("#[cfg(test)]") {
        let attr = from + at;
        from = attr + "#[cfg(test)]".len();
        let rest = code[from..].trim_start();
        let after_ws = code.len() - rest.len();
        let rest = rest.strip_prefix("pub ").unwrap_or(rest);
        if !rest.starts_with("mod ") {
            continue;
        }
        let Some(open) = code[after_ws..].find(['{', ';']).map(|p| after_ws + p) else {
            continue;
        };
        if code.as_bytes()[open] == b';' {
            continue;
        }
        let end = matching_brace(code, open).unwrap_or(code.len());
        out.push(attr..end);
        from = end;
    }
    out
}

/// The end (exclusive) of the brace block opening at `open` in a code-only text.
pub fn matching_brace(code: &str, open: usize) -> Option<usize> {
    let mut depth = 0usize;
    for (i, b) in code.bytes().enumerate().skip(open) {
        match b {
            b'{' => depth += 1,
            b'}' => {
                depth = depth.checked_sub(1)?;
                if depth == 0 {
                    return Some(i + 1);
                }
            }
            _ => {}
        }
    }
    None
}

/// `code` with the given ranges blanked out (newlines kept).
pub fn without(code: &str, ranges: &[std::ops::Range<usize>]) -> String {
    let mut out = code.as_bytes().to_vec();
    for r in ranges {
        blank(&mut out, r.start, r.end);
    }
    String::from_utf8(out).unwrap_or_default()
}

/// The line (from 1) of a byte offset.
pub fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn comments_strings_and_chars_are_blanked_line_for_line() {
        let source = "let a = \"{ // }\"; // {\n/* { /* } */ } */ let b = '{';\nlet c = r#\"}\"#; fn f<'a>(x: &'a u8) {}\n";
        let code = code_only(source);
        assert_eq!(code.len(), source.len());
        assert_eq!(code.lines().count(), source.lines().count());
        assert_eq!(code.matches('{').count(), 1, "{code}");
        assert_eq!(code.matches('}').count(), 1, "{code}");
        assert!(code.contains("'a"), "lifetimes stay: {code}");
    }

    #[test]
    fn escaped_quotes_and_byte_strings_do_not_end_a_literal_early() {
        let code = code_only("let s = b\"\\\"{\"; let c = '\\''; let d = br##\"\"#{\"##; {}");
        assert_eq!(code.matches('{').count(), 1, "{code}");
    }

    #[test]
    fn inline_test_modules_are_found_and_declared_ones_are_not() {
        let code = code_only(
            "fn a() {}\n#[cfg(test)]\nmod tests {\n    fn b() { {} }\n}\n#[cfg(test)]\nmod more;\nfn c() {}\n",
        );
        let ranges = test_modules(&code);
        assert_eq!(ranges.len(), 1);
        let kept = without(&code, &ranges);
        assert!(kept.contains("fn a") && kept.contains("fn c") && !kept.contains("fn b"));
    }
}
