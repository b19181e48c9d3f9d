//! Trainers: the part-shape auto-encoder (`physnap train shape`) and, later, the articulation
//! denoiser.
//!
//! Why it exists: training is a library function (data directory + config in, weights and a
//! report out, progress through a callback) so the CLI, tests and benchmarks drive the same
//! code. Trainers read the layout `data::dataset` writes, load what they need into memory once,
//! and are deterministic for a seed (own [`crate::data::rng::Rng`], seeded weight init). CPU
//! work runs on the current rayon pool unless a config asks for its own thread count.

pub mod codebook;
pub mod diffusion;
pub mod ema;
pub mod held_out;
pub mod shape;

use std::path::{Path, PathBuf};

/// Errors of the training layer.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A data or weights file is malformed or inconsistent (names the file and the problem).
    #[error("{path}: {detail}")]
    Data {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the value.
        detail: String,
    },
    /// A configuration value is out of range.
    #[error("invalid training config {0}")]
    Config(crate::error::Invalid),
    /// The loss became non-finite or exploded.
    #[error("training diverged at step {step}: loss {loss}")]
    Diverged {
        /// The step (0-based).
        step: usize,
        /// The loss value.
        loss: f64,
    },
    /// The model configuration is invalid.
    #[error(transparent)]
    Model(#[from] crate::model::ModelError),
    /// A graph record is inconsistent.
    #[error(transparent)]
    Core(#[from] crate::error::CoreError),
    /// A weights file could not be saved or loaded.
    #[error(transparent)]
    Weights(#[from] crate::model::weights::WeightsError),
}

impl TrainError {
    /// Machine-readable error kind.
    pub fn error_type(&self) -> &'static str {
        match self {
            TrainError::Io { .. } => "io",
            TrainError::Data { .. } => "malformed",
            TrainError::Config(crate::error::Invalid { .. }) => "invalid_option",
            TrainError::Diverged { .. } => "diverged",
            TrainError::Model(_) => "invalid_option",
            TrainError::Core(e) => e.error_type(),
            TrainError::Weights(_) => "weights",
        }
    }

    /// Wrap an I/O error with its path.
    pub fn io(path: impl AsRef<Path>) -> impl FnOnce(std::io::Error) -> TrainError {
        let path = path.as_ref().to_path_buf();
        move |source| TrainError::Io { path, source }
    }

    /// A data error about `path`.
    pub fn data(path: impl AsRef<Path>, detail: impl Into<String>) -> TrainError {
        TrainError::Data {
            path: path.as_ref().to_path_buf(),
            detail: detail.into(),
        }
    }

    /// A config error naming field, rule and value.
    pub fn config(
        field: impl Into<String>,
        limit: impl Into<String>,
        value: impl ToString,
    ) -> TrainError {
        TrainError::Config(crate::error::Invalid {
            field: field.into(),
            limit: limit.into(),
            value: value.to_string(),
        })
    }
}

/// The batch's loss and gradient from its slices' (both trainers' `--batch-shards`): the
/// values and gradients summed in slice order, so the result does not depend on which thread
/// finished first.
pub(crate) fn sum_slices<M: burn::module::Module>(
    model: &M,
    slices: Vec<(f64, burn::optim::GradientsParams)>,
) -> (f64, burn::optim::GradientsParams) {
    let mut acc = burn::optim::GradientsAccumulator::<M>::new();
    let mut value = 0.0;
    for (v, g) in slices {
        value += v;
        acc.accumulate(model, g);
    }
    (value, acc.grads())
}

/// The check both trainers' batch-slice tests share. `run(k)` trains a short run with the batch
/// in k slices and returns its per-step losses and its weights file. Two and three slices must
/// track the single pass within 1e-4 per step (the same loss and gradient up to float
/// rounding), round differently from it (so the slices really ran), and a repeated two-slice
/// run must give the same losses and the same file, bit for bit.
#[cfg(test)]
pub(crate) fn check_sharded_runs(mut run: impl FnMut(usize) -> (Vec<f64>, Vec<u8>)) {
    let (one, w1) = run(1);
    let (two, w2) = run(2);
    let (three, _) = run(3);
    assert!(!one.is_empty() && one.len() == two.len() && one.len() == three.len());
    for (k, ((a, b), c)) in one.iter().zip(&two).zip(&three).enumerate() {
        assert!(
            (a - b).abs() <= 1e-4 * a.abs(),
            "step {k}: {a} vs {b} (2 shards)"
        );
        assert!(
            (a - c).abs() <= 1e-4 * a.abs(),
            "step {k}: {a} vs {c} (3 shards)"
        );
    }
    assert_ne!(w1, w2, "two shards should round differently from one pass");
    let (again, w2b) = run(2);
    assert_eq!(two, again);
    assert!(w2 == w2b, "the repeated run's weights differ");
}
