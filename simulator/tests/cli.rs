//! The simulator's command line: `--help` exits 0, a usage error exits 2.

use std::process::Command;

#[test]
fn help_exits_zero_and_a_bad_flag_exits_two() {
    let bin = env!("CARGO_BIN_EXE_simulator");
    let help = Command::new(bin).arg("--help").output().expect("runs");
    assert!(help.status.success());
    assert!(String::from_utf8_lossy(&help.stdout).contains("--faults"));
    let bad = Command::new(bin)
        .arg("--faults")
        .arg("hurricane")
        .output()
        .expect("runs");
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown faults hurricane"));
}
