//! `physnap train codebook`: put the retrieval codebook into a weights directory.
//!
//! Why it exists: generation replaces a part whose decoded shape meshes empty by its nearest
//! training code (model/codebook.rs, method.md §5.9). The codes are the shape prior's
//! codebook (`train shape` output) restricted to the training split, minus the codes that do
//! not mesh non-empty themselves at the check resolution. The shape prior in the weights must
//! be the one that produced the codes (checked by sha256), or the codes would decode to
//! unrelated shapes. Writes `codebook.safetensors` and adds its entry to `manifest.json`
//! (atomically); `train diffusion` runs this at its end, so every new weights directory has one.
//!
//! When every training key of the shape directory names its object's category (`train shape`
//! and `train encode` write it), each kept code also records that category's index in the
//! manifest's list, for `--retrieval category`; older shape directories give a codebook
//! without categories.

use std::path::Path;
use std::time::Instant;

use super::TrainError;
use crate::io::manifest::{self, CodebookConfig, Entry};
use crate::mesh::MeshingOptions;
use crate::model::codebook::Codebook;
use crate::model::shape_prior::{LatentSdfDecoder, ShapePrior};
use crate::model::weights::{self, sha256_hex};

/// The codebook file name inside a weights directory.
pub const CODEBOOK_WEIGHTS_FILE: &str = "codebook.safetensors";

/// Default meshing resolution of the non-empty check.
pub const DEFAULT_CHECK_RESOLUTION: usize = 16;

/// What [`build_codebook`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct CodebookReport {
    /// Codes written.
    pub rows: usize,
    /// Training-split codes checked.
    pub candidates: usize,
    /// sha256 of `codebook.safetensors`.
    pub sha256: String,
    /// Whether the codes carry their categories (every training key named a listed category).
    pub categories: bool,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Build the codebook of `weights` from the training-split codes in `shape` (a `train shape`
/// output) and register it in `weights/manifest.json`. `on_row(done, total)` reports progress.
pub fn build_codebook(
    shape: &Path,
    weights_dir: &Path,
    check_resolution: usize,
    on_row: &mut dyn FnMut(usize, usize),
) -> Result<CodebookReport, TrainError> {
    let started = Instant::now();
    let check = MeshingOptions {
        resolution: check_resolution,
    };
    check
        .validate()
        .map_err(|e| TrainError::config("check resolution", "between 8 and 256", e))?;
    let manifest_path = weights_dir.join("manifest.json");
    let text = std::fs::read_to_string(&manifest_path).map_err(TrainError::io(&manifest_path))?;
    let mut m = manifest::from_str(&text, &manifest_path.display().to_string())
        .map_err(|e| TrainError::data(&manifest_path, e.to_string()))?;
    // The codes must come from the shape prior the weights ship.
    let shape_file = shape.join("shape_prior.safetensors");
    let shape_bytes = std::fs::read(&shape_file).map_err(TrainError::io(&shape_file))?;
    let shape_sha = sha256_hex(&shape_bytes);
    if shape_sha != m.shape_prior.sha256 {
        return Err(TrainError::data(
            &shape_file,
            format!(
                "sha256 {shape_sha} is not the shape prior of {} ({}): its codes would decode to unrelated shapes",
                manifest_path.display(),
                m.shape_prior.sha256
            ),
        ));
    }
    let device = crate::model::cpu();
    let mut prior = ShapePrior::new(&m.shape_prior.config, &device);
    weights::load_bytes(&mut prior, shape_bytes, &shape_file.display().to_string())?;
    let decoder = LatentSdfDecoder::new(&prior.decoder);

    let latent = m.shape_prior.config.latent;
    let book = super::shape::read_codebook(shape, latent)?;
    let cols = book.cols;
    let train_rows: Vec<(&serde_json::Value, &[f32])> = book
        .keys
        .iter()
        .zip(book.codes.chunks_exact(cols))
        .filter(|(k, _)| k["split"] == "train")
        .collect();
    let train: Vec<f32> = train_rows
        .iter()
        .flat_map(|(_, c)| c.iter().copied())
        .collect();
    // Each training code's category index, when every key names a listed category.
    let row_categories: Option<Vec<u32>> = train_rows
        .iter()
        .map(|(k, _)| {
            let name = k["category"].as_str()?;
            m.categories
                .iter()
                .position(|c| c == name)
                .map(|i| i as u32)
        })
        .collect();
    let candidates = train.len() / cols;
    if candidates == 0 {
        return Err(TrainError::data(
            shape.join(super::shape::CODEBOOK_INDEX_FILE),
            "no training-split codes",
        ));
    }
    let (codebook, kept) = Codebook::build(latent, &train, &decoder, &check, on_row)?;
    let codebook = match &row_categories {
        Some(cats) => {
            codebook.with_categories(kept.iter().map(|&i| cats[i]).collect(), m.categories.len())?
        }
        None => codebook,
    };
    let file = weights_dir.join(CODEBOOK_WEIGHTS_FILE);
    let sha256 = codebook.save(&file)?;
    m.codebook = Some(Entry {
        file: CODEBOOK_WEIGHTS_FILE.into(),
        sha256: sha256.clone(),
        config: CodebookConfig {
            rows: codebook.rows(),
            latent,
            split: "train".into(),
            candidates,
            check_resolution,
            categories: codebook.categories().is_some(),
        },
    });
    crate::io::atomic::write(&manifest_path, manifest::to_string(&m).as_bytes())
        .map_err(|e| TrainError::io(&e.path)(e.source))?;
    Ok(CodebookReport {
        rows: codebook.rows(),
        candidates,
        sha256,
        categories: codebook.categories().is_some(),
        seconds: started.elapsed().as_secs_f64(),
    })
}
