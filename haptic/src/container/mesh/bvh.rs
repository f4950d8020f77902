//! A bounding volume hierarchy over triangles for nearest-hit ray queries: median splits on
//! the longest axis of the centroids, at most [`LEAF_TRIANGLES_MAX`] triangles per leaf,
//! nodes in one array (left child next to its parent), and an allocation-free traversal with
//! a fixed stack, nearer child first.

use glam::DVec3;

/// Triangles per leaf at most.
pub const LEAF_TRIANGLES_MAX: usize = 4;
/// Depth of the traversal stack. Median splits halve the triangle count per level, so a tree
/// over `n` triangles is `ceil(log2(n / LEAF_TRIANGLES_MAX)) + 1` deep: 64 covers any count
/// that fits in memory, and [`super::TRIANGLES_MAX`] is far below.
pub const TRAVERSAL_STACK_LEN: usize = 64;

/// A triangle prepared for intersection: a corner, two edges and the unit normal given by the
/// winding (`e1 x e2`, outward for a counter-clockwise closed mesh).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    /// First corner.
    pub v0: DVec3,
    /// Second corner minus the first.
    pub e1: DVec3,
    /// Third corner minus the first.
    pub e2: DVec3,
    /// Unit normal by winding.
    pub normal: DVec3,
}

impl Triangle {
    /// A triangle from corners; `None` when degenerate (no normal) or not finite.
    pub fn new(a: DVec3, b: DVec3, c: DVec3) -> Option<Self> {
        let (e1, e2) = (b - a, c - a);
        let normal = e1.cross(e2).try_normalize()?;
        (a.is_finite() && b.is_finite() && c.is_finite()).then_some(Self {
            v0: a,
            e1,
            e2,
            normal,
        })
    }

    fn lo_hi(&self) -> (DVec3, DVec3) {
        let (b, c) = (self.v0 + self.e1, self.v0 + self.e2);
        (self.v0.min(b).min(c), self.v0.max(b).max(c))
    }

    fn centroid(&self) -> DVec3 {
        self.v0 + (self.e1 + self.e2) / 3.0
    }

    /// The ray parameter of the hit with `origin + t * dir`, `0 <= t <= t_max`
    /// (Moeller-Trumbore, both sides, edges included).
    pub fn intersect(&self, origin: DVec3, dir: DVec3, t_max: f64) -> Option<f64> {
        let pvec = dir.cross(self.e2);
        let det = self.e1.dot(pvec);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv = 1.0 / det;
        let tvec = origin - self.v0;
        let u = tvec.dot(pvec) * inv;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let qvec = tvec.cross(self.e1);
        let v = dir.dot(qvec) * inv;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let t = self.e2.dot(qvec) * inv;
        (0.0..=t_max).contains(&t).then_some(t)
    }
}

/// The nearest hit of a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter (distance when the direction is a unit vector).
    pub t: f64,
    /// Index into [`Bvh::triangles`].
    pub tri_idx: u32,
}

#[derive(Clone, Copy, Debug)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    /// First triangle of a leaf, or the right child of an inner node.
    first_or_right: u32,
    /// Triangles in a leaf; 0 for an inner node (whose left child is the next node).
    count: u32,
}

/// The hierarchy and its triangles (reordered so each leaf's triangles are contiguous).
#[derive(Clone, Debug)]
pub struct Bvh {
    nodes: Vec<Node>,
    tris: Vec<Triangle>,
}

impl Bvh {
    /// Builds the hierarchy (allocates; not for the servo thread).
    pub fn build(mut tris: Vec<Triangle>) -> Self {
        let mut nodes = Vec::with_capacity(2 * tris.len().div_ceil(LEAF_TRIANGLES_MAX) + 1);
        if !tris.is_empty() {
            let n = tris.len();
            build_range(&mut nodes, &mut tris, 0, n);
        }
        Self { nodes, tris }
    }

    /// The triangles, in leaf order.
    pub fn triangles(&self) -> &[Triangle] {
        &self.tris
    }

