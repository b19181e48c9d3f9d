//! The articulation-graph denoiser ε_θ(V_t, E_t, t [, category]): NAP's "v60"
//! (`GraphDenoiseConvV60`, method.md §3) with PhysNAP's changes (§8.1).
//!
//! Why it exists: the DDPM sampler, the trainer and loss guidance all call this network; guidance
//! back-propagates through it w.r.t. its *inputs* (method.md §8.2), so every op here is
//! differentiable and batched (B samples × 8 nodes × 64 directed edges, no per-sample loops).
//!
//! Data flow (B = batch, w = width, 64 directed entries (i, j) at row i·8 + j, diagonal included):
//!
//! ```text
//! V [B,8,135] ─► h⁰ = L_o(o)+L_b(b)+L_t(t)+L_s(s) (+ cat)           [B,8,w]
//! E [B,28,13] ─► dense 8×8 (class 1↔2 swapped for i > j, zero diagonal)
//!             ─► g⁰ = L₃(c̃) + L₆(l,m) + L₄(ranges) (+ cat)           [B,64,w]
//! L × GraphLayer(h, g; slot PE π, time PE τ) ─► (h^ℓ, g^ℓ)
//! H = L_wide([h⁰…h^L])        G = L_wide([g⁰…g^L]) at the 28 pairs i < j (directed G_ij)
//! ε̂_V = [head_o | head_b | head_t | head_s]([H ; V slice])          [B,8,135]
//! ε̂_E = [head_c̃ | head_Plücker | head_ranges]([G ; E slice])        [B,28,13]
//! ```
//!
//! Exact rewrites for speed (same function, and one stored weight per NAP `Linear` with NAP's
//! shape, so a NAP checkpoint maps 1:1 onto these parameters after renaming and burn's
//! [in, out] transpose): every `Linear` over a concatenation `W [a ; b ; c]` is evaluated as
//! `W_a a + W_b b + W_c c` with the row blocks of the one stored weight, so per-node and per-sample
//! terms (A v_i, B v_j, the slot and time encodings, the pooled feature) are computed once instead
//! of per edge; the edge wide-skip is evaluated only at the 28 entries the heads read.
//!
//! Category (A6): one table of `categories + 1` rows; row `categories` means "no category" (used
//! when `category` is `None`, and for classifier-free-style dropout in training). Its row is added
//! to every initial node feature and every initial directed edge feature (diagonal included).
//! With `categories == 0` the model is unconditional, has no table and **ignores** the `category`
//! argument (the sampler can pass the request's category uniformly); [`Denoiser::check_inputs`]
//! reports a category given to an unconditional model as an error for callers that want to be
//! strict.
//!
//! `category_layers` (physnap's option, on in the shipped weights since 2026-11-26, off in
//! [`DenoiserConfig::default`]): a second, zero-initialised
//! table of (categories + 1) × (L · w) whose row block ℓ is added to layer ℓ's node and edge
//! inputs, `(h, g) ← GraphLayer_ℓ(h + c_ℓ, g + c_ℓ)`, so every layer sees the category, not
//! only h⁰ / g⁰ (which reach the heads through the wide skip). Drawn after every other
//! parameter, so turning it on leaves the rest of the initialisation unchanged.

use burn::module::{Module, Param, ParamId};
use burn::nn::{Embedding, Linear};
use burn::tensor::activation::{leaky_relu, silu, softmax};
use burn::tensor::module::linear;
use burn::tensor::{Device, Int, Shape, Tensor, TensorData};

use super::ModelError;
use crate::data::rng::Rng;
use crate::graph::{EDGE_DIM, EDGE_PAIRS, K, NODE_DIM, NUM_EDGES, edge_index};
use crate::object::LATENT_DIM;

