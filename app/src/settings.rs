//! What a user chose and expects to find again: the name and colour others see, the brush,
//! and the window's layout (its size and the side panel's width). Kept as a small JSON file in the program's data directory, written whole to a
//! temporary file and renamed into place; a missing or unreadable file gives the defaults and
//! a notice, never an error that stops the program.

use std::path::Path;

use serde_json::{Value, json};

use crate::brush::Brush;

/// The settings file's name in the data directory.
pub const SETTINGS_FILE: &str = "settings.json";
/// Longest settings file read.
pub const MAX_SETTINGS_BYTES: u64 = 64 * 1024;
/// Window sides kept, in points: smaller or larger ones (a broken file) are not restored.
pub const WINDOW_POINTS_RANGE: [f32; 2] = [200.0, 8192.0];
/// Side panel widths kept, in points.
pub const SIDE_PANEL_POINTS_RANGE: [f32; 2] = [150.0, 4096.0];

/// The kept settings.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Settings {
    /// The name other peers see.
    pub name: Option<String>,
    /// The colour other peers see (sRGB).
    pub colour: Option<[u8; 3]>,
    /// The brush.
    pub brush: Option<Brush>,
    /// The window's inner size, points.
    pub window_points: Option<[f32; 2]>,
    /// The side panel's width, points.
    pub side_panel_points: Option<f32>,
}

impl Settings {
    /// Reads the settings at `path`: the defaults when there is no file, and the defaults with
    /// the reason when it cannot be read.
    pub fn load(path: &Path) -> (Settings, Option<String>) {
        if matches!(std::fs::symlink_metadata(path), Err(e) if e.kind() == std::io::ErrorKind::NotFound)
        {
            return (Settings::default(), None);
        }
        let parsed = crate::files::read_bounded(path, MAX_SETTINGS_BYTES)
            .and_then(|bytes| {
                String::from_utf8(bytes).map_err(|_| format!("{}: not UTF-8", path.display()))
            })
            .and_then(|t| {
                serde_json::from_str::<Value>(&t).map_err(|e| format!("{}: {e}", path.display()))
            });
        match parsed {
            Ok(v) => Settings::from_json(&v),
            Err(e) => (
                Settings::default(),
                Some(format!("{e}; using the defaults")),
            ),
        }
    }

    fn from_json(v: &Value) -> (Settings, Option<String>) {
        let name = v["name"].as_str().map(str::to_string);
        let colour = v["colour"].as_array().and_then(|c| {
            let c: Vec<u8> = c
                .iter()
                .filter_map(|x| x.as_u64().and_then(|x| u8::try_from(x).ok()))
                .collect();
            <[u8; 3]>::try_from(c).ok()
        });
        let (brush, notice) = match v["brush"].as_str() {
            Some(text) => match Brush::default().parse(text) {
                Ok(b) => (Some(b), None),
                Err(e) => (
                    None,
                    Some(format!("the kept brush is not understood ({e})")),
                ),
            },
            None => (None, None),
        };
        let within = |x: f64, [lo, hi]: [f32; 2]| {
            let x = x as f32;
            (x.is_finite() && (lo..=hi).contains(&x)).then_some(x)
        };
        let window_points = v["window"].as_array().and_then(|w| match w.as_slice() {
            [a, b] => Some([
                within(a.as_f64()?, WINDOW_POINTS_RANGE)?,
                within(b.as_f64()?, WINDOW_POINTS_RANGE)?,
            ]),
            _ => None,
        });
        let side_panel_points = v["side_panel"]
            .as_f64()
            .and_then(|w| within(w, SIDE_PANEL_POINTS_RANGE));
        (
            Settings {
                name,
                colour,
                brush,
                window_points,
                side_panel_points,
            },
            notice,
        )
    }

    /// Writes the settings to `path` (a temporary file beside it, then a rename).
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        let value = json!({
            "name": self.name,
            "colour": self.colour,
            "brush": self.brush.map(|b| b.describe()),
            "window": self.window_points,
            "side_panel": self.side_panel_points,
        });
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let tmp = path.with_extension(format!("json.tmp-{}", std::process::id()));
        std::fs::write(&tmp, serde_json::to_string_pretty(&value)?)?;
        std::fs::rename(&tmp, path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brush::BrushOp;

    #[test]
    fn settings_round_trip_and_a_bad_file_gives_the_defaults() {
        let dir = std::env::temp_dir().join(format!("sculpt-settings-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join(SETTINGS_FILE);
        assert_eq!(Settings::load(&path), (Settings::default(), None));
        let brush = Brush::default()
            .parse("paint colour 1 0.5 0 box radius 0.3 blend 0.1 mirror y")
            .unwrap();
        let kept = Settings {
            name: Some("Ada".into()),
            colour: Some([10, 200, 30]),
            brush: Some(brush),
            window_points: Some([1000.0, 640.0]),
            side_panel_points: Some(320.5),
        };
        kept.save(&path).unwrap();
        assert_eq!(Settings::load(&path), (kept, None));
        assert!(matches!(brush.op, BrushOp::Paint(..)));
        std::fs::write(&path, "{ not json").unwrap();
        let (defaults, notice) = Settings::load(&path);
        assert_eq!(defaults, Settings::default());
        assert!(notice.unwrap().contains("using the defaults"));
        // A layout out of range (a window of 0 or 10^9 points) is not restored.
        std::fs::write(&path, r#"{"window": [0, 1e9], "side_panel": -5}"#).unwrap();
        let (read, notice) = Settings::load(&path);
        assert_eq!(
            (read.window_points, read.side_panel_points, notice),
            (None, None, None)
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
