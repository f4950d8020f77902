//! Running a closure on a thread with a small stack, so that a test sees unbounded recursion
//! as a crash instead of passing on the large stack of the test harness's threads.
//!
//! A stack overflow aborts the whole test process (Rust's guard page, not a panic), so a test
//! that recurses too deep fails loudly, with "has overflowed its stack" on stderr.

/// The stack the small-stack helpers give: the budget the product's threads that read
/// untrusted input must fit in (`app`'s engine thread runs a debug build's parse, compile and
/// fold on stacks of this order).
pub const SMALL_STACK_BYTES: usize = 256 * 1024;

/// Runs `f` on a thread named `small-stack` with a stack of [`SMALL_STACK_BYTES`], and
/// returns what it returns; a panic in `f` is resumed on the caller's thread.
pub fn on_small_stack<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    on_stack(SMALL_STACK_BYTES, f)
}

/// [`on_small_stack`] with a stack of `stack_bytes`.
pub fn on_stack<T: Send>(stack_bytes: usize, f: impl FnOnce() -> T + Send) -> T {
    std::thread::scope(|scope| {
        let handle = std::thread::Builder::new()
            .name("small-stack".into())
            .stack_size(stack_bytes)
            .spawn_scoped(scope, f)
            .expect("the OS starts a thread");
        match handle.join() {
            Ok(value) => value,
            Err(panic) => std::panic::resume_unwind(panic),
        }
    })
}
