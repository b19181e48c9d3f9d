//! The durable job store: jobs, their event log and idempotency keys, in one SQLite file.
//!
//! Why it exists: a job that got 202 must survive a crash and reach exactly one terminal state.
//! SQLite in WAL mode with `synchronous = FULL` fsyncs every committed transaction, so once
//! [`Store::insert`] returns the job is on disk. Every state change is one transaction that
//! updates the job row *and* appends its events, so the event log (what SSE and `WatchJob`
//! replay by sequence) never disagrees with the job. `RUNNING` is recorded, but a job found
//! `RUNNING` at start-up is simply re-queued (at-least-once execution; the fixed seed makes the
//! re-run produce the same bytes).
//!
//! The store is synchronous; async callers run it on tokio's blocking pool.

use std::path::Path;

use rusqlite::{Connection, OptionalExtension, params};
use serde::{Deserialize, Serialize};

use super::spec::JobSpec;
use crate::engine::generate::{JointMotion, RepairMode, Retrieval};
use crate::engine::sample::Sampler;
use crate::engine::schedule::{NUM_STEPS, timesteps};

/// Errors of the store layer.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// SQLite refused (I/O, corruption, constraint).
    #[error("job store: {0}")]
    Sqlite(#[from] rusqlite::Error),
    /// A stored row does not decode (written by an incompatible version, or corrupted).
    #[error("job store: corrupt row for job {id}: {detail}")]
    Corrupt {
        /// Job id.
        id: String,
        /// What failed to decode.
        detail: String,
    },
}

