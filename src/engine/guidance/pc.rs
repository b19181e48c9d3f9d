//! ℓ_pc, the point-cloud alignment loss (method.md §8.4).
//!
//! ```text
//! d_ij = d(P_j, i)                      (part SDF of §8.3, all K = 8 slots, existing or not)
//! α_ij = softmax_i( −τ · d_ij² / (õ_i + ε) )      τ = 1000 (option), ε = 1e-6, õ clamped to [0, 1]
//! ℓ_pc = Σ_j Σ_i α_ij · d_ij²                     (sum over points, not mean)
//! ```
//!
//! α is not detached, so the gradient reaches the existences through it. The softmax subtracts
//! the per-point maximum (log-sum-exp stable; the shift is a constant, so the gradient is exact).
//!
//! Speed: with τ = 1000 the assignment is nearly hard — a point's α over parts more than a few
//! centimetres further than its nearest part underflows. A pass without gradient decodes all
//! K × M pairs once (no autodiff graph); the differentiable pass decodes only the pairs whose
//! logit is within [`PRUNE_LOGIT`] of the point's best (α ≥ e^−40 ≈ 4·10⁻¹⁸ relative), and the
//! softmax sums over those (a segment sum). The dropped terms change the value and gradient by
//! a relative ≲ K·e^−40·τ/ε — below f32 resolution ([`loss_dense`] is the reference, compared in
//! the tests).

use burn::tensor::{IndexingUpdateOp, Tensor, TensorData};

use super::field::{PartTensors, SdfField, host_points, part_sdf, part_sdf_values};
use super::grid::{index_tensor, ints};

/// ε in the assignment temperature.
pub const EXIST_EPS: f32 = 1e-6;

/// Pairs whose assignment logit is more than this below the point's best are left out of the
/// differentiable pass (their α < e^−40 relative).
pub const PRUNE_LOGIT: f32 = 40.0;

/// Local coordinates of every point in every part's frame, [K·M, 3] (part-major), with the
/// part index of each row (host).
fn all_pairs(parts: &PartTensors, points: &[[f32; 3]]) -> (Tensor<2>, Vec<usize>) {
    let device = parts.boxes.device();
    let k = parts.boxes.dims()[0];
    let m = points.len();
    let flat: Vec<f32> = points.iter().flatten().copied().collect();
    let p = Tensor::<2>::from_data(TensorData::new(flat, [m, 3]), &device);
    let idx: Vec<usize> = (0..k).flat_map(|i| std::iter::repeat_n(i, m)).collect();
    let u = p.repeat_dim(0, k) - parts.centres.clone().select(0, index_tensor(&idx, &device));
    (u, idx)
}

/// ℓ_pc decoding every (part, point) pair with gradient: the reference for [`loss`].
pub fn loss_dense(
    field: &dyn SdfField,
    parts: &PartTensors,
    exist: Tensor<1>,
    points: &[[f32; 3]],
    tau: f32,
) -> Tensor<1> {
    let k = parts.boxes.dims()[0];
    let m = points.len();
    let (u, idx) = all_pairs(parts, points);
    let d2 = part_sdf(field, parts, index_tensor(&idx, &u.device()), u)
        .reshape([k, m])
        .powi_scalar(2);
    let o = exist.clamp(0.0, 1.0).reshape([k, 1]) + EXIST_EPS;
    let logits = -(d2.clone() * tau) / o;
    let shifted = (logits.clone() - logits.max_dim(0).detach()).exp();
    let alpha = shifted.clone() / shifted.sum_dim(0);
    (alpha * d2).sum()
}

/// ℓ_pc of the observed `points` [M, 3] (object frame) for `parts` with existences `exist` [K]
/// (clamped here). Returns a scalar tensor [1]. Same value and gradient as [`loss_dense`] to
/// f32 precision, decoding only the pairs that matter with gradient (module docs).
pub fn loss(
    field: &dyn SdfField,
    parts: &PartTensors,
    exist: Tensor<1>,
    points: &[[f32; 3]],
    tau: f32,
) -> Tensor<1> {
    let device = parts.boxes.device();
    let k = parts.boxes.dims()[0];
    let m = points.len();
    let (u, idx) = all_pairs(parts, points);
    // Pass 1, no gradient: every d_ij and the logits on the host.
    let host = |t: Tensor<1>| t.into_data().try_to_vec::<f32>().unwrap_or_default();
    let d = parts
        .values()
        .zip(host_points(&u))
        .map(|(values, u)| part_sdf_values(field, &values, &idx, &u))
        .unwrap_or_default();
    let o: Vec<f32> = host(exist.clone().detach().clamp(0.0, 1.0))
        .into_iter()
        .map(|o| o + EXIST_EPS)
        .collect();
    if d.len() != k * m || o.len() != k || d.iter().any(|v| !v.is_finite()) {
        // Non-finite values: let the dense reference carry them to the divergence checks.
        return loss_dense(field, parts, exist, points, tau);
    }
    let logit = |i: usize, j: usize| -(d[i * m + j] * d[i * m + j] * tau) / o[i];
    let top: Vec<f32> = (0..m)
        .map(|j| {
            (0..k)
                .map(|i| logit(i, j))
                .fold(f32::NEG_INFINITY, f32::max)
        })
        .collect();
    let (mut rows, mut owners) = (Vec::new(), Vec::new());
    for i in 0..k {
        for (j, &t) in top.iter().enumerate() {
            if logit(i, j) >= t - PRUNE_LOGIT {
                rows.push((i * m + j) as i64);
                owners.push(j);
            }
        }
    }
    // Pass 2, with gradient, on the kept pairs only.
    let n = rows.len();
    let rows = ints(rows, &device);
    let owner = ints(owners.iter().map(|&j| j as i64).collect(), &device);
    let pidx = index_tensor(&idx, &device).select(0, rows.clone());
    let d2 = part_sdf(field, parts, pidx.clone(), u.select(0, rows)).powi_scalar(2);
    let o = (exist.clamp(0.0, 1.0) + EXIST_EPS).select(0, pidx);
    let logits = -(d2.clone() * tau) / o;
    // The shift is the per-point maximum of *these* logits (not pass 1's: with õ → 0 the logits
    // reach −10⁹·d², where a last-bit difference between the two passes would overflow exp).
    let mut best = vec![f32::NEG_INFINITY; m];
    for (v, &j) in host(logits.clone().detach()).iter().zip(&owners) {
        best[j] = best[j].max(*v);
    }
    let shift =
        Tensor::<1>::from_data(TensorData::new(best, [m]), &device).select(0, owner.clone());
    let shifted = (logits - shift).exp();
    let sums = Tensor::<1>::zeros([m], &device).select_assign(
        0,
        owner.clone(),
        shifted.clone(),
        IndexingUpdateOp::Add,
    );
    debug_assert_eq!(shifted.dims(), [n]);
    let alpha = shifted / sums.select(0, owner);
    (alpha * d2).sum()
}
