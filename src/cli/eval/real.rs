//! `physnap eval real`: generation on every scan of a benchmark set, scored against the assets
//! with real-scans.md §3's metrics; writes OUT/real.md and OUT/real.json.
//!
//! Why it exists apart from `eval guided`: this measures what a user of a real scan gets (the
//! `best` sample as `generate` ranks it, its URDF in MuJoCo, the joints against the asset's),
//! not the paper's guidance table. Flags to library calls (`physnap::eval::real`), files via
//! `physnap::io::real`; the MuJoCo check is scripts/sim_check.py, embedded in the binary and
//! run as a subprocess.
//!
//! Layout of OUT: `scans/<scan>.json` (one per finished scan; a rerun with the same settings
//! skips them, so a stopped run resumes), `jobs/<scan>/<row>/` (the export of each job's best
//! sample: robot.urdf, meshes/, model.glb, object.json), `settings.json`, `sim_check.py`,
//! `real.md`, `real.json`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;
use serde_json::json;

use physnap::data::categories::category_index;
use physnap::data::dataset::load_object_meshes;
use physnap::engine::frame::estimate;
use physnap::engine::generate::{GenerateRequest, PartShapes};
use physnap::engine::guidance::{GuidanceOptions, SdfField};
use physnap::engine::schedule::Schedule;
use physnap::eval::real::frame::{
    MovedUp, frame_error, move_of, moved, to_truth, truth_to_estimate,
};
use physnap::eval::real::{
    GtObject, JobResult, JobSample, RowKind, RowSpec, ScanResult, best_of, draw_samples,
    object_metrics, report, row_specs,
};
use physnap::export::{ExportOptions, export_dir_with_repairs};
use physnap::io::manifest::load_models;
use physnap::io::real::{
    ScanRecord, read_scan_result, read_scan_set, scan_json, sim_check, sim_probe, write_json,
};
use physnap::mesh::MeshingOptions;
use physnap::model::shape_prior::LatentSdfDecoder;
use physnap::pointcloud::{Limits, PointCloud};

use crate::cli::generate::{
    SamplingArgs, joint_motion, repair_mode, retrieval_mode, sampler, scale_of,
};
use crate::cli::progress_bar;

/// The MuJoCo check, shipped inside the binary so an installed `physnap` has it.
const SIM_CHECK: &str = include_str!("../../../scripts/sim_check.py");

