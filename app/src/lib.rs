//! The library under the `sculpt` program: the session engine and what every face of the
//! program shares (the window, the headless peer, the command line, tests).
//!
//! - [`engine`]: [`engine::Engine`], the one driver of a session: identity, the store
//!   directory (locked), the QUIC node with its discovery, and the fold of the log into a
//!   published [`engine::View`] that names what each change touched. All IO runs on the
//!   engine's own thread.
//! - [`brush`]: brushes (add, carve, paint a property; shape, size, blend, mirror) and the
//!   strokes a drag draws with them, one op each.
//! - [`command`]: the command/chat language (`shape:`, `colour:`, `new:`, `undo`, ...),
//!   planned into ops against a view.
//! - [`new_object`]: how an object a user makes (`new:`, an imported mesh) starts out.
//! - [`files`]: scene files a user opens, their `Inline` files confined to the scene's
//!   folder.
//! - [`transfer`]: files in and out of a session: FVRML scenes and STL, OBJ and glTF meshes
//!   imported as planned ops, a scene or one object exported as the renderer meshes it.
//! - [`touch`]: the haptic servo on the app's scenes: replayed headless over a CSV path
//!   (`sculpt touch`), and fed the live scene's changed objects as snapshots.
//! - [`demos`]: the thesis's applications as scene files built into the program
//!   (`sculpt demo NAME`).
//! - [`settings`]: the name, colour and brush a user expects to find again.
//! - [`dirs`]: the data directory and where session stores go in it.
//! - [`samples`]: bounded series of timings and their summaries.
//! - [`clock`]: the program's one read of the clock.
//!
//! What it is not: the window (egui) and the argument parsing live in the binary; the
//! replication, object model, rendering and haptic libraries live in their own crates.
//!
//! ```no_run
//! use app::engine::{Engine, EngineConfig, Network, lock};
//!
//! let config = EngineConfig {
//!     store: "/tmp/sculpt-example".into(),
//!     invite: None,
//!     network: Network::default(),
//!     demo: app::demos::find(app::demos::DEFAULT_DEMO).ok(),
//!     memory_fallback: false,
//!     name: None,
//!     session_name: None,
//! };
//! let engine = Engine::start(config, app::clock::now().wall).unwrap();
//! println!("{} objects", lock(engine.view()).scene().len());
//! engine.shutdown();
//! ```
#![warn(missing_docs)]

pub mod brush;
pub mod clock;
pub mod command;
pub mod demos;
pub mod dirs;
pub mod engine;
pub mod files;
pub mod new_object;
pub mod samples;
pub mod settings;
pub mod touch;
pub mod transfer;
pub mod workload;
