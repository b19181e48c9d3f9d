//! The PostgreSQL job store: the same rows as SQLite, artefacts as `bytea`, for physnap
//! processes on several machines sharing one database.
//!
//! Why it exists: a lab outgrows one machine, and the database labs already run is the answer,
//! not a home-made coordinator (`../shared/spec/service.md` §3). The schema is versioned: each
//! entry of [`MIGRATIONS`] runs once, in order, inside a transaction holding an advisory lock,
//! so replicas starting together migrate exactly once. Artefacts live in the database, so no
//! shared disk is needed. A dropped connection is re-opened on the next call.

use std::str::FromStr;
use std::time::Duration;

use postgres::{Client, Config, NoTls, Transaction};

use super::{
    Artifact, COLUMNS, Channel, JobRecord, JobState, JobStore, Lease, RawJob, StoreError,
    StoredEvent, artifact_record,
};

/// The schema, one migration an entry; version `i + 1` is `MIGRATIONS[i]`. Append only.
pub const MIGRATIONS: &[&str] = &[
    // 1: jobs, their events, idempotency keys and artefacts.
    "CREATE TABLE jobs (
        id TEXT PRIMARY KEY,
        tenant TEXT NOT NULL,
        state TEXT NOT NULL,
        spec TEXT NOT NULL,
        points BYTEA NOT NULL,
        created_ms BIGINT NOT NULL,
        started_ms BIGINT,
        ended_ms BIGINT,
        deadline_ms BIGINT NOT NULL,
        attempt BIGINT NOT NULL,
        sequence BIGINT NOT NULL,
        error_type TEXT,
        error_detail TEXT,
        artifacts TEXT NOT NULL
    );
    CREATE INDEX jobs_tenant ON jobs (tenant, id);
    CREATE INDEX jobs_unfinished ON jobs (id) WHERE state IN ('QUEUED', 'RUNNING');
    CREATE TABLE events (
        job_id TEXT NOT NULL,
        sequence BIGINT NOT NULL,
        kind TEXT NOT NULL,
        data TEXT NOT NULL,
        PRIMARY KEY (job_id, sequence)
    );
    CREATE TABLE idempotency (
        tenant TEXT NOT NULL,
        key TEXT NOT NULL,
        request_hash TEXT NOT NULL,
        job_id TEXT NOT NULL,
        PRIMARY KEY (tenant, key)
    );
    CREATE TABLE artifact_data (
        job_id TEXT NOT NULL,
        name TEXT NOT NULL,
        bytes BYTEA NOT NULL,
        PRIMARY KEY (job_id, name)
    );",
    // 2: leases (a worker's claim on a RUNNING job until it stops heartbeating) and cancels
    // requested of a job running in another process.
    "ALTER TABLE jobs ADD COLUMN lease_owner TEXT;
    ALTER TABLE jobs ADD COLUMN lease_expires_ms BIGINT;
    ALTER TABLE jobs ADD COLUMN cancel_requested BOOLEAN NOT NULL DEFAULT FALSE;",
];

/// Any constant: the advisory lock that serialises migrations between replicas.
const MIGRATION_LOCK: i64 = 0x0070_6879_736e_6170; // "physnap" in ASCII

/// Connecting gives up after this long unless the URL says otherwise (`connect_timeout`).
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// The PostgreSQL job store.
pub struct PgStore {
    config: Config,
    /// Always `Some` until dropped (see the `Drop` impl).
    client: Option<Client>,
}

/// The synchronous client closes its connection with a `block_on` of its own, which tokio
/// forbids on a runtime thread, where the service's last handle may well be dropped: there
/// the client is closed on a thread of its own.
impl Drop for PgStore {
    fn drop(&mut self) {
        if let Some(c) = self.client.take()
            && tokio::runtime::Handle::try_current().is_ok()
        {
            let _ = std::thread::Builder::new()
                .name("physnap-pg-close".into())
                .spawn(move || drop(c));
        }
    }
}

