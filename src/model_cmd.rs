//! `physnap train …` and `physnap generate`: flags to library calls, progress bars, reports.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use physnap::data::categories::category_index;
use physnap::engine::EngineError;
use physnap::engine::generate::{
    GenerateRequest, JointMotion, PartShapes, Retrieval, generate_with as run_generate,
};
use physnap::engine::guidance::{GuidanceOptions, SdfField};
use physnap::engine::sample::Sampler;
use physnap::engine::schedule::Schedule;
use physnap::eval::guided::metrics as guided_metrics;
use physnap::export::{ExportOptions, export_dir};
use physnap::io::manifest::{
    Entry, LoadedModels, Manifest, load_models, to_string as manifest_to_string,
};
use physnap::mesh::MeshingOptions;
use physnap::model::Compute;
use physnap::model::denoiser::DenoiserConfig;
use physnap::model::shape_prior::LatentSdfDecoder;
use physnap::model::weights::sha256_hex;
use physnap::pointcloud::{Limits, PointCloud};
use physnap::train::codebook::{
    CODEBOOK_WEIGHTS_FILE, CodebookReport, DEFAULT_CHECK_RESOLUTION, build_codebook,
};
use physnap::train::diffusion::{DiffusionTrainConfig, load_data, train_diffusion};
use physnap::train::shape::{
    DecoderBackward, Encoding, ShapeTrainConfig, encode_shape_dir, load_shape_prior,
    model_config_of, read_model_config, train_shape, write_atomic,
};

use super::{
    CodebookArgs, DiffusionArgs, EncodeArgs, EvalGuidedArgs, GenerateArgs, InstallShapeArgs,
    ShapeArgs,
};

pub fn shape(a: ShapeArgs) -> anyhow::Result<()> {
    let defaults = ShapeTrainConfig::default();
    let m = defaults.model;
    let compute = Compute::parse("device", &a.device)?;
    let cfg = ShapeTrainConfig {
        model: physnap::model::shape_prior::ShapePriorConfig {
            decoder_hidden: a.decoder_hidden.unwrap_or(m.decoder_hidden),
            decoder_blocks: a.decoder_blocks.unwrap_or(m.decoder_blocks),
            encoder_hidden: a.encoder_hidden.unwrap_or(m.encoder_hidden),
            encoder_blocks: a.encoder_blocks.unwrap_or(m.encoder_blocks),
            pe_freqs: a.pe_freqs.unwrap_or(m.pe_freqs),
            code_every_block: a.code_every_block,
            ..m
        },
        queries_per_part: a.queries_per_part.unwrap_or(defaults.queries_per_part),
        near_fraction: a.near_fraction.unwrap_or(defaults.near_fraction),
        surface_points: a.surface_points.unwrap_or(defaults.surface_points),
        lr: a.lr.unwrap_or(defaults.lr),
        lr_final_factor: a.lr_final_factor.unwrap_or(defaults.lr_final_factor),
        truncation: a.truncation.or(defaults.truncation),
        wrong_side: a.wrong_side.unwrap_or(defaults.wrong_side),
        ema_decay: a.ema_decay.unwrap_or(defaults.ema_decay),
        val_parts: a.val_parts.unwrap_or(defaults.val_parts),
        steps: a.steps,
        seed: a.seed,
        batch_parts: a.batch_parts.unwrap_or(defaults.batch_parts),
        max_parts: a.max_parts,
        eval_every: a.eval_every,
        checkpoint_every: a.checkpoint_every,
        resume: a.resume,
        stop_at: a.stop_at,
        decoder_backward: match (a.decoder_backward.as_deref(), compute) {
            (Some("burn"), _) | (None, Compute::Gpu(_)) => DecoderBackward::Burn,
            _ => DecoderBackward::Host,
        },
        compute,
        init_from: a.init_from.as_ref().map(|p| {
            if p.is_dir() {
                p.join("shape_prior.safetensors")
            } else {
                p.clone()
            }
        }),
        freeze_encoder: a.freeze_encoder,
        freeze_decoder: a.freeze_decoder,
        codes_from: a.codes.clone(),
        eikonal: a.eikonal.unwrap_or(defaults.eikonal),
        batch_shards: a.batch_shards.unwrap_or(defaults.batch_shards),
        ..defaults
    };
    let pb = super::progress_bar(cfg.steps, "shape");
    let report = train_shape(&a.data, &cfg, &a.out, &mut |p| {
        pb.set_position(p.step as u64);
        match p.val_iou {
            Some(iou) => {
                pb.set_prefix(format!("loss {:.4} val IoU {iou:.3}", p.loss));
                // Also in the log, where a hidden bar (no TTY) shows no prefix.
                tracing::info!(
                    "shape: step {} val IoU {iou:.4}, val L1 {:.5}, loss {:.5}, lr {:.2e}, {:.0} s",
                    p.step,
                    p.val_l1.unwrap_or(f64::NAN),
                    p.loss,
                    p.lr,
                    p.elapsed_s
                );
            }
            None => pb.set_prefix(format!("loss {:.4}", p.loss)),
        }
    })?;
    pb.finish_and_clear();
    if report.steps < cfg.steps {
        println!(
            "stopped the shape prior at step {} of {} with a checkpoint in {} (continue with --resume)",
            report.steps,
            cfg.steps,
            a.out.display()
        );
        return Ok(());
    }
    println!(
        "trained the shape prior for {} steps in {:.0} s: loss {:.4} -> {:.4}, val IoU {}",
        report.steps,
        report.wall_s,
        report.initial_loss,
        report.final_loss,
        report
            .val_iou
            .map(|v| format!("{v:.3}"))
            .unwrap_or_else(|| "n/a".into())
    );
    println!("weights and codebook: {}", a.out.display());
    Ok(())
}

