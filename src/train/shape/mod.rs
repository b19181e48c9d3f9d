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

mod checkpoint;
mod config;
mod data;
mod encoding;
mod loss;
#[cfg(test)]
mod tests;
mod trainer;

#[allow(unused_imports)]
use crate::eval::shape_iou::*;
pub use checkpoint::*;
pub use config::*;
pub(crate) use data::*;
pub use encoding::*;
pub(crate) use loss::*;
pub use trainer::*;

use super::TrainError;
use serde_json::{Value, json};

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
pub(crate) const RESUME_FIELDS: [&str; 17] = [
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

/// Write `bytes` to `path` atomically (temp file + rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), TrainError> {
    crate::io::atomic::write(path, bytes).map_err(|e| TrainError::io(&e.path)(e.source))
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
    pub(crate) fn to_json(&self) -> Value {
        json!({ "step": self.step, "elapsed_s": self.elapsed_s, "iou": self.iou, "l1": self.l1 })
    }

    /// The inverse of [`EvalPoint::to_json`] (None when a field is missing or not a number).
    pub(crate) fn from_json(v: &Value) -> Option<Self> {
        Some(EvalPoint {
            step: v["step"].as_u64()? as usize,
            elapsed_s: v["elapsed_s"].as_f64()?,
            iou: v["iou"].as_f64()?,
            l1: v["l1"].as_f64()?,
        })
    }
}