fn raw(r: &postgres::Row) -> RawJob {
    RawJob {
        id: r.get(0),
        tenant: r.get(1),
        state: r.get(2),
        spec: r.get(3),
        points: r.get(4),
        created_ms: r.get(5),
        started_ms: r.get(6),
        ended_ms: r.get(7),
        deadline_ms: r.get(8),
        attempt: r.get(9),
        sequence: r.get(10),
        error_type: r.get(11),
        error_detail: r.get(12),
        artifacts: r.get(13),
    }
}

impl PgStore {
    /// Connect to `url` and bring the schema up to date.
    pub fn connect(url: &str) -> Result<PgStore, StoreError> {
        let mut config = Config::from_str(url)?;
        if config.get_connect_timeout().is_none() {
            config.connect_timeout(CONNECT_TIMEOUT);
        }
        config.application_name("physnap");
        let client = config.connect(NoTls)?;
        let mut store = PgStore {
            config,
            client: Some(client),
        };
        store.migrate()?;
        Ok(store)
    }

    /// The schema version the database is at now.
    pub fn schema_version(&mut self) -> Result<i32, StoreError> {
        self.with(|c| {
            Ok(
                c.query_one("SELECT COALESCE(MAX(version), 0) FROM physnap_schema", &[])?
                    .get(0),
            )
        })
    }

    fn migrate(&mut self) -> Result<(), StoreError> {
        let mut tx = self.client()?.transaction()?;
        tx.execute("SELECT pg_advisory_xact_lock($1)", &[&MIGRATION_LOCK])?;
        tx.batch_execute(
            "CREATE TABLE IF NOT EXISTS physnap_schema (
                version INTEGER PRIMARY KEY,
                applied_ms BIGINT NOT NULL
            )",
        )?;
        let found: i32 = tx
            .query_one("SELECT COALESCE(MAX(version), 0) FROM physnap_schema", &[])?
            .get(0);
        let known = MIGRATIONS.len() as i32;
        if found > known {
            return Err(StoreError::SchemaTooNew { found, known });
        }
        for (i, sql) in MIGRATIONS.iter().enumerate().skip(found as usize) {
            tx.batch_execute(sql)?;
            tx.execute(
                "INSERT INTO physnap_schema (version, applied_ms) VALUES ($1, $2)",
                &[&(i as i32 + 1), &crate::service::jobs::now_ms()],
            )?;
            tracing::info!(version = i + 1, "job store: migrated PostgreSQL schema");
        }
        tx.commit()?;
        Ok(())
    }

    /// Run `f` on the connection; when the server had dropped it (a restart, a failover, an
    /// idle timeout), reconnect and run `f` once more. Every write is safe to repeat: a
    /// repeated insert or event fails on its key, a repeated lease at worst leaves a lease
    /// that expires.
    fn with<T>(
        &mut self,
        mut f: impl FnMut(&mut Client) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        match f(self.client()?) {
            Err(StoreError::Postgres(e)) if e.is_closed() => {
                tracing::warn!("job store: PostgreSQL connection lost ({e}); reconnecting");
                self.client = Some(self.config.connect(NoTls)?);
                f(self.client()?)
            }
            other => other,
        }
    }

    /// The connection, re-opened if the server dropped it.
    fn client(&mut self) -> Result<&mut Client, StoreError> {
        if self.client.as_ref().is_none_or(Client::is_closed) {
            tracing::warn!("job store: PostgreSQL connection lost; reconnecting");
            self.client = Some(self.config.connect(NoTls)?);
        }
        Ok(self.client.as_mut().expect("set just above"))
    }

    /// Write the job's mutable fields and append `events`, only while the stored job is in
    /// `expect` (state, attempt) when given; announce the last event on [`Channel::Events`].
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
        self.with(|c| {
            let mut tx = c.transaction()?;
            let n = tx.execute(
                "UPDATE jobs SET state = $2, started_ms = $3, ended_ms = $4, attempt = $5, sequence = $6, \
                 error_type = $7, error_detail = $8, artifacts = $9, \
                 lease_owner = CASE WHEN $2 = 'RUNNING' THEN lease_owner END, \
                 lease_expires_ms = CASE WHEN $2 = 'RUNNING' THEN lease_expires_ms END \
                 WHERE id = $1 AND ($10::TEXT IS NULL OR state = $10) AND ($11::BIGINT IS NULL OR attempt = $11)",
                &[
                    &j.id,
                    &j.state,
                    &j.started_ms,
                    &j.ended_ms,
                    &j.attempt,
                    &j.sequence,
                    &j.error_type,
                    &j.error_detail,
                    &j.artifacts,
                    &state,
                    &attempt,
                ],
            )?;
            if n == 0 && expect.is_some() {
                return Ok(false);
            }
            append_events(&mut tx, &job.id, events)?;
            tx.commit()?;
            Ok(true)
        })
    }

    fn query_jobs(
        &mut self,
        sql: &str,
        params: &[&(dyn postgres::types::ToSql + Sync)],
    ) -> Result<Vec<JobRecord>, StoreError> {
        self.with(|c| {
            c.query(sql, params)?
                .iter()
                .map(|r| raw(r).decode())
                .collect()
        })
    }
}

