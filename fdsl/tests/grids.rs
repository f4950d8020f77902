//! Sampled grids called from formulas: every evaluator agrees with the grid's own trilinear
//! interpolation, intervals enclose it, tapes simplify around it, and misuse is a located
//! error.
#![allow(
    clippy::unwrap_used,
    reason = "test helpers unwrap what a test expects to succeed"
)]

use std::sync::Arc;

use fdsl::eval::{BulkEval, GradBulkEval, GradEval, Interval, IntervalEval, PointEval};
use fdsl::grid::{Grid, MAX_GRIDS};
use fdsl::{Function, Options};

/// A 5 x 4 x 3 grid of bytes that are not a linear function of the index, spanning
/// [-1, 1] x [-0.75, 0.75] x [-0.5, 0.5], standing for values in [-1, 1].
fn bumpy(name: &str) -> Arc<Grid> {
    let bytes: Vec<u8> = (0..60u32).map(|n| ((n * 97 + 13) % 251) as u8).collect();
    let grid = Grid::from_raw(
        name,
        [5, 4, 3],
        [-1.0, -0.75, -0.5],
        [0.5; 3],
        [-1.0, 1.0],
        &bytes,
    );
    Arc::new(grid.unwrap())
}

fn with(grids: &[Arc<Grid>]) -> Options {
    Options {
        grids: grids.to_vec().into(),
        ..Options::default()
    }
}

fn points() -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    for i in 0..9 {
        for j in 0..7 {
            for k in 0..5 {
                // Inside, on the faces and outside, off the sample lattice.
                out.push([
                    -1.3 + 0.33 * i as f64,
                    -1.0 + 0.31 * j as f64,
                    -0.7 + 0.29 * k as f64,
                ]);
            }
        }
    }
    out
}

#[test]
fn every_evaluator_computes_the_grids_trilinear_interpolation() {
    let grid = bumpy("scan");
    let f =
        Function::parse_with("2 * scan(x, y, z) - 0.25 * x", with(&[Arc::clone(&grid)])).unwrap();
    let tape = f.tape();
    let ps = points();
    let mut point = PointEval::new(&tape);
    let mut grad = GradEval::new(&tape);
    let want: Vec<f64> = ps
        .iter()
        .map(|p| 2.0 * grid.value(*p) - 0.25 * p[0])
        .collect();
    for (p, w) in ps.iter().zip(&want) {
        assert_eq!(point.eval([p[0], p[1], p[2], 0.0]), *w, "{p:?}");
        let g = grad.eval([p[0], p[1], p[2], 0.0]);
        assert_eq!(g.v, *w);
        let (_, dg) = grid.value_grad(*p);
        let expected = [2.0 * dg[0] - 0.25, 2.0 * dg[1], 2.0 * dg[2]];
        for a in 0..3 {
            assert!(
                (g.gradient()[a] - expected[a]).abs() < 1e-12,
                "{p:?} {:?} {expected:?}",
                g.gradient()
            );
        }
    }
    // The gradient is the derivative: central differences inside a cell agree.
    let p = [0.1, 0.2, -0.1];
    let g = grad.eval([p[0], p[1], p[2], 0.0]).gradient();
    let h = 1e-6;
    for a in 0..3 {
        let (mut lo, mut hi) = ([p[0], p[1], p[2], 0.0], [p[0], p[1], p[2], 0.0]);
        lo[a] -= h;
        hi[a] += h;
        let numeric = (point.eval(hi) - point.eval(lo)) / (2.0 * h);
        assert!(
            (numeric - g[a]).abs() < 1e-6,
            "axis {a}: {numeric} {}",
            g[a]
        );
    }
    let xs: Vec<f32> = ps.iter().map(|p| p[0] as f32).collect();
    let ys: Vec<f32> = ps.iter().map(|p| p[1] as f32).collect();
    let zs: Vec<f32> = ps.iter().map(|p| p[2] as f32).collect();
    let mut bulk = vec![0.0f32; ps.len()];
    BulkEval::new(&tape).eval(&xs, &ys, &zs, 0.0, &mut bulk);
    let mut grads = vec![Default::default(); ps.len()];
    GradBulkEval::new(&tape).eval(&xs, &ys, &zs, 0.0, &mut grads);
    for i in 0..ps.len() {
        let p32 = [f64::from(xs[i]), f64::from(ys[i]), f64::from(zs[i])];
        let w32 = 2.0 * grid.value(p32) - 0.25 * p32[0];
        assert!(
            (f64::from(bulk[i]) - w32).abs() < 1e-5,
            "{:?}: {} {w32}",
            ps[i],
            bulk[i]
        );
        assert!((f64::from(grads[i].v) - w32).abs() < 1e-5);
    }
}

