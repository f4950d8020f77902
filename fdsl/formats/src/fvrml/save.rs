//! A [`Scene`] to a [`Document`]: groups become `Group` or `Transform` nodes, objects become
//! `FShape`s with every property and their edit histories (`FEdit`s) written out, in an order
//! that makes the loader give the same ids back (see [`save`]).

use std::collections::BTreeMap;

use super::document::{Document, Field, Node, NodeRef, Value};
use super::edit::write_edits;
use super::placement::{numbers, write_domain, write_motion, write_timing, write_transform};
use super::shape::parametric_by_outputs;
use model::mesh::TriMesh;
use model::object::{
    Appearance, ColorDef, ColorMap, ForceField, Formula, Geometry, Object, ParametricKind, Physics,
    Property, Shape,
};
use model::scene::{GroupId, ObjectId, Scene};

/// The scene as a document. Every object is an `FShape` holding its name, transform, motion,
/// geometry, appearance, physics and edit history (`edits`, one `FEdit` per edit in history
/// order, undone ones with `active FALSE`); every group a `Group` (identity transform) or a
/// `Transform` holding its name. Numbers are written as they are, so loading gives back the
/// same objects and edits bit for bit.
///
/// Ids are not written either. Siblings are written in id order, a group placed before an
/// object when its first object has a smaller id, so loading gives every object and group
/// the id it had whenever the scene's ids were given in that order from the load's first
/// ids, as they are in any loaded scene.
pub fn save(scene: &Scene) -> Document {
    let mut saver = Saver {
        scene,
        groups: BTreeMap::new(),
        objects: BTreeMap::new(),
        first_object: BTreeMap::new(),
    };
    for (id, group) in scene.groups() {
        saver.groups.entry(group.parent).or_default().push(id);
    }
    for (id, o) in scene.objects() {
        saver.objects.entry(o.group).or_default().push(id);
    }
    // Ancestors' first objects: walk up from each object (ids are visited in order, so the
    // first object seen under a group is its smallest).
    for (id, o) in scene.objects() {
        let mut up = o.group;
        let mut depth = 0;
        while let Some(g) = up {
            saver.first_object.entry(g).or_insert(id);
            up = scene.group(g).and_then(|g| g.parent);
            depth += 1;
            if depth > model::limits::MAX_GROUP_DEPTH {
                break;
            }
        }
    }
    Document {
        nodes: saver.level(None, 0),
    }
}

struct Saver<'s> {
    scene: &'s Scene,
    groups: BTreeMap<Option<GroupId>, Vec<GroupId>>,
    objects: BTreeMap<Option<GroupId>, Vec<ObjectId>>,
    first_object: BTreeMap<GroupId, ObjectId>,
}

impl Saver<'_> {
    /// The nodes under `parent`, merged in id order.
    fn level(&self, parent: Option<GroupId>, depth: usize) -> Vec<NodeRef> {
        let groups = self.groups.get(&parent).map(Vec::as_slice).unwrap_or(&[]);
        let objects = self.objects.get(&parent).map(Vec::as_slice).unwrap_or(&[]);
        let (mut g, mut o) = (0, 0);
        let mut out = Vec::with_capacity(groups.len() + objects.len());
        while g < groups.len() || o < objects.len() {
            let group_first = match (groups.get(g), objects.get(o)) {
                (Some(gid), Some(oid)) => self.first_object.get(gid).is_none_or(|f| f < oid),
                (Some(_), None) => true,
                _ => false,
            };
            if group_first {
                out.push(self.group(groups[g], depth));
                g += 1;
            } else {
                if let Some(object) = self.scene.object(objects[o]) {
                    out.push(node(shape(object)));
                }
                o += 1;
            }
        }
        out
    }

    fn group(&self, id: GroupId, depth: usize) -> NodeRef {
        let Some(group) = self.scene.group(id) else {
            return NodeRef::Null;
        };
        let mut fields = Vec::new();
        if !group.name.is_empty() {
            fields.push(Field::new("name", Value::String(group.name.clone())));
        }
        write_transform(&group.transform, &mut fields);
        let type_name = if fields.iter().any(|f| f.name != "name") {
            "Transform"
        } else {
            "Group"
        };
        // The scene bounds group depth; the guard keeps a broken scene from recursing far.
        let children = if depth < model::limits::MAX_GROUP_DEPTH {
            self.level(Some(id), depth + 1)
        } else {
            Vec::new()
        };
        if !children.is_empty() {
            fields.push(Field::new("children", Value::NodeList(children)));
        }
        node(Node::new(type_name, fields))
    }
}

