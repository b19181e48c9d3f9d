//! The job store's contract, run on both implementations: SQLite (the embedded default) and
//! PostgreSQL (a throwaway cluster, `support::pg`). Whatever the service relies on — atomic
//! job + event writes, ordered replay, idempotency keys, per-tenant paging, recovery of
//! unfinished jobs, artefact bytes, deletion, durability across a reopen — is checked here
//! once and must hold on both.

mod support;

use physnap::service::spec::{JobInput, Limits, ModelCaps, PointsInput, validate};
use physnap::service::store::postgres::{MIGRATIONS, PgStore};
use physnap::service::store::{
    self, JobFailure, JobRecord, JobState, JobStore, Lease, StoreError, StoreLocation, StoredEvent,
};
use support::pg::Pg;

fn record(id: &str, tenant: &str, seed: u64) -> JobRecord {
    let caps = ModelCaps {
        categories: vec!["Door".into()],
        conditional: true,
        schedule_steps: 1000,
        codebook: false,
        codebook_categories: Vec::new(),
    };
    let input = JobInput {
        points: Some(PointsInput::Triples(
            (0..20).map(|i| [i as f64 * 0.01, 0.5, -0.25]).collect(),
        )),
        category: Some("Door".into()),
        seed: Some(seed),
        ..JobInput::default()
    };
    let spec = validate(&input, &caps, &Limits::default(), 0).unwrap();
    JobRecord {
        id: id.into(),
        tenant: tenant.into(),
        state: JobState::Queued,
        spec,
        created_ms: 1_700_000_000_000,
        started_ms: None,
        ended_ms: None,
        deadline_ms: 1_700_000_600_000,
        attempt: 0,
        sequence: 1,
        failure: None,
        artifacts: Vec::new(),
    }
}

fn ev(sequence: u64, kind: &str) -> StoredEvent {
    StoredEvent {
        sequence,
        kind: kind.into(),
        data: format!("{{\"n\":{sequence}}}"),
    }
}

