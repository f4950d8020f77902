//! Sampled grids: volume data (a scan, a simulation) as a function of space.
//!
//! A [`Grid`] is a named box of 8-bit samples at regular spacing. A formula compiled with grids
//! in its [`crate::Options`] calls one by name, `head(x, y, z)`, and gets the samples
//! interpolated trilinearly: continuous everywhere, with exact gradients inside each cell and
//! exact bounds over any box (an interpolated value lies between the samples around it).
//! Outside the grid the coordinate is clamped to its faces, so the value continues the border
//! samples; a NaN coordinate gives NaN.
//!
//! Samples are bytes, so a grid of [`MAX_GRID_SAMPLES`] is 256 KiB on the wire (replication
//! authors an object that large in parts); `range` maps byte 0 and byte 255 to the values they stand for. Grids are read from raw bytes with a
//! declared size ([`Grid::from_raw`]) or from an NRRD file ([`Grid::from_nrrd`]), and every
//! constructor checks the limits, so a `Grid` is never invalid.

use std::hash::{Hash, Hasher};

use serde::{Deserialize, Serialize};

/// Most samples in one grid: a 64 x 64 x 64 grid, 256 KiB, so that an object's
/// [`MAX_GRIDS`] grids fit in one change authored in parts (4 MiB in replication).
pub const MAX_GRID_SAMPLES: usize = 64 * 64 * 64;
/// Most grids one formula may call (and one object may hold).
pub const MAX_GRIDS: usize = 8;
/// Longest grid name, in bytes.
pub const MAX_GRID_NAME_BYTES: usize = 32;
/// Longest NRRD header read, in bytes.
pub const MAX_NRRD_HEADER_BYTES: usize = 4096;
/// Most samples an interval evaluation scans for a box's bounds; over a larger block it takes
/// the whole grid's bounds (still true, looser).
const MAX_INTERVAL_SCAN: usize = 512;

/// Names a grid may not take: the coordinates and the language's own functions.
const RESERVED: &[&str] = &[
    "x", "y", "z", "t", "u", "v", "w", "pi", "e", "if", "else", "for", "while", "return",
    "function",
];

/// Why a grid was refused. Errors in NRRD headers name their line.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GridError {
    /// The name is not an identifier, is too long or is taken.
    #[error(
        "grid name `{0}` is not usable: it must be a letter or `_` then letters, digits or `_`, at most {MAX_GRID_NAME_BYTES} bytes, and not a coordinate or a function of the language"
    )]
    BadName(String),
    /// A side below 2 samples, or too many samples.
    #[error(
        "a grid of {0:?} samples is not allowed: each side needs 2 or more, and at most {MAX_GRID_SAMPLES} samples in all"
    )]
    BadSize([usize; 3]),
    /// The bytes do not match the size.
    #[error("the grid declares {expected} samples but {found} bytes were given")]
    WrongLength {
        /// Samples the size declares.
        expected: usize,
        /// Bytes given.
        found: usize,
    },
    /// A spacing that is not finite and positive, or an origin or range that is not finite.
    #[error("grid {what} must be finite{}", if *.what == "spacing" { " and positive" } else { "" })]
    BadNumber {
        /// `origin`, `spacing` or `range`.
        what: &'static str,
    },
    /// The NRRD header is malformed or asks for what we do not read.
    #[error("NRRD line {line}: {message}")]
    Nrrd {
        /// 1-based line of the header.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// A named 3D grid of byte samples, trilinearly interpolated.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(try_from = "GridData", into = "GridData")]
pub struct Grid {
    data: GridData,
    /// The smallest and largest sample.
    bytes_lo: u8,
    bytes_hi: u8,
}

/// A grid's plain fields, as encoded.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridData {
    /// What formulas call it.
    pub name: String,
    /// Samples along x, y and z.
    pub size: [u16; 3],
    /// Where sample (0, 0, 0) sits.
    pub origin: [f64; 3],
    /// The distance between samples along each axis.
    pub spacing: [f64; 3],
    /// The values bytes 0 and 255 stand for (linear in between).
    pub range: [f64; 2],
    /// `size[0] * size[1] * size[2]` bytes, x fastest, then y, then z.
    pub samples: Vec<u8>,
}