/// Seed of [`Denoiser::new`] (NAP's training seed).
pub const DEFAULT_SEED: u64 = 12345;
/// Number of diffusion steps; the time encoding table has one row per step index 0..=999.
pub const TIME_STEPS: usize = 1000;
/// Directed edge entries, K² (the diagonal included).
pub const DIRECTED: usize = K * K;
/// Node slices seen by the node input embeddings and heads: o, b, t, s (offset, width).
pub const NODE_SLICES: [(usize, usize); 4] = [(0, 1), (1, 3), (4, 3), (7, LATENT_DIM)];
/// Edge slices of the output heads: c̃, Plücker (l, m), ranges (offset, width).
pub const EDGE_SLICES: [(usize, usize); 3] = [(0, 3), (3, 6), (9, 4)];
/// LeakyReLU slope of the heads.
const HEAD_SLOPE: f64 = 0.01;

/// Hyper-parameters of the denoiser.
#[derive(Debug, Clone, PartialEq)]
pub struct DenoiserConfig {
    /// Feature width of every node and edge feature (NAP: 512).
    pub width: usize,
    /// Number of graph layers (NAP: 5).
    pub layers: usize,
    /// Channels per attention head (NAP's `c_atten_head`: 32); heads = width / head_channels.
    pub head_channels: usize,
    /// Width of the sinusoidal time encoding (NAP: 200).
    pub t_pe_dim: usize,
    /// Width of the sinusoidal slot encoding (NAP: 100).
    pub slot_pe_dim: usize,
    /// Hidden widths of the node heads (NAP: [256, 256, 256]).
    pub node_head_hidden: Vec<usize>,
    /// Hidden widths of the edge heads (NAP: [256, 128, 64]).
    pub edge_head_hidden: Vec<usize>,
    /// 0 = unconditional; else the number of categories. The table has `categories + 1` rows,
    /// the last one meaning "no category".
    pub categories: usize,
    /// Reproduce NAP's buggy edge-embedding slicing (method.md §3.3); only for loading NAP
    /// weights. Default false (PhysNAP's fix).
    pub legacy_edge_embedding: bool,
    /// Also add a learned per-layer category row to every graph layer's node and edge inputs
    /// (physnap, not in the paper, which adds the category to the initial embeddings only).
    /// One extra table of (categories + 1) × (layers · w), zero-initialised. Ignored when
    /// unconditional. Default false (the paper's model); the shipped weights have it on.
    pub category_layers: bool,
}

impl Default for DenoiserConfig {
    /// The small CPU model: width 160, 4 layers, 5 heads of 32 channels, node heads
    /// [128, 128, 128], edge heads [128, 64, 32], 46 categories; 2 161 508 parameters. Its
    /// speed (this module for training, the host path for sampling) is in BENCHMARKS.md,
    /// "Sampling (the denoiser)".
    fn default() -> Self {
        DenoiserConfig {
            width: 160,
            layers: 4,
            head_channels: 32,
            t_pe_dim: 200,
            slot_pe_dim: 100,
            node_head_hidden: vec![128, 128, 128],
            edge_head_hidden: vec![128, 64, 32],
            categories: crate::data::categories::CATEGORIES.len(),
            legacy_edge_embedding: false,
            category_layers: false,
        }
    }
}

impl DenoiserConfig {
    /// NAP's v6.1 denoiser: width 512, 5 layers, 16 heads of 32, PE 200/100, heads
    /// [256,256,256] / [256,128,64], unconditional, fixed edge embedding. 20 753 380 parameters.
    pub fn nap() -> Self {
        DenoiserConfig {
            width: 512,
            layers: 5,
            head_channels: 32,
            t_pe_dim: 200,
            slot_pe_dim: 100,
            node_head_hidden: vec![256, 256, 256],
            edge_head_hidden: vec![256, 128, 64],
            categories: 0,
            legacy_edge_embedding: false,
            category_layers: false,
        }
    }

    /// Number of attention heads.
    pub fn heads(&self) -> usize {
        self.width / self.head_channels.max(1)
    }

