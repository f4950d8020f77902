//! Patched uploads: a renderer handed each edit's `MeshPatch` (`Renderer::patch_object`)
//! draws, after every edit of a sculpting session, exactly the picture of a renderer that
//! uploads the whole new mesh, while writing only a fraction of its bytes; a patch with one
//! range left out shows in the picture.
//!
//! The session is the unit ball with 40 carves and blobs meshed at depth 6 through
//! `ObjectField` and `OctreeMesher`, then edited near the point facing the camera with remesh
//! and `mesh_update` after each edit. Each renderer is a `Headless` of its own (Vulkan on
//! llvmpipe in CI); they draw the same vertex and index data, so the pictures must be equal to
//! the byte. With no adapter at all the test prints a note and passes, as the goldens do.
//!
//! A prepare also says whether it changed anything a draw shows (`Renderer::changed`), so that
//! a window may show its last picture again: each thing drawn, changed alone, says so once.
//! A kept picture (`KeptPicture`) whose scene changed only its lines draws only the lines and
//! the transparent objects over its kept layer of the others, and one handed each patch draws
//! the objects again only in the patch's region; both show the one-pass picture.
//! A closed object (`SceneObject::closed`) is drawn without its back faces: the ball's picture
//! is the two-sided one, and a triangle seen from behind is not drawn at all.
#![allow(
    clippy::unwrap_used,
    reason = "the session and the device helpers unwrap fixed, known-good inputs"
)]

use glam::{DVec3, Mat4, Vec3};
use model::object::{Domain, Edit, EditOp, Formula, Geometry, Object, ObjectData, Pose, ToolShape};
use render::camera::Camera;
use render::gpu::KeptFrame;
use render::gpu::offscreen::{Headless, OffscreenError};
use render::mesh::object_field::{Dirty, dirty_boxes};
use render::mesh::octree::{MeshPatch, MeshSettings, OctreeMesher};
use render::mesh::{Aabb, Mesh, ObjectField};
use render::scene::{Material, Scene};
use std::sync::Arc;

const WIDTH: u32 = 192;
const HEIGHT: u32 = 144;
const DEPTH: u8 = 6;

/// A headless device and renderer, or `None` (with a note) where there is no adapter.
fn headless() -> Option<Headless> {
    match Headless::new() {
        Ok(h) => Some(h),
        Err(e @ (OffscreenError::NoAdapter(_) | OffscreenError::Device(_))) => {
            println!("no wgpu adapter: patched uploads not drawn ({e})");
            None
        }
        Err(e) => panic!("headless setup failed: {e}"),
    }
}

/// Prepares `scene` with `h`'s renderer, draws it and reads the RGBA pixels back.
fn draw(h: &mut Headless, scene: &Scene) -> Vec<u8> {
    h.render(scene, WIDTH, HEIGHT).unwrap().pixels
}

