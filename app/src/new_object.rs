//! How an object a user makes starts out: the box a `new:` solid is fitted into when it has
//! none, where it sits beside the others, and the colour it (and an imported mesh) wears.
//!
//! Below both the command line ([`crate::command`]) and file import ([`crate::transfer`]),
//! which make such objects.

use glam::DVec3;
use model::object::Domain;

/// Edge of the domain box of an object made with `new:` (scene units).
pub const NEW_OBJECT_SIZE: f64 = 2.2;
/// How far apart along x objects made with `new:` are placed (scene units).
pub const NEW_OBJECT_SPACING: f64 = 2.5;
/// The diffuse colour of an object made with `new:`, and of an imported mesh.
pub const NEW_OBJECT_COLOUR: [f32; 3] = [0.55, 0.7, 0.95];

/// The domain of a new object whose shape gives none: a cube of [`NEW_OBJECT_SIZE`] about
/// its origin.
pub fn new_object_domain() -> Domain {
    Domain::new(DVec3::ZERO, DVec3::splat(NEW_OBJECT_SIZE))
}
