//! Many physnap processes on one shared store (PostgreSQL): roles, leases and notifications.
//!
//! Why it exists: one process's in-memory queue cannot be shared. With a shared store the
//! queue *is* the store (`../shared/spec/service.md` §3):
//!
//! - **Roles** (`serve --role`): `api` replicas accept, list and stream; `worker`s lease and
//!   run; `all` (the default) does both.
//! - **Leases**: a worker takes the oldest QUEUED job (or one whose lease expired) with
//!   [`JobStore::lease_next`], then heartbeats every third of the lease. A worker that stops
//!   heartbeating loses the job to the next worker that asks, at attempt + 1. Every write of a
//!   run is fenced on its attempt ([`JobStore::update_if`]), so a late writer changes nothing.
//! - **News**: committed events, throttled progress and cancels are `NOTIFY`ed; every process
//!   `LISTEN`s ([`crate::service::store::postgres::listen`]) and feeds its own watchers, so an
//!   SSE or `WatchJob` stream on any API replica follows a job on any worker, resumable by
//!   sequence as ever. Cancels reach the worker at once (and at its next heartbeat anyway).
//! - **Drain**: a worker stopped mid-job puts it back to QUEUED for another worker.
//!
//! [`JobStore::lease_next`]: crate::service::store::JobStore::lease_next
//! [`JobStore::update_if`]: crate::service::store::JobStore::update_if

use std::collections::HashSet;
use std::str::FromStr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use tokio::sync::OwnedSemaphorePermit;

use super::super::api::{self, ProgressView};
use super::super::queue::Full;
use super::super::runner::Progress;
use super::super::store::postgres::{self as pg, Heard};
use super::super::store::{
    Channel, JobRecord, JobState, JobStore, Lease, StoreError, StoreLocation,
};
use super::{Service, ServiceConfig, ServiceError, Snapshot, lock, now_ms, state_events};

/// What a `physnap serve` process does with the job queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Accept, list, stream and serve artefacts (REST, gRPC); run nothing.
    Api,
    /// Lease and run jobs; serve only the admin port.
    Worker,
    /// Both (the default; the only role with the SQLite store).
    All,
}

impl Role {
    /// The flag's value.
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Api => "api",
            Role::Worker => "worker",
            Role::All => "all",
        }
    }

    /// Whether this process runs jobs.
    pub fn runs_jobs(self) -> bool {
        self != Role::Api
    }

    /// Whether this process serves the REST and gRPC APIs.
    pub fn serves_api(self) -> bool {
        self != Role::Worker
    }
}

/// A `--role` that is not `api`, `worker` or `all`.
#[derive(Debug, thiserror::Error)]
#[error("invalid role: {0:?} (must be api, worker or all)")]
pub struct BadRole(String);

impl FromStr for Role {
    type Err = BadRole;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        [Role::Api, Role::Worker, Role::All]
            .into_iter()
            .find(|r| r.as_str() == s.trim())
            .ok_or_else(|| BadRole(s.to_string()))
    }
}

/// Longest a progress notification waits behind the previous one of the same job.
const PROGRESS_EVERY: Duration = Duration::from_millis(250);

/// How the service shares its store.
pub(super) struct Shared {
    url: String,
    /// This process's name in leases: host, pid and a random suffix.
    worker: String,
    lease_ms: i64,
    stop: Arc<AtomicBool>,
}

impl Shared {
    /// `Some` for a shared store; an error for a role that needs one on a store that is not.
    pub(super) fn of(cfg: &ServiceConfig) -> Result<Option<Shared>, ServiceError> {
        match &cfg.store {
            StoreLocation::Sqlite if cfg.role != Role::All => Err(ServiceError::Internal(format!(
                "invalid role: {} needs a store shared between processes (--store postgres://…); \
                 the SQLite store serves one process, role all",
                cfg.role.as_str()
            ))),
            StoreLocation::Sqlite => Ok(None),
            StoreLocation::Postgres(url) => {
                let lease_ms = cfg.lease.as_millis() as i64;
                if lease_ms < 300 {
                    return Err(ServiceError::Internal(format!(
                        "invalid lease: {} s (must be >= 0.3)",
                        cfg.lease.as_secs_f64()
                    )));
                }
                let host = std::fs::read_to_string("/etc/hostname")
                    .map(|h| h.trim().to_string())
                    .unwrap_or_default();
                let tag = uuid::Uuid::now_v7().simple().to_string();
                Ok(Some(Shared {
                    url: url.clone(),
                    worker: format!("{host}:{}:{}", std::process::id(), &tag[24..]),
                    lease_ms,
                    stop: Arc::new(AtomicBool::new(false)),
                }))
            }
        }
    }
}

