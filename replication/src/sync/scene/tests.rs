//! Tests of the scene check: object hashes in parts, what differs, and the bounds on what a
//! remote's claims cost.

use super::*;

fn hashes(objects: &[(u64, u8)], rest: u8) -> ObjectHashes {
    ObjectHashes::new(
        objects
            .iter()
            .map(|(o, h)| (ObjectId(*o), [*h; DIGEST_BYTES])),
        [rest; DIGEST_BYTES],
    )
}

fn ids(objects: &[ObjectId]) -> Vec<u64> {
    objects.iter().map(|o| o.0).collect()
}

#[test]
fn the_parts_tile_every_id_and_name_each_object_once() {
    let n = 2 * MAX_OBJECT_HASHES + 3;
    let many = ObjectHashes::new(
        (0..n as u64).map(|i| (ObjectId(5 + 3 * i), [1; DIGEST_BYTES])),
        [2; DIGEST_BYTES],
    );
    assert_eq!(many.n_parts(), 3);
    let parts: Vec<_> = (0..many.n_parts()).map(|i| many.part([9; 32], i)).collect();
    assert_eq!(parts[0].from, 0);
    assert_eq!(parts[2].to, u64::MAX);
    for pair in parts.windows(2) {
        assert_eq!(pair[0].to + 1, pair[1].from, "the ranges tile");
    }
    let named: usize = parts.iter().map(|p| p.objects.len()).sum();
    assert_eq!(named, n);
    for part in &parts {
        assert!(part.objects.len() <= MAX_OBJECT_HASHES);
        assert!(
            (part.objects.iter()).all(|(o, _)| (part.from..=part.to).contains(o)),
            "every object inside its part's range"
        );
        // A scene compared with its own parts differs nowhere.
        assert_eq!(many.differing(part), (Vec::new(), false));
        // Every part encodes within the message limit, and decodes to itself.
        let message = Message::ObjectHashes(part.clone());
        assert_eq!(Message::decode(&message.encode()), Ok(message));
    }
    // An empty scene still says so, over every id.
    let empty = ObjectHashes::default();
    assert_eq!(empty.n_parts(), 1);
    let part = empty.part([0; 32], 0);
    assert_eq!((part.from, part.to, part.objects.len()), (0, u64::MAX, 0));
}

#[test]
fn differing_names_changed_missing_and_extra_objects_in_the_range_and_the_rest() {
    let ours = hashes(&[(1, 1), (2, 2), (4, 4), (9, 9)], 0);
    let theirs = hashes(&[(1, 1), (2, 7), (3, 3), (9, 9)], 0);
    let part = theirs.part([0; 32], 0);
    let (differ, rest) = ours.differing(&part);
    assert_eq!(ids(&differ), [2, 3, 4]);
    assert!(!rest);
    // Only the part's range counts: object 4 lies outside 0..=3.
    let mut narrow = part.clone();
    narrow.to = 3;
    narrow.objects.retain(|(o, _)| *o <= 3);
    assert_eq!(ids(&ours.differing(&narrow).0), [2, 3]);
    let other_rest = hashes(&[(1, 1), (2, 2), (4, 4), (9, 9)], 5);
    assert_eq!(
        ours.differing(&other_rest.part([0; 32], 0)),
        (Vec::new(), true)
    );
    // Of an id given twice, the last counts.
    assert_eq!(
        hashes(&[(1, 1), (1, 2)], 0).objects(),
        [(ObjectId(1), [2; 32])]
    );
}

const CUT: SceneCut = SceneCut {
    digest: [3; DIGEST_BYTES],
    n_ops: 10,
};

/// A check whose owner says `hash` at [`CUT`] and answers every mismatch with `objects`.
struct Owned {
    check: SceneCheck,
    objects: Arc<ObjectHashes>,
    events: VecDeque<Event>,
    n_refolded: usize,
    n_rest_refolds: usize,
    n_mismatches: usize,
}

impl Owned {
    fn new(hash: u8, objects: ObjectHashes) -> Self {
        let mut check = SceneCheck::default();
        check.set_local(CUT.with_hash([hash; DIGEST_BYTES]));
        Self {
            check,
            objects: Arc::new(objects),
            events: VecDeque::new(),
            n_refolded: 0,
            n_rest_refolds: 0,
            n_mismatches: 0,
        }
    }

    /// Runs due timeouts, then answers what the check asked, as an owner would.
    fn step(&mut self, now: Timestamp) {
        if self.check.due().is_some_and(|t| t <= now) {
            self.check.timeout(now, &mut self.events);
        }
        while let Some(event) = self.events.pop_front() {
            match event {
                Event::Scene(SceneEvent::Mismatch(m)) => {
                    assert_eq!(m.ours.cut, m.theirs.cut, "compared at one cut only");
                    self.n_mismatches += 1;
                    let objects = Arc::clone(&self.objects);
                    self.check
                        .set_local_objects(CUT.digest, &objects, &mut self.events);
                }
                Event::Scene(SceneEvent::Resync(r)) => {
                    self.n_refolded += r.objects.len();
                    self.n_rest_refolds += usize::from(r.rest);
                }
                other => panic!("{other:?}"),
            }
        }
    }
}

