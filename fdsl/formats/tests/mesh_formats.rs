//! `formats::mesh` readers and writers: round trips of random meshes through every format, the
//! sample files in `tests/data/meshes/`, and hostile inputs (every truncation of a valid file,
//! lying headers, out-of-range offsets and indices, huge numbers, random and mutated bytes),
//! each of which must be an error with a location, never a panic.
#![allow(
    clippy::unwrap_used,
    reason = "test helpers unwrap what a test expects to succeed"
)]

use formats::mesh::glb::{self, GlbError};
use formats::mesh::obj::{self, ObjError};
use formats::mesh::stl::{self, StlError};
use formats::mesh::{MeshFormat, ReadError};
use glam::DVec3;
use model::mesh::{MAX_MESH_TRIANGLES, TriMesh, shapes};
use proptest::prelude::*;

const CUBE_ASCII_STL: &[u8] = include_bytes!("../../../tests/data/meshes/cube_ascii.stl");
const CUBE_BINARY_STL: &[u8] = include_bytes!("../../../tests/data/meshes/cube_binary.stl");
const CUBE_OBJ: &[u8] = include_bytes!("../../../tests/data/meshes/cube.obj");
const ICOSPHERE_GLB: &[u8] = include_bytes!("../../../tests/data/meshes/icosphere.glb");

fn unit_box() -> TriMesh {
    shapes::cube(DVec3::splat(-1.0), DVec3::splat(1.0))
}

fn written(mesh: &TriMesh, format: MeshFormat) -> Vec<u8> {
    let mut out = Vec::new();
    format.write(mesh, &mut out);
    out
}

/// A GLB container around `json` and, when given, a binary chunk.
fn glb_file(json: &str, bin: Option<&[u8]>) -> Vec<u8> {
    let mut json = json.as_bytes().to_vec();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut chunks = Vec::new();
    chunks.extend_from_slice(&(json.len() as u32).to_le_bytes());
    chunks.extend_from_slice(b"JSON");
    chunks.extend_from_slice(&json);
    if let Some(bin) = bin {
        let mut bin = bin.to_vec();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        chunks.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        chunks.extend_from_slice(b"BIN\0");
        chunks.extend_from_slice(&bin);
    }
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(12 + chunks.len() as u32).to_le_bytes());
    out.extend_from_slice(&chunks);
    out
}

/// The JSON of one triangle primitive over accessor 0 (positions) and, if `indices`, 1.
fn gltf_json(accessors: &str, buffer_views: &str, buffer_bytes: usize, indices: bool) -> String {
    let indices = if indices { r#","indices":1"# } else { "" };
    format!(
        r#"{{"asset":{{"version":"2.0"}},"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}{indices}}}]}}],"buffers":[{{"byteLength":{buffer_bytes}}}],"bufferViews":[{buffer_views}],"accessors":[{accessors}]}}"#
    )
}

/// Four tetrahedron corners as f32 bytes, each followed by a 12-byte normal (stride 24).
fn interleaved_tetrahedron() -> (Vec<u8>, [[f32; 3]; 4]) {
    let corners = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let mut bin = Vec::new();
    for c in corners {
        for v in c.into_iter().chain([0.5, 0.5, 0.5]) {
            bin.extend_from_slice(&f32::to_le_bytes(v));
        }
    }
    (bin, corners)
}

const TETRAHEDRON: [[u32; 3]; 4] = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];

fn glb_err(bytes: &[u8]) -> GlbError {
    match glb::read(bytes) {
        Ok(mesh) => panic!("read {mesh:?}"),
        Err(e) => e,
    }
}

fn invalid_path(e: &GlbError) -> &str {
    match e {
        GlbError::Invalid { path, .. } => path,
        other => panic!("not an Invalid error: {other}"),
    }
}

