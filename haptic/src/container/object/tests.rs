//! Unit tests of [`super::ObjectContainer`]: affine placement (points, gradients, metric
//! depth), bounds, properties in object coordinates with painting, the force field's mapping,
//! motion, and scenes with groups.

use std::sync::Arc;

use glam::{DQuat, DVec3};

use model::object::{
    Domain, Edit, EditOp, ForceField, Formula, Geometry, Motion, Object, ObjectData, PaintValue,
    Paintable, Physics, Pose, Property, Sampler, Timing, ToolShape, Transform,
};
use model::scene::{Group, GroupId, ObjectId, Scene};

use super::{ObjectContainer, ObjectContainerError};
use crate::container::Container;

fn formula(text: &str) -> Formula {
    Formula::new(text).unwrap()
}

/// The unit ball as a distance (`1 - |p|`), optionally clipped to a domain.
fn ball_data(domain: Option<Domain>) -> ObjectData {
    ObjectData {
        geometry: Some(Geometry {
            domain,
            ..Geometry::implicit(formula("1 - sqrt(x^2 + y^2 + z^2)"))
        }),
        ..ObjectData::default()
    }
}

/// A stretched, turned and moved placement: object x is scaled by 2, z by 0.5.
fn skewed() -> Transform {
    Transform::from_trs(
        DVec3::new(1.0, 2.0, 3.0),
        DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1),
        DVec3::new(2.0, 1.0, 0.5),
    )
}

fn container(data: ObjectData, world_from_parent: Transform) -> ObjectContainer {
    ObjectContainer::from_object(5, &Object::new(data).unwrap(), world_from_parent).unwrap()
}

#[test]
fn affine_placement_maps_points_gradients_and_depths() {
    let mut data = ball_data(None);
    data.transform = skewed();
    let group = Transform::from_trs(
        DVec3::new(-1.0, 0.0, 0.5),
        DQuat::from_rotation_y(0.4),
        DVec3::ONE,
    );
    let world_from_object = group.then(&skewed());
    let mut c = container(data, group);
    assert_eq!(c.id(), 5);
    let to_world = |q: DVec3| world_from_object.point(q);
    assert!(c.value_grad(to_world(DVec3::new(0.9, 0.0, 0.0)), 0.0).0 > 0.0);
    assert!(c.value_grad(to_world(DVec3::new(1.1, 0.0, 0.0)), 0.0).0 < 0.0);
    assert!(c.value_grad(to_world(DVec3::new(0.0, 0.0, 1.05)), 0.0).0 < 0.0);
    // The world gradient is the derivative of the world value (central differences).
    for q in [
        DVec3::new(0.5, 0.2, -0.1),
        DVec3::new(-0.3, 0.6, 0.4),
        DVec3::new(1.2, -0.4, 0.3),
    ] {
        let p = to_world(q);
        let (_, grad) = c.value_grad(p, 0.0);
        let h = 1e-6;
        let numeric = DVec3::from_array([DVec3::X, DVec3::Y, DVec3::Z].map(|axis| {
            (c.value_grad(p + axis * h, 0.0).0 - c.value_grad(p - axis * h, 0.0).0) / (2.0 * h)
        }));
        assert!(
            (grad - numeric).length() < 1e-6 * grad.length(),
            "{grad} vs {numeric}"
        );
    }
    // Near the tip of the long axis (object x, stretched by 2) the metric depth is the world
    // distance to the surface: object depth 0.005 is 0.01 world units.
    let p = to_world(DVec3::new(0.995, 0.0, 0.0));
    let (v, g) = c.value_grad(p, 0.0);
    assert!((v / g.length() - 0.01).abs() < 1e-9, "{}", v / g.length());
    // And near the short axis (object z, squashed by 2): object depth 0.01 is 0.005 world.
    let (v, g) = c.value_grad(to_world(DVec3::new(0.0, 0.0, 0.99)), 0.0);
    assert!((v / g.length() - 0.005).abs() < 1e-9, "{}", v / g.length());
}

