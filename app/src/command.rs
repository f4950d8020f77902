//! The command/chat line: plain text is chat; commands change the selected object (or make
//! one): `shape:`, `colour:`, `new:`, the properties (`density:`, `tension:`, `friction:`,
//! `depth:`, `transparency:`, `shininess:`, `texture:`, `force:`), `name:`, the lease
//! (`lease`, `hold`, `release`), `undo` and `redo`. A line becomes at most one op, and only
//! when every formula in it compiles: otherwise the error, with fdsl's caret under the
//! culprit, is what the line gives, and nothing is authored.

use fdsl::tape::Tape;
use fdsl::{Diagnostic, Function, Grids};
use glam::DVec3;
use model::object::{
    ColorDef, Field, ForceField, Formula, Geometry, Object, ObjectData, ObjectError, Property,
    Shape, Slot, Timing, Transform, fit_domain,
};
use replication::payload::LeaseAction;
use replication::shape::ShapePayload;

use crate::engine::{Validated, View};
use crate::new_object::{NEW_OBJECT_COLOUR, NEW_OBJECT_SPACING, new_object_domain};

/// How long a lease taken from the command line lasts (it is taken again by editing on).
pub const LEASE_TTL_SECS: u64 = 300;

/// A property set by a formula (or switched off with `off`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PropertyKind {
    /// `density:` interior density (a fraction of the device's maximum).
    Density,
    /// `tension:` surface tension.
    Tension,
    /// `friction:` surface friction.
    Friction,
    /// `depth:` the surface zone's depth.
    ZoneDepth,
    /// `transparency:` 0 opaque to 1 clear.
    Transparency,
    /// `shininess:` 0 to 1.
    Shininess,
    /// `texture:` a displacement of the surface along its normal.
    Texture,
    /// `force:` a force field `x = ..; y = ..; z = ..;` of `u v w t`.
    Force,
}

impl PropertyKind {
    const ALL: [(&'static str, PropertyKind); 8] = [
        ("density", PropertyKind::Density),
        ("tension", PropertyKind::Tension),
        ("friction", PropertyKind::Friction),
        ("depth", PropertyKind::ZoneDepth),
        ("transparency", PropertyKind::Transparency),
        ("shininess", PropertyKind::Shininess),
        ("texture", PropertyKind::Texture),
        ("force", PropertyKind::Force),
    ];

    /// The keyword.
    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(_, k)| *k == self)
            .map_or("property", |(n, _)| n)
    }

    /// The field a formula (or `None`: off) sets.
    fn field(self, formula: Option<Formula>) -> Field {
        let property = |f: Option<Formula>| f.map(Property::new);
        match self {
            Self::Density => Field::Density(property(formula)),
            Self::Tension => Field::Tension(property(formula)),
            Self::Friction => Field::Friction(property(formula)),
            Self::ZoneDepth => Field::ZoneDepth(property(formula)),
            Self::Transparency => Field::Transparency(formula),
            Self::Shininess => Field::Shininess(formula),
            Self::Texture => Field::Displacement(formula),
            Self::Force => Field::Force(formula.map(|formula| {
                Box::new(ForceField {
                    formula,
                    parameters: [[0.0, 1.0]; 3],
                    timing: Timing::default(),
                    enabled: true,
                })
            })),
        }
    }
}

/// Which lease a line asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LeaseKind {
    /// `lease`: take the object over (a weak lease: others may take it back).
    Weak,
    /// `hold`: take it only if free (a strong lease).
    Strong,
    /// `release`: give it back.
    Release,
}

