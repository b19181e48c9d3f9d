//! A value-only copy of the SDF decoder ([`ShapeDecoder`]) in plain `f32` buffers, evaluated in
//! cache-sized row blocks: the fast path for every decode that needs numbers and no gradient.
//!
//! ```text
//! h₀ = γ(q) W_p + b_p + (z W_c + b_c)                 (z W_c + b_c once per code)
//! h_{l+1} = h_l + (ReLU(ReLU(h_l) W₀ + b₀)) W₁ + b₁    (a bias-free shortcut S h_l if widths differ)
//! f(q; z) = LeakyReLU₀.₂(h_L) · w_out + b_out
//! ```
//!
//! Why it exists: guidance spends most of its time in passes that only *read* the SDF — the
//! ℓ_pen / ℓ_mob grids (to find the overlapping points) and ℓ_pc's assignment pass — and the
//! mesher and the metrics read it too. Through burn each layer is a separate tensor op over
//! the whole batch (tens of thousands of rows × 128 channels, megabytes that leave the cache
//! between ops). Here one block of [`BLOCK_ROWS`] rows runs through the whole network while its
//! activations stay in L1/L2, the bias and residual additions are folded into the GEMM (`gemm`
//! crate, the kernel burn's Flex backend uses too), and blocks run in parallel on the current
//! rayon pool. Same function as [`ShapeDecoder::sdf_with_features`] up to float summation order
//! (tested to 1e-5 relative).
//!
//! It also gives the *input* gradients of f per row ([`HostDecoder::eval_with_grads`]): a batch
//! row depends only on its own point and code, so one backward pass seeded with ones yields
//! ∂f/∂q [Q, 3] and ∂f/∂h₀ [Q, hidden] (h₀'s code term is z W_c + b_c, so ∂f/∂z = W_cᵀ ∂f/∂h₀)
//! at the cost of one more GEMM per layer and no weight gradients:
//!
//! ```text
//! g_L = w_out ⊙ LeakyReLU'(h_L)
//! g_l = (g_{l+1} or g_{l+1} Sᵀ) + ((g_{l+1} W₁ᵀ ⊙ [t > 0]) W₀ᵀ) ⊙ [h_l > 0]
//! ∂f/∂γ = g₀ W_pᵀ,   ∂f/∂q_c = ∂f/∂γ_c + Σ_f 2^f (−sin(2^f q_c) ∂f/∂cos_cf + cos(2^f q_c) ∂f/∂sin_cf)
//! ```
//!
//! Guidance's differentiable SDF passes use these through a first-order surrogate in burn
//! (`engine::guidance::field`), instead of recording every decoder layer on burn's autodiff tape.
//!
//! Training: [`HostDecoder::weight_grads`] runs the same backward pass seeded with the loss's
//! upstream gradient u_r = ∂L/∂f_r per row (g_L = u_r · w_out ⊙ LeakyReLU'(h_L)) and also sums
//! the weight gradients of every layer on the way:
//!
//! ```text
//! ∂w_out = Σ_r u_r LeakyReLU(h_L),  ∂W₁ = Σ_r t_lᵀ g_{l+1},  ∂W₀ = Σ_r ReLU(h_l)ᵀ a_l,
//! ∂S = Σ_r h_lᵀ g_{l+1},  ∂W_p = Σ_r γᵀ g₀,  ∂b = Σ_r (the layer's output gradient),
//! ∂features_i = Σ_{r: idx_r = i} g₀,   a_l = (g_{l+1} W₁ᵀ) ⊙ [t_l > 0]
//! ```
//!
//! The shape prior's trainer (`train::shape`) hands these to burn through a surrogate
//! Σ W ⊙ sg(∂W) whose gradient is exactly them, so burn's tape holds the encoder only.

use rayon::prelude::*;

use super::kernels::{HostLinear, add_into, matmul_at_acc, matmul_bt_acc};

use super::shape_prior::ShapeDecoder;

/// Rows per block: 128 rows × 128 channels × 4 B = 64 KiB per activation buffer.
pub const BLOCK_ROWS: usize = 128;

/// Blocks per gradient group of [`HostDecoder::weight_grads`]: each group sums its blocks'
/// weight gradients into its own buffers (one allocation of all gradients per group).
pub const GROUP_BLOCKS: usize = 8;

/// ReLU's backward pass: zero `g` where the matching entry of `x` (the ReLU's input, or its
/// output) is ≤ 0. Written as a select, not a conditional store, so that it vectorises on the
/// baseline x86-64 target (the conditional store did not: 8 % of a `train shape` step in
/// `perf`, BENCHMARKS.md "Faster training steps"); the same values bit for bit, NaN included.
fn relu_backward(g: &mut [f32], x: &[f32]) {
    for (g, &x) in g.iter_mut().zip(x) {
        *g = if x <= 0.0 { 0.0 } else { *g };
    }
}

