//! `physnap eval denoiser`: the denoiser's held-out ε-loss at fixed noise levels.

use anyhow::{Context, bail};
use clap::Args;
use physnap::io::manifest::load_models;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub(crate) struct EvalDenoiserArgs {
    /// Weights directory with manifest.json: its denoiser and feature scales are measured.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    pub(crate) weights: PathBuf,
    /// Imported data set (output of `physnap data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    pub(crate) data: PathBuf,
    /// Shape prior directory holding every part's code (`train shape` or `train encode`
    /// output): the codes the denoiser was trained on.
    #[arg(long, env = "PHYSNAP_SHAPE")]
    pub(crate) shape: PathBuf,
    /// Split to measure: val (default), test, or train (the gap to val is the overfitting).
    #[arg(long, env = "PHYSNAP_EVAL_SPLIT", default_value = "val")]
    pub(crate) split: String,
    /// Noise levels t (0..999), comma-separated.
    #[arg(
        long,
        env = "PHYSNAP_EVAL_LEVELS",
        value_delimiter = ',',
        default_value = "10,50,100,200,300,400,500,600,800,950"
    )]
    pub(crate) levels: Vec<usize>,
    /// Seed of the node permutations and noise (the same seed pairs two models' inputs).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    pub(crate) seed: u64,
    /// Also write the report as JSON here.
    #[arg(long, env = "PHYSNAP_EVAL_OUT")]
    pub(crate) out: Option<PathBuf>,
}

/// `physnap eval denoiser`: the held-out ε-loss per noise level, with and without the
/// category (module `physnap::train::held_out`).
pub(crate) fn denoiser(a: EvalDenoiserArgs) -> anyhow::Result<()> {
    use physnap::train::{diffusion::load_split, held_out::held_out_loss};
    if !["train", "val", "test"].contains(&a.split.as_str()) {
        bail!("invalid --split {:?} (must be train, val or test)", a.split);
    }
    let started = Instant::now();
    let device = physnap::model::cpu();
    let models = load_models(&a.weights, &device)
        .with_context(|| format!("loading weights from {}", a.weights.display()))?;
    let data = load_split(&a.data, &a.shape, &a.split)?;
    let scales = &models.manifest.feature_scales;
    let r = held_out_loss(&models.denoiser, &data, scales, &a.levels, a.seed)?;
    println!(
        "denoiser ε-loss on {} {} objects (seed {}), feature scales of {}:",
        r.objects,
        a.split,
        a.seed,
        a.weights.display()
    );
    println!(
        "{:>5}  {:>10}  {:>12}  {:>6}",
        "t", "category", "no category", "gain"
    );
    for (i, t) in r.levels.iter().enumerate() {
        match &r.unconditional {
            Some(u) => println!(
                "{t:>5}  {:>10.5}  {:>12.5}  {:>6.3}",
                r.conditional[i],
                u[i],
                u[i] / r.conditional[i]
            ),
            None => println!("{t:>5}  {:>10.5}", r.conditional[i]),
        }
    }
    let mean_u = r.mean_unconditional();
    match mean_u {
        Some(u) => println!(
            " mean  {:>10.5}  {u:>12.5}  {:>6.3}   ({:.1} s)",
            r.mean_conditional(),
            u / r.mean_conditional(),
            started.elapsed().as_secs_f64()
        ),
        None => println!(
            " mean  {:>10.5}   ({:.1} s)",
            r.mean_conditional(),
            started.elapsed().as_secs_f64()
        ),
    }
    if let Some(out) = &a.out {
        let report = json!({
            "format": "physnap.eval_denoiser/v1",
            "command": std::env::args().collect::<Vec<_>>().join(" "),
            "weights": a.weights,
            "denoiser_sha256": models.manifest.denoiser.sha256,
            "data": a.data,
            "shape": a.shape,
            "split": a.split,
            "seed": a.seed,
            "objects": r.objects,
            "levels": r.levels,
            "conditional": r.conditional,
            "unconditional": r.unconditional,
            "mean_conditional": r.mean_conditional(),
            "mean_unconditional": mean_u,
            "seconds": started.elapsed().as_secs_f64(),
        });
        std::fs::write(out, serde_json::to_string_pretty(&report)? + "\n")
            .with_context(|| format!("writing {}", out.display()))?;
    }
    Ok(())
}
