//! The field rules of a job request, and [`validate`], which applies them all.
//!
//! Why it exists: a client that sends five bad fields should learn of all five in one answer,
//! not one per round trip. Each rule here checks one field (or one field against another it
//! depends on) and returns its value or a [`Violation`]; `validate` runs every rule whose
//! inputs are valid, collects every violation ([`Violations`]), and builds the [`JobSpec`] only
//! when there are none. Rules that need the whole request run last, once the fields are valid
//! on their own: the frame estimate (points, up and cameras) and the engine's check of the
//! guidance the job will run with (the cameras' count, range and place outside the box).

use super::*;

/// Every rule a request broke, in field order; never empty.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Violations(Vec<Violation>);

impl Violations {
    /// The violations given, or `None` when there are none.
    pub fn new(list: Vec<Violation>) -> Option<Self> {
        (!list.is_empty()).then_some(Violations(list))
    }

    /// The violations, in field order.
    pub fn iter(&self) -> std::slice::Iter<'_, Violation> {
        self.0.iter()
    }

    /// The first violation (the one a transport with room for one reports).
    pub fn first(&self) -> &Violation {
        &self.0[0]
    }

    /// How many rules were broken (≥ 1).
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// Always false: a `Violations` holds at least one.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

impl From<Violation> for Violations {
    fn from(v: Violation) -> Self {
        Violations(vec![v])
    }
}

impl std::fmt::Display for Violations {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let all: Vec<String> = self.0.iter().map(Violation::to_string).collect();
        f.write_str(&all.join("; "))
    }
}

impl std::error::Error for Violations {}

/// The field a violation is about, for telling whether it was refused already: the name
/// before any index (`camera[1]` → `camera`), every points field as `points`.
fn subject(field: &str) -> &str {
    let top = field.split(['[', '.']).next().unwrap_or(field);
    if top.starts_with("points") {
        "points"
    } else {
        top
    }
}

/// The violations found so far, starting with what the transport refused
/// ([`JobInput::refused`]).
struct Found {
    list: Vec<Violation>,
    /// The subjects the transport refused (and took out of the input).
    refused: Vec<String>,
}

impl Found {
    fn new(refused: &[Violation]) -> Self {
        Found {
            list: refused.to_vec(),
            refused: refused
                .iter()
                .map(|v| subject(&v.field).to_string())
                .collect(),
        }
    }

    /// The value of a rule that held; `None`, with the violation kept, for one that did not.
    /// A violation about a field the transport refused is not kept: that field was taken out
    /// of the input, so the rule saw it missing.
    fn take<T>(&mut self, r: Result<T, Violation>) -> Option<T> {
        r.map_err(|v| {
            if !self.refused.iter().any(|s| s == subject(&v.field)) {
                self.list.push(v);
            }
        })
        .ok()
    }

    /// `Err` with everything found, or `Ok` when nothing was.
    fn result(self) -> Result<(), Violations> {
        if self.list.is_empty() {
            Ok(())
        } else {
            Err(Violations(self.list))
        }
    }
}