impl JobStore for PgStore {
    fn backend(&self) -> &'static str {
        "postgres"
    }

    fn insert(
        &mut self,
        job: &JobRecord,
        events: &[StoredEvent],
        idempotency: Option<(&str, &str)>,
    ) -> Result<(), StoreError> {
        let j = RawJob::encode(job);
        self.with(|c| {
            let mut tx = c.transaction()?;
            tx.execute(
                &format!(
                    "INSERT INTO jobs ({COLUMNS}) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14)"
                ),
                &[
                    &j.id,
                    &j.tenant,
                    &j.state,
                    &j.spec,
                    &j.points,
                    &j.created_ms,
                    &j.started_ms,
                    &j.ended_ms,
                    &j.deadline_ms,
                    &j.attempt,
                    &j.sequence,
                    &j.error_type,
                    &j.error_detail,
                    &j.artifacts,
                ],
            )?;
            if let Some((key, hash)) = idempotency {
                tx.execute(
                    "INSERT INTO idempotency (tenant, key, request_hash, job_id) VALUES ($1, $2, $3, $4)",
                    &[&job.tenant, &key, &hash, &job.id],
                )?;
            }
            append_events(&mut tx, &job.id, events)?;
            tx.commit()?;
            Ok(())
        })
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
        // The well-trodden queue: the subquery locks one eligible row and skips rows other
        // workers are leasing right now, so no two callers get the same job.
        let sql = format!(
            "UPDATE jobs SET state = 'RUNNING', attempt = attempt + 1, started_ms = $2, \
             lease_owner = $1, lease_expires_ms = $3 \
             WHERE id = (SELECT id FROM jobs WHERE state = 'QUEUED' OR (state = 'RUNNING' AND \
                 (lease_expires_ms IS NULL OR lease_expires_ms < $2)) \
                 ORDER BY id COLLATE \"C\" LIMIT 1 FOR UPDATE SKIP LOCKED) \
             RETURNING {COLUMNS}, cancel_requested"
        );
        self.with(|c| {
            let row = c.query_opt(&sql, &[&worker, &now_ms, &(now_ms + lease_ms)])?;
            row.map(|r| {
                Ok(Lease {
                    cancel_requested: r.get(14),
                    job: raw(&r).decode()?,
                })
            })
            .transpose()
        })
    }

    fn heartbeat(
        &mut self,
        id: &str,
        attempt: u32,
        now_ms: i64,
        lease_ms: i64,
    ) -> Result<Option<bool>, StoreError> {
        self.with(|c| {
            Ok(c.query_opt(
                    "UPDATE jobs SET lease_expires_ms = $3 \
                     WHERE id = $1 AND attempt = $2 AND state = 'RUNNING' RETURNING cancel_requested",
                    &[&id, &i64::from(attempt), &(now_ms + lease_ms)],
                )?
                .map(|r| r.get(0)))
        })
    }

    fn request_cancel(&mut self, id: &str) -> Result<(), StoreError> {
        self.with(|c| {
            let mut tx = c.transaction()?;
            tx.execute(
                "UPDATE jobs SET cancel_requested = TRUE WHERE id = $1",
                &[&id],
            )?;
            tx.execute("SELECT pg_notify($1, $2)", &[&Channel::Cancel.name(), &id])?;
            tx.commit()?;
            Ok(())
        })
    }

    fn notify(&mut self, channel: Channel, payload: &str) -> Result<(), StoreError> {
        self.with(|c| {
            c.execute("SELECT pg_notify($1, $2)", &[&channel.name(), &payload])?;
            Ok(())
        })
    }

    fn idempotency(
        &mut self,
        tenant: &str,
        key: &str,
    ) -> Result<Option<(String, String)>, StoreError> {
        self.with(|c| {
            Ok(c.query_opt(
                "SELECT request_hash, job_id FROM idempotency WHERE tenant = $1 AND key = $2",
                &[&tenant, &key],
            )?
            .map(|r| (r.get(0), r.get(1))))
        })
    }

    fn get(&mut self, id: &str) -> Result<Option<JobRecord>, StoreError> {
        let sql = format!("SELECT {COLUMNS} FROM jobs WHERE id = $1");
        Ok(self.query_jobs(&sql, &[&id])?.pop())
    }

    fn list(
        &mut self,
        tenant: &str,
        after: Option<&str>,
        limit: usize,
    ) -> Result<Vec<JobRecord>, StoreError> {
        // COLLATE "C": ids compare byte-wise, as in SQLite, whatever the database's locale.
        let sql = format!(
            "SELECT {COLUMNS} FROM jobs WHERE tenant = $1 AND id > $2 COLLATE \"C\" \
             ORDER BY id COLLATE \"C\" LIMIT $3"
        );
        self.query_jobs(&sql, &[&tenant, &after.unwrap_or(""), &(limit as i64)])
    }

    fn unfinished(&mut self) -> Result<Vec<JobRecord>, StoreError> {
        let sql = format!(
            "SELECT {COLUMNS} FROM jobs WHERE state IN ('QUEUED', 'RUNNING') ORDER BY id COLLATE \"C\""
        );
        self.query_jobs(&sql, &[])
    }

    fn events_after(&mut self, id: &str, after: u64) -> Result<Vec<StoredEvent>, StoreError> {
        let after = i64::try_from(after).unwrap_or(i64::MAX);
        self.with(|c| {
            Ok(c.query(
                    "SELECT sequence, kind, data FROM events WHERE job_id = $1 AND sequence > $2 ORDER BY sequence",
                    &[&id, &after],
                )?
                .iter()
                .map(|r| StoredEvent {
                    sequence: r.get::<_, i64>(0) as u64,
                    kind: r.get(1),
                    data: r.get(2),
                })
                .collect())
        })
    }

    fn delete(&mut self, id: &str) -> Result<(), StoreError> {
        self.with(|c| {
            let mut tx = c.transaction()?;
            for table in ["events", "idempotency", "artifact_data", "jobs"] {
                let key = if table == "jobs" { "id" } else { "job_id" };
                tx.execute(&format!("DELETE FROM {table} WHERE {key} = $1"), &[&id])?;
            }
            tx.commit()?;
            Ok(())
        })
    }

    fn count_by_state(&mut self) -> Result<Vec<(String, u64)>, StoreError> {
        self.with(|c| {
            Ok(
                c.query("SELECT state, COUNT(*) FROM jobs GROUP BY state", &[])?
                    .iter()
                    .map(|r| (r.get(0), r.get::<_, i64>(1) as u64))
                    .collect(),
            )
        })
    }

    fn put_artifacts(
        &mut self,
        id: &str,
        files: &[(String, Vec<u8>)],
    ) -> Result<Vec<Artifact>, StoreError> {
        self.with(|c| {
            let mut tx = c.transaction()?;
            for (name, bytes) in files {
                tx.execute(
                    "INSERT INTO artifact_data (job_id, name, bytes) VALUES ($1, $2, $3) \
                     ON CONFLICT (job_id, name) DO UPDATE SET bytes = EXCLUDED.bytes",
                    &[&id, name, bytes],
                )?;
            }
            tx.commit()?;
            Ok(files.iter().map(|(n, b)| artifact_record(n, b)).collect())
        })
    }

    fn artifact(&mut self, id: &str, name: &str) -> Result<Option<Vec<u8>>, StoreError> {
        self.with(|c| {
            Ok(c.query_opt(
                "SELECT bytes FROM artifact_data WHERE job_id = $1 AND name = $2",
                &[&id, &name],
            )?
            .map(|r| r.get(0)))
        })
    }
}

