//! Reading fields of a document node with types: the [`Reader`] the loader converts nodes
//! with (issues, the file, `USE` resolution) and the [`Fields`] tracker that warns about
//! fields nobody read and fields given twice.

use std::collections::BTreeMap;

use glam::DVec3;

use super::Issues;
use super::document::{Document, Field, Node, NodeRef, Pos, Value};
use super::writer::format_number;
use model::object::{Formula, Slot};

/// The names `DEF`ined in one file, to resolve `USE`s: a name refers to the last node of
/// that name whose definition ended before the `USE` (so a node cannot use itself).
pub(super) struct Scope<'d> {
    /// A number unique to this file within the load (for caches keyed by node address).
    pub(super) serial: usize,
    /// The file's path (`None` for the root text).
    pub(super) file: Option<String>,
    defs: BTreeMap<&'d str, Vec<(u64, &'d Node)>>,
    uses: BTreeMap<usize, u64>,
}

/// The address of a node or reference, a key that is stable while the document is borrowed.
pub(super) fn address<T>(r: &T) -> usize {
    std::ptr::from_ref(r) as usize
}

impl<'d> Scope<'d> {
    /// Numbers every node and `USE` of `doc` in document order.
    pub(super) fn new(doc: &'d Document, serial: usize, file: Option<String>) -> Scope<'d> {
        enum Step<'d> {
            Enter(&'d NodeRef),
            Exit(&'d Node),
        }
        let mut scope = Scope {
            serial,
            file,
            defs: BTreeMap::new(),
            uses: BTreeMap::new(),
        };
        let mut counter = 0u64;
        let mut stack: Vec<Step<'d>> = doc.nodes.iter().rev().map(Step::Enter).collect();
        while let Some(step) = stack.pop() {
            counter += 1;
            match step {
                Step::Enter(r @ NodeRef::Use { .. }) => {
                    scope.uses.insert(address(r), counter);
                }
                Step::Enter(NodeRef::Null) => {}
                Step::Enter(NodeRef::Node(node)) => {
                    stack.push(Step::Exit(node));
                    for field in node.fields.iter().rev() {
                        match &field.value {
                            Value::Node(r) => stack.push(Step::Enter(r)),
                            Value::NodeList(list) => {
                                stack.extend(list.iter().rev().map(Step::Enter))
                            }
                            _ => {}
                        }
                    }
                }
                Step::Exit(node) => {
                    if let Some(def) = &node.def {
                        scope.defs.entry(def).or_default().push((counter, node));
                    }
                }
            }
        }
        scope
    }

    /// The node `r` stands for.
    pub(super) fn resolve(&self, r: &'d NodeRef) -> Result<Option<&'d Node>, String> {
        match r {
            NodeRef::Node(node) => Ok(Some(node)),
            NodeRef::Null => Ok(None),
            NodeRef::Use { name, .. } => {
                let at = self.uses.get(&address(r)).copied().unwrap_or(u64::MAX);
                let defs = self
                    .defs
                    .get(name.as_str())
                    .map(Vec::as_slice)
                    .unwrap_or(&[]);
                let before = defs.partition_point(|(ordinal, _)| *ordinal < at);
                match before.checked_sub(1).and_then(|i| defs.get(i)) {
                    Some((_, node)) => Ok(Some(node)),
                    None => Err(format!(
                        "`USE {name}` names no node defined before it (a node cannot use \
                         itself, and skipped nodes define nothing)"
                    )),
                }
            }
        }
    }
}

/// Which fields of a node were read.
pub(super) struct Fields<'d> {
    pub(super) node: &'d Node,
    used: Vec<bool>,
}

impl<'d> Fields<'d> {
    pub(super) fn new(node: &'d Node) -> Fields<'d> {
        Fields {
            node,
            used: vec![false; node.fields.len()],
        }
    }

    /// The last field named `name` (earlier ones are reported by [`Reader::finish`]).
    pub(super) fn get(&mut self, name: &str) -> Option<&'d Field> {
        let mut found = None;
        for (i, field) in self.node.fields.iter().enumerate() {
            if field.name == name {
                self.used[i] = true;
                found = Some(field);
            }
        }
        found
    }

    /// Every field named `name`, in order (for `children`).
    pub(super) fn all(&mut self, name: &str) -> Vec<&'d Field> {
        let mut out = Vec::new();
        for (i, field) in self.node.fields.iter().enumerate() {
            if field.name == name {
                self.used[i] = true;
                out.push(field);
            }
        }
        out
    }

    pub(super) fn has(&self, name: &str) -> bool {
        self.node.fields.iter().any(|f| f.name == name)
    }
}

/// Converts nodes of one file: reports issues there and resolves its `USE`s.
pub(super) struct Reader<'a, 'd> {
    pub(super) issues: &'a mut Issues,
    pub(super) scope: &'a Scope<'d>,
    /// Where each formula of the object being read was written, to place compile errors.
    pub(super) positions: BTreeMap<Slot, Pos>,
}

impl<'d> Reader<'_, 'd> {
    pub(super) fn error(&mut self, pos: Pos, message: impl Into<String>) {
        let file = self.scope.file.as_deref();
        self.issues.error(pos, file, message);
    }

