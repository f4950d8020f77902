//! Golden-image tests: offscreen renders compared with checked-in PNGs within a tolerance.
//!
//! The goldens were rendered on Mesa 22.3.6 llvmpipe through wgpu's GL backend (the machine
//! had no Vulkan driver); other GPUs and backends may differ by more than the tolerance along
//! silhouettes, and a failure prints the adapter used. With no adapter at all the tests print
//! a note and pass.
//! `UPDATE_SNAPSHOTS=1 cargo test -p render --test golden` rewrites them.

use glam::{Mat4, Vec3};
use render::camera::Camera;
use render::gpu::offscreen::{Headless, OffscreenError};
use render::image::RgbaImage;
use render::mesh::octree::{MeshSettings, mesh};
use render::mesh::{Aabb, Field, Mesh};
use render::scene::{Material, Scene};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Largest per-channel difference (of 255) that still counts as the same pixel.
const CHANNEL_TOLERANCE: u8 = 10;
/// Largest fraction of pixels allowed to differ by more than the channel tolerance.
const DIFFERING_FRACTION_MAX: f64 = 0.005;
const WIDTH: u32 = 160;
const HEIGHT: u32 = 120;

struct Sphere(f32);
impl Field for Sphere {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        let near: f32 = (0..3)
            .map(|a| {
                if lo[a] > 0.0 {
                    lo[a]
                } else if hi[a] < 0.0 {
                    -hi[a]
                } else {
                    0.0
                }
            })
            .map(|d| d * d)
            .sum();
        let far: f32 = (0..3)
            .map(|a| lo[a].abs().max(hi[a].abs()))
            .map(|d| d * d)
            .sum();
        (self.0 - far.sqrt(), self.0 - near.sqrt())
    }
    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        for i in 0..xs.len() {
            out[i] = self.0 - (xs[i] * xs[i] + ys[i] * ys[i] + zs[i] * zs[i]).sqrt();
        }
    }
}

struct Cube(f32);
impl Field for Cube {
    fn interval(&mut self, lo: [f32; 3], hi: [f32; 3]) -> (f32, f32) {
        let far = (0..3)
            .map(|a| lo[a].abs().max(hi[a].abs()))
            .fold(0.0, f32::max);
        let near = (0..3)
            .map(|a| {
                if lo[a] > 0.0 {
                    lo[a]
                } else if hi[a] < 0.0 {
                    -hi[a]
                } else {
                    0.0
                }
            })
            .fold(0.0, f32::max);
        (self.0 - far, self.0 - near)
    }
    fn values(&mut self, xs: &[f32], ys: &[f32], zs: &[f32], out: &mut [f32]) {
        for i in 0..xs.len() {
            out[i] = self.0 - xs[i].abs().max(ys[i].abs()).max(zs[i].abs());
        }
    }
}

fn mesh_of(field: &mut impl Field) -> Mesh {
    let m = mesh(
        field,
        &MeshSettings {
            bounds: Aabb::new([-1.1; 3], [1.1; 3]),
            depth: 5,
        },
    )
    .expect("mesh a closed-form field");
    assert_eq!(m.open_edges(), 0);
    assert_eq!(m.non_manifold_edges(), 0);
    m
}

fn camera() -> Camera {
    Camera {
        distance: 3.5,
        ..Camera::default()
    }
}

fn coloured_sphere() -> Scene {
    let mut m = mesh_of(&mut Sphere(1.0));
    m.colour_with(|p| [0.5 + 0.5 * p[0], 0.5 + 0.5 * p[1], 0.5 + 0.5 * p[2], 1.0]);
    let mut scene = Scene {
        camera: camera(),
        ..Scene::default()
    };
    scene.add_object(
        Arc::new(m),
        Mat4::IDENTITY,
        Material {
            shininess: 24.0,
            specular: 0.5,
            ..Material::default()
        },
    );
    scene.add_crosshair(Vec3::new(0.0, 0.0, 1.2), 0.2, [1.0, 1.0, 0.0, 1.0]);
    scene
}

fn transparent_box_over_opaque() -> Scene {
    let mut inner = mesh_of(&mut Cube(0.45));
    inner.colour_with(|_| [0.9, 0.3, 0.1, 1.0]);
    let mut outer = mesh_of(&mut Cube(0.9));
    outer.colour_with(|_| [0.2, 0.5, 1.0, 1.0]);
    let mut scene = Scene {
        camera: camera(),
        ..Scene::default()
    };
    let glass = Material {
        opacity: 0.35,
        specular: 0.6,
        ..Material::default()
    };
    scene.add_object(Arc::new(outer), Mat4::IDENTITY, glass);
    scene.add_object(
        Arc::new(inner),
        Mat4::from_translation(Vec3::new(0.0, 0.0, -0.2)),
        Material::default(),
    );
    scene.add_box(Aabb::new([-1.0; 3], [1.0; 3]), [1.0, 1.0, 1.0, 1.0]);
    scene
}

fn diff_dir() -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .unwrap_or(Path::new("."))
        .join("golden-diff")
}

