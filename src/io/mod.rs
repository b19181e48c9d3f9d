//! File formats physnap reads and writes that are not export artefacts.
//!
//! Why it exists: serialisation is kept out of the core (`object`, `graph`, `mesh`,
//! `kinematics` never import serde); this layer maps wire/file shapes onto core types and back.

pub mod atomic;
pub mod manifest;
pub mod npy;
pub mod object_json;
pub mod real;
pub mod verdict;

/// Errors of the file-format layer.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The text is not valid JSON for the schema; `path` locates the field.
    #[error("malformed {what} at `{path}`: {message}")]
    Malformed {
        /// What was being read, e.g. "object JSON".
        what: &'static str,
        /// JSON path of the offending field (`.` for the document).
        path: String,
        /// The parser's message (with line and column).
        message: String,
    },
    /// The document parsed, but a value breaks a rule of the object model.
    #[error(transparent)]
    Invalid(#[from] crate::error::CoreError),
    /// A weights file is missing, corrupted or does not fit its config.
    #[error(transparent)]
    Weights(#[from] crate::model::weights::WeightsError),
    /// Reading or writing the file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        source: std::io::Error,
    },
}

impl FormatError {
    /// Machine-readable error kind.
    pub fn error_type(&self) -> &'static str {
        match self {
            FormatError::Malformed { .. } => "malformed",
            FormatError::Invalid(e) => e.error_type(),
            FormatError::Weights(_) => "weights",
            FormatError::Io { .. } => "io",
        }
    }
}

/// At most 40 bytes of untrusted input, escaped, for error messages.
pub(crate) fn snippet(bytes: &[u8]) -> String {
    const MAX: usize = 40;
    let mut s = bytes[..bytes.len().min(MAX)].escape_ascii().to_string();
    if bytes.len() > MAX {
        s.push_str("...");
    }
    s
}