impl StoreError {
    /// Machine-readable kind.
    pub fn error_type(&self) -> &'static str {
        match self {
            StoreError::Sqlite(_) => "store",
            StoreError::Corrupt { .. } => "store_corrupt",
        }
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

/// Persistence form of [`JobSpec`] (points go in a separate f32le blob).
#[derive(Serialize, Deserialize)]
struct SpecDoc {
    category: Option<(usize, String)>,
    w_pc: f64,
    w_pen: f64,
    w_mob: f64,
    /// n_g as in the paper: the steps with diffusion time t < this are guided.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    n_g_t: Option<u32>,
    /// Rows written before n_g had the paper's meaning hold it as a count: the last this many
    /// of the `steps` reverse steps were guided ([`threshold_of_final_steps`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    n_g: Option<u32>,
    tau: f64,
    #[serde(default)]
    guidance_max_step: Option<f64>,
    /// Absent in specs stored before refinement existed: those were accepted without it.
    #[serde(default)]
    refine_steps: u32,
    /// Absent in specs stored before physics-only refinement existed: those ran none.
    #[serde(default)]
    refine_physics_steps: u32,
    sampler: String,
    #[serde(default)]
    eta: f64,
    steps: u32,
    seed: u64,
    samples: u32,
    deadline_seconds: f64,
    preview_every: u32,
    resolution: u32,
    /// Rows written before retrieval existed ran without it.
    #[serde(default = "retrieval_off")]
    retrieval: String,
    /// Rows written before category guidance existed ran without it.
    #[serde(default)]
    category_guidance: f64,
    /// Rows written before the guidance could be limited to t < 500 guided every step.
    #[serde(default = "every_step")]
    category_guidance_below: u32,
    /// Rows written before joint motions could be chosen kept NAP's screws.
    #[serde(default = "joint_motion_screw")]
    joint_motion: String,
    /// Rows written before cameras could be given had none.
    #[serde(default)]
    cameras: Vec<[f32; 3]>,
    /// ... and so no ℓ_free.
    #[serde(default)]
    w_free: f64,
    /// Rows written before repair could be chosen were accepted by a pipeline without it.
    #[serde(default = "repair_off")]
    repair: String,
    /// ... and without a scale hypothesis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    scale: Option<f64>,
    /// ... and with the scan in the canonical frame: `(up, yaw, translation)` of the scan's
    /// frame when it was estimated at submission (`frame: auto`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    frame: Option<([f64; 3], f64, [f64; 3])>,
}

/// The diffusion-time threshold that guides exactly the last `last` of `steps` reverse steps
/// over the schedule: t < (the time of the `last`-th last step) + 1. How rows stored with
/// n_g as a count of final steps are read.
fn threshold_of_final_steps(steps: u32, last: u32) -> u32 {
    let times = timesteps(NUM_STEPS, steps as usize);
    let n = (last as usize).min(times.len());
    if n == 0 {
        0
    } else {
        (times[times.len() - n] + 1) as u32
    }
}

fn repair_off() -> String {
    RepairMode::Off.as_str().into()
}

fn joint_motion_screw() -> String {
    crate::engine::generate::JointMotion::Screw.as_str().into()
}

fn every_step() -> u32 {
    NUM_STEPS as u32
}

fn retrieval_off() -> String {
    "off".into()
}

fn spec_to_row(s: &JobSpec) -> (String, Vec<u8>) {
    let doc = SpecDoc {
        category: s.category.clone(),
        w_pc: s.w_pc,
        w_pen: s.w_pen,
        w_mob: s.w_mob,
        n_g_t: Some(s.n_g),
        n_g: None,
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
        cameras: s.cameras.clone(),
        w_free: s.w_free,
        repair: s.repair.as_str().to_string(),
        scale: s.scale,
        frame: s.frame.map(|f| (f.up.into(), f.yaw, f.translation.into())),
    };
    let mut blob = Vec::with_capacity(s.points.len() * 12);
    for p in &s.points {
        for c in p {
            blob.extend_from_slice(&c.to_le_bytes());
        }
    }
    // Serialising plain numbers and strings cannot fail.
    (serde_json::to_string(&doc).unwrap_or_default(), blob)
}

fn spec_from_row(id: &str, json: &str, blob: &[u8]) -> Result<JobSpec, StoreError> {
    let corrupt = |detail: String| StoreError::Corrupt {
        id: id.to_string(),
        detail,
    };
    let d: SpecDoc = serde_json::from_str(json).map_err(|e| corrupt(e.to_string()))?;
    if !blob.len().is_multiple_of(12) {
        return Err(corrupt(format!("points blob of {} bytes", blob.len())));
    }
    let f = |c: &[u8]| f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
    let sampler = match d.sampler.as_str() {
        "ddpm" => Sampler::Ddpm,
        "ddim" => Sampler::Ddim { eta: d.eta },
        other => return Err(corrupt(format!("unknown sampler {other:?}"))),
    };
    let retrieval = Retrieval::parse(&d.retrieval)
        .ok_or_else(|| corrupt(format!("unknown retrieval {:?}", d.retrieval)))?;
    let joint_motion = JointMotion::parse(&d.joint_motion)
        .ok_or_else(|| corrupt(format!("unknown joint motion {:?}", d.joint_motion)))?;
    let repair = RepairMode::parse(&d.repair)
        .ok_or_else(|| corrupt(format!("unknown repair mode {:?}", d.repair)))?;
    let n_g = match (d.n_g_t, d.n_g) {
        (Some(t), _) => t,
        (None, Some(last)) => threshold_of_final_steps(d.steps, last),
        (None, None) => return Err(corrupt("no n_g".into())),
    };
    Ok(JobSpec {
        points: blob
            .chunks_exact(12)
            .map(|c| [f(&c[0..4]), f(&c[4..8]), f(&c[8..12])])
            .collect(),
        category: d.category,
        w_pc: d.w_pc,
        w_pen: d.w_pen,
        w_mob: d.w_mob,
        n_g,
        tau: d.tau,
        guidance_max_step: d.guidance_max_step,
        refine_steps: d.refine_steps,
        refine_physics_steps: d.refine_physics_steps,
        sampler,
        steps: d.steps,
        seed: d.seed,
        samples: d.samples,
        deadline_seconds: d.deadline_seconds,
        preview_every: d.preview_every,
        resolution: d.resolution,
        retrieval,
        category_guidance: d.category_guidance,
        category_guidance_below: d.category_guidance_below,
        joint_motion,
        cameras: d.cameras,
        w_free: d.w_free,
        repair,
        scale: d.scale,
        frame: d
            .frame
            .and_then(|(up, yaw, t)| crate::frame::ScanFrame::new(up, yaw, t).ok()),
    })
}

/// The SQLite job store.
pub struct Store {
    conn: Connection,
}

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    tenant TEXT NOT NULL,
    state TEXT NOT NULL,
    spec TEXT NOT NULL,
    points BLOB NOT NULL,
    created_ms INTEGER NOT NULL,
    started_ms INTEGER,
    ended_ms INTEGER,
    deadline_ms INTEGER NOT NULL,
    attempt INTEGER NOT NULL,
    sequence INTEGER NOT NULL,
    error_type TEXT,
    error_detail TEXT,
    artifacts TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS jobs_tenant ON jobs (tenant, id);
CREATE TABLE IF NOT EXISTS events (
    job_id TEXT NOT NULL,
    sequence INTEGER NOT NULL,
    kind TEXT NOT NULL,
    data TEXT NOT NULL,
    PRIMARY KEY (job_id, sequence)
);
CREATE TABLE IF NOT EXISTS idempotency (
    tenant TEXT NOT NULL,
    key TEXT NOT NULL,
    request_hash TEXT NOT NULL,
    job_id TEXT NOT NULL,
    PRIMARY KEY (tenant, key)
);
";

const COLUMNS: &str = "id, tenant, state, spec, points, created_ms, started_ms, ended_ms, \
    deadline_ms, attempt, sequence, error_type, error_detail, artifacts";

fn row_to_record(r: &rusqlite::Row<'_>) -> rusqlite::Result<Result<JobRecord, StoreError>> {
    let id: String = r.get(0)?;
    let state: String = r.get(2)?;
    let spec: String = r.get(3)?;
    let points: Vec<u8> = r.get(4)?;
    let error_type: Option<String> = r.get(11)?;
    let error_detail: Option<String> = r.get(12)?;
    let artifacts: String = r.get(13)?;
    let tenant: String = r.get(1)?;
    let (created_ms, started_ms, ended_ms, deadline_ms): (i64, Option<i64>, Option<i64>, i64) =
        (r.get(5)?, r.get(6)?, r.get(7)?, r.get(8)?);
    let (attempt, sequence): (u32, i64) = (r.get(9)?, r.get(10)?);
    Ok((|| {
        let corrupt = |detail: String| StoreError::Corrupt {
            id: id.clone(),
            detail,
        };
        Ok(JobRecord {
            state: JobState::parse(&state).ok_or_else(|| corrupt(format!("state {state:?}")))?,
            spec: spec_from_row(&id, &spec, &points)?,
            tenant,
            created_ms,
            started_ms,
            ended_ms,
            deadline_ms,
            attempt,
            sequence: sequence as u64,
            failure: error_type.map(|error_type| JobFailure {
                error_type,
                detail: error_detail.unwrap_or_default(),
            }),
            artifacts: serde_json::from_str(&artifacts).map_err(|e| corrupt(e.to_string()))?,
            id: id.clone(),
        })
    })())
}

impl Store {
    /// Open (or create) the store at `path`: WAL journal, `synchronous = FULL`.
    pub fn open(path: &Path) -> Result<Store, StoreError> {
        let conn = Connection::open(path)?;
        let mode: String =
            conn.pragma_update_and_check(None, "journal_mode", "WAL", |r| r.get(0))?;
        if !mode.eq_ignore_ascii_case("wal") {
            tracing::warn!(mode, "SQLite refused WAL mode; continuing with {mode}");
        }
        conn.pragma_update(None, "synchronous", "FULL")?;
        conn.pragma_update(None, "foreign_keys", "ON")?;
        conn.busy_timeout(std::time::Duration::from_secs(5))?;
        conn.execute_batch(SCHEMA)?;
        Ok(Store { conn })
    }

