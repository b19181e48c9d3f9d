//! `physnap eval generative`: sample the trained prior, compare the samples with the held-out
//! test split by instantiation distance, and print validity, MMD / COV / 1-NNA and the
//! category accuracy of conditioned samples (issue 4's quality targets). Also `eval shape`
//! (the shape prior's IoU) and `eval reconstruction` (test objects through the representation
//! against the originals: what the shape prior alone loses, and so bounds).

use std::ops::ControlFlow;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{Context, bail};
use rayon::prelude::*;
use serde_json::json;

use physnap::data::categories::category_index;
use physnap::data::dataset::load_object_meshes;
use physnap::data::rng::Rng;
use physnap::engine::generate::{GenerateRequest, Generated, Retrieval, generate as run_generate};
use physnap::engine::schedule::Schedule;
use physnap::eval::generative::{
    IdOptions, MetricOrder, StateClouds, distance_matrix, distribution_metrics, invalid_reason,
    state_clouds,
};
use physnap::io::manifest::{LoadedModels, load_models};
use physnap::mesh::MeshingOptions;
use physnap::model::shape_prior::LatentSdfDecoder;

use super::{EvalDenoiserArgs, EvalGenerativeArgs, EvalReconstructionArgs, EvalShapeArgs};

/// The imported data set's `dataset.json`, with its path for error messages.
fn read_index(data: &Path) -> anyhow::Result<(std::path::PathBuf, serde_json::Value)> {
    let index_path = data.join("dataset.json");
    let index = serde_json::from_str(
        &std::fs::read_to_string(&index_path)
            .with_context(|| format!("reading {}", index_path.display()))?,
    )
    .with_context(|| format!("parsing {}", index_path.display()))?;
    Ok((index_path, index))
}

/// Reference objects: `n` test-split objects (seeded choice), with their category names.
fn references(
    data: &Path,
    n: usize,
    seed: u64,
) -> anyhow::Result<
    Vec<(
        String,
        physnap::object::ArticulatedObject,
        Vec<physnap::mesh::TriMesh>,
    )>,
> {
    let ids = test_ids(data, n, seed)?;
    ids.par_iter()
        .map(|id| {
            let (obj, meshes) = load_object_meshes(&data.join("objects").join(id))?;
            let cat = obj.category.clone().unwrap_or_default();
            Ok((cat, obj, meshes))
        })
        .collect()
}

/// Ids of `n` test-split objects (seeded choice, sorted; all of them when n ≥ the split).
fn test_ids(data: &Path, n: usize, seed: u64) -> anyhow::Result<Vec<String>> {
    let (index_path, index) = read_index(data)?;
    let mut ids: Vec<String> = index["splits"]["test"]
        .as_array()
        .with_context(|| format!("{}: no test split", index_path.display()))?
        .iter()
        .filter_map(|v| v.as_str().map(String::from))
        .collect();
    if ids.is_empty() {
        bail!("{}: the test split is empty", index_path.display());
    }
    let mut rng = Rng::new(seed);
    for i in (1..ids.len()).rev() {
        ids.swap(i, rng.int(0, i));
    }
    ids.truncate(n);
    ids.sort();
    Ok(ids)
}

