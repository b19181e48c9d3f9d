//! PhysNAP's loss guidance (method.md §8.2–§8.7): the losses on the decoded x̂₀ and their
//! weighted sum, as burn tensor code differentiable back to x_t.
//!
//! ```text
//! ℓ(x̂₀) = w_pc ℓ_pc + w_pen ℓ_pen + w_mob ℓ_mob (+ w_free ℓ_free with a camera)
//! paper:   w_pc,base = 45, w_pen,base = 2, w_mob,base = 2, each ÷ #active terms;
//!          guided steps n_g = 500 (the last ones, t < n_g); τ = 1000
//! physnap: the same, with w_pen and w_mob × 3 ([`DEFAULT_LOSS_SCALES`]) and every gradient
//!          entry clamped to ±0.02 ([`DEFAULT_MAX_STEP`]) — two measured deviations
//! decoding (§8.3, §9 A8): raw = x̂₀ ⊙ feature scales; õ, c̃ clamped to [0, 1] where used;
//!                   b ← max(|b|, 1e-4); Plücker lines projected in ℓ_mob
//! ```
//!
//! Why it exists: the sampler ([`super::sample`]) only needs "loss and its value per term of a
//! batch of x̂₀"; the terms live in one module each ([`pc`], [`pen`], [`mob`]) on the shared
//! part SDF ([`field`]) and grid ([`grid`]). Inputs are validated here ([`GuidanceOptions::
//! validate`]) so bad requests fail before any sampling.

pub mod field;
pub mod free;
pub mod grid;
pub mod mob;
pub mod pc;
pub mod pen;

use burn::tensor::Tensor;

use super::EngineError;
use crate::data::rng::Rng;
use crate::graph::{EDGE_DIM, K, NODE_DIM, NUM_EDGES, edge_ch, node_ch};
pub use field::{BoxField, PartTensors, SdfField};

/// Smallest half-extent used by the losses (§9 A8).
pub const MIN_HALF_EXTENT: f32 = 1e-4;
/// Paper base weight of ℓ_pc.
pub const W_PC_BASE: f64 = 45.0;
/// Paper base weight of ℓ_pen.
pub const W_PEN_BASE: f64 = 2.0;
/// Paper base weight of ℓ_mob.
pub const W_MOB_BASE: f64 = 2.0;
/// physnap's default weight of ℓ_free when the request has a camera (real-scans.md §5; not in
/// the paper): ℓ_pc's default weight with all three paper terms on (45 ÷ 3), so a free-space
/// sample inside a part costs what an observed point off the surface does.
pub const DEFAULT_W_FREE: f64 = W_PC_BASE / 3.0;
/// Paper n_g.
pub const DEFAULT_GUIDED_STEPS: usize = 500;
/// Paper τ.
pub const DEFAULT_TAU: f64 = 1000.0;
/// Default clamp of each guidance-gradient entry (model space). The paper subtracts the raw
/// gradient (§9 A11); with our CPU-trained weights that gradient exceeds 10⁴ at the first
/// guided step on every test scan (EVALUATION.md), so physnap clamps by default and keeps the
/// raw rule one setting away (`max_step: None`; `guidance_max_step = 0` at the API / CLI).
/// 0.05 was stable on 300 of 300 evaluation samples; 0.5 let ℓ_pc push parts into each other.
/// Since the eikonal decoder (2026-11-27) 0.02, together with [`DEFAULT_LOSS_SCALES`]: on 30
/// test scans × 2 in both blocks it fits the scans closer than 0.05 at no more mesh overlap
/// (EVALUATION.md, "Guidance defaults for the eikonal decoder").
pub const DEFAULT_MAX_STEP: f64 = 0.02;
/// physnap's default multipliers of the paper's weights of ℓ_pc, ℓ_pen and ℓ_mob (a deviation;
/// [`GuidanceOptions::paper`] keeps the paper's). The tighter clamp caps the physics terms'
/// gradient entries as much as ℓ_pc's, so alone it trades overlap for alignment; ℓ_pen and
/// ℓ_mob at 3× the paper's weight buy the overlap back (EVALUATION.md).
pub const DEFAULT_LOSS_SCALES: [f64; 3] = [1.0, 3.0, 3.0];
/// Refinement steps the CLI and the service run by default (EVALUATION.md, "Refinement" and
/// "Thirty refinement steps"). 30 since 2026-11-28: against 10, on 30 fresh scans × 2 × 2 seed
/// sets in both blocks, E_pc fell in 239 of 240 samples and D_pc in 182 of 240 (means 0.96×,
/// 0.95×), E_pen and E_mob means fell to 0.62–0.73×, and O_mesh and ID_gt stayed level; a
/// step costs ≈ 0.06–0.2 s (BENCHMARKS.md, "Guided sampling").
pub const DEFAULT_REFINE_STEPS: usize = 30;
/// Physics-only refinement steps the CLI and the service run by default after the refinement
/// steps ([`GuidanceOptions::refine_physics_steps`]; 0: none). They trade scan alignment for
/// fewer overlaps (EVALUATION.md, "Physics-only refinement"), so they are opt-in.
pub const DEFAULT_REFINE_PHYSICS_STEPS: usize = 0;
/// Most refinement steps accepted (each of `refine_steps` and `refine_physics_steps`).
pub const MAX_REFINE_STEPS: usize = 1000;
/// Refinement clamps at this fraction of `max_step`. Steps of the full clamp bounce on ℓ_pc's
/// landscape (no denoiser pulls the sample back); a tenth descends smoothly (EVALUATION.md).
pub const REFINE_STEP_FRACTION: f64 = 0.1;
/// Most observed points accepted.
pub const MAX_POINTS: usize = 100_000;
/// Largest accepted weight (beyond this a step is a jump, not guidance).
pub const MAX_WEIGHT: f64 = 1e6;
/// Largest accepted |coordinate| of an observed point (metres).
pub const MAX_COORD: f32 = 1e3;

