//! The REST adapter (axum): `/v1/jobs…`, SSE progress, artefact downloads, and the admin
//! listener (`/livez`, `/readyz`, `/metrics`).
//!
//! Why it exists: it maps HTTP onto [`Service`] and nothing more: bodies become a
//! [`JobInput`](super::spec::JobInput), [`ServiceError`]s become RFC 9457 problem+json once (in
//! [`IntoResponse`]), and SSE frames are built from the service's watch items. The OpenAPI
//! document is generated from the annotations here ([`ApiDoc`]) and made exact by
//! [`super::openapi`]; `tests/openapi.rs` fails when the committed `openapi.yaml` drifts.

use std::convert::Infallible;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, Path, Query, RawQuery, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, Uri, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::Deserialize;
use sha2::{Digest, Sha256};
use tokio_stream::StreamExt as _;
use tokio_stream::wrappers::ReceiverStream;
use utoipa::OpenApi;

use super::api::{
    ARTIFACT_NAMES, ArtifactView, FieldError, JobList, JobRequest, JobView, Problem, UploadParams,
    media_type,
};
use super::auth::Tenants;
use super::jobs::{DEFAULT_PAGE_SIZE, Service, ServiceError, WatchItem};
use super::spec::{JobInput, PointsInput};

/// Shared state of the REST handlers.
#[derive(Clone)]
pub struct HttpState {
    /// The job service.
    pub svc: Arc<Service>,
    /// Token table.
    pub tenants: Arc<Tenants>,
    /// Largest accepted body.
    pub max_body_bytes: usize,
}

fn pointer(field: &str) -> String {
    // `points[3][1]` → `/points/3/1`.
    let mut p = String::from("/");
    for c in field.chars() {
        match c {
            '[' | '.' => p.push('/'),
            ']' => {}
            c => p.push(c),
        }
    }
    p
}

/// HTTP status of a service error.
pub fn status_of(e: &ServiceError) -> StatusCode {
    match e {
        ServiceError::Invalid(_) | ServiceError::IdempotencyReused { .. } => {
            StatusCode::UNPROCESSABLE_ENTITY
        }
        ServiceError::QueueFull { .. } => StatusCode::TOO_MANY_REQUESTS,
        ServiceError::ShuttingDown { .. } => StatusCode::SERVICE_UNAVAILABLE,
        ServiceError::NotFound(_) | ServiceError::NoRoute => StatusCode::NOT_FOUND,
        ServiceError::Conflict { .. } => StatusCode::CONFLICT,
        ServiceError::Unauthenticated(_) => StatusCode::UNAUTHORIZED,
        ServiceError::Malformed(_) => StatusCode::BAD_REQUEST,
        ServiceError::TooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
        ServiceError::UnsupportedMediaType { .. } => StatusCode::UNSUPPORTED_MEDIA_TYPE,
        ServiceError::Store(_) | ServiceError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
    }
}

/// The problem document of a service error.
pub fn problem_of(e: &ServiceError, instance: Option<String>) -> Problem {
    let status = status_of(e);
    let retry = match e {
        ServiceError::QueueFull { retry_after, .. }
        | ServiceError::ShuttingDown { retry_after } => Some(*retry_after),
        _ => None,
    };
    let errors = match e {
        ServiceError::Invalid(all) => all
            .iter()
            .map(|v| FieldError {
                pointer: pointer(&v.field),
                field: v.field.clone(),
                limit: v.limit.clone(),
                value: v.value.clone(),
                detail: v.to_string(),
            })
            .collect(),
        _ => Vec::new(),
    };
    let detail = match e {
        // Never leak internals beyond the message; the log has the rest.
        ServiceError::Store(_) => "the job store failed; see the server log".to_string(),
        other => other.to_string(),
    };
    Problem {
        problem_type: format!("/problems/{}", e.error_type()),
        title: status.canonical_reason().unwrap_or("Error").to_string(),
        status: status.as_u16(),
        detail,
        instance,
        errors,
        retry_after_seconds: retry,
    }
}

/// A service error with the request path, rendered as problem+json.
pub struct ApiError(pub ServiceError, pub Option<String>);

