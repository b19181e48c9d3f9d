//! Service benchmark (BENCHMARKS.md): admission latency of `POST /v1/jobs` while the worker
//! pool is busy, SSE fan-out to many watchers, and memory per queued job. Bounded and on
//! loopback only; uses tiny untrained weights (the admission path does not depend on model
//! size). Run: `cargo run --release --example bench_service -- [requests] [concurrency] [watchers]`.

#[path = "../tests/support/mod.rs"]
mod support;

use std::time::{Duration, Instant};

use serde_json::{Value, json};
use support::{Opts, SseReader, cloud, start};

fn rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

fn pct(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * p).round() as usize]
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("numbers"))
        .collect();
    let (requests, concurrency, watchers) = (
        *args.first().unwrap_or(&2000),
        *args.get(1).unwrap_or(&16),
        *args.get(2).unwrap_or(&100),
    );
    let s = start(Opts {
        queue_capacity: requests + 10,
        ..Default::default()
    })
    .await;
    let c = reqwest::Client::new();
    let url = s.url("/v1/jobs");
    // Keep the pool busy: one long job runs throughout.
    let busy: Value = c
        .post(&url)
        .json(&json!({"points": cloud(64), "samples": 16, "resolution": 8}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;

    // SSE fan-out: `watchers` streams on the busy job; time until each sees a progress event.
    let t0 = Instant::now();
    let mut handles = Vec::new();
    for _ in 0..watchers {
        let c = c.clone();
        let u = s.url(&format!("/v1/jobs/{}/events", busy["id"].as_str().unwrap()));
        handles.push(tokio::spawn(async move {
            let mut r = SseReader::new(c.get(u).send().await.unwrap());
            let mut n = 0;
            while let Some(e) = r.next().await {
                if e.event == "progress" {
                    n += 1;
                    if n == 5 {
                        break;
                    }
                }
            }
            Instant::now()
        }));
    }
    let mut fan = Vec::new();
    for h in handles {
        fan.push((h.await.unwrap() - t0).as_secs_f64());
    }
    println!(
        "SSE fan-out: {watchers} watchers each got 5 progress events; slowest after {:.3} s",
        fan.iter().cloned().fold(0.0, f64::max)
    );

    // Admission latency under `concurrency` concurrent clients, pool busy.
    let body = serde_json::to_vec(&json!({"points": cloud(1000), "resolution": 8})).unwrap();
    let rss0 = rss_kib();
    let per = requests / concurrency;
    let t0 = Instant::now();
    let mut handles = Vec::new();
    for _ in 0..concurrency {
        let (c, url, body) = (c.clone(), url.clone(), body.clone());
        handles.push(tokio::spawn(async move {
            let mut lat = Vec::with_capacity(per);
            for _ in 0..per {
                let t = Instant::now();
                let r = c
                    .post(&url)
                    .header("content-type", "application/json")
                    .body(body.clone())
                    .send()
                    .await
                    .unwrap();
                assert_eq!(r.status(), 202);
                let _ = r.bytes().await;
                lat.push(t.elapsed().as_secs_f64() * 1000.0);
            }
            lat
        }));
    }
    let mut lat = Vec::new();
    for h in handles {
        lat.extend(h.await.unwrap());
    }
    let wall = t0.elapsed().as_secs_f64();
    let rss1 = rss_kib();
    let n = lat.len();
    println!(
        "admission: {n} jobs (1000 points each) at concurrency {concurrency} in {wall:.2} s ({:.0}/s); \
         latency p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        n as f64 / wall,
        pct(&mut lat, 0.5),
        pct(&mut lat, 0.99),
        pct(&mut lat, 1.0)
    );
    println!(
        "memory: RSS {} KiB -> {} KiB with {} queued jobs: {:.1} KiB per queued job (in-process: \
         queue entry + live watch; the cloud itself lives in SQLite)",
        rss0,
        rss1,
        s.svc.queued().await.unwrap(),
        (rss1 as f64 - rss0 as f64) / n as f64
    );
    let db = support::data_dir(&s).join("jobs.sqlite3");
    println!(
        "store: {} bytes on disk after {} jobs",
        std::fs::metadata(&db).map(|m| m.len()).unwrap_or(0),
        n + 1
    );
    std::process::exit(0);
}
