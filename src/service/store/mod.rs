//! The durable job store: jobs, their event log, idempotency keys and artefacts.
//!
//! Why it exists: a job that got 202 must survive a crash and reach exactly one terminal state.
//! [`JobStore`] is that promise as a trait, with two real implementations that pass the same
//! contract tests (`tests/store_contract.rs`):
//!
//! - [`sqlite::SqliteStore`], the embedded default: one SQLite file in WAL mode with
//!   `synchronous = FULL`, artefacts as files beside it;
//! - [`postgres::PgStore`] (`serve --store postgres://…`): the same rows in PostgreSQL, artefacts
//!   as `bytea`, schema migrations versioned and run at start.
//!
//! Every state change is one transaction that updates the job row *and* appends its events, so
//! the event log (what SSE and `WatchJob` replay by sequence) never disagrees with the job.
//! Once [`JobStore::insert`] returns, the job is durable. `RUNNING` is recorded, but a job found
//! `RUNNING` at start-up is re-queued (at-least-once execution; the fixed seed makes the re-run
//! produce the same bytes).
//!
//! The stores are synchronous; async callers run them on tokio's blocking pool.

use std::path::Path;
use std::str::FromStr;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::spec::JobSpec;

mod doc;
pub mod postgres;
pub mod sqlite;

/// Errors of the store layer.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// SQLite refused (I/O, corruption, constraint).
    #[error("job store: {0}")]
    Sqlite(#[from] rusqlite::Error),
    /// PostgreSQL refused or is unreachable.
    #[error("job store (PostgreSQL): {0}")]
    Postgres(#[from] ::postgres::Error),
    /// An artefact file could not be written or read.
    #[error("job store: {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A stored row does not decode (written by an incompatible version, or corrupted).
    #[error("job store: corrupt row for job {id}: {detail}")]
    Corrupt {
        /// Job id.
        id: String,
        /// What failed to decode.
        detail: String,
    },
    /// The database's schema is newer than this binary knows.
    #[error(
        "job store: the database is at schema version {found}, this physnap knows up to {known}; \
         run a newer physnap"
    )]
    SchemaTooNew {
        /// The database's version.
        found: i32,
        /// The newest this binary migrates to.
        known: i32,
    },
}

impl StoreError {
    /// Machine-readable kind.
    pub fn error_type(&self) -> &'static str {
        match self {
            StoreError::Sqlite(_) | StoreError::Postgres(_) | StoreError::Io { .. } => "store",
            StoreError::Corrupt { .. } | StoreError::SchemaTooNew { .. } => "store_corrupt",
        }
    }
}

/// Where jobs are stored: `--store sqlite` (the default: `jobs.sqlite3` and `artifacts/` in the
/// data directory) or `--store postgres://user:password@host:port/db`.
#[derive(Clone, PartialEq, Eq)]
pub enum StoreLocation {
    /// SQLite in the data directory.
    Sqlite,
    /// A PostgreSQL connection URL (`postgres://` or `postgresql://`).
    Postgres(String),
}

impl std::fmt::Debug for StoreLocation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{self}")
    }
}

/// Shown with the password replaced by `***` (the location is logged at start).
impl std::fmt::Display for StoreLocation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StoreLocation::Sqlite => f.write_str("sqlite"),
            StoreLocation::Postgres(url) => f.write_str(&redact_password(url)),
        }
    }
}

/// `scheme://user:password@host/...` → `scheme://user:***@host/...`.
fn redact_password(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_string();
    };
    let (auth, host) = match rest.rsplit_once('@') {
        Some(p) => p,
        None => return url.to_string(),
    };
    match auth.split_once(':') {
        Some((user, _)) => format!("{scheme}://{user}:***@{host}"),
        None => url.to_string(),
    }
}

/// A `--store` value that is neither `sqlite` nor a PostgreSQL URL.
#[derive(Debug, thiserror::Error)]
#[error("invalid store: {value:?} (must be `sqlite` or a `postgres://` / `postgresql://` URL)")]
pub struct BadStoreLocation {
    /// What was given (password redacted).
    pub value: String,
}

