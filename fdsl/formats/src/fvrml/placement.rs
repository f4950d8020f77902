//! Fields that place things, read and written: VRML's transform fields (and our exact
//! `matrix`), domains (`bboxCenter`, `bboxSize`), time mappings (`cycleInterval`,
//! `timeSpan`) and motions (`translationFunction`, `rotationAxis`, `angleFunction`).

use glam::{DAffine3, DMat3, DQuat, DVec3};

use super::document::{Field, Value};
use super::read::{Fields, Reader};
use model::object::{Domain, Motion, Slot, Timing, Transform};

/// The fields [`Reader::motion`] reads.
pub(super) const MOTION_FIELDS: [&str; 5] = [
    "translationFunction",
    "rotationAxis",
    "angleFunction",
    "cycleInterval",
    "timeSpan",
];

impl<'d> Reader<'_, 'd> {
    /// The transform of VRML's fields, `T * C * R * SR * S * -SR * -C`, or our `matrix`
    /// (three rows of four numbers: the linear part and the translation), which replaces them.
    pub(super) fn transform(&mut self, fields: &mut Fields<'d>) -> Transform {
        let translation = fields.get("translation").and_then(|f| self.vec3(f));
        let rotation = fields.get("rotation").and_then(|f| self.rotation(f));
        let scale = fields.get("scale").and_then(|f| self.vec3(f));
        let orientation = fields
            .get("scaleOrientation")
            .and_then(|f| self.rotation(f));
        let center = fields.get("center").and_then(|f| self.vec3(f));
        if let Some(field) = fields.get("matrix") {
            let Some(m) = self.fixed(field, 12) else {
                return Transform::IDENTITY;
            };
            if translation.is_some() || rotation.is_some() || scale.is_some() || center.is_some() {
                self.warning(
                    field.pos,
                    "`matrix` replaces `translation`, `rotation`, `scale` and `center`, which are ignored",
                );
            }
            return Transform {
                parent_from_child: DAffine3 {
                    matrix3: DMat3::from_cols_array(&[
                        m[0], m[4], m[8], m[1], m[5], m[9], m[2], m[6], m[10],
                    ]),
                    translation: DVec3::new(m[3], m[7], m[11]),
                },
            };
        }
        let t = translation.unwrap_or(DVec3::ZERO);
        let s = scale.unwrap_or(DVec3::ONE);
        if rotation.is_none() && center.is_none() && orientation.is_none() {
            // Exact: no products, so what `write_transform` writes reads back bit-identical.
            return Transform {
                parent_from_child: DAffine3 {
                    matrix3: DMat3::from_diagonal(s),
                    translation: t,
                },
            };
        }
        let c = center.unwrap_or(DVec3::ZERO);
        let r = rotation.unwrap_or(DQuat::IDENTITY);
        let sr = orientation.unwrap_or(DQuat::IDENTITY);
        let m = DAffine3::from_translation(t + c)
            * DAffine3::from_quat(r)
            * DAffine3::from_quat(sr)
            * DAffine3::from_scale(s)
            * DAffine3::from_quat(sr.inverse())
            * DAffine3::from_translation(-c);
        Transform {
            parent_from_child: m,
        }
    }

    /// An `SFRotation`: axis and angle in radians.
    fn rotation(&mut self, field: &'d Field) -> Option<DQuat> {
        let v = self.fixed(field, 4)?;
        let axis = DVec3::new(v[0], v[1], v[2]);
        if axis.length() <= 1e-12 {
            if v[3] != 0.0 {
                self.warning(
                    field.value_pos,
                    "a rotation about a zero axis is no rotation",
                );
            }
            return Some(DQuat::IDENTITY);
        }
        Some(DQuat::from_axis_angle(axis.normalize(), v[3]))
    }

    /// `bboxCenter` and `bboxSize` as a domain; `bboxSize -1 -1 -1` (VRML's default) is none.
    pub(super) fn domain(&mut self, fields: &mut Fields<'d>) -> Option<Domain> {
        let center = fields.get("bboxCenter");
        let size = fields.get("bboxSize");
        let center_value = center.and_then(|f| self.vec3(f));
        let Some(size_field) = size else {
            if let Some(c) = center {
                self.warning(c.pos, "`bboxCenter` without `bboxSize` is ignored");
            }
            return None;
        };
        let size = self.vec3(size_field)?;
        if size == DVec3::splat(-1.0) {
            return None;
        }
        Some(Domain::new(center_value.unwrap_or(DVec3::ZERO), size))
    }

    /// `cycleInterval` (seconds, default 0: no cycling) and `timeSpan` (start and end).
    pub(super) fn timing(&mut self, fields: &mut Fields<'d>) -> Timing {
        let cycle_interval_secs = fields
            .get("cycleInterval")
            .and_then(|f| self.number(f))
            .unwrap_or(0.0);
        let time_span = fields
            .get("timeSpan")
            .and_then(|f| self.fixed(f, 2))
            .map(|v| [v[0], v[1]]);
        Timing {
            cycle_interval_secs,
            time_span,
        }
    }

    /// The motion fields of an `FTransform` (or of an `FShape`, as `save` writes them):
    /// `translationFunction` (outputs `x`, `y`, `z` of `t`), `rotationAxis` (default `0 0 1`),
    /// `angleFunction` (radians, of `t`), `cycleInterval` and `timeSpan`. `None` when none is
    /// given.
    pub(super) fn motion(&mut self, fields: &mut Fields<'d>) -> Option<Motion> {
        if !MOTION_FIELDS.iter().any(|name| fields.has(name)) {
            return None;
        }
        let translation = fields
            .get("translationFunction")
            .and_then(|f| self.formula_for(f, Slot::Motion));
        let axis = fields
            .get("rotationAxis")
            .and_then(|f| self.vec3(f))
            .unwrap_or(DVec3::Z);
        let angle = fields
            .get("angleFunction")
            .and_then(|f| self.formula_for(f, Slot::Motion));
        let timing = self.timing(fields);
        Some(Motion {
            translation,
            axis,
            angle,
            timing,
        })
    }
}