/// Which loss terms are on (for the paper's weight rule).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Terms {
    /// ℓ_pc.
    pub pc: bool,
    /// ℓ_pen.
    pub pen: bool,
    /// ℓ_mob.
    pub mob: bool,
}

impl Terms {
    /// All three.
    pub const ALL: Terms = Terms {
        pc: true,
        pen: true,
        mob: true,
    };
}

/// Guidance settings of one job.
#[derive(Debug, Clone, PartialEq)]
pub struct GuidanceOptions {
    /// Observed partial point cloud (object frame, metres); needed when `w_pc > 0`.
    pub points: Vec<[f32; 3]>,
    /// Weight of ℓ_pc.
    pub w_pc: f64,
    /// Weight of ℓ_pen.
    pub w_pen: f64,
    /// Weight of ℓ_mob.
    pub w_mob: f64,
    /// Sensor positions (object frame, metres) the scan was seen from; empty: unknown. With
    /// `w_free > 0` they give ℓ_free (real-scans.md §5).
    pub cameras: Vec<[f32; 3]>,
    /// Weight of ℓ_free (0 without cameras).
    pub w_free: f64,
    /// n_g: guide the last this many steps (t < n_g).
    pub steps: usize,
    /// τ of the soft assignment in ℓ_pc.
    pub tau: f64,
    /// Clamp every entry of ∇_{x_t} ℓ to ±this (model space) before subtracting it. A
    /// deviation from the paper (which subtracts the raw gradient, §9 A11), on by default
    /// ([`DEFAULT_MAX_STEP`]); None is the paper's raw step. With a clamp, the runaway-gradient
    /// check only rejects non-finite gradients.
    pub max_step: Option<f64>,
    /// Refinement steps after the last reverse step (physnap, not in the paper): x₀ ← x₀ −
    /// clamp(∇_{x₀} ℓ(x₀), ±max_step · [`REFINE_STEP_FRACTION`]) this many times, on the sample
    /// itself (no denoiser, no noise). 0: off (the paper).
    pub refine_steps: usize,
    /// Physics-only refinement (physnap, not in the paper): after the `refine_steps`, this many
    /// more of the same clamped steps on w_pen ℓ_pen + w_mob ℓ_mob alone (ℓ_pc off), moving
    /// only the parts' boxes (half-extents and centres; existence, shape codes and joints stay).
    /// Under ℓ_pc a contact settles where ℓ_pc's pull into a neighbour balances ℓ_pen's
    /// quadratic push out, a small overlap that stays; without ℓ_pc it is pushed out, at a cost
    /// in scan alignment. Of the states these steps evaluate (the first is the refined sample),
    /// the one with the lowest loss is returned: ℓ_mob is noisy and ℓ_pen jumps where boxes
    /// start to intersect. No steps run (and none are reported) when w_pen and w_mob are both
    /// 0. 0: off.
    pub refine_physics_steps: usize,
}

