//! The denoiser's inference path: [`Denoiser::forward`] and its input gradient (a
//! vector–Jacobian product) in plain `f32` buffers, for sampling and guidance.
//!
//! Why it exists: sampling calls the denoiser once or twice per reverse step and guidance also
//! back-propagates through it to its inputs; through burn each of the network's ~150 tensor ops
//! is a separate op with its own allocation and a scalar `expf` per SiLU, which made a batch of
//! 16 samples 2.6× slower than PyTorch on the same CPU. Here the same function runs on
//! [`super::super::kernels`]: GEMMs with bias and residual folded into the accumulation, SIMD SiLU,
//! buffers owned by a reusable [`Workspace`] (nothing allocated per call once warm), and the
//! samples of a batch in fixed blocks of [`BLOCK_SAMPLES`] on the current rayon pool.
//!
//! Invariants:
//! - The same function as the burn model it was copied from, up to float summation order
//!   (tests: values and input gradients against burn's autodiff, and the PyTorch golden
//!   fixtures). Training keeps the burn model (weight gradients, the optimiser).
//! - Deterministic: a sample's result does not depend on the thread count, because blocks are
//!   fixed and no reduction is split across threads.
//! - [`HostDenoiser::backward`] is the gradient of Σ ⟨d_eps, ε̂⟩ with respect to (V, E) at the
//!   inputs of the last recorded forward; `t` and the category are not differentiable.
//!
//! Layout (per sample: 8 node rows, 64 directed entry rows i·8 + j, 28 upper pairs in
//! `EDGE_PAIRS` order) and the forward pass are the burn module's; see `denoiser.rs`.

use rayon::prelude::*;

use super::{Denoiser, DenoiserConfig, EDGE_SLICES, HEAD_SLOPE, NODE_SLICES, TIME_STEPS};
use crate::graph::{EDGE_DIM, EDGE_PAIRS, K, NODE_DIM, NUM_EDGES, edge_index};
use crate::model::kernels::{
    HostLinear, View, add_into, add_rows, mm, mul_into, silu, silu_with_deriv,
};

/// Samples per block of work by default: blocks run in parallel, a block's rows go through each
/// GEMM together. Fixed per [`HostDenoiser`], so results do not depend on the thread count.
pub const BLOCK_SAMPLES: usize = 1;
/// Directed entries per sample.
const D: usize = K * K;

/// One graph layer's weights.
#[derive(Debug, Clone)]
struct Layer {
    node_bind: HostLinear,
    edge_bind: HostLinear,
    edge_mlp1: HostLinear,
    edge_mlp2: HostLinear,
    query: HostLinear,
    key: HostLinear,
    self_term: HostLinear,
    node_out: HostLinear,
    /// π W_π, the slot term of the node binding, [K, w].
    slot: Vec<f32>,
}

/// The denoiser's weights on the host (see the module docs).
#[derive(Debug, Clone)]
pub struct HostDenoiser {
    config: DenoiserConfig,
    block: usize,
    w: usize,
    heads: usize,
    scale: f32,
    /// The four node input embeddings stacked by channel, [NODE_DIM, w], and their bias sum.
    node_w: Vec<f32>,
    node_b: Vec<f32>,
    /// The three edge input embeddings as one map of the 13 dense channels, [EDGE_DIM, w]
    /// (NAP's legacy slicing included), and their bias sum.
    edge_w: Vec<f32>,
    edge_b: Vec<f32>,
    category: Option<Vec<f32>>,
    category_layers: Option<Vec<f32>>,
    layers: Vec<Layer>,
    node_wide: HostLinear,
    edge_wide: HostLinear,
    node_heads: Vec<Head>,
    edge_heads: Vec<Head>,
    /// [TIME_STEPS, t_pe_dim].
    time_pe: Vec<f32>,
}

/// What one layer's backward pass reads (and the layer's scratch in a value-only pass).
#[derive(Debug, Default)]
struct LayerTape {
    /// SiLU′ of the node binding, the edge binding, the edge hidden layer, the self term and
    /// the node output, each at its input.
    d_vb: Vec<f32>,
    d_eb: Vec<f32>,
    d_hid: Vec<f32>,
    d_self: Vec<f32>,
    d_out: Vec<f32>,
    /// The edge messages u [64n, w] (the next layer's edge input).
    u: Vec<f32>,
    q: Vec<f32>,
    k: Vec<f32>,
    /// Attention weights [n, heads, 8, 8].
    alpha: Vec<f32>,
    /// The node row of each channel's max-pool, [n, w].
    argmax: Vec<u8>,
}

