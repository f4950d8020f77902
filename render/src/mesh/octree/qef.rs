//! Vertex placement for dual contouring: edge crossings narrowed by false position, their
//! Hermite data (point, value, gradient), the quadric error function (QEF) whose minimiser
//! keeps sharp edges and corners, and the normals of vertices on those features.
//!
//! Each crossing stands for the plane where the first-order expansion of f about it vanishes,
//! f(x) + g . (y - x) = 0: on a flat face that is the face itself, wherever along the edge the
//! narrowing stopped, so the planes of two faces meet exactly on their crease. The vertex of a
//! patch is the least-squares point of its planes, found in f64 about the crossings' mean
//! with a small Tikhonov term for the directions the planes leave free, and kept in its cell
//! by minimising the quadric over the cell (or, for a feature just outside, over a slightly
//! larger box): see [`solve_qef`].

use super::super::field::Field;
use super::topology::inside;

/// Tikhonov weight pulling a vertex towards its crossings' mean (then towards the last
/// step's answer), in cell units: it decides the directions the planes leave (nearly) free.
const QEF_REGULARISATION: f64 = 0.02;

/// Steps of iterated Tikhonov regularisation. Each step pulls towards the previous answer,
/// so along a direction the planes fix with weight s (about the number of crossings on a
/// face) the answer misses the planes' point by (w / (s + w))^steps of the way from the
/// mass point, w the weight above: 4e-4 with two steps, where one step would leave 2%.
/// Directions the planes leave free stay near the mass point.
const QEF_STEPS: usize = 2;

/// Width, as a fraction of its grid edge, that each crossing's bracket is narrowed to: the
/// crossing is then within 1/64 cell of a sign change of f.
///
/// Linear interpolation alone misplaces crossings where f has a kink along the edge (near
/// CSG edges). The plane of a crossing does not depend on where it lies on a flat face (its
/// value corrects for that), but the crossings' mean does, and on curved faces the expansion
/// is only good near the surface.
const CROSSING_WIDTH: f32 = 1.0 / 64.0;

/// Rounds that step by false position (Illinois: an end kept twice in a row counts half) or,
/// where the line through the bracket's ends puts the sign change within half of
/// [`CROSSING_WIDTH`] of the last point, try a point that far past it: where f is nearly
/// linear along the edge the first step lands that close and the second closes the
/// bracket there, two evaluations where bisection takes six.
const SECANT_ROUNDS: usize = 6;

/// Rounds in all: after the secant rounds, bisection narrows any bracket, even a whole edge,
/// to [`CROSSING_WIDTH`] (six halvings).
const MAX_CROSSING_ROUNDS: usize = SECANT_ROUNDS + 6;

/// A sign change of f on the segment `pa..pb`, bracketed in `t.0..t.1` with values `f`.
pub(super) struct Bracket {
    pub(super) pa: [f32; 3],
    pub(super) pb: [f32; 3],
    pub(super) t: (f32, f32),
    pub(super) f: (f32, f32),
}

impl Bracket {
    fn at(&self, t: f32) -> [f32; 3] {
        std::array::from_fn(|a| self.pa[a] + t * (self.pb[a] - self.pa[a]))
    }

    fn width(&self) -> f32 {
        self.t.1 - self.t.0
    }

    /// The crossing: of the bracket's ends that the narrowing evaluated (at least one), the
    /// one nearer the surface (the smaller |f|), and f there. The edge's own ends are left
    /// out: a block without a record lends its neighbours a stand-in of the right sign for
    /// its values, not f.
    pub(super) fn crossing(&self) -> ([f32; 3], f32) {
        let magnitude = |t: f32, f: f32| {
            if t == 0.0 || t == 1.0 || f.is_nan() {
                f32::INFINITY
            } else {
                f.abs()
            }
        };
        if magnitude(self.t.1, self.f.1) < magnitude(self.t.0, self.f.0) {
            (self.at(self.t.1), self.f.1)
        } else {
            (self.at(self.t.0), self.f.0)
        }
    }
}

/// How a bracket is being narrowed: the end last replaced and how often the other was kept.
#[derive(Clone, Copy)]
struct Narrowing {
    /// The end (0 or 1) the last evaluation replaced, if any.
    replaced: Option<usize>,
    /// Weights of the ends' values in the false position (halved while an end is kept).
    weight: [f32; 2],
}

