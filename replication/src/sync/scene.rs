//! The scene check: peers compare the hashes of their folded scenes at quiescent points of a
//! connection, and where two differ at one cut, find the objects whose states differ and
//! refold them from the log. A detector of divergence in the product, not only in the
//! simulator.
//!
//! The core never folds. The scene's owner (the app's engine, a harness) tells the
//! [`Peer`](crate::peer::Peer) the hash of its fold at a [`SceneCut`]: a digest of the log's
//! heads, which name the causally closed op set exactly (op ids hash their deps). Each
//! connection sends it ([`Message::SceneHash`]) at a quiescent point (nothing to send,
//! nothing unacknowledged, both sides holding the same ops), once per change; a receiver at
//! the same cut compares. A different hash is a mismatch ([`SceneEvent::Mismatch`]): the
//! owner hands over its per-object hashes ([`ObjectHashes`]), each side sends them in parts
//! ([`Message::ObjectHashes`]), compares the other's with its own, and reports the objects
//! that differ ([`SceneEvent::Resync`]), which its owner refolds from its log. The changed
//! hash goes out again and the two agree. Both sides refold: the core cannot tell which one
//! is wrong, and refolding a right object changes nothing.
//!
//! **Bounds.** A remote's claims are untrusted. A mismatch is acted on (the owner computes
//! per-object hashes, and objects are refolded) at most once per window, which starts at
//! [`MIN_RESYNC_WAIT_MICROS`] and doubles up to [`MAX_RESYNC_WAIT_MICROS`] while mismatches
//! go on (it falls back to the shortest after a quiet [`MAX_RESYNC_WAIT_MICROS`]); one window
//! refolds at most [`MAX_RESYNC_OBJECTS`] objects and what belongs to no object once. Parts
//! outside an open window are counted and dropped, and at most [`MAX_HELD_PARTS`] wait for
//! the owner's own hashes. So a remote that claims mismatches without end costs this peer at
//! most one per-object hashing of its scene and [`MAX_RESYNC_OBJECTS`] object refolds a
//! minute, whatever it sends. A mismatch that a resync did not settle is tried again when
//! the window ends, so a lost message delays a repair and never prevents it; a try that
//! comes while this side's window is still open (the two windows out of step) has this
//! side's object hashes sent once more in it, so a repair never waits for windows that
//! double. Object hashes belong to one scene hash: a scene refolded or gone wrong again at
//! the same cut is hashed afresh, since the old ones would name what differed before.
//!
//! Non-guarantee: a refold repairs a fold that went wrong (a scene state that no longer
//! matches the log); two logs that judge the same ops differently fold to different scenes
//! however often they are refolded, and the check reports that, bounded, and no more.

use std::collections::VecDeque;
use std::sync::Arc;

use crate::identity::OpId;
use crate::log::Log;
use crate::payload::{ObjectId, Payload};
use crate::sync::message::{DIGEST_BYTES, MAX_OBJECT_HASHES, Message, ObjectHashesPart, SceneAt};
use crate::sync::state::Event;
use crate::time::Timestamp;

/// The shortest window between two mismatches acted on, on one connection (1 s).
pub const MIN_RESYNC_WAIT_MICROS: u64 = 1_000_000;
/// The longest (60 s): the window doubles up to it while mismatches go on.
pub const MAX_RESYNC_WAIT_MICROS: u64 = 60_000_000;
/// Most objects one window refolds on a remote's word (the rest wait for the next window).
pub const MAX_RESYNC_OBJECTS: usize = 64;
/// Most parts of the remote's object hashes held until the owner's own are known.
pub const MAX_HELD_PARTS: usize = 4;

/// A cut of a log: the digest of its heads (the op set they close), and the ops its version
/// vector counts (for people reading a report; the digest alone decides).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct SceneCut {
    /// The digest of the heads in id order.
    pub digest: [u8; DIGEST_BYTES],
    /// The ops the log's version vector counts.
    pub n_ops: u64,
}

impl std::fmt::Display for SceneCut {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ops, heads {}", self.n_ops, self.short())
    }
}

