//! Closed-form containers (spheres, the watermelon, the whirlpool cylinder) for tests,
//! benchmarks and demos, before fdsl objects implement [`Container`].
//!
//! Each solid uses a distance-like function (`f >= 0` inside) so the metric depth
//! `f / |grad f|` is close to the true distance to the surface.

use glam::DVec3;

use crate::container::{Aabb, Container, FieldDomain};

/// A closed-form solid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Solid {
    /// `radius - |p - center|`.
    Sphere {
        /// Centre, world units.
        center: DVec3,
        /// Radius, world units.
        radius: f64,
    },
    /// A sphere minus the wedge `x > center.x && z > center.z` (a quarter cut out).
    Watermelon {
        /// Centre, world units.
        center: DVec3,
        /// Radius, world units.
        radius: f64,
    },
    /// The vertical cylinder `radius - sqrt(x^2+z^2) & y - y_min & y_max - y`.
    Cylinder {
        /// Radius about the y axis.
        radius: f64,
        /// Bottom plane.
        y_min: f64,
        /// Top plane.
        y_max: f64,
    },
}

/// Gradient of `r - |d|` at offset `d` (zero at the centre, where it is undefined).
fn sphere_grad(d: DVec3) -> DVec3 {
    -d.normalize_or_zero()
}

impl Solid {
    /// The function value and gradient at `p`.
    pub fn value_grad(&self, p: DVec3) -> (f64, DVec3) {
        match *self {
            Solid::Sphere { center, radius } => {
                let d = p - center;
                (radius - d.length(), sphere_grad(d))
            }
            Solid::Watermelon { center, radius } => {
                let d = p - center;
                let ball = (radius - d.length(), sphere_grad(d));
                // Outside the wedge: max(cx - x, cz - z).
                let cut = if -d.x >= -d.z {
                    (-d.x, DVec3::NEG_X)
                } else {
                    (-d.z, DVec3::NEG_Z)
                };
                if ball.0 <= cut.0 { ball } else { cut }
            }
            Solid::Cylinder {
                radius,
                y_min,
                y_max,
            } => {
                let radial = DVec3::new(p.x, 0.0, p.z);
                let mut best = (radius - radial.length(), sphere_grad(radial));
                for candidate in [(p.y - y_min, DVec3::Y), (y_max - p.y, DVec3::NEG_Y)] {
                    if candidate.0 < best.0 {
                        best = candidate;
                    }
                }
                best
            }
        }
    }

    /// A box around the solid.
    pub fn bounds(&self) -> Aabb {
        match *self {
            Solid::Sphere { center, radius } | Solid::Watermelon { center, radius } => {
                Aabb::new(center - radius, center + radius)
            }
            Solid::Cylinder {
                radius,
                y_min,
                y_max,
            } => Aabb::new(
                DVec3::new(-radius, y_min, -radius),
                DVec3::new(radius, y_max, radius),
            ),
        }
    }
}

/// How interior density varies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Density {
    /// The same everywhere.
    Uniform(f64),
    /// Crunchy: `base + amplitude * sin(2 pi |p - center| / wavelength)`, clamped to `[0, 1]`.
    Crunchy {
        /// Centre of the layers.
        center: DVec3,
        /// Mean density.
        base: f64,
        /// Layer contrast.
        amplitude: f64,
        /// Layer spacing, world units.
        wavelength: f64,
    },
}

/// A built-in force field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Field {
    /// The thesis's whirlpool (Figure 7.4): a unit vector spiralling about the w axis.
    Whirlpool,
    /// A constant vector.
    Constant(DVec3),
}

/// A closed-form container with its properties (each optional).
#[derive(Clone, Debug, PartialEq)]
pub struct Analytic {
    /// Object id.
    pub id: u64,
    /// Geometry of the container.
    pub solid: Solid,
    /// Surface tension in `[0, 1]`.
    pub tension: Option<f64>,
    /// Friction coefficient in `[0, 1]`.
    pub friction: Option<f64>,
    /// Interior density.
    pub density: Option<Density>,
    /// Surface zone depth, world units.
    pub zone_depth: f64,
    /// Force field and its domain.
    pub field: Option<(Field, FieldDomain)>,
}

impl Analytic {
    /// A container with no properties.
    pub fn new(id: u64, solid: Solid) -> Self {
        Self {
            id,
            solid,
            tension: None,
            friction: None,
            density: None,
            zone_depth: 0.0,
            field: None,
        }
    }

