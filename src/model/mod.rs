//! Neural networks: the part-shape prior (SDF auto-decoder/encoder) and the articulation
//! denoiser, on burn 0.22.1's Flex CPU backend.
//!
//! Why it exists: this is the learned half of physnap. Model code is backend-agnostic burn
//! (`Tensor<D>` carries its device); [`cpu`] and [`cpu_autodiff`] give the devices the rest of
//! the crate uses. CPU work runs on the *current* rayon pool, so callers bound a job with
//! `ThreadPool::install` (ml-stack.md §4).

pub mod codebook;
pub mod denoiser;
pub mod host_decoder;
pub mod shape_prior;

use burn::tensor::Device;

pub mod weights;

/// The inference device: Flex (pure-Rust CPU).
pub fn cpu() -> Device {
    Device::flex()
}

/// The training / guidance device: Flex with reverse-mode autodiff.
pub fn cpu_autodiff() -> Device {
    Device::flex().autodiff()
}

/// Errors of the model layer.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// A configuration value is out of range.
    #[error("invalid model config {field}: {value} (must be {limit})")]
    Config {
        /// The field.
        field: String,
        /// The rule.
        limit: String,
        /// The value.
        value: String,
    },
    /// A tensor had the wrong shape.
    #[error("shape mismatch for {what}: expected {expected}, got {got}")]
    Shape {
        /// What was checked.
        what: String,
        /// Expected shape.
        expected: String,
        /// Actual shape.
        got: String,
    },
}

#[cfg(test)]
mod tests {
    use burn::tensor::Tensor;

    #[test]
    fn flex_autodiff_backward_works() {
        let device = super::cpu_autodiff();
        let x = Tensor::<1>::from_floats([1.0, 2.0, 3.0], &device).require_grad();
        let y = (x.clone() * x.clone()).sum();
        let grads = y.backward();
        let g = x.grad(&grads).expect("gradient");
        let v: Vec<f32> = g.into_data().try_to_vec::<f32>().expect("f32 data");
        assert_eq!(v, vec![2.0, 4.0, 6.0]);
    }
}