/// A weights directory's manifest (and its path) and the path of its shape prior, whose sha256
/// is checked against the manifest's.
fn manifest_with_shape_prior(weights: &Path) -> anyhow::Result<(Manifest, PathBuf, PathBuf)> {
    let path = weights.join("manifest.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let manifest = physnap::io::manifest::from_str(&text, &path.display().to_string())?;
    let file = weights.join(&manifest.shape_prior.file);
    let sha =
        sha256_hex(&std::fs::read(&file).with_context(|| format!("reading {}", file.display()))?);
    if sha != manifest.shape_prior.sha256 {
        bail!(
            "{}: sha256 {sha} does not match manifest.json's shape_prior.sha256 {}; the file is corrupt or from other weights",
            file.display(),
            manifest.shape_prior.sha256
        );
    }
    Ok((manifest, path, file))
}

pub fn encode(a: EncodeArgs) -> anyhow::Result<()> {
    // A weights directory (its manifest's training.shape report), or a `train shape` output
    // directory (its shape_train.json), e.g. a decoder cycle's, before any denoiser exists.
    let shape_report = a.weights.join("shape_train.json");
    let (report, path, file) =
        if !a.weights.join("manifest.json").is_file() && shape_report.is_file() {
            let report = read_json(&shape_report)?;
            let file = a.weights.join(physnap::train::shape::WEIGHTS_FILE);
            (report, shape_report, file)
        } else {
            let (manifest, path, file) = manifest_with_shape_prior(&a.weights)?;
            (manifest.training["shape"].clone(), path, file)
        };
    let mut report = report;
    if report.is_object() {
        report["lineage"] = lineage(&a.weights, &report)?;
    }
    let report = &report;
    if !report.is_object() {
        bail!(
            "{}: no training.shape report (the shape prior's shape_train.json), which holds the encoder input size",
            path.display()
        );
    }
    let encoding = Encoding {
        views: a.encoder_views,
        fit_steps: a.fit_steps,
        fit_queries: a.fit_queries,
        fit_prox: a.fit_prox,
    };
    encoding.validate()?;
    let t = std::time::Instant::now();
    let pb = super::progress_bar(0, "parts");
    let enc = encode_shape_dir(
        &file,
        report,
        &a.data,
        &a.out,
        &encoding,
        &mut |done, total| {
            pb.set_length(total as u64);
            pb.set_position(done as u64);
        },
    )?;
    pb.finish_and_clear();
    println!(
        "encoded {} parts of {} ({} surface points a view, {} view(s), {} fitting steps on {} samples, pull {}) with {} in {:.0} s; shape directory: {}",
        enc.rows,
        a.data.display(),
        enc.surface_points,
        encoding.views,
        encoding.fit_steps,
        encoding.fit_queries,
        encoding.fit_prox,
        file.display(),
        t.elapsed().as_secs_f64(),
        a.out.display()
    );
    Ok(())
}

/// A JSON file, with its path in the error.
fn read_json(path: &Path) -> anyhow::Result<serde_json::Value> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
}

/// The runs a shape prior continued, for the manifest `train diffusion` writes from the
/// encoded directory: `{"shape_base": the prior trained from scratch, "shape_cycles": the
/// decoder cycles between it and this one, oldest first}`. A weights directory's manifest has
/// them already (`install-shape` records them); a `train shape` directory's report names the
/// weights it started from (`config.init_from`), whose directory's report is followed back to
/// the run without one, or whose weights directory's manifest ends the chain with the history
/// it keeps. A start whose report is gone (or a relative path from elsewhere) ends it there.
fn lineage(dir: &Path, report: &serde_json::Value) -> anyhow::Result<serde_json::Value> {
    let manifest = dir.join("manifest.json");
    if manifest.is_file() {
        let m = read_json(&manifest)?;
        return Ok(serde_json::json!({
            "shape_base": m["training"]["shape_base"],
            "shape_cycles": m["training"]["shape_cycles"],
        }));
    }
    let mut chain = Vec::new();
    let mut at = report.clone();
    // A chain longer than this is a loop of directories, not a history.
    for _ in 0..64 {
        let Some(from) = at["config"]["init_from"].as_str().map(PathBuf::from) else {
            break;
        };
        let Some(dir) = from.parent() else { break };
        let weights = dir.join("manifest.json");
        if weights.is_file() {
            // A weights directory (a cycle trained on installed weights): its prior, then the
            // history its manifest keeps, newest first.
            let m = read_json(&weights)?;
            let t = &m["training"];
            chain.push(t["shape"].clone());
            if let Some(cycles) = t["shape_cycles"].as_array() {
                chain.extend(cycles.iter().rev().cloned());
            }
            if !t["shape_base"].is_null() {
                chain.push(t["shape_base"].clone());
            }
            break;
        }
        let prev = dir.join(physnap::train::shape::REPORT_FILE);
        if !prev.is_file() {
            break;
        }
        at = read_json(&prev)?;
        chain.push(at.clone());
    }
    // chain: newest first; its last entry is the base.
    let base = chain.pop().unwrap_or(serde_json::Value::Null);
    chain.reverse();
    Ok(serde_json::json!({
        "shape_base": base,
        "shape_cycles": if chain.is_empty() { serde_json::Value::Null } else { chain.into() },
    }))
}