#[test]
fn equal_hashes_at_one_cut_agree_and_hashes_at_other_cuts_are_not_compared() {
    let mut a = Owned::new(1, hashes(&[(1, 1)], 0));
    let mut events = VecDeque::new();
    a.check
        .on_remote_hash(Timestamp(1), CUT.with_hash([1; 32]), &mut events);
    assert!(events.is_empty());
    assert_eq!(a.check.stats.agrees, Some(true));
    let elsewhere = SceneAt {
        cut: [4; 32],
        n_ops: 10,
        hash: [2; 32],
    };
    a.check.on_remote_hash(Timestamp(2), elsewhere, &mut events);
    assert!(events.is_empty());
    assert_eq!(
        (a.check.stats.n_checks, a.check.stats.n_mismatches),
        (1, 0),
        "another cut is not compared"
    );
    // The hash goes out once per change.
    assert!(a.check.take_hash().is_some());
    assert!(a.check.take_hash().is_none());
}

#[test]
fn a_remote_claiming_mismatches_without_end_costs_a_bounded_refold_budget() {
    let mut ours = Owned::new(1, hashes(&[(1, 1), (2, 2)], 0));
    // Every message claims every object differs: three thousand of them, and another rest.
    let bogus = ObjectHashes::new(
        (0..3_000u64).map(|i| (ObjectId(i), [0xee; DIGEST_BYTES])),
        [0xee; DIGEST_BYTES],
    );
    let parts: Vec<_> = (0..bogus.n_parts())
        .map(|i| bogus.part(CUT.digest, i))
        .collect();
    let duration_micros = 600 * 1_000_000;
    let mut now = 0;
    let mut n_messages = 0u64;
    let mut n_parts_sent = 0;
    while now < duration_micros {
        // A claim every 50 ms: a new hash at our cut, and all the parts.
        let claim = CUT.with_hash([(now % 251) as u8 + 2; DIGEST_BYTES]);
        let mut events = std::mem::take(&mut ours.events);
        ours.check
            .on_remote_hash(Timestamp(now), claim, &mut events);
        for part in &parts {
            ours.check
                .on_part(Timestamp(now), part.clone(), &mut events);
        }
        ours.events = events;
        n_messages += 1 + parts.len() as u64;
        ours.step(Timestamp(now));
        while ours.check.next_part().is_some() {
            n_parts_sent += 1;
        }
        now += 50_000;
    }
    // Windows of 1, 2, 4, ... then 60 s: 7 to reach the longest, one a minute after.
    let max_windows = 7 + (duration_micros / MAX_RESYNC_WAIT_MICROS) as usize;
    assert!(
        ours.n_mismatches <= max_windows,
        "{} mismatches acted on",
        ours.n_mismatches
    );
    assert!(ours.n_refolded <= max_windows * MAX_RESYNC_OBJECTS);
    // Our hashes (one part) go out once a window, and once more on a try of the remote's
    // within it.
    assert!(n_parts_sent <= 2 * max_windows, "{n_parts_sent} parts sent");
    assert!(n_parts_sent > ours.n_mismatches, "the tries are answered");
    assert!(ours.n_rest_refolds <= max_windows);
    assert!(
        ours.n_mismatches >= 2,
        "the check still acts, within its budget"
    );
    let stats = &ours.check.stats;
    assert_eq!(stats.n_resyncs, ours.n_mismatches as u64);
    assert!(stats.n_dropped > n_messages / 2, "{stats:?}");
    assert!(ours.check.held.len() <= MAX_HELD_PARTS);
}

#[test]
fn parts_outside_a_window_or_at_another_cut_are_dropped_and_early_ones_held() {
    let mut ours = Owned::new(1, hashes(&[(1, 1)], 0));
    let theirs = hashes(&[(1, 7)], 0);
    let mut events = VecDeque::new();
    // No mismatch yet: a part is dropped.
    ours.check
        .on_part(Timestamp(0), theirs.part(CUT.digest, 0), &mut events);
    assert_eq!(ours.check.stats.n_dropped, 1);
    ours.check
        .on_remote_hash(Timestamp(0), CUT.with_hash([7; 32]), &mut events);
    assert!(matches!(
        events.pop_front(),
        Some(Event::Scene(SceneEvent::Mismatch(_)))
    ));
    // Before the owner's hashes: held, within the bound; at another cut: dropped.
    for _ in 0..MAX_HELD_PARTS + 2 {
        ours.check
            .on_part(Timestamp(1), theirs.part(CUT.digest, 0), &mut events);
    }
    ours.check
        .on_part(Timestamp(1), theirs.part([8; 32], 0), &mut events);
    assert_eq!(ours.check.held.len(), MAX_HELD_PARTS);
    assert_eq!(ours.check.stats.n_dropped, 4);
    // The owner's hashes come: each held part is compared and names object 1 (a repeated
    // part costs the window's budget again).
    let objects = Arc::clone(&ours.objects);
    ours.check
        .set_local_objects(CUT.digest, &objects, &mut events);
    let resyncs: Vec<_> = events
        .drain(..)
        .filter_map(|e| match e {
            Event::Scene(SceneEvent::Resync(r)) => Some(r),
            _ => None,
        })
        .collect();
    assert_eq!(resyncs.len(), MAX_HELD_PARTS);
    assert!(resyncs.iter().all(|r| ids(&r.objects) == [1] && !r.rest));
    // Our parts go out once in the window.
    assert!(matches!(
        ours.check.next_part(),
        Some(Message::ObjectHashes(_))
    ));
    assert!(ours.check.next_part().is_none());
}
