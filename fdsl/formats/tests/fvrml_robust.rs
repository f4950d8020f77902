//! FVRML against hostile input (truncated figures, unbalanced brackets, huge numbers, deep
//! nesting, USE explosions, Inline cycles, token soups) and the round-trip properties: for
//! random documents `parse(write(doc)) == doc` and writing is idempotent; for random scenes
//! (edit histories included) `load(save(scene)) == scene`.
#![allow(clippy::unwrap_used, reason = "test helpers unwrap")]

use formats::fvrml::{self, Document, Field, Issue, LoadOptions, Node, NodeRef, Value};
use glam::{DAffine3, DMat3, DQuat, DVec3};
use model::object::{
    Appearance, Axis, ColorDef, ColorMap, Domain, Edit, EditOp, ForceField, Formula, Geometry,
    Motion, ObjectData, PaintValue, Paintable, ParametricKind, Physics, Pose, Property, Shape,
    Timing, ToolShape, Transform,
};
use model::scene::{Group, GroupId, ObjectId, Scene};
use proptest::prelude::*;
use testkit::stack::on_small_stack;

const FIGURES: [&str; 4] = [
    include_str!("../../../tests/data/scenes/figure_7_4.wrl"),
    include_str!("../../../tests/data/scenes/figure_7_8.wrl"),
    include_str!("../../../tests/data/scenes/figure_7_14.wrl"),
    include_str!("../../../scenes/watermelon.wrl"),
];

/// Loads with a resolver that serves `inline` for every path; checks that every issue has
/// a position inside the text it names (root text only).
fn try_load(text: &str, inline: &str) -> Result<Vec<Issue>, Vec<Issue>> {
    let mut resolve = |_: &str| Ok(inline.as_bytes().to_vec());
    let n_lines = u32::try_from(text.lines().count().max(1)).unwrap();
    let result = fvrml::load(text, &LoadOptions::default(), &mut resolve);
    let issues = match &result {
        Ok(loaded) => &loaded.warnings,
        Err(e) => &e.issues,
    };
    for issue in issues {
        let root = issue.location.file.is_none() && !issue.message.contains("more issues");
        if root {
            assert!(issue.location.line >= 1, "{issue}");
            assert!(
                issue.location.line <= n_lines + 1,
                "{issue} in {n_lines} lines"
            );
            assert!(issue.location.span.end as usize <= text.len(), "{issue}");
        }
        assert!(!issue.to_string().is_empty());
    }
    match result {
        Ok(loaded) => Ok(loaded.warnings),
        Err(e) => Err(e.issues),
    }
}

fn errors(text: &str) -> Vec<Issue> {
    match try_load(text, "") {
        Ok(w) => panic!("loaded with warnings {w:#?}"),
        Err(issues) => issues.into_iter().filter(Issue::is_error).collect(),
    }
}

#[test]
fn truncated_figures_never_panic() {
    for text in FIGURES {
        assert!(try_load(text, "").is_ok());
        for end in 0..text.len() {
            if text.is_char_boundary(end) {
                let _ = try_load(&text[..end], "");
            }
        }
    }
}

#[test]
fn unbalanced_and_broken_text_is_reported() {
    for text in [
        "FShape {",
        "FShape { geometry FGeometry { definition \"1\" }",
        "}}}} ]]",
        "Group { children [ FShape { } ",
        "DEF",
        "DEF A",
        "USE",
        "PROTO X [",
        "EXTERNPROTO X [ ] [ \"a\" ",
        "FShape { geometry }",
        "FShape { : }",
        "[ ] { }",
        "FShape { geometry FGeometry { definition \"unterminated } }",
        "FShape { geometry FGeometry { definition “unterminated } }",
        "FShape { geometry FGeometry { definition 1e999 } }",
        "Transform { translation 1 2 } FShape { }",
        "Group { children [ 1 \"a\" ] }",
        "FShape { physics FPhysics { force FForce { parameters [0 1 2] definition \"x=u;y=v;z=w;\" } } }",
        "FShape { geometry FGeometry { definition \"0\" kind \"blob\" } }",
        "FShape { appearance FAppearance { material FMaterial { diffuseColor 2 0 0 } } }",
        "FShape { geometry Box { size 0 1 1 } }",
        "Transform { scale 0 1 1 children FShape { } }",
        "FShape { physics FPhysics { surface FSurface { tension FTension { } } } }",
        "\u{0}\u{1}@ FShape",
    ] {
        let errors = errors(text);
        assert!(!errors.is_empty(), "{text}");
    }
}

#[test]
fn huge_numbers_are_errors_or_exact() {
    let big = format!("1{}", "0".repeat(400));
    assert!(!errors(&format!("Box {{ size {big} 1 1 }}")).is_empty());
    assert!(
        !errors(&format!(
            "Shape {{ geometry Box {{ size 0x{} 1 1 }} }}",
            "F".repeat(40)
        ))
        .is_empty()
    );
    let exact = format!("1{}", "0".repeat(300));
    let text = format!("Shape {{ geometry Sphere {{ radius {exact} }} }}");
    assert!(try_load(&text, "").is_ok());
    // A subnormal scale makes the transform singular.
    let issues = errors("Transform { scale 1e-320 1 1 children FShape { } }");
    assert!(issues[0].message.contains("not invertible"), "{issues:#?}");
}

