//! FVRML: the thesis's function-based extension of VRML97 (section 6.4), read into and written
//! from a [`Scene`].
//!
//! Reading is two steps, each usable alone:
//! 1. [`parse`]: text to a [`Document`], a tree that keeps what was written (node types, `DEF`
//!    names, fields in order with typed values, `USE` references) with positions. It never
//!    fails: problems are [`Issue`]s with a line, a column and a byte span, and the tree holds
//!    everything that could be read. Nodes of types we do not read (`Script`, `NetConnection`,
//!    `PROTO` and `EXTERNPROTO` declarations, anything else) are skipped with a warning.
//! 2. [`load_document`] (or [`load`], which parses first): the tree to a [`Scene`] of objects
//!    and groups. `Inline` files are read through a resolver callback the caller provides, so
//!    this module does no IO.
//!
//! Writing is the reverse: [`save`] turns a scene into a [`Document`] and [`write()`] prints a
//! document as canonical text that [`parse`] reads back equal (numbers bit-identical).
//! `load(save(scene))` gives back the scene, the objects' edit histories included, except
//! that ids are those the loader assigns (see [`LoadOptions`]).
//!
//! The dialect (node and field names, our extensions, the thesis's spellings) is described in
//! full below, after the examples, and on the items. In short: the thesis's `FShape`,
//! `FGeometry`, `FAppearance`, `FMaterial`, `FTexture3D`, `FPhysics`, `FSurface`,
//! `FTension`, `FFriction`, `FDensity`, `FForce` and `FTransform`; our `FColorMap`,
//! `FDepth` and `FEdit`; VRML97's `Shape`, `Appearance`, `Material`, `Box`, `Sphere`, `Cylinder`,
//! `Cone`, `IndexedFaceSet`, `Coordinate`, `Transform`, `Group` and `Inline`.
//!
//! An `FShape`'s sculpting history is its field `edits`, one `FEdit` per edit in history
//! order, applied after the shape's description through the object model (the checks edits
//! from peers get; a refused or malformed edit is a located error):
//!
//! ```text
//! FEdit {
//!   operation "paint"          # "union", "subtract", "intersect" or "paint"
//!   property "friction"        # painting only: "diffuseColor", "transparency", "shininess",
//!                              # "tension", "friction", "depth" or "density"
//!   value 0.7                  # painting only: one number, or three (r g b) for a colour
//!   tool "cylinder"            # "sphere" (radius), "box" (halfExtents x y z, rounding,
//!   radius 0.1                 # default 0) or "cylinder" (radius, halfHeight)
//!   halfHeight 0.3
//!   path [                     # the stroke, one pose per line: position x y z,
//!     0 0.2 0 0 0 0 1 1,       # rotation quaternion qx qy qz qw, uniform scale
//!     0.5 0.2 0 0 0 0 1 1
//!   ]
//!   blendRadius 0.05           # default 0 (sharp)
//!   mirror "x"                 # default none; "x", "y" or "z": also mirrored in x = 0, ...
//!   active FALSE               # default TRUE; FALSE for an undone edit
//! }
//! ```
//!
//! ```
//! use formats::fvrml::{self, LoadOptions};
//! use glam::DVec3;
//!
//! let text = r#"#VRML V2.0 utf8
//! DEF Ball FShape {
//!   geometry FGeometry { definition "1-x^2-y^2-z^2" bboxSize 2 2 2 }
//!   physics FPhysics { surface FSurface { tension FTension { definition "1" } } }
//! }
//! Inline { url "http://example.com/room.wrl" }
//! "#;
//! let mut no_files = |path: &str| Err(format!("no file {path}"));
//! let loaded = fvrml::load(text, &LoadOptions::default(), &mut no_files).unwrap();
//! assert_eq!(loaded.scene.len(), 1);
//! assert!(loaded.warnings[0].message.contains("remote url not fetched"));
//! assert_eq!(loaded.warnings[0].location.line, 6);
//!
//! let (_, ball) = loaded.scene.objects().next().unwrap();
//! assert_eq!(ball.object.data().name, "Ball");
//! assert!(ball.object.sampler().value(DVec3::ZERO, 0.0) > 0.0);
//!
//! // Saving and loading again gives the same scene.
//! let text = fvrml::write(&fvrml::save(&loaded.scene));
//! let again = fvrml::load(&text, &LoadOptions::default(), &mut no_files).unwrap();
//! assert_eq!(again.scene, loaded.scene);
//! ```
#![doc = include_str!("dialect.md")]

mod document;
mod edit;
mod fitted;
mod grid;
mod lend;
mod lexer;
mod load;
mod parser;
mod placement;
mod read;
mod save;
mod schema;
mod shape;
mod writer;

use std::fmt;

pub use document::{Document, Field, InvalidDocument, Node, NodeRef, Pos, Value, is_identifier};
pub use load::{LoadError, LoadOptions, Loaded, load, load_document};
pub use save::save;
pub use schema::KNOWN_NODES;
pub use writer::{format_number, write};

use fdsl::Severity;
use fdsl::syntax::Span;

#[cfg(doc)]
use model::scene::Scene;

