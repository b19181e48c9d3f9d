//! The reverse-diffusion sampling loop.
//!
//! Why it exists: one loop serves the CLI, the service and evaluation. Per step it calls the
//! denoiser, applies the schedule's update, checks for divergence, and hands a [`StepEvent`] to
//! the caller's callback, which can stop the run (cancellation, deadline) — the hook the
//! service's progress stream and the guidance terms attach to.
//!
//! Refinement (physnap, not in the paper; `GuidanceOptions::refine_steps`, 0 in the paper's
//! settings, 30 at the CLI / service): after the last reverse step,
//! `x₀ ← x₀ − clamp(∇_{x₀} ℓ(x₀), ±0.1·max_step)` on the finished sample, with no denoiser and
//! no noise. The 200-step default leaves part overlaps the 1000-step sampler removes over its
//! 500 guided steps; these steps remove them (EVALUATION.md, "Refinement after sampling"). The
//! full clamp makes them bounce on ℓ_pc's landscape, a tenth of it descends. Physics-only
//! refinement (`refine_physics_steps`, 0 by default) then runs more such steps on
//! `w_pen ℓ_pen + w_mob ℓ_mob` alone, on the part boxes alone, which pushes out the small
//! overlaps that ℓ_pc holds in place; the lowest-loss state they evaluated is the result.
//!
//! Determinism: all noise (x_T and every z) is drawn from `Rng::new(seed)` in a fixed order and
//! uploaded as data, so a seed fixes the output for a given model and thread count.

use std::ops::ControlFlow;

use burn::tensor::{Device, Int, Tensor, TensorData};

use super::guidance::{GuidanceLosses, GuidanceOptions, SdfField, guidance_loss};
use super::schedule::{Schedule, timesteps};
use super::{EngineError, from_tensors};
use crate::data::rng::Rng;
use crate::graph::{EDGE_DIM, FeatureScales, GraphTensor, K, NODE_DIM, NUM_EDGES};
use crate::model::denoiser::Denoiser;

/// The reverse-step rule.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Sampler {
    /// NAP's DDPM (σ² = β_t) over every step; with fewer steps, the strided ancestral sampler
    /// (DDIM with η = 1).
    #[default]
    Ddpm,
    /// DDIM with noise level η (0: deterministic given x_T).
    Ddim {
        /// η ∈ [0, 1].
        eta: f64,
    },
}

impl Sampler {
    /// Wire / flag name: `ddpm` or `ddim`.
    pub fn name(self) -> &'static str {
        match self {
            Sampler::Ddpm => "ddpm",
            Sampler::Ddim { .. } => "ddim",
        }
    }

    /// DDIM's η; 0 for DDPM.
    pub fn eta(self) -> f64 {
        match self {
            Sampler::Ddpm => 0.0,
            Sampler::Ddim { eta } => eta,
        }
    }
}

/// The reverse steps physnap's CLI and service use by default: DDIM (η = 0) over 200 of the
/// 1000 schedule steps, the last 100 of them guided (n_g = 500 of 1000, scaled). The paper's
/// 1000-step DDPM with n_g = 500 takes minutes per guided sample on 2 cores; EVALUATION.md
/// ("Fast sampling") compares the two. [`SampleRequest::default`] stays the paper's sampler.
pub const DEFAULT_STEPS: usize = 200;

/// Largest |∇ℓ| entry a guided step may subtract (model space, where features are scaled to
/// about [−1, 1]); a step that throws a value this far is a blow-up and fails as diverged.
pub const DIVERGENCE_LIMIT: f32 = 1e4;

/// Mixed into the seed for the stream of ℓ_mob's joint states (`Rng::fork(seed ^ this, step)`),
/// apart from the diffusion noise.
const MOB_STREAM: u64 = 0x4755_4944_414e_4345;

/// The category guidance weight the CLI and the service use by default for plain sampling
/// (see EVALUATION.md, "Category guidance").
pub const UNGUIDED_CATEGORY_GUIDANCE: f64 = 2.0;

/// The category guidance weight by default when loss guidance pulls the sample to a scan: none.
/// There w = 2 put completions 1.6× further from the scanned object (ID_gt) than w = 0, on the
/// fresh and on the test scans, and D_pc and part overlap were no better (EVALUATION.md, "Scan
/// completion measured against the scanned object"). The category still conditions the
/// denoiser.
pub const LOSS_GUIDED_CATEGORY_GUIDANCE: f64 = 0.0;

/// The [`SampleRequest::category_guidance`] the CLI, the evaluations and the service run: the
/// requested weight, else [`UNGUIDED_CATEGORY_GUIDANCE`] for plain sampling and
/// [`LOSS_GUIDED_CATEGORY_GUIDANCE`] when loss guidance pulls the sample to a scan. Not
/// range-checked here: [`sample_guided`] and the service validate it.
pub fn category_guidance(requested: Option<f64>, loss_guided: bool) -> f64 {
    requested.unwrap_or(if loss_guided {
        LOSS_GUIDED_CATEGORY_GUIDANCE
    } else {
        UNGUIDED_CATEGORY_GUIDANCE
    })
}

