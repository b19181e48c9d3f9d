//! Wire types of the job API (JSON, with OpenAPI schemas) and their conversions.
//!
//! Why it exists: the JSON documents (the job, its progress, events, problems, the request) are
//! shared by REST responses, SSE `data:` lines and the gRPC messages' `json` fields, so they are
//! defined once, here, next to the `utoipa` schemas that `openapi.yaml` is generated from.
//! Nothing outside `src/service` sees these types; requests become a domain
//! [`JobInput`](super::spec::JobInput) before validation.

use base64::Engine as _;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::runner::{Preview, Progress};
use super::spec::{CameraInput, JobInput, JobSpec, PointsInput, Violation, request_knobs};
use super::store::{Artifact, JobRecord};

/// Defines the REST request types from the knob list ([`request_knobs`]): the JSON body
/// [`JobRequest`] and the query parameters of a raw upload [`UploadParams`], with their
/// conversions into a [`JobInput`].
macro_rules! wire_requests {
    ($($(#[doc = $doc:literal])* $name:ident: $ty:ty,)*) => {
        /// A job request (`POST /v1/jobs`, `application/json`). Give the point cloud in exactly
        /// one of `points`, `points_f32le_base64`, `points_ply_base64`, `points_npy_base64`.
        ///
        /// The cloud (16–100 000 finite points) guides the sampler (PhysNAP loss guidance:
        /// ℓ_pc, ℓ_pen, ℓ_mob with weights `w_pc`, `w_pen`, `w_mob` in the steps with
        /// diffusion time t < `n_g`, temperature `tau`; with a `camera`, also the free-space
        /// loss ℓ_free at `w_free`); with every weight 0 the job samples unguided. Best-of-N
        /// samples are ranked by one score (D_pc, free space, attachment, overlaps; listed in
        /// `ranking.json`) and the best one is exported.
        #[derive(Debug, Clone, Default, Deserialize, Serialize, ToSchema)]
        #[serde(deny_unknown_fields)]
        pub struct JobRequest {
            /// `[[x, y, z], ...]`, object frame, metres.
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub points: Option<Vec<[f64; 3]>>,
            /// Base64 of little-endian f32 triples.
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub points_f32le_base64: Option<String>,
            /// Base64 of a PLY file (any PLY encoding).
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub points_ply_base64: Option<String>,
            /// Base64 of a NumPy `(N, 3)` float array.
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub points_npy_base64: Option<String>,
            $(
                $(#[doc = $doc])*
                #[serde(
                    default,
                    skip_serializing_if = "Option::is_none",
                    deserialize_with = "knob::opt"
                )]
                pub $name: Option<$ty>,
            )*
            /// Sensor position(s) the scan was taken from (object frame, metres): one
            /// `[x, y, z]` or a list `[[x, y, z], ...]` of at most 16, each 3 finite numbers
            /// with |coordinate| <= 1000, outside the axis-aligned box of the points. Turns on
            /// the free-space loss ℓ_free (weight `w_free`) and, with `repair` on, the removal
            /// of parts in space the cameras saw through.
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub camera: Option<CameraRequest>,
            /// The scan's up direction with `frame: auto`, `[x, y, z]` (default `[0, 0, 1]`).
            #[serde(default, skip_serializing_if = "Option::is_none")]
            pub up: Option<[f64; 3]>,
        }

        /// Query parameters of a raw upload (`POST /v1/jobs` with a PLY, NPY or f32le body):
        /// the same knobs as [`JobRequest`] without the points.
        #[derive(Debug, Clone, Default, Deserialize, ToSchema, utoipa::IntoParams)]
        #[serde(deny_unknown_fields)]
        #[into_params(parameter_in = Query)]
        pub struct UploadParams {
            $(
                $(#[doc = $doc])*
                #[serde(default, deserialize_with = "knob::opt")]
                pub $name: Option<$ty>,
            )*
            /// Sensor position `x,y,z` (object frame, metres); repeat the parameter for several
            /// (at most 16).
            #[serde(default)]
            #[param(style = Form, explode)]
            pub camera: Vec<String>,
            /// The scan's up direction `x,y,z` with `frame=auto` (default `0,0,1`).
            pub up: Option<String>,
        }

        impl JobRequest {
            /// Into the domain input, with what could not be read taken out and listed in
            /// [`JobInput::refused`] (undecodable base64; more than one points field, reported
            /// as `points` violating "exactly one of ..."), so that validation can still check
            /// the rest.
            pub fn into_input(mut self) -> JobInput {
                let (points, refused) = self.points_input();
                JobInput {
                    refused,
                    points,
                    $($name: self.$name,)*
                    camera: self.camera.map(CameraInput::from),
                    up: self.up,
                }
            }
        }

        impl UploadParams {
            /// Into the domain input with the uploaded cloud. One `camera` parameter is named
            /// `camera` in errors, the j-th of several `camera[j]`. What could not be read
            /// (cameras, `up`) is taken out and listed in [`JobInput::refused`], so that
            /// validation can still check the rest.
            pub fn into_input(self, points: PointsInput) -> JobInput {
                let (camera, up, refused) = self.camera_and_up();
                JobInput {
                    refused,
                    points: Some(points),
                    $($name: self.$name,)*
                    camera,
                    up,
                }
            }
        }
    };
}
request_knobs!(wire_requests);

/// `camera` of a [`JobRequest`]: one sensor position or a list of them. Its OpenAPI schema is
/// written out below (the derive cannot say "3 numbers").
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum CameraRequest {
    /// One sensor position `[x, y, z]`.
    One(Vec<f64>),
    /// Several, `[[x, y, z], ...]`.
    Many(Vec<Vec<f64>>),
}

impl utoipa::PartialSchema for CameraRequest {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        use utoipa::openapi::schema::{
            ArrayBuilder, KnownFormat, ObjectBuilder, OneOfBuilder, SchemaFormat, Type,
        };
        let triple = || {
            ArrayBuilder::new()
                .items(
                    ObjectBuilder::new()
                        .schema_type(Type::Number)
                        .format(Some(SchemaFormat::KnownFormat(KnownFormat::Double))),
                )
                .min_items(Some(3))
                .max_items(Some(3))
        };
        OneOfBuilder::new()
            .item(triple().description(Some("One sensor position `[x, y, z]` (metres).")))
            .item(
                ArrayBuilder::new()
                    .items(triple())
                    .max_items(Some(super::spec::MAX_CAMERAS))
                    .description(Some(
                        "Several sensor positions `[[x, y, z], ...]` (metres; at most 16).",
                    )),
            )
            .description(Some(
                "Sensor position(s) of a job: one `[x, y, z]` or a list of them.",
            ))
            .into()
    }
}

impl ToSchema for CameraRequest {}

impl From<CameraRequest> for CameraInput {
    fn from(c: CameraRequest) -> Self {
        match c {
            // `[]` is the empty list: no camera.
            CameraRequest::One(t) if t.is_empty() => CameraInput::Many(Vec::new()),
            CameraRequest::One(t) => CameraInput::One(t),
            CameraRequest::Many(l) => CameraInput::Many(l),
        }
    }
}

impl JobRequest {
    /// The one points field given, decoded, and what was refused: undecodable base64, or more
    /// than one points field (reported as `points` violating "exactly one of ...").
    fn points_input(&mut self) -> (Option<PointsInput>, Vec<Violation>) {
        let mut refused = Vec::new();
        let mut b64 = |field: &'static str, s: &str| {
            base64::engine::general_purpose::STANDARD
                .decode(s.trim())
                .map_err(|e| {
                    refused.push(Violation {
                        field: field.into(),
                        limit: "valid base64".into(),
                        value: e.to_string(),
                    })
                })
                .ok()
        };
        let mut given = Vec::new();
        if let Some(p) = self.points.take() {
            given.push(Some(PointsInput::Triples(p)));
        }
        if let Some(s) = &self.points_f32le_base64 {
            given.push(b64("points_f32le_base64", s).map(PointsInput::F32Le));
        }
        if let Some(s) = &self.points_ply_base64 {
            given.push(b64("points_ply_base64", s).map(PointsInput::Ply));
        }
        if let Some(s) = &self.points_npy_base64 {
            given.push(b64("points_npy_base64", s).map(PointsInput::Npy));
        }
        if given.len() > 1 {
            refused.push(Violation {
                field: "points".into(),
                limit: "exactly one of points, points_f32le_base64, points_ply_base64, points_npy_base64".into(),
                value: format!("{} given", given.len()),
            });
            given.clear();
        }
        (given.pop().flatten(), refused)
    }
}

