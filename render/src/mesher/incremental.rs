//! One mesh job: the kept octree patched where the changed edits act when only an implicit
//! object's edit history changed, otherwise the object meshed whole (see the parent module).

use std::ops::Range;
use std::sync::Arc;

use glam::{DMat4, Mat4};
use model::bvh::Aabb as Aabb64;
use model::object::history::HistoryEntry;
use model::object::{CompiledEdit, Object, Shape, Transform};

use super::{MAX_PATCH_EDITS, MeshJob, MeshKind, Meshed, Spares};
use crate::appearance::CompiledAppearance;
use crate::mesh::object_field::{Dirty, dirty_boxes, mesh_bounds, to_f32_box};
use crate::mesh::octree::{MAX_OCTREE_DEPTH, MeshPatch, MeshSettings, OctreeMesher};
use crate::mesh::{Aabb, Mesh, ObjectField};
use crate::scene::{Line, Material, PickRuns, SceneObject};
use crate::snapshot::{
    SnapshotSettings, build, colour_vertices, is_colour_paint, render_from_scene,
};

/// Cells kept between an object's bounds and its octree's for a patch. `mesh_bounds` leaves
/// 2.5 for a surface the domain clips; a union's box already reaches past its solid (by the
/// tool's margin), so one cell keeps the surface strictly inside.
const GRID_MARGIN_CELLS: f32 = 1.0;

/// What the workers keep of one implicit object between its jobs.
pub(super) struct Incremental {
    /// The object the octree's blocks hold, except inside `dirty`.
    object: Object,
    world_from_group: Transform,
    depth: u8,
    bounds: Aabb,
    pub(super) octree: OctreeMesher,
    /// The last mesh handed out (coloured, ambient colours included).
    pub(super) mesh: Arc<Mesh>,
    appearance: CompiledAppearance,
    world_from_object: Mat4,
    material: Material,
    /// The surface stays strictly inside `bounds`, so the mesh is closed
    /// ([`OctreeMesher::encloses`]).
    closed: bool,
    /// Boxes a stopped patch may have remeshed with a newer field: the next job remeshes them.
    dirty: Vec<Aabb>,
    /// The run boxes of `mesh` (shared with the object handed out, whose worker makes them
    /// once it is out): a patch's are made from them.
    runs: PickRuns,
}

/// Meshes one job: patched from `state` when only edits changed, otherwise whole. `None` when
/// a newer job superseded it (`superseded` is asked before the work and between boxes). A
/// patch is written into a mesh from `spares` when one is free, and leaves its base there.
pub(super) fn mesh(
    job: Box<MeshJob>,
    state: Option<Incremental>,
    superseded: &dyn Fn() -> bool,
    spares: &Spares,
) -> (Option<Meshed>, Option<Incremental>) {
    if superseded() {
        return (None, state);
    }
    let MeshJob {
        id,
        mut object,
        world_from_group,
        generation,
        depth,
        requested_at,
        t_secs,
        coarse_first: _,
    } = *job;
    object.prepare();
    let mut out = Meshed {
        id,
        generation,
        object: None,
        lines: Vec::new(),
        n_triangles: 0,
        skipped: None,
        mesh_secs: 0.0,
        requested_at,
        t_secs,
        kind: MeshKind::Whole,
        patch: None,
        coarse: false,
    };
    let previous = state.as_ref().map(|s| Arc::clone(&s.mesh));
    let kept = state.filter(|s| s.depth == depth && s.world_from_group == world_from_group);
    let patched = match kept.map(|state| patch(state, &object, superseded, spares)) {
        Some(Patched::Done(state, patch, kind)) => {
            out.kind = kind;
            out.patch = patch;
            Some(state)
        }
        Some(Patched::Stopped(state)) => return (None, Some(state)),
        Some(Patched::Whole) | None => None,
    };
    let mut state = match patched {
        Some(state) => Some(state),
        None => whole(object, world_from_group, depth, previous, &mut out),
    };
    if let Some(state) = &mut state {
        // A patch's run boxes come from its base's; an unchanged mesh keeps its own.
        state.runs = match (&out.patch, out.kind) {
            (Some((base, patch)), MeshKind::Patch) => state.runs.patched(base, &state.mesh, patch),
            (_, MeshKind::Unchanged) => state.runs.clone(),
            _ => PickRuns::default(),
        };
        out.t_secs = 0.0;
        out.n_triangles = state.mesh.n_triangles();
        out.object = (out.n_triangles > 0).then(|| SceneObject {
            mesh: Arc::clone(&state.mesh),
            world_from_object: state.world_from_object,
            material: state.material,
            closed: state.closed,
            pick_runs: state.runs.clone(),
        });
    }
    (Some(out), state)
}

