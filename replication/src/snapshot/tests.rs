//! Snapshot tests: a peer joined from a snapshot syncs the ops after the cut and ends with the
//! scene of a peer that replayed everything, also after undo/redo reaching into the base and
//! after a second snapshot taken from a joined peer; corrupt and hostile snapshots are refused.

use super::*;
use crate::identity::Keypair;
use crate::lease::Mark;
use crate::log::InsertError;
use crate::log::tests::{TLog, deliver_all, key, set, workload};
use crate::materialize::test_scene::TestScene;
use crate::payload::test_payload::TestPayload;
use crate::pending::Origin;
use crate::sync::state::{Event, SyncConfig, SyncState};

type TScene = Materialized<TestPayload, TestScene>;
type TSnapshot = Snapshot<TestPayload>;

/// One side of an in-memory connection, with its scene kept in step by sync events.
struct Side {
    log: TLog,
    scene: TScene,
    sync: SyncState<TestPayload>,
    /// What was last asked of the remote.
    wanted: Option<crate::causal::VersionVector>,
}

impl Side {
    fn new(log: TLog, scene: TScene, me: &Keypair, origin: u64) -> Self {
        let config = SyncConfig {
            session_id: [4; 16],
            local: me.peer_id(),
            origin: Origin(origin),
        };
        Self {
            sync: SyncState::new(Timestamp(0), config),
            wanted: None,
            log,
            scene,
        }
    }

    fn drain(&mut self) {
        while let Some(event) = self.sync.poll_event() {
            if let Event::Delivered(ins) = event {
                self.scene.apply_insertion(&self.log, &ins);
            }
        }
    }

    fn author(&mut self, key: &Keypair, now: u64, payload: TestPayload) -> OpId {
        let (op, ins) = self.log.author(key, Timestamp(now), payload).unwrap();
        self.scene.apply_insertion(&self.log, &ins);
        op.id()
    }
}

/// Moves messages both ways, advancing virtual time 1 ms a round, until nothing moves.
fn pump(a: &mut Side, b: &mut Side, now: &mut u64) {
    for _ in 0..100_000 {
        let mut moved = false;
        while let Some(bytes) = a.sync.poll_transmit(Timestamp(*now), &a.log) {
            b.sync.handle_input(Timestamp(*now), &bytes, &mut b.log);
            moved = true;
        }
        while let Some(bytes) = b.sync.poll_transmit(Timestamp(*now), &b.log) {
            a.sync.handle_input(Timestamp(*now), &bytes, &mut a.log);
            moved = true;
        }
        a.drain();
        b.drain();
        // A lone connection asks its remote for everything it lacks (a `Peer` would choose
        // among its connections).
        for side in [&mut *a, &mut *b] {
            let lacking = side.sync.lacking(&side.log);
            if !lacking.is_empty() && side.wanted.as_ref() != Some(&lacking) {
                side.sync.want(lacking.clone(), &side.log);
                side.wanted = Some(lacking);
                moved = true;
            }
        }
        *now += 1000;
        let done = a.log.version_vector() == b.log.version_vector();
        if !moved && done {
            return;
        }
    }
    panic!("sync did not quiesce");
}

fn full(ops_log: &TLog) -> TScene {
    TScene::fold(ops_log).unwrap()
}

