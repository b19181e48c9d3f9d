//! Tests of `gltf`.

use super::*;
use std::path::PathBuf;
use std::process::Command;

/// The Node wrapper around the Khronos glTF-Validator (`npm ci --prefix tests/tools`).
const VALIDATOR_SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/tools/validate_gltf.js");

/// Axis-aligned box centred at `center`, 4 vertices per face with face normals, CCW outward.
fn box_mesh(center: [f32; 3], half: [f32; 3]) -> MeshData {
    let mut mesh = MeshData::default();
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            let (mut a, mut b) = ((axis + 1) % 3, (axis + 2) % 3);
            if sign < 0.0 {
                std::mem::swap(&mut a, &mut b);
            }
            let mut normal = [0.0; 3];
            normal[axis] = sign;
            let base = mesh.positions.len() as u32;
            for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                let mut p = center;
                p[axis] += sign * half[axis];
                p[a] += su * half[a];
                p[b] += sv * half[b];
                mesh.positions.push(p);
                mesh.normals.push(normal);
            }
            mesh.triangles.push([base, base + 1, base + 2]);
            mesh.triangles.push([base, base + 2, base + 3]);
        }
    }
    mesh
}

fn quat_y(angle: f32) -> [f32; 4] {
    let (s, c) = (angle / 2.0).sin_cos();
    [0.0, s, 0.0, c]
}

/// Child (a lid) listed before its parent (a base), both with box meshes; the child has
/// extras and is animated by a rotation and a translation animation.
fn sample_scene() -> Scene {
    let lid = Node {
        name: "lid".into(),
        parent: Some(1),
        translation: [0.0, 0.25, -0.1],
        rotation: quat_y(0.3),
        mesh: Some(box_mesh([0.0, 0.01, 0.1], [0.2, 0.01, 0.1])),
        color: [0.8, 0.2, 0.1, 1.0],
        extras: json!({
            "joint": { "type": "revolute", "axis": [1.0, 0.0, 0.0], "limits": [0.0, 1.57] }
        }),
    };
    let base = Node {
        name: "base".into(),
        parent: None,
        translation: [0.0, 0.0, 0.0],
        rotation: [0.0, 0.0, 0.0, 1.0],
        mesh: Some(box_mesh([0.0, 0.125, 0.0], [0.2, 0.125, 0.1])),
        color: [0.5, 0.5, 0.55, 1.0],
        extras: json!({ "part": 0 }),
    };
    let open = Animation {
        name: "lid_open".into(),
        node: 0,
        times: vec![0.0, 0.5, 1.0],
        translations: vec![],
        rotations: vec![quat_y(0.3), quat_y(0.8), quat_y(1.3)],
    };
    let slide = Animation {
        name: "lid_slide".into(),
        node: 0,
        times: vec![0.0, 2.0],
        translations: vec![[0.0, 0.25, -0.1], [0.0, 0.25, 0.1]],
        rotations: vec![],
    };
    Scene {
        nodes: vec![lid, base],
        animations: vec![open, slide],
        extras: json!({ "coordinates": "+Y up, metres, right-handed" }),
    }
}

fn plain_node(name: &str, parent: Option<usize>) -> Node {
    Node {
        name: name.into(),
        parent,
        translation: [0.0; 3],
        rotation: [0.0, 0.0, 0.0, 1.0],
        mesh: None,
        color: [1.0; 4],
        extras: Value::Null,
    }
}

/// A fresh directory per call (names are unique per test), removed by the caller.
fn temp_dir_for(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("physnap-gltf-test-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("create temp dir");
    dir
}

/// Runs the Khronos validator on `bytes`; returns its JSON report. Panics (never skips) when
/// Node.js or the validator package is unavailable.
fn validate_with_khronos(bytes: &[u8], name: &str) -> Value {
    let dir = temp_dir_for(name);
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write GLB");
    let output = Command::new("node")
        .arg(VALIDATOR_SCRIPT)
        .arg(&path)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run `node` ({e}): install Node.js and run \
                 `npm ci --prefix tests/tools` to install the glTF validator"
            )
        });
    let _ = std::fs::remove_dir_all(&dir);
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        matches!(output.status.code(), Some(0 | 1)),
        "glTF validator did not run ({}); run `npm ci --prefix tests/tools` \
         (or set NODE_PATH to a node_modules containing gltf-validator).\n\
         stderr: {stderr}\nstdout: {stdout}",
        output.status
    );
    let report: Value = serde_json::from_str(&stdout)
        .unwrap_or_else(|e| panic!("validator printed invalid JSON ({e}): {stdout}"));
    println!("{name}: {stdout}");
    report
}