/// A shape whose formula nests as deep as the language allows: statements to
/// `MAX_STATEMENT_DEPTH`, and an expression to `MAX_NESTING_DEPTH` inside the deepest one, so
/// that the loads below compile the worst formula at their deepest point.
fn deepest_shape() -> String {
    use fdsl::limits::{MAX_NESTING_DEPTH, MAX_STATEMENT_DEPTH};
    let n = MAX_STATEMENT_DEPTH - 1;
    // The pending `-` is one level of the expression.
    let m = MAX_NESTING_DEPTH - 1;
    let formula = format!(
        "function frep(x,y,z) {{ r = 0; {}r = 0.5 - {}x{} + 0*x^2;{} return r; }}",
        "{ ".repeat(n),
        "(".repeat(m),
        ")".repeat(m),
        " }".repeat(n)
    );
    assert!(fdsl::Function::parse(&formula).is_ok());
    format!("FShape {{ geometry FGeometry {{ definition \"{formula}\" }} }}")
}

#[test]
fn deep_nesting_never_overflows_the_stack() {
    let d = fvrml::MAX_NESTING_DEPTH;
    let too_deep = format!("deeper than the limit of {d}");
    // On the stack of the engine's thread, where every load runs.
    on_small_stack(|| {
        let braces = "Group { children [ ".repeat(100_000);
        let issues = errors(&braces);
        assert!(issues.iter().any(|i| i.message.contains(&too_deep)));
        let _ = errors(&"[".repeat(1_000_000));
        let _ = errors(&"{".repeat(1_000_000));
        let _ = errors(&format!("Group {{ children {} }}", "[".repeat(1_000_000)));
        let _ = errors(&"FShape { geometry ".repeat(100_000));
        let deep = |n: usize, inner: &str| {
            format!(
                "{}{inner}{}",
                "Transform { children [ ".repeat(n),
                "] } ".repeat(n)
            )
        };
        // Closed, but deeper than the limit.
        assert!(!errors(&deep(200, "FShape { }")).is_empty());
        let shape = deepest_shape();
        // As many nested groups as a scene may hold, around the deepest formula: what
        // saving such a scene writes loads back.
        assert!(try_load(&deep(model::limits::MAX_GROUP_DEPTH, &shape), "").is_ok());
        // Under a moving FTransform nested groups flatten, so only the nesting limits apply:
        // the parser's comes first (the FTransform, the groups, the shape and its geometry).
        let moving = |inner: &str| {
            format!("FTransform {{ translationFunction \"x=t; y=0; z=0;\" children [ {inner} ] }}")
        };
        assert!(try_load(&moving(&deep(d - 3, &shape)), "").is_ok());
        let issues = try_load(&moving(&deep(d - 2, &shape)), "").unwrap_err();
        assert!(issues[0].message.contains(&too_deep), "{issues:#?}");
        // The worst case for the stack: an Inline at that depth, whose file is parsed there
        // and nests as deep again (the loader then stops at its limit).
        let text = moving(&deep(d - 3, "Inline { url \"deep.wrl\" }"));
        let issues = try_load(&text, &deep(d - 3, &shape)).unwrap_err();
        assert!(
            issues[0]
                .message
                .contains(&format!("groups nest {too_deep}")),
            "{issues:#?}"
        );
        // An Inline whose file loads the deepest formula at the deepest place it may.
        let text = moving(&deep(d - 9, "Inline { url \"deep.wrl\" }"));
        assert!(try_load(&text, &deep(6, &shape)).is_ok());
        // A chain of `USE`s, each a group holding the previous one, as deep as loads allow.
        let chain = |n: usize| {
            let mut text = format!("DEF G0 Transform {{ children [ {shape} ] }}\n");
            for k in 1..n {
                text.push_str(&format!(
                    "DEF G{k} Transform {{ children [ USE G{} ] }}\n",
                    k - 1
                ));
            }
            text
        };
        assert!(try_load(&moving(&chain(d - 1)), "").is_ok());
        let issues = try_load(&moving(&chain(d)), "").unwrap_err();
        assert!(
            issues
                .iter()
                .any(|i| i.message.contains(&format!("groups nest {too_deep}"))),
            "{issues:#?}"
        );
        let issues = try_load(&chain(model::limits::MAX_GROUP_DEPTH + 1), "").unwrap_err();
        assert!(
            issues.iter().any(|i| i.message.contains("deeper")),
            "{issues:#?}"
        );
    });
}

#[test]
fn use_explosions_are_bounded() {
    // Each level holds the previous one twice: 2^40 shapes if nothing stopped it.
    let mut text = String::from("DEF L0 FShape { }\n");
    for k in 1..=40 {
        text.push_str(&format!(
            "DEF L{k} Group {{ children [ USE L{} USE L{} ] }}\n",
            k - 1,
            k - 1
        ));
    }
    let issues = errors(&text);
    assert!(
        issues
            .iter()
            .any(|i| i.message.contains("the most groups allowed")),
        "{issues:#?}"
    );
    // Under a moving FTransform groups are flattened, so the step limit stops it.
    let mut text = String::from(
        "FTransform { translationFunction \"x=t; y=0; z=0;\" children [\nDEF L0 Transform { }\n",
    );
    for k in 1..=40 {
        text.push_str(&format!(
            "DEF L{k} Transform {{ children [ USE L{} USE L{} ] }}\n",
            k - 1,
            k - 1
        ));
    }
    text.push_str("] }");
    let issues = errors(&text);
    assert!(
        issues
            .iter()
            .any(|i| i.message.contains("loading visits more than")),
        "{issues:#?}"
    );
}

