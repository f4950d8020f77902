//! Wavefront OBJ: vertices (`v x y z`, extra numbers such as `w` or colours ignored) and faces
//! (`f` with `v`, `v/vt`, `v/vt/vn` or `v//vn` corners, negative indices counting back from
//! the last vertex so far). Polygons are split into a fan of triangles around their first
//! corner. Texture coordinates, normals, materials, groups, objects, smoothing, lines, points
//! and unknown directives are ignored without error; `#` starts a comment.
//!
//! A face may only use vertices defined above it (as the format intends; forward references
//! are an error rather than resolved at the end). Vertices are kept as they are, not welded.

use thiserror::Error;

use super::text::{F32, Token, Tokens, push_fmt};
use model::mesh::{MAX_MESH_TRIANGLES, MAX_MESH_VERTICES, MeshError, TriMesh};

/// Why an OBJ file could not be read. Lines and byte columns count from 1.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum ObjError {
    /// A vertex coordinate is missing or not a number.
    #[error("{line}:{column}: expected a coordinate, found {found}")]
    BadCoordinate {
        /// Where.
        line: usize,
        /// Where.
        column: usize,
        /// What was there instead, or "the end of the line".
        found: String,
    },
    /// A vertex coordinate is infinite or not a number.
    #[error("{line}:{column}: the coordinate `{text}` is not a finite number")]
    NotFinite {
        /// Where.
        line: usize,
        /// Where.
        column: usize,
        /// The number as written.
        text: String,
    },
    /// A face corner does not start with an integer.
    #[error("{line}:{column}: expected a vertex index, found `{text}`")]
    BadIndex {
        /// Where.
        line: usize,
        /// Where.
        column: usize,
        /// The corner as written.
        text: String,
    },
    /// A face uses index 0, which OBJ does not have (it counts from 1).
    #[error("{line}:{column}: vertex indices count from 1 (or back from -1), so 0 is none")]
    ZeroIndex {
        /// Where.
        line: usize,
        /// Where.
        column: usize,
    },
    /// A face uses a vertex that is not defined above it.
    #[error("{line}:{column}: vertex {index} is not defined; there are {n_vertices} so far")]
    IndexOutOfRange {
        /// Where.
        line: usize,
        /// Where.
        column: usize,
        /// The index as written.
        index: String,
        /// How many vertices were defined above.
        n_vertices: usize,
    },
    /// A face with fewer than three corners.
    #[error("{line}:{column}: a face needs three corners at least, this one has {n_corners}")]
    TooFewCorners {
        /// Where the face starts.
        line: usize,
        /// Where the face starts.
        column: usize,
        /// How many it has.
        n_corners: usize,
    },
    /// More vertices or triangles than the mesh limits allow.
    #[error("{line}:{column}: more than {limit} {what}")]
    TooMany {
        /// Where.
        line: usize,
        /// Where.
        column: usize,
        /// "vertices" or "triangles".
        what: &'static str,
        /// The limit.
        limit: usize,
    },
    /// The parts do not make a mesh (not expected after the checks above).
    #[error("{0}")]
    Mesh(#[from] MeshError),
}

/// Reads an OBJ file.
pub fn read(bytes: &[u8]) -> Result<TriMesh, ObjError> {
    let mut tokens = Tokens::new(bytes, true);
    let mut positions: Vec<[f32; 3]> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    while let Some(directive) = tokens.next_token() {
        match directive.text {
            b"v" => {
                if positions.len() == MAX_MESH_VERTICES {
                    return Err(too_many(directive, "vertices", MAX_MESH_VERTICES));
                }
                positions.push(vertex(&mut tokens)?);
            }
            b"f" => face(&mut tokens, directive, positions.len(), &mut triangles)?,
            _ => {}
        }
        tokens.skip_line();
    }
    Ok(TriMesh::new(positions, triangles)?)
}

fn too_many(at: Token<'_>, what: &'static str, limit: usize) -> ObjError {
    ObjError::TooMany {
        line: at.line,
        column: at.column,
        what,
        limit,
    }
}

