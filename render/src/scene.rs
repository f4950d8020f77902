//! What to draw: objects (meshes with materials and transforms), lines (boxes such as the
//! haptic zone, arrows such as force-field vectors, crosshair cursors, tool avatars), camera
//! and light.

use crate::camera::{Camera, Ray};
use crate::mesh::octree::MeshPatch;
use crate::mesh::{Aabb, Mesh};
use glam::{Mat4, Vec3};
use model::object::{Pose, ToolShape};
use std::sync::{Arc, OnceLock, Weak};

/// How a surface reflects light; multiplies the per-vertex colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Ambient weight 0..1.
    pub ambient: f32,
    /// Diffuse (Lambert) weight 0..1.
    pub diffuse: f32,
    /// Specular (Blinn-Phong) weight 0..1.
    pub specular: f32,
    /// Specular exponent: larger is shinier.
    pub shininess: f32,
    /// Opacity 0..1 multiplied into the vertex alpha; below 1 the object is drawn transparent.
    pub opacity: f32,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            ambient: 0.2,
            diffuse: 0.75,
            specular: 0.3,
            shininess: 32.0,
            opacity: 1.0,
        }
    }
}

impl Material {
    /// Whether the object needs the transparent pass.
    pub fn is_transparent(&self) -> bool {
        self.opacity < 1.0
    }
}

/// One drawable object.
#[derive(Clone, Debug)]
pub struct SceneObject {
    /// The mesh in object space; shared so that unchanged meshes are not uploaded again.
    pub mesh: Arc<Mesh>,
    /// World from object.
    pub world_from_object: Mat4,
    /// Lighting parameters.
    pub material: Material,
    /// The mesh encloses its solid and winds counter-clockwise seen from outside, so its back
    /// faces are hidden from any eye outside it and are not drawn (a software rasteriser then
    /// shades about half the triangles). False draws both sides (open surfaces, imported
    /// meshes, and anything not proven closed).
    pub closed: bool,
    /// Where a pick looks among the mesh's triangles, made by the first pick and shared by
    /// the object's clones.
    pub pick_runs: PickRuns,
}

/// Triangles a pick takes together: a ray tests a run's triangles only when it meets the
/// box around them (an octree's mesh keeps each block's triangles together).
pub const PICK_RUN_TRIANGLES: usize = 64;

/// Boxes around a mesh's runs of [`PICK_RUN_TRIANGLES`] triangles (in index order) and
/// around all of them, made once per mesh; clones share them. They name the mesh they were
/// made for (a weak reference: its allocation, so its address, outlives it, but not its
/// buffers), so an object given another mesh never reads the boxes of the old one.
#[derive(Clone, Default)]
pub struct PickRuns(Arc<OnceLock<RunBoxes>>);

/// Says how many runs were made, not the mesh they hold.
impl std::fmt::Debug for PickRuns {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n_runs = self.0.get().map(|b| b.runs.len());
        f.debug_struct("PickRuns").field("n_runs", &n_runs).finish()
    }
}

struct RunBoxes {
    mesh: Weak<Mesh>,
    /// Around every valid triangle.
    all: Option<Aabb>,
    /// One per run; `None` for a run without a valid triangle.
    runs: Vec<Option<Aabb>>,
}

impl RunBoxes {
    fn made_for(&self, mesh: &Arc<Mesh>) -> bool {
        std::ptr::eq(self.mesh.as_ptr(), Arc::as_ptr(mesh))
    }

    fn of(mesh: &Arc<Mesh>) -> RunBoxes {
        let n_runs = mesh.n_triangles().div_ceil(PICK_RUN_TRIANGLES);
        RunBoxes::from_runs(mesh, (0..n_runs).map(|k| run_box(mesh, k)).collect())
    }