fn assert_clean(report: &Value) {
    assert_eq!(report["numErrors"], 0, "validator errors: {report:#}");
    assert_eq!(report["numWarnings"], 0, "validator warnings: {report:#}");
}

/// Asserts that writing `scene` fails with an `InvalidScene` error for `field`; returns the
/// error message.
fn expect_invalid(scene: &Scene, field: &str) -> String {
    let err = match write_glb(scene) {
        Ok(_) => panic!("expected an error for {field}, but the scene was written"),
        Err(e) => e,
    };
    let GltfError::InvalidScene { field: got, .. } = &err else {
        panic!("expected InvalidScene for {field}, got {err:?}");
    };
    assert_eq!(got, field, "wrong field in error: {err}");
    let msg = err.to_string();
    assert!(
        msg.contains(field),
        "message does not name the field: {msg}"
    );
    msg
}

fn word(bytes: &[u8], offset: usize) -> u32 {
    u32::from_le_bytes(bytes[offset..offset + 4].try_into().unwrap())
}

#[test]
fn sample_scene_passes_khronos_validator() {
    let bytes = write_glb(&sample_scene()).expect("write");
    let report = validate_with_khronos(&bytes, "sample.glb");
    assert_clean(&report);
}

#[test]
fn khronos_validator_catches_corruption() {
    // Negative control: the validator pipeline must report real errors, not always pass.
    let mut bytes = write_glb(&sample_scene()).unwrap();
    let bin_data = 20 + word(&bytes, 12) as usize + 8;
    // First POSITION component of the first mesh, now far above the accessor's `max`.
    bytes[bin_data..bin_data + 4].copy_from_slice(&100.0f32.to_le_bytes());
    let report = validate_with_khronos(&bytes, "corrupted.glb");
    assert!(report["numErrors"].as_u64().unwrap() > 0, "{report:#}");
    let codes: Vec<&str> = report["messages"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|m| m["code"].as_str())
        .collect();
    assert!(codes.contains(&"ACCESSOR_MAX_MISMATCH"), "{report:#}");
}

#[test]
fn variant_scenes_pass_khronos_validator() {
    // Mesh without normals, plus a node whose mesh is empty.
    let mut no_normals = sample_scene();
    no_normals.nodes[1].mesh.as_mut().unwrap().normals.clear();
    no_normals.nodes[0].mesh = Some(MeshData::default());
    no_normals.extras = Value::Null;
    // One animation driving both paths: two samplers sharing one input accessor.
    no_normals.animations[0].translations = vec![[0.0, 0.25, -0.1]; 3];
    let bytes = write_glb(&no_normals).unwrap();
    let json = read_glb_json(&bytes).unwrap();
    let channels = &json["animations"][0]["channels"];
    assert_eq!(channels.as_array().unwrap().len(), 2);
    assert_eq!(
        json["animations"][0]["samplers"][0]["input"],
        json["animations"][0]["samplers"][1]["input"]
    );
    assert_clean(&validate_with_khronos(&bytes, "no_normals.glb"));

    // A single node without geometry: no BIN chunk at all.
    let single = Scene {
        nodes: vec![plain_node("only", None)],
        animations: vec![],
        extras: Value::Null,
    };
    let bytes = write_glb(&single).unwrap();
    let json = read_glb_json(&bytes).unwrap();
    assert!(json.get("buffers").is_none());
    assert_clean(&validate_with_khronos(&bytes, "single.glb"));

    // No nodes at all.
    let empty = Scene {
        nodes: vec![],
        animations: vec![],
        extras: Value::Null,
    };
    assert_clean(&validate_with_khronos(
        &write_glb(&empty).unwrap(),
        "empty.glb",
    ));
}

