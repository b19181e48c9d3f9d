//! The shape prior's loss: truncated L1 on SDF samples, code regulariser, eikonal and wrong-side
//! terms, and the host-decoder surrogate that carries the decoder's gradients.

#[allow(unused_imports)]
use super::*;
use crate::model::host_decoder::HostDecoder;
use crate::model::shape_prior::{ShapeDecoder, ShapePrior};
use burn::module::Module;
use burn::nn::Linear;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use rayon::prelude::*;

/// f̂' − clamp(f, −δ, δ), where f̂' clamps the prediction only on the side where the target was
/// clamped: beyond ±δ on the target's side costs nothing, but a prediction on the wrong side
/// of the band keeps its gradient. (Clamping both sides, DeepSDF's form, freezes a freshly
/// initialised network whose outputs start outside the band: measured, it never left a loss
/// of 0.055 and val IoU 0.03.)
pub(crate) fn truncated_residual(pred: Tensor<2>, target: Tensor<2>, delta: f32) -> Tensor<2> {
    let above = target.clone().greater_equal_elem(delta);
    let below = target.clone().lower_equal_elem(-delta);
    let pred = pred.clone().mask_where(above, pred.clamp_max(delta));
    let pred = pred.clone().mask_where(below, pred.clamp_min(-delta));
    pred - target.clamp(-delta, delta)
}

/// ∂|r|/∂pred of one query's (possibly truncated) residual, as [`truncated_residual`] and
/// burn's `abs` differentiate it: 0 where the truncation clamps the prediction, else sign(r)
/// (0 at r = 0).
pub(crate) fn l1_upstream(pred: f32, target: f32, truncation: Option<f32>) -> (f32, f32) {
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
pub(crate) fn wrong_side(pred: f32, target: f32, w: f32) -> (f32, f32) {
    if (target < 0.0 && pred > 0.0) || (target > 0.0 && pred < 0.0) {
        (w * pred.abs(), w * pred.signum())
    } else {
        (0.0, 0.0)
    }
}

/// The linear layers of `decoder` in the order of `WeightGrads::layers`
/// ([`HostDecoder::weight_grads`]).
pub(crate) fn decoder_linears(decoder: &ShapeDecoder) -> Vec<&Linear> {
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
pub(crate) struct Eikonal {
    /// w · mean over the chosen rows of (|∇̃f| − 1)².
    pub(crate) value: f64,
    /// The shifted probes q + h·e_k (three per chosen row), normalised frame.
    pub(crate) probes: Vec<[f32; 3]>,
    /// Their part indices.
    pub(crate) probe_idx: Vec<usize>,
    /// ∂(term)/∂f at each probe.
    pub(crate) probe_upstream: Vec<f32>,
    /// ∂(term)/∂f at each row of the batch (0 for rows not chosen).
    pub(crate) base_upstream: Vec<f32>,
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
pub(crate) fn eikonal_term(
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
pub(crate) fn host_decoder_surrogate(
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
pub(crate) fn batch_loss(
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
pub(crate) fn sharded_loss(
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
    crate::train::sum_slices(model, results)
}
