//! Files of a shape-prior run: weights, codebook, checkpoints and resume, each written atomically
//! and checked by sha256 when read back.

#[allow(unused_imports)]
use super::*;
use crate::data::rng::Rng;
use crate::io::npy;
use crate::model::host_decoder::HostDecoder;
use crate::model::shape_prior::{ShapePrior, ShapePriorConfig};
use crate::train::TrainError;
use burn::module::Module;
use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::Device;
use serde_json::{Value, json};

/// Save `model`'s weights (f32 safetensors; keys are the module paths, e.g.
/// `decoder.blocks.0.fc_0.weight`, Linear weights stored `[in, out]` as burn holds them).
/// The header's metadata is written in sorted order (`model::weights::to_bytes`), so equal
/// weights give equal files and equal sha256 (burn writes it in hash order).
pub fn save_shape_prior(model: &ShapePrior, path: &Path) -> Result<(), TrainError> {
    let bytes = crate::model::weights::to_bytes(&model.valid())
        .map_err(|e| TrainError::data(path, e.to_string()))?;
    write_atomic(path, &bytes)
}

/// Load weights written by [`save_shape_prior`] into a model of size `cfg` on `device`.
/// Every tensor must be present with the right shape, and no extra tensor may be in the file.
pub fn load_shape_prior(
    path: &Path,
    cfg: &ShapePriorConfig,
    device: &Device,
) -> Result<ShapePrior, TrainError> {
    cfg.validate()?;
    if !path.is_file() {
        return Err(TrainError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such weights file"),
        });
    }
    let mut model = ShapePrior::new(cfg, device);
    let mut store = SafetensorsStore::from_file(path);
    let result = model
        .load_from(&mut store)
        .map_err(|e| TrainError::data(path, e.to_string()))?;
    if !result.errors.is_empty() || !result.missing.is_empty() || !result.unused.is_empty() {
        return Err(TrainError::data(
            path,
            format!(
                "weights do not match the model config: {} errors, missing {:?}, unused {:?}",
                result.errors.len(),
                result.missing.iter().map(|(k, _)| k).collect::<Vec<_>>(),
                result.unused
            ),
        ));
    }
    Ok(model)
}

/// The decoder sizes stored in the safetensors file `path`, read from its header: N_pe and the
/// hidden width from `decoder.fc_p.weight` ([3 + 6 N_pe, hidden]), the residual blocks from
/// the `decoder.blocks.<i>.` names.
pub(crate) fn stored_decoder_sizes(path: &Path) -> Result<(usize, usize, usize), TrainError> {
    use std::io::Read;
    let bad = |detail: String| TrainError::data(path, detail);
    let mut file = std::fs::File::open(path).map_err(TrainError::io(path))?;
    let mut len = [0u8; 8];
    file.read_exact(&mut len).map_err(TrainError::io(path))?;
    let len = u64::from_le_bytes(len);
    if len > 1 << 24 {
        return Err(bad(format!(
            "safetensors header of {len} bytes (limit 16 MiB)"
        )));
    }
    let mut header = vec![0u8; len as usize];
    file.read_exact(&mut header).map_err(TrainError::io(path))?;
    let header: Value = serde_json::from_slice(&header)
        .map_err(|e| bad(format!("safetensors header is not JSON: {e}")))?;
    let shape = &header["decoder.fc_p.weight"]["shape"];
    let (Some(d_in), Some(hidden)) = (shape[0].as_u64(), shape[1].as_u64()) else {
        return Err(bad(
            "no decoder.fc_p.weight in the safetensors header".into()
        ));
    };
    let pe_freqs = match d_in.checked_sub(3) {
        Some(d) if d % 6 == 0 => (d / 6) as usize,
        _ => {
            return Err(bad(format!(
                "decoder.fc_p.weight has {d_in} input rows, not 3 + 6 N_pe"
            )));
        }
    };
    let blocks = (0..)
        .take_while(|i| {
            header
                .get(format!("decoder.blocks.{i}.fc_0.weight"))
                .is_some()
        })
        .count();
    Ok((pe_freqs, hidden as usize, blocks))
}

