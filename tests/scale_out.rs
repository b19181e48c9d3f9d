//! Scale-out on one PostgreSQL database (a throwaway cluster): an API replica and two workers,
//! in one test process with real HTTP clients. Two workers share the queue and no job runs
//! twice; the API replica runs nothing and streams every job's progress; a cancel reaches a
//! job running on a worker; every process survives the database dropping its connections;
//! roles that need a shared store are refused on SQLite.

mod support;

use std::time::{Duration, Instant};

use physnap::service::jobs::Role;
use physnap::service::server::Server;
use physnap::service::store::StoreLocation;
use serde_json::{Value, json};
use support::{Opts, TestServer, cloud, events_of, submit_json};

async fn job(c: &reqwest::Client, api: &TestServer, id: &str) -> Value {
    c.get(api.url(&format!("/v1/jobs/{id}")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap()
}

async fn wait_state(c: &reqwest::Client, api: &TestServer, id: &str, states: &[&str]) -> Value {
    let t0 = Instant::now();
    loop {
        let j = job(c, api, id).await;
        if states.contains(&j["state"].as_str().unwrap()) {
            return j;
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "stuck: {j:#}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn two_workers_share_the_queue_and_the_api_replica_streams_and_cancels() {
    let (_pg, url) = tokio::task::block_in_place(|| {
        let pg = support::pg::Pg::start();
        let url = pg.fresh_db("scale");
        (pg, url)
    });
    let store: StoreLocation = url.parse().unwrap();
    let opts = |role| Opts {
        store: store.clone(),
        role,
        lease: Duration::from_secs(3),
        queue_capacity: 32,
        ..Opts::default()
    };
    let api = support::start(opts(Role::Api)).await;
    let workers = [
        support::start(opts(Role::Worker)).await,
        support::start(opts(Role::Worker)).await,
    ];
    for w in &workers {
        assert!(!w.addrs.api, "a worker serves no API");
    }
    let c = reqwest::Client::new();
    let body = |seed: u64| {
        json!({"points": cloud(30), "seed": seed, "samples": 2, "resolution": 8,
               "sampler": "ddpm", "steps": 400, "category": "Door",
               "w_pc": 0.0, "w_pen": 0.0, "w_mob": 0.0})
    };
    let mut ids = Vec::new();
    for seed in 0..6 {
        ids.push(submit_json(&c, &api, &body(seed)).await);
    }
    // The API replica streams a job running in a worker: progress, then done.
    let events = events_of(&c, &api, &ids[0]).await;
    assert!(
        events.iter().any(|e| e.event == "progress"),
        "no progress reached the API replica"
    );
    assert_eq!(events.last().unwrap().event, "done");
    for id in &ids {
        let j = wait_state(&c, &api, id, &["SUCCEEDED", "FAILED", "CANCELLED"]).await;
        assert_eq!(j["state"], "SUCCEEDED", "{j:#}");
        assert_eq!(j["attempt"], 1, "run more than once: {j:#}");
        let events = events_of(&c, &api, id).await;
        let states: Vec<&str> = events
            .iter()
            .filter(|e| e.event == "state")
            .map(|e| match e.json()["state"].as_str().unwrap() {
                "QUEUED" => "QUEUED",
                "RUNNING" => "RUNNING",
                other => {
                    assert_eq!(other, "SUCCEEDED");
                    "SUCCEEDED"
                }
            })
            .collect();
        assert_eq!(states, ["QUEUED", "RUNNING", "SUCCEEDED"]);
        // Artefacts come from the database through the API replica.
        let glb = c
            .get(api.url(&format!("/v1/jobs/{id}/artifacts/model.glb")))
            .send()
            .await
            .unwrap();
        assert_eq!(glb.status(), 200);
        assert!(glb.bytes().await.unwrap().starts_with(b"glTF"));
    }
    let ran: Vec<u64> = workers
        .iter()
        .map(|w| {
            w.svc
                .metrics
                .succeeded
                .load(std::sync::atomic::Ordering::Relaxed)
        })
        .collect();
    assert_eq!(ran.iter().sum::<u64>(), 6, "{ran:?}");
    assert!(
        ran.iter().all(|&n| n > 0),
        "one worker ran every job: {ran:?}"
    );
    let api_ran = api
        .svc
        .metrics
        .succeeded
        .load(std::sync::atomic::Ordering::Relaxed);
    assert_eq!(api_ran, 0, "the API replica ran a job");

    // A cancel through the API replica stops a job running in a worker.
    let mut long = body(99);
    long["steps"] = json!(1000);
    long["samples"] = json!(8);
    let id = submit_json(&c, &api, &long).await;
    wait_state(&c, &api, &id, &["RUNNING"]).await;
    let r = c
        .post(api.url(&format!("/v1/jobs/{id}/cancel")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let t0 = Instant::now();
    let j = wait_state(&c, &api, &id, &["CANCELLED", "SUCCEEDED", "FAILED"]).await;
    assert_eq!(j["state"], "CANCELLED", "{j:#}");
    assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());

    // The database drops every physnap connection (a restart, a failover): the next calls
    // reconnect, the listeners re-subscribe, and a new job runs and streams to its end.
    let killed: i64 = tokio::task::block_in_place(|| {
        let mut c = postgres::Client::connect(&url, postgres::NoTls).unwrap();
        c.query(
            "SELECT pg_terminate_backend(pid) FROM pg_stat_activity \
             WHERE application_name LIKE 'physnap%'",
            &[],
        )
        .unwrap()
        .len() as i64
    });
    assert!(killed >= 6, "{killed} connections terminated");
    let id = submit_json(&c, &api, &body(7)).await;
    let events = events_of(&c, &api, &id).await;
    assert_eq!(events.last().unwrap().event, "done");
    let j = job(&c, &api, &id).await;
    assert_eq!(j["state"], "SUCCEEDED", "{j:#}");

    api.shutdown().await;
    for w in workers {
        w.shutdown().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn api_and_worker_roles_need_a_shared_store() {
    for role in [Role::Api, Role::Worker] {
        let root = tempfile::tempdir().unwrap();
        support::tiny_weights(&root.path().join("weights"));
        let cfg = support::serve_config(
            root.path(),
            &Opts {
                role,
                ..Opts::default()
            },
        );
        let e = Server::bind(cfg).await.err().expect("refused").to_string();
        assert!(e.contains("invalid role"), "{e}");
        assert!(e.contains("postgres://"), "{e}");
    }
}