    /// Check every field; the error names the field, the rule and the value.
    pub fn validate(&self) -> Result<(), ModelError> {
        let err = |field: &str, limit: &str, value: String| {
            Err(ModelError::Config(crate::error::Invalid {
                field: format!("denoiser.{field}"),
                limit: limit.into(),
                value,
            }))
        };
        if self.width == 0 || self.width > 8192 {
            return err("width", "in 1..=8192", self.width.to_string());
        }
        if self.layers == 0 || self.layers > 64 {
            return err("layers", "in 1..=64", self.layers.to_string());
        }
        if self.head_channels == 0 || !self.width.is_multiple_of(self.head_channels) {
            return err(
                "head_channels",
                &format!("≥ 1 and a divisor of width {}", self.width),
                self.head_channels.to_string(),
            );
        }
        for (field, d) in [
            ("t_pe_dim", self.t_pe_dim),
            ("slot_pe_dim", self.slot_pe_dim),
        ] {
            if d < 2 || !d.is_multiple_of(2) || d > 4096 {
                return err(field, "even and in 2..=4096", d.to_string());
            }
        }
        for (field, hidden) in [
            ("node_head_hidden", &self.node_head_hidden),
            ("edge_head_hidden", &self.edge_head_hidden),
        ] {
            if hidden.len() > 16 || hidden.iter().any(|&h| h == 0 || h > 8192) {
                return err(
                    field,
                    "at most 16 entries, each in 1..=8192",
                    format!("{hidden:?}"),
                );
            }
        }
        if self.categories > 100_000 {
            return err("categories", "at most 100000", self.categories.to_string());
        }
        Ok(())
    }
}

/// Sinusoidal table of method.md §3.2: row n, columns 2k / 2k+1 = sin / cos(n · 10000^(−4k/d)).
pub fn sinusoidal_table(rows: usize, dim: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; rows * dim];
    for n in 0..rows {
        for k in 0..dim / 2 {
            let freq = 10000f64.powf(-4.0 * k as f64 / dim as f64);
            let a = n as f64 * freq;
            out[n * dim + 2 * k] = a.sin() as f32;
            out[n * dim + 2 * k + 1] = a.cos() as f32;
        }
    }
    out
}

/// The rows `idx` [B] of an embedding table, as [B,1,width] to broadcast over nodes or edges.
fn rows_of_table(table: &Embedding, idx: &Tensor<1, Int>) -> Tensor<3> {
    let b = idx.dims()[0];
    table.forward(idx.clone().reshape([b, 1]))
}

/// The weight row block `rows` of a linear layer, `[len, d_out]`.
fn rows_of(l: &Linear, start: usize, len: usize) -> Tensor<2> {
    l.weight.val().narrow(0, start, len)
}

fn bias_of(l: &Linear) -> Option<Tensor<1>> {
    l.bias.as_ref().map(|b| b.val())
}

/// Deterministic, lazy parameter initialisation: parameter number k draws from its own
/// SplitMix64 stream `Rng::fork(seed, k)`, so a model is a pure function of (config, seed) on
/// every machine and thread count (burn's initialisers use a global device RNG). Distributions
/// follow PyTorch's defaults: Linear weight and bias U(±1/√fan_in), embedding N(0, 1).
struct Init {
    seed: u64,
    next: u64,
    device: Device,
}

impl Init {
    fn param<const D: usize>(
        &mut self,
        shape: [usize; D],
        normal: bool,
        bound: f64,
    ) -> Param<Tensor<D>> {
        let (seed, stream) = (self.seed, self.next);
        self.next += 1;
        Param::uninitialized(
            ParamId::new(),
            move |device, require_grad| {
                let mut rng = Rng::fork(seed, stream);
                let n = shape.iter().product();
                let values: Vec<f32> = (0..n)
                    .map(|_| {
                        if normal {
                            rng.gauss() as f32
                        } else {
                            rng.range(-bound, bound) as f32
                        }
                    })
                    .collect();
                let t = Tensor::from_data(TensorData::new(values, shape), device);
                if require_grad { t.require_grad() } else { t }
            },
            self.device.clone(),
            true,
            Shape::new(shape),
        )
    }

    fn linear(&mut self, d_in: usize, d_out: usize) -> Linear {
        let bound = 1.0 / (d_in as f64).sqrt();
        Linear {
            weight: self.param([d_in, d_out], false, bound),
            bias: Some(self.param([d_out], false, bound)),
        }
    }

