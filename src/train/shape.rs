//! `physnap train shape`: train the part-shape auto-encoder (method.md §4.6) on a data set made
//! by `physnap data import`, then encode every part into the codebook (§4.7).
//!
//! Why it exists: the diffusion prior needs a 128-d code per part and a decoder that turns codes
//! back into SDFs; NAP's checkpoint and codebook are unpublished, so we train our own.
//!
//! What it does:
//! - loads the SDF samples of the train split's parts (capped by `max_parts`) into memory once,
//!   plus up to `val_parts` validation parts spread evenly over the val split, whose ground-truth
//!   occupancy on the IoU grid is computed once (analytic primitives when the part has them,
//!   otherwise the generalised winding number of `part<k>.obj`);
//! - each step draws `batch_parts` parts (shuffled epochs), `queries_per_part` samples per
//!   part — a `near_fraction` share (default ½, as NAP) near-surface, the rest uniform, with
//!   replacement as NAP does — and `surface_points` encoder points (without replacement when
//!   the part has enough); loss =
//!   mean |f̂ − f| + w_reg · mean(z²), optionally truncated to the band [−δ, δ], optionally
//!   plus the eikonal term w_eik · mean (|∇̃f| − 1)² on a quarter of the near-surface queries
//!   (forward differences, [`EIKONAL_STEP`]; off by default), optionally plus the wrong-side
//!   term w_ws · mean relu(−f̂ · sign f), which weighs the queries on the wrong side of the
//!   surface 1 + w_ws times (off by default);
//! - with `codes_from` (a decoder cycle on fixed codes, encoder frozen) z is each part's row of
//!   a given codebook instead of the encoder's code of its surface points — the fitted codes a
//!   denoiser learns, which then stay valid — and the run's codebook is a copy of that one;
//! - Adam with a cosine decay from `lr` to `lr · lr_final_factor`;
//! - every `eval_every` steps and at the end: mean IoU of `SDF < 0` against ground truth on a
//!   `iou_resolution`³ grid of cell centres over [−0.55, 0.55]³, codes encoded from each val
//!   part's first `surface_points` surface points (the codebook's deterministic path);
//! - writes `shape_prior.safetensors`, `codebook.npy` + `codebook.json` (every part of every
//!   split, dataset order) and `shape_train.json` into `out`;
//! - every `checkpoint_every` steps (and at `stop_at`) writes the weights and
//!   `shape_checkpoint.json` (step, generator state, the rest of the shuffled epoch, losses,
//!   evaluations, weights sha256); `resume` continues the same batch stream from there. Adam's
//!   moments restart at a resume (as in `train diffusion`), so a resumed run is close to, not
//!   bit-identical with, an uninterrupted one.
//!
//! The decoder's gradients come from the host pass `HostDecoder::weight_grads` (hand-written
//! backward, fixed summation order) through a surrogate (see [`DecoderBackward`]);
//! `DecoderBackward::Burn` is burn autodiff through every layer, the reference the tests
//! compare with.
//!
//! Deterministic for a seed at a fixed thread count: weights come from our seeded init, batches
//! from [`Rng`].

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::module::Module;
use burn::nn::Linear;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::{Device, Tensor, TensorData};
use rayon::prelude::*;
use serde_json::{Value, json};

use super::TrainError;
use super::ema::Ema;
use crate::data::rng::Rng;
use crate::io::npy;
use crate::mesh::DOMAIN_HALF;
use crate::mesh::bvh::MeshBvh;
use crate::model::host_decoder::HostDecoder;
use crate::model::shape_prior::{ShapeDecoder, ShapePrior, ShapePriorConfig};
use crate::model::{Compute, cpu};
use crate::shape::{AnalyticSdf, PartShape, Sdf};

/// Weights file name in the output directory.
pub const WEIGHTS_FILE: &str = "shape_prior.safetensors";
/// Codebook array (P × F, f32) in the output directory.
pub const CODEBOOK_FILE: &str = "codebook.npy";
/// Codebook index (row keys and splits) in the output directory.
pub const CODEBOOK_INDEX_FILE: &str = "codebook.json";
/// Training report in the output directory.
pub const REPORT_FILE: &str = "shape_train.json";
/// Format tag of `codebook.json`.
pub const CODEBOOK_FORMAT: &str = "physnap.codebook/v1";
/// Format tag of `shape_train.json`.
pub const REPORT_FORMAT: &str = "physnap.shape_train/v1";
/// Checkpoint state in the output directory (next to `shape_prior.safetensors`).
pub const CHECKPOINT_FILE: &str = "shape_checkpoint.json";
/// Format tag of `shape_checkpoint.json`.
pub const CHECKPOINT_FORMAT: &str = "physnap.shape_checkpoint/v1";
/// The EMA weights of a checkpoint (`ema_decay > 0`), beside the raw ones in
/// `shape_prior.safetensors`.
pub const EMA_CHECKPOINT_FILE: &str = "shape_prior_ema.checkpoint.safetensors";
/// The config fields a resumed run must share with its checkpoint (they define the run's
/// batches, schedule and model); the others (threads, evaluation, checkpointing, the decoder's
/// backward implementation) may change between pieces.
const RESUME_FIELDS: [&str; 17] = [
    "model",
    "max_parts",
    "steps",
    "batch_parts",
    "queries_per_part",
    "near_fraction",
    "surface_points",
    "lr",
    "lr_final_factor",
    "w_reg",
    "truncation",
    "wrong_side",
    "seed",
    "ema_decay",
    "freeze_encoder",
    "freeze_decoder",
    "codes_from",
];
/// Largest number of validation parts evaluated.
pub const MAX_VAL_PARTS: usize = 64;
/// A loss above this (or non-finite) counts as divergence.
pub const DIVERGED_LOSS: f64 = 1e4;

/// Options of a shape-prior training run.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeTrainConfig {
    /// Network sizes.
    pub model: ShapePriorConfig,
    /// Optimiser steps.
    pub steps: usize,
    /// Parts per step.
    pub batch_parts: usize,
    /// SDF queries per part and step, uniform and near-surface (even).
    pub queries_per_part: usize,
    /// Share of the queries drawn from the near-surface samples (NAP: 0.5); the rest are
    /// uniform. More near-surface queries spend the batch where the walls are.
    pub near_fraction: f64,
    /// Encoder input points per part.
    pub surface_points: usize,
    /// Adam learning rate at step 0.
    pub lr: f64,
    /// Cosine decay to `lr · lr_final_factor` at the last step (1 = constant).
    pub lr_final_factor: f64,
    /// Weight of mean(z²) (NAP: 0.001).
    pub w_reg: f64,
    /// Truncate the L1 loss to the band [−δ, δ] (see [`truncated_residual`]; None: plain L1 as
    /// NAP).
    pub truncation: Option<f32>,
    /// Weight w of the wrong-side term w · mean relu(−f̂ · sign f) ([`wrong_side`]; 0: off, as
    /// NAP). It adds w to the L1 gradient of every query whose predicted sign is wrong: the
    /// IoU counts signs, and a thin wall's inside queries cost the L1 fit little when the
    /// decoder smooths the wall away (|f| ≤ half its thickness).
    pub wrong_side: f64,
    /// Seed of weight init and batch sampling.
    pub seed: u64,
    /// Weight EMA decay (0: off, the raw weights are the result). With an EMA the evaluations,
    /// the saved weights and the codebook use the averaged weights (see `train::ema`).
    pub ema_decay: f64,
    /// Evaluate every this many steps (0: only at the end).
    pub eval_every: usize,
    /// Validation parts evaluated (≤ [`MAX_VAL_PARTS`]).
    pub val_parts: usize,
    /// IoU grid points per axis.
    pub iou_resolution: usize,
    /// Use at most this many train parts (None: all).
    pub max_parts: Option<usize>,
    /// Own rayon pool with this many threads (None: the current pool).
    pub threads: Option<usize>,
    /// How the decoder's gradients are computed.
    pub decoder_backward: DecoderBackward,
    /// Write a checkpoint every this many steps (0: none).
    pub checkpoint_every: usize,
    /// Continue from the checkpoint in the output directory, if there is one.
    pub resume: bool,
    /// End this run after this many steps in total, with a checkpoint (the schedule still
    /// spans `steps`; continue with `resume`). None: run to `steps`.
    pub stop_at: Option<usize>,
    /// Where the optimiser steps run (evaluation, saving and the codebook run on the CPU).
    pub compute: Compute,
    /// Start from these weights (a `shape_prior.safetensors` of the same sizes, or with a
    /// smaller decoder, which [`ShapeDecoder::grow`] grows to `model`'s sizes) instead of the
    /// seeded initialisation: continued training, a second cosine cycle.
    pub init_from: Option<PathBuf>,
    /// Keep the encoder's weights fixed (needs `init_from`): only the decoder trains, so every
    /// part's code, and with it a denoiser trained on those codes, stays valid.
    pub freeze_encoder: bool,
    /// Keep the decoder's weights fixed (needs `init_from`): only the encoder trains, towards
    /// the codes the decoder decodes best. Every code changes, so a denoiser must be trained
    /// on the new ones; the decoder, and with it guidance and meshing of given codes, stays.
    pub freeze_decoder: bool,
    /// Train the decoder on these fixed codes instead of the encoder's (needs
    /// `freeze_encoder`): a directory holding a `codebook.npy` + `codebook.json` of the same
    /// data set, e.g. a `train encode` output. Each training part's code is its row there, so
    /// the decoder learns to decode exactly the codes a denoiser trained on that codebook
    /// generates from, and that denoiser stays valid. The run's codebook is a copy of those
    /// codes, its report records their encoding, and its evaluations encode the val parts by
    /// that encoding.
    pub codes_from: Option<PathBuf>,
    /// Weight of the eikonal term on the near-surface queries ([`eikonal_term`]; 0: off, as
    /// NAP). It asks the decoder for a field of slope 1, a signed distance, instead of the
    /// flatter field an L1 fit leaves (slope 0.3–0.5 on the shipped prior's surfaces, which
    /// guidance can flatten further; EVALUATION.md).
    pub eikonal: f64,
    /// Each step's parts in this many contiguous slices whose forward and backward passes run
    /// in parallel ([`sharded_loss`]; 1 = the single pass of the runs before 2026-11-29).
    pub batch_shards: usize,
}

/// Finite-difference step of the eikonal term, normalised units (a third of a 64³ IoU cell).
pub const EIKONAL_STEP: f32 = 0.005;
/// Share of each part's near-surface queries that also carry the eikonal term.
pub const EIKONAL_SHARE: usize = 4;

/// How a training step computes the SDF decoder's gradients. Both give the same gradients up
/// to float summation order (tested); the host pass is the fast one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DecoderBackward {
    /// The hand-written forward/backward on the host ([`HostDecoder::weight_grads`]), handed to
    /// burn through a surrogate: burn's autodiff tape holds only the encoder and W_c.
    #[default]
    Host,
    /// burn's autodiff through every decoder layer (the reference implementation).
    Burn,
}

impl DecoderBackward {
    /// The name used in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            DecoderBackward::Host => "host",
            DecoderBackward::Burn => "burn",
        }
    }
}

impl Default for ShapeTrainConfig {
    fn default() -> Self {
        ShapeTrainConfig {
            model: ShapePriorConfig::default(),
            steps: 10_000,
            batch_parts: 16,
            queries_per_part: 2048,
            near_fraction: 0.5,
            surface_points: 512,
            lr: 1e-3,
            lr_final_factor: 0.1,
            w_reg: 1e-3,
            truncation: None,
            wrong_side: 0.0,
            seed: 0,
            ema_decay: 0.0,
            eval_every: 1000,
            val_parts: 32,
            iou_resolution: 64,
            max_parts: None,
            threads: None,
            decoder_backward: DecoderBackward::Host,
            checkpoint_every: 1000,
            resume: false,
            stop_at: None,
            compute: Compute::Cpu,
            init_from: None,
            freeze_encoder: false,
            freeze_decoder: false,
            codes_from: None,
            eikonal: 0.0,
            batch_shards: 2,
        }
    }
}

