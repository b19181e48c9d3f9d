//! `physnap eval guided`: the paper's Table 1 (E_pc, D_pc, E_pen, E_mob) on test scans, per variant.

use crate::cli::generate::*;
use anyhow::bail;
use clap::Args;
use physnap::engine::schedule::Schedule;
use physnap::io::manifest::load_models;
use physnap::mesh::MeshingOptions;
use physnap::model::shape_prior::LatentSdfDecoder;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub(crate) struct EvalGuidedArgs {
    /// Weights directory with manifest.json.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    pub(crate) weights: PathBuf,
    /// Test scans: a `physnap data testset` folder (testset.json gives categories) or a folder
    /// of .ply/.npy/.json clouds (no categories: category-aware rows are skipped).
    #[arg(long, env = "PHYSNAP_CLOUDS")]
    pub(crate) clouds: PathBuf,
    /// Samples per cloud and variant (paper: 15).
    #[arg(long, env = "PHYSNAP_SAMPLES_PER_CLOUD", default_value_t = 15)]
    pub(crate) samples_per_cloud: usize,
    /// Use at most this many clouds (0: all; paper: 30).
    #[arg(long, env = "PHYSNAP_MAX_CLOUDS", default_value_t = 0)]
    pub(crate) max_clouds: usize,
    /// Skip the first N clouds (then take --max-clouds). The samples keep the seeds a run over
    /// all the clouds gives them, so two slices make up one full run's samples (the per-cloud
    /// MMD / 1-NNA references after the scanned object are drawn anew and can differ).
    #[arg(long, env = "PHYSNAP_SKIP_CLOUDS", default_value_t = 0)]
    pub(crate) skip_clouds: usize,
    /// Seed of the first sample.
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    pub(crate) seed: u64,
    /// Sampler and guidance schedule.
    #[command(flatten)]
    pub(crate) sampling: SamplingArgs,
    /// Marching-cubes grid cells per axis (for D_pc).
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = physnap::mesh::DEFAULT_RESOLUTION)]
    pub(crate) resolution: usize,
    /// Output directory for guided_table.md / .json.
    #[arg(long, env = "PHYSNAP_OUT")]
    pub(crate) out: PathBuf,
    /// Imported data set (`data import` output) holding the scanned objects and the test split:
    /// enables the per-cloud MMD / 1-NNA columns and ID_gt (each sample's instantiation distance
    /// to the object its scan came from). Without it they show "—".
    #[arg(long, env = "PHYSNAP_DATA")]
    pub(crate) data: Option<PathBuf>,
    /// Reference objects per cloud for MMD / 1-NNA: the scanned object, then test objects of its
    /// category (0: as many as --samples-per-cloud).
    #[arg(long, env = "PHYSNAP_REFS_PER_CLOUD", default_value_t = 0)]
    pub(crate) refs_per_cloud: usize,
    /// Rows to run: comma-separated variants among pc+pen+mob, pc+pen, pc+mob, pc, uncond
    /// (default: all five).
    #[arg(long, env = "PHYSNAP_VARIANTS", value_delimiter = ',')]
    pub(crate) variants: Vec<String>,
    /// Category-aware blocks: no, yes, or both (both when the weights are category-conditional).
    #[arg(long, env = "PHYSNAP_CATEGORY_AWARE", default_value = "both", value_parser = ["no", "yes", "both"])]
    pub(crate) category_aware: String,
    /// Multipliers of the paper's weights of ℓ_pc, ℓ_pen and ℓ_mob in every guided row
    /// (PC,PEN,MOB; each in [0, 100]). Default: physnap's, 1,3,3 (what `generate` and the
    /// service run); 1,1,1 is the paper's table.
    #[arg(long, env = "PHYSNAP_LOSS_SCALES", value_delimiter = ',')]
    pub(crate) loss_scales: Option<Vec<f64>>,
    /// Run a hyper-parameter sweep of the supplementary material instead of Table 1: pc, pen or
    /// mob (that loss alone over --sweep-ng × --sweep-weights) or tau (ℓ_pc alone over
    /// --sweep-tau); each block starts with the unguided baseline. Writes sweep_<kind>.md/json.
    #[arg(long, env = "PHYSNAP_SWEEP", value_parser = ["pc", "pen", "mob", "tau"])]
    pub(crate) sweep: Option<String>,
    /// n_g values of a sweep (diffusion time t < n_g is guided).
    #[arg(
        long,
        env = "PHYSNAP_SWEEP_NG",
        value_delimiter = ',',
        default_value = "100,500,1000"
    )]
    pub(crate) sweep_ng: Vec<usize>,
    /// Weight multipliers of a sweep (× the loss's base weight: 45, 2, 2).
    #[arg(
        long,
        env = "PHYSNAP_SWEEP_WEIGHTS",
        value_delimiter = ',',
        default_value = "0.1,0.3,1,3,10"
    )]
    pub(crate) sweep_weights: Vec<f64>,
    /// τ values of a `--sweep tau` (paper: 10² and 10³ were the candidates).
    #[arg(
        long,
        env = "PHYSNAP_SWEEP_TAU",
        value_delimiter = ',',
        default_value = "10,100,1000,10000"
    )]
    pub(crate) sweep_tau: Vec<f64>,
    /// Joint states per object of the instantiation distance (NAP: 10).
    #[arg(long, env = "PHYSNAP_ID_STATES", default_value_t = 4)]
    pub(crate) id_states: usize,
    /// Surface points per state of the instantiation distance (NAP: 2048).
    #[arg(long, env = "PHYSNAP_ID_POINTS", default_value_t = 256)]
    pub(crate) id_points: usize,
}

