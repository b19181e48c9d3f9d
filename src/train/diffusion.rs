//! `physnap train diffusion`: the articulation denoiser's training loop (method.md §2).
//!
//! Why it exists: one command turns an imported data set plus the shape prior's codebook into
//! denoiser weights. Per step: draw `batch_objects` training graphs, permute their node slots
//! at random (§1.6), scale them by the training-split feature scales (§1.7), replicate each
//! `noise_levels` times with its own t ~ U{0..999} and ε ~ N(0, I), and minimise NAP's grouped
//! ε-prediction loss
//!
//! ```text
//! e = (ε − ε̂)², averaged over the 8 node slots / 28 edge rows
//! L_node = ¼ [e_o + mean(e_b) + mean(e_t) + mean(e_s)]
//! L_edge = mean(e_c̃) + mean(e_Plücker) + mean(e_ρ)
//! L = mean over samples of (L_node + L_edge), clamped to [−100, 100]
//! ```
//!
//! with Adam. Optionally (`min_snr_gamma` = γ > 0; off by default, i.e. NAP's loss) each
//! sample's L is weighted by Min-SNR-γ (Hang et al., ICCV 2023) before the batch mean:
//!
//! ```text
//! w(t) = min(1, γ / SNR(t)),   SNR(t) = ᾱ_t / (1 − ᾱ_t)
//! ```
//!
//! which damps the low-noise steps (large SNR) whose ε-loss otherwise dominates the gradient,
//! leaving the mid- and high-noise steps, where an object's coarse layout and category are
//! decided, a larger share. Measured with γ = 5 on the shipped recipe it gave no gain
//! (EVALUATION.md, "Category conditioning"), so the shipped weights are trained without it.
//!
//! The other end (`high_noise_cap` = C > 1; off by default): the capped truncated-SNR weight
//!
//! ```text
//! w(t) = clamp(1 / SNR(t), 1, C)
//! ```
//!
//! turns the high-noise steps' ε-loss into an x̂₀-loss (ε-MSE / SNR = x̂₀-MSE), up to the cap,
//! where what there is to learn is the category's typical layout. Both weights multiply.
//!
//! Box-overlap penalty (`overlap_weight` = λ > 0; off by default, i.e. NAP's loss): generated
//! part boxes intersect three to four times as often as the data's, and ten times deeper
//! (measured on the weights of 2026-11), which guidance then fights. For the samples with t <
//! `overlap_max_t` the step also decodes the boxes of x̂₀ = (x_t − √(1 − ᾱ_t) ε̂) / √ᾱ_t,
//! un-scaled to object units, and penalises every pair of parts that exist in x₀ for
//! intersecting more deeply than the same pair does in x₀:
//!
//! ```text
//! d(i, j) = min over axes a of [min(hi_ia, hi_ja) − max(lo_ia, lo_ja)],  lo/hi = t ∓ |b|
//! L_overlap = λ · (1/B) Σ_samples Σ_{i<j, both exist} max(0, d̂(i, j) − max(0, d(i, j)))²
//! ```
//!
//! d > 0 is the depth by which two boxes intersect (the smallest per-axis overlap), d ≤ 0 a
//! gap. The term is one-sided: contact, nesting and gaps that the data has cost nothing; only
//! overlap beyond the data's does. L = L_ε + L_overlap.
//!
//! Layout gain (`layout_gain` = G; 1 by default, i.e. NAP's scaling): NAP scales every channel
//! by its max-abs over the training split (§1.7), which leaves the part boxes and centres with
//! a standard deviation of only 0.17–0.32 in model space against unit noise. With the linear
//! β schedule the noise outgrows that spread (σ_t / √ᾱ_t > 0.17–0.32) by t = 23–61 of 1000,
//! so a sample settles where its parts sit in the last few per cent of the reverse steps, and
//! two parts of one size that the data keeps a few centimetres apart (a suitcase's two shells
//! at ±0.07 m, 0.15 in model space, buried by t ≈ 20) come out averaged on top of each other.
//! G divides the box and centre scales:
//!
//! ```text
//! model value = raw value / (scale_c / G)   for c in the box and centre channels
//! ```
//!
//! so the layout spans G times as much of model space and stays readable up to G times the
//! noise (G = 2: a spread of 0.35–0.65, buried at t = 61–144; images in [−1, 1], what the
//! schedule was made for, have about 0.5). The scales the run trains in (with G applied) are
//! what `diffusion_train.json` and the manifest record, so sampling needs nothing else; a
//! resume whose scales differ from the recorded ones (another G, codebook or data set) is
//! refused. Measured with G = 2 (EVALUATION.md, "Layout gain"): suitcase layouts move towards
//! the data's, category accuracy 80.3 % over nine seeds against 77.6 %, 1-NNA level, guided
//! fits level or closer; the shipped weights use G = 2 since 2026-11-30 (the recipe's
//! `LAYOUT_GAIN`), while the flag's default stays NAP's 1.
//!
//! Code gain (`code_gain` = G_z; 1 by default): the same division for the 128 shape-code
//! channels, `model value = raw value / (scale_c / G_z)`. NAP's grouped loss gives the codes
//! one group, and generated codes land about ten times further from the nearest training code
//! than held-out parts encode; G_z > 1 keeps the codes
//! readable to G_z times the noise, so the reverse process has more steps to place them.
//! Recorded, applied and checked on resume exactly as the layout gain. Measured with G_z = 2
//! on fitted codes: category accuracy 81.6 % over nine seeds against 80.3 % at G_z = 1, 1-NNA
//! ≤ 0.69, and the generated codes' median distance to the nearest training code 0.61 against
//! 1.03 at G_z = 1 on the same codes (DDIM 200; 0.71 against 1.28 with DDPM 1000); the shipped
//! weights use G_z = 2 (the recipe's `CODE_GAIN`), while the flag's default stays NAP's 1.
//!
//! Category conditioning: each sample carries its object's category index, replaced
//! by the "no category" row with probability `category_dropout`, so one model serves both the
//! category-aware and the unconditional mode.
//!
//! Learning rate: constant `lr` up to step `lr_decay_start`, then a cosine decay to
//! `lr · lr_final_factor` at the last step:
//!
//! ```text
//! lr(s) = lr                                                   for s < s₀
//! lr(s) = lr · [f + (1 − f) · ½(1 + cos(π (s − s₀) / (S − s₀)))]   for s ≥ s₀
//! ```
//!
//! Weight EMA (as in DDPM/NAP sampling practice): after every step the shadow weights follow
//! `θ̄ ← d θ̄ + (1 − d) θ` with `d = min(ema_decay, (1 + n)/(10 + n))`, n = steps since the EMA
//! started. The shadow is what `denoiser.safetensors` holds (it is what samples well); the raw
//! weights are checkpointed beside it as `denoiser_raw.safetensors` so training can continue.
//! `ema_decay = 0` turns the EMA off (the file then holds the raw weights).
//!
//! Both cores: each step's batch is split into `batch_shards` slices (default 2) whose forward
//! and backward passes run in parallel on the rayon pool, each slice's loss weighted by its
//! share of the batch, so the summed gradient is the batch's (up to float rounding). With one
//! shard the step is the single-pass one of the runs before 2026-11-28, bit for bit; a run is
//! deterministic for a given shard count on any number of threads.
//!
//! Reproducibility and resume: step s draws everything from `Rng::fork(seed, s)`, so a resumed
//! run sees exactly the batches and noise of an uninterrupted one. Checkpoints
//! (`denoiser.safetensors`, `denoiser_raw.safetensors` + `checkpoint.json`) are written every
//! `checkpoint_every` steps and at the end; `resume` continues from them (and carries the loss
//! EMA and the cumulative wall time, `wall_seconds_total`, across the runs). Adam's moment
//! estimates are not checkpointed and restart from zero on resume (documented deviation; the
//! loss recovers within a few hundred steps). A checkpoint without a raw file (written before
//! the EMA existed) resumes from `denoiser.safetensors` and starts the EMA there.

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Int, Tensor, TensorData};
use serde_json::{Value, json};

