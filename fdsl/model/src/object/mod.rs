//! The object model every crate shares (thesis chapter 4, section 6.4): an [`Object`] is
//! geometry, appearance and physics, each a set of formulas in its own domain placed by its
//! own instance transform, plus the history of sculpting [`Edit`]s folded over them.
//!
//! - [`ObjectData`] is the plain description (what files and ops carry); [`Object`] is the
//!   same, validated, with every formula compiled and the edit history indexed.
//! - A change of one property is a [`Field`]; its [`Slot`] names the property (replication
//!   resolves concurrent writes per slot).
//! - [`Sampler`] evaluates an object (value, gradient, interval over a box, colour, each
//!   physical property, force field) at object-space points and scene time, allocating only
//!   when created. [`BoxSampler`] (from [`Sampler::restrict`]) is the same object restricted
//!   to a box, evaluating many points at once with the sampler's values bit for bit.
//! - [`codec`] is the canonical, versioned binary form of objects and edits.
//! - An edit's tool is a [`ToolShape`]; [`ToolKind`] is the one list of its kinds, with the
//!   names and the sizes ([`ToolSize`]) that brushes and files read and write them by.
//! - A formula checked before its object is built ([`Formula::tape`]) is compiled through the
//!   same per-process cache ([`compiled`]), so it is compiled once.
//!
//! Sign convention: `f >= 0` is inside (an imported mesh's value is its signed distance). An
//! object with no geometry, or with parametric
//! geometry (which has no field; its surface is meshed from its parameters), starts from
//! [`NOTHING`] and is what its union edits add.

pub mod appearance;
mod arena;
mod box_sampler;
pub mod codec;
pub mod compiled;
pub mod edit;
pub mod fit;
pub mod geometry;
pub mod history;
pub mod physics;
mod sample;
mod shared;
mod slice_eval;
pub mod space;
pub mod tool;

use std::fmt;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

pub use appearance::{Appearance, ColorDef, ColorMap, Rgb};
pub use box_sampler::{BoxSampler, MAX_SCAN_EDITS};
pub use edit::{CompiledEdit, Edit, EditOp, PaintValue, Paintable};
pub use fit::{FitError, fit_domain, fit_domain_within};
pub use geometry::{Geometry, ParametricKind, Shape};
pub use history::History;
pub use physics::{ForceField, Physics, Property};
pub use sample::{ColorSlot, DEFAULT_DIFFUSE, MAX_RAY_PIECES, Sampler};
pub use shared::Shared;
pub use space::{Domain, Motion, Timing, Transform};
pub use tool::{Axis, Pose, ToolKind, ToolShape, ToolSize};

use crate::bvh::Aabb;
use fdsl::limits::MAX_SOURCE_BYTES;
use fdsl::tape::Tape;
use fdsl::{CompileError, Function, Grids, MissingOutput};

/// The value of empty space: far outside, finite so that blends stay well defined.
pub const NOTHING: f64 = -1e30;

/// Longest object name, in bytes.
pub const MAX_NAME_BYTES: usize = 256;

/// A function string as the user typed it (compiled when an object is built).
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Formula(String);

impl Formula {
    /// A formula from text, at most [`MAX_SOURCE_BYTES`] long.
    pub fn new(text: impl Into<String>) -> Result<Formula, ObjectError> {
        let text = text.into();
        if text.len() > MAX_SOURCE_BYTES {
            return Err(ObjectError::FormulaTooLong { len: text.len() });
        }
        Ok(Formula(text))
    }

