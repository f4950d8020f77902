//! The command line follows the usual conventions: every subcommand has a generated `--help`
//! that exits 0, a usage error exits 2, and errors a person can act on say what to do (a weak
//! or mistyped invite, a port in use, a directory that is not a session store).
#![allow(
    clippy::unwrap_used,
    reason = "helpers outside #[test] fns unwrap process output"
)]

use std::process::{Command, Output};

fn sculpt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sculpt"))
        .args(args)
        .output()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn every_subcommand_has_help_that_exits_zero() {
    let subcommands = [
        "demo",
        "peer",
        "discovery",
        "invite",
        "sessions",
        "check",
        "eval",
        "slice",
        "render",
        "touch",
        "import",
        "export",
    ];
    for sub in subcommands {
        let run = sculpt(&[sub, "--help"]);
        assert!(run.status.success(), "{sub}: {}", text(&run.stderr));
        assert!(text(&run.stdout).contains("Usage: sculpt"), "{sub}");
    }
    let top = sculpt(&["--help"]);
    assert!(top.status.success());
    for sub in subcommands {
        assert!(text(&top.stdout).contains(sub), "{sub} missing from --help");
    }
    let bad = sculpt(&["peer", "--no-such-flag"]);
    assert_eq!(bad.status.code(), Some(2), "{}", text(&bad.stderr));
}

#[test]
fn demo_lists_the_scenes_and_names_them_when_one_is_unknown() {
    let list = sculpt(&["demo", "--list"]);
    assert!(list.status.success(), "{}", text(&list.stderr));
    let stdout = text(&list.stdout);
    let names: Vec<&str> = stdout
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    let expected: Vec<&str> = app::demos::DEMOS.iter().map(|d| d.name).collect();
    assert_eq!(names, expected, "{stdout}");
    assert!(
        stdout.contains("wind  ") && stdout.contains("invisible cone"),
        "{stdout}"
    );
    // An unknown name fails before any window opens, listing the names there are.
    let unknown = sculpt(&["demo", "shark-tank"]);
    assert!(!unknown.status.success());
    let stderr = text(&unknown.stderr);
    assert!(
        stderr.contains("no demo is called `shark-tank`; there are: watermelon, wind"),
        "{stderr}"
    );
}

#[test]
fn weak_and_mistyped_invites_are_refused_with_what_to_do() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli-invite");
    let store = dir.to_str().unwrap();
    let weak = sculpt(&["peer", "--store", store, "--invite", "password"]);
    assert_eq!(weak.status.code(), Some(2));
    assert!(
        text(&weak.stderr).contains("sculpt invite"),
        "{}",
        text(&weak.stderr)
    );
    let good = text(&sculpt(&["invite"]).stdout).trim().to_string();
    // One wrong character: the error names its group.
    let mut typo: Vec<char> = good.chars().collect();
    typo[7] = if typo[7] == 'a' { 'b' } else { 'a' };
    let typo: String = typo.into_iter().collect();
    let run = sculpt(&["peer", "--store", store, "--invite", &typo]);
    assert_eq!(run.status.code(), Some(2));
    assert!(
        text(&run.stderr).contains("group 2"),
        "{}",
        text(&run.stderr)
    );
    assert!(!dir.exists(), "nothing was created for a refused invite");
}

#[test]
fn a_port_in_use_is_named_with_what_to_do() {
    let blocker = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let addr = blocker.local_addr().unwrap().to_string();
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli-port");
    let _ = std::fs::remove_dir_all(&dir);
    let invite = text(&sculpt(&["invite"]).stdout).trim().to_string();
    let run = sculpt(&[
        "peer",
        "--store",
        dir.to_str().unwrap(),
        "--invite",
        &invite,
        "--no-lan",
        "--listen",
        &addr,
    ]);
    assert!(!run.status.success());
    let said = text(&run.stderr);
    assert!(
        said.contains("in use") && said.contains("--listen"),
        "{said}"
    );
}

#[test]
fn sessions_lists_the_stores_under_a_root() {
    use app::engine::{Engine, EngineConfig, Network};
    let root = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli-sessions");
    let _ = std::fs::remove_dir_all(&root);
    let empty = sculpt(&["sessions", "--root", root.to_str().unwrap()]);
    assert!(empty.status.success());
    assert!(
        text(&empty.stdout).contains("no sessions"),
        "{}",
        text(&empty.stdout)
    );
    for name in ["design-review", "classroom"] {
        let config = EngineConfig {
            store: root.join(name),
            invite: None,
            network: Network {
                listen: (std::net::Ipv4Addr::LOCALHOST, 0).into(),
                ..Network::default()
            },
            demo: app::demos::find(app::demos::DEFAULT_DEMO).ok(),
            memory_fallback: false,
            name: None,
            session_name: None,
        };
        Engine::start(config, app::clock::now().wall)
            .unwrap()
            .shutdown();
    }
    std::fs::create_dir_all(root.join("not-a-session")).unwrap();
    let listed = sculpt(&["sessions", "--root", root.to_str().unwrap()]);
    let out = text(&listed.stdout);
    assert!(listed.status.success(), "{out}");
    assert!(
        out.contains("design-review") && out.contains("classroom"),
        "{out}"
    );
    assert!(!out.contains("not-a-session"), "{out}");
}

#[test]
fn check_locates_a_too_deep_formula_instead_of_overflowing_the_stack() {
    // `x^x^...` once recursed a level per `^`: 60 KB of it aborted the 8 MiB main thread.
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("cli-check");
    std::fs::create_dir_all(&dir).unwrap();
    let deep = dir.join("deep.fdsl");
    std::fs::write(&deep, "x^".repeat(30_000) + "x").unwrap();
    let run = sculpt(&["check", &format!("@{}", deep.display())]);
    let stderr = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("nests deeper than"), "{stderr}");
    assert!(stderr.contains("--> 1:"), "{stderr}");
    // As long a flat chain nests nothing and compiles.
    let flat = dir.join("flat.fdsl");
    std::fs::write(&flat, "x+".repeat(30_000) + "x").unwrap();
    let run = sculpt(&["check", &format!("@{}", flat.display())]);
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert!(text(&run.stdout).starts_with("ok: outputs value"));
}
