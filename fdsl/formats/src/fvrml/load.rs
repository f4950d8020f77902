//! A [`Document`] to a [`Scene`]: shapes become objects, `Transform`, `Group` and `FTransform`
//! become groups, `DEF`/`USE` make copies, `Inline` files are read through the caller's
//! resolver. Ids are given in document order.

use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;

use super::document::{Document, Field, Node, NodeRef, Pos, Value};
use super::read::{Fields, Reader, Scope, address};
use super::{
    Issue, Issues, MAX_INLINE_DEPTH, MAX_INLINE_FILES, MAX_LOAD_EDITS, MAX_LOAD_STAMPS,
    MAX_LOAD_STEPS, MAX_NESTING_DEPTH, MAX_TOTAL_BYTES, parser,
};
use fdsl::grid::Grid;
use model::object::{CompiledEdit, Motion, Object, ObjectError, Slot, Transform};
use model::scene::{Group, GroupId, ObjectId, Scene, SceneError};

/// How to load.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// The id of the first object; the others follow in document order.
    pub first_object_id: u64,
    /// The id of the first group; the others follow in document order.
    pub first_group_id: u64,
    /// The path of the text being loaded, in the resolver's terms: `Inline` urls are relative
    /// to its directory. Empty: relative to the resolver's root.
    pub path: String,
}

/// A loaded scene.
#[derive(Debug)]
pub struct Loaded {
    /// The objects and groups.
    pub scene: Scene,
    /// What was skipped or read leniently, in file order.
    pub warnings: Vec<Issue>,
    /// The id after the last object's (to add more objects).
    pub next_object_id: u64,
    /// The id after the last group's.
    pub next_group_id: u64,
}

/// The text cannot be loaded: at least one issue is an error.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub struct LoadError {
    /// Every issue, errors and warnings, in file order.
    pub issues: Vec<Issue>,
}

impl LoadError {
    /// The errors alone.
    pub fn errors(&self) -> impl Iterator<Item = &Issue> {
        self.issues.iter().filter(|i| i.is_error())
    }
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut first = true;
        for issue in self.errors() {
            if !first {
                writeln!(f)?;
            }
            first = false;
            write!(f, "{issue}")?;
        }
        Ok(())
    }
}

/// Reads FVRML text into a scene. `resolve` gets the path of each local `Inline` (relative
/// to [`LoadOptions::path`]'s directory, normalised, with `/` separators) and returns its
/// text or why not; remote urls are not fetched (a warning says so).
pub fn load(
    text: &str,
    options: &LoadOptions,
    resolve: &mut dyn FnMut(&str) -> Result<Vec<u8>, String>,
) -> Result<Loaded, LoadError> {
    let mut issues = Issues::default();
    let doc = parser::parse(text, None, &mut issues);
    run(&doc, issues, text.len(), options, resolve)
}

/// [`load`] of a document already parsed (or built in code).
pub fn load_document(
    doc: &Document,
    options: &LoadOptions,
    resolve: &mut dyn FnMut(&str) -> Result<Vec<u8>, String>,
) -> Result<Loaded, LoadError> {
    run(doc, Issues::default(), 0, options, resolve)
}

fn run(
    doc: &Document,
    issues: Issues,
    n_bytes: usize,
    options: &LoadOptions,
    resolve: &mut dyn FnMut(&str) -> Result<Vec<u8>, String>,
) -> Result<Loaded, LoadError> {
    let mut loader = Loader {
        resolve,
        issues,
        scene: Scene::new(),
        next_object: options.first_object_id,
        next_group: options.first_group_id,
        steps: 0,
        stopped: false,
        total_bytes: n_bytes,
        n_files: 0,
        root_path: options.path.clone(),
        inline_stack: Vec::new(),
        cache: BTreeMap::new(),
        edit_cache: BTreeMap::new(),
        n_edits: 0,
        n_stamps: 0,
        fit_work_left: super::MAX_LOAD_FIT_WORK,
        carriers: std::collections::BTreeSet::new(),
    };
    let scope = Scope::new(doc, 0, None);
    let place = Place {
        group: None,
        moving: None,
        depth: 0,
    };
    for r in &doc.nodes {
        loader.visit(&scope, r, &place);
    }
    if loader.issues.has_errors() {
        return Err(LoadError {
            issues: loader.issues.finish(),
        });
    }
    Ok(Loaded {
        scene: loader.scene,
        warnings: loader.issues.finish(),
        next_object_id: loader.next_object,
        next_group_id: loader.next_group,
    })
}