    fn embedding(&mut self, rows: usize, width: usize) -> Embedding {
        Embedding {
            weight: self.param([rows, width], true, 0.0),
        }
    }
}

fn int_tensor(values: Vec<i64>, device: &Device) -> Tensor<1, Int> {
    let n = values.len();
    Tensor::from_data(TensorData::new(values, [n]), device)
}

/// NAP's "NaiveMLP" head: hidden Linear → LeakyReLU(0.01) layers; the output layer reads
/// `[input ; every hidden activation]`.
#[derive(Module, Debug)]
struct WideMlp {
    hidden: Vec<Linear>,
    out: Linear,
}

impl WideMlp {
    fn new(d_in: usize, hidden: &[usize], d_out: usize, init: &mut Init) -> Self {
        let mut layers = Vec::with_capacity(hidden.len());
        let mut d = d_in;
        for &h in hidden {
            layers.push(init.linear(d, h));
            d = h;
        }
        let wide = d_in + hidden.iter().sum::<usize>();
        WideMlp {
            hidden: layers,
            out: init.linear(wide, d_out),
        }
    }

    fn forward(&self, z: Tensor<3>) -> Tensor<3> {
        let mut acts = Vec::with_capacity(self.hidden.len() + 1);
        let mut h = z.clone();
        acts.push(z);
        for l in &self.hidden {
            h = leaky_relu(l.forward(h), HEAD_SLOPE);
            acts.push(h.clone());
        }
        self.out.forward(Tensor::cat(acts, 2))
    }
}

/// One NAP `GraphLayer` (method.md §3.4), all widths `w`.
#[derive(Module, Debug)]
struct GraphLayer {
    /// [v ; π ; τ] → w.
    node_bind: Linear,
    /// [e ; τ] → w.
    edge_bind: Linear,
    /// [v_i ; v_j ; e_ij] → w.
    edge_mlp1: Linear,
    /// w → w, no activation: the layer's edge output u.
    edge_mlp2: Linear,
    query: Linear,
    key: Linear,
    /// The self term SiLU(W_s v).
    self_term: Linear,
    /// [v' ; max-pool] → w.
    node_out: Linear,
    width: usize,
    heads: usize,
    /// 1 / √(head_channels · 3).
    scale: f64,
}

impl GraphLayer {
    fn new(cfg: &DenoiserConfig, init: &mut Init) -> Self {
        let w = cfg.width;
        GraphLayer {
            node_bind: init.linear(w + cfg.slot_pe_dim + cfg.t_pe_dim, w),
            edge_bind: init.linear(w + cfg.t_pe_dim, w),
            edge_mlp1: init.linear(3 * w, w),
            edge_mlp2: init.linear(w, w),
            query: init.linear(w, w),
            key: init.linear(w, w),
            self_term: init.linear(w, w),
            node_out: init.linear(2 * w, w),
            width: w,
            heads: cfg.heads(),
            scale: 1.0 / ((cfg.head_channels * 3) as f64).sqrt(),
        }
    }

