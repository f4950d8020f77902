//! Runs the tidy checks over the real workspace.

use std::path::Path;
use std::process::Command;
use tests::tidy;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate sits in the workspace root")
}

#[test]
fn dependency_edges_follow_the_architecture_map() {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let allowed = tidy::parse_dependency_map(&text).unwrap();
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
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let metadata: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let actual = tidy::workspace_edges(&metadata).unwrap();
    let mut problems = tidy::check_edges(&allowed, &actual);
    problems.extend(tidy::non_dev_uses(&metadata, "testkit"));
    assert!(
        problems.is_empty(),
        "dependency map violations:\n{}",
        problems.join("\n")
    );
}

#[test]
fn every_source_file_has_a_header() {
    let members = [
        "fdsl",
        "replication",
        "haptic",
        "render",
        "app",
        "simulator",
        "tests",
        "testkit",
    ];
    let files: Vec<_> = members
        .iter()
        .flat_map(|m| tidy::rust_files(&root().join(m)))
        .collect();
    assert!(files.len() >= members.len(), "found only {files:?}");
    let missing = tidy::files_without_header(&files);
    assert!(
        missing.is_empty(),
        "files without a `//!` header: {missing:?}"
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
