//! Export acceptance: every GLB and URDF we write passes the real validators (Khronos
//! glTF-Validator, urdfdom's check_urdf), the URDF parses back with urdf-rs with matching
//! joints, limits and dynamics, one visual and one collision mesh per part and inertials every
//! engine accepts, and the GLB carries the hierarchy, extras and one animation per joint.
//! (MuJoCo's view of the URDF and the MJCF is tests/mjcf.rs.)

mod common;

use std::path::Path;

use common::{Rng, assert_gltf_clean, check_urdf, random_object};
use physnap::export::gltf::read_glb_json;
use physnap::export::{ExportOptions, export_dir, mesh_parts};
use physnap::mesh::MeshingOptions;
use physnap::shape::PartShape;
use physnap::{ArticulatedObject, JointKind};

fn export(obj: &ArticulatedObject, dir: &Path) {
    let opts = ExportOptions {
        meshing: MeshingOptions { resolution: 40 },
        ..Default::default()
    };
    let meshes = mesh_parts(obj, None, &opts.meshing).unwrap();
    assert!(
        meshes.iter().all(|m| !m.is_empty()),
        "every part meshes non-empty"
    );
    export_dir(obj, &meshes, dir, &opts).unwrap();
}

/// Check the URDF with check_urdf and urdf-rs, and compare joints with the object.
fn check_urdf_matches(obj: &ArticulatedObject, urdf_path: &Path) {
    let report = check_urdf(urdf_path);
    assert!(report.contains("Successfully Parsed XML"), "{report}");
    let robot = urdf_rs::read_file(urdf_path).expect("urdf-rs parses our URDF");
    let expected_links = obj.parts.len()
        + obj
            .joints
            .iter()
            .filter(|j| j.kind == JointKind::Screw)
            .count();
    assert_eq!(robot.links.len(), expected_links);
    let dir = urdf_path.parent().unwrap();
    for link in &robot.links {
        // Inertials every engine accepts: mass > 0, positive definite, triangle inequality.
        let i = &link.inertial.inertia;
        let t = nalgebra::Matrix3::new(
            i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
        );
        let mut m: Vec<f64> = t.symmetric_eigenvalues().iter().copied().collect();
        m.sort_by(f64::total_cmp);
        assert!(link.inertial.mass.value > 0.0, "{} mass", link.name);
        assert!(
            m[0] > 0.0 && m[0] + m[1] >= m[2],
            "{}: moments {m:?}",
            link.name
        );
        if link.name.ends_with("_screw_helper") {
            continue;
        }
        // The visual mesh and its convex collision pieces, all on disk.
        let file = |g: &urdf_rs::Geometry| match g {
            urdf_rs::Geometry::Mesh { filename, .. } => filename.clone(),
            other => panic!("{}: {other:?}", link.name),
        };
        assert_eq!(link.visual.len(), 1, "{}", link.name);
        assert_eq!(
            file(&link.visual[0].geometry),
            format!("meshes/{}.obj", link.name)
        );
        assert!(!link.collision.is_empty(), "{}", link.name);
        for (k, c) in link.collision.iter().enumerate() {
            let piece = file(&c.geometry);
            assert_eq!(piece, format!("meshes/{}_collision_{k}.obj", link.name));
            assert!(dir.join(&piece).is_file(), "{piece}");
        }
    }
    for j in &obj.joints {
        let child = &obj.parts[j.child].name;
        let find = |name: &str| {
            robot
                .joints
                .iter()
                .find(|x| x.name == name)
                .unwrap_or_else(|| panic!("joint {name} missing"))
        };
        let check_limit = |x: &urdf_rs::Joint, r: [f64; 2]| {
            assert!((x.limit.lower - r[0]).abs() < 1e-12, "{} lower", x.name);
            assert!((x.limit.upper - r[1]).abs() < 1e-12, "{} upper", x.name);
            assert!(x.limit.effort > 0.0 && x.limit.velocity > 0.0);
            let d = x
                .dynamics
                .as_ref()
                .expect("movable joints carry <dynamics>");
            let defaults = ExportOptions::default();
            assert_eq!(
                (d.damping, d.friction),
                (defaults.damping, defaults.friction)
            );
            for a in 0..3 {
                assert!((x.axis.xyz[a] - j.axis[a]).abs() < 1e-12, "{} axis", x.name);
            }
        };
        match j.kind {
            JointKind::Revolute => {
                let x = find(&format!("joint_{child}"));
                assert!(matches!(x.joint_type, urdf_rs::JointType::Revolute));
                check_limit(x, j.revolute);
            }
            JointKind::Prismatic => {
                let x = find(&format!("joint_{child}"));
                assert!(matches!(x.joint_type, urdf_rs::JointType::Prismatic));
                check_limit(x, j.prismatic);
            }
            JointKind::Screw => {
                let slide = find(&format!("joint_{child}_slide"));
                assert!(matches!(slide.joint_type, urdf_rs::JointType::Prismatic));
                check_limit(slide, j.prismatic);
                let turn = find(&format!("joint_{child}_turn"));
                assert!(matches!(turn.joint_type, urdf_rs::JointType::Revolute));
                check_limit(turn, j.revolute);
                assert_eq!(turn.child.link, *child);
            }
            JointKind::Fixed => {
                let x = find(&format!("joint_{child}"));
                assert!(matches!(x.joint_type, urdf_rs::JointType::Fixed));
            }
        }
    }
}