pub fn install_shape(a: InstallShapeArgs) -> anyhow::Result<()> {
    let (mut manifest, path, installed) = manifest_with_shape_prior(&a.weights)?;
    let report_path = a.shape.join("shape_train.json");
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&report_path)
            .with_context(|| format!("reading {}", report_path.display()))?,
    )
    .with_context(|| format!("parsing {}", report_path.display()))?;
    let cfg = model_config_of(&report, &report_path)?;
    let installed_cfg = manifest.shape_prior.config;
    // A decoder grown by train shape --init-from (more octaves, wider, deeper) keeps the
    // encoder and the code space; any other difference, or a smaller decoder, is refused.
    cfg.check_decoder_growth(&installed_cfg).with_context(|| {
        format!(
            "{}: model sizes {cfg:?} do not grow the installed shape prior's {installed_cfg:?}",
            report_path.display()
        )
    })?;
    // Fitted codes (the encoding's fitting steps) were fitted to the installed decoder: another
    // decoder decodes them into other shapes unless it was trained on them (`train shape
    // --codes`, whose report keeps their encoding). Codes from the encoder alone stay valid
    // under any decoder that keeps the encoder.
    let installed_enc = Encoding::of_report(&manifest.training["shape"], &path)?;
    let new_enc = Encoding::of_report(&report, &report_path)?;
    if installed_enc.fit_steps > 0
        && (report["config"]["codes_from"].is_null() || new_enc != installed_enc)
    {
        bail!(
            "{}: the installed codes were fitted {} steps to the installed decoder (training.shape.encoding in {}), so a decoder not trained on them decodes them into other shapes; train it on those codes (train shape --init-from {} --freeze-encoder --codes DIR, DIR the train encode output the denoiser learned), or train a new denoiser",
            report_path.display(),
            installed_enc.fit_steps,
            path.display(),
            a.weights.display()
        );
    }
    let candidate = a.shape.join("shape_prior.safetensors");
    let device = physnap::model::cpu();
    let old = load_shape_prior(&installed, &installed_cfg, &device)?;
    let new = load_shape_prior(&candidate, &cfg, &device)?;
    // Same encoder = same function: both encode the same 8 × 256 seeded points to the same
    // bits (weights that differ anywhere change the codes).
    let mut rng = physnap::data::rng::Rng::new(0x5eed);
    let points: Vec<f32> = (0..8 * 256 * 3)
        .map(|_| (rng.uniform() - 0.5) as f32)
        .collect();
    let probe = || {
        burn::tensor::Tensor::<3>::from_data(
            burn::tensor::TensorData::new(points.clone(), [8, 256, 3]),
            &device,
        )
    };
    let codes = |m: &physnap::model::shape_prior::ShapePrior| -> Vec<f32> {
        m.encoder
            .encode(probe())
            .into_data()
            .try_into_vec::<f32>()
            .expect("model outputs are f32")
    };
    if codes(&old) != codes(&new) {
        bail!(
            "{}: its encoder differs from the installed one in {}, so every part's code, and the denoiser trained on them, would change; train it with --init-from {} --freeze-encoder, or train a new denoiser on it (train diffusion)",
            candidate.display(),
            a.weights.display(),
            a.weights.display()
        );
    }
    let new_bytes =
        std::fs::read(&candidate).with_context(|| format!("reading {}", candidate.display()))?;
    write_atomic(&installed, &new_bytes)?;
    manifest.shape_prior.sha256 = sha256_hex(&new_bytes);
    manifest.shape_prior.config = cfg;
    // Every run this one continued stays on record: `shape_base` is the prior trained from
    // scratch (its encoder made the codes), `shape_cycles` the decoder cycles installed since,
    // oldest first. The metrics were measured with the old decoder.
    let previous = std::mem::replace(&mut manifest.training["shape"], report);
    if manifest.training["shape_base"].is_null() {
        manifest.training["shape_base"] = previous;
    } else {
        match &mut manifest.training["shape_cycles"] {
            serde_json::Value::Array(cycles) => cycles.push(previous),
            slot => *slot = serde_json::Value::Array(vec![previous]),
        }
    }
    manifest.metrics = serde_json::Value::Null;
    if a.no_codebook {
        manifest.codebook = None;
    }
    std::fs::write(&path, manifest_to_string(&manifest))
        .with_context(|| format!("writing {}", path.display()))?;
    println!(
        "installed the shape prior of {} into {} (same encoder, so the codes and the denoiser are unchanged); the manifest's metrics are cleared: run eval generative --write-manifest",
        a.shape.display(),
        a.weights.display()
    );
    if a.no_codebook {
        remove_codebook(&a.weights)?;
        return Ok(());
    }
    write_codebook(&a.shape, &a.weights, DEFAULT_CHECK_RESOLUTION)?;
    Ok(())
}

/// Remove the retrieval codebook file of `weights` (the caller has written a manifest without
/// its entry): one built with another decoder or denoiser run must not linger beside these.
fn remove_codebook(weights: &Path) -> anyhow::Result<()> {
    let file = weights.join(CODEBOOK_WEIGHTS_FILE);
    if file.exists() {
        std::fs::remove_file(&file).with_context(|| format!("removing {}", file.display()))?;
    }
    println!(
        "no retrieval codebook (--no-codebook): build it with physnap train codebook --shape S --weights {}",
        weights.display()
    );
    Ok(())
}

