//! Saving and loading model weights as safetensors, with sha256 checks.
//!
//! Why it exists: shipped weights must load only when they are exactly the files the manifest
//! describes, and fail clearly otherwise (a truncated download, a config that does not fit).
//! Saving goes through burn's `SafetensorsStore` into memory, then an atomic write; loading
//! verifies the sha256 first, then applies the tensors and refuses missing, unused or
//! mis-shaped tensors. f32 tensors round-trip bit-exactly, and equal weights give byte-equal
//! files (the header's metadata is written in sorted order), so equal weights hash alike.

use std::path::Path;

use burn::module::Module;
use burn::store::{ModuleSnapshot, SafetensorsStore};
use sha2::{Digest, Sha256};

/// Errors of loading or saving weights.
#[derive(Debug, thiserror::Error)]
pub enum WeightsError {
    /// Reading or writing the file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The file is not the one the manifest names.
    #[error(
        "{path}: sha256 mismatch: manifest says {expected}, file has {actual} (corrupted or replaced weights)"
    )]
    Checksum {
        /// The file.
        path: String,
        /// From the manifest.
        expected: String,
        /// Of the bytes on disk.
        actual: String,
    },
    /// The file is not valid safetensors, or does not fit the model's configuration.
    #[error("{path}: {detail}")]
    Incompatible {
        /// The file.
        path: String,
        /// What does not fit.
        detail: String,
    },
}

/// Hex sha256 of bytes.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Serialise a module's parameters to safetensors bytes.
pub fn to_bytes<M: Module + ModuleSnapshot>(module: &M) -> Result<Vec<u8>, WeightsError> {
    let mut store = SafetensorsStore::from_bytes(None);
    let err = |e: &dyn std::fmt::Display| WeightsError::Incompatible {
        path: "<memory>".into(),
        detail: e.to_string(),
    };
    module.save_into(&mut store).map_err(|e| err(&e))?;
    let mut bytes = store.get_bytes().map_err(|e| err(&e))?;
    sort_metadata(&mut bytes);
    Ok(bytes)
}

/// Put the `__metadata__` entries of a safetensors header in sorted order, in place.
///
/// burn 0.22.1 writes them (`producer`, `format`, `version`) from a hash map, so two saves of
/// the same weights could differ in these bytes and so in their sha256. Sorting makes equal
/// weights give equal files. The entries are flat `"key":"value"` strings; anything else (a
/// comma or brace inside a value, no metadata) leaves the bytes untouched, and the header's
/// length never changes, so the tensors' offsets stay valid.
fn sort_metadata(bytes: &mut [u8]) {
    const KEY: &[u8] = b"\"__metadata__\":{";
    let Some(len) = bytes
        .get(..8)
        .map(|b| u64::from_le_bytes(b.try_into().unwrap_or_default()))
    else {
        return;
    };
    let Some(header) = usize::try_from(len)
        .ok()
        .and_then(|n| bytes.get_mut(8..8 + n))
    else {
        return;
    };
    let Some(start) = header
        .windows(KEY.len())
        .position(|w| w == KEY)
        .map(|i| i + KEY.len())
    else {
        return;
    };
    let Some(end) = header[start..]
        .iter()
        .position(|&b| b == b'}')
        .map(|i| start + i)
    else {
        return;
    };
    let Ok(inner) = std::str::from_utf8(&header[start..end]) else {
        return;
    };
    let mut entries: Vec<&str> = inner.split(',').collect();
    if entries
        .iter()
        .any(|e| e.matches('"').count() != 4 || !e.starts_with('"') || e.contains('{'))
    {
        return;
    }
    entries.sort_unstable();
    let sorted = entries.join(",");
    header[start..end].copy_from_slice(sorted.as_bytes());
}

/// Save a module to `path` (atomically); returns the file's sha256.
pub fn save<M: Module + ModuleSnapshot>(module: &M, path: &Path) -> Result<String, WeightsError> {
    let bytes = to_bytes(module)?;
    let io = |source| WeightsError::Io {
        path: path.display().to_string(),
        source,
    };
    crate::io::atomic::write(path, &bytes).map_err(|e| io(e.source))?;
    Ok(sha256_hex(&bytes))
}

