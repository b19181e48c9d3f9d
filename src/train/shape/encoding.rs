//! How a part's shape code is made from its points (`Encoding`: encoder views, then an
//! optional fit to the part's SDF samples), and `train encode`, which encodes a whole data set.

#[allow(unused_imports)]
use super::*;
use crate::model::cpu;
use crate::model::host_decoder::HostDecoder;
use crate::model::shape_prior::{ShapeDecoder, ShapePrior};
use crate::train::TrainError;
use burn::tensor::{Tensor, TensorData};
use rayon::prelude::*;
use serde_json::{Value, json};

/// How a part's code is made from its data: what the codebook (and so the denoiser's training
/// codes), `eval shape` and `eval reconstruction` use.
///
/// ```text
/// z₀ = (1/V) Σ_v E(P_v)        P_v: surface points v·S … (v+1)·S − 1 of the part (cycled)
/// z  = argmin_z mean_r |f(q_r; z) − s_r| + λ ‖z − z₀‖²   by `fit_steps` Adam steps from z₀
///      (lr FIT_LR), over the part's first fit_queries/2 uniform and near-surface samples,
///      decoder frozen; λ = `fit_prox` (0: the plain fit)
/// ```
///
/// V = 1 and no fit is NAP's encoding (one encoder call on the first S points). Averaging the
/// views evens out which S points the encoder happens to see; the fit is DeepSDF's
/// auto-decoder inference started from the encoder's code. Both use only what the data set
/// holds for every part, so the codebook's codes and the evaluated val codes come from the
/// same protocol. The pull toward z₀ keeps a fitted code near the encoder's codes: the plain
/// fit moves a code by a median 0.215 (the encoder's codes lie 0.089 apart) and spreads the
/// codes out of the ≈ 16 directions that hold 98.7 % of the encoder codes' variance; on the
/// decoder it was measured with, any pull (λ = 0.01 … 1) gave back 0.02 of the fit's IoU, so
/// no recipe uses it yet. A report without an `"encoding"` entry
/// was made by NAP's encoding; one without `"fit_prox"`, by the plain fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Encoding {
    /// Encoder calls per part, each on the next `surface_points` surface points; the code is
    /// their mean.
    pub views: usize,
    /// Adam steps fitting each code to its part's SDF samples (0: the encoder's code).
    pub fit_steps: usize,
    /// SDF samples a part's fit uses (half uniform, half near-surface; even).
    pub fit_queries: usize,
    /// Weight λ of the fit's pull λ ‖z − z₀‖² toward the encoder's code (0: none).
    pub fit_prox: f32,
}

impl Default for Encoding {
    fn default() -> Self {
        Encoding {
            views: 1,
            fit_steps: 0,
            fit_queries: 2048,
            fit_prox: 0.0,
        }
    }
}

/// Most encoder views per part.
pub const MAX_ENCODER_VIEWS: usize = 64;

/// Most fitting steps per code.
pub const MAX_FIT_STEPS: usize = 1000;

/// Most SDF samples per part a fit uses.
pub const MAX_FIT_QUERIES: usize = 8192;

/// Largest weight of the fit's pull toward the encoder's code.
pub const MAX_FIT_PROX: f32 = 1000.0;

impl Encoding {
    /// Check every field against its range; the error names the field, the limit and the
    /// value.
    pub fn validate(&self) -> Result<(), TrainError> {
        if !(1..=MAX_ENCODER_VIEWS).contains(&self.views) {
            return Err(TrainError::config(
                "encoder_views",
                format!("between 1 and {MAX_ENCODER_VIEWS}"),
                self.views,
            ));
        }
        if self.fit_steps > MAX_FIT_STEPS {
            return Err(TrainError::config(
                "fit_steps",
                format!("at most {MAX_FIT_STEPS}"),
                self.fit_steps,
            ));
        }
        if !(2..=MAX_FIT_QUERIES).contains(&self.fit_queries) || !self.fit_queries.is_multiple_of(2)
        {
            return Err(TrainError::config(
                "fit_queries",
                format!("an even number between 2 and {MAX_FIT_QUERIES}"),
                self.fit_queries,
            ));
        }
        if !(0.0..=MAX_FIT_PROX).contains(&self.fit_prox) {
            return Err(TrainError::config(
                "fit_prox",
                format!("between 0 and {MAX_FIT_PROX}"),
                self.fit_prox,
            ));
        }
        Ok(())
    }

    /// The `"encoding"` entry of a shape report.
    pub fn to_json(&self) -> Value {
        json!({
            "views": self.views,
            "fit_steps": self.fit_steps,
            "fit_queries": self.fit_queries,
            "fit_lr": FIT_LR,
            "fit_prox": self.fit_prox,
        })
    }

