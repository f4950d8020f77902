//! The spellings the thesis prints for the same thing in different places, one test each: each
//! is read as the canonical spelling reads, with a warning that names the canonical one
//! (except where both spellings are ours to read alike); printed code that is really broken
//! (an unclosed brace, an extra parenthesis) keeps its located error and hint.
#![allow(clippy::unwrap_used, reason = "test helpers unwrap")]

use formats::fvrml::{self, Issue, LoadOptions, Loaded};
use glam::DVec3;
use model::object::{ObjectData, Paintable};

fn no_files(path: &str) -> Result<Vec<u8>, String> {
    Err(format!("no file {path}"))
}

fn load(text: &str) -> Loaded {
    match fvrml::load(text, &LoadOptions::default(), &mut no_files) {
        Ok(loaded) => loaded,
        Err(e) => panic!("load failed:\n{e}"),
    }
}

/// The description of the only object of `text`.
fn data(loaded: &Loaded) -> ObjectData {
    let objects: Vec<_> = loaded.scene.objects().collect();
    assert_eq!(objects.len(), 1);
    ObjectData::clone(objects[0].1.object.data())
}

/// The one warning that mentions `needle`.
fn warning<'a>(loaded: &'a Loaded, needle: &str) -> &'a Issue {
    let found: Vec<&Issue> = loaded
        .warnings
        .iter()
        .filter(|w| w.message.contains(needle))
        .collect();
    assert_eq!(found.len(), 1, "{needle:?} in {:#?}", loaded.warnings);
    found[0]
}

/// A ball with `physics` as its physics node.
fn ball_with(physics: &str) -> String {
    format!(
        "FShape {{\n  geometry FGeometry {{ definition \"1-x^2-y^2-z^2\" bboxSize 2 2 2 }}\n  \
         physics {physics}\n}}\n"
    )
}

const CANONICAL: &str = "FPhysics { surface FSurface { \
                         tension FTension { enable TRUE definition \"1\" } \
                         friction FFriction { enable FALSE } } }";

#[test]
fn surface_properties_straight_under_fphysics_as_figure_7_4_writes_them() {
    // Figure 7.4: `physics FPhysics { friction FFriction {enable FALSE} ... }`.
    let printed = ball_with(
        "FPhysics {\n     tension FTension {enable TRUE definition \"1\"}\n     \
         friction FFriction {enable FALSE}\n  }",
    );
    let loaded = load(&printed);
    let canonical = load(&ball_with(CANONICAL));
    assert!(canonical.warnings.is_empty(), "{:#?}", canonical.warnings);
    assert_eq!(data(&loaded), data(&canonical));
    let friction = warning(&loaded, "`friction` belongs in the surface");
    assert!(
        friction
            .message
            .contains("surface FSurface { friction FFriction { ... } }"),
        "{friction}"
    );
    assert_eq!(friction.location.line, 5);
    assert_eq!(warning(&loaded, "`tension` belongs").location.line, 4);
    assert_eq!(loaded.warnings.len(), 2, "{:#?}", loaded.warnings);
}

#[test]
fn a_colon_after_the_field_name_as_figure_7_8_writes_it() {
    // Figure 7.8: `tension FTension {enable TRUE definition: "1"}`.
    let printed = ball_with(
        "FPhysics { surface FSurface { tension FTension {enable TRUE definition: \"1\"} \
         friction FFriction { enable FALSE } } }",
    );
    let loaded = load(&printed);
    assert_eq!(data(&loaded), data(&load(&ball_with(CANONICAL))));
    let colon = warning(&loaded, "stray `:` after the field name `definition`");
    assert!(
        colon.message.contains("VRML writes `definition value`"),
        "{colon}"
    );
    assert_eq!(loaded.warnings.len(), 1, "{:#?}", loaded.warnings);
}