impl From<ServiceError> for ApiError {
    fn from(e: ServiceError) -> Self {
        ApiError(e, None)
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let p = problem_of(&self.0, self.1);
        if p.status >= 500 && p.status != 503 {
            tracing::error!(error = %self.0, "request failed");
        }
        let mut r = (
            StatusCode::from_u16(p.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR),
            [(header::CONTENT_TYPE, "application/problem+json")],
            serde_json::to_string(&p).unwrap_or_default(),
        )
            .into_response();
        if let Some(s) = p.retry_after_seconds {
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        if p.status == 413 {
            // The request's body may not have been read to the end: the connection cannot be
            // reused, and the client must know it.
            r.headers_mut()
                .insert(header::CONNECTION, HeaderValue::from_static("close"));
        }
        if p.status == 401 {
            r.headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        r
    }
}

type ApiResult<T> = Result<T, ApiError>;

fn tenant(st: &HttpState, headers: &HeaderMap) -> Result<String, ServiceError> {
    st.tenants.resolve(
        headers
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok()),
    )
}

fn at(uri: &Uri) -> impl Fn(ServiceError) -> ApiError + '_ {
    move |e| ApiError(e, Some(uri.path().to_string()))
}

/// Submit a job.
#[utoipa::path(
    post, path = "/v1/jobs", tag = "jobs",
    params(
        ("Idempotency-Key" = Option<String>, Header, description = "Retry-safe submission: the same key and body return the same job"),
        UploadParams
    ),
    request_body(content(
        (JobRequest = "application/json"),
        (Vec<u8> = "application/x-ply"),
        (Vec<u8> = "application/x-npy"),
        (Vec<u8> = "application/octet-stream")
    ), description = "A JSON job request, or a raw point-cloud upload (PLY, NPY, or little-endian f32 triples) with the knobs as query parameters (which a JSON body must not carry: 422)"),
    responses(
        (status = 202, description = "Accepted; `Location` names the job", body = JobView),
        (status = 400, description = "A body or query string that does not parse (not JSON, broken encoding)", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Body too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Unsupported content type", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Fields broke limits or have the wrong type (every one listed in `errors` with field, limit and value, in one answer), query parameters came with a JSON body, or the Idempotency-Key was reused with another body", body = Problem, content_type = "application/problem+json"),
        (status = 429, description = "Queue full; see Retry-After", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Shutting down; see Retry-After", body = Problem, content_type = "application/problem+json"),
    )
)]
async fn submit(
    State(st): State<HttpState>,
    uri: Uri,
    headers: HeaderMap,
    RawQuery(query): RawQuery,
    body: axum::body::Body,
) -> ApiResult<Response> {
    let err = at(&uri);
    let tenant = tenant(&st, &headers).map_err(&err)?;
    let body = read_body(body, &headers, st.max_body_bytes)
        .await
        .map_err(&err)?;
    let ctype = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    // Parsing a large body (100k points of JSON is ~3 MB) is CPU work: keep it off the tokio
    // workers.
    let (ct, q, b) = (ctype.clone(), query.clone(), body.clone());
    let input = tokio::task::spawn_blocking(move || parse_body(&ct, q.as_deref(), &b))
        .await
        .map_err(|e| err(ServiceError::Internal(e.to_string())))?
        .map_err(&err)?;
    let idem = match headers.get("idempotency-key") {
        None => None,
        Some(v) => {
            let key = v
                .to_str()
                .ok()
                .filter(|k| !k.is_empty() && k.len() <= 255)
                .ok_or_else(|| {
                    err(ServiceError::from(super::spec::Violation {
                        field: "Idempotency-Key".into(),
                        limit: "1..=255 visible ASCII characters".into(),
                        value: format!("{} bytes", v.len()),
                    }))
                })?;
            let mut h = Sha256::new();
            h.update(ctype.as_bytes());
            h.update([0]);
            h.update(query.as_deref().unwrap_or("").as_bytes());
            h.update([0]);
            h.update(&body);
            Some((key.to_string(), format!("{:x}", h.finalize())))
        }
    };
    let (job, _created) = st.svc.submit(&tenant, input, idem).await.map_err(&err)?;
    let location = format!("/v1/jobs/{}", job.id);
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, location)],
        Json(job),
    )
        .into_response())
}

