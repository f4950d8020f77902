//! Named limits on everything that grows in the object model: colour maps, strokes, edit
//! histories, scenes and their encoded bytes.
//!
//! Objects, edits and scenes come from files and from remote peers, so every dimension is
//! bounded here; exceeding one is an error, never a panic or an unbounded allocation. The
//! limits on reading and compiling a formula are the language's (`fdsl::limits`).

/// Most keys in a colour map.
pub const MAX_COLOR_KEYS: usize = 256;
/// Most poses in one stroke (one hand movement).
pub const MAX_STROKE_POSES: usize = 4096;
/// Most primitive stamps a stroke expands to (densified along its path).
pub const MAX_STROKE_STAMPS: usize = 16_384;
/// Most edits in one object's history.
pub const MAX_EDITS_PER_OBJECT: usize = 1 << 20;
/// Most objects in a scene.
pub const MAX_OBJECTS: usize = 1 << 16;
/// Most groups in a scene, and the deepest nesting of groups.
pub const MAX_GROUPS: usize = 1 << 14;
/// Deepest nesting of groups.
pub const MAX_GROUP_DEPTH: usize = 64;
/// Largest encoded object, edit or scene accepted by the decoders, in bytes.
pub const MAX_ENCODED_BYTES: usize = 64 << 20;
/// Largest tool, in scene units (a tool must have bounded support).
pub const MAX_TOOL_SIZE: f64 = 1e6;
