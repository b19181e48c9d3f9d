//! Tests of the shape prior's training, encoding and evaluation.

use super::*;
use crate::data::rng::Rng;
use crate::io::npy;
use crate::model::shape_prior::{ShapePrior, ShapePriorConfig};
use crate::model::{Compute, cpu};
use crate::shape::PartShape;
use burn::module::Module;
use burn::tensor::{Tensor, TensorData};
use serde_json::{Value, json};
use std::time::Instant;

use crate::data::categories::SYNTH_CATEGORIES;
use crate::data::dataset::{ImportOptions, import_dir};
use crate::data::generate::{SynthOptions, synthesize};
use crate::mesh::{MeshingOptions, part_mesh};
use crate::model::shape_prior::LatentSdfDecoder;
use crate::object::Part;
use nalgebra::Vector3;

/// A small imported data set: `objects` synthetic objects, few samples per part.
fn tiny_dataset(objects: usize) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("synth");
    synthesize(
        &src,
        &SynthOptions {
            objects,
            seed: 7,
            categories: SYNTH_CATEGORIES.iter().map(|s| s.to_string()).collect(),
            max_attempts: 200,
        },
        &|_, _| {},
    )
    .unwrap();
    import_dir(
        &src,
        &dir.path().join("train"),
        &ImportOptions {
            seed: 0,
            uniform: 512,
            near: 512,
            surface: 128,
        },
        &|_, _| {},
    )
    .unwrap();
    dir
}

fn tiny_config() -> ShapeTrainConfig {
    ShapeTrainConfig {
        model: ShapePriorConfig {
            latent: 16,
            decoder_hidden: 32,
            decoder_blocks: 2,
            encoder_hidden: 32,
            encoder_blocks: 2,
            pe_freqs: 4,
            code_every_block: false,
        },
        steps: 100,
        batch_parts: 8,
        queries_per_part: 256,
        surface_points: 64,
        lr: 2e-3,
        lr_final_factor: 1.0,
        eval_every: 50,
        val_parts: 4,
        iou_resolution: 16,
        ..ShapeTrainConfig::default()
    }
}

#[test]
fn tiny_training_lowers_the_loss_and_writes_everything() {
    let data = tiny_dataset(39);
    let out = data.path().join("out");
    let cfg = tiny_config();
    let mut seen = Vec::new();
    let report = train_shape(&data.path().join("train"), &cfg, &out, &mut |p| {
        seen.push((p.step, p.loss, p.val_iou))
    })
    .unwrap();
    assert_eq!(seen.len(), cfg.steps);
    assert!(seen.iter().enumerate().all(|(i, s)| s.0 == i + 1));
    assert_eq!(seen.iter().filter(|s| s.2.is_some()).count(), 2);
    assert!(
        report.final_loss < 0.7 * report.initial_loss,
        "loss {} → {}",
        report.initial_loss,
        report.final_loss
    );
    let iou = report.val_iou.unwrap();
    assert!((0.0..=1.0).contains(&iou), "{iou}");
    assert_eq!(report.curve.len(), 2);

    // Codebook: one row per part of every split, in dataset order.
    let parts = read_index(&data.path().join("train")).unwrap();
    let (rows, cols, codes) = npy::read(&out.join(CODEBOOK_FILE)).unwrap();
    assert_eq!((rows, cols), (parts.len(), 16));
    assert!(codes.iter().all(|v| v.is_finite()));
    let index: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join(CODEBOOK_INDEX_FILE)).unwrap())
            .unwrap();
    let keys = index["keys"].as_array().unwrap();
    assert_eq!(keys.len(), rows);
    assert_eq!(keys[1]["key"], format!("{}_{}", parts[1].id, parts[1].k));
    assert!(keys.iter().any(|k| k["split"] == "val"));
    assert_eq!(
        read_model_config(&out.join(REPORT_FILE)).unwrap(),
        cfg.model
    );

    // The codebook's first row is what the saved encoder gives for that part.
    let model = load_shape_prior(&out.join(WEIGHTS_FILE), &cfg.model, &cpu()).unwrap();
    let (_, surf) = read_rows(&parts[0].file(&data.path().join("train"), "surface"), 3).unwrap();
    let z = to_vec(model.encoder.encode(Tensor::from_data(
        TensorData::new(first_points(&surf, 64), [1, 64, 3]),
        &cpu(),
    )));
    assert_eq!(z, codes[..16].to_vec());

    // The trained decoder meshes a latent part through the LatentDecoder adapter.
    let adapter = LatentSdfDecoder::new(&model.decoder);
    let part = Part {
        name: "latent".into(),
        half_extents: Vector3::new(0.3, 0.2, 0.1),
        center: Vector3::new(0.0, 0.0, 0.5),
        shape: PartShape::Latent(codes[..16].to_vec()),
    };
    let mesh = part_mesh(&part, Some(&adapter), &MeshingOptions { resolution: 24 }).unwrap();
    assert!(mesh.positions.iter().flatten().all(|v| v.is_finite()));

    // Re-encoding the data set from the weights and report alone (what `train encode` does
    // with a shipped weights directory) gives the same codebook, byte for byte, and a
    // report `train diffusion` reads the model config from.
    let report_doc: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join(REPORT_FILE)).unwrap()).unwrap();
    let again = data.path().join("again");
    let enc = encode_shape_dir(
        &out.join(WEIGHTS_FILE),
        &report_doc,
        &data.path().join("train"),
        &again,
        &Encoding::default(),
        &mut |_, _| {},
    )
    .unwrap();
    assert_eq!(
        (enc.rows, enc.surface_points),
        (parts.len(), cfg.surface_points)
    );
    for f in [CODEBOOK_FILE, CODEBOOK_INDEX_FILE, WEIGHTS_FILE] {
        assert_eq!(
            std::fs::read(out.join(f)).unwrap(),
            std::fs::read(again.join(f)).unwrap(),
            "{f}"
        );
    }
    assert_eq!(
        read_model_config(&again.join(REPORT_FILE)).unwrap(),
        cfg.model
    );
    // A report without the encoder input size, or weights of another size, are refused.
    let refused = |report: &Value| {
        encode_shape_dir(
            &out.join(WEIGHTS_FILE),
            report,
            &data.path().join("train"),
            &again,
            &Encoding::default(),
            &mut |_, _| {},
        )
        .unwrap_err()
        .to_string()
    };
    let mut no_points = report_doc.clone();
    no_points["config"]["surface_points"] = Value::Null;
    let err = refused(&no_points);
    assert!(err.contains("surface_points"), "{err}");
    let mut wider = report_doc;
    wider["config"]["model"]["decoder_hidden"] = json!(cfg.model.decoder_hidden * 2);
    let err = refused(&wider);
    assert!(
        err.contains(WEIGHTS_FILE) && err.contains("decoder.fc_p.weight"),
        "{err}"
    );
}

/// A tiny data set of `objects` objects and a 10-step prior trained on it, for the
/// continued-training tests: (the data, its `train` import, the 10-step config, the prior).
fn ten_step_prior(objects: usize) -> (tempfile::TempDir, PathBuf, ShapeTrainConfig, PathBuf) {
    let data = tiny_dataset(objects);
    let train = data.path().join("train");
    let short = ShapeTrainConfig {
        steps: 10,
        eval_every: 0,
        ..tiny_config()
    };
    let base = data.path().join("base");
    train_shape(&train, &short, &base, &mut |_| {}).unwrap();
    (data, train, short, base)
}

