//! FVRML against hostile input (truncated figures, unbalanced brackets, huge numbers, deep
//! nesting, USE explosions, Inline cycles, token soups) and the round-trip properties: for
//! random documents `parse(write(doc)) == doc` and writing is idempotent; for random scenes
//! `load(save(scene)) == scene`.
#![allow(clippy::unwrap_used, reason = "test helpers unwrap")]

use fdsl::fvrml::{self, Document, Field, Issue, LoadOptions, Node, NodeRef, Value};
use fdsl::object::{
    Appearance, ColorDef, ColorMap, Domain, ForceField, Formula, Geometry, Motion, ObjectData,
    ParametricKind, Physics, Property, Shape, Timing, Transform,
};
use fdsl::scene::{Group, GroupId, ObjectId, Scene};
use glam::{DAffine3, DMat3, DQuat, DVec3};
use proptest::prelude::*;

const FIGURES: [&str; 4] = [
    include_str!("../../tests/data/scenes/figure_7_4.wrl"),
    include_str!("../../tests/data/scenes/figure_7_8.wrl"),
    include_str!("../../tests/data/scenes/figure_7_14.wrl"),
    include_str!("../../scenes/watermelon.wrl"),
];

/// Loads with a resolver that serves `inline` for every path; checks that every issue has
/// a position inside the text it names (root text only).
fn try_load(text: &str, inline: &str) -> Result<Vec<Issue>, Vec<Issue>> {
    let mut resolve = |_: &str| Ok(inline.to_string());
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

/// Runs `f` on a named thread with a small stack, so that unbounded recursion would crash.
fn on_small_stack(f: impl FnOnce() + Send + 'static) {
    std::thread::Builder::new()
        .name("fvrml-small-stack".into())
        .stack_size(2048 * 1024)
        .spawn(f)
        .unwrap()
        .join()
        .unwrap();
}

#[test]
fn deep_nesting_never_overflows_the_stack() {
    on_small_stack(|| {
        let braces = "Group { children [ ".repeat(100_000);
        let issues = errors(&braces);
        assert!(
            issues
                .iter()
                .any(|i| i.message.contains("deeper than the limit of 128"))
        );
        let _ = errors(&"[".repeat(1_000_000));
        let _ = errors(&"{".repeat(1_000_000));
        let _ = errors(&format!("Group {{ children {} }}", "[".repeat(1_000_000)));
        // Closed, but deeper than the limit.
        let text = format!(
            "{}FShape {{ }}{}",
            "Transform { children [ ".repeat(200),
            "] } ".repeat(200)
        );
        assert!(!errors(&text).is_empty());
        // 63 nested groups (the scene allows 64) around a shape load.
        let text = format!(
            "{}FShape {{ }}{}",
            "Transform { children [ ".repeat(63),
            "] } ".repeat(63)
        );
        assert!(try_load(&text, "").is_ok());
        // The worst case for the stack: a moving FTransform (nested groups flatten, so only
        // the nesting limit applies) around an Inline whose file is parsed at that depth and
        // nests as deep again (the loader then stops at its limit).
        let deep = |inner: &str| {
            format!(
                "{}{inner}{}",
                "Transform { children [ ".repeat(125),
                "] } ".repeat(125)
            )
        };
        let text = format!(
            "FTransform {{ translationFunction \"x=t; y=0; z=0;\" children [ {} ] }}",
            deep("Inline { url \"deep.wrl\" }")
        );
        let issues = try_load(&text, &deep("FShape { }")).unwrap_err();
        assert!(
            issues[0]
                .message
                .contains("groups nest deeper than the limit of 128")
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
        ))
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
        Just(Shape::Mesh(std::sync::Arc::new(fdsl::mesh::shapes::cube(
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
    (
        text(),
        prop::option::of(geometry()),
        appearance,
        physics,
        transform(),
        motion,
    )
        .prop_map(
            |(name, geometry, appearance, physics, transform, motion)| ObjectData {
                name,
                geometry,
                appearance,
                physics,
                transform,
                motion,
            },
        )
        .boxed()
}

#[derive(Clone, Debug)]
enum Item {
    Object(Box<ObjectData>),
    Group(String, Transform, Vec<Item>),
}

fn items() -> impl Strategy<Value = Vec<Item>> {
    let leaf = object_data().prop_map(|d| Item::Object(Box::new(d)));
    let tree = leaf.prop_recursive(3, 12, 3, |inner| {
        prop_oneof![
            2 => object_data().prop_map(|d| Item::Object(Box::new(d))),
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
            Item::Object(data) => {
                scene
                    .create(ObjectId(ids.0), (**data).clone(), parent)
                    .unwrap();
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
