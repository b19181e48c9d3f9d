//! The training data of the shape prior: the imported parts' SDF samples and surface points,
//! loaded once, the validation parts, and the batches drawn from them each step.

#[allow(unused_imports)]
use super::*;
use crate::data::rng::Rng;
use crate::io::npy;
use crate::train::TrainError;
use burn::tensor::Tensor;
use serde_json::{Value, json};

/// One part of the data set.
#[derive(Debug, Clone)]
pub(crate) struct PartRef {
    pub(crate) id: String,
    pub(crate) k: usize,
    pub(crate) split: String,
    /// The object's category name (dataset.json's `category`), when listed.
    pub(crate) category: Option<String>,
}

impl PartRef {
    pub(crate) fn file(&self, data: &Path, kind: &str) -> PathBuf {
        data.join("objects")
            .join(&self.id)
            .join(format!("part{}_{kind}.npy", self.k))
    }
}

/// A part's samples in memory.
pub(crate) struct PartSamples {
    /// U × 4 (x y z sdf).
    pub(crate) uniform: Vec<f32>,
    /// N × 4.
    pub(crate) near: Vec<f32>,
    /// S × 3.
    pub(crate) surface: Vec<f32>,
}

/// A val part: encoder input (every view), query samples, the samples a code fit uses, and
/// the ground-truth occupancy.
pub(crate) struct ValPart {
    pub(crate) surface: Vec<f32>,
    pub(crate) queries: Vec<f32>,
    pub(crate) targets: Vec<f32>,
    pub(crate) fit: FitSamples,
    pub(crate) occupancy: Vec<bool>,
}

/// The SDF samples a part's code is fitted to ([`Encoding::fit_queries`] rows; empty when
/// the encoding fits nothing).
#[derive(Default)]
pub(crate) struct FitSamples {
    /// [n × 3].
    pub(crate) queries: Vec<f32>,
    /// [n].
    pub(crate) targets: Vec<f32>,
}

/// The first `n / 2` uniform and the first `n / 2` near-surface samples of `s` (cycled when a
/// file has fewer): the deterministic evaluation rows, as NAP's evaluation takes chunk 0.
pub(crate) fn first_samples(s: &PartSamples, n: usize) -> FitSamples {
    let half = n / 2;
    let mut out = FitSamples {
        queries: Vec::with_capacity(2 * half * 3),
        targets: Vec::with_capacity(2 * half),
    };
    for rows in [&s.uniform, &s.near] {
        let m = rows.len() / 4;
        for i in 0..half {
            let r = &rows[4 * (i % m)..4 * (i % m) + 4];
            out.queries.extend_from_slice(&r[..3]);
            out.targets.push(r[3]);
        }
    }
    out
}

/// All parts of `data/dataset.json` in dataset order (objects, then part index).
pub(crate) fn read_index(data: &Path) -> Result<Vec<PartRef>, TrainError> {
    let path = data.join("dataset.json");
    let text = std::fs::read_to_string(&path).map_err(TrainError::io(&path))?;
    let v: Value =
        serde_json::from_str(&text).map_err(|e| TrainError::data(&path, e.to_string()))?;
    let objects = v["objects"]
        .as_array()
        .ok_or_else(|| TrainError::data(&path, "no \"objects\" array"))?;
    let mut parts = Vec::new();
    for (i, o) in objects.iter().enumerate() {
        let field = |k: &str| TrainError::data(&path, format!("objects[{i}].{k} is missing"));
        let id = o["id"].as_str().ok_or_else(|| field("id"))?;
        let split = o["split"].as_str().ok_or_else(|| field("split"))?;
        let n = o["parts"].as_u64().ok_or_else(|| field("parts"))? as usize;
        if id.is_empty() || id.contains(['/', '\\']) || id.starts_with('.') {
            return Err(TrainError::data(
                &path,
                format!("objects[{i}].id {id:?} is not a folder name"),
            ));
        }
        let category = o["category"].as_str().map(str::to_string);
        for k in 0..n {
            parts.push(PartRef {
                id: id.to_string(),
                k,
                split: split.to_string(),
                category: category.clone(),
            });
        }
    }
    Ok(parts)
}