/// One residual block.
#[derive(Debug, Clone)]
struct HostBlock {
    fc_0: HostLinear,
    fc_1: HostLinear,
    shortcut: Option<HostLinear>,
}

/// Per-thread activation buffers for one block of rows. With gradients every layer's input and
/// hidden activation is kept (the backward pass reads them) and gradient buffers exist; without,
/// one h buffer is updated in place and one t buffer reused, so the working set stays in cache.
struct Scratch {
    /// Whether every layer's activations are kept.
    keep: bool,
    /// γ(q) [rows, pe_dim].
    pe: Vec<f32>,
    /// h_0 … h_L (kept) or the one buffer updated in place, each [rows, width]; see
    /// [`Scratch::slot`].
    hs: Vec<Vec<f32>>,
    /// t_l = ReLU(ReLU(h_l) W₀ + b₀) per block (kept) or one buffer, [rows, width].
    ts: Vec<Vec<f32>>,
    /// ReLU(h_l) in the forward pass; g W₁ᵀ in the backward pass.
    a: Vec<f32>,
    /// Backward: ∂f/∂h_l and the next one, [rows, width] (empty for value-only scratch).
    g: Vec<f32>,
    g_next: Vec<f32>,
    /// Backward: ∂f/∂γ [rows, pe_dim].
    g_pe: Vec<f32>,
}

impl Scratch {
    /// Index of h_l in `hs`.
    fn slot(&self, l: usize) -> usize {
        if self.keep { l } else { 0 }
    }

    /// Index of t_l in `ts`.
    fn t_slot(&self, l: usize) -> usize {
        if self.keep { l } else { 0 }
    }
}

/// `(&v[i], &mut v[j])` for i ≠ j.
fn read_write(v: &mut [Vec<f32>], i: usize, j: usize) -> (&[f32], &mut [f32]) {
    if i < j {
        let (lo, hi) = v.split_at_mut(j);
        (&lo[i], &mut hi[0])
    } else {
        let (lo, hi) = v.split_at_mut(i);
        (&hi[0], &mut lo[j])
    }
}

/// Per-row values and input gradients of the decoder ([`HostDecoder::eval_with_grads`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct InputGrads {
    /// f per row, [Q] (equal to [`HostDecoder::eval`]'s output).
    pub values: Vec<f32>,
    /// ∂f/∂q per row, [Q].
    pub d_points: Vec<[f32; 3]>,
    /// ∂f/∂(code features) per row, [Q × feature_width] flat: the gradient with respect to the
    /// row's code features (z W_c + b_c; ∂f/∂h₀ for row 0, ∂f/∂h_l for block l's row).
    pub d_features: Vec<f32>,
}

/// Gradient of a loss with respect to one linear layer: `w` [d_in × d_out] flat (the layer's
/// layout), `b` [d_out] when the layer has a bias.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearGrad {
    /// ∂L/∂W.
    pub w: Vec<f32>,
    /// ∂L/∂b.
    pub b: Option<Vec<f32>>,
}

impl LinearGrad {
    fn zeros(l: &HostLinear) -> Self {
        LinearGrad {
            w: vec![0.0; l.w.len()],
            b: l.b.as_ref().map(|b| vec![0.0; b.len()]),
        }
    }

    fn add(&mut self, other: &LinearGrad) {
        add_into(&mut self.w, &other.w);
        if let (Some(a), Some(b)) = (&mut self.b, &other.b) {
            add_into(a, b);
        }
    }
}

/// `dst` [n] += Σ_r `g`[r, ·] over the rows of `g` [rows, n] (a bias gradient).
fn col_sums_acc(dst: &mut [f32], g: &[f32], rows: usize) {
    let n = dst.len();
    for row in g[..rows * n].chunks_exact(n) {
        add_into(dst, row);
    }
}

/// Values and weight gradients of a loss L for upstream gradients u_r = ∂L/∂f_r
/// ([`HostDecoder::weight_grads`]).
#[derive(Debug, Clone, PartialEq)]
pub struct WeightGrads {
    /// f per row, [Q].
    pub values: Vec<f32>,
    /// ∂L/∂(code features) per part, [P × hidden] flat: W_c's and b_c's gradients (and the
    /// code's) follow from it by the chain rule through z W_c + b_c.
    pub d_features: Vec<f32>,
    /// ∂L/∂ of every other layer, in the decoder's field order: `fc_p`, then per residual
    /// block `fc_0`, `fc_1` and `shortcut` when the block has one, then `fc_out` (`fc_c` is
    /// not among them, see `d_features`).
    pub layers: Vec<LinearGrad>,
}

