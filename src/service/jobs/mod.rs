//! The job service core: admission, the worker pool, cancellation, events (the queue's own
//! state and rules are [`super::queue::QueueState`]).
//!
//! Why it exists: REST and gRPC are thin adapters over this one [`Service`], so both transports
//! share one queue, one store, one set of limits and one event log. The rules it enforces:
//!
//! - **Admission** validates first (nothing invalid is ever stored), then reserves a queue slot
//!   (full → [`ServiceError::QueueFull`] with a retry hint; draining → `ShuttingDown`), then
//!   commits the job and its first event with fsync before answering.
//! - **Scheduling**: one dispatcher task pops the queue when one of `max_running_jobs` slots
//!   (a semaphore) is free; the job runs on tokio's blocking pool inside
//!   `ThreadPool::install` of the service's dedicated rayon pool, so CPU work never runs on a
//!   tokio worker and every rayon call of the engine stays inside `--worker-threads` threads.
//! - **Stop conditions** (cancel flag, deadline, hard shutdown) are polled at every diffusion
//!   step by the runner.
//! - **Events**: state changes, artefacts and the terminal `done` are persisted with a
//!   per-job sequence; progress goes through a `tokio::sync::watch` (latest wins, so slow
//!   readers never buffer) and is not persisted. Watchers resume from any sequence; the fan-out
//!   to them is [`fanout`].
//! - **Durability**: a job found QUEUED or RUNNING at start-up is re-queued (attempt + 1); the
//!   seed is part of the job, so the re-run writes the same bytes. Disconnects never cancel.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use tokio::sync::{Notify, OwnedSemaphorePermit, Semaphore, watch};

use super::api::{self, JobList, JobView};
use super::queue::{Full, QueueState};

mod fanout;
mod shared;

use super::runner::{Models, Progress, RunError, run_job};
use super::spec::{JobInput, Limits, ModelCaps, Violation, Violations, validate};
use super::store::{
    self, Artifact, JobFailure, JobRecord, JobState, JobStore, StoreError, StoreLocation,
    StoredEvent,
};
use fanout::Live;
pub use fanout::{Snapshot, WatchItem};
pub use shared::Role;
use shared::Shared;

/// Settings of the job service.
#[derive(Debug, Clone)]
pub struct ServiceConfig {
    /// The SQLite store (`jobs.sqlite3`, `artifacts/`) lives here.
    pub data_dir: PathBuf,
    /// Where jobs and artefacts are stored.
    pub store: StoreLocation,
    /// What this process does with the queue.
    pub role: Role,
    /// How long a worker's lease on a job lasts without a heartbeat (shared store).
    pub lease: Duration,
    /// Jobs running at once.
    pub max_running_jobs: usize,
    /// Threads of the dedicated rayon pool.
    pub worker_threads: usize,
    /// Jobs waiting at most (beyond that: 429 / RESOURCE_EXHAUSTED).
    pub queue_capacity: usize,
    /// Retry hint for 429 / 503 (seconds).
    pub retry_after_seconds: u64,
    /// Request limits.
    pub limits: Limits,
}

/// Errors of the service layer; each transport maps them once (problem+json, gRPC status).
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// The request broke limits (every one it broke).
    #[error("{0}")]
    Invalid(#[from] Violations),
    /// The queue is full.
    #[error("queue is full: {queued} jobs queued (limit {capacity})")]
    QueueFull {
        /// Jobs queued.
        queued: usize,
        /// The limit.
        capacity: usize,
        /// Retry hint (s).
        retry_after: u64,
    },
    /// Draining: no new jobs.
    #[error("the server is shutting down and admits no new jobs")]
    ShuttingDown {
        /// Retry hint (s).
        retry_after: u64,
    },
    /// No such job (or another tenant's).
    #[error("no job {0}")]
    NotFound(String),
    /// No such route (REST): the path is not echoed.
    #[error("no such route; the API lives under /v1 (see openapi.yaml)")]
    NoRoute,
    /// The job is in the wrong state for the operation.
    #[error("{detail}")]
    Conflict {
        /// `job-already-finished`, `job-not-finished`, `artifact-not-found`.
        kind: &'static str,
        /// Detail.
        detail: String,
    },
    /// The idempotency key was used for a different request.
    #[error("Idempotency-Key {key:?} was already used with a different request")]
    IdempotencyReused {
        /// The key.
        key: String,
    },
    /// No or an unknown bearer token.
    #[error("{0}")]
    Unauthenticated(String),
    /// The body does not parse (JSON syntax, wrong types, unknown fields).
    #[error("malformed request: {0}")]
    Malformed(String),
    /// The body exceeds the limit.
    #[error("request body too large: more than {limit} bytes")]
    TooLarge {
        /// The limit (bytes).
        limit: usize,
        /// The size received, when known (a gRPC message; a REST body is not read to its end).
        size: Option<usize>,
    },
    /// A content type the endpoint does not take.
    #[error("unsupported content type {got:?} (use {expected})")]
    UnsupportedMediaType {
        /// What came.
        got: String,
        /// What is accepted.
        expected: &'static str,
    },
    /// The store failed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// Anything else (I/O on artefacts, a panicked task).
    #[error("internal error: {0}")]
    Internal(String),
}

