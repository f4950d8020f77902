//! The process's compile cache holds at most `MAX_CACHED_BYTES`, measured on the heap: a
//! stream of long distinct formulas (64 KiB texts that compile to a few instructions, which
//! a bound on instructions alone let pile up) keeps the heap within that bound.
//!
//! Its own test binary: the cache is one per process, and the heap is measured whole.

use model::object::compiled::{self, MAX_CACHED_BYTES, MAX_CACHED_TAPES};
use model::object::{Formula, Geometry, Object, ObjectData};
use testkit::alloc::{CountingAlloc, live_bytes};

#[global_allocator]
static ALLOC: CountingAlloc = CountingAlloc;

#[test]
fn long_distinct_formulas_keep_the_cache_within_its_bytes() {
    let comment = "/* ".to_string() + &"padding ".repeat(7_500) + "*/";
    let text = |i: usize| format!("{i}.5 - x^2 - y^2 - z^2 {comment}");
    assert!(text(0).len() > 56 * 1024 && text(0).len() <= fdsl::limits::MAX_SOURCE_BYTES);
    // More entries than the bytes allow, fewer than the tape count does.
    let n = 3 * MAX_CACHED_BYTES / (2 * text(0).len());
    assert!(n < MAX_CACHED_TAPES);
    compiled::clear();
    let before = live_bytes();
    for i in 0..n {
        let object = Object::new(ObjectData {
            geometry: Some(Geometry::implicit(Formula::new(text(i)).unwrap())),
            ..ObjectData::default()
        })
        .unwrap();
        drop(object);
    }
    let held = live_bytes().saturating_sub(before);
    let (n_tapes, estimate) = compiled::cached();
    assert!(n_tapes < n, "nothing was evicted: {n_tapes} tapes");
    assert!(estimate <= MAX_CACHED_BYTES, "{estimate} bytes estimated");
    // The estimate is honest: what the process holds after the stream is what the cache
    // holds, within a margin for the allocator's own bookkeeping of other things.
    assert!(
        held <= MAX_CACHED_BYTES + MAX_CACHED_BYTES / 8,
        "the heap grew by {held} bytes for a cache of at most {MAX_CACHED_BYTES}"
    );
    assert!(
        held <= estimate + estimate / 4,
        "the heap grew by {held} bytes, the cache estimates {estimate}"
    );
    compiled::clear();
}
