//! `FShape` and `Shape` nodes to [`ObjectData`]: geometry (`FGeometry` and VRML's `Box`,
//! `Sphere`, `Cylinder`, `Cone` as exact F-Rep solids), appearance (`FAppearance`,
//! `FMaterial`, `FColorMap`, `FTexture3D`, VRML's `Appearance` and `Material`) and physics
//! (`FPhysics`, `FSurface`, `FTension`, `FFriction`, `FDepth`, `FDensity`, `FForce`).

use glam::DVec3;

use super::document::{Field, Node, Value};
use super::read::{Fields, Reader};
use super::writer::format_number;
use crate::Function;
use crate::object::{
    Appearance, ColorDef, ColorMap, Domain, ForceField, Formula, Geometry, ObjectData,
    ParametricKind, Physics, Property, Rgb, Shape, Slot,
};

/// Node types that can be a geometry.
pub(super) const GEOMETRY_TYPES: &[&str] = &[
    "FGeometry",
    "Box",
    "Sphere",
    "Cylinder",
    "Cone",
    "IndexedFaceSet",
];

/// The parameter range of a parametric definition or force field that the text leaves out.
pub(super) const DEFAULT_RANGE: [f64; 2] = [0.0, 1.0];

const KIND_MESSAGE: &str = "`kind` is \"implicit\", \"curve\", \"surface\" or \"solid\"";

/// What a geometry node gave.
pub(super) enum Read<T> {
    /// A value.
    Value(T),
    /// Nothing usable (already reported).
    Nothing,
    /// Something the object model cannot hold yet: the shape is skipped (already reported).
    Unsupported,
}

