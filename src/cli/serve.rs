//! CLI wiring of `physnap serve` and `physnap healthcheck` (binary only).
//!
//! Why it exists: the flags (each with a `PHYSNAP_*` env twin) become a
//! [`ServeConfig`](physnap::service::server::ServeConfig); the effective config is logged with
//! the tokens redacted; SIGINT/SIGTERM start the graceful drain. `healthcheck` is a tiny HTTP
//! GET of the admin `/readyz` so container images need no curl.

use anyhow::Context;
use clap::Args;
use physnap::service::auth::Tenants;
use physnap::service::jobs::Role;
use physnap::service::server::{ServeConfig, Server};
use physnap::service::store::StoreLocation;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::time::Duration;

#[derive(Args, Debug)]
pub struct ServeArgs {
    /// REST (+ SSE) listen address.
    #[arg(long, env = "PHYSNAP_HTTP", default_value = "127.0.0.1:8080")]
    http: SocketAddr,
    /// gRPC listen address.
    #[arg(long, env = "PHYSNAP_GRPC", default_value = "127.0.0.1:50051")]
    grpc: SocketAddr,
    /// Admin listen address (/metrics, /livez, /readyz); keep it off the gateway.
    #[arg(long, env = "PHYSNAP_ADMIN", default_value = "127.0.0.1:9000")]
    admin: SocketAddr,
    /// Directory of the SQLite job store and its artefacts.
    #[arg(long, env = "PHYSNAP_DATA_DIR", default_value = "data")]
    data_dir: PathBuf,
    /// Job store: `sqlite` (in --data-dir) or `postgres://user:password@host:port/db`
    /// (jobs, events and artefacts in PostgreSQL; the schema is migrated at start).
    #[arg(
        long,
        env = "PHYSNAP_STORE",
        default_value = "sqlite",
        hide_env_values = true
    )]
    store: StoreLocation,
    /// What this process does: `api` (accept, list, stream), `worker` (lease and run jobs;
    /// admin port only) or `all`. api and worker need a shared store (--store postgres://…).
    #[arg(long, env = "PHYSNAP_ROLE", default_value = "all")]
    role: Role,
    /// Seconds a worker's lease on a job lasts without a heartbeat (heartbeats come every
    /// third of it); a killed worker's job is re-leased after this long. Shared store only.
    #[arg(long, env = "PHYSNAP_LEASE_SECONDS", default_value_t = 15.0)]
    lease_seconds: f64,
    /// Weights directory with manifest.json.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    weights: PathBuf,
    /// Jobs running at once.
    #[arg(long, env = "PHYSNAP_MAX_RUNNING_JOBS", default_value_t = 1)]
    max_running_jobs: usize,
    /// Threads of the job worker pool (default: all cores).
    #[arg(long, env = "PHYSNAP_WORKER_THREADS")]
    worker_threads: Option<usize>,
    /// Jobs waiting at most; beyond that submissions get 429 / RESOURCE_EXHAUSTED.
    #[arg(long, env = "PHYSNAP_QUEUE_CAPACITY", default_value_t = 64)]
    queue_capacity: usize,
    /// Largest request body / gRPC message (bytes).
    #[arg(long, env = "PHYSNAP_MAX_BODY_BYTES", default_value_t = 16 << 20)]
    max_body_bytes: usize,
    /// Default job deadline (seconds) when a request gives none.
    #[arg(long, env = "PHYSNAP_JOB_TIMEOUT", default_value_t = 3600.0)]
    job_timeout: f64,
    /// Seconds running jobs may take to finish after a shutdown signal.
    #[arg(long, env = "PHYSNAP_DRAIN_TIMEOUT", default_value_t = 30.0)]
    drain_timeout: f64,
    /// Retry-After (seconds) on 429 / 503.
    #[arg(long, env = "PHYSNAP_RETRY_AFTER", default_value_t = 30)]
    retry_after: u64,
    /// Bearer tokens, `tenant:token,...`. None (and no file): no authentication, loopback only.
    #[arg(
        long,
        env = "PHYSNAP_TOKENS",
        default_value = "",
        hide_env_values = true
    )]
    tokens: String,
    /// File of `tenant token` lines.
    #[arg(long, env = "PHYSNAP_TOKENS_FILE")]
    tokens_file: Option<PathBuf>,
}

