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
//! Codes may carry the category of the training object they came from (one index into the
//! manifest's category list per row). Then a category-conditioned sample can take its part
//! shapes from the requested category only ([`Codebook::nearest_in`]; `--retrieval category`),
//! so a dishwasher sample gets a dishwasher's shell rather than the nearest cabinet's.
//!
//! On disk: `codebook.safetensors` with one f32 tensor `codes` of shape [rows, latent] and, when
//! the codes carry categories, an f32 tensor `categories` of shape [rows] (integral values);
//! listed in `weights/manifest.json` (file, sha256, rows, latent, categories) and verified on
//! load like the models.

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

/// The codes and their rows' category indices (stored as f32, integral).
#[derive(Module, Debug)]
struct CategorisedTensors {
    codes: Param<Tensor<2>>,
    categories: Param<Tensor<1>>,
}

/// Training-part codes for nearest-neighbour retrieval (row-major, `rows × latent`), with the
/// category index of each row's training object when known.
#[derive(Debug, Clone, PartialEq)]
pub struct Codebook {
    latent: usize,
    codes: Vec<f32>,
    categories: Option<Vec<u32>>,
}

impl Codebook {
    /// Wrap `codes` (`rows × latent`, row-major); refuses an empty or ragged table and
    /// non-finite values.
    pub fn new(latent: usize, codes: Vec<f32>) -> Result<Self, ModelError> {
        let config = |field: &str, limit: &str, value: String| {
            ModelError::Config(crate::error::Invalid {
                field: field.into(),
                limit: limit.into(),
                value,
            })
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
        Ok(Codebook {
            latent,
            codes,
            categories: None,
        })
    }

    /// Attach each row's category index (`categories.len()` must equal the rows, every index
    /// below `category_count`, the length of the manifest's category list).
    pub fn with_categories(
        mut self,
        categories: Vec<u32>,
        category_count: usize,
    ) -> Result<Self, ModelError> {
        if categories.len() != self.rows() {
            return Err(ModelError::Config(crate::error::Invalid {
                field: "codebook categories".into(),
                limit: format!("one per code ({} codes)", self.rows()),
                value: format!("{} categories", categories.len()),
            }));
        }
        if let Some(i) = categories
            .iter()
            .position(|&c| c as usize >= category_count)
        {
            return Err(ModelError::Config(crate::error::Invalid {
                field: "codebook categories".into(),
                limit: format!("indices below the category count {category_count}"),
                value: format!("{} at row {i}", categories[i]),
            }));
        }
        self.categories = Some(categories);
        Ok(self)
    }

    /// Each row's category index, when the codebook carries them.
    pub fn categories(&self) -> Option<&[u32]> {
        self.categories.as_deref()
    }

    /// Rows of category `category` (0 when the codebook carries no categories).
    pub fn rows_of_category(&self, category: usize) -> usize {
        self.categories()
            .map_or(0, |c| c.iter().filter(|&&k| k as usize == category).count())
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
        check.validate().map_err(|e| {
            ModelError::Config(crate::error::Invalid {
                field: "codebook check resolution".into(),
                limit: "a valid meshing resolution".into(),
                value: e.to_string(),
            })
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
            return Err(ModelError::Config(crate::error::Invalid {
                field: "codebook".into(),
                limit: "at least one code that decodes to a non-empty shape".into(),
                value: format!("0 of {total} codes"),
            }));
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
        self.nearest_in(code, None)
    }

    /// The nearest code to `code` among the rows of `category` (every row when `None`), as
    /// [`Codebook::nearest`]; `None` also when no row has that category (or the codebook
    /// carries no categories).
    pub fn nearest_in(&self, code: &[f32], category: Option<usize>) -> Option<(usize, f32)> {
        if code.len() != self.latent {
            return None;
        }
        let wanted = |i: usize| match (category, self.categories()) {
            (None, _) => true,
            (Some(c), Some(cats)) => cats[i] as usize == c,
            (Some(_), None) => false,
        };
        self.codes
            .chunks(self.latent)
            .enumerate()
            .filter(|(i, _)| wanted(*i))
            .map(|(i, row)| {
                (
                    i,
                    row.iter().zip(code).map(|(a, b)| (a - b) * (a - b)).sum(),
                )
            })
            .fold(None, |best: Option<(usize, f32)>, (i, d)| match best {
                Some((_, bd)) if bd <= d => best,
                _ => Some((i, d)),
            })
    }

    fn codes_param(&self, device: &Device) -> Param<Tensor<2>> {
        Param::from_data(
            TensorData::new(self.codes.clone(), [self.rows(), self.latent]),
            device,
        )
    }

    /// Save to `path` (safetensors, atomically; with the `categories` tensor when the codebook
    /// carries categories); returns the file's sha256.
    pub fn save(&self, path: &Path) -> Result<String, WeightsError> {
        let device = super::cpu();
        match &self.categories {
            None => weights::save(
                &CodebookTensors {
                    codes: self.codes_param(&device),
                },
                path,
            ),
            Some(c) => weights::save(
                &CategorisedTensors {
                    codes: self.codes_param(&device),
                    categories: Param::from_data(
                        TensorData::new(c.iter().map(|&k| k as f32).collect(), [c.len()]),
                        &device,
                    ),
                },
                path,
            ),
        }
    }

    /// Load `rows × latent` codes from `path`, verifying `expected_sha256` when given; with
    /// `categories = Some(count)` the file must also hold each row's category index, below
    /// `count`.
    pub fn load(
        path: &Path,
        rows: usize,
        latent: usize,
        categories: Option<usize>,
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
        let empty = Codebook {
            latent,
            codes: vec![0.0; rows * latent],
            categories: None,
        };
        let f32s = |t: TensorData, what: &str| {
            t.try_into_vec::<f32>()
                .map_err(|e| incompatible(format!("{what} are not f32: {e:?}")))
        };
        let Some(count) = categories else {
            let mut t = CodebookTensors {
                codes: empty.codes_param(&device),
            };
            weights::load(&mut t, path, expected_sha256)?;
            let codes = f32s(t.codes.val().into_data(), "codes")?;
            return Codebook::new(latent, codes).map_err(|e| incompatible(e.to_string()));
        };
        let mut t = CategorisedTensors {
            codes: empty.codes_param(&device),
            categories: Param::from_data(TensorData::new(vec![0.0f32; rows], [rows]), &device),
        };
        weights::load(&mut t, path, expected_sha256)?;
        let codes = f32s(t.codes.val().into_data(), "codes")?;
        let raw = f32s(t.categories.val().into_data(), "categories")?;
        if let Some(i) = raw
            .iter()
            .position(|v| !(v.is_finite() && *v >= 0.0 && v.fract() == 0.0))
        {
            return Err(incompatible(format!(
                "category of row {i} is {}, not a category index",
                raw[i]
            )));
        }
        Codebook::new(latent, codes)
            .and_then(|c| c.with_categories(raw.iter().map(|&v| v as u32).collect(), count))
            .map_err(|e| incompatible(e.to_string()))
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
    fn nearest_in_a_category_searches_only_that_categorys_rows() {
        let cb = Codebook::new(2, vec![0.0, 0.0, 1.0, 1.0, -1.0, 2.0, 0.9, 0.9])
            .unwrap()
            .with_categories(vec![3, 3, 0, 0], 4)
            .unwrap();
        assert_eq!(cb.rows_of_category(3), 2);
        assert_eq!(cb.rows_of_category(1), 0);
        // Row 3 (category 0) is nearest over all rows; within category 3 it is row 1.
        assert_eq!(cb.nearest(&[0.92, 0.9]).unwrap().0, 3);
        assert_eq!(cb.nearest_in(&[0.92, 0.9], Some(3)).unwrap().0, 1);
        assert_eq!(cb.nearest_in(&[0.92, 0.9], Some(0)).unwrap().0, 3);
        assert_eq!(cb.nearest_in(&[0.92, 0.9], Some(1)), None, "no rows");
        let plain = Codebook::new(2, vec![0.0, 0.0]).unwrap();
        assert_eq!(
            plain.nearest_in(&[0.0, 0.0], Some(0)),
            None,
            "no categories"
        );
        let e = Codebook::new(2, vec![0.0; 4])
            .unwrap()
            .with_categories(vec![0], 4)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("one per code (2 codes)") && e.contains("1 categories"),
            "{e}"
        );
        let e = Codebook::new(2, vec![0.0; 4])
            .unwrap()
            .with_categories(vec![0, 4], 4)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("below the category count 4") && e.contains("4 at row 1"),
            "{e}"
        );
    }

    #[test]
    fn categories_round_trip_and_a_file_without_them_is_refused_when_asked_for() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("codebook.safetensors");
        let cb = Codebook::new(2, vec![0.5, -1.25, 3.0, 1e-7, 2.0, -0.0])
            .unwrap()
            .with_categories(vec![2, 0, 45], 46)
            .unwrap();
        let sha = cb.save(&path).unwrap();
        assert_eq!(
            Codebook::load(&path, 3, 2, Some(46), Some(&sha)).unwrap(),
            cb
        );
        // The indices must fit the manifest's category list.
        let e = Codebook::load(&path, 3, 2, Some(45), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("below the category count 45"), "{e}");
        let plain = dir.path().join("plain.safetensors");
        Codebook::new(2, vec![0.0; 6])
            .unwrap()
            .save(&plain)
            .unwrap();
        assert!(Codebook::load(&plain, 3, 2, Some(46), None).is_err());
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
        assert_eq!(Codebook::load(&path, 2, 3, None, Some(&sha)).unwrap(), cb);
        let e = Codebook::load(&path, 3, 3, None, Some(&sha))
            .unwrap_err()
            .to_string();
        assert!(e.contains("codebook.safetensors"), "{e}");
        let e = Codebook::load(&path, 2, 3, None, Some("00"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("sha256 mismatch"), "{e}");
    }
}