#[test]
fn inline_cycles_and_floods_are_errors() {
    let issues =
        try_load("Inline { url \"self.wrl\" }", "Inline { url \"self.wrl\" }").unwrap_err();
    assert!(
        issues.iter().any(|i| i.message.contains("Inline cycle")),
        "{issues:#?}"
    );
    // Many distinct files: the file count stops it.
    let mut resolve = |path: &str| {
        let n: usize = path.trim_end_matches(".wrl").parse().unwrap();
        Ok(format!(
            "Inline {{ url \"{}.wrl\" }} Inline {{ url \"{}.wrl\" }}",
            2 * n + 1,
            2 * n + 2
        )
        .into_bytes())
    };
    let result = fvrml::load(
        "Inline { url \"0.wrl\" }",
        &LoadOptions::default(),
        &mut resolve,
    );
    let issues = result.unwrap_err().issues;
    assert!(issues.iter().any(|i| i.is_error()), "{issues:#?}");
}

#[test]
fn size_and_count_limits_hold() {
    let text = " ".repeat(fvrml::MAX_FILE_BYTES + 1);
    let issues = errors(&text);
    assert!(issues[0].message.contains("more than the limit"));
    let text = "Group { }\n".repeat(fvrml::MAX_NODES + 1);
    let parsed = fvrml::parse(&text);
    assert_eq!(parsed.document.nodes.len(), fvrml::MAX_NODES);
    assert!(parsed.has_errors());
    // Issues beyond the limit are counted, not kept.
    let text = "}".repeat(1000);
    let issues = errors(&text);
    assert_eq!(issues.len(), fvrml::MAX_ISSUES + 1);
    assert_eq!(
        issues[fvrml::MAX_ISSUES].message,
        "744 more issues not shown"
    );
}

const SOUP: &[&str] = &[
    "{",
    "}",
    "[",
    "]",
    "DEF",
    "USE",
    "NULL",
    "TRUE",
    "FALSE",
    "PROTO",
    "EXTERNPROTO",
    "ROUTE",
    "TO",
    ".",
    ":",
    "FShape",
    "FGeometry",
    "Group",
    "Transform",
    "FTransform",
    "Inline",
    "Shape",
    "Box",
    "Sphere",
    "Cone",
    "children",
    "geometry",
    "definition",
    "physics",
    "FPhysics",
    "FForce",
    "force",
    "parameters",
    "url",
    "\"1-x^2\"",
    "“0”",
    "”x",
    "\"",
    "1",
    "-2.5",
    "1e999",
    "0x1F",
    "#c\n",
    "//c\n",
    "A",
    "name",
    "translation",
    "rotation",
    "scale",
    "matrix",
    "FSurface",
    "FTension",
    "surface",
    "tension",
    "enable",
    "\"a.wrl\"",
    "\"http://x\"",
    "bboxSize",
    "bboxCenter",
    "IndexedFaceSet",
    "coord",
    "Coordinate",
    "point",
    "coordIndex",
    "-1",
    "0",
    "3",
    "Script",
    "appearance",
    "FAppearance",
    "material",
    "FMaterial",
    "diffuseColor",
    "diffuseColorMap",
    "FColorMap",
    "key",
    "keyValue",
    "translationFunction",
    "\"x=t;y=0;z=0;\"",
    "kind",
    "\"solid\"",
    "\n",
    ",",
    "é",
    "\\",
    "edits",
    "FEdit",
    "operation",
    "\"union\"",
    "\"paint\"",
    "property",
    "\"friction\"",
    "value",
    "tool",
    "\"cylinder\"",
    "\"box\"",
    "radius",
    "halfHeight",
    "halfExtents",
    "path",
    "blendRadius",
    "mirror",
    "\"x\"",
    "active",
];

/// Text for documents: quotes, backslashes, line breaks, braces and typographic quotes.
fn text() -> impl Strategy<Value = String> {
    let chars = vec![
        'a', '"', '\\', '\n', '\u{201C}', '\u{201D}', '#', '/', '{', '}', '[', ']', ' ', 'é', '\r',
        '\t', '0', ',', '\u{0}',
    ];
    prop::collection::vec(prop::sample::select(chars), 0..12).prop_map(|v| v.into_iter().collect())
}

fn ident() -> impl Strategy<Value = String> {
    let first = vec!['a', 'Z', '_', 'é', 'x', 'T', 'D'];
    let rest = vec!['a', 'b', '0', '9', '_', '+', '-', 'Ω', 'E', 'F', 'O'];
    (
        prop::sample::select(first),
        prop::collection::vec(prop::sample::select(rest), 0..6),
    )
        .prop_map(|(c, rest)| std::iter::once(c).chain(rest).collect::<String>())
        .prop_filter("an identifier", |s| fvrml::is_identifier(s))
}

fn number() -> impl Strategy<Value = f64> {
    prop_oneof![
        any::<f64>().prop_filter("finite", |v| v.is_finite()),
        Just(0.0),
        Just(-0.0),
        -10.0..10.0f64,
        (-1000i64..1000).prop_map(|v| v as f64),
    ]
}

fn value(node: BoxedStrategy<NodeRef>) -> impl Strategy<Value = Value> {
    prop_oneof![
        any::<bool>().prop_map(Value::Bool),
        prop::collection::vec(number(), 1..5).prop_map(Value::Numbers),
        text().prop_map(Value::String),
        node.clone().prop_map(Value::Node),
        prop::collection::vec(any::<bool>(), 1..4).prop_map(Value::Bools),
        prop::collection::vec(number(), 1..20).prop_map(Value::NumberList),
        prop::collection::vec(text(), 1..4).prop_map(Value::StringList),
        prop::collection::vec(node, 1..3).prop_map(Value::NodeList),
        Just(Value::EmptyList),
    ]
}

