//! Reference containers for tests, benchmarks and demos: closed-form solids (spheres, the
//! watermelon, the whirlpool cylinder), the same scenes as fdsl [`FunctionContainer`]s (the
//! watermelon's properties, the thesis's Figure 7.4 whirlpool), as objects of the shared
//! object model for [`crate::container::object::ObjectContainer`] (with optional sculpted
//! dents), and triangle meshes (a cube, an icosphere) for
//! [`crate::container::mesh::MeshContainer`].
//!
//! Each closed-form solid uses a distance-like function (`f >= 0` inside) so the metric depth
//! `f / |grad f|` is close to the true distance to the surface.

use glam::DVec3;

use fdsl::Function;

use crate::aabb::Aabb;
use crate::container::function::{FunctionContainer, FunctionContainerError, Placement};
use crate::container::mesh::{MeshContainer, MeshError, RayParams};
use crate::container::properties::{FieldSpec, PropertySpec, Scalar};
use crate::container::{Container, FieldDomain};

/// A closed-form solid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solid {
    /// `radius - |p - center|`.
    Sphere {
        /// Centre, world units.
        center: DVec3,
        /// Radius, world units.
        radius: f64,
    },
    /// A sphere minus the wedge `x > center.x && z > center.z` (a quarter cut out).
    Watermelon {
        /// Centre, world units.
        center: DVec3,
        /// Radius, world units.
        radius: f64,
    },
    /// The vertical cylinder `radius - sqrt(x^2+z^2) & y - y_min & y_max - y`.
    Cylinder {
        /// Radius about the y axis.
        radius: f64,
        /// Bottom plane.
        y_min: f64,
        /// Top plane.
        y_max: f64,
    },
}

/// Gradient of `r - |d|` at offset `d` (zero at the centre, where it is undefined).
fn sphere_grad(d: DVec3) -> DVec3 {
    -d.normalize_or_zero()
}

impl Solid {
    /// The function value and gradient at `p`.
    pub fn value_grad(&self, p: DVec3) -> (f64, DVec3) {
        match *self {
            Solid::Sphere { center, radius } => {
                let d = p - center;
                (radius - d.length(), sphere_grad(d))
            }
            Solid::Watermelon { center, radius } => {
                let d = p - center;
                let ball = (radius - d.length(), sphere_grad(d));
                // Outside the wedge: max(cx - x, cz - z).
                let cut = if -d.x >= -d.z {
                    (-d.x, DVec3::NEG_X)
                } else {
                    (-d.z, DVec3::NEG_Z)
                };
                if ball.0 <= cut.0 { ball } else { cut }
            }
            Solid::Cylinder {
                radius,
                y_min,
                y_max,
            } => {
                let radial = DVec3::new(p.x, 0.0, p.z);
                let mut best = (radius - radial.length(), sphere_grad(radial));
                for candidate in [(p.y - y_min, DVec3::Y), (y_max - p.y, DVec3::NEG_Y)] {
                    if candidate.0 < best.0 {
                        best = candidate;
                    }
                }
                best
            }
        }
    }

    /// A box around the solid.
    pub fn bounds(&self) -> Aabb {
        match *self {
            Solid::Sphere { center, radius } | Solid::Watermelon { center, radius } => {
                Aabb::new(center - radius, center + radius)
            }
            Solid::Cylinder {
                radius,
                y_min,
                y_max,
            } => Aabb::new(
                DVec3::new(-radius, y_min, -radius),
                DVec3::new(radius, y_max, radius),
            ),
        }
    }
}

/// How interior density varies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Density {
    /// The same everywhere.
    Uniform(f64),
    /// Crunchy: `base + amplitude * sin(2 pi |p - center| / wavelength)`, clamped to `[0, 1]`.
    Crunchy {
        /// Centre of the layers.
        center: DVec3,
        /// Mean density.
        base: f64,
        /// Layer contrast.
        amplitude: f64,
        /// Layer spacing, world units.
        wavelength: f64,
    },
}

/// A built-in force field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Field {
    /// The thesis's whirlpool (Figure 7.4): a unit vector spiralling about the w axis.
    Whirlpool,
    /// A constant vector.
    Constant(DVec3),
}