/// Where the nodes being visited go.
#[derive(Clone)]
struct Place {
    group: Option<GroupId>,
    /// Inside an `FTransform` with motion: the transform from nested (flattened) groups to
    /// the moving group, and the motion.
    moving: Option<Moving>,
    depth: usize,
}

#[derive(Clone)]
struct Moving {
    transform: Transform,
    motion: Motion,
    /// Where the motion's formulas were written.
    pos: Pos,
}

/// What a group node says.
struct GroupNode<'d> {
    name: String,
    transform: Transform,
    motion: Option<(Motion, Pos)>,
    children: Vec<&'d Field>,
}

/// A compiled `FEdit` and whether it is active.
type LoadedEdit = (Arc<CompiledEdit>, bool);

struct Loader<'r> {
    resolve: &'r mut dyn FnMut(&str) -> Result<Vec<u8>, String>,
    issues: Issues,
    scene: Scene,
    next_object: u64,
    next_group: u64,
    steps: usize,
    stopped: bool,
    total_bytes: usize,
    n_files: usize,
    root_path: String,
    /// The `Inline` paths being read, outermost first.
    inline_stack: Vec<String>,
    /// Converted shapes by (file serial, node address): `USE` copies reuse them.
    cache: BTreeMap<(usize, usize), Option<Object>>,
    /// Compiled `FEdit`s and whether they are active, keyed the same way (`None`: refused,
    /// already reported).
    edit_cache: BTreeMap<(usize, usize), Option<LoadedEdit>>,
    /// Edits held by the objects loaded so far (bounded by [`MAX_LOAD_EDITS`]).
    n_edits: usize,
    /// Stamps the compiled edits expand to (bounded by [`MAX_LOAD_STAMPS`]).
    n_stamps: usize,
    /// What is left of [`super::MAX_LOAD_FIT_WORK`] for fitting domains.
    fit_work_left: u64,
    /// Objects written as shapeless `FShape`s that give their group physics (`lend.rs`).
    carriers: std::collections::BTreeSet<u64>,
}

