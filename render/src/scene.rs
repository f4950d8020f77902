//! What to draw: objects (meshes with materials and transforms), lines (boxes such as the
//! haptic zone, arrows such as force-field vectors, crosshair cursors, tool avatars), camera
//! and light.

use crate::camera::{Camera, Ray};
use crate::mesh::{Aabb, Mesh};
use glam::{Mat4, Vec3};
use model::object::{Pose, ToolShape};
use std::sync::Arc;

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
    /// pick runs on every drag and hover frame, over meshes of a million triangles.
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
            // A pass over the positions is a small part of one over the triangles.
            if m.bounds().is_none_or(|b| !ray_meets_box(&local, b)) {
                continue;
            }
            let p = |i: u32| Vec3::from_array(m.positions[i as usize]);
            for (triangle_idx, [a, b, c]) in m.triangles().enumerate() {
                if [a, b, c].iter().any(|&i| i as usize >= m.positions.len()) {
                    continue;
                }
                let Some(t) = ray_triangle(&local, p(a), p(b), p(c)) else {
                    continue;
                };
                if best.is_none_or(|h| t < h.distance) {
                    let point_in_world = ray.origin + t * ray.direction;
                    best = Some(PickHit {
                        object_idx,
                        triangle_idx,
                        point_in_world,
                        distance: t,
                    });
                }
            }
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

/// Whether the ray meets box `b` (its faces included, grown by a ten-thousandth of its size
/// against rounding) at a distance of zero or more.
fn ray_meets_box(ray: &Ray, b: Aabb) -> bool {
    let (lo, hi) = (Vec3::from_array(b.lo), Vec3::from_array(b.hi));
    let pad = 1e-4 * (hi - lo).max_element() + 1e-6;
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
