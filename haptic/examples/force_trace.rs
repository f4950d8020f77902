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
use haptic::aabb::Aabb;
use haptic::device::Capabilities;
use haptic::device::sim::{HandModel, SimDevice, Waypoint};
use haptic::force::zone::HapticZone;
use haptic::force::{ForceParams, Region, Rig};
use haptic::servo::Servo;
use haptic::shapes::{FdslShapeError, fdsl_watermelon};
use plot::font::{draw_text, text_width};
use plot::image::RgbaImage;
use plot::series::{LinePlot, Series};
use tiny_skia::{
    Color, IntSize, LineJoin, Mask, Paint, PathBuilder, Pixmap, PixmapPaint, Rect, Stroke,
    StrokeDash, Transform,
};

const WATERMELON: &str = include_str!("../../tests/data/models/watermelon.fdsl");
const DT_SECS: f64 = 0.001;
const WIDTH: u32 = 1100;
const HEIGHT: u32 = 640;

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
    /// The line plot could not be drawn.
    #[error("plot: {0}")]
    Plot(#[from] plot::PlotError),
    /// Writing the PNG failed.
    #[error("writing the PNG: {0}")]
    Png(#[from] plot::image::PngError),
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
//
// The axes, ticks, series and their legend are a `plot::series::LinePlot`. The plot crate
// has no region shading, dashed lines, per-series widths or vertical text, so those are drawn
// here over the finished picture with tiny-skia. Shading, the wide magnitude line and the
// markers paint only "paper" pixels (background, grid, light grey fringes; see `paper_mask`),
// so that they sit under the series as if drawn first. The font has no `|`, so the magnitude
// is named in words.

fn region_name(region: Region) -> &'static str {
    match region {
        Region::Free => "free",
        Region::Surface => "surface",
        Region::Interior => "interior",
    }
}

/// 8-bit colours of the series (the test looks for them on the canvas).
const MAGNITUDE_RGB: [u8; 3] = [100, 100, 100];
const FX_RGB: [u8; 3] = [214, 39, 40];
const FY_RGB: [u8; 3] = [44, 160, 44];
const FZ_RGB: [u8; 3] = [31, 119, 180];
/// Region shading, 8-bit RGBA.
const SURFACE_RGBA: [u8; 4] = [255, 214, 102, 90];
const INTERIOR_RGBA: [u8; 4] = [120, 200, 120, 70];
const MARKER_RGB: [u8; 3] = [90, 90, 160];
const INK_RGB: [u8; 3] = [20, 20, 20];
/// Cap height of the labels drawn here, pixels (the plot's own labels are 9).
const LABEL_PX: f32 = 10.0;
/// Width of the magnitude drawn under the components, pixels (the plot draws every series 2).
const MAGNITUDE_UNDERLAY_PX: f32 = 5.0;

/// An 8-bit colour as the plot's RGBA 0..1.
fn linear([r, g, b]: [u8; 3]) -> [f32; 4] {
    [
        f32::from(r) / 255.0,
        f32::from(g) / 255.0,
        f32::from(b) / 255.0,
        1.0,
    ]
}

fn paint([r, g, b, a]: [u8; 4]) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color(Color::from_rgba8(r, g, b, a));
    p.anti_alias = true;
    p
}

fn opaque([r, g, b]: [u8; 3]) -> [u8; 4] {
    [r, g, b, 255]
}

/// The line plot of |f| and its components over time; the force axis runs from the lowest
/// component to the largest magnitude, rounded out to half newtons.
fn line_plot(trace: &[TraceSample]) -> LinePlot {
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
    let t_max = trace.last().map_or(1.0, |s| s.t_secs).max(1e-3);
    let series = |name: &str, rgb: [u8; 3], value: fn(DVec3) -> f64| Series {
        name: name.to_owned(),
        colour: linear(rgb),
        points: trace
            .iter()
            .map(|s| [s.t_secs, value(s.force_newtons)])
            .collect(),
    };
    LinePlot {
        title: "watermelon force trace (fdsl container, simulated hand)".to_owned(),
        x_label: "time (s)".to_owned(),
        y_label: "force (N)".to_owned(),
        series: vec![
            series("magnitude", MAGNITUDE_RGB, DVec3::length),
            series("fx", FX_RGB, |f| f.x),
            series("fy", FY_RGB, |f| f.y),
            series("fz", FZ_RGB, |f| f.z),
        ],
        x_range: Some((0.0, t_max)),
        y_range: Some((f_min, f_max)),
    }
}

