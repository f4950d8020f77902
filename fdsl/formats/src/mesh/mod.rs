//! Mesh files: STL (binary and ASCII), Wavefront OBJ and binary glTF, read into and written
//! from the object model's [`TriMesh`], and [`MeshFormat`], the registry of these formats by
//! file name extension.
//!
//! What is guaranteed, and what is not:
//! - Readers never panic and never allocate more than the input length and the limits of
//!   [`model::mesh`] allow; every error names a byte offset, a line and column, or a JSON path.
//! - A mesh written and read back in the same format has the same triangles; STL stores
//!   corners, not shared vertices, so its reader merges equal corners
//!   ([`TriMesh::welded`]), and a mesh read from it may have fewer vertices.
//! - Only positions and triangles are kept: whatever else a file holds (normals, colours,
//!   materials, texture coordinates, node transforms) is ignored.
//!
//! ```
//! use formats::mesh;
//! use glam::DVec3;
//! use model::mesh::shapes;
//!
//! let cube = shapes::cube(DVec3::splat(-1.0), DVec3::splat(1.0));
//! let mut stl = Vec::new();
//! mesh::stl::write_binary(&cube, &mut stl);
//! let back = mesh::stl::read(&stl).unwrap();
//! assert!(back.is_closed());
//! assert_eq!(back.signed_distance(DVec3::new(0.5, 0.0, 0.0)), 0.5);
//! assert_eq!(back.signed_distance(DVec3::new(3.0, 0.0, 0.0)), -2.0);
//! ```

pub mod glb;
pub mod obj;
pub mod stl;
mod text;

use model::mesh::TriMesh;
use thiserror::Error;

/// Largest mesh file read, in bytes. An imported object is at most
/// `replication::shape::parts::MAX_ASSEMBLED_BYTES` as ops (a mesh of about 170 000
/// triangles), so files this large are refused for their size long before; the limit only
/// stops a huge file being read at all.
pub const MAX_MESH_FILE_BYTES: u64 = 16 << 20;

/// The mesh file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// STL, binary (the reader also accepts ASCII).
    StlBinary,
    /// STL, ASCII (the reader also accepts binary).
    StlAscii,
    /// Wavefront OBJ.
    Obj,
    /// Binary glTF 2.0.
    Glb,
}

impl MeshFormat {
    /// The format for a file name extension (any case): `stl` is binary STL, `obj`, `glb`.
    pub fn from_extension(extension: &str) -> Option<MeshFormat> {
        match extension.to_ascii_lowercase().as_str() {
            "stl" => Some(MeshFormat::StlBinary),
            "obj" => Some(MeshFormat::Obj),
            "glb" => Some(MeshFormat::Glb),
            _ => None,
        }
    }

    /// Reads a mesh in this format.
    pub fn read(self, bytes: &[u8]) -> Result<TriMesh, ReadError> {
        Ok(match self {
            MeshFormat::StlBinary | MeshFormat::StlAscii => stl::read(bytes)?,
            MeshFormat::Obj => obj::read(bytes)?,
            MeshFormat::Glb => glb::read(bytes)?,
        })
    }

    /// Appends `mesh` in this format to `out`.
    pub fn write(self, mesh: &TriMesh, out: &mut Vec<u8>) {
        match self {
            MeshFormat::StlBinary => stl::write_binary(mesh, out),
            MeshFormat::StlAscii => stl::write_ascii(mesh, out),
            MeshFormat::Obj => obj::write(mesh, out),
            MeshFormat::Glb => glb::write(mesh, out),
        }
    }
}

/// Why a mesh file could not be read, by format.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum ReadError {
    /// An STL problem.
    #[error("STL: {0}")]
    Stl(#[from] stl::StlError),
    /// An OBJ problem.
    #[error("OBJ: {0}")]
    Obj(#[from] obj::ObjError),
    /// A glTF problem.
    #[error("glTF: {0}")]
    Glb(#[from] glb::GlbError),
}
