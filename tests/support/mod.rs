//! Shared helpers of the service tests: tiny real weights, an in-process server on ephemeral
//! ports, a minimal SSE reader and problem+json checks.
#![allow(dead_code)]

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use physnap::graph::FeatureScales;
use physnap::io::manifest::{Entry, Manifest, to_string as manifest_to_string};
use physnap::model::denoiser::{Denoiser, DenoiserConfig};
use physnap::model::shape_prior::{ShapePrior, ShapePriorConfig};
use physnap::model::weights;
use physnap::service::auth::Tenants;
use physnap::service::jobs::Service;
use physnap::service::server::{BoundAddrs, ServeConfig, Server};

/// Write a tiny, randomly initialised (untrained) but real weights directory: the engine
/// path (denoiser, schedule, projection, shape decoder, meshing, export) runs for real.
pub fn tiny_weights(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    let device = physnap::model::cpu();
    let sp_cfg = ShapePriorConfig {
        latent: 128,
        decoder_hidden: 16,
        decoder_blocks: 1,
        encoder_hidden: 16,
        encoder_blocks: 1,
        pe_freqs: 2,
        code_every_block: false,
    };
    let sp = ShapePrior::new(&sp_cfg, &device);
    let sp_sha = weights::save(&sp, &dir.join("shape_prior.safetensors")).unwrap();
    let categories: Vec<String> = physnap::data::categories::CATEGORIES
        .iter()
        .map(|s| s.to_string())
        .collect();
    let dn_cfg = DenoiserConfig {
        width: 16,
        layers: 1,
        head_channels: 16,
        t_pe_dim: 8,
        slot_pe_dim: 8,
        node_head_hidden: vec![16],
        edge_head_hidden: vec![16],
        categories: categories.len(),
        legacy_edge_embedding: false,
        category_layers: false,
    };
    let dn = Denoiser::new(&dn_cfg, &device).unwrap();
    let dn_sha = weights::save(&dn, &dir.join("denoiser.safetensors")).unwrap();
    let m = Manifest {
        shape_prior: Entry {
            file: "shape_prior.safetensors".into(),
            sha256: sp_sha,
            config: sp_cfg,
        },
        denoiser: Entry {
            file: "denoiser.safetensors".into(),
            sha256: dn_sha,
            config: dn_cfg,
        },
        codebook: None,
        feature_scales: FeatureScales::default(),
        categories,
        data: serde_json::json!({"note": "untrained test weights"}),
        training: serde_json::Value::Null,
        metrics: serde_json::Value::Null,
    };
    std::fs::write(dir.join("manifest.json"), manifest_to_string(&m)).unwrap();
}

/// Test knobs.
#[derive(Clone)]
pub struct Opts {
    pub max_running_jobs: usize,
    pub queue_capacity: usize,
    pub max_body_bytes: usize,
    pub tokens: String,
}

impl Default for Opts {
    fn default() -> Self {
        Opts {
            max_running_jobs: 1,
            queue_capacity: 8,
            max_body_bytes: 4 << 20,
            tokens: String::new(),
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
