//! Benchmark: denoiser forward / input-gradient / training-step times on the Flex CPU backend.
//!
//! Run: `cargo run --release --example bench_denoiser -- [--threads 2] [--sweep] [--train-batch 64]`.
//! Every measurement runs inside a rayon pool of `--threads` threads (default 2, the service's
//! budget). Reported: median over the repetitions, after warm-up.
//!
//! - `fwd B`: `Denoiser::forward` on the plain device, outputs read back.
//! - `fwd+bwd B=1`: guidance set-up: model on the plain device, inputs on the autodiff device,
//!   loss = Σ x̂₀·R with x̂₀ = (x − √(1−ᾱ) ε̂)/√ᾱ, gradient w.r.t. (V, E) read back.
//! - `train B`: model on the autodiff device, ε-MSE loss, backward incl. all weight gradients
//!   (no optimiser step), i.e. the cost of one training iteration of B denoising samples.

use std::time::Instant;

use burn::tensor::{Device, Int, Tensor, TensorData};
use physnap::data::rng::Rng;
use physnap::graph::{EDGE_DIM, K, NODE_DIM, NUM_EDGES};
use physnap::model::denoiser::{Denoiser, DenoiserConfig};
use physnap::model::{cpu, cpu_autodiff};

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn median_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    f(); // warm-up (also initialises lazy parameters)
    f();
    let mut times: Vec<f64> = (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[reps / 2]
}

fn inputs(b: usize, device: &Device) -> (Tensor<3>, Tensor<3>, Tensor<1, Int>, Tensor<1, Int>) {
    let mut rng = Rng::new(1);
    let mut g = |n: usize| (0..n).map(|_| rng.gauss() as f32).collect::<Vec<_>>();
    let v = Tensor::from_data(
        TensorData::new(g(b * K * NODE_DIM), [b, K, NODE_DIM]),
        device,
    );
    let e = Tensor::from_data(
        TensorData::new(g(b * NUM_EDGES * EDGE_DIM), [b, NUM_EDGES, EDGE_DIM]),
        device,
    );
    let t = Tensor::from_data(
        TensorData::new((0..b).map(|i| (i * 61 % 1000) as i64).collect(), [b]),
        device,
    );
    let c = Tensor::from_data(
        TensorData::new((0..b).map(|i| (i % 13) as i64).collect(), [b]),
        device,
    );
    (v, e, t, c)
}

fn bench(name: &str, cfg: &DenoiserConfig, train_batch: usize) {
    let model = Denoiser::new(cfg, &cpu()).expect("valid config");
    let params = model.parameter_count();
    let cat = |c: Tensor<1, Int>| (cfg.categories > 0).then_some(c);

    let fwd = |b: usize, reps: usize| {
        let (v, e, t, c) = inputs(b, &cpu());
        median_ms(reps, || {
            let (ev, ee) = model.forward(v.clone(), e.clone(), t.clone(), cat(c.clone()));
            let _ = ev.into_data();
            let _ = ee.into_data();
        })
    };
    let f1 = fwd(1, 41);
    let f16 = fwd(16, 11);

    let ad = cpu_autodiff();
    let (v, e, t, c) = inputs(1, &ad);
    let (rv, re, _, _) = inputs(1, &ad);
    let fb1 = median_ms(21, || {
        let (v, e) = (v.clone().require_grad(), e.clone().require_grad());
        let (ev, ee) = model.forward(v.clone(), e.clone(), t.clone(), cat(c.clone()));
        let (s, r) = (0.5f32.sqrt(), 0.5f32.sqrt());
        let x0v = (v.clone() - ev * s) / r;
        let x0e = (e.clone() - ee * s) / r;
        let loss = (x0v * rv.clone()).sum() + (x0e * re.clone()).sum();
        let g = loss.backward();
        let _ = v.grad(&g).expect("v grad").into_data();
        let _ = e.grad(&g).expect("e grad").into_data();
    });

    let train = (train_batch > 0).then(|| {
        let tm = Denoiser::new(cfg, &ad).expect("valid config");
        let (v, e, t, c) = inputs(train_batch, &ad);
        let (nv, ne, _, _) = inputs(train_batch, &ad);
        median_ms(5, || {
            let (ev, ee) = tm.forward(v.clone(), e.clone(), t.clone(), cat(c.clone()));
            let loss =
                (ev - nv.clone()).powi_scalar(2).mean() + (ee - ne.clone()).powi_scalar(2).mean();
            let _grads = loss.backward();
        })
    });

    let train_s = train
        .map(|ms| {
            format!(
                "{ms:.0} ms ({:.0} samples/s)",
                train_batch as f64 / ms * 1e3
            )
        })
        .unwrap_or_else(|| "–".into());
    println!(
        "| {name} | {} | {} | {} | {} | {params} | {f1:.2} | {f16:.1} | {fb1:.1} | {train_s} |",
        cfg.width,
        cfg.layers,
        cfg.heads(),
        cfg.categories
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let threads = args
        .iter()
        .position(|a| a == "--threads")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(2usize);
    let sweep = args.iter().any(|a| a == "--sweep");
    let train_batch = args
        .iter()
        .position(|a| a == "--train-batch")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(64usize);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("rayon pool");
    pool.install(|| {
        println!("threads: {}", rayon::current_num_threads());
        println!(
            "| config | width | layers | heads | categories | parameters | fwd B=1 (ms) | fwd B=16 (ms) | fwd+bwd B=1 (ms) | train step B={train_batch} |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|");
        bench("default", &DenoiserConfig::default(), train_batch);
        bench("nap", &DenoiserConfig::nap(), if sweep { 0 } else { train_batch });
        if sweep {
            for (w, l, nh, eh) in [
                (128, 4, vec![128, 128, 128], vec![128, 64, 32]),
                (192, 4, vec![128, 128, 128], vec![128, 64, 32]),
                (256, 4, vec![256, 256, 256], vec![256, 128, 64]),
                (256, 5, vec![256, 256, 256], vec![256, 128, 64]),
            ] {
                let cfg = DenoiserConfig {
                    width: w,
                    layers: l,
                    node_head_hidden: nh,
                    edge_head_hidden: eh,
                    ..DenoiserConfig::default()
                };
                bench(&format!("w{w} L{l}"), &cfg, train_batch);
            }
        }
    });
}
