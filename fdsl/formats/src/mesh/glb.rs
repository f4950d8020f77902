//! Binary glTF 2.0 (`.glb`): a 12-byte header, a JSON chunk (parsed with serde_json) and a
//! binary chunk holding the data.
//!
//! Reading takes every triangle primitive (mode 4) of every mesh: its `POSITION` accessor
//! (`FLOAT` `VEC3`) and its indices (`UNSIGNED_BYTE`, `_SHORT` or `_INT`) or, without
//! indices, consecutive triples of positions. Primitives are concatenated; node transforms,
//! scenes, materials and every other attribute are ignored, so a mesh placed by its node comes
//! back in its own coordinates. Other modes, sparse or normalized accessors, and buffers
//! outside the file (URIs, which would need IO) are errors. Every offset, stride and count is
//! checked against the lengths it must fit in, with checked arithmetic, before anything is
//! allocated. Vertices are kept as they are, not welded.
//!
//! Writing produces one mesh with one indexed primitive (u32 indices) in one node of one
//! scene. A mesh without triangles is written as an asset with no mesh, and reads back
//! empty.

use serde::Deserialize;
use serde::de::IgnoredAny;
use thiserror::Error;

use super::text::{F32, push_fmt};
use model::mesh::{MAX_MESH_TRIANGLES, MAX_MESH_VERTICES, MeshError, TriMesh};

const MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
const HEADER_BYTES: usize = 12;
const CHUNK_HEADER_BYTES: usize = 8;
const MODE_TRIANGLES: u64 = 4;
const COMPONENT_FLOAT: u64 = 5126;
const COMPONENT_U8: u64 = 5121;
const COMPONENT_U16: u64 = 5123;
const COMPONENT_U32: u64 = 5125;
/// The largest byte stride glTF allows.
const MAX_STRIDE_BYTES: u64 = 252;

