//! What a live touch session leaves behind: the tool's path recorded as the CSV that
//! `sculpt touch --trace` replays ([`Recorder`]), and the recent force and energy the window
//! plots ([`ForceHistory`]).
//!
//! The recorder writes a row whenever it is given one (the window gives one a frame, after
//! the pointer or the 3D mouse moved the tool), in the scene's coordinates with the button
//! state, as [`super::path::TouchPath`] reads it: the replay interpolates between rows to
//! 1 kHz. It stops by itself at the path's limits ([`MAX_PATH_ROWS`] rows,
//! [`MAX_PATH_DURATION_SECS`] seconds, [`MAX_PATH_FILE_BYTES`] bytes), so what it writes
//! always replays.

use std::collections::VecDeque;
use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::path::{MAX_LINE_BYTES, MAX_PATH_DURATION_SECS, MAX_PATH_FILE_BYTES, MAX_PATH_ROWS};

/// How much recent history the force plot keeps, seconds.
pub const FORCE_HISTORY_SECS: f64 = 10.0;
/// Most samples the force plot keeps (a frame each).
pub const MAX_FORCE_HISTORY_SAMPLES: usize = 4_096;

/// A touch path being written to a file.
pub struct Recorder {
    out: BufWriter<File>,
    path: PathBuf,
    n_rows: usize,
    n_bytes: u64,
    last_t_secs: f64,
    full: bool,
}

impl Recorder {
    /// Creates (or replaces) `path` and writes the header.
    pub fn create(path: &Path) -> std::io::Result<Recorder> {
        const HEADER: &[u8] = b"t,x,y,z,button\n";
        let mut out = BufWriter::new(File::create(path)?);
        out.write_all(HEADER)?;
        Ok(Recorder {
            out,
            path: path.into(),
            n_rows: 0,
            n_bytes: HEADER.len() as u64,
            last_t_secs: f64::NEG_INFINITY,
            full: false,
        })
    }

    /// Appends the tool at `t_secs` (seconds since recording began). Rows whose time does not
    /// increase, or that are not finite, are skipped; past the path's limits nothing more is
    /// written. Returns whether there is room for more.
    pub fn push(&mut self, t_secs: f64, hip: DVec3, button: bool) -> std::io::Result<bool> {
        if self.full {
            return Ok(false);
        }
        let room = MAX_PATH_FILE_BYTES.saturating_sub(self.n_bytes);
        if self.n_rows >= MAX_PATH_ROWS
            || t_secs > MAX_PATH_DURATION_SECS
            || room < MAX_LINE_BYTES as u64
        {
            self.full = true;
            return Ok(false);
        }
        if !(t_secs > self.last_t_secs && t_secs.is_finite() && hip.is_finite()) {
            return Ok(true);
        }
        let row = format!(
            "{t_secs},{},{},{},{}\n",
            hip.x,
            hip.y,
            hip.z,
            u8::from(button)
        );
        self.out.write_all(row.as_bytes())?;
        self.n_bytes += row.len() as u64;
        self.last_t_secs = t_secs;
        self.n_rows += 1;
        Ok(true)
    }

    /// Rows written so far.
    pub fn n_rows(&self) -> usize {
        self.n_rows
    }

    /// Whether a limit stopped the recording.
    pub fn is_full(&self) -> bool {
        self.full
    }

    /// Flushes and closes the file; returns its path and row count.
    pub fn finish(mut self) -> std::io::Result<(PathBuf, usize)> {
        self.out.flush()?;
        self.out.get_ref().sync_all()?;
        Ok((self.path, self.n_rows))
    }
}

/// One sample of the force plot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceSample {
    /// Seconds, on the caller's clock.
    pub t_secs: f64,
    /// The force's length, newtons.
    pub force_newtons: f64,
    /// The passivity observer's energy, joules.
    pub energy_joules: f64,
}

