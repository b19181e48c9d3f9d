//! The domain job: a validated [`JobSpec`] and the limits it is checked against.
//!
//! Why it exists: REST and gRPC both accept a job in their own wire format; both hand a
//! transport-neutral [`JobInput`] to [`validate`], which is the only way to get a [`JobSpec`].
//! The runner (and through it the engine) only ever sees a `JobSpec`, so every invariant below
//! holds for every job that is stored or run. Each rejection is a [`Violation`] naming the
//! field, the limit and the offending value, which both transports render (problem+json /
//! `INVALID_ARGUMENT`).

use crate::data::categories::category_index;
use crate::engine::EngineError;
use crate::engine::generate::{JointMotion, RepairMode, Retrieval};
use crate::engine::guidance::{
    DEFAULT_GUIDED_STEPS, DEFAULT_MAX_STEP, DEFAULT_REFINE_PHYSICS_STEPS, DEFAULT_REFINE_STEPS,
    DEFAULT_TAU, DEFAULT_W_FREE, GuidanceOptions, MAX_REFINE_STEPS, weights_active,
};
use crate::engine::sample::Sampler;
use crate::engine::sample::{
    DEFAULT_STEPS, MAX_CATEGORY_GUIDANCE, category_guidance, category_guidance_below,
};
use crate::engine::schedule::{NUM_STEPS, timesteps};
use crate::pointcloud::{Format, Limits as CloudLimits, PointCloud, PointCloudError};

/// The raw point-cloud payload, as it arrived.
#[derive(Debug, Clone, PartialEq)]
pub enum PointsInput {
    /// `[x, y, z]` triples (JSON array).
    Triples(Vec<[f64; 3]>),
    /// Flat `[x0, y0, z0, x1, ...]` (gRPC `repeated float`).
    Flat(Vec<f32>),
    /// Little-endian f32 triples (decoded base64, gRPC bytes, or a raw upload).
    F32Le(Vec<u8>),
    /// A PLY file (any PLY encoding).
    Ply(Vec<u8>),
    /// A NumPy `(N, 3)` float array.
    Npy(Vec<u8>),
}

/// The sensor position(s) of a request as the client wrote them, so that a rejection names
/// `camera` for a single triple and `camera[j]` for the j-th of a list. The coordinates are
/// not yet checked (a triple may have the wrong length).
#[derive(Debug, Clone, PartialEq)]
pub enum CameraInput {
    /// One `[x, y, z]`.
    One(Vec<f64>),
    /// `[[x, y, z], ...]`.
    Many(Vec<Vec<f64>>),
}

impl CameraInput {
    /// The field name of the `j`-th camera, as the client wrote it.
    pub fn field(&self, j: usize) -> String {
        match self {
            CameraInput::One(_) => "camera".into(),
            CameraInput::Many(_) => format!("camera[{j}]"),
        }
    }

    fn triples(&self) -> Vec<&[f64]> {
        match self {
            CameraInput::One(t) => vec![t.as_slice()],
            CameraInput::Many(l) => l.iter().map(Vec::as_slice).collect(),
        }
    }
}

