//! The fdsl payload: ops over the shared object model ([`ShapePayload`]), and the scene they
//! fold into ([`ShapeScene`], a [`Materialize`] over [`model::scene::Scene`]).
//!
//! Every op names the object it changes, so leases and per-object re-folds apply. Properties
//! are written whole per [`model::object::Slot`]: concurrent writes to one slot resolve by the
//! linear order (the last writer wins); sculpting edits all apply, in the order. A payload is
//! validated when decoded (formulas compiled, numbers checked), so an op that reaches the fold
//! describes a valid change; a change to an object that does not exist (deleted, or created by
//! an op that lost a race) changes nothing and stays in history.
//!
//! Object ids are bound to their creator ([`object_id`]): a `Create` makes its object only
//! under an id derived from its own author's key and the counter it carries, so a member who
//! predicts the id another peer will use next cannot take it.
//!
//! A delete removes only what it saw ([`Payload::is_delete`]): the edits of its object in its
//! causal past, its creation included, become inactive. An edit made concurrently stays
//! active, but without its creation the object is still gone (it changes nothing); a delete
//! that never saw the creation (one backdated by a member, say) removes nothing, and a
//! creation after a delete it saw makes the object anew.
//!
//! A change too large for one op (an imported mesh, large sampled grids) is authored in parts
//! ([`parts`]): `Part` ops carry its encoding in pieces, and an `Assemble` op names the pieces
//! by hash; the fold puts the change together when it reaches the `Assemble`.

pub mod parts;
mod wire;

use std::collections::BTreeMap;
use std::sync::Arc;

use model::object::codec as object_codec;
use model::object::{CompiledEdit, Edit, Field, Object, ObjectData};
use model::scene::{self, Group, GroupId, Scene};
use serde::{Deserialize, Serialize};

use crate::codec::DecodeError;
use crate::identity::{OpId, PeerId};
use crate::log::OrderKey;
use crate::materialize::{FoldEntry, Materialize, SceneHash};
use crate::membership::{Admission, Membership};
use crate::payload::{Effect, LeaseAction, MAX_PAYLOAD_BYTES, ObjectId, Payload};
use crate::sync::scene::ObjectHashes;

/// Longest chat message, in bytes.
pub const MAX_CHAT_BYTES: usize = 2048;

/// Groups share the lease space of objects with the top bit set.
const GROUP_LEASE_BIT: u64 = 1 << 63;

/// Set in every id [`object_id`] derives, and in no id a `Create` without a counter (signed
/// before ids were derived) may take.
pub const DERIVED_ID_BIT: u64 = 1 << 31;

/// The id of the object that `author`'s `Create` with `counter` makes: 62 bits of a hash of
/// both, with [`DERIVED_ID_BIT`] set and the group bit clear. Nobody else can create it: a
/// `Create` takes effect only when its id is its author's ([`may_create`]), and finding
/// another key and counter with the same id is a search of about 2^62 hashes.
pub fn object_id(author: PeerId, counter: u32) -> u64 {
    let mut hasher =
        blake3::Hasher::new_derive_key("sculpt 2026-11-27 object id of author and counter");
    hasher.update(&author.0);
    hasher.update(&counter.to_le_bytes());
    let [a, b, c, d, e, f, g, h, ..] = *hasher.finalize().as_bytes();
    (u64::from_le_bytes([a, b, c, d, e, f, g, h]) & !GROUP_LEASE_BIT) | DERIVED_ID_BIT
}

/// Whether a `Create` of `object` with `counter` by `author` may make the object: a derived
/// id must be its author's, and a `Create` without a counter (an op signed before ids were
/// derived) may take only an id outside the derived ones.
pub fn may_create(author: PeerId, object: u64, counter: Option<u32>) -> bool {
    match counter {
        Some(counter) => object == object_id(author, counter),
        None => object & DERIVED_ID_BIT == 0,
    }
}

/// Where an author's next new object (or group) ids come from: its key and a counter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IdSource {
    /// The author.
    pub author: PeerId,
    /// The counter of the next id.
    pub counter: u32,
}

impl IdSource {
    /// The first source of `author`'s ids.
    pub fn first(author: PeerId) -> IdSource {
        IdSource { author, counter: 1 }
    }

    /// The next id.
    pub fn id(&self) -> u64 {
        object_id(self.author, self.counter)
    }