/// `init_from`'s weights as a model of `cfg`. When the file's decoder is smaller than `cfg`'s
/// (fewer positional-encoding octaves, a narrower hidden width, fewer blocks) it is grown to
/// `cfg` ([`ShapeDecoder::grow`]: the same SDF, room for finer detail; new weights seeded
/// from `seed`); every other size must match the file.
pub(crate) fn load_init(
    path: &Path,
    cfg: &ShapePriorConfig,
    seed: u64,
    device: &Device,
) -> Result<ShapePrior, TrainError> {
    let (pe_freqs, decoder_hidden, decoder_blocks) = stored_decoder_sizes(path)?;
    let stored = ShapePriorConfig {
        pe_freqs: pe_freqs.min(cfg.pe_freqs),
        decoder_hidden: decoder_hidden.min(cfg.decoder_hidden),
        decoder_blocks: decoder_blocks.min(cfg.decoder_blocks),
        ..*cfg
    };
    if stored == *cfg {
        return load_shape_prior(path, cfg, device);
    }
    let model = load_shape_prior(path, &stored, device)?;
    tracing::info!(
        from = ?(stored.pe_freqs, stored.decoder_hidden, stored.decoder_blocks),
        to = ?(cfg.pe_freqs, cfg.decoder_hidden, cfg.decoder_blocks),
        "growing the decoder (N_pe, hidden, blocks)"
    );
    let mut rng = Rng::fork(seed, 0x4752_4f57);
    Ok(ShapePrior {
        encoder: model.encoder,
        decoder: model.decoder.grow(cfg, &mut rng)?,
    })
}

/// The shape prior in a `train shape` output directory with its sizes and the document they
/// came from: `shape_train.json` of a finished run, else `shape_checkpoint.json` of a run that
/// stopped at a checkpoint (`--stop-at`, or killed), whose weights must match the sha256 it
/// recorded. Lets a candidate be measured before — or while — it trains to the end.
pub fn load_shape_dir(
    dir: &Path,
    device: &Device,
) -> Result<(ShapePrior, ShapePriorConfig, Value), TrainError> {
    let report = dir.join(REPORT_FILE);
    let checkpoint = dir.join(CHECKPOINT_FILE);
    let doc_path = if report.is_file() {
        report
    } else if checkpoint.is_file() {
        checkpoint
    } else {
        return Err(TrainError::data(
            dir,
            format!("neither {REPORT_FILE} nor {CHECKPOINT_FILE}: not a `train shape` output"),
        ));
    };
    let text = std::fs::read_to_string(&doc_path).map_err(TrainError::io(&doc_path))?;
    let doc: Value =
        serde_json::from_str(&text).map_err(|e| TrainError::data(&doc_path, e.to_string()))?;
    let cfg = model_config_of(&doc, &doc_path)?;
    let weights = dir.join(WEIGHTS_FILE);
    if doc_path.ends_with(CHECKPOINT_FILE) {
        check_checkpoint_weights(&weights, &doc["weights_sha256"], &doc_path)?;
    }
    let model = load_shape_prior(&weights, &cfg, device)?;
    Ok((model, cfg, doc))
}

/// A `train shape` codebook as read back: codes (row-major) with their `codebook.json` keys.
pub struct CodebookFile {
    /// Code size.
    pub cols: usize,
    /// `rows × cols` codes.
    pub codes: Vec<f32>,
    /// One `{"key", "object", "part", "split"}` entry per row.
    pub keys: Vec<serde_json::Value>,
    /// The index's `"encoding"` entry (null for NAP's; [`Encoding::of_report`] reads it).
    pub encoding: serde_json::Value,
}

/// Read `shape/codebook.npy` + `shape/codebook.json`; refuses codes that are not `latent` wide
/// and a key list that does not match the rows, naming the file.
pub fn read_codebook(shape: &Path, latent: usize) -> Result<CodebookFile, TrainError> {
    let npy_path = shape.join(CODEBOOK_FILE);
    let (rows, cols, codes) =
        npy::read(&npy_path).map_err(|e| TrainError::data(&npy_path, e.to_string()))?;
    if cols != latent {
        return Err(TrainError::data(
            &npy_path,
            format!("codes have {cols} dimensions, expected {latent}"),
        ));
    }
    let index_path = shape.join(CODEBOOK_INDEX_FILE);
    let text = std::fs::read_to_string(&index_path).map_err(TrainError::io(&index_path))?;
    let index: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| TrainError::data(&index_path, e.to_string()))?;
    let keys = index["keys"]
        .as_array()
        .ok_or_else(|| TrainError::data(&index_path, "no \"keys\" list"))?
        .clone();
    if keys.len() != rows {
        return Err(TrainError::data(
            &index_path,
            format!("{} keys for {rows} codes", keys.len()),
        ));
    }
    Ok(CodebookFile {
        cols,
        codes,
        keys,
        encoding: index["encoding"].clone(),
    })
}

