//! `physnap eval …`: the paper's metrics over trained weights. One module per subcommand; the
//! reference sets and report writing they share live here.

mod denoiser;
mod frame;
mod generative;
mod guided;
mod real;
mod reconstruction;
mod shape;

use super::progress_bar;
use anyhow::{Context, bail};
use clap::Subcommand;
use denoiser::EvalDenoiserArgs;
use frame::EvalFrameArgs;
use generative::EvalGenerativeArgs;
use guided::EvalGuidedArgs;
use physnap::data::dataset::load_object_meshes;
use physnap::data::rng::Rng;
use physnap::eval::generative::{IdOptions, StateClouds, state_clouds};
use physnap::io::manifest::load_models;
use rayon::prelude::*;
use real::EvalRealArgs;
use reconstruction::EvalReconstructionArgs;
use serde_json::json;
use shape::EvalShapeArgs;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

#[derive(Subcommand, Debug)]
pub(crate) enum EvalCommand {
    /// Sample the prior and compare with the test split: validity, MMD / COV / 1-NNA by
    /// instantiation distance, category accuracy of conditioned samples.
    Generative(EvalGenerativeArgs),
    /// Guidance metrics (E_pc, D_pc, E_pen, E_mob medians) per variant on test scans, in the
    /// paper's Table 1 layout; writes guided_table.md and guided_table.json.
    Guided(Box<EvalGuidedArgs>),
    /// Shape prior IoU (mean IoU on val parts at a 64³ grid): per part and by kind
    /// (single primitive, several primitives, mesh, thinner than a grid cell, with a primitive
    /// under a cell thick, every primitive at least 2 cells thick), plus SDF L1.
    Shape(EvalShapeArgs),
    /// Test objects passed through the representation (graph, shape codes from the encoder,
    /// projection, decoder meshing) against the originals: what the shape prior loses, and
    /// the category accuracy a perfect denoiser could reach with it.
    Reconstruction(EvalReconstructionArgs),
    /// The denoiser's ε-loss on a held-out split at fixed noise levels, with each object's
    /// category and with the "no category" row: generalisation and category use in about a
    /// minute, without sampling (paired: the same seed gives every model the same inputs).
    Denoiser(EvalDenoiserArgs),
    /// Real-scan metrics (real-scans.md §3) on a benchmark set: parts and joint types exact,
    /// axis and hinge errors, Chamfer/diag, sim-clean in MuJoCo, seconds; per object, per
    /// category and overall, for the prior, guided and best-of-N rows. Writes real.md/json.
    Real(Box<EvalRealArgs>),
    /// The scan-frame estimate (`generate --frame auto`) on every scan of a benchmark set,
    /// each moved by a random yaw and translation with +Z and with +Y up: yaw and floor
    /// errors with and without the camera. No generation; seconds.
    Frame(EvalFrameArgs),
}

/// Runs one `physnap eval …` subcommand.
pub(crate) fn run(command: EvalCommand) -> anyhow::Result<()> {
    match command {
        EvalCommand::Generative(a) => generative::generative(a),
        EvalCommand::Guided(a) => guided::eval_guided(*a),
        EvalCommand::Shape(a) => shape::shape(a),
        EvalCommand::Reconstruction(a) => reconstruction::reconstruction(a),
        EvalCommand::Denoiser(a) => denoiser::denoiser(a),
        EvalCommand::Real(a) => real::eval_real(*a),
        EvalCommand::Frame(a) => frame::eval_frame(a),
    }
}

/// The imported data set's `dataset.json`, with its path for error messages.
pub(crate) fn read_index(data: &Path) -> anyhow::Result<(std::path::PathBuf, serde_json::Value)> {
    let index_path = data.join("dataset.json");
    let index = serde_json::from_str(
        &std::fs::read_to_string(&index_path)
            .with_context(|| format!("reading {}", index_path.display()))?,
    )
    .with_context(|| format!("parsing {}", index_path.display()))?;
    Ok((index_path, index))
}

/// Reference objects: `n` test-split objects (seeded choice), with their category names.
pub(crate) fn references(
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
pub(crate) fn test_ids(data: &Path, n: usize, seed: u64) -> anyhow::Result<Vec<String>> {
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
pub(crate) fn cloud_references(
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

/// Write an evaluation report as pretty JSON (with a final newline) to `out`.
pub(crate) fn write_report(out: &Path, doc: &serde_json::Value) -> anyhow::Result<()> {
    std::fs::write(out, serde_json::to_string_pretty(doc)? + "\n")
        .with_context(|| format!("writing {}", out.display()))
}

/// Record evaluation figures in `weights/manifest.json` under `metrics` (`set` edits the parsed
/// manifest; `metrics` is an object when it runs). The weights files and their sha256 are
/// untouched; the file is replaced atomically. Returns the manifest's path.
pub(crate) fn record_in_manifest(
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
    physnap::io::atomic::write(&path, (serde_json::to_string_pretty(&m)? + "\n").as_bytes())?;
    Ok(path)
}

/// The shape prior of `dir` with its sizes and training report (or checkpoint): a weights
/// directory (`manifest.json`, sha256 checked) or a `train shape` output directory, finished
/// or stopped at a checkpoint, so candidates are measured before a denoiser is trained on them.
pub(crate) fn load_any_shape_prior(
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

/// A progress bar over `total` instantiation-distance pairs, ticked from `distance_matrix`'s
/// parallel workers.
pub(crate) struct PairProgress {
    pub(crate) pb: indicatif::ProgressBar,
    pub(crate) done: AtomicUsize,
    pub(crate) total: usize,
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

/// One requested category's conditioned samples: how many, how many hit, and the category of
/// each sample's nearest reference (`(invalid)` for samples that failed validity).
#[derive(Default)]
pub(crate) struct CategoryHits {
    pub(crate) category: String,
    pub(crate) hits: usize,
    pub(crate) samples: usize,
    pub(crate) nearest: std::collections::BTreeMap<String, usize>,
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

/// Most parts `eval shape` evaluates (each costs a 64³ decode and its ground truth).
pub(crate) const MAX_SHAPE_PARTS: usize = 5000;

/// Most encoder points `eval shape --surface-points` takes (a part's surface file has 1,024;
/// more are repeats).
pub(crate) const MAX_SURFACE_POINTS: usize = 8192;
