//! Pictures of a whole [`model::scene::Scene`] (for example one read from an FVRML file by
//! `formats::fvrml::load`): every object meshed, coloured and placed, drawn offscreen from a
//! camera that frames the scene, once per [`View`]. The `sculpt render` command is a thin
//! wrapper around [`snapshot`].
//!
//! How each object becomes triangles, at scene time `t`:
//! - implicit geometry (and union edits, on any geometry) through [`ObjectField`] and the
//!   octree mesher at [`SnapshotSettings::depth`], inside [`mesh_bounds`] (the domain and
//!   the union edits); a solid without a domain is unbounded and is skipped with a reason;
//! - parametric geometry by [`parametric`]: surfaces triangulated over their (u, v) ranges,
//!   curves as tubes, solids as the six faces of their (u, v, w) box;
//! - an imported mesh as it is (through the field instead when edits change its shape).
//!
//! Then the appearance is applied ([`CompiledAppearance`]; painted colours come from fdsl's
//! `Sampler`), and the object is placed by the object model's one rule,
//! `model::scene::world_from_object` (its own transform and motion at `t`, then its groups'
//! transforms). Scenes are +y up (VRML); the renderer's world is +z up, so the whole scene
//! is turned by [`render_from_scene`]. Force fields can be drawn as arrows sampled on a grid
//! inside their container (see [`SnapshotSettings::force_arrows`]).
//!
//! Objects that cannot be drawn are listed in [`Built::objects`] with the reason, never a
//! panic; only bad settings and GPU failures are errors.

use std::sync::Arc;

use glam::{DAffine3, DMat4, DVec3, Mat4, Vec3};
use model::object::{CompiledEdit, EditOp, Object, ParametricKind, Shape, Slot};
use model::scene::ObjectId;

use crate::appearance::CompiledAppearance;
use crate::camera::Camera;
use crate::gpu::offscreen::{Headless, MAX_OFFSCREEN_SIDE, OffscreenError};
use crate::mesh::object_field::mesh_bounds;
use crate::mesh::octree::{MAX_OCTREE_DEPTH, MeshSettings, mesh_on_threads};
use crate::mesh::parametric::{
    self, SurfaceSettings, TubeSettings, UvDomain, triangulate_surface, tube,
};
use crate::mesh::{Aabb, Mesh, ObjectField};
use crate::scene::{Line, Material, Scene};
use plot::image::RgbaImage;

/// Most views one snapshot may ask for.
pub const MAX_VIEWS: usize = 16;
/// Most force-field arrows along each axis of a field's domain.
pub const MAX_ARROWS_PER_AXIS: u32 = 32;
/// Most vertices of one parametric surface or face.
pub const MAX_PARAMETRIC_VERTICES_PER_OBJECT: usize = 200_000;
/// Opacity at most of an object whose force field is drawn, so the arrows inside show.
pub const MAX_FORCE_CONTAINER_OPACITY: f32 = 0.35;
/// Colour of force-field arrows.
pub const FORCE_ARROW_COLOUR: [f32; 4] = [1.0, 0.75, 0.1, 1.0];
/// Imported meshes are drawn flat across edges whose faces meet at more than this angle
/// (degrees), smooth across gentler ones (`Mesh::split_creases`).
pub const CREASE_DEGREES: f32 = 40.0;

/// A named camera direction around the scene's centre.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// A short name, used in file names (letters, digits, `-` and `_`).
    pub name: String,
    /// Rotation about the vertical axis, radians; 0 looks along the scene's -z (VRML's
    /// default view).
    pub yaw: f32,
    /// Elevation, radians; positive looks down.
    pub pitch: f32,
}

impl View {
    /// The two default views: from the front, and from above the +x +y +z corner.
    pub fn defaults() -> Vec<View> {
        vec![
            View {
                name: "front".into(),
                yaw: 0.0,
                pitch: 0.3,
            },
            View {
                name: "corner".into(),
                yaw: 0.78,
                pitch: 0.6,
            },
        ]
    }
}