/// What a line asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command<'a> {
    /// `density: <formula>`, `tension: off`, ...: one property of the selected object.
    Property(PropertyKind, &'a str),
    /// `name: <text>`: the selected object's name.
    Name(&'a str),
    /// `lease`, `hold` or `release` the selected object.
    Lease(LeaseKind),
    /// `tool: carve ball radius 0.2 ...`: the brush a drag sculpts with (no op; see
    /// [`crate::brush::Brush::parse`]).
    Tool(&'a str),
    /// `probe: radius 0.1 tension 0.8 ...`: the touch tool's body, which others feel (no op;
    /// see [`crate::touch::body::ToolBody::parse`]).
    Probe(&'a str),
    /// Plain text: a chat message.
    Chat(&'a str),
    /// `shape: <formula>`: the selected object's implicit geometry.
    Shape(&'a str),
    /// `colour: <r>, <g>, <b>` (formulas or numbers), `colour: r=..; g=..; b=..;`, or one
    /// scalar formula for an object coloured through a colour map.
    Colour(&'a str),
    /// `new: <formula>`: a new object.
    New(&'a str),
    /// `undo`: this peer's latest effective edit of the selected object.
    Undo,
    /// `redo`: the edit this peer's latest undo of the selected object took back.
    Redo,
    /// `expel: <name or id>`: the founder removes a member from the session.
    Expel(&'a str),
    /// `readmit: <name or id>`: the founder takes back its expels of a member.
    Readmit(&'a str),
}

/// Reads a line; `None` for an empty one.
pub fn parse(line: &str) -> Option<Command<'_>> {
    let line = line.trim();
    if line.is_empty() {
        return None;
    }
    if line.eq_ignore_ascii_case("undo") {
        return Some(Command::Undo);
    }
    if line.eq_ignore_ascii_case("redo") {
        return Some(Command::Redo);
    }
    for (word, kind) in [
        ("lease", LeaseKind::Weak),
        ("hold", LeaseKind::Strong),
        ("release", LeaseKind::Release),
    ] {
        if line.eq_ignore_ascii_case(word) {
            return Some(Command::Lease(kind));
        }
    }
    if let Some((keyword, rest)) = line.split_once(':') {
        let rest = rest.trim();
        match keyword.trim().to_ascii_lowercase().as_str() {
            "shape" => return Some(Command::Shape(rest)),
            "colour" | "color" => return Some(Command::Colour(rest)),
            "new" => return Some(Command::New(rest)),
            "name" => return Some(Command::Name(rest)),
            "tool" => return Some(Command::Tool(rest)),
            "probe" => return Some(Command::Probe(rest)),
            "expel" => return Some(Command::Expel(rest)),
            "readmit" => return Some(Command::Readmit(rest)),
            other => {
                if let Some((_, kind)) = PropertyKind::ALL.iter().find(|(n, _)| *n == other) {
                    return Some(Command::Property(*kind, rest));
                }
            }
        }
    }
    Some(Command::Chat(line))
}

/// The op a command authors, and a line saying what it does.
#[derive(Clone, Debug, PartialEq)]
pub struct Planned {
    /// The op's payload, validated: the engine authors it without checking it again
    /// ([`crate::engine::Engine::author_validated`]).
    pub payload: Validated,
    /// What it does, for the status line.
    pub summary: String,
    /// The object it selects afterwards (a new object), if any.
    pub select: Option<u64>,
}

/// Turns a command into an op against the engine's `session` view, or into the error to
/// show under the input.
pub fn plan(
    command: Command<'_>,
    session: &View,
    selected: Option<u64>,
) -> Result<Planned, String> {
    match command {
        Command::Chat(text) => {
            let payload = Validated::new(ShapePayload::Chat(text.to_string()))?;
            Ok(planned(payload, "sent".into()))
        }
        Command::Expel(who) => plan_membership(session, who, true),
        Command::Readmit(who) => plan_membership(session, who, false),
        Command::Shape(text) => plan_shape(session, selected, text),
        Command::Colour(text) => plan_colour(session, selected, text),
        Command::New(text) => plan_new(session, text),
        Command::Property(kind, text) => plan_property(session, selected, kind, text),
        Command::Name(text) => {
            let (id, _) = selected_object(session, selected)?;
            let payload = ShapePayload::Set {
                object: id,
                field: Box::new(Field::Name(text.to_string())),
            };
            let payload = validated("name", payload)?;
            let summary = format!("named {} {text}", session.object_label(id));
            Ok(planned(payload, summary))
        }
        Command::Lease(kind) => plan_lease(session, selected, kind),
        Command::Tool(_) => Err("tool: is a brush setting, not an op; the window sets it".into()),
        Command::Probe(_) => {
            Err("probe: is the touch tool's body, not an op; the window sets it".into())
        }
        Command::Undo => plan_undo(session, selected, false),
        Command::Redo => plan_undo(session, selected, true),
    }
}

/// `payload` once it validates, as every peer checks it; else why not, after `what`.
fn validated(what: &str, payload: ShapePayload) -> Result<Validated, String> {
    Validated::new(payload).map_err(|e| format!("{what}: {e}"))
}

/// A plan that selects nothing new.
fn planned(payload: Validated, summary: String) -> Planned {
    Planned {
        payload,
        summary,
        select: None,
    }
}

/// The selected object, with its id, or why there is none to change.
fn selected_object(session: &View, selected: Option<u64>) -> Result<(u64, &Object), String> {
    let id = selected.ok_or("select an object first (click it in the view or the list)")?;
    session
        .scene()
        .object(model::scene::ObjectId(id))
        .map(|o| (id, o))
        .ok_or_else(|| format!("{} is not in the scene", session.object_label(id)))
}

/// `expel:` or `readmit:`, as the view's membership rules allow.
fn plan_membership(session: &View, who: &str, expel: bool) -> Result<Planned, String> {
    let membership = session.membership_change(who, expel)?;
    let member = membership.member;
    let summary = if expel {
        format!(
            "expelled {}: its ops from now on count for nothing, and every peer closes its \
             connections to it",
            member.short()
        )
    } else {
        format!("readmitted {}", member.short())
    };
    let payload = Validated::new(ShapePayload::Member(Box::new(membership)))?;
    Ok(planned(payload, summary))
}

/// `shape:`: the selected object's implicit geometry, in a domain that fits it.
fn plan_shape(session: &View, selected: Option<u64>, text: &str) -> Result<Planned, String> {
    let (id, object) = selected_object(session, selected)?;
    let (formula, tape) = checked("shape", text, Slot::Geometry, &[])?;
    let current = object.data().geometry.as_ref();
    // A bounded solid gets a domain that fits it; an unbounded one (a half-space that
    // carves) keeps the object's box, which clips it as before.
    let fitted = fit_domain(&tape, 0.0).ok();
    let geometry = Geometry {
        shape: Shape::Implicit(formula),
        domain: fitted
            .or_else(|| current.and_then(|g| g.domain))
            .or(Some(new_object_domain())),
        transform: current.map_or(Transform::IDENTITY, |g| g.transform),
    };
    let payload = ShapePayload::Set {
        object: id,
        field: Box::new(Field::Geometry(Some(Box::new(geometry)))),
    };
    let payload = validated("shape", payload)?;
    let summary = format!("set the shape of {}", session.object_label(id));
    Ok(planned(payload, summary))
}

/// `colour:`: the selected object's diffuse colour (see [`Command::Colour`]).
fn plan_colour(session: &View, selected: Option<u64>, text: &str) -> Result<Planned, String> {
    let (id, object) = selected_object(session, selected)?;
    let current = object.data().appearance.diffuse.as_ref();
    let payload = ShapePayload::Set {
        object: id,
        field: Box::new(Field::Diffuse(Some(colour_def(text, current)?))),
    };
    let payload = validated("colour", payload)?;
    let summary = format!("set the colour of {}", session.object_label(id));
    Ok(planned(payload, summary))
}

/// `new:`: an object whose solid is the formula, in a domain that fits it, placed beside the
/// others.
fn plan_new(session: &View, text: &str) -> Result<Planned, String> {
    let (formula, tape) = checked("new", text, Slot::Geometry, &[])?;
    let domain = fit_domain(&tape, 0.0).map_err(|e| format!("new: {e}"))?;
    let ids = session.next_object();
    let object = ids.id();
    let n_objects = session.scene().len();
    let name = format!("object {}", ids.counter);
    let data = ObjectData {
        name: name.clone(),
        geometry: Some(Geometry::implicit_in(formula, domain)),
        transform: Transform::translate(DVec3::new(
            NEW_OBJECT_SPACING * n_objects as f64,
            0.0,
            0.0,
        )),
        appearance: model::object::Appearance {
            diffuse: Some(ColorDef::Constant(NEW_OBJECT_COLOUR)),
            ..Default::default()
        }
        .into(),
        ..ObjectData::default()
    };
    let payload = ids.create(data, None);
    let payload = validated("new", payload)?;
    Ok(Planned {
        payload,
        summary: format!("created {name}"),
        select: Some(object),
    })
}

/// `density:`, `force:`, ...: one property of the selected object, or `off`.
fn plan_property(
    session: &View,
    selected: Option<u64>,
    kind: PropertyKind,
    text: &str,
) -> Result<Planned, String> {
    let (id, _) = selected_object(session, selected)?;
    let what = kind.name();
    let formula = if text.eq_ignore_ascii_case("off") {
        None
    } else {
        // A force field is the vector `x`, `y`, `z`; the other properties are one value.
        let outputs: &[&str] = match kind {
            PropertyKind::Force => &["x", "y", "z"],
            _ => &[],
        };
        let formula = formula(what, text)?;
        match formula.tape(kind.field(None).slot(), outputs, &Grids::default()) {
            Ok(_) => Some(formula),
            Err(ObjectError::MissingOutput { .. }) => {
                return Err(
                    "force: give x = ...; y = ...; z = ...; (functions of u, v, w, t)".into(),
                );
            }
            Err(e) => return Err(refusal(what, e)),
        }
    };
    let payload = ShapePayload::Set {
        object: id,
        field: Box::new(kind.field(formula)),
    };
    let payload = validated(what, payload)?;
    let summary = format!("set the {what} of {}", session.object_label(id));
    Ok(planned(payload, summary))
}

/// `lease`, `hold` or `release` the selected object.
fn plan_lease(session: &View, selected: Option<u64>, kind: LeaseKind) -> Result<Planned, String> {
    let (id, _) = selected_object(session, selected)?;
    let label = session.object_label(id);
    let (payload, summary) = match kind {
        LeaseKind::Release => (
            ShapePayload::Lease(LeaseAction::Release { object: id }),
            format!("released {label}"),
        ),
        strong => (
            ShapePayload::Lease(LeaseAction::Acquire {
                object: id,
                strong: strong == LeaseKind::Strong,
                ttl_micros: LEASE_TTL_SECS * 1_000_000,
            }),
            format!("took the lease of {label} for {LEASE_TTL_SECS} s"),
        ),
    };
    Ok(planned(Validated::new(payload)?, summary))
}

/// `undo` this peer's latest effective edit of the selected object, or (`redo`) the edit its
/// latest undo of it took back.
fn plan_undo(session: &View, selected: Option<u64>, redo: bool) -> Result<Planned, String> {
    let (id, _) = selected_object(session, selected)?;
    let label = session.object_label(id);
    if redo {
        let target = session
            .redo_target(id)
            .ok_or_else(|| format!("nothing of yours to redo on {label}"))?;
        let summary = format!("redid your last undone edit of {label}");
        return Ok(planned(
            Validated::new(ShapePayload::Redo(target))?,
            summary,
        ));
    }
    let target = session
        .undo_target(id)
        .ok_or_else(|| format!("nothing of yours to undo on {label}"))?;
    let summary = format!("undid your last edit of {label}");
    Ok(planned(
        Validated::new(ShapePayload::Undo(target))?,
        summary,
    ))
}

/// The formula a line gives for `what`, and its tape of `outputs` for `slot`: through the
/// object model's compile cache ([`Formula::tape`]), so the op built from it next compiles
/// nothing again. Refused, the error names `what` and, when the formula does not compile,
/// renders every error diagnostic of fdsl with its caret under the culprit.
fn checked(
    what: &str,
    text: &str,
    slot: Slot,
    outputs: &[&str],
) -> Result<(Formula, Tape), String> {
    let formula = formula(what, text)?;
    let tape = formula
        .tape(slot, outputs, &Grids::default())
        .map_err(|e| refusal(what, e))?;
    Ok((formula, tape))
}

/// The formula of a line's `text`, or why there is none: nothing after the colon, or a text
/// longer than the language takes.
fn formula(what: &str, text: &str) -> Result<Formula, String> {
    if text.trim().is_empty() {
        return Err(format!("{what}: give a formula after the colon"));
    }
    // Too long: fdsl's parser says so before it reads the text, with its caret under the
    // excess, as a line has always shown it.
    Formula::new(text)
        .map_err(|_| does_not_compile(what, text, &Function::compile(text).diagnostics))
}

/// The object model's refusal of a line's formula, as the line shows it.
fn refusal(what: &str, e: ObjectError) -> String {
    match e {
        ObjectError::Compile { error, .. } => {
            does_not_compile(what, &error.source, &error.diagnostics)
        }
        other => format!("{what}: {other}"),
    }
}

/// Every error diagnostic rendered with its caret, under a line naming `what`.
fn does_not_compile(what: &str, source: &str, diagnostics: &[Diagnostic]) -> String {
    let rendered: Vec<String> = diagnostics
        .iter()
        .filter(|d| d.is_error())
        .map(|d| d.render(source))
        .collect();
    format!(
        "{what}: the formula does not compile\n{}",
        rendered.join("\n")
    )
}

/// Splits at commas outside brackets, so `atan2(x, z)` stays one part.
fn split_top_level(text: &str) -> Vec<&str> {
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0i32, 0);
    for (i, c) in text.char_indices() {
        match c {
            '(' | '[' | '{' => depth += 1,
            ')' | ']' | '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(text[start..i].trim());
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(text[start..].trim());
    parts
}

/// The colour a `colour:` line describes (see [`Command::Colour`]).
fn colour_def(text: &str, current: Option<&ColorDef>) -> Result<ColorDef, String> {
    let parts = split_top_level(text);
    match parts.as_slice() {
        [r, g, b] => {
            let numbers: Vec<f32> = parts.iter().filter_map(|p| p.parse().ok()).collect();
            if numbers.len() == 3 {
                if !numbers.iter().all(|v| (0.0..=1.0).contains(v)) {
                    return Err("colour: numbers must lie between 0 and 1".into());
                }
                return Ok(ColorDef::Constant([numbers[0], numbers[1], numbers[2]]));
            }
            // Each part on its own first, so that an error points into the part typed.
            for (name, part) in [("r", r), ("g", g), ("b", b)] {
                checked(&format!("colour ({name})"), part, Slot::Diffuse, &[])?;
            }
            let formula = Formula::new(format!("r = {r}; g = {g}; b = {b};"))
                .map_err(|e| format!("colour: {e}"))?;
            Ok(ColorDef::Rgb(formula))
        }
        [one] => {
            let formula = formula("colour", one)?;
            // An `r`, `g`, `b` formula, or else a scalar through the object's colour map:
            // asked in one go, the text is compiled once whichever it is.
            let rgb_or_scalar: [&[&str]; 2] = [&["r", "g", "b"], &[]];
            let (choice_idx, _) = formula
                .first_tape(Slot::Diffuse, &rgb_or_scalar, &Grids::default())
                .map_err(|e| refusal("colour", e))?;
            if choice_idx == 0 {
                return Ok(ColorDef::Rgb(formula));
            }
            match current {
                Some(ColorDef::Map { map, .. }) => Ok(ColorDef::Map {
                    formula,
                    map: map.clone(),
                }),
                _ => Err(
                    "colour: give r, g, b (three formulas or numbers from 0 to 1), or \
                          r = ...; g = ...; b = ...; (one formula through a colour map works \
                          only for an object that has one)"
                        .into(),
                ),
            }
        }
        _ => Err(format!(
            "colour: give r, g, b (three formulas or numbers), not {} parts",
            parts.len()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use replication::Timestamp;

    #[test]
    fn lines_are_commands_or_chat() {
        assert_eq!(parse("  "), None);
        assert_eq!(parse("Undo"), Some(Command::Undo));
        assert_eq!(parse("redo "), Some(Command::Redo));
        assert_eq!(parse("shape: 1-x^2"), Some(Command::Shape("1-x^2")));
        assert_eq!(parse("Color:0,1,0"), Some(Command::Colour("0,1,0")));
        assert_eq!(parse("new: x"), Some(Command::New("x")));
        assert_eq!(
            parse("Density: 0.5+x"),
            Some(Command::Property(PropertyKind::Density, "0.5+x"))
        );
        assert_eq!(
            parse("tension: off"),
            Some(Command::Property(PropertyKind::Tension, "off"))
        );
        assert_eq!(parse("HOLD"), Some(Command::Lease(LeaseKind::Strong)));
        assert_eq!(parse("release"), Some(Command::Lease(LeaseKind::Release)));
        assert_eq!(parse("name: melon"), Some(Command::Name("melon")));
        assert_eq!(
            parse("note: looks good"),
            Some(Command::Chat("note: looks good"))
        );
        assert_eq!(
            parse("undo it please"),
            Some(Command::Chat("undo it please"))
        );
    }

    #[test]
    fn commas_inside_brackets_do_not_split_a_colour() {
        assert_eq!(
            split_top_level("atan2(x, z), max(y, 0), 1"),
            vec!["atan2(x, z)", "max(y, 0)", "1"]
        );
    }

    /// A view of a log holding the demo scene, its one object, and nothing to clean up.
    fn session() -> (View, u64) {
        let (_, _, s, id) = session_log();
        (s, id)
    }

    /// [`session`] with the log and the key that authored it.
    fn session_log() -> (
        replication::Keypair,
        replication::Log<ShapePayload>,
        View,
        u64,
    ) {
        let keypair = replication::Keypair::from_seed([3; 32]);
        let mut log = replication::Log::default();
        let me = keypair.peer_id();
        let first = View::new(me, &log).unwrap().next_object();
        for payload in crate::demos::DEMOS[0].payloads(first).unwrap() {
            log.author(&keypair, Timestamp(1_000_000), payload).unwrap();
        }
        let s = View::new(me, &log).unwrap();
        let id = s.scene().objects().next().unwrap().0.0;
        (keypair, log, s, id)
    }

    /// Issue 52: a typed formula is compiled once, through the object model's cache, from
    /// the line to the scene (the line's check of it once compiled the text outside the
    /// cache, and the op's object compiled it again). The op's object is built once by the
    /// plan, which checks it as every peer will; the engine authors the planned payload
    /// without building it again ([`Validated`]); signing then decodes it as every peer
    /// will, and the fold builds the scene's object. Counted on this thread, which plans,
    /// signs and folds here as the face and the engine thread do.
    #[test]
    fn a_typed_formula_is_compiled_once_from_the_line_to_the_scene() {
        use model::object::compiled::{
            n_edits_compiled_on_this_thread, n_objects_built_on_this_thread,
        };
        let (keypair, mut log, mut view, id) = session_log();
        let counts = || {
            [
                fdsl::n_compiled_on_this_thread(),
                n_objects_built_on_this_thread(),
                n_edits_compiled_on_this_thread(),
            ]
        };
        let since = |before: [u64; 3]| {
            let now = counts();
            [0, 1, 2].map(|i| now[i] - before[i])
        };
        let lines = [
            "shape: 0.61 - sqrt(x^2 + y^2 + z^2) /* compiled once: shape */",
            "new: 0.3 - sqrt((x-1)^2 + y^2 + z^2) /* compiled once: new */",
            // The watermelon is coloured through a colour map: one scalar keeps the map.
            "colour: 0.5 + 0.2*y /* compiled once: colour through the map */",
            "colour: r = x; g = 0.5; b = abs(z); /* compiled once: colour */",
            "density: 0.5 + 0.1*x /* compiled once: density */",
            "force: x = -v; y = u; z = 0; /* compiled once: force */",
        ];
        for (n, line) in lines.into_iter().enumerate() {
            let before = counts();
            let planned = plan(parse(line).unwrap(), &view, Some(id)).unwrap();
            assert_eq!(since(before), [1, 1, 0], "planning `{line}`");
            // What the engine thread does with a payload `Engine::author_validated` hands it.
            let now = Timestamp(2_000_000 + n as u64);
            let payload = planned.payload.into_payload();
            let (_, insertion) = log.author(&keypair, now, payload).unwrap();
            view.apply(&log, &insertion);
            view.refresh(&log);
            // Nothing is compiled again; besides the plan's, the op's object is built by the
            // signing (which decodes the payload as every peer will) and by the fold.
            assert_eq!(
                since(before),
                [1, 3, 0],
                "`{line}` from the line to the scene"
            );
        }
    }

    #[test]
    fn a_bad_formula_gives_the_caret_diagnostic_and_no_op() {
        let (s, id) = session();
        let err = plan(Command::Shape("1-x^2-sni(y)"), &s, Some(id)).unwrap_err();
        assert!(err.contains("sni"), "{err}");
        assert!(err.contains('^'), "{err}");
        let err = plan(Command::Colour("x, y +, 1"), &s, Some(id)).unwrap_err();
        assert!(err.starts_with("colour (g)"), "{err}");
        assert!(plan(Command::Shape("x"), &s, None).is_err());
        assert!(
            plan(Command::Undo, &s, Some(id))
                .unwrap_err()
                .contains("nothing")
        );
    }

    #[test]
    fn only_the_founder_plans_an_expel_or_a_readmit() {
        let (s, _) = session();
        for command in [Command::Expel("ada"), Command::Readmit("ada")] {
            let err = plan(command, &s, None).unwrap_err();
            assert!(err.contains("founder"), "{err}");
        }
    }

    #[test]
    fn colours_take_numbers_formulas_or_a_scalar_through_the_map() {
        let (s, id) = session();
        let colour = |text| match plan(Command::Colour(text), &s, Some(id))
            .unwrap()
            .payload
            .into_payload()
        {
            ShapePayload::Set { field, .. } => match *field {
                Field::Diffuse(Some(def)) => def,
                other => panic!("{other:?}"),
            },
            other => panic!("{other:?}"),
        };
        assert_eq!(colour("0.2, 0.4, 1"), ColorDef::Constant([0.2, 0.4, 1.0]));
        assert!(matches!(colour("abs(x), y*y, 0.5"), ColorDef::Rgb(_)));
        assert!(matches!(colour("r=x; g=y; b=z;"), ColorDef::Rgb(_)));
        // The watermelon is coloured through a colour map: one scalar keeps the map.
        assert!(matches!(colour("sqrt(x^2+y^2+z^2)"), ColorDef::Map { .. }));
        assert!(plan(Command::Colour("2, 0, 0"), &s, Some(id)).is_err());
    }

    #[test]
    fn new_objects_get_fresh_ids_beside_the_others() {
        let (s, _) = session();
        let planned = plan(Command::New("0.8-sqrt(x^2+y^2+z^2)"), &s, None).unwrap();
        let ShapePayload::Create { object, data, .. } = &*planned.payload else {
            panic!("{planned:?}");
        };
        assert_eq!(planned.select, Some(*object));
        assert_eq!(
            data.transform,
            Transform::translate(DVec3::new(2.5, 0.0, 0.0))
        );
        assert!(s.scene().object(model::scene::ObjectId(*object)).is_none());
    }

    #[test]
    fn every_property_is_a_command_with_caret_errors() {
        let (s, id) = session();
        for (name, kind) in PropertyKind::ALL {
            let text = if kind == PropertyKind::Force {
                "x = -v; y = u; z = 0;"
            } else {
                "0.5+0.1*x"
            };
            let planned = plan(Command::Property(kind, text), &s, Some(id)).unwrap();
            let ShapePayload::Set { object, field } = &*planned.payload else {
                panic!("{planned:?}");
            };
            assert_eq!(*object, id);
            assert_eq!(field.slot(), kind.field(None).slot(), "{name}");
            let off = plan(Command::Property(kind, "off"), &s, Some(id)).unwrap();
            assert!(off.summary.contains(name));
            let err = plan(Command::Property(kind, "0.5+"), &s, Some(id)).unwrap_err();
            assert!(err.starts_with(name) && err.contains('^'), "{err}");
        }
        let err = plan(Command::Property(PropertyKind::Force, "0.5"), &s, Some(id)).unwrap_err();
        assert!(err.contains("x = ..."), "{err}");
        let lease = plan(Command::Lease(LeaseKind::Weak), &s, Some(id)).unwrap();
        assert!(matches!(
            lease.payload.into_payload(),
            ShapePayload::Lease(LeaseAction::Acquire { strong: false, .. })
        ));
    }

    #[test]
    fn a_new_object_gets_a_domain_that_fits_and_an_unbounded_one_is_refused() {
        let (s, _) = session();
        let planned = plan(Command::New("0.3-sqrt((x-1)^2+y^2+z^2)"), &s, None).unwrap();
        let ShapePayload::Create { data, .. } = &*planned.payload else {
            panic!("{planned:?}");
        };
        let b = data.geometry.as_ref().unwrap().domain.unwrap().aabb();
        // The old fixed 2.2 box cut this ball flat at x = 1.1.
        assert!(b.lo.x <= 0.7 && b.hi.x >= 1.3, "{b:?}");
        let err = plan(Command::New("x"), &s, None).unwrap_err();
        assert!(err.contains("unbounded"), "{err}");
    }
    /// One rule for a solid made without a domain: the same bounded formula gets the same
    /// domain, bit for bit, from `new:`, from an FVRML file without `bboxSize` (as an import
    /// plans it), and from a peer (the import's op over the wire and through another log, whose
    /// scene hashes alike); an unbounded one is refused everywhere with the same words.
    #[test]
    fn the_same_bounded_formula_gets_the_same_domain_from_new_a_file_and_a_peer() {
        use replication::Payload as _;
        let (s, _) = session();
        let formula = "0.3-sqrt((x-1)^2+y^2+z^2)";
        let domain_of = |payload: &ShapePayload| match payload {
            ShapePayload::Create { data, .. } => data.geometry.as_ref().unwrap().domain.unwrap(),
            other => panic!("{other:?}"),
        };
        let bits =
            |d: model::object::Domain| [d.center, d.size].map(|v| v.to_array().map(f64::to_bits));
        let from_new = domain_of(&plan(Command::New(formula), &s, None).unwrap().payload);

        let text = format!("FShape {{ geometry FGeometry {{ definition \"{formula}\" }} }}");
        let mut no_files = |path: &str| Err(format!("no file {path}"));
        let options = formats::fvrml::LoadOptions::default();
        let loaded = formats::fvrml::load(&text, &options, &mut no_files).unwrap();
        assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
        let path = std::path::Path::new("ball.wrl");
        let imported = crate::transfer::scene_payloads(path, &loaded.scene, s.next_object())
            .unwrap()
            .payloads;
        let create = imported.last().unwrap();
        assert_eq!(bits(domain_of(create)), bits(from_new));

        // A peer decodes the op's bytes and folds it into its own log.
        let mut bytes = Vec::new();
        create.encode(&mut bytes);
        let decoded = ShapePayload::decode(&bytes).unwrap();
        assert_eq!(bits(domain_of(&decoded)), bits(from_new));
        // Authored by the session's peer, whose ids the import took.
        let (a, b) = (
            replication::Keypair::from_seed([3; 32]),
            replication::Keypair::from_seed([5; 32]),
        );
        let mut log_a = replication::Log::default();
        log_a.author(&a, Timestamp(2_000_000), decoded).unwrap();
        let mut log_b = replication::Log::default();
        log_b.merge(Timestamp(2_000_001), &log_a).unwrap();
        let mut view_a = View::new(a.peer_id(), &log_a).unwrap();
        let mut view_b = View::new(b.peer_id(), &log_b).unwrap();
        assert_eq!(view_a.scene_hash_hex(), view_b.scene_hash_hex());
        let (_, on_b) = view_b.scene().objects().next().unwrap();
        let domain = on_b
            .object
            .data()
            .geometry
            .as_ref()
            .unwrap()
            .domain
            .unwrap();
        assert_eq!(bits(domain), bits(from_new));

        // Unbounded: `new:` refuses it, the file keeps it without a domain and says the same,
        // and the renderer says the same again.
        let unbounded = model::object::FitError::Unbounded.to_string();
        let err = plan(Command::New("x"), &s, None).unwrap_err();
        assert_eq!(err, format!("new: {unbounded}"));
        let text = "FShape { geometry FGeometry { definition \"x\" } }";
        let loaded = formats::fvrml::load(text, &options, &mut no_files).unwrap();
        assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
        assert!(
            loaded.warnings[0].message.ends_with(&unbounded),
            "{:?}",
            loaded.warnings
        );
    }
}
