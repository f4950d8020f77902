//! The touch tool's own body: a ball with physical properties that travels with the tool in
//! presence, so that other peers feel it as they feel any object (the thesis's tools carry
//! their own tension, friction and density: a drill feels different from a probe).
//!
//! Set with the `probe:` command (`probe: radius 0.1 tension 0.8 friction 0.3 density 1`,
//! `probe: off`) or the Touch section. A body with no tension and no density is not tangible
//! and is not sent. Receivers read the other peers' tangible tools from their presence
//! ([`peer_tools`]) and hand them to their servo's feed (`haptic::feed`), which builds each
//! at the sender's tool point as an fdsl object: the ball `radius - |p|` with those
//! properties and a surface zone of half the radius.

use std::collections::BTreeMap;

use glam::DVec3;
use haptic::feed::RemoteTool;
use model::object::{Domain, Formula, Geometry, Object, ObjectData, Physics, Property, Transform};
use replication::PeerId;

use replication::sync::ephemeral::presence::Presence;

/// Largest tool radius, scene units.
pub const MAX_TOOL_RADIUS: f64 = 10.0;
/// Largest tension, friction or density a tool may carry.
pub const MAX_TOOL_PROPERTY: f64 = 10.0;
/// The radius a body starts with, scene units.
pub const DEFAULT_TOOL_RADIUS: f64 = 0.08;

/// The touch tool's body (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolBody {
    /// The ball's radius, scene units (0 < r ≤ [`MAX_TOOL_RADIUS`]).
    pub radius: f64,
    /// Surface tension (0: none), at most [`MAX_TOOL_PROPERTY`].
    pub tension: f64,
    /// Surface friction (0: none).
    pub friction: f64,
    /// Interior density (0: none).
    pub density: f64,
}

impl Default for ToolBody {
    /// Intangible: a ball of [`DEFAULT_TOOL_RADIUS`] with no properties.
    fn default() -> Self {
        ToolBody {
            radius: DEFAULT_TOOL_RADIUS,
            tension: 0.0,
            friction: 0.0,
            density: 0.0,
        }
    }
}

impl ToolBody {
    /// Whether others can feel it (it has tension or density).
    pub fn is_tangible(&self) -> bool {
        self.tension > 0.0 || self.density > 0.0
    }

    /// Whether every number is within its limits (what a receiver checks of a sender's).
    pub fn is_valid(&self) -> bool {
        let property = |v: f64| (0.0..=MAX_TOOL_PROPERTY).contains(&v);
        self.radius > 0.0
            && self.radius <= MAX_TOOL_RADIUS
            && property(self.tension)
            && property(self.friction)
            && property(self.density)
    }

    /// This body changed by `text`: words and numbers in any order (`radius R`, `tension T`,
    /// `friction F`, `density D`), or `off` (no tension, friction or density). An error names
    /// the word it is about.
    pub fn parse(&self, text: &str) -> Result<ToolBody, String> {
        let text = text.trim();
        if text == "off" {
            return Ok(ToolBody {
                radius: self.radius,
                ..ToolBody::default()
            });
        }
        let mut out = *self;
        let mut words = text.split_whitespace();
        let mut n = 0;
        while let Some(word) = words.next() {
            let value = words
                .next()
                .ok_or_else(|| format!("`{word}` needs a number after it"))?;
            let v: f64 = value
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| format!("`{word} {value}`: `{value}` is not a number"))?;
            let (slot, max) = match word {
                "radius" => (&mut out.radius, MAX_TOOL_RADIUS),
                "tension" => (&mut out.tension, MAX_TOOL_PROPERTY),
                "friction" => (&mut out.friction, MAX_TOOL_PROPERTY),
                "density" => (&mut out.density, MAX_TOOL_PROPERTY),
                other => {
                    return Err(format!(
                        "`{other}`: a probe has radius, tension, friction and density (or `off`)"
                    ));
                }
            };
            let lowest_ok = if word == "radius" { v > 0.0 } else { v >= 0.0 };
            if !lowest_ok || v > max {
                let lowest = if word == "radius" { "above 0" } else { "0" };
                return Err(format!("`{word} {value}`: from {lowest} to {max}"));
            }
            *slot = v;
            n += 1;
        }
        if n == 0 {
            return Err(
                "probe: give radius, tension, friction or density with a number, or off".into(),
            );
        }
        Ok(out)
    }

    /// In words, for the status line.
    pub fn describe(&self) -> String {
        if !self.is_tangible() {
            return format!("a probe of radius {} that others cannot feel", self.radius);
        }
        format!(
            "a probe of radius {}, tension {}, friction {}, density {}",
            self.radius, self.tension, self.friction, self.density
        )
    }

    /// `[radius, tension, friction, density]`, as presence carries it.
    pub fn to_wire(&self) -> [f32; 4] {
        [self.radius, self.tension, self.friction, self.density].map(|v| v as f32)
    }

    /// A body from presence, if it is valid.
    pub fn from_wire(wire: [f32; 4]) -> Option<ToolBody> {
        let [radius, tension, friction, density] = wire.map(f64::from);
        let body = ToolBody {
            radius,
            tension,
            friction,
            density,
        };
        body.is_valid().then_some(body)
    }

    /// The body as an object at `at` (scene coordinates), for a servo's scene.
    pub fn object(&self, at: DVec3) -> Option<Object> {
        // A property where the value is positive; a number's text always compiles.
        let property = |v: f64| {
            (v > 0.0)
                .then(|| Formula::new(format!("{v}")).map(Property::new))
                .transpose()
                .ok()
        };
        let data = ObjectData {
            name: "probe".into(),
            geometry: Some(Geometry {
                transform: Transform::translate(at),
                ..Geometry::implicit_in(
                    Formula::new(format!("{} - sqrt(x^2 + y^2 + z^2)", self.radius)).ok()?,
                    Domain::new(DVec3::ZERO, DVec3::splat(2.2 * self.radius)),
                )
            }),
            physics: Physics {
                tension: property(self.tension)?,
                friction: property(self.friction)?,
                density: property(self.density)?,
                zone_depth: property(0.5 * self.radius)?,
                ..Physics::default()
            }
            .into(),
            ..ObjectData::default()
        };
        Object::new(data).ok()
    }
}

