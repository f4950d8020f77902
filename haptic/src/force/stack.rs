//! The entry-order container stack (thesis 4.3, Figure 4.6): entering pushes, leaving
//! removes, the top rules. Fixed capacity, no allocation.

/// The deepest nesting tracked; containers entered beyond it are counted and ignored.
pub const MAX_STACK_DEPTH: usize = 64;

/// One container the HIP is inside.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StackEntry {
    /// Container id (stable across snapshots).
    pub id: u64,
    /// Index in the current scene (re-resolved when the scene changes).
    pub idx: u32,
}

/// The containers the HIP is inside, in the order it entered them (last is top).
#[derive(Clone, Debug)]
pub struct ContainerStack {
    entries: [StackEntry; MAX_STACK_DEPTH],
    len: usize,
    n_overflows: u64,
}

impl Default for ContainerStack {
    fn default() -> Self {
        Self {
            entries: [StackEntry { id: 0, idx: 0 }; MAX_STACK_DEPTH],
            len: 0,
            n_overflows: 0,
        }
    }
}

impl ContainerStack {
    /// Entries, bottom first.
    pub fn entries(&self) -> &[StackEntry] {
        &self.entries[..self.len]
    }

    /// Entries, bottom first, as mutable (to re-resolve indices).
    pub(crate) fn entries_mut(&mut self) -> &mut [StackEntry] {
        &mut self.entries[..self.len]
    }

    /// The ruling container.
    pub fn top(&self) -> Option<StackEntry> {
        self.entries().last().copied()
    }

    /// True when `id` is on the stack.
    pub fn contains(&self, id: u64) -> bool {
        self.entries().iter().any(|e| e.id == id)
    }

    /// Pushes unless present; counts an overflow when full.
    pub fn push(&mut self, entry: StackEntry) {
        if self.contains(entry.id) {
            return;
        }
        if self.len == MAX_STACK_DEPTH {
            self.n_overflows += 1;
            return;
        }
        self.entries[self.len] = entry;
        self.len += 1;
    }

    /// Removes `id` wherever it is (the HIP may leave a container that is not on top).
    pub fn remove(&mut self, id: u64) {
        if let Some(pos) = self.entries().iter().position(|e| e.id == id) {
            self.entries.copy_within(pos + 1..self.len, pos);
            self.len -= 1;
        }
    }

    /// Removes entries for which `keep` is false, keeping order.
    pub(crate) fn retain(&mut self, mut keep: impl FnMut(&StackEntry) -> bool) {
        let mut out = 0;
        for k in 0..self.len {
            if keep(&self.entries[k]) {
                self.entries[out] = self.entries[k];
                out += 1;
            }
        }
        self.len = out;
    }

    /// Empties the stack.
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Containers that could not be pushed because the stack was full.
    pub fn n_overflows(&self) -> u64 {
        self.n_overflows
    }
}
