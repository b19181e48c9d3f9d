//! `physnap train …`: the shape prior, the codebook, shape encoding and the denoiser, from flags
//! to `physnap::train` calls with progress bars and reports.

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use physnap::io::manifest::{Entry, Manifest, to_string as manifest_to_string};
use physnap::model::Compute;
use physnap::model::denoiser::DenoiserConfig;
use physnap::model::weights::sha256_hex;
use physnap::train::codebook::{
    CODEBOOK_WEIGHTS_FILE, CodebookReport, DEFAULT_CHECK_RESOLUTION, build_codebook,
};
use physnap::train::diffusion::{DiffusionTrainConfig, load_data, train_diffusion};
use physnap::train::shape::{
    DecoderBackward, Encoding, ShapeTrainConfig, encode_shape_dir, load_shape_prior,
    model_config_of, read_model_config, train_shape, write_atomic,
};
use std::path::{Path, PathBuf};

#[derive(Subcommand, Debug)]
pub(crate) enum TrainCommand {
    /// Train the part-shape auto-encoder on an imported data set; writes weights + codebook.
    Shape(Box<ShapeArgs>),
    /// Train the articulation denoiser; writes denoiser weights, the shape prior, the retrieval
    /// codebook and manifest.json.
    Diffusion(DiffusionArgs),
    /// (Re)build the retrieval codebook of a weights directory from a `train shape` output.
    Codebook(CodebookArgs),
    /// Make a `train shape` output directory from a weights directory's shape prior (its
    /// weights, its training report and every part of --data encoded), so `train diffusion`
    /// can train a new denoiser on it without retraining the shape prior.
    Encode(EncodeArgs),
    /// Install a `train shape --freeze-encoder` output into a weights directory: its decoder
    /// replaces the installed one while every code, and so the denoiser, stays valid (refused
    /// when the encoder differs). The decoder may be larger (`train shape --init-from` with a
    /// larger `--pe-freqs`, `--decoder-hidden` or `--decoder-blocks` grows it), never
    /// smaller. Rewrites the manifest and the codebook and clears the metrics, which
    /// `eval generative --write-manifest` measures again.
    InstallShape(InstallShapeArgs),
}

/// Runs one `physnap train …` subcommand.
pub(crate) fn run(command: TrainCommand) -> anyhow::Result<()> {
    match command {
        TrainCommand::Shape(a) => shape(*a),
        TrainCommand::Diffusion(a) => diffusion(a),
        TrainCommand::Codebook(a) => codebook(a),
        TrainCommand::Encode(a) => encode(a),
        TrainCommand::InstallShape(a) => install_shape(a),
    }
}

#[derive(Args, Debug)]
pub(crate) struct InstallShapeArgs {
    /// Shape prior directory (output of `physnap train shape`, trained with --freeze-encoder
    /// from these weights).
    #[arg(long, env = "PHYSNAP_SHAPE")]
    pub(crate) shape: PathBuf,
    /// Weights directory to update (manifest.json + shape_prior.safetensors).
    #[arg(long, env = "PHYSNAP_WEIGHTS")]
    pub(crate) weights: PathBuf,
    /// Do not rebuild the retrieval codebook (≈ 1 min): for a decoder that a later cycle
    /// replaces. The old codebook, made with the old decoder, is removed; `physnap train
    /// codebook` builds one.
    #[arg(long, env = "PHYSNAP_NO_CODEBOOK")]
    pub(crate) no_codebook: bool,
}

