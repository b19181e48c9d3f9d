//! The `physnap export` command as a user runs it: success path, env twins, and clear errors
//! that name the field, the limit and the value.

use std::path::Path;
use std::process::{Command, Output};

fn physnap(args: &[&str], envs: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_physnap"));
    cmd.args(args).env("PHYSNAP_LOG", "warn");
    for (k, v) in envs {
        cmd.env(k, v);
    }
    cmd.output().expect("run physnap")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

const EXAMPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/cabinet.json");

#[test]
fn export_writes_all_artefacts() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = physnap(
        &[
            "export",
            "--object",
            EXAMPLE,
            "--out",
            out.to_str().unwrap(),
            "--resolution",
            "32",
        ],
        &[],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "model.glb",
        "robot.urdf",
        "robot.zip",
        "object.json",
        "meshes/body.obj",
        "meshes/door.obj",
        "meshes/drawer.obj",
    ] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    // The printed file list is what a script would consume.
    let listed = String::from_utf8_lossy(&o.stdout);
    assert!(listed.lines().any(|l| l.ends_with("model.glb")));
}

#[test]
fn env_twins_replace_flags() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = physnap(
        &["export"],
        &[
            ("PHYSNAP_OBJECT", EXAMPLE),
            ("PHYSNAP_OUT", out.to_str().unwrap()),
            ("PHYSNAP_MC_RESOLUTION", "16"),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("model.glb").is_file());
}

fn export_err(dir: &Path, json: &str) -> String {
    let obj = write(dir, "bad.json", json);
    let o = physnap(
        &[
            "export",
            "--object",
            &obj,
            "--out",
            dir.join("o").to_str().unwrap(),
        ],
        &[],
    );
    assert!(!o.status.success(), "a bad object must fail");
    assert!(
        !dir.join("o/model.glb").exists(),
        "nothing is written for a bad object"
    );
    stderr(&o)
}

fn cabinet_with(f: impl FnOnce(&mut serde_json::Value)) -> String {
    let mut v: serde_json::Value = serde_json::from_str(physnap::fixtures::CABINET_JSON).unwrap();
    f(&mut v);
    v.to_string()
}

#[test]
fn malformed_json_names_the_place() {
    let dir = tempfile::tempdir().unwrap();
    let e = export_err(
        dir.path(),
        "{\"name\": \"x\", \"parts\": [ {\"name\": 3} ]}",
    );
    assert!(
        e.contains("malformed object JSON") && e.contains("parts[0].name"),
        "{e}"
    );
    let e = export_err(dir.path(), "{ not json");
    assert!(
        e.contains("malformed object JSON") && e.contains("line 1"),
        "{e}"
    );
    let e = export_err(
        dir.path(),
        &cabinet_with(|v| v["parts"][0]["colour"] = "red".into()),
    );
    assert!(e.contains("unknown field `colour`"), "{e}");
}

#[test]
fn negative_box_size_names_field_limit_and_value() {
    let dir = tempfile::tempdir().unwrap();
    let e = export_err(
        dir.path(),
        &cabinet_with(|v| v["parts"][1]["half_extents"][2] = (-0.5).into()),
    );
    assert!(
        e.contains("parts[1].half_extents[2]") && e.contains("> 0") && e.contains("-0.5"),
        "{e}"
    );
}

#[test]
fn non_finite_values_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    // JSON has no NaN; a literal NaN or an overflowing number is refused by the parser, with its place.
    let text = physnap::fixtures::CABINET_JSON.replacen("[0.0, 0.0, 0.4]", "[0.0, NaN, 0.4]", 1);
    let e = export_err(dir.path(), &text);
    assert!(
        e.contains("malformed object JSON") && e.contains("parts[0].center"),
        "{e}"
    );
    let text = physnap::fixtures::CABINET_JSON.replacen("[0.0, 0.0, 0.4]", "[0.0, 1e999, 0.4]", 1);
    let e = export_err(dir.path(), &text);
    assert!(e.contains("parts[0].center"), "{e}");
}

#[test]
fn more_than_eight_parts_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let e = export_err(
        dir.path(),
        &cabinet_with(|v| {
            let door = v["parts"][1].clone();
            let parts = v["parts"].as_array_mut().unwrap();
            for i in 0..7 {
                let mut p = door.clone();
                p["name"] = format!("extra{i}").into();
                parts.push(p);
            }
        }),
    );
    assert!(
        e.contains("parts") && e.contains("between 1 and 8") && e.contains("10 parts"),
        "{e}"
    );
}

