//! URDF import (`physnap data import --urdf`) on hand-written URDFs, and the MJCF converter
//! (`scripts/mjcf_to_urdf.py`) on a hand-written MJCF with classes, defaults and a binary
//! `.msh` mesh.
//!
//! The converter test needs Python with the `mujoco` package (.ci/setup installs
//! mujoco==4.0.0 into tests/tools/mjvenv); it fails with that instruction when it is missing,
//! unless PHYSNAP_SKIP_MUJOCO=1.

use std::path::{Path, PathBuf};
use std::process::Command;

use physnap::data::dataset::ImportOptions;
use physnap::data::urdf::{PerObject, UrdfOptions, import};
use physnap::object::{ArticulatedObject, JointKind};
use serde_json::Value;

fn small() -> ImportOptions {
    ImportOptions {
        seed: 0,
        uniform: 64,
        near: 64,
        surface: 64,
    }
}

fn opts(category: &str) -> UrdfOptions {
    UrdfOptions {
        category: PerObject::parse(&[category.to_string()]),
        ..Default::default()
    }
}

fn write_urdf(dir: &Path, name: &str, body: &str) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let p = dir.join(format!("{name}.urdf"));
    std::fs::write(
        &p,
        format!("<?xml version=\"1.0\"?>\n<robot name=\"{name}\">\n{body}\n</robot>\n"),
    )
    .unwrap();
    p
}

fn index(out: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("dataset.json")).unwrap()).unwrap()
}

fn object(out: &Path, id: &str) -> ArticulatedObject {
    physnap::io::object_json::read(&out.join("objects").join(id).join("object.json")).unwrap()
}

fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

fn skip_reason(idx: &Value, id: &str) -> String {
    idx["skipped"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["id"] == id)
        .map(|s| s["reason"].as_str().unwrap().to_string())
        .unwrap_or_else(|| panic!("{id} not skipped: {}", idx["skipped"]))
}

/// A cabinet: base box with a fixed top slab, a door on a hinge whose joint frame is rolled
/// by 90° (rpy), a handle fixed to the door (a cylinder laid along Z by its own rpy).
const CABINET: &str = r#"
  <link name="base">
    <visual><origin xyz="0 0 0.5"/><geometry><box size="1 1 1"/></geometry></visual>
    <collision><geometry><sphere radius="0.1"/></geometry></collision>
  </link>
  <link name="top">
    <visual><origin xyz="0 0 1.05"/><geometry><box size="1 1 0.1"/></geometry></visual>
  </link>
  <joint name="top_fixed" type="fixed"><parent link="base"/><child link="top"/></joint>
  <link name="door">
    <visual><origin xyz="0 0 -0.5"/><geometry><box size="0.02 1 1"/></geometry></visual>
  </link>
  <joint name="hinge" type="revolute">
    <origin xyz="-0.51 -0.5 0.5" rpy="1.5707963267948966 0 0"/>
    <axis xyz="0 1 0"/>
    <parent link="base"/><child link="door"/>
    <limit lower="0" upper="1.5" effort="1" velocity="1"/>
  </joint>
  <link name="handle">
    <visual><origin xyz="-0.02 0 -0.9" rpy="0 0 0"/><geometry><cylinder radius="0.01" length="0.2"/></geometry></visual>
  </link>
  <joint name="handle_fixed" type="fixed">
    <origin xyz="0 0 0" rpy="0 0 0"/><parent link="door"/><child link="handle"/>
  </joint>
"#;

