//! The generation engine: schedule, sampling loop, PhysNAP's loss guidance.
//!
//! Why it exists: this is the transport-free core that the CLI and the service both drive. It
//! takes validated inputs (no serde, prost or HTTP types), runs the reverse diffusion on the
//! current rayon pool, reports every step through a callback (progress, cancellation, previews)
//! and returns raw graphs for projection and export.

pub mod frame;
pub mod free_space;
pub mod generate;
pub mod guidance;
pub mod predict;
pub mod prune;
pub mod sample;
pub mod schedule;

use crate::graph::{EDGE_DIM, GraphTensor, K, NODE_DIM, NUM_EDGES};
use burn::tensor::{Device, Tensor, TensorData};

/// Errors of the engine layer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EngineError {
    /// An option is out of range.
    #[error("invalid {0}")]
    Invalid(crate::error::Invalid),
    /// The caller asked to stop (cancellation or deadline), at the given step.
    #[error("stopped at step {step} of {total}: {reason}")]
    Stopped {
        /// Steps completed.
        step: usize,
        /// Steps planned.
        total: usize,
        /// Why.
        reason: String,
    },
    /// The sample diverged (non-finite values, or a guidance gradient beyond
    /// `sample::DIVERGENCE_LIMIT`), at the given step.
    #[error("sampling diverged at step {step} (t = {t}): non-finite or runaway values in {what}")]
    Diverged {
        /// Steps completed.
        step: usize,
        /// Diffusion time index.
        t: usize,
        /// Which tensor.
        what: &'static str,
    },
}

impl EngineError {
    /// Machine-readable error kind.
    pub fn error_type(&self) -> &'static str {
        match self {
            EngineError::Invalid(crate::error::Invalid { .. }) => "invalid_option",
            EngineError::Stopped { .. } => "stopped",
            EngineError::Diverged { .. } => "diverged",
        }
    }
}

/// Stack graphs into (V [B, 8, 135], E [B, 28, 13]) tensors.
pub fn to_tensors(graphs: &[GraphTensor], device: &Device) -> (Tensor<3>, Tensor<3>) {
    let b = graphs.len();
    let v: Vec<f32> = graphs
        .iter()
        .flat_map(|g| g.nodes.iter().copied())
        .collect();
    let e: Vec<f32> = graphs
        .iter()
        .flat_map(|g| g.edges.iter().copied())
        .collect();
    (
        Tensor::from_data(TensorData::new(v, [b, K, NODE_DIM]), device),
        Tensor::from_data(TensorData::new(e, [b, NUM_EDGES, EDGE_DIM]), device),
    )
}

/// Split (V, E) tensors back into graphs.
pub fn from_tensors(v: Tensor<3>, e: Tensor<3>) -> Vec<GraphTensor> {
    let b = v.dims()[0];
    let vd: Vec<f32> = v.into_data().try_to_vec::<f32>().unwrap_or_default();
    let ed: Vec<f32> = e.into_data().try_to_vec::<f32>().unwrap_or_default();
    (0..b)
        .map(|i| GraphTensor {
            nodes: vd[i * K * NODE_DIM..(i + 1) * K * NODE_DIM].to_vec(),
            edges: ed[i * NUM_EDGES * EDGE_DIM..(i + 1) * NUM_EDGES * EDGE_DIM].to_vec(),
        })
        .collect()
}
