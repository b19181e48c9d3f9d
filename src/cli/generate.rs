//! `physnap generate`: sample the prior (guided by a scan when one is given), export every
//! sample and rank them into `ranking.json`. The sampling flags here are shared with
//! `physnap eval guided`.

use anyhow::{Context, bail};
use clap::Args;
use physnap::data::categories::category_index;
use physnap::engine::EngineError;
use physnap::engine::generate::{
    GenerateRequest, JointMotion, PartShapes, RepairMode, Retrieval, auto_scale,
    generate_with as run_generate,
};
use physnap::engine::guidance::{GuidanceOptions, SdfField};
use physnap::engine::sample::Sampler;
use physnap::engine::schedule::Schedule;
use physnap::eval::guided::metrics as guided_metrics;
use physnap::export::{ExportOptions, export_dir_with_repairs};
use physnap::io::manifest::{LoadedModels, load_models};
use physnap::mesh::MeshingOptions;
use physnap::model::shape_prior::LatentSdfDecoder;
use physnap::pointcloud::{Limits, PointCloud};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

#[derive(Args, Debug)]
pub(crate) struct GenerateArgs {
    /// Weights directory with manifest.json.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    pub(crate) weights: PathBuf,
    /// Category (e.g. StorageFurniture); omit for unconditional generation.
    #[arg(long, env = "PHYSNAP_CATEGORY")]
    pub(crate) category: Option<String>,
    /// Number of samples.
    #[arg(long, env = "PHYSNAP_SAMPLES", default_value_t = 1)]
    pub(crate) samples: usize,
    /// Seed of the first sample (sample i uses seed + i).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    pub(crate) seed: u64,
    /// Output directory (one sample_NNN folder per sample).
    #[arg(long, env = "PHYSNAP_OUT")]
    pub(crate) out: PathBuf,
    /// Marching-cubes grid cells per axis.
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = physnap::mesh::DEFAULT_RESOLUTION)]
    pub(crate) resolution: usize,
    /// Observed partial point cloud (PLY, NPY or JSON; object frame, metres): PhysNAP guidance
    /// (pc+pen+mob by default), samples ranked by D_pc into ranking.json.
    #[arg(long, env = "PHYSNAP_POINTS")]
    pub(crate) points: Option<PathBuf>,
    /// Weight of the point-cloud loss (default with --points: 45 ÷ active terms).
    #[arg(
        long,
        help_heading = "Guidance weights",
        hide_short_help = true,
        env = "PHYSNAP_W_PC"
    )]
    pub(crate) w_pc: Option<f64>,
    /// Weight of the penetration loss (default with --points: physnap's 3 × the paper's 2 ÷
    /// active terms, 2 for pc+pen+mob; 0 turns it off).
    #[arg(
        long,
        help_heading = "Guidance weights",
        hide_short_help = true,
        env = "PHYSNAP_W_PEN"
    )]
    pub(crate) w_pen: Option<f64>,
    /// Weight of the mobility loss (default with --points: physnap's 3 × the paper's 2 ÷ active
    /// terms, 2 for pc+pen+mob; 0 turns it off).
    #[arg(
        long,
        help_heading = "Guidance weights",
        hide_short_help = true,
        env = "PHYSNAP_W_MOB"
    )]
    pub(crate) w_mob: Option<f64>,
    /// Sensor position x,y,z (object frame, metres) the scan was taken from; repeat the flag
    /// (or separate with ';' in PHYSNAP_CAMERA) for several views. Turns on the free-space loss
    /// ℓ_free and the removal of parts in space the camera saw through.
    #[arg(
        long = "camera",
        env = "PHYSNAP_CAMERA",
        value_delimiter = ';',
        value_name = "X,Y,Z",
        allow_hyphen_values = true
    )]
    pub(crate) cameras: Vec<String>,
    /// Weight of the free-space loss (default with --camera: 15, ℓ_pc's; 0 turns it off).
    #[arg(
        long,
        help_heading = "Guidance weights",
        hide_short_help = true,
        env = "PHYSNAP_W_FREE"
    )]
    pub(crate) w_free: Option<f64>,
    /// Joint repair and part removal: on (default: hinges onto their part's edge or centre
    /// line, axes snapped to box axes, children attached, parts the scan does not allow
    /// removed; listed in object.json and ranking.json) or off (the raw projection).
    #[arg(long, env = "PHYSNAP_REPAIR", default_value = "on", value_parser = ["on", "off"])]
    pub(crate) repair: String,
    /// Scale hypothesis: auto (default: the scan is scaled so its size is the category's
    /// typical size in the training data, the result scaled back), off, or a factor.
    #[arg(long, env = "PHYSNAP_SCALE", default_value = "auto")]
    pub(crate) scale: String,
    /// The scan's frame: canonical (default: the points are in physnap's frame, +Z up, front
    /// −X, floor z = 0) or auto (any right-handed metric frame with up --up: the floor, yaw and
    /// position are estimated, the model is returned in the scan's frame).
    #[arg(long, env = "PHYSNAP_FRAME", default_value = "canonical", value_parser = ["canonical", "auto"])]
    pub(crate) frame: String,
    /// The scan's up direction x,y,z with --frame auto (default 0,0,1).
    #[arg(
        long,
        env = "PHYSNAP_UP",
        default_value = "0,0,1",
        value_name = "X,Y,Z",
        allow_hyphen_values = true
    )]
    pub(crate) up: String,
    /// Quality preset: fast (100 reverse steps, meshing resolution 24: about half the time,
    /// a little coarser surfaces) or standard (the defaults below). A flag or environment
    /// variable given explicitly wins over the preset. (There is no "best": best of 4 by the
    /// ranking score scored worse than one sample on the real-asset benchmark.)
    #[arg(long, env = "PHYSNAP_QUALITY", default_value = "standard", value_parser = ["fast", "standard"])]
    pub(crate) quality: String,
    /// Sampler and guidance schedule.
    #[command(flatten)]
    pub(crate) sampling: SamplingArgs,
}