/// Without loss guidance, category guidance is applied by default only in the steps with
/// diffusion time t below this ([`SampleRequest::category_guidance_below`]): above it the
/// guidance buys no category accuracy, only larger objects with more parts, and costs a second
/// forward per step (EVALUATION.md, "Category guidance only at t < 500").
pub const UNGUIDED_CATEGORY_GUIDANCE_BELOW: usize = 500;

/// The [`SampleRequest::category_guidance_below`] the CLI, the evaluations and the service run:
/// the requested limit, else [`UNGUIDED_CATEGORY_GUIDANCE_BELOW`] for plain sampling and every
/// step when loss guidance pulls the sample to a scan (there the limit aligned worse;
/// EVALUATION.md). Not range-checked here: [`sample_guided`] and the service validate it.
pub fn category_guidance_below(requested: Option<usize>, loss_guided: bool) -> usize {
    requested.unwrap_or(if loss_guided {
        crate::engine::schedule::NUM_STEPS
    } else {
        UNGUIDED_CATEGORY_GUIDANCE_BELOW
    })
}

/// Largest accepted [`SampleRequest::category_guidance`].
pub const MAX_CATEGORY_GUIDANCE: f64 = 20.0;

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
    /// Loss guidance (PhysNAP); None: plain NAP sampling. Needs [`sample_guided`].
    pub guidance: Option<GuidanceOptions>,
    /// Reverse-step rule.
    pub sampler: Sampler,
    /// Number of reverse steps (0: every step of the schedule).
    pub steps: usize,
    /// Classifier-free category guidance weight w (Ho & Salimans 2022):
    /// ε̂ = ε̂(c) + w·(ε̂(c) − ε̂(∅)), with ∅ the model's "no category" row, which category
    /// dropout in training taught. 0: plain conditioning (one forward per step); > 0 costs a
    /// second forward (batched with the first). Ignored without a category or for an
    /// unconditional model.
    pub category_guidance: f64,
    /// Apply the category guidance only in steps with diffusion time t below this (the other
    /// steps use the plain conditional prediction, one forward); None: in every step.
    pub category_guidance_below: Option<usize>,
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
    /// Guidance loss values of this step (guided steps only).
    pub guidance: Option<GuidanceLosses>,
}

fn gaussian(rng: &mut Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.gauss() as f32).collect()
}

/// Run the full reverse diffusion; returns the final x₀ graphs in *model (scaled) space*.
/// `on_step` may return `ControlFlow::Break(reason)` to stop with [`EngineError::Stopped`].
/// Guided requests need the shape decoder: use [`sample_guided`].
pub fn sample(
    model: &Denoiser,
    schedule: &Schedule,
    req: &SampleRequest,
    device: &Device,
    on_step: &mut dyn FnMut(&StepEvent) -> ControlFlow<String>,
) -> Result<Vec<GraphTensor>, EngineError> {
    sample_guided(model, schedule, req, None, device, on_step)
}

/// The shape decoder and feature scales guidance needs to decode x̂₀.
#[derive(Clone, Copy)]
pub struct GuidanceContext<'a> {
    /// The part SDF (the trained shape decoder).
    pub field: &'a dyn SdfField,
    /// Model space → raw units.
    pub scales: &'a FeatureScales,
}

fn check_state(
    x: &Tensor<3>,
    what: &'static str,
    step: usize,
    t: usize,
) -> Result<(), EngineError> {
    let s: f32 = x.clone().abs().max().into_scalar::<f32>();
    if !s.is_finite() {
        return Err(EngineError::Diverged { step, t, what });
    }
    Ok(())
}

