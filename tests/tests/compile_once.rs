//! Issue 18's "compile once", counted end to end: a scene whose objects hold every kind of
//! formula (implicit and parametric geometry, colour map, parametric colours, transparency,
//! shininess, geometric texture, container, tension, friction, zone depth, density, force
//! field, motion) is built, then meshed, coloured and animated as `render` does for the
//! window and `sculpt render`, made into haptic containers as the servo's snapshots are, and
//! sampled. Each distinct formula text must be compiled exactly once, when its object is
//! built; a second scene with the same formulas compiles nothing.
//!
//! Compilations are counted by `fdsl::n_compiled_on_this_thread`, which
//! counts every `fdsl::Function::compile` on the calling thread. Everything here runs on the
//! test's thread: render meshes and colours on the calling thread, and haptic containers are
//! built where they are asked for (the servo thread only samples them, and is not started).

use fdsl::n_compiled_on_this_thread;
use glam::DVec3;
use haptic::container::Container;
use haptic::container::object::ObjectContainer;
use model::object::compiled;
use model::object::{
    Appearance, ColorDef, ColorMap, ColorSlot, Domain, Edit, EditOp, ForceField, Formula, Geometry,
    Motion, ObjectData, Paintable, ParametricKind, Physics, Pose, Property, Shape, Timing,
    ToolShape, Transform,
};
use model::scene::{ObjectId, Scene};
use render::animation::{Animator, FrameBudget};
use render::appearance::CompiledAppearance;
use render::mesh::Mesh;
use render::mesh::object_field::{ObjectField, mesh_bounds};
use render::mesh::octree::{MeshSettings, mesh};
use render::snapshot::{SnapshotSettings, build};

/// The formulas of the scene, each text distinct (a marker comment keeps them apart from
/// other tests' formulas in the process's cache).
const GEOMETRY: &str = "0.6 + 0.05*sin(t) - sqrt(x^2 + y^2 + z^2) /* compile_once */";
const DIFFUSE: &str = "y + 0.5 /* compile_once */";
const AMBIENT: &str = "r = 0.1; g = 0.1*abs(x); b = 0.2; /* compile_once */";
const SPECULAR: &str = "r = 0.5; g = 0.5; b = 0.5 + 0.1*z; /* compile_once */";
const TRANSPARENCY: &str = "0.1 + 0.05*x /* compile_once */";
const SHININESS: &str = "0.4 + 0.1*y /* compile_once */";
const DISPLACEMENT: &str = "0.01*sin(10*x) /* compile_once */";
const CONTAINER: &str = "0.7 - sqrt(x^2 + y^2 + z^2) /* compile_once */";
const TENSION: &str = "0.8 - 0.1*z /* compile_once */";
const FRICTION: &str = "0.3 + 0.1*x /* compile_once */";
const ZONE_DEPTH: &str = "0.05 + 0.01*y /* compile_once */";
const DENSITY: &str = "0.5 + 0.2*sin(8*x) /* compile_once */";
const FORCE: &str = "x = -v; y = u; z = 0.1*t; /* compile_once */";
const TRANSLATION: &str = "x = 0.1*sin(t); y = 0; z = 0; /* compile_once */";
const ANGLE: &str = "0.5*t /* compile_once */";
const SURFACE: &str = "x = cos(u)*(1 + 0.1*sin(t)); y = sin(u); z = v; /* compile_once */";
const CUBE: &str = "0.5 - max(abs(x), max(abs(y), abs(z))) /* compile_once */";

/// Every distinct formula of [`scene`].
const FORMULAS: [&str; 17] = [
    GEOMETRY,
    DIFFUSE,
    AMBIENT,
    SPECULAR,
    TRANSPARENCY,
    SHININESS,
    DISPLACEMENT,
    CONTAINER,
    TENSION,
    FRICTION,
    ZONE_DEPTH,
    DENSITY,
    FORCE,
    TRANSLATION,
    ANGLE,
    SURFACE,
    CUBE,
];

fn formula(text: &str) -> Formula {
    Formula::new(text).expect("a short formula")
}

fn unit_box(side: f64) -> Domain {
    Domain::new(DVec3::ZERO, DVec3::splat(side))
}

/// An implicit solid with every appearance and physics formula, moving.
fn everything() -> ObjectData {
    ObjectData {
        name: "everything".into(),
        geometry: Some(Geometry::implicit_in(formula(GEOMETRY), unit_box(1.6))),
        appearance: Appearance {
            diffuse: Some(ColorDef::Map {
                formula: formula(DIFFUSE),
                map: ColorMap {
                    keys: vec![(0.0, [1.0, 0.0, 0.0]), (1.0, [0.0, 0.0, 1.0])],
                },
            }),
            ambient: Some(ColorDef::Rgb(formula(AMBIENT))),
            specular: Some(ColorDef::Rgb(formula(SPECULAR))),
            transparency: Some(formula(TRANSPARENCY)),
            shininess: Some(formula(SHININESS)),
            displacement: Some(formula(DISPLACEMENT)),
            ..Appearance::default()
        }
        .into(),
        physics: Physics {
            container: Some(Geometry::implicit_in(formula(CONTAINER), unit_box(1.6))),
            tension: Some(Property::new(formula(TENSION))),
            friction: Some(Property::new(formula(FRICTION))),
            zone_depth: Some(Property::new(formula(ZONE_DEPTH))),
            density: Some(Property::new(formula(DENSITY))),
            force: Some(ForceField {
                formula: formula(FORCE),
                parameters: [[-1.0, 1.0]; 3],
                timing: Timing::default(),
                enabled: true,
            }),
            ..Physics::default()
        }
        .into(),
        motion: Some(Motion {
            translation: Some(formula(TRANSLATION)),
            axis: DVec3::Z,
            angle: Some(formula(ANGLE)),
            timing: Timing::default(),
        }),
        ..ObjectData::default()
    }
}

