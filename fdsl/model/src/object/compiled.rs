//! Compiled formulas kept per process, keyed by their text and the outputs taken: a formula is
//! compiled once however many times objects holding it are built (a received op is validated,
//! then folded; a scene is reloaded; an object is copied for the mesher or the servo), and
//! however often a caller checks it before building one ([`crate::object::Formula::tape`]).
//!
//! The cache holds at most [`MAX_CACHED_TAPES`] tapes and [`MAX_CACHED_BYTES`] bytes in all
//! (tapes, the texts and outputs that key them, and the grids they keep alive, estimated from
//! their sizes: a 64 KiB text can compile to a few instructions); past either, the oldest
//! entries go first. A formula that compiles but lacks the outputs asked for is kept as that
//! answer, so asking again (a colour's `r`, `g`, `b`, then its main value) compiles nothing.
//! Failures to compile are not kept (a formula that fails stops at its budget, see
//! [`fdsl::limits::formula_node_budget`]).

use fdsl::{Function, Grids, MissingOutput};
use std::cell::Cell;
use std::collections::{BTreeMap, VecDeque};
use std::sync::{Mutex, PoisonError};

use fdsl::tape::Tape;

/// Most tapes kept.
pub const MAX_CACHED_TAPES: usize = 4096;
/// Most bytes the cache holds (see [`entry_bytes`]).
pub const MAX_CACHED_BYTES: usize = 64 << 20;

/// A formula's text, its outputs (empty: the main value), and the grids it was compiled
/// with (compared by content).
type Key = (String, Vec<String>, Grids);

/// What a formula that compiled gives for a key: the tape, or the outputs it lacks.
type Answer = Result<Tape, MissingOutput>;

struct Cache {
    /// Each answer with the bytes its entry holds.
    tapes: BTreeMap<Key, (Answer, usize)>,
    /// Keys in insertion order, oldest first.
    order: VecDeque<Key>,
    n_bytes: usize,
}

static CACHE: Mutex<Cache> = Mutex::new(Cache {
    tapes: BTreeMap::new(),
    order: VecDeque::new(),
    n_bytes: 0,
});

/// The bytes an entry holds: its answer, its key twice (in the map and in the order), and
/// the grids it keeps alive (counted for each entry, though entries may share them).
fn entry_bytes(key: &Key, answer: &Answer) -> usize {
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
    let slots = size_of::<Key>() + size_of::<(Answer, usize)>();
    let answer_bytes = match answer {
        Ok(tape) => tape.heap_bytes(),
        Err(missing) => missing.name.capacity() + missing.available.capacity(),
    };
    2 * key_bytes + slots + grid_bytes + answer_bytes
}

thread_local! {
    /// Edits compiled on this thread (every [`crate::object::CompiledEdit::new`]).
    static N_EDITS_COMPILED: Cell<u64> = const { Cell::new(0) };
    /// Objects built on this thread (every [`crate::object::Object::new`] and
    /// [`crate::object::Object::set`]).
    static N_OBJECTS_BUILT: Cell<u64> = const { Cell::new(0) };
}

/// How many objects this thread has built from their descriptions (every
/// [`crate::object::Object::new`] and [`crate::object::Object::set`], successful or not: each
/// takes every formula of the description from the cache or compiles it, and checks every
/// number): what a test reads to show how often an op's object is built between the line a
/// user typed and the scene.
pub fn n_objects_built_on_this_thread() -> u64 {
    N_OBJECTS_BUILT.with(Cell::get)
}

/// Counts one object built on this thread (called where an object's description is compiled).
pub(crate) fn count_object_build() {
    N_OBJECTS_BUILT.with(|n| n.set(n.get() + 1));
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

/// The first of `choices` (sets of outputs; empty: the main value) that the formula `text`
/// defines, with its tape, from the cache or from `compile` (called at most once, then every
/// answer it gave is kept); `Ok(Err)` when it defines none of them (the last one's missing
/// output).
pub(crate) fn first_tape<E>(
    text: &str,
    choices: &[&[&str]],
    grids: &Grids,
    compile: impl FnOnce() -> Result<Function, E>,
) -> Result<Result<(usize, Tape), MissingOutput>, E> {
    let key = |outputs: &[&str]| -> Key {
        (
            text.to_owned(),
            outputs.iter().map(|&o| o.to_owned()).collect(),
            grids.clone(),
        )
    };
    let mut missing = MissingOutput {
        name: String::new(),
        available: String::new(),
    };
    for (choice_idx, outputs) in choices.iter().enumerate() {
        let cached = lock().tapes.get(&key(outputs)).map(|(a, _)| a.clone());
        match cached {
            Some(Ok(tape)) => return Ok(Ok((choice_idx, tape))),
            Some(Err(m)) => missing = m,
            None => {
                // Compiled outside the lock: another thread may compile the same formula
                // meanwhile, and both results are the same.
                let function = compile()?;
                for (idx, outputs) in choices.iter().enumerate().skip(choice_idx) {
                    let answer = if outputs.is_empty() {
                        Ok(function.tape())
                    } else {
                        function.tape_for(outputs)
                    };
                    keep(key(outputs), &answer);
                    match answer {
                        Ok(tape) => return Ok(Ok((idx, tape))),
                        Err(m) => missing = m,
                    }
                }
                return Ok(Err(missing));
            }
        }
    }
    Ok(Err(missing))
}

/// Keeps `answer` under `key`, making room by dropping the oldest entries.
fn keep(key: Key, answer: &Answer) {
    let n_bytes = entry_bytes(&key, answer);
    let mut cache = lock();
    if n_bytes > MAX_CACHED_BYTES || cache.tapes.contains_key(&key) {
        return;
    }
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
    cache.tapes.insert(key, (answer.clone(), n_bytes));
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

    /// A caller that checks a formula before building its object (the app's command line)
    /// compiles it once, whichever outputs it asks for, and the object built next compiles
    /// nothing: a formula that lacks outputs is kept as such.
    #[test]
    fn a_formula_checked_for_several_outputs_then_built_compiles_once() {
        use crate::object::{ColorDef, ColorMap, ObjectError, Slot};
        let formula = Formula::new("0.5 + 0.2*y /* checked, then built */").unwrap();
        let before = n_compiled_on_this_thread();
        let rgb_or_scalar: [&[&str]; 2] = [&["r", "g", "b"], &[]];
        let (choice_idx, _) = formula
            .first_tape(Slot::Diffuse, &rgb_or_scalar, &Grids::default())
            .unwrap();
        assert_eq!(choice_idx, 1, "a scalar is its main value");
        assert!(matches!(
            formula.tape(Slot::Diffuse, &["r", "g", "b"], &Grids::default()),
            Err(ObjectError::MissingOutput { .. })
        ));
        Object::new(ObjectData {
            geometry: Some(Geometry::implicit(
                Formula::new("1 - x^2 /* checked, then built: geometry */").unwrap(),
            )),
            appearance: crate::object::Appearance {
                diffuse: Some(ColorDef::Map {
                    formula,
                    map: ColorMap {
                        keys: vec![(0.0, [0.0; 3])],
                    },
                }),
                ..Default::default()
            }
            .into(),
            ..ObjectData::default()
        })
        .unwrap();
        // The geometry's formula is the one other compile.
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
