//! Reading a file's bytes into the object model: an FVRML scene's objects and groups, or one
//! object whose geometry is a mesh file's triangles. This is the part of importing that knows
//! formats; the caller reads the bytes (bounded by [`FileFormat::max_file_bytes`]) and turns
//! what [`read`] returns into whatever it makes of objects (the app: replicated ops).
//!
//! - `.wrl`: the FVRML scene as [`fvrml::load`] reads it, its `Inline`s (and grids' samples)
//!   through the caller's resolver.
//! - `.stl`, `.obj`, `.glb`: one object named after the file, whose geometry is the mesh (its
//!   signed distance, positive inside) in a domain around it (grown by
//!   [`MESH_DOMAIN_MARGIN`]), in the file's own coordinates.
//!
//! Every failure is an [`ImportError`] naming the file and where in it (line and column, byte
//! offset or JSON path, as the reader reports); warnings are lines in the same form.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DVec3;
use model::mesh::TriMesh;
use model::object::{Domain, Geometry, MAX_NAME_BYTES, ObjectData, Shape, Transform};
use model::scene::Scene;

use crate::fvrml::{self, LoadOptions};
use crate::registry::FileFormat;

/// The domain around an imported mesh: its box grown on every side by this fraction of the
/// box's diagonal, so sculpting just outside the surface stays inside the domain.
pub const MESH_DOMAIN_MARGIN: f64 = 0.05;
/// The smallest margin of an imported mesh's domain (scene units), for flat meshes.
pub const MIN_MESH_DOMAIN_MARGIN: f64 = 1e-3;

/// Why a file's bytes could not be read into objects. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The extension is not one of [`crate::registry::EXTENSIONS`].
    #[error("{}: unknown file type; import reads .wrl (FVRML), .stl, .obj and .glb", .path.display())]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// A text format's bytes are not UTF-8.
    #[error("{}: not UTF-8 text", .path.display())]
    NotText {
        /// The file.
        path: PathBuf,
    },
    /// The FVRML text does not load; one located error per line.
    #[error("{}\n{}: cannot import the scene", .errors.join("\n"), .path.display())]
    Scene {
        /// The file.
        path: PathBuf,
        /// `file:line:column: error: message`, the file being an `Inline` path or this one.
        errors: Vec<String>,
    },
    /// The mesh file is malformed.
    #[error("{}: {error}", .path.display())]
    Mesh {
        /// The file.
        path: PathBuf,
        /// The reader's error, with its byte offset, line and column, or JSON path (in the
        /// message, not as a source, so that it is printed once).
        error: crate::mesh::ReadError,
    },
    /// The mesh file holds no triangles.
    #[error("{}: the mesh has no triangles", .path.display())]
    EmptyMesh {
        /// The file.
        path: PathBuf,
    },
}

/// What a file holds, read.
#[derive(Clone, Debug)]
pub enum Contents {
    /// A scene file's objects and groups (their ids are the reader's, see
    /// [`fvrml::LoadOptions`]).
    Scene(Scene),
    /// A mesh file's one object: named after the file, its geometry the mesh in a domain
    /// around it, everything else default.
    Mesh(Box<ObjectData>),
}

/// A file read: what it holds and what was skipped or read leniently.
#[derive(Clone, Debug)]
pub struct Read {
    /// The objects.
    pub contents: Contents,
    /// FVRML warnings with their locations, an open mesh: one line each, naming the file.
    pub warnings: Vec<String>,
}

/// The format of `path`'s extension, or the error that names it unknown.
pub fn format_of(path: &Path) -> Result<FileFormat, ImportError> {
    FileFormat::of(path).ok_or_else(|| ImportError::UnknownFormat { path: path.into() })
}