/// A `camera` query value, `x,y,z`, as numbers (their count and range are checked in
/// validation).
fn camera_of_query(field: String, text: &str) -> Result<Vec<f64>, Violation> {
    text.split(',')
        .map(|c| c.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| Violation {
            field,
            limit: "x,y,z: 3 finite numbers (object frame, metres)".into(),
            value: format!("{text:?}"),
        })
}

impl UploadParams {
    /// The `camera` and `up` parameters read, and those that could not be read.
    fn camera_and_up(&self) -> (Option<CameraInput>, Option<[f64; 3]>, Vec<Violation>) {
        let mut refused = Vec::new();
        let mut keep = |r: Result<Vec<f64>, Violation>| r.map_err(|v| refused.push(v)).ok();
        let camera = match self.camera.as_slice() {
            [] => None,
            [one] => keep(camera_of_query("camera".into(), one)).map(CameraInput::One),
            many => {
                let read: Vec<Option<Vec<f64>>> = many
                    .iter()
                    .enumerate()
                    .map(|(j, c)| keep(camera_of_query(format!("camera[{j}]"), c)))
                    .collect();
                read.into_iter()
                    .collect::<Option<Vec<_>>>()
                    .map(CameraInput::Many)
            }
        };
        let up = self
            .up
            .as_deref()
            .and_then(|u| parse_up(u).map_err(|v| refused.push(v)).ok());
        (camera, up, refused)
    }
}