fn node_ref() -> impl Strategy<Value = NodeRef> {
    let type_name = || prop::sample::select(fvrml::KNOWN_NODES.to_vec());
    let leaf = prop_oneof![
        ident().prop_map(|name| NodeRef::Use {
            name,
            pos: fvrml::Pos::default()
        }),
        Just(NodeRef::Null),
        (type_name(), prop::option::of(ident())).prop_map(|(t, def)| {
            let mut node = Node::new(t, Vec::new());
            node.def = def;
            NodeRef::Node(Box::new(node))
        }),
    ];
    leaf.prop_recursive(4, 40, 4, move |inner| {
        (
            type_name(),
            prop::option::of(ident()),
            prop::collection::vec((ident(), value(inner.boxed())), 0..4),
        )
            .prop_map(|(t, def, fields)| {
                let fields = fields.into_iter().map(|(n, v)| Field::new(n, v)).collect();
                let mut node = Node::new(t, fields);
                node.def = def;
                NodeRef::Node(Box::new(node))
            })
    })
}

fn formula(text: &str) -> Formula {
    Formula::new(text).unwrap()
}

fn transform() -> impl Strategy<Value = Transform> {
    let v = || prop::array::uniform3(-5.0..5.0f64).prop_map(DVec3::from_array);
    let s = || prop::array::uniform3(0.1..3.0f64).prop_map(DVec3::from_array);
    prop_oneof![
        Just(Transform::IDENTITY),
        v().prop_map(Transform::translate),
        (v(), s()).prop_map(|(t, s)| Transform::from_trs(t, DQuat::IDENTITY, s)),
        (v(), prop::array::uniform3(-1.0..1.0f64), -3.0..3.0f64, s()).prop_map(
            |(t, a, angle, s)| {
                let axis = DVec3::from_array(a).try_normalize().unwrap_or(DVec3::X);
                Transform::from_trs(t, DQuat::from_axis_angle(axis, angle), s)
            }
        ),
        (prop::array::uniform9(-1.0..1.0f64), v()).prop_map(|(m, t)| Transform {
            parent_from_child: DAffine3 {
                matrix3: DMat3::from_cols_array(&m) + DMat3::from_diagonal(DVec3::splat(3.0)),
                translation: t,
            },
        }),
    ]
}

fn domain() -> impl Strategy<Value = Option<Domain>> {
    prop::option::of(
        (
            prop::array::uniform3(-5.0..5.0f64),
            prop::array::uniform3(0.01..10.0f64),
        )
            .prop_map(|(c, s)| Domain::new(DVec3::from_array(c), DVec3::from_array(s))),
    )
}

fn ranges() -> impl Strategy<Value = [[f64; 2]; 3]> {
    prop::array::uniform3((-5.0..5.0f64, 0.0..5.0f64).prop_map(|(lo, w)| [lo, lo + w]))
}

fn geometry() -> BoxedStrategy<Geometry> {
    let shape = prop_oneof![
        prop::sample::select(vec!["1-x^2-y^2-z^2", "x & y", "0", "x=1; y=2; z=3;"])
            .prop_map(|f| Shape::Implicit(formula(f))),
        (
            prop::sample::select(vec![
                ParametricKind::Curve,
                ParametricKind::Surface,
                ParametricKind::Solid,
            ]),
            ranges()
        )
            .prop_map(|(kind, parameters)| Shape::Parametric {
                formula: formula("x=u; y=v; z=w;"),
                kind,
                parameters,
            }),
        Just(Shape::Mesh(std::sync::Arc::new(model::mesh::shapes::cube(
            DVec3::splat(-0.3),
            DVec3::new(0.7, 1.1, 0.123_456_7)
        ),))),
    ];
    (shape, domain(), transform())
        .prop_map(|(shape, domain, transform)| Geometry {
            shape,
            domain,
            transform,
        })
        .boxed()
}

fn color() -> BoxedStrategy<Option<ColorDef>> {
    let rgb = || prop::array::uniform3(0.0..=1.0f32);
    prop::option::of(prop_oneof![
        rgb().prop_map(ColorDef::Constant),
        Just(ColorDef::Rgb(formula("r=x; g=y; b=abs(z);"))),
        prop::collection::vec((0.001..1.0f64, rgb()), 1..5).prop_map(|steps| {
            let mut g = -1.0;
            let keys = steps
                .into_iter()
                .map(|(dg, c)| {
                    g += dg;
                    (g, c)
                })
                .collect();
            ColorDef::Map {
                formula: formula("sqrt(x^2+y^2)"),
                map: ColorMap { keys },
            }
        }),
    ])
    .boxed()
}

fn scalar() -> impl Strategy<Value = Option<Formula>> {
    prop::option::of(prop::sample::select(vec!["0.5", "x*t", "0.25"]).prop_map(formula))
}

fn property() -> impl Strategy<Value = Option<Property>> {
    prop::option::of(
        (
            prop::sample::select(vec!["1", "x^2+y^2", "0.3"]),
            any::<bool>(),
        )
            .prop_map(|(f, enabled)| Property {
                formula: formula(f),
                enabled,
            }),
    )
}

fn timing() -> impl Strategy<Value = Timing> {
    (
        prop_oneof![Just(0.0), 0.1..10.0f64],
        prop::option::of((0.0..10.0f64, 0.0..10.0f64).prop_map(|(a, w)| [a, a + w])),
    )
        .prop_map(|(cycle_interval_secs, time_span)| Timing {
            cycle_interval_secs,
            time_span,
        })
}