    /// The text.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    fn check_len(&self) -> Result<(), ObjectError> {
        if self.0.len() > MAX_SOURCE_BYTES {
            return Err(ObjectError::FormulaTooLong { len: self.0.len() });
        }
        Ok(())
    }

    /// The tape of `outputs` (the main value when empty) of the formula, which may call
    /// `grids`, for `slot` (which errors name): from the process's compile cache
    /// ([`compiled`]), or compiled once and kept there. What objects are built with, and what
    /// a caller checking a formula before it builds an object takes, so that the text is
    /// compiled once.
    pub fn tape(&self, slot: Slot, outputs: &[&str], grids: &Grids) -> Result<Tape, ObjectError> {
        self.first_tape(slot, &[outputs], grids)
            .map(|(_, tape)| tape)
    }

    /// The first of `choices` (sets of outputs, as for [`Formula::tape`]) that the formula
    /// defines, with its tape, compiling the text at most once whichever it is (a colour is
    /// its `r`, `g`, `b`, or else a scalar through a colour map). Defining none of them is
    /// [`ObjectError::MissingOutput`] for the last.
    pub fn first_tape(
        &self,
        slot: Slot,
        choices: &[&[&str]],
        grids: &Grids,
    ) -> Result<(usize, Tape), ObjectError> {
        self.check_len()?;
        let answer = compiled::first_tape(&self.0, choices, grids, || {
            let options = fdsl::Options {
                max_graph_nodes: Some(fdsl::limits::formula_node_budget(self.0.len())),
                grids: grids.clone(),
                ..fdsl::Options::default()
            };
            Function::parse_with(&self.0, options).map_err(|error| ObjectError::Compile {
                slot,
                error: Box::new(error),
            })
        })?;
        answer.map_err(|error| ObjectError::MissingOutput { slot, error })
    }
}

impl fmt::Display for Formula {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// A property of an object that one [`Field`] sets: the unit of last-writer-wins.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Slot {
    /// The name.
    Name,
    /// The geometry.
    Geometry,
    /// Diffuse colour.
    Diffuse,
    /// Ambient colour.
    Ambient,
    /// Specular colour.
    Specular,
    /// Transparency.
    Transparency,
    /// Shininess.
    Shininess,
    /// Geometric texture.
    Displacement,
    /// The appearance's domain and transform.
    AppearanceSpace,
    /// The haptic container.
    Container,
    /// Surface tension.
    Tension,
    /// Friction.
    Friction,
    /// Surface-zone depth.
    ZoneDepth,
    /// Density.
    Density,
    /// Force field.
    Force,
    /// The physics' domain and transform.
    PhysicsSpace,
    /// The object's transform.
    Transform,
    /// The object's motion.
    Motion,
    /// The sampled grids its formulas may call.
    Grids,
}

impl fmt::Display for Slot {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = match self {
            Slot::Name => "name",
            Slot::Geometry => "geometry",
            Slot::Diffuse => "diffuse colour",
            Slot::Ambient => "ambient colour",
            Slot::Specular => "specular colour",
            Slot::Transparency => "transparency",
            Slot::Shininess => "shininess",
            Slot::Displacement => "geometric texture",
            Slot::AppearanceSpace => "appearance domain",
            Slot::Container => "haptic container",
            Slot::Tension => "surface tension",
            Slot::Friction => "friction",
            Slot::ZoneDepth => "surface-zone depth",
            Slot::Density => "density",
            Slot::Force => "force field",
            Slot::PhysicsSpace => "physics domain",
            Slot::Transform => "transform",
            Slot::Motion => "motion",
            Slot::Grids => "grids",
        };
        f.write_str(name)
    }
}

/// What is wrong with an object, an edit or their encoding.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ObjectError {
    /// The grids are too many or share a name.
    #[error("grids: {reason}")]
    BadGrids {
        /// What is wrong.
        reason: String,
    },
    /// A formula does not compile.
    #[error("{slot}: {error}")]
    Compile {
        /// Where the formula is.
        slot: Slot,
        /// The compiler's diagnostics.
        error: Box<CompileError>,
    },
    /// A formula lacks an output its slot needs (for example `r`, `g`, `b` of a colour).
    #[error("{slot}: {error}")]
    MissingOutput {
        /// Where the formula is.
        slot: Slot,
        /// Which output.
        error: MissingOutput,
    },
    /// A formula is longer than `MAX_SOURCE_BYTES`.
    #[error("a formula of {len} bytes is longer than the limit of {MAX_SOURCE_BYTES}")]
    FormulaTooLong {
        /// Its length.
        len: usize,
    },
    /// A name is longer than [`MAX_NAME_BYTES`].
    #[error("a name of {len} bytes is longer than the limit of {MAX_NAME_BYTES}")]
    NameTooLong {
        /// Its length.
        len: usize,
    },
    /// A domain box is not finite or has an edge that is not positive.
    #[error("{slot}: the domain box must be finite with positive size")]
    BadDomain {
        /// Where.
        slot: Slot,
    },
    /// A transform is not finite or not invertible.
    #[error("{slot}: the transform must be finite and invertible")]
    BadTransform {
        /// Where.
        slot: Slot,
    },
    /// A cycle interval or time span is not valid.
    #[error("{slot}: the cycle interval must be >= 0 and the time span finite and ordered")]
    BadTiming {
        /// Where.
        slot: Slot,
    },
    /// Parameter ranges are not finite and ordered.
    #[error("{slot}: parameter ranges must be finite with lo <= hi")]
    BadParameters {
        /// Where.
        slot: Slot,
    },
    /// A colour map or colour is not valid.
    #[error("{slot}: {reason}")]
    BadColorMap {
        /// Where.
        slot: Slot,
        /// What is wrong.
        reason: &'static str,
    },
    /// A tool shape is not valid.
    #[error("tool: {reason}")]
    BadTool {
        /// What is wrong.
        reason: &'static str,
    },
    /// A stroke is not valid.
    #[error("stroke: {reason}")]
    BadStroke {
        /// What is wrong.
        reason: &'static str,
    },
    /// A painted value is not finite (or a colour component is outside `[0, 1]`).
    #[error("paint: the value must be finite and colours within [0, 1]")]
    BadPaint,
    /// The history is full.
    #[error("the object already holds the most edits allowed")]
    TooManyEdits,
    /// Bytes do not decode.
    #[error("cannot decode {what}: {reason}")]
    Decode {
        /// What was being decoded.
        what: &'static str,
        /// Why not.
        reason: String,
    },
}

