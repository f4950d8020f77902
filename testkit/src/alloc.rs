//! A counting global allocator: [`System`]'s allocations, counted on the side.
//!
//! A test or benchmark binary installs it with
//! `#[global_allocator] static ALLOC: testkit::alloc::CountingAlloc = CountingAlloc;`, then
//! asks [`allocations_in`] how many allocator calls a closure made on this thread (calls on
//! other threads, such as tests running in parallel, are not counted), or [`live_bytes`] how
//! many heap bytes the whole process holds.
//!
//! The simulator keeps its own allocator (`simulator::memory`): it attributes live bytes to
//! the simulated peer running on each thread, which needs a header in every block.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The counting allocator (see the module documentation).
#[derive(Debug, Clone, Copy, Default)]
pub struct CountingAlloc;

static LIVE_BYTES: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    // Const-initialised and without destructors, so the allocator may read them at any time,
    // thread teardown included.
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static N_CALLS: Cell<usize> = const { Cell::new(0) };
}

fn count_call() {
    if ARMED.with(Cell::get) {
        N_CALLS.with(|n| n.set(n.get() + 1));
    }
}

#[expect(
    unsafe_code,
    reason = "a global allocator is an unsafe trait; it only counts"
)]
// SAFETY: every method forwards to `System` with the caller's arguments unchanged, so the
// allocator contract is `System`'s; the counters are arithmetic on the side.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count_call();
        LIVE_BYTES.fetch_add(layout.size(), Ordering::Relaxed);
        // SAFETY: forwarded unchanged (see the impl).
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        count_call();
        LIVE_BYTES.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: forwarded unchanged (see the impl).
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count_call();
        LIVE_BYTES.fetch_add(new_size, Ordering::Relaxed);
        LIVE_BYTES.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: forwarded unchanged (see the impl).
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Runs `f` and returns how many allocator calls (allocations, frees, reallocations) it made
/// on this thread. Zero unless [`CountingAlloc`] is the global allocator.
pub fn allocations_in(f: impl FnOnce()) -> usize {
    let before = N_CALLS.with(Cell::get);
    ARMED.with(|a| a.set(true));
    f();
    ARMED.with(|a| a.set(false));
    N_CALLS.with(Cell::get) - before
}

/// Heap bytes the process holds now (allocated minus freed through [`CountingAlloc`]).
pub fn live_bytes() -> usize {
    LIVE_BYTES.load(Ordering::Relaxed)
}
