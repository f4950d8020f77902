//! The verdicts on a log's linear order, one byte per op.
//!
//! A [`Mark`] is 33 bytes because two rejections name the lease holder. Most ops are
//! effective and few rejections name anyone, so a log keeps each verdict as a one-byte code
//! and the holders aside, by the op's position in the log's slab (which, unlike its position
//! in the order, never shifts).

use std::collections::BTreeMap;

use crate::identity::PeerId;
use crate::lease::{Mark, RejectReason};

/// One verdict per position of the linear order.
#[derive(Clone, Debug, Default)]
pub(crate) struct Marks {
    codes: Vec<u8>,
    /// The holder each `LeaseHeld` or `StrongLeaseHeld` verdict names, by slab position.
    holders: BTreeMap<u32, PeerId>,
}

impl Marks {
    /// The verdict at order position `pos`, whose op the slab holds at `at`.
    pub(crate) fn get(&self, pos: usize, at: u32) -> Mark {
        let holder = || {
            *self
                .holders
                .get(&at)
                .expect("a named holder is kept with its verdict")
        };
        match self.codes[pos] {
            0 => Mark::Effective,
            1 => Mark::Rejected(RejectReason::LeaseHeld { holder: holder() }),
            2 => Mark::Rejected(RejectReason::StrongLeaseHeld { holder: holder() }),
            3 => Mark::Rejected(RejectReason::NotHolder),
            4 => Mark::Rejected(RejectReason::UnknownTarget),
            5 => Mark::Rejected(RejectReason::NotOwnTarget),
            6 => Mark::Rejected(RejectReason::TargetNotEdit),
            7 => Mark::Rejected(RejectReason::TargetNotEffective),
            8 => Mark::Rejected(RejectReason::AlreadyUndone),
            9 => Mark::Rejected(RejectReason::NotUndone),
            10 => Mark::Rejected(RejectReason::Expelled),
            _ => Mark::Rejected(RejectReason::Forked),
        }
    }

    /// Sets the verdict at order position `pos`, whose op the slab holds at `at`.
    pub(crate) fn set(&mut self, pos: usize, at: u32, mark: Mark) {
        let (code, holder) = match mark {
            Mark::Effective => (0, None),
            Mark::Rejected(reason) => match reason {
                RejectReason::LeaseHeld { holder } => (1, Some(holder)),
                RejectReason::StrongLeaseHeld { holder } => (2, Some(holder)),
                RejectReason::NotHolder => (3, None),
                RejectReason::UnknownTarget => (4, None),
                RejectReason::NotOwnTarget => (5, None),
                RejectReason::TargetNotEdit => (6, None),
                RejectReason::TargetNotEffective => (7, None),
                RejectReason::AlreadyUndone => (8, None),
                RejectReason::NotUndone => (9, None),
                RejectReason::Expelled => (10, None),
                RejectReason::Forked => (11, None),
            },
        };
        self.codes[pos] = code;
        match holder {
            Some(holder) => self.holders.insert(at, holder),
            None => self.holders.remove(&at),
        };
    }

    /// Makes room at order position `pos` for an op just delivered, effective until judged.
    pub(crate) fn insert(&mut self, pos: usize) {
        self.codes.insert(pos, 0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_verdict_reads_back_as_set_and_only_named_holders_are_kept() {
        let holder = PeerId([7; 32]);
        let reasons = [
            RejectReason::LeaseHeld { holder },
            RejectReason::StrongLeaseHeld { holder },
            RejectReason::NotHolder,
            RejectReason::UnknownTarget,
            RejectReason::NotOwnTarget,
            RejectReason::TargetNotEdit,
            RejectReason::TargetNotEffective,
            RejectReason::AlreadyUndone,
            RejectReason::NotUndone,
            RejectReason::Expelled,
            RejectReason::Forked,
        ];
        let marks = std::iter::once(Mark::Effective).chain(reasons.map(Mark::Rejected));
        let mut m = Marks::default();
        for (pos, mark) in marks.clone().enumerate() {
            m.insert(pos);
            assert_eq!(
                m.get(pos, 100 + pos as u32),
                Mark::Effective,
                "a placeholder"
            );
            m.set(pos, 100 + pos as u32, mark);
        }
        for (pos, mark) in marks.enumerate() {
            assert_eq!(m.get(pos, 100 + pos as u32), mark);
        }
        assert_eq!(m.holders.len(), 2);
        // A verdict that changes from naming a holder to not naming one drops it.
        m.set(1, 101, Mark::Rejected(RejectReason::NotHolder));
        m.set(2, 102, Mark::Effective);
        assert!(m.holders.is_empty());
        // Shifting positions in the order keeps each holder with its op.
        m.set(1, 101, Mark::Rejected(RejectReason::LeaseHeld { holder }));
        m.insert(0);
        assert_eq!(
            m.get(2, 101),
            Mark::Rejected(RejectReason::LeaseHeld { holder })
        );
    }
}