#[derive(Args, Debug)]
pub(crate) struct EncodeArgs {
    /// Weights directory whose shape prior to use (manifest.json + shape_prior.safetensors),
    /// or a `train shape` output directory (shape_train.json + shape_prior.safetensors).
    #[arg(long, env = "PHYSNAP_WEIGHTS")]
    pub(crate) weights: PathBuf,
    /// Imported data set to encode (output of `physnap data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    pub(crate) data: PathBuf,
    /// Output shape directory (shape_prior.safetensors, shape_train.json, codebook.npy/json).
    #[arg(long, env = "PHYSNAP_OUT")]
    pub(crate) out: PathBuf,
    /// Encoder calls per part, each on the next block of surface points (as many as the prior
    /// was trained with); a part's code is their mean. 1: NAP's single call.
    #[arg(long, env = "PHYSNAP_ENCODER_VIEWS", default_value_t = 1)]
    pub(crate) encoder_views: usize,
    /// Then fit each code to its part's SDF samples for this many Adam steps, decoder frozen
    /// (DeepSDF's auto-decoder inference from the encoder's code). 0: the encoder's code.
    #[arg(long, env = "PHYSNAP_FIT_STEPS", default_value_t = 0)]
    pub(crate) fit_steps: usize,
    /// SDF samples per part the fit uses (half uniform, half near-surface; even).
    #[arg(long, env = "PHYSNAP_FIT_QUERIES", default_value_t = 2048)]
    pub(crate) fit_queries: usize,
    /// Weight λ of the fit's pull λ‖z − z₀‖² toward the encoder's code z₀, which keeps fitted
    /// codes near the encoder's (0: the plain fit).
    #[arg(long, env = "PHYSNAP_FIT_PROX", default_value_t = 0.0)]
    pub(crate) fit_prox: f32,
}

#[derive(Args, Debug)]
pub(crate) struct CodebookArgs {
    /// Shape prior directory (output of `physnap train shape`: weights + codebook.npy/json).
    #[arg(long, env = "PHYSNAP_SHAPE")]
    pub(crate) shape: PathBuf,
    /// Weights directory to add codebook.safetensors to (its manifest.json is updated).
    #[arg(long, env = "PHYSNAP_WEIGHTS")]
    pub(crate) weights: PathBuf,
    /// Meshing resolution of the check that keeps only codes that decode non-empty.
    #[arg(long, env = "PHYSNAP_CODEBOOK_CHECK_RESOLUTION", default_value_t = physnap::train::codebook::DEFAULT_CHECK_RESOLUTION)]
    pub(crate) check_resolution: usize,
}

