//! NAP's part-shape auto-encoder (method.md §4): a ResNet-PointNet encoder turns a part's surface
//! points into a latent code z; an OccNet-style residual MLP decodes (query, z) into the part's
//! SDF in its normalised frame (negative inside).
//!
//! Why it exists: the diffusion prior generates shape *codes*; this decoder turns them back into
//! geometry for meshing ([`LatentSdfDecoder`] implements [`LatentDecoder`]) and for PhysNAP's
//! guidance losses, which need d SDF / d point and d SDF / d code. [`ShapeDecoder::sdf`] therefore
//! takes every part and point of a step in one call ([P, N, 3] points, [P, F] codes) and is
//! differentiable in both inputs.
//!
//! One option departs from NAP: `code_every_block` adds a code feature W_c,l z + b_c,l to the
//! input of every residual block l (ConvONet's decoder), where NAP adds z W_c + b_c to the first
//! layer only; W_c then has `decoder_blocks` stacked outputs of `decoder_hidden`, row 0 being
//! NAP's. Off by default, and absent from manifests of NAP's decoder.
//!
//! Widths are configurable: [`ShapePriorConfig::nap`] is the paper's network (decoder 704,513
//! parameters, encoder 6,628,480), [`ShapePriorConfig::default`] a smaller one that trains on a
//! 2-core CPU in about an hour. Weights are initialised from our own seeded [`Rng`]
//! (PyTorch's default `nn.Linear` init, zeros for each residual block's second weight as in
//! OccNet), so a model is a pure function of (config, seed), independent of burn's global RNG.
//!
//! Thread safety: burn 0.22 tensors and modules are `Send + Sync` (checked at compile time
//! below), so the mesher can call one decoder from several rayon workers without a lock.

use burn::module::{Module, Param};
use burn::nn::Linear;
use burn::tensor::activation::{leaky_relu, relu};
use burn::tensor::{Device, Tensor, TensorData};

use super::ModelError;
use super::host_decoder::HostDecoder;
use crate::data::rng::Rng;
use crate::shape::{LatentDecoder, Sdf};

/// Sizes of the shape auto-encoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShapePriorConfig {
    /// Latent code width F (NAP: 128).
    pub latent: usize,
    /// Decoder width (NAP: 256).
    pub decoder_hidden: usize,
    /// Decoder residual blocks (NAP: 5).
    pub decoder_blocks: usize,
    /// Encoder width H; the first per-point layer is 2H wide (NAP: 512, first layer 1024).
    pub encoder_hidden: usize,
    /// Encoder residual blocks, the first without max-pool concatenation (NAP: 5).
    pub encoder_blocks: usize,
    /// Positional-encoding octaves N_pe (NAP: 8), γ(q) has 3 + 6·N_pe channels.
    pub pe_freqs: usize,
    /// Add a code feature W_c,l z to the input of every residual block l (ConvONet's decoder),
    /// not only to the first layer (NAP). W_c then maps z to `decoder_blocks` stacked feature
    /// rows of `decoder_hidden` each, the first being NAP's.
    pub code_every_block: bool,
}

impl Default for ShapePriorConfig {
    /// The CPU default: decoder 128 × 4 blocks, encoder 128 × 4 blocks, F = 128.
    fn default() -> Self {
        ShapePriorConfig {
            latent: 128,
            decoder_hidden: 128,
            decoder_blocks: 4,
            encoder_hidden: 128,
            encoder_blocks: 4,
            pe_freqs: 8,
            code_every_block: false,
        }
    }
}

/// Largest accepted width (latent, hidden).
pub const MAX_WIDTH: usize = 4096;
/// Largest accepted number of residual blocks.
pub const MAX_BLOCKS: usize = 32;
/// Largest accepted number of positional-encoding octaves (2^15 is still exact in f32).
pub const MAX_PE_FREQS: usize = 16;

impl ShapePriorConfig {
    /// NAP's sizes (method.md §4.2–4.3).
    pub fn nap() -> Self {
        ShapePriorConfig {
            latent: 128,
            decoder_hidden: 256,
            decoder_blocks: 5,
            encoder_hidden: 512,
            encoder_blocks: 5,
            pe_freqs: 8,
            code_every_block: false,
        }
    }

    /// Width of γ(q): 3 + 6·N_pe (51 for N_pe = 8).
    pub fn pe_dim(&self) -> usize {
        3 + 6 * self.pe_freqs
    }

    /// Code-feature rows of `decoder_hidden` the decoder adds: one per residual block with
    /// `code_every_block` (at least one), else one (the input's).
    pub fn code_rows(&self) -> usize {
        if self.code_every_block {
            self.decoder_blocks.max(1)
        } else {
            1
        }
    }

