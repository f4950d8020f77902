//! The sampling sphere (thesis, Figure 7.11): the live touch tool drawn as a sphere coloured by
//! the density under it, so that a user exploring a scan sees which tissue the hand is in as
//! well as feeling it.

use glam::DVec3;
use model::object::Paintable;
use model::scene::{ObjectId, Scene};

/// The sampling sphere's radius, as a fraction of the haptic zone's width.
pub const SAMPLING_RADIUS_OF_ZONE: f64 = 0.02;

/// The density of object `id` at `at` (scene coordinates) at scene time `t`: `None` when the
/// object is gone, `at` is outside its solid, or it has no density there.
pub fn density_at(scene: &Scene, id: u64, at: DVec3, t: f64) -> Option<f64> {
    let entry = scene.scene_object(ObjectId(id))?;
    let mut sampler = entry.object.sampler();
    let scene_from_object =
        model::scene::world_from_object(&scene.world_from_group(entry.group), &mut sampler, t);
    let p = scene_from_object.inverse()?.point(at);
    if sampler.container_value(p, t) < 0.0 {
        return None;
    }
    sampler
        .scalar(Paintable::Density, p, t)
        .filter(|d| d.is_finite())
}

/// The density under the tool at `at`: in the object the servo reports touching (`top`),
/// else in the first object, by id, whose solid holds `at` and has a density there. Looking
/// through every object costs a sampler each, so a caller whose servo has reported a scene
/// passes its `top` and calls this only before (the window, every frame while touching).
pub fn density_under(scene: &Scene, top: Option<u64>, at: DVec3, t: f64) -> Option<f64> {
    if let Some(d) = top.and_then(|id| density_at(scene, id, at, t)) {
        return Some(d);
    }
    scene
        .objects()
        .find_map(|(id, _)| density_at(scene, id.0, at, t))
}

/// The sampling sphere's colour for a density: grey where there is none, then blue (0) through
/// green (0.5) to red (1 and more), opaque.
pub fn sampling_colour(density: Option<f64>) -> [f32; 4] {
    let Some(d) = density else {
        return [0.6, 0.6, 0.6, 1.0];
    };
    let d = d.clamp(0.0, 1.0) as f32;
    let (r, g, b) = if d < 0.5 {
        let f = d / 0.5;
        (0.1, 0.3 + 0.6 * f, 0.9 - 0.7 * f)
    } else {
        let f = (d - 0.5) / 0.5;
        (0.1 + 0.85 * f, 0.9 - 0.75 * f, 0.2 - 0.1 * f)
    };
    [r, g, b, 1.0]
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::object::{Formula, Geometry, ObjectData, Property};

    #[test]
    fn the_density_under_the_tool_is_the_objects_and_colours_ramp_with_it() {
        let mut scene = Scene::new();
        let mut data = ObjectData {
            geometry: Some(Geometry::implicit(Formula::new("1-x^2-y^2-z^2").unwrap())),
            transform: model::object::Transform::from_trs(
                DVec3::new(2.0, 0.0, 0.0),
                glam::DQuat::IDENTITY,
                DVec3::ONE,
            ),
            ..ObjectData::default()
        };
        data.physics.density = Some(Property::new(Formula::new("0.5 + 0.4*x").unwrap()));
        scene
            .insert_object(ObjectId(3), model::object::Object::new(data).unwrap(), None)
            .unwrap();
        // Scene (2.5, 0, 0) is the object's (0.5, 0, 0): density 0.7.
        let d = density_at(&scene, 3, DVec3::new(2.5, 0.0, 0.0), 0.0).unwrap();
        assert!((d - 0.7).abs() < 1e-12, "{d}");
        assert_eq!(density_at(&scene, 3, DVec3::new(0.0, 0.0, 0.0), 0.0), None);
        assert_eq!(density_at(&scene, 4, DVec3::new(2.5, 0.0, 0.0), 0.0), None);
        // Without the servo's word (or with a stale one), the object holding the point.
        let under = |top| density_under(&scene, top, DVec3::new(2.5, 0.0, 0.0), 0.0);
        assert_eq!(under(None), Some(d));
        assert_eq!(under(Some(4)), Some(d));
        assert_eq!(
            density_under(&scene, None, DVec3::new(9.0, 0.0, 0.0), 0.0),
            None
        );
        let (low, high) = (sampling_colour(Some(0.1)), sampling_colour(Some(0.95)));
        assert!(low[2] > low[0] && high[0] > high[2], "{low:?} {high:?}");
        assert_ne!(sampling_colour(None), low);
    }
}