impl TryFrom<GridData> for Grid {
    type Error = GridError;
    fn try_from(data: GridData) -> Result<Grid, GridError> {
        Grid::new(data)
    }
}

impl From<Grid> for GridData {
    fn from(grid: Grid) -> GridData {
        grid.data
    }
}

impl PartialEq for Grid {
    fn eq(&self, other: &Grid) -> bool {
        self.key() == other.key()
    }
}

impl Eq for Grid {}

impl Grid {
    /// Every field, floats as bits: what equality, order and hashing compare.
    fn key(&self) -> (&str, [u16; 3], [u64; 8], &[u8]) {
        let d = &self.data;
        let bits = [
            d.origin[0],
            d.origin[1],
            d.origin[2],
            d.spacing[0],
            d.spacing[1],
            d.spacing[2],
            d.range[0],
            d.range[1],
        ]
        .map(f64::to_bits);
        (&d.name, d.size, bits, &d.samples)
    }
}

impl PartialOrd for Grid {
    fn partial_cmp(&self, other: &Grid) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Grid {
    fn cmp(&self, other: &Grid) -> std::cmp::Ordering {
        self.key().cmp(&other.key())
    }
}

impl Hash for Grid {
    fn hash<H: Hasher>(&self, state: &mut H) {
        self.key().hash(state);
    }
}

/// Whether `name` may name a grid: an identifier that is neither a coordinate nor a function
/// of the language.
pub fn is_usable_name(name: &str) -> bool {
    let mut chars = name.chars();
    let Some(first) = chars.next() else {
        return false;
    };
    name.len() <= MAX_GRID_NAME_BYTES
        && (first.is_ascii_alphabetic() || first == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !RESERVED.contains(&name)
        && !crate::builtins::is_builtin_function(name)
}

impl Grid {
    /// A grid from its fields, checked.
    pub fn new(data: GridData) -> Result<Grid, GridError> {
        if !is_usable_name(&data.name) {
            return Err(GridError::BadName(data.name));
        }
        let size = data.size.map(usize::from);
        let n = size.iter().product::<usize>();
        if size.iter().any(|&s| s < 2) || n > MAX_GRID_SAMPLES {
            return Err(GridError::BadSize(size));
        }
        if data.samples.len() != n {
            return Err(GridError::WrongLength {
                expected: n,
                found: data.samples.len(),
            });
        }
        if !data.origin.iter().all(|v| v.is_finite()) {
            return Err(GridError::BadNumber { what: "origin" });
        }
        if !data.spacing.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(GridError::BadNumber { what: "spacing" });
        }
        if !data.range.iter().all(|v| v.is_finite()) {
            return Err(GridError::BadNumber { what: "range" });
        }
        let bytes_lo = data.samples.iter().copied().min().unwrap_or(0);
        let bytes_hi = data.samples.iter().copied().max().unwrap_or(0);
        Ok(Grid {
            data,
            bytes_lo,
            bytes_hi,
        })
    }

    /// A grid from raw bytes (x fastest) of a declared size, placed by `origin` and `spacing`,
    /// with bytes 0..=255 standing for `range`.
    pub fn from_raw(
        name: &str,
        size: [usize; 3],
        origin: [f64; 3],
        spacing: [f64; 3],
        range: [f64; 2],
        bytes: &[u8],
    ) -> Result<Grid, GridError> {
        if size.iter().any(|&s| s < 2 || s > usize::from(u16::MAX))
            || size
                .iter()
                .try_fold(1usize, |a, &s| a.checked_mul(s))
                .is_none_or(|n| n > MAX_GRID_SAMPLES)
        {
            return Err(GridError::BadSize(size));
        }
        Grid::new(GridData {
            name: name.to_string(),
            size: size.map(|s| s as u16),
            origin,
            spacing,
            range,
            samples: bytes.to_vec(),
        })
    }

    /// A grid from an NRRD file: `type` `uchar`/`uint8` (or `signed char`), `dimension: 3`,
    /// `encoding: raw`, `sizes`, and optional `spacings` (default 1) and `space origin`
    /// (default 0), with the raw samples after the blank line. Bytes stand for `range`.
    pub fn from_nrrd(name: &str, bytes: &[u8], range: [f64; 2]) -> Result<Grid, GridError> {
        let header = nrrd::parse(bytes)?;
        let n = header.size.iter().product::<usize>();
        let data = &bytes[header.data_at..];
        if data.len() != n {
            return Err(GridError::WrongLength {
                expected: n,
                found: data.len(),
            });
        }
        Grid::from_raw(
            name,
            header.size,
            header.origin,
            header.spacing,
            range,
            data,
        )
    }

    /// The plain fields.
    pub fn data(&self) -> &GridData {
        &self.data
    }

    /// What formulas call it.
    pub fn name(&self) -> &str {
        &self.data.name
    }

    /// The box the samples span: `origin` to `origin + (size - 1) * spacing`.
    pub fn extent(&self) -> ([f64; 3], [f64; 3]) {
        let d = &self.data;
        let hi = std::array::from_fn(|a| d.origin[a] + f64::from(d.size[a] - 1) * d.spacing[a]);
        (d.origin, hi)
    }

    fn byte_to_value(&self, b: f64) -> f64 {
        let [lo, hi] = self.data.range;
        lo + (hi - lo) * (b / 255.0)
    }

    /// Per axis: the cell's first index, the fraction within it, and whether the coordinate
    /// lies strictly inside the grid (where the value moves with it). `None` for NaN.
    fn locate(&self, axis: usize, p: f64) -> Option<(usize, f64, bool)> {
        let n = usize::from(self.data.size[axis]);
        let u = (p - self.data.origin[axis]) / self.data.spacing[axis];
        if u.is_nan() {
            return None;
        }
        let last = (n - 1) as f64;
        let clamped = u.clamp(0.0, last);
        let i = (clamped.floor() as usize).min(n - 2);
        Some((i, clamped - i as f64, u > 0.0 && u < last))
    }

    fn byte(&self, i: usize, j: usize, k: usize) -> f64 {
        let [nx, ny, _] = self.data.size.map(usize::from);
        f64::from(self.data.samples[i + nx * (j + ny * k)])
    }

    /// The 8 bytes of the cell at `(i, j, k)`, indexed by `dx + 2 dy + 4 dz`.
    fn corners(&self, i: usize, j: usize, k: usize) -> [f64; 8] {
        std::array::from_fn(|c| self.byte(i + (c & 1), j + ((c >> 1) & 1), k + (c >> 2)))
    }

    /// The interpolated value at `p`.
    pub fn value(&self, p: [f64; 3]) -> f64 {
        self.value_grad(p).0
    }

    /// The interpolated value at `p` and its gradient (zero along an axis where `p` lies
    /// outside the grid; one-sided on the faces between cells).
    pub fn value_grad(&self, p: [f64; 3]) -> (f64, [f64; 3]) {
        let (Some(x), Some(y), Some(z)) = (
            self.locate(0, p[0]),
            self.locate(1, p[1]),
            self.locate(2, p[2]),
        ) else {
            return (f64::NAN, [f64::NAN; 3]);
        };
        let c = self.corners(x.0, y.0, z.0);
        let lerp = |a: f64, b: f64, f: f64| a + (b - a) * f;
        let (fx, fy, fz) = (x.1, y.1, z.1);
        // Along x first, then y, then z.
        let e: [f64; 4] = std::array::from_fn(|r| lerp(c[2 * r], c[2 * r + 1], fx));
        let f0 = lerp(e[0], e[1], fy);
        let f1 = lerp(e[2], e[3], fy);
        let bytes = lerp(f0, f1, fz);
        // Derivatives in index units.
        let dx: [f64; 4] = std::array::from_fn(|r| c[2 * r + 1] - c[2 * r]);
        let du = lerp(lerp(dx[0], dx[1], fy), lerp(dx[2], dx[3], fy), fz);
        let dv = lerp(e[1] - e[0], e[3] - e[2], fz);
        let dw = f1 - f0;
        let [lo, hi] = self.data.range;
        let scale = (hi - lo) / 255.0;
        let s = self.data.spacing;
        let along = |d: f64, inside: bool, h: f64| if inside { d * scale / h } else { 0.0 };
        (
            self.byte_to_value(bytes),
            [
                along(du, x.2, s[0]),
                along(dv, y.2, s[1]),
                along(dw, z.2, s[2]),
            ],
        )
    }

    /// Bounds of the interpolated value over the box `lo..=hi` (ends may be infinite), as
    /// `(low, high)`; `None` when a coordinate bound is NaN.
    pub fn bounds(&self, lo: [f64; 3], hi: [f64; 3]) -> Option<(f64, f64)> {
        let mut first = [0usize; 3];
        let mut last = [0usize; 3];
        let mut count = 1usize;
        for a in 0..3 {
            let n = usize::from(self.data.size[a]);
            let index = |p: f64| {
                let u = (p - self.data.origin[a]) / self.data.spacing[a];
                (!u.is_nan()).then(|| u.clamp(0.0, (n - 1) as f64))
            };
            let (u0, u1) = (index(lo[a])?, index(hi[a])?);
            first[a] = u0.min(u1).floor() as usize;
            last[a] = (u0.max(u1).ceil() as usize).min(n - 1);
            count = count.saturating_mul(last[a] - first[a] + 1);
        }
        let (b_lo, b_hi) = if count <= MAX_INTERVAL_SCAN {
            let mut b = (u8::MAX, u8::MIN);
            for k in first[2]..=last[2] {
                for j in first[1]..=last[1] {
                    for i in first[0]..=last[0] {
                        let v = self.byte(i, j, k) as u8;
                        b = (b.0.min(v), b.1.max(v));
                    }
                }
            }
            b
        } else {
            (self.bytes_lo, self.bytes_hi)
        };
        let (v0, v1) = (
            self.byte_to_value(f64::from(b_lo)),
            self.byte_to_value(f64::from(b_hi)),
        );
        Some((v0.min(v1), v0.max(v1)))
    }
}

mod nrrd {
    //! The part of NRRD (teem's "nearly raw raster data") that volume tools write for 8-bit
    //! scans: a text header, a blank line, raw bytes.