fn node(n: Node) -> NodeRef {
    NodeRef::Node(Box::new(n))
}

fn string(name: &str, f: &Formula) -> Field {
    Field::new(name, Value::String(f.as_str().to_string()))
}

fn node_field(name: &str, n: Node) -> Field {
    Field::new(name, Value::Node(node(n)))
}

/// An object as an `FShape`.
fn shape(object: &Object) -> Node {
    let data = object.data();
    let mut fields = Vec::new();
    if !data.name.is_empty() {
        fields.push(Field::new("name", Value::String(data.name.clone())));
    }
    write_transform(&data.transform, &mut fields);
    if let Some(m) = &data.motion {
        write_motion(m, &mut fields);
    }
    if let Some(g) = &data.geometry {
        fields.push(node_field("geometry", geometry(g)));
    }
    if *data.appearance != Appearance::default() {
        fields.push(node_field("appearance", appearance(&data.appearance)));
    }
    if *data.physics != Physics::default() {
        fields.push(node_field("physics", physics(&data.physics)));
    }
    super::grid::write_grids(&data.grids, &mut fields);
    write_edits(object, &mut fields);
    Node::new("FShape", fields)
}

fn geometry(g: &Geometry) -> Node {
    let mut fields = Vec::new();
    match &g.shape {
        Shape::Mesh(mesh) => {
            let faces = mesh_node(mesh);
            if g.domain.is_none() && g.transform.is_identity() {
                return faces;
            }
            fields.push(node_field("mesh", faces));
        }
        Shape::Implicit(f) => {
            fields.push(string("definition", f));
            if parametric_by_outputs(f).is_some() {
                fields.push(Field::new("kind", Value::String("implicit".into())));
            }
        }
        Shape::Parametric {
            formula,
            kind,
            parameters,
        } => {
            fields.push(string("definition", formula));
            let kind = match kind {
                ParametricKind::Curve => "curve",
                ParametricKind::Surface => "surface",
                ParametricKind::Solid => "solid",
            };
            fields.push(Field::new("kind", Value::String(kind.into())));
            fields.push(ranges(parameters));
        }
    }
    match &g.domain {
        Some(d) => write_domain(d, &mut fields),
        // Said on purpose, so that loading neither fits one (`fitted.rs`) nor reads a
        // constant 0 as physics for its group (`lend.rs`).
        None if matches!(g.shape, Shape::Implicit(_)) => {
            fields.push(numbers("bboxSize", &[-1.0; 3]));
        }
        None => {}
    }
    write_transform(&g.transform, &mut fields);
    Node::new("FGeometry", fields)
}

/// A mesh as VRML's `IndexedFaceSet`, one triangle per `-1`-ended polygon.
fn mesh_node(mesh: &TriMesh) -> Node {
    let list = |v: Vec<f64>| {
        if v.is_empty() {
            Value::EmptyList
        } else {
            Value::NumberList(v)
        }
    };
    let points = mesh
        .positions()
        .iter()
        .flat_map(|p| p.map(f32_value))
        .collect();
    let indices = mesh
        .triangles()
        .iter()
        .flat_map(|t| [f64::from(t[0]), f64::from(t[1]), f64::from(t[2]), -1.0])
        .collect();
    let coord = Node::new("Coordinate", vec![Field::new("point", list(points))]);
    Node::new(
        "IndexedFaceSet",
        vec![
            node_field("coord", coord),
            Field::new("coordIndex", list(indices)),
        ],
    )
}

