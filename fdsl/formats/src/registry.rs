//! The file formats by file name extension: what import reads and export writes, for the
//! command line, the window's menu and file dialogs, and tests.
//!
//! Extensions, any case: `.wrl` FVRML ([`crate::fvrml`]), `.stl` (binary when written, binary
//! or ASCII when read), `.obj` and `.glb` ([`crate::mesh`]). A new format is a variant here
//! (or of [`MeshFormat`]), its extension in [`EXTENSIONS`], and its reader and writer.

use std::path::Path;

use crate::mesh::{MAX_MESH_FILE_BYTES, MeshFormat};

/// The file name extensions import and export understand, for file dialogs.
pub const EXTENSIONS: [&str; 4] = ["wrl", "stl", "obj", "glb"];

/// A file format, from a path's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileFormat {
    /// FVRML text (`.wrl`).
    Fvrml,
    /// A triangle mesh (`.stl`, `.obj`, `.glb`).
    Mesh(MeshFormat),
}

impl FileFormat {
    /// The format of `path`'s extension, if it is one of [`EXTENSIONS`].
    pub fn of(path: &Path) -> Option<FileFormat> {
        let extension = path.extension()?.to_str()?;
        if extension.eq_ignore_ascii_case("wrl") {
            return Some(FileFormat::Fvrml);
        }
        MeshFormat::from_extension(extension).map(FileFormat::Mesh)
    }

    /// The format's name for people.
    pub fn name(self) -> &'static str {
        match self {
            FileFormat::Fvrml => "FVRML",
            FileFormat::Mesh(MeshFormat::StlBinary) => "binary STL",
            FileFormat::Mesh(MeshFormat::StlAscii) => "ASCII STL",
            FileFormat::Mesh(MeshFormat::Obj) => "Wavefront OBJ",
            FileFormat::Mesh(MeshFormat::Glb) => "binary glTF",
        }
    }

    /// The largest file of this format read, in bytes: a reader refuses a longer file
    /// before reading it.
    pub fn max_file_bytes(self) -> u64 {
        match self {
            FileFormat::Fvrml => crate::fvrml::MAX_FILE_BYTES as u64,
            FileFormat::Mesh(_) => MAX_MESH_FILE_BYTES,
        }
    }

    /// Whether a file of this format may name other files to read with it (FVRML's
    /// `Inline`s, a grid's samples), through the resolver [`crate::import::read`] takes.
    pub fn reads_other_files(self) -> bool {
        match self {
            FileFormat::Fvrml => true,
            FileFormat::Mesh(_) => false,
        }
    }
}
