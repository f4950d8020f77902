//! Where a function of one variable changes side within a bracket: the crossing of a surface
//! along a segment, as the haptic servo locates it every tick a tip enters or leaves a solid.
//!
//! Sides follow the sign convention: a value `>= 0` is inside, anything else (a NaN too) is
//! outside. [`crossing`] narrows a bracket whose ends lie on opposite sides by false position
//! with the Illinois correction (the secant through the bracket's ends; an end kept twice in
//! a row has its value halved, so that the other end moves too), and bisects whenever three
//! steps did not halve the bracket or the secant leaves it, and steps at least half the tolerance off an end. Near a surface a signed distance
//! is nearly linear along a short segment, so a crossing takes a handful of evaluations where
//! bisection to the same width takes 30; a kink, a jump or a NaN costs at most
//! [`MAX_CROSSING_STEPS`] evaluations, as bisection did.

/// The most evaluations [`crossing`] makes: bisection's count to reach [`CROSSING_TOLERANCE`].
pub const MAX_CROSSING_STEPS: usize = 30;
/// The bracket's width, in the parameter's units over a bracket of width 1, below which
/// [`crossing`] stops: 2^-30, where 30 bisections stop.
pub const CROSSING_TOLERANCE: f64 = 1.0 / (1u64 << 30) as f64;

/// The point of `[a, b]` nearest `a`'s side change that lies on `b`'s side: `f(a)` is `fa` and
/// `f(b)` is `fb`, on opposite sides (`>= 0` is inside). It narrows the bracket to
/// [`CROSSING_TOLERANCE`] times `b - a` or for at most [`MAX_CROSSING_STEPS`] evaluations of
/// `f`, and returns the end on `b`'s side; `a` may be greater than `b`. Given ends on the same
/// side it returns `b` without evaluating.
pub fn crossing(a: f64, fa: f64, b: f64, fb: f64, mut f: impl FnMut(f64) -> f64) -> f64 {
    let side_b = fb >= 0.0;
    if (fa >= 0.0) == side_b {
        return b;
    }
    // The bracket as offsets from `a` along `b - a`, so that `[lo, hi]` runs from 0 to 1.
    let span = b - a;
    let at = |s: f64| if s >= 1.0 { b } else { a + span * s };
    let (mut lo, mut f_lo, mut hi, mut f_hi) = (0.0f64, fa, 1.0f64, fb);
    const NUDGE: f64 = 0.5 * CROSSING_TOLERANCE;
    // Which end moved last (`Some(true)`: `hi`), and the bracket's widths one, two and three
    // steps ago: the Illinois correction needs two steps at one end before the other moves.
    let mut moved_hi = None;
    let mut widths = [f64::INFINITY; 3];
    for _ in 0..MAX_CROSSING_STEPS {
        let width = hi - lo;
        if width <= CROSSING_TOLERANCE {
            break;
        }
        let secant = lo - f_lo * width / (f_hi - f_lo);
        // A secant on an end (a value of exactly zero there, or one too small to move it) is
        // pushed half the tolerance inside, so that a root at an end closes the bracket.
        let s = if width > 0.5 * widths[2] || !(secant >= lo && secant <= hi) {
            0.5 * (lo + hi)
        } else {
            secant.clamp(lo + NUDGE, hi - NUDGE)
        };
        let f_s = f(at(s));
        if (f_s >= 0.0) == side_b {
            (hi, f_hi) = (s, f_s);
            if moved_hi == Some(true) {
                f_lo *= 0.5;
            }
            moved_hi = Some(true);
        } else {
            (lo, f_lo) = (s, f_s);
            if moved_hi == Some(false) {
                f_hi *= 0.5;
            }
            moved_hi = Some(false);
        }
        widths = [width, widths[0], widths[1]];
    }
    at(hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// `crossing` of `f` over `[a, b]`, with the evaluations it made.
    fn counted(a: f64, b: f64, f: impl Fn(f64) -> f64) -> (f64, usize) {
        let mut n = 0;
        let s = crossing(a, f(a), b, f(b), |s| {
            n += 1;
            f(s)
        });
        (s, n)
    }

    /// A ball's signed distance along a chord that leaves it near `s = 0.7`.
    fn ball_along_chord(s: f64) -> f64 {
        let p = glam::DVec3::new(-1.2, 0.3, 0.1).lerp(glam::DVec3::new(1.2, 0.3, 0.1), s);
        0.9 - p.length()
    }

    #[test]
    fn a_smooth_crossing_takes_a_handful_of_evaluations_to_bisections_width() {
        // Entering and leaving the ball, and a straight line, each from both ends.
        let line: fn(f64) -> f64 = |s| 0.3 - s;
        let cases = [
            (0.0, 0.5, ball_along_chord as fn(f64) -> f64),
            (0.5, 1.0, ball_along_chord),
            (0.0, 1.0, line),
        ];
        for (a, b, f) in cases {
            for (a, b) in [(a, b), (b, a)] {
                let (s, n) = counted(a, b, f);
                assert!(n <= 6, "{n} evaluations over [{a}, {b}]");
                assert_eq!(f(s) >= 0.0, f(b) >= 0.0, "on b's side");
                let other = s - (b - a) * CROSSING_TOLERANCE;
                assert_ne!(
                    f(other) >= 0.0,
                    f(b) >= 0.0,
                    "within the tolerance of the change"
                );
            }
        }
    }

    #[test]
    fn a_jump_or_a_nan_costs_at_most_bisections_evaluations() {
        let jump = |s: f64| if s < 0.3 { -1.0 } else { 1.0 };
        let nan_inside = |s: f64| if s < 0.6 { f64::NAN } else { 2.0 };
        let kink = |s: f64| 1e-12 * (s - 0.41).abs().max(1e-3) * (s - 0.41).signum();
        for f in [jump, nan_inside, kink] {
            let (s, n) = counted(0.0, 1.0, f);
            assert!(n <= MAX_CROSSING_STEPS);
            assert!(f(s) >= 0.0);
        }
        // A jump is found to within 2^-10 however the secant falls: the safeguard bisects.
        let (s, _) = counted(0.0, 1.0, jump);
        assert!((s - 0.3).abs() < 1.0 / 1024.0, "{s}");
    }

    #[test]
    fn ends_on_one_side_give_b_without_evaluating() {
        let (s, n) = counted(0.0, 1.0, |s| s + 1.0);
        assert_eq!((s, n), (1.0, 0));
    }

    proptest! {
        /// For a smooth function with one root, wavy or not, from either end, the answer lies
        /// on `b`'s side within the tolerance of the root, in a few evaluations.
        #[test]
        fn the_answer_is_on_bs_side_next_to_the_change(
            root in 0.001f64..0.999,
            wave in 0.0f64..3.0,
            flip in any::<bool>(),
        ) {
            let g = |s: f64| {
                let v = (s - root) + wave * 0.1 * (40.0 * (s - root)).sin() * (s - root);
                if flip { -v } else { v }
            };
            for (a, b) in [(0.0, 1.0), (1.0, 0.0)] {
                let (s, n) = counted(a, b, g);
                prop_assert!(n <= 16, "{} evaluations", n);
                prop_assert_eq!(g(s) >= 0.0, g(b) >= 0.0);
                prop_assert!((s - root).abs() <= 2.0 * CROSSING_TOLERANCE, "{} from {}", s, root);
            }
        }
    }
}
