//! Scripted users: each honest peer's user creates objects, sets colours and formulas,
//! carves and paints, undoes its own edits, chats and fights over leases.
//!
//! The workload is a list of [`Action`]s drawn up front from the seed's workload stream: a
//! virtual time, a raw peer draw (the peer is `peer_draw % n_peers`, so the same list runs
//! with fewer peers) and a seed for the action's own choices. What the action authors is
//! drawn when it runs, from its seed and the user's state then (the objects known, its own
//! edits for undo), so any subset of the list is a valid workload: this is what the
//! shrinker cuts down.

use model::object::{
    ColorDef, Edit, EditOp, Field, Formula, Geometry, ObjectData, PaintValue, Paintable, Pose,
    ToolShape,
};
use replication::payload::LeaseAction;
use replication::shape::{IdSource, ShapePayload};
use replication::{OpId, PeerId};

use crate::rng::SimRng;

/// The object every user fights over (created by peer 0 at the start).
pub const HOT_OBJECT: u64 = 1;
/// Most own edits a user remembers for undo.
pub const MAX_UNDO_HISTORY: usize = 64;
/// Lease time to live used by the users.
pub const LEASE_TTL_MICROS: u64 = 2_000_000;

/// Formulas users type for geometry.
const SHAPES: [&str; 4] = [
    "1 - x^2 - y^2 - z^2",
    "min(1 - abs(x), min(1 - abs(y), 1 - abs(z)))",
    "0.8 - sqrt(x^2 + z^2) & (1 - abs(y))",
    "1 - x^2 - y^2 - z^2 + 0.1*sin(5*x)",
];

/// Colour formulas (outputs `r g b`).
const COLOURS: [&str; 3] = [
    "r = 0.5 + 0.5*sin(x); g = 0.3; b = abs(z);",
    "r = 1; g = abs(y); b = 0.2;",
    "r = t; g = 0.5; b = 0.5;",
];

/// The stream of the seed that draws the workload.
pub const WORKLOAD_STREAM: u64 = 2;
/// Mean virtual time between two user actions (over all peers).
pub const MEAN_ACTION_GAP_MICROS: u64 = 20_000;

/// One scripted user action.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Action {
    /// When it happens (virtual µs).
    pub at_micros: u64,
    /// Which peer acts: `peer_draw % n_peers`.
    pub peer_draw: u64,
    /// Seeds what the action does.
    pub seed: u64,
}

impl Action {
    /// The acting peer among `n_peers`.
    pub fn peer(&self, n_peers: usize) -> usize {
        (self.peer_draw % n_peers.max(1) as u64) as usize
    }
}

/// The `n_actions` actions of `seed`, starting after `start_micros`, in time order.
pub fn actions(seed: u64, n_actions: usize, start_micros: u64) -> Vec<Action> {
    let mut rng = SimRng::stream(seed, WORKLOAD_STREAM);
    let mut at_micros = start_micros;
    (0..n_actions)
        .map(|_| {
            at_micros += 1 + rng.below(2 * MEAN_ACTION_GAP_MICROS);
            Action {
                at_micros,
                peer_draw: rng.next_u64(),
                seed: rng.next_u64(),
            }
        })
        .collect()
}

/// What one user remembers between actions.
#[derive(Debug, Clone)]
pub struct User {
    /// Whose key its objects' ids derive from.
    author: PeerId,
    /// Objects this user created.
    created: u32,
    /// Its own edits, most recent last (for undo).
    edits: Vec<OpId>,
}

fn shape_data(rng: &mut SimRng, name: String) -> Option<ObjectData> {
    let formula = Formula::new(SHAPES[rng.index(SHAPES.len())]).ok()?;
    Some(ObjectData {
        name,
        geometry: Some(Geometry::implicit(formula)),
        ..ObjectData::default()
    })
}

/// A stroke of 1 to 4 poses on `target`, carving or adding.
fn stroke(rng: &mut SimRng, target: u64) -> ShapePayload {
    let op = if rng.chance(700) {
        EditOp::Subtract
    } else {
        EditOp::Union
    };
    let at = [
        rng.range_f64(-1.0, 1.0),
        rng.range_f64(-1.0, 1.0),
        rng.range_f64(-1.0, 1.0),
    ];
    let n_poses = 1 + rng.index(4);
    let path = (0..n_poses)
        .map(|i| Pose::at([at[0] + 0.05 * i as f64, at[1], at[2]].into()))
        .collect();
    ShapePayload::edit(
        target,
        Edit::stroke(
            op,
            ToolShape::Sphere {
                radius: rng.range_f64(0.05, 0.4),
            },
            path,
        ),
    )
    .expect("a valid edit")
}

/// A stamp of paint on `target`.
fn paint(rng: &mut SimRng, target: u64) -> ShapePayload {
    ShapePayload::edit(
        target,
        Edit::stamp(
            EditOp::Paint {
                property: Paintable::Color,
                value: PaintValue::Color([rng.unit() as f32, rng.unit() as f32, rng.unit() as f32]),
            },
            ToolShape::Sphere {
                radius: rng.range_f64(0.1, 0.5),
            },
            Pose::at([rng.range_f64(-1.0, 1.0), 0.0, 0.0].into()),
        ),
    )
    .expect("a valid edit")
}