/// Why a binary glTF file could not be read.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum GlbError {
    /// The container (header or chunks) is malformed.
    #[error("byte {offset}: {message}")]
    Container {
        /// Where.
        offset: usize,
        /// What is wrong.
        message: String,
    },
    /// The JSON chunk is not valid JSON or does not have the expected shape.
    #[error("JSON chunk {line}:{column}: {message}")]
    Json {
        /// The line in the JSON chunk, from 1.
        line: usize,
        /// The column in the JSON chunk, from 1.
        column: usize,
        /// What serde_json says.
        message: String,
    },
    /// The JSON describes data that is unsupported or does not fit the buffers.
    #[error("{path}: {message}")]
    Invalid {
        /// Where in the JSON, such as `accessors[2].count`.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// The parts do not make a mesh (not expected after the checks above).
    #[error("{0}")]
    Mesh(#[from] MeshError),
}

#[derive(Deserialize)]
struct Gltf {
    asset: Asset,
    #[serde(default)]
    meshes: Vec<Mesh>,
    #[serde(default)]
    accessors: Vec<Accessor>,
    #[serde(default, rename = "bufferViews")]
    buffer_views: Vec<BufferView>,
    #[serde(default)]
    buffers: Vec<Buffer>,
}

#[derive(Deserialize)]
struct Asset {
    version: String,
}

#[derive(Deserialize)]
struct Mesh {
    primitives: Vec<Primitive>,
}

#[derive(Deserialize)]
struct Primitive {
    attributes: Attributes,
    indices: Option<u64>,
    mode: Option<u64>,
}

#[derive(Deserialize)]
struct Attributes {
    #[serde(rename = "POSITION")]
    position: Option<u64>,
}

#[derive(Deserialize)]
struct Accessor {
    #[serde(rename = "bufferView")]
    buffer_view: Option<u64>,
    #[serde(default, rename = "byteOffset")]
    byte_offset: u64,
    #[serde(rename = "componentType")]
    component_type: u64,
    #[serde(default)]
    normalized: bool,
    count: u64,
    #[serde(rename = "type")]
    kind: String,
    sparse: Option<IgnoredAny>,
}

#[derive(Deserialize)]
struct BufferView {
    buffer: u64,
    #[serde(default, rename = "byteOffset")]
    byte_offset: u64,
    #[serde(rename = "byteLength")]
    byte_length: u64,
    #[serde(rename = "byteStride")]
    byte_stride: Option<u64>,
}

#[derive(Deserialize)]
struct Buffer {
    #[serde(rename = "byteLength")]
    byte_length: u64,
    uri: Option<IgnoredAny>,
}

fn container(offset: usize, message: String) -> GlbError {
    GlbError::Container { offset, message }
}

fn invalid(path: impl Into<String>, message: String) -> GlbError {
    GlbError::Invalid {
        path: path.into(),
        message,
    }
}

fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// The JSON chunk and the binary chunk (empty when absent) of a GLB container.
fn chunks(bytes: &[u8]) -> Result<(&[u8], &[u8]), GlbError> {
    if bytes.len() < HEADER_BYTES {
        return Err(container(
            0,
            format!(
                "the file is {} bytes, shorter than the 12-byte header",
                bytes.len()
            ),
        ));
    }
    if &bytes[..4] != MAGIC {
        return Err(container(
            0,
            "the file does not start with `glTF`".to_string(),
        ));
    }
    let version = u32_at(bytes, 4).unwrap_or(0);
    if version != 2 {
        return Err(container(4, format!("version {version} is not 2")));
    }
    let length = u32_at(bytes, 8).unwrap_or(0) as usize;
    if length > bytes.len() || length < HEADER_BYTES {
        return Err(container(
            8,
            format!(
                "the header says {length} bytes, but the file has {}",
                bytes.len()
            ),
        ));
    }
    let bytes = &bytes[..length];
    let mut at = HEADER_BYTES;
    let mut json = None;
    let mut bin: &[u8] = &[];
    // Each chunk takes 8 bytes at least, so this ends.
    while at < bytes.len() {
        let (Some(chunk_length), Some(kind)) = (u32_at(bytes, at), u32_at(bytes, at + 4)) else {
            return Err(container(at, "a chunk header is cut short".to_string()));
        };
        let start = at + CHUNK_HEADER_BYTES;
        let end = start
            .checked_add(chunk_length as usize)
            .filter(|&end| end <= bytes.len())
            .ok_or_else(|| {
                container(
                    at,
                    format!(
                        "the chunk says {chunk_length} bytes, but only {} remain",
                        bytes.len() - start
                    ),
                )
            })?;
        match (json.is_some(), kind) {
            (false, CHUNK_JSON) => json = Some(&bytes[start..end]),
            (false, _) => return Err(container(at, "the first chunk is not JSON".to_string())),
            (true, CHUNK_BIN) if bin.is_empty() => bin = &bytes[start..end],
            // Unknown chunk types are to be ignored, says the specification.
            (true, _) => {}
        }
        at = end;
    }
    let json = json.ok_or_else(|| container(HEADER_BYTES, "there is no JSON chunk".to_string()))?;
    Ok((json, bin))
}

/// Reads a binary glTF file.
pub fn read(bytes: &[u8]) -> Result<TriMesh, GlbError> {
    let (json, bin) = chunks(bytes)?;
    let gltf: Gltf = serde_json::from_slice(json).map_err(|e| GlbError::Json {
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    })?;
    if !gltf.asset.version.starts_with("2.") {
        return Err(invalid(
            "asset.version",
            format!("version `{}` is not 2.x", gltf.asset.version),
        ));
    }
    let mut positions: Vec<[f32; 3]> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    for (m, mesh) in gltf.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let path = format!("meshes[{m}].primitives[{p}]");
            let mode = primitive.mode.unwrap_or(MODE_TRIANGLES);
            if mode != MODE_TRIANGLES {
                return Err(invalid(
                    format!("{path}.mode"),
                    format!("only triangles (mode 4) are read, not mode {mode}"),
                ));
            }
            let base = positions.len();
            let Some(position) = primitive.attributes.position else {
                return Err(invalid(
                    format!("{path}.attributes"),
                    "there is no POSITION attribute".to_string(),
                ));
            };
            read_positions(&gltf, bin, position, &mut positions)?;
            let n_new = positions.len() - base;
            match primitive.indices {
                Some(indices) => read_indices(&gltf, bin, indices, base, n_new, &mut triangles)?,
                None => non_indexed(&path, base, n_new, &mut triangles)?,
            }
        }
    }
    Ok(TriMesh::new(positions, triangles)?)
}