/// The decoder's weights on the host (see the module docs).
#[derive(Debug, Clone)]
pub struct HostDecoder {
    fc_p: HostLinear,
    fc_c: HostLinear,
    blocks: Vec<HostBlock>,
    fc_out: HostLinear,
    pe_freqs: usize,
    /// Widest activation (hidden, or a block's width).
    width: usize,
    /// Code-feature rows of `hidden` (1, or one per block with `code_every_block`).
    code_rows: usize,
}

impl HostDecoder {
    /// Copy `decoder`'s weights.
    pub fn new(decoder: &ShapeDecoder) -> Self {
        let blocks: Vec<HostBlock> = decoder
            .blocks
            .iter()
            .map(|b| HostBlock {
                fc_0: HostLinear::new(&b.fc_0),
                fc_1: HostLinear::new(&b.fc_1),
                shortcut: b.shortcut.as_ref().map(HostLinear::new),
            })
            .collect();
        let fc_p = HostLinear::new(&decoder.fc_p);
        let width = blocks
            .iter()
            .flat_map(|b| [b.fc_0.d_in, b.fc_0.d_out, b.fc_1.d_out])
            .fold(fc_p.d_out, usize::max);
        let fc_c = HostLinear::new(&decoder.fc_c);
        let code_rows = fc_c.d_out / fc_p.d_out;
        HostDecoder {
            code_rows,
            fc_p,
            fc_c,
            blocks,
            fc_out: HostLinear::new(&decoder.fc_out),
            pe_freqs: decoder.pe_freqs,
            width,
        }
    }

    /// Code width F.
    pub fn latent(&self) -> usize {
        self.fc_c.d_in
    }

    /// Hidden width (of the first layer; the code features' width).
    pub fn hidden(&self) -> usize {
        self.fc_p.d_out
    }

    /// Width of one part's code features: hidden · rows (rows = 1, or one per block with
    /// `code_every_block`).
    pub fn feature_width(&self) -> usize {
        self.fc_c.d_out
    }

    /// z W_c + b_c for `codes` [P, F] (flat) → [P, feature_width] (flat).
    pub fn code_features(&self, codes: &[f32]) -> Vec<f32> {
        let p = codes.len() / self.latent();
        let mut out = vec![0.0; p * self.feature_width()];
        self.fc_c.apply(codes, &mut out, p, false);
        out
    }

    fn check_inputs(&self, q: &[[f32; 3]], features: &[f32], idx: &[usize]) {
        assert_eq!(q.len(), idx.len(), "one part index per point");
        let fw = self.feature_width();
        assert!(
            idx.iter().all(|&i| (i + 1) * fw <= features.len()),
            "part index past the code features"
        );
    }

    /// f at normalised points `q` for the code features `features[idx[r]]` (rows of
    /// [`HostDecoder::code_features`]) → `out` [Q]. Blocks of rows run in parallel on the
    /// current rayon pool.
    ///
    /// # Panics
    /// When `idx`, `q` and `out` differ in length or an index is past the features.
    pub fn eval(&self, q: &[[f32; 3]], features: &[f32], idx: &[usize], out: &mut [f32]) {
        self.check_inputs(q, features, idx);
        assert_eq!(q.len(), out.len(), "one output per point");
        out.par_chunks_mut(BLOCK_ROWS)
            .zip(q.par_chunks(BLOCK_ROWS))
            .zip(idx.par_chunks(BLOCK_ROWS))
            .for_each_init(
                || self.scratch(false),
                |s, ((o, q), idx)| self.forward_block(q, features, idx, o, s),
            );
    }

    /// [`HostDecoder::eval`] plus the input gradients of every row (module docs), without
    /// any weight gradient.
    ///
    /// # Panics
    /// When `idx` and `q` differ in length or an index is past the features.
    pub fn eval_with_grads(&self, q: &[[f32; 3]], features: &[f32], idx: &[usize]) -> InputGrads {
        self.check_inputs(q, features, idx);
        let fw = self.feature_width();
        let mut g = InputGrads {
            values: vec![0.0; q.len()],
            d_points: vec![[0.0; 3]; q.len()],
            d_features: vec![0.0; q.len() * fw],
        };
        g.values
            .par_chunks_mut(BLOCK_ROWS)
            .zip(g.d_points.par_chunks_mut(BLOCK_ROWS))
            .zip(g.d_features.par_chunks_mut(BLOCK_ROWS * fw))
            .zip(q.par_chunks(BLOCK_ROWS))
            .zip(idx.par_chunks(BLOCK_ROWS))
            .for_each_init(
                || self.scratch(true),
                |s, ((((o, dq), dh), q), idx)| {
                    self.forward_block(q, features, idx, o, s);
                    self.backward_block(q, dq, dh, s);
                },
            );
        g
    }

