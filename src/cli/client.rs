//! CLI wiring of `physnap submit` and `physnap watch`: a small gRPC client of a running server
//! (binary only).
//!
//! Why it exists: scripts want "send this point cloud, show progress, give me the files"
//! without writing a client. It uses the generated tonic client of `proto/physnap/v1`, reads the
//! cloud with the same readers as the server (PLY, NPY, JSON; the server re-validates), shows a
//! progress bar from `WatchJob`, and downloads the artefacts with `GetArtifact`, checking their
//! sha256.

use anyhow::{Context, bail};
use clap::Args;
use physnap::pointcloud::{Limits, PointCloud};
use physnap::service::grpc::pb::{self, job_service_client::JobServiceClient};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use tokio_stream::StreamExt as _;
use tonic::Request;

#[derive(Args, Debug)]
pub struct ConnArgs {
    /// gRPC address of the server.
    #[arg(long, env = "PHYSNAP_SERVER", default_value = "http://127.0.0.1:50051")]
    server: String,
    /// Bearer token (when the server has tenants).
    #[arg(long, env = "PHYSNAP_TOKEN", hide_env_values = true)]
    token: Option<String>,
}

#[derive(Args, Debug)]
pub struct SubmitArgs {
    #[command(flatten)]
    conn: ConnArgs,
    /// Partial point cloud (.ply, .npy or .json).
    #[arg(long, env = "PHYSNAP_POINTS")]
    points: PathBuf,
    /// Category (e.g. StorageFurniture); omit for unconditional generation.
    #[arg(long, env = "PHYSNAP_CATEGORY")]
    category: Option<String>,
    /// Seed of sample 0 (default: the server picks one and reports it).
    #[arg(long, env = "PHYSNAP_SEED")]
    seed: Option<u64>,
    /// Best-of-N samples.
    #[arg(long, env = "PHYSNAP_SAMPLES")]
    samples: Option<u32>,
    /// Marching-cubes resolution.
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION")]
    resolution: Option<u32>,
    /// Job deadline in seconds.
    #[arg(long, env = "PHYSNAP_DEADLINE")]
    deadline: Option<f64>,
    /// Point-cloud loss weight (server default: 45 ÷ active terms; all weights 0 = unguided).
    #[arg(long, env = "PHYSNAP_W_PC")]
    w_pc: Option<f64>,
    /// Penetration loss weight (server default: 3 × the paper's 2 ÷ active terms; 0 turns it
    /// off).
    #[arg(long, env = "PHYSNAP_W_PEN")]
    w_pen: Option<f64>,
    /// Mobility loss weight (server default: 3 × the paper's 2 ÷ active terms; 0 turns it off).
    #[arg(long, env = "PHYSNAP_W_MOB")]
    w_mob: Option<f64>,
    /// n_g, as in the paper: guide the reverse steps with diffusion time t < this (0-1000;
    /// server default 500).
    #[arg(long, env = "PHYSNAP_N_G")]
    n_g: Option<u32>,
    /// Temperature τ of the point-to-part soft assignment (server default 1000).
    #[arg(long, env = "PHYSNAP_TAU")]
    tau: Option<f64>,
    /// Clamp each guidance-gradient entry to ±this (a deviation from the paper; server default
    /// 0.02, 0 = off).
    #[arg(long, env = "PHYSNAP_GUIDANCE_MAX_STEP")]
    guidance_max_step: Option<f64>,
    /// Refinement steps on the guidance loss of the finished sample (physnap, not in the
    /// paper; server default 30, 0 = off).
    #[arg(long, env = "PHYSNAP_GUIDANCE_REFINE_STEPS")]
    guidance_refine_steps: Option<u32>,
    /// Physics-only refinement steps after the refinement steps: ℓ_pen and ℓ_mob alone, part
    /// boxes only (0-1000; server default 0 = off; they run only when w_pen or w_mob > 0).
    #[arg(long, env = "PHYSNAP_GUIDANCE_REFINE_PHYSICS_STEPS")]
    guidance_refine_physics_steps: Option<u32>,
    /// Reverse-step rule: ddim (server default) or ddpm (the paper's, with --steps 1000).
    #[arg(long, env = "PHYSNAP_SAMPLER", value_parser = ["ddpm", "ddim"])]
    sampler: Option<String>,
    /// DDIM noise level η in [0, 1] (ddim only).
    #[arg(long, env = "PHYSNAP_DDIM_ETA")]
    eta: Option<f64>,
    /// Reverse steps, 1-1000 (server default 200).
    #[arg(long, env = "PHYSNAP_STEPS")]
    steps: Option<u32>,
    /// Codebook retrieval of part shapes: auto (server default: empty when the weights have a
    /// codebook), off, empty, all or category (with --category: every part from that
    /// category's codes).
    #[arg(long, env = "PHYSNAP_RETRIEVAL", value_parser = ["auto", "off", "empty", "all", "category"])]
    retrieval: Option<String>,
    /// Classifier-free category guidance w in [0, 20] with --category (server default: 0 for a
    /// scan-guided job, 2 without loss guidance; 0: plain conditioning).
    #[arg(long, env = "PHYSNAP_CATEGORY_GUIDANCE")]
    category_guidance: Option<f64>,
    /// Apply the category guidance only in steps with diffusion time t below this, 1-1000
    /// (server default: 1000, every step, for a scan-guided job; 500 without loss guidance).
    #[arg(long, env = "PHYSNAP_CATEGORY_GUIDANCE_BELOW")]
    category_guidance_below: Option<u32>,
    /// Joint motions of the result: screw (NAP: both ranges kept) or dominant (each joint
    /// keeps only its wider range); server default when unset.
    #[arg(long, env = "PHYSNAP_JOINT_MOTION", value_parser = ["screw", "dominant"])]
    joint_motion: Option<String>,
    /// Sensor position x,y,z (object frame, metres) the scan was taken from; repeat the flag
    /// (or separate with ';' in PHYSNAP_CAMERA) for several views. Turns on the free-space loss
    /// and the removal of parts in space the camera saw through.
    #[arg(
        long = "camera",
        env = "PHYSNAP_CAMERA",
        value_delimiter = ';',
        value_name = "X,Y,Z",
        allow_hyphen_values = true
    )]
    cameras: Vec<String>,
    /// Weight of the free-space loss (server default: 15 with a camera, 0 without).
    #[arg(long, env = "PHYSNAP_W_FREE")]
    w_free: Option<f64>,
    /// Joint repair and part removal: on or off (server default: on).
    #[arg(long, env = "PHYSNAP_REPAIR", value_parser = ["on", "off"])]
    repair: Option<String>,
    /// Scale hypothesis: auto, off or a factor (server default: auto).
    #[arg(long, env = "PHYSNAP_SCALE")]
    scale: Option<String>,
    /// The scan's frame: canonical or auto (server default: canonical; see `generate --frame`).
    #[arg(long, env = "PHYSNAP_FRAME", value_parser = ["canonical", "auto"])]
    frame: Option<String>,
    /// The scan's up direction x,y,z with --frame auto (server default: 0,0,1).
    #[arg(
        long,
        env = "PHYSNAP_UP",
        value_name = "X,Y,Z",
        allow_hyphen_values = true
    )]
    up: Option<String>,
    /// Idempotency key (a retry with the same key returns the same job).
    #[arg(long, env = "PHYSNAP_REQUEST_ID", default_value = "")]
    request_id: String,
    /// Watch the job to the end and download its artefacts into this directory.
    #[arg(long, env = "PHYSNAP_OUT")]
    out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct WatchArgs {
    #[command(flatten)]
    conn: ConnArgs,
    /// Job id.
    #[arg(env = "PHYSNAP_JOB_ID")]
    id: String,
    /// Download the artefacts into this directory once the job succeeded.
    #[arg(long, env = "PHYSNAP_OUT")]
    out: Option<PathBuf>,
}

