//! ℓ_free, the free-space loss (real-scans.md §5; physnap, not in the paper).
//!
//! ```text
//! q_k: the free-space samples of the scan's cameras (engine::free_space)
//! ℓ_free = (M / Q) · Σ_k Σ_i õ_i · relu(δ − d(q_k, i))²       δ = ½ m, M points, Q samples
//! ```
//!
//! d is ℓ_pc's part SDF (field.rs), so the term is differentiable in the boxes, centres, codes
//! and, through õ, the existences: a part that fills space the camera saw through is pushed
//! out of it, shrunk, or faded. The M / Q factor puts the term on ℓ_pc's per-point scale, so a
//! weight means the same for any number of rays.
//!
//! Speed: most (sample, part) pairs are far outside the part's box, where d is at least the box
//! distance, beyond δ, and contributes exactly 0. Pairs within δ of the box are decoded once
//! without gradient; the differentiable pass decodes only those with d below δ.

use burn::tensor::Tensor;

use super::HostParts;
use super::field::{PartTensors, SdfField, part_sdf, part_sdf_values};
use super::grid::index_tensor;

/// Parts with õ below this are skipped (their contribution is negligible).
pub const MIN_EXIST: f32 = 1e-4;

/// ℓ_free of the free-space `samples` for `parts` with existences `exist` [K] (clamped here),
/// `m` observed points (the M / Q scale) and margin `delta`; None when no sample is within
/// `delta` of a part.
pub fn loss(
    field: &dyn SdfField,
    parts: &PartTensors,
    exist: Tensor<1>,
    host: &HostParts,
    samples: &[[f32; 3]],
    m: usize,
    delta: f32,
) -> Option<Tensor<1>> {
    if samples.is_empty() {
        return None;
    }
    let values = parts.values()?;
    let k = host.boxes.len();
    // Candidate pairs: the sample within δ of the part's box (box distance, host).
    let mut idx = Vec::new();
    let mut local = Vec::new();
    let mut owner = Vec::new();
    for i in 0..k {
        if host.exist[i] < MIN_EXIST {
            continue;
        }
        let (c, b) = (host.centres[i], host.boxes[i]);
        for (j, q) in samples.iter().enumerate() {
            let u = [q[0] - c[0], q[1] - c[1], q[2] - c[2]];
            let out2: f32 = (0..3).map(|a| (u[a].abs() - b[a]).max(0.0).powi(2)).sum();
            if out2 < delta * delta {
                idx.push(i);
                local.push(u);
                owner.push(j);
            }
        }
    }
    if idx.is_empty() {
        return None;
    }
    let d = part_sdf_values(field, &values, &idx, &local);
    // NaN is kept, so it reaches the divergence checks.
    let keep: Vec<usize> = (0..idx.len())
        .filter(|&r| d[r] < delta || d[r].is_nan())
        .collect();
    if keep.is_empty() {
        return None;
    }
    let device = parts.boxes.device();
    let kidx: Vec<usize> = keep.iter().map(|&r| idx[r]).collect();
    let flat: Vec<f32> = keep.iter().flat_map(|&r| local[r]).collect();
    let u = Tensor::<2>::from_data(
        burn::tensor::TensorData::new(flat, [keep.len(), 3]),
        &device,
    );
    // u was taken relative to the host centres: re-add them, subtract the tensor centres, so the
    // gradient reaches the centres.
    let pidx = index_tensor(&kidx, &device);
    let host_c: Vec<f32> = kidx.iter().flat_map(|&i| host.centres[i]).collect();
    let hc = Tensor::<2>::from_data(
        burn::tensor::TensorData::new(host_c, [keep.len(), 3]),
        &device,
    );
    let u = u + hc - parts.centres.clone().select(0, pidx.clone());
    let d = part_sdf(field, parts, pidx.clone(), u);
    let o = exist.clamp(0.0, 1.0).select(0, pidx);
    let scale = m.max(1) as f32 / samples.len() as f32;
    Some((o * (-d + delta).clamp_min(0.0).powi_scalar(2)).sum() * scale)
}
