//! Parser tests: each source is printed as an S-expression, or as its rendered diagnostics.

use super::*;

fn sexpr(e: &Expr) -> String {
    match &e.kind {
        ExprKind::Number(v) => format!("{v}"),
        ExprKind::Var(n) => n.clone(),
        ExprKind::Unary(op, a) => format!(
            "({} {})",
            if *op == UnaryOp::Neg { "-" } else { "!" },
            sexpr(a)
        ),
        ExprKind::Binary(op, a, b) => format!("({op:?} {} {})", sexpr(a), sexpr(b)),
        ExprKind::Call(name, args) => {
            let args: Vec<_> = args.iter().map(sexpr).collect();
            format!("({} {})", name.name, args.join(" "))
        }
    }
}

fn stmt(s: &Stmt) -> String {
    match s {
        Stmt::Assign { name, value } => format!("{}={}", name.name, sexpr(value)),
        Stmt::If {
            cond,
            then,
            otherwise,
            ..
        } => match otherwise {
            Some(o) => format!("if {} {{{}}} else {{{}}}", sexpr(cond), stmt(then), stmt(o)),
            None => format!("if {} {{{}}}", sexpr(cond), stmt(then)),
        },
        Stmt::Block(body, _) => body.iter().map(stmt).collect::<Vec<_>>().join("; "),
        Stmt::Return(e, _) => format!("return {}", sexpr(e)),
        Stmt::Loop {
            init,
            cond,
            step,
            body,
            ..
        } => format!(
            "loop [{}] [{}] [{}] {{{}}}",
            init.as_deref().map(stmt).unwrap_or_default(),
            cond.as_ref().map(sexpr).unwrap_or_default(),
            step.as_deref().map(stmt).unwrap_or_default(),
            stmt(body)
        ),
        Stmt::Expr(e) => sexpr(e),
    }
}

/// The program printed item by item, then every diagnostic rendered.
fn check(src: &str) -> String {
    let (program, diagnostics) = parse(src);
    let mut out: Vec<String> = program
        .items
        .iter()
        .map(|item| match item {
            Item::Function(f) => {
                let params: Vec<_> = f.params.iter().map(|p| p.name.as_str()).collect();
                let body: Vec<_> = f.body.iter().map(stmt).collect();
                format!(
                    "fn {}({}) {{{}}}",
                    f.name.name,
                    params.join(","),
                    body.join("; ")
                )
            }
            Item::Statement(s) => stmt(s),
        })
        .collect();
    out.extend(diagnostics.iter().map(|d| d.render(src)));
    out.join("\n")
}

#[test]
fn arithmetic_precedence() {
    assert_eq!(
        check("1-x^2-y^2-z^2"),
        "(Sub (Sub (Sub 1 (Pow x 2)) (Pow y 2)) (Pow z 2))"
    );
    assert_eq!(check("-x^2"), "(- (Pow x 2))");
    assert_eq!(check("2^3^2"), "(Pow 2 (Pow 3 2))");
    assert_eq!(check("x^-2"), "(Pow x (- 2))");
    assert_eq!(check("a*b+c/d%e"), "(Add (Mul a b) (Mod (Div c d) e))");
    assert_eq!(check("+x"), "x");
}

#[test]
fn set_operators_bind_looser_than_arithmetic() {
    assert_eq!(
        check("(2^2-x^2-z^2) &(y+5) & (5-y)"),
        "(Intersect (Intersect (Sub (Sub (Pow 2 2) (Pow x 2)) (Pow z 2)) (Add y 5)) (Sub 5 y))"
    );
    assert_eq!(
        check("a | b & c \\ d"),
        "(Union a (Subtract (Intersect b c) d))"
    );
    assert_eq!(
        check("a < b && c >= d || !e"),
        "(Or (And (Lt a b) (Ge c d)) (! e))"
    );
}

#[test]
fn calls_and_statement_lists() {
    assert_eq!(check("max(x, y, 1)"), "(max x y 1)");
    assert_eq!(
        check("x=cos(u*pi)*((sin(0.5*v*pi))^3);y=sin(u*pi);z=cos(0.5*v*pi);"),
        "x=(Mul (cos (Mul u pi)) (Pow (sin (Mul (Mul 0.5 v) pi)) 3))\ny=(sin (Mul u pi))\nz=(cos (Mul (Mul 0.5 v) pi))"
    );
}

#[test]
fn scripts_with_if_else_and_loops() {
    assert_eq!(
        check("function frep(x,y,z,t){ if (y>-0.9) g=x^2+y^2+z^2; else g=0.4; return g; }"),
        "fn frep(x,y,z,t) {if (Gt y (- 0.9)) {g=(Add (Add (Pow x 2) (Pow y 2)) (Pow z 2))} else {g=0.4}; return g}"
    );
    assert_eq!(
        check("s=0; for (i=0; i<3; i=i+1) { s = s + i; } while (s < 10) s = s*2;"),
        "s=0\nloop [i=0] [(Lt i 3)] [i=(Add i 1)] {s=(Add s i)}\nloop [] [(Lt s 10)] [] {s=(Mul s 2)}"
    );
}

