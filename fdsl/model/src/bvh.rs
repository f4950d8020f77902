//! A static bounding volume hierarchy over axis-aligned boxes: which items can matter at a
//! point, in a box or along a ray. The edit history of an object and imported triangle meshes
//! index themselves with it.
//!
//! Built once from a slice of boxes (median split of the centroids along the widest axis, up to
//! [`LEAF_SIZE`] items per leaf), queried without allocating: traversal keeps its stack in a
//! fixed array, which is deep enough because the split halves the items at every level.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Most items in one leaf.
pub const LEAF_SIZE: usize = 4;

/// Traversal stack depth; a median split of at most 2^32 items is at most 32 levels deep.
const STACK_DEPTH: usize = 64;

/// An axis-aligned box, `lo <= hi` on every axis for a non-empty box.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// The low corner.
    pub lo: DVec3,
    /// The high corner.
    pub hi: DVec3,
}

impl Aabb {
    /// The box containing nothing: the identity of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb {
        lo: DVec3::splat(f64::INFINITY),
        hi: DVec3::splat(f64::NEG_INFINITY),
    };

    /// The box from its two corners (in any order).
    pub fn new(a: DVec3, b: DVec3) -> Aabb {
        Aabb {
            lo: a.min(b),
            hi: a.max(b),
        }
    }

    /// The box of centre `center` and half-size `half`.
    pub fn around(center: DVec3, half: DVec3) -> Aabb {
        Aabb::new(center - half, center + half)
    }

    /// Whether the box contains nothing.
    pub fn is_empty(&self) -> bool {
        !(self.lo.x <= self.hi.x && self.lo.y <= self.hi.y && self.lo.z <= self.hi.z)
    }

    /// The smallest box holding both.
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            lo: self.lo.min(other.lo),
            hi: self.hi.max(other.hi),
        }
    }

    /// The box grown by `margin` on every side.
    pub fn expand(&self, margin: f64) -> Aabb {
        Aabb {
            lo: self.lo - DVec3::splat(margin),
            hi: self.hi + DVec3::splat(margin),
        }
    }

    /// Whether `p` lies inside or on the boundary.
    #[inline]
    pub fn contains(&self, p: DVec3) -> bool {
        p.x >= self.lo.x
            && p.x <= self.hi.x
            && p.y >= self.lo.y
            && p.y <= self.hi.y
            && p.z >= self.lo.z
            && p.z <= self.hi.z
    }

    /// Whether the two boxes share a point.
    #[inline]
    pub fn overlaps(&self, other: &Aabb) -> bool {
        self.lo.x <= other.hi.x
            && other.lo.x <= self.hi.x
            && self.lo.y <= other.hi.y
            && other.lo.y <= self.hi.y
            && self.lo.z <= other.hi.z
            && other.lo.z <= self.hi.z
    }

    /// Whether `other` lies entirely inside this box.
    pub fn contains_box(&self, other: &Aabb) -> bool {
        self.contains(other.lo) && self.contains(other.hi)
    }

    /// The centre.
    pub fn center(&self) -> DVec3 {
        (self.lo + self.hi) * 0.5
    }

    /// The edge lengths.
    pub fn size(&self) -> DVec3 {
        self.hi - self.lo
    }

    /// The parameter interval `[t0, t1]` within `[0, t_max]` over which the ray
    /// `origin + t * dir` is inside the box, if any. `inv_dir` is `1 / dir` per axis.
    #[inline]
    pub fn ray_interval(&self, origin: DVec3, inv_dir: DVec3, t_max: f64) -> Option<(f64, f64)> {
        let a = (self.lo - origin) * inv_dir;
        let b = (self.hi - origin) * inv_dir;
        // NaN (0 * inf for a ray in a box face's plane) counts as "no constraint" via max/min.
        let t0 = a.min(b).max_element().max(0.0);
        let t1 = a.max(b).min_element().min(t_max);
        (t0 <= t1).then_some((t0, t1))
    }

    /// The range of the distance from `p` to points of the box: `(min, max)`.
    pub fn distance_range(&self, p: DVec3) -> (f64, f64) {
        let nearest = p.clamp(self.lo, self.hi);
        let far = DVec3::select((p - self.lo).cmpgt(self.hi - p), self.lo, self.hi);
        (p.distance(nearest), p.distance(far))
    }
}

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first index into `items`; inner: index of the right child (the left child
    /// follows its parent).
    first: u32,
    /// Leaf: number of items (> 0); inner: 0.
    count: u32,
}

/// The hierarchy. Items are the indices of the boxes it was built from.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    items: Vec<u32>,
}

