//! The retrieval codebook: training-part shape codes that decode to a real surface.
//!
//! Why it exists: a generated part's latent code can decode to an SDF that is positive
//! everywhere — the part meshes empty and the object is unusable (measured: every invalid
//! sample of the 7,000-step denoiser had an empty base part). NAP's retrieval variant
//! (method.md §5.9) answers this by replacing a generated part's shape with its nearest training
//! part (1-NN, Euclidean, on the raw, unscaled codes). We retrieve the nearest training *code*
//! and decode it with the shipped shape prior, rather than a training *mesh*: the codes are
//! 9k × 128 floats (≈ 4.6 MB) where the meshes would be hundreds of MB, and the decoded shape
//! is what every other part of the pipeline already uses.
//!
//! Only codes whose decoded SDF meshes non-empty (checked at build time, see
//! [`Codebook::build`]) enter the codebook, so a retrieved shape is never empty itself.
//!
//! On disk: `codebook.safetensors` with one f32 tensor `codes` of shape [rows, latent], listed
//! in `weights/manifest.json` (file, sha256, rows, latent) and verified on load like the
//! models.

use std::path::Path;

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};

use super::ModelError;
use super::weights::{self, WeightsError};
use crate::mesh::{MeshingOptions, extract_normalised};
use crate::shape::LatentDecoder;

/// The codes as a burn module, so they save and load through [`weights`] (safetensors,
/// sha256-checked, shape-checked).
#[derive(Module, Debug)]
struct CodebookTensors {
    codes: Param<Tensor<2>>,
}

/// Training-part codes for nearest-neighbour retrieval (row-major, `rows × latent`).
#[derive(Debug, Clone, PartialEq)]
pub struct Codebook {
    latent: usize,
    codes: Vec<f32>,
}

impl Codebook {
    /// Wrap `codes` (`rows × latent`, row-major); refuses an empty or ragged table and
    /// non-finite values.
    pub fn new(latent: usize, codes: Vec<f32>) -> Result<Self, ModelError> {
        let config = |field: &str, limit: &str, value: String| ModelError::Config {
            field: field.into(),
            limit: limit.into(),
            value,
        };
        if latent == 0 {
            return Err(config("codebook latent", "at least 1", "0".into()));
        }
        if codes.is_empty() || !codes.len().is_multiple_of(latent) {
            return Err(config(
                "codebook codes",
                &format!("a non-empty multiple of the latent size {latent}"),
                format!("{} values", codes.len()),
            ));
        }
        if let Some(i) = codes.iter().position(|v| !v.is_finite()) {
            return Err(config(
                "codebook codes",
                "finite",
                format!("{} at row {}", codes[i], i / latent),
            ));
        }
        Ok(Codebook { latent, codes })
    }

    /// Keep the rows of `codes` whose decoded SDF meshes non-empty at `check` (parallel over
    /// the current rayon pool through the mesher). `on_row(done, total)` reports progress.
    /// Returns the codebook and the indices (into `codes`) of the rows kept.
    pub fn build(
        latent: usize,
        codes: &[f32],
        decoder: &dyn LatentDecoder,
        check: &MeshingOptions,
        on_row: &mut dyn FnMut(usize, usize),
    ) -> Result<(Self, Vec<usize>), ModelError> {
        Codebook::new(latent, codes.to_vec())?;
        check.validate().map_err(|e| ModelError::Config {
            field: "codebook check resolution".into(),
            limit: "a valid meshing resolution".into(),
            value: e.to_string(),
        })?;
        let total = codes.len() / latent;
        let mut kept = Vec::new();
        let mut table = Vec::new();
        for (i, code) in codes.chunks(latent).enumerate() {
            // extract_normalised only fails on bad options, validated above.
            let non_empty = extract_normalised(decoder.sdf(code).as_ref(), check)
                .map(|m| !m.triangles.is_empty())
                .unwrap_or(false);
            if non_empty {
                kept.push(i);
                table.extend_from_slice(code);
            }
            on_row(i + 1, total);
        }
        if kept.is_empty() {
            return Err(ModelError::Config {
                field: "codebook".into(),
                limit: "at least one code that decodes to a non-empty shape".into(),
                value: format!("0 of {total} codes"),
            });
        }
        Ok((Codebook::new(latent, table)?, kept))
    }

    /// Code size.
    pub fn latent(&self) -> usize {
        self.latent
    }

    /// Number of codes.
    pub fn rows(&self) -> usize {
        self.codes.len() / self.latent
    }

    /// Row `i`.
    pub fn row(&self, i: usize) -> &[f32] {
        &self.codes[i * self.latent..(i + 1) * self.latent]
    }

