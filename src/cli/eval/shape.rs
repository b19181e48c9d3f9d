//! `physnap eval shape`: the shape prior's IoU per part and by kind.

use super::*;
use anyhow::bail;
use clap::Args;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub(crate) struct EvalShapeArgs {
    /// Weights directory with manifest.json, or a `train shape` output directory
    /// (shape_prior.safetensors + shape_train.json, or + shape_checkpoint.json of a run
    /// stopped at a checkpoint): its shape prior is evaluated.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    pub(crate) weights: PathBuf,
    /// Imported data set (output of `physnap data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    pub(crate) data: PathBuf,
    /// Split to evaluate: val (the target's), test, or train (to tell under- from overfitting).
    #[arg(long, env = "PHYSNAP_EVAL_SPLIT", default_value = "val")]
    pub(crate) split: String,
    /// Parts, spread evenly over the split (training evaluates 32 of val).
    #[arg(long, env = "PHYSNAP_EVAL_PARTS", default_value_t = 64)]
    pub(crate) parts: usize,
    /// IoU grid cells per axis over [-0.55, 0.55]³.
    #[arg(long, env = "PHYSNAP_EVAL_IOU_RESOLUTION", default_value_t = 64)]
    pub(crate) resolution: usize,
    /// Also write the report (with every part) as JSON here.
    #[arg(long, env = "PHYSNAP_EVAL_OUT")]
    pub(crate) out: Option<PathBuf>,
    /// Record the summary (no per-part list) under `metrics.shape` in the weights'
    /// manifest.json.
    #[arg(long, env = "PHYSNAP_EVAL_WRITE_MANIFEST")]
    pub(crate) write_manifest: bool,
    /// Fit each part's code to its SDF samples for this many Adam steps, decoder frozen
    /// (DeepSDF's auto-decoder inference), before measuring. Default: the encoding the
    /// weights' codebook was made with (`train encode --fit-steps`; 0 for NAP's); another
    /// count measures the decoder with other codes than the denoiser learns.
    #[arg(long, env = "PHYSNAP_EVAL_FIT_CODES")]
    pub(crate) fit_codes: Option<usize>,
    /// Encoder calls per part whose codes are averaged. Default: the codebook's encoding
    /// (`train encode --encoder-views`; 1 for NAP's).
    #[arg(long, env = "PHYSNAP_EVAL_ENCODER_VIEWS")]
    pub(crate) encoder_views: Option<usize>,
    /// SDF samples per part a fit uses. Default: the codebook's encoding (2048 for NAP's).
    #[arg(long, env = "PHYSNAP_EVAL_FIT_QUERIES")]
    pub(crate) fit_queries: Option<usize>,
    /// Weight λ of a fit's pull λ‖z − z₀‖² toward the encoder's code. Default: the codebook's
    /// encoding (0 for the plain fit).
    #[arg(long, env = "PHYSNAP_EVAL_FIT_PROX")]
    pub(crate) fit_prox: Option<f32>,
    /// Encoder input: the first N surface points of each part (cycled when a part has fewer).
    /// Default: the count the prior was trained with, which the codebook and so the denoiser
    /// use; another count measures what the encoder makes of more or fewer points.
    #[arg(long, env = "PHYSNAP_EVAL_SURFACE_POINTS")]
    pub(crate) surface_points: Option<usize>,
}

