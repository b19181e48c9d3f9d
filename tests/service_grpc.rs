//! The gRPC API (tonic generated client) against a real server on ephemeral loopback ports:
//! submit → WatchJob → GetArtifact, resume by sequence, INVALID_ARGUMENT, health, reflection.

mod support;

use physnap::service::grpc::pb::{self, job_service_client::JobServiceClient};
use sha2::{Digest, Sha256};
use support::{Opts, cloud, start};
use tokio_stream::StreamExt as _;

fn spec(points: Vec<f32>) -> pb::JobSpec {
    pb::JobSpec {
        points: Some(pb::job_spec::Points::Xyz(pb::FlatPoints { values: points })),
        category: "Laptop".into(),
        seed: Some(9),
        preview_every: Some(10),
        // Guided (paper weights), few DDIM steps; the clamp keeps the untrained test
        // weights from diverging.
        sampler: "ddim".into(),
        steps: Some(40),
        // The last 10 of the 40 steps (t < 250).
        n_g: Some(250),
        tau: Some(1000.0),
        guidance_max_step: Some(0.05),
        ..Default::default()
    }
}

/// Submits `spec` and returns the error the server must answer with.
async fn refused(
    cl: &mut JobServiceClient<tonic::transport::Channel>,
    spec: pb::JobSpec,
) -> tonic::Status {
    cl.submit_job(pb::SubmitJobRequest {
        spec: Some(spec),
        request_id: String::new(),
    })
    .await
    .unwrap_err()
}