/// A job request in transport-neutral form: every optional knob is `None` when not given.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JobInput {
    /// The partial point cloud (required).
    pub points: Option<PointsInput>,
    /// Category name (case-insensitive; NAP or PartNet-Mobility spelling).
    pub category: Option<String>,
    /// Point-cloud guidance weight.
    pub w_pc: Option<f64>,
    /// Penetration guidance weight.
    pub w_pen: Option<f64>,
    /// Mobility guidance weight.
    pub w_mob: Option<f64>,
    /// n_g: how many of the final reverse steps are guided.
    pub n_g: Option<u32>,
    /// τ: temperature of the soft point-to-part correspondence in ℓ_pc.
    pub tau: Option<f64>,
    /// Clamp of each guidance-gradient entry (model space; off when absent).
    pub guidance_max_step: Option<f64>,
    /// Refinement steps after sampling (default [`DEFAULT_REFINE_STEPS`]; 0: off).
    pub refine_steps: Option<u32>,
    /// Physics-only refinement steps after the refinement steps: ℓ_pen and ℓ_mob alone, part
    /// boxes only (default [`DEFAULT_REFINE_PHYSICS_STEPS`]; 0: off).
    pub refine_physics_steps: Option<u32>,
    /// Sampler name (`ddpm` or `ddim`).
    pub sampler: Option<String>,
    /// DDIM noise level η (only with `ddim`).
    pub eta: Option<f64>,
    /// Reverse steps.
    pub steps: Option<u32>,
    /// Seed of sample 0.
    pub seed: Option<u64>,
    /// Best-of-N.
    pub samples: Option<u32>,
    /// Seconds from submission until the job fails with `deadline-exceeded`.
    pub deadline_seconds: Option<f64>,
    /// x̂₀ preview every this many steps (0 = never).
    pub preview_every: Option<u32>,
    /// Marching-cubes grid resolution.
    pub resolution: Option<u32>,
    /// Codebook retrieval of part shapes (`auto`, `off`, `empty`, `all`, `category`).
    pub retrieval: Option<String>,
    /// Classifier-free category guidance w (with a category only).
    pub category_guidance: Option<f64>,
    /// Apply the category guidance only in steps with diffusion time t below this (1-1000).
    pub category_guidance_below: Option<u32>,
    /// Joint motions of the result: `screw` or `dominant` (see [`JobSpec::joint_motion`]).
    pub joint_motion: Option<String>,
    /// Sensor position(s) the scan was taken from (object frame, metres).
    pub camera: Option<CameraInput>,
    /// Weight of the free-space loss ℓ_free (default [`DEFAULT_W_FREE`] with a camera, 0
    /// without).
    pub w_free: Option<f64>,
    /// Joint repair and part removal: `on` (default) or `off`.
    pub repair: Option<String>,
    /// Scale hypothesis: `auto` (default: the scan is scaled so its box diagonal is the
    /// category's typical procedural size, at most ×/÷ 4, and the result scaled back), `off`, or
    /// a factor such as `"2.5"` (1/16–16).
    pub scale: Option<String>,
    /// The scan's frame: `canonical` (default: physnap's frame, +Z up, front −X, floor z = 0)
    /// or `auto` (any right-handed metric frame with up `up`: floor, yaw and position are
    /// estimated at submission, the model is returned in the scan's frame).
    pub frame: Option<String>,
    /// The scan's up direction with `frame: auto` (default [0, 0, 1]).
    pub up: Option<[f64; 3]>,
}

/// Most cameras of a job (the engine's limit).
pub use crate::engine::free_space::MAX_CAMERAS;

/// The joint motion of a job that names none.
pub const DEFAULT_JOINT_MOTION: JointMotion = JointMotion::Dominant;

/// The repair mode of a job that names none (the product default, as `physnap generate`'s; the
/// engine's own default is off).
pub const DEFAULT_REPAIR: RepairMode = RepairMode::On;

/// NAP's DDPM (strided ancestral sampling when fewer steps than the schedule are asked for).
pub const SAMPLER_DDPM: &str = "ddpm";
/// DDIM with noise level η.
pub const SAMPLER_DDIM: &str = "ddim";

/// Limits of a job; the service's flags can tighten them.
#[derive(Debug, Clone, PartialEq)]
pub struct Limits {
    /// Fewest points.
    pub min_points: usize,
    /// Most points.
    pub max_points: usize,
    /// Largest loss weight.
    pub max_weight: f64,
    /// Most samples (best-of-N).
    pub max_samples: u32,
    /// Longest deadline (seconds).
    pub max_deadline_seconds: f64,
    /// Deadline when none is given (seconds).
    pub default_deadline_seconds: f64,
    /// Meshing resolution range.
    pub resolution: (u32, u32),
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            min_points: 16,
            max_points: 100_000,
            max_weight: 1.0e6,
            max_samples: 16,
            max_deadline_seconds: 7.0 * 86_400.0,
            default_deadline_seconds: 3_600.0,
            resolution: (8, 128),
        }
    }
}

