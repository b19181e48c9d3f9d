//! Scale-out benchmark (BENCHMARKS.md): a batch of short jobs through one API replica with
//! 1, 2 and 3 workers on one PostgreSQL database (a throwaway cluster, as the tests start), each
//! worker one thread; then the queue's own overheads: lease-to-start latency (an idle worker,
//! from the job's commit to its start) and the notification-to-SSE delay (from the worker's
//! commit of `done` to its arrival on the API replica's SSE stream). In-process servers, real
//! HTTP, tiny untrained weights (unguided 1000-step DDPM jobs: CPU-bound, like real ones).
//! Run: `cargo run --release --example bench_scale -- [jobs] [max_workers] [probes]`.

#[path = "../tests/support/mod.rs"]
mod support;

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use physnap::service::jobs::Role;
use physnap::service::store::StoreLocation;
use serde_json::{Value, json};
use support::{Opts, SseReader, TestServer, cloud, start, submit_json};

fn now_ms() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
        * 1000.0
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// Follow a job's SSE stream to `done`; the `done` event's job and when it arrived (Unix ms).
async fn follow(c: &reqwest::Client, api: &TestServer, id: &str) -> (Value, f64) {
    let mut sse = SseReader::new(
        c.get(api.url(&format!("/v1/jobs/{id}/events")))
            .send()
            .await
            .unwrap(),
    );
    while let Some(e) = sse.next().await {
        if e.event == "done" {
            return (e.json(), now_ms());
        }
    }
    panic!("the stream of {id} ended without done");
}

#[tokio::main(flavor = "multi_thread", worker_threads = 4)]
async fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("numbers"))
        .collect();
    let (jobs, max_workers, probes) = (
        *args.first().unwrap_or(&8),
        *args.get(1).unwrap_or(&3),
        *args.get(2).unwrap_or(&10),
    );
    let pg = tokio::task::block_in_place(support::pg::Pg::start);
    let c = reqwest::Client::new();
    let body = |seed: usize| {
        json!({"points": cloud(64), "seed": seed, "samples": 2, "resolution": 8,
               "sampler": "ddpm", "steps": 1000, "category": "Door",
               "w_pc": 0.0, "w_pen": 0.0, "w_mob": 0.0})
    };
    for n in 1..=max_workers {
        let db = tokio::task::block_in_place(|| pg.fresh_db(&format!("scale{n}")));
        let store: StoreLocation = db.parse().unwrap();
        let opts = |role| Opts {
            store: store.clone(),
            role,
            queue_capacity: 64,
            ..Opts::default()
        };
        let api = start(opts(Role::Api)).await;
        let mut workers = Vec::new();
        for _ in 0..n {
            workers.push(start(opts(Role::Worker)).await);
        }
        let t0 = Instant::now();
        let mut ids = Vec::new();
        for i in 0..jobs {
            ids.push(submit_json(&c, &api, &body(i)).await);
        }
        let mut runs = Vec::new();
        for id in &ids {
            let (done, _) = follow(&c, &api, id).await;
            assert_eq!(done["state"], "SUCCEEDED", "{done:#}");
            runs.push(
                (done["end_time_ms"].as_f64().unwrap() - done["start_time_ms"].as_f64().unwrap())
                    / 1000.0,
            );
        }
        let wall = t0.elapsed().as_secs_f64();
        println!(
            "{n} worker(s): {jobs} jobs in {wall:.2} s ({:.2} jobs/s); a job runs {:.2} s (median)",
            jobs as f64 / wall,
            median(&mut runs)
        );
        if n == 1 {
            // The queue's overheads, on an idle worker, one job at a time.
            let (mut lease, mut notify) = (Vec::new(), Vec::new());
            for i in 0..probes {
                tokio::time::sleep(Duration::from_millis(300)).await;
                let id = submit_json(&c, &api, &body(1000 + i)).await;
                let (done, arrived) = follow(&c, &api, &id).await;
                lease.push(
                    done["start_time_ms"].as_f64().unwrap()
                        - done["create_time_ms"].as_f64().unwrap(),
                );
                notify.push(arrived - done["end_time_ms"].as_f64().unwrap());
            }
            println!(
                "queue overhead ({probes} jobs, idle worker): commit to start {:.1} ms median, \
                 max {:.1} ms; done committed to SSE on the API replica {:.1} ms median, max {:.1} ms",
                median(&mut lease),
                lease.iter().cloned().fold(0.0, f64::max),
                median(&mut notify),
                notify.iter().cloned().fold(0.0, f64::max)
            );
        }
        api.shutdown().await;
        for w in workers {
            w.shutdown().await;
        }
    }
}
