//! Every way compiling can fail has a message, a location and (mostly) a hint; none panics.
//! Parser errors are tested next to the parser; these are the compiler's.

use fdsl::Function;

/// The rendered errors of a text that must not compile.
fn errors(src: &str) -> String {
    match Function::parse(src) {
        Ok(f) => panic!(
            "{src:?} compiled to outputs {:?}",
            f.output_names().collect::<Vec<_>>()
        ),
        Err(e) => e.to_string(),
    }
}

#[test]
fn compiler_errors_have_messages_locations_and_hints() {
    let many_vars: String = (0..600).map(|i| format!("v{i} = {i};")).collect();
    let many_outputs: String = (0..70).map(|i| format!("o{i} = x + {i};")).collect();
    let cases: Vec<(&str, &str)> = vec![
        ("", "error: the definition is empty"),
        (
            "   // only a comment",
            "hint: write an expression such as `1-x^2-y^2-z^2`",
        ),
        (
            "a = 1; function frep(x) { return x; }",
            "error: statements outside a function\n --> 1:1",
        ),
        (
            "function frep(x) { return x; } function frep(y) { return y; }",
            "error: `frep` is defined twice",
        ),
        (
            "function frep(a, b, c, d, e) { return a; }",
            "error: a function takes at most four parameters",
        ),
        (
            "function frep(x, x) { return x; }",
            "error: the parameter `x` is named twice",
        ),
        (
            "function frep(x) { g = x; }",
            "error: `frep` never returns a value",
        ),
        (
            "function frep(x) { if (x > 0) return 1; }",
            "error: `frep` can reach its end without returning",
        ),
        (
            "function frep(x) { x + 1; return x; }",
            "error: a value on its own does nothing here",
        ),
        (
            "x + 1; y = 2;",
            "error: a value on its own must be the last statement",
        ),
        (
            "if (x > 0) return 1;",
            "error: the text can end without returning",
        ),
        ("{ }", "error: the text defines no value"),
        (&many_vars, "error: more than 512 variables"),
        (
            &many_outputs,
            "error: the text defines more than 64 outputs",
        ),
        (
            "s = 0; for (i = 0; i < 5000; i = i + 1) s = s + 1; s",
            "error: this loop runs more than 1024 times",
        ),
        (
            "s = 0; for (i = 0; i < 1000; i = i + 1) for (j = 0; j < 1000; j = j + 1) s = s + 1; s",
            "error: the program runs more than 100000 statements",
        ),
        (
            "function frep(x) { if (x > 0) g = 1; return g; }",
            "error: `g` is not assigned on every path before this use",
        ),
        (
            "function frep(x) { if (x > 0) g = 1; return g; }",
            "hint: assign `g` before the `if`, or in every branch",
        ),
        ("1 - x^2 - yy^2", "error: unknown name `yy`"),
        ("1 - x^2 - yy^2", "hint: did you mean `y`?"),
        ("sin + 1", "hint: `sin` is a function: write `sin(...)`"),
        (
            "function frep(x, y) { return z; }",
            "hint: add `z` to the function's parameters",
        ),
        ("radius - x", "hint: assign it before use"),
        ("sni(x)", "error: unknown function `sni`\n --> 1:1"),
        ("sni(x)", "hint: did you mean `sin`?"),
        ("frobnicate(x)", "hint: see the list of functions"),
        (
            "sin(x, y)",
            "error: `sin` takes 1 argument, but 2 were given",
        ),
        (
            "atan2(x)",
            "error: `atan2` takes 2 arguments, but 1 were given",
        ),
        (
            "min(x)",
            "error: `min` takes at least 2 arguments, but 1 were given",
        ),
        (
            "clamp(x, 1)",
            "error: `clamp` takes 3 arguments, but 2 were given",
        ),
    ];
    for (src, expected) in &cases {
        let out = errors(src);
        assert!(
            out.contains(expected),
            "source {src:?}\nexpected {expected:?}\ngot:\n{out}"
        );
    }
}

#[test]
fn the_graph_limit_is_an_error_not_an_allocation() {
    // Each trip doubles the expression: 2^40 operations unless the limit stops it.
    let src = "s = x; for (i = 0; i < 40; i = i + 1) { s = sin(s) + cos(s*i); } s";
    let ok = Function::parse(src);
    assert!(ok.is_ok(), "shared subexpressions keep this small");
    // A loop that builds distinct operations past the limit.
    let big = "s = x; for (i = 0; i < 1000; i = i + 1) { a = sin(s + i); b = cos(s * i); c = a*b + i; s = c; } \
               t2 = 0; for (j = 0; j < 1000; j = j + 1) { for (k = 0; k < 90; k = k + 1) { t2 = t2 + sin(x*j + k); } } t2 + s";
    let out = errors(big);
    assert!(
        out.contains("the expression needs more than 200000 operations")
            || out.contains("runs more than 100000 statements"),
        "{out}"
    );
}

#[test]
fn warnings_do_not_stop_compilation() {
    let compiled = Function::compile("BEGIN 1-x^2 END");
    assert!(compiled.function.is_some());
    assert!(compiled.diagnostics.iter().all(|d| !d.is_error()));
}