/// `init_from` + `freeze_encoder` trains the decoder only: the codes stay byte-identical.
#[test]
fn freeze_encoder_trains_the_decoder_and_keeps_every_code() {
    let (data, train, short, base) = ten_step_prior(12);
    let continued = |out: &str, freeze_encoder: bool| {
        let cfg = ShapeTrainConfig {
            init_from: Some(base.join(WEIGHTS_FILE)),
            freeze_encoder,
            seed: 1,
            ..short.clone()
        };
        let out = data.path().join(out);
        train_shape(&train, &cfg, &out, &mut |_| {}).unwrap();
        out
    };
    let frozen = continued("frozen", true);
    let free = continued("free", false);
    let read = |dir: &Path, f: &str| std::fs::read(dir.join(f)).unwrap();
    // Same codes, byte for byte, so a denoiser trained on them stays valid ...
    assert_eq!(read(&base, CODEBOOK_FILE), read(&frozen, CODEBOOK_FILE));
    // ... while the decoder moved, and without the freeze the encoder moves too.
    assert_ne!(read(&base, WEIGHTS_FILE), read(&frozen, WEIGHTS_FILE));
    assert_ne!(read(&base, CODEBOOK_FILE), read(&free, CODEBOOK_FILE));
    // More positional-encoding octaves than the file's: the decoder is widened, the codes
    // stay, and the run records its own N_pe; fewer than the file's is refused.
    let with_pe = |out: &str, pe_freqs: usize| {
        let cfg = ShapeTrainConfig {
            init_from: Some(base.join(WEIGHTS_FILE)),
            freeze_encoder: true,
            model: ShapePriorConfig {
                pe_freqs,
                ..short.model
            },
            ..short.clone()
        };
        let out = data.path().join(out);
        train_shape(&train, &cfg, &out, &mut |_| {}).map(|_| out)
    };
    let wide = with_pe("wide", short.model.pe_freqs + 2).unwrap();
    assert_eq!(read(&base, CODEBOOK_FILE), read(&wide, CODEBOOK_FILE));
    let (_, wide_cfg, _) = load_shape_dir(&wide, &cpu()).unwrap();
    assert_eq!(wide_cfg.pe_freqs, short.model.pe_freqs + 2);
    let e = with_pe("narrow", short.model.pe_freqs - 1)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(WEIGHTS_FILE) && e.contains("decoder.fc_p.weight"),
        "{e}"
    );
    // A smaller decoder, or an encoder of other sizes (which growth never touches), is
    // refused with the file's name.
    for model in [
        ShapePriorConfig {
            decoder_hidden: 24,
            ..short.model
        },
        ShapePriorConfig {
            encoder_hidden: 48,
            ..short.model
        },
    ] {
        let cfg = ShapeTrainConfig {
            init_from: Some(base.join(WEIGHTS_FILE)),
            model,
            ..short.clone()
        };
        let e = train_shape(&train, &cfg, &data.path().join("bad"), &mut |_| {})
            .unwrap_err()
            .to_string();
        assert!(e.contains(WEIGHTS_FILE), "{e}");
    }
    // Freezing a random encoder is refused.
    let cfg = ShapeTrainConfig {
        freeze_encoder: true,
        ..short.clone()
    };
    let e = cfg.validate().unwrap_err().to_string();
    assert!(
        e.contains("freeze_encoder") && e.contains("init_from"),
        "{e}"
    );
}

/// `codes_from` trains the decoder on a codebook's fixed codes (here fitted ones, as the
/// shipped denoiser learns): the encoder stays, the run's codebook is the given one byte
/// for byte with its encoding recorded, each part gets its own row, and the loss on those
/// codes falls; a part without a code, codes of another width and a run without the frozen
/// encoder are refused, naming what is wrong.
#[test]
fn codes_from_trains_the_decoder_on_the_given_codes() {
    let (data, train, short, base) = ten_step_prior(14);
    let base_report: Value =
        serde_json::from_str(&std::fs::read_to_string(base.join(REPORT_FILE)).unwrap()).unwrap();
    let fit = Encoding {
        views: 2,
        fit_steps: 5,
        fit_queries: 64,
        fit_prox: 0.0,
    };
    let codes = data.path().join("codes");
    encode_shape_dir(
        &base.join(WEIGHTS_FILE),
        &base_report,
        &train,
        &codes,
        &fit,
        &mut |_, _| {},
    )
    .unwrap();
    let cfg = ShapeTrainConfig {
        init_from: Some(base.join(WEIGHTS_FILE)),
        freeze_encoder: true,
        codes_from: Some(codes.clone()),
        steps: 60,
        eval_every: 0,
        seed: 1,
        ..short.clone()
    };
    let out = data.path().join("on_codes");
    let rep = train_shape(&train, &cfg, &out, &mut |_| {}).unwrap();
    assert!(
        rep.final_loss < 0.9 * rep.initial_loss,
        "loss {} -> {}",
        rep.initial_loss,
        rep.final_loss
    );
    let read = |dir: &Path, f: &str| std::fs::read(dir.join(f)).unwrap();
    for f in [CODEBOOK_FILE, CODEBOOK_INDEX_FILE] {
        assert_eq!(read(&codes, f), read(&out, f), "{f}");
    }
    assert_ne!(read(&base, WEIGHTS_FILE), read(&out, WEIGHTS_FILE));
    let doc: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join(REPORT_FILE)).unwrap()).unwrap();
    assert_eq!(Encoding::of_report(&doc, &out).unwrap(), fit);
    assert_eq!(
        doc["config"]["codes_from"],
        json!(codes.display().to_string())
    );
    // The encoder did not move: its codes (NAP's encoding) are the base prior's.
    let all = read_index(&train).unwrap();
    let id = all[0].id.clone();
    let n = all.iter().filter(|p| p.id == id).count();
    let (before, ..) = load_shape_dir(&base, &cpu()).unwrap();
    let (after, ..) = load_shape_dir(&out, &cpu()).unwrap();
    let nap = Encoding::default();
    assert_eq!(
        encode_object_parts(&before, &train, &id, n, short.surface_points, &nap).unwrap(),
        encode_object_parts(&after, &train, &id, n, short.surface_points, &nap).unwrap()
    );
    // Each training part gets its own row, whatever order the run lists the parts in.
    let book = read_codebook(&codes, short.model.latent).unwrap();
    let f = short.model.latent;
    let mut refs: Vec<&PartRef> = all.iter().filter(|p| p.split == "train").collect();
    refs.reverse();
    let fixed = FixedCodes::read(&codes, f, &refs).unwrap();
    for (i, p) in refs.iter().enumerate() {
        let r = all.iter().position(|q| q.id == p.id && q.k == p.k).unwrap();
        assert_eq!(
            fixed.row(i),
            &book.codes[r * f..(r + 1) * f],
            "{}_{}",
            p.id,
            p.k
        );
    }
    // A training part missing from the codebook is named.
    let mut index: Value =
        serde_json::from_str(&std::fs::read_to_string(codes.join(CODEBOOK_INDEX_FILE)).unwrap())
            .unwrap();
    let key = format!("{}_{}", refs[0].id, refs[0].k);
    let row = index["keys"]
        .as_array()
        .unwrap()
        .iter()
        .position(|k| k["key"] == json!(key))
        .unwrap();
    index["keys"][row]["key"] = json!("elsewhere_0");
    let broken = data.path().join("broken");
    std::fs::create_dir_all(&broken).unwrap();
    std::fs::write(broken.join(CODEBOOK_FILE), read(&codes, CODEBOOK_FILE)).unwrap();
    std::fs::write(broken.join(CODEBOOK_INDEX_FILE), index.to_string()).unwrap();
    let run_on = |dir: &Path, model: ShapePriorConfig| {
        let cfg = ShapeTrainConfig {
            codes_from: Some(dir.to_path_buf()),
            model,
            ..cfg.clone()
        };
        train_shape(&train, &cfg, &data.path().join("refused"), &mut |_| {})
            .unwrap_err()
            .to_string()
    };
    let e = run_on(&broken, short.model);
    assert!(
        e.contains(&key) && e.contains(CODEBOOK_INDEX_FILE) && e.contains("no code"),
        "{e}"
    );
    // Codes of another width than the latent are refused with the file's name.
    let e = run_on(
        &codes,
        ShapePriorConfig {
            latent: f + 8,
            ..short.model
        },
    );
    assert!(
        e.contains(CODEBOOK_FILE) && e.contains(&format!("{f} dimensions")),
        "{e}"
    );
    // Without the frozen encoder the option is refused, naming both.
    let cfg = ShapeTrainConfig {
        freeze_encoder: false,
        ..cfg.clone()
    };
    let e = cfg.validate().unwrap_err().to_string();
    assert!(
        e.contains("codes_from") && e.contains("freeze_encoder") && e.contains("codes"),
        "{e}"
    );
}