    /// The source `n` ids on; `None` past the last counter.
    pub fn skip(self, n: u64) -> Option<IdSource> {
        let counter = u64::from(self.counter).checked_add(n)?;
        Some(IdSource {
            author: self.author,
            counter: u32::try_from(counter).ok()?,
        })
    }

    /// Where `author`'s next ids start in `log`: after the highest counter of its `Create`s,
    /// past the ids its `Part`s, `Assemble`s and `SetGroup`s already use (an object authored
    /// in parts, a group); the last counter when all are used.
    pub fn next_in(log: &crate::Log<ShapePayload>, author: PeerId) -> IdSource {
        let mut highest = 0;
        let mut used = std::collections::BTreeSet::new();
        for e in log.entries().filter(|e| e.op.author() == author) {
            match e.op.payload() {
                ShapePayload::Create {
                    counter: Some(c), ..
                } => highest = highest.max(*c),
                ShapePayload::Part { object, .. }
                | ShapePayload::Assemble { object, .. }
                | ShapePayload::SetGroup { group: object, .. } => {
                    used.insert(*object);
                }
                _ => {}
            }
        }
        let mut next = IdSource {
            author,
            counter: highest.saturating_add(1),
        };
        while used.contains(&next.id()) && next.counter < u32::MAX {
            next.counter += 1;
        }
        next
    }

    /// A `Create` of the next id.
    pub fn create(&self, data: ObjectData, group: Option<u64>) -> ShapePayload {
        ShapePayload::Create {
            object: self.id(),
            counter: Some(self.counter),
            data: Arc::new(data),
            group,
        }
    }
}

/// One change to the shared scene.
#[derive(Clone, Debug, PartialEq)]
pub enum ShapePayload {
    /// Creates object `object`, which must be [`object_id`] of the op's author and `counter`
    /// ([`IdSource::create`]); any other `Create` changes nothing and stays in history.
    Create {
        /// The new object's id.
        object: u64,
        /// The author's counter `object` derives from; `None` in ops signed before ids were
        /// derived, which may take only ids without [`DERIVED_ID_BIT`] and are not bound to
        /// their author.
        counter: Option<u32>,
        /// Its description.
        data: Arc<ObjectData>,
        /// The group it hangs from.
        group: Option<u64>,
    },
    /// Deletes an object.
    Delete {
        /// The object.
        object: u64,
    },
    /// Sets one property of an object.
    Set {
        /// The object.
        object: u64,
        /// The property and its value (boxed: the largest variant would set the size of every
        /// payload a log holds).
        field: Box<Field>,
    },
    /// A sculpting edit (union, carve, intersect or paint, possibly a whole stroke).
    Edit {
        /// The object.
        object: u64,
        /// The edit, compiled once when made or decoded (an edit that does not compile never
        /// decodes) and shared with the object that folds it.
        edit: Arc<CompiledEdit>,
    },
    /// Adds, changes (`Some`) or removes (`None`) a group.
    SetGroup {
        /// The group.
        group: u64,
        /// Its new description (boxed, as `Set`'s field).
        value: Option<Box<Group>>,
    },
    /// Moves an object into a group (or to the top).
    Move {
        /// The object.
        object: u64,
        /// The new group.
        group: Option<u64>,
    },
    /// Takes or gives back the object's lease (a group's id loses its group bit: groups cannot
    /// be leased).
    Lease(LeaseAction),
    /// Undoes one of the author's earlier edits.
    Undo(OpId),
    /// Redoes an undone edit.
    Redo(OpId),
    /// A chat message.
    Chat(String),
    /// One piece of a change too large for one op: the fold keeps it with its object until an
    /// `Assemble` names it.
    Part {
        /// The object the change is for.
        object: u64,
        /// At most [`parts::MAX_PART_BYTES`] bytes of the change's encoding.
        bytes: Vec<u8>,
    },
    /// The change whose canonical encoding is the concatenation, in order, of the parts with
    /// these blake3 hashes, which the object's fold holds: a `Create` or a `Set` of `object`,
    /// at most [`parts::MAX_ASSEMBLED_BYTES`] long ([`parts::split`] makes both kinds of op).
    Assemble {
        /// The object.
        object: u64,
        /// The parts' hashes, in order (at most [`parts::MAX_PARTS`]).
        parts: Vec<[u8; 32]>,
    },
    /// Expels or readmits a member; counts only from the session's founder
    /// ([`crate::membership`]). Boxed, as `Set`'s field.
    Member(Box<Membership>),
    /// Admits a key, granting it bytes of the author's budget ([`crate::membership`]). Boxed,
    /// as `Set`'s field.
    Admit(Box<Admission>),
}