/// What the model can do, from the loaded weights' manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelCaps {
    /// Category names, index = position.
    pub categories: Vec<String>,
    /// Whether the denoiser is category-conditioned.
    pub conditional: bool,
    /// Diffusion steps of the schedule.
    pub schedule_steps: u32,
    /// Whether the weights ship a retrieval codebook.
    pub codebook: bool,
    /// Category indices that have codes in the codebook (what `retrieval: "category"` can
    /// use); empty when the codes carry no categories.
    pub codebook_categories: Vec<usize>,
}

/// A validated job. Invariants: 16..=100k finite points (per [`Limits`]), a known category for
/// a conditional model, finite non-negative weights, `sampler` `ddpm` or `ddim` (η ∈ [0, 1],
/// 0 for `ddpm`), `steps` in 1..=schedule, `n_g ≤ steps`, τ finite and > 0, 1..=max samples, a
/// positive finite deadline, at most 16 finite cameras outside the points' box (`w_free` 0
/// without one), and guidance the engine accepts ([`GuidanceOptions::validate`]).
#[derive(Debug, Clone, PartialEq)]
pub struct JobSpec {
    /// The point cloud (object frame, metres).
    pub points: Vec<[f32; 3]>,
    /// Category index and canonical name.
    pub category: Option<(usize, String)>,
    /// Point-cloud loss weight.
    pub w_pc: f64,
    /// Penetration loss weight.
    pub w_pen: f64,
    /// Mobility loss weight.
    pub w_mob: f64,
    /// n_g: the last this many of the `steps` reverse steps are guided (see
    /// [`JobSpec::guidance_threshold`] for the engine's diffusion-time form).
    pub n_g: u32,
    /// τ: temperature of the soft point-to-part correspondence in ℓ_pc.
    pub tau: f64,
    /// Clamp of each guidance-gradient entry (None: the paper's raw gradient).
    pub guidance_max_step: Option<f64>,
    /// Refinement steps after sampling (0: off, the paper).
    pub refine_steps: u32,
    /// Physics-only refinement steps after the refinement steps (ℓ_pen and ℓ_mob alone, part
    /// boxes only; 0: off). They run only when `w_pen` or `w_mob` is > 0.
    pub refine_physics_steps: u32,
    /// The reverse-step rule (DDIM carries its η).
    pub sampler: Sampler,
    /// Reverse steps (1..=schedule).
    pub steps: u32,
    /// Seed of sample 0 (always materialised).
    pub seed: u64,
    /// Best-of-N.
    pub samples: u32,
    /// Seconds from submission.
    pub deadline_seconds: f64,
    /// Preview period in steps (0 = never).
    pub preview_every: u32,
    /// Marching-cubes resolution.
    pub resolution: u32,
    /// Codebook retrieval of part shapes (`auto` resolved).
    pub retrieval: Retrieval,
    /// Classifier-free category guidance w (0 without a category).
    pub category_guidance: f64,
    /// The guidance applies in steps with diffusion time t below this (1000: every step;
    /// default 1000 for a guided job, 500 for plain sampling).
    pub category_guidance_below: u32,
    /// `Screw` (NAP: each joint keeps its rotation and translation ranges) or `Dominant` (each
    /// joint keeps only the wider one, so exported joints are plain revolute / prismatic).
    pub joint_motion: JointMotion,
    /// Sensor positions (object frame, metres) the scan was taken from; empty: unknown. They
    /// give ℓ_free (with `w_free` > 0) and, with `repair` on, the removal of parts in space the
    /// cameras saw through.
    pub cameras: Vec<[f32; 3]>,
    /// Weight of ℓ_free (0 without cameras).
    pub w_free: f64,
    /// Joint repair and removal of parts the scan does not allow, after sampling.
    pub repair: RepairMode,
    /// The resolved scale hypothesis (None: the scan as given); `auto` is resolved at
    /// submission, so a stored job keeps the factor it was accepted with.
    pub scale: Option<f64>,
    /// The scan's frame (None: canonical input); `auto` is estimated at submission, so a
    /// stored job keeps the frame it was accepted with.
    pub frame: Option<crate::frame::ScanFrame>,
}