use super::TrainError;
use super::ema::Ema;
use crate::data::categories::CATEGORIES;
use crate::data::rng::Rng;
use crate::engine::schedule::Schedule;
use crate::graph::{
    EDGE_DIM, FeatureScales, GraphTensor, K, NODE_DIM, NUM_EDGES, edge_ch, node_ch,
};
use crate::io::npy;
use crate::model::denoiser::{Denoiser, DenoiserConfig};
use crate::model::{Compute, weights};

/// Training knobs.
#[derive(Debug, Clone)]
pub struct DiffusionTrainConfig {
    /// Denoiser architecture.
    pub model: DenoiserConfig,
    /// Total optimiser steps.
    pub steps: usize,
    /// Objects per step.
    pub batch_objects: usize,
    /// Noise levels per object per step (NAP: 10).
    pub noise_levels: usize,
    /// Adam learning rate.
    pub lr: f64,
    /// Seed.
    pub seed: u64,
    /// Probability of replacing the category by "no category".
    pub category_dropout: f64,
    /// Steps between checkpoints (0: only the one at the end of the run).
    pub checkpoint_every: usize,
    /// Step from which the learning rate decays (cosine) towards `lr · lr_final_factor`.
    pub lr_decay_start: usize,
    /// Final learning rate as a fraction of `lr` (1 = constant).
    pub lr_final_factor: f64,
    /// Weight-EMA decay (0 = off).
    pub ema_decay: f64,
    /// End this run after this many steps in total (a checkpoint is written there; the
    /// schedule still runs to `steps`, so `--resume` continues the same run). None: `steps`.
    pub stop_at: Option<usize>,
    /// Min-SNR-γ loss weighting (Hang et al., ICCV 2023): each sample's ε-loss is weighted by
    /// `min(1, γ / SNR(t))`. 0 = off (NAP's unweighted loss).
    pub min_snr_gamma: f64,
    /// Capped truncated-SNR weighting of the high-noise steps: each sample's ε-loss is also
    /// weighted by `clamp(1 / SNR(t), 1, cap)`. 1 (or less) = off (NAP's unweighted loss).
    pub high_noise_cap: f64,
    /// Weight λ of the box-overlap penalty on x̂₀ (module documentation); 0 = off (NAP's loss).
    pub overlap_weight: f64,
    /// The penalty counts only samples with t below this (x̂₀ is a blur at high noise).
    pub overlap_max_t: usize,
    /// Layout gain G: the box and centre channels' feature scales are divided by G, so in model
    /// space the part layout spans G times NAP's max-abs range (module documentation). 1 =
    /// NAP's scaling.
    pub layout_gain: f64,
    /// Code gain G_z: the 128 shape-code channels' feature scales are divided by G_z, so the
    /// codes span G_z times NAP's max-abs range in model space (module documentation). 1 =
    /// NAP's scaling.
    pub code_gain: f64,
    /// Shards each step's batch is split into: their forward and backward passes run in
    /// parallel on the rayon pool and their gradients are summed (see the module documentation).
    pub batch_shards: usize,
    /// Where the optimiser steps run.
    pub compute: Compute,
}

impl DiffusionTrainConfig {
    /// Whether any per-sample loss weighting is on.
    pub fn weighted(&self) -> bool {
        self.min_snr_gamma > 0.0 || self.high_noise_cap > 1.0
    }