/// Writes a transform so that [`Reader::transform`] reads back the same matrix: a
/// translation, plus a scale for a diagonal linear part, else the exact `matrix`.
pub(super) fn write_transform(t: &Transform, out: &mut Vec<Field>) {
    let m = t.parent_from_child;
    let a = m.matrix3.to_cols_array();
    let diagonal = [a[1], a[2], a[3], a[5], a[6], a[7]]
        .iter()
        .all(|v| *v == 0.0);
    if diagonal {
        if m.translation != DVec3::ZERO {
            out.push(numbers("translation", &m.translation.to_array()));
        }
        if m.matrix3.diagonal() != DVec3::ONE {
            out.push(numbers("scale", &m.matrix3.diagonal().to_array()));
        }
        return;
    }
    let (c, p) = (a, m.translation);
    let rows = [
        c[0], c[3], c[6], p.x, c[1], c[4], c[7], p.y, c[2], c[5], c[8], p.z,
    ];
    out.push(Field::new("matrix", Value::NumberList(rows.to_vec())));
}

/// Writes a domain as `bboxCenter` and `bboxSize`.
pub(super) fn write_domain(d: &Domain, out: &mut Vec<Field>) {
    out.push(numbers("bboxCenter", &d.center.to_array()));
    out.push(numbers("bboxSize", &d.size.to_array()));
}

/// Writes a time mapping (nothing for the default).
pub(super) fn write_timing(t: &Timing, out: &mut Vec<Field>) {
    if t.cycle_interval_secs != 0.0 {
        out.push(numbers("cycleInterval", &[t.cycle_interval_secs]));
    }
    if let Some(span) = t.time_span {
        out.push(numbers("timeSpan", &span));
    }
}

/// Writes a motion's fields (`rotationAxis` always, so that a motion is never empty).
pub(super) fn write_motion(m: &Motion, out: &mut Vec<Field>) {
    if let Some(f) = &m.translation {
        out.push(Field::new(
            "translationFunction",
            Value::String(f.as_str().to_string()),
        ));
    }
    out.push(numbers("rotationAxis", &m.axis.to_array()));
    if let Some(f) = &m.angle {
        out.push(Field::new(
            "angleFunction",
            Value::String(f.as_str().to_string()),
        ));
    }
    write_timing(&m.timing, out);
}

/// A field holding a run of numbers.
pub(super) fn numbers(name: &str, v: &[f64]) -> Field {
    Field::new(name, Value::Numbers(v.to_vec()))
}
