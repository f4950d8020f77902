//! Materialisation: how a payload's object model folds the log's active entries into a scene,
//! per object, and the driver ([`Materialized`]) that keeps a scene in step with a [`Log`] by
//! re-folding only the objects an insertion changed.
//!
//! The scene is a function of the active entries alone: for each object, the fold of its
//! active edits in linear order; plus the independent entries (chat) in linear order. Lease,
//! release, undo and redo ops never reach the scene directly: they decide which edits are
//! active. So the same op set gives the same scene, and the same [`SceneHash`], on every peer.

use std::collections::BTreeMap;
use std::collections::btree_map::Entry;
use std::marker::PhantomData;

use crate::identity::{OpId, PeerId};

use crate::log::{Drained, Insertion, Log, OrderKey, Refold};
use crate::op::Op;
use crate::payload::{Effect, ObjectId, Payload};
use crate::sync::scene::ObjectHashes;

/// Length of a [`SceneHash`].
pub const SCENE_HASH_BYTES: usize = 32;

/// The blake3 hash of a scene's canonical encoding: equal on every peer with the same op set.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct SceneHash(pub [u8; SCENE_HASH_BYTES]);

impl SceneHash {
    /// The hash of `bytes` (a scene's canonical encoding).
    pub fn of(bytes: &[u8]) -> Self {
        Self(*blake3::hash(bytes).as_bytes())
    }
}

/// One active entry handed to the scene.
#[derive(Debug, Clone, Copy)]
pub struct FoldEntry<'a, P> {
    /// Its place in the linear order (stable across peers and insertions).
    pub key: OrderKey,
    /// The op.
    pub op: &'a Op<P>,
}

/// A payload's object model as a scene that the log's active entries fold into.
///
/// The driver calls, for each object, [`Materialize::reset_object`] and then
/// [`Materialize::apply`] with the object's active edits in linear order; after a late op it
/// resets and re-folds only the objects whose fold changed, or appends to an object when the
/// change lies after everything applied to it. Independent entries ([`Effect::Independent`])
/// are applied exactly once each, usually in linear order; a late one arrives after entries
/// that follow it, and the scene places it by its key (a chat list sorted by key).
/// Leases, releases, undos and redos are never applied: they only decide which edits are
/// active.
pub trait Materialize<P: Payload> {
    /// Forgets everything folded into `object`: its fold starts again.
    fn reset_object(&mut self, object: ObjectId);

    /// Folds one active entry: an edit of one object, or an independent entry.
    fn apply(&mut self, entry: FoldEntry<'_, P>);

    /// Forgets the independent entries by `author` with seq `from_seq` or later (the ops of a
    /// member an expel voided, or a readmit brought back); the active ones are applied again.
    fn reset_independent(&mut self, author: PeerId, from_seq: u64);

    /// Readies `object` for the queries that follow a batch of folds (an object model's index
    /// of its recent edits); nothing by default. Folds never need it, and it changes nothing
    /// the scene encodes, so a face that samples the scene calls it once per batch.
    fn prepare(&mut self, _object: ObjectId) {}

    /// The blake3 hash of the scene's canonical encoding.
    fn scene_hash(&self) -> SceneHash;

    /// The scene's hash split by object (each id that [`Materialize::reset_object`] takes),
    /// and the rest: two scenes whose parts all hash equal have equal scene hashes, so peers
    /// whose scene hashes differ find the objects to refold ([`crate::sync::scene`]).
    fn object_hashes(&self) -> ObjectHashes;
}

/// What a [`Materialized`] did, to measure how much a refold costs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FoldStats {
    /// Entries applied to the scene.
    pub n_applied: u64,
    /// Objects reset and re-folded from their start.
    pub n_object_refolds: u64,
    /// Objects appended to without a reset.
    pub n_object_appends: u64,
}

/// A scene kept in step with a log.
///
/// Feed it every [`Insertion`] the log (or a [`crate::SyncState`] event) reports, in the order
/// they were reported; it may lag the log (keys, not positions, say what changed).
#[derive(Debug, Clone)]
pub struct Materialized<P, M> {
    scene: M,
    /// Per object, the key of the last held edit applied since its last reset.
    last_applied: BTreeMap<ObjectId, OrderKey>,
    stats: FoldStats,
    payload: PhantomData<P>,
}

