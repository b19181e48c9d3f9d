//! MJCF acceptance: `model.xml` and `robot.urdf` are one model in MuJoCo.
//!
//! Exports the cabinet, the eight-part fixture (every joint type), a hand-made object with a
//! 1 mm panel, a tiny fixed knob (merged into its parent) and a tiny slider (kept with the
//! floor mass), and two random 8-part trees with random axes, then runs `tests/support/mjcf_equivalence.py` with the MuJoCo of
//! `bash .ci/setup` (tests/tools/mjvenv): both files must compile, have the same bodies,
//! joints, inertials and collision geoms, and give the same world pose for every body at five
//! joint states within 1e-6, equal to physnap's own kinematics.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use nalgebra::{Point3, Translation3, Vector3};
use physnap::export::names::link_names;
use physnap::export::{ExportNote, ExportOptions, ExportReport, export_dir, mesh_parts, urdf};
use physnap::fixtures::box_part;
use physnap::frame::ScanFrame;
use physnap::mesh::primitives::part_primitive_mesh;
use physnap::mesh::{MeshingOptions, TriMesh};
use physnap::{ArticulatedObject, Joint, JointKind};
use serde_json::{Value, json};

const FRACTIONS: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];

fn mujoco_python() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/tools/mjvenv/bin/python");
    p.exists().then_some(p)
}

/// A base, a 1 mm × 0.5 m × 0.5 m lid on a hinge, a 5 mm knob fixed on the lid (a tiny fixed
/// leaf), a 4 mm slider on the base (tiny but movable) and a screw cap.
fn panel_rig() -> ArticulatedObject {
    let joint = |parent, child, kind, axis: [f64; 3], origin: [f64; 3], r, p| Joint {
        parent,
        child,
        kind,
        axis: Vector3::from(axis),
        origin: Point3::from(origin),
        revolute: r,
        prismatic: p,
    };
    let z = [0.0, 0.0];
    ArticulatedObject {
        name: "panel rig".into(),
        category: None,
        parts: vec![
            box_part("base", [0.0, 0.0, 0.2], [0.25, 0.25, 0.2]),
            box_part("lid", [0.0, 0.0, 0.4005], [0.25, 0.25, 0.0005]),
            box_part("knob", [0.2, 0.0, 0.4035], [0.0025, 0.0025, 0.0025]),
            box_part("slider", [-0.252, 0.0, 0.2], [0.002, 0.002, 0.002]),
            box_part("cap", [0.0, 0.26, 0.2], [0.03, 0.01, 0.03]),
        ],
        joints: vec![
            joint(
                0,
                1,
                JointKind::Revolute,
                [0.0, 1.0, 0.0],
                [-0.25, 0.0, 0.4],
                [0.0, 1.9],
                z,
            ),
            joint(
                1,
                2,
                JointKind::Fixed,
                [0.0, 0.0, 1.0],
                [0.2, 0.0, 0.401],
                z,
                z,
            ),
            joint(
                0,
                3,
                JointKind::Prismatic,
                [0.0, 0.0, 1.0],
                [-0.252, 0.0, 0.2],
                z,
                [-0.1, 0.1],
            ),
            joint(
                0,
                4,
                JointKind::Screw,
                [0.0, 1.0, 0.0],
                [0.0, 0.25, 0.2],
                [0.0, 6.0],
                [0.0, 0.01],
            ),
        ],
    }
}

/// World pose `[x, y, z, qw, qx, qy, qz]` of every link frame at each fraction, from physnap's
/// kinematics (the URDF/MJCF link frames, moved by the parts' motions), merged parts left out.
fn expected_poses(
    obj: &ArticulatedObject,
    report: &ExportReport,
    to_scan: &nalgebra::Isometry3<f64>,
) -> Value {
    let frames = urdf::link_frames(obj);
    let names = link_names(obj);
    let merged: Vec<&str> = report
        .notes
        .iter()
        .filter_map(|n| match n {
            ExportNote::MergedIntoParent { part, .. } => Some(part.as_str()),
            _ => None,
        })
        .collect();
    let mut poses = serde_json::Map::new();
    for (p, part) in obj.parts.iter().enumerate() {
        if merged.contains(&part.name.as_str()) {
            continue;
        }
        let per_fraction: Vec<Value> = FRACTIONS
            .iter()
            .map(|&f| {
                let motion = obj.part_motions(&obj.states_at(f))[p];
                let pose = to_scan * motion * Translation3::from(frames[p]);
                let t = pose.translation.vector;
                let q = pose.rotation;
                json!([t.x, t.y, t.z, q.w, q.i, q.j, q.k])
            })
            .collect();
        poses.insert(names[p].clone(), Value::Array(per_fraction));
    }
    Value::Object(poses)
}

fn export(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    dir: &Path,
    frame: Option<ScanFrame>,
) -> ExportReport {
    let opts = ExportOptions {
        frame,
        ..Default::default()
    };
    export_dir(obj, meshes, dir, &opts).unwrap()
}