impl Loader<'_> {
    fn error(&mut self, scope: &Scope<'_>, pos: Pos, message: impl Into<String>) {
        self.issues.error(pos, scope.file.as_deref(), message);
    }

    fn warning(&mut self, scope: &Scope<'_>, pos: Pos, message: impl Into<String>) {
        self.issues.warning(pos, scope.file.as_deref(), message);
    }

    fn visit<'d>(&mut self, scope: &Scope<'d>, r: &'d NodeRef, place: &Place) {
        if self.stopped {
            return;
        }
        self.steps += 1;
        let node = match scope.resolve(r) {
            Ok(Some(node)) => node,
            Ok(None) => return,
            Err(message) => {
                let pos = match r {
                    NodeRef::Use { pos, .. } => *pos,
                    _ => Pos::default(),
                };
                self.error(scope, pos, message);
                return;
            }
        };
        if self.steps > MAX_LOAD_STEPS {
            self.error(
                scope,
                node.pos,
                format!("loading visits more than {MAX_LOAD_STEPS} nodes (USE of USE?); stopped"),
            );
            self.stopped = true;
            return;
        }
        if place.depth > MAX_NESTING_DEPTH {
            self.error(
                scope,
                node.pos,
                format!("groups nest deeper than the limit of {MAX_NESTING_DEPTH}"),
            );
            return;
        }
        match node.type_name.as_str() {
            "FShape" | "Shape" => self.object(scope, node, place),
            "Transform" | "Group" | "FTransform" => self.group(scope, node, place),
            "Inline" => self.inline(scope, node, place),
            other => {
                let message = format!(
                    "a `{other}` cannot stand here (a shape, a group or an Inline can); ignored"
                );
                self.warning(scope, node.pos, message);
            }
        }
    }

    /// The object of a shape node, converted once per node.
    fn converted<'d>(&mut self, scope: &Scope<'d>, node: &'d Node) -> Option<Object> {
        let key = (scope.serial, address(node));
        if let Some(object) = self.cache.get(&key) {
            return object.clone();
        }
        let mut reader = Reader {
            issues: &mut self.issues,
            scope,
            positions: BTreeMap::new(),
        };
        let (mut data, edit_nodes, grid_nodes) = reader.object(node);
        let positions = reader.positions;
        data.grids = self.grids(scope, &grid_nodes).into();
        let object = match Object::new(data) {
            Ok(mut object) => {
                let left = &mut self.fit_work_left;
                for (slot, why) in super::fitted::fit_domains(&mut object, scope, node, left) {
                    let pos = positions.get(&slot).copied().unwrap_or(node.pos);
                    self.warning(scope, pos, why.to_string());
                }
                self.apply_edits(scope, &mut object, &edit_nodes);
                Some(object)
            }
            Err(e) => {
                // The edits are still read, so that their errors are reported too.
                for edit in edit_nodes {
                    if !self.stopped {
                        self.compiled_edit(scope, edit);
                    }
                }
                let pos = slot_of(&e)
                    .and_then(|slot| positions.get(&slot).copied())
                    .unwrap_or(node.pos);
                self.error(scope, pos, e.to_string());
                None
            }
        };
        self.cache.insert(key, object.clone());
        object
    }

    /// The grids of `FGrid` nodes: samples inline, or a file's (tried in url order, relative
    /// to the file being read, counted in the load's totals). One that cannot be built is an
    /// error at its node and left out (the formulas calling it then say so too).
    fn grids<'d>(&mut self, scope: &Scope<'d>, nodes: &[&'d Node]) -> Vec<Arc<Grid>> {
        let mut grids = Vec::new();
        for &node in nodes {
            let mut reader = Reader {
                issues: &mut self.issues,
                scope,
                positions: BTreeMap::new(),
            };
            let Some(read) = reader.grid(node) else {
                continue;
            };
            let mut file = None;
            let mut failures = Vec::new();
            for url in &read.urls {
                let url = url.trim();
                let Url::Relative(relative) = classify(url) else {
                    failures.push(format!("url not read (only relative paths are): {url}"));
                    continue;
                };
                let base = scope.file.as_deref().unwrap_or(&self.root_path);
                let path = join(base, relative);
                match (self.resolve)(&path) {
                    Ok(bytes) => {
                        self.total_bytes = self.total_bytes.saturating_add(bytes.len());
                        file = Some(bytes);
                        break;
                    }
                    Err(e) => failures.push(format!("cannot read grid `{path}`: {e}")),
                }
            }
            if self.total_bytes > MAX_TOTAL_BYTES {
                let message = format!("the files read exceed {MAX_TOTAL_BYTES} bytes; stopped");
                self.error(scope, read.url_pos, message);
                self.stopped = true;
                return grids;
            }
            if file.is_none() && !read.urls.is_empty() {
                for message in failures {
                    self.error(scope, read.url_pos, message);
                }
                continue;
            }
            match read.build(file.as_deref()) {
                Ok(grid) => grids.push(Arc::new(grid)),
                Err(message) => {
                    let pos = if file.is_some() {
                        read.url_pos
                    } else {
                        read.pos
                    };
                    self.error(scope, pos, format!("grid `{}`: {message}", read.name));
                }
            }
        }
        grids
    }

    /// Applies the `FEdit`s to `object` in order, through the object model (the checks edits
    /// from peers get); an edit it refuses is an error at the field it is about.
    fn apply_edits<'d>(&mut self, scope: &Scope<'d>, object: &mut Object, nodes: &[&'d Node]) {
        for &node in nodes {
            if self.stopped {
                return;
            }
            let Some((edit, active)) = self.compiled_edit(scope, node) else {
                continue;
            };
            match object.apply_compiled(edit) {
                Ok(idx) => {
                    if !active {
                        object.undo(idx);
                    }
                }
                Err(e) => {
                    // The history is full: later edits would be refused too.
                    self.error(scope, node.pos, format!("this edit cannot be applied: {e}"));
                    return;
                }
            }
        }
    }

    /// An `FEdit` read and compiled, once per node (`USE` copies share it).
    fn compiled_edit<'d>(&mut self, scope: &Scope<'d>, node: &'d Node) -> Option<LoadedEdit> {
        let key = (scope.serial, address(node));
        if let Some(cached) = self.edit_cache.get(&key) {
            return cached.clone();
        }
        let mut reader = Reader {
            issues: &mut self.issues,
            scope,
            positions: BTreeMap::new(),
        };
        let read = reader.edit(node);
        let compiled = read.and_then(|read| match CompiledEdit::new(read.edit.clone()) {
            Ok(compiled) => Some((Arc::new(compiled), read.active)),
            Err(e) => {
                let message = format!("this edit cannot be applied: {e}");
                self.error(scope, read.pos_of(&e), message);
                None
            }
        });
        if let Some((edit, _)) = &compiled {
            self.n_stamps = self.n_stamps.saturating_add(edit.n_stamps());
            if self.n_stamps > MAX_LOAD_STAMPS {
                let message = format!(
                    "the edits read expand to more than {MAX_LOAD_STAMPS} tool stamps; stopped"
                );
                self.error(scope, node.pos, message);
                self.stopped = true;
            }
        }
        self.edit_cache.insert(key, compiled.clone());
        compiled
    }

    #[inline(never)]
    fn object<'d>(&mut self, scope: &Scope<'d>, node: &'d Node, place: &Place) {
        let Some(mut object) = self.converted(scope, node) else {
            return;
        };
        if let Some(moving) = &place.moving {
            if object.data().motion.is_some() {
                self.warning(
                    scope,
                    node.pos,
                    "this shape's own motion is replaced by the enclosing FTransform's",
                );
            }
            // `set` keeps the edit history (edits are in object coordinates, which the
            // placement does not change).
            let transform = moving.transform.then(&object.data().transform);
            let placed = object
                .set(model::object::Field::Transform(Box::new(transform)))
                .and_then(|()| {
                    let motion = Box::new(moving.motion.clone());
                    object.set(model::object::Field::Motion(Some(motion)))
                });
            match placed {
                Ok(()) => {}
                Err(e) => {
                    let pos = if slot_of(&e) == Some(Slot::Motion) {
                        moving.pos
                    } else {
                        node.pos
                    };
                    self.error(scope, pos, e.to_string());
                    return;
                }
            }
        }
        self.n_edits = self.n_edits.saturating_add(object.history().len());
        if self.n_edits > MAX_LOAD_EDITS {
            let message =
                format!("the loaded objects hold more than {MAX_LOAD_EDITS} edits; stopped");
            self.error(scope, node.pos, message);
            self.stopped = true;
            return;
        }
        let id = self.next_object;
        if super::lend::written_as_carrier(scope, node) {
            self.carriers.insert(id);
        }
        match self.scene.insert_object(ObjectId(id), object, place.group) {
            Ok(()) => match id.checked_add(1) {
                Some(next) => self.next_object = next,
                None => {
                    self.error(scope, node.pos, "object ids run out");
                    self.stopped = true;
                }
            },
            Err(e) => self.scene_error(scope, node.pos, &e),
        }
    }

    fn scene_error(&mut self, scope: &Scope<'_>, pos: Pos, e: &SceneError) {
        self.error(scope, pos, e.to_string());
        if matches!(e, SceneError::Full(_)) {
            self.stopped = true;
        }
    }

    fn group<'d>(&mut self, scope: &Scope<'d>, node: &'d Node, place: &Place) {
        let group = self.read_group(scope, node);
        let children = group.children.clone();
        let Some(inner) = self.enter(scope, node, place, group) else {
            return;
        };
        let first_object = self.next_object;
        for field in children {
            match &field.value {
                Value::NodeList(list) => {
                    for r in list {
                        self.visit(scope, r, &inner);
                    }
                }
                Value::Node(r) => self.visit(scope, r, &inner),
                Value::EmptyList => {}
                _ => self.error(
                    scope,
                    field.value_pos,
                    "`children` should be a list of nodes",
                ),
            }
        }
        self.lend_physics(scope, node, inner.group, first_object);
    }

    /// A shapeless `FShape`'s physics for the shapes grouped with it ([`super::lend`]).
    fn lend_physics(&mut self, scope: &Scope<'_>, node: &Node, group: Option<GroupId>, first: u64) {
        let ids = first..self.next_object;
        let lent = super::lend::lend_physics(&mut self.scene, group, ids, &self.carriers);
        for message in lent.messages() {
            self.warning(scope, node.pos, message);
        }
    }

    /// The fields of a `Group`, `Transform` or `FTransform`.
    #[inline(never)]
    fn read_group<'d>(&mut self, scope: &Scope<'d>, node: &'d Node) -> GroupNode<'d> {
        let mut reader = Reader {
            issues: &mut self.issues,
            scope,
            positions: BTreeMap::new(),
        };
        let mut fields = Fields::new(node);
        let name = reader.name(&mut fields);
        let transform = if node.type_name == "Group" {
            Transform::IDENTITY
        } else {
            reader.transform(&mut fields)
        };
        let motion = if node.type_name == "FTransform" {
            reader.motion(&mut fields)
        } else {
            None
        };
        // VRML's bounding-box hints: nothing to do with them.
        fields.get("bboxCenter");
        fields.get("bboxSize");
        let children = fields.all("children");
        let motion_pos = reader
            .positions
            .get(&Slot::Motion)
            .copied()
            .unwrap_or(node.pos);
        reader.finish(fields);
        GroupNode {
            name,
            transform,
            motion: motion.map(|m| (m, motion_pos)),
            children,
        }
    }

    /// Makes the group (or, under a moving `FTransform`, folds its transform into the
    /// motion's frame); returns where its children go.
    #[inline(never)]
    fn enter(
        &mut self,
        scope: &Scope<'_>,
        node: &Node,
        place: &Place,
        group: GroupNode<'_>,
    ) -> Option<Place> {
        if group.transform.inverse().is_none() {
            let message = format!(
                "the transform of this `{}` is not invertible (a scale of 0?)",
                node.type_name
            );
            self.error(scope, node.pos, message);
            return None;
        }
        if let Some(moving) = &place.moving {
            if group.motion.is_some() {
                self.warning(
                    scope,
                    node.pos,
                    "an FTransform inside a moving FTransform: its motion is ignored \
                     (motions do not compose)",
                );
            }
            return Some(Place {
                group: place.group,
                moving: Some(Moving {
                    transform: moving.transform.then(&group.transform),
                    ..moving.clone()
                }),
                depth: place.depth + 1,
            });
        }
        let id = GroupId(self.next_group);
        let scene_group = Group {
            name: group.name,
            parent: place.group,
            transform: group.transform,
        };
        if let Err(e) = self.scene.set_group(id, scene_group) {
            self.scene_error(scope, node.pos, &e);
            return None;
        }
        let Some(next) = self.next_group.checked_add(1) else {
            self.error(scope, node.pos, "group ids run out");
            self.stopped = true;
            return None;
        };
        self.next_group = next;
        Some(Place {
            group: Some(id),
            moving: group.motion.map(|(motion, pos)| Moving {
                transform: Transform::IDENTITY,
                motion,
                pos,
            }),
            depth: place.depth + 1,
        })
    }

    #[inline(never)]
    fn inline<'d>(&mut self, scope: &Scope<'d>, node: &'d Node, place: &Place) {
        let mut reader = Reader {
            issues: &mut self.issues,
            scope,
            positions: BTreeMap::new(),
        };
        let mut fields = Fields::new(node);
        let url_field = fields.get("url");
        let urls = url_field
            .and_then(|f| reader.strings(f))
            .unwrap_or_default();
        fields.get("bboxCenter");
        fields.get("bboxSize");
        reader.finish(fields);
        let pos = url_field.map_or(node.pos, |f| f.value_pos);
        let mut failures = Vec::new();
        for url in urls {
            let url = url.trim();
            match classify(url) {
                Url::Remote => {
                    self.warning(scope, pos, format!("remote url not fetched: {url}"));
                }
                Url::Other => self.warning(
                    scope,
                    pos,
                    format!("url not followed (only relative paths are read): {url}"),
                ),
                Url::Relative(relative) => {
                    let base = scope.file.as_deref().unwrap_or(&self.root_path);
                    let path = join(base, relative);
                    match self.read_inline(scope, &path, pos, place) {
                        Ok(()) => {
                            for message in failures {
                                self.warning(scope, pos, message);
                            }
                            return;
                        }
                        Err(Some(message)) => failures.push(message),
                        Err(None) => return,
                    }
                }
            }
        }
        for message in failures {
            self.error(scope, pos, message);
        }
    }

    /// Reads one `Inline` file into `place`. `Err(Some)`: it could not be read (another url
    /// may be tried); `Err(None)`: an error already reported.
    fn read_inline(
        &mut self,
        scope: &Scope<'_>,
        path: &str,
        pos: Pos,
        place: &Place,
    ) -> Result<(), Option<String>> {
        if self.inline_stack.iter().any(|p| p == path) {
            let root = if self.root_path.is_empty() {
                "<input>"
            } else {
                &self.root_path
            };
            let chain: Vec<&str> = std::iter::once(root)
                .chain(self.inline_stack.iter().map(String::as_str))
                .chain(std::iter::once(path))
                .collect();
            let message = format!("Inline cycle: {}", chain.join(" -> "));
            self.error(scope, pos, message);
            return Err(None);
        }
        if self.inline_stack.len() >= MAX_INLINE_DEPTH {
            let message =
                format!("Inline files nest deeper than the limit of {MAX_INLINE_DEPTH}: {path}");
            self.error(scope, pos, message);
            return Err(None);
        }
        if self.n_files >= MAX_INLINE_FILES {
            let message = format!("more than {MAX_INLINE_FILES} Inline files; {path} not read");
            self.error(scope, pos, message);
            self.stopped = true;
            return Err(None);
        }
        let bytes =
            (self.resolve)(path).map_err(|e| Some(format!("cannot read Inline `{path}`: {e}")))?;
        let text = String::from_utf8(bytes)
            .map_err(|_| Some(format!("Inline `{path}` is not UTF-8 text")))?;
        self.total_bytes = self.total_bytes.saturating_add(text.len());
        if self.total_bytes > MAX_TOTAL_BYTES {
            let message = format!("the files read exceed {MAX_TOTAL_BYTES} bytes; {path} not read");
            self.error(scope, pos, message);
            self.stopped = true;
            return Err(None);
        }
        self.n_files += 1;
        let doc = parser::parse(&text, Some(path), &mut self.issues);
        let inner_scope = Scope::new(&doc, self.n_files, Some(path.to_string()));
        let inner = Place {
            depth: place.depth + 1,
            ..place.clone()
        };
        self.inline_stack.push(path.to_string());
        for r in &doc.nodes {
            self.visit(&inner_scope, r, &inner);
        }
        self.inline_stack.pop();
        Ok(())
    }
}

