//! Sculpting edits as `FEdit` nodes (our extension), read and written. An `FShape`'s
//! `edits [ FEdit { ... } ... ]` is its object's history in order: each edit's operation
//! (and, for painting, the property and its value), tool, stroke, blend radius, mirror plane
//! and whether it is active (an undone edit stays in the history, `active FALSE`).
//!
//! Reading checks the syntax (field types, names, counts); whether an edit is valid is the
//! object model's decision ([`CompiledEdit::new`], the same check as for edits from peers),
//! which the loader reports at the field it is about.

use glam::{DQuat, DVec3};

use super::document::{Field, Node, NodeRef, Pos, Value};
use super::placement::numbers;
use super::read::{Fields, Reader};
use super::save::f32_value;
use model::limits::MAX_EDITS_PER_OBJECT;
use model::object::{
    Axis, Edit, EditOp, Object, ObjectError, PaintValue, Paintable, Pose, ToolKind, ToolShape,
    ToolSize,
};

#[cfg(doc)]
use model::object::CompiledEdit;

/// Numbers per pose in `path`: the position `x y z`, the rotation quaternion `qx qy qz qw`
/// and the uniform scale.
pub(super) const POSE_NUMBERS: usize = 8;

/// The values of `operation` (`Paint` stands for every painting; its property is read apart).
const OPERATIONS: [(&str, EditOp); 4] = [
    ("union", EditOp::Union),
    ("subtract", EditOp::Subtract),
    ("intersect", EditOp::Intersect),
    (
        "paint",
        EditOp::Paint {
            property: Paintable::Color,
            value: PaintValue::Scalar(0.0),
        },
    ),
];

/// The values of `property`: the names of the `FMaterial` and `FPhysics` fields they paint.
const PROPERTIES: [(&str, Paintable); 7] = [
    ("diffuseColor", Paintable::Color),
    ("transparency", Paintable::Transparency),
    ("shininess", Paintable::Shininess),
    ("tension", Paintable::Tension),
    ("friction", Paintable::Friction),
    ("depth", Paintable::ZoneDepth),
    ("density", Paintable::Density),
];

