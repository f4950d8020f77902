//! Physical properties of a haptic container given as fdsl functions or constants (thesis
//! 4.3, 6.4): surface tension, friction, surface-zone depth and density as explicit functions
//! of `x, y, z, t`, and a force field as a parametric vector function of `u, v, w, t` in the
//! container's normalised domain. Each may be left out (disabled).
//!
//! Evaluators are built once in [`Properties::new`]; evaluating allocates nothing, so the
//! servo thread may call it.

use glam::DVec3;

use fdsl::eval::PointEval;
use fdsl::{Function, MissingOutput};

use super::FieldDomain;
use crate::aabb::Aabb;

/// The output names of a force field: `function parametric_x/_y/_z(u, v, w)` or the statement
/// list `x = ...; y = ...; z = ...;`.
pub const FIELD_OUTPUTS: [&str; 3] = ["x", "y", "z"];

/// A scalar property: the same everywhere, or an explicit function of `x, y, z, t`.
#[derive(Clone, Debug)]
pub enum Scalar {
    /// A constant value.
    Constant(f64),
    /// A function of world `x, y, z` and time `t`; its main value is used.
    Function(Function),
}

/// A force field: three functions of `u, v, w, t` over the container's box mapped to `uvw`.
#[derive(Clone, Debug)]
pub struct FieldSpec {
    /// Defines the outputs `x`, `y`, `z` (see [`FIELD_OUTPUTS`]).
    pub function: Function,
    /// The parameter ranges the container's box maps to (the thesis's `parameters`, e.g.
    /// `[-1 1 0 1 -1 1]`).
    pub uvw: Aabb,
    /// The field repeats with this period, seconds; 0 means it never repeats.
    pub cycle_interval_secs: f64,
    /// Within each cycle the field acts for this long, seconds; infinite means always.
    pub time_span_secs: f64,
}

impl FieldSpec {
    /// A field that always acts, over `uvw`.
    pub fn always(function: Function, uvw: Aabb) -> Self {
        Self {
            function,
            uvw,
            cycle_interval_secs: 0.0,
            time_span_secs: f64::INFINITY,
        }
    }
}

/// What a container feels like; `None` disables a property.
#[derive(Clone, Debug, Default)]
pub struct PropertySpec {
    /// Surface tension in `[0, 1]`, a fraction of the device's maximum stiffness.
    pub tension: Option<Scalar>,
    /// Surface friction coefficient in `[0, 1]`.
    pub friction: Option<Scalar>,
    /// Interior density in `[0, 1]`, a fraction of the device's maximum damping.
    pub density: Option<Scalar>,
    /// Depth of the surface zone, world units; `None` leaves it to the device
    /// ([`crate::force::Rig::zone_depth_world`]).
    pub zone_depth: Option<Scalar>,
    /// The force field.
    pub field: Option<FieldSpec>,
}

