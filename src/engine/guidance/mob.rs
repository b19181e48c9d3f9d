//! ℓ_mob, the mobility (collision-while-moving) loss (method.md §8.6, §9 A5, A12).
//!
//! ```text
//! for pairs (i < j) with max(c̃₁, c̃₂) > 0.1, for each chirality k ∈ {1, 2} with c̃_k > 0.1:
//!   (l, m) ← projected Plücker line (l/‖l‖, m − (l·m)l), times s = +1 (k = 1) or −1 (k = 2)
//!   frame i: m_i = m − t_i × l, p₀ = l × m_i
//!   2 states: γ = r_lo + u (r_hi − r_lo), d = p_lo + u' (p_hi − p_lo), u, u' ~ U(0, 1)
//!   T_ij = T_screw(l, m_i, γ, d) · translation(t_j − t_i),  T_screw x = R x + (I − R) p₀ + d l
//!   grid (grid.rs, N* = 1000) in  AABB(T_ij(B_j)) ∩ B_i   (frame i)
//!   ψ_a = ½ · max(0, −(d_i(q_a) + d_j(T_ij⁻¹ q_a)))²
//! ℓ_mob = 2 · Σ_(pairs, k, states) c̃_k · V_el · Σ_a ψ_a          (c̃ clamped to [0, 1])
//! ```
//!
//! No node-existence weight (as the paper). The states are drawn from the caller's RNG (seeded
//! per sample and step, so guidance is deterministic). The same sweep with 5 equally spaced
//! synchronised states and unit weights is the E_mob metric ([`sweep`] with [`metric_items`]).
//! Items whose swept box does not meet B_i contribute exactly zero and are skipped; all grid
//! points of all items, for both parts, are one field call.

use burn::tensor::{Tensor, TensorData};

use super::field::{PartTensors, SdfField, overlap_energy};
use super::grid::{GridBatch, axis_counts, ints};
use crate::data::rng::Rng;
use crate::graph::{EDGE_DIM, EDGE_PAIRS, edge_ch};

/// Edge-existence threshold.
pub const EDGE_THRESHOLD: f32 = 0.1;
/// Random states per pair and chirality.
pub const STATES: usize = 2;
/// The factor balancing the single ordering against ℓ_pen's ordered pairs.
pub const PAIR_FACTOR: f32 = 2.0;
/// States of the E_mob metric.
pub const METRIC_STATES: usize = 5;

/// One (edge, chirality, state) to sweep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepItem {
    /// Edge row.
    pub edge: usize,
    /// Parent slot (lower index).
    pub i: usize,
    /// Child slot.
    pub j: usize,
    /// Chirality class (1: +L, 2: −L).
    pub class: usize,
    /// Fraction of the revolute range.
    pub u_r: f32,
    /// Fraction of the prismatic range.
    pub u_p: f32,
}

/// The loss's items: every edge and chirality over the threshold, [`STATES`] random states each.
/// `classes` are the 28 edge rows' c̃ (clamped here).
pub fn loss_items(classes: &[[f32; 3]], rng: &mut Rng) -> Vec<SweepItem> {
    let mut out = Vec::new();
    for (edge, &(i, j)) in EDGE_PAIRS.iter().enumerate() {
        let c = classes[edge].map(|v| v.clamp(0.0, 1.0));
        for (class, &ck) in c.iter().enumerate().skip(1) {
            if ck > EDGE_THRESHOLD {
                for _ in 0..STATES {
                    let (u_r, u_p) = (rng.uniform() as f32, rng.uniform() as f32);
                    out.push(SweepItem {
                        edge,
                        i,
                        j,
                        class,
                        u_r,
                        u_p,
                    });
                }
            }
        }
    }
    out
}