/// A parametric surface of time.
fn surface() -> ObjectData {
    ObjectData {
        name: "surface".into(),
        geometry: Some(Geometry {
            shape: Shape::Parametric {
                formula: formula(SURFACE),
                kind: ParametricKind::Surface,
                parameters: [[0.0, 6.2], [0.0, 1.0], [0.0, 0.0]],
            },
            domain: None,
            transform: Transform::translate(DVec3::new(3.0, 0.0, 0.0)),
        }),
        ..ObjectData::default()
    }
}

/// The scene: the two objects above and a sculpted cube (carved and painted), whose
/// diffuse colour is the same colour-map formula as the first object's.
fn scene() -> Scene {
    let mut scene = Scene::new();
    scene
        .create(ObjectId(1), everything(), None)
        .expect("valid");
    scene.create(ObjectId(2), surface(), None).expect("valid");
    let cube = ObjectData {
        name: "cube".into(),
        geometry: Some(Geometry::implicit_in(formula(CUBE), unit_box(1.2))),
        appearance: everything().appearance,
        transform: Transform::translate(DVec3::new(-3.0, 0.0, 0.0)),
        ..ObjectData::default()
    };
    scene.create(ObjectId(3), cube, None).expect("valid");
    let ball = ToolShape::Sphere { radius: 0.2 };
    let carve = Edit::stamp(EditOp::Subtract, ball, Pose::at(DVec3::new(0.5, 0.5, 0.5)));
    scene.apply(ObjectId(3), carve).expect("an edit");
    let paint = Edit::stamp(
        EditOp::Paint {
            property: Paintable::Density,
            value: model::object::PaintValue::Scalar(0.9),
        },
        ball,
        Pose::at(DVec3::ZERO),
    );
    scene.apply(ObjectId(3), paint).expect("an edit");
    scene.prepare();
    scene
}

/// What the app does with a scene: picture it, animate it, colour meshes as the window's
/// mesher does, build the haptic snapshot and feel it, and sample it.
fn use_scene(scene: &Scene) {
    let settings = SnapshotSettings {
        depth: 4,
        force_arrows: 3,
        ..SnapshotSettings::default()
    };
    let built = build(scene, &settings).expect("good settings");
    assert!(
        built.objects.iter().all(|o| o.skipped.is_none()),
        "{:?}",
        built.objects
    );
    assert!(built.objects.iter().all(|o| o.n_triangles > 0));

    let mut animator = Animator::new(scene, &settings).expect("good settings");
    for frame_idx in 1..4 {
        let stats = animator.frame(0.1 * f64::from(frame_idx), FrameBudget { blocks_max: 64 });
        assert!(
            !stats.remeshed.is_empty(),
            "shapes of time are meshed again"
        );
    }

    // The window's mesher: each object through `ObjectField`, coloured by its appearance.
    for (_, entry) in scene.objects() {
        let object = &entry.object;
        let mut mesh = match mesh_bounds(object, settings.depth) {
            Some(bounds) => mesh(
                &mut ObjectField::new(object, 0.0),
                &MeshSettings {
                    bounds,
                    depth: settings.depth,
                },
            )
            .expect("meshes"),
            None => Mesh::default(),
        };
        // The app's mesher and render's own paths take the object's tapes.
        let mut appearance = CompiledAppearance::of(object);
        appearance.apply(&mut mesh, 0.5);
    }

    let (mut containers, refused) = ObjectContainer::from_scene(scene);
    assert!(refused.is_empty());
    for container in &mut containers {
        for p in [
            DVec3::ZERO,
            DVec3::new(0.3, -0.2, 0.1),
            DVec3::new(3.0, 0.5, 0.0),
            DVec3::new(-2.7, 0.1, 0.2),
        ] {
            let (value, _) = container.value_grad(p, 0.25);
            assert!(value.is_finite());
            container.tension(p, 0.25);
            container.friction(p, 0.25);
            container.density(p, 0.25);
            container.zone_depth(p, 0.25);
            container.field_at(p, 0.25);
        }
    }

    let mut sampler = scene.sampler();
    for id in [ObjectId(1), ObjectId(2), ObjectId(3)] {
        let p = DVec3::new(0.1, 0.2, 0.3);
        sampler.value(id, p, 0.5);
        sampler.color(id, ColorSlot::Diffuse, p, 0.5);
        sampler.scalar(id, Paintable::Density, p, 0.5);
        sampler.force(id, p, 0.5);
    }
}

#[test]
fn each_formula_is_compiled_once_from_text_to_pixels_and_forces() {
    compiled::clear();
    let before = n_compiled_on_this_thread();
    let first = scene();
    let n_building = n_compiled_on_this_thread() - before;
    use_scene(&first);
    let n_total = n_compiled_on_this_thread() - before;
    println!("compilations: {n_building} building the scene, {n_total} in all");
    assert_eq!(
        n_building,
        FORMULAS.len() as u64,
        "building the objects compiles each distinct formula once"
    );
    assert_eq!(
        n_total,
        FORMULAS.len() as u64,
        "render, haptic and sampling compiled formulas again"
    );

    // The same formulas in new objects: everything comes from the cache.
    let before = n_compiled_on_this_thread();
    let second = scene();
    use_scene(&second);
    assert_eq!(
        n_compiled_on_this_thread() - before,
        0,
        "a second scene with the same formulas compiled again"
    );
}
