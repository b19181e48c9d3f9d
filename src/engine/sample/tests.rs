//! Tests of `sample`.

use super::*;
use crate::model::denoiser::DenoiserConfig;

fn tiny() -> Denoiser {
    let cfg = DenoiserConfig {
        width: 16,
        layers: 1,
        head_channels: 8,
        node_head_hidden: vec![16],
        edge_head_hidden: vec![16],
        categories: 3,
        ..DenoiserConfig::default()
    };
    Denoiser::new(&cfg, &crate::model::cpu()).unwrap()
}

#[test]
fn sampling_is_deterministic_per_seed_and_reports_every_step() {
    let model = tiny();
    let schedule = Schedule::default();
    let dev = crate::model::cpu();
    let req = SampleRequest {
        seed: 7,
        batch: 2,
        category: Some(1),
        preview_every: 0,
        ..Default::default()
    };
    let mut steps = Vec::new();
    let a = sample(&model, &schedule, &req, &dev, &mut |s| {
        steps.push(s.t);
        ControlFlow::Continue(())
    })
    .unwrap();
    assert_eq!(steps.len(), 1000);
    assert_eq!((steps[0], steps[999]), (999, 0));
    let b = sample(&model, &schedule, &req, &dev, &mut |_| {
        ControlFlow::Continue(())
    })
    .unwrap();
    assert_eq!(a, b);
    assert!(a.iter().all(|g| g.flatten().iter().all(|v| v.is_finite())));
    let c = sample(
        &model,
        &schedule,
        &SampleRequest {
            seed: 8,
            ..req.clone()
        },
        &dev,
        &mut |_| ControlFlow::Continue(()),
    )
    .unwrap();
    assert_ne!(a, c);
}

#[test]
fn category_guidance_extrapolates_from_the_no_category_prediction() {
    // One deterministic DDIM jump from t = 999 lands on x̂₀, which is linear in ε̂, so the
    // guided result must be out(c) + w·(out(c) − out(∅)) for the same noise.
    let model = tiny();
    let dev = crate::model::cpu();
    let run = |category: Option<usize>, w: f64| {
        let req = SampleRequest {
            seed: 4,
            batch: 2,
            category,
            sampler: Sampler::Ddim { eta: 0.0 },
            steps: 1,
            category_guidance: w,
            ..Default::default()
        };
        sample(&model, &Schedule::default(), &req, &dev, &mut |_| {
            ControlFlow::Continue(())
        })
        .map(|gs| gs.iter().flat_map(|g| g.flatten()).collect::<Vec<f32>>())
    };
    let cond = run(Some(2), 0.0).unwrap();
    let none = run(None, 0.0).unwrap();
    let guided = run(Some(2), 3.0).unwrap();
    assert_ne!(cond, none, "the category must change the prediction");
    for ((c, u), g) in cond.iter().zip(&none).zip(&guided) {
        let want = c + 3.0 * (c - u);
        assert!(
            (g - want).abs() <= 1e-3 * (1.0 + want.abs()),
            "{g} vs {want}"
        );
    }
    // Without a category the weight has nothing to extrapolate from: plain sampling.
    assert_eq!(run(None, 3.0).unwrap(), none);
    // Out-of-range weights are refused, naming the field, the limit and the value.
    let e = run(Some(2), -1.0).unwrap_err().to_string();
    assert!(
        e.contains("category_guidance") && e.contains("[0, 20]") && e.contains("-1"),
        "{e}"
    );
}