/// Per-cloud references of the guided table's MMD / 1-NNA (our reading of "per point cloud",
/// which the paper leaves open): the scanned object itself when `data` holds it, then other
/// test-split objects of the cloud's category in a seeded order, `per_cloud` in all, each
/// prepared for the instantiation distance. A cloud without a category gets only its own object.
/// Also returns, per cloud, whether its first reference is the scanned object (for ID_gt).
pub fn cloud_references(
    data: &Path,
    clouds: &[physnap::eval::guided::Cloud],
    per_cloud: usize,
    id: &IdOptions,
    seed: u64,
) -> anyhow::Result<(Vec<Vec<StateClouds>>, Vec<bool>)> {
    let (index_path, index) = read_index(data)?;
    let objects = index["objects"]
        .as_array()
        .with_context(|| format!("{}: no objects list", index_path.display()))?;
    let entry = |o: &serde_json::Value| {
        (
            o["id"].as_str().unwrap_or_default().to_string(),
            o["category_index"].as_u64().map(|c| c as usize),
            o["split"].as_str() == Some("test"),
        )
    };
    let all: Vec<(String, Option<usize>, bool)> = objects.iter().map(entry).collect();
    let mut rng = Rng::new(seed);
    let scanned: Vec<bool> = clouds
        .iter()
        .map(|cloud| all.iter().any(|(id, _, _)| id == &cloud.id) && per_cloud > 0)
        .collect();
    let refs = clouds
        .iter()
        .zip(&scanned)
        .map(|(cloud, &known)| {
            let mut ids: Vec<String> = Vec::new();
            if known {
                ids.push(cloud.id.clone());
            }
            if let Some(cat) = cloud.category {
                let mut others: Vec<&String> = all
                    .iter()
                    .filter(|(id, c, test)| *test && *c == Some(cat) && id != &cloud.id)
                    .map(|(id, _, _)| id)
                    .collect();
                for i in (1..others.len()).rev() {
                    others.swap(i, rng.int(0, i));
                }
                ids.extend(others.into_iter().cloned());
            }
            ids.truncate(per_cloud);
            ids.par_iter()
                .enumerate()
                .map(|(k, oid)| {
                    let (obj, meshes) = load_object_meshes(&data.join("objects").join(oid))?;
                    Ok(state_clouds(&obj, &meshes, id, seed ^ ((k as u64) << 20))?)
                })
                .collect()
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok((refs, scanned))
}

/// A progress bar over `total` instantiation-distance pairs, ticked from `distance_matrix`'s
/// parallel workers.
struct PairProgress {
    pb: indicatif::ProgressBar,
    done: AtomicUsize,
    total: usize,
}

impl PairProgress {
    fn new(total: usize) -> Self {
        PairProgress {
            pb: super::progress_bar(total, "ID pairs"),
            done: AtomicUsize::new(0),
            total,
        }
    }

    fn tick(&self, n: usize) {
        let d = self.done.fetch_add(n, Ordering::Relaxed) + n;
        if d.is_multiple_of(64) || d == self.total {
            self.pb.set_position(d as u64);
        }
    }

    fn finish(self) {
        self.pb.finish_and_clear();
    }
}

/// Draw `req.samples` objects for `req` (its category name filled in from the manifest).
fn sample_set(
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

/// One requested category's conditioned samples: how many, how many hit, and the category of
/// each sample's nearest reference (`(invalid)` for samples that failed validity).
#[derive(Default)]
struct CategoryHits {
    category: String,
    hits: usize,
    samples: usize,
    nearest: std::collections::BTreeMap<String, usize>,
}

impl CategoryHits {
    /// One empty row per category, in `cats`' order.
    fn table(cats: &[String]) -> Vec<CategoryHits> {
        cats.iter()
            .map(|c| CategoryHits {
                category: c.clone(),
                ..Default::default()
            })
            .collect()
    }

    /// The row of category `c` in a [`CategoryHits::table`] (which lists every category).
    fn row<'t>(table: &'t mut [CategoryHits], c: &str) -> &'t mut CategoryHits {
        table
            .iter_mut()
            .find(|e| e.category == c)
            .expect("the table lists every category")
    }

    /// The categories its items landed nearest to instead of their own, as
    /// "   nearest instead: Box 2, Table 1" (empty when there were none).
    fn misses(&self) -> String {
        let misses: Vec<String> = self
            .nearest
            .iter()
            .filter(|(n, _)| **n != self.category)
            .map(|(n, k)| format!("{n} {k}"))
            .collect();
        if misses.is_empty() {
            String::new()
        } else {
            format!("   nearest instead: {}", misses.join(", "))
        }
    }

    /// The leave-one-out table of a labelled set with distance matrix `d`: per category, how
    /// many of its objects have an object of their own category nearest, and which they have
    /// instead. Every row is empty when `d` holds fewer than two objects or does not fit
    /// `labels`.
    fn leave_one_out(cats: &[String], labels: &[String], d: &[Vec<f64>]) -> Vec<CategoryHits> {
        let mut t = CategoryHits::table(cats);
        let nn = physnap::eval::generative::loo_nearest(d).filter(|nn| nn.len() == labels.len());
        for (i, &j) in nn.iter().flatten().enumerate() {
            CategoryHits::row(&mut t, &labels[i]).record(&labels[j]);
        }
        t
    }

    fn to_json(&self) -> serde_json::Value {
        json!({"hits": self.hits, "objects": self.samples, "nearest": self.nearest})
    }

    fn record(&mut self, nearest: &str) {
        self.samples += 1;
        if nearest == self.category {
            self.hits += 1;
        }
        *self.nearest.entry(nearest.to_string()).or_default() += 1;
    }
}

pub fn generative(a: EvalGenerativeArgs) -> anyhow::Result<()> {
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
    let retrieval = super::model_cmd::retrieval_mode(&a.retrieval, &models)?;
    let pb = super::progress_bar(total_samples, "sample");
    let base = GenerateRequest {
        seed: a.seed,
        samples: a.samples,
        meshing: MeshingOptions {
            resolution: a.resolution,
        },
        retrieval,
        joint_motion: super::model_cmd::joint_motion(&a.joint_motion)?,
        sampler: super::model_cmd::sampler(&a.sampler, a.eta),
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

/// Write an evaluation report as pretty JSON (with a final newline) to `out`.
fn write_report(out: &Path, doc: &serde_json::Value) -> anyhow::Result<()> {
    std::fs::write(out, serde_json::to_string_pretty(doc)? + "\n")
        .with_context(|| format!("writing {}", out.display()))
}

/// Record evaluation figures in `weights/manifest.json` under `metrics` (`set` edits the parsed
/// manifest; `metrics` is an object when it runs). The weights files and their sha256 are
/// untouched; the file is replaced atomically. Returns the manifest's path.
fn record_in_manifest(
    weights: &Path,
    set: impl FnOnce(&mut serde_json::Value),
) -> anyhow::Result<std::path::PathBuf> {
    let path = weights.join("manifest.json");
    let mut m: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path)?)
        .with_context(|| format!("parsing {}", path.display()))?;
    if !m["metrics"].is_object() {
        m["metrics"] = json!({});
    }
    set(&mut m);
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(&m)? + "\n")?;
    std::fs::rename(&tmp, &path)?;
    Ok(path)
}

