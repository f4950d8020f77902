//! Lock-free handoff of owned values (scene snapshots, rig settings) from the app to the servo
//! thread, with retired values returned to the app on a fixed ring so that the servo thread
//! never frees memory.
//!
//! The app [`Publisher::publish`]es a `Box<T>` into a one-slot mailbox (replacing and freeing
//! an unconsumed one on its own thread). The servo [`Receiver::take`]s it and later
//! [`Receiver::retire`]s the previous value into the ring; the app frees retired values in
//! [`Publisher::collect_retired`]. Both sides only swap and compare-exchange pointers: no
//! lock, no allocation on the servo side. When the ring is full, `retire` hands the value
//! back and the servo keeps it until there is room.
//!
//! The atomics come from `crate::sync`: `tests/loom.rs` model-checks this module with loom
//! (`RUSTFLAGS="--cfg loom"`, see ARCHITECTURE.md).

use std::marker::PhantomData;
use std::ptr;
use std::sync::Mutex;

use crate::sync::{Arc, AtomicPtr, Ordering};

/// Slots in the retired ring: how many values the servo may retire before the app collects.
#[cfg(not(loom))]
pub const RETIRED_RING_LEN: usize = 16;
/// Slots in the retired ring; two under loom, so that the model reaches a full ring and its
/// interleavings stay few enough to enumerate.
#[cfg(loom)]
pub const RETIRED_RING_LEN: usize = 2;

struct Shared<T> {
    incoming: AtomicPtr<T>,
    retired: [AtomicPtr<T>; RETIRED_RING_LEN],
    /// Owns `T`s and is `Send + Sync` exactly when `T: Send`, like a `Mutex<T>`.
    _owns: PhantomData<Mutex<Box<T>>>,
}

impl<T> Shared<T> {
    /// Takes ownership of what a slot held.
    #[expect(
        unsafe_code,
        reason = "turning pointers made by Box::into_raw back into boxes"
    )]
    fn owned(raw: *mut T) -> Option<Box<T>> {
        // SAFETY: every non-null pointer stored in a slot came from `Box::into_raw` and is
        // owned by the slot; callers got `raw` by swapping it out of its slot (or out of the
        // mailbox), which transfers that ownership to them exactly once.
        (!raw.is_null()).then(|| unsafe { Box::from_raw(raw) })
    }

    fn drain(slot: &AtomicPtr<T>) -> Option<Box<T>> {
        Self::owned(slot.swap(ptr::null_mut(), Ordering::AcqRel))
    }
}

impl<T> Drop for Shared<T> {
    fn drop(&mut self) {
        drop(Self::drain(&self.incoming));
        for slot in &self.retired {
            drop(Self::drain(slot));
        }
    }
}

// Values of `T` move between threads through the slots: `channel` requires `T: Send`, the
// only way to make the two ends.
/// The app's end.
pub struct Publisher<T> {
    shared: Arc<Shared<T>>,
}

/// The servo's end.
pub struct Receiver<T> {
    shared: Arc<Shared<T>>,
}

/// A connected publisher and receiver.
pub fn channel<T: Send>() -> (Publisher<T>, Receiver<T>) {
    let shared = Arc::new(Shared {
        incoming: AtomicPtr::new(ptr::null_mut()),
        retired: std::array::from_fn(|_| AtomicPtr::new(ptr::null_mut())),
        _owns: PhantomData,
    });
    (
        Publisher {
            shared: Arc::clone(&shared),
        },
        Receiver { shared },
    )
}

impl<T: Send> Publisher<T> {
    /// Offers `value` to the servo; an offer it has not taken yet is replaced and freed here.
    pub fn publish(&self, value: Box<T>) {
        let raw = Box::into_raw(value);
        let old = self.shared.incoming.swap(raw, Ordering::AcqRel);
        drop(Shared::owned(old));
    }

    /// Frees the values the servo has retired; returns how many.
    pub fn collect_retired(&self) -> usize {
        self.shared
            .retired
            .iter()
            .filter_map(Shared::drain)
            .map(drop)
            .count()
    }
}

impl<T: Send> Receiver<T> {
    /// The newest published value, if one arrived since the last take.
    pub fn take(&mut self) -> Option<Box<T>> {
        Shared::drain(&self.shared.incoming)
    }

