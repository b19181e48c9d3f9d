//! The whole model pipeline as a user runs it, at toy scale: synth → import → train shape →
//! train diffusion (writes weights + manifest) → generate (GLB/URDF per sample). CI never trains
//! a real model: a few steps of tiny configs only.

mod common;

use std::path::Path;
use std::process::{Command, Output};

fn physnap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_physnap"))
        .args(args)
        .env("PHYSNAP_LOG", "warn")
        .output()
        .expect("run physnap")
}

fn ok(args: &[&str]) -> String {
    let o = physnap(args);
    assert!(
        o.status.success(),
        "physnap {args:?} failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// How many `train diffusion` runs the recipe script logged (`+ physnap …` on stderr) with
/// `flag`.
fn diffusion_runs_with(err: &str, flag: &str) -> usize {
    err.lines()
        .filter(|l| l.starts_with("+ physnap train diffusion") && l.contains(flag))
        .count()
}

/// `eval shape` on the prior of `weights` with `extra`.
fn shape_args(weights: &Path, data: &Path, extra: &[&str]) -> Vec<String> {
    ["eval", "shape", "--weights", s(weights), "--data", s(data)]
        .iter()
        .chain(extra)
        .map(|a| a.to_string())
        .collect()
}

/// The `&str`s of `args`, as `physnap` and `ok` take them.
fn strs(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}

/// The sum of a JSON object of counts (a report's `nearest` row).
fn count_sum(counts: &serde_json::Value) -> u64 {
    counts
        .as_object()
        .expect("an object of counts")
        .values()
        .map(|n| n.as_u64().expect("a count"))
        .sum()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Corrupt a weights file: flip one byte near its end.
fn flip_byte(path: &Path) {
    let mut bytes = std::fs::read(path).unwrap();
    let n = bytes.len();
    bytes[n - 3] ^= 0xFF;
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn synth_import_train_generate() {
    let root = tempfile::tempdir().unwrap();
    let (synth, data, shape, weights, gen1, gen2) = (
        root.path().join("synth"),
        root.path().join("train"),
        root.path().join("shape"),
        root.path().join("weights"),
        root.path().join("gen1"),
        root.path().join("gen2"),
    );
    ok(&[
        "data",
        "synth",
        "--out",
        s(&synth),
        "--objects",
        // Three per category: every category gets a val and a test object.
        "39",
        "--seed",
        "4",
    ]);
    ok(&[
        "data",
        "import",
        "--partnet-mobility",
        s(&synth),
        "--out",
        s(&data),
        "--uniform",
        "256",
        "--near",
        "256",
        "--surface",
        "64",
    ]);
    // Under `output()` stderr is not a terminal: the bar is hidden and progress comes as log
    // lines every --progress-interval seconds instead.
    // A non-default model and loss: the sizes flow through the manifest to every loader.
    let sizes = [
        "--batch-parts",
        "4",
        "--decoder-hidden",
        "48",
        "--decoder-blocks",
        "2",
        "--encoder-hidden",
        "32",
        "--encoder-blocks",
        "1",
        "--queries-per-part",
        "512",
        "--surface-points",
        "64",
    ];
    let mut args = vec![
        "--log",
        "info",
        "--progress-interval",
        "0.02",
        "train",
        "shape",
        "--data",
        s(&data),
        "--out",
        s(&shape),
        "--steps",
        "6",
        "--truncation",
        "0.1",
    ];
    args.extend(sizes);
    let o = physnap(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "train shape failed:\n{err}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(shape.join("shape_train.json")).unwrap())
            .unwrap();
    let c = &report["config"];
    assert_eq!(
        (
            &c["model"]["decoder_hidden"],
            &c["model"]["encoder_blocks"],
            &c["queries_per_part"],
            &c["surface_points"],
        ),
        (
            &serde_json::json!(48),
            &serde_json::json!(1),
            &serde_json::json!(512),
            &serde_json::json!(64)
        ),
        "{c:#}"
    );
    assert!(
        (c["truncation"].as_f64().unwrap() - 0.1).abs() < 1e-6,
        "{c:#}"
    );
    // An out-of-range size is refused, naming the field, the limit and the value.
    let o = physnap(&[
        "train",
        "shape",
        "--data",
        s(&data),
        "--out",
        s(&root.path().join("bad_shape")),
        "--decoder-hidden",
        "0",
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("decoder_hidden") && e.contains("between 1 and") && e.contains('0'),
        "{e}"
    );
    assert!(
        err.lines()
            .any(|l| l.contains("shape: ") && l.contains("/6 (")),
        "no progress lines on a non-terminal stderr:\n{err}"
    );
    for f in [
        "shape_prior.safetensors",
        "codebook.npy",
        "codebook.json",
        "shape_train.json",
    ] {
        assert!(shape.join(f).is_file(), "missing {f}");
    }
    // A tiny denoiser on that codebook: `steps` steps into `out`, with `extra` flags.
    let diffusion = |out: &Path, steps: &str, extra: &[&str]| {
        let mut args = vec![
            "train",
            "diffusion",
            "--data",
            s(&data),
            "--shape",
            s(&shape),
            "--out",
            s(out),
            "--steps",
            steps,
            "--batch-objects",
            "2",
            "--noise-levels",
            "2",
            "--width",
            "32",
            "--layers",
            "1",
        ];
        args.extend_from_slice(extra);
        physnap(&args)
    };
    let o = diffusion(&weights, "4", &["--category-dropout", "0.1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(weights.join("manifest.json")).unwrap())
            .unwrap();
    assert_eq!(manifest["format"], "physnap.weights/v1");
    assert_eq!(
        manifest["training"]["diffusion"]["category_dropout"], 0.1,
        "{manifest:#}"
    );
    let o = diffusion(
        &root.path().join("refused"),
        "4",
        &["--category-dropout", "1.5"],
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("category_dropout") && err.contains("1.5"),
        "{err}"
    );
    // --layout-gain: the manifest carries the scales the run trained in (box and centre ÷ G),
    // which is all sampling reads; an out-of-range gain is refused by name.
    let gained = root.path().join("gained");
    let run =
        |gain: &str, out: &Path| diffusion(out, "2", &["--no-codebook", "--layout-gain", gain]);
    assert!(run("2", &gained).status.success());
    let g: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(gained.join("manifest.json")).unwrap())
            .unwrap();
    let node = |m: &serde_json::Value, c: usize| m["feature_scales"]["node"][c].as_f64().unwrap();
    use physnap::graph::node_ch;
    for c in 0..node_ch::LATENT + 3 {
        let want = if (node_ch::BOX..node_ch::LATENT).contains(&c) {
            node(&manifest, c) / 2.0
        } else {
            node(&manifest, c)
        };
        assert!(
            (node(&g, c) - want).abs() <= 1e-6 * want,
            "channel {c}: {g:#}"
        );
    }
    let o = run("9", &root.path().join("refused_gain"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success()
            && err.contains("layout_gain")
            && err.contains("9")
            && err.contains("[0.25, 8]"),
        "{err}"
    );
    assert_eq!(manifest["categories"].as_array().unwrap().len(), 46);
    assert_eq!(manifest["denoiser"]["sha256"].as_str().unwrap().len(), 64);
    assert_eq!(manifest["shape_prior"]["config"]["decoder_hidden"], 48);
    // The retrieval codebook: training-split codes that mesh non-empty, sha256 in the manifest.
    let cb = &manifest["codebook"];
    let rows = cb["config"]["rows"].as_u64().unwrap() as usize;
    assert!(
        rows >= 1 && rows <= cb["config"]["candidates"].as_u64().unwrap() as usize,
        "{cb}"
    );
    let codebook = physnap::model::codebook::Codebook::load(
        &weights.join("codebook.safetensors"),
        rows,
        128,
        Some(manifest["categories"].as_array().unwrap().len()),
        cb["sha256"].as_str(),
    )
    .unwrap();

    // Generation is deterministic per seed and writes valid artefacts.
    let args = |out: &Path| -> Vec<String> {
        [
            "generate",
            "--weights",
            s(&weights),
            "--samples",
            "2",
            "--seed",
            "9",
            "--category",
            "Laptop",
            "--resolution",
            "16",
            "--out",
            s(out),
        ]
        .iter()
        .map(|x| x.to_string())
        .collect()
    };
    let a1 = args(&gen1);
    ok(&a1.iter().map(String::as_str).collect::<Vec<_>>());
    let a2 = args(&gen2);
    ok(&a2.iter().map(String::as_str).collect::<Vec<_>>());
    for k in ["sample_000", "sample_001"] {
        let j1 = std::fs::read(gen1.join(k).join("object.json")).unwrap();
        assert_eq!(
            j1,
            std::fs::read(gen2.join(k).join("object.json")).unwrap(),
            "{k} differs between runs"
        );
        let obj = physnap::io::object_json::from_str(std::str::from_utf8(&j1).unwrap()).unwrap();
        assert!(obj.parts.len() >= 2);
        assert_eq!(obj.category.as_deref(), Some("Laptop"));
        common::check_urdf(&gen1.join(k).join("robot.urdf"));
        let report = common::gltf_validate(&gen1.join(k).join("model.glb"));
        assert_eq!(report["numErrors"], 0, "{report:#}");
    }

    // Generate sample 0 (seed 9, 16³) with `extra` flags: (stdout, its object, its latent codes).
    let retrieved = |dir: &str, extra: &[&str]| {
        let out_dir = root.path().join(dir);
        let mut args = vec![
            "generate",
            "--weights",
            s(&weights),
            "--seed",
            "9",
            "--resolution",
            "16",
            "--out",
            s(&out_dir),
        ];
        args.extend_from_slice(extra);
        let out = ok(&args);
        let j = std::fs::read_to_string(out_dir.join("sample_000/object.json")).unwrap();
        let obj = physnap::io::object_json::from_str(&j).unwrap();
        let codes: Vec<(String, Vec<f32>)> = obj
            .parts
            .iter()
            .filter_map(|p| match &p.shape {
                physnap::shape::PartShape::Latent(code) => Some((p.name.clone(), code.clone())),
                _ => None,
            })
            .collect();
        assert!(!codes.is_empty(), "{j}");
        (out, codes)
    };
    // --retrieval all: every latent part takes a codebook code, and says so.
    let (out, codes) = retrieved("gen3", &["--retrieval", "all"]);
    assert!(out.contains("took their nearest codebook shape"), "{out}");
    for (name, code) in &codes {
        assert_eq!(
            codebook.nearest(code).unwrap().1,
            0.0,
            "{name} not retrieved"
        );
    }
    // --retrieval category: every latent part takes a code of the requested category's
    // training parts (the codes carry categories: train shape wrote them into the keys).
    assert_eq!(cb["config"]["categories"], true, "{cb}");
    let cats = codebook.categories().unwrap();
    let c = cats[0] as usize;
    let category = manifest["categories"][c].as_str().unwrap();
    let (_, codes) = retrieved("gen4", &["--category", category, "--retrieval", "category"]);
    for (name, code) in &codes {
        let (row, d) = codebook.nearest_in(code, Some(c)).unwrap();
        assert_eq!(d, 0.0, "{name} not retrieved from {category}");
        assert_eq!(cats[row] as usize, c);
    }
    // Without a category it is refused, naming the flag.
    let o = physnap(&[
        "generate",
        "--weights",
        s(&weights),
        "--retrieval",
        "category",
        "--out",
        s(&root.path().join("gen5")),
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        e.contains("retrieval") && e.contains("without a category"),
        "{e}"
    );
    // A codebook from another shape prior is refused: its codes would decode to other shapes.
    let other = root.path().join("other_shape");
    std::fs::create_dir_all(&other).unwrap();
    for f in ["codebook.npy", "codebook.json", "shape_prior.safetensors"] {
        std::fs::copy(shape.join(f), other.join(f)).unwrap();
    }
    let mut b = std::fs::read(other.join("shape_prior.safetensors")).unwrap();
    let k = b.len() - 5;
    b[k] ^= 0x10;
    std::fs::write(other.join("shape_prior.safetensors"), b).unwrap();
    let o = physnap(&[
        "train",
        "codebook",
        "--shape",
        s(&other),
        "--weights",
        s(&weights),
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        e.contains("shape_prior.safetensors") && e.contains("is not the shape prior of"),
        "{e}"
    );

    // Generated (latent) shapes render with the weights.
    let png = root.path().join("sample.png");
    ok(&[
        "render",
        s(&gen1.join("sample_000/object.json")),
        "--weights",
        s(&weights),
        "--resolution",
        "16",
        "--size",
        "64",
        "--out",
        s(&png),
    ]);
    assert_eq!(&std::fs::read(&png).unwrap()[..4], b"\x89PNG");

    // `train encode` turns the weights' shape prior back into the shape directory a new
    // denoiser trains on: the same codebook, byte for byte.
    let shape2 = root.path().join("shape2");
    let out = ok(&[
        "train",
        "encode",
        "--weights",
        s(&weights),
        "--data",
        s(&data),
        "--out",
        s(&shape2),
    ]);
    assert!(out.contains("encoded"), "{out}");
    for f in ["codebook.npy", "codebook.json", "shape_prior.safetensors"] {
        assert_eq!(
            std::fs::read(shape.join(f)).unwrap(),
            std::fs::read(shape2.join(f)).unwrap(),
            "{f}"
        );
    }

    // `train encode` also reads a `train shape` directory, and makes codes by another
    // encoding (views averaged, then fitted), which its report records and `eval shape` then
    // measures by default; a bad count is refused by field, limit and value.
    let fitted_dir = root.path().join("shape_fitted");
    let encode_fitted = |extra: &[&str]| {
        let mut args = vec![
            "train",
            "encode",
            "--weights",
            s(&shape),
            "--data",
            s(&data),
            "--out",
            s(&fitted_dir),
        ];
        args.extend_from_slice(extra);
        physnap(&args)
    };
    let o = encode_fitted(&[
        "--encoder-views",
        "2",
        "--fit-steps",
        "3",
        "--fit-queries",
        "64",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("2 view(s), 3 fitting steps on 64 samples"),
        "{out}"
    );
    assert_ne!(
        std::fs::read(shape.join("codebook.npy")).unwrap(),
        std::fs::read(fitted_dir.join("codebook.npy")).unwrap()
    );
    let rep: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(fitted_dir.join("shape_train.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(rep["encoding"]["views"], 2);
    assert_eq!(rep["encoding"]["fit_steps"], 3);
    let shape_out = ok(&[
        "eval",
        "shape",
        "--weights",
        s(&fitted_dir),
        "--data",
        s(&data),
        "--parts",
        "2",
        "--resolution",
        "16",
    ]);
    assert!(
        shape_out.contains("mean of 2 encoder calls") && shape_out.contains("codes fitted"),
        "{shape_out}"
    );
    let o = encode_fitted(&["--encoder-views", "0"]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("encoder_views") && e.contains("between 1 and 64") && e.contains('0'),
        "{e}"
    );

    // `eval denoiser`: the held-out ε-loss per noise level, with and without the category, on
    // the codes the denoiser trained on; the same seed repeats it exactly.
    let den = |split: &str, out: &Path| {
        ok(&[
            "eval",
            "denoiser",
            "--weights",
            s(&weights),
            "--data",
            s(&data),
            "--shape",
            s(&shape2),
            "--split",
            split,
            "--levels",
            "20,500",
            "--out",
            s(out),
        ])
    };
    let (d1, d2) = (root.path().join("den1.json"), root.path().join("den2.json"));
    let out = den("val", &d1);
    assert!(
        out.contains("val objects") && out.contains("no category"),
        "{out}"
    );
    den("val", &d2);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&d1).unwrap()).unwrap();
    assert_eq!(r["split"], "val");
    assert_eq!(r["levels"], serde_json::json!([20, 500]));
    let losses = r["conditional"].as_array().unwrap();
    assert_eq!(losses.len(), 2);
    assert!(losses.iter().all(|l| l.as_f64().unwrap() > 0.0), "{r}");
    assert_eq!(r["unconditional"].as_array().unwrap().len(), 2);
    let r2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&d2).unwrap()).unwrap();
    assert_eq!(r["conditional"], r2["conditional"]);
    let o = physnap(&[
        "eval",
        "denoiser",
        "--weights",
        s(&weights),
        "--data",
        s(&data),
        "--shape",
        s(&shape2),
        "--levels",
        "20,1000",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("levels") && err.contains("1000"), "{err}");

    // `eval shape` reports the shape prior's IoU per part and overall. `small`: on 3 val parts
    // at 16³.
    let small = |extra: &[&str]| -> Vec<String> {
        shape_args(
            &weights,
            &data,
            &[&["--parts", "3", "--resolution", "16"], extra].concat(),
        )
    };
    let report = root.path().join("shape_eval.json");
    let out = ok(&strs(&small(&["--out", s(&report), "--write-manifest"])));
    assert!(out.contains("mean IoU"), "{out}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let parts = r["parts"].as_array().unwrap();
    assert!((1..=3).contains(&parts.len()), "{r}");
    assert_eq!(r["split"], "val");
    // Synthetic parts are primitives: each reports its thinnest wall, which is no thicker
    // than the part's thinnest box extent, and the wall groups are listed.
    for p in parts {
        let wall = p["thinnest_primitive"].as_f64().unwrap();
        assert!(
            wall > 0.0 && wall <= p["thinnest"].as_f64().unwrap() + 1e-9,
            "{p}"
        );
    }
    let groups: Vec<&str> = r["groups"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| g["name"].as_str().unwrap())
        .collect();
    assert!(groups.contains(&"a primitive under a cell"), "{groups:?}");
    let mean = r["mean_iou"].as_f64().unwrap();
    let by_hand = parts
        .iter()
        .map(|p| p["iou"].as_f64().unwrap())
        .sum::<f64>()
        / parts.len() as f64;
    assert!(
        (0.0..=1.0).contains(&mean) && (mean - by_hand).abs() < 1e-12,
        "{r}"
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(weights.join("manifest.json")).unwrap())
            .unwrap();
    assert_eq!(m["metrics"]["shape"]["mean_iou"], r["mean_iou"], "{m:#}");
    assert_eq!(m["metrics"]["shape"]["parts"], parts.len());
    // With fitted codes (decoder alone) the report says so, and the manifest is refused.
    let fitted = root.path().join("shape_fit.json");
    let out = ok(&strs(&small(&["--fit-codes", "5", "--out", s(&fitted)])));
    assert!(out.contains("codes fitted"), "{out}");
    let f: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&fitted).unwrap()).unwrap();
    assert_eq!(f["fit_codes"], 5);
    assert_eq!(f["parts"].as_array().unwrap().len(), parts.len());
    let o = physnap(&strs(&small(&[
        "--fit-codes",
        "5",
        "--fit-prox",
        "0.5",
        "--write-manifest",
    ])));
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--write-manifest")
            && err.contains("--fit-codes 5 (the codebook's: 0)")
            && err.contains("--fit-prox 0.5 (the codebook's: 0)"),
        "{err}"
    );
    // A pull outside its range is refused by field, limit and value.
    let o = physnap(&strs(&small(&["--fit-codes", "5", "--fit-prox=-1"])));
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("fit_prox") && err.contains("between 0 and 1000") && err.contains("-1"),
        "{err}"
    );
    // Another encoder input is measured and reported as such (its refusals: below).
    let more = root.path().join("shape_more_points.json");
    let out = ok(&strs(&small(&[
        "--surface-points",
        "96",
        "--out",
        s(&more),
    ])));
    assert!(out.contains("encoder input: 96 surface points"), "{out}");
    let more: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&more).unwrap()).unwrap();
    assert_eq!(more["surface_points"], 96);
    // `eval generative` at toy scale: category accuracy searches the whole test split.
    let report = root.path().join("generative.json");
    let out = ok(&[
        "eval",
        "generative",
        "--weights",
        s(&weights),
        "--data",
        s(&data),
        "--samples",
        "2",
        "--refs",
        "2",
        "--per-category",
        "1",
        "--states",
        "1",
        "--points",
        "32",
        "--resolution",
        "16",
        "--out",
        s(&report),
    ]);
    assert!(
        out.contains("MMD") && out.contains("category accuracy"),
        "{out}"
    );
    let g: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("dataset.json")).unwrap()).unwrap();
    let test_split = index["splits"]["test"].as_array().unwrap().len();
    assert_eq!(g["references"], 2, "{g:#}");
    assert_eq!(g["conditional"]["references"], test_split, "{g:#}");
    assert_eq!(g["unconditional"]["samples"], 2, "{g:#}");
    let acc = g["conditional"]["accuracy"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&acc), "{g:#}");
    // Each category's confusion row accounts for every sample, its own count for the hits.
    for c in g["conditional"]["categories"].as_array().unwrap() {
        assert_eq!(
            count_sum(&c["nearest"]),
            c["samples"].as_u64().unwrap(),
            "{c:#}"
        );
        let own = c["nearest"].get(c["category"].as_str().unwrap());
        assert_eq!(
            own.map_or(0, |n| n.as_u64().unwrap()),
            c["hits"].as_u64().unwrap(),
            "{c:#}"
        );
    }
    // The ceiling per category: every test object once, the hits adding up to the pooled
    // ceiling, each row's confusion accounting for its objects.
    let rows = g["conditional"]["categories"].as_array().unwrap();
    let (mut loo_hits, mut loo_objects) = (0, 0);
    for c in rows {
        let r = &c["reference_loo"];
        assert_eq!(
            count_sum(&r["nearest"]),
            r["objects"].as_u64().unwrap(),
            "{c:#}"
        );
        loo_hits += r["hits"].as_u64().unwrap();
        loo_objects += r["objects"].as_u64().unwrap();
    }
    assert_eq!(loo_objects as usize, test_split, "{g:#}");
    let pooled = g["conditional"]["reference_loo_accuracy"].as_f64().unwrap();
    assert!(
        (loo_hits as f64 / loo_objects as f64 - pooled).abs() < 1e-12,
        "{g:#}"
    );
    // A `train shape` output directory is evaluated as well (a candidate before any denoiser
    // is trained on it): the same shape prior, the same figures.
    let report2 = root.path().join("shape_eval_dir.json");
    ok(&[
        "eval",
        "shape",
        "--weights",
        s(&shape),
        "--data",
        s(&data),
        "--parts",
        "3",
        "--resolution",
        "16",
        "--out",
        s(&report2),
    ]);
    let r2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report2).unwrap()).unwrap();
    assert_eq!(r2["mean_iou"], m["metrics"]["shape"]["mean_iou"], "{r2:#}");
    let o = physnap(&[
        "eval",
        "shape",
        "--weights",
        s(&shape),
        "--data",
        s(&data),
        "--write-manifest",
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("--write-manifest needs a weights directory with manifest.json"),
        "{e}"
    );
    // `eval reconstruction`: every test object through the representation, against the
    // originals.
    // This test's weights and data, 1 state × 32 points, plus `extra`.
    let reconstruct = |extra: &[&str]| -> String {
        let mut args = vec![
            "eval",
            "reconstruction",
            "--weights",
            s(&weights),
            "--data",
            s(&data),
            "--states",
            "1",
            "--points",
            "32",
        ];
        args.extend_from_slice(extra);
        ok(&args)
    };
    let report = root.path().join("reconstruction.json");
    let out = reconstruct(&["--resolution", "16", "--out", s(&report)]);
    assert!(out.contains("category accuracy"), "{out}");
    let rc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(rc["objects"], test_split, "{rc:#}");
    for k in [
        "category_accuracy",
        "self_retrieval",
        "original_loo_accuracy",
    ] {
        let v = rc[k].as_f64().unwrap_or(-1.0);
        assert!((0.0..=1.0).contains(&v), "{k}: {rc:#}");
    }
    let per_cat: u64 = rc["categories"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["objects"].as_u64().unwrap())
        .sum();
    assert_eq!(per_cat as usize, test_split, "{rc:#}");
    // Per category, where the reconstructions land and the originals' own leave-one-out
    // ceiling, adding up to the pooled figures.
    let (mut hits, mut loo_hits) = (0, 0);
    for c in rc["categories"].as_array().unwrap() {
        assert_eq!(
            count_sum(&c["nearest"]),
            c["objects"].as_u64().unwrap(),
            "{c:#}"
        );
        assert_eq!(c["original_loo"]["objects"], c["objects"], "{c:#}");
        hits += c["hits"].as_u64().unwrap();
        loo_hits += c["original_loo"]["hits"].as_u64().unwrap();
    }
    let close =
        |a: u64, k: &str| (a as f64 / test_split as f64 - rc[k].as_f64().unwrap()).abs() < 1e-12;
    assert!(close(hits, "category_accuracy"), "{rc:#}");
    assert!(close(loo_hits, "original_loo_accuracy"), "{rc:#}");
    assert!(
        rc["id_to_original"]["mean"].as_f64().unwrap() > 0.0,
        "{rc:#}"
    );
    let overlap = rc["o_mesh"]["reconstruction"]["mean"]
        .as_f64()
        .unwrap_or(-1.0);
    assert!((0.0..=1.0).contains(&overlap), "{rc:#}");
    // The data's own E_pen / E_mob under the decoder (what samples are read against).
    for k in ["e_pen", "e_mob"] {
        let mean = rc[k]["mean"].as_f64().unwrap_or(-1.0);
        assert!(mean.is_finite() && mean >= 0.0, "{k}: {rc:#}");
        let above = rc[k]["share_above_1e-4"].as_f64().unwrap_or(-1.0);
        assert!((0.0..=1.0).contains(&above), "{k}: {rc:#}");
    }
    assert!(out.contains("E_pen of the test objects"), "{out}");
    // The control: the originals' meshes on the projected graphs. The graph representation
    // loses nothing, so every reconstruction is at distance ≈ 0 from its original and the
    // category accuracy is the originals' own leave-one-out figure.
    let report = root.path().join("reconstruction_original.json");
    reconstruct(&["--shapes", "original", "--out", s(&report)]);
    let rc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    // (0 up to rounding: the graph stores f32.)
    assert!(
        rc["id_to_original"]["mean"].as_f64().unwrap() < 1e-9,
        "{rc:#}"
    );
    assert_eq!(rc["self_retrieval"], 1.0, "{rc:#}");
    // Generated data passes the validity check, so no part is buried in another on the
    // original meshes, and neither on the same meshes placed by the projected graph.
    assert_eq!(rc["o_mesh"]["original"]["mean"], 0.0, "{rc:#}");
    assert_eq!(rc["o_mesh"]["reconstruction"]["mean"], 0.0, "{rc:#}");
    assert_eq!(
        rc["category_accuracy"], rc["original_loo_accuracy"],
        "{rc:#}"
    );
    for c in rc["categories"].as_array().unwrap() {
        assert_eq!(c["hits"], c["original_loo"]["hits"], "{c:#}");
    }
    // `--shapes analytic`: the originals' primitives meshed like decoded shapes.
    let out = reconstruct(&["--shapes", "analytic", "--resolution", "16"]);
    assert!(out.contains("category accuracy"), "{out}");
    let o = physnap(&[
        "eval",
        "reconstruction",
        "--weights",
        s(&weights),
        "--data",
        s(&data),
        "--states",
        "0",
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("states") && e.contains("between 1 and 100"),
        "{e}"
    );
    // Out of range is refused with the limit; another encoder input is never recorded.
    for (flags, expect) in [
        (&["--split", "holdout"][..], "invalid --split \"holdout\""),
        (
            &["--parts", "0"][..],
            "invalid --parts 0: must be between 1 and",
        ),
        (
            &["--surface-points", "0"][..],
            "invalid --surface-points 0: must be between 1 and 8192",
        ),
        (
            &["--surface-points", "96", "--write-manifest"][..],
            "--surface-points",
        ),
    ] {
        let o = physnap(&strs(&shape_args(&weights, &data, flags)));
        assert!(!o.status.success(), "{flags:?}");
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(e.contains(expect), "{flags:?}: {e}");
    }

    // Bad inputs are refused clearly.
    let o = physnap(&[
        "generate",
        "--weights",
        s(&weights),
        "--category",
        "Spaceship",
        "--out",
        s(&gen1),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("invalid --category \"Spaceship\""));
    let o = physnap(&[
        "generate",
        "--weights",
        s(&root.path().join("nowhere")),
        "--out",
        s(&gen1),
    ]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("no trained weights"));

    // `train shape --init-from weights --freeze-encoder` trains the decoder on with every code
    // unchanged, and `train install-shape` puts it into the weights: new sha256, metrics
    // cleared, the old report kept, and the weights still generate. The frozen run widens the
    // decoder's positional encoding (8 → 10 octaves), which the manifest then records. A run
    // whose encoder moved is refused.
    let ft = root.path().join("ft");
    let moved = root.path().join("moved");
    for (out, freeze) in [(&ft, true), (&moved, false)] {
        let mut args = vec!["train", "shape", "--data", s(&data), "--out", s(out)];
        args.extend(["--steps", "3", "--init-from", s(&weights)]);
        args.extend(sizes);
        if freeze {
            args.extend(["--freeze-encoder", "--pe-freqs", "10"]);
        }
        ok(&args);
    }
    assert_eq!(
        std::fs::read(ft.join("codebook.npy")).unwrap(),
        std::fs::read(shape.join("codebook.npy")).unwrap()
    );
    let o = physnap(&[
        "train",
        "install-shape",
        "--shape",
        s(&moved),
        "--weights",
        s(&weights),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("encoder differs") && e.contains("--freeze-encoder"),
        "{e}"
    );
    ok(&[
        "train",
        "install-shape",
        "--shape",
        s(&ft),
        "--weights",
        s(&weights),
    ]);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(weights.join("manifest.json")).unwrap())
            .unwrap();
    let installed = std::fs::read(weights.join("shape_prior.safetensors")).unwrap();
    assert_eq!(
        installed,
        std::fs::read(ft.join("shape_prior.safetensors")).unwrap()
    );
    assert_eq!(
        m["shape_prior"]["sha256"],
        physnap::model::weights::sha256_hex(&installed)
    );
    assert!(m["metrics"].is_null(), "{m:#}");
    assert_eq!(m["shape_prior"]["config"]["pe_freqs"], 10);
    assert_eq!(m["training"]["shape"]["config"]["freeze_encoder"], true);
    assert_eq!(m["training"]["shape_base"]["steps"], 6);
    // The first cycle installed: no earlier cycle to list.
    assert!(m["training"]["shape_cycles"].is_null(), "{m:#}");
    let gen_ft = root.path().join("gen_ft");
    ok(&[
        "generate",
        "--weights",
        s(&weights),
        "--samples",
        "1",
        "--resolution",
        "16",
        "--out",
        s(&gen_ft),
    ]);

    // A corrupted weights file is refused with a checksum error.
    let w = weights.join("denoiser.safetensors");
    flip_byte(&w);
    let o = physnap(&["generate", "--weights", s(&weights), "--out", s(&gen1)]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("sha256 mismatch") && e.contains("denoiser.safetensors"),
        "{e}"
    );
    // So is a corrupted shape prior, by `train encode`.
    let w = weights.join("shape_prior.safetensors");
    flip_byte(&w);
    let o = physnap(&[
        "train",
        "encode",
        "--weights",
        s(&weights),
        "--data",
        s(&data),
        "--out",
        s(&root.path().join("shape3")),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("shape_prior.safetensors") && e.contains("does not match manifest.json"),
        "{e}"
    );
}

/// `scripts/reproduce-weights.sh` (the README's one command for the shipped weights) runs its
/// whole recipe — including the denoiser stages (three by default, two with STAGE2=0), its
/// restart cycles and the codebook — at toy scale.
#[test]
fn the_reproduce_script_runs_the_recipe_at_toy_scale() {
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("repro");
    // The toy shape prior's batch (SHAPE_BATCH) and sizes (SHAPE_FLAGS): a narrow prior, so
    // the recipe's fitted encoding (16 views, 50 steps a part) runs in seconds, not minutes, in
    // a debug build.
    let toy_shape = [
        "--batch-parts",
        "4",
        "--queries-per-part",
        "64",
        "--decoder-hidden",
        "32",
        "--encoder-hidden",
        "32",
    ];
    // The script at toy scale into `out`, with `stages` = (STAGE1, STAGE2, STEPS) and any
    // further knobs in `extra`.
    let repro = |out: &Path, stages: [&str; 3], extra: &[(&str, &str)]| -> Output {
        Command::new("bash")
            .arg(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/scripts/reproduce-weights.sh"
            ))
            .arg(out)
            .env("PHYSNAP_BIN", env!("CARGO_BIN_EXE_physnap"))
            .env("PHYSNAP_LOG", "warn")
            .env("OBJECTS", "26")
            .env("SHAPE_STEPS", "4")
            .env("STAGE1", stages[0])
            .env("STAGE2", stages[1])
            .env("STEPS", stages[2])
            .env("BATCH_OBJECTS", "2")
            .env("CHECKPOINT_EVERY", "1")
            .env("IMPORT_FLAGS", "--uniform 256 --near 256 --surface 64")
            .env("SHAPE_BATCH", toy_shape[..4].join(" "))
            .env("SHAPE_FLAGS", toy_shape[4..].join(" "))
            .env("DENOISER_FLAGS", "--width 32 --layers 1")
            .env("DECODER_STEPS", "2")
            .env("CODES_DECODER_STEPS", "2")
            .env("EVAL", "0")
            .envs(extra.iter().copied())
            .output()
            .unwrap()
    };
    // The main toy recipe into `out`, with two restart cycles, and any `extra` knobs.
    let again = |extra: &[(&str, &str)]| {
        let mut knobs = vec![("RESTART_STEPS", "7 8"), ("RESTART_OVERLAP", "0 3")];
        knobs.extend_from_slice(extra);
        repro(&out, ["2", "3", "5"], &knobs)
    };
    // In two runs: UNTIL stops after the encoding, the same command without it goes on.
    let o = again(&[("UNTIL", "encode")]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("stopped after stage encode"), "{err}");
    assert!(!err.contains("train diffusion"), "{err}");
    let o = again(&[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.matches("done before, skipped").count(), 7, "{err}");
    // The five runs ran in order: stage 2 stopped at 3, stage 3 resumed there and ran to 5,
    // the first restart cycle resumed at 5, decaying from there to 7, and the second, with
    // the box-overlap penalty, from 7 to 8.
    assert_eq!(err.matches("+ physnap train diffusion").count(), 5, "{err}");
    let read = |p: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let w = out.join("weights");
    let summary = read(&w.join("diffusion_train.json"));
    assert_eq!(
        (
            &summary["completed"],
            &summary["resumed_from"],
            &summary["lr_decay_start"]
        ),
        (
            &serde_json::json!(8),
            &serde_json::json!(7),
            &serde_json::json!(7)
        ),
        "{summary:#}"
    );
    assert_eq!(summary["overlap_weight"], 3.0, "{summary:#}");
    assert!(err.contains("--overlap-weight 0 "), "{err}");
    assert_eq!(read(&w.join("checkpoint.json"))["step"], 8);
    let m = read(&w.join("manifest.json"));
    assert!(
        m["codebook"]["config"]["rows"].as_u64().unwrap() >= 1,
        "{m:#}"
    );
    // The recipe's denoiser adds its category to every graph layer, as the shipped one does.
    assert_eq!(m["denoiser"]["config"]["category_layers"], true, "{m:#}");
    // Three decoder cycles, encoder frozen, continue the first prior, each the last, before
    // the denoiser; `train encode` makes the codes from the last one as shipped (the mean of
    // 16 encoder views, fitted 50 steps on 512 SDF samples), and the manifest keeps the whole
    // lineage and the encoding.
    assert!(!err.contains("+ physnap train install-shape"), "{err}");
    assert!(
        err.contains("train encode --weights")
            && err.contains("--encoder-views 16 --fit-steps 50 --fit-queries 512"),
        "{err}"
    );
    assert!(
        err.find("--out {}/shape_decoder3".replace("{}", s(&out)).as_str())
            < err.find("+ physnap train diffusion"),
        "cycles before the denoiser: {err}"
    );
    assert_eq!(
        m["training"]["shape"]["encoding"],
        serde_json::json!({"views": 16, "fit_steps": 50, "fit_queries": 512, "fit_lr": 0.01,
            "fit_prox": 0.0}),
        "{m:#}"
    );
    assert_eq!(
        m["training"]["shape"]["config"]["freeze_encoder"], true,
        "{m:#}"
    );
    // The shipped prior is the last cycle's decoder trained on exactly those codes (stage
    // decoder_codes, seed 3): its report keeps the encoding above and where the codes came
    // from, and the denoiser's --shape directory is that cycle's.
    assert_eq!(m["training"]["shape"]["config"]["seed"], 3, "{m:#}");
    assert_eq!(
        m["training"]["shape"]["config"]["codes_from"],
        serde_json::json!(out.join("codes").display().to_string()),
        "{m:#}"
    );
    assert!(
        err.contains(&format!("--shape {}/shape_codes ", s(&out))),
        "{err}"
    );
    assert_eq!(m["training"]["shape_base"]["steps"], 4, "{m:#}");
    assert_eq!(
        m["training"]["shape_base"]["config"]["freeze_encoder"], false,
        "{m:#}"
    );
    // The first prior's decoder gradients come from the host backward pass by default, as
    // shipped, and SHAPE_BATCH sets the batch of the prior and of every cycle.
    assert_eq!(
        m["training"]["shape_base"]["config"]["decoder_backward"], "host",
        "{m:#}"
    );
    for stage in ["shape_base", "shape"] {
        assert_eq!(
            m["training"][stage]["config"]["queries_per_part"], 64,
            "{stage}: {m:#}"
        );
        // Both cores: the parts of each step in two slices (SHAPE_SHARDS).
        assert_eq!(
            m["training"][stage]["config"]["batch_shards"], 2,
            "{stage}: {m:#}"
        );
    }
    // Every denoiser run takes two batch slices by default, as the shipped denoiser was trained,
    // and the shipped layout gain (LAYOUT_GAIN 2), which the manifest records.
    assert_eq!(diffusion_runs_with(&err, "--batch-shards 2"), 5, "{err}");
    assert_eq!(diffusion_runs_with(&err, "--layout-gain 2"), 5, "{err}");
    assert_eq!(m["training"]["diffusion"]["layout_gain"], 2.0, "{m:#}");
    // The shape codes at twice NAP's scale too (CODE_GAIN 2), as shipped.
    assert_eq!(diffusion_runs_with(&err, "--code-gain 2"), 5, "{err}");
    assert_eq!(m["training"]["diffusion"]["code_gain"], 2.0, "{m:#}");
    let cycles = m["training"]["shape_cycles"].as_array().unwrap();
    assert_eq!(cycles.len(), 3, "{m:#}");
    for (i, c) in cycles.iter().enumerate() {
        assert_eq!(c["config"]["seed"], i, "{m:#}");
        assert_eq!(c["config"]["freeze_encoder"], true, "{m:#}");
    }
    // Each cycle with its own eikonal and wrong-side weights, as the shipped decoder was
    // trained: eikonal 0.01, 0.03, 0.03; the wrong-side term in the third only
    // (DECODER_WRONG_SIDE "0 0 10").
    assert_eq!(cycles[0]["config"]["eikonal"], 0.01, "{m:#}");
    assert_eq!(cycles[1]["config"]["eikonal"], 0.03, "{m:#}");
    assert_eq!(cycles[1]["config"]["wrong_side"], 0.0, "{m:#}");
    assert_eq!(cycles[2]["config"]["wrong_side"], 10.0, "{m:#}");
    assert!(cycles[2]["config"]["codes_from"].is_null(), "{m:#}");
    assert_eq!(m["training"]["shape"]["config"]["eikonal"], 0.03, "{m:#}");
    assert_eq!(
        m["training"]["shape"]["config"]["wrong_side"], 10.0,
        "{m:#}"
    );
    assert_eq!(err.matches("--wrong-side 0 ").count(), 2, "{err}");
    // Only the last state gets a retrieval codebook: the first four denoiser runs skip
    // theirs (the recipe's time budget), the last builds it (above).
    assert_eq!(err.matches("--no-codebook").count(), 4, "{err}");
    // Every stage is timed in stages.tsv (name, wall seconds, command): data 2, prior 1, three
    // cycles, the encoding, the cycle on the codes and the five denoiser runs.
    let tsv = std::fs::read_to_string(out.join("stages.tsv")).unwrap();
    let stages: Vec<&str> = tsv.lines().map(|l| l.split('\t').next().unwrap()).collect();
    assert_eq!(
        stages,
        [
            "synth",
            "import",
            "shape",
            "decoder1",
            "decoder2",
            "decoder3",
            "encode",
            "decoder_codes",
            "denoiser_stage1",
            "denoiser_stage2",
            "denoiser_decay",
            "denoiser_restart1",
            "denoiser_restart2"
        ],
        "{tsv}"
    );
    // A rerun into the same OUT skips every finished stage and changes nothing; one whose last
    // stage did not finish runs that stage alone, resumed from its checkpoint.
    let manifest_bytes = std::fs::read(w.join("manifest.json")).unwrap();
    let o = again(&[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(!err.contains("+ physnap"), "{err}");
    assert_eq!(err.matches("done before, skipped").count(), 13, "{err}");
    assert_eq!(
        std::fs::read(w.join("manifest.json")).unwrap(),
        manifest_bytes
    );
    std::fs::remove_file(out.join("stages/denoiser_restart2.done")).unwrap();
    let o = again(&[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.matches("+ physnap").count(), 1, "{err}");
    assert!(
        err.contains("+ physnap train diffusion") && err.contains("--resume"),
        "{err}"
    );
    assert_eq!(read(&w.join("checkpoint.json"))["step"], 8);
    // A shape stage stopped at a checkpoint goes on from it: the third cycle, stopped after
    // one of its two steps, is the only stage the rerun runs, with --resume.
    let d3 = out.join("shape_decoder3");
    std::fs::remove_dir_all(&d3).unwrap();
    std::fs::remove_file(out.join("stages/decoder3.done")).unwrap();
    let train_dir = out.join("train");
    let data = s(&train_dir);
    // One toy `train shape` cycle into `dir`: encoder frozen, the toy prior's batch and sizes.
    let toy_cycle = |dir: &Path, extra: &[&str]| {
        let head = [
            "train",
            "shape",
            "--data",
            data,
            "--out",
            s(dir),
            "--freeze-encoder",
        ];
        ok(&[&head[..], &toy_shape, extra].concat());
    };
    let d2 = out.join("shape_decoder2");
    toy_cycle(
        &d3,
        &[
            "--steps",
            "2",
            "--seed",
            "2",
            "--init-from",
            s(&d2),
            "--lr",
            "5e-4",
            "--wrong-side",
            "10",
            "--stop-at",
            "1",
            "--checkpoint-every",
            "1",
        ],
    );
    assert!(d3.join("shape_checkpoint.json").is_file());
    let o = again(&[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.matches("+ physnap").count(), 1, "{err}");
    assert!(
        err.contains(&format!("--out {} ", s(&d3))) && err.contains("--resume"),
        "{err}"
    );
    assert!(!d3.join("shape_checkpoint.json").exists());
    assert_eq!(read(&d3.join("shape_train.json"))["steps"], 2);
    // Other knobs than the ones OUT was started with are refused, by name, before anything runs.
    let o = again(&[("CODE_GAIN", "1")]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("invalid CODE_GAIN")
            && err.contains("CODE_GAIN=2")
            && err.contains("CODE_GAIN=1"),
        "{err}"
    );
    assert!(!err.contains("+ physnap"), "{err}");
    // A cycle trained on the weights directory itself: `train encode` of it follows its start
    // into the manifest and keeps that history (the first prior, the three cycles, then the one on the codes).
    let c3 = out.join("cycle_on_weights");
    toy_cycle(&c3, &["--steps", "1", "--init-from", s(&w)]);
    let codes3 = out.join("codes3");
    ok(&[
        "train",
        "encode",
        "--weights",
        s(&c3),
        "--data",
        s(&out.join("train")),
        "--out",
        s(&codes3),
    ]);
    let lineage = &read(&codes3.join("shape_train.json"))["lineage"];
    assert_eq!(lineage["shape_base"]["steps"], 4, "{lineage:#}");
    let seeds: Vec<_> = lineage["shape_cycles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["config"]["seed"].clone())
        .collect();
    assert_eq!(
        seeds,
        [0, 1, 2, 3].map(|i| serde_json::json!(i)),
        "{lineage:#}"
    );
    // The codes the denoiser learned were fitted to the decoder: one not trained on them (the
    // third cycle) is refused, naming the fitting and the way out; the cycle trained on them
    // installs. Installing without a codebook drops the stale one, file and manifest entry,
    // and says how to build it; `train codebook` puts it back.
    let install = |shape: &Path| {
        physnap(&[
            "train",
            "install-shape",
            "--shape",
            s(shape),
            "--weights",
            s(&w),
            "--no-codebook",
        ])
    };
    let o = install(&d3);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{e}");
    assert!(
        e.contains("fitted 50 steps") && e.contains("--codes") && e.contains("shape_decoder3"),
        "{e}"
    );
    assert!(
        w.join("codebook.safetensors").exists(),
        "refused: nothing changed"
    );
    let codes_cycle = out.join("shape_codes");
    let o = install(&codes_cycle);
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(said.contains("physnap train codebook"), "{said}");
    assert!(!w.join("codebook.safetensors").exists());
    assert!(read(&w.join("manifest.json"))["codebook"].is_null());
    ok(&[
        "train",
        "codebook",
        "--shape",
        s(&codes_cycle),
        "--weights",
        s(&w),
    ]);
    assert!(
        read(&w.join("manifest.json"))["codebook"]["config"]["rows"]
            .as_u64()
            .unwrap()
            >= 1
    );
    // Bad knobs are refused (exit 2, naming the knob and the value) before anything runs.
    let bad = root.path().join("bad");
    for (knobs, expect) in [
        (
            &[("STAGE1", "5"), ("STAGE2", "3")][..],
            "STAGE1 < STAGE2 < STEPS",
        ),
        (&[("DECODER_CYCLES", "two")][..], "DECODER_CYCLES"),
        (&[("SHAPE_BACKWARD", "fast")][..], "SHAPE_BACKWARD"),
        (&[("DECODER_EIKONAL", "0.01 strong")][..], "strong"),
        (&[("DECODER_EIKONAL", "0.01")][..], "DECODER_EIKONAL"),
        (&[("DECODER_WRONG_SIDE", "0 much")][..], "much"),
        (&[("DECODER_WRONG_SIDE", "10")][..], "DECODER_WRONG_SIDE"),
        (&[("DENOISER_SHARDS", "0")][..], "DENOISER_SHARDS"),
        (&[("RESTART_SHARDS", "two")][..], "RESTART_SHARDS"),
        (&[("RESTART_STEPS", "6000")][..], "RESTART_STEPS"),
        (&[("RESTART_STEPS", "20000 19000")][..], "19000"),
        (
            &[("RESTART_STEPS", "20000 21000"), ("RESTART_OVERLAP", "3")][..],
            "RESTART_OVERLAP",
        ),
        (
            &[("RESTART_STEPS", "20000"), ("RESTART_OVERLAP", "lots")][..],
            "lots",
        ),
        (&[("DECAY_OVERLAP", "-1")][..], "DECAY_OVERLAP"),
        (&[("SHAPE_SHARDS", "0")][..], "SHAPE_SHARDS"),
        (&[("FIT_STEPS", "many")][..], "FIT_STEPS"),
        (&[("ENCODER_VIEWS", "-2")][..], "ENCODER_VIEWS"),
        (&[("LAYOUT_GAIN", "twice")][..], "LAYOUT_GAIN"),
        (&[("CODE_GAIN", "double")][..], "CODE_GAIN"),
        (&[("CODES_DECODER_STEPS", "all")][..], "CODES_DECODER_STEPS"),
        (
            &[("CODES_DECODER_WRONG_SIDE", "-3")][..],
            "CODES_DECODER_WRONG_SIDE",
        ),
        (&[("UNTIL", "denoiser")][..], "UNTIL"),
    ] {
        let o = Command::new("bash")
            .arg(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/scripts/reproduce-weights.sh"
            ))
            .arg(&bad)
            .env("PHYSNAP_BIN", env!("CARGO_BIN_EXE_physnap"))
            .envs(knobs.iter().copied())
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2));
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(e.contains(expect), "{e}");
        assert!(e.contains(knobs.last().unwrap().1), "{e}");
        assert!(!bad.exists());
    }

    // STAGE2=0, RESTART_STEPS=0: two denoiser runs, the second resuming at STAGE1 and running to STEPS; the
    // first prior with burn's autodiff (SHAPE_BACKWARD=burn), the single-pass steps of the
    // weights shipped before (DENOISER_SHARDS=1, SHAPE_SHARDS=1), one decoder cycle without
    // the eikonal term and with the wrong-side term (DECODER_WRONG_SIDE=10), NAP's feature
    // scales for the layout and the codes (LAYOUT_GAIN=1, CODE_GAIN=1: NAP's scaling),
    // a small fitted encoding and no cycle on the codes (CODES_DECODER_STEPS=0: the recipe
    // before 2026-12-01).
    let two = root.path().join("two");
    let o = repro(
        &two,
        ["2", "0", "4"],
        &[
            ("RESTART_STEPS", "0"),
            ("CODES_DECODER_STEPS", "0"),
            ("SHAPE_BACKWARD", "burn"),
            ("DENOISER_SHARDS", "1"),
            ("DECODER_CYCLES", "1"),
            ("DECODER_EIKONAL", "0"),
            ("DECODER_WRONG_SIDE", "10"),
            ("DECAY_OVERLAP", "2"),
            ("SHAPE_SHARDS", "1"),
            ("ENCODER_VIEWS", "2"),
            ("FIT_STEPS", "2"),
            ("FIT_QUERIES", "32"),
            ("LAYOUT_GAIN", "1"),
            ("CODE_GAIN", "1"),
        ],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.matches("+ physnap train diffusion").count(), 2, "{err}");
    let summary = read(&two.join("weights/diffusion_train.json"));
    assert_eq!(
        (&summary["completed"], &summary["resumed_from"]),
        (&serde_json::json!(4), &serde_json::json!(2)),
        "{summary:#}"
    );
    // DECAY_OVERLAP is the penalty of the run that ends at STEPS.
    assert_eq!(summary["overlap_weight"], 2.0, "{summary:#}");
    assert_eq!(diffusion_runs_with(&err, "--batch-shards 1"), 2, "{err}");
    let m = read(&two.join("weights/manifest.json"));
    // LAYOUT_GAIN=1, CODE_GAIN=1: NAP's scaling.
    assert_eq!(m["training"]["diffusion"]["layout_gain"], 1.0, "{m:#}");
    assert_eq!(m["training"]["diffusion"]["code_gain"], 1.0, "{m:#}");
    assert_eq!(diffusion_runs_with(&err, "--code-gain 1"), 2, "{err}");
    assert_eq!(
        m["training"]["shape_base"]["config"]["decoder_backward"], "burn",
        "{m:#}"
    );
    assert_eq!(m["training"]["shape"]["config"]["eikonal"], 0.0, "{m:#}");
    assert_eq!(
        m["training"]["shape"]["config"]["wrong_side"], 10.0,
        "{m:#}"
    );
    assert!(m["training"]["shape_cycles"].is_null(), "one cycle: {m:#}");
    // The codes the denoiser learned were made by the encoding the knobs asked for, and the
    // manifest says so (eval shape measures that encoding by default).
    assert_eq!(
        m["training"]["shape"]["encoding"],
        serde_json::json!({"views": 2, "fit_steps": 2, "fit_queries": 32, "fit_lr": 0.01,
            "fit_prox": 0.0}),
        "{m:#}"
    );
    assert_eq!(
        m["training"]["shape_base"]["config"]["batch_shards"], 1,
        "{m:#}"
    );
}
