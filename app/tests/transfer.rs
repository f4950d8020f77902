//! End to end: `sculpt import` brings scene and mesh files into a session's store as objects
//! (checked by opening the store with the engine), `sculpt export` writes a sculpted object
//! as closed meshes and as FVRML that read back, and hostile files are refused with their
//! location while the store's op file stays byte for byte as it was.
#![allow(
    clippy::unwrap_used,
    reason = "helpers outside #[test] fns unwrap process output"
)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use app::engine::{Engine, EngineConfig, lock, store};
use formats::mesh::MeshFormat;
use glam::DVec3;
use model::mesh::TriMesh;
use model::object::{Domain, Edit, EditOp, Formula, Geometry, ObjectData, Pose, ToolShape};
use model::scene::{ObjectId, Scene};
use replication::shape::ShapePayload;

fn sculpt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sculpt"))
        .args(args)
        .output()
        .unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn data(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/data")
        .join(relative)
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn arg(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// Runs `sculpt` and requires success, returning stdout.
fn ok(args: &[&str]) -> String {
    let run = sculpt(args);
    let (stdout, stderr) = (text(&run.stdout), text(&run.stderr));
    assert!(run.status.success(), "{args:?}\n{stdout}\n{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    stdout
}

/// Runs `sculpt` and requires a failure without a panic, returning stderr.
fn refused(args: &[&str]) -> String {
    let run = sculpt(args);
    let stderr = text(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{args:?}\n{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    stderr
}

/// An engine on `dir` that reaches no one.
fn engine(dir: &Path) -> Engine {
    Engine::start(EngineConfig::on_loopback(dir), app::clock::now().wall).unwrap()
}

/// The scene a store holds, read through the engine.
fn scene_of(dir: &Path) -> Scene {
    let engine = engine(dir);
    let scene = lock(engine.view()).scene().clone();
    engine.shutdown();
    scene
}

fn object_named(scene: &Scene, name: &str) -> ObjectId {
    let found: Vec<ObjectId> = scene
        .objects()
        .filter(|(_, o)| o.object.data().name == name)
        .map(|(id, _)| id)
        .collect();
    assert_eq!(found.len(), 1, "one object named {name}");
    found[0]
}

fn read_mesh(path: &Path) -> TriMesh {
    let extension = path.extension().unwrap().to_str().unwrap();
    let format = MeshFormat::from_extension(extension).unwrap();
    format.read(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn import_and_export_have_help() {
    for sub in ["import", "export"] {
        let help = ok(&[sub, "--help"]);
        assert!(help.contains("Usage: sculpt"), "{help}");
        assert!(help.contains("--store"), "{help}");
    }
    assert!(ok(&["--help"]).contains("import"));
    let no_files = sculpt(&["import", "--store", "x"]);
    assert_eq!(
        no_files.status.code(),
        Some(2),
        "{}",
        text(&no_files.stderr)
    );
}

#[test]
fn each_mesh_file_becomes_an_object_with_the_files_signed_distance() {
    let dir = scratch("transfer_meshes");
    let store_dir = dir.join("store");
    let mut files = [
        "meshes/cube.obj",
        "meshes/cube_binary.stl",
        "meshes/cube_ascii.stl",
        "meshes/icosphere.glb",
    ]
    .map(data)
    .to_vec();
    // 20,480 triangles: about 240 KB, authored in parts.
    let big = dir.join("big_ball.glb");
    let mut bytes = Vec::new();
    formats::mesh::glb::write(&model::mesh::shapes::icosphere(0.8, 5), &mut bytes);
    assert!(bytes.len() > 10 * replication::payload::MAX_PAYLOAD_BYTES);
    std::fs::write(&big, &bytes).unwrap();
    files.push(big);
    let mut args = vec!["import", "--store", arg(&store_dir)];
    args.extend(files.iter().map(|f| arg(f)));
    let stdout = ok(&args);
    assert_eq!(
        stdout.lines().count(),
        files.len(),
        "one line per object: {stdout}"
    );
    let scene = scene_of(&store_dir);
    assert_eq!(scene.len(), files.len(), "{stdout}");
    for file in &files {
        let stem = file.file_stem().unwrap().to_str().unwrap();
        let id = object_named(&scene, stem);
        assert!(
            stdout.contains(&format!("object {} \"{stem}\"", id.0)),
            "{stdout}"
        );
        let expected = read_mesh(file);
        assert!(expected.is_closed(), "{stem}");
        let object = scene.object(id).unwrap();
        let domain = object.data().geometry.as_ref().unwrap().domain.unwrap();
        let (lo, size) = (domain.aabb().lo, domain.size);
        let mut sampler = object.sampler();
        // A 5^3 grid over the domain: inside, on the faces, outside the mesh. Where the
        // domain's own distance is the smaller, the domain clips the value: skip those.
        let mut n_compared = 0;
        for i in 0..125 {
            let f = DVec3::new((i % 5) as f64, (i / 5 % 5) as f64, (i / 25) as f64) / 4.0;
            let p = lo + size * f;
            let (got, want) = (sampler.value(p, 0.0), expected.signed_distance(p));
            if domain.signed_distance(p) > want {
                assert_eq!(got, want, "{stem} at {p}");
                n_compared += 1;
            }
        }
        assert!(n_compared > 100, "{stem}: {n_compared} points compared");
        assert!(
            sampler.value(expected.bounds().center(), 0.0) > 0.0,
            "{stem}"
        );
    }
}

#[test]
fn the_watermelon_scene_is_imported_as_its_object() {
    let dir = scratch("transfer_watermelon");
    let store_dir = dir.join("store");
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/watermelon.wrl");
    let stdout = ok(&["import", "--store", arg(&store_dir), arg(&file)]);
    assert!(
        stdout.contains("\"Watermelon\": implicit solid"),
        "{stdout}"
    );
    let scene = scene_of(&store_dir);
    assert_eq!(scene.len(), 1);
    let id = object_named(&scene, "Watermelon");
    let text = std::fs::read_to_string(&file).unwrap();
    let mut no_files = |url: &str| Err(format!("no {url}"));
    let loaded = formats::fvrml::load(&text, &Default::default(), &mut no_files).unwrap();
    let (_, expected) = loaded.scene.objects().next().unwrap();
    assert_eq!(scene.object(id).unwrap().data(), expected.object.data());
    // Importing again adds a second copy under new ids.
    ok(&["import", "--store", arg(&store_dir), arg(&file)]);
    assert_eq!(scene_of(&store_dir).len(), 2);
}

/// A store holding a ball carved by a ball at (1, 0, 0); returns the ball's id.
fn sculpted_ball(dir: &Path) -> ObjectId {
    let engine = engine(dir);
    let ids = lock(engine.view()).next_object();
    let object = ids.id();
    let data = ObjectData {
        name: "ball".into(),
        geometry: Some(Geometry::implicit_in(
            Formula::new("1-sqrt(x^2+y^2+z^2)").unwrap(),
            Domain::new(DVec3::ZERO, DVec3::splat(2.2)),
        )),
        ..ObjectData::default()
    };
    let create = ids.create(data, None);
    engine.author(create).unwrap().wait().unwrap();
    let carve = Edit::stamp(
        EditOp::Subtract,
        ToolShape::Sphere { radius: 0.5 },
        Pose::at(DVec3::X),
    );
    let edit = ShapePayload::edit(object, carve).expect("a valid edit");
    engine.author(edit).unwrap().wait().unwrap();
    engine.shutdown();
    ObjectId(object)
}

#[test]
fn a_sculpted_ball_exports_as_closed_meshes_and_as_fvrml() {
    let dir = scratch("transfer_export");
    let store_dir = dir.join("store");
    let id = sculpted_ball(&store_dir);
    for name in ["ball.stl", "ball.obj", "ball.glb"] {
        let out = dir.join(name);
        let stdout = ok(&[
            "export",
            "--store",
            arg(&store_dir),
            "--depth",
            "6",
            arg(&out),
        ]);
        assert!(stdout.contains(", closed)"), "{name}: {stdout}");
        assert!(
            stdout.contains("\"ball\"") && stdout.contains("1 edits"),
            "{stdout}"
        );
        let mesh = read_mesh(&out);
        assert!(mesh.is_closed(), "{name}");
        let n = mesh.triangles().len();
        assert!((1_000..200_000).contains(&n), "{name}: {n} triangles");
        // The carve shows: (0.8, 0, 0) was inside the ball and is now outside; the far
        // side is as it was.
        assert!(
            mesh.signed_distance(DVec3::new(0.8, 0.0, 0.0)) < 0.0,
            "{name}"
        );
        let inside = mesh.signed_distance(DVec3::new(-0.5, 0.0, 0.0));
        assert!((inside - 0.5).abs() < 0.05, "{name}: {inside}");
        assert!(
            mesh.signed_volume() > 3.0 && mesh.signed_volume() < 4.19,
            "{name}"
        );
    }
    // One object by the number the window shows.
    let one = dir.join("one.obj");
    let short = (id.0 & 0xffff_ffff).to_string();
    let stdout = ok(&[
        "export",
        "--store",
        arg(&store_dir),
        "--object",
        &short,
        "--depth",
        "5",
        arg(&one),
    ]);
    assert!(stdout.contains(&format!("object {}", id.0)), "{stdout}");
    assert!(read_mesh(&one).is_closed());

    let wrl = dir.join("ball.wrl");
    let stdout = ok(&["export", "--store", arg(&store_dir), arg(&wrl)]);
    assert!(!stdout.contains("edit histories"), "{stdout}");
    let text = std::fs::read_to_string(&wrl).unwrap();
    let mut no_files = |url: &str| Err(format!("no {url}"));
    let loaded = formats::fvrml::load(&text, &Default::default(), &mut no_files).unwrap();
    let (_, ball) = loaded.scene.objects().next().unwrap();
    assert_eq!(loaded.scene.len(), 1);
    assert_eq!(ball.object.data().name, "ball");
    // The carve is in the file: read back, (0.8, 0, 0) is outside the ball.
    let mut sampler = model::object::Sampler::new(std::sync::Arc::new(ball.object.clone()));
    assert!(sampler.value(DVec3::new(0.8, 0.0, 0.0), 0.0) < 0.0);
    assert!(sampler.value(DVec3::new(-0.5, 0.0, 0.0), 0.0) > 0.0);

    let missing = refused(&[
        "export",
        "--store",
        arg(&store_dir),
        "--object",
        "12345",
        arg(&dir.join("x.stl")),
    ]);
    assert!(
        missing.contains("no object 12345") && missing.contains("ball"),
        "{missing}"
    );
    let not_a_store = refused(&["export", "--store", arg(&dir), arg(&dir.join("x.stl"))]);
    assert!(not_a_store.contains("not a session store"), "{not_a_store}");
    assert!(!dir.join("x.stl").exists());
}

/// The bytes of the store's op file.
fn ops(store_dir: &Path) -> Vec<u8> {
    std::fs::read(store_dir.join(store::OPS_FILE)).unwrap()
}

#[test]
fn hostile_files_are_refused_with_their_location_and_author_nothing() {
    let dir = scratch("transfer_hostile");
    let store_dir = dir.join("store");
    ok(&[
        "import",
        "--store",
        arg(&store_dir),
        arg(&data("meshes/cube.obj")),
    ]);
    let before = ops(&store_dir);

    let stl = std::fs::read(data("meshes/cube_binary.stl")).unwrap();
    let truncated = dir.join("truncated.stl");
    std::fs::write(&truncated, &stl[..600]).unwrap();
    let obj = dir.join("index.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n").unwrap();
    let glb = std::fs::read(data("meshes/icosphere.glb")).unwrap();
    let needle = b"\"count\":42";
    let at = glb.windows(needle.len()).position(|w| w == needle);
    let at = at.expect("the sample's first accessor holds 42 vertices");
    let bad_accessor = dir.join("accessor.glb");
    let mut bytes = glb.clone();
    bytes[at..at + 10].copy_from_slice(b"\"count\":99");
    std::fs::write(&bad_accessor, &bytes).unwrap();

    for (file, location) in [
        (&truncated, "byte 80"),
        (&obj, "5:7"),
        (&bad_accessor, "accessors[0]"),
    ] {
        let stderr = refused(&["import", "--store", arg(&store_dir), arg(file)]);
        assert!(stderr.contains(arg(file)), "{stderr}");
        assert!(stderr.contains(location), "{location}: {stderr}");
        assert_eq!(ops(&store_dir), before, "{}", file.display());
    }
    // A good file before a bad one is not authored either.
    let icosphere = data("meshes/icosphere.glb");
    let good_then_bad = [
        "import",
        "--store",
        arg(&store_dir),
        arg(&icosphere),
        arg(&truncated),
    ];
    refused(&good_then_bad);
    assert_eq!(ops(&store_dir), before);
    assert_eq!(scene_of(&store_dir).len(), 1);
}

#[test]
fn an_inline_outside_the_files_folder_is_refused() {
    let dir = scratch("transfer_inline");
    let scenes = dir.join("scenes");
    std::fs::create_dir_all(scenes.join("parts")).unwrap();
    let ball = "#VRML V2.0 utf8\nFShape { geometry FGeometry { definition \"1-x^2-y^2-z^2\" \
                bboxSize 2 2 2 } }\n";
    std::fs::write(dir.join("outside.wrl"), ball).unwrap();
    std::fs::write(scenes.join("parts/inside.wrl"), ball).unwrap();
    let hostile = scenes.join("hostile.wrl");
    std::fs::write(
        &hostile,
        "#VRML V2.0 utf8\nInline { url \"../outside.wrl\" }\n",
    )
    .unwrap();
    let store_dir = dir.join("store");
    let stderr = refused(&["import", "--store", arg(&store_dir), arg(&hostile)]);
    assert!(stderr.contains("leaves the scene's folder"), "{stderr}");
    assert!(
        stderr.contains(&format!("{}:2:", hostile.display())),
        "{stderr}"
    );
    assert!(!store_dir.exists(), "a refused file opens no store");
    let wider = ["--inline-root", arg(&dir)];
    ok(&[
        &["import", "--store", arg(&store_dir), arg(&hostile)],
        &wider[..],
    ]
    .concat());
    assert_eq!(scene_of(&store_dir).len(), 1, "allowed by the user");

    let friendly = scenes.join("friendly.wrl");
    std::fs::write(
        &friendly,
        "#VRML V2.0 utf8\nInline { url \"parts/inside.wrl\" }\n",
    )
    .unwrap();
    ok(&["import", "--store", arg(&store_dir), arg(&friendly)]);
    assert_eq!(scene_of(&store_dir).len(), 2);
}

#[test]
fn a_scan_larger_than_an_op_is_imported_whole() {
    let dir = scratch("transfer_scan");
    let store_dir = dir.join("store");
    // A 48^3 ball of bytes (110,592 samples, seven ops' worth), raw, beside the scene.
    let n = 48usize;
    let samples: Vec<u8> = (0..n * n * n)
        .map(|i| {
            let c = |v: usize| v as f64 / (n - 1) as f64 * 2.0 - 1.0;
            let (x, y, z) = (c(i % n), c(i / n % n), c(i / (n * n)));
            (255.0 * (1.0 - (x * x + y * y + z * z).sqrt()).clamp(0.0, 1.0)) as u8
        })
        .collect();
    std::fs::write(dir.join("ball.raw"), &samples).unwrap();
    let scene = dir.join("scan.wrl");
    std::fs::write(
        &scene,
        format!(
            "#VRML V2.0 utf8\nDEF Scan FShape {{\n  grids [ FGrid {{ name \"ball\" size {n} {n} {n} \
             origin -1 -1 -1 spacing {s} {s} {s} url \"ball.raw\" }} ]\n  geometry FGeometry {{ \
             definition \"ball(x, y, z) - 0.5\" bboxSize 2 2 2 }}\n}}\n",
            s = 2.0 / (n - 1) as f64
        ),
    )
    .unwrap();
    let stdout = ok(&["import", "--store", arg(&store_dir), arg(&scene)]);
    assert_eq!(stdout.lines().count(), 1, "{stdout}");
    let scene = scene_of(&store_dir);
    let object = scene.object(object_named(&scene, "Scan")).unwrap();
    let grids = &object.data().grids;
    assert_eq!(grids.len(), 1);
    assert_eq!(grids[0].data().samples.len(), samples.len());
    let mut sampler = object.sampler();
    // The ball's value is 1 - r: inside the solid within r < 0.5. The centre falls between
    // samples 0.037 from it.
    let centre = sampler.value(DVec3::ZERO, 0.0);
    assert!((centre - 0.5).abs() < 0.05, "{centre}");
    assert!(sampler.value(DVec3::new(0.3, 0.0, 0.0), 0.0) > 0.1);
    assert!(sampler.value(DVec3::new(0.0, 0.7, 0.0), 0.0) < -0.1);
}
