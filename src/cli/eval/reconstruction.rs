//! `physnap eval reconstruction`: test objects through the representation (graph, codes, meshing) against the originals.

use super::*;
use anyhow::{Context, bail};
use clap::Args;
use physnap::data::dataset::load_object_meshes;
use physnap::eval::generative::{IdOptions, StateClouds, distance_matrix, state_clouds};
use physnap::mesh::MeshingOptions;
use physnap::model::shape_prior::LatentSdfDecoder;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub(crate) struct EvalReconstructionArgs {
    /// Weights directory with manifest.json, or a `train shape` output directory
    /// (shape_prior.safetensors + shape_train.json, or + shape_checkpoint.json of a run
    /// stopped at a checkpoint): its shape prior is evaluated.
    #[arg(long, env = "PHYSNAP_WEIGHTS", default_value = "weights")]
    pub(crate) weights: PathBuf,
    /// Imported data set whose test split is reconstructed.
    #[arg(long, env = "PHYSNAP_DATA")]
    pub(crate) data: PathBuf,
    /// Test objects (seeded choice); 0: the whole test split.
    #[arg(long, env = "PHYSNAP_EVAL_OBJECTS", default_value_t = 0)]
    pub(crate) objects: usize,
    /// Joint states per object for the instantiation distance (method.md: 10).
    #[arg(long, env = "PHYSNAP_EVAL_STATES", default_value_t = 4)]
    pub(crate) states: usize,
    /// Surface points per state for the instantiation distance (method.md: 2048).
    #[arg(long, env = "PHYSNAP_EVAL_POINTS", default_value_t = 256)]
    pub(crate) points: usize,
    /// Marching-cubes grid cells per axis for the reconstructions.
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = 32)]
    pub(crate) resolution: usize,
    /// Seed (object choice, state sampling).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 12345)]
    pub(crate) seed: u64,
    /// Part shapes of the reconstructions: encoded (codes from the shape prior's encoder,
    /// meshed by its decoder), original (the originals' meshes on the projected graph: what
    /// the graph representation alone loses, the control) or analytic (the originals'
    /// primitive shapes meshed by marching cubes like decoded ones: what meshing alone loses).
    #[arg(long, env = "PHYSNAP_EVAL_SHAPES", default_value = "encoded", value_parser = ["encoded", "original", "analytic"])]
    pub(crate) shapes: String,
    /// Also write the report as JSON here.
    #[arg(long, env = "PHYSNAP_EVAL_OUT")]
    pub(crate) out: Option<PathBuf>,
}

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
pub(crate) fn reconstruction(a: EvalReconstructionArgs) -> anyhow::Result<()> {
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