pub fn diffusion(a: DiffusionArgs) -> anyhow::Result<()> {
    let compute = Compute::parse("device", &a.device)?;
    let data = load_data(&a.data, &a.shape)?;
    let model = DenoiserConfig {
        width: a.width,
        layers: a.layers,
        category_layers: a.category_layers,
        ..DenoiserConfig::default()
    };
    let cfg = DiffusionTrainConfig {
        model: model.clone(),
        steps: a.steps,
        batch_objects: a.batch_objects,
        noise_levels: a.noise_levels,
        lr: a.lr,
        seed: a.seed,
        checkpoint_every: a.checkpoint_every,
        lr_decay_start: a.lr_decay_start,
        lr_final_factor: a.lr_final_factor,
        ema_decay: a.ema_decay,
        stop_at: a.stop_at,
        min_snr_gamma: a.min_snr_gamma,
        high_noise_cap: a.high_noise_cap,
        overlap_weight: a.overlap_weight,
        overlap_max_t: a.overlap_max_t,
        layout_gain: a.layout_gain,
        code_gain: a.code_gain,
        category_dropout: a.category_dropout,
        batch_shards: a.batch_shards,
        compute,
    };
    let pb = super::progress_bar(cfg.steps, "diffusion");
    let report = train_diffusion(&data, &cfg, &a.out, a.resume, &mut |p| {
        pb.set_position(p.step as u64);
        pb.set_prefix(format!("loss {:.4} (ema {:.4})", p.loss, p.loss_ema));
    })?;
    pb.finish_and_clear();
    // Ship the shape prior next to the denoiser and describe both in the manifest.
    let shape_src = a.shape.join("shape_prior.safetensors");
    let shape_dst = a.out.join("shape_prior.safetensors");
    std::fs::copy(&shape_src, &shape_dst)
        .with_context(|| format!("copying {}", shape_src.display()))?;
    let shape_sha = sha256_hex(&std::fs::read(&shape_dst)?);
    let shape_cfg = read_model_config(&a.shape.join("shape_train.json"))?;
    let read = |p: &Path| -> serde_json::Value {
        std::fs::read_to_string(p)
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok())
            .unwrap_or(serde_json::Value::Null)
    };
    let manifest = Manifest {
        shape_prior: Entry {
            file: "shape_prior.safetensors".into(),
            sha256: shape_sha,
            config: shape_cfg,
        },
        denoiser: Entry {
            file: "denoiser.safetensors".into(),
            sha256: report.sha256.clone(),
            config: model,
        },
        feature_scales: report.scales.clone(),
        categories: physnap::data::categories::CATEGORIES
            .iter()
            .map(|s| s.to_string())
            .collect(),
        data: serde_json::json!({ "dataset": a.data.display().to_string(), "synth": read(&a.data.join("../synth/synth.json")) }),
        training: {
            // `train encode` records the runs its prior continued under "lineage"; the
            // manifest keeps them beside it, as `install-shape` does. A `train shape`
            // directory (a decoder cycle on the codes, `--codes`) is followed back through
            // the runs it started from.
            let mut shape = read(&a.shape.join("shape_train.json"));
            let lineage = match shape.as_object_mut().and_then(|o| o.remove("lineage")) {
                Some(l) => l,
                None if shape.is_object() => lineage(&a.shape, &shape)?,
                None => serde_json::Value::Null,
            };
            let mut t = serde_json::json!({
                "shape": shape,
                "diffusion": read(&a.out.join("diffusion_train.json")),
            });
            for k in ["shape_base", "shape_cycles"] {
                if !lineage[k].is_null() {
                    t[k] = lineage[k].clone();
                }
            }
            t
        },
        codebook: None,
        metrics: serde_json::Value::Null,
    };
    std::fs::write(a.out.join("manifest.json"), manifest_to_string(&manifest))?;
    // Every new weights directory gets its retrieval codebook (needs the manifest above), unless
    // asked not to. The weights are usable without one, so a codebook that cannot be built is a
    // warning here (`physnap train codebook` reports it as an error).
    if a.no_codebook {
        remove_codebook(&a.out)?;
    } else if let Err(e) = write_codebook(&a.shape, &a.out, DEFAULT_CHECK_RESOLUTION) {
        eprintln!("warning: weights written without a retrieval codebook: {e:#}");
    }
    println!(
        "trained the denoiser for {} steps in {:.0} s ({:.0} s including resumed runs; loss ema {:.4}); weights + manifest in {}",
        report.steps,
        report.wall_seconds,
        report.wall_seconds_total,
        report.final_loss,
        a.out.display()
    );
    if report.steps < a.steps {
        println!(
            "stopped at step {} of {} (--stop-at); continue with the same command and --resume",
            report.steps, a.steps
        );
    }
    Ok(())
}

pub fn codebook(a: CodebookArgs) -> anyhow::Result<()> {
    write_codebook(&a.shape, &a.weights, a.check_resolution)?;
    Ok(())
}

/// Build and register the retrieval codebook of `weights` (with a progress bar).
fn write_codebook(shape: &Path, weights: &Path, check: usize) -> anyhow::Result<CodebookReport> {
    let pb = super::progress_bar(0, "codebook");
    let report = build_codebook(shape, weights, check, &mut |done, total| {
        pb.set_length(total as u64);
        pb.set_position(done as u64);
    })?;
    pb.finish_and_clear();
    println!(
        "codebook: {} of {} training codes decode non-empty (checked at {check}³) in {:.0} s; {} in {}",
        report.rows,
        report.candidates,
        report.seconds,
        CODEBOOK_WEIGHTS_FILE,
        weights.display()
    );
    if !report.categories {
        println!(
            "codebook: the codes carry no categories (the shape directory's codebook.json names none; remake it with `physnap train encode`), so --retrieval category is unavailable"
        );
    }
    Ok(report)
}