impl Bvh {
    /// Builds the hierarchy over `boxes`; item `i` is `boxes[i]`. Empty boxes are left out.
    pub fn build(boxes: &[Aabb]) -> Bvh {
        assert!(u32::try_from(boxes.len()).is_ok(), "at most 2^32 items");
        let mut items: Vec<u32> = (0..boxes.len() as u32)
            .filter(|&i| !boxes[i as usize].is_empty())
            .collect();
        let mut nodes = Vec::with_capacity(2 * items.len() / LEAF_SIZE + 1);
        if !items.is_empty() {
            let n = items.len();
            build_node(boxes, &mut items, 0, n, &mut nodes);
        }
        Bvh { nodes, items }
    }

    /// Number of items indexed.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Whether nothing is indexed.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// The box around everything, or [`Aabb::EMPTY`].
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| n.bounds)
    }

    /// Calls `visit(item)` for every item whose leaf box contains `p` (the caller tests the
    /// item's own box if leaves hold several).
    #[inline]
    pub fn visit_point(&self, p: DVec3, visit: impl FnMut(u32)) {
        self.traverse(|b| b.contains(p), visit);
    }

    /// Calls `visit(item)` for every item in leaves overlapping `region`.
    pub fn visit_box(&self, region: &Aabb, visit: impl FnMut(u32)) {
        self.traverse(|b| b.overlaps(region), visit);
    }

    /// Calls `visit(item)` for every item in leaves the ray `origin + t * dir`, `0 <= t <=
    /// t_max`, passes through.
    pub fn visit_ray(&self, origin: DVec3, dir: DVec3, t_max: f64, visit: impl FnMut(u32)) {
        let inv = dir.recip();
        self.traverse(|b| b.ray_interval(origin, inv, t_max).is_some(), visit);
    }

    /// The item nearest to `p` by `item_distance` (the distance from `p` to the item, e.g. to
    /// a triangle's closest point), with that distance; `None` when nothing lies nearer than
    /// `max_distance`. Children are visited nearest box first, and a box no nearer than the best
    /// item so far is skipped, so `item_distance` must not be smaller than the distance from
    /// `p` to the item's box. Ties keep the first item found.
    pub fn nearest(
        &self,
        p: DVec3,
        max_distance: f64,
        mut item_distance: impl FnMut(u32) -> f64,
    ) -> Option<(u32, f64)> {
        let root = self.nodes.first()?;
        let box_distance_sq = |b: &Aabb| p.distance_squared(p.clamp(b.lo, b.hi));
        let mut best: Option<(u32, f64)> = None;
        let mut best_distance = max_distance;
        // Each level pops one entry and pushes at most two, so the stack never holds more than
        // the depth plus one entries.
        let mut stack = [(0u32, 0.0f64); STACK_DEPTH];
        stack[0] = (0, box_distance_sq(&root.bounds));
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let (idx, distance_sq) = stack[top];
            if distance_sq >= best_distance * best_distance {
                continue;
            }
            let node = &self.nodes[idx as usize];
            if node.count > 0 {
                let first = node.first as usize;
                for &item in &self.items[first..first + node.count as usize] {
                    let d = item_distance(item);
                    if d < best_distance {
                        best_distance = d;
                        best = Some((item, d));
                    }
                }
                continue;
            }
            let (left, right) = (idx + 1, node.first);
            let dl = box_distance_sq(&self.nodes[left as usize].bounds);
            let dr = box_distance_sq(&self.nodes[right as usize].bounds);
            let (near, far) = if dl <= dr {
                ((left, dl), (right, dr))
            } else {
                ((right, dr), (left, dl))
            };
            stack[top] = far;
            stack[top + 1] = near;
            top += 2;
        }
        best
    }

    #[inline]
    fn traverse(&self, mut enter: impl FnMut(&Aabb) -> bool, mut visit: impl FnMut(u32)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = [0u32; STACK_DEPTH];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            if !enter(&node.bounds) {
                continue;
            }
            if node.count > 0 {
                let first = node.first as usize;
                for &item in &self.items[first..first + node.count as usize] {
                    visit(item);
                }
            } else {
                let idx = stack[top];
                stack[top] = node.first;
                stack[top + 1] = idx + 1;
                top += 2;
            }
        }
    }
}