/// The slot an object error is about.
fn slot_of(e: &ObjectError) -> Option<Slot> {
    match e {
        ObjectError::Compile { slot, .. }
        | ObjectError::MissingOutput { slot, .. }
        | ObjectError::BadDomain { slot }
        | ObjectError::BadTransform { slot }
        | ObjectError::BadTiming { slot }
        | ObjectError::BadParameters { slot }
        | ObjectError::BadColorMap { slot, .. } => Some(*slot),
        ObjectError::BadGrids { .. } => Some(Slot::Grids),
        _ => None,
    }
}

enum Url<'u> {
    Remote,
    Other,
    Relative(&'u str),
}

fn classify(url: &str) -> Url<'_> {
    let lower = url.to_ascii_lowercase();
    if ["http://", "https://", "ftp://"]
        .iter()
        .any(|s| lower.starts_with(s))
    {
        return Url::Remote;
    }
    let scheme = url
        .find(':')
        .is_some_and(|i| !url[..i].contains(['/', '\\']));
    if url.is_empty() || scheme || url.starts_with(['/', '\\']) {
        return Url::Other;
    }
    // A fragment names a node inside the file; the whole file is read.
    Url::Relative(url.split('#').next().unwrap_or(url))
}

/// `relative` against the directory of `base`, with `.` and `..` resolved where possible.
fn join(base: &str, relative: &str) -> String {
    let mut parts: Vec<&str> = base.split(['/', '\\']).collect();
    parts.pop();
    parts.retain(|p| !p.is_empty() && *p != ".");
    for part in relative.split(['/', '\\']) {
        match part {
            "" | "." => {}
            ".." if parts.last().is_some_and(|p| *p != "..") => {
                parts.pop();
            }
            part => parts.push(part),
        }
    }
    parts.join("/")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joins_relative_paths() {
        assert_eq!(join("", "a.wrl"), "a.wrl");
        assert_eq!(join("scenes/root.wrl", "sub/b.wrl"), "scenes/sub/b.wrl");
        assert_eq!(join("scenes/sub/b.wrl", "../c.wrl"), "scenes/c.wrl");
        assert_eq!(join("a.wrl", "../x/./y.wrl"), "../x/y.wrl");
        assert!(matches!(classify("HTTP://x/y.wrl"), Url::Remote));
        assert!(matches!(classify("file:///etc/passwd"), Url::Other));
        assert!(matches!(classify("/etc/passwd"), Url::Other));
        assert!(matches!(classify("c.wrl#Node"), Url::Relative("c.wrl")));
    }
}