/// Most bytes of an oversize body read and thrown away before the 413, so that a client still
/// sending it reads the answer instead of a reset. A larger body (by its Content-Length or as
/// it arrives) is answered at once; the 413 carries `Connection: close` either way, so no
/// client reuses a connection whose request was not read to the end.
const DRAIN_BYTES: usize = 64 << 20;

/// How long the drain of an oversize body may take.
const DRAIN_TIME: Duration = Duration::from_secs(15);

/// Read a submission body of at most `limit` bytes; see [`DRAIN_BYTES`] for the rest.
async fn read_body(
    body: axum::body::Body,
    headers: &HeaderMap,
    limit: usize,
) -> Result<Bytes, ServiceError> {
    let too_large = ServiceError::TooLarge { limit, size: None };
    let declared = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > (limit + DRAIN_BYTES) as u64) {
        return Err(too_large);
    }
    let mut stream = body.into_data_stream();
    let mut buf = Vec::with_capacity(declared.map_or(0, |n| (n as usize).min(limit)));
    let mut total = 0usize;
    while let Some(chunk) = stream.next().await {
        let chunk = chunk.map_err(|e| ServiceError::Malformed(format!("reading the body: {e}")))?;
        total += chunk.len();
        if total > limit {
            break;
        }
        buf.extend_from_slice(&chunk);
    }
    if total <= limit {
        return Ok(Bytes::from(buf));
    }
    let drain = async {
        while let Some(Ok(chunk)) = stream.next().await {
            total += chunk.len();
            if total > limit + DRAIN_BYTES {
                break;
            }
        }
    };
    let _ = tokio::time::timeout(DRAIN_TIME, drain).await;
    Err(too_large)
}

/// A submission body (JSON request, or a raw PLY / NPY / f32le upload with the knobs in the
/// query string) as the domain input; fields of the wrong type are taken out and listed in
/// [`JobInput::refused`].
fn parse_body(ctype: &str, query: Option<&str>, body: &[u8]) -> Result<JobInput, ServiceError> {
    let upload = |points: PointsInput| -> Result<JobInput, ServiceError> {
        let (params, refused) = upload_params(query.unwrap_or(""))?;
        let mut input = params.into_input(points);
        input.refused.splice(0..0, refused);
        Ok(input)
    };
    match ctype {
        "application/json" => {
            // The query string carries the knobs of raw uploads only; with a JSON body they
            // would be silently lost, so they are refused.
            if let Some(name) = query
                .unwrap_or("")
                .split('&')
                .find(|p| !p.is_empty())
                .map(|p| p.split('=').next().unwrap_or(p))
            {
                return Err(ServiceError::Invalid(
                    super::spec::Violation {
                        field: name.chars().take(64).collect(),
                        limit: "absent with a JSON body (query parameters are for raw uploads; put the field in the body)".into(),
                        value: "given in the query string".into(),
                    }
                    .into(),
                ));
            }
            let (req, refused) = json_request(body)?;
            let mut input = req.into_input();
            input.refused.splice(0..0, refused);
            Ok(input)
        }
        "application/x-ply" | "application/ply" | "model/x-ply" => {
            upload(PointsInput::Ply(body.to_vec()))
        }
        "application/x-npy" | "application/npy" => upload(PointsInput::Npy(body.to_vec())),
        "application/octet-stream" => upload(PointsInput::F32Le(body.to_vec())),
        other => Err(ServiceError::UnsupportedMediaType {
            got: other.to_string(),
            expected: "application/json, application/x-ply, application/x-npy or application/octet-stream",
        }),
    }
}

/// Most fields one request can have refused for their type (a bound on the re-reads of
/// [`json_request`] and [`upload_params`]; more than the request has).
const MAX_TYPE_ERRORS: usize = 64;

/// The top-level name of a field path (`points[3][1]` → `points`).
fn top_field(path: &str) -> &str {
    path.split(['[', '.']).next().unwrap_or(path)
}

