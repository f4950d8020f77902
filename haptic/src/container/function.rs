//! [`FunctionContainer`]: a haptic container whose geometry is an fdsl function (`f >= 0`
//! inside) over a bounding box, with properties from [`super::properties`].
//!
//! The container is the solid `f >= 0` clipped to its box (the thesis's `bboxCenter` and
//! `bboxSize`), so a half-space such as `y` still makes a closed container. Values and exact
//! gradients come from fdsl's forward-mode [`GradEval`]; where the box face is nearer than the
//! function's metric depth `f / |grad f|`, the face is returned instead (distance and inward
//! unit normal), which keeps the sign and the depth right on both.
//!
//! Evaluators are built in [`FunctionContainer::new`]; sampling allocates nothing.

use glam::DVec3;

use fdsl::Function;
use fdsl::eval::GradEval;

use super::properties::{Properties, PropertyError, PropertySpec};
use super::{Container, FieldDomain};
use crate::aabb::Aabb;

/// Why a function container could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FunctionContainerError {
    /// The bounding box is not finite or has `min > max` on some axis.
    #[error("the container's box is not finite or is inverted: {min:?} .. {max:?}")]
    BadBounds {
        /// Smallest corner given.
        min: DVec3,
        /// Largest corner given.
        max: DVec3,
    },
    /// A property could not be compiled.
    #[error(transparent)]
    Property(#[from] PropertyError),
}

/// Checks an untrusted box before [`Aabb::new`] (which asserts).
pub(crate) fn checked_box(min: DVec3, max: DVec3) -> Option<Aabb> {
    (min.is_finite() && max.is_finite() && min.cmple(max).all()).then(|| Aabb::new(min, max))
}

/// Where a container sits in the world: `world = translation + scale * object`.
///
/// Rotation is left to the caller (rotate the function's coordinates in its text): with
/// translation and uniform scale only, the object's box stays a box and metric depths scale
/// exactly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    translation: DVec3,
    scale: f64,
}

impl Placement {
    /// Object coordinates are world coordinates.
    pub const IDENTITY: Placement = Placement {
        translation: DVec3::ZERO,
        scale: 1.0,
    };

    /// A placement; `None` unless finite with `scale > 0`.
    pub fn new(translation: DVec3, scale: f64) -> Option<Self> {
        (translation.is_finite() && scale.is_finite() && scale > 0.0)
            .then_some(Self { translation, scale })
    }

    /// A world point in object coordinates.
    pub fn object_from_world(&self, p: DVec3) -> DVec3 {
        (p - self.translation) / self.scale
    }

    /// An object point in world coordinates.
    pub fn world_from_object(&self, p: DVec3) -> DVec3 {
        self.translation + p * self.scale
    }
}

/// A container defined by an fdsl function.
#[derive(Clone, Debug)]
pub struct FunctionContainer {
    id: u64,
    geometry: GradEval,
    box_object: Aabb,
    placement: Placement,
    bounds: Aabb,
    props: Properties,
}

impl FunctionContainer {
    /// Builds the container `geometry >= 0` inside the box `min..max`, with `props`; object
    /// coordinates are world coordinates, and the force field's domain is the box.
    pub fn new(
        id: u64,
        geometry: &Function,
        box_object: (DVec3, DVec3),
        props: &PropertySpec,
    ) -> Result<Self, FunctionContainerError> {
        Self::new_placed(id, geometry, box_object, Placement::IDENTITY, props)
    }

    /// [`FunctionContainer::new`] for an object at `placement`: the geometry, its box and the
    /// property functions (zone depth included) are in object coordinates and units.
    pub fn new_placed(
        id: u64,
        geometry: &Function,
        (min, max): (DVec3, DVec3),
        placement: Placement,
        props: &PropertySpec,
    ) -> Result<Self, FunctionContainerError> {
        let box_object =
            checked_box(min, max).ok_or(FunctionContainerError::BadBounds { min, max })?;
        let bounds = Aabb::new(
            placement.world_from_object(box_object.min),
            placement.world_from_object(box_object.max),
        );
        Ok(Self {
            id,
            geometry: GradEval::new(&geometry.tape()),
            box_object,
            placement,
            bounds,
            props: Properties::new(props, bounds)?,
        })
    }

