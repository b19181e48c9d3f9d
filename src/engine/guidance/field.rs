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
//!
//! The learned decoder's differentiable call runs its layers on the host (values and per-row
//! input gradients, `HostDecoder::eval_with_grads`) and hands burn a first-order surrogate with
//! the same value and gradient (see `impl SdfField for LatentSdfDecoder`): burn's autodiff tape
//! then holds a few element-wise ops per call instead of every decoder layer.

use burn::tensor::{Int, Tensor, TensorData};

#[cfg(doc)]
use crate::model::host_decoder::HostDecoder;
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

    /// The values of [`SdfField::sdf`] without gradient, host in and out: `q` [Q], `codes`
    /// [P × F] flat, `idx` [Q]. The default goes through `sdf` on the inference device; the
    /// learned decoder overrides it with its faster value-only path.
    fn sdf_values(&self, q: &[[f32; 3]], codes: &[f32], idx: &[usize]) -> Vec<f32> {
        let device = crate::model::cpu();
        let n = q.len();
        let f = self.latent().max(1);
        let flat: Vec<f32> = q.iter().flatten().copied().collect();
        let q = Tensor::<2>::from_data(TensorData::new(flat, [n, 3]), &device);
        let codes = Tensor::<2>::from_data(
            TensorData::new(codes.to_vec(), [codes.len() / f, f]),
            &device,
        );
        self.sdf(q, codes, super::grid::index_tensor(idx, &device))
            .into_data()
            .try_to_vec::<f32>()
            .unwrap_or_else(|_| vec![f32::NAN; n])
    }
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

    /// The decoder runs on the host ([`HostDecoder::eval_with_grads`]: values and per-row
    /// input gradients, no autodiff tape); burn only sees the first-order surrogate
    ///
    /// ```text
    /// f̃ = f + Σ_c (q − sg(q))_c ∂f/∂q_c + Σ_k (h − sg(h))_k ∂f/∂h_k,   h = (z W_c + b_c)[idx]
    /// ```
    ///
    /// (sg: stop-gradient), whose value is f exactly and whose gradient with respect to q and z
    /// is the decoder's. Falls back to the burn decoder if a tensor cannot be read as f32 / i64.
    fn sdf(&self, q: Tensor<2>, codes: Tensor<2>, idx: Tensor<1, Int>) -> Tensor<1> {
        let host_codes = codes.clone().detach().into_data().try_to_vec::<f32>().ok();
        let host_idx = idx
            .clone()
            .into_data()
            .convert::<i64>()
            .try_to_vec::<i64>()
            .ok();
        let (Some(points), Some(host_codes), Some(host_idx)) =
            (host_points(&q), host_codes, host_idx)
        else {
            return SdfField::sdf(self.decoder(), q, codes, idx);
        };
        let host = self.host();
        let hidden = host.feature_width();
        let rows: Vec<usize> = host_idx.iter().map(|&i| i as usize).collect();
        let g = host.eval_with_grads(&points, &host.code_features(&host_codes), &rows);
        let (n, device) = (points.len(), q.device());
        let values = Tensor::<1>::from_data(TensorData::new(g.values, [n]), &device);
        let d_points: Vec<f32> = g.d_points.into_iter().flatten().collect();
        let d_points = Tensor::<2>::from_data(TensorData::new(d_points, [n, 3]), &device);
        let d_features =
            Tensor::<2>::from_data(TensorData::new(g.d_features, [n, hidden]), &device);
        let features = self.decoder().code_features(codes).select(0, idx);
        let dq = (q.clone() - q.detach()) * d_points;
        let dh = (features.clone() - features.detach()) * d_features;
        values + dq.sum_dim(1).reshape([n]) + dh.sum_dim(1).reshape([n])
    }

    fn sdf_values(&self, q: &[[f32; 3]], codes: &[f32], idx: &[usize]) -> Vec<f32> {
        let host = self.host();
        let mut out = vec![0.0; q.len()];
        host.eval(q, &host.code_features(codes), idx, &mut out);
        out
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

/// Host copies of [`PartTensors`] for the value-only passes ([`part_sdf_values`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PartValues {
    /// Half-extents (clamped as in [`PartTensors::boxes`]).
    pub boxes: Vec<[f32; 3]>,
    /// κ per part.
    pub kappa: Vec<f32>,
    /// Codes [K × F] flat.
    pub codes: Vec<f32>,
}

