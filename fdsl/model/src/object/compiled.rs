//! Compiled formulas kept per process, keyed by their text and the outputs taken: a formula is
//! compiled once however many times objects holding it are built (a received op is validated,
//! then folded; a scene is reloaded; an object is copied for the mesher or the servo).
//!
//! The cache holds at most [`MAX_CACHED_TAPES`] tapes and [`MAX_CACHED_BYTES`] bytes in all
//! (tapes, the texts and outputs that key them, and the grids they keep alive, estimated from
//! their sizes: a 64 KiB text can compile to a few instructions); past either, the oldest
//! entries go first. Failures are not kept (a formula that fails stops at its budget, see
//! [`fdsl::limits::formula_node_budget`]).

use fdsl::Grids;
use std::cell::Cell;
use std::collections::{BTreeMap, VecDeque};
use std::sync::{Mutex, PoisonError};

use fdsl::tape::Tape;

/// Most tapes kept.
pub const MAX_CACHED_TAPES: usize = 4096;
/// Most bytes the cache holds (see [`entry_bytes`]).
pub const MAX_CACHED_BYTES: usize = 64 << 20;

/// The formula's text and the outputs its tape takes (empty: the main value).
/// A formula's text, its outputs, and the grids it was compiled with (compared by content).
type Key = (String, Vec<String>, Grids);

struct Cache {
    /// Each tape with the bytes its entry holds.
    tapes: BTreeMap<Key, (Tape, usize)>,
    /// Keys in insertion order, oldest first.
    order: VecDeque<Key>,
    n_bytes: usize,
}

static CACHE: Mutex<Cache> = Mutex::new(Cache {
    tapes: BTreeMap::new(),
    order: VecDeque::new(),
    n_bytes: 0,
});

/// The bytes an entry holds: its tape, its key twice (in the map and in the order), and the
/// grids it keeps alive (counted for each entry, though entries may share them).
fn entry_bytes(key: &Key, tape: &Tape) -> usize {
    let (text, outputs, grids) = key;
    let strings: usize = outputs
        .iter()
        .map(|o| size_of::<String>() + o.capacity())
        .sum();
    let key_bytes = size_of::<Key>() + text.capacity() + strings;
    let samples: usize = grids
        .iter()
        .map(|g| size_of::<fdsl::grid::Grid>() + g.name().len() + g.data().samples.capacity())
        .sum();
    let grid_bytes = size_of_val(&**grids) + samples;
    // A map entry and a queue slot besides the key's own bytes.
    let slots = size_of::<Key>() + size_of::<(Tape, usize)>();
    2 * key_bytes + slots + grid_bytes + tape.heap_bytes()
}

thread_local! {
    /// Edits compiled on this thread (every [`crate::object::CompiledEdit::new`]).
    static N_EDITS_COMPILED: Cell<u64> = const { Cell::new(0) };
}

/// How many sculpting edits this thread has compiled (every
/// [`crate::object::CompiledEdit::new`], successful or not): what a test reads to show that a
/// received edit is compiled once from its bytes to the scene.
pub fn n_edits_compiled_on_this_thread() -> u64 {
    N_EDITS_COMPILED.with(Cell::get)
}

/// Counts one edit compilation on this thread (called by `CompiledEdit::new`).
pub(crate) fn count_edit_compilation() {
    N_EDITS_COMPILED.with(|n| n.set(n.get() + 1));
}

/// The tape of `outputs` of the formula `text`, from the cache or from `compile` (then kept).
pub(crate) fn tape<E>(
    text: &str,
    outputs: &[&str],
    grids: &Grids,
    compile: impl FnOnce() -> Result<Tape, E>,
) -> Result<Tape, E> {
    let key: Key = (
        text.to_owned(),
        outputs.iter().map(|&o| o.to_owned()).collect(),
        grids.clone(),
    );
    if let Some((tape, _)) = lock().tapes.get(&key) {
        return Ok(tape.clone());
    }
    // Compiled outside the lock: another thread may compile the same formula meanwhile, and
    // both results are the same.
    let tape = compile()?;
    let n_bytes = entry_bytes(&key, &tape);
    let mut cache = lock();
    if n_bytes <= MAX_CACHED_BYTES && !cache.tapes.contains_key(&key) {
        while cache.tapes.len() >= MAX_CACHED_TAPES || cache.n_bytes + n_bytes > MAX_CACHED_BYTES {
            let Some(oldest) = cache.order.pop_front() else {
                break;
            };
            if let Some((_, old_bytes)) = cache.tapes.remove(&oldest) {
                cache.n_bytes -= old_bytes;
            }
        }
        cache.n_bytes += n_bytes;
        cache.order.push_back(key.clone());
        cache.tapes.insert(key, (tape.clone(), n_bytes));
    }
    Ok(tape)
}

