//! Time as data: op timestamps and the hybrid logical clock that makes them monotonic.

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

    /// Takes note of a timestamp seen on a remote op.
    pub fn observe(&mut self, seen: Timestamp) {
        self.last = self.last.max(seen);
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
        c.observe(Timestamp(100));
        assert_eq!(c.tick(Timestamp(50)), Timestamp(101));
        assert_eq!(c.tick(Timestamp(200)), Timestamp(200));
    }
}