impl ShapeTrainConfig {
    /// Check every option against its range.
    pub fn validate(&self) -> Result<(), TrainError> {
        self.model.validate()?;
        let range = |field: &str, v: usize, lo: usize, hi: usize| {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(TrainError::config(
                    field,
                    format!("between {lo} and {hi}"),
                    v,
                ))
            }
        };
        range("steps", self.steps, 1, 100_000_000)?;
        range("batch_parts", self.batch_parts, 1, 4096)?;
        range("batch_shards", self.batch_shards, 1, self.batch_parts)?;
        range("queries_per_part", self.queries_per_part, 2, 1 << 20)?;
        if !self.queries_per_part.is_multiple_of(2) {
            return Err(TrainError::config(
                "queries_per_part",
                "even (the val L1 uses half uniform, half near-surface)",
                self.queries_per_part,
            ));
        }
        if !(self.near_fraction.is_finite() && (0.0..=1.0).contains(&self.near_fraction)) {
            return Err(TrainError::config(
                "near_fraction",
                "between 0 and 1",
                self.near_fraction,
            ));
        }
        range("surface_points", self.surface_points, 1, 1 << 16)?;
        range("val_parts", self.val_parts, 0, MAX_VAL_PARTS)?;
        range("iou_resolution", self.iou_resolution, 8, 256)?;
        range("threads", self.threads.unwrap_or(1), 1, 1024)?;
        range("stop_at", self.stop_at.unwrap_or(1), 1, self.steps)?;
        range("max_parts", self.max_parts.unwrap_or(1), 1, usize::MAX)?;
        let positive = |field: &str, v: f64, lo: f64, hi: f64| {
            if v.is_finite() && v > lo && v <= hi {
                Ok(())
            } else {
                Err(TrainError::config(field, format!("in ({lo}, {hi}]"), v))
            }
        };
        positive("lr", self.lr, 0.0, 1.0)?;
        positive("lr_final_factor", self.lr_final_factor, 0.0, 1.0)?;
        if !(self.w_reg.is_finite() && self.w_reg >= 0.0) {
            return Err(TrainError::config("w_reg", "finite and ≥ 0", self.w_reg));
        }
        if let Some(d) = self.truncation {
            positive("truncation", d as f64, 0.0, 10.0)?;
        }
        if !(self.wrong_side.is_finite() && (0.0..=100.0).contains(&self.wrong_side)) {
            return Err(TrainError::config(
                "wrong_side",
                "between 0 and 100 (0 turns it off)",
                self.wrong_side,
            ));
        }
        if !(self.ema_decay.is_finite() && (0.0..1.0).contains(&self.ema_decay)) {
            return Err(TrainError::config(
                "ema_decay",
                "in [0, 1) (0 turns the EMA off)",
                self.ema_decay,
            ));
        }
        if self.freeze_encoder && self.init_from.is_none() {
            return Err(TrainError::config(
                "freeze_encoder",
                "init_from set (a frozen, randomly initialised encoder maps every part to noise)",
                "true without init_from",
            ));
        }
        if self.freeze_decoder && self.init_from.is_none() {
            return Err(TrainError::config(
                "freeze_decoder",
                "init_from set (an encoder trained against a random decoder learns nothing)",
                "true without init_from",
            ));
        }
        if self.freeze_decoder && self.freeze_encoder {
            return Err(TrainError::config(
                "freeze_decoder",
                "false while freeze_encoder is set (with both frozen nothing trains)",
                "true with freeze_encoder",
            ));
        }
        if let (Some(dir), false) = (&self.codes_from, self.freeze_encoder) {
            return Err(TrainError::config(
                "codes_from",
                "freeze_encoder set (the fixed codes replace the encoder, which must not train)",
                dir.display(),
            ));
        }
        if !(self.eikonal.is_finite() && (0.0..=100.0).contains(&self.eikonal)) {
            return Err(TrainError::config(
                "eikonal",
                "between 0 and 100 (0 turns it off)",
                self.eikonal,
            ));
        }
        if self.compute != Compute::Cpu && self.decoder_backward == DecoderBackward::Host {
            return Err(TrainError::config(
                "decoder_backward",
                format!(
                    "burn with device {} (the host pass runs on the CPU)",
                    self.compute.name()
                ),
                "host",
            ));
        }
        Ok(())
    }

    /// Near-surface queries per part and step: `queries_per_part · near_fraction`, rounded
    /// (the default 0.5 gives exactly half, as NAP).
    pub fn near_queries(&self) -> usize {
        (self.queries_per_part as f64 * self.near_fraction).round() as usize
    }

    /// The rows of each part that carry the eikonal term: (offset within the part's queries,
    /// count) — the first 1/[`EIKONAL_SHARE`] of its near-surface queries (at least one).
    pub fn eikonal_rows(&self) -> (usize, usize) {
        let near = self.near_queries();
        (
            self.queries_per_part - near,
            (near / EIKONAL_SHARE).max(1).min(near),
        )
    }

    /// Learning rate at `step` (0-based): cosine from `lr` to `lr · lr_final_factor`.
    pub fn lr_at(&self, step: usize) -> f64 {
        let t = if self.steps > 1 {
            step as f64 / (self.steps - 1) as f64
        } else {
            0.0
        };
        let f = self.lr_final_factor
            + (1.0 - self.lr_final_factor) * 0.5 * (1.0 + (std::f64::consts::PI * t).cos());
        self.lr * f
    }

    fn to_json(&self) -> Value {
        json!({
            "model": model_config_json(&self.model),
            "steps": self.steps,
            "batch_parts": self.batch_parts,
            "queries_per_part": self.queries_per_part,
            "near_fraction": self.near_fraction,
            "surface_points": self.surface_points,
            "lr": self.lr,
            "lr_final_factor": self.lr_final_factor,
            "w_reg": self.w_reg,
            "truncation": self.truncation,
            "wrong_side": self.wrong_side,
            "seed": self.seed,
            "ema_decay": self.ema_decay,
            "eval_every": self.eval_every,
            "val_parts": self.val_parts,
            "iou_resolution": self.iou_resolution,
            "max_parts": self.max_parts,
            "threads": self.threads,
            "decoder_backward": self.decoder_backward.name(),
            "checkpoint_every": self.checkpoint_every,
            "init_from": self.init_from.as_ref().map(|p| p.display().to_string()),
            "freeze_encoder": self.freeze_encoder,
            "freeze_decoder": self.freeze_decoder,
            "codes_from": self.codes_from.as_ref().map(|p| p.display().to_string()),
            "eikonal": self.eikonal,
            "batch_shards": self.batch_shards,
        })
    }
}

fn model_config_json(m: &ShapePriorConfig) -> Value {
    let mut doc = json!({
        "latent": m.latent,
        "decoder_hidden": m.decoder_hidden,
        "decoder_blocks": m.decoder_blocks,
        "encoder_hidden": m.encoder_hidden,
        "encoder_blocks": m.encoder_blocks,
        "pe_freqs": m.pe_freqs,
    });
    // Written only when on, so reports and checkpoints of NAP's decoder read as before.
    if m.code_every_block {
        doc["code_every_block"] = json!(true);
    }
    doc
}

/// The model sizes recorded in a `shape_train.json` (to load its weights).
pub fn read_model_config(report: &Path) -> Result<ShapePriorConfig, TrainError> {
    let text = std::fs::read_to_string(report).map_err(TrainError::io(report))?;
    let v: Value =
        serde_json::from_str(&text).map_err(|e| TrainError::data(report, e.to_string()))?;
    model_config_of(&v, report)
}

/// The model sizes in a parsed `shape_train.json` document; `report` names it in errors.
pub fn model_config_of(v: &Value, report: &Path) -> Result<ShapePriorConfig, TrainError> {
    let get = |k: &str| -> Result<usize, TrainError> {
        v["config"]["model"][k]
            .as_u64()
            .map(|x| x as usize)
            .ok_or_else(|| TrainError::data(report, format!("config.model.{k} is missing")))
    };
    let cfg = ShapePriorConfig {
        latent: get("latent")?,
        decoder_hidden: get("decoder_hidden")?,
        decoder_blocks: get("decoder_blocks")?,
        encoder_hidden: get("encoder_hidden")?,
        encoder_blocks: get("encoder_blocks")?,
        pe_freqs: get("pe_freqs")?,
        // Absent in reports written before the option existed.
        code_every_block: v["config"]["model"]["code_every_block"]
            .as_bool()
            .unwrap_or(false),
    };
    cfg.validate()?;
    Ok(cfg)
}

/// What the trainer reports after each step.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeTrainProgress {
    /// Steps done (1-based).
    pub step: usize,
    /// Total steps.
    pub steps: usize,
    /// This step's loss.
    pub loss: f64,
    /// This step's learning rate.
    pub lr: f64,
    /// Seconds since training started.
    pub elapsed_s: f64,
    /// Mean val IoU when this step evaluated.
    pub val_iou: Option<f64>,
    /// Mean val L1 (SDF, normalised units) when this step evaluated.
    pub val_l1: Option<f64>,
}

/// One evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalPoint {
    /// Steps done.
    pub step: usize,
    /// Seconds since training started.
    pub elapsed_s: f64,
    /// Mean IoU over the val parts.
    pub iou: f64,
    /// Mean L1 over the val parts' uniform + near samples.
    pub l1: f64,
}

impl EvalPoint {
    /// `{"step", "elapsed_s", "iou", "l1"}` as in `shape_train.json` and checkpoints.
    fn to_json(&self) -> Value {
        json!({ "step": self.step, "elapsed_s": self.elapsed_s, "iou": self.iou, "l1": self.l1 })
    }

    /// The inverse of [`EvalPoint::to_json`] (None when a field is missing or not a number).
    fn from_json(v: &Value) -> Option<Self> {
        Some(EvalPoint {
            step: v["step"].as_u64()? as usize,
            elapsed_s: v["elapsed_s"].as_f64()?,
            iou: v["iou"].as_f64()?,
            l1: v["l1"].as_f64()?,
        })
    }
}

/// What a training run did.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeTrainReport {
    /// Steps run.
    pub steps: usize,
    /// Wall time of the whole run (loading, training, evaluation, codebook), seconds.
    pub wall_s: f64,
    /// Seconds spent in optimiser steps only.
    pub train_s: f64,
    /// Mean loss of the first min(20, steps) steps.
    pub initial_loss: f64,
    /// Mean loss of the last min(50, steps) steps.
    pub final_loss: f64,
    /// Final mean val IoU (None without val parts).
    pub val_iou: Option<f64>,
    /// Every evaluation.
    pub curve: Vec<EvalPoint>,
    /// Train parts used.
    pub train_parts: usize,
    /// Val parts evaluated.
    pub val_parts: usize,
    /// Rows of the codebook.
    pub codebook_rows: usize,
    /// Decoder queries per second of optimiser-step time.
    pub queries_per_s: f64,
}

/// One part of the data set.
#[derive(Debug, Clone)]
struct PartRef {
    id: String,
    k: usize,
    split: String,
    /// The object's category name (dataset.json's `category`), when listed.
    category: Option<String>,
}

impl PartRef {
    fn file(&self, data: &Path, kind: &str) -> PathBuf {
        data.join("objects")
            .join(&self.id)
            .join(format!("part{}_{kind}.npy", self.k))
    }
}

/// A part's samples in memory.
struct PartSamples {
    /// U × 4 (x y z sdf).
    uniform: Vec<f32>,
    /// N × 4.
    near: Vec<f32>,
    /// S × 3.
    surface: Vec<f32>,
}

/// A val part: encoder input (every view), query samples, the samples a code fit uses, and
/// the ground-truth occupancy.
struct ValPart {
    surface: Vec<f32>,
    queries: Vec<f32>,
    targets: Vec<f32>,
    fit: FitSamples,
    occupancy: Vec<bool>,
}

/// The SDF samples a part's code is fitted to ([`Encoding::fit_queries`] rows; empty when
/// the encoding fits nothing).
#[derive(Default)]
struct FitSamples {
    /// [n × 3].
    queries: Vec<f32>,
    /// [n].
    targets: Vec<f32>,
}

/// The first `n / 2` uniform and the first `n / 2` near-surface samples of `s` (cycled when a
/// file has fewer): the deterministic evaluation rows, as NAP's evaluation takes chunk 0.
fn first_samples(s: &PartSamples, n: usize) -> FitSamples {
    let half = n / 2;
    let mut out = FitSamples {
        queries: Vec::with_capacity(2 * half * 3),
        targets: Vec::with_capacity(2 * half),
    };
    for rows in [&s.uniform, &s.near] {
        let m = rows.len() / 4;
        for i in 0..half {
            let r = &rows[4 * (i % m)..4 * (i % m) + 4];
            out.queries.extend_from_slice(&r[..3]);
            out.targets.push(r[3]);
        }
    }
    out
}

/// All parts of `data/dataset.json` in dataset order (objects, then part index).
fn read_index(data: &Path) -> Result<Vec<PartRef>, TrainError> {
    let path = data.join("dataset.json");
    let text = std::fs::read_to_string(&path).map_err(TrainError::io(&path))?;
    let v: Value =
        serde_json::from_str(&text).map_err(|e| TrainError::data(&path, e.to_string()))?;
    let objects = v["objects"]
        .as_array()
        .ok_or_else(|| TrainError::data(&path, "no \"objects\" array"))?;
    let mut parts = Vec::new();
    for (i, o) in objects.iter().enumerate() {
        let field = |k: &str| TrainError::data(&path, format!("objects[{i}].{k} is missing"));
        let id = o["id"].as_str().ok_or_else(|| field("id"))?;
        let split = o["split"].as_str().ok_or_else(|| field("split"))?;
        let n = o["parts"].as_u64().ok_or_else(|| field("parts"))? as usize;
        if id.is_empty() || id.contains(['/', '\\']) || id.starts_with('.') {
            return Err(TrainError::data(
                &path,
                format!("objects[{i}].id {id:?} is not a folder name"),
            ));
        }
        let category = o["category"].as_str().map(str::to_string);
        for k in 0..n {
            parts.push(PartRef {
                id: id.to_string(),
                k,
                split: split.to_string(),
                category: category.clone(),
            });
        }
    }
    Ok(parts)
}

