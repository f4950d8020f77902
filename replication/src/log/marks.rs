//! The verdicts on a log's ops, one byte per op.
//!
//! A [`Mark`] is 33 bytes because two rejections name the lease holder. Most ops are
//! effective and few rejections name anyone, so a log keeps each verdict as a one-byte code
//! and the holders aside. Both are indexed by the op's position in the log's slab, which,
//! unlike its position in the linear order, never shifts: a late op appends a verdict, and a
//! verdict is found from the op alone.

use std::collections::BTreeMap;

use crate::identity::PeerId;
use crate::lease::{Mark, RejectReason};

/// One verdict per held op.
#[derive(Clone, Debug, Default)]
pub(crate) struct Marks {
    /// By slab position.
    codes: Vec<u8>,
    /// The holder each `LeaseHeld` or `StrongLeaseHeld` verdict names, by slab position.
    holders: BTreeMap<u32, PeerId>,
}

impl Marks {
    /// The verdict on the op the slab holds at `at`.
    pub(crate) fn get(&self, at: u32) -> Mark {
        let holder = || {
            *self
                .holders
                .get(&at)
                .expect("a named holder is kept with its verdict")
        };
        match self.codes[at as usize] {
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
            11 => Mark::Rejected(RejectReason::Forked),
            12 => Mark::Rejected(RejectReason::UnknownObject),
            _ => Mark::Rejected(RejectReason::TooManyLeases),
        }
    }

    /// Sets the verdict on the op the slab holds at `at`.
    pub(crate) fn set(&mut self, at: u32, mark: Mark) {
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
                RejectReason::UnknownObject => (12, None),
                RejectReason::TooManyLeases => (13, None),
            },
        };
        let old = std::mem::replace(&mut self.codes[at as usize], code);
        if let Some(holder) = holder {
            self.holders.insert(at, holder);
        } else if names_holder(old) {
            self.holders.remove(&at);
        }
    }

    /// Adds the verdict on the op just held at the slab's next position, effective until
    /// judged.
    pub(crate) fn push(&mut self) {
        self.codes.push(0);
    }
}

/// Whether verdicts with `code` name a lease holder.
fn names_holder(code: u8) -> bool {
    matches!(code, 1 | 2)
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
            RejectReason::UnknownObject,
            RejectReason::TooManyLeases,
        ];
        let marks = std::iter::once(Mark::Effective).chain(reasons.map(Mark::Rejected));
        let mut m = Marks::default();
        for (at, mark) in (0..).zip(marks.clone()) {
            m.push();
            assert_eq!(m.get(at), Mark::Effective, "a placeholder");
            m.set(at, mark);
        }
        for (at, mark) in (0..).zip(marks) {
            assert_eq!(m.get(at), mark);
        }
        assert_eq!(m.holders.len(), 2);
        // A verdict that changes from naming a holder to not naming one drops it.
        m.set(1, Mark::Rejected(RejectReason::NotHolder));
        m.set(2, Mark::Effective);
        assert!(m.holders.is_empty());
        let other = PeerId([9; 32]);
        m.set(1, Mark::Rejected(RejectReason::LeaseHeld { holder }));
        m.set(
            1,
            Mark::Rejected(RejectReason::StrongLeaseHeld { holder: other }),
        );
        assert_eq!(
            m.get(1),
            Mark::Rejected(RejectReason::StrongLeaseHeld { holder: other })
        );
        assert_eq!(m.holders.len(), 1);
    }
}
