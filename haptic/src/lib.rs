//! Haptic rendering of function-defined scenes: force computation from scene snapshots, the
//! 1 kHz servo loop, and haptic devices behind one trait (thesis sections 4.3 and 6.5).
//!
//! What it is:
//! - [`force::render`]: a pure function of (scene snapshot, [`force::ProxyState`], device
//!   sample, time, `dt_secs`) that locates the haptic interface point by function sign, keeps
//!   the entry-order container stack, renders surface tension (with pop-through), friction,
//!   density and force fields, and makes the result safe (clamp, rate limit, cross-fade,
//!   passivity observer, zero on stall);
//! - [`servo::Servo`] (init / reset / allocation-free `step`) and [`servo::spawn`], the named,
//!   paced 1 kHz thread, fed through the lock-free [`handoff`];
//! - [`feed::Feed`]: a live scene to the servo, on a thread of its own: whoever owns a scene
//!   that changes (the app's session) implements [`feed::SceneSource`], and each change
//!   becomes a snapshot that rebuilds only the objects it touched;
//! - [`device::HapticDevice`] with a simulated device, a mouse-driven device, a trace
//!   recorder and replayer, and HID drivers (3D mouse input, HID PID force output);
//! - [`force::coupling`]: a shared tool held by several devices through spring-dampers;
//! - haptic containers: [`container::object::ObjectContainer`] (an object of the shared
//!   object model, `model::object`, with its sculpting edits and painted properties, placed by
//!   a general affine transform; [`container::object::ObjectContainer::from_scene`] turns an
//!   `model::scene::Scene` into a servo snapshot), [`container::function::FunctionContainer`]
//!   (fdsl geometry and properties: tension, friction, zone depth, density, force field) and
//!   [`container::mesh::MeshContainer`] (closed triangle meshes located by multiple haptic
//!   rays over fdsl's BVH), all built off the servo thread and sampled without allocating.
//!
//! What it is not: it does not parse scene files or fold edits itself (it reads objects
//! through `model::object::Sampler`), never sees the op log or the network (the shared tool's
//! packets and remote tools come in as values), draws nothing and reads the clock in one
//! place (the servo's pacing, whose clock the feed's timing shares).
//!
//! Conventions: `f >= 0` is inside; distance to the surface is the metric depth
//! `f / |grad f|`; device positions are metres and forces newtons in the device frame; the
//! [`force::zone::HapticZone`] maps the device workspace into world units.
//!
//! ```
//! use glam::DVec3;
//! use haptic::aabb::Aabb;
//! use haptic::device::{Capabilities, DeviceSample};
//! use haptic::force::{render, ForceParams, ProxyState, Region, Rig, zone::HapticZone};
//! use haptic::shapes::Analytic;
//!
//! let caps = Capabilities::desktop_pen();
//! let world = Aabb::new(DVec3::splat(-1.6), DVec3::splat(1.6));
//! let rig = Rig { caps, zone: HapticZone::fit(caps.workspace_metres, world), params: ForceParams::default() };
//! let mut scene = vec![Analytic::watermelon(1, DVec3::ZERO, 1.0)];
//! let mut state = ProxyState::new();
//! // Press the tip about half a millimetre into the rind (20 world units per device metre).
//! let tip = DVec3::new(-0.005, 1.0 / 20.0 - 0.001, -0.005);
//! let mut out = None;
//! for k in 0..300 {
//!     let sample = DeviceSample::at(tip, k * 1000);
//!     out = Some(render(&mut scene, &mut state, &rig, &sample, k as f64 * 1e-3, 1e-3));
//! }
//! let out = out.unwrap();
//! assert_eq!((out.top_id, out.region), (Some(1), Region::Surface));
//! assert!(out.force_newtons.y > 0.3, "the rind pushes the tip back out");
//! ```
#![warn(missing_docs)]

pub mod aabb;
pub mod container;
pub mod device;
pub mod feed;
pub mod force;
pub mod handoff;
pub mod servo;
pub mod shapes;
pub mod shared;
mod sync;
