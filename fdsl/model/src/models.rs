//! The reference sculpting workload of the object model: the edit history the benchmarks of
//! model, render and the app replay (the reference formulas themselves are the language's,
//! `fdsl::models`).

use glam::DVec3;

use crate::object::{
    Domain, Edit, EditOp, Formula, Geometry, Object, ObjectData, ObjectError, Pose, ToolShape,
};

/// The benchmarks' sculpting history (render's `remesh_object` and `remesh_bench`):
/// edit `k` of a golden-angle spiral of `n` over the unit sphere, turned by `phase` radians; a
/// ball of `tool_radius` that carves, adding every fifth time, a single stamp every second
/// time and a two-pose stroke otherwise.
pub fn spiral_edit(k: usize, n: usize, phase: f64, tool_radius: f64) -> Edit {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let y = 1.0 - 2.0 * ((k % n) as f64 + 0.5) / n as f64;
    let ring = (1.0 - y * y).max(0.0).sqrt();
    let phi = golden * k as f64 + phase;
    let at = DVec3::new(ring * phi.cos(), y, ring * phi.sin());
    let op = if k % 5 == 4 {
        EditOp::Union
    } else {
        EditOp::Subtract
    };
    let tool = ToolShape::Sphere {
        radius: tool_radius,
    };
    if k.is_multiple_of(2) {
        Edit::stamp(op, tool, Pose::at(at))
    } else {
        let side = at.any_orthonormal_vector() * 0.03;
        Edit::stroke(op, tool, vec![Pose::at(at - side), Pose::at(at + side)])
    }
}

/// The unit ball (`1-sqrt(x^2+y^2+z^2)` in a 2.2-unit domain) carved by the first `n` edits
/// of [`spiral_edit`] with tools of `tool_radius`, indexed: the object the benchmarks remesh.
pub fn spiral_ball(n: usize, tool_radius: f64) -> Result<Object, ObjectError> {
    let mut object = Object::new(ObjectData {
        geometry: Some(Geometry::implicit_in(
            Formula::new("1-sqrt(x^2+y^2+z^2)")?,
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        ..ObjectData::default()
    })?;
    for k in 0..n {
        object.apply(spiral_edit(k, n, 0.0, tool_radius))?;
    }
    object.prepare();
    Ok(object)
}
