//! Appearance on meshes: colour, transparency, shininess and geometric texture from an
//! object's [`model::object::Appearance`], evaluated in bulk at a mesh's vertices at time `t`.
//!
//! - Diffuse colour becomes the vertex colour: a constant, a parametric RGB function (a
//!   statement list with outputs `r`, `g`, `b`), or a scalar function through a
//!   [`ColorMap`] (linear between keys, clamped at the ends). Components are clamped to
//!   `[0, 1]`; NaN becomes 0. No diffuse colour gives [`DEFAULT_DIFFUSE`].
//! - Transparency (0 opaque, 1 clear) becomes vertex alpha, so one object may be partly
//!   transparent; the renderer draws any object with an alpha below 1 in its transparent pass.
//! - Ambient colour becomes the vertex ambient colour ([`Mesh::ambient`]), evaluated like the
//!   diffuse one. It is the ambient reflectance already scaled by its intensity (fdsl reads
//!   VRML's `ambientIntensity` k as k times the diffuse colour), so an object with an ambient
//!   colour gets the [`Material`] ambient weight 1: the shader's ambient term is weight times
//!   ambient colour. Without one the term is the default weight 0.2 (VRML's default
//!   `ambientIntensity`) times the diffuse colour, the same picture as `ambientIntensity 0.2`.
//! - Shininess (0..1) sets the [`Material`]'s Blinn-Phong exponent (VRML's convention: times
//!   128), and the specular colour's mean luminance its specular weight, both averaged over
//!   the vertices: the shader has one material per object.
//! - Displacement is a geometric texture: each vertex moves by d(p) along its normal, then
//!   normals are recomputed. It runs before the colours, which see the displaced points.
//!
//! Every function is evaluated in the appearance's own space (through the inverse of its
//! transform), at the mesh's object-space vertices, in one bulk call per function.
//! Not done here: the appearance's domain, which fdsl documents as informative.
//!
//! Nothing here compiles text: [`CompiledAppearance::of`] takes the tapes the
//! [`Object`] compiled when its appearance was set, and [`CompiledAppearance::new`] builds
//! an object from a bare [`Appearance`] (through model's per-process cache of compiled
//! formulas, so a formula already seen is not compiled again).

use crate::mesh::Mesh;
use crate::scene::Material;
use fdsl::eval::BulkEval;
use glam::{DAffine3, DVec3};
use model::object::{
    Appearance, ColorMap, ColorSlot, CompiledColor, DEFAULT_DIFFUSE, Object, ObjectData,
    ObjectError, Slot,
};

/// Shininess 1 maps to this Blinn-Phong exponent (VRML's `shininess` times 128).
pub const MAX_SHININESS_EXPONENT: f32 = 128.0;
/// The material's ambient weight for an object with an ambient colour (see the module
/// documentation).
pub const AMBIENT_WEIGHT_WITH_COLOUR: f32 = 1.0;

/// Why an appearance could not be compiled.
#[derive(Debug, thiserror::Error)]
pub enum AppearanceError {
    /// A formula does not compile.
    #[error("{slot}: {source}")]
    Compile {
        /// Which part of the appearance.
        slot: &'static str,
        /// The compiler's diagnostics.
        source: fdsl::CompileError,
    },
    /// A parametric colour lacks one of `r`, `g`, `b`.
    #[error("{slot}: {source}")]
    MissingOutput {
        /// Which part of the appearance.
        slot: &'static str,
        /// The missing output.
        source: fdsl::MissingOutput,
    },
    /// The appearance transform cannot be inverted.
    #[error("the appearance transform is not invertible")]
    BadTransform,
    /// Another part of the appearance is not valid (a colour map, a colour, the domain, a
    /// formula's length), as the object model checks it.
    #[error(transparent)]
    Invalid(ObjectError),
}

impl AppearanceError {
    /// The error of building an object that holds only the appearance.
    fn of_object(error: ObjectError) -> AppearanceError {
        let slot = |slot: Slot| match slot {
            Slot::Diffuse => "diffuse colour",
            Slot::Ambient => "ambient colour",
            Slot::Specular => "specular colour",
            Slot::Transparency => "transparency",
            Slot::Shininess => "shininess",
            Slot::Displacement => "displacement",
            _ => "appearance",
        };
        match error {
            ObjectError::Compile { slot: s, error } => AppearanceError::Compile {
                slot: slot(s),
                source: *error,
            },
            ObjectError::MissingOutput { slot: s, error } => AppearanceError::MissingOutput {
                slot: slot(s),
                source: error,
            },
            ObjectError::BadTransform { .. } => AppearanceError::BadTransform,
            other => AppearanceError::Invalid(other),
        }
    }
}