    use super::{GridError, MAX_NRRD_HEADER_BYTES};

    pub(super) struct Header {
        pub size: [usize; 3],
        pub spacing: [f64; 3],
        pub origin: [f64; 3],
        /// Where the samples start.
        pub data_at: usize,
    }

    fn error(line: usize, message: impl Into<String>) -> GridError {
        GridError::Nrrd {
            line,
            message: message.into(),
        }
    }

    fn numbers<const N: usize>(line: usize, text: &str) -> Result<[f64; N], GridError> {
        let words: Vec<&str> = text
            .split(|c: char| c.is_whitespace() || "(),".contains(c))
            .filter(|w| !w.is_empty())
            .collect();
        if words.len() != N {
            return Err(error(line, format!("expected {N} numbers, found `{text}`")));
        }
        let mut out = [0.0; N];
        for (o, w) in out.iter_mut().zip(words) {
            *o = w
                .parse()
                .map_err(|_| error(line, format!("`{w}` is not a number")))?;
        }
        Ok(out)
    }

    /// What the header's fields have set so far.
    struct Fields {
        size: Option<[usize; 3]>,
        spacing: [f64; 3],
        origin: [f64; 3],
        kind_ok: bool,
    }

    pub(super) fn parse(bytes: &[u8]) -> Result<Header, GridError> {
        let mut fields = Fields {
            size: None,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            kind_ok: false,
        };
        let mut at = 0usize;
        let mut line = 0usize;
        loop {
            line += 1;
            let rest = &bytes[at..];
            let Some(end) = rest.iter().position(|&b| b == b'\n') else {
                return Err(error(line, "the header has no blank line before the data"));
            };
            if at + end > MAX_NRRD_HEADER_BYTES {
                return Err(error(
                    line,
                    format!("the header is longer than {MAX_NRRD_HEADER_BYTES} bytes"),
                ));
            }
            let text = std::str::from_utf8(&rest[..end])
                .map_err(|_| error(line, "the header is not text"))?
                .trim_end_matches('\r');
            at += end + 1;
            if line == 1 {
                if !text.starts_with("NRRD000") {
                    return Err(error(1, "not an NRRD file (it must start with `NRRD000`)"));
                }
                continue;
            }
            if text.is_empty() {
                break;
            }
            if text.starts_with('#') || text.contains(":=") {
                continue;
            }
            let Some((key, value)) = text.split_once(':') else {
                return Err(error(line, format!("`{text}` is not `field: value`")));
            };
            read_field(&mut fields, line, key.trim(), value.trim())?;
        }
        if !fields.kind_ok {
            return Err(error(line, "the header has no `type: uchar`"));
        }
        let Some(size) = fields.size else {
            return Err(error(line, "the header has no `sizes`"));
        };
        Ok(Header {
            size,
            spacing: fields.spacing,
            origin: fields.origin,
            data_at: at,
        })
    }

