//! The DDPM noise schedule and the reverse-step update (method.md §2).
//!
//! Why it exists: training (forward noising), plain sampling, guided sampling and fast
//! (strided) sampling all share one schedule; keeping it apart from the denoiser and the loop
//! makes each testable with tiny tensors (the `Scheduler` split of candle/diffusers).
//!
//! ```text
//! β_t = linspace(0.001, 0.02, T)[t],  α_t = 1 − β_t,  ᾱ_t = Π_{k≤t} α_k          (T = 1000)
//! forward:  x_t = √ᾱ_t x₀ + √(1 − ᾱ_t) ε
//! x̂₀(x_t, ε̂) = (x_t − √(1 − ᾱ_t) ε̂) / √ᾱ_t
//! reverse:  x_{t−1} = (x_t − β_t/√(1 − ᾱ_t) ε̂) / √α_t + σ_t z,  σ_t² = β_t,  no noise at t = 0
//! ```
//!
//! Indices are 0-based: t = T − 1 is the first reverse step, t = 0 the last.
//!
//! Fast sampling (fewer steps, the paper's future work) jumps from t to an earlier t' with the
//! DDIM update (Song et al. 2021); η = 1 is the strided ancestral DDPM sampler, η = 0 DDIM:
//!
//! ```text
//! σ = η · √((1 − ᾱ_t')/(1 − ᾱ_t)) · √(1 − ᾱ_t/ᾱ_t')
//! x_t' = √ᾱ_t' x̂₀ + √(1 − ᾱ_t' − σ²) ε̂ + σ z           (after t = 0: x̂₀ itself)
//! ```
//!
//! [`timesteps`] spreads S steps evenly over 999 … 0 (always including both ends).

/// Number of diffusion steps NAP trains with.
pub const NUM_STEPS: usize = 1000;

/// The linear-β DDPM schedule.
#[derive(Debug, Clone, PartialEq)]
pub struct Schedule {
    /// β_t.
    pub beta: Vec<f64>,
    /// α_t = 1 − β_t.
    pub alpha: Vec<f64>,
    /// ᾱ_t = Π_{k≤t} α_k.
    pub alpha_bar: Vec<f64>,
}

impl Default for Schedule {
    fn default() -> Self {
        Schedule::linear(NUM_STEPS, 0.001, 0.02)
    }
}

/// Per-step coefficients of the reverse update `x_{t−1} = c_x x_t − c_eps ε̂ + σ z`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepCoefficients {
    /// Multiplies x_t.
    pub c_x: f64,
    /// Multiplies ε̂ (subtracted).
    pub c_eps: f64,
    /// Standard deviation of the added noise (0 at the last step).
    pub sigma: f64,
}

impl Schedule {
    /// β linear from `beta_start` to `beta_end` over `steps` steps.
    pub fn linear(steps: usize, beta_start: f64, beta_end: f64) -> Self {
        let beta: Vec<f64> = (0..steps)
            .map(|t| {
                if steps == 1 {
                    beta_start
                } else {
                    beta_start + (beta_end - beta_start) * t as f64 / (steps - 1) as f64
                }
            })
            .collect();
        let alpha: Vec<f64> = beta.iter().map(|b| 1.0 - b).collect();
        let mut alpha_bar = Vec::with_capacity(steps);
        let mut acc = 1.0;
        for a in &alpha {
            acc *= a;
            alpha_bar.push(acc);
        }
        Schedule {
            beta,
            alpha,
            alpha_bar,
        }
    }

    /// Number of steps T.
    pub fn len(&self) -> usize {
        self.beta.len()
    }

    /// Whether the schedule has no steps.
    pub fn is_empty(&self) -> bool {
        self.beta.is_empty()
    }

    /// (√ᾱ_t, √(1 − ᾱ_t)): the forward-noising coefficients.
    pub fn noise_coefficients(&self, t: usize) -> (f64, f64) {
        let ab = self.alpha_bar[t];
        (ab.sqrt(), (1.0 - ab).sqrt())
    }

    /// Coefficients of the plain DDPM reverse step from t to t − 1.
    pub fn step_coefficients(&self, t: usize) -> StepCoefficients {
        let (a, ab, b) = (self.alpha[t], self.alpha_bar[t], self.beta[t]);
        StepCoefficients {
            c_x: 1.0 / a.sqrt(),
            c_eps: b / ((1.0 - ab).sqrt() * a.sqrt()),
            sigma: if t == 0 { 0.0 } else { b.sqrt() },
        }
    }

    /// Coefficients of a jump from t to `t_prev` (< t), or to the end (None: x̂₀), with DDIM
    /// noise level `eta` (1: strided DDPM, 0: deterministic DDIM).
    pub fn jump_coefficients(&self, t: usize, t_prev: Option<usize>, eta: f64) -> StepCoefficients {
        let (s, n) = self.noise_coefficients(t);
        let Some(tp) = t_prev else {
            return StepCoefficients {
                c_x: 1.0 / s,
                c_eps: n / s,
                sigma: 0.0,
            };
        };
        let (ab, abp) = (self.alpha_bar[t], self.alpha_bar[tp]);
        let sigma = eta * ((1.0 - abp) / (1.0 - ab)).sqrt() * (1.0 - ab / abp).max(0.0).sqrt();
        let dir = (1.0 - abp - sigma * sigma).max(0.0).sqrt();
        // x' = √ᾱ' (x − n ε)/s + dir ε + σ z
        StepCoefficients {
            c_x: abp.sqrt() / s,
            c_eps: abp.sqrt() * n / s - dir,
            sigma,
        }
    }

