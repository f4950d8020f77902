//! Every grammar form at the largest size the limits accept, and one step past it, through
//! the whole pipeline (parse, lower, fold, tape, every evaluator, the object model, drop) on a
//! thread with a 256 KiB stack: a clean `Ok`, or an error located in the text. Recursion
//! that grows with the input would overflow that stack and abort the test.

use fdsl::Function;
use fdsl::eval::{
    BulkEval, Grad, GradBulkEval, GradEval, Interval, IntervalBulkEval, IntervalEval, PointEval,
};
use fdsl::limits::{MAX_NESTING_DEPTH, MAX_SOURCE_BYTES, MAX_STATEMENT_DEPTH};
use fdsl::syntax::ast::{Expr, ExprKind, Item, Program, Stmt, UnaryOp};
use fdsl::syntax::{Span, parser};
use fdsl::tape::{Fidelity, Tape};
use model::object::Object;
use testkit::stack::on_small_stack;

/// Compiles `source` and runs every evaluator over every output, on a small stack. Returns
/// the first error's message, or `None` when it compiled.
fn pipeline(source: &str) -> Option<String> {
    on_small_stack(|| {
        let compiled = Function::compile(source);
        let Some(function) = compiled.function else {
            let error = compiled
                .diagnostics
                .iter()
                .find(|d| d.is_error())
                .expect("a rejected text has an error");
            let span = error.span;
            assert!(
                span.start <= span.end && span.end as usize <= source.len(),
                "{error:?} lies outside the text"
            );
            assert!(!error.render(source).is_empty());
            return Some(error.message.clone());
        };
        let names: Vec<&str> = function.output_names().collect();
        for name in names {
            evaluate(&function.tape_for(&[name]).expect("a named output"));
        }
        // The object model compiles the formula again, with its own budget and caches.
        if function.has_output("value") {
            let mut object = Object::implicit(source).expect("a formula that compiled");
            object.prepare();
        }
        None
    })
}

fn evaluate(tape: &Tape) {
    let p = [0.25, -0.5, 0.75, 0.1];
    PointEval::new(tape).eval(p);
    GradEval::new(tape).eval(p);
    let mut out = [0.0f32; 3];
    let (x, y, z) = ([0.1, 0.2, 0.3], [0.0; 3], [-0.5; 3]);
    BulkEval::new(tape).eval(&x, &y, &z, 0.0, &mut out);
    let mut grads = [Grad::<f32>::default(); 3];
    GradBulkEval::new(tape).eval(&x, &y, &z, 0.0, &mut grads);
    let i = Interval::new(-1.0, 1.0);
    let region = [i, i, i, Interval::point(0.0)];
    let mut interval = IntervalEval::new(tape);
    interval.eval(region);
    let mut bulk = [Interval::point(0.0)];
    IntervalBulkEval::new(tape).eval(&[region], &mut bulk);
    for fidelity in [Fidelity::Exact, Fidelity::Sign] {
        let simpler = tape.simplify(interval.choices(), fidelity);
        PointEval::new(&simpler).eval(p);
        IntervalEval::new(&simpler).eval(region);
    }
}

/// `n` copies of `open`, then `inner`, then `n` copies of `close`.
fn nest(n: usize, open: &str, inner: &str, close: &str) -> String {
    format!("{}{inner}{}", open.repeat(n), close.repeat(n))
}

/// The deepest `form(n)` compiles; one level more is the nesting error.
fn check_limit(what: &str, max: usize, form: impl Fn(usize) -> String) {
    let text = form(max);
    if let Some(error) = pipeline(&text) {
        panic!("{what} at {max} levels ({} bytes): {error}", text.len());
    }
    let error = pipeline(&form(max + 1)).unwrap_or_else(|| panic!("{what} past the limit"));
    assert!(error.contains("deeper than"), "{what}: {error}");
}

#[test]
fn expressions_nest_up_to_the_limit_and_no_further() {
    let n = MAX_NESTING_DEPTH;
    // The form the issue found: `unary` returned `power` without counting, and the exponent
    // of `^` is a `unary`, so `x^x^...` recursed once per `^` unseen by the limit.
    check_limit("x^x^...", n, |k| "x^".repeat(k) + "x");
    check_limit("x^-x^-...", n / 2, |k| "x^-".repeat(k) + "x");
    check_limit("-(-(...", n / 2, |k| nest(k, "-(", "x", ")"));
    check_limit("!!!...", n, |k| "!".repeat(k) + "x");
    check_limit("+++...", n, |k| "+".repeat(k) + "x");
    check_limit("((((", n, |k| nest(k, "(", "x", ")"));
    check_limit("x+(x+(...", n / 2, |k| nest(k, "x+(", "x", ")"));
    // `x*(y-` opens three: the pending `*`, the parenthesis and the pending `-`.
    check_limit("x*(y-(...", n / 3, |k| nest(k, "x*(y-", "z", ")"));
    check_limit("sin(sin(...", n, |k| nest(k, "sin(", "x", ")"));
    check_limit("max(x, max(x, ...", n, |k| nest(k, "max(x,", "y", ")"));
    check_limit("(x)^(x)^...", n, |k| "(x)^".repeat(k) + "x");
    // Pending operators of rising precedence nest too; `y && x ||` closes the `&&`, so each
    // level holds two frames but the innermost three.
    check_limit("x||(y&&(...", (n - 1) / 2, |k| nest(k, "x||(y&&", "z", ")"));
    // Inside a function body, the expression nests from zero again.
    check_limit("return ((((", n, |k| {
        format!(
            "function frep(x,y,z) {{ return {}; }}",
            nest(k, "(", "x", ")")
        )
    });
}