/// Where an accessor's elements lie in the binary chunk.
struct Layout {
    /// Offset of the first element in the binary chunk.
    start: usize,
    /// Bytes from one element to the next.
    stride: usize,
    count: usize,
}

/// Checks accessor `idx` (its buffer view, its buffer, offsets, stride and count) against the
/// binary chunk, for elements of `element_bytes`.
fn layout(gltf: &Gltf, bin: &[u8], idx: u64, element_bytes: u64) -> Result<Layout, GlbError> {
    let path = format!("accessors[{idx}]");
    let accessor = item(&gltf.accessors, idx, "accessors")?;
    if accessor.sparse.is_some() {
        return Err(invalid(
            format!("{path}.sparse"),
            "sparse accessors are not read".to_string(),
        ));
    }
    let view_idx = accessor
        .buffer_view
        .ok_or_else(|| invalid(&path, "the accessor has no buffer view".to_string()))?;
    let view = buffer_view(gltf, bin, view_idx)?;
    let view_path = format!("bufferViews[{view_idx}]");
    let stride = view.byte_stride.unwrap_or(element_bytes);
    if stride < element_bytes || stride > MAX_STRIDE_BYTES {
        return Err(invalid(
            format!("{view_path}.byteStride"),
            format!("a stride of {stride} bytes does not fit elements of {element_bytes}"),
        ));
    }
    // The last element ends at offset + (count - 1) * stride + element_bytes.
    let needed = match accessor.count.checked_sub(1) {
        None => Some(accessor.byte_offset),
        Some(last) => last
            .checked_mul(stride)
            .and_then(|b| b.checked_add(element_bytes))
            .and_then(|b| b.checked_add(accessor.byte_offset)),
    };
    if needed.is_none_or(|n| n > view.byte_length) {
        return Err(invalid(
            format!("{path}.count"),
            format!(
                "{} elements from byte {} with a stride of {stride} do not fit in the buffer \
                 view's {} bytes",
                accessor.count, accessor.byte_offset, view.byte_length
            ),
        ));
    }
    // Everything is now within the binary chunk, whose length is a usize.
    Ok(Layout {
        start: (view.byte_offset + accessor.byte_offset) as usize,
        stride: stride as usize,
        count: accessor.count as usize,
    })
}

/// Buffer view `view_idx`, checked to lie in the file's own binary chunk `bin`.
fn buffer_view<'a>(gltf: &'a Gltf, bin: &[u8], view_idx: u64) -> Result<&'a BufferView, GlbError> {
    let view = item(&gltf.buffer_views, view_idx, "bufferViews")?;
    let view_path = format!("bufferViews[{view_idx}]");
    let buffer = item(&gltf.buffers, view.buffer, "buffers")?;
    if view.buffer != 0 || buffer.uri.is_some() {
        return Err(invalid(
            format!("{view_path}.buffer"),
            "only the file's own binary chunk (buffer 0, without a uri) is read".to_string(),
        ));
    }
    if buffer.byte_length > bin.len() as u64 {
        return Err(invalid(
            "buffers[0].byteLength",
            format!(
                "{} bytes, but the binary chunk has {}",
                buffer.byte_length,
                bin.len()
            ),
        ));
    }
    let view_end = view.byte_offset.checked_add(view.byte_length);
    if view_end.is_none_or(|end| end > buffer.byte_length) {
        return Err(invalid(
            view_path,
            format!(
                "bytes {} + {} do not fit in the buffer's {}",
                view.byte_offset, view.byte_length, buffer.byte_length
            ),
        ));
    }
    Ok(view)
}

