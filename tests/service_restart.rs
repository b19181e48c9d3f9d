//! Durability: `kill -9` of a `physnap serve` child while a job runs, then a restart on the
//! same store. The job must be re-run and finish exactly once, with the same artefact bytes
//! as an uninterrupted run of the same request (fixed seed). Run on the SQLite store (same data
//! dir) and on PostgreSQL (the restarted server gets an empty data dir: nothing is on disk).

mod support;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use support::{SseReader, cloud, tiny_weights};

struct Child9 {
    child: Child,
    http: String,
}

impl Drop for Child9 {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `physnap serve` with `--data-dir root/<data> --store <store>`.
/// `physnap serve` on `store` with more flags (`--role`, `--lease-seconds`).
fn spawn_with(root: &Path, data: &str, store: &str, more: &[&str]) -> Child9 {
    let mut child = Command::new(env!("CARGO_BIN_EXE_physnap"))
        .args(["serve", "--http", "127.0.0.1:0", "--grpc", "127.0.0.1:0"])
        .args(more)
        .args(["--admin", "127.0.0.1:0", "--worker-threads", "1"])
        .arg("--data-dir")
        .arg(root.join(data))
        .env("PHYSNAP_STORE", store)
        .arg("--weights")
        .arg(root.join("weights"))
        .env("PHYSNAP_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("spawn physnap serve");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    // "physnap serve: http=127.0.0.1:P grpc=... admin=..."
    let http = line
        .split_whitespace()
        .find_map(|w| w.strip_prefix("http="))
        .unwrap_or_else(|| panic!("no address line: {line:?}"))
        .to_string();
    Child9 { child, http }
}

async fn get(c: &reqwest::Client, url: &str) -> Value {
    c.get(url).send().await.unwrap().json().await.unwrap()
}

async fn wait_done(c: &reqwest::Client, url: &str) -> Value {
    let t0 = Instant::now();
    loop {
        let j = get(c, url).await;
        if ["SUCCEEDED", "FAILED", "CANCELLED"].contains(&j["state"].as_str().unwrap()) {
            return j;
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "stuck: {j:#}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn glb_sha(j: &Value) -> String {
    j["artifacts"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"] == "model.glb")
        .unwrap()["sha256"]
        .as_str()
        .unwrap()
        .to_string()
}

/// The paper's 1000-step sampler: a long job that is surely still running at step 100.
fn long_job() -> Value {
    json!({"points": cloud(30), "seed": 11, "samples": 6, "resolution": 8,
           "sampler": "ddpm", "steps": 1000,
           "category": "Door", "w_pc": 0.0, "w_pen": 0.0, "w_mob": 0.0})
}

/// POST a job to the server at `http`; its id.
async fn submit(c: &reqwest::Client, http: &str, body: &Value) -> String {
    let r = c
        .post(format!("http://{http}/v1/jobs"))
        .json(body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    r.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string()
}

/// The job's SSE stream, read until progress reaches step 100 (the job must not end first).
async fn well_into_the_run(c: &reqwest::Client, url_job: &str) -> SseReader {
    let mut sse = SseReader::new(c.get(format!("{url_job}/events")).send().await.unwrap());
    loop {
        let e = sse.next().await.expect("stream ended before progress");
        if e.event == "progress" && e.json()["step"].as_u64().unwrap() >= 100 {
            return sse;
        }
        assert_ne!(
            e.event, "done",
            "the job finished before it could be killed"
        );
    }
}

/// The states of a finished job's event log, checking it has one `done`.
async fn states_of(c: &reqwest::Client, url_job: &str) -> Vec<String> {
    let events = SseReader::new(c.get(format!("{url_job}/events")).send().await.unwrap())
        .collect()
        .await;
    assert_eq!(events.iter().filter(|e| e.event == "done").count(), 1);
    assert_eq!(
        events.iter().filter(|e| e.event == "artifact").count(),
        physnap::service::api::ARTIFACT_NAMES.len()
    );
    events
        .iter()
        .filter(|e| e.event == "state")
        .map(|e| e.json()["state"].as_str().unwrap().to_string())
        .collect()
}

/// An uninterrupted run of the same request through `http` gives the bytes `job` (served at
/// `url_job`) has.
async fn same_bytes_as_uninterrupted(
    c: &reqwest::Client,
    http: &str,
    body: &Value,
    job: &Value,
    url_job: &str,
) {
    let id2 = submit(c, http, body).await;
    let job2 = wait_done(c, &format!("http://{http}/v1/jobs/{id2}")).await;
    assert_eq!(job2["attempt"], 1);
    assert_eq!(glb_sha(job), glb_sha(&job2));
    let bytes = c
        .get(format!("{url_job}/artifacts/model.glb"))
        .send()
        .await
        .unwrap()
        .bytes()
        .await
        .unwrap();
    use sha2::Digest as _;
    assert_eq!(format!("{:x}", sha2::Sha256::digest(&bytes)), glb_sha(job));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill_9_mid_run_then_restart_finishes_once_with_same_bytes() {
    kill_9_then_restart("sqlite", false).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill_9_mid_run_then_restart_on_postgres_finishes_once_with_same_bytes() {
    let (_pg, url) = tokio::task::block_in_place(|| {
        let pg = support::pg::Pg::start();
        let url = pg.fresh_db("restart");
        (pg, url)
    });
    kill_9_then_restart(&url, true).await;
}

/// `shared`: a shared store (PostgreSQL): the restarted server gets a new, empty data
/// directory, and takes the job over when its lease (2 s) expires, with no QUEUED in between.
async fn kill_9_then_restart(store: &str, shared: bool) {
    let lease: &[&str] = if shared {
        &["--lease-seconds", "2"]
    } else {
        &[]
    };
    let root = tempfile::tempdir().unwrap();
    tiny_weights(&root.path().join("weights"));
    let c = reqwest::Client::new();
    let body = long_job();
    let server = spawn_with(root.path(), "data", store, lease);
    let id = submit(&c, &server.http, &body).await;
    // Well into the run, SIGKILL.
    drop(well_into_the_run(&c, &format!("http://{}/v1/jobs/{id}", server.http)).await);
    drop(server); // kill -9 + wait

    let server = spawn_with(
        root.path(),
        if shared { "data2" } else { "data" },
        store,
        lease,
    );
    let url = format!("http://{}/v1/jobs/{id}", server.http);
    let job = wait_done(&c, &url).await;
    assert_eq!(job["state"], "SUCCEEDED", "{job:#}");
    assert_eq!(job["attempt"], 2, "{job:#}");
    let expected: &[&str] = if shared {
        &["QUEUED", "RUNNING", "RUNNING", "SUCCEEDED"]
    } else {
        &["QUEUED", "RUNNING", "QUEUED", "RUNNING", "SUCCEEDED"]
    };
    assert_eq!(states_of(&c, &url).await, expected);
    same_bytes_as_uninterrupted(&c, &server.http, &body, &job, &url).await;
    if shared {
        for data in ["data", "data2"] {
            assert!(!root.path().join(data).join("artifacts").exists());
        }
    }
}

#[test]
fn serve_logs_its_config_with_tokens_redacted() {
    let root = tempfile::tempdir().unwrap();
    tiny_weights(&root.path().join("weights"));
    let mut child = Command::new(env!("CARGO_BIN_EXE_physnap"))
        .args(["serve", "--http", "127.0.0.1:0", "--grpc", "127.0.0.1:0"])
        .args(["--admin", "127.0.0.1:0", "--worker-threads", "1"])
        .arg("--data-dir")
        .arg(root.path().join("data"))
        .arg("--weights")
        .arg(root.path().join("weights"))
        .env("PHYSNAP_LOG", "info")
        .env("PHYSNAP_TOKENS", "lab:very-secret-token-42")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.starts_with("physnap serve: http="), "{line:?}");
    // SIGTERM: graceful drain, then a clean exit.
    let pid = child.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .unwrap()
            .success()
    );
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "exit status {:?}", out.status);
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(log.contains("effective config"), "{log}");
    assert!(log.contains("lab"), "tenant names are logged: {log}");
    assert!(log.contains("[redacted]"), "{log}");
    assert!(!log.contains("very-secret-token-42"), "token leaked: {log}");
    assert!(log.contains("stopped"), "{log}");
}

#[test]
fn no_auth_is_refused_off_loopback() {
    let root = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_physnap"))
        .args(["serve", "--http", "0.0.0.0:0", "--grpc", "127.0.0.1:0"])
        .args(["--admin", "127.0.0.1:0"])
        .arg("--data-dir")
        .arg(root.path().join("data"))
        .arg("--weights")
        .arg(root.path().join("weights"))
        .env("PHYSNAP_LOG", "warn")
        .env_remove("PHYSNAP_TOKENS")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("no tokens configured") && e.contains("0.0.0.0"),
        "{e}"
    );
    assert!(
        !root.path().join("data").exists(),
        "nothing is created when refusing"
    );
}

/// Scale-out: an API replica and a worker on one PostgreSQL database, all `physnap serve`
/// processes. The API replica streams the worker's progress; `kill -9` of the worker mid-job,
/// then a second worker: the job is re-leased once its lease expires, runs once more (attempt
/// 2, no other run of it), and gives the bytes of an uninterrupted run.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill_9_of_a_worker_then_another_worker_finishes_its_job_once() {
    let (_pg, url) = tokio::task::block_in_place(|| {
        let pg = support::pg::Pg::start();
        let url = pg.fresh_db("workers");
        (pg, url)
    });
    let root = tempfile::tempdir().unwrap();
    tiny_weights(&root.path().join("weights"));
    let c = reqwest::Client::new();
    let body = long_job();
    let worker_flags = ["--role", "worker", "--lease-seconds", "2"];
    let api = spawn_with(root.path(), "api", &url, &["--role", "api"]);
    assert_ne!(api.http, "-");
    let worker = spawn_with(root.path(), "w1", &url, &worker_flags);
    assert_eq!(worker.http, "-", "a worker serves no API");
    let id = submit(&c, &api.http, &body).await;
    let url_job = format!("http://{}/v1/jobs/{id}", api.http);
    // The API replica streams the progress of the job running in the worker process.
    let sse = well_into_the_run(&c, &url_job).await;
    let t_kill = Instant::now();
    drop(worker); // kill -9 + wait
    let _worker2 = spawn_with(root.path(), "w2", &url, &worker_flags);
    // The stream that was open goes on to the end, through the takeover.
    let rest = sse.collect().await;
    assert_eq!(rest.iter().filter(|e| e.event == "done").count(), 1);
    let job = wait_done(&c, &url_job).await;
    assert!(
        t_kill.elapsed() >= Duration::from_millis(1500),
        "re-leased before expiry"
    );
    assert_eq!(job["state"], "SUCCEEDED", "{job:#}");
    assert_eq!(job["attempt"], 2, "{job:#}");
    assert_eq!(
        states_of(&c, &url_job).await,
        ["QUEUED", "RUNNING", "RUNNING", "SUCCEEDED"]
    );
    // An uninterrupted run gives the same bytes, served by the API replica from the database.
    same_bytes_as_uninterrupted(&c, &api.http, &body, &job, &url_job).await;
    for dir in ["api", "w1", "w2"] {
        assert!(!root.path().join(dir).join("artifacts").exists());
    }
}