/// How to picture a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct SnapshotSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Octree depth for implicit objects: 2^depth cells along each axis of an object's box.
    pub depth: u8,
    /// Scene time in seconds (motions, time-dependent shapes and colours).
    pub t_secs: f64,
    /// The views, one picture each.
    pub views: Vec<View>,
    /// Arrows per axis of each enabled force field's domain (0: no arrows). Only arrows
    /// inside the container are drawn, and the container is drawn at most
    /// [`MAX_FORCE_CONTAINER_OPACITY`] opaque so that they show (as the thesis's Figure 7.3
    /// shows its whirlpool field in a transparent cylinder).
    pub force_arrows: u32,
    /// Threads one object's mesh may run on (see
    /// [`OctreeMesher::remesh_parallel`](crate::mesh::octree::OctreeMesher::remesh_parallel));
    /// one by default, [`crate::mesher::remesh_threads`] for a command line's or a window's
    /// share of the cores.
    pub mesh_threads: usize,
}

impl Default for SnapshotSettings {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            depth: 7,
            t_secs: 0.0,
            views: View::defaults(),
            force_arrows: 7,
            mesh_threads: 1,
        }
    }
}

/// One picture: the view's name and the image.
pub type ViewImage = (String, RgbaImage);

/// Why no picture could be made.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// A setting is out of range; the message names it.
    #[error("bad snapshot setting: {0}")]
    BadSetting(&'static str),
    /// Offscreen rendering failed (no adapter, device, readback).
    #[error(transparent)]
    Offscreen(#[from] OffscreenError),
}

/// What became of one object of the scene.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectReport {
    /// The object's id.
    pub id: ObjectId,
    /// Its name.
    pub name: String,
    /// Triangles drawn.
    pub n_triangles: usize,
    /// Force-field arrows drawn.
    pub n_arrows: usize,
    /// Why the object (or part of it) is not drawn, if so.
    pub skipped: Option<String>,
}

/// A scene ready to draw: the renderer's scene (camera not yet aimed) and what was drawn.
#[derive(Clone, Debug)]
pub struct Built {
    /// Objects and lines, in the renderer's +z-up world.
    pub scene: Scene,
    /// One report per scene object, by id.
    pub objects: Vec<ObjectReport>,
    /// The box around everything drawn, renderer world; `None` when nothing is.
    pub bounds: Option<Aabb>,
    /// A sphere around everything drawn (centre, radius), renderer world: the box's centre
    /// and the farthest vertex or line end from it. Cameras frame it.
    pub sphere: Option<(Vec3, f32)>,
}

/// The turn from scene space (+y up, VRML) into the renderer's world (+z up): x stays, y
/// becomes z, z becomes -y.
pub fn render_from_scene() -> Mat4 {
    Mat4::from_rotation_x(std::f32::consts::FRAC_PI_2)
}

pub(crate) fn check(settings: &SnapshotSettings) -> Result<(), SnapshotError> {
    let side_ok = |s: u32| (1..=MAX_OFFSCREEN_SIDE).contains(&s);
    if !(side_ok(settings.width) && side_ok(settings.height)) {
        return Err(SnapshotError::BadSetting("image size out of range"));
    }
    if settings.depth > MAX_OCTREE_DEPTH {
        return Err(SnapshotError::BadSetting("octree depth above the maximum"));
    }
    if !settings.t_secs.is_finite() {
        return Err(SnapshotError::BadSetting("time is not finite"));
    }
    if settings.views.is_empty() || settings.views.len() > MAX_VIEWS {
        return Err(SnapshotError::BadSetting("1 to MAX_VIEWS views"));
    }
    let name_ok = |v: &View| {
        !v.name.is_empty()
            && v.name.len() <= 64
            && v.name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
            && v.yaw.is_finite()
            && v.pitch.is_finite()
    };
    if !settings.views.iter().all(name_ok) {
        return Err(SnapshotError::BadSetting(
            "view names must be short, of letters, digits, - and _, with finite angles",
        ));
    }
    if settings.force_arrows > MAX_ARROWS_PER_AXIS {
        return Err(SnapshotError::BadSetting(
            "force arrows per axis above the maximum",
        ));
    }
    Ok(())
}