/// Validate a request into a [`JobSpec`], listing every rule it breaks. `random_seed` is used
/// only when no seed was given.
pub fn validate(
    input: &JobInput,
    caps: &ModelCaps,
    limits: &Limits,
    random_seed: u64,
) -> Result<JobSpec, Violations> {
    let mut found = Found::new(&input.refused);
    let points = found.take(match &input.points {
        None => Err(violation("points", "present", "missing")),
        Some(p) => parse_points(p, limits),
    });
    let category = found.take(category(input, caps));
    // physnap's defaults (the paper's 45/2/2 ÷ active terms, ℓ_pen and ℓ_mob × 3) for the terms
    // not switched off with a 0; given weights override. The rule lives in the engine, shared
    // with `physnap generate --points`.
    let [w_pc, w_pen, w_mob] =
        GuidanceOptions::weights_or_defaults([input.w_pc, input.w_pen, input.w_mob], true);
    let w_pc = found.take(weight("w_pc", w_pc, limits));
    let w_pen = found.take(weight("w_pen", w_pen, limits));
    let w_mob = found.take(weight("w_mob", w_mob, limits));
    let cameras = found.take(match &input.camera {
        None => Ok(Vec::new()),
        Some(c) => parse_cameras(c),
    });
    let w_free = found.take(
        input
            .w_free
            .map(|w| weight("w_free", w, limits))
            .transpose(),
    );
    // ℓ_free's weight: as given, the default with a camera, and 0 without one (the rule of
    // `GuidanceOptions::with_cameras`, as `physnap generate`).
    let w_free = match (&cameras, w_free) {
        (Some(c), _) if c.is_empty() => Some(0.0),
        (_, Some(Some(w))) => Some(w),
        (_, Some(None)) => Some(DEFAULT_W_FREE),
        (_, None) => None,
    };
    // Whether the job is guided decides two defaults below; a rejected weight counts as 0
    // there (the job is refused anyway).
    let guided = loss_guided(
        w_pc.unwrap_or(0.0),
        w_pen.unwrap_or(0.0),
        w_mob.unwrap_or(0.0),
        w_free.unwrap_or(0.0),
        cameras.as_deref().unwrap_or(&[]),
    );
    let repair = found.take(repair(input));
    let frame_auto = found.take(frame_mode(input));
    let scale = found.take(scale_mode(input));
    let sampler = found.take(sampler(input));
    let steps = found.take(steps(input, caps));
    let n_g = found.take(n_g(input, caps));
    let tau = found.take(tau(input));
    let guidance_max_step = found.take(guidance_max_step(input));
    let refine_steps = found.take(at_most_refine_steps(
        "refine_steps",
        input.refine_steps.unwrap_or(DEFAULT_REFINE_STEPS as u32),
    ));
    let refine_physics_steps = found.take(at_most_refine_steps(
        "refine_physics_steps",
        input
            .refine_physics_steps
            .unwrap_or(DEFAULT_REFINE_PHYSICS_STEPS as u32),
    ));
    let samples = found.take(samples(input, limits));
    let deadline_seconds = found.take(deadline(input, limits));
    let preview_every = steps.and_then(|s| found.take(preview_every(input, s)));
    let resolution = found.take(resolution(input, limits));
    let retrieval = found.take(retrieval(
        input,
        caps,
        category.as_ref().map(Option::as_ref),
    ));
    let joint_motion = found.take(joint_motion(input));
    let category_guidance = found.take(category_guidance_of(input, category.as_ref(), guided));
    let category_guidance_below = found.take(category_guidance_below_of(input, guided));

    // The frame estimate needs the points, up and cameras, valid on their own.
    let frame = match (frame_auto, &points, &cameras) {
        (Some(true), Some(p), Some(c)) => found.take(estimate_frame(input, p, c)).map(Some),
        (Some(false), ..) => Some(None),
        _ => None,
    };
    found.result()?;
    let (
        Some(points),
        Some(category),
        Some(w_pc),
        Some(w_pen),
        Some(w_mob),
        Some(cameras),
        Some(w_free),
        Some(repair),
        Some(scale),
        Some(sampler),
        Some(steps),
        Some(n_g),
        Some(tau),
        Some(guidance_max_step),
        Some(refine_steps),
        Some(refine_physics_steps),
        Some(samples),
        Some(deadline_seconds),
        Some(preview_every),
        Some(resolution),
        Some(retrieval),
        Some(joint_motion),
        Some(category_guidance),
        Some(category_guidance_below),
        Some(frame),
    ) = (
        points,
        category,
        w_pc,
        w_pen,
        w_mob,
        cameras,
        w_free,
        repair,
        scale,
        sampler,
        steps,
        n_g,
        tau,
        guidance_max_step,
        refine_steps,
        refine_physics_steps,
        samples,
        deadline_seconds,
        preview_every,
        resolution,
        retrieval,
        joint_motion,
        category_guidance,
        category_guidance_below,
        frame,
    )
    else {
        // Every `None` above comes with a violation, so `found.result()` has returned.
        unreachable!("a field without a value and without a violation")
    };
    // The scale hypothesis is resolved on the canonical scan (the frame's when it is `auto`).
    let scale = match scale {
        Some(s) => Some(s),
        None if !matches!(input.scale.as_deref().map(str::trim), Some("off")) => {
            let canonical = frame.map(|f| f.points_to_canonical(&points));
            crate::engine::generate::auto_scale(
                canonical.as_deref().unwrap_or(&points),
                Some(crate::data::synth::prior_diagonal(
                    category.as_ref().map(|c| c.1.as_str()),
                )),
            )
        }
        None => None,
    };
    let spec = JobSpec {
        points,
        category,
        w_pc,
        w_pen,
        w_mob,
        n_g,
        tau,
        guidance_max_step,
        refine_steps,
        refine_physics_steps,
        sampler,
        steps,
        seed: input.seed.unwrap_or(random_seed),
        samples,
        deadline_seconds,
        preview_every,
        resolution,
        retrieval,
        category_guidance,
        category_guidance_below,
        joint_motion,
        cameras,
        w_free,
        repair,
        scale,
        frame,
    };
    // The engine's own checks of the guidance the job will run with (the cameras' count,
    // range and place outside the points' box among them), at submission rather than at run.
    if let Some(g) = super::super::runner::guidance_of(&spec) {
        g.validate(caps.schedule_steps as usize)
            .map_err(|e| engine_violation(e, input.camera.as_ref()))?;
    }
    Ok(spec)
}

