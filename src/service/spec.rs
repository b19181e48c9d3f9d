//! The domain job: a validated [`JobSpec`] and the limits it is checked against.
//!
//! Why it exists: REST and gRPC both accept a job in their own wire format; both hand a
//! transport-neutral [`JobInput`] to [`validate`], which is the only way to get a [`JobSpec`].
//! The runner (and through it the engine) only ever sees a `JobSpec`, so every invariant below
//! holds for every job that is stored or run. Each rejection is a [`Violation`] naming the
//! field, the limit and the offending value, which both transports render (problem+json /
//! `INVALID_ARGUMENT`).

use crate::data::categories::category_index;
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
    /// Guidance gradient steps per diffusion step.
    pub n_g: Option<u32>,
    /// Guidance is applied for diffusion time t < τ.
    pub tau: Option<u32>,
    /// Sampler name.
    pub sampler: Option<String>,
    /// Diffusion steps.
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
}

/// The only sampler the engine has today (full 1000-step DDPM).
pub const SAMPLER_DDPM: &str = "ddpm";

/// Limits of a job; the service's flags can tighten them.
#[derive(Debug, Clone, PartialEq)]
pub struct Limits {
    /// Fewest points.
    pub min_points: usize,
    /// Most points.
    pub max_points: usize,
    /// Largest loss weight.
    pub max_weight: f64,
    /// Most guidance steps per diffusion step.
    pub max_n_g: u32,
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
            max_n_g: 100,
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
}

/// A validated job. Invariants: 16..=100k finite points (per [`Limits`]), a known category for
/// a conditional model, finite non-negative weights, `sampler == "ddpm"`, `steps` equal to the
/// schedule, `τ ≤ steps`, 1..=max samples, a positive finite deadline.
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
    /// Guidance gradient steps per diffusion step.
    pub n_g: u32,
    /// Guidance applies for t < τ.
    pub tau: u32,
    /// Sampler name.
    pub sampler: String,
    /// Diffusion steps.
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

fn weight(field: &str, v: Option<f64>, limits: &Limits) -> Result<f64, Violation> {
    let v = v.unwrap_or(0.0);
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
    let w_pc = weight("w_pc", input.w_pc, limits)?;
    let w_pen = weight("w_pen", input.w_pen, limits)?;
    let w_mob = weight("w_mob", input.w_mob, limits)?;
    let n_g = input.n_g.unwrap_or(1);
    if n_g > limits.max_n_g {
        return Err(violation("n_g", format!("<= {}", limits.max_n_g), n_g));
    }
    let sampler = input
        .sampler
        .clone()
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| SAMPLER_DDPM.to_string());
    if sampler != SAMPLER_DDPM {
        return Err(violation(
            "sampler",
            format!("\"{SAMPLER_DDPM}\" (the only sampler of this engine)"),
            format!("{sampler:?}"),
        ));
    }
    let steps = input.steps.unwrap_or(caps.schedule_steps);
    if steps != caps.schedule_steps {
        return Err(violation(
            "steps",
            format!(
                "{} (the DDPM schedule the weights were trained with)",
                caps.schedule_steps
            ),
            steps,
        ));
    }
    let tau = input.tau.unwrap_or(steps / 2);
    if tau > steps {
        return Err(violation("tau", format!("<= steps ({steps})"), tau));
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
    Ok(JobSpec {
        points,
        category,
        w_pc,
        w_pen,
        w_mob,
        n_g,
        tau,
        sampler,
        steps,
        seed: input.seed.unwrap_or(random_seed),
        samples,
        deadline_seconds,
        preview_every,
        resolution,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn caps() -> ModelCaps {
        ModelCaps {
            categories: vec!["Door".into(), "Window".into()],
            conditional: true,
            schedule_steps: 1000,
        }
    }

    fn cloud(n: usize) -> PointsInput {
        PointsInput::Triples((0..n).map(|i| [i as f64, 0.0, 1.0]).collect())
    }

    #[test]
    fn accepts_defaults_and_materialises_the_seed() {
        let input = JobInput {
            points: Some(cloud(16)),
            ..Default::default()
        };
        let s = validate(&input, &caps(), &Limits::default(), 77).unwrap();
        assert_eq!((s.seed, s.samples, s.steps, s.tau), (77, 1, 1000, 500));
        assert_eq!(s.points.len(), 16);
    }

    #[test]
    fn each_limit_names_field_limit_and_value() {
        let l = Limits::default();
        let bad = |f: &dyn Fn(&mut JobInput)| {
            let mut i = JobInput {
                points: Some(cloud(20)),
                ..Default::default()
            };
            f(&mut i);
            validate(&i, &caps(), &l, 0).unwrap_err()
        };
        let v = bad(&|i| i.points = Some(cloud(15)));
        assert_eq!(
            (v.field.as_str(), v.value.as_str()),
            ("points", "15 points")
        );
        assert!(v.limit.contains("16..=100000"));
        let v = bad(&|i| i.w_pen = Some(-1.0));
        assert_eq!((v.field.as_str(), v.value.as_str()), ("w_pen", "-1"));
        assert!(v.limit.contains(">= 0"));
        let v = bad(&|i| i.category = Some("Spaceship".into()));
        assert_eq!(v.field, "category");
        assert!(v.limit.contains("Door, Window"), "{v}");
        let mut flat = vec![0.5f32; 60];
        flat[4] = f32::NAN;
        let v = bad(&|i| i.points = Some(PointsInput::Flat(flat.clone())));
        assert_eq!(
            (v.field.as_str(), v.limit.as_str()),
            ("points[1][1]", "finite")
        );
        let v = bad(&|i| i.samples = Some(0));
        assert_eq!(v.field, "samples");
        let v = bad(&|i| i.steps = Some(50));
        assert_eq!((v.field.as_str(), v.value.as_str()), ("steps", "50"));
        let v = bad(&|i| i.points = Some(PointsInput::F32Le(vec![0; 13])));
        assert!(v.limit.contains("multiple of 12"));
        let v = bad(&|i| i.points = Some(PointsInput::Ply(b"ply\nformat nonsense\n".to_vec())));
        assert_eq!(v.field, "points");
        assert!(v.value.contains("PLY"), "{v}");
    }
}