/// Read an NPY array and check its column count.
fn read_rows(path: &Path, cols: usize) -> Result<(usize, Vec<f32>), TrainError> {
    let (rows, c, data) = npy::read(path).map_err(|e| TrainError::data(path, e.to_string()))?;
    if c != cols {
        return Err(TrainError::data(
            path,
            format!("expected {cols} columns, got {c}"),
        ));
    }
    if rows == 0 {
        return Err(TrainError::data(path, "no rows"));
    }
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(TrainError::data(
            path,
            format!("non-finite value at row {}, column {}", i / cols, i % cols),
        ));
    }
    Ok((rows, data))
}

fn load_part(data: &Path, p: &PartRef) -> Result<PartSamples, TrainError> {
    Ok(PartSamples {
        uniform: read_rows(&p.file(data, "uniform"), 4)?.1,
        near: read_rows(&p.file(data, "near"), 4)?.1,
        surface: read_rows(&p.file(data, "surface"), 3)?.1,
    })
}

/// The first `n` points of `surface` (S × 3), cycled when S < n (max-pooling makes repeats
/// harmless: a duplicated point adds nothing to the pooled feature).
fn first_points(surface: &[f32], n: usize) -> Vec<f32> {
    let s = surface.len() / 3;
    (0..n)
        .flat_map(|i| {
            let j = i % s;
            [surface[3 * j], surface[3 * j + 1], surface[3 * j + 2]]
        })
        .collect()
}

/// Cell-centre grid over [−0.55, 0.55]³, x fastest: where `eval shape` samples both
/// occupancies of its IoU.
pub fn iou_grid(res: usize) -> Vec<[f32; 3]> {
    let h = DOMAIN_HALF as f64;
    let c = |i: usize| (-h + 2.0 * h * (i as f64 + 0.5) / res as f64) as f32;
    let mut g = Vec::with_capacity(res * res * res);
    for k in 0..res {
        for j in 0..res {
            for i in 0..res {
                g.push([c(i), c(j), c(k)]);
            }
        }
    }
    g
}

/// Ground-truth occupancy of a part on `grid`: analytic primitives from `object.json` when the
/// part has them, else the winding number of its normalised mesh `part<k>.obj`.
fn gt_occupancy(data: &Path, p: &PartRef, grid: &[[f32; 3]]) -> Result<Vec<bool>, TrainError> {
    let dir = data.join("objects").join(&p.id);
    let obj_path = dir.join("object.json");
    let object = crate::io::object_json::read(&obj_path)
        .map_err(|e| TrainError::data(&obj_path, e.to_string()))?;
    let part = object.parts.get(p.k).ok_or_else(|| {
        TrainError::data(
            &obj_path,
            format!("part {} missing ({} parts)", p.k, object.parts.len()),
        )
    })?;
    const CHUNK: usize = 4096;
    if let PartShape::Primitives(prims) = &part.shape {
        let sdf = AnalyticSdf {
            primitives: prims,
            half_extents: part.half_extents,
            kappa: part.kappa(),
        };
        return Ok(grid
            .par_chunks(CHUNK)
            .flat_map_iter(|pts| {
                let mut out = vec![0.0f32; pts.len()];
                sdf.eval_batch(pts, &mut out);
                out.into_iter().map(|d| d < 0.0)
            })
            .collect());
    }
    let mesh_path = dir.join(format!("part{}.obj", p.k));
    let text = std::fs::read_to_string(&mesh_path).map_err(TrainError::io(&mesh_path))?;
    let mesh = crate::mesh::obj::parse(&text).map_err(|e| TrainError::data(&mesh_path, e))?;
    let bvh = MeshBvh::new(&mesh.positions, &mesh.triangles)
        .map_err(|e| TrainError::data(&mesh_path, e))?;
    Ok(grid.par_iter().map(|q| bvh.is_inside(*q)).collect())
}

fn load_val_part(
    data: &Path,
    p: &PartRef,
    cfg: &ShapeTrainConfig,
    enc: &Encoding,
    grid: &[[f32; 3]],
) -> Result<ValPart, TrainError> {
    let s = load_part(data, p)?;
    let FitSamples { queries, targets } = first_samples(&s, cfg.queries_per_part);
    Ok(ValPart {
        surface: first_points(&s.surface, cfg.surface_points * enc.views),
        queries,
        targets,
        fit: if enc.fit_steps > 0 {
            first_samples(&s, enc.fit_queries)
        } else {
            FitSamples::default()
        },
        occupancy: gt_occupancy(data, p, grid)?,
    })
}

/// One training batch on `device`: (query points [B, Q, 3], targets [B, Q], surface [B, S, 3]).
/// One step's training batch on the host: B parts × Q queries (xyz, target SDF) and B × S
/// encoder points.
struct Batch {
    /// [B × Q × 3].
    pts: Vec<f32>,
    /// [B × Q].
    tgt: Vec<f32>,
    /// [B × S × 3].
    surf: Vec<f32>,
    /// [B × F] fixed codes (`codes_from`); empty when the encoder makes them.
    codes: Vec<f32>,
}

impl Batch {
    /// Parts `start..end` of the batch.
    fn slice(&self, start: usize, end: usize, cfg: &ShapeTrainConfig) -> Batch {
        let (q, s) = (cfg.queries_per_part, cfg.surface_points);
        let f = self.codes.len() / (self.tgt.len() / q).max(1);
        Batch {
            pts: self.pts[start * q * 3..end * q * 3].to_vec(),
            tgt: self.tgt[start * q..end * q].to_vec(),
            surf: self.surf[start * s * 3..end * s * 3].to_vec(),
            codes: self.codes[start * f..end * f].to_vec(),
        }
    }
}

/// One step's batch of the parts `order`; `codes` ([`FixedCodes`]) adds their fixed codes.
/// The random draws are the same with or without them.
fn sample_batch(
    parts: &[PartSamples],
    order: &[usize],
    cfg: &ShapeTrainConfig,
    codes: Option<&FixedCodes>,
    rng: &mut Rng,
) -> Batch {
    let (b, q, s) = (order.len(), cfg.queries_per_part, cfg.surface_points);
    let mut pts = Vec::with_capacity(b * q * 3);
    let mut tgt = Vec::with_capacity(b * q);
    let mut surf = Vec::with_capacity(b * s * 3);
    let mut idx: Vec<usize> = Vec::new();
    let near = cfg.near_queries();
    for &pi in order {
        let part = &parts[pi];
        for (rows, count) in [(&part.uniform, q - near), (&part.near, near)] {
            let n = rows.len() / 4;
            for _ in 0..count {
                let r = rng.int(0, n - 1);
                pts.extend_from_slice(&rows[4 * r..4 * r + 3]);
                tgt.push(rows[4 * r + 3]);
            }
        }
        let n = part.surface.len() / 3;
        if n >= s {
            // Partial Fisher–Yates: s distinct points.
            idx.clear();
            idx.extend(0..n);
            for i in 0..s {
                let j = rng.int(i, n - 1);
                idx.swap(i, j);
            }
            for &j in &idx[..s] {
                surf.extend_from_slice(&part.surface[3 * j..3 * j + 3]);
            }
        } else {
            for _ in 0..s {
                let j = rng.int(0, n - 1);
                surf.extend_from_slice(&part.surface[3 * j..3 * j + 3]);
            }
        }
    }
    let codes = codes.map_or_else(Vec::new, |c| {
        order
            .iter()
            .flat_map(|&pi| c.row(pi).iter().copied())
            .collect()
    });
    Batch {
        pts,
        tgt,
        surf,
        codes,
    }
}

/// The fixed codes of a `codes_from` run: one row per training part, in the run's part order,
/// and the encoding that made them.
struct FixedCodes {
    /// `parts × latent` codes.
    codes: Vec<f32>,
    latent: usize,
    encoding: Encoding,
    /// The codebook directory, and its number of rows (every part of every split).
    dir: PathBuf,
    rows: usize,
}

impl FixedCodes {
    fn row(&self, part: usize) -> &[f32] {
        &self.codes[part * self.latent..(part + 1) * self.latent]
    }

    /// The rows of `dir`'s codebook for `train`'s parts, matched by key (`<object>_<part>`);
    /// refuses codes of another width, a part without a code (a codebook of another data set)
    /// and an encoding it cannot read, naming the file.
    fn read(dir: &Path, latent: usize, train: &[&PartRef]) -> Result<FixedCodes, TrainError> {
        let book = read_codebook(dir, latent)?;
        let index_path = dir.join(CODEBOOK_INDEX_FILE);
        let encoding = Encoding::of_report(&json!({ "encoding": book.encoding }), &index_path)?;
        let rows: std::collections::HashMap<&str, usize> = book
            .keys
            .iter()
            .enumerate()
            .filter_map(|(r, k)| k["key"].as_str().map(|k| (k, r)))
            .collect();
        let mut codes = Vec::with_capacity(train.len() * latent);
        for p in train {
            let key = format!("{}_{}", p.id, p.k);
            let r = *rows.get(key.as_str()).ok_or_else(|| {
                TrainError::data(
                    &index_path,
                    format!(
                        "training part {key} has no code ({} codes; made from another data set?)",
                        book.keys.len()
                    ),
                )
            })?;
            codes.extend_from_slice(&book.codes[r * latent..(r + 1) * latent]);
        }
        Ok(FixedCodes {
            codes,
            latent,
            encoding,
            dir: dir.to_path_buf(),
            rows: book.keys.len(),
        })
    }

    /// Copy the codebook, byte for byte, into `out` (the run's codebook: the codes its decoder
    /// was trained on); returns its number of rows.
    fn copy_to(&self, out: &Path) -> Result<usize, TrainError> {
        for file in [CODEBOOK_FILE, CODEBOOK_INDEX_FILE] {
            let (src, dst) = (self.dir.join(file), out.join(file));
            if src != dst {
                let bytes = std::fs::read(&src).map_err(TrainError::io(&src))?;
                write_atomic(&dst, &bytes)?;
            }
        }
        Ok(self.rows)
    }
}

fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data()
        .try_into_vec::<f32>()
        .expect("model outputs are f32")
}

/// Per-part IoU and mean L1 of `model` (inference mode) on the val parts.
fn evaluate(
    model: &ShapePrior,
    val: &[ValPart],
    cfg: &ShapeTrainConfig,
    grid: &[f32],
    enc: &Encoding,
) -> (Vec<f64>, f64) {
    if val.is_empty() {
        return (Vec::new(), f64::NAN);
    }
    let device = cpu();
    let (v, q) = (val.len(), cfg.queries_per_part);
    // The grid decodes (and the code fitting) run on the value-only host decoder (same
    // function, 3-4× faster).
    let host = HostDecoder::new(&model.decoder);
    let surf: Vec<f32> = val.iter().flat_map(|p| p.surface.iter().copied()).collect();
    let fit: Vec<&FitSamples> = val.iter().map(|p| &p.fit).collect();
    let codes = encode_codes(model, &host, surf, cfg.surface_points, &fit, enc);
    let codes = Tensor::from_data(TensorData::new(codes, [v, model.decoder.latent()]), &device);
    let features = model.decoder.code_features(codes);
    let queries: Vec<f32> = val.iter().flat_map(|p| p.queries.iter().copied()).collect();
    let pred = to_vec(model.decoder.sdf_with_features(
        Tensor::from_data(TensorData::new(queries, [v, q, 3]), &device),
        features.clone(),
    ));
    let targets = val.iter().flat_map(|p| p.targets.iter());
    let l1 = pred
        .iter()
        .zip(targets)
        .map(|(a, b)| (a - b).abs() as f64)
        .sum::<f64>()
        / (v * q) as f64;
    let features = to_vec(features);
    let grid: Vec<[f32; 3]> = grid.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    let n = grid.len();
    let mut d = vec![0.0; n];
    let mut idx = vec![0; n];
    let mut ious = Vec::with_capacity(v);
    for (i, part) in val.iter().enumerate() {
        idx.fill(i);
        host.eval(&grid, &features, &idx, &mut d);
        ious.push(occupancy_iou(
            d.iter()
                .zip(&part.occupancy)
                .map(|(dv, &gt)| (*dv < 0.0, gt)),
        ));
    }
    (ious, l1)
}

