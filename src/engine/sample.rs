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

use burn::tensor::{Device, Tensor, TensorData};

use super::guidance::{FreeSamples, GuidanceLosses, GuidanceOptions, SdfField, guidance_loss};
use super::predict::{Predictor, tensor};
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
/// ε̂ comes from the host denoiser with its forward recorded, ∇ℓ(x̂₀ ⊙ scales) is taken at x̂₀
/// through the SDF field (burn autodiff), pushed to x_t through x̂₀ = (x_t − n ε̂(x_t)) / s and
/// the denoiser's input gradient ([`Predictor::backward`]), and −∇ℓ is added after the usual
/// update. No weight gradients are computed. The mobility states are drawn from
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
        return Err(EngineError::Invalid(crate::error::Invalid {
            field: "batch".into(),
            limit: "at least 1".into(),
            value: "0".into(),
        }));
    }
    let eta = match req.sampler {
        Sampler::Ddpm => 1.0,
        Sampler::Ddim { eta } => {
            if !(eta.is_finite() && (0.0..=1.0).contains(&eta)) {
                return Err(EngineError::Invalid(crate::error::Invalid {
                    field: "sampler.eta".into(),
                    limit: "in [0, 1]".into(),
                    value: eta.to_string(),
                }));
            }
            eta
        }
    };
    if !(req.category_guidance.is_finite()
        && (0.0..=MAX_CATEGORY_GUIDANCE).contains(&req.category_guidance))
    {
        return Err(EngineError::Invalid(crate::error::Invalid {
            field: "category_guidance".into(),
            limit: format!("in [0, {MAX_CATEGORY_GUIDANCE}]"),
            value: req.category_guidance.to_string(),
        }));
    }
    if let Some(below) = req.category_guidance_below
        && !(1..=schedule.len()).contains(&below)
    {
        return Err(EngineError::Invalid(crate::error::Invalid {
            field: "category_guidance_below".into(),
            limit: format!("in [1, {}]", schedule.len()),
            value: below.to_string(),
        }));
    }
    if req.steps > schedule.len() {
        return Err(EngineError::Invalid(crate::error::Invalid {
            field: "steps".into(),
            limit: format!("at most {} (0: all)", schedule.len()),
            value: req.steps.to_string(),
        }));
    }
    let guidance = match (&req.guidance, guide) {
        (Some(g), Some(ctx)) if g.is_active() => {
            g.validate(schedule.len())?;
            if ctx.field.latent() + crate::graph::node_ch::LATENT > NODE_DIM {
                return Err(EngineError::Invalid(crate::error::Invalid {
                    field: "guidance.decoder".into(),
                    limit: format!(
                        "latent width ≤ {}",
                        NODE_DIM - crate::graph::node_ch::LATENT
                    ),
                    value: ctx.field.latent().to_string(),
                }));
            }
            ctx.scales.validate().map_err(|e| {
                EngineError::Invalid(crate::error::Invalid {
                    field: "guidance.scales".into(),
                    limit: "valid feature scales".into(),
                    value: e.to_string(),
                })
            })?;
            Some((g, ctx))
        }
        (Some(g), None) if g.is_active() => {
            return Err(EngineError::Invalid(crate::error::Invalid {
                field: "guidance".into(),
                limit: "a shape decoder (call sample_guided / generate_with)".into(),
                value: "none given".into(),
            }));
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
    // The denoiser on the host path; classifier-free guidance batches the conditional and the
    // "no category" halves into one forward.
    let mut predictor = Predictor::new(
        model,
        b,
        req.category,
        req.category_guidance,
        req.category_guidance_below.unwrap_or(usize::MAX),
    );
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
    // ℓ_free's samples depend only on the points and cameras: once per run.
    let free = guidance
        .map(|(g, _)| FreeSamples::of(g))
        .unwrap_or_default();
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
            let (ev, ee) = predictor.eps(&v, &e, t, true);
            let (sv, se) = scale_tensors.clone().expect("scales with guidance");
            // ℓ's gradient at x̂₀ (raw units, a leaf), then the chain rule through
            // x̂₀ = (x − n ε̂(x)) / s ⊙ scales on the host denoiser.
            let x0v = ((v.clone() - ev.clone() * n) / s * sv.clone())
                .autodiff()
                .require_grad();
            let x0e = ((e.clone() - ee.clone() * n) / s * se.clone())
                .autodiff()
                .require_grad();
            let mut mob_rng = Rng::fork(req.seed ^ MOB_STREAM, k as u64);
            let (grad, values) = guidance_gradient(
                ctx.field,
                g,
                &free,
                (&x0v, &x0e),
                (x0v.clone(), x0e.clone()),
                &mut mob_rng,
            );
            let grad =
                grad.map(|gx| through_denoiser(&mut predictor, gx, (&sv, &se), (s, n), (&v, &e)));
            let values = checked(&grad, g, values, (k + 1, t))?;
            losses = Some(values);
            (ev, ee, grad)
        } else {
            let (ev, ee) = predictor.eps(&v, &e, t, false);
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
            let (grad, values) =
                guidance_gradient(ctx.field, g, &free, (&va, &ea), (x0v, x0e), &mut mob_rng);
            let values = checked(&grad, g, values, (step, 0))?;
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
/// was computed from `wrt` on the autodiff device.
fn guidance_gradient(
    field: &dyn SdfField,
    g: &GuidanceOptions,
    free: &FreeSamples,
    wrt: (&Tensor<3>, &Tensor<3>),
    x0: (Tensor<3>, Tensor<3>),
    mob_rng: &mut Rng,
) -> (Option<Gradient>, GuidanceLosses) {
    let (loss, values) = guidance_loss(field, g, free, x0.0, x0.1, mob_rng);
    let grad = loss.filter(|_| values.total.is_finite()).map(|loss| {
        let grads = loss.backward();
        let gv = wrt.0.grad(&grads).map(|g| g.inner());
        let ge = wrt.1.grad(&grads).map(|g| g.inner());
        (gv, ge)
    });
    (grad, values)
}

/// The gradient of ℓ with respect to the state x_t from its gradient `gx` at x̂₀ = (x − n ε̂(x))
/// / s ⊙ scales: the direct term gx ⊙ scales / s, and −n times it pushed back through the
/// denoiser's last recorded forward.
fn through_denoiser(
    predictor: &mut Predictor,
    (gv, ge): Gradient,
    (sv, se): (&Tensor<3>, &Tensor<3>),
    (s, n): (f32, f32),
    (v, e): (&Tensor<3>, &Tensor<3>),
) -> Gradient {
    let direct = |g: Option<Tensor<3>>, scale: &Tensor<3>, like: &Tensor<3>| match g {
        Some(g) => g * scale.clone() / s,
        None => like.zeros_like(),
    };
    let (dv, de) = (direct(gv, sv, v), direct(ge, se, e));
    let flat = |x: &Tensor<3>| -> Vec<f32> {
        let up = x.clone() * -n;
        up.into_data().try_to_vec::<f32>().expect("f32 gradient")
    };
    let (jv, je) = predictor.backward(&flat(&dv), &flat(&de));
    let device = v.device();
    (
        Some(dv + tensor(jv, v.dims(), &device)),
        Some(de + tensor(je, e.dims(), &device)),
    )
}

/// `values` with the gradient's largest entry, or diverged on a non-finite loss, or on a
/// non-finite gradient (or, without a clamp, one beyond [`DIVERGENCE_LIMIT`]).
fn checked(
    grad: &Option<Gradient>,
    g: &GuidanceOptions,
    mut values: GuidanceLosses,
    (step, t): (usize, usize),
) -> Result<GuidanceLosses, EngineError> {
    if !values.total.is_finite() {
        return Err(EngineError::Diverged {
            step,
            t,
            what: "guidance loss",
        });
    }
    let mut gmax = 0.0f32;
    if let Some((gv, ge)) = grad {
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
    Ok(values)
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
mod tests;