/// The JSON request with every field of the wrong type (or unknown) taken out and listed: the
/// body is read again without each field a type error names, so that a request with five bad
/// fields hears of all five.
fn json_request(body: &[u8]) -> Result<(JobRequest, Vec<super::spec::Violation>), ServiceError> {
    let data_error = |e: &serde_path_to_error::Error<serde_json::Error>| {
        let msg = e.inner().to_string();
        // serde_json appends " at line L column C" to errors read from text.
        let msg = msg.split(" at line ").next().unwrap_or(&msg).to_string();
        type_violation(&e.path().to_string(), &msg)
    };
    // The common case, a valid request, is read straight from the text.
    let de = &mut serde_json::Deserializer::from_slice(body);
    let first = match serde_path_to_error::deserialize::<_, JobRequest>(de) {
        Ok(req) => return Ok((req, Vec::new())),
        Err(e) if e.inner().classify() == serde_json::error::Category::Data => data_error(&e),
        Err(e) => return Err(ServiceError::Malformed(e.to_string())),
    };
    let mut value: serde_json::Value =
        serde_json::from_slice(body).map_err(|e| ServiceError::Malformed(e.to_string()))?;
    let mut refused = vec![first];
    while refused.len() <= MAX_TYPE_ERRORS {
        let field = top_field(&refused[refused.len() - 1].field).to_string();
        if value
            .as_object_mut()
            .and_then(|o| o.remove(&field))
            .is_none()
        {
            break;
        }
        match serde_path_to_error::deserialize::<_, JobRequest>(&value) {
            Ok(req) => return Ok((req, refused)),
            Err(e) => refused.push(data_error(&e)),
        }
    }
    Err(ServiceError::Invalid(
        super::spec::Violations::new(refused).expect("at least the first"),
    ))
}

/// A value of the wrong type (or out of its type's range) as a field violation:
/// serde's "invalid value: integer `-1`, expected u32" becomes field, limit `u32`, value
/// `integer -1`.
fn type_violation(field: &str, msg: &str) -> super::spec::Violation {
    let (value, limit) = msg
        .split_once(", expected ")
        .unwrap_or((msg, "the documented type"));
    let value = value
        .strip_prefix("invalid type: ")
        .or_else(|| value.strip_prefix("invalid value: "))
        .unwrap_or(value)
        .replace('`', "");
    super::spec::Violation {
        field: if field.is_empty() || field == "." {
            "body".into()
        } else {
            field.to_string()
        },
        limit: limit.to_string(),
        value,
    }
}

/// A query string that does not parse into its parameters: a field of the wrong type is a
/// field violation (422, listed in `errors`); anything else is malformed (400).
fn query_error(e: axum::extract::rejection::QueryRejection) -> ServiceError {
    let text = e.body_text();
    let msg = text
        .strip_prefix("Failed to deserialize query string: ")
        .unwrap_or(&text);
    match msg.split_once(": ") {
        Some((field, detail))
            if !field.is_empty()
                && field
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') =>
        {
            ServiceError::Invalid(type_violation(field, detail).into())
        }
        _ => ServiceError::Malformed(text),
    }
}

fn query_parse<T: serde::de::DeserializeOwned>(q: &str) -> Result<T, ServiceError> {
    // axum's Query extractor uses serde_urlencoded; going through `Query::try_from_uri` keeps
    // the same parser without a direct dependency.
    let uri: Uri = format!("/?{q}")
        .parse()
        .map_err(|e| ServiceError::Malformed(format!("query string: {e}")))?;
    Query::<T>::try_from_uri(&uri)
        .map(|q| q.0)
        .map_err(query_error)
}

/// The knobs of a raw upload, with every parameter of the wrong type (or unknown) taken out and
/// listed. `camera` may repeat, which serde_urlencoded does not take into a struct field: its
/// values are collected first (in order) and the other pairs parsed as [`UploadParams`].
fn upload_params(q: &str) -> Result<(UploadParams, Vec<super::spec::Violation>), ServiceError> {
    let mut cameras = Vec::new();
    let mut rest = Vec::new();
    // serde_urlencoded splits pairs at '&' alone, as here.
    for pair in q.split('&').filter(|p| !p.is_empty()) {
        match query_parse::<Vec<(String, String)>>(pair)?.as_slice() {
            [(k, v)] if k == "camera" => cameras.push(v.clone()),
            [(k, _)] => rest.push((k.clone(), pair)),
            _ => rest.push((String::new(), pair)),
        }
    }
    let mut refused = Vec::new();
    loop {
        let query: Vec<&str> = rest.iter().map(|(_, p)| *p).collect();
        match query_parse::<UploadParams>(&query.join("&")) {
            Ok(mut params) => {
                params.camera = cameras;
                return Ok((params, refused));
            }
            Err(ServiceError::Invalid(v)) if refused.len() < MAX_TYPE_ERRORS => {
                let v = v.first().clone();
                let before = rest.len();
                rest.retain(|(k, _)| k != top_field(&v.field));
                refused.push(v);
                if rest.len() == before {
                    break;
                }
            }
            Err(e) if refused.is_empty() => return Err(e),
            Err(_) => break,
        }
    }
    Err(ServiceError::Invalid(
        super::spec::Violations::new(refused).expect("at least one"),
    ))
}