/// Plots the trace: |f| and fx, fy, fz over time, regions shaded, stack changes marked.
pub fn plot(trace: &[TraceSample], path: &Path) -> Result<(), TraceError> {
    let picture = line_plot(trace).render(WIDTH, HEIGHT)?;
    let size = IntSize::from_wh(WIDTH, HEIGHT).ok_or(TraceError::Canvas)?;
    // The plot is opaque, so its straight-alpha pixels are already premultiplied.
    let mut pixmap =
        Pixmap::from_vec(picture.image.pixels.clone(), size).ok_or(TraceError::Canvas)?;
    let paper = paper_mask(&pixmap).ok_or(TraceError::Canvas)?;
    let area = picture.area;
    let x_of = |t: f64| picture.data_to_pixel([t, 0.0])[0];
    let phases = phases(trace);
    for (k, &(start, _, region, _)) in phases.iter().enumerate() {
        let end = phases.get(k + 1).map_or(trace.len(), |p| p.0);
        let rgba = match region {
            Region::Free => continue,
            Region::Surface => SURFACE_RGBA,
            Region::Interior => INTERIOR_RGBA,
        };
        let (x0, x1) = (
            x_of(trace[start].t_secs - DT_SECS),
            x_of(trace[end - 1].t_secs),
        );
        if let Some(rect) = Rect::from_ltrb(x0, area.y, x1.max(x0 + 1.0), area.y + area.h) {
            pixmap.fill_rect(rect, &paint(rgba), Transform::identity(), Some(&paper));
        }
    }
    // The magnitude again, wide, under the components.
    let magnitude: Vec<[f32; 2]> = trace
        .iter()
        .map(|s| picture.data_to_pixel([s.t_secs, s.force_newtons.length()]))
        .collect();
    stroke(
        &mut pixmap,
        &magnitude,
        opaque(MAGNITUDE_RGB),
        MAGNITUDE_UNDERLAY_PX,
        None,
        Some(&paper),
    );
    // Stack changes: dashed lines, labelled unless too close to the previous label.
    let mut last_label_x = f32::NEG_INFINITY;
    for &(start, id, region, _) in phases.iter().skip(1) {
        let x = x_of(trace[start].t_secs);
        let dash = StrokeDash::new(vec![8.0, 6.0], 0.0);
        let marker = [[x, area.y], [x, area.y + area.h]];
        stroke(
            &mut pixmap,
            &marker,
            opaque(MARKER_RGB),
            1.5,
            dash,
            Some(&paper),
        );
        if x - last_label_x < 2.0 * LABEL_PX {
            continue;
        }
        last_label_x = x;
        let label = match id {
            Some(id) => format!("{id}: {}", region_name(region)),
            None => "free".to_owned(),
        };
        let bottom = area.y + 6.0 + text_width(&label, LABEL_PX);
        vertical_text(&mut pixmap, &label, x + 3.0, bottom, opaque(MARKER_RGB));
    }
    draw_key(&mut pixmap, area.x + 6.0, area.y + area.h - 6.0);
    Ok(RgbaImage::from_pixmap(&pixmap).save_png(path)?)
}

/// Where the picture is background, grid or the anti-aliased fringe of a grey line (neutral
/// and lighter than the magnitude's grey): what layers "under" the series may paint.
fn paper_mask(pixmap: &Pixmap) -> Option<Mask> {
    let mut mask = Mask::new(pixmap.width(), pixmap.height())?;
    for (m, p) in mask.data_mut().iter_mut().zip(pixmap.pixels()) {
        let (lo, hi) = (
            p.red().min(p.green()).min(p.blue()),
            p.red().max(p.green()).max(p.blue()),
        );
        *m = if lo > MAGNITUDE_RGB[0] + 10 && hi - lo <= 16 {
            255
        } else {
            0
        };
    }
    Some(mask)
}

fn stroke(
    pixmap: &mut Pixmap,
    points: &[[f32; 2]],
    rgba: [u8; 4],
    width: f32,
    dash: Option<StrokeDash>,
    mask: Option<&Mask>,
) {
    let mut pb = PathBuilder::new();
    for (k, &[x, y]) in points.iter().enumerate() {
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
        dash,
        ..Stroke::default()
    };
    pixmap.stroke_path(&path, &paint(rgba), &stroke, Transform::identity(), mask);
}