/// Largest τ accepted (the engine's limit).
pub const MAX_TAU: f64 = 1e9;

impl JobSpec {
    /// Whether any guidance weight is positive (ℓ_free's only with a camera; otherwise the job
    /// samples unguided).
    pub fn guided(&self) -> bool {
        loss_guided(
            self.w_pc,
            self.w_pen,
            self.w_mob,
            self.w_free,
            &self.cameras,
        )
    }

    /// n_g in the engine's form: guidance applies for diffusion time t < this. The reverse
    /// steps visit `timesteps(schedule_steps, steps)` (descending); guiding the last `n_g` of
    /// them means t < (the time of the n_g-th last step) + 1.
    pub fn guidance_threshold(&self, schedule_steps: usize) -> usize {
        let times = timesteps(schedule_steps, self.steps as usize);
        let n = (self.n_g as usize).min(times.len());
        if n == 0 {
            0
        } else {
            times[times.len() - n] + 1
        }
    }
}

/// One broken rule: the field, the limit and the value.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("invalid {field}: {value} (must be {limit})")]
pub struct Violation {
    /// JSON-pointer-like path, e.g. `points[3][1]` or `w_pc`.
    pub field: String,
    /// The rule, e.g. `>= 0`.
    pub limit: String,
    /// The value given, rendered.
    pub value: String,
}

fn violation(
    field: impl Into<String>,
    limit: impl Into<String>,
    value: impl ToString,
) -> Violation {
    Violation {
        field: field.into(),
        limit: limit.into(),
        value: value.to_string(),
    }
}

fn cloud_violation(e: PointCloudError, limits: &Limits) -> Violation {
    let range = format!("{}..={} points", limits.min_points, limits.max_points);
    match e {
        PointCloudError::NonFinite { index, axis, value } => {
            violation(format!("points[{index}][{axis}]"), "finite", value)
        }
        PointCloudError::Empty => violation("points", range, "0 points"),
        PointCloudError::TooFew { count, .. } => {
            violation("points", range, format!("{count} points"))
        }
        PointCloudError::TooMany { count, .. } => {
            violation("points", range, format!("{count} points"))
        }
        other => violation("points", "a well-formed point cloud", other.to_string()),
    }
}

/// Whether a job's losses guide it: one of ℓ_pc, ℓ_pen, ℓ_mob on, or ℓ_free with a camera (the
/// rule of [`GuidanceOptions::is_active`]; a job always has points).
fn loss_guided(w_pc: f64, w_pen: f64, w_mob: f64, w_free: f64, cameras: &[[f32; 3]]) -> bool {
    weights_active(w_pc, w_pen, w_mob) || (w_free > 0.0 && !cameras.is_empty())
}

/// Renders numbers as the client wrote them: `[1, 2.5]`.
fn list(v: &[f64]) -> String {
    let items: Vec<String> = v.iter().map(f64::to_string).collect();
    format!("[{}]", items.join(", "))
}

/// The cameras' shape: each 3 finite numbers. The engine checks the rest (count, range, outside
/// the points' box) on the job's guidance, see [`engine_violation`].
fn parse_cameras(c: &CameraInput) -> Result<Vec<[f32; 3]>, Violation> {
    c.triples()
        .into_iter()
        .enumerate()
        .map(|(j, t)| match t {
            [x, y, z] if t.iter().all(|v| v.is_finite()) => Ok([*x as f32, *y as f32, *z as f32]),
            _ => Err(violation(
                c.field(j),
                "3 finite numbers [x, y, z] (object frame, metres)",
                list(t),
            )),
        })
        .collect()
}

