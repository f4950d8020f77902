//! FVRML reading, writing and round trips: the thesis's Figures 7.4, 7.8 and 7.14 as printed,
//! a hand-written watermelon, standard VRML shapes, transforms, DEF/USE, Inline and errors.
#![allow(clippy::unwrap_used, reason = "test helpers unwrap")]

use std::collections::BTreeMap;

use fdsl::Severity;
use formats::fvrml::{self, Issue, LoadOptions, Loaded};
use glam::{DQuat, DVec3};
use model::object::{
    Axis, ColorDef, ColorSlot, Edit, EditOp, FitError, Object, ObjectData, PaintValue, Paintable,
    ParametricKind, Pose, Shape, ToolShape, fit_domain,
};
use model::scene::{GroupId, ObjectId, Scene};

const FIGURE_7_4: &str = include_str!("../../../tests/data/scenes/figure_7_4.wrl");
const FIGURE_7_8: &str = include_str!("../../../tests/data/scenes/figure_7_8.wrl");
const FIGURE_7_14: &str = include_str!("../../../tests/data/scenes/figure_7_14.wrl");
const WATERMELON: &str = include_str!("../../../scenes/watermelon.wrl");
const WATERMELON_FDSL: &str = include_str!("../../../tests/data/models/watermelon.fdsl");

fn no_files(path: &str) -> Result<Vec<u8>, String> {
    Err(format!("no file {path}"))
}

fn load(text: &str) -> Loaded {
    match fvrml::load(text, &LoadOptions::default(), &mut no_files) {
        Ok(loaded) => loaded,
        Err(e) => panic!("load failed:\n{e}"),
    }
}

fn load_err(text: &str) -> Vec<Issue> {
    match fvrml::load(text, &LoadOptions::default(), &mut no_files) {
        Ok(_) => panic!("loaded, but an error was expected"),
        Err(e) => e.issues,
    }
}

fn objects(scene: &Scene) -> Vec<(ObjectId, Option<GroupId>, &Object)> {
    scene
        .objects()
        .map(|(id, o)| (id, o.group, &o.object))
        .collect()
}

/// The warning containing `text`, with its line.
fn warning_line(issues: &[Issue], text: &str) -> u32 {
    let found: Vec<&Issue> = issues.iter().filter(|i| i.message.contains(text)).collect();
    assert!(!found.is_empty(), "no issue mentions {text:?}: {issues:#?}");
    found[0].location.line
}

fn lines_of(issues: &[Issue], text: &str) -> Vec<u32> {
    issues
        .iter()
        .filter(|i| i.message.contains(text))
        .map(|i| i.location.line)
        .collect()
}

/// Saving, writing, parsing and loading again gives the same scene, and saving that again
/// gives the same text; the only warnings are about solids no domain fits (an unbounded
/// solid says so on every load).
fn assert_round_trip(scene: &Scene) {
    let text = fvrml::write(&fvrml::save(scene));
    let again = load(&text);
    assert_eq!(&again.scene, scene, "scene changed through:\n{text}");
    let other: Vec<&Issue> = again
        .warnings
        .iter()
        .filter(|w| !w.message.starts_with("no domain fits"))
        .collect();
    assert!(other.is_empty(), "{other:#?}");
    assert_eq!(fvrml::write(&fvrml::save(&again.scene)), text);
}

#[test]
fn figure_7_4_loads_as_printed() {
    let loaded = load(FIGURE_7_4);
    let objs = objects(&loaded.scene);
    assert_eq!(objs.len(), 1);
    let (id, group, object) = objs[0];
    assert_eq!((id, group), (ObjectId(0), None));
    let data = object.data();

    // The invisible cylindrical container is the geometry itself, clipped to its box.
    let geometry = data.geometry.as_ref().unwrap();
    assert_eq!(
        geometry.shape,
        Shape::Implicit(model::object::Formula::new("(1.6^2-x^2-z^2) &y& (0.7-y)").unwrap())
    );
    let domain = geometry.domain.unwrap();
    assert_eq!(domain.center, DVec3::new(0.0, 0.35, 0.0));
    assert_eq!(domain.size, DVec3::new(3.2, 0.7, 3.2));
    assert!(data.physics.container.is_none());
    let mut s = object.sampler();
    assert!(s.container_value(DVec3::new(0.0, 0.35, 0.0), 0.0) > 0.0);
    assert!(s.container_value(DVec3::new(1.5, 0.1, 0.0), 0.0) > 0.0);
    assert!(s.container_value(DVec3::new(1.7, 0.35, 0.0), 0.0) < 0.0);
    assert!(s.container_value(DVec3::new(0.0, 0.8, 0.0), 0.0) < 0.0);

    assert_eq!(
        data.appearance.transparency.as_ref().map(|f| f.as_str()),
        Some("0")
    );
    let friction = data.physics.friction.as_ref().unwrap();
    assert!(!friction.enabled);
    assert!(data.physics.tension.is_none());

    let force = data.physics.force.as_ref().unwrap();
    assert!(force.enabled);
    assert_eq!(force.parameters, [[-1.0, 1.0], [0.0, 1.0], [-1.0, 1.0]]);
    assert!(
        force
            .formula
            .as_str()
            .contains("function parametric_z (u, v, w)")
    );
    // The helical field is a unit vector everywhere in the cylinder.
    for p in [
        DVec3::new(0.3, 0.1, -0.4),
        DVec3::new(-1.2, 0.6, 0.5),
        DVec3::new(1.0, 0.35, 1.0),
        DVec3::new(0.0, 0.05, 1.5),
    ] {
        let f = s.force(p, 0.0).unwrap();
        assert!((f.length() - 1.0).abs() < 1e-9, "{p}: {f}");
    }
    // At the +x face centre: u = 1, v = 0.5, w = 0.
    let f = s.force(DVec3::new(1.6, 0.35, 0.0), 0.0).unwrap();
    let expected = DVec3::new(-0.1, -0.05, -1.0).normalize();
    assert!((f - expected).length() < 1e-9, "{f}");

    let w = &loaded.warnings;
    assert!(w.iter().all(|i| i.severity == Severity::Warning));
    assert_eq!(
        warning_line(
            w,
            "remote url not fetched: http://......MovieTextureWhirlpool.wrl"
        ),
        20
    );
    assert_eq!(warning_line(w, "typographic quotes"), 3);
    assert_eq!(warning_line(w, "`friction` belongs in the surface"), 9);
    assert_round_trip(&loaded.scene);
}