/// The scan's frame a job ran with (`frame: auto`): scan → canonical, p_c = Rz(yaw) U(up) p_s
/// + translation, U the smallest rotation taking `up` to +Z.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct FrameView {
    /// `auto`.
    pub mode: String,
    /// The scan's up direction (unit).
    pub up: [f64; 3],
    /// Yaw about +Z after up was turned onto it, degrees in [0, 360).
    pub yaw_degrees: f64,
    /// Translation (metres, canonical frame).
    pub translation: [f64; 3],
}

/// An `up` query value, `x,y,z`, as numbers (the engine checks they are finite and not all 0).
fn parse_up(v: &str) -> Result<[f64; 3], Violation> {
    crate::frame::parse_xyz(v).ok_or_else(|| Violation {
        field: "up".into(),
        limit: "x,y,z: three numbers".into(),
        value: format!("{v:?}"),
    })
}

/// The validated request, echoed back (seed always set).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct RequestView {
    /// Category, canonical spelling.
    pub category: Option<String>,
    /// Point count.
    pub point_count: usize,
    /// Point-cloud loss weight.
    pub w_pc: f64,
    /// Penetration loss weight.
    pub w_pen: f64,
    /// Mobility loss weight.
    pub w_mob: f64,
    /// n_g: the steps with diffusion time t < n_g were guided.
    pub n_g: u32,
    /// Temperature τ of ℓ_pc.
    pub tau: f64,
    /// Guidance-gradient clamp (absent: off, the paper's raw gradient).
    pub guidance_max_step: Option<f64>,
    /// Refinement steps after sampling (0: off).
    pub refine_steps: u32,
    /// Physics-only refinement steps after the refinement steps (0: off; they run only when
    /// `w_pen` or `w_mob` is > 0).
    pub refine_physics_steps: u32,
    /// Sampler.
    pub sampler: String,
    /// DDIM η (0 for `ddpm`).
    pub eta: f64,
    /// Diffusion steps.
    pub steps: u32,
    /// Seed of sample 0.
    pub seed: u64,
    /// Best-of-N.
    pub samples: u32,
    /// Deadline (s from submission).
    pub deadline_seconds: f64,
    /// Preview period.
    pub preview_every: u32,
    /// Meshing resolution.
    pub resolution: u32,
    /// Codebook retrieval as run: `off`, `empty`, `all` or `category` (`auto` resolved).
    pub retrieval: String,
    /// Classifier-free category guidance w as run (0 without a category).
    pub category_guidance: f64,
    /// The category guidance applied at diffusion time t below this (1000: every step).
    pub category_guidance_below: u32,
    /// Joint motions as run: `screw` or `dominant`.
    pub joint_motion: String,
    /// Sensor positions as run (object frame, metres; empty: none).
    #[serde(default)]
    pub camera: Vec<[f32; 3]>,
    /// Free-space loss weight as run (0 without a camera).
    #[serde(default)]
    pub w_free: f64,
    /// Joint repair and part removal as run: `on` or `off`.
    #[serde(default = "repair_off")]
    pub repair: String,
    /// The scale hypothesis as run (absent: none, the scan as given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
    /// The scan's frame as run (absent: canonical input).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<FrameView>,
    /// Whether guidance is applied (some weight > 0, ℓ_free's with a camera); false = plain NAP
    /// sampling.
    pub guided: bool,
}