#[test]
fn statements_nest_up_to_the_limit_and_no_further() {
    let n = MAX_STATEMENT_DEPTH;
    let body = |s: String| format!("function frep(x,y,z) {{ r = 0; {s} return r; }}");
    // A function's body is at depth 1, so its statements nest `n - 1` more.
    check_limit("{{{", n - 1, |k| body(nest(k, "{", "r = r + x;", "}")));
    check_limit("if (..) if (..)", n - 1, |k| {
        body(nest(k, "if (x < 1) ", "r = 1;", ""))
    });
    check_limit("if (..) { if (..) {", (n - 1) / 2, |k| {
        body(nest(k, "if (x < 1) { ", "r = 1;", " }"))
    });
    check_limit("else if chain", n - 1, |k| {
        body(format!(
            "if (x < 0) r = 0;{} else r = 2;",
            " else if (x < 1) r = 1;".repeat(k - 1)
        ))
    });
    check_limit("for (..) for (..)", n - 1, |k| {
        body(nest(k, "for (i = 0; i < 1; i = i + 1) ", "r = r + x;", ""))
    });
    check_limit("while (..) while (..)", n - 1, |k| {
        body(nest(k, "while (r < 1) ", "r = r + 1;", ""))
    });
    // Top-level statements are at depth 1 too.
    check_limit("top-level {{{", n - 1, |k| {
        nest(k, "{", "r = x;", "}") + " r"
    })
}

/// The longest text repeating `unit` between `head` and `tail` within `MAX_SOURCE_BYTES`.
fn longest(head: &str, unit: &str, tail: &str) -> String {
    let n = (MAX_SOURCE_BYTES - head.len() - tail.len()) / unit.len();
    let text = format!("{head}{}{tail}", unit.repeat(n));
    assert!(text.len() <= MAX_SOURCE_BYTES && text.len() + unit.len() > MAX_SOURCE_BYTES);
    text
}

#[test]
fn flat_chains_as_long_as_the_text_compile() {
    // Left-leaning chains nest nothing but are as deep as the text is long: the parser, the
    // lowering and the drop of the tree walk them without recursion.
    for (head, unit, tail) in [
        ("", "x+", "x"),
        ("", "x-", "x"),
        ("", "x*y+", "x"),
        ("1", "-x^2", ""),
        ("", "x|", "y"),
        ("", "x<", "y"),
        ("", "x&&", "y"),
        ("", "(x+1)*", "y"),
        ("", "sin(x)+", "y"),
        ("", "x^2+y^2+", "z"),
        ("a = x; ", "a = a*x+y; ", "a"),
        (
            "function frep(x,y,z) { r = 0; ",
            "r = r + x; ",
            "return r; }",
        ),
        (
            "function frep(x,y,z) { r = 0; ",
            "if (x<0) r = r+1; ",
            "return r; }",
        ),
    ] {
        let text = longest(head, unit, tail);
        if let Some(error) = pipeline(&text) {
            panic!("{head}{unit}...{tail}: {error}");
        }
    }
    let over = "x+".repeat(MAX_SOURCE_BYTES / 2) + "x";
    let error = pipeline(&over).expect("longer than the limit");
    assert!(error.contains("the limit is"), "{error}");
}

#[test]
fn a_deep_expression_built_in_code_drops_without_recursion() {
    // Trees built in code can be deeper than any text.
    let span = Span::new(0, 1);
    on_small_stack(|| {
        let mut e = Expr {
            kind: ExprKind::Var("x".into()),
            span,
        };
        for _ in 0..1_000_000 {
            e = Expr {
                kind: ExprKind::Unary(UnaryOp::Neg, Box::new(e)),
                span,
            };
        }
        drop(e);
    });
}

#[test]
fn deep_statements_built_in_code_are_refused_by_the_lowering() {
    // The parser bounds statement nesting; a program built in code is checked again, and
    // dropped without recursion.
    let span = Span::new(0, 1);
    let deep_block = |n: usize| {
        let mut s = Stmt::Expr(Expr {
            kind: ExprKind::Var("x".into()),
            span,
        });
        for _ in 0..n {
            s = Stmt::Block(vec![s], span);
        }
        Program {
            items: vec![Item::Statement(s)],
        }
    };
    on_small_stack(|| {
        let program = deep_block(100_000);
        let (lowered, diagnostics) = fdsl::compile::lower::lower(&program, Default::default());
        assert!(lowered.is_none());
        assert!(
            diagnostics
                .iter()
                .any(|d| d.message.contains("statements nest deeper than")),
            "{diagnostics:?}"
        );
    });
}

#[test]
fn the_parser_alone_reads_any_text_on_a_small_stack() {
    // Garbage deep nestings: each is one located error, never a crash.
    for text in [
        "x^".repeat(30_000) + "x",
        "(".repeat(60_000),
        "{".repeat(60_000),
        "sin(".repeat(16_000),
        "-".repeat(60_000),
        "if (x) ".repeat(9_000) + "r = 1;",
        " else if (x) r=1;".repeat(3_000),
        "for(;;)".repeat(9_000),
    ] {
        on_small_stack(|| {
            let (_, diagnostics) = parser::parse(&text);
            assert!(diagnostics.iter().any(|d| d.is_error()));
        });
    }
}