/// The whole contract, on a fresh store; `reopen` gives a new handle on the same data.
fn contract(mut s: Box<dyn JobStore>, reopen: &dyn Fn() -> Box<dyn JobStore>) {
    // Insert: the row, its first event and its idempotency key, read back exactly.
    let a = record("0001-a", "t1", 7);
    s.insert(&a, &[ev(1, "state")], Some(("key-1", "hash-1")))
        .unwrap();
    assert_eq!(s.get("0001-a").unwrap().as_ref(), Some(&a));
    assert_eq!(s.get("nope").unwrap(), None);
    assert_eq!(
        s.idempotency("t1", "key-1").unwrap(),
        Some(("hash-1".into(), "0001-a".into()))
    );
    assert_eq!(s.idempotency("t2", "key-1").unwrap(), None);

    // A second job reusing the key is refused as a whole: no row, no event.
    let dup = record("0002-dup", "t1", 8);
    assert!(
        s.insert(&dup, &[ev(1, "state")], Some(("key-1", "other")))
            .is_err()
    );
    assert_eq!(s.get("0002-dup").unwrap(), None);
    assert!(s.events_after("0002-dup", 0).unwrap().is_empty());

    // Update: state, attempt, failure and artefact records change; events append in order.
    let mut running = a.clone();
    running.state = JobState::Running;
    running.attempt = 1;
    running.started_ms = Some(1_700_000_001_000);
    running.sequence = 2;
    s.update(&running, &[ev(2, "state")]).unwrap();
    assert_eq!(s.get("0001-a").unwrap().unwrap(), running);
    let seqs = |s: &mut Box<dyn JobStore>, after| -> Vec<u64> {
        s.events_after("0001-a", after)
            .unwrap()
            .iter()
            .map(|e| e.sequence)
            .collect()
    };
    assert_eq!(seqs(&mut s, 0), vec![1, 2]);
    assert_eq!(seqs(&mut s, 1), vec![2]);
    assert!(seqs(&mut s, u64::MAX).is_empty());
    assert_eq!(s.events_after("0001-a", 1).unwrap()[0], ev(2, "state"));

    // An update whose event collides with a stored sequence changes nothing.
    let mut bad = running.clone();
    bad.state = JobState::Failed;
    assert!(s.update(&bad, &[ev(2, "state")]).is_err());
    assert_eq!(s.get("0001-a").unwrap().unwrap(), running);

    // Artefacts: bytes back exactly, records with size and sha256, a re-put replaces.
    let files = vec![
        ("model.glb".to_string(), vec![1u8, 2, 3, 0, 255]),
        ("object.json".to_string(), b"{}".to_vec()),
    ];
    let arts = s.put_artifacts("0001-a", &files).unwrap();
    assert_eq!(arts[0].name, "model.glb");
    assert_eq!(arts[0].size_bytes, 5);
    assert_eq!(arts[1].sha256.len(), 64);
    assert_eq!(
        s.artifact("0001-a", "model.glb").unwrap(),
        Some(vec![1, 2, 3, 0, 255])
    );
    assert_eq!(s.artifact("0001-a", "robot.zip").unwrap(), None);
    s.put_artifacts("0001-a", &[("model.glb".into(), vec![9])])
        .unwrap();
    assert_eq!(s.artifact("0001-a", "model.glb").unwrap(), Some(vec![9]));

    let mut done = running.clone();
    done.state = JobState::Failed;
    done.ended_ms = Some(1_700_000_002_000);
    done.failure = Some(JobFailure {
        error_type: "engine".into(),
        detail: "a detail with 'quotes' and ünïcode".into(),
    });
    done.artifacts = arts;
    done.sequence = 4;
    s.update(&done, &[ev(3, "state"), ev(4, "done")]).unwrap();
    assert_eq!(s.get("0001-a").unwrap().unwrap(), done);

    // Unfinished jobs, oldest first; per-tenant pages by id; counts per state.
    for (id, tenant) in [("0003-b", "t1"), ("0004-c", "t2"), ("0005-d", "t1")] {
        s.insert(&record(id, tenant, 1), &[ev(1, "state")], None)
            .unwrap();
    }
    let ids = |v: Vec<JobRecord>| v.into_iter().map(|r| r.id).collect::<Vec<_>>();
    assert_eq!(ids(s.unfinished().unwrap()), ["0003-b", "0004-c", "0005-d"]);
    assert_eq!(
        ids(s.list("t1", None, 10).unwrap()),
        ["0001-a", "0003-b", "0005-d"]
    );
    assert_eq!(ids(s.list("t1", None, 2).unwrap()), ["0001-a", "0003-b"]);
    assert_eq!(ids(s.list("t1", Some("0003-b"), 2).unwrap()), ["0005-d"]);
    assert_eq!(ids(s.list("t2", None, 10).unwrap()), ["0004-c"]);
    assert!(s.list("t3", None, 10).unwrap().is_empty());
    let mut counts = s.count_by_state().unwrap();
    counts.sort();
    assert_eq!(counts, [("FAILED".into(), 1), ("QUEUED".into(), 3)]);

    // Durable: a new handle sees everything.
    drop(s);
    let mut s = reopen();
    assert_eq!(s.get("0001-a").unwrap().unwrap(), done);
    assert_eq!(s.artifact("0001-a", "model.glb").unwrap(), Some(vec![9]));
    assert_eq!(s.unfinished().unwrap().len(), 3);

    // Delete: the job, its events, its keys and its artefacts.
    s.delete("0001-a").unwrap();
    assert_eq!(s.get("0001-a").unwrap(), None);
    assert!(s.events_after("0001-a", 0).unwrap().is_empty());
    assert_eq!(s.idempotency("t1", "key-1").unwrap(), None);
    assert_eq!(s.artifact("0001-a", "model.glb").unwrap(), None);
    // ... and the key is free again.
    s.insert(
        &record("0006-e", "t1", 2),
        &[ev(1, "state")],
        Some(("key-1", "h")),
    )
    .unwrap();
}

