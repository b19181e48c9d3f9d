//! `physnap eval generative`: validity, MMD / COV / 1-NNA and category accuracy of unguided samples.

use super::*;
use crate::cli::generate::CategoryGuidanceArgs;
use anyhow::{Context, bail};
use clap::Args;
use physnap::data::categories::category_index;
use physnap::engine::generate::{GenerateRequest, Generated, Retrieval, generate as run_generate};
use physnap::engine::schedule::Schedule;
use physnap::eval::generative::{
    IdOptions, MetricOrder, StateClouds, distance_matrix, distribution_metrics, invalid_reason,
    state_clouds,
};
use physnap::io::manifest::{LoadedModels, load_models};
use physnap::mesh::MeshingOptions;
use physnap::model::shape_prior::LatentSdfDecoder;
use rayon::prelude::*;
use serde_json::json;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub(crate) struct EvalGenerativeArgs {
    /// Weights directory with manifest.json.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    pub(crate) weights: PathBuf,
    /// Imported data set whose test split is the reference set.
    #[arg(long, env = "PHYSNAP_DATA")]
    pub(crate) data: PathBuf,
    /// Unconditional samples.
    #[arg(long, env = "PHYSNAP_SAMPLES", default_value_t = 64)]
    pub(crate) samples: usize,
    /// Reference (test-split) objects, chosen by the seed.
    #[arg(long, env = "PHYSNAP_EVAL_REFS", default_value_t = 64)]
    pub(crate) refs: usize,
    /// Category-conditioned samples per category of the test split (0: skip).
    #[arg(long, env = "PHYSNAP_EVAL_PER_CATEGORY", default_value_t = 6)]
    pub(crate) per_category: usize,
    /// Test objects a conditioned sample's nearest neighbour is searched among for the category
    /// accuracy (seeded choice); 0: the whole test split (the nearest test object).
    #[arg(long, env = "PHYSNAP_EVAL_CATEGORY_REFS", default_value_t = 0)]
    pub(crate) category_refs: usize,
    /// Joint states per object for the instantiation distance (method.md: 10).
    #[arg(long, env = "PHYSNAP_EVAL_STATES", default_value_t = 4)]
    pub(crate) states: usize,
    /// Surface points per state for the instantiation distance (method.md: 2048).
    #[arg(long, env = "PHYSNAP_EVAL_POINTS", default_value_t = 512)]
    pub(crate) points: usize,
    /// MMD/COV/1-NNA set order: pointflow (PhysNAP, default) or nap (NAP's original code).
    #[arg(long, env = "PHYSNAP_EVAL_ORDER", default_value = "pointflow")]
    pub(crate) order: String,
    /// Marching-cubes grid cells per axis for the samples.
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = 32)]
    pub(crate) resolution: usize,
    /// Seed (samples, reference choice, state sampling).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 12345)]
    pub(crate) seed: u64,
    /// Also write the report as JSON here.
    #[arg(long, env = "PHYSNAP_EVAL_OUT")]
    pub(crate) out: Option<PathBuf>,
    /// Category guidance.
    #[command(flatten)]
    pub(crate) category: CategoryGuidanceArgs,
    /// Record the report under `metrics` in the weights' manifest.json.
    #[arg(long, env = "PHYSNAP_EVAL_WRITE_MANIFEST")]
    pub(crate) write_manifest: bool,
    /// Replace part shapes by their nearest training code of the weights' codebook: auto
    /// (empty shapes when the weights have a codebook, else off), off, empty (shapes that mesh
    /// empty), all (every latent shape: NAP's retrieval variant), category (every latent shape
    /// of a category-conditioned sample, from that category's codes; samples without a
    /// category: as empty).
    #[arg(long, env = "PHYSNAP_RETRIEVAL", default_value = "auto", value_parser = ["auto", "off", "empty", "all", "category"])]
    pub(crate) retrieval: String,
    /// Joint motions of the projected samples: screw (default here: NAP's protocol, which the
    /// manifest's figures use; both ranges kept) or dominant (`generate`'s default: each joint
    /// keeps only its wider range, in units of the feature scales).
    #[arg(long, env = "PHYSNAP_JOINT_MOTION", default_value = "screw", value_parser = ["screw", "dominant"])]
    pub(crate) joint_motion: String,
    /// Reverse-step rule: ddpm (default here: the paper's sampler, which every generative
    /// figure uses) or ddim (`generate`'s default).
    #[arg(long, env = "PHYSNAP_SAMPLER", default_value = "ddpm", value_parser = ["ddpm", "ddim"])]
    pub(crate) sampler: String,
    /// Reverse steps (0: all 1000, the paper's; `generate` defaults to 200).
    #[arg(long, env = "PHYSNAP_STEPS", default_value_t = 0)]
    pub(crate) steps: usize,
    /// DDIM noise level η in [0, 1] (ddim only).
    #[arg(long, env = "PHYSNAP_DDIM_ETA", default_value_t = 0.0)]
    pub(crate) eta: f64,
}

