//! The training set: PartNet-Mobility-layout objects → graph records, normalised part meshes,
//! SDF samples and splits.
//!
//! Why it exists: the shape prior trains on per-part SDF samples in the normalised part frame,
//! the diffusion prior on NAP graph records; both need fixed, reproducible splits. This is
//! NAP's missing preprocessing (method.md §1, §4.5–4.6, §9 A3 and A16), written once for real
//! and synthetic data alike. Output layout:
//!
//! ```text
//! OUT/dataset.json                       index: objects, splits, categories, sample counts, skips
//! OUT/objects/<id>/object.json           merged object (object frame, metres)
//! OUT/objects/<id>/graph.npy             (1, 1444) raw graph, identity slot order (real nodes first)
//! OUT/objects/<id>/part<k>.obj           part mesh in the normalised frame q = (p − t)/κ, κ = 2‖b‖
//! OUT/objects/<id>/part<k>_uniform.npy   (U, 4) x y z sdf, uniform in [−0.55, 0.55]³
//! OUT/objects/<id>/part<k>_near.npy      (N, 4) surface + N(0, σ²), σ ∈ {0.01, 0.005} (half each)
//! OUT/objects/<id>/part<k>_surface.npy   (S, 3) outer-surface points (encoder input)
//! ```
//!
//! Normalisation (§9 A3 resolved): centre = the part's box centre, scale κ = 2‖b‖₂ = the box
//! diagonal, so the part box has unit diagonal and fits [−0.5, 0.5]³. SDF values are in
//! normalised units (object-frame distance / κ), negative inside. Signs: exact analytic SDF
//! for synthetic parts (`physnap_shapes.json`); for imported meshes, the generalised winding
//! number (robust to PartNet-Mobility's overlapping, non-watertight leaf meshes) with
//! unsigned distance to the closest triangle.
//!
//! Splits: per category, objects are ordered by a hash of (seed, id) and cut 80 / 10 / 10 %
//! (train / val / test, at least one val and one test object per category with ≥ 3 objects).
//! Deterministic, stratified by category, by object (never by part).

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use rayon::prelude::*;
use serde_json::{Value, json};

use super::DataError;
use super::categories::{CATEGORIES, category_index};
use super::partnet::{ImportedObject, read_object};
use super::rng::Rng;
use crate::graph::{FLAT_DIM, encode};
use crate::io::npy;
use crate::mesh::bvh::MeshBvh;
use crate::mesh::{TriMesh, obj};
use crate::shape::{AnalyticSdf, PartShape, Sdf};

/// Dataset format tag in `dataset.json`.
pub const FORMAT: &str = "physnap.dataset/v1";
/// Half-width of the uniform sampling cube (normalised frame), as the meshing domain.
pub const UNIFORM_HALF: f64 = 0.55;

/// Import options.
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// Seed for SDF sampling and splits.
    pub seed: u64,
    /// Uniform SDF samples per part.
    pub uniform: usize,
    /// Near-surface SDF samples per part.
    pub near: usize,
    /// Surface points per part.
    pub surface: usize,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            seed: 0,
            uniform: 4096,
            near: 4096,
            surface: 1024,
        }
    }
}

/// One imported object in the index.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    /// Object id (source folder name).
    pub id: String,
    /// Canonical category.
    pub category: String,
    /// Fixed category index.
    pub category_index: usize,
    /// "train", "val" or "test".
    pub split: &'static str,
    /// Nodes after merging fixed joints.
    pub parts: usize,
    /// Semantic labels per part.
    pub labels: Vec<String>,
    /// Joint type names.
    pub joints: Vec<&'static str>,
}

/// What an import did.
#[derive(Debug, Clone, Default)]
pub struct ImportReport {
    /// Imported objects, sorted by id.
    pub entries: Vec<Entry>,
    /// Skipped objects: (folder, reason).
    pub skipped: Vec<(String, String)>,
    /// Non-fatal notes per object.
    pub notes: Vec<(String, String)>,
}

/// Object folders under `src` (those with a `mobility_v2.json`), sorted by name.
pub fn object_dirs(src: &Path) -> Result<Vec<PathBuf>, DataError> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(src)
        .map_err(DataError::io(src))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("mobility_v2.json").is_file())
        .collect();
    dirs.sort();
    Ok(dirs)
}

