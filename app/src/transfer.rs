//! Files in and out of a session, shared by `sculpt import`/`sculpt export` and the window's
//! menu: [`import`] plans the ops that bring a file's objects into a session, [`export`]
//! writes a scene (or one object) to a file.
//!
//! What a file format is and how its bytes become objects and objects bytes is the `formats`
//! crate's (`formats::registry`, `formats::import`, `formats::export`); this module adds the
//! session's side: reading and writing the files, the ops, and meshing through `render`.
//!
//! Importing is planning, never authoring: [`import`] returns the payloads and the caller
//! authors them in order. A file is read whole within its format's limit
//! ([`formats::registry::FileFormat::max_file_bytes`]) before it is parsed; its `Inline`s may
//! read only files in its own folder, or under a root the user names ([`import_within`],
//! checked by [`crate::files::InlineResolver`]); an object too large for one op
//! ([`replication::payload::MAX_PAYLOAD_BYTES`]: a mesh of a few hundred triangles) is
//! authored in parts ([`replication::shape::parts`]), up to
//! [`replication::shape::parts::MAX_ASSEMBLED_BYTES`] (a mesh of about 170 000 triangles), and
//! a file may bring at most [`MAX_IMPORT_OBJECTS`] objects. Any failure is an error naming
//! the file and where in it (line and column, byte offset or JSON path, as the reader
//! reports), and then no payload at all is returned.
//!
//! Exporting meshes each object as `sculpt render` does (`render::snapshot::build`: the
//! octree mesher over the object's geometry folded with its edits, parametric shapes
//! triangulated, imported meshes as they are, displacement applied) at the depth asked, and
//! `formats::export` places and merges the meshes (see there for what is guaranteed). The
//! file is written to a temporary file beside the target, synced, then renamed over it, so a
//! failed export leaves no partial file.

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use formats::export::{EXPORT_T_SECS, ExportReport, MeshParts, ObjectMesh};
use formats::import::{Contents, Read};
use model::mesh::TriMesh;
use model::object::{ColorDef, ObjectData, ParametricKind, Shape};
use model::scene::{GroupId, ObjectId, Scene};
use replication::shape::parts::{self, MAX_ASSEMBLED_BYTES, SplitError};
use replication::shape::{IdSource, ShapePayload};

use crate::files::InlineResolver;

/// Most objects one imported file may bring into a session (each is an op, stored and sent
/// to every peer).
pub const MAX_IMPORT_OBJECTS: usize = 1024;
/// Most groups one imported file may bring.
pub const MAX_IMPORT_GROUPS: usize = 1024;

/// Why a file could not be imported. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The file's format is unknown or its contents do not read (see `formats::import`).
    #[error(transparent)]
    File(#[from] formats::import::ImportError),
    /// The file could not be read (missing, unreadable, over its size limit).
    #[error("{message}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What went wrong, with the path.
        message: String,
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
///   (`formats::import`), in the colour of a new object.
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
    let format = formats::import::format_of(path)?;
    let read_error = |message: String| ImportError::Read {
        path: path.into(),
        message,
    };
    let bytes = crate::files::read_bounded(path, format.max_file_bytes()).map_err(read_error)?;
    let inlines = if format.reads_other_files() {
        let dir = path.parent().unwrap_or(Path::new(""));
        Some(InlineResolver::new(dir, inline_root).map_err(read_error)?)
    } else {
        None
    };
    let mut resolve = |url: &str| match &inlines {
        Some(inlines) => inlines.read(url),
        None => Err(format!("{}: names no other files", path.display())),
    };
    let Read { contents, warnings } = formats::import::read(path, format, &bytes, &mut resolve)?;
    let mut imported = match contents {
        Contents::Scene(scene) => scene_payloads(path, &scene, next)?,
        Contents::Mesh(data) => mesh_payloads(path, *data, next)?,
    };
    let mut all = warnings;
    all.append(&mut imported.warnings);
    imported.warnings = all;
    Ok(imported)
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

/// The payloads of a mesh file's object, in the colour of a new object, with the id `next`.
fn mesh_payloads(
    path: &Path,
    mut data: ObjectData,
    next: IdSource,
) -> Result<Imported, ImportError> {
    let ids = IdRange::new(path, next, 1)?;
    data.appearance = model::object::Appearance {
        diffuse: Some(ColorDef::Constant(crate::new_object::NEW_OBJECT_COLOUR)),
        ..Default::default()
    }
    .into();
    let name = data.name.clone();
    let mesh = match data.geometry.as_ref().map(|g| &g.shape) {
        Some(Shape::Mesh(m)) => Some(m.clone()),
        _ => None,
    };
    let made = format!("object {} \"{name}\": {}", ids.first.id(), kind(&data));
    let payload = ids.first.create(data, None);
    let what = format!("the mesh \"{name}\"");
    let ops = payload_ops(path, &what, payload, mesh.as_deref())?;
    let mut imported = Imported {
        payloads: Vec::new(),
        made: Vec::new(),
        warnings: Vec::new(),
        next: ids.end,
    };
    push_ops(&mut imported, ops, made);
    Ok(imported)
}

/// Why an export failed. Nothing was written at `path` (a temporary file is removed).
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The format is unknown, the object missing, the scene empty or the merged mesh too
    /// large (see `formats::export`).
    #[error(transparent)]
    File(#[from] formats::export::ExportError),
    /// The octree depth is out of range.
    #[error(
        "depth {depth} is more than the mesher's maximum of {}",
        render::mesh::octree::MAX_OCTREE_DEPTH
    )]
    Depth {
        /// The depth asked for.
        depth: u8,
    },
    /// The scene could not be meshed (bad settings).
    #[error(transparent)]
    Mesh(#[from] render::snapshot::SnapshotError),
    /// The file could not be written.
    #[error("cannot write {}: {error}", .path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why (in the message, not as a source, so that it is printed once).
        error: std::io::Error,
    },
}