impl<P: Payload, M: Materialize<P>> Materialized<P, M> {
    /// The scene of `log`, folded from scratch.
    pub fn fold(log: &Log<P>) -> Self
    where
        M: Default,
    {
        let mut out = Self {
            scene: M::default(),
            last_applied: BTreeMap::new(),
            stats: FoldStats::default(),
            payload: PhantomData,
        };
        for entry in log.entries().filter(|e| e.active) {
            let key = OrderKey::of(entry.op);
            if let Effect::Edit { object } = entry.op.payload().effect() {
                out.last_applied.insert(object, key);
            }
            out.scene.apply(FoldEntry { key, op: entry.op });
            out.stats.n_applied += 1;
        }
        out
    }

    /// The scene.
    pub fn scene(&self) -> &M {
        &self.scene
    }

    /// The scene's hash.
    pub fn scene_hash(&self) -> SceneHash {
        self.scene.scene_hash()
    }

    /// What the driver did so far.
    pub fn stats(&self) -> FoldStats {
        self.stats
    }

    /// The scene's per-object hashes ([`Materialize::object_hashes`]).
    pub fn object_hashes(&self) -> ObjectHashes {
        self.scene.object_hashes()
    }

    /// Refolds `objects` from their start in `log`, and with `rest` the independent entries:
    /// the repair when a peer's scene differs from another's at the same cut
    /// ([`crate::sync::scene::Resync`]). A fold that was right is left as it was.
    pub fn resync(&mut self, log: &Log<P>, objects: &[ObjectId], rest: bool) {
        for object in objects {
            self.refold_object(log, *object);
        }
        if rest {
            let void_from = (log.version_vector().iter())
                .map(|(author, _)| (*author, 1))
                .collect();
            let refold = Refold {
                void_from,
                ..Refold::default()
            };
            self.apply_refold(log, &[], &refold);
        }
    }

    /// Changes the folded scene behind the log's back, to test that peers find and repair a
    /// scene that no longer matches their log ([`crate::sync::scene`]). Never call it
    /// otherwise.
    #[doc(hidden)]
    pub fn plant_difference(&mut self, plant: impl FnOnce(&mut M)) {
        plant(&mut self.scene);
    }

    /// Readies `objects` for queries after a batch of folds ([`Materialize::prepare`]).
    pub fn prepare(&mut self, objects: impl IntoIterator<Item = ObjectId>) {
        objects.into_iter().for_each(|o| self.scene.prepare(o));
    }

    /// Brings the scene up to date with what `insertion` changed in `log`.
    pub fn apply_insertion(&mut self, log: &Log<P>, insertion: &Insertion) {
        if let Some(refold) = &insertion.refold {
            self.apply_refold(log, &insertion.delivered, refold);
        }
    }

    /// Brings the scene up to date with several insertions drained together, all of them
    /// already in `log`: their refolds merged ([`Drained`]) and folded once. Applying them one
    /// by one would refold from scratch every object an earlier one already folded past a
    /// later one's first change.
    pub fn apply_insertions<'a>(
        &mut self,
        log: &Log<P>,
        insertions: impl IntoIterator<Item = &'a Insertion>,
    ) {
        let mut drained = Drained::default();
        for insertion in insertions {
            drained.add(insertion);
        }
        if let Some(refold) = &drained.refold {
            self.apply_refold(log, &drained.delivered, refold);
        }
    }

    /// Re-folds what `refold` names and applies the `delivered` independent entries (the
    /// active ones: those of an expelled member's void ops are not).
    pub fn apply_refold(&mut self, log: &Log<P>, delivered: &[OpId], refold: &Refold) {
        for (author, from_seq) in &refold.void_from {
            self.scene.reset_independent(*author, *from_seq);
            let last = log.version_vector().get(author);
            for seq in *from_seq..=last {
                let Some(op) = log.by_seq(author, seq) else {
                    continue;
                };
                if op.payload().effect() == Effect::Independent && log.is_active(&op.id()) {
                    self.scene.apply(FoldEntry {
                        key: OrderKey::of(op),
                        op,
                    });
                    self.stats.n_applied += 1;
                }
            }
        }
        let reapplied =
            |op: &Op<P>| (refold.void_from.get(&op.author())).is_some_and(|from| op.seq() >= *from);
        for (object, from) in &refold.object_keys {
            // Looked up once: to choose, then to note what an append applied.
            let last = self.last_applied.entry(*object);
            let applied_after = matches!(&last, Entry::Occupied(l) if *l.get() >= *from);
            if applied_after {
                self.refold_object(log, *object);
                continue;
            }
            // The change lies after everything applied to the object: append.
            self.stats.n_object_appends += 1;
            let (scene, stats) = (&mut self.scene, &mut self.stats);
            if let Some(key) = apply_held_edits(scene, stats, log, *object, Some(from)) {
                last.insert_entry(key);
            }
        }
        for id in delivered {
            let Some(op) = log.get(id) else { continue };
            if op.payload().effect() == Effect::Independent && log.is_active(id) && !reapplied(op) {
                self.scene.apply(FoldEntry {
                    key: OrderKey::of(op),
                    op,
                });
                self.stats.n_applied += 1;
            }
        }
    }

    /// Resets `object` and folds all of its active edits.
    fn refold_object(&mut self, log: &Log<P>, object: ObjectId) {
        self.scene.reset_object(object);
        self.stats.n_object_refolds += 1;
        self.last_applied.remove(&object);
        let (scene, stats) = (&mut self.scene, &mut self.stats);
        if let Some(key) = apply_held_edits(scene, stats, log, object, None) {
            self.last_applied.insert(object, key);
        }
    }
}