    /// Insert a new job with its first events, and its idempotency key, in one transaction.
    pub fn insert(
        &mut self,
        job: &JobRecord,
        events: &[StoredEvent],
        idempotency: Option<(&str, &str)>,
    ) -> Result<(), StoreError> {
        let tx = self.conn.transaction()?;
        let (spec, points) = spec_to_row(&job.spec);
        tx.execute(
            &format!(
                "INSERT INTO jobs ({COLUMNS}) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14)"
            ),
            params![
                job.id,
                job.tenant,
                job.state.as_str(),
                spec,
                points,
                job.created_ms,
                job.started_ms,
                job.ended_ms,
                job.deadline_ms,
                job.attempt,
                job.sequence as i64,
                job.failure.as_ref().map(|f| f.error_type.clone()),
                job.failure.as_ref().map(|f| f.detail.clone()),
                serde_json::to_string(&job.artifacts).unwrap_or_else(|_| "[]".into()),
            ],
        )?;
        if let Some((key, hash)) = idempotency {
            tx.execute(
                "INSERT INTO idempotency (tenant, key, request_hash, job_id) VALUES (?1, ?2, ?3, ?4)",
                params![job.tenant, key, hash, job.id],
            )?;
        }
        append_events(&tx, &job.id, events)?;
        tx.commit()?;
        Ok(())
    }

