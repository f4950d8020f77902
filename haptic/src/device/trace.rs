//! Recording and replaying device traces: a line-based text format with validation.
//!
//! ```text
//! sculpt-haptic-trace 1
//! caps <dof_in> <dof_out> <force_max> <stiffness_max> <damping_max> <ws_min xyz> <ws_max xyz> <n_buttons> [<resolution>]
//! s <timestamp_micros> <px> <py> <pz> <qx> <qy> <qz> <qw> <buttons>
//! f <fx> <fy> <fz>
//! ```
//! Lines starting with `#` and blank lines are ignored. A bad file is an error naming the line.
//! The position resolution (metres) was added later: a `caps` line without it reads as 0,
//! unknown.

use std::fmt::Write as _;

use glam::{DQuat, DVec3};

use super::{Capabilities, DeviceError, DeviceSample, HapticDevice};
use crate::aabb::Aabb;

/// The first line of every trace.
pub const TRACE_HEADER: &str = "sculpt-haptic-trace 1";
/// The most lines a trace file may have.
pub const MAX_TRACE_LINES: usize = 10_000_000;
/// The longest line accepted, in bytes.
pub const MAX_TRACE_LINE_BYTES: usize = 512;

/// One recorded event.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TraceEvent {
    /// A device sample.
    Sample(DeviceSample),
    /// A force sent to the device, newtons.
    Force(DVec3),
}

/// A recorded session: the device's capabilities and its events in order.
#[derive(Clone, Debug, PartialEq)]
pub struct Trace {
    /// The capabilities of the recorded device.
    pub caps: Capabilities,
    /// Samples and forces, in the order they happened.
    pub events: Vec<TraceEvent>,
}

/// What is wrong with a trace line.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum TraceErrorKind {
    /// The first line is not [`TRACE_HEADER`].
    #[error("expected header `{TRACE_HEADER}`")]
    BadHeader,
    /// The `caps` line is missing or repeated.
    #[error("expected exactly one `caps` line before any event")]
    BadCaps,
    /// The record type is unknown.
    #[error("unknown record `{0}`")]
    UnknownRecord(String),
    /// The record has the wrong number of fields.
    #[error("expected {expected} fields, found {found}")]
    FieldCount {
        /// Fields the record type needs.
        expected: usize,
        /// Fields found.
        found: usize,
    },
    /// A field is not a number of the right kind.
    #[error("field {0} is not a valid number")]
    BadNumber(usize),
    /// A number is NaN or infinite.
    #[error("field {0} is not finite")]
    NotFinite(usize),
    /// Sample timestamps go backwards.
    #[error("timestamp goes backwards")]
    TimestampBackwards,
    /// A limit was exceeded.
    #[error(
        "line longer than {MAX_TRACE_LINE_BYTES} bytes or file longer than {MAX_TRACE_LINES} lines"
    )]
    TooLarge,
}

/// A trace that could not be parsed, with the 1-based line number.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
#[error("trace line {line}: {kind}")]
pub struct TraceError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong.
    pub kind: TraceErrorKind,
}