fn ranges(parameters: &[[f64; 2]; 3]) -> Field {
    Field::new(
        "parameters",
        Value::NumberList(parameters.iter().flatten().copied().collect()),
    )
}

fn appearance(a: &Appearance) -> Node {
    let mut material = Vec::new();
    for (name, def) in [
        ("diffuseColor", &a.diffuse),
        ("ambientColor", &a.ambient),
        ("specularColor", &a.specular),
    ] {
        if let Some(def) = def {
            color(name, def, &mut material);
        }
    }
    if let Some(f) = &a.transparency {
        material.push(string("transparency", f));
    }
    if let Some(f) = &a.shininess {
        material.push(string("shininess", f));
    }
    let mut fields = Vec::new();
    if !material.is_empty() {
        fields.push(node_field("material", Node::new("FMaterial", material)));
    }
    if let Some(f) = &a.displacement {
        let texture = Node::new("FTexture3D", vec![string("definition", f)]);
        fields.push(node_field("texture", texture));
    }
    if let Some(d) = &a.domain {
        write_domain(d, &mut fields);
    }
    write_transform(&a.transform, &mut fields);
    Node::new("FAppearance", fields)
}

fn color(name: &str, def: &ColorDef, out: &mut Vec<Field>) {
    match def {
        ColorDef::Constant(c) => out.push(numbers(name, &c.map(f32_value))),
        ColorDef::Rgb(f) => out.push(string(name, f)),
        ColorDef::Map { formula, map } => {
            out.push(string(name, formula));
            out.push(node_field(&format!("{name}Map"), color_map(map)));
        }
    }
}

fn color_map(map: &ColorMap) -> Node {
    let key = map.keys.iter().map(|(g, _)| *g).collect();
    let values = map
        .keys
        .iter()
        .flat_map(|(_, c)| c.map(f32_value))
        .collect();
    Node::new(
        "FColorMap",
        vec![
            Field::new("key", Value::NumberList(key)),
            Field::new("keyValue", Value::NumberList(values)),
        ],
    )
}

/// An `f32` as the shortest `f64` whose text reads back to the same `f32` (so `0.8f32` is
/// written `0.8`, not `0.800000011920929`).
pub(super) fn f32_value(v: f32) -> f64 {
    let short: f64 = format!("{v}").parse().unwrap_or(f64::from(v));
    let same = short as f32 == v;
    if same { short } else { f64::from(v) }
}

fn physics(p: &Physics) -> Node {
    let mut surface = Vec::new();
    for (name, type_name, prop) in [
        ("tension", "FTension", &p.tension),
        ("friction", "FFriction", &p.friction),
        ("depth", "FDepth", &p.zone_depth),
    ] {
        if let Some(prop) = prop {
            surface.push(node_field(name, property(type_name, prop)));
        }
    }
    let mut fields = Vec::new();
    if !surface.is_empty() {
        fields.push(node_field("surface", Node::new("FSurface", surface)));
    }
    if let Some(d) = &p.density {
        fields.push(node_field("density", property("FDensity", d)));
    }
    if let Some(f) = &p.force {
        fields.push(node_field("force", force(f)));
    }
    if let Some(c) = &p.container {
        fields.push(node_field("container", geometry(c)));
    }
    if let Some(d) = &p.domain {
        write_domain(d, &mut fields);
    }
    write_transform(&p.transform, &mut fields);
    Node::new("FPhysics", fields)
}

fn property(type_name: &str, p: &Property) -> Node {
    Node::new(
        type_name,
        vec![
            Field::new("enable", Value::Bool(p.enabled)),
            string("definition", &p.formula),
        ],
    )
}

fn force(f: &ForceField) -> Node {
    let mut fields = vec![
        Field::new("enable", Value::Bool(f.enabled)),
        string("definition", &f.formula),
        ranges(&f.parameters),
    ];
    write_timing(&f.timing, &mut fields);
    Node::new("FForce", fields)
}