    /// Check that a decoder of `self`'s sizes can be grown from one of `from`'s
    /// ([`ShapeDecoder::grow`]): every size outside the decoder equal, and N_pe, the decoder
    /// width and its blocks each at least `from`'s. The error names the first field that
    /// differs or would shrink, its limit and value.
    pub fn check_decoder_growth(&self, from: &ShapePriorConfig) -> Result<(), ModelError> {
        let refuse = |field: &str, limit: String, value: String| {
            Err(ModelError::Config(crate::error::Invalid {
                field: field.into(),
                limit,
                value,
            }))
        };
        for (field, want, have) in [
            ("pe_freqs", self.pe_freqs, from.pe_freqs),
            ("decoder_hidden", self.decoder_hidden, from.decoder_hidden),
            ("decoder_blocks", self.decoder_blocks, from.decoder_blocks),
        ] {
            if want < have {
                return refuse(field, format!("at least {have}"), want.to_string());
            }
        }
        for (field, want, have) in [
            ("latent", self.latent, from.latent),
            ("encoder_hidden", self.encoder_hidden, from.encoder_hidden),
            ("encoder_blocks", self.encoder_blocks, from.encoder_blocks),
        ] {
            if want != have {
                return refuse(field, format!("{have}, as before"), want.to_string());
            }
        }
        if self.code_every_block != from.code_every_block {
            let have = from.code_every_block.to_string();
            return refuse("code_every_block", have, self.code_every_block.to_string());
        }
        Ok(())
    }

    /// Check every size against its range.
    pub fn validate(&self) -> Result<(), ModelError> {
        let check = |field: &str, value: usize, lo: usize, hi: usize| {
            if (lo..=hi).contains(&value) {
                Ok(())
            } else {
                Err(ModelError::Config(crate::error::Invalid {
                    field: field.into(),
                    limit: format!("between {lo} and {hi}"),
                    value: value.to_string(),
                }))
            }
        };
        check("latent", self.latent, 1, MAX_WIDTH)?;
        check("decoder_hidden", self.decoder_hidden, 1, MAX_WIDTH)?;
        check("decoder_blocks", self.decoder_blocks, 0, MAX_BLOCKS)?;
        check("encoder_hidden", self.encoder_hidden, 1, MAX_WIDTH)?;
        check("encoder_blocks", self.encoder_blocks, 1, MAX_BLOCKS)?;
        check("pe_freqs", self.pe_freqs, 0, MAX_PE_FREQS)
    }
}

/// A linear layer with PyTorch's default init, U(−1/√fan_in, 1/√fan_in) for weight and bias,
/// drawn from `rng`; `zero_weight` zeroes the weight (bias stays random, as OccNet does).
fn linear(
    d_in: usize,
    d_out: usize,
    bias: bool,
    zero_weight: bool,
    rng: &mut Rng,
    device: &Device,
) -> Linear {
    let bound = 1.0 / (d_in as f64).sqrt();
    let mut draw = |n: usize| -> Vec<f32> {
        (0..n)
            .map(|_| rng.range(-bound, bound) as f32)
            .collect::<Vec<_>>()
    };
    let w = if zero_weight {
        vec![0.0f32; d_in * d_out]
    } else {
        draw(d_in * d_out)
    };
    let weight = Param::from_data(TensorData::new(w, [d_in, d_out]), device);
    let bias = bias.then(|| Param::from_data(TensorData::new(draw(d_out), [d_out]), device));
    Linear { weight, bias }
}

/// γ(q) (method.md §4.1) of `q` = [M, 3]: [x, y, z, cos(2^f x)…, cos(2^f z)…, sin(2^f x)…],
/// coordinate-major within each block, frequencies 2^f (f = 0 … N_pe − 1), no π. → [M, 3 + 6 N_pe].
pub fn positional_encoding(q: Tensor<2>, pe_freqs: usize) -> Tensor<2> {
    if pe_freqs == 0 {
        return q;
    }
    let [m, _] = q.dims();
    let freqs: Vec<f32> = (0..pe_freqs).map(|f| (1u64 << f) as f32).collect();
    let freqs = Tensor::<3>::from_data(TensorData::new(freqs, [1, 1, pe_freqs]), &q.device());
    let scaled = (q.clone().unsqueeze_dim::<3>(2) * freqs).reshape([m, 3 * pe_freqs]);
    Tensor::cat(vec![q, scaled.clone().cos(), scaled.sin()], 1)
}

/// OccNet's `ResnetBlockFC`: x_s + fc_1(ReLU(fc_0(ReLU(x)))), x_s = x or a bias-free linear
/// shortcut when the width changes.
#[derive(Module, Debug)]
pub struct ResBlock {
    /// First linear (size_in → size_h).
    pub fc_0: Linear,
    /// Second linear (size_h → size_out), zero-initialised weight.
    pub fc_1: Linear,
    /// Bias-free shortcut when size_in ≠ size_out.
    pub shortcut: Option<Linear>,
}

impl ResBlock {
    fn new(size_in: usize, size_out: usize, rng: &mut Rng, device: &Device) -> Self {
        let size_h = size_in.min(size_out);
        ResBlock {
            fc_0: linear(size_in, size_h, true, false, rng, device),
            fc_1: linear(size_h, size_out, true, true, rng, device),
            shortcut: (size_in != size_out)
                .then(|| linear(size_in, size_out, false, false, rng, device)),
        }
    }

    /// Apply to [M, size_in] → [M, size_out].
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        let dx = self.fc_1.forward(relu(self.fc_0.forward(relu(x.clone()))));
        match &self.shortcut {
            Some(s) => s.forward(x) + dx,
            None => x + dx,
        }
    }
}

