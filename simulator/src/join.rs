//! Late joins from a snapshot: the producer captures its log at its stable Lamport time with
//! the real [`Snapshot::capture`], encodes it; the joiner decodes those bytes (so the codec
//! is exercised too) and joins with [`Snapshot::join`], then syncs only the ops after the cut.

use replication::log::RefoldBudget;
use replication::pending::PendingLimits;
use replication::shape::{ShapePayload, ShapeScene};
use replication::snapshot::Snapshot;
use replication::{Keypair, Peer};

use crate::honest::{Honest, Scene};
use crate::memory;
use crate::session::SESSION_ID;

/// What a snapshot join gives the joiner: the snapshot's bytes (kept beside its store), the
/// cut, the peer and its scene.
pub(crate) type Joined = (Vec<u8>, u64, Peer<ShapePayload>, Scene);

/// Joins `joiner` from a snapshot of `producer`'s log.
/// The joiner's log runs with the refold `budget`.
pub(crate) fn from_snapshot(
    producer: &Honest,
    joiner: &Honest,
    budget: RefoldBudget,
) -> Result<Joined, String> {
    let log = producer.peer.log();
    let cut = log.stable_lamport();
    let snapshot = Snapshot::<ShapePayload>::capture::<ShapeScene>(log, cut)
        .map_err(|e| format!("capture at {cut}: {e}"))?;
    let bytes = snapshot.encode().map_err(|e| format!("encode: {e}"))?;
    let (peer, scene) = memory::with_slot(joiner.slot, || {
        let decoded =
            Snapshot::<ShapePayload>::decode(&bytes).map_err(|e| format!("decode: {e}"))?;
        let (mut log, scene) = decoded
            .join::<ShapeScene>(PendingLimits::default())
            .map_err(|e| format!("join: {e}"))?;
        log.set_refold_budget(budget);
        let key = Keypair::from_seed(joiner.key_seed);
        Ok::<_, String>((Peer::new(key, SESSION_ID, log), scene))
    })?;
    Ok((bytes, cut, peer, scene))
}
