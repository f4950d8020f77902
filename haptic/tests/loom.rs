//! Model checks of the snapshot handoff (`haptic::handoff`) with loom: every interleaving of
//! the app publishing and collecting with the servo taking and retiring, within loom's
//! bounds. Each snapshot's payload lives in a `loom::cell::UnsafeCell` that is written when
//! the snapshot is made and overwritten when it is freed, so loom fails the model if the
//! servo reads a snapshot that was not fully published to it (a torn snapshot) or one being
//! freed at the same time (a use after free); a loom thread-local marks the servo thread,
//! and freeing a snapshot there fails; loom also fails a model that leaks one.
//!
//! Built only with `--cfg loom` (the handoff then uses loom's atomics through
//! `haptic::sync`); the command is in ARCHITECTURE.md:
//!
//! ```text
//! RUSTFLAGS="--cfg loom" CARGO_TARGET_DIR=/work/target-loom \
//!     cargo test -p haptic --test loom --release
//! ```
#![cfg(loom)]
#![allow(
    clippy::unwrap_used,
    reason = "test helpers outside #[test] fns unwrap"
)]

use std::cell::Cell;
use std::sync::atomic::AtomicBool;

use haptic::handoff::{self, Publisher, RETIRED_RING_LEN, Receiver};
use loom::cell::UnsafeCell;
use loom::sync::Arc;
use loom::sync::atomic::{AtomicUsize, Ordering};

loom::thread_local! {
    static ON_SERVO: Cell<bool> = Cell::new(false);
}

/// Set (across all interleavings) when the servo found the retired ring full.
static SAW_FULL_RING: AtomicBool = AtomicBool::new(false);

/// A scene snapshot as far as the handoff can tell: a generation and a payload.
struct Snapshot {
    generation: u64,
    payload: UnsafeCell<[u64; 2]>,
    live: Arc<AtomicUsize>,
}

impl Snapshot {
    fn new(generation: u64, live: &Arc<AtomicUsize>) -> Box<Snapshot> {
        live.fetch_add(1, Ordering::Relaxed);
        Box::new(Snapshot {
            generation,
            payload: UnsafeCell::new([generation; 2]),
            live: Arc::clone(live),
        })
    }

    #[expect(unsafe_code, reason = "loom's UnsafeCell hands out raw pointers")]
    fn read(&self) -> [u64; 2] {
        // SAFETY: the handoff gives a snapshot one owner at a time; loom checks exactly that
        // this read is ordered after the write that made the payload and before the free.
        self.payload.with(|p| unsafe { *p })
    }
}

impl Drop for Snapshot {
    #[expect(unsafe_code, reason = "loom's UnsafeCell hands out raw pointers")]
    fn drop(&mut self) {
        assert!(
            !ON_SERVO.with(Cell::get),
            "snapshot {} freed on the servo thread",
            self.generation
        );
        // SAFETY: `&mut self`: nothing else holds the snapshot. The write lets loom see a
        // read on another thread that is not ordered before this free.
        self.payload.with_mut(|p| unsafe { *p = [u64::MAX, 0] });
        self.live.fetch_sub(1, Ordering::Relaxed);
    }
}

/// What the servo thread ends with: its receiver, the snapshot it renders, one it could not
/// retire yet, and how many ticks saw a snapshot.
type ServoEnd = (
    Receiver<Snapshot>,
    Option<Box<Snapshot>>,
    Option<Box<Snapshot>>,
    usize,
);

/// `n_ticks` ticks of the servo's handoff polling (as `Servo::step` does it), reading the
/// current snapshot every tick.
fn servo_ticks(mut receiver: Receiver<Snapshot>, n_ticks: usize) -> ServoEnd {
    ON_SERVO.with(|on| on.set(true));
    let mut current: Option<Box<Snapshot>> = None;
    let mut retiring: Option<Box<Snapshot>> = None;
    let mut n_seen = 0;
    let mut last_generation = 0;
    for _ in 0..n_ticks {
        if let Some(old) = retiring.take() {
            retiring = receiver.retire(old).err();
        }
        if retiring.is_none()
            && let Some(next) = receiver.take()
            && let Some(old) = current.replace(next)
        {
            retiring = receiver.retire(old).err();
        }
        if retiring.is_some() {
            SAW_FULL_RING.store(true, std::sync::atomic::Ordering::Relaxed);
        }
        if let Some(snapshot) = &current {
            let generation = snapshot.generation;
            assert_eq!(snapshot.read(), [generation; 2], "a complete snapshot");
            assert!(
                generation > 0 && generation >= last_generation,
                "newest first"
            );
            last_generation = generation;
            n_seen += 1;
        }
    }
    ON_SERVO.with(|on| on.set(false));
    (receiver, current, retiring, n_seen)
}

fn spawn_servo(receiver: Receiver<Snapshot>, n_ticks: usize) -> loom::thread::JoinHandle<ServoEnd> {
    loom::thread::Builder::new()
        .name("loom-servo".into())
        .spawn(move || servo_ticks(receiver, n_ticks))
        .unwrap()
}

/// The app's side after the servo stopped: free what is left; nothing may stay alive.
fn finish(publisher: Publisher<Snapshot>, end: ServoEnd, live: &Arc<AtomicUsize>) {
    let (receiver, current, retiring, _) = end;
    drop((current, retiring));
    publisher.collect_retired();
    drop((publisher, receiver));
    assert_eq!(live.load(Ordering::Relaxed), 0, "every snapshot freed once");
}

#[test]
fn publish_take_retire_and_collect_race() {
    loom::model(|| {
        let live = Arc::new(AtomicUsize::new(0));
        let (publisher, receiver) = handoff::channel::<Snapshot>();
        let servo = spawn_servo(receiver, 3);
        for generation in 1..=3 {
            publisher.publish(Snapshot::new(generation, &live));
            publisher.collect_retired();
        }
        finish(publisher, servo.join().unwrap(), &live);
    });
}

#[test]
fn a_full_ring_keeps_the_old_snapshot_on_the_servo_until_the_app_collects() {
    let n_snapshots = RETIRED_RING_LEN as u64 + 2;
    loom::model(move || {
        let live = Arc::new(AtomicUsize::new(0));
        let (publisher, receiver) = handoff::channel::<Snapshot>();
        let servo = spawn_servo(receiver, n_snapshots as usize + 2);
        for generation in 1..=n_snapshots {
            publisher.publish(Snapshot::new(generation, &live));
        }
        publisher.collect_retired();
        finish(publisher, servo.join().unwrap(), &live);
    });
    assert!(
        SAW_FULL_RING.load(std::sync::atomic::Ordering::Relaxed),
        "some interleaving filled the ring"
    );
}

#[test]
fn the_app_may_drop_its_end_while_the_servo_runs() {
    loom::model(|| {
        let live = Arc::new(AtomicUsize::new(0));
        let (publisher, receiver) = handoff::channel::<Snapshot>();
        let servo = spawn_servo(receiver, 2);
        publisher.publish(Snapshot::new(1, &live));
        publisher.publish(Snapshot::new(2, &live));
        drop(publisher);
        let (receiver, current, retiring, _) = servo.join().unwrap();
        // The servo's end is now the last: dropping it (here, off the servo) frees the rest.
        drop((current, retiring, receiver));
        assert_eq!(live.load(Ordering::Relaxed), 0, "every snapshot freed once");
    });
}