#[test]
fn fixed_links_merge_and_rpy_origins_place_parts_and_axes() {
    let tmp = tempfile::tempdir().unwrap();
    let src = write_urdf(&tmp.path().join("src"), "cabinet", CABINET);
    let out = tmp.path().join("out");
    let r = import(
        &[src],
        None,
        &out,
        &opts("StorageFurniture"),
        &small(),
        &|_, _| {},
    )
    .unwrap();
    assert_eq!(r.dataset.entries.len(), 1, "{:?}", r.dataset.skipped);
    let e = &r.dataset.entries[0];
    assert_eq!((e.id.as_str(), e.parts), ("cabinet", 2));
    assert_eq!(e.joints, vec!["revolute"]);
    let o = object(&out, "cabinet");
    // Source x bounds [-0.54 (handle), 0.5] -> centred: +0.02; floor already at z = 0.
    let base = &o.parts[0];
    assert!(
        close(base.center.as_slice(), &[0.02, 0.0, 0.55], 1e-5),
        "{:?}",
        base.center
    );
    assert!(close(base.half_extents.as_slice(), &[0.5, 0.5, 0.55], 1e-5));
    let door = &o.parts[1];
    // Door slab + handle (merged): x from -0.54 to -0.50, y -0.5..0.5, z 0..1.
    assert!(
        close(door.center.as_slice(), &[-0.5, 0.0, 0.5], 1e-5),
        "{:?}",
        door.center
    );
    assert!(
        close(door.half_extents.as_slice(), &[0.02, 0.5, 0.5], 1e-5),
        "{:?}",
        door.half_extents
    );
    let j = &o.joints[0];
    assert_eq!(j.kind, JointKind::Revolute);
    assert!(
        close(j.axis.as_slice(), &[0.0, 0.0, 1.0], 1e-9),
        "{:?}",
        j.axis
    );
    assert!(
        close(j.origin.coords.as_slice(), &[-0.49, -0.5, 0.5], 1e-6),
        "{:?}",
        j.origin
    );
    assert!(close(&j.revolute, &[0.0, 1.5], 1e-9));
    let idx = index(&out);
    let s = &idx["objects"][0]["source"];
    assert_eq!(s["format"], "urdf");
    assert_eq!(s["parts"][0]["links"], serde_json::json!(["base", "top"]));
    assert_eq!(
        s["parts"][1]["links"],
        serde_json::json!(["door", "handle"])
    );
    assert!((s["to_canonical"][0][3].as_f64().unwrap() - 0.02).abs() < 1e-6);
    // The staged PartNet-Mobility folder is kept (data scan --object reads it).
    assert!(out.join("pm/cabinet/mobility_v2.json").is_file());
    assert!(out.join("pm/cabinet/source.json").is_file());

    // --geometry collision: the base has a sphere, the door nothing -> skipped with a reason.
    let out2 = tmp.path().join("out2");
    let mut o2 = opts("StorageFurniture");
    o2.geometry = physnap::data::urdf::convert::GeometrySource::Collision;
    let r = import(
        &[tmp.path().join("src")],
        None,
        &out2,
        &o2,
        &small(),
        &|_, _| {},
    )
    .unwrap();
    assert!(r.dataset.entries.is_empty());
    assert!(skip_reason(&index(&out2), "cabinet").contains("no collision geometry"));
}

const SPINNER: &str = r#"
  <link name="body"><visual><geometry><box size="0.4 0.4 0.2"/></geometry></visual></link>
  <link name="wheel"><visual><geometry><cylinder radius="0.1" length="0.05"/></geometry></visual></link>
  <joint name="spin" type="continuous">
    <origin xyz="0 0 0.125"/><axis xyz="0 0 2"/>
    <parent link="body"/><child link="wheel"/>
    <mimic joint="other"/>
  </joint>
"#;