/// A closed-form container with its properties (each optional).
#[derive(Clone, Debug, PartialEq)]
pub struct Analytic {
    /// Object id.
    pub id: u64,
    /// Geometry of the container.
    pub solid: Solid,
    /// Surface tension in `[0, 1]`.
    pub tension: Option<f64>,
    /// Friction coefficient in `[0, 1]`.
    pub friction: Option<f64>,
    /// Interior density.
    pub density: Option<Density>,
    /// Surface zone depth, world units.
    pub zone_depth: f64,
    /// Force field and its domain.
    pub field: Option<(Field, FieldDomain)>,
}

impl Analytic {
    /// A container with no properties.
    pub fn new(id: u64, solid: Solid) -> Self {
        Self {
            id,
            solid,
            tension: None,
            friction: None,
            density: None,
            zone_depth: 0.0,
            field: None,
        }
    }

    /// The thesis's watermelon: a tense rind the tool pops through, then crunchy flesh.
    pub fn watermelon(id: u64, center: DVec3, radius: f64) -> Self {
        Self {
            tension: Some(0.8),
            friction: Some(0.3),
            density: Some(Density::Crunchy {
                center,
                base: 0.5,
                amplitude: 0.4,
                wavelength: radius * 0.1,
            }),
            zone_depth: radius * 0.05,
            ..Self::new(id, Solid::Watermelon { center, radius })
        }
    }

    /// The thesis's whirlpool (Figure 7.3): an invisible cylinder with a helical field.
    pub fn whirlpool(id: u64) -> Self {
        let solid = Solid::Cylinder {
            radius: 1.6,
            y_min: 0.0,
            y_max: 0.7,
        };
        let domain = FieldDomain {
            box_world: solid.bounds(),
            uvw: Aabb::new(DVec3::new(-1.0, 0.0, -1.0), DVec3::new(1.0, 1.0, 1.0)),
            cycle_interval_secs: 0.0,
            time_span_secs: f64::INFINITY,
        };
        Self {
            field: Some((Field::Whirlpool, domain)),
            ..Self::new(id, solid)
        }
    }
}

impl Container for Analytic {
    fn id(&self) -> u64 {
        self.id
    }
    fn bounds(&self) -> Aabb {
        self.solid.bounds()
    }
    fn value_grad(&mut self, p: DVec3, _t_secs: f64) -> (f64, DVec3) {
        self.solid.value_grad(p)
    }
    fn tension(&mut self, _p: DVec3, _t_secs: f64) -> Option<f64> {
        self.tension
    }
    fn friction(&mut self, _p: DVec3, _t_secs: f64) -> Option<f64> {
        self.friction
    }
    fn density(&mut self, p: DVec3, _t_secs: f64) -> Option<f64> {
        self.density.map(|d| match d {
            Density::Uniform(v) => v,
            Density::Crunchy {
                center,
                base,
                amplitude,
                wavelength,
            } => {
                let phase = std::f64::consts::TAU * (p - center).length() / wavelength;
                (base + amplitude * phase.sin()).clamp(0.0, 1.0)
            }
        })
    }
    fn zone_depth(&mut self, _p: DVec3, _t_secs: f64) -> Option<f64> {
        Some(self.zone_depth)
    }
    fn field_domain(&self) -> Option<FieldDomain> {
        self.field.map(|(_, domain)| domain)
    }
    fn force_field(&mut self, uvw: DVec3, _t_local_secs: f64) -> DVec3 {
        match self.field {
            Some((Field::Whirlpool, _)) => {
                let (u, v, w) = (uvw.x, uvw.y, uvw.z);
                let d = -0.1;
                DVec3::new(w + d * u, d * v, -u + d * w).normalize_or_zero()
            }
            Some((Field::Constant(f), _)) => f,
            None => DVec3::ZERO,
        }
    }
}

/// `n` watermelons on a square grid in the plane `z = 0` inside `[-1.6, 1.6]^2`, ids `1..=n`:
/// the shared scene of the step benchmark and the zero-allocation test.
pub fn watermelon_grid(n: usize) -> Vec<Analytic> {
    grid_placements(n)
        .map(|(id, center, radius)| Analytic::watermelon(id, center, radius))
        .collect()
}