impl From<Violation> for ServiceError {
    fn from(v: Violation) -> Self {
        ServiceError::Invalid(v.into())
    }
}

impl ServiceError {
    /// Stable machine-readable kind (also the problem `type` suffix).
    pub fn error_type(&self) -> &'static str {
        match self {
            ServiceError::Invalid(_) => "validation",
            ServiceError::QueueFull { .. } => "queue-full",
            ServiceError::ShuttingDown { .. } => "shutting-down",
            ServiceError::NotFound(_) | ServiceError::NoRoute => "not-found",
            ServiceError::Conflict { kind, .. } => kind,
            ServiceError::IdempotencyReused { .. } => "idempotency-key-reused",
            ServiceError::Unauthenticated(_) => "unauthenticated",
            ServiceError::Malformed(_) => "malformed-request",
            ServiceError::TooLarge { .. } => "body-too-large",
            ServiceError::UnsupportedMediaType { .. } => "unsupported-media-type",
            ServiceError::Store(e) => e.error_type(),
            ServiceError::Internal(_) => "internal",
        }
    }
}

/// Counters for `/metrics`.
#[derive(Debug, Default)]
pub struct Metrics {
    /// Jobs admitted.
    pub submitted: AtomicU64,
    /// Rejected: invalid.
    pub rejected_invalid: AtomicU64,
    /// Rejected: queue full.
    pub rejected_full: AtomicU64,
    /// Rejected: draining.
    pub rejected_draining: AtomicU64,
    /// Finished per state.
    pub succeeded: AtomicU64,
    /// Failed.
    pub failed: AtomicU64,
    /// Cancelled.
    pub cancelled: AtomicU64,
    /// Diffusion steps run.
    pub steps: AtomicU64,
    /// Jobs re-queued at start-up.
    pub recovered: AtomicU64,
    /// Sum of job run seconds (successful).
    pub run_seconds_sum_ms: AtomicU64,
}

/// The job service.
pub struct Service {
    cfg: ServiceConfig,
    store: Arc<Mutex<Box<dyn JobStore>>>,
    models: Arc<Models>,
    caps: ModelCaps,
    pool: Arc<rayon::ThreadPool>,
    queue: Mutex<QueueState>,
    wake: Notify,
    slots: Arc<Semaphore>,
    live: Mutex<HashMap<String, Live>>,
    draining: AtomicBool,
    hard_stop: Arc<AtomicBool>,
    running: AtomicUsize,
    shutdown_tx: watch::Sender<bool>,
    /// Set when the store is shared with other processes (PostgreSQL): the queue is the
    /// store's, jobs run under leases, and news arrive by notification.
    shared: Option<Shared>,
    /// Jobs this process runs under a lease (shared store).
    leased: Mutex<shared::Leased>,
    /// Counters.
    pub metrics: Metrics,
}

/// Unix time in ms.
pub fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panic while holding one of these locks cannot leave the data half-updated (every
    // critical section is a single insert/remove), so a poisoned lock is still usable.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn event(rec: &JobRecord, kind: &str, data: String) -> StoredEvent {
    StoredEvent {
        sequence: rec.sequence,
        kind: kind.into(),
        data,
    }
}

/// Append the state event (and, for a terminal state, `done`) for the record's current state.
fn state_events(rec: &mut JobRecord) -> Vec<StoredEvent> {
    let mut out = Vec::new();
    rec.sequence += 1;
    let data = serde_json::to_string(&api::job_view(rec, None, false)).unwrap_or_default();
    out.push(event(rec, "state", data));
    if rec.state.is_terminal() {
        rec.sequence += 1;
        let data = serde_json::to_string(&api::job_view(rec, None, false)).unwrap_or_default();
        out.push(event(rec, "done", data));
    }
    out
}