#[test]
fn bounds_follow_the_domain_and_are_infinite_without_one() {
    let placement = Transform::translate(DVec3::new(3.0, 0.0, 0.0));
    let c = container(ball_data(Some(Domain::UNIT)), placement);
    let b = c.bounds();
    assert!(
        (b.min - DVec3::new(2.0, -1.0, -1.0)).length() < 1e-12,
        "{b:?}"
    );
    assert!(
        (b.max - DVec3::new(4.0, 1.0, 1.0)).length() < 1e-12,
        "{b:?}"
    );
    let unbounded = container(ball_data(None), placement).bounds();
    assert!(unbounded.min == DVec3::NEG_INFINITY && unbounded.max == DVec3::INFINITY);
    // A union edit outside the domain widens the box.
    let mut object = Object::new(ball_data(Some(Domain::UNIT))).unwrap();
    object
        .apply(Edit::stamp(
            EditOp::Union,
            ToolShape::Sphere { radius: 0.5 },
            Pose::at(DVec3::new(2.0, 0.0, 0.0)),
        ))
        .unwrap();
    let mut c = ObjectContainer::from_object(1, &object, Transform::IDENTITY).unwrap();
    assert!(c.bounds().contains(DVec3::new(2.4, 0.0, 0.0)));
    assert!(c.value_grad(DVec3::new(2.4, 0.0, 0.0), 0.0).0 > 0.0);
}

#[test]
fn properties_are_read_in_object_coordinates_and_painting_overrides() {
    let mut data = ball_data(Some(Domain::UNIT));
    data.transform = Transform::from_trs(
        DVec3::new(10.0, 0.0, 0.0),
        DQuat::IDENTITY,
        DVec3::splat(2.0),
    );
    data.physics = Physics {
        tension: Some(Property::new(formula("0.5 + 0.1 * x"))),
        zone_depth: Some(Property::new(formula("0.04"))),
        friction: Some(Property {
            formula: formula("0.3"),
            enabled: false,
        }),
        ..Physics::default()
    }
    .into();
    let mut object = Object::new(data).unwrap();
    object
        .apply(Edit::stamp(
            EditOp::Paint {
                property: Paintable::Density,
                value: PaintValue::Scalar(0.9),
            },
            ToolShape::Sphere { radius: 0.3 },
            Pose::at(DVec3::new(0.5, 0.0, 0.0)),
        ))
        .unwrap();
    let mut c = ObjectContainer::from_object(1, &object, Transform::IDENTITY).unwrap();
    // World (11, 0, 0) is object (0.5, 0, 0).
    let inside_paint = DVec3::new(11.0, 0.0, 0.0);
    assert!((c.tension(inside_paint, 0.0).unwrap() - 0.55).abs() < 1e-12);
    assert_eq!(c.friction(inside_paint, 0.0), None, "disabled");
    assert_eq!(c.density(inside_paint, 0.0), Some(0.9), "painted");
    assert_eq!(c.density(DVec3::new(9.0, 0.0, 0.0), 0.0), None, "unpainted");
    // Scene units: the object's scale does not touch the zone depth.
    assert_eq!(c.zone_depth(inside_paint, 0.0), Some(0.04));
    assert_eq!(c.field_at(inside_paint, 0.0), None, "no field");
}

#[test]
fn force_field_turns_with_the_object_and_keeps_its_length() {
    let mut data = ball_data(Some(Domain::UNIT));
    data.transform = Transform::from_trs(
        DVec3::ZERO,
        DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2),
        DVec3::splat(3.0),
    );
    data.physics.force = Some(ForceField {
        formula: formula("x = 0.5 + 0.5 * t; y = 0; z = 0;"),
        parameters: [[0.0, 1.0]; 3],
        timing: Timing {
            cycle_interval_secs: 2.0,
            time_span: None,
        },
        enabled: true,
    });
    let mut c = container(data, Transform::IDENTITY);
    // Object +x is world +y; the local time is the fraction of the 2 s cycle.
    let f = c.field_at(DVec3::new(0.0, 1.0, 0.0), 1.0).unwrap();
    assert!((f - DVec3::new(0.0, 0.75, 0.0)).length() < 1e-12, "{f}");
    let f = c.field_at(DVec3::new(0.0, 1.0, 0.0), 2.0).unwrap();
    assert!((f - DVec3::new(0.0, 0.5, 0.0)).length() < 1e-12, "{f}");
}

