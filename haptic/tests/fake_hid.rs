//! End-to-end HID tests against the FUSE fake devices in `tests/fake-hid/`: the test binary
//! re-runs itself under `run.sh` (as the "child"), drives the real hidapi backend against the
//! fake, and the parent asserts on what the driver read and what the fake logged. Where the
//! fake cannot run (not root, no /dev/fuse, packages missing) the test says why and returns.

use std::path::PathBuf;
use std::process::Command;

use glam::DVec3;
use haptic::device::HapticDevice;
use haptic::device::hid::{PidForce, SpaceMouse};

const CHILD_ENV: &str = "HAPTIC_FAKE_HID_CHILD";

fn fake_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fake-hid")
}

/// Why the fake cannot run here, if it cannot.
fn fake_unavailable() -> Option<String> {
    let uid = Command::new("id").arg("-u").output().ok()?;
    if String::from_utf8_lossy(&uid.stdout).trim() != "0" {
        return Some("not root".into());
    }
    if !std::path::Path::new("/dev/fuse").exists() {
        return Some("no /dev/fuse".into());
    }
    let fusepy = Command::new("/usr/bin/python3")
        .args(["-c", "import fusepy"])
        .output();
    if !fusepy.is_ok_and(|o| o.status.success()) {
        return Some("python3-fusepy missing (apt-get install python3-fusepy libfuse2)".into());
    }
    if !Command::new("unshare")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
    {
        return Some("unshare missing".into());
    }
    None
}

/// Runs this test binary's `test_name` under the fake; returns (stdout, device log).
fn run_under_fake(kind: &str, test_name: &str) -> Option<(String, String)> {
    if let Some(why) = fake_unavailable() {
        eprintln!("skipping the fake-HID test {test_name}: {why}");
        return None;
    }
    let exe = std::env::current_exe().expect("test binary path");
    let out = Command::new(fake_dir().join("run.sh"))
        .env("FAKE_HID_KIND", kind)
        .env(CHILD_ENV, kind)
        .arg(exe)
        .args(["--exact", test_name, "--nocapture", "--test-threads=1"])
        .output()
        .expect("run.sh starts");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "child failed:\n{stdout}\n{stderr}");
    let (child, log) = stdout
        .split_once("--- device log:")
        .expect("run.sh prints the log");
    Some((child.to_owned(), log.to_owned()))
}

#[test]
fn spacemouse_end_to_end() {
    if std::env::var(CHILD_ENV).as_deref() == Ok("spacemouse") {
        let mut mouse = SpaceMouse::open_first().expect("the fake SpaceMouse opens");
        let mut n_reports = 0;
        while n_reports < 20 {
            if mouse.poll(500).expect("reads") {
                n_reports += 1;
            }
        }
        let s = mouse.state();
        let sample = mouse.sample().expect("samples");
        println!(
            "CHILD translation {:?} rotation {:?}",
            s.translation, s.rotation
        );
        println!(
            "CHILD bad {} position_ok {}",
            mouse.n_bad_reports(),
            sample.position_metres.is_finite()
        );
        return;
    }
    let Some((child, log)) = run_under_fake("spacemouse", "spacemouse_end_to_end") else {
        return;
    };
    assert!(log.contains("open /hidraw0"), "{log}");
    assert!(child.contains("rotation [1, 2, 3]"), "{child}");
    assert!(child.contains("CHILD bad 0 position_ok true"), "{child}");
    // The fake streams X = i % 350, Y = -X, Z = 7.
    // libtest may print its own `test ... ` prefix on the same line.
    let line = child
        .lines()
        .find_map(|l| l.split_once("CHILD translation").map(|(_, rest)| rest))
        .expect("child line");
    let nums: Vec<i64> = line
        .split(|c: char| !(c.is_ascii_digit() || c == '-'))
        .filter_map(|t| t.parse().ok())
        .collect();
    assert_eq!(nums.len(), 6, "{line}");
    assert!(nums[0] > 0 && nums[1] == -nums[0] && nums[2] == 7, "{line}");
}

#[test]
fn pid_force_end_to_end() {
    if std::env::var(CHILD_ENV).as_deref() == Ok("pid") {
        let mut dev = PidForce::open(0x1234, 0xf00d, 3.0).expect("the fake PID device opens");
        println!("CHILD block {}", dev.block_idx());
        dev.set_force(DVec3::new(1.5, 0.0, 0.0)).expect("writes");
        dev.set_force(DVec3::new(-9.0, 0.0, 0.0)).expect("writes");
        return;
    }
    let Some((child, log)) = run_under_fake("pid", "pid_force_end_to_end") else {
        return;
    };
    assert!(child.contains("CHILD block 7"), "{child}");
    let expected = [
        "feature set: 0b010000",
        "feature get: 0c",
        "output report: 010701ffff00000000ffff01",
        "output report: 05070000",
        "output report: 0a070101",
        // 1.5 N of 3 N is magnitude 5000; -9 N saturates at -10000.
        "output report: 05078813",
        "output report: 0507f0d8",
    ];
    let mut rest = log.as_str();
    for line in expected {
        let at = rest
            .find(line)
            .unwrap_or_else(|| panic!("missing `{line}` in order:\n{log}"));
        rest = &rest[at + line.len()..];
    }
}

#[test]
fn missing_hardware_is_an_error_not_a_panic() {
    if std::env::var(CHILD_ENV).is_ok() {
        return;
    }
    // No such device exists here (the fake only lives inside run.sh's namespace).
    assert!(PidForce::open(0xdead, 0xbeef, 1.0).is_err());
}
