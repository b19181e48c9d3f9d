//! `physnap train …` and `physnap generate`: flags to library calls, progress bars, reports.

use std::ops::ControlFlow;
use std::path::Path;

use anyhow::{Context, bail};

use physnap::data::categories::category_index;
use physnap::engine::generate::{GenerateRequest, generate as run_generate};
use physnap::engine::schedule::Schedule;
use physnap::export::{ExportOptions, export_dir};
use physnap::io::manifest::{Entry, Manifest, load_models, to_string as manifest_to_string};
use physnap::mesh::MeshingOptions;
use physnap::model::denoiser::DenoiserConfig;
use physnap::model::shape_prior::LatentSdfDecoder;
use physnap::model::weights::sha256_hex;
use physnap::train::diffusion::{DiffusionTrainConfig, load_data, train_diffusion};
use physnap::train::shape::{ShapeTrainConfig, read_model_config, train_shape};

use super::{DiffusionArgs, GenerateArgs, ShapeArgs};

pub fn shape(a: ShapeArgs) -> anyhow::Result<()> {
    let defaults = ShapeTrainConfig::default();
    let cfg = ShapeTrainConfig {
        steps: a.steps,
        seed: a.seed,
        batch_parts: a.batch_parts.unwrap_or(defaults.batch_parts),
        max_parts: a.max_parts,
        ..defaults
    };
    let pb = super::progress_bar(cfg.steps, "shape");
    let report = train_shape(&a.data, &cfg, &a.out, &mut |p| {
        pb.set_position(p.step as u64);
        match p.val_iou {
            Some(iou) => pb.set_prefix(format!("loss {:.4} val IoU {iou:.3}", p.loss)),
            None => pb.set_prefix(format!("loss {:.4}", p.loss)),
        }
    })?;
    pb.finish_and_clear();
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

pub fn diffusion(a: DiffusionArgs) -> anyhow::Result<()> {
    let data = load_data(&a.data, &a.shape)?;
    let model = DenoiserConfig {
        width: a.width,
        layers: a.layers,
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
        ..DiffusionTrainConfig::default()
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
        feature_scales: data.scales.clone(),
        categories: physnap::data::categories::CATEGORIES
            .iter()
            .map(|s| s.to_string())
            .collect(),
        data: serde_json::json!({ "dataset": a.data.display().to_string(), "synth": read(&a.data.join("../synth/synth.json")) }),
        training: serde_json::json!({
            "shape": read(&a.shape.join("shape_train.json")),
            "diffusion": read(&a.out.join("diffusion_train.json")),
        }),
        metrics: serde_json::Value::Null,
    };
    std::fs::write(a.out.join("manifest.json"), manifest_to_string(&manifest))?;
    println!(
        "trained the denoiser for {} steps in {:.0} s (loss ema {:.4}); weights + manifest in {}",
        report.steps,
        report.wall_seconds,
        report.final_loss,
        a.out.display()
    );
    Ok(())
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
    let req = GenerateRequest {
        seed: a.seed,
        samples: a.samples,
        category,
        category_name: category.map(|i| models.manifest.categories[i].clone()),
        meshing: MeshingOptions {
            resolution: a.resolution,
        },
        ..Default::default()
    };
    req.meshing.validate()?;
    let schedule = Schedule::default();
    let pb = super::progress_bar(a.samples * schedule.len(), "generate");
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let results = run_generate(
        &models.denoiser,
        &decoder,
        &models.manifest.feature_scales,
        &schedule,
        &req,
        &mut |e| {
            pb.set_position((e.sample * e.step.total + e.step.step) as u64);
            ControlFlow::Continue(())
        },
    )?;
    pb.finish_and_clear();
    let opts = ExportOptions {
        meshing: req.meshing,
        ..Default::default()
    };
    for g in &results {
        let dir = a.out.join(format!("sample_{:03}", g.index));
        export_dir(&g.object, &g.meshes, &dir, &opts)?;
        println!(
            "{}: {} parts, {} joints (seed {})",
            dir.display(),
            g.object.parts.len(),
            g.object.joints.len(),
            g.seed
        );
    }
    Ok(())
}
