//! An honest peer as the harness holds it ([`Honest`]): the real core, its scene kept up to
//! date from every insertion, its scripted user, its disk and its counters; and calls into a
//! core (the byzantine member's too) guarded against panics, which are recorded, never
//! propagated.

use std::collections::BTreeSet;
use std::panic::{self, AssertUnwindSafe};

use replication::log::RefoldBudget;
use replication::materialize::Materialized;
use replication::shape::{ShapePayload, ShapeScene};
use replication::{Keypair, Log, OpId, Peer};

use crate::memory;
use crate::report::CatchUp;
use crate::session::SESSION_ID;
use crate::store::Disk;
use crate::workload::User;

/// Most events or messages drained from one core in one go (a live-lock guard).
pub const MAX_DRAIN: usize = 1_000_000;

/// The scene of a peer, kept in step with its log.
pub(crate) type Scene = Materialized<ShapePayload, ShapeScene>;

/// One honest peer and what the harness knows about it.
pub(crate) struct Honest {
    /// The key's seed (a restart rebuilds the key from it).
    pub(crate) key_seed: [u8; 32],
    pub(crate) peer: Peer<ShapePayload>,
    /// Kept up to date incrementally from every insertion, as the app does.
    pub(crate) scene: Scene,
    pub(crate) user: User,
    /// Ops delivered so far, to check that every op's deps came before it.
    pub(crate) seen: BTreeSet<OpId>,
    pub(crate) n_received_insertions: u64,
    pub(crate) panicked: Option<String>,
    pub(crate) offline_depth: u32,
    /// False until a late peer joins.
    pub(crate) started: bool,
    pub(crate) wake_at: Option<u64>,
    pub(crate) n_causal_violations: u64,
    pub(crate) authored: Vec<OpId>,
    /// Its own ops that were effective when it authored them (the causal-erasure checker's).
    pub(crate) effective_at_author: Vec<OpId>,
    pub(crate) disk: Disk,
    /// Memory slot ([`memory`]) its calls are charged to.
    pub(crate) slot: usize,
    pub(crate) slot_baseline: i64,
    pub(crate) peak_live_bytes: i64,
    pub(crate) n_messages_sent: u64,
    pub(crate) n_bytes_sent: u64,
    /// A crash waiting for the next write (its restart delay, and whether it waits for an
    /// op of the peer's own).
    pub(crate) crash_armed: Option<(u64, bool)>,
    /// How it catches up after healing.
    pub(crate) catch_up: CatchUp,
}

impl Honest {
    /// Heap bytes its calls hold now (0 without the counting allocator).
    pub(crate) fn live_bytes(&self) -> i64 {
        memory::live_bytes(self.slot) - self.slot_baseline
    }
}

/// A fresh honest peer with `log` (charged to memory slot `slot`).
pub(crate) fn new_honest(
    key_seed: [u8; 32],
    mut log: Log<ShapePayload>,
    slot: usize,
    budget: RefoldBudget,
) -> Option<Honest> {
    log.set_refold_budget(budget);
    let slot_baseline = memory::live_bytes(slot);
    let (peer, scene) = memory::with_slot(slot, || {
        let scene = Scene::fold(&log);
        Some((
            Peer::new(Keypair::from_seed(key_seed), SESSION_ID, log),
            scene,
        ))
    })?;
    let user = User::new(peer.peer_id());
    Some(Honest {
        key_seed,
        peer,
        scene,
        user,
        seen: BTreeSet::new(),
        n_received_insertions: 0,
        panicked: None,
        offline_depth: 0,
        started: true,
        wake_at: None,
        n_causal_violations: 0,
        authored: Vec::new(),
        effective_at_author: Vec::new(),
        disk: Disk::default(),
        slot,
        slot_baseline,
        peak_live_bytes: 0,
        n_messages_sent: 0,
        n_bytes_sent: 0,
        crash_armed: None,
        catch_up: CatchUp::default(),
    })
}

/// Records ops as delivered at a peer, checking that each one's deps came first.
pub(crate) fn note_delivered(h: &mut Honest, delivered: &[OpId]) {
    for id in delivered {
        if let Some(op) = h.peer.log().get(id) {
            let early = op.deps().iter().filter(|d| !h.seen.contains(*d)).count();
            h.n_causal_violations += early as u64;
        }
        h.seen.insert(*id);
    }
}

/// Calls into a peer unless it already panicked; a panic is recorded, never propagated.
/// Memory the call allocates is charged to the peer's slot.
pub(crate) fn guarded<R>(
    h: &mut Honest,
    f: impl FnOnce(&mut Peer<ShapePayload>) -> R,
) -> Option<R> {
    if h.panicked.is_some() {
        return None;
    }
    let slot = h.slot;
    let result = memory::with_slot(slot, || {
        panic::catch_unwind(AssertUnwindSafe(|| f(&mut h.peer)))
    });
    match result {
        Ok(r) => Some(r),
        Err(e) => {
            h.panicked = Some(panic_text(e.as_ref()));
            None
        }
    }
}

/// Calls into a core unless it already panicked; a panic is recorded in `panicked`.
pub(crate) fn guarded_call<R>(
    panicked: &mut Option<String>,
    peer: &mut Peer<ShapePayload>,
    f: impl FnOnce(&mut Peer<ShapePayload>) -> R,
) -> Option<R> {
    if panicked.is_some() {
        return None;
    }
    match panic::catch_unwind(AssertUnwindSafe(|| f(peer))) {
        Ok(r) => Some(r),
        Err(e) => {
            *panicked = Some(panic_text(e.as_ref()));
            None
        }
    }
}

/// What a caught panic said.
pub(crate) fn panic_text(e: &(dyn std::any::Any + Send)) -> String {
    e.downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| e.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "non-text panic".into())
}
