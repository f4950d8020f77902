//! Fuzzes the whole front end and the evaluators: any bytes, read as text, must compile or be
//! rejected with diagnostics, never panic, hang or allocate without bound; a compiled function
//! must evaluate at a point, over a box and with a simplified tape without panicking. Each
//! input runs on a thread with a 256 KiB stack, the budget of the engine's thread, so that a
//! recursion as deep as the input is a crash the fuzzer finds.
#![no_main]

use fdsl::Function;
use fdsl::eval::{BulkEval, GradEval, Interval, IntervalBulkEval, IntervalEval, PointEval};
use fdsl::tape::Fidelity;
use libfuzzer_sys::fuzz_target;
use testkit::stack::on_small_stack;

fuzz_target!(|data: &[u8]| on_small_stack(|| compile(data)));

fn compile(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let compiled = Function::compile(&text);
    for d in &compiled.diagnostics {
        let _ = d.render(&text);
    }
    let Some(f) = compiled.function else {
        assert!(compiled.diagnostics.iter().any(|d| d.is_error()), "rejected without an error");
        return;
    };
    let tape = f.tape();
    let p = [0.25, -0.5, 0.75, 0.1];
    let _ = PointEval::new(&tape).eval(p);
    let _ = GradEval::new(&tape).eval(p);
    let mut out = [0.0f32; 3];
    BulkEval::new(&tape).eval(&[0.1, 0.2, 0.3], &[0.0; 3], &[-0.5; 3], 0.0, &mut out);
    let i = Interval::new(-1.0, 1.0);
    let mut interval = IntervalEval::new(&tape);
    let bounds = interval.eval([i, i, i, Interval::point(0.0)]);
    let mut bulk = [Interval::point(0.0)];
    IntervalBulkEval::new(&tape).eval(&[[i, i, i, Interval::point(0.0)]], &mut bulk);
    assert_eq!(format!("{bounds:?}"), format!("{:?}", bulk[0]), "bulk bounds differ");
    let simpler = tape.simplify(interval.choices(), Fidelity::Sign);
    let _ = PointEval::new(&simpler).eval(p);
}
