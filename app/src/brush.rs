//! Brushes and strokes: the tool a user sculpts with (add, carve, or paint a property, with a
//! shape, a size, a blend and a mirror plane), and the stroke a drag draws with it, which
//! becomes one sculpting op.
//!
//! Points arrive in scene coordinates (+y up) as the pointer moves over a surface; a stroke
//! keeps them in the object's own coordinates, spaced at least [`STROKE_SPACING`] of the
//! tool's size apart and at most [`model::limits::MAX_STROKE_POSES`] of them, so a long drag
//! stays one bounded op.

use glam::DVec3;
use model::limits::MAX_STROKE_POSES;
use model::object::{
    Axis, Edit, EditOp, PaintValue, Paintable, Pose, ToolKind, ToolShape, Transform,
};
use model::scene::ObjectId;
use replication::shape::ShapePayload;

use crate::command::Planned;
use crate::engine::{Validated, View};

/// Points closer than this fraction of the tool's radius to the last kept one are skipped.
pub const STROKE_SPACING: f64 = 0.25;
/// The smallest and largest tool radius a brush accepts (scene units).
pub const RADIUS_RANGE: [f64; 2] = [0.005, 10.0];

/// What a brush does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BrushOp {
    /// Adds the tool's volume.
    Add,
    /// Carves it away.
    Carve,
    /// Paints a property inside it.
    Paint(Paintable, PaintValue),
}

/// A brush: what a drag on a surface does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Brush {
    /// Add, carve or paint.
    pub op: BrushOp,
    /// The kind of tool; its size is the radius ([`ToolShape::of_kind`]).
    pub shape: ToolKind,
    /// Its radius (half its size), scene units.
    pub radius: f64,
    /// Smooth blending radius (0: sharp).
    pub blend: f64,
    /// Also act mirrored in this plane of the object.
    pub mirror: Option<Axis>,
}

impl Default for Brush {
    fn default() -> Self {
        Self {
            op: BrushOp::Carve,
            shape: ToolKind::Sphere,
            radius: 0.15,
            blend: 0.0,
            mirror: None,
        }
    }
}

impl Brush {
    /// The tool's solid.
    pub fn tool(&self) -> ToolShape {
        ToolShape::of_kind(self.shape, self.radius)
    }

    /// The edit operation.
    pub fn edit_op(&self) -> EditOp {
        match self.op {
            BrushOp::Add => EditOp::Union,
            BrushOp::Carve => EditOp::Subtract,
            BrushOp::Paint(property, value) => EditOp::Paint { property, value },
        }
    }

    /// Reads `tool: <add|carve|paint PROPERTY VALUE> [SHAPE] [radius R] [blend B]
    /// [mirror x|y|z|off]`, starting from `self`, where SHAPE is any [`ToolKind`] by its
    /// label or name (`ball` or `sphere`, `box`, ...). A colour is painted as
    /// `paint colour R G B` (0 to 1).
    pub fn parse(&self, text: &str) -> Result<Brush, String> {
        let mut brush = *self;
        let mut words = text.split_whitespace().map(str::to_ascii_lowercase);
        while let Some(word) = words.next() {
            match word.as_str() {
                "add" => brush.op = BrushOp::Add,
                "carve" => brush.op = BrushOp::Carve,
                "paint" => brush.op = paint_op(&mut words)?,
                "radius" | "size" => {
                    let r = number(words.next(), "radius")?;
                    if !(RADIUS_RANGE[0]..=RADIUS_RANGE[1]).contains(&r) {
                        return Err(format!(
                            "tool: radius {r} is outside {} to {}",
                            RADIUS_RANGE[0], RADIUS_RANGE[1]
                        ));
                    }
                    brush.radius = r;
                }
                "blend" => {
                    let b = number(words.next(), "blend")?;
                    if !(0.0..=brush.radius * 4.0).contains(&b) {
                        return Err("tool: blend lies between 0 and 4 radii".into());
                    }
                    brush.blend = b;
                }
                "mirror" => {
                    brush.mirror = match words.next().as_deref() {
                        Some("x") => Some(Axis::X),
                        Some("y") => Some(Axis::Y),
                        Some("z") => Some(Axis::Z),
                        Some("off" | "none") => None,
                        _ => return Err("tool: mirror x, y, z or off".into()),
                    };
                }
                other => match ToolKind::from_name(other) {
                    Some(kind) => brush.shape = kind,
                    None => {
                        let shapes = ToolKind::ALL.map(ToolKind::label).join(", ");
                        return Err(format!(
                            "tool: `{other}` is not understood; say add, carve or paint \
                             PROPERTY VALUE, a shape ({}), radius R, blend B, mirror x|y|z",
                            shapes
                        ));
                    }
                },
            }
        }
        Ok(brush)
    }

