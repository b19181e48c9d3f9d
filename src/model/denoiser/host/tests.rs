//! Tests of the host denoiser against the burn model it copies.

use burn::module::Param;
use burn::nn::Embedding;
use burn::tensor::{Int, Tensor, TensorData};

use super::*;
use crate::data::rng::Rng;
use crate::model::{cpu, cpu_autodiff};

fn config(width: usize, layers: usize, categories: usize) -> DenoiserConfig {
    DenoiserConfig {
        width,
        layers,
        head_channels: 8,
        t_pe_dim: 16,
        slot_pe_dim: 8,
        node_head_hidden: vec![16, 12],
        edge_head_hidden: vec![16],
        categories,
        legacy_edge_embedding: false,
        category_layers: false,
    }
}

fn gaussian(rng: &mut Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.gauss() as f32).collect()
}

/// A model of `cfg` whose per-layer category table (zero at initialisation) is random.
fn model(cfg: &DenoiserConfig, seed: u64) -> Denoiser {
    let mut m = Denoiser::with_seed(cfg, &cpu(), seed).expect("valid config");
    if let Some(t) = &m.category_layers {
        let [r, c] = t.weight.shape().dims::<2>();
        let mut rng = Rng::new(seed ^ 7);
        let vals = gaussian(&mut rng, r * c);
        m.category_layers = Some(Embedding {
            weight: Param::from_tensor(Tensor::from_data(TensorData::new(vals, [r, c]), &cpu())),
        });
    }
    m
}

struct Case {
    v: Vec<f32>,
    e: Vec<f32>,
    t: Vec<usize>,
    cats: Option<Vec<usize>>,
}

fn case(b: usize, seed: u64, categories: Option<usize>) -> Case {
    let mut rng = Rng::new(seed);
    Case {
        v: gaussian(&mut rng, b * K * NODE_DIM),
        e: gaussian(&mut rng, b * NUM_EDGES * EDGE_DIM),
        t: (0..b).map(|i| (i * 397 + 11) % TIME_STEPS).collect(),
        cats: categories.map(|c| (0..b).map(|i| i % (c + 1)).collect()),
    }
}

fn burn_inputs(
    c: &Case,
    device: &burn::tensor::Device,
) -> (Tensor<3>, Tensor<3>, Tensor<1, Int>, Option<Tensor<1, Int>>) {
    let b = c.t.len();
    let ints = |x: &[usize]| {
        Tensor::<1, Int>::from_data(
            TensorData::new(x.iter().map(|&x| x as i64).collect::<Vec<_>>(), [b]),
            device,
        )
    };
    (
        Tensor::from_data(TensorData::new(c.v.clone(), [b, K, NODE_DIM]), device),
        Tensor::from_data(
            TensorData::new(c.e.clone(), [b, NUM_EDGES, EDGE_DIM]),
            device,
        ),
        ints(&c.t),
        c.cats.as_deref().map(ints),
    )
}

fn flat(x: Tensor<3>) -> Vec<f32> {
    x.into_data().try_to_vec::<f32>().expect("f32")
}

fn host_forward(
    h: &HostDenoiser,
    c: &Case,
    ws: &mut Workspace,
    record: bool,
) -> (Vec<f32>, Vec<f32>) {
    let mut ev = vec![0.0; c.v.len()];
    let mut ee = vec![0.0; c.e.len()];
    h.forward(
        &c.v,
        &c.e,
        &c.t,
        c.cats.as_deref(),
        &mut ev,
        &mut ee,
        ws,
        record,
    );
    (ev, ee)
}

/// max |a − b| / max(1, max |b|).
fn rel_diff(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(1.0f64, |m, x| m.max(x.abs() as f64));
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .fold(0.0, f64::max)
        / scale
}

fn configs() -> Vec<(&'static str, DenoiserConfig)> {
    let mut legacy = config(32, 2, 0);
    legacy.legacy_edge_embedding = true;
    let mut layered = config(32, 3, 5);
    layered.category_layers = true;
    let mut no_hidden = config(16, 1, 3);
    no_hidden.node_head_hidden.clear();
    no_hidden.edge_head_hidden.clear();
    let shipped = DenoiserConfig {
        category_layers: true,
        ..DenoiserConfig::default()
    };
    vec![
        ("unconditional", config(32, 2, 0)),
        ("legacy edge embedding", legacy),
        ("category layers", layered),
        ("heads without hidden layers", no_hidden),
        ("shipped sizes", shipped),
    ]
}