    /// The loss weight of a sample at noise coefficients `(√ᾱ_t, √(1 − ᾱ_t))`, with
    /// `SNR = ᾱ_t / (1 − ᾱ_t)`: `min(1, γ / SNR)` when min-SNR weighting is on, times
    /// `clamp(1 / SNR, 1, cap)` when the high-noise cap is on; 1 with both off.
    pub fn loss_weight(&self, sqrt_alpha_bar: f64, sqrt_one_minus: f64) -> f64 {
        let snr = (sqrt_alpha_bar * sqrt_alpha_bar) / (sqrt_one_minus * sqrt_one_minus).max(1e-20);
        let mut w = 1.0;
        if self.min_snr_gamma > 0.0 {
            w *= (self.min_snr_gamma / snr).min(1.0);
        }
        if self.high_noise_cap > 1.0 {
            w *= (1.0 / snr.max(1e-20)).clamp(1.0, self.high_noise_cap);
        }
        w
    }

    /// The learning rate of step `step` (0-based); see the module documentation.
    pub fn lr_at(&self, step: usize) -> f64 {
        if step < self.lr_decay_start || self.steps <= self.lr_decay_start + 1 {
            return self.lr;
        }
        let span = (self.steps - 1 - self.lr_decay_start) as f64;
        let x = ((step - self.lr_decay_start) as f64 / span).min(1.0);
        let f = self.lr_final_factor;
        self.lr * (f + (1.0 - f) * 0.5 * (1.0 + (std::f64::consts::PI * x).cos()))
    }
}

impl Default for DiffusionTrainConfig {
    fn default() -> Self {
        DiffusionTrainConfig {
            model: DenoiserConfig::default(),
            steps: 20_000,
            batch_objects: 32,
            noise_levels: 4,
            lr: 2e-4,
            seed: 12345,
            category_dropout: DEFAULT_CATEGORY_DROPOUT,
            checkpoint_every: 1000,
            lr_decay_start: 0,
            lr_final_factor: 0.1,
            ema_decay: 0.999,
            stop_at: None,
            min_snr_gamma: 0.0,
            high_noise_cap: 1.0,
            overlap_weight: 0.0,
            overlap_max_t: DEFAULT_OVERLAP_MAX_T,
            layout_gain: DEFAULT_LAYOUT_GAIN,
            code_gain: DEFAULT_CODE_GAIN,
            batch_shards: 2,
            compute: Compute::Cpu,
        }
    }
}

/// Default share of training samples that see the "no category" row.
pub const DEFAULT_CATEGORY_DROPOUT: f64 = 0.2;

/// Default `layout_gain`: NAP's max-abs scaling, unchanged.
pub const DEFAULT_LAYOUT_GAIN: f64 = 1.0;
/// Smallest accepted `layout_gain` and `code_gain`.
pub const MIN_GAIN: f64 = 0.25;
/// Largest accepted `layout_gain` and `code_gain`.
pub const MAX_GAIN: f64 = 8.0;

/// The accepted gains, as a config error states them.
const GAIN_LIMIT: &str = "within [0.25, 8] (1 = NAP's scaling)";

/// Default `code_gain`: NAP's max-abs scaling, unchanged.
pub const DEFAULT_CODE_GAIN: f64 = 1.0;

/// Default `overlap_max_t`.
pub const DEFAULT_OVERLAP_MAX_T: usize = 300;
/// Largest `overlap_max_t`: beyond it x̂₀ = (x_t − √(1 − ᾱ_t) ε̂) / √ᾱ_t amplifies the
/// prediction's error more than 4×, and the penalty swamps the ε-loss (a tiny run counting
/// every t did not learn: its loss rose from ≈ 620 to ≈ 950 over 60 steps).
pub const MAX_OVERLAP_T: usize = 500;

/// One progress report.
#[derive(Debug, Clone)]
pub struct DiffusionProgress {
    /// Steps done.
    pub step: usize,
    /// Steps planned.
    pub total: usize,
    /// Loss of this step.
    pub loss: f64,
    /// Exponential moving average of the loss.
    pub loss_ema: f64,
    /// Seconds since the start of this run.
    pub elapsed: f64,
}

/// The training set in memory: raw graphs (codes filled in) and category indices.
pub struct DiffusionData {
    /// Raw (unscaled) training graphs, real nodes first.
    pub graphs: Vec<GraphTensor>,
    /// Category index per graph.
    pub categories: Vec<usize>,
    /// Feature scales fitted on the training split and the whole codebook.
    pub scales: FeatureScales,
}

fn data_err(path: &Path, detail: impl Into<String>) -> TrainError {
    TrainError::data(path, detail)
}

fn read_json(path: &Path) -> Result<Value, TrainError> {
    let text = std::fs::read_to_string(path).map_err(|e| data_err(path, e.to_string()))?;
    serde_json::from_str(&text).map_err(|e| data_err(path, e.to_string()))
}

/// Load the training split with latent codes from the shape prior's codebook
/// (`shape/codebook.npy` + `shape/codebook.json`).
pub fn load_data(data: &Path, shape: &Path) -> Result<DiffusionData, TrainError> {
    load_split(data, shape, "train")
}

