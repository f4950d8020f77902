//! Heap bytes held per peer, measured by a counting global allocator.
//!
//! [`CountingAlloc`] wraps the system allocator and puts a small header before every block
//! naming the *slot* (one per simulated peer, 0 for the harness) that was current on this
//! thread when the block was allocated; freeing subtracts from that slot, whoever frees it.
//! The simulation makes a peer's slot current around every call into that peer and into its
//! scene ([`with_slot`]), so a slot's live bytes are what the peer's calls allocated and still
//! hold: its log (ops, order, marks, checkpoints), pending buffer, sync states, queued events
//! and its incrementally folded scene. Message bytes put on the simulated network are copied
//! into harness memory, so traffic in flight is not charged to the sender.
//!
//! It counts only where a binary or test installs it (`#[global_allocator] static A:
//! CountingAlloc = CountingAlloc;`, as `main.rs` and `tests/seeds.rs` do); elsewhere
//! [`installed`] is false and runs report no memory figures. Realloc keeps a block's slot.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicUsize, Ordering};

/// Number of counters; slots are handed out round-robin, so this bounds how many peers of
/// concurrent runs are told apart (slot 0 is the harness).
pub const N_SLOTS: usize = 1 << 14;
/// Bytes of header before each block (it keeps the block's slot).
const HEADER_BYTES: usize = 16;

static LIVE_BYTES: [AtomicI64; N_SLOTS] = [const { AtomicI64::new(0) }; N_SLOTS];
static INSTALLED: AtomicBool = AtomicBool::new(false);
static NEXT_SLOT: AtomicUsize = AtomicUsize::new(1);

thread_local! {
    static CURRENT_SLOT: Cell<usize> = const { Cell::new(0) };
}

/// The counting allocator (see the module documentation).
#[derive(Debug, Clone, Copy, Default)]
pub struct CountingAlloc;

/// The block actually allocated for `layout`, and where the caller's part starts in it.
fn outer(layout: Layout) -> Option<(Layout, usize)> {
    let align = layout.align().max(HEADER_BYTES);
    let size = layout.size().checked_add(align)?;
    Some((Layout::from_size_align(size, align).ok()?, align))
}

fn current_slot() -> usize {
    CURRENT_SLOT.try_with(Cell::get).unwrap_or(0) % N_SLOTS
}

fn charge(slot: usize, bytes: usize, sign: i64) {
    LIVE_BYTES[slot % N_SLOTS].fetch_add(sign * bytes as i64, Ordering::Relaxed);
}

#[expect(
    unsafe_code,
    reason = "a global allocator is an unsafe trait; it forwards to System with a header"
)]
// SAFETY (for the whole impl): every block handed out is `System`'s block for `outer(layout)`
// offset by `outer(layout).1` bytes, which is at least `HEADER_BYTES` and a multiple of the
// caller's alignment, so the caller's pointer is aligned and the header lies inside the block.
// `dealloc` and `realloc` get the caller's layout back (the `GlobalAlloc` contract) and so
// recompute the same outer layout and offset.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let Some((outer, offset)) = outer(layout) else {
            return std::ptr::null_mut();
        };
        // SAFETY: `outer` has a non-zero size (it includes the header).
        let base = unsafe { System.alloc(outer) };
        if base.is_null() {
            return base;
        }
        // SAFETY: `offset < outer.size()`, so `user` and the 8 bytes before it (the slot word,
        // 8-aligned because `offset` is a multiple of 16) are inside the block.
        let user = unsafe { base.add(offset) };
        let slot = current_slot();
        unsafe { user.sub(8).cast::<u64>().write(slot as u64) };
        charge(slot, layout.size(), 1);
        if !INSTALLED.load(Ordering::Relaxed) {
            INSTALLED.store(true, Ordering::Relaxed);
        }
        user
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        let Some((outer, offset)) = outer(layout) else {
            return;
        };
        // SAFETY: `ptr` came from `alloc`/`realloc` with this layout, so the slot word is
        // 8 bytes before it and the block starts `offset` bytes before it.
        let slot = unsafe { ptr.sub(8).cast::<u64>().read() } as usize;
        charge(slot, layout.size(), -1);
        unsafe { System.dealloc(ptr.sub(offset), outer) };
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let (Some((old_outer, offset)), Some(new_size_outer)) = (
            outer(layout),
            new_size.checked_add(layout.align().max(HEADER_BYTES)),
        ) else {
            return std::ptr::null_mut();
        };
        // SAFETY: as in `dealloc`; `System.realloc` keeps the prefix (the header) and the
        // alignment of `old_outer`, so the offset stays valid in the new block.
        let slot = unsafe { ptr.sub(8).cast::<u64>().read() } as usize;
        let base = unsafe { System.realloc(ptr.sub(offset), old_outer, new_size_outer) };
        if base.is_null() {
            return base;
        }
        charge(slot, new_size, 1);
        charge(slot, layout.size(), -1);
        unsafe { base.add(offset) }
    }
}

/// True once a [`CountingAlloc`] has served an allocation in this process.
pub fn installed() -> bool {
    INSTALLED.load(Ordering::Relaxed)
}

/// `n` fresh slots for one run's peers, as the first slot's number (consecutive, wrapping
/// past [`N_SLOTS`], never 0).
pub fn reserve_slots(n: usize) -> usize {
    let first = NEXT_SLOT.fetch_add(n, Ordering::Relaxed);
    1 + (first - 1) % (N_SLOTS - 1)
}

/// The slot that `first + idx` names (wrapping as [`reserve_slots`] does).
pub fn slot(first: usize, idx: usize) -> usize {
    1 + (first - 1 + idx) % (N_SLOTS - 1)
}

/// Bytes live in `slot` now (allocated under it and not yet freed).
pub fn live_bytes(slot: usize) -> i64 {
    LIVE_BYTES[slot % N_SLOTS].load(Ordering::Relaxed)
}

/// Runs `f` with `slot` current on this thread (restored afterwards, even on panic).
pub fn with_slot<R>(slot: usize, f: impl FnOnce() -> R) -> R {
    struct Restore(usize);
    impl Drop for Restore {
        fn drop(&mut self) {
            let previous = self.0;
            let _ = CURRENT_SLOT.try_with(|c| c.set(previous));
        }
    }
    let previous = CURRENT_SLOT.try_with(|c| c.replace(slot)).unwrap_or(0);
    let _restore = Restore(previous);
    f()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_wrap_and_skip_the_harness() {
        assert_eq!(slot(N_SLOTS - 1, 0), N_SLOTS - 1);
        assert_eq!(slot(N_SLOTS - 1, 1), 1);
        let first = reserve_slots(3);
        assert!((1..N_SLOTS).contains(&first));
        assert_ne!(slot(first, 2), 0);
    }

    #[test]
    fn the_header_layout_keeps_alignment() {
        for (size, align) in [(1, 1), (24, 8), (100, 32), (0, 4096)] {
            let layout = Layout::from_size_align(size, align).unwrap();
            let (outer, offset) = outer(layout).unwrap();
            assert_eq!(offset % align, 0);
            assert!(offset >= HEADER_BYTES);
            assert_eq!(outer.size(), size + offset);
        }
    }
}