type Client = JobServiceClient<tonic::transport::Channel>;

fn request<T>(conn: &ConnArgs, msg: T) -> anyhow::Result<Request<T>> {
    let mut r = Request::new(msg);
    if let Some(t) = &conn.token {
        r.metadata_mut().insert(
            "authorization",
            format!("Bearer {t}")
                .parse()
                .context("the token is not valid header text")?,
        );
    }
    Ok(r)
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?)
}

async fn connect(conn: &ConnArgs) -> anyhow::Result<Client> {
    JobServiceClient::connect(conn.server.clone())
        .await
        .with_context(|| format!("connecting to {}", conn.server))
}

fn status(e: tonic::Status) -> anyhow::Error {
    anyhow::anyhow!("{:?}: {}", e.code(), e.message())
}

pub fn submit(a: SubmitArgs) -> anyhow::Result<()> {
    let cloud = PointCloud::read(&a.points, &Limits::default())
        .with_context(|| format!("reading {}", a.points.display()))?;
    let xyz: Vec<u8> = cloud
        .points
        .iter()
        .flat_map(|p| p.iter().flat_map(|c| c.to_le_bytes()))
        .collect();
    let camera = super::generate::parse_cameras(&a.cameras)?
        .into_iter()
        .map(|[x, y, z]| pb::Vec3 {
            x: x.into(),
            y: y.into(),
            z: z.into(),
        })
        .collect();
    runtime()?.block_on(async {
        let mut cl = connect(&a.conn).await?;
        let spec = pb::JobSpec {
            points: Some(pb::job_spec::Points::XyzF32le(xyz)),
            category: a.category.clone().unwrap_or_default(),
            seed: a.seed,
            samples: a.samples,
            resolution: a.resolution,
            deadline_seconds: a.deadline,
            w_pc: a.w_pc,
            w_pen: a.w_pen,
            w_mob: a.w_mob,
            n_g: a.n_g,
            tau: a.tau,
            guidance_max_step: a.guidance_max_step,
            refine_steps: a.guidance_refine_steps,
            refine_physics_steps: a.guidance_refine_physics_steps,
            sampler: a.sampler.clone().unwrap_or_default(),
            eta: a.eta,
            steps: a.steps,
            retrieval: a.retrieval.clone().unwrap_or_default(),
            category_guidance: a.category_guidance,
            category_guidance_below: a.category_guidance_below,
            joint_motion: a.joint_motion.clone().unwrap_or_default(),
            camera,
            w_free: a.w_free,
            repair: a.repair.clone().unwrap_or_default(),
            scale: a.scale.clone().unwrap_or_default(),
            frame: a.frame.clone().unwrap_or_default(),
            up: a
                .up
                .as_deref()
                .map(super::generate::parse_up)
                .transpose()?
                .map(|[x, y, z]| pb::Vec3 { x, y, z }),
            ..Default::default()
        };
        let job = cl
            .submit_job(request(
                &a.conn,
                pb::SubmitJobRequest {
                    spec: Some(spec),
                    request_id: a.request_id.clone(),
                },
            )?)
            .await
            .map_err(status)?
            .into_inner();
        println!("{}", job.id);
        match &a.out {
            Some(out) => watch_and_fetch(&mut cl, &a.conn, &job.id, Some(out)).await,
            None => Ok(()),
        }
    })
}