#[test]
fn a_moving_object_is_felt_where_it_is() {
    let mut data = ball_data(Some(Domain::UNIT));
    data.motion = Some(Motion {
        translation: Some(formula("x = t; y = 0; z = 0;")),
        axis: DVec3::Y,
        angle: None,
        timing: Timing::default(),
    });
    let mut c = container(data, Transform::IDENTITY);
    assert_eq!(c.bounds().max, DVec3::INFINITY, "moving: no fixed box");
    for t in [0.0, 0.5, 2.0] {
        let centre = DVec3::new(t, 0.0, 0.0);
        assert!((c.value_grad(centre, t).0 - 1.0).abs() < 1e-12, "t = {t}");
        assert!(c.value_grad(centre + DVec3::new(1.2, 0.0, 0.0), t).0 < 0.0);
        assert_eq!(c.world_from_object(t).point(DVec3::ZERO), centre);
    }
}

#[test]
fn scenes_become_containers_by_id_with_group_placements() {
    let mut scene = Scene::new();
    let group = Group {
        name: "shelf".into(),
        parent: None,
        transform: Transform::translate(DVec3::new(0.0, 5.0, 0.0)),
    };
    scene.set_group(GroupId(1), group).unwrap();
    scene
        .create(ObjectId(7), ball_data(Some(Domain::UNIT)), Some(GroupId(1)))
        .unwrap();
    let mut skewed_data = ball_data(Some(Domain::UNIT));
    skewed_data.transform = skewed();
    scene.create(ObjectId(3), skewed_data, None).unwrap();
    // Felt objects have physics; one without is seen, not felt, and left out.
    let felt = |id: u64, scene: &mut Scene| {
        let tension = model::object::Property::new(formula("1"));
        let object = scene.object_mut(ObjectId(id)).unwrap();
        object
            .set(model::object::Field::Tension(Some(tension)))
            .unwrap();
    };
    felt(7, &mut scene);
    felt(3, &mut scene);
    scene.create(ObjectId(5), ball_data(None), None).unwrap();
    let (mut containers, refused) = ObjectContainer::from_scene(&scene);
    assert!(refused.is_empty());
    let ids: Vec<u64> = containers.iter().map(|c| c.id()).collect();
    assert_eq!(ids, [3, 7]);
    assert!(containers[1].value_grad(DVec3::new(0.0, 5.5, 0.0), 0.0).0 > 0.0);
    assert!(containers[1].value_grad(DVec3::ZERO, 0.0).0 < 0.0);
    // The same answers as the object model's own world-space sampler.
    let mut world = scene.sampler();
    let p = DVec3::new(1.3, 2.2, 2.9);
    let (v, g) = world.gradient(ObjectId(3), p, 0.0).unwrap();
    let (cv, cg) = containers[0].value_grad(p, 0.0);
    assert!(
        (v - cv).abs() < 1e-12 && (g - cg).length() < 1e-12,
        "{v} {g} vs {cv} {cg}"
    );
}

#[test]
fn a_degenerate_placement_is_refused() {
    let sampler = Sampler::new(Arc::new(Object::new(ball_data(None)).unwrap()));
    let flat = Transform::from_trs(DVec3::ZERO, DQuat::IDENTITY, DVec3::new(1.0, 0.0, 1.0));
    assert_eq!(
        ObjectContainer::new(4, sampler, flat).unwrap_err(),
        ObjectContainerError::BadPlacement { id: 4 }
    );
}

