//! The shark demo's polygon model, generated here rather than downloaded: a lofted body of
//! elliptical rings from tail to nose, closed by a point at each end, and thin closed prisms
//! for the fins. `scenes/shark.wrl` holds its output as an `IndexedFaceSet`; a test keeps the
//! file and this generator in step (`UPDATE_SCENES=1` rewrites the file).
//!
//! The shark's own frame: nose towards +x, back up (+y), 1.9 units from tail tip to nose.

use std::f64::consts::TAU;
use std::fmt::Write as _;

use glam::DVec3;

/// Rings along the body between the tail point and the nose point.
const N_RINGS: usize = 22;
/// Vertices around each ring.
const N_AROUND: usize = 18;
/// Where the body starts (the tail point) and ends (the nose point), along x.
const TAIL_X: f64 = -0.85;
const NOSE_X: f64 = 0.72;
/// The body's largest half-height and half-width.
const HALF_HEIGHT: f64 = 0.16;
const HALF_WIDTH: f64 = 0.13;

/// A closed, outward-facing triangle mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PolygonModel {
    /// Vertex positions.
    pub points: Vec<DVec3>,
    /// Triangles as vertex indices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl PolygonModel {
    fn point(&mut self, p: DVec3) -> u32 {
        self.points.push(p);
        u32::try_from(self.points.len() - 1).unwrap_or(u32::MAX)
    }

    /// A thin closed prism over triangle `a b c`, `half_thickness` to each side of its plane.
    fn fin(&mut self, a: DVec3, b: DVec3, c: DVec3, half_thickness: f64) {
        let normal = (b - a).cross(c - a).normalize() * half_thickness;
        let corners = [a, b, c];
        let low: Vec<u32> = corners.iter().map(|&p| self.point(p - normal)).collect();
        let high: Vec<u32> = corners.iter().map(|&p| self.point(p + normal)).collect();
        self.triangles.push([high[0], high[1], high[2]]);
        self.triangles.push([low[0], low[2], low[1]]);
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            self.triangles.push([low[i], low[j], high[j]]);
            self.triangles.push([low[i], high[j], high[i]]);
        }
    }
}

/// The body's thickness at `s` from tail (0) to nose (1), largest (1) at s = 0.62: a slim
/// tail stock, a full trunk and a blunt snout.
fn thickness(s: f64) -> f64 {
    let (a, b) = (0.9, 0.55);
    let peak = a / (a + b);
    let raw = |s: f64| s.powf(a) * (1.0 - s).powf(b);
    raw(s) / raw(peak)
}

/// The shark: body and fins.
pub fn shark() -> PolygonModel {
    let mut model = PolygonModel::default();
    body(&mut model);
    fins(&mut model);
    model
}

/// The body: a point at the tail, rings, a point at the nose, and the triangles between them.
fn body(model: &mut PolygonModel) {
    let tail = model.point(DVec3::new(TAIL_X, 0.0, 0.0));
    let mut rings = Vec::with_capacity(N_RINGS);
    for i in 1..=N_RINGS {
        let s = i as f64 / (N_RINGS + 1) as f64;
        let x = TAIL_X + (NOSE_X - TAIL_X) * s;
        let k = thickness(s);
        // The belly is flatter than the back, and the snout sits a little low.
        let centre_y = -0.02 * s * s;
        let ring: Vec<u32> = (0..N_AROUND)
            .map(|j| {
                let angle = TAU * j as f64 / N_AROUND as f64;
                let (sin, cos) = angle.sin_cos();
                let up = if sin > 0.0 { 1.0 } else { 0.8 };
                model.point(DVec3::new(
                    x,
                    centre_y + HALF_HEIGHT * k * up * sin,
                    HALF_WIDTH * k * cos,
                ))
            })
            .collect();
        rings.push(ring);
    }
    let nose = model.point(DVec3::new(NOSE_X, -0.03, 0.0));
    // Around each ring the angle turns from +z to +y: clockwise seen from the nose.
    for j in 0..N_AROUND {
        let next = (j + 1) % N_AROUND;
        let first = &rings[0];
        model.triangles.push([tail, first[j], first[next]]);
        let last = &rings[N_RINGS - 1];
        model.triangles.push([nose, last[next], last[j]]);
    }
    for pair in rings.windows(2) {
        let (back, front) = (&pair[0], &pair[1]);
        for j in 0..N_AROUND {
            let next = (j + 1) % N_AROUND;
            model.triangles.push([back[j], front[next], back[next]]);
            model.triangles.push([back[j], front[j], front[next]]);
        }
    }
}

