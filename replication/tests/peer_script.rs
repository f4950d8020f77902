//! A whole peer under scripted hostile remotes (see `peer_support/mod.rs`): random scripts, and
//! the fuzz corpus's findings, never panic it, never lose its user's ops and never leave it
//! producing output without end.

mod peer_support;

use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn any_script_leaves_the_peer_whole(data in proptest::collection::vec(any::<u8>(), 0..3000)) {
        peer_support::run(&data);
    }
}

/// A script that connects, says hello as a hostile key, floods ops with wild counters and
/// times, authors locally and lets time pass, repeated: it reaches every kind of step.
#[test]
fn a_long_mixed_script_runs_every_step() {
    let data: Vec<u8> = (0..20_000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    let stats = peer_support::run(&data);
    // The script must reach the peer's every path: hellos accepted, hostile ops inserted and
    // refused, messages sent back, the user's own ops authored.
    assert!(
        stats.connected > 0
            && stats.delivered > 0
            && stats.rejected > 0
            && stats.sent > 0
            && stats.authored > 0,
        "{stats:?}"
    );
}