/// An object described plainly: what files and ops carry.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ObjectData {
    /// A label for people.
    pub name: String,
    /// The geometry; `None` is empty space, to be built by union edits.
    pub geometry: Option<Geometry>,
    /// How it looks (shared between copies until one changes it).
    pub appearance: Shared<Appearance>,
    /// How it feels (shared between copies until one changes it).
    pub physics: Shared<Physics>,
    /// Object space to its parent's space.
    pub transform: Transform,
    /// A time-dependent placement applied after `transform`.
    pub motion: Option<Motion>,
    /// Sampled grids (volume data) its formulas may call by name: at most
    /// [`fdsl::grid::MAX_GRIDS`], with distinct names.
    pub grids: Grids,
}

/// One property's new value (see [`Slot`]). Values larger than a colour are boxed: every
/// replicated `Set` holds a field, and the largest variant sets the size of all of them. A box
/// encodes as its value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Field {
    /// The name.
    Name(String),
    /// The geometry.
    Geometry(Option<Box<Geometry>>),
    /// Diffuse colour.
    Diffuse(Option<ColorDef>),
    /// Ambient colour.
    Ambient(Option<ColorDef>),
    /// Specular colour.
    Specular(Option<ColorDef>),
    /// Transparency.
    Transparency(Option<Formula>),
    /// Shininess.
    Shininess(Option<Formula>),
    /// Geometric texture (displacement along the normal).
    Displacement(Option<Formula>),
    /// The appearance's domain and transform.
    AppearanceSpace(Option<Box<Domain>>, Box<Transform>),
    /// The haptic container (`None`: the geometry).
    Container(Option<Box<Geometry>>),
    /// Surface tension.
    Tension(Option<Property>),
    /// Friction.
    Friction(Option<Property>),
    /// Surface-zone depth.
    ZoneDepth(Option<Property>),
    /// Density.
    Density(Option<Property>),
    /// Force field.
    Force(Option<Box<ForceField>>),
    /// The physics' domain and transform.
    PhysicsSpace(Option<Box<Domain>>, Box<Transform>),
    /// The object's transform.
    Transform(Box<Transform>),
    /// The object's motion.
    Motion(Option<Box<Motion>>),
    /// The sampled grids (every formula is compiled again with them).
    Grids(Grids),
}

// A replicated `Set` holds one field: a colour's size, not a geometry's (which was 240 bytes).
const _: () = assert!(size_of::<Field>() <= 56);