/// Largest FVRML text read, in bytes (each file, `Inline`s included).
pub const MAX_FILE_BYTES: usize = 16 << 20;
/// Most bytes read over one load, the root file and every `Inline` together.
pub const MAX_TOTAL_BYTES: usize = 64 << 20;
/// Deepest nesting of nodes and lists in one file.
pub const MAX_NESTING_DEPTH: usize = 72;
/// Most nodes in one file.
pub const MAX_NODES: usize = 200_000;
/// Most values in one list (or one run of numbers).
pub const MAX_LIST_ITEMS: usize = 4 << 20;
/// Deepest chain of `Inline` files.
pub const MAX_INLINE_DEPTH: usize = 8;
/// Most `Inline` files read over one load.
pub const MAX_INLINE_FILES: usize = 256;
/// Most nodes the loader visits over one load (bounds `USE` copies of `USE` copies).
pub const MAX_LOAD_STEPS: usize = 1 << 20;
/// Most edits the loaded objects hold together, `USE` copies included (a shape with many
/// edits can be copied many times for a few bytes each).
pub const MAX_LOAD_EDITS: usize = 1 << 22;
/// Most tool stamps the edits of one load compile to (a short `FEdit` can sweep a small tool
/// far, expanding to up to `MAX_STROKE_STAMPS` stamps).
pub const MAX_LOAD_STAMPS: usize = 1 << 22;
/// Most cells times tape instructions one load spends fitting domains to implicit solids
/// written without `bboxSize` (about a second of interval evaluation in a release build);
/// later solids keep no domain, with a warning.
pub const MAX_LOAD_FIT_WORK: u64 = 1 << 28;
/// Most issues kept for one load; later ones are counted in a last issue.
pub const MAX_ISSUES: usize = 256;

/// Where something was written.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Location {
    /// The `Inline` path of the file, as given to the resolver; `None` for the text passed in.
    pub file: Option<String>,
    /// Line, from 1 (0 when unknown: a document built in code).
    pub line: u32,
    /// Column in characters, from 1 (0 when unknown).
    pub column: u32,
    /// Byte range in that file's text.
    pub span: Span,
}

impl Location {
    fn at(pos: Pos, file: Option<&str>) -> Location {
        Location {
            file: file.map(str::to_string),
            line: pos.line,
            column: pos.column,
            span: pos.span,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let file = self.file.as_deref().unwrap_or("<input>");
        write!(f, "{file}:{}:{}", self.line, self.column)
    }
}

/// A problem found while reading FVRML: an error (the text cannot be used as written) or a
/// warning (something was skipped or read leniently).
#[derive(Clone, Debug, PartialEq)]
pub struct Issue {
    /// Error or warning.
    pub severity: Severity,
    /// Where.
    pub location: Location,
    /// What, in plain words (a formula's rendered diagnostic spans several lines).
    pub message: String,
}

impl Issue {
    /// Whether this is an error.
    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }
}

impl fmt::Display for Issue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let severity = match self.severity {
            Severity::Error => "error",
            Severity::Warning => "warning",
        };
        write!(f, "{}: {severity}: {}", self.location, self.message)
    }
}

/// Issues of one load, bounded by [`MAX_ISSUES`].
#[derive(Debug, Default)]
struct Issues {
    list: Vec<Issue>,
    n_dropped: usize,
    n_errors: usize,
}

impl Issues {
    fn push(&mut self, severity: Severity, pos: Pos, file: Option<&str>, message: String) {
        if severity == Severity::Error {
            self.n_errors += 1;
        }
        if self.list.len() >= MAX_ISSUES {
            self.n_dropped += 1;
            return;
        }
        self.list.push(Issue {
            severity,
            location: Location::at(pos, file),
            message,
        });
    }

    fn error(&mut self, pos: Pos, file: Option<&str>, message: impl Into<String>) {
        self.push(Severity::Error, pos, file, message.into());
    }

    fn warning(&mut self, pos: Pos, file: Option<&str>, message: impl Into<String>) {
        self.push(Severity::Warning, pos, file, message.into());
    }

    fn has_errors(&self) -> bool {
        self.n_errors > 0
    }

    /// The issues in file order, with a last one counting those dropped.
    fn finish(mut self) -> Vec<Issue> {
        self.list.sort_by(|a, b| {
            (a.location.file.as_deref(), a.location.span.start)
                .cmp(&(b.location.file.as_deref(), b.location.span.start))
        });
        if self.n_dropped > 0 {
            let severity = if self.n_errors > self.list.iter().filter(|i| i.is_error()).count() {
                Severity::Error
            } else {
                Severity::Warning
            };
            self.list.push(Issue {
                severity,
                location: Location::default(),
                message: format!("{} more issues not shown", self.n_dropped),
            });
        }
        self.list
    }
}

/// The result of [`parse`]: the tree that could be read and every issue found.
#[derive(Clone, Debug)]
pub struct Parsed {
    /// The document (without the nodes that were skipped).
    pub document: Document,
    /// Errors and warnings in text order.
    pub issues: Vec<Issue>,
}

impl Parsed {
    /// Whether any issue is an error.
    pub fn has_errors(&self) -> bool {
        self.issues.iter().any(Issue::is_error)
    }
}

/// Reads FVRML text into a document tree. Never fails and never panics; see [`Parsed`].
pub fn parse(text: &str) -> Parsed {
    let mut issues = Issues::default();
    let document = parser::parse(text, None, &mut issues);
    Parsed {
        document,
        issues: issues.finish(),
    }
}
