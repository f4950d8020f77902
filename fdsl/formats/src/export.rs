//! Writing a scene (or one object) as a file's bytes: the whole scene as FVRML, or every
//! object meshed, placed in scene coordinates and merged into one mesh as STL, OBJ or glTF.
//!
//! Meshing is the caller's: [`export`] asks a mesher (the app's is `render`'s, as
//! `sculpt render` meshes: the octree mesher over the object's geometry folded with its edits,
//! parametric shapes triangulated, imported meshes as they are, displacement applied) for
//! each object's triangles in its own coordinates, and places them here (groups, transform
//! and motion at [`EXPORT_T_SECS`]; +y up, as in FVRML and glTF). Colours, materials and
//! physics are not written to mesh files. FVRML holds everything, the edit histories included
//! (`FEdit` nodes, [`crate::fvrml`]). Writing the bytes to a file is the caller's too.
//!
//! Guarantee: a mesh exported from a closed solid (an implicit solid inside its box, a closed
//! mesh, anything sculpted) is closed when the mesher meshes it closed, and [`ExportReport`]
//! says so per object and for the file, checked with [`TriMesh::is_closed`]. Non-guarantees:
//! exported meshes may self-intersect where objects overlap (objects are merged, not united),
//! parametric solids are written as their six faces and may not be closed, and an STL reader
//! merges corners of exactly equal coordinates across objects.

use std::fmt;
use std::path::{Path, PathBuf};

use glam::DVec3;
use model::limits::MAX_GROUP_DEPTH;
use model::mesh::{MAX_MESH_TRIANGLES, MAX_MESH_VERTICES, MeshError, TriMesh};
use model::object::{Object, ParametricKind, Shape, Transform};
use model::scene::{ObjectId, Scene};

use crate::fvrml;
use crate::mesh::MeshFormat;
use crate::registry::FileFormat;

/// The scene time at which exported objects are meshed and placed.
pub const EXPORT_T_SECS: f64 = 0.0;

/// Why an export failed: nothing was written.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The extension is not one of [`crate::registry::EXTENSIONS`].
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
    /// The merged mesh is over `model::mesh`'s limits.
    #[error("the merged mesh cannot be written: {0}")]
    TooLarge(MeshError),
}

/// One object as a mesher meshed it, in the object's own coordinates.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjectMesh {
    /// Its triangles; `None` when nothing of the object was meshed.
    pub mesh: Option<MeshParts>,
    /// Why it (or part of it) was not meshed, if so.
    pub skipped: Option<String>,
}

/// A mesh as a mesher gives it, before it is placed and checked against the limits.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshParts {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Triangles of vertex indices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
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

