//! Shared helpers of the service tests: tiny real weights, an in-process server on ephemeral
//! ports, a minimal SSE reader and problem+json checks.
#![allow(dead_code)]

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

pub mod pg;

use physnap::service::auth::Tenants;
use physnap::service::jobs::{Role, Service};
use physnap::service::server::{BoundAddrs, ServeConfig, Server};
use physnap::service::store::StoreLocation;

/// Write a tiny, randomly initialised (untrained) but real weights directory
/// ([`physnap::fixtures::tiny_weights`]).
pub fn tiny_weights(dir: &Path) {
    physnap::fixtures::tiny_weights(dir).unwrap();
}

/// Test knobs.
#[derive(Clone)]
pub struct Opts {
    pub max_running_jobs: usize,
    pub queue_capacity: usize,
    pub max_body_bytes: usize,
    pub tokens: String,
    pub store: StoreLocation,
    pub role: Role,
    pub lease: Duration,
}

impl Default for Opts {
    fn default() -> Self {
        Opts {
            max_running_jobs: 1,
            queue_capacity: 8,
            max_body_bytes: 4 << 20,
            tokens: String::new(),
            store: StoreLocation::Sqlite,
            role: Role::All,
            lease: Duration::from_secs(15),
        }
    }
}

/// A running in-process server.
pub struct TestServer {
    pub addrs: BoundAddrs,
    pub svc: Arc<Service>,
    pub stop: Option<tokio::sync::oneshot::Sender<()>>,
    pub task: tokio::task::JoinHandle<()>,
    pub root: tempfile::TempDir,
}

impl TestServer {
    pub fn url(&self, path: &str) -> String {
        format!("http://{}{}", self.addrs.http, path)
    }

    pub fn grpc_url(&self) -> String {
        format!("http://{}", self.addrs.grpc)
    }

    pub async fn shutdown(mut self) {
        if let Some(s) = self.stop.take() {
            let _ = s.send(());
        }
        let _ = tokio::time::timeout(Duration::from_secs(20), &mut self.task).await;
    }
}

pub fn loopback() -> SocketAddr {
    "127.0.0.1:0".parse().unwrap()
}

pub fn serve_config(root: &Path, o: &Opts) -> ServeConfig {
    ServeConfig {
        http: loopback(),
        grpc: loopback(),
        admin: loopback(),
        data_dir: root.join("data"),
        store: o.store.clone(),
        role: o.role,
        lease: o.lease,
        weights: root.join("weights"),
        max_running_jobs: o.max_running_jobs,
        worker_threads: 1,
        queue_capacity: o.queue_capacity,
        max_body_bytes: o.max_body_bytes,
        job_timeout_seconds: 600.0,
        drain_timeout: Duration::from_secs(5),
        retry_after_seconds: 7,
        tenants: Tenants::load(&o.tokens, None).unwrap(),
    }
}

pub async fn start(o: Opts) -> TestServer {
    let root = tempfile::tempdir().unwrap();
    tiny_weights(&root.path().join("weights"));
    let server = Server::bind(serve_config(root.path(), &o)).await.unwrap();
    let addrs = server.addrs();
    let svc = server.service();
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(async move {
        server
            .run(async {
                let _ = rx.await;
            })
            .await
            .unwrap();
    });
    TestServer {
        addrs,
        svc,
        stop: Some(tx),
        task,
        root,
    }
}

/// A cloud of `n` points on a box surface-ish pattern (finite, deterministic).
pub fn cloud(n: usize) -> Vec<[f32; 3]> {
    (0..n)
        .map(|i| {
            let f = i as f32 / n as f32;
            [f - 0.5, (f * 7.0).sin() * 0.3, (f * 3.0).cos() * 0.4 + 0.5]
        })
        .collect()
}

pub fn f32le(points: &[[f32; 3]]) -> Vec<u8> {
    points
        .iter()
        .flat_map(|p| p.iter().flat_map(|c| c.to_le_bytes()))
        .collect()
}

/// One server-sent event.
#[derive(Debug, Clone, PartialEq)]
pub struct SseEvent {
    pub id: Option<String>,
    pub event: String,
    pub data: String,
}

impl SseEvent {
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_str(&self.data).unwrap_or_else(|e| panic!("{e}: {}", self.data))
    }
    pub fn seq(&self) -> u64 {
        self.id.as_deref().unwrap().parse().unwrap()
    }
}

/// Reads an SSE response incrementally.
pub struct SseReader {
    resp: reqwest::Response,
    buf: String,
}

impl SseReader {
    pub fn new(resp: reqwest::Response) -> Self {
        assert_eq!(resp.status(), 200);
        assert!(
            resp.headers()["content-type"]
                .to_str()
                .unwrap()
                .starts_with("text/event-stream")
        );
        SseReader {
            resp,
            buf: String::new(),
        }
    }

    /// The next event (skipping keep-alive comments); None at end of stream.
    pub async fn next(&mut self) -> Option<SseEvent> {
        loop {
            if let Some(pos) = self.buf.find("\n\n") {
                let block: String = self.buf.drain(..pos + 2).collect();
                let mut ev = SseEvent {
                    id: None,
                    event: "message".into(),
                    data: String::new(),
                };
                let mut any = false;
                for line in block.lines() {
                    if let Some(v) = line.strip_prefix("id:") {
                        ev.id = Some(v.trim().to_string());
                        any = true;
                    } else if let Some(v) = line.strip_prefix("event:") {
                        ev.event = v.trim().to_string();
                        any = true;
                    } else if let Some(v) = line.strip_prefix("data:") {
                        if !ev.data.is_empty() {
                            ev.data.push('\n');
                        }
                        ev.data.push_str(v.strip_prefix(' ').unwrap_or(v));
                        any = true;
                    }
                }
                if any {
                    return Some(ev);
                }
                continue;
            }
            match tokio::time::timeout(Duration::from_secs(60), self.resp.chunk())
                .await
                .expect("SSE stalled for 60 s")
            {
                Ok(Some(c)) => self.buf.push_str(&String::from_utf8_lossy(&c)),
                _ => return None,
            }
        }
    }

    /// All events until the stream ends.
    pub async fn collect(mut self) -> Vec<SseEvent> {
        let mut v = Vec::new();
        while let Some(e) = self.next().await {
            v.push(e);
        }
        v
    }
}

/// Assert a problem+json response and return it.
pub async fn problem(resp: reqwest::Response, status: u16) -> serde_json::Value {
    assert_eq!(resp.status().as_u16(), status, "unexpected status");
    assert_eq!(
        resp.headers()["content-type"].to_str().unwrap(),
        "application/problem+json"
    );
    let p: serde_json::Value = serde_json::from_slice(&resp.bytes().await.unwrap()).unwrap();
    assert_eq!(p["status"], status);
    assert!(p["type"].as_str().unwrap().starts_with("/problems/"));
    p
}

pub fn data_dir(s: &TestServer) -> PathBuf {
    s.root.path().join("data")
}

/// Submit a JSON job to `s` (asserting 202); its id.
pub async fn submit_json(c: &reqwest::Client, s: &TestServer, body: &serde_json::Value) -> String {
    let r = c.post(s.url("/v1/jobs")).json(body).send().await.unwrap();
    assert_eq!(r.status(), 202);
    r.json::<serde_json::Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string()
}

/// Every event of job `id`'s SSE stream on `s`, to its end.
pub async fn events_of(c: &reqwest::Client, s: &TestServer, id: &str) -> Vec<SseEvent> {
    let url = s.url(&format!("/v1/jobs/{id}/events"));
    SseReader::new(c.get(url).send().await.unwrap())
        .collect()
        .await
}