#[test]
fn joined_peer_matches_a_full_replay_and_follows_later_ops() {
    let ops = workload(21, 3, 700);
    let mut a_log = deliver_all(&ops);
    // Make every author's latest op recent, so the stable cut is near the end.
    for i in 0..3 {
        a_log
            .author(
                &key(i),
                Timestamp(1_000_000),
                TestPayload::Chat("sync".into()),
            )
            .unwrap();
    }
    let cut = a_log.stable_lamport();
    assert!(
        matches!(
            TSnapshot::capture::<TestScene>(&a_log, cut + 1),
            Err(CaptureError::Cut(CutError::NotStable { .. }))
        ),
        "a cut above the stable time is refused"
    );
    let snapshot = TSnapshot::capture::<TestScene>(&a_log, cut).unwrap();
    let bytes = snapshot.encode().unwrap();
    let decoded = TSnapshot::decode(&bytes).unwrap();
    assert_eq!(decoded.encode().unwrap(), bytes, "canonical encoding");
    assert!(decoded.n_ops() > 600, "{}", decoded.n_ops());
    let (b_log, b_scene) = decoded.join::<TestScene>(PendingLimits::default()).unwrap();
    assert_eq!(b_log.len(), decoded_len(&bytes));
    assert!(b_log.n_held() == 0);

    let (ka, kb) = (key(0), Keypair::from_seed([77; 32]));
    let a_scene = full(&a_log);
    let mut a = Side::new(a_log, a_scene, &ka, 1);
    let mut b = Side::new(b_log, b_scene, &kb, 2);
    let mut now = 2_000_000;
    pump(&mut a, &mut b, &mut now);
    assert_eq!(b.log.len(), a.log.len());
    assert!(
        b.log.n_held() < a.log.len() / 10,
        "only ops after the cut travel"
    );
    assert_eq!(b.scene.scene_hash(), full(&a.log).scene_hash());
    assert_eq!(b.scene.scene_hash(), a.scene.scene_hash());

    // A undoes, then redoes, its oldest effective edit, far inside the base.
    let oldest = a
        .log
        .entries()
        .find(|e| {
            e.active
                && e.op.author() == ka.peer_id()
                && matches!(e.op.payload(), TestPayload::Set { .. })
        })
        .map(|e| e.op.id())
        .unwrap();
    now += 10_000_000;
    let undo = a.author(&ka, now, TestPayload::Undo(oldest));
    assert_eq!(a.log.mark(&undo), Some(Mark::Effective));
    b.author(&kb, now, set(9, "from b"));
    pump(&mut a, &mut b, &mut now);
    assert!(!b.log.is_active(&oldest));
    assert_eq!(b.scene.scene_hash(), full(&a.log).scene_hash());
    assert_eq!(a.scene.scene_hash(), b.scene.scene_hash());
    a.author(&ka, now, TestPayload::Redo(oldest));
    pump(&mut a, &mut b, &mut now);
    assert!(b.log.is_active(&oldest));
    assert_eq!(b.scene.scene_hash(), full(&a.log).scene_hash());
    // From scratch, the joined log folds to the same scene too.
    assert_eq!(full(&b.log).scene_hash(), b.scene.scene_hash());

    // A third peer joins from a snapshot of the joined peer, at a later cut.
    b.author(&kb, now, TestPayload::Chat("b".into()));
    a.author(&ka, now, TestPayload::Chat("a".into()));
    pump(&mut a, &mut b, &mut now);
    let cut2 = b.log.stable_lamport();
    assert!(cut2 > cut);
    let again = TSnapshot::capture::<TestScene>(&b.log, cut2).unwrap();
    let (c_log, c_scene) = TSnapshot::decode(&again.encode().unwrap())
        .unwrap()
        .join::<TestScene>(PendingLimits::default())
        .unwrap();
    let kc = Keypair::from_seed([78; 32]);
    let mut c = Side::new(c_log, c_scene, &kc, 3);
    let mut a2 = Side::new(a.log.clone(), full(&a.log), &ka, 4);
    pump(&mut a2, &mut c, &mut now);
    assert_eq!(c.scene.scene_hash(), full(&a.log).scene_hash());
}

fn decoded_len(bytes: &[u8]) -> usize {
    TSnapshot::decode(bytes).unwrap().n_ops()
}

#[test]
fn an_unknown_author_before_the_cut_is_refused() {
    let ops = workload(4, 2, 60);
    let log = deliver_all(&ops);
    let cut = log.stable_lamport();
    let snapshot = TSnapshot::capture::<TestScene>(&log, cut).unwrap();
    let mut joined = snapshot.into_log(PendingLimits::default());
    // A stranger authored offline at Lamport time 1, before ever syncing.
    let mut stranger = TLog::default();
    let (early, _) = stranger
        .author(&key(9), Timestamp(1), set(1, "early"))
        .unwrap();
    assert_eq!(
        joined.insert(Timestamp(0), early, Origin(1)),
        Err(InsertError::BeforeBase {
            lamport: 1,
            cut_lamport: cut
        })
    );
    // A local op lands after the cut.
    let (own, _) = joined
        .author(&key(8), Timestamp(5), set(1, "mine"))
        .unwrap();
    assert!(own.lamport() > cut);
    // Ops inside the base are duplicates, not refusals.
    let ins = joined
        .insert(Timestamp(0), ops[0].clone(), Origin(1))
        .unwrap();
    assert!(ins.duplicate);
}