/// The `--retrieval` flag against the loaded weights: `auto` is `empty` with a codebook and
/// `off` without one; `empty` / `all` without a codebook are refused.
pub fn retrieval_mode(flag: &str, models: &LoadedModels) -> anyhow::Result<Retrieval> {
    let has = models.codebook.is_some();
    match (flag, Retrieval::parse(flag)) {
        ("auto", _) => Ok(if has {
            Retrieval::Empty
        } else {
            Retrieval::Off
        }),
        (_, Some(Retrieval::Off)) => Ok(Retrieval::Off),
        (_, Some(r)) if has => Ok(r),
        (_, Some(_)) => bail!(
            "invalid --retrieval {flag:?}: these weights have no codebook (manifest.json has no \"codebook\" entry); add one with `physnap train codebook` or use --retrieval off"
        ),
        (_, None) => {
            bail!("invalid --retrieval {flag:?} (must be auto, off, empty, all or category)")
        }
    }
}

/// The `--joint-motion` flag.
pub fn joint_motion(flag: &str) -> anyhow::Result<JointMotion> {
    JointMotion::parse(flag)
        .with_context(|| format!("invalid --joint-motion {flag:?} (must be screw or dominant)"))
}

/// The `--sampler` / `--eta` flags (`ddim` or `ddpm`; clap has checked the name).
pub fn sampler(name: &str, eta: f64) -> Sampler {
    match name {
        "ddim" => Sampler::Ddim { eta },
        _ => Sampler::Ddpm,
    }
}

pub fn generate(a: GenerateArgs) -> anyhow::Result<()> {
    let manifest_path = a.weights.join("manifest.json");
    if !manifest_path.is_file() {
        bail!(
            "no trained weights at {} (train them with `physnap train shape` and `physnap train diffusion`, see README)",
            manifest_path.display()
        );
    }
    let device = physnap::model::cpu();
    let models = load_models(&a.weights, &device)?;
    let category = match &a.category {
        None => None,
        Some(c) => {
            let idx = category_index(c)
                .filter(|&i| i < models.manifest.categories.len())
                .with_context(|| {
                    format!(
                        "invalid --category {c:?} (must be one of: {})",
                        models.manifest.categories.join(", ")
                    )
                })?;
            if models.manifest.denoiser.config.categories == 0 {
                bail!("invalid --category {c:?}: these weights are unconditional");
            }
            Some(idx)
        }
    };
    if a.samples == 0 {
        bail!("invalid --samples: 0 (must be at least 1)");
    }
    let guidance = guidance_options(&a)?;
    let loss_guided = guidance.as_ref().is_some_and(|g| g.is_active());
    let sampler = sampler(&a.sampling.sampler, a.sampling.eta);
    let req = GenerateRequest {
        seed: a.seed,
        samples: a.samples,
        category,
        category_name: category.map(|i| models.manifest.categories[i].clone()),
        meshing: MeshingOptions {
            resolution: a.resolution,
        },
        guidance: guidance.clone(),
        sampler,
        steps: a.sampling.steps,
        retrieval: retrieval_mode(&a.sampling.retrieval, &models)?,
        category_guidance: a.sampling.category.weight(loss_guided),
        category_guidance_below: Some(a.sampling.category.below(loss_guided)),
        joint_motion: joint_motion(&a.sampling.joint_motion)?,
        ..Default::default()
    };
    req.meshing.validate()?;
    let schedule = Schedule::default();
    let steps = physnap::engine::schedule::timesteps(schedule.len(), a.sampling.steps).len();
    let pb = super::progress_bar(a.samples * steps, "generate");
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let started = std::time::Instant::now();
    let mut last_losses = None;
    // One request per sample (sample i uses seed + i either way), so a guided sample that
    // diverges is reported and the others still count for best-of-N.
    let mut results = Vec::new();
    let mut diverged = Vec::new();
    for i in 0..a.samples {
        let one = GenerateRequest {
            seed: a.seed.wrapping_add(i as u64),
            samples: 1,
            ..req.clone()
        };
        let shapes = PartShapes {
            decoder: &decoder,
            field: Some(&decoder as &dyn SdfField),
            codebook: models.codebook.as_ref(),
        };
        let r = run_generate(
            &models.denoiser,
            &shapes,
            &models.manifest.feature_scales,
            &schedule,
            &one,
            &mut |e| {
                pb.set_position((i * e.step.total + e.step.step) as u64);
                if let Some(l) = e.step.guidance {
                    last_losses = Some(l);
                }
                ControlFlow::Continue(())
            },
        );
        match r {
            Ok(mut out) => {
                let mut g = out.remove(0);
                g.index = i;
                g.object.name = format!("sample_{i:03}");
                results.push(g);
            }
            Err(e @ EngineError::Diverged { .. }) => {
                pb.println(format!("sample_{i:03} (seed {}): {e}", one.seed));
                diverged.push((format!("sample_{i:03}"), one.seed, e.to_string()));
            }
            Err(e) => return Err(e.into()),
        }
    }
    pb.finish_and_clear();
    if results.is_empty() {
        bail!(
            "all {} samples diverged (first: {}); lower the guidance weights (--w-pc/--w-pen/--w-mob) or --guidance-steps",
            a.samples,
            diverged.first().map(|d| d.2.as_str()).unwrap_or("")
        );
    }
    let per_sample = started.elapsed().as_secs_f64() / a.samples as f64;
    let opts = ExportOptions {
        meshing: req.meshing,
        ..Default::default()
    };
    let mut rows = Vec::new();
    for g in &results {
        let name = format!("sample_{:03}", g.index);
        let dir = a.out.join(&name);
        export_dir(&g.object, &g.meshes, &dir, &opts)?;
        println!(
            "{}: {} parts, {} joints (seed {})",
            dir.display(),
            g.object.parts.len(),
            g.object.joints.len(),
            g.seed
        );
        if !g.retrieved.is_empty() {
            println!(
                "  parts {:?} took their nearest codebook shape (--retrieval {})",
                g.retrieved,
                req.retrieval.as_str()
            );
        }
        if let Some(opts) = &guidance {
            let m = guided_metrics(&decoder, &g.raw, &g.object, &g.meshes, &opts.points, g.seed);
            rows.push((name, g.seed, m));
        }
    }
    println!("{per_sample:.1} s per sample (sampling + meshing)");
    if let Some(l) = last_losses {
        println!(
            "last guided step: ℓ_pc {:.4e}, ℓ_pen {:.4e}, ℓ_mob {:.4e}, weighted {:.4e}",
            l.pc, l.pen, l.mob, l.total
        );
    }
    if let (Some(opts), Some(points)) = (&guidance, &a.points) {
        write_ranking(&a.out, points, opts, rows, &diverged)?;
    }
    Ok(())
}