    /// The properties, in object coordinates (to evaluate them outside the servo).
    pub fn properties_mut(&mut self) -> &mut Properties {
        &mut self.props
    }

    /// The box the geometry is clipped to, object coordinates.
    pub fn box_object(&self) -> Aabb {
        self.box_object
    }

    /// Where the object sits.
    pub fn placement(&self) -> Placement {
        self.placement
    }
}

/// The signed distance to the nearest face of `b` (positive inside) and the inward normal.
pub(crate) fn box_depth(b: &Aabb, p: DVec3) -> (f64, DVec3) {
    let mut best = (f64::INFINITY, DVec3::X);
    for axis in 0..3 {
        let mut normal = DVec3::ZERO;
        normal[axis] = 1.0;
        for (depth, n) in [
            (p[axis] - b.min[axis], normal),
            (b.max[axis] - p[axis], -normal),
        ] {
            if depth < best.0 {
                best = (depth, n);
            }
        }
    }
    best
}

impl Container for FunctionContainer {
    fn id(&self) -> u64 {
        self.id
    }

    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn value_grad(&mut self, p_world: DVec3, t_secs: f64) -> (f64, DVec3) {
        let p = self.placement.object_from_world(p_world);
        let g = self.geometry.eval([p.x, p.y, p.z, t_secs]);
        // d/dworld = d/dobject / scale, so metric depths come out in world units.
        let grad = DVec3::new(g.dx, g.dy, g.dz) / self.placement.scale;
        let grad_len = grad.length();
        let metric = if grad_len > super::MIN_GRADIENT_NORM {
            g.v / grad_len
        } else if g.v >= 0.0 {
            f64::INFINITY
        } else {
            f64::NEG_INFINITY
        };
        let (face_depth, face_normal) = box_depth(&self.bounds, p_world);
        // NaN values stay NaN (outside): the comparison is false for them.
        if face_depth < metric {
            (face_depth, face_normal)
        } else {
            (g.v, grad)
        }
    }

    fn tension(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        let p = self.placement.object_from_world(p);
        self.props.tension(p, t_secs)
    }

    fn friction(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        let p = self.placement.object_from_world(p);
        self.props.friction(p, t_secs)
    }

    fn density(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        let p = self.placement.object_from_world(p);
        self.props.density(p, t_secs)
    }

    fn zone_depth(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        let p = self.placement.object_from_world(p);
        Some(self.props.zone_depth(p, t_secs)? * self.placement.scale)
    }

    fn field_domain(&self) -> Option<FieldDomain> {
        self.props.field_domain()
    }

