//! Late joins from a snapshot: the producer captures its log and scene hash with the real
//! [`Snapshot::capture`] and encodes them; the joiner decodes those bytes (so the codec is
//! exercised too), joins with [`Snapshot::join`] into its empty, configured log (which folds
//! the ops and checks the fold against the named scene hash), and runs the check a peer runs
//! after joining ([`snapshot::verify`]: the signatures). A snapshot that fails either is not
//! adopted: the joiner starts empty and syncs op by op. The hostile member hands some joiners
//! a snapshot whose scene is not its ops' fold (an empty scene's hash): the join must refuse
//! it.

use replication::log::RefoldBudget;
use replication::shape::{ShapePayload, ShapeScene};
use replication::snapshot::{self, JoinError, Snapshot};
use replication::{Keypair, Log, Peer, Timestamp};

use crate::honest::{Honest, Scene};
use crate::memory;
use crate::session::SESSION_ID;

/// What a snapshot join gives the joiner: the snapshot's bytes (kept beside its store), the
/// peer and its scene.
pub(crate) type Joined = (Vec<u8>, Peer<ShapePayload>, Scene);

/// Why a snapshot join did not happen.
pub(crate) enum Failed {
    /// The join's fold or the check afterwards refused the snapshot.
    Refused(String),
    /// Anything else (an honest producer's snapshot should never get here).
    Other(String),
}

/// Joins `joiner` from a snapshot of `producer`'s log and scene, or with `planted` of its log
/// and an empty scene; the joiner's log runs with the refold `budget`. An error leaves the
/// joiner to sync op by op.
pub(crate) fn from_snapshot(
    producer: &Honest,
    joiner: &Honest,
    budget: RefoldBudget,
    now: Timestamp,
    planted: bool,
) -> Result<Joined, Failed> {
    let log = producer.peer.log();
    let empty = planted.then(|| Scene::fold(&Log::default()));
    let bytes = Snapshot::capture(log, empty.as_ref().unwrap_or(&producer.scene))
        .encode()
        .map_err(|e| Failed::Other(format!("capture: {e}")))?;
    let fresh = joiner.peer.log().clone();
    let (peer, scene) = memory::with_slot(joiner.slot, || {
        let decoded = (Snapshot::<ShapePayload>::decode(&bytes))
            .map_err(|e| Failed::Other(format!("decode: {e}")))?;
        let (mut log, scene) = (decoded.join::<ShapeScene>(fresh, now)).map_err(|e| match e {
            JoinError::SceneHash => Failed::Refused(format!("join: {e}")),
            e => Failed::Other(format!("join: {e}")),
        })?;
        snapshot::verify(&log, &SESSION_ID, |_| {})
            .map_err(|e| Failed::Refused(format!("verify: {e}")))?;
        log.set_refold_budget(budget);
        let key = Keypair::from_seed(joiner.key_seed);
        Ok::<_, Failed>((Peer::new(key, SESSION_ID, log), scene))
    })?;
    Ok((bytes, peer, scene))
}