/// IoU of two occupancies given as (a, b) pairs per grid point; 1 when both are empty.
pub fn occupancy_iou(pairs: impl Iterator<Item = (bool, bool)>) -> f64 {
    let (mut inter, mut union) = (0usize, 0usize);
    for (a, b) in pairs {
        inter += (a && b) as usize;
        union += (a || b) as usize;
    }
    if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    }
}

/// The val parts a run evaluates: `cfg.val_parts` spread evenly over the val split.
fn val_selection<'a>(all: &'a [PartRef], cfg: &ShapeTrainConfig) -> Vec<&'a PartRef> {
    split_selection(all, "val", cfg.val_parts)
}

/// `n` parts of `split` spread evenly over it (dataset order); all of them when it has fewer.
fn split_selection<'a>(all: &'a [PartRef], split: &str, n: usize) -> Vec<&'a PartRef> {
    let of_split: Vec<&PartRef> = all.iter().filter(|p| p.split == split).collect();
    let n = n.min(of_split.len());
    (0..n).map(|i| of_split[i * of_split.len() / n]).collect()
}

/// IoU of one evaluated part, with what makes a part hard for the 64³ grid.
#[derive(Debug, Clone, PartialEq)]
pub struct PartIou {
    /// `<id>_<k>`.
    pub key: String,
    /// IoU of `SDF < 0` against ground truth on the grid.
    pub iou: f64,
    /// Number of analytic primitives (None: a mesh part).
    pub primitives: Option<usize>,
    /// Thinnest box extent over the part's normalisation scale κ (the AABB diagonal), i.e. in
    /// normalised units where the grid spacing is 1.1 / resolution.
    pub thinnest: f64,
    /// Smallest extent of the thinnest analytic primitive over κ (normalised units): the
    /// part's thinnest wall, panel or detail. None for a mesh part. A cabinet shell's walls
    /// are often under one 64³ cell, where a surface error of a quarter cell moves a whole
    /// wall's cells in or out of the IoU.
    pub thinnest_primitive: Option<f64>,
}

/// The smallest extent of `part`'s thinnest primitive over its κ (see [`PartIou`]); None
/// when the part has no analytic primitives.
pub fn thinnest_primitive(part: &crate::object::Part) -> Option<f64> {
    match &part.shape {
        PartShape::Primitives(prims) => prims
            .iter()
            .map(|p| {
                let (lo, hi) = p.bounds();
                (hi - lo).min() / part.kappa()
            })
            .min_by(f64::total_cmp),
        _ => None,
    }
}

/// Parts per batch of [`evaluate_shape_prior`] (bounds the ground-truth grids in memory).
const EVAL_CHUNK: usize = 32;

/// Evaluate `model` on `n` parts of `split` (spread evenly over it) exactly as training
/// evaluates its val parts (`cfg.iou_resolution`³ grid), with codes made by `enc`
/// ([`Encoding`]; training's evaluations use NAP's: the first `cfg.surface_points` surface
/// points). `progress(done, total)` after every batch of parts. Returns per-part IoUs and the
/// mean L1 on the parts' first `cfg.queries_per_part` samples.
pub fn evaluate_shape_prior(
    model: &ShapePrior,
    data: &Path,
    cfg: &ShapeTrainConfig,
    split: &str,
    n: usize,
    enc: &Encoding,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<PartIou>, f64), TrainError> {
    cfg.validate()?;
    enc.validate()?;
    let all = read_index(data)?;
    let refs = split_selection(&all, split, n);
    if refs.is_empty() {
        return Err(TrainError::data(
            data.join("dataset.json"),
            format!("no parts in split {split:?}"),
        ));
    }
    let grid_pts = iou_grid(cfg.iou_resolution);
    let grid: Vec<f32> = grid_pts.iter().flatten().copied().collect();
    let model = model.valid();
    let (mut per_part, mut l1_sum) = (Vec::with_capacity(refs.len()), 0.0);
    for chunk in refs.chunks(EVAL_CHUNK) {
        let parts: Vec<ValPart> = chunk
            .par_iter()
            .map(|p| load_val_part(data, p, cfg, enc, &grid_pts))
            .collect::<Result<_, _>>()?;
        let (ious, l1) = evaluate(&model, &parts, cfg, &grid, enc);
        l1_sum += l1 * chunk.len() as f64;
        for (p, iou) in chunk.iter().zip(ious) {
            let file = data.join("objects").join(&p.id).join("object.json");
            let obj = crate::io::object_json::read(&file)
                .map_err(|e| TrainError::data(&file, e.to_string()))?;
            let part = obj.parts.get(p.k).ok_or_else(|| {
                TrainError::data(&file, format!("no part {} (dataset.json lists it)", p.k))
            })?;
            per_part.push(PartIou {
                key: format!("{}_{}", p.id, p.k),
                iou,
                primitives: match &part.shape {
                    PartShape::Primitives(prims) => Some(prims.len()),
                    _ => None,
                },
                thinnest: 2.0 * part.half_extents.min() / part.kappa(),
                thinnest_primitive: thinnest_primitive(part),
            });
        }
        progress(per_part.len(), refs.len());
    }
    Ok((per_part, l1_sum / refs.len() as f64))
}

/// How a part's code is made from its data: what the codebook (and so the denoiser's training
/// codes), `eval shape` and `eval reconstruction` use.
///
/// ```text
/// z₀ = (1/V) Σ_v E(P_v)        P_v: surface points v·S … (v+1)·S − 1 of the part (cycled)
/// z  = argmin_z mean_r |f(q_r; z) − s_r| + λ ‖z − z₀‖²   by `fit_steps` Adam steps from z₀
///      (lr FIT_LR), over the part's first fit_queries/2 uniform and near-surface samples,
///      decoder frozen; λ = `fit_prox` (0: the plain fit)
/// ```
///
/// V = 1 and no fit is NAP's encoding (one encoder call on the first S points). Averaging the
/// views evens out which S points the encoder happens to see; the fit is DeepSDF's
/// auto-decoder inference started from the encoder's code. Both use only what the data set
/// holds for every part, so the codebook's codes and the evaluated val codes come from the
/// same protocol. The pull toward z₀ keeps a fitted code near the encoder's codes: the plain
/// fit moves a code by a median 0.215 (the encoder's codes lie 0.089 apart) and spreads the
/// codes out of the ≈ 16 directions that hold 98.7 % of the encoder codes' variance; on the
/// ws10 decoder any pull (λ = 0.01 … 1) gave back 0.02 of the fit's IoU (EVALUATION.md,
/// forty-ninth session), so no recipe uses it yet. A report without an `"encoding"` entry
/// was made by NAP's encoding; one without `"fit_prox"`, by the plain fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Encoding {
    /// Encoder calls per part, each on the next `surface_points` surface points; the code is
    /// their mean.
    pub views: usize,
    /// Adam steps fitting each code to its part's SDF samples (0: the encoder's code).
    pub fit_steps: usize,
    /// SDF samples a part's fit uses (half uniform, half near-surface; even).
    pub fit_queries: usize,
    /// Weight λ of the fit's pull λ ‖z − z₀‖² toward the encoder's code (0: none).
    pub fit_prox: f32,
}

impl Default for Encoding {
    fn default() -> Self {
        Encoding {
            views: 1,
            fit_steps: 0,
            fit_queries: 2048,
            fit_prox: 0.0,
        }
    }
}

/// Most encoder views per part.
pub const MAX_ENCODER_VIEWS: usize = 64;
/// Most fitting steps per code.
pub const MAX_FIT_STEPS: usize = 1000;
/// Most SDF samples per part a fit uses.
pub const MAX_FIT_QUERIES: usize = 8192;
/// Largest weight of the fit's pull toward the encoder's code.
pub const MAX_FIT_PROX: f32 = 1000.0;

impl Encoding {
    /// Check every field against its range; the error names the field, the limit and the
    /// value.
    pub fn validate(&self) -> Result<(), TrainError> {
        if !(1..=MAX_ENCODER_VIEWS).contains(&self.views) {
            return Err(TrainError::config(
                "encoder_views",
                format!("between 1 and {MAX_ENCODER_VIEWS}"),
                self.views,
            ));
        }
        if self.fit_steps > MAX_FIT_STEPS {
            return Err(TrainError::config(
                "fit_steps",
                format!("at most {MAX_FIT_STEPS}"),
                self.fit_steps,
            ));
        }
        if !(2..=MAX_FIT_QUERIES).contains(&self.fit_queries) || !self.fit_queries.is_multiple_of(2)
        {
            return Err(TrainError::config(
                "fit_queries",
                format!("an even number between 2 and {MAX_FIT_QUERIES}"),
                self.fit_queries,
            ));
        }
        if !(0.0..=MAX_FIT_PROX).contains(&self.fit_prox) {
            return Err(TrainError::config(
                "fit_prox",
                format!("between 0 and {MAX_FIT_PROX}"),
                self.fit_prox,
            ));
        }
        Ok(())
    }

    /// The `"encoding"` entry of a shape report.
    pub fn to_json(&self) -> Value {
        json!({
            "views": self.views,
            "fit_steps": self.fit_steps,
            "fit_queries": self.fit_queries,
            "fit_lr": FIT_LR,
            "fit_prox": self.fit_prox,
        })
    }

    /// The encoding a shape report (`shape_train.json`, or a manifest's `training.shape`)
    /// records; NAP's single encoder call when it records none. `file` names the report in
    /// errors.
    pub fn of_report(report: &Value, file: &Path) -> Result<Encoding, TrainError> {
        let e = &report["encoding"];
        if e.is_null() {
            return Ok(Encoding::default());
        }
        let field = |k: &str| {
            e[k].as_u64().map(|v| v as usize).ok_or_else(|| {
                TrainError::data(file, format!("encoding.{k} is missing or not a count"))
            })
        };
        let enc = Encoding {
            views: field("views")?,
            fit_steps: field("fit_steps")?,
            fit_queries: field("fit_queries")?,
            fit_prox: match &e["fit_prox"] {
                Value::Null => 0.0,
                v => v.as_f64().ok_or_else(|| {
                    TrainError::data(file, "encoding.fit_prox is not a number".to_string())
                })? as f32,
            },
        };
        enc.validate()?;
        Ok(enc)
    }
}

/// Adam learning rate of [`fit_codes`].
pub const FIT_LR: f64 = 1e-2;

/// Codes [P × F] of P parts by `enc` ([`Encoding`]): `surface` holds each part's `enc.views`
/// × `s` encoder points in a row, `fit` each part's fit samples (unused without fitting).
fn encode_codes(
    model: &ShapePrior,
    host: &HostDecoder,
    surface: Vec<f32>,
    s: usize,
    fit: &[&FitSamples],
    enc: &Encoding,
) -> Vec<f32> {
    let (p, f, k) = (fit.len(), model.decoder.latent(), enc.views);
    let z = model.encoder.encode(Tensor::from_data(
        TensorData::new(surface, [p * k, s, 3]),
        &cpu(),
    ));
    let z = if k > 1 {
        z.reshape([p, k, f]).mean_dim(1).reshape([p, f])
    } else {
        z
    };
    let codes = to_vec(z);
    if enc.fit_steps == 0 {
        return codes;
    }
    fit_codes(
        &model.decoder,
        host,
        codes,
        fit,
        enc.fit_steps,
        enc.fit_prox,
    )
}

/// The decoder's best codes for parts with samples `fit`: `steps` Adam steps (lr [`FIT_LR`])
/// on each part's code, from `codes` [P × F], minimising the mean |f(q; z) − f_gt| over the
/// part's samples plus `prox` ‖z − z₀‖² (z₀ the code it started from), with the decoder
/// frozen (DeepSDF's auto-decoder inference). Each part's code moves by its own samples
/// only, so the result does not depend on how parts are batched.
fn fit_codes(
    decoder: &ShapeDecoder,
    host: &HostDecoder,
    mut codes: Vec<f32>,
    fit: &[&FitSamples],
    steps: usize,
    prox: f32,
) -> Vec<f32> {
    let (f, fw) = (host.latent(), host.feature_width());
    let start = codes.clone();
    let w_c = to_vec(decoder.fc_c.weight.val()); // [F, fw], row-major
    let pts: Vec<[f32; 3]> = fit
        .iter()
        .flat_map(|p| p.queries.chunks_exact(3).map(|c| [c[0], c[1], c[2]]))
        .collect();
    let tgt: Vec<f32> = fit.iter().flat_map(|p| p.targets.iter().copied()).collect();
    // Row r's part, and each part's 1 / n of its mean.
    let idx: Vec<usize> = fit
        .iter()
        .enumerate()
        .flat_map(|(i, p)| std::iter::repeat_n(i, p.targets.len()))
        .collect();
    let inv_n: Vec<f32> = fit.iter().map(|p| 1.0 / p.targets.len() as f32).collect();
    let (mut m, mut v) = (vec![0.0f32; codes.len()], vec![0.0f32; codes.len()]);
    let (b1, b2, eps) = (0.9f32, 0.999f32, 1e-8f32);
    for t in 1..=steps {
        let features = host.code_features(&codes);
        let g = host.feature_grads(&pts, &features, &idx, &|r, y| {
            (y - tgt[r]).signum() * inv_n[idx[r]]
        });
        let (c1, c2) = (1.0 - b1.powi(t as i32), 1.0 - b2.powi(t as i32));
        for (p, dh) in g.d_features.chunks_exact(fw).enumerate() {
            for i in 0..f {
                let row = &w_c[i * fw..(i + 1) * fw];
                let k = p * f + i;
                let dz: f32 = row.iter().zip(dh).map(|(a, b)| a * b).sum::<f32>()
                    + 2.0 * prox * (codes[k] - start[k]);
                m[k] = b1 * m[k] + (1.0 - b1) * dz;
                v[k] = b2 * v[k] + (1.0 - b2) * dz * dz;
                codes[k] -= FIT_LR as f32 * (m[k] / c1) / ((v[k] / c2).sqrt() + eps);
            }
        }
    }
    codes
}