/// A batch with fixed codes decodes those codes, not the encoder's: given the encoder's own
/// codes of its surface points, the loss is the loss without codes; other codes change it;
/// and the surface points no longer matter. Both backward passes take the same path.
#[test]
fn fixed_codes_replace_the_encoder_in_the_loss() {
    let cfg = ShapeTrainConfig {
        queries_per_part: 64,
        surface_points: 32,
        wrong_side: 10.0,
        eikonal: 0.03,
        ..tiny_config()
    };
    let device = crate::model::cpu_autodiff();
    let model = ShapePrior::with_seed(&cfg.model, 5, &device);
    let mut rng = Rng::new(6);
    let mut draw = |n: usize, lo: f64, hi: f64| -> Vec<f32> {
        (0..n).map(|_| rng.range(lo, hi) as f32).collect()
    };
    let b = 3;
    let (pts, tgt) = (
        draw(b * cfg.queries_per_part * 3, -0.5, 0.5),
        draw(b * cfg.queries_per_part, -0.2, 0.2),
    );
    let (surf, other_surf) = (
        draw(b * cfg.surface_points * 3, -0.5, 0.5),
        draw(b * cfg.surface_points * 3, -0.5, 0.5),
    );
    let encoded = to_vec(model.encoder.encode(Tensor::from_data(
        TensorData::new(surf.clone(), [b, cfg.surface_points, 3]),
        &device,
    )));
    let shifted: Vec<f32> = encoded.iter().map(|c| c + 0.5).collect();
    for backward in [DecoderBackward::Host, DecoderBackward::Burn] {
        let cfg = ShapeTrainConfig {
            decoder_backward: backward,
            ..cfg.clone()
        };
        let loss = |surf: &[f32], codes: &[f32]| {
            let batch = Batch {
                pts: pts.clone(),
                tgt: tgt.clone(),
                surf: surf.to_vec(),
                codes: codes.to_vec(),
            };
            batch_loss(&model, batch, &cfg, &device).1
        };
        let plain = loss(&surf, &[]);
        let fixed = loss(&surf, &encoded);
        assert!(
            (plain - fixed).abs() <= 1e-6 * plain.abs(),
            "{backward:?}: {plain} vs {fixed}"
        );
        assert_eq!(fixed, loss(&other_surf, &encoded), "{backward:?}");
        let moved = loss(&surf, &shifted);
        assert!(
            (moved - fixed).abs() > 1e-4 * fixed.abs(),
            "{backward:?}: {moved}"
        );
    }
}

/// `init_from` + `freeze_decoder` trains the encoder only: the decoder's field is the
/// same function, every code moves; freezing both, or a random decoder, is refused.
#[test]
fn freeze_decoder_trains_the_encoder_and_keeps_the_field() {
    let (data, train, short, base) = ten_step_prior(13);
    let cfg = ShapeTrainConfig {
        init_from: Some(base.join(WEIGHTS_FILE)),
        freeze_decoder: true,
        seed: 1,
        ..short.clone()
    };
    let frozen = data.path().join("frozen");
    train_shape(&train, &cfg, &frozen, &mut |_| {}).unwrap();
    let read = |dir: &Path, f: &str| std::fs::read(dir.join(f)).unwrap();
    assert_ne!(read(&base, CODEBOOK_FILE), read(&frozen, CODEBOOK_FILE));
    // The same field for the same points and codes, bit for bit.
    let device = cpu();
    let field = |dir: &Path| -> Vec<f32> {
        let (model, cfg, _) = load_shape_dir(dir, &device).unwrap();
        let pts: Vec<f32> = (0..3 * 50)
            .map(|i| ((i * 37 % 101) as f32 / 101.0) - 0.5)
            .collect();
        let codes: Vec<f32> = (0..2 * cfg.latent)
            .map(|i| ((i * 13 % 29) as f32 / 29.0) - 0.5)
            .collect();
        model
            .decoder
            .sdf(
                Tensor::<3>::from_data(TensorData::new(pts.repeat(2), [2, 50, 3]), &device),
                Tensor::<2>::from_data(TensorData::new(codes, [2, cfg.latent]), &device),
            )
            .into_data()
            .try_to_vec::<f32>()
            .unwrap()
    };
    let (a, b) = (field(&base), field(&frozen));
    assert!(
        a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
        "{a:?} {b:?}"
    );
    for (cfg, expect) in [
        (
            ShapeTrainConfig {
                freeze_decoder: true,
                ..short.clone()
            },
            "init_from",
        ),
        (
            ShapeTrainConfig {
                freeze_decoder: true,
                freeze_encoder: true,
                init_from: Some(base.join(WEIGHTS_FILE)),
                ..short.clone()
            },
            "nothing trains",
        ),
    ] {
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains("freeze_decoder") && e.contains(expect), "{e}");
    }
}

#[test]
fn sharded_steps_match_the_single_pass_and_are_deterministic() {
    // Two or three slices of the parts in parallel give the whole batch's loss and gradient
    // (L1, eikonal and code regulariser alike) up to float rounding, so a short run tracks
    // the single pass closely; and a sharded run repeats bit for bit.
    let data = tiny_dataset(39);
    let train = data.path().join("train");
    let mut runs = 0..;
    let run = |shards: usize, out: &str| {
        let cfg = ShapeTrainConfig {
            steps: 8,
            eval_every: 0,
            val_parts: 0,
            checkpoint_every: 0,
            eikonal: 0.1,
            batch_shards: shards,
            ..tiny_config()
        };
        let mut losses = Vec::new();
        let dir = data.path().join(out);
        train_shape(&train, &cfg, &dir, &mut |p| losses.push(p.loss)).unwrap();
        (losses, std::fs::read(dir.join(WEIGHTS_FILE)).unwrap())
    };
    super::super::check_sharded_runs(|k| run(k, &format!("run{}", runs.next().unwrap())));
}