/// Meshes, colours and places every object of `scene` (see the module documentation).
pub fn build(
    scene: &model::scene::Scene,
    settings: &SnapshotSettings,
) -> Result<Built, SnapshotError> {
    check(settings)?;
    let mut built = Built {
        scene: Scene::default(),
        objects: Vec::new(),
        bounds: None,
        sphere: None,
    };
    let turn = render_from_scene();
    for (id, entry) in scene.objects() {
        let object = &entry.object;
        let mut sampler = object.sampler();
        let scene_from_object = model::scene::world_from_object(
            &scene.world_from_group(entry.group),
            &mut sampler,
            settings.t_secs,
        );
        let world_from_object = turn * to_mat4(scene_from_object.parent_from_child);
        let ObjectMesh { mesh, skipped, .. } = object_mesh(
            object,
            settings.depth,
            settings.t_secs,
            settings.mesh_threads,
        );
        let mut report = ObjectReport {
            id,
            name: object.data().name.clone(),
            n_triangles: mesh.n_triangles(),
            n_arrows: 0,
            skipped: None,
        };
        if settings.force_arrows > 0 {
            let lines = force_arrows(
                &mut sampler,
                settings.force_arrows,
                settings.t_secs,
                world_from_object,
            );
            report.n_arrows = lines.len() / 5;
            built.scene.lines.extend(lines);
        }
        if mesh.n_triangles() > 0 {
            let mut appearance = CompiledAppearance::of(object);
            let (mesh, mut material) = colour(object, &mut appearance, mesh, settings.t_secs);
            if report.n_arrows > 0 {
                material.opacity = material.opacity.min(MAX_FORCE_CONTAINER_OPACITY);
            }
            built
                .scene
                .add_object(Arc::new(mesh), world_from_object, material);
        }
        report.skipped = skipped;
        built.objects.push(report);
    }
    built.bounds = world_bounds(&built.scene);
    built.sphere = built.bounds.map(|b| {
        let centre = Vec3::from_array(b.centre());
        (centre, farthest_from(&built.scene, centre))
    });
    Ok(built)
}

/// `scene` framed for each view of `settings` and drawn on `gpu`, one image per view.
pub fn draw(
    gpu: &mut Headless,
    built: &Built,
    settings: &SnapshotSettings,
) -> Result<Vec<ViewImage>, SnapshotError> {
    check(settings)?;
    let mut scene = built.scene.clone();
    let mut images = Vec::with_capacity(settings.views.len());
    for view in &settings.views {
        scene.camera = frame(built.sphere, view, settings.width, settings.height);
        let image = gpu.render(&scene, settings.width, settings.height)?;
        images.push((view.name.clone(), image));
    }
    Ok(images)
}

/// Builds `scene` and draws every view on a fresh headless device: `(view name, image)`
/// pairs, in the order of `settings.views`, and the report of each object.
pub fn snapshot(
    scene: &model::scene::Scene,
    settings: &SnapshotSettings,
) -> Result<(Vec<ViewImage>, Vec<ObjectReport>), SnapshotError> {
    let built = build(scene, settings)?;
    let mut gpu = Headless::new()?;
    let images = draw(&mut gpu, &built, settings)?;
    Ok((images, built.objects))
}

/// A camera looking at the centre of `sphere` (centre, radius) from `view`'s direction, far
/// enough that the sphere fits the narrower field of view of a `width` x `height` picture.
pub fn frame(sphere: Option<(Vec3, f32)>, view: &View, width: u32, height: u32) -> Camera {
    let Some((centre, radius)) = sphere else {
        return Camera {
            yaw: view.yaw,
            pitch: view.pitch,
            ..Camera::default()
        };
    };
    let radius = radius.max(1e-3);
    let fov_y = Camera::default().fov_y;
    let aspect = width.max(1) as f32 / height.max(1) as f32;
    let half_x = (aspect * (0.5 * fov_y).tan()).atan();
    let half = half_x.min(0.5 * fov_y);
    let distance = 1.05 * radius / half.sin();
    Camera {
        target: centre,
        yaw: view.yaw,
        pitch: view.pitch,
        distance,
        fov_y,
        near: (distance - 1.5 * radius).max(1e-3 * distance),
        far: distance + 2.0 * radius,
    }
}