/// Load one split (`train`, `val` or `test`) with its latent codes, as [`load_data`] does for
/// the training split. The feature scales are always fitted on that split's graphs and the
/// whole codebook; callers measuring a trained model use the manifest's scales instead.
pub fn load_split(data: &Path, shape: &Path, split: &str) -> Result<DiffusionData, TrainError> {
    let index = read_json(&data.join("dataset.json"))?;
    let book = super::shape::read_codebook(shape, crate::object::LATENT_DIM)?;
    let (cols, codes) = (book.cols, &book.codes);
    let keys: Vec<String> = book
        .keys
        .iter()
        .map(|k| {
            k["key"]
                .as_str()
                .or(k.as_str())
                .unwrap_or_default()
                .to_string()
        })
        .collect();
    let code_of: std::collections::HashMap<&str, &[f32]> = keys
        .iter()
        .enumerate()
        .map(|(i, k)| (k.as_str(), &codes[i * cols..(i + 1) * cols]))
        .collect();
    let mut graphs = Vec::new();
    let mut categories = Vec::new();
    for o in index["objects"].as_array().into_iter().flatten() {
        if o["split"] != split {
            continue;
        }
        let id = o["id"].as_str().unwrap_or_default();
        let path = data.join("objects").join(id).join("graph.npy");
        let (_, _, flat) = npy::read(&path).map_err(|e| data_err(&path, e.to_string()))?;
        let mut g = GraphTensor::from_flat(&flat).map_err(|e| data_err(&path, e.to_string()))?;
        for k in 0..K {
            if g.node(k)[node_ch::EXIST] < 0.5 {
                continue;
            }
            let key = format!("{id}_{k}");
            let code = code_of.get(key.as_str()).ok_or_else(|| {
                data_err(
                    &shape.join("codebook.json"),
                    format!("no code for part {key}"),
                )
            })?;
            g.node_mut(k)[node_ch::LATENT..].copy_from_slice(code);
        }
        graphs.push(g);
        categories.push(o["category_index"].as_u64().unwrap_or(0) as usize);
    }
    if graphs.is_empty() {
        return Err(data_err(
            &data.join("dataset.json"),
            format!("no {split} objects"),
        ));
    }
    let scales = FeatureScales::fit(&graphs, codes.chunks_exact(cols));
    Ok(DiffusionData {
        graphs,
        categories,
        scales,
    })
}

/// NAP's grouped loss on (prediction, target) pairs: without weights, the batch mean clamped
/// to [−100, 100] as NAP does (a guard: beyond it the gradient is zero). With per-sample
/// weights (`[B]`), the guard clamps each sample's unweighted loss and the weighted losses are
/// averaged, so a large weight cannot push the mean into the clamp and zero the gradient of
/// the whole batch (the first `--high-noise-cap 100` run lost its training that way).
pub fn grouped_loss(
    pred_v: Tensor<3>,
    pred_e: Tensor<3>,
    eps_v: Tensor<3>,
    eps_e: Tensor<3>,
    weights: Option<Tensor<1>>,
) -> Tensor<1> {
    let per_sample = grouped_loss_per_sample(pred_v, pred_e, eps_v, eps_e);
    match weights {
        Some(w) => (per_sample.clamp(-100.0, 100.0) * w).mean(),
        None => per_sample.mean().clamp(-100.0, 100.0),
    }
}

/// NAP's grouped loss of each sample of the batch, `[B]` (not clamped).
pub fn grouped_loss_per_sample(
    pred_v: Tensor<3>,
    pred_e: Tensor<3>,
    eps_v: Tensor<3>,
    eps_e: Tensor<3>,
) -> Tensor<1> {
    let b = pred_v.dims()[0];
    let ev = (pred_v - eps_v).powi_scalar(2).mean_dim(1); // [B, 1, 135]
    let ee = (pred_e - eps_e).powi_scalar(2).mean_dim(1); // [B, 1, 13]
    let group = |x: &Tensor<3>, a: usize, b: usize| x.clone().narrow(2, a, b - a).mean_dim(2);
    let node = (group(&ev, node_ch::EXIST, node_ch::BOX)
        + group(&ev, node_ch::BOX, node_ch::CENTER)
        + group(&ev, node_ch::CENTER, node_ch::LATENT)
        + group(&ev, node_ch::LATENT, NODE_DIM))
        / 4.0;
    let edge = group(&ee, edge_ch::CLASS, edge_ch::DIR)
        + group(&ee, edge_ch::DIR, edge_ch::REVOLUTE)
        + group(&ee, edge_ch::REVOLUTE, EDGE_DIM);
    (node + edge).reshape([b])
}

/// Intersection depth of two parts' boxes, from their raw (unscaled) node rows: the smallest
/// per-axis overlap of `[t − |b|, t + |b|]`; > 0 intersecting, ≤ 0 a gap (module
/// documentation).
pub fn box_depth(a: &[f32], b: &[f32]) -> f32 {
    (0..3)
        .map(|k| {
            let (ca, ha) = (a[node_ch::CENTER + k], a[node_ch::BOX + k].abs());
            let (cb, hb) = (b[node_ch::CENTER + k], b[node_ch::BOX + k].abs());
            (ca + ha).min(cb + hb) - (ca - ha).max(cb - hb)
        })
        .fold(f32::INFINITY, f32::min)
}

/// The penalty's per-pair targets of one raw graph, each `K × K` row-major: max(0, d(i, j))
/// and the mask of the pairs i < j whose parts both exist.
fn pair_targets(raw: &GraphTensor) -> (Vec<f32>, Vec<f32>) {
    let mut depth = vec![0.0f32; K * K];
    let mut mask = vec![0.0f32; K * K];
    let exists = |i: usize| raw.node(i)[node_ch::EXIST] > 0.5;
    for i in 0..K {
        for j in i + 1..K {
            if exists(i) && exists(j) {
                depth[i * K + j] = box_depth(raw.node(i), raw.node(j)).max(0.0);
                mask[i * K + j] = 1.0;
            }
        }
    }
    (depth, mask)
}