#[test]
fn corrupt_truncated_or_hostile_snapshots_are_refused() {
    let log = deliver_all(&workload(6, 3, 80));
    let snapshot = TSnapshot::capture::<TestScene>(&log, log.stable_lamport()).unwrap();
    let bytes = snapshot.encode().unwrap();
    for i in (0..bytes.len()).step_by(7) {
        let mut bad = bytes.clone();
        bad[i] ^= 0x40;
        assert!(TSnapshot::decode(&bad).is_err(), "flip at {i}");
    }
    for cut in (0..bytes.len()).step_by(5) {
        assert!(TSnapshot::decode(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    // Consistent checksum, inconsistent content: a cut below the last op of the author that
    // defined it.
    let mut body = bytes[..bytes.len() - SNAPSHOT_CHECKSUM_BYTES].to_vec();
    let at = SNAPSHOT_MAGIC.len() + 1;
    assert!((1..0x80).contains(&body[at]), "a one-byte cut");
    body[at] -= 1;
    body.extend_from_slice(blake3::hash(&body).as_bytes());
    assert!(TSnapshot::decode(&body).is_err());
    assert!(TSnapshot::decode(&vec![0; MAX_SNAPSHOT_BYTES + 1]).is_err());
}

/// Issue 17: a snapshot could name at most 4,096 authors, fewer than a log holds; one of a
/// log with more did not decode.
#[test]
fn a_snapshot_holds_more_authors_than_a_version_vector_message_names() {
    let log = crate::sync::state::tests::log_of_many_authors(5_000);
    let snapshot = TSnapshot::capture::<TestScene>(&log, log.stable_lamport()).unwrap();
    let bytes = snapshot.encode().unwrap();
    let decoded = TSnapshot::decode(&bytes).unwrap();
    assert_eq!(&decoded.version_vector(), log.version_vector());
    assert_eq!(decoded.n_ops(), 5_000);
    assert_eq!(decoded.encode().unwrap(), bytes, "canonical encoding");
    // A count of authors the bytes cannot hold is refused before anything is allocated.
    let mut body = SNAPSHOT_MAGIC.to_vec();
    body.push(SNAPSHOT_FORMAT_VERSION);
    body.extend_from_slice(&[1, 1]);
    put_varint(&mut body, MAX_SNAPSHOT_AUTHORS as u64);
    body.extend_from_slice(blake3::hash(&body).as_bytes());
    assert!(matches!(
        TSnapshot::decode(&body),
        Err(DecodeError::OverLimit {
            what: "author count",
            limit: 0,
            ..
        })
    ));
}

/// A member leaps Lamport time past 2^32 before the cut; the honest ops after the cut, whose
/// dependencies lie inside the base, are accepted by the joined log as by a full one, and an
/// op leaping again from there is refused by both.
#[test]
fn ops_after_a_lamport_leap_before_the_cut_get_the_verdicts_of_a_full_log() {
    use crate::log::MAX_LAMPORT_JUMP;
    use crate::log::tests::signed;
    let (honest, mallory) = (key(0), key(9));
    let mut full = TLog::default();
    let (first, _) = full.author(&honest, Timestamp(1_000), set(1, "a")).unwrap();
    let leap_lamport = 1 + MAX_LAMPORT_JUMP;
    let chat = |text: &str| TestPayload::Chat(text.into());
    let leap = signed(
        &mallory,
        1,
        leap_lamport,
        1_000,
        vec![first.id()],
        chat("leap"),
    );
    full.insert(Timestamp(1_000), leap.clone(), Origin(1))
        .unwrap();
    let (after, _) = full.author(&honest, Timestamp(2_000), set(1, "b")).unwrap();
    assert_eq!(after.deps(), &[leap.id()]);
    let cut = full.stable_lamport();
    assert_eq!(cut, leap_lamport);
    let snapshot = TSnapshot::capture::<TestScene>(&full, cut).unwrap();
    let bytes = snapshot.encode().unwrap();
    let mut joined = TSnapshot::decode(&bytes)
        .unwrap()
        .into_log(PendingLimits::default());
    let ins = joined.insert(Timestamp(3_000), after.clone(), Origin(1));
    assert_eq!(ins.map(|i| i.delivered.to_vec()), Ok(vec![after.id()]));
    let leap_again = |lamport| signed(&mallory, 2, lamport, 3_000, vec![leap.id()], chat("again"));
    for log in [&mut full, &mut joined] {
        let too_far = leap_lamport + MAX_LAMPORT_JUMP + 1;
        assert!(matches!(
            log.insert(Timestamp(3_000), leap_again(too_far), Origin(1)),
            Err(InsertError::LamportJump { .. })
        ));
        let (own, _) = log.author(&key(1), Timestamp(4_000), set(2, "c")).unwrap();
        assert!(own.lamport() > leap_lamport);
    }
}