pub fn watch(a: WatchArgs) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let mut cl = connect(&a.conn).await?;
        watch_and_fetch(&mut cl, &a.conn, &a.id, a.out.as_deref()).await
    })
}

async fn watch_and_fetch(
    cl: &mut Client,
    conn: &ConnArgs,
    id: &str,
    out: Option<&Path>,
) -> anyhow::Result<()> {
    let mut stream = cl
        .watch_job(request(
            conn,
            pb::WatchJobRequest {
                id: id.to_string(),
                after_sequence: 0,
            },
        )?)
        .await
        .map_err(status)?
        .into_inner();
    let pb_ = super::progress_bar(1000, "job");
    let mut last: Option<pb::JobEvent> = None;
    while let Some(ev) = stream.next().await {
        let ev = ev.map_err(status)?;
        if ev.kind == "progress" {
            let p: serde_json::Value = serde_json::from_str(&ev.json).unwrap_or_default();
            let (step, total) = (p["step"].as_u64().unwrap_or(0), p["total_steps"].as_u64());
            let (sample, samples) = (p["sample"].as_u64().unwrap_or(0), p["samples"].as_u64());
            if let (Some(total), Some(samples)) = (total, samples) {
                pb_.set_length(total * samples);
                pb_.set_position(sample * total + step);
            }
            pb_.set_prefix(p["phase"].as_str().unwrap_or("").to_string());
        }
        last = Some(ev);
    }
    pb_.finish_and_clear();
    let last = last.context("the event stream ended without events")?;
    let job: serde_json::Value = serde_json::from_str(&last.json).unwrap_or_default();
    let state = job["state"].as_str().unwrap_or("?");
    eprintln!("job {id}: {state}");
    if state != "SUCCEEDED" {
        bail!(
            "job {id} {state}: {} ({})",
            job["error"]["detail"].as_str().unwrap_or(""),
            job["error"]["type"].as_str().unwrap_or("")
        );
    }
    let Some(out) = out else { return Ok(()) };
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for name in physnap::service::api::ARTIFACT_NAMES {
        let mut chunks = cl
            .get_artifact(request(
                conn,
                pb::GetArtifactRequest {
                    id: id.to_string(),
                    name: name.to_string(),
                },
            )?)
            .await
            .map_err(status)?
            .into_inner();
        let (mut bytes, mut sha) = (Vec::new(), String::new());
        while let Some(c) = chunks.next().await {
            let c = c.map_err(status)?;
            bytes.extend_from_slice(&c.data);
            if !c.sha256.is_empty() {
                sha = c.sha256;
            }
        }
        let got = format!("{:x}", Sha256::digest(&bytes));
        if got != sha {
            bail!("{name}: sha256 {got} does not match the server's {sha}");
        }
        let path = out.join(name);
        physnap::export::write_atomic(&path, &bytes)?;
        println!("{}", path.display());
    }
    Ok(())
}