/// The SDF decoder (method.md §4.2).
#[derive(Module, Debug)]
pub struct ShapeDecoder {
    /// W_p: γ(q) → hidden.
    pub fc_p: Linear,
    /// W_c: code → hidden (conditioning by addition at the input).
    pub fc_c: Linear,
    /// Residual blocks (hidden → hidden, ReLU inside).
    pub blocks: Vec<ResBlock>,
    /// Output hidden → 1 after LeakyReLU(0.2).
    pub fc_out: Linear,
    /// N_pe.
    pub pe_freqs: usize,
}

impl ShapeDecoder {
    /// A freshly initialised decoder.
    pub fn new(cfg: &ShapePriorConfig, rng: &mut Rng, device: &Device) -> Self {
        let h = cfg.decoder_hidden;
        ShapeDecoder {
            fc_p: linear(cfg.pe_dim(), h, true, false, rng, device),
            fc_c: linear(cfg.latent, h * cfg.code_rows(), true, false, rng, device),
            blocks: (0..cfg.decoder_blocks)
                .map(|_| ResBlock::new(h, h, rng, device))
                .collect(),
            fc_out: linear(h, 1, true, false, rng, device),
            pe_freqs: cfg.pe_freqs,
        }
    }

    /// W_c z + b_c per part: [P, F] → [P, hidden · rows] (rows = 1, or one per block with
    /// `code_every_block`). Compute once per code and reuse with
    /// [`ShapeDecoder::sdf_with_features`].
    pub fn code_features(&self, codes: Tensor<2>) -> Tensor<2> {
        self.fc_c.forward(codes)
    }

    /// SDF of `points` [P, N, 3] (normalised part frame) for parts whose code features
    /// (from [`ShapeDecoder::code_features`]) are `features` [P, hidden · rows] → [P, N].
    /// Row 0 is added to the first layer's output, row l to block l's input (l ≥ 1).
    pub fn sdf_with_features(&self, points: Tensor<3>, features: Tensor<2>) -> Tensor<2> {
        let [p, n, _] = points.dims();
        let hidden = self.hidden();
        let rows = features.dims()[1] / hidden;
        let row = |l: usize| {
            features
                .clone()
                .narrow(1, l * hidden, hidden)
                .unsqueeze_dim::<3>(1)
        };
        let pe = positional_encoding(points.reshape([p * n, 3]), self.pe_freqs);
        let h = self.fc_p.forward(pe).reshape([p, n, hidden]) + row(0);
        let mut h = h.reshape([p * n, hidden]);
        for (l, block) in self.blocks.iter().enumerate() {
            if l > 0 && l < rows {
                h = (h.reshape([p, n, hidden]) + row(l)).reshape([p * n, hidden]);
            }
            h = block.forward(h);
        }
        self.fc_out.forward(leaky_relu(h, 0.2)).reshape([p, n])
    }

    /// SDF (negative inside) of `points` [P, N, 3] in the normalised frame of part p with code
    /// `codes[p]` ([P, F]) → [P, N]. Differentiable in points and codes; W_c z is computed once
    /// per part and broadcast over its points.
    pub fn sdf(&self, points: Tensor<3>, codes: Tensor<2>) -> Tensor<2> {
        self.sdf_with_features(points, self.code_features(codes))
    }