fn object_data() -> BoxedStrategy<ObjectData> {
    let appearance = (
        (color(), color(), color()),
        (scalar(), scalar(), scalar()),
        domain(),
        transform(),
    )
        .prop_map(
            |((diffuse, ambient, specular), (t, s, d), domain, transform)| Appearance {
                diffuse,
                ambient,
                specular,
                transparency: t,
                shininess: s,
                displacement: d,
                domain,
                transform,
            },
        )
        .boxed();
    let force = prop::option::of((ranges(), timing(), any::<bool>()).prop_map(
        |(parameters, timing, enabled)| ForceField {
            formula: formula("x=u; y=v*t; z=w;"),
            parameters,
            timing,
            enabled,
        },
    ));
    let physics = (
        prop::option::of(geometry()),
        (property(), property(), property(), property()),
        force,
        domain(),
        transform(),
    )
        .prop_map(
            |(container, (tension, friction, zone_depth, density), force, domain, transform)| {
                Physics {
                    container,
                    tension,
                    friction,
                    zone_depth,
                    density,
                    force,
                    domain,
                    transform,
                }
            },
        )
        .boxed();
    let motion = prop::option::of(
        (
            prop::option::of(Just(formula("x=t; y=0; z=-t;"))),
            prop::array::uniform3(-1.0..1.0f64),
            prop::option::of(Just(formula("2*pi*t"))),
            timing(),
        )
            .prop_map(|(translation, axis, angle, timing)| Motion {
                translation,
                axis: DVec3::from_array(axis) + DVec3::X * 2.0,
                angle,
                timing,
            }),
    );
    // A grid no formula calls (the object still holds and saves it), placed by any numbers,
    // -0 included.
    let grid = (
        prop::array::uniform3(2usize..4),
        prop::array::uniform3(prop_oneof![Just(0.0), Just(-0.0), -3.0..3.0f64]),
        prop::array::uniform3(prop_oneof![Just(1.0), 0.01..2.0f64]),
        prop::array::uniform2(-5.0..5.0f64),
        prop::collection::vec(any::<u8>(), 64),
    )
        .prop_map(|(size, origin, spacing, range, bytes)| {
            let n = size.iter().product::<usize>();
            let grid =
                fdsl::grid::Grid::from_raw("scan", size, origin, spacing, range, &bytes[..n]);
            std::sync::Arc::new(grid.unwrap())
        });
    (
        text(),
        prop::option::of(geometry()),
        appearance,
        physics,
        transform(),
        motion,
        prop::option::of(grid),
    )
        .prop_map(
            |(name, geometry, appearance, physics, transform, motion, grid)| ObjectData {
                name,
                geometry,
                appearance: appearance.into(),
                physics: physics.into(),
                transform,
                motion,
                grids: grid.into_iter().collect(),
            },
        )
        .boxed()
}

/// A valid edit with awkward numbers (`-0`, thirds, tiny and large values), and whether it
/// stays active.
fn edit() -> impl Strategy<Value = (Edit, bool)> {
    let coordinate = || prop_oneof![-2.0..2.0f64, Just(-0.0), Just(1.0 / 3.0), Just(1e-9)];
    let size = || prop_oneof![0.05..1.0f64, Just(0.1 + 0.2)];
    let pose = (
        prop::array::uniform3(coordinate()),
        prop::array::uniform4(-1.0..1.0f64),
        0.5..2.0f64,
    )
        .prop_map(|(p, q, scale)| Pose {
            position: DVec3::from_array(p),
            rotation: DQuat::from_array(q) + DQuat::from_xyzw(0.0, 0.0, 0.0, 1.5),
            scale,
        });
    let tool = prop_oneof![
        size().prop_map(|radius| ToolShape::Sphere { radius }),
        (prop::array::uniform3(size()), 0.0..1.0f64).prop_map(|(h, r)| {
            let half_extents = DVec3::from_array(h);
            ToolShape::Box {
                half_extents,
                rounding: r * half_extents.min_element(),
            }
        }),
        (size(), size()).prop_map(|(radius, half_height)| ToolShape::Cylinder {
            radius,
            half_height
        }),
    ];
    let op = prop_oneof![
        Just(EditOp::Union),
        Just(EditOp::Subtract),
        Just(EditOp::Intersect),
        (
            prop::sample::select(Paintable::ALL.to_vec()),
            prop_oneof![
                prop::num::f64::NORMAL.prop_map(PaintValue::Scalar),
                prop::array::uniform3(0.0..=1.0f32).prop_map(PaintValue::Color),
            ]
        )
            .prop_map(|(property, value)| EditOp::Paint { property, value }),
    ];
    let mirror = prop::option::of(prop::sample::select(vec![Axis::X, Axis::Y, Axis::Z]));
    let blend = prop_oneof![Just(0.0), Just(-0.0), 0.0..0.5f64];
    (
        op,
        tool,
        prop::collection::vec(pose, 1..4),
        blend,
        mirror,
        any::<bool>(),
    )
        .prop_map(|(op, tool, path, blend_radius, mirror, active)| {
            let edit = Edit {
                op,
                tool,
                path,
                blend_radius,
                mirror,
            };
            (edit, active)
        })
}

#[derive(Clone, Debug)]
enum Item {
    Object(Box<ObjectData>, Vec<(Edit, bool)>),
    Group(String, Transform, Vec<Item>),
}

