//! Training and test data: procedural objects, the PartNet-Mobility layout and importer,
//! partial scans.
//!
//! Why it exists: the shape and diffusion priors need thousands of articulated objects with
//! exact part shapes, and PartNet-Mobility cannot be downloaded here. physnap generates its own
//! (`synth`), writes them exactly as PartNet-Mobility stores objects (`partnet`), and one
//! importer (`dataset`) turns either source into graph records, normalised part meshes, SDF
//! samples and splits. `scan` renders the paper's partial point clouds.

pub mod categories;
pub mod dataset;
pub mod generate;
pub mod partnet;
pub mod rng;
pub mod scan;
pub mod synth;
pub mod urdf;
pub mod validity;

use crate::object::ArticulatedObject;

/// An object with PartNet-Mobility semantic labels, one per part (`drawer`, `door`,
/// `rotation_door`, `handle`, `knob`, `lid`, `furniture_body`, `screen`, `base_body`, ...).
#[derive(Debug, Clone, PartialEq)]
pub struct LabelledObject {
    /// The object (procedural parts carry `PartShape::Primitives`).
    pub object: ArticulatedObject,
    /// Semantic label per part, same order as `object.parts`.
    pub labels: Vec<String>,
}

/// Errors of the data layer.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// An object or option broke a rule of the core model.
    #[error(transparent)]
    Core(#[from] crate::error::CoreError),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A source file is malformed (names the file and what is wrong).
    #[error("{path}: {detail}")]
    Malformed {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong, with the value.
        detail: String,
    },
    /// A command-line or API option is out of range.
    #[error("invalid {0}")]
    Option(crate::error::Invalid),
}

impl DataError {
    /// Machine-readable error kind.
    pub fn error_type(&self) -> &'static str {
        match self {
            DataError::Core(e) => e.error_type(),
            DataError::Io { .. } => "io",
            DataError::Malformed { .. } => "malformed",
            DataError::Option(crate::error::Invalid { .. }) => "invalid_option",
        }
    }

    /// Wrap an I/O error with its path.
    pub fn io(path: impl Into<std::path::PathBuf>) -> impl FnOnce(std::io::Error) -> DataError {
        let path = path.into();
        move |source| DataError::Io { path, source }
    }
}