/// The guidance of `generate`: paper defaults for the terms that are on, flags override.
fn guidance_options(a: &GenerateArgs) -> anyhow::Result<Option<GuidanceOptions>> {
    let points = match &a.points {
        Some(path) => {
            let cloud = PointCloud::read(
                path,
                &Limits {
                    min_points: 1,
                    max_points: physnap::engine::guidance::MAX_POINTS,
                },
            )
            .with_context(|| format!("invalid --points {}", path.display()))?;
            cloud.points
        }
        None => Vec::new(),
    };
    if points.is_empty() && a.w_pc.is_some_and(|w| w > 0.0) {
        bail!("invalid --w-pc: needs --points (the observed point cloud)");
    }
    if points.is_empty() && a.w_pen.is_none() && a.w_mob.is_none() {
        return Ok(None);
    }
    let [w_pc, w_pen, w_mob] =
        GuidanceOptions::weights_or_defaults([a.w_pc, a.w_pen, a.w_mob], !points.is_empty());
    let opts = GuidanceOptions {
        points,
        w_pc,
        w_pen,
        w_mob,
        steps: a.sampling.guidance_steps,
        tau: a.sampling.tau,
        max_step: super::max_step(a.sampling.guidance_max_step),
        refine_steps: a.sampling.guidance_refine_steps,
        refine_physics_steps: a.sampling.guidance_refine_physics_steps,
    };
    opts.validate(Schedule::default().len())?;
    Ok(Some(opts))
}

/// `ranking.json`: samples by ascending D_pc (the paper's best-of-N), the best one marked.
fn write_ranking(
    out: &Path,
    points: &Path,
    opts: &GuidanceOptions,
    mut rows: Vec<(String, u64, physnap::eval::guided::GuidedMetrics)>,
    diverged: &[(String, u64, String)],
) -> anyhow::Result<()> {
    rows.sort_by(|a, b| {
        let key = |m: &physnap::eval::guided::GuidedMetrics| {
            if m.d_pc.is_finite() {
                m.d_pc
            } else {
                f64::INFINITY
            }
        };
        key(&a.2).total_cmp(&key(&b.2)).then(a.0.cmp(&b.0))
    });
    let num = |v: f64| {
        if v.is_finite() {
            serde_json::json!(v)
        } else {
            serde_json::Value::Null
        }
    };
    let ranked: Vec<serde_json::Value> = rows
        .iter()
        .enumerate()
        .map(|(r, (name, seed, m))| {
            serde_json::json!({
                "rank": r + 1,
                "sample": name,
                "seed": seed,
                "best": r == 0,
                "d_pc": num(m.d_pc),
                "e_pc": num(m.e_pc),
                "e_pen": num(m.e_pen),
                "e_mob": num(m.e_mob),
                "o_mesh": num(m.o_mesh),
            })
        })
        .collect();
    let best = rows.first().map(|r| r.0.clone());
    let doc = serde_json::json!({
        "format": "physnap.ranking/v1",
        "points": points.display().to_string(),
        "ranked_by": "d_pc (mean point-to-mesh distance, m)",
        "guidance": {
            "w_pc": opts.w_pc, "w_pen": opts.w_pen, "w_mob": opts.w_mob,
            "steps": opts.steps, "tau": opts.tau,
        },
        "best": best,
        "samples": ranked,
        "diverged": diverged.iter().map(|(name, seed, error)| serde_json::json!({
            "sample": name, "seed": seed, "error": error,
        })).collect::<Vec<_>>(),
    });
    let path = out.join("ranking.json");
    std::fs::write(&path, serde_json::to_string_pretty(&doc)? + "\n")?;
    for (r, (name, _, m)) in rows.iter().enumerate() {
        println!(
            "{}{}: D_pc {:.4} E_pc {:.5} E_pen {:.5} E_mob {:.5}",
            if r == 0 { "best " } else { "     " },
            name,
            m.d_pc,
            m.e_pc,
            m.e_pen,
            m.e_mob
        );
    }
    println!("ranking: {}", path.display());
    Ok(())
}

