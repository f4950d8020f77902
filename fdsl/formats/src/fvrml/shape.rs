//! `FShape` and `Shape` nodes to [`ObjectData`]: geometry (`FGeometry` and VRML's `Box`,
//! `Sphere`, `Cylinder`, `Cone` as exact F-Rep solids), appearance (`FAppearance`,
//! `FMaterial`, `FColorMap`, `FTexture3D`, VRML's `Appearance` and `Material`) and physics
//! (`FPhysics`, `FSurface`, `FTension`, `FFriction`, `FDepth`, `FDensity`, `FForce`).

use std::sync::Arc;

use glam::DVec3;

use super::document::{Field, Node, Pos, Value};
use super::read::{Fields, Reader};
use super::writer::format_number;
use fdsl::Function;
use model::mesh::TriMesh;
use model::object::{
    Appearance, ColorDef, ColorMap, Domain, ForceField, Formula, Geometry, ObjectData,
    ParametricKind, Physics, Property, Rgb, Shape, Slot, Transform,
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

impl<'d> Reader<'_, 'd> {
    /// An object from an `FShape` or `Shape` (what could not be read is reported and left
    /// out), the `FEdit` nodes of an `FShape`'s `edits`, in order (the loader applies them to
    /// the object), and the `FGrid` nodes of its `grids` (the loader reads their files).
    pub(super) fn object(&mut self, node: &'d Node) -> (ObjectData, Vec<&'d Node>, Vec<&'d Node>) {
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
        if let Some(field) = fields.get("geometry")
            && let Some(g) = self.node_of(field, GEOMETRY_TYPES)
        {
            data.geometry = self.geometry(g, Slot::Geometry);
        }
        if let Some(field) = fields.get("appearance")
            && let Some(a) = self.node_of(field, &["FAppearance", "Appearance"])
        {
            data.appearance = self.appearance(a).into();
        }
        if function_shape
            && let Some(field) = fields.get("physics")
            && let Some(p) = self.node_of(field, &["FPhysics"])
        {
            data.physics = self.physics(p).into();
        }
        let mut edits = Vec::new();
        if function_shape && let Some(field) = fields.get("edits") {
            edits = self.edit_nodes(field);
        }
        let mut grids = Vec::new();
        if function_shape && let Some(field) = fields.get("grids") {
            self.positions.insert(Slot::Grids, field.value_pos);
            grids = self.grid_nodes(field);
        }
        self.finish(fields);
        (data, edits, grids)
    }

    /// The `name` field (our extension), else the `DEF` name, else empty.
    pub(super) fn name(&mut self, fields: &mut Fields<'d>) -> String {
        if let Some(field) = fields.get("name")
            && let Some(v) = self.strings(field)
        {
            if let [name] = v.as_slice() {
                return (*name).to_string();
            }
            self.error(field.value_pos, "the field `name` should be one string");
        }
        fields.node.def.clone().unwrap_or_default()
    }

    /// A geometry node, for `slot` (the geometry or the haptic container).
    pub(super) fn geometry(&mut self, node: &'d Node, slot: Slot) -> Option<Geometry> {
        let mut fields = Fields::new(node);
        let read = match node.type_name.as_str() {
            "FGeometry" => self.function_geometry(&mut fields, slot),
            "IndexedFaceSet" => self.mesh(&mut fields).map(|mesh| Geometry {
                shape: Shape::Mesh(Arc::new(mesh)),
                domain: None,
                transform: Transform::IDENTITY,
            }),
            _ => self.primitive(&mut fields),
        };
        // Errors in a shape without a formula of its own point at the node.
        self.positions.entry(slot).or_insert(node.pos);
        self.finish(fields);
        read
    }

    fn function_geometry(&mut self, fields: &mut Fields<'d>, slot: Slot) -> Option<Geometry> {
        if let Some(field) = fields.get("mesh") {
            return self.placed_mesh(fields, field);
        }
        let Some(field) = fields.get("definition") else {
            self.error(
                fields.node.pos,
                "`FGeometry` needs a `definition` (or a `mesh`)",
            );
            return None;
        };
        let formula = self.formula_for(field, slot)?;
        let domain = self.domain(fields);
        let transform = self.transform(fields);
        let shape = self.function_shape(fields, formula)?;
        Some(Geometry {
            shape,
            domain,
            transform,
        })
    }

    /// Our extension: `FGeometry { mesh IndexedFaceSet { ... } }`, a mesh placed in its own
    /// domain and frame.
    fn placed_mesh(&mut self, fields: &mut Fields<'d>, field: &'d Field) -> Option<Geometry> {
        let mesh = self.node_of(field, &["IndexedFaceSet"]).and_then(|node| {
            let mut mesh_fields = Fields::new(node);
            let mesh = self.mesh(&mut mesh_fields);
            self.finish(mesh_fields);
            mesh
        });
        if let Some(d) = fields.get("definition") {
            self.warning(d.pos, "`definition` is ignored next to `mesh`");
        }
        let domain = self.domain(fields);
        let transform = self.transform(fields);
        mesh.map(|mesh| Geometry {
            shape: Shape::Mesh(Arc::new(mesh)),
            domain,
            transform,
        })
    }

    /// Implicit or parametric: `kind` says, else the number of `parameters` ranges, else
    /// the definition's outputs.
    fn function_shape(&mut self, fields: &mut Fields<'d>, formula: Formula) -> Option<Shape> {
        let kind = fields.get("kind");
        let parameters = fields.get("parameters");
        if kind.is_none() && parameters.is_none() {
            return Some(match parametric_by_outputs(&formula) {
                Some(kind) => Shape::Parametric {
                    formula,
                    kind,
                    parameters: [DEFAULT_RANGE; 3],
                },
                None => Shape::Implicit(formula),
            });
        }
        if kind.is_some_and(|f| matches!(&f.value, Value::String(s) if s == "implicit")) {
            if let Some(p) = parameters {
                self.warning(p.pos, "`parameters` are ignored for `kind \"implicit\"`");
            }
            return Some(Shape::Implicit(formula));
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
            return None;
        };
        Some(Shape::Parametric {
            formula,
            kind,
            parameters: ranges.map_or([DEFAULT_RANGE; 3], |(r, _)| r),
        })
    }

    /// VRML's `IndexedFaceSet`: `coord Coordinate { point [...] }` and `coordIndex` polygons
    /// ended by `-1`, fanned into triangles (turned over with `ccw FALSE`).
    fn mesh(&mut self, fields: &mut Fields<'d>) -> Option<TriMesh> {
        let node = fields.node;
        let mut points: &[f64] = &[];
        if let Some(field) = fields.get("coord")
            && let Some(coord) = self.node_of(field, &["Coordinate"])
        {
            let mut coord_fields = Fields::new(coord);
            if let Some(f) = coord_fields.get("point") {
                points = self.numbers_of(f).unwrap_or(&[]);
                if !points.len().is_multiple_of(3) {
                    self.error(f.value_pos, "`point` should hold three numbers per point");
                    points = &[];
                }
            }
            self.finish(coord_fields);
        }
        let n_points = points.len() / 3;
        let index_field = fields.get("coordIndex");
        let indices = index_field.and_then(|f| self.numbers_of(f)).unwrap_or(&[]);
        let ccw = fields
            .get("ccw")
            .and_then(|f| self.boolean(f))
            .unwrap_or(true);
        // Hints for renderers; a solid is read as it is.
        for hint in ["solid", "convex", "creaseAngle"] {
            fields.get(hint);
        }
        for name in [
            "normal",
            "normalIndex",
            "normalPerVertex",
            "color",
            "colorIndex",
            "colorPerVertex",
            "texCoord",
            "texCoordIndex",
        ] {
            if let Some(f) = fields.get(name) {
                self.warning(f.pos, format!("`{name}` is ignored (meshes carry no colours, normals or texture coordinates)"));
            }
        }
        let pos = index_field.map_or(node.pos, |f| f.value_pos);
        let triangles = self.triangles(indices, n_points, ccw, pos)?;
        let positions = points
            .chunks_exact(3)
            .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
            .collect();
        match TriMesh::new(positions, triangles) {
            Ok(mesh) => Some(mesh),
            Err(e) => {
                self.error(node.pos, e.to_string());
                None
            }
        }
    }

    fn triangles(
        &mut self,
        indices: &[f64],
        n_points: usize,
        ccw: bool,
        pos: Pos,
    ) -> Option<Vec<[u32; 3]>> {
        let mut triangles = Vec::new();
        let mut polygon: Vec<u32> = Vec::new();
        let mut n_degenerate = 0usize;
        for (k, &i) in indices.iter().chain(std::iter::once(&-1.0)).enumerate() {
            if i == -1.0 {
                if polygon.len() < 3 && !(polygon.is_empty() && k == indices.len()) {
                    n_degenerate += 1;
                }
                for w in 1..polygon.len().saturating_sub(1) {
                    let (a, b, c) = (polygon[0], polygon[w], polygon[w + 1]);
                    triangles.push(if ccw { [a, b, c] } else { [a, c, b] });
                }
                polygon.clear();
                continue;
            }
            let in_range = i.fract() == 0.0 && i >= 0.0 && i < n_points as f64;
            if !in_range {
                self.error(
                    pos,
                    format!("`coordIndex` holds {i}, not a point index (0 to {n_points}) or -1"),
                );
                return None;
            }
            polygon.push(i as u32);
        }
        if n_degenerate > 0 {
            self.warning(
                pos,
                format!("{n_degenerate} polygons with fewer than three points are skipped"),
            );
        }
        Some(triangles)
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
    fn primitive(&mut self, fields: &mut Fields<'d>) -> Option<Geometry> {
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
        let primitive = match node.type_name.as_str() {
            "Box" => {
                let size = match fields.get("size") {
                    Some(f) => self.vec3(f),
                    None => Some(DVec3::splat(2.0)),
                };
                let Some(size) = size.filter(|s| s.is_finite() && s.min_element() > 0.0) else {
                    self.error(node.pos, "a `Box` needs a positive `size`");
                    return None;
                };
                Some(Primitive::Box(size))
            }
            "Sphere" => positive(self, "radius", 1.0).map(Primitive::Sphere),
            "Cylinder" => {
                let r = positive(self, "radius", 1.0);
                let h = positive(self, "height", 2.0);
                self.closed(fields, &["side", "top", "bottom"]);
                r.zip(h).map(|(r, h)| Primitive::Cylinder(r, h))
            }
            "Cone" => {
                let r = positive(self, "bottomRadius", 1.0);
                let h = positive(self, "height", 2.0);
                self.closed(fields, &["side", "bottom"]);
                r.zip(h).map(|(r, h)| Primitive::Cone(r, h))
            }
            _ => None,
        };
        let (text, size) = primitive?.solid();
        match Formula::new(text) {
            Ok(formula) => Some(Geometry::implicit_in(
                formula,
                Domain::new(DVec3::ZERO, size),
            )),
            Err(e) => {
                self.error(node.pos, e.to_string());
                None
            }
        }
    }

    /// Warns when a part of a cylinder or cone is switched off: solids are always closed.
    fn closed(&mut self, fields: &mut Fields<'d>, parts: &[&str]) {
        for part in parts {
            if let Some(field) = fields.get(part)
                && self.boolean(field) == Some(false)
            {
                self.warning(
                    field.pos,
                    format!("`{part} FALSE` is ignored: the solid is read closed"),
                );
            }
        }
    }

    fn appearance(&mut self, node: &'d Node) -> Appearance {
        let mut fields = Fields::new(node);
        let mut appearance = Appearance::default();
        if let Some(field) = fields.get("material")
            && let Some(m) = self.node_of(field, &["FMaterial", "Material"])
        {
            if m.type_name == "FMaterial" {
                self.function_material(m, &mut appearance);
            } else {
                self.material(m, &mut appearance);
            }
        }
        if let Some(field) = fields.get("texture")
            && let Some(t) = self.node_of(field, &["FTexture3D"])
        {
            let mut texture = Fields::new(t);
            if let Some(f) = texture.get("definition") {
                appearance.displacement = self.formula_for(f, Slot::Displacement);
            }
            self.finish(texture);
        }
        if node.type_name == "FAppearance" {
            appearance.domain = self.domain(&mut fields);
            appearance.transform = self.transform(&mut fields);
        } else if let Some(field) = fields.get("textureTransform") {
            self.warning(
                field.pos,
                "`textureTransform` is ignored (image textures are not read)",
            );
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
                self.warning(
                    field.pos,
                    format!("`{map_name}` is ignored for a constant colour"),
                );
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
        if let Some(e) = constant(self, "emissiveColor", Slot::Diffuse)
            && e != [0.0; 3]
        {
            let pos = fields.get("emissiveColor").map_or(node.pos, |f| f.pos);
            self.warning(
                pos,
                "`emissiveColor` is ignored (the object model has no emission)",
            );
        }
        a.diffuse = diffuse.map(ColorDef::Constant);
        a.specular = specular.map(ColorDef::Constant);
        if let Some(field) = fields.get("ambientIntensity")
            && let Some(k) = self.number(field)
        {
            let base = diffuse.unwrap_or([0.8; 3]);
            let k = k.clamp(0.0, 1.0) as f32;
            a.ambient = Some(ColorDef::Constant(base.map(|c| c * k)));
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
        if let Some(field) = fields.get("surface")
            && let Some(s) = self.node_of(field, &["FSurface"])
        {
            let mut surface = Fields::new(s);
            self.surface(&mut surface, &mut p, false);
            self.finish(surface);
        }
        // The thesis's Figure 7.4 writes `friction` straight under `FPhysics`.
        self.surface(&mut fields, &mut p, true);
        if let Some(field) = fields.get("density")
            && let Some(d) = self.node_of(field, &["FDensity"])
        {
            p.density = self.property(d, Slot::Density);
        }
        if let Some(field) = fields.get("force")
            && let Some(f) = self.node_of(field, &["FForce"])
        {
            p.force = self.force(f);
        }
        if let Some(field) = fields.get("container")
            && let Some(g) = self.node_of(field, GEOMETRY_TYPES)
        {
            p.container = self.geometry(g, Slot::Container);
        }
        p.domain = self.domain(&mut fields);
        p.transform = self.transform(&mut fields);
        self.finish(fields);
        p
    }

    /// `tension`, `friction` and `depth` of an `FSurface`, or written straight under
    /// `FPhysics` (`under_physics`), as the thesis's Figure 7.4 does: read alike, with a warning
    /// that names where they belong (Figure 7.8's spelling and section 6.4's hierarchy).
    fn surface(&mut self, fields: &mut Fields<'d>, p: &mut Physics, under_physics: bool) {
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
            if under_physics {
                self.warning(
                    field.pos,
                    format!(
                        "`{name}` belongs in the surface: `physics FPhysics {{ surface FSurface {{ \
                         {name} {type_name} {{ ... }} }} }}`; read as if written there"
                    ),
                );
            }
            let property = self.property(node, slot);
            let target = match slot {
                Slot::Tension => &mut p.tension,
                Slot::Friction => &mut p.friction,
                _ => &mut p.zone_depth,
            };
            if target.is_some() {
                self.warning(
                    field.pos,
                    format!(
                        "`{name}` is given both in `FSurface` and in `FPhysics`; this one counts"
                    ),
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
                    format!(
                        "`{}` needs a `definition` (or `enable FALSE`)",
                        node.type_name
                    ),
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
                self.error(
                    node.pos,
                    "`FForce` needs a `definition` (or `enable FALSE`)",
                );
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

/// VRML's solid primitives, centred at the origin with their axis along y.
enum Primitive {
    /// Edge lengths.
    Box(DVec3),
    /// Radius.
    Sphere(f64),
    /// Radius and height.
    Cylinder(f64, f64),
    /// Bottom radius and height (apex up).
    Cone(f64, f64),
}

impl Primitive {
    /// The exact F-Rep (a signed distance inside, a lower bound of it outside) and the box.
    fn solid(self) -> (String, DVec3) {
        let n = format_number;
        match self {
            Primitive::Box(size) => {
                let h = size * 0.5;
                let text = format!(
                    "min({}-abs(x), {}-abs(y), {}-abs(z))",
                    n(h.x),
                    n(h.y),
                    n(h.z)
                );
                (text, size)
            }
            Primitive::Sphere(r) => (format!("{}-sqrt(x^2+y^2+z^2)", n(r)), DVec3::splat(2.0 * r)),
            Primitive::Cylinder(r, h) => (
                format!("min({}-sqrt(x^2+z^2), {}-abs(y))", n(r), n(h * 0.5)),
                DVec3::new(2.0 * r, h, 2.0 * r),
            ),
            // The slanted side's distance, positive inside: the radius at height y is
            // r/2 - (r/h) y (zero at the apex y = h/2), scaled by the side's cosine.
            Primitive::Cone(r, h) => (
                format!(
                    "min(({}-{}*y-sqrt(x^2+z^2))*{}, y+{})",
                    n(r * 0.5),
                    n(r / h),
                    n(h / r.hypot(h)),
                    n(h * 0.5)
                ),
                DVec3::new(2.0 * r, h, 2.0 * r),
            ),
        }
    }
}

/// The kind of a definition without `parameters` or `kind`: parametric when it defines `x`,
/// `y` and `z` and no single value, by the last of `u`, `v`, `w` it reads.
pub(super) fn parametric_by_outputs(formula: &Formula) -> Option<ParametricKind> {
    let function = Function::parse(formula.as_str()).ok()?;
    let parametric =
        ["x", "y", "z"].iter().all(|o| function.has_output(o)) && !function.has_output("value");
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