/// The category: absent, or one the weights know and are conditioned on.
fn category(input: &JobInput, caps: &ModelCaps) -> Result<Option<(usize, String)>, Violation> {
    let Some(c) = input
        .category
        .as_deref()
        .map(str::trim)
        .filter(|c| !c.is_empty())
    else {
        return Ok(None);
    };
    let idx = category_index(c)
        .filter(|&i| i < caps.categories.len())
        .ok_or_else(|| {
            violation(
                "category",
                format!("one of: {}", caps.categories.join(", ")),
                format!("{c:?}"),
            )
        })?;
    if !caps.conditional {
        return Err(violation(
            "category",
            "absent (these weights are unconditional)",
            format!("{c:?}"),
        ));
    }
    Ok(Some((idx, caps.categories[idx].clone())))
}

fn repair(input: &JobInput) -> Result<RepairMode, Violation> {
    match input.repair.as_deref().filter(|r| !r.is_empty()) {
        None => Ok(DEFAULT_REPAIR),
        Some(r) => RepairMode::parse(r)
            .ok_or_else(|| violation("repair", "\"on\" or \"off\"", format!("{r:?}"))),
    }
}

/// Whether the frame is `auto` (and `up` is given only then).
fn frame_mode(input: &JobInput) -> Result<bool, Violation> {
    match input
        .frame
        .as_deref()
        .map(str::trim)
        .filter(|s| !s.is_empty())
    {
        None | Some("canonical") => match input.up {
            Some(up) => Err(violation(
                "up",
                "given only with frame \"auto\"",
                format!("{up:?}"),
            )),
            None => Ok(false),
        },
        Some("auto") => Ok(true),
        Some(f) => Err(violation(
            "frame",
            "\"canonical\" or \"auto\"",
            format!("{f:?}"),
        )),
    }
}

/// The scan's frame, estimated now (the scale is then the canonical scan's).
fn estimate_frame(
    input: &JobInput,
    points: &[[f32; 3]],
    cameras: &[[f32; 3]],
) -> Result<crate::frame::ScanFrame, Violation> {
    let up = input.up.unwrap_or([0.0, 0.0, 1.0]);
    crate::engine::frame::estimate(points, up, cameras)
        .map(|est| est.frame)
        .map_err(|e| match e {
            EngineError::Invalid(i) => Violation {
                field: i.field,
                limit: i.limit,
                value: i.value,
            },
            other => violation("frame", "an estimable scan", other.to_string()),
        })
}

/// A fixed scale factor, or `None` for `auto` and `off` (resolved once the frame is known).
fn scale_mode(input: &JobInput) -> Result<Option<f64>, Violation> {
    match input
        .scale
        .as_deref()
        .map(str::trim)
        .filter(|s| !s.is_empty())
    {
        None | Some("auto") | Some("off") => Ok(None),
        Some(v) => {
            let [lo, hi] = crate::engine::generate::SCALE_RANGE;
            v.parse()
                .ok()
                .filter(|s: &f64| s.is_finite() && (lo..=hi).contains(s))
                .map(Some)
                .ok_or_else(|| {
                    violation(
                        "scale",
                        format!("\"auto\", \"off\" or a number in [{lo}, {hi}]"),
                        format!("{v:?}"),
                    )
                })
        }
    }
}