    fn layers(&self) -> Vec<&HostLinear> {
        let mut out = vec![&self.fc_p];
        for b in &self.blocks {
            out.push(&b.fc_0);
            out.push(&b.fc_1);
            out.extend(b.shortcut.as_ref());
        }
        out.push(&self.fc_out);
        out
    }

    /// The training pass: values f_r and the gradients of a loss L with ∂L/∂f_r =
    /// `upstream(r, f_r)` with respect to every weight and to the code features (module docs,
    /// "Training"), for `features` [P × hidden] with P = `features.len() / hidden`. `upstream`
    /// sees each row's value as soon as the forward pass has it, so one pass does both.
    ///
    /// Rows run in fixed groups of [`GROUP_BLOCKS`] blocks on the current rayon pool, and the
    /// groups' gradients are summed in group order, so the result does not depend on the
    /// thread count or on scheduling.
    ///
    /// # Panics
    /// When `idx`, `q` and `upstream` differ in length or an index is past the features.
    pub fn weight_grads(
        &self,
        q: &[[f32; 3]],
        features: &[f32],
        idx: &[usize],
        upstream: &(dyn Fn(usize, f32) -> f32 + Sync),
    ) -> WeightGrads {
        self.grads(q, features, idx, upstream, true)
    }

    /// [`HostDecoder::weight_grads`] without the weights' gradients (`layers` is empty): the
    /// values and ∂L/∂(code features) alone, what fitting a code with the decoder frozen
    /// needs: the backward pass skips every weight-gradient product.
    ///
    /// # Panics
    /// As [`HostDecoder::weight_grads`].
    pub fn feature_grads(
        &self,
        q: &[[f32; 3]],
        features: &[f32],
        idx: &[usize],
        upstream: &(dyn Fn(usize, f32) -> f32 + Sync),
    ) -> WeightGrads {
        self.grads(q, features, idx, upstream, false)
    }

    fn grads(
        &self,
        q: &[[f32; 3]],
        features: &[f32],
        idx: &[usize],
        upstream: &(dyn Fn(usize, f32) -> f32 + Sync),
        with_weights: bool,
    ) -> WeightGrads {
        self.check_inputs(q, features, idx);
        let fw = self.feature_width();
        let group_rows = GROUP_BLOCKS * BLOCK_ROWS;
        let zeros = || WeightGrads {
            values: Vec::new(),
            d_features: vec![0.0; features.len() / fw * fw],
            layers: if with_weights {
                self.layers().into_iter().map(LinearGrad::zeros).collect()
            } else {
                Vec::new()
            },
        };
        let groups: Vec<WeightGrads> = q
            .par_chunks(group_rows)
            .zip(idx.par_chunks(group_rows))
            .enumerate()
            .map(|(gi, (q, idx))| {
                let mut acc = zeros();
                let mut values = vec![0.0; q.len()];
                let mut up = vec![0.0; BLOCK_ROWS];
                let mut s = self.scratch(true);
                for (bi, ((q, idx), out)) in q
                    .chunks(BLOCK_ROWS)
                    .zip(idx.chunks(BLOCK_ROWS))
                    .zip(values.chunks_mut(BLOCK_ROWS))
                    .enumerate()
                {
                    self.forward_block(q, features, idx, out, &mut s);
                    let first = gi * group_rows + bi * BLOCK_ROWS;
                    for (r, (u, &f)) in up.iter_mut().zip(out.iter()).enumerate() {
                        *u = upstream(first + r, f);
                    }
                    self.backward_weights(idx, &up[..q.len()], &mut s, &mut acc, with_weights);
                }
                acc.values = values;
                acc
            })
            .collect();
        let mut total = zeros();
        total.values.reserve(q.len());
        for g in &groups {
            total.values.extend_from_slice(&g.values);
            add_into(&mut total.d_features, &g.d_features);
            for (t, l) in total.layers.iter_mut().zip(&g.layers) {
                t.add(l);
            }
        }
        total
    }