/// The buffers of one block of samples.
#[derive(Debug, Default)]
struct Block {
    n: usize,
    /// h⁰ … h^L, each [8n, w].
    hs: Vec<Vec<f32>>,
    /// g⁰ … g^L at the upper pairs, each [28n, w].
    gs: Vec<Vec<f32>>,
    /// The current layer's edge input [64n, w].
    g: Vec<f32>,
    dense: Vec<f32>,
    tau: Vec<f32>,
    hin: Vec<f32>,
    vb: Vec<f32>,
    eb: Vec<f32>,
    time_n: Vec<f32>,
    time_e: Vec<f32>,
    a: Vec<f32>,
    bj: Vec<f32>,
    hid: Vec<f32>,
    msg: Vec<f32>,
    st: Vec<f32>,
    pool: Vec<f32>,
    pooled: Vec<f32>,
    hw: Vec<f32>,
    gw: Vec<f32>,
    /// Per layer when recording, else one reused.
    tapes: Vec<LayerTape>,
    /// Per head, its hidden activations (all heads when recording).
    head_acts: Vec<Vec<Vec<f32>>>,
    /// Whether `tapes` and `head_acts` hold a forward pass for `backward`.
    recorded: bool,
    // Backward scratch.
    dhw: Vec<f32>,
    dgw: Vec<f32>,
    dhs: Vec<Vec<f32>>,
    dgs: Vec<Vec<f32>>,
    dh: Vec<f32>,
    dg: Vec<f32>,
    t1: Vec<f32>,
    dv1: Vec<f32>,
    dvb: Vec<f32>,
    dq: Vec<f32>,
    dk: Vec<f32>,
    du: Vec<f32>,
    dalpha: Vec<f32>,
    da: Vec<f32>,
    db: Vec<f32>,
    dpool: Vec<f32>,
    dgmax: Vec<f32>,
    ddense: Vec<f32>,
    dacts: Vec<Vec<f32>>,
}

/// Reusable buffers of [`HostDenoiser::forward`] and [`HostDenoiser::backward`]: keep one per
/// sampling loop, so steps after the first allocate nothing.
#[derive(Debug, Default)]
pub struct Workspace {
    blocks: Vec<Block>,
    batch: usize,
}

fn sized(buf: &mut Vec<f32>, len: usize) {
    buf.clear();
    buf.resize(len, 0.0);
}

fn leaky(x: &mut [f32]) {
    let s = HEAD_SLOPE as f32;
    x.iter_mut()
        .for_each(|x| *x = if *x > 0.0 { *x } else { *x * s });
}

/// `g` ← `g` ⊙ LeakyReLU′ at the activation `act` (same sign as its input).
fn leaky_backward(g: &mut [f32], act: &[f32]) {
    let s = HEAD_SLOPE as f32;
    g.iter_mut()
        .zip(act)
        .for_each(|(g, &a)| *g = if a > 0.0 { *g } else { *g * s });
}

/// Add `rows[s]` (a [w] row per sample) to every one of the `per` rows of sample s in `dst`.
fn add_per_sample(dst: &mut [f32], rows: &[f32], per: usize, w: usize) {
    for (s, block) in dst.chunks_exact_mut(per * w).enumerate() {
        add_rows(block, &rows[s * w..(s + 1) * w]);
    }
}

/// The upper-pair rows of `g` [64n, w] into `dst` [28n, w].
fn gather_upper(dst: &mut [f32], g: &[f32], n: usize, w: usize) {
    for s in 0..n {
        for (p, &(i, j)) in EDGE_PAIRS.iter().enumerate() {
            let src = (s * D + i * K + j) * w;
            let to = (s * NUM_EDGES + p) * w;
            dst[to..to + w].copy_from_slice(&g[src..src + w]);
        }
    }
}

/// `dst` [64n, w] += the upper-pair rows `src` [28n, w] at their directed entries.
fn scatter_upper(dst: &mut [f32], src: &[f32], n: usize, w: usize) {
    for s in 0..n {
        for (p, &(i, j)) in EDGE_PAIRS.iter().enumerate() {
            let to = (s * D + i * K + j) * w;
            let from = (s * NUM_EDGES + p) * w;
            add_into(&mut dst[to..to + w], &src[from..from + w]);
        }
    }
}

