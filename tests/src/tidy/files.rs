//! Which files the checks read, and the checks of single files: the `//!` header every
//! source file opens with, and words a crate's code must not use.

use std::path::{Path, PathBuf};

use super::source::{code_only, line_of};

/// Rust files under `root` (skipping `target` and hidden folders), sorted.
pub fn rust_files(root: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if path.is_dir() {
                if name != "target" && !name.starts_with('.') && name != "out" {
                    stack.push(path);
                }
            } else if name.ends_with(".rs") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// Whether a source text opens with a `//!` module header.
pub fn has_module_header(source: &str) -> bool {
    source.trim_start().starts_with("//!")
}

/// Files among `files` whose text does not open with a `//!` header.
pub fn files_without_header(files: &[PathBuf]) -> Vec<PathBuf> {
    files
        .iter()
        .filter(|f| std::fs::read_to_string(f).map_or(true, |s| !has_module_header(&s)))
        .cloned()
        .collect()
}

/// Where `words` occur in the code (not the comments or strings) of `files`, as
/// `path:line: word` lines: a crate that must not do some work (the app meshing, say) must
/// not name the types that do it.
pub fn files_naming(files: &[PathBuf], words: &[&str]) -> Vec<String> {
    let mut out = Vec::new();
    for file in files {
        let Ok(source) = std::fs::read_to_string(file) else {
            continue;
        };
        let code = code_only(&source);
        for word in words {
            for (at, _) in code.match_indices(word) {
                let before = code[..at].chars().next_back();
                let after = code[at + word.len()..].chars().next();
                let part_of_name =
                    |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
                if !part_of_name(before) && !part_of_name(after) {
                    out.push(format!("{}:{}: {word}", file.display(), line_of(&code, at)));
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers() {
        assert!(has_module_header("//! Text.\nfn f() {}"));
        assert!(!has_module_header("// Text.\nfn f() {}"));
        assert!(!has_module_header("fn f() {}"));
    }

    #[test]
    fn a_forbidden_word_is_found_in_code_and_not_in_comments_or_longer_names() {
        let dir = std::env::temp_dir().join(format!("tidy-words-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("a.rs");
        std::fs::write(&file, "//! OctreeMesher in a comment.\nlet s = \"OctreeMesher\";\nlet m = OctreeMesherish;\nlet n = render::OctreeMesher::new();\n").unwrap();
        let found = files_naming(std::slice::from_ref(&file), &["OctreeMesher"]);
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(found.len(), 1, "{found:?}");
        assert!(found[0].ends_with(":4: OctreeMesher"), "{found:?}");
    }
}