    /// `v` [B,8,w], `e` [B,64,w], `slot_pe` [8,P], `tau` [B,T] → (v'' [B,8,w], u [B,64,w]).
    fn forward(
        &self,
        v: Tensor<3>,
        e: Tensor<3>,
        slot_pe: Tensor<2>,
        tau: Tensor<2>,
    ) -> (Tensor<3>, Tensor<3>) {
        let w = self.width;
        let [b, _, _] = v.dims();
        let p = slot_pe.dims()[1];
        let t = tau.dims()[1];

        // 1. Time/slot binding, W [v ; π ; τ] + b as row blocks.
        let nb = &self.node_bind;
        let slot = linear(slot_pe, rows_of(nb, w, p), None).reshape([1, K, w]);
        let time = linear(tau.clone(), rows_of(nb, w + p, t), bias_of(nb)).reshape([b, 1, w]);
        let v = silu(linear(v, rows_of(nb, 0, w), None) + slot + time);
        let eb = &self.edge_bind;
        let time = linear(tau, rows_of(eb, w, t), bias_of(eb)).reshape([b, 1, w]);
        let e = silu(linear(e, rows_of(eb, 0, w), None) + time);

        // 2. Edge message u_ij = W₂ SiLU(A v_i + B v_j + C e_ij + b₁) + b₂.
        let m1 = &self.edge_mlp1;
        let a = linear(v.clone(), rows_of(m1, 0, w), None).reshape([b, K, 1, w]);
        let bj = linear(v.clone(), rows_of(m1, w, w), None).reshape([b, 1, K, w]);
        let c = linear(e, rows_of(m1, 2 * w, w), bias_of(m1)).reshape([b, K, K, w]);
        let hidden = silu(c + a + bj).reshape([b, DIRECTED, w]);
        let u = self.edge_mlp2.forward(hidden);

        // 3–5. Multi-head attention of node i over the 8 slots j, values u_ij.
        let (h, hc) = (self.heads, w / self.heads);
        let q = self
            .query
            .forward(v.clone())
            .reshape([b, K, h, hc])
            .swap_dims(1, 2);
        let k = self
            .key
            .forward(v.clone())
            .reshape([b, K, h, hc])
            .swap_dims(1, 2);
        let logits = q.matmul(k.swap_dims(2, 3)).mul_scalar(self.scale); // [B,H,i,j]
        let alpha = softmax(logits, 3)
            .permute([0, 2, 3, 1]) // [B,i,j,H]
            .reshape([b, K, K, h, 1]);
        let msg = (u.clone().reshape([b, K, K, h, hc]) * alpha)
            .sum_dim(2)
            .reshape([b, K, w]);

        // 6. Self term.
        let v1 = msg + silu(self.self_term.forward(v));

        // 7–8. Global max pool and node output, W [v' ; g] + b as row blocks.
        let g = v1.clone().max_dim(1); // [B,1,w]
        let no = &self.node_out;
        let pooled = linear(g, rows_of(no, w, w), bias_of(no));
        let v2 = silu(linear(v1, rows_of(no, 0, w), None) + pooled);
        (v2, u)
    }
}

/// NAP's v60 articulation-graph denoiser with PhysNAP's fixed edge embedding and optional
/// category embedding. See the module documentation.
#[derive(Module, Debug)]
pub struct Denoiser {
    /// Node input embeddings for o, b, t, s.
    node_embed: Vec<Linear>,
    /// Edge input embedding of the class one-hot c̃ (3 → w).
    edge_embed_class: Linear,
    /// Edge input embedding of the Plücker line (6 → w).
    edge_embed_line: Linear,
    /// Edge input embedding of the ranges (4 → w).
    edge_embed_range: Linear,
    /// (categories + 1) × w, absent when unconditional.
    category: Option<Embedding>,
    /// (categories + 1) × (layers · w): row block ℓ is added to layer ℓ's inputs; present only
    /// with `category_layers` on a conditional model.
    category_layers: Option<Embedding>,
    layers: Vec<GraphLayer>,
    /// [h⁰ … h^L] → w.
    node_wide: Linear,
    /// [g⁰ … g^L] → w.
    edge_wide: Linear,
    /// Heads for o, b, t, s.
    node_heads: Vec<WideMlp>,
    /// Heads for c̃, Plücker, ranges.
    edge_heads: Vec<WideMlp>,
    /// Time encoding table [TIME_STEPS, t_pe_dim] (constant).
    time_pe: Tensor<2>,
    /// Slot encoding table [8, slot_pe_dim] (constant).
    slot_pe: Tensor<2>,
    /// For each directed entry i·8 + j: its row in `[E ; 0 ; E with classes 1↔2 swapped]`.
    dense_index: Tensor<1, Int>,
    /// Channel permutation swapping classes 1 and 2.
    class_swap: Tensor<1, Int>,
    /// Directed entry i·8 + j of each upper-triangle pair, in EDGE_PAIRS order.
    upper_index: Tensor<1, Int>,
    #[module(skip)]
    config: DenoiserConfig,
}

impl Denoiser {
    /// A randomly initialised denoiser on `device`, seed [`DEFAULT_SEED`].
    pub fn new(config: &DenoiserConfig, device: &Device) -> Result<Self, ModelError> {
        Self::with_seed(config, device, DEFAULT_SEED)
    }