/// Most parts `eval shape` evaluates (each costs a 64³ decode and its ground truth).
const MAX_SHAPE_PARTS: usize = 5000;
/// Most encoder points `eval shape --surface-points` takes (a part's surface file has 1,024;
/// more are repeats).
const MAX_SURFACE_POINTS: usize = 8192;

/// `physnap eval reconstruction`: test objects passed through the representation the denoiser
/// learns (their `graph.npy`, each part's code from the shape prior's encoder, projection,
/// meshing with the decoder), compared with the originals by instantiation distance; plus the
/// test objects' own E_pen and E_mob under the decoder (the data's level of the physical metrics
/// that generated samples are read against).
///
/// Why: it separates what the shape prior and the representation lose from what the denoiser
/// loses. Its category accuracy is what a conditioned sample could reach if the denoiser
/// reproduced test objects exactly; if it is far below the originals' own leave-one-out figure,
/// no denoiser can meet the category target with this shape prior.
pub fn reconstruction(a: EvalReconstructionArgs) -> anyhow::Result<()> {
    use physnap::eval::generative::{
        loo_label_accuracy, reconstruction_hits, reconstruction_neighbours,
    };
    use physnap::eval::guided::{
        MESH_OVERLAP_DEPTH, MESH_OVERLAP_SAMPLES, mesh_overlap, positive_share as share,
        sdf_metrics, share_above,
    };
    use physnap::graph::{GraphTensor, ProjectOptions, node_ch, project};
    use physnap::train::shape::{Encoding, encode_object_parts};
    let started = Instant::now();
    let id = IdOptions {
        states: a.states,
        points: a.points,
    };
    id.validate()?;
    let meshing = MeshingOptions {
        resolution: a.resolution,
    };
    meshing.validate()?;
    let (prior, _, report) = load_any_shape_prior(&a.weights)?;
    let surface_points = report["config"]["surface_points"].as_u64().map_or(
        physnap::train::shape::ShapeTrainConfig::default().surface_points,
        |n| n as usize,
    );
    let encoding = Encoding::of_report(&report, &a.weights)?;
    let decoder = LatentSdfDecoder::new(&prior.decoder);
    let n = if a.objects == 0 {
        usize::MAX
    } else {
        a.objects
    };
    let ids = test_ids(&a.data, n, a.seed)?;
    if ids.len() < 2 {
        bail!(
            "--objects: need at least 2 test objects, {} has {}",
            a.data.display(),
            ids.len()
        );
    }
    let pb = super::progress_bar(ids.len(), "objects");
    // Per object: category, original clouds, reconstruction (clouds or why not), empty parts,
    // O_mesh of the original and of the reconstruction, E_pen and E_mob of the reconstruction.
    type Rec = (
        String,
        StateClouds,
        Result<StateClouds, String>,
        usize,
        [f64; 2],
        [f64; 2],
    );
    let recs: Vec<Rec> = ids
        .iter()
        .enumerate()
        .map(|(k, oid)| -> anyhow::Result<Rec> {
            let dir = a.data.join("objects").join(oid);
            let (orig, orig_meshes) = load_object_meshes(&dir)?;
            let cat = orig.category.clone().unwrap_or_default();
            let salt = a.seed ^ ((k as u64) << 20);
            let orig_clouds = state_clouds(&orig, &orig_meshes, &id, salt)?;
            let graph_path = dir.join("graph.npy");
            let (_, _, flat) = physnap::io::npy::read(&graph_path)
                .with_context(|| format!("reading {}", graph_path.display()))?;
            let mut g = GraphTensor::from_flat(&flat)
                .with_context(|| format!("{}", graph_path.display()))?;
            let codes = encode_object_parts(
                &prior,
                &a.data,
                oid,
                orig.parts.len(),
                surface_points,
                &encoding,
            )?;
            // Slot k holds part k (the codebook's key `<id>_<k>`, as `train diffusion` reads it).
            for slot in 0..physnap::graph::K {
                if g.node(slot)[node_ch::EXIST] >= 0.5 {
                    let code = codes.get(slot).with_context(|| {
                        format!(
                            "{}: node {slot} exists but the object has {} parts",
                            graph_path.display(),
                            codes.len()
                        )
                    })?;
                    g.node_mut(slot)[node_ch::LATENT..].copy_from_slice(code);
                }
            }
            // The paper's physical metrics of the test object itself, as the decoder sees it: the
            // level a denoiser that reproduced the data exactly would reach (guided and unguided
            // samples' E_pen / E_mob are read against it).
            let physical = sdf_metrics(&decoder, &g, &[]);
            // Projection turns every node into a part with its latent code as the shape.
            let obj = project(
                &g,
                &ProjectOptions {
                    name: oid.clone(),
                    category: Some(cat.clone()),
                    ..Default::default()
                },
            )
            .with_context(|| format!("projecting {}", graph_path.display()))?;
            let meshes = if a.shapes == "original" {
                if obj.parts.len() != orig_meshes.len() {
                    bail!(
                        "{}: the projected graph has {} parts, the object {}",
                        graph_path.display(),
                        obj.parts.len(),
                        orig_meshes.len()
                    );
                }
                orig_meshes.clone()
            } else if a.shapes == "analytic" {
                // The originals' own shapes (primitives), meshed like decoded ones: what
                // marching cubes at this resolution alone loses.
                let mut obj = obj.clone();
                for (part, o) in obj.parts.iter_mut().zip(&orig.parts) {
                    part.shape = o.shape.clone();
                }
                physnap::mesh::mesh_parts(&obj, None, &meshing)?
            } else {
                physnap::mesh::mesh_parts(&obj, Some(&decoder), &meshing)?
            };
            let empty = meshes.iter().filter(|m| m.triangles.is_empty()).count();
            // The same seed as the original: the same joint states, so the distance to it is the
            // shapes' (and the graph's) loss, not state-sampling noise.
            let rec = state_clouds(&obj, &meshes, &id, salt).map_err(|e| e.to_string());
            // How much the parts overlap on the meshes, original and reconstruction (the
            // representation's own share of a generated sample's O_mesh).
            let overlap = [(&orig, &orig_meshes), (&obj, &meshes)]
                .map(|(o, m)| mesh_overlap(o, m, MESH_OVERLAP_SAMPLES, salt));
            pb.inc(1);
            Ok((
                cat,
                orig_clouds,
                rec,
                empty,
                overlap,
                [physical.e_pen, physical.e_mob],
            ))
        })
        .collect::<anyhow::Result<_>>()?;
    pb.finish_and_clear();
    let mesh_s = started.elapsed().as_secs_f64();

    let labels: Vec<String> = recs.iter().map(|r| r.0.clone()).collect();
    let originals: Vec<StateClouds> = recs.iter().map(|r| r.1.clone()).collect();
    let rows: Vec<usize> = (0..recs.len()).filter(|&i| recs[i].2.is_ok()).collect();
    let rec_clouds: Vec<StateClouds> = rows
        .iter()
        .map(|&i| recs[i].2.clone().expect("kept rows are Ok"))
        .collect();
    let objects_with_empty = recs.iter().filter(|r| r.3 > 0).count();
    let empty_parts: usize = recs.iter().map(|r| r.3).sum();
    let overlap: [Vec<f64>; 2] = [0, 1].map(|k| {
        recs.iter()
            .map(|r| r.4[k])
            .filter(|v| v.is_finite())
            .collect()
    });
    let physical: [Vec<f64>; 2] = [0, 1].map(|k| recs.iter().map(|r| r.5[k]).collect());
    let above = |v: &[f64]| share_above(v, 1e-4);

    let pairs = rec_clouds.len() * originals.len() + originals.len() * (originals.len() - 1) / 2;
    let progress = PairProgress::new(pairs);
    let tick = |n: usize| progress.tick(n);
    let d_ro = distance_matrix(&rec_clouds, &originals, false, &tick);
    let d_oo = distance_matrix(&originals, &originals, true, &tick);
    progress.finish();
    let neighbours = reconstruction_neighbours(&d_ro, &rows, labels.len())
        .context("reconstruction distances")?;
    let (cat_hits, self_hits) = reconstruction_hits(&neighbours, &rows, &labels);
    let ceiling = loo_label_accuracy(&d_oo, &labels);
    let total = recs.len();
    let own: Vec<f64> = rows.iter().enumerate().map(|(r, &i)| d_ro[r][i]).collect();
    let nearest_other: Vec<f64> = (0..total)
        .map(|i| {
            (0..total)
                .filter(|&j| j != i)
                .map(|j| d_oo[i][j])
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    let median = |v: &[f64]| -> Option<f64> {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        (!v.is_empty()).then(|| v[v.len() / 2])
    };
    let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    let mut cats: Vec<String> = labels.clone();
    cats.sort();
    cats.dedup();
    // Per category: where the reconstructions land (objects without any surface count as
    // misses), and where the originals land among themselves (the ceiling).
    let mut per_cat = CategoryHits::table(&cats);
    for (&(other, _), &i) in neighbours.iter().zip(&rows) {
        CategoryHits::row(&mut per_cat, &labels[i]).record(&labels[other]);
    }
    for i in (0..total).filter(|&i| recs[i].2.is_err()) {
        CategoryHits::row(&mut per_cat, &labels[i]).record("(no surface)");
    }
    let orig_loo = CategoryHits::leave_one_out(&cats, &labels, &d_oo);
    let pct = |k: usize| 100.0 * k as f64 / total as f64;
    if a.shapes == "original" {
        println!(
            "reconstruction of {total} test objects: projected graphs with the original meshes ({} states × {} points)",
            a.states, a.points
        );
    } else {
        println!(
            "reconstruction of {total} test objects through the shape prior of {} ({} states × {} points, meshing {}³)",
            a.weights.display(),
            a.states,
            a.points,
            a.resolution
        );
    }
    println!(
        "  parts meshing empty: {empty_parts} in {objects_with_empty} objects; {} objects without any surface",
        total - rows.len()
    );
    println!(
        "  category accuracy (nearest other test object has the category): {:.1}% ({cat_hits}/{total}); originals: {:.1}%",
        pct(cat_hits),
        100.0 * ceiling.unwrap_or(f64::NAN)
    );
    println!(
        "  nearest test object is the original itself: {:.1}% ({self_hits}/{total})",
        pct(self_hits)
    );
    println!(
        "  ID reconstruction↔original: mean {:.4}, median {:.4}; original↔nearest other: median {:.4}",
        mean(&own).unwrap_or(f64::NAN),
        median(&own).unwrap_or(f64::NAN),
        median(&nearest_other).unwrap_or(f64::NAN)
    );
    println!(
        "  O_mesh (surface buried > {} mm in another part, mean over 5 joint states): originals mean {:.4} ({:.0}% > 0), reconstructions mean {:.4} ({:.0}% > 0)",
        1000.0 * MESH_OVERLAP_DEPTH,
        mean(&overlap[0]).unwrap_or(f64::NAN),
        100.0 * share(&overlap[0]),
        mean(&overlap[1]).unwrap_or(f64::NAN),
        100.0 * share(&overlap[1]),
    );
    for (name, v) in ["E_pen", "E_mob"].iter().zip(&physical) {
        println!(
            "  {name} of the test objects under the decoder (graph.npy with encoder codes, at rest / swept): mean {:.3e}, median {:.3e}, {:.0}% > 0, {:.0}% > 1e-4",
            mean(v).unwrap_or(f64::NAN),
            median(v).unwrap_or(f64::NAN),
            100.0 * share(v),
            100.0 * above(v),
        );
    }
    println!(
        "  per category: reconstructions (originals, leave one out), then where reconstructions land instead"
    );
    for (e, o) in per_cat.iter().zip(&orig_loo) {
        println!(
            "    {:<18} {}/{} ({}/{}){}",
            e.category,
            e.hits,
            e.samples,
            o.hits,
            o.samples,
            e.misses()
        );
    }
    let wall = started.elapsed().as_secs_f64();
    println!("  time: encode+mesh {mesh_s:.0} s, total {wall:.0} s");
    if let Some(out) = &a.out {
        let doc = json!({
            "format": "physnap.eval_reconstruction/v1",
            "weights": a.weights.display().to_string(),
            "data": a.data.display().to_string(),
            "objects": total,
            "seed": a.seed,
            "id": { "states": a.states, "points": a.points },
            "meshing_resolution": a.resolution,
            "shapes": a.shapes,
            "surface_points": surface_points,
            "empty_parts": empty_parts,
            "objects_with_empty_parts": objects_with_empty,
            "objects_without_surface": total - rows.len(),
            "category_accuracy": cat_hits as f64 / total as f64,
            "original_loo_accuracy": ceiling,
            "self_retrieval": self_hits as f64 / total as f64,
            "id_to_original": { "mean": mean(&own), "median": median(&own) },
            "original_nearest_other_median": median(&nearest_other),
            "o_mesh": {
                "original": { "mean": mean(&overlap[0]), "median": median(&overlap[0]), "share": share(&overlap[0]) },
                "reconstruction": { "mean": mean(&overlap[1]), "median": median(&overlap[1]), "share": share(&overlap[1]) },
            },
            "e_pen": { "mean": mean(&physical[0]), "median": median(&physical[0]), "share": share(&physical[0]), "share_above_1e-4": above(&physical[0]) },
            "e_mob": { "mean": mean(&physical[1]), "median": median(&physical[1]), "share": share(&physical[1]), "share_above_1e-4": above(&physical[1]) },
            "categories": per_cat.iter().zip(&orig_loo).map(|(e, o)| json!({"category": e.category, "hits": e.hits, "objects": e.samples, "nearest": e.nearest, "original_loo": o.to_json()})).collect::<Vec<_>>(),
            "seconds": { "encode_mesh": mesh_s, "total": wall },
            "command": std::env::args().collect::<Vec<_>>().join(" "),
        });
        write_report(out, &doc)?;
        println!("  report: {}", out.display());
    }
    Ok(())
}

/// The shape prior of `dir` with its sizes and training report (or checkpoint): a weights
/// directory (`manifest.json`, sha256 checked) or a `train shape` output directory, finished
/// or stopped at a checkpoint, so candidates are measured before a denoiser is trained on them.
fn load_any_shape_prior(
    dir: &Path,
) -> anyhow::Result<(
    physnap::model::shape_prior::ShapePrior,
    physnap::model::shape_prior::ShapePriorConfig,
    serde_json::Value,
)> {
    use physnap::train::shape::{CHECKPOINT_FILE, REPORT_FILE, load_shape_dir};
    let is_run = dir.join(REPORT_FILE).is_file() || dir.join(CHECKPOINT_FILE).is_file();
    if dir.join("manifest.json").is_file() || !is_run {
        let models = load_models(dir, &physnap::model::cpu())?;
        let cfg = models.manifest.shape_prior.config;
        let report = models.manifest.training["shape"].clone();
        return Ok((models.shape_prior, cfg, report));
    }
    Ok(load_shape_dir(dir, &physnap::model::cpu())?)
}

/// `physnap eval shape`: IoU of the weights' shape prior on parts of one split.
pub fn shape(a: EvalShapeArgs) -> anyhow::Result<()> {
    use physnap::train::shape::{Encoding, PartIou, ShapeTrainConfig, evaluate_shape_prior};
    let started = Instant::now();
    if !["train", "val", "test"].contains(&a.split.as_str()) {
        bail!("invalid --split {:?} (must be train, val or test)", a.split);
    }
    if !(1..=MAX_SHAPE_PARTS).contains(&a.parts) {
        bail!(
            "invalid --parts {}: must be between 1 and {MAX_SHAPE_PARTS}",
            a.parts
        );
    }
    if a.write_manifest && !a.weights.join("manifest.json").is_file() {
        bail!(
            "--write-manifest needs a weights directory with manifest.json; {} has none (drop \
             --write-manifest, or keep the figures with --out)",
            a.weights.display()
        );
    }
    if let Some(n) = a.surface_points
        && !(1..=MAX_SURFACE_POINTS).contains(&n)
    {
        bail!("invalid --surface-points {n}: must be between 1 and {MAX_SURFACE_POINTS}");
    }
    if a.write_manifest && a.surface_points.is_some() {
        bail!(
            "--write-manifest records the IoU of the codes the codebook uses; --surface-points \
             measures another encoder input (keep it with --out)"
        );
    }
    let (shape_prior, model_cfg, report) = load_any_shape_prior(&a.weights)?;
    // The codebook's encoding is the default; another one measures codes the denoiser never
    // learned, which the manifest must not record as the prior's IoU.
    let recorded = Encoding::of_report(&report, &a.weights)?;
    let enc = Encoding {
        views: a.encoder_views.unwrap_or(recorded.views),
        fit_steps: a.fit_codes.unwrap_or(recorded.fit_steps),
        fit_queries: a.fit_queries.unwrap_or(recorded.fit_queries),
        fit_prox: a.fit_prox.unwrap_or(recorded.fit_prox),
    };
    enc.validate()?;
    if a.write_manifest && enc != recorded {
        let s = |v: &dyn std::fmt::Display| v.to_string();
        let differs = [
            ("--encoder-views", s(&enc.views), s(&recorded.views)),
            ("--fit-codes", s(&enc.fit_steps), s(&recorded.fit_steps)),
            (
                "--fit-queries",
                s(&enc.fit_queries),
                s(&recorded.fit_queries),
            ),
            ("--fit-prox", s(&enc.fit_prox), s(&recorded.fit_prox)),
        ]
        .iter()
        .filter(|(_, asked, rec)| asked != rec)
        .map(|(flag, asked, rec)| format!("{flag} {asked} (the codebook's: {rec})"))
        .collect::<Vec<_>>()
        .join(", ");
        bail!(
            "--write-manifest records the IoU of the codes the codebook uses, which the denoiser \
             learned; {differs} measures other codes (keep that report with --out)"
        );
    }
    let defaults = ShapeTrainConfig::default();
    let trained_points = report["config"]["surface_points"]
        .as_u64()
        .map_or(defaults.surface_points, |n| n as usize);
    let surface_points = a.surface_points.unwrap_or(trained_points);
    let cfg = ShapeTrainConfig {
        model: model_cfg,
        surface_points,
        iou_resolution: a.resolution,
        ..defaults
    };
    let pb = super::progress_bar(a.parts, "parts");
    let (parts, l1) = evaluate_shape_prior(
        &shape_prior,
        &a.data,
        &cfg,
        &a.split,
        a.parts,
        &enc,
        &mut |done, total| {
            pb.set_length(total as u64);
            pb.set_position(done as u64);
        },
    )?;
    pb.finish_and_clear();
    let cell = 1.1 / a.resolution as f64;
    let mean = |sel: &[&PartIou]| -> Option<f64> {
        (!sel.is_empty()).then(|| sel.iter().map(|p| p.iou).sum::<f64>() / sel.len() as f64)
    };
    let all: Vec<&PartIou> = parts.iter().collect();
    let pick = |keep: &dyn Fn(&PartIou) -> bool| -> Vec<&PartIou> {
        all.iter().copied().filter(|p| keep(p)).collect()
    };
    let groups: [(&str, Vec<&PartIou>); 7] = [
        ("all", all.clone()),
        ("single primitive", pick(&|p| p.primitives == Some(1))),
        (
            "several primitives",
            pick(&|p| p.primitives.is_some_and(|n| n > 1)),
        ),
        ("mesh", pick(&|p| p.primitives.is_none())),
        ("thinner than a grid cell", pick(&|p| p.thinnest < cell)),
        // Where the IoU is lost: walls and panels under a cell thick, whose cells flip in or
        // out of the part with a surface error of a fraction of a cell.
        (
            "a primitive under a cell",
            pick(&|p| p.thinnest_primitive.is_some_and(|t| t < cell)),
        ),
        (
            "every primitive >= 2 cells",
            pick(&|p| p.thinnest_primitive.is_some_and(|t| t >= 2.0 * cell)),
        ),
    ];
    println!(
        "shape prior of {}: {} {} parts of {}, {}³ grid (cell {cell:.4}), {:.0} s",
        a.weights.display(),
        parts.len(),
        a.split,
        a.data.display(),
        a.resolution,
        started.elapsed().as_secs_f64()
    );
    for (name, sel) in &groups {
        if let Some(m) = mean(sel) {
            println!("  {name:<26} {:>4} parts  mean IoU {m:.3}", sel.len());
        }
    }
    println!("  mean SDF L1 {l1:.5} (normalised units)");
    if enc.views > 1 {
        println!(
            "  codes: the mean of {} encoder calls a part, each on the next {surface_points} surface points",
            enc.views
        );
    }
    if enc.fit_steps > 0 {
        println!(
            "  codes fitted to each part's first {} SDF samples ({} Adam steps from the encoder's, decoder frozen, pull toward it {})",
            enc.fit_queries, enc.fit_steps, enc.fit_prox
        );
    }
    if enc != recorded {
        println!(
            "  (the codebook's encoding is {} view(s), {} fitting steps, pull {}: these are not the codes the denoiser learned)",
            recorded.views, recorded.fit_steps, recorded.fit_prox
        );
    }
    if surface_points != trained_points {
        println!(
            "  encoder input: {surface_points} surface points a part (trained with, and the \
             codebook uses, {trained_points})"
        );
    }
    let summary = json!({
        "format": "physnap.eval_shape/v1",
        "split": a.split,
        "parts": parts.len(),
        "resolution": a.resolution,
        "mean_iou": mean(&all),
        "l1": l1,
        "fit_codes": enc.fit_steps,
        "encoding": enc.to_json(),
        "groups": groups.iter().map(|(name, sel)| json!({
            "name": name, "parts": sel.len(), "mean_iou": mean(sel),
        })).collect::<Vec<_>>(),
        "command": std::env::args().collect::<Vec<_>>().join(" "),
    });
    if a.write_manifest {
        let path = record_in_manifest(&a.weights, |m| m["metrics"]["shape"] = summary.clone())?;
        println!("metrics recorded in {} (metrics.shape)", path.display());
    }
    if let Some(out) = &a.out {
        // The summary, with every part instead of their count.
        let mut doc = summary;
        doc["weights"] = json!(a.weights.display().to_string());
        doc["data"] = json!(a.data.display().to_string());
        doc["surface_points"] = json!(surface_points);
        doc["parts"] = parts
            .iter()
            .map(|p| {
                json!({
                    "key": p.key, "iou": p.iou, "primitives": p.primitives, "thinnest": p.thinnest,
                    "thinnest_primitive": p.thinnest_primitive,
                })
            })
            .collect();
        doc["seconds"] = json!(started.elapsed().as_secs_f64());
        write_report(out, &doc)?;
        println!("report: {}", out.display());
    }
    Ok(())
}

/// `physnap eval denoiser`: the held-out ε-loss per noise level, with and without the
/// category (module `physnap::train::held_out`).
pub fn denoiser(a: EvalDenoiserArgs) -> anyhow::Result<()> {
    use physnap::train::{diffusion::load_split, held_out::held_out_loss};
    if !["train", "val", "test"].contains(&a.split.as_str()) {
        bail!("invalid --split {:?} (must be train, val or test)", a.split);
    }
    let started = Instant::now();
    let device = physnap::model::cpu();
    let models = load_models(&a.weights, &device)
        .with_context(|| format!("loading weights from {}", a.weights.display()))?;
    let data = load_split(&a.data, &a.shape, &a.split)?;
    let scales = &models.manifest.feature_scales;
    let r = held_out_loss(&models.denoiser, &data, scales, &a.levels, a.seed)?;
    println!(
        "denoiser ε-loss on {} {} objects (seed {}), feature scales of {}:",
        r.objects,
        a.split,
        a.seed,
        a.weights.display()
    );
    println!(
        "{:>5}  {:>10}  {:>12}  {:>6}",
        "t", "category", "no category", "gain"
    );
    for (i, t) in r.levels.iter().enumerate() {
        match &r.unconditional {
            Some(u) => println!(
                "{t:>5}  {:>10.5}  {:>12.5}  {:>6.3}",
                r.conditional[i],
                u[i],
                u[i] / r.conditional[i]
            ),
            None => println!("{t:>5}  {:>10.5}", r.conditional[i]),
        }
    }
    let mean_u = r.mean_unconditional();
    match mean_u {
        Some(u) => println!(
            " mean  {:>10.5}  {u:>12.5}  {:>6.3}   ({:.1} s)",
            r.mean_conditional(),
            u / r.mean_conditional(),
            started.elapsed().as_secs_f64()
        ),
        None => println!(
            " mean  {:>10.5}   ({:.1} s)",
            r.mean_conditional(),
            started.elapsed().as_secs_f64()
        ),
    }
    if let Some(out) = &a.out {
        let report = json!({
            "format": "physnap.eval_denoiser/v1",
            "command": std::env::args().collect::<Vec<_>>().join(" "),
            "weights": a.weights,
            "denoiser_sha256": models.manifest.denoiser.sha256,
            "data": a.data,
            "shape": a.shape,
            "split": a.split,
            "seed": a.seed,
            "objects": r.objects,
            "levels": r.levels,
            "conditional": r.conditional,
            "unconditional": r.unconditional,
            "mean_conditional": r.mean_conditional(),
            "mean_unconditional": mean_u,
            "seconds": started.elapsed().as_secs_f64(),
        });
        std::fs::write(out, serde_json::to_string_pretty(&report)? + "\n")
            .with_context(|| format!("writing {}", out.display()))?;
    }
    Ok(())
}