    /// Reads the field `key: value` of header line `line`; fields we do not read are skipped.
    fn read_field(
        fields: &mut Fields,
        line: usize,
        key: &str,
        value: &str,
    ) -> Result<(), GridError> {
        match key {
            "type" => {
                if !matches!(value, "uchar" | "unsigned char" | "uint8" | "uint8_t") {
                    return Err(error(
                        line,
                        format!("type `{value}` is not read: only 8-bit unsigned samples"),
                    ));
                }
                fields.kind_ok = true;
            }
            "dimension" if value != "3" => {
                return Err(error(line, format!("dimension {value}: only 3 is read")));
            }
            "encoding" if value != "raw" => {
                return Err(error(line, format!("encoding `{value}`: only raw is read")));
            }
            "sizes" => {
                let [a, b, c] = numbers::<3>(line, value)?;
                let ok = |v: f64| v.fract() == 0.0 && (2.0..=65_535.0).contains(&v);
                if !(ok(a) && ok(b) && ok(c)) {
                    return Err(error(line, format!("sizes `{value}` are not 2 to 65535")));
                }
                fields.size = Some([a as usize, b as usize, c as usize]);
            }
            "spacings" => fields.spacing = numbers::<3>(line, value)?,
            "space origin" => fields.origin = numbers::<3>(line, value)?,
            "space directions" => {
                let v = numbers::<9>(line, value)?;
                let diagonal = [v[1], v[2], v[3], v[5], v[6], v[7]]
                    .iter()
                    .all(|&x| x == 0.0);
                if !diagonal {
                    return Err(error(line, "only axis-aligned space directions are read"));
                }
                fields.spacing = [v[0], v[4], v[8]];
            }
            _ => {}
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp() -> Grid {
        // Byte = 10 i + 20 j + 40 k over a 3 x 3 x 3 grid at spacing 0.5 from (-0.5, -0.5, -0.5).
        let bytes: Vec<u8> = (0..27)
            .map(|n| (10 * (n % 3) + 20 * ((n / 3) % 3) + 40 * (n / 9)) as u8)
            .collect();
        Grid::from_raw("ramp", [3, 3, 3], [-0.5; 3], [0.5; 3], [0.0, 255.0], &bytes).unwrap()
    }

    #[test]
    fn a_linear_ramp_is_interpolated_exactly_with_its_gradient() {
        let g = ramp();
        for p in [[0.1, -0.3, 0.2], [-0.5, -0.5, -0.5], [0.49, 0.01, -0.2]] {
            let want =
                10.0 * (p[0] + 0.5) / 0.5 + 20.0 * (p[1] + 0.5) / 0.5 + 40.0 * (p[2] + 0.5) / 0.5;
            let (v, d) = g.value_grad(p);
            assert!((v - want).abs() < 1e-9, "{v} {want}");
            if p[0] > -0.5 {
                assert!(
                    (d[0] - 20.0).abs() < 1e-9
                        && (d[1] - 40.0).abs() < 1e-9
                        && (d[2] - 80.0).abs() < 1e-9,
                    "{d:?}"
                );
            }
        }
        // Outside, the value continues the face and does not change along the clamped axis.
        let (v, d) = g.value_grad([3.0, 0.0, 0.0]);
        assert_eq!(v, 20.0 + 20.0 + 40.0);
        assert_eq!(d[0], 0.0);
        assert!(g.value([f64::NAN, 0.0, 0.0]).is_nan());
    }

    #[test]
    fn bounds_hold_every_value_in_the_box() {
        let g = ramp();
        let (lo, hi) = g.bounds([-0.2, -0.2, -0.2], [0.2, 0.1, 0.3]).unwrap();
        for k in 0..=10 {
            let f = k as f64 / 10.0;
            let v = g.value([-0.2 + 0.4 * f, -0.2 + 0.3 * f, -0.2 + 0.5 * f]);
            assert!(lo <= v && v <= hi, "{lo} {v} {hi}");
        }
        let all = g
            .bounds([f64::NEG_INFINITY; 3], [f64::INFINITY; 3])
            .unwrap();
        assert_eq!(all, (0.0, 140.0));
        assert!(g.bounds([f64::NAN, 0.0, 0.0], [0.0; 3]).is_none());
    }

    #[test]
    fn bad_grids_are_refused_with_the_reason() {
        let ok =
            |name: &str| Grid::from_raw(name, [2, 2, 2], [0.0; 3], [1.0; 3], [0.0, 1.0], &[0; 8]);
        assert!(ok("head").is_ok());
        for name in ["", "2head", "sin", "x", "min", "a-b", &"n".repeat(40)] {
            assert!(matches!(ok(name), Err(GridError::BadName(_))), "{name}");
        }
        let sized = |size: [usize; 3], n: usize| {
            Grid::from_raw("g", size, [0.0; 3], [1.0; 3], [0.0, 1.0], &vec![0; n])
        };
        assert!(matches!(sized([1, 2, 2], 4), Err(GridError::BadSize(_))));
        assert!(sized([64, 64, 64], 64 * 64 * 64).is_ok());
        assert!(matches!(
            sized([65, 64, 64], 65 * 64 * 64),
            Err(GridError::BadSize(_))
        ));
        assert!(matches!(
            sized([usize::MAX, 2, 2], 4),
            Err(GridError::BadSize(_))
        ));
        assert!(matches!(
            sized([2, 2, 2], 7),
            Err(GridError::WrongLength {
                expected: 8,
                found: 7
            })
        ));
        let spaced = Grid::from_raw(
            "g",
            [2, 2, 2],
            [0.0; 3],
            [0.0, 1.0, 1.0],
            [0.0, 1.0],
            &[0; 8],
        );
        assert!(matches!(
            spaced,
            Err(GridError::BadNumber { what: "spacing" })
        ));
    }

    #[test]
    fn nrrd_files_are_read_and_bad_headers_name_their_line() {
        let mut file = b"NRRD0004\n# a phantom\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspacings: 0.5 0.5 2\nspace origin: (1,2,3)\nencoding: raw\n\n".to_vec();
        file.extend([0, 255, 0, 255, 0, 255, 0, 255]);
        let g = Grid::from_nrrd("scan", &file, [0.0, 1.0]).unwrap();
        assert_eq!(g.data().spacing, [0.5, 0.5, 2.0]);
        assert_eq!(g.extent(), ([1.0, 2.0, 3.0], [1.5, 2.5, 5.0]));
        assert!((g.value([1.25, 2.0, 3.0]) - 0.5).abs() < 1e-12);
        let bad = |header: &str| {
            Grid::from_nrrd("scan", header.as_bytes(), [0.0, 1.0])
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            bad("P6\n"),
            "NRRD line 1: not an NRRD file (it must start with `NRRD000`)"
        );
        assert_eq!(
            bad("NRRD0004\ntype: float\n\n"),
            "NRRD line 2: type `float` is not read: only 8-bit unsigned samples"
        );
        assert_eq!(
            bad("NRRD0004\ntype: uchar\nencoding: gzip\n\n"),
            "NRRD line 3: encoding `gzip`: only raw is read"
        );
        assert_eq!(
            bad("NRRD0004\ntype: uchar\nsizes: 2 2\n\n"),
            "NRRD line 3: expected 3 numbers, found `2 2`"
        );
        assert_eq!(
            bad("NRRD0004\ntype: uchar\n"),
            "NRRD line 3: the header has no blank line before the data"
        );
        assert_eq!(
            bad("NRRD0004\ntype: uchar\nsizes: 2 2 2\n\n\u{0}"),
            "the grid declares 8 samples but 1 bytes were given"
        );
        let long = format!("NRRD0004\n#{}\n\n", "a".repeat(5000));
        assert!(bad(&long).contains("longer than 4096"));
    }
}