/// A rejection of [`GuidanceOptions::validate`] with the field named as the client wrote it
/// (`guidance.cameras[1]` → `camera[1]`, or `camera` for a single triple; `guidance.w_pc` →
/// `w_pc`).
fn engine_violation(e: EngineError, camera: Option<&CameraInput>) -> Violation {
    let EngineError::Invalid(inv) = e else {
        return violation("guidance", "options the engine accepts", e.to_string());
    };
    let field = inv.field.strip_prefix("guidance.").unwrap_or(&inv.field);
    let field = match field {
        "max_step" => "guidance_max_step".to_string(),
        "steps" => "n_g".to_string(),
        f => match (f.strip_prefix("cameras"), camera) {
            (None, _) => f.to_string(),
            (Some(index), Some(CameraInput::Many(_))) => format!("camera{index}"),
            (Some(_), _) => "camera".to_string(),
        },
    };
    violation(field, inv.limit, inv.value)
}

fn weight(field: &str, v: f64, limits: &Limits) -> Result<f64, Violation> {
    if !v.is_finite() || v < 0.0 || v > limits.max_weight {
        return Err(violation(
            field,
            format!("finite, >= 0 and <= {}", limits.max_weight),
            v,
        ));
    }
    Ok(v)
}

/// Decode the point payload and check count and finiteness.
pub fn parse_points(p: &PointsInput, limits: &Limits) -> Result<Vec<[f32; 3]>, Violation> {
    let cl = CloudLimits {
        min_points: limits.min_points,
        max_points: limits.max_points,
    };
    let cloud =
        match p {
            PointsInput::Triples(t) => {
                // f64 → f32: values beyond f32 range become infinite and are rejected below.
                let cloud = PointCloud {
                    points: t.iter().map(|q| q.map(|c| c as f32)).collect(),
                };
                cloud
                    .validate(&cl)
                    .map_err(|e| cloud_violation(e, limits))?;
                cloud
            }
            PointsInput::Flat(v) => {
                if !v.len().is_multiple_of(3) {
                    return Err(violation(
                        "points",
                        "a multiple of 3 values (x, y, z per point)",
                        format!("{} values", v.len()),
                    ));
                }
                let cloud = PointCloud {
                    points: v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
                };
                cloud
                    .validate(&cl)
                    .map_err(|e| cloud_violation(e, limits))?;
                cloud
            }
            PointsInput::F32Le(b) => {
                if !b.len().is_multiple_of(12) {
                    return Err(violation(
                        "points",
                        "a multiple of 12 bytes (3 little-endian f32 per point)",
                        format!("{} bytes", b.len()),
                    ));
                }
                if b.len() / 12 > limits.max_points {
                    return Err(cloud_violation(
                        PointCloudError::TooMany {
                            count: (b.len() / 12) as u64,
                            max: limits.max_points,
                        },
                        limits,
                    ));
                }
                let f = |c: &[u8]| f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                let cloud = PointCloud {
                    points: b
                        .chunks_exact(12)
                        .map(|c| [f(&c[0..4]), f(&c[4..8]), f(&c[8..12])])
                        .collect(),
                };
                cloud
                    .validate(&cl)
                    .map_err(|e| cloud_violation(e, limits))?;
                cloud
            }
            PointsInput::Ply(b) => PointCloud::from_bytes(b, Format::Ply, &cl)
                .map_err(|e| cloud_violation(e, limits))?,
            PointsInput::Npy(b) => PointCloud::from_bytes(b, Format::Npy, &cl)
                .map_err(|e| cloud_violation(e, limits))?,
        };
    Ok(cloud.points)
}

