//! Files in and out of a session, shared by `sculpt import`/`sculpt export` and the window's
//! menu: [`import`] plans the ops that bring a file's objects into a session, [`export`]
//! writes a scene (or one object) to a file.
//!
//! Formats, by extension (any case): `.wrl` FVRML (`formats::fvrml`), `.stl` (binary when
//! written, binary or ASCII when read), `.obj` and `.glb` (`model::mesh`).
//!
//! Importing is planning, never authoring: [`import`] returns the payloads and the caller
//! authors them in order. A file is read whole within a named limit before it is parsed
//! ([`formats::fvrml::MAX_FILE_BYTES`], [`MAX_MESH_FILE_BYTES`]); its `Inline`s may read only
//! files in its own folder, or under a root the user names ([`import_within`], checked by
//! [`crate::files::InlineResolver`]); an object too large for one op
//! ([`replication::payload::MAX_PAYLOAD_BYTES`]: a mesh of a few hundred triangles) is
//! authored in parts ([`replication::shape::parts`]), up to
//! [`replication::shape::parts::MAX_ASSEMBLED_BYTES`] (a mesh of about 170 000 triangles), and
//! a file may bring at most [`MAX_IMPORT_OBJECTS`] objects. Any failure is an error naming
//! the file and where in it (line and column, byte offset or JSON path, as the reader
//! reports), and then no payload at all is returned.
//!
//! Exporting meshes each object as `sculpt render` does (`render::snapshot::build`: the
//! octree mesher over the object's geometry folded with its edits, parametric shapes
//! triangulated, imported meshes as they are, displacement applied) at the depth asked,
//! places it in scene coordinates (groups, transform and motion at t = 0; +y up, as in
//! FVRML and glTF) and merges every object into one mesh. Colours, materials and physics
//! are not written to mesh files. FVRML holds everything, the edit histories included
//! (`FEdit` nodes, `formats::fvrml`). The file is written to a temporary file beside the target, synced, then
//! renamed over it, so a failed export leaves no partial file.
//!
//! Guarantee: a mesh exported from a closed solid (an implicit solid inside its box, a
//! closed mesh, anything sculpted) is closed, and [`ExportReport`] says so per object and
//! for the file, checked with [`TriMesh::is_closed`]. Non-guarantees: exported meshes may
//! self-intersect where objects overlap (objects are merged, not united), parametric
//! solids are written as their six faces and may not be closed, and an STL reader merges
//! corners of exactly equal coordinates across objects.

use std::collections::BTreeMap;
use std::fmt;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use formats::fvrml::{self, LoadOptions};
use formats::mesh::MeshFormat;
use glam::DVec3;
use model::mesh::TriMesh;
use model::object::{ColorDef, Domain, Geometry, Object, ObjectData, ParametricKind, Shape};
use model::scene::{GroupId, ObjectId, Scene};
use replication::shape::parts::{self, MAX_ASSEMBLED_BYTES, SplitError};
use replication::shape::{IdSource, ShapePayload};

use crate::files::{InlineResolver, read_scene_text};

/// Most objects one imported file may bring into a session (each is an op, stored and sent
/// to every peer).
pub const MAX_IMPORT_OBJECTS: usize = 1024;
/// Most groups one imported file may bring.
pub const MAX_IMPORT_GROUPS: usize = 1024;
/// Largest mesh file read, in bytes. An object is at most
/// [`replication::shape::parts::MAX_ASSEMBLED_BYTES`] as ops, so files this large are refused
/// for their size long before; the limit only stops a huge file being read at all.
pub const MAX_MESH_FILE_BYTES: u64 = 16 << 20;
/// The domain around an imported mesh: its box grown on every side by this fraction of the
/// box's diagonal, so sculpting just outside the surface stays inside the domain.
pub const MESH_DOMAIN_MARGIN: f64 = 0.05;
/// The smallest margin of an imported mesh's domain (scene units), for flat meshes.
pub const MESH_DOMAIN_MARGIN_MIN: f64 = 1e-3;
/// The file name extensions import and export understand, for file dialogs.
pub const EXTENSIONS: [&str; 4] = ["wrl", "stl", "obj", "glb"];
/// The scene time at which exported objects are meshed and placed.
const EXPORT_T_SECS: f64 = 0.0;

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
}

/// Why a file could not be imported. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The extension is not one of [`EXTENSIONS`].
    #[error("{}: unknown file type; import reads .wrl (FVRML), .stl, .obj and .glb", .path.display())]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The file could not be read (missing, unreadable, over its size limit).
    #[error("{message}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What went wrong, with the path.
        message: String,
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
        error: formats::mesh::ReadError,
    },
    /// The mesh file holds no triangles.
    #[error("{}: the mesh has no triangles", .path.display())]
    EmptyMesh {
        /// The file.
        path: PathBuf,
    },
    /// More objects or groups than [`MAX_IMPORT_OBJECTS`] or [`MAX_IMPORT_GROUPS`].
    #[error("{}: {count} {what}, more than the {limit} one import may bring", .path.display())]
    TooMany {
        /// The file.
        path: PathBuf,
        /// "objects" or "groups".
        what: &'static str,
        /// How many the file holds.
        count: usize,
        /// The limit.
        limit: usize,
    },
    /// An object is larger than a change authored in parts may be.
    #[error(
        "{}: {what} takes {n_bytes} bytes as ops, more than the {MAX_ASSEMBLED_BYTES} one \
         object may take{hint}", .path.display()
    )]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The object, in words.
        what: String,
        /// Its encoded size.
        n_bytes: usize,
        /// What to do about it.
        hint: String,
    },
    /// An object is not valid (a check the reader does not make).
    #[error("{}: {what}: {reason}", .path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The object, in words.
        what: String,
        /// Why.
        reason: String,
    },
    /// The ids from `next` on would use up this peer's counter.
    #[error("{}: no object ids left for {count} more objects and groups", .path.display())]
    IdsExhausted {
        /// The file.
        path: PathBuf,
        /// How many ids were needed.
        count: usize,
    },
}