/// What a `--quality` preset sets: (reverse steps, meshing resolution); None keeps the flag's
/// default.
fn quality_preset(name: &str) -> (Option<usize>, Option<usize>) {
    match name {
        "fast" => (Some(100), Some(24)),
        _ => (None, None),
    }
}

impl GenerateArgs {
    /// Applies `--quality` to the flags `matches` (this subcommand's) holds at their defaults.
    pub(crate) fn apply_quality(&mut self, matches: &clap::ArgMatches) {
        let default =
            |id: &str| matches.value_source(id) == Some(clap::parser::ValueSource::DefaultValue);
        let (steps, resolution) = quality_preset(&self.quality);
        if let (Some(v), true) = (steps, default("steps")) {
            self.sampling.steps = v;
        }
        if let (Some(v), true) = (resolution, default("resolution")) {
            self.resolution = v;
        }
    }
}

/// `--up x,y,z` as a vector (the estimate checks it is finite and non-zero).
pub(crate) fn parse_up(v: &str) -> anyhow::Result<[f64; 3]> {
    physnap::frame::parse_xyz(v)
        .with_context(|| format!("invalid --up {v:?}: expected x,y,z (three numbers)"))
}

/// The `--frame` / `--up` flags for the scan of `guidance`: None for canonical, else the
/// engine's estimate (needs --points).
pub(crate) fn frame_estimate(
    mode: &str,
    up: &str,
    guidance: Option<&GuidanceOptions>,
) -> anyhow::Result<Option<physnap::engine::frame::FrameEstimate>> {
    if mode != "auto" {
        return Ok(None);
    }
    let up = parse_up(up)?;
    let Some(g) = guidance.filter(|g| !g.points.is_empty()) else {
        bail!("invalid --frame auto: needs --points (the scan whose frame is estimated)");
    };
    let est = physnap::engine::frame::estimate(&g.points, up, &g.cameras)
        .map_err(|e| anyhow::anyhow!("--frame auto: {e}"))?;
    Ok(Some(est))
}

/// The scale flag against the scan in the canonical frame (`est`'s when auto).
fn canonical_points(
    guidance: Option<&GuidanceOptions>,
    est: Option<&physnap::engine::frame::FrameEstimate>,
) -> Vec<[f32; 3]> {
    let points = guidance.map_or(&[][..], |g| &g.points[..]);
    match est {
        Some(e) => e.frame.points_to_canonical(points),
        None => points.to_vec(),
    }
}