#[test]
fn figure_7_8_loads_as_printed() {
    let loaded = load(FIGURE_7_8);
    let groups: Vec<_> = loaded.scene.groups().collect();
    assert_eq!(groups.len(), 1, "the Group");
    let (gid, group) = groups[0];
    assert_eq!(group.parent, None);
    let objs = objects(&loaded.scene);
    assert_eq!(objs.len(), 1);
    let (_, in_group, object) = objs[0];
    assert_eq!(in_group, Some(gid));
    let data = object.data();
    let geometry = data.geometry.as_ref().unwrap();
    assert_eq!(
        geometry.shape,
        Shape::Implicit(model::object::Formula::new("0").unwrap())
    );
    let tension = data.physics.tension.as_ref().unwrap();
    assert!(tension.enabled);
    assert_eq!(tension.formula.as_str(), "1");
    let friction = data.physics.friction.as_ref().unwrap();
    assert!(friction.enabled);
    assert_eq!(friction.formula.as_str(), "0.3");
    let mut s = object.sampler();
    assert_eq!(s.scalar(Paintable::Tension, DVec3::ZERO, 0.0), Some(1.0));
    assert_eq!(s.scalar(Paintable::Friction, DVec3::ONE, 0.0), Some(0.3));

    let w = &loaded.warnings;
    assert_eq!(warning_line(w, "`NetConnection` node skipped"), 1);
    assert_eq!(warning_line(w, "`BSCollaborate` node skipped"), 7);
    assert_eq!(lines_of(w, "stray `:`"), vec![14, 17, 18]);
    assert_eq!(warning_line(w, "read as one of its `children`"), 12);
    assert_eq!(
        warning_line(
            w,
            "remote url not fetched: http://cospace.sce.ntu.edu.sg/vircampus/enter.wrl"
        ),
        22
    );
    assert_eq!(lines_of(w, "PROTO `HapticDevice`"), vec![25]);
    assert_eq!(lines_of(w, "PROTO `AvatarInfo`"), vec![41]);
    assert_eq!(lines_of(w, "EXTERNPROTO `Chat`"), vec![30]);
    assert_eq!(lines_of(w, "`Script` node skipped"), vec![27, 33, 38, 43]);
    assert_eq!(warning_line(w, "`TextToSpeech` node skipped"), 36);
    // The Script after a PROTO without a body is still found: nothing else went wrong (its
    // Inline, the campus it makes tangible, is remote: it is kept as written).
    assert_eq!(w.len(), 16, "{w:#?}");
    assert_round_trip(&loaded.scene);
}

/// Figure 7.8's physics-only `FShape` as printed, grouped with a local campus instead of the
/// remote one: its physics goes to every shape of the group that has none (through nested
/// groups and Inline files too), the carrier leaves the scene, and shapes with physics of
/// their own, or outside the group, keep theirs.
#[test]
fn a_shapeless_fshape_gives_its_physics_to_the_shapes_grouped_with_it() {
    let carrier_start = FIGURE_7_8.find(" FShape").unwrap();
    let carrier_end = FIGURE_7_8.find(" Inline").unwrap();
    let carrier = &FIGURE_7_8[carrier_start..carrier_end];
    let text = format!(
        "Group {{ children [\n{carrier}\n Inline {{ url \"campus.wrl\" }}\n \
         Transform {{ translation 3 0 0 children Shape {{ geometry Sphere {{ }} }} }}\n \
         FShape {{ geometry Box {{ }} physics FPhysics {{ density FDensity {{ definition \"0.5\" }} }} }}\n\
         ] }}\nShape {{ geometry Cone {{ }} }}\n"
    );
    let campus = "Shape { geometry Box { size 1 2 1 } }\n\
                  Shape { geometry IndexedFaceSet { coord Coordinate { point [0 0 0, 1 0 0, 0 1 0, 0 0 1] } \
                  coordIndex [0 2 1 -1, 0 1 3 -1, 0 3 2 -1, 1 2 3 -1] } }\n";
    let mut resolve = |path: &str| match path {
        "campus.wrl" => Ok(campus.as_bytes().to_vec()),
        _ => Err(format!("no file {path}")),
    };
    let loaded = fvrml::load(&text, &LoadOptions::default(), &mut resolve).unwrap();
    let objs = objects(&loaded.scene);
    // The box, the mesh and the sphere got the carrier's physics; the carrier is gone.
    let tangible: Vec<ObjectId> = objs
        .iter()
        .filter(|o| o.2.is_tangible())
        .map(|o| o.0)
        .collect();
    assert_eq!(objs.len(), 5, "{objs:#?}");
    assert_eq!(
        tangible,
        [ObjectId(1), ObjectId(2), ObjectId(3), ObjectId(4)]
    );
    assert!(objs.iter().all(|o| o.0 != ObjectId(0)), "the carrier left");
    for id in [1, 2, 3] {
        let object = loaded.scene.object(ObjectId(id)).unwrap();
        let p = &object.data().physics;
        assert_eq!(p.tension.as_ref().unwrap().formula.as_str(), "1", "{id}");
        assert_eq!(p.friction.as_ref().unwrap().formula.as_str(), "0.3", "{id}");
        assert!(p.zone_depth.is_none() && p.density.is_none(), "{id}");
    }
    // A shape with physics of its own keeps it; the cone outside the group is not touched.
    let own = &loaded.scene.object(ObjectId(4)).unwrap().data().physics;
    assert!(own.tension.is_none() && own.density.is_some());
    assert!(!loaded.scene.object(ObjectId(5)).unwrap().is_tangible());
    let w = &loaded.warnings;
    assert_eq!(
        warning_line(w, "gives its physics to the 3 shapes grouped with it"),
        1
    );
    // Saved, the shapes carry the physics themselves: loaded again, nothing is lent.
    let again = load(&fvrml::write(&fvrml::save(&loaded.scene)));
    assert!(again.warnings.is_empty(), "{:#?}", again.warnings);
    let data = |scene: &Scene| -> Vec<ObjectData> {
        scene
            .objects()
            .map(|(_, o)| o.object.data().clone())
            .collect()
    };
    assert_eq!(data(&again.scene), data(&loaded.scene));
}