    /// The nearest code to `code` (Euclidean) and its squared distance; `None` when `code` has
    /// the wrong length. Ties go to the lower row. Brute force over rows × latent floats (the
    /// shipped codebook: 7,358 × 128), once per retrieved part.
    pub fn nearest(&self, code: &[f32]) -> Option<(usize, f32)> {
        if code.len() != self.latent {
            return None;
        }
        self.codes
            .chunks(self.latent)
            .map(|row| row.iter().zip(code).map(|(a, b)| (a - b) * (a - b)).sum())
            .enumerate()
            .fold(None, |best: Option<(usize, f32)>, (i, d)| match best {
                Some((_, bd)) if bd <= d => best,
                _ => Some((i, d)),
            })
    }

    fn tensors(&self, device: &Device) -> CodebookTensors {
        CodebookTensors {
            codes: Param::from_data(
                TensorData::new(self.codes.clone(), [self.rows(), self.latent]),
                device,
            ),
        }
    }

    /// Save to `path` (safetensors, atomically); returns the file's sha256.
    pub fn save(&self, path: &Path) -> Result<String, WeightsError> {
        weights::save(&self.tensors(&super::cpu()), path)
    }

    /// Load `rows × latent` codes from `path`, verifying `expected_sha256` when given.
    pub fn load(
        path: &Path,
        rows: usize,
        latent: usize,
        expected_sha256: Option<&str>,
    ) -> Result<Self, WeightsError> {
        let incompatible = |detail: String| WeightsError::Incompatible {
            path: path.display().to_string(),
            detail,
        };
        if rows == 0 || latent == 0 {
            return Err(incompatible(format!(
                "codebook size must be at least 1 × 1, got {rows} × {latent}"
            )));
        }
        let device = super::cpu();
        let mut t = Codebook {
            latent,
            codes: vec![0.0; rows * latent],
        }
        .tensors(&device);
        weights::load(&mut t, path, expected_sha256)?;
        let codes = t
            .codes
            .val()
            .into_data()
            .try_into_vec::<f32>()
            .map_err(|e| incompatible(format!("codes are not f32: {e:?}")))?;
        Codebook::new(latent, codes).map_err(|e| incompatible(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::SphereCodes as Spheres;

    #[test]
    fn nearest_is_the_euclidean_nearest_row() {
        let cb = Codebook::new(2, vec![0.0, 0.0, 1.0, 1.0, -1.0, 2.0]).unwrap();
        assert_eq!(cb.rows(), 3);
        assert_eq!(cb.nearest(&[0.9, 0.8]).unwrap().0, 1);
        assert_eq!(cb.nearest(&[-0.6, 1.5]).unwrap().0, 2);
        let (i, d) = cb.nearest(&[0.1, 0.0]).unwrap();
        assert_eq!(i, 0);
        assert!((d - 0.01).abs() < 1e-6);
        assert_eq!(cb.nearest(&[0.0]), None, "wrong length");
    }

    #[test]
    fn bad_tables_are_refused_naming_the_problem() {
        let e = Codebook::new(2, vec![0.0; 3]).unwrap_err().to_string();
        assert!(
            e.contains("multiple of the latent size 2") && e.contains("3 values"),
            "{e}"
        );
        let e = Codebook::new(2, vec![0.0, f32::NAN])
            .unwrap_err()
            .to_string();
        assert!(e.contains("finite") && e.contains("row 0"), "{e}");
        assert!(Codebook::new(2, vec![]).is_err());
    }

    #[test]
    fn build_keeps_only_codes_that_mesh_non_empty() {
        let codes = [0.3, 7.0, -0.2, 8.0, 0.0, 9.0, 0.25, 10.0];
        let mut calls = 0;
        let (cb, kept) = Codebook::build(
            2,
            &codes,
            &Spheres,
            &MeshingOptions { resolution: 16 },
            &mut |done, total| {
                calls += 1;
                assert_eq!(total, 4);
                assert_eq!(done, calls);
            },
        )
        .unwrap();
        assert_eq!(kept, vec![0, 3]);
        assert_eq!(cb.row(1), &[0.25, 10.0]);
        let e = Codebook::build(
            2,
            &[-0.1, 0.0],
            &Spheres,
            &MeshingOptions { resolution: 16 },
            &mut |_, _| {},
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("0 of 1 codes"), "{e}");
    }

    #[test]
    fn save_load_round_trips_and_checks_sha_and_size() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("codebook.safetensors");
        let cb = Codebook::new(3, vec![0.5, -1.25, 3.0, 1e-7, 2.0, -0.0]).unwrap();
        let sha = cb.save(&path).unwrap();
        assert_eq!(Codebook::load(&path, 2, 3, Some(&sha)).unwrap(), cb);
        let e = Codebook::load(&path, 3, 3, Some(&sha))
            .unwrap_err()
            .to_string();
        assert!(e.contains("codebook.safetensors"), "{e}");
        let e = Codebook::load(&path, 2, 3, Some("00"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("sha256 mismatch"), "{e}");
    }
}
