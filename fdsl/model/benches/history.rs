//! History-independent cost: evaluation rate of an object with 10 to 10^5 small random edits
//! (union and carve strokes of small balls and boxes, some paint), at the same random points.
//! The goal is the rate at 10^5 edits within 2x of the rate at 10.
//!
//! `block_values_point` and `block_values_bulk` compare the two ways to evaluate a mesher's
//! blocks (lattices of 9^3 points in boxes of edge 1/8): the sampler point by point, and the
//! sampler restricted to each box (`Sampler::restrict`, its cost included) evaluating the
//! box's lattice in one call.
//!
//! `cargo bench -p model --bench history`

use divan::{Bencher, black_box};
use glam::DVec3;
use model::bvh::Aabb;

#[path = "shared/history_workload.rs"]
mod history_workload;
use history_workload::{N_POINTS, Rng, boxes, object_with_edits, points};

fn main() {
    divan::main();
}

const EDIT_COUNTS: [usize; 4] = [10, 1_000, 10_000, 100_000];

#[divan::bench(args = EDIT_COUNTS, sample_count = 20)]
fn value(bencher: Bencher, n_edits: usize) {
    let mut sampler = object_with_edits(n_edits).sampler();
    let points = points();
    bencher
        .counter(divan::counter::ItemsCount::new(N_POINTS))
        .bench_local(|| {
            let mut sum = 0.0;
            for p in &points {
                sum += sampler.value(*p, 0.0);
            }
            black_box(sum)
        });
}

#[divan::bench(args = EDIT_COUNTS, sample_count = 20)]
fn gradient(bencher: Bencher, n_edits: usize) {
    let mut sampler = object_with_edits(n_edits).sampler();
    let points = points();
    bencher
        .counter(divan::counter::ItemsCount::new(N_POINTS))
        .bench_local(|| {
            let mut sum = DVec3::ZERO;
            for p in &points {
                sum += sampler.gradient(*p, 0.0).1;
            }
            black_box(sum)
        });
}

#[divan::bench(args = EDIT_COUNTS, sample_count = 20)]
fn color(bencher: Bencher, n_edits: usize) {
    let mut sampler = object_with_edits(n_edits).sampler();
    let points = points();
    bencher
        .counter(divan::counter::ItemsCount::new(N_POINTS))
        .bench_local(|| {
            let mut sum = 0.0;
            for p in &points {
                sum += sampler.diffuse(*p, 0.0)[0];
            }
            black_box(sum)
        });
}

/// Boxes of an octree's finer levels (edge 1/32, about 1/64 of the object; see `boxes`).
#[divan::bench(args = EDIT_COUNTS, sample_count = 20)]
fn interval(bencher: Bencher, n_edits: usize) {
    let mut sampler = object_with_edits(n_edits).sampler();
    let boxes = boxes();
    bencher
        .counter(divan::counter::ItemsCount::new(N_POINTS))
        .bench_local(|| {
            let mut sum = 0.0;
            for b in &boxes {
                sum += sampler.interval(b, 0.0).hi;
            }
            black_box(sum)
        });
}

/// Boxes of edge 1/8 (a mesher block at depth 7 over 2.5 units is 0.156) with their 9^3
/// lattice points.
fn blocks() -> Vec<(Aabb, Vec<DVec3>)> {
    let mut rng = Rng(0x5eed_b10c);
    (0..N_BLOCKS)
        .map(|_| {
            let region = Aabb::around(rng.in_cube(0.9), DVec3::splat(1.0 / 16.0));
            let step = region.size() / 8.0;
            let lattice = (0..729)
                .map(|i| {
                    let k = DVec3::new((i % 9) as f64, ((i / 9) % 9) as f64, (i / 81) as f64);
                    (region.lo + step * k).min(region.hi)
                })
                .collect();
            (region, lattice)
        })
        .collect()
}

const N_BLOCKS: usize = 8;

#[divan::bench(args = EDIT_COUNTS, sample_count = 20)]
fn block_values_point(bencher: Bencher, n_edits: usize) {
    let mut sampler = object_with_edits(n_edits).sampler();
    let blocks = blocks();
    bencher
        .counter(divan::counter::ItemsCount::new(N_BLOCKS * 729))
        .bench_local(|| {
            let mut sum = 0.0;
            for (_, lattice) in &blocks {
                for p in lattice {
                    sum += sampler.value(*p, 0.0);
                }
            }
            black_box(sum)
        });
}

#[divan::bench(args = EDIT_COUNTS, sample_count = 20)]
fn block_values_bulk(bencher: Bencher, n_edits: usize) {
    let sampler = object_with_edits(n_edits).sampler();
    let blocks = blocks();
    let mut out = vec![0.0; 729];
    bencher
        .counter(divan::counter::ItemsCount::new(N_BLOCKS * 729))
        .bench_local(|| {
            let mut sum = 0.0;
            for (region, lattice) in &blocks {
                sampler.restrict(region, 0.0).values(lattice, &mut out);
                sum += out.iter().sum::<f64>();
            }
            black_box(sum)
        });
}

/// Applying edits (compile the stroke and append; indexing happens on `prepare`).
#[divan::bench(sample_count = 20)]
fn apply_and_index_10k(bencher: Bencher) {
    bencher.bench_local(|| black_box(object_with_edits(10_000).history().len()));
}