#[test]
fn sample_files_read_as_the_box_and_the_sphere() {
    let cube = unit_box();
    assert_eq!(obj::read(CUBE_OBJ).unwrap(), cube);
    let from_ascii = stl::read(CUBE_ASCII_STL).unwrap();
    assert_eq!(from_ascii, cube.welded());
    assert!(from_ascii.is_closed());
    assert_eq!(stl::read(CUBE_BINARY_STL).unwrap(), cube.welded());
    let sphere = glb::read(ICOSPHERE_GLB).unwrap();
    assert_eq!(sphere, shapes::icosphere(1.0, 1));
    assert!(sphere.is_closed());
    assert_eq!(
        MeshFormat::from_extension("GLB")
            .unwrap()
            .read(ICOSPHERE_GLB),
        Ok(sphere)
    );
    assert_eq!(MeshFormat::from_extension("ply"), None);
}

/// The binary sample files are what the writers produce; `UPDATE_SNAPSHOTS=1` rewrites them.
#[test]
fn writers_reproduce_the_binary_sample_files() {
    let cases = [
        (
            written(&unit_box(), MeshFormat::StlBinary),
            CUBE_BINARY_STL,
            "cube_binary.stl",
        ),
        (
            written(&shapes::icosphere(1.0, 1), MeshFormat::Glb),
            ICOSPHERE_GLB,
            "icosphere.glb",
        ),
    ];
    for (bytes, checked_in, name) in cases {
        if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../tests/data/meshes")
                .join(name);
            std::fs::write(&path, &bytes).unwrap();
        } else {
            assert!(
                bytes == checked_in,
                "{name} differs from the writer's output"
            );
        }
    }
}

#[test]
fn glb_written_by_fdsl_is_plain_gltf() {
    let bytes = written(&unit_box(), MeshFormat::Glb);
    assert_eq!(&bytes[..4], b"glTF");
    assert_eq!(
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize,
        bytes.len()
    );
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    assert!(json_len.is_multiple_of(4));
    let json: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    assert_eq!(json["asset"]["version"], "2.0");
    for k in 0..3 {
        assert_eq!(json["accessors"][0]["min"][k].as_f64(), Some(-1.0));
        assert_eq!(json["accessors"][0]["max"][k].as_f64(), Some(1.0));
    }
    assert_eq!(json["accessors"][1]["count"], 36);
    assert_eq!(json["scenes"][0]["nodes"][0], 0);
    // A mesh without triangles is an asset without meshes.
    let empty = TriMesh::new(vec![[1.0, 2.0, 3.0]], vec![]).unwrap();
    let back = glb::read(&written(&empty, MeshFormat::Glb)).unwrap();
    assert!(back.is_empty() && back.positions().is_empty());
}

#[test]
fn glb_reads_interleaved_positions_small_indices_and_several_primitives() {
    let (mut bin, corners) = interleaved_tetrahedron();
    let indices_u16_at = bin.len();
    for i in TETRAHEDRON.as_flattened() {
        bin.extend_from_slice(&(*i as u16).to_le_bytes());
    }
    let indices_u8_at = bin.len();
    bin.extend(TETRAHEDRON.as_flattened().iter().map(|&i| i as u8));
    let n = bin.len();
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},
        "meshes":[{{"primitives":[
            {{"attributes":{{"POSITION":0,"NORMAL":3}},"indices":1,"mode":4}},
            {{"attributes":{{"POSITION":0}},"indices":2}}]}},
            {{"primitives":[{{"attributes":{{"POSITION":4}}}}]}}],
        "buffers":[{{"byteLength":{n}}}],
        "bufferViews":[
            {{"buffer":0,"byteLength":96,"byteStride":24}},
            {{"buffer":0,"byteOffset":{indices_u16_at},"byteLength":24}},
            {{"buffer":0,"byteOffset":{indices_u8_at},"byteLength":12}},
            {{"buffer":0,"byteLength":72}}],
        "accessors":[
            {{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3"}},
            {{"bufferView":1,"componentType":5123,"count":12,"type":"SCALAR"}},
            {{"bufferView":2,"componentType":5121,"count":12,"type":"SCALAR"}},
            {{"bufferView":0,"byteOffset":12,"componentType":5126,"count":4,"type":"VEC3"}},
            {{"bufferView":3,"componentType":5126,"count":6,"type":"VEC3"}}],
        "nodes":[{{"mesh":0,"translation":[5,0,0]}}],
        "extensionsUsed":[]}}"#
    );
    let mesh = glb::read(&glb_file(&json, Some(&bin))).unwrap();
    // Two indexed copies of the tetrahedron, then two triangles from the first six floats
    // (stride 12) of the interleaved data, read as positions.
    assert_eq!(mesh.positions().len(), 4 + 4 + 6);
    assert_eq!(&mesh.positions()[..4], &corners);
    assert_eq!(&mesh.positions()[4..8], &corners);
    assert_eq!(&mesh.triangles()[..4], &TETRAHEDRON);
    assert_eq!(mesh.triangles()[4], [4, 6, 5]);
    assert_eq!(&mesh.triangles()[8..], &[[8, 9, 10], [11, 12, 13]]);
}

