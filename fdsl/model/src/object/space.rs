//! Where functions live: a part's coordinate [`Domain`], the affine [`Transform`] that places it,
//! the time mapping ([`Timing`]) of animated parts and the time-dependent [`Motion`] of an
//! object.

use glam::{DAffine3, DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

use super::{Formula, ObjectError, Slot};
use crate::bvh::Aabb;

/// A part's coordinate domain: the box, in the part's own coordinates, over which its functions
/// are defined (the thesis's `bboxCenter` and `bboxSize`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Domain {
    /// The box's centre.
    pub center: DVec3,
    /// The box's edge lengths (all positive).
    pub size: DVec3,
}

impl Domain {
    /// The cube `[-1, 1]^3`.
    pub const UNIT: Domain = Domain {
        center: DVec3::ZERO,
        size: DVec3::splat(2.0),
    };

    /// The domain of centre `center` and edge lengths `size`.
    pub fn new(center: DVec3, size: DVec3) -> Domain {
        Domain { center, size }
    }

    /// The domain as a box.
    pub fn aabb(&self) -> Aabb {
        Aabb::around(self.center, self.size * 0.5)
    }

    /// Signed distance to the box, positive inside (the F-Rep convention); exact outside,
    /// a lower bound of the depth inside.
    pub fn signed_distance(&self, p: DVec3) -> f64 {
        let q = (p - self.center).abs() - self.size * 0.5;
        let outside = q.max(DVec3::ZERO).length();
        let inside = q.max_element().min(0.0);
        -(outside + inside)
    }

    /// Maps `p` to the domain's normalised coordinates: the box to `[0, 1]^3`.
    pub fn normalise(&self, p: DVec3) -> DVec3 {
        (p - (self.center - self.size * 0.5)) / self.size
    }

    pub(crate) fn validate(&self, slot: Slot) -> Result<(), ObjectError> {
        if !(self.center.is_finite() && self.size.is_finite() && self.size.min_element() > 0.0) {
            return Err(ObjectError::BadDomain { slot });
        }
        Ok(())
    }
}

/// An affine map from a part's coordinates into its parent's (an instance transform).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Child-to-parent map.
    pub parent_from_child: DAffine3,
}

impl Default for Transform {
    fn default() -> Transform {
        Transform::IDENTITY
    }
}

impl Transform {
    /// The identity.
    pub const IDENTITY: Transform = Transform {
        parent_from_child: DAffine3::IDENTITY,
    };

    /// Scale, then rotate, then translate (VRML's order without `center` and
    /// `scaleOrientation`).
    pub fn from_trs(translation: DVec3, rotation: DQuat, scale: DVec3) -> Transform {
        Transform {
            parent_from_child: DAffine3::from_scale_rotation_translation(
                scale,
                rotation,
                translation,
            ),
        }
    }

    /// A translation.
    pub fn translate(t: DVec3) -> Transform {
        Transform {
            parent_from_child: DAffine3::from_translation(t),
        }
    }

    /// `self` after `child`: maps the child's child space into `self`'s parent space.
    pub fn then(&self, child: &Transform) -> Transform {
        Transform {
            parent_from_child: self.parent_from_child * child.parent_from_child,
        }
    }

    /// Whether this is exactly the identity (evaluation skips it).
    pub fn is_identity(&self) -> bool {
        self.parent_from_child == DAffine3::IDENTITY
    }

    /// The inverse map, if the transform is finite and invertible.
    pub fn inverse(&self) -> Option<Transform> {
        let m = self.parent_from_child;
        let det = m.matrix3.determinant();
        if !(det.is_finite() && det.abs() > 1e-12 && m.translation.is_finite()) {
            return None;
        }
        Some(Transform {
            parent_from_child: m.inverse(),
        })
    }

    /// Maps a point.
    #[inline]
    pub fn point(&self, p: DVec3) -> DVec3 {
        self.parent_from_child.transform_point3(p)
    }

    /// The linear part.
    pub fn linear(&self) -> DMat3 {
        self.parent_from_child.matrix3
    }

    /// The box around the image of `b`.
    pub fn aabb(&self, b: &Aabb) -> Aabb {
        if b.is_empty() {
            return *b;
        }
        let center = self.point(b.center());
        let half = b.size() * 0.5;
        let m = self.linear();
        let extent = DVec3::new(
            m.row(0).abs().dot(half),
            m.row(1).abs().dot(half),
            m.row(2).abs().dot(half),
        );
        Aabb::around(center, extent)
    }

    pub(crate) fn validate(&self, slot: Slot) -> Result<(), ObjectError> {
        self.inverse()
            .map(|_| ())
            .ok_or(ObjectError::BadTransform { slot })
    }
}

/// How the scene's time maps to a part's local time `t`: first clamped to the time span, then
/// counted from its start, then, with a cycle interval, taken as the fraction of the current
/// cycle (in `[0, 1)`, as VRML's `TimeSensor` does).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Length of one cycle in seconds; 0 means no cycling.
    pub cycle_interval_secs: f64,
    /// The span `[start, end]` in scene seconds outside which time stands still.
    pub time_span: Option<[f64; 2]>,
}

impl Timing {
    /// The local time at scene time `t_secs`.
    pub fn local(&self, t_secs: f64) -> f64 {
        let t = match self.time_span {
            Some([start, end]) => t_secs.clamp(start, end.max(start)) - start,
            None => t_secs,
        };
        if self.cycle_interval_secs > 0.0 {
            (t / self.cycle_interval_secs).rem_euclid(1.0)
        } else {
            t
        }
    }

    /// Whether scene time `t_secs` lies inside the time span (always, without a span).
    pub fn is_active(&self, t_secs: f64) -> bool {
        self.time_span
            .is_none_or(|[start, end]| t_secs >= start && t_secs <= end)
    }

    pub(crate) fn validate(&self, slot: Slot) -> Result<(), ObjectError> {
        let span_ok = self
            .time_span
            .is_none_or(|[a, b]| a.is_finite() && b.is_finite() && a <= b);
        if !(self.cycle_interval_secs.is_finite() && self.cycle_interval_secs >= 0.0 && span_ok) {
            return Err(ObjectError::BadTiming { slot });
        }
        Ok(())
    }
}

/// An object's time-dependent placement, applied after its static transform: a translation
/// (a formula with outputs `x`, `y`, `z` of `t`) and a rotation by an angle (a formula of `t`,
/// radians) about a fixed axis through the origin.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Motion {
    /// Offset as a function of local time, outputs `x`, `y`, `z`.
    pub translation: Option<Formula>,
    /// The rotation axis (need not be unit length; not zero when `angle` is set).
    pub axis: DVec3,
    /// Rotation angle in radians as a function of local time.
    pub angle: Option<Formula>,
    /// Scene time to local time.
    pub timing: Timing,
}