impl SceneCut {
    /// The cut `log` is at.
    pub fn of<P: Payload>(log: &Log<P>) -> Self {
        Self::of_heads(log.heads(), log.version_vector().n_ops())
    }

    /// The cut whose heads are `heads`, in id order, where a version vector counts `n_ops`
    /// (a snapshot's, before it is joined).
    pub fn of_heads<'a>(heads: impl IntoIterator<Item = &'a OpId>, n_ops: u64) -> Self {
        let mut hasher = blake3::Hasher::new();
        hasher.update(b"sculpt scene cut 1");
        for head in heads {
            hasher.update(&head.0);
        }
        Self {
            digest: *hasher.finalize().as_bytes(),
            n_ops,
        }
    }

    /// The first bytes of the digest in hex, for people reading a report.
    pub fn short(&self) -> String {
        (self.digest[..6].iter())
            .map(|b| format!("{b:02x}"))
            .collect()
    }

    /// A scene hash at this cut.
    pub fn with_hash(self, hash: [u8; DIGEST_BYTES]) -> SceneAt {
        SceneAt {
            cut: self.digest,
            n_ops: self.n_ops,
            hash,
        }
    }
}

/// A scene's hash split by object: each object's own hash, in id order, and the hash of what
/// belongs to no object (independent entries such as the chat). Two scenes whose objects'
/// and rests' hashes are all equal have equal scene hashes.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ObjectHashes {
    objects: Vec<(ObjectId, [u8; DIGEST_BYTES])>,
    rest: [u8; DIGEST_BYTES],
}

impl ObjectHashes {
    /// The hashes of `objects` (in any order; of an id given twice, the last) and of the rest.
    pub fn new(
        objects: impl IntoIterator<Item = (ObjectId, [u8; DIGEST_BYTES])>,
        rest: [u8; DIGEST_BYTES],
    ) -> Self {
        let mut objects: Vec<_> = objects.into_iter().collect();
        objects.reverse();
        objects.sort_by_key(|(object, _)| *object);
        objects.dedup_by_key(|(object, _)| *object);
        Self { objects, rest }
    }

    /// Each object's hash, in id order.
    pub fn objects(&self) -> &[(ObjectId, [u8; DIGEST_BYTES])] {
        &self.objects
    }

    /// The hash of what belongs to no object.
    pub fn rest(&self) -> [u8; DIGEST_BYTES] {
        self.rest
    }

    /// How many parts the hashes go out in (one at least, so that an empty scene says so).
    fn n_parts(&self) -> usize {
        self.objects.len().div_ceil(MAX_OBJECT_HASHES).max(1)
    }

    /// Part `part_idx` at `cut`: its objects, over a range that the parts tile from 0 to
    /// `u64::MAX`.
    fn part(&self, cut: [u8; DIGEST_BYTES], part_idx: usize) -> ObjectHashesPart {
        let start = part_idx * MAX_OBJECT_HASHES;
        let end = (start + MAX_OBJECT_HASHES).min(self.objects.len());
        let from = match part_idx {
            0 => 0,
            _ => self.objects[start].0.0,
        };
        let to = match self.objects.get(end) {
            Some((next, _)) => next.0 - 1,
            None => u64::MAX,
        };
        ObjectHashesPart {
            cut,
            from,
            to,
            rest: self.rest,
            objects: (self.objects[start.min(end)..end].iter())
                .map(|(object, hash)| (object.0, *hash))
                .collect(),
        }
    }

    /// The objects in `part`'s range whose hashes differ from these (held on one side only
    /// included), in id order, and whether the rests differ.
    pub fn differing(&self, part: &ObjectHashesPart) -> (Vec<ObjectId>, bool) {
        let lo = self.objects.partition_point(|(o, _)| o.0 < part.from);
        let hi = self.objects.partition_point(|(o, _)| o.0 <= part.to);
        let mut ours = self.objects[lo..hi].iter().peekable();
        let mut theirs = part.objects.iter().peekable();
        let mut differ = Vec::new();
        loop {
            match (ours.peek(), theirs.peek()) {
                (Some((o, a)), Some((t, b))) if o.0 == *t => {
                    if a != b {
                        differ.push(*o);
                    }
                    ours.next();
                    theirs.next();
                }
                (Some((o, _)), Some((t, _))) if o.0 > *t => {
                    differ.push(ObjectId(*t));
                    theirs.next();
                }
                (Some((o, _)), _) => {
                    differ.push(*o);
                    ours.next();
                }
                (_, Some((t, _))) => {
                    differ.push(ObjectId(*t));
                    theirs.next();
                }
                (None, None) => break,
            }
        }
        (differ, part.rest != self.rest)
    }
}