#[test]
fn category_guidance_applies_only_below_its_time_limit() {
    // The single DDIM jump runs at t = 999: a limit at or below it leaves the plain
    // conditional prediction, a limit above it (1000, the whole schedule) guides.
    let model = tiny();
    let dev = crate::model::cpu();
    let run = |w: f64, below: Option<usize>| {
        let req = SampleRequest {
            seed: 4,
            batch: 1,
            category: Some(1),
            sampler: Sampler::Ddim { eta: 0.0 },
            steps: 1,
            category_guidance: w,
            category_guidance_below: below,
            ..Default::default()
        };
        sample(&model, &Schedule::default(), &req, &dev, &mut |_| {
            ControlFlow::Continue(())
        })
        .map(|gs| gs.iter().flat_map(|g| g.flatten()).collect::<Vec<f32>>())
    };
    let plain = run(0.0, None).unwrap();
    let guided = run(2.0, None).unwrap();
    assert_ne!(plain, guided);
    assert_eq!(run(2.0, Some(999)).unwrap(), plain);
    assert_eq!(run(2.0, Some(500)).unwrap(), plain);
    assert_eq!(run(2.0, Some(1000)).unwrap(), guided);
    for bad in [0, 1001] {
        let e = run(2.0, Some(bad)).unwrap_err().to_string();
        assert!(
            e.contains("category_guidance_below")
                && e.contains("[1, 1000]")
                && e.contains(&bad.to_string()),
            "{e}"
        );
    }
}

#[test]
fn previews_come_every_k_steps_and_the_last_one_is_the_result() {
    let model = tiny();
    let req = SampleRequest {
        seed: 3,
        batch: 1,
        category: None,
        preview_every: 250,
        ..Default::default()
    };
    let mut previews = Vec::new();
    let out = sample(
        &model,
        &Schedule::default(),
        &req,
        &crate::model::cpu(),
        &mut |s| {
            if let Some(p) = &s.x0_preview {
                previews.push((s.step, p.clone()));
            }
            ControlFlow::Continue(())
        },
    )
    .unwrap();
    let steps: Vec<usize> = previews.iter().map(|(s, _)| *s).collect();
    assert_eq!(steps, vec![250, 500, 750, 1000]);
    // At t = 0 the DDPM mean is exactly x̂₀ (σ = 0, ᾱ₀ = α₀).
    let last = previews.last().unwrap().1[0].flatten();
    for (a, b) in last.iter().zip(out[0].flatten()) {
        assert!((a - b).abs() < 1e-3 * (1.0 + b.abs()), "{a} vs {b}");
    }
}

#[test]
fn the_callback_can_stop_a_run() {
    let model = tiny();
    let req = SampleRequest {
        seed: 1,
        batch: 1,
        category: None,
        preview_every: 0,
        ..Default::default()
    };
    let e = sample(
        &model,
        &Schedule::default(),
        &req,
        &crate::model::cpu(),
        &mut |s| {
            if s.step == 5 {
                ControlFlow::Break("cancelled".into())
            } else {
                ControlFlow::Continue(())
            }
        },
    )
    .unwrap_err();
    assert!(matches!(e, EngineError::Stopped { step: 5, .. }), "{e}");
    assert!(e.to_string().contains("cancelled"));
}

fn tiny_field() -> crate::model::shape_prior::ShapeDecoder {
    let cfg = crate::model::shape_prior::ShapePriorConfig {
        latent: 8,
        decoder_hidden: 16,
        decoder_blocks: 1,
        encoder_hidden: 8,
        encoder_blocks: 1,
        pe_freqs: 2,
        code_every_block: false,
    };
    crate::model::shape_prior::ShapeDecoder::new(&cfg, &mut Rng::new(4), &crate::model::cpu())
}

fn cloud() -> Vec<[f32; 3]> {
    let mut rng = Rng::new(2);
    (0..32)
        .map(|_| {
            [
                rng.range(-0.4, 0.4) as f32,
                rng.range(-0.3, 0.3) as f32,
                rng.range(0.0, 0.8) as f32,
            ]
        })
        .collect()
}

/// ℓ_pc of final (model-space = raw, unit scales) graphs.
fn pc_of(field: &dyn SdfField, g: &GraphTensor, points: &[[f32; 3]]) -> f64 {
    let dev = crate::model::cpu();
    let (v, e) = super::super::to_tensors(std::slice::from_ref(g), &dev);
    let d = super::super::guidance::decode(
        v.reshape([K, NODE_DIM]),
        e.reshape([NUM_EDGES, EDGE_DIM]),
        field.latent(),
    );
    super::super::guidance::pc::loss(field, &d.parts, d.exist, points, 1000.0).into_scalar::<f32>()
        as f64
}

