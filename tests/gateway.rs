//! The shipped gateway config (`deploy/Caddyfile`) runs for real on loopback in front of the
//! server: one REST job, its SSE stream (events must arrive while the job runs, not buffered
//! to the end) and a gRPC `WatchJob` stream (h2c) all go through Caddy. The only edits to the
//! file are the addresses and turning off Caddy's admin endpoint and automatic HTTPS.
//! Requires Debian's `caddy` (`bash .ci/setup`).

mod support;

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use physnap::service::grpc::pb::{self, job_service_client::JobServiceClient};
use serde_json::{Value, json};
use support::{Opts, SseReader, cloud, start};
use tokio_stream::StreamExt as _;

struct Caddy(Child);

impl Drop for Caddy {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rest_sse_and_grpc_through_caddy() {
    let s = start(Opts::default()).await;
    let port = free_port();
    let shipped =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/deploy/Caddyfile")).unwrap();
    let cfg = shipped
        .replace(
            "{\n\tservers {",
            "{\n\tadmin off\n\tauto_https off\n\tservers {",
        )
        .replace("h2c://physnap:50051", &format!("h2c://{}", s.addrs.grpc))
        .replace("physnap:8080", &s.addrs.http.to_string())
        .replace("\n:8080 {", &format!("\nhttp://127.0.0.1:{port} {{"));
    assert!(cfg.contains("admin off") && cfg.contains(&format!(":{port}")));
    let path = s.root.path().join("Caddyfile");
    std::fs::write(&path, &cfg).unwrap();
    let v = Command::new("caddy")
        .args(["validate", "--adapter", "caddyfile", "--config"])
        .arg(&path)
        .output()
        .expect("caddy is required for the gateway test: run `bash .ci/setup`");
    assert!(
        v.status.success(),
        "caddy validate: {}",
        String::from_utf8_lossy(&v.stderr)
    );
    let log = s.root.path().join("caddy.log");
    let mut caddy = Caddy(
        Command::new("caddy")
            .args(["run", "--adapter", "caddyfile", "--config"])
            .arg(&path)
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap(),
    );
    let gw = format!("http://127.0.0.1:{port}");
    let c = reqwest::Client::new();
    let t0 = Instant::now();
    while c.get(format!("{gw}/v1/categories")).send().await.is_err() {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "caddy did not start (exit: {:?}):\n{}\nconfig:\n{cfg}",
            caddy.0.try_wait(),
            std::fs::read_to_string(&log).unwrap_or_default()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }

    // REST submit + SSE through the gateway: progress arrives before the end of the job.
    let r = c
        .post(format!("{gw}/v1/jobs"))
        .json(
            &json!({"points": cloud(32), "samples": 4, "resolution": 8, "seed": 2,
                       "sampler": "ddpm", "steps": 1000,
                       "w_pc": 0.0, "w_pen": 0.0, "w_mob": 0.0}),
        )
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let mut sse = SseReader::new(
        c.get(format!("{gw}/v1/jobs/{id}/events"))
            .send()
            .await
            .unwrap(),
    );
    let mut first_progress = None;
    let mut done = None;
    while let Some(e) = sse.next().await {
        if e.event == "progress" && first_progress.is_none() {
            first_progress = Some(Instant::now());
        }
        if e.event == "done" {
            done = Some((Instant::now(), e.json()));
        }
    }
    let (t_done, job) = done.expect("done event through the gateway");
    assert_eq!(job["state"], "SUCCEEDED");
    let lead = t_done - first_progress.expect("progress through the gateway");
    assert!(
        lead > Duration::from_millis(300),
        "events were buffered by the gateway: first progress only {lead:?} before done"
    );
    // gRPC (h2c) through the same gateway port: WatchJob replays to `done`, then OK.
    let mut cl = JobServiceClient::connect(gw.clone()).await.unwrap();
    let mut stream = cl
        .watch_job(pb::WatchJobRequest {
            id: id.clone(),
            after_sequence: 0,
        })
        .await
        .unwrap()
        .into_inner();
    let mut kinds = Vec::new();
    while let Some(e) = stream.next().await {
        kinds.push(e.unwrap().kind);
    }
    assert_eq!(kinds.first().map(String::as_str), Some("state"));
    assert_eq!(kinds.last().map(String::as_str), Some("done"));
    let j = cl
        .get_job(pb::GetJobRequest { id })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(j.state, pb::State::Succeeded as i32);
    s.shutdown().await;
}
