//! One name for one idea: a limit is `MAX_*` (or `MIN_*`), never `*_MAX` or `*_MAX_*`, so a
//! reader finds every limit by its first word.

use std::path::PathBuf;

use super::source::{code_only, line_of};

/// The names of constants and statics declared in a code-only text, with their offsets.
fn constants(code: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    for keyword in ["const ", "static "] {
        for (at, _) in code.match_indices(keyword) {
            let before = code[..at].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                continue;
            }
            let rest = code[at + keyword.len()..].trim_start_matches("mut ");
            let end = rest
                .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                .unwrap_or(rest.len());
            let name = &rest[..end];
            if !name.is_empty()
                && name
                    .chars()
                    .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
            {
                out.push((at, name));
            }
        }
    }
    out
}

/// Whether a constant's name is a limit written the other way round: `MAX` or `MIN` as a word
/// anywhere but first.
pub fn is_misnamed_limit(name: &str) -> bool {
    name.split('_')
        .skip(1)
        .any(|word| word == "MAX" || word == "MIN")
}

/// Limits in `files` named the other way round, as `path:line: NAME` lines.
pub fn misnamed_limits(files: &[PathBuf]) -> Vec<String> {
    let mut out = Vec::new();
    for file in files {
        let Ok(source) = std::fs::read_to_string(file) else {
            continue;
        };
        let code = code_only(&source);
        for (at, name) in constants(&code) {
            if is_misnamed_limit(name) {
                out.push(format!("{}:{}: {name}", file.display(), line_of(&code, at)));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_put_max_or_min_first() {
        for good in [
            "MAX_LOG_OPS",
            "MIN_RESEND_AFTER_MICROS",
            "MAXIMAL",
            "ENERGY_MAXIMA",
        ] {
            assert!(!is_misnamed_limit(good), "{good}");
        }
        for bad in [
            "JOBS_QUEUED_MAX",
            "RESEND_AFTER_MAX_MICROS",
            "FOV_Y_MIN_RADIANS",
        ] {
            assert!(is_misnamed_limit(bad), "{bad}");
        }
    }

    #[test]
    fn constants_and_statics_are_found_in_code_only() {
        let code = code_only(
            "pub const A_MAX: u8 = 1;\n// const B_MAX: u8 = 2;\nstatic mut C: u8 = 0;\nfn f<const N: usize>() {}\n",
        );
        let names: Vec<_> = constants(&code).into_iter().map(|(_, n)| n).collect();
        assert_eq!(names, ["A_MAX", "N", "C"]);
    }
}