/// The payload that creates the hot object.
pub fn hot_object(rng: &mut SimRng) -> Option<ShapePayload> {
    // Without a counter, as ops signed before ids were derived create: every peer may, and
    // the first in the order makes the object.
    Some(ShapePayload::Create {
        object: HOT_OBJECT,
        counter: None,
        data: shape_data(rng, "hot".into())?.into(),
        group: None,
    })
}

impl User {
    /// The user of the peer whose key is `author`.
    pub fn new(author: PeerId) -> User {
        User {
            author,
            created: 0,
            edits: Vec::new(),
        }
    }

    /// Draws the next action of the user of peer `peer_idx`; `known` are the objects it may
    /// touch (the hot one and the ones created so far by anyone).
    pub fn next(
        &mut self,
        rng: &mut SimRng,
        peer_idx: usize,
        known: &[u64],
    ) -> Option<ShapePayload> {
        let target = if rng.chance(400) || known.is_empty() {
            HOT_OBJECT
        } else {
            known[rng.index(known.len())]
        };
        let roll = rng.below(100);
        let payload = match roll {
            0..=7 => {
                self.created += 1;
                let ids = IdSource {
                    author: self.author,
                    counter: self.created,
                };
                ids.create(
                    shape_data(rng, format!("p{peer_idx}-{}", self.created))?,
                    None,
                )
            }
            8..=17 => ShapePayload::Set {
                object: target,
                field: Box::new(Field::Diffuse(Some(ColorDef::Constant([
                    rng.unit() as f32,
                    rng.unit() as f32,
                    rng.unit() as f32,
                ])))),
            },
            18..=22 => ShapePayload::Set {
                object: target,
                field: Box::new(Field::Diffuse(Some(ColorDef::Rgb(
                    Formula::new(COLOURS[rng.index(COLOURS.len())]).ok()?,
                )))),
            },
            23..=27 => ShapePayload::Set {
                object: target,
                field: Box::new(Field::Geometry(Some(Box::new(Geometry::implicit(
                    Formula::new(SHAPES[rng.index(SHAPES.len())]).ok()?,
                ))))),
            },
            28..=52 => stroke(rng, target),
            53..=64 => paint(rng, target),
            65..=72 => match self.edits.len() {
                0 => ShapePayload::Chat(format!("nothing to undo from {peer_idx}")),
                n => ShapePayload::Undo(self.edits[rng.index(n)]),
            },
            73..=80 => ShapePayload::Chat(format!("hello from {peer_idx} ({roll})")),
            81..=92 => ShapePayload::Lease(LeaseAction::Acquire {
                object: HOT_OBJECT,
                strong: rng.chance(500),
                ttl_micros: LEASE_TTL_MICROS,
            }),
            _ => ShapePayload::Lease(LeaseAction::Release { object: HOT_OBJECT }),
        };
        Some(payload)
    }

    /// Where the ids of this user's next objects start.
    pub fn next_ids(&self) -> IdSource {
        IdSource {
            author: self.author,
            counter: self.created.saturating_add(1),
        }
    }

    /// Takes note of an authored op (edits become undoable).
    pub fn authored(&mut self, payload: &ShapePayload, id: OpId) {
        if matches!(payload, ShapePayload::Edit { .. }) {
            if self.edits.len() >= MAX_UNDO_HISTORY {
                self.edits.remove(0);
            }
            self.edits.push(id);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use replication::Payload;

    #[test]
    fn actions_are_a_pure_function_of_the_seed() {
        let a = actions(5, 50, 1000);
        assert_eq!(a, actions(5, 50, 1000));
        assert_eq!(a[..20], actions(5, 20, 1000)[..]);
        assert!(a.windows(2).all(|w| w[0].at_micros < w[1].at_micros));
        assert!(a.iter().all(|x| x.peer(3) < 3));
        assert_ne!(a, actions(6, 50, 1000));
    }

    #[test]
    fn every_drawn_payload_validates_and_round_trips() {
        let mut rng = SimRng::new(3);
        let mut user = User::new(PeerId([2; 32]));
        let mut kinds = std::collections::BTreeSet::new();
        for i in 0..400 {
            let p = user.next(&mut rng, 2, &[HOT_OBJECT]).unwrap();
            p.validate().unwrap();
            let mut bytes = Vec::new();
            p.encode(&mut bytes);
            assert_eq!(ShapePayload::decode(&bytes).unwrap(), p);
            kinds.insert(match &p {
                ShapePayload::Create { .. } => "create",
                ShapePayload::Set { .. } => "set",
                ShapePayload::Edit { .. } => "edit",
                ShapePayload::Undo(_) => "undo",
                ShapePayload::Chat(_) => "chat",
                ShapePayload::Lease(LeaseAction::Acquire { .. }) => "acquire",
                ShapePayload::Lease(LeaseAction::Release { .. }) => "release",
                _ => "other",
            });
            user.authored(&p, OpId([i as u8; 32]));
        }
        assert_eq!(kinds.len(), 7, "{kinds:?}");
    }
}
