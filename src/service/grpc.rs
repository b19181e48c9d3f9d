//! The gRPC adapter (tonic): `physnap.v1.JobService` over the same [`Service`] as REST.
//!
//! Why it exists: scripts and notebooks that prefer typed streaming use gRPC; this module maps
//! the proto messages onto [`JobInput`] and [`ServiceError`]s onto status codes once
//! (`INVALID_ARGUMENT` carries the same "field, limit, value" message as the REST problem, plus
//! `physnap-field` / `physnap-limit` / `physnap-value` metadata; a full queue is
//! `RESOURCE_EXHAUSTED` with `retry-after` metadata). `WatchJob` resumes by sequence like SSE;
//! `GetArtifact` streams 1 MiB chunks and puts the sha256 on the last one.

use std::pin::Pin;
use std::sync::Arc;

use sha2::{Digest, Sha256};
use tokio_stream::wrappers::ReceiverStream;
use tokio_stream::{Stream, StreamExt as _};
use tonic::metadata::MetadataValue;
use tonic::{Request, Response, Status};

use super::api::{ARTIFACT_NAMES, JobView};
use super::auth::Tenants;
use super::jobs::{DEFAULT_PAGE_SIZE, Service, ServiceError, WatchItem};
use super::spec::{CameraInput, JobInput, PointsInput, request_knobs};

/// Generated protobuf and tonic code for `proto/physnap/v1/jobs.proto`.
#[allow(missing_docs, clippy::all)]
pub mod pb {
    tonic::include_proto!("physnap.v1");

    /// Encoded descriptor set of the proto (for reflection).
    pub const FILE_DESCRIPTOR_SET: &[u8] =
        include_bytes!(concat!(env!("OUT_DIR"), "/physnap_v1_descriptor.bin"));
}

use pb::job_service_server::JobService;

/// Chunk size of `GetArtifact`.
pub const CHUNK_BYTES: usize = 1 << 20;

/// The tonic service.
#[derive(Clone)]
pub struct GrpcJobs {
    /// The job service.
    pub svc: Arc<Service>,
    /// Token table.
    pub tenants: Arc<Tenants>,
    /// Largest `SubmitJob` message (the REST body limit). tonic itself refuses only messages
    /// past [`DECODE_LIMIT_FACTOR`] times this, so oversize submissions up to there are
    /// answered with physnap's metadata.
    pub max_message_bytes: usize,
}

/// tonic's own decoding limit, as a multiple of [`GrpcJobs::max_message_bytes`].
pub const DECODE_LIMIT_FACTOR: usize = 4;

/// gRPC status of a service error.
pub fn status_of(e: ServiceError) -> Status {
    let msg = e.to_string();
    let mut s = match &e {
        ServiceError::Invalid(_)
        | ServiceError::Malformed(_)
        | ServiceError::UnsupportedMediaType { .. } => Status::invalid_argument(msg),
        ServiceError::QueueFull { .. } => Status::resource_exhausted(msg),
        ServiceError::ShuttingDown { .. } => Status::unavailable(msg),
        ServiceError::NotFound(_) | ServiceError::NoRoute => Status::not_found(msg),
        ServiceError::Conflict { .. } => Status::failed_precondition(msg),
        ServiceError::IdempotencyReused { .. } => Status::already_exists(msg),
        ServiceError::Unauthenticated(_) => Status::unauthenticated(msg),
        ServiceError::TooLarge { .. } => Status::out_of_range(msg),
        ServiceError::Store(_) | ServiceError::Internal(_) => {
            tracing::error!(error = %e, "gRPC request failed");
            Status::internal("internal error; see the server log")
        }
    };
    let md = s.metadata_mut();
    if let Ok(v) = MetadataValue::try_from(e.error_type()) {
        md.insert("physnap-error-type", v);
    }
    match &e {
        // One field/limit/value triple per violation, in order (`get` reads the first,
        // `get_all` every one); text that is not visible ASCII is escaped so the triples stay
        // aligned.
        ServiceError::Invalid(all) => {
            for v in all.iter() {
                for (k, val) in [
                    ("physnap-field", &v.field),
                    ("physnap-limit", &v.limit),
                    ("physnap-value", &v.value),
                ] {
                    let ascii: String = val
                        .chars()
                        .map(|c| match c {
                            ' '..='~' => c.to_string(),
                            c => c.escape_unicode().to_string(),
                        })
                        .collect();
                    if let Ok(m) = MetadataValue::try_from(ascii.as_str()) {
                        md.append(k, m);
                    }
                }
            }
        }
        ServiceError::TooLarge { limit, size } => {
            md.insert("physnap-field", MetadataValue::from_static("message"));
            if let Ok(m) = MetadataValue::try_from(format!("<= {limit} bytes")) {
                md.insert("physnap-limit", m);
            }
            if let Some(Ok(m)) = size.map(|n| MetadataValue::try_from(format!("{n} bytes"))) {
                md.insert("physnap-value", m);
            }
        }
        ServiceError::QueueFull { retry_after, .. }
        | ServiceError::ShuttingDown { retry_after } => {
            if let Ok(m) = MetadataValue::try_from(retry_after.to_string()) {
                md.insert("retry-after", m);
            }
        }
        _ => {}
    }
    s
}