#[test]
fn urdf_and_mjcf_agree_in_mujoco() {
    let root = tempfile::tempdir().unwrap();
    let meshing = MeshingOptions { resolution: 40 };
    let mut cases: Vec<(ArticulatedObject, Vec<TriMesh>)> = Vec::new();
    for obj in [
        physnap::fixtures::cabinet(),
        physnap::fixtures::eight_part(),
    ] {
        let meshes = mesh_parts(&obj, None, &meshing).unwrap();
        assert!(meshes.iter().all(|m| !m.is_empty()));
        cases.push((obj, meshes));
    }
    // The rig's 1 mm lid needs exact meshes (marching cubes would lose it).
    let rig = panel_rig();
    rig.validate().unwrap();
    let rig_meshes = rig
        .parts
        .iter()
        .map(|p| part_primitive_mesh(p).unwrap())
        .collect();
    cases.push((rig, rig_meshes));
    // Random trees, random axes and joint types, box parts with exact meshes.
    for seed in [3u64, 11] {
        let mut obj = common::random_object(&mut common::Rng(seed), 8);
        obj.name = format!("random_{seed}");
        for p in &mut obj.parts {
            p.shape = physnap::shape::PartShape::Box;
        }
        let meshes = obj
            .parts
            .iter()
            .map(|p| part_primitive_mesh(p).unwrap())
            .collect();
        cases.push((obj, meshes));
    }

    let mut dirs = Vec::new();
    let mut expected = serde_json::Map::new();
    // The eight-part object once more, put back in a scan's frame (+Y up, yawed, moved): the
    // URDF's `world` link and the MJCF's root body hold the transform.
    let frame = ScanFrame::new([0.0, 1.0, 0.0], 0.7, [0.4, -1.1, 0.25]).unwrap();
    let framed = vec![(cases[1].0.clone(), cases[1].1.clone(), Some(frame))];
    for (obj, meshes, frame) in cases
        .iter()
        .map(|(o, m)| (o.clone(), m.clone(), None))
        .chain(framed)
    {
        let name = if frame.is_some() {
            format!("{}_framed", obj.name)
        } else {
            obj.name.clone()
        };
        let dir = root.path().join(name);
        let report = export(&obj, &meshes, &dir, frame);
        let key = dir.to_str().unwrap().to_string();
        let to_scan = frame.unwrap_or_default().to_scan();
        expected.insert(key.clone(), expected_poses(&obj, &report, &to_scan));
        dirs.push((key, obj.clone(), report));
    }
    // The framed export: a `world` link with the transform, valid for urdfdom and Khronos.
    let framed_dir = Path::new(&dirs[cases.len()].0);
    let urdf_text = std::fs::read_to_string(framed_dir.join("robot.urdf")).unwrap();
    assert!(urdf_text.contains("<link name=\"world\"/>"), "{urdf_text}");
    common::check_urdf(&framed_dir.join("robot.urdf"));
    common::assert_gltf_clean(&framed_dir.join("model.glb"));

    // The rig: the knob went into the lid, the slider kept its link with the floor mass.
    let (_, rig, report) = &dirs[2];
    assert!(
        report.notes.iter().any(|n| matches!(n,
            ExportNote::MergedIntoParent { part, parent, .. } if part == "knob" && parent == "lid")),
        "{:?}",
        report.notes
    );
    assert!(
        report.notes.iter().any(|n| matches!(n,
            ExportNote::MassFloored { part, written, .. } if part == "slider" && *written == 1e-3)),
        "{:?}",
        report.notes
    );
    assert_eq!(report.notes.len(), 2, "{:?}", report.notes);
    let rig_dir = Path::new(&dirs[2].0);
    let urdf_text = std::fs::read_to_string(rig_dir.join("robot.urdf")).unwrap();
    let xml = std::fs::read_to_string(rig_dir.join("model.xml")).unwrap();
    assert!(!urdf_text.contains("\"knob\"") && !xml.contains("\"knob\""));
    assert!(!rig_dir.join("meshes/knob.obj").exists());
    // The lid's link carries the knob: mesh (8 + 8 box vertices) and two collision pieces.
    let lid = std::fs::read_to_string(rig_dir.join("meshes/lid.obj")).unwrap();
    assert_eq!(lid.lines().filter(|l| l.starts_with("v ")).count(), 16);
    assert!(rig_dir.join("meshes/lid_collision_1.obj").exists());
    // The GLB still has every part.
    let glb = std::fs::read(rig_dir.join("model.glb")).unwrap();
    let gltf = physnap::export::gltf::read_glb_json(&glb).unwrap();
    let node_names: Vec<&str> = gltf["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|n| n["name"].as_str())
        .collect();
    assert!(node_names.contains(&"knob"), "{node_names:?}");
    assert_eq!(rig.parts.len(), 5);

    let Some(python) = mujoco_python() else {
        eprintln!(
            "SKIPPED urdf_and_mjcf_agree_in_mujoco's MuJoCo check: tests/tools/mjvenv/bin/python \
             does not exist (run `bash .ci/setup`)"
        );
        return;
    };
    let expected_path = root.path().join("expected.json");
    std::fs::write(
        &expected_path,
        serde_json::to_string(&json!({"fractions": FRACTIONS, "poses": expected})).unwrap(),
    )
    .unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/support/mjcf_equivalence.py");
    let out = Command::new(&python)
        .arg(&script)
        .arg("--expected")
        .arg(&expected_path)
        .args(dirs.iter().map(|d| &d.0))
        .output()
        .expect("running the MuJoCo script");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "mjcf_equivalence.py failed ({:?}):\n{stdout}\n{stderr}",
        out.status.code()
    );
    let doc: Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(doc["mujoco"], "4.0.0");
    let results = doc["results"].as_array().unwrap();
    assert_eq!(results.len(), dirs.len());
    for (r, (_, obj, _)) in results.iter().zip(&dirs) {
        assert_eq!(r["ok"], true, "{r:#}");
        let movable: usize = obj
            .joints
            .iter()
            .map(|j| match j.kind {
                JointKind::Fixed => 0,
                JointKind::Screw => 2,
                _ => 1,
            })
            .sum();
        assert_eq!(r["joints"].as_u64().unwrap() as usize, movable, "{r:#}");
        assert!(r["max_pose_error"].as_f64().unwrap() <= 1e-6, "{r:#}");
    }
    // The rig's bodies: every part but the knob.
    assert_eq!(results[2]["bodies"], 4);
}