/// Two scene hashes that differ at one cut: this peer's and the remote's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneMismatch {
    /// This peer's cut and hash.
    pub ours: SceneAt,
    /// The remote's cut (the same digest) and hash.
    pub theirs: SceneAt,
}

/// Objects whose states differ from the remote's at a cut: the owner refolds them from its
/// log, if its fold is still at that cut.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Resync {
    /// The cut ([`SceneCut::digest`]).
    pub cut: [u8; DIGEST_BYTES],
    /// The objects, in id order (at most [`MAX_RESYNC_OBJECTS`] a window).
    pub objects: Vec<ObjectId>,
    /// What belongs to no object differs too: refold the independent entries.
    pub rest: bool,
}

/// What the scene check asks of the scene's owner.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SceneEvent {
    /// The remote's scene hash differs from this peer's at one cut, and the check acts on it:
    /// hand over this scene's per-object hashes at that cut
    /// ([`Peer::set_object_hashes`](crate::peer::Peer::set_object_hashes)).
    Mismatch(SceneMismatch),
    /// Refold these objects from the log.
    Resync(Resync),
}

/// What the scene check of one connection did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SceneStats {
    /// Scene hashes compared at one cut (the remote's with this peer's).
    pub n_checks: u64,
    /// Of those, the ones that differed.
    pub n_mismatches: u64,
    /// Mismatches acted on (at most one a window).
    pub n_resyncs: u64,
    /// Objects named for a refold.
    pub n_resync_objects: u64,
    /// Scene messages dropped: parts outside an open window or at another cut, or over
    /// [`MAX_HELD_PARTS`], and objects over [`MAX_RESYNC_OBJECTS`].
    pub n_dropped: u64,
    /// Whether the last comparison agreed (`None` before the first).
    pub agrees: Option<bool>,
    /// The last mismatch seen.
    pub last_mismatch: Option<SceneMismatch>,
}

/// A window in which the remote's object hashes at `cut` are compared and acted on.
#[derive(Clone, Copy, Debug)]
struct Window {
    cut: [u8; DIGEST_BYTES],
    until: Timestamp,
    objects_left: usize,
    rest_done: bool,
    sent: bool,
    /// The parts went again on the remote's new try ([`SceneCheck::resend_parts`]).
    resent: bool,
}

/// The scene check of one connection (kept by its [`crate::SyncState`]).
#[derive(Debug, Default)]
pub(crate) struct SceneCheck {
    /// This peer's scene hash at its log's current cut, as the owner last said.
    local: Option<SceneAt>,
    /// This peer's object hashes at `local`'s cut, once the owner handed them over.
    local_objects: Option<Arc<ObjectHashes>>,
    /// The scene hash last sent.
    sent: Option<SceneAt>,
    /// The remote's last scene hash.
    remote: Option<SceneAt>,
    /// `local` or `remote` changed since the last comparison.
    compare_due: bool,
    window: Option<Window>,
    /// Parts of this peer's object hashes to send, and the next one's index.
    out: Option<(Arc<ObjectHashes>, usize)>,
    /// The remote's parts that came before `local_objects`.
    held: Vec<ObjectHashesPart>,
    /// The next window's length, and when it may open.
    wait_micros: u64,
    next_at: Timestamp,
    pub(crate) stats: SceneStats,
}

