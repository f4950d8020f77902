//! The language as users type it: each case compiles a text and checks its values.
#![allow(
    clippy::unwrap_used,
    reason = "test helpers unwrap what a test expects to succeed"
)]

use fdsl::Function;
use fdsl::eval::PointEval;

/// The main value of `src` at `p`, or the rendered errors.
fn value(src: &str, p: [f64; 4]) -> Result<f64, String> {
    let f = Function::parse(src).map_err(|e| e.to_string())?;
    Ok(PointEval::new(&f.tape()).eval(p))
}

fn output(src: &str, name: &str, p: [f64; 4]) -> f64 {
    let f = Function::parse(src).unwrap();
    PointEval::new(&f.tape_for(&[name]).unwrap()).eval(p)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * (1.0 + b.abs())
}

#[track_caller]
fn check(src: &str, p: [f64; 4], expected: f64) {
    let got = value(src, p).unwrap_or_else(|e| panic!("{src}:\n{e}"));
    assert!(
        close(got, expected),
        "{src} at {p:?}: got {got}, expected {expected}"
    );
}

const O: [f64; 4] = [0.0; 4];

#[test]
fn arithmetic_and_functions() {
    let p = [0.3, -0.7, 1.1, 2.0];
    let (x, y, z, t) = (p[0], p[1], p[2], p[3]);
    check("1-x^2-y^2-z^2", p, 1.0 - x * x - y * y - z * z);
    check("2^3^2", O, 512.0);
    check("-2^2", O, -4.0);
    check("x^-2", p, 1.0 / (x * x));
    check("x^0.5 + pow(t, 1.5)", p, x.sqrt() + t.powf(1.5));
    check("y^3", p, y * y * y);
    check("10 % 3 + mod(-1, 3)", O, 1.0 + 2.0);
    check("sin(x)*cos(y)+tan(z)", p, x.sin() * y.cos() + z.tan());
    check(
        "asin(x)+acos(x)+atan(y)+atan2(y, x)",
        p,
        x.asin() + x.acos() + y.atan() + y.atan2(x),
    );
    check(
        "sqrt(t)+abs(y)+exp(x)+log(t)+ln(t)+log10(100)",
        p,
        t.sqrt() + y.abs() + x.exp() + 2.0 * t.ln() + 2.0,
    );
    check("min(x, y, z) + max(x, y, z)", p, y + z);
    check(
        "floor(y) + ceil(y) + round(2.5) + sign(y)",
        p,
        -1.0 + 0.0 + 3.0 - 1.0,
    );
    check("clamp(z, 0, 1) + clamp(y, 0, 1)", p, 1.0);
    check(
        "sinh(x) + cosh(x) + tanh(x)",
        p,
        x.sinh() + x.cosh() + x.tanh(),
    );
    check("sqr(y) + 1.5e1 + .5 + 2.", p, y * y + 15.0 + 0.5 + 2.0);
    check("0.8", p, 0.8);
    check("pi + PI", O, 2.0 * std::f64::consts::PI);
    check("u + 2*v + 4*w + 8*t", p, x + 2.0 * y + 4.0 * z + 8.0 * t);
}