/// Write `bytes` to `path` atomically (temp file + rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), TrainError> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).map_err(TrainError::io(&tmp))?;
    std::fs::rename(&tmp, path).map_err(TrainError::io(path))
}

/// Save `model`'s weights (f32 safetensors; keys are the module paths, e.g.
/// `decoder.blocks.0.fc_0.weight`, Linear weights stored `[in, out]` as burn holds them).
/// The header's metadata is written in sorted order (`model::weights::to_bytes`), so equal
/// weights give equal files and equal sha256 (burn writes it in hash order).
pub fn save_shape_prior(model: &ShapePrior, path: &Path) -> Result<(), TrainError> {
    let bytes = crate::model::weights::to_bytes(&model.valid())
        .map_err(|e| TrainError::data(path, e.to_string()))?;
    write_atomic(path, &bytes)
}

/// Load weights written by [`save_shape_prior`] into a model of size `cfg` on `device`.
/// Every tensor must be present with the right shape, and no extra tensor may be in the file.
pub fn load_shape_prior(
    path: &Path,
    cfg: &ShapePriorConfig,
    device: &Device,
) -> Result<ShapePrior, TrainError> {
    cfg.validate()?;
    if !path.is_file() {
        return Err(TrainError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such weights file"),
        });
    }
    let mut model = ShapePrior::new(cfg, device);
    let mut store = SafetensorsStore::from_file(path);
    let result = model
        .load_from(&mut store)
        .map_err(|e| TrainError::data(path, e.to_string()))?;
    if !result.errors.is_empty() || !result.missing.is_empty() || !result.unused.is_empty() {
        return Err(TrainError::data(
            path,
            format!(
                "weights do not match the model config: {} errors, missing {:?}, unused {:?}",
                result.errors.len(),
                result.missing.iter().map(|(k, _)| k).collect::<Vec<_>>(),
                result.unused
            ),
        ));
    }
    Ok(model)
}

/// The decoder sizes stored in the safetensors file `path`, read from its header: N_pe and the
/// hidden width from `decoder.fc_p.weight` ([3 + 6 N_pe, hidden]), the residual blocks from
/// the `decoder.blocks.<i>.` names.
fn stored_decoder_sizes(path: &Path) -> Result<(usize, usize, usize), TrainError> {
    use std::io::Read;
    let bad = |detail: String| TrainError::data(path, detail);
    let mut file = std::fs::File::open(path).map_err(TrainError::io(path))?;
    let mut len = [0u8; 8];
    file.read_exact(&mut len).map_err(TrainError::io(path))?;
    let len = u64::from_le_bytes(len);
    if len > 1 << 24 {
        return Err(bad(format!(
            "safetensors header of {len} bytes (limit 16 MiB)"
        )));
    }
    let mut header = vec![0u8; len as usize];
    file.read_exact(&mut header).map_err(TrainError::io(path))?;
    let header: Value = serde_json::from_slice(&header)
        .map_err(|e| bad(format!("safetensors header is not JSON: {e}")))?;
    let shape = &header["decoder.fc_p.weight"]["shape"];
    let (Some(d_in), Some(hidden)) = (shape[0].as_u64(), shape[1].as_u64()) else {
        return Err(bad(
            "no decoder.fc_p.weight in the safetensors header".into()
        ));
    };
    let pe_freqs = match d_in.checked_sub(3) {
        Some(d) if d % 6 == 0 => (d / 6) as usize,
        _ => {
            return Err(bad(format!(
                "decoder.fc_p.weight has {d_in} input rows, not 3 + 6 N_pe"
            )));
        }
    };
    let blocks = (0..)
        .take_while(|i| {
            header
                .get(format!("decoder.blocks.{i}.fc_0.weight"))
                .is_some()
        })
        .count();
    Ok((pe_freqs, hidden as usize, blocks))
}

/// `init_from`'s weights as a model of `cfg`. When the file's decoder is smaller than `cfg`'s
/// (fewer positional-encoding octaves, a narrower hidden width, fewer blocks) it is grown to
/// `cfg` ([`ShapeDecoder::grow`]: the same SDF, room for finer detail; new weights seeded
/// from `seed`); every other size must match the file.
fn load_init(
    path: &Path,
    cfg: &ShapePriorConfig,
    seed: u64,
    device: &Device,
) -> Result<ShapePrior, TrainError> {
    let (pe_freqs, decoder_hidden, decoder_blocks) = stored_decoder_sizes(path)?;
    let stored = ShapePriorConfig {
        pe_freqs: pe_freqs.min(cfg.pe_freqs),
        decoder_hidden: decoder_hidden.min(cfg.decoder_hidden),
        decoder_blocks: decoder_blocks.min(cfg.decoder_blocks),
        ..*cfg
    };
    if stored == *cfg {
        return load_shape_prior(path, cfg, device);
    }
    let model = load_shape_prior(path, &stored, device)?;
    tracing::info!(
        from = ?(stored.pe_freqs, stored.decoder_hidden, stored.decoder_blocks),
        to = ?(cfg.pe_freqs, cfg.decoder_hidden, cfg.decoder_blocks),
        "growing the decoder (N_pe, hidden, blocks)"
    );
    let mut rng = Rng::fork(seed, 0x4752_4f57);
    Ok(ShapePrior {
        encoder: model.encoder,
        decoder: model.decoder.grow(cfg, &mut rng)?,
    })
}

/// The shape prior in a `train shape` output directory with its sizes and the document they
/// came from: `shape_train.json` of a finished run, else `shape_checkpoint.json` of a run that
/// stopped at a checkpoint (`--stop-at`, or killed), whose weights must match the sha256 it
/// recorded. Lets a candidate be measured before — or while — it trains to the end.
pub fn load_shape_dir(
    dir: &Path,
    device: &Device,
) -> Result<(ShapePrior, ShapePriorConfig, Value), TrainError> {
    let report = dir.join(REPORT_FILE);
    let checkpoint = dir.join(CHECKPOINT_FILE);
    let doc_path = if report.is_file() {
        report
    } else if checkpoint.is_file() {
        checkpoint
    } else {
        return Err(TrainError::data(
            dir,
            format!("neither {REPORT_FILE} nor {CHECKPOINT_FILE}: not a `train shape` output"),
        ));
    };
    let text = std::fs::read_to_string(&doc_path).map_err(TrainError::io(&doc_path))?;
    let doc: Value =
        serde_json::from_str(&text).map_err(|e| TrainError::data(&doc_path, e.to_string()))?;
    let cfg = model_config_of(&doc, &doc_path)?;
    let weights = dir.join(WEIGHTS_FILE);
    if doc_path.ends_with(CHECKPOINT_FILE) {
        check_checkpoint_weights(&weights, &doc["weights_sha256"], &doc_path)?;
    }
    let model = load_shape_prior(&weights, &cfg, device)?;
    Ok((model, cfg, doc))
}

/// Codes of parts `0..parts` of object `id` in `data`, made as the codebook makes them: by
/// `enc` from the first `surface_points` × `enc.views` points of each `part<k>_surface.npy`
/// (cycled if fewer) and, when it fits, the part's SDF samples; one encoder call for the
/// object.
pub fn encode_object_parts(
    model: &ShapePrior,
    data: &Path,
    id: &str,
    parts: usize,
    surface_points: usize,
    enc: &Encoding,
) -> Result<Vec<Vec<f32>>, TrainError> {
    if parts == 0 || surface_points == 0 {
        return Ok(Vec::new());
    }
    enc.validate()?;
    let refs: Vec<PartRef> = (0..parts)
        .map(|k| PartRef {
            id: id.to_string(),
            k,
            split: String::new(),
            category: None,
        })
        .collect();
    let host = HostDecoder::new(&model.decoder);
    let codes = encode_refs(model, &host, data, &refs, surface_points, enc)?;
    Ok(codes
        .chunks_exact(model.decoder.latent())
        .map(<[f32]>::to_vec)
        .collect())
}

/// Codes [P × F] of the parts `refs` by `enc`, read from `data` (surface points, and the SDF
/// samples when the encoding fits).
fn encode_refs(
    model: &ShapePrior,
    host: &HostDecoder,
    data: &Path,
    refs: &[PartRef],
    surface_points: usize,
    enc: &Encoding,
) -> Result<Vec<f32>, TrainError> {
    let loaded: Vec<(Vec<f32>, FitSamples)> = refs
        .par_iter()
        .map(|p| {
            let n = surface_points * enc.views;
            if enc.fit_steps == 0 {
                let (_, pts) = read_rows(&p.file(data, "surface"), 3)?;
                return Ok((first_points(&pts, n), FitSamples::default()));
            }
            let s = load_part(data, p)?;
            Ok((
                first_points(&s.surface, n),
                first_samples(&s, enc.fit_queries),
            ))
        })
        .collect::<Result<_, TrainError>>()?;
    let surface: Vec<f32> = loaded.iter().flat_map(|(s, _)| s.iter().copied()).collect();
    let fit: Vec<&FitSamples> = loaded.iter().map(|(_, f)| f).collect();
    Ok(encode_codes(
        model,
        host,
        surface,
        surface_points,
        &fit,
        enc,
    ))
}

/// What [`encode_shape_dir`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodeReport {
    /// Codebook rows (every part of every split of the data set).
    pub rows: usize,
    /// Encoder input: surface points per part.
    pub surface_points: usize,
}

/// Make a `train shape` output directory (`shape_prior.safetensors`, `shape_train.json`,
/// `codebook.npy` + `codebook.json`) for an already trained shape prior: its weights
/// (`weights_file`) and its training report (`report`, the `shape_train.json` it was trained
/// with; a weights manifest keeps it under `training.shape`), with every part of `data`
/// encoded as `train shape` does at its end (first `config.surface_points` surface points).
///
/// Why: `train diffusion` trains on a shape directory, and the shipped weights keep only the
/// shape prior, not that directory. With this a new denoiser (a longer schedule, another seed,
/// another imported data set) trains on the shipped shape prior without retraining it; on the
/// data set the prior was trained on, the codes are those of the original run.
///
/// The report is copied with `data` and `codebook_rows` set to this encoding's and an
/// `"encoded_from"` entry naming `weights_file`.
pub fn encode_shape_dir(
    weights_file: &Path,
    report: &Value,
    data: &Path,
    out: &Path,
    enc: &Encoding,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<EncodeReport, TrainError> {
    enc.validate()?;
    let model_cfg = model_config_of(report, weights_file)?;
    let surface_points = report["config"]["surface_points"]
        .as_u64()
        .filter(|&n| n > 0)
        .ok_or_else(|| {
            TrainError::data(
                weights_file,
                "its training report has no config.surface_points (the encoder input size)",
            )
        })? as usize;
    let model = load_shape_prior(weights_file, &model_cfg, &cpu())?;
    let all = read_index(data)?;
    std::fs::create_dir_all(out).map_err(TrainError::io(out))?;
    let cfg = ShapeTrainConfig {
        model: model_cfg,
        surface_points,
        ..ShapeTrainConfig::default()
    };
    let rows = write_codebook(&model, data, &all, &cfg, enc, out, progress)?;
    let dst = out.join(WEIGHTS_FILE);
    if dst != weights_file {
        std::fs::copy(weights_file, &dst).map_err(TrainError::io(&dst))?;
    }
    let mut doc = report.clone();
    doc["data"] = json!(data.display().to_string());
    doc["codebook_rows"] = json!(rows);
    doc["encoded_from"] = json!(weights_file.display().to_string());
    if *enc == Encoding::default() {
        // NAP's encoding is what a report without the entry means; an older report's own
        // entry (it was encoded otherwise before) would now be wrong.
        if let Some(o) = doc.as_object_mut() {
            o.remove("encoding");
        }
    } else {
        doc["encoding"] = enc.to_json();
    }
    write_atomic(
        &out.join(REPORT_FILE),
        serde_json::to_string_pretty(&doc)
            .unwrap_or_default()
            .as_bytes(),
    )?;
    Ok(EncodeReport {
        rows,
        surface_points,
    })
}

/// A `train shape` codebook as read back: codes (row-major) with their `codebook.json` keys.
pub struct CodebookFile {
    /// Code size.
    pub cols: usize,
    /// `rows × cols` codes.
    pub codes: Vec<f32>,
    /// One `{"key", "object", "part", "split"}` entry per row.
    pub keys: Vec<serde_json::Value>,
    /// The index's `"encoding"` entry (null for NAP's; [`Encoding::of_report`] reads it).
    pub encoding: serde_json::Value,
}

/// Read `shape/codebook.npy` + `shape/codebook.json`; refuses codes that are not `latent` wide
/// and a key list that does not match the rows, naming the file.
pub fn read_codebook(shape: &Path, latent: usize) -> Result<CodebookFile, TrainError> {
    let npy_path = shape.join(CODEBOOK_FILE);
    let (rows, cols, codes) =
        npy::read(&npy_path).map_err(|e| TrainError::data(&npy_path, e.to_string()))?;
    if cols != latent {
        return Err(TrainError::data(
            &npy_path,
            format!("codes have {cols} dimensions, expected {latent}"),
        ));
    }
    let index_path = shape.join(CODEBOOK_INDEX_FILE);
    let text = std::fs::read_to_string(&index_path).map_err(TrainError::io(&index_path))?;
    let index: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| TrainError::data(&index_path, e.to_string()))?;
    let keys = index["keys"]
        .as_array()
        .ok_or_else(|| TrainError::data(&index_path, "no \"keys\" list"))?
        .clone();
    if keys.len() != rows {
        return Err(TrainError::data(
            &index_path,
            format!("{} keys for {rows} codes", keys.len()),
        ));
    }
    Ok(CodebookFile {
        cols,
        codes,
        keys,
        encoding: index["encoding"].clone(),
    })
}

