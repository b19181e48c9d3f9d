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
use crate::engine::schedule::NUM_STEPS;
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

/// Hands the request's plain knobs to the macro `$then`, as `/// doc` `name: type,` items. These
/// are every field of a job request except the point cloud, the cameras and `up`, whose wire
/// forms differ by transport.
///
/// This is the one list of them: [`JobInput`], the REST body and query parameters
/// (`api::JobRequest`, `api::UploadParams`) and the gRPC conversion (`grpc::input_of`, which
/// does not compile unless the proto's `JobSpec` has every knob) are generated from it. A new
/// knob is one line here plus its rule in `spec/check.rs`, its proto field and, where it is
/// stored, the store's document.
macro_rules! request_knobs {
    ($then:ident) => {
        $then! {
            /// Category (see `/v1/categories`; NAP or PartNet-Mobility spelling, any case);
            /// absent = unconditional.
            category: String,
            /// Point-cloud loss weight ℓ_pc (>= 0). Default: the paper's 45 ÷ active terms (15).
            w_pc: f64,
            /// Penetration loss weight ℓ_pen (>= 0). Default: physnap's 3 × the paper's 2 ÷
            /// active terms (2 with all three terms); 0 turns it off.
            w_pen: f64,
            /// Mobility loss weight ℓ_mob (>= 0). Default: physnap's 3 × the paper's 2 ÷ active
            /// terms (2 with all three terms); 0 turns it off.
            w_mob: f64,
            /// n_g, as in the paper: the reverse steps with diffusion time t < n_g are guided
            /// (0-1000; default 500, the paper's; 0 = none, 1000 = every step).
            n_g: u32,
            /// τ: temperature of the soft point-to-part correspondence in ℓ_pc (finite, > 0;
            /// default 1000).
            tau: f64,
            /// Clamp each guidance-gradient entry to ±this (model space; finite, >= 0; default
            /// 0.02). A deviation from the paper's raw gradient, which diverges with the shipped
            /// weights; 0 = off (the paper's raw step).
            guidance_max_step: f64,
            /// Refinement steps after sampling (physnap, not in the paper): small clamped
            /// gradient steps on the guidance loss of the finished sample (0-1000; default 30;
            /// 0 = off, the paper).
            refine_steps: u32,
            /// Physics-only refinement steps after the refinement steps: ℓ_pen and ℓ_mob alone,
            /// part boxes only (0-1000; default 0 = off). They run only when `w_pen` or `w_mob`
            /// is > 0.
            refine_physics_steps: u32,
            /// Sampler: `ddim` (default) or `ddpm` (NAP's; strided ancestral with fewer steps).
            /// The paper's sampler is `ddpm` with 1000 steps.
            sampler: String,
            /// DDIM noise level η in [0, 1] (default 0); only with `sampler` `ddim` (the
            /// default).
            eta: f64,
            /// Reverse steps, 1–1000 (default 200; 1000 is the full schedule).
            steps: u32,
            /// Seed of sample 0; absent = random, echoed in `request.seed`.
            seed: u64,
            /// Best-of-N samples (1–16).
            samples: u32,
            /// Seconds from submission until the job fails with `deadline-exceeded`.
            deadline_seconds: f64,
            /// Attach an x̂₀ preview to every this many steps' progress (0 = never).
            preview_every: u32,
            /// Marching-cubes resolution (8–128, default 32).
            resolution: u32,
            /// Replace part shapes by their nearest training code of the weights' codebook:
            /// `auto` (default: `empty` when the weights have a codebook, else `off`), `off`,
            /// `empty` (shapes that mesh empty), `all` (NAP's retrieval variant) or `category`
            /// (with a category: every part takes the nearest code of that category's training
            /// parts).
            retrieval: String,
            /// Classifier-free category guidance w in [0, 20] (jobs with a category only):
            /// ε̂ = ε̂(c) + w·(ε̂(c) − ε̂(∅)); 0 = plain conditioning. Default 0 for a
            /// scan-guided job (w = 2 completed scans further from the scanned object), 2
            /// without loss guidance (all weights 0).
            category_guidance: f64,
            /// Apply the category guidance only in reverse steps with diffusion time t below
            /// this, 1-1000; 1000 = every step, the default for a scan-guided job. Default 500
            /// without loss guidance (all weights 0): above t = 500 the guidance bought no
            /// category accuracy there, only larger objects with more parts, and those steps
            /// take one denoiser forward instead of two.
            category_guidance_below: u32,
            /// Joint motions of the result: `screw` (NAP: each joint keeps its rotation and
            /// translation ranges; URDF screws need a helper link) or `dominant` (each joint
            /// keeps only the wider range, in units of the model's feature scales: plain
            /// revolute and prismatic joints). Default `dominant`.
            joint_motion: String,
            /// Free-space loss weight ℓ_free (>= 0). Default: 15 (ℓ_pc's) with a camera; 0
            /// without one (a weight given without a camera is ignored).
            w_free: f64,
            /// Joint repair and part removal: `on` (default: hinges onto their part's edge or
            /// centre line, axes snapped to box axes, children attached, parts the scan does not
            /// allow removed (empty, in the cameras' free space, floating); listed in
            /// `object.json` and `ranking.json`) or `off` (the raw projection).
            repair: String,
            /// Scale hypothesis: `auto` (default: the scan is scaled so its box diagonal is the
            /// category's typical procedural size, at most ×/÷ 4, and the result scaled back),
            /// `off`, or a factor such as `"2.5"` (1/16–16).
            scale: String,
            /// The scan's frame: `canonical` (default: physnap's frame, +Z up, front −X, floor
            /// z = 0) or `auto` (any right-handed metric frame whose up is `up`: the floor, yaw
            /// and position are estimated at submission; `object.json`, the URDF's `world`
            /// link, the MJCF root and the GLB root node put the model back in the scan's
            /// frame).
            frame: String,
        }
    };
}
pub(crate) use request_knobs;

/// Defines [`JobInput`] from the knob list.
macro_rules! job_input {
    ($($(#[doc = $doc:literal])* $name:ident: $ty:ty,)*) => {
        /// A job request in transport-neutral form: every optional knob is `None` when not
        /// given. The knobs are [`request_knobs`]'s.
        #[derive(Debug, Clone, PartialEq, Default)]
        pub struct JobInput {
            /// The partial point cloud (required).
            pub points: Option<PointsInput>,
            $($(#[doc = $doc])* pub $name: Option<$ty>,)*
            /// Sensor position(s) the scan was taken from (object frame, metres).
            pub camera: Option<CameraInput>,
            /// The scan's up direction with `frame: auto` (default [0, 0, 1]).
            pub up: Option<[f64; 3]>,
            /// What the transport could not read (a value of the wrong type, undecodable
            /// base64), each field taken out of the input: [`validate`] lists these first and
            /// checks the rest.
            pub refused: Vec<Violation>,
        }
    };
}
request_knobs!(job_input);

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
/// 0 for `ddpm`), `steps` in 1..=schedule, `n_g ≤ schedule`, τ finite and > 0, 1..=max samples, a
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
    /// n_g, as in the paper and the engine: the reverse steps with diffusion time t < n_g are
    /// guided (0..=schedule).
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

mod check;
pub use check::{Violations, validate};

#[cfg(test)]
mod tests;
