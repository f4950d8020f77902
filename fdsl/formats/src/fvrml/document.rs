//! The document tree: what an FVRML text says, node by node and field by field, with the
//! position of each part. Positions are not part of a document's identity: two documents
//! that differ only in where things were written are equal. Numbers compare bit for bit.

use fdsl::syntax::Span;

/// Where a part of a document was written: line and column (from 1, in characters) and the
/// byte span. Always equal to any other `Pos`, so that documents compare by content.
#[derive(Clone, Copy, Debug, Default)]
pub struct Pos {
    /// Line, from 1; 0 for a part built in code.
    pub line: u32,
    /// Column in characters, from 1; 0 for a part built in code.
    pub column: u32,
    /// Byte range.
    pub span: Span,
}

impl PartialEq for Pos {
    fn eq(&self, _: &Pos) -> bool {
        true
    }
}

/// A whole text: its top-level statements.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Document {
    /// Top-level nodes and `USE`s, in order.
    pub nodes: Vec<NodeRef>,
}

/// A place where a node can be written.
#[derive(Clone, Debug, PartialEq)]
pub enum NodeRef {
    /// A node written out.
    Node(Box<Node>),
    /// `USE name`: another instance of the node last `DEF`ined with that name.
    Use {
        /// The name.
        name: String,
        /// Where the `USE` was written.
        pos: Pos,
    },
    /// `NULL`.
    Null,
}

/// A node: `[DEF name] Type { fields }`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Node {
    /// The node type, for example `FShape`.
    pub type_name: String,
    /// The `DEF` name, if any.
    pub def: Option<String>,
    /// The fields in the order written (a name may repeat; nodes written directly in a body,
    /// as the thesis's Figure 7.8 does inside `Group`, become a `children` field).
    pub fields: Vec<Field>,
    /// Where the node (its `DEF` or its type) starts.
    pub pos: Pos,
}

impl Node {
    /// A node of `type_name` with these fields.
    pub fn new(type_name: impl Into<String>, fields: Vec<Field>) -> Node {
        Node {
            type_name: type_name.into(),
            def: None,
            fields,
            pos: Pos::default(),
        }
    }

    /// The last field of this name.
    pub fn field(&self, name: &str) -> Option<&Field> {
        self.fields.iter().rev().find(|f| f.name == name)
    }
}

/// One field: `name value`.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// Its name.
    pub name: String,
    /// Its value.
    pub value: Value,
    /// Where the name was written.
    pub pos: Pos,
    /// Where the value starts.
    pub value_pos: Pos,
}

impl Field {
    /// A field with this value.
    pub fn new(name: impl Into<String>, value: Value) -> Field {
        Field {
            name: name.into(),
            value,
            pos: Pos::default(),
            value_pos: Pos::default(),
        }
    }
}

/// A field's value. VRML's types map onto these by their written form: `SFBool` is `Bool`,
/// `SFFloat`, `SFInt32`, `SFVec3f`, `SFColor`, `SFRotation` and other fixed groups of numbers
/// are `Numbers` (a run of one or more numbers), `SFString` is `String`, `SFNode` is `Node`,
/// and MF types are the list variants (`[ ... ]`).
#[derive(Clone, Debug)]
pub enum Value {
    /// `TRUE` or `FALSE`.
    Bool(bool),
    /// One or more numbers written one after another (never empty; all finite).
    Numbers(Vec<f64>),
    /// A string.
    String(String),
    /// A node, a `USE` or `NULL`.
    Node(NodeRef),
    /// `[TRUE FALSE ...]`.
    Bools(Vec<bool>),
    /// `[1 2 3, ...]` (commas are white space, as in VRML).
    NumberList(Vec<f64>),
    /// `["a" "b" ...]`.
    StringList(Vec<String>),
    /// `[Node { } USE X ...]`.
    NodeList(Vec<NodeRef>),
    /// `[]`.
    EmptyList,
}