/// The values of `tool`: every kind's name.
fn tools() -> [(&'static str, ToolKind); ToolKind::ALL.len()] {
    ToolKind::ALL.map(|kind| (kind.name(), kind))
}

/// The values of `mirror`: the axis normal to the mirror plane.
const AXES: [(&str, Axis); 3] = [("x", Axis::X), ("y", Axis::Y), ("z", Axis::Z)];

/// An `FEdit` as read, before the object model checks it.
pub(super) struct ReadEdit {
    pub(super) edit: Edit,
    pub(super) active: bool,
    /// Where the node and the parts the object model may refuse were written.
    node_pos: Pos,
    tool_pos: Pos,
    path_pos: Pos,
    blend_pos: Pos,
    value_pos: Pos,
}

impl ReadEdit {
    /// Where the object model's refusal `e` of this edit points.
    pub(super) fn pos_of(&self, e: &ObjectError) -> Pos {
        let blend = self.edit.blend_radius;
        match e {
            ObjectError::BadTool { .. } => self.tool_pos,
            ObjectError::BadPaint => self.value_pos,
            ObjectError::BadStroke { .. } if !(blend.is_finite() && blend >= 0.0) => self.blend_pos,
            ObjectError::BadStroke { .. } => self.path_pos,
            _ => self.node_pos,
        }
    }
}

impl<'d> Reader<'_, 'd> {
    /// The `FEdit` nodes of an `FShape`'s `edits` field, in order (`USE` resolved, `NULL`
    /// skipped, nodes of other types warned about and skipped).
    pub(super) fn edit_nodes(&mut self, field: &'d Field) -> Vec<&'d Node> {
        self.listed_nodes(field, "FEdit", MAX_EDITS_PER_OBJECT, "edits")
    }

    /// An `FEdit`: `operation`, `property` and `value` (painting), `tool` and its sizes,
    /// `path`, `blendRadius` (default 0), `mirror` (default none), `active` (default `TRUE`).
    pub(super) fn edit(&mut self, node: &'d Node) -> Option<ReadEdit> {
        let mut fields = Fields::new(node);
        let (op, value_pos) = self.operation(&mut fields);
        let (tool, tool_pos) = self.tool(&mut fields);
        let (path, path_pos) = self.path(&mut fields);
        let blend_field = fields.get("blendRadius");
        let blend_radius = blend_field.map_or(Some(0.0), |f| self.number(f));
        let mirror = match fields.get("mirror") {
            Some(f) => self.keyword(f, &AXES).map(Some),
            None => Some(None),
        };
        let active = fields.get("active").map_or(Some(true), |f| self.boolean(f));
        self.finish(fields);
        Some(ReadEdit {
            edit: Edit {
                op: op?,
                tool: tool?,
                path: path?,
                blend_radius: blend_radius?,
                mirror: mirror?,
            },
            active: active?,
            node_pos: node.pos,
            tool_pos,
            path_pos,
            blend_pos: blend_field.map_or(node.pos, |f| f.value_pos),
            value_pos,
        })
    }

    /// `operation`, with `property` and `value` for `"paint"`; also where the value is.
    fn operation(&mut self, fields: &mut Fields<'d>) -> (Option<EditOp>, Pos) {
        let node = fields.node;
        let property = fields.get("property");
        let value = fields.get("value");
        let value_pos = value.map_or(node.pos, |f| f.value_pos);
        let Some(field) = fields.get("operation") else {
            self.error(
                node.pos,
                format!("`FEdit` needs an `operation` ({})", one_of(&OPERATIONS)),
            );
            return (None, value_pos);
        };
        let op = self.keyword(field, &OPERATIONS);
        if !matches!(op, Some(EditOp::Paint { .. })) {
            if op.is_some() {
                for f in [property, value].into_iter().flatten() {
                    self.warning(
                        f.pos,
                        format!("`{}` is ignored: only painting uses it", f.name),
                    );
                }
            }
            return (op, value_pos);
        }
        let property = match property {
            Some(f) => self.keyword(f, &PROPERTIES),
            None => {
                self.error(
                    node.pos,
                    format!(
                        "a painting `FEdit` needs a `property` ({})",
                        one_of(&PROPERTIES)
                    ),
                );
                None
            }
        };
        let value = match value {
            Some(f) => self.paint_value(f),
            None => {
                self.error(
                    node.pos,
                    "a painting `FEdit` needs a `value` (one number, or three for a colour)",
                );
                None
            }
        };
        let op = property
            .zip(value)
            .map(|(property, value)| EditOp::Paint { property, value });
        (op, value_pos)
    }

    /// One number (a scalar) or three (a colour `r g b`).
    fn paint_value(&mut self, field: &'d Field) -> Option<PaintValue> {
        match self.numbers_of(field)? {
            [v] => Some(PaintValue::Scalar(*v)),
            [r, g, b] => Some(PaintValue::Color([*r as f32, *g as f32, *b as f32])),
            v => {
                self.error(
                    field.value_pos,
                    format!(
                        "`value` should be one number (a scalar) or three (a colour r g b), \
                         not {}",
                        v.len()
                    ),
                );
                None
            }
        }
    }

    /// `tool` and the sizes its shape needs; also where the tool is named.
    fn tool(&mut self, fields: &mut Fields<'d>) -> (Option<ToolShape>, Pos) {
        let node = fields.node;
        let Some(field) = fields.get("tool") else {
            self.error(
                node.pos,
                format!("`FEdit` needs a `tool` ({})", one_of(&tools())),
            );
            return (None, node.pos);
        };
        let pos = field.value_pos;
        let Some(kind) = self.keyword(field, &tools()) else {
            return (None, pos);
        };
        let tool = kind.name();
        for size in ToolSize::ALL {
            if !kind.sizes().contains(&size)
                && let Some(f) = fields.get(size.name)
            {
                let name = size.name;
                self.warning(f.pos, format!("`{name}` is ignored for a \"{tool}\" tool"));
            }
        }
        // Every size is read, so that each missing or bad one is reported.
        let values: Vec<Option<Vec<f64>>> = kind
            .sizes()
            .iter()
            .map(|size| self.size(fields, *size, tool))
            .collect();
        // `size` gives each size its count of numbers, so the values always fit the kind.
        let shape = values
            .into_iter()
            .collect::<Option<Vec<_>>>()
            .and_then(|values| ToolShape::from_sizes(kind, &values));
        (shape, pos)
    }

    /// The numbers of a size the tool needs: its field's, or its default when left out.
    fn size(&mut self, fields: &mut Fields<'d>, size: ToolSize, tool: &str) -> Option<Vec<f64>> {
        match fields.get(size.name) {
            Some(f) if size.n_numbers == 3 => self.vec3(f).map(|v| v.to_array().to_vec()),
            Some(f) => self.number(f).map(|v| vec![v]),
            None => match size.default {
                Some(v) => Some(vec![v; size.n_numbers]),
                None => {
                    let name = size.name;
                    self.error(fields.node.pos, format!("a \"{tool}\" tool needs `{name}`"));
                    None
                }
            },
        }
    }

    /// `path`: [`POSE_NUMBERS`] numbers per pose; also where it is.
    fn path(&mut self, fields: &mut Fields<'d>) -> (Option<Vec<Pose>>, Pos) {
        let node = fields.node;
        let Some(field) = fields.get("path") else {
            self.error(
                node.pos,
                "`FEdit` needs a `path` (per pose: x y z, rotation qx qy qz qw, scale)",
            );
            return (None, node.pos);
        };
        let pos = field.value_pos;
        let Some(v) = self.numbers_of(field) else {
            return (None, pos);
        };
        if !v.len().is_multiple_of(POSE_NUMBERS) {
            self.error(
                pos,
                format!(
                    "`path` should hold {POSE_NUMBERS} numbers per pose (x y z, rotation qx qy \
                     qz qw, scale), not {}",
                    v.len()
                ),
            );
            return (None, pos);
        }
        let poses = v
            .chunks_exact(POSE_NUMBERS)
            .map(|p| Pose {
                position: DVec3::new(p[0], p[1], p[2]),
                rotation: DQuat::from_xyzw(p[3], p[4], p[5], p[6]),
                scale: p[7],
            })
            .collect();
        (Some(poses), pos)
    }

    /// One of `choices`, written as a string.
    fn keyword<T: Copy>(&mut self, field: &'d Field, choices: &[(&str, T)]) -> Option<T> {
        if let Value::String(s) = &field.value
            && let Some((_, v)) = choices.iter().find(|(name, _)| name == s)
        {
            return Some(*v);
        }
        self.error(
            field.value_pos,
            format!("`{}` is one of {}", field.name, one_of(choices)),
        );
        None
    }
}

/// `"a", "b" or "c"`.
fn one_of<T>(choices: &[(&str, T)]) -> String {
    let names: Vec<String> = choices.iter().map(|(n, _)| format!("\"{n}\"")).collect();
    match names.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        _ => names.concat(),
    }
}