#[test]
fn read_glb_json_round_trips() {
    let scene = sample_scene();
    let json = read_glb_json(&write_glb(&scene).unwrap()).unwrap();
    assert_eq!(json["asset"]["version"], "2.0");
    assert_eq!(
        json["asset"]["generator"],
        format!("physnap {}", env!("CARGO_PKG_VERSION"))
    );
    assert_eq!(json["asset"]["extras"], scene.extras);
    let nodes = json["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), 2);
    for (written, node) in nodes.iter().zip(&scene.nodes) {
        assert_eq!(written["name"], node.name.as_str());
        assert_eq!(written["extras"], node.extras);
    }
    assert_eq!(json["scenes"][0]["nodes"], json!([1]));
    assert_eq!(nodes[1]["children"], json!([0]));
    assert!(nodes[0].get("children").is_none());

    let anims = json["animations"].as_array().unwrap();
    assert_eq!(anims.len(), 2);
    assert_eq!(anims[0]["name"], "lid_open");
    assert_eq!(
        anims[0]["channels"][0]["target"],
        json!({ "node": 0, "path": "rotation" })
    );
    assert_eq!(anims[1]["channels"][0]["target"]["path"], "translation");
    assert_eq!(anims[0]["channels"].as_array().unwrap().len(), 1);
    assert_eq!(anims[0]["samplers"][0]["interpolation"], "LINEAR");

    let material = &json["materials"][0]["pbrMetallicRoughness"];
    assert_eq!(material["metallicFactor"], 0.0);
    assert_eq!(material["roughnessFactor"].as_f64().unwrap() as f32, 0.8);
    let color: Vec<f32> = material["baseColorFactor"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_f64().unwrap() as f32)
        .collect();
    assert_eq!(color, scene.nodes[0].color);

    // Exact POSITION bounds of the lid box.
    let pos = &json["accessors"][0];
    let min: Vec<f32> = pos["min"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap() as f32)
        .collect();
    let max: Vec<f32> = pos["max"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap() as f32)
        .collect();
    assert_eq!(min, [-0.2, 0.0, 0.0]);
    assert_eq!(max, [0.2, 0.02, 0.2]);
}

#[test]
fn rejects_parent_out_of_range() {
    let mut scene = sample_scene();
    scene.nodes[0].parent = Some(7);
    let msg = expect_invalid(&scene, "nodes[0].parent");
    assert!(msg.contains("out of range"), "{msg}");
}

#[test]
fn rejects_parent_cycle() {
    let scene = Scene {
        nodes: vec![
            plain_node("root", None),
            plain_node("a", Some(2)),
            plain_node("b", Some(3)),
            plain_node("c", Some(1)),
        ],
        animations: vec![],
        extras: Value::Null,
    };
    let msg = expect_invalid(&scene, "nodes[1].parent");
    assert!(msg.contains("cycle: 1 -> 2 -> 3 -> 1"), "{msg}");

    let mut self_parent = sample_scene();
    self_parent.nodes[1].parent = Some(1);
    let msg = expect_invalid(&self_parent, "nodes[1].parent");
    assert!(msg.contains("own parent"), "{msg}");
}

#[test]
fn rejects_triangle_index_out_of_range() {
    let mut scene = sample_scene();
    scene.nodes[1].mesh.as_mut().unwrap().triangles[5] = [0, 1, 24];
    let msg = expect_invalid(&scene, "nodes[1].mesh.triangles[5]");
    assert!(
        msg.contains("vertex index 24 out of range (24 vertices)"),
        "{msg}"
    );
}

#[test]
fn rejects_non_finite_values() {
    let mut scene = sample_scene();
    scene.nodes[0].mesh.as_mut().unwrap().positions[3][1] = f32::NAN;
    let msg = expect_invalid(&scene, "nodes[0].mesh.positions[3]");
    assert!(msg.contains("non-finite"), "{msg}");

    let mut scene = sample_scene();
    scene.nodes[1].translation[2] = f32::INFINITY;
    expect_invalid(&scene, "nodes[1].translation");

    let mut scene = sample_scene();
    scene.animations[1].translations[1][0] = f32::NAN;
    expect_invalid(&scene, "animations[1].translations[1]");
}

#[test]
fn rejects_bad_animation_times() {
    let mut scene = sample_scene();
    scene.animations[0].times = vec![0.0, 0.5, 0.5];
    let msg = expect_invalid(&scene, "animations[0].times[2]");
    assert!(msg.contains("strictly increasing"), "{msg}");

    let mut scene = sample_scene();
    scene.animations[0].times = vec![0.0, 1.0, 0.5];
    expect_invalid(&scene, "animations[0].times[2]");

    let mut scene = sample_scene();
    scene.animations[1].times = vec![-1.0, 0.0];
    expect_invalid(&scene, "animations[1].times[0]");
}

#[test]
fn rejects_other_invalid_scenes() {
    let mut scene = sample_scene();
    scene.animations[0].rotations.pop();
    expect_invalid(&scene, "animations[0].rotations");

    let mut scene = sample_scene();
    scene.animations[1].translations.clear();
    expect_invalid(&scene, "animations[1]");

    let mut scene = sample_scene();
    scene.animations[1].node = 2;
    expect_invalid(&scene, "animations[1].node");

    let mut scene = sample_scene();
    scene.nodes[0].rotation = [0.0, 0.0, 0.0, 1.1];
    expect_invalid(&scene, "nodes[0].rotation");

    let mut scene = sample_scene();
    scene.animations[0].rotations[1] = [0.0, 0.0, 0.0, 0.0];
    expect_invalid(&scene, "animations[0].rotations[1]");

    let mut scene = sample_scene();
    scene.nodes[1].mesh.as_mut().unwrap().normals.pop();
    expect_invalid(&scene, "nodes[1].mesh.normals");

    let mut scene = sample_scene();
    scene.nodes[1].color = [1.5, 0.0, 0.0, 1.0];
    expect_invalid(&scene, "nodes[1].color");
}

#[test]
fn near_unit_quaternions_are_renormalised() {
    let mut scene = sample_scene();
    scene.nodes[0].rotation = [0.0, 0.0, 0.0, 1.0005];
    scene.animations[0].rotations[0] = [0.0, 0.0, 0.0, 0.9995];
    let bytes = write_glb(&scene).unwrap();
    let json = read_glb_json(&bytes).unwrap();
    assert_eq!(json["nodes"][0]["rotation"], json!([0.0, 0.0, 0.0, 1.0]));
    assert_clean(&validate_with_khronos(&bytes, "renormalised.glb"));
}

#[test]
fn output_is_deterministic_and_well_framed() {
    let scene = sample_scene();
    let bytes = write_glb(&scene).unwrap();
    assert_eq!(bytes, write_glb(&scene.clone()).unwrap());

    assert_eq!(word(&bytes, 0), GLB_MAGIC);
    assert_eq!(&bytes[0..4], b"glTF");
    assert_eq!(word(&bytes, 4), 2);
    assert_eq!(word(&bytes, 8) as usize, bytes.len());
    assert_eq!(bytes.len() % 4, 0);

    let json_len = word(&bytes, 12) as usize;
    assert_eq!(&bytes[16..20], b"JSON");
    assert_eq!(json_len % 4, 0);
    let bin_header = 20 + json_len;
    let bin_len = word(&bytes, bin_header) as usize;
    assert_eq!(&bytes[bin_header + 4..bin_header + 8], b"BIN\0");
    assert_eq!(bin_len % 4, 0);
    assert_eq!(bin_header + 8 + bin_len, bytes.len());

    let json = read_glb_json(&bytes).unwrap();
    assert_eq!(
        json["buffers"][0]["byteLength"].as_u64().unwrap() as usize,
        bin_len
    );
    for view in json["bufferViews"].as_array().unwrap() {
        assert_eq!(view["byteOffset"].as_u64().unwrap() % 4, 0, "{view}");
    }
    // Every accessor and view is used exactly once: 3 per mesh, 1 + outputs per animation.
    assert_eq!(json["accessors"].as_array().unwrap().len(), 3 + 3 + 2 + 2);
    assert_eq!(json["bufferViews"].as_array().unwrap().len(), 10);
}

#[test]
fn json_chunk_padding_uses_spaces() {
    // Vary the name length so that every padding amount (0..=3) occurs.
    for extra in 0..4 {
        let mut scene = sample_scene();
        scene.nodes[0].name.push_str(&"x".repeat(extra));
        let bytes = write_glb(&scene).unwrap();
        let json_len = word(&bytes, 12) as usize;
        let chunk = &bytes[20..20 + json_len];
        let text_end = chunk.iter().rposition(|&b| b == b'}').unwrap() + 1;
        assert!(json_len - text_end < 4);
        assert!(chunk[text_end..].iter().all(|&b| b == b' '));
    }
}

#[test]
fn empty_mesh_gets_no_mesh_key() {
    let mut scene = sample_scene();
    scene.nodes[0].mesh = Some(MeshData {
        positions: vec![[0.0; 3]; 3],
        normals: vec![],
        triangles: vec![],
    });
    scene.nodes[1].mesh = Some(MeshData::default());
    let json = read_glb_json(&write_glb(&scene).unwrap()).unwrap();
    for node in json["nodes"].as_array().unwrap() {
        assert!(node.get("mesh").is_none(), "{node}");
    }
    assert!(json.get("meshes").is_none());
    assert!(json.get("materials").is_none());
    // Only the animation data remains in the buffer.
    assert_eq!(json["accessors"].as_array().unwrap().len(), 4);
}

#[test]
fn read_glb_json_rejects_garbage() {
    assert!(matches!(
        read_glb_json(b"glTF"),
        Err(GltfError::InvalidGlb { .. })
    ));
    assert!(matches!(
        read_glb_json(&[0u8; 32]),
        Err(GltfError::InvalidGlb { .. })
    ));
    let mut bytes = write_glb(&sample_scene()).unwrap();
    bytes.truncate(bytes.len() - 4);
    let err = read_glb_json(&bytes).unwrap_err();
    assert!(err.to_string().contains("declares"), "{err}");
}
