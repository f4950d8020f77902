//! Drives a simulated hand through the fdsl watermelon (`tests/data/models/watermelon.fdsl`):
//! approach, press through the rind (surface tension, then pop-through), move inside the
//! crunchy flesh (density), withdraw; and plots the force trace as a PNG: force magnitude and
//! per-axis components over time, the region shaded, markers where the stack changes.
//!
//! ```text
//! cargo run -p haptic --example force_trace -- [out.png]
//! ```

use std::path::Path;

use glam::DVec3;
use haptic::container::Aabb;
use haptic::device::Capabilities;
use haptic::device::sim::{HandModel, SimDevice, Waypoint};
use haptic::force::zone::HapticZone;
use haptic::force::{ForceParams, Region, Rig};
use haptic::servo::Servo;
use haptic::shapes::{FdslShapeError, fdsl_watermelon};
use tiny_skia::{
    Color, LineCap, LineJoin, Paint, PathBuilder, Pixmap, Rect, Stroke, StrokeDash, Transform,
};

const WATERMELON: &str = include_str!("../../tests/data/models/watermelon.fdsl");
const DT_SECS: f64 = 0.001;
const WIDTH: u32 = 1400;
const HEIGHT: u32 = 820;

/// One servo tick of the trace.
#[derive(Clone, Copy, Debug)]
pub struct TraceSample {
    /// Time, seconds.
    pub t_secs: f64,
    /// The force sent, newtons, device frame.
    pub force_newtons: DVec3,
    /// The region in the ruling container.
    pub region: Region,
    /// The ruling container.
    pub top_id: Option<u64>,
    /// How many containers the HIP is inside.
    pub stack_depth: usize,
}