impl SceneCheck {
    /// The owner's scene hash at the log's current cut. Object hashes taken at another hash
    /// are forgotten, even at the same cut: they would name what differed then.
    pub(crate) fn set_local(&mut self, at: SceneAt) {
        if self.local == Some(at) {
            return;
        }
        self.local_objects = None;
        if self.local.is_none_or(|l| l.cut != at.cut) {
            self.held.retain(|part| part.cut == at.cut);
            if self.window.is_some_and(|w| w.cut != at.cut) {
                self.window = None;
                self.out = None;
            }
        }
        self.local = Some(at);
        self.compare_due = self.remote.is_some();
    }

    /// The owner's object hashes at `cut`: sent if a window at that cut waits for them, and
    /// compared with the remote's parts held.
    pub(crate) fn set_local_objects(
        &mut self,
        cut: [u8; DIGEST_BYTES],
        hashes: &Arc<ObjectHashes>,
        events: &mut VecDeque<Event>,
    ) {
        if self.local.is_none_or(|l| l.cut != cut) {
            return;
        }
        self.local_objects = Some(Arc::clone(hashes));
        self.queue_parts();
        for part in std::mem::take(&mut self.held) {
            self.compare_part(&part, events);
        }
    }

    /// The remote's scene hash.
    pub(crate) fn on_remote_hash(
        &mut self,
        now: Timestamp,
        at: SceneAt,
        events: &mut VecDeque<Event>,
    ) {
        self.remote = Some(at);
        self.compare(now, events);
    }

    /// A part of the remote's object hashes: compared inside an open window at this peer's
    /// cut (held while the owner's own hashes are not known), dropped elsewhere.
    pub(crate) fn on_part(
        &mut self,
        now: Timestamp,
        part: ObjectHashesPart,
        events: &mut VecDeque<Event>,
    ) {
        let open = self
            .window
            .is_some_and(|w| w.cut == part.cut && now < w.until);
        if !open {
            self.stats.n_dropped += 1;
        } else if self.local_objects.is_some() {
            self.compare_part(&part, events);
        } else if self.held.len() < MAX_HELD_PARTS {
            self.held.push(part);
        } else {
            self.stats.n_dropped += 1;
        }
    }

    /// When [`SceneCheck::timeout`] is due: at once after a change, and at the end of a
    /// window while the mismatch it opened for lasts.
    pub(crate) fn due(&self) -> Option<Timestamp> {
        if self.compare_due {
            Some(Timestamp(0))
        } else if self.stats.agrees == Some(false) && self.same_cut() {
            Some(self.next_at)
        } else {
            None
        }
    }

    /// Compares after a change, and tries a lasting mismatch again once its window ends
    /// (sending this peer's hash again, so the remote compares too).
    pub(crate) fn timeout(&mut self, now: Timestamp, events: &mut VecDeque<Event>) {
        let retry = self.stats.agrees == Some(false) && now >= self.next_at;
        if self.compare_due || (retry && self.same_cut()) {
            if retry {
                self.sent = None;
            }
            self.compare(now, events);
        }
    }

    /// The next part of this peer's object hashes to send.
    pub(crate) fn next_part(&mut self) -> Option<Message> {
        let (hashes, part_idx) = self.out.as_mut()?;
        let cut = self.local?.cut;
        let part = hashes.part(cut, *part_idx);
        *part_idx += 1;
        if *part_idx >= hashes.n_parts() {
            self.out = None;
        }
        Some(Message::ObjectHashes(part))
    }

    /// True when this peer's scene hash changed since it was last sent.
    pub(crate) fn hash_unsent(&self) -> bool {
        self.local.is_some() && self.sent != self.local
    }

    /// This peer's scene hash, to send at a quiescent point of the connection.
    pub(crate) fn take_hash(&mut self) -> Option<Message> {
        let at = self.local.filter(|_| self.hash_unsent())?;
        self.sent = Some(at);
        Some(Message::SceneHash(at))
    }

    fn same_cut(&self) -> bool {
        matches!((self.local, self.remote), (Some(l), Some(r)) if l.cut == r.cut)
    }