/// Validate a request into a [`JobSpec`]. `random_seed` is used only when no seed was given.
pub fn validate(
    input: &JobInput,
    caps: &ModelCaps,
    limits: &Limits,
    random_seed: u64,
) -> Result<JobSpec, Violation> {
    let points = match &input.points {
        None => return Err(violation("points", "present", "missing")),
        Some(p) => parse_points(p, limits)?,
    };
    let category = match input.category.as_deref().map(str::trim) {
        None | Some("") => None,
        Some(c) => {
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
            Some((idx, caps.categories[idx].clone()))
        }
    };
    // physnap's defaults (the paper's 45/2/2 ÷ active terms, ℓ_pen and ℓ_mob × 3) for the terms
    // not switched off with a 0; given weights override. The rule lives in the engine, shared
    // with `physnap generate --points`.
    let [w_pc, w_pen, w_mob] =
        GuidanceOptions::weights_or_defaults([input.w_pc, input.w_pen, input.w_mob], true);
    let w_pc = weight("w_pc", w_pc, limits)?;
    let w_pen = weight("w_pen", w_pen, limits)?;
    let w_mob = weight("w_mob", w_mob, limits)?;
    let cameras = match &input.camera {
        None => Vec::new(),
        Some(c) => parse_cameras(c)?,
    };
    // ℓ_free's weight: as given (checked like the others), the default with a camera, and 0
    // without one (the rule of `GuidanceOptions::with_cameras`, as `physnap generate`).
    let w_free = input
        .w_free
        .map(|w| weight("w_free", w, limits))
        .transpose()?;
    let w_free = match (cameras.is_empty(), w_free) {
        (true, _) => 0.0,
        (false, Some(w)) => w,
        (false, None) => DEFAULT_W_FREE,
    };
    let guided = loss_guided(w_pc, w_pen, w_mob, w_free, &cameras);
    let repair = match input.repair.as_deref().filter(|r| !r.is_empty()) {
        None => DEFAULT_REPAIR,
        Some(r) => RepairMode::parse(r)
            .ok_or_else(|| violation("repair", "\"on\" or \"off\"", format!("{r:?}")))?,
    };
    // The scan's frame, estimated now (the scale is then the canonical scan's).
    let frame = match input
        .frame
        .as_deref()
        .map(str::trim)
        .filter(|s| !s.is_empty())
    {
        None | Some("canonical") => {
            if let Some(up) = input.up {
                return Err(violation(
                    "up",
                    "given only with frame \"auto\"",
                    format!("{up:?}"),
                ));
            }
            None
        }
        Some("auto") => {
            let up = input.up.unwrap_or([0.0, 0.0, 1.0]);
            let est =
                crate::engine::frame::estimate(&points, up, &cameras).map_err(|e| match e {
                    EngineError::Invalid(i) => Violation {
                        field: i.field,
                        limit: i.limit,
                        value: i.value,
                    },
                    other => violation("frame", "an estimable scan", other.to_string()),
                })?;
            Some(est.frame)
        }
        Some(f) => {
            return Err(violation(
                "frame",
                "\"canonical\" or \"auto\"",
                format!("{f:?}"),
            ));
        }
    };
    let canonical_points = frame.map(|f| f.points_to_canonical(&points));
    let scale = match input
        .scale
        .as_deref()
        .map(str::trim)
        .filter(|s| !s.is_empty())
    {
        None | Some("auto") => crate::engine::generate::auto_scale(
            canonical_points.as_deref().unwrap_or(&points),
            Some(crate::data::synth::prior_diagonal(
                category.as_ref().map(|c| c.1.as_str()),
            )),
        ),
        Some("off") => None,
        Some(v) => {
            let [lo, hi] = crate::engine::generate::SCALE_RANGE;
            let s: f64 = v
                .parse()
                .ok()
                .filter(|s: &f64| s.is_finite() && (lo..=hi).contains(s))
                .ok_or_else(|| {
                    violation(
                        "scale",
                        format!("\"auto\", \"off\" or a number in [{lo}, {hi}]"),
                        format!("{v:?}"),
                    )
                })?;
            Some(s)
        }
    };
    let sampler = input
        .sampler
        .clone()
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| SAMPLER_DDIM.to_string());
    if sampler != SAMPLER_DDPM && sampler != SAMPLER_DDIM {
        return Err(violation(
            "sampler",
            format!("\"{SAMPLER_DDPM}\" or \"{SAMPLER_DDIM}\""),
            format!("{sampler:?}"),
        ));
    }
    let eta = match input.eta {
        None => 0.0,
        Some(e) if sampler != SAMPLER_DDIM => {
            return Err(violation(
                "eta",
                format!("absent unless sampler is \"{SAMPLER_DDIM}\""),
                e,
            ));
        }
        Some(e) if !(e.is_finite() && (0.0..=1.0).contains(&e)) => {
            return Err(violation("eta", "finite, in [0, 1]", e));
        }
        Some(e) => e,
    };
    let sampler = if sampler == SAMPLER_DDIM {
        Sampler::Ddim { eta }
    } else {
        Sampler::Ddpm
    };
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
    // The paper's n_g = 500 of T = 1000 steps, scaled to the steps asked for: the same share
    // of the run as the CLI's `--guidance-steps 500` (t < 500) guides with `--steps`.
    let n_g = input.n_g.unwrap_or_else(|| {
        ((DEFAULT_GUIDED_STEPS as f64 * steps as f64 / caps.schedule_steps.max(1) as f64).round()
            as u32)
            .min(steps)
    });
    if n_g > steps {
        return Err(violation("n_g", format!("<= steps ({steps})"), n_g));
    }
    let tau = input.tau.unwrap_or(DEFAULT_TAU);
    if !(tau.is_finite() && tau > 0.0 && tau <= MAX_TAU) {
        return Err(violation(
            "tau",
            format!("finite, > 0 and <= {MAX_TAU}"),
            tau,
        ));
    }
    // Absent: physnap's default clamp; 0: off (the paper's raw gradient).
    let guidance_max_step = match input.guidance_max_step {
        None => Some(DEFAULT_MAX_STEP),
        Some(0.0) => None,
        Some(c) if c.is_finite() && c > 0.0 => Some(c),
        Some(c) => {
            return Err(violation(
                "guidance_max_step",
                "finite and >= 0 (0: off, the paper's raw gradient)",
                c,
            ));
        }
    };
    let refine_steps = input.refine_steps.unwrap_or(DEFAULT_REFINE_STEPS as u32);
    if refine_steps as usize > MAX_REFINE_STEPS {
        return Err(violation(
            "refine_steps",
            format!("<= {MAX_REFINE_STEPS} (0: off)"),
            refine_steps,
        ));
    }
    let refine_physics_steps = input
        .refine_physics_steps
        .unwrap_or(DEFAULT_REFINE_PHYSICS_STEPS as u32);
    if refine_physics_steps as usize > MAX_REFINE_STEPS {
        return Err(violation(
            "refine_physics_steps",
            format!("<= {MAX_REFINE_STEPS} (0: off)"),
            refine_physics_steps,
        ));
    }
    let samples = input.samples.unwrap_or(1);
    if samples == 0 || samples > limits.max_samples {
        return Err(violation(
            "samples",
            format!("1..={}", limits.max_samples),
            samples,
        ));
    }
    let deadline_seconds = input
        .deadline_seconds
        .unwrap_or(limits.default_deadline_seconds);
    if !deadline_seconds.is_finite()
        || deadline_seconds <= 0.0
        || deadline_seconds > limits.max_deadline_seconds
    {
        return Err(violation(
            "deadline_seconds",
            format!("> 0 and <= {}", limits.max_deadline_seconds),
            deadline_seconds,
        ));
    }
    let preview_every = input.preview_every.unwrap_or(0);
    if preview_every > steps {
        return Err(violation(
            "preview_every",
            format!("<= steps ({steps})"),
            preview_every,
        ));
    }
    let resolution = input.resolution.unwrap_or(32);
    if resolution < limits.resolution.0 || resolution > limits.resolution.1 {
        return Err(violation(
            "resolution",
            format!("{}..={}", limits.resolution.0, limits.resolution.1),
            resolution,
        ));
    }
    let retrieval = match input.retrieval.as_deref().filter(|r| !r.is_empty()) {
        None | Some("auto") => Retrieval::auto(caps.codebook),
        Some(r) => match Retrieval::parse(r) {
            None => {
                return Err(violation(
                    "retrieval",
                    "\"auto\", \"off\", \"empty\", \"all\" or \"category\"",
                    format!("{r:?}"),
                ));
            }
            Some(Retrieval::Off) => Retrieval::Off,
            Some(_) if !caps.codebook => {
                return Err(violation(
                    "retrieval",
                    "\"off\" or \"auto\" (these weights have no codebook)",
                    format!("{r:?}"),
                ));
            }
            Some(Retrieval::Category) => match &category {
                None => {
                    return Err(violation(
                        "retrieval",
                        "a category with \"category\" (it takes the requested category's codes)",
                        format!("{r:?} without a category"),
                    ));
                }
                Some((c, name)) if !caps.codebook_categories.contains(c) => {
                    return Err(violation(
                        "retrieval",
                        if caps.codebook_categories.is_empty() {
                            "a codebook whose codes carry categories (these weights' do not)"
                                .to_string()
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
                    ));
                }
                Some(_) => Retrieval::Category,
            },
            Some(mode) => mode,
        },
    };
    let joint_motion = match input.joint_motion.as_deref().filter(|m| !m.is_empty()) {
        None => DEFAULT_JOINT_MOTION,
        Some(m) => match JointMotion::parse(m) {
            Some(motion) => motion,
            None => {
                return Err(violation(
                    "joint_motion",
                    "\"screw\" or \"dominant\"",
                    format!("{m:?}"),
                ));
            }
        },
    };
    // Classifier-free category guidance: with a category, the default for a scan-guided or a
    // plain job (0 and 2); 0 without one.
    let category_guidance = match (input.category_guidance, &category) {
        (Some(w), _) if !(w.is_finite() && (0.0..=MAX_CATEGORY_GUIDANCE).contains(&w)) => {
            return Err(violation(
                "category_guidance",
                format!("finite, in [0, {MAX_CATEGORY_GUIDANCE}]"),
                w,
            ));
        }
        (Some(w), None) if w > 0.0 => {
            return Err(violation(
                "category_guidance",
                "0 or absent without a category",
                w,
            ));
        }
        (_, None) => 0.0,
        (requested, Some(_)) => category_guidance(requested, guided),
    };
    let category_guidance_below =
        category_guidance_below(input.category_guidance_below.map(|b| b as usize), guided);
    if !(1..=NUM_STEPS).contains(&category_guidance_below) {
        return Err(violation(
            "category_guidance_below",
            format!("in [1, {NUM_STEPS}]"),
            category_guidance_below,
        ));
    }
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
        // In [1, NUM_STEPS], checked above.
        category_guidance_below: category_guidance_below as u32,
        joint_motion,
        cameras,
        w_free,
        repair,
        scale,
        frame,
    };
    // The engine's own checks of the guidance the job will run with (the cameras' count,
    // range and place outside the points' box among them), at submission rather than at run.
    if let Some(g) = super::runner::guidance_of(&spec, caps.schedule_steps as usize) {
        g.validate(caps.schedule_steps as usize)
            .map_err(|e| engine_violation(e, input.camera.as_ref()))?;
    }
    Ok(spec)
}

#[cfg(test)]
mod tests;