/// Read an NPY array and check its column count.
pub(crate) fn read_rows(path: &Path, cols: usize) -> Result<(usize, Vec<f32>), TrainError> {
    let (rows, c, data) = npy::read(path).map_err(|e| TrainError::data(path, e.to_string()))?;
    if c != cols {
        return Err(TrainError::data(
            path,
            format!("expected {cols} columns, got {c}"),
        ));
    }
    if rows == 0 {
        return Err(TrainError::data(path, "no rows"));
    }
    if let Some(i) = data.iter().position(|v| !v.is_finite()) {
        return Err(TrainError::data(
            path,
            format!("non-finite value at row {}, column {}", i / cols, i % cols),
        ));
    }
    Ok((rows, data))
}

pub(crate) fn load_part(data: &Path, p: &PartRef) -> Result<PartSamples, TrainError> {
    Ok(PartSamples {
        uniform: read_rows(&p.file(data, "uniform"), 4)?.1,
        near: read_rows(&p.file(data, "near"), 4)?.1,
        surface: read_rows(&p.file(data, "surface"), 3)?.1,
    })
}

/// The first `n` points of `surface` (S × 3), cycled when S < n (max-pooling makes repeats
/// harmless: a duplicated point adds nothing to the pooled feature).
pub(crate) fn first_points(surface: &[f32], n: usize) -> Vec<f32> {
    let s = surface.len() / 3;
    (0..n)
        .flat_map(|i| {
            let j = i % s;
            [surface[3 * j], surface[3 * j + 1], surface[3 * j + 2]]
        })
        .collect()
}

pub(crate) fn load_val_part(
    data: &Path,
    p: &PartRef,
    cfg: &ShapeTrainConfig,
    enc: &Encoding,
    grid: &[[f32; 3]],
) -> Result<ValPart, TrainError> {
    let s = load_part(data, p)?;
    let FitSamples { queries, targets } = first_samples(&s, cfg.queries_per_part);
    Ok(ValPart {
        surface: first_points(&s.surface, cfg.surface_points * enc.views),
        queries,
        targets,
        fit: if enc.fit_steps > 0 {
            first_samples(&s, enc.fit_queries)
        } else {
            FitSamples::default()
        },
        occupancy: gt_occupancy(data, p, grid)?,
    })
}

/// One training batch on `device`: (query points [B, Q, 3], targets [B, Q], surface [B, S, 3]).
/// One step's training batch on the host: B parts × Q queries (xyz, target SDF) and B × S
/// encoder points.
pub(crate) struct Batch {
    /// [B × Q × 3].
    pub(crate) pts: Vec<f32>,
    /// [B × Q].
    pub(crate) tgt: Vec<f32>,
    /// [B × S × 3].
    pub(crate) surf: Vec<f32>,
    /// [B × F] fixed codes (`codes_from`); empty when the encoder makes them.
    pub(crate) codes: Vec<f32>,
}

impl Batch {
    /// Parts `start..end` of the batch.
    pub(crate) fn slice(&self, start: usize, end: usize, cfg: &ShapeTrainConfig) -> Batch {
        let (q, s) = (cfg.queries_per_part, cfg.surface_points);
        let f = self.codes.len() / (self.tgt.len() / q).max(1);
        Batch {
            pts: self.pts[start * q * 3..end * q * 3].to_vec(),
            tgt: self.tgt[start * q..end * q].to_vec(),
            surf: self.surf[start * s * 3..end * s * 3].to_vec(),
            codes: self.codes[start * f..end * f].to_vec(),
        }
    }
}

/// One step's batch of the parts `order`; `codes` ([`FixedCodes`]) adds their fixed codes.
/// The random draws are the same with or without them.
pub(crate) fn sample_batch(
    parts: &[PartSamples],
    order: &[usize],
    cfg: &ShapeTrainConfig,
    codes: Option<&FixedCodes>,
    rng: &mut Rng,
) -> Batch {
    let (b, q, s) = (order.len(), cfg.queries_per_part, cfg.surface_points);
    let mut pts = Vec::with_capacity(b * q * 3);
    let mut tgt = Vec::with_capacity(b * q);
    let mut surf = Vec::with_capacity(b * s * 3);
    let mut idx: Vec<usize> = Vec::new();
    let near = cfg.near_queries();
    for &pi in order {
        let part = &parts[pi];
        for (rows, count) in [(&part.uniform, q - near), (&part.near, near)] {
            let n = rows.len() / 4;
            for _ in 0..count {
                let r = rng.int(0, n - 1);
                pts.extend_from_slice(&rows[4 * r..4 * r + 3]);
                tgt.push(rows[4 * r + 3]);
            }
        }
        let n = part.surface.len() / 3;
        if n >= s {
            // Partial Fisher–Yates: s distinct points.
            idx.clear();
            idx.extend(0..n);
            for i in 0..s {
                let j = rng.int(i, n - 1);
                idx.swap(i, j);
            }
            for &j in &idx[..s] {
                surf.extend_from_slice(&part.surface[3 * j..3 * j + 3]);
            }
        } else {
            for _ in 0..s {
                let j = rng.int(0, n - 1);
                surf.extend_from_slice(&part.surface[3 * j..3 * j + 3]);
            }
        }
    }
    let codes = codes.map_or_else(Vec::new, |c| {
        order
            .iter()
            .flat_map(|&pi| c.row(pi).iter().copied())
            .collect()
    });
    Batch {
        pts,
        tgt,
        surf,
        codes,
    }
}

