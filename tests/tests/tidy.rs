//! Runs the tidy checks over the real workspace.

use std::path::{Path, PathBuf};
use std::process::Command;
use tests::tidy::{deps, files, functions, modules, names};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate sits in the workspace root")
}

/// `cargo metadata` of the workspace's own packages.
fn metadata() -> serde_json::Value {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let output = Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(root())
        .output()
        .expect("cargo runs");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).expect("cargo metadata prints JSON")
}

#[test]
fn dependency_edges_follow_the_architecture_map() {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let allowed = deps::parse_dependency_map(&text).unwrap();
    let metadata = metadata();
    let actual = deps::workspace_edges(&metadata).unwrap();
    let mut problems = deps::check_edges(&allowed, &actual);
    problems.extend(deps::non_dev_uses(&metadata, "testkit"));
    assert!(
        problems.is_empty(),
        "dependency map violations:\n{}",
        problems.join("\n")
    );
}

/// ARCHITECTURE.md is a map, not a changelog: short enough to read in one sitting, one
/// sentence a line. Figures go to BENCHMARKS.md and history to commit messages.
#[test]
fn the_architecture_map_stays_short() {
    const MAX_MAP_LINES: usize = 250;
    const MAX_MAP_LINE_CHARS: usize = 300;
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let n_lines = text.lines().count();
    assert!(
        n_lines <= MAX_MAP_LINES,
        "ARCHITECTURE.md has {n_lines} lines, over {MAX_MAP_LINES}"
    );
    let long: Vec<String> = (text.lines().enumerate())
        .filter(|(_, line)| line.chars().count() > MAX_MAP_LINE_CHARS)
        .map(|(i, line)| format!("line {}: {} characters", i + 1, line.chars().count()))
        .collect();
    assert!(
        long.is_empty(),
        "ARCHITECTURE.md lines over {MAX_MAP_LINE_CHARS} characters:\n{}",
        long.join("\n")
    );
}

/// The folder of every workspace member (the `members` of `Cargo.toml`), from its manifest.
fn member_dirs() -> Vec<PathBuf> {
    let metadata = metadata();
    let dirs: Vec<PathBuf> = metadata["packages"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|p| p["manifest_path"].as_str())
        .filter_map(|m| Path::new(m).parent().map(Path::to_path_buf))
        .collect();
    assert!(dirs.len() >= 9, "found only {dirs:?}");
    dirs
}

/// Every Rust file of the members, their tests, benches and examples included (a member
/// nested in another's folder is read once).
fn all_rust_files() -> Vec<PathBuf> {
    let mut files: Vec<_> = member_dirs()
        .iter()
        .flat_map(|m| files::rust_files(m))
        .collect();
    files.sort();
    files.dedup();
    files
}

/// The files under the members' `src` folders.
fn source_files() -> Vec<PathBuf> {
    member_dirs()
        .iter()
        .flat_map(|m| files::rust_files(&m.join("src")))
        .collect()
}

#[test]
fn every_source_file_has_a_header() {
    let missing = files::files_without_header(&all_rust_files());
    assert!(
        missing.is_empty(),
        "files without a `//!` header: {missing:?}"
    );
}

#[test]
fn no_crate_has_an_import_circle_between_its_top_level_modules() {
    let mut problems = Vec::new();
    for member in member_dirs() {
        let src = member.join("src");
        let graph = modules::module_graph(&src);
        let src = src
            .strip_prefix(root())
            .unwrap_or(&src)
            .display()
            .to_string();
        for circle in modules::circles(&graph) {
            let edges: Vec<String> = circle
                .iter()
                .map(|m| {
                    format!(
                        "{m} -> {:?}",
                        graph[m]
                            .intersection(&circle.iter().cloned().collect())
                            .collect::<Vec<_>>()
                    )
                })
                .collect();
            problems.push(format!("{src}: {}", edges.join("; ")));
        }
    }
    assert!(
        problems.is_empty(),
        "import circles:\n{}",
        problems.join("\n")
    );
}

#[test]
fn functions_are_short_or_marked_tables() {
    let problems = functions::too_long(&source_files());
    assert!(
        problems.is_empty(),
        "functions over {} lines, or over {} without `{}`:\n{}",
        functions::MAX_FUNCTION_LINES,
        functions::MAX_PLAIN_FUNCTION_LINES,
        functions::TABLE_MARK,
        problems.join("\n")
    );
}

#[test]
fn limits_are_named_max_first() {
    let problems = names::misnamed_limits(&all_rust_files());
    assert!(
        problems.is_empty(),
        "limits named `*_MAX` (write `MAX_*`):\n{}",
        problems.join("\n")
    );
}

/// The app is a face: meshing lives in `render::mesher` and the scene-to-servo feed in
/// `haptic::feed`. The app drives them through those types (and hands a mesher's patch to the
/// renderer as it is) but names none of the parts that do the work (patch assembly, dirty
/// boxes, recolouring, servo snapshots).
#[test]
fn the_app_holds_no_meshing_or_servo_feed_code() {
    const WORKS: [&str; 5] = [
        "OctreeMesher",
        "mesh_update",
        "dirty_boxes",
        "colour_with",
        "Snapshotter",
    ];
    let app: Vec<PathBuf> = files::rust_files(&root().join("app"));
    assert!(app.len() > 10, "found only {app:?}");
    let found = files::files_naming(&app, &WORKS);
    assert!(
        found.is_empty(),
        "the app does render's or haptic's work:\n{}",
        found.join("\n")
    );
}

/// The sans-IO core builds without sockets or an async runtime: the simulator (which drives
/// the core alone) has no tokio or quinn in its normal dependency tree, while the app (which
/// enables `replication`'s `net` feature) does. The second half shows the check can fail.
#[test]
fn the_simulator_builds_without_the_network_adapter() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let tree = |package: &str| {
        let output = Command::new(&cargo)
            .args([
                "tree",
                "--offline",
                "-e",
                "normal",
                "--prefix",
                "none",
                "-p",
            ])
            .arg(package)
            .current_dir(root())
            .output()
            .unwrap();
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        String::from_utf8(output.stdout).unwrap()
    };
    let has = |tree: &str, krate: &str| tree.lines().any(|l| l.starts_with(&format!("{krate} v")));
    let simulator = tree("simulator");
    for krate in ["tokio", "quinn", "socket2", "rcgen"] {
        assert!(!has(&simulator, krate), "the simulator depends on {krate}");
    }
    let app = tree("app");
    assert!(has(&app, "tokio") && has(&app, "quinn"), "{app}");
}