/// The reverse-step rule; η only with DDIM, in [0, 1].
fn sampler(input: &JobInput) -> Result<Sampler, Violation> {
    let sampler = input
        .sampler
        .as_deref()
        .filter(|s| !s.is_empty())
        .unwrap_or(SAMPLER_DDIM);
    if sampler != SAMPLER_DDPM && sampler != SAMPLER_DDIM {
        return Err(violation(
            "sampler",
            format!("\"{SAMPLER_DDPM}\" or \"{SAMPLER_DDIM}\""),
            format!("{sampler:?}"),
        ));
    }
    match input.eta {
        Some(e) if sampler != SAMPLER_DDIM => Err(violation(
            "eta",
            format!("absent unless sampler is \"{SAMPLER_DDIM}\""),
            e,
        )),
        Some(e) if !(e.is_finite() && (0.0..=1.0).contains(&e)) => {
            Err(violation("eta", "finite, in [0, 1]", e))
        }
        _ if sampler == SAMPLER_DDPM => Ok(Sampler::Ddpm),
        e => Ok(Sampler::Ddim {
            eta: e.unwrap_or(0.0),
        }),
    }
}

fn steps(input: &JobInput, caps: &ModelCaps) -> Result<u32, Violation> {
    let steps = input
        .steps
        .unwrap_or((DEFAULT_STEPS as u32).min(caps.schedule_steps));
    if steps == 0 || steps > caps.schedule_steps {
        return Err(violation(
            "steps",
            format!(
                "1..={} (the diffusion schedule the weights were trained with)",
                caps.schedule_steps
            ),
            steps,
        ));
    }
    Ok(steps)
}

/// n_g as in the paper: the steps with diffusion time t < n_g are guided, 0..=the schedule's
/// length (default the paper's 500, or the whole schedule when it is shorter).
fn n_g(input: &JobInput, caps: &ModelCaps) -> Result<u32, Violation> {
    let n_g = input
        .n_g
        .unwrap_or((DEFAULT_GUIDED_STEPS as u32).min(caps.schedule_steps));
    if n_g > caps.schedule_steps {
        return Err(violation(
            "n_g",
            format!(
                "<= {} (diffusion steps of the schedule)",
                caps.schedule_steps
            ),
            n_g,
        ));
    }
    Ok(n_g)
}

fn tau(input: &JobInput) -> Result<f64, Violation> {
    let tau = input.tau.unwrap_or(DEFAULT_TAU);
    if !(tau.is_finite() && tau > 0.0 && tau <= MAX_TAU) {
        return Err(violation(
            "tau",
            format!("finite, > 0 and <= {MAX_TAU}"),
            tau,
        ));
    }
    Ok(tau)
}

/// Absent: physnap's default clamp; 0: off (the paper's raw gradient).
fn guidance_max_step(input: &JobInput) -> Result<Option<f64>, Violation> {
    match input.guidance_max_step {
        None => Ok(Some(DEFAULT_MAX_STEP)),
        Some(0.0) => Ok(None),
        Some(c) if c.is_finite() && c > 0.0 => Ok(Some(c)),
        Some(c) => Err(violation(
            "guidance_max_step",
            "finite and >= 0 (0: off, the paper's raw gradient)",
            c,
        )),
    }
}

fn at_most_refine_steps(field: &str, n: u32) -> Result<u32, Violation> {
    if n as usize > MAX_REFINE_STEPS {
        return Err(violation(
            field,
            format!("<= {MAX_REFINE_STEPS} (0: off)"),
            n,
        ));
    }
    Ok(n)
}

fn samples(input: &JobInput, limits: &Limits) -> Result<u32, Violation> {
    let samples = input.samples.unwrap_or(1);
    if samples == 0 || samples > limits.max_samples {
        return Err(violation(
            "samples",
            format!("1..={}", limits.max_samples),
            samples,
        ));
    }
    Ok(samples)
}

fn deadline(input: &JobInput, limits: &Limits) -> Result<f64, Violation> {
    let d = input
        .deadline_seconds
        .unwrap_or(limits.default_deadline_seconds);
    if !d.is_finite() || d <= 0.0 || d > limits.max_deadline_seconds {
        return Err(violation(
            "deadline_seconds",
            format!("> 0 and <= {}", limits.max_deadline_seconds),
            d,
        ));
    }
    Ok(d)
}