impl Drop for Shared {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// QUEUED jobs in per-state counts.
pub(super) fn queued_of(counts: &[(String, u64)]) -> usize {
    counts
        .iter()
        .find(|(s, _)| s == JobState::Queued.as_str())
        .map_or(0, |(_, n)| *n as usize)
}

/// Admission against the shared queue's length.
pub(super) fn check_admit(
    store: &mut dyn JobStore,
    capacity: usize,
) -> Result<Result<(), Full>, StoreError> {
    let queued = queued_of(&store.count_by_state()?);
    Ok(if queued >= capacity {
        Err(Full { queued, capacity })
    } else {
        Ok(())
    })
}

/// `<id> <sequence> <kind>` of [`Channel::Events`].
fn parse_event(payload: &str) -> Option<(&str, u64, &str)> {
    let mut it = payload.split(' ');
    Some((it.next()?, it.next()?.parse().ok()?, it.next()?))
}

impl Service {
    fn shared(&self) -> &Shared {
        self.shared
            .as_ref()
            .expect("shared-store method on a service without a shared store")
    }

    /// Follow the other processes' news (a thread with its own connection, opened on the
    /// blocking pool: the synchronous client must not run on a runtime thread).
    pub(super) async fn start_listening(self: &Arc<Self>) -> Result<(), ServiceError> {
        let s = self.shared();
        let (url, stop, weak) = (s.url.clone(), s.stop.clone(), Arc::downgrade(self));
        tokio::task::spawn_blocking(move || {
            pg::listen(&url, stop, move |heard| {
                if let Some(svc) = weak.upgrade() {
                    svc.heard(heard);
                }
            })
        })
        .await
        .map_err(|e| ServiceError::Internal(e.to_string()))??;
        Ok(())
    }

    /// One notification: move the live entries the watchers of this process follow.
    fn heard(&self, heard: Heard) {
        match heard {
            Heard::Note(Channel::Events, payload) => {
                let Some((id, sequence, kind)) = parse_event(&payload) else {
                    return;
                };
                // A new or re-queued job: an idle worker here may lease it.
                self.wake.notify_one();
                let mut live = lock(&self.live);
                if let Some(l) = live.get(id) {
                    l.tx.send_if_modified(|s| {
                        if s.sequence >= sequence {
                            return false;
                        }
                        *s = Arc::new(Snapshot {
                            sequence,
                            ..(**s).clone()
                        });
                        true
                    });
                }
                if kind == "done" && !self.runs_here(id) {
                    live.remove(id);
                }
            }
            Heard::Note(Channel::Progress, payload) => {
                let Some((id, rest)) = payload.split_once(' ') else {
                    return;
                };
                let Some((worker, json)) = rest.split_once(' ') else {
                    return;
                };
                if worker == self.shared().worker {
                    return;
                }
                let Some(p) = serde_json::from_str::<ProgressView>(json)
                    .ok()
                    .and_then(|v| api::progress_of_view(&v))
                else {
                    return;
                };
                if let Some(l) = lock(&self.live).get(id) {
                    l.tx.send_modify(|s| {
                        *s = Arc::new(Snapshot {
                            progress: Some(p),
                            ..(**s).clone()
                        })
                    });
                }
            }
            Heard::Note(Channel::Cancel, id) => {
                if let Some(l) = lock(&self.live).get(&id) {
                    l.cancel.store(true, Ordering::Relaxed);
                }
            }
            Heard::Resync => {
                // News may have been missed: every watcher re-reads the store.
                self.wake.notify_one();
                for l in lock(&self.live).values() {
                    l.tx.send_modify(|_| {});
                }
            }
        }
    }

    fn runs_here(&self, id: &str) -> bool {
        lock(&self.leased).contains(id)
    }

    /// Lease and run jobs while slots are free.
    pub(super) async fn dispatch_shared(self: Arc<Self>) {
        let (worker, lease_ms) = {
            let s = self.shared();
            (s.worker.clone(), s.lease_ms)
        };
        loop {
            let Ok(permit) = self.slots.clone().acquire_owned().await else {
                return;
            };
            let lease = loop {
                if self.is_draining() {
                    return;
                }
                let w = worker.clone();
                match self.db(move |s| s.lease_next(&w, now_ms(), lease_ms)).await {
                    Ok(Some(l)) => break l,
                    Ok(None) => {}
                    Err(e) => tracing::warn!("leasing a job failed: {e}"),
                }
                // Woken by a notification of a new job; polled too, since expired leases
                // announce nothing.
                let poll = Duration::from_millis((lease_ms as u64 / 2).clamp(100, 2_000));
                let _ = tokio::time::timeout(poll, self.wake.notified()).await;
            };
            let svc = self.clone();
            tokio::spawn(async move {
                let id = lease.job.id.clone();
                if let Err(e) = svc.clone().run_leased(lease, permit).await {
                    tracing::error!(job = %id, "job run failed in the service: {e}");
                }
            });
        }
    }

