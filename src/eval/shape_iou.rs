//! Shape IoU of a trained shape prior (`physnap eval shape`, and the validation IoU of `train shape`):
//! occupancy of `SDF < 0` against the ground truth on a grid of cell centres, per part and by the
//! thinnest primitive a part has.

use crate::mesh::DOMAIN_HALF;
use crate::mesh::bvh::MeshBvh;
use crate::model::cpu;
use crate::model::host_decoder::HostDecoder;
use crate::model::shape_prior::ShapePrior;
use crate::shape::{AnalyticSdf, PartShape, Sdf};
use crate::train::TrainError;
use crate::train::shape::*;
use burn::module::Module;
use burn::tensor::{Tensor, TensorData};
use rayon::prelude::*;
use std::path::Path;

/// Cell-centre grid over [−0.55, 0.55]³, x fastest: where `eval shape` samples both
/// occupancies of its IoU.
pub fn iou_grid(res: usize) -> Vec<[f32; 3]> {
    let h = DOMAIN_HALF as f64;
    let c = |i: usize| (-h + 2.0 * h * (i as f64 + 0.5) / res as f64) as f32;
    let mut g = Vec::with_capacity(res * res * res);
    for k in 0..res {
        for j in 0..res {
            for i in 0..res {
                g.push([c(i), c(j), c(k)]);
            }
        }
    }
    g
}

/// Ground-truth occupancy of a part on `grid`: analytic primitives from `object.json` when the
/// part has them, else the winding number of its normalised mesh `part<k>.obj`.
pub(crate) fn gt_occupancy(
    data: &Path,
    p: &PartRef,
    grid: &[[f32; 3]],
) -> Result<Vec<bool>, TrainError> {
    let dir = data.join("objects").join(&p.id);
    let obj_path = dir.join("object.json");
    let object = crate::io::object_json::read(&obj_path)
        .map_err(|e| TrainError::data(&obj_path, e.to_string()))?;
    let part = object.parts.get(p.k).ok_or_else(|| {
        TrainError::data(
            &obj_path,
            format!("part {} missing ({} parts)", p.k, object.parts.len()),
        )
    })?;
    const CHUNK: usize = 4096;
    if let PartShape::Primitives(prims) = &part.shape {
        let sdf = AnalyticSdf {
            primitives: prims,
            half_extents: part.half_extents,
            kappa: part.kappa(),
        };
        return Ok(grid
            .par_chunks(CHUNK)
            .flat_map_iter(|pts| {
                let mut out = vec![0.0f32; pts.len()];
                sdf.eval_batch(pts, &mut out);
                out.into_iter().map(|d| d < 0.0)
            })
            .collect());
    }
    let mesh_path = dir.join(format!("part{}.obj", p.k));
    let text = std::fs::read_to_string(&mesh_path).map_err(TrainError::io(&mesh_path))?;
    let mesh =
        crate::mesh::obj::parse(&text).map_err(|e| TrainError::data(&mesh_path, e.to_string()))?;
    let bvh = MeshBvh::new(&mesh.positions, &mesh.triangles)
        .map_err(|e| TrainError::data(&mesh_path, e.to_string()))?;
    Ok(grid.par_iter().map(|q| bvh.is_inside(*q)).collect())
}

/// Per-part IoU and mean L1 of `model` (inference mode) on the val parts.
pub(crate) fn evaluate(
    model: &ShapePrior,
    val: &[ValPart],
    cfg: &ShapeTrainConfig,
    grid: &[f32],
    enc: &Encoding,
) -> (Vec<f64>, f64) {
    if val.is_empty() {
        return (Vec::new(), f64::NAN);
    }
    let device = cpu();
    let (v, q) = (val.len(), cfg.queries_per_part);
    // The grid decodes (and the code fitting) run on the value-only host decoder (same
    // function, 3-4× faster).
    let host = HostDecoder::new(&model.decoder);
    let surf: Vec<f32> = val.iter().flat_map(|p| p.surface.iter().copied()).collect();
    let fit: Vec<&FitSamples> = val.iter().map(|p| &p.fit).collect();
    let codes = encode_codes(model, &host, surf, cfg.surface_points, &fit, enc);
    let codes = Tensor::from_data(TensorData::new(codes, [v, model.decoder.latent()]), &device);
    let features = model.decoder.code_features(codes);
    let queries: Vec<f32> = val.iter().flat_map(|p| p.queries.iter().copied()).collect();
    let pred = to_vec(model.decoder.sdf_with_features(
        Tensor::from_data(TensorData::new(queries, [v, q, 3]), &device),
        features.clone(),
    ));
    let targets = val.iter().flat_map(|p| p.targets.iter());
    let l1 = pred
        .iter()
        .zip(targets)
        .map(|(a, b)| (a - b).abs() as f64)
        .sum::<f64>()
        / (v * q) as f64;
    let features = to_vec(features);
    let grid: Vec<[f32; 3]> = grid.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    let n = grid.len();
    let mut d = vec![0.0; n];
    let mut idx = vec![0; n];
    let mut ious = Vec::with_capacity(v);
    for (i, part) in val.iter().enumerate() {
        idx.fill(i);
        host.eval(&grid, &features, &idx, &mut d);
        ious.push(occupancy_iou(
            d.iter()
                .zip(&part.occupancy)
                .map(|(dv, &gt)| (*dv < 0.0, gt)),
        ));
    }
    (ious, l1)
}