    /// The nearest triangle hit by `origin + t * dir` with `0 <= t <= t_max`. No allocation.
    pub fn nearest_hit(&self, origin: DVec3, dir: DVec3, t_max: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        let inv_dir = dir.recip();
        let mut stack = [0u32; TRAVERSAL_STACK_LEN];
        let mut len = 0;
        if self
            .nodes
            .first()
            .is_some_and(|n| slab(n, origin, inv_dir, t_best).is_some())
        {
            stack[0] = 0;
            len = 1;
        }
        while len > 0 {
            len -= 1;
            let node_idx = stack[len];
            let node = &self.nodes[node_idx as usize];
            // Pushed when its box was hit; the best hit may have moved closer since.
            if slab(node, origin, inv_dir, t_best).is_none() {
                continue;
            }
            if node.count > 0 {
                let first = node.first_or_right as usize;
                for (k, tri) in self.tris[first..first + node.count as usize]
                    .iter()
                    .enumerate()
                {
                    if let Some(t) = tri.intersect(origin, dir, t_best) {
                        t_best = t;
                        best = Some(Hit {
                            t,
                            tri_idx: (first + k) as u32,
                        });
                    }
                }
                continue;
            }
            // The left child is stored right after its parent.
            let (left, right) = (node_idx + 1, node.first_or_right);
            let t_left = slab(&self.nodes[left as usize], origin, inv_dir, t_best);
            let t_right = slab(&self.nodes[right as usize], origin, inv_dir, t_best);
            // Push the farther child first so the nearer one is visited next.
            let (near, far) = match (t_left, t_right) {
                (Some(a), Some(b)) if b < a => (Some(right), Some(left)),
                (Some(_), Some(_)) => (Some(left), Some(right)),
                (Some(_), None) => (Some(left), None),
                (None, Some(_)) => (Some(right), None),
                (None, None) => (None, None),
            };
            for child in [far, near].into_iter().flatten() {
                assert!(len < TRAVERSAL_STACK_LEN, "BVH deeper than its stack");
                stack[len] = child;
                len += 1;
            }
        }
        best
    }
}

/// Entry parameter of the ray into the node's box within `[0, t_max]`, if it enters.
fn slab(node: &Node, origin: DVec3, inv_dir: DVec3, t_max: f64) -> Option<f64> {
    let t0 = (node.lo - origin) * inv_dir;
    let t1 = (node.hi - origin) * inv_dir;
    // `min`/`max` ignore the NaN of 0 * inf (a ray in a slab's plane), keeping the other bound.
    let t_near = t0.min(t1).max_element().max(0.0);
    let t_far = t0.max(t1).min_element().min(t_max);
    (t_near <= t_far).then_some(t_near)
}

/// Builds the subtree over `tris[start..end]`, returning its node index. Recursion depth is
/// the tree depth, bounded as [`TRAVERSAL_STACK_LEN`] explains.
fn build_range(nodes: &mut Vec<Node>, tris: &mut [Triangle], start: usize, end: usize) -> u32 {
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    let (mut c_lo, mut c_hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for tri in &tris[start..end] {
        let (a, b) = tri.lo_hi();
        lo = lo.min(a);
        hi = hi.max(b);
        c_lo = c_lo.min(tri.centroid());
        c_hi = c_hi.max(tri.centroid());
    }
    let idx = nodes.len() as u32;
    nodes.push(Node {
        lo,
        hi,
        first_or_right: start as u32,
        count: (end - start) as u32,
    });
    if end - start <= LEAF_TRIANGLES_MAX {
        return idx;
    }
    let extent = c_hi - c_lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let mid = (start + end) / 2;
    tris[start..end].select_nth_unstable_by(mid - start, |a, b| {
        a.centroid()[axis].total_cmp(&b.centroid()[axis])
    });
    build_range(nodes, tris, start, mid);
    let right = build_range(nodes, tris, mid, end);
    nodes[idx as usize].first_or_right = right;
    nodes[idx as usize].count = 0;
    idx
}