fn vertex(tokens: &mut Tokens<'_>) -> Result<[f32; 3], ObjError> {
    let mut p = [0f32; 3];
    for c in &mut p {
        let Some(t) = tokens.next_on_line() else {
            let (line, column) = tokens.here();
            return Err(ObjError::BadCoordinate {
                line,
                column,
                found: "the end of the line".to_string(),
            });
        };
        *c = match t.number() {
            Some(v) if v.is_finite() => v,
            Some(_) => {
                return Err(ObjError::NotFinite {
                    line: t.line,
                    column: t.column,
                    text: t.shown(),
                });
            }
            None => {
                return Err(ObjError::BadCoordinate {
                    line: t.line,
                    column: t.column,
                    found: format!("`{}`", t.shown()),
                });
            }
        };
    }
    Ok(p)
}

/// Reads the corners of a face and appends its fan of triangles.
fn face(
    tokens: &mut Tokens<'_>,
    directive: Token<'_>,
    n_vertices: usize,
    triangles: &mut Vec<[u32; 3]>,
) -> Result<(), ObjError> {
    let mut first = None;
    let mut previous = None;
    let mut n_corners = 0;
    while let Some(t) = tokens.next_on_line() {
        let v = corner(t, n_vertices)?;
        n_corners += 1;
        match (first, previous) {
            (None, _) => first = Some(v),
            (Some(_), None) => previous = Some(v),
            (Some(a), Some(b)) => {
                if triangles.len() == MAX_MESH_TRIANGLES {
                    return Err(too_many(t, "triangles", MAX_MESH_TRIANGLES));
                }
                triangles.push([a, b, v]);
                previous = Some(v);
            }
        }
    }
    if n_corners < 3 {
        return Err(ObjError::TooFewCorners {
            line: directive.line,
            column: directive.column,
            n_corners,
        });
    }
    Ok(())
}

/// The zero-based vertex of a face corner (`v`, `v/vt`, `v/vt/vn` or `v//vn`). The texture
/// and normal indices are not used, but must be numbers, so that a damaged line (`5/f 12 11`,
/// two faces run together) is refused rather than read as one larger face.
fn corner(t: Token<'_>, n_vertices: usize) -> Result<u32, ObjError> {
    let mut parts = t.text.split(|&b| b == b'/');
    let text = parts.next().unwrap_or(t.text);
    let bad_index = || ObjError::BadIndex {
        line: t.line,
        column: t.column,
        text: t.shown(),
    };
    let number = |part: &[u8]| {
        let digits = part.strip_prefix(b"-").unwrap_or(part);
        !digits.is_empty() && digits.iter().all(u8::is_ascii_digit)
    };
    let (vt, vn, more) = (parts.next(), parts.next(), parts.next());
    let well_formed = more.is_none()
        && match (vt, vn) {
            (None, _) => true,
            (Some(vt), None) => number(vt),
            (Some(vt), Some(vn)) => (vt.is_empty() || number(vt)) && number(vn),
        };
    if !well_formed {
        return Err(bad_index());
    }
    let out_of_range = || ObjError::IndexOutOfRange {
        line: t.line,
        column: t.column,
        index: String::from_utf8_lossy(text).into_owned(),
        n_vertices,
    };
    let digits = text.strip_prefix(b"-").unwrap_or(text);
    if digits.is_empty() || !digits.iter().all(u8::is_ascii_digit) {
        return Err(bad_index());
    }
    // Digits only, so a failure to parse is an overflow.
    let index: i64 = std::str::from_utf8(text)
        .ok()
        .and_then(|s| s.parse().ok())
        .ok_or_else(out_of_range)?;
    let resolved = match index {
        0 => {
            return Err(ObjError::ZeroIndex {
                line: t.line,
                column: t.column,
            });
        }
        i if i > 0 => i - 1,
        i => (n_vertices as i64)
            .checked_add(i)
            .ok_or_else(out_of_range)?,
    };
    if resolved < 0 || resolved >= n_vertices as i64 {
        return Err(out_of_range());
    }
    // Below n_vertices <= MAX_MESH_VERTICES, so it fits.
    Ok(resolved as u32)
}

/// Appends `mesh` as OBJ (vertices, then triangles); numbers read back exactly.
pub fn write(mesh: &TriMesh, out: &mut Vec<u8>) {
    push_fmt(
        out,
        format_args!(
            "# written by fdsl: {} vertices, {} triangles\n",
            mesh.positions().len(),
            mesh.triangles().len()
        ),
    );
    for &[x, y, z] in mesh.positions() {
        push_fmt(out, format_args!("v {} {} {}\n", F32(x), F32(y), F32(z)));
    }
    for &[a, b, c] in mesh.triangles() {
        push_fmt(out, format_args!("f {} {} {}\n", a + 1, b + 1, c + 1));
    }
}
