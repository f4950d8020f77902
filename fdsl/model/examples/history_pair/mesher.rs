//! The queries render's octree mesher (`render/src/mesh/octree.rs` over `ObjectField`) makes
//! of an object with edits, replayed here without render: the same descent, the same boxes,
//! the same restrictions and the same lattices, in the mesher's order.
//!
//! The mesher splits its box into 2^depth cells along each axis and visits nodes depth first,
//! children in corner order (x fastest). At each node it asks an interval over the node's box
//! (the root through the [`Sampler`], every other node through its parent's [`BoxSampler`]),
//! prunes the node when the interval has one sign, and otherwise restricts its field to the
//! box (`Field::simplify`: `Sampler::restrict` at the root, `BoxSampler::restrict` below).
//! A node of [`BLOCK_CELLS`] cells is a leaf block: its restricted sampler gives the values
//! of the lattice points the block owns (its upper faces; the grid's lower faces too), in one
//! call.
//!
//! What is timed: [`Descent::intervals`] asks every node's interval in the mesher's order,
//! of samplers restricted once when the descent was recorded (so neither the inner nodes'
//! restrictions nor a restricted sampler's point-path fallback, made on its first need, are
//! in it); [`Descent::block_values`] restricts each leaf block from its parent and evaluates
//! its lattice, as the mesher does for every block it does not prune.
//!
//! Left out: the Hermite data of the crossed cells (six bisection rounds of values, then
//! values and gradients at the crossings and gradients at the vertices, in batches of a
//! block's crossed edges through the same leaf sampler), and the blocks of pruned nodes that
//! a disagreeing neighbour gives cells. The box is the object's, grown as render's
//! `mesh_bounds` grows it (the workload's sphere has no domain: its box is taken as
//! `[-1.1, 1.1]^3`, which holds every edit's tool).

use glam::DVec3;
use model::bvh::Aabb;
use model::object::{BoxSampler, Sampler};

/// The mesher's usual octree depth: 128 cells along each axis.
pub const DEPTH: u8 = 7;
/// Cells along each axis of a leaf block (render's `BLOCK_CELLS`).
const BLOCK_CELLS: u32 = 8;
/// Half the side of the box the workload's object is taken to fill.
const OBJECT_HALF_SIDE: f32 = 1.1;

/// The mesher's lattice, in single precision as the mesher computes its points.
#[derive(Clone, Copy)]
struct Grid {
    lo: f32,
    step: f32,
}

impl Grid {
    /// render's `mesh_bounds` over `[-OBJECT_HALF_SIDE, OBJECT_HALF_SIDE]^3` at [`DEPTH`].
    fn new() -> Grid {
        let side = 2.0 * OBJECT_HALF_SIDE;
        let n_cells = (1u32 << DEPTH) as f32;
        let margin = 2.5 * side / (n_cells - 5.0).max(1.0);
        let lo = -OBJECT_HALF_SIDE - margin;
        let hi = OBJECT_HALF_SIDE + margin;
        Grid {
            lo,
            step: (hi - lo) / n_cells,
        }
    }

    fn point(&self, i: [u32; 3]) -> DVec3 {
        let c = i.map(|k| f64::from(self.lo + k as f32 * self.step));
        DVec3::from_array(c)
    }

    fn region(&self, origin: [u32; 3], size: u32) -> Aabb {
        Aabb::new(self.point(origin), self.point(origin.map(|o| o + size)))
    }
}

/// Which sampler answers a query: the object's own (the root), or an inner node's.
#[derive(Clone, Copy)]
enum Parent {
    Root,
    Node(usize),
}

/// One object's octree descent, recorded once, then replayed by [`Descent::intervals`] and
/// [`Descent::block_values`].
pub struct Descent {
    grid: Grid,
    /// The restricted samplers of the inner nodes that were not pruned, in visit order.
    parents: Vec<BoxSampler>,
    /// Every node's interval query: who answers it, over which box.
    interval_queries: Vec<(Parent, Aabb)>,
    /// Every leaf block that was not pruned: its parent and its origin in cells.
    blocks: Vec<(usize, [u32; 3])>,
    points: Vec<DVec3>,
    values: Vec<f64>,
}

impl Descent {
    /// The descent the mesher makes over the object `sampler` evaluates, at time 0.
    pub fn record(sampler: &mut Sampler) -> Descent {
        let mut descent = Descent {
            grid: Grid::new(),
            parents: Vec::new(),
            interval_queries: Vec::new(),
            blocks: Vec::new(),
            points: Vec::new(),
            values: Vec::new(),
        };
        descent.visit(sampler, Parent::Root, [0; 3], 1 << DEPTH);
        descent
    }

    /// Visits the node of `size` cells at `origin` as `Visit::node` does; the recursion is
    /// as deep as the octree ([`DEPTH`] levels less the block's).
    fn visit(&mut self, sampler: &mut Sampler, parent: Parent, origin: [u32; 3], size: u32) {
        let region = self.grid.region(origin, size);
        let iv = match parent {
            Parent::Root => sampler.interval(&region, 0.0),
            Parent::Node(i) => self.parents[i].interval(&region),
        };
        self.interval_queries.push((parent, region));
        if iv.lo > 0.0 || iv.hi < 0.0 {
            return;
        }
        if size <= BLOCK_CELLS {
            // The leaf's restriction is timed with its values.
            let Parent::Node(p) = parent else {
                unreachable!("the root is never a block at this depth")
            };
            self.blocks.push((p, origin));
            return;
        }
        let restricted = match parent {
            Parent::Root => sampler.restrict(&region, 0.0),
            Parent::Node(i) => self.parents[i].restrict(&region),
        };
        let me = self.parents.len();
        self.parents.push(restricted);
        let half = size / 2;
        for k in 0..8u32 {
            let corner = [k & 1, (k >> 1) & 1, (k >> 2) & 1];
            let child = std::array::from_fn(|a| origin[a] + corner[a] * half);
            self.visit(sampler, Parent::Node(me), child, half);
        }
    }

    /// Interval queries of one descent.
    pub fn n_intervals(&self) -> usize {
        self.interval_queries.len()
    }

    /// Leaf blocks of one descent.
    pub fn n_blocks(&self) -> usize {
        self.blocks.len()
    }

    /// Every interval query of the descent, in its order (the sum of upper bounds).
    pub fn intervals(&mut self, sampler: &mut Sampler) -> f64 {
        let mut sum = 0.0;
        for (parent, region) in &self.interval_queries {
            let iv = match *parent {
                Parent::Root => sampler.interval(region, 0.0),
                Parent::Node(i) => self.parents[i].interval(region),
            };
            sum += iv.hi;
        }
        sum
    }

    /// Every leaf block of the descent: restricted from its parent, then its owned lattice
    /// points' values in one call (the sum of the values).
    pub fn block_values(&mut self) -> f64 {
        let mut sum = 0.0;
        for &(parent, origin) in &self.blocks {
            let region = self.grid.region(origin, BLOCK_CELLS);
            let mut block = self.parents[parent].restrict(&region);
            self.points.clear();
            let from = origin.map(|o| u32::from(o > 0));
            for z in from[2]..=BLOCK_CELLS {
                for y in from[1]..=BLOCK_CELLS {
                    for x in from[0]..=BLOCK_CELLS {
                        let i = [origin[0] + x, origin[1] + y, origin[2] + z];
                        self.points.push(self.grid.point(i));
                    }
                }
            }
            self.values.resize(self.points.len(), 0.0);
            block.values(&self.points, &mut self.values);
            sum += self.values.iter().sum::<f64>();
        }
        sum
    }
}
