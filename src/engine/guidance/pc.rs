//! ℓ_pc, the point-cloud alignment loss (method.md §8.4).
//!
//! ```text
//! d_ij = d(P_j, i)                      (part SDF of §8.3, all K = 8 slots, existing or not)
//! α_ij = softmax_i( −τ · d_ij² / (õ_i + ε) )      τ = 1000 (option), ε = 1e-6, õ clamped to [0, 1]
//! ℓ_pc = Σ_j Σ_i α_ij · d_ij²                     (sum over points, not mean)
//! ```
//!
//! α is not detached, so the gradient reaches the existences through it. The softmax subtracts
//! the per-point maximum (log-sum-exp stable). All K × M queries are one field call.

use burn::tensor::{Tensor, TensorData};

use super::field::{PartTensors, SdfField, part_sdf};
use super::grid::ints;

/// ε in the assignment temperature.
pub const EXIST_EPS: f32 = 1e-6;

/// ℓ_pc of the observed `points` [M, 3] (object frame) for `parts` with existences `exist` [K]
/// (clamped here). Returns a scalar tensor [1].
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
    let flat: Vec<f32> = points.iter().flatten().copied().collect();
    let p = Tensor::<2>::from_data(TensorData::new(flat, [m, 3]), &device);
    let idx: Vec<i64> = (0..k as i64)
        .flat_map(|i| std::iter::repeat_n(i, m))
        .collect();
    let idx = ints(idx, &device);
    let u = p.repeat_dim(0, k) - parts.centres.clone().select(0, idx.clone());
    let d2 = part_sdf(field, parts, idx, u)
        .reshape([k, m])
        .powi_scalar(2);
    let o = exist.clamp(0.0, 1.0).reshape([k, 1]) + EXIST_EPS;
    let logits = -(d2.clone() * tau) / o;
    // Max-subtracted (log-sum-exp stable; the shift is a constant, so the gradient is exact).
    let shifted = (logits.clone() - logits.max_dim(0).detach()).exp();
    let alpha = shifted.clone() / shifted.sum_dim(0);
    (alpha * d2).sum()
}