/// IoU of two occupancies given as (a, b) pairs per grid point; 1 when both are empty.
pub fn occupancy_iou(pairs: impl Iterator<Item = (bool, bool)>) -> f64 {
    let (mut inter, mut union) = (0usize, 0usize);
    for (a, b) in pairs {
        inter += (a && b) as usize;
        union += (a || b) as usize;
    }
    if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    }
}

/// IoU of one evaluated part, with what makes a part hard for the 64³ grid.
#[derive(Debug, Clone, PartialEq)]
pub struct PartIou {
    /// `<id>_<k>`.
    pub key: String,
    /// IoU of `SDF < 0` against ground truth on the grid.
    pub iou: f64,
    /// Number of analytic primitives (None: a mesh part).
    pub primitives: Option<usize>,
    /// Thinnest box extent over the part's normalisation scale κ (the AABB diagonal), i.e. in
    /// normalised units where the grid spacing is 1.1 / resolution.
    pub thinnest: f64,
    /// Smallest extent of the thinnest analytic primitive over κ (normalised units): the
    /// part's thinnest wall, panel or detail. None for a mesh part. A cabinet shell's walls
    /// are often under one 64³ cell, where a surface error of a quarter cell moves a whole
    /// wall's cells in or out of the IoU.
    pub thinnest_primitive: Option<f64>,
}

/// The smallest extent of `part`'s thinnest primitive over its κ (see [`PartIou`]); None
/// when the part has no analytic primitives.
pub fn thinnest_primitive(part: &crate::object::Part) -> Option<f64> {
    match &part.shape {
        PartShape::Primitives(prims) => prims
            .iter()
            .map(|p| {
                let (lo, hi) = p.bounds();
                (hi - lo).min() / part.kappa()
            })
            .min_by(f64::total_cmp),
        _ => None,
    }
}

/// Parts per batch of [`evaluate_shape_prior`] (bounds the ground-truth grids in memory).
pub(crate) const EVAL_CHUNK: usize = 32;

/// Evaluate `model` on `n` parts of `split` (spread evenly over it) exactly as training
/// evaluates its val parts (`cfg.iou_resolution`³ grid), with codes made by `enc`
/// ([`Encoding`]; training's evaluations use NAP's: the first `cfg.surface_points` surface
/// points). `progress(done, total)` after every batch of parts. Returns per-part IoUs and the
/// mean L1 on the parts' first `cfg.queries_per_part` samples.
pub fn evaluate_shape_prior(
    model: &ShapePrior,
    data: &Path,
    cfg: &ShapeTrainConfig,
    split: &str,
    n: usize,
    enc: &Encoding,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<PartIou>, f64), TrainError> {
    cfg.validate()?;
    enc.validate()?;
    let all = read_index(data)?;
    let refs = split_selection(&all, split, n);
    if refs.is_empty() {
        return Err(TrainError::data(
            data.join("dataset.json"),
            format!("no parts in split {split:?}"),
        ));
    }
    let grid_pts = iou_grid(cfg.iou_resolution);
    let grid: Vec<f32> = grid_pts.iter().flatten().copied().collect();
    let model = model.valid();
    let (mut per_part, mut l1_sum) = (Vec::with_capacity(refs.len()), 0.0);
    for chunk in refs.chunks(EVAL_CHUNK) {
        let parts: Vec<ValPart> = chunk
            .par_iter()
            .map(|p| load_val_part(data, p, cfg, enc, &grid_pts))
            .collect::<Result<_, _>>()?;
        let (ious, l1) = evaluate(&model, &parts, cfg, &grid, enc);
        l1_sum += l1 * chunk.len() as f64;
        for (p, iou) in chunk.iter().zip(ious) {
            let file = data.join("objects").join(&p.id).join("object.json");
            let obj = crate::io::object_json::read(&file)
                .map_err(|e| TrainError::data(&file, e.to_string()))?;
            let part = obj.parts.get(p.k).ok_or_else(|| {
                TrainError::data(&file, format!("no part {} (dataset.json lists it)", p.k))
            })?;
            per_part.push(PartIou {
                key: format!("{}_{}", p.id, p.k),
                iou,
                primitives: match &part.shape {
                    PartShape::Primitives(prims) => Some(prims.len()),
                    _ => None,
                },
                thinnest: 2.0 * part.half_extents.min() / part.kappa(),
                thinnest_primitive: thinnest_primitive(part),
            });
        }
        progress(per_part.len(), refs.len());
    }
    Ok((per_part, l1_sum / refs.len() as f64))
}
