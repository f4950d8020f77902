//! The one place the app reads the clock: the wall clock for op timestamps and the monotonic
//! clock for frame and meshing times. Everything else takes `Now` as an argument.

use std::time::{Instant, SystemTime, UNIX_EPOCH};

use replication::Timestamp;

/// Both clocks, read at one instant.
#[derive(Clone, Copy, Debug)]
pub struct Now {
    /// Wall-clock time for op timestamps (microseconds since the Unix epoch).
    pub wall: Timestamp,
    /// Monotonic time for durations.
    pub instant: Instant,
}

/// Reads the clocks.
#[expect(
    clippy::disallowed_methods,
    reason = "the app's single clock read: ops need wall-clock timestamps, frames and meshing durations"
)]
pub fn now() -> Now {
    let wall = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX));
    Now {
        wall: Timestamp(wall),
        instant: Instant::now(),
    }
}

/// `HH:MM:SS` (UTC) of a timestamp, for chat and history lines.
pub fn time_of_day_utc(t: Timestamp) -> String {
    let secs = t.0 / 1_000_000;
    let day_secs = secs % 86_400;
    format!(
        "{:02}:{:02}:{:02}",
        day_secs / 3600,
        day_secs / 60 % 60,
        day_secs % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_of_day_counts_from_midnight_utc() {
        assert_eq!(time_of_day_utc(Timestamp(0)), "00:00:00");
        // 2026-11-22T13:45:07Z is 1795355107 s after the epoch.
        assert_eq!(
            time_of_day_utc(Timestamp(1_795_355_107 * 1_000_000 + 999_999)),
            "13:45:07"
        );
    }
}
