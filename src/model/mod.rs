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
pub(crate) mod kernels;
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

/// Where training runs: the Flex CPU backend (always there) or, in a binary built with
/// `--features gpu`, burn's Vulkan backend (wgpu, SPIR-V kernels): the best Vulkan device
/// (`gpu`; `CUBECL_WGPU_DEFAULT_DEVICE` overrides) or discrete GPU `N` (`gpu:N`).
/// Inference (sampling, guidance, the service) stays on the CPU; a model trained on a GPU is
/// saved and loaded like any other.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compute {
    /// Flex on the current rayon pool.
    #[default]
    Cpu,
    /// Vulkan on the discrete GPU with this index, or (None) the best Vulkan device.
    Gpu(Option<usize>),
}

impl Compute {
    /// Parse `cpu`, `gpu` (the best Vulkan device) or `gpu:N` (discrete GPU N). `field` names the option in the error.
    pub fn parse(field: &str, s: &str) -> Result<Self, ModelError> {
        let bad = |limit: &str| {
            ModelError::Config(crate::error::Invalid {
                field: field.to_string(),
                limit: limit.to_string(),
                value: s.to_string(),
            })
        };
        let compute = match s {
            "cpu" => return Ok(Compute::Cpu),
            "gpu" => Compute::Gpu(None),
            _ => match s.strip_prefix("gpu:").map(str::parse::<usize>) {
                Some(Ok(i)) => Compute::Gpu(Some(i)),
                _ => return Err(bad("cpu, gpu or gpu:N")),
            },
        };
        if cfg!(feature = "gpu") {
            Ok(compute)
        } else {
            Err(bad(
                "cpu in this binary (built without GPU support: cargo build --release --features gpu)",
            ))
        }
    }

    /// The name reports carry (`cpu`, `gpu`, `gpu:0`).
    pub fn name(self) -> String {
        match self {
            Compute::Cpu => "cpu".to_string(),
            Compute::Gpu(None) => "gpu".to_string(),
            Compute::Gpu(Some(i)) => format!("gpu:{i}"),
        }
    }

    /// The inference device.
    pub fn device(self) -> Device {
        match self {
            Compute::Cpu => cpu(),
            Compute::Gpu(i) => gpu_device(i),
        }
    }

    /// The training device (with autodiff).
    pub fn autodiff(self) -> Device {
        self.device().autodiff()
    }
}

#[cfg(feature = "gpu")]
fn gpu_device(index: Option<usize>) -> Device {
    use burn::tensor::DeviceKind;
    Device::vulkan(index.map_or(DeviceKind::DefaultDevice, DeviceKind::DiscreteGpu))
}

#[cfg(not(feature = "gpu"))]
fn gpu_device(_index: Option<usize>) -> Device {
    unreachable!("Compute::parse refuses gpu in a binary built without the gpu feature")
}

/// Errors of the model layer.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// A configuration value is out of range.
    #[error("invalid model config {0}")]
    Config(crate::error::Invalid),
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
    fn compute_parses_and_names_the_limit() {
        use super::Compute;
        assert_eq!(Compute::parse("device", "cpu").unwrap(), Compute::Cpu);
        let e = Compute::parse("device", "tpu").unwrap_err().to_string();
        assert!(
            e.contains("device") && e.contains("tpu") && e.contains("gpu:N"),
            "{e}"
        );
        let gpu = Compute::parse("device", "gpu:1");
        if cfg!(feature = "gpu") {
            assert_eq!(gpu.unwrap(), Compute::Gpu(Some(1)));
        } else {
            let e = gpu.unwrap_err().to_string();
            assert!(e.contains("--features gpu") && e.contains("gpu:1"), "{e}");
        }
    }

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
