//! Remeshing on several threads, with the same result as on one, bit for bit.
//!
//! The caller's thread visits the octree's top [`PARALLEL_LEVELS`] as a one-thread visit
//! would (intervals, pruning, simplified fields) and stops at the subtrees below them (64 at
//! two levels), each a task with its own copy of the field its root receives: the copy is
//! made by asking the same simplification again, so it is the same field (or, where the field
//! did not simplify, by [`Field::fork`]). A block reads only
//! the values of the blocks below it (lower along each axis), and a one-thread visit builds
//! blocks in Morton order, in which those come first. So subtrees run in waves by the sum of
//! their coordinates: every subtree a block reads from is in an earlier wave or its own, and
//! the subtrees of one wave run at once, each on the blocks it owns (taken out of the mesher
//! and put back after the wave) and reading the rest. A node the plan pruned is pruned part
//! by part, each part in its subtree's wave, on the caller's thread (it holds that field).

use std::collections::VecDeque;
use std::sync::{Mutex, MutexGuard, PoisonError};

use super::{
    Aabb, BlockRange, Field, Local, MeshStats, OctreeMeshError, OctreeMesher, Step, Visit,
    corner_offset,
};

/// Octree levels the caller's thread plans: the 4^3 = 64 subtrees below them are the tasks
/// threads take.
pub const PARALLEL_LEVELS: u32 = 2;
/// Fewest blocks a remesh must touch to run on several threads: a smaller one (a stroke's
/// patch) would spend more on starting threads and copying fields than it saves.
pub const MIN_PARALLEL_BLOCKS: usize = 64;

/// A subtree's work.
enum Work<F> {
    /// Visit the subtree's root with this copy of the field it receives.
    Visit {
        origin: [u32; 3],
        size: u32,
        field: F,
    },
    /// The part in this subtree of a node the plan pruned.
    Prune {
        first: [u32; 3],
        last: [u32; 3],
        rep: f32,
    },
}

/// One subtree's work, with its position among the subtrees.
struct Task<F> {
    cell: [u32; 3],
    work: Work<F>,
}

/// A task ready to run: its place in the plan, its work and the blocks it may change.
type Job<F> = (usize, Work<F>, Local);

impl OctreeMesher {
    /// [`OctreeMesher::remesh`] on up to `n_threads` threads, with the same mesh, stats and
    /// records as a result. It runs on one thread when `dirty` touches fewer than
    /// [`MIN_PARALLEL_BLOCKS`] blocks, when the grid is too small to split, and when the
    /// field neither simplifies nor forks over the top levels' nodes (no copies).
    pub fn remesh_parallel<F: Field + Send>(
        &mut self,
        field: &mut F,
        dirty: Aabb,
        n_threads: usize,
    ) -> Result<MeshStats, OctreeMeshError> {
        let large =
            (self.grid.blocks_touching(dirty)).is_some_and(|r| r.n_blocks() >= MIN_PARALLEL_BLOCKS);
        if n_threads < 2 || self.n_blocks < 1 << PARALLEL_LEVELS || !large {
            return self.remesh(field, dirty);
        }
        let Some((range, wide)) = self.begin(dirty) else {
            return Ok(MeshStats::default());
        };
        let mut planner = Visit::new(self, Local::none(), range, wide);
        let Some((mut top, tasks)) = planner.plan(field) else {
            // Only the planner's counts are dropped: it changed nothing.
            return Ok(self.visit_whole(field, range, wide));
        };
        let mut stats = planner.stats;
        let cell_blocks = self.n_blocks >> PARALLEL_LEVELS;
        let mut tasks: Vec<Option<Task<F>>> = tasks.into_iter().map(Some).collect();
        for wave in 0..=3 * ((1 << PARALLEL_LEVELS) - 1) {
            let mut jobs = Vec::new();
            for (i, slot) in tasks.iter_mut().enumerate() {
                if slot
                    .as_ref()
                    .is_some_and(|t| t.cell.iter().sum::<u32>() == wave)
                    && let Some(task) = slot.take()
                {
                    let keys = BlockRange {
                        lo: std::array::from_fn(|a| (task.cell[a] * cell_blocks).max(wide.lo[a])),
                        hi: std::array::from_fn(|a| {
                            ((task.cell[a] + 1) * cell_blocks - 1).min(wide.hi[a])
                        }),
                    };
                    jobs.push((i, task.work, self.take_local(keys)));
                }
            }
            let mut done = run_wave(self, &mut top, jobs, [range, wide], n_threads);
            done.sort_by_key(|(i, _, _)| *i);
            for (_, local, s) in done {
                self.put_local(local);
                stats += s;
            }
        }
        Ok(stats)
    }
}