/// The bytes of a file at `path` (which is only named, never opened) holding `scene`, or only
/// `object`, in the format of its extension, and the report of what they hold.
///
/// A mesh format meshes every object: `mesher` is called once, after the scene is checked, to
/// make the function that meshes one object given a scene holding only that object and the
/// groups above it (so a mesher that cannot start refuses before any object is meshed); an
/// FVRML export never calls it.
pub fn export<M, E>(
    scene: &Scene,
    object: Option<ObjectId>,
    path: &Path,
    mesher: impl FnOnce() -> Result<M, E>,
) -> Result<(Vec<u8>, ExportReport), E>
where
    M: FnMut(&Scene) -> Result<ObjectMesh, E>,
    E: From<ExportError>,
{
    let format =
        FileFormat::of(path).ok_or_else(|| ExportError::UnknownFormat { path: path.into() })?;
    let ids: Vec<ObjectId> = match object {
        Some(id) if scene.object(id).is_none() => return Err(ExportError::NoObject(id).into()),
        Some(id) => vec![id],
        None => scene.objects().map(|(id, _)| id).collect(),
    };
    if ids.is_empty() {
        return Err(ExportError::Empty("the scene has no objects".into()).into());
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
        FileFormat::Mesh(mesh_format) => {
            let mut mesh_one = mesher()?;
            mesh_bytes(scene, &ids, mesh_format, &mut mesh_one, &mut report)?
        }
    };
    report.n_bytes = bytes.len() as u64;
    Ok((bytes, report))
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
        if chain.len() > MAX_GROUP_DEPTH {
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
fn mesh_bytes<E: From<ExportError>>(
    scene: &Scene,
    ids: &[ObjectId],
    format: MeshFormat,
    mesh_one: &mut impl FnMut(&Scene) -> Result<ObjectMesh, E>,
    report: &mut ExportReport,
) -> Result<Vec<u8>, E> {
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    for &id in ids {
        let (row, mesh) = object_mesh(scene, id, mesh_one)?;
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
        })
        .into());
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

/// One object meshed by `mesh_one`, in scene coordinates.
fn object_mesh<E: From<ExportError>>(
    scene: &Scene,
    id: ObjectId,
    mesh_one: &mut impl FnMut(&Scene) -> Result<ObjectMesh, E>,
) -> Result<(ExportedObject, Option<TriMesh>), E> {
    let Some(entry) = scene.scene_object(id) else {
        return Err(ExportError::NoObject(id).into());
    };
    let mut row = exported_object(id, &entry.object);
    let Some(one) = one_object_scene(scene, id) else {
        row.skipped = Some("its groups nest too deep".into());
        return Ok((row, None));
    };
    let meshed = mesh_one(&one)?;
    row.skipped = meshed.skipped;
    let Some(MeshParts {
        positions,
        triangles,
    }) = meshed.mesh
    else {
        return Ok((row, None));
    };
    let object = &entry.object;
    let placement = match &object.data().motion {
        None => object.data().transform,
        Some(_) => object.sampler().placement(EXPORT_T_SECS),
    };
    let scene_from_object = scene.world_from_group(entry.group).then(&placement);
    let mesh = placed(positions, triangles, &scene_from_object)?;
    row.n_triangles = mesh.triangles().len();
    row.closed = Some(mesh.is_closed());
    Ok((row, Some(mesh)))
}

/// A mesh's parts mapped by `transform`; welded when that closes it (a mesh assembled from
/// separately triangulated faces).
fn placed(
    mut positions: Vec<[f32; 3]>,
    mut triangles: Vec<[u32; 3]>,
    transform: &Transform,
) -> Result<TriMesh, ExportError> {
    for p in &mut positions {
        let q = transform.point(DVec3::from_array(p.map(f64::from)));
        *p = q.to_array().map(|c| c as f32);
    }
    // A mirror turns the winding inside out.
    if transform.linear().determinant() < 0.0 {
        for [_, b, c] in &mut triangles {
            std::mem::swap(b, c);
        }
    }
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
    if n_vertices > MAX_MESH_VERTICES {
        return Err(ExportError::TooLarge(MeshError::TooManyVertices {
            n_vertices,
        }));
    }
    let n_triangles = triangles.len() + mesh.triangles().len();
    if n_triangles > MAX_MESH_TRIANGLES {
        return Err(ExportError::TooLarge(MeshError::TooManyTriangles {
            n_triangles,
        }));
    }
    // Below MAX_MESH_VERTICES, which fits in a u32.
    let base = positions.len() as u32;
    positions.extend_from_slice(mesh.positions());
    triangles.extend(mesh.triangles().iter().map(|t| t.map(|i| i + base)));
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::DQuat;
    use model::object::{ObjectData, Transform};
    use model::scene::{Group, GroupId};

    use super::*;
    use crate::import::mesh_geometry;

    /// A mesher for objects whose geometry is a mesh: that mesh, as it is.
    fn mesh_of(one: &Scene) -> Result<ObjectMesh, ExportError> {
        let (_, entry) = one.objects().next().expect("one object");
        let mesh = match entry.object.data().geometry.as_ref().map(|g| &g.shape) {
            Some(Shape::Mesh(m)) => Some(MeshParts {
                positions: m.positions().to_vec(),
                triangles: m.triangles().to_vec(),
            }),
            _ => None,
        };
        let skipped = mesh.is_none().then(|| "not a mesh".to_string());
        Ok(ObjectMesh { mesh, skipped })
    }

    /// A mesher as [`export`] takes it, without state.
    type Mesher = fn(&Scene) -> Result<ObjectMesh, ExportError>;

    fn mesher() -> Result<Mesher, ExportError> {
        Ok(mesh_of)
    }

    fn cube_object(transform: Transform) -> ObjectData {
        let cube = model::mesh::shapes::cube(DVec3::ZERO, DVec3::ONE);
        ObjectData {
            name: "cube".into(),
            geometry: Some(mesh_geometry(Arc::new(cube))),
            transform,
            ..ObjectData::default()
        }
    }

    #[test]
    fn a_mirrored_object_in_a_group_is_placed_outward_facing_and_closed() {
        let mut scene = Scene::new();
        let up = Group {
            name: "up".into(),
            parent: None,
            transform: Transform::translate(DVec3::Y),
        };
        scene.set_group(GroupId(4), up).unwrap();
        let mirror = Transform::from_trs(
            DVec3::new(5.0, 0.0, 0.0),
            DQuat::IDENTITY,
            DVec3::new(-1.0, 1.0, 1.0),
        );
        let data = cube_object(mirror);
        scene.create(ObjectId(3), data, Some(GroupId(4))).unwrap();
        let (bytes, report) = export(&scene, None, Path::new("out.obj"), mesher).unwrap();
        assert_eq!(report.closed, Some(true), "{report}");
        assert_eq!(report.n_bytes, bytes.len() as u64);
        assert_eq!((report.n_triangles, report.n_vertices), (12, 8));
        let back = MeshFormat::Obj.read(&bytes).unwrap();
        assert!(
            (back.signed_volume() - 1.0).abs() < 1e-6,
            "{}",
            back.signed_volume()
        );
        let bounds = back.bounds();
        assert_eq!((bounds.lo.x, bounds.hi.x), (4.0, 5.0));
        assert_eq!((bounds.lo.y, bounds.hi.y), (1.0, 2.0));
    }

    #[test]
    fn fvrml_holds_the_object_and_its_groups_without_meshing() {
        let mut scene = Scene::new();
        let group = Group {
            name: "shelf".into(),
            ..Group::default()
        };
        scene.set_group(GroupId(1), group).unwrap();
        scene
            .create(
                ObjectId(2),
                cube_object(Transform::IDENTITY),
                Some(GroupId(1)),
            )
            .unwrap();
        scene
            .create(ObjectId(3), cube_object(Transform::IDENTITY), None)
            .unwrap();
        let refuses =
            || -> Result<Mesher, ExportError> { panic!("an FVRML export meshes nothing") };
        let path = Path::new("one.wrl");
        let (bytes, report) = export(&scene, Some(ObjectId(2)), path, refuses).unwrap();
        assert_eq!(report.closed, None);
        assert_eq!(report.objects.len(), 1);
        let text = String::from_utf8(bytes).unwrap();
        assert!(text.contains("shelf"), "{text}");
        let mut no_files = |url: &str| Err(format!("no file {url}"));
        let loaded = fvrml::load(&text, &Default::default(), &mut no_files).unwrap();
        assert_eq!(loaded.scene.len(), 1);
    }

    #[test]
    fn nothing_to_write_is_an_error_that_says_why() {
        let mut scene = Scene::new();
        let path = Path::new("out.stl");
        let empty = export(&scene, None, path, mesher).unwrap_err();
        assert!(matches!(empty, ExportError::Empty(_)), "{empty}");
        let implicit = ObjectData {
            geometry: Some(model::object::Geometry::implicit(
                model::object::Formula::new("1-x^2-y^2-z^2").unwrap(),
            )),
            ..ObjectData::default()
        };
        scene.create(ObjectId(7), implicit, None).unwrap();
        let missing = export(&scene, Some(ObjectId(8)), path, mesher).unwrap_err();
        assert!(matches!(missing, ExportError::NoObject(ObjectId(8))));
        let skipped = export(&scene, None, path, mesher).unwrap_err();
        assert_eq!(
            skipped.to_string(),
            "nothing to export: object 7: not a mesh"
        );
        let unknown = export(&scene, None, Path::new("out.png"), mesher).unwrap_err();
        assert!(matches!(unknown, ExportError::UnknownFormat { .. }));
    }
}