/// Applies `object`'s active held edits to `scene`: all of them, or those from key `from` on.
/// Returns the key of the last one applied, for the caller to note where it keeps it (one
/// write per object, not one per edit).
fn apply_held_edits<P: Payload, M: Materialize<P>>(
    scene: &mut M,
    stats: &mut FoldStats,
    log: &Log<P>,
    object: ObjectId,
    from: Option<&OrderKey>,
) -> Option<OrderKey> {
    let mut last = None;
    for (key, entry) in log.object_edits(object, from) {
        if !entry.active {
            continue;
        }
        scene.apply(FoldEntry { key, op: entry.op });
        stats.n_applied += 1;
        last = Some(key);
    }
    last
}

/// A toy scene for [`crate::payload::test_payload::TestPayload`]: each object's value (the
/// last active `Set`) and the chat list in linear order.
pub mod test_scene {
    use super::*;
    use crate::codec::{put_bytes, put_varint};
    use crate::payload::test_payload::TestPayload;

    /// Version byte of the test scene's canonical encoding.
    pub const TEST_SCENE_FORMAT_VERSION: u8 = 1;

    /// Object values and the chat list.
    #[derive(Clone, Debug, Default, PartialEq, Eq)]
    pub struct TestScene {
        /// Object -> value of its last active `Set`.
        pub objects: BTreeMap<u64, String>,
        /// Chat lines sorted by order key.
        pub chat: Vec<(OrderKey, String)>,
    }

    impl Materialize<TestPayload> for TestScene {
        fn reset_object(&mut self, object: ObjectId) {
            self.objects.remove(&object.0);
        }

        fn reset_independent(&mut self, author: PeerId, from_seq: u64) {
            self.chat
                .retain(|(key, _)| key.author != author || key.seq < from_seq);
        }

        fn apply(&mut self, entry: FoldEntry<'_, TestPayload>) {
            match entry.op.payload() {
                TestPayload::Set { object, value } => match self.objects.get_mut(object) {
                    // Reuses the old value's buffer.
                    Some(old) => old.clone_from(value),
                    None => {
                        self.objects.insert(*object, value.clone());
                    }
                },
                TestPayload::Chat(text) => {
                    let at = self.chat.partition_point(|(k, _)| *k < entry.key);
                    // Applying a line twice changes nothing.
                    if self.chat.get(at).is_none_or(|(k, _)| *k != entry.key) {
                        self.chat.insert(at, (entry.key, text.clone()));
                    }
                }
                _ => {}
            }
        }

        fn scene_hash(&self) -> SceneHash {
            let mut bytes = Vec::new();
            self.encode(&mut bytes);
            SceneHash::of(&bytes)
        }

        fn object_hashes(&self) -> ObjectHashes {
            let objects = (self.objects.iter())
                .map(|(object, value)| (ObjectId(*object), SceneHash::of(value.as_bytes()).0));
            let mut chat = Vec::new();
            for (key, text) in &self.chat {
                put_varint(&mut chat, key.lamport);
                chat.extend_from_slice(&key.author.0);
                put_varint(&mut chat, key.seq);
                put_bytes(&mut chat, text.as_bytes());
            }
            ObjectHashes::new(objects, SceneHash::of(&chat).0)
        }
    }

    impl TestScene {
        /// The scene's canonical encoding, which its hash hashes.
        fn encode(&self, out: &mut Vec<u8>) {
            out.push(TEST_SCENE_FORMAT_VERSION);
            put_varint(out, self.objects.len() as u64);
            for (object, value) in &self.objects {
                put_varint(out, *object);
                put_bytes(out, value.as_bytes());
            }
            put_varint(out, self.chat.len() as u64);
            for (key, text) in &self.chat {
                put_varint(out, key.lamport);
                out.extend_from_slice(&key.author.0);
                put_varint(out, key.seq);
                put_bytes(out, text.as_bytes());
            }
        }
    }
}

#[cfg(test)]
mod tests;
