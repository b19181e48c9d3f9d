//! `weights/manifest.json`: what the shipped weights are and how they were made.
//!
//! Why it exists: a weights directory must be self-describing and verifiable. The manifest
//! holds each model's architecture config, file name and sha256, the feature scales the
//! denoiser was trained with, the category list, and (verbatim JSON) how the data were made,
//! how training went and the evaluation metrics. [`load_models`] refuses files whose sha256
//! differs and configs that do not fit the tensors.
//!
//! ```json
//! { "format": "physnap.weights/v1",
//!   "shape_prior": { "file": "shape_prior.safetensors", "sha256": "…", "config": { "latent": 128, … } },
//!   "denoiser":    { "file": "denoiser.safetensors",    "sha256": "…", "config": { "width": 160, … } },
//!   "codebook":    { "file": "codebook.safetensors",    "sha256": "…", "config": { "rows": 9000, "latent": 128, … } },
//!   "feature_scales": { "node": [135 floats], "edge": [13 floats] },
//!   "categories": ["Door", "Window", …],
//!   "data": {…}, "training": {…}, "metrics": {…} }
//! ```

use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::FormatError;
use crate::graph::FeatureScales;
use crate::model::codebook::Codebook;
use crate::model::denoiser::{Denoiser, DenoiserConfig};
use crate::model::shape_prior::{ShapePrior, ShapePriorConfig};
use crate::model::weights;