/// The metric's items: each joint (edge row, class) at [`METRIC_STATES`] equally spaced
/// synchronised states k/4, k = 0…4.
pub fn metric_items(joints: &[(usize, usize)]) -> Vec<SweepItem> {
    let mut out = Vec::new();
    for &(edge, class) in joints {
        let (i, j) = EDGE_PAIRS[edge];
        for k in 0..METRIC_STATES {
            let u = k as f32 / (METRIC_STATES - 1) as f32;
            out.push(SweepItem {
                edge,
                i,
                j,
                class,
                u_r: u,
                u_p: u,
            });
        }
    }
    out
}

/// Per-item weights of the loss: 2 · c̃_k from the (raw) edges [28, 13].
pub fn loss_weights(edges: Tensor<2>, items: &[SweepItem]) -> Tensor<1> {
    let device = edges.device();
    let n = edges.dims()[0];
    let classes = edges
        .narrow(1, edge_ch::CLASS, 3)
        .clamp(0.0, 1.0)
        .reshape([n * 3]);
    let idx = ints(
        items
            .iter()
            .map(|it| (it.edge * 3 + it.class) as i64)
            .collect(),
        &device,
    );
    classes.select(0, idx) * PAIR_FACTOR
}

fn column(x: &Tensor<2>, c: usize) -> Tensor<2> {
    x.clone().narrow(1, c, 1)
}

/// a × b row-wise, [n, 3].
pub fn cross(a: Tensor<2>, b: Tensor<2>) -> Tensor<2> {
    let (ax, ay, az) = (column(&a, 0), column(&a, 1), column(&a, 2));
    let (bx, by, bz) = (column(&b, 0), column(&b, 1), column(&b, 2));
    Tensor::cat(
        vec![
            ay.clone() * bz.clone() - az.clone() * by.clone(),
            az * bx.clone() - ax.clone() * bz,
            ax * by - ay * bx,
        ],
        1,
    )
}

/// Rodrigues: R = cos θ I + sin θ [l]× + (1 − cos θ) l lᵀ for unit `l` [n, 3], `theta` [n, 1].
pub fn rotation(l: Tensor<2>, theta: Tensor<2>) -> Tensor<3> {
    let n = l.dims()[0];
    let device = l.device();
    let (lx, ly, lz) = (column(&l, 0), column(&l, 1), column(&l, 2));
    let zero = lx.clone() * 0.0;
    let skew: Tensor<3> = Tensor::stack(
        vec![
            Tensor::cat(vec![zero.clone(), -lz.clone(), ly.clone()], 1),
            Tensor::cat(vec![lz, zero.clone(), -lx.clone()], 1),
            Tensor::cat(vec![-ly, lx, zero], 1),
        ],
        1,
    );
    let outer = l.clone().unsqueeze_dim::<3>(2) * l.unsqueeze_dim::<3>(1);
    let eye = Tensor::<2>::from_data(
        TensorData::new(vec![1.0f32, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], [3, 3]),
        &device,
    )
    .unsqueeze::<3>();
    let (c, s) = (
        theta.clone().cos().reshape([n, 1, 1]),
        theta.sin().reshape([n, 1, 1]),
    );
    eye * c.clone() + skew * s + outer * (-c + 1.0)
}

/// R v row-wise: [n, 3, 3] × [n, 3] → [n, 3].
pub fn apply(r: Tensor<3>, v: Tensor<2>) -> Tensor<2> {
    let n = v.dims()[0];
    (r * v.unsqueeze_dim::<3>(1)).sum_dim(2).reshape([n, 3])
}

/// Rᵀ v row-wise.
pub fn apply_transpose(r: Tensor<3>, v: Tensor<2>) -> Tensor<2> {
    let n = v.dims()[0];
    (r * v.unsqueeze_dim::<3>(2)).sum_dim(1).reshape([n, 3])
}