    async fn run_leased(
        self: Arc<Self>,
        lease: Lease,
        _permit: OwnedSemaphorePermit,
    ) -> Result<(), ServiceError> {
        let Lease {
            job: mut rec,
            cancel_requested,
        } = lease;
        let attempt = rec.attempt;
        if !lock(&self.live).contains_key(&rec.id) {
            self.add_live(&rec);
        }
        let (tx, cancel) = {
            let live = lock(&self.live);
            let l = &live[&rec.id];
            (l.tx.clone(), l.cancel.clone())
        };
        if cancel_requested {
            cancel.store(true, Ordering::Relaxed);
        }
        lock(&self.leased).insert(rec.id.clone());
        let evs = state_events(&mut rec);
        let r2 = rec.clone();
        let id = rec.id.clone();
        let held = self
            .db(move |s| s.update_if(&r2, &evs, JobState::Running, attempt))
            .await;
        let out = match held {
            Ok(true) => {
                tracing::info!(job = %id, attempt, "job leased");
                self.clone().execute(rec, tx, cancel, Some(attempt)).await
            }
            Ok(false) => Ok(()),
            Err(e) => Err(e),
        };
        lock(&self.leased).remove(&id);
        out
    }

    /// Keep the lease of `id` at `attempt` until aborted; set `lost` when another attempt owns
    /// the job (or the store has not answered for a whole lease), `cancel` when requested.
    pub(super) fn heartbeat(
        self: Arc<Self>,
        id: &str,
        attempt: u32,
        cancel: &Arc<AtomicBool>,
        lost: &Arc<AtomicBool>,
    ) -> tokio::task::JoinHandle<()> {
        let lease_ms = self.shared().lease_ms;
        let (id, cancel, lost) = (id.to_string(), cancel.clone(), lost.clone());
        tokio::spawn(async move {
            let every = Duration::from_millis(lease_ms as u64 / 3);
            let mut last_held = Instant::now();
            loop {
                tokio::time::sleep(every).await;
                let key = id.clone();
                match self
                    .db(move |s| s.heartbeat(&key, attempt, now_ms(), lease_ms))
                    .await
                {
                    Ok(Some(requested)) => {
                        last_held = Instant::now();
                        if requested {
                            cancel.store(true, Ordering::Relaxed);
                        }
                    }
                    Ok(None) => {
                        lost.store(true, Ordering::Relaxed);
                        return;
                    }
                    Err(e) => {
                        tracing::warn!(job = %id, "heartbeat failed: {e}");
                        if last_held.elapsed().as_millis() as i64 >= lease_ms {
                            lost.store(true, Ordering::Relaxed);
                            return;
                        }
                    }
                }
            }
        })
    }

    /// What a run calls with each progress: in a shared store, a `NOTIFY` at most every
    /// [`PROGRESS_EVERY`] (and at each new phase or sample) for the other processes' watchers.
    pub(super) fn progress_publisher(
        &self,
        id: &str,
    ) -> impl FnMut(&Service, &Progress) + Send + use<> {
        let worker = self.shared.as_ref().map(|s| s.worker.clone());
        let id = id.to_string();
        let mut last: Option<(Instant, u32, &'static str)> = None;
        move |svc: &Service, p: &Progress| {
            let Some(worker) = &worker else { return };
            let due = match last {
                None => true,
                Some((t, sample, phase)) => {
                    t.elapsed() >= PROGRESS_EVERY || sample != p.sample || phase != p.phase.as_str()
                }
            };
            if !due {
                return;
            }
            last = Some((Instant::now(), p.sample, p.phase.as_str()));
            let view = api::progress_view(&Progress {
                preview: None,
                ..p.clone()
            });
            let payload = format!(
                "{id} {worker} {}",
                serde_json::to_string(&view).unwrap_or_default()
            );
            // Best effort: progress is not part of the durability promise.
            if let Err(e) = lock(&svc.store).notify(Channel::Progress, &payload) {
                tracing::debug!(job = %id, "progress notification failed: {e}");
            }
        }
    }

    /// A run stopped by the drain timeout: with a shared store it goes back to QUEUED for
    /// another worker (fenced on its lease); alone, it stays RUNNING and re-runs on restart.
    pub(super) async fn stopped_by_shutdown(
        &self,
        mut rec: JobRecord,
        fence: Option<u32>,
        at: &str,
    ) -> Result<(), ServiceError> {
        let Some(attempt) = fence else {
            tracing::warn!(job = %rec.id, "stopped by shutdown {at}; it re-runs on restart");
            return Ok(());
        };
        rec.state = JobState::Queued;
        rec.ended_ms = None;
        let evs = state_events(&mut rec);
        let id = rec.id.clone();
        let back = self
            .db(move |s| s.update_if(&rec, &evs, JobState::Running, attempt))
            .await?;
        if back {
            tracing::warn!(job = %id, "stopped by shutdown {at}; re-queued for another worker");
        }
        Ok(())
    }
}

/// The jobs this process runs under a lease.
pub(super) type Leased = HashSet<String>;