/// The `--scale` flag for a scan of `points` (empty: no scan) of `category`: auto is the
/// engine's [`auto_scale`] with the procedural generator's typical size, off is None.
pub(crate) fn scale_of(
    flag: &str,
    points: &[[f32; 3]],
    category: Option<&str>,
) -> anyhow::Result<Option<f64>> {
    match flag {
        "off" => Ok(None),
        "auto" => Ok(auto_scale(
            points,
            Some(physnap::data::synth::prior_diagonal(category)),
        )),
        v => {
            let s: f64 = v
                .parse()
                .ok()
                .filter(|s: &f64| s.is_finite())
                .with_context(|| {
                    format!("invalid --scale {v:?}: expected auto, off or a finite number")
                })?;
            Ok(Some(s))
        }
    }
}

/// `--camera` values ("x,y,z" each) as points.
pub(crate) fn parse_cameras(values: &[String]) -> anyhow::Result<Vec<[f32; 3]>> {
    values
        .iter()
        .map(|v| {
            let c: Vec<f32> = v
                .split(',')
                .map(|x| x.trim().parse::<f32>())
                .collect::<Result<_, _>>()
                .ok()
                .filter(|c: &Vec<f32>| c.len() == 3 && c.iter().all(|x| x.is_finite()))
                .with_context(|| {
                    format!("invalid --camera {v:?}: expected x,y,z (three finite numbers, metres)")
                })?;
            Ok([c[0], c[1], c[2]])
        })
        .collect()
}

/// The `--repair` flag (clap has checked the name).
pub(crate) fn repair_mode(flag: &str) -> RepairMode {
    RepairMode::parse(flag).unwrap_or(RepairMode::On)
}

/// The category-guidance flag of every command that samples locally.
#[derive(Args, Debug)]
#[command(next_help_heading = "Category guidance")]
pub(crate) struct CategoryGuidanceArgs {
    /// Classifier-free category guidance w for category-conditioned samples:
    /// ε̂ = ε̂(c) + w·(ε̂(c) − ε̂(∅)) (0: plain conditioning; > 0 doubles the denoiser's work).
    /// Default: 2 without loss guidance, 0 when a scan guides the sample (w = 2 completed scans
    /// worse).
    #[arg(long, hide_short_help = true, env = "PHYSNAP_CATEGORY_GUIDANCE")]
    pub(crate) category_guidance: Option<f64>,
    /// Apply the category guidance only in steps with diffusion time t below this, 1-1000;
    /// above it the plain conditional prediction is used (one forward). Default: 500 without
    /// loss guidance, 1000 (every step) when a scan guides the sample.
    #[arg(long, hide_short_help = true, env = "PHYSNAP_CATEGORY_GUIDANCE_BELOW")]
    pub(crate) category_guidance_below: Option<usize>,
}

impl CategoryGuidanceArgs {
    /// `--category-guidance`, or its default for a sample with or without loss guidance.
    pub(crate) fn weight(&self, loss_guided: bool) -> f64 {
        physnap::engine::sample::category_guidance(self.category_guidance, loss_guided)
    }

    /// `--category-guidance-below`, or its default for a sample with or without loss guidance.
    pub(crate) fn below(&self, loss_guided: bool) -> usize {
        physnap::engine::sample::category_guidance_below(self.category_guidance_below, loss_guided)
    }
}