    fn from_runs(mesh: &Arc<Mesh>, runs: Vec<Option<Aabb>>) -> RunBoxes {
        let all = runs.iter().flatten().copied().reduce(|a, b| a.union(&b));
        RunBoxes {
            mesh: Arc::downgrade(mesh),
            all,
            runs,
        }
    }
}

/// The box around run `k`'s valid triangles (those whose corners are all vertices), `None`
/// when it has none.
fn run_box(mesh: &Mesh, k: usize) -> Option<Aabb> {
    let n = mesh.positions.len();
    let start = (3 * PICK_RUN_TRIANGLES * k).min(mesh.indices.len());
    let end = (start + 3 * PICK_RUN_TRIANGLES).min(mesh.indices.len());
    let valid = mesh.indices[start..end]
        .chunks_exact(3)
        .filter(|t| t.iter().all(|&i| (i as usize) < n));
    let corners = valid.flatten().map(|&i| mesh.positions[i as usize]);
    corners.fold(None, |b: Option<Aabb>, p| {
        Some(b.map_or(Aabb::new(p, p), |b| b.union(&Aabb::new(p, p))))
    })
}

/// Which of `mesh`'s runs a patch from `base` changed: those holding a triangle the patch
/// wrote, and the last of either mesh when their triangle counts differ. Triangles that use
/// a vertex the patch wrote are among those it wrote (the assembly emits a changed block's
/// neighbours again), which [`PickRuns::patched`] checks in debug builds.
fn runs_changed(base: &Mesh, mesh: &Mesh, patch: &MeshPatch) -> Vec<bool> {
    let n_triangles = mesh.n_triangles();
    let mut changed = vec![false; n_triangles.div_ceil(PICK_RUN_TRIANGLES)];
    let mut mark = |triangles: std::ops::Range<usize>| {
        let last = triangles.end.min(n_triangles);
        if triangles.start < last {
            let runs = triangles.start / PICK_RUN_TRIANGLES..=(last - 1) / PICK_RUN_TRIANGLES;
            runs.for_each(|k| changed[k] = true);
        }
    };
    patch.triangle_ranges.iter().cloned().for_each(&mut mark);
    let old = base.n_triangles();
    if old != n_triangles {
        mark(old.min(n_triangles).saturating_sub(1)..old.max(n_triangles));
    }
    changed
}

impl PickRuns {
    /// The boxes of the runs of `mesh`'s triangles, when they were made for it.
    pub(crate) fn runs_made_for(&self, mesh: &Arc<Mesh>) -> Option<&[Option<Aabb>]> {
        let made = self.0.get().filter(|b| b.made_for(mesh))?;
        Some(&made.runs)
    }

    /// The run boxes of `mesh`, which `patch` made from `base`: those of `base` kept here
    /// where the patch wrote no triangle of a run, the others boxed again, so a small patch
    /// of a large mesh boxes few runs. Empty (made on first use) when these were not made
    /// for `base`, or the patch wrote everything.
    pub fn patched(&self, base: &Arc<Mesh>, mesh: &Arc<Mesh>, patch: &MeshPatch) -> PickRuns {
        let Some(kept) = self.0.get().filter(|b| b.made_for(base) && !patch.full) else {
            return PickRuns::default();
        };
        let changed = runs_changed(base, mesh, patch);
        let runs: Vec<Option<Aabb>> = (changed.iter().enumerate())
            .map(|(k, &changed)| match kept.runs.get(k) {
                Some(&b) if !changed => b,
                _ => run_box(mesh, k),
            })
            .collect();
        debug_assert!(
            runs == RunBoxes::of(mesh).runs,
            "a patch moved a triangle it did not write"
        );
        PickRuns(Arc::new(OnceLock::from(RunBoxes::from_runs(mesh, runs))))
    }

    /// Makes the run boxes of `mesh` now, unless some were made: a mesher's worker calls it
    /// after handing a mesh out, so that the window's first pick of it finds them.
    pub fn prepare(&self, mesh: &Arc<Mesh>) {
        self.0.get_or_init(|| RunBoxes::of(mesh));
    }