fn state_of(s: &str) -> pb::State {
    match s {
        "QUEUED" => pb::State::Queued,
        "RUNNING" => pb::State::Running,
        "SUCCEEDED" => pb::State::Succeeded,
        "FAILED" => pb::State::Failed,
        "CANCELLED" => pb::State::Cancelled,
        _ => pb::State::Unspecified,
    }
}

fn job_msg(j: &JobView) -> pb::Job {
    pb::Job {
        id: j.id.clone(),
        state: state_of(&j.state) as i32,
        json: serde_json::to_string(j).unwrap_or_default(),
        sequence: j.sequence,
        attempt: j.attempt,
        error_type: j
            .error
            .as_ref()
            .map(|e| e.error_type.clone())
            .unwrap_or_default(),
        error_detail: j
            .error
            .as_ref()
            .map(|e| e.detail.clone())
            .unwrap_or_default(),
    }
}

/// A proto field as a knob of [`JobInput`]: proto3 `optional` scalars are `Option`s already,
/// and an empty `string` is "not given".
trait ProtoKnob<T> {
    fn knob(self) -> Option<T>;
}

impl<T> ProtoKnob<T> for Option<T> {
    fn knob(self) -> Option<T> {
        self
    }
}

impl ProtoKnob<String> for String {
    fn knob(self) -> Option<String> {
        Some(self).filter(|s| !s.is_empty())
    }
}