#[test]
fn cabinet_exports_pass_both_validators() {
    let dir = tempfile::tempdir().unwrap();
    let obj = physnap::fixtures::cabinet();
    export(&obj, dir.path());
    assert_gltf_clean(&dir.path().join("model.glb"));
    check_urdf_matches(&obj, &dir.path().join("robot.urdf"));
    for p in &obj.parts {
        assert!(dir.path().join(format!("meshes/{}.obj", p.name)).exists());
    }
}

#[test]
fn eight_part_object_with_every_joint_type_validates() {
    let dir = tempfile::tempdir().unwrap();
    let obj = physnap::fixtures::eight_part();
    export(&obj, dir.path());
    assert_gltf_clean(&dir.path().join("model.glb"));
    check_urdf_matches(&obj, &dir.path().join("robot.urdf"));

    // GLB: one node per part plus one pivot per joint, hierarchy = kinematic tree,
    // joint extras, one animation per movable joint.
    let json = read_glb_json(&std::fs::read(dir.path().join("model.glb")).unwrap()).unwrap();
    let nodes = json["nodes"].as_array().unwrap();
    assert_eq!(nodes.len(), obj.parts.len() + obj.joints.len());
    let movable = obj
        .joints
        .iter()
        .filter(|j| j.kind != JointKind::Fixed)
        .count();
    assert_eq!(json["animations"].as_array().unwrap().len(), movable);
    let pivots: Vec<_> = nodes
        .iter()
        .filter(|n| n["extras"]["joint"].is_object())
        .collect();
    assert_eq!(pivots.len(), obj.joints.len());
    for j in &obj.joints {
        let pivot = pivots
            .iter()
            .find(|n| n["extras"]["joint"]["child"] == obj.parts[j.child].name.as_str())
            .expect("pivot node per joint");
        assert_eq!(pivot["extras"]["joint"]["type"], j.kind.as_str());
        // glTF is +Y up: object axis (x, y, z) is stored as (x, z, -y).
        let axis = pivot["extras"]["joint"]["axis"].as_array().unwrap();
        let a: Vec<f64> = axis.iter().map(|v| v.as_f64().unwrap()).collect();
        assert!(
            (a[0] - j.axis.x).abs() < 1e-6
                && (a[1] - j.axis.z).abs() < 1e-6
                && (a[2] + j.axis.y).abs() < 1e-6
        );
        // The pivot's only child is the child part's node.
        let children = pivot["children"].as_array().unwrap();
        assert_eq!(children.len(), 1);
        let child_node = &nodes[children[0].as_u64().unwrap() as usize];
        assert_eq!(
            child_node["extras"]["part"]["name"],
            obj.parts[j.child].name.as_str()
        );
    }
    // Only the root part is a scene root.
    assert_eq!(json["scenes"][0]["nodes"].as_array().unwrap().len(), 1);
}