    /// A short description for the status line and the panel.
    pub fn describe(&self) -> String {
        let what = match self.op {
            BrushOp::Add => "add".to_string(),
            BrushOp::Carve => "carve".to_string(),
            BrushOp::Paint(p, PaintValue::Scalar(v)) => format!("paint {} {v}", paint_name(p)),
            BrushOp::Paint(p, PaintValue::Color(c)) => {
                format!("paint {} {} {} {}", paint_name(p), c[0], c[1], c[2])
            }
        };
        let shape = self.shape.label();
        let mirror = match self.mirror {
            None => "",
            Some(Axis::X) => " mirror x",
            Some(Axis::Y) => " mirror y",
            Some(Axis::Z) => " mirror z",
        };
        format!(
            "{what} {shape} radius {} blend {}{mirror}",
            self.radius, self.blend
        )
    }
}

/// The word for a paintable property.
pub fn paint_name(p: Paintable) -> &'static str {
    match p {
        Paintable::Color => "colour",
        Paintable::Transparency => "transparency",
        Paintable::Shininess => "shininess",
        Paintable::Tension => "tension",
        Paintable::Friction => "friction",
        Paintable::ZoneDepth => "depth",
        Paintable::Density => "density",
    }
}

fn paintable(word: &str) -> Option<Paintable> {
    Paintable::ALL.into_iter().find(|p| paint_name(*p) == word)
}

/// The number a `tool:` line gives for `what`.
fn number(word: Option<String>, what: &str) -> Result<f64, String> {
    let w = word.ok_or(format!("tool: {what} needs a number"))?;
    w.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or(format!("tool: `{w}` is not a number for {what}"))
}

/// What follows `paint` in a `tool:` line: `PROPERTY VALUE`, or `colour R G B`.
fn paint_op(words: &mut impl Iterator<Item = String>) -> Result<BrushOp, String> {
    let name = words
        .next()
        .ok_or("tool: paint what? (colour, density, ...)")?;
    if let "colour" | "color" = name.as_str() {
        let mut c = [0.0f32; 3];
        for v in &mut c {
            *v = number(words.next(), "a colour")? as f32;
        }
        if !c.iter().all(|v| (0.0..=1.0).contains(v)) {
            return Err("tool: colour components lie between 0 and 1".into());
        }
        return Ok(BrushOp::Paint(Paintable::Color, PaintValue::Color(c)));
    }
    let property = paintable(&name).ok_or(format!(
        "tool: cannot paint `{name}`: colour, density, tension, friction, depth, \
         transparency or shininess"
    ))?;
    let value = number(words.next(), &name)?;
    Ok(BrushOp::Paint(property, PaintValue::Scalar(value)))
}

/// A stroke being drawn on one object.
#[derive(Clone, Debug)]
pub struct Stroke {
    /// The object sculpted.
    pub object: u64,
    brush: Brush,
    object_from_scene: Transform,
    /// Points in the object's coordinates.
    points: Vec<DVec3>,
    /// Points in scene coordinates, as drawn (for the outline and tests).
    scene_points: Vec<DVec3>,
}

impl Stroke {
    /// Starts a stroke on `object` with `brush` at scene point `at`.
    pub fn begin(view: &View, object: u64, brush: Brush, at: DVec3) -> Result<Stroke, String> {
        let scene = view.scene();
        let entry = scene
            .scene_object(ObjectId(object))
            .ok_or_else(|| format!("{} is not in the scene", view.object_label(object)))?;
        let scene_from_object = scene
            .world_from_group(entry.group)
            .then(&entry.object.data().transform);
        let object_from_scene = scene_from_object
            .inverse()
            .ok_or("the object's transform cannot be inverted")?;
        let mut stroke = Stroke {
            object,
            brush,
            object_from_scene,
            points: Vec::new(),
            scene_points: Vec::new(),
        };
        stroke.push(at);
        Ok(stroke)
    }