#[test]
fn continuous_joints_get_the_continuous_range_and_axes_are_normalised() {
    let tmp = tempfile::tempdir().unwrap();
    let src = write_urdf(&tmp.path().join("src"), "spinner", SPINNER);
    let out = tmp.path().join("out");
    let r = import(
        std::slice::from_ref(&src),
        None,
        &out,
        &opts("Fan"),
        &small(),
        &|_, _| {},
    )
    .unwrap();
    assert_eq!(r.dataset.entries.len(), 1, "{:?}", r.dataset.skipped);
    let j = &object(&out, "spinner").joints[0];
    assert_eq!(j.kind, JointKind::Revolute);
    assert!(
        close(&j.revolute, &[0.0, std::f64::consts::TAU], 1e-9),
        "{:?}",
        j.revolute
    );
    assert!((j.axis.norm() - 1.0).abs() < 1e-12 && (j.axis.z - 1.0).abs() < 1e-12);
    let notes: Vec<String> = r.dataset.notes.iter().map(|(_, n)| n.clone()).collect();
    assert!(notes.iter().any(|n| n.contains("normalised")), "{notes:?}");
    assert!(notes.iter().any(|n| n.contains("mimic")), "{notes:?}");

    let out = tmp.path().join("out2");
    let mut o = opts("Fan");
    o.continuous_range = [-1.0, 1.0];
    import(&[src], None, &out, &o, &small(), &|_, _| {}).unwrap();
    let j = &object(&out, "spinner").joints[0];
    assert!(close(&j.revolute, &[-1.0, 1.0], 1e-9), "{:?}", j.revolute);
}

fn cube() -> physnap::mesh::TriMesh {
    let mut m = physnap::mesh::TriMesh::default();
    physnap::mesh::primitives::append_primitive(
        &mut m,
        &physnap::shape::Primitive::Cuboid {
            center: nalgebra::Vector3::zeros(),
            half_extents: nalgebra::Vector3::repeat(0.5),
        },
        &nalgebra::Vector3::zeros(),
    );
    m
}

fn ascii_stl(m: &physnap::mesh::TriMesh) -> String {
    let mut s = String::from("solid cube\n");
    for t in &m.triangles {
        s.push_str("facet normal 0 0 0\n outer loop\n");
        for &i in t {
            let p = m.positions[i as usize];
            s.push_str(&format!("  vertex {} {} {}\n", p[0], p[1], p[2]));
        }
        s.push_str(" endloop\nendfacet\n");
    }
    s + "endsolid cube\n"
}

#[test]
fn scaled_stl_meshes_ascii_and_binary() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    std::fs::create_dir_all(src.join("meshes")).unwrap();
    std::fs::write(src.join("meshes/cube_ascii.stl"), ascii_stl(&cube())).unwrap();
    std::fs::write(
        src.join("meshes/cube_bin.STL"),
        physnap::mesh::stl::to_binary(&cube()),
    )
    .unwrap();
    let body = r#"
  <link name="body"><visual><origin xyz="0 0 0.25"/><geometry><mesh filename="meshes/cube_ascii.stl" scale="2 1 0.5"/></geometry></visual></link>
  <link name="lid"><visual><origin xyz="0 0 0.05"/><geometry><mesh filename="package://box_pkg/meshes/cube_bin.STL" scale="0.5 0.5 0.1"/></geometry></visual></link>
  <joint name="lid" type="prismatic">
    <origin xyz="0 0 0.5"/><axis xyz="0 0 1"/><parent link="body"/><child link="lid"/>
    <limit lower="0" upper="0.3"/>
  </joint>"#;
    let f = write_urdf(&src, "stlbox", body);
    let out = tmp.path().join("out");
    let r = import(&[f], None, &out, &opts("Box"), &small(), &|_, _| {}).unwrap();
    assert_eq!(r.dataset.entries.len(), 1, "{:?}", r.dataset.skipped);
    let o = object(&out, "stlbox");
    assert!(
        close(o.parts[0].half_extents.as_slice(), &[1.0, 0.5, 0.25], 1e-6),
        "{:?}",
        o.parts[0].half_extents
    );
    assert!(close(o.parts[0].center.as_slice(), &[0.0, 0.0, 0.25], 1e-6));
    assert!(
        close(
            o.parts[1].half_extents.as_slice(),
            &[0.25, 0.25, 0.05],
            1e-6
        ),
        "{:?}",
        o.parts[1].half_extents
    );
    assert!(close(o.parts[1].center.as_slice(), &[0.0, 0.0, 0.55], 1e-6));
    assert_eq!(o.joints[0].kind, JointKind::Prismatic);
    assert!(close(&o.joints[0].prismatic, &[0.0, 0.3], 1e-12));
}