/// [`sample`] with optional loss guidance (method.md §8.2, DPS): in steps with t < n_g,
/// ε̂ and x̂₀ are computed on the autodiff device, ℓ(x̂₀ ⊙ scales) is back-propagated through the
/// SDF field and the denoiser to x_t, and −∇ℓ is added after the usual update. The model's
/// weights stay on the plain device (no weight gradients). The mobility states are drawn from
/// `Rng::fork(seed, step)`, apart from the diffusion noise, so a seed fixes the result and
/// guided and unguided runs share their noise.
pub fn sample_guided(
    model: &Denoiser,
    schedule: &Schedule,
    req: &SampleRequest,
    guide: Option<GuidanceContext<'_>>,
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
    let eta = match req.sampler {
        Sampler::Ddpm => 1.0,
        Sampler::Ddim { eta } => {
            if !(eta.is_finite() && (0.0..=1.0).contains(&eta)) {
                return Err(EngineError::Invalid {
                    field: "sampler.eta".into(),
                    limit: "in [0, 1]".into(),
                    value: eta.to_string(),
                });
            }
            eta
        }
    };
    if !(req.category_guidance.is_finite()
        && (0.0..=MAX_CATEGORY_GUIDANCE).contains(&req.category_guidance))
    {
        return Err(EngineError::Invalid {
            field: "category_guidance".into(),
            limit: format!("in [0, {MAX_CATEGORY_GUIDANCE}]"),
            value: req.category_guidance.to_string(),
        });
    }
    if let Some(below) = req.category_guidance_below
        && !(1..=schedule.len()).contains(&below)
    {
        return Err(EngineError::Invalid {
            field: "category_guidance_below".into(),
            limit: format!("in [1, {}]", schedule.len()),
            value: below.to_string(),
        });
    }
    if req.steps > schedule.len() {
        return Err(EngineError::Invalid {
            field: "steps".into(),
            limit: format!("at most {} (0: all)", schedule.len()),
            value: req.steps.to_string(),
        });
    }
    let guidance = match (&req.guidance, guide) {
        (Some(g), Some(ctx)) if g.is_active() => {
            g.validate(schedule.len())?;
            if ctx.field.latent() + crate::graph::node_ch::LATENT > NODE_DIM {
                return Err(EngineError::Invalid {
                    field: "guidance.decoder".into(),
                    limit: format!(
                        "latent width ≤ {}",
                        NODE_DIM - crate::graph::node_ch::LATENT
                    ),
                    value: ctx.field.latent().to_string(),
                });
            }
            ctx.scales.validate().map_err(|e| EngineError::Invalid {
                field: "guidance.scales".into(),
                limit: "valid feature scales".into(),
                value: e.to_string(),
            })?;
            Some((g, ctx))
        }
        (Some(g), None) if g.is_active() => {
            return Err(EngineError::Invalid {
                field: "guidance".into(),
                limit: "a shape decoder (call sample_guided / generate_with)".into(),
                value: "none given".into(),
            });
        }
        _ => None,
    };
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
    // Classifier-free guidance: the conditional and the "no category" batch in one forward.
    let cfg = req
        .category
        .filter(|_| req.category_guidance > 0.0 && model.config().categories > 0)
        .map(|c| {
            let mut idx = vec![c as i64; b];
            idx.extend(vec![model.config().categories as i64; b]);
            (
                Tensor::<1, Int>::from_data(TensorData::new(idx, [2 * b]), device),
                req.category_guidance as f32,
            )
        });
    let guide_below = req.category_guidance_below.unwrap_or(usize::MAX);
    let predict = |v: Tensor<3>, e: Tensor<3>, t: usize| -> (Tensor<3>, Tensor<3>) {
        match cfg.as_ref().filter(|_| t < guide_below) {
            None => {
                let tt =
                    Tensor::<1, Int>::from_data(TensorData::new(vec![t as i64; b], [b]), device);
                model.forward(v, e, tt, category.clone())
            }
            Some((cats, w)) => {
                let tt = Tensor::<1, Int>::from_data(
                    TensorData::new(vec![t as i64; 2 * b], [2 * b]),
                    device,
                );
                let (ev, ee) = model.forward(
                    Tensor::cat(vec![v.clone(), v], 0),
                    Tensor::cat(vec![e.clone(), e], 0),
                    tt,
                    Some(cats.clone()),
                );
                let mix = |x: Tensor<3>| {
                    let c = x.clone().narrow(0, 0, b);
                    let u = x.narrow(0, b, b);
                    c.clone() + (c - u) * *w
                };
                (mix(ev), mix(ee))
            }
        }
    };
    let scale_tensors = guidance.map(|(_, ctx)| {
        (
            Tensor::<3>::from_data(
                TensorData::new(ctx.scales.node.clone(), [1, 1, NODE_DIM]),
                device,
            ),
            Tensor::<3>::from_data(
                TensorData::new(ctx.scales.edge.clone(), [1, 1, EDGE_DIM]),
                device,
            ),
        )
    });
    let times = timesteps(schedule.len(), req.steps);
    let full = times.len() == schedule.len();
    let total = step_events(schedule.len(), req.steps, guidance.map(|(g, _)| g));
    for (k, &t) in times.iter().enumerate() {
        let t_prev = times.get(k + 1).copied();
        let (s, n) = schedule.noise_coefficients(t);
        let (s, n) = (s as f32, n as f32);
        let guided = guidance.filter(|(g, _)| t < g.steps);
        let mut losses = None;
        let (eps_v, eps_e, grad) = if let Some((g, ctx)) = guided {
            let va = v.clone().autodiff().require_grad();
            let ea = e.clone().autodiff().require_grad();
            let (ev, ee) = predict(va.clone(), ea.clone(), t);
            let (sv, se) = scale_tensors.clone().expect("scales with guidance");
            let x0v = (va.clone() - ev.clone() * n) / s * sv.autodiff();
            let x0e = (ea.clone() - ee.clone() * n) / s * se.autodiff();
            let mut mob_rng = Rng::fork(req.seed ^ MOB_STREAM, k as u64);
            let (grad, values) = guidance_gradient(
                ctx.field,
                g,
                (&va, &ea),
                (x0v, x0e),
                &mut mob_rng,
                (k + 1, t),
            )?;
            losses = Some(values);
            (ev.inner(), ee.inner(), grad)
        } else {
            let (ev, ee) = predict(v.clone(), e.clone(), t);
            (ev, ee, None)
        };
        let x0_preview = (req.preview_every > 0
            && ((k + 1) % req.preview_every == 0 || k + 1 == total))
            .then(|| {
                from_tensors(
                    (v.clone() - eps_v.clone() * n) / s,
                    (e.clone() - eps_e.clone() * n) / s,
                )
            });
        let c = if full {
            schedule.step_coefficients(t)
        } else {
            schedule.jump_coefficients(t, t_prev, eta)
        };
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
        if let (Some((g, _)), Some(grad)) = (guided, grad) {
            (v, e) = descend((v, e), grad, g.max_step);
        }
        // A cheap divergence check every 50 steps, every guided step and at the end.
        if k % 50 == 49 || k + 1 == times.len() || guided.is_some() {
            check_state(&v, "nodes", k + 1, t)?;
            check_state(&e, "edges", k + 1, t)?;
        }
        if let ControlFlow::Break(reason) = on_step(&StepEvent {
            step: k + 1,
            total,
            t,
            x0_preview,
            guidance: losses,
        }) {
            return Err(EngineError::Stopped {
                step: k + 1,
                total,
                reason,
            });
        }
    }
    // Refinement (physnap, not in the paper): small clamped gradient steps on ℓ of the sample
    // itself, x₀ ← x₀ − clamp(∇_{x₀} ℓ(x₀)); no denoiser, no noise.
    // Then the physics-only steps, the same with ℓ_pc off (`refine_physics_steps`).
    if let Some((g, ctx)) = guidance.filter(|(g, _)| g.refine_steps + g.physics_steps_run() > 0) {
        let (sv, se) = scale_tensors.expect("scales with guidance");
        let (refine, physics) = (g.refine_steps, g.physics_only());
        let box_mask = physics_mask(&v.device());
        // The physics phase keeps the lowest-loss state it evaluated (the first is the refined
        // sample): its loss is noisy (ℓ_mob draws new joint states each step) and jumps where
        // boxes start to intersect, so the last iterate can be far worse than an earlier one.
        let mut best: Option<(f64, Tensor<3>, Tensor<3>)> = None;
        for r in 0..refine + g.physics_steps_run() {
            let step = times.len() + r + 1;
            let physics_step = r >= refine;
            let g = if physics_step { &physics } else { g };
            let va = v.clone().autodiff().require_grad();
            let ea = e.clone().autodiff().require_grad();
            let x0v = va.clone() * sv.clone().autodiff();
            let x0e = ea.clone() * se.clone().autodiff();
            let mut mob_rng = Rng::fork(req.seed ^ MOB_STREAM, (step - 1) as u64);
            let (grad, values) = guidance_gradient(
                ctx.field,
                g,
                (&va, &ea),
                (x0v, x0e),
                &mut mob_rng,
                (step, 0),
            )?;
            if physics_step && best.as_ref().is_none_or(|b| values.total < b.0) {
                best = Some((values.total, v.clone(), e.clone()));
            }
            if let Some(grad) = grad {
                // A physics-only step moves the part boxes alone (see `physics_mask`).
                let grad = if physics_step {
                    (grad.0.map(|x| x * box_mask.clone()), None)
                } else {
                    grad
                };
                (v, e) = descend((v, e), grad, g.refine_max_step());
            }
            check_state(&v, "nodes", step, 0)?;
            check_state(&e, "edges", step, 0)?;
            let x0_preview = (req.preview_every > 0
                && (step.is_multiple_of(req.preview_every) || step == total))
                .then(|| from_tensors(v.clone(), e.clone()));
            if let ControlFlow::Break(reason) = on_step(&StepEvent {
                step,
                total,
                t: 0,
                x0_preview,
                guidance: Some(values),
            }) {
                return Err(EngineError::Stopped {
                    step,
                    total,
                    reason,
                });
            }
        }
        if let Some((_, bv, be)) = best {
            (v, e) = (bv, be);
        }
    }
    Ok(from_tensors(v, e))
}