impl Service {
    /// Open the store, re-queue interrupted jobs and start the dispatcher. Must be called inside
    /// a tokio runtime.
    pub async fn start(cfg: ServiceConfig, models: Models) -> Result<Arc<Service>, ServiceError> {
        // The stores are synchronous clients (PostgreSQL's runs its own runtime), so they are
        // only ever used from the blocking pool.
        let (location, dir) = (cfg.store.clone(), cfg.data_dir.clone());
        let store = tokio::task::spawn_blocking(move || store::open(&location, &dir))
            .await
            .map_err(|e| ServiceError::Internal(e.to_string()))?
            .map_err(|e| {
                ServiceError::Internal(format!("opening the job store {}: {e}", cfg.store))
            })?;
        tracing::info!(store = %cfg.store, backend = store.backend(), "job store open");
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(cfg.worker_threads.max(1))
            .thread_name(|i| format!("physnap-worker-{i}"))
            .build()
            .map_err(|e| ServiceError::Internal(e.to_string()))?;
        let m = &models.loaded.manifest;
        let caps = ModelCaps {
            categories: m.categories.clone(),
            conditional: m.denoiser.config.categories > 0,
            schedule_steps: models.schedule.len() as u32,
            codebook: models.loaded.codebook.is_some(),
            codebook_categories: models.loaded.codebook.as_ref().map_or(Vec::new(), |cb| {
                (0..m.categories.len())
                    .filter(|&c| cb.rows_of_category(c) > 0)
                    .collect()
            }),
        };
        let (shutdown_tx, _) = watch::channel(false);
        let queue = Mutex::new(QueueState::new(cfg.queue_capacity));
        let shared = Shared::of(&cfg)?;
        let svc = Arc::new(Service {
            slots: Arc::new(Semaphore::new(cfg.max_running_jobs.max(1))),
            cfg,
            store: Arc::new(Mutex::new(store)),
            models: Arc::new(models),
            caps,
            pool: Arc::new(pool),
            queue,
            wake: Notify::new(),
            live: Mutex::new(HashMap::new()),
            draining: AtomicBool::new(false),
            hard_stop: Arc::new(AtomicBool::new(false)),
            running: AtomicUsize::new(0),
            shutdown_tx,
            shared,
            leased: Mutex::new(Default::default()),
            metrics: Metrics::default(),
        });
        if svc.shared.is_some() {
            // No recovery pass: a job whose worker died is re-leased when its lease expires.
            svc.start_listening().await?;
        } else {
            let r = svc.clone();
            tokio::task::spawn_blocking(move || r.recover())
                .await
                .map_err(|e| ServiceError::Internal(e.to_string()))??;
        }
        if svc.cfg.role.runs_jobs() {
            let d = svc.clone();
            if svc.shared.is_some() {
                tokio::spawn(async move { d.dispatch_shared().await });
            } else {
                tokio::spawn(async move { d.dispatch().await });
            }
        }
        Ok(svc)
    }

    /// Re-queue every job that was admitted but did not finish (synchronous, at start-up).
    fn recover(&self) -> Result<(), ServiceError> {
        let mut store = lock(&self.store);
        for mut rec in store.unfinished()? {
            if rec.state == JobState::Running {
                rec.state = JobState::Queued;
                let evs = state_events(&mut rec);
                store.update(&rec, &evs)?;
            }
            self.add_live(&rec);
            lock(&self.queue).requeue(rec.id.clone());
            self.metrics.recovered.fetch_add(1, Ordering::Relaxed);
            tracing::info!(job = %rec.id, attempt = rec.attempt, "re-queued interrupted job");
        }
        Ok(())
    }

    fn add_live(&self, rec: &JobRecord) {
        let (tx, _) = watch::channel(Arc::new(Snapshot {
            sequence: rec.sequence,
            progress: None,
            previews: 0,
            last_preview: None,
        }));
        lock(&self.live).insert(
            rec.id.clone(),
            Live {
                tx: Arc::new(tx),
                cancel: Arc::new(AtomicBool::new(false)),
            },
        );
    }

    /// Model capabilities (categories, schedule) requests are validated against.
    pub fn caps(&self) -> &ModelCaps {
        &self.caps
    }