/// Reads `bytes`, the file at `path` in `format`, into objects. `path` only names the file
/// (in errors, warnings and a mesh's object) and is never opened; files it names are read
/// through `resolve` (see [`fvrml::load`]), only when [`FileFormat::reads_other_files`].
pub fn read(
    path: &Path,
    format: FileFormat,
    bytes: &[u8],
    resolve: &mut dyn FnMut(&str) -> Result<Vec<u8>, String>,
) -> Result<Read, ImportError> {
    match format {
        FileFormat::Fvrml => read_scene(path, bytes, resolve),
        FileFormat::Mesh(mesh_format) => {
            let mesh = mesh_format.read(bytes).map_err(|error| ImportError::Mesh {
                path: path.into(),
                error,
            })?;
            read_mesh(path, mesh)
        }
    }
}

fn read_scene(
    path: &Path,
    bytes: &[u8],
    resolve: &mut dyn FnMut(&str) -> Result<Vec<u8>, String>,
) -> Result<Read, ImportError> {
    let text =
        std::str::from_utf8(bytes).map_err(|_| ImportError::NotText { path: path.into() })?;
    let shown = path.display().to_string();
    let loaded =
        fvrml::load(text, &LoadOptions::default(), resolve).map_err(|e| ImportError::Scene {
            path: path.into(),
            errors: e.errors().map(|i| located(i, &shown)).collect(),
        })?;
    let warnings = loaded.warnings.iter().map(|w| located(w, &shown)).collect();
    Ok(Read {
        contents: Contents::Scene(loaded.scene),
        warnings,
    })
}

/// An FVRML issue as `file:line:column: severity: message`.
fn located(issue: &fvrml::Issue, shown: &str) -> String {
    let file = issue.location.file.as_deref().unwrap_or(shown);
    let severity = if issue.is_error() { "error" } else { "warning" };
    let (line, column) = (issue.location.line, issue.location.column);
    format!("{file}:{line}:{column}: {severity}: {}", issue.message)
}

fn read_mesh(path: &Path, mesh: TriMesh) -> Result<Read, ImportError> {
    if mesh.is_empty() {
        return Err(ImportError::EmptyMesh { path: path.into() });
    }
    let mut warnings = Vec::new();
    if !mesh.is_closed() {
        warnings.push(format!(
            "{}: warning: the mesh is not closed, so it bounds no volume exactly: its inside is \
             decided by a majority of rays, which fills small holes",
            path.display()
        ));
    }
    let data = ObjectData {
        name: mesh_name(path),
        geometry: Some(mesh_geometry(Arc::new(mesh))),
        ..ObjectData::default()
    };
    Ok(Read {
        contents: Contents::Mesh(Box::new(data)),
        warnings,
    })
}

/// The mesh in a domain around it, in its own coordinates.
pub fn mesh_geometry(mesh: Arc<TriMesh>) -> Geometry {
    let bounds = mesh.bounds();
    let margin = (MESH_DOMAIN_MARGIN * bounds.size().length()).max(MIN_MESH_DOMAIN_MARGIN);
    Geometry {
        domain: Some(Domain::new(
            bounds.center(),
            bounds.size() + DVec3::splat(2.0 * margin),
        )),
        shape: Shape::Mesh(mesh),
        transform: Transform::IDENTITY,
    }
}

