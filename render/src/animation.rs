//! Animated scenes: an [`Animator`] keeps a drawable [`Scene`] of an `fdsl` scene and brings
//! it to each frame's time, doing only the work time asks for, within a per-frame budget.
//!
//! Each object is classified once, when the animator is made:
//! - a shape of time (its formula reads `t`) is meshed again every frame, at the deepest
//!   octree depth (at most [`SnapshotSettings::depth`], at least [`MIN_ANIMATED_DEPTH`])
//!   whose predicted cost fits its share of the frame's [`FrameBudget`];
//! - an appearance of time (any colour, transparency, shininess or texture formula reads
//!   `t`) is applied again to the kept mesh;
//! - a moving object (with a motion) is placed again;
//! - force fields are sampled again (their formulas may read `t`, their containers move);
//! - everything else is left as it is: its `Arc<Mesh>` stays the same allocation, so the
//!   renderer does not upload it again.
//!
//! The budget counts octree blocks evaluated (each [`BLOCK_CELLS`](crate::mesh::octree::BLOCK_CELLS)^3
//! cells, one bulk evaluation of its lattice): a measure of work that does not depend on the
//! machine, so frames stay reproducible. A depth is first guessed from the last frame's count
//! (a surface's blocks grow four times per level), then checked before meshing with
//! [`count_blocks`] (interval arithmetic only, which gives exactly the blocks meshing will
//! evaluate) and lowered until it fits. So a frame never evaluates more blocks than its budget,
//! unless even [`MIN_ANIMATED_DEPTH`] does not fit (the shape is then meshed at that depth
//! anyway; [`FrameStats::over_budget`] says so). Parametric shapes of time cost no blocks and
//! are sampled at their own tolerances.

use std::sync::Arc;

use fdsl::Tape;
use glam::Mat4;
use model::object::{Object, Slot};
use model::scene::ObjectId;

use crate::appearance::CompiledAppearance;
use crate::mesh::object_field::mesh_bounds;
use crate::mesh::octree::{MeshSettings, count_blocks};
use crate::mesh::{Mesh, ObjectField};
use crate::scene::{Material, Scene, SceneObject};
use crate::snapshot::{
    MAX_FORCE_CONTAINER_OPACITY, SnapshotError, SnapshotSettings, check, colour, force_arrows,
    object_mesh, render_from_scene, to_mat4,
};

/// The shallowest depth an animated shape is meshed at, whatever the budget.
pub const MIN_ANIMATED_DEPTH: u8 = 3;

/// The work one frame may do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameBudget {
    /// Octree blocks evaluated over all shapes of time.
    pub blocks_max: usize,
}

/// What one frame did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FrameStats {
    /// Octree blocks evaluated.
    pub blocks_evaluated: usize,
    /// Objects meshed again, with the depth each got.
    pub remeshed: Vec<(ObjectId, u8)>,
    /// Objects whose appearance was applied again.
    pub n_recoloured: usize,
    /// Objects placed again.
    pub n_moved: usize,
    /// Whether a shape did not fit its share even at [`MIN_ANIMATED_DEPTH`].
    pub over_budget: bool,
}

/// One object and what time changes of it.
struct Animated {
    id: ObjectId,
    object: Object,
    sampler: model::object::Sampler,
    world_from_group: model::object::Transform,
    appearance: CompiledAppearance,
    timed_shape: bool,
    timed_look: bool,
    moving: bool,
    has_force: bool,
    /// The mesh in object space before the appearance (for shapes or looks of time).
    base: Arc<Mesh>,
    /// The depth `base` was meshed at, and the blocks it took.
    depth: u8,
    blocks: usize,
}

/// A drawable scene kept up to date with time; see the module documentation.
pub struct Animator {
    settings: SnapshotSettings,
    objects: Vec<Animated>,
    scene: Scene,
}