#[test]
fn bad_joint_references_and_axes_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let e = export_err(
        dir.path(),
        &cabinet_with(|v| v["joints"][0]["child"] = "lid".into()),
    );
    assert!(
        e.contains("joints[0].child") && e.contains("\"lid\""),
        "{e}"
    );
    let e = export_err(
        dir.path(),
        &cabinet_with(|v| v["joints"][1]["axis"] = serde_json::json!([0, 0, 0])),
    );
    assert!(
        e.contains("joints[1].axis") && e.contains("non-zero"),
        "{e}"
    );
    let e = export_err(
        dir.path(),
        &cabinet_with(|v| v["joints"][0]["revolute"] = serde_json::json!([2.0, 1.0])),
    );
    assert!(
        e.contains("joints[0].revolute") && e.contains("lower <= upper") && e.contains("[2, 1]"),
        "{e}"
    );
}

#[test]
fn bad_resolution_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let o = physnap(
        &[
            "export",
            "--object",
            EXAMPLE,
            "--out",
            dir.path().to_str().unwrap(),
            "--resolution",
            "1000",
        ],
        &[],
    );
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("resolution") && e.contains("between 8 and 256") && e.contains("1000"),
        "{e}"
    );
}

#[test]
fn missing_file_is_reported() {
    let o = physnap(
        &[
            "export",
            "--object",
            "/nonexistent/x.json",
            "--out",
            "/tmp/x",
        ],
        &[],
    );
    assert!(!o.status.success());
    assert!(stderr(&o).contains("/nonexistent/x.json"), "{}", stderr(&o));
}

#[test]
fn negative_progress_interval_names_flag_limit_and_value() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let args = [
        "export",
        "--object",
        EXAMPLE,
        "--out",
        out.to_str().unwrap(),
    ];
    let o = physnap(&args, &[("PHYSNAP_PROGRESS_INTERVAL", "-1")]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--progress-interval must be finite and >= 0 seconds (0: off), got -1"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists(), "nothing is written after a refused flag");
}

#[test]
fn train_device_names_the_flag_the_choices_and_the_value() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let missing = dir.path().join("no-data");
    let (data, out_s) = (missing.to_str().unwrap(), out.to_str().unwrap());
    // Checked before any data is read, so a typo costs nothing.
    let shape = ["train", "shape", "--data", data, "--out", out_s];
    let o = physnap(&shape, &[("PHYSNAP_TRAIN_DEVICE", "tpu")]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("device") && e.contains("cpu, gpu or gpu:N") && e.contains("tpu"),
        "{e}"
    );
    let diffusion = [
        "train",
        "diffusion",
        "--data",
        data,
        "--shape",
        data,
        "--out",
        out_s,
        "--device",
        "gpu:0",
    ];
    let o = physnap(&diffusion, &[]);
    assert!(!o.status.success());
    let e = stderr(&o);
    if cfg!(feature = "gpu") {
        assert!(e.contains("no-data"), "a GPU build gets to the data: {e}");
    } else {
        assert!(
            e.contains("device") && e.contains("--features gpu") && e.contains("gpu:0"),
            "{e}"
        );
    }
    assert!(!out.exists(), "nothing is written after a refused flag");
}