/// Get a job.
#[utoipa::path(
    get, path = "/v1/jobs/{id}", tag = "jobs",
    params(("id" = String, Path, description = "Job id")),
    responses(
        (status = 200, body = JobView),
        (status = 404, description = "No such job for this tenant", body = Problem, content_type = "application/problem+json"),
    )
)]
async fn get_job(
    State(st): State<HttpState>,
    uri: Uri,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> ApiResult<Json<JobView>> {
    let err = at(&uri);
    let tenant = tenant(&st, &headers).map_err(&err)?;
    Ok(Json(st.svc.get(&tenant, &id).await.map_err(&err)?))
}

/// Paging parameters.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
struct ListParams {
    /// Jobs per page (1–500, default 50).
    #[serde(default, deserialize_with = "super::api::integral::opt_u32")]
    page_size: Option<u32>,
    /// `next_page_token` of the previous page.
    page_token: Option<String>,
}

/// List the tenant's jobs, oldest first.
#[utoipa::path(
    get, path = "/v1/jobs", tag = "jobs",
    params(ListParams),
    responses(
        (status = 200, body = JobList),
        (status = 400, description = "A query string that does not parse", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "page_size out of range or not an integer, or a page_token that is not one (listed in `errors`)", body = Problem, content_type = "application/problem+json"),
    )
)]
async fn list_jobs(
    State(st): State<HttpState>,
    uri: Uri,
    headers: HeaderMap,
    q: Result<Query<ListParams>, axum::extract::rejection::QueryRejection>,
) -> ApiResult<Json<JobList>> {
    let err = at(&uri);
    let tenant = tenant(&st, &headers).map_err(&err)?;
    let Query(q) = q.map_err(|e| err(query_error(e)))?;
    Ok(Json(
        st.svc
            .list(
                &tenant,
                q.page_size.unwrap_or(DEFAULT_PAGE_SIZE),
                q.page_token.as_deref(),
            )
            .await
            .map_err(&err)?,
    ))
}

