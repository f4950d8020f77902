//! Prints the thesis's central claim as Markdown tables: for each reference model and each
//! object of the FVRML scenes, the bytes of its signed create op and of a sculpting session's
//! edit ops, against the binary STL and GLB of its octree mesh and the mesh delta of each edit.
//!
//! ```text
//! cargo run -p tests --release --example footprint -- [--depths 6,7] [--only sphere,...] [--edits 20] [--poses 16] [--seed 7]
//! ```

use std::process::ExitCode;

use tests::footprint::{
    Footprint, FootprintError, SessionSpec, measure, model_subjects, scene_subjects,
};

/// Command-line options.
struct Options {
    depths: Vec<u8>,
    /// Subject names to measure (all when empty).
    only: Vec<String>,
    session: SessionSpec,
}

fn parse_args() -> Result<Options, String> {
    let mut options = Options {
        depths: vec![6, 7],
        only: Vec::new(),
        session: SessionSpec {
            n_edits: 20,
            poses_per_stroke: 16,
            seed: 7,
        },
    };
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let value = args.next().ok_or(format!("{flag} needs a value"))?;
        let bad = |e: std::num::ParseIntError| format!("{flag} {value}: {e}");
        match flag.as_str() {
            "--depths" => {
                options.depths = value
                    .split(',')
                    .map(|d| d.parse::<u8>().map_err(bad))
                    .collect::<Result<_, _>>()?;
            }
            "--only" => options.only = value.split(',').map(str::to_owned).collect(),
            "--edits" => options.session.n_edits = value.parse().map_err(bad)?,
            "--poses" => options.session.poses_per_stroke = value.parse().map_err(bad)?,
            "--seed" => options.session.seed = value.parse().map_err(bad)?,
            _ => return Err(format!("unknown option {flag}")),
        }
    }
    Ok(options)
}

fn ratio(a: usize, b: usize) -> String {
    if b == 0 {
        "-".to_owned()
    } else {
        format!("{:.0}", a as f64 / b as f64)
    }
}

fn print_tables(footprints: &[Footprint], session: &SessionSpec) {
    println!("Create op against the mesh of the object as created:\n");
    println!(
        "| object | depth | create op B | triangles | vertices | STL B | GLB B | STL / op | GLB / op |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for f in footprints {
        let m = &f.base_mesh;
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            f.name,
            f.depth,
            f.create_op_bytes,
            m.n_triangles,
            m.n_vertices,
            m.stl_bytes,
            m.glb_bytes,
            ratio(m.stl_bytes, f.create_op_bytes),
            ratio(m.glb_bytes, f.create_op_bytes),
        );
    }
    println!(
        "\nA session of {} strokes ({} poses each, seed {}): ops against meshes and mesh deltas:\n",
        session.n_edits, session.poses_per_stroke, session.seed
    );
    println!(
        "| object | depth | session ops B | final STL B | final GLB B | STL / ops | edit op B (mean) \
         | triangles changed per edit (mean) | delta B per edit (mean) | delta / edit op |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for f in footprints.iter().filter(|f| f.has_surface()) {
        let n = f.edits.len().max(1);
        let changed: usize = f.edits.iter().map(|e| e.n_added + e.n_removed).sum();
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1} |",
            f.name,
            f.depth,
            f.session_op_bytes(),
            f.final_mesh.stl_bytes,
            f.final_mesh.glb_bytes,
            ratio(f.final_mesh.stl_bytes, f.session_op_bytes()),
            f.edit_op_bytes() / n,
            changed / n,
            f.delta_bytes() / n,
            f.delta_bytes() as f64 / f.edit_op_bytes().max(1) as f64,
        );
    }
}

fn run(options: &Options) -> Result<(), FootprintError> {
    let mut subjects = model_subjects()?;
    subjects.extend(scene_subjects()?);
    let mut footprints = Vec::new();
    subjects.retain(|s| options.only.is_empty() || options.only.contains(&s.name));
    for subject in &subjects {
        for &depth in &options.depths {
            footprints.push(measure(subject, &options.session, depth)?);
        }
    }
    print_tables(&footprints, &options.session);
    let mut no_surface: Vec<&str> = footprints
        .iter()
        .filter(|f| !f.has_surface())
        .map(|f| f.name.as_str())
        .collect();
    no_surface.dedup();
    if !no_surface.is_empty() {
        println!("\nNo surface inside the box (left out of the session table): {no_surface:?}");
    }
    Ok(())
}

fn main() -> ExitCode {
    let options = match parse_args() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("footprint: {e}");
            return ExitCode::from(2);
        }
    };
    match run(&options) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("footprint: {e}");
            ExitCode::FAILURE
        }
    }
}