/// Scales, schedule and guidance under which a random tiny model's guidance descends.
fn guided_setup() -> (FeatureScales, Schedule, GuidanceOptions) {
    // Realistic raw sizes (boxes and centres ~0.2 m per unit of model space).
    let mut scales = FeatureScales::default();
    for c in 1..7 {
        scales.node[c] = 0.2;
    }
    // A random model is no denoiser: over NAP's 1000 steps its samples run off to |x| ~ 1e3.
    // A short schedule (ᾱ ≥ 0.6) keeps x̂₀ in a physical range, so guidance acts as on a
    // trained model.
    let schedule = Schedule::linear(40, 1e-3, 0.02);
    // Small weights: the raw DPS gradient of the paper's weights overshoots on a random
    // model (its x̂₀ is far from any object); here guidance must act as a descent.
    let guidance = GuidanceOptions {
        steps: 20,
        w_pc: 0.2,
        w_pen: 0.01,
        w_mob: 0.01,
        ..GuidanceOptions::paper(cloud(), super::super::guidance::Terms::ALL)
    };
    (scales, schedule, guidance)
}

#[test]
fn guided_sampling_lowers_the_loss_reports_it_and_is_deterministic() {
    let model = tiny();
    let field = tiny_field();
    let (scales, schedule, guidance) = guided_setup();
    let ctx = GuidanceContext {
        field: &field,
        scales: &scales,
    };
    let points = guidance.points.clone();
    let req = SampleRequest {
        seed: 5,
        batch: 1,
        category: Some(0),
        guidance: Some(guidance),
        ..Default::default()
    };
    let dev = crate::model::cpu();
    let mut guided_ts = Vec::new();
    let mut first_last = Vec::new();
    let a = sample_guided(&model, &schedule, &req, Some(ctx), &dev, &mut |s| {
        if let Some(l) = s.guidance {
            guided_ts.push(s.t);
            assert!(l.total.is_finite() && l.grad_max.is_finite(), "{l:?}");
            first_last.push(l.pc);
        }
        ControlFlow::Continue(())
    })
    .unwrap();
    assert_eq!(guided_ts, (0..20).rev().collect::<Vec<_>>());
    let b = sample_guided(&model, &schedule, &req, Some(ctx), &dev, &mut |_| {
        ControlFlow::Continue(())
    })
    .unwrap();
    assert_eq!(a, b, "guided sampling must be deterministic per seed");
    let plain = sample(
        &model,
        &schedule,
        &SampleRequest {
            guidance: None,
            ..req.clone()
        },
        &dev,
        &mut |_| ControlFlow::Continue(()),
    )
    .unwrap();
    let (lg, lu) = (
        pc_of(&field, &a[0], &points),
        pc_of(&field, &plain[0], &points),
    );
    assert!(
        lg < lu,
        "guidance must lower ℓ_pc: guided {lg} vs unguided {lu}"
    );
    // Without a field the request is refused, naming the field.
    let e = sample(&model, &schedule, &req, &dev, &mut |_| {
        ControlFlow::Continue(())
    })
    .unwrap_err();
    assert!(e.to_string().contains("guidance"), "{e}");
}

#[test]
fn refinement_descends_the_guidance_loss_after_the_last_step() {
    let model = tiny();
    let field = tiny_field();
    let (scales, schedule, base) = guided_setup();
    let ctx = GuidanceContext {
        field: &field,
        scales: &scales,
    };
    let run = |refine_steps: usize, events: &mut Vec<(usize, usize, usize, f64)>| {
        let req = SampleRequest {
            seed: 5,
            batch: 1,
            category: Some(0),
            guidance: Some(GuidanceOptions {
                refine_steps,
                ..base.clone()
            }),
            ..Default::default()
        };
        let dev = crate::model::cpu();
        sample_guided(&model, &schedule, &req, Some(ctx), &dev, &mut |s| {
            let total = s.guidance.map_or(f64::NAN, |l| l.total);
            events.push((s.step, s.total, s.t, total));
            ControlFlow::Continue(())
        })
        .unwrap()
    };
    let (mut plain_ev, mut refined_ev) = (Vec::new(), Vec::new());
    let plain = run(0, &mut plain_ev);
    let refined = run(10, &mut refined_ev);
    // The reverse steps are the same; ten more events follow, at t = 0, each guided.
    assert_eq!(refined_ev.len(), 50);
    assert!(refined_ev.iter().all(|e| e.1 == 50), "{refined_ev:?}");
    assert_eq!(
        refined_ev[..40]
            .iter()
            .map(|e| e.3.to_bits())
            .collect::<Vec<_>>(),
        plain_ev.iter().map(|e| e.3.to_bits()).collect::<Vec<_>>()
    );
    let tail = &refined_ev[40..];
    assert!(tail.iter().all(|e| e.2 == 0 && e.3.is_finite()), "{tail:?}");
    assert_eq!(
        tail.iter().map(|e| e.0).collect::<Vec<_>>(),
        (41..=50).collect::<Vec<_>>()
    );
    // Its first loss is the unrefined sample's; nine small steps later the loss is lower.
    let (first, last) = (tail[0].3, tail[9].3);
    assert!(last < first, "refinement must descend: {first} -> {last}");
    assert_ne!(plain, refined);
    assert_eq!(refined, run(10, &mut Vec::new()), "deterministic per seed");
}