impl Field {
    /// The property this field writes.
    pub fn slot(&self) -> Slot {
        match self {
            Field::Name(_) => Slot::Name,
            Field::Geometry(_) => Slot::Geometry,
            Field::Diffuse(_) => Slot::Diffuse,
            Field::Ambient(_) => Slot::Ambient,
            Field::Specular(_) => Slot::Specular,
            Field::Transparency(_) => Slot::Transparency,
            Field::Shininess(_) => Slot::Shininess,
            Field::Displacement(_) => Slot::Displacement,
            Field::AppearanceSpace(..) => Slot::AppearanceSpace,
            Field::Container(_) => Slot::Container,
            Field::Tension(_) => Slot::Tension,
            Field::Friction(_) => Slot::Friction,
            Field::ZoneDepth(_) => Slot::ZoneDepth,
            Field::Density(_) => Slot::Density,
            Field::Force(_) => Slot::Force,
            Field::PhysicsSpace(..) => Slot::PhysicsSpace,
            Field::Transform(_) => Slot::Transform,
            Field::Motion(_) => Slot::Motion,
            Field::Grids(_) => Slot::Grids,
        }
    }

    /// Writes the field into `data`.
    pub fn apply_to(self, data: &mut ObjectData) {
        let (a, p) = (&mut data.appearance, &mut data.physics);
        match self {
            Field::Name(v) => data.name = v,
            Field::Geometry(v) => data.geometry = v.map(|g| *g),
            Field::Diffuse(v) => a.diffuse = v,
            Field::Ambient(v) => a.ambient = v,
            Field::Specular(v) => a.specular = v,
            Field::Transparency(v) => a.transparency = v,
            Field::Shininess(v) => a.shininess = v,
            Field::Displacement(v) => a.displacement = v,
            Field::AppearanceSpace(d, t) => (a.domain, a.transform) = (d.map(|d| *d), *t),
            Field::Container(v) => p.container = v.map(|g| *g),
            Field::Tension(v) => p.tension = v,
            Field::Friction(v) => p.friction = v,
            Field::ZoneDepth(v) => p.zone_depth = v,
            Field::Density(v) => p.density = v,
            Field::Force(v) => p.force = v.map(|f| *f),
            Field::PhysicsSpace(d, t) => (p.domain, p.transform) = (d.map(|d| *d), *t),
            Field::Transform(v) => data.transform = *v,
            Field::Motion(v) => data.motion = v.map(|m| *m),
            Field::Grids(v) => data.grids = v,
        }
    }
}

/// An object's grids are few enough and distinctly named.
fn check_grids(grids: &Grids) -> Result<(), ObjectError> {
    let bad = |reason: String| Err(ObjectError::BadGrids { reason });
    if grids.len() > fdsl::grid::MAX_GRIDS {
        return bad(format!(
            "{} grids; an object may hold at most {}",
            grids.len(),
            fdsl::grid::MAX_GRIDS
        ));
    }
    for (i, g) in grids.iter().enumerate() {
        if grids[..i].iter().any(|h| h.name() == g.name()) {
            return bad(format!("two grids are named `{}`", g.name()));
        }
    }
    Ok(())
}

/// A compiled shape: its field's tape (none for parametric shapes) and its placement.
#[derive(Clone, Debug)]
pub(crate) struct CompiledShape {
    pub(crate) tape: Option<Tape>,
    /// A parametric shape's outputs `x`, `y`, `z` (render triangulates it; it has no field).
    pub(crate) parametric: Option<Tape>,
    pub(crate) mesh: Option<Arc<crate::mesh::TriMesh>>,
    pub(crate) domain: Option<Domain>,
    /// Object space to shape space.
    pub(crate) local_from_object: Transform,
}

impl CompiledShape {
    fn new(geometry: &Geometry, slot: Slot, grids: &Grids) -> Result<CompiledShape, ObjectError> {
        geometry.validate(slot)?;
        let (tape, parametric, mesh) = match &geometry.shape {
            Shape::Implicit(f) => (Some(f.tape(slot, &[], grids)?), None, None),
            Shape::Parametric { formula, .. } => (
                None,
                Some(formula.tape(slot, &["x", "y", "z"], grids)?),
                None,
            ),
            Shape::Mesh(m) => (None, None, Some(m.clone())),
        };
        Ok(CompiledShape {
            tape,
            parametric,
            mesh,
            domain: geometry.domain,
            local_from_object: geometry
                .transform
                .inverse()
                .ok_or(ObjectError::BadTransform { slot })?,
        })
    }
}

/// A colour definition ([`ColorDef`]) compiled: what [`Object::color`] hands to evaluators
/// ([`Sampler`], render's appearance) so that they do not compile its text again.
#[derive(Clone, Debug)]
pub enum CompiledColor {
    /// One colour everywhere.
    Constant(Rgb),
    /// A tape with the outputs `r`, `g`, `b`, in that order.
    Rgb(Tape),
    /// A scalar tape and the colour map it goes through.
    Map(Tape, ColorMap),
}