/// A colour definition compiled for bulk evaluation.
#[derive(Clone, Debug)]
enum Colour {
    Constant([f32; 3]),
    /// Outputs r, g, b.
    Rgb(BulkEval),
    /// A scalar through a map.
    Map(BulkEval, ColorMap),
}

/// An [`Appearance`] with every formula compiled, ready to apply to meshes.
#[derive(Clone, Debug)]
pub struct CompiledAppearance {
    diffuse: Option<Colour>,
    ambient: Option<Colour>,
    specular: Option<Colour>,
    transparency: Option<BulkEval>,
    shininess: Option<BulkEval>,
    displacement: Option<BulkEval>,
    appearance_from_object: DAffine3,
}

impl Colour {
    /// The compiled colour `slot` of `object`, for bulk evaluation.
    fn of(object: &Object, slot: ColorSlot) -> Option<Colour> {
        Some(match object.color(slot)? {
            CompiledColor::Constant(c) => Colour::Constant(c.map(clamp_unit)),
            CompiledColor::Rgb(tape) => Colour::Rgb(BulkEval::new(tape)),
            CompiledColor::Map(tape, map) => Colour::Map(BulkEval::new(tape), map.clone()),
        })
    }
}

/// `v` clamped to `[0, 1]`, NaN as 0.
fn clamp_unit(v: f32) -> f32 {
    if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) }
}

/// Points in structure-of-arrays form, as the bulk evaluator takes them.
struct Points {
    xs: Vec<f32>,
    ys: Vec<f32>,
    zs: Vec<f32>,
}

impl Points {
    fn len(&self) -> usize {
        self.xs.len()
    }
}

impl Colour {
    /// The colour at every point, written to `out`.
    fn eval(&mut self, p: &Points, t: f32, out: &mut [[f32; 3]]) {
        let n = p.len();
        match self {
            Colour::Constant(c) => out.fill(*c),
            Colour::Rgb(eval) => {
                let (mut r, mut g, mut b) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
                eval.eval_outputs(&p.xs, &p.ys, &p.zs, t, &mut [&mut r, &mut g, &mut b]);
                for (i, o) in out.iter_mut().enumerate() {
                    *o = [r[i], g[i], b[i]].map(clamp_unit);
                }
            }
            Colour::Map(eval, map) => {
                let mut s = vec![0.0; n];
                eval.eval(&p.xs, &p.ys, &p.zs, t, &mut s);
                for (o, &v) in out.iter_mut().zip(&s) {
                    *o = map.color(f64::from(v)).map(clamp_unit);
                }
            }
        }
    }
}

impl CompiledAppearance {
    /// `object`'s appearance, from the tapes the object compiled (nothing is compiled here).
    pub fn of(object: &Object) -> CompiledAppearance {
        let scalar = |slot| object.tape(slot).map(BulkEval::new);
        CompiledAppearance {
            diffuse: Colour::of(object, ColorSlot::Diffuse),
            ambient: Colour::of(object, ColorSlot::Ambient),
            specular: Colour::of(object, ColorSlot::Specular),
            transparency: scalar(Slot::Transparency),
            shininess: scalar(Slot::Shininess),
            displacement: scalar(Slot::Displacement),
            appearance_from_object: object.appearance_from_object().parent_from_child,
        }
    }

    /// A bare `appearance`, validated and compiled as an object holding only it (formulas
    /// come from model's per-process cache when already compiled). Prefer
    /// [`CompiledAppearance::of`] for an object's appearance.
    pub fn new(appearance: &Appearance) -> Result<CompiledAppearance, AppearanceError> {
        let object = Object::new(ObjectData {
            appearance: appearance.clone().into(),
            ..ObjectData::default()
        })
        .map_err(AppearanceError::of_object)?;
        Ok(CompiledAppearance::of(&object))
    }
}