/// What [`import`] planned: the payloads to author in order, and what they make.
#[derive(Clone, Debug)]
pub struct Imported {
    /// `SetGroup` ops (parents first), then one `Create` per object; an object larger than
    /// one op comes as its `Part`s and the `Assemble` that completes it.
    pub payloads: Vec<ShapePayload>,
    /// One line per payload, in the same order, saying what it makes (a part: which one).
    pub made: Vec<String>,
    /// What was skipped or read leniently (FVRML warnings with their locations, an open
    /// mesh), one line each.
    pub warnings: Vec<String>,
    /// The id after the last one used: where a following import should start.
    pub next: IdSource,
}

/// The ops that bring the objects of the file at `path` into a session, with ids from
/// `next` on ([`crate::engine::View::next_object`]); see [`import`].
pub fn import_payloads(path: &Path, next: IdSource) -> Result<Vec<ShapePayload>, ImportError> {
    import(path, next).map(|imported| imported.payloads)
}

/// Reads the file at `path` and plans the ops that bring its objects into a session.
///
/// - `.wrl`: every object of the FVRML scene becomes a `Create`; its groups become
///   `SetGroup`s authored before the objects, which are created in their groups. `Inline`s
///   may read only files in the file's own folder.
/// - `.stl`, `.obj`, `.glb`: one object named after the file, whose geometry is the mesh
///   (its signed distance, positive inside) in a domain around it (grown by
///   [`MESH_DOMAIN_MARGIN`]), in the file's own coordinates.
///
/// Ids: groups take the ids of the counters from `next` on, then objects the ones after
/// them, so the highest counter used is an object's and the view's next object moves past
/// all of them.
pub fn import(path: &Path, next: IdSource) -> Result<Imported, ImportError> {
    let dir = path.parent().unwrap_or(Path::new(""));
    import_within(path, next, dir)
}

/// [`import`], with `Inline` files allowed anywhere inside `inline_root` (which the user
/// chose: `sculpt import --inline-root DIR`) rather than only in the file's own folder.
pub fn import_within(
    path: &Path,
    next: IdSource,
    inline_root: &Path,
) -> Result<Imported, ImportError> {
    match FileFormat::of(path) {
        Some(FileFormat::Fvrml) => import_scene(path, next, inline_root),
        Some(FileFormat::Mesh(format)) => import_mesh(path, format, next),
        None => Err(ImportError::UnknownFormat { path: path.into() }),
    }
}

fn import_scene(path: &Path, next: IdSource, inline_root: &Path) -> Result<Imported, ImportError> {
    let read_error = |message: String| ImportError::Read {
        path: path.into(),
        message,
    };
    let text = read_scene_text(path).map_err(read_error)?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let inlines = InlineResolver::new(dir, inline_root).map_err(read_error)?;
    let mut resolve = |url: &str| inlines.read(url);
    let shown = path.display().to_string();
    let loaded = fvrml::load(&text, &LoadOptions::default(), &mut resolve).map_err(|e| {
        ImportError::Scene {
            path: path.into(),
            errors: e.errors().map(|i| located(i, &shown)).collect(),
        }
    })?;
    let mut imported = scene_payloads(path, &loaded.scene, next)?;
    let mut warnings: Vec<String> = loaded.warnings.iter().map(|w| located(w, &shown)).collect();
    warnings.append(&mut imported.warnings);
    imported.warnings = warnings;
    Ok(imported)
}

/// An FVRML issue as `file:line:column: severity: message`.
fn located(issue: &fvrml::Issue, shown: &str) -> String {
    let file = issue.location.file.as_deref().unwrap_or(shown);
    let severity = if issue.is_error() { "error" } else { "warning" };
    let (line, column) = (issue.location.line, issue.location.column);
    format!("{file}:{line}:{column}: {severity}: {}", issue.message)
}

/// The payloads of a loaded scene: groups parents first, then objects, ids from `next`.
pub(crate) fn scene_payloads(
    path: &Path,
    scene: &Scene,
    next: IdSource,
) -> Result<Imported, ImportError> {
    let too_many = |what, count, limit| ImportError::TooMany {
        path: path.into(),
        what,
        count,
        limit,
    };
    if scene.len() > MAX_IMPORT_OBJECTS {
        return Err(too_many("objects", scene.len(), MAX_IMPORT_OBJECTS));
    }
    let mut imported = Imported {
        payloads: Vec::new(),
        made: Vec::new(),
        warnings: Vec::new(),
        next,
    };
    if scene.is_empty() {
        imported
            .warnings
            .push(format!("{}: the file holds no objects", path.display()));
        return Ok(imported);
    }
    let groups = groups_parents_first(scene);
    if groups.len() > MAX_IMPORT_GROUPS {
        return Err(too_many("groups", groups.len(), MAX_IMPORT_GROUPS));
    }
    let ids = IdRange::new(path, next, groups.len() + scene.len())?;
    let group_ids = group_payloads(path, scene, &groups, &ids, &mut imported)?;
    let new_group = |g: Option<GroupId>| g.and_then(|g| group_ids.get(&g).copied());
    for (k, (_, entry)) in scene.objects().enumerate() {
        let data = entry.object.data();
        let source = ids.at(groups.len() + k);
        let payload = source.create(data.clone(), new_group(entry.group));
        let object = source.id();
        let what = format!("object \"{}\"", data.name);
        let mesh = match data.geometry.as_ref().map(|g| &g.shape) {
            Some(Shape::Mesh(m)) => Some(&**m),
            _ => None,
        };
        let made = format!("object {object} \"{}\": {}", data.name, kind(data));
        let ops = payload_ops(path, &what, payload, mesh)?;
        push_ops(&mut imported, ops, made);
    }
    imported.next = ids.end;
    Ok(imported)
}