/// The directed entry (i, j)'s row of E and whether classes 1 and 2 are swapped (i > j); None
/// on the diagonal.
fn dense_source(i: usize, j: usize) -> Option<(usize, bool)> {
    (i != j).then(|| (edge_index(i, j), i > j))
}

/// Channel c of the swapped row reads channel `swap(c)`.
fn swap(c: usize) -> usize {
    match c {
        1 => 2,
        2 => 1,
        c => c,
    }
}

impl HostDenoiser {
    /// Copy `model`'s weights.
    pub fn new(model: &Denoiser) -> Self {
        let config = model.config().clone();
        let w = config.width;
        let read = |t: burn::tensor::Tensor<2>| -> Vec<f32> {
            t.into_data()
                .try_to_vec::<f32>()
                .expect("denoiser weights are f32")
        };
        let mut node_w = vec![0.0; NODE_DIM * w];
        let mut node_b = vec![0.0; w];
        for (&(o, n), l) in NODE_SLICES.iter().zip(&model.node_embed) {
            let l = HostLinear::new(l);
            node_w[o * w..(o + n) * w].copy_from_slice(&l.w);
            add_into(&mut node_b, l.b.as_deref().expect("embedding bias"));
        }
        let (line_at, range_at) = if config.legacy_edge_embedding {
            (6, 6)
        } else {
            (3, 9)
        };
        let mut edge_w = vec![0.0; EDGE_DIM * w];
        let mut edge_b = vec![0.0; w];
        for (l, at) in [
            (&model.edge_embed_class, 0),
            (&model.edge_embed_line, line_at),
            (&model.edge_embed_range, range_at),
        ] {
            let l = HostLinear::new(l);
            add_into(&mut edge_w[at * w..(at + l.d_in) * w], &l.w);
            add_into(&mut edge_b, l.b.as_deref().expect("embedding bias"));
        }
        let slot_pe = read(model.slot_pe.clone());
        let p = config.slot_pe_dim;
        let layers = model
            .layers
            .iter()
            .map(|l| {
                let node_bind = HostLinear::new(&l.node_bind);
                let mut slot = vec![0.0; K * w];
                mm(
                    &mut slot,
                    w,
                    View::rows(&slot_pe, p),
                    View::rows(node_bind.rows(w, p), w),
                    K,
                    p,
                    w,
                    false,
                );
                Layer {
                    node_bind,
                    edge_bind: HostLinear::new(&l.edge_bind),
                    edge_mlp1: HostLinear::new(&l.edge_mlp1),
                    edge_mlp2: HostLinear::new(&l.edge_mlp2),
                    query: HostLinear::new(&l.query),
                    key: HostLinear::new(&l.key),
                    self_term: HostLinear::new(&l.self_term),
                    node_out: HostLinear::new(&l.node_out),
                    slot,
                }
            })
            .collect();
        HostDenoiser {
            block: BLOCK_SAMPLES,
            w,
            heads: config.heads(),
            scale: (1.0 / ((config.head_channels * 3) as f64).sqrt()) as f32,
            node_w,
            node_b,
            edge_w,
            edge_b,
            category: model.category.as_ref().map(|t| read(t.weight.val())),
            category_layers: model.category_layers.as_ref().map(|t| read(t.weight.val())),
            layers,
            node_wide: HostLinear::new(&model.node_wide),
            edge_wide: HostLinear::new(&model.edge_wide),
            node_heads: NODE_SLICES
                .iter()
                .zip(&model.node_heads)
                .map(|(&(_, n), h)| Head::new(h, n))
                .collect(),
            edge_heads: EDGE_SLICES
                .iter()
                .zip(&model.edge_heads)
                .map(|(&(_, n), h)| Head::new(h, n))
                .collect(),
            time_pe: read(model.time_pe.clone()),
            config,
        }
    }

    /// The same weights with `samples` (≥ 1) samples per block of work: more rows per GEMM, fewer
    /// blocks to share among threads. Results change only by float rounding.
    pub fn with_block_samples(mut self, samples: usize) -> Self {
        self.block = samples.max(1);
        self
    }

