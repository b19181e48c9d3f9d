//! The reverse-diffusion sampling loop.
//!
//! Why it exists: one loop serves the CLI, the service and evaluation. Per step it calls the
//! denoiser, applies the schedule's update, checks for divergence, and hands a [`StepEvent`] to
//! the caller's callback, which can stop the run (cancellation, deadline) — the hook the
//! service's progress stream and the guidance terms attach to.
//!
//! Determinism: all noise (x_T and every z) is drawn from `Rng::new(seed)` in a fixed order and
//! uploaded as data, so a seed fixes the output for a given model and thread count.

use std::ops::ControlFlow;

use burn::tensor::{Device, Int, Tensor, TensorData};

use super::schedule::Schedule;
use super::{EngineError, from_tensors};
use crate::data::rng::Rng;
use crate::graph::{EDGE_DIM, GraphTensor, K, NODE_DIM, NUM_EDGES};
use crate::model::denoiser::Denoiser;

/// What to sample.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SampleRequest {
    /// Seed of all noise.
    pub seed: u64,
    /// Samples generated together (one batch).
    pub batch: usize,
    /// Category index (None = unconditional, using the model's "no category" entry when it
    /// has one).
    pub category: Option<usize>,
    /// Attach the predicted clean graph x̂₀ to every this many steps' event (0: never). The
    /// service streams it as a light preview of where the sample is heading.
    pub preview_every: usize,
}

/// Reported after every reverse step.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StepEvent {
    /// 1-based step number.
    pub step: usize,
    /// Steps in the run.
    pub total: usize,
    /// Diffusion time index of the step just taken (999 … 0).
    pub t: usize,
    /// x̂₀ = (x_t − √(1−ᾱ_t) ε̂) / √ᾱ_t of this step in model (scaled) space, one graph per batch
    /// element; present every `preview_every` steps and on the last step when requested.
    pub x0_preview: Option<Vec<GraphTensor>>,
}

fn gaussian(rng: &mut Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.gauss() as f32).collect()
}

