//! The thesis's central claim, measured end to end: a model and its sculpting edits travel as
//! signed function-string ops far smaller than the meshes they describe.
//!
//! [`measure`] builds real ops. A [`Subject`] (a reference model of `tests/data/models`, or an
//! object of an FVRML scene in `tests/data/scenes`) is created by a signed
//! [`ShapePayload::Create`] op and sculpted by seeded strokes ([`ShapePayload::Edit`] of an
//! [`Edit`]), each authored through a [`Log`] and folded by [`Materialized`] into a
//! [`ShapeScene`], exactly as a peer does. The folded object is meshed by render's octree mesher
//! through [`object_field`] (render's `ObjectField` over the object's [`Sampler`]: base
//! formula, domain, transforms and the whole edit history), and the mesh is written as binary
//! STL and as GLB by `model::mesh`.
//! After each edit the mesher re-meshes only the edit's box ([`OctreeMesher::remesh`]); the
//! triangles it adds and removes are the mesh delta a mesh-shipping system would have to send
//! for that edit.
//!
//! What it does not measure: compression (neither ops nor meshes are compressed), sync framing
//! (an op travels in a batch with a few bytes of header, see `replication::sync::message`),
//! colours and other vertex attributes (STL and our GLB carry positions only).

use std::collections::BTreeMap;

use glam::{DQuat, DVec3};
use model::object::{Edit, EditOp, Object, ObjectData, Pose, Sampler, Shape, ToolShape};
use model::scene::ObjectId;
use render::mesh::object_field::ObjectField;
use render::mesh::octree::{MeshSettings, OctreeMeshError, OctreeMesher};
use render::mesh::{Aabb, Mesh};
use replication::materialize::Materialized;
use replication::shape::{IdSource, ShapePayload, ShapeScene};
use replication::{Keypair, Log, Timestamp};

/// The reference models (`tests/data/models/*.fdsl`), name and source.
pub use fdsl::models::REFERENCE_MODELS as MODELS;

/// The FVRML scenes (`tests/data/scenes/*.wrl`), file name and text.
pub const SCENES: [(&str, &str); 4] = [
    (
        "figure_7_4.wrl",
        include_str!("../data/scenes/figure_7_4.wrl"),
    ),
    (
        "figure_7_8.wrl",
        include_str!("../data/scenes/figure_7_8.wrl"),
    ),
    (
        "figure_7_14.wrl",
        include_str!("../data/scenes/figure_7_14.wrl"),
    ),
    (
        "watermelon.wrl",
        include_str!("../../scenes/watermelon.wrl"),
    ),
];

/// Half the side of the cube meshed around a model without a domain (the models fit in the
/// unit ball; render's own model tests mesh the same box).
pub const MODEL_HALF_SIDE: f32 = 1.2;
/// A binary STL triangle record: normal, three corners (12 `f32`) and a 2-byte attribute.
pub const STL_TRIANGLE_BYTES: usize = 50;
/// What a mesh delta spends to name one removed triangle (a `u32` index).
pub const REMOVED_TRIANGLE_BYTES: usize = 4;
/// The key that authors every measured session.
const AUTHOR_SEED: [u8; 32] = [0x5c; 32];
/// Tries to find the surface with a ray before a stroke starts at the object's centre.
const MAX_SURFACE_TRIES: usize = 16;
/// Steps of the march that finds a stroke's starting point on the surface.
const MARCH_STEPS: usize = 256;
/// Bisections of the step where the march crossed the surface.
const BISECTIONS: usize = 20;
/// Microseconds between two ops of a session.
const OP_INTERVAL_MICROS: u64 = 500_000;