impl<'d> Reader<'_, 'd> {
    /// An object from an `FShape` or `Shape`; `None` when it cannot be represented.
    pub(super) fn object(&mut self, node: &'d Node) -> Option<ObjectData> {
        let mut fields = Fields::new(node);
        let mut data = ObjectData {
            name: self.name(&mut fields),
            ..ObjectData::default()
        };
        let function_shape = node.type_name == "FShape";
        if function_shape {
            data.transform = self.transform(&mut fields);
            data.motion = self.motion(&mut fields);
        }
        if let Some(field) = fields.get("geometry") {
            if let Some(g) = self.node_of(field, GEOMETRY_TYPES) {
                match self.geometry(g, Slot::Geometry) {
                    Read::Value(g) => data.geometry = Some(g),
                    Read::Nothing => {}
                    Read::Unsupported => {
                        self.finish(fields);
                        return None;
                    }
                }
            }
        }
        if let Some(field) = fields.get("appearance") {
            if let Some(a) = self.node_of(field, &["FAppearance", "Appearance"]) {
                data.appearance = self.appearance(a);
            }
        }
        if function_shape {
            if let Some(field) = fields.get("physics") {
                if let Some(p) = self.node_of(field, &["FPhysics"]) {
                    data.physics = self.physics(p);
                }
            }
        }
        self.finish(fields);
        Some(data)
    }

    /// The `name` field (our extension), else the `DEF` name, else empty.
    pub(super) fn name(&mut self, fields: &mut Fields<'d>) -> String {
        if let Some(field) = fields.get("name") {
            if let Some(v) = self.strings(field) {
                if let [name] = v.as_slice() {
                    return (*name).to_string();
                }
                self.error(field.value_pos, "the field `name` should be one string");
            }
        }
        fields.node.def.clone().unwrap_or_default()
    }

    /// A geometry node, for `slot` (the geometry or the haptic container).
    pub(super) fn geometry(&mut self, node: &'d Node, slot: Slot) -> Read<Geometry> {
        self.positions.entry(slot).or_insert(node.pos);
        let mut fields = Fields::new(node);
        let read = match node.type_name.as_str() {
            "FGeometry" => self.function_geometry(&mut fields, slot),
            "IndexedFaceSet" => {
                self.warning(
                    node.pos,
                    "polygon meshes are not yet part of the object model; this shape is skipped",
                );
                // Every field of a mesh is left alone on purpose: the warning covers them.
                return Read::Unsupported;
            }
            _ => self.primitive(&mut fields),
        };
        self.finish(fields);
        read
    }

    fn function_geometry(&mut self, fields: &mut Fields<'d>, slot: Slot) -> Read<Geometry> {
        let Some(field) = fields.get("definition") else {
            self.error(fields.node.pos, "`FGeometry` needs a `definition`");
            return Read::Nothing;
        };
        let Some(formula) = self.formula_for(field, slot) else {
            return Read::Nothing;
        };
        let domain = self.domain(fields);
        let transform = self.transform(fields);
        let kind = fields.get("kind");
        let parameters = fields.get("parameters");
        let shape = if kind.is_some() || parameters.is_some() {
            let implicit = kind.is_some_and(|f| matches!(&f.value, Value::String(s) if s == "implicit"));
            if implicit {
                if let Some(p) = parameters {
                    self.warning(p.pos, "`parameters` are ignored for `kind \"implicit\"`");
                }
                return Read::Value(Geometry {
                    shape: Shape::Implicit(formula),
                    domain,
                    transform,
                });
            }
            let ranges = parameters.and_then(|f| self.ranges(f));
            let kind = match kind {
                Some(f) => self.kind(f),
                None => ranges.as_ref().and_then(|(_, n)| match n {
                    1 => Some(ParametricKind::Curve),
                    2 => Some(ParametricKind::Surface),
                    3 => Some(ParametricKind::Solid),
                    _ => None,
                }),
            };
            let Some(kind) = kind else {
                self.error(
                    fields.node.pos,
                    "a parametric `FGeometry` needs one to three `parameters` ranges or a `kind`",
                );
                return Read::Nothing;
            };
            let parameters = ranges.map_or([DEFAULT_RANGE; 3], |(r, _)| r);
            Shape::Parametric {
                formula,
                kind,
                parameters,
            }
        } else {
            parametric_by_outputs(&formula).map_or(Shape::Implicit(formula.clone()), |kind| {
                Shape::Parametric {
                    formula,
                    kind,
                    parameters: [DEFAULT_RANGE; 3],
                }
            })
        };
        Read::Value(Geometry {
            shape,
            domain,
            transform,
        })
    }

    /// `parameters [lo hi ...]`: one to three ranges; the rest are [`DEFAULT_RANGE`].
    fn ranges(&mut self, field: &'d Field) -> Option<([[f64; 2]; 3], usize)> {
        let v = self.numbers_of(field)?;
        if v.len() % 2 != 0 || v.len() > 6 {
            self.error(
                field.value_pos,
                "`parameters` should be pairs of numbers `lo hi`, one pair per parameter (u, v, w)",
            );
            return None;
        }
        let mut ranges = [DEFAULT_RANGE; 3];
        for (range, pair) in ranges.iter_mut().zip(v.chunks_exact(2)) {
            *range = [pair[0], pair[1]];
        }
        Some((ranges, v.len() / 2))
    }

    fn kind(&mut self, field: &'d Field) -> Option<ParametricKind> {
        match &field.value {
            Value::String(s) => match s.as_str() {
                "curve" => Some(ParametricKind::Curve),
                "surface" => Some(ParametricKind::Surface),
                "solid" => Some(ParametricKind::Solid),
                _ => {
                    self.error(field.value_pos, KIND_MESSAGE);
                    None
                }
            },
            _ => {
                self.error(field.value_pos, KIND_MESSAGE);
                None
            }
        }
    }

    /// VRML's `Box`, `Sphere`, `Cylinder` and `Cone` as exact F-Rep solids in their boxes.
    fn primitive(&mut self, fields: &mut Fields<'d>) -> Read<Geometry> {
        let node = fields.node;
        let mut positive = |reader: &mut Self, name: &str, default: f64| -> Option<f64> {
            let Some(field) = fields.get(name) else {
                return Some(default);
            };
            let v = reader.number(field)?;
            if v.is_finite() && v > 0.0 {
                Some(v)
            } else {
                reader.error(field.value_pos, format!("`{name}` should be positive"));
                None
            }
        };
        let n = format_number;
        let solid = match node.type_name.as_str() {
            "Box" => {
                let size = match fields.get("size") {
                    Some(f) => self.vec3(f),
                    None => Some(DVec3::splat(2.0)),
                };
                let Some(size) = size.filter(|s| s.is_finite() && s.min_element() > 0.0) else {
                    self.error(node.pos, "a `Box` needs a positive `size`");
                    return Read::Nothing;
                };
                let h = size * 0.5;
                Some((
                    format!("min({}-abs(x), {}-abs(y), {}-abs(z))", n(h.x), n(h.y), n(h.z)),
                    size,
                ))
            }
            "Sphere" => positive(self, "radius", 1.0)
                .map(|r| (format!("{}-sqrt(x^2+y^2+z^2)", n(r)), DVec3::splat(2.0 * r))),
            "Cylinder" => {
                let r = positive(self, "radius", 1.0);
                let h = positive(self, "height", 2.0);
                self.closed(fields, &["side", "top", "bottom"]);
                r.zip(h).map(|(r, h)| {
                    (
                        format!("min({}-sqrt(x^2+z^2), {}-abs(y))", n(r), n(h * 0.5)),
                        DVec3::new(2.0 * r, h, 2.0 * r),
                    )
                })
            }
            "Cone" => {
                let r = positive(self, "bottomRadius", 1.0);
                let h = positive(self, "height", 2.0);
                self.closed(fields, &["side", "bottom"]);
                // The slanted side's distance, positive inside: the radius at height y is
                // r/2 - (r/h) y (zero at the apex y = h/2), scaled by the side's cosine.
                r.zip(h).map(|(r, h)| {
                    (
                        format!(
                            "min(({}-{}*y-sqrt(x^2+z^2))*{}, y+{})",
                            n(r * 0.5),
                            n(r / h),
                            n(h / r.hypot(h)),
                            n(h * 0.5)
                        ),
                        DVec3::new(2.0 * r, h, 2.0 * r),
                    )
                })
            }
            _ => None,
        };
        let Some((text, size)) = solid else {
            return Read::Nothing;
        };
        match Formula::new(text) {
            Ok(formula) => Read::Value(Geometry::implicit_in(
                formula,
                Domain::new(DVec3::ZERO, size),
            )),
            Err(e) => {
                self.error(node.pos, e.to_string());
                Read::Nothing
            }
        }
    }

    /// Warns when a part of a cylinder or cone is switched off: solids are always closed.
    fn closed(&mut self, fields: &mut Fields<'d>, parts: &[&str]) {
        for part in parts {
            if let Some(field) = fields.get(part) {
                if self.boolean(field) == Some(false) {
                    self.warning(
                        field.pos,
                        format!("`{part} FALSE` is ignored: the solid is read closed"),
                    );
                }
            }
        }
    }

    fn appearance(&mut self, node: &'d Node) -> Appearance {
        let mut fields = Fields::new(node);
        let mut appearance = Appearance::default();
        if let Some(field) = fields.get("material") {
            if let Some(m) = self.node_of(field, &["FMaterial", "Material"]) {
                if m.type_name == "FMaterial" {
                    self.function_material(m, &mut appearance);
                } else {
                    self.material(m, &mut appearance);
                }
            }
        }
        if let Some(field) = fields.get("texture") {
            if let Some(t) = self.node_of(field, &["FTexture3D"]) {
                let mut texture = Fields::new(t);
                if let Some(f) = texture.get("definition") {
                    appearance.displacement = self.formula_for(f, Slot::Displacement);
                }
                self.finish(texture);
            }
        }
        if node.type_name == "FAppearance" {
            appearance.domain = self.domain(&mut fields);
            appearance.transform = self.transform(&mut fields);
        } else if let Some(field) = fields.get("textureTransform") {
            self.warning(field.pos, "`textureTransform` is ignored (image textures are not read)");
        }
        self.finish(fields);
        appearance
    }

    fn function_material(&mut self, node: &'d Node, a: &mut Appearance) {
        let mut fields = Fields::new(node);
        a.diffuse = self.color(&mut fields, "diffuseColor", Slot::Diffuse);
        a.ambient = self.color(&mut fields, "ambientColor", Slot::Ambient);
        a.specular = self.color(&mut fields, "specularColor", Slot::Specular);
        a.transparency = fields
            .get("transparency")
            .and_then(|f| self.formula_for(f, Slot::Transparency));
        a.shininess = fields
            .get("shininess")
            .and_then(|f| self.formula_for(f, Slot::Shininess));
        self.finish(fields);
    }

    /// A colour field of `FMaterial`: three numbers, a formula with outputs `r`, `g`, `b`, or
    /// a scalar formula with a colour map in the field `<name>Map`.
    fn color(&mut self, fields: &mut Fields<'d>, name: &str, slot: Slot) -> Option<ColorDef> {
        let map_name = format!("{name}Map");
        let map = fields
            .get(&map_name)
            .and_then(|f| self.node_of(f, &["FColorMap"]))
            .and_then(|m| self.color_map(m));
        let field = fields.get(name);
        let Some(field) = field else {
            if map.is_some() {
                self.warning(
                    fields.node.pos,
                    format!("`{map_name}` without `{name}` is ignored"),
                );
            }
            return None;
        };
        self.positions.entry(slot).or_insert(field.value_pos);
        if let Value::Numbers(v) | Value::NumberList(v) = &field.value {
            if map.is_some() {
                self.warning(field.pos, format!("`{map_name}` is ignored for a constant colour"));
            }
            return self.rgb(field, v).map(ColorDef::Constant);
        }
        let formula = self.formula(field)?;
        Some(match map {
            Some(map) => ColorDef::Map { formula, map },
            None => ColorDef::Rgb(formula),
        })
    }

    fn rgb(&mut self, field: &Field, v: &[f64]) -> Option<Rgb> {
        if let [r, g, b] = v {
            #[expect(clippy::cast_possible_truncation, reason = "colours are f32")]
            Some([*r as f32, *g as f32, *b as f32])
        } else {
            self.error(
                field.value_pos,
                format!("the colour `{}` should be three numbers r g b", field.name),
            );
            None
        }
    }

    /// `FColorMap { key [g0 g1 ...] keyValue [r g b, ...] }`.
    fn color_map(&mut self, node: &'d Node) -> Option<ColorMap> {
        let mut fields = Fields::new(node);
        let key = fields.get("key").and_then(|f| self.numbers_of(f));
        let value_field = fields.get("keyValue");
        let values = value_field.and_then(|f| self.numbers_of(f));
        self.finish(fields);
        let (key, values) = (key?, values?);
        if values.len() != 3 * key.len() {
            let pos = value_field.map_or(node.pos, |f| f.value_pos);
            self.error(
                pos,
                format!(
                    "`keyValue` should hold one colour (three numbers) per key: {} keys, {} numbers",
                    key.len(),
                    values.len()
                ),
            );
            return None;
        }
        #[expect(clippy::cast_possible_truncation, reason = "colours are f32")]
        let keys = key
            .iter()
            .zip(values.chunks_exact(3))
            .map(|(g, c)| (*g, [c[0] as f32, c[1] as f32, c[2] as f32]))
            .collect();
        Some(ColorMap { keys })
    }

    /// VRML's `Material`: constant colours and numbers.
    fn material(&mut self, node: &'d Node, a: &mut Appearance) {
        let mut fields = Fields::new(node);
        let mut constant = |reader: &mut Self, name: &str, slot: Slot| -> Option<Rgb> {
            let field = fields.get(name)?;
            reader.positions.entry(slot).or_insert(field.value_pos);
            let v = reader.numbers_of(field)?;
            reader.rgb(field, v)
        };
        let diffuse = constant(self, "diffuseColor", Slot::Diffuse);
        let specular = constant(self, "specularColor", Slot::Specular);
        if let Some(e) = constant(self, "emissiveColor", Slot::Diffuse) {
            if e != [0.0; 3] {
                let pos = fields.get("emissiveColor").map_or(node.pos, |f| f.pos);
                self.warning(pos, "`emissiveColor` is ignored (the object model has no emission)");
            }
        }
        a.diffuse = diffuse.map(ColorDef::Constant);
        a.specular = specular.map(ColorDef::Constant);
        if let Some(field) = fields.get("ambientIntensity") {
            if let Some(k) = self.number(field) {
                let base = diffuse.unwrap_or([0.8; 3]);
                #[expect(clippy::cast_possible_truncation, reason = "colours are f32")]
                let k = k.clamp(0.0, 1.0) as f32;
                a.ambient = Some(ColorDef::Constant(base.map(|c| c * k)));
            }
        }
        a.transparency = fields
            .get("transparency")
            .and_then(|f| self.formula_for(f, Slot::Transparency));
        a.shininess = fields
            .get("shininess")
            .and_then(|f| self.formula_for(f, Slot::Shininess));
        self.finish(fields);
    }

    fn physics(&mut self, node: &'d Node) -> Physics {
        let mut fields = Fields::new(node);
        let mut p = Physics::default();
        if let Some(field) = fields.get("surface") {
            if let Some(s) = self.node_of(field, &["FSurface"]) {
                let mut surface = Fields::new(s);
                self.surface(&mut surface, &mut p);
                self.finish(surface);
            }
        }
        // The thesis's Figure 7.4 writes `friction` straight under `FPhysics`.
        self.surface(&mut fields, &mut p);
        if let Some(field) = fields.get("density") {
            if let Some(d) = self.node_of(field, &["FDensity"]) {
                p.density = self.property(d, Slot::Density);
            }
        }
        if let Some(field) = fields.get("force") {
            if let Some(f) = self.node_of(field, &["FForce"]) {
                p.force = self.force(f);
            }
        }
        if let Some(field) = fields.get("container") {
            if let Some(g) = self.node_of(field, GEOMETRY_TYPES) {
                if let Read::Value(g) = self.geometry(g, Slot::Container) {
                    p.container = Some(g);
                }
            }
        }
        p.domain = self.domain(&mut fields);
        p.transform = self.transform(&mut fields);
        self.finish(fields);
        p
    }

    /// `tension`, `friction` and `depth` of an `FSurface` (or written under `FPhysics`).
    fn surface(&mut self, fields: &mut Fields<'d>, p: &mut Physics) {
        for (name, type_name, slot) in [
            ("tension", "FTension", Slot::Tension),
            ("friction", "FFriction", Slot::Friction),
            ("depth", "FDepth", Slot::ZoneDepth),
        ] {
            let Some(field) = fields.get(name) else {
                continue;
            };
            let Some(node) = self.node_of(field, &[type_name]) else {
                continue;
            };
            let property = self.property(node, slot);
            let target = match slot {
                Slot::Tension => &mut p.tension,
                Slot::Friction => &mut p.friction,
                _ => &mut p.zone_depth,
            };
            if target.is_some() {
                self.warning(
                    field.pos,
                    format!("`{name}` is given both in `FSurface` and in `FPhysics`; this one counts"),
                );
            }
            *target = property;
        }
    }

    /// `enable` (default `TRUE`) and `definition`; a disabled property may leave out its
    /// definition (it is kept as `"0"`).
    fn property(&mut self, node: &'d Node, slot: Slot) -> Option<Property> {
        let mut fields = Fields::new(node);
        let enabled = fields
            .get("enable")
            .and_then(|f| self.boolean(f))
            .unwrap_or(true);
        let formula = match fields.get("definition") {
            Some(f) => self.formula_for(f, slot),
            None if !enabled => Formula::new("0").ok(),
            None => {
                self.error(
                    node.pos,
                    format!("`{}` needs a `definition` (or `enable FALSE`)", node.type_name),
                );
                None
            }
        };
        self.finish(fields);
        Some(Property {
            formula: formula?,
            enabled,
        })
    }

    /// `FForce`: `enable`, `definition` (outputs `x`, `y`, `z` of `u`, `v`, `w`, `t`),
    /// `parameters`, `cycleInterval`, `timeSpan`.
    fn force(&mut self, node: &'d Node) -> Option<ForceField> {
        let mut fields = Fields::new(node);
        let enabled = fields
            .get("enable")
            .and_then(|f| self.boolean(f))
            .unwrap_or(true);
        let formula = match fields.get("definition") {
            Some(f) => self.formula_for(f, Slot::Force),
            None if !enabled => Formula::new("0").ok(),
            None => {
                self.error(node.pos, "`FForce` needs a `definition` (or `enable FALSE`)");
                None
            }
        };
        let parameters = match fields.get("parameters") {
            Some(f) => self.ranges(f).map(|(r, _)| r),
            None => Some([DEFAULT_RANGE; 3]),
        };
        let timing = self.timing(&mut fields);
        self.finish(fields);
        Some(ForceField {
            formula: formula?,
            parameters: parameters?,
            timing,
            enabled,
        })
    }
}

/// The kind of a definition without `parameters` or `kind`: parametric when it defines `x`,
/// `y` and `z` and no single value, by the last of `u`, `v`, `w` it reads.
pub(super) fn parametric_by_outputs(formula: &Formula) -> Option<ParametricKind> {
    let function = Function::parse(formula.as_str()).ok()?;
    let parametric = ["x", "y", "z"].iter().all(|o| function.has_output(o))
        && !function.has_output("value");
    if !parametric {
        return None;
    }
    let used = function.inputs_used();
    Some(if used[2] {
        ParametricKind::Solid
    } else if used[1] {
        ParametricKind::Surface
    } else {
        ParametricKind::Curve
    })
}