/// A shape defined as the constant 0 with physics, saved from a scene where it gave nothing
/// (here, made in code), loads back as it was: saving writes it `bboxSize -1 -1 -1`, which
/// no carrier has.
#[test]
fn a_zero_shape_with_physics_saved_in_a_group_loads_back_as_it_was() {
    let mut scene = Scene::new();
    let group = model::scene::Group {
        name: "campus".into(),
        parent: None,
        transform: model::object::Transform::IDENTITY,
    };
    scene.set_group(GroupId(0), group).unwrap();
    let formula = |text: &str| model::object::Formula::new(text).unwrap();
    let zero = ObjectData {
        geometry: Some(model::object::Geometry::implicit(formula("0"))),
        physics: model::object::Physics {
            tension: Some(model::object::Property::new(formula("1"))),
            ..model::object::Physics::default()
        }
        .into(),
        ..ObjectData::default()
    };
    let building = ObjectData {
        geometry: Some(model::object::Geometry::implicit_in(
            formula("0.5-abs(x)"),
            model::object::Domain::new(DVec3::ZERO, DVec3::ONE),
        )),
        ..ObjectData::default()
    };
    for (id, data) in [zero, building].into_iter().enumerate() {
        let object = Object::new(data).unwrap();
        scene
            .insert_object(ObjectId(id as u64), object, Some(GroupId(0)))
            .unwrap();
    }
    let text = fvrml::write(&fvrml::save(&scene));
    assert!(text.contains("bboxSize -1 -1 -1"), "{text}");
    assert_round_trip(&scene);
}

/// An implicit solid written without `bboxSize` gets the domain `new:` would fit to it (the
/// geometry and a container alike); one that is unbounded or empty keeps none and says why
/// at its definition, in `new:`'s words.
#[test]
fn a_solid_without_a_bbox_gets_the_domain_new_fits_and_an_unbounded_one_says_why() {
    let ball = "0.3-sqrt((x-1)^2+y^2+z^2)";
    let text = format!(
        "FShape {{ geometry FGeometry {{ definition \"{ball}\" }}\n\
         physics FPhysics {{ surface FSurface {{ tension FTension {{ definition \"1\" }} }}\n\
         container FGeometry {{ definition \"0.5-sqrt(x^2+y^2+z^2)\" }} }} }}\n\
         FShape {{ geometry FGeometry {{ definition \"x\" }} }}\n\
         FShape {{ geometry FGeometry {{ definition \"-1-x^2\" }} }}\n"
    );
    let loaded = load(&text);
    let fitted = |src: &str| fit_domain(&fdsl::Function::parse(src).unwrap().tape(), 0.0);
    let objs = objects(&loaded.scene);
    let data = objs[0].2.data();
    assert_eq!(
        data.geometry.as_ref().unwrap().domain,
        Some(fitted(ball).unwrap())
    );
    let container = data.physics.container.as_ref().unwrap();
    assert_eq!(
        container.domain,
        Some(fitted("0.5-sqrt(x^2+y^2+z^2)").unwrap())
    );
    assert!(objs[0].2.bounds().is_some());
    for (k, e) in [(1, FitError::Unbounded), (2, FitError::Empty)] {
        assert_eq!(objs[k].2.data().geometry.as_ref().unwrap().domain, None);
        let issue = &loaded.warnings[k - 1];
        assert_eq!(issue.location.line, k as u32 + 3, "{issue}");
        assert_eq!(issue.message, format!("no domain fits: {e}"));
    }
    assert_eq!(loaded.warnings.len(), 2, "{:#?}", loaded.warnings);
    assert_round_trip(&loaded.scene);
}

#[test]
fn figure_7_14_loads_as_printed() {
    let loaded = load(FIGURE_7_14);
    assert!(loaded.scene.is_empty());
    let w = &loaded.warnings;
    assert_eq!(warning_line(w, "remote url not fetched"), 10);
    assert_eq!(lines_of(w, "`Script` node skipped").len(), 7);
    assert_eq!(lines_of(w, "PROTO `").len(), 5);
}

#[test]
fn hand_written_watermelon_loads_and_round_trips() {
    let loaded = load(WATERMELON);
    assert!(loaded.warnings.is_empty(), "{:#?}", loaded.warnings);
    let objs = objects(&loaded.scene);
    assert_eq!(objs.len(), 1);
    let data = objs[0].2.data();
    assert_eq!(data.name, "Watermelon");
    let Some(Shape::Implicit(formula)) = data.geometry.as_ref().map(|g| &g.shape) else {
        panic!("implicit geometry expected");
    };
    assert_eq!(formula.as_str(), WATERMELON_FDSL.trim());
    let Some(ColorDef::Map { map, .. }) = &data.appearance.diffuse else {
        panic!("a colour map expected");
    };
    assert_eq!(map.keys.len(), 6);
    assert_eq!(map.keys[5], (1.0, [0.0, 0.2, 0.0]));

    let mut s = objs[0].2.sampler();
    // The wedge is cut away; the flesh is inside.
    assert!(s.value(DVec3::new(-0.5, -0.5, -0.5), 0.0) > 0.0);
    assert!(s.value(DVec3::new(0.5, 0.5, 0.5), 0.0) < 0.0);
    // Red at the centre, green on the rind.
    let centre = s.color(ColorSlot::Diffuse, DVec3::ZERO, 0.0).unwrap();
    assert!(centre[0] > 0.8 && centre[1] < 0.2, "{centre:?}");
    let rind = s
        .color(ColorSlot::Diffuse, DVec3::new(0.0, -0.995, 0.0), 0.0)
        .unwrap();
    assert!(rind[1] > rind[0] && rind[1] > rind[2], "{rind:?}");
    assert_eq!(s.scalar(Paintable::Tension, DVec3::X, 0.0), Some(1.0));
    assert_eq!(s.scalar(Paintable::Friction, DVec3::X, 0.0), Some(0.1));
    assert_eq!(s.scalar(Paintable::ZoneDepth, DVec3::X, 0.0), Some(0.05));
    assert_eq!(
        s.scalar(Paintable::Density, DVec3::new(0.0, -0.9, 0.0), 0.0),
        Some(0.8)
    );
    let inner = s
        .scalar(Paintable::Density, DVec3::new(0.01, -0.2, 0.03), 0.0)
        .unwrap();
    assert!((0.1..=0.5).contains(&inner), "{inner}");
    assert_round_trip(&loaded.scene);
}