    pub(super) fn warning(&mut self, pos: Pos, message: impl Into<String>) {
        let file = self.scope.file.as_deref();
        self.issues.warning(pos, file, message);
    }

    /// Warns about fields that were not read and fields given more than once.
    pub(super) fn finish(&mut self, fields: Fields<'d>) {
        let node = fields.node;
        for (i, field) in node.fields.iter().enumerate() {
            if !fields.used[i] {
                self.warning(
                    field.pos,
                    format!(
                        "`{}` has no field `{}` that FVRML reads; ignored",
                        node.type_name, field.name
                    ),
                );
            } else if field.name != "children"
                && node.fields[i + 1..].iter().any(|f| f.name == field.name)
            {
                self.warning(
                    field.pos,
                    format!(
                        "the field `{}` is given again later; the last one counts",
                        field.name
                    ),
                );
            }
        }
    }

    pub(super) fn wrong_type(&mut self, field: &Field, expected: &str) {
        self.error(
            field.value_pos,
            format!("the field `{}` should be {expected}", field.name),
        );
    }

    /// Exactly `n` numbers.
    pub(super) fn fixed(&mut self, field: &'d Field, n: usize) -> Option<&'d [f64]> {
        let v = self.numbers_of(field)?;
        if v.len() == n {
            Some(v)
        } else {
            let what = if n == 1 {
                "one number".to_string()
            } else {
                format!("{n} numbers")
            };
            self.wrong_type(field, &what);
            None
        }
    }

    /// The numbers of a field (a run or a list).
    pub(super) fn numbers_of(&mut self, field: &'d Field) -> Option<&'d [f64]> {
        match &field.value {
            Value::Numbers(v) | Value::NumberList(v) => Some(v),
            Value::EmptyList => Some(&[]),
            _ => {
                self.wrong_type(field, "numbers");
                None
            }
        }
    }

    pub(super) fn number(&mut self, field: &'d Field) -> Option<f64> {
        self.fixed(field, 1).map(|v| v[0])
    }

    pub(super) fn vec3(&mut self, field: &'d Field) -> Option<DVec3> {
        self.fixed(field, 3).map(DVec3::from_slice)
    }

    pub(super) fn boolean(&mut self, field: &'d Field) -> Option<bool> {
        match &field.value {
            Value::Bool(b) => Some(*b),
            _ => {
                self.wrong_type(field, "TRUE or FALSE");
                None
            }
        }
    }

    /// Strings of a field written as one string or a list.
    pub(super) fn strings(&mut self, field: &'d Field) -> Option<Vec<&'d str>> {
        match &field.value {
            Value::String(s) => Some(vec![s.as_str()]),
            Value::StringList(v) => Some(v.iter().map(String::as_str).collect()),
            Value::EmptyList => Some(Vec::new()),
            _ => {
                self.wrong_type(field, "a string or a list of strings");
                None
            }
        }
    }

    /// A formula: a string, or a single number (read as its text). What the formula language
    /// reads leniently (a printed dash for a minus, the thesis's `BEGIN ... END` wrapper) is
    /// a warning at the string, with the formula's own rendered diagnostic; compile errors
    /// are reported where the object is built.
    pub(super) fn formula(&mut self, field: &'d Field) -> Option<Formula> {
        let text = match &field.value {
            Value::String(s) => s.clone(),
            Value::Numbers(v) if v.len() == 1 => format_number(v[0]),
            _ => {
                self.wrong_type(field, "a formula (a string or one number)");
                return None;
            }
        };
        match Formula::new(text) {
            Ok(f) => {
                self.lenient_reads(field, f.as_str());
                Some(f)
            }
            Err(e) => {
                self.error(field.value_pos, e.to_string());
                None
            }
        }
    }

    /// Warns of what the formula's syntax reads leniently (parsing only: compiling happens
    /// once, where the object is built).
    fn lenient_reads(&mut self, field: &'d Field, text: &str) {
        let (_, diagnostics) = fdsl::syntax::parser::parse(text);
        if diagnostics.iter().any(fdsl::Diagnostic::is_error) {
            return;
        }
        for d in diagnostics {
            let rendered = d.render(text);
            let message = format!("`{}`: {}", field.name, rendered.trim_end());
            self.warning(field.value_pos, message);
        }
    }

    /// A formula, remembering where it was written for `slot`'s compile errors.
    pub(super) fn formula_for(&mut self, field: &'d Field, slot: Slot) -> Option<Formula> {
        self.positions.entry(slot).or_insert(field.value_pos);
        self.formula(field)
    }

    /// The nodes of type `type_name` a list field holds, in order (`USE` resolved, `NULL`
    /// skipped, nodes of other types warned about and skipped); none, with an error, when it
    /// holds more than `max` (`what` names them in the message).
    pub(super) fn listed_nodes(
        &mut self,
        field: &'d Field,
        type_name: &str,
        max: usize,
        what: &str,
    ) -> Vec<&'d Node> {
        let items: &'d [NodeRef] = match &field.value {
            Value::NodeList(list) => list,
            Value::Node(r) => std::slice::from_ref(r),
            Value::EmptyList => &[],
            _ => {
                self.wrong_type(field, &format!("a list of `{type_name}` nodes"));
                return Vec::new();
            }
        };
        if items.len() > max {
            let message = format!(
                "`{}` holds {} {what}, more than the limit of {max} an object may hold",
                field.name,
                items.len()
            );
            self.error(field.value_pos, message);
            return Vec::new();
        }
        let mut nodes = Vec::with_capacity(items.len());
        for r in items {
            let Some(node) = self.resolve(r, field.value_pos) else {
                continue;
            };
            if node.type_name == type_name {
                nodes.push(node);
            } else {
                let message = format!(
                    "`{}` cannot be in `{}` (expected {type_name}); ignored",
                    node.type_name, field.name
                );
                self.warning(node.pos, message);
            }
        }
        nodes
    }

    /// The node of an `SFNode` field (resolving `USE`); `None` for `NULL` or on error.
    pub(super) fn node(&mut self, field: &'d Field) -> Option<&'d Node> {
        match &field.value {
            Value::Node(r) => self.resolve(r, field.value_pos),
            _ => {
                self.wrong_type(field, "a node");
                None
            }
        }
    }

    /// The node `r` stands for, reporting an undefined `USE` at `pos`.
    pub(super) fn resolve(&mut self, r: &'d NodeRef, pos: Pos) -> Option<&'d Node> {
        match self.scope.resolve(r) {
            Ok(node) => node,
            Err(message) => {
                let at = match r {
                    NodeRef::Use { pos, .. } => *pos,
                    _ => pos,
                };
                self.error(at, message);
                None
            }
        }
    }

    /// A node in field `field` that must be one of `types`.
    pub(super) fn node_of(&mut self, field: &'d Field, types: &[&str]) -> Option<&'d Node> {
        let node = self.node(field)?;
        if types.contains(&node.type_name.as_str()) {
            Some(node)
        } else {
            self.warning(
                node.pos,
                format!(
                    "`{}` cannot be the `{}` here (expected {}); ignored",
                    node.type_name,
                    field.name,
                    types.join(" or ")
                ),
            );
            None
        }
    }
}
