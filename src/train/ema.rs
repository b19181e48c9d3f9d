//! Exponential moving average of a model's weights, shared by `train shape` and
//! `train diffusion`.
//!
//! Why it exists: both trainers run Adam at a learning rate whose step noise limits what the
//! raw weights reach; the average of the recent weights samples (denoiser) and decodes (shape
//! prior) better than the last iterate. After every optimiser step the shadow follows
//!
//! ```text
//! θ̄ ← d θ̄ + (1 − d) θ,   d = min(decay, (1 + n) / (10 + n))
//! ```
//!
//! with n the number of updates so far (the warm-up keeps the shadow from remembering the
//! initialisation). The shadow lives on the host as one `Vec<f32>` per float parameter, in the
//! module's visiting order; [`Ema::install`] writes it into a copy of the module.

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::{Tensor, TensorData};

/// The shadow weights of one module.
#[derive(Debug, Clone)]
pub struct Ema {
    /// Target decay (the warm-up caps it early on).
    pub decay: f64,
    /// Updates so far (n).
    pub steps: usize,
    shadow: Vec<Vec<f32>>,
}

impl Ema {
    /// A shadow starting at `model`'s weights, with `steps` updates already counted (0 for a
    /// new run; a resumed run passes its checkpoint's count).
    pub fn new<M: Module>(model: &M, decay: f64, steps: usize) -> Self {
        Ema {
            decay,
            steps,
            shadow: collect(model),
        }
    }

    /// Decay of the next update: `min(decay, (1 + n) / (10 + n))`.
    pub fn next_decay(&self) -> f64 {
        let n = self.steps as f64;
        self.decay.min((1.0 + n) / (10.0 + n))
    }

    /// Blend `model`'s current weights into the shadow.
    pub fn update<M: Module>(&mut self, model: &M) {
        let decay = self.next_decay() as f32;
        model.visit(&mut Blend {
            shadow: &mut self.shadow,
            decay,
            next: 0,
        });
        self.steps += 1;
    }

    /// `model` with its float parameters replaced by the shadow.
    pub fn install<M: Module>(&self, model: M) -> M {
        model.map(&mut Install {
            shadow: &self.shadow,
            next: 0,
        })
    }
}

/// Host copies of a module's float parameters, in visiting order.
pub fn collect<M: Module>(m: &M) -> Vec<Vec<f32>> {
    let mut c = Collect(Vec::new());
    m.visit(&mut c);
    c.0
}

struct Collect(Vec<Vec<f32>>);

impl ModuleVisitor for Collect {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let v = param.val().into_data().convert::<f32>();
        self.0.push(v.try_to_vec::<f32>().unwrap_or_default());
    }
}

/// `shadow[i] ← d · shadow[i] + (1 − d) · θᵢ` over a module's float parameters.
struct Blend<'a> {
    shadow: &'a mut [Vec<f32>],
    decay: f32,
    next: usize,
}

impl ModuleVisitor for Blend<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let v = param.val().into_data().convert::<f32>();
        let v = v.as_slice::<f32>().unwrap_or(&[]);
        let s = &mut self.shadow[self.next];
        let d = self.decay;
        for (a, b) in s.iter_mut().zip(v) {
            *a = d * *a + (1.0 - d) * b;
        }
        self.next += 1;
    }
}

/// Replaces a module's float parameters by the shadow values.
struct Install<'a> {
    shadow: &'a [Vec<f32>],
    next: usize,
}

impl ModuleMapper for Install<'_> {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let values = self.shadow[self.next].clone();
        self.next += 1;
        param.map(|t| {
            let (shape, device) = (t.shape(), t.device());
            Tensor::from_data(TensorData::new(values, shape), &device)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::shape_prior::{ShapePrior, ShapePriorConfig};

    fn tiny() -> ShapePriorConfig {
        ShapePriorConfig {
            latent: 4,
            decoder_hidden: 8,
            decoder_blocks: 1,
            encoder_hidden: 8,
            encoder_blocks: 1,
            pe_freqs: 1,
            code_every_block: false,
        }
    }

    /// One update with the target decay blends every parameter, and `install` writes the
    /// blend back into a module of the same shape.
    #[test]
    fn blends_and_installs_every_parameter() {
        let device = crate::model::cpu();
        let a = ShapePrior::with_seed(&tiny(), 1, &device);
        let b = ShapePrior::with_seed(&tiny(), 2, &device);
        let (va, vb) = (collect(&a), collect(&b));
        assert_ne!(va, vb, "two initialisations should differ");
        // n = 1000 updates so far: the warm-up cap (1001 / 1010) is above the target 0.25.
        let mut ema = Ema::new(&a, 0.25, 1000);
        assert_eq!(ema.next_decay(), 0.25);
        ema.update(&b);
        assert_eq!(ema.steps, 1001);
        let installed = collect(&ema.install(a.clone()));
        assert_eq!(installed.len(), va.len());
        for ((x, y), z) in va
            .iter()
            .flatten()
            .zip(vb.iter().flatten())
            .zip(installed.iter().flatten())
        {
            assert!((0.25 * x + 0.75 * y - z).abs() < 1e-6);
        }
    }

    /// The warm-up: the first update copies the model almost entirely (d = 1/10), later ones
    /// approach the target.
    #[test]
    fn warm_up_caps_the_decay() {
        let device = crate::model::cpu();
        let a = ShapePrior::with_seed(&tiny(), 1, &device);
        let mut ema = Ema::new(&a, 0.999, 0);
        assert!((ema.next_decay() - 0.1).abs() < 1e-12);
        ema.update(&a);
        assert!((ema.next_decay() - 2.0 / 11.0).abs() < 1e-12);
        ema.steps = 1_000_000;
        assert_eq!(ema.next_decay(), 0.999);
    }
}
