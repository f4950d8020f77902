//! A run's report as pictures (PNG, drawn with the `plot` crate): convergence (ops each peer
//! lacks against the best-informed peer, over virtual time, with the moment of healing
//! marked), messages and bytes each peer sent, and heap bytes each peer held.

use std::path::{Path, PathBuf};

use plot::series::{LinePlot, Series};

use crate::report::{PeerSample, Report};

/// Picture width in pixels.
pub const PLOT_WIDTH_PX: u32 = 900;
/// Picture height in pixels.
pub const PLOT_HEIGHT_PX: u32 = 500;
/// Peers drawn one line each; beyond this a plot shows the mean and the maximum.
pub const MAX_PEER_LINES: usize = 12;

const PALETTE: [[f32; 4]; 12] = [
    [0.12, 0.47, 0.71, 1.0],
    [1.0, 0.50, 0.05, 1.0],
    [0.17, 0.63, 0.17, 1.0],
    [0.84, 0.15, 0.16, 1.0],
    [0.58, 0.40, 0.74, 1.0],
    [0.55, 0.34, 0.29, 1.0],
    [0.89, 0.47, 0.76, 1.0],
    [0.50, 0.50, 0.50, 1.0],
    [0.74, 0.74, 0.13, 1.0],
    [0.09, 0.75, 0.81, 1.0],
    [0.0, 0.0, 0.5, 1.0],
    [0.5, 0.0, 0.0, 1.0],
];
const HEAL_COLOUR: [f32; 4] = [0.0, 0.0, 0.0, 1.0];

/// Why the plots could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PlotsError {
    /// The directory could not be made.
    #[error("{0}: {1}")]
    Dir(PathBuf, std::io::Error),
    /// A plot could not be drawn.
    #[error("drawing {0}: {1}")]
    Draw(&'static str, plot::PlotError),
    /// A PNG could not be written.
    #[error("writing {0}: {1}")]
    Png(&'static str, plot::image::PngError),
}

/// Writes `convergence.png`, `messages.png`, `bytes.png` and (if memory was measured)
/// `memory.png` into `dir`; returns their paths.
pub fn write_plots(report: &Report, dir: &Path) -> Result<Vec<PathBuf>, PlotsError> {
    std::fs::create_dir_all(dir).map_err(|e| PlotsError::Dir(dir.to_path_buf(), e))?;
    let c = &report.config;
    let run = format!("SEED {} {} PEERS {}", c.seed, c.n_peers, c.faults.name);
    let mut plots = vec![
        (
            "convergence.png",
            plot(
                report,
                format!("OPS MISSING PER PEER ({run})"),
                "OPS",
                missing_ops,
            ),
        ),
        (
            "messages.png",
            plot(
                report,
                format!("MESSAGES SENT ({run})"),
                "MESSAGES",
                |s, _| s.n_messages_sent as f64,
            ),
        ),
        (
            "bytes.png",
            plot(report, format!("BYTES SENT ({run})"), "KIB", |s, _| {
                s.n_bytes_sent as f64 / 1024.0
            }),
        ),
    ];
    if report.memory.is_some() {
        plots.push((
            "memory.png",
            plot(
                report,
                format!("HEAP HELD PER PEER ({run})"),
                "KIB",
                |s, _| s.live_bytes as f64 / 1024.0,
            ),
        ));
    }
    let mut paths = Vec::new();
    for (name, line_plot) in plots {
        let picture = line_plot
            .render(PLOT_WIDTH_PX, PLOT_HEIGHT_PX)
            .map_err(|e| PlotsError::Draw(name, e))?;
        let path = dir.join(name);
        picture
            .image
            .save_png(&path)
            .map_err(|e| PlotsError::Png(name, e))?;
        paths.push(path);
    }
    Ok(paths)
}

/// Ops a peer lacks against the best-informed peer at that moment.
fn missing_ops(s: &PeerSample, all: &[PeerSample]) -> f64 {
    let best = all.iter().map(|p| p.n_ops_held).max().unwrap_or(0);
    (best - s.n_ops_held) as f64
}

/// A plot of `value` per peer over virtual seconds, with a vertical line at healing.
fn plot(
    report: &Report,
    title: String,
    y_label: &str,
    value: impl Fn(&PeerSample, &[PeerSample]) -> f64,
) -> LinePlot {
    let n_peers = report.samples.first().map_or(0, |s| s.peers.len());
    let t = |at_micros: u64| at_micros as f64 / 1e6;
    let mut series = Vec::new();
    let mut y_max: f64 = 0.0;
    if n_peers <= MAX_PEER_LINES {
        for p in 0..n_peers {
            let points: Vec<[f64; 2]> = report
                .samples
                .iter()
                .map(|s| [t(s.at_micros), value(&s.peers[p], &s.peers)])
                .collect();
            y_max = points.iter().map(|q| q[1]).fold(y_max, f64::max);
            series.push(Series {
                name: format!("PEER {p}"),
                colour: PALETTE[p % PALETTE.len()],
                points,
            });
        }
    } else {
        let (mut mean, mut max) = (Vec::new(), Vec::new());
        for s in &report.samples {
            let values: Vec<f64> = s.peers.iter().map(|p| value(p, &s.peers)).collect();
            let m = values.iter().copied().fold(0.0, f64::max);
            y_max = y_max.max(m);
            mean.push([
                t(s.at_micros),
                values.iter().sum::<f64>() / values.len() as f64,
            ]);
            max.push([t(s.at_micros), m]);
        }
        for (name, points, colour) in [("MEAN", mean, PALETTE[0]), ("MAX", max, PALETTE[3])] {
            series.push(Series {
                name: format!("{name} OF {n_peers} PEERS"),
                colour,
                points,
            });
        }
    }
    let heal = t(report.heal_micros);
    series.push(Series {
        name: "HEAL".into(),
        colour: HEAL_COLOUR,
        points: vec![[heal, 0.0], [heal, y_max.max(1.0)]],
    });
    LinePlot {
        title,
        x_label: "VIRTUAL TIME S".into(),
        y_label: y_label.into(),
        series,
        x_range: None,
        y_range: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Config, Faults};

    #[test]
    fn a_run_draws_its_plots_as_pngs() {
        let config = Config::new(3, 3, 30, Faults::named("wan").unwrap());
        let report = crate::sim::run(config).unwrap();
        assert!(report.samples.len() > 10, "{}", report.samples.len());
        let dir = std::env::temp_dir().join(format!("sculpt-sim-plots-{}", std::process::id()));
        let paths = write_plots(&report, &dir).unwrap();
        assert!(paths.len() >= 3);
        for path in &paths {
            let image = plot::image::RgbaImage::from_png(&std::fs::read(path).unwrap()).unwrap();
            assert_eq!((image.width, image.height), (PLOT_WIDTH_PX, PLOT_HEIGHT_PX));
            // Something besides the white background was drawn.
            assert!(image.pixels.chunks(4).any(|p| p[0] < 100));
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