impl Trace {
    /// Writes the trace in the text format.
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let c = &self.caps;
        let (lo, hi) = (c.workspace_metres.min, c.workspace_metres.max);
        // Writing to a String cannot fail.
        let _ = writeln!(out, "{TRACE_HEADER}");
        let _ = writeln!(
            out,
            "caps {} {} {} {} {} {} {} {} {} {} {} {} {}",
            c.n_dof_input,
            c.n_dof_output,
            c.force_newtons_max,
            c.stiffness_newtons_per_metre_max,
            c.damping_newton_secs_per_metre_max,
            lo.x,
            lo.y,
            lo.z,
            hi.x,
            hi.y,
            hi.z,
            c.n_buttons,
            c.position_resolution_metres
        );
        for event in &self.events {
            let _ = match event {
                TraceEvent::Sample(s) => {
                    let (p, q) = (s.position_metres, s.orientation);
                    writeln!(
                        out,
                        "s {} {} {} {} {} {} {} {} {}",
                        s.timestamp_micros, p.x, p.y, p.z, q.x, q.y, q.z, q.w, s.buttons
                    )
                }
                TraceEvent::Force(f) => writeln!(out, "f {} {} {}", f.x, f.y, f.z),
            };
        }
        out
    }

    /// Parses the text format; every problem is an error naming its line, never a panic.
    pub fn parse(text: &str) -> Result<Self, TraceError> {
        let mut caps = None;
        let mut events = Vec::new();
        let mut header_seen = false;
        let mut last_timestamp = 0u64;
        for (line_idx, raw) in text.lines().enumerate() {
            let line = line_idx + 1;
            let err = |kind| TraceError { line, kind };
            if line > MAX_TRACE_LINES || raw.len() > MAX_TRACE_LINE_BYTES {
                return Err(err(TraceErrorKind::TooLarge));
            }
            let trimmed = raw.trim();
            if !header_seen {
                if trimmed != TRACE_HEADER {
                    return Err(err(TraceErrorKind::BadHeader));
                }
                header_seen = true;
                continue;
            }
            if trimmed.is_empty() || trimmed.starts_with('#') {
                continue;
            }
            let mut fields = trimmed.split_ascii_whitespace();
            let record = fields.next().unwrap_or_default();
            let rest: Vec<&str> = fields.collect();
            match record {
                "caps" if caps.is_none() && events.is_empty() => {
                    caps = Some(parse_caps(&rest).map_err(err)?);
                }
                "caps" => return Err(err(TraceErrorKind::BadCaps)),
                _ if caps.is_none() => return Err(err(TraceErrorKind::BadCaps)),
                "s" => {
                    let sample = parse_sample(&rest).map_err(err)?;
                    if sample.timestamp_micros < last_timestamp {
                        return Err(err(TraceErrorKind::TimestampBackwards));
                    }
                    last_timestamp = sample.timestamp_micros;
                    events.push(TraceEvent::Sample(sample));
                }
                "f" => {
                    let v = floats::<3>(&rest, 0).map_err(err)?;
                    events.push(TraceEvent::Force(DVec3::from_array(v)));
                }
                other => return Err(err(TraceErrorKind::UnknownRecord(other.to_owned()))),
            }
        }
        let end = text.lines().count() + 1;
        let caps = caps.ok_or(TraceError {
            line: end,
            kind: if header_seen {
                TraceErrorKind::BadCaps
            } else {
                TraceErrorKind::BadHeader
            },
        })?;
        Ok(Self { caps, events })
    }

    /// The samples of the trace, in order.
    pub fn samples(&self) -> impl Iterator<Item = &DeviceSample> {
        self.events.iter().filter_map(|e| match e {
            TraceEvent::Sample(s) => Some(s),
            TraceEvent::Force(_) => None,
        })
    }
}

fn field_count(fields: &[&str], expected: usize) -> Result<(), TraceErrorKind> {
    if fields.len() == expected {
        Ok(())
    } else {
        Err(TraceErrorKind::FieldCount {
            expected,
            found: fields.len(),
        })
    }
}

fn floats<const N: usize>(fields: &[&str], first: usize) -> Result<[f64; N], TraceErrorKind> {
    if first == 0 {
        field_count(fields, N)?;
    }
    let mut out = [0.0; N];
    for (k, slot) in out.iter_mut().enumerate() {
        let idx = first + k;
        let text = fields.get(idx).ok_or(TraceErrorKind::BadNumber(idx + 1))?;
        let v: f64 = text
            .parse()
            .map_err(|_| TraceErrorKind::BadNumber(idx + 1))?;
        if !v.is_finite() {
            return Err(TraceErrorKind::NotFinite(idx + 1));
        }
        *slot = v;
    }
    Ok(out)
}

fn integer<T: std::str::FromStr>(fields: &[&str], idx: usize) -> Result<T, TraceErrorKind> {
    let text = fields.get(idx).ok_or(TraceErrorKind::BadNumber(idx + 1))?;
    text.parse().map_err(|_| TraceErrorKind::BadNumber(idx + 1))
}

fn parse_caps(fields: &[&str]) -> Result<Capabilities, TraceErrorKind> {
    let resolution = match fields.len() {
        13 => floats::<1>(fields, 12)?[0],
        _ => {
            field_count(fields, 12)?;
            0.0
        }
    };
    if resolution < 0.0 {
        return Err(TraceErrorKind::BadNumber(13));
    }
    let limits = floats::<3>(fields, 2)?;
    let ws = floats::<6>(fields, 5)?;
    let (lo, hi) = (
        DVec3::new(ws[0], ws[1], ws[2]),
        DVec3::new(ws[3], ws[4], ws[5]),
    );
    if !lo.cmple(hi).all() || limits.iter().any(|&v| v < 0.0) {
        return Err(TraceErrorKind::BadNumber(6));
    }
    Ok(Capabilities {
        n_dof_input: integer(fields, 0)?,
        n_dof_output: integer(fields, 1)?,
        force_newtons_max: limits[0],
        stiffness_newtons_per_metre_max: limits[1],
        damping_newton_secs_per_metre_max: limits[2],
        workspace_metres: Aabb::new(lo, hi),
        n_buttons: integer(fields, 11)?,
        position_resolution_metres: resolution,
    })
}