    /// x̂₀ from x_t and ε̂ on plain slices (the tensor version lives with the sampler).
    pub fn predict_x0(&self, t: usize, x_t: &[f32], eps: &[f32]) -> Vec<f32> {
        let (s, n) = self.noise_coefficients(t);
        x_t.iter()
            .zip(eps)
            .map(|(x, e)| ((*x as f64 - n * *e as f64) / s) as f32)
            .collect()
    }
}

/// `steps` diffusion times spread evenly over `total − 1 … 0`, descending, both ends included
/// (0 or ≥ total: every step).
pub fn timesteps(total: usize, steps: usize) -> Vec<usize> {
    if steps == 0 || steps >= total || total < 2 {
        return (0..total).rev().collect();
    }
    if steps == 1 {
        return vec![total - 1];
    }
    let mut out: Vec<usize> = (0..steps)
        .map(|k| ((k as f64 * (total - 1) as f64) / (steps - 1) as f64).round() as usize)
        .collect();
    out.dedup();
    out.reverse();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alpha_bar_matches_nap_reference_values() {
        // method.md §2 "useful values".
        let s = Schedule::default();
        assert_eq!(s.len(), 1000);
        let close = |t: usize, v: f64, rel: f64| {
            assert!(
                (s.alpha_bar[t] - v).abs() / v < rel,
                "ᾱ_{t} = {} vs {v}",
                s.alpha_bar[t]
            );
        };
        close(0, 0.999, 1e-12);
        close(99, 0.8234, 1e-3);
        close(249, 0.4301, 1e-3);
        close(499, 0.05598, 1e-3);
        close(999, 2.565e-5, 1e-2);
    }

    #[test]
    fn reverse_step_inverts_forward_noising_given_true_noise() {
        // With ε̂ = ε and no added noise, the reverse step's mean equals the posterior mean;
        // x̂₀ recovers x₀ exactly.
        let s = Schedule::default();
        let x0 = [0.3f32, -1.2, 0.7];
        let eps = [0.5f32, 0.1, -2.0];
        for t in [0usize, 10, 500, 999] {
            let (a, b) = s.noise_coefficients(t);
            let xt: Vec<f32> = x0
                .iter()
                .zip(&eps)
                .map(|(x, e)| (a * *x as f64 + b * *e as f64) as f32)
                .collect();
            let back = s.predict_x0(t, &xt, &eps);
            for (u, v) in back.iter().zip(&x0) {
                assert!((u - v).abs() < 1e-3 * (1.0 / a as f32), "t={t}: {u} vs {v}");
            }
        }
        assert_eq!(s.step_coefficients(0).sigma, 0.0);
        assert!(s.step_coefficients(1).sigma > 0.0);
    }

    #[test]
    fn jumps_generalise_the_ddpm_step() {
        let s = Schedule::default();
        // A jump from x_t with the true ε lands on √ᾱ' x₀ + √(1−ᾱ') ε for DDIM (η = 0).
        let (x0, eps) = (0.7f64, -1.3f64);
        for (t, tp) in [(999usize, 899usize), (500, 250), (10, 0)] {
            let (a, b) = s.noise_coefficients(t);
            let xt = a * x0 + b * eps;
            let c = s.jump_coefficients(t, Some(tp), 0.0);
            assert_eq!(c.sigma, 0.0);
            let (ap, bp) = s.noise_coefficients(tp);
            let got = c.c_x * xt - c.c_eps * eps;
            assert!((got - (ap * x0 + bp * eps)).abs() < 1e-9, "{t}→{tp}: {got}");
        }
        // The end: x̂₀.
        let c = s.jump_coefficients(0, None, 1.0);
        let (a, b) = s.noise_coefficients(0);
        assert!((c.c_x * (a * x0 + b * eps) - c.c_eps * eps - x0).abs() < 1e-9);
        // η = 1 over one step: σ² is the posterior variance β̃_t = β_t (1−ᾱ_{t−1})/(1−ᾱ_t).
        let c = s.jump_coefficients(500, Some(499), 1.0);
        let post = s.beta[500] * (1.0 - s.alpha_bar[499]) / (1.0 - s.alpha_bar[500]);
        assert!((c.sigma * c.sigma - post).abs() < 1e-12);
    }

    #[test]
    fn timesteps_spread_evenly_and_include_both_ends() {
        assert_eq!(timesteps(1000, 0).len(), 1000);
        assert_eq!(timesteps(1000, 1000), (0..1000).rev().collect::<Vec<_>>());
        let t = timesteps(1000, 4);
        assert_eq!(t, vec![999, 666, 333, 0]);
        let t = timesteps(1000, 100);
        assert_eq!((t.len(), t[0], t[99]), (100, 999, 0));
        assert!(t.windows(2).all(|w| w[0] > w[1]));
    }
}