pub(crate) fn eval_guided(a: EvalGuidedArgs) -> anyhow::Result<()> {
    use physnap::eval::generative::IdOptions;
    use physnap::eval::guided::{
        SweepKind, TableOptions, run_rows, sweep_rows, table_markdown, table_rows,
    };
    if a.samples_per_cloud == 0 {
        bail!("invalid --samples-per-cloud: 0 (must be at least 1)");
    }
    let sweep = a.sweep.as_deref().map(SweepKind::parse).transpose()?;
    if sweep.is_some() && !a.variants.is_empty() {
        bail!("invalid --variants with --sweep: a sweep chooses its own rows (drop one of them)");
    }
    if sweep.is_some() && a.loss_scales.is_some() {
        bail!(
            "invalid --loss-scales with --sweep: a sweep chooses its own weights (drop one of them)"
        );
    }
    let device = physnap::model::cpu();
    let models = load_models(&a.weights, &device)?;
    let clouds = read_clouds(&a.clouds, a.skip_clouds, a.max_clouds)?;
    let meshing = MeshingOptions {
        resolution: a.resolution,
    };
    meshing.validate()?;
    let conditional = models.manifest.denoiser.config.categories > 0;
    let opts = TableOptions {
        samples_per_cloud: a.samples_per_cloud,
        seed: a.seed,
        first_cloud: a.skip_clouds,
        category_aware: match a.category_aware.as_str() {
            "no" => vec![false],
            "yes" => vec![true],
            _ if conditional => vec![false, true],
            _ => vec![false],
        },
        variants: a.variants.clone(),
        guided_steps: a.sampling.n_g,
        tau: a.sampling.tau,
        loss_scales: match a.loss_scales.as_deref() {
            None => physnap::engine::guidance::DEFAULT_LOSS_SCALES,
            Some(&[pc, pen, mob]) => [pc, pen, mob],
            Some(other) => bail!(
                "invalid --loss-scales: {} values (must be three: PC,PEN,MOB)",
                other.len()
            ),
        },
        max_step: max_step(a.sampling.guidance_max_step),
        refine_steps: a.sampling.guidance_refine_steps,
        refine_physics_steps: a.sampling.guidance_refine_physics_steps,
        sampler: sampler(&a.sampling.sampler, a.sampling.eta),
        steps: a.sampling.steps,
        meshing,
        references: Vec::new(),
        scanned: Vec::new(),
        id: IdOptions {
            states: a.id_states,
            points: a.id_points,
        },
        retrieval: retrieval_mode(&a.sampling.retrieval, &models)?,
        category_guidance: a.sampling.category.category_guidance,
        category_guidance_below: a.sampling.category.category_guidance_below,
        joint_motion: joint_motion(&a.sampling.joint_motion)?,
    };
    opts.id.validate()?;
    let per_cloud = if a.refs_per_cloud == 0 {
        a.samples_per_cloud
    } else {
        a.refs_per_cloud
    };
    let opts = match &a.data {
        Some(data) => {
            eprintln!(
                "preparing up to {per_cloud} reference objects per cloud from {}…",
                data.display()
            );
            let (references, scanned) =
                super::cloud_references(data, &clouds, per_cloud, &opts.id, a.seed)?;
            TableOptions {
                references,
                scanned,
                ..opts
            }
        }
        None => opts,
    };
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    if a.category_aware == "yes" && !conditional {
        bail!("invalid --category-aware yes: the weights' denoiser has no category input");
    }
    let specs = match sweep {
        Some(kind) => sweep_rows(
            kind,
            &opts.category_aware,
            &a.sweep_ng,
            &a.sweep_weights,
            &a.sweep_tau,
            a.sampling.n_g,
            a.sampling.tau,
        )?,
        None => table_rows(&opts)?,
    };
    let pb = super::progress_bar(
        specs.len() * clouds.len() * a.samples_per_cloud,
        "eval guided",
    );
    let on_sample = &mut |done: usize, _: usize| pb.set_position(done as u64);
    let rows = run_rows(
        &models.denoiser,
        &decoder,
        models.codebook.as_ref(),
        &models.manifest.feature_scales,
        &Schedule::default(),
        &clouds,
        &opts,
        &specs,
        on_sample,
    )?;
    pb.finish_and_clear();
    let stem = match sweep {
        Some(kind) => format!("sweep_{}", kind.name()),
        None => "guided_table".to_string(),
    };
    let md = table_markdown(&rows);
    print!("{md}");
    std::fs::create_dir_all(&a.out)?;
    std::fs::write(a.out.join(format!("{stem}.md")), &md)?;
    let num = |v: f64| {
        if v.is_finite() {
            serde_json::json!(v)
        } else {
            serde_json::Value::Null
        }
    };
    let sample_json = |s: &physnap::eval::guided::SampleRecord| {
        let m = |i: usize| s.metrics.map(|m| num(m[i]));
        serde_json::json!({
            "cloud": s.cloud, "seed": s.seed, "seconds": s.seconds, "diverged": s.metrics.is_none(),
            "e_pc": m(0), "d_pc": m(1), "e_pen": m(2), "e_mob": m(3), "o_mesh": m(4),
            "id_gt": s.id_gt.map(num),
        })
    };
    let row_json = |r: &physnap::eval::guided::TableRow| {
        let mut v = serde_json::json!({
            "category_aware": r.category_aware, "variant": r.variant,
            "guidance": r.guidance.map(|g| serde_json::json!({
                "w_pc": g.w_pc, "w_pen": g.w_pen, "w_mob": g.w_mob, "n_g": g.steps, "tau": g.tau,
            })),
            "e_pc": num(r.e_pc), "d_pc": num(r.d_pc), "e_pen": num(r.e_pen), "e_mob": num(r.e_mob),
            "e_pen_mean": num(r.e_pen_mean), "e_mob_mean": num(r.e_mob_mean),
            "pen_share": num(r.pen_share), "mob_share": num(r.mob_share),
            "o_mesh_mean": num(r.o_mesh_mean), "o_mesh_share": num(r.o_mesh_share),
            "mmd": num(r.mmd), "one_nna": num(r.one_nna),
            "samples": r.samples, "diverged": r.diverged, "seconds_per_sample": r.seconds_per_sample,
            "per_sample": r.per_sample.iter().map(sample_json).collect::<Vec<_>>(),
        });
        // Set apart: two more keys inside the json! above exceed the macro's recursion limit.
        v["id_gt"] = num(r.id_gt);
        v["id_gt_mean"] = num(r.id_gt_mean);
        v["category_guidance"] = r.category_guidance.map(|(w, _)| w).into();
        v["category_guidance_below"] = r.category_guidance.map(|(_, b)| b).into();
        v
    };
    let json = serde_json::json!({
        "format": "physnap.guided_table/v1",
        "clouds": clouds.iter().map(|c| c.id.clone()).collect::<Vec<_>>(),
        "samples_per_cloud": a.samples_per_cloud,
        "skip_clouds": a.skip_clouds,
        "command": std::env::args().collect::<Vec<_>>().join(" "),
        "seed": a.seed, "n_g": a.sampling.n_g, "tau": a.sampling.tau,
        "guidance_max_step": opts.max_step, "guidance_refine_steps": opts.refine_steps,
        "guidance_refine_physics_steps": opts.refine_physics_steps,
        "loss_scales": opts.loss_scales,
        "sampler": a.sampling.sampler, "steps": a.sampling.steps, "eta": a.sampling.eta,
        // The flags as given (null: each row's default, recorded in the row).
        "category_guidance": a.sampling.category.category_guidance,
        "category_guidance_below": a.sampling.category.category_guidance_below,
        "retrieval": opts.retrieval.as_str(), "joint_motion": a.sampling.joint_motion,
        "statistic": "E_* and D_pc: median over all samples; MMD and 1-NNA: per cloud (its samples vs its references), median over clouds; ID_gt: each sample's instantiation distance to the scanned object, median and mean over samples",
        "references": a.data.as_ref().map(|d| serde_json::json!({
            "data": d.display().to_string(), "per_cloud": per_cloud,
            "id_states": a.id_states, "id_points": a.id_points,
        })),
        "sweep": a.sweep,
        "rows": rows.iter().map(row_json).collect::<Vec<_>>(),
    });
    std::fs::write(
        a.out.join(format!("{stem}.json")),
        serde_json::to_string_pretty(&json)? + "\n",
    )?;
    println!("table: {}", a.out.join(format!("{stem}.md")).display());
    Ok(())
}