impl CompiledColor {
    fn new(def: &ColorDef, slot: Slot, grids: &Grids) -> Result<CompiledColor, ObjectError> {
        def.validate(slot)?;
        Ok(match def {
            ColorDef::Constant(c) => CompiledColor::Constant(*c),
            ColorDef::Rgb(f) => CompiledColor::Rgb(f.tape(slot, &["r", "g", "b"], grids)?),
            ColorDef::Map { formula, map } => {
                CompiledColor::Map(formula.tape(slot, &[], grids)?, map.clone())
            }
        })
    }
}

/// Every formula of an object, compiled. A scene holds one per object: the parts most objects
/// lack (a container, a space other than the object's) cost a pointer each.
#[derive(Clone, Debug)]
pub(crate) struct CompiledParts {
    pub(crate) geometry: Option<CompiledShape>,
    pub(crate) container: Option<Box<CompiledShape>>,
    pub(crate) colors: [Option<CompiledColor>; 3],
    /// Transparency, shininess, displacement.
    pub(crate) looks: [Option<Tape>; 3],
    pub(crate) appearance_from_object: SparseTransform,
    /// Tension, friction, zone depth, density (disabled ones are `None`).
    pub(crate) feels: [Option<Tape>; 4],
    pub(crate) physics_from_object: SparseTransform,
    pub(crate) force: Option<Tape>,
    pub(crate) motion: Option<[Option<Tape>; 2]>,
}

const _: () = assert!(size_of::<CompiledParts>() <= 400);

/// A transform held behind a pointer unless it is the identity, which is then not stored.
#[derive(Clone, Debug)]
pub(crate) struct SparseTransform(Option<Box<Transform>>);

impl SparseTransform {
    fn new(t: Transform) -> SparseTransform {
        SparseTransform((!t.is_identity()).then(|| Box::new(t)))
    }

    /// The transform.
    pub(crate) fn get(&self) -> &Transform {
        self.0.as_deref().unwrap_or(&Transform::IDENTITY)
    }
}

impl CompiledParts {
    fn new(data: &ObjectData) -> Result<CompiledParts, ObjectError> {
        compiled::count_object_build();
        if data.name.len() > MAX_NAME_BYTES {
            return Err(ObjectError::NameTooLong {
                len: data.name.len(),
            });
        }
        let grids = &data.grids;
        check_grids(grids)?;
        let geometry = data
            .geometry
            .as_ref()
            .map(|g| CompiledShape::new(g, Slot::Geometry, grids))
            .transpose()?;
        let (a, p) = (&data.appearance, &data.physics);
        a.validate()?;
        p.validate()?;
        let force = match &p.force {
            Some(f) => {
                let tape = f.formula.tape(Slot::Force, &["x", "y", "z"], grids)?;
                f.enabled.then_some(tape)
            }
            None => None,
        };
        let motion = data
            .motion
            .as_ref()
            .map(|m| motion_tapes(m, grids))
            .transpose()?;
        data.transform.validate(Slot::Transform)?;
        let container = p
            .container
            .as_ref()
            .map(|g| CompiledShape::new(g, Slot::Container, grids).map(Box::new))
            .transpose()?;
        let (colors, looks) = appearance_parts(a, grids)?;
        let appearance_from_object =
            SparseTransform::new(a.transform.inverse().ok_or(ObjectError::BadTransform {
                slot: Slot::AppearanceSpace,
            })?);
        let feels = feel_tapes(p, grids)?;
        let physics_from_object =
            SparseTransform::new(p.transform.inverse().ok_or(ObjectError::BadTransform {
                slot: Slot::PhysicsSpace,
            })?);
        Ok(CompiledParts {
            geometry,
            container,
            colors,
            looks,
            appearance_from_object,
            feels,
            physics_from_object,
            force,
            motion,
        })
    }
}