    /// The backward pass of the block just run by [`HostDecoder::forward_block`], seeded with
    /// `up` (∂L/∂f per row): accumulates the weight gradients and ∂L/∂features into `acc`.
    ///
    /// With `with_weights` false only ∂L/∂features is accumulated (`acc.layers` may be empty).
    fn backward_weights(
        &self,
        idx: &[usize],
        up: &[f32],
        s: &mut Scratch,
        acc: &mut WeightGrads,
        with_weights: bool,
    ) {
        let rows = idx.len();
        let n_blocks = self.blocks.len();
        let last = self.blocks.last().map_or(self.hidden(), |b| b.fc_1.d_out);
        // Layer index into acc.layers (counts down; unused without the weights' gradients).
        let mut layer = self.layers().len() - 1;
        // f = LeakyReLU(h_L) w_out + b_out: ∂w_out = Σ_r u_r LeakyReLU(h_L,r), ∂b_out = Σ_r u_r,
        // g_L = u_r w_out ⊙ LeakyReLU'(h_L).
        let w = &self.fc_out.w;
        for (r, ((g, h), &u)) in s.g[..rows * last]
            .chunks_exact_mut(last)
            .zip(s.hs[n_blocks].chunks_exact(last))
            .zip(up)
            .enumerate()
        {
            for ((g, &h), &w) in g.iter_mut().zip(h).zip(w) {
                *g = u * if h >= 0.0 { 1.0 } else { 0.2 } * w;
            }
            if with_weights {
                let out = &mut acc.layers[layer];
                let h = &s.hs[n_blocks][r * last..(r + 1) * last];
                for (dw, &h) in out.w.iter_mut().zip(h) {
                    *dw += u * if h >= 0.0 { h } else { 0.2 * h };
                }
                if let Some(db) = &mut out.b {
                    db[0] += u;
                }
            }
        }
        for (l, b) in self.blocks.iter().enumerate().rev() {
            let (w_in, mid, w_out) = (b.fc_0.d_in, b.fc_0.d_out, b.fc_1.d_out);
            if b.shortcut.is_some() {
                // ∂S = h_lᵀ g.
                if with_weights {
                    let sc = &mut acc.layers[layer - 1];
                    matmul_at_acc(&mut sc.w, &s.hs[l], &s.g, w_in, rows, w_out);
                }
                layer -= 1;
            }
            // ∂W₁ = t_lᵀ g, ∂b₁ = Σ_r g.
            if with_weights {
                let fc_1 = &mut acc.layers[layer - 1];
                matmul_at_acc(&mut fc_1.w, &s.ts[l], &s.g, mid, rows, w_out);
                if let Some(db) = &mut fc_1.b {
                    col_sums_acc(db, &s.g, rows);
                }
            }
            // a = (g W₁ᵀ) ⊙ [t_l > 0]; ∂W₀ = ReLU(h_l)ᵀ a, ∂b₀ = Σ_r a.
            s.a[..rows * mid].fill(0.0);
            matmul_bt_acc(&mut s.a, &s.g, &b.fc_1.w, rows, w_out, mid);
            relu_backward(&mut s.a[..rows * mid], &s.ts[l]);
            if with_weights {
                s.g_next[..rows * w_in]
                    .iter_mut()
                    .zip(&s.hs[l][..rows * w_in])
                    .for_each(|(r, &h)| *r = h.max(0.0));
                let fc_0 = &mut acc.layers[layer - 2];
                matmul_at_acc(&mut fc_0.w, &s.g_next, &s.a, w_in, rows, mid);
                if let Some(db) = &mut fc_0.b {
                    col_sums_acc(db, &s.a, rows);
                }
            }
            layer -= 2;
            // g_next = (a W₀ᵀ) ⊙ [h_l > 0] + (g or g Sᵀ).
            s.g_next[..rows * w_in].fill(0.0);
            matmul_bt_acc(&mut s.g_next, &s.a, &b.fc_0.w, rows, mid, w_in);
            relu_backward(&mut s.g_next[..rows * w_in], &s.hs[l]);
            match &b.shortcut {
                Some(sc) => matmul_bt_acc(&mut s.g_next, &s.g, &sc.w, rows, w_out, w_in),
                None => add_into(&mut s.g_next[..rows * w_in], &s.g[..rows * w_in]),
            }
            std::mem::swap(&mut s.g, &mut s.g_next);
            // Block l's input carries code row l (l ≥ 1): ∂features_i[row l] += Σ_{idx=i} g_l.
            if l > 0 && l < self.code_rows {
                self.add_feature_grads(idx, l, &s.g, &mut acc.d_features);
            }
        }
        debug_assert_eq!(layer, 1, "every layer but fc_p visited");
        // h₀ = features[idx] + γ W_p + b_p: ∂W_p = γᵀ g₀, ∂b_p = Σ_r g₀, ∂features[i] = Σ_{idx=i} g₀.
        let hidden = self.hidden();
        let pe_dim = self.fc_p.d_in;
        if with_weights {
            let fc_p = &mut acc.layers[0];
            matmul_at_acc(&mut fc_p.w, &s.pe, &s.g, pe_dim, rows, hidden);
            if let Some(db) = &mut fc_p.b {
                col_sums_acc(db, &s.g, rows);
            }
        }
        self.add_feature_grads(idx, 0, &s.g, &mut acc.d_features);
    }