pub(crate) fn to_mat4(m: DAffine3) -> Mat4 {
    DMat4::from(m).as_mat4()
}

/// Whether `object` has active edits that change its shape.
fn has_shape_edits(object: &Object) -> bool {
    object
        .history()
        .entries()
        .iter()
        .any(|e| e.active && e.edit.is_geometric())
}

/// Whether `edit` paints colour.
pub(crate) fn is_colour_paint(edit: &CompiledEdit) -> bool {
    matches!(
        edit.edit().op,
        EditOp::Paint {
            property: model::object::Paintable::Color,
            ..
        }
    )
}

/// Whether `object` has active colour paintings.
fn has_colour_paint(object: &Object) -> bool {
    object
        .history()
        .entries()
        .iter()
        .any(|e| e.active && is_colour_paint(&e.edit))
}

/// An object's triangles in object space, before its appearance.
pub(crate) struct ObjectMesh {
    pub(crate) mesh: Mesh,
    /// Why (part of) the object is not drawn.
    pub(crate) skipped: Option<String>,
    /// Octree blocks evaluated (0 for parametric and imported shapes).
    pub(crate) blocks_evaluated: usize,
}

/// The object's triangles in object space at `depth` and time `t_secs`.
pub(crate) fn object_mesh(object: &Object, depth: u8, t_secs: f64, threads: usize) -> ObjectMesh {
    let geometry = object.data().geometry.as_ref();
    let mut out = Mesh::default();
    let mut skipped = None;
    let field_part = match geometry.map(|g| &g.shape) {
        Some(Shape::Implicit(_)) => true,
        Some(Shape::Mesh(_)) => has_shape_edits(object),
        Some(Shape::Parametric { .. }) | None => has_union_edits(object),
    };
    if let Some(g) = geometry {
        let part = match &g.shape {
            Shape::Parametric {
                kind, parameters, ..
            } => match object.tape(Slot::Geometry) {
                Some(tape) => parametric_mesh(tape, *kind, parameters, t_secs),
                None => Err("a parametric shape without its compiled x, y, z".into()),
            },
            Shape::Mesh(m) if !field_part => {
                Ok(tri_mesh(m, object.data().appearance.displacement.is_none()))
            }
            _ => Ok(Mesh::default()),
        };
        match part {
            Ok(mut m) => {
                transform_mesh(&mut m, g.transform.parent_from_child);
                append(&mut out, &m, &mut skipped);
            }
            Err(reason) => skipped = Some(reason),
        }
    }
    let mut blocks_evaluated = 0;
    if field_part {
        match mesh_bounds(object, depth) {
            Some(bounds) => {
                let meshed = mesh_on_threads(
                    &mut ObjectField::new(object, t_secs),
                    &MeshSettings { bounds, depth },
                    threads,
                );
                match meshed {
                    Ok((m, stats)) => {
                        blocks_evaluated = stats.blocks_evaluated;
                        append(&mut out, &m, &mut skipped);
                    }
                    Err(e) => skipped = Some(e.to_string()),
                }
            }
            None => skipped = Some(model::object::FitError::Unbounded.to_string()),
        }
    }
    ObjectMesh {
        mesh: out,
        skipped,
        blocks_evaluated,
    }
}

fn has_union_edits(object: &Object) -> bool {
    object
        .history()
        .entries()
        .iter()
        .any(|e| e.active && matches!(e.edit.edit().op, EditOp::Union))
}

fn append(out: &mut Mesh, m: &Mesh, skipped: &mut Option<String>) {
    if let Err(e) = out.append(m) {
        *skipped = Some(e.to_string());
    }
}

/// An imported mesh with normals from its faces.
/// An imported mesh's triangles with faceted normals: split at creases sharper than
/// [`CREASE_DEGREES`] (a polygon model's box keeps its edges) unless a displacement will move
/// its vertices, which would crack it there.
fn tri_mesh(m: &model::mesh::TriMesh, faceted: bool) -> Mesh {
    let mut out = Mesh {
        positions: m.positions().to_vec(),
        indices: m.triangles().iter().flatten().copied().collect(),
        ..Mesh::default()
    };
    if faceted {
        out.split_creases(CREASE_DEGREES);
    } else {
        out.recompute_normals();
    }
    out.colours = vec![[1.0; 4]; out.n_vertices()];
    out
}