    /// The same function in a larger decoder of `cfg`'s sizes (each ≥ its own; the code
    /// width and `code_every_block` must match): more positional-encoding octaves, a wider
    /// hidden width, more residual blocks. Function-preserving growth (Net2Net-style):
    /// - γ(q)'s existing channels keep their rows of W_p at their new places; the new
    ///   octaves' rows are zero into the old hidden channels;
    /// - a new hidden channel of the residual stream carries a fresh random feature of γ(q)
    ///   (its W_p column and bias), but nothing reads it yet: its rows of every block's first
    ///   layer and of the output layer are zero. (A channel held at zero instead would never
    ///   learn: the blocks' leading ReLU has no gradient at 0.)
    /// - a block's new inner units read the old channels through fresh random weights and
    ///   write nothing yet (their rows of the block's second layer are zero);
    /// - new blocks are identities (second layer weight and bias zero).
    ///
    /// Fresh values come from `rng` with PyTorch's bound 1/√fan_in. The SDF is unchanged up
    /// to float rounding until training moves the new weights, so a trained decoder gains room
    /// while its codes, and every model trained on them, stay valid. Refuses, with the field,
    /// limit and value, a size that would shrink or change.
    pub fn grow(self, cfg: &ShapePriorConfig, rng: &mut Rng) -> Result<Self, ModelError> {
        let h = self.hidden();
        let (blocks, rows, f) = (self.blocks.len(), self.feature_width() / h, self.latent());
        let from = ShapePriorConfig {
            pe_freqs: self.pe_freqs,
            decoder_hidden: h,
            decoder_blocks: blocks,
            latent: f,
            ..*cfg
        };
        cfg.check_decoder_growth(&from)?;
        if cfg.code_rows() != rows {
            return Err(ModelError::Config(crate::error::Invalid {
                field: "code_every_block".into(),
                limit: format!("{rows} code rows"),
                value: cfg.code_rows().to_string(),
            }));
        }
        let device = self.fc_p.weight.device();
        let hh = cfg.decoder_hidden;
        let (n_old, n_new) = (self.pe_freqs, cfg.pe_freqs);
        let pe_new = 3 + 6 * n_new;
        // γ(q) = [q, cos block, sin block], each block coordinate-major: the new index of old
        // channel i (octave f of axis a in block k).
        let pe_row = |i: usize| {
            if i < 3 {
                return i;
            }
            let (k, rest) = ((i - 3) / (3 * n_old), (i - 3) % (3 * n_old));
            3 + k * 3 * n_new + (rest / n_old) * n_new + rest % n_old
        };
        let same = |i: usize| i;
        // Code row l's h columns move to l · hh.
        let code_col = |j: usize| (j / h) * hh + j % h;
        // A layer of shape [r_new, c_new] (+ bias [c_new]) holding `old`'s weights [r, c] at
        // (row_at(i), col_at(j)) and its bias at col_at(j); every other entry from
        // fill(row is old, column is old).
        let mut grow_linear = |old: &Linear,
                               (r_new, c_new): (usize, usize),
                               row_at: &dyn Fn(usize) -> usize,
                               col_at: &dyn Fn(usize) -> usize,
                               fill: &dyn Fn(bool, bool) -> bool| {
            let [r, c] = old.weight.shape().dims::<2>();
            let w = old.weight.val().into_data().try_into_vec::<f32>();
            let w = w.expect("f32 weights");
            let (mut row_old, mut col_old) = (vec![false; r_new], vec![false; c_new]);
            let mut placed = vec![None; r_new * c_new];
            for j in 0..c {
                col_old[col_at(j)] = true;
            }
            for i in 0..r {
                row_old[row_at(i)] = true;
                for j in 0..c {
                    placed[row_at(i) * c_new + col_at(j)] = Some(w[i * c + j]);
                }
            }
            let bound = 1.0 / (r_new as f64).sqrt();
            let mut fresh = |random: bool| {
                if random {
                    rng.range(-bound, bound) as f32
                } else {
                    0.0
                }
            };
            let w: Vec<f32> = (0..r_new * c_new)
                .map(|k| {
                    let (i, j) = (k / c_new, k % c_new);
                    placed[k].unwrap_or_else(|| fresh(fill(row_old[i], col_old[j])))
                })
                .collect();
            let bias = old.bias.as_ref().map(|b| {
                let b = b.val().into_data().try_into_vec::<f32>();
                let b = b.expect("f32 weights");
                let mut out: Vec<Option<f32>> = vec![None; c_new];
                for (j, v) in b.into_iter().enumerate() {
                    out[col_at(j)] = Some(v);
                }
                let out: Vec<f32> = out
                    .into_iter()
                    .map(|v| v.unwrap_or_else(|| fresh(fill(true, false))))
                    .collect();
                Param::from_data(TensorData::new(out, [c_new]), &device)
            });
            Linear {
                weight: Param::from_data(TensorData::new(w, [r_new, c_new]), &device),
                bias,
            }
        };
        // W_p: new channels random (new octaves too), old channels see no new octave.
        let fc_p = grow_linear(&self.fc_p, (pe_new, hh), &pe_row, &same, &|_, col| !col);
        // W_c: the code adds nothing to new channels yet.
        let fc_c = grow_linear(&self.fc_c, (f, rows * hh), &same, &code_col, &|_, _| false);
        let mut grown: Vec<ResBlock> = Vec::with_capacity(cfg.decoder_blocks);
        for b in &self.blocks {
            // First layer: new inner units read the old channels; new channels are read by
            // nobody. Second layer: new inner units write nothing; new channels get nothing.
            let fc_0 = grow_linear(&b.fc_0, (hh, hh), &same, &same, &|row, col| row && !col);
            let fc_1 = grow_linear(&b.fc_1, (hh, hh), &same, &same, &|_, _| false);
            grown.push(ResBlock {
                fc_0,
                fc_1,
                shortcut: None,
            });
        }
        let fc_out = grow_linear(&self.fc_out, (hh, 1), &same, &same, &|_, _| false);
        for _ in blocks..cfg.decoder_blocks {
            let mut block = ResBlock::new(hh, hh, rng, &device);
            let zero = TensorData::new(vec![0.0f32; hh], [hh]);
            block.fc_1.bias = Some(Param::from_data(zero, &device));
            grown.push(block);
        }
        Ok(ShapeDecoder {
            fc_p,
            fc_c,
            blocks: grown,
            fc_out,
            pe_freqs: n_new,
        })
    }

    /// Hidden width.
    pub fn hidden(&self) -> usize {
        self.fc_p.weight.shape().dims::<2>()[1]
    }

    /// Latent width F.
    pub fn latent(&self) -> usize {
        self.fc_c.weight.shape().dims::<2>()[0]
    }

    /// Width of the code features (hidden · rows).
    pub fn feature_width(&self) -> usize {
        self.fc_c.weight.shape().dims::<2>()[1]
    }
}