#[test]
fn message_wrappers_are_recognised() {
    let out = check("BEGIN 0.2*x; END");
    assert!(
        out.starts_with("(Mul 0.2 x)\nwarning: ignored the message wrapper `BEGIN`"),
        "{out}"
    );
    assert!(
        out.contains("warning: ignored the message wrapper `END`"),
        "{out}"
    );
}

#[test]
fn quotes_are_rejected_with_a_hint() {
    let out = check("“BEGIN 1-x^2 END”");
    assert!(
        out.contains("error: the character `“` is not part of the language"),
        "{out}"
    );
    assert!(out.contains("hint: remove the quotation marks"), "{out}");
}

#[test]
fn every_error_path_has_a_message_and_location() {
    let cases: &[(&str, &str)] = &[
        (
            "1 +",
            "error: the text ends where a value was expected\n --> 1:4",
        ),
        (
            "(1 + x",
            "error: this `(` is not closed (found the end of the text)\n --> 1:1",
        ),
        ("sin(x", "error: the arguments of `sin` are not closed"),
        (
            "1 + )",
            "error: expected a number, a name or `(`, found `)`",
        ),
        (
            "x = 1 y = 2",
            "error: expected `;` or an operator, found `y`",
        ),
        (
            "function f(x) { return x;",
            "error: this `{` is never closed",
        ),
        (
            "function (x) { }",
            "error: expected a function name after `function`, found `(`",
        ),
        (
            "function f x",
            "error: expected `(` after the function name, found `x`",
        ),
        (
            "function f(x, 1) {}",
            "error: expected a parameter name, found the number `1`",
        ),
        (
            "function f(x) x",
            "error: expected `{` to open the function body, found `x`",
        ),
        (
            "if x > 1 g = 1;",
            "error: expected `(` after `if`, found `x`",
        ),
        (
            "if (x = 1) g = 1;",
            "error: `=` assigns; a condition compares",
        ),
        (
            "if (x > 1 g = 1;",
            "error: expected `)` to close the condition, found `g`",
        ),
        ("else g = 1;", "error: `else` without a matching `if`"),
        (
            "for (i=0 i<3; i=i+1) {}",
            "error: expected `;` after the loop's start, found `i`",
        ),
        (
            "for (i=0; i<3 i=i+1) {}",
            "error: expected `;` after the loop's condition, found `i`",
        ),
        (
            "for (i=0; i<3; i=i+1 {}",
            "error: expected `)` to close the loop header, found `{`",
        ),
        ("while x {}", "error: expected `(` after `while`, found `x`"),
        ("1e999", "error: this number is too large to represent"),
        (
            "x − 1",
            "warning: read the printed dash `−` as a minus sign `-`",
        ),
        ("2π", "hint: write `pi`"),
        ("Geometry: 1-x", "hint: remove a label such as `Geometry:`"),
        (
            "x = 1 = 2",
            "error: only a variable name can stand left of `=`",
        ),
        ("x + 1)", "error: this `)` has no matching `(`"),
        ("x = if + 1", "error: `if` is a keyword, not a name"),
        (
            "{ function f() {} }",
            "error: a function can only be defined at the top level",
        ),
        (
            "x #",
            "error: the character `#` is not part of the language",
        ),
    ];
    for (src, expected) in cases {
        let out = check(src);
        assert!(
            out.contains(expected),
            "source {src:?}\nexpected {expected:?}\ngot:\n{out}"
        );
    }
}

#[test]
fn several_errors_are_reported_and_parsing_goes_on() {
    let (program, diagnostics) = parse("a = 1 +; b = 2; c = *3; d = 4;");
    assert_eq!(diagnostics.len(), 2, "{diagnostics:?}");
    assert_eq!(program.items.len(), 2);
}

#[test]
fn limits_hold() {
    let deep = format!("{}x{}", "(".repeat(10_000), ")".repeat(10_000));
    let (_, d) = parse(&deep);
    assert_eq!(d.len(), 1);
    assert!(d[0].message.contains("nests deeper than"), "{d:?}");
    let deep_unary = "-".repeat(50_000) + "x";
    let (_, d) = parse(&deep_unary);
    assert!(d[0].message.contains("nests deeper than"), "{d:?}");
    let long = "x+".repeat(40_000) + "x";
    let (_, d) = parse(&long);
    assert!(d[0].message.contains("the limit is"), "{d:?}");
    let many_errors = "x = ; ".repeat(1000);
    let (_, d) = parse(&many_errors);
    assert_eq!(d.len(), crate::limits::MAX_DIAGNOSTICS);
}