#[test]
fn stl_detects_binary_and_ascii() {
    // A binary file whose header starts with `solid`, as many exporters write.
    let mut bytes = written(&unit_box(), MeshFormat::StlBinary);
    bytes[..11].copy_from_slice(b"solid cube ");
    assert_eq!(stl::read(&bytes).unwrap(), unit_box().welded());
    // ... and the same with a wrong count is read as ASCII and fails with a line.
    bytes[80] = 13;
    assert!(matches!(
        stl::read(&bytes),
        Err(StlError::Syntax { line: 1, .. })
    ));
    assert_eq!(
        stl::read(b"").unwrap_err(),
        StlError::TooShort { len: 0 },
        "empty"
    );
    let empty = stl::read(b"solid empty\nendsolid empty\n").unwrap();
    assert!(empty.is_empty());
    // Two solids in one file (here the same twice, so every edge is used four times).
    let one = written(&unit_box(), MeshFormat::StlAscii);
    let mut two = one.clone();
    two.extend_from_slice(&one);
    let twice = stl::read(&two).unwrap();
    assert_eq!(twice.triangles().len(), 24);
    assert_eq!(twice.positions().len(), 8);
    assert!(!twice.is_closed());
}

#[test]
fn stl_errors_say_where() {
    let mut claims_all = vec![0u8; 84];
    claims_all[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
    assert_eq!(
        stl::read(&claims_all).unwrap_err(),
        StlError::LengthMismatch {
            n_triangles: u32::MAX,
            expected_len: 84 + 50 * u64::from(u32::MAX),
            len: 84,
        }
    );
    // A count that matches the length but exceeds the limit is refused before reading.
    let n = MAX_MESH_TRIANGLES as u32 + 1;
    let mut over_limit = vec![0u8; 84 + 50 * n as usize];
    over_limit[80..84].copy_from_slice(&n.to_le_bytes());
    assert_eq!(
        stl::read(&over_limit).unwrap_err(),
        StlError::TooManyTriangles { n_triangles: n }
    );
    let mut nan = written(&unit_box(), MeshFormat::StlBinary);
    nan[84 + 50 + 12 + 4..84 + 50 + 12 + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    assert_eq!(
        stl::read(&nan).unwrap_err(),
        StlError::NotFinite {
            offset: 84 + 50 + 16
        }
    );
    let cases: [(&str, &str); 6] = [
        (
            "solid x\nfacet normal 0 0 1\n outer loop\n  vertex 1 2\n  endloop",
            "5:3: expected a coordinate, found `endloop`",
        ),
        (
            "solid x\nfacet normal 0 0 1\n outer loop\n  vertex 1 2 inf\n",
            "4:14: a coordinate `inf` is not a finite number",
        ),
        (
            "solid x\nfacet normal 0 0 1\n",
            "3:1: the file ends where `outer` was expected",
        ),
        (
            "solid x\n  facets",
            "2:3: expected `facet` or `endsolid`, found `facets`",
        ),
        (
            "solid x\nendsolid x\nsoup",
            "3:1: expected `solid`, found `soup`",
        ),
        (
            "solid x\nfacet normal 0 0 1\n outer loop\n  vertex 1 2 3\n",
            "5:1: the file ends where `vertex` was expected",
        ),
    ];
    for (text, want) in cases {
        assert_eq!(
            stl::read(text.as_bytes()).unwrap_err().to_string(),
            want,
            "{text:?}"
        );
    }
}

#[test]
fn obj_corners_may_name_texture_and_normal_indices() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1/1 2/2 3/3\nf 1//1 2//1 4//1\nf -1/1/1 -2/-1/1 -3//-2\n";
    let mesh = obj::read(text.as_bytes()).expect("valid corners");
    assert_eq!(mesh.triangles(), &[[0, 1, 2], [0, 1, 3], [3, 2, 1]]);
}

#[test]
fn obj_errors_say_where() {
    let cases: [(&str, &str); 13] = [
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n",
            "4:7: vertex indices count from 1",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
            "4:7: vertex 4 is not defined; there are 3 so far",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n",
            "4:3: vertex -4 is not defined; there are 3",
        ),
        (
            "v 0 0 0\nf 1 2 3\nv 1 0 0\nv 0 1 0\n",
            "2:5: vertex 2 is not defined; there are 1 so far",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999999\n",
            "4:7: vertex 99999999999999999999999999 is not defined",
        ),
        (
            "v 1e999 0 0\n",
            "1:3: the coordinate `1e999` is not a finite number",
        ),
        (
            "v 1 2\n",
            "1:6: expected a coordinate, found the end of the line",
        ),
        ("v 1 two 3\n", "1:5: expected a coordinate, found `two`"),
        (
            "v 0 0 0\nv 1 0 0\n  f 1 2 # a comment\n",
            "3:3: a face needs three corners at least, this one has 2",
        ),
        // Two faces run together by a damaged newline are not one larger face.
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3/f 2 3 1\n",
            "4:7: expected a vertex index, found `3/f`",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n",
            "4:3: expected a vertex index, found `1/1/1/1`",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/ 2 3\n",
            "4:3: expected a vertex index, found `1/`",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/2/3 x/1 3\n",
            "4:9: expected a vertex index, found `x/1`",
        ),
    ];
    for (text, want) in cases {
        let got = obj::read(text.as_bytes()).unwrap_err().to_string();
        assert!(got.starts_with(want), "{text:?}: {got}");
    }
    assert!(matches!(
        obj::read(b"v 0 0 0\nf 1 1 0").unwrap_err(),
        ObjError::ZeroIndex { line: 2, column: 7 }
    ));
    // Comments, blank lines, unknown directives and a missing final newline are fine.
    let mesh =
        obj::read(b"# hi\n\nfoo bar\nv 0 0 0\nv 1 0 0\nv 0 1 0\r\nvp 1 2\nf -3 -2 -1").unwrap();
    assert_eq!(mesh.triangles(), &[[0, 1, 2]]);
}