    /// A randomly initialised denoiser; the weights are a pure function of (config, seed).
    /// Parameters are initialised lazily (on first use), so building even the NAP model is cheap.
    pub fn with_seed(
        config: &DenoiserConfig,
        device: &Device,
        seed: u64,
    ) -> Result<Self, ModelError> {
        config.validate()?;
        let w = config.width;
        let mut init = Init {
            seed,
            next: 0,
            device: device.clone(),
        };
        let node_embed = NODE_SLICES
            .iter()
            .map(|&(_, n)| init.linear(n, w))
            .collect();
        let edge_embed_class = init.linear(3, w);
        let edge_embed_line = init.linear(6, w);
        let edge_embed_range = init.linear(4, w);
        let category = (config.categories > 0).then(|| init.embedding(config.categories + 1, w));
        let layers = (0..config.layers)
            .map(|_| GraphLayer::new(config, &mut init))
            .collect();
        let node_wide = init.linear((config.layers + 1) * w, w);
        let edge_wide = init.linear((config.layers + 1) * w, w);
        let node_heads = NODE_SLICES
            .iter()
            .map(|&(_, n)| WideMlp::new(w + n, &config.node_head_hidden, n, &mut init))
            .collect();
        let edge_heads = EDGE_SLICES
            .iter()
            .map(|&(_, n)| WideMlp::new(w + n, &config.edge_head_hidden, n, &mut init))
            .collect();
        // Drawn last, so the other parameters do not depend on the option.
        let category_layers =
            (config.categories > 0 && config.category_layers).then(|| Embedding {
                weight: init.param([config.categories + 1, config.layers * w], false, 0.0),
            });

        let time_pe = Tensor::from_data(
            TensorData::new(
                sinusoidal_table(TIME_STEPS, config.t_pe_dim),
                [TIME_STEPS, config.t_pe_dim],
            ),
            device,
        );
        let slot_pe = Tensor::from_data(
            TensorData::new(
                sinusoidal_table(K, config.slot_pe_dim),
                [K, config.slot_pe_dim],
            ),
            device,
        );
        let mut dense = Vec::with_capacity(DIRECTED);
        for i in 0..K {
            for j in 0..K {
                let row = match i.cmp(&j) {
                    std::cmp::Ordering::Less => edge_index(i, j),
                    std::cmp::Ordering::Equal => NUM_EDGES,
                    std::cmp::Ordering::Greater => NUM_EDGES + 1 + edge_index(i, j),
                };
                dense.push(row as i64);
            }
        }
        let mut swap: Vec<i64> = (0..EDGE_DIM as i64).collect();
        swap.swap(1, 2);
        let upper = EDGE_PAIRS
            .iter()
            .map(|&(i, j)| (i * K + j) as i64)
            .collect();

        Ok(Denoiser {
            node_embed,
            edge_embed_class,
            edge_embed_line,
            edge_embed_range,
            category,
            category_layers,
            layers,
            node_wide,
            edge_wide,
            node_heads,
            edge_heads,
            time_pe,
            slot_pe,
            dense_index: int_tensor(dense, device),
            class_swap: int_tensor(swap, device),
            upper_index: int_tensor(upper, device),
            config: config.clone(),
        })
    }

    /// The configuration this model was built with.
    pub fn config(&self) -> &DenoiserConfig {
        &self.config
    }

    /// Number of trainable parameters.
    pub fn parameter_count(&self) -> usize {
        self.num_params()
    }