    fn force_field(&mut self, uvw: DVec3, t_local_secs: f64) -> DVec3 {
        self.props.force_field(uvw, t_local_secs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::container::properties::Scalar;

    fn parse(s: &str) -> Function {
        Function::parse(s).unwrap()
    }

    #[test]
    fn sphere_value_gradient_and_metric_depth() {
        let f = parse("1 - x^2 - y^2 - z^2");
        let box_world = (DVec3::splat(-2.0), DVec3::splat(2.0));
        let mut c = FunctionContainer::new(3, &f, box_world, &PropertySpec::default()).unwrap();
        let (v, g) = c.value_grad(DVec3::new(0.5, 0.0, 0.0), 0.0);
        assert_eq!((v, g), (0.75, DVec3::new(-1.0, 0.0, 0.0)));
        // The metric depth near the surface approximates the distance.
        let (v, g) = c.value_grad(DVec3::new(0.0, 0.9, 0.0), 0.0);
        assert!((v / g.length() - 0.19 / 1.8).abs() < 1e-12);
        assert_eq!(c.id(), 3);
        assert!(c.value_grad(DVec3::new(0.8, 0.8, 0.0), 0.0).0 < 0.0);
    }

    #[test]
    fn half_space_is_clipped_to_its_box() {
        // `y` alone is a half-space; the box makes it a closed slab container.
        let mut c = FunctionContainer::new(
            1,
            &parse("y"),
            (DVec3::new(-1.0, -1.0, -1.0), DVec3::new(1.0, 1.0, 1.0)),
            &PropertySpec::default(),
        )
        .unwrap();
        let (v, g) = c.value_grad(DVec3::new(0.0, 0.2, 0.0), 0.0);
        assert_eq!((v, g), (0.2, DVec3::Y), "the function's own surface rules");
        let (v, g) = c.value_grad(DVec3::new(0.95, 0.5, 0.0), 0.0);
        assert!(
            (v - 0.05).abs() < 1e-12 && g == DVec3::NEG_X,
            "the box face is nearer"
        );
        assert!(c.value_grad(DVec3::new(1.2, 0.5, 0.0), 0.0).0 < 0.0);
        assert!(c.value_grad(DVec3::new(0.0, -0.5, 0.0), 0.0).0 < 0.0);
    }

    #[test]
    fn placed_container_scales_depths_and_properties() {
        let props = PropertySpec {
            density: Some(Scalar::Function(parse("x"))),
            zone_depth: Some(Scalar::Constant(0.1)),
            ..PropertySpec::default()
        };
        let placement = Placement::new(DVec3::new(10.0, 0.0, 0.0), 2.0).unwrap();
        let mut c = FunctionContainer::new_placed(
            1,
            &parse("1 - x^2 - y^2 - z^2"),
            (DVec3::splat(-2.0), DVec3::splat(2.0)),
            placement,
            &props,
        )
        .unwrap();
        assert_eq!(
            c.bounds(),
            Aabb::new(DVec3::new(6.0, -4.0, -4.0), DVec3::new(14.0, 4.0, 4.0))
        );
        // World (11.8, 0, 0) is object (0.9, 0, 0): f = 0.19, world gradient 1.8 / 2.
        let (v, g) = c.value_grad(DVec3::new(11.8, 0.0, 0.0), 0.0);
        assert!(
            (v - 0.19).abs() < 1e-12 && (g.x + 0.9).abs() < 1e-12,
            "{v} {g}"
        );
        assert!(
            (v / g.length() - 0.19 / 0.9).abs() < 1e-12,
            "world metric depth"
        );
        assert_eq!(c.density(DVec3::new(11.0, 0.0, 0.0), 0.0), Some(0.5));
        assert_eq!(c.zone_depth(DVec3::new(11.0, 0.0, 0.0), 0.0), Some(0.2));
        assert!(Placement::new(DVec3::ZERO, 0.0).is_none());
        assert!(Placement::new(DVec3::NAN, 1.0).is_none());
    }

    #[test]
    fn bad_box_and_bad_properties_are_errors() {
        let f = parse("1 - x^2");
        let inverted = (DVec3::ONE, DVec3::ZERO);
        assert!(matches!(
            FunctionContainer::new(1, &f, inverted, &PropertySpec::default()),
            Err(FunctionContainerError::BadBounds { .. })
        ));
        let nan = (DVec3::ZERO, DVec3::new(1.0, f64::NAN, 1.0));
        assert!(FunctionContainer::new(1, &f, nan, &PropertySpec::default()).is_err());
        let props = PropertySpec {
            tension: Some(Scalar::Constant(f64::INFINITY)),
            ..PropertySpec::default()
        };
        assert!(matches!(
            FunctionContainer::new(1, &f, (DVec3::ZERO, DVec3::ONE), &props),
            Err(FunctionContainerError::Property(_))
        ));
    }
}
