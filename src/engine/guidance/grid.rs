//! The integration grid of ℓ_pen and ℓ_mob (method.md §8.5 steps 1–5, §9 A8).
//!
//! ```text
//! box extents e_k > 0, V = e₁e₂e₃, l_V = V^{1/3}
//! n_k = min(⌊max(N*^{1/3} · e_k / l_V, 1)⌋, 64)          N* = 1000, so N*^{1/3} = 10
//! q_a = lo + (a + ½) ⊙ e / n,  a ∈ {0…n₁−1}×{0…n₂−1}×{0…n₃−1}   (cell centres)
//! V_el = 10⁵ · Π_k e_k / n_k
//! ```
//!
//! Why it exists: both collision terms integrate ½·max(0, −(dᵢ + dⱼ))² over a box grid built the
//! same way. The counts n_k are read from the current values (piecewise constant, no gradient);
//! the grid points and V_el are tensor functions of the box bounds, so the gradient reaches the
//! boxes and centres through them. All boxes of a step go into one flat batch ([`GridBatch`]).

use burn::tensor::{Device, Int, Tensor, TensorData};

/// N*, the target number of grid points per box.
pub const TARGET_POINTS: usize = 1000;
/// N*^{1/3}.
const PER_AXIS: f64 = 10.0;
/// Cap on points per axis (method.md §9 A8), bounding thin intersections.
pub const MAX_PER_AXIS: usize = 64;
/// The 10⁵ in V_el.
pub const VOLUME_SCALE: f32 = 1e5;

/// n_k for extents `e`, or None when the box is empty (some e_k ≤ 0 or non-finite).
pub fn axis_counts(e: [f32; 3]) -> Option<[usize; 3]> {
    if e.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return None;
    }
    let e = e.map(|v| v as f64);
    let lv = (e[0] * e[1] * e[2]).cbrt();
    if !(lv.is_finite() && lv > 0.0) {
        return None;
    }
    // + 1e-9: exact ratios (a cube: 10 · e / l_V = 10) must not floor to 9 by rounding.
    Some(e.map(|v| (((PER_AXIS * v / lv).max(1.0) + 1e-9).floor() as usize).clamp(1, MAX_PER_AXIS)))
}

/// Grid points of several boxes in one flat list.
#[derive(Debug, Clone, Default)]
pub struct GridBatch {
    /// Which box each point belongs to (index into the active boxes).
    pub owner: Vec<i64>,
    /// Cell-centre fractions (a + ½)/n per point, flat [Q × 3].
    pub frac: Vec<f32>,
    /// n_k per box, flat [A × 3].
    pub counts: Vec<f32>,
}

impl GridBatch {
    /// Append a box with counts `n`.
    pub fn push(&mut self, n: [usize; 3]) {
        let owner = (self.counts.len() / 3) as i64;
        self.counts.extend(n.map(|v| v as f32));
        for a in 0..n[0] {
            for b in 0..n[1] {
                for c in 0..n[2] {
                    self.owner.push(owner);
                    self.frac.extend([
                        (a as f32 + 0.5) / n[0] as f32,
                        (b as f32 + 0.5) / n[1] as f32,
                        (c as f32 + 0.5) / n[2] as f32,
                    ]);
                }
            }
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.owner.len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.owner.is_empty()
    }

    /// Owner indices as a tensor [Q].
    pub fn owner_tensor(&self, device: &Device) -> Tensor<1, Int> {
        ints(self.owner.clone(), device)
    }

    /// Grid points lo + frac ⊙ e [Q, 3] and V_el [A] for box bounds `lo`, extents `ext` [A, 3].
    pub fn points(&self, lo: Tensor<2>, ext: Tensor<2>, device: &Device) -> (Tensor<2>, Tensor<1>) {
        let a = self.counts.len() / 3;
        let q = self.len();
        let owner = self.owner_tensor(device);
        let frac = Tensor::<2>::from_data(TensorData::new(self.frac.clone(), [q, 3]), device);
        let points = lo.select(0, owner.clone()) + frac * ext.clone().select(0, owner);
        let counts = Tensor::<2>::from_data(TensorData::new(self.counts.clone(), [a, 3]), device);
        let cell = ext / counts;
        let vel =
            cell.clone().narrow(1, 0, 1) * cell.clone().narrow(1, 1, 1) * cell.narrow(1, 2, 1);
        (points, vel.reshape([a]) * VOLUME_SCALE)
    }
}

/// An Int tensor from indices.
pub fn ints(v: Vec<i64>, device: &Device) -> Tensor<1, Int> {
    let n = v.len();
    Tensor::<1, Int>::from_data(TensorData::new(v, [n]), device)
}

/// An Int tensor from host part indices.
pub fn index_tensor(idx: &[usize], device: &Device) -> Tensor<1, Int> {
    ints(idx.iter().map(|&i| i as i64).collect(), device)
}

/// ψ = ½ · max(0, −(dᵢ + dⱼ))² per point.
pub fn psi(di: Tensor<1>, dj: Tensor<1>) -> Tensor<1> {
    (-(di + dj)).clamp_min(0.0).powi_scalar(2) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_follow_the_cube_root_rule() {
        assert_eq!(axis_counts([1.0, 1.0, 1.0]), Some([10, 10, 10]));
        // Thin box: l_V = (1·1·0.001)^{1/3} = 0.1 → 100 (capped 64), 64, max(0.1, 1) = 1.
        assert_eq!(axis_counts([1.0, 1.0, 0.001]), Some([64, 64, 1]));
        assert_eq!(axis_counts([0.2, 0.4, 0.1]), Some([10, 20, 5]));
        assert_eq!(axis_counts([0.0, 1.0, 1.0]), None);
        assert_eq!(axis_counts([f32::NAN, 1.0, 1.0]), None);
    }

    #[test]
    fn grid_points_are_cell_centres_and_volume_is_scaled() {
        let dev = crate::model::cpu();
        let mut g = GridBatch::default();
        g.push([2, 1, 1]);
        let lo = Tensor::<2>::from_data(TensorData::new(vec![0.0f32, 0.0, 0.0], [1, 3]), &dev);
        let ext = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, 2.0, 3.0], [1, 3]), &dev);
        let (p, vel) = g.points(lo, ext, &dev);
        let p: Vec<f32> = p.into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(p, vec![0.25, 1.0, 1.5, 0.75, 1.0, 1.5]);
        let vel: f32 = vel.into_scalar::<f32>();
        assert!((vel - 1e5 * 0.5 * 2.0 * 3.0).abs() < 1.0, "{vel}");
    }
}