/// Whether a compiled formula reads `t` (the object's tapes: nothing is compiled here).
fn reads_time(tape: &Tape) -> bool {
    tape.inputs()[3].is_some()
}

/// Whether `object`'s shape (implicit or parametric) reads `t`.
fn shape_reads_time(object: &Object) -> bool {
    object.tape(Slot::Geometry).is_some_and(reads_time)
}

/// Whether any colour, transparency, shininess or texture formula of `object` reads `t`.
fn look_reads_time(object: &Object) -> bool {
    [
        Slot::Diffuse,
        Slot::Ambient,
        Slot::Specular,
        Slot::Transparency,
        Slot::Shininess,
        Slot::Displacement,
    ]
    .into_iter()
    .any(|slot| object.tape(slot).is_some_and(reads_time))
}

/// Whether anything `snapshot` draws of `object` changes with time: its shape, its look, or
/// its force field's arrows (a motion only moves it: see `Object::data().motion`).
pub fn object_reads_time(object: &Object) -> bool {
    shape_reads_time(object)
        || look_reads_time(object)
        || object.tape(Slot::Force).is_some_and(reads_time)
}

impl Animator {
    /// Meshes every object of `scene` at `settings.t_secs` and `settings.depth` (this first
    /// build is not bounded by a budget).
    pub fn new(
        scene: &model::scene::Scene,
        settings: &SnapshotSettings,
    ) -> Result<Animator, SnapshotError> {
        check(settings)?;
        let mut animator = Animator {
            settings: settings.clone(),
            objects: Vec::new(),
            scene: Scene::default(),
        };
        for (id, entry) in scene.objects() {
            let object = entry.object.clone();
            let data = object.data();
            let timed_shape = shape_reads_time(&object);
            let built = object_mesh(
                &object,
                settings.depth,
                settings.t_secs,
                settings.mesh_threads,
            );
            let animated = Animated {
                id,
                sampler: object.sampler(),
                world_from_group: scene.world_from_group(entry.group),
                appearance: CompiledAppearance::of(&object),
                timed_shape,
                timed_look: look_reads_time(&object),
                moving: data.motion.is_some(),
                has_force: data.physics.force.as_ref().is_some_and(|f| f.enabled),
                base: Arc::new(built.mesh),
                depth: settings.depth,
                blocks: built.blocks_evaluated,
                object,
            };
            animator.scene.objects.push(SceneObject {
                mesh: Arc::new(Mesh::default()),
                world_from_object: Mat4::IDENTITY,
                material: Material::default(),
                closed: false,
                pick_runs: Default::default(),
            });
            animator.objects.push(animated);
        }
        let t = settings.t_secs;
        for i in 0..animator.objects.len() {
            animator.place(i, t);
            animator.recolour(i, t);
        }
        animator.sample_forces(t);
        Ok(animator)
    }