#[derive(Args, Debug)]
pub struct EvalRealArgs {
    /// Weights directory with manifest.json.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    weights: PathBuf,
    /// Benchmark set: an imported data set (dataset.json, objects/<id>/: the ground truth), or
    /// a folder with it as DATA/dataset (scripts/real-assets.sh's layout); scans in DATA/scans
    /// (see --scans).
    #[arg(long, env = "PHYSNAP_DATA")]
    data: PathBuf,
    /// Scan folder (default DATA/scans): per-scan `<object>_<view>.json` records (object,
    /// category, camera) next to `<object>_<view>.ply`, or an index scans.json / testset.json
    /// (`physnap data testset`'s).
    #[arg(long, env = "PHYSNAP_REAL_SCANS")]
    scans: Option<PathBuf>,
    /// Output directory (real.md, real.json, scans/, jobs/).
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,
    /// Views per object, the first ones by view index (0: all).
    #[arg(long, env = "PHYSNAP_REAL_VIEWS", default_value_t = 0)]
    views: usize,
    /// Samples of the best-of row (the best by the ranking score, as `generate --samples N`
    /// ranks them); 1 drops the row.
    #[arg(long, env = "PHYSNAP_SAMPLES", default_value_t = 4)]
    samples: usize,
    /// Give the model the scan's category: yes (as `generate --category`), no, or both blocks.
    #[arg(long, env = "PHYSNAP_CATEGORY_AWARE", default_value = "yes", value_parser = ["yes", "no", "both"])]
    category_aware: String,
    /// Use the first N objects (sorted by id; 0: all).
    #[arg(long, env = "PHYSNAP_MAX_OBJECTS", default_value_t = 0)]
    max_objects: usize,
    /// Rows to run, comma-separated among prior, guided, best (default: all three).
    #[arg(long, env = "PHYSNAP_REAL_ROWS", value_delimiter = ',', value_parser = ["prior", "guided", "best"])]
    rows: Vec<String>,
    /// Seed of sample 0 of every scan (sample k uses seed + k, as `generate`).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    seed: u64,
    /// Marching-cubes grid cells per axis.
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = physnap::mesh::DEFAULT_RESOLUTION)]
    resolution: usize,
    /// Weight of the point-cloud loss of the guided rows (default: `generate --points`').
    #[arg(long, env = "PHYSNAP_W_PC")]
    w_pc: Option<f64>,
    /// Weight of the penetration loss of the guided rows (default: `generate --points`').
    #[arg(long, env = "PHYSNAP_W_PEN")]
    w_pen: Option<f64>,
    /// Weight of the mobility loss of the guided rows (default: `generate --points`').
    #[arg(long, env = "PHYSNAP_W_MOB")]
    w_mob: Option<f64>,
    /// Weight of the free-space loss of the guided rows when the scan has a camera (default:
    /// `generate --camera`'s).
    #[arg(long, env = "PHYSNAP_W_FREE")]
    w_free: Option<f64>,
    /// Use each scan's recorded camera position (as `generate --camera`): use (default) or
    /// ignore (the scan alone, as without a camera).
    #[arg(long, env = "PHYSNAP_SCAN_CAMERA", default_value = "use", value_parser = ["use", "ignore"])]
    scan_camera: String,
    /// Scale hypothesis of the guided rows, as `generate --scale`: auto (default), off or a
    /// factor.
    #[arg(long, env = "PHYSNAP_SCALE", default_value = "auto")]
    scale: String,
    /// Joint repair and part removal, as `generate --repair`: on (default) or off.
    #[arg(long, env = "PHYSNAP_REPAIR", default_value = "on", value_parser = ["on", "off"])]
    repair: String,
    /// The scans' frame: canonical (default: as recorded, in physnap's frame) or auto (each
    /// scan moved into a user's frame by a random yaw and translation, `physnap eval frame`'s
    /// move, with --frame-up up, and completed with `generate --frame auto`; the metrics are
    /// computed after mapping the output back by the true move).
    #[arg(long, env = "PHYSNAP_FRAME", default_value = "canonical", value_parser = ["canonical", "auto"])]
    frame: String,
    /// Up axis of the moved scans with --frame auto: z (only yaw and position unknown) or y.
    #[arg(long, env = "PHYSNAP_FRAME_UP", default_value = "z", value_parser = ["z", "y"])]
    frame_up: String,
    /// Sampler and guidance schedule.
    #[command(flatten)]
    sampling: SamplingArgs,
    /// Python 3 with `mujoco` (pip install mujoco==4.0.0) for the sim-clean check.
    #[arg(long, env = "PHYSNAP_PYTHON", default_value = "python3")]
    python: PathBuf,
    /// The sim-clean script (default: the copy built into physnap, written to OUT/sim_check.py).
    #[arg(long, env = "PHYSNAP_SIM_SCRIPT")]
    sim_script: Option<PathBuf>,
    /// Ignore the scan results of an earlier run in OUT instead of resuming from them.
    #[arg(long, env = "PHYSNAP_REAL_FRESH")]
    fresh: bool,
}

/// The settings a resumed run must share with the run it continues.
fn settings(a: &EvalRealArgs, rows: &[RowSpec]) -> serde_json::Value {
    json!({
        "weights": a.weights.display().to_string(),
        "data": a.data.display().to_string(),
        "rows": rows.iter().map(|r| r.key()).collect::<Vec<_>>(),
        "seed": a.seed,
        "resolution": a.resolution,
        "w": [a.w_pc, a.w_pen, a.w_mob],
        "w_free": a.w_free,
        "scan_camera": a.scan_camera,
        "repair": a.repair,
        "scale": a.scale,
        "frame": if a.frame == "auto" { format!("auto, {} up", a.frame_up) } else { a.frame.clone() },
        "sampling": format!("{:?}", a.sampling),
    })
}