impl Default for GuidanceOptions {
    /// physnap's default pc+pen+mob guidance ([`GuidanceOptions::defaults`]), with no points
    /// (set them).
    fn default() -> Self {
        GuidanceOptions::defaults(Vec::new(), Terms::ALL)
    }
}

impl GuidanceOptions {
    /// The paper's settings for `terms`: base weights ÷ number of active terms, n_g, τ — with
    /// physnap's default gradient clamp ([`DEFAULT_MAX_STEP`]).
    pub fn paper(points: Vec<[f32; 3]>, terms: Terms) -> Self {
        let n = [terms.pc, terms.pen, terms.mob]
            .iter()
            .filter(|t| **t)
            .count()
            .max(1) as f64;
        let on = |t: bool, w: f64| if t { w / n } else { 0.0 };
        GuidanceOptions {
            points,
            w_pc: on(terms.pc, W_PC_BASE),
            w_pen: on(terms.pen, W_PEN_BASE),
            w_mob: on(terms.mob, W_MOB_BASE),
            cameras: Vec::new(),
            w_free: 0.0,
            steps: DEFAULT_GUIDED_STEPS,
            tau: DEFAULT_TAU,
            max_step: Some(DEFAULT_MAX_STEP),
            refine_steps: 0,
            refine_physics_steps: 0,
        }
    }

    /// physnap's defaults for `terms`, what the CLI and the service run when a weight is not
    /// given: the paper's weights times [`DEFAULT_LOSS_SCALES`], with the default clamp.
    pub fn defaults(points: Vec<[f32; 3]>, terms: Terms) -> Self {
        GuidanceOptions::paper(points, terms).with_loss_scales(DEFAULT_LOSS_SCALES)
    }

    /// The weights (w_pc, w_pen, w_mob) a request runs with, the one rule of `physnap generate`
    /// and the service: a given weight as given; an unset one physnap's default for the active
    /// terms, where a term is active unless its weight is given as ≤ 0 (ℓ_pc also needs
    /// points: `has_points`).
    pub fn weights_or_defaults(given: [Option<f64>; 3], has_points: bool) -> [f64; 3] {
        let on = |w: Option<f64>| w.is_none_or(|w| w > 0.0);
        let [pc, pen, mob] = given;
        let terms = Terms {
            pc: has_points && on(pc),
            pen: on(pen),
            mob: on(mob),
        };
        let d = GuidanceOptions::defaults(Vec::new(), terms);
        [
            pc.unwrap_or(d.w_pc),
            pen.unwrap_or(d.w_pen),
            mob.unwrap_or(d.w_mob),
        ]
    }

    /// The same guidance seen from `cameras`, with ℓ_free at `w_free` (None: [`DEFAULT_W_FREE`]
    /// when there is a camera, 0 without).
    pub fn with_cameras(self, cameras: Vec<[f32; 3]>, w_free: Option<f64>) -> Self {
        let w_free = match (cameras.is_empty(), w_free) {
            (true, _) => 0.0,
            (false, Some(w)) => w,
            (false, None) => DEFAULT_W_FREE,
        };
        GuidanceOptions {
            cameras,
            w_free,
            ..self
        }
    }

    /// The same guidance with w_pc, w_pen and w_mob multiplied by `scales` (in that order).
    pub fn with_loss_scales(self, scales: [f64; 3]) -> Self {
        let [pc, pen, mob] = scales;
        GuidanceOptions {
            w_pc: self.w_pc * pc,
            w_pen: self.w_pen * pen,
            w_mob: self.w_mob * mob,
            ..self
        }
    }