/// Cancel a job (queued: at once; running: at the next diffusion step). Idempotent: cancelling a
/// CANCELLED job answers 200 with the job; a SUCCEEDED or FAILED one answers 409.
#[utoipa::path(
    post, path = "/v1/jobs/{id}/cancel", tag = "jobs",
    params(("id" = String, Path, description = "Job id")),
    responses(
        (status = 200, description = "The job: CANCELLED (at once when it was queued; also when it was already CANCELLED, so a retried cancel succeeds), or RUNNING with cancel_requested", body = JobView),
        (status = 404, description = "No such job for this tenant", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Already SUCCEEDED or FAILED", body = Problem, content_type = "application/problem+json"),
    )
)]
async fn cancel_job(
    State(st): State<HttpState>,
    uri: Uri,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> ApiResult<Json<JobView>> {
    let err = at(&uri);
    let tenant = tenant(&st, &headers).map_err(&err)?;
    Ok(Json(st.svc.cancel(&tenant, &id).await.map_err(&err)?))
}

/// Delete a finished job and its artefacts.
#[utoipa::path(
    delete, path = "/v1/jobs/{id}", tag = "jobs",
    params(("id" = String, Path, description = "Job id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, description = "No such job for this tenant", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not finished", body = Problem, content_type = "application/problem+json"),
    )
)]
async fn delete_job(
    State(st): State<HttpState>,
    uri: Uri,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> ApiResult<StatusCode> {
    let err = at(&uri);
    let tenant = tenant(&st, &headers).map_err(&err)?;
    st.svc.delete(&tenant, &id).await.map_err(&err)?;
    Ok(StatusCode::NO_CONTENT)
}

/// Resume point of an event stream.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
struct EventsParams {
    /// Replay events after this sequence (the `Last-Event-ID` header wins when both are given).
    #[serde(default, deserialize_with = "super::api::integral::opt_u64")]
    after: Option<u64>,
}

/// Server-sent events of a job: `state`, `progress`, `artifact`, `done` (then the stream
/// closes), `shutdown` (server draining; reconnect with Last-Event-ID). Every event's `id` is
/// the last persisted sequence, so a reconnect with `Last-Event-ID` loses no state event.
/// Progress is not replayed: a resumed stream gets the latest progress.
#[utoipa::path(
    get, path = "/v1/jobs/{id}/events", tag = "jobs",
    params(
        ("id" = String, Path, description = "Job id"),
        ("Last-Event-ID" = Option<u64>, Header, nullable = false, description = "Resume after this sequence (a non-negative integer)"),
        EventsParams
    ),
    responses(
        (status = 200, description = "text/event-stream", content_type = "text/event-stream", body = String),
        (status = 204, description = "The client has already seen the terminal event"),
        (status = 400, description = "A query string that does not parse", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such job for this tenant", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Last-Event-ID or after is not a sequence number (listed in `errors`)", body = Problem, content_type = "application/problem+json"),
    )
)]
async fn events(
    State(st): State<HttpState>,
    uri: Uri,
    headers: HeaderMap,
    Path(id): Path<String>,
    q: Result<Query<EventsParams>, axum::extract::rejection::QueryRejection>,
) -> ApiResult<Response> {
    let err = at(&uri);
    let tenant = tenant(&st, &headers).map_err(&err)?;
    let Query(q) = q.map_err(|e| err(query_error(e)))?;
    // Sequences are at most i64::MAX (the store's integer); both resume points are checked,
    // whichever is used (the header wins).
    let beyond = |field: &str, value: String| {
        err(ServiceError::from(super::spec::Violation {
            field: field.into(),
            limit: format!("a non-negative integer sequence <= {}", i64::MAX),
            value,
        }))
    };
    if let Some(a) = q.after.filter(|&a| a > i64::MAX as u64) {
        return Err(beyond("after", a.to_string()));
    }
    let after = match headers.get("last-event-id") {
        Some(v) => v
            .to_str()
            .ok()
            .and_then(|s| s.trim().parse::<u64>().ok())
            .filter(|&a| a <= i64::MAX as u64)
            .ok_or_else(|| beyond("Last-Event-ID", format!("{v:?}")))?,
        None => q.after.unwrap_or(0),
    };
    let job = st.svc.get(&tenant, &id).await.map_err(&err)?;
    let terminal = matches!(job.state.as_str(), "SUCCEEDED" | "FAILED" | "CANCELLED");
    if terminal && after >= job.sequence {
        return Ok(StatusCode::NO_CONTENT.into_response());
    }
    let rx = st.svc.watch(&tenant, &id, after).await.map_err(&err)?;
    let stream = ReceiverStream::new(rx).map(|item| {
        let ev = match item {
            WatchItem::Stored(e) => Event::default()
                .id(e.sequence.to_string())
                .event(e.kind)
                .data(e.data),
            WatchItem::Progress { sequence, progress } => Event::default()
                .id(sequence.to_string())
                .event("progress")
                .data(serde_json::to_string(&progress).unwrap_or_default()),
            WatchItem::Shutdown { sequence } => Event::default()
                .id(sequence.to_string())
                .event("shutdown")
                .data("{}"),
        };
        Ok::<_, Infallible>(ev)
    });
    let mut r = Sse::new(stream)
        .keep_alive(KeepAlive::new().interval(Duration::from_secs(15)))
        .into_response();
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    r.headers_mut()
        .insert("x-accel-buffering", HeaderValue::from_static("no"));
    Ok(r)
}