    /// The thesis's watermelon: a tense rind the tool pops through, then crunchy flesh.
    pub fn watermelon(id: u64, center: DVec3, radius: f64) -> Self {
        Self {
            tension: Some(0.8),
            friction: Some(0.3),
            density: Some(Density::Crunchy {
                center,
                base: 0.5,
                amplitude: 0.4,
                wavelength: radius * 0.1,
            }),
            zone_depth: radius * 0.05,
            ..Self::new(id, Solid::Watermelon { center, radius })
        }
    }

    /// The thesis's whirlpool (Figure 7.3): an invisible cylinder with a helical field.
    pub fn whirlpool(id: u64) -> Self {
        let solid = Solid::Cylinder {
            radius: 1.6,
            y_min: 0.0,
            y_max: 0.7,
        };
        let domain = FieldDomain {
            box_world: solid.bounds(),
            uvw: Aabb::new(DVec3::new(-1.0, 0.0, -1.0), DVec3::new(1.0, 1.0, 1.0)),
            cycle_interval_secs: 0.0,
            time_span_secs: f64::INFINITY,
        };
        Self {
            field: Some((Field::Whirlpool, domain)),
            ..Self::new(id, solid)
        }
    }
}

impl Container for Analytic {
    fn id(&self) -> u64 {
        self.id
    }
    fn bounds(&self) -> Aabb {
        self.solid.bounds()
    }
    fn value_grad(&mut self, p: DVec3, _t_secs: f64) -> (f64, DVec3) {
        self.solid.value_grad(p)
    }
    fn tension(&mut self, _p: DVec3, _t_secs: f64) -> Option<f64> {
        self.tension
    }
    fn friction(&mut self, _p: DVec3, _t_secs: f64) -> Option<f64> {
        self.friction
    }
    fn density(&mut self, p: DVec3, _t_secs: f64) -> Option<f64> {
        self.density.map(|d| match d {
            Density::Uniform(v) => v,
            Density::Crunchy {
                center,
                base,
                amplitude,
                wavelength,
            } => {
                let phase = std::f64::consts::TAU * (p - center).length() / wavelength;
                (base + amplitude * phase.sin()).clamp(0.0, 1.0)
            }
        })
    }
    fn zone_depth(&mut self, _p: DVec3, _t_secs: f64) -> f64 {
        self.zone_depth
    }
    fn field_domain(&self) -> Option<FieldDomain> {
        self.field.map(|(_, domain)| domain)
    }
    fn force_field(&mut self, uvw: DVec3, _t_local_secs: f64) -> DVec3 {
        match self.field {
            Some((Field::Whirlpool, _)) => {
                let (u, v, w) = (uvw.x, uvw.y, uvw.z);
                let d = -0.1;
                DVec3::new(w + d * u, d * v, -u + d * w).normalize_or_zero()
            }
            Some((Field::Constant(f), _)) => f,
            None => DVec3::ZERO,
        }
    }
}

/// `n` watermelons on a square grid in the plane `z = 0` inside `[-1.6, 1.6]^2`, ids `1..=n`:
/// the shared scene of the step benchmark and the zero-allocation test.
pub fn watermelon_grid(n: usize) -> Vec<Analytic> {
    let per_row = (n as f64).sqrt().ceil().max(1.0) as usize;
    let spacing = 3.2 / per_row as f64;
    (0..n)
        .map(|k| {
            let (row, col) = (k / per_row, k % per_row);
            let center = DVec3::new(
                -1.6 + spacing * (col as f64 + 0.5),
                -1.6 + spacing * (row as f64 + 0.5),
                0.0,
            );
            Analytic::watermelon(k as u64 + 1, center, spacing * 0.45)
        })
        .collect()
}

/// Waypoints of a tip circling the device workspace centre in the x-y plane, `n_loops` times
/// with `period_secs` each: it crosses the objects of [`watermelon_grid`] over and over.
pub fn circle_waypoints(
    radius_metres: f64,
    period_secs: f64,
    n_loops: usize,
) -> Vec<crate::device::sim::Waypoint> {
    const N_PER_LOOP: usize = 64;
    (0..=n_loops * N_PER_LOOP)
        .map(|k| {
            let angle = std::f64::consts::TAU * k as f64 / N_PER_LOOP as f64;
            crate::device::sim::Waypoint {
                t_secs: period_secs * k as f64 / N_PER_LOOP as f64,
                position_metres: DVec3::new(angle.cos(), angle.sin(), 0.0) * radius_metres,
            }
        })
        .collect()
}