#[test]
fn broken_assets_are_skipped_with_reasons_and_the_rest_imports() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    write_urdf(&src, "good", CABINET);
    write_urdf(
        &src,
        "missing_mesh",
        &CABINET.replace(
            "<box size=\"0.02 1 1\"/>",
            "<mesh filename=\"meshes/door.obj\"/>",
        ),
    );
    // "door" gets a second parent: a loop, not a tree.
    write_urdf(
        &src,
        "loop",
        &format!(
            "{CABINET}<joint name=\"again\" type=\"fixed\"><parent link=\"top\"/><child link=\"door\"/></joint>"
        ),
    );
    write_urdf(
        &src,
        "static",
        &CABINET.replace("type=\"revolute\"", "type=\"fixed\""),
    );
    let mut nine = String::from(
        "<link name=\"b\"><visual><geometry><box size=\"1 1 1\"/></geometry></visual></link>",
    );
    for k in 0..8 {
        nine.push_str(&format!(
            "<link name=\"d{k}\"><visual><geometry><box size=\"0.1 0.1 0.1\"/></geometry></visual></link>\
             <joint name=\"j{k}\" type=\"prismatic\"><origin xyz=\"0.6 0 {}\"/><parent link=\"b\"/><child link=\"d{k}\"/><limit lower=\"0\" upper=\"0.1\"/></joint>",
            0.1 * k as f64
        ));
    }
    write_urdf(&src, "nine", &nine);
    let out = tmp.path().join("out");
    let r = import(
        &[src],
        None,
        &out,
        &opts("StorageFurniture"),
        &small(),
        &|_, _| {},
    )
    .unwrap();
    let ids: Vec<&str> = r.dataset.entries.iter().map(|e| e.id.as_str()).collect();
    assert_eq!(ids, vec!["good"]);
    let idx = index(&out);
    assert!(skip_reason(&idx, "missing_mesh").contains("missing mesh \"meshes/door.obj\""));
    assert!(skip_reason(&idx, "loop").contains("more than one parent"));
    assert!(skip_reason(&idx, "static").contains("no movable joint"));
    assert!(skip_reason(&idx, "nine").contains("9 parts after merging"));
    assert!(!out.join("pm/missing_mesh").exists());
}

/// A scene: a room root, a cabinet with a drawer, and a microwave standing on the cabinet
/// (a fixed child of it) with its own door.
const SCENE: &str = r#"
  <link name="room"><visual><geometry><box size="4 4 0.01"/></geometry></visual></link>
  <link name="cab"><visual><origin xyz="0 0 0.4"/><geometry><box size="0.6 0.6 0.8"/></geometry></visual></link>
  <joint name="room_cab" type="fixed"><origin xyz="1 1 0" rpy="0 0 1.5707963267948966"/><parent link="room"/><child link="cab"/></joint>
  <link name="drawer"><visual><geometry><box size="0.5 0.5 0.2"/></geometry></visual></link>
  <joint name="slide" type="prismatic"><origin xyz="-0.05 0 0.6"/><axis xyz="-1 0 0"/><parent link="cab"/><child link="drawer"/><limit lower="0" upper="0.4"/></joint>
  <link name="mw"><visual><origin xyz="0 0 0.15"/><geometry><box size="0.4 0.5 0.3"/></geometry></visual></link>
  <joint name="cab_mw" type="fixed"><origin xyz="0 0 0.8"/><parent link="cab"/><child link="mw"/></joint>
  <link name="mw_door"><visual><origin xyz="0 0.25 0.15"/><geometry><box size="0.02 0.5 0.3"/></geometry></visual></link>
  <joint name="mw_hinge" type="revolute"><origin xyz="-0.21 -0.25 0"/><axis xyz="0 0 -1"/><parent link="mw"/><child link="mw_door"/><limit lower="-1.5" upper="0"/></joint>