/// The fixed codes of a `codes_from` run: one row per training part, in the run's part order,
/// and the encoding that made them.
pub(crate) struct FixedCodes {
    /// `parts × latent` codes.
    pub(crate) codes: Vec<f32>,
    pub(crate) latent: usize,
    pub(crate) encoding: Encoding,
    /// The codebook directory, and its number of rows (every part of every split).
    pub(crate) dir: PathBuf,
    pub(crate) rows: usize,
}

impl FixedCodes {
    pub(crate) fn row(&self, part: usize) -> &[f32] {
        &self.codes[part * self.latent..(part + 1) * self.latent]
    }

    /// The rows of `dir`'s codebook for `train`'s parts, matched by key (`<object>_<part>`);
    /// refuses codes of another width, a part without a code (a codebook of another data set)
    /// and an encoding it cannot read, naming the file.
    pub(crate) fn read(
        dir: &Path,
        latent: usize,
        train: &[&PartRef],
    ) -> Result<FixedCodes, TrainError> {
        let book = read_codebook(dir, latent)?;
        let index_path = dir.join(CODEBOOK_INDEX_FILE);
        let encoding = Encoding::of_report(&json!({ "encoding": book.encoding }), &index_path)?;
        let rows: std::collections::HashMap<&str, usize> = book
            .keys
            .iter()
            .enumerate()
            .filter_map(|(r, k)| k["key"].as_str().map(|k| (k, r)))
            .collect();
        let mut codes = Vec::with_capacity(train.len() * latent);
        for p in train {
            let key = format!("{}_{}", p.id, p.k);
            let r = *rows.get(key.as_str()).ok_or_else(|| {
                TrainError::data(
                    &index_path,
                    format!(
                        "training part {key} has no code ({} codes; made from another data set?)",
                        book.keys.len()
                    ),
                )
            })?;
            codes.extend_from_slice(&book.codes[r * latent..(r + 1) * latent]);
        }
        Ok(FixedCodes {
            codes,
            latent,
            encoding,
            dir: dir.to_path_buf(),
            rows: book.keys.len(),
        })
    }

    /// Copy the codebook, byte for byte, into `out` (the run's codebook: the codes its decoder
    /// was trained on); returns its number of rows.
    pub(crate) fn copy_to(&self, out: &Path) -> Result<usize, TrainError> {
        for file in [CODEBOOK_FILE, CODEBOOK_INDEX_FILE] {
            let (src, dst) = (self.dir.join(file), out.join(file));
            if src != dst {
                let bytes = std::fs::read(&src).map_err(TrainError::io(&src))?;
                write_atomic(&dst, &bytes)?;
            }
        }
        Ok(self.rows)
    }
}

pub(crate) fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data()
        .try_into_vec::<f32>()
        .expect("model outputs are f32")
}

/// The val parts a run evaluates: `cfg.val_parts` spread evenly over the val split.
pub(crate) fn val_selection<'a>(all: &'a [PartRef], cfg: &ShapeTrainConfig) -> Vec<&'a PartRef> {
    split_selection(all, "val", cfg.val_parts)
}

/// `n` parts of `split` spread evenly over it (dataset order); all of them when it has fewer.
pub(crate) fn split_selection<'a>(all: &'a [PartRef], split: &str, n: usize) -> Vec<&'a PartRef> {
    let of_split: Vec<&PartRef> = all.iter().filter(|p| p.split == split).collect();
    let n = n.min(of_split.len());
    (0..n).map(|i| of_split[i * of_split.len() / n]).collect()
}