/// Meshes the job's object from scratch into `out`: keeping what later patches need (the
/// patch from `previous`, the mesh last handed out) when it can take the incremental path,
/// otherwise as `snapshot` draws it.
fn whole(
    object: Object,
    world_from_group: Transform,
    depth: u8,
    previous: Option<Arc<Mesh>>,
    out: &mut Meshed,
) -> Option<Incremental> {
    if !patchable(&object) {
        snapshot(object, world_from_group, depth, out);
        return None;
    }
    match mesh_whole(object, world_from_group, depth) {
        Ok((state, patch)) => {
            out.patch = Some((previous.unwrap_or_default(), patch));
            Some(state)
        }
        Err(reason) => {
            out.skipped = Some(reason);
            None
        }
    }
}

/// Whether an object can take the incremental path: an implicit shape (what the octree meshes
/// alone), without a geometric texture (a patch reads the mesh's positions, which that moves)
/// and without force arrows (which edits move).
pub(super) fn patchable(object: &Object) -> bool {
    let data = object.data();
    let implicit = data
        .geometry
        .as_ref()
        .is_some_and(|g| matches!(g.shape, Shape::Implicit(_)));
    let force = data.physics.force.as_ref().is_some_and(|f| f.enabled);
    implicit
        && data.appearance.displacement.is_none()
        && !force
        && !crate::animation::object_reads_time(object)
}

enum Patched {
    Done(Incremental, Option<(Arc<Mesh>, MeshPatch)>, MeshKind),
    /// A newer job came between boxes: the state, with the boxes to remesh next time.
    Stopped(Incremental),
    /// Not an edit-only change: mesh whole.
    Whole,
}

/// An edit whose activity differs between two objects, and where it can change the field:
/// everywhere the edit acts, or only `grown`'s boxes for a stroke drawn further.
struct Change<'a> {
    edit: &'a CompiledEdit,
    grown: Option<[Aabb64; 2]>,
}

/// The edits whose activity differs between `old` and `new` (changed in a common prefix of
/// the same edits, or in the tails after it); `None` past [`MAX_PATCH_EDITS`]. Where the tails
/// pair up as strokes drawn further (a stroke's previews), each pair is one change over the
/// stamps the longer stroke adds ([`CompiledEdit::grown_from`]), not both strokes' boxes.
fn changed_edits<'a>(old: &'a Object, new: &'a Object) -> Option<Vec<Change<'a>>> {
    let (a, b) = (old.history().entries(), new.history().entries());
    let same = |x: &HistoryEntry, y: &HistoryEntry| {
        Arc::ptr_eq(&x.edit, &y.edit) || x.edit.edit() == y.edit.edit()
    };
    let prefix = a.iter().zip(b).take_while(|(x, y)| same(x, y)).count();
    let whole = |edit| Change { edit, grown: None };
    let mut changed = Vec::new();
    for (x, y) in a[..prefix].iter().zip(&b[..prefix]) {
        if x.active != y.active {
            changed.push(whole(&*y.edit));
        }
    }
    let (a, b) = (&a[prefix..], &b[prefix..]);
    let tails = (a.len() == b.len()).then(|| grown_pairs(a, b)).flatten();
    let tails = tails.unwrap_or_else(|| {
        let active = a.iter().chain(b).filter(|e| e.active);
        active.map(|e| whole(&*e.edit)).collect()
    });
    for change in tails {
        if changed.len() >= MAX_PATCH_EDITS {
            return None;
        }
        changed.push(change);
    }
    Some(changed)
}

/// `b`'s entries as `a`'s strokes drawn further, pair by pair, each a change over the stamps
/// it adds; `None` unless every pair is active and such a continuation.
fn grown_pairs<'a>(a: &[HistoryEntry], b: &'a [HistoryEntry]) -> Option<Vec<Change<'a>>> {
    let grown = |(x, y): (&HistoryEntry, &'a HistoryEntry)| {
        let both = x.active && y.active;
        let region = both.then(|| y.edit.grown_from(&x.edit)).flatten()?;
        Some(Change {
            edit: &y.edit,
            grown: Some(region),
        })
    };
    a.iter().zip(b).map(grown).collect()
}