    /// Adds the point under the pointer (scene coordinates); near or excess points are
    /// skipped.
    pub fn push(&mut self, at: DVec3) {
        if !at.is_finite() || self.points.len() >= MAX_STROKE_POSES {
            return;
        }
        let p = self.object_from_scene.point(at);
        let spacing = self.brush.radius * STROKE_SPACING;
        if self.points.last().is_some_and(|q| q.distance(p) < spacing) {
            return;
        }
        self.points.push(p);
        self.scene_points.push(at);
    }

    /// The points drawn so far, in scene coordinates.
    pub fn scene_points(&self) -> &[DVec3] {
        &self.scene_points
    }

    /// The edit the stroke makes so far.
    pub fn edit(&self) -> Edit {
        let mut edit = Edit::stroke(
            self.brush.edit_op(),
            self.brush.tool(),
            self.points.iter().copied().map(Pose::at).collect(),
        );
        edit.blend_radius = self.brush.blend;
        edit.mirror = self.brush.mirror;
        edit
    }

    /// The op the finished stroke authors.
    pub fn finish(&self, view: &View) -> Result<Planned, String> {
        let payload =
            ShapePayload::edit(self.object, self.edit()).map_err(|e| format!("stroke: {e}"))?;
        // The edit was compiled just now: validating it builds nothing.
        let payload = Validated::new(payload).map_err(|e| format!("stroke: {e}"))?;
        Ok(Planned {
            payload,
            summary: format!(
                "{} on {} ({} points)",
                self.brush.describe(),
                view.object_label(self.object),
                self.points.len()
            ),
            select: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tool_lines_set_the_brush_and_bad_ones_say_why() {
        let b = Brush::default()
            .parse("paint density 0.9 cylinder radius 0.3 blend 0.05 mirror x")
            .unwrap();
        assert_eq!(
            b.op,
            BrushOp::Paint(Paintable::Density, PaintValue::Scalar(0.9))
        );
        assert_eq!(
            (b.shape, b.radius, b.blend, b.mirror),
            (ToolKind::Cylinder, 0.3, 0.05, Some(Axis::X))
        );
        let c = b.parse("paint colour 1 0 0.5 ball").unwrap();
        assert_eq!(
            c.op,
            BrushOp::Paint(Paintable::Color, PaintValue::Color([1.0, 0.0, 0.5]))
        );
        assert_eq!(c.radius, 0.3, "unnamed settings are kept");
        for bad in [
            "paint",
            "paint smell 1",
            "radius -1",
            "radius 99",
            "blend x",
            "mirror q",
            "paint colour 2 0 0",
            "wobble",
        ] {
            let err = Brush::default().parse(bad).unwrap_err();
            assert!(err.starts_with("tool:"), "{bad}: {err}");
        }
    }

    #[test]
    fn a_stroke_keeps_spaced_points_in_object_coordinates_and_makes_one_edit() {
        let keypair = replication::Keypair::from_seed([5; 32]);
        let mut log = replication::Log::default();
        let me = keypair.peer_id();
        let first = View::new(me, &log).unwrap().next_object();
        for payload in crate::demos::DEMOS[0].payloads(first).unwrap() {
            log.author(&keypair, replication::Timestamp(1), payload)
                .unwrap();
        }
        let view = View::new(me, &log).unwrap();
        let melon = view.scene().objects().next().unwrap().0.0;
        let brush = Brush::default();
        let mut stroke = Stroke::begin(&view, melon, brush, DVec3::new(0.0, 0.9, 0.0)).unwrap();
        stroke.push(DVec3::new(0.001, 0.9, 0.0));
        for i in 1..=10 {
            stroke.push(DVec3::new(0.02 * f64::from(i), 0.9, 0.0));
        }
        assert_eq!(
            stroke.scene_points().len(),
            6,
            "points closer than a quarter radius are skipped"
        );
        let planned = stroke.finish(&view).unwrap();
        let ShapePayload::Edit { object, edit } = &*planned.payload else {
            panic!("{planned:?}");
        };
        assert_eq!(*object, melon);
        assert_eq!(edit.edit().op, EditOp::Subtract);
        assert_eq!(edit.edit().path.len(), 6);
        assert!(Stroke::begin(&view, 12345, brush, DVec3::ZERO).is_err());
    }
}