/// List a finished job's artefacts.
#[utoipa::path(
    get, path = "/v1/jobs/{id}/artifacts", tag = "jobs",
    params(("id" = String, Path, description = "Job id")),
    responses(
        (status = 200, body = Vec<ArtifactView>),
        (status = 404, description = "No such job for this tenant", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not finished", body = Problem, content_type = "application/problem+json"),
    )
)]
async fn list_artifacts(
    State(st): State<HttpState>,
    uri: Uri,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> ApiResult<Json<Vec<ArtifactView>>> {
    let err = at(&uri);
    let tenant = tenant(&st, &headers).map_err(&err)?;
    let job = st.svc.get(&tenant, &id).await.map_err(&err)?;
    if job.state != "SUCCEEDED" {
        return Err(err(ServiceError::Conflict {
            kind: "job-not-finished",
            detail: format!(
                "job {id} is {}; artefacts exist once it SUCCEEDED",
                job.state
            ),
        }));
    }
    Ok(Json(job.artifacts))
}

/// Download an artefact: `model.glb` (model/gltf-binary), `model.xml` (MJCF for MuJoCo,
/// application/xml; its meshes are in `robot.zip`), `robot.zip` (URDF + MJCF + OBJ meshes),
/// `object.json` (physnap.object/v1), `ranking.json` (physnap.job_ranking/v1).
#[utoipa::path(
    get, path = "/v1/jobs/{id}/artifacts/{name}", tag = "jobs",
    params(
        ("id" = String, Path, description = "Job id"),
        ("name" = String, Path, description = "model.glb, model.xml, robot.zip, object.json or ranking.json")
    ),
    responses(
        (status = 200, description = "The file; ETag is its sha256", body = Vec<u8>, content_type = "application/octet-stream"),
        (status = 304, description = "If-None-Match matched the ETag"),
        (status = 404, description = "No such job for this tenant, or no artefact of that name", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not finished", body = Problem, content_type = "application/problem+json"),
    )
)]
async fn get_artifact(
    State(st): State<HttpState>,
    uri: Uri,
    headers: HeaderMap,
    Path((id, name)): Path<(String, String)>,
) -> ApiResult<Response> {
    let err = at(&uri);
    let tenant = tenant(&st, &headers).map_err(&err)?;
    if !ARTIFACT_NAMES.contains(&name.as_str()) {
        // Neither the detail nor the instance echoes the name: it is arbitrary client input
        // (path-traversal probes).
        return Err(ApiError(
            ServiceError::NotFound(format!(
                "{id} artefact of that name; artefacts are named {}",
                ARTIFACT_NAMES.join(", ")
            )),
            Some(format!("/v1/jobs/{id}/artifacts")),
        ));
    }
    let (bytes, a) = st.svc.artifact(&tenant, &id, &name).await.map_err(&err)?;
    let etag = format!("\"{}\"", a.sha256);
    if headers
        .get(header::IF_NONE_MATCH)
        .is_some_and(|v| v.as_bytes() == etag.as_bytes())
    {
        return Ok(StatusCode::NOT_MODIFIED.into_response());
    }
    Ok((
        [
            (header::CONTENT_TYPE, media_type(&name).to_string()),
            (header::ETAG, etag),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{name}\""),
            ),
        ],
        bytes,
    )
        .into_response())
}

/// Categories the loaded weights know (index = position).
#[utoipa::path(
    get, path = "/v1/categories", tag = "jobs",
    responses((status = 200, body = Vec<String>))
)]
async fn categories(State(st): State<HttpState>) -> Json<Vec<String>> {
    Json(st.svc.caps().categories.clone())
}

/// Unknown routes: the path is not echoed (arbitrary client input).
async fn not_found() -> ApiError {
    ApiError(ServiceError::NoRoute, None)
}

/// The OpenAPI document of the REST API.
#[derive(OpenApi)]
#[openapi(
    info(
        title = "physnap job service",
        description = "Articulated-object generation jobs (PhysNAP). Jobs are resources: submit, watch (SSE), download. The point cloud guides the sampler (PhysNAP loss guidance, plus the free-space loss when a camera is given); the best sample is repaired and exported as GLB, URDF and object JSON.",
        license(name = "MIT OR Apache-2.0")
    ),
    paths(submit, get_job, list_jobs, cancel_job, delete_job, events, list_artifacts, get_artifact, categories),
    components(schemas(JobRequest, JobView, JobList, Problem, FieldError, ArtifactView)),
    modifiers(&Security),
    security(("bearer" = []))
)]
pub struct ApiDoc;

struct Security;

impl utoipa::Modify for Security {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
        let c = openapi.components.get_or_insert_with(Default::default);
        c.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
    }
}