/// The scans to run: `--max-objects` objects, `--views` views each, view-major (every object's
/// first view, then every second view, ...), so a run stopped early covers every object.
fn select(mut scans: Vec<ScanRecord>, views: usize, max_objects: usize) -> Vec<ScanRecord> {
    let mut objects: Vec<String> = scans.iter().map(|s| s.object.clone()).collect();
    objects.dedup();
    if max_objects > 0 {
        objects.truncate(max_objects);
    }
    let mut per: HashMap<String, usize> = HashMap::new();
    scans.retain(|s| {
        let n = per.entry(s.object.clone()).or_default();
        *n += 1;
        objects.contains(&s.object) && (views == 0 || *n <= views)
    });
    scans.sort_by(|a, b| (a.view, &a.object, &a.id).cmp(&(b.view, &b.object, &b.id)));
    scans
}

pub fn eval_real(a: EvalRealArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    if a.samples == 0 {
        bail!("invalid --samples: 0 (must be at least 1)");
    }
    let meshing = MeshingOptions {
        resolution: a.resolution,
    };
    meshing.validate()?;
    let blocks: Vec<bool> = match a.category_aware.as_str() {
        "no" => vec![false],
        "yes" => vec![true],
        _ => vec![false, true],
    };
    let rows = row_specs(&blocks, a.samples, &a.rows);
    if rows.is_empty() {
        bail!("invalid --rows {:?} with --samples 1: no row left", a.rows);
    }
    // DATA is the imported data set, or a folder holding it as DATA/dataset next to DATA/scans
    // (scripts/real-assets.sh's layout).
    let scan_dir = a.scans.clone().unwrap_or_else(|| a.data.join("scans"));
    let dataset = if !a.data.join("dataset.json").is_file()
        && a.data.join("dataset").join("dataset.json").is_file()
    {
        a.data.join("dataset")
    } else {
        a.data.clone()
    };
    let scans = select(
        read_scan_set(&scan_dir)
            .with_context(|| format!("reading scans of {}", scan_dir.display()))?,
        a.views,
        a.max_objects,
    );
    if scans.is_empty() {
        bail!("no scans in {}", scan_dir.display());
    }
    std::fs::create_dir_all(a.out.join("scans"))
        .with_context(|| format!("creating {}", a.out.display()))?;
    // The MuJoCo check first: a missing mujoco should stop the run before hours of sampling.
    let script = match &a.sim_script {
        Some(p) => p.clone(),
        None => {
            let p = a.out.join("sim_check.py");
            std::fs::write(&p, SIM_CHECK).with_context(|| format!("writing {}", p.display()))?;
            p
        }
    };
    let probe = sim_probe(&a.python, &script)?;
    tracing::info!("sim check: {probe}");
    let settings = settings(&a, &rows);
    let settings_path = a.out.join("settings.json");
    if !a.fresh && settings_path.is_file() {
        let old: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&settings_path)?).unwrap_or_default();
        if old != settings {
            bail!(
                "{} holds a run with other settings ({}); resume it with those, or pass --fresh, or another --out",
                a.out.display(),
                settings_path.display()
            );
        }
    }
    write_json(&settings_path, &settings)?;

    let device = physnap::model::cpu();
    let models = load_models(&a.weights, &device)
        .with_context(|| format!("loading weights from {}", a.weights.display()))?;
    let conditional = models.manifest.denoiser.config.categories > 0;
    if blocks.contains(&true) && !conditional {
        bail!(
            "invalid --category-aware {}: the weights' denoiser has no category input",
            a.category_aware
        );
    }
    let retrieval = retrieval_mode(&a.sampling.retrieval, &models)?;
    let joint_motion = joint_motion(&a.sampling.joint_motion)?;
    let sampler = sampler(&a.sampling.sampler, a.sampling.eta);
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let shapes = PartShapes {
        decoder: &decoder,
        field: Some(&decoder as &dyn SdfField),
        codebook: models.codebook.as_ref(),
    };
    let schedule = Schedule::default();
    let [w_pc, w_pen, w_mob] =
        GuidanceOptions::weights_or_defaults([a.w_pc, a.w_pen, a.w_mob], true);

    // Samples per scan: per block, 1 for the prior, the guided draws once for both guided rows.
    let draws = |aware: bool| -> (usize, usize) {
        let mine: Vec<&RowSpec> = rows.iter().filter(|r| r.category_aware == aware).collect();
        let prior = usize::from(mine.iter().any(|r| r.kind == RowKind::Prior));
        let guided = mine
            .iter()
            .filter(|r| r.kind != RowKind::Prior)
            .map(|r| r.kind.samples())
            .max()
            .unwrap_or(0);
        (prior, guided)
    };
    let per_scan: usize = blocks.iter().map(|&b| draws(b).0 + draws(b).1).sum();
    let pb = progress_bar(scans.len() * per_scan, "eval real");
    let mut gts: HashMap<String, GtObject> = HashMap::new();
    let mut results: Vec<ScanResult> = Vec::new();
    let mut resumed = 0;
    let limits = Limits {
        min_points: 1,
        max_points: physnap::engine::guidance::MAX_POINTS,
    };
    for (si, scan) in scans.iter().enumerate() {
        let result_path = a.out.join("scans").join(format!("{}.json", scan.id));
        // Resume: a finished scan of this run's rows (settings.json vouches for the rest).
        if !a.fresh
            && result_path.is_file()
            && let Ok(r) = read_scan_result(&result_path)
            && r.jobs.iter().map(|j| j.row).eq(rows.iter().copied())
        {
            results.push(r);
            resumed += 1;
            pb.set_position(((si + 1) * per_scan) as u64);
            continue;
        }
        if !gts.contains_key(&scan.object) {
            let dir = dataset.join("objects").join(&scan.object);
            let (object, meshes) = load_object_meshes(&dir)
                .with_context(|| format!("ground truth of scan {}", scan.id))?;
            gts.insert(scan.object.clone(), GtObject { object, meshes });
        }
        let gt = &gts[&scan.object];
        let points = PointCloud::read(&scan.cloud, &limits)
            .with_context(|| format!("reading {}", scan.cloud.display()))?
            .points;
        let category = scan.category.clone().or_else(|| gt.object.category.clone());
        // --frame auto: the scan (and its camera) in a user's frame, and the frame estimated
        // from it as `generate --frame auto` does.
        let camera = match (a.scan_camera.as_str(), scan.camera) {
            ("use", Some(c)) => vec![c.map(|v| v as f32)],
            _ => Vec::new(),
        };
        let framed = match MovedUp::parse(&a.frame_up).filter(|_| a.frame == "auto") {
            None => None,
            Some(up) => {
                let m = move_of(&scan.id, a.seed, up);
                let (p, c) = (moved(&m, &points), moved(&m, &camera));
                let est = estimate(&p, up.vector(), &c).map_err(|e| e.to_string());
                Some((m, p, c, est))
            }
        };
        let frame_error = match &framed {
            Some((m, _, _, Ok(e))) => Some(frame_error(m, &e.frame)),
            _ => None,
        };
        let mut jobs: Vec<JobResult> = Vec::new();
        let mut done = si * per_scan;
        for &aware in &blocks {
            let (n_prior, n_guided) = draws(aware);
            let cat = if aware {
                category
                    .as_deref()
                    .and_then(category_index)
                    .filter(|&i| i < models.manifest.categories.len())
            } else {
                None
            };
            let mine: Vec<RowSpec> = rows
                .iter()
                .copied()
                .filter(|r| r.category_aware == aware)
                .collect();
            if aware && cat.is_none() {
                for r in mine {
                    jobs.push(failed_job(r, "the scan has no category the weights know"));
                }
                done += n_prior + n_guided;
                pb.set_position(done as u64);
                continue;
            }
            let base = GenerateRequest {
                seed: a.seed,
                samples: 1,
                category: cat,
                category_name: cat.map(|i| models.manifest.categories[i].clone()),
                meshing,
                sampler,
                steps: a.sampling.steps,
                retrieval: if cat.is_some() {
                    retrieval
                } else {
                    retrieval.without_category()
                },
                joint_motion,
                repair: repair_mode(&a.repair),
                ..Default::default()
            };
            // Draws `n` samples of `req` on this scan, moving the bar and `done` along.
            let draw = |req: &GenerateRequest, n: usize, done: &mut usize| -> anyhow::Result<_> {
                let d0 = *done;
                let s = draw_samples(
                    &models.denoiser,
                    &shapes,
                    &models.manifest.feature_scales,
                    &schedule,
                    req,
                    n,
                    &points,
                    &mut |k| pb.set_position((d0 + k) as u64),
                )?;
                *done += n;
                Ok(s)
            };
            let prior = if n_prior > 0 {
                let req = GenerateRequest {
                    category_guidance: a.sampling.category.weight(false),
                    category_guidance_below: Some(a.sampling.category.below(false)),
                    ..base.clone()
                };
                draw(&req, 1, &mut done)?
            } else {
                Vec::new()
            };
            let mut frame_refused = None;
            let guided = if n_guided > 0 {
                // The scan as the user gives it, and its frame.
                let (given, cameras, frame) = match &framed {
                    None => (points.clone(), camera.clone(), None),
                    Some((_, p, c, Ok(e))) => (p.clone(), c.clone(), Some(e.frame)),
                    Some((_, _, _, Err(why))) => {
                        frame_refused = Some(format!("frame: {why}"));
                        (Vec::new(), Vec::new(), None)
                    }
                };
                if frame_refused.is_some() {
                    done += n_guided;
                    Vec::new()
                } else {
                    let canonical = frame.map_or(given.clone(), |f| f.points_to_canonical(&given));
                    let opts = a
                        .sampling
                        .guidance(given, [w_pc, w_pen, w_mob])
                        .with_cameras(cameras, a.w_free);
                    opts.validate(schedule.len())?;
                    let scale = scale_of(
                        &a.scale,
                        &canonical,
                        cat.map(|i| models.manifest.categories[i].as_str()),
                    )?;
                    let req = GenerateRequest {
                        guidance: Some(opts),
                        scale,
                        frame,
                        category_guidance: a.sampling.category.weight(true),
                        category_guidance_below: Some(a.sampling.category.below(true)),
                        ..base.clone()
                    };
                    draw(&req, n_guided, &mut done)?
                }
            } else {
                Vec::new()
            };
            // Guided outputs come out in the estimated canonical frame: G maps the truth there.
            let to_estimate = match &framed {
                Some((m, _, _, Ok(e))) => Some(truth_to_estimate(m, &e.frame)),
                _ => None,
            };
            for r in mine {
                let (samples, n, g) = match r.kind {
                    RowKind::Prior => (&prior, 1, None),
                    k => (&guided, k.samples(), to_estimate),
                };
                if let (Some(why), false) = (&frame_refused, r.kind == RowKind::Prior) {
                    jobs.push(failed_job(r, why));
                    continue;
                }
                let dir = a.out.join("jobs").join(&scan.id).join(r.key());
                jobs.push(job(r, samples, n, gt, &dir, meshing, a.seed ^ si as u64, g));
            }
        }
        // MuJoCo on every exported job of the scan, in one call.
        let urdfs: Vec<(usize, PathBuf)> = jobs
            .iter()
            .enumerate()
            .filter(|(_, j)| j.error.is_none())
            .map(|(i, j)| {
                (
                    i,
                    a.out
                        .join("jobs")
                        .join(&scan.id)
                        .join(j.row.key())
                        .join("robot.urdf"),
                )
            })
            .collect();
        let t = Instant::now();
        let verdicts = sim_check(
            &a.python,
            &script,
            &urdfs.iter().map(|u| u.1.clone()).collect::<Vec<_>>(),
        )?;
        let sim_s = t.elapsed().as_secs_f64() / urdfs.len().max(1) as f64;
        for ((i, _), v) in urdfs.iter().zip(verdicts) {
            jobs[*i].sim = Some(v);
            jobs[*i].seconds += sim_s;
        }
        let r = ScanResult {
            scan: scan.id.clone(),
            object: scan.object.clone(),
            category,
            view: scan.view,
            camera: scan.camera,
            points: points.len(),
            gt_joints: gt.movable_joints(),
            gt_revolute: gt.revolute_joints(),
            frame_error,
            jobs,
        };
        write_json(&result_path, &scan_json(&r))?;
        let line: Vec<String> = r
            .jobs
            .iter()
            .map(|j| match (&j.error, &j.metrics) {
                (None, Some(m)) => format!(
                    "{}: {}/{} parts, {:?}, chamfer {:.3}, sim {}",
                    j.row.key(),
                    m.parts,
                    m.gt_parts,
                    m.types,
                    m.chamfer_diag,
                    j.sim
                        .as_ref()
                        .map_or("—", |s| if s.clean { "clean" } else { "no" })
                ),
                (e, _) => format!("{}: failed ({})", j.row.key(), e.as_deref().unwrap_or("")),
            })
            .collect();
        let msg = format!(
            "{} [{}/{}] {}",
            scan.id,
            si + 1,
            scans.len(),
            line.join("; ")
        );
        // A hidden bar (no terminal) prints nothing: log the line instead.
        if pb.is_hidden() {
            tracing::info!("{msg}");
        } else {
            pb.println(msg);
        }
        results.push(r);
        pb.set_position(((si + 1) * per_scan) as u64);
    }
    pb.finish_and_clear();
    let wall = started.elapsed().as_secs_f64();
    let title = format!(
        "eval real: {} on {} ({} s{})",
        a.weights.display(),
        a.data.display(),
        wall.round(),
        if resumed > 0 {
            format!(", {resumed} scans resumed")
        } else {
            String::new()
        }
    );
    let md = report::markdown(&title, &results);
    print!("{md}");
    std::fs::write(a.out.join("real.md"), &md)?;
    write_json(&a.out.join("real.json"), &report_json(&a, &results, wall))?;
    println!("report: {}", a.out.join("real.md").display());
    Ok(())
}