/// Appends a `SetGroup` for each of `groups` (parents first), with ids from `ids` in that
/// order so that each parent exists when its children are set; returns the new ids.
fn group_payloads(
    path: &Path,
    scene: &Scene,
    groups: &[GroupId],
    ids: &IdRange,
    imported: &mut Imported,
) -> Result<BTreeMap<GroupId, u64>, ImportError> {
    let group_ids: BTreeMap<GroupId, u64> = (groups.iter().enumerate())
        .map(|(k, g)| (*g, ids.at(k).id()))
        .collect();
    for (k, g) in groups.iter().enumerate() {
        let new = ids.at(k);
        let Some(group) = scene.group(*g) else {
            continue;
        };
        let value = model::scene::Group {
            parent: group
                .parent
                .and_then(|p| group_ids.get(&p).copied())
                .map(GroupId),
            ..group.clone()
        };
        let what = format!("group \"{}\"", value.name);
        let made = format!("group {} \"{}\"", new.id(), value.name);
        let payload = ShapePayload::SetGroup {
            group: new.id(),
            value: Some(Box::new(value)),
        };
        let ops = payload_ops(path, &what, payload, None)?;
        push_ops(imported, ops, made);
    }
    Ok(group_ids)
}

/// The scene's groups ordered so that each comes after its parent: by depth, then id.
fn groups_parents_first(scene: &Scene) -> Vec<GroupId> {
    let depth = |mut g: GroupId| {
        let mut d = 0;
        while let Some(parent) = scene.group(g).and_then(|group| group.parent) {
            d += 1;
            g = parent;
            if d > model::limits::MAX_GROUP_DEPTH {
                break;
            }
        }
        d
    };
    let mut groups: Vec<(usize, GroupId)> = scene.groups().map(|(g, _)| (depth(g), g)).collect();
    groups.sort_unstable();
    groups.into_iter().map(|(_, g)| g).collect()
}

/// `count` consecutive counters of one author from `first`.
struct IdRange {
    first: IdSource,
    end: IdSource,
}

impl IdRange {
    fn new(path: &Path, first: IdSource, count: usize) -> Result<IdRange, ImportError> {
        match first.skip(count as u64) {
            Some(end) => Ok(IdRange { first, end }),
            None => Err(ImportError::IdsExhausted {
                path: path.into(),
                count,
            }),
        }
    }

    /// The source of the `k`-th id of the range (`k` below its count).
    fn at(&self, k: usize) -> IdSource {
        IdSource {
            counter: self.first.counter + k as u32,
            ..self.first
        }
    }
}

/// What kind of object `data` describes, in words.
fn kind(data: &ObjectData) -> String {
    match data.geometry.as_ref().map(|g| &g.shape) {
        None => "no geometry".into(),
        Some(Shape::Implicit(_)) => "implicit solid".into(),
        Some(Shape::Parametric { kind, .. }) => format!("parametric {}", parametric_name(*kind)),
        Some(Shape::Mesh(m)) => format!(
            "a mesh of {} triangles, {}",
            m.triangles().len(),
            if m.is_closed() { "closed" } else { "open" }
        ),
    }
}

fn parametric_name(kind: ParametricKind) -> &'static str {
    match kind {
        ParametricKind::Curve => "curve",
        ParametricKind::Surface => "surface",
        ParametricKind::Solid => "solid",
    }
}

/// Checks that `payload` is valid and returns the ops that author it: itself, or its parts
/// and their assembly when it is larger than one op ([`parts::split`]); `mesh` gives a hint
/// when it is too large even for that.
fn payload_ops(
    path: &Path,
    what: &str,
    payload: ShapePayload,
    mesh: Option<&TriMesh>,
) -> Result<Vec<ShapePayload>, ImportError> {
    payload.validate().map_err(|reason| ImportError::Invalid {
        path: path.into(),
        what: what.into(),
        reason,
    })?;
    let n_bytes = match parts::split(payload) {
        Ok(ops) => return Ok(ops),
        Err(SplitError::TooLarge { n_bytes }) => n_bytes,
        Err(e) => {
            return Err(ImportError::Invalid {
                path: path.into(),
                what: what.into(),
                reason: e.to_string(),
            });
        }
    };
    let hint = match mesh {
        Some(m) => {
            let n = m.triangles().len();
            // Bytes grow about linearly with triangles; aim 10% under the limit.
            let fits = n * MAX_ASSEMBLED_BYTES / n_bytes * 9 / 10;
            format!(
                "; it has {n} triangles and {} vertices: simplify it to about {fits} triangles",
                m.positions().len()
            )
        }
        None => String::new(),
    };
    Err(ImportError::TooLarge {
        path: path.into(),
        what: what.into(),
        n_bytes,
        hint,
    })
}