fn fnv(s: &str) -> u64 {
    s.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

/// Import every object under `src` into `out`. `progress(done, total)` is called as objects
/// finish (from worker threads). Broken objects are skipped with a reason; the run never
/// stops on one.
pub fn import_dir(
    src: &Path,
    out: &Path,
    opts: &ImportOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<ImportReport, DataError> {
    let dirs = object_dirs(src)?;
    std::fs::create_dir_all(out.join("objects")).map_err(DataError::io(out))?;
    let total = dirs.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<(String, Result<ImportedObject, DataError>)> = dirs
        .par_iter()
        .map(|dir| {
            let name = dir
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            let r = read_object(dir).and_then(|o| {
                write_object_samples(&o, &out.join("objects").join(&o.id), opts)?;
                Ok(o)
            });
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(n, total);
            (name, r)
        })
        .collect();

    let mut report = ImportReport::default();
    let mut imported = Vec::new();
    for (name, r) in results {
        match r {
            Ok(o) => {
                for note in &o.notes {
                    report.notes.push((name.clone(), note.clone()));
                }
                imported.push(o);
            }
            Err(reason) => report.skipped.push((name, reason.to_string())),
        }
    }
    let splits = assign_splits(&imported, opts.seed);
    for (o, split) in imported.iter().zip(splits) {
        report.entries.push(Entry {
            id: o.id.clone(),
            category: o.category.clone(),
            category_index: category_index(&o.category).unwrap_or(usize::MAX),
            split,
            parts: o.object.parts.len(),
            labels: o.labels.clone(),
            joints: o.object.joints.iter().map(|j| j.kind.as_str()).collect(),
        });
    }
    write_index(out, &report, opts)?;
    Ok(report)
}

/// Stratified, hash-ordered 80/10/10 split per category.
fn assign_splits(objs: &[ImportedObject], seed: u64) -> Vec<&'static str> {
    let mut out = vec!["train"; objs.len()];
    let mut cats: Vec<&str> = objs.iter().map(|o| o.category.as_str()).collect();
    cats.sort_unstable();
    cats.dedup();
    for cat in cats {
        let mut members: Vec<usize> = (0..objs.len())
            .filter(|&i| objs[i].category == cat)
            .collect();
        members.sort_by_key(|&i| {
            (
                fnv(&objs[i].id) ^ seed.wrapping_mul(0x9E37_79B9_7F4A_7C15),
                objs[i].id.clone(),
            )
        });
        let n = members.len();
        let (mut n_val, mut n_test) = (
            (n as f64 * 0.1).round() as usize,
            (n as f64 * 0.1).round() as usize,
        );
        if n >= 3 {
            n_val = n_val.max(1);
            n_test = n_test.max(1);
        }
        for (rank, &i) in members.iter().enumerate() {
            out[i] = if rank < n_test {
                "test"
            } else if rank < n_test + n_val {
                "val"
            } else {
                "train"
            };
        }
    }
    out
}

fn write_index(out: &Path, report: &ImportReport, opts: &ImportOptions) -> Result<(), DataError> {
    let split_ids = |s: &str| -> Vec<&str> {
        report
            .entries
            .iter()
            .filter(|e| e.split == s)
            .map(|e| e.id.as_str())
            .collect()
    };
    let index = json!({
        "format": FORMAT,
        "seed": opts.seed,
        "samples_per_part": { "uniform": opts.uniform, "near": opts.near, "surface": opts.surface },
        "normalisation": "q = (p - box_centre) / (2 * |half_extents|); sdf in normalised units, negative inside",
        "categories": CATEGORIES.to_vec(),
        "splits": { "train": split_ids("train"), "val": split_ids("val"), "test": split_ids("test") },
        "objects": report.entries.iter().map(|e| json!({
            "id": e.id, "category": e.category, "category_index": e.category_index,
            "split": e.split, "parts": e.parts, "labels": e.labels, "joints": e.joints,
        })).collect::<Vec<Value>>(),
        "skipped": report.skipped.iter().map(|(id, r)| json!({ "id": id, "reason": r })).collect::<Vec<Value>>(),
        "notes": report.notes.iter().map(|(id, r)| json!({ "id": id, "note": r })).collect::<Vec<Value>>(),
    });
    let path = out.join("dataset.json");
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&index).unwrap_or_default(),
    )
    .map_err(DataError::io(&path))
}

/// The SDF of part `k` in its normalised frame: analytic when available, else from the mesh.
enum PartSdf<'a> {
    Analytic(AnalyticSdf<'a>),
    Mesh(&'a MeshBvh),
}

impl PartSdf<'_> {
    fn eval(&self, pts: &[[f32; 3]]) -> Vec<f32> {
        let mut out = vec![0.0; pts.len()];
        match self {
            PartSdf::Analytic(a) => a.eval_batch(pts, &mut out),
            PartSdf::Mesh(b) => b.signed_distances(pts, &mut out),
        }
        out
    }
}