#[test]
fn standard_vrml_shapes_are_exact_solids() {
    let text = r#"
        Shape { geometry Box { size 2 4 6 } appearance Appearance {
            material Material { diffuseColor 1 0 0 transparency 0.25 shininess 0.5 ambientIntensity 0.5 } } }
        Shape { geometry Sphere { radius 2 } }
        Shape { geometry Cylinder { radius 1 height 4 } }
        Shape { geometry Cone { bottomRadius 1 height 2 } }
    "#;
    let loaded = load(text);
    let objs = objects(&loaded.scene);
    assert_eq!(objs.len(), 4);
    let value = |i: usize, p: [f64; 3]| objs[i].2.sampler().value(DVec3::from_array(p), 0.0);
    // Box: half sizes 1, 2, 3; the value is the distance to the nearest face inside.
    assert!((value(0, [0.0, 0.0, 0.0]) - 1.0).abs() < 1e-12);
    assert!((value(0, [0.5, 1.5, 2.0]) - 0.5).abs() < 1e-12);
    assert!(value(0, [1.1, 0.0, 0.0]) < 0.0);
    assert!(value(0, [0.0, 0.0, 3.1]) < 0.0);
    // Sphere: a signed distance.
    assert!((value(1, [1.0, 0.0, 0.0]) - 1.0).abs() < 1e-12);
    assert!(value(1, [1.5, 1.5, 0.0]) < 0.0);
    // Cylinder along y.
    assert!(value(2, [0.0, 1.9, 0.0]) > 0.0);
    assert!(value(2, [0.0, 2.1, 0.0]) < 0.0);
    assert!(value(2, [0.7, 0.0, 0.7]) > 0.0);
    assert!(value(2, [0.8, 0.0, 0.8]) < 0.0);
    // Cone: apex at y = 1, base radius 1 at y = -1; its side is at distance 0.
    assert!(value(3, [0.0, 0.9, 0.0]) > 0.0);
    assert!(value(3, [0.0, 1.1, 0.0]) < 0.0);
    assert!(value(3, [0.0, -1.1, 0.0]) < 0.0);
    assert!(value(3, [0.4, 0.0, 0.0]) > 0.0);
    assert!(value(3, [0.6, 0.0, 0.0]) < 0.0);
    assert!(value(3, [0.5, 0.0, 0.0]).abs() < 1e-12);

    let a = &objs[0].2.data().appearance;
    assert_eq!(a.diffuse, Some(ColorDef::Constant([1.0, 0.0, 0.0])));
    assert_eq!(a.ambient, Some(ColorDef::Constant([0.5, 0.0, 0.0])));
    assert_eq!(a.transparency.as_ref().map(|f| f.as_str()), Some("0.25"));
    assert_eq!(a.shininess.as_ref().map(|f| f.as_str()), Some("0.5"));
    assert_round_trip(&loaded.scene);
}

