//! `physnap eval denoiser`: a trained denoiser's ε-loss on a held-out split, with and
//! without its category.
//!
//! Why it exists: the training loss keeps falling over restart cycles while the generative
//! metrics do not follow, and those metrics take a quarter
//! of an hour a seed and are measured on the test split. This measures, in about a minute,
//! whether the denoiser generalises to objects it never saw (`val`) and how much its category
//! tells it there: NAP's grouped ε-loss (module [`super::diffusion`])
//!
//! ```text
//! L(t) = mean over the split's objects of L_node + L_edge at x_t = √ᾱ_t x₀ + √(1 − ᾱ_t) ε
//! gain(t) = L_∅(t) / L_c(t)     (L_∅: the "no category" row; > 1 where the category helps)
//! ```
//!
//! at fixed noise levels t, once with each object's category (L_c) and once with the "no
//! category" row (L_∅). Every object gets one node permutation and one ε per level, drawn from
//! the seed and the object's position, so two models measured with the same seed see the same
//! noised inputs and their losses compare pair by pair. The feature scales are the weights'
//! own (the training split's), never refitted on the held-out split.

use burn::tensor::{Int, Tensor, TensorData};

use super::TrainError;
use super::diffusion::{DiffusionData, graph_noise, grouped_loss_per_sample, random_slots};
use crate::data::rng::Rng;
use crate::engine::schedule::Schedule;
use crate::graph::FeatureScales;
use crate::model::denoiser::Denoiser;

/// Objects per denoiser forward.
const CHUNK: usize = 64;

/// The held-out loss at each noise level.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldOutLoss {
    /// Objects measured.
    pub objects: usize,
    /// The noise levels t.
    pub levels: Vec<usize>,
    /// Mean grouped loss with each object's category, per level.
    pub conditional: Vec<f64>,
    /// Mean grouped loss with the "no category" row, per level (`None` for a denoiser without
    /// categories).
    pub unconditional: Option<Vec<f64>>,
}

impl HeldOutLoss {
    /// Mean over the levels of the conditional loss.
    pub fn mean_conditional(&self) -> f64 {
        self.conditional.iter().sum::<f64>() / self.conditional.len() as f64
    }

    /// Mean over the levels of the "no category" loss (`None` without categories).
    pub fn mean_unconditional(&self) -> Option<f64> {
        let u = self.unconditional.as_ref()?;
        Some(u.iter().sum::<f64>() / u.len() as f64)
    }
}