/// Appends the ops of one planned change, each with the line saying what it makes (`made`
/// for the last, which completes it; the parts before it say which part they are).
fn push_ops(imported: &mut Imported, ops: Vec<ShapePayload>, made: String) {
    let n_parts = ops.len() - 1;
    for (i, op) in ops.into_iter().enumerate() {
        let line = if i == n_parts {
            made.clone()
        } else {
            format!("{made}: part {} of {n_parts}", i + 1)
        };
        imported.made.push(line);
        imported.payloads.push(op);
    }
}

fn import_mesh(path: &Path, format: MeshFormat, next: IdSource) -> Result<Imported, ImportError> {
    let bytes = read_bounded(path, MAX_MESH_FILE_BYTES)?;
    let mesh = format.read(&bytes).map_err(|error| ImportError::Mesh {
        path: path.into(),
        error,
    })?;
    if mesh.is_empty() {
        return Err(ImportError::EmptyMesh { path: path.into() });
    }
    let name = mesh_name(path);
    let ids = IdRange::new(path, next, 1)?;
    let mesh = Arc::new(mesh);
    let data = ObjectData {
        name: name.clone(),
        geometry: Some(mesh_geometry(mesh.clone())),
        appearance: model::object::Appearance {
            diffuse: Some(ColorDef::Constant(crate::command::NEW_OBJECT_COLOUR)),
            ..Default::default()
        }
        .into(),
        ..ObjectData::default()
    };
    let made = format!("object {} \"{name}\": {}", ids.first.id(), kind(&data));
    let payload = ids.first.create(data, None);
    let ops = payload_ops(path, &format!("the mesh \"{name}\""), payload, Some(&mesh))?;
    let mut warnings = Vec::new();
    if !mesh.is_closed() {
        warnings.push(format!(
            "{}: warning: the mesh is not closed, so it bounds no volume exactly: its inside is \
             decided by a majority of rays, which fills small holes",
            path.display()
        ));
    }
    let mut imported = Imported {
        payloads: Vec::new(),
        made: Vec::new(),
        warnings,
        next: ids.end,
    };
    push_ops(&mut imported, ops, made);
    Ok(imported)
}

/// The mesh in a domain around it, in its own coordinates.
fn mesh_geometry(mesh: Arc<TriMesh>) -> Geometry {
    let bounds = mesh.bounds();
    let margin = (MESH_DOMAIN_MARGIN * bounds.size().length()).max(MESH_DOMAIN_MARGIN_MIN);
    Geometry {
        domain: Some(Domain::new(
            bounds.center(),
            bounds.size() + DVec3::splat(2.0 * margin),
        )),
        shape: Shape::Mesh(mesh),
        transform: model::object::Transform::IDENTITY,
    }
}

/// An object name from a file name: its stem, cut to the name limit.
fn mesh_name(path: &Path) -> String {
    let stem = path
        .file_stem()
        .map_or_else(|| "mesh".into(), |s| s.to_string_lossy().into_owned());
    let mut end = stem.len().min(model::object::MAX_NAME_BYTES);
    while !stem.is_char_boundary(end) {
        end -= 1;
    }
    stem[..end].to_string()
}

/// The file's bytes through [`crate::files::read_bounded`], refused before reading when
/// over `limit` or not a regular file.
fn read_bounded(path: &Path, limit: u64) -> Result<Vec<u8>, ImportError> {
    crate::files::read_bounded(path, limit).map_err(|message| ImportError::Read {
        path: path.into(),
        message,
    })
}

/// Why an export failed. Nothing was written at `path` (a temporary file is removed).
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The extension is not one of [`EXTENSIONS`].
    #[error("{}: unknown file type; export writes .stl (binary), .obj, .glb and .wrl (FVRML)", .path.display())]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The object asked for is not in the scene.
    #[error("object {} is not in the scene", .0.0)]
    NoObject(ObjectId),
    /// Nothing to write: no objects, or no object has triangles.
    #[error("nothing to export: {0}")]
    Empty(String),
    /// The octree depth is out of range.
    #[error(
        "depth {depth} is more than the mesher's maximum of {}",
        render::mesh::octree::OCTREE_DEPTH_MAX
    )]
    Depth {
        /// The depth asked for.
        depth: u8,
    },
    /// The scene could not be meshed (bad settings).
    #[error(transparent)]
    Mesh(#[from] render::snapshot::SnapshotError),
    /// The merged mesh is over `model::mesh`'s limits.
    #[error("the merged mesh cannot be written: {0}")]
    TooLarge(model::mesh::MeshError),
    /// The file could not be written.
    #[error("cannot write {}: {error}", .path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why (in the message, not as a source, so that it is printed once).
        error: std::io::Error,
    },
}

/// What [`export`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportReport {
    /// The file written.
    pub path: PathBuf,
    /// Its format.
    pub format: FileFormat,
    /// Its length.
    pub n_bytes: u64,
    /// Triangles written (0 for FVRML).
    pub n_triangles: usize,
    /// Vertices written (0 for FVRML).
    pub n_vertices: usize,
    /// Whether the written mesh is closed, as a reader reads it back (for STL, with corners
    /// merged); `None` for FVRML.
    pub closed: Option<bool>,
    /// Each object exported, by id.
    pub objects: Vec<ExportedObject>,
    /// What a person should know: objects not exported and why, solids whose mesh is open.
    pub notes: Vec<String>,
}