/// The last [`FORCE_HISTORY_SECS`] of force and energy, at most
/// [`MAX_FORCE_HISTORY_SAMPLES`] samples.
#[derive(Clone, Debug, Default)]
pub struct ForceHistory {
    samples: VecDeque<ForceSample>,
}

impl ForceHistory {
    /// Adds a sample and forgets what is older than the window.
    pub fn push(&mut self, sample: ForceSample) {
        if self.samples.len() == MAX_FORCE_HISTORY_SAMPLES {
            self.samples.pop_front();
        }
        self.samples.push_back(sample);
        while self
            .samples
            .front()
            .is_some_and(|s| s.t_secs < sample.t_secs - FORCE_HISTORY_SECS)
        {
            self.samples.pop_front();
        }
    }

    /// The samples, oldest first.
    pub fn samples(&self) -> impl Iterator<Item = &ForceSample> {
        self.samples.iter()
    }

    /// How many samples there are.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The largest force in the window, newtons (0 when empty).
    pub fn peak_newtons(&self) -> f64 {
        self.samples
            .iter()
            .map(|s| s.force_newtons)
            .fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::super::path::TouchPath;
    use super::*;

    #[test]
    fn a_recording_replays_as_a_touch_path_with_its_rows() {
        let dir = std::env::temp_dir().join(format!("sculpt-record-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("path.csv");
        let mut recorder = Recorder::create(&file).unwrap();
        let points = [
            (0.0, DVec3::new(0.0, 1.2, 0.0), false),
            (0.5, DVec3::new(0.1, 1.0, 0.0), true),
            // Time going back, and a non-finite point, are skipped.
            (0.4, DVec3::new(9.0, 9.0, 9.0), false),
            (0.6, DVec3::new(f64::NAN, 0.0, 0.0), false),
            (1.0, DVec3::new(0.2, 0.9, -0.1), false),
        ];
        for (t, p, b) in points {
            assert!(recorder.push(t, p, b).unwrap());
        }
        assert_eq!(recorder.n_rows(), 3);
        let (written, n_rows) = recorder.finish().unwrap();
        assert_eq!((written.as_path(), n_rows), (file.as_path(), 3));
        let text = std::fs::read_to_string(&file).unwrap();
        let path = TouchPath::parse(&text).unwrap();
        let mut cursor = 0;
        let at = path.at_tick(500, 0.001, &mut cursor);
        assert!((at.hip_scene - DVec3::new(0.1, 1.0, 0.0)).length() < 1e-12);
        assert_eq!(path.n_ticks(0.001), 1001);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_recording_stops_at_the_paths_duration_limit() {
        let dir = std::env::temp_dir().join(format!("sculpt-record-long-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut recorder = Recorder::create(&dir.join("long.csv")).unwrap();
        assert!(recorder.push(0.0, DVec3::ZERO, false).unwrap());
        assert!(
            !recorder
                .push(MAX_PATH_DURATION_SECS + 1.0, DVec3::ZERO, false)
                .unwrap()
        );
        assert!(recorder.is_full());
        assert!(!recorder.push(1.0, DVec3::ZERO, false).unwrap());
        assert_eq!(recorder.n_rows(), 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_force_history_keeps_its_window_and_its_bound() {
        let mut history = ForceHistory::default();
        for k in 0..20_000 {
            let t = f64::from(k) * 0.001;
            history.push(ForceSample {
                t_secs: t,
                force_newtons: t,
                energy_joules: 0.0,
            });
        }
        assert_eq!(history.len(), MAX_FORCE_HISTORY_SAMPLES);
        let mut sparse = ForceHistory::default();
        for k in 0..100 {
            sparse.push(ForceSample {
                t_secs: f64::from(k),
                force_newtons: 1.0,
                energy_joules: 0.0,
            });
        }
        assert_eq!(sparse.len(), 11, "samples from t = 89 to 99");
        assert_eq!(sparse.peak_newtons(), 1.0);
    }
}