impl FromStr for StoreLocation {
    type Err = BadStoreLocation;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim();
        if t.eq_ignore_ascii_case("sqlite") {
            return Ok(StoreLocation::Sqlite);
        }
        let lower = t.to_ascii_lowercase();
        let pg = ["postgres://", "postgresql://"]
            .iter()
            .any(|p| lower.starts_with(p) && lower.len() > p.len());
        if pg {
            return Ok(StoreLocation::Postgres(t.to_string()));
        }
        Err(BadStoreLocation {
            value: redact_password(t),
        })
    }
}

/// Open the store at `location`; SQLite lives under `data_dir`.
pub fn open(location: &StoreLocation, data_dir: &Path) -> Result<Box<dyn JobStore>, StoreError> {
    Ok(match location {
        StoreLocation::Sqlite => Box::new(sqlite::SqliteStore::open(data_dir)?),
        StoreLocation::Postgres(url) => Box::new(postgres::PgStore::connect(url)?),
    })
}

/// The durable job store. Every method is one transaction (or one read); every write is
/// durable when it returns.
pub trait JobStore: Send {
    /// `sqlite` or `postgres` (logged, and in metrics).
    fn backend(&self) -> &'static str;

    /// Insert a new job with its first events, and its idempotency key `(key, request hash)`,
    /// in one transaction.
    fn insert(
        &mut self,
        job: &JobRecord,
        events: &[StoredEvent],
        idempotency: Option<(&str, &str)>,
    ) -> Result<(), StoreError>;

    /// Write the job's mutable fields and append `events`, in one transaction.
    fn update(&mut self, job: &JobRecord, events: &[StoredEvent]) -> Result<(), StoreError>;

    /// Like [`JobStore::update`], but only while the stored job is still in `state` at
    /// `attempt` (the fencing token: a worker whose lease was taken over, or an API replica
    /// cancelling a job a worker just leased, writes nothing). False when fenced out. A state
    /// other than RUNNING ends the job's lease.
    fn update_if(
        &mut self,
        job: &JobRecord,
        events: &[StoredEvent],
        state: JobState,
        attempt: u32,
    ) -> Result<bool, StoreError>;

    /// Lease the oldest job that is QUEUED, or RUNNING under an expired lease, to `worker`
    /// until `now_ms + lease_ms`: it becomes RUNNING with `attempt + 1` and `started_ms =
    /// now_ms` (no event is written: the caller appends the RUNNING event with
    /// [`JobStore::update_if`]). Concurrent callers never get the same job.
    fn lease_next(
        &mut self,
        worker: &str,
        now_ms: i64,
        lease_ms: i64,
    ) -> Result<Option<Lease>, StoreError>;

    /// Extend the lease of `id` at `attempt` to `now_ms + lease_ms`. `None`: the lease is lost
    /// (the job was re-leased or ended); otherwise whether a cancel was requested.
    fn heartbeat(
        &mut self,
        id: &str,
        attempt: u32,
        now_ms: i64,
        lease_ms: i64,
    ) -> Result<Option<bool>, StoreError>;

    /// Ask whichever worker runs `id` to cancel it (seen at its next heartbeat, or at once
    /// through [`Channel::Cancel`]).
    fn request_cancel(&mut self, id: &str) -> Result<(), StoreError>;

    /// Tell other processes something that is not stored (progress, cancels). Committed events
    /// are announced by the writes themselves ([`Channel::Events`]). A no-op where no other
    /// process can share the store (SQLite).
    fn notify(&mut self, channel: Channel, payload: &str) -> Result<(), StoreError>;

    /// The job an idempotency key was first used for: `(request_hash, job_id)`.
    fn idempotency(
        &mut self,
        tenant: &str,
        key: &str,
    ) -> Result<Option<(String, String)>, StoreError>;

    /// One job.
    fn get(&mut self, id: &str) -> Result<Option<JobRecord>, StoreError>;

    /// A tenant's jobs with id > `after`, oldest first, at most `limit`.
    fn list(
        &mut self,
        tenant: &str,
        after: Option<&str>,
        limit: usize,
    ) -> Result<Vec<JobRecord>, StoreError>;