/// Measure `model` on every graph of `data` at `levels` (each in 0..1000), with `scales` (the
/// weights' feature scales).
pub fn held_out_loss(
    model: &Denoiser,
    data: &DiffusionData,
    scales: &FeatureScales,
    levels: &[usize],
    seed: u64,
) -> Result<HeldOutLoss, TrainError> {
    let schedule = Schedule::default();
    if levels.is_empty() {
        return Err(TrainError::Config(crate::error::Invalid {
            field: "levels".into(),
            limit: "at least one noise level".into(),
            value: "none".into(),
        }));
    }
    if let Some(&t) = levels.iter().find(|&&t| t >= schedule.len()) {
        return Err(TrainError::Config(crate::error::Invalid {
            field: "levels".into(),
            limit: format!("each in 0..{}", schedule.len()),
            value: t.to_string(),
        }));
    }
    let categories = model.config().categories;
    if let Some(&c) = data.categories.iter().find(|&&c| c >= categories)
        && categories > 0
    {
        return Err(TrainError::Config(crate::error::Invalid {
            field: "category_index".into(),
            limit: format!("below the denoiser's {categories} categories"),
            value: c.to_string(),
        }));
    }
    let device = crate::model::cpu();
    let n = data.graphs.len();
    let mut conditional = Vec::with_capacity(levels.len());
    let mut unconditional = Vec::with_capacity(levels.len());
    for &t in levels {
        let (a, b) = schedule.noise_coefficients(t);
        let (mut sum_c, mut sum_u) = (0.0f64, 0.0f64);
        for (chunk, start) in (0..n).step_by(CHUNK).enumerate() {
            let end = (start + CHUNK).min(n);
            let bsz = end - start;
            let mut rng = Rng::fork(seed ^ ((t as u64) << 32), chunk as u64);
            let mut x0 = Vec::with_capacity(bsz);
            for g in &data.graphs[start..end] {
                let perm = random_slots(&mut rng);
                x0.push(g.permuted(&perm).map_err(TrainError::Core)?.scaled(scales));
            }
            let (v0, e0) = crate::engine::to_tensors(&x0, &device);
            let (eps_v, eps_e) = graph_noise(&mut rng, bsz, &device);
            let vt = v0 * (a as f32) + eps_v.clone() * (b as f32);
            let et = e0 * (a as f32) + eps_e.clone() * (b as f32);
            let ts =
                Tensor::<1, Int>::from_data(TensorData::new(vec![t as i64; bsz], [bsz]), &device);
            let loss = |cats: Option<Vec<i64>>| -> f64 {
                let category =
                    cats.map(|c| Tensor::<1, Int>::from_data(TensorData::new(c, [bsz]), &device));
                let (pv, pe) = model.forward(vt.clone(), et.clone(), ts.clone(), category);
                grouped_loss_per_sample(pv, pe, eps_v.clone(), eps_e.clone())
                    .into_data()
                    .try_to_vec::<f32>()
                    .expect("model outputs are f32")
                    .iter()
                    .map(|&v| v as f64)
                    .sum()
            };
            if categories > 0 {
                let own = data.categories[start..end].iter().map(|&c| c as i64);
                sum_c += loss(Some(own.collect()));
                sum_u += loss(Some(vec![categories as i64; bsz]));
            } else {
                sum_c += loss(None);
            }
        }
        conditional.push(sum_c / n as f64);
        unconditional.push(sum_u / n as f64);
    }
    Ok(HeldOutLoss {
        objects: n,
        levels: levels.to_vec(),
        conditional,
        unconditional: (categories > 0).then_some(unconditional),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::weights;
    use crate::train::diffusion::tests::{tiny_config, tiny_data};
    use crate::train::diffusion::train_diffusion;

    #[test]
    fn training_lowers_the_held_out_loss_and_the_measure_repeats() {
        let data = tiny_data();
        let cfg = tiny_config(60);
        let dir = tempfile::tempdir().unwrap();
        let report = train_diffusion(&data, &cfg, dir.path(), false, &mut |_| {}).unwrap();
        let device = crate::model::cpu();
        let untrained = Denoiser::new(&cfg.model, &device).unwrap();
        let mut trained = Denoiser::new(&cfg.model, &device).unwrap();
        weights::load(&mut trained, &report.weights, None).unwrap();
        let levels = [20, 300, 900];
        let before = held_out_loss(&untrained, &data, &data.scales, &levels, 7).unwrap();
        let after = held_out_loss(&trained, &data, &data.scales, &levels, 7).unwrap();
        assert_eq!(after.objects, data.graphs.len());
        assert_eq!(after.levels, levels);
        assert_eq!(
            after.unconditional.as_ref().map(Vec::len),
            Some(levels.len())
        );
        assert!(
            after.mean_conditional() < 0.8 * before.mean_conditional(),
            "trained {} vs untrained {}",
            after.mean_conditional(),
            before.mean_conditional()
        );
        // Paired inputs: the same seed gives the same numbers, another seed other noise.
        let again = held_out_loss(&trained, &data, &data.scales, &levels, 7).unwrap();
        assert_eq!(again, after);
        let other = held_out_loss(&trained, &data, &data.scales, &levels, 8).unwrap();
        assert_ne!(other.conditional, after.conditional);
        // The "no category" row is a different input, so its loss differs.
        assert_ne!(after.unconditional.as_ref().unwrap(), &after.conditional);
    }

    #[test]
    fn bad_levels_and_categories_are_named() {
        let data = tiny_data();
        let cfg = tiny_config(1);
        let model = Denoiser::new(&cfg.model, &crate::model::cpu()).unwrap();
        let err = |levels: &[usize], data: &DiffusionData| {
            held_out_loss(&model, data, &data.scales, levels, 0)
                .unwrap_err()
                .to_string()
        };
        let e = err(&[10, 1000], &data);
        assert!(
            e.contains("levels") && e.contains("1000") && e.contains("0..1000"),
            "{e}"
        );
        let e = err(&[], &data);
        assert!(e.contains("levels") && e.contains("at least one"), "{e}");
        let mut wrong = tiny_data();
        wrong.categories[1] = 5;
        let e = err(&[10], &wrong);
        assert!(
            e.contains("category_index") && e.contains('5') && e.contains('3'),
            "{e}"
        );
    }
}