    /// Check shapes and index ranges of a forward call (reads `t` and `category` back; cheap).
    /// [`Denoiser::forward`] itself only asserts shapes.
    pub fn check_inputs(
        &self,
        v: &Tensor<3>,
        e: &Tensor<3>,
        t: &Tensor<1, Int>,
        category: Option<&Tensor<1, Int>>,
    ) -> Result<(), ModelError> {
        let shape = |what: &str, expected: String, got: String| {
            Err(ModelError::Shape {
                what: what.into(),
                expected,
                got,
            })
        };
        let [b, kv, dv] = v.dims();
        if kv != K || dv != NODE_DIM || b == 0 {
            return shape(
                "v",
                format!("[B ≥ 1, {K}, {NODE_DIM}]"),
                format!("{:?}", v.dims()),
            );
        }
        if e.dims() != [b, NUM_EDGES, EDGE_DIM] {
            return shape(
                "e",
                format!("[{b}, {NUM_EDGES}, {EDGE_DIM}]"),
                format!("{:?}", e.dims()),
            );
        }
        if t.dims() != [b] {
            return shape("t", format!("[{b}]"), format!("{:?}", t.dims()));
        }
        let range = |field: &str, x: &Tensor<1, Int>, hi: usize| -> Result<(), ModelError> {
            let vals: Vec<i64> = x.clone().try_into_vec_as::<i64>().unwrap_or_default();
            if let Some((k, bad)) = vals
                .iter()
                .enumerate()
                .find(|(_, v)| **v < 0 || **v as usize > hi)
            {
                return Err(ModelError::Config(crate::error::Invalid {
                    field: format!("{field}[{k}]"),
                    limit: format!("in 0..={hi}"),
                    value: bad.to_string(),
                }));
            }
            Ok(())
        };
        range("t", t, TIME_STEPS - 1)?;
        if let Some(c) = category {
            if self.config.categories == 0 {
                return Err(ModelError::Config(crate::error::Invalid {
                    field: "category".into(),
                    limit: "absent for an unconditional model (categories = 0)".into(),
                    value: "given".into(),
                }));
            }
            if c.dims() != [b] {
                return shape("category", format!("[{b}]"), format!("{:?}", c.dims()));
            }
            range("category", c, self.config.categories)?;
        }
        Ok(())
    }

    /// ε̂ for noisy graphs: `v` [B,8,135], `e` [B,28,13], `t` [B] in 0..=999, `category` [B] in
    /// 0..=categories (`categories` = "no category", also used for `None`; ignored when the model
    /// is unconditional). Returns (ε̂_V [B,8,135], ε̂_E [B,28,13]).
    ///
    /// Differentiable w.r.t. `v` and `e`: for guidance keep the model on a plain device
    /// (`model.valid()`) and pass autodiff inputs, so no weight gradients are computed.
    ///
    /// # Panics
    /// On wrong shapes; out-of-range indices are the caller's contract (see
    /// [`Denoiser::check_inputs`]).
    pub fn forward(
        &self,
        v: Tensor<3>,
        e: Tensor<3>,
        t: Tensor<1, Int>,
        category: Option<Tensor<1, Int>>,
    ) -> (Tensor<3>, Tensor<3>) {
        let [b, kv, dv] = v.dims();
        assert!(
            kv == K && dv == NODE_DIM,
            "denoiser: v must be [B, {K}, {NODE_DIM}], got {:?}",
            v.dims()
        );
        assert_eq!(e.dims(), [b, NUM_EDGES, EDGE_DIM], "denoiser: e shape");
        assert_eq!(t.dims(), [b], "denoiser: t shape");
        let w = self.config.width;
        let idx = self.category_index(category, b);
        let cat = self.category.as_ref().map(|t| rows_of_table(t, &idx));
        let cat_layers = self
            .category_layers
            .as_ref()
            .map(|t| rows_of_table(t, &idx));
        let h0 = self.node_embedding(v.clone(), cat.clone());
        let g0 = self.edge_embedding_with(e.clone(), cat);

        let tau = self.time_pe.clone().select(0, t);
        let upper = self.upper_index.clone();
        let mut hs = Vec::with_capacity(self.layers.len() + 1);
        let mut gs = Vec::with_capacity(self.layers.len() + 1);
        hs.push(h0.clone());
        gs.push(g0.clone().select(1, upper.clone()));
        let (mut h, mut g) = (h0, g0);
        for (l, layer) in self.layers.iter().enumerate() {
            if let Some(c) = &cat_layers {
                let c = c.clone().narrow(2, l * w, w); // [B,1,w]
                h = h + c.clone();
                g = g + c;
            }
            (h, g) = layer.forward(h, g, self.slot_pe.clone(), tau.clone());
            hs.push(h.clone());
            gs.push(g.clone().select(1, upper.clone()));
        }
        let hw = self.node_wide.forward(Tensor::cat(hs, 2)); // [B,8,w]
        let gw = self.edge_wide.forward(Tensor::cat(gs, 2)); // [B,28,w]
        debug_assert_eq!(hw.dims(), [b, K, w]);

        let eps_v = NODE_SLICES
            .iter()
            .zip(&self.node_heads)
            .map(|(&(o, n), head)| {
                head.forward(Tensor::cat(vec![hw.clone(), v.clone().narrow(2, o, n)], 2))
            })
            .collect();
        let eps_e = EDGE_SLICES
            .iter()
            .zip(&self.edge_heads)
            .map(|(&(o, n), head)| {
                head.forward(Tensor::cat(vec![gw.clone(), e.clone().narrow(2, o, n)], 2))
            })
            .collect();
        (Tensor::cat(eps_v, 2), Tensor::cat(eps_e, 2))
    }