/// Encode every part of the data set (dataset order) by `enc` ([`Encoding`]); writes
/// `codebook.npy` and `codebook.json`. `progress(done, total)` after every batch of parts.
/// Returns the number of rows.
fn write_codebook(
    model: &ShapePrior,
    data: &Path,
    parts: &[PartRef],
    cfg: &ShapeTrainConfig,
    enc: &Encoding,
    out: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<usize, TrainError> {
    // Parts per encoder call (and per fitting batch: each code's fit is its own, so the batch
    // size changes nothing but the speed).
    const BATCH: usize = 32;
    let s = cfg.surface_points;
    let f = cfg.model.latent;
    let host = HostDecoder::new(&model.decoder);
    let mut codes = Vec::with_capacity(parts.len() * f);
    for chunk in parts.chunks(BATCH) {
        codes.extend(encode_refs(model, &host, data, chunk, s, enc)?);
        progress(codes.len() / f, parts.len());
    }
    let mut max_abs = vec![0.0f32; f];
    for row in codes.chunks(f) {
        for (m, v) in max_abs.iter_mut().zip(row) {
            *m = m.max(v.abs());
        }
    }
    write_atomic(
        &out.join(CODEBOOK_FILE),
        &npy::to_bytes(parts.len(), f, &codes),
    )?;
    let index = json!({
        "format": CODEBOOK_FORMAT,
        "latent": f,
        "rows": parts.len(),
        "encoder_input": format!("first {s} points of part<k>_surface.npy (cycled if fewer)"),
        "encoding": enc.to_json(),
        "max_abs": max_abs,
        "keys": parts.iter().map(|p| {
            let mut key = json!({
                "key": format!("{}_{}", p.id, p.k), "object": p.id, "part": p.k, "split": p.split,
            });
            if let Some(c) = &p.category {
                key["category"] = json!(c);
            }
            key
        }).collect::<Vec<_>>(),
    });
    write_atomic(
        &out.join(CODEBOOK_INDEX_FILE),
        serde_json::to_string_pretty(&index)
            .unwrap_or_default()
            .as_bytes(),
    )?;
    Ok(parts.len())
}

/// f̂' − clamp(f, −δ, δ), where f̂' clamps the prediction only on the side where the target was
/// clamped: beyond ±δ on the target's side costs nothing, but a prediction on the wrong side
/// of the band keeps its gradient. (Clamping both sides, DeepSDF's form, freezes a freshly
/// initialised network whose outputs start outside the band: measured, it never left a loss
/// of 0.055 and val IoU 0.03.)
fn truncated_residual(pred: Tensor<2>, target: Tensor<2>, delta: f32) -> Tensor<2> {
    let above = target.clone().greater_equal_elem(delta);
    let below = target.clone().lower_equal_elem(-delta);
    let pred = pred.clone().mask_where(above, pred.clamp_max(delta));
    let pred = pred.clone().mask_where(below, pred.clamp_min(-delta));
    pred - target.clamp(-delta, delta)
}

/// ∂|r|/∂pred of one query's (possibly truncated) residual, as [`truncated_residual`] and
/// burn's `abs` differentiate it: 0 where the truncation clamps the prediction, else sign(r)
/// (0 at r = 0).
fn l1_upstream(pred: f32, target: f32, truncation: Option<f32>) -> (f32, f32) {
    let (pred, target, clamped) = match truncation {
        Some(d) if target >= d && pred > d => (d, d, true),
        Some(d) if target <= -d && pred < -d => (-d, -d, true),
        Some(d) => (pred, target.clamp(-d, d), false),
        None => (pred, target, false),
    };
    let r = pred - target;
    let sign = if clamped || r == 0.0 { 0.0 } else { r.signum() };
    (r.abs(), sign)
}

/// One query's wrong-side term w · relu(−pred · sign target) and its derivative in `pred`:
/// (w·|pred|, w·sign pred) where pred and target have opposite signs, else (0, 0) (a target
/// of 0 has no side). Its gradient points where the L1 term's does, so on a wrong-side query
/// the two add up to 1 + w.
fn wrong_side(pred: f32, target: f32, w: f32) -> (f32, f32) {
    if (target < 0.0 && pred > 0.0) || (target > 0.0 && pred < 0.0) {
        (w * pred.abs(), w * pred.signum())
    } else {
        (0.0, 0.0)
    }
}

/// The linear layers of `decoder` in the order of `WeightGrads::layers`
/// ([`HostDecoder::weight_grads`]).
fn decoder_linears(decoder: &ShapeDecoder) -> Vec<&Linear> {
    let mut out = vec![&decoder.fc_p];
    for b in &decoder.blocks {
        out.push(&b.fc_0);
        out.push(&b.fc_1);
        out.extend(b.shortcut.as_ref());
    }
    out.push(&decoder.fc_out);
    out
}

/// The eikonal term of a step and its gradient with respect to the decoder's outputs.
struct Eikonal {
    /// w · mean over the chosen rows of (|∇̃f| − 1)².
    value: f64,
    /// The shifted probes q + h·e_k (three per chosen row), normalised frame.
    probes: Vec<[f32; 3]>,
    /// Their part indices.
    probe_idx: Vec<usize>,
    /// ∂(term)/∂f at each probe.
    probe_upstream: Vec<f32>,
    /// ∂(term)/∂f at each row of the batch (0 for rows not chosen).
    base_upstream: Vec<f32>,
}

/// The eikonal term on the `chosen` rows of a batch (physnap, off by default):
///
/// ```text
/// ∇̃f(q) = ((f(q + h e_x) − f(q)) / h, (f(q + h e_y) − f(q)) / h, (f(q + h e_z) − f(q)) / h)
/// L_eik  = w · mean_q (|∇̃f(q)| − 1)²          h = EIKONAL_STEP (normalised units)
/// ```
///
/// Forward differences keep it first-order: the probes are ordinary decoder rows, so the host
/// pass differentiates the term with the same code as the L1 term. One forward pass here reads
/// f at the chosen rows and probes; the gradient is returned per row for the backward pass.
fn eikonal_term(
    host: &HostDecoder,
    q: &[[f32; 3]],
    features: &[f32],
    idx: &[usize],
    chosen: &[usize],
    weight: f32,
) -> Eikonal {
    let h = EIKONAL_STEP;
    let mut probes = Vec::with_capacity(3 * chosen.len());
    let mut probe_idx = Vec::with_capacity(3 * chosen.len());
    for &r in chosen {
        for k in 0..3 {
            let mut p = q[r];
            p[k] += h;
            probes.push(p);
            probe_idx.push(idx[r]);
        }
    }
    // One forward pass: the chosen rows, then their probes.
    let at: Vec<[f32; 3]> = chosen
        .iter()
        .map(|&r| q[r])
        .chain(probes.iter().copied())
        .collect();
    let at_idx: Vec<usize> = chosen
        .iter()
        .map(|&r| idx[r])
        .chain(probe_idx.iter().copied())
        .collect();
    let mut f = vec![0.0; at.len()];
    host.eval(&at, features, &at_idx, &mut f);
    let (f_rows, f_probes) = f.split_at(chosen.len());
    let m = chosen.len().max(1) as f32;
    let mut value = 0.0f64;
    let mut probe_upstream = vec![0.0; probes.len()];
    let mut base_upstream = vec![0.0; q.len()];
    for (c, &r) in chosen.iter().enumerate() {
        let f0 = f_rows[c];
        let d: [f32; 3] = std::array::from_fn(|k| (f_probes[3 * c + k] - f0) / h);
        let g = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt().max(1e-6);
        value += (weight * (g - 1.0) * (g - 1.0) / m) as f64;
        // ∂/∂f_k of w (g − 1)² / m, with ∂g/∂f_k = d_k / (g h); f0 enters every d_k with −1.
        let common = 2.0 * weight * (g - 1.0) / (m * g * h);
        for k in 0..3 {
            probe_upstream[3 * c + k] = common * d[k];
            base_upstream[r] -= common * d[k];
        }
    }
    Eikonal {
        value,
        probes,
        probe_idx,
        probe_upstream,
        base_upstream,
    }
}

/// The decoder half of a training step with [`DecoderBackward::Host`]: the host pass computes
/// the L1 term's value and its gradients ([`HostDecoder::weight_grads`]), and burn gets
///
/// ```text
/// S = Σ_layers (Σ W ⊙ sg(∂W) + Σ b ⊙ sg(∂b)) + Σ (z W_c + b_c) ⊙ sg(∂features)
/// ```
///
/// whose gradient with respect to every decoder weight, W_c, b_c and (through z) the encoder
/// is the L1 term's (with the wrong-side and eikonal terms when they are on). Returns (S, the
/// value of those terms).
fn host_decoder_surrogate(
    decoder: &ShapeDecoder,
    z: Tensor<2>,
    pts: &[f32],
    tgt: &[f32],
    queries_per_part: usize,
    cfg: &ShapeTrainConfig,
) -> (Tensor<1>, f64) {
    let device = z.device();
    let features = decoder.code_features(z);
    let host = HostDecoder::new(decoder);
    let hidden = host.feature_width();
    let feature_values = to_vec(features.clone().detach());
    let mut q: Vec<[f32; 3]> = pts.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    let mut idx: Vec<usize> = (0..q.len()).map(|r| r / queries_per_part).collect();
    let n = q.len() as f32;
    let rows = q.len();
    let ws = cfg.wrong_side as f32;
    let eik = (cfg.eikonal > 0.0).then(|| {
        let (offset, per_part) = cfg.eikonal_rows();
        let chosen: Vec<usize> = (0..rows / queries_per_part)
            .flat_map(|p| {
                let first = p * queries_per_part + offset;
                first..first + per_part
            })
            .collect();
        eikonal_term(
            &host,
            &q,
            &feature_values,
            &idx,
            &chosen,
            cfg.eikonal as f32,
        )
    });
    // The eikonal term's shifted probes join the batch as extra rows; its gradient on the base
    // rows is added to theirs.
    if let Some(e) = &eik {
        q.extend_from_slice(&e.probes);
        idx.extend_from_slice(&e.probe_idx);
    }
    let g = host.weight_grads(&q, &feature_values, &idx, &|r, f| {
        if r < rows {
            (l1_upstream(f, tgt[r], cfg.truncation).1 + wrong_side(f, tgt[r], ws).1) / n
                + eik.as_ref().map_or(0.0, |e| e.base_upstream[r])
        } else {
            eik.as_ref().map_or(0.0, |e| e.probe_upstream[r - rows])
        }
    });
    let l1 = g.values[..rows]
        .iter()
        .zip(tgt)
        .map(|(&f, &t)| (l1_upstream(f, t, cfg.truncation).0 + wrong_side(f, t, ws).0) as f64)
        .sum::<f64>()
        / rows.max(1) as f64
        + eik.as_ref().map_or(0.0, |e| e.value);
    let p = feature_values.len() / hidden;
    let d_features = Tensor::<2>::from_data(TensorData::new(g.d_features, [p, hidden]), &device);
    let mut surrogate = (features * d_features).sum();
    for (layer, grad) in decoder_linears(decoder).into_iter().zip(g.layers) {
        let w = layer.weight.val();
        let dw = Tensor::<2>::from_data(TensorData::new(grad.w, w.dims()), &device);
        surrogate = surrogate + (w * dw).sum();
        if let (Some(b), Some(db)) = (&layer.bias, grad.b) {
            let len = db.len();
            let db = Tensor::<1>::from_data(TensorData::new(db, [len]), &device);
            surrogate = surrogate + (b.val() * db).sum();
        }
    }
    (surrogate, l1)
}

/// A step's loss L = mean |f̂ − f| + w_reg · mean(z²) (+ the wrong-side and eikonal terms when
/// on) on `batch`: (a tensor whose gradient is ∂L, L's value). With [`DecoderBackward::Burn`]
/// the tensor is L itself; with [`DecoderBackward::Host`] it is the surrogate of
/// [`host_decoder_surrogate`] plus the regulariser.
fn batch_loss(
    model: &ShapePrior,
    batch: Batch,
    cfg: &ShapeTrainConfig,
    device: &Device,
) -> (Tensor<1>, f64) {
    let (q, s) = (cfg.queries_per_part, cfg.surface_points);
    let b = batch.tgt.len() / q;
    let z = if batch.codes.is_empty() {
        let surf = Tensor::from_data(TensorData::new(batch.surf, [b, s, 3]), device);
        model.encoder.encode(surf)
    } else {
        let f = batch.codes.len() / b;
        Tensor::from_data(TensorData::new(batch.codes, [b, f]), device)
    };
    let reg = z.clone().square().mean().mul_scalar(cfg.w_reg);
    match cfg.decoder_backward {
        DecoderBackward::Burn => {
            let pts = Tensor::from_data(TensorData::new(batch.pts, [b, q, 3]), device);
            let tgt = Tensor::from_data(TensorData::new(batch.tgt, [b, q]), device);
            let pred = model.decoder.sdf(pts.clone(), z.clone());
            let side = (cfg.wrong_side > 0.0).then(|| {
                let wrong = burn::tensor::activation::relu(-(pred.clone() * tgt.clone().sign()));
                wrong.mean().mul_scalar(cfg.wrong_side)
            });
            let diff = match cfg.truncation {
                Some(d) => truncated_residual(pred, tgt, d),
                None => pred - tgt,
            };
            let mut loss = diff.abs().mean() + reg;
            if let Some(side) = side {
                loss = loss + side;
            }
            if cfg.eikonal > 0.0 {
                // The reference form of `eikonal_term`, through burn's autodiff.
                let (offset, per_part) = cfg.eikonal_rows();
                let p0 = pts.narrow(1, offset, per_part);
                let f0 = model.decoder.sdf(p0.clone(), z.clone());
                let mut g2 = f0.zeros_like();
                for k in 0..3 {
                    let mut e = [0.0f32; 3];
                    e[k] = EIKONAL_STEP;
                    let shift =
                        Tensor::<3>::from_data(TensorData::new(e.to_vec(), [1, 1, 3]), device);
                    let fk = model.decoder.sdf(p0.clone() + shift, z.clone());
                    g2 = g2 + ((fk - f0.clone()) / EIKONAL_STEP).powi_scalar(2);
                }
                let g = g2.sqrt().clamp_min(1e-6);
                loss = loss + (g - 1.0).powi_scalar(2).mean().mul_scalar(cfg.eikonal);
            }
            let value = loss.clone().into_scalar::<f32>() as f64;
            (loss, value)
        }
        DecoderBackward::Host => {
            let (surrogate, l1) =
                host_decoder_surrogate(&model.decoder, z, &batch.pts, &batch.tgt, q, cfg);
            let value = l1 + reg.clone().into_scalar::<f32>() as f64;
            (surrogate + reg, value)
        }
    }
}

/// The batch's loss value and its gradients, computed in `cfg.batch_shards` contiguous slices of
/// (nearly) equal part counts, as `train diffusion` does (its `sharded_step`): each slice runs
/// [`batch_loss`] on its own fork of the model (fresh autodiff leaves, the same parameter ids)
/// in parallel on the rayon pool, its loss weighted by its share of the parts. Every term is a
/// mean over parts with the same number of rows each (L1, eikonal, w_reg · mean(z²)), so the
/// weighted sum is the whole batch's loss and gradient up to float rounding. Gradients are
/// summed in slice order whatever the thread timing, so a run is deterministic for a given
/// shard count at a fixed thread count. Why: the step's single pass keeps only ≈ 1.3 of the two
/// cores busy; two slices keep both.
fn sharded_loss(
    model: &ShapePrior,
    batch: Batch,
    cfg: &ShapeTrainConfig,
    device: &Device,
) -> (f64, GradientsParams) {
    let b = batch.tgt.len() / cfg.queries_per_part;
    let shards = cfg.batch_shards.clamp(1, b.max(1));
    if shards == 1 {
        let (loss, value) = batch_loss(model, batch, cfg, device);
        return (value, GradientsParams::from_grads(loss.backward(), model));
    }
    let slices: Vec<(ShapePrior, Batch, f64)> = (0..shards)
        .map(|k| {
            let (start, end) = (k * b / shards, (k + 1) * b / shards);
            (
                model.clone().fork(device),
                batch.slice(start, end, cfg),
                (end - start) as f64 / b as f64,
            )
        })
        .collect();
    let results: Vec<(f64, GradientsParams)> = slices
        .into_par_iter()
        .map(|(m, slice, share)| {
            let (loss, value) = batch_loss(&m, slice, cfg, device);
            let loss = loss.mul_scalar(share as f32);
            (
                value * share,
                GradientsParams::from_grads(loss.backward(), &m),
            )
        })
        .collect();
    super::sum_slices(model, results)
}

/// The optimisation state of a run: model, Adam, batch sampler.
struct Trainer<'a> {
    cfg: &'a ShapeTrainConfig,
    parts: &'a [PartSamples],
    /// The training parts' fixed codes (`codes_from`).
    codes: Option<&'a FixedCodes>,
    /// Always `Some` between steps (taken by value for the optimiser, so parameters are
    /// updated in place rather than copied).
    model: Option<ShapePrior>,
    optim: ModuleOptimizer,
    rng: Rng,
    /// What is left of the current shuffled epoch (popped from the back).
    epoch: Vec<usize>,
    /// The weight EMA (`ema_decay > 0`).
    ema: Option<Ema>,
    device: Device,
}