    /// Calls `f` with the run boxes of `mesh`: those kept when they were made for it, else
    /// made now (and kept when none were).
    fn with<R>(&self, mesh: &Arc<Mesh>, f: impl FnOnce(&RunBoxes) -> R) -> R {
        let kept = self.0.get_or_init(|| RunBoxes::of(mesh));
        if kept.made_for(mesh) {
            f(kept)
        } else {
            f(&RunBoxes::of(mesh))
        }
    }
}

impl SceneObject {
    /// Whether any vertex alpha or the material opacity is below 1.
    pub fn is_transparent(&self) -> bool {
        self.material.is_transparent() || self.mesh.has_translucent_vertices()
    }
}

/// A line segment in world space with a straight-alpha RGBA colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Line {
    /// Start.
    pub from: Vec3,
    /// End.
    pub to: Vec3,
    /// Colour, linear RGBA 0..1.
    pub colour: [f32; 4],
}

/// Everything one frame shows.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Objects, indexed by `object_idx` in [`PickHit`].
    pub objects: Vec<SceneObject>,
    /// Lines: arrows, boxes, cursors.
    pub lines: Vec<Line>,
    /// The viewpoint.
    pub camera: Camera,
    /// Direction towards the light, world space (need not be unit length).
    pub light_towards: Vec3,
    /// Clear colour, linear RGBA.
    pub background: [f32; 4],
}

impl Default for Scene {
    fn default() -> Self {
        Self {
            objects: Vec::new(),
            lines: Vec::new(),
            camera: Camera::default(),
            light_towards: Vec3::new(0.4, -0.6, 1.0),
            background: [0.08, 0.09, 0.11, 1.0],
        }
    }
}

/// Where a ray hits the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PickHit {
    /// Index into [`Scene::objects`].
    pub object_idx: usize,
    /// Index of the triangle within that object's mesh.
    pub triangle_idx: usize,
    /// The hit point in world space.
    pub point_in_world: Vec3,
    /// Distance along the ray.
    pub distance: f32,
}

impl Scene {
    /// Adds an object, drawn two-sided, and returns its index.
    pub fn add_object(
        &mut self,
        mesh: Arc<Mesh>,
        world_from_object: Mat4,
        material: Material,
    ) -> usize {
        self.objects.push(SceneObject {
            mesh,
            world_from_object,
            material,
            closed: false,
            pick_runs: PickRuns::default(),
        });
        self.objects.len() - 1
    }

    /// Adds the twelve edges of a box (the haptic zone, a selection).
    pub fn add_box(&mut self, b: Aabb, colour: [f32; 4]) {
        let corner = |k: usize| {
            Vec3::from_array(std::array::from_fn(|a| {
                if k >> a & 1 == 1 { b.hi[a] } else { b.lo[a] }
            }))
        };
        for k in 0..8usize {
            for a in 0..3 {
                if k >> a & 1 == 0 {
                    self.lines.push(Line {
                        from: corner(k),
                        to: corner(k | 1 << a),
                        colour,
                    });
                }
            }
        }
    }

    /// Adds an arrow from `from` to `to` with a four-line head (force-field vectors).
    pub fn add_arrow(&mut self, from: Vec3, to: Vec3, colour: [f32; 4]) {
        self.lines.push(Line { from, to, colour });
        let d = to - from;
        let len = d.length();
        if len.is_nan() || len <= f32::EPSILON {
            return;
        }
        let dir = d / len;
        let side = dir.any_orthonormal_vector();
        let up = dir.cross(side);
        let head = 0.2 * len;
        for s in [side, -side, up, -up] {
            self.lines.push(Line {
                from: to,
                to: to - head * dir + 0.5 * head * s,
                colour,
            });
        }
    }