/// A run split by `stop_at` + `resume` continues the same batch stream and report: the
/// first resumed step's loss (the checkpoint's weights on the next batch, before any Adam
/// update) equals the uninterrupted run's bit for bit, the first piece's losses and
/// evaluations are kept, the checkpoint is removed at the end; a resume with other training
/// options or mismatching weights is refused, naming the field or the file.
#[test]
fn stopped_run_resumes_from_its_checkpoint() {
    let data = tiny_dataset(39); // enough objects for a val split
    let train = data.path().join("train");
    let cfg = ShapeTrainConfig {
        steps: 12,
        eval_every: 4,
        checkpoint_every: 0,
        ..tiny_config()
    };
    let mut whole_losses = Vec::new();
    let whole = train_shape(&train, &cfg, &data.path().join("whole"), &mut |p| {
        whole_losses.push(p.loss)
    })
    .unwrap();

    let out = data.path().join("split");
    let first = ShapeTrainConfig {
        stop_at: Some(6),
        ..cfg.clone()
    };
    let mut losses = Vec::new();
    let r1 = train_shape(&train, &first, &out, &mut |p| losses.push(p.loss)).unwrap();
    assert_eq!(r1.steps, 6);
    assert!(out.join(CHECKPOINT_FILE).is_file() && !out.join(REPORT_FILE).exists());
    // A stopped run's weights load from its checkpoint, with its sizes.
    let (_, sizes, doc) = load_shape_dir(&out, &cpu()).unwrap();
    assert_eq!(sizes, cfg.model);
    assert_eq!(doc["step"], 6);
    // Other training options: refused, naming the field and both values.
    let other = ShapeTrainConfig {
        lr: 1e-3,
        resume: true,
        ..cfg.clone()
    };
    let err = train_shape(&train, &other, &out, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("lr") && err.contains("0.001") && err.contains("0.002"),
        "{err}"
    );

    // A checkpoint written before the wrong-side term existed has no such field: it ran
    // without the term and resumes as such.
    let ckpt = out.join(CHECKPOINT_FILE);
    let mut doc: Value = serde_json::from_str(&std::fs::read_to_string(&ckpt).unwrap()).unwrap();
    assert!(
        doc["config"]
            .as_object_mut()
            .unwrap()
            .remove("wrong_side")
            .is_some()
    );
    std::fs::write(&ckpt, doc.to_string()).unwrap();
    let resumed = ShapeTrainConfig {
        resume: true,
        ..cfg.clone()
    };
    let mut steps = Vec::new();
    let r2 = train_shape(&train, &resumed, &out, &mut |p| {
        steps.push(p.step);
        losses.push(p.loss);
    })
    .unwrap();
    assert_eq!(steps, (7..=12).collect::<Vec<_>>());
    assert_eq!(r2.steps, 12);
    assert_eq!(
        losses[..7],
        whole_losses[..7],
        "same weights and batches up to step 7"
    );
    assert_eq!(r2.initial_loss.to_bits(), mean_of(&losses).to_bits());
    let evals: Vec<usize> = r2.curve.iter().map(|e| e.step).collect();
    assert_eq!(evals, [4, 8, 12]);
    assert_eq!(r2.curve[0], r1.curve[0]);
    assert_eq!(r2.curve[0].iou.to_bits(), whole.curve[0].iou.to_bits());
    assert!(!out.join(CHECKPOINT_FILE).exists());
    assert!(out.join(REPORT_FILE).is_file() && out.join(CODEBOOK_FILE).is_file());

    // A checkpoint whose weights were replaced is refused, naming the weights file.
    let broken = data.path().join("broken");
    train_shape(&train, &first, &broken, &mut |_| {}).unwrap();
    std::fs::copy(out.join(WEIGHTS_FILE), broken.join(WEIGHTS_FILE)).unwrap();
    let err = train_shape(&train, &resumed, &broken, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(WEIGHTS_FILE) && err.contains("sha256"),
        "{err}"
    );
    let err = load_shape_dir(&broken, &cpu()).unwrap_err().to_string();
    assert!(
        err.contains(WEIGHTS_FILE) && err.contains("sha256"),
        "{err}"
    );
    // A finished run loads from its report; an empty directory is named as not a run.
    let (_, sizes, doc) = load_shape_dir(&out, &cpu()).unwrap();
    assert_eq!((sizes, doc["steps"].as_u64()), (cfg.model, Some(12)));
    let err = load_shape_dir(data.path(), &cpu()).unwrap_err().to_string();
    assert!(err.contains("not a `train shape` output"), "{err}");
}

/// A decoder with the code at every block trains (the loss falls), and its run directory
/// loads back with the option on: the report carries it to every loader.
#[test]
fn code_every_block_trains_and_loads_back() {
    let data = tiny_dataset(12);
    let train = data.path().join("train");
    let out = data.path().join("every");
    let mut cfg = ShapeTrainConfig {
        steps: 40,
        eval_every: 0,
        checkpoint_every: 0,
        val_parts: 0,
        ..tiny_config()
    };
    cfg.model.code_every_block = true;
    let report = train_shape(&train, &cfg, &out, &mut |_| {}).unwrap();
    assert!(
        report.final_loss < report.initial_loss,
        "{} → {}",
        report.initial_loss,
        report.final_loss
    );
    let (model, sizes, _) = load_shape_dir(&out, &cpu()).unwrap();
    assert_eq!(sizes, cfg.model);
    assert_eq!(
        model.decoder.feature_width(),
        cfg.model.decoder_hidden * cfg.model.decoder_blocks
    );
}

/// Fitting the codes with the decoder frozen (`eval shape --fit-codes`) lowers the L1 on
/// the parts' samples below what the encoder's codes give, and 0 steps is the plain
/// evaluation.
#[test]
fn fitted_codes_fit_the_samples_better_than_encoded_ones() {
    let data = tiny_dataset(39);
    let train = data.path().join("train");
    let out = data.path().join("run");
    let cfg = ShapeTrainConfig {
        steps: 30,
        eval_every: 0,
        checkpoint_every: 0,
        ..tiny_config()
    };
    train_shape(&train, &cfg, &out, &mut |_| {}).unwrap();
    let (model, _, _) = load_shape_dir(&out, &cpu()).unwrap();
    let run = |fit_steps| {
        let enc = Encoding {
            fit_steps,
            ..Encoding::default()
        };
        evaluate_shape_prior(&model, &train, &cfg, "val", 4, &enc, &mut |_, _| {})
    };
    let (_, encoded) = run(0).unwrap();
    let (_, again) = run(0).unwrap();
    let (_, fitted) = run(30).unwrap();
    assert_eq!(encoded.to_bits(), again.to_bits());
    assert!(
        fitted < 0.9 * encoded,
        "fitted {fitted} vs encoded {encoded}"
    );
}