#[test]
fn set_operations() {
    let p = [0.2, 0.4, 0.1, 0.0];
    let sphere = 1.0 - 0.04 - 0.16 - 0.01;
    check("(1-x^2-y^2-z^2) & (0.5 - x)", p, f64::min(sphere, 0.3));
    check("(1-x^2-y^2-z^2) | (0.5 - x)", p, f64::max(sphere, 0.3));
    check("(1-x^2-y^2-z^2) \\ (0.5 - x)", p, f64::min(sphere, -0.3));
    // The thesis's formula: `&` binds looser than arithmetic.
    check(
        "(2^2-x^2-z^2) &(y+5) & (5-y)",
        p,
        (4.0 - 0.04 - 0.01f64).min(5.4).min(4.6),
    );
    let (a, b) = (sphere, 0.3f64);
    check(
        "r_and(1-x^2-y^2-z^2, 0.5-x)",
        p,
        a + b - (a * a + b * b).sqrt(),
    );
    check(
        "r_or(1-x^2-y^2-z^2, 0.5-x)",
        p,
        a + b + (a * a + b * b).sqrt(),
    );
    check(
        "r_sub(1-x^2-y^2-z^2, x-0.5)",
        p,
        a + b - (a * a + b * b).sqrt(),
    );
    // Blends equal min/max far from the seam and dip or bulge near it.
    check("blend_and(x, 10, 0.5)", p, 0.2);
    let blended = value("blend_and(x, y, 0.5)", p).unwrap();
    assert!(blended < 0.2 && blended > 0.2 - 0.5 / 4.0, "{blended}");
    check("blend_or(x, -10, 0.5)", p, 0.2);
    check("blend_sub(x, -10, 0.5)", p, 0.2);
}

#[test]
fn r_function_mode_changes_set_operators() {
    let p = [0.2, 0.4, 0.1, 0.0];
    let options = fdsl::Options {
        set_ops: fdsl::SetOps::RFunction,
        ..fdsl::Options::default()
    };
    let f = Function::parse_with("(1-x^2-y^2-z^2) & (0.5 - x)", options).unwrap();
    let v = PointEval::new(&f.tape()).eval(p);
    let (a, b) = (0.79f64, 0.3f64);
    assert!(close(v, a + b - (a * a + b * b).sqrt()), "{v}");
}

#[test]
fn comparisons_and_logic() {
    let p = [0.3, -0.7, 1.1, 2.0];
    check("x < y", p, 0.0);
    check("x > y", p, 1.0);
    check("x <= 0.3 && y >= -0.7", p, 1.0);
    check("x == 0.3 || y != -0.7", p, 1.0);
    check("!(x == 0.3)", p, 0.0);
    check("x != 0.3", p, 0.0);
}

#[test]
fn scripts() {
    let density = "function frep(x,y,z,t){dist=sqrt(x^2+y^2+z^2); \
                   g=0.8; a=120*pi; if(dist<0.7) g=0.3+0.2*sin(x*a)*sin(y*a)*sin(z*a); return g; }";
    check(density, [0.9, 0.0, 0.0, 0.0], 0.8);
    let a = 120.0 * std::f64::consts::PI;
    let q = [0.1, 0.2, 0.3, 0.0];
    check(
        density,
        q,
        0.3 + 0.2 * (0.1 * a).sin() * (0.2 * a).sin() * (0.3 * a).sin(),
    );
    let tension = "function frep(x,y,z,t){ if (y>-0.9) g=x^2+y^2+z^2; else g=0.4; return g; }";
    check(tension, [0.1, 0.0, 0.2, 0.0], 0.05);
    check(tension, [0.1, -1.0, 0.2, 0.0], 0.4);
    // The author picks the parameter names; they bind to x, y, z, t in order.
    check(
        "function frep(x1, y1, z1, t) { x = x1; return x + 10*y1 + 100*z1; }",
        [1.0, 2.0, 3.0, 0.0],
        321.0,
    );
    // Blocks, nested if/else, early return, reassignment.
    let script = "function frep(a, b) { s = 0; if (a > 0) { s = s + 1; if (b > 0) { return 10; } } else s = -1; s = s * 2; return s; }";
    check(script, [1.0, 1.0, 0.0, 0.0], 10.0);
    check(script, [1.0, -1.0, 0.0, 0.0], 2.0);
    check(script, [-1.0, 1.0, 0.0, 0.0], -2.0);
    // Returns on every path of an if/else end the function.
    check(
        "function frep(x) { if (x > 0) return 1; else return 2; }",
        [-1.0, 0.0, 0.0, 0.0],
        2.0,
    );
    // Top-level statements with a final value.
    check("r = 0.5; r - sqrt(x^2+y^2)", [0.3, 0.0, 0.0, 0.0], 0.2);
}

