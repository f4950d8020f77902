//! A domain that fits a solid, found from its function by interval evaluation, so that an
//! object made from a formula alone is never silently cut off by a guessed box.
//!
//! The search covers the cube `±MAX_FIT_HALF_SIZE` and keeps the cells where the function may
//! be `>= 0` (its interval's upper bound, or a possible NaN), splitting them down to
//! [`FIT_DEPTH`] levels; cells where the function is surely `>= 0` are kept whole. The box of
//! the kept cells, grown by one finest cell, is the domain. Interval bounds enclose the true
//! values, so the solid lies inside the domain; they may be loose, so the domain may be
//! larger than the solid. A solid that reaches the search cube's faces is unbounded; one with
//! no cell kept is empty.

use glam::DVec3;

use super::space::Domain;
use fdsl::eval::{BOX_CHUNK, Interval, IntervalBulkEval};
use fdsl::tape::Tape;

/// Half the edge of the cube searched for the solid (scene units).
pub const MAX_FIT_HALF_SIZE: f64 = 64.0;
/// Levels of splitting: the finest cell is `2 * MAX_FIT_HALF_SIZE / 2^FIT_DEPTH` wide.
pub const FIT_DEPTH: u32 = 11;
/// Cells evaluated at most; a function whose boundary needs more is refused.
pub const MAX_FIT_CELLS: usize = 400_000;

/// Why no domain fits.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FitError {
    /// The solid reaches the search cube's faces.
    #[error(
        "the solid reaches ±{MAX_FIT_HALF_SIZE} (it is unbounded, like a half-space); bound it, \
         for example `(...) & ({MAX_FIT_HALF_SIZE}-abs(x))`, or give the object a domain"
    )]
    Unbounded,
    /// The function is below zero everywhere searched.
    #[error("the solid is empty: the function is below 0 everywhere within ±{MAX_FIT_HALF_SIZE}")]
    Empty,
    /// The boundary needed more than [`MAX_FIT_CELLS`] cells (or the caller's budget).
    #[error(
        "the solid's boundary is too intricate to bound within {MAX_FIT_CELLS} cells; give the \
         object a domain"
    )]
    TooComplex,
}

/// The domain of the solid `tape >= 0` at time `t` (the tape's first output is the value).
///
/// Cells are bounded [`BOX_CHUNK`] at a time by the bulk interval evaluator, whose bounds are
/// the box-by-box ones; the kept cells, and so the domain, do not depend on that order.
///
/// This is the one rule for an implicit solid made without a domain, wherever it is made:
/// the command line's `new:` and `shape:`, and an FVRML file's `FGeometry` without
/// `bboxSize`. The object carries the domain found, so peers take it from the op and never
/// fit again.
pub fn fit_domain(tape: &Tape, t: f64) -> Result<Domain, FitError> {
    fit_domain_within(tape, t, MAX_FIT_CELLS).0
}

/// [`fit_domain`] evaluating at most `max_cells` cells (at most [`MAX_FIT_CELLS`]; past it,
/// [`FitError::TooComplex`]), and the number of cells it evaluated: what a caller with a
/// budget over several solids counts (an FVRML load).
pub fn fit_domain_within(
    tape: &Tape,
    t: f64,
    max_cells: usize,
) -> (Result<Domain, FitError>, usize) {
    let max_cells = max_cells.min(MAX_FIT_CELLS);
    let mut n_evaluated = 0usize;
    let fitted = search(tape, t, max_cells, &mut n_evaluated);
    (fitted, n_evaluated.min(max_cells))
}