fn item<'a, T>(items: &'a [T], idx: u64, name: &str) -> Result<&'a T, GlbError> {
    usize::try_from(idx)
        .ok()
        .and_then(|i| items.get(i))
        .ok_or_else(|| {
            invalid(
                format!("{name}[{idx}]"),
                format!("there are only {} {name}", items.len()),
            )
        })
}

fn read_positions(
    gltf: &Gltf,
    bin: &[u8],
    idx: u64,
    positions: &mut Vec<[f32; 3]>,
) -> Result<(), GlbError> {
    let path = format!("accessors[{idx}]");
    let accessor = item(&gltf.accessors, idx, "accessors")?;
    if accessor.component_type != COMPONENT_FLOAT || accessor.kind != "VEC3" {
        return Err(invalid(
            path,
            format!(
                "positions must be FLOAT ({COMPONENT_FLOAT}) VEC3, not {} {}",
                accessor.component_type, accessor.kind
            ),
        ));
    }
    if accessor.normalized {
        return Err(invalid(
            format!("{path}.normalized"),
            "float positions cannot be normalized".to_string(),
        ));
    }
    let layout = layout(gltf, bin, idx, 12)?;
    if layout.count > MAX_MESH_VERTICES - positions.len() {
        return Err(invalid(
            format!("{path}.count"),
            format!("more than {MAX_MESH_VERTICES} vertices in all"),
        ));
    }
    positions.reserve(layout.count);
    for i in 0..layout.count {
        let at = layout.start + i * layout.stride;
        let mut p = [0f32; 3];
        for (k, c) in p.iter_mut().enumerate() {
            let b = &bin[at + 4 * k..at + 4 * k + 4];
            *c = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
        if !p.iter().all(|c| c.is_finite()) {
            return Err(invalid(
                path,
                format!("position {i} (binary chunk byte {at}) is not finite"),
            ));
        }
        positions.push(p);
    }
    Ok(())
}

fn read_indices(
    gltf: &Gltf,
    bin: &[u8],
    idx: u64,
    base: usize,
    n_vertices: usize,
    triangles: &mut Vec<[u32; 3]>,
) -> Result<(), GlbError> {
    let path = format!("accessors[{idx}]");
    let accessor = item(&gltf.accessors, idx, "accessors")?;
    let element_bytes = match accessor.component_type {
        COMPONENT_U8 => 1,
        COMPONENT_U16 => 2,
        COMPONENT_U32 => 4,
        other => {
            return Err(invalid(
                format!("{path}.componentType"),
                format!("indices must be unsigned bytes, shorts or ints, not {other}"),
            ));
        }
    };
    if accessor.kind != "SCALAR" {
        return Err(invalid(
            format!("{path}.type"),
            format!("indices must be SCALAR, not {}", accessor.kind),
        ));
    }
    let layout = layout(gltf, bin, idx, element_bytes)?;
    if !layout.count.is_multiple_of(3) {
        return Err(invalid(
            format!("{path}.count"),
            format!("{} indices do not make whole triangles", layout.count),
        ));
    }
    if layout.count / 3 > MAX_MESH_TRIANGLES - triangles.len() {
        return Err(invalid(
            format!("{path}.count"),
            format!("more than {MAX_MESH_TRIANGLES} triangles in all"),
        ));
    }
    let index = |i: usize| -> Result<u32, GlbError> {
        let at = layout.start + i * layout.stride;
        let b = &bin[at..at + element_bytes as usize];
        let v = match b {
            [x] => u32::from(*x),
            [x, y] => u32::from(u16::from_le_bytes([*x, *y])),
            [x, y, z, w] => u32::from_le_bytes([*x, *y, *z, *w]),
            _ => 0,
        };
        if v as usize >= n_vertices {
            return Err(invalid(
                path.clone(),
                format!("index {i} is {v}, but the primitive has {n_vertices} positions"),
            ));
        }
        // base + v < MAX_MESH_VERTICES, which fits in a u32.
        Ok((base + v as usize) as u32)
    };
    triangles.reserve(layout.count / 3);
    for t in 0..layout.count / 3 {
        triangles.push([index(3 * t)?, index(3 * t + 1)?, index(3 * t + 2)?]);
    }
    Ok(())
}

fn non_indexed(
    path: &str,
    base: usize,
    n_vertices: usize,
    triangles: &mut Vec<[u32; 3]>,
) -> Result<(), GlbError> {
    if !n_vertices.is_multiple_of(3) {
        return Err(invalid(
            format!("{path}.attributes.POSITION"),
            format!("without indices, {n_vertices} positions do not make whole triangles"),
        ));
    }
    if n_vertices / 3 > MAX_MESH_TRIANGLES - triangles.len() {
        return Err(invalid(
            path,
            format!("more than {MAX_MESH_TRIANGLES} triangles in all"),
        ));
    }
    // base + n_vertices <= MAX_MESH_VERTICES, which fits in a u32.
    triangles.extend((0..n_vertices / 3).map(|t| {
        let i = (base + 3 * t) as u32;
        [i, i + 1, i + 2]
    }));
    Ok(())
}

/// The JSON chunk describing `mesh`, padded with spaces to a multiple of 4 bytes.
fn json_chunk(mesh: &TriMesh) -> Vec<u8> {
    let n_vertices = mesh.positions().len();
    let n_triangles = mesh.triangles().len();
    let mut json = Vec::new();
    if n_triangles == 0 {
        json.extend_from_slice(br#"{"asset":{"version":"2.0","generator":"fdsl"}}"#);
    } else {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in mesh.positions() {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let positions_bytes = 12 * n_vertices;
        let indices_bytes = 12 * n_triangles;
        push_fmt(
            &mut json,
            format_args!(
                concat!(
                    r#"{{"asset":{{"version":"2.0","generator":"fdsl"}},"#,
                    r#""scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],"#,
                    r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1,"mode":4}}]}}],"#,
                    r#""buffers":[{{"byteLength":{}}}],"#,
                    r#""bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{},"target":34962}},"#,
                    r#"{{"buffer":0,"byteOffset":{},"byteLength":{},"target":34963}}],"#,
                    r#""accessors":[{{"bufferView":0,"componentType":5126,"count":{},"type":"VEC3","#,
                    r#""min":[{},{},{}],"max":[{},{},{}]}},"#,
                    r#"{{"bufferView":1,"componentType":5125,"count":{},"type":"SCALAR"}}]}}"#,
                ),
                positions_bytes + indices_bytes,
                positions_bytes,
                positions_bytes,
                indices_bytes,
                n_vertices,
                F32(lo[0]),
                F32(lo[1]),
                F32(lo[2]),
                F32(hi[0]),
                F32(hi[1]),
                F32(hi[2]),
                3 * n_triangles,
            ),
        );
    }
    // Chunks start and end on 4-byte boundaries: JSON is padded with spaces.
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    json
}

/// Appends `mesh` as binary glTF 2.0: one scene, one node, one mesh, one indexed primitive.
pub fn write(mesh: &TriMesh, out: &mut Vec<u8>) {
    let n_vertices = mesh.positions().len();
    let n_triangles = mesh.triangles().len();
    let json = json_chunk(mesh);
    let bin_bytes = 12 * (n_vertices + n_triangles);
    let bin_chunk = if n_triangles == 0 {
        0
    } else {
        CHUNK_HEADER_BYTES + bin_bytes
    };
    let total = HEADER_BYTES + CHUNK_HEADER_BYTES + json.len() + bin_chunk;
    out.reserve(total);
    // The limits keep a mesh's file far below 4 GiB.
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(&json);
    if n_triangles > 0 {
        out.extend_from_slice(&(bin_bytes as u32).to_le_bytes());
        out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
        for v in mesh.positions().as_flattened() {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for i in mesh.triangles().as_flattened() {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
}