/// Why a measurement failed.
#[derive(Debug, thiserror::Error)]
pub enum FootprintError {
    /// A scene did not load.
    #[error("{scene}: {error}")]
    Load {
        /// The scene's file name.
        scene: &'static str,
        /// What went wrong.
        error: formats::fvrml::LoadError,
    },
    /// A model is not a valid object.
    #[error("{name}: {error}")]
    Object {
        /// The model.
        name: String,
        /// What went wrong.
        error: model::object::ObjectError,
    },
    /// The empty log did not fold (it always does).
    #[error("folding the log: {0}")]
    Fold(#[from] replication::codec::DecodeError),
    /// The log refused to author an op.
    #[error("authoring an op: {0}")]
    Author(#[from] replication::log::AuthorError),
    /// The folded scene lacks the object the session created.
    #[error("the folded scene has no object of the session")]
    Missing,
    /// The mesher failed.
    #[error("meshing: {0}")]
    Mesh(#[from] OctreeMeshError),
    /// The mesh is not a valid `fdsl` triangle mesh (too large for the writers).
    #[error("writing the mesh: {0}")]
    Write(#[from] model::mesh::MeshError),
}

/// One object to measure: its description and the box to mesh it in.
#[derive(Clone, Debug)]
pub struct Subject {
    /// `model` or `scene.wrl:object`.
    pub name: String,
    /// What the create op carries.
    pub data: ObjectData,
    /// The box the mesher covers, in object space (a cube, so that cells are cubes).
    pub bounds: Aabb,
}

/// The reference models as objects (implicit geometry, no domain, nothing else).
pub fn model_subjects() -> Result<Vec<Subject>, FootprintError> {
    MODELS
        .iter()
        .map(|&(name, source)| {
            let object = Object::implicit(source).map_err(|error| FootprintError::Object {
                name: name.to_owned(),
                error,
            })?;
            Ok(Subject {
                name: name.to_owned(),
                data: object.data().clone(),
                bounds: Aabb::new([-MODEL_HALF_SIDE; 3], [MODEL_HALF_SIDE; 3]),
            })
        })
        .collect()
}

/// The objects of the FVRML scenes that have implicit geometry, meshed in a cube around their
/// domain (or the models' cube when they have none). `Inline` files are not resolved: the
/// figures only inline remote urls, which are skipped with a warning.
pub fn scene_subjects() -> Result<Vec<Subject>, FootprintError> {
    let mut out = Vec::new();
    for &(scene, text) in &SCENES {
        let mut no_files = |path: &str| Err(format!("{path}: no local files here"));
        let loaded = formats::fvrml::load(text, &Default::default(), &mut no_files)
            .map_err(|error| FootprintError::Load { scene, error })?;
        for (id, entry) in loaded.scene.objects() {
            let object = &entry.object;
            let implicit = object
                .data()
                .geometry
                .as_ref()
                .is_some_and(|g| matches!(g.shape, Shape::Implicit(_)));
            if !implicit {
                continue;
            }
            let bounds = match object.bounds() {
                Some(b) => cube_around(b.lo, b.hi),
                None => Aabb::new([-MODEL_HALF_SIDE; 3], [MODEL_HALF_SIDE; 3]),
            };
            let name = match object.data().name.as_str() {
                "" => format!("{scene}:{}", id.0),
                n => format!("{scene}:{n}"),
            };
            out.push(Subject {
                name,
                data: object.data().clone(),
                bounds,
            });
        }
    }
    Ok(out)
}

/// A cube around `lo..hi` with 10% to spare on each side, so the surface lies strictly inside.
fn cube_around(lo: DVec3, hi: DVec3) -> Aabb {
    let centre = (lo + hi) / 2.0;
    let half = ((hi - lo).max_element() / 2.0 * 1.1).max(1e-3);
    let (lo, hi) = (centre - half, centre + half);
    Aabb::new(lo.as_vec3().to_array(), hi.as_vec3().to_array())
}

/// An object's solid as a mesher field: render's [`ObjectField`] over the object's
/// [`Sampler`] (base formula, domain, transform and the fold of its edit history), in object
/// space at time `t`, always on the sampler path so that incremental remeshes agree with full
/// ones.
pub fn object_field(object: &Object, t: f64) -> ObjectField {
    let mut object = object.clone();
    object.prepare();
    ObjectField::from_sampler(object.sampler(), t)
}

fn dvec(p: [f32; 3]) -> DVec3 {
    DVec3::new(p[0].into(), p[1].into(), p[2].into())
}

/// Sizes of one mesh in the formats people exchange.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshBytes {
    /// Triangles.
    pub n_triangles: usize,
    /// Vertices (shared between triangles).
    pub n_vertices: usize,
    /// Binary STL.
    pub stl_bytes: usize,
    /// Binary glTF (indexed positions).
    pub glb_bytes: usize,
}

/// The `fdsl` triangle mesh of a render mesh (positions and triangles).
pub fn tri_mesh(mesh: &Mesh) -> Result<model::mesh::TriMesh, FootprintError> {
    let triangles = mesh.triangles().collect();
    Ok(model::mesh::TriMesh::new(
        mesh.positions.clone(),
        triangles,
    )?)
}

/// Binary STL of a render mesh.
pub fn stl(mesh: &Mesh) -> Result<Vec<u8>, FootprintError> {
    let mut out = Vec::new();
    formats::mesh::stl::write_binary(&tri_mesh(mesh)?, &mut out);
    Ok(out)
}

/// Counts the bytes of `mesh` as binary STL and GLB.
pub fn mesh_bytes(mesh: &Mesh) -> Result<MeshBytes, FootprintError> {
    let tri = tri_mesh(mesh)?;
    let mut stl = Vec::new();
    formats::mesh::stl::write_binary(&tri, &mut stl);
    let mut glb = Vec::new();
    formats::mesh::glb::write(&tri, &mut glb);
    Ok(MeshBytes {
        n_triangles: mesh.n_triangles(),
        n_vertices: mesh.n_vertices(),
        stl_bytes: stl.len(),
        glb_bytes: glb.len(),
    })
}

/// Meshes `object` in `bounds` at `depth` from scratch.
pub fn mesh_object(object: &Object, bounds: Aabb, depth: u8) -> Result<Mesh, FootprintError> {
    let settings = MeshSettings { bounds, depth };
    Ok(render::mesh::octree::mesh(
        &mut object_field(object, 0.0),
        &settings,
    )?)
}

/// A sculpting session: how many strokes, how finely each is sampled, and the seed of both.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SessionSpec {
    /// Edits (strokes), each one op.
    pub n_edits: usize,
    /// Poses per stroke (the hand's samples along one movement).
    pub poses_per_stroke: usize,
    /// Seed of the strokes.
    pub seed: u64,
}

/// What one edit costs as an op and as a mesh delta.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EditCost {
    /// The signed op's encoded bytes.
    pub op_bytes: usize,
    /// Triangles the re-mesh of the edit's box added.
    pub n_added: usize,
    /// Triangles it removed.
    pub n_removed: usize,
}

impl EditCost {
    /// Bytes of the mesh delta: each added triangle as a binary STL record, each removed one
    /// as a `u32` index.
    pub fn delta_bytes(&self) -> usize {
        self.n_added * STL_TRIANGLE_BYTES + self.n_removed * REMOVED_TRIANGLE_BYTES
    }
}

/// The measurement of one subject at one depth.
#[derive(Clone, Debug)]
pub struct Footprint {
    /// The subject's name.
    pub name: String,
    /// Octree depth (2^depth cells along each axis of the subject's cube).
    pub depth: u8,
    /// The create op's encoded bytes.
    pub create_op_bytes: usize,
    /// The mesh of the object as created.
    pub base_mesh: MeshBytes,
    /// One entry per edit, in order.
    pub edits: Vec<EditCost>,
    /// The mesh after the last edit (kept up to date by local re-meshing).
    pub final_mesh: MeshBytes,
    /// Every op of the session, encoded (signed, as sent), in authoring order.
    pub ops: Vec<Vec<u8>>,
    /// The object the session's ops fold into.
    pub final_object: Object,
}

impl Footprint {
    /// Bytes of every op of the session: the create op and the edits.
    pub fn session_op_bytes(&self) -> usize {
        self.ops.iter().map(Vec::len).sum()
    }