/// Why the trace could not be made.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    /// The watermelon could not be built.
    #[error("watermelon: {0}")]
    Shape(#[from] FdslShapeError),
    /// The model text did not compile.
    #[error("{0}")]
    Compile(#[from] fdsl::CompileError),
    /// The simulated device rejected the script.
    #[error("device: {0}")]
    Device(#[from] haptic::device::sim::SimError),
    /// The canvas could not be made.
    #[error("cannot make a {WIDTH}x{HEIGHT} canvas")]
    Canvas,
    /// Writing the PNG failed.
    #[error("writing the PNG: {0}")]
    Png(String),
}

/// The hand's script in world units: down through the rind, across the flesh, back out.
fn script() -> Vec<(f64, DVec3)> {
    let at = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    vec![
        (0.0, at(-0.2, 1.25, -0.2)),
        (1.5, at(-0.2, 0.5, -0.2)),
        (1.7, at(-0.2, 0.5, -0.2)),
        (2.7, at(0.3, 0.45, -0.35)),
        (2.9, at(0.3, 0.45, -0.35)),
        (4.4, at(0.3, 1.3, -0.35)),
        (4.8, at(0.3, 1.3, -0.35)),
    ]
}

/// Runs the servo over the fdsl watermelon with the scripted hand.
pub fn watermelon_trace() -> Result<Vec<TraceSample>, TraceError> {
    let caps = Capabilities::desktop_pen();
    let world = Aabb::new(DVec3::splat(-1.6), DVec3::splat(1.6));
    let rig = Rig {
        caps,
        zone: HapticZone::fit(caps.workspace_metres, world),
        params: ForceParams::default(),
    };
    let geometry = fdsl::Function::parse(WATERMELON)?;
    let melon = vec![fdsl_watermelon(7, &geometry, DVec3::ZERO, 1.0)?];
    let script = script();
    let duration_secs = script.last().map_or(0.0, |w| w.0);
    let waypoints = script
        .into_iter()
        .map(|(t_secs, p)| Waypoint {
            t_secs,
            position_metres: p / rig.zone.world_per_device_metre,
        })
        .collect();
    let device = SimDevice::new(caps, waypoints, HandModel::default(), DT_SECS)?;
    let (mut servo, link) = Servo::init(device, rig);
    link.scenes.publish(Box::new(melon));
    let n_ticks = (duration_secs / DT_SECS) as usize;
    Ok((0..n_ticks)
        .map(|k| {
            let out = servo.step(DT_SECS);
            TraceSample {
                t_secs: (k + 1) as f64 * DT_SECS,
                force_newtons: out.force_newtons,
                region: out.region,
                top_id: out.top_id,
                stack_depth: servo.state().stack().entries().len(),
            }
        })
        .collect())
}

/// The trace cut into runs of equal (top container, region, stack depth): start index and key.
pub fn phases(trace: &[TraceSample]) -> Vec<(usize, Option<u64>, Region, usize)> {
    let mut out: Vec<(usize, Option<u64>, Region, usize)> = vec![];
    for (k, s) in trace.iter().enumerate() {
        let key = (s.top_id, s.region, s.stack_depth);
        if out
            .last()
            .is_none_or(|&(_, id, region, depth)| (id, region, depth) != key)
        {
            out.push((k, key.0, key.1, key.2));
        }
    }
    out
}

// ---- Plotting -------------------------------------------------------------------------

/// Strokes of a glyph on a 4 x 6 grid (y down): polylines separated by `|`, points `xy`.
fn glyph(c: char) -> &'static str {
    match c.to_ascii_uppercase() {
        '0' => "00 40 46 06 00",
        '1' => "11 20 26|06 46",
        '2' => "00 40 43 03 06 46",
        '3' => "00 40 46 06|03 43",
        '4' => "00 03 43|40 46",
        '5' => "40 00 03 43 46 06",
        '6' => "40 00 06 46 43 03",
        '7' => "00 40 26",
        '8' => "00 40 46 06 00|03 43",
        '9' => "43 03 00 40 46 06",
        'A' => "06 01 10 30 41 46|03 43",
        'B' => "00 30 41 42 33 03|33 44 45 36 06 00",
        'C' => "40 00 06 46",
        'D' => "00 30 41 45 36 06 00",
        'E' => "40 00 06 46|03 33",
        'F' => "40 00 06|03 33",
        'G' => "40 00 06 46 43 23",
        'H' => "00 06|40 46|03 43",
        'I' => "10 30|20 26|16 36",
        'K' => "00 06|40 03 46",
        'L' => "00 06 46",
        'M' => "06 00 23 40 46",
        'N' => "06 00 46 40",
        'O' => "00 40 46 06 00",
        'P' => "06 00 40 43 03",
        'R' => "06 00 40 43 03 46",
        'S' => "40 00 03 43 46 06",
        'T' => "00 40|20 26",
        'U' => "00 06 46 40",
        'V' => "00 26 40",
        'W' => "00 06 23 46 40",
        'X' => "00 46|40 06",
        'Y' => "00 23 40|23 26",
        'Z' => "00 40 06 46",
        '.' => "25 26",
        ',' => "25 16",
        '-' => "13 33",
        '+' => "13 33|22 24",
        ':' => "21 22|24 25",
        '/' => "06 40",
        '(' => "30 11 15 36",
        ')' => "10 31 35 16",
        '|' => "20 26",
        '=' => "02 42|04 44",
        ' ' => "",
        _ => "00 40 42 22 23|25 26",
    }
}

/// Draws `text` with its top-left corner at `(x, y)`, `size` pixels tall; rotated by 90 degrees
/// counter-clockwise when `vertical`.
fn text(pixmap: &mut Pixmap, s: &str, (x, y): (f32, f32), size: f32, color: Color, vertical: bool) {
    let unit = size / 6.0;
    let mut pb = PathBuilder::new();
    for (idx, c) in s.chars().enumerate() {
        let origin = idx as f32 * 6.0 * unit;
        for stroke in glyph(c).split('|') {
            let points: Vec<(f32, f32)> = stroke
                .split_whitespace()
                .filter_map(|p| {
                    let mut digits = p.chars().filter_map(|d| d.to_digit(10));
                    Some((digits.next()? as f32, digits.next()? as f32))
                })
                .collect();
            for (k, &(gx, gy)) in points.iter().enumerate() {
                let (px, py) = (origin + gx * unit, gy * unit);
                if k == 0 {
                    pb.move_to(px, py);
                } else {
                    pb.line_to(px, py);
                }
            }
            if points.len() == 1 {
                pb.line_to(origin + points[0].0 * unit + 0.1, points[0].1 * unit);
            }
        }
    }
    let Some(path) = pb.finish() else { return };
    let transform = if vertical {
        Transform::from_row(0.0, -1.0, 1.0, 0.0, x, y)
    } else {
        Transform::from_translate(x, y)
    };
    let stroke = Stroke {
        width: (size / 9.0).max(1.2),
        line_cap: LineCap::Round,
        line_join: LineJoin::Round,
        ..Stroke::default()
    };
    pixmap.stroke_path(&path, &paint(color), &stroke, transform, None);
}

fn text_width(s: &str, size: f32) -> f32 {
    s.chars().count() as f32 * size - size / 3.0
}

fn paint(color: Color) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color(color);
    p.anti_alias = true;
    p
}