/// Ids, centres and radii of [`watermelon_grid`].
pub fn grid_placements(n: usize) -> impl Iterator<Item = (u64, DVec3, f64)> {
    let per_row = (n as f64).sqrt().ceil().max(1.0) as usize;
    let spacing = 3.2 / per_row as f64;
    (0..n).map(move |k| {
        let (row, col) = (k / per_row, k % per_row);
        let center = DVec3::new(
            -1.6 + spacing * (col as f64 + 0.5),
            -1.6 + spacing * (row as f64 + 0.5),
            0.0,
        );
        (k as u64 + 1, center, spacing * 0.45)
    })
}

/// Waypoints of a tip circling the device workspace centre in the x-y plane, `n_loops` times
/// with `period_secs` each: it crosses the objects of [`watermelon_grid`] over and over.
pub fn circle_waypoints(
    radius_metres: f64,
    period_secs: f64,
    n_loops: usize,
) -> Vec<crate::device::sim::Waypoint> {
    const N_PER_LOOP: usize = 64;
    (0..=n_loops * N_PER_LOOP)
        .map(|k| {
            let angle = std::f64::consts::TAU * k as f64 / N_PER_LOOP as f64;
            crate::device::sim::Waypoint {
                t_secs: period_secs * k as f64 / N_PER_LOOP as f64,
                position_metres: DVec3::new(angle.cos(), angle.sin(), 0.0) * radius_metres,
            }
        })
        .collect()
}

/// A triangle mesh as vertices and counter-clockwise (outward) index triples.
pub type TriangleMesh = (Vec<[f32; 3]>, Vec<[u32; 3]>);

/// The closed cube `[center - half, center + half]`, 12 outward triangles
/// (`model::mesh::shapes::cube`).
pub fn cube_mesh(center: DVec3, half: f64) -> TriangleMesh {
    model::mesh::shapes::cube(center - DVec3::splat(half), center + DVec3::splat(half)).into_parts()
}

/// A sphere of `radius` about `center`: an icosahedron subdivided `n_subdivisions` times
/// (`20 * 4^n` outward triangles; `model::mesh::shapes::icosphere`, at most
/// `MAX_ICOSPHERE_SUBDIVISIONS`), vertices on the sphere.
pub fn icosphere(center: DVec3, radius: f64, n_subdivisions: u32) -> TriangleMesh {
    let (mut vertices, triangles) =
        model::mesh::shapes::icosphere(radius, n_subdivisions).into_parts();
    let offset = center.as_vec3();
    for v in &mut vertices {
        *v = (glam::Vec3::from_array(*v) + offset).to_array();
    }
    (vertices, triangles)
}

/// The thesis's Figure 7.4 container: an invisible cylinder, as printed.
pub const WHIRLPOOL_GEOMETRY: &str = "(1.6^2-x^2-z^2) & y & (0.7-y)";
/// The thesis's Figure 7.4 helical force field, as printed (less the typographic quotes).
pub const WHIRLPOOL_FIELD: &str = "
    function parametric_x (u, v, w) {d=-0.1; x=w+d*u; y=d*v; z=-u+d*w; return x/sqrt(x^2+y^2+z^2) ;}
    function parametric_y (u, v, w) {d=-0.1; x=w+d*u; y=d*v; z=-u+d*w; return y/sqrt(x^2+y^2+z^2) ;}
    function parametric_z (u, v, w) {d=-0.1; x=w+d*u; y=d*v; z=-u+d*w; return z/sqrt(x^2+y^2+z^2) ;}";
/// The watermelon's crunchy flesh: layers of density every tenth of the radius, in object
/// coordinates of a unit watermelon (the same as [`Density::Crunchy`] of
/// [`Analytic::watermelon`]).
pub const WATERMELON_DENSITY: &str = "0.5 + 0.4*sin(2*pi*sqrt(x^2+y^2+z^2)/0.1)";