impl Points {
    /// `mesh`'s vertices mapped by `appearance_from_object`.
    fn of(mesh: &Mesh, appearance_from_object: DAffine3) -> Points {
        let n = mesh.n_vertices();
        let mut p = Points {
            xs: Vec::with_capacity(n),
            ys: Vec::with_capacity(n),
            zs: Vec::with_capacity(n),
        };
        for v in &mesh.positions {
            let q = appearance_from_object.transform_point3(DVec3::new(
                v[0].into(),
                v[1].into(),
                v[2].into(),
            ));
            p.xs.push(q.x as f32);
            p.ys.push(q.y as f32);
            p.zs.push(q.z as f32);
        }
        p
    }
}

impl CompiledAppearance {
    /// Displaces `mesh` by the geometric texture, then sets its vertex colours (diffuse colour
    /// and transparency as alpha) and ambient colours (none without an ambient colour), all
    /// at time `t`.
    pub fn apply(&mut self, mesh: &mut Mesh, t: f32) {
        if let Some(eval) = &mut self.displacement {
            let p = Points::of(mesh, self.appearance_from_object);
            let mut heights = vec![0.0; p.len()];
            eval.eval(&p.xs, &p.ys, &p.zs, t, &mut heights);
            mesh.displace_by(&heights);
        }
        let p = Points::of(mesh, self.appearance_from_object);
        let mut rgb = vec![DEFAULT_DIFFUSE; p.len()];
        if let Some(c) = &mut self.diffuse {
            c.eval(&p, t, &mut rgb);
        }
        let mut alpha = vec![0.0; p.len()];
        if let Some(eval) = &mut self.transparency {
            eval.eval(&p.xs, &p.ys, &p.zs, t, &mut alpha);
        }
        mesh.colours = rgb
            .iter()
            .zip(&alpha)
            .map(|(c, &a)| [c[0], c[1], c[2], 1.0 - clamp_unit(a)])
            .collect();
        mesh.ambient.clear();
        if let Some(c) = &mut self.ambient {
            mesh.ambient = vec![[0.0; 3]; p.len()];
            c.eval(&p, t, &mut mesh.ambient);
        }
    }

    /// `base` with the appearance's shininess and specular weight, averaged over `mesh`'s
    /// vertices at time `t`, and with [`AMBIENT_WEIGHT_WITH_COLOUR`] when it has an ambient
    /// colour (parts the appearance leaves out keep `base`'s values).
    pub fn material(&mut self, mesh: &Mesh, t: f32, base: Material) -> Material {
        let mut material = base;
        if self.ambient.is_some() {
            material.ambient = AMBIENT_WEIGHT_WITH_COLOUR;
        }
        let p = Points::of(mesh, self.appearance_from_object);
        let n = p.len();
        if n == 0 {
            return material;
        }
        if let Some(eval) = &mut self.shininess {
            let mut s = vec![0.0; n];
            eval.eval(&p.xs, &p.ys, &p.zs, t, &mut s);
            let mean = s.iter().map(|&v| clamp_unit(v)).sum::<f32>() / n as f32;
            material.shininess = (mean * MAX_SHININESS_EXPONENT).max(1.0);
        }
        if let Some(c) = &mut self.specular {
            let mut rgb = vec![[0.0; 3]; n];
            c.eval(&p, t, &mut rgb);
            let luminance = |c: &[f32; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
            material.specular = rgb.iter().map(luminance).sum::<f32>() / n as f32;
        }
        material
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::object::{ColorDef, Formula, Transform};

    fn formula(text: &str) -> Formula {
        Formula::new(text).unwrap()
    }

    /// A strip of two triangles along x from 0 to 2 at z = 0, normals +z.
    fn strip() -> Mesh {
        let mut m = Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
            ],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            colours: vec![[1.0; 4]; 4],
            ambient: Vec::new(),
            indices: vec![0, 1, 3, 1, 2, 3],
        };
        m.normals = vec![[0.0, 0.0, 1.0]; 4];
        m
    }

    #[test]
    fn colour_map_interpolates_between_keys_and_clamps_at_the_ends() {
        let map = ColorMap {
            keys: vec![(0.5, [1.0, 0.0, 0.0]), (1.5, [0.0, 0.0, 1.0])],
        };
        let mut a = CompiledAppearance::new(&Appearance {
            diffuse: Some(ColorDef::Map {
                formula: formula("x"),
                map,
            }),
            ..Appearance::default()
        })
        .unwrap();
        let mut m = strip();
        a.apply(&mut m, 0.0);
        assert_eq!(m.colours[0], [1.0, 0.0, 0.0, 1.0], "below the first key");
        assert_eq!(m.colours[1], [0.5, 0.0, 0.5, 1.0], "halfway");
        assert_eq!(m.colours[2], [0.0, 0.0, 1.0, 1.0], "above the last key");
    }

