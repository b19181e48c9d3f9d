//! A job's event stream: what a watcher (SSE or gRPC) receives, and the feeder that sends it.
//!
//! Why it exists apart from the queue and the runner: every watcher of a job, on either
//! transport, gets the persisted events replayed from the store after its resume point, then
//! live progress from a `tokio::sync::watch` (latest wins, so a slow reader never buffers), then
//! the terminal `done`. Previews are sticky: coalesced progress never loses the latest one. A
//! watcher that goes away stops its feeder; the job is unaffected.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use tokio::sync::{mpsc, watch};

use super::super::api::{self, ProgressView};
use super::super::runner::Progress;
use super::super::store::{JobRecord, StoredEvent};
use super::{Service, ServiceError, lock};

/// What a watcher sees of a live job.
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// Sequence of the last persisted event.
    pub sequence: u64,
    /// Latest progress.
    pub progress: Option<Progress>,
    /// Number of previews published so far (a watcher sends a preview when this changes).
    pub previews: u64,
    /// The latest preview, as progress carrying it.
    pub last_preview: Option<Progress>,
}

pub(super) struct Live {
    pub(super) tx: Arc<watch::Sender<Arc<Snapshot>>>,
    pub(super) cancel: Arc<AtomicBool>,
}

/// One item of a job's event stream.
#[derive(Debug, Clone)]
pub enum WatchItem {
    /// A persisted event (`state`, `artifact`, `done`).
    Stored(StoredEvent),
    /// Latest progress; `sequence` is the last persisted sequence (resume point).
    Progress {
        /// Resume point.
        sequence: u64,
        /// Progress JSON.
        progress: ProgressView,
    },
    /// The server is shutting down; resume elsewhere from the last sequence.
    Shutdown {
        /// Resume point.
        sequence: u64,
    },
}

impl Service {
    /// A job's events after `after`: persisted events replayed from the store, then live
    /// progress and new events until `done` (or shutdown). Dropping the receiver stops the
    /// feeder; the job is unaffected.
    pub async fn watch(
        self: &Arc<Self>,
        tenant: &str,
        id: &str,
        after: u64,
    ) -> Result<mpsc::Receiver<WatchItem>, ServiceError> {
        let rec = self.owned(tenant, id).await?;
        if self.shared.is_some() && !rec.state.is_terminal() {
            // The job may run in another process: follow it through notifications.
            let live = lock(&self.live).contains_key(id);
            if !live {
                self.add_live(&rec);
            }
        }
        let (tx, rx) = mpsc::channel(16);
        let svc = self.clone();
        tokio::spawn(async move { svc.feed(rec, after, tx).await });
        Ok(rx)
    }

    /// Send the live job's latest preview if this watcher has not seen it (previews are sticky:
    /// coalesced progress must not lose them). False when the watcher is gone.
    async fn send_preview(
        tx: &mpsc::Sender<WatchItem>,
        live: Option<&watch::Receiver<Arc<Snapshot>>>,
        previews_sent: &mut u64,
        sequence: u64,
    ) -> bool {
        let Some(rx) = live else { return true };
        let snap = rx.borrow().clone();
        match &snap.last_preview {
            Some(p) if snap.previews != *previews_sent => {
                *previews_sent = snap.previews;
                tx.send(WatchItem::Progress {
                    sequence,
                    progress: api::progress_view(p),
                })
                .await
                .is_ok()
            }
            _ => true,
        }
    }

    async fn feed(self: Arc<Self>, rec: JobRecord, after: u64, tx: mpsc::Sender<WatchItem>) {
        // Subscribe before reading the log, so no event falls between the two.
        let mut live = lock(&self.live).get(&rec.id).map(|l| l.tx.subscribe());
        let mut shutdown = self.shutdown_tx.subscribe();
        // A resume point beyond the job's log (a client cannot have seen events that do not
        // exist yet) resumes from the log's end, so the stream still ends with `done`.
        let mut sent = after.min(rec.sequence);
        let (mut last_step, mut previews_sent) = (None, 0u64);
        let throttle = Duration::from_millis(100);
        loop {
            let id = rec.id.clone();
            let evs = match self.db(move |s| s.events_after(&id, sent)).await {
                Ok(e) => e,
                Err(e) => {
                    tracing::warn!(job = %rec.id, "event replay failed: {e}");
                    return;
                }
            };
            for e in evs {
                let done = e.kind == "done";
                // The latest preview goes out before the stream ends, even when the job
                // finished between two wake-ups of this feed (it is never persisted).
                if done && !Self::send_preview(&tx, live.as_ref(), &mut previews_sent, sent).await {
                    return;
                }
                sent = e.sequence;
                if tx.send(WatchItem::Stored(e)).await.is_err() || done {
                    return;
                }
            }
            if !Self::send_preview(&tx, live.as_ref(), &mut previews_sent, sent).await {
                return;
            }
            let Some(rx) = live.as_mut() else { return };
            let snap = rx.borrow_and_update().clone();
            if snap.sequence > sent {
                continue;
            }
            if let Some(p) = &snap.progress
                && last_step != Some((p.sample, p.step, p.phase))
            {
                last_step = Some((p.sample, p.step, p.phase));
                if tx
                    .send(WatchItem::Progress {
                        sequence: sent,
                        progress: api::progress_view(p),
                    })
                    .await
                    .is_err()
                {
                    return;
                }
                tokio::time::sleep(throttle).await;
            }
            let gone = tokio::select! {
                r = rx.changed() => r.is_err(),
                _ = shutdown.changed() => {
                    let _ = tx.send(WatchItem::Shutdown { sequence: sent }).await;
                    return;
                }
                _ = tx.closed() => return,
            };
            if gone {
                // The job left the live set (finished or deleted): replay once more, then stop.
                live = None;
            }
        }
    }
}
