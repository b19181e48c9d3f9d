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

use burn::nn::Linear;
use rayon::prelude::*;

use super::shape_prior::ShapeDecoder;

/// Rows per block: 128 rows × 128 channels × 4 B = 64 KiB per activation buffer.
pub const BLOCK_ROWS: usize = 128;

/// A linear layer: `w` [d_in, d_out] row-major (burn's layout), `b` [d_out] or none.
#[derive(Debug, Clone)]
struct HostLinear {
    w: Vec<f32>,
    b: Option<Vec<f32>>,
    d_in: usize,
    d_out: usize,
}

impl HostLinear {
    fn new(l: &Linear) -> Self {
        let [d_in, d_out] = l.weight.shape().dims::<2>();
        let w = l
            .weight
            .val()
            .into_data()
            .try_to_vec::<f32>()
            .expect("decoder weights are f32");
        let b = l.bias.as_ref().map(|b| {
            b.val()
                .into_data()
                .try_to_vec::<f32>()
                .expect("decoder biases are f32")
        });
        HostLinear { w, b, d_in, d_out }
    }

    /// `dst` [rows, d_out] = (accumulate ? dst : 0) + bias + `x` [rows, d_in] · W.
    fn apply(&self, x: &[f32], dst: &mut [f32], rows: usize, accumulate: bool) {
        if !accumulate {
            dst[..rows * self.d_out].fill(0.0);
        }
        if let Some(b) = &self.b {
            for r in dst[..rows * self.d_out].chunks_exact_mut(self.d_out) {
                r.iter_mut().zip(b).for_each(|(v, b)| *v += b);
            }
        }
        matmul_acc(dst, x, &self.w, rows, self.d_in, self.d_out);
    }
}

/// `dst` [m, n] += `a` [m, k] · `b` [k, n], all row-major and contiguous.
fn matmul_acc(dst: &mut [f32], a: &[f32], b: &[f32], m: usize, k: usize, n: usize) {
    assert!(dst.len() >= m * n && a.len() >= m * k && b.len() >= k * n);
    if m == 0 || n == 0 || k == 0 {
        return;
    }
    // SAFETY: the three buffers hold at least m·n, m·k and k·n elements (asserted above), the
    // strides describe contiguous row-major matrices inside them, and `dst` is a unique borrow
    // that does not alias `a` or `b`.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            true,
            a.as_ptr(),
            1,
            k as isize,
            b.as_ptr(),
            1,
            n as isize,
            1.0f32,
            1.0f32,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// One residual block.
#[derive(Debug, Clone)]
struct HostBlock {
    fc_0: HostLinear,
    fc_1: HostLinear,
    shortcut: Option<HostLinear>,
}

/// Per-thread activation buffers for one block of rows.
struct Scratch {
    pe: Vec<f32>,
    h: Vec<f32>,
    a: Vec<f32>,
    t: Vec<f32>,
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
        HostDecoder {
            fc_p,
            fc_c: HostLinear::new(&decoder.fc_c),
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

    /// z W_c + b_c for `codes` [P, F] (flat) → [P, hidden] (flat).
    pub fn code_features(&self, codes: &[f32]) -> Vec<f32> {
        let p = codes.len() / self.latent();
        let mut out = vec![0.0; p * self.hidden()];
        self.fc_c.apply(codes, &mut out, p, false);
        out
    }

    /// f at normalised points `q` for the code features `features[idx[r]]` (rows of
    /// [`HostDecoder::code_features`]) → `out` [Q]. Blocks of rows run in parallel on the
    /// current rayon pool.
    ///
    /// # Panics
    /// When `idx`, `q` and `out` differ in length or an index is past the features.
    pub fn eval(&self, q: &[[f32; 3]], features: &[f32], idx: &[usize], out: &mut [f32]) {
        assert_eq!(q.len(), idx.len(), "one part index per point");
        assert_eq!(q.len(), out.len(), "one output per point");
        let hidden = self.hidden();
        assert!(
            idx.iter().all(|&i| (i + 1) * hidden <= features.len()),
            "part index past the code features"
        );
        out.par_chunks_mut(BLOCK_ROWS)
            .zip(q.par_chunks(BLOCK_ROWS))
            .zip(idx.par_chunks(BLOCK_ROWS))
            .for_each_init(
                || self.scratch(),
                |s, ((o, q), idx)| self.eval_block(q, features, idx, o, s),
            );
    }

    fn scratch(&self) -> Scratch {
        let pe_dim = self.fc_p.d_in;
        Scratch {
            pe: vec![0.0; BLOCK_ROWS * pe_dim],
            h: vec![0.0; BLOCK_ROWS * self.width],
            a: vec![0.0; BLOCK_ROWS * self.width],
            t: vec![0.0; BLOCK_ROWS * self.width],
        }
    }

    /// One block of at most [`BLOCK_ROWS`] rows through the whole network.
    fn eval_block(
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
        // h = features[idx] + γ W_p + b_p.
        let hidden = self.hidden();
        for (r, &i) in idx.iter().enumerate() {
            s.h[r * hidden..(r + 1) * hidden]
                .copy_from_slice(&features[i * hidden..(i + 1) * hidden]);
        }
        self.fc_p.apply(&s.pe, &mut s.h, rows, true);
        let mut width = hidden;
        for b in &self.blocks {
            // a = ReLU(h); t = ReLU(a W₀ + b₀).
            let n_in = rows * width;
            s.a[..n_in]
                .iter_mut()
                .zip(&s.h[..n_in])
                .for_each(|(a, h)| *a = h.max(0.0));
            b.fc_0.apply(&s.a, &mut s.t, rows, false);
            s.t[..rows * b.fc_0.d_out]
                .iter_mut()
                .for_each(|v| *v = v.max(0.0));
            // h ← (h or S h) + t W₁ + b₁.
            if let Some(sc) = &b.shortcut {
                sc.apply(&s.h, &mut s.a, rows, false);
                std::mem::swap(&mut s.h, &mut s.a);
            }
            b.fc_1.apply(&s.t, &mut s.h, rows, true);
            width = b.fc_1.d_out;
        }
        let w = &self.fc_out.w;
        let bias = self.fc_out.b.as_ref().map_or(0.0, |b| b[0]);
        for (r, o) in out.iter_mut().enumerate() {
            let h = &s.h[r * width..(r + 1) * width];
            *o = h
                .iter()
                .zip(w)
                .map(|(&h, &w)| if h >= 0.0 { h } else { 0.2 * h } * w)
                .sum::<f32>()
                + bias;
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
        for cfg in [
            ShapePriorConfig {
                latent: 16,
                decoder_hidden: 24,
                decoder_blocks: 3,
                encoder_hidden: 8,
                encoder_blocks: 1,
                pe_freqs: 4,
            },
            ShapePriorConfig {
                pe_freqs: 0,
                decoder_blocks: 0,
                ..ShapePriorConfig::default()
            },
            ShapePriorConfig::default(),
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
