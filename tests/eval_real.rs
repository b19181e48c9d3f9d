//! `physnap eval real` end to end at toy scale, and scripts/sim_check.py (MuJoCo) on URDFs
//! whose verdict is known. Both need the Python package `mujoco` (CI: `pip install
//! mujoco==4.0.0`; another interpreter via PHYSNAP_PYTHON).

mod support;

use std::path::Path;
use std::process::{Command, Output};

/// PHYSNAP_PYTHON, else .ci/setup's tests/tools/mjvenv, else python3.
fn python() -> String {
    let venv = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/tools/mjvenv/bin/python");
    std::env::var("PHYSNAP_PYTHON").unwrap_or_else(|_| {
        if Path::new(venv).is_file() {
            venv.into()
        } else {
            "python3".into()
        }
    })
}

fn physnap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_physnap"))
        .args(args)
        .env("PHYSNAP_LOG", "warn")
        .env("PHYSNAP_PYTHON", python())
        .output()
        .expect("run physnap")
}

fn ok(args: &[&str]) -> String {
    let o = physnap(args);
    assert!(
        o.status.success(),
        "physnap {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn sim_check(urdfs: &[&Path]) -> serde_json::Value {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/sim_check.py");
    let o = Command::new(python())
        .arg(script)
        .args(urdfs)
        .output()
        .expect("run python");
    assert!(
        o.status.success(),
        "sim_check.py failed (CI must `pip install mujoco==4.0.0`):\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

/// OBJ text of an axis-aligned box.
fn box_obj(c: [f64; 3], h: [f64; 3]) -> String {
    let mut t = String::new();
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                t += &format!(
                    "v {} {} {}\n",
                    c[0] + sx * h[0],
                    c[1] + sy * h[1],
                    c[2] + sz * h[2]
                );
            }
        }
    }
    for f in [
        [0, 1, 3],
        [0, 3, 2],
        [4, 6, 7],
        [4, 7, 5],
        [0, 4, 5],
        [0, 5, 1],
        [2, 3, 7],
        [2, 7, 6],
        [0, 2, 6],
        [0, 6, 4],
        [1, 5, 7],
        [1, 7, 3],
    ] {
        t += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    t
}

/// A 0.6 m cabinet and a 4 cm slab ("door") on a prismatic joint along x at `x`, range
/// [lo, hi]; `mesh` names the door's mesh file.
fn slab_urdf(dir: &Path, name: &str, x: f64, lo: f64, hi: f64, mesh: &str) -> std::path::PathBuf {
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    std::fs::write(
        dir.join("meshes/base.obj"),
        box_obj([0.0, 0.0, 0.5], [0.3, 0.3, 0.5]),
    )
    .unwrap();
    std::fs::write(
        dir.join("meshes/door.obj"),
        box_obj([0.0, 0.0, 0.0], [0.02, 0.3, 0.5]),
    )
    .unwrap();
    let inertial = |m: f64| {
        format!(
            "<inertial><origin xyz=\"0 0 0\" rpy=\"0 0 0\"/><mass value=\"{m}\"/><inertia ixx=\"0.1\" ixy=\"0\" ixz=\"0\" iyy=\"0.1\" iyz=\"0\" izz=\"0.1\"/></inertial>"
        )
    };
    let urdf = format!(
        r#"<?xml version="1.0"?>
<robot name="{name}">
  <link name="base">{}<collision><geometry><mesh filename="meshes/base.obj"/></geometry></collision></link>
  <link name="door">{}<collision><geometry><mesh filename="meshes/{mesh}"/></geometry></collision></link>
  <joint name="joint_door" type="prismatic"><parent link="base"/><child link="door"/>
    <origin xyz="{x} 0 0.5" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="{lo}" upper="{hi}" effort="1" velocity="1"/></joint>
</robot>
"#,
        inertial(10.0),
        inertial(1.0)
    );
    let path = dir.join(format!("{name}.urdf"));
    std::fs::write(&path, urdf).unwrap();
    path
}

#[test]
fn sim_check_tells_clean_jammed_swept_into_and_refused_urdfs_apart() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    // A 3 cm gap at rest, sliding away: clean.
    let clean = slab_urdf(d, "clean", -0.35, -0.2, 0.0, "door.obj");
    // 7 cm inside the cabinet at rest.
    let jam = slab_urdf(d, "jam", -0.25, -0.2, 0.0, "door.obj");
    // Clean at rest, slides 20 cm into the cabinet at its upper limit.
    let swept = slab_urdf(d, "swept", -0.35, 0.0, 0.2, "door.obj");
    // Its mesh does not exist: MuJoCo refuses the file.
    let refused = slab_urdf(d, "refused", -0.35, -0.2, 0.0, "missing.obj");
    let v = sim_check(&[&clean, &jam, &swept, &refused]);
    let r = v["results"].as_array().unwrap();
    assert_eq!(r.len(), 4);
    assert_eq!(r[0]["clean"], true, "{}", r[0]);
    assert_eq!(r[0]["joints"], 1);
    assert_eq!(r[1]["clean"], false);
    assert!(
        (r[1]["rest_depth"].as_f64().unwrap() - 0.07).abs() < 1e-3,
        "{}",
        r[1]
    );
    // Parent and child collide (MuJoCo's parent filter is off).
    assert_eq!(r[1]["worst"]["bodies"], serde_json::json!(["base", "door"]));
    assert_eq!(r[2]["clean"], false);
    assert!(r[2]["rest_depth"].as_f64().unwrap() < 0.005, "{}", r[2]);
    assert!(r[2]["sweep_depth"].as_f64().unwrap() > 0.1, "{}", r[2]);
    assert_eq!(r[3]["compiled"], false);
    assert_eq!(r[3]["clean"], false);
    assert!(
        r[3]["error"].as_str().unwrap().contains("missing"),
        "{}",
        r[3]
    );
}