    /// Check every field against its limit; `total_steps` is the sampler's T.
    pub fn validate(&self, total_steps: usize) -> Result<(), EngineError> {
        let bad = |field: &str, limit: String, value: String| {
            Err(EngineError::Invalid(crate::error::Invalid {
                field: format!("guidance.{field}"),
                limit,
                value,
            }))
        };
        for (name, w) in [
            ("w_pc", self.w_pc),
            ("w_pen", self.w_pen),
            ("w_mob", self.w_mob),
            ("w_free", self.w_free),
        ] {
            if !(w.is_finite() && (0.0..=MAX_WEIGHT).contains(&w)) {
                return bad(name, format!("finite, in [0, {MAX_WEIGHT}]"), w.to_string());
            }
        }
        if !(self.tau.is_finite() && self.tau > 0.0 && self.tau <= 1e9) {
            return bad("tau", "finite, in (0, 1e9]".into(), self.tau.to_string());
        }
        if let Some(c) = self.max_step
            && !(c.is_finite() && c > 0.0)
        {
            return bad("max_step", "finite and > 0".into(), c.to_string());
        }
        if self.steps > total_steps {
            return bad(
                "steps",
                format!("at most the {total_steps} sampler steps"),
                self.steps.to_string(),
            );
        }
        if self.refine_steps > MAX_REFINE_STEPS {
            return bad(
                "refine_steps",
                format!("at most {MAX_REFINE_STEPS}"),
                self.refine_steps.to_string(),
            );
        }
        if self.refine_physics_steps > MAX_REFINE_STEPS {
            return bad(
                "refine_physics_steps",
                format!("at most {MAX_REFINE_STEPS}"),
                self.refine_physics_steps.to_string(),
            );
        }
        if self.w_pc > 0.0 && self.points.is_empty() {
            return bad(
                "points",
                "at least 1 point when w_pc > 0".into(),
                "0 points".into(),
            );
        }
        if self.points.len() > MAX_POINTS {
            return bad(
                "points",
                format!("at most {MAX_POINTS} points"),
                format!("{} points", self.points.len()),
            );
        }
        if let Some((j, p)) = self
            .points
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|v| !(v.is_finite() && v.abs() <= MAX_COORD)))
        {
            return bad(
                &format!("points[{j}]"),
                format!("finite, |coordinate| ≤ {MAX_COORD}"),
                format!("{p:?}"),
            );
        }
        self.validate_cameras()
    }

    /// The cameras: at most [`free_space::MAX_CAMERAS`], finite, |coordinate| ≤ [`MAX_COORD`],
    /// with points to look at, each outside the points' box (a sensor does not sit inside what
    /// it scans; a camera there is almost always a frame mistake).
    fn validate_cameras(&self) -> Result<(), EngineError> {
        let bad = |field: String, limit: String, value: String| {
            Err(EngineError::Invalid(crate::error::Invalid {
                field: format!("guidance.{field}"),
                limit,
                value,
            }))
        };
        use super::free_space::MAX_CAMERAS;
        if self.cameras.len() > MAX_CAMERAS {
            return bad(
                "cameras".into(),
                format!("at most {MAX_CAMERAS} cameras"),
                format!("{} cameras", self.cameras.len()),
            );
        }
        if !self.cameras.is_empty() && self.points.is_empty() {
            return bad(
                "cameras".into(),
                "cameras only with observed points".into(),
                format!("{} cameras, 0 points", self.cameras.len()),
            );
        }
        let (lo, hi) = super::free_space::bounds(&self.points);
        for (j, c) in self.cameras.iter().enumerate() {
            if c.iter().any(|v| !(v.is_finite() && v.abs() <= MAX_COORD)) {
                return bad(
                    format!("cameras[{j}]"),
                    format!("finite, |coordinate| ≤ {MAX_COORD}"),
                    format!("{c:?}"),
                );
            }
            if (0..3).all(|k| c[k] >= lo[k] && c[k] <= hi[k]) {
                return bad(
                    format!("cameras[{j}]"),
                    format!(
                        "outside the points' box [{:.3}, {:.3}] × [{:.3}, {:.3}] × [{:.3}, {:.3}] (object frame, metres)",
                        lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]
                    ),
                    format!("{c:?}"),
                );
            }
        }
        Ok(())
    }

    /// The clamp of a refinement step (None: raw gradient, as `max_step`).
    pub fn refine_max_step(&self) -> Option<f64> {
        self.max_step.map(|c| c * REFINE_STEP_FRACTION)
    }

    /// The physics-only refinement steps that run: `refine_physics_steps`, or 0 when neither
    /// ℓ_pen nor ℓ_mob is on.
    pub fn physics_steps_run(&self) -> usize {
        if self.w_pen > 0.0 || self.w_mob > 0.0 {
            self.refine_physics_steps
        } else {
            0
        }
    }

    /// The same guidance with ℓ_pc off: what a physics-only refinement step descends.
    pub fn physics_only(&self) -> GuidanceOptions {
        GuidanceOptions {
            w_pc: 0.0,
            points: Vec::new(),
            cameras: Vec::new(),
            w_free: 0.0,
            ..self.clone()
        }
    }

    /// Whether any term has a positive weight.
    pub fn is_active(&self) -> bool {
        weights_active(self.w_pc, self.w_pen, self.w_mob) || self.free_active()
    }

    /// Whether ℓ_free is on (a camera and a positive weight).
    pub fn free_active(&self) -> bool {
        self.w_free > 0.0 && !self.cameras.is_empty() && !self.points.is_empty()
    }
}