// Payloads are validated on decode (no NaN reaches one), so equality is reflexive.
impl Eq for ShapePayload {}

// A log holds one decoded payload per op: its largest variant sets the size of every one.
#[cfg(target_pointer_width = "64")]
const _: () = assert!(std::mem::size_of::<ShapePayload>() <= 40);
// And one op: the payload, counters, id and encoding (read in place for the rest).
#[cfg(target_pointer_width = "64")]
const _: () = assert!(std::mem::size_of::<crate::Op<ShapePayload>>() <= 120);

impl ShapePayload {
    /// An [`ShapePayload::Edit`] of `object`: the edit compiled, or why it cannot be.
    pub fn edit(
        object: u64,
        edit: impl Into<Arc<Edit>>,
    ) -> Result<ShapePayload, model::object::ObjectError> {
        let edit = Arc::new(CompiledEdit::new(edit)?);
        Ok(ShapePayload::Edit { object, edit })
    }

    /// Checks what decoding cannot: formulas compile, numbers are valid, text is short.
    pub fn validate(&self) -> Result<(), String> {
        match self {
            ShapePayload::Create { data, .. } => Object::new(Arc::clone(data))
                .map(|_| ())
                .map_err(|e| e.to_string()),
            ShapePayload::Set { field, .. } => {
                let mut data = ObjectData::default();
                field.clone().apply_to(&mut data);
                Object::new(data).map(|_| ()).map_err(|e| e.to_string())
            }
            ShapePayload::SetGroup { value: Some(g), .. } => {
                if g.transform.inverse().is_none() || g.name.len() > model::object::MAX_NAME_BYTES {
                    return Err("group transform not invertible or name too long".into());
                }
                Ok(())
            }
            ShapePayload::Chat(text) if text.len() > MAX_CHAT_BYTES => {
                Err(format!("chat message longer than {MAX_CHAT_BYTES} bytes"))
            }
            ShapePayload::Part { bytes, .. } => parts::check_part(bytes),
            ShapePayload::Assemble { parts: hashes, .. } => parts::check_assemble(hashes),
            _ => Ok(()),
        }
    }
}

impl Payload for ShapePayload {
    fn encode(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&object_codec::encode(self));
    }

    fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        if bytes.len() > MAX_PAYLOAD_BYTES {
            return Err(DecodeError::OverLimit {
                offset: 0,
                what: "shape payload length",
                value: bytes.len() as u64,
                limit: MAX_PAYLOAD_BYTES as u64,
            });
        }
        let payload = wire::decode("shape payload", bytes).map_err(|_| DecodeError::Invalid {
            offset: 0,
            what: "shape payload encoding",
        })?;
        payload.validate().map_err(|_| DecodeError::Invalid {
            offset: 0,
            what: "shape payload contents (a formula, number or text is not valid)",
        })?;
        Ok(payload)
    }

    fn is_canonical(&self, bytes: &[u8]) -> bool {
        wire::is_canonical(self, bytes)
    }

    fn effect(&self) -> Effect {
        let object = |id: u64| ObjectId(id & !GROUP_LEASE_BIT);
        match *self {
            ShapePayload::Create { object: o, .. }
            | ShapePayload::Delete { object: o }
            | ShapePayload::Set { object: o, .. }
            | ShapePayload::Edit { object: o, .. }
            | ShapePayload::Move { object: o, .. }
            | ShapePayload::Part { object: o, .. }
            | ShapePayload::Assemble { object: o, .. } => Effect::Edit { object: object(o) },
            ShapePayload::SetGroup { group, .. } => Effect::Edit {
                object: ObjectId(group | GROUP_LEASE_BIT),
            },
            ShapePayload::Lease(lease) => lease.effect(object),
            ShapePayload::Undo(target) => Effect::Undo { target },
            ShapePayload::Redo(target) => Effect::Redo { target },
            ShapePayload::Chat(_) | ShapePayload::Member(_) | ShapePayload::Admit(_) => {
                Effect::Independent
            }
        }
    }

    fn is_delete(&self) -> bool {
        matches!(self, ShapePayload::Delete { .. })
    }

    /// A `Create` that may make its object ([`may_create`]), or the first part of one
    /// authored in parts. Groups cannot be leased (an acquire's id loses its group bit).
    fn creates(&self, author: &PeerId) -> bool {
        match self {
            ShapePayload::Create {
                object, counter, ..
            } => may_create(*author, *object, *counter),
            ShapePayload::Part { object, bytes } => parts::starts_create(author, *object, bytes),
            _ => false,
        }
    }

    fn membership(&self) -> Option<Membership> {
        match self {
            ShapePayload::Member(m) => Some(**m),
            _ => None,
        }
    }

    fn admission(&self) -> Option<Admission> {
        match self {
            ShapePayload::Admit(a) => Some(**a),
            _ => None,
        }
    }

    fn admitting(admission: Admission) -> Option<Self> {
        Some(ShapePayload::Admit(Box::new(admission)))
    }
}

