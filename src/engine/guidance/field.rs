//! The part SDF d(p, i) that every guidance loss and metric uses (method.md §8.3), as batched,
//! differentiable burn tensor code.
//!
//! ```text
//! u = p − t_i (part frame; rotation is identity), B_i = [−b_i, b_i], κ_i = 2‖b_i‖₂
//! u* = clamp(u, −b_i, b_i)                                  (closest box point; u* = u inside)
//! d(p, i) = ‖u − u*‖ + κ_i · f(u*/κ_i; s_i)                 (f: the normalised-frame SDF)
//! ```
//!
//! Why it exists: ℓ_pc, ℓ_pen and ℓ_mob all query "SDF of part i at local point u" for
//! thousands of (part, point) pairs per step; [`part_sdf`] does all of them in one decoder call
//! ([`SdfField::sdf`] takes a flat list of points with a part index each). The field is a trait
//! so the losses can be unit-tested with exact analytic SDFs ([`BoxField`]) as well as run with
//! the learned [`ShapeDecoder`].
//!
//! ‖·‖ is evaluated as √(x² + ε²) − ε with ε = 1e-6, so its gradient is 0 (not NaN) inside the
//! box.

use burn::tensor::{Int, Tensor};

use crate::model::shape_prior::{LatentSdfDecoder, ShapeDecoder};

/// ε of the smooth norm.
const NORM_EPS: f32 = 1e-6;

/// A normalised-frame SDF f(q; s) over a batch of points, each with its own part code.
pub trait SdfField {
    /// Code width F.
    fn latent(&self) -> usize;
    /// f at normalised points `q` [Q, 3] for the codes `codes[idx[q]]` (`codes` [P, F],
    /// `idx` [Q]) → [Q]. Must be differentiable in `q` and `codes`.
    fn sdf(&self, q: Tensor<2>, codes: Tensor<2>, idx: Tensor<1, Int>) -> Tensor<1>;
}

impl SdfField for ShapeDecoder {
    fn latent(&self) -> usize {
        ShapeDecoder::latent(self)
    }

    fn sdf(&self, q: Tensor<2>, codes: Tensor<2>, idx: Tensor<1, Int>) -> Tensor<1> {
        let n = q.dims()[0];
        // W_c z once per part, then one row per query point: a single [Q, 1, 3] decoder call.
        let features = self.code_features(codes).select(0, idx);
        self.sdf_with_features(q.reshape([n, 1, 3]), features)
            .reshape([n])
    }
}

impl SdfField for LatentSdfDecoder {
    fn latent(&self) -> usize {
        self.decoder().latent()
    }

    fn sdf(&self, q: Tensor<2>, codes: Tensor<2>, idx: Tensor<1, Int>) -> Tensor<1> {
        SdfField::sdf(self.decoder(), q, codes, idx)
    }
}

/// An exact analytic field for tests and calibration: the code's first three channels are the
/// normalised half-extents h of a box, f(q; s) = box_sdf(q, |s₀..₂|). With h = b/κ the part SDF
/// d(p, i) is exactly the SDF of the part's box.
#[derive(Debug, Clone, Copy, Default)]
pub struct BoxField {
    /// Code width (≥ 3).
    pub latent: usize,
}

impl SdfField for BoxField {
    fn latent(&self) -> usize {
        self.latent
    }

    fn sdf(&self, q: Tensor<2>, codes: Tensor<2>, idx: Tensor<1, Int>) -> Tensor<1> {
        let n = q.dims()[0];
        let h = codes.narrow(1, 0, 3).abs().select(0, idx);
        let a = q.abs() - h;
        let outside = smooth_norm(a.clone().clamp_min(0.0));
        let inside = a.max_dim(1).reshape([n]).clamp_max(0.0);
        outside + inside
    }
}

/// √(Σ x² + ε²) − ε over the last axis of [Q, 3] → [Q].
pub fn smooth_norm(x: Tensor<2>) -> Tensor<1> {
    let n = x.dims()[0];
    (x.powi_scalar(2).sum_dim(1).reshape([n]) + NORM_EPS * NORM_EPS).sqrt() - NORM_EPS
}

/// The decoded parts of one graph that the SDF needs (object units, on the autodiff device).
#[derive(Debug, Clone)]
pub struct PartTensors {
    /// Half-extents |b| clamped to ≥ 1e-4, [K, 3].
    pub boxes: Tensor<2>,
    /// Centres t, [K, 3].
    pub centres: Tensor<2>,
    /// Raw shape codes s, [K, F].
    pub codes: Tensor<2>,
    /// κ = 2‖b‖₂, [K, 1].
    pub kappa: Tensor<2>,
}

impl PartTensors {
    /// From boxes, centres and codes.
    pub fn new(boxes: Tensor<2>, centres: Tensor<2>, codes: Tensor<2>) -> Self {
        let k = boxes.dims()[0];
        let boxes = boxes.abs().clamp_min(super::MIN_HALF_EXTENT);
        let kappa = boxes
            .clone()
            .powi_scalar(2)
            .sum_dim(1)
            .sqrt()
            .reshape([k, 1])
            * 2.0;
        PartTensors {
            boxes,
            centres,
            codes,
            kappa,
        }
    }
}

/// d(p, i) for local points `u` [Q, 3] (already in part `idx[q]`'s frame) → [Q], in one field
/// call.
pub fn part_sdf(
    field: &dyn SdfField,
    parts: &PartTensors,
    idx: Tensor<1, Int>,
    u: Tensor<2>,
) -> Tensor<1> {
    let n = u.dims()[0];
    let b = parts.boxes.clone().select(0, idx.clone());
    let kappa = parts.kappa.clone().select(0, idx.clone());
    let closest = u.clone().max_pair(-b.clone()).min_pair(b);
    let outside = smooth_norm(u - closest.clone());
    let f = field.sdf(closest / kappa.clone(), parts.codes.clone(), idx);
    outside + kappa.reshape([n]) * f
}