impl PartTensors {
    /// Host copies of the values (None if a tensor cannot be read as f32).
    pub fn values(&self) -> Option<PartValues> {
        let host = |t: Tensor<2>| t.detach().into_data().try_to_vec::<f32>().ok();
        let boxes = host(self.boxes.clone())?;
        Some(PartValues {
            boxes: boxes.chunks(3).map(|c| [c[0], c[1], c[2]]).collect(),
            kappa: host(self.kappa.clone())?,
            codes: host(self.codes.clone())?,
        })
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

/// Host copy of points [Q, 3] (cut from the autodiff graph), or None if not f32.
pub fn host_points(u: &Tensor<2>) -> Option<Vec<[f32; 3]>> {
    let v = u.clone().detach().into_data().try_to_vec::<f32>().ok()?;
    Some(v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// [`part_sdf`] without gradient on host values: d(u_q, idx[q]) for local points `u` [Q] (in
/// part `idx[q]`'s frame) → [Q], in one [`SdfField::sdf_values`] call.
pub fn part_sdf_values(
    field: &dyn SdfField,
    parts: &PartValues,
    idx: &[usize],
    u: &[[f32; 3]],
) -> Vec<f32> {
    let mut outside = Vec::with_capacity(u.len());
    let q: Vec<[f32; 3]> = u
        .iter()
        .zip(idx)
        .map(|(u, &i)| {
            let (b, kappa) = (parts.boxes[i], parts.kappa[i]);
            let c: [f32; 3] = std::array::from_fn(|k| u[k].max(-b[k]).min(b[k]));
            let r2: f32 = (0..3).map(|k| (u[k] - c[k]).powi(2)).sum();
            outside.push((r2 + NORM_EPS * NORM_EPS).sqrt() - NORM_EPS);
            c.map(|v| v / kappa)
        })
        .collect();
    let f = field.sdf_values(&q, &parts.codes, idx);
    outside
        .iter()
        .zip(idx)
        .zip(f)
        .map(|((o, &i), f)| o + parts.kappa[i] * f)
        .collect()
}

/// The pair-overlap energy ψ = ½·max(0, −(d_i + d_j))² (grid.rs) summed with per-point weights
/// `w` [Q], for the point batch `u` = [Q points in part i's frame; the same Q points in part
/// j's frame] with part indices `idx` [2Q] (host) — computed only where the parts overlap.
///
/// Why: ψ and its gradient are exactly 0 wherever d_i + d_j ≥ 0, and in ℓ_pen / ℓ_mob that is
/// most of the integration grid. A pass without gradient ([`part_sdf_values`] on host copies)
/// finds the overlapping points; the differentiable pass decodes only those. Same value and
/// gradient as decoding every point, at a fraction of the backward cost. None when no point
/// overlaps (the loss is exactly 0).
pub fn overlap_energy(
    field: &dyn SdfField,
    parts: &PartTensors,
    idx: &[usize],
    u: Tensor<2>,
    w: Tensor<1>,
) -> Option<Tensor<1>> {
    let nq = u.dims()[0] / 2;
    let d = part_sdf_values(field, &parts.values()?, idx, &host_points(&u)?);
    // NaN sums are kept: the differentiable pass must see them (divergence checks).
    let keep: Vec<i64> = (0..nq)
        .filter(|&a| {
            let s = d[a] + d[a + nq];
            s < 0.0 || s.is_nan()
        })
        .map(|a| a as i64)
        .collect();
    if keep.is_empty() {
        return None;
    }
    let device = u.device();
    let m = keep.len();
    let rows: Vec<i64> = keep
        .iter()
        .chain(keep.iter())
        .enumerate()
        .map(|(k, &a)| if k < m { a } else { a + nq as i64 })
        .collect();
    let rows = Tensor::<1, Int>::from_data(TensorData::new(rows, [2 * m]), &device);
    let keep = Tensor::<1, Int>::from_data(TensorData::new(keep, [m]), &device);
    let idx = super::grid::index_tensor(idx, &device);
    let d = part_sdf(field, parts, idx.select(0, rows.clone()), u.select(0, rows));
    let psi = super::grid::psi(d.clone().narrow(0, 0, m), d.narrow(0, m, m));
    Some((psi * w.select(0, keep)).sum())
}
