//! Replays every hostile input under `tests/data/fuzz-crashers/fdsl/`: each must be rejected
//! with an error diagnostic, never a panic or a hang, on a thread with a 256 KiB stack (so
//! that a recursion as deep as the input is a crash here, as it is on the engine's thread).

use std::path::Path;

use testkit::stack::on_small_stack;

#[test]
fn every_checked_in_crasher_is_rejected() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/fuzz-crashers/fdsl");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("the crasher folder exists") {
        let path = entry.expect("readable entry").path();
        if path.extension().and_then(|e| e.to_str()) != Some("fdsl") {
            continue;
        }
        let bytes = std::fs::read(&path).expect("readable file");
        let text = String::from_utf8_lossy(&bytes);
        let compiled = on_small_stack(|| fdsl::Function::compile(&text));
        assert!(compiled.function.is_none(), "{} compiled", path.display());
        assert!(
            compiled.diagnostics.iter().any(|d| d.is_error()),
            "{} has no error",
            path.display()
        );
        for d in &compiled.diagnostics {
            assert!(!d.render(&text).is_empty());
        }
        n += 1;
    }
    assert!(n >= 10, "found only {n} inputs in {}", dir.display());
}

#[test]
fn nesting_at_the_limit_compiles_on_a_small_stack() {
    let depth = fdsl::limits::MAX_NESTING_DEPTH;
    let text = format!("{}x{}", "(".repeat(depth), ")".repeat(depth));
    assert!(on_small_stack(|| fdsl::Function::parse(&text)).is_ok());
    let calls = format!("{}x{}", "sin(".repeat(depth), ")".repeat(depth));
    assert!(on_small_stack(|| fdsl::Function::parse(&calls)).is_ok());
}