fn ball() -> Object {
    Object::new(ObjectData {
        geometry: Some(Geometry::implicit_in(
            Formula::new("1-sqrt(x^2+y^2+z^2)").unwrap(),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        ..ObjectData::default()
    })
    .unwrap()
}

fn settings() -> MeshSettings {
    MeshSettings {
        bounds: Aabb::new([-1.25; 3], [1.25; 3]),
        depth: DEPTH,
    }
}

/// Edit `k` of `n` along a golden-angle spiral over the unit sphere: carves, every fifth a
/// blob added, alternating stamps and short strokes.
fn spiral_edit(k: usize, n: usize) -> Edit {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let y = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
    let ring = (1.0 - y * y).max(0.0).sqrt();
    let phi = golden * k as f64;
    let at = DVec3::new(ring * phi.cos(), y, ring * phi.sin());
    let op = if k % 5 == 4 {
        EditOp::Union
    } else {
        EditOp::Subtract
    };
    let tool = ToolShape::Sphere { radius: 0.09 };
    if k.is_multiple_of(2) {
        Edit::stamp(op, tool, Pose::at(at))
    } else {
        let side = at.any_orthonormal_vector() * 0.08;
        Edit::stroke(op, tool, vec![Pose::at(at - side), Pose::at(at + side)])
    }
}

/// Edit `k` of the session: on the side of the ball facing the camera at `towards_eye`
/// (unit), carves, a blob and a stroke, each a little further round; the eighth carves a
/// notch in the outline, where the background shows through afterwards.
fn visible_edit(k: usize, towards_eye: DVec3) -> Edit {
    let u = towards_eye.any_orthonormal_vector();
    let v = towards_eye.cross(u);
    if k == 7 {
        let notch = ToolShape::Sphere { radius: 0.25 };
        let at = (u + 0.2 * towards_eye).normalize();
        return Edit::stamp(EditOp::Subtract, notch, Pose::at(at));
    }
    let angle = 1.3 * k as f64;
    let at = (towards_eye + 0.35 * (angle.cos() * u + angle.sin() * v)).normalize();
    let tool = ToolShape::Sphere {
        radius: 0.08 + 0.02 * (k % 3) as f64,
    };
    match k % 4 {
        0 | 2 => Edit::stamp(EditOp::Subtract, tool, Pose::at(at)),
        1 => Edit::stamp(EditOp::Union, tool, Pose::at(at * 1.02)),
        _ => Edit::stroke(
            EditOp::Subtract,
            tool,
            vec![Pose::at(at - 0.15 * u), Pose::at(at + 0.15 * u)],
        ),
    }
}

/// `object` meshed whole at [`DEPTH`]: the mesher (for later patches), the mesh and the
/// patch that made it.
fn meshed(object: &mut Object) -> (OctreeMesher, Mesh, MeshPatch) {
    object.prepare();
    let mut mesher = OctreeMesher::new(&settings()).unwrap();
    mesher
        .remesh(&mut ObjectField::new(object, 0.0), settings().bounds)
        .unwrap();
    let mut mesh = Mesh::default();
    let patch = mesher.mesh_update(&mut mesh).unwrap();
    (mesher, mesh, patch)
}

/// Applies `edit`, remeshes its boxes and patches a copy of `base`; returns the new mesh and
/// its patch.
fn edit_and_patch(
    object: &mut Object,
    mesher: &mut OctreeMesher,
    base: &Mesh,
    edit: Edit,
) -> (Mesh, MeshPatch) {
    let idx = object.apply(edit).unwrap();
    object.prepare();
    let boxes = match dirty_boxes(&object.history().entries()[idx].edit) {
        Dirty::Boxes(boxes) => boxes,
        Dirty::Everywhere => vec![settings().bounds],
    };
    let mut field = ObjectField::new(object, 0.0);
    for b in boxes {
        mesher.remesh(&mut field, b).unwrap();
    }
    let mut next = base.clone();
    let patch = mesher.mesh_update(&mut next).unwrap();
    (next, patch)
}

/// `patch` with its longest triangle range left out (what a renderer that forgot a range
/// would upload); `None` when it has no triangle range.
fn without_longest_range(patch: &MeshPatch) -> Option<MeshPatch> {
    let longest =
        (0..patch.triangle_ranges.len()).max_by_key(|&i| patch.triangle_ranges[i].len())?;
    let mut skipped = patch.clone();
    skipped.triangle_ranges.remove(longest);
    Some(skipped)
}

fn n_differing_pixels(a: &[u8], b: &[u8]) -> usize {
    assert_eq!(a.len(), b.len());
    a.chunks_exact(4)
        .zip(b.chunks_exact(4))
        .filter(|(p, q)| p != q)
        .count()
}

/// Whole-mesh bytes as the renderer uploads them: 52-byte vertices and 12-byte triangles.
fn whole_bytes(m: &Mesh) -> u64 {
    (52 * m.n_vertices() + 12 * m.n_triangles()) as u64
}

#[test]
fn patched_uploads_draw_the_whole_upload_picture_after_each_edit() {
    let (Some(mut patched), Some(mut skipping), Some(mut whole), Some(mut kept)) =
        (headless(), headless(), headless(), headless())
    else {
        return;
    };
    let mut object = ball();
    let n = 40;
    for k in 0..n {
        object.apply(spiral_edit(k, n)).unwrap();
    }
    let (mut mesher, first, patch) = meshed(&mut object);
    assert!(patch.full);
    let mut scene = one_object_scene(first);
    let towards_eye = scene.camera.eye().normalize().as_dvec3();

    // `patched` gets every patch, `skipping` every patch less its longest triangle range,
    // `whole` none: it uploads each new mesh whole.
    let before = draw(&mut patched, &scene);
    assert_eq!(before, draw(&mut skipping, &scene));
    assert_eq!(before, draw(&mut whole, &scene));
    // `kept` draws into a kept picture, each patch only where it reaches.
    let mut picture = kept.kept_picture(WIDTH, HEIGHT).unwrap();
    assert_eq!(
        before,
        kept.render_kept(&scene, &mut picture).unwrap().0.pixels
    );
    let mut n_regions = 0;
    let background = &before[..4];
    let n_object_pixels = before.chunks_exact(4).filter(|p| p != &background).count();
    assert!(
        n_object_pixels > (WIDTH * HEIGHT / 4) as usize,
        "the ball fills the picture: {n_object_pixels} pixels"
    );

    let (mut n_patched, mut n_skipping_wrong) = (0, 0);
    for k in 0..8 {
        let base = Arc::clone(&scene.objects[0].mesh);
        let (next, patch) = edit_and_patch(
            &mut object,
            &mut mesher,
            &base,
            visible_edit(k, towards_eye),
        );
        let next = Arc::new(next);
        patched
            .renderer_mut()
            .patch_object(0, &base, &next, &patch)
            .unwrap();
        (kept.renderer_mut())
            .patch_object(0, &base, &next, &patch)
            .unwrap();
        let skipped = without_longest_range(&patch).unwrap_or_else(|| patch.clone());
        skipping
            .renderer_mut()
            .patch_object(0, &base, &next, &skipped)
            .unwrap();
        scene.objects[0].mesh = Arc::clone(&next);
        // The mesher's worker boxes each new mesh's runs of triangles: a region is drawn
        // from the runs that reach it.
        scene.objects[0].pick_runs = Default::default();
        scene.objects[0].pick_runs.prepare(&next);
        // A new background halfway: everything is drawn again, and the regions after it are
        // cleared to the new one.
        let new_background = k == 4;
        if new_background {
            scene.background = [0.3, 0.5, 0.2, 1.0];
        }

        let expected = draw(&mut whole, &scene);
        assert_eq!(
            whole.renderer_mut().mesh_bytes_uploaded(),
            whole_bytes(&next)
        );
        let changed = n_differing_pixels(&expected, &before);
        assert!(changed > 0, "edit {k} does not show");
        let actual = draw(&mut patched, &scene);
        let wrong = n_differing_pixels(&actual, &expected);
        assert_eq!(
            wrong, 0,
            "edit {k}: {wrong} pixels differ from the whole upload ({patch:?})"
        );
        let bytes = patched.renderer_mut().mesh_bytes_uploaded();
        // The first patch outgrows the exact buffers of the first, unpatched upload: whole.
        if k == 0 || patch.full {
            assert_eq!(bytes, whole_bytes(&next), "edit {k}");
        } else {
            n_patched += 1;
            assert!(
                4 * bytes < whole_bytes(&next),
                "edit {k}: {bytes} of {} bytes uploaded",
                whole_bytes(&next)
            );
        }
        let (in_region, frame) = kept.render_kept(&scene, &mut picture).unwrap();
        let wrong = n_differing_pixels(&in_region.pixels, &expected);
        assert_eq!(
            wrong, 0,
            "edit {k}, kept picture drawing {frame:?}: {wrong} pixels"
        );
        if let KeptFrame::Region([x0, y0, x1, y1]) = frame {
            n_regions += 1;
            assert!(
                4 * (x1 - x0) * (y1 - y0) < WIDTH * HEIGHT,
                "edit {k}: {frame:?} is most of the picture"
            );
            let [drawn, held] = kept.renderer_mut().region_indices();
            assert!(
                0 < drawn && drawn < held,
                "edit {k}: {drawn} of {held} indices drawn in {frame:?}"
            );
        } else {
            assert!(
                k == 0 || patch.full || new_background,
                "edit {k}: {frame:?}"
            );
        }
        let drawn_skipping = draw(&mut skipping, &scene);
        n_skipping_wrong += usize::from(n_differing_pixels(&drawn_skipping, &expected) > 0);
    }
    assert!(n_patched >= 5, "{n_patched} edits uploaded as patches");
    assert!(
        n_regions + 1 >= n_patched,
        "{n_regions} of {n_patched} patches in a region"
    );
    assert!(
        2 * n_skipping_wrong >= n_patched,
        "leaving a patch range out showed in only {n_skipping_wrong} of {n_patched} pictures"
    );
}

#[test]
fn a_patch_from_another_mesh_or_with_wrong_lengths_is_refused_or_uploaded_whole() {
    let Some(mut headless) = headless() else {
        return;
    };
    let mut object = ball();
    object.apply(spiral_edit(0, 1)).unwrap();
    let (mut mesher, first, whole_patch) = meshed(&mut object);
    let first = Arc::new(first);
    let mut scene = Scene::default();
    scene.add_object(Arc::clone(&first), Mat4::IDENTITY, Material::default());
    // Handed in as a (whole) patch, the first upload gets buffers with spare room.
    let empty = Arc::new(Mesh::default());
    headless
        .renderer_mut()
        .patch_object(0, &empty, &first, &whole_patch)
        .unwrap();
    draw(&mut headless, &scene);
    assert_eq!(
        headless.renderer_mut().mesh_bytes_uploaded(),
        whole_bytes(&first)
    );

    let towards_eye = scene.camera.eye().normalize().as_dvec3();
    let (next, patch) = edit_and_patch(
        &mut object,
        &mut mesher,
        &first,
        visible_edit(0, towards_eye),
    );
    assert!(!patch.full);
    let next = Arc::new(next);
    let mut short = patch.clone();
    short.n_triangles -= 1;
    assert!(matches!(
        headless
            .renderer_mut()
            .patch_object(0, &first, &next, &short),
        Err(render::gpu::PatchError::Lengths { .. })
    ));
    let mut beyond = patch.clone();
    beyond
        .vertex_ranges
        .push(patch.n_vertices..patch.n_vertices + 1);
    assert!(matches!(
        headless
            .renderer_mut()
            .patch_object(0, &first, &next, &beyond),
        Err(render::gpu::PatchError::Range { .. })
    ));
    // A patch said to start from a copy of the uploaded mesh, not the uploaded one: the
    // renderer cannot know what its buffers lack, so it uploads the mesh whole.
    let copy = Arc::new((*first).clone());
    headless
        .renderer_mut()
        .patch_object(0, &copy, &next, &patch)
        .unwrap();
    scene.objects[0].mesh = Arc::clone(&next);
    draw(&mut headless, &scene);
    assert_eq!(
        headless.renderer_mut().mesh_bytes_uploaded(),
        whole_bytes(&next)
    );
    // The next patch, from the uploaded mesh, fits the spare room: only its ranges go up.
    let (last, patch) = edit_and_patch(
        &mut object,
        &mut mesher,
        &next,
        visible_edit(1, towards_eye),
    );
    assert!(!patch.full);
    let last = Arc::new(last);
    headless
        .renderer_mut()
        .patch_object(0, &next, &last, &patch)
        .unwrap();
    scene.objects[0].mesh = Arc::clone(&last);
    draw(&mut headless, &scene);
    let bytes = headless.renderer_mut().mesh_bytes_uploaded();
    assert!(bytes > 0 && 4 * bytes < whole_bytes(&last), "{bytes} bytes");
}

/// One change to a scene.
type SceneEdit = Box<dyn Fn(&mut Scene)>;

/// A scene of `mesh` alone, plain, seen from the default direction 3.2 units away.
fn one_object_scene(mesh: Mesh) -> Scene {
    let mut scene = Scene {
        camera: Camera {
            distance: 3.2,
            ..Camera::default()
        },
        ..Scene::default()
    };
    scene.add_object(Arc::new(mesh), Mat4::IDENTITY, Material::default());
    scene
}

/// The plain ball's mesh, which the octree proves closed.
fn ball_mesh() -> Mesh {
    let (mesher, mesh, _) = meshed(&mut ball());
    assert!(mesher.encloses());
    mesh
}

#[test]
fn a_prepare_says_whether_it_changed_what_a_draw_shows() {
    let Some(mut h) = headless() else {
        return;
    };
    let mesh = Arc::new(ball_mesh());
    let mut scene = Scene::default();
    scene.add_object(Arc::clone(&mesh), Mat4::IDENTITY, Material::default());
    let mut changed = |scene: &Scene| {
        draw(&mut h, scene);
        h.renderer_mut().changed()
    };
    assert!(changed(&scene), "the first prepare draws");
    assert!(!changed(&scene), "the same scene again");
    assert!(!changed(&scene.clone()), "a copy shares the mesh");

    // Each thing a draw shows, changed alone, then asked again unchanged.
    let edits: Vec<(&str, SceneEdit)> = vec![
        ("the camera", Box::new(|s| s.camera.yaw += 0.1)),
        ("the light", Box::new(|s| s.light_towards.x += 0.1)),
        ("the background", Box::new(|s| s.background[0] += 0.1)),
        (
            "the object's place",
            Box::new(|s| {
                s.objects[0].world_from_object *= Mat4::from_scale(glam::Vec3::splat(0.9))
            }),
        ),
        (
            "the object's material",
            Box::new(|s| s.objects[0].material.opacity = 0.5),
        ),
        (
            "a line",
            Box::new(|s| {
                s.lines.push(render::scene::Line {
                    from: glam::Vec3::ZERO,
                    to: glam::Vec3::X,
                    colour: [1.0; 4],
                });
            }),
        ),
        (
            "the mesh, the same triangles in a new allocation",
            Box::new(|s| s.objects[0].mesh = Arc::new((*s.objects[0].mesh).clone())),
        ),
        (
            "the object's closedness",
            Box::new(|s| s.objects[0].closed = !s.objects[0].closed),
        ),
        (
            "one object more",
            Box::new(|s| s.objects.push(s.objects[0].clone())),
        ),
        ("one object less", Box::new(|s| drop(s.objects.pop()))),
    ];
    for (what, edit) in &edits {
        edit(&mut scene);
        assert!(changed(&scene), "{what} changed");
        assert!(!changed(&scene), "{what} unchanged the next time");
    }
}

#[test]
fn a_kept_picture_draws_only_moved_lines_again_and_shows_the_one_pass_picture() {
    let (Some(mut kept), Some(mut one_pass)) = (headless(), headless()) else {
        return;
    };
    let mesh = Arc::new(ball_mesh());
    let mut scene = one_object_scene((*mesh).clone());
    let glass = Material {
        opacity: 0.5,
        ..Material::default()
    };
    let beside =
        Mat4::from_translation(Vec3::new(0.6, 0.3, 0.5)) * Mat4::from_scale(Vec3::splat(0.5));
    scene.add_object(Arc::clone(&mesh), beside, glass);
    // A peer's tool: a cross partly inside the ball, partly behind the glass.
    let tool = |scene: &mut Scene, at: Vec3| {
        scene.lines.clear();
        scene.add_crosshair(at, 0.8, [1.0, 0.2, 0.1, 1.0]);
    };
    let mut picture = kept.kept_picture(WIDTH, HEIGHT).unwrap();
    let mut frame = |scene: &Scene| {
        let (image, kept) = kept.render_kept(scene, &mut picture).unwrap();
        let expected = one_pass.render(scene, WIDTH, HEIGHT).unwrap();
        let n = n_differing_pixels(&image.pixels, &expected.pixels);
        (image.pixels, kept, n)
    };
    tool(&mut scene, Vec3::new(0.9, 0.0, 0.3));
    let (first, kept, n) = frame(&scene);
    assert_eq!(kept, KeptFrame::Whole, "a new picture draws everything");
    assert_eq!(n, 0, "the first frame is the one-pass picture");

    tool(&mut scene, Vec3::new(0.5, 0.4, 0.6));
    let (moved, kept, n) = frame(&scene);
    assert_eq!(
        kept,
        KeptFrame::LinesOnly,
        "only the lines changed: the objects are not drawn again"
    );
    assert_eq!(
        n, 0,
        "moved lines over the kept objects are the one-pass picture"
    );
    assert!(
        n_differing_pixels(&first, &moved) > 50,
        "the lines moved in the picture"
    );
    let (_, kept, n) = frame(&scene);
    assert!(
        kept == KeptFrame::LinesOnly && n == 0,
        "nothing changed: the kept layer again"
    );

    let changes: Vec<(&str, SceneEdit)> = vec![
        ("the camera", Box::new(|s| s.camera.yaw += 0.2)),
        (
            "the glass",
            Box::new(|s| s.objects[1].material.opacity = 0.7),
        ),
        (
            "the ball and the lines together",
            Box::new(move |s| {
                s.objects[0].mesh = Arc::new((*s.objects[0].mesh).clone());
                tool(s, Vec3::new(-0.4, 0.2, 0.9));
            }),
        ),
    ];
    for (what, change) in &changes {
        change(&mut scene);
        let (_, kept, n) = frame(&scene);
        assert_eq!(
            kept,
            KeptFrame::Whole,
            "{what} changed: everything is drawn"
        );
        assert_eq!(n, 0, "{what}: the one-pass picture");
        tool(&mut scene, Vec3::new(0.2, -0.3, 0.7));
        let (_, kept, n) = frame(&scene);
        assert!(
            kept == KeptFrame::LinesOnly && n == 0,
            "then the lines alone over {what}"
        );
    }
}

#[test]
fn a_closed_object_draws_its_two_sided_picture_without_its_back_faces() {
    let Some(mut h) = headless() else {
        return;
    };
    let mesh = ball_mesh();
    let mut scene = one_object_scene(mesh);
    let two_sided = draw(&mut h, &scene);
    scene.objects[0].closed = true;
    let culled = draw(&mut h, &scene);
    assert_eq!(n_differing_pixels(&two_sided, &culled), 0);

    // One triangle facing the eye, wound so that its back is what the eye sees.
    let eye = scene.camera.eye();
    let side = eye.cross(Vec3::Z).normalize();
    let corners = [-side - Vec3::Z, side - Vec3::Z, Vec3::Z].map(|c| 0.5 * c);
    let towards_eye = (corners[1] - corners[0])
        .cross(corners[2] - corners[0])
        .dot(eye)
        > 0.0;
    scene.objects[0].mesh = Arc::new(Mesh {
        positions: corners.map(|c| c.to_array()).to_vec(),
        normals: vec![eye.normalize().to_array(); 3],
        colours: vec![[0.9, 0.2, 0.2, 1.0]; 3],
        ambient: Vec::new(),
        indices: if towards_eye {
            vec![0, 2, 1]
        } else {
            vec![0, 1, 2]
        },
    });
    scene.objects[0].closed = false;
    let shown = draw(&mut h, &scene);
    scene.objects[0].closed = true;
    let hidden = draw(&mut h, &scene);
    let background = &hidden[..4];
    assert!(hidden.chunks_exact(4).all(|p| p == background), "culled");
    assert!(n_differing_pixels(&shown, &hidden) > 100, "drawn two-sided");
}

#[test]
fn objects_keep_their_buffers_when_others_come_or_go_before_them() {
    // The renderer holds buffers by the scene's order; a window orders objects by id, so a
    // new object, or one deleted, moves the others. Each keeps its buffers (nothing but the
    // new mesh goes up), a patch finds its base where it moved, and the picture is a fresh
    // renderer's.
    let (Some(mut h), Some(mut fresh)) = (headless(), headless()) else {
        return;
    };
    let mut object = ball();
    let (mut mesher, first, _) = meshed(&mut object);
    let small = |x: f32, y: f32| {
        Mat4::from_translation(Vec3::new(x, y, 0.0)) * Mat4::from_scale(Vec3::splat(0.3))
    };
    let mut scene = Scene {
        camera: Camera {
            distance: 3.2,
            ..Camera::default()
        },
        ..Scene::default()
    };
    for x in [-1.0, 0.0, 1.0] {
        scene.add_object(Arc::new(first.clone()), small(x, 0.0), Material::default());
    }
    let mut same_as_fresh = |h: &mut Headless, scene: &Scene| {
        let picture = draw(h, scene);
        let bytes = h.renderer_mut().mesh_bytes_uploaded();
        assert_eq!(n_differing_pixels(&picture, &draw(&mut fresh, scene)), 0);
        bytes
    };
    same_as_fresh(&mut h, &scene);
    // The last object patched in place: its first patch outgrows the exact buffers of its
    // first upload, which it replaces with room to spare.
    let mut patch_last = |scene: &mut Scene, h: &mut Headless, k: usize| {
        let last = scene.objects.len() - 1;
        let base = Arc::clone(&scene.objects[last].mesh);
        let (next, patch) =
            edit_and_patch(&mut object, &mut mesher, &base, visible_edit(k, DVec3::Z));
        let next = Arc::new(next);
        h.renderer_mut()
            .patch_object(last, &base, &next, &patch)
            .unwrap();
        scene.objects[last].mesh = Arc::clone(&next);
        scene.objects[last].pick_runs = Default::default();
        scene.objects[last].pick_runs.prepare(&next);
        next
    };
    let next = patch_last(&mut scene, &mut h, 0);
    assert_eq!(same_as_fresh(&mut h, &scene), whole_bytes(&next));
    // A new object first in the order: only its mesh goes up.
    let newcomer = Arc::new(ball_mesh());
    let mut with_new = scene.clone();
    with_new.add_object(Arc::clone(&newcomer), small(0.0, 0.9), Material::default());
    with_new.objects.rotate_right(1);
    assert_eq!(same_as_fresh(&mut h, &with_new), whole_bytes(&newcomer));
    // The last object's next patch, handed in at its new place, finds its base there: the
    // patch alone goes up.
    let next = patch_last(&mut with_new, &mut h, 2);
    let bytes = same_as_fresh(&mut h, &with_new);
    assert!(bytes > 0 && bytes < whole_bytes(&next), "{bytes}");
    // The newcomer goes again: nothing goes up.
    with_new.objects.remove(0);
    assert_eq!(same_as_fresh(&mut h, &with_new), 0);
}