/// The shared queue: leases, heartbeats, fencing by attempt, cancels across processes.
fn lease_contract(open: &dyn Fn() -> Box<dyn JobStore>) {
    let mut s = open();
    for id in ["q1", "q2"] {
        s.insert(&record(id, "t", 1), &[ev(1, "state")], None)
            .unwrap();
    }
    // The oldest job first: RUNNING at attempt 1, started now, no cancel.
    let Lease {
        job: mut q1,
        cancel_requested,
    } = s.lease_next("w1", 1_000, 500).unwrap().unwrap();
    assert_eq!(
        (q1.id.as_str(), q1.state, q1.attempt, q1.started_ms),
        ("q1", JobState::Running, 1, Some(1_000))
    );
    assert!(!cancel_requested);
    assert_eq!(s.get("q1").unwrap().unwrap(), q1);
    // Its RUNNING event, fenced on the lease.
    q1.sequence = 2;
    assert!(
        s.update_if(&q1, &[ev(2, "state")], JobState::Running, 1)
            .unwrap()
    );
    // Another worker gets the next job; then nothing while both leases hold.
    let q2 = s.lease_next("w2", 1_100, 500).unwrap().unwrap().job;
    assert_eq!(q2.id, "q2");
    assert_eq!(s.lease_next("w3", 1_200, 500).unwrap(), None);
    // Heartbeats extend a lease and carry cancel requests.
    assert_eq!(s.heartbeat("q1", 1, 1_300, 500).unwrap(), Some(false));
    s.request_cancel("q2").unwrap();
    assert_eq!(s.heartbeat("q2", 1, 1_300, 500).unwrap(), Some(true));
    assert_eq!(s.heartbeat("q2", 7, 1_300, 500).unwrap(), None);
    // q1's worker stops heartbeating: after expiry (1,800) another worker takes it over.
    assert_eq!(s.lease_next("w3", 1_700, 500).unwrap(), None);
    let taken = s.lease_next("w3", 1_900, 500).unwrap().unwrap().job;
    assert_eq!((taken.id.as_str(), taken.attempt), ("q1", 2));
    assert_eq!(taken.sequence, 2, "the lease keeps the event log");
    // The old attempt is fenced out: its heartbeat says lost, its writes change nothing.
    assert_eq!(s.heartbeat("q1", 1, 1_950, 500).unwrap(), None);
    let mut late = q1.clone();
    late.state = JobState::Succeeded;
    late.sequence = 3;
    assert!(
        !s.update_if(&late, &[ev(3, "done")], JobState::Running, 1)
            .unwrap()
    );
    assert_eq!(s.get("q1").unwrap().unwrap(), taken);
    assert_eq!(s.events_after("q1", 0).unwrap().len(), 2);
    // The new attempt finishes, and a finished job is never leased again.
    let mut done = taken.clone();
    done.state = JobState::Succeeded;
    done.sequence = 3;
    assert!(
        s.update_if(&done, &[ev(3, "done")], JobState::Running, 2)
            .unwrap()
    );
    assert_eq!(s.heartbeat("q1", 2, 2_000, 500).unwrap(), None);
    let q2 = s.lease_next("w4", 99_000, 10_000_000).unwrap().unwrap().job;
    assert_eq!((q2.id.as_str(), q2.attempt), ("q2", 2));
    assert_eq!(s.lease_next("w4", 99_000, 500).unwrap(), None);
    // A cancel of a QUEUED job, fenced on QUEUED, loses to a worker that leased it first.
    s.insert(&record("q3", "t", 1), &[ev(1, "state")], None)
        .unwrap();
    let queued = s.get("q3").unwrap().unwrap();
    assert_eq!(
        s.lease_next("w1", 100_000, 10_000_000)
            .unwrap()
            .unwrap()
            .job
            .id,
        "q3"
    );
    let mut cancelled = queued.clone();
    cancelled.state = JobState::Cancelled;
    cancelled.sequence = 2;
    assert!(
        !s.update_if(&cancelled, &[ev(2, "state")], JobState::Queued, 0)
            .unwrap()
    );
    assert_eq!(s.get("q3").unwrap().unwrap().state, JobState::Running);

    // Four workers, each with its own connection, drain 24 jobs: each job leased once.
    for i in 0..24 {
        s.insert(
            &record(&format!("r{i:02}"), "t", 1),
            &[ev(1, "state")],
            None,
        )
        .unwrap();
    }
    let leased = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for w in 0..4 {
            let mut store = open();
            let leased = &leased;
            scope.spawn(move || {
                while let Some(l) = store.lease_next(&format!("w{w}"), 200_000, 60_000).unwrap() {
                    leased.lock().unwrap().push(l.job.id);
                }
            });
        }
    });
    let mut leased = leased.into_inner().unwrap();
    leased.sort();
    let expected: Vec<String> = (0..24).map(|i| format!("r{i:02}")).collect();
    assert_eq!(leased, expected);
}