async fn watch(
    cl: &mut JobServiceClient<tonic::transport::Channel>,
    id: &str,
    after: u64,
) -> Vec<pb::JobEvent> {
    let mut stream = cl
        .watch_job(pb::WatchJobRequest {
            id: id.into(),
            after_sequence: after,
        })
        .await
        .unwrap()
        .into_inner();
    let mut out = Vec::new();
    while let Some(e) = stream.next().await {
        out.push(e.unwrap());
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn submit_watch_get_artifact() {
    let s = start(Opts::default()).await;
    let mut cl = JobServiceClient::connect(s.grpc_url()).await.unwrap();
    let flat: Vec<f32> = cloud(48).into_iter().flatten().collect();
    let job = cl
        .submit_job(pb::SubmitJobRequest {
            spec: Some(spec(flat.clone())),
            request_id: "req-1".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(job.state, pb::State::Queued as i32);
    // The same request id and spec is the same job.
    let again = cl
        .submit_job(pb::SubmitJobRequest {
            spec: Some(spec(flat.clone())),
            request_id: "req-1".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(again.id, job.id);

    let evs = watch(&mut cl, &job.id, 0).await;
    let last = evs.last().unwrap();
    assert_eq!(last.kind, "done");
    assert_eq!(last.state, pb::State::Succeeded as i32);
    assert!(evs.iter().any(|e| e.kind == "progress"));
    let persisted: Vec<u64> = evs
        .iter()
        .filter(|e| e.kind != "progress")
        .map(|e| e.sequence)
        .collect();
    assert_eq!(persisted, (1..=persisted.len() as u64).collect::<Vec<_>>());
    // Resume after sequence 2: exactly the rest.
    let rest: Vec<u64> = watch(&mut cl, &job.id, 2)
        .await
        .iter()
        .filter(|e| e.kind != "progress")
        .map(|e| e.sequence)
        .collect();
    assert_eq!(rest, persisted[2..].to_vec());

    let done = cl
        .get_job(pb::GetJobRequest { id: job.id.clone() })
        .await
        .unwrap()
        .into_inner();
    let view: serde_json::Value = serde_json::from_str(&done.json).unwrap();
    let want = view["artifacts"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"] == "model.glb")
        .unwrap()["sha256"]
        .as_str()
        .unwrap()
        .to_string();
    let mut chunks = cl
        .get_artifact(pb::GetArtifactRequest {
            id: job.id.clone(),
            name: "model.glb".into(),
        })
        .await
        .unwrap()
        .into_inner();
    let (mut bytes, mut sha) = (Vec::new(), String::new());
    while let Some(c) = chunks.next().await {
        let c = c.unwrap();
        assert_eq!(c.offset as usize, bytes.len());
        bytes.extend_from_slice(&c.data);
        if !c.sha256.is_empty() {
            sha = c.sha256;
        }
    }
    assert_eq!(&bytes[..4], b"glTF");
    assert_eq!(format!("{:x}", Sha256::digest(&bytes)), want);
    assert_eq!(sha, want);

    let list = cl
        .list_jobs(pb::ListJobsRequest::default())
        .await
        .unwrap()
        .into_inner();
    assert_eq!(list.jobs.len(), 1);

    // Bad input: INVALID_ARGUMENT naming field, limit and value; nothing stored.
    let mut bad = flat.clone();
    bad[7] = f32::NAN;
    let e = refused(&mut cl, spec(bad)).await;
    assert_eq!(e.code(), tonic::Code::InvalidArgument);
    assert!(e.message().contains("points[2][1]"), "{}", e.message());
    assert_eq!(e.metadata().get("physnap-field").unwrap(), "points[2][1]");
    assert_eq!(e.metadata().get("physnap-limit").unwrap(), "finite");
    let mut neg = spec(flat.clone());
    neg.w_mob = Some(-1.0);
    let e = refused(&mut cl, neg).await;
    assert_eq!(e.code(), tonic::Code::InvalidArgument);
    assert!(
        e.message().contains("w_mob") && e.message().contains("-1"),
        "{}",
        e.message()
    );
    // joint_motion reaches the same validation as REST.
    let mut motion = spec(flat.clone());
    motion.joint_motion = "revolute".into();
    let e = refused(&mut cl, motion).await;
    assert_eq!(e.code(), tonic::Code::InvalidArgument);
    assert_eq!(e.metadata().get("physnap-field").unwrap(), "joint_motion");
    // So does category_guidance_below.
    let mut below = spec(flat.clone());
    below.category_guidance_below = Some(1001);
    let e = refused(&mut cl, below).await;
    assert_eq!(e.code(), tonic::Code::InvalidArgument);
    assert_eq!(
        e.metadata().get("physnap-field").unwrap(),
        "category_guidance_below"
    );
    assert!(e.message().contains("1001"), "{}", e.message());
    let mut cat = spec(flat.clone());
    cat.category = "Spaceship".into();
    let e = refused(&mut cl, cat).await;
    assert_eq!(e.code(), tonic::Code::InvalidArgument);
    let e = refused(
        &mut cl,
        pb::JobSpec {
            points: Some(pb::job_spec::Points::Ply(b"ply\ngarbage".to_vec())),
            ..Default::default()
        },
    )
    .await;
    assert_eq!(e.code(), tonic::Code::InvalidArgument);
    let list = cl
        .list_jobs(pb::ListJobsRequest::default())
        .await
        .unwrap()
        .into_inner();
    assert_eq!(list.jobs.len(), 1, "a rejected job was stored");
    let e = cl
        .get_job(pb::GetJobRequest { id: "nope".into() })
        .await
        .unwrap_err();
    assert_eq!(e.code(), tonic::Code::NotFound);

    // Standard health service.
    let channel = tonic::transport::Endpoint::from_shared(s.grpc_url())
        .unwrap()
        .connect()
        .await
        .unwrap();
    let mut health = tonic_health::pb::health_client::HealthClient::new(channel);
    let h = health
        .check(tonic_health::pb::HealthCheckRequest {
            service: "physnap.v1.JobService".into(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(
        h.status,
        tonic_health::pb::health_check_response::ServingStatus::Serving as i32
    );

    // Reflection, v1 and v1alpha (grpcurl-style discovery), lists the job service and health.
    macro_rules! list_services {
        ($refl:path) => {{
            use $refl as refl;
            let mut rc =
                refl::server_reflection_client::ServerReflectionClient::new(channel_for(&s).await);
            let req = refl::ServerReflectionRequest {
                host: String::new(),
                message_request: Some(
                    refl::server_reflection_request::MessageRequest::ListServices(String::new()),
                ),
            };
            let mut resp = rc
                .server_reflection_info(tokio_stream::iter(vec![req]))
                .await
                .unwrap()
                .into_inner();
            let first = resp.next().await.unwrap().unwrap();
            let Some(refl::server_reflection_response::MessageResponse::ListServicesResponse(
                list,
            )) = first.message_response
            else {
                panic!("unexpected reflection answer: {first:?}");
            };
            list.service.into_iter().map(|s| s.name).collect::<Vec<String>>()
        }};
    }
    for names in [
        list_services!(tonic_reflection::pb::v1),
        list_services!(tonic_reflection::pb::v1alpha),
    ] {
        for want in ["physnap.v1.JobService", "grpc.health.v1.Health"] {
            assert!(names.contains(&want.to_string()), "{want}: {names:?}");
        }
    }
    s.shutdown().await;
}

async fn channel_for(s: &support::TestServer) -> tonic::transport::Channel {
    tonic::transport::Endpoint::from_shared(s.grpc_url())
        .unwrap()
        .connect()
        .await
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn queue_full_is_resource_exhausted() {
    let s = start(Opts {
        queue_capacity: 1,
        ..Default::default()
    })
    .await;
    let mut cl = JobServiceClient::connect(s.grpc_url()).await.unwrap();
    let flat: Vec<f32> = cloud(20).into_iter().flatten().collect();
    let mut long = spec(flat);
    long.samples = Some(16);
    let mut ids = Vec::new();
    let mut exhausted = None;
    for _ in 0..4 {
        match cl
            .submit_job(pb::SubmitJobRequest {
                spec: Some(long.clone()),
                request_id: String::new(),
            })
            .await
        {
            Ok(j) => ids.push(j.into_inner().id),
            Err(e) => {
                exhausted = Some(e);
                break;
            }
        }
    }
    let e = exhausted.expect("the queue never filled");
    assert_eq!(e.code(), tonic::Code::ResourceExhausted);
    assert_eq!(e.metadata().get("retry-after").unwrap(), "7");
    for id in ids {
        cl.cancel_job(pb::CancelJobRequest { id }).await.unwrap();
    }
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cli_submit_watch_downloads_verified_artifacts() {
    let s = start(Opts::default()).await;
    let ply = s.root.path().join("scan.ply");
    physnap::pointcloud::PointCloud { points: cloud(40) }
        .write(&ply, physnap::pointcloud::Format::Ply)
        .unwrap();
    let out = s.root.path().join("out");
    let (server, ply2, out2) = (s.grpc_url(), ply.clone(), out.clone());
    let o = tokio::task::spawn_blocking(move || {
        std::process::Command::new(env!("CARGO_BIN_EXE_physnap"))
            .args(["submit", "--server", &server, "--category", "Door"])
            .args(["--seed", "4", "--resolution", "8", "--sampler", "ddim"])
            .args([
                "--steps",
                "20",
                "--n-g",
                "5",
                "--guidance-max-step",
                "0.05",
                "--camera=-2,0,0.5",
                "--repair",
                "off",
                "--points",
            ])
            .arg(&ply2)
            .arg("--out")
            .arg(&out2)
            .env("PHYSNAP_LOG", "warn")
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let id = stdout.lines().next().unwrap().trim().to_string();
    let job = s.svc.get("local", &id).await.unwrap();
    assert_eq!(job.state, "SUCCEEDED");
    assert_eq!(job.request.category.as_deref(), Some("Door"));
    // A scan-guided job with a category runs without category guidance by default (w = 2
    // completed scans worse), in every step when a weight is asked for.
    assert_eq!(job.request.category_guidance, 0.0);
    assert_eq!(job.request.category_guidance_below, 1000);
    // The scan's camera, at ℓ_free's default weight, and repair as asked.
    assert_eq!(job.request.camera, vec![[-2.0, 0.0, 0.5]]);
    assert_eq!(
        (job.request.w_free, job.request.repair.as_str()),
        (15.0, "off")
    );
    for a in &job.artifacts {
        let bytes = std::fs::read(out.join(&a.name)).unwrap();
        assert_eq!(
            format!("{:x}", Sha256::digest(&bytes)),
            a.sha256,
            "{}",
            a.name
        );
    }
    // `watch` of a finished job prints its state; an unknown id fails with NOT_FOUND.
    let server = s.grpc_url();
    let o = tokio::task::spawn_blocking(move || {
        std::process::Command::new(env!("CARGO_BIN_EXE_physnap"))
            .args(["watch", "--server", &server, "no-such-job"])
            .env("PHYSNAP_LOG", "warn")
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("NotFound"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    s.shutdown().await;
}

async fn artifact(
    cl: &mut JobServiceClient<tonic::transport::Channel>,
    id: &str,
    name: &str,
) -> Vec<u8> {
    let mut chunks = cl
        .get_artifact(pb::GetArtifactRequest {
            id: id.into(),
            name: name.into(),
        })
        .await
        .unwrap()
        .into_inner();
    let mut bytes = Vec::new();
    while let Some(c) = chunks.next().await {
        bytes.extend_from_slice(&c.unwrap().data);
    }
    bytes
}

/// Submits `spec`, waits for the job to succeed and returns its view and ranking.json.
async fn run_to_ranking(
    cl: &mut JobServiceClient<tonic::transport::Channel>,
    spec: pb::JobSpec,
) -> (serde_json::Value, serde_json::Value) {
    let job = cl
        .submit_job(pb::SubmitJobRequest {
            spec: Some(spec),
            request_id: String::new(),
        })
        .await
        .unwrap()
        .into_inner();
    let view: serde_json::Value = serde_json::from_str(&job.json).unwrap();
    let last = watch(cl, &job.id, 0).await.pop().unwrap();
    assert_eq!(last.state, pb::State::Succeeded as i32, "{}", last.json);
    let ranking = serde_json::from_slice(&artifact(cl, &job.id, "ranking.json").await).unwrap();
    (view, ranking)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cameras_w_free_and_repair_reach_the_job_and_its_ranking() {
    let s = start(Opts::default()).await;
    let mut cl = JobServiceClient::connect(s.grpc_url()).await.unwrap();
    // cloud(48) lies in [-0.5, 0.5] × [-0.3, 0.3] × [0.1, 0.9].
    let flat: Vec<f32> = cloud(48).into_iter().flatten().collect();
    let cam = |x, y, z| pb::Vec3 { x, y, z };
    let quick = pb::JobSpec {
        steps: Some(10),
        n_g: Some(500),
        refine_steps: Some(2),
        resolution: Some(8),
        ..spec(flat.clone())
    };
    let with = pb::JobSpec {
        camera: vec![cam(-2.0, 0.0, 0.5), cam(0.0, -2.0, 0.5)],
        w_free: Some(4.0),
        ..quick.clone()
    };
    let (view, ranking) = run_to_ranking(&mut cl, with.clone()).await;
    let req = &view["request"];
    assert_eq!(
        req["camera"],
        serde_json::json!([[-2.0, 0.0, 0.5], [0.0, -2.0, 0.5]]),
        "{req}"
    );
    assert_eq!(
        (req["w_free"].as_f64(), req["repair"].as_str()),
        (Some(4.0), Some("on")),
        "{req}"
    );
    assert_eq!(ranking["guidance"]["w_free"], 4.0, "{ranking:#}");
    assert_eq!(ranking["guidance"]["cameras"], req["camera"], "{ranking:#}");
    assert_eq!(ranking["repair"], "on");
    let row = &ranking["samples"][0];
    assert!(row["repairs"].as_u64().is_some(), "{ranking:#}");
    assert!(row["removed"].is_array(), "{ranking:#}");
    // repair "off", one camera at the default ℓ_free weight.
    let off = pb::JobSpec {
        camera: vec![cam(-2.0, 0.0, 0.5)],
        w_free: None,
        repair: "off".into(),
        ..quick.clone()
    };
    let (view, ranking) = run_to_ranking(&mut cl, off).await;
    let req = &view["request"];
    assert_eq!(
        (req["w_free"].as_f64(), req["repair"].as_str()),
        (Some(15.0), Some("off")),
        "{req}"
    );
    assert_eq!(ranking["repair"], "off");
    assert_eq!(ranking["samples"][0]["repairs"], 0, "{ranking:#}");
    assert_eq!(
        ranking["samples"][0]["removed"],
        serde_json::json!([]),
        "{ranking:#}"
    );
    // INVALID_ARGUMENT names the repeated field's entry, the limit and the value.
    let cases: [(pb::JobSpec, &str, &str); 6] = [
        (
            pb::JobSpec {
                camera: vec![cam(-2.0, 0.0, 0.5), cam(0.0, 0.0, 0.5)],
                ..quick.clone()
            },
            "camera[1]",
            "outside the points' box",
        ),
        (
            pb::JobSpec {
                camera: vec![cam(f64::NAN, 0.0, 0.5)],
                ..quick.clone()
            },
            "camera[0]",
            "3 finite numbers",
        ),
        (
            pb::JobSpec {
                w_free: Some(-1.0),
                ..with.clone()
            },
            "w_free",
            ">= 0",
        ),
        (
            pb::JobSpec {
                repair: "maybe".into(),
                ..quick.clone()
            },
            "repair",
            "\"on\" or \"off\"",
        ),
        // The frame fields reach the estimate: a zero up is refused by name.
        (
            pb::JobSpec {
                frame: "auto".into(),
                up: Some(cam(0.0, 0.0, 0.0)),
                ..quick.clone()
            },
            "up",
            "non-zero",
        ),
        (
            pb::JobSpec {
                frame: "sideways".into(),
                ..quick.clone()
            },
            "frame",
            "\"canonical\" or \"auto\"",
        ),
    ];
    for (bad, field, limit) in cases {
        let e = refused(&mut cl, bad).await;
        assert_eq!(e.code(), tonic::Code::InvalidArgument);
        assert_eq!(e.metadata().get("physnap-field").unwrap(), field);
        // (The box's limit has a '×', which ASCII metadata cannot carry; the message has it.)
        assert!(
            e.message().contains(field) && e.message().contains(limit),
            "{}",
            e.message()
        );
    }
    // Several defects: one field/limit/value triple each, in order, and all in the message.
    let e = refused(
        &mut cl,
        pb::JobSpec {
            frame: "sideways".into(),
            samples: Some(0),
            resolution: Some(1),
            ..quick.clone()
        },
    )
    .await;
    assert_eq!(e.code(), tonic::Code::InvalidArgument);
    let all = |k: &str| -> Vec<String> {
        e.metadata()
            .get_all(k)
            .iter()
            .map(|v| v.to_str().unwrap().to_string())
            .collect()
    };
    assert_eq!(all("physnap-field"), ["frame", "samples", "resolution"]);
    assert_eq!(all("physnap-limit").len(), 3);
    assert_eq!(all("physnap-value").len(), 3);
    for f in ["frame", "samples", "resolution"] {
        assert!(e.message().contains(f), "{}", e.message());
    }
    s.shutdown().await;
}

/// An oversize SubmitJob gets OUT_OF_RANGE with physnap's field/limit/value metadata, and a
/// resume point beyond the log of a running job still ends the stream with `done`, as SSE.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oversize_message_metadata_and_resume_ahead_ends_with_done() {
    let s = start(Opts {
        max_body_bytes: 1 << 20,
        ..Opts::default()
    })
    .await;
    let mut cl = JobServiceClient::connect(s.grpc_url())
        .await
        .unwrap()
        .max_encoding_message_size(64 << 20);
    // 150k points of 3 f32: 1.8 MB, above the 1 MiB limit.
    let big: Vec<f32> = (0..450_000).map(|i| (i % 97) as f32 * 0.01).collect();
    let st = refused(&mut cl, spec(big)).await;
    assert_eq!(st.code(), tonic::Code::OutOfRange, "{st:?}");
    let md = st.metadata();
    assert_eq!(md.get("physnap-field").unwrap(), "message");
    assert_eq!(md.get("physnap-limit").unwrap(), "<= 1048576 bytes");
    assert!(
        md.get("physnap-value")
            .unwrap()
            .to_str()
            .unwrap()
            .ends_with(" bytes"),
        "{md:?}"
    );
    // A long job, watched from far beyond its log while it runs.
    let mut long = spec(cloud(32).into_iter().flatten().collect());
    long.sampler = "ddpm".into();
    long.steps = Some(1000);
    long.n_g = Some(0);
    let job = cl
        .submit_job(pb::SubmitJobRequest {
            spec: Some(long),
            request_id: String::new(),
        })
        .await
        .unwrap()
        .into_inner();
    let events = watch(&mut cl, &job.id, 1_000_000).await;
    assert_eq!(
        events.last().map(|e| e.kind.as_str()),
        Some("done"),
        "{:?}",
        events.iter().map(|e| &e.kind).collect::<Vec<_>>()
    );
    s.shutdown().await;
}