/// The repair of a job view written before repair could be chosen (stored `state` events).
fn repair_off() -> String {
    crate::engine::generate::RepairMode::Off.as_str().into()
}

/// A part box of a preview.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct PreviewPartView {
    /// Part name.
    pub name: String,
    /// Box centre (m).
    pub center: [f64; 3],
    /// Half-extents (m).
    pub half_extents: [f64; 3],
}

/// A joint of a preview.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct PreviewJointView {
    /// Parent part index.
    pub parent: usize,
    /// Child part index.
    pub child: usize,
    /// Joint kind.
    pub kind: String,
    /// Unit axis.
    pub axis: [f64; 3],
    /// A point on the axis.
    pub origin: [f64; 3],
}

/// The projected x̂₀ of a step.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct PreviewView {
    /// Part boxes.
    pub parts: Vec<PreviewPartView>,
    /// Joints.
    pub joints: Vec<PreviewJointView>,
}

/// Progress of a running job.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ProgressView {
    /// `denoising`, `meshing` or `exporting`.
    pub phase: String,
    /// Sample being drawn (0-based).
    pub sample: u32,
    /// Samples in the job.
    pub samples: u32,
    /// 1-based step within the sample.
    pub step: u32,
    /// Steps per sample.
    pub total_steps: u32,
    /// Diffusion time index.
    pub t: u32,
    /// Estimated seconds left.
    pub eta_seconds: Option<f64>,
    /// x̂₀ preview (every `preview_every` steps).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preview: Option<PreviewView>,
    /// Guidance loss values of this step (guided steps only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub guidance: Option<GuidanceLossesView>,
}

/// Loss values of one guided step (unweighted terms and the weighted total).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct GuidanceLossesView {
    /// ℓ_pc.
    pub l_pc: f64,
    /// ℓ_pen.
    pub l_pen: f64,
    /// ℓ_mob.
    pub l_mob: f64,
    /// ℓ_free (0 without a camera).
    #[serde(default)]
    pub l_free: f64,
    /// w_pc ℓ_pc + w_pen ℓ_pen + w_mob ℓ_mob + w_free ℓ_free.
    pub total: f64,
}