fn search(
    tape: &Tape,
    t: f64,
    max_cells: usize,
    n_evaluated: &mut usize,
) -> Result<Domain, FitError> {
    let mut eval = IntervalBulkEval::new(tape);
    let finest = 2.0 * MAX_FIT_HALF_SIZE / f64::from(1u32 << FIT_DEPTH);
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    let mut cells = vec![Cell {
        corner: DVec3::splat(-MAX_FIT_HALF_SIZE),
        edge: 2.0 * MAX_FIT_HALF_SIZE,
        depth: 0,
    }];
    let mut batch = Vec::with_capacity(BOX_CHUNK);
    let mut boxes = [[Interval::point(0.0); 4]; BOX_CHUNK];
    let mut bounds = [Interval::point(0.0); BOX_CHUNK];
    while !cells.is_empty() {
        let n = cells.len().min(BOX_CHUNK);
        *n_evaluated += n;
        if *n_evaluated > max_cells {
            return Err(FitError::TooComplex);
        }
        batch.clear();
        batch.extend(cells.drain(cells.len() - n..));
        for (b, cell) in boxes.iter_mut().zip(&batch) {
            let axis = |a: usize| Interval::new(cell.corner[a], cell.corner[a] + cell.edge);
            *b = [axis(0), axis(1), axis(2), Interval::point(t)];
        }
        eval.eval(&boxes[..n], &mut bounds[..n]);
        for (cell, v) in batch.iter().zip(&bounds) {
            let maybe_inside = v.hi >= 0.0 || v.has_nan();
            if !maybe_inside {
                continue;
            }
            let surely_inside = v.lo >= 0.0 && !v.has_nan();
            if surely_inside || cell.depth == FIT_DEPTH {
                let far = cell.corner + DVec3::splat(cell.edge);
                let touches_edge = cell.corner.min_element() <= -MAX_FIT_HALF_SIZE
                    || far.max_element() >= MAX_FIT_HALF_SIZE;
                if touches_edge {
                    return Err(FitError::Unbounded);
                }
                lo = lo.min(cell.corner);
                hi = hi.max(far);
                continue;
            }
            cell.split_into(&mut cells);
        }
    }
    if lo.x > hi.x {
        return Err(FitError::Empty);
    }
    let (lo, hi) = (lo - DVec3::splat(finest), hi + DVec3::splat(finest));
    Ok(Domain::new((lo + hi) / 2.0, hi - lo))
}

/// A cube of the search: its lowest corner, its edge and how many splits made it.
#[derive(Clone, Copy)]
struct Cell {
    corner: DVec3,
    edge: f64,
    depth: u32,
}

