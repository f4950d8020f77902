//! An object's geometry: an F-Rep solid, a parametric curve, surface or solid, or an imported
//! triangle mesh, in its own domain and placed by its own instance transform.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::space::{Domain, Transform};
use super::{Formula, ObjectError, Slot};
use crate::mesh::TriMesh;

/// What a parametric definition sweeps: its formula has outputs `x`, `y`, `z` of `u` (curve),
/// `u, v` (surface) or `u, v, w` (solid), and `t`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ParametricKind {
    /// A curve of `u`.
    Curve,
    /// A surface of `u, v`.
    Surface,
    /// A solid of `u, v, w`.
    Solid,
}

impl ParametricKind {
    /// How many parameters it reads.
    pub fn dimensions(self) -> usize {
        match self {
            ParametricKind::Curve => 1,
            ParametricKind::Surface => 2,
            ParametricKind::Solid => 3,
        }
    }
}

/// The shape itself.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Shape {
    /// The solid `f(x, y, z, t) >= 0`: the thesis's implicit surface `f = 0` and explicit solid
    /// `g >= 0` are both this.
    Implicit(Formula),
    /// Points `(x, y, z)(u, v, w, t)` over the parameter ranges.
    Parametric {
        /// Outputs `x`, `y`, `z`.
        formula: Formula,
        /// Curve, surface or solid.
        kind: ParametricKind,
        /// `[lo, hi]` of `u`, `v`, `w` (unused ones are ignored).
        parameters: [[f64; 2]; 3],
    },
    /// An imported triangle mesh: inside by ray parity, value the signed distance (positive
    /// inside).
    Mesh(#[serde(with = "mesh_serde")] Arc<TriMesh>),
}

/// A mesh travels as its vertices and triangles and is validated again when read.
mod mesh_serde {
    use std::sync::Arc;

    use serde::de::Error;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use crate::mesh::TriMesh;

    pub fn serialize<S: Serializer>(mesh: &Arc<TriMesh>, s: S) -> Result<S::Ok, S::Error> {
        (mesh.positions(), mesh.triangles()).serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Arc<TriMesh>, D::Error> {
        let (positions, triangles) = <(Vec<[f32; 3]>, Vec<[u32; 3]>)>::deserialize(d)?;
        TriMesh::new(positions, triangles)
            .map(Arc::new)
            .map_err(D::Error::custom)
    }
}

/// Geometry: a shape in its own domain, mapped into the object's space.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Geometry {
    /// The shape.
    pub shape: Shape,
    /// Where the shape is defined; outside it the solid is clipped away. `None` is unbounded.
    pub domain: Option<Domain>,
    /// Geometry space to object space.
    pub transform: Transform,
}

impl Geometry {
    /// An implicit solid with no domain and no transform.
    pub fn implicit(formula: Formula) -> Geometry {
        Geometry {
            shape: Shape::Implicit(formula),
            domain: None,
            transform: Transform::IDENTITY,
        }
    }

    /// An implicit solid clipped to `domain`.
    pub fn implicit_in(formula: Formula, domain: Domain) -> Geometry {
        Geometry {
            domain: Some(domain),
            ..Geometry::implicit(formula)
        }
    }

    pub(crate) fn validate(&self, slot: Slot) -> Result<(), ObjectError> {
        if let Some(d) = &self.domain {
            d.validate(slot)?;
        }
        self.transform.validate(slot)?;
        if let Shape::Parametric { parameters, .. } = &self.shape {
            let ok = parameters
                .iter()
                .all(|[a, b]| a.is_finite() && b.is_finite() && a <= b);
            if !ok {
                return Err(ObjectError::BadParameters { slot });
            }
        }
        Ok(())
    }
}
