//! The embedded job store: SQLite in WAL mode with `synchronous = FULL`, artefacts as files.
//!
//! Why it exists: a single physnap needs no database server. Every committed transaction is
//! fsynced; artefacts are written to `artifacts/<job>/` by an atomic rename and the directory
//! is synced before the job row says SUCCEEDED.

use std::path::{Path, PathBuf};

use rusqlite::{Connection, OptionalExtension, TransactionBehavior, params};

use super::{
    Artifact, COLUMNS, Channel, JobRecord, JobState, JobStore, Lease, RawJob, StoreError,
    StoredEvent, artifact_record,
};

/// The SQLite job store: `jobs.sqlite3` and `artifacts/` in one data directory.
pub struct SqliteStore {
    conn: Connection,
    artifacts: PathBuf,
}

/// The schema, one migration an entry (`PRAGMA user_version` counts those applied). The
/// first is idempotent: stores made before versioning are at version 0 with its tables.
const MIGRATIONS: &[&str] = &[
    "
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
",
    "
ALTER TABLE jobs ADD COLUMN lease_owner TEXT;
ALTER TABLE jobs ADD COLUMN lease_expires_ms INTEGER;
ALTER TABLE jobs ADD COLUMN cancel_requested INTEGER NOT NULL DEFAULT 0;
",
];

fn raw(r: &rusqlite::Row<'_>) -> rusqlite::Result<RawJob> {
    Ok(RawJob {
        id: r.get(0)?,
        tenant: r.get(1)?,
        state: r.get(2)?,
        spec: r.get(3)?,
        points: r.get(4)?,
        created_ms: r.get(5)?,
        started_ms: r.get(6)?,
        ended_ms: r.get(7)?,
        deadline_ms: r.get(8)?,
        attempt: r.get(9)?,
        sequence: r.get(10)?,
        error_type: r.get(11)?,
        error_detail: r.get(12)?,
        artifacts: r.get(13)?,
    })
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> StoreError + '_ {
    move |source| StoreError::Io {
        path: path.display().to_string(),
        source,
    }
}

impl SqliteStore {
    /// Open (or create) the store in `data_dir`: `jobs.sqlite3` (WAL journal,
    /// `synchronous = FULL`) and `artifacts/`.
    pub fn open(data_dir: &Path) -> Result<SqliteStore, StoreError> {
        let artifacts = data_dir.join("artifacts");
        std::fs::create_dir_all(&artifacts).map_err(io(&artifacts))?;
        let mut conn = Connection::open(data_dir.join("jobs.sqlite3"))?;
        let mode: String =
            conn.pragma_update_and_check(None, "journal_mode", "WAL", |r| r.get(0))?;
        if !mode.eq_ignore_ascii_case("wal") {
            tracing::warn!(mode, "SQLite refused WAL mode; continuing with {mode}");
        }
        conn.pragma_update(None, "synchronous", "FULL")?;
        conn.pragma_update(None, "foreign_keys", "ON")?;
        conn.busy_timeout(std::time::Duration::from_secs(5))?;
        let tx = conn.transaction_with_behavior(TransactionBehavior::Immediate)?;
        let version: i64 = tx.query_row("PRAGMA user_version", [], |r| r.get(0))?;
        if version > MIGRATIONS.len() as i64 {
            return Err(StoreError::SchemaTooNew {
                found: version as i32,
                known: MIGRATIONS.len() as i32,
            });
        }
        for sql in MIGRATIONS.iter().skip(version as usize) {
            tx.execute_batch(sql)?;
        }
        tx.pragma_update(None, "user_version", MIGRATIONS.len() as i64)?;
        tx.commit()?;
        Ok(SqliteStore { conn, artifacts })
    }