fn build_node(boxes: &[Aabb], items: &mut [u32], first: usize, end: usize, nodes: &mut Vec<Node>) {
    let slice = &mut items[first..end];
    let bounds = slice
        .iter()
        .fold(Aabb::EMPTY, |acc, &i| acc.union(&boxes[i as usize]));
    let me = nodes.len();
    nodes.push(Node {
        bounds,
        first: first as u32,
        count: slice.len() as u32,
    });
    if slice.len() <= LEAF_SIZE {
        return;
    }
    let centroids = slice.iter().fold(Aabb::EMPTY, |acc, &i| {
        let c = boxes[i as usize].center();
        acc.union(&Aabb { lo: c, hi: c })
    });
    let axis = centroids.size().max_position();
    let mid = slice.len() / 2;
    slice.select_nth_unstable_by(mid, |&a, &b| {
        let ca = boxes[a as usize].center()[axis];
        let cb = boxes[b as usize].center()[axis];
        ca.total_cmp(&cb)
    });
    build_node(boxes, items, first, first + mid, nodes);
    let right = nodes.len() as u32;
    build_node(boxes, items, first + mid, end, nodes);
    nodes[me].first = right;
    nodes[me].count = 0;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_boxes(n: usize) -> Vec<Aabb> {
        (0..n)
            .map(|i| {
                let c = DVec3::new((i % 10) as f64, ((i / 10) % 10) as f64, (i / 100) as f64);
                Aabb::around(c, DVec3::splat(0.3))
            })
            .collect()
    }

    #[test]
    fn point_box_and_ray_queries_match_brute_force() {
        let boxes = grid_boxes(1000);
        let bvh = Bvh::build(&boxes);
        assert_eq!(bvh.len(), 1000);
        for p in [
            DVec3::new(3.1, 4.2, 5.0),
            DVec3::new(3.5, 4.0, 5.0),
            DVec3::new(-1.0, 0.0, 0.0),
        ] {
            let mut got = Vec::new();
            bvh.visit_point(p, |i| {
                if boxes[i as usize].contains(p) {
                    got.push(i)
                }
            });
            got.sort_unstable();
            let want: Vec<u32> = (0..1000u32)
                .filter(|&i| boxes[i as usize].contains(p))
                .collect();
            assert_eq!(got, want, "at {p}");
        }
        let region = Aabb::new(DVec3::new(1.5, 1.5, 1.5), DVec3::new(3.2, 2.1, 2.9));
        let mut got = Vec::new();
        bvh.visit_box(&region, |i| {
            if boxes[i as usize].overlaps(&region) {
                got.push(i)
            }
        });
        got.sort_unstable();
        let want: Vec<u32> = (0..1000u32)
            .filter(|&i| boxes[i as usize].overlaps(&region))
            .collect();
        assert_eq!(got, want);
        assert!(!want.is_empty());

        let (o, d) = (DVec3::new(-1.0, 2.0, 3.0), DVec3::X);
        let inv = d.recip();
        let mut got = Vec::new();
        bvh.visit_ray(o, d, 100.0, |i| {
            if boxes[i as usize].ray_interval(o, inv, 100.0).is_some() {
                got.push(i)
            }
        });
        got.sort_unstable();
        assert_eq!(got, (0..10).map(|k| 320 + k).collect::<Vec<u32>>());
    }

    #[test]
    fn empty_and_degenerate_inputs() {
        let bvh = Bvh::build(&[]);
        assert!(bvh.is_empty());
        bvh.visit_point(DVec3::ZERO, |_| panic!("nothing to visit"));
        let same = vec![Aabb::around(DVec3::ONE, DVec3::splat(0.1)); 100];
        let bvh = Bvh::build(&same);
        let mut n = 0;
        bvh.visit_point(DVec3::ONE, |_| n += 1);
        assert_eq!(n, 100);
        let with_empty = [Aabb::EMPTY, Aabb::around(DVec3::ZERO, DVec3::ONE)];
        assert_eq!(Bvh::build(&with_empty).len(), 1);
    }

    #[test]
    fn nearest_matches_brute_force() {
        let boxes = grid_boxes(1000);
        let bvh = Bvh::build(&boxes);
        let centre_distance = |p: DVec3, i: u32| p.distance(boxes[i as usize].center());
        for p in [
            DVec3::new(3.1, 4.2, 5.0),
            DVec3::new(-7.0, 20.0, 2.5),
            DVec3::new(4.5, 4.5, 4.5),
        ] {
            let mut calls = 0;
            let (item, d) = bvh
                .nearest(p, f64::INFINITY, |i| {
                    calls += 1;
                    centre_distance(p, i)
                })
                .unwrap();
            let want = (0..1000u32)
                .map(|i| centre_distance(p, i))
                .fold(f64::INFINITY, f64::min);
            assert_eq!(d, want, "at {p}");
            assert_eq!(centre_distance(p, item), want);
            assert!(calls < 200, "{calls} items measured at {p}: no pruning");
        }
        let far = DVec3::splat(100.0);
        assert!(bvh.nearest(far, 1.0, |i| centre_distance(far, i)).is_none());
        assert!(
            Bvh::build(&[])
                .nearest(far, f64::INFINITY, |_| 0.0)
                .is_none()
        );
    }

    #[test]
    fn distance_range_bounds_the_distance() {
        let b = Aabb::new(DVec3::ZERO, DVec3::ONE);
        let (lo, hi) = b.distance_range(DVec3::new(2.0, 0.5, 0.5));
        assert_eq!(lo, 1.0);
        assert!((hi - (4.0f64 + 0.25 + 0.25).sqrt()).abs() < 1e-12);
        assert_eq!(b.distance_range(DVec3::splat(0.5)).0, 0.0);
    }
}