/// One object of an export.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportedObject {
    /// Its id.
    pub id: ObjectId,
    /// Its name.
    pub name: String,
    /// Its active edits (sculpting and painting).
    pub n_edits: usize,
    /// Whether it encloses a volume (implicit, a closed mesh, a parametric solid, sculpted),
    /// so that its mesh should be closed.
    pub solid: bool,
    /// Its triangles in the file (0 for FVRML).
    pub n_triangles: usize,
    /// Whether its mesh is closed; `None` for FVRML.
    pub closed: Option<bool>,
    /// Why it (or part of it) was not meshed, if so.
    pub skipped: Option<String>,
}

impl ExportedObject {
    /// `object ID "name"`, or `object ID` when it has no name.
    pub fn label(&self) -> String {
        if self.name.is_empty() {
            format!("object {}", self.id.0)
        } else {
            format!("object {} \"{}\"", self.id.0, self.name)
        }
    }
}

impl fmt::Display for ExportReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "wrote {} ({}, {} bytes",
            self.path.display(),
            self.format.name(),
            self.n_bytes
        )?;
        if let Some(closed) = self.closed {
            let closed = if closed { "closed" } else { "not closed" };
            write!(
                f,
                ", {} triangles, {} vertices, {closed}",
                self.n_triangles, self.n_vertices
            )?;
        }
        writeln!(f, ")")?;
        for o in &self.objects {
            write!(f, "  {}:", o.label())?;
            if let Some(closed) = o.closed {
                let closed = if closed { "closed" } else { "open" };
                write!(f, " {} triangles, {closed},", o.n_triangles)?;
            }
            let solid = if o.solid { "solid" } else { "surface" };
            writeln!(f, " {solid}, {} edits", o.n_edits)?;
        }
        for note in &self.notes {
            writeln!(f, "note: {note}")?;
        }
        Ok(())
    }
}

/// Writes `scene` (or only `object`) to `path`, in the format of its extension (see the
/// module documentation), meshing implicit shapes at octree `depth` (the render default is
/// `render::snapshot::SnapshotSettings::default().depth`). Meshing takes time: take a clone
/// of the view's scene rather than meshing under the view's lock.
pub fn export(
    scene: &Scene,
    object: Option<ObjectId>,
    path: &Path,
    depth: u8,
) -> Result<ExportReport, ExportError> {
    let format =
        FileFormat::of(path).ok_or_else(|| ExportError::UnknownFormat { path: path.into() })?;
    let ids: Vec<ObjectId> = match object {
        Some(id) if scene.object(id).is_none() => return Err(ExportError::NoObject(id)),
        Some(id) => vec![id],
        None => scene.objects().map(|(id, _)| id).collect(),
    };
    if ids.is_empty() {
        return Err(ExportError::Empty("the scene has no objects".into()));
    }
    let mut report = ExportReport {
        path: path.into(),
        format,
        n_bytes: 0,
        n_triangles: 0,
        n_vertices: 0,
        closed: None,
        objects: Vec::new(),
        notes: Vec::new(),
    };
    let bytes = match format {
        FileFormat::Fvrml => fvrml_bytes(scene, object, &mut report),
        FileFormat::Mesh(mesh_format) => mesh_bytes(scene, &ids, mesh_format, depth, &mut report)?,
    };
    write_atomically(path, &bytes)?;
    report.n_bytes = bytes.len() as u64;
    Ok(report)
}

/// The scene (or the one object, with the groups above it) as FVRML text.
fn fvrml_bytes(scene: &Scene, object: Option<ObjectId>, report: &mut ExportReport) -> Vec<u8> {
    let one;
    let scene = match object.and_then(|id| one_object_scene(scene, id)) {
        Some(s) => {
            one = s;
            &one
        }
        None => scene,
    };
    for (id, entry) in scene.objects() {
        report.objects.push(exported_object(id, &entry.object));
    }
    fvrml::write(&fvrml::save(scene)).into_bytes()
}

/// A scene holding only `id` and the chain of groups it hangs from.
fn one_object_scene(scene: &Scene, id: ObjectId) -> Option<Scene> {
    let entry = scene.scene_object(id)?;
    let mut chain = Vec::new();
    let mut up = entry.group;
    while let Some(g) = up {
        let group = scene.group(g)?;
        chain.push((g, group.clone()));
        up = group.parent;
        if chain.len() > model::limits::MAX_GROUP_DEPTH {
            return None;
        }
    }
    let mut one = Scene::new();
    for (g, group) in chain.into_iter().rev() {
        one.set_group(g, group).ok()?;
    }
    one.insert_object(id, entry.object.clone(), entry.group)
        .ok()?;
    Some(one)
}

/// The object's row of the report, before meshing.
fn exported_object(id: ObjectId, object: &Object) -> ExportedObject {
    let entries = object.history().entries();
    let sculpted = entries.iter().any(|e| e.active && e.edit.is_geometric());
    let solid = sculpted
        || match object.data().geometry.as_ref().map(|g| &g.shape) {
            Some(Shape::Implicit(_)) => true,
            Some(Shape::Mesh(m)) => m.is_closed(),
            Some(Shape::Parametric { kind, .. }) => *kind == ParametricKind::Solid,
            None => false,
        };
    ExportedObject {
        id,
        name: object.data().name.clone(),
        n_edits: entries.iter().filter(|e| e.active).count(),
        solid,
        n_triangles: 0,
        closed: None,
        skipped: None,
    }
}