#[test]
fn eval_guided_refuses_unknown_variants_and_empty_cloud_folders() {
    let dir = tempfile::tempdir().unwrap();
    let clouds = dir.path().join("clouds");
    std::fs::create_dir(&clouds).unwrap();
    let weights = concat!(env!("CARGO_MANIFEST_DIR"), "/weights");
    let out = dir.path().join("out").display().to_string();
    let clouds_s = clouds.display().to_string();
    let args = |extra: &[&'static str]| {
        let mut a: Vec<String> = [
            "eval",
            "guided",
            "--weights",
            weights,
            "--clouds",
            &clouds_s,
            "--out",
            &out,
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let run = |a: Vec<String>| {
        let refs: Vec<&str> = a.iter().map(String::as_str).collect();
        physnap(&refs, &[])
    };
    // No clouds: the folder is named.
    let o = run(args(&[]));
    assert!(!o.status.success());
    assert!(stderr(&o).contains("no point clouds"), "{}", stderr(&o));
    // An unknown row name: the field, the allowed names and the value.
    std::fs::copy(
        concat!(env!("CARGO_MANIFEST_DIR"), "/examples/scan_microwave.ply"),
        clouds.join("scan.ply"),
    )
    .unwrap();
    let o = run(args(&[
        "--variants",
        "pc,pc+penn",
        "--samples-per-cloud",
        "1",
    ]));
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("variants") && e.contains("pc+penn") && e.contains("pc+pen+mob"),
        "{e}"
    );
    assert!(!dir.path().join("out/guided_table.md").exists());
    // Skipping every cloud: the flag, the limit and the value.
    let o = run(args(&["--skip-clouds", "1"]));
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("--skip-clouds") && e.contains("below the 1 clouds") && e.contains(": 1"),
        "{e}"
    );
    // A sweep picks its own rows; bad sweep values are named.
    let o = run(args(&["--sweep", "pen", "--variants", "pc"]));
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--variants with --sweep"),
        "{}",
        stderr(&o)
    );
    let o = run(args(&["--sweep", "mob", "--sweep-weights", "1,0"]));
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("sweep_weights") && e.contains("> 0"), "{e}");
    // A tiny τ sweep runs end to end: the baseline row and one row per τ.
    let o = run(args(&[
        "--sweep",
        "tau",
        "--sweep-tau",
        "100,1000",
        "--samples-per-cloud",
        "1",
        "--category-aware",
        "no",
        "--steps",
        "3",
        "--resolution",
        "8",
    ]));
    assert!(o.status.success(), "{}", stderr(&o));
    let md = std::fs::read_to_string(dir.path().join("out/sweep_tau.md")).unwrap();
    assert!(
        md.contains("| no | uncond |") && md.contains("| no | pc τ=1000 |"),
        "{md}"
    );
    assert_eq!(md.lines().count(), 2 + 3, "{md}");
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("out/sweep_tau.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(json["sweep"], "tau");
    assert_eq!(json["rows"][1]["guidance"]["tau"], 100.0);
    assert_eq!(json["rows"][1]["guidance"]["w_pc"], 45.0);
}

const SCAN: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/scan_microwave.ply");
const WEIGHTS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/weights");

/// A short guided `generate` of the example scan with extra flags.
fn generate(out: &Path, extra: &[&str]) -> Output {
    physnap(&generate_args(out, SCAN, extra), &[])
}

/// The arguments of a short guided `generate` of `points` with extra flags.
fn generate_args<'a>(out: &'a Path, points: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "generate",
        "--weights",
        WEIGHTS,
        "--points",
        points,
        "--category",
        "Microwave",
        "--steps",
        "8",
        "--guidance-refine-steps",
        "2",
        "--resolution",
        "16",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    args
}

#[test]
fn a_camera_turns_on_free_space_and_ranking_json_lists_every_term() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("g");
    let o = generate(&out, &["--samples", "2", "--camera", "-0.9,0.3,0.6"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("ℓ_free"), "{stdout}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ranking.json")).unwrap()).unwrap();
    assert_eq!(r["guidance"]["w_free"], 15.0);
    assert_eq!(r["guidance"]["cameras"].as_array().unwrap().len(), 1);
    // n_g as the paper (and REST, gRPC) mean it: t < 500 guided.
    assert_eq!(r["guidance"]["n_g"], 500);
    let samples = r["samples"].as_array().unwrap();
    assert_eq!(samples.len(), 2);
    let scores: Vec<f64> = samples
        .iter()
        .map(|s| s["score"].as_f64().unwrap())
        .collect();
    assert!(scores[0] <= scores[1], "ranked by score: {scores:?}");
    for s in samples {
        for t in [
            "d_pc_per_scan_diagonal",
            "free",
            "attach_per_object_diagonal",
            "o_mesh",
            "sim_depth_per_object_diagonal",
        ] {
            assert!(s["terms"][t].is_number(), "{t} missing in {s}");
        }
        assert!(s["terms"]["sim"]["clean"].is_boolean(), "{s}");
        let sum: f64 = [
            "d_pc_per_scan_diagonal",
            "free",
            "attach_per_object_diagonal",
            "o_mesh",
            "sim_depth_per_object_diagonal",
        ]
        .iter()
        .map(|t| s["terms"][t].as_f64().unwrap())
        .sum();
        assert!((sum - s["score"].as_f64().unwrap()).abs() < 1e-9, "{s}");
        assert!(s["removed"].is_array() && s["repairs"].is_number(), "{s}");
    }
}