/// The node channels a physics-only refinement step moves: each part's box half-extents and
/// centre (1 there, 0 elsewhere, `[1, 1, NODE_DIM]`). Existence, shape code and joints stay. Left
/// free, ℓ_pen's cheapest way out is to lower a part's existence (õ_i õ_j weights the pair) or
/// to reshape it, and on guided samples of earlier weights 10 steps on every channel deleted whole parts
/// (D_pc 0.0050 → 0.0223 on one scan; EVALUATION.md, "Physics-only refinement").
fn physics_mask(device: &Device) -> Tensor<3> {
    use crate::graph::node_ch;
    let mask: Vec<f32> = (0..NODE_DIM)
        .map(|c| f32::from((node_ch::BOX..node_ch::LATENT).contains(&c)))
        .collect();
    Tensor::from_data(TensorData::new(mask, [1, 1, NODE_DIM]), device)
}

/// How many [`StepEvent`]s a sample reports (its `total`): the reverse steps of `steps` (0: all
/// of a `schedule_len` schedule), plus the refinement steps of an active guidance.
pub fn step_events(schedule_len: usize, steps: usize, guidance: Option<&GuidanceOptions>) -> usize {
    timesteps(schedule_len, steps).len()
        + guidance
            .filter(|g| g.is_active())
            .map_or(0, |g| g.refine_steps + g.physics_steps_run())
}