impl<'a> Trainer<'a> {
    /// The run's starting point: `init_from`'s weights, else the seeded initialisation.
    fn new(
        cfg: &'a ShapeTrainConfig,
        parts: &'a [PartSamples],
        codes: Option<&'a FixedCodes>,
    ) -> Result<Self, TrainError> {
        let device = cfg.compute.autodiff();
        let model = match &cfg.init_from {
            Some(init) => load_init(init, &cfg.model, cfg.seed, &device)?,
            None => ShapePrior::with_seed(&cfg.model, cfg.seed, &device),
        };
        Ok(Trainer {
            cfg,
            parts,
            codes,
            ema: (cfg.ema_decay > 0.0).then(|| Ema::new(&model, cfg.ema_decay, 0)),
            model: Some(model),
            optim: AdamConfig::new().with_epsilon(1e-8).init(),
            rng: Rng::fork(cfg.seed, 1),
            epoch: Vec::new(),
            device,
        })
    }

    /// One optimiser step (0-based `step`): (loss, learning rate).
    fn step(&mut self, step: usize) -> Result<(f64, f64), TrainError> {
        let cfg = self.cfg;
        let mut order = Vec::with_capacity(cfg.batch_parts);
        while order.len() < cfg.batch_parts {
            if self.epoch.is_empty() {
                self.epoch = (0..self.parts.len()).collect();
                for i in (1..self.epoch.len()).rev() {
                    self.epoch.swap(i, self.rng.int(0, i));
                }
            }
            order.extend(self.epoch.pop());
        }
        let batch = sample_batch(self.parts, &order, cfg, self.codes, &mut self.rng);
        let model = self.model.take().expect("model is present between steps");
        let (value, grads) = sharded_loss(&model, batch, cfg, &self.device);
        if !value.is_finite() || value > DIVERGED_LOSS {
            return Err(TrainError::Diverged { step, loss: value });
        }
        let lr = cfg.lr_at(step);
        let model = self.optim.step(lr, model, grads);
        if let Some(ema) = self.ema.as_mut() {
            ema.update(&model);
        }
        self.model = Some(model);
        Ok((value, lr))
    }

    /// The raw (last-iterate) model in inference mode.
    fn raw_model(&self) -> ShapePrior {
        self.model
            .as_ref()
            .expect("model is present between steps")
            .valid()
    }

    /// The model the run evaluates and saves, on the CPU: the EMA weights when there is an
    /// EMA, else the raw ones.
    fn inference_model(&self) -> ShapePrior {
        let model = match &self.ema {
            Some(ema) => ema.install(self.raw_model()),
            None => self.raw_model(),
        };
        match self.cfg.compute {
            Compute::Cpu => model,
            Compute::Gpu(_) => model.to_device(&cpu()),
        }
    }
}