fn failed_job(row: RowSpec, why: &str) -> JobResult {
    JobResult {
        row,
        samples: row.kind.samples(),
        best: None,
        d_pc: f64::NAN,
        error: Some(why.to_string()),
        metrics: None,
        sim: None,
        native: None,
        seconds: 0.0,
    }
}

/// One job from its samples (the first `n`): the best one exported to `dir` (in the scan's
/// frame, when it has one) and scored; `to_estimate` (with `--frame auto`) maps the true
/// canonical frame onto the one the samples came out in.
#[allow(clippy::too_many_arguments)]
fn job(
    row: RowSpec,
    samples: &[JobSample],
    n: usize,
    gt: &GtObject,
    dir: &Path,
    meshing: MeshingOptions,
    seed: u64,
    to_estimate: Option<nalgebra::Isometry3<f64>>,
) -> JobResult {
    let t = Instant::now();
    let drawn: f64 = samples.iter().take(n).map(|s| s.seconds).sum();
    let mut r = failed_job(row, "");
    r.samples = n;
    let Some(b) = best_of(samples, n) else {
        let why = samples
            .iter()
            .take(n)
            .find_map(|s| s.outcome.as_ref().err().map(ToString::to_string))
            .unwrap_or_else(|| "no sample".into());
        r.error = Some(format!("every sample failed (first: {why})"));
        r.seconds = drawn;
        return r;
    };
    let s = &samples[b];
    let g = s
        .outcome
        .as_ref()
        .expect("best_of picks a sample with an object");
    r.best = Some((s.index, s.seed));
    r.d_pc = s.d_pc;
    let opts = ExportOptions {
        meshing,
        frame: Some(g.frame),
        ..Default::default()
    };
    match export_dir_with_repairs(&g.object, &g.meshes, &g.repairs, dir, &opts) {
        Ok(report) => {
            // The same check on each whole mesh's hull: what an engine makes of a part without
            // collision pieces (EVALUATION compares the two).
            let hulls = physnap::export::collision::hulls_only(
                &g.meshes,
                physnap::mesh::convex::MAX_VERTICES,
            );
            let on_hulls = physnap::sim::check(&g.object, &hulls, &opts.sim).ok();
            r.native = Some(physnap::eval::real::NativeSim {
                clean: report.sim.clean,
                worst_depth: report.sim.worst_depth(),
                hulls_clean: on_hulls.is_some_and(|h| h.clean),
                hulls_worst_depth: on_hulls.map_or(f64::NAN, |h| h.worst_depth()),
            });
            let m = match to_estimate {
                Some(t) => {
                    let (o, meshes) = to_truth(&t, &g.object, &g.meshes);
                    object_metrics(&o, &meshes, &gt.object, &gt.meshes, seed)
                }
                None => object_metrics(&g.object, &g.meshes, &gt.object, &gt.meshes, seed),
            };
            if m.chamfer_diag.is_finite() {
                r.error = None;
            } else {
                r.error = Some("the best sample has no surface".into());
            }
            r.metrics = Some(m);
        }
        Err(e) => r.error = Some(format!("export: {e}")),
    }
    r.seconds = drawn + t.elapsed().as_secs_f64();
    r
}

