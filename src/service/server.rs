//! `physnap serve`: load the weights, open the store, bind the three listeners, run until a
//! shutdown signal, then drain.
//!
//! Why it exists: the binary and the tests start the server the same way. [`Server::bind`]
//! returns the actual bound addresses (port 0 gives an ephemeral port, which tests use), and
//! [`Server::run`] serves REST, gRPC (+ health, reflection) and admin until the given shutdown
//! future resolves: it then stops admitting (503 / UNAVAILABLE, `/readyz` 503, gRPC health
//! NOT_SERVING), lets running jobs finish for up to `drain_timeout`, stops the rest at their
//! next step (they re-run on the next start), closes event streams and exits.

use std::future::Future;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use tokio::net::TcpListener;
use tokio_stream::wrappers::TcpListenerStream;

use super::auth::Tenants;
use super::grpc::{GrpcJobs, pb};
use super::http::{HttpState, admin_router, router};
use super::jobs::Role;
use super::jobs::{Service, ServiceConfig, ServiceError};
use super::runner::Models;
use super::spec::Limits;
use super::store::StoreLocation;
use crate::engine::schedule::Schedule;

/// Everything `serve` needs.
#[derive(Debug, Clone)]
pub struct ServeConfig {
    /// REST listener.
    pub http: SocketAddr,
    /// gRPC listener.
    pub grpc: SocketAddr,
    /// Admin listener (`/metrics`, `/livez`, `/readyz`).
    pub admin: SocketAddr,
    /// The SQLite store and its artefacts.
    pub data_dir: PathBuf,
    /// Where jobs and artefacts are stored.
    pub store: StoreLocation,
    /// What this process does with the queue (api and worker need a shared store).
    pub role: Role,
    /// A worker's lease on a job without a heartbeat (shared store).
    pub lease: Duration,
    /// Weights directory (`manifest.json`).
    pub weights: PathBuf,
    /// Jobs running at once.
    pub max_running_jobs: usize,
    /// Threads of the job pool.
    pub worker_threads: usize,
    /// Jobs waiting at most.
    pub queue_capacity: usize,
    /// Largest request body / gRPC message.
    pub max_body_bytes: usize,
    /// Default job deadline (s).
    pub job_timeout_seconds: f64,
    /// Drain timeout on shutdown.
    pub drain_timeout: Duration,
    /// Retry-After for 429 / 503.
    pub retry_after_seconds: u64,
    /// Tenants.
    pub tenants: Tenants,
}

/// A bound, not yet running server.
pub struct Server {
    cfg: ServeConfig,
    svc: Arc<Service>,
    /// HTTP and gRPC (absent for a worker), admin.
    listeners: (Option<[TcpListener; 2]>, TcpListener),
}

/// The addresses actually bound (a worker binds no HTTP or gRPC listener: those are
/// `0.0.0.0:0` and `api` is false).
#[derive(Debug, Clone, Copy)]
pub struct BoundAddrs {
    /// Whether the REST and gRPC listeners are served.
    pub api: bool,
    /// REST.
    pub http: SocketAddr,
    /// gRPC.
    pub grpc: SocketAddr,
    /// Admin.
    pub admin: SocketAddr,
}

fn io(what: &str, addr: SocketAddr) -> impl Fn(std::io::Error) -> ServiceError + '_ {
    move |e| ServiceError::Internal(format!("binding the {what} listener on {addr}: {e}"))
}

impl Server {
    /// Check the config, load weights, open the store (re-queueing interrupted jobs) and bind.
    pub async fn bind(cfg: ServeConfig) -> Result<Server, ServiceError> {
        if cfg.tenants.is_open() && !(cfg.http.ip().is_loopback() && cfg.grpc.ip().is_loopback()) {
            return Err(ServiceError::Internal(format!(
                "no tokens configured (--tokens / --tokens-file), so no authentication: allowed only \
                 when the HTTP and gRPC listeners are on loopback, not on {} / {}",
                cfg.http, cfg.grpc
            )));
        }
        let weights = cfg.weights.clone();
        let loaded = tokio::task::spawn_blocking(move || {
            crate::io::manifest::load_models(&weights, &crate::model::cpu())
        })
        .await
        .map_err(|e| ServiceError::Internal(e.to_string()))?
        .map_err(|e| {
            ServiceError::Internal(format!(
                "loading weights from {}: {e}",
                cfg.weights.display()
            ))
        })?;
        let limits = Limits {
            default_deadline_seconds: cfg.job_timeout_seconds,
            ..Limits::default()
        };
        let svc = Service::start(
            ServiceConfig {
                data_dir: cfg.data_dir.clone(),
                store: cfg.store.clone(),
                role: cfg.role,
                lease: cfg.lease,
                max_running_jobs: cfg.max_running_jobs,
                worker_threads: cfg.worker_threads,
                queue_capacity: cfg.queue_capacity,
                retry_after_seconds: cfg.retry_after_seconds,
                limits,
            },
            Models {
                loaded,
                schedule: Schedule::default(),
            },
        )
        .await?;
        let api = if cfg.role.serves_api() {
            Some([
                TcpListener::bind(cfg.http)
                    .await
                    .map_err(io("HTTP", cfg.http))?,
                TcpListener::bind(cfg.grpc)
                    .await
                    .map_err(io("gRPC", cfg.grpc))?,
            ])
        } else {
            None
        };
        let admin = TcpListener::bind(cfg.admin)
            .await
            .map_err(io("admin", cfg.admin))?;
        let listeners = (api, admin);
        Ok(Server {
            cfg,
            svc,
            listeners,
        })
    }