/// The point encoder ("ResnetPointnet", method.md §4.3).
#[derive(Module, Debug)]
pub struct ShapeEncoder {
    /// Per-point 3 → 2H.
    pub fc_pos: Linear,
    /// block_0: 2H → H; block_k (k ≥ 1): [feature, max-pool] 2H → H.
    pub blocks: Vec<ResBlock>,
    /// H → F after ReLU of the final max-pool.
    pub fc_c: Linear,
}

impl ShapeEncoder {
    /// A freshly initialised encoder.
    pub fn new(cfg: &ShapePriorConfig, rng: &mut Rng, device: &Device) -> Self {
        let h = cfg.encoder_hidden;
        ShapeEncoder {
            fc_pos: linear(3, 2 * h, true, false, rng, device),
            blocks: (0..cfg.encoder_blocks)
                .map(|_| ResBlock::new(2 * h, h, rng, device))
                .collect(),
            fc_c: linear(h, cfg.latent, true, false, rng, device),
        }
    }

    /// Codes of parts from their surface points [P, S, 3] (normalised frame) → [P, F].
    pub fn encode(&self, surface: Tensor<3>) -> Tensor<2> {
        let [p, s, _] = surface.dims();
        let mut net = self.fc_pos.forward(surface.reshape([p * s, 3]));
        for (k, block) in self.blocks.iter().enumerate() {
            if k > 0 {
                let h = net.dims()[1];
                let per_point = net.reshape([p, s, h]);
                let pooled = per_point.clone().max_dim(1).expand([p, s, h]);
                net = Tensor::cat(vec![per_point, pooled], 2).reshape([p * s, 2 * h]);
            }
            net = block.forward(net);
        }
        let h = net.dims()[1];
        let pooled = net.reshape([p, s, h]).max_dim(1).reshape([p, h]);
        self.fc_c.forward(relu(pooled))
    }
}

/// The part-shape auto-encoder.
#[derive(Module, Debug)]
pub struct ShapePrior {
    /// Surface points → code.
    pub encoder: ShapeEncoder,
    /// (query, code) → SDF.
    pub decoder: ShapeDecoder,
}

impl ShapePrior {
    /// A model initialised from seed 0 (see [`ShapePrior::with_seed`]).
    pub fn new(cfg: &ShapePriorConfig, device: &Device) -> Self {
        Self::with_seed(cfg, 0, device)
    }

    /// A model initialised from `seed` (deterministic, independent of burn's RNG). Panics on an
    /// invalid config; call [`ShapePriorConfig::validate`] first for untrusted sizes.
    pub fn with_seed(cfg: &ShapePriorConfig, seed: u64, device: &Device) -> Self {
        if let Err(e) = cfg.validate() {
            panic!("{e}");
        }
        let mut rng = Rng::fork(seed, 0x0053_4841_5045);
        let encoder = ShapeEncoder::new(cfg, &mut rng, device);
        let decoder = ShapeDecoder::new(cfg, &mut rng, device);
        ShapePrior { encoder, decoder }
    }
}

/// A (non-autodiff) decoder as a [`LatentDecoder`], so `mesh::part_mesh` can mesh latent parts.
///
/// Holds the burn module (for differentiable guidance queries) and its value-only copy
/// ([`HostDecoder`], for meshing and every pass that needs no gradient). Safe to share across
/// threads (the mesher evaluates z-slabs in parallel); burn modules are `Sync`.
#[derive(Debug, Clone)]
pub struct LatentSdfDecoder {
    decoder: ShapeDecoder,
    host: HostDecoder,
}

impl LatentSdfDecoder {
    /// Wrap `decoder`; it is put into inference mode ([`Module::valid`], no autodiff graph).
    pub fn new(decoder: &ShapeDecoder) -> Self {
        let decoder = decoder.valid();
        LatentSdfDecoder {
            host: HostDecoder::new(&decoder),
            decoder,
        }
    }

    /// The wrapped decoder.
    pub fn decoder(&self) -> &ShapeDecoder {
        &self.decoder
    }

    /// Its value-only copy.
    pub fn host(&self) -> &HostDecoder {
        &self.host
    }
}

/// The SDF of one code: the code features are computed once, points are decoded by the
/// value-only decoder.
struct CodeSdf<'a> {
    decoder: &'a HostDecoder,
    /// [hidden], or `None` when the code had the wrong length (SDF = NaN: meshes empty).
    features: Option<Vec<f32>>,
}

impl Sdf for CodeSdf<'_> {
    fn eval_batch(&self, points: &[[f32; 3]], out: &mut [f32]) {
        match &self.features {
            Some(features) => {
                let idx = vec![0; points.len()];
                self.decoder.eval(points, features, &idx, out);
            }
            None => out.fill(f32::NAN),
        }
    }
}

impl LatentDecoder for LatentSdfDecoder {
    /// A code of the wrong length gives an SDF that is NaN everywhere (the mesher treats that as
    /// outside, so the part meshes empty) and logs a warning.
    fn sdf<'a>(&'a self, code: &'a [f32]) -> Box<dyn Sdf + 'a> {
        let latent = self.decoder.latent();
        let features = if code.len() == latent {
            Some(self.host.code_features(code))
        } else {
            tracing::warn!(
                expected = latent,
                got = code.len(),
                "latent code has the wrong length"
            );
            None
        };
        Box::new(CodeSdf {
            decoder: &self.host,
            features,
        })
    }
}