    /// `d_features[idx_r][row] += g_r` for every row r of the block (g: [rows, hidden]).
    fn add_feature_grads(&self, idx: &[usize], row: usize, g: &[f32], d_features: &mut [f32]) {
        let (hidden, fw) = (self.hidden(), self.feature_width());
        for (r, &i) in idx.iter().enumerate() {
            let at = i * fw + row * hidden;
            add_into(
                &mut d_features[at..at + hidden],
                &g[r * hidden..(r + 1) * hidden],
            );
        }
    }

    /// `d_features[r][row] = g_r` for the block's rows (per-row input gradients).
    fn copy_feature_grads(&self, rows: usize, row: usize, g: &[f32], d_features: &mut [f32]) {
        let (hidden, fw) = (self.hidden(), self.feature_width());
        for r in 0..rows {
            let at = r * fw + row * hidden;
            d_features[at..at + hidden].copy_from_slice(&g[r * hidden..(r + 1) * hidden]);
        }
    }

    fn scratch(&self, grads: bool) -> Scratch {
        let pe_dim = self.fc_p.d_in;
        let buf = |n: usize| vec![0.0; BLOCK_ROWS * n];
        let (g, g_pe) = if grads {
            (buf(self.width), buf(pe_dim))
        } else {
            (Vec::new(), Vec::new())
        };
        let (n_h, n_t) = if grads {
            (self.blocks.len() + 1, self.blocks.len())
        } else {
            (1, 1)
        };
        Scratch {
            keep: grads,
            pe: buf(pe_dim),
            hs: (0..n_h).map(|_| buf(self.width)).collect(),
            ts: (0..n_t).map(|_| buf(self.width)).collect(),
            a: buf(self.width),
            g_next: g.clone(),
            g,
            g_pe,
        }
    }

    /// One block of at most [`BLOCK_ROWS`] rows through the whole network (every layer's
    /// activations stay in `s` when it keeps them).
    fn forward_block(
        &self,
        q: &[[f32; 3]],
        features: &[f32],
        idx: &[usize],
        out: &mut [f32],
        s: &mut Scratch,
    ) {
        let rows = q.len();
        let nf = self.pe_freqs;
        let pe_dim = self.fc_p.d_in;
        // γ(q): [x, y, z, cos(2^f q_c) (c-major), sin(2^f q_c)] (shape_prior::positional_encoding).
        for (r, p) in q.iter().enumerate() {
            let row = &mut s.pe[r * pe_dim..(r + 1) * pe_dim];
            row[..3].copy_from_slice(p);
            for (c, &v) in p.iter().enumerate() {
                let mut scale = 1.0f32;
                for f in 0..nf {
                    let x = v * scale;
                    row[3 + c * nf + f] = x.cos();
                    row[3 + 3 * nf + c * nf + f] = x.sin();
                    scale *= 2.0;
                }
            }
        }
        // h₀ = features[idx] (row 0) + γ W_p + b_p.
        let (hidden, fw) = (self.hidden(), self.feature_width());
        for (r, &i) in idx.iter().enumerate() {
            s.hs[0][r * hidden..(r + 1) * hidden]
                .copy_from_slice(&features[i * fw..i * fw + hidden]);
        }
        self.fc_p.apply(&s.pe, &mut s.hs[0], rows, true);
        let mut width = hidden;
        for (l, b) in self.blocks.iter().enumerate() {
            let (i, k) = (s.slot(l), s.t_slot(l));
            // Code row l joins block l's input (l ≥ 1, `code_every_block`).
            if l > 0 && l < self.code_rows {
                for (r, &p) in idx.iter().enumerate() {
                    let at = p * fw + l * hidden;
                    add_into(
                        &mut s.hs[i][r * hidden..(r + 1) * hidden],
                        &features[at..at + hidden],
                    );
                }
            }
            // a = ReLU(h_l); t_l = ReLU(a W₀ + b₀).
            let n_in = rows * width;
            s.a[..n_in]
                .iter_mut()
                .zip(&s.hs[i][..n_in])
                .for_each(|(a, h)| *a = h.max(0.0));
            let t = &mut s.ts[k];
            b.fc_0.apply(&s.a, t, rows, false);
            t[..rows * b.fc_0.d_out]
                .iter_mut()
                .for_each(|v| *v = v.max(0.0));
            // h_{l+1} = (h_l or S h_l) + t_l W₁ + b₁: into the next kept buffer, or in place.
            if s.keep {
                let (h, h_next) = read_write(&mut s.hs, l, l + 1);
                match &b.shortcut {
                    Some(sc) => sc.apply(h, h_next, rows, false),
                    None => h_next[..n_in].copy_from_slice(&h[..n_in]),
                }
                b.fc_1.apply(&s.ts[k], h_next, rows, true);
            } else {
                if let Some(sc) = &b.shortcut {
                    sc.apply(&s.hs[0], &mut s.a, rows, false);
                    std::mem::swap(&mut s.hs[0], &mut s.a);
                }
                b.fc_1.apply(&s.ts[k], &mut s.hs[0], rows, true);
            }
            width = b.fc_1.d_out;
        }
        let h = &s.hs[s.slot(self.blocks.len())];
        let w = &self.fc_out.w;
        let bias = self.fc_out.b.as_ref().map_or(0.0, |b| b[0]);
        for (r, o) in out.iter_mut().enumerate() {
            let h = &h[r * width..(r + 1) * width];
            *o = h
                .iter()
                .zip(w)
                .map(|(&h, &w)| if h >= 0.0 { h } else { 0.2 * h } * w)
                .sum::<f32>()
                + bias;
        }
    }