/// Maps positions by `m` and normals by its inverse transpose.
fn transform_mesh(mesh: &mut Mesh, m: DAffine3) {
    if m == DAffine3::IDENTITY {
        return;
    }
    let normal_matrix = m.matrix3.inverse().transpose();
    for p in &mut mesh.positions {
        let q = m.transform_point3(DVec3::from_array(p.map(f64::from)));
        *p = q.to_array().map(|c| c as f32);
    }
    for n in &mut mesh.normals {
        let q = (normal_matrix * DVec3::from_array(n.map(f64::from))).normalize_or_zero();
        *n = q.to_array().map(|c| c as f32);
    }
    if m.matrix3.determinant() < 0.0 {
        // A mirror turns the winding inside out.
        for t in mesh.indices.chunks_exact_mut(3) {
            t.swap(1, 2);
        }
    }
}

/// Triangulates a parametric shape, whose compiled outputs `x`, `y`, `z` are `tape`, at time
/// `t` in its geometry space.
fn parametric_mesh(
    tape: &fdsl::Tape,
    kind: ParametricKind,
    parameters: &[[f64; 2]; 3],
    t: f64,
) -> Result<Mesh, String> {
    let mut eval = fdsl::eval::PointEval::new(tape);
    let mut xyz = [0.0f64; 3];
    let mut at = |uvw: [f64; 3]| -> [f32; 3] {
        eval.eval_all([uvw[0], uvw[1], uvw[2], t], &mut xyz);
        xyz.map(|c| if c.is_finite() { c as f32 } else { 0.0 })
    };
    let range = |i: usize| (parameters[i][0] as f32, parameters[i][1] as f32);
    // The size of the shape sets tolerances and the tube radius.
    let diagonal = sampled_diagonal(&mut at, kind.dimensions(), parameters);
    let white = |_: [f32; 2], _: [f32; 3]| [1.0f32; 4];
    let surface_settings = |u: (f32, f32), v: (f32, f32)| SurfaceSettings {
        domain: UvDomain { u, v },
        initial_divisions: 16,
        tolerance: 1e-3 * diagonal,
        vertices_max: MAX_PARAMETRIC_VERTICES_PER_OBJECT / 6,
    };
    let err = |e: parametric::ParametricError| format!("parametric {kind:?}: {e}");
    match kind {
        ParametricKind::Curve => tube(
            |u| at([f64::from(u), 0.0, 0.0]),
            |_, _| [1.0; 4],
            &TubeSettings {
                domain: range(0),
                radius: 0.01 * diagonal,
                n_sides: 12,
                initial_divisions: 32,
                tolerance: 1e-3 * diagonal,
                samples_max: 20_000,
            },
        )
        .map_err(err),
        ParametricKind::Surface => triangulate_surface(
            |[u, v]| at([f64::from(u), f64::from(v), 0.0]),
            white,
            &surface_settings(range(0), range(1)),
        )
        .map_err(err),
        ParametricKind::Solid => {
            // The boundary: the images of the six faces of the (u, v, w) box.
            let mut out = Mesh::default();
            for fixed in 0..3 {
                let (a, b) = ((fixed + 1) % 3, (fixed + 2) % 3);
                for &c in &parameters[fixed] {
                    let face = triangulate_surface(
                        |uv| {
                            let mut uvw = [0.0; 3];
                            uvw[fixed] = c;
                            uvw[a] = f64::from(uv[0]);
                            uvw[b] = f64::from(uv[1]);
                            at(uvw)
                        },
                        white,
                        &surface_settings(range(a), range(b)),
                    )
                    .map_err(err)?;
                    out.append(&face).map_err(|e| e.to_string())?;
                }
            }
            Ok(out)
        }
    }
}