/// A committed artefact.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ArtifactView {
    /// File name.
    pub name: String,
    /// Media type.
    pub media_type: String,
    /// Size.
    pub size_bytes: u64,
    /// Hex sha256.
    pub sha256: String,
    /// Download path.
    pub href: String,
}

/// Why a job failed or was cancelled.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct JobErrorView {
    /// `deadline-exceeded`, `cancelled`, `engine`, `internal`.
    #[serde(rename = "type")]
    pub error_type: String,
    /// Detail.
    pub detail: String,
}

/// A job.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct JobView {
    /// UUIDv7.
    pub id: String,
    /// `jobs/{id}`.
    pub name: String,
    /// `QUEUED`, `RUNNING`, `SUCCEEDED`, `FAILED`, `CANCELLED`.
    pub state: String,
    /// Runs started (2 after a re-run following a restart).
    pub attempt: u32,
    /// Sequence of the last persisted event.
    pub sequence: u64,
    /// Unix ms.
    pub create_time_ms: i64,
    /// Unix ms.
    pub start_time_ms: Option<i64>,
    /// Unix ms.
    pub end_time_ms: Option<i64>,
    /// Unix ms.
    pub deadline_ms: i64,
    /// Cancellation was requested and takes effect at the next step.
    pub cancel_requested: bool,
    /// The validated request.
    pub request: RequestView,
    /// Latest progress (running jobs).
    pub progress: Option<ProgressView>,
    /// Set when FAILED or CANCELLED.
    pub error: Option<JobErrorView>,
    /// Set when SUCCEEDED.
    pub artifacts: Vec<ArtifactView>,
}

/// A page of jobs.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct JobList {
    /// Oldest first.
    pub jobs: Vec<JobView>,
    /// Opaque; absent on the last page.
    pub next_page_token: Option<String>,
}

/// RFC 9457 problem details.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct Problem {
    /// `/problems/<kind>`.
    #[serde(rename = "type")]
    pub problem_type: String,
    /// Short summary.
    pub title: String,
    /// HTTP status.
    pub status: u16,
    /// What is wrong, naming field, limit and value for validation errors.
    pub detail: String,
    /// The request path.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instance: Option<String>,
    /// Every field the request got wrong (type, limit or combination), in field order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub errors: Vec<FieldError>,
    /// Seconds to wait before retrying (429, 503).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub retry_after_seconds: Option<u64>,
}

/// One field violation.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct FieldError {
    /// JSON pointer of the field (`/points/3/1`).
    pub pointer: String,
    /// The field's path as named in messages (`points[3][1]`).
    pub field: String,
    /// The rule.
    pub limit: String,
    /// The value given.
    pub value: String,
    /// Sentence.
    pub detail: String,
}

/// Media type of an artefact name.
pub fn media_type(name: &str) -> &'static str {
    match name {
        "model.glb" => "model/gltf-binary",
        "robot.zip" => "application/zip",
        "model.xml" => "application/xml",
        "object.json" | "ranking.json" => "application/json",
        _ => "application/octet-stream",
    }
}

/// The artefacts a job produces.
pub const ARTIFACT_NAMES: [&str; 5] = [
    "model.glb",
    "model.xml",
    "robot.zip",
    "object.json",
    "ranking.json",
];