#[derive(Args, Debug)]
pub(crate) struct ShapeArgs {
    /// Imported data set (output of `physnap data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    pub(crate) data: PathBuf,
    /// Output directory (shape_prior.safetensors, codebook.npy/json, shape_train.json).
    #[arg(long, env = "PHYSNAP_OUT")]
    pub(crate) out: PathBuf,
    /// Optimiser steps.
    #[arg(long, env = "PHYSNAP_TRAIN_STEPS", default_value_t = 3000)]
    pub(crate) steps: usize,
    /// Seed.
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    pub(crate) seed: u64,
    /// Parts per step (default: the trainer's).
    #[arg(long, env = "PHYSNAP_SHAPE_BATCH_PARTS")]
    pub(crate) batch_parts: Option<usize>,
    /// Use at most this many training parts.
    #[arg(long, env = "PHYSNAP_SHAPE_MAX_PARTS")]
    pub(crate) max_parts: Option<usize>,
    /// How the SDF decoder's gradients are computed: `host` (hand-written backward pass on the
    /// host, the fast default on the CPU) or `burn` (burn autodiff through every layer, the
    /// reference; the default with --device gpu).
    #[arg(long, env = "PHYSNAP_SHAPE_DECODER_BACKWARD", value_parser = ["host", "burn"])]
    pub(crate) decoder_backward: Option<String>,
    /// Where the optimiser steps run: `cpu`, or `gpu` / `gpu:N` (Vulkan) in a binary built with
    /// `--features gpu`.
    #[arg(long, env = "PHYSNAP_TRAIN_DEVICE", default_value = "cpu")]
    pub(crate) device: String,
    /// Start from these weights instead of the seeded initialisation: a shape_prior.safetensors
    /// of the same sizes, or a directory holding one (weights/, a train shape output).
    #[arg(long, env = "PHYSNAP_SHAPE_INIT_FROM")]
    pub(crate) init_from: Option<PathBuf>,
    /// Keep the encoder fixed (needs --init-from): only the decoder trains, so every part's code
    /// stays what it was and a denoiser trained on those codes stays valid.
    #[arg(long, env = "PHYSNAP_SHAPE_FREEZE_ENCODER")]
    pub(crate) freeze_encoder: bool,
    /// Keep the decoder fixed (needs --init-from; not with --freeze-encoder): only the encoder
    /// trains, towards the codes the decoder decodes best. Every code changes, so a denoiser
    /// must be trained on the new ones.
    #[arg(long, env = "PHYSNAP_SHAPE_FREEZE_DECODER")]
    pub(crate) freeze_decoder: bool,
    /// Train the decoder on fixed codes instead of the encoder's (needs --freeze-encoder): a
    /// directory with codebook.npy + codebook.json of the same data set, e.g. a `train encode`
    /// output. The decoder learns to decode exactly those codes, so a denoiser trained on them
    /// stays valid; the run's codebook is a copy of them and its report keeps their encoding.
    #[arg(long, env = "PHYSNAP_SHAPE_CODES")]
    pub(crate) codes: Option<PathBuf>,
    /// Evaluate val IoU every this many steps (0: only at the end).
    #[arg(long, env = "PHYSNAP_SHAPE_EVAL_EVERY", default_value_t = 1000)]
    pub(crate) eval_every: usize,
    /// Steps between checkpoints (weights + shape_checkpoint.json in --out; 0: none).
    #[arg(long, env = "PHYSNAP_CHECKPOINT_EVERY", default_value_t = 1000)]
    pub(crate) checkpoint_every: usize,
    /// Continue from the checkpoint in --out (same data and training options).
    #[arg(long, env = "PHYSNAP_RESUME")]
    pub(crate) resume: bool,
    /// End this run after this many steps in total, with a checkpoint (the learning-rate
    /// schedule still spans --steps; continue with --resume).
    #[arg(long, env = "PHYSNAP_SHAPE_STOP_AT")]
    pub(crate) stop_at: Option<usize>,
    /// SDF decoder width (default 128; NAP: 256). The latent stays 128, the denoiser's F.
    /// Above --init-from's, the decoder is grown function-preservingly (new channels unread
    /// until they train), so the codes, and the denoiser trained on them, stay valid.
    #[arg(long, env = "PHYSNAP_SHAPE_DECODER_HIDDEN")]
    pub(crate) decoder_hidden: Option<usize>,
    /// SDF decoder residual blocks (default 4; NAP: 5). Above --init-from's, new blocks start
    /// as identities.
    #[arg(long, env = "PHYSNAP_SHAPE_DECODER_BLOCKS")]
    pub(crate) decoder_blocks: Option<usize>,
    /// Point encoder width (default 128; NAP: 512).
    #[arg(long, env = "PHYSNAP_SHAPE_ENCODER_HIDDEN")]
    pub(crate) encoder_hidden: Option<usize>,
    /// Point encoder residual blocks (default 4; NAP: 5).
    #[arg(long, env = "PHYSNAP_SHAPE_ENCODER_BLOCKS")]
    pub(crate) encoder_blocks: Option<usize>,
    /// Positional-encoding octaves of the query (default 8, as NAP). Above --init-from's, the
    /// decoder is grown (as for --decoder-hidden and --decoder-blocks): training starts from
    /// the same SDF and codes.
    #[arg(long, env = "PHYSNAP_SHAPE_PE_FREQS")]
    pub(crate) pe_freqs: Option<usize>,
    /// Add the code to every residual block's input of the SDF decoder (ConvONet's decoder),
    /// not only to the first layer as NAP does.
    #[arg(long, env = "PHYSNAP_SHAPE_CODE_EVERY_BLOCK")]
    pub(crate) code_every_block: bool,
    /// SDF queries per part and step, half uniform and half near-surface (default 2048).
    #[arg(long, env = "PHYSNAP_SHAPE_QUERIES_PER_PART")]
    pub(crate) queries_per_part: Option<usize>,
    /// Share of the queries drawn near the surface (default 0.5, as NAP; the rest uniform).
    #[arg(long, env = "PHYSNAP_SHAPE_NEAR_FRACTION")]
    pub(crate) near_fraction: Option<f64>,
    /// Encoder input points per part (default 512).
    #[arg(long, env = "PHYSNAP_SHAPE_SURFACE_POINTS")]
    pub(crate) surface_points: Option<usize>,
    /// Adam learning rate at step 0 (default 1e-3).
    #[arg(long, env = "PHYSNAP_SHAPE_LR")]
    pub(crate) lr: Option<f64>,
    /// Cosine decay to lr × this at the last step (default 0.1; 1: constant).
    #[arg(long, env = "PHYSNAP_SHAPE_LR_FINAL_FACTOR")]
    pub(crate) lr_final_factor: Option<f64>,
    /// Truncate the L1 loss to the band [−δ, δ] (DeepSDF); default: plain L1, as NAP.
    #[arg(long, env = "PHYSNAP_SHAPE_TRUNCATION")]
    pub(crate) truncation: Option<f32>,
    /// Weight w of the wrong-side term w · mean relu(−f̂ · sign f): queries on the wrong side
    /// of the surface count 1 + w times (default 0: off, as NAP).
    #[arg(long, env = "PHYSNAP_SHAPE_WRONG_SIDE")]
    pub(crate) wrong_side: Option<f64>,
    /// Weight EMA decay, e.g. 0.999 (default 0: off). With an EMA the val IoU, the saved
    /// weights and the codebook use the averaged weights.
    #[arg(long, env = "PHYSNAP_SHAPE_EMA_DECAY")]
    pub(crate) ema_decay: Option<f64>,
    /// Val parts evaluated every --eval-every steps (default 32, at most 64).
    #[arg(long, env = "PHYSNAP_SHAPE_VAL_PARTS")]
    pub(crate) val_parts: Option<usize>,
    /// Weight of the eikonal term (|∇f| = 1 by forward differences on a quarter of the
    /// near-surface queries; default 0: off, as NAP).
    #[arg(long, env = "PHYSNAP_SHAPE_EIKONAL")]
    pub(crate) eikonal: Option<f64>,
    /// Each step's parts in this many slices computed in parallel (default 2: both cores busy,
    /// 1.33× the steps per second of one pass on the recipe's first prior, 1.18× on a decoder
    /// cycle; the same loss up to float rounding; 1 = the single pass of runs before
    /// 2026-11-29). At most --batch-parts.
    #[arg(long, env = "PHYSNAP_SHAPE_BATCH_SHARDS")]
    pub(crate) batch_shards: Option<usize>,
}