    /// Jobs that were admitted but never finished (QUEUED or RUNNING), oldest first.
    fn unfinished(&mut self) -> Result<Vec<JobRecord>, StoreError>;

    /// A job's events with sequence > `after`, in order.
    fn events_after(&mut self, id: &str, after: u64) -> Result<Vec<StoredEvent>, StoreError>;

    /// Remove a job, its events, its idempotency keys and its artefacts.
    fn delete(&mut self, id: &str) -> Result<(), StoreError>;

    /// Number of jobs per state (for metrics).
    fn count_by_state(&mut self) -> Result<Vec<(String, u64)>, StoreError>;

    /// Store a job's artefacts `(name, bytes)`, durably, replacing any of the same name (a
    /// re-run writes the same bytes). Returns their records, in order.
    fn put_artifacts(
        &mut self,
        id: &str,
        files: &[(String, Vec<u8>)],
    ) -> Result<Vec<Artifact>, StoreError>;

    /// The bytes of a stored artefact.
    fn artifact(&mut self, id: &str, name: &str) -> Result<Option<Vec<u8>>, StoreError>;
}

/// A job leased to a worker.
#[derive(Debug, Clone, PartialEq)]
pub struct Lease {
    /// The job, now RUNNING at its new attempt.
    pub job: JobRecord,
    /// Whether a cancel was requested before the lease.
    pub cancel_requested: bool,
}

/// The notification channels between processes sharing a store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channel {
    /// `<job id> <sequence> <kind>` of a job's last committed event.
    Events,
    /// A job's latest progress, `<job id> <progress JSON>`.
    Progress,
    /// `<job id>`: a cancel was requested.
    Cancel,
}

impl Channel {
    /// The channel's name (PostgreSQL `LISTEN` / `NOTIFY`).
    pub fn name(self) -> &'static str {
        match self {
            Channel::Events => "physnap_events",
            Channel::Progress => "physnap_progress",
            Channel::Cancel => "physnap_cancel",
        }
    }

    /// The channel of a name.
    pub fn of(name: &str) -> Option<Channel> {
        [Channel::Events, Channel::Progress, Channel::Cancel]
            .into_iter()
            .find(|c| c.name() == name)
    }
}

/// The record of an artefact's bytes.
pub fn artifact_record(name: &str, bytes: &[u8]) -> Artifact {
    Artifact {
        name: name.to_string(),
        size_bytes: bytes.len() as u64,
        sha256: format!("{:x}", Sha256::digest(bytes)),
    }
}

/// The columns of a job row, as both stores read them; [`RawJob::decode`] is the one place a
/// row becomes a [`JobRecord`].
pub(crate) struct RawJob {
    pub id: String,
    pub tenant: String,
    pub state: String,
    pub spec: String,
    pub points: Vec<u8>,
    pub created_ms: i64,
    pub started_ms: Option<i64>,
    pub ended_ms: Option<i64>,
    pub deadline_ms: i64,
    pub attempt: i64,
    pub sequence: i64,
    pub error_type: Option<String>,
    pub error_detail: Option<String>,
    pub artifacts: String,
}

/// The job columns, in [`RawJob`]'s order.
pub(crate) const COLUMNS: &str = "id, tenant, state, spec, points, created_ms, started_ms, \
    ended_ms, deadline_ms, attempt, sequence, error_type, error_detail, artifacts";

impl RawJob {
    /// The stored form of a record.
    pub fn encode(job: &JobRecord) -> RawJob {
        let (spec, points) = doc::spec_to_row(&job.spec);
        RawJob {
            id: job.id.clone(),
            tenant: job.tenant.clone(),
            state: job.state.as_str().to_string(),
            spec,
            points,
            created_ms: job.created_ms,
            started_ms: job.started_ms,
            ended_ms: job.ended_ms,
            deadline_ms: job.deadline_ms,
            attempt: i64::from(job.attempt),
            sequence: job.sequence as i64,
            error_type: job.failure.as_ref().map(|f| f.error_type.clone()),
            error_detail: job.failure.as_ref().map(|f| f.detail.clone()),
            artifacts: serde_json::to_string(&job.artifacts).unwrap_or_else(|_| "[]".into()),
        }
    }