// The mesher needs `Sdf: Sync`; fail the build, not a run, if burn ever changes this.
const _: () = {
    const fn assert_sync<T: Sync + Send>() {}
    assert_sync::<ShapeDecoder>();
    assert_sync::<Tensor<2>>();
};

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::model::{cpu, cpu_autodiff};

    fn tiny() -> ShapePriorConfig {
        ShapePriorConfig {
            latent: 8,
            decoder_hidden: 16,
            decoder_blocks: 2,
            encoder_hidden: 16,
            encoder_blocks: 2,
            pe_freqs: 8,
            code_every_block: false,
        }
    }

    fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
        t.into_data().try_into_vec::<f32>().unwrap()
    }

    #[test]
    fn nap_parameter_counts_match_the_paper() {
        let cfg = ShapePriorConfig::nap();
        let mut rng = Rng::new(0);
        let device = cpu();
        assert_eq!(
            ShapeDecoder::new(&cfg, &mut rng, &device).num_params(),
            704_513
        );
        assert_eq!(
            ShapeEncoder::new(&cfg, &mut rng, &device).num_params(),
            6_628_480
        );
        assert_eq!(cfg.pe_dim(), 51);
    }

    /// Growing the decoder (N_pe 8 → 11, hidden 16 → 24, 2 → 3 blocks) keeps the SDF, makes
    /// a decoder of the larger config whose new weights get gradients, and refuses to shrink.
    #[test]
    fn growing_the_decoder_keeps_the_sdf() {
        let device = cpu_autodiff();
        let cfg = tiny();
        let mut rng = Rng::new(3);
        // Random second-layer weights too (fresh ones are zero), so every block matters.
        let decoder = randomised(ShapeDecoder::new(&cfg, &mut rng, &device), 9);
        let pts: Vec<f32> = (0..3 * 40).map(|_| rng.range(-0.5, 0.5) as f32).collect();
        let codes: Vec<f32> = (0..2 * cfg.latent).map(|_| rng.gauss() as f32).collect();
        let run = |d: &ShapeDecoder| {
            let p = Tensor::<3>::from_data(TensorData::new(pts.clone(), [2, 20, 3]), &device);
            let c =
                Tensor::<2>::from_data(TensorData::new(codes.clone(), [2, cfg.latent]), &device);
            to_vec(d.sdf(p, c))
        };
        let before = run(&decoder);
        let big = ShapePriorConfig {
            pe_freqs: 11,
            decoder_hidden: 24,
            decoder_blocks: 3,
            ..cfg
        };
        for (field, smaller) in [
            ("pe_freqs", ShapePriorConfig { pe_freqs: 7, ..cfg }),
            (
                "decoder_hidden",
                ShapePriorConfig {
                    decoder_hidden: 8,
                    ..cfg
                },
            ),
            (
                "decoder_blocks",
                ShapePriorConfig {
                    decoder_blocks: 1,
                    ..cfg
                },
            ),
            ("latent", ShapePriorConfig { latent: 9, ..cfg }),
        ] {
            let e = decoder
                .clone()
                .grow(&smaller, &mut rng)
                .unwrap_err()
                .to_string();
            assert!(e.contains(field), "{e}");
        }
        // install-shape's check: the encoder's sizes may not change with the decoder's.
        let other_encoder = ShapePriorConfig {
            encoder_hidden: 32,
            ..big
        };
        let e = other_encoder
            .check_decoder_growth(&cfg)
            .unwrap_err()
            .to_string();
        assert!(e.contains("encoder_hidden"), "{e}");
        big.check_decoder_growth(&cfg).unwrap();
        let grown = decoder.grow(&big, &mut rng).unwrap();
        assert_eq!(grown.pe_freqs, 11);
        assert_eq!(grown.fc_p.weight.shape().dims::<2>(), [3 + 6 * 11, 24]);
        assert_eq!(grown.blocks.len(), 3);
        assert_eq!(grown.hidden(), 24);
        let after = run(&grown);
        for (a, b) in before.iter().zip(&after) {
            assert!((a - b).abs() <= 1e-5 * (1.0 + a.abs()), "{a} vs {b}");
        }
        assert!(
            before.iter().any(|v| v.abs() > 1e-3),
            "a trivial decoder tests nothing"
        );
        // The grown weights learn: d SDF / d W is nonzero on the new hidden channels of W_p
        // and of the new block's second layer.
        let p = Tensor::<3>::from_data(TensorData::new(pts.clone(), [2, 20, 3]), &device);
        let c = Tensor::<2>::from_data(TensorData::new(codes.clone(), [2, cfg.latent]), &device);
        let grads = grown.sdf(p, c).sum().backward();
        let g = |w: &Param<Tensor<2>>| to_vec(w.val().grad(&grads).unwrap());
        // New channels are read through block 0's first layer and the output layer ...
        let g_0 = g(&grown.blocks[0].fc_0.weight);
        assert!(g_0[16 * 24..].iter().any(|v| *v != 0.0));
        assert!(g(&grown.fc_out.weight)[16..].iter().any(|v| *v != 0.0));
        // ... new inner units write through the second layer, and the new block learns.
        let g_1 = g(&grown.blocks[0].fc_1.weight);
        assert!(g_1[16 * 24..].iter().any(|v| *v != 0.0));
        assert!(g(&grown.blocks[2].fc_1.weight).iter().any(|v| *v != 0.0));
    }

    #[test]
    fn positional_encoding_layout_and_values() {
        let device = cpu();
        let q = Tensor::<2>::from_data(TensorData::new(vec![0.1f32, -0.2, 0.3], [1, 3]), &device);
        let g = to_vec(positional_encoding(q, 8));
        assert_eq!(g.len(), 51);
        let p = [0.1f64, -0.2, 0.3];
        let mut want = p.to_vec();
        for f in [f64::cos, f64::sin] {
            for c in p {
                for k in 0..8 {
                    want.push(f(c * (1u64 << k) as f64));
                }
            }
        }
        for (i, (a, b)) in g.iter().zip(&want).enumerate() {
            assert!((*a as f64 - b).abs() < 1e-5, "γ[{i}] = {a}, want {b}");
        }
        // Spot checks of the layout: cos(2^7 y) at 3 + 8 + 7, sin(2^0 x) at 3 + 24.
        assert!((g[18] as f64 - (-0.2f64 * 128.0).cos()).abs() < 1e-5);
        assert!((g[27] as f64 - 0.1f64.sin()).abs() < 1e-6);
    }

    #[test]
    fn decoder_and_encoder_shapes() {
        let device = cpu();
        let cfg = tiny();
        let model = ShapePrior::with_seed(&cfg, 3, &device);
        let surface = Tensor::<3>::random(
            [3, 10, 3],
            burn::tensor::Distribution::Uniform(-0.5, 0.5),
            &device,
        );
        let z = model.encoder.encode(surface);
        assert_eq!(z.dims(), [3, 8]);
        let pts = Tensor::<3>::zeros([3, 7, 3], &device);
        assert_eq!(model.decoder.sdf(pts, z).dims(), [3, 7]);
    }

    #[test]
    fn config_errors_name_field_limit_value() {
        let cfg = ShapePriorConfig {
            decoder_hidden: 0,
            ..ShapePriorConfig::default()
        };
        let e = cfg.validate().unwrap_err().to_string();
        assert!(
            e.contains("decoder_hidden") && e.contains("between 1 and 4096") && e.contains(": 0"),
            "{e}"
        );
        let cfg = ShapePriorConfig {
            pe_freqs: 17,
            ..ShapePriorConfig::default()
        };
        assert!(cfg.validate().unwrap_err().to_string().contains("17"));
    }

    /// Randomise every parameter (the residual blocks' zero init would hide their gradients).
    pub(crate) fn randomised(decoder: ShapeDecoder, seed: u64) -> ShapeDecoder {
        struct Mapper(Rng);
        impl burn::module::ModuleMapper for Mapper {
            fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
                param.map(|t| {
                    let shape = t.shape();
                    let n = shape.num_elements();
                    let v: Vec<f32> = (0..n).map(|_| self.0.range(-0.3, 0.3) as f32).collect();
                    Tensor::from_data(TensorData::new(v, shape), &t.device())
                })
            }
        }
        decoder.map(&mut Mapper(Rng::new(seed)))
    }

    #[test]
    fn sdf_gradients_match_finite_differences() {
        let device = cpu_autodiff();
        // Four octaves (highest frequency 8): with N_pe = 8 the field oscillates at 2^7 per
        // unit and a 1e-3 central difference is no longer a derivative.
        let cfg = ShapePriorConfig {
            pe_freqs: 4,
            ..tiny()
        };
        let mut rng = Rng::new(5);
        let decoder = randomised(ShapeDecoder::new(&cfg, &mut rng, &device), 9);
        let (p, n, f) = (2, 4, cfg.latent);
        let pts: Vec<f32> = (0..p * n * 3)
            .map(|_| rng.range(-0.4, 0.4) as f32)
            .collect();
        let codes: Vec<f32> = (0..p * f).map(|_| rng.range(-1.0, 1.0) as f32).collect();
        let readout: Vec<f32> = (0..p * n).map(|_| rng.range(-1.0, 1.0) as f32).collect();
        let r = Tensor::<2>::from_data(TensorData::new(readout, [p, n]), &device);
        let eval = |pts: &[f32], codes: &[f32]| -> f64 {
            let x = Tensor::<3>::from_data(TensorData::new(pts.to_vec(), [p, n, 3]), &device);
            let z = Tensor::<2>::from_data(TensorData::new(codes.to_vec(), [p, f]), &device);
            let v: f32 = (decoder.sdf(x, z) * r.clone()).sum().into_scalar();
            v as f64
        };
        let x =
            Tensor::<3>::from_data(TensorData::new(pts.clone(), [p, n, 3]), &device).require_grad();
        let z =
            Tensor::<2>::from_data(TensorData::new(codes.clone(), [p, f]), &device).require_grad();
        let grads = (decoder.sdf(x.clone(), z.clone()) * r.clone())
            .sum()
            .backward();
        let gx = to_vec(x.grad(&grads).expect("gradient w.r.t. points"));
        let gz = to_vec(z.grad(&grads).expect("gradient w.r.t. codes"));
        let check = |analytic: &[f32], base: &[f32], eps: f32, is_points: bool| {
            let mut err2 = 0.0f64;
            let mut norm2 = 0.0f64;
            for i in 0..base.len() {
                let (mut hi, mut lo) = (base.to_vec(), base.to_vec());
                hi[i] += eps;
                lo[i] -= eps;
                let fd = if is_points {
                    (eval(&hi, &codes) - eval(&lo, &codes)) / (2.0 * eps as f64)
                } else {
                    (eval(&pts, &hi) - eval(&pts, &lo)) / (2.0 * eps as f64)
                };
                err2 += (analytic[i] as f64 - fd).powi(2);
                norm2 += fd * fd;
            }
            let rel = (err2 / norm2.max(1e-12)).sqrt();
            assert!(norm2 > 1e-6, "gradient is (numerically) zero");
            assert!(
                rel < 2e-2,
                "relative gradient error {rel} (points: {is_points})"
            );
        };
        check(&gx, &pts, 1e-3, true);
        check(&gz, &codes, 1e-2, false);
    }

    /// Median seconds of `f` over `reps` runs after one warm-up.
    fn median_secs(reps: usize, mut f: impl FnMut()) -> f64 {
        f();
        let mut t: Vec<f64> = (0..reps)
            .map(|_| {
                let t0 = std::time::Instant::now();
                f();
                t0.elapsed().as_secs_f64()
            })
            .collect();
        t.sort_by(f64::total_cmp);
        t[reps / 2]
    }

    /// Decoder throughput (BENCHMARKS.md): `cargo test --release --lib shape_prior::tests::
    /// decoder_throughput -- --ignored --nocapture`.
    #[test]
    #[ignore = "benchmark"]
    fn decoder_throughput() {
        for (name, cfg) in [
            ("default", ShapePriorConfig::default()),
            ("nap", ShapePriorConfig::nap()),
        ] {
            for (p, n) in [(1, 8192), (8, 1024), (1, 32768)] {
                let mut rng = Rng::new(1);
                let pts: Vec<f32> = (0..p * n * 3)
                    .map(|_| rng.range(-0.55, 0.55) as f32)
                    .collect();
                let codes: Vec<f32> = (0..p * cfg.latent)
                    .map(|_| rng.range(-1.0, 1.0) as f32)
                    .collect();
                let device = cpu();
                let dec = randomised(ShapeDecoder::new(&cfg, &mut rng, &device), 2);
                let fwd = median_secs(9, || {
                    let x =
                        Tensor::<3>::from_data(TensorData::new(pts.clone(), [p, n, 3]), &device);
                    let z = Tensor::<2>::from_data(
                        TensorData::new(codes.clone(), [p, cfg.latent]),
                        &device,
                    );
                    let _ = to_vec(dec.sdf(x, z));
                });
                let host = crate::model::host_decoder::HostDecoder::new(&dec);
                let q: Vec<[f32; 3]> = pts.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
                let idx: Vec<usize> = (0..p * n).map(|r| r / n).collect();
                let mut out = vec![0.0f32; p * n];
                let fwd_host = median_secs(9, || {
                    host.eval(&q, &host.code_features(&codes), &idx, &mut out);
                });
                let ad = cpu_autodiff();
                let dec_ad = dec.clone().fork(&ad).no_grad();
                let bwd = median_secs(9, || {
                    let x = Tensor::<3>::from_data(TensorData::new(pts.clone(), [p, n, 3]), &ad)
                        .require_grad();
                    let z = Tensor::<2>::from_data(
                        TensorData::new(codes.clone(), [p, cfg.latent]),
                        &ad,
                    )
                    .require_grad();
                    let grads = dec_ad.sdf(x.clone(), z.clone()).sum().backward();
                    let _ = to_vec(x.grad(&grads).unwrap());
                    let _ = to_vec(z.grad(&grads).unwrap());
                });
                let bwd_host = median_secs(9, || {
                    let g = host.eval_with_grads(&q, &host.code_features(&codes), &idx);
                    assert_eq!(g.values.len(), p * n);
                });
                let total = (p * n) as f64;
                println!(
                    "decoder {name} P={p} N={n}: fwd {:.0} points/s ({:.1} ms), host fwd {:.0} points/s ({:.1} ms), fwd+bwd(points, codes) {:.0} points/s ({:.1} ms), host fwd+input grads {:.0} points/s ({:.1} ms), threads {}",
                    total / fwd,
                    fwd * 1e3,
                    total / fwd_host,
                    fwd_host * 1e3,
                    total / bwd,
                    bwd * 1e3,
                    total / bwd_host,
                    bwd_host * 1e3,
                    rayon::current_num_threads()
                );
            }
        }
    }
}
