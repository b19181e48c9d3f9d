//! ℓ_pen, the penetration loss at rest (method.md §8.5, sign per §9 A1).
//!
//! ```text
//! for ordered pairs (i, i'), i ≠ i':  I = [t−b, t+b] ∩ [t'−b', t'+b'],  grid q_a in I (grid.rs)
//! ψ_a = ½ · max(0, −(d(q_a, i) + d(q_a, i')))²              (SDF negative inside: overlap > 0)
//! ℓ_pen = Σ_(i,i') õ_i õ_i' · V_el(i, i') · Σ_a ψ_a         V_el = 10⁵ · Π e_k / n_k, N* = 1000
//! ```
//!
//! Everything in the sum is symmetric in (i, i'), so each unordered pair is evaluated once and
//! counted twice. Skipped (exact zero contribution, or negligible): pairs whose boxes do not
//! intersect, and pairs with õ_i õ_i' < [`MIN_EXIST_PRODUCT`] (õ clamped to [0, 1]). All grid
//! points of all remaining pairs, for both parts, are one field call without gradient; the
//! differentiable call decodes only the points where the parts overlap (`overlap_energy`).

use burn::tensor::Tensor;

use super::HostParts;
use super::field::{PartTensors, SdfField, overlap_energy};
use super::grid::{GridBatch, axis_counts, index_tensor, ints};
use crate::graph::EDGE_PAIRS;

/// Pairs whose existence product is below this are skipped.
pub const MIN_EXIST_PRODUCT: f32 = 1e-4;

/// Box intersection [lo, hi] extents on the host.
fn intersection(host: &HostParts, i: usize, j: usize) -> [f32; 3] {
    std::array::from_fn(|k| {
        let lo = (host.centres[i][k] - host.boxes[i][k]).max(host.centres[j][k] - host.boxes[j][k]);
        let hi = (host.centres[i][k] + host.boxes[i][k]).min(host.centres[j][k] + host.boxes[j][k]);
        (hi - lo).max(0.0)
    })
}

/// The pairs (i < j) that contribute, with their grid counts.
pub fn active_pairs(host: &HostParts) -> Vec<(usize, usize, [usize; 3])> {
    EDGE_PAIRS
        .iter()
        .filter(|&&(i, j)| host.exist[i] * host.exist[j] >= MIN_EXIST_PRODUCT)
        .filter_map(|&(i, j)| axis_counts(intersection(host, i, j)).map(|n| (i, j, n)))
        .collect()
}

/// ℓ_pen weighted by `exist` [K] (clamped here), or None when no pair contributes. With
/// `exist` all ones this is the unweighted E_pen of method.md §8.8.
pub fn loss(
    field: &dyn SdfField,
    parts: &PartTensors,
    exist: Tensor<1>,
    host: &HostParts,
) -> Option<Tensor<1>> {
    let pairs = active_pairs(host);
    if pairs.is_empty() {
        return None;
    }
    let device = parts.boxes.device();
    let mut grid = GridBatch::default();
    for &(_, _, n) in &pairs {
        grid.push(n);
    }
    let pi = ints(pairs.iter().map(|p| p.0 as i64).collect(), &device);
    let pj = ints(pairs.iter().map(|p| p.1 as i64).collect(), &device);
    let (ci, cj) = (
        parts.centres.clone().select(0, pi.clone()),
        parts.centres.clone().select(0, pj.clone()),
    );
    let (bi, bj) = (
        parts.boxes.clone().select(0, pi.clone()),
        parts.boxes.clone().select(0, pj.clone()),
    );
    let lo = (ci.clone() - bi.clone()).max_pair(cj.clone() - bj.clone());
    let hi = (ci + bi).min_pair(cj + bj);
    let ext = (hi - lo.clone()).clamp_min(0.0);
    let (q, vel) = grid.points(lo, ext, &device);
    let owner = grid.owner_tensor(&device);
    let qi: Vec<usize> = grid.owner.iter().map(|&a| pairs[a as usize].0).collect();
    let qj: Vec<usize> = grid.owner.iter().map(|&a| pairs[a as usize].1).collect();
    let idx = [qi, qj].concat();
    let u = q.repeat_dim(0, 2) - parts.centres.clone().select(0, index_tensor(&idx, &device));
    let o = exist.clamp(0.0, 1.0);
    let weight = o.clone().select(0, pi) * o.select(0, pj) * vel * 2.0;
    overlap_energy(field, parts, &idx, u, weight.select(0, owner))
}