/// `physnap eval shape`: IoU of the weights' shape prior on parts of one split.
pub(crate) fn shape(a: EvalShapeArgs) -> anyhow::Result<()> {
    use physnap::eval::shape_iou::{PartIou, evaluate_shape_prior};
    use physnap::train::shape::{Encoding, ShapeTrainConfig};
    let started = Instant::now();
    if !["train", "val", "test"].contains(&a.split.as_str()) {
        bail!("invalid --split {:?} (must be train, val or test)", a.split);
    }
    if !(1..=MAX_SHAPE_PARTS).contains(&a.parts) {
        bail!(
            "invalid --parts {}: must be between 1 and {MAX_SHAPE_PARTS}",
            a.parts
        );
    }
    if a.write_manifest && !a.weights.join("manifest.json").is_file() {
        bail!(
            "--write-manifest needs a weights directory with manifest.json; {} has none (drop \
             --write-manifest, or keep the figures with --out)",
            a.weights.display()
        );
    }
    if let Some(n) = a.surface_points
        && !(1..=MAX_SURFACE_POINTS).contains(&n)
    {
        bail!("invalid --surface-points {n}: must be between 1 and {MAX_SURFACE_POINTS}");
    }
    if a.write_manifest && a.surface_points.is_some() {
        bail!(
            "--write-manifest records the IoU of the codes the codebook uses; --surface-points \
             measures another encoder input (keep it with --out)"
        );
    }
    let (shape_prior, model_cfg, report) = load_any_shape_prior(&a.weights)?;
    // The codebook's encoding is the default; another one measures codes the denoiser never
    // learned, which the manifest must not record as the prior's IoU.
    let recorded = Encoding::of_report(&report, &a.weights)?;
    let enc = Encoding {
        views: a.encoder_views.unwrap_or(recorded.views),
        fit_steps: a.fit_codes.unwrap_or(recorded.fit_steps),
        fit_queries: a.fit_queries.unwrap_or(recorded.fit_queries),
        fit_prox: a.fit_prox.unwrap_or(recorded.fit_prox),
    };
    enc.validate()?;
    if a.write_manifest && enc != recorded {
        let s = |v: &dyn std::fmt::Display| v.to_string();
        let differs = [
            ("--encoder-views", s(&enc.views), s(&recorded.views)),
            ("--fit-codes", s(&enc.fit_steps), s(&recorded.fit_steps)),
            (
                "--fit-queries",
                s(&enc.fit_queries),
                s(&recorded.fit_queries),
            ),
            ("--fit-prox", s(&enc.fit_prox), s(&recorded.fit_prox)),
        ]
        .iter()
        .filter(|(_, asked, rec)| asked != rec)
        .map(|(flag, asked, rec)| format!("{flag} {asked} (the codebook's: {rec})"))
        .collect::<Vec<_>>()
        .join(", ");
        bail!(
            "--write-manifest records the IoU of the codes the codebook uses, which the denoiser \
             learned; {differs} measures other codes (keep that report with --out)"
        );
    }
    let defaults = ShapeTrainConfig::default();
    let trained_points = report["config"]["surface_points"]
        .as_u64()
        .map_or(defaults.surface_points, |n| n as usize);
    let surface_points = a.surface_points.unwrap_or(trained_points);
    let cfg = ShapeTrainConfig {
        model: model_cfg,
        surface_points,
        iou_resolution: a.resolution,
        ..defaults
    };
    let pb = super::progress_bar(a.parts, "parts");
    let (parts, l1) = evaluate_shape_prior(
        &shape_prior,
        &a.data,
        &cfg,
        &a.split,
        a.parts,
        &enc,
        &mut |done, total| {
            pb.set_length(total as u64);
            pb.set_position(done as u64);
        },
    )?;
    pb.finish_and_clear();
    let cell = 1.1 / a.resolution as f64;
    let mean = |sel: &[&PartIou]| -> Option<f64> {
        (!sel.is_empty()).then(|| sel.iter().map(|p| p.iou).sum::<f64>() / sel.len() as f64)
    };
    let all: Vec<&PartIou> = parts.iter().collect();
    let pick = |keep: &dyn Fn(&PartIou) -> bool| -> Vec<&PartIou> {
        all.iter().copied().filter(|p| keep(p)).collect()
    };
    let groups: [(&str, Vec<&PartIou>); 7] = [
        ("all", all.clone()),
        ("single primitive", pick(&|p| p.primitives == Some(1))),
        (
            "several primitives",
            pick(&|p| p.primitives.is_some_and(|n| n > 1)),
        ),
        ("mesh", pick(&|p| p.primitives.is_none())),
        ("thinner than a grid cell", pick(&|p| p.thinnest < cell)),
        // Where the IoU is lost: walls and panels under a cell thick, whose cells flip in or
        // out of the part with a surface error of a fraction of a cell.
        (
            "a primitive under a cell",
            pick(&|p| p.thinnest_primitive.is_some_and(|t| t < cell)),
        ),
        (
            "every primitive >= 2 cells",
            pick(&|p| p.thinnest_primitive.is_some_and(|t| t >= 2.0 * cell)),
        ),
    ];
    println!(
        "shape prior of {}: {} {} parts of {}, {}³ grid (cell {cell:.4}), {:.0} s",
        a.weights.display(),
        parts.len(),
        a.split,
        a.data.display(),
        a.resolution,
        started.elapsed().as_secs_f64()
    );
    for (name, sel) in &groups {
        if let Some(m) = mean(sel) {
            println!("  {name:<26} {:>4} parts  mean IoU {m:.3}", sel.len());
        }
    }
    println!("  mean SDF L1 {l1:.5} (normalised units)");
    if enc.views > 1 {
        println!(
            "  codes: the mean of {} encoder calls a part, each on the next {surface_points} surface points",
            enc.views
        );
    }
    if enc.fit_steps > 0 {
        println!(
            "  codes fitted to each part's first {} SDF samples ({} Adam steps from the encoder's, decoder frozen, pull toward it {})",
            enc.fit_queries, enc.fit_steps, enc.fit_prox
        );
    }
    if enc != recorded {
        println!(
            "  (the codebook's encoding is {} view(s), {} fitting steps, pull {}: these are not the codes the denoiser learned)",
            recorded.views, recorded.fit_steps, recorded.fit_prox
        );
    }
    if surface_points != trained_points {
        println!(
            "  encoder input: {surface_points} surface points a part (trained with, and the \
             codebook uses, {trained_points})"
        );
    }
    let summary = json!({
        "format": "physnap.eval_shape/v1",
        "split": a.split,
        "parts": parts.len(),
        "resolution": a.resolution,
        "mean_iou": mean(&all),
        "l1": l1,
        "fit_codes": enc.fit_steps,
        "encoding": enc.to_json(),
        "groups": groups.iter().map(|(name, sel)| json!({
            "name": name, "parts": sel.len(), "mean_iou": mean(sel),
        })).collect::<Vec<_>>(),
        "command": std::env::args().collect::<Vec<_>>().join(" "),
    });
    if a.write_manifest {
        let path = record_in_manifest(&a.weights, |m| m["metrics"]["shape"] = summary.clone())?;
        println!("metrics recorded in {} (metrics.shape)", path.display());
    }
    if let Some(out) = &a.out {
        // The summary, with every part instead of their count.
        let mut doc = summary;
        doc["weights"] = json!(a.weights.display().to_string());
        doc["data"] = json!(a.data.display().to_string());
        doc["surface_points"] = json!(surface_points);
        doc["parts"] = parts
            .iter()
            .map(|p| {
                json!({
                    "key": p.key, "iou": p.iou, "primitives": p.primitives, "thinnest": p.thinnest,
                    "thinnest_primitive": p.thinnest_primitive,
                })
            })
            .collect();
        doc["seconds"] = json!(started.elapsed().as_secs_f64());
        write_report(out, &doc)?;
        println!("report: {}", out.display());
    }
    Ok(())
}
