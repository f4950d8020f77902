//! `FGrid`, our extension: an object's sampled grids (volume data its formulas call by name),
//! read and written.
//!
//! `FShape { grids [ FGrid { ... } ... ] }`. An `FGrid` gives a `name` and its samples, either
//! inline as `samples [b0 b1 ...]` (bytes 0 to 255, x fastest, then y, then z) with `size`, or
//! from a file: `url "scan.nrrd"` (an NRRD header gives the size, spacing and origin) or
//! `url "scan.raw"` (raw bytes, with `size`). `origin` (default 0 0 0) and `spacing` (default
//! 1 1 1) place the samples unless an NRRD header does; `range` (default 0 1) gives the values
//! bytes 0 and 255 stand for. Saving writes the samples inline, so a saved scene needs no other
//! file.

use super::document::{Field, Node, NodeRef, Pos, Value};
use super::read::{Fields, Reader};
use fdsl::grid::{Grid, MAX_GRIDS};

/// An `FGrid` as read: its fields, before its file (if any) is resolved.
pub(super) struct GridRead<'d> {
    pub name: String,
    pub pos: Pos,
    pub size: Option<[usize; 3]>,
    pub origin: Option<[f64; 3]>,
    pub spacing: Option<[f64; 3]>,
    pub range: [f64; 2],
    pub samples: Option<Vec<u8>>,
    pub urls: Vec<&'d str>,
    pub url_pos: Pos,
}

impl GridRead<'_> {
    /// The grid from inline samples or a file's bytes (`bytes`), or why not.
    pub(super) fn build(&self, bytes: Option<&[u8]>) -> Result<Grid, String> {
        let origin = self.origin.unwrap_or([0.0; 3]);
        let spacing = self.spacing.unwrap_or([1.0; 3]);
        let raw = |samples: &[u8]| {
            let Some(size) = self.size else {
                return Err("raw samples need a `size` (three counts)".to_string());
            };
            Grid::from_raw(&self.name, size, origin, spacing, self.range, samples)
                .map_err(|e| e.to_string())
        };
        match (bytes, &self.samples) {
            (Some(file), _) if file.starts_with(b"NRRD000") => {
                Grid::from_nrrd(&self.name, file, self.range).map_err(|e| e.to_string())
            }
            (Some(file), _) => raw(file),
            (None, Some(samples)) => raw(samples),
            (None, None) => Err("`FGrid` needs `samples` or a `url`".to_string()),
        }
    }
}

impl<'d> Reader<'_, 'd> {
    /// The `FGrid` nodes of a `grids` field.
    pub(super) fn grid_nodes(&mut self, field: &'d Field) -> Vec<&'d Node> {
        self.listed_nodes(field, "FGrid", MAX_GRIDS, "grids")
    }

    /// The fields of one `FGrid`; `None` (reported) when they cannot make a grid.
    pub(super) fn grid(&mut self, node: &'d Node) -> Option<GridRead<'d>> {
        let mut fields = Fields::new(node);
        let name = self.grid_name(&mut fields, node);
        let mut ok = name.is_some();
        let name = name.unwrap_or_default();
        let mut three = |fields: &mut Fields<'d>, reader: &mut Self, what: &str| {
            let field = fields.get(what)?;
            let v = reader.fixed(field, 3);
            if v.is_none() {
                ok = false;
            }
            v.map(|v| [v[0], v[1], v[2]])
        };
        let size_pos = node
            .fields
            .iter()
            .find(|f| f.name == "size")
            .map(|f| f.value_pos);
        let size = three(&mut fields, self, "size").and_then(|v| {
            if v.iter()
                .all(|s| s.fract() == 0.0 && (2.0..=65_535.0).contains(s))
            {
                Some(v.map(|s| s as usize))
            } else {
                let message = "`size` should be three whole counts from 2 to 65535";
                self.error(size_pos.unwrap_or(node.pos), message);
                None
            }
        });
        let origin = three(&mut fields, self, "origin");
        let spacing = three(&mut fields, self, "spacing");
        // A `size` given but refused is reported once, not again as a missing size.
        ok &= size_pos.is_none() || size.is_some();
        let range = match fields.get("range") {
            Some(f) => match self.fixed(f, 2) {
                Some(v) => [v[0], v[1]],
                None => return None,
            },
            None => [0.0, 1.0],
        };
        let samples = match fields.get("samples") {
            Some(f) => Some(self.grid_samples(f)?),
            None => None,
        };
        let url_field = fields.get("url");
        let urls = url_field.and_then(|f| self.strings(f)).unwrap_or_default();
        self.finish(fields);
        ok.then_some(GridRead {
            name,
            pos: node.pos,
            size,
            origin,
            spacing,
            range,
            samples,
            urls,
            url_pos: url_field.map_or(node.pos, |f| f.value_pos),
        })
    }
}

impl<'d> Reader<'_, 'd> {
    /// An `FGrid`'s `name`; `None` (reported) when it has none or it is not one string.
    fn grid_name(&mut self, fields: &mut Fields<'d>, node: &'d Node) -> Option<String> {
        match fields.get("name").map(|f| (f, self.strings(f))) {
            Some((_, Some(v))) if v.len() == 1 => Some(v[0].to_string()),
            Some((f, _)) => {
                self.error(f.value_pos, "the field `name` should be one string");
                None
            }
            None => {
                self.error(node.pos, "`FGrid` needs a `name` (what formulas call it)");
                None
            }
        }
    }

    /// An `FGrid`'s inline `samples`; `None` (reported) unless they are all bytes.
    fn grid_samples(&mut self, field: &'d Field) -> Option<Vec<u8>> {
        let v = self.numbers_of(field)?;
        if v.iter()
            .any(|b| b.fract() != 0.0 || !(0.0..=255.0).contains(b))
        {
            self.error(
                field.value_pos,
                "`samples` should be whole numbers from 0 to 255",
            );
            return None;
        }
        Some(v.iter().map(|&b| b as u8).collect())
    }
}

/// An object's grids as an `FShape` field, samples inline.
pub(super) fn write_grids(grids: &[std::sync::Arc<Grid>], out: &mut Vec<Field>) {
    if grids.is_empty() {
        return;
    }
    let numbers = |v: &[f64]| Value::Numbers(v.to_vec());
    let nodes = grids
        .iter()
        .map(|g| {
            let d = g.data();
            let mut fields = vec![
                Field::new("name", Value::String(d.name.clone())),
                Field::new("size", numbers(&d.size.map(f64::from))),
            ];
            // Defaults are left out only when equal bit for bit (a -0 is written).
            let is = |v: &[f64], default: f64| v.iter().all(|x| x.to_bits() == default.to_bits());
            if !is(&d.origin, 0.0) {
                fields.push(Field::new("origin", numbers(&d.origin)));
            }
            if !is(&d.spacing, 1.0) {
                fields.push(Field::new("spacing", numbers(&d.spacing)));
            }
            if !(d.range[0].to_bits() == 0.0f64.to_bits()
                && d.range[1].to_bits() == 1.0f64.to_bits())
            {
                fields.push(Field::new("range", numbers(&d.range)));
            }
            let samples = d.samples.iter().map(|&b| f64::from(b)).collect();
            fields.push(Field::new("samples", Value::NumberList(samples)));
            NodeRef::Node(Box::new(Node::new("FGrid", fields)))
        })
        .collect();
    out.push(Field::new("grids", Value::NodeList(nodes)));
}
