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