#[test]
fn a_separate_container_is_felt_instead_of_the_geometry() {
    use model::object::Shape;
    // A small visible ball inside an invisible mesh cube: the hand feels the cube.
    let cube = model::mesh::shapes::cube(DVec3::splat(-1.0), DVec3::splat(1.0));
    let mut data = ball_data(None);
    data.geometry = Some(Geometry::implicit(formula("0.2 - sqrt(x^2 + y^2 + z^2)")));
    data.physics.container = Some(Geometry {
        shape: Shape::Mesh(Arc::new(cube)),
        domain: None,
        transform: Transform::IDENTITY,
    });
    data.transform = Transform::translate(DVec3::new(0.0, 2.0, 0.0));
    let mut c = container(data, Transform::IDENTITY);
    let b = c.bounds();
    assert_eq!(
        (b.min, b.max),
        (DVec3::new(-1.0, 1.0, -1.0), DVec3::new(1.0, 3.0, 1.0))
    );
    let (v, g) = c.value_grad(DVec3::new(0.7, 2.0, 0.0), 0.0);
    assert!(
        (v - 0.3).abs() < 1e-9 && (g - DVec3::NEG_X).length() < 1e-9,
        "{v} {g}"
    );
    assert!(c.value_grad(DVec3::new(1.2, 2.0, 0.0), 0.0).0 < 0.0);
}

/// A formula a peer may send that unrolls to tens of thousands of instructions: a loop of
/// 1000 trips, padded with spaces to 2 KiB so that the object model's unrolling budget
/// (`fdsl::limits::formula_node_budget`) admits it.
fn costly_ball() -> ObjectData {
    let mut text = String::from(
        "function frep(x,y,z,t) { s = 0; for (i = 0; i < 1000; i = i + 1) { \
         s = s + sin(x*i + y)*cos(z*i - x) + sqrt(abs(y*i + z)); } \
         return 1 - sqrt(x^2+y^2+z^2) + 1e-9*s; }",
    );
    text.push_str(&" ".repeat(2048 - text.len()));
    let mut data = ball_data(Some(Domain::UNIT));
    data.geometry = Some(Geometry {
        domain: Some(Domain::UNIT),
        ..Geometry::implicit(formula(&text))
    });
    data.physics.tension = Some(Property::new(formula("1")));
    data
}

#[test]
fn an_object_too_costly_for_the_tick_is_refused_by_name_and_the_rest_is_felt() {
    let costly = Object::new(costly_ball()).unwrap();
    let instructions = costly.touch_instructions();
    assert!(
        instructions > super::MAX_TOUCH_INSTRUCTIONS,
        "{instructions}"
    );
    let mut scene = Scene::new();
    scene.create(ObjectId(1), costly_ball(), None).unwrap();
    let mut cheap = ball_data(Some(Domain::UNIT));
    cheap.physics.tension = Some(Property::new(formula("1")));
    scene.create(ObjectId(2), cheap, None).unwrap();
    let (containers, refused) = ObjectContainer::from_scene(&scene);
    assert_eq!(containers.iter().map(|c| c.id()).collect::<Vec<_>>(), [2]);
    assert_eq!(refused.len(), 1);
    let (id, why) = &refused[0];
    assert_eq!(*id, ObjectId(1));
    assert!(
        matches!(why, ObjectContainerError::TooCostly { instructions: n, .. } if *n == instructions)
    );
    let message = why.to_string();
    assert!(message.contains("too costly to feel"), "{message}");
    // Every reference model is well within the budget.
    for (name, source) in fdsl::models::REFERENCE_MODELS {
        let mut data = ball_data(Some(Domain::UNIT));
        data.geometry = Some(Geometry::implicit(formula(source)));
        let n = Object::new(data).unwrap().touch_instructions();
        assert!(n * 4 < super::MAX_TOUCH_INSTRUCTIONS, "{name}: {n}");
    }
}