/// Compares `actual` with the golden `name`.png; returns a failure message.
fn compare(name: &str, actual: &RgbaImage, adapter: &str) -> Result<(), String> {
    let golden_path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(format!("{name}.png"));
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        actual.save_png(&golden_path).expect("write golden");
        println!("wrote {} on {adapter}", golden_path.display());
        return Ok(());
    }
    let golden = RgbaImage::from_png(&std::fs::read(&golden_path).map_err(|e| {
        format!(
            "{}: {e} (run with UPDATE_SNAPSHOTS=1)",
            golden_path.display()
        )
    })?)
    .map_err(|e| e.to_string())?;
    if (golden.width, golden.height) != (actual.width, actual.height) {
        return Err(format!(
            "{name}: size {}x{} vs golden {}x{}",
            actual.width, actual.height, golden.width, golden.height
        ));
    }
    let mut diff = actual.clone();
    let mut n_differing = 0usize;
    for (i, (a, g)) in actual
        .pixels
        .chunks_exact(4)
        .zip(golden.pixels.chunks_exact(4))
        .enumerate()
    {
        let worst = a
            .iter()
            .zip(g)
            .map(|(x, y)| x.abs_diff(*y))
            .max()
            .unwrap_or(0);
        let bad = worst > CHANNEL_TOLERANCE;
        n_differing += usize::from(bad);
        diff.pixels[4 * i..4 * i + 4].copy_from_slice(if bad {
            &[255, 0, 255, 255]
        } else {
            &[0, 0, 0, 255]
        });
    }
    let fraction = n_differing as f64 / (actual.width * actual.height) as f64;
    if fraction <= DIFFERING_FRACTION_MAX {
        return Ok(());
    }
    let dir = diff_dir();
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let (actual_path, diff_path) = (
        dir.join(format!("{name}.actual.png")),
        dir.join(format!("{name}.diff.png")),
    );
    actual.save_png(&actual_path).map_err(|e| e.to_string())?;
    diff.save_png(&diff_path).map_err(|e| e.to_string())?;
    Err(format!(
        "{name}: {:.2}% of pixels differ by more than {CHANNEL_TOLERANCE} (allowed {:.2}%) on {adapter}; actual {}, diff {}",
        100.0 * fraction,
        100.0 * DIFFERING_FRACTION_MAX,
        actual_path.display(),
        diff_path.display()
    ))
}

fn headless() -> Option<Headless> {
    match Headless::new() {
        Ok(h) => Some(h),
        Err(e @ (OffscreenError::NoAdapter(_) | OffscreenError::Device(_))) => {
            println!("skipping golden test: {e}");
            None
        }
        Err(e) => panic!("headless setup failed: {e}"),
    }
}

#[test]
fn coloured_sphere_matches_golden() {
    let Some(mut gpu) = headless() else { return };
    let image = gpu.render(&coloured_sphere(), WIDTH, HEIGHT).unwrap();
    // Whatever the GPU, the centre is the lit sphere and the corner the background.
    let bg = image.pixel(0, 0).unwrap();
    let centre = image.pixel(WIDTH / 2, HEIGHT / 2).unwrap();
    assert_ne!(bg, centre);
    compare("coloured_sphere", &image, &gpu.adapter_description()).unwrap();
}

#[test]
fn transparent_box_over_opaque_matches_golden() {
    let Some(mut gpu) = headless() else { return };
    let scene = transparent_box_over_opaque();
    let image = gpu.render(&scene, WIDTH, HEIGHT).unwrap();
    // The opaque inner cube shows through the glass: the centre is reddish, not blue.
    let c = image.pixel(WIDTH / 2, HEIGHT / 2 + 8).unwrap();
    assert!(
        c[0] > c[2],
        "centre {c:?} should show the red cube through the glass"
    );
    compare(
        "transparent_box_over_opaque",
        &image,
        &gpu.adapter_description(),
    )
    .unwrap();
}

#[test]
fn a_changed_picture_fails_and_writes_actual_and_diff() {
    // Needs no GPU: compares an edited copy of a checked-in golden with the original.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/coloured_sphere.png");
    let mut edited = RgbaImage::from_png(&std::fs::read(path).unwrap()).unwrap();
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        return;
    }
    assert_eq!(compare("coloured_sphere", &edited, "cpu"), Ok(()));
    // Small noise within the tolerance still passes.
    for b in edited.pixels.iter_mut().step_by(4) {
        *b = b.saturating_add(CHANNEL_TOLERANCE / 2);
    }
    assert_eq!(compare("coloured_sphere", &edited, "cpu"), Ok(()));
    // A 20x20 block of changed pixels (2% of the image) fails.
    for y in 50..70 {
        for x in 70..90 {
            let i = 4 * (y * WIDTH as usize + x);
            edited.pixels[i] ^= 0x80;
        }
    }
    let err = compare("coloured_sphere", &edited, "cpu").unwrap_err();
    assert!(err.contains("2.08% of pixels"), "{err}");
    assert!(diff_dir().join("coloured_sphere.diff.png").exists());
    assert!(diff_dir().join("coloured_sphere.actual.png").exists());
}