/// An object name from a file name: its stem, cut to the name limit.
fn mesh_name(path: &Path) -> String {
    let stem = path
        .file_stem()
        .map_or_else(|| "mesh".into(), |s| s.to_string_lossy().into_owned());
    let mut end = stem.len().min(MAX_NAME_BYTES);
    while !stem.is_char_boundary(end) {
        end -= 1;
    }
    stem[..end].to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshFormat;

    fn no_files(url: &str) -> Result<Vec<u8>, String> {
        Err(format!("no file {url}"))
    }

    #[test]
    fn a_mesh_file_is_one_object_named_after_it_in_a_domain_around_it() {
        let cube = model::mesh::shapes::cube(DVec3::splat(-1.0), DVec3::new(1.0, 2.0, 3.0));
        let mut bytes = Vec::new();
        MeshFormat::Obj.write(&cube, &mut bytes);
        let path = Path::new("some/folder/block.OBJ");
        let format = format_of(path).unwrap();
        let file = read(path, format, &bytes, &mut no_files).unwrap();
        assert!(file.warnings.is_empty(), "{:?}", file.warnings);
        let Contents::Mesh(data) = file.contents else {
            panic!("{:?}", file.contents);
        };
        assert_eq!(data.name, "block");
        let geometry = data.geometry.as_ref().unwrap();
        let domain = geometry.domain.unwrap().aabb();
        assert!(domain.lo.cmplt(DVec3::splat(-1.0)).all(), "{domain:?}");
        assert!(
            domain.hi.cmpgt(DVec3::new(1.0, 2.0, 3.0)).all(),
            "{domain:?}"
        );
        let object = model::object::Object::new(*data).unwrap();
        let p = DVec3::new(0.9, 1.5, -0.5);
        assert_eq!(object.sampler().value(p, 0.0), cube.signed_distance(p));
    }

    #[test]
    fn an_open_mesh_is_read_with_a_warning_and_an_empty_one_is_refused() {
        let (positions, mut triangles) =
            model::mesh::shapes::cube(DVec3::ZERO, DVec3::ONE).into_parts();
        triangles.pop();
        let open = TriMesh::new(positions, triangles).unwrap();
        let mut bytes = Vec::new();
        MeshFormat::Glb.write(&open, &mut bytes);
        let path = Path::new("open.glb");
        let file = read(path, format_of(path).unwrap(), &bytes, &mut no_files).unwrap();
        assert_eq!(file.warnings.len(), 1);
        assert!(file.warnings[0].starts_with("open.glb: warning: the mesh is not closed"));
        let path = Path::new("empty.obj");
        let empty = read(path, format_of(path).unwrap(), b"v 0 0 0\n", &mut no_files);
        assert!(matches!(empty, Err(ImportError::EmptyMesh { .. })));
    }

    #[test]
    fn errors_name_the_file_and_where_in_it() {
        let unknown = format_of(Path::new("notes.txt")).unwrap_err();
        assert_eq!(
            unknown.to_string(),
            "notes.txt: unknown file type; import reads .wrl (FVRML), .stl, .obj and .glb"
        );
        let path = Path::new("scene.wrl");
        let not_text = read(path, FileFormat::Fvrml, &[0xff, 0xfe], &mut no_files).unwrap_err();
        assert_eq!(not_text.to_string(), "scene.wrl: not UTF-8 text");
        let text = b"#VRML V2.0 utf8\nFShape { geometry FGeometry { definition \"1-\" } }\n";
        let scene = read(path, FileFormat::Fvrml, text, &mut no_files).unwrap_err();
        let ImportError::Scene { errors, .. } = &scene else {
            panic!("{scene}");
        };
        assert!(errors[0].starts_with("scene.wrl:2:"), "{errors:?}");
        assert!(
            scene
                .to_string()
                .ends_with("scene.wrl: cannot import the scene")
        );
        let path = Path::new("broken.stl");
        let mesh = read(
            path,
            format_of(path).unwrap(),
            b"solid x\nfacet",
            &mut no_files,
        );
        assert!(
            mesh.unwrap_err()
                .to_string()
                .starts_with("broken.stl: STL: ")
        );
    }

    #[test]
    fn a_scene_reads_its_inlines_through_the_resolver() {
        let text = b"#VRML V2.0 utf8\nInline { url \"part.wrl\" }\n";
        let mut asked = Vec::new();
        let mut resolve = |url: &str| {
            asked.push(url.to_string());
            Ok(b"#VRML V2.0 utf8\nFShape { geometry Sphere { radius 0.5 } }\n".to_vec())
        };
        let path = Path::new("room.wrl");
        let file = read(path, FileFormat::Fvrml, text, &mut resolve).unwrap();
        let Contents::Scene(scene) = file.contents else {
            panic!("{:?}", file.contents);
        };
        assert_eq!(scene.len(), 1);
        assert_eq!(asked, ["part.wrl"]);
    }
}