#[test]
fn glb_errors_name_the_json_path() {
    let (bin, _) = interleaved_tetrahedron();
    let views = r#"{"buffer":0,"byteLength":96,"byteStride":24}"#;
    let positions = |extra: &str| {
        format!(r#"{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3"{extra}}}"#)
    };
    let read = |accessors: &str, views: &str, buffer_bytes: usize| {
        glb_err(&glb_file(
            &gltf_json(accessors, views, buffer_bytes, false),
            Some(&bin),
        ))
    };
    // Out-of-range offsets and huge counts, with and without overflow.
    let huge_offset = positions(r#","byteOffset":18446744073709551615"#);
    assert_eq!(
        invalid_path(&read(&huge_offset, views, 96)),
        "accessors[0].count"
    );
    let huge_count = r#"{"bufferView":0,"componentType":5126,"count":1099511627776,"type":"VEC3"}"#;
    assert_eq!(
        invalid_path(&read(huge_count, views, 96)),
        "accessors[0].count"
    );
    let max_count =
        r#"{"bufferView":0,"componentType":5126,"count":18446744073709551615,"type":"VEC3"}"#;
    assert_eq!(
        invalid_path(&read(max_count, views, 96)),
        "accessors[0].count"
    );
    let view_past_buffer = r#"{"buffer":0,"byteOffset":18446744073709551615,"byteLength":96}"#;
    assert_eq!(
        invalid_path(&read(&positions(""), view_past_buffer, 96)),
        "bufferViews[0]"
    );
    assert_eq!(
        invalid_path(&read(&positions(""), views, 1 << 20)),
        "buffers[0].byteLength"
    );
    let bad_stride = r#"{"buffer":0,"byteLength":96,"byteStride":8}"#;
    assert_eq!(
        invalid_path(&read(&positions(""), bad_stride, 96)),
        "bufferViews[0].byteStride"
    );
    assert_eq!(
        invalid_path(&read(&positions(r#","sparse":{"count":1}"#), views, 96)),
        "accessors[0].sparse"
    );
    let ints = r#"{"bufferView":0,"componentType":5125,"count":4,"type":"VEC3"}"#;
    assert_eq!(invalid_path(&read(ints, views, 96)), "accessors[0]");
    let missing_view = r#"{"buffer":0,"byteLength":96,"byteStride":24}"#;
    let wrong_view = r#"{"bufferView":7,"componentType":5126,"count":4,"type":"VEC3"}"#;
    assert_eq!(
        invalid_path(&read(wrong_view, missing_view, 96)),
        "bufferViews[7]"
    );
    // Four positions without indices do not make whole triangles.
    assert_eq!(
        invalid_path(&read(&positions(""), views, 96)),
        "meshes[0].primitives[0].attributes.POSITION"
    );
    // An index past the positions, and an index accessor of the wrong type.
    let mut with_indices = bin.clone();
    with_indices.extend_from_slice(&[0, 1, 4, 0]);
    let index_views = format!(r#"{views},{{"buffer":0,"byteOffset":96,"byteLength":3}}"#);
    let index_accessors = |kind: &str| {
        format!(
            r#"{},{{"bufferView":1,"componentType":{kind},"count":3,"type":"SCALAR"}}"#,
            positions("")
        )
    };
    let json = gltf_json(&index_accessors("5121"), &index_views, 100, true);
    let e = glb_err(&glb_file(&json, Some(&with_indices)));
    assert_eq!(invalid_path(&e), "accessors[1]");
    assert!(
        e.to_string()
            .contains("index 2 is 4, but the primitive has 4 positions"),
        "{e}"
    );
    let json = gltf_json(&index_accessors("5126"), &index_views, 100, true);
    let e = glb_err(&glb_file(&json, Some(&with_indices)));
    assert_eq!(invalid_path(&e), "accessors[1].componentType");
    // Modes other than triangles, missing positions, external buffers, other versions.
    let json = gltf_json(&positions(""), views, 96, false)
        .replace(r#""POSITION":0"#, r#""POSITION":0},"mode":1,"x":{"#);
    assert_eq!(
        invalid_path(&glb_err(&glb_file(&json, Some(&bin)))),
        "meshes[0].primitives[0].mode"
    );
    let json = gltf_json(&positions(""), views, 96, false).replace("POSITION", "NORMAL");
    assert_eq!(
        invalid_path(&glb_err(&glb_file(&json, Some(&bin)))),
        "meshes[0].primitives[0].attributes"
    );
    let json = gltf_json(&positions(""), views, 96, false).replace(
        r#""byteLength":96}"#,
        r#""byteLength":96,"uri":"data.bin"}"#,
    );
    assert_eq!(
        invalid_path(&glb_err(&glb_file(&json, Some(&bin)))),
        "bufferViews[0].buffer"
    );
    let json = gltf_json(&positions(""), views, 96, false).replace("2.0", "1.0");
    assert_eq!(
        invalid_path(&glb_err(&glb_file(&json, Some(&bin)))),
        "asset.version"
    );
    // A missing binary chunk is a buffer too short.
    let json = gltf_json(&positions(""), views, 96, false);
    assert_eq!(
        invalid_path(&glb_err(&glb_file(&json, None))),
        "buffers[0].byteLength"
    );
}

#[test]
fn glb_container_and_json_errors() {
    let good = written(&unit_box(), MeshFormat::Glb);
    let container_offset = |bytes: &[u8]| match glb_err(bytes) {
        GlbError::Container { offset, .. } => offset,
        other => panic!("{other}"),
    };
    let mut bad_magic = good.clone();
    bad_magic[0] = b'x';
    assert_eq!(container_offset(&bad_magic), 0);
    let mut bad_version = good.clone();
    bad_version[4] = 1;
    assert_eq!(container_offset(&bad_version), 4);
    let mut long_header = good.clone();
    long_header[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
    assert_eq!(container_offset(&long_header), 8);
    let mut long_chunk = good.clone();
    long_chunk[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
    assert_eq!(container_offset(&long_chunk), 12);
    let mut bin_first = good.clone();
    bin_first[16..20].copy_from_slice(b"BIN\0");
    assert_eq!(container_offset(&bin_first), 12);
    for (json, line, column) in [
        ("{\"asset\":{\"version\":\"2.0\"}", 1, 28),
        (
            "{\"asset\":{\"version\":\"2.0\"},\n\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":-1}}]}]}",
            2,
            53,
        ),
        ("{\"asset\":{\"version\":2}}", 1, 21),
        ("{\"meshes\":[]}", 1, 13),
        ("[1, 2, 3]", 1, 2),
    ] {
        match glb_err(&glb_file(json, None)) {
            GlbError::Json {
                line: l, column: c, ..
            } => {
                assert_eq!((l, c), (line, column), "{json}");
            }
            other => panic!("{json}: {other}"),
        }
    }
    let nested = format!(
        "{{\"asset\":{}1{}}}",
        "[".repeat(10_000),
        "]".repeat(10_000)
    );
    assert!(matches!(
        glb_err(&glb_file(&nested, None)),
        GlbError::Json { .. }
    ));
}

#[test]
fn every_truncation_of_a_binary_file_is_an_error() {
    for (name, bytes) in [
        ("binary STL", written(&unit_box(), MeshFormat::StlBinary)),
        ("GLB", written(&unit_box(), MeshFormat::Glb)),
    ] {
        let format = if name == "GLB" {
            MeshFormat::Glb
        } else {
            MeshFormat::StlBinary
        };
        assert!(format.read(&bytes).is_ok());
        for len in 0..bytes.len() {
            assert!(
                format.read(&bytes[..len]).is_err(),
                "{name} cut to {len} bytes was read"
            );
        }
    }
}

#[test]
fn every_truncation_of_an_ascii_stl_fails_until_endsolid() {
    let bytes = written(&unit_box(), MeshFormat::StlAscii);
    let full = stl::read(&bytes).unwrap();
    let endsolid = bytes.windows(8).rposition(|w| w == b"endsolid").unwrap();
    for len in 0..bytes.len() {
        match stl::read(&bytes[..len]) {
            Ok(mesh) => {
                assert!(len >= endsolid + 8, "cut to {len} bytes was read");
                assert_eq!(mesh, full);
            }
            Err(e) => {
                assert!(len < endsolid + 8, "cut to {len}: {e}");
                assert!(
                    matches!(e, StlError::Syntax { .. } | StlError::TooShort { .. }),
                    "{e}"
                );
            }
        }
    }
}

#[test]
fn every_truncation_of_an_obj_is_an_error_or_a_prefix() {
    let full = obj::read(CUBE_OBJ).unwrap();
    let mut n_errors = 0;
    for len in 0..CUBE_OBJ.len() {
        match obj::read(&CUBE_OBJ[..len]) {
            Ok(mesh) => {
                assert!(
                    full.triangles().starts_with(mesh.triangles()),
                    "cut to {len}"
                );
                // The last vertex may have lost digits.
                let n = mesh.positions().len().saturating_sub(1);
                assert_eq!(
                    &mesh.positions()[..n],
                    &full.positions()[..n],
                    "cut to {len}"
                );
            }
            Err(_) => n_errors += 1,
        }
    }
    assert!(n_errors > 20, "{n_errors}");
}

/// Meshes of up to 24 vertices (coordinates mixing small integers, zeros of both signs and
/// arbitrary finite floats of any magnitude) and 40 triangles, which may repeat vertices.
fn random_mesh() -> impl Strategy<Value = TriMesh> {
    let coordinate = prop_oneof![
        (-4i8..4).prop_map(f32::from),
        Just(-0.0f32),
        any::<f32>().prop_filter("finite", |x| x.is_finite()),
        -1e3f32..1e3,
    ];
    (1usize..24)
        .prop_flat_map(move |n| {
            let positions = prop::collection::vec(
                [coordinate.clone(), coordinate.clone(), coordinate.clone()],
                n,
            );
            let triangles = prop::collection::vec([0..n as u32, 0..n as u32, 0..n as u32], 1..40);
            (positions, triangles)
        })
        .prop_map(|(positions, triangles)| TriMesh::new(positions, triangles).unwrap())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn every_format_round_trips(mesh in random_mesh()) {
        for format in [MeshFormat::Obj, MeshFormat::Glb] {
            let back = format.read(&written(&mesh, format)).unwrap();
            prop_assert_eq!(&back, &mesh, "{:?}", format);
            // Exactly, down to the sign of zero.
            let bits = |m: &TriMesh| m.positions().iter().map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
            prop_assert_eq!(bits(&back), bits(&mesh));
        }
        // STL stores corners, so what comes back is the welded mesh.
        for format in [MeshFormat::StlBinary, MeshFormat::StlAscii] {
            let back = format.read(&written(&mesh, format)).unwrap();
            prop_assert_eq!(&back, &mesh.welded(), "{:?}", format);
        }
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        for format in [MeshFormat::StlBinary, MeshFormat::Obj, MeshFormat::Glb] {
            let _ = format.read(&bytes);
        }
        // And with the magic numbers that get past the first checks.
        let mut glb = b"glTF\x02\0\0\0".to_vec();
        glb.extend_from_slice(&(bytes.len() as u32 + 12).to_le_bytes());
        glb.extend_from_slice(&bytes);
        let _ = glb::read(&glb);
        let mut ascii = b"solid x\n".to_vec();
        ascii.extend_from_slice(&bytes);
        let _ = stl::read(&ascii);
    }

    #[test]
    fn mutated_files_never_panic(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
    ) {
        for format in [MeshFormat::StlBinary, MeshFormat::StlAscii, MeshFormat::Obj, MeshFormat::Glb] {
            let mut bytes = written(&shapes::icosphere(1.0, 0), format);
            for (at, value) in &edits {
                let i = at.index(bytes.len());
                bytes[i] = *value;
            }
            if let Ok(mesh) = format.read(&bytes) {
                prop_assert!(mesh.triangles().len() <= 20);
            }
        }
    }
}

#[test]
fn read_errors_name_their_format() {
    let e: ReadError = MeshFormat::Obj.read(b"f 1 2 3").unwrap_err();
    assert!(
        e.to_string()
            .starts_with("OBJ: 1:3: vertex 1 is not defined"),
        "{e}"
    );
    let e = MeshFormat::StlAscii.read(b"nonsense").unwrap_err();
    assert!(e.to_string().starts_with("STL: byte 0:"), "{e}");
    let e = MeshFormat::Glb.read(b"nonsense").unwrap_err();
    assert!(e.to_string().starts_with("glTF: byte 0:"), "{e}");
}

#[test]
fn deep_json_in_a_glb_reads_on_a_small_stack() {
    use testkit::stack::on_small_stack;
    // A value nobody reads is skipped by serde_json without recursion, however deep; where
    // the glTF types expect an object, nesting is a type error at once.
    let (bin, _) = interleaved_tetrahedron();
    let views = r#"{"buffer":0,"byteLength":96,"byteStride":24}"#;
    let accessors = r#"{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3"}"#;
    let file = |field: &str, depth: usize, open: &str, close: &str| {
        let value = format!("{}0{}", open.repeat(depth), close.repeat(depth));
        let json = gltf_json(accessors, views, 96, false);
        let json = format!(r#"{{"{field}":{value},{}"#, &json[1..]);
        glb_file(&json, Some(&bin))
    };
    on_small_stack(|| {
        for (open, close) in [("[", "]"), (r#"{"a":"#, "}")] {
            for depth in [127, 128, 100_000] {
                // The JSON reads; the mesh it describes is the error (4 corners, no indices).
                let e = glb::read(&file("extras", depth, open, close)).unwrap_err();
                assert!(matches!(e, GlbError::Invalid { .. }), "{e}");
                let e = glb::read(&file("asset", depth, "[", "]")).unwrap_err();
                assert!(matches!(e, GlbError::Json { .. }), "{e}");
            }
        }
    });
}