/// Σ_items weight · V_el · Σ_a ψ_a for the raw `edges` [28, 13] and `weights` [items], or None
/// when no item's swept box meets its parent box.
pub fn sweep(
    field: &dyn SdfField,
    parts: &PartTensors,
    edges: Tensor<2>,
    items: &[SweepItem],
    weights: Tensor<1>,
) -> Option<Tensor<1>> {
    if items.is_empty() {
        return None;
    }
    let device = parts.boxes.device();
    let n = items.len();
    let col = |f: &dyn Fn(&SweepItem) -> f32| {
        Tensor::<2>::from_data(
            TensorData::new(items.iter().map(f).collect::<Vec<f32>>(), [n, 1]),
            &device,
        )
    };
    let ii = ints(items.iter().map(|it| it.i as i64).collect(), &device);
    let jj = ints(items.iter().map(|it| it.j as i64).collect(), &device);
    let rows = edges.select(
        0,
        ints(items.iter().map(|it| it.edge as i64).collect(), &device),
    );
    debug_assert_eq!(rows.dims(), [n, EDGE_DIM]);
    let l = rows.clone().narrow(1, edge_ch::DIR, 3);
    let m = rows.clone().narrow(1, edge_ch::MOMENT, 3);
    let len = l.clone().powi_scalar(2).sum_dim(1).sqrt().clamp_min(1e-12);
    let lh = l / len;
    let m = m.clone() - lh.clone() * (lh.clone() * m).sum_dim(1);
    let sign = col(&|it| if it.class == 2 { -1.0 } else { 1.0 });
    let (lh, m) = (lh * sign.clone(), m * sign);
    let ti = parts.centres.clone().select(0, ii.clone());
    let tj = parts.centres.clone().select(0, jj.clone());
    let mi = m - cross(ti.clone(), lh.clone());
    let p0 = cross(lh.clone(), mi);
    let range = |c: usize, u: Tensor<2>| {
        let lo = rows.clone().narrow(1, c, 1);
        let hi = rows.clone().narrow(1, c + 1, 1);
        lo.clone() + u * (hi - lo)
    };
    let theta = range(edge_ch::REVOLUTE, col(&|it| it.u_r));
    let disp = range(edge_ch::PRISMATIC, col(&|it| it.u_p));
    let r = rotation(lh.clone(), theta);
    let tr = p0.clone() - apply(r.clone(), p0) + lh * disp;
    let delta = tj - ti;
    let centre = apply(r.clone(), delta.clone()) + tr.clone();
    let bj = parts.boxes.clone().select(0, jj);
    let bi = parts.boxes.clone().select(0, ii);
    let half = apply(r.clone().abs(), bj);
    let lo = (centre.clone() - half.clone()).max_pair(-bi.clone());
    let hi = (centre + half).min_pair(bi);
    let ext = (hi - lo.clone()).clamp_min(0.0);

    let ext_host: Vec<f32> = ext.clone().into_data().try_to_vec::<f32>().ok()?;
    let mut grid = GridBatch::default();
    let mut active = Vec::new();
    for (a, e) in ext_host.chunks(3).enumerate() {
        if let Some(counts) = axis_counts([e[0], e[1], e[2]]) {
            grid.push(counts);
            active.push(a as i64);
        }
    }
    if active.is_empty() {
        return None;
    }
    let act = ints(active.clone(), &device);
    let (q, vel) = grid.points(
        lo.select(0, act.clone()),
        ext.select(0, act.clone()),
        &device,
    );
    let owner = grid.owner_tensor(&device);
    let item_of: Vec<usize> = grid
        .owner
        .iter()
        .map(|&a| active[a as usize] as usize)
        .collect();
    let per_point = ints(item_of.iter().map(|&k| k as i64).collect(), &device);
    let xj = apply_transpose(
        r.select(0, per_point.clone()),
        q.clone() - tr.select(0, per_point.clone()),
    ) - delta.select(0, per_point);
    let qi: Vec<usize> = item_of.iter().map(|&k| items[k].i).collect();
    let qj: Vec<usize> = item_of.iter().map(|&k| items[k].j).collect();
    let idx = [qi, qj].concat();
    let w = weights.select(0, act) * vel;
    overlap_energy(
        field,
        parts,
        &idx,
        Tensor::cat(vec![q, xj], 0),
        w.select(0, owner),
    )
}