    /// The record a row holds.
    pub fn decode(self) -> Result<JobRecord, StoreError> {
        let corrupt = |detail: String| StoreError::Corrupt {
            id: self.id.clone(),
            detail,
        };
        Ok(JobRecord {
            state: JobState::parse(&self.state)
                .ok_or_else(|| corrupt(format!("state {:?}", self.state)))?,
            spec: doc::spec_from_row(&self.id, &self.spec, &self.points)?,
            attempt: u32::try_from(self.attempt)
                .map_err(|_| corrupt(format!("attempt {}", self.attempt)))?,
            sequence: u64::try_from(self.sequence)
                .map_err(|_| corrupt(format!("sequence {}", self.sequence)))?,
            failure: self.error_type.map(|error_type| JobFailure {
                error_type,
                detail: self.error_detail.unwrap_or_default(),
            }),
            artifacts: serde_json::from_str(&self.artifacts).map_err(|e| corrupt(e.to_string()))?,
            tenant: self.tenant,
            created_ms: self.created_ms,
            started_ms: self.started_ms,
            ended_ms: self.ended_ms,
            deadline_ms: self.deadline_ms,
            id: self.id,
        })
    }
}

/// Job states. Terminal: `Succeeded`, `Failed`, `Cancelled`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum JobState {
    /// Admitted, waiting for a worker.
    Queued,
    /// On the worker pool.
    Running,
    /// Artefacts committed.
    Succeeded,
    /// Failed (the error says why, e.g. `deadline-exceeded`).
    Failed,
    /// Cancelled by its tenant.
    Cancelled,
}

impl JobState {
    /// Wire name (`QUEUED`, ...).
    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "QUEUED",
            JobState::Running => "RUNNING",
            JobState::Succeeded => "SUCCEEDED",
            JobState::Failed => "FAILED",
            JobState::Cancelled => "CANCELLED",
        }
    }

    /// Parse a wire name.
    pub fn parse(s: &str) -> Option<JobState> {
        Some(match s {
            "QUEUED" => JobState::Queued,
            "RUNNING" => JobState::Running,
            "SUCCEEDED" => JobState::Succeeded,
            "FAILED" => JobState::Failed,
            "CANCELLED" => JobState::Cancelled,
            _ => return None,
        })
    }

    /// Whether no further transition can happen.
    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            JobState::Succeeded | JobState::Failed | JobState::Cancelled
        )
    }
}

/// A committed artefact.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Artifact {
    /// File name (`model.glb`, ...).
    pub name: String,
    /// Size in bytes.
    pub size_bytes: u64,
    /// Hex sha256.
    pub sha256: String,
}

/// Why a job failed or was cancelled.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JobFailure {
    /// Stable kind, e.g. `deadline-exceeded`, `cancelled`, `engine`.
    pub error_type: String,
    /// Human-readable detail.
    pub detail: String,
}

/// A job row.
#[derive(Debug, Clone, PartialEq)]
pub struct JobRecord {
    /// UUIDv7 (sorts by creation time).
    pub id: String,
    /// Owner.
    pub tenant: String,
    /// Current state.
    pub state: JobState,
    /// The validated request.
    pub spec: JobSpec,
    /// Creation time, Unix ms.
    pub created_ms: i64,
    /// Last start time, Unix ms.
    pub started_ms: Option<i64>,
    /// End time, Unix ms.
    pub ended_ms: Option<i64>,
    /// Absolute deadline, Unix ms.
    pub deadline_ms: i64,
    /// Runs started (a re-run after a restart increments it).
    pub attempt: u32,
    /// Sequence of the last persisted event.
    pub sequence: u64,
    /// Set when FAILED or CANCELLED.
    pub failure: Option<JobFailure>,
    /// Set when SUCCEEDED.
    pub artifacts: Vec<Artifact>,
}

/// A persisted event.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoredEvent {
    /// Monotonic per job, from 1.
    pub sequence: u64,
    /// `state`, `artifact` or `done`.
    pub kind: String,
    /// JSON payload.
    pub data: String,
}