    #[test]
    fn parametric_rgb_depends_on_time_and_is_clamped() {
        let mut a = CompiledAppearance::new(&Appearance {
            diffuse: Some(ColorDef::Rgb(formula("r = t; g = x - 0.5; b = 2*y;"))),
            transparency: Some(formula("0.25*x")),
            ..Appearance::default()
        })
        .unwrap();
        let mut m = strip();
        a.apply(&mut m, 0.75);
        assert_eq!(m.colours[0], [0.75, 0.0, 0.0, 1.0]);
        assert_eq!(m.colours[2], [0.75, 1.0, 0.0, 0.5]);
        assert_eq!(m.colours[3], [0.75, 0.5, 1.0, 0.75]);
        a.apply(&mut m, 2.0);
        assert_eq!(m.colours[0][0], 1.0);
    }

    #[test]
    fn displacement_moves_along_normals_in_appearance_space() {
        // Appearance space sits at +1 along x in object space, so object x is appearance
        // x - 1 and d = 0.1 * (x_object - 1).
        let mut a = CompiledAppearance::new(&Appearance {
            displacement: Some(formula("0.1*x")),
            transform: Transform::translate(DVec3::new(1.0, 0.0, 0.0)),
            ..Appearance::default()
        })
        .unwrap();
        let mut m = strip();
        a.apply(&mut m, 0.0);
        let z: Vec<f32> = m.positions.iter().map(|p| p[2]).collect();
        assert_eq!(z, vec![-0.1, 0.0, 0.1, 0.0]);
        assert_eq!(m.colours[0], [0.8, 0.8, 0.8, 1.0], "default diffuse");
    }

    #[test]
    fn ambient_colour_goes_to_the_vertices_and_sets_the_ambient_weight() {
        let mut plain = CompiledAppearance::new(&Appearance::default()).unwrap();
        let mut m = strip();
        plain.apply(&mut m, 0.0);
        assert!(m.ambient.is_empty());
        assert_eq!(plain.material(&m, 0.0, Material::default()).ambient, 0.2);
        let mut a = CompiledAppearance::new(&Appearance {
            diffuse: Some(ColorDef::Constant([1.0, 1.0, 1.0])),
            ambient: Some(ColorDef::Rgb(formula("r = 0; g = 0.1*x; b = 0.2;"))),
            ..Appearance::default()
        })
        .unwrap();
        a.apply(&mut m, 0.0);
        assert_eq!(m.validate(), Ok(()));
        assert_eq!(m.ambient[2], [0.0, 0.2, 0.2]);
        assert_eq!(m.colours[2], [1.0; 4], "the diffuse colour is unchanged");
        assert_eq!(
            a.material(&m, 0.0, Material::default()).ambient,
            AMBIENT_WEIGHT_WITH_COLOUR
        );
    }

    #[test]
    fn material_takes_mean_shininess_and_specular() {
        let mut a = CompiledAppearance::new(&Appearance {
            shininess: Some(formula("0.5")),
            specular: Some(ColorDef::Constant([1.0, 1.0, 1.0])),
            ..Appearance::default()
        })
        .unwrap();
        let m = a.material(&strip(), 0.0, Material::default());
        assert_eq!(m.shininess, 64.0);
        assert!((m.specular - 1.0).abs() < 1e-6);
        assert_eq!(m.opacity, 1.0);
    }

    #[test]
    fn bad_formulas_are_errors_naming_the_slot() {
        let err = CompiledAppearance::new(&Appearance {
            diffuse: Some(ColorDef::Rgb(formula("r = x; g = y;"))),
            ..Appearance::default()
        })
        .unwrap_err();
        assert!(err.to_string().starts_with("diffuse colour"), "{err}");
        let err = CompiledAppearance::new(&Appearance {
            displacement: Some(formula("sin(")),
            ..Appearance::default()
        })
        .unwrap_err();
        assert!(matches!(
            err,
            AppearanceError::Compile {
                slot: "displacement",
                ..
            }
        ));
    }
}
