//! A device path as a CSV file (`t,x,y,z,button`: seconds, the haptic interface point in
//! the scene's own coordinates, button 0 or 1), read with every problem located at its line
//! and column, and resampled to the servo's ticks.
//!
//! Rows may come at any rate; times must increase. Between rows the point is interpolated
//! linearly and the button holds the earlier row's state. A file is bounded before it is
//! read ([`MAX_PATH_FILE_BYTES`]) and while it is read ([`MAX_PATH_ROWS`],
//! [`MAX_LINE_BYTES`], [`MAX_PATH_DURATION_SECS`]), so a hostile file costs bounded memory.

use glam::DVec3;

/// The header line an input path must start with.
pub const PATH_HEADER: &str = "t,x,y,z,button";
/// The most rows (after the header) a path may have.
pub const MAX_PATH_ROWS: usize = 1_000_000;
/// The longest line accepted, bytes.
pub const MAX_LINE_BYTES: usize = 256;
/// The longest path, seconds from its first row to its last (600 000 ticks at 1 kHz).
pub const MAX_PATH_DURATION_SECS: f64 = 600.0;
/// The largest path file read, bytes (checked before reading).
pub const MAX_PATH_FILE_BYTES: u64 = 64 << 20;

/// One row of a path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathRow {
    /// Time, seconds.
    pub t_secs: f64,
    /// The haptic interface point, scene coordinates.
    pub hip_scene: DVec3,
    /// The button is held.
    pub pressed: bool,
}

/// A path read from CSV: at least one row, times increasing.
#[derive(Clone, Debug, PartialEq)]
pub struct TouchPath {
    rows: Vec<PathRow>,
}

/// What is wrong with a path file, at a 1-based line and column (the column of the field
/// in question, or 1 for the whole line).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{line}:{column}: {message}")]
pub struct PathError {
    /// 1-based line.
    pub line: usize,
    /// 1-based byte column.
    pub column: usize,
    /// What is wrong, in words.
    pub message: String,
}

const FIELDS: [&str; 5] = ["t", "x", "y", "z", "button"];

impl TouchPath {
    /// Parses the CSV text of a path.
    pub fn parse(text: &str) -> Result<TouchPath, PathError> {
        let err = |line: usize, column: usize, message: String| PathError {
            line,
            column,
            message,
        };
        let mut rows: Vec<PathRow> = Vec::new();
        let mut header_seen = false;
        for (line_idx, raw) in text.split('\n').enumerate() {
            let line = line_idx + 1;
            let raw = raw.strip_suffix('\r').unwrap_or(raw);
            if raw.len() > MAX_LINE_BYTES {
                let message = format!("line longer than {MAX_LINE_BYTES} bytes");
                return Err(err(line, MAX_LINE_BYTES + 1, message));
            }
            if raw.trim().is_empty() {
                continue;
            }
            if !header_seen {
                if raw.trim() != PATH_HEADER {
                    let message = format!("expected the header `{PATH_HEADER}`");
                    return Err(err(line, 1, message));
                }
                header_seen = true;
                continue;
            }
            if rows.len() == MAX_PATH_ROWS {
                let message = format!("more than {MAX_PATH_ROWS} rows");
                return Err(err(line, 1, message));
            }
            let row = parse_row(raw).map_err(|(column, message)| err(line, column, message))?;
            if let Some(first) = rows.first() {
                let last = rows[rows.len() - 1];
                if row.t_secs <= last.t_secs {
                    let message = format!(
                        "t = {} does not come after the previous row's {}",
                        row.t_secs, last.t_secs
                    );
                    return Err(err(line, 1, message));
                }
                if row.t_secs - first.t_secs > MAX_PATH_DURATION_SECS {
                    let message =
                        format!("the path would last more than {MAX_PATH_DURATION_SECS} s");
                    return Err(err(line, 1, message));
                }
            }
            rows.push(row);
        }
        if !header_seen {
            return Err(err(1, 1, format!("expected the header `{PATH_HEADER}`")));
        }
        if rows.is_empty() {
            let end = text.split('\n').count();
            return Err(err(end, 1, "the path has no rows".into()));
        }
        Ok(TouchPath { rows })
    }

    /// The rows, in time order.
    pub fn rows(&self) -> &[PathRow] {
        &self.rows
    }

    /// The first row's time, seconds.
    pub fn start_secs(&self) -> f64 {
        self.rows[0].t_secs
    }

    /// Ticks of `dt_secs` from the first row to the last, both included.
    pub fn n_ticks(&self, dt_secs: f64) -> usize {
        assert!(dt_secs > 0.0, "tick length {dt_secs}");
        let span = self.rows[self.rows.len() - 1].t_secs - self.start_secs();
        // A row a rounding error short of a tick still gets it.
        (span / dt_secs + 1e-9).floor() as usize + 1
    }

    /// The point and button at tick `tick` (time `start + tick * dt_secs`): linear between
    /// rows, the button of the row at or before it, the last row held past the end.
    pub fn at_tick(&self, tick: usize, dt_secs: f64, cursor: &mut usize) -> PathRow {
        let t = self.start_secs() + tick as f64 * dt_secs;
        while *cursor + 1 < self.rows.len() && self.rows[*cursor + 1].t_secs <= t {
            *cursor += 1;
        }
        let a = self.rows[*cursor];
        let Some(b) = self.rows.get(*cursor + 1) else {
            return PathRow { t_secs: t, ..a };
        };
        let s = ((t - a.t_secs) / (b.t_secs - a.t_secs)).clamp(0.0, 1.0);
        PathRow {
            t_secs: t,
            hip_scene: a.hip_scene.lerp(b.hip_scene, s),
            pressed: a.pressed,
        }
    }
}