#[test]
fn transforms_follow_vrml_order_and_nest() {
    let text = "
        DEF Outer Transform {
          translation 1 0 0
          rotation 0 0 1 1.5707963267948966
          scale 2 2 2
          center 0 1 0
          children [
            Transform { translation 0 0 5 children FShape { geometry FGeometry { definition \"1-x^2-y^2-z^2\" } } }
          ]
        }";
    let loaded = load(text);
    let groups: Vec<_> = loaded.scene.groups().collect();
    assert_eq!(groups.len(), 2);
    assert_eq!(groups[0].1.name, "Outer");
    assert_eq!(groups[1].1.parent, Some(GroupId(0)));
    let objs = objects(&loaded.scene);
    assert_eq!(objs[0].1, Some(GroupId(1)));
    // The object's origin: (0,0,5) -> -C (0,-1,5) -> S (0,-2,10) -> R (2,0,10) -> C (2,1,10)
    // -> T (3,1,10).
    let world = loaded.scene.world_from_group(Some(GroupId(1)));
    let p = world.point(DVec3::ZERO);
    assert!((p - DVec3::new(3.0, 1.0, 10.0)).length() < 1e-12, "{p}");
    let mut sampler = loaded.scene.sampler();
    let v = sampler
        .value(ObjectId(0), DVec3::new(3.0, 1.0, 10.0), 0.0)
        .unwrap();
    assert!((v - 1.0).abs() < 1e-12);
    assert_round_trip(&loaded.scene);
}

#[test]
fn ftransform_motion_moves_its_shapes() {
    let text = r#"
        FTransform {
          translation 0 1 0
          translationFunction "x = t; y = 0; z = 0;"
          rotationAxis 0 1 0
          angleFunction "0"
          cycleInterval 4
          children [
            Transform { translation 0 0 2 children [ DEF Ball FShape { geometry FGeometry { definition "1-x^2-y^2-z^2" } } ] }
          ]
        }
        USE Ball
    "#;
    let loaded = load(text);
    assert_eq!(
        loaded.scene.groups().count(),
        1,
        "nested groups are flattened under motion"
    );
    let objs = objects(&loaded.scene);
    assert_eq!(objs.len(), 2);
    let moving = objs[0].2.data();
    let motion = moving.motion.as_ref().unwrap();
    assert_eq!(motion.timing.cycle_interval_secs, 4.0);
    assert_eq!(motion.axis, DVec3::Y);
    assert!(
        objs[1].2.data().motion.is_none(),
        "USE outside keeps the plain shape"
    );
    assert_eq!(objs[1].2.data().name, "Ball");
    let mut sampler = loaded.scene.sampler();
    // At t = 2 s the cycle is half done: local t = 0.5, so the ball is at (0.5, 1, 2).
    let at = sampler
        .world_from_object(ObjectId(0), 2.0)
        .unwrap()
        .point(DVec3::ZERO);
    assert!((at - DVec3::new(0.5, 1.0, 2.0)).length() < 1e-12, "{at}");
    assert_round_trip(&loaded.scene);
}

#[test]
fn def_and_use_copy_shapes_and_groups() {
    let text = r#"
        DEF G Group { children [
          DEF S FShape { geometry FGeometry { definition "1-x^2-y^2-z^2" } }
          Transform { translation 3 0 0 children USE S }
        ] }
        Transform { translation 0 5 0 children [ USE G ] }
    "#;
    let loaded = load(text);
    let groups: Vec<_> = loaded
        .scene
        .groups()
        .map(|(id, g)| (id, g.clone()))
        .collect();
    // G, its Transform, the outer Transform, and the copy of G with its Transform.
    assert_eq!(groups.len(), 5);
    assert_eq!(groups[3].1.name, "G");
    assert_eq!(groups[3].1.parent, Some(GroupId(2)));
    assert_eq!(groups[4].1.parent, Some(GroupId(3)));
    let objs = objects(&loaded.scene);
    assert_eq!(objs.len(), 4);
    assert!(objs.iter().all(|o| o.2.data() == objs[0].2.data()));
    assert_eq!(
        objs.iter().map(|o| o.1).collect::<Vec<_>>(),
        vec![
            Some(GroupId(0)),
            Some(GroupId(1)),
            Some(GroupId(3)),
            Some(GroupId(4))
        ]
    );
    assert_round_trip(&loaded.scene);

    let issues = load_err("USE Nothing\nDEF A Group { children [ USE A ] }");
    assert_eq!(lines_of(&issues, "`USE Nothing` names no node"), vec![1]);
    assert_eq!(lines_of(&issues, "`USE A` names no node"), vec![2]);
}

#[test]
fn ids_start_where_the_caller_says() {
    let text = "Group { children [ FShape { } FShape { } ] } FShape { }";
    let options = LoadOptions {
        first_object_id: 100,
        first_group_id: 7,
        ..LoadOptions::default()
    };
    let loaded = fvrml::load(text, &options, &mut no_files).unwrap();
    let ids: Vec<_> = loaded.scene.objects().map(|(id, _)| id.0).collect();
    assert_eq!(ids, vec![100, 101, 102]);
    assert_eq!(loaded.scene.groups().next().unwrap().0, GroupId(7));
    assert_eq!((loaded.next_object_id, loaded.next_group_id), (103, 8));
}

#[test]
fn inline_reads_local_files_through_the_resolver() {
    let files: BTreeMap<&str, &str> = [
        (
            "scenes/parts/ball.wrl",
            "Inline { url \"../sub/deeper.wrl\" } FShape { geometry Sphere { radius 0.5 } }",
        ),
        ("scenes/sub/deeper.wrl", "FShape { geometry Box { } }"),
        ("scenes/loop_a.wrl", "Inline { url \"loop_b.wrl\" }"),
        (
            "scenes/loop_b.wrl",
            "Group { children Inline { url [\"loop_a.wrl\"] } }",
        ),
        (
            "scenes/bad.wrl",
            "FShape {\n geometry FGeometry { definition \"1-x^\" } }",
        ),
    ]
    .into_iter()
    .collect();
    let asked = std::cell::RefCell::new(Vec::new());
    let mut resolve = |path: &str| {
        asked.borrow_mut().push(path.to_string());
        files
            .get(path)
            .map(|s| s.as_bytes().to_vec())
            .ok_or_else(|| "not found".to_string())
    };
    let options = LoadOptions {
        path: "scenes/root.wrl".into(),
        ..LoadOptions::default()
    };
    let text = "Transform { translation 1 0 0 children [ Inline { url [\"http://x/y.wrl\" \"missing.wrl\" \"parts/ball.wrl\"] } ] }";
    let loaded = fvrml::load(text, &options, &mut resolve).unwrap();
    assert_eq!(
        *asked.borrow(),
        vec![
            "scenes/missing.wrl",
            "scenes/parts/ball.wrl",
            "scenes/sub/deeper.wrl"
        ]
    );
    let objs = objects(&loaded.scene);
    assert_eq!(objs.len(), 2);
    assert!(objs.iter().all(|o| o.1 == Some(GroupId(0))));
    assert_eq!(
        warning_line(&loaded.warnings, "remote url not fetched: http://x/y.wrl"),
        1
    );
    assert_eq!(
        warning_line(&loaded.warnings, "cannot read Inline `scenes/missing.wrl`"),
        1
    );

    // A cycle is an error naming the chain.
    let issues = match fvrml::load("Inline { url \"loop_a.wrl\" }", &options, &mut resolve) {
        Err(e) => e.issues,
        Ok(_) => panic!("a cycle must fail"),
    };
    let cycle = issues
        .iter()
        .find(|i| i.message.contains("Inline cycle"))
        .unwrap();
    assert_eq!(
        cycle.message,
        "Inline cycle: scenes/root.wrl -> scenes/loop_a.wrl -> scenes/loop_b.wrl -> scenes/loop_a.wrl"
    );
    assert_eq!(cycle.location.file.as_deref(), Some("scenes/loop_b.wrl"));

    // An error inside an inlined file names that file, line and column.
    let issues = match fvrml::load("Inline { url \"bad.wrl\" }", &options, &mut resolve) {
        Err(e) => e.issues,
        Ok(_) => panic!("a bad formula must fail"),
    };
    let error = issues.iter().find(|i| i.is_error()).unwrap();
    assert_eq!(error.location.file.as_deref(), Some("scenes/bad.wrl"));
    assert_eq!((error.location.line, error.location.column), (2, 34));

    // Without a resolver that knows the file, the load fails with the reason.
    let issues = load_err("Inline { url \"nowhere.wrl\" }");
    assert!(
        issues[0]
            .message
            .contains("cannot read Inline `nowhere.wrl`: no file nowhere.wrl")
    );
}

#[test]
fn inline_depth_is_limited() {
    let mut resolve = |path: &str| {
        let n: usize = path
            .trim_end_matches(".wrl")
            .trim_start_matches('f')
            .parse()
            .unwrap();
        Ok(format!("Inline {{ url \"f{}.wrl\" }}", n + 1).into_bytes())
    };
    let issues = match fvrml::load(
        "Inline { url \"f0.wrl\" }",
        &LoadOptions::default(),
        &mut resolve,
    ) {
        Err(e) => e.issues,
        Ok(_) => panic!("too deep must fail"),
    };
    assert!(
        issues[0]
            .message
            .contains("Inline files nest deeper than the limit of 8"),
        "{issues:#?}"
    );
}

#[test]
fn formula_errors_point_into_the_file() {
    let text = "FShape {\n  geometry FGeometry { definition \"1 - x^2 -\" }\n}";
    let issues = load_err(text);
    assert_eq!(issues.len(), 1, "{issues:#?}");
    let e = &issues[0];
    assert_eq!((e.location.line, e.location.column), (2, 35));
    assert_eq!(&text[e.location.span.start as usize..][..1], "\"");
    // The formula's own diagnostic, rendered with its caret.
    assert!(e.message.starts_with("geometry: "), "{}", e.message);
    assert!(e.message.contains("1 - x^2 -"), "{}", e.message);
    assert!(e.message.contains('^'), "{}", e.message);
    let shown = e.to_string();
    assert!(
        shown.starts_with("<input>:2:35: error: geometry:"),
        "{shown}"
    );

    let issues = load_err(
        "FShape { appearance FAppearance { material FMaterial {\n diffuseColor \"x+y\" } } }",
    );
    assert_eq!(issues[0].location.line, 2);
    assert!(
        issues[0].message.contains("diffuse colour"),
        "{}",
        issues[0].message
    );
    assert!(
        issues[0].message.contains("no output `r`"),
        "{}",
        issues[0].message
    );
}

#[test]
fn parametric_geometry_kinds() {
    let text = r#"
        FShape { geometry FGeometry { definition "x=cos(2*pi*u); y=sin(2*pi*u); z=0;" parameters [0 1] } }
        FShape { geometry FGeometry { definition "x=u; y=v; z=u*v;" parameters [-1 1 -1 1] } }
        FShape { geometry FGeometry { definition "x=u; y=v; z=w;" } }
        FShape { geometry FGeometry { definition "x=u; y=u; z=0;" kind "surface" parameters [0 2] } }
        FShape { geometry FGeometry { definition "x=1; y=2; z=3;" kind "implicit" } }
    "#;
    let loaded = load(text);
    let shapes: Vec<_> = objects(&loaded.scene)
        .iter()
        .map(|o| o.2.data().geometry.clone().unwrap().shape)
        .collect();
    let kind = |s: &Shape| match s {
        Shape::Parametric {
            kind, parameters, ..
        } => Some((*kind, *parameters)),
        _ => None,
    };
    assert_eq!(
        kind(&shapes[0]),
        Some((ParametricKind::Curve, [[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]]))
    );
    assert_eq!(
        kind(&shapes[1]),
        Some((
            ParametricKind::Surface,
            [[-1.0, 1.0], [-1.0, 1.0], [0.0, 1.0]]
        ))
    );
    assert_eq!(kind(&shapes[2]).map(|k| k.0), Some(ParametricKind::Solid));
    assert_eq!(
        kind(&shapes[3]),
        Some((
            ParametricKind::Surface,
            [[0.0, 2.0], [0.0, 1.0], [0.0, 1.0]]
        ))
    );
    assert_eq!(kind(&shapes[4]), None);
    assert_round_trip(&loaded.scene);
}

#[test]
fn indexed_face_sets_become_meshes() {
    // A tetrahedron, faces counter-clockwise seen from outside, one face a quad split in two.
    let text = "Shape {\n geometry IndexedFaceSet { coord Coordinate { point [0 0 0, 1 0 0, 0 1 0, 0 0 1] }
          coordIndex [0 2 1 -1 0 1 3 -1 0 3 2 -1 1 2 3] solid TRUE } }
        FShape { geometry FGeometry { mesh IndexedFaceSet { ccw FALSE coord Coordinate { point [0 0 0, 1 0 0, 0 1 0, 0 0 1] }
          coordIndex [0 1 2 -1 0 3 1 -1 0 2 3 -1 1 3 2 -1] } translation 5 0 0 bboxSize 4 4 4 } }
        Shape { geometry IndexedFaceSet { coord Coordinate { point [0 0 0] } coordIndex [0 0 7] } }";
    let issues = load_err(text);
    assert_eq!(issues.len(), 1, "{issues:#?}");
    assert!(
        issues[0].message.contains("`coordIndex` holds 7"),
        "{issues:#?}"
    );
    assert_eq!(issues[0].location.line, 6);

    let text = text.rsplit_once("Shape {").unwrap().0;
    let loaded = load(text);
    let objs = objects(&loaded.scene);
    assert_eq!(objs.len(), 2);
    let (a, b) = (objs[0].2.data(), objs[1].2.data());
    let (Some(Shape::Mesh(ma)), Some(Shape::Mesh(mb))) = (
        a.geometry.as_ref().map(|g| &g.shape),
        b.geometry.as_ref().map(|g| &g.shape),
    ) else {
        panic!("meshes expected");
    };
    assert_eq!(
        ma.triangles(),
        mb.triangles(),
        "ccw FALSE turns the faces over"
    );
    assert!(ma.is_closed());
    let mut s = objs[0].2.sampler();
    assert!(s.value(DVec3::splat(0.1), 0.0) > 0.0);
    assert!(s.value(DVec3::splat(1.0), 0.0) < 0.0);
    let mut s = objs[1].2.sampler();
    assert!(s.value(DVec3::new(5.1, 0.1, 0.1), 0.0) > 0.0);
    assert_round_trip(&loaded.scene);
    let written = fvrml::write(&fvrml::save(&loaded.scene));
    assert!(written.contains("geometry IndexedFaceSet {"), "{written}");
    assert!(written.contains("mesh IndexedFaceSet {"), "{written}");
}

#[test]
fn unknown_fields_and_misplaced_nodes_warn() {
    let text = "FShape { colour 1 0 0 geometry Material { } }\nFGeometry { definition \"1\" }";
    let loaded = load(text);
    assert_eq!(loaded.scene.len(), 1);
    let w = &loaded.warnings;
    assert_eq!(warning_line(w, "no field `colour`"), 1);
    assert_eq!(warning_line(w, "`Material` cannot be the `geometry`"), 1);
    assert_eq!(warning_line(w, "a `FGeometry` cannot stand here"), 2);
}

#[test]
fn canonical_text_is_stable() {
    let text = "#VRML V2.0 utf8\nDEF A FShape{geometry FGeometry{definition “1-x^2” bboxCenter 0,0,0 bboxSize 2 2 2 parameters[]}}\nGroup{children[USE A NULL]}";
    let parsed = fvrml::parse(text);
    assert!(!parsed.has_errors(), "{:#?}", parsed.issues);
    let written = fvrml::write(&parsed.document);
    let expected = r#"#VRML V2.0 utf8

DEF A FShape {
  geometry FGeometry {
    definition "1-x^2"
    bboxCenter 0 0 0
    bboxSize 2 2 2
    parameters []
  }
}

Group {
  children [
    USE A
    NULL
  ]
}
"#;
    assert_eq!(written, expected);
    assert_eq!(fvrml::parse(&written).document, parsed.document);
    assert!(parsed.document.validate().is_ok());
}

#[test]
fn saving_a_rich_scene_keeps_everything() {
    let text = r#"
        DEF Melon FShape {
          translation 1 2 3
          geometry FGeometry { definition "1-x^2-y^2-z^2" bboxCenter 0 0 0 bboxSize 2 2 2 rotation 0 1 0 0.3 }
          appearance FAppearance {
            material FMaterial {
              diffuseColor "r=x; g=y; b=z;"
              ambientColor 0.1 0.2 0.3
              specularColor "x" specularColorMap FColorMap { key [0 1] keyValue [0 0 0, 1 1 1] }
              transparency "0.1*t" shininess 0.7
            }
            texture FTexture3D { definition "0.01*sin(20*x)" }
            bboxSize 3 3 3 scale 2 1 1
          }
          physics FPhysics {
            surface FSurface { tension FTension { definition "1" } depth FDepth { enable FALSE } }
            density FDensity { definition "0.5" }
            force FForce { enable FALSE definition "x=u; y=v; z=w;" parameters [0 1 0 2 0 3] cycleInterval 2 timeSpan 1 5 }
            container Sphere { radius 1.5 }
            bboxCenter 1 1 1 bboxSize 4 4 4 translation 0 0 1
          }
        }
        Transform { scale 1 2 3 children [ Group { name "inner \"quoted\" \\ name" } ] }
    "#;
    let loaded = load(text);
    assert_eq!(loaded.scene.len(), 1);
    assert_eq!(loaded.scene.groups().count(), 2);
    let data: &ObjectData = objects(&loaded.scene)[0].2.data();
    assert!(data.physics.zone_depth.as_ref().is_some_and(|p| !p.enabled));
    assert!(data.physics.container.is_some());
    assert!(data.appearance.displacement.is_some());
    assert_eq!(
        loaded.scene.groups().nth(1).unwrap().1.name,
        "inner \"quoted\" \\ name"
    );
    assert_round_trip(&loaded.scene);
}

/// The thesis mixes straight and typographic quotes in one string (`"0.8”`): either closes it,
/// with the one typographic-quote warning, and the values are exactly the printed ones.
#[test]
fn strings_opened_straight_and_closed_typographic_read_as_printed() {
    let text = "FShape {\n  geometry FGeometry { definition \"1-x^2-y^2-z^2” }\n  \
                physics FPhysics { surface FSurface { tension FTension { definition \"0.8” } } }\n}\n";
    let loaded = load(text);
    assert_eq!(loaded.warnings.len(), 1, "{:#?}", loaded.warnings);
    assert!(
        loaded.warnings[0].message.contains("typographic"),
        "{:#?}",
        loaded.warnings
    );
    let objs = objects(&loaded.scene);
    let data = objs[0].2.data();
    let Some(Shape::Implicit(formula)) = data.geometry.as_ref().map(|g| &g.shape) else {
        panic!("implicit geometry expected");
    };
    assert_eq!(formula.as_str(), "1-x^2-y^2-z^2");
    let tension = data.physics.tension.as_ref().unwrap();
    assert_eq!(tension.formula.as_str(), "0.8");
}

/// Sculpting edits of every kind, with numbers that only read back exactly when written
/// exactly: saved, written, parsed and loaded, the objects hold the same edits bit for bit
/// (undone ones included) and sample the same.
#[test]
fn sculpting_edits_survive_save_and_load() {
    let text = r#"
        FShape {
          name "Block"
          geometry FGeometry { definition "min(1-abs(x), 1-abs(y), 1-abs(z))" bboxSize 2.5 2.5 2.5 }
          physics FPhysics {
            surface FSurface { friction FFriction { definition "0.2" } }
            density FDensity { definition "1" }
          }
        }
        FShape { name "Lump" geometry Sphere { radius 0.5 } translation 3 0 0 }
    "#;
    let base = load(text).scene;
    let mut scene = base.clone();
    let (block, lump) = (ObjectId(0), ObjectId(1));
    let carve = Edit {
        op: EditOp::Subtract,
        tool: ToolShape::Cylinder {
            radius: 0.1,
            half_height: 0.3,
        },
        path: (0..5)
            .map(|i| {
                let i = f64::from(i);
                Pose {
                    position: DVec3::new(-0.6 + 0.3 * i, 1.0 / 3.0, 0.1 + 0.2),
                    rotation: DQuat::from_rotation_x(0.1 * i),
                    scale: 1.0 + 0.01 * i,
                }
            })
            .collect(),
        blend_radius: 0.0,
        mirror: None,
    };
    let mut blob = Edit::stamp(
        EditOp::Union,
        ToolShape::Sphere { radius: 0.3 },
        Pose::at(DVec3::new(-0.0, 1.1, 1e-7)),
    );
    blob.blend_radius = 0.15;
    let mut clip = Edit::stamp(
        EditOp::Intersect,
        ToolShape::Box {
            half_extents: DVec3::new(0.9, 1.5, 0.95),
            rounding: 0.1,
        },
        Pose::at(DVec3::ZERO),
    );
    clip.blend_radius = -0.0;
    let mut dents = Edit::stamp(
        EditOp::Subtract,
        ToolShape::Sphere { radius: 0.2 },
        Pose::at(DVec3::new(0.9, -0.5, 0.1)),
    );
    dents.mirror = Some(Axis::X);
    dents.blend_radius = 0.05;
    let rough = Edit::stroke(
        EditOp::Paint {
            property: Paintable::Friction,
            value: PaintValue::Scalar(0.7),
        },
        ToolShape::Box {
            half_extents: DVec3::splat(0.4),
            rounding: 0.0,
        },
        vec![
            Pose::at(DVec3::new(0.0, 0.8, 0.0)),
            Pose::at(DVec3::new(0.5, 0.8, 0.0)),
        ],
    );
    let red = Edit::stamp(
        EditOp::Paint {
            property: Paintable::Color,
            value: PaintValue::Color([0.8, 0.1, 1.0 / 3.0]),
        },
        ToolShape::Sphere { radius: 0.6 },
        Pose::at(DVec3::new(0.0, 0.0, 1.0)),
    );
    let heavy = Edit::stamp(
        EditOp::Paint {
            property: Paintable::Density,
            value: PaintValue::Scalar(-2.5e-300),
        },
        ToolShape::Sphere { radius: 0.5 },
        Pose::at(DVec3::ZERO),
    );
    for edit in [carve, blob, clip, dents, rough, red, heavy.clone()] {
        scene.apply(block, edit).unwrap();
    }
    // An undone edit stays in the history.
    let undone = scene.apply(block, heavy).unwrap();
    assert!(scene.object_mut(block).unwrap().undo(undone));
    let mut bump = Edit::stamp(
        EditOp::Union,
        ToolShape::Sphere { radius: 0.2 },
        Pose::at(DVec3::new(0.0, 0.0, 0.5)),
    );
    bump.mirror = Some(Axis::Z);
    scene.apply(lump, bump).unwrap();

    let written = fvrml::write(&fvrml::save(&scene));
    assert!(written.contains("edits [\n"), "{written}");
    assert_eq!(written.matches("FEdit {").count(), 9, "{written}");
    let again = load(&written);
    assert!(again.warnings.is_empty(), "{:#?}", again.warnings);
    assert_eq!(again.scene, scene, "{written}");
    // Bit for bit: `Debug` tells `-0.0` from `0.0` and prints every f64 exactly.
    for id in [block, lump] {
        let edits = |s: &Scene| {
            let entries = s.object(id).unwrap().history().entries();
            let edits: Vec<_> = entries
                .iter()
                .map(|e| (e.edit.edit().clone(), e.active))
                .collect();
            format!("{edits:?}")
        };
        assert_eq!(edits(&again.scene), edits(&scene));
    }
    assert_eq!(fvrml::write(&fvrml::save(&again.scene)), written);

    // The loaded objects sample as the sculpted ones, and differ from the unsculpted base.
    let (mut sculpted, mut loaded) = (scene.sampler(), again.scene.sampler());
    let mut unsculpted = base.sampler();
    let mut n_changed = 0;
    for i in 0..400 {
        let s = f64::from(i);
        let p = DVec3::new((s * 0.37).sin(), (s * 0.53).cos() * 1.3, (s * 0.71).sin());
        for (id, p) in [(block, p), (lump, DVec3::X * 3.0 + p * 0.6)] {
            let value = sculpted.value(id, p, 0.0).unwrap();
            assert_eq!(
                value.to_bits(),
                loaded.value(id, p, 0.0).unwrap().to_bits(),
                "{p}"
            );
            let gradient = sculpted.gradient(id, p, 0.0);
            assert_eq!(
                format!("{gradient:?}"),
                format!("{:?}", loaded.gradient(id, p, 0.0))
            );
            let diffuse = sculpted.color(id, ColorSlot::Diffuse, p, 0.0);
            assert_eq!(diffuse, loaded.color(id, ColorSlot::Diffuse, p, 0.0), "{p}");
            for property in [Paintable::Friction, Paintable::Density] {
                let v = sculpted.scalar(id, property, p, 0.0);
                assert_eq!(
                    v,
                    loaded.scalar(id, property, p, 0.0),
                    "{property:?} at {p}"
                );
            }
            let changed = value != unsculpted.value(id, p, 0.0).unwrap()
                || diffuse != unsculpted.color(id, ColorSlot::Diffuse, p, 0.0)
                || sculpted.scalar(id, Paintable::Friction, p, 0.0)
                    != unsculpted.scalar(id, Paintable::Friction, p, 0.0);
            if changed {
                n_changed += 1;
            }
        }
    }
    assert!(n_changed > 100, "the edits change only {n_changed} samples");
}

/// A 3 x 2 x 2 grid whose byte is 100 i + 20 j + 10 k, written inline.
const GRID_SCENE: &str = r#"#VRML V2.0 utf8
FShape {
  name "phantom"
  grids [
    FGrid {
      name "scan"
      size 3 2 2
      origin -1 -0.5 -0.5
      spacing 1 1 1
      range 0 2.55
      samples [0 100 200 20 120 220 10 110 210 30 130 230]
    }
  ]
  geometry FGeometry { definition "scan(x, y, z) - 1" }
  physics FPhysics { density FDensity { definition "scan(x, y, z)" } }
}
"#;

#[test]
fn grids_are_read_inline_or_from_files_and_saved_inline() {
    let loaded = load(GRID_SCENE);
    let (_, _, object) = objects(&loaded.scene)[0];
    let mut s = object.sampler();
    // Bytes stand for 0 to 2.55: the value at index (1.5, 0.5, 0.5) is (150 + 10 + 5) / 100.
    let p = DVec3::new(0.5, 0.0, 0.0);
    assert!((s.scalar(model::object::Paintable::Density, p, 0.0).unwrap() - 1.65).abs() < 1e-12);
    assert!((s.value(p, 0.0) - 0.65).abs() < 1e-12);
    // Saved, the samples are written inline and read back bit for bit.
    let text = fvrml::write(&fvrml::save(&loaded.scene));
    assert!(text.contains("FGrid"), "{text}");
    assert_eq!(load(&text).scene, loaded.scene);
    // The same samples from an NRRD file and from a raw file with a declared size.
    let samples: [u8; 12] = [0, 100, 200, 20, 120, 220, 10, 110, 210, 30, 130, 230];
    let mut nrrd = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 3 2 2\nspace origin: (-1,-0.5,-0.5)\nencoding: raw\n\n".to_vec();
    nrrd.extend(samples);
    let mut files = |path: &str| match path {
        "scans/head.nrrd" => Ok(nrrd.clone()),
        "scans/head.raw" => Ok(samples.to_vec()),
        _ => Err(format!("no file {path}")),
    };
    let options = LoadOptions {
        path: "scans/scene.wrl".into(),
        ..LoadOptions::default()
    };
    let inline = GRID_SCENE.find("      spacing").unwrap()..GRID_SCENE.find("    }\n  ]").unwrap();
    for replacement in [
        "      range 0 2.55\n      url \"head.nrrd\"\n",
        "      spacing 1 1 1\n      range 0 2.55\n      url [\"missing.raw\" \"head.raw\"]\n",
    ] {
        let mut text = GRID_SCENE.to_string();
        text.replace_range(inline.clone(), replacement);
        if replacement.contains("nrrd") {
            text = text.replace("      size 3 2 2\n      origin -1 -0.5 -0.5\n", "");
        }
        let from_file = fvrml::load(&text, &options, &mut files).unwrap();
        assert_eq!(from_file.scene, loaded.scene, "{replacement}");
    }
}

#[test]
fn bad_grids_are_located_errors() {
    let cases = [
        // What is replaced in GRID_SCENE, by what, and the error's line and words.
        ("      name \"scan\"\n", "", 5, "`FGrid` needs a `name`"),
        ("230]", "256]", 11, "whole numbers from 0 to 255"),
        (
            "size 3 2 2",
            "size 3 2 1",
            7,
            "whole counts from 2 to 65535",
        ),
        (
            "size 3 2 2",
            "size 3 2 3",
            5,
            "declares 18 samples but 12 bytes were given",
        ),
        (
            "      samples [0 100 200 20 120 220 10 110 210 30 130 230]\n",
            "      url \"gone.raw\"\n",
            11,
            "cannot read grid `gone.raw`",
        ),
        (
            "definition \"scan(x, y, z) - 1\"",
            "definition \"scna(x, y, z) - 1\"",
            14,
            "did you mean `scan`?",
        ),
        (
            "name \"scan\"",
            "name \"sin\"",
            5,
            "grid name `sin` is not usable",
        ),
    ];
    for (from, to, line, words) in cases {
        assert!(GRID_SCENE.contains(from), "{from}");
        let issues = load_err(&GRID_SCENE.replace(from, to));
        let error = issues.iter().find(|i| i.message.contains(words));
        let Some(error) = error else {
            panic!("{from} -> {to}: no error with {words:?} in {issues:#?}");
        };
        assert_eq!(error.location.line, line, "{from} -> {to}: {error:?}");
    }
}