impl Narrowing {
    /// A bracket not narrowed yet: both ends count whole.
    const START: Narrowing = Narrowing {
        replaced: None,
        weight: [1.0; 2],
    };

    /// Where round `round` evaluates f in bracket `b`.
    fn next(&self, b: &Bracket, round: usize) -> f32 {
        let (t0, t1) = b.t;
        if round >= SECANT_ROUNDS {
            return 0.5 * (t0 + t1);
        }
        let (f0, f1) = b.f;
        let step = 0.5 * CROSSING_WIDTH;
        if let Some(end) = self.replaced {
            // The line through the ends: how far from the last point its zero lies.
            let last = if end == 0 { f0 } else { f1 };
            let distance = (last / (f1 - f0)).abs() * b.width();
            if distance < step {
                return if end == 0 { t0 + step } else { t1 - step };
            }
        }
        let (g0, g1) = (f0 * self.weight[0], f1 * self.weight[1]);
        let s = g0 / (g0 - g1);
        let s = if s.is_finite() {
            s.clamp(1e-3, 1.0 - 1e-3)
        } else {
            0.5
        };
        t0 + s * (t1 - t0)
    }

    /// End `end` was replaced: the other end, kept twice in a row, counts half from now on.
    fn replace(&mut self, end: usize) {
        if self.replaced == Some(end) {
            self.weight[1 - end] *= 0.5;
        }
        self.weight[end] = 1.0;
        self.replaced = Some(end);
    }
}

/// Narrows every bracket to [`CROSSING_WIDTH`] (false position and points just past it, then
/// bisection), evaluating each round's points in one bulk call.
pub(super) fn refine_crossings<F: Field>(field: &mut F, brackets: &mut [Bracket]) {
    let n = brackets.len();
    let (mut xs, mut ys, mut zs) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    let mut out = vec![0.0f32; n];
    let mut narrowing = vec![Narrowing::START; n];
    let mut asked = vec![0.0f32; n];
    let mut active: Vec<usize> = Vec::with_capacity(n);
    for round in 0..MAX_CROSSING_ROUNDS {
        active.clear();
        active.extend((0..n).filter(|&i| brackets[i].width() > CROSSING_WIDTH));
        if active.is_empty() {
            return;
        }
        xs.clear();
        ys.clear();
        zs.clear();
        for &i in &active {
            asked[i] = narrowing[i].next(&brackets[i], round);
            let p = brackets[i].at(asked[i]);
            xs.push(p[0]);
            ys.push(p[1]);
            zs.push(p[2]);
        }
        field.values(&xs, &ys, &zs, &mut out[..active.len()]);
        for (&i, &fm) in active.iter().zip(&out) {
            let b = &mut brackets[i];
            let end = if inside(fm) == inside(b.f.0) { 0 } else { 1 };
            if end == 0 {
                (b.t.0, b.f.0) = (asked[i], fm);
            } else {
                (b.t.1, b.f.1) = (asked[i], fm);
            }
            narrowing[i].replace(end);
        }
    }
}

/// One crossing's Hermite data: a point on a grid edge where f changes sign (to within the
/// bracket), f there, and the gradient there.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Hermite {
    pub(super) point: [f32; 3],
    pub(super) value: f32,
    pub(super) gradient: [f32; 3],
}

/// How far outside its cell, in cells, a vertex may follow a sharp feature whose tangent
/// planes meet there.
///
/// A crease or corner that passes just outside a cell can still cut the cell's edges on both
/// of its faces (the feature pokes through a grid edge without changing its sign); the planes
/// then meet outside, and the best point inside the cell lies off both faces: a notch in the
/// edge. Half a cell lets such a vertex sit on the feature.
pub(super) const FEATURE_REACH_CELLS: f32 = 0.5;

/// How close, in cells, every plane of a patch must pass to the planes' least-squares point
/// for the vertex to leave its cell for it: the planes must really meet there (a crease or a
/// corner of flat faces), not merely be the tangents of a curved sheet, whose least-squares
/// point may lie anywhere.
const FEATURE_FIT_CELLS: f64 = 0.02;