fn summary_json(s: &physnap::eval::real::Summary) -> serde_json::Value {
    use physnap::eval::real::Summary as S;
    let num = |v: f64| {
        if v.is_finite() {
            json!(v)
        } else if v.is_infinite() {
            json!("inf")
        } else {
            serde_json::Value::Null
        }
    };
    json!({
        "jobs": s.jobs, "failed": s.failed,
        "parts_exact": num(S::share(s.parts_exact, s.jobs)), "parts_exact_count": s.parts_exact,
        "joint_types_exact": num(S::share(s.types_exact, s.jobs)), "joint_types_exact_count": s.types_exact,
        "gt_joints": s.gt_joints, "axis_within_10deg": num(S::share(s.axis_ok, s.gt_joints)),
        "axis_within_10deg_count": s.axis_ok, "axis_median_deg": num(s.axis_median),
        "gt_revolute": s.gt_revolute, "revolute_matched": s.revolute_matched,
        "pivot_within_0_05": num(S::share(s.pivot_ok, s.gt_revolute)), "pivot_within_0_05_count": s.pivot_ok,
        "pivot_median": num(s.pivot_median),
        "chamfer_diag_median": num(s.chamfer_median),
        "sim_compiled": s.sim_compiled, "sim_clean": num(S::share(s.sim_clean, s.jobs)), "sim_clean_count": s.sim_clean,
        "native_clean": num(S::share(s.native_clean, s.jobs)), "hulls_clean": num(S::share(s.hulls_clean, s.jobs)),
        "seconds_median": num(s.seconds_median), "seconds_mean": num(s.seconds_mean),
    })
}