/// Defines [`input_of`] from the knob list: it does not compile unless the proto's `JobSpec`
/// has every knob, with a type that reads as the knob's.
macro_rules! proto_input {
    ($($(#[doc = $doc:literal])* $name:ident: $ty:ty,)*) => {
        /// The domain input of a proto spec.
        pub fn input_of(spec: pb::JobSpec) -> JobInput {
            use pb::job_spec::Points;
            JobInput {
                points: spec.points.map(|p| match p {
                    Points::Xyz(f) => PointsInput::Flat(f.values),
                    Points::XyzF32le(b) => PointsInput::F32Le(b),
                    Points::Ply(b) => PointsInput::Ply(b),
                    Points::Npy(b) => PointsInput::Npy(b),
                }),
                $($name: ProtoKnob::<$ty>::knob(spec.$name),)*
                // A repeated field: errors name the j-th camera `camera[j]`.
                camera: (!spec.camera.is_empty()).then(|| {
                    CameraInput::Many(spec.camera.iter().map(|c| vec![c.x, c.y, c.z]).collect())
                }),
                up: spec.up.map(|u| [u.x, u.y, u.z]),
                // Protobuf types every field: nothing is refused for its type.
                refused: Vec::new(),
            }
        }
    };
}
request_knobs!(proto_input);

impl GrpcJobs {
    fn tenant<T>(&self, req: &Request<T>) -> Result<String, Status> {
        self.tenants
            .resolve(
                req.metadata()
                    .get("authorization")
                    .and_then(|v| v.to_str().ok()),
            )
            .map_err(status_of)
    }
}

type BoxStream<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

#[tonic::async_trait]
impl JobService for GrpcJobs {
    async fn submit_job(
        &self,
        req: Request<pb::SubmitJobRequest>,
    ) -> Result<Response<pb::Job>, Status> {
        let tenant = self.tenant(&req)?;
        let r = req.into_inner();
        let size = prost::Message::encoded_len(&r);
        if size > self.max_message_bytes {
            return Err(status_of(ServiceError::TooLarge {
                limit: self.max_message_bytes,
                size: Some(size),
            }));
        }
        let spec = r
            .spec
            .ok_or_else(|| Status::invalid_argument("invalid spec: missing (must be present)"))?;
        let idem = (!r.request_id.is_empty()).then(|| {
            let hash = format!("{:x}", Sha256::digest(prost::Message::encode_to_vec(&spec)));
            (r.request_id.clone(), format!("grpc:{hash}"))
        });
        let (job, _) = self
            .svc
            .submit(&tenant, input_of(spec), idem)
            .await
            .map_err(status_of)?;
        Ok(Response::new(job_msg(&job)))
    }

    async fn get_job(&self, req: Request<pb::GetJobRequest>) -> Result<Response<pb::Job>, Status> {
        let tenant = self.tenant(&req)?;
        let j = self
            .svc
            .get(&tenant, &req.into_inner().id)
            .await
            .map_err(status_of)?;
        Ok(Response::new(job_msg(&j)))
    }

    async fn list_jobs(
        &self,
        req: Request<pb::ListJobsRequest>,
    ) -> Result<Response<pb::ListJobsResponse>, Status> {
        let tenant = self.tenant(&req)?;
        let r = req.into_inner();
        // 0 = the default, as proto3 cannot tell unset from 0.
        let size = if r.page_size == 0 {
            DEFAULT_PAGE_SIZE
        } else {
            r.page_size
        };
        let page = self
            .svc
            .list(&tenant, size, Some(r.page_token.as_str()))
            .await
            .map_err(status_of)?;
        Ok(Response::new(pb::ListJobsResponse {
            jobs: page.jobs.iter().map(job_msg).collect(),
            next_page_token: page.next_page_token.unwrap_or_default(),
        }))
    }

    async fn cancel_job(
        &self,
        req: Request<pb::CancelJobRequest>,
    ) -> Result<Response<pb::Job>, Status> {
        let tenant = self.tenant(&req)?;
        let j = self
            .svc
            .cancel(&tenant, &req.into_inner().id)
            .await
            .map_err(status_of)?;
        Ok(Response::new(job_msg(&j)))
    }

    type WatchJobStream = BoxStream<pb::JobEvent>;

    async fn watch_job(
        &self,
        req: Request<pb::WatchJobRequest>,
    ) -> Result<Response<Self::WatchJobStream>, Status> {
        let tenant = self.tenant(&req)?;
        let r = req.into_inner();
        let rx = self
            .svc
            .watch(&tenant, &r.id, r.after_sequence)
            .await
            .map_err(status_of)?;
        let stream = ReceiverStream::new(rx).map(|item| match item {
            WatchItem::Stored(e) => {
                let state = if e.kind == "artifact" {
                    pb::State::Running
                } else {
                    serde_json::from_str::<JobView>(&e.data)
                        .map(|j| state_of(&j.state))
                        .unwrap_or(pb::State::Unspecified)
                };
                Ok(pb::JobEvent {
                    sequence: e.sequence,
                    kind: e.kind,
                    state: state as i32,
                    json: e.data,
                })
            }
            WatchItem::Progress { sequence, progress } => Ok(pb::JobEvent {
                sequence,
                kind: "progress".into(),
                state: pb::State::Running as i32,
                json: serde_json::to_string(&progress).unwrap_or_default(),
            }),
            WatchItem::Shutdown { sequence } => Err(Status::unavailable(format!(
                "server shutting down; resume with after_sequence = {sequence}"
            ))),
        });
        Ok(Response::new(Box::pin(stream)))
    }

    type GetArtifactStream = BoxStream<pb::ArtifactChunk>;

    async fn get_artifact(
        &self,
        req: Request<pb::GetArtifactRequest>,
    ) -> Result<Response<Self::GetArtifactStream>, Status> {
        let tenant = self.tenant(&req)?;
        let r = req.into_inner();
        if !ARTIFACT_NAMES.contains(&r.name.as_str()) {
            return Err(Status::invalid_argument(format!(
                "invalid name: {:?} (must be one of {})",
                r.name,
                ARTIFACT_NAMES.join(", ")
            )));
        }
        let (bytes, a) = self
            .svc
            .artifact(&tenant, &r.id, &r.name)
            .await
            .map_err(status_of)?;
        let n = bytes.len().div_ceil(CHUNK_BYTES).max(1);
        let chunks: Vec<Result<pb::ArtifactChunk, Status>> = (0..n)
            .map(|i| {
                let lo = i * CHUNK_BYTES;
                let hi = (lo + CHUNK_BYTES).min(bytes.len());
                Ok(pb::ArtifactChunk {
                    data: bytes[lo..hi].to_vec(),
                    offset: lo as u64,
                    sha256: if i + 1 == n {
                        a.sha256.clone()
                    } else {
                        String::new()
                    },
                })
            })
            .collect();
        Ok(Response::new(Box::pin(tokio_stream::iter(chunks))))
    }
}