/// Write the records and samples of one imported object into `dir`.
pub fn write_object_samples(
    o: &ImportedObject,
    dir: &Path,
    opts: &ImportOptions,
) -> Result<(), DataError> {
    std::fs::create_dir_all(dir).map_err(DataError::io(dir))?;
    let obj_path = dir.join("object.json");
    std::fs::write(&obj_path, crate::io::object_json::to_string(&o.object))
        .map_err(DataError::io(&obj_path))?;
    let slots: Vec<usize> = (0..o.object.parts.len()).collect();
    let graph = encode(&o.object, &slots)?.flatten();
    write_npy(&dir.join("graph.npy"), 1, FLAT_DIM, &graph)?;
    let mut rng = Rng::fork(opts.seed, fnv(&o.id));
    for (k, (part, mesh)) in o.object.parts.iter().zip(&o.meshes).enumerate() {
        let kappa = part.kappa();
        let t = part.center;
        let normalised = mesh.clone().map_positions(|p| {
            let q = (Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) - t) / kappa;
            [q.x as f32, q.y as f32, q.z as f32]
        });
        let path = dir.join(format!("part{k}.obj"));
        std::fs::write(&path, obj::to_text(&normalised)).map_err(DataError::io(&path))?;
        let bvh = MeshBvh::new(&normalised.positions, &normalised.triangles).map_err(|d| {
            DataError::Malformed {
                path: path.clone(),
                detail: d.to_string(),
            }
        })?;
        let prims: &[crate::shape::Primitive] = match &part.shape {
            PartShape::Primitives(p) => p,
            _ => &[],
        };
        let sdf = if o.analytic {
            PartSdf::Analytic(AnalyticSdf {
                primitives: prims,
                half_extents: part.half_extents,
                kappa,
            })
        } else {
            PartSdf::Mesh(&bvh)
        };
        let surface = outer_surface(&bvh, &sdf, opts.surface.max(opts.near), &mut rng);
        if surface.is_empty() {
            return Err(DataError::Malformed {
                path: path.clone(),
                detail: format!("part {k} has no surface to sample"),
            });
        }
        let uniform: Vec<[f32; 3]> = (0..opts.uniform)
            .map(|_| std::array::from_fn(|_| rng.range(-UNIFORM_HALF, UNIFORM_HALF) as f32))
            .collect();
        let near: Vec<[f32; 3]> = (0..opts.near)
            .map(|i| {
                let s = surface[i % surface.len()];
                let sigma = if i % 2 == 0 { 0.01 } else { 0.005 };
                std::array::from_fn(|a| s[a] + (sigma * rng.gauss()) as f32)
            })
            .collect();
        for (name, pts) in [("uniform", &uniform), ("near", &near)] {
            let d = sdf.eval(pts);
            let rows: Vec<f32> = pts
                .iter()
                .zip(&d)
                .flat_map(|(p, v)| [p[0], p[1], p[2], *v])
                .collect();
            write_npy(
                &dir.join(format!("part{k}_{name}.npy")),
                pts.len(),
                4,
                &rows,
            )?;
        }
        let surf: Vec<f32> = surface
            .iter()
            .take(opts.surface)
            .flatten()
            .copied()
            .collect();
        write_npy(
            &dir.join(format!("part{k}_surface.npy")),
            surf.len() / 3,
            3,
            &surf,
        )?;
    }
    Ok(())
}

fn write_npy(path: &Path, rows: usize, cols: usize, data: &[f32]) -> Result<(), DataError> {
    std::fs::write(path, npy::to_bytes(rows, cols, data)).map_err(DataError::io(path))
}

/// `n` points on the part's *outer* surface. For analytic unions, samples on faces buried inside
/// another primitive of the same part are dropped (the concatenated mesh has internal faces).
fn outer_surface(bvh: &MeshBvh, sdf: &PartSdf<'_>, n: usize, rng: &mut Rng) -> Vec<[f32; 3]> {
    let mut out = Vec::with_capacity(n);
    for _round in 0..8 {
        let want = (n - out.len()) * 2 + 16;
        let cand: Vec<[f32; 3]> = bvh
            .sample_surface(want, &mut || rng.uniform())
            .into_iter()
            .map(|(p, _)| p)
            .collect();
        let keep: Vec<bool> = match sdf {
            PartSdf::Analytic(_) => sdf.eval(&cand).iter().map(|d| *d > -1e-5).collect(),
            PartSdf::Mesh(_) => vec![true; cand.len()],
        };
        out.extend(
            cand.into_iter()
                .zip(keep)
                .filter(|(_, k)| *k)
                .map(|(p, _)| p),
        );
        if out.len() >= n {
            out.truncate(n);
            break;
        }
    }
    out
}

/// Meshes of an imported dataset object in the object frame (from its normalised part OBJs).
pub fn load_object_meshes(
    obj_dir: &Path,
) -> Result<(crate::object::ArticulatedObject, Vec<TriMesh>), DataError> {
    let object = crate::io::object_json::read(&obj_dir.join("object.json")).map_err(|e| {
        DataError::Malformed {
            path: obj_dir.join("object.json"),
            detail: e.to_string(),
        }
    })?;
    let mut meshes = Vec::with_capacity(object.parts.len());
    for (k, part) in object.parts.iter().enumerate() {
        let path = obj_dir.join(format!("part{k}.obj"));
        let text = std::fs::read_to_string(&path).map_err(DataError::io(&path))?;
        let m = obj::parse(&text).map_err(|d| DataError::Malformed {
            path: path.clone(),
            detail: d.to_string(),
        })?;
        let (kappa, t) = (part.kappa() as f32, part.center.map(|v| v as f32));
        meshes.push(
            m.map_positions(|q| [t.x + kappa * q[0], t.y + kappa * q[1], t.z + kappa * q[2]]),
        );
    }
    Ok((object, meshes))
}