/// Sampler and guidance-schedule flags shared by `generate` and `eval guided`.
#[derive(Args, Debug)]
#[command(next_help_heading = "Sampling and guidance schedule")]
pub(crate) struct SamplingArgs {
    /// n_g, as in the paper: guide the reverse steps with diffusion time t < this (0-1000; the
    /// REST and gRPC field `n_g` is the same number).
    #[arg(long = "n-g", alias = "guidance-steps", hide_short_help = true, env = "PHYSNAP_N_G", default_value_t = physnap::engine::guidance::DEFAULT_GUIDED_STEPS)]
    pub(crate) n_g: usize,
    /// Temperature τ of the point-to-part soft assignment.
    #[arg(long, hide_short_help = true, env = "PHYSNAP_TAU", default_value_t = physnap::engine::guidance::DEFAULT_TAU)]
    pub(crate) tau: f64,
    /// Clamp each guidance-gradient entry to ±this (model space); a deviation from the paper's
    /// raw gradient, which diverges with the shipped weights. 0: off (the paper's raw step).
    #[arg(long, hide_short_help = true, env = "PHYSNAP_GUIDANCE_MAX_STEP", default_value_t = physnap::engine::guidance::DEFAULT_MAX_STEP)]
    pub(crate) guidance_max_step: f64,
    /// Refinement: small clamped gradient steps (a tenth of --guidance-max-step) on the guidance
    /// loss of the finished sample (physnap, not in the paper; 0: off).
    #[arg(long, hide_short_help = true, env = "PHYSNAP_GUIDANCE_REFINE_STEPS", default_value_t = physnap::engine::guidance::DEFAULT_REFINE_STEPS)]
    pub(crate) guidance_refine_steps: usize,
    /// Physics-only refinement: this many more such steps after those, on ℓ_pen and ℓ_mob alone
    /// (ℓ_pc off), which push out the small overlaps ℓ_pc holds in place (physnap; 0: off).
    #[arg(long, hide_short_help = true, env = "PHYSNAP_GUIDANCE_REFINE_PHYSICS_STEPS", default_value_t = physnap::engine::guidance::DEFAULT_REFINE_PHYSICS_STEPS)]
    pub(crate) guidance_refine_physics_steps: usize,
    /// Reverse-step rule: ddim (default) or ddpm (NAP; strided ancestral with --steps < 1000).
    /// The paper's sampler is `--sampler ddpm --steps 0`.
    #[arg(long, hide_short_help = true, env = "PHYSNAP_SAMPLER", default_value = "ddim", value_parser = ["ddpm", "ddim"])]
    pub(crate) sampler: String,
    /// Reverse steps (0: all 1000). Guidance applies to those with t < --n-g.
    #[arg(long, hide_short_help = true, env = "PHYSNAP_STEPS", default_value_t = physnap::engine::sample::DEFAULT_STEPS)]
    pub(crate) steps: usize,
    /// DDIM noise level η in [0, 1].
    #[arg(
        long,
        hide_short_help = true,
        env = "PHYSNAP_DDIM_ETA",
        default_value_t = 0.0
    )]
    pub(crate) eta: f64,
    /// Replace part shapes by their nearest training code of the weights' codebook: auto
    /// (empty shapes when the weights have a codebook, else off), off, empty (shapes that mesh
    /// empty), all (every latent shape: NAP's retrieval variant), category (every latent shape
    /// of a category-conditioned sample, from that category's codes; samples without a
    /// category: as empty).
    #[arg(long, hide_short_help = true, env = "PHYSNAP_RETRIEVAL", default_value = "auto", value_parser = ["auto", "off", "empty", "all", "category"])]
    pub(crate) retrieval: String,
    /// Joint motions of the projected samples: dominant (default: each joint keeps only its
    /// wider range, in units of the feature scales, so it rotates, slides or is fixed) or
    /// screw (NAP: both ranges kept).
    #[arg(long, hide_short_help = true, env = "PHYSNAP_JOINT_MOTION", default_value = "dominant", value_parser = ["screw", "dominant"])]
    pub(crate) joint_motion: String,
    /// Category guidance.
    #[command(flatten)]
    pub(crate) category: CategoryGuidanceArgs,
}

impl SamplingArgs {
    /// The guidance these flags give for `points` and the resolved `[w_pc, w_pen, w_mob]`
    /// (not yet validated against a schedule).
    pub(crate) fn guidance(
        &self,
        points: Vec<[f32; 3]>,
        [w_pc, w_pen, w_mob]: [f64; 3],
    ) -> GuidanceOptions {
        GuidanceOptions {
            points,
            w_pc,
            w_pen,
            w_mob,
            cameras: Vec::new(),
            w_free: 0.0,
            steps: self.n_g,
            tau: self.tau,
            max_step: max_step(self.guidance_max_step),
            refine_steps: self.guidance_refine_steps,
            refine_physics_steps: self.guidance_refine_physics_steps,
        }
    }
}