impl Cell {
    /// Pushes the cell's eight halves onto `cells`, x fastest.
    fn split_into(&self, cells: &mut Vec<Cell>) {
        let half = self.edge / 2.0;
        for k in 0..8u32 {
            let offset = DVec3::new(
                f64::from(k & 1) * half,
                f64::from(k >> 1 & 1) * half,
                f64::from(k >> 2 & 1) * half,
            );
            cells.push(Cell {
                corner: self.corner + offset,
                edge: half,
                depth: self.depth + 1,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fdsl::Function;

    fn fit(src: &str) -> Result<Domain, FitError> {
        fit_domain(&Function::parse(src).unwrap().tape(), 0.0)
    }

    #[test]
    fn a_ball_off_centre_gets_a_domain_around_it_and_inside_the_solid_is_kept() {
        // The example: `new:` used to cut this flat at x = 1.1.
        let d = fit("0.3-sqrt((x-1)^2+y^2+z^2)").unwrap();
        let b = d.aabb();
        assert!(b.lo.x <= 0.7 && b.hi.x >= 1.3, "{d:?}");
        assert!(b.lo.y <= -0.3 && b.hi.y >= 0.3, "{d:?}");
        assert!(b.hi.x < 1.6 && b.lo.x > 0.4, "tight enough: {d:?}");
        let big = fit("5-sqrt(x^2+y^2+z^2)").unwrap().aabb();
        assert!(big.lo.x <= -5.0 && big.hi.z >= 5.0, "{big:?}");
        let slab = fit("min(1-abs(x), min(2-abs(y), 3-abs(z-10)))")
            .unwrap()
            .aabb();
        assert!(
            slab.lo.z <= 7.0 && slab.hi.z >= 13.0 && slab.hi.x < 1.5,
            "{slab:?}"
        );
    }

    #[test]
    fn every_reference_solid_fits_inside_its_domain() {
        for (name, src) in fdsl::models::surface_models() {
            let f = Function::parse(src).unwrap();
            let d = fit_domain(&f.tape(), 0.0).unwrap_or_else(|e| panic!("{name}: {e}"));
            // Points sampled on the domain's faces are outside the solid.
            let b = d.aabb();
            let mut eval = fdsl::eval::PointEval::new(&f.tape());
            for i in 0..=8 {
                for j in 0..=8 {
                    let (u, v) = (f64::from(i) / 8.0, f64::from(j) / 8.0);
                    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
                    for p in [
                        [b.lo.x, lerp(b.lo.y, b.hi.y, u), lerp(b.lo.z, b.hi.z, v)],
                        [b.hi.x, lerp(b.lo.y, b.hi.y, u), lerp(b.lo.z, b.hi.z, v)],
                        [lerp(b.lo.x, b.hi.x, u), b.lo.y, lerp(b.lo.z, b.hi.z, v)],
                        [lerp(b.lo.x, b.hi.x, u), lerp(b.lo.y, b.hi.y, v), b.hi.z],
                    ] {
                        let value = eval.eval([p[0], p[1], p[2], 0.0]);
                        assert!(value < 0.0, "{name}: {value} at {p:?} on {d:?}");
                    }
                }
            }
        }
    }

    /// The search as it was, one cell at a time in depth-first order through the box-by-box
    /// evaluator: the batched search must find the same domains.
    fn fit_box_by_box(tape: &Tape) -> Result<Domain, FitError> {
        let mut eval = fdsl::eval::IntervalEval::new(tape);
        let finest = 2.0 * MAX_FIT_HALF_SIZE / f64::from(1u32 << FIT_DEPTH);
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        let mut cells = vec![(DVec3::splat(-MAX_FIT_HALF_SIZE), 2.0 * MAX_FIT_HALF_SIZE, 0)];
        while let Some((corner, edge, depth)) = cells.pop() {
            let axis = |a: usize| Interval::new(corner[a], corner[a] + edge);
            let v = eval.eval([axis(0), axis(1), axis(2), Interval::point(0.0)]);
            if !(v.hi >= 0.0 || v.has_nan()) {
                continue;
            }
            if (v.lo >= 0.0 && !v.has_nan()) || depth == FIT_DEPTH {
                let far = corner + DVec3::splat(edge);
                if corner.min_element() <= -MAX_FIT_HALF_SIZE
                    || far.max_element() >= MAX_FIT_HALF_SIZE
                {
                    return Err(FitError::Unbounded);
                }
                (lo, hi) = (lo.min(corner), hi.max(far));
                continue;
            }
            for k in 0..8u32 {
                let offset = DVec3::new(
                    f64::from(k & 1),
                    f64::from(k >> 1 & 1),
                    f64::from(k >> 2 & 1),
                ) * (edge / 2.0);
                cells.push((corner + offset, edge / 2.0, depth + 1));
            }
        }
        if lo.x > hi.x {
            return Err(FitError::Empty);
        }
        let (lo, hi) = (lo - DVec3::splat(finest), hi + DVec3::splat(finest));
        Ok(Domain::new((lo + hi) / 2.0, hi - lo))
    }

    #[test]
    fn batched_search_finds_the_box_by_box_domains() {
        let sources = fdsl::models::REFERENCE_MODELS
            .into_iter()
            .map(|(_, src)| src)
            .chain([
                "0.3-sqrt((x-1)^2+y^2+z^2)",
                "min(1-abs(x), min(2-abs(y), 3-abs(z-10)))",
                "sqrt(0.25-x^2-y^2-z^2) - 0.1",
                "x",
                "-1",
            ]);
        for src in sources {
            let tape = Function::parse(src).unwrap().tape();
            assert_eq!(fit_domain(&tape, 0.0), fit_box_by_box(&tape), "{src}");
        }
    }

    #[test]
    fn unbounded_and_empty_solids_are_refused_with_a_reason() {
        assert_eq!(fit("x"), Err(FitError::Unbounded));
        assert_eq!(fit("1"), Err(FitError::Unbounded));
        assert_eq!(fit("-1"), Err(FitError::Empty));
        assert_eq!(fit("-1-x^2"), Err(FitError::Empty));
        let message = FitError::Unbounded.to_string();
        assert!(message.contains("abs(x)"), "{message}");
    }
}
