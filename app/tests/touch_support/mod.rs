//! Running `sculpt touch` from the integration tests that feel a scene headless (`touch`,
//! `demo_sessions`, `window`): a path as CSV, the run, and the forces it wrote.

#![allow(
    dead_code,
    reason = "each test binary uses a different subset of the helpers"
)]

use std::path::Path;
use std::process::{Command, Output};

use glam::DVec3;

/// A path as CSV from `(t, point)` rows, button up.
pub fn csv(rows: &[(f64, DVec3)]) -> String {
    let mut out = String::from("t,x,y,z,button\n");
    for (t, p) in rows {
        out.push_str(&format!("{t},{},{},{},0\n", p.x, p.y, p.z));
    }
    out
}

/// Runs `sculpt touch SCENE --trace INPUT --out OUTPUT EXTRA...`.
pub fn sculpt_touch(scene: &Path, input: &Path, output: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sculpt"))
        .arg("touch")
        .arg(scene)
        .arg("--trace")
        .arg(input)
        .arg("--out")
        .arg(output)
        .args(extra)
        .output()
        .expect("sculpt runs")
}

/// The forces `sculpt touch` wrote to `output`, one `(t, force)` per tick.
pub fn read_forces(output: &Path) -> Vec<(f64, DVec3)> {
    let written = std::fs::read_to_string(output).expect("the forces file");
    let mut lines = written.lines();
    assert_eq!(lines.next(), Some("t,fx,fy,fz"));
    lines
        .map(|line| {
            let v: Vec<f64> = line
                .split(',')
                .map(|x| x.parse().expect("a number"))
                .collect();
            assert_eq!(v.len(), 4, "{line}");
            (v[0], DVec3::new(v[1], v[2], v[3]))
        })
        .collect()
}

/// Runs `sculpt touch` over `path_csv` (written to `dir`) and reads the forces it wrote.
pub fn touch(dir: &Path, scene: &Path, path_csv: &str, extra: &[&str]) -> Vec<(f64, DVec3)> {
    let (input, output) = (dir.join("in.csv"), dir.join("out.csv"));
    std::fs::write(&input, path_csv).expect("the path file");
    let run = sculpt_touch(scene, &input, &output, extra);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    read_forces(&output)
}
