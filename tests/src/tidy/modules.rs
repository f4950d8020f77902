//! Import circles between the top-level modules of a crate: module `a` naming `crate::b`
//! while `b` names `crate::a` (directly or through others) means neither can be read, moved
//! or split without the other. Each crate's top-level modules must form layers.
//!
//! Test code (`tests.rs` files and inline `#[cfg(test)]` modules) is left out: a test may
//! reach anywhere.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use super::files::rust_files;
use super::source::{code_only, test_modules, without};

/// Each top-level module of a crate and the other top-level modules it names.
pub type ModuleGraph = BTreeMap<String, BTreeSet<String>>;

/// The top-level module a file under `src` belongs to (`src/log.rs` and `src/log/base.rs`
/// are both `log`), or `None` for a crate root (`lib.rs`, `main.rs`) or a test file.
pub fn module_of(src: &Path, file: &Path) -> Option<String> {
    let relative = file.strip_prefix(src).ok()?;
    if relative.file_name().is_some_and(|n| n == "tests.rs") {
        return None;
    }
    let first = relative.components().next()?.as_os_str().to_str()?;
    let name = first.strip_suffix(".rs").unwrap_or(first);
    (!matches!(name, "lib" | "main")).then(|| name.to_string())
}

/// The first segment of every `crate::` path in a code-only text, including every item of a
/// `crate::{a, b::c}` group.
pub fn crate_paths(code: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (at, _) in code.match_indices("crate::") {
        let before = code[..at].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue;
        }
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            out.extend(group_heads(group));
        } else {
            out.extend(ident_at(rest));
        }
    }
    out
}

/// The first identifier of each item at the top level of a `{...}` group (the text after
/// its opening brace).
fn group_heads(group: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut depth = 0usize;
    let mut item_start = true;
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => break,
            '}' => depth -= 1,
            ',' if depth == 0 => item_start = true,
            c if item_start && depth == 0 && !c.is_whitespace() => {
                out.extend(ident_at(&group[i..]));
                item_start = false;
            }
            _ => {}
        }
    }
    out
}

fn ident_at(text: &str) -> Option<String> {
    let end = text
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(text.len());
    (end > 0).then(|| text[..end].to_string())
}

/// The graph of a crate's top-level modules (those with a file under `src`), from the
/// `crate::` paths of their non-test code.
pub fn module_graph(src: &Path) -> ModuleGraph {
    let mut graph = ModuleGraph::new();
    let mut named = BTreeMap::<String, BTreeSet<String>>::new();
    for file in rust_files(src) {
        let Some(module) = module_of(src, &file) else {
            continue;
        };
        let source = std::fs::read_to_string(&file).unwrap_or_default();
        let code = code_only(&source);
        let code = without(&code, &test_modules(&code));
        graph.entry(module.clone()).or_default();
        named.entry(module).or_default().extend(crate_paths(&code));
    }
    for (module, names) in named {
        let edges = names
            .into_iter()
            .filter(|n| *n != module && graph.contains_key(n))
            .collect();
        graph.insert(module, edges);
    }
    graph
}

/// The circles of a graph: each set of two or more modules that all reach one another,
/// sorted.
pub fn circles(graph: &ModuleGraph) -> Vec<Vec<String>> {
    let reach: BTreeMap<&String, BTreeSet<&String>> =
        graph.keys().map(|m| (m, reachable(graph, m))).collect();
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    for m in graph.keys() {
        if seen.contains(m) {
            continue;
        }
        let circle: Vec<String> = graph
            .keys()
            .filter(|n| *n == m || (reach[m].contains(n) && reach[n].contains(m)))
            .cloned()
            .collect();
        seen.extend(circle.iter().cloned());
        if circle.len() > 1 {
            out.push(circle);
        }
    }
    out
}

/// Every module `from` reaches through one or more edges.
fn reachable<'g>(graph: &'g ModuleGraph, from: &String) -> BTreeSet<&'g String> {
    let mut out = BTreeSet::new();
    let mut stack: Vec<&String> = graph[from].iter().collect();
    while let Some(m) = stack.pop() {
        if let Some((key, next)) = graph.get_key_value(m)
            && out.insert(key)
        {
            stack.extend(next.iter());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph(edges: &[(&str, &[&str])]) -> ModuleGraph {
        edges
            .iter()
            .map(|(m, to)| (m.to_string(), to.iter().map(|s| s.to_string()).collect()))
            .collect()
    }

    #[test]
    fn paths_and_groups_name_their_first_segments() {
        let code = "use crate::op::OpId;\nuse crate::{sync::message::{A, B}, log as l};\nlet x = $crate::time::now;\npub(crate) fn f() {}\nmycrate::z();";
        let names: Vec<_> = crate_paths(code).into_iter().collect();
        assert_eq!(names, ["log", "op", "sync", "time"]);
    }

    #[test]
    fn a_circle_through_three_modules_is_found_and_layers_pass() {
        let layered = graph(&[("a", &["b"]), ("b", &["c"]), ("c", &[])]);
        assert!(circles(&layered).is_empty());
        let knot = graph(&[("a", &["b"]), ("b", &["c"]), ("c", &["a"]), ("d", &["a"])]);
        assert_eq!(circles(&knot), [["a", "b", "c"]]);
    }

    #[test]
    fn files_map_to_their_top_level_module_and_tests_and_roots_to_none() {
        let src = Path::new("/w/src");
        assert_eq!(
            module_of(src, Path::new("/w/src/log/base.rs")).as_deref(),
            Some("log")
        );
        assert_eq!(
            module_of(src, Path::new("/w/src/op.rs")).as_deref(),
            Some("op")
        );
        assert_eq!(module_of(src, Path::new("/w/src/lib.rs")), None);
        assert_eq!(module_of(src, Path::new("/w/src/log/tests.rs")), None);
    }
}