#[test]
fn physics_refinement_follows_with_pc_off_and_descends_pen_plus_mob() {
    let model = tiny();
    let field = tiny_field();
    let (scales, schedule, base) = guided_setup();
    let ctx = GuidanceContext {
        field: &field,
        scales: &scales,
    };
    // (step, total, ℓ_pc, w_pen ℓ_pen + w_mob ℓ_mob) of every event.
    let run = |g: GuidanceOptions, events: &mut Vec<(usize, usize, f64, f64)>| {
        let req = SampleRequest {
            seed: 5,
            batch: 1,
            category: Some(0),
            guidance: Some(g.clone()),
            ..Default::default()
        };
        let dev = crate::model::cpu();
        sample_guided(&model, &schedule, &req, Some(ctx), &dev, &mut |s| {
            let (pc, phys) = s.guidance.map_or((f64::NAN, f64::NAN), |l| {
                (l.pc, g.w_pen * l.pen + g.w_mob * l.mob)
            });
            events.push((s.step, s.total, pc, phys));
            ControlFlow::Continue(())
        })
        .unwrap()
    };
    let g = GuidanceOptions {
        refine_steps: 2,
        refine_physics_steps: 8,
        ..base.clone()
    };
    let mut ev = Vec::new();
    let out = run(g.clone(), &mut ev);
    // 40 reverse steps, 2 refinement steps with ℓ_pc, then 8 without it.
    assert_eq!(step_events(40, 0, Some(&g)), 50);
    assert_eq!(ev.len(), 50);
    assert!(ev.iter().all(|e| e.1 == 50), "{ev:?}");
    assert!(ev[40..42].iter().all(|e| e.2 > 0.0), "{ev:?}");
    // Everything before them is the run without them.
    let mut before = Vec::new();
    let unmoved = run(
        GuidanceOptions {
            refine_physics_steps: 0,
            ..g.clone()
        },
        &mut before,
    );
    // They moved part boxes (half-extents, centres) and nothing else.
    use crate::graph::node_ch;
    let (a, b) = (&out[0], &unmoved[0]);
    assert_eq!(a.edges, b.edges, "joints must stay");
    let (mut moved, mut kept) = (0, 0);
    for (c, (x, y)) in a.nodes.iter().zip(&b.nodes).enumerate() {
        if (node_ch::BOX..node_ch::LATENT).contains(&(c % NODE_DIM)) {
            moved += usize::from(x != y);
        } else {
            assert_eq!(x.to_bits(), y.to_bits(), "node channel {}", c % NODE_DIM);
            kept += 1;
        }
    }
    assert!(moved > 0 && kept > 0);
    let bits = |e: &[(usize, usize, f64, f64)]| {
        e.iter()
            .map(|e| (e.0, e.2.to_bits(), e.3.to_bits()))
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&ev[..42]), bits(&before));
    let tail = &ev[42..];
    assert!(
        tail.iter().all(|e| e.2 == 0.0 && e.3.is_finite()),
        "{tail:?}"
    );
    let (first, last) = (tail[0].3, tail[7].3);
    assert!(
        first > 0.0,
        "the sample must overlap for this test to mean anything: {ev:?}"
    );
    assert!(
        last < first,
        "physics steps must descend: {first} -> {last}"
    );
    // Without ℓ_pen and ℓ_mob there is nothing to descend: no physics steps run.
    let pc_only = GuidanceOptions {
        w_pen: 0.0,
        w_mob: 0.0,
        ..g.clone()
    };
    assert_eq!(step_events(40, 0, Some(&pc_only)), 42);
    let mut pc_ev = Vec::new();
    run(pc_only, &mut pc_ev);
    assert_eq!(pc_ev.len(), 42);
    assert_eq!(
        out,
        run(g.clone(), &mut Vec::new()),
        "deterministic per seed"
    );
    // It returns the lowest-loss state the physics steps evaluated: event i's loss is that
    // of the state before its step, which event i − 1 previews.
    let req = SampleRequest {
        seed: 5,
        batch: 1,
        category: Some(0),
        guidance: Some(g.clone()),
        preview_every: 1,
        ..Default::default()
    };
    let mut seen: Vec<(f64, Vec<GraphTensor>)> = Vec::new();
    let dev = crate::model::cpu();
    let previewed = sample_guided(&model, &schedule, &req, Some(ctx), &dev, &mut |s| {
        let total = s.guidance.map_or(f64::NAN, |l| l.total);
        seen.push((total, s.x0_preview.clone().expect("a preview every step")));
        ControlFlow::Continue(())
    })
    .unwrap();
    assert_eq!(previewed, out);
    let mut best = 42;
    for i in 43..50 {
        if seen[i].0 < seen[best].0 {
            best = i;
        }
    }
    assert_eq!(
        out,
        seen[best - 1].1,
        "best at event {best}: {:?}",
        &seen[42..]
    );
}