    /// Bytes of all edit ops.
    pub fn edit_op_bytes(&self) -> usize {
        self.edits.iter().map(|e| e.op_bytes).sum()
    }

    /// Bytes of all mesh deltas.
    pub fn delta_bytes(&self) -> usize {
        self.edits.iter().map(EditCost::delta_bytes).sum()
    }

    /// Whether the object has a surface inside its box at this depth.
    pub fn has_surface(&self) -> bool {
        self.base_mesh.n_triangles > 0
    }
}

/// Runs a session on `subject`: creates it, meshes it at `depth`, then authors, folds and
/// re-meshes each edit of `session`.
pub fn measure(
    subject: &Subject,
    session: &SessionSpec,
    depth: u8,
) -> Result<Footprint, FootprintError> {
    let author = Keypair::from_seed(AUTHOR_SEED);
    let mut log = Log::<ShapePayload>::default();
    let mut scene = Materialized::<ShapePayload, ShapeScene>::fold(&log);
    let mut now = Timestamp(1_000_000);
    let create = IdSource::first(author.peer_id()).create(subject.data.clone(), None);
    let (op, insertion) = log.author(&author, now, create)?;
    scene.apply_insertion(&log, &insertion);
    let mut ops = vec![op.encoded().to_vec()];
    let object = folded(&scene)?;
    let settings = MeshSettings {
        bounds: subject.bounds,
        depth,
    };
    let mut mesher = OctreeMesher::new(&settings)?;
    mesher.remesh(&mut object_field(&object, 0.0), subject.bounds)?;
    let mut mesh = mesher.mesh()?;
    let base_mesh = mesh_bytes(&mesh)?;
    let mut triangles = triangle_set(&mesh);
    let mut rng = SplitMix64(session.seed);
    let mut edits = Vec::with_capacity(session.n_edits);
    let mut object = object;
    for edit_idx in 0..session.n_edits {
        let edit = stroke(&mut rng, &object, subject.bounds, edit_idx, session);
        now = now.saturating_add_micros(OP_INTERVAL_MICROS);
        let payload = ShapePayload::edit(object_id(), edit).expect("a valid edit");
        let (op, insertion) = log.author(&author, now, payload)?;
        scene.apply_insertion(&log, &insertion);
        ops.push(op.encoded().to_vec());
        object = folded(&scene)?;
        let dirty = object
            .history()
            .entries()
            .last()
            .map_or(model::bvh::Aabb::EMPTY, |e| e.edit.bounds());
        let dirty = Aabb::new(dirty.lo.as_vec3().to_array(), dirty.hi.as_vec3().to_array());
        mesher.remesh(&mut object_field(&object, 0.0), dirty)?;
        mesh = mesher.mesh()?;
        let after = triangle_set(&mesh);
        edits.push(EditCost {
            op_bytes: op.encoded().len(),
            n_added: count_missing(&after, &triangles),
            n_removed: count_missing(&triangles, &after),
        });
        triangles = after;
    }
    Ok(Footprint {
        name: subject.name.clone(),
        depth,
        create_op_bytes: ops[0].len(),
        base_mesh,
        edits,
        final_mesh: mesh_bytes(&mesh)?,
        ops,
        final_object: object,
    })
}

/// The id of every measured session's object: its author's first.
fn object_id() -> u64 {
    IdSource::first(Keypair::from_seed(AUTHOR_SEED).peer_id()).id()
}

/// The session's object in a folded scene.
pub fn folded(scene: &Materialized<ShapePayload, ShapeScene>) -> Result<Object, FootprintError> {
    scene
        .scene()
        .scene()
        .object(ObjectId(object_id()))
        .cloned()
        .ok_or(FootprintError::Missing)
}

/// A triangle by the bits of its corners, rotated to start at the smallest (orientation kept).
type TriangleKey = [[u32; 3]; 3];

/// The triangles of `mesh` as a multiset of corner positions.
fn triangle_set(mesh: &Mesh) -> BTreeMap<TriangleKey, usize> {
    let mut set = BTreeMap::new();
    for t in mesh.triangles() {
        let c = t.map(|i| {
            mesh.positions
                .get(i as usize)
                .map_or([u32::MAX; 3], |p| p.map(f32::to_bits))
        });
        let first = (0..3).min_by_key(|&k| c[k]).unwrap_or(0);
        let key = [c[first], c[(first + 1) % 3], c[(first + 2) % 3]];
        *set.entry(key).or_insert(0) += 1;
    }
    set
}

/// How many triangles of `a` (with multiplicity) `b` lacks.
fn count_missing(a: &BTreeMap<TriangleKey, usize>, b: &BTreeMap<TriangleKey, usize>) -> usize {
    a.iter()
        .map(|(k, &n)| n.saturating_sub(b.get(k).copied().unwrap_or(0)))
        .sum()
}

/// The seeded generator of the strokes (SplitMix64).
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `lo..hi`.
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }

    fn unit_vector(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            );
            let n = v.length();
            if (0.1..=1.0).contains(&n) {
                return v / n;
            }
        }
    }
}