/// The diagonal of the box around `at` sampled on a coarse grid over the first `dims`
/// parameter ranges (at least 1e-3, so that tolerances derived from it stay positive).
fn sampled_diagonal(
    at: &mut impl FnMut([f64; 3]) -> [f32; 3],
    dims: usize,
    parameters: &[[f64; 2]; 3],
) -> f32 {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    let n = 8;
    for i in 0..(n + 1usize).pow(dims as u32) {
        let mut uvw = [0.0f64; 3];
        let mut rest = i;
        for (a, c) in uvw.iter_mut().enumerate().take(dims) {
            let s = (rest % (n + 1)) as f64 / n as f64;
            rest /= n + 1;
            *c = parameters[a][0] + s * (parameters[a][1] - parameters[a][0]);
        }
        let p = at(uvw);
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (0..3)
        .map(|a| (hi[a] - lo[a]).powi(2))
        .sum::<f32>()
        .sqrt()
        .max(1e-3)
}

/// Applies the object's compiled appearance at time `t`: vertex colours (painted ones from
/// the sampler), alpha, displacement, and the material.
pub(crate) fn colour(
    object: &Object,
    appearance: &mut CompiledAppearance,
    mut mesh: Mesh,
    t: f64,
) -> (Mesh, Material) {
    colour_vertices(object, appearance, &mut mesh, t);
    let material = appearance.material(&mesh, t as f32, Material::default());
    (mesh, material)
}

/// Sets every vertex's colour, ambient colour and alpha (and displaces it) from the object's
/// compiled appearance at time `t`, then the colours painted on the object from the sampler.
/// The one colouring of object meshes: the incremental mesher colours the vertices a patch
/// wrote through it, so a patched mesh has the colours a whole one would.
pub(crate) fn colour_vertices(
    object: &Object,
    appearance: &mut CompiledAppearance,
    mesh: &mut Mesh,
    t: f64,
) {
    appearance.apply(mesh, t as f32);
    if has_colour_paint(object) {
        let mut sampler = object.sampler();
        for (p, c) in mesh.positions.iter().zip(mesh.colours.iter_mut()) {
            let rgb = sampler.diffuse(DVec3::from_array(p.map(f64::from)), t);
            c[..3].copy_from_slice(&rgb);
        }
    }
}

/// Arrows of the object's force field (if enabled) at time `t_secs`, at the centres of a grid
/// of cubic cells over its domain (`per_axis` cells along the longest side), where the
/// container holds the point; mapped by `world_from_object`. The longest arrow is 0.8 cells
/// long. Each arrow is five lines (see [`Scene::add_arrow`]).
pub fn force_arrows(
    sampler: &mut model::object::Sampler,
    per_axis: u32,
    t_secs: f64,
    world_from_object: Mat4,
) -> Vec<Line> {
    let enabled = sampler
        .object()
        .data()
        .physics
        .force
        .as_ref()
        .is_some_and(|f| f.enabled);
    if !enabled {
        return Vec::new();
    }
    let t = t_secs;
    let per_axis = per_axis.clamp(1, MAX_ARROWS_PER_AXIS);
    let (domain, object_from_field) = sampler.field_domain();
    // Cubic grid cells: `force_arrows` along the domain's longest side, fewer along the others.
    let step = domain.size.max_element() / f64::from(per_axis);
    let counts = domain
        .size
        .to_array()
        .map(|s| ((s / step).round() as u32).clamp(1, per_axis));
    let mut arrows: Vec<(DVec3, DVec3)> = Vec::new();
    for k in 0..counts.iter().product::<u32>() {
        let cell = [
            k % counts[0],
            (k / counts[0]) % counts[1],
            k / (counts[0] * counts[1]),
        ];
        let s: [f64; 3] =
            std::array::from_fn(|a| (f64::from(cell[a]) + 0.5) / f64::from(counts[a]));
        let local = domain.center + (DVec3::from_array(s) - 0.5) * domain.size;
        let p = object_from_field.point(local);
        if sampler.container_value(p, t) < 0.0 {
            continue;
        }
        if let Some(f) = sampler.force(p, t).filter(|f| f.is_finite()) {
            arrows.push((p, f));
        }
    }
    let longest = arrows.iter().map(|(_, f)| f.length()).fold(0.0, f64::max);
    if longest <= 0.0 {
        return Vec::new();
    }
    let scale = 0.8 * step / longest;
    let mut scene = Scene::default();
    for (p, f) in arrows {
        let from = world_from_object.transform_point3(p.as_vec3());
        let to = world_from_object.transform_point3((p + f * scale).as_vec3());
        scene.add_arrow(from, to, FORCE_ARROW_COLOUR);
    }
    scene.lines
}

/// The largest distance from `centre` to a vertex or line end of `scene`.
pub(crate) fn farthest_from(scene: &Scene, centre: Vec3) -> f32 {
    let mut r2 = 0.0f32;
    for o in &scene.objects {
        for p in &o.mesh.positions {
            let w = o.world_from_object.transform_point3(Vec3::from_array(*p));
            r2 = r2.max((w - centre).length_squared());
        }
    }
    for l in &scene.lines {
        r2 = r2
            .max((l.from - centre).length_squared())
            .max((l.to - centre).length_squared());
    }
    r2.sqrt()
}

/// The world box around every object's vertices and every line.
pub(crate) fn world_bounds(scene: &Scene) -> Option<Aabb> {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for o in &scene.objects {
        if let Some(b) = o.mesh.bounds() {
            for k in 0..8usize {
                let c = Vec3::from_array(std::array::from_fn(|a| {
                    if k >> a & 1 == 1 { b.hi[a] } else { b.lo[a] }
                }));
                let w = o.world_from_object.transform_point3(c);
                lo = lo.min(w);
                hi = hi.max(w);
            }
        }
    }
    for l in &scene.lines {
        lo = lo.min(l.from).min(l.to);
        hi = hi.max(l.from).max(l.to);
    }
    (lo.is_finite() && hi.is_finite()).then(|| Aabb::new(lo.to_array(), hi.to_array()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use formats::fvrml::{LoadOptions, load};

    fn load_text(text: &str) -> model::scene::Scene {
        let mut no_files = |path: &str| Err(format!("no file {path}"));
        load(text, &LoadOptions::default(), &mut no_files)
            .unwrap()
            .scene
    }

    fn small() -> SnapshotSettings {
        SnapshotSettings {
            depth: 5,
            ..SnapshotSettings::default()
        }
    }

    #[test]
    fn kinds_of_geometry_become_triangles_and_unbounded_ones_are_reported() {
        let scene = load_text(
            r#"
            DEF Ball FShape { geometry FGeometry { definition "1-x^2-y^2-z^2" bboxSize 2 2 2 } }
            DEF Sheet FShape { geometry FGeometry {
                definition "x = u; y = v; z = 0.2*sin(3*u);" parameters [0 1 0 1] } }
            DEF Helix FShape { geometry FGeometry {
                definition "x = cos(6*u); y = u; z = sin(6*u);" parameters [0 2] } }
            DEF Brick FShape { geometry FGeometry {
                definition "x = u; y = v; z = w;" parameters [0 1 0 1 0 0.5] } }
            DEF Everywhere FShape { geometry FGeometry { definition "0" } }
            DEF Moved Transform { translation 5 0 0 children [
                FShape { geometry Box { size 1 1 1 } } ] }
            "#,
        );
        let built = build(&scene, &small()).unwrap();
        let by_name = |name: &str| built.objects.iter().find(|o| o.name == name).unwrap();
        for name in ["Ball", "Sheet", "Helix", "Brick"] {
            let o = by_name(name);
            assert!(o.n_triangles > 100 && o.skipped.is_none(), "{o:?}");
        }
        let everywhere = by_name("Everywhere");
        assert_eq!(everywhere.n_triangles, 0);
        assert!(everywhere.skipped.as_deref().unwrap().contains("unbounded"));
        // The helix is a closed tube; the ball is closed.
        for o in &built.scene.objects {
            assert_eq!(o.mesh.validate(), Ok(()));
        }
        // The box moved by its group to x = 5 (scene), which stays x = 5 in the turned world.
        let b = built.bounds.unwrap();
        assert!(b.hi[0] > 5.4 && b.lo[0] < -0.9, "{b:?}");
        // Scene +y (the helix's axis, up to 2) is the world's +z.
        assert!(b.hi[2] > 1.9 && b.hi[2] < 2.2, "{b:?}");
    }

    #[test]
    fn force_fields_become_arrows_inside_their_container() {
        let text = include_str!("../../tests/data/scenes/figure_7_4.wrl");
        let scene = load_text(text);
        let settings = SnapshotSettings {
            force_arrows: 5,
            ..small()
        };
        let built = build(&scene, &settings).unwrap();
        assert_eq!(built.objects.len(), 1);
        let o = &built.objects[0];
        // 5 x 1 x 5 cubic cells over the 3.2 x 0.7 x 3.2 box, of which those inside the
        // cylinder of radius 1.6: the four corners lie outside it.
        assert_eq!(o.n_arrows, 21, "{o:?}");
        assert!(built.scene.objects[0].material.opacity <= MAX_FORCE_CONTAINER_OPACITY);
        // The field turns about the vertical axis: at scene (x, z) it points along about
        // (z, -x), whose world form is (z_scene, x_scene) turned; check one arrow's shaft
        // is horizontal-ish and perpendicular to its radius.
        let shaft = built.scene.lines[0];
        let r = Vec3::new(shaft.from.x, shaft.from.y, 0.0);
        let d = shaft.to - shaft.from;
        assert!(d.dot(r).abs() <= 0.5 * d.length() * r.length(), "{shaft:?}");
        let none = build(
            &scene,
            &SnapshotSettings {
                force_arrows: 0,
                ..small()
            },
        )
        .unwrap();
        assert!(none.scene.lines.is_empty());
        assert_eq!(none.scene.objects[0].material.opacity, 1.0);
    }

    #[test]
    fn shapes_of_time_are_meshed_at_the_settings_time() {
        let scene = load_text(
            r#"DEF Pulse FShape { geometry FGeometry {
                definition "0.3+0.2*t-sqrt(x^2+y^2+z^2)" bboxSize 2 2 2 } }"#,
        );
        let width_at = |t_secs| {
            let built = build(&scene, &SnapshotSettings { t_secs, ..small() }).unwrap();
            built.bounds.unwrap().size()[0]
        };
        let (w0, w2) = (width_at(0.0), width_at(2.0));
        assert!(
            (w0 - 0.6).abs() < 0.05 && (w2 - 1.4).abs() < 0.05,
            "{w0} {w2}"
        );
    }

    #[test]
    fn bad_settings_are_errors() {
        let scene = model::scene::Scene::new();
        for s in [
            SnapshotSettings {
                width: 0,
                ..small()
            },
            SnapshotSettings {
                depth: 11,
                ..small()
            },
            SnapshotSettings {
                views: Vec::new(),
                ..small()
            },
            SnapshotSettings {
                views: vec![View {
                    name: "../x".into(),
                    yaw: 0.0,
                    pitch: 0.0,
                }],
                ..small()
            },
            SnapshotSettings {
                t_secs: f64::NAN,
                ..small()
            },
        ] {
            assert!(matches!(
                build(&scene, &s),
                Err(SnapshotError::BadSetting(_))
            ));
        }
        let empty = build(&scene, &small()).unwrap();
        assert!(empty.objects.is_empty() && empty.bounds.is_none());
    }

    #[test]
    fn framing_fits_the_bounds_in_view() {
        let b = Aabb::new([-1.0, -2.0, 0.0], [3.0, 2.0, 1.0]);
        let sphere = (
            Vec3::from_array(b.centre()),
            0.5 * Vec3::from_array(b.size()).length(),
        );
        for view in View::defaults() {
            let camera = frame(Some(sphere), &view, 320, 200);
            for k in 0..8usize {
                let c = Vec3::from_array(std::array::from_fn(|a| {
                    if k >> a & 1 == 1 { b.hi[a] } else { b.lo[a] }
                }));
                let px = camera.project(c, [320, 200]).unwrap();
                assert!(
                    (0.0..=320.0).contains(&px[0]) && (0.0..=200.0).contains(&px[1]),
                    "{c} at {px:?}"
                );
            }
        }
    }
}