fn lock() -> std::sync::MutexGuard<'static, Cache> {
    CACHE.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Drops every cached tape (what a process that built formulas it will not see again, or a
/// benchmark that must start cold, calls).
pub fn clear() {
    let mut cache = lock();
    cache.tapes.clear();
    cache.order.clear();
    cache.n_bytes = 0;
}

/// Tapes and bytes held now.
pub fn cached() -> (usize, usize) {
    let cache = lock();
    (cache.tapes.len(), cache.n_bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::object::{Formula, Geometry, Object, ObjectData};
    use fdsl::n_compiled_on_this_thread;

    fn object(text: &str) -> Object {
        Object::new(ObjectData {
            geometry: Some(Geometry::implicit(Formula::new(text).unwrap())),
            ..ObjectData::default()
        })
        .unwrap()
    }

    #[test]
    fn a_formula_is_compiled_once_however_many_objects_hold_it() {
        let text = "0.7071 - sqrt(x^2 + y^2 + z^2) /* compiled once */";
        let before = n_compiled_on_this_thread();
        let a = object(text);
        assert_eq!(n_compiled_on_this_thread(), before + 1);
        let b = object(text);
        let c = a.clone();
        assert_eq!(
            n_compiled_on_this_thread(),
            before + 1,
            "the second object compiled again"
        );
        // The cached tape computes what a fresh compile does.
        let p = glam::DVec3::new(0.1, 0.2, 0.3);
        assert_eq!(a.sampler().value(p, 0.0), b.sampler().value(p, 0.0));
        assert_eq!(c.sampler().value(p, 0.0), b.sampler().value(p, 0.0));
        // Another text is another compile.
        object("0.7072 - sqrt(x^2 + y^2 + z^2)");
        assert_eq!(n_compiled_on_this_thread(), before + 2);
    }

    #[test]
    fn objects_hand_out_their_compiled_tapes_without_compiling_again() {
        use crate::object::{
            ColorDef, ColorMap, ColorSlot, CompiledColor, ForceField, ParametricKind, Physics,
            Property, Shape, Slot, Timing, Transform,
        };
        use fdsl::eval::PointEval;
        let f = |text: &str| Formula::new(text).unwrap();
        let data = ObjectData {
            geometry: Some(Geometry {
                shape: Shape::Parametric {
                    formula: f("x = u; y = v*t; z = 0; /* tapes */"),
                    kind: ParametricKind::Surface,
                    parameters: [[0.0, 1.0]; 3],
                },
                domain: None,
                transform: Transform::IDENTITY,
            }),
            appearance: crate::object::Appearance {
                diffuse: Some(ColorDef::Rgb(f("r = x; g = 0.5; b = y; /* tapes */"))),
                ambient: Some(ColorDef::Map {
                    formula: f("z + 1 /* tapes */"),
                    map: ColorMap {
                        keys: vec![(0.0, [0.0; 3])],
                    },
                }),
                specular: Some(ColorDef::Constant([1.0; 3])),
                shininess: Some(f("0.25 /* tapes */")),
                ..Default::default()
            }
            .into(),
            physics: Physics {
                tension: Some(Property {
                    formula: f("0.5 /* tapes, disabled */"),
                    enabled: false,
                }),
                density: Some(Property::new(f("x*y /* tapes */"))),
                force: Some(ForceField {
                    formula: f("x = u; y = v; z = w + t; /* tapes */"),
                    parameters: [[0.0, 1.0]; 3],
                    timing: Timing::default(),
                    enabled: true,
                }),
                ..Physics::default()
            }
            .into(),
            ..ObjectData::default()
        };
        let object = Object::new(data).unwrap();
        let before = n_compiled_on_this_thread();
        let n_outputs = |slot| object.tape(slot).map(|t| t.outputs().len());
        assert_eq!(n_outputs(Slot::Geometry), Some(3), "parametric x y z");
        assert_eq!(n_outputs(Slot::Diffuse), Some(3), "r g b");
        assert_eq!(n_outputs(Slot::Ambient), Some(1), "the map's scalar");
        assert_eq!(n_outputs(Slot::Specular), None, "a constant colour");
        assert_eq!(n_outputs(Slot::Shininess), Some(1));
        assert_eq!(n_outputs(Slot::Transparency), None, "not set");
        assert_eq!(n_outputs(Slot::Tension), None, "disabled");
        assert_eq!(n_outputs(Slot::Density), Some(1));
        assert_eq!(n_outputs(Slot::Force), Some(3));
        assert_eq!(n_outputs(Slot::Motion), None);
        assert!(matches!(
            object.color(ColorSlot::Ambient),
            Some(CompiledColor::Map(_, map)) if map.keys.len() == 1
        ));
        assert!(matches!(
            object.color(ColorSlot::Specular),
            Some(CompiledColor::Constant([1.0, 1.0, 1.0]))
        ));
        // The tapes compute what the texts say.
        let mut out = [0.0; 3];
        PointEval::new(object.tape(Slot::Geometry).unwrap())
            .eval_all([0.5, 2.0, 0.0, 3.0], &mut out);
        assert_eq!(out, [0.5, 6.0, 0.0]);
        let density =
            PointEval::new(object.tape(Slot::Density).unwrap()).eval([2.0, 3.0, 0.0, 0.0]);
        assert_eq!(density, 6.0);
        assert_eq!(
            n_compiled_on_this_thread(),
            before,
            "handing out tapes compiled"
        );
    }

    #[test]
    fn the_cache_stays_within_its_limits() {
        for i in 0..MAX_CACHED_TAPES + 50 {
            object(&format!("{i}.5 - x^2 - y^2 - z^2"));
        }
        let (n_tapes, n_bytes) = cached();
        assert!(n_tapes <= MAX_CACHED_TAPES, "{n_tapes}");
        assert!(n_bytes <= MAX_CACHED_BYTES);
        // The newest stay, the oldest went.
        let before = n_compiled_on_this_thread();
        object(&format!("{}.5 - x^2 - y^2 - z^2", MAX_CACHED_TAPES + 49));
        assert_eq!(n_compiled_on_this_thread(), before);
        object("0.5 - x^2 - y^2 - z^2");
        assert_eq!(n_compiled_on_this_thread(), before + 1);
    }
}