/// `--guidance-max-step` to the engine's option: 0 turns the clamp off (the paper's raw step);
/// other values, negative ones included, go to the engine, which validates them.
pub(crate) fn max_step(flag: f64) -> Option<f64> {
    (flag != 0.0).then_some(flag)
}

/// The `--retrieval` flag against the loaded weights: `auto` is `empty` with a codebook and
/// `off` without one; `empty` / `all` without a codebook are refused.
pub(crate) fn retrieval_mode(flag: &str, models: &LoadedModels) -> anyhow::Result<Retrieval> {
    let has = models.codebook.is_some();
    match (flag, Retrieval::parse(flag)) {
        ("auto", _) => Ok(Retrieval::auto(has)),
        (_, Some(Retrieval::Off)) => Ok(Retrieval::Off),
        (_, Some(r)) if has => Ok(r),
        (_, Some(_)) => bail!(
            "invalid --retrieval {flag:?}: these weights have no codebook (manifest.json has no \"codebook\" entry); add one with `physnap train codebook` or use --retrieval off"
        ),
        (_, None) => {
            bail!("invalid --retrieval {flag:?} (must be auto, off, empty, all or category)")
        }
    }
}

/// The `--joint-motion` flag.
pub(crate) fn joint_motion(flag: &str) -> anyhow::Result<JointMotion> {
    JointMotion::parse(flag)
        .with_context(|| format!("invalid --joint-motion {flag:?} (must be screw or dominant)"))
}

/// The `--sampler` / `--eta` flags (`ddim` or `ddpm`; clap has checked the name).
pub(crate) fn sampler(name: &str, eta: f64) -> Sampler {
    match name {
        "ddim" => Sampler::Ddim { eta },
        _ => Sampler::Ddpm,
    }
}

