//! End to end: `sculpt render` turns a scene file into PNG files, and reports a bad file's
//! errors with their location instead of panicking.
#![allow(
    clippy::unwrap_used,
    reason = "helpers outside #[test] fns unwrap process output"
)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn sculpt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sculpt"))
        .args(args)
        .output()
        .unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn render_writes_one_png_per_view_of_the_watermelon() {
    let out = scratch("render_watermelon");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/watermelon.wrl");
    let run = sculpt(&[
        "render",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--size",
        "64x48",
        "--depth",
        "4",
    ]);
    let (stdout, stderr) = (text(&run.stdout), text(&run.stderr));
    if !run.status.success() && stderr.contains("no wgpu adapter") {
        println!("skipping: {stderr}");
        return;
    }
    assert!(run.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("Watermelon:"), "{stdout}");
    for view in ["front", "corner"] {
        let path = out.join(format!("watermelon_{view}.png"));
        assert!(
            stdout.contains(&format!("wrote {}", path.display())),
            "{stdout}"
        );
        let image = plot::image::RgbaImage::from_png(&std::fs::read(&path).unwrap()).unwrap();
        assert_eq!((image.width, image.height), (64, 48));
        // The watermelon fills the middle; the corner is background.
        assert_ne!(image.pixel(32, 24), image.pixel(0, 0), "{view}");
    }
}

#[test]
fn render_reports_a_bad_file_with_its_location_and_bad_arguments_clearly() {
    let dir = scratch("render_bad");
    let bad = dir.join("bad.wrl");
    std::fs::write(
        &bad,
        "#VRML V2.0 utf8\nFShape {\n  geometry FGeometry { definition \"1-x^\" }\n}\n",
    )
    .unwrap();
    let out = dir.join("out");
    let run = sculpt(&[
        "render",
        bad.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = text(&run.stderr);
    assert!(!run.status.success());
    assert!(
        stderr.contains(&format!("{}:3:", bad.display())) && stderr.contains("error"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!out.exists(), "nothing is written for a bad file");

    let missing = sculpt(&["render", "no/such/file.wrl", "--out", out.to_str().unwrap()]);
    assert!(!missing.status.success());
    assert!(text(&missing.stderr).contains("no/such/file.wrl"));
    let no_out = sculpt(&["render", bad.to_str().unwrap()]);
    assert!(text(&no_out.stderr).contains("--out"));
    let bad_size = sculpt(&["render", "x.wrl", "--out", "o", "--size", "big"]);
    assert!(text(&bad_size.stderr).contains("WxH"));
}

#[test]
fn an_inline_outside_the_scenes_folder_is_refused_unless_allowed() {
    let dir = scratch("render_inline");
    let scenes = dir.join("scenes");
    std::fs::create_dir_all(&scenes).unwrap();
    // A file outside the scene's folder that a hostile scene tries to pull in.
    std::fs::write(
        dir.join("outside.wrl"),
        "#VRML V2.0 utf8\nFShape { geometry FGeometry { definition \"1-x^2-y^2-z^2\" } }\n",
    )
    .unwrap();
    let scene = scenes.join("scene.wrl");
    std::fs::write(
        &scene,
        "#VRML V2.0 utf8\nInline { url \"../outside.wrl\" }\n",
    )
    .unwrap();
    let out = dir.join("out");
    let args = [
        "render",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--size",
        "32x24",
        "--depth",
        "3",
    ];
    let refused = sculpt(&args);
    let stderr = text(&refused.stderr);
    assert!(!refused.status.success(), "{stderr}");
    assert!(stderr.contains("leaves the scene's folder"), "{stderr}");
    assert!(stderr.contains("--inline-root"), "{stderr}");
    assert!(!out.exists());
    let mut allowed: Vec<&str> = args.to_vec();
    allowed.extend(["--inline-root", dir.to_str().unwrap()]);
    let run = sculpt(&allowed);
    let (stdout, stderr) = (text(&run.stdout), text(&run.stderr));
    if !run.status.success() && stderr.contains("no wgpu adapter") {
        println!("skipping the allowed half: {stderr}");
        return;
    }
    assert!(run.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("triangles"), "{stdout}");
}

#[cfg(unix)]
#[test]
fn a_fifo_in_the_scenes_folder_is_refused_instead_of_waited_on() {
    let dir = scratch("render_fifo");
    let part = dir.join("part.wrl");
    let made = Command::new("mkfifo").arg(&part).status().unwrap();
    assert!(made.success(), "mkfifo");
    let scene = dir.join("scene.wrl");
    std::fs::write(&scene, "#VRML V2.0 utf8\nInline { url \"part.wrl\" }\n").unwrap();
    let out = dir.join("out");
    // Run with a deadline of 400 polls 50 ms apart: before the fix the process waited on the FIFO forever.
    let mut child = Command::new(env!("CARGO_BIN_EXE_sculpt"))
        .args([
            "render",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut polls = 0;
    while child.try_wait().unwrap().is_none() {
        polls += 1;
        if polls > 400 {
            child.kill().unwrap();
            panic!("sculpt render waited on a FIFO for 20 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let run = child.wait_with_output().unwrap();
    let stderr = text(&run.stderr);
    assert!(!run.status.success(), "{stderr}");
    assert!(stderr.contains("part.wrl"), "{stderr}");
    assert!(stderr.contains("not a regular file"), "{stderr}");
    // And the scene file itself may not be one either.
    let refused = sculpt(&[
        "render",
        part.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!refused.status.success());
    assert!(text(&refused.stderr).contains("not a regular file"));
}
