//! The shipped gateway configs run for real on loopback in front of the server: one REST job,
//! its SSE stream (events must arrive while the job runs, not buffered to the end) and a gRPC
//! `WatchJob` stream (h2c) all go through the gateway.
//! - `deploy/Caddyfile` with Debian's `caddy`: REST and gRPC on one port. The only edits are
//!   the addresses and turning off Caddy's admin endpoint and automatic HTTPS.
//! - `deploy/nginx.conf` with Debian's `nginx`: REST on one port, gRPC on its own. The only
//!   edits are the addresses and the paths nginx writes (pid, logs, temp files).
//!
//! Requires both (`bash .ci/setup`).

mod support;

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use physnap::service::grpc::pb::{self, job_service_client::JobServiceClient};
use serde_json::{Value, json};
use support::{Opts, SseReader, cloud, start};
use tokio_stream::StreamExt as _;

/// A gateway process, killed when the test ends.
struct Gateway(Child);

impl Drop for Gateway {
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
    let mut caddy = Gateway(
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

    exercise(&gw, &gw).await;
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rest_sse_and_grpc_through_nginx() {
    let s = start(Opts::default()).await;
    let (rest_port, grpc_port) = (free_port(), free_port());
    let dir = s.root.path().join("nginx");
    std::fs::create_dir_all(&dir).unwrap();
    // nginx started by root runs its workers as `nobody`: they must be able to write the
    // temp-file folders.
    use std::os::unix::fs::PermissionsExt as _;
    std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o777)).unwrap();
    let d = dir.display();
    let shipped =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/deploy/nginx.conf")).unwrap();
    let cfg = shipped
        .replace("server physnap:8080;", &format!("server {};", s.addrs.http))
        .replace(
            "server physnap:50051;",
            &format!("server {};", s.addrs.grpc),
        )
        .replace("listen 8080;", &format!("listen 127.0.0.1:{rest_port};"))
        .replace(
            "listen 50051 http2;",
            &format!("listen 127.0.0.1:{grpc_port} http2;"),
        )
        .replace(
            "http {\n",
            &format!(
                "http {{\n    access_log off;\n    client_body_temp_path {d}/body;\n    \
                 proxy_temp_path {d}/proxy;\n    fastcgi_temp_path {d}/fastcgi;\n    \
                 uwsgi_temp_path {d}/uwsgi;\n    scgi_temp_path {d}/scgi;\n"
            ),
        );
    assert!(
        cfg.contains(&format!("listen 127.0.0.1:{grpc_port} http2;"))
            && cfg.contains(&format!("{d}/body"))
            && !cfg.contains("physnap:"),
        "nginx.conf changed shape; update the test's substitutions:\n{cfg}"
    );
    let conf = dir.join("nginx.conf");
    std::fs::write(&conf, &cfg).unwrap();
    let log = dir.join("error.log");
    let run = |extra: &[&str]| {
        let mut c = Command::new("nginx");
        c.arg("-p")
            .arg(&dir)
            .arg("-c")
            .arg(&conf)
            .arg("-e")
            .arg(&log);
        c.arg("-g")
            .arg(format!("pid {d}/nginx.pid; daemon off;"))
            .args(extra);
        c
    };
    let t = run(&["-t"])
        .output()
        .expect("nginx is required for the gateway test: run `bash .ci/setup`");
    assert!(
        t.status.success(),
        "nginx -t: {}\nconfig:\n{cfg}",
        String::from_utf8_lossy(&t.stderr)
    );
    let mut nginx = Gateway(
        run(&[])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let rest = format!("http://127.0.0.1:{rest_port}");
    let grpc = format!("http://127.0.0.1:{grpc_port}");
    let c = reqwest::Client::new();
    let t0 = Instant::now();
    while c.get(format!("{rest}/v1/categories")).send().await.is_err() {
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "nginx did not start (exit: {:?}):\n{}\nconfig:\n{cfg}",
            nginx.0.try_wait(),
            std::fs::read_to_string(&log).unwrap_or_default()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    exercise(&rest, &grpc).await;
    s.shutdown().await;
}

/// One REST job through the gateway at `rest`, its SSE stream (progress must arrive while the
/// job runs, not buffered to the end), then a gRPC `WatchJob` of it through `grpc` (h2c).
async fn exercise(rest: &str, grpc: &str) {
    let c = reqwest::Client::new();
    // REST submit + SSE through the gateway: progress arrives before the end of the job.
    let r = c
        .post(format!("{rest}/v1/jobs"))
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
        c.get(format!("{rest}/v1/jobs/{id}/events"))
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
    let mut cl = JobServiceClient::connect(grpc.to_string()).await.unwrap();
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
}
