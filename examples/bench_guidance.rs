//! Benchmark: time per reverse step and per full sample for the guidance variants (uncond, pc,
//! pc+pen+mob), with a tiny and the default-sized models (random weights: the number of
//! overlapping pairs and edges over the threshold follows from random x̂₀, so the pen/mob cost is
//! that of a busy graph, not of a trained sample).
//!
//! Run: `cargo run --example bench_guidance [-- STEPS [BATCH]]` (figures go to BENCHMARKS.md);
//! BATCH (default 1) samples in one run: the cost of a guided step at N = BATCH.
//! Threads: the rayon global pool (RAYON_NUM_THREADS, default = cores).

use std::ops::ControlFlow;
use std::time::Instant;

use physnap::data::rng::Rng;
use physnap::engine::guidance::{GuidanceLosses, GuidanceOptions, Terms};
use physnap::engine::sample::{GuidanceContext, SampleRequest, sample_guided};
use physnap::engine::schedule::Schedule;
use physnap::graph::FeatureScales;
use physnap::model::denoiser::{Denoiser, DenoiserConfig};
use physnap::model::shape_prior::{ShapeDecoder, ShapePriorConfig};

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn cloud() -> Vec<[f32; 3]> {
    let mut rng = Rng::new(1);
    (0..1000)
        .map(|_| {
            [
                rng.range(-0.5, 0.5) as f32,
                rng.range(-0.4, 0.4) as f32,
                rng.range(0.0, 1.0) as f32,
            ]
        })
        .collect()
}

fn main() {
    let steps: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(10);
    let batch: usize = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    println!("batch: {batch}");
    println!("threads: {}", rayon::current_num_threads());
    let dev = physnap::model::cpu();
    let tiny = (
        "tiny",
        DenoiserConfig {
            width: 32,
            layers: 1,
            head_channels: 8,
            node_head_hidden: vec![32],
            edge_head_hidden: vec![32],
            ..DenoiserConfig::default()
        },
        ShapePriorConfig {
            decoder_hidden: 32,
            decoder_blocks: 1,
            ..ShapePriorConfig::default()
        },
    );
    let default = (
        "default",
        DenoiserConfig::default(),
        ShapePriorConfig::default(),
    );
    let scales = FeatureScales::default();
    println!(
        "| model | variant | ms / step | guided terms (last step) | est. 1000-step sample (s) |"
    );
    println!("|---|---|---|---|---|");
    for (name, dcfg, scfg) in [tiny, default] {
        let denoiser = Denoiser::new(&dcfg, &dev).expect("config");
        let decoder = ShapeDecoder::new(&scfg, &mut Rng::new(0), &dev);
        let mut plain_ms = 0.0;
        for (variant, terms) in [
            ("uncond", None),
            (
                "pc",
                Some(Terms {
                    pc: true,
                    ..Terms::default()
                }),
            ),
            ("pc+pen+mob", Some(Terms::ALL)),
        ] {
            // Every step guided; the clamp keeps a random model's sample from running off (it
            // changes no cost: the same queries are made).
            let guidance = terms.map(|t| GuidanceOptions {
                steps: 1000,
                max_step: Some(0.05),
                ..GuidanceOptions::paper(cloud(), t)
            });
            let req = SampleRequest {
                seed: 3,
                batch,
                category: None,
                guidance,
                steps,
                ..Default::default()
            };
            let mut last = GuidanceLosses::default();
            let t0 = Instant::now();
            let r = sample_guided(
                &denoiser,
                &Schedule::default(),
                &req,
                Some(GuidanceContext {
                    field: &decoder,
                    scales: &scales,
                }),
                &dev,
                &mut |s| {
                    if let Some(l) = s.guidance {
                        last = l;
                    }
                    ControlFlow::Continue(())
                },
            );
            let ms = t0.elapsed().as_secs_f64() * 1e3 / steps as f64;
            if terms.is_none() {
                plain_ms = ms;
            }
            // Paper schedule: 500 plain + 500 guided steps.
            let full = if terms.is_none() {
                ms
            } else {
                0.5 * (ms + plain_ms)
            };
            let status = match r {
                Ok(_) => format!(
                    "pc {:.2e} pen {:.2e} mob {:.2e}",
                    last.pc, last.pen, last.mob
                ),
                Err(e) => format!("error: {e}"),
            };
            println!("| {name} | {variant} | {ms:.1} | {status} | {:.1} |", full);
        }
    }
}