#[test]
fn intervals_enclose_every_value_and_tapes_simplify_around_samples() {
    let grid = bumpy("scan");
    let f =
        Function::parse_with("min(scan(x, y, z), x - 0.9)", with(&[Arc::clone(&grid)])).unwrap();
    let tape = f.tape();
    let mut interval = IntervalEval::new(&tape);
    let mut point = PointEval::new(&tape);
    for (lo, hi) in [
        ([-0.2, -0.2, -0.2], [0.3, 0.1, 0.2]),
        ([-3.0, -3.0, -3.0], [3.0, 3.0, 3.0]),
        ([0.9, 0.7, 0.45], [2.0, 0.8, 0.5]),
    ] {
        let i = interval.eval(
            [0, 1, 2]
                .map(|a| Interval::new(lo[a], hi[a]))
                .into_iter()
                .chain([Interval::point(0.0)])
                .collect::<Vec<_>>()
                .try_into()
                .unwrap(),
        );
        for s in 0..=20 {
            let f = f64::from(s) / 20.0;
            let p =
                [0, 1, 2].map(|a| lo[a] + (hi[a] - lo[a]) * ((f * (a as f64 + 1.0) * 7.3) % 1.0));
            let v = point.eval([p[0], p[1], p[2], 0.0]);
            assert!(i.contains(v), "{v} outside {i:?} at {p:?}");
        }
    }
    // Far to the left, x - 0.9 decides the minimum: the sample drops out of the tape.
    let left = [
        Interval::new(-30.0, -20.0),
        Interval::new(-0.1, 0.1),
        Interval::new(-0.1, 0.1),
        Interval::point(0.0),
    ];
    interval.eval(left);
    let simpler = tape.simplify(interval.choices(), fdsl::tape::Fidelity::Exact);
    assert!(simpler.len() < tape.len());
    assert_eq!(PointEval::new(&simpler).eval([-25.0, 0.0, 0.0, 0.0]), -25.9);
    // A NaN coordinate gives NaN, and intervals say it may.
    assert!(point.eval([f64::NAN, 0.0, 0.0, 0.0]).is_nan());
    let nan = interval.eval([
        Interval::new(0.0, 1.0),
        Interval::point(f64::NAN),
        Interval::point(0.0),
        Interval::point(0.0),
    ]);
    assert!(nan.has_nan());
}

#[test]
fn a_grid_at_constant_coordinates_folds_and_two_grids_are_told_apart() {
    let (a, b) = (bumpy("a"), bumpy("b_scan"));
    let f = Function::parse_with(
        "a(0.1, 0.2, 0.3) + b_scan(z, y, x)",
        with(&[Arc::clone(&a), Arc::clone(&b)]),
    )
    .unwrap();
    let tape = f.tape();
    assert_eq!(tape.grids().len(), 1, "the constant call folded away");
    let v = PointEval::new(&tape).eval([0.3, -0.2, 0.1, 0.0]);
    assert_eq!(v, a.value([0.1, 0.2, 0.3]) + b.value([0.1, -0.2, 0.3]));
}

#[test]
fn misusing_a_grid_is_a_located_error() {
    let scan = bumpy("scan");
    let error = |text: &str, options: Options| {
        let e = Function::parse_with(text, options).unwrap_err();
        let d = e.diagnostics.iter().find(|d| d.is_error()).unwrap().clone();
        (d.span.start, e.to_string())
    };
    let (at, text) = error("1 - scan(x, y)", with(&[Arc::clone(&scan)]));
    assert_eq!(at, 4);
    assert!(
        text.contains("`scan` takes 3 arguments, but 2 were given"),
        "{text}"
    );
    let (at, text) = error("scna(x, y, z)", with(&[Arc::clone(&scan)]));
    assert_eq!(at, 0);
    assert!(text.contains("did you mean `scan`?"), "{text}");
    // Without the grid, the name is unknown.
    let (_, text) = error("scan(x, y, z)", Options::default());
    assert!(text.contains("unknown function `scan`"), "{text}");
    let twice = with(&[bumpy("scan"), bumpy("scan")]);
    assert!(
        error("scan(x, y, z)", twice)
            .1
            .contains("two grids are named `scan`")
    );
    let many: Vec<Arc<Grid>> = (0..=MAX_GRIDS).map(|i| bumpy(&format!("g{i}"))).collect();
    assert!(error("g0(x, y, z)", with(&many)).1.contains("at most 8"));
}

/// A valid 3 x 3 x 3 NRRD file.
fn nrrd_file() -> Vec<u8> {
    let mut file = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 3 3 3\nspacings: 0.5 0.5 0.5\nspace origin: (-0.5,-0.5,-0.5)\nencoding: raw\n\n".to_vec();
    file.extend((0..27u8).map(|b| b * 9));
    file
}

proptest::proptest! {
    /// Any bytes read as NRRD are a grid or an error, never a panic.
    #[test]
    fn any_bytes_are_a_grid_or_an_nrrd_error(bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..400)) {
        let _ = Grid::from_nrrd("scan", &bytes, [0.0, 1.0]);
    }

    /// A valid file with bytes changed anywhere (header or samples) is a grid whose samples
    /// are the file's tail, or an error.
    #[test]
    fn changed_files_are_a_grid_or_an_nrrd_error(
        changes in proptest::collection::vec((0usize..140, proptest::prelude::any::<u8>()), 1..6),
    ) {
        let mut file = nrrd_file();
        for (at, byte) in changes {
            let at = at % file.len();
            file[at] = byte;
        }
        if let Ok(grid) = Grid::from_nrrd("scan", &file, [0.0, 1.0]) {
            let samples = &grid.data().samples;
            proptest::prop_assert!(file.ends_with(samples));
            proptest::prop_assert_eq!(samples.len(), grid.data().size.iter().map(|&s| usize::from(s)).product::<usize>());
        }
    }
}

#[test]
fn the_valid_file_reads() {
    let grid = Grid::from_nrrd("scan", &nrrd_file(), [0.0, 1.0]).unwrap();
    assert_eq!(grid.extent(), ([-0.5; 3], [0.5; 3]));
}