/// The encoding protocol ([`Encoding`]): V views average V encoder calls on consecutive
/// blocks of surface points; a fit moves each code by its own part's samples only, so an
/// object's parts (`encode_object_parts`, `eval reconstruction`) get the codes the
/// codebook (`train encode`, batches of 32 parts) gives them; the report records the
/// encoding and reads it back, and a bad field is refused by name, limit and value.
#[test]
fn encodings_average_views_fit_per_part_and_are_recorded() {
    let (data, train, cfg, out) = ten_step_prior(13);
    let (model, _, report) = load_shape_dir(&out, &cpu()).unwrap();
    let all = read_index(&train).unwrap();
    let id = all[0].id.clone();
    let n = all.iter().filter(|p| p.id == id).count();
    let s = cfg.surface_points;
    let nap = Encoding::default();
    let two = Encoding { views: 2, ..nap };
    // Two views = the mean of the encoder on points 0..S and S..2S.
    let one = encode_object_parts(&model, &train, &id, n, s, &nap).unwrap();
    let avg = encode_object_parts(&model, &train, &id, n, s, &two).unwrap();
    let (_, pts) = read_rows(&all[0].file(&train, "surface"), 3).unwrap();
    let second = first_points(&pts, 2 * s)[3 * s..].to_vec();
    let z2 = to_vec(model.encoder.encode(Tensor::from_data(
        TensorData::new(second, [1, s, 3]),
        &cpu(),
    )));
    for (i, (a, b)) in one[0].iter().zip(&z2).enumerate() {
        let want = (a + b) / 2.0;
        assert!(
            (avg[0][i] - want).abs() < 1e-5,
            "dim {i}: {} vs {want}",
            avg[0][i]
        );
    }
    assert_ne!(one[0], avg[0]);
    // Fitted codes: the codebook's rows of this object are its own encoding's.
    let fit = Encoding {
        views: 2,
        fit_steps: 5,
        fit_queries: 64,
        fit_prox: 0.5,
    };
    let fitted = encode_object_parts(&model, &train, &id, n, s, &fit).unwrap();
    // The pull toward the encoder's code: a strong one keeps every code nearer to it than
    // the plain fit moves it.
    let dist = |a: &[f32], b: &[f32]| -> f32 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y) * (x - y))
            .sum::<f32>()
            .sqrt()
    };
    let plain = Encoding {
        fit_prox: 0.0,
        ..fit
    };
    let pulled = Encoding {
        fit_prox: 1000.0,
        ..fit
    };
    let plain = encode_object_parts(&model, &train, &id, n, s, &plain).unwrap();
    let pulled = encode_object_parts(&model, &train, &id, n, s, &pulled).unwrap();
    for k in 0..n {
        let (d0, d1) = (dist(&plain[k], &avg[k]), dist(&pulled[k], &avg[k]));
        assert!(d1 < 0.5 * d0, "part {k}: pulled {d1} vs plain {d0}");
    }
    let dir = data.path().join("fitted");
    let rep = encode_shape_dir(
        &out.join(WEIGHTS_FILE),
        &report,
        &train,
        &dir,
        &fit,
        &mut |_, _| {},
    )
    .unwrap();
    assert_eq!(rep.rows, all.len());
    let book = read_codebook(&dir, cfg.model.latent).unwrap();
    let f = cfg.model.latent;
    for (k, code) in fitted.iter().enumerate() {
        let row = all.iter().position(|p| p.id == id && p.k == k).unwrap();
        let stored = &book.codes[row * f..(row + 1) * f];
        let moved: f32 = code.iter().zip(&avg[k]).map(|(a, b)| (a - b).abs()).sum();
        assert!(moved > 1e-4, "part {k}: the fit did not move the code");
        for (a, b) in stored.iter().zip(code) {
            assert!((a - b).abs() < 1e-4, "part {k}: codebook {a} vs object {b}");
        }
    }
    let doc: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(REPORT_FILE)).unwrap()).unwrap();
    assert_eq!(Encoding::of_report(&doc, &dir).unwrap(), fit);
    assert_eq!(Encoding::of_report(&report, &out).unwrap(), nap);
    // NAP's encoding again drops the entry.
    let again = data.path().join("again");
    encode_shape_dir(
        &dir.join(WEIGHTS_FILE),
        &doc,
        &train,
        &again,
        &nap,
        &mut |_, _| {},
    )
    .unwrap();
    let doc: Value =
        serde_json::from_str(&std::fs::read_to_string(again.join(REPORT_FILE)).unwrap()).unwrap();
    assert!(doc["encoding"].is_null(), "{doc}");
    for (bad, field, limit, value) in [
        (
            Encoding { views: 0, ..nap },
            "encoder_views",
            "between 1 and 64",
            "0",
        ),
        (
            Encoding {
                fit_steps: 1001,
                ..nap
            },
            "fit_steps",
            "at most 1000",
            "1001",
        ),
        (
            Encoding {
                fit_queries: 7,
                ..nap
            },
            "fit_queries",
            "an even number",
            "7",
        ),
        (
            Encoding {
                fit_prox: -1.0,
                ..nap
            },
            "fit_prox",
            "between 0 and 1000",
            "-1",
        ),
    ] {
        let e = bad.validate().unwrap_err().to_string();
        assert!(
            e.contains(field) && e.contains(limit) && e.contains(value),
            "{e}"
        );
        let e = encode_object_parts(&model, &train, &id, n, s, &bad)
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{e}");
    }
}

/// With `ema_decay` the training losses are the raw run's (the EMA only reads the
/// weights), while the evaluations, the saved weights and the codebook come from the
/// averaged ones; a stopped EMA run checkpoints the shadow and resumes from it, and a
/// resume with another decay, or without the shadow's file, is refused by name.
#[test]
fn ema_run_saves_the_average_and_resumes_it() {
    let data = tiny_dataset(39);
    let train = data.path().join("train");
    let cfg = ShapeTrainConfig {
        steps: 8,
        eval_every: 4,
        checkpoint_every: 0,
        ..tiny_config()
    };
    let ema_cfg = ShapeTrainConfig {
        ema_decay: 0.9,
        ..cfg.clone()
    };
    let mut raw_losses = Vec::new();
    let raw = train_shape(&train, &cfg, &data.path().join("raw"), &mut |p| {
        raw_losses.push(p.loss)
    })
    .unwrap();
    let mut ema_losses = Vec::new();
    let averaged = train_shape(&train, &ema_cfg, &data.path().join("ema"), &mut |p| {
        ema_losses.push(p.loss)
    })
    .unwrap();
    assert_eq!(raw_losses, ema_losses, "the EMA must not change training");
    assert_ne!(
        raw.curve[1].l1, averaged.curve[1].l1,
        "evaluated the raw weights"
    );
    let weights = |dir: &str| std::fs::read(data.path().join(dir).join(WEIGHTS_FILE)).unwrap();
    assert_ne!(weights("raw"), weights("ema"), "saved the raw weights");
    let report: Value = serde_json::from_str(
        &std::fs::read_to_string(data.path().join("ema").join(REPORT_FILE)).unwrap(),
    )
    .unwrap();
    assert_eq!(report["config"]["ema_decay"], 0.9);

    let out = data.path().join("split");
    let first = ShapeTrainConfig {
        stop_at: Some(4),
        ..ema_cfg.clone()
    };
    train_shape(&train, &first, &out, &mut |_| {}).unwrap();
    assert!(out.join(EMA_CHECKPOINT_FILE).is_file());
    let other = ShapeTrainConfig {
        ema_decay: 0.99,
        resume: true,
        ..ema_cfg.clone()
    };
    let err = train_shape(&train, &other, &out, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("ema_decay") && err.contains("0.9"), "{err}");
    let resumed = ShapeTrainConfig {
        resume: true,
        ..ema_cfg.clone()
    };
    let kept = data.path().join("kept.safetensors");
    std::fs::rename(out.join(EMA_CHECKPOINT_FILE), &kept).unwrap();
    let err = train_shape(&train, &resumed, &out, &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains(EMA_CHECKPOINT_FILE), "{err}");
    std::fs::rename(&kept, out.join(EMA_CHECKPOINT_FILE)).unwrap();
    let mut losses = Vec::new();
    let r2 = train_shape(&train, &resumed, &out, &mut |p| losses.push(p.loss)).unwrap();
    assert_eq!(r2.steps, 8);
    assert_eq!(losses[0], ema_losses[4], "resumed from the raw weights");
    // The step-4 evaluation is the averaged weights' and survives the resume.
    assert_eq!(r2.curve[0].l1.to_bits(), averaged.curve[0].l1.to_bits());
    assert!(!out.join(EMA_CHECKPOINT_FILE).exists() && !out.join(CHECKPOINT_FILE).exists());
}

