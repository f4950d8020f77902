//! Connections as QUIC gives them ([`Faults::streams`]): a lost packet is sent again once its
//! sender detects the loss, so loss is delay; a connection delivers its messages in order and
//! never twice; a partition stalls a connection, which the idle timeout closes if the
//! partition outlasts it, and the two ends dial again once it ends.
//!
//! [`Faults::streams`]: crate::config::Faults::streams

use super::{Ev, Simulation, deliver};

/// The product's QUIC idle timeout (`replication::net::tls::IDLE_TIMEOUT_MILLIS`).
pub(crate) const STREAM_IDLE_TIMEOUT_MICROS: u64 = 10_000_000;
/// What a partition stalled on one directed link: when the first message stalled, and the
/// messages with their connection epochs.
pub(super) type Stalled = (u64, Vec<(u64, Vec<u8>)>);

/// Most times one message is lost in a row before it gets through (a longer run is one the
/// idle timeout would end).
const MAX_RETRANSMISSIONS: u32 = 8;

impl Simulation {
    /// The time a sender on the link `from -> to` takes to find a packet lost: 9/8 of the
    /// round trip, as QUIC's time threshold.
    fn loss_detection_micros(&self, from: usize, to: usize) -> u64 {
        let rtt = self.latency_micros[from][to]
            + self.latency_micros[to][from]
            + self.faults.jitter_micros;
        rtt * 9 / 8
    }

    /// Puts an honest message on the connection `from -> to`: stalled while a partition
    /// cuts the link, else sent, after each loss again, and delivered after every message
    /// sent on the connection before it.
    pub(super) fn stream_send(&mut self, from: usize, to: usize, bytes: Vec<u8>) {
        let epoch = self.pair(from, to).epoch;
        if self.blocked.contains_key(&(from, to)) {
            self.stats.n_stalled += 1;
            self.n_in_flight += 1;
            let now = self.now;
            let stalled = self.stalled.entry((from, to)).or_insert((now, Vec::new()));
            stalled.1.push((epoch, bytes));
            return;
        }
        self.stream_transmit(from, to, epoch, bytes, 0);
    }

    /// Sends `bytes` (of connection `epoch`) after `extra` microseconds of waiting.
    fn stream_transmit(&mut self, from: usize, to: usize, epoch: u64, bytes: Vec<u8>, extra: u64) {
        let Some(departs) = self.transmit_slot(from, to, bytes.len()) else {
            self.stats.n_queue_drops += 1;
            return;
        };
        let jitter = self.net.below(self.faults.jitter_micros + 1);
        let mut at = departs + extra + self.latency_micros[from][to] + jitter;
        let mut n_lost = 0;
        while n_lost < MAX_RETRANSMISSIONS && self.net.chance(self.faults.loss_per_mille) {
            at += self.loss_detection_micros(from, to);
            n_lost += 1;
        }
        self.stats.n_retransmitted += u64::from(n_lost);
        // In order within the connection: after the last message it carries.
        let tail = &mut self.stream_tail[from][to];
        if tail.0 == epoch {
            at = at.max(tail.1);
        }
        *tail = (epoch, at);
        self.n_in_flight += 1;
        self.push(at, deliver(from, to, epoch, bytes, None));
    }

    /// A partition cut the links `cut`: each connection it stalls closes at the idle timeout
    /// if the cut still holds then.
    pub(super) fn stream_partition_start(&mut self, cut: &[(usize, usize)]) {
        let at = self.now + STREAM_IDLE_TIMEOUT_MICROS;
        for &(from, to) in cut {
            let epoch = self.pair(from, to).epoch;
            self.push(at, Ev::IdleTimeout { from, to, epoch });
        }
    }

    /// The idle timeout of a stalled connection: closed if its link is still cut.
    pub(super) fn stream_idle_timeout(&mut self, from: usize, to: usize, epoch: u64) {
        let pair = *self.pair(from, to);
        if pair.connected && pair.epoch == epoch && self.blocked.contains_key(&(from, to)) {
            self.disconnect_pair(from, to);
        }
    }

    /// Links that are no longer cut: what stalled on them goes out at the sender's next probe
    /// (every loss detection time since the first stall, doubling each time, as QUIC backs
    /// off), and a connection the idle timeout closed is dialed again.
    pub(super) fn stream_unblocked(&mut self, links: &[(usize, usize)]) {
        for &(from, to) in links {
            if self.blocked.contains_key(&(from, to)) {
                continue;
            }
            let current = self.pair(from, to).epoch;
            let (since, stalled) = self.stalled.remove(&(from, to)).unwrap_or_default();
            let probe = next_probe(since, self.loss_detection_micros(from, to), self.now);
            for (epoch, bytes) in stalled {
                self.n_in_flight -= 1;
                if epoch == current && self.pair(from, to).connected {
                    self.stream_transmit(from, to, epoch, bytes, probe);
                } else {
                    self.stats.n_stale_drops += 1;
                }
            }
            if !self.pair(from, to).connected
                && !self.blocked.contains_key(&(to, from))
                && self.online(from)
                && self.online(to)
            {
                self.connect_pair(from, to);
            }
        }
    }
}

/// How long after `now` a sender that first failed to reach its peer at `since` probes again:
/// its probes go out `pto`, then twice, four times... that long apart.
fn next_probe(since: u64, pto: u64, now: u64) -> u64 {
    let (mut at, mut gap) = (since, pto.max(1));
    while at < now {
        at = at.saturating_add(gap);
        gap = gap.saturating_mul(2);
    }
    at - now
}

#[cfg(test)]
mod tests {
    use super::next_probe;

    #[test]
    fn probes_back_off_from_the_first_stall() {
        // Probes at 100, 300, 700, 1500 after a first stall at 0.
        assert_eq!(next_probe(0, 100, 0), 0);
        assert_eq!(next_probe(0, 100, 50), 50);
        assert_eq!(next_probe(0, 100, 300), 0);
        assert_eq!(next_probe(0, 100, 301), 399);
        assert_eq!(next_probe(0, 100, 1_000), 500);
    }
}