#[test]
fn forward_matches_the_burn_model() {
    for (name, cfg) in configs() {
        let m = model(&cfg, 3);
        let h = HostDenoiser::new(&m);
        let cats = (cfg.categories > 0).then_some(cfg.categories);
        for (b, with_cat) in [(1, false), (3, true), (5, false)] {
            let c = case(b, 10 + b as u64, cats.filter(|_| with_cat));
            let (v, e, t, cat) = burn_inputs(&c, &cpu());
            let (bv, be) = m.forward(v, e, t, cat);
            let (hv, he) = host_forward(&h, &c, &mut Workspace::default(), false);
            let (dv, de) = (rel_diff(&hv, &flat(bv)), rel_diff(&he, &flat(be)));
            assert!(
                dv < 2e-5 && de < 2e-5,
                "{name}, B = {b}: ε̂_V off by {dv:e}, ε̂_E by {de:e}"
            );
        }
    }
}

#[test]
fn input_gradient_matches_burn_autodiff() {
    for (name, cfg) in configs() {
        let m = model(&cfg, 5);
        let h = HostDenoiser::new(&m);
        let cats = (cfg.categories > 0).then_some(cfg.categories);
        let c = case(3, 21, cats);
        let mut rng = Rng::new(99);
        let rv = gaussian(&mut rng, c.v.len());
        let re = gaussian(&mut rng, c.e.len());
        // burn: model on the plain device, inputs on the autodiff device (what guidance does).
        let ad = cpu_autodiff();
        let (v, e, t, cat) = burn_inputs(&c, &ad);
        let (v, e) = (v.require_grad(), e.require_grad());
        let (ev, ee) = m.forward(v.clone(), e.clone(), t, cat);
        let b = c.t.len();
        let r = |x: Vec<f32>, d: [usize; 3]| Tensor::<3>::from_data(TensorData::new(x, d), &ad);
        let loss = (ev * r(rv.clone(), [b, K, NODE_DIM])).sum()
            + (ee * r(re.clone(), [b, NUM_EDGES, EDGE_DIM])).sum();
        let grads = loss.backward();
        let gv = flat(v.grad(&grads).expect("v grad").inner());
        let ge = flat(e.grad(&grads).expect("e grad").inner());

        let mut ws = Workspace::default();
        host_forward(&h, &c, &mut ws, true);
        let mut hv = vec![0.0; c.v.len()];
        let mut he = vec![0.0; c.e.len()];
        h.backward(&mut ws, &rv, &re, &mut hv, &mut he);
        let (dv, de) = (rel_diff(&hv, &gv), rel_diff(&he, &ge));
        assert!(
            dv < 5e-5 && de < 5e-5,
            "{name}: ∂/∂V off by {dv:e}, ∂/∂E by {de:e}"
        );
        // A second backward over the same recording gives the same gradient.
        let mut hv2 = vec![0.0; c.v.len()];
        let mut he2 = vec![0.0; c.e.len()];
        h.backward(&mut ws, &rv, &re, &mut hv2, &mut he2);
        assert_eq!((hv, he), (hv2, he2), "{name}: backward is repeatable");
    }
}

#[test]
fn results_do_not_depend_on_threads_or_a_reused_workspace() {
    let mut cfg = config(32, 2, 4);
    cfg.category_layers = true;
    let m = model(&cfg, 8);
    let h = HostDenoiser::new(&m);
    let big = case(6, 1, Some(4));
    let small = case(2, 2, None);
    let run = |threads: usize, ws: &mut Workspace| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            let out = host_forward(&h, &big, ws, true);
            let mut gv = vec![0.0; big.v.len()];
            let mut ge = vec![0.0; big.e.len()];
            h.backward(ws, &big.v, &big.e, &mut gv, &mut ge);
            (out, gv, ge)
        })
    };
    let one = run(1, &mut Workspace::default());
    let mut ws = Workspace::default();
    host_forward(&h, &small, &mut ws, false);
    let two = run(2, &mut ws);
    assert_eq!(one, two, "1 vs 2 threads, fresh vs reused workspace");
}

#[test]
#[should_panic(expected = "backward without a recorded forward pass")]
fn backward_needs_a_recorded_forward() {
    let m = model(&config(16, 1, 0), 1);
    let h = HostDenoiser::new(&m);
    let c = case(1, 1, None);
    let mut ws = Workspace::default();
    host_forward(&h, &c, &mut ws, false);
    let (mut gv, mut ge) = (vec![0.0; c.v.len()], vec![0.0; c.e.len()]);
    h.backward(&mut ws, &c.v, &c.e, &mut gv, &mut ge);
}
