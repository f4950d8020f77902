//! The language's budget on an object's formula: what every peer of a session compiles may
//! unroll only in proportion to its text, with a located error past that.

use fdsl::Function;
use fdsl::limits::{MAX_FORMULA_NODES_BASE, MAX_FORMULA_NODES_PER_BYTE, formula_node_budget};
use model::object::{Formula, Geometry, Object, ObjectData};

#[test]
fn an_objects_formula_may_unroll_only_in_proportion_to_its_text() {
    let object = |src: &str| {
        Object::new(ObjectData {
            geometry: Some(Geometry::implicit(Formula::new(src).unwrap())),
            ..ObjectData::default()
        })
    };
    // 82 bytes that unroll to 9,002 operations: fine as a function, too costly as an object's
    // formula, which every peer of a session compiles.
    let bomb = "s = x; for (i = 0; i < 1000; i = i + 1) { s = sin(s + i*y) * cos(s - i*z) + s; } s";
    assert_eq!(Function::parse(bomb).unwrap().graph_len(), 9_002);
    assert_eq!(
        formula_node_budget(bomb.len()),
        MAX_FORMULA_NODES_BASE + 16 * 82
    );
    let refused = object(bomb).unwrap_err().to_string();
    let budget = MAX_FORMULA_NODES_BASE + MAX_FORMULA_NODES_PER_BYTE * bomb.len();
    assert!(
        refused.contains(&format!(
            "the expression needs more than {budget} operations"
        )),
        "{refused}"
    );
    assert!(refused.contains("run loops fewer times"), "{refused}");
    assert!(refused.contains("1:"), "located: {refused}");
    // A loop of a sensible size, and every reference model, still make objects.
    object("s = 0; for (i = 1; i < 40; i = i + 1) { s = s + sin(i*x)/i; } 0.5 - s*s - y^2 - z^2")
        .unwrap();
    for (name, src) in fdsl::models::REFERENCE_MODELS {
        assert!(object(src).is_ok(), "{name}");
    }
}