#[derive(Args, Debug)]
pub(crate) struct DiffusionArgs {
    /// Imported data set (output of `physnap data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    pub(crate) data: PathBuf,
    /// Shape prior directory (output of `physnap train shape`: weights + codebook).
    #[arg(long, env = "PHYSNAP_SHAPE")]
    pub(crate) shape: PathBuf,
    /// Output (weights) directory: denoiser.safetensors, shape_prior.safetensors, manifest.json.
    #[arg(long, env = "PHYSNAP_OUT")]
    pub(crate) out: PathBuf,
    /// Optimiser steps.
    #[arg(long, env = "PHYSNAP_TRAIN_STEPS", default_value_t = 20000)]
    pub(crate) steps: usize,
    /// Objects per step.
    #[arg(long, env = "PHYSNAP_DIFFUSION_BATCH_OBJECTS", default_value_t = 32)]
    pub(crate) batch_objects: usize,
    /// Noise levels per object per step.
    #[arg(long, env = "PHYSNAP_DIFFUSION_NOISE_LEVELS", default_value_t = 4)]
    pub(crate) noise_levels: usize,
    /// Adam learning rate.
    #[arg(long, env = "PHYSNAP_DIFFUSION_LR", default_value_t = 2e-4)]
    pub(crate) lr: f64,
    /// Denoiser width.
    #[arg(long, env = "PHYSNAP_DENOISER_WIDTH", default_value_t = 160)]
    pub(crate) width: usize,
    /// Denoiser graph layers.
    #[arg(long, env = "PHYSNAP_DENOISER_LAYERS", default_value_t = 4)]
    pub(crate) layers: usize,
    /// Also add a learned category row to every graph layer's inputs, not only to the initial
    /// embeddings (physnap's option, not the paper's; the shipped weights are trained with it).
    #[arg(long, env = "PHYSNAP_DENOISER_CATEGORY_LAYERS")]
    pub(crate) category_layers: bool,
    /// Seed.
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 12345)]
    pub(crate) seed: u64,
    /// Steps between checkpoints (0: only the one at the end of the run).
    #[arg(long, env = "PHYSNAP_CHECKPOINT_EVERY", default_value_t = 1000)]
    pub(crate) checkpoint_every: usize,
    /// Step from which the learning rate decays (cosine) to lr × --lr-final-factor.
    #[arg(long, env = "PHYSNAP_DIFFUSION_LR_DECAY_START", default_value_t = 0)]
    pub(crate) lr_decay_start: usize,
    /// Final learning rate as a fraction of --lr (1 = constant).
    #[arg(long, env = "PHYSNAP_DIFFUSION_LR_FINAL_FACTOR", default_value_t = 0.1)]
    pub(crate) lr_final_factor: f64,
    /// Decay of the weight EMA that is shipped as denoiser.safetensors (0 = no EMA).
    #[arg(long, env = "PHYSNAP_DIFFUSION_EMA_DECAY", default_value_t = 0.999)]
    pub(crate) ema_decay: f64,
    /// Continue from the checkpoint in --out.
    #[arg(long, env = "PHYSNAP_RESUME")]
    pub(crate) resume: bool,
    /// End this run after this many steps in total, with a checkpoint (the learning-rate
    /// schedule still spans --steps; continue with --resume). For splitting long runs.
    #[arg(long, env = "PHYSNAP_DIFFUSION_STOP_AT")]
    pub(crate) stop_at: Option<usize>,
    /// Min-SNR-γ loss weighting: each sample's ε-loss × min(1, γ/SNR(t)); 0 = off (NAP).
    #[arg(long, env = "PHYSNAP_DIFFUSION_MIN_SNR_GAMMA", default_value_t = 0.0)]
    pub(crate) min_snr_gamma: f64,
    /// High-noise weighting: each sample's ε-loss × clamp(1/SNR(t), 1, CAP), an x̂₀-loss at
    /// high noise up to the cap; 1 = off (NAP).
    #[arg(long, env = "PHYSNAP_DIFFUSION_HIGH_NOISE_CAP", default_value_t = 1.0)]
    pub(crate) high_noise_cap: f64,
    /// Box-overlap penalty λ: for samples with t < --overlap-max-t, x̂₀'s part boxes pay
    /// λ · (depth beyond the data pair's depth)² per intersecting pair; 0 = off (NAP).
    #[arg(long, env = "PHYSNAP_DIFFUSION_OVERLAP_WEIGHT", default_value_t = 0.0)]
    pub(crate) overlap_weight: f64,
    /// The box-overlap penalty counts only samples with t below this (1..=500).
    #[arg(long, env = "PHYSNAP_DIFFUSION_OVERLAP_MAX_T", default_value_t = physnap::train::diffusion::DEFAULT_OVERLAP_MAX_T)]
    pub(crate) overlap_max_t: usize,
    /// Layout gain G: the part boxes' and centres' feature scales are divided by G, so the
    /// layout spans G times NAP's max-abs range in model space and survives G times as much
    /// noise (0.25..=8; 1 = NAP). Recorded in the manifest's feature scales.
    #[arg(long, env = "PHYSNAP_DIFFUSION_LAYOUT_GAIN", default_value_t = physnap::train::diffusion::DEFAULT_LAYOUT_GAIN)]
    pub(crate) layout_gain: f64,
    /// Code gain G_z: the 128 shape-code channels' feature scales are divided by G_z, so the
    /// generated codes are denoised at G_z times NAP's max-abs range in model space
    /// (0.25..=8; 1 = NAP). Recorded in the manifest's feature scales.
    #[arg(long, env = "PHYSNAP_DIFFUSION_CODE_GAIN", default_value_t = physnap::train::diffusion::DEFAULT_CODE_GAIN)]
    pub(crate) code_gain: f64,
    /// Share of training samples that see the "no category" row instead of their category
    /// (0..=1): what classifier-free category guidance and unconditional sampling use.
    #[arg(long, env = "PHYSNAP_DIFFUSION_CATEGORY_DROPOUT", default_value_t = physnap::train::diffusion::DEFAULT_CATEGORY_DROPOUT)]
    pub(crate) category_dropout: f64,
    /// Slices each step's batch is split into, their passes run in parallel (one per core is
    /// the point; results depend on this number, not on the thread count; 1 = the single-pass
    /// step of runs before 2026-11-28). Measured on the CPU only: with `--device gpu` the
    /// slices share the one device, so 1 is likely the better choice there.
    #[arg(long, env = "PHYSNAP_DIFFUSION_BATCH_SHARDS", default_value_t = 2)]
    pub(crate) batch_shards: usize,
    /// Do not build the retrieval codebook (≈ 1 min) into --out: for a run that a later run
    /// continues (--stop-at, --resume) or whose decoder a later cycle replaces. `physnap train
    /// codebook` builds it.
    #[arg(long, env = "PHYSNAP_NO_CODEBOOK")]
    pub(crate) no_codebook: bool,
    /// Where the optimiser steps run: `cpu`, or `gpu` / `gpu:N` (Vulkan) in a binary built with
    /// `--features gpu`.
    #[arg(long, env = "PHYSNAP_TRAIN_DEVICE", default_value = "cpu")]
    pub(crate) device: String,
}