pub(crate) fn generate(a: GenerateArgs) -> anyhow::Result<()> {
    let manifest_path = a.weights.join("manifest.json");
    if !manifest_path.is_file() {
        bail!(
            "no trained weights at {} (train them with `physnap train shape` and `physnap train diffusion`, see README)",
            manifest_path.display()
        );
    }
    let device = physnap::model::cpu();
    let models = load_models(&a.weights, &device)?;
    let category = match &a.category {
        None => None,
        Some(c) => {
            let idx = category_index(c)
                .filter(|&i| i < models.manifest.categories.len())
                .with_context(|| {
                    format!(
                        "invalid --category {c:?} (must be one of: {})",
                        models.manifest.categories.join(", ")
                    )
                })?;
            if models.manifest.denoiser.config.categories == 0 {
                bail!("invalid --category {c:?}: these weights are unconditional");
            }
            Some(idx)
        }
    };
    if a.samples == 0 {
        bail!("invalid --samples: 0 (must be at least 1)");
    }
    let guidance = guidance_options(&a)?;
    let loss_guided = guidance.as_ref().is_some_and(|g| g.is_active());
    let estimate = frame_estimate(&a.frame, &a.up, guidance.as_ref())?;
    if let Some(e) = &estimate {
        println!("{}", physnap::io::verdict::frame_summary(e));
    }
    let sampler = sampler(&a.sampling.sampler, a.sampling.eta);
    let req = GenerateRequest {
        seed: a.seed,
        samples: a.samples,
        category,
        category_name: category.map(|i| models.manifest.categories[i].clone()),
        meshing: MeshingOptions {
            resolution: a.resolution,
        },
        guidance: guidance.clone(),
        sampler,
        steps: a.sampling.steps,
        retrieval: retrieval_mode(&a.sampling.retrieval, &models)?,
        category_guidance: a.sampling.category.weight(loss_guided),
        category_guidance_below: Some(a.sampling.category.below(loss_guided)),
        joint_motion: joint_motion(&a.sampling.joint_motion)?,
        repair: repair_mode(&a.repair),
        scale: scale_of(
            &a.scale,
            &canonical_points(guidance.as_ref(), estimate.as_ref()),
            category.map(|i| models.manifest.categories[i].as_str()),
        )?,
        frame: estimate.as_ref().map(|e| e.frame),
        ..Default::default()
    };
    // What the samples are ranked against: the scan in the canonical frame they come out in.
    let ranked_against = physnap::engine::generate::canonical_guidance(&req);
    req.meshing.validate()?;
    let schedule = Schedule::default();
    let steps = physnap::engine::schedule::timesteps(schedule.len(), a.sampling.steps).len();
    let pb = super::progress_bar(a.samples * steps, "generate");
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let started = std::time::Instant::now();
    let mut last_losses = None;
    // One request per sample (sample i uses seed + i either way), so a guided sample that
    // diverges is reported and the others still count for best-of-N.
    let mut results = Vec::new();
    let mut diverged = Vec::new();
    for i in 0..a.samples {
        let one = GenerateRequest {
            seed: a.seed.wrapping_add(i as u64),
            samples: 1,
            ..req.clone()
        };
        let shapes = PartShapes {
            decoder: &decoder,
            field: Some(&decoder as &dyn SdfField),
            codebook: models.codebook.as_ref(),
        };
        let r = run_generate(
            &models.denoiser,
            &shapes,
            &models.manifest.feature_scales,
            &schedule,
            &one,
            &mut |e| {
                pb.set_position((i * e.step.total + e.step.step) as u64);
                if let Some(l) = e.step.guidance {
                    last_losses = Some(l);
                }
                ControlFlow::Continue(())
            },
        );
        match r {
            Ok(mut out) => {
                let mut g = out.remove(0);
                g.index = i;
                g.object.name = format!("sample_{i:03}");
                results.push(g);
            }
            Err(e @ EngineError::Diverged { .. }) => {
                pb.println(format!("sample_{i:03} (seed {}): {e}", one.seed));
                diverged.push((format!("sample_{i:03}"), one.seed, e.to_string()));
            }
            Err(e) => return Err(e.into()),
        }
    }
    pb.finish_and_clear();
    if results.is_empty() {
        bail!(
            "all {} samples diverged (first: {}); lower the guidance weights (--w-pc/--w-pen/--w-mob) or --n-g",
            a.samples,
            diverged.first().map(|d| d.2.as_str()).unwrap_or("")
        );
    }
    let per_sample = started.elapsed().as_secs_f64() / a.samples as f64;
    let opts = ExportOptions {
        meshing: req.meshing,
        frame: req.frame,
        ..Default::default()
    };
    let mut rows = Vec::new();
    for g in &results {
        let name = format!("sample_{:03}", g.index);
        let dir = a.out.join(&name);
        let report = export_dir_with_repairs(&g.object, &g.meshes, &g.repairs, &dir, &opts)?;
        println!(
            "{}: {} parts, {} joints (seed {})",
            dir.display(),
            g.object.parts.len(),
            g.object.joints.len(),
            g.seed
        );
        println!(
            "  {}",
            crate::cli::check_sim::summary(&g.object, &report.sim)
        );
        for note in &report.notes {
            println!("  note: {note}");
        }
        for r in &g.repairs {
            println!("  repair {} {}: {}", r.child, r.rule.as_str(), r.detail);
        }
        for r in &g.removed {
            println!("  removed {} ({}): {}", r.part, r.reason.as_str(), r.detail);
        }
        if !g.retrieved.is_empty() {
            println!(
                "  parts {:?} took their nearest codebook shape (--retrieval {})",
                g.retrieved,
                req.retrieval.as_str()
            );
        }
        if let Some(opts) = &ranked_against {
            let m = guided_metrics(
                &decoder,
                &g.raw,
                &g.object,
                &g.meshes,
                &opts.points,
                g.scale,
                g.seed,
            );
            let terms = physnap::eval::rank::rank_terms(
                &g.object,
                &g.meshes,
                &opts.points,
                &opts.cameras,
                m.d_pc,
                m.o_mesh,
            );
            rows.push(RankRow {
                name,
                seed: g.seed,
                metrics: m,
                terms_json: physnap::io::verdict::terms_json(&g.object, &terms),
                terms,
                changes: changes_json(g),
            });
        }
    }
    println!("{per_sample:.1} s per sample (sampling + meshing)");
    if let Some(l) = last_losses {
        println!(
            "last guided step: ℓ_pc {:.4e}, ℓ_pen {:.4e}, ℓ_mob {:.4e}, ℓ_free {:.4e}, weighted {:.4e}",
            l.pc, l.pen, l.mob, l.free, l.total
        );
    }
    if let (Some(opts), Some(points)) = (&ranked_against, &a.points) {
        write_ranking(&a.out, points, opts, rows, &diverged, estimate.as_ref())?;
    }
    Ok(())
}