/// A chat line in the scene.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChatLine {
    /// Lamport time, author and sequence: where the line sits in the order.
    pub lamport: u64,
    /// Who wrote it.
    pub author: [u8; 32],
    /// The author's sequence number.
    pub seq: u64,
    /// The text.
    pub text: String,
}

/// The materialised scene of [`ShapePayload`] ops.
#[derive(Clone, Debug, Default)]
pub struct ShapeScene {
    scene: Scene,
    /// Chat lines in linear order.
    chat: Vec<ChatLine>,
    /// For each object, the op of each history entry (to map undo targets to edits).
    edit_ops: BTreeMap<u64, Vec<OpId>>,
    /// For each object, the parts folded and not yet assembled.
    parts: parts::HeldParts,
}

impl ShapeScene {
    /// The scene (objects and groups).
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The chat, in linear order.
    pub fn chat(&self) -> &[ChatLine] {
        &self.chat
    }

    /// The op that made each entry of an object's edit history.
    pub fn edit_ops(&self, object: u64) -> &[OpId] {
        self.edit_ops.get(&object).map_or(&[], Vec::as_slice)
    }

    /// Indexes recent edits of every object (call after a batch, before sampling).
    pub fn prepare(&mut self) {
        self.scene.prepare();
    }

    fn encode(&self) -> Vec<u8> {
        let edit_ops: Vec<(u64, Vec<[u8; 32]>)> = self
            .edit_ops
            .iter()
            .map(|(o, ids)| (*o, ids.iter().map(|id| id.0).collect()))
            .collect();
        object_codec::encode(&(
            self.scene.encode(),
            &self.chat,
            edit_ops,
            self.parts.encode(),
        ))
    }
}

impl PartialEq for ShapeScene {
    fn eq(&self, other: &Self) -> bool {
        self.scene == other.scene && self.chat == other.chat && self.parts == other.parts
    }
}

impl ShapeScene {
    /// Folds one payload: an active entry's, or a change its `Assemble` put together.
    fn apply_payload(&mut self, key: OrderKey, id: OpId, payload: &ShapePayload) {
        match payload {
            ShapePayload::Create {
                object,
                counter,
                data,
                group,
            } => {
                // Only the author an id is derived from makes the object (a member cannot take
                // an id another peer is about to use), and the first creation in the order.
                if may_create(key.author, *object, *counter) {
                    self.create(scene::ObjectId(*object), data, *group);
                }
            }
            // A delete acts through the log: it hides the edits of its object that it saw
            // (their creation included), and the object is the fold of those left.
            ShapePayload::Delete { .. } => {}
            ShapePayload::Set { object, field } => {
                if let Some(o) = self.scene.object_mut(scene::ObjectId(*object)) {
                    let _ = o.set((**field).clone());
                }
            }
            ShapePayload::Edit { object, edit } => {
                let Some(o) = self.scene.object_mut(scene::ObjectId(*object)) else {
                    return;
                };
                if o.apply_compiled(Arc::clone(edit)).is_ok() {
                    self.edit_ops.entry(*object).or_default().push(id);
                }
            }
            ShapePayload::SetGroup { group, value } => {
                let g = GroupId(*group);
                match value {
                    Some(v) => {
                        let _ = self.scene.set_group(g, (**v).clone());
                    }
                    None => {
                        self.scene.remove_group(g);
                    }
                }
            }
            ShapePayload::Move { object, group } => {
                let _ = self
                    .scene
                    .set_object_group(scene::ObjectId(*object), group.map(GroupId));
            }
            ShapePayload::Chat(text) => self.chat_line(key, text),
            ShapePayload::Lease(_)
            | ShapePayload::Undo(_)
            | ShapePayload::Redo(_)
            | ShapePayload::Member(_)
            | ShapePayload::Admit(_) => {}
            ShapePayload::Part { object, bytes } => self.parts.hold(*object, bytes),
            ShapePayload::Assemble {
                object,
                parts: hashes,
            } => {
                if let Some(change) = self.parts.assemble(id, *object, hashes) {
                    self.apply_payload(key, id, &change);
                }
            }
        }
    }
}