    /// The configuration of the model this was copied from.
    pub fn config(&self) -> &DenoiserConfig {
        &self.config
    }

    /// ε̂ for `t.len()` noisy graphs: `v` [B·8·135], `e` [B·28·13], `t` [B] in 0..1000,
    /// `category` [B] in 0..=categories (None, or the value `categories`: "no category";
    /// ignored when the model is unconditional); writes `eps_v` [B·8·135] and `eps_e`
    /// [B·28·13]. With `record`, `ws` keeps what [`HostDenoiser::backward`] needs.
    ///
    /// # Panics
    /// On buffer lengths that do not match `t.len()`, and on `t` or `category` out of range.
    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        v: &[f32],
        e: &[f32],
        t: &[usize],
        category: Option<&[usize]>,
        eps_v: &mut [f32],
        eps_e: &mut [f32],
        ws: &mut Workspace,
        record: bool,
    ) {
        let b = t.len();
        let (nv, ne) = (K * NODE_DIM, NUM_EDGES * EDGE_DIM);
        assert!(b > 0, "denoiser: empty batch");
        assert!(
            v.len() == b * nv
                && e.len() == b * ne
                && eps_v.len() == b * nv
                && eps_e.len() == b * ne,
            "denoiser: buffers do not match a batch of {b}"
        );
        assert!(
            t.iter().all(|&t| t < TIME_STEPS),
            "denoiser: t out of 0..{TIME_STEPS}"
        );
        let none = self.config.categories;
        if let Some(c) = category {
            assert!(
                c.len() == b && c.iter().all(|&c| c <= none),
                "denoiser: category out of 0..={none}"
            );
        }
        let blocks = b.div_ceil(self.block);
        ws.blocks.resize_with(blocks, Block::default);
        ws.batch = b;
        let cs = self.block;
        eps_v
            .par_chunks_mut(cs * nv)
            .zip(eps_e.par_chunks_mut(cs * ne))
            .zip(ws.blocks.par_iter_mut())
            .enumerate()
            .for_each(|(k, ((ov, oe), blk))| {
                let (s0, n) = (k * cs, ov.len() / nv);
                self.forward_block(
                    &v[s0 * nv..(s0 + n) * nv],
                    &e[s0 * ne..(s0 + n) * ne],
                    &t[s0..s0 + n],
                    category.map(|c| &c[s0..s0 + n]),
                    ov,
                    oe,
                    blk,
                    record,
                );
            });
    }

    /// The gradient of Σ ⟨`d_eps_v`, ε̂_V⟩ + ⟨`d_eps_e`, ε̂_E⟩ with respect to V and E at the
    /// last forward pass recorded in `ws`, written to `d_v` and `d_e` (same layouts).
    ///
    /// # Panics
    /// When `ws` holds no recorded forward pass, or on buffer lengths that do not match it.
    pub fn backward(
        &self,
        ws: &mut Workspace,
        d_eps_v: &[f32],
        d_eps_e: &[f32],
        d_v: &mut [f32],
        d_e: &mut [f32],
    ) {
        let b = ws.batch;
        let (nv, ne) = (K * NODE_DIM, NUM_EDGES * EDGE_DIM);
        assert!(
            ws.blocks
                .iter()
                .take(b.div_ceil(self.block))
                .all(|b| b.recorded)
                && b > 0,
            "denoiser: backward without a recorded forward pass"
        );
        assert!(
            d_eps_v.len() == b * nv
                && d_eps_e.len() == b * ne
                && d_v.len() == b * nv
                && d_e.len() == b * ne,
            "denoiser: gradient buffers do not match the recorded batch of {b}"
        );
        let cs = self.block;
        d_v.par_chunks_mut(cs * nv)
            .zip(d_e.par_chunks_mut(cs * ne))
            .zip(ws.blocks.par_iter_mut())
            .enumerate()
            .for_each(|(k, ((dv, de), blk))| {
                let (s0, n) = (k * cs, dv.len() / nv);
                self.backward_block(
                    &d_eps_v[s0 * nv..(s0 + n) * nv],
                    &d_eps_e[s0 * ne..(s0 + n) * ne],
                    dv,
                    de,
                    blk,
                );
            });
    }

    fn layer_tapes(&self, blk: &mut Block, record: bool) {
        let count = if record { self.layers.len() } else { 1 };
        blk.tapes
            .resize_with(count.max(blk.tapes.len()), LayerTape::default);
    }

    #[allow(clippy::too_many_arguments)]
    fn forward_block(
        &self,
        v: &[f32],
        e: &[f32],
        t: &[usize],
        cats: Option<&[usize]>,
        eps_v: &mut [f32],
        eps_e: &mut [f32],
        blk: &mut Block,
        record: bool,
    ) {
        let n = t.len();
        let w = self.w;
        let (rv, re, ru) = (K * n, D * n, NUM_EDGES * n);
        let nl = self.layers.len();
        blk.n = n;
        blk.recorded = false;
        self.layer_tapes(blk, record);
        blk.hs.resize_with(nl + 1, Vec::new);
        blk.gs.resize_with(nl + 1, Vec::new);
        // Sample s's category row ("no category" without a category).
        let cat_of = |s: usize| cats.map_or(self.config.categories, |c| c[s]);
        let cat_row = |s: usize| {
            self.category
                .as_ref()
                .map(|c| &c[cat_of(s) * w..(cat_of(s) + 1) * w])
        };

        // Node embedding h⁰ = V W + b (+ category).
        let h0 = &mut blk.hs[0];
        sized(h0, rv * w);
        add_rows(h0, &self.node_b);
        mm(
            h0,
            w,
            View::rows(v, NODE_DIM),
            View::rows(&self.node_w, w),
            rv,
            NODE_DIM,
            w,
            true,
        );
        // Edge embedding g⁰ over the dense directed entries.
        sized(&mut blk.dense, re * EDGE_DIM);
        for s in 0..n {
            for i in 0..K {
                for j in 0..K {
                    if let Some((p, swapped)) = dense_source(i, j) {
                        let src = &e[(s * NUM_EDGES + p) * EDGE_DIM..][..EDGE_DIM];
                        let dst = &mut blk.dense[(s * D + i * K + j) * EDGE_DIM..][..EDGE_DIM];
                        for (c, d) in dst.iter_mut().enumerate() {
                            *d = src[if swapped { swap(c) } else { c }];
                        }
                    }
                }
            }
        }
        sized(&mut blk.g, re * w);
        add_rows(&mut blk.g, &self.edge_b);
        mm(
            &mut blk.g,
            w,
            View::rows(&blk.dense, EDGE_DIM),
            View::rows(&self.edge_w, w),
            re,
            EDGE_DIM,
            w,
            true,
        );
        if self.category.is_some() {
            for s in 0..n {
                let c = cat_row(s).expect("category table");
                add_rows(&mut blk.hs[0][s * K * w..(s + 1) * K * w], c);
                add_rows(&mut blk.g[s * D * w..(s + 1) * D * w], c);
            }
        }
        sized(&mut blk.gs[0], ru * w);
        gather_upper(&mut blk.gs[0], &blk.g, n, w);

        // The time encodings of the block's samples.
        let td = self.config.t_pe_dim;
        sized(&mut blk.tau, n * td);
        for (s, &t) in t.iter().enumerate() {
            blk.tau[s * td..(s + 1) * td].copy_from_slice(&self.time_pe[t * td..(t + 1) * td]);
        }

        for (l, layer) in self.layers.iter().enumerate() {
            let tape = &mut blk.tapes[if record { l } else { 0 }];
            // Inputs (+ the layer's category row).
            blk.hin.clear();
            blk.hin.extend_from_slice(&blk.hs[l]);
            if let Some(cl) = &self.category_layers {
                let lw = nl * w;
                for s in 0..n {
                    let row = &cl[cat_of(s) * lw + l * w..][..w];
                    add_rows(&mut blk.hin[s * K * w..(s + 1) * K * w], row);
                    add_rows(&mut blk.g[s * D * w..(s + 1) * D * w], row);
                }
            }
            let p = self.config.slot_pe_dim;
            // 1. Time/slot binding.
            let nb = &layer.node_bind;
            sized(&mut blk.time_n, n * w);
            add_rows(&mut blk.time_n, nb.b.as_deref().expect("bias"));
            mm(
                &mut blk.time_n,
                w,
                View::rows(&blk.tau, td),
                View::rows(nb.rows(w + p, td), w),
                n,
                td,
                w,
                true,
            );
            let eb_l = &layer.edge_bind;
            sized(&mut blk.time_e, n * w);
            add_rows(&mut blk.time_e, eb_l.b.as_deref().expect("bias"));
            mm(
                &mut blk.time_e,
                w,
                View::rows(&blk.tau, td),
                View::rows(eb_l.rows(w, td), w),
                n,
                td,
                w,
                true,
            );

            sized(&mut blk.vb, rv * w);
            for s in 0..n {
                let dst = &mut blk.vb[s * K * w..(s + 1) * K * w];
                dst.copy_from_slice(&layer.slot);
                add_rows(dst, &blk.time_n[s * w..(s + 1) * w]);
            }
            mm(
                &mut blk.vb,
                w,
                View::rows(&blk.hin, w),
                View::rows(nb.rows(0, w), w),
                rv,
                w,
                w,
                true,
            );
            activate(&mut blk.vb, &mut tape.d_vb, record);

            sized(&mut blk.eb, re * w);
            add_per_sample(&mut blk.eb, &blk.time_e, D, w);
            mm(
                &mut blk.eb,
                w,
                View::rows(&blk.g, w),
                View::rows(eb_l.rows(0, w), w),
                re,
                w,
                w,
                true,
            );
            activate(&mut blk.eb, &mut tape.d_eb, record);

            // 2. Edge messages u_ij = W₂ SiLU(A v_i + B v_j + C e_ij + b₁) + b₂.
            let m1 = &layer.edge_mlp1;
            sized(&mut blk.a, rv * w);
            mm(
                &mut blk.a,
                w,
                View::rows(&blk.vb, w),
                View::rows(m1.rows(0, w), w),
                rv,
                w,
                w,
                false,
            );
            sized(&mut blk.bj, rv * w);
            mm(
                &mut blk.bj,
                w,
                View::rows(&blk.vb, w),
                View::rows(m1.rows(w, w), w),
                rv,
                w,
                w,
                false,
            );
            sized(&mut blk.hid, re * w);
            add_rows(&mut blk.hid, m1.b.as_deref().expect("bias"));
            for s in 0..n {
                for i in 0..K {
                    let ai = &blk.a[(s * K + i) * w..][..w];
                    for j in 0..K {
                        let bj = &blk.bj[(s * K + j) * w..][..w];
                        let row = &mut blk.hid[(s * D + i * K + j) * w..][..w];
                        for ((r, a), b) in row.iter_mut().zip(ai).zip(bj) {
                            *r += a + b;
                        }
                    }
                }
            }
            mm(
                &mut blk.hid,
                w,
                View::rows(&blk.eb, w),
                View::rows(m1.rows(2 * w, w), w),
                re,
                w,
                w,
                true,
            );
            activate(&mut blk.hid, &mut tape.d_hid, record);
            let m2 = &layer.edge_mlp2;
            sized(&mut tape.u, re * w);
            m2.apply(&blk.hid, &mut tape.u, re, true);

            // 3–5. Attention of node i over the slots j, values u_ij.
            sized(&mut tape.q, rv * w);
            layer.query.apply(&blk.vb, &mut tape.q, rv, true);
            sized(&mut tape.k, rv * w);
            layer.key.apply(&blk.vb, &mut tape.k, rv, true);
            let (h, hc) = (self.heads, w / self.heads);
            sized(&mut tape.alpha, n * h * D);
            sized(&mut blk.msg, rv * w);
            for s in 0..n {
                for hh in 0..h {
                    for i in 0..K {
                        let qi = &tape.q[(s * K + i) * w + hh * hc..][..hc];
                        let al = &mut tape.alpha[((s * h + hh) * K + i) * K..][..K];
                        for (j, a) in al.iter_mut().enumerate() {
                            let kj = &tape.k[(s * K + j) * w + hh * hc..][..hc];
                            *a = qi.iter().zip(kj).map(|(x, y)| x * y).sum::<f32>() * self.scale;
                        }
                        let mx = al.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                        let mut z = 0.0;
                        for a in al.iter_mut() {
                            *a = (*a - mx).exp();
                            z += *a;
                        }
                        al.iter_mut().for_each(|a| *a /= z);
                        let dst = &mut blk.msg[(s * K + i) * w + hh * hc..][..hc];
                        for (j, &a) in al.iter().enumerate() {
                            let uij = &tape.u[(s * D + i * K + j) * w + hh * hc..][..hc];
                            dst.iter_mut().zip(uij).for_each(|(d, u)| *d += a * u);
                        }
                    }
                }
            }
            // 6. Self term: v₁ = msg + SiLU(W_s v + b_s).
            sized(&mut blk.st, rv * w);
            layer.self_term.apply(&blk.vb, &mut blk.st, rv, true);
            activate(&mut blk.st, &mut tape.d_self, record);
            add_into(&mut blk.msg, &blk.st);
            // 7–8. Max-pool over the nodes and the node output.
            sized(&mut blk.pool, n * w);
            tape.argmax.clear();
            tape.argmax.resize(n * w, 0);
            for s in 0..n {
                for c in 0..w {
                    let (mut best, mut at) = (f32::NEG_INFINITY, 0u8);
                    for i in 0..K {
                        let x = blk.msg[(s * K + i) * w + c];
                        if x > best {
                            (best, at) = (x, i as u8);
                        }
                    }
                    blk.pool[s * w + c] = best;
                    tape.argmax[s * w + c] = at;
                }
            }
            let no = &layer.node_out;
            sized(&mut blk.pooled, n * w);
            add_rows(&mut blk.pooled, no.b.as_deref().expect("bias"));
            mm(
                &mut blk.pooled,
                w,
                View::rows(&blk.pool, w),
                View::rows(no.rows(w, w), w),
                n,
                w,
                w,
                true,
            );
            let out = &mut blk.hs[l + 1];
            sized(out, rv * w);
            add_per_sample(out, &blk.pooled, K, w);
            mm(
                out,
                w,
                View::rows(&blk.msg, w),
                View::rows(no.rows(0, w), w),
                rv,
                w,
                w,
                true,
            );
            activate(out, &mut tape.d_out, record);
            // The next layer's edge input and the wide skip's rows.
            blk.g.clear();
            blk.g.extend_from_slice(&tape.u);
            sized(&mut blk.gs[l + 1], ru * w);
            gather_upper(&mut blk.gs[l + 1], &tape.u, n, w);
        }

        // Wide skips and heads.
        sized(&mut blk.hw, rv * w);
        add_rows(&mut blk.hw, self.node_wide.b.as_deref().expect("bias"));
        for (l, h) in blk.hs.iter().enumerate() {
            mm(
                &mut blk.hw,
                w,
                View::rows(h, w),
                View::rows(self.node_wide.rows(l * w, w), w),
                rv,
                w,
                w,
                true,
            );
        }
        sized(&mut blk.gw, ru * w);
        add_rows(&mut blk.gw, self.edge_wide.b.as_deref().expect("bias"));
        for (l, g) in blk.gs.iter().enumerate() {
            mm(
                &mut blk.gw,
                w,
                View::rows(g, w),
                View::rows(self.edge_wide.rows(l * w, w), w),
                ru,
                w,
                w,
                true,
            );
        }
        let heads = self.node_heads.len() + self.edge_heads.len();
        blk.head_acts.resize_with(heads, Vec::new);
        for (k, (&(o, _), head)) in NODE_SLICES.iter().zip(&self.node_heads).enumerate() {
            let acts = &mut blk.head_acts[if record { k } else { 0 }];
            head.forward(
                &blk.hw,
                View::cols(v, NODE_DIM, o),
                &mut eps_v[o..],
                NODE_DIM,
                rv,
                w,
                acts,
            );
        }
        let base = self.node_heads.len();
        for (k, (&(o, _), head)) in EDGE_SLICES.iter().zip(&self.edge_heads).enumerate() {
            let acts = &mut blk.head_acts[if record { base + k } else { 0 }];
            head.forward(
                &blk.gw,
                View::cols(e, EDGE_DIM, o),
                &mut eps_e[o..],
                EDGE_DIM,
                ru,
                w,
                acts,
            );
        }
        blk.recorded = record;
    }
}

/// SiLU in place; with `record`, its derivative at the input into `deriv`.
fn activate(x: &mut [f32], deriv: &mut Vec<f32>, record: bool) {
    if record {
        sized(deriv, x.len());
        silu_with_deriv(x, deriv);
    } else {
        silu(x);
    }
}

mod backward;
mod head;
use head::Head;

#[cfg(test)]
mod tests;