/// Why a reference fdsl container could not be built.
#[derive(Debug, thiserror::Error)]
pub enum FdslShapeError {
    /// A reference text did not compile.
    #[error("{0}")]
    Compile(#[from] fdsl::CompileError),
    /// The container rejected it.
    #[error(transparent)]
    Container(#[from] FunctionContainerError),
}

/// The watermelon's properties as fdsl functions (object coordinates of a unit watermelon):
/// a tense rind with friction in a surface zone 0.05 deep, then crunchy density.
pub fn watermelon_properties() -> Result<PropertySpec, fdsl::CompileError> {
    Ok(PropertySpec {
        tension: Some(Scalar::Function(Function::parse("0.8")?)),
        friction: Some(Scalar::Function(Function::parse("0.3")?)),
        density: Some(Scalar::Function(Function::parse(WATERMELON_DENSITY)?)),
        zone_depth: Some(Scalar::Constant(0.05)),
        field: None,
    })
}

/// A watermelon whose geometry is `geometry` (a unit-radius model such as
/// `tests/data/models/watermelon.fdsl`), placed at `center` with `radius`.
pub fn fdsl_watermelon(
    id: u64,
    geometry: &Function,
    center: DVec3,
    radius: f64,
) -> Result<FunctionContainer, FdslShapeError> {
    let placement = Placement::new(center, radius).ok_or(FunctionContainerError::BadBounds {
        min: center,
        max: center,
    })?;
    Ok(FunctionContainer::new_placed(
        id,
        geometry,
        (DVec3::splat(-1.0), DVec3::ONE),
        placement,
        &watermelon_properties()?,
    )?)
}

/// [`watermelon_grid`] with fdsl watermelons of the given geometry.
pub fn fdsl_watermelon_grid(
    geometry: &Function,
    n: usize,
) -> Result<Vec<FunctionContainer>, FdslShapeError> {
    grid_placements(n)
        .map(|(id, center, radius)| fdsl_watermelon(id, geometry, center, radius))
        .collect()
}

/// The thesis's Figure 7.4 whirlpool from its printed texts: bbox centre `0 0.35 0`, size
/// `3.2 0.7 3.2`, friction disabled, field parameters `[-1 1 0 1 -1 1]`.
pub fn fdsl_whirlpool(id: u64) -> Result<FunctionContainer, FdslShapeError> {
    let (center, size) = (DVec3::new(0.0, 0.35, 0.0), DVec3::new(3.2, 0.7, 3.2));
    let props = PropertySpec {
        field: Some(FieldSpec::always(
            Function::parse(WHIRLPOOL_FIELD)?,
            Aabb::new(DVec3::new(-1.0, 0.0, -1.0), DVec3::new(1.0, 1.0, 1.0)),
        )),
        ..PropertySpec::default()
    };
    Ok(FunctionContainer::new(
        id,
        &Function::parse(WHIRLPOOL_GEOMETRY)?,
        (center - size / 2.0, center + size / 2.0),
        &props,
    )?)
}

/// Edge of the domain box of [`object_watermelon`], object units: the unit watermelon plus a
/// tenth on every side. The object model clips a solid to its domain by value (`min(f, box
/// distance)`), and where the sphere nearly touches a face of a tight box the face's value
/// would win within the surface zone and pop the membrane early; the margin keeps the clip
/// out of the zone.
pub const OBJECT_WATERMELON_DOMAIN_SIZE: f64 = 2.2;

/// A watermelon as an object of the object model: `geometry` (a unit-radius model such as
/// `tests/data/models/watermelon.fdsl`) in a domain of [`OBJECT_WATERMELON_DOMAIN_SIZE`],
/// placed at `center` scaled by `radius`, with [`watermelon_properties`]'s tension, friction
/// and crunchy density (object coordinates) and a surface zone `0.05 * radius` deep (scene
/// units): what [`fdsl_watermelon`] builds as a function container.
pub fn object_watermelon(
    geometry: &str,
    center: DVec3,
    radius: f64,
) -> Result<model::object::Object, model::object::ObjectError> {
    use model::object::{Domain, Formula, Geometry, Object, ObjectData, Physics, Property};
    let property = |text: &str| Formula::new(text).map(|f| Some(Property::new(f)));
    Object::new(ObjectData {
        name: "watermelon".into(),
        geometry: Some(Geometry::implicit_in(
            Formula::new(geometry)?,
            Domain::new(DVec3::ZERO, DVec3::splat(OBJECT_WATERMELON_DOMAIN_SIZE)),
        )),
        physics: Physics {
            tension: property("0.8")?,
            friction: property("0.3")?,
            density: property(WATERMELON_DENSITY)?,
            zone_depth: property(&format!("{}", 0.05 * radius))?,
            ..Physics::default()
        }
        .into(),
        transform: model::object::Transform::from_trs(
            center,
            glam::DQuat::IDENTITY,
            DVec3::splat(radius),
        ),
        ..ObjectData::default()
    })
}

/// `n_dents` small spherical dents of `radius` (object units) carved into the unit sphere's
/// surface at points of a Fibonacci spiral (about evenly spread, deterministic): a long
/// sculpting history whose edits each touch a small region. Compiled once, to share between
/// objects with [`model::object::Object::apply_compiled`].
pub fn sphere_dents(
    n_dents: usize,
    radius: f64,
) -> Result<Vec<std::sync::Arc<model::object::CompiledEdit>>, model::object::ObjectError> {
    use model::object::{CompiledEdit, Edit, EditOp, Pose, ToolShape};
    let golden_angle = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n_dents)
        .map(|k| {
            let y = 1.0 - 2.0 * (k as f64 + 0.5) / n_dents as f64;
            let ring = (1.0 - y * y).max(0.0).sqrt();
            let phi = golden_angle * k as f64;
            let at = DVec3::new(ring * phi.cos(), y, ring * phi.sin());
            let edit = Edit::stamp(EditOp::Subtract, ToolShape::Sphere { radius }, Pose::at(at));
            CompiledEdit::new(edit).map(std::sync::Arc::new)
        })
        .collect()
}

/// [`watermelon_grid`] as an object-model scene (object ids `1..=n`), each watermelon carved
/// with the same `dents` (see [`sphere_dents`]), histories indexed.
pub fn object_watermelon_scene(
    geometry: &str,
    n: usize,
    dents: &[std::sync::Arc<model::object::CompiledEdit>],
) -> Result<model::scene::Scene, model::scene::SceneError> {
    let mut scene = model::scene::Scene::new();
    for (id, center, radius) in grid_placements(n) {
        let mut object = object_watermelon(geometry, center, radius)?;
        for dent in dents {
            object.apply_compiled(std::sync::Arc::clone(dent))?;
        }
        scene.insert_object(model::scene::ObjectId(id), object, None)?;
    }
    scene.prepare();
    Ok(scene)
}

/// Icospheres (`20 * 4^n_subdivisions` triangles each) at the places of [`watermelon_grid`],
/// with the watermelon's properties as constants: the mesh counterpart of the grid.
pub fn mesh_grid(n: usize, n_subdivisions: u32) -> Result<Vec<MeshContainer>, MeshError> {
    let props = PropertySpec {
        tension: Some(Scalar::Constant(0.8)),
        friction: Some(Scalar::Constant(0.3)),
        density: Some(Scalar::Constant(0.5)),
        zone_depth: Some(Scalar::Constant(0.05)),
        field: None,
    };
    grid_placements(n)
        .map(|(id, center, radius)| {
            let (vertices, triangles) = icosphere(center, radius, n_subdivisions);
            let props = PropertySpec {
                zone_depth: Some(Scalar::Constant(0.05 * radius)),
                ..props.clone()
            };
            MeshContainer::new(id, &vertices, &triangles, &props, RayParams::default())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whirlpool_of_figure_7_4() {
        // The texts as printed in the thesis, through the shared builder.
        let mut c = fdsl_whirlpool(9).unwrap();
        assert_eq!(
            c.bounds(),
            Aabb::new(DVec3::new(-1.6, 0.0, -1.6), DVec3::new(1.6, 0.7, 1.6))
        );
        let p = DVec3::new(0.8, 0.35, 0.0);
        assert!(c.value_grad(p, 0.0).0 > 0.0);
        let uvw = c.field_domain().unwrap().uvw_from_world(p);
        assert!((uvw - DVec3::new(0.5, 0.5, 0.0)).length() < 1e-12);
        let expected = DVec3::new(-0.05, -0.05, -0.5).normalize();
        assert!((c.force_field(uvw, 0.0) - expected).length() < 1e-12);
    }
}