    /// Write the job's mutable fields and append `events`, in one transaction.
    pub fn update(&mut self, job: &JobRecord, events: &[StoredEvent]) -> Result<(), StoreError> {
        let tx = self.conn.transaction()?;
        tx.execute(
            "UPDATE jobs SET state = ?2, started_ms = ?3, ended_ms = ?4, attempt = ?5, sequence = ?6, \
             error_type = ?7, error_detail = ?8, artifacts = ?9 WHERE id = ?1",
            params![
                job.id,
                job.state.as_str(),
                job.started_ms,
                job.ended_ms,
                job.attempt,
                job.sequence as i64,
                job.failure.as_ref().map(|f| f.error_type.clone()),
                job.failure.as_ref().map(|f| f.detail.clone()),
                serde_json::to_string(&job.artifacts).unwrap_or_else(|_| "[]".into()),
            ],
        )?;
        append_events(&tx, &job.id, events)?;
        tx.commit()?;
        Ok(())
    }

    /// The job an idempotency key was first used for: `(request_hash, job_id)`.
    pub fn idempotency(
        &self,
        tenant: &str,
        key: &str,
    ) -> Result<Option<(String, String)>, StoreError> {
        Ok(self
            .conn
            .query_row(
                "SELECT request_hash, job_id FROM idempotency WHERE tenant = ?1 AND key = ?2",
                params![tenant, key],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()?)
    }

    /// One job.
    pub fn get(&self, id: &str) -> Result<Option<JobRecord>, StoreError> {
        self.conn
            .query_row(
                &format!("SELECT {COLUMNS} FROM jobs WHERE id = ?1"),
                params![id],
                row_to_record,
            )
            .optional()?
            .transpose()
    }

    /// A tenant's jobs with id > `after`, oldest first, at most `limit`.
    pub fn list(
        &self,
        tenant: &str,
        after: Option<&str>,
        limit: usize,
    ) -> Result<Vec<JobRecord>, StoreError> {
        let mut stmt = self.conn.prepare(&format!(
            "SELECT {COLUMNS} FROM jobs WHERE tenant = ?1 AND id > ?2 ORDER BY id LIMIT ?3"
        ))?;
        let rows = stmt.query_map(
            params![tenant, after.unwrap_or(""), limit as i64],
            row_to_record,
        )?;
        let mut out = Vec::new();
        for r in rows {
            out.push(r??);
        }
        Ok(out)
    }

    /// Jobs that were admitted but never finished (QUEUED or RUNNING), oldest first.
    pub fn unfinished(&self) -> Result<Vec<JobRecord>, StoreError> {
        let mut stmt = self.conn.prepare(&format!(
            "SELECT {COLUMNS} FROM jobs WHERE state IN ('QUEUED', 'RUNNING') ORDER BY id"
        ))?;
        let rows = stmt.query_map([], row_to_record)?;
        let mut out = Vec::new();
        for r in rows {
            out.push(r??);
        }
        Ok(out)
    }

    /// A job's events with sequence > `after`.
    pub fn events_after(&self, id: &str, after: u64) -> Result<Vec<StoredEvent>, StoreError> {
        let mut stmt = self.conn.prepare(
            "SELECT sequence, kind, data FROM events WHERE job_id = ?1 AND sequence > ?2 ORDER BY sequence",
        )?;
        let rows = stmt.query_map(params![id, after as i64], |r| {
            Ok(StoredEvent {
                sequence: r.get::<_, i64>(0)? as u64,
                kind: r.get(1)?,
                data: r.get(2)?,
            })
        })?;
        Ok(rows.collect::<Result<_, _>>()?)
    }

    /// Remove a job, its events and its idempotency keys.
    pub fn delete(&mut self, id: &str) -> Result<(), StoreError> {
        let tx = self.conn.transaction()?;
        tx.execute("DELETE FROM events WHERE job_id = ?1", params![id])?;
        tx.execute("DELETE FROM idempotency WHERE job_id = ?1", params![id])?;
        tx.execute("DELETE FROM jobs WHERE id = ?1", params![id])?;
        tx.commit()?;
        Ok(())
    }

    /// Number of jobs per state (for metrics).
    pub fn count_by_state(&self) -> Result<Vec<(String, u64)>, StoreError> {
        let mut stmt = self
            .conn
            .prepare("SELECT state, COUNT(*) FROM jobs GROUP BY state")?;
        let rows = stmt.query_map([], |r| Ok((r.get(0)?, r.get::<_, i64>(1)? as u64)))?;
        Ok(rows.collect::<Result<_, _>>()?)
    }
}

fn append_events(
    tx: &rusqlite::Transaction<'_>,
    id: &str,
    events: &[StoredEvent],
) -> Result<(), StoreError> {
    for e in events {
        tx.execute(
            "INSERT INTO events (job_id, sequence, kind, data) VALUES (?1, ?2, ?3, ?4)",
            params![id, e.sequence as i64, e.kind, e.data],
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_stored_before_newer_options_keep_the_behaviour_they_were_accepted_with() {
        // A spec row as the first service release wrote it (no retrieval, category guidance,
        // guidance limit or joint motion): it still runs, as it was accepted.
        let json = r#"{"category":[1,"Door"],"w_pc":1.0,"w_pen":1.0,"w_mob":1.0,"n_g":200,
            "tau":0.1,"sampler":"ddim","steps":200,"seed":7,"samples":1,
            "deadline_seconds":600.0,"preview_every":0,"resolution":32}"#;
        let spec = spec_from_row("j", json, &[0u8; 24]).unwrap();
        assert_eq!(spec.points.len(), 2);
        assert_eq!(spec.retrieval, Retrieval::Off);
        assert_eq!(spec.category_guidance, 0.0);
        assert_eq!(spec.category_guidance_below, 1000);
        assert_eq!(spec.joint_motion, JointMotion::Screw);
        assert_eq!(spec.refine_physics_steps, 0);
        // n_g was then a count of final steps: the last 200 of 200 steps guided is every step
        // (t < 1000); the threshold read for any count guides exactly that many steps.
        assert_eq!(spec.n_g, 1000);
        for last in [0, 1, 7, 100, 200] {
            let old = json.replace(r#""n_g":200"#, &format!(r#""n_g":{last}"#));
            let t = spec_from_row("j", &old, &[]).unwrap().n_g as usize;
            let guided = timesteps(NUM_STEPS, 200).into_iter().filter(|&s| s < t);
            assert_eq!(guided.count(), last as usize, "{last}: t < {t}");
        }
        // And a spec round-trips through its row unchanged.
        let (json, blob) = spec_to_row(&JobSpec {
            refine_physics_steps: 7,
            ..spec.clone()
        });
        let back = spec_from_row("j", &json, &blob).unwrap();
        assert_eq!(
            back,
            JobSpec {
                refine_physics_steps: 7,
                ..spec
            }
        );
        assert_eq!(back.category_guidance_below, 1000);
        assert_eq!(back.seed, 7);
        let corrupt = spec_from_row("j", &json, &[0u8; 5])
            .unwrap_err()
            .to_string();
        assert!(corrupt.contains("5 bytes"), "{corrupt}");
    }

    #[test]
    fn rows_stored_before_cameras_and_repair_load_without_them() {
        // A spec row as the service wrote it before cameras, w_free and repair: it was accepted
        // by a pipeline without repair or ℓ_free, and loads as such.
        let json = r#"{"category":null,"w_pc":15.0,"w_pen":2.0,"w_mob":2.0,"n_g":100,
            "tau":1000.0,"guidance_max_step":0.02,"refine_steps":30,"refine_physics_steps":0,
            "sampler":"ddim","eta":0.0,"steps":200,"seed":3,"samples":1,
            "deadline_seconds":3600.0,"preview_every":0,"resolution":32,"retrieval":"empty",
            "category_guidance":0.0,"category_guidance_below":1000,"joint_motion":"dominant"}"#;
        let spec = spec_from_row("j", json, &[0u8; 24]).unwrap();
        assert_eq!(spec.repair, RepairMode::Off);
        assert!(spec.cameras.is_empty());
        assert_eq!(spec.w_free, 0.0);
        assert_eq!(spec.joint_motion, JointMotion::Dominant);
        // The new fields round-trip exactly (f32 cameras through JSON included).
        let with = JobSpec {
            cameras: vec![[0.1, -2.5, 1.0e-3], [3.0, 0.0, 0.7]],
            w_free: 15.0,
            repair: RepairMode::On,
            ..spec
        };
        let (json, blob) = spec_to_row(&with);
        assert_eq!(spec_from_row("j", &json, &blob).unwrap(), with);
        let bad = json.replace(r#""repair":"on""#, r#""repair":"maybe""#);
        assert_ne!(bad, json);
        let e = spec_from_row("j", &bad, &blob).unwrap_err().to_string();
        assert!(e.contains("unknown repair mode \"maybe\""), "{e}");
    }
}