/// Train the shape prior on `data` (a `physnap data import` output) and write weights, codebook
/// and report into `out`. `progress` is called after every step.
pub fn train_shape(
    data: &Path,
    cfg: &ShapeTrainConfig,
    out: &Path,
    progress: &mut dyn FnMut(&ShapeTrainProgress),
) -> Result<ShapeTrainReport, TrainError> {
    cfg.validate()?;
    let Some(n) = cfg.threads else {
        return run(data, cfg, out, progress);
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .map_err(|e| TrainError::config("threads", "a buildable thread pool", e))?;
    // Burn runs on the *current* rayon pool, so the loop runs inside `pool`; `progress` need
    // not be `Send`, so it is called here, on the caller's thread, from a channel.
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::scope(|s| {
        let worker = s.spawn(move || {
            pool.install(|| {
                run(data, cfg, out, &mut |p| {
                    let _ = tx.send(p.clone());
                })
            })
        });
        for p in rx {
            progress(&p);
        }
        worker
            .join()
            .unwrap_or_else(|e| std::panic::resume_unwind(e))
    })
}

fn mean_of(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len().max(1) as f64
}

/// What `shape_checkpoint.json` holds besides the weights: enough to continue the same batch
/// stream (generator state and the rest of the shuffled epoch) and the same report. Adam's
/// moment estimates are not kept; they restart from zero on resume, as in `train diffusion`.
struct Checkpoint {
    step: usize,
    rng_state: u64,
    epoch: Vec<usize>,
    losses: Vec<f64>,
    curve: Vec<EvalPoint>,
    train_s: f64,
    elapsed_s: f64,
    /// EMA updates so far (runs with an EMA; the shadow is [`EMA_CHECKPOINT_FILE`]). Taken
    /// from the trainer when writing.
    ema_steps: Option<usize>,
}

/// Weights (temp file + rename), then `shape_checkpoint.json` (atomic) with the weights'
/// sha256, so a crash between the two is detected on resume rather than mixing steps.
fn write_checkpoint(
    out: &Path,
    cfg: &ShapeTrainConfig,
    trainer: &Trainer<'_>,
    c: &Checkpoint,
) -> Result<(), TrainError> {
    // Weights go to a temp file, are hashed, then renamed into place.
    let tmp = out.join("shape_prior.checkpoint.tmp");
    let save = |model: &ShapePrior, file: &str| -> Result<String, TrainError> {
        save_shape_prior(model, &tmp)?;
        let bytes = std::fs::read(&tmp).map_err(TrainError::io(&tmp))?;
        let dest = out.join(file);
        std::fs::rename(&tmp, &dest).map_err(TrainError::io(&dest))?;
        Ok(crate::model::weights::sha256_hex(&bytes))
    };
    let raw = trainer
        .model
        .as_ref()
        .expect("model is present between steps");
    let weights_sha = save(raw, WEIGHTS_FILE)?;
    let ema = match &trainer.ema {
        Some(ema) => json!({
            "steps": ema.steps,
            "sha256": save(&trainer.inference_model(), EMA_CHECKPOINT_FILE)?,
        }),
        None => Value::Null,
    };
    let doc = json!({
        "ema": ema,
        "format": CHECKPOINT_FORMAT,
        "step": c.step,
        "config": cfg.to_json(),
        "weights_sha256": weights_sha,
        "rng_state": c.rng_state.to_string(),
        "epoch": c.epoch,
        "losses": c.losses,
        "curve": c.curve.iter().map(EvalPoint::to_json).collect::<Vec<_>>(),
        "train_s": c.train_s,
        "elapsed_s": c.elapsed_s,
    });
    write_atomic(
        &out.join(CHECKPOINT_FILE),
        serde_json::to_string(&doc).unwrap_or_default().as_bytes(),
    )
}

/// Refuse `weights` unless its sha256 is `recorded`, the value the checkpoint document (read
/// from `doc_path`) holds for it: a run killed between the two writes leaves them apart.
fn check_checkpoint_weights(
    weights: &Path,
    recorded: &Value,
    doc_path: &Path,
) -> Result<(), TrainError> {
    let bytes = std::fs::read(weights).map_err(TrainError::io(weights))?;
    if *recorded != crate::model::weights::sha256_hex(&bytes).as_str() {
        return Err(TrainError::data(
            weights,
            format!(
                "sha256 differs from the one {} recorded: the checkpoint is incomplete",
                doc_path.display()
            ),
        ));
    }
    Ok(())
}

/// Read `out/shape_checkpoint.json`, refusing one written by a different run (a config field of
/// [`RESUME_FIELDS`] differs: named with both values) or whose weights file is not the one it
/// was written with.
fn read_checkpoint(out: &Path, cfg: &ShapeTrainConfig) -> Result<Checkpoint, TrainError> {
    let path = out.join(CHECKPOINT_FILE);
    let text = std::fs::read_to_string(&path).map_err(TrainError::io(&path))?;
    let v: Value =
        serde_json::from_str(&text).map_err(|e| TrainError::data(&path, e.to_string()))?;
    if v["format"] != CHECKPOINT_FORMAT {
        return Err(TrainError::data(
            &path,
            format!("format {} is not {CHECKPOINT_FORMAT}", v["format"]),
        ));
    }
    let ours = cfg.to_json();
    let defaults = ShapeTrainConfig::default().to_json();
    for field in RESUME_FIELDS {
        // A field newer than the checkpoint (the EMA, the frozen encoder, the wrong-side term)
        // is missing from it: that run had the option off, which is its default.
        let theirs = match &v["config"][field] {
            Value::Null => defaults[field].clone(),
            x => x.clone(),
        };
        if theirs != ours[field] {
            return Err(TrainError::Config {
                field: field.to_string(),
                limit: format!(
                    "the checkpoint's value {theirs} to resume {} (or start afresh without --resume)",
                    path.display()
                ),
                value: ours[field].to_string(),
            });
        }
    }
    check_checkpoint_weights(&out.join(WEIGHTS_FILE), &v["weights_sha256"], &path)?;
    let bad = |k: &str| TrainError::data(&path, format!("{k} is missing or malformed"));
    let num = |k: &str| v[k].as_f64().ok_or_else(|| bad(k));
    let step = v["step"].as_u64().ok_or_else(|| bad("step"))? as usize;
    let rng_state = v["rng_state"]
        .as_str()
        .and_then(|s| s.parse::<u64>().ok())
        .ok_or_else(|| bad("rng_state"))?;
    let epoch = v["epoch"]
        .as_array()
        .and_then(|a| a.iter().map(|x| x.as_u64().map(|x| x as usize)).collect())
        .ok_or_else(|| bad("epoch"))?;
    let losses: Vec<f64> = v["losses"]
        .as_array()
        .and_then(|a| a.iter().map(Value::as_f64).collect())
        .ok_or_else(|| bad("losses"))?;
    let curve = v["curve"]
        .as_array()
        .and_then(|a| a.iter().map(EvalPoint::from_json).collect())
        .ok_or_else(|| bad("curve"))?;
    if losses.len() != step || step >= cfg.steps {
        return Err(TrainError::data(
            &path,
            format!(
                "step {step} with {} losses does not fit a run of {} steps",
                losses.len(),
                cfg.steps
            ),
        ));
    }
    let ema_steps = if cfg.ema_decay > 0.0 {
        check_checkpoint_weights(&out.join(EMA_CHECKPOINT_FILE), &v["ema"]["sha256"], &path)?;
        Some(v["ema"]["steps"].as_u64().ok_or_else(|| bad("ema.steps"))? as usize)
    } else {
        None
    };
    Ok(Checkpoint {
        step,
        rng_state,
        epoch,
        losses,
        curve,
        train_s: num("train_s")?,
        elapsed_s: num("elapsed_s")?,
        ema_steps,
    })
}

fn run(
    data: &Path,
    cfg: &ShapeTrainConfig,
    out: &Path,
    progress: &mut dyn FnMut(&ShapeTrainProgress),
) -> Result<ShapeTrainReport, TrainError> {
    let t0 = Instant::now();
    let all = read_index(data)?;
    let mut train: Vec<&PartRef> = all.iter().filter(|p| p.split == "train").collect();
    if let Some(m) = cfg.max_parts {
        train.truncate(m);
    }
    if train.is_empty() {
        return Err(TrainError::data(
            data.join("dataset.json"),
            "no train parts (split \"train\")",
        ));
    }
    let fixed = match &cfg.codes_from {
        Some(dir) => Some(FixedCodes::read(dir, cfg.model.latent, &train)?),
        None => None,
    };
    // What the run's evaluations encode the val parts by: the fixed codes' encoding, else
    // NAP's (the encoder's code).
    let encoding = fixed
        .as_ref()
        .map_or_else(Encoding::default, |f| f.encoding);
    let val_refs = val_selection(&all, cfg);
    let parts: Vec<PartSamples> = train
        .par_iter()
        .map(|p| load_part(data, p))
        .collect::<Result<_, _>>()?;
    let grid_pts = iou_grid(cfg.iou_resolution);
    let val: Vec<ValPart> = val_refs
        .iter()
        .map(|p| load_val_part(data, p, cfg, &encoding, &grid_pts))
        .collect::<Result<_, _>>()?;
    let grid: Vec<f32> = grid_pts.into_iter().flatten().collect();
    std::fs::create_dir_all(out).map_err(TrainError::io(out))?;

    let mut trainer = Trainer::new(cfg, &parts, fixed.as_ref())?;
    let mut losses = Vec::with_capacity(cfg.steps);
    let mut curve = Vec::new();
    let mut train_s = 0.0;
    // Seconds of training before this run (resumed runs), so `elapsed_s` spans the whole run.
    let mut elapsed_before = 0.0;
    let mut start = 0;
    let ckpt_path = out.join(CHECKPOINT_FILE);
    if cfg.resume && ckpt_path.is_file() {
        let c = read_checkpoint(out, cfg)?;
        trainer.model = Some(load_shape_prior(
            &out.join(WEIGHTS_FILE),
            &cfg.model,
            &trainer.device,
        )?);
        if let Some(steps) = c.ema_steps {
            let path = out.join(EMA_CHECKPOINT_FILE);
            let averaged = load_shape_prior(&path, &cfg.model, &trainer.device)?;
            trainer.ema = Some(Ema::new(&averaged, cfg.ema_decay, steps));
        }
        trainer.rng = Rng::from_state(c.rng_state);
        trainer.epoch = c.epoch;
        (losses, curve, train_s, elapsed_before, start) =
            (c.losses, c.curve, c.train_s, c.elapsed_s, c.step);
    }
    if cfg.freeze_encoder || cfg.freeze_decoder {
        let mut model = trainer
            .model
            .take()
            .expect("model is present between steps");
        if cfg.freeze_encoder {
            model.encoder = model.encoder.no_grad();
        }
        if cfg.freeze_decoder {
            model.decoder = model.decoder.no_grad();
        }
        trainer.model = Some(model);
    }
    let end = cfg.stop_at.unwrap_or(cfg.steps).max(start);
    let t_train = Instant::now();
    for step in start..end {
        let t_step = Instant::now();
        let (value, lr) = trainer.step(step)?;
        train_s += t_step.elapsed().as_secs_f64();
        losses.push(value);
        let done = step + 1;
        let eval_now = done == cfg.steps || (cfg.eval_every > 0 && done % cfg.eval_every == 0);
        let (mut val_iou, mut val_l1) = (None, None);
        if eval_now && !val.is_empty() {
            let (ious, l1) = evaluate(&trainer.inference_model(), &val, cfg, &grid, &encoding);
            let iou = ious.iter().sum::<f64>() / ious.len() as f64;
            let elapsed_s = elapsed_before + t_train.elapsed().as_secs_f64();
            curve.push(EvalPoint {
                step: done,
                elapsed_s,
                iou,
                l1,
            });
            (val_iou, val_l1) = (Some(iou), Some(l1));
        }
        progress(&ShapeTrainProgress {
            step: done,
            steps: cfg.steps,
            loss: value,
            lr,
            elapsed_s: elapsed_before + t_train.elapsed().as_secs_f64(),
            val_iou,
            val_l1,
        });
        let checkpoint_now =
            done == end || (cfg.checkpoint_every > 0 && done.is_multiple_of(cfg.checkpoint_every));
        if done < cfg.steps && checkpoint_now {
            write_checkpoint(
                out,
                cfg,
                &trainer,
                &Checkpoint {
                    step: done,
                    rng_state: trainer.rng.state(),
                    epoch: trainer.epoch.clone(),
                    losses: losses.clone(),
                    curve: curve.clone(),
                    train_s,
                    elapsed_s: elapsed_before + t_train.elapsed().as_secs_f64(),
                    ema_steps: None,
                },
            )?;
        }
    }
    let report = |codebook_rows: usize, curve: Vec<EvalPoint>| ShapeTrainReport {
        steps: end,
        wall_s: t0.elapsed().as_secs_f64(),
        train_s,
        initial_loss: mean_of(&losses[..losses.len().min(20)]),
        final_loss: mean_of(&losses[losses.len().saturating_sub(50)..]),
        val_iou: curve.last().map(|e| e.iou),
        curve,
        train_parts: parts.len(),
        val_parts: val.len(),
        codebook_rows,
        queries_per_s: (losses.len() * cfg.batch_parts * cfg.queries_per_part) as f64
            / train_s.max(1e-9),
    };
    if end < cfg.steps {
        // Stopped early (`stop_at`): the checkpoint holds the run; no final outputs yet.
        return Ok(report(0, curve));
    }

    let model = trainer.inference_model();
    save_shape_prior(&model, &out.join(WEIGHTS_FILE))?;
    let codebook_rows = match &fixed {
        Some(f) => f.copy_to(out)?,
        None => write_codebook(
            &model,
            data,
            &all,
            cfg,
            &Encoding::default(),
            out,
            &mut |_, _| {},
        )?,
    };
    let report = report(codebook_rows, curve);
    let mut doc = json!({
        "format": REPORT_FORMAT,
        "config": cfg.to_json(),
        "data": data.display().to_string(),
        "steps": report.steps,
        "wall_s": report.wall_s,
        "train_s": report.train_s,
        "initial_loss": report.initial_loss,
        "final_loss": report.final_loss,
        "val_iou": report.val_iou,
        "curve": report.curve.iter().map(EvalPoint::to_json).collect::<Vec<_>>(),
        "train_parts": report.train_parts,
        "val_parts": report.val_parts,
        "codebook_rows": report.codebook_rows,
        "queries_per_s": report.queries_per_s,
        "weights": WEIGHTS_FILE,
        "threads": rayon::current_num_threads(),
        "device": cfg.compute.name(),
    });
    if encoding != Encoding::default() {
        // As `encode_shape_dir` records it: what `eval shape` and `train diffusion` check.
        doc["encoding"] = encoding.to_json();
    }
    write_atomic(
        &out.join(REPORT_FILE),
        serde_json::to_string_pretty(&doc)
            .unwrap_or_default()
            .as_bytes(),
    )?;
    // The run is complete: a leftover checkpoint would describe older weights.
    for path in [ckpt_path, out.join(EMA_CHECKPOINT_FILE)] {
        if path.is_file() {
            std::fs::remove_file(&path).map_err(TrainError::io(&path))?;
        }
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
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
        let (_, surf) =
            read_rows(&parts[0].file(&data.path().join("train"), "surface"), 3).unwrap();
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
            serde_json::from_str(&std::fs::read_to_string(base.join(REPORT_FILE)).unwrap())
                .unwrap();
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
        let mut index: Value = serde_json::from_str(
            &std::fs::read_to_string(codes.join(CODEBOOK_INDEX_FILE)).unwrap(),
        )
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
        let mut doc: Value =
            serde_json::from_str(&std::fs::read_to_string(&ckpt).unwrap()).unwrap();
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
            serde_json::from_str(&std::fs::read_to_string(again.join(REPORT_FILE)).unwrap())
                .unwrap();
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
            let model = ShapePrior::with_seed(&cfg.model, seed, &device)
                .map(&mut Randomise(Rng::new(seed)));
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
                        .map(|i| format!(
                            " val_iou {i:.4} val_l1 {:.5}",
                            p.val_l1.unwrap_or(f64::NAN)
                        ))
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
}