/// The colours (diffuse, ambient, specular) and looks (transparency, shininess, displacement)
/// of an appearance, compiled in that order.
#[expect(
    clippy::type_complexity,
    reason = "the two arrays of CompiledParts, as they are"
)]
fn appearance_parts(
    a: &Appearance,
    grids: &Grids,
) -> Result<([Option<CompiledColor>; 3], [Option<Tape>; 3]), ObjectError> {
    let color = |def: &Option<ColorDef>, slot| {
        def.as_ref()
            .map(|d| CompiledColor::new(d, slot, grids))
            .transpose()
    };
    let scalar =
        |f: &Option<Formula>, slot| f.as_ref().map(|f| f.tape(slot, &[], grids)).transpose();
    let colors = [
        color(&a.diffuse, Slot::Diffuse)?,
        color(&a.ambient, Slot::Ambient)?,
        color(&a.specular, Slot::Specular)?,
    ];
    let looks = [
        scalar(&a.transparency, Slot::Transparency)?,
        scalar(&a.shininess, Slot::Shininess)?,
        scalar(&a.displacement, Slot::Displacement)?,
    ];
    Ok((colors, looks))
}

/// The tapes of the enabled surface and interior properties: tension, friction, zone depth,
/// density. Disabled properties are compiled too (a broken one is an error now, not when it is
/// enabled later) but not kept.
fn feel_tapes(p: &Physics, grids: &Grids) -> Result<[Option<Tape>; 4], ObjectError> {
    let feel = |prop: &Option<Property>, slot| -> Result<Option<Tape>, ObjectError> {
        let Some(prop) = prop else { return Ok(None) };
        let tape = prop.formula.tape(slot, &[], grids)?;
        Ok(prop.enabled.then_some(tape))
    };
    Ok([
        feel(&p.tension, Slot::Tension)?,
        feel(&p.friction, Slot::Friction)?,
        feel(&p.zone_depth, Slot::ZoneDepth)?,
        feel(&p.density, Slot::Density)?,
    ])
}

/// A motion's translation and angle tapes, once its timing and axis are checked.
fn motion_tapes(m: &Motion, grids: &Grids) -> Result<[Option<Tape>; 2], ObjectError> {
    m.timing.validate(Slot::Motion)?;
    if m.angle.is_some() && !(m.axis.is_finite() && m.axis.length() > 1e-12) {
        return Err(ObjectError::BadTransform { slot: Slot::Motion });
    }
    Ok([
        m.translation
            .as_ref()
            .map(|f| f.tape(Slot::Motion, &["x", "y", "z"], grids))
            .transpose()?,
        m.angle
            .as_ref()
            .map(|f| f.tape(Slot::Motion, &[], grids))
            .transpose()?,
    ])
}

/// An object: its description, compiled, and its indexed edit history.
#[derive(Clone, Debug)]
pub struct Object {
    /// Shared with whoever holds the description (a replicated op), not copied: an
    /// `ObjectData` is about 0.5 KB before its formulas.
    data: Arc<ObjectData>,
    parts: Arc<CompiledParts>,
    history: History,
}

// A scene holds its objects inline and their descriptions behind a pointer (192 bytes until
// the history's bounds for its intervals, 12 more, and their padding).
const _: () = assert!(size_of::<Object>() <= 200);

impl Object {
    /// Validates and compiles `data` (an `ObjectData`, or an `Arc<ObjectData>` to share);
    /// every formula must compile.
    pub fn new(data: impl Into<Arc<ObjectData>>) -> Result<Object, ObjectError> {
        let data = data.into();
        let parts = Arc::new(CompiledParts::new(&data)?);
        Ok(Object {
            data,
            parts,
            history: History::default(),
        })
    }

    /// An object with the implicit solid `formula` as geometry and nothing else.
    pub fn implicit(formula: &str) -> Result<Object, ObjectError> {
        Object::new(ObjectData {
            geometry: Some(Geometry::implicit(Formula::new(formula)?)),
            ..ObjectData::default()
        })
    }

    /// The description (without the edits; see [`Object::history`]).
    pub fn data(&self) -> &ObjectData {
        &self.data
    }

    /// The description as shared with whoever else holds it.
    pub fn shared_data(&self) -> &Arc<ObjectData> {
        &self.data
    }

    /// Sets one property; on error the object is unchanged.
    pub fn set(&mut self, field: Field) -> Result<(), ObjectError> {
        let mut data = ObjectData::clone(&self.data);
        field.apply_to(&mut data);
        self.parts = Arc::new(CompiledParts::new(&data)?);
        self.data = Arc::new(data);
        Ok(())
    }

