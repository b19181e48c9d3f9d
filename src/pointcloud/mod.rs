//! Point-cloud files: PLY (ascii and binary), NPY and JSON readers and writers.
//!
//! Why it exists: physnap takes a partial point cloud of an object (object frame, metres) and
//! generates an articulated 3D model. The data pipeline writes scans with this module, the CLI
//! reads user clouds with it, and the HTTP/gRPC service will reuse the same readers for
//! uploads. So the readers are built for hostile input: they never panic, never allocate from a
//! header's claims before checking them against the [`Limits`] and against the bytes actually
//! present, and every error names what is wrong (the field or header line, the limit, the
//! value) and has a stable machine-readable kind ([`PointCloudError::error_type`]).
//!
//! Formats:
//! - **PLY**: read in any encoding (`ascii`, `binary_little_endian`, `binary_big_endian`);
//!   the `vertex` element must have scalar `x`, `y`, `z` properties (any order, any scalar
//!   type); other vertex properties and other elements are skipped. [`Format::Ply`] writes
//!   binary little-endian `float` x, y, z; [`Format::PlyAscii`] writes ascii.
//! - **NPY**: versions 1.0, 2.0 and 3.0, `descr` `<f4`, `>f4`, `<f8` or `>f8`, C or Fortran
//!   order, shape `(N, 3)`. Written as version 1.0, `<f4`, data aligned to 64 bytes.
//! - **JSON**: `[[x, y, z], ...]` or `{"points": [[x, y, z], ...], ...}` (other keys ignored).
//!   Written as compact `{"points":[[x,y,z],...]}`; every written number reads back to the
//!   same `f32` bit for bit.
//!
//! Every reader ends with [`PointCloud::validate`], so a cloud that comes back from a reader
//! has between `min_points` and `max_points` points, all finite.

use std::collections::HashSet;

mod json;
mod npy;
mod ply;
#[cfg(test)]
mod tests;

pub(crate) use crate::io::snippet;
pub(crate) use json::*;
pub(crate) use npy::*;
pub use ply::*;

use std::fs;
use std::path::{Path, PathBuf};

/// A point cloud in object coordinates (metres). Invariant after `validate`: 1..=max points, all finite.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    /// The points, `[x, y, z]` each.
    pub points: Vec<[f32; 3]>,
}

/// A point-cloud file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// PLY. Written as binary little-endian; read in any PLY encoding.
    Ply,
    /// PLY, written as ascii; read in any PLY encoding (same reader as [`Format::Ply`]).
    PlyAscii,
    /// NumPy `.npy`, an `(N, 3)` float array.
    Npy,
    /// JSON, `{"points": [[x, y, z], ...]}` or a bare `[[x, y, z], ...]`.
    Json,
}

impl Format {
    /// From a file extension: .ply, .npy, .json (case-insensitive). None otherwise.
    pub fn from_path(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?;
        if ext.eq_ignore_ascii_case("ply") {
            Some(Format::Ply)
        } else if ext.eq_ignore_ascii_case("npy") {
            Some(Format::Npy)
        } else if ext.eq_ignore_ascii_case("json") {
            Some(Format::Json)
        } else {
            None
        }
    }
}

/// Why a point cloud could not be read, written or accepted.
#[derive(Debug, thiserror::Error)]
pub enum PointCloudError {
    /// The file system refused (open, read, write, fsync, rename).
    #[error("I/O error on '{}': {source}", path.display())]
    Io {
        /// The file the operation was on.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The path's extension names no supported format.
    #[error(
        "cannot tell the point-cloud format of '{}': expected extension .ply, .npy or .json",
        path.display()
    )]
    UnknownFormat {
        /// The offending path.
        path: PathBuf,
    },
    /// The bytes do not follow the format; `detail` names the header line, field or index.
    #[error("invalid {format}: {detail}")]
    Malformed {
        /// `"PLY"`, `"NPY"` or `"JSON"`.
        format: &'static str,
        /// What is wrong, where, and the offending value.
        detail: String,
    },
    /// The header promises more data than the input holds.
    #[error("truncated {format}: need at least {expected_bytes} bytes, got {got_bytes}")]
    Truncated {
        /// `"PLY"` or `"NPY"`.
        format: &'static str,
        /// Bytes the whole input needs to hold what its header claims.
        expected_bytes: u64,
        /// Bytes the input has.
        got_bytes: u64,
    },
    /// A coordinate is NaN or infinite (or, from JSON, outside the `f32` range).
    #[error("point {index} has a non-finite {} coordinate ({value})", axis_name(*.axis))]
    NonFinite {
        /// Index of the point.
        index: usize,
        /// 0 = x, 1 = y, 2 = z.
        axis: usize,
        /// The offending value.
        value: f32,
    },
    /// The cloud has no points.
    #[error("point cloud is empty (0 points, at least 1 required)")]
    Empty,
    /// Fewer points than [`Limits::min_points`].
    #[error("too few points: {count} (minimum {min})")]
    TooFew {
        /// Points in the cloud.
        count: usize,
        /// The limit.
        min: usize,
    },
    /// More points than [`Limits::max_points`]. `count` is a `u64` because it may be a
    /// header's claim that does not fit a `usize`.
    #[error("too many points: {count} (limit {max})")]
    TooMany {
        /// Points in the cloud, or claimed by its header.
        count: u64,
        /// The limit.
        max: usize,
    },
}