/// Every object meshed, placed in scene coordinates and merged, in `format`.
fn mesh_bytes(
    scene: &Scene,
    ids: &[ObjectId],
    format: MeshFormat,
    depth: u8,
    report: &mut ExportReport,
) -> Result<Vec<u8>, ExportError> {
    if depth > render::mesh::octree::OCTREE_DEPTH_MAX {
        return Err(ExportError::Depth { depth });
    }
    let settings = render::snapshot::SnapshotSettings {
        depth,
        t_secs: EXPORT_T_SECS,
        force_arrows: 0,
        ..Default::default()
    };
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    for &id in ids {
        let (row, mesh) = object_mesh(scene, id, &settings)?;
        if let Some(mesh) = mesh {
            append_mesh(&mut positions, &mut triangles, &mesh)?;
        }
        note_object(report, &row);
        report.objects.push(row);
    }
    if triangles.is_empty() {
        return Err(ExportError::Empty(if report.notes.is_empty() {
            "no object has a surface".into()
        } else {
            report.notes.join("; ")
        }));
    }
    let merged = TriMesh::new(positions, triangles).map_err(ExportError::TooLarge)?;
    report.n_triangles = merged.triangles().len();
    report.n_vertices = merged.positions().len();
    // An STL file stores corners; readers merge equal ones, and that mesh is what counts.
    let closed = match format {
        MeshFormat::StlBinary | MeshFormat::StlAscii => merged.welded().is_closed(),
        MeshFormat::Obj | MeshFormat::Glb => merged.is_closed(),
    };
    if !closed && merged.is_closed() {
        report.notes.push(
            "objects meet at vertices of exactly equal coordinates, which an STL reader merges \
             into one open surface; export .obj or .glb to keep them apart"
                .into(),
        );
    }
    report.closed = Some(closed);
    let mut bytes = Vec::new();
    format.write(&merged, &mut bytes);
    Ok(bytes)
}

/// Notes about one object: not meshed, or a solid whose mesh is open.
fn note_object(report: &mut ExportReport, row: &ExportedObject) {
    let label = row.label();
    if let Some(why) = &row.skipped {
        report.notes.push(format!("{label}: {why}"));
    }
    if row.solid && row.closed == Some(false) && row.n_triangles > 0 {
        report.notes.push(format!(
            "{label} is a solid, but its mesh is open (not watertight)"
        ));
    }
}

/// One object meshed as `sculpt render` meshes it, in scene coordinates.
fn object_mesh(
    scene: &Scene,
    id: ObjectId,
    settings: &render::snapshot::SnapshotSettings,
) -> Result<(ExportedObject, Option<TriMesh>), ExportError> {
    let Some(entry) = scene.scene_object(id) else {
        return Err(ExportError::NoObject(id));
    };
    let mut row = exported_object(id, &entry.object);
    let Some(one) = one_object_scene(scene, id) else {
        row.skipped = Some("its groups nest too deep".into());
        return Ok((row, None));
    };
    let built = render::snapshot::build(&one, settings)?;
    row.skipped = built.objects.first().and_then(|o| o.skipped.clone());
    let Some(drawn) = built.scene.objects.first() else {
        return Ok((row, None));
    };
    let object = &entry.object;
    let placement = match &object.data().motion {
        None => object.data().transform,
        Some(_) => object.sampler().placement(settings.t_secs),
    };
    let scene_from_object = scene.world_from_group(entry.group).then(&placement);
    let mesh = placed(&drawn.mesh, &scene_from_object)?;
    row.n_triangles = mesh.triangles().len();
    row.closed = Some(mesh.is_closed());
    Ok((row, Some(mesh)))
}

/// A render mesh mapped by `transform` as an `fdsl` mesh; welded when that closes it (a
/// mesh assembled from separately triangulated faces).
fn placed(
    mesh: &render::mesh::Mesh,
    transform: &model::object::Transform,
) -> Result<TriMesh, ExportError> {
    let positions = mesh
        .positions
        .iter()
        .map(|p| {
            let q = transform.point(DVec3::from_array(p.map(f64::from)));
            q.to_array().map(|c| c as f32)
        })
        .collect();
    // A mirror turns the winding inside out.
    let mirrored = transform.linear().determinant() < 0.0;
    let triangles = mesh
        .triangles()
        .map(|[a, b, c]| if mirrored { [a, c, b] } else { [a, b, c] })
        .collect();
    let mesh = TriMesh::new(positions, triangles).map_err(ExportError::TooLarge)?;
    if mesh.is_closed() {
        return Ok(mesh);
    }
    let welded = mesh.welded();
    Ok(if welded.is_closed() { welded } else { mesh })
}

/// Appends `mesh` to the merged parts, renumbering its vertices.
fn append_mesh(
    positions: &mut Vec<[f32; 3]>,
    triangles: &mut Vec<[u32; 3]>,
    mesh: &TriMesh,
) -> Result<(), ExportError> {
    let n_vertices = positions.len() + mesh.positions().len();
    if n_vertices > model::mesh::MAX_MESH_VERTICES {
        return Err(ExportError::TooLarge(
            model::mesh::MeshError::TooManyVertices { n_vertices },
        ));
    }
    let n_triangles = triangles.len() + mesh.triangles().len();
    if n_triangles > model::mesh::MAX_MESH_TRIANGLES {
        return Err(ExportError::TooLarge(
            model::mesh::MeshError::TooManyTriangles { n_triangles },
        ));
    }
    // Below MAX_MESH_VERTICES, which fits in a u32.
    let base = positions.len() as u32;
    positions.extend_from_slice(mesh.positions());
    triangles.extend(mesh.triangles().iter().map(|t| t.map(|i| i + base)));
    Ok(())
}