/// Request echo of a spec.
pub fn request_view(s: &JobSpec) -> RequestView {
    RequestView {
        category: s.category.as_ref().map(|c| c.1.clone()),
        point_count: s.points.len(),
        w_pc: s.w_pc,
        w_pen: s.w_pen,
        w_mob: s.w_mob,
        n_g: s.n_g,
        tau: s.tau,
        guidance_max_step: s.guidance_max_step,
        refine_steps: s.refine_steps,
        refine_physics_steps: s.refine_physics_steps,
        sampler: s.sampler.name().to_string(),
        eta: s.sampler.eta(),
        steps: s.steps,
        seed: s.seed,
        samples: s.samples,
        deadline_seconds: s.deadline_seconds,
        preview_every: s.preview_every,
        resolution: s.resolution,
        retrieval: s.retrieval.as_str().to_string(),
        category_guidance: s.category_guidance,
        category_guidance_below: s.category_guidance_below,
        joint_motion: s.joint_motion.as_str().to_string(),
        camera: s.cameras.clone(),
        w_free: s.w_free,
        repair: s.repair.as_str().to_string(),
        scale: s.scale,
        frame: s.frame.map(|f| FrameView {
            mode: "auto".into(),
            up: f.up.into(),
            yaw_degrees: f.yaw.to_degrees(),
            translation: f.translation.into(),
        }),
        guided: s.guided(),
    }
}

fn preview_view(p: &Preview) -> PreviewView {
    PreviewView {
        parts: p
            .parts
            .iter()
            .map(|q| PreviewPartView {
                name: q.name.clone(),
                center: q.center,
                half_extents: q.half_extents,
            })
            .collect(),
        joints: p
            .joints
            .iter()
            .map(|j| PreviewJointView {
                parent: j.parent,
                child: j.child,
                kind: j.kind.to_string(),
                axis: j.axis,
                origin: j.origin,
            })
            .collect(),
    }
}

/// Wire form of progress.
pub fn progress_view(p: &Progress) -> ProgressView {
    ProgressView {
        phase: p.phase.as_str().to_string(),
        sample: p.sample,
        samples: p.samples,
        step: p.step,
        total_steps: p.total_steps,
        t: p.t,
        eta_seconds: p.eta_seconds,
        preview: p.preview.as_ref().map(preview_view),
        guidance: p.guidance.map(|l| GuidanceLossesView {
            l_pc: l.pc,
            l_pen: l.pen,
            l_mob: l.mob,
            l_free: l.free,
            total: l.total,
        }),
    }
}

/// The progress a [`ProgressView`] shows (without its preview), for progress that reached this
/// process as JSON from another one. `None` for an unknown phase.
pub fn progress_of_view(v: &ProgressView) -> Option<Progress> {
    use super::runner::Phase;
    let phase = [Phase::Denoising, Phase::Meshing, Phase::Exporting]
        .into_iter()
        .find(|p| p.as_str() == v.phase)?;
    Some(Progress {
        phase,
        sample: v.sample,
        samples: v.samples,
        step: v.step,
        total_steps: v.total_steps,
        t: v.t,
        eta_seconds: v.eta_seconds,
        preview: None,
        guidance: v
            .guidance
            .as_ref()
            .map(|g| crate::engine::guidance::GuidanceLosses {
                pc: g.l_pc,
                pen: g.l_pen,
                mob: g.l_mob,
                free: g.l_free,
                total: g.total,
                grad_max: 0.0,
            }),
    })
}

/// Wire form of an artefact of job `id`.
pub fn artifact_view(id: &str, a: &Artifact) -> ArtifactView {
    ArtifactView {
        name: a.name.clone(),
        media_type: media_type(&a.name).to_string(),
        size_bytes: a.size_bytes,
        sha256: a.sha256.clone(),
        href: format!("/v1/jobs/{id}/artifacts/{}", a.name),
    }
}

/// Wire form of a job.
pub fn job_view(r: &JobRecord, progress: Option<&Progress>, cancel_requested: bool) -> JobView {
    JobView {
        id: r.id.clone(),
        name: format!("jobs/{}", r.id),
        state: r.state.as_str().to_string(),
        attempt: r.attempt,
        sequence: r.sequence,
        create_time_ms: r.created_ms,
        start_time_ms: r.started_ms,
        end_time_ms: r.ended_ms,
        deadline_ms: r.deadline_ms,
        cancel_requested: cancel_requested && !r.state.is_terminal(),
        request: request_view(&r.spec),
        progress: if r.state.is_terminal() {
            None
        } else {
            progress.map(progress_view)
        },
        error: r.failure.as_ref().map(|f| JobErrorView {
            error_type: f.error_type.clone(),
            detail: f.detail.clone(),
        }),
        artifacts: r
            .artifacts
            .iter()
            .map(|a| artifact_view(&r.id, a))
            .collect(),
    }
}