#[test]
fn random_objects_validate() {
    // Random trees with random axes, limits and joint types (box-shaped parts).
    for seed in 0..4u64 {
        let mut rng = Rng(seed);
        let mut obj = random_object(&mut rng, 2 + (seed as usize * 2) % 7);
        for p in &mut obj.parts {
            p.shape = PartShape::Box;
        }
        let dir = tempfile::tempdir().unwrap();
        export(&obj, dir.path());
        assert_gltf_clean(&dir.path().join("model.glb"));
        check_urdf_matches(&obj, &dir.path().join("robot.urdf"));
    }
}

#[test]
fn zip_bundle_holds_urdf_and_meshes_and_export_is_deterministic() {
    let obj = physnap::fixtures::cabinet();
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    export(&obj, a.path());
    export(&obj, b.path());
    for f in [
        "model.glb",
        "robot.urdf",
        "model.xml",
        "robot.zip",
        "object.json",
    ] {
        assert_eq!(
            std::fs::read(a.path().join(f)).unwrap(),
            std::fs::read(b.path().join(f)).unwrap(),
            "{f} differs between two identical exports"
        );
    }
    // The zip unpacks to a URDF that check_urdf accepts, next to its meshes.
    let bytes = std::fs::read(a.path().join("robot.zip")).unwrap();
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).unwrap();
    let names: Vec<String> = zip.file_names().map(String::from).collect();
    assert!(names.contains(&"robot.urdf".to_string()));
    assert!(names.contains(&"model.xml".to_string()));
    for p in &obj.parts {
        for f in [
            format!("meshes/{}.obj", p.name),
            format!("meshes/{}_collision_0.obj", p.name),
        ] {
            assert!(names.contains(&f), "{f} not in {names:?}");
        }
    }
    // Nothing but the two documents and the meshes (one visual, and the collision pieces).
    let meshes = names.iter().filter(|n| n.starts_with("meshes/")).count();
    let pieces = names.iter().filter(|n| n.contains("_collision_")).count();
    assert_eq!(names.len(), 2 + meshes, "{names:?}");
    assert_eq!(meshes, obj.parts.len() + pieces, "{names:?}");
    let out = tempfile::tempdir().unwrap();
    zip.extract(out.path()).unwrap();
    check_urdf_matches(&obj, &out.path().join("robot.urdf"));
}

#[test]
fn object_json_round_trips_exactly() {
    for obj in [
        physnap::fixtures::cabinet(),
        physnap::fixtures::eight_part(),
    ] {
        let text = physnap::io::object_json::to_string(&obj);
        assert_eq!(physnap::io::object_json::from_str(&text).unwrap(), obj);
    }
    let mut rng = Rng(7);
    let obj = random_object(&mut rng, 8);
    let text = physnap::io::object_json::to_string(&obj);
    assert_eq!(physnap::io::object_json::from_str(&text).unwrap(), obj);
}

#[test]
fn bad_export_options_name_field_limit_and_value() {
    let obj = physnap::fixtures::cabinet();
    let meshes = mesh_parts(&obj, None, &MeshingOptions { resolution: 16 }).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut opts = ExportOptions::default();
    opts.inertial.density = -2.5;
    let e = export_dir(&obj, &meshes, dir.path(), &opts).unwrap_err();
    let s = e.to_string();
    assert!(
        s.contains("density") && s.contains("> 0") && s.contains("-2.5"),
        "{s}"
    );
    assert_eq!(e.error_type(), "invalid_field");
    let opts = ExportOptions {
        damping: f64::NAN,
        ..Default::default()
    };
    let s = export_dir(&obj, &meshes, dir.path(), &opts)
        .unwrap_err()
        .to_string();
    assert!(
        s.contains("damping") && s.contains(">= 0") && s.contains("NaN"),
        "{s}"
    );
    // Nothing was written.
    assert!(!dir.path().join("robot.urdf").exists());
}