#[test]
fn weights_round_trip_bit_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config().model;
    let device = cpu();
    let model = ShapePrior::with_seed(&cfg, 42, &device);
    let path = dir.path().join(WEIGHTS_FILE);
    save_shape_prior(&model, &path).unwrap();
    let loaded = load_shape_prior(&path, &cfg, &device).unwrap();
    let mut rng = Rng::new(1);
    let pts: Vec<f32> = (0..2 * 50 * 3)
        .map(|_| rng.range(-0.5, 0.5) as f32)
        .collect();
    let run = |m: &ShapePrior| {
        let x = Tensor::<3>::from_data(TensorData::new(pts.clone(), [2, 50, 3]), &device);
        let z = m.encoder.encode(x.clone());
        (to_vec(z.clone()), to_vec(m.decoder.sdf(x, z)))
    };
    let (a, b) = (run(&model), run(&loaded));
    assert_eq!(a.0, b.0, "encoder outputs differ after reload");
    assert_eq!(a.1, b.1, "decoder outputs differ after reload");
    // A differently initialised model really differs (the comparison can fail).
    let other = ShapePrior::with_seed(&cfg, 43, &device);
    assert_ne!(run(&other).1, a.1);
    // Wrong sizes are refused, naming the file.
    let wrong = ShapePriorConfig {
        decoder_hidden: 48,
        ..cfg
    };
    let e = load_shape_prior(&path, &wrong, &device)
        .unwrap_err()
        .to_string();
    assert!(e.contains(WEIGHTS_FILE), "{e}");
}

#[test]
fn config_and_data_errors_are_specific() {
    let cfg = ShapeTrainConfig {
        queries_per_part: 7,
        ..ShapeTrainConfig::default()
    };
    let e = cfg.validate().unwrap_err().to_string();
    assert!(
        e.contains("queries_per_part") && e.contains("even") && e.contains('7'),
        "{e}"
    );
    let cfg = ShapeTrainConfig {
        val_parts: 65,
        ..ShapeTrainConfig::default()
    };
    let e = cfg.validate().unwrap_err().to_string();
    assert!(
        e.contains("val_parts") && e.contains("between 0 and 64") && e.contains("65"),
        "{e}"
    );
    let cfg = ShapeTrainConfig {
        lr: f64::NAN,
        ..ShapeTrainConfig::default()
    };
    assert!(cfg.validate().unwrap_err().to_string().contains("lr"));
    // Field, limit and value in each message.
    let d = ShapeTrainConfig::default;
    for (cfg, want) in [
        (
            ShapeTrainConfig {
                eikonal: -0.5,
                ..d()
            },
            ["eikonal", "between 0 and 100", "-0.5"],
        ),
        (
            ShapeTrainConfig {
                wrong_side: 101.0,
                ..d()
            },
            ["wrong_side", "between 0 and 100", "101"],
        ),
        (
            ShapeTrainConfig {
                batch_shards: 17,
                ..d()
            },
            ["batch_shards", "between 1 and 16", "17"],
        ),
    ] {
        let e = cfg.validate().unwrap_err().to_string();
        assert!(want.iter().all(|w| e.contains(w)), "{e}");
    }
    // The host backward pass is CPU code: a GPU run must take burn's.
    let cfg = ShapeTrainConfig {
        compute: Compute::Gpu(Some(0)),
        ..ShapeTrainConfig::default()
    };
    let e = cfg.validate().unwrap_err().to_string();
    assert!(
        e.contains("decoder_backward") && e.contains("gpu:0") && e.contains("host"),
        "{e}"
    );
    let dir = tempfile::tempdir().unwrap();
    let e = train_shape(
        dir.path(),
        &tiny_config(),
        &dir.path().join("o"),
        &mut |_| {},
    )
    .unwrap_err();
    assert_eq!(e.error_type(), "io");
    assert!(e.to_string().contains("dataset.json"), "{e}");
    std::fs::write(
        dir.path().join("dataset.json"),
        r#"{"objects":[{"id":"a","split":"train","parts":1}]}"#,
    )
    .unwrap();
    let e = train_shape(
        dir.path(),
        &tiny_config(),
        &dir.path().join("o"),
        &mut |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("part0_uniform.npy"), "{e}");
}

/// `eval shape` groups parts by their thinnest primitive: a shell's wall is its smallest
/// extent over κ, whatever the primitive's kind; parts without primitives have none.
#[test]
fn thinnest_primitive_is_the_thinnest_wall_over_kappa() {
    use crate::shape::{Axis, Primitive};
    let b = Vector3::new(0.3, 0.2, 0.25);
    let mut part = Part {
        name: "body".into(),
        half_extents: b,
        center: Vector3::zeros(),
        shape: PartShape::Primitives(vec![
            Primitive::Cuboid {
                center: Vector3::new(0.29, 0.0, 0.0),
                half_extents: Vector3::new(0.01, 0.2, 0.25),
            },
            Primitive::Cylinder {
                center: Vector3::zeros(),
                axis: Axis::Z,
                radius: 0.05,
                half_height: 0.25,
            },
        ]),
    };
    let kappa = 2.0 * b.norm();
    let t = thinnest_primitive(&part).unwrap();
    assert!((t - 0.02 / kappa).abs() < 1e-12, "{t}");
    // A thinner cylinder (diameter 0.01) becomes the thinnest.
    if let PartShape::Primitives(p) = &mut part.shape {
        p.push(Primitive::Cylinder {
            center: Vector3::zeros(),
            axis: Axis::X,
            radius: 0.005,
            half_height: 0.1,
        });
    }
    let t = thinnest_primitive(&part).unwrap();
    assert!((t - 0.01 / kappa).abs() < 1e-12, "{t}");
    part.shape = PartShape::Box;
    assert_eq!(thinnest_primitive(&part), None);
}

#[test]
fn truncated_residual_keeps_wrong_side_gradients() {
    let d = cpu();
    let t = |v: Vec<f32>| Tensor::<2>::from_data(TensorData::new(v, [1, 4]), &d);
    // Targets: far outside, far outside, inside the band, far inside.
    let target = t(vec![0.5, 0.5, 0.02, -0.3]);
    // Predictions: beyond the band (same side: free), wrong side, in band, wrong side.
    let pred = t(vec![0.3, -0.2, 0.05, 0.4]);
    let r = to_vec(truncated_residual(pred, target, 0.1));
    let want = [0.0, -0.3, 0.03, 0.5];
    for (a, b) in r.iter().zip(want) {
        assert!((a - b).abs() < 1e-6, "{r:?}");
    }
}

