//! The object model: edits fold as set operations, painting and undo obey their laws, the
//! index changes nothing but speed, samplers agree with each other, and the canonical
//! encoding round-trips.
#![allow(clippy::unwrap_used, reason = "test helpers outside #[test] functions")]

use std::sync::Arc;

use fdsl::grid::Grid;
use glam::{DQuat, DVec3};
use model::bvh::Aabb;
use model::object::codec;
use model::object::{
    Appearance, Axis, BoxSampler, ColorDef, ColorMap, Domain, Edit, EditOp, Field, Formula,
    Geometry, Motion, Object, ObjectData, PaintValue, Paintable, Physics, Pose, Property, Sampler,
    Timing, ToolShape, Transform,
};
use model::scene::{Group, GroupId, ObjectId, Scene};
use proptest::prelude::*;

const SPHERE: &str = "1 - x^2 - y^2 - z^2";

fn op_strategy() -> impl Strategy<Value = EditOp> {
    prop_oneof![
        4 => Just(EditOp::Union),
        4 => Just(EditOp::Subtract),
        1 => Just(EditOp::Intersect),
        2 => (0.0..5.0f64).prop_map(|v| EditOp::Paint {
            property: Paintable::Density,
            value: PaintValue::Scalar(v),
        }),
        2 => (0.0..1.0f32).prop_map(|r| EditOp::Paint {
            property: Paintable::Color,
            value: PaintValue::Color([r, 0.5, 1.0 - r]),
        }),
    ]
}

fn tool_strategy() -> impl Strategy<Value = ToolShape> {
    prop_oneof![
        (0.05..0.4f64).prop_map(|radius| ToolShape::Sphere { radius }),
        (0.05..0.3f64, 0.05..0.3f64, 0.05..0.3f64).prop_map(|(a, b, c)| ToolShape::Box {
            half_extents: DVec3::new(a, b, c),
            rounding: 0.01,
        }),
        (0.05..0.3f64, 0.05..0.3f64).prop_map(|(radius, half_height)| ToolShape::Cylinder {
            radius,
            half_height
        }),
    ]
}