/// Run the full reverse diffusion; returns the final x₀ graphs in *model (scaled) space*.
/// `on_step` may return `ControlFlow::Break(reason)` to stop with [`EngineError::Stopped`].
pub fn sample(
    model: &Denoiser,
    schedule: &Schedule,
    req: &SampleRequest,
    device: &Device,
    on_step: &mut dyn FnMut(&StepEvent) -> ControlFlow<String>,
) -> Result<Vec<GraphTensor>, EngineError> {
    if req.batch == 0 {
        return Err(EngineError::Invalid {
            field: "batch".into(),
            limit: "at least 1".into(),
            value: "0".into(),
        });
    }
    let b = req.batch;
    let (nv, ne) = (b * K * NODE_DIM, b * NUM_EDGES * EDGE_DIM);
    let mut rng = Rng::new(req.seed);
    let mut v = Tensor::<3>::from_data(
        TensorData::new(gaussian(&mut rng, nv), [b, K, NODE_DIM]),
        device,
    );
    let mut e = Tensor::<3>::from_data(
        TensorData::new(gaussian(&mut rng, ne), [b, NUM_EDGES, EDGE_DIM]),
        device,
    );
    let category = req
        .category
        .map(|c| Tensor::<1, Int>::from_data(TensorData::new(vec![c as i64; b], [b]), device));
    let total = schedule.len();
    for (k, t) in (0..total).rev().enumerate() {
        let tt = Tensor::<1, Int>::from_data(TensorData::new(vec![t as i64; b], [b]), device);
        let (eps_v, eps_e) = model.forward(v.clone(), e.clone(), tt, category.clone());
        let x0_preview = (req.preview_every > 0 && ((k + 1) % req.preview_every == 0 || t == 0))
            .then(|| {
                let (s, n) = schedule.noise_coefficients(t);
                let (s, n) = (s as f32, n as f32);
                from_tensors(
                    (v.clone() - eps_v.clone() * n) / s,
                    (e.clone() - eps_e.clone() * n) / s,
                )
            });
        let c = schedule.step_coefficients(t);
        v = v * c.c_x - eps_v * c.c_eps;
        e = e * c.c_x - eps_e * c.c_eps;
        if c.sigma > 0.0 {
            let zv = Tensor::<3>::from_data(
                TensorData::new(gaussian(&mut rng, nv), [b, K, NODE_DIM]),
                device,
            );
            let ze = Tensor::<3>::from_data(
                TensorData::new(gaussian(&mut rng, ne), [b, NUM_EDGES, EDGE_DIM]),
                device,
            );
            v = v + zv * c.sigma;
            e = e + ze * c.sigma;
        }
        // A cheap divergence check every 50 steps and at the end.
        if k % 50 == 49 || t == 0 {
            for (what, x) in [("nodes", &v), ("edges", &e)] {
                let s: f32 = x.clone().abs().max().into_scalar::<f32>();
                if !s.is_finite() {
                    return Err(EngineError::Diverged {
                        step: k + 1,
                        t,
                        what,
                    });
                }
            }
        }
        if let ControlFlow::Break(reason) = on_step(&StepEvent {
            step: k + 1,
            total,
            t,
            x0_preview,
        }) {
            return Err(EngineError::Stopped {
                step: k + 1,
                total,
                reason,
            });
        }
    }
    Ok(from_tensors(v, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::denoiser::DenoiserConfig;

    fn tiny() -> Denoiser {
        let cfg = DenoiserConfig {
            width: 16,
            layers: 1,
            head_channels: 8,
            node_head_hidden: vec![16],
            edge_head_hidden: vec![16],
            categories: 3,
            ..DenoiserConfig::default()
        };
        Denoiser::new(&cfg, &crate::model::cpu()).unwrap()
    }

    #[test]
    fn sampling_is_deterministic_per_seed_and_reports_every_step() {
        let model = tiny();
        let schedule = Schedule::default();
        let dev = crate::model::cpu();
        let req = SampleRequest {
            seed: 7,
            batch: 2,
            category: Some(1),
            preview_every: 0,
        };
        let mut steps = Vec::new();
        let a = sample(&model, &schedule, &req, &dev, &mut |s| {
            steps.push(s.t);
            ControlFlow::Continue(())
        })
        .unwrap();
        assert_eq!(steps.len(), 1000);
        assert_eq!((steps[0], steps[999]), (999, 0));
        let b = sample(&model, &schedule, &req, &dev, &mut |_| {
            ControlFlow::Continue(())
        })
        .unwrap();
        assert_eq!(a, b);
        assert!(a.iter().all(|g| g.flatten().iter().all(|v| v.is_finite())));
        let c = sample(
            &model,
            &schedule,
            &SampleRequest {
                seed: 8,
                ..req.clone()
            },
            &dev,
            &mut |_| ControlFlow::Continue(()),
        )
        .unwrap();
        assert_ne!(a, c);
    }

    #[test]
    fn previews_come_every_k_steps_and_the_last_one_is_the_result() {
        let model = tiny();
        let req = SampleRequest {
            seed: 3,
            batch: 1,
            category: None,
            preview_every: 250,
        };
        let mut previews = Vec::new();
        let out = sample(
            &model,
            &Schedule::default(),
            &req,
            &crate::model::cpu(),
            &mut |s| {
                if let Some(p) = &s.x0_preview {
                    previews.push((s.step, p.clone()));
                }
                ControlFlow::Continue(())
            },
        )
        .unwrap();
        let steps: Vec<usize> = previews.iter().map(|(s, _)| *s).collect();
        assert_eq!(steps, vec![250, 500, 750, 1000]);
        // At t = 0 the DDPM mean is exactly x̂₀ (σ = 0, ᾱ₀ = α₀).
        let last = previews.last().unwrap().1[0].flatten();
        for (a, b) in last.iter().zip(out[0].flatten()) {
            assert!((a - b).abs() < 1e-3 * (1.0 + b.abs()), "{a} vs {b}");
        }
    }

    #[test]
    fn the_callback_can_stop_a_run() {
        let model = tiny();
        let req = SampleRequest {
            seed: 1,
            batch: 1,
            category: None,
            preview_every: 0,
        };
        let e = sample(
            &model,
            &Schedule::default(),
            &req,
            &crate::model::cpu(),
            &mut |s| {
                if s.step == 5 {
                    ControlFlow::Break("cancelled".into())
                } else {
                    ControlFlow::Continue(())
                }
            },
        )
        .unwrap_err();
        assert!(matches!(e, EngineError::Stopped { step: 5, .. }), "{e}");
        assert!(e.to_string().contains("cancelled"));
    }
}
