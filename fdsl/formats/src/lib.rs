//! `formats`: sculpt's files, read into and written from the object model (`model`). FVRML
//! text, the thesis's function-based VRML, holds whole scenes with their formulas and edit
//! histories ([`fvrml`]); STL, Wavefront OBJ and binary glTF hold triangle meshes
//! ([`mesh`]).
//!
//! What it is: bytes in, bytes out. Readers take untrusted bytes, never panic, bound every
//! allocation by a named limit and report errors located in the file (line and column, byte
//! offset or JSON path); writers print canonical bytes that their reader reads back equal.
//!
//! What it is not: it does no IO, reads no clock and starts no thread. Files an FVRML scene
//! inlines are read through a resolver callback the caller provides, so the caller decides
//! which files may be read and how (the app's bounded, non-blocking reading). It neither
//! meshes implicit shapes (that is `render`) nor turns a file into replicated ops (the app).
//!
//! Key items: [`fvrml::load`] and [`fvrml::save`] with [`fvrml::write`]; [`mesh::MeshFormat`],
//! the mesh formats by file name extension, with each format's `read` and `write`.
//!
//! ```
//! use formats::{fvrml, mesh::MeshFormat};
//! use glam::DVec3;
//!
//! // A scene with one ball defined by a formula, and no files to inline.
//! let text = r#"#VRML V2.0 utf8
//! DEF Ball FShape { geometry FGeometry { definition "1-x^2-y^2-z^2" bboxSize 2.2 2.2 2.2 } }
//! "#;
//! let mut no_files = |path: &str| Err(format!("no file {path}"));
//! let loaded = fvrml::load(text, &fvrml::LoadOptions::default(), &mut no_files).unwrap();
//! let (_, ball) = loaded.scene.objects().next().unwrap();
//! assert!(ball.object.sampler().value(DVec3::ZERO, 0.0) > 0.0);
//!
//! // Written as canonical text and read back: the same scene.
//! let again = fvrml::write(&fvrml::save(&loaded.scene));
//! let back = fvrml::load(&again, &fvrml::LoadOptions::default(), &mut no_files).unwrap();
//! assert_eq!(back.scene, loaded.scene);
//!
//! // A mesh through the format its file name's extension names.
//! let cube = model::mesh::shapes::cube(DVec3::splat(-1.0), DVec3::splat(1.0));
//! let glb = MeshFormat::from_extension("GLB").unwrap();
//! let mut bytes = Vec::new();
//! glb.write(&cube, &mut bytes);
//! assert_eq!(glb.read(&bytes).unwrap(), cube);
//! ```
#![warn(missing_docs)]

pub mod export;
pub mod fvrml;
pub mod import;
pub mod mesh;
pub mod registry;
