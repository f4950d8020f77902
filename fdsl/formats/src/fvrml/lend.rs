//! Physics lent by a shapeless `FShape` to the shapes grouped with it: the thesis makes
//! standard VRML objects tangible "by grouping them with a function defined object which has
//! only a tangible surface property defined" (Figure 7.2's fan, cabinet and carpet), and
//! Figure 7.8 does so for a whole campus with `geometry FGeometry { definition "0" }` beside
//! an `Inline`.
//!
//! A carrier is an `FShape` in a group written with `geometry FGeometry { definition "0" }`
//! and no `bboxSize` (no solid of its own: `0` is the surface everywhere, with no normal to
//! push along), with physics and no container of its own. Its physics goes to every object
//! loaded under the group (its children, nested groups and `Inline` files included) that is
//! not tangible yet, read in each object's own coordinates; the carrier itself then leaves
//! the scene. A carrier with nothing to lend to, and every later carrier of the group, stays
//! as it was written; `save` writes such a one with `bboxSize -1 -1 -1`, so that it loads
//! back as it was instead of lending.

use std::collections::BTreeSet;
use std::ops::Range;

use super::document::{Node, Value};
use super::read::Scope;
use model::object::{Field, Object, ObjectError, Physics};
use model::scene::{GroupId, ObjectId, Scene};

/// What lending did in one group.
#[derive(Debug, Default)]
pub(super) struct Lent {
    /// Carriers found directly in the group.
    pub(super) n_carriers: usize,
    /// Objects that got a carrier's physics.
    pub(super) n_lent: usize,
    /// Objects that could not take it, with why.
    pub(super) refused: Vec<(ObjectId, ObjectError)>,
}

impl Lent {
    /// What to tell the reader of the file, at the group.
    pub(super) fn messages(&self) -> Vec<String> {
        let mut messages: Vec<String> = self
            .refused
            .iter()
            .map(|(id, e)| format!("object {} cannot take the group's physics: {e}", id.0))
            .collect();
        // Nothing to give to (a remote Inline, say warns of itself): the carrier is as written.
        if self.n_lent == 0 {
            return messages;
        }
        messages.push(format!(
            "the `FShape` here without a shape of its own (geometry \"0\") gives its physics to \
             the {} shapes grouped with it, as the thesis's Figures 7.2 and 7.8 do",
            self.n_lent
        ));
        if self.n_carriers > 1 {
            messages.push(format!(
                "{} more `FShape`s without a shape of their own in this group give nothing (the \
                 first one's physics counts) and are kept as written",
                self.n_carriers - 1
            ));
        }
        messages
    }
}

/// Whether the shape `node` is written as a carrier: an `FShape` with physics whose geometry
/// is an `FGeometry` (through `USE`) defined as the constant 0, without `bboxSize`.
pub(super) fn written_as_carrier(scope: &Scope<'_>, node: &Node) -> bool {
    fn last<'n>(node: &'n Node, name: &str) -> Option<&'n super::document::Field> {
        node.fields.iter().rev().find(|f| f.name == name)
    }
    if node.type_name != "FShape" || last(node, "physics").is_none() {
        return false;
    }
    let Some(Value::Node(r)) = last(node, "geometry").map(|f| &f.value) else {
        return false;
    };
    let Ok(Some(geometry)) = scope.resolve(r) else {
        return false;
    };
    let zero = match last(geometry, "definition").map(|f| &f.value) {
        Some(Value::String(s)) => s.trim().parse::<f64>().is_ok_and(|v| v == 0.0),
        Some(Value::Numbers(v)) => v.as_slice() == [0.0],
        _ => false,
    };
    geometry.type_name == "FGeometry" && zero && last(geometry, "bboxSize").is_none()
}

/// Whether the object's geometry is the constant 0 (a carrier without physics): it takes none.
fn zero(object: &Object) -> bool {
    object.data().geometry.as_ref().is_some_and(|g| {
        matches!(&g.shape, model::object::Shape::Implicit(f)
            if f.as_str().trim().parse::<f64>().is_ok_and(|v| v == 0.0))
    })
}

/// Whether `object`, written as a carrier, can give physics: it has some, and no container.
fn gives_physics(object: &Object) -> bool {
    object.data().physics.container.is_none() && object.is_tangible()
}

/// Lends the physics of the first carrier (of `carriers`, the ids of objects written as one)
/// directly in `group` to the other objects with ids in `ids` (those loaded under the group)
/// that are not tangible; later carriers of the group are counted and left as written.
pub(super) fn lend_physics(
    scene: &mut Scene,
    group: Option<GroupId>,
    ids: Range<u64>,
    carriers: &BTreeSet<u64>,
) -> Lent {
    let mut lent = Lent::default();
    // Each object is looked at once per group it is under: at most `MAX_NESTING_DEPTH` times.
    let mut carrier = None;
    let mut recipients = Vec::new();
    for id in ids.map(ObjectId) {
        let Some(o) = scene.scene_object(id) else {
            continue;
        };
        if o.group == group && carriers.contains(&id.0) && gives_physics(&o.object) {
            lent.n_carriers += 1;
            carrier = carrier.or(Some(id));
        } else if !o.object.is_tangible() && o.object.data().geometry.is_some() && !zero(&o.object)
        {
            recipients.push(id);
        }
    }
    let Some(carrier) = carrier else {
        return lent;
    };
    let Some(physics) = scene.object(carrier).map(|o| o.data().physics.clone()) else {
        return lent;
    };
    for id in recipients {
        let Some(object) = scene.object_mut(id) else {
            continue;
        };
        match give(object, &physics) {
            Ok(()) => lent.n_lent += 1,
            Err(e) => lent.refused.push((id, e)),
        }
    }
    if lent.n_lent > 0 {
        scene.remove_object(carrier);
    }
    lent
}

/// Sets every part of `physics` the object model keeps per field; all or nothing.
fn give(object: &mut Object, physics: &Physics) -> Result<(), ObjectError> {
    let p = physics.clone();
    let mut taking = object.clone();
    for field in [
        Field::Tension(p.tension),
        Field::Friction(p.friction),
        Field::ZoneDepth(p.zone_depth),
        Field::Density(p.density),
        Field::Force(p.force.map(Box::new)),
        Field::PhysicsSpace(p.domain.map(Box::new), Box::new(p.transform)),
    ] {
        taking.set(field)?;
    }
    *object = taking;
    Ok(())
}