    /// The initial directed edge features g⁰ [B,64,w] (entry i·8 + j), category included —
    /// exposed for tests and debugging of the edge embedding (method.md §3.3).
    pub fn edge_embedding(&self, e: Tensor<3>, category: Option<Tensor<1, Int>>) -> Tensor<3> {
        let b = e.dims()[0];
        let cat = self.category_vector(category, b);
        self.edge_embedding_with(e, cat)
    }

    /// The category row [B,1,w] to add, or None for an unconditional model.
    fn category_vector(&self, category: Option<Tensor<1, Int>>, b: usize) -> Option<Tensor<3>> {
        let table = self.category.as_ref()?;
        Some(rows_of_table(table, &self.category_index(category, b)))
    }

    /// The category rows to look up, [B]: `None` means "no category" for every sample.
    fn category_index(&self, category: Option<Tensor<1, Int>>, b: usize) -> Tensor<1, Int> {
        let device = self.dense_index.device();
        let idx =
            category.unwrap_or_else(|| int_tensor(vec![self.config.categories as i64; b], &device));
        assert_eq!(idx.dims(), [b], "denoiser: category shape");
        idx
    }

    fn node_embedding(&self, v: Tensor<3>, cat: Option<Tensor<3>>) -> Tensor<3> {
        let mut h = NODE_SLICES
            .iter()
            .zip(&self.node_embed)
            .map(|(&(o, n), l)| l.forward(v.clone().narrow(2, o, n)))
            .reduce(|a, b| a + b)
            .expect("four node slices");
        if let Some(c) = cat {
            h = h + c;
        }
        h
    }

    fn edge_embedding_with(&self, e: Tensor<3>, cat: Option<Tensor<3>>) -> Tensor<3> {
        let [b, _, _] = e.dims();
        // Dense directed entries: [E ; 0 ; E with classes 1↔2 swapped] gathered per (i, j).
        let zero = e.zeros_like().narrow(1, 0, 1);
        let swapped = e.clone().select(2, self.class_swap.clone());
        let dense = Tensor::cat(vec![e, zero, swapped], 1).select(1, self.dense_index.clone());
        debug_assert_eq!(dense.dims(), [b, DIRECTED, EDGE_DIM]);
        // NAP (legacy) slices the symmetric part S = channels 3..13 at S[3:9] and S[3:7], i.e.
        // channels 6..12 and 6..10: l and p_hi never enter the graph layers (method.md §3.3).
        let (line, range) = if self.config.legacy_edge_embedding {
            (dense.clone().narrow(2, 6, 6), dense.clone().narrow(2, 6, 4))
        } else {
            (dense.clone().narrow(2, 3, 6), dense.clone().narrow(2, 9, 4))
        };
        let mut g = self.edge_embed_class.forward(dense.narrow(2, 0, 3))
            + self.edge_embed_line.forward(line)
            + self.edge_embed_range.forward(range);
        if let Some(c) = cat {
            g = g + c;
        }
        g
    }
}

pub mod host;

#[cfg(test)]
mod tests;