#[test]
fn bad_cameras_name_the_flag_the_limit_and_the_value() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("g");
    let err = stderr(&generate(&out, &["--camera", "0,0,0.1"]));
    assert!(
        err.contains("guidance.cameras[0]")
            && err.contains("outside the points' box")
            && err.contains("0.1"),
        "{err}"
    );
    let err = stderr(&generate(&out, &["--camera", "nan,0,1"]));
    assert!(
        err.contains("--camera") && err.contains("nan,0,1") && err.contains("finite"),
        "{err}"
    );
    let err = stderr(&generate(&out, &["--camera", "1,2"]));
    assert!(err.contains("--camera") && err.contains("x,y,z"), "{err}");
    let many = vec!["-1,0,0"; 17].join(";");
    let o = physnap(
        &[
            "generate",
            "--weights",
            WEIGHTS,
            "--points",
            SCAN,
            "--steps",
            "8",
            "--out",
            out.to_str().unwrap(),
        ],
        &[("PHYSNAP_CAMERA", &many)],
    );
    let err = stderr(&o);
    assert!(
        err.contains("guidance.cameras") && err.contains("at most 16") && err.contains("17"),
        "{err}"
    );
    let err = stderr(&physnap(
        &[
            "generate",
            "--weights",
            WEIGHTS,
            "--camera",
            "-1,0,0",
            "--out",
            out.to_str().unwrap(),
        ],
        &[],
    ));
    assert!(
        err.contains("--camera") && err.contains("--points"),
        "{err}"
    );
}

#[test]
fn check_sim_passes_the_example_and_fails_a_jammed_drawer() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cab");
    let args = |obj: &str, out: &Path| {
        physnap(
            &["export", "--object", obj, "--out", out.to_str().unwrap()],
            &[],
        )
    };
    let o = args(EXAMPLE, &out);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("sim-clean"), "{}", stderr(&o));
    assert!(out.join("model.xml").is_file() && out.join("meshes/body_collision_0.obj").is_file());
    let o = physnap(&["check-sim", out.to_str().unwrap()], &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("sim-clean"));
    let o = physnap(&["check-sim", out.to_str().unwrap(), "--json"], &[]);
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["format"], "physnap.sim_report/v1");
    assert_eq!(doc["clean"], true);
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("object.json")).unwrap()).unwrap();
    assert_eq!(written["sim"]["clean"], true, "{written}");

    // The drawer slides the wrong way, through the body's back wall.
    let mut obj: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(EXAMPLE).unwrap()).unwrap();
    let drawer = obj["joints"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .find(|j| j["type"] == "prismatic")
        .unwrap();
    drawer["axis"] = serde_json::json!([1.0, 0.0, 0.0]);
    let jammed = write(dir.path(), "jammed.json", &obj.to_string());
    let out2 = dir.path().join("jammed");
    let o = args(&jammed, &out2);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("NOT sim-clean"), "{}", stderr(&o));
    let o = physnap(&["check-sim", out2.to_str().unwrap()], &[]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("not sim-clean") && e.contains("exceeds 0.005 m"),
        "{e}"
    );
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("drawer"),
        "the worst pair is named"
    );

    // An export without collision pieces (written before they existed) is decomposed.
    for e in std::fs::read_dir(out.join("meshes")).unwrap() {
        let p = e.unwrap().path();
        if p.to_string_lossy().contains("_collision_") {
            std::fs::remove_file(p).unwrap();
        }
    }
    let o = physnap(
        &["check-sim", out.to_str().unwrap()],
        &[("PHYSNAP_LOG", "warn")],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("decomposed its visual meshes"),
        "{}",
        stderr(&o)
    );

    // Bad input names the field, the limit and the value.
    let o = physnap(&["check-sim", out.to_str().unwrap(), "--states", "0"], &[]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("sim.states") && stderr(&o).contains("1..=101"),
        "{}",
        stderr(&o)
    );
    let o = physnap(
        &["check-sim", dir.path().join("nowhere").to_str().unwrap()],
        &[],
    );
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("object.json") && stderr(&o).contains("export directory"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn bad_collision_and_inertial_flags_name_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    for (flag, value, field, limit) in [
        ("--collision-pieces", "0", "collision.max_pieces", "1..=64"),
        (
            "--collision-vertices",
            "4",
            "collision.max_vertices",
            "8..=256",
        ),
        (
            "--collision-resolution",
            "1000",
            "collision.resolution",
            "16..=128",
        ),
        ("--density", "0", "density", "> 0"),
    ] {
        let o = physnap(
            &[
                "export",
                "--object",
                EXAMPLE,
                "--out",
                out.to_str().unwrap(),
                flag,
                value,
            ],
            &[],
        );
        assert!(!o.status.success(), "{flag} {value} was accepted");
        let e = stderr(&o);
        assert!(
            e.contains(field) && e.contains(limit) && e.contains(value),
            "{flag}: {e}"
        );
        assert!(
            !out.join("robot.urdf").exists(),
            "{flag}: nothing is written"
        );
    }
}