/// Integer fields as JSON Schema reads them: an integer is any number with no fractional part,
/// so `2567.0` is the integer 2567 (and a query string's `"2567.0"` too). Fractions, negatives
/// and values beyond the type are refused with serde's usual type error.
/// The deserialiser of every knob field: a knob's type picks how it is read ([`knob::Knob`]).
pub(crate) mod knob {
    use serde::{Deserialize, Deserializer};

    /// A knob's value type.
    pub trait Knob: Sized {
        /// `Option<Self>` from JSON or a query value (`null` is `None`).
        fn read<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Self>, D::Error>;
    }

    impl Knob for f64 {
        fn read<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Self>, D::Error> {
            Option::<f64>::deserialize(d)
        }
    }

    impl Knob for String {
        fn read<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Self>, D::Error> {
            Option::<String>::deserialize(d)
        }
    }

    /// Integers also from an integral float or a string ([`super::integral`]).
    impl Knob for u32 {
        fn read<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Self>, D::Error> {
            super::integral::opt_u32(d)
        }
    }

    impl Knob for u64 {
        fn read<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Self>, D::Error> {
            super::integral::opt_u64(d)
        }
    }

    /// `deserialize_with` of a knob field.
    pub fn opt<'de, D: Deserializer<'de>, T: Knob>(d: D) -> Result<Option<T>, D::Error> {
        T::read(d)
    }
}

pub(crate) mod integral {
    use serde::de::{self, Deserializer, Visitor};
    use std::fmt;
    use std::marker::PhantomData;

    /// Largest float that still holds every integer exactly (2^53).
    const EXACT: f64 = 9_007_199_254_740_992.0;

    struct V<T>(PhantomData<T>);

    impl<'de, T: TryFrom<u64>> Visitor<'de> for V<T> {
        type Value = Option<T>;
        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            write!(f, "a non-negative integer no larger than {}", max::<T>())
        }
        fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
            d.deserialize_any(self)
        }
        fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
            T::try_from(v)
                .map(Some)
                .map_err(|_| E::invalid_value(de::Unexpected::Unsigned(v), &self))
        }
        fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
            u64::try_from(v)
                .map_err(|_| E::invalid_value(de::Unexpected::Signed(v), &self))
                .and_then(|u| self.visit_u64(u))
        }
        fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
            if v.fract() == 0.0 && (0.0..=EXACT).contains(&v) {
                self.visit_u64(v as u64)
            } else {
                Err(E::invalid_value(de::Unexpected::Float(v), &self))
            }
        }
        fn visit_str<E: de::Error>(self, v: &str) -> Result<Self::Value, E> {
            if let Ok(u) = v.parse::<u64>() {
                return self.visit_u64(u);
            }
            match v.parse::<f64>() {
                Ok(f) if f.is_finite() => self.visit_f64(f),
                _ => Err(E::invalid_value(de::Unexpected::Str(v), &self)),
            }
        }
    }

    fn max<T: TryFrom<u64>>() -> u64 {
        // The largest u64 that fits T (u32 or u64 here).
        if T::try_from(u64::MAX).is_ok() {
            u64::MAX
        } else {
            u32::MAX as u64
        }
    }

    /// `Option<u32>` from an integer, an integral float or a string of either.
    pub fn opt_u32<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u32>, D::Error> {
        d.deserialize_option(V::<u32>(PhantomData))
    }

    /// `Option<u64>` from an integer, an integral float or a string of either.
    pub fn opt_u64<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u64>, D::Error> {
        d.deserialize_option(V::<u64>(PhantomData))
    }
}