/// The largest correction, in cells, that a crossing's value may make to its plane
/// (|f| / |gradient|): the narrowing leaves a crossing within 1/64 cell of the surface, so a
/// larger one comes from a gradient too small to trust, and the plane then goes through the
/// crossing's point.
const MAX_PLANE_CORRECTION_CELLS: f32 = 1.0 / 16.0;

/// Places a vertex: the least-squares point of the planes of the crossings `data`, within
/// `reach` when every plane passes within [`FEATURE_FIT_CELLS`] of it, else the point of the
/// cell `cell` (`[lo, hi]`) where the same quadric is least; `h` is the mean cell size.
///
/// The planes' least-squares point is the corner or the edge where they meet, so sharp
/// features are reproduced. Where the planes leave directions free (a flat patch leaves two,
/// a crease one), the Tikhonov term picks the point nearest the crossings' mean (the mass
/// point). Minimising over the cell, rather than clamping the free minimiser axis by axis,
/// keeps a vertex on a crease that crosses its cell but whose point nearest the mass point
/// lies outside.
pub(super) fn solve_qef(
    data: &[Hermite],
    cell: [[f32; 3]; 2],
    reach: [[f32; 3]; 2],
    h: f32,
) -> [f32; 3] {
    let planes = Planes::new(data, h);
    let mut q = planes.quadric();
    let r0 = q.r;
    let local = |b: [[f32; 3]; 2]| -> [[f64; 3]; 2] {
        b.map(|x| std::array::from_fn(|a| (f64::from(x[a]) - planes.centre[a]) / f64::from(h)))
    };
    let (cell, reach_local) = (local(cell), local(reach));
    let within = |y: [f64; 3], b: [[f64; 3]; 2]| (0..3).all(|a| b[0][a] <= y[a] && y[a] <= b[1][a]);
    // The steps change only r, so one inverse serves them all.
    let inverse = invert3(q.m);
    // Each step pulls towards the last answer, the first towards the mass point (y = 0).
    let mut y = [0.0; 3];
    for _ in 0..QEF_STEPS {
        q.r = std::array::from_fn(|a| r0[a] + QEF_REGULARISATION * y[a]);
        let free =
            inverse.map(|inv| inv.map(|row| row[0] * q.r[0] + row[1] * q.r[1] + row[2] * q.r[2]));
        y = match free.filter(|y| y.iter().all(|v| v.is_finite())) {
            Some(y) if within(y, cell) => y,
            Some(y) if within(y, reach_local) && planes.max_distance(y) <= FEATURE_FIT_CELLS => y,
            _ => q.minimise_in_box(cell[0], cell[1]),
        };
    }
    std::array::from_fn(|a| {
        let x = planes.centre[a] + f64::from(h) * y[a];
        (x as f32).clamp(reach[0][a], reach[1][a])
    })
}

/// The planes of a patch's crossings, in cell units about their mass point `centre`.
struct Planes<'a> {
    data: &'a [Hermite],
    centre: [f64; 3],
    h: f64,
}

/// Most crossings of one patch: every edge of a cell.
const MAX_PLANES: usize = 12;

impl Planes<'_> {
    fn new(data: &[Hermite], h: f32) -> Planes<'_> {
        let n_points = data.len().max(1) as f64;
        let centre: [f64; 3] = std::array::from_fn(|a| {
            data.iter().map(|d| f64::from(d.point[a])).sum::<f64>() / n_points
        });
        Planes {
            data,
            centre,
            h: f64::from(h),
        }
    }

    /// Each crossing's plane n . y = b (n a unit vector), skipping crossings without a usable
    /// gradient.
    fn planes(&self) -> impl Iterator<Item = ([f64; 3], f64)> + '_ {
        self.data.iter().filter_map(|d| {
            let g = d.gradient.map(f64::from);
            let len = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            if !(len > f64::MIN_POSITIVE && len.is_finite()) {
                return None;
            }
            let n = g.map(|x| x / len);
            // f(x) + g . (y - x) = 0, that is n . y = n . x - f(x) / |g|.
            let correction = f64::from(d.value) / len;
            let correction = if correction.abs() <= f64::from(MAX_PLANE_CORRECTION_CELLS) * self.h {
                correction
            } else {
                0.0
            };
            let along: f64 = (0..3)
                .map(|a| n[a] * (f64::from(d.point[a]) - self.centre[a]))
                .sum();
            Some((n, (along - correction) / self.h))
        })
    }

    /// The sum of squared distances to the planes plus the Tikhonov term.
    fn quadric(&self) -> Quadric {
        let mut q = Quadric::default();
        for (n, b) in self.planes() {
            for i in 0..3 {
                for k in 0..3 {
                    q.m[i][k] += n[i] * n[k];
                }
                q.r[i] += n[i] * b;
            }
        }
        for (i, row) in q.m.iter_mut().enumerate() {
            row[i] += QEF_REGULARISATION;
        }
        q
    }

    /// The largest distance from `y` to a plane, in cells.
    fn max_distance(&self, y: [f64; 3]) -> f64 {
        self.planes()
            .map(|(n, b)| (n[0] * y[0] + n[1] * y[1] + n[2] * y[2] - b).abs())
            .fold(0.0, f64::max)
    }
}