#[test]
fn frame_auto_finds_the_scans_frame_and_returns_the_model_in_it() {
    use physnap::eval::real::frame::{MovedUp, frame_error, move_of, moved};
    let dir = tempfile::tempdir().unwrap();
    // The example scan moved into a user's frame: +Y up, a random yaw, up to 2 m away.
    let limits = physnap::pointcloud::Limits {
        min_points: 1,
        max_points: 100_000,
    };
    let scan = physnap::pointcloud::PointCloud::read(Path::new(SCAN), &limits)
        .unwrap()
        .points;
    let m = move_of("cli", 0, MovedUp::Y);
    let points = moved(&m, &scan);
    let eye = moved(&m, &[[-0.9, 0.3, 0.6]])[0];
    let cloud = write(
        dir.path(),
        "moved.json",
        &serde_json::to_string(&points).unwrap(),
    );
    let camera = format!("{},{},{}", eye[0], eye[1], eye[2]);
    let out = dir.path().join("g");
    let mut args = generate_args(&out, &cloud, &["--camera", &camera]);
    let o = physnap(&args, &[("PHYSNAP_FRAME", "auto"), ("PHYSNAP_UP", "0,1,0")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let sample = out.join("sample_000");
    let text = std::fs::read_to_string(sample.join("object.json")).unwrap();
    let frame = physnap::io::object_json::frame_from_str(&text)
        .unwrap()
        .expect("object.json has the frame");
    let err = frame_error(&m, &frame);
    assert!(err.yaw_deg < 10.0 && err.floor_m < 0.05, "{err:?}");
    let doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(doc["frame"]["mode"], "auto");
    assert_eq!(
        doc["scan_frame"]["parts"].as_array().unwrap().len(),
        doc["parts"].as_array().unwrap().len()
    );
    // The model sits on the scan: every part centre (scan frame) inside the scan's box, grown
    // by a quarter of its diagonal.
    let (lo, hi) = physnap::engine::free_space::bounds(&points);
    let grow = 0.25 * physnap::engine::free_space::extent(&points);
    for p in doc["scan_frame"]["parts"].as_array().unwrap() {
        for k in 0..3 {
            let c = p["center"][k].as_f64().unwrap() as f32;
            assert!(
                c > lo[k] - grow && c < hi[k] + grow,
                "{p} outside {lo:?}..{hi:?}"
            );
        }
    }
    let ranking: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ranking.json")).unwrap()).unwrap();
    assert_eq!(ranking["frame"]["chosen_by"], "planes+camera");
    assert!(ranking["frame"]["floor"].is_number(), "{ranking}");
    assert_eq!(ranking["frame"]["hypotheses"].as_array().unwrap().len(), 4);
    let urdf = std::fs::read_to_string(sample.join("robot.urdf")).unwrap();
    assert!(urdf.contains("<link name=\"world\"/>"), "{urdf}");
    // Bad frames: a zero up, and auto without a scan.
    args.extend_from_slice(&["--frame", "auto", "--up", "0,0,0"]);
    let o = physnap(&args, &[]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("up") && e.contains("non-zero") && e.contains("0,0,0"),
        "{e}"
    );
    let o = physnap(
        &[
            "generate",
            "--weights",
            WEIGHTS,
            "--frame",
            "auto",
            "--out",
            dir.path().join("h").to_str().unwrap(),
        ],
        &[],
    );
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--frame auto: needs --points"),
        "{}",
        stderr(&o)
    );
}
