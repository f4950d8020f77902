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

/// The scene's time, which motions, fields and time-dependent shapes read: it runs with the
/// monotonic clock while playing and stands still while paused. Instants are arguments.
#[derive(Clone, Copy, Debug)]
pub struct SceneClock {
    /// Seconds of scene time at `since`.
    at_since_secs: f64,
    since: Instant,
    playing: bool,
}

impl SceneClock {
    /// Scene time 0 at `now`, playing.
    pub fn new(now: Instant) -> SceneClock {
        SceneClock {
            at_since_secs: 0.0,
            since: now,
            playing: true,
        }
    }

    /// The scene time at `now`, seconds.
    pub fn secs(&self, now: Instant) -> f64 {
        if self.playing {
            self.at_since_secs + now.saturating_duration_since(self.since).as_secs_f64()
        } else {
            self.at_since_secs
        }
    }

    /// Whether time runs.
    pub fn playing(&self) -> bool {
        self.playing
    }

    /// Runs or stops time at `now`, keeping the scene time reached.
    pub fn set_playing(&mut self, playing: bool, now: Instant) {
        self.at_since_secs = self.secs(now);
        self.since = now;
        self.playing = playing;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_time_runs_while_playing_and_holds_while_paused() {
        let start = now().instant;
        let at = |secs: f64| start + std::time::Duration::from_secs_f64(secs);
        let mut clock = SceneClock::new(start);
        assert_eq!(clock.secs(at(1.5)), 1.5);
        clock.set_playing(false, at(2.0));
        assert!(!clock.playing());
        assert_eq!(clock.secs(at(9.0)), 2.0);
        clock.set_playing(true, at(10.0));
        assert_eq!(clock.secs(at(10.25)), 2.25);
        // An instant before the last change (a stale frame) reads the time of the change.
        assert_eq!(clock.secs(at(5.0)), 2.0);
    }

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
