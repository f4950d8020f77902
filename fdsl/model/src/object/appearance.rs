//! An object's appearance: colours as parametric RGB or a scalar through a colour map,
//! transparency, shininess and a geometric texture, in the appearance's own domain.

use serde::{Deserialize, Serialize};

use super::space::{Domain, Transform};
use super::{Formula, ObjectError, Slot};
use crate::limits::MAX_COLOR_KEYS;

/// A linear RGB colour, components in `[0, 1]`.
pub type Rgb = [f32; 3];

/// A colour map: key values and their colours; values between keys interpolate linearly,
/// values outside take the nearest end.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColorMap {
    /// `(value, colour)` pairs with strictly increasing values.
    pub keys: Vec<(f64, Rgb)>,
}

impl ColorMap {
    /// The colour at `g`.
    pub fn color(&self, g: f64) -> Rgb {
        let keys = &self.keys;
        let Some(first) = keys.first() else {
            return [0.0; 3];
        };
        if g.is_nan() || g <= first.0 {
            return first.1;
        }
        let i = keys.partition_point(|(k, _)| *k <= g);
        if i >= keys.len() {
            return keys[keys.len() - 1].1;
        }
        let ((g0, c0), (g1, c1)) = (keys[i - 1], keys[i]);
        let s = ((g - g0) / (g1 - g0)) as f32;
        [0, 1, 2].map(|k| c0[k] + (c1[k] - c0[k]) * s)
    }

    fn validate(&self, slot: Slot) -> Result<(), ObjectError> {
        if self.keys.is_empty() || self.keys.len() > MAX_COLOR_KEYS {
            return Err(ObjectError::BadColorMap {
                slot,
                reason: "needs 1 to MAX_COLOR_KEYS keys",
            });
        }
        let increasing = self.keys.windows(2).all(|w| w[0].0 < w[1].0);
        let finite = self.keys.iter().all(|(g, c)| {
            g.is_finite() && c.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v))
        });
        if !(increasing && finite) {
            return Err(ObjectError::BadColorMap {
                slot,
                reason: "key values must be finite and strictly increasing, colours in [0, 1]",
            });
        }
        Ok(())
    }
}

/// How a colour is defined.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ColorDef {
    /// One colour everywhere.
    Constant(Rgb),
    /// A formula with outputs `r`, `g`, `b` (clamped to `[0, 1]`).
    Rgb(Formula),
    /// A scalar formula through a colour map.
    Map {
        /// The scalar field.
        formula: Formula,
        /// Its colours.
        map: ColorMap,
    },
}

impl ColorDef {
    pub(crate) fn validate(&self, slot: Slot) -> Result<(), ObjectError> {
        match self {
            ColorDef::Constant(c) if !c.iter().all(|v| (0.0..=1.0).contains(v)) => {
                Err(ObjectError::BadColorMap {
                    slot,
                    reason: "colour components must lie in [0, 1]",
                })
            }
            ColorDef::Map { map, .. } => map.validate(slot),
            _ => Ok(()),
        }
    }
}

/// Appearance: every field optional; a missing diffuse colour renders a neutral grey.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Appearance {
    /// Diffuse colour.
    pub diffuse: Option<ColorDef>,
    /// Ambient colour.
    pub ambient: Option<ColorDef>,
    /// Specular colour.
    pub specular: Option<ColorDef>,
    /// Transparency in `[0, 1]` (0 opaque), a scalar formula.
    pub transparency: Option<Formula>,
    /// Shininess in `[0, 1]`, a scalar formula.
    pub shininess: Option<Formula>,
    /// Geometric texture: displacement along the outward normal, a scalar formula.
    pub displacement: Option<Formula>,
    /// Where the appearance functions are defined (informative: colours are evaluated
    /// everywhere).
    pub domain: Option<Domain>,
    /// Appearance space to object space.
    pub transform: Transform,
}

impl Appearance {
    pub(crate) fn validate(&self) -> Result<(), ObjectError> {
        for (slot, def) in [
            (Slot::Diffuse, &self.diffuse),
            (Slot::Ambient, &self.ambient),
            (Slot::Specular, &self.specular),
        ] {
            if let Some(def) = def {
                def.validate(slot)?;
            }
        }
        if let Some(d) = &self.domain {
            d.validate(Slot::AppearanceSpace)?;
        }
        self.transform.validate(Slot::AppearanceSpace)
    }
}
