//! The dependency map: which workspace crates may depend on which, as written in
//! `ARCHITECTURE.md`, against the edges `cargo metadata` reports.

use std::collections::{BTreeMap, BTreeSet};

/// Allowed edges: crate name -> the workspace crates it may depend on.
pub type DependencyMap = BTreeMap<String, BTreeSet<String>>;

/// The opening of the fenced block in `ARCHITECTURE.md` that holds the dependency map.
pub const MAP_FENCE: &str = "```tidy-deps";

/// Reads the dependency map from the fenced ```` ```tidy-deps ```` block of a Markdown text.
///
/// Each line is `crate -> dep dep ...`; a crate with no dependencies is written `crate ->`.
pub fn parse_dependency_map(markdown: &str) -> Result<DependencyMap, String> {
    let start = markdown
        .find(MAP_FENCE)
        .ok_or_else(|| format!("no `{MAP_FENCE}` block found"))?;
    let body = &markdown[start + MAP_FENCE.len()..];
    let end = body
        .find("```")
        .ok_or_else(|| "the dependency map block is not closed".to_string())?;
    let mut map = DependencyMap::new();
    for (line_idx, line) in body[..end].lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let (from, to) = line.split_once("->").ok_or_else(|| {
            format!("map line {line_idx}: expected `crate -> deps`, got `{line}`")
        })?;
        let deps = to.split_whitespace().map(str::to_string).collect();
        if map.insert(from.trim().to_string(), deps).is_some() {
            return Err(format!(
                "map line {line_idx}: `{}` listed twice",
                from.trim()
            ));
        }
    }
    Ok(map)
}

/// The real edges between workspace members, from `cargo metadata --format-version 1` output.
///
/// Every dependency kind counts (normal, dev and build).
pub fn workspace_edges(metadata: &serde_json::Value) -> Result<DependencyMap, String> {
    let packages = metadata["packages"]
        .as_array()
        .ok_or("cargo metadata has no `packages` array")?;
    let members: BTreeSet<&str> = metadata["workspace_members"]
        .as_array()
        .ok_or("cargo metadata has no `workspace_members` array")?
        .iter()
        .filter_map(|id| id.as_str())
        .collect();
    let member_names: BTreeSet<String> = packages
        .iter()
        .filter(|p| p["id"].as_str().is_some_and(|id| members.contains(id)))
        .filter_map(|p| p["name"].as_str().map(str::to_string))
        .collect();
    let mut edges = DependencyMap::new();
    for package in packages {
        let Some(name) = package["name"].as_str() else {
            continue;
        };
        if !member_names.contains(name) {
            continue;
        }
        let deps = package["dependencies"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|d| d["name"].as_str())
            .filter(|d| member_names.contains(*d))
            .map(str::to_string)
            .collect();
        edges.insert(name.to_string(), deps);
    }
    Ok(edges)
}

/// Every difference between the real edges and the allowed map, as readable lines.
pub fn check_edges(allowed: &DependencyMap, actual: &DependencyMap) -> Vec<String> {
    let mut problems = Vec::new();
    for (krate, deps) in actual {
        let Some(allowed_deps) = allowed.get(krate) else {
            problems.push(format!(
                "crate `{krate}` is missing from the dependency map"
            ));
            continue;
        };
        for dep in deps.difference(allowed_deps) {
            problems.push(format!(
                "`{krate}` depends on `{dep}`, which the dependency map in ARCHITECTURE.md does not allow"
            ));
        }
    }
    for krate in allowed.keys() {
        if !actual.contains_key(krate) {
            problems.push(format!(
                "the dependency map names `{krate}`, which is not a workspace member"
            ));
        }
    }
    problems
}

/// The packages (from `cargo metadata --format-version 1` output) that depend on
/// `dev_only` other than as a dev-dependency, with the kind they use.
pub fn non_dev_uses(metadata: &serde_json::Value, dev_only: &str) -> Vec<String> {
    let mut out = Vec::new();
    for package in metadata["packages"].as_array().into_iter().flatten() {
        for dep in package["dependencies"].as_array().into_iter().flatten() {
            let kind = dep["kind"].as_str().unwrap_or("normal");
            if dep["name"].as_str() == Some(dev_only) && kind != "dev" {
                let name = package["name"].as_str().unwrap_or("?");
                out.push(format!("`{name}` uses `{dev_only}` as a {kind} dependency"));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dev_only_crate_used_otherwise_is_found() {
        let metadata = serde_json::json!({"packages": [
            {"name": "fdsl", "dependencies": [{"name": "testkit", "kind": "dev"}]},
            {"name": "app", "dependencies": [{"name": "testkit", "kind": null}]},
        ]});
        assert_eq!(
            non_dev_uses(&metadata, "testkit"),
            ["`app` uses `testkit` as a normal dependency"]
        );
    }

    const MAP: &str = "intro\n```tidy-deps\nfdsl ->\nrender -> fdsl\napp -> fdsl render\n```\n";

    fn edges(pairs: &[(&str, &[&str])]) -> DependencyMap {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.iter().map(|s| s.to_string()).collect()))
            .collect()
    }

    #[test]
    fn allowed_edges_pass() {
        let map = parse_dependency_map(MAP).unwrap();
        let actual = edges(&[("fdsl", &[]), ("render", &["fdsl"]), ("app", &["render"])]);
        assert_eq!(check_edges(&map, &actual), Vec::<String>::new());
    }

    #[test]
    fn a_wrong_edge_fails() {
        let map = parse_dependency_map(MAP).unwrap();
        let actual = edges(&[("fdsl", &["render"]), ("render", &["fdsl"]), ("app", &[])]);
        let problems = check_edges(&map, &actual);
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(
            problems[0].contains("`fdsl` depends on `render`"),
            "{problems:?}"
        );
    }

    #[test]
    fn unknown_and_missing_crates_fail() {
        let map = parse_dependency_map(MAP).unwrap();
        let actual = edges(&[("fdsl", &[]), ("render", &["fdsl"]), ("extra", &[])]);
        let problems = check_edges(&map, &actual);
        assert!(
            problems.iter().any(|p| p.contains("`extra` is missing")),
            "{problems:?}"
        );
        assert!(
            problems.iter().any(|p| p.contains("names `app`")),
            "{problems:?}"
        );
    }

    #[test]
    fn malformed_maps_are_errors() {
        assert!(parse_dependency_map("no block").is_err());
        assert!(parse_dependency_map("```tidy-deps\nfdsl\n```").is_err());
        assert!(parse_dependency_map("```tidy-deps\nfdsl ->\n").is_err());
        assert!(parse_dependency_map("```tidy-deps\nfdsl ->\nfdsl ->\n```").is_err());
    }
}