#[test]
fn sim_check_on_the_exported_example_cabinet() {
    // real-scans.md §4: the hand-made cabinet, whose parts do not overlap, jams in MuJoCo as
    // exported (contacts deeper than 5 mm at rest).
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("cab");
    let example = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/cabinet.json");
    ok(&["export", "--object", example, "--out", s(&out)]);
    let v = sim_check(&[&out.join("robot.urdf")]);
    let r = &v["results"][0];
    assert_eq!(r["compiled"], true, "{r}");
    assert!(r["joints"].as_u64().unwrap() >= 1, "{r}");
    assert!(r["rest_depth"].as_f64().is_some() && r["sweep_depth"].as_f64().is_some());
}

#[test]
fn eval_real_on_two_procedural_objects_resumes_and_refuses_other_settings() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let (src, data, weights, out) = (
        root.join("synth"),
        root.join("data"),
        root.join("weights"),
        root.join("out"),
    );
    ok(&[
        "data",
        "synth",
        "--out",
        s(&src),
        "--objects",
        "2",
        "--seed",
        "99",
    ]);
    ok(&[
        "data",
        "import",
        "--partnet-mobility",
        s(&src),
        "--out",
        s(&data),
        "--uniform",
        "64",
        "--near",
        "64",
        "--surface",
        "64",
    ]);
    // The benchmark layout: one record + cloud per scan in DATA/scans.
    let scans = data.join("scans");
    std::fs::create_dir_all(&scans).unwrap();
    for id in ["000000", "000001"] {
        let cloud = scans.join(format!("{id}_0.ply"));
        ok(&[
            "data",
            "scan",
            "--object",
            s(&src.join(id)),
            "--out",
            s(&cloud),
            "--points",
            "300",
        ]);
        let category = json(&data.join("objects").join(id).join("object.json"))["category"].clone();
        std::fs::write(
            scans.join(format!("{id}_0.json")),
            serde_json::json!({"object": id, "category": category, "camera": [-2.0, 0.5, 1.5]})
                .to_string(),
        )
        .unwrap();
    }
    support::tiny_weights(&weights);
    let args = [
        "eval",
        "real",
        "--weights",
        s(&weights),
        "--data",
        s(&data),
        "--out",
        s(&out),
        "--samples",
        "2",
        "--steps",
        "20",
        "--guidance-refine-steps",
        "2",
        "--guidance-refine-physics-steps",
        "0",
        "--resolution",
        "16",
    ];
    let stdout = ok(&args);
    assert!(stdout.contains("| prior+category |"), "{stdout}");
    assert!(stdout.contains("| best-of-2+category |"), "{stdout}");
    assert!(stdout.contains("## Per category"), "{stdout}");
    let md = std::fs::read_to_string(out.join("real.md")).unwrap();
    assert!(md.contains("2 scans of 2 objects"), "{md}");
    let report = json(&out.join("real.json"));
    assert_eq!(report["format"], "physnap.eval_real/v1");
    let rows = report["rows"].as_array().unwrap();
    let keys: Vec<&str> = rows.iter().map(|r| r["row"].as_str().unwrap()).collect();
    assert_eq!(
        keys,
        ["prior+category", "guided+category", "best-of-2+category"]
    );
    for r in rows {
        assert_eq!(r["overall"]["jobs"], 2, "{r}");
        assert_eq!(r["objects"].as_object().unwrap().len(), 2);
        assert!(!r["categories"].as_object().unwrap().is_empty());
    }
    let scans = report["scans"].as_array().unwrap();
    assert_eq!(scans.len(), 2);
    for sc in scans {
        assert!(sc["gt_joints"].as_u64().unwrap() >= 1, "{sc}");
        let jobs = sc["jobs"].as_array().unwrap();
        assert_eq!(jobs.len(), 3);
        // guided is best-of-2's sample 0: same seed as sample 0 of the best-of draws.
        assert_eq!(jobs[1]["best_seed"], 0, "{}", jobs[1]);
        for j in jobs {
            if j["failed"] == false {
                let dir = out
                    .join("jobs")
                    .join(sc["scan"].as_str().unwrap())
                    .join(j["row"].as_str().unwrap());
                assert!(dir.join("robot.urdf").is_file());
                assert!(j["sim"]["compiled"].is_boolean(), "{j}");
                let m = &j["metrics"];
                assert_eq!(
                    m["joints"].as_array().unwrap().len() as u64,
                    sc["gt_joints"].as_u64().unwrap()
                );
                assert!(m["chamfer_diag"].as_f64().unwrap() > 0.0);
            }
        }
        assert!(
            out.join("scans")
                .join(format!("{}.json", sc["scan"].as_str().unwrap()))
                .is_file()
        );
    }
    // A second run resumes from the per-scan files.
    let again = ok(&args);
    assert!(again.contains("2 scans resumed"), "{again}");
    assert_eq!(json(&out.join("real.json"))["scans"], report["scans"]);
    // Other settings on the same OUT are refused.
    let mut other: Vec<&str> = args.to_vec();
    other.extend(["--seed", "5"]);
    let o = physnap(&other);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--fresh"));
}
