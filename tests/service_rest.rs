//! The REST API against a real server on ephemeral loopback ports, with tiny real weights: the
//! whole engine path (denoiser, projection, shape decoder, meshing, GLB export) runs.

mod common;
mod support;

use std::time::{Duration, Instant};

use base64::Engine as _;
use serde_json::{Value, json};
use sha2::{Digest, Sha256};
use support::{Opts, SseReader, cloud, f32le, problem, start};

fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(120))
        .build()
        .unwrap()
}

fn points_json(n: usize) -> Value {
    json!(cloud(n))
}

/// `n` test points as a PLY file (a raw upload body).
fn ply(n: usize) -> Vec<u8> {
    physnap::pointcloud::PointCloud { points: cloud(n) }.to_bytes(physnap::pointcloud::Format::Ply)
}

async fn submit(c: &reqwest::Client, url: &str, body: Value) -> reqwest::Response {
    c.post(url).json(&body).send().await.unwrap()
}

async fn wait_state(c: &reqwest::Client, url: &str, want: &[&str]) -> Value {
    let t0 = Instant::now();
    loop {
        let j: Value = c.get(url).send().await.unwrap().json().await.unwrap();
        if want.contains(&j["state"].as_str().unwrap()) {
            return j;
        }
        assert!(t0.elapsed() < Duration::from_secs(90), "stuck: {j:#}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn submit_stream_download_validate_resume() {
    let s = start(Opts::default()).await;
    let c = client();
    let r = submit(
        &c,
        &s.url("/v1/jobs"),
        json!({"points": points_json(64), "category": "Laptop", "seed": 5,
               "preview_every": 50, "resolution": 16,
               "w_pc": 0.0, "w_pen": 0.0, "w_mob": 0.0}),
    )
    .await;
    assert_eq!(r.status(), 202);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    let job: Value = r.json().await.unwrap();
    let id = job["id"].as_str().unwrap().to_string();
    assert_eq!(loc, format!("/v1/jobs/{id}"));
    assert_eq!(job["request"]["seed"], 5);
    assert_eq!(job["request"]["category"], "Laptop");
    assert_eq!(job["request"]["point_count"], 64);
    assert_eq!(job["request"]["guided"], false);

    // The whole event stream, from the start.
    let r = c.get(s.url(&format!("{loc}/events"))).send().await.unwrap();
    assert_eq!(r.headers()["x-accel-buffering"], "no");
    let evs = SseReader::new(r).collect().await;
    let kinds: Vec<&str> = evs.iter().map(|e| e.event.as_str()).collect();
    assert_eq!(kinds.first(), Some(&"state"), "{kinds:?}");
    assert_eq!(kinds.last(), Some(&"done"), "{kinds:?}");
    let states: Vec<String> = evs
        .iter()
        .filter(|e| e.event == "state")
        .map(|e| e.json()["state"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(states, ["QUEUED", "RUNNING", "SUCCEEDED"]);
    assert_eq!(
        evs.iter().filter(|e| e.event == "artifact").count(),
        physnap::service::api::ARTIFACT_NAMES.len(),
        "{kinds:?}"
    );
    let progress: Vec<Value> = evs
        .iter()
        .filter(|e| e.event == "progress")
        .map(|e| e.json())
        .collect();
    assert!(!progress.is_empty(), "no progress events: {kinds:?}");
    for p in &progress {
        assert_eq!(p["total_steps"], 200); // the default: DDIM over 200 steps
        assert!(p["step"].as_u64().unwrap() >= 1);
        assert!(["denoising", "meshing", "exporting"].contains(&p["phase"].as_str().unwrap()));
    }
    assert!(progress.iter().any(|p| p["eta_seconds"].is_number()));
    let preview = progress
        .iter()
        .find(|p| p.get("preview").is_some())
        .expect("a progress event with an x̂₀ preview");
    assert!(preview["step"].as_u64().unwrap() % 50 == 0 || preview["step"] == 200);
    assert!(!preview["preview"]["parts"].as_array().unwrap().is_empty());
    // Persisted events carry contiguous sequences 1..=N; progress ids repeat the last one.
    let persisted: Vec<u64> = evs
        .iter()
        .filter(|e| e.event != "progress")
        .map(|e| e.seq())
        .collect();
    assert_eq!(persisted, (1..=persisted.len() as u64).collect::<Vec<_>>());

    // Artefacts: GLB passes the Khronos validator; bytes match the advertised sha256.
    let done = evs.last().unwrap().json();
    assert_eq!(done["state"], "SUCCEEDED");
    let glb_meta = done["artifacts"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"] == "model.glb")
        .unwrap()
        .clone();
    assert_eq!(glb_meta["media_type"], "model/gltf-binary");
    let r = c
        .get(s.url(glb_meta["href"].as_str().unwrap()))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-type"], "model/gltf-binary");
    let glb = r.bytes().await.unwrap();
    assert_eq!(
        format!("{:x}", Sha256::digest(&glb)),
        glb_meta["sha256"].as_str().unwrap()
    );
    let path = s.root.path().join("downloaded.glb");
    std::fs::write(&path, &glb).unwrap();
    let report = common::gltf_validate(&path);
    assert_eq!(report["numErrors"], 0, "{report:#}");
    // Every media type the server sends is the one openapi.yaml documents for the download.
    let doc: Value = serde_json::from_str(&physnap::service::http::openapi_document()).unwrap();
    let documented =
        &doc["paths"]["/v1/jobs/{id}/artifacts/{name}"]["get"]["responses"]["200"]["content"];
    for (name, media) in [
        ("model.glb", "model/gltf-binary"),
        ("robot.zip", "application/zip"),
        ("model.xml", "application/xml"),
        ("object.json", "application/json"),
        ("ranking.json", "application/json"),
    ] {
        let r = c
            .get(s.url(&format!("{loc}/artifacts/{name}")))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200, "{name}");
        assert_eq!(r.headers()["content-type"], media, "{name}");
        assert!(
            documented.get(media).is_some(),
            "{name}: {media} is not documented: {documented}"
        );
        if name == "model.xml" {
            let xml = r.text().await.unwrap();
            assert!(
                xml.starts_with("<mujoco model=") && xml.contains("<worldbody>"),
                "{xml}"
            );
        }
    }
    let obj: Value = c
        .get(s.url(&format!("{loc}/artifacts/object.json")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(obj["category"], "Laptop");

    // Resume: after any persisted id, the replay is exactly the rest of the log.
    let last = *persisted.last().unwrap();
    for after in [0, 1, 2, last - 1] {
        let r = c
            .get(s.url(&format!("{loc}/events")))
            .header("last-event-id", after.to_string())
            .send()
            .await
            .unwrap();
        let replay: Vec<u64> = SseReader::new(r)
            .collect()
            .await
            .iter()
            .filter(|e| e.event != "progress")
            .map(|e| e.seq())
            .collect();
        assert_eq!(
            replay,
            ((after + 1)..=last).collect::<Vec<_>>(),
            "after {after}"
        );
    }
    // Already saw the terminal event: 204 stops EventSource reconnecting.
    let r = c
        .get(s.url(&format!("{loc}/events")))
        .header("last-event-id", last.to_string())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 204);

    // Same seed, same request → the same bytes (a second job).
    let r = submit(
        &c,
        &s.url("/v1/jobs"),
        json!({"points": points_json(64), "category": "Laptop", "seed": 5, "resolution": 16,
               "w_pc": 0.0, "w_pen": 0.0, "w_mob": 0.0}),
    )
    .await;
    let j2: Value = r.json().await.unwrap();
    let j2 = wait_state(
        &c,
        &s.url(&format!("/v1/jobs/{}", j2["id"].as_str().unwrap())),
        &["SUCCEEDED"],
    )
    .await;
    let sha2 = j2["artifacts"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"] == "model.glb")
        .unwrap()["sha256"]
        .clone();
    assert_eq!(sha2, glb_meta["sha256"]);

    // Listing pages through both jobs; delete removes a finished job.
    let page: Value = c
        .get(s.url("/v1/jobs?page_size=1"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(page["jobs"].as_array().unwrap().len(), 1);
    assert_eq!(page["jobs"][0]["id"], id.as_str());
    let tok = page["next_page_token"].as_str().unwrap();
    let page2: Value = c
        .get(s.url(&format!("/v1/jobs?page_size=1&page_token={tok}")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(page2["jobs"][0]["id"], j2["id"]);
    assert!(page2["next_page_token"].is_null());
    let r = c.delete(s.url(&loc)).send().await.unwrap();
    assert_eq!(r.status(), 204);
    problem(c.get(s.url(&loc)).send().await.unwrap(), 404).await;
    assert!(!support::data_dir(&s).join("artifacts").join(&id).exists());

    // Metrics and health on the admin listener.
    let admin = format!("http://{}", s.addrs.admin);
    let m = c
        .get(format!("{admin}/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(m.contains("physnap_jobs_succeeded_total 2"), "{m}");
    assert_eq!(
        c.get(format!("{admin}/readyz"))
            .send()
            .await
            .unwrap()
            .status(),
        200
    );
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn idempotency_key_replays_and_rejects_a_different_body() {
    let s = start(Opts::default()).await;
    let c = client();
    let body = json!({"points": points_json(32), "seed": 1, "resolution": 8});
    let post = |b: Value| {
        c.post(s.url("/v1/jobs"))
            .header("idempotency-key", "k-1")
            .json(&b)
            .send()
    };
    let a: Value = post(body.clone()).await.unwrap().json().await.unwrap();
    let r = post(body.clone()).await.unwrap();
    assert_eq!(r.status(), 202);
    let b: Value = r.json().await.unwrap();
    assert_eq!(a["id"], b["id"]);
    let p = problem(
        post(json!({"points": points_json(32), "seed": 2}))
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["type"], "/problems/idempotency-key-reused");
    let list: Value = c
        .get(s.url("/v1/jobs"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(list["jobs"].as_array().unwrap().len(), 1);
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn queue_full_429_cancel_and_deadline() {
    let s = start(Opts {
        max_running_jobs: 1,
        queue_capacity: 1,
        ..Default::default()
    })
    .await;
    let c = client();
    let long = |extra: Value| {
        let mut b = json!({"points": points_json(32), "samples": 16, "resolution": 8,
                           "sampler": "ddpm", "steps": 1000});
        for (k, v) in extra.as_object().unwrap() {
            b[k] = v.clone();
        }
        b
    };
    // A runs, B waits, C finds the queue full.
    let a: Value = submit(&c, &s.url("/v1/jobs"), long(json!({})))
        .await
        .json()
        .await
        .unwrap();
    let a_url = s.url(&format!("/v1/jobs/{}", a["id"].as_str().unwrap()));
    wait_state(&c, &a_url, &["RUNNING"]).await;
    let b: Value = submit(&c, &s.url("/v1/jobs"), long(json!({})))
        .await
        .json()
        .await
        .unwrap();
    assert_eq!(b["state"], "QUEUED");
    let r = submit(&c, &s.url("/v1/jobs"), long(json!({}))).await;
    assert_eq!(r.headers()["retry-after"], "7");
    let p = problem(r, 429).await;
    assert_eq!(p["type"], "/problems/queue-full");
    assert!(p["detail"].as_str().unwrap().contains("limit 1"), "{p}");

    // Cancel the queued job: CANCELLED at once.
    let b_url = s.url(&format!("/v1/jobs/{}", b["id"].as_str().unwrap()));
    let r: Value = c
        .post(format!("{b_url}/cancel"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(r["state"], "CANCELLED");

    // Cancel the running job mid-run: it stops at the next step.
    let mut sse = SseReader::new(c.get(format!("{a_url}/events")).send().await.unwrap());
    let mut last_step = 0;
    while let Some(e) = sse.next().await {
        if e.event == "progress" {
            last_step = e.json()["step"].as_u64().unwrap();
            break;
        }
    }
    assert!(last_step > 0);
    let t0 = Instant::now();
    let r: Value = c
        .post(format!("{a_url}/cancel"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(r["cancel_requested"], true);
    let mut done = None;
    while let Some(e) = sse.next().await {
        if e.event == "done" {
            done = Some(e.json());
        }
    }
    let latency = t0.elapsed();
    let done = done.expect("done event");
    assert_eq!(done["state"], "CANCELLED", "{done:#}");
    assert_eq!(done["error"]["type"], "cancelled");
    assert!(
        done["error"]["detail"]
            .as_str()
            .unwrap()
            .contains("at step"),
        "{done:#}"
    );
    assert!(latency < Duration::from_secs(5), "cancel took {latency:?}");
    // Cancelling again is idempotent; a finished job cannot be cancelled into another state.
    let r: Value = c
        .post(format!("{a_url}/cancel"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(r["state"], "CANCELLED");

    // Deadline: a job that cannot finish in 0.3 s fails with a clear reason.
    let d: Value = submit(
        &c,
        &s.url("/v1/jobs"),
        long(json!({"deadline_seconds": 0.3})),
    )
    .await
    .json()
    .await
    .unwrap();
    let d = wait_state(
        &c,
        &s.url(&format!("/v1/jobs/{}", d["id"].as_str().unwrap())),
        &["FAILED", "SUCCEEDED", "CANCELLED"],
    )
    .await;
    assert_eq!(d["state"], "FAILED", "{d:#}");
    assert_eq!(d["error"]["type"], "deadline-exceeded");
    let detail = d["error"]["detail"].as_str().unwrap();
    assert!(detail.contains("deadline of 0.3 s exceeded"), "{detail}");
    // A finished job's artefacts are not there; cancelling it is a conflict.
    let p = problem(
        c.get(s.url(&format!(
            "/v1/jobs/{}/artifacts/model.glb",
            d["id"].as_str().unwrap()
        )))
        .send()
        .await
        .unwrap(),
        409,
    )
    .await;
    assert_eq!(p["type"], "/problems/job-not-finished");
    let p = problem(
        c.post(s.url(&format!("/v1/jobs/{}/cancel", d["id"].as_str().unwrap())))
            .send()
            .await
            .unwrap(),
        409,
    )
    .await;
    assert_eq!(p["type"], "/problems/job-already-finished");
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_inputs_get_problems_and_nothing_is_stored() {
    let s = start(Opts {
        max_body_bytes: 2 << 20,
        ..Default::default()
    })
    .await;
    let c = client();
    let b64 = |b: &[u8]| base64::engine::general_purpose::STANDARD.encode(b);
    let mut nan = cloud(20);
    nan[3][1] = f32::NAN;
    let cases: Vec<(Value, u16, &str, &str)> = vec![
        (
            json!({"points_f32le_base64": b64(&f32le(&nan))}),
            422,
            "points[3][1]",
            "NaN",
        ),
        (json!({"points": []}), 422, "points", "0 points"),
        (
            json!({"points_f32le_base64": b64(&f32le(&cloud(100_001)))}),
            422,
            "points",
            "100001 points",
        ),
        (
            json!({"points": points_json(10)}),
            422,
            "points",
            "10 points",
        ),
        (
            json!({"points": points_json(20), "category": "Spaceship"}),
            422,
            "category",
            "\"Spaceship\"",
        ),
        (
            json!({"points": points_json(20), "w_pen": -0.5}),
            422,
            "w_pen",
            "-0.5",
        ),
        (
            json!({"points": points_json(20), "samples": 99}),
            422,
            "samples",
            "99",
        ),
        (json!({"category": "Laptop"}), 422, "points", "missing"),
    ];
    for (body, status, field, value) in cases {
        let p = problem(submit(&c, &s.url("/v1/jobs"), body.clone()).await, status).await;
        assert_eq!(p["type"], "/problems/validation");
        let e = &p["errors"][0];
        assert_eq!(e["field"], field, "{p:#}");
        assert!(e["value"].as_str().unwrap().contains(value), "{p:#}");
        assert!(!e["limit"].as_str().unwrap().is_empty());
        assert!(p["detail"].as_str().unwrap().contains(field), "{p:#}");
    }
    // Malformed JSON, an unknown field, a malformed PLY upload, a wrong content type.
    let p = problem(
        c.post(s.url("/v1/jobs"))
            .header("content-type", "application/json")
            .body("{\"points\": [[1,2,")
            .send()
            .await
            .unwrap(),
        400,
    )
    .await;
    assert_eq!(p["type"], "/problems/malformed-request");
    let p = problem(
        submit(
            &c,
            &s.url("/v1/jobs"),
            json!({"points": points_json(20), "wpc": 1}),
        )
        .await,
        422,
    )
    .await;
    assert!(p["detail"].as_str().unwrap().contains("wpc"), "{p}");
    assert_eq!(p["errors"][0]["field"], "wpc", "{p}");
    let p = problem(
        c.post(s.url("/v1/jobs?seed=3"))
            .header("content-type", "application/x-ply")
            .body("ply\nformat ascii 1.0\nelement vertex 20\nproperty float x\nend_header\n1 2 3\n")
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["errors"][0]["field"], "points");
    assert!(p["detail"].as_str().unwrap().contains("PLY"), "{p}");
    problem(
        c.post(s.url("/v1/jobs"))
            .header("content-type", "text/plain")
            .body("hello")
            .send()
            .await
            .unwrap(),
        415,
    )
    .await;
    // Oversize body: 413 problem+json from the app. The server answers as soon as the
    // Content-Length exceeds the limit; over HTTP/1.1 a client still sending may see the
    // connection close before it reads that answer (a race that lost under CI load), so this
    // request uses HTTP/2, where the early answer always arrives.
    let h2 = reqwest::Client::builder()
        .http2_prior_knowledge()
        .timeout(Duration::from_secs(120))
        .build()
        .unwrap();
    let p = problem(
        h2.post(s.url("/v1/jobs"))
            .header("content-type", "application/octet-stream")
            .body(vec![0u8; 3 << 20])
            .send()
            .await
            .unwrap(),
        413,
    )
    .await;
    assert!(p["detail"].as_str().unwrap().contains("2097152"), "{p}");
    // Nothing was stored.
    let list: Value = c
        .get(s.url("/v1/jobs"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert!(list["jobs"].as_array().unwrap().is_empty(), "{list}");
    assert_eq!(s.svc.counts().await.unwrap(), vec![]);
    // A valid raw PLY upload is accepted (the reader path).
    let upload = ply(40);
    let r = c
        .post(s.url("/v1/jobs?seed=3&resolution=8&category=Door"))
        .header("content-type", "application/x-ply")
        .body(upload)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let j: Value = r.json().await.unwrap();
    assert_eq!(j["request"]["point_count"], 40);
    assert_eq!(j["request"]["category"], "Door");
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tenants_see_only_their_jobs() {
    let s = start(Opts {
        tokens: "alice:alice-token-1,bob:bob-token-22".into(),
        ..Default::default()
    })
    .await;
    let c = client();
    let r = c
        .post(s.url("/v1/jobs"))
        .bearer_auth("alice-token-1")
        .json(&json!({"points": points_json(20), "resolution": 8}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let url = s.url(&format!("/v1/jobs/{id}"));
    assert_eq!(
        c.get(&url)
            .bearer_auth("alice-token-1")
            .send()
            .await
            .unwrap()
            .status(),
        200
    );
    for path in ["", "/events", "/artifacts/model.glb"] {
        problem(
            c.get(format!("{url}{path}"))
                .bearer_auth("bob-token-22")
                .send()
                .await
                .unwrap(),
            404,
        )
        .await;
    }
    problem(
        c.post(format!("{url}/cancel"))
            .bearer_auth("bob-token-22")
            .send()
            .await
            .unwrap(),
        404,
    )
    .await;
    let bobs: Value = c
        .get(s.url("/v1/jobs"))
        .bearer_auth("bob-token-22")
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert!(bobs["jobs"].as_array().unwrap().is_empty());
    let r = c.get(&url).send().await.unwrap();
    assert_eq!(r.headers()["www-authenticate"], "Bearer");
    problem(r, 401).await;
    problem(
        c.get(&url)
            .bearer_auth("nope-nope-nope")
            .send()
            .await
            .unwrap(),
        401,
    )
    .await;
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn drain_refuses_new_jobs_with_503() {
    let s = start(Opts::default()).await;
    let c = client();
    let svc = s.svc.clone();
    let drain = tokio::spawn(async move { svc.shutdown(Duration::from_secs(5)).await });
    tokio::time::sleep(Duration::from_millis(50)).await;
    let r = submit(&c, &s.url("/v1/jobs"), json!({"points": points_json(20)})).await;
    assert_eq!(r.headers()["retry-after"], "7");
    let p = problem(r, 503).await;
    assert_eq!(p["type"], "/problems/shutting-down");
    assert_eq!(
        c.get(format!("http://{}/readyz", s.addrs.admin))
            .send()
            .await
            .unwrap()
            .status(),
        503
    );
    drain.await.unwrap();
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sse_resume_mid_run_loses_no_state_event() {
    let s = start(Opts::default()).await;
    let c = client();
    let j: Value = submit(
        &c,
        &s.url("/v1/jobs"),
        json!({"points": points_json(32), "samples": 8, "resolution": 8, "seed": 3,
               "sampler": "ddpm", "steps": 1000, "w_pc": 0.0, "w_pen": 0.0, "w_mob": 0.0}),
    )
    .await
    .json()
    .await
    .unwrap();
    let ev_url = s.url(&format!("/v1/jobs/{}/events", j["id"].as_str().unwrap()));
    // First connection: read until the job is running and has made progress, then hang up.
    let mut seen = Vec::new();
    let mut sse = SseReader::new(c.get(&ev_url).send().await.unwrap());
    let mut last_id = 0;
    while let Some(e) = sse.next().await {
        last_id = e.seq();
        if e.event != "progress" {
            seen.push(e.seq());
        } else if e.json()["step"].as_u64().unwrap() > 50 {
            break;
        }
        assert_ne!(e.event, "done", "finished before the disconnect");
    }
    drop(sse);
    assert!(
        seen.contains(&2),
        "RUNNING not seen before disconnect: {seen:?}"
    );
    // The job keeps running without a client; reconnect with Last-Event-ID.
    let r = c
        .get(&ev_url)
        .header("last-event-id", last_id.to_string())
        .send()
        .await
        .unwrap();
    let rest = SseReader::new(r).collect().await;
    assert!(
        rest.iter().any(|e| e.event == "progress"),
        "a resumed stream gets progress"
    );
    seen.extend(
        rest.iter()
            .filter(|e| e.event != "progress")
            .map(|e| e.seq()),
    );
    assert_eq!(seen, (1..=seen.len() as u64).collect::<Vec<_>>());
    assert_eq!(rest.last().unwrap().event, "done");
    assert_eq!(rest.last().unwrap().json()["state"], "SUCCEEDED");
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn guided_ddim_job_streams_losses_and_ranks_best_of_n() {
    let s = start(Opts::default()).await;
    let c = client();
    // Repair off: the joint-motion check below needs the projection's joints, and with the
    // untrained test weights the part removal can leave a sample without any.
    let r = submit(
        &c,
        &s.url("/v1/jobs"),
        json!({"points": points_json(64), "seed": 3, "samples": 2, "resolution": 8,
               "sampler": "ddim", "eta": 0.0, "steps": 20, "n_g": 500, "w_pc": 15.0,
               "tau": 1000.0, "preview_every": 1, "guidance_max_step": 0.05,
               "repair": "off"}),
    )
    .await;
    assert_eq!(r.status(), 202);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    let job: Value = r.json().await.unwrap();
    let req = &job["request"];
    assert_eq!(req["guided"], true);
    assert_eq!(
        (req["n_g"].as_u64(), req["steps"].as_u64()),
        (Some(500), Some(20))
    );
    assert_eq!(
        (req["sampler"].as_str(), req["tau"].as_f64()),
        (Some("ddim"), Some(1000.0))
    );
    // auto retrieval resolves to off for weights without a codebook.
    assert_eq!(req["retrieval"], "off", "{req}");
    // No category: no category guidance.
    assert_eq!(req["category_guidance"].as_f64(), Some(0.0), "{req}");
    // A scan-guided job is category-guided in every step by default (echoed as run).
    assert_eq!(req["category_guidance_below"].as_u64(), Some(1000), "{req}");
    // The default joint motion: one per joint.
    assert_eq!(req["joint_motion"], "dominant", "{req}");
    // Unset weights follow physnap's rule: the paper's 2 ÷ 3 terms, × 3 for ℓ_pen and ℓ_mob.
    for (key, want) in [("w_pc", 15.0), ("w_pen", 2.0), ("w_mob", 2.0)] {
        let got = req[key].as_f64().unwrap();
        assert!((got - want).abs() < 1e-12, "{key}: {req}");
    }

    let r = c.get(s.url(&format!("{loc}/events"))).send().await.unwrap();
    let evs = SseReader::new(r).collect().await;
    let done = evs.last().unwrap().json();
    assert_eq!(done["state"], "SUCCEEDED", "{done:#}");
    let progress: Vec<Value> = evs
        .iter()
        .filter(|e| e.event == "progress")
        .map(|e| e.json())
        .collect();
    // 20 reverse steps, then the default 30 refinement steps (at t = 0, each with losses).
    assert_eq!(req["refine_steps"], 30, "{req}");
    assert!(
        progress.iter().all(|p| p["total_steps"] == 50),
        "{progress:?}"
    );
    // (The exporting event that may follow carries step 50 but no losses; the stream delivers
    // it or not depending on timing, so it is not a refinement step.)
    let refined: Vec<&Value> = progress
        .iter()
        .filter(|p| p["step"].as_u64().unwrap() > 20 && p["phase"] == "denoising")
        .collect();
    assert!(!refined.is_empty(), "no refinement progress: {progress:?}");
    assert!(
        refined
            .iter()
            .all(|p| p["t"] == 0 && p.get("guidance").is_some()),
        "{refined:?}"
    );
    // The last reverse step (t = 0) is always guided with n_g >= 1, and it is a preview.
    let guided: Vec<&Value> = progress
        .iter()
        .filter(|p| p.get("guidance").is_some())
        .collect();
    assert!(
        !guided.is_empty(),
        "no progress event with loss values: {progress:?}"
    );
    for p in &guided {
        let g = &p["guidance"];
        for k in ["l_pc", "l_pen", "l_mob", "total"] {
            assert!(g[k].as_f64().is_some_and(f64::is_finite), "{k}: {g}");
        }
        assert!(g["l_pc"].as_f64().unwrap() > 0.0, "{g}");
        // Only the steps with t < n_g = 500 are guided: the last 10 of the 20.
        assert!(p["step"].as_u64().unwrap() > 10, "{p}");
    }

    // ranking.json: both samples, best first by D_pc, the exported one marked.
    let ranking: Value = c
        .get(s.url(&format!("{loc}/artifacts/ranking.json")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(ranking["format"], "physnap.job_ranking/v1");
    assert_eq!(ranking["guided"], true);
    assert_eq!(ranking["guidance"]["n_g"], 500);
    assert_eq!(ranking["guidance"]["refine_steps"], 30);
    assert_eq!(ranking["retrieval"], "off");
    assert_eq!(ranking["joint_motion"], "dominant");
    let rows = ranking["samples"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{ranking:#}");
    let d: Vec<f64> = rows.iter().map(|r| r["d_pc"].as_f64().unwrap()).collect();
    assert!(d[0] <= d[1], "{ranking:#}");
    // Every finished sample reports how much of its surface is buried in another part.
    for r in rows {
        let o = r["o_mesh"].as_f64().unwrap_or(-1.0);
        assert!((0.0..=1.0).contains(&o), "{ranking:#}");
    }
    assert_eq!(rows[0]["exported"], true);
    assert_eq!(rows[0]["diverged"], false);
    assert_eq!(rows[0]["retrieved_parts"], json!([]));
    assert_eq!(ranking["best"], rows[0]["index"]);
    let seeds: Vec<u64> = rows.iter().map(|r| r["seed"].as_u64().unwrap()).collect();
    assert!(seeds.contains(&3) && seeds.contains(&4), "{seeds:?}");
    let model: Value = c
        .get(s.url(&format!("{loc}/artifacts/object.json")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(
        model["name"].as_str().unwrap(),
        format!("sample_{:03}", rows[0]["index"].as_u64().unwrap())
    );
    // joint_motion "dominant": every joint rotates, slides or is fixed, none is a screw.
    let joints = model["joints"].as_array().unwrap();
    assert!(!joints.is_empty(), "{model}");
    assert!(joints.iter().all(|j| j["type"] != "screw"), "{model}");
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn physics_refinement_steps_are_a_job_setting_counted_in_progress() {
    let s = start(Opts::default()).await;
    let c = client();
    // (physics steps asked, w_pen = w_mob, total progress steps): 10 reverse steps and 2
    // refinement steps, then the 3 physics-only steps, which run only with w_pen or w_mob > 0.
    for (w_phys, want_total) in [(2.0, 15), (0.0, 12)] {
        let r = submit(
            &c,
            &s.url("/v1/jobs"),
            json!({"points": points_json(64), "seed": 5, "resolution": 8, "sampler": "ddim",
                   "steps": 10, "n_g": 500, "w_pc": 15.0, "w_pen": w_phys, "w_mob": w_phys,
                   "guidance_max_step": 0.05, "refine_steps": 2, "refine_physics_steps": 3}),
        )
        .await;
        assert_eq!(r.status(), 202);
        let loc = r.headers()["location"].to_str().unwrap().to_string();
        let job: Value = r.json().await.unwrap();
        let req = &job["request"];
        assert_eq!(req["refine_physics_steps"], 3, "{req}");
        let r = c.get(s.url(&format!("{loc}/events"))).send().await.unwrap();
        let evs = SseReader::new(r).collect().await;
        let done = evs.last().unwrap().json();
        assert_eq!(done["state"], "SUCCEEDED", "{done:#}");
        let progress: Vec<Value> = evs
            .iter()
            .filter(|e| e.event == "progress")
            .map(|e| e.json())
            .collect();
        assert!(!progress.is_empty());
        assert!(
            progress.iter().all(|p| p["total_steps"] == want_total),
            "w_pen = w_mob = {w_phys}: {progress:?}"
        );
        let ranking: Value = c
            .get(s.url(&format!("{loc}/artifacts/ranking.json")))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        assert_eq!(
            ranking["guidance"]["refine_physics_steps"], 3,
            "{ranking:#}"
        );
    }
    s.shutdown().await;
}

/// Each `(query, field, value)`: an NPY upload with that query string is refused with 422,
/// its first error naming the field and the value as written, with a limit.
async fn assert_query_refused(
    c: &reqwest::Client,
    s: &support::TestServer,
    npy: &[u8],
    cases: &[(&str, &str, &str)],
) {
    for &(query, field, value) in cases {
        let r = c
            .post(s.url(&format!("/v1/jobs?{query}")))
            .header("content-type", "application/x-npy")
            .body(npy.to_vec())
            .send()
            .await
            .unwrap();
        let p = problem(r, 422).await;
        let e = &p["errors"][0];
        assert_eq!(
            (e["field"].as_str(), e["value"].as_str()),
            (Some(field), Some(value)),
            "{query}: {p}"
        );
        assert!(!e["limit"].as_str().unwrap().is_empty(), "{p}");
    }
}

async fn json_artifact(
    c: &reqwest::Client,
    s: &support::TestServer,
    loc: &str,
    name: &str,
) -> Value {
    let r = c
        .get(s.url(&format!("{loc}/artifacts/{name}")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200, "{name}");
    r.json().await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cameras_w_free_and_repair_reach_the_job_and_its_ranking() {
    let s = start(Opts::default()).await;
    let c = client();
    // cloud(64) lies in [-0.5, 0.5] × [-0.3, 0.3] × [0.1, 0.9]: both cameras are outside it.
    let quick = json!({"points": points_json(64), "seed": 5, "resolution": 8,
                       "sampler": "ddim", "steps": 10, "n_g": 500, "refine_steps": 2,
                       "guidance_max_step": 0.05});
    // JSON, one camera as a single triple: ℓ_free at its default weight, repair on.
    let mut body = quick.clone();
    body["camera"] = json!([-2.0, 0.0, 0.5]);
    let r = submit(&c, &s.url("/v1/jobs"), body).await;
    assert_eq!(r.status(), 202);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    let job: Value = r.json().await.unwrap();
    let req = &job["request"];
    assert_eq!(req["camera"], json!([[-2.0, 0.0, 0.5]]), "{req}");
    assert_eq!(
        (req["w_free"].as_f64(), req["repair"].as_str()),
        (Some(15.0), Some("on")),
        "{req}"
    );
    let r = c.get(s.url(&format!("{loc}/events"))).send().await.unwrap();
    let evs = SseReader::new(r).collect().await;
    let done = evs.last().unwrap().json();
    assert_eq!(done["state"], "SUCCEEDED", "{done:#}");
    // Progress reports ℓ_free next to the other terms.
    let losses: Vec<Value> = evs
        .iter()
        .filter(|e| e.event == "progress")
        .filter_map(|e| e.json().get("guidance").cloned())
        .collect();
    assert!(!losses.is_empty());
    assert!(
        losses.iter().all(|g| g["l_free"]
            .as_f64()
            .is_some_and(|v| v.is_finite() && v >= 0.0)),
        "{losses:?}"
    );
    let ranking = json_artifact(&c, &s, &loc, "ranking.json").await;
    assert_eq!(ranking["guidance"]["w_free"], 15.0, "{ranking:#}");
    assert_eq!(
        ranking["guidance"]["cameras"],
        json!([[-2.0, 0.0, 0.5]]),
        "{ranking:#}"
    );
    assert_eq!(ranking["repair"], "on");
    let row = &ranking["samples"][0];
    assert!(row["repairs"].as_u64().is_some(), "{ranking:#}");
    // The score is the sum of its four terms, each listed; a sample without a surface (the
    // test weights' often are) has no D_pc and so no score, and ranks last.
    let terms = [
        "d_pc_per_scan_diagonal",
        "free",
        "attach_per_object_diagonal",
        "o_mesh",
    ];
    for t in terms {
        assert!(row["terms"].get(t).is_some(), "{t}: {ranking:#}");
    }
    if row["d_pc"].is_null() {
        assert!(row["score"].is_null(), "{ranking:#}");
    } else {
        let sum: f64 = terms.iter().filter_map(|t| row["terms"][t].as_f64()).sum();
        assert!(
            (sum - row["score"].as_f64().unwrap()).abs() < 1e-9,
            "{ranking:#}"
        );
    }
    let removed = row["removed"].as_array().expect("removed is a list");
    for r in removed {
        assert!(!r["part"].as_str().unwrap().is_empty(), "{r}");
        assert!(
            ["empty", "free_space", "floating"].contains(&r["reason"].as_str().unwrap()),
            "{r}"
        );
        assert!(!r["detail"].as_str().unwrap().is_empty(), "{r}");
    }
    // A raw NPY upload with the knobs in the query string: `camera` repeats (the second with
    // its commas percent-encoded), and repair off leaves the sample as projected.
    let npy = physnap::pointcloud::PointCloud { points: cloud(64) }
        .to_bytes(physnap::pointcloud::Format::Npy);
    let r = c
        .post(s.url(
            "/v1/jobs?camera=-2,0,0.5&camera=0%2C-2%2C0.5&w_free=3&repair=off&seed=5\
             &resolution=8&sampler=ddim&steps=10&n_g=500&refine_steps=2&guidance_max_step=0.05",
        ))
        .header("content-type", "application/x-npy")
        .body(npy.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    let job: Value = r.json().await.unwrap();
    let req = &job["request"];
    assert_eq!(req["point_count"], 64);
    assert_eq!(
        req["camera"],
        json!([[-2.0, 0.0, 0.5], [0.0, -2.0, 0.5]]),
        "{req}"
    );
    assert_eq!(
        (req["w_free"].as_f64(), req["repair"].as_str()),
        (Some(3.0), Some("off")),
        "{req}"
    );
    let j = wait_state(&c, &s.url(&loc), &["SUCCEEDED", "FAILED"]).await;
    assert_eq!(j["state"], "SUCCEEDED", "{j:#}");
    let ranking = json_artifact(&c, &s, &loc, "ranking.json").await;
    assert_eq!(ranking["guidance"]["w_free"], 3.0, "{ranking:#}");
    assert_eq!(ranking["guidance"]["cameras"].as_array().unwrap().len(), 2);
    assert_eq!(ranking["repair"], "off");
    assert_eq!(ranking["samples"][0]["repairs"], 0, "{ranking:#}");
    assert_eq!(ranking["samples"][0]["removed"], json!([]), "{ranking:#}");
    // JSON, a list of cameras and repair off.
    let mut body = quick.clone();
    body["camera"] = json!([[-2.0, 0.0, 0.5]]);
    body["repair"] = json!("off");
    body["w_free"] = json!(0.0);
    let r = submit(&c, &s.url("/v1/jobs"), body).await;
    assert_eq!(r.status(), 202);
    let job: Value = r.json().await.unwrap();
    let req = &job["request"];
    assert_eq!(req["camera"], json!([[-2.0, 0.0, 0.5]]), "{req}");
    assert_eq!(
        (req["w_free"].as_f64(), req["repair"].as_str()),
        (Some(0.0), Some("off")),
        "{req}"
    );
    // Bad cameras in the query string are named as written.
    let cases = [
        ("camera=1,2", "camera", "[1, 2]"),
        ("camera=up", "camera", "\"up\""),
        (
            "camera=-2,0,0.5&camera=0,nan,0.5",
            "camera[1]",
            "[0, NaN, 0.5]",
        ),
        ("camera=0,0,0.5", "camera", "[0.0, 0.0, 0.5]"),
        ("repair=sometimes", "repair", "\"sometimes\""),
    ];
    assert_query_refused(&c, &s, &npy, &cases).await;
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frame_auto_is_estimated_at_submission_and_reaches_the_artefacts() {
    let s = start(Opts::default()).await;
    let c = client();
    // Three faces of a 0.6 × 0.5 × 0.8 m box seen from the front-left (front −X, +Z up), a
    // metre off the origin: the frame is estimated at submission.
    let mut pts = Vec::new();
    for i in 0..12 {
        for j in 0..12 {
            let (u, v) = (i as f64 / 11.0, j as f64 / 11.0);
            pts.push(json!([1.0 - 0.3, -0.25 + 0.5 * u, 0.8 * v]));
            pts.push(json!([1.0 - 0.3 + 0.6 * u, -0.25, 0.8 * v]));
            pts.push(json!([1.0 - 0.3 + 0.6 * u, -0.25 + 0.5 * v, 0.8]));
        }
    }
    let body = json!({"points": pts, "seed": 5, "resolution": 8, "sampler": "ddim",
                      "steps": 10, "n_g": 500, "refine_steps": 2, "guidance_max_step": 0.05,
                      "camera": [-1.5, -1.5, 1.5], "frame": "auto", "up": [0.0, 0.0, 1.0]});
    let r = submit(&c, &s.url("/v1/jobs"), body).await;
    assert_eq!(r.status(), 202);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    let job: Value = r.json().await.unwrap();
    let f = &job["request"]["frame"];
    assert_eq!(f["mode"], "auto", "{job:#}");
    let yaw = f["yaw_degrees"].as_f64().unwrap();
    assert!(yaw.min(360.0 - yaw) < 5.0, "{f}");
    // The box is centred in x/y and stood on the floor.
    let t = f["translation"].as_array().unwrap();
    assert!((t[0].as_f64().unwrap() + 1.0).abs() < 0.05, "{f}");
    assert!(t[2].as_f64().unwrap().abs() < 0.05, "{f}");
    let j = wait_state(&c, &s.url(&loc), &["SUCCEEDED", "FAILED"]).await;
    assert_eq!(j["state"], "SUCCEEDED", "{j:#}");
    let ranking = json_artifact(&c, &s, &loc, "ranking.json").await;
    assert_eq!(ranking["frame"]["mode"], "auto", "{ranking:#}");
    assert!(ranking["frame"]["floor"].is_number(), "{ranking:#}");
    let object = json_artifact(&c, &s, &loc, "object.json").await;
    assert_eq!(object["frame"]["mode"], "auto", "{object:#}");
    assert!(object["scan_frame"]["parts"].is_array(), "{object:#}");
    // Bad frames are refused naming the field, the limit and the value.
    let npy = physnap::pointcloud::PointCloud { points: cloud(64) }
        .to_bytes(physnap::pointcloud::Format::Npy);
    let cases = [
        ("frame=auto&up=0,0,0", "up", "0,0,0"),
        ("frame=auto&up=1,2", "up", "\"1,2\""),
        ("up=0,1,0", "up", "[0.0, 1.0, 0.0]"),
        ("frame=tilted", "frame", "\"tilted\""),
    ];
    assert_query_refused(&c, &s, &npy, &cases).await;
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn guidance_and_sampler_fields_are_validated() {
    let s = start(Opts::default()).await;
    let c = client();
    let cases = [
        (json!({"steps": 20, "n_g": 2500}), "n_g", "2500"),
        (json!({"n_g": 1001}), "n_g", "1001"),
        (json!({"tau": 0.0}), "tau", "0"),
        (json!({"tau": -3.5}), "tau", "-3.5"),
        (json!({"sampler": "euler"}), "sampler", "\"euler\""),
        (json!({"sampler": "ddim", "eta": 2.0}), "eta", "2"),
        (json!({"steps": 0}), "steps", "0"),
        (json!({"steps": 1001}), "steps", "1001"),
        (
            json!({"guidance_max_step": -1.0}),
            "guidance_max_step",
            "-1",
        ),
        (json!({"refine_steps": 1001}), "refine_steps", "1001"),
        (
            json!({"refine_physics_steps": 1001}),
            "refine_physics_steps",
            "1001",
        ),
        (json!({"retrieval": "nearest"}), "retrieval", "\"nearest\""),
        (
            json!({"joint_motion": "revolute"}),
            "joint_motion",
            "\"revolute\"",
        ),
        // The test weights have no codebook: only off / auto are possible.
        (json!({"retrieval": "empty"}), "retrieval", "\"empty\""),
        (
            json!({"category_guidance": 25.0}),
            "category_guidance",
            "25",
        ),
        // Category guidance needs a category to extrapolate from.
        (json!({"category_guidance": 2.0}), "category_guidance", "2"),
        (
            json!({"category_guidance_below": 0}),
            "category_guidance_below",
            "0",
        ),
        (
            json!({"category_guidance_below": 1001}),
            "category_guidance_below",
            "1001",
        ),
        // A camera inside the points' box, a triple of the wrong length, more than 16.
        (
            json!({"camera": [0.0, 0.0, 0.5]}),
            "camera",
            "[0.0, 0.0, 0.5]",
        ),
        (
            json!({"camera": [[-2.0, 0.0, 0.5], [1.0, 2.0]]}),
            "camera[1]",
            "[1, 2]",
        ),
        (
            json!({"camera": vec![[-2.0, 0.0, 0.5]; 17]}),
            "camera",
            "17 cameras",
        ),
        (
            json!({"camera": [-2.0, 0.0, 0.5], "w_free": -1.0}),
            "w_free",
            "-1",
        ),
        (json!({"repair": "maybe"}), "repair", "\"maybe\""),
    ];
    for (extra, field, value) in cases {
        let mut b = json!({"points": points_json(32)});
        for (k, v) in extra.as_object().unwrap() {
            b[k] = v.clone();
        }
        let p = problem(submit(&c, &s.url("/v1/jobs"), b).await, 422).await;
        let e = &p["errors"][0];
        assert_eq!(
            (e["field"].as_str(), e["value"].as_str()),
            (Some(field), Some(value)),
            "{p}"
        );
        assert!(!e["limit"].as_str().unwrap().is_empty(), "{p}");
    }
    // JSON has no NaN: a raw upload's query string carries one.
    let r = c
        .post(s.url("/v1/jobs?tau=NaN"))
        .header("content-type", "application/octet-stream")
        .body(f32le(&cloud(32)))
        .send()
        .await
        .unwrap();
    let p = problem(r, 422).await;
    assert_eq!(
        (
            p["errors"][0]["field"].as_str(),
            p["errors"][0]["value"].as_str()
        ),
        (Some("tau"), Some("NaN")),
        "{p}"
    );
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_whose_samples_all_diverge_fails_with_the_reason() {
    let s = start(Opts::default()).await;
    let c = client();
    // The untrained test weights blow up under the paper's raw (unclamped) gradient, which a
    // job asks for with guidance_max_step = 0 (the default clamps).
    let r = submit(
        &c,
        &s.url("/v1/jobs"),
        json!({"points": points_json(64), "seed": 3, "samples": 2, "resolution": 8,
               "sampler": "ddim", "steps": 20, "n_g": 500, "w_pc": 1.0e6,
               "guidance_max_step": 0.0}),
    )
    .await;
    assert_eq!(r.status(), 202);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    let j = wait_state(&c, &s.url(&loc), &["SUCCEEDED", "FAILED"]).await;
    assert_eq!(j["state"], "FAILED", "{j:#}");
    assert_eq!(j["error"]["type"], "diverged", "{j:#}");
    let detail = j["error"]["detail"].as_str().unwrap();
    assert!(detail.contains("all 2 samples diverged"), "{detail}");
    assert!(j["artifacts"].as_array().unwrap().is_empty(), "{j:#}");
    s.shutdown().await;
}

/// An oversize body gets its 413 and `Connection: close`, so a client that pools connections
/// never sends its next request down a connection the server is closing (the bug an httpx
/// client hit: 5 of 50 requests after an oversize upload failed).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oversize_body_closes_cleanly_and_pooled_connections_keep_working() {
    use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
    let s = start(Opts {
        max_body_bytes: 1 << 20,
        ..Opts::default()
    })
    .await;
    // Raw HTTP/1.1: the whole oversize body is sent (the server drains it), the answer is a 413
    // problem that says `connection: close`, and the server then closes.
    let mut tcp = tokio::net::TcpStream::connect(s.addrs.http).await.unwrap();
    let body = vec![0u8; 3 << 20];
    let head = format!(
        "POST /v1/jobs HTTP/1.1\r\nhost: x\r\ncontent-type: application/octet-stream\r\ncontent-length: {}\r\n\r\n",
        body.len()
    );
    tcp.write_all(head.as_bytes()).await.unwrap();
    tcp.write_all(&body).await.unwrap();
    let mut answer = Vec::new();
    tokio::time::timeout(Duration::from_secs(30), tcp.read_to_end(&mut answer))
        .await
        .expect("the server closes the connection after the 413")
        .unwrap();
    let answer = String::from_utf8_lossy(&answer).to_ascii_lowercase();
    assert!(answer.starts_with("http/1.1 413"), "{answer}");
    assert!(answer.contains("\r\nconnection: close\r\n"), "{answer}");
    assert!(answer.contains("application/problem+json"), "{answer}");
    // A pooled client (one connection) alternating oversize uploads and small requests.
    let c = reqwest::Client::builder()
        .http1_only()
        .pool_max_idle_per_host(1)
        .timeout(Duration::from_secs(60))
        .build()
        .unwrap();
    for round in 0..5 {
        let r = c
            .post(s.url("/v1/jobs"))
            .header("content-type", "application/octet-stream")
            .body(vec![0u8; 2 << 20])
            .send()
            .await
            .unwrap_or_else(|e| panic!("round {round}: oversize upload: {e}"));
        assert_eq!(r.headers()["connection"], "close");
        problem(r, 413).await;
        for i in 0..10 {
            let r = c
                .get(s.url("/v1/jobs"))
                .send()
                .await
                .unwrap_or_else(|e| panic!("round {round}, request {i} after the 413: {e}"));
            assert_eq!(r.status(), 200);
        }
    }
    s.shutdown().await;
}

/// The places where the OpenAPI document and the server once disagreed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_server_accepts_and_refuses_what_the_document_says() {
    let s = start(Opts {
        tokens: "lab:secret-token-1".into(),
        ..Opts::default()
    })
    .await;
    let c = client();
    let auth = |r: reqwest::RequestBuilder| r.bearer_auth("secret-token-1");
    // The one public operation.
    let r = c.get(s.url("/v1/categories")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    problem(c.get(s.url("/v1/jobs")).send().await.unwrap(), 401).await;
    // An integral float is an integer (JSON Schema's reading), in the body and the query.
    let r = auth(c.post(s.url("/v1/jobs")))
        .json(
            &json!({"points": points_json(20), "seed": 2567.0, "steps": 4.0,
                      "resolution": 8, "w_pc": 0.0, "w_pen": 0.0, "w_mob": 0.0}),
        )
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let job: Value = r.json().await.unwrap();
    assert_eq!(job["request"]["seed"], 2567);
    let id = job["id"].as_str().unwrap().to_string();
    let upload = ply(20);
    let r = auth(c.post(s.url("/v1/jobs?seed=7.0&steps=4&resolution=8.0")))
        .header("content-type", "application/x-ply")
        .body(upload)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    // Type errors are field violations like any other: a fraction, a negative, a value past
    // the type, in the body and in the query.
    let p = problem(
        auth(c.post(s.url("/v1/jobs")))
            .json(&json!({"points": points_json(20), "seed": 2567.5}))
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["errors"][0]["field"], "seed", "{p}");
    assert!(
        p["errors"][0]["value"].as_str().unwrap().contains("2567.5"),
        "{p}"
    );
    for (query, field) in [
        ("steps=-1", "steps"),
        ("steps=1000000000000", "steps"),
        ("seed=18446744073709551616", "seed"),
    ] {
        let upload = ply(20);
        let p = problem(
            auth(c.post(s.url(&format!("/v1/jobs?{query}"))))
                .header("content-type", "application/x-ply")
                .body(upload)
                .send()
                .await
                .unwrap(),
            422,
        )
        .await;
        assert_eq!(p["errors"][0]["field"], field, "{query}: {p}");
        assert!(!p["errors"][0]["limit"].as_str().unwrap().is_empty(), "{p}");
    }
    // Every violation of one request is listed, type errors and range errors together, in
    // the body and in the query; nothing is stored.
    let before = jobs_of(&c, &s, "secret-token-1").await;
    let p = problem(
        auth(c.post(s.url("/v1/jobs")))
            .json(
                &json!({"points": points_json(3), "seed": "soon", "steps": -2,
                          "w_pc": -1.0, "resolution": 1, "wpc": 2,
                          "points_ply_base64": "%%"}),
            )
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;
    let mut fields = error_fields(&p);
    fields.sort_unstable();
    assert_eq!(
        fields,
        [
            "points",
            "points_ply_base64",
            "resolution",
            "seed",
            "steps",
            "w_pc",
            "wpc"
        ],
        "{p:#}"
    );
    for e in p["errors"].as_array().unwrap() {
        assert!(!e["limit"].as_str().unwrap().is_empty(), "{e}");
        assert!(!e["value"].as_str().unwrap().is_empty(), "{e}");
    }
    let p = problem(
        auth(c.post(
            s.url("/v1/jobs?steps=x&seed=-1&samples=0&camera=1,2&camera=a&up=1,2&frame=sideways"),
        ))
        .header("content-type", "application/x-ply")
        .body(ply(20))
        .send()
        .await
        .unwrap(),
        422,
    )
    .await;
    assert_eq!(
        error_fields(&p),
        ["steps", "seed", "camera[1]", "up", "frame", "samples"],
        "{p:#}"
    );
    assert_eq!(jobs_of(&c, &s, "secret-token-1").await, before);
    // Paging: page_size outside 1..=500 is refused with the field listed; any well-formed
    // cursor is a page.
    for bad in ["0", "501"] {
        let p = problem(
            auth(c.get(s.url(&format!("/v1/jobs?page_size={bad}"))))
                .send()
                .await
                .unwrap(),
            422,
        )
        .await;
        assert_eq!(p["errors"][0]["field"], "page_size", "{p}");
        assert_eq!(p["errors"][0]["value"], bad, "{p}");
    }
    let cursor = base64::engine::general_purpose::URL_SAFE_NO_PAD.encode("after:zzz");
    let r = auth(c.get(s.url(&format!("/v1/jobs?page_size=2&page_token={cursor}"))))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let page: Value = r.json().await.unwrap();
    assert!(page["jobs"].as_array().unwrap().is_empty(), "{page}");
    // Last-Event-ID must be a sequence number.
    let p = problem(
        auth(c.get(s.url(&format!("/v1/jobs/{id}/events"))))
            .header("last-event-id", "null")
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["errors"][0]["field"], "Last-Event-ID", "{p}");
    // A resume point past the store's sequences is refused, in the query even when the
    // header is the one used.
    let p = problem(
        auth(c.get(s.url(&format!("/v1/jobs/{id}/events?after=9223372036854775808"))))
            .header("last-event-id", "1")
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["errors"][0]["field"], "after", "{p}");
    // The artefact-name 404 and the unknown-route 404 do not echo the request.
    for path in [
        format!("/v1/jobs/{id}/artifacts/..%2F..%2Fetc%2Fpasswd-probe"),
        "/v1/nothing-here-probe".to_string(),
    ] {
        let p = problem(auth(c.get(s.url(&path))).send().await.unwrap(), 404).await;
        assert!(!p.to_string().contains("probe"), "{path}: {p}");
    }
    s.shutdown().await;
}

/// Cancel is idempotent: a CANCELLED job answers 200 again; a finished one answers 409.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_twice_is_200_and_cancel_after_success_is_409() {
    let s = start(Opts {
        max_running_jobs: 1,
        ..Opts::default()
    })
    .await;
    let c = client();
    // A long job keeps the worker busy, so the second one is still queued when cancelled.
    let long = submit(
        &c,
        &s.url("/v1/jobs"),
        json!({"points": points_json(20), "steps": 1000, "sampler": "ddpm", "resolution": 8,
               "w_pc": 0.0, "w_pen": 0.0, "w_mob": 0.0}),
    )
    .await;
    assert_eq!(long.status(), 202);
    let long = long.headers()["location"].to_str().unwrap().to_string();
    let queued = submit(
        &c,
        &s.url("/v1/jobs"),
        json!({"points": points_json(20), "steps": 4, "resolution": 8}),
    )
    .await;
    let queued = queued.headers()["location"].to_str().unwrap().to_string();
    for _ in 0..2 {
        let r = c
            .post(s.url(&format!("{queued}/cancel")))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(r.json::<Value>().await.unwrap()["state"], "CANCELLED");
    }
    let r = c
        .post(s.url(&format!("{long}/cancel")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    wait_state(&c, &s.url(&long), &["CANCELLED"]).await;
    let done = submit(
        &c,
        &s.url("/v1/jobs"),
        json!({"points": points_json(20), "steps": 2, "resolution": 8,
               "w_pc": 0.0, "w_pen": 0.0, "w_mob": 0.0}),
    )
    .await;
    let done = done.headers()["location"].to_str().unwrap().to_string();
    wait_state(&c, &s.url(&done), &["SUCCEEDED"]).await;
    problem(
        c.post(s.url(&format!("{done}/cancel")))
            .send()
            .await
            .unwrap(),
        409,
    )
    .await;
    s.shutdown().await;
}

/// How many jobs `token`'s tenant has.
async fn jobs_of(c: &reqwest::Client, s: &support::TestServer, token: &str) -> usize {
    let page: Value = c
        .get(s.url("/v1/jobs?page_size=500"))
        .bearer_auth(token)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    page["jobs"].as_array().unwrap().len()
}

/// The fields a problem document lists in `errors`, in order.
fn error_fields(p: &Value) -> Vec<&str> {
    p["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["field"].as_str().unwrap())
        .collect()
}
