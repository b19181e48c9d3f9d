//! Benchmark: denoiser forward / input-gradient / training-step times, the burn module on the
//! Flex CPU backend beside the host inference path (`model::denoiser::host`, what sampling and
//! guidance run).
//!
//! Run: `cargo run --release --example bench_denoiser -- [--threads 2] [--weights weights]
//! [--sweep] [--train-batch 64] [--versus]`. With `--weights DIR` the first table row is the shipped
//! denoiser (its manifest's config and values) instead of a random default-config model.
//! Every measurement runs inside a rayon pool of `--threads` threads (default 2, the service's
//! budget). Reported: median over the repetitions, after warm-up.
//!
//! - `fwd B`: `Denoiser::forward` on the plain device, outputs read back.
//! - `fwd+bwd B=1`: guidance set-up: model on the plain device, inputs on the autodiff device,
//!   loss = Σ x̂₀·R with x̂₀ = (x − √(1−ᾱ) ε̂)/√ᾱ, gradient w.r.t. (V, E) read back.
//! - `host …`: the same quantities on the host path (forward with a recorded tape, then the
//!   vector–Jacobian product); `sample`: a 200-step DDIM sample B = 1 with the category,
//!   classifier-free guidance w = 2 at t < 500 (the unguided default), through `engine::sample`.
//!   Burn and host runs alternate (A B A B), so both see the same machine load.
//! - `train B`: model on the autodiff device, ε-MSE loss, backward incl. all weight gradients
//!   (no optimiser step), i.e. the cost of one training iteration of B denoising samples.

use std::time::Instant;

use burn::tensor::{Device, Int, Tensor, TensorData};
use physnap::data::rng::Rng;
use physnap::engine::sample::{SampleRequest, Sampler, sample};
use physnap::engine::schedule::Schedule;
use physnap::graph::{EDGE_DIM, K, NODE_DIM, NUM_EDGES};
use physnap::model::denoiser::host::{HostDenoiser, Workspace};
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

/// Medians of `a` and `b` over `reps` alternating runs (A B A B …), after warm-up.
fn paired_ms(reps: usize, mut a: impl FnMut(), mut b: impl FnMut()) -> (f64, f64) {
    for _ in 0..2 {
        a();
        b();
    }
    let (mut ta, mut tb) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        let t = Instant::now();
        a();
        ta.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        b();
        tb.push(t.elapsed().as_secs_f64() * 1e3);
    }
    ta.sort_by(f64::total_cmp);
    tb.sort_by(f64::total_cmp);
    (ta[reps / 2], tb[reps / 2])
}