    /// Write the job's mutable fields and append `events`, only while the stored job is in
    /// `expect` (state, attempt) when given.
    fn write(
        &mut self,
        job: &JobRecord,
        events: &[StoredEvent],
        expect: Option<(JobState, u32)>,
    ) -> Result<bool, StoreError> {
        let j = RawJob::encode(job);
        let (state, attempt) = match expect {
            Some((s, a)) => (Some(s.as_str()), Some(i64::from(a))),
            None => (None, None),
        };
        let tx = self.conn.transaction()?;
        let n = tx.execute(
            "UPDATE jobs SET state = ?2, started_ms = ?3, ended_ms = ?4, attempt = ?5, sequence = ?6, \
             error_type = ?7, error_detail = ?8, artifacts = ?9, \
             lease_owner = CASE WHEN ?2 = 'RUNNING' THEN lease_owner END, \
             lease_expires_ms = CASE WHEN ?2 = 'RUNNING' THEN lease_expires_ms END \
             WHERE id = ?1 AND (?10 IS NULL OR state = ?10) AND (?11 IS NULL OR attempt = ?11)",
            params![
                j.id,
                j.state,
                j.started_ms,
                j.ended_ms,
                j.attempt,
                j.sequence,
                j.error_type,
                j.error_detail,
                j.artifacts,
                state,
                attempt,
            ],
        )?;
        if n == 0 && expect.is_some() {
            return Ok(false);
        }
        append_events(&tx, &job.id, events)?;
        tx.commit()?;
        Ok(true)
    }

    fn query_jobs(
        &self,
        sql: &str,
        params: impl rusqlite::Params,
    ) -> Result<Vec<JobRecord>, StoreError> {
        let mut stmt = self.conn.prepare(sql)?;
        let rows = stmt.query_map(params, raw)?;
        let mut out = Vec::new();
        for r in rows {
            out.push(r?.decode()?);
        }
        Ok(out)
    }
}

