//! The node types FVRML reads. The parser keeps nodes of these types and skips any other
//! (with a warning); the loader warns about each field it does not read.

/// The node types the parser keeps; any other type is skipped with a warning.
pub const KNOWN_NODES: &[&str] = &[
    "FShape",
    "FGeometry",
    "FAppearance",
    "FMaterial",
    "FColorMap",
    "FTexture3D",
    "FPhysics",
    "FSurface",
    "FTension",
    "FFriction",
    "FDepth",
    "FDensity",
    "FForce",
    "FTransform",
    "FEdit",
    "FGrid",
    "Shape",
    "Appearance",
    "Material",
    "Box",
    "Sphere",
    "Cylinder",
    "Cone",
    "IndexedFaceSet",
    "Coordinate",
    "Transform",
    "Group",
    "Inline",
];

/// Whether the parser keeps nodes of this type.
pub(super) fn is_known(type_name: &str) -> bool {
    KNOWN_NODES.contains(&type_name)
}