/// The host decoder pass ([`DecoderBackward::Host`]) gives burn autodiff's loss value and
/// gradients for every parameter — decoder layers, W_c, and the encoder through the codes —
/// with and without truncation, the eikonal term, positional encoding and residual blocks.
#[test]
fn host_decoder_backward_equals_burn_autodiff() {
    struct Randomise(Rng);
    impl burn::module::ModuleMapper for Randomise {
        fn map_float<const D: usize>(
            &mut self,
            param: burn::module::Param<Tensor<D>>,
        ) -> burn::module::Param<Tensor<D>> {
            param.map(|t| {
                let shape = t.shape();
                let n = shape.num_elements();
                let v: Vec<f32> = (0..n).map(|_| self.0.range(-0.3, 0.3) as f32).collect();
                Tensor::from_data(TensorData::new(v, shape), &t.device()).require_grad()
            })
        }
    }
    for (seed, pe_freqs, blocks, truncation, code_every_block, eikonal, wrong_side) in [
        (1, 4, 2, None, false, 0.0, 0.0),
        (2, 0, 1, Some(0.05), false, 0.0, 0.0),
        (3, 6, 0, None, false, 0.0, 0.0),
        (4, 4, 3, None, true, 0.0, 0.0),
        (5, 4, 2, None, false, 0.7, 0.0),
        (6, 6, 1, Some(0.05), true, 2.0, 0.0),
        (7, 4, 2, None, false, 0.0, 3.0),
        (8, 6, 1, Some(0.05), false, 0.7, 1.5),
    ] {
        let cfg = ShapeTrainConfig {
            model: ShapePriorConfig {
                latent: 12,
                decoder_hidden: 24,
                decoder_blocks: blocks,
                encoder_hidden: 8,
                encoder_blocks: 2,
                pe_freqs,
                code_every_block,
            },
            queries_per_part: 350, // 3 × 350 rows: several 128-row blocks and a partial one
            surface_points: 40,
            truncation,
            eikonal,
            wrong_side,
            w_reg: 0.01,
            ..ShapeTrainConfig::default()
        };
        let device = crate::model::cpu_autodiff();
        let model =
            ShapePrior::with_seed(&cfg.model, seed, &device).map(&mut Randomise(Rng::new(seed)));
        let mut rng = Rng::new(seed + 10);
        let mut draw = |n: usize, lo: f64, hi: f64| -> Vec<f32> {
            (0..n).map(|_| rng.range(lo, hi) as f32).collect()
        };
        let b = 3;
        let (pts, tgt, surf) = (
            draw(b * cfg.queries_per_part * 3, -0.55, 0.55),
            draw(b * cfg.queries_per_part, -0.2, 0.2),
            draw(b * cfg.surface_points * 3, -0.5, 0.5),
        );
        let batch = || Batch {
            pts: pts.clone(),
            tgt: tgt.clone(),
            surf: surf.clone(),
            codes: Vec::new(),
        };
        let run = |backward: DecoderBackward| {
            let cfg = ShapeTrainConfig {
                decoder_backward: backward,
                ..cfg.clone()
            };
            let (loss, value) = batch_loss(&model, batch(), &cfg, &device);
            let grads = loss.backward();
            macro_rules! grad {
                ($t:expr) => {
                    $t.grad(&grads)
                        .expect("every parameter has a gradient")
                        .into_data()
                        .try_to_vec::<f32>()
                        .unwrap()
                };
            }
            let mut params: Vec<(String, Vec<f32>)> = Vec::new();
            for (k, l) in decoder_linears(&model.decoder).into_iter().enumerate() {
                params.push((format!("decoder layer {k} W"), grad!(l.weight.val())));
                if let Some(bias) = &l.bias {
                    params.push((format!("decoder layer {k} b"), grad!(bias.val())));
                }
            }
            let (dec, enc) = (&model.decoder, &model.encoder);
            params.push(("decoder fc_c W".into(), grad!(dec.fc_c.weight.val())));
            params.push(("encoder fc_pos W".into(), grad!(enc.fc_pos.weight.val())));
            params.push(("encoder fc_c W".into(), grad!(enc.fc_c.weight.val())));
            (value, params)
        };
        let (host_value, host) = run(DecoderBackward::Host);
        let (burn_value, burn) = run(DecoderBackward::Burn);
        // Each extra term is there: the same batch without it has a different loss.
        for (on, plain) in [
            (
                eikonal > 0.0,
                ShapeTrainConfig {
                    eikonal: 0.0,
                    ..cfg.clone()
                },
            ),
            (
                wrong_side > 0.0,
                ShapeTrainConfig {
                    wrong_side: 0.0,
                    ..cfg.clone()
                },
            ),
        ] {
            if on {
                let (_, without) = batch_loss(&model, batch(), &plain, &device);
                assert!(
                    (host_value - without).abs() > 1e-3,
                    "seed {seed}: the term left the loss at {without}"
                );
            }
        }
        assert!(
            (host_value - burn_value).abs() <= 1e-5 * burn_value.abs().max(1.0),
            "loss: host {host_value} vs burn {burn_value}"
        );
        assert_eq!(host.len(), burn.len());
        // The eikonal term divides the two implementations' f32 rounding of f by h = 0.005
        // (forward differences), so its gradients agree to 2·10⁻³, the rest to 10⁻⁴.
        let tol = if eikonal > 0.0 { 2e-3 } else { 1e-4 };
        for ((name, h), (_, w)) in host.iter().zip(&burn) {
            let scale = w.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            assert!(scale > 0.0, "{name}: burn's gradient is all zero");
            for (i, (x, y)) in h.iter().zip(w).enumerate() {
                assert!(
                    (x - y).abs() <= tol * scale,
                    "seed {seed} {name}[{i}]: host {x} vs burn {y} (scale {scale})"
                );
            }
        }
    }
}

#[test]
fn l1_upstream_follows_the_truncated_residual() {
    // (pred, target) as in truncated_residual_keeps_wrong_side_gradients, δ = 0.1: beyond
    // the band on the target's side is free, the wrong side keeps its gradient.
    let cases = [
        (0.3, 0.5, (0.0, 0.0)),
        (-0.2, 0.5, (0.3, -1.0)),
        (0.05, 0.02, (0.03, 1.0)),
        (0.4, -0.3, (0.5, 1.0)),
        (-0.4, -0.3, (0.0, 0.0)),
    ];
    for (pred, target, (abs, sign)) in cases {
        let (a, s) = l1_upstream(pred, target, Some(0.1));
        assert!(
            (a - abs).abs() < 1e-6 && s == sign,
            "{pred} {target}: {a} {s}"
        );
    }
    let (a, s) = l1_upstream(0.3, 0.5, None);
    assert!((a - 0.2).abs() < 1e-6 && s == -1.0, "{a} {s}");
    assert_eq!(l1_upstream(0.5, 0.5, None), (0.0, 0.0));
}

/// `near_fraction` sets how many of a part's queries come from its near-surface samples
/// (here tagged by their target: uniform rows 1, near rows −1); the default is NAP's half.
#[test]
fn near_fraction_sets_the_share_of_near_surface_queries() {
    let part = PartSamples {
        uniform: [0.1, 0.2, 0.3, 1.0].repeat(10),
        near: [0.0, 0.0, 0.0, -1.0].repeat(10),
        surface: [0.0; 3].repeat(8),
    };
    let parts = [part];
    for (fraction, near) in [(0.5, 32), (0.75, 48), (1.0, 64), (0.0, 0)] {
        let cfg = ShapeTrainConfig {
            queries_per_part: 64,
            surface_points: 8,
            near_fraction: fraction,
            ..ShapeTrainConfig::default()
        };
        cfg.validate().unwrap();
        assert_eq!(cfg.near_queries(), near);
        let batch = sample_batch(&parts, &[0, 0], &cfg, None, &mut Rng::new(1));
        assert_eq!(batch.tgt.len(), 128);
        assert_eq!(
            batch.tgt.iter().filter(|&&t| t < 0.0).count(),
            2 * near,
            "fraction {fraction}"
        );
    }
    let err = ShapeTrainConfig {
        near_fraction: 1.5,
        ..ShapeTrainConfig::default()
    }
    .validate()
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("near_fraction") && err.contains("between 0 and 1") && err.contains("1.5"),
        "{err}"
    );
}

#[test]
fn cosine_schedule_ends_at_the_final_factor() {
    let cfg = ShapeTrainConfig {
        steps: 101,
        lr: 1e-3,
        lr_final_factor: 0.1,
        ..ShapeTrainConfig::default()
    };
    assert!((cfg.lr_at(0) - 1e-3).abs() < 1e-12);
    assert!((cfg.lr_at(50) - 0.55e-3).abs() < 1e-9);
    assert!((cfg.lr_at(100) - 1e-4).abs() < 1e-12);
}