impl JobStore for SqliteStore {
    fn backend(&self) -> &'static str {
        "sqlite"
    }

    fn insert(
        &mut self,
        job: &JobRecord,
        events: &[StoredEvent],
        idempotency: Option<(&str, &str)>,
    ) -> Result<(), StoreError> {
        let tx = self.conn.transaction()?;
        let j = RawJob::encode(job);
        tx.execute(
            &format!(
                "INSERT INTO jobs ({COLUMNS}) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14)"
            ),
            params![
                j.id,
                j.tenant,
                j.state,
                j.spec,
                j.points,
                j.created_ms,
                j.started_ms,
                j.ended_ms,
                j.deadline_ms,
                j.attempt,
                j.sequence,
                j.error_type,
                j.error_detail,
                j.artifacts,
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

    fn update(&mut self, job: &JobRecord, events: &[StoredEvent]) -> Result<(), StoreError> {
        self.write(job, events, None).map(|_| ())
    }

    fn update_if(
        &mut self,
        job: &JobRecord,
        events: &[StoredEvent],
        state: JobState,
        attempt: u32,
    ) -> Result<bool, StoreError> {
        self.write(job, events, Some((state, attempt)))
    }

    fn lease_next(
        &mut self,
        worker: &str,
        now_ms: i64,
        lease_ms: i64,
    ) -> Result<Option<Lease>, StoreError> {
        // An immediate transaction holds SQLite's one write lock: no other lease interleaves.
        let tx = self
            .conn
            .transaction_with_behavior(TransactionBehavior::Immediate)?;
        let id: Option<String> = tx
            .query_row(
                "SELECT id FROM jobs WHERE state = 'QUEUED' OR (state = 'RUNNING' AND \
                 (lease_expires_ms IS NULL OR lease_expires_ms < ?1)) ORDER BY id LIMIT 1",
                params![now_ms],
                |r| r.get(0),
            )
            .optional()?;
        let Some(id) = id else { return Ok(None) };
        tx.execute(
            "UPDATE jobs SET state = 'RUNNING', attempt = attempt + 1, started_ms = ?2, \
             lease_owner = ?3, lease_expires_ms = ?4 WHERE id = ?1",
            params![id, now_ms, worker, now_ms + lease_ms],
        )?;
        let (raw, cancel) = tx.query_row(
            &format!("SELECT {COLUMNS}, cancel_requested FROM jobs WHERE id = ?1"),
            params![id],
            |r| Ok((raw(r)?, r.get::<_, bool>(14)?)),
        )?;
        tx.commit()?;
        Ok(Some(Lease {
            job: raw.decode()?,
            cancel_requested: cancel,
        }))
    }

    fn heartbeat(
        &mut self,
        id: &str,
        attempt: u32,
        now_ms: i64,
        lease_ms: i64,
    ) -> Result<Option<bool>, StoreError> {
        Ok(self
            .conn
            .query_row(
                "UPDATE jobs SET lease_expires_ms = ?3 \
                 WHERE id = ?1 AND attempt = ?2 AND state = 'RUNNING' RETURNING cancel_requested",
                params![id, attempt, now_ms + lease_ms],
                |r| r.get(0),
            )
            .optional()?)
    }

    fn request_cancel(&mut self, id: &str) -> Result<(), StoreError> {
        self.conn.execute(
            "UPDATE jobs SET cancel_requested = 1 WHERE id = ?1",
            params![id],
        )?;
        Ok(())
    }

    /// Nothing to tell: one process owns a SQLite store.
    fn notify(&mut self, _channel: Channel, _payload: &str) -> Result<(), StoreError> {
        Ok(())
    }

    fn idempotency(
        &mut self,
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

    fn get(&mut self, id: &str) -> Result<Option<JobRecord>, StoreError> {
        let sql = format!("SELECT {COLUMNS} FROM jobs WHERE id = ?1");
        Ok(self.query_jobs(&sql, params![id])?.pop())
    }

    fn list(
        &mut self,
        tenant: &str,
        after: Option<&str>,
        limit: usize,
    ) -> Result<Vec<JobRecord>, StoreError> {
        let sql = format!(
            "SELECT {COLUMNS} FROM jobs WHERE tenant = ?1 AND id > ?2 ORDER BY id LIMIT ?3"
        );
        self.query_jobs(&sql, params![tenant, after.unwrap_or(""), limit as i64])
    }

    fn unfinished(&mut self) -> Result<Vec<JobRecord>, StoreError> {
        let sql =
            format!("SELECT {COLUMNS} FROM jobs WHERE state IN ('QUEUED', 'RUNNING') ORDER BY id");
        self.query_jobs(&sql, [])
    }

    fn events_after(&mut self, id: &str, after: u64) -> Result<Vec<StoredEvent>, StoreError> {
        let mut stmt = self.conn.prepare(
            "SELECT sequence, kind, data FROM events WHERE job_id = ?1 AND sequence > ?2 ORDER BY sequence",
        )?;
        let after = i64::try_from(after).unwrap_or(i64::MAX);
        let rows = stmt.query_map(params![id, after], |r| {
            Ok(StoredEvent {
                sequence: r.get::<_, i64>(0)? as u64,
                kind: r.get(1)?,
                data: r.get(2)?,
            })
        })?;
        Ok(rows.collect::<Result<_, _>>()?)
    }

    fn delete(&mut self, id: &str) -> Result<(), StoreError> {
        let tx = self.conn.transaction()?;
        tx.execute("DELETE FROM events WHERE job_id = ?1", params![id])?;
        tx.execute("DELETE FROM idempotency WHERE job_id = ?1", params![id])?;
        tx.execute("DELETE FROM jobs WHERE id = ?1", params![id])?;
        tx.commit()?;
        let dir = self.artifacts.join(id);
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(io(&dir))?;
        }
        Ok(())
    }

    fn count_by_state(&mut self) -> Result<Vec<(String, u64)>, StoreError> {
        let mut stmt = self
            .conn
            .prepare("SELECT state, COUNT(*) FROM jobs GROUP BY state")?;
        let rows = stmt.query_map([], |r| Ok((r.get(0)?, r.get::<_, i64>(1)? as u64)))?;
        Ok(rows.collect::<Result<_, _>>()?)
    }

    fn put_artifacts(
        &mut self,
        id: &str,
        files: &[(String, Vec<u8>)],
    ) -> Result<Vec<Artifact>, StoreError> {
        let dir = self.artifacts.join(id);
        std::fs::create_dir_all(&dir).map_err(io(&dir))?;
        let mut out = Vec::with_capacity(files.len());
        for (name, bytes) in files {
            let path = dir.join(name);
            crate::io::atomic::write(&path, bytes).map_err(|e| StoreError::Io {
                path: e.path.display().to_string(),
                source: e.source,
            })?;
            out.push(artifact_record(name, bytes));
        }
        // Make the renames durable before the job row says SUCCEEDED.
        std::fs::File::open(&dir)
            .and_then(|d| d.sync_all())
            .map_err(io(&dir))?;
        Ok(out)
    }

    fn artifact(&mut self, id: &str, name: &str) -> Result<Option<Vec<u8>>, StoreError> {
        let path = self.artifacts.join(id).join(name);
        match std::fs::read(&path) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(io(&path)(e)),
        }
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