/// Writes `scene` (or only `object`) to `path`, in the format of its extension (see
/// `formats::export`), meshing implicit shapes at octree `depth` (the render default is
/// `render::snapshot::SnapshotSettings::default().depth`). Meshing takes time: take a clone
/// of the view's scene rather than meshing under the view's lock.
pub fn export(
    scene: &Scene,
    object: Option<ObjectId>,
    path: &Path,
    depth: u8,
) -> Result<ExportReport, ExportError> {
    let mesher = || {
        if depth > render::mesh::octree::MAX_OCTREE_DEPTH {
            return Err(ExportError::Depth { depth });
        }
        let settings = render::snapshot::SnapshotSettings {
            depth,
            t_secs: EXPORT_T_SECS,
            force_arrows: 0,
            // The window exports too: a core is left to it.
            mesh_threads: render::mesher::remesh_threads(render::mesher::WINDOW_CORES),
            ..Default::default()
        };
        Ok(move |one: &Scene| mesh_object(one, &settings))
    };
    let (bytes, report) = formats::export::export(scene, object, path, mesher)?;
    write_atomically(path, &bytes)?;
    Ok(report)
}

/// The one object of `one` meshed as `sculpt render` meshes it, in its own coordinates.
fn mesh_object(
    one: &Scene,
    settings: &render::snapshot::SnapshotSettings,
) -> Result<ObjectMesh, ExportError> {
    let built = render::snapshot::build(one, settings)?;
    let skipped = built.objects.first().and_then(|o| o.skipped.clone());
    let mesh = built.scene.objects.first().map(|drawn| MeshParts {
        positions: drawn.mesh.positions.clone(),
        triangles: drawn.mesh.triangles().collect(),
    });
    Ok(ObjectMesh { mesh, skipped })
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
    use formats::export::ExportError as FileExportError;
    use formats::import::{ImportError as FileImportError, mesh_geometry};
    use glam::DVec3;
    use model::object::{Domain, Formula, Geometry, Object, Transform};
    use model::scene::Group;
    use std::sync::Arc;

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
            Err(ImportError::File(FileImportError::UnknownFormat { .. }))
        ));
        let missing = import(&dir.join("missing.stl"), ids(1)).unwrap_err();
        assert!(missing.to_string().contains("missing.stl"), "{missing}");
        std::fs::write(dir.join("empty.obj"), "v 0 0 0\n").unwrap();
        assert!(matches!(
            import(&dir.join("empty.obj"), ids(1)),
            Err(ImportError::File(FileImportError::EmptyMesh { .. }))
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
            Err(ExportError::File(FileExportError::NoObject(ObjectId(2))))
        ));
        assert!(matches!(
            export(
                &scene,
                None,
                &target,
                render::mesh::octree::MAX_OCTREE_DEPTH + 1
            ),
            Err(ExportError::Depth { .. })
        ));
        assert!(matches!(
            export(&Scene::new(), None, &target, 4),
            Err(ExportError::File(FileExportError::Empty(_)))
        ));
        assert!(matches!(
            export(&scene, None, &dir.join("kept.png"), 4),
            Err(ExportError::File(FileExportError::UnknownFormat { .. }))
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