/// Training-step throughput of the default config on in-memory sphere data (BENCHMARKS.md):
/// `cargo test --release --lib train::shape::tests::training_throughput -- --ignored
/// --nocapture`.
#[test]
#[ignore = "benchmark"]
fn training_throughput() {
    let mut rng = Rng::new(3);
    let mut rows = |n: usize| -> Vec<f32> {
        (0..n)
            .flat_map(|_| {
                let p: [f32; 3] = std::array::from_fn(|_| rng.range(-0.55, 0.55) as f32);
                let d = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.3;
                [p[0], p[1], p[2], d]
            })
            .collect()
    };
    let parts: Vec<PartSamples> = (0..64)
        .map(|_| {
            let uniform = rows(4096);
            let near = rows(4096);
            let surface = rows(1024)
                .chunks(4)
                .flat_map(|r| [r[0], r[1], r[2]])
                .collect();
            PartSamples {
                uniform,
                near,
                surface,
            }
        })
        .collect();
    for (batch_parts, queries_per_part, surface_points, backward) in [
        (16, 2048, 512, DecoderBackward::Burn),
        (16, 2048, 512, DecoderBackward::Host),
        (32, 1024, 512, DecoderBackward::Host),
        (16, 2048, 256, DecoderBackward::Host),
        (32, 2048, 256, DecoderBackward::Host),
    ] {
        let cfg = ShapeTrainConfig {
            batch_parts,
            queries_per_part,
            surface_points,
            decoder_backward: backward,
            ..ShapeTrainConfig::default()
        };
        let mut trainer = Trainer::new(&cfg, &parts, None).unwrap();
        trainer.step(0).unwrap();
        let n = 10;
        let t0 = Instant::now();
        for step in 1..=n {
            trainer.step(step).unwrap();
        }
        let dt = t0.elapsed().as_secs_f64() / n as f64;
        println!(
            "train step (default model, {} backward) B={batch_parts} Q={queries_per_part} S={surface_points}: {:.2} steps/s, {:.0} queries/s, {:.0} ms/step, threads {}",
            backward.name(),
            1.0 / dt,
            (batch_parts * queries_per_part) as f64 / dt,
            dt * 1e3,
            rayon::current_num_threads()
        );
    }
}

/// A real run on an imported data set, until the CLI exposes `physnap train shape`:
/// `PHYSNAP_SHAPE_DATA=D/train PHYSNAP_SHAPE_OUT=D/out PHYSNAP_SHAPE_STEPS=3000 cargo test
/// --release --lib train::shape::tests::train_from_env -- --ignored --nocapture`. Optional:
/// `PHYSNAP_SHAPE_{EVAL_EVERY,LR,LR_FINAL,BATCH,QUERIES,SURFACE,DEC_H,DEC_B,ENC_H,ENC_B,
/// VAL_PARTS,TRUNCATION,SEED,THREADS}`.
#[test]
#[ignore = "manual training run"]
fn train_from_env() {
    let var = |k: &str| std::env::var(format!("PHYSNAP_SHAPE_{k}")).ok();
    let num = |k: &str, d: f64| var(k).map_or(d, |v| v.parse::<f64>().unwrap());
    let (Some(data), Some(out)) = (var("DATA"), var("OUT")) else {
        panic!("set PHYSNAP_SHAPE_DATA and PHYSNAP_SHAPE_OUT");
    };
    let d = ShapeTrainConfig::default();
    let m = d.model;
    let cfg = ShapeTrainConfig {
        model: ShapePriorConfig {
            decoder_hidden: num("DEC_H", m.decoder_hidden as f64) as usize,
            decoder_blocks: num("DEC_B", m.decoder_blocks as f64) as usize,
            encoder_hidden: num("ENC_H", m.encoder_hidden as f64) as usize,
            encoder_blocks: num("ENC_B", m.encoder_blocks as f64) as usize,
            ..m
        },
        steps: num("STEPS", d.steps as f64) as usize,
        eval_every: num("EVAL_EVERY", d.eval_every as f64) as usize,
        lr: num("LR", d.lr),
        lr_final_factor: num("LR_FINAL", d.lr_final_factor),
        batch_parts: num("BATCH", d.batch_parts as f64) as usize,
        queries_per_part: num("QUERIES", d.queries_per_part as f64) as usize,
        surface_points: num("SURFACE", d.surface_points as f64) as usize,
        val_parts: num("VAL_PARTS", d.val_parts as f64) as usize,
        truncation: var("TRUNCATION").map(|v| v.parse().unwrap()),
        seed: num("SEED", 0.0) as u64,
        threads: var("THREADS").map(|v| v.parse().unwrap()),
        ..d
    };
    println!("{cfg:?}");
    let report = train_shape(Path::new(&data), &cfg, Path::new(&out), &mut |p| {
        if p.step % 50 == 0 || p.val_iou.is_some() {
            println!(
                "step {} loss {:.5} lr {:.2e} t {:.0}s{}",
                p.step,
                p.loss,
                p.lr,
                p.elapsed_s,
                p.val_iou
                    .map(|i| format!(" val_iou {i:.4} val_l1 {:.5}", p.val_l1.unwrap_or(f64::NAN)))
                    .unwrap_or_default()
            );
        }
    })
    .unwrap();
    println!("{report:?}");
}

/// Per-part IoU of a finished run: `PHYSNAP_SHAPE_DATA=D/train PHYSNAP_SHAPE_OUT=D/run
/// cargo test --release --lib train::shape::tests::eval_from_env -- --ignored --nocapture`
/// (`PHYSNAP_SHAPE_VAL_PARTS`, default 64).
#[test]
#[ignore = "manual evaluation"]
fn eval_from_env() {
    let var = |k: &str| std::env::var(format!("PHYSNAP_SHAPE_{k}")).ok();
    let (Some(data), Some(out)) = (var("DATA"), var("OUT")) else {
        panic!("set PHYSNAP_SHAPE_DATA and PHYSNAP_SHAPE_OUT");
    };
    let (data, out) = (Path::new(&data), Path::new(&out));
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join(REPORT_FILE)).unwrap()).unwrap();
    let model_cfg = read_model_config(&out.join(REPORT_FILE)).unwrap();
    let model = load_shape_prior(&out.join(WEIGHTS_FILE), &model_cfg, &cpu()).unwrap();
    let cfg = ShapeTrainConfig {
        model: model_cfg,
        surface_points: report["config"]["surface_points"].as_u64().unwrap() as usize,
        val_parts: var("VAL_PARTS").map_or(MAX_VAL_PARTS, |v| v.parse().unwrap()),
        ..ShapeTrainConfig::default()
    };
    let (ious, l1) = evaluate_shape_prior(
        &model,
        data,
        &cfg,
        "val",
        cfg.val_parts,
        &Encoding::default(),
        &mut |_, _| {},
    )
    .unwrap();
    for p in &ious {
        let kind = match p.primitives {
            Some(n) => format!("{n} primitives"),
            None => "mesh".into(),
        };
        println!(
            "{} iou {:.3} thickness {:.4} {kind}",
            p.key, p.iou, p.thinnest
        );
    }
    let mean = ious.iter().map(|p| p.iou).sum::<f64>() / ious.len() as f64;
    println!("mean iou {mean:.4} over {} parts, l1 {l1:.5}", ious.len());
}
