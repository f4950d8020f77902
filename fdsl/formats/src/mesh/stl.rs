//! STL, binary and ASCII. STL stores each triangle's three corners (and a normal, which is
//! ignored on reading and recomputed on writing); reading merges corners with exactly equal
//! coordinates so that a closed solid comes back closed (see [`TriMesh::welded`]).
//!
//! Which kind a file is: binary when its length is exactly what its header's triangle count
//! implies (84 + 50 per triangle), otherwise ASCII when its first word is `solid`, otherwise
//! binary (and its length is the error). Binary files whose header starts with `solid` are
//! common, which is why the length decides first.

use thiserror::Error;

use super::text::{F32, Token, Tokens, push_fmt};
use model::mesh::{MAX_MESH_TRIANGLES, MeshError, TriMesh};

/// The bytes before the first triangle of a binary STL: an 80-byte header and a `u32` count.
const BINARY_HEADER_BYTES: usize = 84;
/// The bytes of one binary triangle: normal, three corners (12 `f32`) and a `u16`.
const BINARY_TRIANGLE_BYTES: usize = 50;
/// The header written into binary files; it must not start with `solid`.
const HEADER: &[u8] = b"binary STL written by fdsl";

/// Why an STL file could not be read.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum StlError {
    /// Shorter than a binary header, and not ASCII.
    #[error(
        "byte 0: the file is {len} bytes, too short for binary STL (84 at least), and does not \
         start with `solid`"
    )]
    TooShort {
        /// The file's length.
        len: usize,
    },
    /// The binary header's triangle count does not match the file's length.
    #[error(
        "byte 80: the header says {n_triangles} triangles, which take {expected_len} bytes, \
         but the file has {len}"
    )]
    LengthMismatch {
        /// The count in the header.
        n_triangles: u32,
        /// The length that count implies.
        expected_len: u64,
        /// The file's length.
        len: usize,
    },
    /// More triangles than [`MAX_MESH_TRIANGLES`].
    #[error("byte 80: {n_triangles} triangles is more than the limit of {MAX_MESH_TRIANGLES}")]
    TooManyTriangles {
        /// The count in the header.
        n_triangles: u32,
    },
    /// A binary coordinate is infinite or not a number.
    #[error("byte {offset}: the coordinate is not a finite number")]
    NotFinite {
        /// Where the coordinate starts.
        offset: usize,
    },
    /// An ASCII file does not follow the grammar.
    #[error("{line}:{column}: {message}")]
    Syntax {
        /// The line, from 1.
        line: usize,
        /// The byte column, from 1.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// The triangles do not make a mesh (not expected after the checks above).
    #[error("{0}")]
    Mesh(#[from] MeshError),
}

/// Reads a binary or ASCII STL file.
pub fn read(bytes: &[u8]) -> Result<TriMesh, StlError> {
    if binary_length_matches(bytes) {
        return read_binary(bytes);
    }
    let mut tokens = Tokens::new(bytes, false);
    if tokens.next_token().is_some_and(|t| t.is("solid")) {
        return read_ascii(bytes);
    }
    read_binary(bytes)
}

fn binary_triangle_count(bytes: &[u8]) -> Option<u32> {
    let count = bytes.get(80..BINARY_HEADER_BYTES)?;
    Some(u32::from_le_bytes([count[0], count[1], count[2], count[3]]))
}

fn binary_length(n_triangles: u32) -> u64 {
    // At most 84 + 50 * (2^32 - 1), which fits in a u64.
    BINARY_HEADER_BYTES as u64 + BINARY_TRIANGLE_BYTES as u64 * u64::from(n_triangles)
}

fn binary_length_matches(bytes: &[u8]) -> bool {
    binary_triangle_count(bytes).is_some_and(|n| binary_length(n) == bytes.len() as u64)
}

fn read_binary(bytes: &[u8]) -> Result<TriMesh, StlError> {
    let n_triangles =
        binary_triangle_count(bytes).ok_or(StlError::TooShort { len: bytes.len() })?;
    let expected_len = binary_length(n_triangles);
    if expected_len != bytes.len() as u64 {
        return Err(StlError::LengthMismatch {
            n_triangles,
            expected_len,
            len: bytes.len(),
        });
    }
    if n_triangles as usize > MAX_MESH_TRIANGLES {
        return Err(StlError::TooManyTriangles { n_triangles });
    }
    // The count is now known to match the length, so this allocation is bounded by it.
    let mut soup = Vec::with_capacity(n_triangles as usize);
    for (t, record) in bytes[BINARY_HEADER_BYTES..]
        .chunks_exact(BINARY_TRIANGLE_BYTES)
        .enumerate()
    {
        let mut corners = [[0f32; 3]; 3];
        for (k, value) in corners.as_flattened_mut().iter_mut().enumerate() {
            // Skip the normal (12 bytes); corners follow as little-endian f32.
            let at = 12 + 4 * k;
            let v =
                f32::from_le_bytes([record[at], record[at + 1], record[at + 2], record[at + 3]]);
            if !v.is_finite() {
                return Err(StlError::NotFinite {
                    offset: BINARY_HEADER_BYTES + t * BINARY_TRIANGLE_BYTES + at,
                });
            }
            *value = v;
        }
        soup.push(corners);
    }
    Ok(TriMesh::from_triangle_soup(&soup)?)
}

fn syntax(at: (usize, usize), message: String) -> StlError {
    StlError::Syntax {
        line: at.0,
        column: at.1,
        message,
    }
}

/// The next token, which must be `word`.
fn expect(tokens: &mut Tokens<'_>, word: &str) -> Result<(), StlError> {
    match tokens.next_token() {
        Some(t) if t.is(word) => Ok(()),
        Some(t) => Err(syntax(
            (t.line, t.column),
            format!("expected `{word}`, found `{}`", t.shown()),
        )),
        None => Err(syntax(
            tokens.here(),
            format!("the file ends where `{word}` was expected"),
        )),
    }
}

/// The next token as a number (finite when `finite`).
fn number(tokens: &mut Tokens<'_>, what: &str, finite: bool) -> Result<f32, StlError> {
    let Some(t) = tokens.next_token() else {
        return Err(syntax(
            tokens.here(),
            format!("the file ends where {what} was expected"),
        ));
    };
    match t.number() {
        Some(v) if v.is_finite() || !finite => Ok(v),
        Some(_) => Err(syntax(
            (t.line, t.column),
            format!("{what} `{}` is not a finite number", t.shown()),
        )),
        None => Err(syntax(
            (t.line, t.column),
            format!("expected {what}, found `{}`", t.shown()),
        )),
    }
}

fn read_ascii(bytes: &[u8]) -> Result<TriMesh, StlError> {
    let mut tokens = Tokens::new(bytes, false);
    let mut soup: Vec<[[f32; 3]; 3]> = Vec::new();
    // Files may hold several solids one after another.
    while let Some(first) = tokens.next_token() {
        if !first.is("solid") {
            return Err(unexpected(first, "`solid`"));
        }
        tokens.skip_line(); // the solid's name
        loop {
            let Some(t) = tokens.next_token() else {
                return Err(syntax(
                    tokens.here(),
                    "the file ends before `endsolid`".to_string(),
                ));
            };
            if t.is("endsolid") {
                tokens.skip_line();
                break;
            }
            if !t.is("facet") {
                return Err(unexpected(t, "`facet` or `endsolid`"));
            }
            if soup.len() == MAX_MESH_TRIANGLES {
                return Err(syntax(
                    (t.line, t.column),
                    format!("more than {MAX_MESH_TRIANGLES} facets"),
                ));
            }
            soup.push(facet(&mut tokens)?);
        }
    }
    Ok(TriMesh::from_triangle_soup(&soup)?)
}

fn unexpected(t: Token<'_>, wanted: &str) -> StlError {
    syntax(
        (t.line, t.column),
        format!("expected {wanted}, found `{}`", t.shown()),
    )
}

/// One facet after its `facet` keyword, through `endfacet`.
fn facet(tokens: &mut Tokens<'_>) -> Result<[[f32; 3]; 3], StlError> {
    expect(tokens, "normal")?;
    // Normals are recomputed; exporters write `nan` for degenerate facets, so any number goes.
    for _ in 0..3 {
        number(tokens, "a normal component", false)?;
    }
    expect(tokens, "outer")?;
    expect(tokens, "loop")?;
    let mut corners = [[0f32; 3]; 3];
    for corner in &mut corners {
        expect(tokens, "vertex")?;
        for c in corner.iter_mut() {
            *c = number(tokens, "a coordinate", true)?;
        }
    }
    expect(tokens, "endloop")?;
    expect(tokens, "endfacet")?;
    Ok(corners)
}

/// Appends `mesh` as binary STL.
pub fn write_binary(mesh: &TriMesh, out: &mut Vec<u8>) {
    let mut header = [b' '; 80];
    header[..HEADER.len()].copy_from_slice(HEADER);
    out.extend_from_slice(&header);
    // A mesh has at most MAX_MESH_TRIANGLES triangles, which fits in a u32.
    out.extend_from_slice(&(mesh.triangles().len() as u32).to_le_bytes());
    out.reserve(BINARY_TRIANGLE_BYTES * mesh.triangles().len());
    for t in 0..mesh.triangles().len() as u32 {
        let normal = facet_normal(mesh, t);
        for v in normal.into_iter().chain(corner_values(mesh, t)) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&[0, 0]);
    }
}