/// Per-entry gradients of ℓ with respect to the (autodiff) nodes and edges.
type Gradient = (Option<Tensor<3>>, Option<Tensor<3>>);

/// ℓ(x̂₀) and its gradient with respect to `wrt`, where `x0` = (nodes, edges) of x̂₀ in raw units
/// was computed from `wrt` on the autodiff device. Fails as diverged on a non-finite loss, or on
/// a non-finite gradient (or, without a clamp, one beyond [`DIVERGENCE_LIMIT`]).
fn guidance_gradient(
    field: &dyn SdfField,
    g: &GuidanceOptions,
    wrt: (&Tensor<3>, &Tensor<3>),
    x0: (Tensor<3>, Tensor<3>),
    mob_rng: &mut Rng,
    (step, t): (usize, usize),
) -> Result<(Option<Gradient>, GuidanceLosses), EngineError> {
    let (loss, mut values) = guidance_loss(field, g, x0.0, x0.1, mob_rng);
    if !values.total.is_finite() {
        return Err(EngineError::Diverged {
            step,
            t,
            what: "guidance loss",
        });
    }
    let grad = loss.map(|loss| {
        let grads = loss.backward();
        let gv = wrt.0.grad(&grads).map(|g| g.inner());
        let ge = wrt.1.grad(&grads).map(|g| g.inner());
        (gv, ge)
    });
    let mut gmax = 0.0f32;
    if let Some((gv, ge)) = &grad {
        for x in [gv, ge].into_iter().flatten() {
            let m: f32 = x.clone().abs().max().into_scalar::<f32>();
            gmax = if m.is_nan() { f32::NAN } else { gmax.max(m) };
        }
    }
    tracing::debug!(
        step,
        t,
        pc = values.pc,
        pen = values.pen,
        mob = values.mob,
        grad_max = gmax,
        "guided step"
    );
    let limit = if g.max_step.is_some() {
        f32::INFINITY
    } else {
        DIVERGENCE_LIMIT
    };
    if !(gmax.is_finite() && gmax <= limit) {
        return Err(EngineError::Diverged {
            step,
            t,
            what: "guidance gradient",
        });
    }
    values.grad_max = gmax as f64;
    Ok((grad, values))
}

