//! The command-line subcommands for headless use: `check`, `eval`, `slice`, `render`.

use anyhow::{Context as _, bail};
use fdsl::Function;
use fdsl::eval::{BulkEval, PointEval};

use crate::USAGE;

/// Runs one headless subcommand; `args[0]` names it.
pub fn run(args: &[String]) -> anyhow::Result<()> {
    let Some(command) = args.first() else {
        print!("{USAGE}");
        return Ok(());
    };
    match command.as_str() {
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
        "render" => render_command(&args[1..]),
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

/// `sculpt render <scene.wrl> --out <dir> [--size WxH] [--depth N] [--t SECS]`: loads the
/// FVRML file (local `Inline`s relative to it), pictures it from the default views with
/// `render::snapshot` and writes `<dir>/<file stem>_<view>.png`, printing what it drew and
/// wrote. Load errors are reported with their file, line and column.
fn render_command(args: &[String]) -> anyhow::Result<()> {
    use fdsl::fvrml::{self, LoadOptions, MAX_FILE_BYTES};
    use render::snapshot::{SnapshotSettings, snapshot};
    use std::path::{Path, PathBuf};

    let mut settings = SnapshotSettings::default();
    let (mut scene_path, mut out_dir) = (None, None);
    let mut rest = args.iter();
    while let Some(arg) = rest.next() {
        let mut value = |name: &str| rest.next().with_context(|| format!("{name} needs a value"));
        match arg.as_str() {
            "--out" => out_dir = Some(PathBuf::from(value("--out")?)),
            "--size" => {
                let v = value("--size")?;
                let (w, h) = v
                    .split_once('x')
                    .with_context(|| format!("--size `{v}` is not WxH"))?;
                settings.width = w.parse().with_context(|| format!("bad width `{w}`"))?;
                settings.height = h.parse().with_context(|| format!("bad height `{h}`"))?;
            }
            "--depth" => {
                let v = value("--depth")?;
                settings.depth = v.parse().with_context(|| format!("bad depth `{v}`"))?;
            }
            "--t" => {
                let v = value("--t")?;
                settings.t_secs = v.parse().with_context(|| format!("bad time `{v}`"))?;
            }
            flag if flag.starts_with("--") => bail!("unknown option `{flag}`\n\n{USAGE}"),
            path if scene_path.is_none() => scene_path = Some(PathBuf::from(path)),
            extra => bail!("unexpected argument `{extra}`\n\n{USAGE}"),
        }
    }
    let scene_path = scene_path.context("give a scene file (.wrl)")?;
    let out_dir = out_dir.context("give an output directory with --out")?;
    let read = |path: &Path| -> Result<String, String> {
        let len = std::fs::metadata(path)
            .map_err(|e| format!("{}: {e}", path.display()))?
            .len();
        if len > MAX_FILE_BYTES as u64 {
            return Err(format!(
                "{}: {len} bytes, more than the limit of {MAX_FILE_BYTES}",
                path.display()
            ));
        }
        std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))
    };
    let text = read(&scene_path).map_err(anyhow::Error::msg)?;
    let dir = scene_path.parent().unwrap_or(Path::new("")).to_path_buf();
    let mut resolve = |inline: &str| read(&dir.join(inline));
    let shown = scene_path.display().to_string();
    let located = |issue: &fvrml::Issue| {
        let file = issue.location.file.as_deref().unwrap_or(&shown);
        let severity = if issue.is_error() { "error" } else { "warning" };
        let (line, column) = (issue.location.line, issue.location.column);
        format!("{file}:{line}:{column}: {severity}: {}", issue.message)
    };
    let loaded = fvrml::load(&text, &LoadOptions::default(), &mut resolve).map_err(|e| {
        let errors: Vec<String> = e.errors().map(located).collect();
        anyhow::anyhow!("{}\n{shown}: cannot load the scene", errors.join("\n"))
    })?;
    for w in &loaded.warnings {
        eprintln!("{}", located(w));
    }
    let (images, objects) = snapshot(&loaded.scene, &settings)?;
    for o in &objects {
        let name = if o.name.is_empty() {
            "(unnamed)"
        } else {
            &o.name
        };
        let drawn = format!("{} triangles, {} force arrows", o.n_triangles, o.n_arrows);
        match &o.skipped {
            Some(why) => println!("object {} {name}: {drawn}; not drawn: {why}", o.id.0),
            None => println!("object {} {name}: {drawn}", o.id.0),
        }
    }
    if objects.is_empty() {
        println!("the scene has no objects to draw");
    }
    std::fs::create_dir_all(&out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    let stem = scene_path
        .file_stem()
        .map_or("scene".into(), |s| s.to_string_lossy());
    for (view, image) in images {
        let path = out_dir.join(format!("{stem}_{view}.png"));
        image.save_png(&path)?;
        println!(
            "wrote {} ({}x{}, view {view}, t = {:?} s)",
            path.display(),
            image.width,
            image.height,
            settings.t_secs
        );
    }
    Ok(())
}
