//! The reference models of `tests/data/models`, compiled in: the shared workload of the
//! checks, benchmarks and examples of fdsl, render and the tests crate (a few kilobytes of
//! text; `spheres100` is the largest at about 11 KB).

/// Every reference model, name and source: spheres, a hundred spheres with min/max and with
/// R-functions, a gyroid in a sphere, the thesis's watermelon (both ways) and a density
/// script with no surface.
pub const REFERENCE_MODELS: [(&str, &str); 7] = [
    (
        "sphere",
        include_str!("../../tests/data/models/sphere.fdsl"),
    ),
    (
        "spheres100",
        include_str!("../../tests/data/models/spheres100.fdsl"),
    ),
    (
        "spheres100_rfunc",
        include_str!("../../tests/data/models/spheres100_rfunc.fdsl"),
    ),
    (
        "gyroid_sphere",
        include_str!("../../tests/data/models/gyroid_sphere.fdsl"),
    ),
    (
        "watermelon",
        include_str!("../../tests/data/models/watermelon.fdsl"),
    ),
    (
        "watermelon_rfunc",
        include_str!("../../tests/data/models/watermelon_rfunc.fdsl"),
    ),
    (
        "script_field",
        include_str!("../../tests/data/models/script_field.fdsl"),
    ),
];

/// The reference models that bound a surface (all but `script_field`, which is positive
/// everywhere): what the meshers are checked and benchmarked on.
pub fn surface_models() -> impl Iterator<Item = (&'static str, &'static str)> {
    REFERENCE_MODELS
        .into_iter()
        .filter(|(name, _)| *name != "script_field")
}

/// The source of the reference model `name`, if there is one.
pub fn reference_model(name: &str) -> Option<&'static str> {
    REFERENCE_MODELS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, source)| *source)
}

/// The benchmarks' sculpting history (render's `remesh_object` and `remesh_bench`):
/// edit `k` of a golden-angle spiral of `n` over the unit sphere, turned by `phase` radians; a
/// ball of `tool_radius` that carves, adding every fifth time, a single stamp every second
/// time and a two-pose stroke otherwise.
pub fn spiral_edit(k: usize, n: usize, phase: f64, tool_radius: f64) -> crate::object::Edit {
    use crate::object::{Edit, EditOp, Pose, ToolShape};
    use glam::DVec3;
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