#[test]
fn a_diverging_guidance_is_reported_not_returned() {
    let model = tiny();
    let field = tiny_field();
    let scales = FeatureScales::default();
    let req = SampleRequest {
        seed: 1,
        batch: 1,
        guidance: Some(GuidanceOptions {
            w_pc: 1e6,
            steps: 10,
            max_step: None, // the paper's raw step: the runaway check applies
            ..GuidanceOptions::paper(cloud(), super::super::guidance::Terms::ALL)
        }),
        steps: 20,
        ..Default::default()
    };
    let e = sample_guided(
        &model,
        &Schedule::default(),
        &req,
        Some(GuidanceContext {
            field: &field,
            scales: &scales,
        }),
        &crate::model::cpu(),
        &mut |_| ControlFlow::Continue(()),
    )
    .unwrap_err();
    assert!(matches!(e, EngineError::Diverged { .. }), "{e}");
}

#[test]
fn strided_and_ddim_sampling_take_the_requested_steps() {
    let model = tiny();
    let dev = crate::model::cpu();
    for sampler in [Sampler::Ddpm, Sampler::Ddim { eta: 0.0 }] {
        let req = SampleRequest {
            seed: 9,
            batch: 1,
            sampler,
            steps: 25,
            preview_every: 25,
            ..Default::default()
        };
        let mut ts = Vec::new();
        let mut last = None;
        let out = sample(&model, &Schedule::default(), &req, &dev, &mut |s| {
            ts.push(s.t);
            if let Some(p) = &s.x0_preview {
                last = Some(p[0].clone());
            }
            ControlFlow::Continue(())
        })
        .unwrap();
        assert_eq!(ts.len(), 25);
        assert_eq!((ts[0], ts[24]), (999, 0));
        assert!(out[0].flatten().iter().all(|v| v.is_finite()));
        // The last jump lands on x̂₀.
        let last = last.unwrap().flatten();
        for (a, b) in last.iter().zip(out[0].flatten()) {
            assert!((a - b).abs() < 1e-3 * (1.0 + b.abs()), "{a} vs {b}");
        }
    }
    let e = sample(
        &model,
        &Schedule::default(),
        &SampleRequest {
            batch: 1,
            sampler: Sampler::Ddim { eta: 2.0 },
            ..Default::default()
        },
        &dev,
        &mut |_| ControlFlow::Continue(()),
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("sampler.eta") && e.to_string().contains('2'),
        "{e}"
    );
}