    /// The bound addresses.
    pub fn addrs(&self) -> BoundAddrs {
        let a = |l: &TcpListener, d: SocketAddr| l.local_addr().unwrap_or(d);
        let none = SocketAddr::from(([0, 0, 0, 0], 0));
        let (api, admin) = &self.listeners;
        BoundAddrs {
            api: api.is_some(),
            http: api.as_ref().map_or(none, |l| a(&l[0], self.cfg.http)),
            grpc: api.as_ref().map_or(none, |l| a(&l[1], self.cfg.grpc)),
            admin: a(admin, self.cfg.admin),
        }
    }

    /// The job service (for in-process use).
    pub fn service(&self) -> Arc<Service> {
        self.svc.clone()
    }

    /// Serve until `shutdown` resolves, then drain and return.
    pub async fn run(
        self,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> Result<(), ServiceError> {
        let Server {
            cfg,
            svc,
            listeners: (api_l, admin_l),
        } = self;
        let tenants = Arc::new(cfg.tenants.clone());
        let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
        let wait = move || {
            let mut rx = stop_rx.clone();
            async move {
                let _ = rx.wait_for(|s| *s).await;
            }
        };
        let (health, health_svc) = tonic_health::server::health_reporter();
        health
            .set_serving::<pb::job_service_server::JobServiceServer<GrpcJobs>>()
            .await;
        {
            let (svc, health, drain) = (svc.clone(), health.clone(), cfg.drain_timeout);
            tokio::spawn(async move {
                shutdown.await;
                tracing::info!("shutdown requested: draining (no new jobs)");
                health
                    .set_not_serving::<pb::job_service_server::JobServiceServer<GrpcJobs>>()
                    .await;
                svc.shutdown(drain).await;
                let _ = stop_tx.send(true);
            });
        }
        let admin = axum::serve(admin_l, admin_router(svc.clone())).with_graceful_shutdown(wait());
        let Some([http_l, grpc_l]) = api_l else {
            // A worker: the admin port only, until the drain ends.
            admin
                .await
                .map_err(|e| ServiceError::Internal(format!("admin server: {e}")))?;
            tracing::info!("stopped");
            return Ok(());
        };
        let http = axum::serve(
            http_l,
            router(HttpState {
                svc: svc.clone(),
                tenants: tenants.clone(),
                max_body_bytes: cfg.max_body_bytes,
            }),
        )
        .with_graceful_shutdown(wait());
        // Reflection in both versions (many clients still speak v1alpha), listing physnap's
        // service and the health service.
        let described = || {
            tonic_reflection::server::Builder::configure()
                .register_encoded_file_descriptor_set(pb::FILE_DESCRIPTOR_SET)
                .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        };
        let reflection_err = |e| ServiceError::Internal(format!("gRPC reflection: {e}"));
        let reflection = described().build_v1().map_err(reflection_err)?;
        let reflection_alpha = described().build_v1alpha().map_err(reflection_err)?;
        let jobs = pb::job_service_server::JobServiceServer::new(GrpcJobs {
            svc: svc.clone(),
            tenants,
            max_message_bytes: cfg.max_body_bytes,
        })
        .max_decoding_message_size(
            cfg.max_body_bytes
                .saturating_mul(crate::service::grpc::DECODE_LIMIT_FACTOR),
        );
        let grpc = tonic::transport::Server::builder()
            .add_service(health_svc)
            .add_service(reflection)
            .add_service(reflection_alpha)
            .add_service(jobs)
            .serve_with_incoming_shutdown(TcpListenerStream::new(grpc_l), wait());
        let (h, a, g) = tokio::join!(async { http.await }, async { admin.await }, grpc);
        h.map_err(|e| ServiceError::Internal(format!("HTTP server: {e}")))?;
        a.map_err(|e| ServiceError::Internal(format!("admin server: {e}")))?;
        g.map_err(|e| ServiceError::Internal(format!("gRPC server: {e}")))?;
        tracing::info!("stopped");
        Ok(())
    }
}