"#;

#[test]
fn subtrees_cut_one_object_per_fixture_with_their_own_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let f = write_urdf(&tmp.path().join("src"), "kitchen", SCENE);
    let out = tmp.path().join("out");
    let o = UrdfOptions {
        subtrees: vec!["cab=cabinet".into(), "mw".into()],
        category: PerObject::parse(&["StorageFurniture".into(), "mw=Microwave".into()]),
        // The cabinet is turned by 90° in the room: its front (local -X) faces room -Y.
        front: PerObject::parse(&["-Y".into(), "kitchen__mw=-Y".into()]),
        ..Default::default()
    };
    let r = import(&[f], None, &out, &o, &small(), &|_, _| {}).unwrap();
    let ids: Vec<(&str, &str, usize)> = r
        .dataset
        .entries
        .iter()
        .map(|e| (e.id.as_str(), e.category.as_str(), e.parts))
        .collect();
    assert_eq!(
        ids,
        vec![
            ("cabinet", "StorageFurniture", 2),
            ("kitchen__mw", "Microwave", 2)
        ],
        "{:?}",
        r.dataset.skipped
    );
    // The drawer slides along its cabinet's front normal: canonical -X.
    let cab = object(&out, "cabinet");
    assert!(
        close(cab.joints[0].axis.as_slice(), &[-1.0, 0.0, 0.0], 1e-9),
        "{:?}",
        cab.joints[0].axis
    );
    // The cabinet object holds the cabinet and drawer only (the microwave is cut out of it):
    // it stands on the floor and is 0.8 m tall.
    let hi = cab
        .parts
        .iter()
        .map(|p| p.center.z + p.half_extents.z)
        .fold(0.0, f64::max);
    assert!((hi - 0.8).abs() < 1e-6, "{hi}");
    assert!((cab.parts[0].center.z - cab.parts[0].half_extents.z).abs() < 1e-6);
    // The microwave sits on the floor of its own frame; its hinge range [-1.5, 0] about -Z is
    // the same motion as [0, 1.5] about +Z.
    let mw = object(&out, "kitchen__mw");
    assert!(
        (mw.parts[0].center.z - 0.15).abs() < 1e-6,
        "{:?}",
        mw.parts[0].center
    );
    let j = &mw.joints[0];
    assert!(
        close(j.axis.as_slice(), &[0.0, 0.0, 1.0], 1e-9),
        "{:?}",
        j.axis
    );
    assert!(close(&j.revolute, &[0.0, 1.5], 1e-9));
    let idx = index(&out);
    let src = idx["objects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["id"] == "kitchen__mw")
        .unwrap()["source"]
        .clone();
    assert_eq!(src["subtree"], "mw");
    assert_eq!(src["front"], "-Y");
    assert_eq!(src["up"], "+Z");
}