/// One data row, or the column and message of its first problem.
fn parse_row(raw: &str) -> Result<PathRow, (usize, String)> {
    let mut values = [0.0; 4];
    let mut pressed = false;
    let mut column = 1;
    let mut n_fields = 0;
    for (idx, field) in raw.split(',').enumerate() {
        if idx >= FIELDS.len() {
            return Err((column, format!("more than {} fields", FIELDS.len())));
        }
        n_fields += 1;
        let text = field.trim();
        if idx == 4 {
            pressed = match text {
                "0" => false,
                "1" => true,
                _ => return Err((column, format!("button must be 0 or 1, not `{text}`"))),
            };
        } else {
            let name = FIELDS[idx];
            let value: f64 = text
                .parse()
                .map_err(|_| (column, format!("{name} is not a number: `{text}`")))?;
            if !value.is_finite() {
                return Err((column, format!("{name} is not finite: `{text}`")));
            }
            values[idx] = value;
        }
        column += field.len() + 1;
    }
    if n_fields < FIELDS.len() {
        let message = format!(
            "expected {} fields ({PATH_HEADER}), found {n_fields}",
            FIELDS.len()
        );
        // Just past the line's end, where the next field would have begun.
        return Err((column - 1, message));
    }
    Ok(PathRow {
        t_secs: values[0],
        hip_scene: DVec3::new(values[1], values[2], values[3]),
        pressed,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn error(text: &str) -> String {
        TouchPath::parse(text).unwrap_err().to_string()
    }

    #[test]
    fn rows_are_read_and_resampled_linearly_with_the_button_held() {
        let path = TouchPath::parse(
            "t,x,y,z,button\r\n0,0,0,0,0\n0.0025, 1, 2, -4, 1\n\n0.004,1,2,-4,0\n",
        )
        .unwrap();
        assert_eq!(path.rows().len(), 3);
        assert_eq!(path.n_ticks(0.001), 5);
        let mut cursor = 0;
        let ticks: Vec<PathRow> = (0..6)
            .map(|k| path.at_tick(k, 0.001, &mut cursor))
            .collect();
        assert_eq!(ticks[1].hip_scene, DVec3::new(0.4, 0.8, -1.6));
        assert!(!ticks[2].pressed);
        assert!(ticks[3].pressed && ticks[3].hip_scene == DVec3::new(1.0, 2.0, -4.0));
        assert!(!ticks[4].pressed, "the last row's button");
        assert_eq!(
            ticks[5].hip_scene,
            DVec3::new(1.0, 2.0, -4.0),
            "held past the end"
        );
        assert!((ticks[5].t_secs - 0.005).abs() < 1e-12);
    }

    #[test]
    fn bad_files_are_located_by_line_and_column() {
        assert_eq!(
            error("t,x,y\n0,0,0"),
            "1:1: expected the header `t,x,y,z,button`"
        );
        assert_eq!(error(""), "1:1: expected the header `t,x,y,z,button`");
        assert_eq!(error("t,x,y,z,button\n"), "2:1: the path has no rows");
        assert_eq!(
            error("t,x,y,z,button\n0,0,0,0,0\n0.1,0,zz,0,0"),
            "3:7: y is not a number: `zz`"
        );
        assert_eq!(
            error("t,x,y,z,button\n0,0,0,0,2"),
            "2:9: button must be 0 or 1, not `2`"
        );
        assert_eq!(
            error("t,x,y,z,button\n0,0,inf,0,0"),
            "2:5: y is not finite: `inf`"
        );
        assert_eq!(
            error("t,x,y,z,button\n0,0,0,0"),
            "2:8: expected 5 fields (t,x,y,z,button), found 4"
        );
        assert_eq!(
            error("t,x,y,z,button\n0,0,0,0,0,7"),
            "2:11: more than 5 fields"
        );
        assert!(
            error("t,x,y,z,button\n1,0,0,0,0\n1,0,0,0,0").starts_with("3:1: t = 1 does not come")
        );
        let long = format!("t,x,y,z,button\n0,0,0,0,0{}", " ".repeat(MAX_LINE_BYTES));
        assert_eq!(error(&long), "2:257: line longer than 256 bytes");
        let late = format!(
            "t,x,y,z,button\n0,0,0,0,0\n{},0,0,0,0",
            MAX_PATH_DURATION_SECS + 0.5
        );
        assert_eq!(error(&late), "3:1: the path would last more than 600 s");
    }

    #[test]
    fn a_path_longer_than_the_row_limit_is_refused_at_the_first_row_past_it() {
        let mut text = String::from(PATH_HEADER);
        for k in 0..=MAX_PATH_ROWS {
            text.push_str(&format!("\n{},0,0,0,0", k as f64 * 1e-4));
        }
        let e = TouchPath::parse(&text).unwrap_err();
        assert_eq!((e.line, e.column), (MAX_PATH_ROWS + 2, 1));
        assert!(e.message.contains("more than 1000000 rows"), "{e}");
    }
}