/// Runs one wave's jobs: pruned parts on this thread with `top` (the plan's field), visits
/// on up to `n_threads` threads, this one among them. Gives back each job's place, the
/// blocks it changed and its counts.
fn run_wave<F: Field + Send>(
    mesher: &OctreeMesher,
    top: &mut F,
    jobs: Vec<Job<F>>,
    [range, wide]: [BlockRange; 2],
    n_threads: usize,
) -> Vec<(usize, Local, MeshStats)> {
    let mut done = Vec::with_capacity(jobs.len());
    let mut visits = VecDeque::new();
    for (i, work, local) in jobs {
        match work {
            Work::Prune { first, last, rep } => {
                let mut visit = Visit::new(mesher, local, range, wide);
                visit.prune(top, first, last, rep);
                done.push((i, visit.local, visit.stats));
            }
            Work::Visit {
                origin,
                size,
                field,
            } => visits.push_back((i, origin, size, field, local)),
        }
    }
    let n_helpers = (n_threads - 1).min(visits.len().saturating_sub(1));
    let queue = Mutex::new(visits);
    let done = Mutex::new(done);
    let work = || {
        loop {
            // Popped apart from the loop's test, which would hold the lock through the body.
            let next = lock(&queue).pop_front();
            let Some((i, origin, size, mut field, local)) = next else {
                break;
            };
            let mut visit = Visit::new(mesher, local, range, wide);
            visit.node(&mut field, origin, size);
            lock(&done).push((i, visit.local, visit.stats));
        }
    };
    std::thread::scope(|scope| {
        for k in 0..n_helpers {
            // A helper that cannot start leaves its share to the others and this thread.
            let _ = std::thread::Builder::new()
                .name(format!("sculpt-remesh-{k}"))
                .spawn_scoped(scope, work);
        }
        work();
    });
    done.into_inner().unwrap_or_else(PoisonError::into_inner)
}

/// A copy of the field the children of a node over `lo..hi` receive from `field`, the node's:
/// `field` simplified there (then true), else `field` itself, forked.
fn child_field<F: Field>(field: &mut F, lo: [f32; 3], hi: [f32; 3]) -> Option<(F, bool)> {
    match field.simplify(lo, hi) {
        Some(simplified) => Some((simplified, true)),
        None => field.fork().map(|f| (f, false)),
    }
}

/// Locks `m`; a thread that panicked holding it left nothing half written that matters here
/// (the scope passes its panic on).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Visit<'_> {
    /// Visits the top two levels of the octree as [`Visit::node`] would, and gives the field
    /// the root's children receive and the tasks below. `None` for a pruned root, or a field
    /// that neither simplifies nor forks (no copies of it can be made).
    fn plan<F: Field>(&mut self, field: &mut F) -> Option<(F, Vec<Task<F>>)> {
        const _: () = assert!(PARALLEL_LEVELS == 2, "the plan visits two levels");
        let n = self.mesher.grid.n_cells;
        let Step::Open { lo, hi } = self.step(field, [0; 3], n) else {
            return None;
        };
        let (mut top, simplified) = child_field(field, lo, hi)?;
        self.stats.fields_simplified += usize::from(simplified);
        let (half, quarter) = (n / 2, n / 4);
        let mut tasks = Vec::new();
        for k in 0..8 {
            let origin: [u32; 3] = std::array::from_fn(|a| corner_offset(k)[a] * half);
            let children = (0..8).map(|j| -> [u32; 3] {
                std::array::from_fn(|a| origin[a] + corner_offset(j)[a] * quarter)
            });
            let mut push = |child: [u32; 3], work| {
                let cell = child.map(|o| o / quarter);
                tasks.push(Task { cell, work });
            };
            match self.step(&mut top, origin, half) {
                Step::Skip => {}
                Step::Prune { first, last, rep } => {
                    for child in children.filter(|c| self.meets_wide(*c, quarter)) {
                        push(child, Work::Prune { first, last, rep });
                    }
                }
                Step::Open { lo, hi } => {
                    // Counted as the one-thread visit counts its one call (one child at
                    // least meets `wide`, as the node does).
                    let children: Vec<[u32; 3]> =
                        children.filter(|c| self.meets_wide(*c, quarter)).collect();
                    let mut counted = false;
                    for child in children {
                        let (field, simplified) = child_field(&mut top, lo, hi)?;
                        if simplified && !counted {
                            self.stats.fields_simplified += 1;
                            counted = true;
                        }
                        push(
                            child,
                            Work::Visit {
                                origin: child,
                                size: quarter,
                                field,
                            },
                        );
                    }
                }
            }
        }
        Some((top, tasks))
    }

    /// Whether the node of `size` cells at `origin` holds a block the visit may change.
    fn meets_wide(&self, origin: [u32; 3], size: u32) -> bool {
        let bc = self.mesher.grid.block;
        (0..3).all(|a| {
            let (first, last) = (origin[a] / bc, (origin[a] + size) / bc - 1);
            last >= self.wide.lo[a] && first <= self.wide.hi[a]
        })
    }
}