/// Draws `text` turned 90 degrees counter-clockwise, reading upwards from `(x, bottom)`.
fn vertical_text(pixmap: &mut Pixmap, text: &str, x: f32, bottom: f32, rgba: [u8; 4]) {
    let (w, h) = (text_width(text, LABEL_PX) + 4.0, LABEL_PX + 4.0);
    let Some(mut label) = Pixmap::new(w.ceil() as u32, h.ceil() as u32) else {
        return;
    };
    let [r, g, b, a] = rgba;
    draw_text(
        &mut label,
        text,
        2.0,
        2.0,
        LABEL_PX,
        Color::from_rgba8(r, g, b, a),
    );
    // (u, v) in the label goes to (x + v, bottom - u).
    let turn = Transform::from_row(0.0, -1.0, 1.0, 0.0, x - 2.0, bottom + 2.0);
    pixmap.draw_pixmap(0, 0, label.as_ref(), &PixmapPaint::default(), turn, None);
}

/// The key to what the line plot's legend does not show: shading and markers, in a box whose
/// lower-left corner is `(x, bottom)`.
fn draw_key(pixmap: &mut Pixmap, x: f32, bottom: f32) {
    let rows: [(&str, [u8; 4], bool); 3] = [
        ("surface zone (tension)", [255, 214, 102, 160], false),
        ("interior (density)", [120, 200, 120, 140], false),
        ("stack change (container: region)", opaque(MARKER_RGB), true),
    ];
    let row_px = LABEL_PX + 8.0;
    let name_px = rows
        .iter()
        .map(|r| text_width(r.0, LABEL_PX))
        .fold(0.0, f32::max);
    let (w, h) = (
        4.0 + 28.0 + 6.0 + name_px + 6.0,
        4.0 + rows.len() as f32 * row_px,
    );
    let top = bottom - h;
    if let Some(rect) = Rect::from_xywh(x, top, w, h) {
        pixmap.fill_rect(
            rect,
            &paint([255, 255, 255, 235]),
            Transform::identity(),
            None,
        );
        let frame = [
            [x, top],
            [x + w, top],
            [x + w, bottom],
            [x, bottom],
            [x, top],
        ];
        stroke(pixmap, &frame, [120, 120, 120, 255], 1.0, None, None);
    }
    for (i, &(name, rgba, dashed)) in rows.iter().enumerate() {
        let y = top + 4.0 + i as f32 * row_px;
        if dashed {
            let sample = [
                [x + 4.0, y + LABEL_PX / 2.0],
                [x + 32.0, y + LABEL_PX / 2.0],
            ];
            stroke(
                pixmap,
                &sample,
                rgba,
                1.5,
                StrokeDash::new(vec![8.0, 6.0], 0.0),
                None,
            );
        } else if let Some(rect) = Rect::from_xywh(x + 4.0, y, 28.0, LABEL_PX) {
            pixmap.fill_rect(rect, &paint(rgba), Transform::identity(), None);
        }
        let [r, g, b] = INK_RGB;
        draw_text(
            pixmap,
            name,
            x + 38.0,
            y,
            LABEL_PX,
            Color::from_rgba8(r, g, b, 255),
        );
    }
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
        let png = RgbaImage::from_png(&std::fs::read(&path).unwrap()).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!((png.width, png.height), (WIDTH, HEIGHT));
        // Each series left its colour on the canvas.
        let count = |rgb: [u8; 3]| {
            png.pixels
                .chunks_exact(4)
                .filter(|p| p[..] == opaque(rgb))
                .count()
        };
        for (name, rgb) in [("fx", FX_RGB), ("fy", FY_RGB), ("fz", FZ_RGB)] {
            assert!(count(rgb) > 200, "{name} drawn: {}", count(rgb));
        }
        // Both regions are shaded under the series: the interior band's tint shows at the
        // middle of the flesh phase, on the paper above the curves.
        let pic = line_plot(&trace).render(WIDTH, HEIGHT).unwrap();
        let [x, y] = pic.data_to_pixel([2.2, 2.3]);
        let p = png.pixel(x as u32, y as u32).unwrap();
        assert!(
            p[1] > p[0] + 20 && p[1] > p[2] + 20,
            "interior shading: {p:?}"
        );
    }
}