/// Whether loss weights guide a sample (some weight > 0); false = plain NAP sampling. The one
/// rule behind [`GuidanceOptions::is_active`], the service's validation and the evaluations'
/// per-row defaults.
pub fn weights_active(w_pc: f64, w_pen: f64, w_mob: f64) -> bool {
    w_pc > 0.0 || w_pen > 0.0 || w_mob > 0.0
}

/// Loss values of one guided step, summed over the batch (unweighted terms).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GuidanceLosses {
    /// ℓ_pc.
    pub pc: f64,
    /// ℓ_pen.
    pub pen: f64,
    /// ℓ_mob.
    pub mob: f64,
    /// ℓ_free (0 without a camera).
    pub free: f64,
    /// w_pc ℓ_pc + w_pen ℓ_pen + w_mob ℓ_mob + w_free ℓ_free.
    pub total: f64,
    /// max |∇_{x_t} ℓ| subtracted this step (model space).
    pub grad_max: f64,
}

/// Host copies of the decoded part boxes, used to plan grids and skip pairs.
#[derive(Debug, Clone, PartialEq)]
pub struct HostParts {
    /// õ clamped to [0, 1].
    pub exist: Vec<f32>,
    /// max(|b|, 1e-4).
    pub boxes: Vec<[f32; 3]>,
    /// t.
    pub centres: Vec<[f32; 3]>,
}

/// One decoded graph: tensors for the losses and host values for planning.
#[derive(Debug, Clone)]
pub struct Decoded {
    /// Boxes, centres, codes.
    pub parts: PartTensors,
    /// Raw existences õ [K] (clamped where used).
    pub exist: Tensor<1>,
    /// Raw edges [28, 13].
    pub edges: Tensor<2>,
    /// Host copies.
    pub host: HostParts,
    /// Edge classes c̃ (raw) per row.
    pub classes: Vec<[f32; 3]>,
}

fn host_rows<const N: usize>(t: Tensor<2>) -> Vec<[f32; N]> {
    let v: Vec<f32> = t.into_data().try_to_vec::<f32>().unwrap_or_default();
    v.chunks(N).map(|c| std::array::from_fn(|k| c[k])).collect()
}