    /// Adds a three-axis crosshair of half-size `size` at `centre` (the 3D cursor).
    pub fn add_crosshair(&mut self, centre: Vec3, size: f32, colour: [f32; 4]) {
        for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
            self.lines.push(Line {
                from: centre - size * axis,
                to: centre + size * axis,
                colour,
            });
        }
    }

    /// Adds a wireframe of a sculpting tool (the tool avatar) placed by `world_from_tool`
    /// (see [`pose_matrix`]): a ball as three great circles, a box as its twelve edges (its
    /// rounding left out), a cylinder (along its local y) as its two rims and four sides.
    pub fn add_tool(&mut self, tool: &ToolShape, world_from_tool: Mat4, colour: [f32; 4]) {
        let mut segment = |a: Vec3, b: Vec3| {
            self.lines.push(Line {
                from: world_from_tool.transform_point3(a),
                to: world_from_tool.transform_point3(b),
                colour,
            });
        };
        // A circle of `radius` about `axis` through `centre`, as TOOL_CIRCLE_SEGMENTS chords.
        let mut circle = |centre: Vec3, axis: Vec3, radius: f32| {
            let u = axis.any_orthonormal_vector();
            let v = axis.cross(u);
            let at = |k: u32| {
                let a = std::f32::consts::TAU * k as f32 / TOOL_CIRCLE_SEGMENTS as f32;
                centre + radius * (a.cos() * u + a.sin() * v)
            };
            for k in 0..TOOL_CIRCLE_SEGMENTS {
                segment(at(k), at(k + 1));
            }
        };
        match *tool {
            ToolShape::Sphere { radius } => {
                for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                    circle(Vec3::ZERO, axis, radius as f32);
                }
            }
            ToolShape::Box { half_extents, .. } => {
                let h = half_extents.as_vec3();
                let mut edges = Scene::default();
                edges.add_box(Aabb::new((-h).to_array(), h.to_array()), colour);
                for l in edges.lines {
                    segment(l.from, l.to);
                }
            }
            ToolShape::Cylinder {
                radius,
                half_height,
            } => {
                let (r, h) = (radius as f32, half_height as f32);
                circle(Vec3::new(0.0, -h, 0.0), Vec3::Y, r);
                circle(Vec3::new(0.0, h, 0.0), Vec3::Y, r);
                for side in [Vec3::X, -Vec3::X, Vec3::Z, -Vec3::Z] {
                    segment(side * r - Vec3::Y * h, side * r + Vec3::Y * h);
                }
            }
        }
    }

    /// The nearest triangle the ray hits, over all objects.
    ///
    /// Each object's triangles are met in its own space, by the ray carried there once (an
    /// affine map keeps the parameter along a line, so distances compare across objects): a
    /// pick runs on every drag and hover frame, over meshes of a million triangles. Within an
    /// object, only the runs of triangles whose box the ray meets are tested
    /// ([`PickRuns`]); the hit is the one testing every triangle finds.
    pub fn pick(&self, ray: &Ray) -> Option<PickHit> {
        let mut best: Option<PickHit> = None;
        for (object_idx, o) in self.objects.iter().enumerate() {
            let object_from_world = o.world_from_object.inverse();
            let local = Ray {
                origin: object_from_world.transform_point3(ray.origin),
                direction: object_from_world.transform_vector3(ray.direction),
            };
            if !(local.origin.is_finite() && local.direction.is_finite()) {
                continue;
            }
            let m = &o.mesh;
            let mut take = |triangle_idx: usize, t: f32| {
                if best.is_none_or(|h| t < h.distance) {
                    best = Some(PickHit {
                        object_idx,
                        triangle_idx,
                        point_in_world: ray.origin + t * ray.direction,
                        distance: t,
                    });
                }
            };
            o.pick_runs
                .with(m, |boxes| pick_runs(m, boxes, &local, &mut take));
        }
        best
    }
}

/// Chords per circle of a tool avatar's wireframe.
pub const TOOL_CIRCLE_SEGMENTS: u32 = 32;