    /// Request limits.
    pub fn limits(&self) -> &Limits {
        &self.cfg.limits
    }

    /// Jobs waiting (in the shared store's queue, when shared).
    pub async fn queued(&self) -> Result<usize, ServiceError> {
        if self.shared.is_none() {
            return Ok(lock(&self.queue).len());
        }
        let counts = self.db(|s| s.count_by_state()).await?;
        Ok(shared::queued_of(&counts))
    }

    /// Jobs running.
    pub fn running(&self) -> usize {
        self.running.load(Ordering::Relaxed)
    }

    /// Whether the service is draining.
    pub fn is_draining(&self) -> bool {
        self.draining.load(Ordering::Relaxed)
    }

    /// Job counts per state, from the store.
    pub async fn counts(&self) -> Result<Vec<(String, u64)>, ServiceError> {
        self.db(|s| s.count_by_state()).await
    }

    /// Run a store operation on the blocking pool.
    async fn db<T: Send + 'static>(
        &self,
        f: impl FnOnce(&mut dyn JobStore) -> Result<T, StoreError> + Send + 'static,
    ) -> Result<T, ServiceError> {
        let store = self.store.clone();
        tokio::task::spawn_blocking(move || f(lock(&store).as_mut()))
            .await
            .map_err(|e| ServiceError::Internal(e.to_string()))?
            .map_err(ServiceError::from)
    }

    fn view(&self, rec: &JobRecord) -> JobView {
        let live = lock(&self.live);
        let l = live.get(&rec.id);
        let snap = l.map(|l| l.tx.borrow().clone());
        api::job_view(
            rec,
            snap.as_ref().and_then(|s| s.progress.as_ref()),
            l.is_some_and(|l| l.cancel.load(Ordering::Relaxed)),
        )
    }

    /// Validate and admit a job. `idempotency` is `(key, request hash)`. Returns the job and
    /// whether it was created now (false: an idempotent replay).
    pub async fn submit(
        self: &Arc<Self>,
        tenant: &str,
        input: JobInput,
        idempotency: Option<(String, String)>,
    ) -> Result<(JobView, bool), ServiceError> {
        if self.is_draining() {
            self.metrics
                .rejected_draining
                .fetch_add(1, Ordering::Relaxed);
            return Err(ServiceError::ShuttingDown {
                retry_after: self.cfg.retry_after_seconds,
            });
        }
        let svc = self.clone();
        let tenant = tenant.to_string();
        let res =
            tokio::task::spawn_blocking(move || svc.submit_blocking(&tenant, input, idempotency))
                .await
                .map_err(|e| ServiceError::Internal(e.to_string()))?;
        match &res {
            Err(ServiceError::Invalid(_)) => {
                self.metrics
                    .rejected_invalid
                    .fetch_add(1, Ordering::Relaxed);
            }
            Err(ServiceError::QueueFull { .. }) => {
                self.metrics.rejected_full.fetch_add(1, Ordering::Relaxed);
            }
            Ok((_, true)) => {
                self.metrics.submitted.fetch_add(1, Ordering::Relaxed);
                self.wake.notify_one();
            }
            _ => {}
        }
        res
    }

    fn submit_blocking(
        &self,
        tenant: &str,
        input: JobInput,
        idempotency: Option<(String, String)>,
    ) -> Result<(JobView, bool), ServiceError> {
        let id = uuid::Uuid::now_v7();
        // The low 62 bits of a UUIDv7 are random: a fresh seed when none was given.
        let random_seed = (id.as_u128() as u64) & ((1 << 62) - 1);
        // Validation first: nothing invalid is stored, and it needs no lock.
        let spec = validate(&input, &self.caps, &self.cfg.limits, random_seed)?;
        // The store lock serialises idempotency look-up, the queue check and the insert.
        let mut store = lock(&self.store);
        if let Some((key, hash)) = &idempotency
            && let Some((old_hash, job_id)) = store.idempotency(tenant, key)?
        {
            if &old_hash != hash {
                return Err(ServiceError::IdempotencyReused { key: key.clone() });
            }
            let rec = store.get(&job_id)?.ok_or(ServiceError::NotFound(job_id))?;
            drop(store);
            return Ok((self.view(&rec), false));
        }
        let admit = if self.shared.is_some() {
            shared::check_admit(store.as_mut(), self.cfg.queue_capacity)?
        } else {
            lock(&self.queue).check_admit()
        };
        if let Err(Full { queued, capacity }) = admit {
            return Err(ServiceError::QueueFull {
                queued,
                capacity,
                retry_after: self.cfg.retry_after_seconds,
            });
        }
        let created_ms = now_ms();
        let mut rec = JobRecord {
            id: id.to_string(),
            tenant: tenant.to_string(),
            state: JobState::Queued,
            deadline_ms: created_ms + (spec.deadline_seconds * 1000.0).ceil() as i64,
            spec,
            created_ms,
            started_ms: None,
            ended_ms: None,
            attempt: 0,
            sequence: 0,
            failure: None,
            artifacts: Vec::new(),
        };
        let evs = state_events(&mut rec);
        store.insert(
            &rec,
            &evs,
            idempotency.as_ref().map(|(k, h)| (k.as_str(), h.as_str())),
        )?;
        drop(store);
        self.add_live(&rec);
        if self.shared.is_none() {
            lock(&self.queue).push(rec.id.clone());
        }
        tracing::info!(job = %rec.id, tenant, seed = rec.spec.seed, "job admitted");
        Ok((self.view(&rec), true))
    }

    async fn owned(&self, tenant: &str, id: &str) -> Result<JobRecord, ServiceError> {
        let key = id.to_string();
        match self.db(move |s| s.get(&key)).await? {
            Some(r) if r.tenant == tenant => Ok(r),
            _ => Err(ServiceError::NotFound(id.to_string())),
        }
    }

    /// One job of `tenant` (another tenant's job is [`ServiceError::NotFound`]).
    pub async fn get(&self, tenant: &str, id: &str) -> Result<JobView, ServiceError> {
        let rec = self.owned(tenant, id).await?;
        Ok(self.view(&rec))
    }

    /// A page of `tenant`'s jobs, oldest first.
    pub async fn list(
        &self,
        tenant: &str,
        page_size: u32,
        page_token: Option<&str>,
    ) -> Result<JobList, ServiceError> {
        let mut refused = Vec::new();
        if !(1..=MAX_PAGE_SIZE).contains(&page_size) {
            refused.push(Violation {
                field: "page_size".into(),
                limit: format!("1..={MAX_PAGE_SIZE}"),
                value: page_size.to_string(),
            });
        }
        let size = page_size as usize;
        let after = match page_token.filter(|t| !t.is_empty()) {
            None => None,
            Some(t) => {
                let after = decode_token(t);
                if after.is_none() {
                    refused.push(Violation {
                        field: "page_token".into(),
                        limit: "a token returned by a previous page".into(),
                        value: format!("{t:?}"),
                    });
                }
                after
            }
        };
        if let Some(all) = Violations::new(refused) {
            return Err(ServiceError::Invalid(all));
        }
        let tenant_s = tenant.to_string();
        let recs = self
            .db(move |s| s.list(&tenant_s, after.as_deref(), size + 1))
            .await?;
        let more = recs.len() > size;
        let jobs: Vec<JobView> = recs.iter().take(size).map(|r| self.view(r)).collect();
        Ok(JobList {
            next_page_token: if more {
                jobs.last().map(|j| encode_token(&j.id))
            } else {
                None
            },
            jobs,
        })
    }

    /// Cancel a queued (at once) or running (at the next step) job. Idempotent; a finished
    /// job gives `job-already-finished`.
    pub async fn cancel(&self, tenant: &str, id: &str) -> Result<JobView, ServiceError> {
        let mut rec = self.owned(tenant, id).await?;
        match rec.state {
            JobState::Cancelled => return Ok(self.view(&rec)),
            JobState::Succeeded | JobState::Failed => {
                return Err(ServiceError::Conflict {
                    kind: "job-already-finished",
                    detail: format!("job {id} already finished ({})", rec.state.as_str()),
                });
            }
            JobState::Queued | JobState::Running => {}
        }
        // Flag first: if the dispatcher takes the job concurrently, the runner sees the flag at
        // its first step.
        if let Some(l) = lock(&self.live).get(id) {
            l.cancel.store(true, Ordering::Relaxed);
        }
        let removed = if self.shared.is_some() {
            rec.state == JobState::Queued
        } else {
            lock(&self.queue).remove(id)
        };
        if removed {
            let fence = self
                .shared
                .as_ref()
                .map(|_| (JobState::Queued, rec.attempt));
            rec.state = JobState::Cancelled;
            rec.ended_ms = Some(now_ms());
            rec.failure = Some(JobFailure {
                error_type: "cancelled".into(),
                detail: "cancelled by request while queued".into(),
            });
            if let Some(rec) = self.finish(rec, fence).await? {
                self.metrics.cancelled.fetch_add(1, Ordering::Relaxed);
                return Ok(self.view(&rec));
            }
        }
        if self.shared.is_some() {
            // Running, or leased by a worker meanwhile: whichever worker runs it is told.
            let key = id.to_string();
            self.db(move |s| s.request_cancel(&key)).await?;
        }
        let key = id.to_string();
        let rec = self
            .db(move |s| s.get(&key))
            .await?
            .ok_or_else(|| ServiceError::NotFound(id.to_string()))?;
        Ok(self.view(&rec))
    }

    /// Delete a finished job and its artefacts.
    pub async fn delete(&self, tenant: &str, id: &str) -> Result<(), ServiceError> {
        let rec = self.owned(tenant, id).await?;
        if !rec.state.is_terminal() {
            return Err(ServiceError::Conflict {
                kind: "job-not-finished",
                detail: format!(
                    "job {id} is {}; cancel it first, then delete it",
                    rec.state.as_str()
                ),
            });
        }
        let key = id.to_string();
        self.db(move |s| s.delete(&key)).await?;
        Ok(())
    }

    /// Bytes and record of a finished job's artefact.
    pub async fn artifact(
        &self,
        tenant: &str,
        id: &str,
        name: &str,
    ) -> Result<(Vec<u8>, Artifact), ServiceError> {
        let rec = self.owned(tenant, id).await?;
        if rec.state != JobState::Succeeded {
            return Err(ServiceError::Conflict {
                kind: "job-not-finished",
                detail: format!(
                    "job {id} is {}; artefacts exist once it SUCCEEDED",
                    rec.state.as_str()
                ),
            });
        }
        let a = rec
            .artifacts
            .iter()
            .find(|a| a.name == name)
            .cloned()
            .ok_or_else(|| ServiceError::NotFound(format!("{id}/artifacts/{name}")))?;
        let (key, file) = (id.to_string(), name.to_string());
        let bytes = self
            .db(move |s| s.artifact(&key, &file))
            .await?
            .ok_or_else(|| {
                ServiceError::Internal(format!("artefact {name} of job {id} is missing"))
            })?;
        Ok((bytes, a))
    }

    async fn dispatch(self: Arc<Self>) {
        loop {
            let Ok(permit) = self.slots.clone().acquire_owned().await else {
                return;
            };
            let id = loop {
                if self.is_draining() {
                    return;
                }
                if let Some(id) = lock(&self.queue).pop() {
                    break id;
                }
                self.wake.notified().await;
            };
            let svc = self.clone();
            tokio::spawn(async move {
                if let Err(e) = svc.clone().run(&id, permit).await {
                    tracing::error!(job = %id, "job run failed in the service: {e}");
                }
            });
        }
    }

    async fn run(
        self: Arc<Self>,
        id: &str,
        _permit: OwnedSemaphorePermit,
    ) -> Result<(), ServiceError> {
        let key = id.to_string();
        let Some(mut rec) = self.db(move |s| s.get(&key)).await? else {
            return Ok(());
        };
        if rec.state.is_terminal() {
            return Ok(());
        }
        let (tx, cancel) = {
            let live = lock(&self.live);
            match live.get(id) {
                Some(l) => (l.tx.clone(), l.cancel.clone()),
                None => return Ok(()),
            }
        };
        rec.state = JobState::Running;
        rec.attempt += 1;
        rec.started_ms = Some(now_ms());
        let evs = state_events(&mut rec);
        let r2 = rec.clone();
        self.db(move |s| s.update(&r2, &evs)).await?;
        self.execute(rec, tx, cancel, None).await
    }

    /// Run a job to its end: progress to watchers, stop conditions, artefacts, the terminal
    /// record. `fence`: the attempt of this process's lease (shared store), which every write
    /// is conditional on and which a heartbeat keeps.
    async fn execute(
        self: Arc<Self>,
        mut rec: JobRecord,
        tx: Arc<watch::Sender<Arc<Snapshot>>>,
        cancel: Arc<AtomicBool>,
        fence: Option<u32>,
    ) -> Result<(), ServiceError> {
        let id = rec.id.clone();
        let id = id.as_str();
        let lost = Arc::new(AtomicBool::new(false));
        let heartbeat = fence.map(|attempt| self.clone().heartbeat(id, attempt, &cancel, &lost));
        let seq = rec.sequence;
        tx.send_modify(|s| {
            *s = Arc::new(Snapshot {
                sequence: seq,
                ..(**s).clone()
            })
        });
        tracing::info!(job = %id, attempt = rec.attempt, "job running");
        self.running.fetch_add(1, Ordering::Relaxed);
        let (models, pool, spec) = (self.models.clone(), self.pool.clone(), rec.spec.clone());
        let (hard, deadline_ms) = (self.hard_stop.clone(), rec.deadline_ms);
        let (tx2, cancel2, lost2) = (tx.clone(), cancel.clone(), lost.clone());
        let mut publish = self.progress_publisher(id);
        let svc = self.clone();
        let t0 = std::time::Instant::now();
        let out = tokio::task::spawn_blocking(move || {
            pool.install(|| {
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    run_job(
                        &models,
                        &spec,
                        &mut |p| {
                            svc.metrics.steps.fetch_add(1, Ordering::Relaxed);
                            publish(&svc, p);
                            tx2.send_modify(|s| {
                                let mut n = (**s).clone();
                                if p.preview.is_some() {
                                    n.previews += 1;
                                    n.last_preview = Some(p.clone());
                                }
                                n.progress = Some(Progress {
                                    preview: None,
                                    ..p.clone()
                                });
                                *s = Arc::new(n);
                            });
                        },
                        &|| {
                            if lost2.load(Ordering::Relaxed) {
                                Some("lease lost".into())
                            } else if cancel2.load(Ordering::Relaxed) {
                                Some("cancelled by request".into())
                            } else if hard.load(Ordering::Relaxed) {
                                Some("server shutting down".into())
                            } else if now_ms() > deadline_ms {
                                Some("deadline exceeded".into())
                            } else {
                                None
                            }
                        },
                    )
                }))
            })
        })
        .await;
        if let Some(h) = heartbeat {
            h.abort();
        }
        self.running.fetch_sub(1, Ordering::Relaxed);
        let progress = tx.borrow().progress.clone();
        let at = progress
            .map(|p| {
                format!(
                    "at step {} of {} (sample {})",
                    p.step, p.total_steps, p.sample
                )
            })
            .unwrap_or_else(|| "before the first step".into());
        rec.ended_ms = Some(now_ms());
        match out {
            Err(join) => {
                rec.state = JobState::Failed;
                rec.failure = Some(JobFailure {
                    error_type: "internal".into(),
                    detail: format!("worker task failed: {join}"),
                });
            }
            Ok(Err(_panic)) => {
                rec.state = JobState::Failed;
                rec.failure = Some(JobFailure {
                    error_type: "internal".into(),
                    detail: "the job panicked in the engine (see server log)".into(),
                });
            }
            Ok(Ok(Ok(output))) => {
                let key = id.to_string();
                let files = output.files;
                if lost.load(Ordering::Relaxed) {
                    tracing::warn!(job = %id, "lease lost before the artefacts were stored; another worker re-runs it");
                    return Ok(());
                }
                let artifacts = self.db(move |s| s.put_artifacts(&key, &files)).await;
                match artifacts {
                    Ok(a) => {
                        rec.state = JobState::Succeeded;
                        rec.artifacts = a;
                        self.metrics
                            .run_seconds_sum_ms
                            .fetch_add(t0.elapsed().as_millis() as u64, Ordering::Relaxed);
                    }
                    Err(e) => {
                        rec.state = JobState::Failed;
                        rec.failure = Some(JobFailure {
                            error_type: "internal".into(),
                            detail: format!("writing artefacts failed: {e}"),
                        });
                    }
                }
            }
            Ok(Ok(Err(RunError::Stopped(reason)))) => {
                if lost.load(Ordering::Relaxed) {
                    tracing::warn!(job = %id, "lease lost {at}; another worker re-runs it");
                    return Ok(());
                } else if cancel.load(Ordering::Relaxed) {
                    rec.state = JobState::Cancelled;
                    rec.failure = Some(JobFailure {
                        error_type: "cancelled".into(),
                        detail: format!("cancelled by request {at}"),
                    });
                } else if self.hard_stop.load(Ordering::Relaxed) {
                    return self.stopped_by_shutdown(rec, fence, &at).await;
                } else {
                    rec.state = JobState::Failed;
                    rec.failure = Some(JobFailure {
                        error_type: "deadline-exceeded".into(),
                        detail: format!(
                            "job deadline of {} s exceeded {at} ({reason})",
                            rec.spec.deadline_seconds
                        ),
                    });
                }
            }
            Ok(Ok(Err(e))) => {
                rec.state = JobState::Failed;
                rec.failure = Some(JobFailure {
                    error_type: e.error_type().into(),
                    detail: e.to_string(),
                });
            }
        }
        match rec.state {
            JobState::Succeeded => &self.metrics.succeeded,
            JobState::Cancelled => &self.metrics.cancelled,
            _ => &self.metrics.failed,
        }
        .fetch_add(1, Ordering::Relaxed);
        tracing::info!(job = %id, state = rec.state.as_str(), "job finished");
        let fence = fence.map(|attempt| (JobState::Running, attempt));
        if self.finish(rec, fence).await?.is_none() {
            tracing::warn!(job = %id, "lease lost: another worker's attempt owns the job; this result is dropped");
        }
        Ok(())
    }

    /// Commit a terminal record (artefact events, state, done) and retire its live entry.
    /// With a `fence` (state, attempt) the write happens only while the stored job is still
    /// there; `None` when it was fenced out (nothing written, the live entry kept).
    async fn finish(
        &self,
        mut rec: JobRecord,
        fence: Option<(JobState, u32)>,
    ) -> Result<Option<JobRecord>, ServiceError> {
        let mut evs = Vec::new();
        for a in rec.artifacts.clone() {
            rec.sequence += 1;
            let data = serde_json::to_string(&api::artifact_view(&rec.id, &a)).unwrap_or_default();
            evs.push(event(&rec, "artifact", data));
        }
        evs.extend(state_events(&mut rec));
        let r2 = rec.clone();
        let written = self
            .db(move |s| match fence {
                Some((state, attempt)) => s.update_if(&r2, &evs, state, attempt),
                None => s.update(&r2, &evs).map(|_| true),
            })
            .await?;
        if !written {
            return Ok(None);
        }
        if let Some(l) = lock(&self.live).remove(&rec.id) {
            let seq = rec.sequence;
            l.tx.send_modify(|s| {
                *s = Arc::new(Snapshot {
                    sequence: seq,
                    ..(**s).clone()
                })
            });
        }
        Ok(Some(rec))
    }

    /// Stop admitting (503), let running jobs finish for up to `drain`, then stop them at their
    /// next step (they stay RUNNING in the store and re-run on the next start), close watchers.
    pub async fn shutdown(&self, drain: Duration) {
        self.draining.store(true, Ordering::Relaxed);
        self.wake.notify_waiters();
        self.wake.notify_one();
        let t0 = std::time::Instant::now();
        while self.running() > 0 && t0.elapsed() < drain {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        if self.running() > 0 {
            tracing::warn!(
                running = self.running(),
                "drain timeout: stopping running jobs; they re-run on restart"
            );
            self.hard_stop.store(true, Ordering::Relaxed);
            let t1 = std::time::Instant::now();
            while self.running() > 0 && t1.elapsed() < Duration::from_secs(10) {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        }
        let _ = self.shutdown_tx.send(true);
    }
}

/// Most jobs on one page of `list`.
pub const MAX_PAGE_SIZE: u32 = 500;

/// Jobs per page when the client gives no page size (REST: absent, gRPC: 0).
pub const DEFAULT_PAGE_SIZE: u32 = 50;

fn encode_token(id: &str) -> String {
    use base64::Engine as _;
    base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(format!("after:{id}"))
}

/// A page token is a cursor: base64url (no padding) of `after:` and a job id. Any well-formed
/// cursor is valid (the page starts after that id, known or not), so the OpenAPI pattern
/// `^YWZ0ZXI6([A-Za-z0-9_-]{4})*$` describes exactly the tokens accepted.
fn decode_token(t: &str) -> Option<String> {
    use base64::Engine as _;
    let b = base64::engine::general_purpose::URL_SAFE_NO_PAD
        .decode(t)
        .ok()?;
    String::from_utf8_lossy(&b)
        .strip_prefix("after:")
        .map(str::to_string)
}