#[test]
fn bounded_loops_unroll() {
    check(
        "s = 0; for (i = 1; i <= 10; i = i + 1) s = s + i; s",
        O,
        55.0,
    );
    check(
        "s = 1; n = 0; while (s < 1000) { s = s * 2; n = n + 1; } n",
        O,
        10.0,
    );
    let harmonics = "function frep(x) { f = 0; for (k = 1; k <= 4; k = k + 1) { f = f + sin(k*x)/k; } return f; }";
    check(
        harmonics,
        [0.5, 0.0, 0.0, 0.0],
        (1..=4).map(|k| (k as f64 * 0.5).sin() / k as f64).sum(),
    );
    // A condition on the coordinates is fine while it settles within the symbolic trip limit.
    check(
        "s = x; for (i = 0; i < 3; i = i + 1) { if (s < 1) s = s * 2; } s",
        [0.3, 0.0, 0.0, 0.0],
        1.2,
    );
    // One that never settles symbolically is refused, whatever its values would be.
    let err = value("s = x; while (s < 1 && s > 0) { s = s * 2; } s", O).unwrap_err();
    assert!(
        err.contains("still depends on the coordinates after 32 trips"),
        "{err}"
    );
    // A return inside a loop stops it.
    check(
        "function frep(x) { for (i = 0; i < 100; i = i + 1) { if (i == 3) return i; } return -1; }",
        O,
        3.0,
    );
}

#[test]
fn parametric_colour_and_field_outputs() {
    let geometry =
        "x=cos(u*pi)*((sin(0.5*v*pi))^3);y=sin(u*pi)*((sin(0.5*v*pi))^3);z=cos(0.5*v*pi);";
    let f = Function::parse(geometry).unwrap();
    assert_eq!(f.output_names().collect::<Vec<_>>(), ["x", "y", "z"]);
    let p = [0.25, 0.5, 0.0, 0.0];
    let s = (0.25 * std::f64::consts::PI).sin().powi(3);
    assert!(close(
        output(geometry, "x", p),
        (0.25 * std::f64::consts::PI).cos() * s
    ));
    assert!(close(
        output(geometry, "z", p),
        (0.25 * std::f64::consts::PI).cos()
    ));
    let colour = "r=t; g=abs(sin(5*u*pi)); b=w;";
    assert!(close(output(colour, "b", [0.0, 0.0, 0.7, 0.2]), 0.7));
    assert!(close(output(colour, "r", [0.0, 0.0, 0.7, 0.2]), 0.2));
    let field = "function parametric_x(u,v,w) { d=-0.1; x=w+d*u; y=d*v; z=-u+d*w; return x/sqrt(x^2+y^2+z^2); } \
                 function parametric_y(u,v,w) { d=-0.1; x=w+d*u; y=d*v; z=-u+d*w; return y/sqrt(x^2+y^2+z^2); } \
                 function parametric_z(u,v,w) { d=-0.1; x=w+d*u; y=d*v; z=-u+d*w; return z/sqrt(x^2+y^2+z^2); }";
    let f = Function::parse(field).unwrap();
    assert_eq!(f.output_names().collect::<Vec<_>>(), ["x", "y", "z"]);
    let tape = f.tape_for(&["x", "y", "z"]).unwrap();
    let mut out = [0.0; 3];
    PointEval::new(&tape).eval_all([1.0, 0.0, 0.0, 0.0], &mut out);
    let n = (0.1f64 * 0.1 + 1.0).sqrt();
    assert!(
        close(out[0], -0.1 / n) && close(out[1], 0.0) && close(out[2], -1.0 / n),
        "{out:?}"
    );
    // Shared subexpressions of the three outputs are computed once.
    let separate: usize = ["x", "y", "z"]
        .iter()
        .map(|o| f.tape_for(&[o]).unwrap().len())
        .sum();
    assert!(tape.len() < separate, "{} vs {separate}", tape.len());
    let missing = f.tape_for(&["q"]).unwrap_err();
    assert_eq!(
        missing.to_string(),
        "the definition has no output `q` (it defines x, y, z)"
    );
}