impl PartialEq for Value {
    /// Numbers compare by their bits, so `0` and `-0` differ and what is written reads back
    /// identical.
    fn eq(&self, other: &Value) -> bool {
        fn same(a: &[f64], b: &[f64]) -> bool {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
        }
        match (self, other) {
            (Value::Bool(a), Value::Bool(b)) => a == b,
            (Value::Numbers(a), Value::Numbers(b)) => same(a, b),
            (Value::String(a), Value::String(b)) => a == b,
            (Value::Node(a), Value::Node(b)) => a == b,
            (Value::Bools(a), Value::Bools(b)) => a == b,
            (Value::NumberList(a), Value::NumberList(b)) => same(a, b),
            (Value::StringList(a), Value::StringList(b)) => a == b,
            (Value::NodeList(a), Value::NodeList(b)) => a == b,
            (Value::EmptyList, Value::EmptyList) => true,
            _ => false,
        }
    }
}

/// Why a document cannot be written so that it reads back equal.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InvalidDocument {
    /// A type, field, `DEF` or `USE` name is not an identifier (or is a keyword).
    #[error("`{0}` is not a valid name")]
    BadName(String),
    /// A node type is not one the parser reads (it would be skipped).
    #[error("`{0}` is not a node type FVRML reads")]
    UnknownNode(String),
    /// A number is not finite.
    #[error("field `{0}` holds a number that is not finite")]
    NotFinite(String),
    /// A run of numbers is empty (write an empty list instead).
    #[error("field `{0}` holds an empty run of numbers")]
    EmptyNumbers(String),
}

/// Words that cannot be names.
pub(super) const KEYWORDS: &[&str] = &[
    "DEF",
    "USE",
    "NULL",
    "TRUE",
    "FALSE",
    "PROTO",
    "EXTERNPROTO",
    "ROUTE",
    "TO",
    "IS",
    "IMPORT",
    "EXPORT",
    "AS",
];

/// Whether `name` can be written as a VRML identifier in our dialect: a letter, `_` or a
/// non-ASCII character, then those or digits, `+` and `-`; not a keyword.
pub fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    let Some(first) = chars.next() else {
        return false;
    };
    super::lexer::is_ident_start(first)
        && chars.all(super::lexer::is_ident_continue)
        && !KEYWORDS.contains(&name)
}

impl Document {
    /// Checks that [`write`](super::write) will print this document so that
    /// [`parse`](super::parse) reads it back equal.
    pub fn validate(&self) -> Result<(), InvalidDocument> {
        let mut stack: Vec<&NodeRef> = self.nodes.iter().collect();
        while let Some(r) = stack.pop() {
            let node = match r {
                NodeRef::Node(node) => node,
                NodeRef::Use { name, .. } => {
                    check_name(name)?;
                    continue;
                }
                NodeRef::Null => continue,
            };
            check_name(&node.type_name)?;
            if !super::schema::is_known(&node.type_name) {
                return Err(InvalidDocument::UnknownNode(node.type_name.clone()));
            }
            if let Some(def) = &node.def {
                check_name(def)?;
            }
            for field in &node.fields {
                check_name(&field.name)?;
                match &field.value {
                    Value::Numbers(v) if v.is_empty() => {
                        return Err(InvalidDocument::EmptyNumbers(field.name.clone()));
                    }
                    Value::Numbers(v) | Value::NumberList(v)
                        if !v.iter().all(|x| x.is_finite()) =>
                    {
                        return Err(InvalidDocument::NotFinite(field.name.clone()));
                    }
                    Value::Node(r) => stack.push(r),
                    Value::NodeList(list) => stack.extend(list),
                    _ => {}
                }
            }
        }
        Ok(())
    }
}

fn check_name(name: &str) -> Result<(), InvalidDocument> {
    if is_identifier(name) {
        Ok(())
    } else {
        Err(InvalidDocument::BadName(name.to_string()))
    }
}