/// Format tag.
pub const FORMAT: &str = "physnap.weights/v1";

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
struct ShapeConfigDoc {
    latent: usize,
    decoder_hidden: usize,
    decoder_blocks: usize,
    encoder_hidden: usize,
    encoder_blocks: usize,
    pe_freqs: usize,
    /// Absent in manifests written before the option existed (false).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    code_every_block: bool,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
struct DenoiserConfigDoc {
    width: usize,
    layers: usize,
    head_channels: usize,
    t_pe_dim: usize,
    slot_pe_dim: usize,
    node_head_hidden: Vec<usize>,
    edge_head_hidden: Vec<usize>,
    categories: usize,
    legacy_edge_embedding: bool,
    /// Absent in manifests written before the option existed (false).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    category_layers: bool,
}

/// The retrieval codebook's size and provenance (model/codebook.rs).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CodebookConfig {
    /// Codes in the file.
    pub rows: usize,
    /// Code size (must equal the shape prior's latent size).
    pub latent: usize,
    /// Codebook split the codes came from (e.g. `train`).
    pub split: String,
    /// Rows of that split before the non-empty check.
    pub candidates: usize,
    /// Meshing resolution of the non-empty check.
    pub check_resolution: usize,
    /// Whether the file also holds each code's category index (into `categories`), which
    /// `--retrieval category` needs. Absent in manifests written before it existed (false).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub categories: bool,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct EntryDoc<C> {
    file: String,
    sha256: String,
    config: C,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct ScalesDoc {
    node: Vec<f32>,
    edge: Vec<f32>,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
struct ManifestDoc {
    format: String,
    shape_prior: EntryDoc<ShapeConfigDoc>,
    denoiser: EntryDoc<DenoiserConfigDoc>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    codebook: Option<EntryDoc<CodebookConfig>>,
    feature_scales: ScalesDoc,
    categories: Vec<String>,
    #[serde(default)]
    data: Value,
    #[serde(default)]
    training: Value,
    #[serde(default)]
    metrics: Value,
}

/// A weights file entry.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry<C> {
    /// File name relative to the manifest.
    pub file: String,
    /// Hex sha256 of the file.
    pub sha256: String,
    /// Architecture.
    pub config: C,
}

/// The parsed manifest.
#[derive(Debug, Clone, PartialEq)]
pub struct Manifest {
    /// The shape prior.
    pub shape_prior: Entry<ShapePriorConfig>,
    /// The denoiser.
    pub denoiser: Entry<DenoiserConfig>,
    /// The retrieval codebook (optional: weights made before it existed have none).
    pub codebook: Option<Entry<CodebookConfig>>,
    /// Feature scales (model space = raw / scale).
    pub feature_scales: FeatureScales,
    /// Category names; index = position.
    pub categories: Vec<String>,
    /// How the data were made (verbatim).
    pub data: Value,
    /// How training went (verbatim).
    pub training: Value,
    /// Evaluation metrics (verbatim).
    pub metrics: Value,
}

fn shape_to_doc(c: &ShapePriorConfig) -> ShapeConfigDoc {
    ShapeConfigDoc {
        latent: c.latent,
        decoder_hidden: c.decoder_hidden,
        decoder_blocks: c.decoder_blocks,
        encoder_hidden: c.encoder_hidden,
        encoder_blocks: c.encoder_blocks,
        pe_freqs: c.pe_freqs,
        code_every_block: c.code_every_block,
    }
}

fn denoiser_to_doc(c: &DenoiserConfig) -> DenoiserConfigDoc {
    DenoiserConfigDoc {
        width: c.width,
        layers: c.layers,
        head_channels: c.head_channels,
        t_pe_dim: c.t_pe_dim,
        slot_pe_dim: c.slot_pe_dim,
        node_head_hidden: c.node_head_hidden.clone(),
        edge_head_hidden: c.edge_head_hidden.clone(),
        categories: c.categories,
        legacy_edge_embedding: c.legacy_edge_embedding,
        category_layers: c.category_layers,
    }
}

/// Serialise a manifest.
pub fn to_string(m: &Manifest) -> String {
    let doc = ManifestDoc {
        format: FORMAT.into(),
        shape_prior: EntryDoc {
            file: m.shape_prior.file.clone(),
            sha256: m.shape_prior.sha256.clone(),
            config: shape_to_doc(&m.shape_prior.config),
        },
        denoiser: EntryDoc {
            file: m.denoiser.file.clone(),
            sha256: m.denoiser.sha256.clone(),
            config: denoiser_to_doc(&m.denoiser.config),
        },
        codebook: m.codebook.as_ref().map(|c| EntryDoc {
            file: c.file.clone(),
            sha256: c.sha256.clone(),
            config: c.config.clone(),
        }),
        feature_scales: ScalesDoc {
            node: m.feature_scales.node.clone(),
            edge: m.feature_scales.edge.clone(),
        },
        categories: m.categories.clone(),
        data: m.data.clone(),
        training: m.training.clone(),
        metrics: m.metrics.clone(),
    };
    serde_json::to_string_pretty(&doc).unwrap_or_default()
}

/// Parse and check a manifest.
pub fn from_str(text: &str, path: &str) -> Result<Manifest, FormatError> {
    let de = &mut serde_json::Deserializer::from_str(text);
    let doc: ManifestDoc =
        serde_path_to_error::deserialize(de).map_err(|e| FormatError::Malformed {
            what: "weights manifest",
            path: format!("{path}: {}", e.path()),
            message: e.into_inner().to_string(),
        })?;
    if doc.format != FORMAT {
        return Err(crate::error::CoreError::invalid(
            "manifest format",
            format!("{FORMAT:?}"),
            format!("{:?}", doc.format),
        )
        .into());
    }
    let s = doc.shape_prior.config;
    let d = doc.denoiser.config;
    let m = Manifest {
        shape_prior: Entry {
            file: doc.shape_prior.file,
            sha256: doc.shape_prior.sha256,
            config: ShapePriorConfig {
                latent: s.latent,
                decoder_hidden: s.decoder_hidden,
                decoder_blocks: s.decoder_blocks,
                encoder_hidden: s.encoder_hidden,
                encoder_blocks: s.encoder_blocks,
                pe_freqs: s.pe_freqs,
                code_every_block: s.code_every_block,
            },
        },
        denoiser: Entry {
            file: doc.denoiser.file,
            sha256: doc.denoiser.sha256,
            config: DenoiserConfig {
                width: d.width,
                layers: d.layers,
                head_channels: d.head_channels,
                t_pe_dim: d.t_pe_dim,
                slot_pe_dim: d.slot_pe_dim,
                node_head_hidden: d.node_head_hidden,
                edge_head_hidden: d.edge_head_hidden,
                categories: d.categories,
                legacy_edge_embedding: d.legacy_edge_embedding,
                category_layers: d.category_layers,
            },
        },
        codebook: doc.codebook.map(|c| Entry {
            file: c.file,
            sha256: c.sha256,
            config: c.config,
        }),
        feature_scales: FeatureScales {
            node: doc.feature_scales.node,
            edge: doc.feature_scales.edge,
        },
        categories: doc.categories,
        data: doc.data,
        training: doc.training,
        metrics: doc.metrics,
    };
    m.feature_scales.validate()?;
    if m.denoiser.config.categories != 0 && m.denoiser.config.categories != m.categories.len() {
        return Err(crate::error::CoreError::invalid(
            "manifest denoiser.config.categories",
            format!(
                "0 or the number of listed categories ({})",
                m.categories.len()
            ),
            m.denoiser.config.categories,
        )
        .into());
    }
    if let Some(c) = &m.codebook
        && c.config.latent != m.shape_prior.config.latent
    {
        return Err(crate::error::CoreError::invalid(
            "manifest codebook.config.latent",
            format!(
                "the shape prior's latent size ({})",
                m.shape_prior.config.latent
            ),
            c.config.latent,
        )
        .into());
    }
    Ok(m)
}

/// Both models, loaded and verified.
pub struct LoadedModels {
    /// The manifest they came from.
    pub manifest: Manifest,
    /// The shape prior (inference device).
    pub shape_prior: ShapePrior,
    /// The denoiser (inference device).
    pub denoiser: Denoiser,
    /// The retrieval codebook, when the manifest lists one.
    pub codebook: Option<Codebook>,
}

/// Read `dir/manifest.json` and load both models (and the codebook, when listed) on `device`,
/// verifying sha256 and configs.
pub fn load_models(dir: &Path, device: &burn::tensor::Device) -> Result<LoadedModels, FormatError> {
    let path = dir.join("manifest.json");
    let text = std::fs::read_to_string(&path).map_err(|source| FormatError::Io {
        path: path.display().to_string(),
        source,
    })?;
    let manifest = from_str(&text, &path.display().to_string())?;
    manifest
        .shape_prior
        .config
        .validate()
        .map_err(|e| FormatError::Malformed {
            what: "weights manifest",
            path: format!("{}: shape_prior.config", path.display()),
            message: e.to_string(),
        })?;
    let mut shape_prior = ShapePrior::new(&manifest.shape_prior.config, device);
    weights::load(
        &mut shape_prior,
        &dir.join(&manifest.shape_prior.file),
        Some(&manifest.shape_prior.sha256),
    )?;
    let mut denoiser =
        Denoiser::new(&manifest.denoiser.config, device).map_err(|e| FormatError::Malformed {
            what: "weights manifest",
            path: format!("{}: denoiser.config", path.display()),
            message: e.to_string(),
        })?;
    weights::load(
        &mut denoiser,
        &dir.join(&manifest.denoiser.file),
        Some(&manifest.denoiser.sha256),
    )?;
    let codebook = match &manifest.codebook {
        None => None,
        Some(c) => Some(Codebook::load(
            &dir.join(&c.file),
            c.config.rows,
            c.config.latent,
            c.config.categories.then_some(manifest.categories.len()),
            Some(&c.sha256),
        )?),
    };
    Ok(LoadedModels {
        manifest,
        shape_prior,
        denoiser,
        codebook,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn category_layers_round_trip_and_default_to_off_in_older_manifests() {
        // A manifest written before the option existed (the denoiser shipped until 2026-11-26)
        // loads as off, and writes back without the field.
        let older = include_str!("testdata/previous_denoiser_manifest.json");
        let m = from_str(older, "previous_denoiser_manifest.json").unwrap();
        assert!(!older.contains("category_layers"));
        assert!(!m.denoiser.config.category_layers);
        assert!(!to_string(&m).contains("category_layers"));
        let mut on = m.clone();
        on.denoiser.config.category_layers = true;
        let text = to_string(&on);
        assert!(text.contains("\"category_layers\": true"), "{text}");
        assert!(
            from_str(&text, "m.json")
                .unwrap()
                .denoiser
                .config
                .category_layers
        );
        // The shipped denoiser was trained with it.
        let shipped = include_str!("../../weights/manifest.json");
        let m = from_str(shipped, "weights/manifest.json").unwrap();
        assert!(m.denoiser.config.category_layers);
    }

    /// The shipped manifest (NAP's decoder) reads `code_every_block` as off and writes back
    /// without it; a manifest with it on round-trips.
    #[test]
    fn code_every_block_round_trips_and_defaults_to_off() {
        let shipped = include_str!("../../weights/manifest.json");
        let m = from_str(shipped, "weights/manifest.json").unwrap();
        assert!(!shipped.contains("code_every_block"));
        assert!(!m.shape_prior.config.code_every_block);
        assert!(!to_string(&m).contains("code_every_block"));
        let mut on = m.clone();
        on.shape_prior.config.code_every_block = true;
        let text = to_string(&on);
        assert!(text.contains("\"code_every_block\": true"), "{text}");
        let back = from_str(&text, "m.json").unwrap();
        assert_eq!(back.shape_prior.config, on.shape_prior.config);
    }
}