fn append_events(
    tx: &mut Transaction<'_>,
    id: &str,
    events: &[StoredEvent],
) -> Result<(), StoreError> {
    for e in events {
        tx.execute(
            "INSERT INTO events (job_id, sequence, kind, data) VALUES ($1, $2, $3, $4)",
            &[&id, &(e.sequence as i64), &e.kind, &e.data],
        )?;
    }
    // Delivered at commit, to every listening process (API replicas' streams, idle workers).
    if let Some(e) = events.last() {
        tx.execute(
            "SELECT pg_notify($1, $2)",
            &[
                &Channel::Events.name(),
                &format!("{id} {} {}", e.sequence, e.kind),
            ],
        )?;
    }
    Ok(())
}

/// What [`listen`] delivers: a notification, or `Resync` after a reconnect (notifications sent
/// while disconnected are lost, so listeners re-read what they follow).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Heard {
    /// A notification on a physnap channel.
    Note(Channel, String),
    /// The connection was re-opened.
    Resync,
}

/// Listen on every [`Channel`] with a connection of its own, on a dedicated thread, and hand
/// each notification to `on` until `stop` is set. A lost connection is re-opened (once a
/// second), followed by [`Heard::Resync`].
pub fn listen(
    url: &str,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    mut on: impl FnMut(Heard) + Send + 'static,
) -> Result<std::thread::JoinHandle<()>, StoreError> {
    use postgres::fallible_iterator::FallibleIterator;
    use std::sync::atomic::Ordering;
    let mut config = Config::from_str(url)?;
    if config.get_connect_timeout().is_none() {
        config.connect_timeout(CONNECT_TIMEOUT);
    }
    config.application_name("physnap-listen");
    let subscribe = move |config: &Config| -> Result<Client, postgres::Error> {
        let mut c = config.connect(NoTls)?;
        for ch in [Channel::Events, Channel::Progress, Channel::Cancel] {
            c.batch_execute(&format!("LISTEN {}", ch.name()))?;
        }
        Ok(c)
    };
    let mut client = subscribe(&config)?;
    let handle = std::thread::Builder::new()
        .name("physnap-listen".into())
        .spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                let failed = {
                    let mut notes = client.notifications();
                    let mut it = notes.timeout_iter(Duration::from_millis(250));
                    loop {
                        match it.next() {
                            Ok(Some(n)) => {
                                if let Some(ch) = Channel::of(n.channel()) {
                                    on(Heard::Note(ch, n.payload().to_string()));
                                }
                            }
                            Ok(None) => break false,
                            Err(e) => {
                                tracing::warn!("job store: listening connection failed: {e}");
                                break true;
                            }
                        }
                    }
                };
                if failed || client.is_closed() {
                    loop {
                        if stop.load(Ordering::Relaxed) {
                            return;
                        }
                        std::thread::sleep(Duration::from_secs(1));
                        match subscribe(&config) {
                            Ok(c) => {
                                client = c;
                                on(Heard::Resync);
                                break;
                            }
                            Err(e) => tracing::warn!("job store: re-listening failed: {e}"),
                        }
                    }
                }
            }
        })
        .map_err(|source| StoreError::Io {
            path: "physnap-listen thread".into(),
            source,
        })?;
    Ok(handle)
}
