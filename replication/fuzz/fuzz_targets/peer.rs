//! Drives a whole `Peer` with structured scripts read from the fuzzer's bytes: hostile remotes
//! on several connections (hellos as anyone, made-up haves and wants, floods of ops signed by
//! hostile keys with any counters, times and dependencies, garbage), time passing, and a local
//! user authoring meanwhile. The script and its invariants live in
//! `replication/tests/peer_support/mod.rs`, which CI also runs under proptest.
#![no_main]

#[path = "../../tests/peer_support/mod.rs"]
mod peer_support;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    peer_support::run(data);
});