#[test]
fn typographic_quotes_as_figures_7_4_and_7_8_print_them() {
    // Figure 7.8: `definition: “1”`; Figure 7.4: `transparency “0”`.
    let printed = ball_with(
        "FPhysics { surface FSurface { tension FTension { definition “1” } \
         friction FFriction { enable FALSE } } }",
    );
    let loaded = load(&printed);
    assert_eq!(data(&loaded), data(&load(&ball_with(CANONICAL))));
    let quotes = warning(&loaded, "typographic quotes");
    assert!(
        quotes.message.contains("read as straight quotes \"...\""),
        "{quotes}"
    );
    assert_eq!(loaded.warnings.len(), 1, "{:#?}", loaded.warnings);
}

#[test]
fn a_string_opened_by_a_closing_quote_as_figure_7_4_prints_it() {
    // Figure 7.4: `force FForce { definition” function parametric_x ... ;}” ... }`.
    let field = "x = -v; y = u; z = 0;";
    let printed = ball_with(&format!(
        "FPhysics {{ force FForce {{ definition”\n  {field}” parameters [-1 1 -1 1 -1 1] }} }}"
    ));
    let canonical = ball_with(&format!(
        "FPhysics {{ force FForce {{ definition \"\n  {field}\" parameters [-1 1 -1 1 -1 1] }} }}"
    ));
    let loaded = load(&printed);
    assert_eq!(data(&loaded), data(&load(&canonical)));
    warning(&loaded, "typographic quotes");
    assert_eq!(loaded.warnings.len(), 1, "{:#?}", loaded.warnings);
}

#[test]
fn a_string_opened_straight_and_closed_typographic() {
    let printed = ball_with(
        "FPhysics { surface FSurface { tension FTension { definition \"1” } \
         friction FFriction { enable FALSE } } }",
    );
    let loaded = load(&printed);
    assert_eq!(data(&loaded), data(&load(&ball_with(CANONICAL))));
    warning(&loaded, "typographic quotes");
    assert_eq!(loaded.warnings.len(), 1, "{:#?}", loaded.warnings);
}

#[test]
fn printed_dashes_for_a_minus_in_a_formula() {
    // The thesis typesets minus signs as dashes; a formula copied from it keeps them.
    let printed =
        "FShape {\n  geometry FGeometry { definition \"1–x^2−y^2—z^2\" bboxSize 2 2 2 }\n}\n";
    let loaded = load(printed);
    let canonical =
        load("FShape { geometry FGeometry { definition \"1-x^2-y^2-z^2\" bboxSize 2 2 2 } }");
    let mut sampler = loaded.scene.objects().next().unwrap().1.object.sampler();
    let mut expected = canonical.scene.objects().next().unwrap().1.object.sampler();
    let p = DVec3::new(0.5, 0.25, -0.125);
    assert_eq!(sampler.value(p, 0.0), expected.value(p, 0.0));
    let dash = warning(&loaded, "read the printed dash `–` as a minus sign `-`");
    assert!(dash.message.starts_with("`definition`: warning:"), "{dash}");
    assert!(dash.message.contains("hint: type `-` for minus"), "{dash}");
    assert_eq!((dash.location.line, dash.location.column), (2, 35));
    assert_eq!(loaded.warnings.len(), 1, "{:#?}", loaded.warnings);
}

#[test]
fn the_message_wrapper_begin_end_of_chapter_5() {
    // Chapter 5's "updated texture definition" message, as printed.
    let message = "BEGIN 0.2*(sin(10*pi*x)*sin(10*pi*y)+sin(10*pi*x)*sin(20*pi*z)+ \
                   sin(10*pi*y)*sin(20*pi*z)); END";
    let printed = format!(
        "FShape {{ geometry FGeometry {{ definition \"1-x^2-y^2-z^2\" bboxSize 2 2 2 }}\n\
         appearance FAppearance {{ texture FTexture3D {{ definition \"{message}\" }} }} }}"
    );
    let loaded = load(&printed);
    let begin = warning(&loaded, "ignored the message wrapper `BEGIN`");
    assert!(
        begin
            .message
            .contains("only the definition between BEGIN and END"),
        "{begin}"
    );
    assert_eq!(begin.location.line, 2);
    warning(&loaded, "ignored the message wrapper `END`");
    let mut sampler = loaded.scene.objects().next().unwrap().1.object.sampler();
    let p = DVec3::new(0.05, 0.05, 0.025);
    let expected = 0.2
        * ((10.0 * std::f64::consts::PI * p.x).sin() * (10.0 * std::f64::consts::PI * p.y).sin()
            + (10.0 * std::f64::consts::PI * p.x).sin()
                * (20.0 * std::f64::consts::PI * p.z).sin()
            + (10.0 * std::f64::consts::PI * p.y).sin()
                * (20.0 * std::f64::consts::PI * p.z).sin());
    assert!((sampler.displacement(p, 0.0).unwrap() - expected).abs() < 1e-12);
}

