//! Time as data: op timestamps and the hybrid logical clock that makes them monotonic.

/// Most a remote op's timestamp may run ahead of the receiver's wall clock (60 s).
///
/// An op stamped further ahead waits in the pending buffer until the receiver's clock is
/// within this bound of it, and [`HybridClock::observe`] never moves the local clock further
/// than this past the wall clock: a member with a clock in the far future can neither pin
/// every peer's clock nor stop leases from expiring. It also bounds how much a member can
/// shorten honest leases by pushing clocks ahead.
pub const MAX_CLOCK_SKEW_MICROS: u64 = 60 * 1_000_000;

/// A hybrid wall-clock timestamp in microseconds since the Unix epoch.
///
/// The core never reads a clock: the app passes the wall clock in, the simulator a virtual one.
/// Timestamps are shown to users and decide lease expiry; they never decide the linear order.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Timestamp(pub u64);

impl Timestamp {
    /// This timestamp plus `micros`, saturating at the end of time.
    pub fn saturating_add_micros(self, micros: u64) -> Self {
        Self(self.0.saturating_add(micros))
    }
}

/// A hybrid logical clock: never goes backwards, even if the wall clock does, and never
/// stamps an op earlier than an op it has seen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HybridClock {
    last: Timestamp,
}

impl HybridClock {
    /// The timestamp for a new local op, given the caller's wall clock `now`.
    pub fn tick(&mut self, now: Timestamp) -> Timestamp {
        let next = if now > self.last {
            now
        } else {
            self.last.saturating_add_micros(1)
        };
        self.last = next;
        next
    }

    /// Takes note of a timestamp seen on an op, given the caller's wall clock `now`: the clock
    /// follows it, but never further than [`MAX_CLOCK_SKEW_MICROS`] past `now`.
    pub fn observe(&mut self, seen: Timestamp, now: Timestamp) {
        let bound = now.saturating_add_micros(MAX_CLOCK_SKEW_MICROS);
        self.last = self.last.max(seen.min(bound));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_is_monotonic_and_follows_seen_time() {
        let mut c = HybridClock::default();
        assert_eq!(c.tick(Timestamp(10)), Timestamp(10));
        assert_eq!(c.tick(Timestamp(5)), Timestamp(11));
        c.observe(Timestamp(100), Timestamp(50));
        assert_eq!(c.tick(Timestamp(50)), Timestamp(101));
        assert_eq!(c.tick(Timestamp(200)), Timestamp(200));
    }

    #[test]
    fn a_far_future_timestamp_moves_the_clock_only_to_the_skew_bound() {
        let mut c = HybridClock::default();
        let now = Timestamp(1_700_000_000_000_000);
        c.observe(Timestamp(u64::MAX - 1), now);
        let bound = now.saturating_add_micros(MAX_CLOCK_SKEW_MICROS);
        assert_eq!(c.tick(now), bound.saturating_add_micros(1));
        // Once the wall clock passes the bound, the clock follows it again.
        let later = bound.saturating_add_micros(10);
        assert_eq!(c.tick(later), later);
    }
}