/// Decode one raw (unscaled) graph: `nodes` [K, 135], `edges` [28, 13].
pub fn decode(nodes: Tensor<2>, edges: Tensor<2>, latent: usize) -> Decoded {
    let exist = nodes.clone().narrow(1, node_ch::EXIST, 1).reshape([K]);
    let parts = PartTensors::new(
        nodes.clone().narrow(1, node_ch::BOX, 3),
        nodes.clone().narrow(1, node_ch::CENTER, 3),
        nodes.narrow(1, node_ch::LATENT, latent),
    );
    let exist_host: Vec<f32> = exist
        .clone()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap_or_default()
        .into_iter()
        .map(|o| if o.is_nan() { 0.0 } else { o.clamp(0.0, 1.0) })
        .collect();
    let host = HostParts {
        exist: exist_host,
        boxes: host_rows::<3>(parts.boxes.clone()),
        centres: host_rows::<3>(parts.centres.clone()),
    };
    let classes = host_rows::<3>(edges.clone().narrow(1, edge_ch::CLASS, 3));
    Decoded {
        parts,
        exist,
        edges,
        host,
        classes,
    }
}

/// The free-space samples ℓ_free evaluates and its margin δ = ½ m. They depend only on the
/// points and cameras, so a sampler computes them once ([`FreeSamples::of`]) and hands them to
/// every [`guidance_loss`] call.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FreeSamples {
    /// The q_k of `engine::free_space`.
    pub samples: Vec<[f32; 3]>,
    /// δ (metres).
    pub delta: f32,
}

impl FreeSamples {
    /// The samples of `opts` (none when ℓ_free is off).
    pub fn of(opts: &GuidanceOptions) -> FreeSamples {
        if !opts.free_active() {
            return FreeSamples::default();
        }
        let free = super::free_space::FreeSpace::new(&opts.points, &opts.cameras);
        FreeSamples {
            samples: free.samples(),
            delta: 0.5 * free.margin(),
        }
    }
}

/// ℓ of a batch of raw x̂₀ (`nodes` [B, K, 135], `edges` [B, 28, 13]) and the unweighted term
/// values; the tensor is None when no term has anything to penalise (zero loss, zero gradient).
/// `free` is [`FreeSamples::of`] `opts` (used only while ℓ_free is on); `rng` draws the
/// mobility states.
pub fn guidance_loss(
    field: &dyn SdfField,
    opts: &GuidanceOptions,
    free: &FreeSamples,
    nodes: Tensor<3>,
    edges: Tensor<3>,
    rng: &mut Rng,
) -> (Option<Tensor<1>>, GuidanceLosses) {
    let b = nodes.dims()[0];
    let latent = field.latent();
    let mut total: Option<Tensor<1>> = None;
    let mut values = GuidanceLosses::default();
    let add = |t: Tensor<1>, w: f64, slot: &mut f64, total: &mut Option<Tensor<1>>| {
        let v = t.clone().into_scalar::<f32>() as f64;
        *slot += v;
        let t = t * w as f32;
        *total = Some(match total.take() {
            Some(s) => s + t,
            None => t,
        });
    };
    for s in 0..b {
        let n = nodes.clone().narrow(0, s, 1).reshape([K, NODE_DIM]);
        let e = edges.clone().narrow(0, s, 1).reshape([NUM_EDGES, EDGE_DIM]);
        let d = decode(n, e, latent);
        if opts.w_pc > 0.0 {
            let l = pc::loss(
                field,
                &d.parts,
                d.exist.clone(),
                &opts.points,
                opts.tau as f32,
            );
            add(l, opts.w_pc, &mut values.pc, &mut total);
        }
        if opts.w_pen > 0.0
            && let Some(l) = pen::loss(field, &d.parts, d.exist.clone(), &d.host)
        {
            add(l, opts.w_pen, &mut values.pen, &mut total);
        }
        if opts.w_mob > 0.0 {
            let items = mob::loss_items(&d.classes, rng);
            let w = mob::loss_weights(d.edges.clone(), &items);
            if let Some(l) = mob::sweep(field, &d.parts, d.edges.clone(), &items, w) {
                add(l, opts.w_mob, &mut values.mob, &mut total);
            }
        }
        if opts.free_active()
            && let Some(l) = free::loss(
                field,
                &d.parts,
                d.exist.clone(),
                &d.host,
                &free.samples,
                opts.points.len(),
                free.delta,
            )
        {
            add(l, opts.w_free, &mut values.free, &mut total);
        }
    }
    values.total = opts.w_pc * values.pc
        + opts.w_pen * values.pen
        + opts.w_mob * values.mob
        + opts.w_free * values.free;
    (total, values)
}

#[cfg(test)]
mod tests;
