//! `model`: the sculpt object model (thesis chapter 4, section 6.4), built on the `fdsl`
//! function language. An [`object::Object`] is geometry, appearance and physics, each a set of
//! formulas in its own domain placed by its own transform, plus the history of sculpting
//! [`object::Edit`]s folded over them; a [`scene::Scene`] holds objects under stable ids in
//! nested groups.
//!
//! What it is:
//! - the plain descriptions files and ops carry ([`object::ObjectData`], [`object::Edit`],
//!   [`scene::Group`]) and their canonical, versioned bytes ([`object::codec`]);
//! - the validated, compiled forms ([`object::Object`], [`object::CompiledEdit`]): every formula
//!   compiled once per process ([`object::compiled`]), the edit history indexed by its bounding
//!   boxes ([`bvh::Bvh`]) so that evaluation cost stays nearly flat as history grows;
//! - evaluation in object coordinates ([`object::Sampler`], [`object::BoxSampler`]) and in
//!   scene coordinates ([`scene::SceneSampler`]): value, gradient, interval over a box, colour,
//!   each physical property and the force field, at a time `t`;
//! - imported triangle meshes as solids ([`mesh::TriMesh`]: inside, signed distance, ray hits);
//! - named limits on everything that grows ([`limits`]), and the benchmarks' reference
//!   sculpting workload ([`models`]).
//!
//! What it is not: it does not parse or evaluate formulas itself (that is `fdsl`), read or
//! write files (FVRML, STL, OBJ, glTF are the `formats` crate), mesh or draw (`render`), or
//! order and merge concurrent edits (`replication` folds ops into a scene through this API).
//! It does no IO, reads no clock and starts no thread; the compile cache is a process-wide,
//! bounded map behind a mutex.
//!
//! Sign convention: `f >= 0` is inside, as in the language; an imported mesh's value is its
//! signed distance, positive inside.
//!
//! ```
//! use glam::DVec3;
//! use model::object::{Domain, Edit, EditOp, Formula, Geometry, Object, ObjectData, Pose, ToolShape};
//! use model::scene::{ObjectId, Scene};
//!
//! // A ball of radius 1 in a box of edge 2.2 around the origin.
//! let ball = ObjectData {
//!     name: "ball".into(),
//!     geometry: Some(Geometry::implicit_in(
//!         Formula::new("1-x^2-y^2-z^2").unwrap(),
//!         Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
//!     )),
//!     ..ObjectData::default()
//! };
//! let mut object = Object::new(ball).unwrap();
//! assert!(object.sampler().value(DVec3::new(0.9, 0.0, 0.0), 0.0) > 0.0);
//!
//! // Carve a small ball out of its side: one edit of its history.
//! let carve = Edit::stamp(
//!     EditOp::Subtract,
//!     ToolShape::Sphere { radius: 0.3 },
//!     Pose::at(DVec3::new(1.0, 0.0, 0.0)),
//! );
//! object.apply(carve).unwrap();
//! assert!(object.sampler().value(DVec3::new(0.9, 0.0, 0.0), 0.0) < 0.0);
//! assert!(object.sampler().value(DVec3::new(-0.9, 0.0, 0.0), 0.0) > 0.0);
//!
//! // A scene answers in its own coordinates, and round-trips through its canonical bytes.
//! let mut scene = Scene::new();
//! scene.insert_object(ObjectId(1), object, None).unwrap();
//! assert_eq!(Scene::decode(&scene.encode()).unwrap(), scene);
//! assert!(scene.sampler().value(ObjectId(1), DVec3::ZERO, 0.0).unwrap() > 0.0);
//! ```
#![warn(missing_docs)]

pub mod bvh;
pub mod limits;
pub mod mesh;
pub mod models;
pub mod object;
pub mod root;
pub mod scene;
