//! Diagnostic: how much does the denoiser use its category input?
//!
//! Run: `cargo run --release --example diag_category -- WEIGHTS DATA SHAPE_DIR [SPLIT] [N]`.
//!
//! For N objects of SPLIT (default `test`, N = 299), at fixed t, with one ε per object and t:
//! the grouped ε-loss with the object's own category, with "no category", and the implicit
//! classifier's accuracy — the category among the data set's categories whose conditional
//! ε̂ has the lowest loss (what a diffusion classifier reads). A model that ignores the
//! category shows equal losses and chance accuracy; one that uses it shows a gap at large t,
//! where x_t alone no longer tells the object.

use std::path::PathBuf;

use burn::tensor::{Int, Tensor, TensorData};
use physnap::data::rng::Rng;
use physnap::engine::schedule::Schedule;
use physnap::model::cpu;
use physnap::train::diffusion::{graph_noise, grouped_loss_per_sample, load_split};

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let weights = PathBuf::from(&args[1]);
    let data = PathBuf::from(&args[2]);
    let shape = PathBuf::from(&args[3]);
    let split = args.get(4).map(String::as_str).unwrap_or("test");
    let n: usize = args.get(5).map(|s| s.parse().unwrap()).unwrap_or(299);
    let device = cpu();
    let models = physnap::io::manifest::load_models(&weights, &device).expect("weights");
    let scales = models.manifest.feature_scales.clone();
    let d = load_split(&data, &shape, split).expect("data");
    let n = n.min(d.graphs.len());
    let mut present: Vec<usize> = d.categories.clone();
    present.sort();
    present.dedup();
    let none = models.denoiser.config().categories;
    let schedule = Schedule::default();
    let graphs: Vec<_> = d.graphs[..n].iter().map(|g| g.scaled(&scales)).collect();
    let (v0, e0) = physnap::engine::to_tensors(&graphs, &device);
    println!(
        "{split}: {n} objects, {} categories; t, loss(own), loss(none), loss(other, mean), implicit-classifier accuracy",
        present.len()
    );
    for &t in &[10usize, 100, 250, 400, 550, 700, 850, 950, 990] {
        let mut rng = Rng::new(7 + t as u64);
        let (eps_v, eps_e) = graph_noise(&mut rng, n, &device);
        let (a, b) = schedule.noise_coefficients(t);
        let vt = v0.clone() * a as f32 + eps_v.clone() * b as f32;
        let et = e0.clone() * a as f32 + eps_e.clone() * b as f32;
        let tt = Tensor::<1, Int>::from_data(TensorData::new(vec![t as i64; n], [n]), &device);
        let loss_with = |cats: Vec<i64>| -> Vec<f32> {
            let c = Tensor::<1, Int>::from_data(TensorData::new(cats, [n]), &device);
            let (pv, pe) = models
                .denoiser
                .forward(vt.clone(), et.clone(), tt.clone(), Some(c));
            grouped_loss_per_sample(pv, pe, eps_v.clone(), eps_e.clone())
                .into_data()
                .try_to_vec::<f32>()
                .unwrap()
        };
        let own = loss_with(d.categories[..n].iter().map(|&c| c as i64).collect());
        let no = loss_with(vec![none as i64; n]);
        let per_cat: Vec<Vec<f32>> = present
            .iter()
            .map(|&c| loss_with(vec![c as i64; n]))
            .collect();
        let mut hits = 0;
        let mut other = 0.0;
        let mut other_n = 0;
        for i in 0..n {
            let (best, _) = per_cat
                .iter()
                .enumerate()
                .min_by(|x, y| x.1[i].total_cmp(&y.1[i]))
                .unwrap();
            if present[best] == d.categories[i] {
                hits += 1;
            }
            for (j, l) in per_cat.iter().enumerate() {
                if present[j] != d.categories[i] {
                    other += l[i] as f64;
                    other_n += 1;
                }
            }
        }
        let mean = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64;
        println!(
            "t={t:4}  own {:.4}  none {:.4}  other {:.4}  classifier {:.1} %",
            mean(&own),
            mean(&no),
            other / other_n as f64,
            100.0 * hits as f64 / n as f64
        );
    }
}