/// Writes `bytes` to a temporary file beside `path`, syncs it and renames it over `path`;
/// on failure the temporary file is removed and `path` is as it was.
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let fail = |error| ExportError::Write {
        path: path.into(),
        error,
    };
    let Some(name) = path.file_name() else {
        return Err(fail(std::io::Error::other("the path names no file")));
    };
    let temp = path.with_file_name(format!(
        ".{}.{}.partial",
        name.to_string_lossy(),
        std::process::id()
    ));
    let written = (|| {
        // A stale temporary file of a crashed export with this process id is ours to replace.
        let _ = std::fs::remove_file(&temp);
        let mut file = std::fs::File::create_new(&temp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        std::fs::rename(&temp, path)
    })();
    if let Err(e) = written {
        let _ = std::fs::remove_file(&temp);
        return Err(fail(e));
    }
    // The rename reaches the disk with the directory; a file system that cannot sync a
    // directory has still renamed the complete, synced file.
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
    if let Ok(dir) = std::fs::File::open(dir.unwrap_or(Path::new("."))) {
        let _ = dir.sync_all();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::object::{Formula, Transform};
    use model::scene::Group;

    /// Ids of one made-up author from `counter`.
    fn ids(counter: u32) -> IdSource {
        IdSource {
            author: replication::PeerId([1; 32]),
            counter,
        }
    }

    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("sculpt-transfer-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    fn ball(name: &str) -> ObjectData {
        ObjectData {
            name: name.into(),
            geometry: Some(Geometry::implicit_in(
                Formula::new("1-sqrt(x^2+y^2+z^2)").unwrap(),
                Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
            )),
            ..ObjectData::default()
        }
    }

    fn mesh_object(mesh: TriMesh, transform: Transform) -> ObjectData {
        ObjectData {
            name: "mesh".into(),
            geometry: Some(mesh_geometry(Arc::new(mesh))),
            transform,
            ..ObjectData::default()
        }
    }

    #[test]
    fn groups_take_the_first_ids_parents_first_then_objects() {
        let mut scene = Scene::new();
        let group = |name: &str, parent| Group {
            name: name.into(),
            parent,
            transform: Transform::translate(DVec3::X),
        };
        // The child has the smaller id: id order is not parents-first order.
        scene.set_group(GroupId(9), group("outer", None)).unwrap();
        scene
            .set_group(GroupId(2), group("inner", Some(GroupId(9))))
            .unwrap();
        scene
            .create(ObjectId(0), ball("a"), Some(GroupId(2)))
            .unwrap();
        scene.create(ObjectId(1), ball("b"), None).unwrap();
        let path = Path::new("scene.wrl");
        let imported = scene_payloads(path, &scene, ids(100)).unwrap();
        assert_eq!(imported.next, ids(104));
        assert_eq!(imported.made.len(), 4);
        let [outer, inner, a, b] = &imported.payloads[..] else {
            panic!("{:?}", imported.payloads);
        };
        assert!(
            matches!(outer, ShapePayload::SetGroup { group, value: Some(g) } if *group == ids(100).id() && g.parent.is_none())
        );
        assert!(
            matches!(inner, ShapePayload::SetGroup { group, value: Some(g) } if *group == ids(101).id() && g.parent == Some(GroupId(ids(100).id())))
        );
        assert_eq!(
            (a, b),
            (
                &ids(102).create(ball("a"), Some(ids(101).id())),
                &ids(103).create(ball("b"), None)
            )
        );
        let exhausted = scene_payloads(path, &scene, ids(u32::MAX - 2)).unwrap_err();
        assert!(matches!(
            exhausted,
            ImportError::IdsExhausted { count: 4, .. }
        ));
    }

    #[test]
    fn a_file_with_too_many_objects_is_refused() {
        let mut scene = Scene::new();
        for i in 0..=MAX_IMPORT_OBJECTS as u64 {
            scene
                .create(ObjectId(i), ObjectData::default(), None)
                .unwrap();
        }
        let e = scene_payloads(Path::new("many.wrl"), &scene, ids(1)).unwrap_err();
        assert!(
            matches!(e, ImportError::TooMany { what: "objects", count, .. } if count == MAX_IMPORT_OBJECTS + 1),
            "{e}"
        );
        assert!(e.to_string().starts_with("many.wrl: "), "{e}");
    }

    #[test]
    fn a_mesh_is_imported_in_a_domain_around_it_in_parts_when_large_and_refused_when_huge() {
        let dir = scratch("mesh");
        let cube = model::mesh::shapes::cube(DVec3::splat(-1.0), DVec3::new(1.0, 2.0, 3.0));
        let mut bytes = Vec::new();
        formats::mesh::obj::write(&cube, &mut bytes);
        let path = dir.join("block.obj");
        std::fs::write(&path, &bytes).unwrap();
        let imported = import(&path, ids(7)).unwrap();
        assert_eq!(imported.next, ids(8));
        assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
        let ShapePayload::Create {
            object,
            counter: Some(7),
            data,
            group: None,
        } = &imported.payloads[0]
        else {
            panic!("{:?}", imported.payloads);
        };
        assert_eq!(*object, ids(7).id());
        assert_eq!(data.name, "block");
        let geometry = data.geometry.as_ref().unwrap();
        let domain = geometry.domain.unwrap().aabb();
        assert!(
            domain.lo.cmplt(DVec3::new(-1.0, -1.0, -1.0)).all(),
            "{domain:?}"
        );
        assert!(
            domain.hi.cmpgt(DVec3::new(1.0, 2.0, 3.0)).all(),
            "{domain:?}"
        );
        let object = Object::new((**data).clone()).unwrap();
        let mut sampler = object.sampler();
        for p in [
            DVec3::ZERO,
            DVec3::new(0.9, 1.5, -0.5),
            DVec3::new(1.1, 0.0, 0.0),
        ] {
            assert_eq!(sampler.value(p, 0.0), cube.signed_distance(p), "{p}");
        }

        // Larger than one op: its parts, then the assembly that makes the object.
        let big = model::mesh::shapes::icosphere(1.0, 4);
        bytes.clear();
        formats::mesh::glb::write(&big, &mut bytes);
        let path = dir.join("big.glb");
        std::fs::write(&path, &bytes).unwrap();
        let imported = import(&path, ids(7)).unwrap();
        let (last, parts) = imported.payloads.split_last().unwrap();
        assert!(parts.len() > 1, "{}", parts.len());
        let seven = ids(7).id();
        assert!(
            parts
                .iter()
                .all(|p| matches!(p, ShapePayload::Part { object, .. } if *object == seven)),
            "{parts:?}"
        );
        let ShapePayload::Assemble {
            object,
            parts: hashes,
        } = last
        else {
            panic!("{last:?}");
        };
        assert_eq!(*object, seven);
        assert_eq!(hashes.len(), parts.len());
        assert_eq!(imported.made.len(), imported.payloads.len());
        let made = format!("object {seven} \"big\": a mesh of 5120 triangles, closed");
        assert_eq!(imported.made.last().unwrap(), &made);
        assert_eq!(
            imported.made[0],
            format!("{made}: part 1 of {}", parts.len())
        );

        // Larger than an object may be: refused with a hint.
        let huge = model::mesh::shapes::icosphere(1.0, 7);
        bytes.clear();
        formats::mesh::glb::write(&huge, &mut bytes);
        let path = dir.join("huge.glb");
        std::fs::write(&path, &bytes).unwrap();
        let e = import(&path, ids(7)).unwrap_err();
        let text = e.to_string();
        assert!(matches!(e, ImportError::TooLarge { .. }), "{text}");
        assert!(
            text.contains("huge.glb") && text.contains("simplify it to about"),
            "{text}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn unknown_missing_and_empty_files_are_refused() {
        let dir = scratch("refused");
        assert!(matches!(
            import(&dir.join("notes.txt"), ids(1)),
            Err(ImportError::UnknownFormat { .. })
        ));
        let missing = import(&dir.join("missing.stl"), ids(1)).unwrap_err();
        assert!(missing.to_string().contains("missing.stl"), "{missing}");
        std::fs::write(dir.join("empty.obj"), "v 0 0 0\n").unwrap();
        assert!(matches!(
            import(&dir.join("empty.obj"), ids(1)),
            Err(ImportError::EmptyMesh { .. })
        ));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_mirrored_object_exports_outward_facing_and_closed() {
        let dir = scratch("mirror");
        let mut scene = Scene::new();
        let cube = model::mesh::shapes::cube(DVec3::ZERO, DVec3::ONE);
        let mirror = Transform::from_trs(
            DVec3::new(5.0, 0.0, 0.0),
            glam::DQuat::IDENTITY,
            DVec3::new(-1.0, 1.0, 1.0),
        );
        scene
            .create(ObjectId(3), mesh_object(cube, mirror), None)
            .unwrap();
        let path = dir.join("mirrored.obj");
        let report = export(&scene, None, &path, 4).unwrap();
        assert_eq!(report.closed, Some(true), "{report}");
        let back = formats::mesh::obj::read(&std::fs::read(&path).unwrap()).unwrap();
        assert!(back.is_closed());
        assert!(
            (back.signed_volume() - 1.0).abs() < 1e-6,
            "{}",
            back.signed_volume()
        );
        let bounds = back.bounds();
        assert_eq!((bounds.lo.x, bounds.hi.x), (4.0, 5.0));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_failed_export_leaves_the_target_as_it_was_and_no_temporary_file() {
        let dir = scratch("atomic");
        let mut scene = Scene::new();
        scene.create(ObjectId(1), ball("ball"), None).unwrap();
        let target = dir.join("kept.stl");
        std::fs::write(&target, b"old").unwrap();
        assert!(matches!(
            export(&scene, Some(ObjectId(2)), &target, 4),
            Err(ExportError::NoObject(ObjectId(2)))
        ));
        assert!(matches!(
            export(
                &scene,
                None,
                &target,
                render::mesh::octree::OCTREE_DEPTH_MAX + 1
            ),
            Err(ExportError::Depth { .. })
        ));
        assert!(matches!(
            export(&Scene::new(), None, &target, 4),
            Err(ExportError::Empty(_))
        ));
        assert!(matches!(
            export(&scene, None, &dir.join("kept.png"), 4),
            Err(ExportError::UnknownFormat { .. })
        ));
        let nowhere = dir.join("no/such/dir/out.glb");
        assert!(matches!(
            export(&scene, None, &nowhere, 4),
            Err(ExportError::Write { .. })
        ));
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        let report = export(&scene, None, &target, 4).unwrap();
        assert_eq!(report.closed, Some(true), "{report}");
        assert_eq!(report.n_bytes, std::fs::metadata(&target).unwrap().len());
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["kept.stl"], "no temporary file is left");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