/// Smallest cosine between two crossing normals of one vertex that still counts as one
/// smooth sheet: normals further apart than about 26 degrees meet at a crease or corner.
const MIN_SMOOTH_NORMAL_COS: f32 = 0.9;

/// Smallest cosine between the sheets of a feature whose vertex may leave its cell: faces
/// whose normals are more than 120 degrees apart are rather the two sides of something
/// thinner than a cell (a wall, a gap between two bodies), where the planes meet between
/// the surfaces, not on them.
const MIN_OPEN_FEATURE_COS: f32 = -0.5;

/// A vertex on a sharp feature: where the gradients of its crossings fall into two or more
/// sheets (each within [`MIN_SMOOTH_NORMAL_COS`] of its first gradient).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Feature {
    /// The unit outward normal: the mean of the sheets' directions.
    pub(super) normal: [f32; 3],
    /// Whether every two sheets are within [`MIN_OPEN_FEATURE_COS`] of each other, so that
    /// the vertex may follow the feature out of its cell.
    pub(super) open: bool,
}

/// The sharp feature the crossings `data` of a vertex lie on, or `None` where their gradients
/// form one smooth sheet (that vertex takes the gradient at its position as its normal).
///
/// The gradient of a `min` or `max` on a crease is that of whichever side wins there, so a
/// vertex on a crease would take one face's normal or the other's as rounding falls, and the
/// crease would be shaded as a saw-tooth. A feature vertex takes instead the mean of its
/// faces' directions, each sheet counting once whatever its number of crossings, so every
/// vertex of a straight crease gets the same normal. Opposite sheets (the two sides of a wall
/// thinner than a cell) have no mean direction: that vertex too takes the gradient.
pub(super) fn feature(data: &[Hermite]) -> Option<Feature> {
    // Per sheet: its first unit gradient and the sum of its unit gradients.
    let mut sheets = [([0.0f32; 3], [0.0f32; 3]); MAX_PLANES];
    let mut n_sheets = 0;
    for d in data {
        let Some(n) = unit(d.gradient) else {
            continue;
        };
        match sheets[..n_sheets]
            .iter_mut()
            .find(|(first, _)| dot(*first, n) >= MIN_SMOOTH_NORMAL_COS)
        {
            Some((_, sum)) => (0..3).for_each(|a| sum[a] += n[a]),
            None if n_sheets < MAX_PLANES => {
                sheets[n_sheets] = (n, n);
                n_sheets += 1;
            }
            None => {}
        }
    }
    if n_sheets < 2 {
        return None;
    }
    let mut directions = [[0.0f32; 3]; MAX_PLANES];
    let mut n_directions = 0;
    for (_, sum) in &sheets[..n_sheets] {
        if let Some(d) = unit(*sum) {
            directions[n_directions] = d;
            n_directions += 1;
        }
    }
    let directions = &directions[..n_directions];
    let mut mean = [0.0f32; 3];
    for d in directions {
        (0..3).for_each(|a| mean[a] += d[a]);
    }
    let open = directions.iter().enumerate().all(|(i, a)| {
        directions[i + 1..]
            .iter()
            .all(|b| dot(*a, *b) >= MIN_OPEN_FEATURE_COS)
    });
    // Outward normals are minus the gradient.
    let normal = unit(mean)?.map(|c| -c);
    // A mean much shorter than one sheet's direction comes from opposite sheets.
    let long = dot(mean, mean) > 0.25;
    long.then_some(Feature { normal, open })
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `v` scaled to unit length, or `None` when it is too short or not finite.
fn unit(v: [f32; 3]) -> Option<[f32; 3]> {
    let len = dot(v, v).sqrt();
    (len > f32::MIN_POSITIVE && len.is_finite()).then(|| v.map(|c| c / len))
}

/// A positive definite quadric E(y) = y^T m y - 2 r^T y (a constant dropped).
#[derive(Default)]
struct Quadric {
    m: [[f64; 3]; 3],
    r: [f64; 3],
}

impl Quadric {
    fn energy(&self, y: [f64; 3]) -> f64 {
        (0..3)
            .map(|i| y[i] * ((0..3).map(|k| self.m[i][k] * y[k]).sum::<f64>() - 2.0 * self.r[i]))
            .sum()
    }

    /// The minimiser over the box `lo..=hi`, which must hold the origin (the mass point), when
    /// the free minimiser lies outside it.
    ///
    /// The minimiser of a strictly convex quadric over a box lies inside one face of the box
    /// (a side, an edge or a corner, the box itself being excluded here) and is the minimiser
    /// over that face's affine hull. Faces are tried sides first; the first feasible
    /// candidate where the quadric rises out of the box across every held bound (the KKT
    /// conditions) is the answer. Should rounding defeat that test, the feasible candidate of
    /// least energy is.
    fn minimise_in_box(&self, lo: [f64; 3], hi: [f64; 3]) -> [f64; 3] {
        // Rounding may put a candidate on a face just outside it, or tilt a flat gradient.
        const SLACK: f64 = 1e-9;
        let feasible = |y: [f64; 3]| (0..3).all(|a| lo[a] - SLACK <= y[a] && y[a] <= hi[a] + SLACK);
        // The mass point is feasible, so the answer is at least as good.
        let mut best = ([0.0; 3], 0.0);
        for n_held in 1..=3 {
            // Each axis free (0), held at its low bound (1) or at its high bound (2).
            for code in 1..27u32 {
                let state: [u32; 3] = std::array::from_fn(|a| code / 3u32.pow(a as u32) % 3);
                if state.iter().filter(|&&s| s != 0).count() != n_held {
                    continue;
                }
                let held: [Option<f64>; 3] = std::array::from_fn(|a| match state[a] {
                    0 => None,
                    1 => Some(lo[a]),
                    _ => Some(hi[a]),
                });
                let Some(y) = self.minimise_with_fixed(held) else {
                    continue;
                };
                if !feasible(y) {
                    continue;
                }
                // Half the gradient of E: m y - r. At a low bound it must not fall inwards
                // (a positive component), at a high bound likewise (a negative one).
                let g: [f64; 3] = std::array::from_fn(|a| {
                    (0..3).map(|k| self.m[a][k] * y[k]).sum::<f64>() - self.r[a]
                });
                let optimal = (0..3).all(|a| match state[a] {
                    0 => true,
                    1 => g[a] >= -SLACK,
                    _ => g[a] <= SLACK,
                });
                if optimal {
                    return y;
                }
                let e = self.energy(y);
                if e < best.1 {
                    best = (y, e);
                }
            }
        }
        best.0
    }

    /// The minimiser with the coordinates of `fixed` held, or `None` if singular.
    fn minimise_with_fixed(&self, fixed: [Option<f64>; 3]) -> Option<[f64; 3]> {
        let mut free = [0usize; 3];
        let mut n_free = 0;
        for a in (0..3).filter(|&a| fixed[a].is_none()) {
            free[n_free] = a;
            n_free += 1;
        }
        let mut y = fixed.map(|f| f.unwrap_or(0.0));
        // The free coordinates solve m_ff y_f = r_f - m_fx y_x.
        let rhs = |i: usize| {
            let row = free[i];
            self.r[row]
                - (0..3)
                    .filter_map(|k| fixed[k].map(|v| self.m[row][k] * v))
                    .sum::<f64>()
        };
        let m = |i: usize, k: usize| self.m[free[i]][free[k]];
        match n_free {
            0 => {}
            1 => y[free[0]] = rhs(0) / m(0, 0),
            2 => {
                let det = m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0);
                let (r0, r1) = (rhs(0), rhs(1));
                y[free[0]] = (r0 * m(1, 1) - m(0, 1) * r1) / det;
                y[free[1]] = (m(0, 0) * r1 - m(1, 0) * r0) / det;
            }
            _ => {
                let inv = invert3(self.m)?;
                y = inv.map(|row| row[0] * self.r[0] + row[1] * self.r[1] + row[2] * self.r[2]);
            }
        }
        y.iter().all(|v| v.is_finite()).then_some(y)
    }
}