#[test]
fn function_frep_with_and_without_t() {
    // Chapter 5 writes `function frep(x,y,z,t){...}`; a script that does not use the time
    // may leave `t` out. Parameters stand for x, y, z, t by position: both read alike.
    let script = |params: &str| {
        ball_with(&format!(
            "FPhysics {{ density FDensity {{ definition \"function frep({params}){{ \
             dist=sqrt(x^2+y^2+z^2); g=0.8; if(dist<0.7) g=0.3; return g; }}\" }} }}"
        ))
    };
    let with_t = load(&script("x,y,z,t"));
    let without_t = load(&script("x,y,z"));
    assert!(with_t.warnings.is_empty() && without_t.warnings.is_empty());
    let density = |loaded: &Loaded, p: DVec3| {
        let mut s = loaded.scene.objects().next().unwrap().1.object.sampler();
        s.scalar(Paintable::Density, p, 0.0)
    };
    for p in [DVec3::ZERO, DVec3::new(0.8, 0.0, 0.0)] {
        assert_eq!(density(&with_t, p), density(&without_t, p), "{p}");
    }
    assert_eq!(density(&with_t, DVec3::ZERO), Some(0.3));
}

#[test]
fn broken_printed_scripts_keep_their_located_errors_and_hints() {
    // Chapter 5's density script as printed: one `)` too many, and no closing `}`.
    let density = "function frep(x,y,z,t){dist=sqrt(x^2+y^2+z^2); g=0.8; a=120*pi; \
                   if(dist<0.7) g=0.3+0.2*sin(x*a)*sin(y*a)*sin(z*a)); return g;";
    let text = ball_with(&format!(
        "FPhysics {{\n density FDensity {{ definition \"{density}\" }} }}"
    ));
    let issues = match fvrml::load(&text, &LoadOptions::default(), &mut no_files) {
        Err(e) => e.issues,
        Ok(_) => panic!("the printed script does not compile"),
    };
    let error = issues.iter().find(|i| i.is_error()).unwrap();
    assert_eq!(
        (error.location.line, error.location.column),
        (4, 32),
        "{error}"
    );
    for part in [
        "density",
        "this `)` has no matching `(`",
        "hint: remove it or add `(` before",
        "this `{` is never closed",
        "hint: add `}` at the end",
    ] {
        assert!(error.message.contains(part), "{part:?} in {error}");
    }
    // Its tension message: no closing `}` either.
    let tension = "function frep(x,y,z,t){ if (y>-0.9) g=x^2+y^2+z^2; else g=0.4; return g;";
    let text = ball_with(&format!(
        "FPhysics {{ surface FSurface {{ tension FTension {{ definition \"{tension}\" }} }} }}"
    ));
    let issues = match fvrml::load(&text, &LoadOptions::default(), &mut no_files) {
        Err(e) => e.issues,
        Ok(_) => panic!("the printed script does not compile"),
    };
    let error = issues.iter().find(|i| i.is_error()).unwrap();
    assert!(
        error.message.contains("this `{` is never closed"),
        "{error}"
    );
    assert!(
        error.message.contains("hint: add `}` at the end"),
        "{error}"
    );
}