fn preview_every(input: &JobInput, steps: u32) -> Result<u32, Violation> {
    let p = input.preview_every.unwrap_or(0);
    if p > steps {
        return Err(violation("preview_every", format!("<= steps ({steps})"), p));
    }
    Ok(p)
}

fn resolution(input: &JobInput, limits: &Limits) -> Result<u32, Violation> {
    let r = input.resolution.unwrap_or(32);
    if r < limits.resolution.0 || r > limits.resolution.1 {
        return Err(violation(
            "resolution",
            format!("{}..={}", limits.resolution.0, limits.resolution.1),
            r,
        ));
    }
    Ok(r)
}

/// Codebook retrieval: what the weights' codebook (and the job's category) can serve.
/// `category` is `None` when the category was rejected (then `"category"` is not checked
/// against it).
fn retrieval(
    input: &JobInput,
    caps: &ModelCaps,
    category: Option<Option<&(usize, String)>>,
) -> Result<Retrieval, Violation> {
    let Some(r) = input.retrieval.as_deref().filter(|r| !r.is_empty()) else {
        return Ok(Retrieval::auto(caps.codebook));
    };
    if r == "auto" {
        return Ok(Retrieval::auto(caps.codebook));
    }
    match Retrieval::parse(r) {
        None => Err(violation(
            "retrieval",
            "\"auto\", \"off\", \"empty\", \"all\" or \"category\"",
            format!("{r:?}"),
        )),
        Some(Retrieval::Off) => Ok(Retrieval::Off),
        Some(_) if !caps.codebook => Err(violation(
            "retrieval",
            "\"off\" or \"auto\" (these weights have no codebook)",
            format!("{r:?}"),
        )),
        Some(Retrieval::Category) => match category {
            None => Ok(Retrieval::Category),
            Some(None) => Err(violation(
                "retrieval",
                "a category with \"category\" (it takes the requested category's codes)",
                format!("{r:?} without a category"),
            )),
            Some(Some((c, name))) if !caps.codebook_categories.contains(c) => Err(violation(
                "retrieval",
                if caps.codebook_categories.is_empty() {
                    "a codebook whose codes carry categories (these weights' do not)".to_string()
                } else {
                    format!(
                        "a category with training codes in the codebook: {}",
                        caps.codebook_categories
                            .iter()
                            .filter_map(|&k| caps.categories.get(k).map(String::as_str))
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                },
                format!("{r:?} with category {name}"),
            )),
            Some(Some(_)) => Ok(Retrieval::Category),
        },
        Some(mode) => Ok(mode),
    }
}

fn joint_motion(input: &JobInput) -> Result<JointMotion, Violation> {
    match input.joint_motion.as_deref().filter(|m| !m.is_empty()) {
        None => Ok(DEFAULT_JOINT_MOTION),
        Some(m) => JointMotion::parse(m).ok_or_else(|| {
            violation(
                "joint_motion",
                "\"screw\" or \"dominant\"",
                format!("{m:?}"),
            )
        }),
    }
}

/// Classifier-free category guidance: with a category, the default for a scan-guided or a
/// plain job (0 and 2); 0 without one. `category` is `None` when the category was rejected
/// (then only the range is checked).
fn category_guidance_of(
    input: &JobInput,
    category: Option<&Option<(usize, String)>>,
    guided: bool,
) -> Result<f64, Violation> {
    match (input.category_guidance, category) {
        (Some(w), _) if !(w.is_finite() && (0.0..=MAX_CATEGORY_GUIDANCE).contains(&w)) => {
            Err(violation(
                "category_guidance",
                format!("finite, in [0, {MAX_CATEGORY_GUIDANCE}]"),
                w,
            ))
        }
        (Some(w), Some(None)) if w > 0.0 => Err(violation(
            "category_guidance",
            "0 or absent without a category",
            w,
        )),
        (_, Some(None)) | (_, None) => Ok(0.0),
        (requested, Some(Some(_))) => Ok(category_guidance(requested, guided)),
    }
}

fn category_guidance_below_of(input: &JobInput, guided: bool) -> Result<u32, Violation> {
    let below = category_guidance_below(input.category_guidance_below.map(|b| b as usize), guided);
    if !(1..=NUM_STEPS).contains(&below) {
        return Err(violation(
            "category_guidance_below",
            format!("in [1, {NUM_STEPS}]"),
            below,
        ));
    }
    Ok(below as u32)
}
