//! The sampler's noise prediction ε̂(x_t, t): the host denoiser at the batch of a run, with
//! classifier-free category guidance, and the vector–Jacobian product guidance needs.
//!
//! Why it exists: the sampling loop keeps its state as burn tensors (the schedule update and the
//! guidance losses are burn ops), but the denoiser runs on the host path
//! ([`HostDenoiser`], several times faster than the burn module at sampling batch sizes). This
//! module is the one crossing: it owns the host weights and the workspace of a run, batches the
//! conditional and the "no category" halves of classifier-free guidance into one forward, and
//! pushes an upstream gradient on ε̂ back to (V, E) through both halves.

use burn::tensor::{Device, Tensor, TensorData};

use crate::graph::{EDGE_DIM, K, NODE_DIM, NUM_EDGES};
use crate::model::denoiser::Denoiser;
use crate::model::denoiser::host::{HostDenoiser, Workspace};

/// ε̂ for the `batch` samples of one run.
pub struct Predictor {
    host: HostDenoiser,
    ws: Workspace,
    batch: usize,
    category: Option<usize>,
    /// Classifier-free guidance weight w, and the steps (t < below) where it applies.
    cfg: Option<(f32, usize)>,
    /// Whether the last forward ran both halves (then `backward` mixes the upstream).
    mixed: bool,
    v: Vec<f32>,
    e: Vec<f32>,
    eps_v: Vec<f32>,
    eps_e: Vec<f32>,
    /// The forward's timesteps and categories, [rows].
    t: Vec<usize>,
    cats: Vec<usize>,
}

fn flat(x: &Tensor<3>) -> Vec<f32> {
    x.clone()
        .into_data()
        .try_to_vec::<f32>()
        .expect("sampler state is f32")
}

/// `[a ; a]` when `twice`, else `a`.
fn doubled(mut a: Vec<f32>, twice: bool) -> Vec<f32> {
    if twice {
        a.extend_from_within(..);
    }
    a
}

impl Predictor {
    /// The predictor of a run of `batch` samples: conditioned on `category` when given (and the
    /// model has categories), with classifier-free weight `cfg_weight` (> 0) in steps t <
    /// `cfg_below`.
    pub fn new(
        model: &Denoiser,
        batch: usize,
        category: Option<usize>,
        cfg_weight: f64,
        cfg_below: usize,
    ) -> Self {
        let conditional = model.config().categories > 0;
        let cfg = category
            .filter(|_| cfg_weight > 0.0 && conditional)
            .map(|_| (cfg_weight as f32, cfg_below));
        Predictor {
            host: HostDenoiser::new(model),
            ws: Workspace::default(),
            batch,
            category: category.filter(|_| conditional),
            cfg,
            mixed: false,
            v: Vec::new(),
            e: Vec::new(),
            eps_v: Vec::new(),
            eps_e: Vec::new(),
            t: Vec::new(),
            cats: Vec::new(),
        }
    }

    /// ε̂ (nodes, edges) at `t` for the state (`v`, `e`) [batch, 8, 135] / [batch, 28, 13].
    /// With `record`, [`Predictor::backward`] can follow.
    pub fn eps(
        &mut self,
        v: &Tensor<3>,
        e: &Tensor<3>,
        t: usize,
        record: bool,
    ) -> (Tensor<3>, Tensor<3>) {
        let b = self.batch;
        let device = v.device();
        let mixed = self.cfg.is_some_and(|(_, below)| t < below);
        let rows = if mixed { 2 * b } else { b };
        self.v = doubled(flat(v), mixed);
        self.e = doubled(flat(e), mixed);
        let none = self.host.config().categories;
        self.t.clear();
        self.t.resize(rows, t);
        self.cats.clear();
        if let Some(c) = self.category {
            self.cats.resize(b, c);
            self.cats.resize(rows, none);
        }
        self.eps_v.resize(rows * K * NODE_DIM, 0.0);
        self.eps_e.resize(rows * NUM_EDGES * EDGE_DIM, 0.0);
        self.host.forward(
            &self.v,
            &self.e,
            &self.t,
            self.category.map(|_| self.cats.as_slice()),
            &mut self.eps_v,
            &mut self.eps_e,
            &mut self.ws,
            record,
        );
        self.mixed = mixed;
        let (nv, ne) = (b * K * NODE_DIM, b * NUM_EDGES * EDGE_DIM);
        let (ev, ee) = if let (true, Some((w, _))) = (mixed, self.cfg) {
            let mix = |x: &[f32], n: usize| -> Vec<f32> {
                let (c, u) = x.split_at(n);
                c.iter().zip(u).map(|(c, u)| c + (c - u) * w).collect()
            };
            (mix(&self.eps_v, nv), mix(&self.eps_e, ne))
        } else {
            (self.eps_v.clone(), self.eps_e.clone())
        };
        (
            tensor(ev, [b, K, NODE_DIM], &device),
            tensor(ee, [b, NUM_EDGES, EDGE_DIM], &device),
        )
    }

    /// ∂/∂(V, E) of Σ ⟨`up_v`, ε̂_V⟩ + ⟨`up_e`, ε̂_E⟩ at the last recorded [`Predictor::eps`]
    /// (flat [batch·8·135] and [batch·28·13]); through both halves under classifier-free
    /// guidance, ε̂ = (1 + w) ε̂_c − w ε̂_u.
    pub fn backward(&mut self, up_v: &[f32], up_e: &[f32]) -> (Vec<f32>, Vec<f32>) {
        let (nv, ne) = (self.batch * K * NODE_DIM, self.batch * NUM_EDGES * EDGE_DIM);
        let weights: Vec<f32> = match (self.mixed, self.cfg) {
            (true, Some((w, _))) => vec![1.0 + w, -w],
            _ => vec![1.0],
        };
        let halves = weights.len();
        let expand = |up: &[f32]| -> Vec<f32> {
            weights
                .iter()
                .flat_map(|&k| up.iter().map(move |x| x * k))
                .collect()
        };
        let (uv, ue) = (expand(up_v), expand(up_e));
        let mut dv = vec![0.0; halves * nv];
        let mut de = vec![0.0; halves * ne];
        self.host.backward(&mut self.ws, &uv, &ue, &mut dv, &mut de);
        let fold = |mut d: Vec<f32>, n: usize| {
            if halves == 2 {
                let (a, b) = d.split_at_mut(n);
                a.iter_mut().zip(b.iter()).for_each(|(a, b)| *a += b);
                d.truncate(n);
            }
            d
        };
        (fold(dv, nv), fold(de, ne))
    }
}

/// A flat buffer as a tensor of `shape` on `device`.
pub fn tensor(x: Vec<f32>, shape: [usize; 3], device: &Device) -> Tensor<3> {
    Tensor::from_data(TensorData::new(x, shape), device)
}