#[test]
fn malformed_urdf_names_file_line_and_element_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let src = tmp.path().join("src");
    write_urdf(&src, "a_good", CABINET);
    // Line 4 of the file: a <link> closed by </joint>.
    std::fs::write(
        src.join("b_bad.urdf"),
        "<?xml version=\"1.0\"?>\n<robot name=\"bad\">\n  <link name=\"x\"/>\n  <link name=\"y\">\n  </joint>\n</robot>\n",
    )
    .unwrap();
    let out = tmp.path().join("out");
    let e = import(
        std::slice::from_ref(&src),
        None,
        &out,
        &opts("Box"),
        &small(),
        &|_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("b_bad.urdf:"), "{e}");
    assert!(e.contains("<link>") || e.contains("<y>"), "{e}");
    assert!(!out.exists(), "a partial data set was written");

    // A URDF error (not XML): an unknown joint type, reported at the <joint> line, via the CLI.
    std::fs::write(
        src.join("b_bad.urdf"),
        "<robot name=\"bad\">\n  <link name=\"x\"/>\n  <link name=\"y\"/>\n  <joint name=\"j\" type=\"hinge\">\n    <parent link=\"x\"/><child link=\"y\"/>\n  </joint>\n</robot>\n",
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_physnap"))
        .args(["data", "import", "--urdf"])
        .arg(&src)
        .arg("--out")
        .arg(&out)
        .args(["--category", "Box", "--front=-X"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(stderr.contains("b_bad.urdf:4: <joint>"), "{stderr}");
    assert!(stderr.contains("\"hinge\""), "{stderr}");
    assert!(!out.exists());
    // A zero axis is malformed too.
    let e = import(
        &[write_urdf(
            &tmp.path().join("z"),
            "zero",
            &CABINET.replace("<axis xyz=\"0 1 0\"/>", "<axis xyz=\"0 0 0\"/>"),
        )],
        None,
        &out,
        &opts("Box"),
        &small(),
        &|_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("<axis>") && e.contains("zero vector"), "{e}");
    assert!(!out.exists());
}

fn python() -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let candidates = [
        std::env::var_os("PHYSNAP_MJCF_PYTHON").map(PathBuf::from),
        Some(root.join("tests/tools/mjvenv/bin/python")),
        Some(PathBuf::from("python3")),
    ];
    candidates.into_iter().flatten().find(|p| {
        Command::new(p)
            .args(["-c", "import mujoco"])
            .output()
            .is_ok_and(|o| o.status.success())
    })
}

/// MuJoCo's binary .msh: int32 nvert, nnormal, ntexcoord, nface; float32 vertices, normals,
/// texcoords; int32 faces.
fn msh_bytes(m: &physnap::mesh::TriMesh) -> Vec<u8> {
    let mut b = Vec::new();
    for n in [m.positions.len(), 0, 0, m.triangles.len()] {
        b.extend_from_slice(&(n as i32).to_le_bytes());
    }
    for p in &m.positions {
        for c in p {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in &m.triangles {
        for i in t {
            b.extend_from_slice(&(*i as i32).to_le_bytes());
        }
    }
    b
}

const MJCF: &str = r#"<mujoco model="chest">
  <compiler angle="degree" meshdir="parts"/>
  <default>
    <default class="lidhinge">
      <joint type="hinge" axis="0 1 0" range="0 90" limited="true"/>
    </default>
    <default class="vis">
      <geom contype="0" conaffinity="0" group="1"/>
    </default>
  </default>
  <asset>
    <mesh name="lid" file="lid.msh" scale="0.5 0.4 0.05"/>
  </asset>
  <worldbody>
    <body name="chest" pos="0 0 0">
      <freejoint/>
      <geom class="vis" type="box" pos="0 0 0.2" size="0.25 0.2 0.2"/>
      <geom type="box" pos="0 0 0.2" size="0.25 0.2 0.2"/>
      <body name="lid" pos="0.25 0 0.4" euler="0 0 0">
        <joint name="lid_hinge" class="lidhinge" pos="0 0 0"/>
        <geom class="vis" type="mesh" mesh="lid" pos="-0.25 0 0.025"/>
        <geom type="box" pos="-0.25 0 0.025" size="0.25 0.2 0.025"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"#;

#[test]
fn mjcf_converter_resolves_classes_degrees_and_msh_meshes() {
    let Some(py) = python() else {
        if std::env::var("PHYSNAP_SKIP_MUJOCO").as_deref() == Ok("1") {
            eprintln!("skipped: no python with mujoco (PHYSNAP_SKIP_MUJOCO=1)");
            return;
        }
        panic!(
            "no python with the mujoco package: run .ci/setup (installs mujoco==4.0.0 into tests/tools/mjvenv) or set PHYSNAP_MJCF_PYTHON"
        );
    };
    let tmp = tempfile::tempdir().unwrap();
    let mj = tmp.path().join("mjcf");
    std::fs::create_dir_all(mj.join("parts")).unwrap();
    std::fs::write(mj.join("parts/lid.msh"), msh_bytes(&cube())).unwrap();
    std::fs::write(mj.join("chest.xml"), MJCF).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/mjcf_to_urdf.py");
    let conv = tmp.path().join("urdf");
    let run = |dir: &Path| {
        let o = Command::new(&py)
            .arg(&script)
            .arg(mj.join("chest.xml"))
            .arg(dir)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8(o.stdout).unwrap()
    };
    let info: Value = serde_json::from_str(run(&conv).trim()).unwrap();
    assert_eq!(info["joints"][0]["type"], "revolute");
    assert!(
        (info["joints"][0]["range"][1].as_f64().unwrap() - std::f64::consts::FRAC_PI_2).abs()
            < 1e-6
    );
    // Deterministic: a second conversion writes the same bytes.
    let conv2 = tmp.path().join("urdf2");
    run(&conv2);
    let a = std::fs::read(conv.join("chest.urdf")).unwrap();
    let b = std::fs::read(conv2.join("chest.urdf")).unwrap();
    assert_eq!(a, b);

    let out = tmp.path().join("out");
    let r = import(
        &[conv.join("chest.urdf")],
        None,
        &out,
        &opts("Box"),
        &small(),
        &|_, _| {},
    )
    .unwrap();
    assert_eq!(r.dataset.entries.len(), 1, "{:?}", r.dataset.skipped);
    let o = object(&out, "chest");
    assert_eq!(o.parts.len(), 2);
    // Visual geometry: the body box and the .msh lid (unit cube scaled to 0.5 x 0.4 x 0.05).
    assert!(
        close(o.parts[0].half_extents.as_slice(), &[0.25, 0.2, 0.2], 1e-5),
        "{:?}",
        o.parts[0].half_extents
    );
    assert!(
        close(
            o.parts[1].half_extents.as_slice(),
            &[0.25, 0.2, 0.025],
            1e-5
        ),
        "{:?}",
        o.parts[1].half_extents
    );
    assert!(
        close(o.parts[1].center.as_slice(), &[0.0, 0.0, 0.425], 1e-5),
        "{:?}",
        o.parts[1].center
    );
    let j = &o.joints[0];
    assert!(
        close(j.axis.as_slice(), &[0.0, 1.0, 0.0], 1e-9),
        "{:?}",
        j.axis
    );
    assert!(
        close(j.origin.coords.as_slice(), &[0.25, 0.0, 0.4], 1e-6),
        "{:?}",
        j.origin
    );
    assert!(close(
        &j.revolute,
        &[0.0, std::f64::consts::FRAC_PI_2],
        1e-6
    ));
}

#[test]
fn cli_flags_take_comma_lists_and_have_env_twins() {
    let tmp = tempfile::tempdir().unwrap();
    let src = write_urdf(&tmp.path().join("src"), "spinner", SPINNER);
    let out = tmp.path().join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_physnap"))
        .args(["data", "import", "--urdf"])
        .arg(&src)
        .arg("--out")
        .arg(&out)
        .args(["--continuous-range=-1,1", "--front=-X", "--up", "+Z"])
        .args(["--uniform", "32", "--near", "32", "--surface", "32"])
        .env("PHYSNAP_URDF_CATEGORY", "spinner=Fan")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j = &object(&out, "spinner").joints[0];
    assert!(close(&j.revolute, &[-1.0, 1.0], 1e-12), "{:?}", j.revolute);
    let o = Command::new(env!("CARGO_BIN_EXE_physnap"))
        .args(["data", "import", "--urdf"])
        .arg(&src)
        .arg("--out")
        .arg(tmp.path().join("out2"))
        .args(["--category", "Fan", "--front=+Z"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        stderr.contains("--front") && stderr.contains("perpendicular"),
        "{stderr}"
    );
}