    /// The encoding a shape report (`shape_train.json`, or a manifest's `training.shape`)
    /// records; NAP's single encoder call when it records none. `file` names the report in
    /// errors.
    pub fn of_report(report: &Value, file: &Path) -> Result<Encoding, TrainError> {
        let e = &report["encoding"];
        if e.is_null() {
            return Ok(Encoding::default());
        }
        let field = |k: &str| {
            e[k].as_u64().map(|v| v as usize).ok_or_else(|| {
                TrainError::data(file, format!("encoding.{k} is missing or not a count"))
            })
        };
        let enc = Encoding {
            views: field("views")?,
            fit_steps: field("fit_steps")?,
            fit_queries: field("fit_queries")?,
            fit_prox: match &e["fit_prox"] {
                Value::Null => 0.0,
                v => v.as_f64().ok_or_else(|| {
                    TrainError::data(file, "encoding.fit_prox is not a number".to_string())
                })? as f32,
            },
        };
        enc.validate()?;
        Ok(enc)
    }
}

/// Adam learning rate of [`fit_codes`].
pub const FIT_LR: f64 = 1e-2;

/// Codes [P × F] of P parts by `enc` ([`Encoding`]): `surface` holds each part's `enc.views`
/// × `s` encoder points in a row, `fit` each part's fit samples (unused without fitting).
pub(crate) fn encode_codes(
    model: &ShapePrior,
    host: &HostDecoder,
    surface: Vec<f32>,
    s: usize,
    fit: &[&FitSamples],
    enc: &Encoding,
) -> Vec<f32> {
    let (p, f, k) = (fit.len(), model.decoder.latent(), enc.views);
    let z = model.encoder.encode(Tensor::from_data(
        TensorData::new(surface, [p * k, s, 3]),
        &cpu(),
    ));
    let z = if k > 1 {
        z.reshape([p, k, f]).mean_dim(1).reshape([p, f])
    } else {
        z
    };
    let codes = to_vec(z);
    if enc.fit_steps == 0 {
        return codes;
    }
    fit_codes(
        &model.decoder,
        host,
        codes,
        fit,
        enc.fit_steps,
        enc.fit_prox,
    )
}

/// The decoder's best codes for parts with samples `fit`: `steps` Adam steps (lr [`FIT_LR`])
/// on each part's code, from `codes` [P × F], minimising the mean |f(q; z) − f_gt| over the
/// part's samples plus `prox` ‖z − z₀‖² (z₀ the code it started from), with the decoder
/// frozen (DeepSDF's auto-decoder inference). Each part's code moves by its own samples
/// only, so the result does not depend on how parts are batched.
pub(crate) fn fit_codes(
    decoder: &ShapeDecoder,
    host: &HostDecoder,
    mut codes: Vec<f32>,
    fit: &[&FitSamples],
    steps: usize,
    prox: f32,
) -> Vec<f32> {
    let (f, fw) = (host.latent(), host.feature_width());
    let start = codes.clone();
    let w_c = to_vec(decoder.fc_c.weight.val()); // [F, fw], row-major
    let pts: Vec<[f32; 3]> = fit
        .iter()
        .flat_map(|p| p.queries.chunks_exact(3).map(|c| [c[0], c[1], c[2]]))
        .collect();
    let tgt: Vec<f32> = fit.iter().flat_map(|p| p.targets.iter().copied()).collect();
    // Row r's part, and each part's 1 / n of its mean.
    let idx: Vec<usize> = fit
        .iter()
        .enumerate()
        .flat_map(|(i, p)| std::iter::repeat_n(i, p.targets.len()))
        .collect();
    let inv_n: Vec<f32> = fit.iter().map(|p| 1.0 / p.targets.len() as f32).collect();
    let (mut m, mut v) = (vec![0.0f32; codes.len()], vec![0.0f32; codes.len()]);
    let (b1, b2, eps) = (0.9f32, 0.999f32, 1e-8f32);
    for t in 1..=steps {
        let features = host.code_features(&codes);
        let g = host.feature_grads(&pts, &features, &idx, &|r, y| {
            (y - tgt[r]).signum() * inv_n[idx[r]]
        });
        let (c1, c2) = (1.0 - b1.powi(t as i32), 1.0 - b2.powi(t as i32));
        for (p, dh) in g.d_features.chunks_exact(fw).enumerate() {
            for i in 0..f {
                let row = &w_c[i * fw..(i + 1) * fw];
                let k = p * f + i;
                let dz: f32 = row.iter().zip(dh).map(|(a, b)| a * b).sum::<f32>()
                    + 2.0 * prox * (codes[k] - start[k]);
                m[k] = b1 * m[k] + (1.0 - b1) * dz;
                v[k] = b2 * v[k] + (1.0 - b2) * dz * dz;
                codes[k] -= FIT_LR as f32 * (m[k] / c1) / ((v[k] / c2).sqrt() + eps);
            }
        }
    }
    codes
}

