//! An object's physics: the haptic container and the functions felt through it (surface
//! tension, friction, surface-zone depth, interior density, force field), each with an enable
//! flag.

use serde::{Deserialize, Serialize};

use super::geometry::Geometry;
use super::space::{Domain, Timing, Transform};
use super::{Formula, ObjectError, Slot};

/// A scalar property: a formula of `x, y, z, t` and whether it is felt.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Property {
    /// The value as a function of the point and time.
    pub formula: Formula,
    /// Disabled properties are kept but not felt (the thesis's `enable FALSE`).
    pub enabled: bool,
}

impl Property {
    /// An enabled property.
    pub fn new(formula: Formula) -> Property {
        Property {
            formula,
            enabled: true,
        }
    }
}

/// A force field: three functions of `u, v, w, t` (outputs `x`, `y`, `z`) over the container's
/// normalised domain: the container's box maps onto the parameter ranges. Values are device
/// independent: the haptic crate reads them as fractions of the device's largest force.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ForceField {
    /// Outputs `x`, `y`, `z` of `u, v, w, t`.
    pub formula: Formula,
    /// `[lo, hi]` of `u`, `v`, `w`.
    pub parameters: [[f64; 2]; 3],
    /// Scene time to the field's `t`.
    pub timing: Timing,
    /// Whether the field is felt.
    pub enabled: bool,
}

/// Physics: a container and its properties.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Physics {
    /// The haptic container; `None` uses the object's geometry. It may be invisible.
    pub container: Option<Geometry>,
    /// Resistance to pushing into the surface within the surface zone, as a fraction of the
    /// device's largest force (how the haptic crate reads it).
    pub tension: Option<Property>,
    /// Friction coefficient against motion along the surface.
    pub friction: Option<Property>,
    /// Depth of the surface zone (scene units); constant or varying.
    pub zone_depth: Option<Property>,
    /// Interior density: viscosity felt inside.
    pub density: Option<Property>,
    /// A force field inside the container.
    pub force: Option<ForceField>,
    /// Where the property functions are defined (informative).
    pub domain: Option<Domain>,
    /// Physics space to object space (the properties' coordinates).
    pub transform: Transform,
}

impl Physics {
    pub(crate) fn validate(&self) -> Result<(), ObjectError> {
        if let Some(c) = &self.container {
            c.validate(Slot::Container)?;
        }
        if let Some(f) = &self.force {
            f.timing.validate(Slot::Force)?;
            let ok = f
                .parameters
                .iter()
                .all(|[a, b]| a.is_finite() && b.is_finite() && a <= b);
            if !ok {
                return Err(ObjectError::BadParameters { slot: Slot::Force });
            }
        }
        if let Some(d) = &self.domain {
            d.validate(Slot::PhysicsSpace)?;
        }
        self.transform.validate(Slot::PhysicsSpace)
    }
}