pub fn serve(a: ServeArgs) -> anyhow::Result<()> {
    let tenants = Tenants::load(&a.tokens, a.tokens_file.as_deref())?;
    if !(a.drain_timeout.is_finite() && a.drain_timeout >= 0.0) {
        anyhow::bail!(
            "invalid --drain-timeout: {} (must be >= 0)",
            a.drain_timeout
        );
    }
    if !(a.lease_seconds.is_finite() && a.lease_seconds >= 0.3) {
        anyhow::bail!(
            "invalid --lease-seconds: {} (must be >= 0.3)",
            a.lease_seconds
        );
    }
    if a.max_running_jobs == 0 || a.queue_capacity == 0 {
        anyhow::bail!("invalid --max-running-jobs / --queue-capacity: must be at least 1");
    }
    let worker_threads = a.worker_threads.unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    });
    let cfg = ServeConfig {
        http: a.http,
        grpc: a.grpc,
        admin: a.admin,
        data_dir: a.data_dir,
        store: a.store,
        role: a.role,
        lease: Duration::from_secs_f64(a.lease_seconds),
        weights: a.weights,
        max_running_jobs: a.max_running_jobs,
        worker_threads,
        queue_capacity: a.queue_capacity,
        max_body_bytes: a.max_body_bytes,
        job_timeout_seconds: a.job_timeout,
        drain_timeout: Duration::from_secs_f64(a.drain_timeout),
        retry_after_seconds: a.retry_after,
        tenants,
    };
    let auth = if cfg.tenants.is_open() {
        "none (loopback only)"
    } else {
        "bearer"
    };
    tracing::info!(
        http = %cfg.http, grpc = %cfg.grpc, admin = %cfg.admin,
        data_dir = %cfg.data_dir.display(), store = %cfg.store, role = cfg.role.as_str(),
        lease_s = a.lease_seconds, weights = %cfg.weights.display(),
        max_running_jobs = cfg.max_running_jobs, worker_threads = cfg.worker_threads,
        queue_capacity = cfg.queue_capacity, max_body_bytes = cfg.max_body_bytes,
        job_timeout_s = cfg.job_timeout_seconds, drain_timeout_s = a.drain_timeout,
        retry_after_s = cfg.retry_after_seconds,
        tenants = ?cfg.tenants.tenant_names(), tokens = "[redacted]",
        auth,
        "effective config"
    );
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("physnap-io")
        .build()?;
    rt.block_on(async move {
        let shutdown = shutdown_signal()?;
        let server = Server::bind(cfg).await?;
        let addrs = server.addrs();
        // One machine-readable line on stdout, so scripts (and tests) using port 0 can find us.
        let (http, grpc) = if addrs.api {
            (addrs.http.to_string(), addrs.grpc.to_string())
        } else {
            ("-".to_string(), "-".to_string())
        };
        println!(
            "physnap serve: http={http} grpc={grpc} admin={}",
            addrs.admin
        );
        std::io::stdout().flush().ok();
        tracing::info!(http = %addrs.http, grpc = %addrs.grpc, admin = %addrs.admin, "listening");
        server.run(shutdown).await?;
        Ok::<_, anyhow::Error>(())
    })
}

/// Resolves on SIGINT or SIGTERM. The handlers are installed when this is *called* (not when
/// the future is first polled), so a signal that arrives right after the address line is
/// printed is never lost.
fn shutdown_signal() -> anyhow::Result<impl std::future::Future<Output = ()> + Send + 'static> {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        let mut term = signal(SignalKind::terminate())?;
        let mut int = signal(SignalKind::interrupt())?;
        Ok(async move {
            tokio::select! {
                _ = term.recv() => {}
                _ = int.recv() => {}
            }
        })
    }
    #[cfg(not(unix))]
    {
        Ok(async {
            let _ = tokio::signal::ctrl_c().await;
        })
    }
}

#[derive(Args, Debug)]
pub struct HealthcheckArgs {
    /// Admin address of the server.
    #[arg(long, env = "PHYSNAP_ADMIN", default_value = "127.0.0.1:9000")]
    admin: SocketAddr,
}

/// GET /readyz with a 2 s timeout; Ok when it answers 200.
pub fn healthcheck(a: HealthcheckArgs) -> anyhow::Result<()> {
    let t = Duration::from_secs(2);
    let mut s = TcpStream::connect_timeout(&a.admin, t)
        .with_context(|| format!("connecting to {}", a.admin))?;
    s.set_read_timeout(Some(t))?;
    s.set_write_timeout(Some(t))?;
    write!(
        s,
        "GET /readyz HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
        a.admin
    )?;
    let mut resp = String::new();
    s.read_to_string(&mut resp)?;
    let status = resp.lines().next().unwrap_or("");
    if status.split_whitespace().nth(1) == Some("200") {
        Ok(())
    } else {
        anyhow::bail!("not ready: {status}")
    }
}