/// The box-overlap penalty's targets for a batch of `B` samples.
#[derive(Clone)]
pub struct OverlapBatch {
    /// √ᾱ_t, `[B, 1, 1]`.
    pub sqrt_alpha_bar: Tensor<3>,
    /// √(1 − ᾱ_t), `[B, 1, 1]`.
    pub sqrt_one_minus: Tensor<3>,
    /// max(0, d(i, j)) of x₀, `[B, K, K]`.
    pub depth: Tensor<3>,
    /// 1 for the pairs that count (i < j, both exist in x₀, t < `overlap_max_t`), `[B, K, K]`.
    pub mask: Tensor<3>,
    /// Box and centre channel scales (model → object units), `[1, 1, 6]`.
    pub scales: Tensor<3>,
    /// λ.
    pub weight: f32,
}

impl OverlapBatch {
    fn slice(&self, start: usize, len: usize) -> OverlapBatch {
        OverlapBatch {
            sqrt_alpha_bar: self.sqrt_alpha_bar.clone().narrow(0, start, len),
            sqrt_one_minus: self.sqrt_one_minus.clone().narrow(0, start, len),
            depth: self.depth.clone().narrow(0, start, len),
            mask: self.mask.clone().narrow(0, start, len),
            scales: self.scales.clone(),
            weight: self.weight,
        }
    }
}

/// L_overlap (module documentation) of a batch: x̂₀'s boxes from the noised nodes `vt` and the
/// predicted noise `pred_v` (both `[B, K, NODE_DIM]`, model space), summed over the counted
/// pairs, averaged over the `B` samples and weighted by λ. `[1]`.
pub fn box_overlap_penalty(vt: Tensor<3>, pred_v: Tensor<3>, o: &OverlapBatch) -> Tensor<1> {
    let [b, k, _] = vt.dims();
    let boxes = |x: Tensor<3>| x.narrow(2, node_ch::BOX, node_ch::LATENT - node_ch::BOX);
    let x0 = (boxes(vt) - boxes(pred_v) * o.sqrt_one_minus.clone()) / o.sqrt_alpha_bar.clone()
        * o.scales.clone();
    let half = x0.clone().narrow(2, 0, 3).abs();
    let centre = x0.narrow(2, 3, 3);
    let (lo, hi) = (centre.clone() - half.clone(), centre + half);
    // [B, K, K, 3]: row i's box against column j's.
    let rows = |x: Tensor<3>| x.unsqueeze_dim::<4>(2).repeat_dim(2, k);
    let cols = |x: Tensor<3>| x.unsqueeze_dim::<4>(1).repeat_dim(1, k);
    let overlap = rows(hi.clone()).min_pair(cols(hi)) - rows(lo.clone()).max_pair(cols(lo));
    let depth = overlap.min_dim(3).reshape([b, k, k]);
    let excess = (depth - o.depth.clone()).clamp_min(0.0);
    (excess.powi_scalar(2) * o.mask.clone())
        .sum()
        .mul_scalar(o.weight / b as f32)
}

/// One step's noised batch: inputs, targets and per-sample loss weights.
struct ShardBatch {
    vt: Tensor<3>,
    et: Tensor<3>,
    t: Tensor<1, Int>,
    category: Option<Tensor<1, Int>>,
    eps_v: Tensor<3>,
    eps_e: Tensor<3>,
    weights: Option<Tensor<1>>,
    overlap: Option<OverlapBatch>,
}

impl ShardBatch {
    /// Samples `start..start + len` of the batch.
    fn slice(&self, start: usize, len: usize) -> ShardBatch {
        ShardBatch {
            vt: self.vt.clone().narrow(0, start, len),
            et: self.et.clone().narrow(0, start, len),
            t: self.t.clone().narrow(0, start, len),
            category: self
                .category
                .as_ref()
                .map(|c| c.clone().narrow(0, start, len)),
            eps_v: self.eps_v.clone().narrow(0, start, len),
            eps_e: self.eps_e.clone().narrow(0, start, len),
            weights: self
                .weights
                .as_ref()
                .map(|w| w.clone().narrow(0, start, len)),
            overlap: self.overlap.as_ref().map(|o| o.slice(start, len)),
        }
    }
}

/// The batch's loss and its gradients, computed in `shards` contiguous slices of (nearly)
/// equal size. Each slice runs on its own fork of the model (fresh autodiff leaves, the same
/// parameter ids, so the slices' graphs never merge under burn's one-mutex-per-graph client)
/// and in parallel on the rayon pool; its loss is weighted by its share of the batch, so the
/// sum of the slices' losses and gradients is the whole batch's mean loss and its gradient, up
/// to float rounding. The gradients are summed in slice order whatever the thread timing, so
/// a run is deterministic for a given `shards` on any number of threads. The loss guard
/// clamps each slice's mean instead of the batch's (it never bites in practice: |L| ≪ 100).
fn sharded_step(
    model: &Denoiser,
    batch: ShardBatch,
    shards: usize,
    device: &burn::tensor::Device,
) -> (f64, GradientsParams) {
    use rayon::prelude::*;
    let bsz = batch.vt.dims()[0];
    let shards = shards.clamp(1, bsz);
    let run = |m: &Denoiser, b: ShardBatch, share: Option<f32>| {
        let (pv, pe) = m.forward(b.vt.clone(), b.et, b.t, b.category);
        let overlap = b
            .overlap
            .as_ref()
            .map(|o| box_overlap_penalty(b.vt, pv.clone(), o));
        let mut loss = grouped_loss(pv, pe, b.eps_v, b.eps_e, b.weights);
        if let Some(overlap) = overlap {
            loss = loss + overlap;
        }
        if let Some(share) = share {
            loss = loss * share;
        }
        let value: f64 = loss
            .clone()
            .into_data()
            .try_to_vec::<f32>()
            .map(|v| v[0] as f64)
            .unwrap_or(f64::NAN);
        (value, GradientsParams::from_grads(loss.backward(), m))
    };
    if shards == 1 {
        return run(model, batch, None);
    }
    let parts: Vec<(Denoiser, ShardBatch, f32)> = (0..shards)
        .map(|k| {
            let (start, end) = (k * bsz / shards, (k + 1) * bsz / shards);
            (
                model.clone().fork(device),
                batch.slice(start, end - start),
                (end - start) as f32 / bsz as f32,
            )
        })
        .collect();
    let results: Vec<(f64, GradientsParams)> = parts
        .into_par_iter()
        .map(|(m, b, share)| run(&m, b, Some(share)))
        .collect();
    super::sum_slices(model, results)
}