/// Another peer's tangible touch tool, as its presence gives it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeerTool {
    /// The peer holding it.
    pub peer: PeerId,
    /// The tool point, scene coordinates.
    pub at: DVec3,
    /// Its body (tangible).
    pub body: ToolBody,
}

impl RemoteTool for PeerTool {
    fn object(&self) -> Option<Object> {
        self.body.object(self.at)
    }
}

/// The tangible tools in other peers' `presence`, in peer id order. Presence carries the
/// tool point in the renderer's world (+z up, as the window draws it); it is turned back into
/// the scene's here.
pub fn peer_tools(presence: &BTreeMap<PeerId, Presence>) -> Vec<PeerTool> {
    let scene_from_render = render::snapshot::render_from_scene().inverse();
    presence
        .iter()
        .filter_map(|(peer, p)| {
            let body = ToolBody::from_wire(p.tool_body?)?;
            let at = scene_from_render.transform_point3(glam::Vec3::from_array(p.tool?));
            body.is_tangible().then_some(PeerTool {
                peer: *peer,
                at: at.as_dvec3(),
                body,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn probes_parse_with_their_limits_and_errors_name_the_word() {
        let body = ToolBody::default()
            .parse("tension 0.8 radius 0.1 density 2")
            .unwrap();
        assert_eq!(
            body,
            ToolBody {
                radius: 0.1,
                tension: 0.8,
                friction: 0.0,
                density: 2.0
            }
        );
        assert!(body.is_tangible() && body.is_valid());
        let off = body.parse("off").unwrap();
        assert!(!off.is_tangible());
        assert_eq!(off.radius, 0.1);
        for (text, word) in [
            ("tension", "`tension` needs"),
            ("tension x", "not a number"),
            ("tension -1", "from 0"),
            ("radius 0", "from above 0"),
            ("density 11", "to 10"),
            ("hardness 2", "`hardness`"),
            ("", "give radius"),
            ("tension NaN", "not a number"),
        ] {
            let e = body.parse(text).unwrap_err();
            assert!(e.contains(word), "{text}: {e}");
        }
        assert_eq!(ToolBody::from_wire(body.to_wire()), Some(body_f32(body)));
        assert_eq!(ToolBody::from_wire([0.1, -1.0, 0.0, 0.0]), None);
        assert_eq!(ToolBody::from_wire([0.0, 1.0, 0.0, 0.0]), None);
    }

    /// `b` through f32, as presence carries it.
    fn body_f32(b: ToolBody) -> ToolBody {
        let [radius, tension, friction, density] = b.to_wire().map(f64::from);
        ToolBody {
            radius,
            tension,
            friction,
            density,
        }
    }

    #[test]
    fn peers_tools_are_their_tangible_valid_bodies_at_their_points_in_the_scene() {
        let body = ToolBody {
            radius: 0.1,
            tension: 0.8,
            friction: 0.0,
            density: 0.0,
        };
        let touching = |tool: Option<[f32; 3]>, body: Option<[f32; 4]>| Presence {
            tool,
            tool_body: body,
            ..Presence::named("p".into(), [0; 3])
        };
        let presence = BTreeMap::from([
            // Its tool point in the renderer's world (+z up): the scene's (0, 1.25, 0).
            (
                PeerId([1; 32]),
                touching(Some([0.0, 0.0, 1.25]), Some(body.to_wire())),
            ),
            (PeerId([2; 32]), touching(None, Some(body.to_wire()))),
            (
                PeerId([3; 32]),
                touching(Some([0.0; 3]), Some(ToolBody::default().to_wire())),
            ),
            (
                PeerId([4; 32]),
                touching(Some([0.0; 3]), Some([-1.0, 1.0, 0.0, 0.0])),
            ),
            (PeerId([5; 32]), touching(Some([0.0; 3]), None)),
        ]);
        let tools = peer_tools(&presence);
        assert_eq!(tools.len(), 1, "{tools:?}");
        assert_eq!(
            (tools[0].peer, tools[0].body),
            (PeerId([1; 32]), body_f32(body))
        );
        assert!((tools[0].at - DVec3::new(0.0, 1.25, 0.0)).length() < 1e-6);
        let object = RemoteTool::object(&tools[0]).unwrap();
        assert!(object.sampler().value(tools[0].at, 0.0) > 0.09);
    }

    #[test]
    fn a_body_is_a_tangible_ball_where_the_tool_is() {
        let body = ToolBody {
            radius: 0.2,
            tension: 0.5,
            friction: 0.1,
            density: 1.0,
        };
        let at = DVec3::new(1.0, 2.0, 3.0);
        let object = body.object(at).unwrap();
        assert!(object.is_tangible());
        let mut s = object.sampler();
        assert!((s.value(at, 0.0) - 0.2).abs() < 1e-9);
        assert!(s.value(at + DVec3::new(0.3, 0.0, 0.0), 0.0) < 0.0);
        assert!(
            (s.scalar(model::object::Paintable::Density, at, 0.0)
                .unwrap()
                - 1.0)
                .abs()
                < 1e-9
        );
    }
}