fn rgb(r: u8, g: u8, b: u8) -> Color {
    Color::from_rgba8(r, g, b, 255)
}

fn line(pixmap: &mut Pixmap, points: &[(f32, f32)], color: Color, width: f32, dash: bool) {
    let mut pb = PathBuilder::new();
    for (k, &(x, y)) in points.iter().enumerate() {
        if k == 0 {
            pb.move_to(x, y);
        } else {
            pb.line_to(x, y);
        }
    }
    let Some(path) = pb.finish() else { return };
    let stroke = Stroke {
        width,
        line_join: LineJoin::Round,
        dash: if dash {
            StrokeDash::new(vec![8.0, 6.0], 0.0)
        } else {
            None
        },
        ..Stroke::default()
    };
    pixmap.stroke_path(&path, &paint(color), &stroke, Transform::identity(), None);
}

fn region_name(region: Region) -> &'static str {
    match region {
        Region::Free => "free",
        Region::Surface => "surface",
        Region::Interior => "interior",
    }
}

/// A plotted series: legend name, colour, line width, the value taken from the force.
type Series = (&'static str, Color, f32, fn(DVec3) -> f64);

/// The plot area in pixels: left, top, right, bottom.
const AREA: (f32, f32, f32, f32) = (100.0, 70.0, 1370.0, 690.0);

/// Plots the trace: |F| and Fx, Fy, Fz over time, regions shaded, stack changes marked.
pub fn plot(trace: &[TraceSample], path: &Path) -> Result<(), TraceError> {
    let mut pixmap = Pixmap::new(WIDTH, HEIGHT).ok_or(TraceError::Canvas)?;
    pixmap.fill(Color::WHITE);
    let (left, top, right, bottom) = AREA;
    let t_max = trace.last().map_or(1.0, |s| s.t_secs).max(1e-3);
    // Force axis: from the lowest component to the largest magnitude, in half newtons.
    let f_max = (trace
        .iter()
        .map(|s| s.force_newtons.length())
        .fold(0.5, f64::max)
        * 2.0)
        .ceil()
        / 2.0;
    let f_min = (trace
        .iter()
        .map(|s| s.force_newtons.min_element())
        .fold(0.0, f64::min)
        * 2.0)
        .floor()
        / 2.0;
    let x_of = |t: f64| left + (right - left) * (t / t_max) as f32;
    let y_of = |f: f64| bottom - (bottom - top) * ((f - f_min) / (f_max - f_min)) as f32;
    let phases = phases(trace);
    // Region bands.
    for (k, &(start, _, region, _)) in phases.iter().enumerate() {
        let end = phases.get(k + 1).map_or(trace.len(), |p| p.0);
        let color = match region {
            Region::Free => continue,
            Region::Surface => Color::from_rgba8(255, 214, 102, 70),
            Region::Interior => Color::from_rgba8(120, 200, 120, 55),
        };
        let (x0, x1) = (
            x_of(trace[start].t_secs - DT_SECS),
            x_of(trace[end - 1].t_secs),
        );
        if let Some(rect) = Rect::from_ltrb(x0, top, x1.max(x0 + 1.0), bottom) {
            pixmap.fill_rect(rect, &paint(color), Transform::identity(), None);
        }
    }
    // Grid, ticks and tick labels.
    let grey = rgb(215, 215, 215);
    let ink = rgb(30, 30, 30);
    let t_step = if t_max > 2.0 { 0.5 } else { 0.25 };
    let mut t = 0.0;
    while t <= t_max + 1e-9 {
        line(
            &mut pixmap,
            &[(x_of(t), top), (x_of(t), bottom)],
            grey,
            1.0,
            false,
        );
        line(
            &mut pixmap,
            &[(x_of(t), bottom), (x_of(t), bottom + 8.0)],
            ink,
            1.5,
            false,
        );
        let label = format!("{t:.1}");
        text(
            &mut pixmap,
            &label,
            (x_of(t) - text_width(&label, 14.0) / 2.0, bottom + 14.0),
            14.0,
            ink,
            false,
        );
        t += t_step;
    }
    let f_step = 0.5;
    let mut f = f_min;
    while f <= f_max + 1e-9 {
        let color = if f.abs() < 1e-9 {
            rgb(120, 120, 120)
        } else {
            grey
        };
        line(
            &mut pixmap,
            &[(left, y_of(f)), (right, y_of(f))],
            color,
            1.0,
            false,
        );
        line(
            &mut pixmap,
            &[(left - 8.0, y_of(f)), (left, y_of(f))],
            ink,
            1.5,
            false,
        );
        let label = format!("{f:.1}");
        text(
            &mut pixmap,
            &label,
            (left - 14.0 - text_width(&label, 14.0), y_of(f) - 7.0),
            14.0,
            ink,
            false,
        );
        f += f_step;
    }
    // Stack-change markers, labelled unless too close to the previous label.
    let mut last_label_x = f32::NEG_INFINITY;
    for &(start, id, region, _) in phases.iter().skip(1) {
        let x = x_of(trace[start].t_secs);
        line(
            &mut pixmap,
            &[(x, top), (x, bottom)],
            rgb(90, 90, 160),
            1.5,
            true,
        );
        if x - last_label_x < 20.0 {
            continue;
        }
        last_label_x = x;
        let label = match id {
            Some(id) => format!("{id}: {}", region_name(region)),
            None => "free".to_string(),
        };
        let at = (x + 4.0, top + 8.0 + text_width(&label, 13.0));
        text(&mut pixmap, &label, at, 13.0, rgb(60, 60, 140), true);
    }
    // Series: the magnitude wide and grey underneath, components on top.
    let series: [Series; 4] = [
        ("|f|", rgb(110, 110, 110), 4.0, |f| f.length()),
        ("fx", rgb(214, 39, 40), 1.8, |f| f.x),
        ("fy", rgb(44, 160, 44), 1.8, |f| f.y),
        ("fz", rgb(31, 119, 180), 1.8, |f| f.z),
    ];
    for &(_, color, width, component) in &series {
        let points: Vec<(f32, f32)> = trace
            .iter()
            .map(|s| (x_of(s.t_secs), y_of(component(s.force_newtons))))
            .collect();
        line(&mut pixmap, &points, color, width, false);
    }
    // Frame, title, axis labels, legend (two rows).
    let frame = [
        (left, top),
        (right, top),
        (right, bottom),
        (left, bottom),
        (left, top),
    ];
    line(&mut pixmap, &frame, ink, 1.5, false);
    let title = "watermelon force trace (fdsl container, simulated hand)";
    text(&mut pixmap, title, (left, 30.0), 20.0, ink, false);
    let x_label = "time (s)";
    let at = (
        (left + right) / 2.0 - text_width(x_label, 16.0) / 2.0,
        bottom + 40.0,
    );
    text(&mut pixmap, x_label, at, 16.0, ink, false);
    let y_label = "force (n)";
    let at = (14.0, (top + bottom) / 2.0 + text_width(y_label, 16.0) / 2.0);
    text(&mut pixmap, y_label, at, 16.0, ink, true);
    let mut legend_x = left;
    let row = bottom + 68.0;
    for &(name, color, width, _) in &series {
        let sample = [(legend_x, row + 7.0), (legend_x + 40.0, row + 7.0)];
        line(&mut pixmap, &sample, color, width, false);
        text(&mut pixmap, name, (legend_x + 50.0, row), 14.0, ink, false);
        legend_x += 130.0;
    }
    let mut legend_x = left;
    let row = row + 26.0;
    for (name, color) in [
        (
            "surface zone (tension)",
            Color::from_rgba8(255, 214, 102, 140),
        ),
        ("interior (density)", Color::from_rgba8(120, 200, 120, 120)),
    ] {
        if let Some(rect) = Rect::from_xywh(legend_x, row, 40.0, 14.0) {
            pixmap.fill_rect(rect, &paint(color), Transform::identity(), None);
        }
        text(&mut pixmap, name, (legend_x + 50.0, row), 14.0, ink, false);
        legend_x += 80.0 + text_width(name, 14.0);
    }
    let sample = [(legend_x, row + 7.0), (legend_x + 40.0, row + 7.0)];
    line(&mut pixmap, &sample, rgb(90, 90, 160), 1.5, true);
    let name = "stack change (container: region)";
    text(&mut pixmap, name, (legend_x + 50.0, row), 14.0, ink, false);
    pixmap
        .save_png(path)
        .map_err(|e| TraceError::Png(e.to_string()))
}

fn main() -> Result<(), TraceError> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "force_trace.png".to_string());
    let trace = watermelon_trace()?;
    plot(&trace, Path::new(&out))?;
    for (start, id, region, depth) in phases(&trace) {
        println!(
            "{:>6.3} s  top {id:?}  {}  stack depth {depth}",
            trace[start].t_secs,
            region_name(region)
        );
    }
    println!("wrote {out}");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trace_has_the_expected_phases_and_the_png_is_written() {
        let trace = watermelon_trace().unwrap();
        let keys: Vec<(Option<u64>, Region)> = phases(&trace)
            .iter()
            .map(|&(_, id, region, _)| (id, region))
            .collect();
        let (free, rind, flesh) = (
            (None, Region::Free),
            (Some(7), Region::Surface),
            (Some(7), Region::Interior),
        );
        assert_eq!(
            keys[..4],
            [free, rind, flesh, rind],
            "approach, rind, flesh, rind"
        );
        // On the way out the tip may bounce on the rind (the hand is a spring), but it never
        // pops back into the flesh, and it ends free.
        assert!(
            keys[4..].iter().all(|&k| k == free || k == rind),
            "{keys:?}"
        );
        assert_eq!(keys.last(), Some(&free));
        // The membrane held before popping, then the flesh resisted the motion.
        let phase = phases(&trace);
        let rind_peak = trace[phase[1].0..phase[2].0]
            .iter()
            .map(|s| s.force_newtons.length())
            .fold(0.0, f64::max);
        assert!(rind_peak > 1.5, "{rind_peak}");
        let flesh_mean = trace[phase[2].0 + 100..phase[3].0]
            .iter()
            .map(|s| s.force_newtons.length())
            .sum::<f64>()
            / (phase[3].0 - phase[2].0 - 100) as f64;
        assert!((0.02..0.5).contains(&flesh_mean), "{flesh_mean}");
        let path =
            std::env::temp_dir().join(format!("force_trace_test_{}.png", std::process::id()));
        plot(&trace, &path).unwrap();
        let png = Pixmap::load_png(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!((png.width(), png.height()), (WIDTH, HEIGHT));
        // Each series left its colour on the canvas.
        let count = |r: u8, g: u8, b: u8| {
            png.pixels()
                .iter()
                .filter(|p| p.alpha() == 255 && (p.red(), p.green(), p.blue()) == (r, g, b))
                .count()
        };
        for (name, (r, g, b)) in [
            ("fx", (214, 39, 40)),
            ("fy", (44, 160, 44)),
            ("fz", (31, 119, 180)),
        ] {
            assert!(count(r, g, b) > 200, "{name} drawn: {}", count(r, g, b));
        }
    }
}