/// The OpenAPI document as committed in `openapi.yaml` ([`super::openapi::document`]).
pub fn openapi_document() -> String {
    super::openapi::document()
}

/// The public REST router.
pub fn router(st: HttpState) -> Router {
    let limit = st.max_body_bytes;
    Router::new()
        .route("/v1/jobs", post(submit).get(list_jobs))
        .route("/v1/jobs/{id}", get(get_job).delete(delete_job))
        .route("/v1/jobs/{id}/cancel", post(cancel_job))
        .route("/v1/jobs/{id}/events", get(events))
        .route("/v1/jobs/{id}/artifacts", get(list_artifacts))
        .route("/v1/jobs/{id}/artifacts/{name}", get(get_artifact))
        .route("/v1/categories", get(categories))
        .fallback(not_found)
        .layer(DefaultBodyLimit::max(limit))
        .with_state(st)
}

/// The admin router: liveness, readiness (503 while draining) and Prometheus metrics.
pub fn admin_router(svc: Arc<Service>) -> Router {
    Router::new()
        .route("/livez", get(|| async { "ok\n" }))
        .route(
            "/readyz",
            get(|State(svc): State<Arc<Service>>| async move {
                if svc.is_draining() {
                    (StatusCode::SERVICE_UNAVAILABLE, "draining\n")
                } else {
                    (StatusCode::OK, "ready\n")
                }
            }),
        )
        .route("/metrics", get(metrics))
        .with_state(svc)
}

async fn metrics(State(svc): State<Arc<Service>>) -> Response {
    use std::fmt::Write as _;
    let m = &svc.metrics;
    let mut s = String::new();
    let mut counter = |name: &str, help: &str, v: u64| {
        let _ = writeln!(s, "# HELP {name} {help}\n# TYPE {name} counter\n{name} {v}");
    };
    counter(
        "physnap_jobs_submitted_total",
        "Jobs admitted.",
        m.submitted.load(Ordering::Relaxed),
    );
    counter(
        "physnap_jobs_succeeded_total",
        "Jobs that succeeded.",
        m.succeeded.load(Ordering::Relaxed),
    );
    counter(
        "physnap_jobs_failed_total",
        "Jobs that failed.",
        m.failed.load(Ordering::Relaxed),
    );
    counter(
        "physnap_jobs_cancelled_total",
        "Jobs cancelled.",
        m.cancelled.load(Ordering::Relaxed),
    );
    counter(
        "physnap_jobs_recovered_total",
        "Jobs re-queued at start-up.",
        m.recovered.load(Ordering::Relaxed),
    );
    counter(
        "physnap_diffusion_steps_total",
        "Diffusion steps run.",
        m.steps.load(Ordering::Relaxed),
    );
    let _ = writeln!(
        s,
        "# HELP physnap_jobs_rejected_total Submissions refused.\n# TYPE physnap_jobs_rejected_total counter\n\
         physnap_jobs_rejected_total{{reason=\"invalid\"}} {}\n\
         physnap_jobs_rejected_total{{reason=\"queue_full\"}} {}\n\
         physnap_jobs_rejected_total{{reason=\"draining\"}} {}",
        m.rejected_invalid.load(Ordering::Relaxed),
        m.rejected_full.load(Ordering::Relaxed),
        m.rejected_draining.load(Ordering::Relaxed)
    );
    let _ = writeln!(
        s,
        "# HELP physnap_job_run_seconds_sum Wall time of successful jobs.\n# TYPE physnap_job_run_seconds_sum counter\nphysnap_job_run_seconds_sum {:.3}",
        m.run_seconds_sum_ms.load(Ordering::Relaxed) as f64 / 1000.0
    );
    // The queue is the store's when it is shared: an unreadable length is NaN, not a guess.
    let queued = svc
        .queued()
        .await
        .map_or_else(|_| "NaN".to_string(), |n| n.to_string());
    let _ = writeln!(
        s,
        "# HELP physnap_jobs_queued Jobs waiting.\n# TYPE physnap_jobs_queued gauge\nphysnap_jobs_queued {}\n\
         # HELP physnap_jobs_running Jobs running.\n# TYPE physnap_jobs_running gauge\nphysnap_jobs_running {}",
        queued,
        svc.running()
    );
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], s).into_response()
}