    /// The backward pass of the block just run by [`HostDecoder::forward_block`] (module docs),
    /// seeded with ∂f/∂f = 1 per row: writes ∂f/∂q into `d_points` and ∂f/∂(code features)
    /// into `d_features` [rows × feature_width] (row 0: ∂f/∂h₀; row l: ∂f/∂h_l).
    fn backward_block(
        &self,
        q: &[[f32; 3]],
        d_points: &mut [[f32; 3]],
        d_features: &mut [f32],
        s: &mut Scratch,
    ) {
        let rows = q.len();
        let last = self.blocks.last().map_or(self.hidden(), |b| b.fc_1.d_out);
        // g_L = w_out ⊙ LeakyReLU'(h_L).
        let w = &self.fc_out.w;
        for (g, h) in s.g[..rows * last]
            .chunks_exact_mut(last)
            .zip(s.hs[self.blocks.len()].chunks_exact(last))
        {
            for ((g, &h), &w) in g.iter_mut().zip(h).zip(w) {
                *g = if h >= 0.0 { w } else { 0.2 * w };
            }
        }
        for (l, b) in self.blocks.iter().enumerate().rev() {
            let (w_in, mid, w_out) = (b.fc_0.d_in, b.fc_0.d_out, b.fc_1.d_out);
            // a = (g W₁ᵀ) ⊙ [t_l > 0].
            s.a[..rows * mid].fill(0.0);
            matmul_bt_acc(&mut s.a, &s.g, &b.fc_1.w, rows, w_out, mid);
            relu_backward(&mut s.a[..rows * mid], &s.ts[l]);
            // g_next = (a W₀ᵀ) ⊙ [h_l > 0] + (g or g Sᵀ).
            s.g_next[..rows * w_in].fill(0.0);
            matmul_bt_acc(&mut s.g_next, &s.a, &b.fc_0.w, rows, mid, w_in);
            relu_backward(&mut s.g_next[..rows * w_in], &s.hs[l]);
            match &b.shortcut {
                Some(sc) => matmul_bt_acc(&mut s.g_next, &s.g, &sc.w, rows, w_out, w_in),
                None => s.g_next[..rows * w_in]
                    .iter_mut()
                    .zip(&s.g[..rows * w_in])
                    .for_each(|(n, g)| *n += g),
            }
            std::mem::swap(&mut s.g, &mut s.g_next);
            if l > 0 && l < self.code_rows {
                self.copy_feature_grads(rows, l, &s.g, d_features);
            }
        }
        let hidden = self.hidden();
        self.copy_feature_grads(rows, 0, &s.g, d_features);
        // ∂f/∂γ = g₀ W_pᵀ, then through γ to q.
        let (nf, pe_dim) = (self.pe_freqs, self.fc_p.d_in);
        s.g_pe[..rows * pe_dim].fill(0.0);
        matmul_bt_acc(&mut s.g_pe, &s.g, &self.fc_p.w, rows, hidden, pe_dim);
        for (r, (p, d)) in q.iter().zip(d_points.iter_mut()).enumerate() {
            let g = &s.g_pe[r * pe_dim..(r + 1) * pe_dim];
            for (c, &v) in p.iter().enumerate() {
                let mut acc = g[c];
                let mut scale = 1.0f32;
                for f in 0..nf {
                    let x = v * scale;
                    acc += scale
                        * (-x.sin() * g[3 + c * nf + f] + x.cos() * g[3 + 3 * nf + c * nf + f]);
                    scale *= 2.0;
                }
                d[c] = acc;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Tensor, TensorData};

    use super::*;
    use crate::data::rng::Rng;
    use crate::model::cpu;
    use crate::model::shape_prior::{ShapePriorConfig, tests::randomised};

    /// Random weights (the residual blocks' zero-initialised weights would hide bugs), random
    /// points and codes: the host path matches the burn decoder.
    #[test]
    fn matches_the_burn_decoder() {
        let small = ShapePriorConfig {
            latent: 16,
            decoder_hidden: 24,
            decoder_blocks: 3,
            encoder_hidden: 8,
            encoder_blocks: 1,
            pe_freqs: 4,
            code_every_block: false,
        };
        for cfg in [
            small,
            ShapePriorConfig {
                code_every_block: true,
                ..small
            },
            ShapePriorConfig {
                pe_freqs: 0,
                decoder_blocks: 0,
                ..ShapePriorConfig::default()
            },
            ShapePriorConfig::default(),
            ShapePriorConfig {
                code_every_block: true,
                ..ShapePriorConfig::default()
            },
        ] {
            let device = cpu();
            let mut rng = Rng::new(7);
            let dec = randomised(ShapeDecoder::new(&cfg, &mut rng, &device), 3);
            let host = HostDecoder::new(&dec);
            let (p, n) = (3, 300); // 900 rows: several blocks and a partial one
            let pts: Vec<[f32; 3]> = (0..p * n)
                .map(|_| std::array::from_fn(|_| rng.range(-0.6, 0.6) as f32))
                .collect();
            let codes: Vec<f32> = (0..p * cfg.latent)
                .map(|_| rng.range(-1.0, 1.0) as f32)
                .collect();
            let flat: Vec<f32> = pts.iter().flatten().copied().collect();
            let want: Vec<f32> = dec
                .sdf(
                    Tensor::<3>::from_data(TensorData::new(flat, [p, n, 3]), &device),
                    Tensor::<2>::from_data(
                        TensorData::new(codes.clone(), [p, cfg.latent]),
                        &device,
                    ),
                )
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            let idx: Vec<usize> = (0..p * n).map(|r| r / n).collect();
            let mut got = vec![0.0; p * n];
            host.eval(&pts, &host.code_features(&codes), &idx, &mut got);
            let scale = want.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            for (r, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    (g - w).abs() <= 1e-5 * scale.max(1.0),
                    "{cfg:?} row {r}: host {g} vs burn {w}"
                );
            }
        }
    }

    /// The fitting pass computes exactly the training pass's values and code-feature
    /// gradients, without the weights' gradients.
    #[test]
    fn feature_grads_are_the_training_pass_without_the_weights() {
        let cfg = ShapePriorConfig {
            latent: 16,
            decoder_hidden: 24,
            decoder_blocks: 3,
            encoder_hidden: 8,
            encoder_blocks: 1,
            pe_freqs: 4,
            code_every_block: true,
        };
        let mut rng = Rng::new(11);
        let dec = randomised(ShapeDecoder::new(&cfg, &mut rng, &cpu()), 5);
        let host = HostDecoder::new(&dec);
        let (p, n) = (3, 700); // several groups of blocks and a partial one
        let pts: Vec<[f32; 3]> = (0..p * n)
            .map(|_| std::array::from_fn(|_| rng.range(-0.6, 0.6) as f32))
            .collect();
        let codes: Vec<f32> = (0..p * cfg.latent)
            .map(|_| rng.range(-1.0, 1.0) as f32)
            .collect();
        let features = host.code_features(&codes);
        let idx: Vec<usize> = (0..p * n).map(|r| r / n).collect();
        let up = |r: usize, f: f32| (f - 0.01 * (r % 7) as f32).signum() / n as f32;
        let full = host.weight_grads(&pts, &features, &idx, &up);
        let lean = host.feature_grads(&pts, &features, &idx, &up);
        assert_eq!(full.values, lean.values);
        assert_eq!(full.d_features, lean.d_features);
        assert!(lean.layers.is_empty());
        assert!(full.d_features.iter().any(|g| *g != 0.0));
    }

    #[test]
    fn empty_input_is_empty_output() {
        let mut rng = Rng::new(1);
        let dec = ShapeDecoder::new(&ShapePriorConfig::default(), &mut rng, &cpu());
        let host = HostDecoder::new(&dec);
        let mut out: Vec<f32> = Vec::new();
        host.eval(&[], &host.code_features(&[]), &[], &mut out);
        assert!(out.is_empty());
    }
}