/// Brings `state` up to `object` by remeshing the changed edits' boxes and patching the mesh.
fn patch(
    mut state: Incremental,
    object: &Object,
    superseded: &dyn Fn() -> bool,
    spares: &Spares,
) -> Patched {
    if state.object.data() != object.data() || !covers(state.bounds, state.depth, object) {
        return Patched::Whole;
    }
    let Some(changed) = changed_edits(&state.object, object) else {
        return Patched::Whole;
    };
    let mut boxes = std::mem::take(&mut state.dirty);
    let mut colour_boxes = Vec::new();
    for Change { edit, grown } in changed {
        if edit.is_geometric() {
            // An intersection drawn further is meshed whole, as when first drawn: outside
            // its boxes it empties the object, which only a whole mesh has been shown to take.
            match (dirty_boxes(edit), grown) {
                (Dirty::Everywhere, _) => return Patched::Whole,
                (Dirty::Boxes(_), Some(grown)) => boxes.extend(grown.iter().filter_map(to_f32_box)),
                (Dirty::Boxes(b), None) => boxes.extend(b),
            }
        } else if is_colour_paint(edit) {
            let region = grown.as_ref().unwrap_or(edit.boxes());
            colour_boxes.extend(region.iter().filter_map(to_f32_box));
        }
    }
    if boxes.is_empty() && colour_boxes.is_empty() {
        state.object = object.clone();
        return Patched::Done(state, None, MeshKind::Unchanged);
    }
    let mut field = ObjectField::new(object, 0.0);
    for (k, b) in boxes.iter().enumerate() {
        if k > 0 && superseded() {
            // Blocks of the boxes done hold the newer field: remesh every box next time.
            state.dirty = boxes;
            return Patched::Stopped(state);
        }
        if (state.octree)
            .remesh_parallel(&mut field, *b, super::remesh_threads(super::WINDOW_CORES))
            .is_err()
        {
            return Patched::Whole;
        }
    }
    if !boxes.is_empty() {
        state.closed = state.octree.encloses();
    }
    let Some(patch) = patch_mesh(&mut state, object, &colour_boxes, spares) else {
        return Patched::Whole;
    };
    let base = std::mem::replace(&mut state.mesh, Arc::new(patch.1));
    spares.give(Arc::clone(&base));
    state.object = object.clone();
    Patched::Done(state, Some((base, patch.0)), MeshKind::Patch)
}

/// The mesh `state`'s remeshed octree gives, patched from its last one (in a spare's buffers
/// when one is free) and recoloured where the patch wrote or a colour painting's box reaches;
/// `None` when the octree cannot assemble it.
fn patch_mesh(
    state: &mut Incremental,
    object: &Object,
    colour_boxes: &[Aabb],
    spares: &Spares,
) -> Option<(MeshPatch, Mesh)> {
    let mut mesh = match spares.take() {
        Some(mut spare) => {
            spare.clone_from(&state.mesh);
            spare
        }
        None => Mesh::clone(&state.mesh),
    };
    let ambient = std::mem::take(&mut mesh.ambient);
    let mut patch = state.octree.mesh_update(&mut mesh).ok()?;
    let mut ranges = patch.vertex_ranges.clone();
    if !colour_boxes.is_empty() {
        let inside = |p: &[f32; 3]| {
            colour_boxes
                .iter()
                .any(|b| (0..3).all(|a| b.lo[a] <= p[a] && p[a] <= b.hi[a]))
        };
        let painted = (0..mesh.n_vertices()).filter(|&i| inside(&mesh.positions[i]));
        ranges.extend(painted.map(|i| i..i + 1));
        ranges = merged(ranges);
    }
    recolour(object, &mut state.appearance, &mut mesh, &ranges, ambient);
    patch.vertex_ranges = ranges;
    Some((patch, mesh))
}

/// Whether the octree over `grid` at `depth` still holds `object`'s bounds with
/// [`GRID_MARGIN_CELLS`] to spare: a union that reaches past that needs a larger grid, meshed
/// whole.
fn covers(grid: Aabb, depth: u8, object: &Object) -> bool {
    let Some(b) = object.bounds().as_ref().and_then(to_f32_box) else {
        return false;
    };
    let side = grid.size().into_iter().fold(0.0f32, f32::max);
    let margin = GRID_MARGIN_CELLS * side / (1u32 << depth.min(MAX_OCTREE_DEPTH)) as f32;
    (0..3).all(|a| grid.lo[a] + margin <= b.lo[a] && b.hi[a] <= grid.hi[a] - margin)
}

/// `ranges` sorted, with overlapping and touching ones joined.
pub(super) fn merged(mut ranges: Vec<Range<usize>>) -> Vec<Range<usize>> {
    ranges.sort_by_key(|r| r.start);
    let mut out: Vec<Range<usize>> = Vec::with_capacity(ranges.len());
    for r in ranges {
        match out.last_mut() {
            Some(last) if r.start <= last.end => last.end = last.end.max(r.end),
            _ => out.push(r),
        }
    }
    out
}

