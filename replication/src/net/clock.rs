//! The one place `replication::net` reads the wall clock; everything else takes `now`.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crate::time::Timestamp;

/// The wall clock as a replication [`Timestamp`] (microseconds since the Unix epoch).
///
/// A clock before the epoch reads as 0; the core's hybrid clock keeps op timestamps monotonic
/// whatever this returns.
#[expect(
    clippy::disallowed_methods,
    reason = "the network adapters pace real sockets: this is their single wall-clock read"
)]
pub(crate) fn wall_clock_now() -> Timestamp {
    let since_epoch = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default();
    Timestamp(u64::try_from(since_epoch.as_micros()).unwrap_or(u64::MAX))
}

/// How long from `now` until `deadline` (zero if it has passed).
pub(crate) fn duration_until(now: Timestamp, deadline: Timestamp) -> Duration {
    Duration::from_micros(deadline.0.saturating_sub(now.0))
}