/// What the run did.
#[derive(Debug, Clone)]
pub struct DiffusionTrainReport {
    /// Steps completed in total (including resumed ones).
    pub steps: usize,
    /// Wall time of this run (seconds).
    pub wall_seconds: f64,
    /// Wall time of this run and every run it resumed, as far as their checkpoints recorded it.
    pub wall_seconds_total: f64,
    /// Final loss EMA.
    pub final_loss: f64,
    /// The weights file.
    pub weights: PathBuf,
    /// sha256 of the weights file.
    pub sha256: String,
    /// The feature scales the run trained in (the data's, with `layout_gain` applied): what the
    /// manifest must record.
    pub scales: FeatureScales,
}

/// Standard-normal noise for a batch of `b` graphs, nodes first then edges, drawn from `rng`.
pub fn graph_noise(
    rng: &mut Rng,
    b: usize,
    device: &burn::tensor::Device,
) -> (Tensor<3>, Tensor<3>) {
    let mut randn = |dims: [usize; 3]| {
        let n = dims.iter().product();
        let v: Vec<f32> = (0..n).map(|_| rng.gauss() as f32).collect();
        Tensor::<3>::from_data(TensorData::new(v, dims), device)
    };
    let v = randn([b, K, NODE_DIM]);
    (v, randn([b, NUM_EDGES, EDGE_DIM]))
}

/// A uniformly random order of the K node slots (Fisher–Yates), the permutation each training
/// object gets (method.md §1.6) and `eval denoiser` draws the same way.
pub(crate) fn random_slots(rng: &mut Rng) -> [usize; K] {
    let mut perm: [usize; K] = std::array::from_fn(|i| i);
    for i in (1..K).rev() {
        perm.swap(i, rng.int(0, i));
    }
    perm
}

/// Refuse to resume a run whose recorded feature scales (`diffusion_train.json`, when there
/// is one) differ from this run's: another codebook, data set or `layout_gain` would put the
/// same weights in another model space. A run directory without the record resumes.
fn check_resumed_scales(record: &Path, scales: &FeatureScales) -> Result<(), TrainError> {
    if !record.is_file() {
        return Ok(());
    }
    let doc = read_json(record)?;
    for (name, now) in [("node", &scales.node), ("edge", &scales.edge)] {
        let Some(was) = doc["feature_scales"][name].as_array() else {
            continue;
        };
        let was: Vec<f32> = was
            .iter()
            .map(|v| v.as_f64().unwrap_or(f64::NAN) as f32)
            .collect();
        if let Some(k) = (0..now.len()).find(|&k| was.get(k) != Some(&now[k])) {
            return Err(TrainError::Config(crate::error::Invalid {
                field: format!("feature_scales.{name}[{k}]"),
                limit: format!(
                    "the resumed run's {} (recorded in {}, layout_gain {}, code_gain {}): resume \
                     with the same codebook, data, --layout-gain and --code-gain",
                    was.get(k).map_or("absent".into(), |v| v.to_string()),
                    record.display(),
                    doc["layout_gain"].as_f64().unwrap_or(DEFAULT_LAYOUT_GAIN),
                    doc["code_gain"].as_f64().unwrap_or(DEFAULT_CODE_GAIN)
                ),
                value: now[k].to_string(),
            }));
        }
    }
    Ok(())
}