fn point() -> impl Strategy<Value = DVec3> {
    (-1.3..1.3f64, -1.3..1.3f64, -1.3..1.3f64).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

fn pose() -> impl Strategy<Value = Pose> {
    (point(), -3.0..3.0f64, 0.5..1.5f64).prop_map(|(position, angle, scale)| Pose {
        position,
        rotation: DQuat::from_rotation_y(angle),
        scale,
    })
}

fn edit_strategy() -> impl Strategy<Value = Edit> {
    (
        op_strategy(),
        tool_strategy(),
        prop::collection::vec(pose(), 1..6),
        prop_oneof![3 => Just(0.0), 1 => 0.0..0.2f64],
        prop_oneof![3 => Just(None), 1 => Just(Some(Axis::X))],
    )
        .prop_map(|(op, tool, path, blend_radius, mirror)| Edit {
            op,
            tool,
            path,
            blend_radius,
            mirror,
        })
}

/// The fold by definition: every active edit in order, each tool with bounded support (its
/// exact value inside its region, empty space outside), no index, no clamping.
fn reference_value(object: &Object, p: DVec3) -> f64 {
    let mut sampler = Object::implicit(SPHERE).unwrap().sampler();
    let mut v = sampler.value(p, 0.0);
    for e in object.history().entries() {
        if !e.active {
            continue;
        }
        let edit = e.edit.edit();
        let g = e.edit.raw_tool_value(p);
        let b = edit.blend_radius;
        v = match edit.op {
            EditOp::Union => model::object::edit::smooth_max(v, g, b),
            EditOp::Subtract => model::object::edit::smooth_min(v, -g, b),
            EditOp::Intersect => model::object::edit::smooth_min(v, g, b),
            EditOp::Paint { .. } => v,
        };
    }
    v
}

/// The tool's exact value at `p`.
fn raw_tool_value(edit: &Edit, p: DVec3) -> f64 {
    model::object::CompiledEdit::new(edit.clone())
        .unwrap()
        .raw_tool_value(p)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The index and the clamping never change the sign, and near surfaces not the value.
    #[test]
    fn edits_fold_as_set_operations(
        edits in prop::collection::vec(edit_strategy(), 1..12),
        points in prop::collection::vec(point(), 16),
    ) {
        let mut object = Object::implicit(SPHERE).unwrap();
        for e in &edits {
            object.apply(e.clone()).unwrap();
        }
        object.prepare();
        let mut sampler = object.sampler();
        for p in points {
            let v = sampler.value(p, 0.0);
            let r = reference_value(&object, p);
            prop_assert!(v.is_finite());
            if r.abs() > 1e-9 {
                prop_assert_eq!(v > 0.0, r > 0.0, "sign at {} : {} vs {}", p, v, r);
            }
            if r.abs() < 0.02 {
                prop_assert!((v - r).abs() < 1e-9, "value at {}: {} vs {}", p, v, r);
            }
        }
    }

    /// Painting: inside the tool the property takes the tool's value, outside it keeps the
    /// old one.
    #[test]
    fn painting_changes_only_the_inside_of_the_tool(
        tool in tool_strategy(),
        at in pose(),
        value in 0.0..10.0f64,
        points in prop::collection::vec(point(), 32),
    ) {
        let mut object = Object::implicit(SPHERE).unwrap();
        object
            .set(Field::Density(Some(Property::new(Formula::new("x + 2").unwrap()))))
            .unwrap();
        let before = object.sampler();
        let paint = Edit::stamp(
            EditOp::Paint { property: Paintable::Density, value: PaintValue::Scalar(value) },
            tool,
            at,
        );
        object.apply(paint.clone()).unwrap();
        let mut after = object.sampler();
        let mut before = before;
        for p in points {
            let inside = raw_tool_value(&paint, p) >= 0.0;
            let d = after.scalar(Paintable::Density, p, 0.0).unwrap();
            if inside {
                prop_assert_eq!(d, value);
            } else {
                prop_assert_eq!(d, before.scalar(Paintable::Density, p, 0.0).unwrap());
            }
            // Painting leaves the geometry alone.
            prop_assert_eq!(after.value(p, 0.0), before.value(p, 0.0));
        }
    }

    /// Undo removes an edit from the fold: undoing a subset equals never applying it, and
    /// undo n times then redo n times returns the same object.
    #[test]
    fn undo_removes_edits_from_the_fold(
        edits in prop::collection::vec(edit_strategy(), 1..10),
        undone in prop::collection::vec(any::<bool>(), 10),
        points in prop::collection::vec(point(), 16),
    ) {
        let mut object = Object::implicit(SPHERE).unwrap();
        let mut kept = Object::implicit(SPHERE).unwrap();
        for (i, e) in edits.iter().enumerate() {
            let idx = object.apply(e.clone()).unwrap();
            if undone[i] {
                object.undo(idx);
            } else {
                kept.apply(e.clone()).unwrap();
            }
        }
        let (mut a, mut b) = (object.sampler(), kept.sampler());
        for p in &points {
            prop_assert_eq!(a.value(*p, 0.0), b.value(*p, 0.0));
            prop_assert_eq!(a.diffuse(*p, 0.0), b.diffuse(*p, 0.0));
            prop_assert_eq!(
                a.scalar(Paintable::Density, *p, 0.0),
                b.scalar(Paintable::Density, *p, 0.0)
            );
        }
        let original = object.clone();
        let n = object.history().len();
        for idx in (0..n).rev() {
            object.undo(idx);
        }
        for idx in 0..n {
            object.redo(idx);
        }
        // Every edit active now; the original had some undone, so compare with all redone.
        let mut all = original.clone();
        for idx in 0..n {
            all.redo(idx);
        }
        prop_assert!(object == all);
    }

    /// Intervals hold every value in their box; gradients match finite differences.
    #[test]
    fn intervals_enclose_and_gradients_match(
        edits in prop::collection::vec(edit_strategy(), 0..8),
        center in point(),
        half in 0.01..0.3f64,
    ) {
        let mut object = Object::implicit(SPHERE).unwrap();
        for e in &edits {
            object.apply(e.clone()).unwrap();
        }
        let mut s = object.sampler();
        let region = Aabb::around(center, DVec3::splat(half));
        let iv = s.interval(&region, 0.0);
        for i in 0..27 {
            let k = DVec3::new((i % 3) as f64, ((i / 3) % 3) as f64, (i / 9) as f64) * 0.5;
            let p = region.lo + region.size() * k;
            let v = s.value(p, 0.0);
            prop_assert!(iv.lo <= v + 1e-9 && v <= iv.hi + 1e-9, "{:?} misses {} at {}", iv, v, p);
        }
        let (v, g) = s.gradient(center, 0.0);
        prop_assert_eq!(v, s.value(center, 0.0));
        let h = 1e-6;
        let fd = DVec3::new(
            s.value(center + DVec3::X * h, 0.0) - s.value(center - DVec3::X * h, 0.0),
            s.value(center + DVec3::Y * h, 0.0) - s.value(center - DVec3::Y * h, 0.0),
            s.value(center + DVec3::Z * h, 0.0) - s.value(center - DVec3::Z * h, 0.0),
        ) / (2.0 * h);
        // Creases (min/max switching) make finite differences meaningless right on them.
        let smooth = [DVec3::X, DVec3::Y, DVec3::Z].iter().all(|d| {
            let a = s.value(center + *d * 1e-4, 0.0) - v;
            let b = v - s.value(center - *d * 1e-4, 0.0);
            (a - b).abs() < 1e-6
        });
        if smooth {
            prop_assert!((g - fd).length() < 1e-4, "{} vs {}", g, fd);
        }
    }

    /// Encoding round-trips edits and whole objects.
    #[test]
    fn encoding_round_trips(edits in prop::collection::vec(edit_strategy(), 0..8), undo in 0usize..8) {
        for e in &edits {
            let bytes = codec::encode_edit(e);
            let back = codec::decode_edit(&bytes).unwrap();
            prop_assert_eq!(back.edit(), e);
        }
        let mut object = rich_object();
        for e in &edits {
            object.apply(e.clone()).unwrap();
        }
        object.undo(undo);
        let bytes = codec::encode_object(&object);
        let back = codec::decode_object(&bytes).unwrap();
        prop_assert!(back == object);
        prop_assert_eq!(codec::encode_object(&back), bytes);
    }

    /// Arbitrary bytes never panic the decoders.
    #[test]
    fn decoders_survive_garbage(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let _ = codec::decode_edit(&bytes);
        let _ = codec::decode_object(&bytes);
        let _ = Scene::decode(&bytes);
        let mut versioned = vec![codec::VERSION];
        versioned.extend_from_slice(&bytes);
        let _ = codec::decode_edit(&versioned);
        let _ = codec::decode_object(&versioned);
        let _ = Scene::decode(&versioned);
    }
}

/// An object using every part of the model.
fn rich_object() -> Object {
    let f = |s: &str| Formula::new(s).unwrap();
    Object::new(ObjectData {
        name: "melon".into(),
        geometry: Some(Geometry::implicit_in(
            f(SPHERE),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        appearance: Appearance {
            diffuse: Some(ColorDef::Map {
                formula: f("sqrt(x^2+y^2+z^2)"),
                map: ColorMap {
                    keys: vec![
                        (0.0, [1.0, 0.1, 0.1]),
                        (0.9, [1.0, 0.3, 0.3]),
                        (0.95, [0.1, 0.6, 0.1]),
                    ],
                },
            }),
            specular: Some(ColorDef::Rgb(f("r = 1; g = x; b = 0.5"))),
            transparency: Some(f("0.1")),
            displacement: Some(f("0.01*sin(20*x)")),
            ..Appearance::default()
        }
        .into(),
        physics: Physics {
            tension: Some(Property::new(f("1"))),
            friction: Some(Property {
                formula: f("0.3"),
                enabled: false,
            }),
            density: Some(Property::new(f("2 + y + scan(x, y, z)"))),
            ..Physics::default()
        }
        .into(),
        transform: Transform::from_trs(
            DVec3::new(1.0, 0.0, 0.0),
            DQuat::from_rotation_z(0.5),
            DVec3::ONE,
        ),
        motion: Some(Motion {
            translation: Some(f("x = 0; y = sin(t); z = 0")),
            axis: DVec3::Y,
            angle: Some(f("t")),
            timing: Timing {
                cycle_interval_secs: 4.0,
                time_span: None,
            },
        }),
        grids: vec![scan()].into(),
    })
    .unwrap()
}

/// A 3 x 3 x 3 grid over [-1, 1]^3 whose byte is 10 i + 20 j + 40 k: linear, so its values
/// are known everywhere inside (0 to 140).
fn scan() -> Arc<Grid> {
    let bytes: Vec<u8> = (0..27u8)
        .map(|n| 10 * (n % 3) + 20 * ((n / 3) % 3) + 40 * (n / 9))
        .collect();
    Arc::new(Grid::from_raw("scan", [3, 3, 3], [-1.0; 3], [1.0; 3], [0.0, 255.0], &bytes).unwrap())
}

#[test]
fn an_objects_formulas_call_its_grids_and_a_grid_in_use_cannot_go() {
    let object = rich_object();
    let mut s = object.sampler();
    // Density is read in physics space, which is object space here.
    let p = DVec3::new(0.5, 0.25, -0.5);
    let grid = 10.0 * 1.5 + 20.0 * 1.25 + 40.0 * 0.5;
    let density = s.scalar(Paintable::Density, p, 0.0).unwrap();
    assert!((density - (2.0 + 0.25 + grid)).abs() < 1e-9, "{density}");
    // Without its grid, the density formula does not compile: refused, object unchanged.
    let mut changed = object.clone();
    let error = changed.set(Field::Grids(Default::default())).unwrap_err();
    assert!(
        error.to_string().contains("unknown function `scan`"),
        "{error}"
    );
    assert!(changed == object);
    // Two grids of one name are refused.
    let error = changed
        .set(Field::Grids(vec![scan(), scan()].into()))
        .unwrap_err();
    assert!(
        error.to_string().contains("two grids are named `scan`"),
        "{error}"
    );
}

#[test]
fn objects_written_before_grids_still_decode() {
    let bytes = include_bytes!("../../../tests/data/format-v1/object.bin");
    assert_eq!(bytes[0], codec::VERSION_1);
    let object = codec::decode_object(bytes).unwrap();
    let mut data = ObjectData {
        name: "clay".into(),
        geometry: Some(Geometry::implicit(Formula::new("1-x^2-y^2-z^2").unwrap())),
        ..ObjectData::default()
    };
    data.physics.density = Some(Property::new(Formula::new("0.5+0.2*y").unwrap()));
    let mut expected = Object::new(data).unwrap();
    expected
        .apply(Edit::stamp(
            EditOp::Subtract,
            ToolShape::Sphere { radius: 0.25 },
            Pose::at(DVec3::new(0.5, 0.0, 0.0)),
        ))
        .unwrap();
    assert!(object == expected);
    // Written again, it is today's version, and reads back the same.
    let again = codec::encode_object(&object);
    assert_eq!(again[0], codec::VERSION);
    assert!(codec::decode_object(&again).unwrap() == expected);
    // A version this build does not know is refused with its number.
    let mut future = again.clone();
    future[0] = codec::VERSION + 1;
    let error = codec::decode_object(&future).unwrap_err().to_string();
    assert!(error.contains("version 3 is not supported"), "{error}");
}

#[test]
fn sculpting_from_nothing_builds_what_the_strokes_draw() {
    let mut object = Object::new(ObjectData::default()).unwrap();
    let path: Vec<Pose> = (0..=100)
        .map(|i| Pose::at(DVec3::new(i as f64 / 100.0, 0.0, 0.0)))
        .collect();
    object
        .apply(Edit::stroke(
            EditOp::Union,
            ToolShape::Sphere { radius: 0.1 },
            path,
        ))
        .unwrap();
    let mut s = object.sampler();
    assert!(s.value(DVec3::new(0.5, 0.05, 0.0), 0.0) > 0.0);
    assert!(s.value(DVec3::new(0.5, 0.15, 0.0), 0.0) < 0.0);
    assert!(s.value(DVec3::new(1.2, 0.0, 0.0), 0.0) < 0.0);
    assert!(s.value(DVec3::new(5.0, 5.0, 5.0), 0.0) < 0.0);
    let b = object.bounds().unwrap();
    assert!(b.contains(DVec3::new(1.05, 0.0, 0.0)) && !b.contains(DVec3::new(2.0, 0.0, 0.0)));
}

#[test]
fn blended_union_fills_the_crease() {
    let make = |blend| {
        let mut o = Object::implicit("-y").unwrap();
        let mut e = Edit::stamp(
            EditOp::Union,
            ToolShape::Sphere { radius: 0.3 },
            Pose::at(DVec3::new(0.0, 0.2, 0.0)),
        );
        e.blend_radius = blend;
        o.apply(e).unwrap();
        o.sampler()
    };
    // Just outside the crease where the ball meets the plane.
    let p = DVec3::new(0.3, 0.02, 0.0);
    assert!(make(0.0).value(p, 0.0) < 0.0);
    assert!(make(0.2).value(p, 0.0) > 0.0);
}

#[test]
fn intersection_keeps_only_the_tool() {
    let mut o = Object::implicit(SPHERE).unwrap();
    o.apply(Edit::stamp(
        EditOp::Intersect,
        ToolShape::Box {
            half_extents: DVec3::splat(0.5),
            rounding: 0.0,
        },
        Pose::at(DVec3::ZERO),
    ))
    .unwrap();
    let mut s = o.sampler();
    assert!(s.value(DVec3::new(0.4, 0.0, 0.0), 0.0) > 0.0);
    assert!(s.value(DVec3::new(0.7, 0.0, 0.0), 0.0) < 0.0);
    assert!(
        s.value(DVec3::new(0.95, 0.0, 0.0), 0.0) < 0.0,
        "outside the tool's box"
    );
    let far = Aabb::around(DVec3::new(0.0, 0.0, 0.97), DVec3::splat(0.01));
    assert!(s.interval(&far, 0.0).hi < 0.0);
}

#[test]
fn properties_colors_fields_and_motion_come_from_their_formulas() {
    let mut o = rich_object();
    let mut s = o.sampler();
    let c = s.diffuse(DVec3::ZERO, 0.0);
    assert_eq!(c, [1.0, 0.1, 0.1]);
    assert_eq!(s.diffuse(DVec3::new(2.0, 0.0, 0.0), 0.0), [0.1, 0.6, 0.1]);
    assert_eq!(
        s.scalar(Paintable::Density, DVec3::new(0.0, 0.5, 0.0), 0.0),
        // 2 + y, plus the grid at index (1, 1.5, 1).
        Some(2.5 + 80.0)
    );
    assert_eq!(
        s.scalar(Paintable::Friction, DVec3::ZERO, 0.0),
        None,
        "disabled"
    );
    assert_eq!(
        s.scalar(Paintable::Transparency, DVec3::ZERO, 0.0),
        Some(0.1)
    );
    assert!(
        (s.displacement(DVec3::new(0.1, 0.0, 0.0), 0.0).unwrap() - 0.01 * 2f64.sin()).abs() < 1e-12
    );
    // Motion: t = 1 within a 4 s cycle is local time 0.25.
    let at = s.placement(1.0).point(DVec3::ZERO);
    let want = Transform::from_trs(
        DVec3::new(0.0, 0.25f64.sin(), 0.0),
        DQuat::from_axis_angle(DVec3::Y, 0.25),
        DVec3::ONE,
    )
    .then(&o.data().transform)
    .point(DVec3::ZERO);
    assert!((at - want).length() < 1e-12);
    // Painting a colour overrides the map inside the tool only.
    o.apply(Edit::stamp(
        EditOp::Paint {
            property: Paintable::Color,
            value: PaintValue::Color([0.0, 0.0, 1.0]),
        },
        ToolShape::Sphere { radius: 0.2 },
        Pose::at(DVec3::ZERO),
    ))
    .unwrap();
    let mut s = o.sampler();
    assert_eq!(s.diffuse(DVec3::ZERO, 0.0), [0.0, 0.0, 1.0]);
    let b = s.diffuse(DVec3::new(0.5, 0.0, 0.0), 0.0)[2];
    assert!((b - (0.1 + 0.2 * 0.5 / 0.9) as f32).abs() < 1e-6, "{b}");
}

#[test]
fn force_fields_map_the_container_box_onto_their_parameters() {
    // The thesis's Figure 7.4 cylinder and helical field.
    let f = |s: &str| Formula::new(s).unwrap();
    let field = "function parametric_x (u, v, w) {d=-0.1; x=w+d*u; y=d*v; z=-u+d*w; return x/sqrt(x^2+y^2+z^2) ;}
                 function parametric_y (u, v, w) {d=-0.1; x=w+d*u; y=d*v; z=-u+d*w; return y/sqrt(x^2+y^2+z^2) ;}
                 function parametric_z (u, v, w) {d=-0.1; x=w+d*u; y=d*v; z=-u+d*w; return z/sqrt(x^2+y^2+z^2) ;}";
    let o = Object::new(ObjectData {
        geometry: Some(Geometry::implicit_in(
            f("(1.6^2-x^2-z^2) &y& (0.7-y)"),
            Domain::new(DVec3::new(0.0, 0.35, 0.0), DVec3::new(3.2, 0.7, 3.2)),
        )),
        physics: Physics {
            force: Some(model::object::ForceField {
                formula: f(field),
                parameters: [[-1.0, 1.0], [0.0, 1.0], [-1.0, 1.0]],
                timing: Timing::default(),
                enabled: true,
            }),
            ..Physics::default()
        }
        .into(),
        ..ObjectData::default()
    })
    .unwrap();
    let mut s = o.sampler();
    // The box's +x face centre maps to u = 1, v = 0.5, w = 0.
    let force = s.force(DVec3::new(1.6, 0.35, 0.0), 0.0).unwrap();
    let (x, y, z): (f64, f64, f64) = (-0.1, -0.05, -1.0);
    let n: f64 = (x * x + y * y + z * z).sqrt();
    assert!(
        (force - DVec3::new(x / n, y / n, z / n)).length() < 1e-12,
        "{force}"
    );
    assert!((force.length() - 1.0).abs() < 1e-12);
}

#[test]
fn bad_descriptions_are_errors_that_name_the_property() {
    let err = Object::implicit("1 - x^2 -").unwrap_err();
    assert!(err.to_string().starts_with("geometry:"), "{err}");
    let mut o = Object::implicit(SPHERE).unwrap();
    let err = o
        .set(Field::Diffuse(Some(ColorDef::Rgb(
            Formula::new("x + 1").unwrap(),
        ))))
        .unwrap_err();
    assert!(
        err.to_string().contains("diffuse colour") && err.to_string().contains("`r`"),
        "{err}"
    );
    assert!(
        o.data().appearance.diffuse.is_none(),
        "a failed set changes nothing"
    );
    let bad_map = ColorDef::Map {
        formula: Formula::new("x").unwrap(),
        map: ColorMap {
            keys: vec![(1.0, [0.0; 3]), (0.0, [1.0; 3])],
        },
    };
    assert!(o.set(Field::Diffuse(Some(bad_map))).is_err());
    let flat = Transform::from_trs(DVec3::ZERO, DQuat::IDENTITY, DVec3::new(1.0, 0.0, 1.0));
    assert!(o.set(Field::Transform(Box::new(flat))).is_err());
    assert!(Formula::new("x".repeat(fdsl::limits::MAX_SOURCE_BYTES + 1)).is_err());
    let nan_edit = Edit::stamp(
        EditOp::Union,
        ToolShape::Sphere { radius: f64::NAN },
        Pose::at(DVec3::ZERO),
    );
    assert!(o.apply(nan_edit).is_err());
    assert_eq!(o.history().len(), 0);
}

#[test]
fn scenes_place_objects_through_groups_and_round_trip() {
    let mut scene = Scene::new();
    scene
        .set_group(
            GroupId(1),
            Group {
                name: "table".into(),
                parent: None,
                transform: Transform::translate(DVec3::new(0.0, 1.0, 0.0)),
            },
        )
        .unwrap();
    scene
        .set_group(
            GroupId(2),
            Group {
                name: "tray".into(),
                parent: Some(GroupId(1)),
                transform: Transform::translate(DVec3::new(2.0, 0.0, 0.0)),
            },
        )
        .unwrap();
    assert!(
        scene
            .set_group(
                GroupId(1),
                Group {
                    parent: Some(GroupId(2)),
                    ..Group::default()
                }
            )
            .is_err(),
        "a cycle"
    );
    scene
        .insert_object(
            ObjectId(7),
            Object::implicit(SPHERE).unwrap(),
            Some(GroupId(2)),
        )
        .unwrap();
    scene
        .insert_object(ObjectId(8), rich_object(), None)
        .unwrap();
    assert!(
        scene
            .insert_object(ObjectId(7), rich_object(), None)
            .is_err()
    );
    scene
        .apply(
            ObjectId(7),
            Edit::stamp(
                EditOp::Subtract,
                ToolShape::Sphere { radius: 0.5 },
                Pose::at(DVec3::ZERO),
            ),
        )
        .unwrap();
    let mut s = scene.sampler();
    // The sphere sits at (2, 1, 0) with a hollow of radius 0.5.
    assert!(
        s.value(ObjectId(7), DVec3::new(2.8, 1.0, 0.0), 0.0)
            .unwrap()
            > 0.0
    );
    assert!(
        s.value(ObjectId(7), DVec3::new(2.0, 1.0, 0.0), 0.0)
            .unwrap()
            < 0.0
    );
    assert!(
        s.value(ObjectId(7), DVec3::new(0.0, 0.0, 0.0), 0.0)
            .unwrap()
            < 0.0
    );
    let (_, g) = s
        .gradient(ObjectId(7), DVec3::new(2.9, 1.0, 0.0), 0.0)
        .unwrap();
    assert!(g.x < 0.0 && g.y.abs() < 1e-9);
    let bytes = scene.encode();
    let back = Scene::decode(&bytes).unwrap();
    assert_eq!(back, scene);
    assert_eq!(back.encode(), bytes);
    scene.remove_group(GroupId(1));
    let mut s = scene.sampler();
    assert!(
        s.value(ObjectId(7), DVec3::new(2.8, 1.0, 0.0), 0.0)
            .unwrap()
            > 0.0,
        "placement kept"
    );
}

#[test]
fn rays_find_the_first_surface_through_edits() {
    let mut o = Object::implicit(SPHERE).unwrap();
    let mut s = o.sampler();
    let hit = s
        .ray_hit(DVec3::new(-3.0, 0.0, 0.0), DVec3::X, 10.0, 0.0)
        .unwrap();
    assert!((hit - 2.0).abs() < 1e-6, "{hit}");
    assert!(
        s.ray_hit(DVec3::new(-3.0, 2.0, 0.0), DVec3::X, 10.0, 0.0)
            .is_none()
    );
    // Carve a tunnel along the x axis: the ray now meets the sphere's far side from inside
    // the tunnel's end only where the tunnel stops.
    o.apply(Edit::stroke(
        EditOp::Subtract,
        ToolShape::Sphere { radius: 0.2 },
        vec![
            Pose::at(DVec3::new(-1.5, 0.0, 0.0)),
            Pose::at(DVec3::new(0.5, 0.0, 0.0)),
        ],
    ))
    .unwrap();
    let mut s = o.sampler();
    let hit = s
        .ray_hit(DVec3::new(-3.0, 0.0, 0.0), DVec3::X, 10.0, 0.0)
        .unwrap();
    assert!(
        (hit - 3.7).abs() < 1e-6,
        "the tunnel ends at x = 0.7: {hit}"
    );
    // From inside the solid the first crossing is where it leaves.
    let out = s
        .ray_hit(DVec3::new(0.0, 0.6, 0.0), DVec3::Y, 10.0, 0.0)
        .unwrap();
    assert!((out - 0.4).abs() < 1e-6, "{out}");
}

#[test]
fn a_ray_along_a_zero_function_gives_up_within_its_budget() {
    // "0" is ambiguous on every piece of every ray: without a budget the search visits all
    // 10^7 pieces of the tolerance (seconds in release, minutes here).
    let o = Object::implicit("0").unwrap();
    let mut s = o.sampler();
    #[allow(
        clippy::disallowed_methods,
        reason = "the budget is the point: 65,536 pieces take milliseconds, 10^7 take seconds"
    )]
    let start = std::time::Instant::now();
    assert_eq!(
        s.ray_hit(DVec3::new(-3.0, 0.0, 0.0), DVec3::X, 10.0, 0.0),
        None
    );
    let elapsed = start.elapsed();
    assert!(elapsed.as_millis() < 250, "{elapsed:?}");
    // A real surface is still found within the budget, also far along a long ray.
    let mut s = Object::implicit(SPHERE).unwrap().sampler();
    let hit = s
        .ray_hit(DVec3::new(-1e6, 0.0, 0.0), DVec3::X, 2e6, 0.0)
        .unwrap();
    assert!((hit - (1e6 - 1.0)).abs() < 1e-2, "{hit}");
}

#[test]
fn imported_meshes_are_solids_that_sculpt_and_round_trip() {
    use std::sync::Arc;
    let ball = model::mesh::shapes::icosphere(1.0, 3);
    let mut o = Object::new(ObjectData {
        geometry: Some(Geometry {
            shape: model::object::Shape::Mesh(Arc::new(ball)),
            domain: None,
            transform: Transform::translate(DVec3::new(0.0, 2.0, 0.0)),
        }),
        ..ObjectData::default()
    })
    .unwrap();
    o.apply(Edit::stamp(
        EditOp::Subtract,
        ToolShape::Sphere { radius: 0.5 },
        Pose::at(DVec3::new(0.0, 3.0, 0.0)),
    ))
    .unwrap();
    let mut s = o.sampler();
    assert!(s.value(DVec3::new(0.0, 2.0, 0.0), 0.0) > 0.9);
    assert!(s.value(DVec3::new(0.0, 2.9, 0.0), 0.0) < 0.0, "carved");
    assert!(s.value(DVec3::new(0.0, 0.0, 0.0), 0.0) < 0.0);
    let (_, g) = s.gradient(DVec3::new(0.8, 2.0, 0.0), 0.0);
    assert!(g.x < -0.9, "points inwards: {g}");
    let region = Aabb::around(DVec3::new(0.0, 2.0, 0.0), DVec3::splat(0.1));
    assert!(s.interval(&region, 0.0).lo > 0.0);
    let b = o.bounds().unwrap();
    assert!(b.contains(DVec3::new(0.0, 2.99, 0.0)) && !b.contains(DVec3::new(0.0, 3.2, 0.0)));
    let bytes = codec::encode_object(&o);
    assert!(codec::decode_object(&bytes).unwrap() == o);
}

/// Geometry for the bulk-versus-point comparisons: none, implicit formulas (with `min`,
/// selects and blends the box sampler may simplify), with or without a domain and a
/// transform, an imported mesh, a parametric surface.
fn geometry_strategy() -> impl Strategy<Value = Option<Geometry>> {
    const FORMULAS: [&str; 5] = [
        SPHERE,
        "min(1 - x^2 - y^2 - z^2, 0.6 - y)",
        "blend_and(1 - x^2 - y^2 - z^2, 0.5 - x, 0.2)",
        "function frep(x,y,z,t){ if (x > 0.2) g = 0.8 - x^2 - y^2 - z^2; else g = 1 - x^2 - y^2 - z^2; return g; }",
        "max(0.7 - sqrt(x^2 + z^2), 0.3 - abs(y)) + 0.05*sin(5*x)",
    ];
    let transform = prop_oneof![
        Just(Transform::IDENTITY),
        (point(), -1.0..1.0f64, 0.7..1.4f64).prop_map(|(at, angle, s)| Transform::from_trs(
            at * 0.3,
            DQuat::from_rotation_z(angle),
            DVec3::new(s, 1.0, 1.0 / s),
        )),
    ];
    let domain = prop_oneof![
        Just(None),
        (0.8..2.4f64).prop_map(|s| Some(Domain::new(DVec3::new(0.1, 0.0, 0.0), DVec3::splat(s)))),
    ];
    prop_oneof![
        1 => Just(None),
        6 => (0..FORMULAS.len(), domain, transform).prop_map(|(k, domain, transform)| {
            Some(Geometry {
                shape: model::object::Shape::Implicit(Formula::new(FORMULAS[k]).unwrap()),
                domain,
                transform,
            })
        }),
        1 => Just(Some(Geometry {
            shape: model::object::Shape::Mesh(std::sync::Arc::new(
                model::mesh::shapes::icosphere(0.9, 1),
            )),
            domain: None,
            transform: Transform::translate(DVec3::new(0.1, 0.0, 0.0)),
        })),
        1 => Just(Some(Geometry {
            shape: model::object::Shape::Parametric {
                formula: Formula::new("x = cos(u); y = sin(u); z = v").unwrap(),
                kind: model::object::ParametricKind::Surface,
                parameters: [[0.0, 6.3], [-1.0, 1.0], [0.0, 0.0]],
            },
            domain: None,
            transform: Transform::IDENTITY,
        })),
    ]
}

/// Points to compare in `region`: random ones, its corners, edge and face centres, points on
/// the faces of the edits' boxes, and a few just outside.
fn region_points(object: &Object, region: &Aabb, fractions: &[DVec3]) -> Vec<DVec3> {
    let pick = |k: usize, a: usize| match k {
        0 => region.lo[a],
        1 => 0.5 * (region.lo[a] + region.hi[a]),
        _ => region.hi[a],
    };
    let mut points: Vec<DVec3> = fractions
        .iter()
        .map(|f| region.lo + region.size() * *f)
        .map(|p| p.clamp(region.lo, region.hi))
        .collect();
    for i in 0..27 {
        let k = [i % 3, (i / 3) % 3, i / 9];
        points.push(DVec3::new(pick(k[0], 0), pick(k[1], 1), pick(k[2], 2)));
    }
    for e in object.history().entries() {
        for b in e.edit.boxes().iter().filter(|b| !b.is_empty()) {
            for (a, face) in [(0, b.lo.x), (1, b.hi.y), (2, b.lo.z), (0, b.hi.x)] {
                let mut p = region.center();
                p[a] = face;
                if region.contains(p) {
                    points.push(p);
                }
            }
        }
    }
    points.push(region.hi + DVec3::splat(0.01));
    points.push(region.lo - DVec3::new(0.0, 0.02, 0.0));
    points
}

/// A lattice over `region`, x fastest (what a mesher's block asks), whose axes hold the
/// region's faces, a plane just outside, and the faces of the first edits' boxes that reach
/// into the region, where the lattice's search for an edit's points must agree with the box.
fn region_lattice(object: &Object, region: &Aabb) -> Vec<DVec3> {
    let size = region.size();
    let mut axes: [Vec<f64>; 3] = std::array::from_fn(|a| {
        let mut axis: Vec<f64> = (0..=4)
            .map(|i| region.lo[a] + size[a] * f64::from(i) / 4.0)
            .collect();
        axis.push(region.hi[a] + 0.01);
        axis
    });
    let boxes = object
        .history()
        .entries()
        .iter()
        .flat_map(|e| *e.edit.boxes());
    for b in boxes.filter(|b| b.overlaps(region)).take(4) {
        for (a, axis) in axes.iter_mut().enumerate() {
            axis.extend(
                [b.lo[a], b.hi[a]]
                    .into_iter()
                    .filter(|c| region.lo[a] <= *c),
            );
        }
    }
    for axis in &mut axes {
        axis.sort_by(f64::total_cmp);
        axis.dedup();
    }
    let [xs, ys, zs] = &axes;
    let row = |&z: &f64| {
        ys.iter()
            .flat_map(move |&y| xs.iter().map(move |&x| (x, y, z)))
    };
    zs.iter()
        .flat_map(row)
        .map(|(x, y, z)| DVec3::new(x, y, z))
        .collect()
}

/// The box sampler's values, gradients and intervals equal the point path's bit for bit.
fn assert_bulk_equals_points(object: &Object, region: &Aabb, fractions: &[DVec3], t: f64) {
    let mut point = object.sampler();
    let mut bulk = point.restrict(region, t);
    let mut points = region_points(object, region, fractions);
    // Then a lattice, which the sampler folds without buckets; its first point repeated
    // (not a lattice), which it folds with them.
    let lattice = region_lattice(object, region);
    for batch in [lattice.clone(), [&lattice[..], &lattice[..1]].concat()] {
        assert_batch_equals_points(&mut bulk, &mut point, &batch, t);
    }
    points.extend(lattice.iter().step_by(7));
    let mut values = vec![0.0; points.len()];
    bulk.values(&points, &mut values);
    let mut grads = vec![(0.0, DVec3::ZERO); points.len()];
    bulk.gradients(&points, &mut grads);
    for (i, p) in points.iter().enumerate() {
        let v = point.value(*p, t);
        assert_eq!(
            values[i].to_bits(),
            v.to_bits(),
            "value at {p}: {} vs {v}",
            values[i]
        );
        let (gv, g) = point.gradient(*p, t);
        assert_eq!(
            grads[i].0.to_bits(),
            gv.to_bits(),
            "gradient's value at {p}"
        );
        for a in 0..3 {
            assert_eq!(
                grads[i].1[a].to_bits(),
                g[a].to_bits(),
                "gradient at {p}: {g}"
            );
        }
    }
    // Intervals over the box, a sub-box, and a box reaching outside.
    let sub = Aabb::new(
        region.lo + region.size() * fractions[0] * 0.5,
        region.hi - region.size() * fractions[1] * 0.5,
    );
    for b in [*region, sub, region.expand(0.05)] {
        let (x, y) = (bulk.interval(&b), point.interval(&b, t));
        assert_eq!(
            (x.lo.to_bits(), x.hi.to_bits(), x.nan),
            (y.lo.to_bits(), y.hi.to_bits(), y.nan),
            "interval over {b:?}: {x:?} vs {y:?}"
        );
    }
    // A restriction of the restriction folds the same.
    let mut inner = bulk.restrict(&sub);
    assert!(inner.n_edits() <= bulk.n_edits());
    let inside: Vec<DVec3> = points
        .iter()
        .copied()
        .filter(|p| sub.contains(*p))
        .collect();
    let mut inner_values = vec![0.0; inside.len()];
    inner.values(&inside, &mut inner_values);
    for (p, v) in inside.iter().zip(&inner_values) {
        assert_eq!(
            v.to_bits(),
            point.value(*p, t).to_bits(),
            "inner value at {p}"
        );
    }
}

/// One batch of the box sampler's values and gradients against the point path's.
fn assert_batch_equals_points(bulk: &mut BoxSampler, point: &mut Sampler, batch: &[DVec3], t: f64) {
    let mut values = vec![0.0; batch.len()];
    bulk.values(batch, &mut values);
    let mut grads = vec![(0.0, DVec3::ZERO); batch.len()];
    bulk.gradients(batch, &mut grads);
    for ((p, v), (gv, g)) in batch.iter().zip(&values).zip(&grads) {
        assert_eq!(v.to_bits(), point.value(*p, t).to_bits(), "value at {p}");
        let (pv, pg) = point.gradient(*p, t);
        assert_eq!(gv.to_bits(), pv.to_bits(), "gradient's value at {p}");
        let bits = |v: DVec3| v.to_array().map(f64::to_bits);
        assert_eq!(bits(*g), bits(pg), "gradient at {p}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// A box sampler gives the point path's values, gradients and intervals bit for bit, on
    /// any geometry, with undone edits, paintings and intersections, on the box's faces and
    /// the edits' box faces.
    #[test]
    fn box_sampler_equals_the_point_path_bit_for_bit(
        geometry in geometry_strategy(),
        edits in prop::collection::vec(edit_strategy(), 0..12),
        undone in prop::collection::vec(any::<bool>(), 12),
        prepare in any::<bool>(),
        center in point(),
        half in (0.02..0.6f64, 0.02..0.6f64, 0.02..0.6f64),
        fractions in prop::collection::vec(
            (0.0..1.0f64, 0.0..1.0f64, 0.0..1.0f64).prop_map(|(a, b, c)| DVec3::new(a, b, c)),
            40,
        ),
        t in prop_oneof![Just(0.0), -1.0..1.0f64],
    ) {
        let mut object = Object::new(ObjectData { geometry, ..ObjectData::default() }).unwrap();
        for (i, e) in edits.iter().enumerate() {
            let idx = object.apply(e.clone()).unwrap();
            if undone[i] && i % 3 == 0 {
                object.undo(idx);
            }
        }
        if prepare {
            object.prepare();
        }
        let region = Aabb::around(center, DVec3::new(half.0, half.1, half.2));
        assert_bulk_equals_points(&object, &region, &fractions, t);
    }
}

#[test]
fn box_sampler_equals_the_point_path_on_a_long_history() {
    // More edits than `MAX_SCAN_EDITS` overlap the large boxes, so restrictions and intervals
    // go through the history's index there and through the parent's list below.
    let mut object = Object::new(ObjectData {
        geometry: Some(Geometry::implicit_in(
            Formula::new(SPHERE).unwrap(),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        ..ObjectData::default()
    })
    .unwrap();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let n = 600;
    for k in 0..n {
        let y = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
        let ring = (1.0 - y * y).sqrt();
        let at = DVec3::new(
            ring * (golden * k as f64).cos(),
            y,
            ring * (golden * k as f64).sin(),
        );
        let op = match k % 7 {
            3 => EditOp::Union,
            5 => EditOp::Paint {
                property: Paintable::Color,
                value: PaintValue::Color([1.0, 0.0, 0.0]),
            },
            _ => EditOp::Subtract,
        };
        let idx = object
            .apply(Edit::stamp(
                op,
                ToolShape::Sphere { radius: 0.12 },
                Pose::at(at),
            ))
            .unwrap();
        if k % 11 == 0 {
            object.undo(idx);
        }
    }
    object.prepare();
    let fractions: Vec<DVec3> = (0..64)
        .map(|i| {
            let a = i as f64;
            DVec3::new((a * 0.37).sin(), (a * 0.73).cos(), (a * 1.11).sin()) * 0.5 + 0.5
        })
        .collect();
    let whole = Aabb::around(DVec3::ZERO, DVec3::splat(1.2));
    assert!(object.sampler().restrict(&whole, 0.0).n_edits() > model::object::MAX_SCAN_EDITS);
    assert_bulk_equals_points(&object, &whole, &fractions, 0.0);
    for c in [DVec3::new(0.9, 0.3, 0.1), DVec3::new(-0.2, -0.95, 0.3)] {
        let region = Aabb::around(c, DVec3::splat(0.15));
        assert_bulk_equals_points(&object, &region, &fractions, 0.0);
    }
    // An intersection leaves the far side of the ball empty, in bulk as point by point.
    object
        .apply(Edit::stamp(
            EditOp::Intersect,
            ToolShape::Box {
                half_extents: DVec3::splat(0.6),
                rounding: 0.05,
            },
            Pose::at(DVec3::new(0.5, 0.0, 0.0)),
        ))
        .unwrap();
    object.prepare();
    for c in [
        DVec3::new(0.9, 0.3, 0.1),
        DVec3::new(-0.8, 0.0, 0.0),
        DVec3::ZERO,
    ] {
        let region = Aabb::around(c, DVec3::splat(0.2));
        assert_bulk_equals_points(&object, &region, &fractions, 0.0);
    }
}

#[test]
fn a_box_sampler_takes_batches_with_nan_points() {
    // A NaN coordinate matches nothing, not even itself: a batch that opens with one is no
    // lattice, and its other points are answered as the point path answers them.
    let mut object = Object::implicit(SPHERE).unwrap();
    let tool = ToolShape::Sphere { radius: 0.2 };
    for at in [DVec3::ZERO, DVec3::splat(0.3)] {
        (object.apply(Edit::stamp(EditOp::Subtract, tool, Pose::at(at)))).unwrap();
    }
    let region = Aabb::around(DVec3::ZERO, DVec3::splat(0.5));
    let lattice = region_lattice(&object, &region);
    let mut point = object.sampler();
    let mut bulk = point.restrict(&region, 0.0);
    for nan in [
        DVec3::new(0.0, f64::NAN, 0.0),
        DVec3::new(0.0, 0.0, f64::NAN),
        DVec3::NAN,
    ] {
        let batch = [&[nan][..], &lattice[..]].concat();
        let mut values = vec![0.0; batch.len()];
        bulk.values(&batch, &mut values);
        let mut grads = vec![(0.0, DVec3::ZERO); batch.len()];
        bulk.gradients(&batch, &mut grads);
        assert_batch_equals_points(&mut bulk, &mut point, &batch[1..], 0.0);
    }
}

#[test]
fn box_samplers_simplify_selects_and_blends_but_not_min_and_max() {
    let select =
        "function frep(x,y,z,t){ if (x > 0.2) g = 0.8 - x^2; else g = 1 - x^2; return g; }";
    let blend = "blend_and(1 - x^2 - y^2 - z^2, 0.5 - x, 0.2)";
    let minimum = "min(1 - x^2 - y^2 - z^2, 0.6 - y)";
    let far = Aabb::new(DVec3::new(0.4, -0.1, -0.1), DVec3::new(0.6, 0.1, 0.1));
    let across = Aabb::around(DVec3::new(0.2, 0.0, 0.0), DVec3::splat(0.1));
    let high = Aabb::new(DVec3::new(-0.1, 0.9, -0.1), DVec3::new(0.1, 1.0, 0.1));
    for (formula, region, simplified) in [
        (select, far, true),
        (select, across, false),
        (
            blend,
            Aabb::around(DVec3::new(-1.2, 0.0, 0.0), DVec3::splat(0.1)),
            true,
        ),
        (
            blend,
            Aabb::around(DVec3::new(1.35, 0.0, 0.0), DVec3::splat(0.05)),
            false,
        ),
        (minimum, high, false),
    ] {
        let sampler = Object::implicit(formula).unwrap().sampler();
        let mut bulk = sampler.restrict(&region, 0.0);
        assert_eq!(
            bulk.is_simplified(),
            simplified,
            "{formula} over {region:?}"
        );
        let points: Vec<DVec3> = (0..=20)
            .map(|i| region.lo.lerp(region.hi, i as f64 / 20.0))
            .collect();
        let mut values = vec![0.0; points.len()];
        bulk.values(&points, &mut values);
        let mut point = Object::implicit(formula).unwrap().sampler();
        for (p, v) in points.iter().zip(&values) {
            assert_eq!(
                v.to_bits(),
                point.value(*p, 0.0).to_bits(),
                "{formula} at {p}"
            );
        }
    }
}

#[test]
fn an_object_is_tangible_only_with_physics_or_painted_physics() {
    let f = |s: &str| Formula::new(s).unwrap();
    let plain = ObjectData {
        geometry: Some(Geometry::implicit_in(
            f(SPHERE),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        ..ObjectData::default()
    };
    let mut object = Object::new(plain.clone()).unwrap();
    assert!(!object.is_tangible(), "a plain shape is seen, not felt");
    // A painted colour does not make it tangible; a painted density does, until undone.
    let paint = |property, value| {
        Edit::stroke(
            EditOp::Paint { property, value },
            ToolShape::Sphere { radius: 0.3 },
            vec![Pose::at(DVec3::ZERO)],
        )
    };
    object
        .apply(paint(Paintable::Color, PaintValue::Color([1.0, 0.0, 0.0])))
        .unwrap();
    assert!(!object.is_tangible());
    let idx = object
        .apply(paint(Paintable::Density, PaintValue::Scalar(0.5)))
        .unwrap();
    assert!(object.is_tangible());
    object.undo(idx);
    assert!(!object.is_tangible(), "an undone painting is not felt");
    // Any enabled property or force field makes it tangible; a disabled one does not.
    let with = |physics: Physics| {
        Object::new(ObjectData {
            physics: physics.into(),
            ..plain.clone()
        })
        .unwrap()
        .is_tangible()
    };
    assert!(with(Physics {
        tension: Some(Property::new(f("1"))),
        ..Physics::default()
    }));
    assert!(with(Physics {
        density: Some(Property::new(f("0.2"))),
        ..Physics::default()
    }));
    assert!(!with(Physics {
        friction: Some(Property {
            formula: f("0.3"),
            enabled: false,
        }),
        ..Physics::default()
    }));
    assert!(rich_object().is_tangible());
}

/// A small stamp (a ball or a rounded box of size 0.005 to 0.05), so that long histories fill
/// the index's grid cells rather than its tree of large boxes.
fn small_edit_strategy() -> impl Strategy<Value = Edit> {
    (
        op_strategy(),
        point(),
        0.005..0.05f64,
        any::<bool>(),
        prop_oneof![3 => Just(0.0), 1 => 0.0..0.02f64],
        prop_oneof![3 => Just(None), 1 => Just(Some(Axis::Z))],
    )
        .prop_map(|(op, at, size, ball, blend_radius, mirror)| {
            let tool = if ball {
                ToolShape::Sphere { radius: size }
            } else {
                ToolShape::Box {
                    half_extents: DVec3::splat(size),
                    rounding: size * 0.25,
                }
            };
            let path = vec![
                Pose::at(at),
                Pose::at(at + DVec3::new(size, size * 0.5, 0.0)),
            ];
            Edit {
                blend_radius,
                mirror,
                ..Edit::stroke(op, tool, path)
            }
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(8))]

    /// The index's large part (the grid and the arena of copied edit data) evaluates exactly
    /// as the unindexed scan of the same history: values, gradients, intervals over small and
    /// large boxes, and paint, bit for bit, also after undo and redo.
    #[test]
    fn a_long_indexed_history_evaluates_as_the_unindexed_scan(
        edits in prop::collection::vec(
            prop_oneof![1 => edit_strategy(), 3 => small_edit_strategy()],
            300..400,
        ),
        toggled in prop::collection::vec(0..400usize, 24),
        points in prop::collection::vec(point(), 48),
        halves in prop::collection::vec(prop_oneof![0.001..0.05f64, 0.05..0.8f64], 48),
    ) {
        let mut scanned = Object::implicit(SPHERE).unwrap();
        for e in &edits {
            scanned.apply(e.clone()).unwrap();
        }
        let mut indexed = scanned.clone();
        indexed.prepare();
        prop_assert_eq!(indexed.history().tail_len(), 0);
        prop_assert!(indexed.history().arena_bytes() > 0);
        for (k, &i) in toggled.iter().enumerate() {
            // Undo most, redo a few of those undone.
            let active = k % 5 == 4;
            scanned.history_mut().set_active(i, active);
            indexed.history_mut().set_active(i, active);
        }
        let (mut a, mut b) = (scanned.sampler(), indexed.sampler());
        for (p, h) in points.iter().zip(&halves) {
            let p = *p;
            prop_assert_eq!(a.value(p, 0.0).to_bits(), b.value(p, 0.0).to_bits(), "value at {}", p);
            let (ga, gb) = (a.gradient(p, 0.0), b.gradient(p, 0.0));
            prop_assert_eq!(ga.0.to_bits(), gb.0.to_bits(), "gradient value at {}", p);
            prop_assert_eq!(ga.1.to_array().map(f64::to_bits), gb.1.to_array().map(f64::to_bits));
            let region = Aabb::around(p, DVec3::splat(*h));
            let (ia, ib) = (a.interval(&region, 0.0), b.interval(&region, 0.0));
            prop_assert_eq!(
                (ia.lo.to_bits(), ia.hi.to_bits(), ia.nan),
                (ib.lo.to_bits(), ib.hi.to_bits(), ib.nan),
                "interval around {} of half size {}", p, h
            );
            prop_assert_eq!(a.diffuse(p, 0.0), b.diffuse(p, 0.0));
            prop_assert_eq!(
                a.scalar(Paintable::Density, p, 0.0).map(f64::to_bits),
                b.scalar(Paintable::Density, p, 0.0).map(f64::to_bits)
            );
        }
    }
}

/// A field's boxed value encodes as the value itself, so fields written before it was boxed
/// (stores, peers) read alike: the variant's index, then the value's own bytes.
#[test]
fn a_boxed_field_encodes_as_its_value() {
    fn encode<T: serde::Serialize>(value: &T) -> Vec<u8> {
        postcard::to_allocvec(value).unwrap()
    }
    let g = Geometry::implicit(Formula::new("x*x + y*y + z*z - 1").unwrap());
    let (d, t) = (Domain::UNIT, Transform::translate(DVec3::X));
    let cases: [(Field, Vec<u8>); 3] = [
        (
            Field::Geometry(Some(Box::new(g.clone()))),
            [vec![1, 1], encode(&g)].concat(),
        ),
        (
            Field::PhysicsSpace(Some(Box::new(d)), Box::new(t)),
            [vec![15, 1], encode(&d), encode(&t)].concat(),
        ),
        (
            Field::Transform(Box::new(t)),
            [vec![16], encode(&t)].concat(),
        ),
    ];
    for (field, expected) in cases {
        assert_eq!(
            postcard::to_allocvec(&field).unwrap(),
            expected,
            "{field:?}"
        );
        let back: Field = postcard::from_bytes(&expected).unwrap();
        assert_eq!(back, field);
    }
}

#[test]
fn moving_a_group_with_groups_below_it_counts_their_depth() {
    let mut scene = Scene::new();
    let chain = |scene: &mut Scene, first: u64, n: u64| {
        for i in 0..n {
            let parent = (i > 0).then(|| GroupId(first + i - 1));
            let group = Group {
                parent,
                ..Group::default()
            };
            scene.set_group(GroupId(first + i), group).unwrap();
        }
    };
    let limit = model::limits::MAX_GROUP_DEPTH as u64;
    // Two chains of 40: hanging the second's root under the first's leaf would nest 80 deep.
    chain(&mut scene, 0, 40);
    chain(&mut scene, 100, 40);
    let under_leaf = Group {
        parent: Some(GroupId(39)),
        ..Group::default()
    };
    assert!(scene.set_group(GroupId(100), under_leaf.clone()).is_err());
    assert_eq!(scene.group(GroupId(100)).unwrap().parent, None, "unchanged");
    // Exactly at the limit is allowed: 40 above and 24 in the moved chain.
    let short = limit - 40;
    chain(&mut scene, 200, short);
    scene.set_group(GroupId(200), under_leaf.clone()).unwrap();
    // One more level below the moved chain's leaf would pass the limit.
    let deeper = Group {
        parent: Some(GroupId(200 + short - 1)),
        ..Group::default()
    };
    assert!(scene.set_group(GroupId(300), deeper).is_err());
}

#[test]
fn a_sampler_asked_again_at_one_point_answers_as_a_fresh_one() {
    // The haptic loop asks the gradient twice and the painted properties at one point each
    // tick, and they reuse the first gradient's index lookup: every answer in any order
    // of asking is what a fresh sampler gives, at other times too.
    let mut object = Object::implicit("1 - x^2 - y^2 - z^2 + 0.1 * t").unwrap();
    for k in 0..300 {
        let a = k as f64;
        let at = DVec3::new((a * 0.37).sin(), (a * 0.23).cos(), (a * 0.11).sin()) * 0.9;
        let op = match k % 4 {
            0 => EditOp::Union,
            1 => EditOp::Subtract,
            2 => EditOp::Paint {
                property: Paintable::Tension,
                value: PaintValue::Scalar(0.1 * (k % 7) as f64),
            },
            _ => EditOp::Paint {
                property: Paintable::Friction,
                value: PaintValue::Scalar(0.5),
            },
        };
        // Small shape edits leave the time's effect seen; large paintings meet the points.
        let radius = if k % 4 < 2 { 0.12 } else { 0.3 };
        let tool = ToolShape::Sphere { radius };
        object.apply(Edit::stamp(op, tool, Pose::at(at))).unwrap();
    }
    object.prepare();
    let object = Arc::new(object);
    let fresh = || model::object::Sampler::new(object.clone());
    let mut sampler = fresh();
    let bits = |(v, g): (f64, DVec3)| (v.to_bits(), g.to_array().map(f64::to_bits));
    // The sampler's answer is a fresh sampler's, bit for bit; true if the point is painted.
    let same_scalar = |sampler: &mut model::object::Sampler, property: Paintable, p, t| {
        let (x, y) = (
            sampler.scalar(property, p, t),
            fresh().scalar(property, p, t),
        );
        assert_eq!(
            x.map(f64::to_bits),
            y.map(f64::to_bits),
            "{property:?} at {p}"
        );
        x.is_some()
    };
    let properties = [Paintable::Tension, Paintable::Friction, Paintable::Density];
    // Asks whose answer the time changes, and properties painted where they are asked: the
    // test would see a stale answer.
    let (mut n_timed, mut n_painted) = (0, 0);
    for k in 0..240 {
        let a = (k / 6) as f64;
        // Each point is asked six times over: twice at another time, in turns of the asks.
        let p = DVec3::new((a * 0.41).cos(), (a * 0.29).sin(), (a * 0.17).cos()) * 0.95;
        let t = [0.0, 0.0, 0.0, 0.5, 0.5, 0.0][k % 6];
        match (k + k / 6) % 4 {
            0 => assert_eq!(bits(sampler.gradient(p, t)), bits(fresh().gradient(p, t))),
            1 => {
                same_scalar(&mut sampler, properties[k % 3], p, t);
            }
            2 => assert_eq!(sampler.value(p, t).to_bits(), fresh().value(p, t).to_bits()),
            _ => {
                let region = Aabb::around(p, DVec3::splat(0.01 + 0.001 * a));
                let (x, y) = (sampler.interval(&region, t), fresh().interval(&region, t));
                assert_eq!(
                    (x.lo.to_bits(), x.hi.to_bits()),
                    (y.lo.to_bits(), y.hi.to_bits())
                );
            }
        }
        // The haptic tick: the gradient twice, then the properties, at one point.
        if k % 6 == 5 {
            let once = bits(sampler.gradient(p, t));
            assert_eq!(bits(sampler.gradient(p, t)), once);
            assert_eq!(once, bits(fresh().gradient(p, t)));
            // A box elsewhere between two asks at the point: the second reads the point's edits.
            sampler.interval(&Aabb::around(-p, DVec3::splat(0.05)), t);
            assert_eq!(bits(sampler.gradient(p, t)), once);
            n_timed += usize::from(once != bits(fresh().gradient(p, 0.5)));
            for property in properties {
                n_painted += usize::from(same_scalar(&mut sampler, property, p, t));
            }
        }
    }
    assert!(n_timed > 10 && n_painted > 10, "{n_timed} {n_painted}");
}