pub(crate) fn shape(a: ShapeArgs) -> anyhow::Result<()> {
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
pub(crate) fn manifest_with_shape_prior(
    weights: &Path,
) -> anyhow::Result<(Manifest, PathBuf, PathBuf)> {
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

pub(crate) fn encode(a: EncodeArgs) -> anyhow::Result<()> {
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
pub(crate) fn read_json(path: &Path) -> anyhow::Result<serde_json::Value> {
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
pub(crate) fn lineage(dir: &Path, report: &serde_json::Value) -> anyhow::Result<serde_json::Value> {
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

pub(crate) fn install_shape(a: InstallShapeArgs) -> anyhow::Result<()> {
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
pub(crate) fn remove_codebook(weights: &Path) -> anyhow::Result<()> {
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

pub(crate) fn diffusion(a: DiffusionArgs) -> anyhow::Result<()> {
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

pub(crate) fn codebook(a: CodebookArgs) -> anyhow::Result<()> {
    write_codebook(&a.shape, &a.weights, a.check_resolution)?;
    Ok(())
}

/// Build and register the retrieval codebook of `weights` (with a progress bar).
pub(crate) fn write_codebook(
    shape: &Path,
    weights: &Path,
    check: usize,
) -> anyhow::Result<CodebookReport> {
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