/// The first point from `from` towards `to` where the solid's value changes sign, found by
/// marching [`MARCH_STEPS`] steps and bisecting the first step that changes sign.
///
/// The recorded figures were taken with this march, from before [`Sampler::ray_hit`] had a
/// budget of pieces (on Figure 7.8's constant "0" it used to visit all 10^7 pieces of its
/// tolerance); a march also places strokes the same way on every build.
fn first_crossing(sampler: &mut Sampler, from: DVec3, to: DVec3) -> Option<DVec3> {
    let at = |k: f64| from + (to - from) * (k / MARCH_STEPS as f64);
    let inside = |sampler: &mut Sampler, p: DVec3| sampler.value(p, 0.0) >= 0.0;
    let start_inside = inside(sampler, from);
    let k = (1..=MARCH_STEPS).find(|&k| inside(sampler, at(k as f64)) != start_inside)?;
    let (mut lo, mut hi) = ((k - 1) as f64, k as f64);
    for _ in 0..BISECTIONS {
        let mid = (lo + hi) / 2.0;
        if inside(sampler, at(mid)) == start_inside {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(at(hi))
}

/// One stroke drawn across the object's surface: a straight movement of 10-30% of the box,
/// started where a ray from a random direction towards the centre first meets the surface. Three strokes in four carve
/// (subtract), one adds; tools cycle through ball, rounded box and cylinder, every other
/// stroke blended.
fn stroke(
    rng: &mut SplitMix64,
    object: &Object,
    bounds: Aabb,
    edit_idx: usize,
    session: &SessionSpec,
) -> Edit {
    let centre = dvec(bounds.centre());
    let size = f64::from(bounds.size()[0]);
    let reach = size * 0.87;
    let mut sampler = object.sampler();
    let mut start = centre;
    let mut normal = DVec3::Y;
    for _ in 0..MAX_SURFACE_TRIES {
        let d = rng.unit_vector();
        if let Some(p) = first_crossing(&mut sampler, centre + d * reach, centre - d * reach) {
            start = p;
            normal = d;
            break;
        }
    }
    let angle = rng.range(0.0, std::f64::consts::TAU);
    let across = DQuat::from_axis_angle(normal, angle) * normal.any_orthonormal_vector();
    let length = size * rng.range(0.1, 0.3);
    let tilt = DQuat::from_axis_angle(rng.unit_vector(), rng.range(0.0, std::f64::consts::PI));
    let n = session.poses_per_stroke.max(1);
    let path = (0..n)
        .map(|i| {
            let f = if n == 1 {
                0.0
            } else {
                i as f64 / (n - 1) as f64 - 0.5
            };
            Pose {
                position: start + across * (length * f),
                // The hand turns a little along the stroke.
                rotation: tilt * DQuat::from_axis_angle(normal, f * 0.3),
                scale: 1.0,
            }
        })
        .collect();
    let r = size * rng.range(0.025, 0.05);
    let tool = match edit_idx % 3 {
        0 => ToolShape::Sphere { radius: r },
        1 => ToolShape::Box {
            half_extents: DVec3::new(r, 0.8 * r, 0.6 * r),
            rounding: 0.2 * r,
        },
        _ => ToolShape::Cylinder {
            radius: 0.7 * r,
            half_height: r,
        },
    };
    let op = if edit_idx % 4 == 3 {
        EditOp::Union
    } else {
        EditOp::Subtract
    };
    let mut edit = Edit::stroke(op, tool, path);
    if edit_idx % 2 == 1 {
        edit.blend_radius = 0.3 * r;
    }
    edit
}