/// Encode every part of the data set (dataset order) by `enc` ([`Encoding`]); writes
/// `codebook.npy` and `codebook.json`. `progress(done, total)` after every batch of parts.
/// Returns the number of rows.
pub(crate) fn write_codebook(
    model: &ShapePrior,
    data: &Path,
    parts: &[PartRef],
    cfg: &ShapeTrainConfig,
    enc: &Encoding,
    out: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<usize, TrainError> {
    // Parts per encoder call (and per fitting batch: each code's fit is its own, so the batch
    // size changes nothing but the speed).
    const BATCH: usize = 32;
    let s = cfg.surface_points;
    let f = cfg.model.latent;
    let host = HostDecoder::new(&model.decoder);
    let mut codes = Vec::with_capacity(parts.len() * f);
    for chunk in parts.chunks(BATCH) {
        codes.extend(encode_refs(model, &host, data, chunk, s, enc)?);
        progress(codes.len() / f, parts.len());
    }
    let mut max_abs = vec![0.0f32; f];
    for row in codes.chunks(f) {
        for (m, v) in max_abs.iter_mut().zip(row) {
            *m = m.max(v.abs());
        }
    }
    write_atomic(
        &out.join(CODEBOOK_FILE),
        &npy::to_bytes(parts.len(), f, &codes),
    )?;
    let index = json!({
        "format": CODEBOOK_FORMAT,
        "latent": f,
        "rows": parts.len(),
        "encoder_input": format!("first {s} points of part<k>_surface.npy (cycled if fewer)"),
        "encoding": enc.to_json(),
        "max_abs": max_abs,
        "keys": parts.iter().map(|p| {
            let mut key = json!({
                "key": format!("{}_{}", p.id, p.k), "object": p.id, "part": p.k, "split": p.split,
            });
            if let Some(c) = &p.category {
                key["category"] = json!(c);
            }
            key
        }).collect::<Vec<_>>(),
    });
    write_atomic(
        &out.join(CODEBOOK_INDEX_FILE),
        serde_json::to_string_pretty(&index)
            .unwrap_or_default()
            .as_bytes(),
    )?;
    Ok(parts.len())
}

/// What `shape_checkpoint.json` holds besides the weights: enough to continue the same batch
/// stream (generator state and the rest of the shuffled epoch) and the same report. Adam's
/// moment estimates are not kept; they restart from zero on resume, as in `train diffusion`.
pub(crate) struct Checkpoint {
    pub(crate) step: usize,
    pub(crate) rng_state: u64,
    pub(crate) epoch: Vec<usize>,
    pub(crate) losses: Vec<f64>,
    pub(crate) curve: Vec<EvalPoint>,
    pub(crate) train_s: f64,
    pub(crate) elapsed_s: f64,
    /// EMA updates so far (runs with an EMA; the shadow is [`EMA_CHECKPOINT_FILE`]). Taken
    /// from the trainer when writing.
    pub(crate) ema_steps: Option<usize>,
}

/// Weights (temp file + rename), then `shape_checkpoint.json` (atomic) with the weights'
/// sha256, so a crash between the two is detected on resume rather than mixing steps.
pub(crate) fn write_checkpoint(
    out: &Path,
    cfg: &ShapeTrainConfig,
    trainer: &Trainer<'_>,
    c: &Checkpoint,
) -> Result<(), TrainError> {
    // Weights go to a temp file, are hashed, then renamed into place.
    let tmp = out.join("shape_prior.checkpoint.tmp");
    let save = |model: &ShapePrior, file: &str| -> Result<String, TrainError> {
        save_shape_prior(model, &tmp)?;
        let bytes = std::fs::read(&tmp).map_err(TrainError::io(&tmp))?;
        let dest = out.join(file);
        std::fs::rename(&tmp, &dest).map_err(TrainError::io(&dest))?;
        Ok(crate::model::weights::sha256_hex(&bytes))
    };
    let raw = trainer
        .model
        .as_ref()
        .expect("model is present between steps");
    let weights_sha = save(raw, WEIGHTS_FILE)?;
    let ema = match &trainer.ema {
        Some(ema) => json!({
            "steps": ema.steps,
            "sha256": save(&trainer.inference_model(), EMA_CHECKPOINT_FILE)?,
        }),
        None => Value::Null,
    };
    let doc = json!({
        "ema": ema,
        "format": CHECKPOINT_FORMAT,
        "step": c.step,
        "config": cfg.to_json(),
        "weights_sha256": weights_sha,
        "rng_state": c.rng_state.to_string(),
        "epoch": c.epoch,
        "losses": c.losses,
        "curve": c.curve.iter().map(EvalPoint::to_json).collect::<Vec<_>>(),
        "train_s": c.train_s,
        "elapsed_s": c.elapsed_s,
    });
    write_atomic(
        &out.join(CHECKPOINT_FILE),
        serde_json::to_string(&doc).unwrap_or_default().as_bytes(),
    )
}

/// Refuse `weights` unless its sha256 is `recorded`, the value the checkpoint document (read
/// from `doc_path`) holds for it: a run killed between the two writes leaves them apart.
pub(crate) fn check_checkpoint_weights(
    weights: &Path,
    recorded: &Value,
    doc_path: &Path,
) -> Result<(), TrainError> {
    let bytes = std::fs::read(weights).map_err(TrainError::io(weights))?;
    if *recorded != crate::model::weights::sha256_hex(&bytes).as_str() {
        return Err(TrainError::data(
            weights,
            format!(
                "sha256 differs from the one {} recorded: the checkpoint is incomplete",
                doc_path.display()
            ),
        ));
    }
    Ok(())
}

/// Read `out/shape_checkpoint.json`, refusing one written by a different run (a config field of
/// [`RESUME_FIELDS`] differs: named with both values) or whose weights file is not the one it
/// was written with.
pub(crate) fn read_checkpoint(
    out: &Path,
    cfg: &ShapeTrainConfig,
) -> Result<Checkpoint, TrainError> {
    let path = out.join(CHECKPOINT_FILE);
    let text = std::fs::read_to_string(&path).map_err(TrainError::io(&path))?;
    let v: Value =
        serde_json::from_str(&text).map_err(|e| TrainError::data(&path, e.to_string()))?;
    if v["format"] != CHECKPOINT_FORMAT {
        return Err(TrainError::data(
            &path,
            format!("format {} is not {CHECKPOINT_FORMAT}", v["format"]),
        ));
    }
    let ours = cfg.to_json();
    let defaults = ShapeTrainConfig::default().to_json();
    for field in RESUME_FIELDS {
        // A field newer than the checkpoint (the EMA, the frozen encoder, the wrong-side term)
        // is missing from it: that run had the option off, which is its default.
        let theirs = match &v["config"][field] {
            Value::Null => defaults[field].clone(),
            x => x.clone(),
        };
        if theirs != ours[field] {
            return Err(TrainError::Config(crate::error::Invalid {
                field: field.to_string(),
                limit: format!(
                    "the checkpoint's value {theirs} to resume {} (or start afresh without --resume)",
                    path.display()
                ),
                value: ours[field].to_string(),
            }));
        }
    }
    check_checkpoint_weights(&out.join(WEIGHTS_FILE), &v["weights_sha256"], &path)?;
    let bad = |k: &str| TrainError::data(&path, format!("{k} is missing or malformed"));
    let num = |k: &str| v[k].as_f64().ok_or_else(|| bad(k));
    let step = v["step"].as_u64().ok_or_else(|| bad("step"))? as usize;
    let rng_state = v["rng_state"]
        .as_str()
        .and_then(|s| s.parse::<u64>().ok())
        .ok_or_else(|| bad("rng_state"))?;
    let epoch = v["epoch"]
        .as_array()
        .and_then(|a| a.iter().map(|x| x.as_u64().map(|x| x as usize)).collect())
        .ok_or_else(|| bad("epoch"))?;
    let losses: Vec<f64> = v["losses"]
        .as_array()
        .and_then(|a| a.iter().map(Value::as_f64).collect())
        .ok_or_else(|| bad("losses"))?;
    let curve = v["curve"]
        .as_array()
        .and_then(|a| a.iter().map(EvalPoint::from_json).collect())
        .ok_or_else(|| bad("curve"))?;
    if losses.len() != step || step >= cfg.steps {
        return Err(TrainError::data(
            &path,
            format!(
                "step {step} with {} losses does not fit a run of {} steps",
                losses.len(),
                cfg.steps
            ),
        ));
    }
    let ema_steps = if cfg.ema_decay > 0.0 {
        check_checkpoint_weights(&out.join(EMA_CHECKPOINT_FILE), &v["ema"]["sha256"], &path)?;
        Some(v["ema"]["steps"].as_u64().ok_or_else(|| bad("ema.steps"))? as usize)
    } else {
        None
    };
    Ok(Checkpoint {
        step,
        rng_state,
        epoch,
        losses,
        curve,
        train_s: num("train_s")?,
        elapsed_s: num("elapsed_s")?,
        ema_steps,
    })
}