/// The guidance of `generate`: paper defaults for the terms that are on, flags override.
pub(crate) fn guidance_options(a: &GenerateArgs) -> anyhow::Result<Option<GuidanceOptions>> {
    let points = match &a.points {
        Some(path) => {
            let cloud = PointCloud::read(
                path,
                &Limits {
                    min_points: 1,
                    max_points: physnap::engine::guidance::MAX_POINTS,
                },
            )
            .with_context(|| format!("invalid --points {}", path.display()))?;
            cloud.points
        }
        None => Vec::new(),
    };
    if points.is_empty() && a.w_pc.is_some_and(|w| w > 0.0) {
        bail!("invalid --w-pc: needs --points (the observed point cloud)");
    }
    let cameras = parse_cameras(&a.cameras)?;
    if points.is_empty() && !cameras.is_empty() {
        bail!("invalid --camera: needs --points (the scan the camera took)");
    }
    if points.is_empty() && a.w_pen.is_none() && a.w_mob.is_none() {
        return Ok(None);
    }
    let weights =
        GuidanceOptions::weights_or_defaults([a.w_pc, a.w_pen, a.w_mob], !points.is_empty());
    let opts = a
        .sampling
        .guidance(points, weights)
        .with_cameras(cameras, a.w_free);
    opts.validate(Schedule::default().len())?;
    Ok(Some(opts))
}

/// One sample of `ranking.json`.
pub(crate) struct RankRow {
    pub(crate) name: String,
    pub(crate) seed: u64,
    pub(crate) metrics: physnap::eval::guided::GuidedMetrics,
    pub(crate) terms: physnap::eval::rank::RankTerms,
    /// The terms as `ranking.json` lists them (`io::verdict::terms_json`).
    pub(crate) terms_json: serde_json::Value,
    /// `repairs` and `removed` (see [`changes_json`]).
    pub(crate) changes: serde_json::Value,
}

/// What repair changed in a sample: the number of joint repairs (object.json lists them) and
/// the removed parts with their reason.
pub(crate) fn changes_json(g: &physnap::engine::generate::Generated) -> serde_json::Value {
    serde_json::json!({
        "repairs": g.repairs.len(),
        "removed": g.removed.iter().map(|r| serde_json::json!({
            "part": r.part, "reason": r.reason.as_str(), "detail": r.detail,
        })).collect::<Vec<_>>(),
    })
}