/// Appends `mesh` as ASCII STL; numbers read back exactly.
pub fn write_ascii(mesh: &TriMesh, out: &mut Vec<u8>) {
    out.extend_from_slice(b"solid fdsl\n");
    for t in 0..mesh.triangles().len() as u32 {
        let [nx, ny, nz] = facet_normal(mesh, t);
        push_fmt(
            out,
            format_args!("facet normal {} {} {}\n", F32(nx), F32(ny), F32(nz)),
        );
        out.extend_from_slice(b"  outer loop\n");
        for [x, y, z] in mesh.triangles()[t as usize].map(|v| mesh.positions()[v as usize]) {
            push_fmt(
                out,
                format_args!("    vertex {} {} {}\n", F32(x), F32(y), F32(z)),
            );
        }
        out.extend_from_slice(b"  endloop\nendfacet\n");
    }
    out.extend_from_slice(b"endsolid fdsl\n");
}

fn facet_normal(mesh: &TriMesh, t: u32) -> [f32; 3] {
    let [a, b, c] = mesh.corners(t);
    model::mesh::geometry::triangle_normal(a, b, c)
        .as_vec3()
        .to_array()
}

fn corner_values(mesh: &TriMesh, t: u32) -> impl Iterator<Item = f32> + '_ {
    mesh.triangles()[t as usize]
        .into_iter()
        .flat_map(|v| mesh.positions()[v as usize])
}