/// Sets the colours (and ambient colours, kept in `ambient` until now) of the vertices in
/// `ranges` by `snapshot`'s colouring of a whole mesh at t = 0, run over those vertices alone.
pub(super) fn recolour(
    object: &Object,
    appearance: &mut CompiledAppearance,
    mesh: &mut Mesh,
    ranges: &[Range<usize>],
    mut ambient: Vec<[f32; 3]>,
) {
    let n = mesh.n_vertices();
    let picked: Vec<usize> = ranges
        .iter()
        .flat_map(Clone::clone)
        .filter(|&i| i < n)
        .collect();
    let mut part = Mesh {
        positions: picked.iter().map(|&i| mesh.positions[i]).collect(),
        normals: picked.iter().map(|&i| mesh.normals[i]).collect(),
        ..Mesh::default()
    };
    colour_vertices(object, appearance, &mut part, 0.0);
    for (k, &i) in picked.iter().enumerate() {
        mesh.colours[i] = part.colours[k];
    }
    if part.ambient.is_empty() {
        mesh.ambient.clear();
    } else {
        ambient.resize(n, [0.0; 3]);
        for (k, &i) in picked.iter().enumerate() {
            ambient[i] = part.ambient[k];
        }
        mesh.ambient = ambient;
    }
}

/// Meshes a patchable object from scratch, keeping what later patches need.
fn mesh_whole(
    object: Object,
    world_from_group: Transform,
    depth: u8,
) -> Result<(Incremental, MeshPatch), String> {
    let bounds = mesh_bounds(&object, depth)
        .ok_or_else(|| model::object::FitError::Unbounded.to_string())?;
    let mut octree =
        OctreeMesher::new(&MeshSettings { bounds, depth }).map_err(|e| e.to_string())?;
    let mut field = ObjectField::new(&object, 0.0);
    (octree.remesh_parallel(
        &mut field,
        bounds,
        super::remesh_threads(super::WINDOW_CORES),
    ))
    .map_err(|e| e.to_string())?;
    let closed = octree.encloses();
    let mut mesh = Mesh::default();
    let patch = octree.mesh_update(&mut mesh).map_err(|e| e.to_string())?;
    let mut appearance = CompiledAppearance::of(&object);
    let everything = std::slice::from_ref(&(0..mesh.n_vertices())).to_vec();
    recolour(&object, &mut appearance, &mut mesh, &everything, Vec::new());
    let material = appearance.material(&mesh, 0.0, Material::default());
    let scene_from_object = world_from_group.then(&object.sampler().placement(0.0));
    let world_from_object =
        render_from_scene() * DMat4::from(scene_from_object.parent_from_child).as_mat4();
    let state = Incremental {
        object,
        world_from_group,
        depth,
        bounds,
        octree,
        mesh: Arc::new(mesh),
        appearance,
        world_from_object,
        material,
        closed,
        dirty: Vec::new(),
        runs: PickRuns::default(),
    };
    Ok((state, patch))
}

/// Meshes one object (`out`'s, at its scene time) through a one-object scene, so that
/// `snapshot` does everything it does for `sculpt render` (parametric shapes, imported meshes,
/// textures, force arrows).
fn snapshot(object: Object, world_from_group: Transform, depth: u8, out: &mut Meshed) {
    let mut scene = model::scene::Scene::new();
    let settings = SnapshotSettings {
        depth,
        t_secs: out.t_secs,
        mesh_threads: super::remesh_threads(super::WINDOW_CORES),
        ..SnapshotSettings::default()
    };
    let built = scene
        .insert_object(out.id, object, None)
        .map_err(|e| e.to_string())
        .and_then(|()| build(&scene, &settings).map_err(|e| e.to_string()));
    match built {
        Ok(built) => {
            // The group's transform, moved from the scene's +y-up space into the renderer's.
            let turn = render_from_scene();
            let group =
                turn * DMat4::from(world_from_group.parent_from_child).as_mat4() * turn.inverse();
            let place = |m: Mat4| group * m;
            out.object = built.scene.objects.into_iter().next().map(|mut o| {
                o.world_from_object = place(o.world_from_object);
                o
            });
            out.lines = built
                .scene
                .lines
                .into_iter()
                .map(|l| Line {
                    from: group.transform_point3(l.from),
                    to: group.transform_point3(l.to),
                    colour: l.colour,
                })
                .collect();
            if let Some(report) = built.objects.into_iter().next() {
                out.n_triangles = report.n_triangles;
                out.skipped = report.skipped;
            }
        }
        Err(e) => out.skipped = Some(e),
    }
}