    /// Compares the two hashes if they are at one cut: an agreement closes the window, a
    /// mismatch opens one if the last has ended.
    fn compare(&mut self, now: Timestamp, events: &mut VecDeque<Event>) {
        self.compare_due = false;
        let (Some(ours), Some(theirs)) = (self.local, self.remote) else {
            return;
        };
        if ours.cut != theirs.cut {
            return;
        }
        self.stats.n_checks += 1;
        if ours.hash == theirs.hash {
            self.stats.agrees = Some(true);
            self.window = None;
            self.out = None;
            self.held.clear();
            return;
        }
        self.stats.agrees = Some(false);
        self.stats.n_mismatches += 1;
        let mismatch = SceneMismatch { ours, theirs };
        self.stats.last_mismatch = Some(mismatch);
        if !self.open_window(now, ours.cut) {
            self.resend_parts(now, mismatch, events);
            return;
        }
        self.stats.n_resyncs += 1;
        events.push_back(Event::Scene(SceneEvent::Mismatch(mismatch)));
        self.queue_parts();
    }

    /// Opens a window at `cut` if the last one ended, and lengthens the next.
    fn open_window(&mut self, now: Timestamp, cut: [u8; DIGEST_BYTES]) -> bool {
        if now < self.next_at {
            return false;
        }
        let quiet = now.0 >= self.next_at.0.saturating_add(MAX_RESYNC_WAIT_MICROS);
        if quiet || self.wait_micros == 0 {
            self.wait_micros = MIN_RESYNC_WAIT_MICROS;
        }
        self.next_at = now.saturating_add_micros(self.wait_micros);
        self.window = Some(Window {
            cut,
            until: self.next_at,
            objects_left: MAX_RESYNC_OBJECTS,
            rest_done: false,
            sent: false,
            resent: false,
        });
        self.wait_micros = (self.wait_micros * 2).min(MAX_RESYNC_WAIT_MICROS);
        true
    }

    /// A mismatch that came while a window at its cut is still open: the remote tried again
    /// (its own window ended first, and what this side sent reached it outside its next one),
    /// so this peer's object hashes go once more, once a window; else it is dropped. Without
    /// this, two sides whose windows are out of step each drop the other's try, and a repair
    /// waits for windows that double.
    fn resend_parts(
        &mut self,
        now: Timestamp,
        mismatch: SceneMismatch,
        events: &mut VecDeque<Event>,
    ) {
        let Some(window) = &mut self.window else {
            self.stats.n_dropped += 1;
            return;
        };
        if window.cut != mismatch.ours.cut || now >= window.until || window.resent {
            self.stats.n_dropped += 1;
            return;
        }
        window.resent = true;
        window.sent = false;
        if self.local_objects.is_none() {
            events.push_back(Event::Scene(SceneEvent::Mismatch(mismatch)));
        }
        self.queue_parts();
    }

    /// Queues this peer's object hashes once per window, once the owner handed them over.
    fn queue_parts(&mut self) {
        let Some(window) = &mut self.window else {
            return;
        };
        if let Some(hashes) = &self.local_objects
            && !window.sent
        {
            window.sent = true;
            self.out = Some((Arc::clone(hashes), 0));
        }
    }

    /// Compares a part of the remote's object hashes with this peer's, within the window's
    /// budget, and asks the owner to refold what differs.
    fn compare_part(&mut self, part: &ObjectHashesPart, events: &mut VecDeque<Event>) {
        let (Some(hashes), Some(window)) = (&self.local_objects, &mut self.window) else {
            return;
        };
        if window.cut != part.cut {
            self.stats.n_dropped += 1;
            return;
        }
        let (mut objects, rest) = hashes.differing(part);
        if objects.len() > window.objects_left {
            self.stats.n_dropped += (objects.len() - window.objects_left) as u64;
            objects.truncate(window.objects_left);
        }
        window.objects_left -= objects.len();
        let rest = rest && !window.rest_done;
        window.rest_done |= rest;
        if objects.is_empty() && !rest {
            return;
        }
        self.stats.n_resync_objects += objects.len() as u64;
        let resync = Resync {
            cut: part.cut,
            objects,
            rest,
        };
        events.push_back(Event::Scene(SceneEvent::Resync(resync)));
    }
}

#[cfg(test)]
mod tests;
