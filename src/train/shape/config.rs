//! The shape prior's training configuration: every knob of `physnap train shape`, its
//! validation and defaults, and the model config it implies.

#[allow(unused_imports)]
use super::*;
use crate::model::Compute;
use crate::model::shape_prior::ShapePriorConfig;
use crate::train::TrainError;
use serde_json::{Value, json};

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

    pub(crate) fn to_json(&self) -> Value {
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

pub(crate) fn model_config_json(m: &ShapePriorConfig) -> Value {
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