fn report_json(a: &EvalRealArgs, scans: &[ScanResult], wall: f64) -> serde_json::Value {
    let keys = report::row_keys(scans);
    let mut objects: Vec<&str> = scans.iter().map(|s| s.object.as_str()).collect();
    objects.sort_unstable();
    objects.dedup();
    let rows: Vec<serde_json::Value> = keys
        .iter()
        .map(|k| {
            let per_cat: serde_json::Map<String, serde_json::Value> = report::categories(scans)
                .into_iter()
                .map(|c| {
                    let s = report::row_summary(scans, k, &|s: &ScanResult| {
                        s.category.as_deref().unwrap_or("—") == c
                    });
                    (c, summary_json(&s))
                })
                .collect();
            let per_obj: serde_json::Map<String, serde_json::Value> = objects
                .iter()
                .map(|o| {
                    let s = report::row_summary(scans, k, &|s: &ScanResult| s.object == *o);
                    (o.to_string(), summary_json(&s))
                })
                .collect();
            json!({
                "row": k,
                "overall": summary_json(&report::row_summary(scans, k, &|_| true)),
                "categories": per_cat,
                "objects": per_obj,
            })
        })
        .collect();
    json!({
        "format": "physnap.eval_real/v1",
        "command": std::env::args().collect::<Vec<_>>().join(" "),
        "weights": a.weights.display().to_string(),
        "data": a.data.display().to_string(),
        "seconds": wall,
        "metrics": "real-scans.md §3: generated object = the best sample by D_pc; failed jobs are misses in every share and +inf in the Chamfer median; GT box diagonal = the union of the GT parts' boxes at rest",
        "rows": rows,
        "scans": scans.iter().map(scan_json).collect::<Vec<_>>(),
    })
}