/// Writes `object`'s history as an `edits` field (nothing when it has no edits).
pub(super) fn write_edits(object: &Object, out: &mut Vec<Field>) {
    let entries = object.history().entries();
    if entries.is_empty() {
        return;
    }
    let nodes = entries
        .iter()
        .map(|e| NodeRef::Node(Box::new(edit_node(e.edit.edit(), e.active))))
        .collect();
    out.push(Field::new("edits", Value::NodeList(nodes)));
}

/// An edit as an `FEdit`, every number as it is (so that it reads back bit-identical).
fn edit_node(edit: &Edit, active: bool) -> Node {
    let string = |name: &str, s: &str| Field::new(name, Value::String(s.to_string()));
    let mut fields = Vec::new();
    match edit.op {
        EditOp::Paint { property, value } => {
            fields.push(string("operation", "paint"));
            fields.push(string("property", name_of(&PROPERTIES, property)));
            fields.push(match value {
                PaintValue::Scalar(v) => numbers("value", &[v]),
                PaintValue::Color(c) => numbers("value", &c.map(f32_value)),
            });
        }
        op => {
            fields.push(string("operation", name_of(&OPERATIONS, op)));
        }
    }
    let kind = edit.tool.kind();
    fields.push(string("tool", kind.name()));
    for (size, values) in kind.sizes().iter().zip(edit.tool.size_values()) {
        fields.push(numbers(size.name, &values));
    }
    let path = edit
        .path
        .iter()
        .flat_map(|p| {
            let [x, y, z] = p.position.to_array();
            let [qx, qy, qz, qw] = p.rotation.to_array();
            [x, y, z, qx, qy, qz, qw, p.scale]
        })
        .collect();
    fields.push(Field::new("path", Value::NumberList(path)));
    // A default is left out only when it is the default bit for bit (`-0` is written).
    if edit.blend_radius.to_bits() != 0 {
        fields.push(numbers("blendRadius", &[edit.blend_radius]));
    }
    if let Some(axis) = edit.mirror {
        fields.push(string("mirror", name_of(&AXES, axis)));
    }
    if !active {
        fields.push(Field::new("active", Value::Bool(false)));
    }
    Node::new("FEdit", fields)
}

/// The name `value` is written as.
fn name_of<T: PartialEq>(pairs: &[(&'static str, T)], value: T) -> &'static str {
    pairs
        .iter()
        .find(|(_, v)| *v == value)
        .map_or("", |(name, _)| name)
}