    /// Returns `value` to the app without freeing it here; gives it back when the ring is full.
    ///
    /// Only this receiver fills ring slots (`&mut self`), and the app only empties them. A slot is claimed by compare-exchange from null, so every access to a slot is a
    /// read-modify-write (the app empties slots by swap) and no claim can overwrite a value.
    /// This also keeps loom's model exact: loom mis-orders a plain store that races a swap on
    /// the same atomic (tokio-rs/loom#254), which a load-then-store claim would hit.
    pub fn retire(&mut self, value: Box<T>) -> Result<(), Box<T>> {
        let raw = Box::into_raw(value);
        for slot in &self.shared.retired {
            if slot
                .compare_exchange(ptr::null_mut(), raw, Ordering::AcqRel, Ordering::Relaxed)
                .is_ok()
            {
                return Ok(());
            }
        }
        // Every slot is full: `raw` was never stored, so it is still ours alone.
        Err(Shared::owned(raw).expect("Box::into_raw never gives null"))
    }

    /// True when a retire would succeed now.
    pub fn has_room(&self) -> bool {
        self.shared
            .retired
            .iter()
            .any(|slot| slot.load(Ordering::Acquire).is_null())
    }
}

// Plain threads: under `--cfg loom` the atomics only work inside `loom::model`.
#[cfg(all(test, not(loom)))]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    /// Counts live values and records which thread dropped them.
    struct Tracked {
        live: Arc<AtomicUsize>,
    }

    impl Drop for Tracked {
        fn drop(&mut self) {
            self.live.fetch_sub(1, Ordering::SeqCst);
        }
    }

    fn tracked(live: &Arc<AtomicUsize>) -> Box<Tracked> {
        live.fetch_add(1, Ordering::SeqCst);
        Box::new(Tracked {
            live: Arc::clone(live),
        })
    }

    #[test]
    fn values_flow_and_are_freed_by_the_app_only() {
        let live = Arc::new(AtomicUsize::new(0));
        let (publisher, mut receiver) = channel::<Tracked>();
        assert!(receiver.take().is_none());
        publisher.publish(tracked(&live));
        // An untaken offer is replaced and freed by the publisher.
        publisher.publish(tracked(&live));
        assert_eq!(live.load(Ordering::SeqCst), 1);
        let mut current = receiver.take().unwrap();
        for _ in 0..RETIRED_RING_LEN {
            publisher.publish(tracked(&live));
            let next = receiver.take().unwrap();
            let old = std::mem::replace(&mut current, next);
            assert!(receiver.retire(old).is_ok());
        }
        assert_eq!(live.load(Ordering::SeqCst), RETIRED_RING_LEN + 1);
        // Ring full: the value comes back, nothing is freed on the servo side.
        assert!(!receiver.has_room());
        let back = receiver.retire(current).unwrap_err();
        assert_eq!(live.load(Ordering::SeqCst), RETIRED_RING_LEN + 1);
        assert_eq!(publisher.collect_retired(), RETIRED_RING_LEN);
        assert_eq!(live.load(Ordering::SeqCst), 1);
        assert!(receiver.retire(back).is_ok());
        drop(publisher);
        drop(receiver);
        assert_eq!(
            live.load(Ordering::SeqCst),
            0,
            "the last end frees what is left"
        );
    }

    #[test]
    fn concurrent_publish_take_retire_loses_nothing() {
        let live = Arc::new(AtomicUsize::new(0));
        let (publisher, mut receiver) = channel::<Tracked>();
        let n_published = 2_000;
        let servo = std::thread::Builder::new()
            .name("handoff-test-servo".into())
            .spawn(move || {
                let mut current: Option<Box<Tracked>> = None;
                let mut pending: Option<Box<Tracked>> = None;
                let mut n_taken = 0;
                for _ in 0..200_000 {
                    if let Some(p) = pending.take() {
                        pending = receiver.retire(p).err();
                    }
                    if pending.is_none()
                        && let Some(next) = receiver.take()
                    {
                        n_taken += 1;
                        if let Some(old) = current.replace(next) {
                            pending = receiver.retire(old).err();
                        }
                    }
                    std::hint::spin_loop();
                }
                (current, pending, n_taken, receiver)
            })
            .unwrap();
        let mut n_collected = 0;
        for _ in 0..n_published {
            publisher.publish(tracked(&live));
            n_collected += publisher.collect_retired();
        }
        let (current, pending, n_taken, receiver) = servo.join().unwrap();
        n_collected += publisher.collect_retired();
        // Every value taken is current, pending, or was retired and collected by the app.
        let held = usize::from(current.is_some()) + usize::from(pending.is_some());
        assert!(n_taken >= 1);
        assert_eq!(n_taken, n_collected + held);
        drop((current, pending, receiver, publisher));
        assert_eq!(live.load(Ordering::SeqCst), 0);
    }
}
