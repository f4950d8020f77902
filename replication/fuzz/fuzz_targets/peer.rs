//! Drives a whole `Peer` with structured scripts read from the fuzzer's bytes: hostile remotes
//! on several connections (hellos as anyone, made-up haves and wants, floods of ops signed by
//! hostile keys with any counters, times and dependencies, garbage), time passing, and a local
//! user authoring meanwhile. The script and its invariants live in
//! `replication/tests/peer_support/mod.rs`, which CI also runs under proptest. Each input
//! runs on a thread with a 256 KiB stack, so that a recursion as deep as the input is a crash.
#![no_main]

#[path = "../../tests/peer_support/mod.rs"]
mod peer_support;

use libfuzzer_sys::fuzz_target;
use testkit::stack::on_small_stack;

fuzz_target!(|data: &[u8]| {
    on_small_stack(|| peer_support::run(data));
});