    /// Applies an edit at the end of the history; returns its index.
    pub fn apply(&mut self, edit: Edit) -> Result<usize, ObjectError> {
        let compiled = CompiledEdit::new(edit)?;
        self.history.push(Arc::new(compiled))
    }

    /// Applies an already compiled edit (edits are shared between objects' checkpoints).
    pub fn apply_compiled(&mut self, edit: Arc<CompiledEdit>) -> Result<usize, ObjectError> {
        self.history.push(edit)
    }

    /// Removes edit `idx` from the fold; false if there is no such edit.
    pub fn undo(&mut self, idx: usize) -> bool {
        self.history.set_active(idx, false)
    }

    /// Puts edit `idx` back into the fold; false if there is no such edit.
    pub fn redo(&mut self, idx: usize) -> bool {
        self.history.set_active(idx, true)
    }

    /// Tape instructions one haptic sample of the object runs: its container's geometry (or
    /// its own) and every enabled physics property and force field, once each. What the
    /// haptic crate weighs against its tick budget; the edits' folds come on top (indexed,
    /// so bounded by the edits near the point).
    pub fn touch_instructions(&self) -> usize {
        let shape = if self.data.physics.container.is_some() {
            Slot::Container
        } else {
            Slot::Geometry
        };
        [
            shape,
            Slot::Tension,
            Slot::Friction,
            Slot::ZoneDepth,
            Slot::Density,
            Slot::Force,
        ]
        .into_iter()
        .filter_map(|slot| self.tape(slot))
        .map(Tape::len)
        .sum()
    }

    /// Whether touch can feel anything of the object: an enabled tension, friction, zone
    /// depth or density, an enabled force field, or an active painting of one of those. An
    /// object with none (a plain VRML `Shape`, an imported polygon model) is seen, not felt:
    /// the haptic crate leaves it out, so it never hides the containers it overlaps.
    pub fn is_tangible(&self) -> bool {
        let p = &self.data.physics;
        let enabled = |q: &Option<Property>| q.as_ref().is_some_and(|q| q.enabled);
        let physical = |what: Paintable| {
            matches!(
                what,
                Paintable::Tension
                    | Paintable::Friction
                    | Paintable::ZoneDepth
                    | Paintable::Density
            )
        };
        enabled(&p.tension)
            || enabled(&p.friction)
            || enabled(&p.zone_depth)
            || enabled(&p.density)
            || p.force.as_ref().is_some_and(|f| f.enabled)
            || self.history.entries().iter().any(|e| {
                e.active
                    && matches!(e.edit.edit().op, EditOp::Paint { property, .. } if physical(property))
            })
    }

    /// The edit history.
    pub fn history(&self) -> &History {
        &self.history
    }

    /// The edit history, to truncate for a re-fold.
    pub fn history_mut(&mut self) -> &mut History {
        &mut self.history
    }

    /// Indexes recent edits; call before sampling after a batch of edits (sampling is correct
    /// without it, only slower).
    pub fn prepare(&mut self) {
        self.history.refresh();
    }

    /// A sampler for this object (an independent copy; later edits do not reach it).
    pub fn sampler(&self) -> Sampler {
        Sampler::new(Arc::new(self.clone()))
    }

    /// A box, in object space, around the solid: the geometry's domain (if bounded) and
    /// every active union edit. `None` when unbounded (an implicit solid without a domain).
    pub fn bounds(&self) -> Option<Aabb> {
        let mut b = match (&self.data.geometry, &self.parts.geometry) {
            (Some(g), Some(c)) => match (&c.mesh, c.tape.is_some(), &g.domain) {
                (_, _, Some(d)) => g.transform.aabb(&d.aabb()),
                (Some(m), _, None) => g.transform.aabb(&m.bounds()),
                (None, true, None) => return None,
                (None, false, None) => Aabb::EMPTY,
            },
            _ => Aabb::EMPTY,
        };
        let mut last_intersect = None;
        for (i, e) in self.history.entries().iter().enumerate() {
            if !e.active {
                continue;
            }
            match e.edit.edit().op {
                EditOp::Union => b = b.union(&e.edit.bounds()),
                EditOp::Intersect => last_intersect = Some(i),
                _ => {}
            }
        }
        if let Some(k) = last_intersect {
            // After an intersection only its tool and later unions hold anything.
            let mut after = self.history.entries()[k].edit.bounds();
            for e in &self.history.entries()[k + 1..] {
                if e.active && matches!(e.edit.edit().op, EditOp::Union) {
                    after = after.union(&e.edit.bounds());
                }
            }
            b = Aabb {
                lo: b.lo.max(after.lo),
                hi: b.hi.min(after.hi),
            };
        }
        Some(b)
    }