/// The fins, each rooted inside the body: dorsal, the tail's two lobes, two pectorals.
fn fins(model: &mut PolygonModel) {
    let v = DVec3::new;
    model.fin(
        v(0.12, 0.1, 0.0),
        v(-0.14, 0.1, 0.0),
        v(-0.12, 0.42, 0.0),
        0.012,
    );
    model.fin(
        v(-0.66, 0.0, 0.0),
        v(-0.8, -0.02, 0.0),
        v(-1.1, 0.36, 0.0),
        0.01,
    );
    model.fin(
        v(-0.68, -0.02, 0.0),
        v(-0.8, 0.01, 0.0),
        v(-1.0, -0.24, 0.0),
        0.01,
    );
    for side in [-1.0, 1.0] {
        model.fin(
            v(0.32, -0.06, 0.07 * side),
            v(0.12, -0.06, 0.07 * side),
            v(0.0, -0.2, 0.46 * side),
            0.01,
        );
    }
}

/// The line that starts the generated geometry in `scenes/shark.wrl`.
pub const GEOMETRY_START: &str = "      geometry IndexedFaceSet {\n";
/// The line that ends it.
pub const GEOMETRY_END: &str = "      # end of the generated model\n";

/// The model as the body of a VRML `IndexedFaceSet` node (`coord` and `coordIndex`), with
/// four decimals, indented for `scenes/shark.wrl`.
pub fn indexed_face_set(model: &PolygonModel) -> String {
    let mut out = String::from(GEOMETRY_START);
    out.push_str("        coord Coordinate {\n          point [\n");
    for p in &model.points {
        let _ = writeln!(out, "            {:.4} {:.4} {:.4},", p.x, p.y, p.z);
    }
    out.push_str("          ]\n        }\n        coordIndex [\n");
    for [a, b, c] in &model.triangles {
        let _ = writeln!(out, "          {a} {b} {c} -1,");
    }
    out.push_str("        ]\n      }\n");
    out
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    /// Each part is closed: every directed edge is matched by its reverse exactly once.
    #[test]
    fn the_shark_is_closed_outward_facing_and_inside_its_container() {
        let model = shark();
        let mut edges: BTreeMap<(u32, u32), i32> = BTreeMap::new();
        for t in &model.triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                *edges.entry((a, b)).or_default() += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1, "edge {a}-{b} used {n} times");
            assert_eq!(edges.get(&(b, a)), Some(&1), "edge {a}-{b} is open");
        }
        // Outward: the signed volume of a closed outward mesh is positive.
        let volume: f64 = model
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| model.points[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        assert!(volume > 0.02, "{volume}");
        // The body lies inside the ellipsoid the scene's container uses.
        for p in &model.points[..1 + N_RINGS * N_AROUND + 1] {
            let q = DVec3::new((p.x + 0.065) / 0.81, p.y / 0.19, p.z / 0.15);
            assert!(q.length_squared() <= 1.0 + 1e-9, "{p}");
        }
    }

    /// `scenes/shark.wrl` holds this generator's model.
    #[test]
    fn the_scene_file_holds_the_generated_model() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/shark.wrl");
        let text = std::fs::read_to_string(&path).unwrap();
        let (begin, end) = (
            text.find(GEOMETRY_START).unwrap(),
            text.find(GEOMETRY_END).unwrap(),
        );
        let generated = indexed_face_set(&shark());
        if std::env::var_os("UPDATE_SCENES").is_some() {
            let updated = format!("{}{generated}{}", &text[..begin], &text[end..]);
            std::fs::write(&path, updated).unwrap();
            return;
        }
        assert!(
            text[begin..end] == generated,
            "scenes/shark.wrl differs from the generator; run \
             `UPDATE_SCENES=1 cargo test -p app --lib shark` to rewrite it"
        );
    }
}