#[test]
fn the_sqlite_store_keeps_the_contract() {
    let dir = tempfile::tempdir().unwrap();
    let open = || store::open(&StoreLocation::Sqlite, dir.path()).unwrap();
    contract(open(), &open);
    // Artefacts are files beside the database, removed with their job.
    assert!(dir.path().join("jobs.sqlite3").exists());
    assert!(!dir.path().join("artifacts").join("0001-a").exists());
    let leases = tempfile::tempdir().unwrap();
    lease_contract(&|| store::open(&StoreLocation::Sqlite, leases.path()).unwrap());
}

#[test]
fn the_postgres_store_keeps_the_contract_and_migrates_once() {
    let pg = Pg::start();
    let url = pg.fresh_db("contract");
    let loc: StoreLocation = url.parse().unwrap();
    let open = || store::open(&loc, pg.dir()).unwrap();
    // Replicas starting together migrate once (the advisory lock), then agree on the version.
    let handles: Vec<_> = (0..4)
        .map(|_| {
            let url = url.clone();
            std::thread::spawn(move || PgStore::connect(&url).map(|mut s| s.schema_version()))
        })
        .collect();
    for h in handles {
        assert_eq!(h.join().unwrap().unwrap().unwrap(), MIGRATIONS.len() as i32);
    }
    contract(open(), &open);
    // Nothing lands on the local disk.
    assert!(!pg.dir().join("artifacts").exists());
    let leases: StoreLocation = pg.fresh_db("leases").parse().unwrap();
    lease_contract(&|| store::open(&leases, pg.dir()).unwrap());

    // A database migrated by a newer physnap is refused with both versions named.
    let mut c = postgres::Client::connect(&url, postgres::NoTls).unwrap();
    c.execute(
        "INSERT INTO physnap_schema (version, applied_ms) VALUES ($1, 0)",
        &[&(MIGRATIONS.len() as i32 + 5)],
    )
    .unwrap();
    match PgStore::connect(&url) {
        Err(e @ StoreError::SchemaTooNew { .. }) => {
            let m = e.to_string();
            assert!(
                m.contains(&format!("version {}", MIGRATIONS.len() + 5)),
                "{m}"
            );
        }
        Err(e) => panic!("expected SchemaTooNew, got {e}"),
        Ok(_) => panic!("a newer schema was accepted"),
    }
}

#[test]
fn store_locations_parse_and_bad_ones_name_the_value_without_the_password() {
    assert_eq!(
        "sqlite".parse::<StoreLocation>().unwrap(),
        StoreLocation::Sqlite
    );
    let pg: StoreLocation = "postgresql://u:secret@db:5432/physnap".parse().unwrap();
    assert_eq!(pg.to_string(), "postgresql://u:***@db:5432/physnap");
    for bad in [
        "mysql://u:secret@db/x",
        "postgres://",
        "",
        "data/jobs.sqlite3",
    ] {
        let e = bad.parse::<StoreLocation>().unwrap_err().to_string();
        assert!(e.contains("invalid store"), "{e}");
        assert!(e.contains("postgres://"), "{e}");
        assert!(!e.contains("secret"), "{e}");
    }
    // An unreachable server fails with PostgreSQL's reason, not a hang.
    let t0 = std::time::Instant::now();
    let e = PgStore::connect("postgres://u@127.0.0.1:1/x?connect_timeout=5")
        .err()
        .expect("nothing listens on port 1");
    assert!(matches!(e, StoreError::Postgres(_)), "{e}");
    assert!(t0.elapsed().as_secs() < 6);
}