#[test]
fn message_wrappers_from_the_thesis() {
    let wrapped =
        "BEGIN function frep(x,y,z,t){ if (y>-0.9) g=x^2+y^2+z^2; else g=0.4; return g; } END";
    let compiled = Function::compile(wrapped);
    assert!(compiled.function.is_some());
    assert_eq!(compiled.diagnostics.len(), 2);
    assert!(compiled.diagnostics.iter().all(|d| !d.is_error()));
    check(wrapped, [0.0, -1.0, 0.0, 0.0], 0.4);
    // The thesis prints this one without its closing brace: reported, with the fix.
    let err = value(
        "BEGIN function frep(x,y,z,t){ if (y>-0.9) g=x^2+y^2+z^2; else g=0.4; return g; END",
        O,
    )
    .unwrap_err();
    assert!(
        err.contains("this `{` is never closed") && err.contains("add `}`"),
        "{err}"
    );
}

#[test]
fn time_dependence_is_known() {
    assert!(Function::parse("r=t; g=u; b=w;").unwrap().depends_on_time());
    assert!(!Function::parse("1-x^2").unwrap().depends_on_time());
    assert_eq!(
        Function::parse("x+z").unwrap().inputs_used(),
        [true, false, true, false]
    );
}

/// The thesis's printed code, taken as printed where the intent is clear (issue: printed-code
/// tolerance): a dash for minus, and a chain of set operations compared with zero.
#[test]
fn printed_code_reads_as_its_author_meant() {
    // The en dash, em dash, minus sign and figure dash read as minus, with one warning.
    for dash in ['\u{2013}', '\u{2014}', '\u{2212}', '\u{2012}'] {
        let src = format!("1 {dash} x^2 {dash}y^2");
        check(&src, [0.5, 0.25, 0.0, 0.0], 1.0 - 0.25 - 0.0625);
        let compiled = Function::compile(&src);
        let warnings: Vec<_> = compiled
            .diagnostics
            .iter()
            .filter(|d| !d.is_error())
            .collect();
        assert_eq!(warnings.len(), 1, "{src}");
        assert!(warnings[0].render(&src).contains("minus sign"), "{src}");
    }
    check("\u{2013}x", [0.5, 0.0, 0.0, 0.0], -0.5);
    // `a & b & c >= 0` compares the whole intersection with zero: true inside the cylinder
    // of radius 2 and height 2 only. (It used to read `a & b & (c >= 0)`, whose value is the
    // intersection's, not a truth value, outside the solid.)
    let cylinder = "(2^2-x^2-z^2) & (y+1) & (1-y) >= 0";
    check(cylinder, [0.0, 0.0, 0.0, 0.0], 1.0);
    check(cylinder, [1.9, 0.9, 0.0, 0.0], 1.0);
    check(cylinder, [3.0, 0.0, 0.0, 0.0], 0.0);
    check(cylinder, [0.0, 1.5, 0.0, 0.0], 0.0);
    check("x | y > 0", [-1.0, 2.0, 0.0, 0.0], 1.0);
    check("x | y > 0", [-1.0, -2.0, 0.0, 0.0], 0.0);
    // The thesis's script with that test inside an `if`.
    let script = "function frep(x,y,z,t) { h = 1; r = 2; g = -1; \
                  if ((r^2-x^2-z^2) & (y+h) & (h-y) >= 0) g = 0.5; return g; }";
    check(script, [0.0, 0.0, 0.0, 0.0], 0.5);
    check(script, [3.0, 0.0, 0.0, 0.0], -1.0);
    // Logic keeps binding looser than comparisons.
    check("x > 0 && y > 0", [1.0, 1.0, 0.0, 0.0], 1.0);
    check("x > 0 && y > 0", [1.0, -1.0, 0.0, 0.0], 0.0);
}