/// `ranking.json`: samples by ascending score (`eval::rank`), the best one marked, each with
/// its terms.
pub(crate) fn write_ranking(
    out: &Path,
    points: &Path,
    opts: &GuidanceOptions,
    rows: Vec<RankRow>,
    diverged: &[(String, u64, String)],
    frame: Option<&physnap::engine::frame::FrameEstimate>,
) -> anyhow::Result<()> {
    // Rows come in sample order (sample_000, sample_001, ...), so ties stay in name order.
    let rows = physnap::eval::rank::ranked(rows, |r| r.terms.score());
    let num = |v: f64| {
        if v.is_finite() {
            serde_json::json!(v)
        } else {
            serde_json::Value::Null
        }
    };
    let ranked: Vec<serde_json::Value> = rows
        .iter()
        .enumerate()
        .map(|(r, row)| {
            let m = &row.metrics;
            let mut v = serde_json::json!({
                "rank": r + 1,
                "sample": row.name,
                "seed": row.seed,
                "best": r == 0,
                "d_pc": num(m.d_pc),
                "e_pc": num(m.e_pc),
                "e_pen": num(m.e_pen),
                "e_mob": num(m.e_mob),
                "o_mesh": num(m.o_mesh),
                "score": num(row.terms.score()),
                "terms": row.terms_json,
            });
            if let (Some(v), Some(c)) = (v.as_object_mut(), row.changes.as_object()) {
                v.extend(c.clone());
            }
            v
        })
        .collect();
    let best = rows.first().map(|r| r.name.clone());
    let mut doc = serde_json::json!({
        "format": "physnap.ranking/v1",
        "points": points.display().to_string(),
        "ranked_by": "score = D_pc / scan diagonal + free-space share + attachment gap / object diagonal + O_mesh + sim contact depth / object diagonal (lower is better)",
        "guidance": {
            "w_pc": opts.w_pc, "w_pen": opts.w_pen, "w_mob": opts.w_mob, "w_free": opts.w_free,
            "cameras": opts.cameras, "n_g": opts.steps, "tau": opts.tau,
        },
        "best": best,
        "samples": ranked,
        "diverged": diverged.iter().map(|(name, seed, error)| serde_json::json!({
            "sample": name, "seed": seed, "error": error,
        })).collect::<Vec<_>>(),
    });
    if let (Some(e), Some(d)) = (frame, doc.as_object_mut()) {
        d.insert("frame".into(), physnap::io::verdict::frame_json(e));
    }
    let path = out.join("ranking.json");
    std::fs::write(&path, serde_json::to_string_pretty(&doc)? + "\n")?;
    for (r, row) in rows.iter().enumerate() {
        let m = &row.metrics;
        println!(
            "{}{}: score {:.4} D_pc {:.4} free {:.3} attach {:.4} O_mesh {:.3} E_pc {:.5} E_pen {:.5} E_mob {:.5}",
            if r == 0 { "best " } else { "     " },
            row.name,
            row.terms.score(),
            m.d_pc,
            row.terms.free,
            row.terms.attach,
            m.o_mesh,
            m.e_pc,
            m.e_pen,
            m.e_mob
        );
    }
    println!("ranking: {}", path.display());
    Ok(())
}

/// Clouds of `dir`: from testset.json when present (with categories), else every cloud file.
pub(crate) fn read_clouds(
    dir: &Path,
    skip: usize,
    max: usize,
) -> anyhow::Result<Vec<physnap::eval::guided::Cloud>> {
    let limits = Limits {
        min_points: 1,
        max_points: physnap::engine::guidance::MAX_POINTS,
    };
    let index = dir.join("testset.json");
    let mut entries: Vec<(String, Option<usize>, std::path::PathBuf)> = Vec::new();
    if index.is_file() {
        let doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&index)?)
            .with_context(|| format!("parsing {}", index.display()))?;
        for c in doc["clouds"].as_array().into_iter().flatten() {
            let id = c["id"].as_str().unwrap_or_default().to_string();
            let file = c["cloud"].as_str().with_context(|| {
                format!("{}: cloud entry without a \"cloud\" file", index.display())
            })?;
            let category = c["category"].as_str().and_then(category_index);
            entries.push((id, category, dir.join(file)));
        }
    } else {
        let mut files: Vec<_> = std::fs::read_dir(dir)
            .with_context(|| format!("invalid --clouds {}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| physnap::pointcloud::Format::from_path(p).is_some())
            .collect();
        files.sort();
        for p in files {
            let id = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            entries.push((id, None, p));
        }
    }
    let available = entries.len();
    if skip > 0 {
        if skip >= available {
            bail!(
                "invalid --skip-clouds: {skip} (must be below the {available} clouds in {})",
                dir.display()
            );
        }
        entries.drain(..skip);
    }
    if max > 0 {
        entries.truncate(max);
    }
    if entries.is_empty() {
        bail!(
            "invalid --clouds {}: no point clouds (must hold testset.json or .ply/.npy/.json files)",
            dir.display()
        );
    }
    entries
        .into_iter()
        .map(|(id, category, path)| {
            let cloud = PointCloud::read(&path, &limits)
                .with_context(|| format!("reading {}", path.display()))?;
            Ok(physnap::eval::guided::Cloud {
                id,
                category,
                points: cloud.points,
            })
        })
        .collect()
}