/// Why properties could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PropertyError {
    /// A constant is not finite.
    #[error("the constant {name} is not finite: {value}")]
    NotFinite {
        /// Which property.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// The force field does not define `x`, `y` and `z`.
    #[error("the force field must define parametric x, y and z: {0}")]
    FieldOutputs(#[from] MissingOutput),
    /// The field's parameter ranges are not finite.
    #[error("the force field's parameter ranges are not finite")]
    FieldRanges,
    /// The cycle interval is negative or not finite, or the time span is negative or NaN.
    #[error("bad force field timing: cycle {cycle_interval_secs} s, span {time_span_secs} s")]
    FieldTiming {
        /// The cycle interval given.
        cycle_interval_secs: f64,
        /// The time span given.
        time_span_secs: f64,
    },
}

/// A compiled scalar property.
#[derive(Clone, Debug)]
enum ScalarEval {
    Constant(f64),
    Function(PointEval),
}

impl ScalarEval {
    fn new(name: &'static str, scalar: &Scalar) -> Result<Self, PropertyError> {
        match scalar {
            Scalar::Constant(value) if !value.is_finite() => Err(PropertyError::NotFinite {
                name,
                value: *value,
            }),
            Scalar::Constant(value) => Ok(Self::Constant(*value)),
            Scalar::Function(function) => Ok(Self::Function(PointEval::new(&function.tape()))),
        }
    }

    fn at(&mut self, p: DVec3, t_secs: f64) -> f64 {
        match self {
            Self::Constant(value) => *value,
            Self::Function(eval) => eval.eval([p.x, p.y, p.z, t_secs]),
        }
    }
}

#[derive(Clone, Debug)]
struct FieldEval {
    eval: PointEval,
    domain: FieldDomain,
    out: [f64; 3],
}

/// Compiled properties, ready for the servo thread.
#[derive(Clone, Debug)]
pub struct Properties {
    tension: Option<ScalarEval>,
    friction: Option<ScalarEval>,
    density: Option<ScalarEval>,
    zone_depth: Option<ScalarEval>,
    field: Option<FieldEval>,
}

impl Properties {
    /// Compiles `spec` for a container whose box is `box_world` (the force field's domain).
    pub fn new(spec: &PropertySpec, box_world: Aabb) -> Result<Self, PropertyError> {
        let scalar =
            |name, s: &Option<Scalar>| s.as_ref().map(|s| ScalarEval::new(name, s)).transpose();
        let field = match &spec.field {
            Some(field) => Some(Self::field(field, box_world)?),
            None => None,
        };
        Ok(Self {
            tension: scalar("tension", &spec.tension)?,
            friction: scalar("friction", &spec.friction)?,
            density: scalar("density", &spec.density)?,
            zone_depth: scalar("zone depth", &spec.zone_depth)?,
            field,
        })
    }

    fn field(field: &FieldSpec, box_world: Aabb) -> Result<FieldEval, PropertyError> {
        let tape = field.function.tape_for(&FIELD_OUTPUTS)?;
        if !(field.uvw.min.is_finite() && field.uvw.max.is_finite()) {
            return Err(PropertyError::FieldRanges);
        }
        let (cycle, span) = (field.cycle_interval_secs, field.time_span_secs);
        if !(cycle.is_finite() && cycle >= 0.0 && span >= 0.0) {
            return Err(PropertyError::FieldTiming {
                cycle_interval_secs: cycle,
                time_span_secs: span,
            });
        }
        Ok(FieldEval {
            eval: PointEval::new(&tape),
            domain: FieldDomain {
                box_world,
                uvw: field.uvw,
                cycle_interval_secs: cycle,
                time_span_secs: span,
            },
            out: [0.0; 3],
        })
    }

    /// Surface tension at `p`, or `None` when disabled.
    pub fn tension(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.tension.as_mut().map(|e| e.at(p, t_secs))
    }

    /// Friction at `p`, or `None` when disabled.
    pub fn friction(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.friction.as_mut().map(|e| e.at(p, t_secs))
    }

    /// Density at `p`, or `None` when disabled.
    pub fn density(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        self.density.as_mut().map(|e| e.at(p, t_secs))
    }

    /// Surface-zone depth at `p`, world units (`None` when not given; a negative or
    /// non-finite value from a function counts as 0).
    pub fn zone_depth(&mut self, p: DVec3, t_secs: f64) -> Option<f64> {
        let depth = self.zone_depth.as_mut()?.at(p, t_secs);
        Some(if depth.is_finite() {
            depth.max(0.0)
        } else {
            0.0
        })
    }

    /// The force field's domain, `None` without a field.
    pub fn field_domain(&self) -> Option<FieldDomain> {
        self.field.as_ref().map(|f| f.domain)
    }

    /// The force field at `uvw` and field time `t_local_secs` (zero without a field).
    pub fn force_field(&mut self, uvw: DVec3, t_local_secs: f64) -> DVec3 {
        match &mut self.field {
            Some(field) => {
                field
                    .eval
                    .eval_all([uvw.x, uvw.y, uvw.z, t_local_secs], &mut field.out);
                DVec3::from_array(field.out)
            }
            None => DVec3::ZERO,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Function {
        Function::parse(s).unwrap()
    }

    #[test]
    fn constants_functions_and_disabled_properties() {
        let spec = PropertySpec {
            tension: Some(Scalar::Constant(0.7)),
            density: Some(Scalar::Function(parse("0.5 + 0.1*x + t"))),
            zone_depth: Some(Scalar::Function(parse("0.1 - 0.2*y"))),
            ..PropertySpec::default()
        };
        let unit = Aabb::new(DVec3::ZERO, DVec3::ONE);
        let mut props = Properties::new(&spec, unit).unwrap();
        let p = DVec3::new(1.0, 1.0, 0.0);
        assert_eq!(props.tension(p, 0.0), Some(0.7));
        assert_eq!(props.friction(p, 0.0), None);
        assert!((props.density(p, 0.25).unwrap() - 0.85).abs() < 1e-12);
        // A negative depth from a function is no zone at all.
        assert_eq!(props.zone_depth(p, 0.0), Some(0.0));
        assert!((props.zone_depth(DVec3::ZERO, 0.0).unwrap() - 0.1).abs() < 1e-12);
        assert_eq!(props.field_domain(), None);
        assert_eq!(props.force_field(p, 0.0), DVec3::ZERO);
    }

    #[test]
    fn field_is_evaluated_in_uvw_with_its_timing() {
        let spec = PropertySpec {
            field: Some(FieldSpec {
                function: parse("x = u; y = v*t; z = -w;"),
                uvw: Aabb::new(DVec3::splat(-1.0), DVec3::ONE),
                cycle_interval_secs: 2.0,
                time_span_secs: 0.5,
            }),
            ..PropertySpec::default()
        };
        let box_world = Aabb::new(DVec3::ZERO, DVec3::splat(4.0));
        let mut props = Properties::new(&spec, box_world).unwrap();
        let domain = props.field_domain().unwrap();
        let uvw = domain.uvw_from_world(DVec3::new(3.0, 4.0, 0.0));
        assert_eq!(uvw, DVec3::new(0.5, 1.0, -1.0));
        assert_eq!(domain.local_time(4.25), Some(0.25));
        assert_eq!(domain.local_time(4.75), None);
        assert_eq!(props.force_field(uvw, 0.25), DVec3::new(0.5, 0.25, 1.0));
    }

    #[test]
    fn bad_specs_are_errors() {
        let unit = Aabb::new(DVec3::ZERO, DVec3::ONE);
        let nan = PropertySpec {
            friction: Some(Scalar::Constant(f64::NAN)),
            ..PropertySpec::default()
        };
        assert!(matches!(
            Properties::new(&nan, unit),
            Err(PropertyError::NotFinite {
                name: "friction",
                ..
            })
        ));
        let mut field = FieldSpec::always(parse("x = u; y = v;"), unit);
        let no_z = PropertySpec {
            field: Some(field.clone()),
            ..PropertySpec::default()
        };
        let err = Properties::new(&no_z, unit).unwrap_err();
        assert!(err.to_string().contains("no output `z`"), "{err}");
        field.function = parse("x = u; y = v; z = w;");
        field.cycle_interval_secs = -1.0;
        let timing = PropertySpec {
            field: Some(field),
            ..PropertySpec::default()
        };
        assert!(matches!(
            Properties::new(&timing, unit),
            Err(PropertyError::FieldTiming { .. })
        ));
    }
}