/// Codes of parts `0..parts` of object `id` in `data`, made as the codebook makes them: by
/// `enc` from the first `surface_points` × `enc.views` points of each `part<k>_surface.npy`
/// (cycled if fewer) and, when it fits, the part's SDF samples; one encoder call for the
/// object.
pub fn encode_object_parts(
    model: &ShapePrior,
    data: &Path,
    id: &str,
    parts: usize,
    surface_points: usize,
    enc: &Encoding,
) -> Result<Vec<Vec<f32>>, TrainError> {
    if parts == 0 || surface_points == 0 {
        return Ok(Vec::new());
    }
    enc.validate()?;
    let refs: Vec<PartRef> = (0..parts)
        .map(|k| PartRef {
            id: id.to_string(),
            k,
            split: String::new(),
            category: None,
        })
        .collect();
    let host = HostDecoder::new(&model.decoder);
    let codes = encode_refs(model, &host, data, &refs, surface_points, enc)?;
    Ok(codes
        .chunks_exact(model.decoder.latent())
        .map(<[f32]>::to_vec)
        .collect())
}

/// Codes [P × F] of the parts `refs` by `enc`, read from `data` (surface points, and the SDF
/// samples when the encoding fits).
pub(crate) fn encode_refs(
    model: &ShapePrior,
    host: &HostDecoder,
    data: &Path,
    refs: &[PartRef],
    surface_points: usize,
    enc: &Encoding,
) -> Result<Vec<f32>, TrainError> {
    let loaded: Vec<(Vec<f32>, FitSamples)> = refs
        .par_iter()
        .map(|p| {
            let n = surface_points * enc.views;
            if enc.fit_steps == 0 {
                let (_, pts) = read_rows(&p.file(data, "surface"), 3)?;
                return Ok((first_points(&pts, n), FitSamples::default()));
            }
            let s = load_part(data, p)?;
            Ok((
                first_points(&s.surface, n),
                first_samples(&s, enc.fit_queries),
            ))
        })
        .collect::<Result<_, TrainError>>()?;
    let surface: Vec<f32> = loaded.iter().flat_map(|(s, _)| s.iter().copied()).collect();
    let fit: Vec<&FitSamples> = loaded.iter().map(|(_, f)| f).collect();
    Ok(encode_codes(
        model,
        host,
        surface,
        surface_points,
        &fit,
        enc,
    ))
}

/// What [`encode_shape_dir`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodeReport {
    /// Codebook rows (every part of every split of the data set).
    pub rows: usize,
    /// Encoder input: surface points per part.
    pub surface_points: usize,
}

/// Make a `train shape` output directory (`shape_prior.safetensors`, `shape_train.json`,
/// `codebook.npy` + `codebook.json`) for an already trained shape prior: its weights
/// (`weights_file`) and its training report (`report`, the `shape_train.json` it was trained
/// with; a weights manifest keeps it under `training.shape`), with every part of `data`
/// encoded as `train shape` does at its end (first `config.surface_points` surface points).
///
/// Why: `train diffusion` trains on a shape directory, and the shipped weights keep only the
/// shape prior, not that directory. With this a new denoiser (a longer schedule, another seed,
/// another imported data set) trains on the shipped shape prior without retraining it; on the
/// data set the prior was trained on, the codes are those of the original run.
///
/// The report is copied with `data` and `codebook_rows` set to this encoding's and an
/// `"encoded_from"` entry naming `weights_file`.
pub fn encode_shape_dir(
    weights_file: &Path,
    report: &Value,
    data: &Path,
    out: &Path,
    enc: &Encoding,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<EncodeReport, TrainError> {
    enc.validate()?;
    let model_cfg = model_config_of(report, weights_file)?;
    let surface_points = report["config"]["surface_points"]
        .as_u64()
        .filter(|&n| n > 0)
        .ok_or_else(|| {
            TrainError::data(
                weights_file,
                "its training report has no config.surface_points (the encoder input size)",
            )
        })? as usize;
    let model = load_shape_prior(weights_file, &model_cfg, &cpu())?;
    let all = read_index(data)?;
    std::fs::create_dir_all(out).map_err(TrainError::io(out))?;
    let cfg = ShapeTrainConfig {
        model: model_cfg,
        surface_points,
        ..ShapeTrainConfig::default()
    };
    let rows = write_codebook(&model, data, &all, &cfg, enc, out, progress)?;
    let dst = out.join(WEIGHTS_FILE);
    if dst != weights_file {
        std::fs::copy(weights_file, &dst).map_err(TrainError::io(&dst))?;
    }
    let mut doc = report.clone();
    doc["data"] = json!(data.display().to_string());
    doc["codebook_rows"] = json!(rows);
    doc["encoded_from"] = json!(weights_file.display().to_string());
    if *enc == Encoding::default() {
        // NAP's encoding is what a report without the entry means; an older report's own
        // entry (it was encoded otherwise before) would now be wrong.
        if let Some(o) = doc.as_object_mut() {
            o.remove("encoding");
        }
    } else {
        doc["encoding"] = enc.to_json();
    }
    write_atomic(
        &out.join(REPORT_FILE),
        serde_json::to_string_pretty(&doc)
            .unwrap_or_default()
            .as_bytes(),
    )?;
    Ok(EncodeReport {
        rows,
        surface_points,
    })
}
