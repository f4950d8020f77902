//! The scripted steps: a table from a script line's prefix to the small function that runs
//! that kind of step; a line no step names runs as if typed in the command line. `--drag`
//! and `--key` reach the same steps as `drag:` and `key:` lines.
//!
//! A step that fails records the failure (the process then exits non-zero with it) and the
//! script goes on; every step, failed or not, makes the next wait until everything is drawn.

use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::window::app::SculptApp;
use ::app::engine::lock;

/// Longest `wait-secs:` step a script may ask for.
const MAX_WAIT_SECS: f64 = 60.0;

/// What a step does with the rest of its line (the text after its prefix, untrimmed).
type Step = fn(&mut SculptApp, &str) -> Result<(), String>;

/// How a line names its step.
#[derive(Clone, Copy, Debug)]
enum Name {
    /// The line starts with this.
    Prefix(&'static str),
    /// The line, trimmed, is this.
    Whole(&'static str),
}

impl Name {
    /// The rest of `line` when it names this step.
    fn rest_of(self, line: &str) -> Option<&str> {
        match self {
            Name::Prefix(prefix) => line.strip_prefix(prefix),
            Name::Whole(whole) => (line.trim() == whole).then_some(""),
        }
    }
}

/// Every kind of step, tried in order.
const STEPS: [(Name, Step); 17] = [
    (Name::Prefix("drag:"), drag),
    (Name::Prefix("wait-ops:"), wait_ops),
    (Name::Prefix("wait-secs:"), wait_secs),
    (Name::Whole("wait-touch-steady"), wait_touch_steady),
    (Name::Prefix("touch:"), touch),
    (Name::Prefix("touch-record:"), touch_record),
    (Name::Prefix("touch-zone:"), touch_zone),
    (Name::Prefix("touch-force:"), touch_force),
    (Name::Prefix("touch-share:"), touch_share),
    (Name::Prefix("touch-device:"), touch_device),
    (Name::Prefix("touch-stroke:"), touch_stroke),
    (Name::Prefix("touch-at:"), touch_at),
    (Name::Prefix("import:"), import),
    (Name::Prefix("export:"), export),
    (Name::Prefix("join:"), join),
    (Name::Prefix("demo:"), demo),
    (Name::Prefix("key:"), key),
];

impl SculptApp {
    /// Runs one script line: the step it names, else a command line as if typed.
    pub(super) fn run_step(&mut self, line: &str) {
        let named = STEPS
            .iter()
            .find_map(|(name, step)| Some((*step, name.rest_of(line)?)));
        let result = match named {
            Some((step, rest)) => step(self, rest),
            None => {
                command(self, line);
                Ok(())
            }
        };
        if let Err(e) = result {
            self.hooks.fail(e);
        }
    }
}

/// A line no step names: run as if typed (a line that fails stays in the input, above its
/// error).
fn command(app: &mut SculptApp, line: &str) {
    println!("sculpt: scripted command: {line}");
    app.command.input = line.to_string();
    app.submit(line);
    if let Some(error) = &app.command.error {
        println!("sculpt: command error:\n{error}");
    }
}

/// `drag: X0,Y0:X1,Y1`: a sculpting drag across the viewport (fractions of its size).
fn drag(app: &mut SculptApp, spec: &str) -> Result<(), String> {
    let drag = parse_drag(spec.trim()).map_err(|e| format!("bad scripted drag `{spec}`: {e}"))?;
    println!("sculpt: scripted drag: {spec}");
    app.hooks.drag = Some((drag, 0));
    Ok(())
}

/// `wait-ops: N`: later steps wait until the session holds N ops.
fn wait_ops(app: &mut SculptApp, n: &str) -> Result<(), String> {
    let n_ops = n
        .trim()
        .parse::<usize>()
        .map_err(|e| format!("bad `wait-ops: {n}`: {e}"))?;
    app.hooks.step_ops = Some(n_ops);
    Ok(())
}

/// `wait-secs: S`: later steps wait S seconds (the scene's time runs on).
fn wait_secs(app: &mut SculptApp, secs: &str) -> Result<(), String> {
    let s = secs
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|s| (0.0..=MAX_WAIT_SECS).contains(s))
        .ok_or_else(|| {
            format!("bad `wait-secs: {secs}`: a number of seconds up to {MAX_WAIT_SECS}")
        })?;
    println!("sculpt: scripted wait: {s} s");
    let wait = std::time::Duration::from_secs_f64(s);
    app.hooks.step_until = Some(::app::clock::now().instant + wait);
    Ok(())
}

/// `wait-touch-steady`: later steps wait until the servo has run without a stall a while.
fn wait_touch_steady(app: &mut SculptApp, _: &str) -> Result<(), String> {
    let live = app
        .touch
        .live
        .as_ref()
        .ok_or("`wait-touch-steady` before `touch: on`")?;
    app.hooks.touch_steady = Some(live.steady_watch());
    Ok(())
}

/// `touch: on|off`: touching with the mouse.
fn touch(app: &mut SculptApp, word: &str) -> Result<(), String> {
    let on = match word.trim() {
        "on" => true,
        "off" => false,
        other => return Err(format!("bad `touch: {other}`: on or off")),
    };
    println!("sculpt: scripted touch: {}", word.trim());
    app.set_touching(on)
}

/// `touch-record: PATH|off`: recording the touch tool's path.
fn touch_record(app: &mut SculptApp, target: &str) -> Result<(), String> {
    let target = target.trim();
    println!("sculpt: scripted touch record: {target}");
    if target == "off" {
        app.stop_touch_recording();
        return Ok(());
    }
    app.start_touch_recording(Path::new(target))
}

/// `touch-zone: X,Y,Z SIZE`: the haptic zone's centre (scene coordinates) and size.
fn touch_zone(app: &mut SculptApp, zone: &str) -> Result<(), String> {
    println!("sculpt: scripted zone: {}", zone.trim());
    let numbers: Vec<f64> = zone
        .split([',', ' '])
        .filter(|w| !w.is_empty())
        .filter_map(|w| w.parse().ok())
        .collect();
    match (&mut app.touch.live, numbers.as_slice()) {
        (Some(live), &[x, y, z, size]) => {
            live.set_zone(DVec3::new(x, y, z), size);
            Ok(())
        }
        (None, _) => Err("`touch-zone:` before `touch: on`".into()),
        _ => Err(format!("bad `touch-zone: {zone}`: X,Y,Z SIZE")),
    }
}

/// `touch-force: VID:PID|off`: the force-feedback device the force goes to.
fn touch_force(app: &mut SculptApp, ids: &str) -> Result<(), String> {
    let ids = ids.trim();
    println!("sculpt: scripted force output: {ids}");
    let parsed = match ids {
        "off" => None,
        _ => Some(
            ::app::touch::force_output::parse_ids(ids)
                .ok_or_else(|| format!("bad `touch-force: {ids}`: VID:PID in hex, or off"))?,
        ),
    };
    app.set_force_output(parsed)
}

/// `touch-share: PEER|off`: holding the touch tool with a peer (short id or name).
fn touch_share(app: &mut SculptApp, who: &str) -> Result<(), String> {
    let who = who.trim();
    println!("sculpt: scripted shared tool: {who}");
    if who == "off" {
        app.touch.hold_with = None;
        return Ok(());
    }
    let found = lock(app.engine.view())
        .peers()
        .iter()
        .find(|r| r.peer.short() == who || r.name == who)
        .map(|r| r.peer);
    let peer = found
        .ok_or_else(|| format!("bad `touch-share: {who}`: no peer with that short id or name"))?;
    app.touch.hold_with = Some(peer);
    Ok(())
}

/// `touch-device: mouse|3d-mouse`: what moves the touch tool.
fn touch_device(app: &mut SculptApp, word: &str) -> Result<(), String> {
    let on = match word.trim() {
        "3d-mouse" => true,
        "mouse" => false,
        other => return Err(format!("bad `touch-device: {other}`: mouse or 3d-mouse")),
    };
    println!("sculpt: scripted touch device: {}", word.trim());
    app.set_spacemouse(on)
}

/// `touch-stroke: X0,Y0,Z0:X1,Y1,Z1`: a stroke with the touch device's button held, along a
/// segment in scene coordinates.
fn touch_stroke(app: &mut SculptApp, spec: &str) -> Result<(), String> {
    let point = |text: &str| -> Option<DVec3> {
        let v: Vec<f64> = text
            .split(',')
            .map(|c| c.trim().parse().ok())
            .collect::<Option<_>>()?;
        (v.len() == 3).then(|| DVec3::new(v[0], v[1], v[2]))
    };
    let ends = spec
        .split_once(':')
        .and_then(|(a, b)| Some([point(a)?, point(b)?]))
        .ok_or_else(|| {
            format!("bad `touch-stroke: {spec}`: X0,Y0,Z0:X1,Y1,Z1 in scene coordinates")
        })?;
    if app.touch.live.is_none() {
        return Err("`touch-stroke:` before `touch: on`".into());
    }
    println!("sculpt: scripted touch stroke: {}", spec.trim());
    app.hooks.touch_drag = Some((ends, 0));
    Ok(())
}

/// `touch-at: X,Y,Z`: moves the touch tool to a point in scene coordinates.
fn touch_at(app: &mut SculptApp, at: &str) -> Result<(), String> {
    let point: Vec<f64> = at
        .split(',')
        .filter_map(|v| v.trim().parse().ok())
        .collect();
    match (&app.touch.live, point.as_slice()) {
        (Some(live), &[x, y, z]) => {
            live.move_to_world(DVec3::new(x, y, z));
            Ok(())
        }
        (None, _) => Err("`touch-at:` before `touch: on`".into()),
        _ => Err(format!("bad `touch-at: {at}`: X,Y,Z")),
    }
}

/// `import: PATH`: a scene or mesh file into the session.
fn import(app: &mut SculptApp, path: &str) -> Result<(), String> {
    println!("sculpt: scripted import: {path}");
    app.import_file(Path::new(path.trim()))
}

/// `export: PATH`: the selection (or the scene) to a file.
fn export(app: &mut SculptApp, path: &str) -> Result<(), String> {
    println!("sculpt: scripted export: {path}");
    app.export_file(PathBuf::from(path.trim()))
}

/// `join: INVITE`: leaves this session for the invite's.
fn join(app: &mut SculptApp, code: &str) -> Result<(), String> {
    println!("sculpt: scripted join");
    app.join(code.trim())
}

/// `demo: NAME`: leaves this session for a demo's own.
fn demo(app: &mut SculptApp, name: &str) -> Result<(), String> {
    let name = name.trim();
    println!("sculpt: scripted demo: {name}");
    ::app::demos::find(name).and_then(|demo| app.open_demo(demo))
}

/// `key: NAME`: a named shortcut (undo, redo, sculpt, navigate, play, pause, space).
fn key(app: &mut SculptApp, key: &str) -> Result<(), String> {
    println!("sculpt: scripted key: {key}");
    app.shortcut_named(key.trim())
}

/// `X0,Y0:X1,Y1`, fractions of the viewport.
pub fn parse_drag(text: &str) -> Result<[[f32; 2]; 2], String> {
    let point = |p: &str| -> Result<[f32; 2], String> {
        let (x, y) = p.split_once(',').ok_or("a point is X,Y")?;
        let f = |v: &str| {
            v.trim()
                .parse::<f32>()
                .ok()
                .filter(|f| (0.0..=1.0).contains(f))
                .ok_or(format!("`{v}` is not a fraction from 0 to 1"))
        };
        Ok([f(x)?, f(y)?])
    };
    let (a, b) = text.split_once(':').ok_or("a drag is X0,Y0:X1,Y1")?;
    Ok([point(a)?, point(b)?])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_line_form_names_its_own_step_and_no_step_hides_a_later_one() {
        for (i, (name, _)) in STEPS.iter().enumerate() {
            let (Name::Prefix(text) | Name::Whole(text)) = *name;
            let line = format!("{text} x");
            let line: &str = if matches!(name, Name::Whole(_)) {
                text
            } else {
                &line
            };
            let first = STEPS.iter().position(|(n, _)| n.rest_of(line).is_some());
            assert_eq!(first, Some(i), "`{line}` runs another step first");
        }
        assert!(
            STEPS
                .iter()
                .all(|(n, _)| n.rest_of("shape: x^2 < 1").is_none()),
            "a command line is no step"
        );
    }

    #[test]
    fn a_drag_is_two_points_of_fractions() {
        assert_eq!(
            parse_drag("0.2,0.5 : 0.8,0.5"),
            Ok([[0.2, 0.5], [0.8, 0.5]])
        );
        assert_eq!(
            parse_drag("0.2,1.5:0,0"),
            Err("`1.5` is not a fraction from 0 to 1".to_string())
        );
        assert_eq!(
            parse_drag("0.2,0.5"),
            Err("a drag is X0,Y0:X1,Y1".to_string())
        );
    }
}