    pub(crate) fn parts(&self) -> &CompiledParts {
        &self.parts
    }

    /// The compiled tape of the formula in `slot`, compiled when the formula was set (through
    /// [`compiled`], the per-process cache): what render and haptic evaluate instead of
    /// compiling the object's text again. Tapes read `x, y, z, t` in the slot's own space
    /// (geometry, container, appearance or physics space; `u, v, w, t` for parametric shapes
    /// and the force field).
    /// - [`Slot::Geometry`], [`Slot::Container`]: an implicit shape's value, or a parametric
    ///   shape's outputs `x`, `y`, `z`; `None` for an imported mesh or no shape.
    /// - [`Slot::Diffuse`], [`Slot::Ambient`], [`Slot::Specular`]: a parametric colour's
    ///   outputs `r`, `g`, `b`, or a colour map's scalar; `None` for a constant colour (see
    ///   [`Object::color`] for the whole definition).
    /// - [`Slot::Transparency`], [`Slot::Shininess`], [`Slot::Displacement`]: the scalar.
    /// - [`Slot::Tension`], [`Slot::Friction`], [`Slot::ZoneDepth`], [`Slot::Density`]: the
    ///   scalar; `None` when the property is disabled.
    /// - [`Slot::Force`]: outputs `x`, `y`, `z`; `None` when the field is disabled.
    /// - [`Slot::Motion`] has two formulas and is `None` here ([`Sampler::placement`]
    ///   evaluates them); the slots without formulas are `None`.
    pub fn tape(&self, slot: Slot) -> Option<&Tape> {
        fn shape(s: Option<&CompiledShape>) -> Option<&Tape> {
            s.and_then(|s| s.tape.as_ref().or(s.parametric.as_ref()))
        }
        fn color(c: &Option<CompiledColor>) -> Option<&Tape> {
            match c {
                Some(CompiledColor::Rgb(tape) | CompiledColor::Map(tape, _)) => Some(tape),
                Some(CompiledColor::Constant(_)) | None => None,
            }
        }
        let parts = &*self.parts;
        match slot {
            Slot::Geometry => shape(parts.geometry.as_ref()),
            Slot::Container => shape(parts.container.as_deref()),
            Slot::Diffuse => color(&parts.colors[ColorSlot::Diffuse as usize]),
            Slot::Ambient => color(&parts.colors[ColorSlot::Ambient as usize]),
            Slot::Specular => color(&parts.colors[ColorSlot::Specular as usize]),
            Slot::Transparency => parts.looks[0].as_ref(),
            Slot::Shininess => parts.looks[1].as_ref(),
            Slot::Displacement => parts.looks[2].as_ref(),
            Slot::Tension => parts.feels[0].as_ref(),
            Slot::Friction => parts.feels[1].as_ref(),
            Slot::ZoneDepth => parts.feels[2].as_ref(),
            Slot::Density => parts.feels[3].as_ref(),
            Slot::Force => parts.force.as_ref(),
            Slot::Name
            | Slot::AppearanceSpace
            | Slot::PhysicsSpace
            | Slot::Transform
            | Slot::Motion
            | Slot::Grids => None,
        }
    }

    /// The compiled colour in `slot`; `None` when the appearance has none there.
    pub fn color(&self, slot: ColorSlot) -> Option<&CompiledColor> {
        self.parts.colors[slot as usize].as_ref()
    }

    /// Object space to appearance space (the inverse of the appearance's transform, checked
    /// when it was set).
    pub fn appearance_from_object(&self) -> Transform {
        *self.parts.appearance_from_object.get()
    }
}

impl PartialEq for Object {
    /// Same description and same edits with the same activity.
    fn eq(&self, other: &Object) -> bool {
        self.data == other.data
            && self.history.len() == other.history.len()
            && self
                .history
                .entries()
                .iter()
                .zip(other.history.entries())
                .all(|(a, b)| a.active == b.active && a.edit.edit() == b.edit.edit())
    }
}