/// Draw `req.samples` objects for `req` (its category name filled in from the manifest).
pub(crate) fn sample_set(
    models: &LoadedModels,
    req: GenerateRequest,
    pb: &indicatif::ProgressBar,
) -> anyhow::Result<Vec<Generated>> {
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let req = GenerateRequest {
        category_name: req.category.map(|i| models.manifest.categories[i].clone()),
        ..req
    };
    Ok(run_generate(
        &models.denoiser,
        &decoder,
        models.codebook.as_ref(),
        &models.manifest.feature_scales,
        &Schedule::default(),
        &req,
        &mut |e| {
            if e.step.step == e.step.total {
                pb.inc(1);
            }
            ControlFlow::Continue(())
        },
    )?)
}

pub(crate) fn generative(a: EvalGenerativeArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let order = match a.order.as_str() {
        "pointflow" => MetricOrder::PointFlow,
        "nap" => MetricOrder::Nap,
        other => bail!("invalid --order {other:?} (must be pointflow or nap)"),
    };
    let id = IdOptions {
        states: a.states,
        points: a.points,
    };
    id.validate()?;
    MeshingOptions {
        resolution: a.resolution,
    }
    .validate()?;
    if a.samples < 2 || a.refs < 2 {
        bail!(
            "invalid --samples/--refs: {}/{} (each must be at least 2 for 1-NNA)",
            a.samples,
            a.refs
        );
    }
    let device = physnap::model::cpu();
    let models = load_models(&a.weights, &device)
        .with_context(|| format!("loading weights from {}", a.weights.display()))?;

    eprintln!("loading {} reference objects (test split)…", a.refs);
    let refs = references(&a.data, a.refs, a.seed)?;
    let ref_clouds: Vec<StateClouds> = refs
        .par_iter()
        .enumerate()
        .map(|(k, (_, o, m))| state_clouds(o, m, &id, a.seed ^ (k as u64) << 20))
        .collect::<Result<_, _>>()?;

    let conditional = a.per_category > 0 && models.manifest.denoiser.config.categories > 0;
    // The conditioned samples here are never loss-guided.
    let guidance_below = a.category.below(false);
    let guidance_weight = a.category.weight(false);
    // Category accuracy searches its own reference set: the whole test split by default.
    let same_refs = conditional && a.category_refs == a.refs;
    let cat_refs = if !conditional {
        Vec::new()
    } else if same_refs {
        refs.iter()
            .map(|r| r.0.clone())
            .zip(ref_clouds.clone())
            .collect()
    } else {
        let n = if a.category_refs == 0 {
            usize::MAX
        } else {
            a.category_refs
        };
        let objs = references(&a.data, n, a.seed)?;
        eprintln!("category accuracy against {} test objects…", objs.len());
        objs.par_iter()
            .enumerate()
            .map(|(k, (c, o, m))| {
                Ok((
                    c.clone(),
                    state_clouds(o, m, &id, a.seed ^ (k as u64) << 20)?,
                ))
            })
            .collect::<anyhow::Result<Vec<(String, StateClouds)>>>()?
    };
    let (cat_ref_cats, cat_ref_clouds): (Vec<String>, Vec<StateClouds>) =
        cat_refs.into_iter().unzip();
    // Conditional runs: every category among the category references.
    let mut cats: Vec<String> = cat_ref_cats.clone();
    cats.sort();
    cats.dedup();
    let total_samples = a.samples
        + if conditional {
            cats.len() * a.per_category
        } else {
            0
        };
    let retrieval = crate::cli::generate::retrieval_mode(&a.retrieval, &models)?;
    let pb = super::progress_bar(total_samples, "sample");
    let base = GenerateRequest {
        seed: a.seed,
        samples: a.samples,
        meshing: MeshingOptions {
            resolution: a.resolution,
        },
        retrieval,
        joint_motion: crate::cli::generate::joint_motion(&a.joint_motion)?,
        sampler: crate::cli::generate::sampler(&a.sampler, a.eta),
        steps: a.steps,
        ..Default::default()
    };
    let uncond = sample_set(
        &models,
        GenerateRequest {
            retrieval: retrieval.without_category(),
            ..base.clone()
        },
        &pb,
    )?;
    let mut cond: Vec<(String, Generated)> = Vec::new();
    if conditional {
        for (ci, c) in cats.iter().enumerate() {
            let idx = category_index(c).with_context(|| format!("unknown category {c:?}"))?;
            let seed = a.seed + 1_000_000 * (ci as u64 + 1);
            let req = GenerateRequest {
                seed,
                samples: a.per_category,
                category: Some(idx),
                category_guidance: guidance_weight,
                category_guidance_below: Some(guidance_below),
                ..base.clone()
            };
            for g in sample_set(&models, req, &pb)? {
                cond.push((c.clone(), g));
            }
        }
    }
    pb.finish_and_clear();
    let sampling_s = started.elapsed().as_secs_f64();

    let valid: Vec<&Generated> = uncond
        .iter()
        .filter(|g| invalid_reason(&g.object, &g.meshes).is_none())
        .collect();
    let mut reasons: Vec<String> = uncond
        .iter()
        .filter_map(|g| invalid_reason(&g.object, &g.meshes))
        .collect();
    reasons.sort();
    let valid_rate = valid.len() as f64 / uncond.len() as f64;
    // Retrieval: how many unconditional samples / parts needed a codebook shape.
    let retrieved_samples = uncond.iter().filter(|g| !g.retrieved.is_empty()).count();
    let retrieved_parts: usize = uncond.iter().map(|g| g.retrieved.len()).sum();
    let clouds = |gs: &[&Generated], salt: u64| -> anyhow::Result<Vec<StateClouds>> {
        Ok(gs
            .par_iter()
            .map(|g| state_clouds(&g.object, &g.meshes, &id, salt ^ g.seed))
            .collect::<Result<_, _>>()?)
    };
    let gen_clouds = clouds(&valid, 0x5eed)?;
    let cond_valid: Vec<&(String, Generated)> = cond
        .iter()
        .filter(|(_, g)| invalid_reason(&g.object, &g.meshes).is_none())
        .collect();
    let cond_clouds = clouds(
        &cond_valid.iter().map(|(_, g)| g).collect::<Vec<_>>(),
        0xca7,
    )?;

    let pairs = gen_clouds.len() * ref_clouds.len()
        + gen_clouds.len() * gen_clouds.len().saturating_sub(1) / 2
        + ref_clouds.len() * ref_clouds.len().saturating_sub(1) / 2
        + cond_clouds.len() * cat_ref_clouds.len()
        + if same_refs {
            0
        } else {
            cat_ref_clouds.len() * cat_ref_clouds.len().saturating_sub(1) / 2
        };
    let progress = PairProgress::new(pairs);
    let tick = |n: usize| progress.tick(n);
    let t_id = Instant::now();
    let d_gr = distance_matrix(&gen_clouds, &ref_clouds, false, &tick);
    let d_gg = distance_matrix(&gen_clouds, &gen_clouds, true, &tick);
    let d_rr = distance_matrix(&ref_clouds, &ref_clouds, true, &tick);
    let d_cr = distance_matrix(&cond_clouds, &cat_ref_clouds, false, &tick);
    let d_cc = if same_refs {
        d_rr.clone()
    } else {
        distance_matrix(&cat_ref_clouds, &cat_ref_clouds, true, &tick)
    };
    progress.finish();
    let id_s = t_id.elapsed().as_secs_f64();

    let metrics = if gen_clouds.len() >= 2 {
        Some(distribution_metrics(&d_gr, &d_gg, &d_rr, order)?)
    } else {
        None
    };
    // Category accuracy: the nearest reference of a conditioned sample has its category. Each
    // entry also counts the categories the samples landed nearest to (the confusion row).
    let mut per_cat = CategoryHits::table(&cats);
    for ((c, _), row) in cond_valid.iter().zip(&d_cr) {
        let nn = row
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, _)| i)
            .unwrap_or(0);
        CategoryHits::row(&mut per_cat, c).record(&cat_ref_cats[nn]);
    }
    // Invalid conditioned samples count as misses.
    for (c, g) in &cond {
        if invalid_reason(&g.object, &g.meshes).is_some() {
            CategoryHits::row(&mut per_cat, c).record("(invalid)");
        }
    }
    let (hits, tries) = per_cat
        .iter()
        .fold((0, 0), |s, e| (s.0 + e.hits, s.1 + e.samples));
    let cat_acc = (tries > 0).then(|| hits as f64 / tries as f64);
    // The ceiling of that metric: how often a test object's nearest other test object (among
    // the category references) shares its category.
    let ref_acc = physnap::eval::generative::loo_label_accuracy(&d_cc, &cat_ref_cats);
    // The same ceiling per category, with the categories the test objects land on instead.
    let ref_loo = CategoryHits::leave_one_out(&cats, &cat_ref_cats, &d_cc);

    // Reverse steps as run (0 asks for the whole schedule).
    let steps_run = if a.steps == 0 {
        physnap::engine::schedule::NUM_STEPS
    } else {
        a.steps
    };
    println!(
        "generative evaluation ({} order) of {}",
        a.order,
        a.weights.display()
    );
    println!(
        "  references: {} test objects; ID: {} states × {} points; meshing {}³; joint motion {}; sampler {} ({} steps)",
        refs.len(),
        a.states,
        a.points,
        a.resolution,
        a.joint_motion,
        a.sampler,
        steps_run
    );
    println!(
        "  unconditional: {} samples, valid {:.1}% ({} invalid{})",
        uncond.len(),
        100.0 * valid_rate,
        uncond.len() - valid.len(),
        if reasons.is_empty() {
            String::new()
        } else {
            format!(
                ": {}",
                reasons
                    .iter()
                    .take(3)
                    .cloned()
                    .collect::<Vec<_>>()
                    .join("; ")
            )
        }
    );
    if retrieval != Retrieval::Off {
        println!(
            "  retrieval {}: {retrieved_parts} parts of {retrieved_samples} samples took their nearest codebook shape",
            retrieval.as_str()
        );
    }
    if let Some(m) = metrics {
        println!(
            "  MMD {:.5}   COV {:.3}   1-NNA {:.3}",
            m.mmd, m.cov, m.one_nna
        );
    }
    if let Some(acc) = cat_acc {
        println!(
            "  category accuracy (nearest of {} test objects has the requested category): {:.1}% ({hits}/{tries})",
            cat_ref_cats.len(),
            100.0 * acc
        );
        println!(
            "  valid conditioned samples: {}/{} (category guidance w = {} at t < {})",
            cond_valid.len(),
            cond.len(),
            guidance_weight,
            guidance_below
        );
        for (k, e) in per_cat.iter().enumerate() {
            let ceiling = ref_loo
                .get(k)
                .map(|r| format!("   (test set: {}/{})", r.hits, r.samples))
                .unwrap_or_default();
            println!(
                "    {:<18} {}/{}{ceiling}{}",
                e.category,
                e.hits,
                e.samples,
                e.misses()
            );
        }
    }
    if let Some(acc) = ref_acc {
        println!(
            "  ceiling: a test object's nearest other test object has its category {:.1}% of the time",
            100.0 * acc
        );
        for r in ref_loo.iter().filter(|r| r.hits < r.samples) {
            println!(
                "    {:<18} {}/{}{}",
                r.category,
                r.hits,
                r.samples,
                r.misses()
            );
        }
    }
    let wall = started.elapsed().as_secs_f64();
    println!("  time: sampling+meshing {sampling_s:.0} s, ID {id_s:.0} s, total {wall:.0} s");

    let report = json!({
        "format": "physnap.eval_generative/v1",
        "weights": a.weights.display().to_string(),
        "data": a.data.display().to_string(),
        "order": a.order,
        "seed": a.seed,
        "references": refs.len(),
        "id": { "states": a.states, "points": a.points },
        "meshing_resolution": a.resolution,
        "retrieval": retrieval.as_str(),
        "joint_motion": a.joint_motion,
        "sampler": a.sampler,
        "steps": steps_run,
        "eta": a.eta,
        "category_guidance": guidance_weight,
        "category_guidance_below": guidance_below,
        "unconditional": {
            "retrieved_samples": retrieved_samples,
            "retrieved_parts": retrieved_parts,
            "samples": uncond.len(),
            "valid": valid.len(),
            "valid_rate": valid_rate,
            "invalid_reasons": reasons,
            "mmd": metrics.map(|m| m.mmd),
            "cov": metrics.map(|m| m.cov),
            "one_nna": metrics.map(|m| m.one_nna),
        },
        "conditional": {
            "per_category": a.per_category,
            "samples": cond.len(),
            "valid": cond_valid.len(),
            "accuracy": cat_acc,
            "reference_loo_accuracy": ref_acc,
            "references": cat_ref_cats.len(),
            "categories": per_cat.iter().enumerate().map(|(k, e)| json!({"category": e.category, "hits": e.hits, "samples": e.samples, "nearest": e.nearest, "reference_loo": ref_loo.get(k).map(CategoryHits::to_json)})).collect::<Vec<_>>(),
        },
        "seconds": { "sampling": sampling_s, "id": id_s, "total": wall },
        "command": std::env::args().collect::<Vec<_>>().join(" "),
    });
    if a.write_manifest {
        // metrics.generative = this report, metrics.shape_val_iou from training.
        let path = record_in_manifest(&a.weights, |m| {
            let iou = m["training"]["shape"]["val_iou"].clone();
            m["metrics"]["generative"] = report.clone();
            m["metrics"]["shape_val_iou"] = iou;
        })?;
        println!("  metrics recorded in {}", path.display());
    }
    if let Some(out) = &a.out {
        write_report(out, &report)?;
        println!("  report: {}", out.display());
    }
    Ok(())
}