fn parse_sample(fields: &[&str]) -> Result<DeviceSample, TraceErrorKind> {
    field_count(fields, 9)?;
    let v = floats::<7>(fields, 1)?;
    let q = DQuat::from_xyzw(v[3], v[4], v[5], v[6]);
    Ok(DeviceSample {
        timestamp_micros: integer(fields, 0)?,
        position_metres: DVec3::new(v[0], v[1], v[2]),
        orientation: if q.length_squared() > 0.0 {
            q.normalize()
        } else {
            DQuat::IDENTITY
        },
        buttons: integer(fields, 8)?,
    })
}

/// Wraps a device and records its samples and commanded forces, up to a fixed capacity
/// reserved up front (recording never allocates in the servo loop).
#[derive(Debug)]
pub struct Recorder<D> {
    device: D,
    trace: Trace,
    capacity: usize,
    n_dropped: u64,
}

impl<D: HapticDevice> Recorder<D> {
    /// Records up to `capacity` events of `device`.
    pub fn new(device: D, capacity: usize) -> Self {
        let caps = *device.capabilities();
        Self {
            device,
            trace: Trace {
                caps,
                events: Vec::with_capacity(capacity),
            },
            capacity,
            n_dropped: 0,
        }
    }

    /// The trace so far.
    pub fn trace(&self) -> &Trace {
        &self.trace
    }

    /// Events not recorded because the capacity was reached.
    pub fn n_dropped(&self) -> u64 {
        self.n_dropped
    }

    /// Gives back the device and the trace.
    pub fn into_parts(self) -> (D, Trace) {
        (self.device, self.trace)
    }

    fn record(&mut self, event: TraceEvent) {
        if self.trace.events.len() < self.capacity {
            self.trace.events.push(event);
        } else {
            self.n_dropped += 1;
        }
    }
}

impl<D: HapticDevice> HapticDevice for Recorder<D> {
    fn capabilities(&self) -> &Capabilities {
        self.device.capabilities()
    }
    fn sample(&mut self) -> Result<DeviceSample, DeviceError> {
        let sample = self.device.sample()?;
        self.record(TraceEvent::Sample(sample));
        Ok(sample)
    }
    fn set_force(&mut self, force_newtons: DVec3) -> Result<(), DeviceError> {
        self.device.set_force(force_newtons)?;
        self.record(TraceEvent::Force(force_newtons));
        Ok(())
    }
}

/// Replays the samples of a trace and keeps the forces it is sent, for comparison with the
/// forces recorded in the trace.
#[derive(Debug)]
pub struct TraceDevice {
    caps: Capabilities,
    samples: Vec<DeviceSample>,
    next_idx: usize,
    forces_newtons: Vec<DVec3>,
}

impl TraceDevice {
    /// A device replaying `trace`.
    pub fn new(trace: &Trace) -> Self {
        let samples: Vec<DeviceSample> = trace.samples().copied().collect();
        let n = samples.len();
        Self {
            caps: trace.caps,
            samples,
            next_idx: 0,
            forces_newtons: Vec::with_capacity(n),
        }
    }

    /// The forces received so far.
    pub fn forces_newtons(&self) -> &[DVec3] {
        &self.forces_newtons
    }
}