/// The map from a tool's own space to its parent's for an fdsl [`Pose`]: scale, then
/// rotate, then move to the position.
pub fn pose_matrix(pose: &Pose) -> Mat4 {
    Mat4::from_scale_rotation_translation(
        Vec3::splat(pose.scale as f32),
        pose.rotation.normalize().as_quat(),
        pose.position.as_vec3(),
    )
}

/// Calls `take` with the index and distance of every triangle of `m` that `ray` (in the
/// mesh's space) hits, testing only the runs whose box in `boxes` it meets.
fn pick_runs(m: &Mesh, boxes: &RunBoxes, ray: &Ray, take: &mut impl FnMut(usize, f32)) {
    if boxes.all.is_none_or(|b| !ray_meets_box(ray, b)) {
        return;
    }
    let p = |i: u32| Vec3::from_array(m.positions[i as usize]);
    for (run, b) in boxes.runs.iter().enumerate() {
        if b.is_none_or(|b| !ray_meets_box(ray, b)) {
            continue;
        }
        let first = run * PICK_RUN_TRIANGLES;
        let end = (3 * (first + PICK_RUN_TRIANGLES)).min(m.indices.len());
        for (k, t) in m.indices[3 * first..end].chunks_exact(3).enumerate() {
            let [a, b, c] = [t[0], t[1], t[2]];
            if [a, b, c].iter().any(|&i| i as usize >= m.positions.len()) {
                continue;
            }
            if let Some(t) = ray_triangle(ray, p(a), p(b), p(c)) {
                take(first + k, t);
            }
        }
    }
}