/// x ← x − clamp(∇ℓ, ±max_step) (no clamp when `max_step` is None).
fn descend(
    (v, e): (Tensor<3>, Tensor<3>),
    (gv, ge): Gradient,
    max_step: Option<f64>,
) -> (Tensor<3>, Tensor<3>) {
    let clip = |g: Tensor<3>| match max_step {
        Some(c) => g.clamp(-c as f32, c as f32),
        None => g,
    };
    let v = match gv {
        Some(g) => v - clip(g),
        None => v,
    };
    let e = match ge {
        Some(g) => e - clip(g),
        None => e,
    };
    (v, e)
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
            ..Default::default()
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
    fn category_guidance_extrapolates_from_the_no_category_prediction() {
        // One deterministic DDIM jump from t = 999 lands on x̂₀, which is linear in ε̂, so the
        // guided result must be out(c) + w·(out(c) − out(∅)) for the same noise.
        let model = tiny();
        let dev = crate::model::cpu();
        let run = |category: Option<usize>, w: f64| {
            let req = SampleRequest {
                seed: 4,
                batch: 2,
                category,
                sampler: Sampler::Ddim { eta: 0.0 },
                steps: 1,
                category_guidance: w,
                ..Default::default()
            };
            sample(&model, &Schedule::default(), &req, &dev, &mut |_| {
                ControlFlow::Continue(())
            })
            .map(|gs| gs.iter().flat_map(|g| g.flatten()).collect::<Vec<f32>>())
        };
        let cond = run(Some(2), 0.0).unwrap();
        let none = run(None, 0.0).unwrap();
        let guided = run(Some(2), 3.0).unwrap();
        assert_ne!(cond, none, "the category must change the prediction");
        for ((c, u), g) in cond.iter().zip(&none).zip(&guided) {
            let want = c + 3.0 * (c - u);
            assert!(
                (g - want).abs() <= 1e-3 * (1.0 + want.abs()),
                "{g} vs {want}"
            );
        }
        // Without a category the weight has nothing to extrapolate from: plain sampling.
        assert_eq!(run(None, 3.0).unwrap(), none);
        // Out-of-range weights are refused, naming the field, the limit and the value.
        let e = run(Some(2), -1.0).unwrap_err().to_string();
        assert!(
            e.contains("category_guidance") && e.contains("[0, 20]") && e.contains("-1"),
            "{e}"
        );
    }

    #[test]
    fn category_guidance_applies_only_below_its_time_limit() {
        // The single DDIM jump runs at t = 999: a limit at or below it leaves the plain
        // conditional prediction, a limit above it (1000, the whole schedule) guides.
        let model = tiny();
        let dev = crate::model::cpu();
        let run = |w: f64, below: Option<usize>| {
            let req = SampleRequest {
                seed: 4,
                batch: 1,
                category: Some(1),
                sampler: Sampler::Ddim { eta: 0.0 },
                steps: 1,
                category_guidance: w,
                category_guidance_below: below,
                ..Default::default()
            };
            sample(&model, &Schedule::default(), &req, &dev, &mut |_| {
                ControlFlow::Continue(())
            })
            .map(|gs| gs.iter().flat_map(|g| g.flatten()).collect::<Vec<f32>>())
        };
        let plain = run(0.0, None).unwrap();
        let guided = run(2.0, None).unwrap();
        assert_ne!(plain, guided);
        assert_eq!(run(2.0, Some(999)).unwrap(), plain);
        assert_eq!(run(2.0, Some(500)).unwrap(), plain);
        assert_eq!(run(2.0, Some(1000)).unwrap(), guided);
        for bad in [0, 1001] {
            let e = run(2.0, Some(bad)).unwrap_err().to_string();
            assert!(
                e.contains("category_guidance_below")
                    && e.contains("[1, 1000]")
                    && e.contains(&bad.to_string()),
                "{e}"
            );
        }
    }

    #[test]
    fn previews_come_every_k_steps_and_the_last_one_is_the_result() {
        let model = tiny();
        let req = SampleRequest {
            seed: 3,
            batch: 1,
            category: None,
            preview_every: 250,
            ..Default::default()
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
            ..Default::default()
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

    fn tiny_field() -> crate::model::shape_prior::ShapeDecoder {
        let cfg = crate::model::shape_prior::ShapePriorConfig {
            latent: 8,
            decoder_hidden: 16,
            decoder_blocks: 1,
            encoder_hidden: 8,
            encoder_blocks: 1,
            pe_freqs: 2,
            code_every_block: false,
        };
        crate::model::shape_prior::ShapeDecoder::new(&cfg, &mut Rng::new(4), &crate::model::cpu())
    }

    fn cloud() -> Vec<[f32; 3]> {
        let mut rng = Rng::new(2);
        (0..32)
            .map(|_| {
                [
                    rng.range(-0.4, 0.4) as f32,
                    rng.range(-0.3, 0.3) as f32,
                    rng.range(0.0, 0.8) as f32,
                ]
            })
            .collect()
    }

    /// ℓ_pc of final (model-space = raw, unit scales) graphs.
    fn pc_of(field: &dyn SdfField, g: &GraphTensor, points: &[[f32; 3]]) -> f64 {
        let dev = crate::model::cpu();
        let (v, e) = super::super::to_tensors(std::slice::from_ref(g), &dev);
        let d = super::super::guidance::decode(
            v.reshape([K, NODE_DIM]),
            e.reshape([NUM_EDGES, EDGE_DIM]),
            field.latent(),
        );
        super::super::guidance::pc::loss(field, &d.parts, d.exist, points, 1000.0)
            .into_scalar::<f32>() as f64
    }

    /// Scales, schedule and guidance under which a random tiny model's guidance descends.
    fn guided_setup() -> (FeatureScales, Schedule, GuidanceOptions) {
        // Realistic raw sizes (boxes and centres ~0.2 m per unit of model space).
        let mut scales = FeatureScales::default();
        for c in 1..7 {
            scales.node[c] = 0.2;
        }
        // A random model is no denoiser: over NAP's 1000 steps its samples run off to |x| ~ 1e3.
        // A short schedule (ᾱ ≥ 0.6) keeps x̂₀ in a physical range, so guidance acts as on a
        // trained model.
        let schedule = Schedule::linear(40, 1e-3, 0.02);
        // Small weights: the raw DPS gradient of the paper's weights overshoots on a random
        // model (its x̂₀ is far from any object); here guidance must act as a descent.
        let guidance = GuidanceOptions {
            steps: 20,
            w_pc: 0.2,
            w_pen: 0.01,
            w_mob: 0.01,
            ..GuidanceOptions::paper(cloud(), super::super::guidance::Terms::ALL)
        };
        (scales, schedule, guidance)
    }

    #[test]
    fn guided_sampling_lowers_the_loss_reports_it_and_is_deterministic() {
        let model = tiny();
        let field = tiny_field();
        let (scales, schedule, guidance) = guided_setup();
        let ctx = GuidanceContext {
            field: &field,
            scales: &scales,
        };
        let points = guidance.points.clone();
        let req = SampleRequest {
            seed: 5,
            batch: 1,
            category: Some(0),
            guidance: Some(guidance),
            ..Default::default()
        };
        let dev = crate::model::cpu();
        let mut guided_ts = Vec::new();
        let mut first_last = Vec::new();
        let a = sample_guided(&model, &schedule, &req, Some(ctx), &dev, &mut |s| {
            if let Some(l) = s.guidance {
                guided_ts.push(s.t);
                assert!(l.total.is_finite() && l.grad_max.is_finite(), "{l:?}");
                first_last.push(l.pc);
            }
            ControlFlow::Continue(())
        })
        .unwrap();
        assert_eq!(guided_ts, (0..20).rev().collect::<Vec<_>>());
        let b = sample_guided(&model, &schedule, &req, Some(ctx), &dev, &mut |_| {
            ControlFlow::Continue(())
        })
        .unwrap();
        assert_eq!(a, b, "guided sampling must be deterministic per seed");
        let plain = sample(
            &model,
            &schedule,
            &SampleRequest {
                guidance: None,
                ..req.clone()
            },
            &dev,
            &mut |_| ControlFlow::Continue(()),
        )
        .unwrap();
        let (lg, lu) = (
            pc_of(&field, &a[0], &points),
            pc_of(&field, &plain[0], &points),
        );
        assert!(
            lg < lu,
            "guidance must lower ℓ_pc: guided {lg} vs unguided {lu}"
        );
        // Without a field the request is refused, naming the field.
        let e = sample(&model, &schedule, &req, &dev, &mut |_| {
            ControlFlow::Continue(())
        })
        .unwrap_err();
        assert!(e.to_string().contains("guidance"), "{e}");
    }

    #[test]
    fn refinement_descends_the_guidance_loss_after_the_last_step() {
        let model = tiny();
        let field = tiny_field();
        let (scales, schedule, base) = guided_setup();
        let ctx = GuidanceContext {
            field: &field,
            scales: &scales,
        };
        let run = |refine_steps: usize, events: &mut Vec<(usize, usize, usize, f64)>| {
            let req = SampleRequest {
                seed: 5,
                batch: 1,
                category: Some(0),
                guidance: Some(GuidanceOptions {
                    refine_steps,
                    ..base.clone()
                }),
                ..Default::default()
            };
            let dev = crate::model::cpu();
            sample_guided(&model, &schedule, &req, Some(ctx), &dev, &mut |s| {
                let total = s.guidance.map_or(f64::NAN, |l| l.total);
                events.push((s.step, s.total, s.t, total));
                ControlFlow::Continue(())
            })
            .unwrap()
        };
        let (mut plain_ev, mut refined_ev) = (Vec::new(), Vec::new());
        let plain = run(0, &mut plain_ev);
        let refined = run(10, &mut refined_ev);
        // The reverse steps are the same; ten more events follow, at t = 0, each guided.
        assert_eq!(refined_ev.len(), 50);
        assert!(refined_ev.iter().all(|e| e.1 == 50), "{refined_ev:?}");
        assert_eq!(
            refined_ev[..40]
                .iter()
                .map(|e| e.3.to_bits())
                .collect::<Vec<_>>(),
            plain_ev.iter().map(|e| e.3.to_bits()).collect::<Vec<_>>()
        );
        let tail = &refined_ev[40..];
        assert!(tail.iter().all(|e| e.2 == 0 && e.3.is_finite()), "{tail:?}");
        assert_eq!(
            tail.iter().map(|e| e.0).collect::<Vec<_>>(),
            (41..=50).collect::<Vec<_>>()
        );
        // Its first loss is the unrefined sample's; nine small steps later the loss is lower.
        let (first, last) = (tail[0].3, tail[9].3);
        assert!(last < first, "refinement must descend: {first} -> {last}");
        assert_ne!(plain, refined);
        assert_eq!(refined, run(10, &mut Vec::new()), "deterministic per seed");
    }

    #[test]
    fn physics_refinement_follows_with_pc_off_and_descends_pen_plus_mob() {
        let model = tiny();
        let field = tiny_field();
        let (scales, schedule, base) = guided_setup();
        let ctx = GuidanceContext {
            field: &field,
            scales: &scales,
        };
        // (step, total, ℓ_pc, w_pen ℓ_pen + w_mob ℓ_mob) of every event.
        let run = |g: GuidanceOptions, events: &mut Vec<(usize, usize, f64, f64)>| {
            let req = SampleRequest {
                seed: 5,
                batch: 1,
                category: Some(0),
                guidance: Some(g.clone()),
                ..Default::default()
            };
            let dev = crate::model::cpu();
            sample_guided(&model, &schedule, &req, Some(ctx), &dev, &mut |s| {
                let (pc, phys) = s.guidance.map_or((f64::NAN, f64::NAN), |l| {
                    (l.pc, g.w_pen * l.pen + g.w_mob * l.mob)
                });
                events.push((s.step, s.total, pc, phys));
                ControlFlow::Continue(())
            })
            .unwrap()
        };
        let g = GuidanceOptions {
            refine_steps: 2,
            refine_physics_steps: 8,
            ..base.clone()
        };
        let mut ev = Vec::new();
        let out = run(g.clone(), &mut ev);
        // 40 reverse steps, 2 refinement steps with ℓ_pc, then 8 without it.
        assert_eq!(step_events(40, 0, Some(&g)), 50);
        assert_eq!(ev.len(), 50);
        assert!(ev.iter().all(|e| e.1 == 50), "{ev:?}");
        assert!(ev[40..42].iter().all(|e| e.2 > 0.0), "{ev:?}");
        // Everything before them is the run without them.
        let mut before = Vec::new();
        let unmoved = run(
            GuidanceOptions {
                refine_physics_steps: 0,
                ..g.clone()
            },
            &mut before,
        );
        // They moved part boxes (half-extents, centres) and nothing else.
        use crate::graph::node_ch;
        let (a, b) = (&out[0], &unmoved[0]);
        assert_eq!(a.edges, b.edges, "joints must stay");
        let (mut moved, mut kept) = (0, 0);
        for (c, (x, y)) in a.nodes.iter().zip(&b.nodes).enumerate() {
            if (node_ch::BOX..node_ch::LATENT).contains(&(c % NODE_DIM)) {
                moved += usize::from(x != y);
            } else {
                assert_eq!(x.to_bits(), y.to_bits(), "node channel {}", c % NODE_DIM);
                kept += 1;
            }
        }
        assert!(moved > 0 && kept > 0);
        let bits = |e: &[(usize, usize, f64, f64)]| {
            e.iter()
                .map(|e| (e.0, e.2.to_bits(), e.3.to_bits()))
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&ev[..42]), bits(&before));
        let tail = &ev[42..];
        assert!(
            tail.iter().all(|e| e.2 == 0.0 && e.3.is_finite()),
            "{tail:?}"
        );
        let (first, last) = (tail[0].3, tail[7].3);
        assert!(
            first > 0.0,
            "the sample must overlap for this test to mean anything: {ev:?}"
        );
        assert!(
            last < first,
            "physics steps must descend: {first} -> {last}"
        );
        // Without ℓ_pen and ℓ_mob there is nothing to descend: no physics steps run.
        let pc_only = GuidanceOptions {
            w_pen: 0.0,
            w_mob: 0.0,
            ..g.clone()
        };
        assert_eq!(step_events(40, 0, Some(&pc_only)), 42);
        let mut pc_ev = Vec::new();
        run(pc_only, &mut pc_ev);
        assert_eq!(pc_ev.len(), 42);
        assert_eq!(
            out,
            run(g.clone(), &mut Vec::new()),
            "deterministic per seed"
        );
        // It returns the lowest-loss state the physics steps evaluated: event i's loss is that
        // of the state before its step, which event i − 1 previews.
        let req = SampleRequest {
            seed: 5,
            batch: 1,
            category: Some(0),
            guidance: Some(g.clone()),
            preview_every: 1,
            ..Default::default()
        };
        let mut seen: Vec<(f64, Vec<GraphTensor>)> = Vec::new();
        let dev = crate::model::cpu();
        let previewed = sample_guided(&model, &schedule, &req, Some(ctx), &dev, &mut |s| {
            let total = s.guidance.map_or(f64::NAN, |l| l.total);
            seen.push((total, s.x0_preview.clone().expect("a preview every step")));
            ControlFlow::Continue(())
        })
        .unwrap();
        assert_eq!(previewed, out);
        let mut best = 42;
        for i in 43..50 {
            if seen[i].0 < seen[best].0 {
                best = i;
            }
        }
        assert_eq!(
            out,
            seen[best - 1].1,
            "best at event {best}: {:?}",
            &seen[42..]
        );
    }

    #[test]
    fn a_diverging_guidance_is_reported_not_returned() {
        let model = tiny();
        let field = tiny_field();
        let scales = FeatureScales::default();
        let req = SampleRequest {
            seed: 1,
            batch: 1,
            guidance: Some(GuidanceOptions {
                w_pc: 1e6,
                steps: 10,
                max_step: None, // the paper's raw step: the runaway check applies
                ..GuidanceOptions::paper(cloud(), super::super::guidance::Terms::ALL)
            }),
            steps: 20,
            ..Default::default()
        };
        let e = sample_guided(
            &model,
            &Schedule::default(),
            &req,
            Some(GuidanceContext {
                field: &field,
                scales: &scales,
            }),
            &crate::model::cpu(),
            &mut |_| ControlFlow::Continue(()),
        )
        .unwrap_err();
        assert!(matches!(e, EngineError::Diverged { .. }), "{e}");
    }

    #[test]
    fn strided_and_ddim_sampling_take_the_requested_steps() {
        let model = tiny();
        let dev = crate::model::cpu();
        for sampler in [Sampler::Ddpm, Sampler::Ddim { eta: 0.0 }] {
            let req = SampleRequest {
                seed: 9,
                batch: 1,
                sampler,
                steps: 25,
                preview_every: 25,
                ..Default::default()
            };
            let mut ts = Vec::new();
            let mut last = None;
            let out = sample(&model, &Schedule::default(), &req, &dev, &mut |s| {
                ts.push(s.t);
                if let Some(p) = &s.x0_preview {
                    last = Some(p[0].clone());
                }
                ControlFlow::Continue(())
            })
            .unwrap();
            assert_eq!(ts.len(), 25);
            assert_eq!((ts[0], ts[24]), (999, 0));
            assert!(out[0].flatten().iter().all(|v| v.is_finite()));
            // The last jump lands on x̂₀.
            let last = last.unwrap().flatten();
            for (a, b) in last.iter().zip(out[0].flatten()) {
                assert!((a - b).abs() < 1e-3 * (1.0 + b.abs()), "{a} vs {b}");
            }
        }
        let e = sample(
            &model,
            &Schedule::default(),
            &SampleRequest {
                batch: 1,
                sampler: Sampler::Ddim { eta: 2.0 },
                ..Default::default()
            },
            &dev,
            &mut |_| ControlFlow::Continue(()),
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("sampler.eta") && e.to_string().contains('2'),
            "{e}"
        );
    }
}