/// Load parameters from `path` into `module` (built with the matching config). When
/// `expected_sha256` is given, the file must match it.
pub fn load<M: Module + ModuleSnapshot>(
    module: &mut M,
    path: &Path,
    expected_sha256: Option<&str>,
) -> Result<(), WeightsError> {
    let p = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| WeightsError::Io {
        path: p.clone(),
        source,
    })?;
    if let Some(expected) = expected_sha256 {
        let actual = sha256_hex(&bytes);
        if !actual.eq_ignore_ascii_case(expected) {
            return Err(WeightsError::Checksum {
                path: p,
                expected: expected.into(),
                actual,
            });
        }
    }
    load_bytes(module, bytes, &p)
}

/// Load parameters from safetensors bytes (`what` names the source in errors).
pub fn load_bytes<M: Module + ModuleSnapshot>(
    module: &mut M,
    bytes: Vec<u8>,
    what: &str,
) -> Result<(), WeightsError> {
    let incompatible = |detail: String| WeightsError::Incompatible {
        path: what.into(),
        detail,
    };
    let mut store = SafetensorsStore::from_bytes(Some(bytes));
    let result = module.load_from(&mut store).map_err(|e| {
        incompatible(format!(
            "cannot be loaded into this model configuration (wrong file or config?): {e}"
        ))
    })?;
    if !result.errors.is_empty() {
        return Err(incompatible(format!(
            "tensors do not fit the model configuration: {:?}",
            result.errors
        )));
    }
    if !result.missing.is_empty() {
        let names: Vec<&str> = result.missing.iter().map(|(n, _)| n.as_str()).collect();
        return Err(incompatible(format!(
            "missing tensors for this model configuration: {}",
            names.join(", ")
        )));
    }
    if !result.unused.is_empty() {
        return Err(incompatible(format!(
            "tensors not used by this model configuration: {}",
            result.unused.join(", ")
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use burn::module::Module;
    use burn::nn::{Linear, LinearConfig};
    use burn::tensor::{Tensor, TensorData};

    #[derive(Module, Debug)]
    struct Tiny {
        a: Linear,
        b: Linear,
    }

    fn tiny(width: usize) -> Tiny {
        let d = crate::model::cpu();
        Tiny {
            a: LinearConfig::new(3, width).init(&d),
            b: LinearConfig::new(width, 2).init(&d),
        }
    }

    fn out(m: &Tiny) -> Vec<f32> {
        let d = crate::model::cpu();
        let x = Tensor::<2>::from_data(
            TensorData::new(vec![0.1f32, -0.2, 0.3, 1.0, 2.0, 3.0], [2, 3]),
            &d,
        );
        m.b.forward(m.a.forward(x))
            .into_data()
            .try_to_vec::<f32>()
            .unwrap()
    }

    #[test]
    fn round_trip_is_bit_exact_and_checksums_are_enforced() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("w.safetensors");
        let m = tiny(8);
        let sha = super::save(&m, &path).unwrap();
        let mut n = tiny(8);
        super::load(&mut n, &path, Some(&sha)).unwrap();
        assert_eq!(out(&m), out(&n));
        // Corrupt one byte: refused with a checksum error naming both hashes.
        let mut bytes = std::fs::read(&path).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 0x55;
        std::fs::write(&path, &bytes).unwrap();
        let e = super::load(&mut tiny(8), &path, Some(&sha))
            .unwrap_err()
            .to_string();
        assert!(e.contains("sha256 mismatch") && e.contains(&sha), "{e}");
        // Truncated file without a checksum: refused as not loadable.
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        assert!(super::load(&mut tiny(8), &path, None).is_err());
    }

    #[test]
    fn equal_weights_give_equal_files() {
        // burn writes the header's metadata from a hash map; save sorts it, so the same
        // weights always hash alike (the order differed between saves before).
        let m = tiny(8);
        let first = super::to_bytes(&m).unwrap();
        for _ in 0..8 {
            assert_eq!(super::to_bytes(&m).unwrap(), first);
        }
        let n = u64::from_le_bytes(first[..8].try_into().unwrap()) as usize;
        let header = std::str::from_utf8(&first[8..8 + n]).unwrap();
        assert!(
            header.starts_with(
                r#"{"__metadata__":{"format":"safetensors","producer":"burn","version":"#
            ),
            "{header}"
        );
        // Bytes that are not a safetensors header are left alone.
        let mut junk = vec![1u8, 2, 3];
        super::sort_metadata(&mut junk);
        assert_eq!(junk, [1, 2, 3]);
    }

    #[test]
    fn a_config_that_does_not_fit_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("w.safetensors");
        super::save(&tiny(8), &path).unwrap();
        let e = super::load(&mut tiny(16), &path, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("model configuration") && e.contains("a.weight"),
            "{e}"
        );
    }
}
