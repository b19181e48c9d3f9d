//! The core layer's error type.
//!
//! Why it exists: every check on an articulated object or an articulation graph (the object
//! model, the graph tensor, projection, kinematics and meshing) reports through one enum, so
//! callers (CLI, exporters, later the service) map exactly one type. Each variant names the
//! offending field, the limit it broke and the value it had, because that is what a user needs
//! to fix their input.

use std::fmt;

/// One broken rule: the field, the limit it broke and the value it had. Every layer's
/// "invalid input" variant carries one (`CoreError::Invalid`, `ModelError::Config`,
/// `EngineError::Invalid`, `TrainError::Config`, `DataError::Option`, `UrdfError::Option`,
/// `EvalError::Invalid`, `RealError::Invalid`), so a caller reads the three the same way
/// whatever the layer; the service's [`Violation`](crate::service::spec::Violation) is the same
/// triple on the wire.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {value} (must be {limit})")]
pub struct Invalid {
    /// Path of the field, e.g. `parts[2].half_extents[1]`.
    pub field: String,
    /// The rule it broke, e.g. `> 0`, `at most 8`.
    pub limit: String,
    /// The offending value, rendered.
    pub value: String,
}

impl Invalid {
    /// The triple from anything printable.
    pub fn new(
        field: impl Into<String>,
        limit: impl Into<String>,
        value: impl fmt::Display,
    ) -> Self {
        Invalid {
            field: field.into(),
            limit: limit.into(),
            value: value.to_string(),
        }
    }
}

/// An error of the geometry core: bad object, bad graph, failed projection.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CoreError {
    /// A field's value broke a limit, e.g. `parts[2].half_extents[1]` = -0.1, limit "> 0".
    #[error("invalid {0}")]
    Invalid(crate::error::Invalid),
    /// The object is structurally inconsistent (joint graph not a tree, duplicate names, ...).
    #[error("invalid object structure: {0}")]
    Structure(String),
}

impl CoreError {
    /// Shorthand for [`CoreError::Invalid`].
    pub fn invalid(
        field: impl Into<String>,
        limit: impl Into<String>,
        value: impl fmt::Display,
    ) -> Self {
        CoreError::Invalid(Invalid::new(field, limit, value))
    }

    /// Machine-readable error kind, stable across releases.
    pub fn error_type(&self) -> &'static str {
        match self {
            CoreError::Invalid(crate::error::Invalid { .. }) => "invalid_field",
            CoreError::Structure(_) => "invalid_structure",
        }
    }
}

/// Result alias of the core layer.
pub type CoreResult<T> = Result<T, CoreError>;

/// Check that every value is finite; the error names `field[index]`.
pub fn check_finite(field: &str, values: &[f64]) -> CoreResult<()> {
    for (i, v) in values.iter().enumerate() {
        if !v.is_finite() {
            return Err(CoreError::invalid(format!("{field}[{i}]"), "finite", v));
        }
    }
    Ok(())
}