/// Clouds of `dir`: from testset.json when present (with categories), else every cloud file.
fn read_clouds(
    dir: &Path,
    skip: usize,
    max: usize,
) -> anyhow::Result<Vec<physnap::eval::guided::Cloud>> {
    let limits = Limits {
        min_points: 1,
        max_points: physnap::engine::guidance::MAX_POINTS,
    };
    let index = dir.join("testset.json");
    let mut entries: Vec<(String, Option<usize>, std::path::PathBuf)> = Vec::new();
    if index.is_file() {
        let doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&index)?)
            .with_context(|| format!("parsing {}", index.display()))?;
        for c in doc["clouds"].as_array().into_iter().flatten() {
            let id = c["id"].as_str().unwrap_or_default().to_string();
            let file = c["cloud"].as_str().with_context(|| {
                format!("{}: cloud entry without a \"cloud\" file", index.display())
            })?;
            let category = c["category"].as_str().and_then(category_index);
            entries.push((id, category, dir.join(file)));
        }
    } else {
        let mut files: Vec<_> = std::fs::read_dir(dir)
            .with_context(|| format!("invalid --clouds {}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| physnap::pointcloud::Format::from_path(p).is_some())
            .collect();
        files.sort();
        for p in files {
            let id = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            entries.push((id, None, p));
        }
    }
    let available = entries.len();
    if skip > 0 {
        if skip >= available {
            bail!(
                "invalid --skip-clouds: {skip} (must be below the {available} clouds in {})",
                dir.display()
            );
        }
        entries.drain(..skip);
    }
    if max > 0 {
        entries.truncate(max);
    }
    if entries.is_empty() {
        bail!(
            "invalid --clouds {}: no point clouds (must hold testset.json or .ply/.npy/.json files)",
            dir.display()
        );
    }
    entries
        .into_iter()
        .map(|(id, category, path)| {
            let cloud = PointCloud::read(&path, &limits)
                .with_context(|| format!("reading {}", path.display()))?;
            Ok(physnap::eval::guided::Cloud {
                id,
                category,
                points: cloud.points,
            })
        })
        .collect()
}

pub fn eval_guided(a: EvalGuidedArgs) -> anyhow::Result<()> {
    use physnap::eval::generative::IdOptions;
    use physnap::eval::guided::{
        SweepKind, TableOptions, run_rows, sweep_rows, table_markdown, table_rows,
    };
    if a.samples_per_cloud == 0 {
        bail!("invalid --samples-per-cloud: 0 (must be at least 1)");
    }
    let sweep = a.sweep.as_deref().map(SweepKind::parse).transpose()?;
    if sweep.is_some() && !a.variants.is_empty() {
        bail!("invalid --variants with --sweep: a sweep chooses its own rows (drop one of them)");
    }
    if sweep.is_some() && a.loss_scales.is_some() {
        bail!(
            "invalid --loss-scales with --sweep: a sweep chooses its own weights (drop one of them)"
        );
    }
    let device = physnap::model::cpu();
    let models = load_models(&a.weights, &device)?;
    let clouds = read_clouds(&a.clouds, a.skip_clouds, a.max_clouds)?;
    let meshing = MeshingOptions {
        resolution: a.resolution,
    };
    meshing.validate()?;
    let conditional = models.manifest.denoiser.config.categories > 0;
    let opts = TableOptions {
        samples_per_cloud: a.samples_per_cloud,
        seed: a.seed,
        first_cloud: a.skip_clouds,
        category_aware: match a.category_aware.as_str() {
            "no" => vec![false],
            "yes" => vec![true],
            _ if conditional => vec![false, true],
            _ => vec![false],
        },
        variants: a.variants.clone(),
        guided_steps: a.sampling.guidance_steps,
        tau: a.sampling.tau,
        loss_scales: match a.loss_scales.as_deref() {
            None => physnap::engine::guidance::DEFAULT_LOSS_SCALES,
            Some(&[pc, pen, mob]) => [pc, pen, mob],
            Some(other) => bail!(
                "invalid --loss-scales: {} values (must be three: PC,PEN,MOB)",
                other.len()
            ),
        },
        max_step: super::max_step(a.sampling.guidance_max_step),
        refine_steps: a.sampling.guidance_refine_steps,
        refine_physics_steps: a.sampling.guidance_refine_physics_steps,
        sampler: sampler(&a.sampling.sampler, a.sampling.eta),
        steps: a.sampling.steps,
        meshing,
        references: Vec::new(),
        scanned: Vec::new(),
        id: IdOptions {
            states: a.id_states,
            points: a.id_points,
        },
        retrieval: retrieval_mode(&a.sampling.retrieval, &models)?,
        category_guidance: a.sampling.category.category_guidance,
        category_guidance_below: a.sampling.category.category_guidance_below,
        joint_motion: joint_motion(&a.sampling.joint_motion)?,
    };
    opts.id.validate()?;
    let per_cloud = if a.refs_per_cloud == 0 {
        a.samples_per_cloud
    } else {
        a.refs_per_cloud
    };
    let opts = match &a.data {
        Some(data) => {
            eprintln!(
                "preparing up to {per_cloud} reference objects per cloud from {}…",
                data.display()
            );
            let (references, scanned) =
                super::eval_cmd::cloud_references(data, &clouds, per_cloud, &opts.id, a.seed)?;
            TableOptions {
                references,
                scanned,
                ..opts
            }
        }
        None => opts,
    };
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    if a.category_aware == "yes" && !conditional {
        bail!("invalid --category-aware yes: the weights' denoiser has no category input");
    }
    let specs = match sweep {
        Some(kind) => sweep_rows(
            kind,
            &opts.category_aware,
            &a.sweep_ng,
            &a.sweep_weights,
            &a.sweep_tau,
            a.sampling.guidance_steps,
            a.sampling.tau,
        )?,
        None => table_rows(&opts)?,
    };
    let pb = super::progress_bar(
        specs.len() * clouds.len() * a.samples_per_cloud,
        "eval guided",
    );
    let on_sample = &mut |done: usize, _: usize| pb.set_position(done as u64);
    let rows = run_rows(
        &models.denoiser,
        &decoder,
        models.codebook.as_ref(),
        &models.manifest.feature_scales,
        &Schedule::default(),
        &clouds,
        &opts,
        &specs,
        on_sample,
    )?;
    pb.finish_and_clear();
    let stem = match sweep {
        Some(kind) => format!("sweep_{}", kind.name()),
        None => "guided_table".to_string(),
    };
    let md = table_markdown(&rows);
    print!("{md}");
    std::fs::create_dir_all(&a.out)?;
    std::fs::write(a.out.join(format!("{stem}.md")), &md)?;
    let num = |v: f64| {
        if v.is_finite() {
            serde_json::json!(v)
        } else {
            serde_json::Value::Null
        }
    };
    let sample_json = |s: &physnap::eval::guided::SampleRecord| {
        let m = |i: usize| s.metrics.map(|m| num(m[i]));
        serde_json::json!({
            "cloud": s.cloud, "seed": s.seed, "seconds": s.seconds, "diverged": s.metrics.is_none(),
            "e_pc": m(0), "d_pc": m(1), "e_pen": m(2), "e_mob": m(3), "o_mesh": m(4),
            "id_gt": s.id_gt.map(num),
        })
    };
    let row_json = |r: &physnap::eval::guided::TableRow| {
        let mut v = serde_json::json!({
            "category_aware": r.category_aware, "variant": r.variant,
            "guidance": r.guidance.map(|g| serde_json::json!({
                "w_pc": g.w_pc, "w_pen": g.w_pen, "w_mob": g.w_mob, "n_g": g.steps, "tau": g.tau,
            })),
            "e_pc": num(r.e_pc), "d_pc": num(r.d_pc), "e_pen": num(r.e_pen), "e_mob": num(r.e_mob),
            "e_pen_mean": num(r.e_pen_mean), "e_mob_mean": num(r.e_mob_mean),
            "pen_share": num(r.pen_share), "mob_share": num(r.mob_share),
            "o_mesh_mean": num(r.o_mesh_mean), "o_mesh_share": num(r.o_mesh_share),
            "mmd": num(r.mmd), "one_nna": num(r.one_nna),
            "samples": r.samples, "diverged": r.diverged, "seconds_per_sample": r.seconds_per_sample,
            "per_sample": r.per_sample.iter().map(sample_json).collect::<Vec<_>>(),
        });
        // Set apart: two more keys inside the json! above exceed the macro's recursion limit.
        v["id_gt"] = num(r.id_gt);
        v["id_gt_mean"] = num(r.id_gt_mean);
        v["category_guidance"] = r.category_guidance.map(|(w, _)| w).into();
        v["category_guidance_below"] = r.category_guidance.map(|(_, b)| b).into();
        v
    };
    let json = serde_json::json!({
        "format": "physnap.guided_table/v1",
        "clouds": clouds.iter().map(|c| c.id.clone()).collect::<Vec<_>>(),
        "samples_per_cloud": a.samples_per_cloud,
        "skip_clouds": a.skip_clouds,
        "command": std::env::args().collect::<Vec<_>>().join(" "),
        "seed": a.seed, "guidance_steps": a.sampling.guidance_steps, "tau": a.sampling.tau,
        "guidance_max_step": opts.max_step, "guidance_refine_steps": opts.refine_steps,
        "guidance_refine_physics_steps": opts.refine_physics_steps,
        "loss_scales": opts.loss_scales,
        "sampler": a.sampling.sampler, "steps": a.sampling.steps, "eta": a.sampling.eta,
        // The flags as given (null: each row's default, recorded in the row).
        "category_guidance": a.sampling.category.category_guidance,
        "category_guidance_below": a.sampling.category.category_guidance_below,
        "retrieval": opts.retrieval.as_str(), "joint_motion": a.sampling.joint_motion,
        "statistic": "E_* and D_pc: median over all samples; MMD and 1-NNA: per cloud (its samples vs its references), median over clouds; ID_gt: each sample's instantiation distance to the scanned object, median and mean over samples",
        "references": a.data.as_ref().map(|d| serde_json::json!({
            "data": d.display().to_string(), "per_cloud": per_cloud,
            "id_states": a.id_states, "id_points": a.id_points,
        })),
        "sweep": a.sweep,
        "rows": rows.iter().map(row_json).collect::<Vec<_>>(),
    });
    std::fs::write(
        a.out.join(format!("{stem}.json")),
        serde_json::to_string_pretty(&json)? + "\n",
    )?;
    println!("table: {}", a.out.join(format!("{stem}.md")).display());
    Ok(())
}