/// The inverse of the 3x3 matrix `m` by its adjugate, or `None` if singular.
fn invert3(m: [[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    // Cofactor (i, k) of m, which is entry (k, i) of the adjugate.
    let cofactor = |i: usize, k: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((k + 1) % 3, (k + 2) % 3);
        m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]
    };
    let det = (0..3).map(|k| m[0][k] * cofactor(0, k)).sum::<f64>();
    if !(det.abs() > f64::MIN_POSITIVE && det.is_finite()) {
        return None;
    }
    Some(std::array::from_fn(|k| {
        std::array::from_fn(|i| cofactor(i, k) / det)
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f along x only, `profile(x)`, counting the points it is asked for.
    struct AlongX<P: Fn(f32) -> f32> {
        profile: P,
        n_values: usize,
    }

    impl<P: Fn(f32) -> f32> Field for AlongX<P> {
        fn interval(&mut self, _: [f32; 3], _: [f32; 3]) -> (f32, f32) {
            (f32::NAN, f32::NAN)
        }

        fn values(&mut self, xs: &[f32], _: &[f32], _: &[f32], out: &mut [f32]) {
            self.n_values += xs.len();
            for (o, &x) in out.iter_mut().zip(xs) {
                *o = (self.profile)(x);
            }
        }
    }

    /// The bracket of `field`'s sign change on the unit edge along x, narrowed.
    fn narrowed<P: Fn(f32) -> f32>(field: &mut AlongX<P>) -> Vec<Bracket> {
        let mut brackets = vec![Bracket {
            pa: [0.0; 3],
            pb: [1.0, 0.0, 0.0],
            t: (0.0, 1.0),
            f: ((field.profile)(0.0), (field.profile)(1.0)),
        }];
        refine_crossings(field, &mut brackets);
        brackets
    }

    /// Each bracket is at most the crossing width and still holds the sign change.
    fn assert_narrowed(brackets: &[Bracket], what: &str) {
        for b in brackets {
            assert!(b.width() <= CROSSING_WIDTH, "{what}: width {}", b.width());
            assert_ne!(inside(b.f.0), inside(b.f.1), "{what}: {:?}", b.f);
        }
    }

    #[test]
    fn where_f_is_linear_along_the_edge_two_values_narrow_a_crossing() {
        for k in 1..100 {
            let root = k as f32 / 100.0;
            let mut field = AlongX {
                profile: move |x: f32| 0.3 * (root - x),
                n_values: 0,
            };
            let brackets = narrowed(&mut field);
            assert_narrowed(&brackets, &format!("root {root}"));
            assert!(
                field.n_values <= 2,
                "root {root}: {} values",
                field.n_values
            );
        }
    }

    #[test]
    fn a_kink_or_a_curve_along_the_edge_is_narrowed_within_the_rounds() {
        // A crease (two planes meeting at 0.37), and a sphere two cells across the edge's
        // line, one cell off it; each with its sign change at `root`.
        let kinked =
            |root: f32| move |x: f32| (root - x).min(4.0 * (0.37 - x) + (root - 0.37).max(0.0));
        let curved =
            |root: f32| move |x: f32| 2.0 - ((x - root + 3f32.sqrt()).powi(2) + 1.0).sqrt();
        // Values per crossing on average, at most: bisection takes 6.
        let n_kinked = mean_values(kinked);
        let n_curved = mean_values(curved);
        assert!(n_kinked < 5.5, "{n_kinked} values a crossing");
        assert!(n_curved < 3.0, "{n_curved} values a crossing");
    }

    /// Narrows the crossings of `profile(root)` for roots along the edge, each within the
    /// width and the rounds; the mean number of values asked per crossing.
    fn mean_values<P: Fn(f32) -> f32>(profile: impl Fn(f32) -> P) -> f64 {
        let mut n_values = 0;
        for k in 1..100 {
            let root = k as f32 / 100.0;
            let mut field = AlongX {
                profile: profile(root),
                n_values: 0,
            };
            let brackets = narrowed(&mut field);
            assert_narrowed(&brackets, &format!("root {root}"));
            assert!(field.n_values <= MAX_CROSSING_ROUNDS, "root {root}");
            n_values += field.n_values;
        }
        n_values as f64 / 99.0
    }

    /// Hermite data on the plane through `point` with outward normal `outward`.
    fn on_plane(points: &[[f32; 3]], outward: [f32; 3]) -> Vec<Hermite> {
        points
            .iter()
            .map(|&point| Hermite {
                point,
                value: 0.0,
                gradient: outward.map(|c| -c),
            })
            .collect()
    }

    const UNIT_CELL: [[f32; 3]; 2] = [[0.0; 3], [1.0; 3]];

    fn grown(by: f32) -> [[f32; 3]; 2] {
        [[-by; 3], [1.0 + by; 3]]
    }

    #[test]
    fn a_vertex_stays_within_its_reach_whatever_its_data() {
        // Pseudo-random crossings on the unit cell's edges, with random gradients and values,
        // some of them zero, huge or not finite: the vertex is finite and within its box.
        let mut rng = testkit::rng::XorShift64(0x2545_f491_4f6c_dd1d);
        let mut next = || rng.unit_f32();
        let odd = [0.0, 1e30, -1e-30, f32::NAN, f32::INFINITY];
        for round in 0..2000 {
            let n = 1 + (next() * 12.0) as usize;
            let data: Vec<Hermite> = (0..n)
                .map(|_| {
                    // A point on an edge: two coordinates at 0 or 1, the third anywhere.
                    let along = (next() * 3.0) as usize % 3;
                    let point =
                        std::array::from_fn(|a| if a == along { next() } else { next().round() });
                    let mut gradient = [next() - 0.5, next() - 0.5, next() - 0.5];
                    let mut value = 0.1 * (next() - 0.5);
                    if round % 7 == 0 {
                        gradient[(next() * 3.0) as usize % 3] = odd[(next() * 5.0) as usize % 5];
                        value = odd[(next() * 5.0) as usize % 5];
                    }
                    Hermite {
                        point,
                        value,
                        gradient,
                    }
                })
                .collect();
            for reach in [UNIT_CELL, grown(FEATURE_REACH_CELLS)] {
                let v = solve_qef(&data, UNIT_CELL, reach, 1.0);
                assert!(
                    (0..3).all(|a| reach[0][a] <= v[a] && v[a] <= reach[1][a]),
                    "{v:?} outside {reach:?} for {data:?}"
                );
            }
            let _ = feature(&data);
        }
    }

    #[test]
    fn the_box_minimiser_is_the_least_energy_in_the_box() {
        // Pseudo-random positive definite quadrics whose free minimiser leaves the box.
        let mut rng = testkit::rng::XorShift64(0x9e37_79b9_7f4a_7c15);
        let mut next = || rng.unit_f64() * 2.0 - 1.0;
        for _ in 0..200 {
            let a: [[f64; 3]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| next()));
            let mut q = Quadric::default();
            for i in 0..3 {
                for k in 0..3 {
                    q.m[i][k] = (0..3).map(|j| a[j][i] * a[j][k]).sum::<f64>();
                }
                q.m[i][i] += 0.01;
                q.r[i] = 3.0 * next();
            }
            let (lo, hi) = ([-0.4, -0.5, -0.3], [0.6, 0.5, 0.7]);
            let y = q.minimise_in_box(lo, hi);
            assert!((0..3).all(|i| lo[i] - 1e-9 <= y[i] && y[i] <= hi[i] + 1e-9));
            // No point of a fine lattice over the box does better.
            let n = 24;
            let mut best = f64::INFINITY;
            for i in 0..=n {
                for j in 0..=n {
                    for k in 0..=n {
                        let t = [i, j, k].map(|v| f64::from(v) / f64::from(n));
                        let p = std::array::from_fn(|d| lo[d] + t[d] * (hi[d] - lo[d]));
                        best = best.min(q.energy(p));
                    }
                }
            }
            assert!(q.energy(y) <= best + 1e-9, "{} > {best}", q.energy(y));
        }
    }

    #[test]
    fn a_crease_through_the_cell_keeps_its_vertex_on_it() {
        // Faces x = 0.9 and y = 0.8 meet along the line (0.9, 0.8, z); the crossings' mean is
        // far from it, so the point nearest the mean on the crease is outside the cell in z.
        let mut data = on_plane(&[[0.9, 0.0, 0.9], [0.9, 0.3, 1.0]], [1.0, 0.0, 0.0]);
        data.extend(on_plane(
            &[[0.0, 0.8, 1.0], [0.2, 0.8, 1.0]],
            [0.0, 1.0, 0.0],
        ));
        let v = solve_qef(&data, UNIT_CELL, UNIT_CELL, 1.0);
        assert!(
            (v[0] - 0.9).abs() < 1e-3 && (v[1] - 0.8).abs() < 1e-3,
            "{v:?}"
        );
    }

    #[test]
    fn a_corner_just_outside_the_cell_is_followed_within_reach() {
        // Three faces that cut the cell meet at (1.2, 0.5, 0.5), 0.2 cells outside it.
        let s = 0.5f32.sqrt();
        let mut data = on_plane(&[[0.7, 1.0, 0.0], [0.8, 0.9, 1.0]], [s, s, 0.0]);
        data.extend(on_plane(&[[0.7, 0.0, 0.0], [0.8, 0.1, 1.0]], [s, -s, 0.0]));
        data.extend(on_plane(
            &[[0.0, 0.2, 0.5], [0.0, 0.8, 0.5]],
            [0.0, 0.0, 1.0],
        ));
        let v = solve_qef(&data, UNIT_CELL, grown(FEATURE_REACH_CELLS), 1.0);
        let corner = [1.2, 0.5, 0.5];
        assert!((0..3).all(|a| (v[a] - corner[a]).abs() < 1e-3), "{v:?}");
        // Without reach the vertex stays in its cell, as near the planes as it can.
        let v = solve_qef(&data, UNIT_CELL, UNIT_CELL, 1.0);
        assert!(
            (v[0] - 1.0).abs() < 1e-6 && (v[1] - 0.5).abs() < 1e-3,
            "{v:?}"
        );
    }

    #[test]
    fn tangents_of_a_curved_sheet_do_not_pull_a_vertex_out_of_its_cell() {
        // Four tangent planes of a sphere of radius 0.6 around (0.5, 0.5, -0.4): their
        // least-squares point lies outside the cell, but they miss it by more than the fit.
        let centre = [0.5f32, 0.5, -0.4];
        let data: Vec<Hermite> = [[0.2f32, 0.2], [0.8, 0.2], [0.2, 0.8], [0.8, 0.8]]
            .iter()
            .map(|&[x, y]| {
                let d = [x - centre[0], y - centre[1]];
                let z = centre[2] + (0.36 - d[0] * d[0] - d[1] * d[1]).sqrt();
                let point = [x, y, z];
                let outward = std::array::from_fn(|a| (point[a] - centre[a]) / 0.6);
                on_plane(&[point], outward)[0]
            })
            .collect();
        let v = solve_qef(&data, UNIT_CELL, grown(FEATURE_REACH_CELLS), 1.0);
        assert!(v.iter().all(|c| (0.0..=1.0).contains(c)), "{v:?}");
    }

    #[test]
    fn a_crease_gets_the_mean_of_its_faces_normals() {
        let mut data = on_plane(&[[0.9, 0.0, 0.0], [0.9, 0.0, 1.0]], [1.0, 0.0, 0.0]);
        data.extend(on_plane(&[[0.0, 0.8, 0.0]], [0.0, 1.0, 0.0]));
        let f = feature(&data).unwrap();
        let s = 0.5f32.sqrt();
        assert!((f.normal[0] - s).abs() < 1e-6 && (f.normal[1] - s).abs() < 1e-6);
        assert!(f.open);
        // One sheet is no feature; two opposite sheets (a thin wall) neither.
        assert_eq!(feature(&data[..2]), None);
        let mut wall = data[..2].to_vec();
        wall.extend(on_plane(&[[0.2, 0.0, 0.0]], [-1.0, 0.0, 0.0]));
        assert_eq!(feature(&wall), None);
    }
}
