//! The `sculpt` program: for now its command-line subcommands; the desktop window comes with
//! the render and replication crates.

use std::process::ExitCode;

use anyhow::{Context as _, bail};
use fdsl::Function;
use fdsl::eval::{BulkEval, PointEval};

const USAGE: &str = "\
sculpt: sculpt 3D objects defined by functions

usage:
  sculpt demo                  show the demo scene (the thesis's watermelon) as a slice
  sculpt check <text|@file>    compile a function and report problems with their location
  sculpt eval <text|@file> X Y Z [T]
                               print every output of a function at a point
  sculpt slice <text|@file> [Z] [T]
                               draw the solid's cross-section at height Z as text
";

/// The demo scene: the thesis's watermelon, a sphere with a wedge cut out.
const DEMO: &str = include_str!("../../tests/data/models/watermelon.fdsl");

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("{e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &[String]) -> anyhow::Result<()> {
    let Some(command) = args.first() else {
        print!("{USAGE}");
        return Ok(());
    };
    match command.as_str() {
        "demo" => {
            println!("The demo scene: {}", DEMO.trim());
            println!("Slice at z = 0.2 ('#' inside, '.' outside):\n");
            print!("{}", slice(&Function::parse(DEMO)?, 0.2, 0.0, 64, 32));
            Ok(())
        }
        "check" => {
            let text = source(args.get(1))?;
            let compiled = Function::compile(&text);
            for d in &compiled.diagnostics {
                eprint!("{}", d.render(&text));
            }
            match compiled.function {
                Some(f) => {
                    let names: Vec<&str> = f.output_names().collect();
                    println!(
                        "ok: outputs {}; {} operations",
                        names.join(", "),
                        f.graph_len()
                    );
                    Ok(())
                }
                None => bail!("the function does not compile"),
            }
        }
        "eval" => {
            let function = Function::parse(&source(args.get(1))?)?;
            let mut p = [0.0; 4];
            for (slot, arg) in args.iter().skip(2).take(4).enumerate() {
                p[slot] = arg
                    .parse()
                    .with_context(|| format!("`{arg}` is not a number"))?;
            }
            for name in function.output_names() {
                let tape = function.tape_for(&[name])?;
                println!("{name} = {}", PointEval::new(&tape).eval(p));
            }
            Ok(())
        }
        "slice" => {
            let function = Function::parse(&source(args.get(1))?)?;
            let number = |i: usize| -> anyhow::Result<f64> {
                args.get(i).map_or(Ok(0.0), |a| {
                    a.parse().with_context(|| format!("`{a}` is not a number"))
                })
            };
            print!("{}", slice(&function, number(2)?, number(3)?, 64, 32));
            Ok(())
        }
        "help" | "--help" | "-h" => {
            print!("{USAGE}");
            Ok(())
        }
        other => bail!("unknown command `{other}`\n\n{USAGE}"),
    }
}

/// The text of a function: the argument itself, or the file named after `@`.
fn source(arg: Option<&String>) -> anyhow::Result<String> {
    let arg = arg.context("give a function text, or @file")?;
    match arg.strip_prefix('@') {
        Some(path) => std::fs::read_to_string(path).with_context(|| format!("cannot read {path}")),
        None => Ok(arg.clone()),
    }
}

/// A text picture of the solid's section at height `z` over [-1.2, 1.2]^2.
fn slice(function: &Function, z: f64, t: f64, width: usize, height: usize) -> String {
    let mut eval = BulkEval::new(&function.tape());
    let mut out = String::new();
    let mut row = vec![0.0f32; width];
    let xs: Vec<f32> = (0..width)
        .map(|i| (-1.2 + 2.4 * (i as f64 + 0.5) / width as f64) as f32)
        .collect();
    let zs = vec![z as f32; width];
    for j in 0..height {
        let y = (1.2 - 2.4 * (j as f64 + 0.5) / height as f64) as f32;
        let ys = vec![y; width];
        eval.eval(&xs, &ys, &zs, t as f32, &mut row);
        out.extend(row.iter().map(|&v| if v >= 0.0 { '#' } else { '.' }));
        out.push('\n');
    }
    out
}