/// Train (or resume training) the denoiser; writes `denoiser.safetensors`, `checkpoint.json`
/// and `diffusion_train.json` into `out`.
pub fn train_diffusion(
    data: &DiffusionData,
    cfg: &DiffusionTrainConfig,
    out: &Path,
    resume: bool,
    progress: &mut dyn FnMut(&DiffusionProgress),
) -> Result<DiffusionTrainReport, TrainError> {
    cfg.model.validate()?;
    for (field, ok, limit, value) in [
        ("steps", cfg.steps >= 1, "at least 1", cfg.steps.to_string()),
        (
            "batch_objects",
            cfg.batch_objects >= 1,
            "at least 1",
            cfg.batch_objects.to_string(),
        ),
        (
            "noise_levels",
            cfg.noise_levels >= 1,
            "at least 1",
            cfg.noise_levels.to_string(),
        ),
        (
            "lr",
            cfg.lr > 0.0 && cfg.lr.is_finite(),
            "> 0",
            cfg.lr.to_string(),
        ),
        (
            "category_dropout",
            (0.0..=1.0).contains(&cfg.category_dropout),
            "within [0, 1]",
            cfg.category_dropout.to_string(),
        ),
        (
            "lr_final_factor",
            cfg.lr_final_factor > 0.0 && cfg.lr_final_factor <= 1.0,
            "within (0, 1]",
            cfg.lr_final_factor.to_string(),
        ),
        (
            "ema_decay",
            (0.0..1.0).contains(&cfg.ema_decay),
            "within [0, 1)",
            cfg.ema_decay.to_string(),
        ),
        (
            "min_snr_gamma",
            cfg.min_snr_gamma >= 0.0 && cfg.min_snr_gamma.is_finite(),
            ">= 0 and finite (0 = off)",
            cfg.min_snr_gamma.to_string(),
        ),
        (
            "high_noise_cap",
            cfg.high_noise_cap.is_finite() && cfg.high_noise_cap <= 1e6,
            "finite and at most 1e6 (1 or less = off)",
            cfg.high_noise_cap.to_string(),
        ),
        (
            "overlap_weight",
            cfg.overlap_weight >= 0.0 && cfg.overlap_weight <= 1e6,
            "within [0, 1e6] (0 = off)",
            cfg.overlap_weight.to_string(),
        ),
        (
            "overlap_max_t",
            (1..=MAX_OVERLAP_T).contains(&cfg.overlap_max_t),
            "within 1..=500 (x̂₀ divides by √ᾱ_t, which falls below 0.24 past t = 500)",
            cfg.overlap_max_t.to_string(),
        ),
        (
            "layout_gain",
            (MIN_GAIN..=MAX_GAIN).contains(&cfg.layout_gain),
            GAIN_LIMIT,
            cfg.layout_gain.to_string(),
        ),
        (
            "code_gain",
            (MIN_GAIN..=MAX_GAIN).contains(&cfg.code_gain),
            GAIN_LIMIT,
            cfg.code_gain.to_string(),
        ),
        (
            "batch_shards",
            (1..=cfg.batch_objects * cfg.noise_levels).contains(&cfg.batch_shards),
            "within 1..=batch_objects × noise_levels",
            cfg.batch_shards.to_string(),
        ),
        (
            "stop_at",
            cfg.stop_at.is_none_or(|s| (1..=cfg.steps).contains(&s)),
            "within 1..=steps",
            format!("{:?}", cfg.stop_at),
        ),
    ] {
        if !ok {
            return Err(TrainError::Config(crate::error::Invalid {
                field: field.into(),
                limit: limit.into(),
                value,
            }));
        }
    }
    let scales = data
        .scales
        .with_layout_gain(cfg.layout_gain as f32)
        .with_code_gain(cfg.code_gain as f32);
    std::fs::create_dir_all(out).map_err(|e| data_err(out, e.to_string()))?;
    let device = cfg.compute.autodiff();
    let schedule = Schedule::default();
    let mut model = Denoiser::new(&cfg.model, &device)?;
    let weights_path = out.join("denoiser.safetensors");
    let raw_path = out.join("denoiser_raw.safetensors");
    let ckpt_path = out.join("checkpoint.json");
    let mut start = 0usize;
    let mut shadow: Option<Ema> = None;
    // Wall time and loss EMA of the runs this one resumes (absent in older checkpoints).
    let mut prior_wall = 0.0f64;
    let mut ema = f64::NAN;
    if resume && ckpt_path.is_file() {
        check_resumed_scales(&out.join("diffusion_train.json"), &scales)?;
        let ck = read_json(&ckpt_path)?;
        start = ck["step"].as_u64().unwrap_or(0) as usize;
        prior_wall = ck["wall_seconds_total"].as_f64().unwrap_or(0.0);
        ema = ck["loss_ema"].as_f64().unwrap_or(f64::NAN);
        match ck["raw_sha256"].as_str() {
            Some(raw_sha) if raw_path.is_file() => {
                weights::load(&mut model, &raw_path, Some(raw_sha))?;
                let mut ema_model = Denoiser::new(&cfg.model, &device)?;
                weights::load(&mut ema_model, &weights_path, ck["sha256"].as_str())?;
                let ema_steps = ck["ema_steps"].as_u64().unwrap_or(0) as usize;
                shadow = Some(Ema::new(&ema_model, cfg.ema_decay, ema_steps));
            }
            _ => weights::load(&mut model, &weights_path, ck["sha256"].as_str())?,
        }
    }
    if cfg.ema_decay > 0.0 && shadow.is_none() {
        shadow = Some(Ema::new(&model, cfg.ema_decay, 0));
    }
    if cfg.ema_decay == 0.0 {
        shadow = None;
    }
    let mut optim = AdamConfig::new().init();
    let t0 = Instant::now();
    let no_category = cfg.model.categories;
    let bsz = cfg.batch_objects * cfg.noise_levels;
    let mut sha = String::new();
    let end = cfg.stop_at.unwrap_or(cfg.steps);
    for step in start..end {
        let mut rng = Rng::fork(cfg.seed, step as u64);
        let mut x0 = Vec::with_capacity(bsz);
        let mut ts = Vec::with_capacity(bsz);
        let mut cats = Vec::with_capacity(bsz);
        let overlap_on = cfg.overlap_weight > 0.0;
        let (mut depth, mut mask) = (Vec::new(), Vec::new());
        for _ in 0..cfg.batch_objects {
            let k = rng.int(0, data.graphs.len() - 1);
            let raw = data.graphs[k]
                .permuted(&random_slots(&mut rng))
                .map_err(TrainError::Core)?;
            let pairs = overlap_on.then(|| pair_targets(&raw));
            let g = raw.scaled(&scales);
            for _ in 0..cfg.noise_levels {
                x0.push(g.clone());
                let t = rng.int(0, schedule.len() - 1);
                ts.push(t);
                if let Some((d, m)) = &pairs {
                    depth.extend_from_slice(d);
                    let on = if t < cfg.overlap_max_t { 1.0 } else { 0.0 };
                    mask.extend(m.iter().map(|v| v * on));
                }
                cats.push(if no_category == 0 || rng.chance(cfg.category_dropout) {
                    no_category
                } else {
                    data.categories[k]
                });
            }
        }
        let (v0, e0) = crate::engine::to_tensors(&x0, &device);
        let (eps_v, eps_e) = graph_noise(&mut rng, bsz, &device);
        let (sa, sb): (Vec<f32>, Vec<f32>) = ts
            .iter()
            .map(|&t| {
                let (a, b) = schedule.noise_coefficients(t);
                (a as f32, b as f32)
            })
            .unzip();
        let weights = cfg.weighted().then(|| {
            let w: Vec<f32> = sa
                .iter()
                .zip(&sb)
                .map(|(&a, &b)| cfg.loss_weight(a as f64, b as f64) as f32)
                .collect();
            Tensor::<1>::from_data(TensorData::new(w, [bsz]), &device)
        });
        let sa = Tensor::<3>::from_data(TensorData::new(sa, [bsz, 1, 1]), &device);
        let sb = Tensor::<3>::from_data(TensorData::new(sb, [bsz, 1, 1]), &device);
        let overlap = overlap_on.then(|| {
            let pairs =
                |v: Vec<f32>| Tensor::<3>::from_data(TensorData::new(v, [bsz, K, K]), &device);
            OverlapBatch {
                sqrt_alpha_bar: sa.clone(),
                sqrt_one_minus: sb.clone(),
                depth: pairs(std::mem::take(&mut depth)),
                mask: pairs(std::mem::take(&mut mask)),
                scales: Tensor::<3>::from_data(
                    TensorData::new(
                        scales.node[node_ch::BOX..node_ch::LATENT].to_vec(),
                        [1, 1, node_ch::LATENT - node_ch::BOX],
                    ),
                    &device,
                ),
                weight: cfg.overlap_weight as f32,
            }
        });
        let vt = v0 * sa.clone() + eps_v.clone() * sb.clone();
        let et = e0 * sa + eps_e.clone() * sb;
        let t = Tensor::<1, Int>::from_data(
            TensorData::new(ts.iter().map(|&t| t as i64).collect::<Vec<_>>(), [bsz]),
            &device,
        );
        let category = (no_category > 0).then(|| {
            Tensor::<1, Int>::from_data(
                TensorData::new(cats.iter().map(|&c| c as i64).collect::<Vec<_>>(), [bsz]),
                &device,
            )
        });
        let batch = ShardBatch {
            vt,
            et,
            t,
            category,
            eps_v,
            eps_e,
            weights,
            overlap,
        };
        let (value, grads) = sharded_step(&model, batch, cfg.batch_shards, &device);
        if !value.is_finite() {
            return Err(TrainError::Diverged { step, loss: value });
        }
        model = optim.step(cfg.lr_at(step), model, grads);
        if let Some(shadow) = shadow.as_mut() {
            shadow.update(&model);
        }
        ema = if ema.is_nan() {
            value
        } else {
            0.99 * ema + 0.01 * value
        };
        progress(&DiffusionProgress {
            step: step + 1,
            total: cfg.steps,
            loss: value,
            loss_ema: ema,
            elapsed: t0.elapsed().as_secs_f64(),
        });
        if (cfg.checkpoint_every > 0 && (step + 1) % cfg.checkpoint_every == 0) || step + 1 == end {
            let ck = match shadow.as_ref() {
                Some(shadow) => {
                    let raw_sha = weights::save(&model.valid(), &raw_path)?;
                    let averaged = shadow.install(model.valid());
                    sha = weights::save(&averaged, &weights_path)?;
                    json!({ "step": step + 1, "sha256": sha, "raw_sha256": raw_sha,
                            "ema_steps": shadow.steps, "loss_ema": ema,
                            "wall_seconds_total": prior_wall + t0.elapsed().as_secs_f64() })
                }
                None => {
                    sha = weights::save(&model.valid(), &weights_path)?;
                    json!({ "step": step + 1, "sha256": sha, "loss_ema": ema,
                            "wall_seconds_total": prior_wall + t0.elapsed().as_secs_f64() })
                }
            };
            std::fs::write(&ckpt_path, ck.to_string())
                .map_err(|e| data_err(&ckpt_path, e.to_string()))?;
        }
    }
    if sha.is_empty() {
        // Resumed a finished run: nothing trained, report the existing weights.
        sha = weights::sha256_hex(
            &std::fs::read(&weights_path).map_err(|e| data_err(&weights_path, e.to_string()))?,
        );
    }
    let wall = t0.elapsed().as_secs_f64();
    let summary = json!({
        "steps": cfg.steps, "resumed_from": start, "completed": end.max(start),
        "wall_seconds": wall,
        "wall_seconds_total": prior_wall + wall, "final_loss_ema": ema,
        "batch_objects": cfg.batch_objects, "noise_levels": cfg.noise_levels, "lr": cfg.lr,
        "lr_decay_start": cfg.lr_decay_start, "lr_final_factor": cfg.lr_final_factor,
        "ema_decay": cfg.ema_decay, "ema_steps": shadow.as_ref().map_or(0, |e| e.steps),
        "seed": cfg.seed, "category_dropout": cfg.category_dropout,
        "min_snr_gamma": cfg.min_snr_gamma, "high_noise_cap": cfg.high_noise_cap,
        "overlap_weight": cfg.overlap_weight, "overlap_max_t": cfg.overlap_max_t,
        "batch_shards": cfg.batch_shards,
        "layout_gain": cfg.layout_gain,
        "code_gain": cfg.code_gain,
        "feature_scales": { "node": &scales.node, "edge": &scales.edge },
        "categories": CATEGORIES.to_vec(), "train_objects": data.graphs.len(), "sha256": sha,
    });
    let path = out.join("diffusion_train.json");
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&summary).unwrap_or_default(),
    )
    .map_err(|e| data_err(&path, e.to_string()))?;
    Ok(DiffusionTrainReport {
        steps: end.max(start),
        wall_seconds: wall,
        wall_seconds_total: prior_wall + wall,
        final_loss: ema,
        weights: weights_path,
        sha256: sha,
        scales,
    })
}

#[cfg(test)]
pub(crate) mod tests;
