//! The MRI demo's scan: a synthetic head phantom, generated here rather than downloaded, in
//! the spirit of Shepp and Logan's: ellipsoids of skin, skull and brain, two ventricles of
//! fluid and a small dense tumour. `scenes/head.nrrd` holds its output (an 8-bit NRRD volume
//! that `scenes/mri.wrl` names); a test keeps the file and this generator in step
//! (`UPDATE_SCENES=1` rewrites it).
//!
//! The phantom spans [-1, 1]^3 (x to the head's left, y up, z to the face). Each sample is the
//! mean over 4^3 points of its cell, as a scanner's partial volume, so thin layers (the skull)
//! still show between samples.

use glam::DVec3;

/// Samples along each axis: 24^3 bytes fit in one replicated op with the rest of the object.
pub const SIDE: usize = 24;
/// Points averaged along each axis of a sample's cell.
const SUPERSAMPLE: usize = 4;

/// An ellipsoid's centre and semi-axes.
struct Ellipsoid {
    centre: DVec3,
    semi: DVec3,
}

impl Ellipsoid {
    const fn new(centre: [f64; 3], semi: [f64; 3]) -> Ellipsoid {
        Ellipsoid {
            centre: DVec3::from_array(centre),
            semi: DVec3::from_array(semi),
        }
    }

    fn contains(&self, p: DVec3) -> bool {
        ((p - self.centre) / self.semi).length_squared() <= 1.0
    }
}

const SKIN: Ellipsoid = Ellipsoid::new([0.0, 0.0, 0.0], [0.74, 0.94, 0.86]);
const SKULL: Ellipsoid = Ellipsoid::new([0.0, 0.02, 0.0], [0.67, 0.87, 0.79]);
const BRAIN: Ellipsoid = Ellipsoid::new([0.0, 0.04, 0.0], [0.5, 0.7, 0.62]);
const VENTRICLES: [Ellipsoid; 2] = [
    Ellipsoid::new([-0.14, 0.12, 0.0], [0.09, 0.22, 0.3]),
    Ellipsoid::new([0.14, 0.12, 0.0], [0.09, 0.22, 0.3]),
];
const TUMOUR: Ellipsoid = Ellipsoid::new([0.24, 0.3, -0.05], [0.17, 0.17, 0.17]);

/// Tissue values (what the scene's density and colours read): fluid, skin, brain, bone and
/// the tumour, the densest (a calcified one), so that no mix of two other tissues in one
/// sample (partial volume) reads as tumour.
pub const FLUID: f64 = 0.15;
/// Scalp and the soft tissue over the skull.
pub const SKIN_VALUE: f64 = 0.4;
/// Grey and white matter.
pub const BRAIN_VALUE: f64 = 0.6;
/// The tumour, denser than the brain round it and than bone.
pub const TUMOUR_VALUE: f64 = 1.0;
/// Bone.
pub const BONE: f64 = 0.85;

/// The phantom's value at `p` (0 outside the head).
pub fn tissue(p: DVec3) -> f64 {
    if TUMOUR.contains(p) {
        TUMOUR_VALUE
    } else if VENTRICLES.iter().any(|v| v.contains(p)) {
        FLUID
    } else if BRAIN.contains(p) {
        BRAIN_VALUE
    } else if SKULL.contains(p) {
        BONE
    } else if SKIN.contains(p) {
        SKIN_VALUE
    } else {
        0.0
    }
}

/// The distance between samples: [-1, 1] in `SIDE` samples, ends included.
pub fn spacing() -> f64 {
    2.0 / (SIDE - 1) as f64
}

/// The samples, x fastest, bytes 0..=255 for values 0..=1.
pub fn samples() -> Vec<u8> {
    let h = spacing();
    let mut out = Vec::with_capacity(SIDE * SIDE * SIDE);
    for k in 0..SIDE {
        for j in 0..SIDE {
            for i in 0..SIDE {
                let centre = DVec3::new(i as f64, j as f64, k as f64) * h - DVec3::ONE;
                let mut sum = 0.0;
                for s in 0..SUPERSAMPLE.pow(3) {
                    let sub = DVec3::new(
                        (s % SUPERSAMPLE) as f64,
                        ((s / SUPERSAMPLE) % SUPERSAMPLE) as f64,
                        (s / (SUPERSAMPLE * SUPERSAMPLE)) as f64,
                    );
                    let offset = ((sub + 0.5) / SUPERSAMPLE as f64 - 0.5) * h;
                    sum += tissue(centre + offset);
                }
                let mean = sum / SUPERSAMPLE.pow(3) as f64;
                out.push((mean * 255.0).round().clamp(0.0, 255.0) as u8);
            }
        }
    }
    out
}

/// The phantom as an NRRD file.
pub fn nrrd() -> Vec<u8> {
    let h = spacing();
    let mut out = format!(
        "NRRD0004\n# A synthetic head phantom for sculpt's MRI demo (app/src/demos/mri.rs).\n\
         type: uchar\ndimension: 3\nsizes: {SIDE} {SIDE} {SIDE}\nspacings: {h} {h} {h}\n\
         space origin: (-1,-1,-1)\nencoding: raw\n\n"
    )
    .into_bytes();
    out.extend(samples());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_head_file_is_the_generators_output() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/head.nrrd");
        let generated = nrrd();
        if std::env::var_os("UPDATE_SCENES").is_some() {
            std::fs::write(&path, &generated).unwrap();
            return;
        }
        let file = std::fs::read(&path).unwrap();
        assert!(
            file == generated,
            "scenes/head.nrrd differs from the generator; run \
             `UPDATE_SCENES=1 cargo test -p app --lib mri` to rewrite it"
        );
    }

    #[test]
    fn the_phantom_has_its_tissues_where_they_belong() {
        let grid = fdsl::grid::Grid::from_nrrd("head", &nrrd(), [0.0, 1.0]).unwrap();
        // Along the x axis through the ventricles' height: air, skin, bone, brain, fluid.
        let at = |x: f64| grid.value([x, 0.12, 0.0]);
        assert!(at(-0.98) < 0.02, "air {}", at(-0.98));
        assert!((at(-0.62) - BONE).abs() < 0.2, "bone {}", at(-0.62));
        assert!((at(-0.4) - BRAIN_VALUE).abs() < 0.05, "brain {}", at(-0.4));
        assert!((at(-0.14) - FLUID).abs() < 0.1, "fluid {}", at(-0.14));
        assert!((grid.value([0.24, 0.3, -0.05]) - TUMOUR_VALUE).abs() < 0.1);
    }
}