impl ShapeScene {
    /// Makes `object`, unless an earlier creation in the order made it.
    fn create(&mut self, object: scene::ObjectId, data: &Arc<ObjectData>, group: Option<u64>) {
        if self.scene.object(object).is_none() {
            // Valid by decode; a missing group puts the object at the top.
            let group = group
                .map(GroupId)
                .filter(|g| self.scene.group(*g).is_some());
            let _ = self.scene.create(object, Arc::clone(data), group);
        }
    }

    /// Puts a chat line at its place in the order (once).
    fn chat_line(&mut self, key: OrderKey, text: &str) {
        let line = ChatLine {
            lamport: key.lamport,
            author: key.author.0,
            seq: key.seq,
            text: text.to_owned(),
        };
        let order = |l: &ChatLine| (l.lamport, l.author, l.seq);
        let at = self.chat.partition_point(|l| order(l) < order(&line));
        if self.chat.get(at).is_none_or(|l| order(l) != order(&line)) {
            self.chat.insert(at, line);
        }
    }
}

impl Materialize<ShapePayload> for ShapeScene {
    fn reset_independent(&mut self, author: PeerId, from_seq: u64) {
        self.chat
            .retain(|l| l.author != author.0 || l.seq < from_seq);
    }

    fn reset_object(&mut self, object: ObjectId) {
        if object.0 & GROUP_LEASE_BIT != 0 {
            // Groups are re-folded by re-applying their ops; removing first keeps the fold
            // from-scratch equal.
            self.scene
                .remove_group(GroupId(object.0 & !GROUP_LEASE_BIT));
        } else {
            self.scene.remove_object(scene::ObjectId(object.0));
            self.edit_ops.remove(&object.0);
            self.parts.forget(object.0);
        }
    }

    fn apply(&mut self, entry: FoldEntry<'_, ShapePayload>) {
        self.apply_payload(entry.key, entry.op.id(), entry.op.payload());
    }

    /// Indexes the object's recent edits ([`model::object::Object::prepare`]); a group has
    /// none.
    fn prepare(&mut self, object: ObjectId) {
        if object.0 & GROUP_LEASE_BIT == 0
            && let Some(o) = self.scene.object_mut(scene::ObjectId(object.0))
        {
            o.prepare();
        }
    }

    fn scene_hash(&self) -> SceneHash {
        SceneHash::of(&self.encode())
    }

    /// Per object: its place, its encoding, the ops of its edit history and its held parts;
    /// per group (under its lease id): the group; the rest: the chat.
    fn object_hashes(&self) -> ObjectHashes {
        let mut ids: std::collections::BTreeSet<u64> =
            self.scene.objects().map(|(id, _)| id.0).collect();
        ids.extend(self.edit_ops.keys().copied());
        ids.extend(self.parts.objects());
        let objects = ids.into_iter().map(|id| {
            let placed = (self.scene.scene_object(scene::ObjectId(id)))
                .map(|o| (o.group, object_codec::encode_object(&o.object)));
            let edit_ops: Vec<[u8; 32]> = self.edit_ops(id).iter().map(|op| op.0).collect();
            let record = (placed, edit_ops, self.parts.of_object(id));
            (
                ObjectId(id),
                SceneHash::of(&object_codec::encode(&record)).0,
            )
        });
        let groups = self.scene.groups().map(|(id, group)| {
            let hash = SceneHash::of(&object_codec::encode(group));
            (ObjectId(id.0 | GROUP_LEASE_BIT), hash.0)
        });
        let rest = SceneHash::of(&object_codec::encode(&self.chat));
        ObjectHashes::new(objects.chain(groups), rest.0)
    }
}

/// The order key of a chat line (for callers matching lines to ops).
pub fn chat_key(line: &ChatLine) -> OrderKey {
    OrderKey {
        lamport: line.lamport,
        author: PeerId(line.author),
        seq: line.seq,
    }
}