fn items() -> impl Strategy<Value = Vec<Item>> {
    let object = || {
        (object_data(), prop::collection::vec(edit(), 0..4))
            .prop_map(|(d, edits)| Item::Object(Box::new(d), edits))
    };
    let leaf = object();
    let tree = leaf.prop_recursive(3, 12, 3, move |inner| {
        prop_oneof![
            2 => object(),
            1 => (text(), transform(), prop::collection::vec(inner, 0..3))
                .prop_map(|(n, t, c)| Item::Group(n, t, c)),
        ]
    });
    prop::collection::vec(tree, 0..4)
}

/// Builds the scene with ids in document order, as the loader gives them.
fn build(items: &[Item], parent: Option<GroupId>, scene: &mut Scene, ids: &mut (u64, u64)) {
    for item in items {
        match item {
            Item::Object(data, edits) => {
                let id = ObjectId(ids.0);
                scene.create(id, (**data).clone(), parent).unwrap();
                for (edit, active) in edits {
                    let idx = scene.apply(id, edit.clone()).unwrap();
                    if !active {
                        scene.object_mut(id).unwrap().undo(idx);
                    }
                }
                ids.0 += 1;
            }
            Item::Group(name, transform, children) => {
                let id = GroupId(ids.1);
                ids.1 += 1;
                let group = Group {
                    name: name.clone(),
                    parent,
                    transform: *transform,
                };
                scene.set_group(id, group).unwrap();
                build(children, Some(id), scene, ids);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn token_soups_never_panic(
        tokens in prop::collection::vec(prop::sample::select(SOUP.to_vec()), 0..120),
        separator in prop::sample::select(vec![" ", "\n", ""]),
    ) {
        let text = tokens.join(separator);
        let _ = try_load(&text, &text);
        let parsed = fvrml::parse(&text);
        // Whatever was read writes out and reads back the same.
        if parsed.document.validate().is_ok() {
            let written = fvrml::write(&parsed.document);
            prop_assert_eq!(&fvrml::parse(&written).document, &parsed.document);
        }
    }

    #[test]
    fn arbitrary_text_never_panics(chars in prop::collection::vec(any::<char>(), 0..200)) {
        let text: String = chars.into_iter().collect();
        let _ = try_load(&text, "");
    }

    #[test]
    fn documents_read_back_equal(nodes in prop::collection::vec(node_ref(), 0..4)) {
        let doc = Document { nodes };
        prop_assert!(doc.validate().is_ok());
        let written = fvrml::write(&doc);
        let parsed = fvrml::parse(&written);
        prop_assert!(parsed.issues.is_empty(), "{:#?}\n{}", parsed.issues, written);
        prop_assert_eq!(&parsed.document, &doc, "{}", written);
        prop_assert_eq!(fvrml::write(&parsed.document), written);
    }
}

/// A field of an `FEdit`, well or badly named, with a value of any form.
fn edit_field() -> impl Strategy<Value = String> {
    let name = prop::sample::select(vec![
        "operation",
        "property",
        "value",
        "tool",
        "radius",
        "halfHeight",
        "halfExtents",
        "rounding",
        "path",
        "blendRadius",
        "mirror",
        "active",
        "colour",
    ]);
    let number = prop_oneof![
        prop::sample::select(vec!["0", "1", "-1", "0.5", "-0", "1e300", "1e-320", "2e6"])
            .prop_map(String::from),
        number().prop_map(fvrml::format_number),
    ];
    let words = prop::sample::select(vec![
        "\"union\"",
        "\"subtract\"",
        "\"intersect\"",
        "\"paint\"",
        "\"sphere\"",
        "\"box\"",
        "\"cylinder\"",
        "\"x\"",
        "\"friction\"",
        "\"diffuseColor\"",
        "\"q\"",
        "TRUE",
        "FALSE",
        "[]",
        "NULL",
        "Sphere { }",
        "[\"a\"]",
    ])
    .prop_map(String::from);
    let value = prop_oneof![
        words,
        prop::collection::vec(number.clone(), 1..4).prop_map(|v| v.join(" ")),
        prop::collection::vec(number, 0..25).prop_map(|v| format!("[{}]", v.join(" "))),
    ];
    (name, value).prop_map(|(n, v)| format!("{n} {v}"))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Random `FEdit`s load or fail with located issues; none panics.
    #[test]
    fn random_edits_are_read_or_located(fields in prop::collection::vec(edit_field(), 0..9)) {
        let text = with_edit(&fields.join(" "));
        let _ = try_load(&text, "");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn scenes_survive_save_and_load(items in items()) {
        let mut scene = Scene::new();
        build(&items, None, &mut scene, &mut (0, 0));
        let text = fvrml::write(&fvrml::save(&scene));
        let mut no_files = |p: &str| Err(format!("no {p}"));
        let loaded = match fvrml::load(&text, &LoadOptions::default(), &mut no_files) {
            Ok(loaded) => loaded,
            Err(e) => return Err(TestCaseError::fail(format!("{e}\n{text}"))),
        };
        prop_assert!(loaded.warnings.is_empty(), "{:#?}", loaded.warnings);
        prop_assert_eq!(&loaded.scene, &scene, "{}", text);
        prop_assert_eq!(fvrml::write(&fvrml::save(&loaded.scene)), text);
    }
}

/// An `FShape` whose third line is `edits [ FEdit { <body> } ]`.
fn with_edit(body: &str) -> String {
    format!("FShape {{\n  geometry Sphere {{ radius 1 }}\n  edits [ FEdit {{ {body} }} ]\n}}\n")
}

/// A stamp that loads cleanly, to build hostile variants from.
const STAMP: &str = r#"operation "subtract" tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 1]"#;

/// Each malformed `FEdit` is an error (the load fails) or a warning (the load goes on), with
/// the message's words, at the first character of `at` (line 3 of the text), never a panic.
/// Errors are for what cannot be read as written, as for every other node; warnings for
/// what is ignored (unknown fields, a node of another type, sizes the tool does not use).
#[test]
fn hostile_edits_are_located_errors_or_warnings() {
    use fdsl::Severity::{Error, Warning};
    let pose = "0 0 0 0 0 0 1 1 ";
    let too_many_poses = format!(
        r#"operation "union" tool "sphere" radius 0.1 path [{}]"#,
        pose.repeat(model::limits::MAX_STROKE_POSES + 1)
    );
    let cases: Vec<(String, &str, fdsl::Severity, &str)> = vec![
        (r#"operation "smear" tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "\"smear\"", Error, "`operation` is one of \"union\", \"subtract\", \"intersect\" or \"paint\""),
        (r#"operation 3 tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "3 tool", Error, "`operation` is one of"),
        (r#"tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "FEdit", Error, "needs an `operation`"),
        (r#"operation "union" tool "sphere" radius 0.1 path [0 0 0 0 0 0 1]"#.into(), "[0 0 0 0 0 0 1]", Error, "8 numbers per pose"),
        (r#"operation "union" tool "sphere" radius 0.1 path []"#.into(), "[]", Error, "a stroke needs 1 to MAX_STROKE_POSES poses"),
        (too_many_poses, "[0 0", Error, "a stroke needs 1 to MAX_STROKE_POSES poses"),
        (r#"operation "union" tool "sphere" radius 0.1 path "0 0 0""#.into(), "\"0 0 0\"", Error, "should be numbers"),
        (r#"operation "union" tool "sphere" radius 0.1 path [0 1e999 0 0 0 0 1 1]"#.into(), "1e999", Error, "the number `1e999` is out of range"),
        (r#"operation "union" tool "sphere" radius -0.1 path [0 0 0 0 0 0 1 1]"#.into(), "\"sphere\"", Error, "tool sizes must be positive"),
        (r#"operation "union" tool "cylinder" radius 0.1 halfHeight 1e7 path [0 0 0 0 0 0 1 1]"#.into(), "\"cylinder\"", Error, "at most MAX_TOOL_SIZE"),
        (r#"operation "union" tool "box" halfExtents 0.1 0.1 0.1 rounding 0.2 path [0 0 0 0 0 0 1 1]"#.into(), "\"box\"", Error, "tool sizes"),
        (r#"operation "union" tool "cylinder" radius 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "FEdit", Error, "a \"cylinder\" tool needs `halfHeight`"),
        (r#"operation "union" tool "box" halfExtents 0.1 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "0.1 0.1 path", Error, "should be 3 numbers"),
        (r#"operation "union" tool "cone" radius 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "\"cone\"", Error, "`tool` is one of"),
        (r#"operation "union" radius 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "FEdit", Error, "needs a `tool`"),
        (r#"operation "union" tool "sphere" radius 0.1"#.into(), "FEdit", Error, "needs a `path`"),
        (format!("{STAMP} blendRadius -1"), "-1", Error, "the blend radius must be finite and not negative"),
        (format!("{STAMP} blendRadius 1 2"), "1 2", Error, "should be one number"),
        (r#"operation "union" tool "sphere" radius 0.1 path [0 0 0 0 0 0 0 1]"#.into(), "[0 0 0 0 0 0 0 1]", Error, "non-zero rotation"),
        (r#"operation "union" tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 0]"#.into(), "[0 0 0 0 0 0 1 0]", Error, "positive scale"),
        (r#"operation "union" tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 1, 2e6 0 0 0 0 0 1 1]"#.into(), "[0 0 0", Error, "poses must be finite"),
        (r#"operation "union" tool "box" halfExtents 1e-6 1e-6 1e-6 path [0 0 0 0 0 0 1 1, 1000 0 0 0 0 0 1 1]"#.into(), "[0 0 0", Error, "MAX_STROKE_STAMPS"),
        (format!("{STAMP} mirror \"w\""), "\"w\"", Error, "`mirror` is one of \"x\", \"y\" or \"z\""),
        (format!("{STAMP} active 1"), "1 } ]", Error, "TRUE or FALSE"),
        (r#"operation "paint" tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 1] value 0.5"#.into(), "FEdit", Error, "needs a `property`"),
        (r#"operation "paint" property "friction" tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "FEdit", Error, "needs a `value`"),
        (r#"operation "paint" property "smell" value 1 tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "\"smell\"", Error, "`property` is one of \"diffuseColor\""),
        (r#"operation "paint" property "friction" value 1 2 tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "1 2", Error, "one number (a scalar) or three"),
        (r#"operation "paint" property "diffuseColor" value 2 0 0 tool "sphere" radius 0.1 path [0 0 0 0 0 0 1 1]"#.into(), "2 0 0", Error, "colours within [0, 1]"),
        (format!("{STAMP} colour 1 0 0"), "colour", Warning, "`FEdit` has no field `colour`"),
        (format!("{STAMP} halfHeight 1"), "halfHeight", Warning, "`halfHeight` is ignored for a \"sphere\" tool"),
        (format!("{STAMP} property \"friction\""), "property", Warning, "`property` is ignored: only painting uses it"),
        (format!("{STAMP} path [0 0 0 0 0 0 1 2]"), "path [0 0 0 0 0 0 1 1]", Warning, "given again later"),
    ];
    for (body, at, severity, message) in &cases {
        let text = with_edit(body);
        let result = try_load(&text, "");
        assert_eq!(result.is_err(), *severity == Error, "{body}: {result:#?}");
        let issues = result.unwrap_or_else(|issues| issues);
        let Some(issue) = issues
            .iter()
            .find(|i| i.severity == *severity && i.message.contains(message))
        else {
            panic!("{body}: no {severity:?} with {message:?} in {issues:#?}");
        };
        let offset = text
            .find(at)
            .unwrap_or_else(|| panic!("{at:?} is not in {text}"));
        assert_eq!(
            issue.location.span.start as usize, offset,
            "{body}: {issue}"
        );
        let line_start = text[..offset].rfind('\n').map_or(0, |i| i + 1);
        let column = text[line_start..offset].chars().count() + 1;
        assert_eq!(issue.location.line, 3, "{body}: {issue}");
        assert_eq!(issue.location.column as usize, column, "{body}: {issue}");
    }

    // Other nodes in `edits` are skipped with a warning, `NULL` quietly; the good edit stays.
    let text = format!(
        "FShape {{\n  geometry Sphere {{ radius 1 }}\n  edits [ Sphere {{ }} NULL FEdit {{ {STAMP} }} ]\n}}\n"
    );
    let issues = try_load(&text, "").unwrap();
    assert_eq!(issues.len(), 1, "{issues:#?}");
    assert!(issues[0].message.contains("`Sphere` cannot be in `edits`"));
    let issues = errors("FShape { edits 5 }");
    assert!(
        issues[0].message.contains("a list of `FEdit` nodes"),
        "{issues:#?}"
    );
    let issues = errors("FShape { edits [ USE Nothing ] }");
    assert!(issues[0].message.contains("`USE Nothing`"), "{issues:#?}");
    // Plain VRML shapes carry no edits.
    let issues = try_load(&format!("Shape {{ edits [ FEdit {{ {STAMP} }} ] }}"), "").unwrap();
    assert!(
        issues[0].message.contains("`Shape` has no field `edits`"),
        "{issues:#?}"
    );
}

/// Documents built in code can hold numbers no text can: NaN and infinities are refused by
/// the object model, as the same edit from a peer would be.
#[test]
fn edits_with_numbers_that_are_not_finite_are_refused() {
    let num = |name: &str, v: Vec<f64>| Field::new(name, Value::Numbers(v));
    let edit = |path: Vec<f64>, blend: f64| {
        let fields = vec![
            Field::new("operation", Value::String("union".into())),
            Field::new("tool", Value::String("sphere".into())),
            num("radius", vec![0.1]),
            Field::new("path", Value::NumberList(path)),
            num("blendRadius", vec![blend]),
        ];
        NodeRef::Node(Box::new(Node::new("FEdit", fields)))
    };
    let pose = |x: f64| vec![x, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0];
    for (item, message) in [
        (edit(pose(f64::NAN), 0.0), "poses must be finite"),
        (edit(pose(f64::INFINITY), 0.0), "poses must be finite"),
        (edit(pose(0.0), f64::NAN), "the blend radius must be finite"),
        (
            edit(pose(0.0), f64::NEG_INFINITY),
            "the blend radius must be finite",
        ),
    ] {
        let shape = Node::new(
            "FShape",
            vec![Field::new("edits", Value::NodeList(vec![item]))],
        );
        let doc = Document {
            nodes: vec![NodeRef::Node(Box::new(shape))],
        };
        let mut no_files = |p: &str| Err(format!("no {p}"));
        let issues = fvrml::load_document(&doc, &LoadOptions::default(), &mut no_files)
            .unwrap_err()
            .issues;
        assert!(issues[0].message.contains(message), "{issues:#?}");
    }
}

/// `USE` makes a file small and its objects large: the edits one object may hold, the edits
/// all loaded objects hold and the stamps the edits expand to are each bounded.
#[test]
fn edit_limits_hold_against_use_copies() {
    let max = model::limits::MAX_EDITS_PER_OBJECT;
    let uses = |n: usize| " USE E".repeat(n);
    let head = format!("FShape {{ edits [ DEF E FEdit {{ {STAMP} }} ] }}\n");
    let text = format!("{head}FShape {{ edits [{}] }}", uses(max + 1));
    let issues = errors(&text);
    assert!(
        issues[0].message.contains("more than the limit"),
        "{issues:#?}"
    );
    // Each copy of a full shape counts again.
    let copies = fvrml::MAX_LOAD_EDITS / max;
    let text = format!(
        "{head}DEF S FShape {{ edits [{}] }}\n{}",
        uses(max - 1),
        "USE S\n".repeat(copies)
    );
    let issues = errors(&text);
    assert!(
        issues[0].message.contains("edits; stopped"),
        "{:#?}",
        &issues[..1]
    );
    // Distinct short edits sweeping a tiny box far.
    let sweep = r#"FEdit { operation "union" tool "box" halfExtents 1e-4 1e-4 1e-4 path [0 0 0 0 0 0 1 1, 0.8 0 0 0 0 0 1 1] }"#;
    let n_stamps = 16_001;
    let n = fvrml::MAX_LOAD_STAMPS / n_stamps + 1;
    let text = format!("FShape {{ edits [ {} ] }}", [sweep].repeat(n).join("\n"));
    let issues = errors(&text);
    assert!(
        issues[0].message.contains("tool stamps; stopped"),
        "{issues:#?}"
    );
}