    /// The scene as of the last frame (camera untouched: aim it with
    /// [`snapshot::frame`](crate::snapshot::frame)).
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The scene, to aim the camera or add lines (they last until the next frame's force
    /// arrows replace the lines).
    pub fn scene_mut(&mut self) -> &mut Scene {
        &mut self.scene
    }

    /// Brings the scene to time `t_secs`, meshing shapes of time within `budget`.
    pub fn frame(&mut self, t_secs: f64, budget: FrameBudget) -> FrameStats {
        let mut stats = FrameStats::default();
        let t = if t_secs.is_finite() { t_secs } else { 0.0 };
        let n_timed = self.objects.iter().filter(|o| o.timed_shape).count();
        let mut n_left = n_timed;
        for i in 0..self.objects.len() {
            let o = &self.objects[i];
            if o.timed_shape {
                let share = budget.blocks_max.saturating_sub(stats.blocks_evaluated) / n_left;
                n_left -= 1;
                let (depth, fits) = self.depth_within(i, share, t);
                stats.over_budget |= !fits;
                let o = &mut self.objects[i];
                let built = object_mesh(&o.object, depth, t, self.settings.mesh_threads);
                o.base = Arc::new(built.mesh);
                (o.depth, o.blocks) = (depth, built.blocks_evaluated);
                stats.blocks_evaluated += built.blocks_evaluated;
                stats.remeshed.push((o.id, depth));
            }
            let o = &self.objects[i];
            if o.timed_shape || o.timed_look {
                self.recolour(i, t);
                stats.n_recoloured += 1;
            }
            if self.objects[i].moving {
                self.place(i, t);
                stats.n_moved += 1;
            }
        }
        self.sample_forces(t);
        stats
    }

    /// The deepest depth at which object `i` costs at most `share` blocks at time `t` (and
    /// whether it fits at all): guessed from the last frame, one level deeper at most, then
    /// counted and lowered until the count fits.
    fn depth_within(&self, i: usize, share: usize, t: f64) -> (u8, bool) {
        let o = &self.objects[i];
        let deepest = self.settings.depth.max(MIN_ANIMATED_DEPTH);
        let mut depth = MIN_ANIMATED_DEPTH;
        while depth < deepest && depth < o.depth + 1 {
            let levels = i32::from(depth + 1) - i32::from(o.depth);
            if (o.blocks as f64) * 4f64.powi(levels) > share as f64 {
                break;
            }
            depth += 1;
        }
        loop {
            let blocks = match mesh_bounds(&o.object, depth) {
                Some(bounds) => count_blocks(
                    &mut ObjectField::new(&o.object, t),
                    &MeshSettings { bounds, depth },
                )
                .unwrap_or(0),
                None => 0,
            };
            if blocks <= share {
                return (depth, true);
            }
            if depth == MIN_ANIMATED_DEPTH {
                return (depth, false);
            }
            depth -= 1;
        }
    }

    /// Places object `i` at time `t`.
    fn place(&mut self, i: usize, t: f64) {
        let o = &mut self.objects[i];
        let scene_from_object =
            model::scene::world_from_object(&o.world_from_group, &mut o.sampler, t);
        self.scene.objects[i].world_from_object =
            render_from_scene() * to_mat4(scene_from_object.parent_from_child);
    }

    /// Applies object `i`'s appearance at time `t` to its base mesh.
    fn recolour(&mut self, i: usize, t: f64) {
        let o = &mut self.objects[i];
        let (mesh, mut material) = colour(&o.object, &mut o.appearance, (*o.base).clone(), t);
        if o.has_force && self.settings.force_arrows > 0 {
            material.opacity = material.opacity.min(MAX_FORCE_CONTAINER_OPACITY);
        }
        let drawn = &mut self.scene.objects[i];
        drawn.mesh = Arc::new(mesh);
        drawn.pick_runs = Default::default();
        drawn.material = material;
    }

    /// Samples every force field again at time `t`.
    fn sample_forces(&mut self, t: f64) {
        if self.settings.force_arrows == 0 {
            return;
        }
        self.scene.lines.clear();
        for (i, o) in self.objects.iter_mut().enumerate() {
            if o.has_force {
                let world_from_object = self.scene.objects[i].world_from_object;
                self.scene.lines.extend(force_arrows(
                    &mut o.sampler,
                    self.settings.force_arrows,
                    t,
                    world_from_object,
                ));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use formats::fvrml::{LoadOptions, load};

    /// A pulsing ball (a shape of time), a ball changing colour (a look of time), a box
    /// moving along x (a motion) and a still ball.
    fn scene() -> model::scene::Scene {
        let text = r#"
            DEF Pulse FShape { geometry FGeometry {
                definition "0.45+0.15*sin(t)-sqrt(x^2+y^2+z^2)" bboxSize 1.4 1.4 1.4 } }
            DEF Blush FShape {
                geometry FGeometry { definition "0.3-sqrt((x-2)^2+y^2+z^2)"
                    bboxCenter 2 0 0 bboxSize 0.8 0.8 0.8 }
                appearance FAppearance { material FMaterial {
                    diffuseColor "r = 0.5+0.5*sin(t); g = 0.2; b = 0.5-0.5*sin(t);" } } }
            FTransform { translationFunction "x = t; y = 0; z = 0;" children [
                DEF Slide FShape { geometry Box { size 0.4 0.4 0.4 } } ] }
            DEF Still FShape { geometry FGeometry {
                definition "0.3-sqrt(x^2+(y-2)^2+z^2)" bboxCenter 0 2 0 bboxSize 0.8 0.8 0.8 } }
        "#;
        let mut no_files = |path: &str| Err(format!("no file {path}"));
        load(text, &LoadOptions::default(), &mut no_files)
            .unwrap()
            .scene
    }

    fn settings() -> SnapshotSettings {
        SnapshotSettings {
            depth: 6,
            ..SnapshotSettings::default()
        }
    }

    #[test]
    fn frames_redo_only_what_time_changes_and_stay_within_budget() {
        let mut animator = Animator::new(&scene(), &settings()).unwrap();
        let name_idx = |name: &str| {
            animator
                .objects
                .iter()
                .position(|o| o.object.data().name == name)
                .unwrap()
        };
        let (pulse, blush, slide, still) = (
            name_idx("Pulse"),
            name_idx("Blush"),
            name_idx("Slide"),
            name_idx("Still"),
        );
        let full_depth_blocks = animator.objects[pulse].blocks;
        let budget = FrameBudget {
            blocks_max: full_depth_blocks / 3,
        };
        let before = animator.scene().objects.clone();
        for k in 1..=20 {
            let t = 0.1 * f64::from(k);
            let stats = animator.frame(t, budget);
            assert!(
                stats.blocks_evaluated <= budget.blocks_max && !stats.over_budget,
                "t = {t}: {stats:?}"
            );
            assert!(stats.blocks_evaluated > 0);
            // The budget allows a third of depth 6's blocks: depth 6 does not fit.
            assert_eq!(stats.remeshed.len(), 1);
            let (id, depth) = stats.remeshed[0];
            assert!(id == animator.objects[pulse].id && depth < 6, "{stats:?}");
            assert_eq!((stats.n_recoloured, stats.n_moved), (2, 1));
            let now = &animator.scene().objects;
            assert!(Arc::ptr_eq(&now[still].mesh, &before[still].mesh), "still");
            assert!(Arc::ptr_eq(&now[slide].mesh, &before[slide].mesh), "slide");
            // The pulse's radius follows 0.45 + 0.15 sin(t) to within about a cell.
            let b = now[pulse].mesh.bounds().unwrap();
            let radius = 0.5 * b.size()[0];
            let expected = 0.45 + 0.15 * t.sin() as f32;
            let cell = 1.5 / (1u32 << depth) as f32;
            assert!(
                (radius - expected).abs() < cell,
                "t = {t}: {radius} vs {expected}"
            );
            // The slide moved to x = t (scene x is world x).
            let x = now[slide].world_from_object.w_axis.x;
            assert!((x - t as f32).abs() < 1e-5, "{x}");
            // The blush's red follows sin(t).
            let red = now[blush].mesh.colours[0][0];
            assert!((red - (0.5 + 0.5 * t.sin() as f32)).abs() < 1e-3);
        }
        // A budget for the whole depth meshes at the whole depth.
        let stats = animator.frame(
            2.5,
            FrameBudget {
                blocks_max: 4 * full_depth_blocks,
            },
        );
        assert_eq!(stats.remeshed[0].1, 6);
        // No budget at all still meshes, at the shallowest depth, and says so.
        let stats = animator.frame(2.6, FrameBudget { blocks_max: 0 });
        assert_eq!(stats.remeshed[0].1, MIN_ANIMATED_DEPTH);
        assert!(stats.over_budget);
        assert!(animator.scene().objects[pulse].mesh.n_triangles() > 0);
    }
}