fn flat_inputs(b: usize) -> (Vec<f32>, Vec<f32>, Vec<usize>, Vec<usize>) {
    let (v, e, t, c) = inputs(b, &cpu());
    let ints = |x: Tensor<1, Int>| -> Vec<usize> {
        x.try_into_vec_as::<i64>()
            .expect("ints")
            .into_iter()
            .map(|x| x as usize)
            .collect()
    };
    let f = |x: Tensor<3>| x.into_data().try_to_vec::<f32>().expect("f32");
    (f(v), f(e), ints(t), ints(c))
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

fn bench(name: &str, model: &Denoiser, train_batch: usize) {
    let cfg = model.config().clone();
    let params = model.parameter_count();
    let cat = |c: Tensor<1, Int>| (cfg.categories > 0).then_some(c);
    let host = HostDenoiser::new(model).with_block_samples(block_samples());

    let fwd = |b: usize, reps: usize| {
        let (v, e, t, c) = inputs(b, &cpu());
        let (hv, he, ht, hc) = flat_inputs(b);
        let mut ws = Workspace::default();
        let (mut ev, mut ee) = (vec![0.0; hv.len()], vec![0.0; he.len()]);
        paired_ms(
            reps,
            || {
                let (ev, ee) = model.forward(v.clone(), e.clone(), t.clone(), cat(c.clone()));
                let _ = ev.into_data();
                let _ = ee.into_data();
            },
            || {
                let hc = (cfg.categories > 0).then_some(hc.as_slice());
                host.forward(&hv, &he, &ht, hc, &mut ev, &mut ee, &mut ws, false);
            },
        )
    };
    let f1 = fwd(1, 41);
    let f16 = fwd(16, 15);

    let ad = cpu_autodiff();
    let (v, e, t, c) = inputs(1, &ad);
    let (rv, re, _, _) = inputs(1, &ad);
    let (hv, he, ht, hc) = flat_inputs(1);
    let (hrv, hre, _, _) = flat_inputs(1);
    let mut ws = Workspace::default();
    let (mut ev, mut ee) = (vec![0.0; hv.len()], vec![0.0; he.len()]);
    let (mut gv, mut ge) = (vec![0.0; hv.len()], vec![0.0; he.len()]);
    let fb1 = paired_ms(
        21,
        || {
            let (v, e) = (v.clone().require_grad(), e.clone().require_grad());
            let (ev, ee) = model.forward(v.clone(), e.clone(), t.clone(), cat(c.clone()));
            let (s, r) = (0.5f32.sqrt(), 0.5f32.sqrt());
            let x0v = (v.clone() - ev * s) / r;
            let x0e = (e.clone() - ee * s) / r;
            let loss = (x0v * rv.clone()).sum() + (x0e * re.clone()).sum();
            let g = loss.backward();
            let _ = v.grad(&g).expect("v grad").into_data();
            let _ = e.grad(&g).expect("e grad").into_data();
        },
        || {
            let hc = (cfg.categories > 0).then_some(hc.as_slice());
            host.forward(&hv, &he, &ht, hc, &mut ev, &mut ee, &mut ws, true);
            host.backward(&mut ws, &hrv, &hre, &mut gv, &mut ge);
        },
    );

    let sample_ms = |batch: usize| {
        let req = SampleRequest {
            seed: 1,
            batch,
            category: (cfg.categories > 0).then_some(6),
            sampler: Sampler::Ddim { eta: 0.0 },
            steps: 200,
            category_guidance: 2.0,
            category_guidance_below: Some(500),
            ..SampleRequest::default()
        };
        median_ms(5, || {
            sample(model, &Schedule::default(), &req, &cpu(), &mut |_| {
                std::ops::ControlFlow::Continue(())
            })
            .expect("sample");
        })
    };
    let (s1, s4) = (sample_ms(1), sample_ms(4));

    let train = (train_batch > 0).then(|| {
        let tm = Denoiser::new(&cfg, &ad).expect("valid config");
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
    let pair = |(b, h): (f64, f64)| format!("{b:.2} / {h:.2} ({:.2}×)", b / h);
    println!(
        "| {name} | {} × {} | {params} | {} | {} | {} | {s1:.0} / {s4:.0} | {train_s} |",
        cfg.width,
        cfg.layers,
        pair(f1),
        pair(f16),
        pair(fb1),
    );
}

/// `PHYSNAP_BENCH_BLOCK`: samples per block of the host path (default: the library's).
fn block_samples() -> usize {
    std::env::var("PHYSNAP_BENCH_BLOCK")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(physnap::model::denoiser::host::BLOCK_SAMPLES)
}

/// `--versus`: what `scripts/torch_reference/bench.py` times on both sides, on the host path,
/// as one JSON line of medians in ms: forward B = 1 and B = 16, forward + input gradient B = 1,
/// and a 200-step DDIM sample B = 1 with the category and no classifier-free guidance.
fn versus(model: &Denoiser) {
    let host = HostDenoiser::new(model).with_block_samples(block_samples());
    let cats = model.config().categories > 0;
    let fwd = |b: usize, reps: usize| {
        let (v, e, t, c) = flat_inputs(b);
        let mut ws = Workspace::default();
        let (mut ev, mut ee) = (vec![0.0; v.len()], vec![0.0; e.len()]);
        let c = cats.then_some(c.as_slice());
        median_ms(reps, || {
            host.forward(&v, &e, &t, c, &mut ev, &mut ee, &mut ws, false)
        })
    };
    let (f1, f16) = (fwd(1, 101), fwd(16, 21));
    let (v, e, t, c) = flat_inputs(1);
    let (rv, re, _, _) = flat_inputs(1);
    let c = cats.then_some(c.as_slice());
    let mut ws = Workspace::default();
    let (mut ev, mut ee) = (vec![0.0; v.len()], vec![0.0; e.len()]);
    let (mut gv, mut ge) = (vec![0.0; v.len()], vec![0.0; e.len()]);
    let fg1 = median_ms(51, || {
        host.forward(&v, &e, &t, c, &mut ev, &mut ee, &mut ws, true);
        host.backward(&mut ws, &rv, &re, &mut gv, &mut ge);
    });
    let req = SampleRequest {
        seed: 1,
        batch: 1,
        category: cats.then_some(6),
        sampler: Sampler::Ddim { eta: 0.0 },
        steps: 200,
        category_guidance: 0.0,
        ..SampleRequest::default()
    };
    let s200 = median_ms(7, || {
        sample(model, &Schedule::default(), &req, &cpu(), &mut |_| {
            std::ops::ControlFlow::Continue(())
        })
        .expect("sample");
    });
    println!(
        "{{\"forward_b1\": {f1:.4}, \"forward_b16\": {f16:.4}, \"forward_grad_b1\": {fg1:.4}, \"sample_ddim200_b1\": {s200:.3}}}"
    );
}

fn random(cfg: &DenoiserConfig) -> Denoiser {
    Denoiser::new(cfg, &cpu()).expect("valid config")
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
    let weights = args
        .iter()
        .position(|a| a == "--weights")
        .and_then(|i| args.get(i + 1))
        .map(std::path::PathBuf::from);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("rayon pool");
    let versus_mode = args.iter().any(|a| a == "--versus");
    pool.install(|| {
        if versus_mode {
            let dir = weights.clone().unwrap_or_else(|| "weights".into());
            let loaded = physnap::io::manifest::load_models(&dir, &cpu()).expect("weights");
            return versus(&loaded.denoiser);
        }
        println!("threads: {}", rayon::current_num_threads());
        println!(
            "| config | width × layers | parameters | fwd B=1 burn / host ms | fwd B=16 | fwd+grad B=1 | sample B=1 / B=4 (ms) | train step B={train_batch} |"
        );
        println!("|---|---|---|---|---|---|---|---|");
        match &weights {
            Some(dir) => {
                let loaded = physnap::io::manifest::load_models(dir, &cpu()).expect("weights");
                bench("shipped", &loaded.denoiser, train_batch);
            }
            None => bench("default", &random(&DenoiserConfig::default()), train_batch),
        }
        bench("nap", &random(&DenoiserConfig::nap()), if sweep { 0 } else { train_batch });
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
                bench(&format!("w{w} L{l}"), &random(&cfg), train_batch);
            }
        }
    });
}