/// Whether the ray meets box `b` (its faces included, grown against rounding by a
/// ten-thousandth of its size and a few ulps of the coordinates involved) at a distance of
/// zero or more.
fn ray_meets_box(ray: &Ray, b: Aabb) -> bool {
    let (lo, hi) = (Vec3::from_array(b.lo), Vec3::from_array(b.hi));
    let magnitude = lo.abs().max(hi.abs()).max(ray.origin.abs()).max_element();
    let pad = 1e-4 * (hi - lo).max_element() + 16.0 * f32::EPSILON * magnitude + 1e-6;
    let (lo, hi) = (lo - pad, hi + pad);
    let (mut near, mut far) = (0.0f32, f32::INFINITY);
    for a in 0..3 {
        let (o, d) = (ray.origin[a], ray.direction[a]);
        if d == 0.0 {
            if o < lo[a] || o > hi[a] {
                return false;
            }
            continue;
        }
        let (t0, t1) = ((lo[a] - o) / d, (hi[a] - o) / d);
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    near <= far
}

/// Möller-Trumbore: the distance along the ray to triangle (a, b, c), either side facing.
#[inline]
pub fn ray_triangle(ray: &Ray, a: Vec3, b: Vec3, c: Vec3) -> Option<f32> {
    let (e1, e2) = (b - a, c - a);
    let p = ray.direction.cross(e2);
    let det = e1.dot(p);
    if det.abs() < f32::EPSILON * e1.length() * e2.length() {
        return None;
    }
    let inv = 1.0 / det;
    let s = ray.origin - a;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = ray.direction.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t >= 0.0).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::parametric::{SurfaceSettings, UvDomain, triangulate_surface};

    fn square(z: f32) -> Arc<Mesh> {
        let settings = SurfaceSettings {
            domain: UvDomain {
                u: (-1.0, 1.0),
                v: (-1.0, 1.0),
            },
            initial_divisions: 2,
            tolerance: 0.1,
            vertices_max: 100,
        };
        Arc::new(triangulate_surface(|uv| [uv[0], uv[1], z], |_, _| [1.0; 4], &settings).unwrap())
    }

    #[test]
    fn pick_returns_the_nearest_object_and_the_point() {
        let mut scene = Scene::default();
        scene.add_object(square(0.0), Mat4::IDENTITY, Material::default());
        scene.add_object(
            square(0.0),
            Mat4::from_translation(Vec3::new(0.0, 0.0, 0.5)),
            Material::default(),
        );
        let ray = Ray {
            origin: Vec3::new(0.25, -0.3, 5.0),
            direction: Vec3::NEG_Z,
        };
        let hit = scene.pick(&ray).unwrap();
        assert_eq!(hit.object_idx, 1);
        assert!((hit.point_in_world - Vec3::new(0.25, -0.3, 0.5)).length() < 1e-5);
        assert!((hit.distance - 4.5).abs() < 1e-5);
        let miss = Ray {
            origin: Vec3::new(3.0, 0.0, 5.0),
            direction: Vec3::NEG_Z,
        };
        assert_eq!(scene.pick(&miss), None);
    }

    #[test]
    fn pick_compares_world_distances_across_scaled_and_turned_objects() {
        let mut scene = Scene::default();
        // A square three times larger, turned about z and raised to z = 1, and a plain one
        // at z = 0.5 behind it; a collapsed one (no inverse) is never hit.
        let big = Mat4::from_translation(Vec3::Z)
            * Mat4::from_rotation_z(0.6)
            * Mat4::from_scale(Vec3::splat(3.0));
        scene.add_object(square(0.0), big, Material::default());
        let plain = Mat4::from_translation(Vec3::new(0.0, 0.0, 0.5));
        scene.add_object(square(0.0), plain, Material::default());
        let flat = Mat4::from_translation(Vec3::new(0.0, 0.0, 2.0)) * Mat4::from_scale(Vec3::ZERO);
        scene.add_object(square(0.0), flat, Material::default());
        let ray = Ray {
            origin: Vec3::new(0.2, 0.1, 5.0),
            direction: Vec3::NEG_Z,
        };
        let hit = scene.pick(&ray).unwrap();
        assert_eq!(hit.object_idx, 0, "{hit:?}");
        assert!((hit.distance - 4.0).abs() < 1e-5, "{hit:?}");
        assert!((hit.point_in_world - Vec3::new(0.2, 0.1, 1.0)).length() < 1e-5);
        // Beside the big square's reach only the plain one lies below the ray.
        scene.objects[0].world_from_object = Mat4::from_translation(Vec3::new(9.0, 0.0, 1.0));
        let hit = scene.pick(&ray).unwrap();
        assert_eq!(hit.object_idx, 1, "{hit:?}");
        assert!((hit.distance - 4.5).abs() < 1e-5, "{hit:?}");
    }

    /// A wavy sheet of `n` by `n` quads far from the origin (where rounding is coarse), its
    /// triangles in row order, then a few that name missing vertices.
    fn wavy_sheet(n: u32, offset: f32) -> Mesh {
        let mut m = Mesh::default();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
                let z = 0.2 * (7.0 * x).sin() * (5.0 * y).cos();
                m.positions.push([offset + x, offset + y, offset + z]);
                m.normals.push([0.0, 0.0, 1.0]);
                m.colours.push([1.0; 4]);
            }
        }
        let at = |i: u32, j: u32| j * (n + 1) + i;
        for j in 0..n {
            for i in 0..n {
                let quad = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
                m.indices
                    .extend([quad[0], quad[1], quad[2], quad[0], quad[2], quad[3]]);
            }
        }
        let missing = m.positions.len() as u32;
        m.indices.extend([0, 1, missing, missing, 2, 3]);
        m
    }

    /// The nearest hit testing every triangle of every object, as picks did before runs.
    fn pick_every_triangle(scene: &Scene, ray: &Ray) -> Option<(usize, usize, f32)> {
        let mut best: Option<(usize, usize, f32)> = None;
        for (object_idx, o) in scene.objects.iter().enumerate() {
            let object_from_world = o.world_from_object.inverse();
            let local = Ray {
                origin: object_from_world.transform_point3(ray.origin),
                direction: object_from_world.transform_vector3(ray.direction),
            };
            let m = &o.mesh;
            let p = |i: u32| Vec3::from_array(m.positions[i as usize]);
            for (k, [a, b, c]) in m.triangles().enumerate() {
                if [a, b, c].iter().any(|&i| i as usize >= m.positions.len()) {
                    continue;
                }
                if let Some(t) = ray_triangle(&local, p(a), p(b), p(c))
                    && best.is_none_or(|h| t < h.2)
                {
                    best = Some((object_idx, k, t));
                }
            }
        }
        best
    }

    #[test]
    fn a_pick_through_the_runs_finds_what_testing_every_triangle_finds() {
        let mut scene = Scene::default();
        for (offset, turn) in [(0.0, 0.0), (100.0, 0.7)] {
            let to_world =
                Mat4::from_rotation_x(turn) * Mat4::from_translation(Vec3::splat(-offset));
            let sheet = Arc::new(wavy_sheet(60, offset));
            scene.add_object(sheet, to_world, Material::default());
        }
        assert!(scene.objects[0].mesh.n_triangles() > 50 * PICK_RUN_TRIANGLES);
        let mut rng = testkit::rng::XorShift64(0x2545_f491_4f6c_dd1d);
        let mut random = move || rng.unit_f32();
        let mut n_hits = 0;
        for _ in 0..2000 {
            let origin = Vec3::new(random() * 3.0 - 1.0, random() * 3.0 - 1.0, 2.0 + random());
            let target = Vec3::new(random() * 1.2 - 0.1, random() * 1.2 - 0.1, random() - 0.5);
            let ray = Ray {
                origin,
                direction: (target - origin).normalize(),
            };
            let hit = scene
                .pick(&ray)
                .map(|h| (h.object_idx, h.triangle_idx, h.distance));
            assert_eq!(hit, pick_every_triangle(&scene, &ray), "{ray:?}");
            n_hits += usize::from(hit.is_some());
        }
        assert!(n_hits > 500, "{n_hits}");
        // An object given another mesh does not read the runs kept for its first.
        let mut moved = scene.objects[0].clone();
        moved.mesh = Arc::new(wavy_sheet(60, 0.5));
        let ray = Ray {
            origin: Vec3::new(0.75, 0.75, 3.0),
            direction: Vec3::NEG_Z,
        };
        let mut alone = Scene::default();
        alone.objects.push(moved);
        assert_eq!(
            alone
                .pick(&ray)
                .map(|h| (h.object_idx, h.triangle_idx, h.distance)),
            pick_every_triangle(&alone, &ray)
        );
        assert!(alone.pick(&ray).is_some());
        // Meshes dropped and made again, which the allocator may place where the dropped ones
        // were, are never taken for them.
        alone.objects[0].pick_runs = PickRuns::default();
        alone.pick(&ray);
        for k in 1..6 {
            let next = wavy_sheet(60, 0.5 - 0.05 * k as f32);
            alone.objects[0].mesh = Arc::new(Mesh::default());
            alone.objects[0].mesh = Arc::new(next);
            let hit = alone.pick(&ray);
            let hit = hit.map(|h| (h.object_idx, h.triangle_idx, h.distance));
            assert_eq!(hit, pick_every_triangle(&alone, &ray), "mesh {k}");
        }
    }

    #[test]
    fn a_ray_meets_a_box_ahead_from_outside_inside_and_along_a_flat_face() {
        let b = Aabb::new([0.0; 3], [1.0, 1.0, 0.0]);
        let ray = |o: [f32; 3], d: Vec3| Ray {
            origin: Vec3::from_array(o),
            direction: d,
        };
        assert!(ray_meets_box(&ray([0.5, 0.5, 3.0], Vec3::NEG_Z), b));
        assert!(!ray_meets_box(&ray([0.5, 0.5, 3.0], Vec3::Z), b), "behind");
        assert!(
            !ray_meets_box(&ray([1.5, 0.5, 3.0], Vec3::NEG_Z), b),
            "beside"
        );
        assert!(
            ray_meets_box(&ray([0.5, 0.5, 0.0], Vec3::X), b),
            "from inside"
        );
        assert!(
            ray_meets_box(&ray([1.0, 1.0, 1.0], Vec3::NEG_Z), b),
            "at a corner"
        );
        let slanted = Vec3::new(1.0, 0.0, -1.0).normalize();
        assert!(ray_meets_box(&ray([-0.5, 0.5, 0.5], slanted), b));
        assert!(!ray_meets_box(&ray([-0.6, 0.5, 0.5], -slanted), b));
    }

    #[test]
    fn pick_through_a_camera_pixel_finds_the_projected_point() {
        let mut scene = Scene::default();
        scene.add_object(square(0.2), Mat4::IDENTITY, Material::default());
        let target = Vec3::new(0.3, 0.4, 0.2);
        let size = [320, 240];
        let px = scene.camera.project(target, size).unwrap();
        let hit = scene
            .pick(&scene.camera.ray_through_pixel(px, size))
            .unwrap();
        assert!((hit.point_in_world - target).length() < 1e-3, "{hit:?}");
    }

    #[test]
    fn helpers_add_the_expected_lines() {
        let mut scene = Scene::default();
        scene.add_box(Aabb::new([0.0; 3], [1.0; 3]), [1.0; 4]);
        assert_eq!(scene.lines.len(), 12);
        assert!(
            scene
                .lines
                .iter()
                .all(|l| ((l.to - l.from).length() - 1.0).abs() < 1e-6)
        );
        scene.add_arrow(Vec3::ZERO, Vec3::X, [1.0; 4]);
        scene.add_crosshair(Vec3::ZERO, 0.1, [1.0; 4]);
        assert_eq!(scene.lines.len(), 12 + 5 + 3);
    }

    #[test]
    fn tool_avatars_are_wireframes_of_the_tool_at_its_pose() {
        let pose = Pose {
            position: glam::DVec3::new(1.0, 2.0, 3.0),
            rotation: glam::DQuat::from_rotation_z(0.7),
            scale: 2.0,
        };
        let at = pose_matrix(&pose);
        let centre = Vec3::new(1.0, 2.0, 3.0);
        let mut scene = Scene::default();
        scene.add_tool(&ToolShape::Sphere { radius: 0.1 }, at, [1.0; 4]);
        let n = TOOL_CIRCLE_SEGMENTS as usize;
        assert_eq!(scene.lines.len(), 3 * n);
        for l in &scene.lines {
            // Radius 0.1 scaled by 2.
            assert!(((l.from - centre).length() - 0.2).abs() < 1e-5, "{l:?}");
        }
        let mut scene = Scene::default();
        let half_extents = glam::DVec3::new(0.1, 0.2, 0.3);
        let boxed = ToolShape::Box {
            half_extents,
            rounding: 0.01,
        };
        scene.add_tool(&boxed, Mat4::IDENTITY, [1.0; 4]);
        assert_eq!(scene.lines.len(), 12);
        assert!(scene.lines.iter().all(|l| {
            let d = (l.from.abs() - half_extents.as_vec3()).abs();
            d.max_element() < 1e-6
        }));
        let mut scene = Scene::default();
        let cylinder = ToolShape::Cylinder {
            radius: 0.1,
            half_height: 0.5,
        };
        scene.add_tool(&cylinder, Mat4::IDENTITY, [1.0; 4]);
        assert_eq!(scene.lines.len(), 2 * n + 4);
        assert!(scene.lines.iter().all(|l| {
            let radial = Vec3::new(l.from.x, 0.0, l.from.z).length();
            (radial - 0.1).abs() < 1e-6 && (l.from.y.abs() - 0.5).abs() < 1e-6
        }));
    }
}