impl HapticDevice for TraceDevice {
    fn capabilities(&self) -> &Capabilities {
        &self.caps
    }
    fn sample(&mut self) -> Result<DeviceSample, DeviceError> {
        let sample = *self
            .samples
            .get(self.next_idx)
            .ok_or(DeviceError::Disconnected)?;
        self.next_idx += 1;
        Ok(sample)
    }
    fn set_force(&mut self, force_newtons: DVec3) -> Result<(), DeviceError> {
        if self.forces_newtons.len() < self.forces_newtons.capacity() {
            self.forces_newtons.push(force_newtons);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::sim::{HandModel, SimDevice, Waypoint};

    fn recorded() -> Trace {
        let waypoints = vec![
            Waypoint {
                t_secs: 0.0,
                position_metres: DVec3::ZERO,
            },
            Waypoint {
                t_secs: 0.02,
                position_metres: DVec3::new(0.01, -0.02, 0.003),
            },
        ];
        let dev = SimDevice::new(
            Capabilities::desktop_pen(),
            waypoints,
            HandModel::default(),
            0.001,
        )
        .unwrap();
        let mut rec = Recorder::new(dev, 30);
        for k in 0..20 {
            rec.sample().unwrap();
            rec.set_force(DVec3::new(0.1 * k as f64, 0.0, -0.25))
                .unwrap();
        }
        assert_eq!(rec.n_dropped(), 10);
        rec.into_parts().1
    }

    #[test]
    fn round_trips_through_text_exactly() {
        let trace = recorded();
        assert_eq!(trace.events.len(), 30);
        let parsed = Trace::parse(&trace.to_text()).unwrap();
        assert_eq!(parsed, trace);
        let mut replay = TraceDevice::new(&parsed);
        let originals: Vec<_> = trace.samples().copied().collect();
        for original in &originals {
            assert_eq!(replay.sample().unwrap(), *original);
            replay.set_force(DVec3::X).unwrap();
        }
        assert_eq!(replay.sample(), Err(DeviceError::Disconnected));
        assert_eq!(replay.forces_newtons().len(), originals.len());
    }

    fn error_of(text: &str) -> TraceError {
        Trace::parse(text).unwrap_err()
    }

    #[test]
    fn bad_files_name_the_line() {
        let good = recorded().to_text();
        let lines: Vec<&str> = good.lines().collect();
        let with = |idx: usize, replacement: &str| {
            let mut v = lines.clone();
            v[idx] = replacement;
            v.join("\n")
        };
        assert_eq!(error_of("hello").kind, TraceErrorKind::BadHeader);
        assert_eq!(error_of("").kind, TraceErrorKind::BadHeader);
        assert_eq!(error_of(TRACE_HEADER).line, 2);
        let e = error_of(&with(3, "s 1 2 3"));
        assert_eq!(
            (e.line, e.kind),
            (
                4,
                TraceErrorKind::FieldCount {
                    expected: 9,
                    found: 3
                }
            )
        );
        let e = error_of(&with(4, "f 1 nan 2"));
        assert_eq!((e.line, e.kind), (5, TraceErrorKind::NotFinite(2)));
        let e = error_of(&with(4, "f 1 x 2"));
        assert_eq!((e.line, e.kind), (5, TraceErrorKind::BadNumber(2)));
        let e = error_of(&with(2, "s 99999999 0 0 0 0 0 0 1 0"));
        // The sample after the far-future one is the one that goes backwards.
        assert_eq!((e.line, e.kind), (5, TraceErrorKind::TimestampBackwards));
        let e = error_of(&with(5, "zap 1"));
        assert_eq!(e.line, 6);
        assert!(matches!(e.kind, TraceErrorKind::UnknownRecord(_)));
        let e = error_of(&with(6, "caps 3 3 1 1 1 0 0 0 1 1 1 2"));
        assert_eq!((e.line, e.kind), (7, TraceErrorKind::BadCaps));
        let e = error_of(&with(1, "caps 3 3 1 1 1 0 0 0 -1 1 1 2"));
        assert_eq!(e.line, 2);
        let long = "#".repeat(MAX_TRACE_LINE_BYTES + 1);
        assert_eq!(error_of(&with(3, &long)).kind, TraceErrorKind::TooLarge);
    }

    #[test]
    fn a_caps_line_without_the_resolution_reads_as_unknown() {
        let trace = recorded();
        assert_eq!(
            trace.caps.position_resolution_metres,
            Capabilities::desktop_pen().position_resolution_metres
        );
        let text = trace.to_text();
        let lines: Vec<&str> = text.lines().collect();
        let old_caps: Vec<&str> = lines[1].split(' ').take(13).collect();
        let mut old = lines.clone();
        let old_line = old_caps.join(" ");
        old[1] = &old_line;
        let parsed = Trace::parse(&old.join("\n")).unwrap();
        assert_eq!(parsed.caps.position_resolution_metres, 0.0);
        assert_eq!(parsed.events, trace.events);
        let negative = format!("{old_line} -1");
        old[1] = &negative;
        let e = error_of(&old.join("\n"));
        assert_eq!((e.line, e.kind), (2, TraceErrorKind::BadNumber(13)));
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        // A deterministic scramble of a good trace: every prefix and many byte flips.
        let good = recorded().to_text();
        let bytes = good.as_bytes();
        for cut in (0..bytes.len()).step_by(7) {
            let _ = Trace::parse(&String::from_utf8_lossy(&bytes[..cut]));
        }
        let mut state = 0x9e37_79b9_u32;
        for _ in 0..500 {
            let mut b = bytes.to_vec();
            for _ in 0..4 {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let idx = state as usize % b.len();
                b[idx] = (state >> 24) as u8;
            }
            let _ = Trace::parse(&String::from_utf8_lossy(&b));
        }
    }
}