pub(crate) fn axis_name(axis: usize) -> &'static str {
    match axis {
        0 => "x",
        1 => "y",
        2 => "z",
        _ => "unknown-axis",
    }
}

impl PointCloudError {
    /// Stable machine-readable kind: "io", "unknown_format", "malformed", "truncated",
    /// "non_finite", "empty", "too_few", "too_many".
    pub fn error_type(&self) -> &'static str {
        match self {
            PointCloudError::Io { .. } => "io",
            PointCloudError::UnknownFormat { .. } => "unknown_format",
            PointCloudError::Malformed { .. } => "malformed",
            PointCloudError::Truncated { .. } => "truncated",
            PointCloudError::NonFinite { .. } => "non_finite",
            PointCloudError::Empty => "empty",
            PointCloudError::TooFew { .. } => "too_few",
            PointCloudError::TooMany { .. } => "too_many",
        }
    }
}

/// Limits applied by readers and `validate`.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Fewest points accepted (an empty cloud is always rejected).
    pub min_points: usize,
    /// Most points accepted; readers check a header's count against it before allocating.
    pub max_points: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            min_points: 1,
            max_points: 10_000_000,
        }
    }
}

impl PointCloud {
    /// Checks the invariant: at least one point, `min_points..=max_points` points, all finite.
    pub fn validate(&self, limits: &Limits) -> Result<(), PointCloudError> {
        check_count(self.points.len() as u64, limits)?;
        for (index, p) in self.points.iter().enumerate() {
            for (axis, &value) in p.iter().enumerate() {
                if !value.is_finite() {
                    return Err(PointCloudError::NonFinite { index, axis, value });
                }
            }
        }
        Ok(())
    }

    /// Reads a file, choosing the format by its extension (see [`Format::from_path`]).
    pub fn read(path: &Path, limits: &Limits) -> Result<PointCloud, PointCloudError> {
        let format = Format::from_path(path).ok_or_else(|| PointCloudError::UnknownFormat {
            path: path.to_path_buf(),
        })?;
        let bytes = fs::read(path).map_err(|source| PointCloudError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(&bytes, format, limits)
    }

    /// Parses `bytes` as `format` (both PLY variants read any PLY encoding) and validates.
    pub fn from_bytes(
        bytes: &[u8],
        format: Format,
        limits: &Limits,
    ) -> Result<PointCloud, PointCloudError> {
        let points = match format {
            Format::Ply | Format::PlyAscii => ply_read(bytes, limits)?,
            Format::Npy => npy_read(bytes, limits)?,
            Format::Json => json_read(bytes, limits)?,
        };
        let cloud = PointCloud { points };
        cloud.validate(limits)?;
        Ok(cloud)
    }

    /// Serialises the cloud. Does not validate: PLY and NPY keep non-finite values as they are,
    /// JSON writes them as `null`; the readers reject both.
    pub fn to_bytes(&self, format: Format) -> Vec<u8> {
        match format {
            Format::Ply => ply_write(&self.points, false),
            Format::PlyAscii => ply_write(&self.points, true),
            Format::Npy => npy_write(&self.points),
            Format::Json => json_write(&self.points),
        }
    }

    /// Atomic write: temp file in the same dir + fsync + rename.
    pub fn write(&self, path: &Path, format: Format) -> Result<(), PointCloudError> {
        atomic_write(path, &self.to_bytes(format))
    }

    /// Axis-aligned bounds (min, max); None if empty. NaN coordinates are ignored.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let first = *self.points.first()?;
        let mut lo = first;
        let mut hi = first;
        for p in &self.points[1..] {
            for axis in 0..3 {
                lo[axis] = lo[axis].min(p[axis]);
                hi[axis] = hi[axis].max(p[axis]);
            }
        }
        Some((lo, hi))
    }
}

// ---------------------------------------------------------------------------------------------
// Shared helpers

pub(crate) const PLY: &str = "PLY";

pub(crate) const NPY: &str = "NPY";

pub(crate) const JSON: &str = "JSON";

pub(crate) fn mal(format: &'static str, detail: impl Into<String>) -> PointCloudError {
    PointCloudError::Malformed {
        format,
        detail: detail.into(),
    }
}

pub(crate) fn truncated(
    format: &'static str,
    expected_bytes: u64,
    got_bytes: usize,
) -> PointCloudError {
    PointCloudError::Truncated {
        format,
        expected_bytes,
        got_bytes: got_bytes as u64,
    }
}

/// Checks a point count (possibly a header's claim) against the limits, before allocating.
pub(crate) fn check_count(count: u64, limits: &Limits) -> Result<usize, PointCloudError> {
    if count > limits.max_points as u64 {
        return Err(PointCloudError::TooMany {
            count,
            max: limits.max_points,
        });
    }
    // count <= max_points, a usize, so this cannot fail; stay panic-free anyway.
    let count = usize::try_from(count).unwrap_or(usize::MAX);
    if count == 0 {
        return Err(PointCloudError::Empty);
    }
    if count < limits.min_points {
        return Err(PointCloudError::TooFew {
            count,
            min: limits.min_points,
        });
    }
    Ok(count)
}

pub(crate) fn atomic_write(path: &Path, bytes: &[u8]) -> Result<(), PointCloudError> {
    crate::io::atomic::write(path, bytes).map_err(|e| PointCloudError::Io {
        path: e.path,
        source: e.source,
    })
}
