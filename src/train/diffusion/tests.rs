//! Tests of `diffusion`.

use super::*;

pub(crate) fn tiny_data() -> DiffusionData {
    let mut rng = Rng::new(3);
    let mut graphs = Vec::new();
    let mut categories = Vec::new();
    for (k, obj) in [
        crate::fixtures::cabinet(),
        crate::fixtures::eight_part().merge_fixed().unwrap().0,
    ]
    .iter()
    .enumerate()
    {
        let slots: Vec<usize> = (0..obj.parts.len()).collect();
        let mut g = crate::graph::encode(obj, &slots).unwrap();
        for s in 0..obj.parts.len() {
            for v in &mut g.node_mut(s)[node_ch::LATENT..] {
                *v = rng.gauss() as f32 * 0.1;
            }
        }
        graphs.push(g);
        categories.push(k);
    }
    let scales = FeatureScales::fit(
        &graphs,
        graphs
            .iter()
            .flat_map(|g| (0..K).map(move |i| &g.node(i)[node_ch::LATENT..])),
    );
    DiffusionData {
        graphs,
        categories,
        scales,
    }
}

pub(crate) fn tiny_config(steps: usize) -> DiffusionTrainConfig {
    DiffusionTrainConfig {
        model: DenoiserConfig {
            width: 32,
            layers: 1,
            head_channels: 8,
            node_head_hidden: vec![32],
            edge_head_hidden: vec![32],
            categories: 3,
            ..DenoiserConfig::default()
        },
        steps,
        batch_objects: 4,
        noise_levels: 2,
        lr: 2e-3,
        seed: 1,
        category_dropout: 0.2,
        checkpoint_every: 20,
        lr_decay_start: 40,
        lr_final_factor: 0.1,
        ema_decay: 0.9,
        stop_at: None,
        min_snr_gamma: 0.0,
        high_noise_cap: 1.0,
        overlap_weight: 0.0,
        overlap_max_t: DEFAULT_OVERLAP_MAX_T,
        layout_gain: 1.0,
        code_gain: 1.0,
        batch_shards: 2,
        compute: crate::model::Compute::Cpu,
    }
}

#[test]
fn checkpoint_every_zero_checkpoints_only_at_the_end() {
    // Was a division by zero (a panic) before 0 meant "only at the end".
    let data = tiny_data();
    let dir = tempfile::tempdir().unwrap();
    let cfg = DiffusionTrainConfig {
        checkpoint_every: 0,
        ..tiny_config(3)
    };
    let r = train_diffusion(&data, &cfg, dir.path(), false, &mut |_| {}).unwrap();
    assert_eq!(r.steps, 3);
    let ck: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("checkpoint.json")).unwrap())
            .unwrap();
    assert_eq!(ck["step"], 3);
}

#[test]
fn tiny_training_lowers_the_loss_and_resumes_exactly() {
    let data = tiny_data();
    let dir = tempfile::tempdir().unwrap();
    let mut losses = Vec::new();
    let report = train_diffusion(&data, &tiny_config(60), dir.path(), false, &mut |p| {
        losses.push(p.loss)
    })
    .unwrap();
    let first: f64 = losses[..10].iter().sum::<f64>() / 10.0;
    let last: f64 = losses[50..].iter().sum::<f64>() / 10.0;
    assert!(last < 0.8 * first, "loss did not fall: {first} -> {last}");
    assert!(report.weights.is_file() && dir.path().join("checkpoint.json").is_file());
    // The shipped file is the EMA, the raw weights sit beside it and differ.
    let raw = std::fs::read(dir.path().join("denoiser_raw.safetensors")).unwrap();
    assert_ne!(raw, std::fs::read(&report.weights).unwrap());
    // Resume: a run to 80 steps continues from step 60; --stop-at 70 ends it there with a
    // checkpoint (off the checkpoint_every grid), and the next resume finishes it.
    let mut steps = Vec::new();
    let stopped = DiffusionTrainConfig {
        stop_at: Some(70),
        ..tiny_config(80)
    };
    let r = train_diffusion(&data, &stopped, dir.path(), true, &mut |p| {
        steps.push(p.step)
    })
    .unwrap();
    assert_eq!((steps.first(), steps.last()), (Some(&61), Some(&70)));
    assert_eq!(r.steps, 70);
    let ck: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("checkpoint.json")).unwrap())
            .unwrap();
    assert_eq!(ck["step"], 70);
    steps.clear();
    train_diffusion(&data, &tiny_config(80), dir.path(), true, &mut |p| {
        steps.push(p.step)
    })
    .unwrap();
    assert_eq!(steps.first(), Some(&71));
    assert_eq!(steps.last(), Some(&80));
    // The report and the checkpoint count the wall time of both runs.
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("diffusion_train.json")).unwrap(),
    )
    .unwrap();
    let (this, total) = (
        summary["wall_seconds"].as_f64().unwrap(),
        summary["wall_seconds_total"].as_f64().unwrap(),
    );
    assert!(total >= this + 0.5 * report.wall_seconds, "{this} {total}");
}

#[test]
fn layout_and_code_gains_scale_their_own_channels_and_a_resume_must_keep_both() {
    let data = tiny_data();
    let dir = tempfile::tempdir().unwrap();
    let gains = |layout_gain, code_gain, steps| DiffusionTrainConfig {
        layout_gain,
        code_gain,
        ..tiny_config(steps)
    };
    let r = train_diffusion(&data, &gains(2.0, 4.0, 4), dir.path(), false, &mut |_| {}).unwrap();
    // Box and centre scales halved, code scales quartered, existence and edges as the data's.
    let codes = node_ch::LATENT..node_ch::LATENT + crate::object::LATENT_DIM;
    for c in 0..NODE_DIM {
        let want = if (node_ch::BOX..node_ch::LATENT).contains(&c) {
            data.scales.node[c] / 2.0
        } else if codes.contains(&c) {
            data.scales.node[c] / 4.0
        } else {
            data.scales.node[c]
        };
        assert_eq!(r.scales.node[c], want, "node channel {c}");
    }
    assert_eq!(r.scales.edge, data.scales.edge);
    // The run's record carries them (the manifest takes `r.scales`) and both gains.
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("diffusion_train.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(
        (&summary["layout_gain"], &summary["code_gain"]),
        (&2.0.into(), &4.0.into())
    );
    for ch in [node_ch::CENTER, node_ch::LATENT] {
        assert_eq!(
            summary["feature_scales"]["node"][ch].as_f64().unwrap() as f32,
            r.scales.node[ch]
        );
    }
    // Resuming with another scaling would train the same weights in another model space:
    // the error names the first channel that differs and the recorded gains.
    let resume_err = |cfg: DiffusionTrainConfig| {
        train_diffusion(&data, &cfg, dir.path(), true, &mut |_| {})
            .err()
            .unwrap()
            .to_string()
    };
    for (cfg, channel) in [
        (tiny_config(8), node_ch::BOX),
        (gains(2.0, 1.0, 8), node_ch::LATENT),
    ] {
        let e = resume_err(cfg);
        assert!(
            e.contains(&format!("feature_scales.node[{channel}]"))
                && e.contains("layout_gain 2, code_gain 4"),
            "{e}"
        );
    }
    // With the same gains it continues.
    let mut steps = Vec::new();
    train_diffusion(&data, &gains(2.0, 4.0, 8), dir.path(), true, &mut |p| {
        steps.push(p.step)
    })
    .unwrap();
    assert_eq!((steps.first(), steps.last()), (Some(&5), Some(&8)));
}

#[test]
fn bad_config_values_are_named() {
    let err = |cfg: DiffusionTrainConfig| {
        let dir = tempfile::tempdir().unwrap();
        train_diffusion(&tiny_data(), &cfg, dir.path(), false, &mut |_| {})
            .err()
            .unwrap()
            .to_string()
    };
    // Each bad value, and what its error must name: the field, the value, the limit.
    let base = || tiny_config(10);
    let cases: [(DiffusionTrainConfig, &[&str]); 10] = [
        (
            DiffusionTrainConfig {
                layout_gain: 0.2,
                ..base()
            },
            &["layout_gain", "0.2", "[0.25, 8]"],
        ),
        (
            DiffusionTrainConfig {
                code_gain: 9.0,
                ..base()
            },
            &["code_gain", "9", "[0.25, 8]"],
        ),
        (
            DiffusionTrainConfig {
                layout_gain: f64::NAN,
                ..base()
            },
            &["layout_gain", "NaN"],
        ),
        (
            DiffusionTrainConfig {
                category_dropout: 1.5,
                ..base()
            },
            &["category_dropout", "1.5"],
        ),
        (
            DiffusionTrainConfig {
                stop_at: Some(11),
                ..base()
            },
            &["stop_at", "11"],
        ),
        (
            DiffusionTrainConfig {
                min_snr_gamma: -1.0,
                ..base()
            },
            &["min_snr_gamma", "-1"],
        ),
        (
            DiffusionTrainConfig {
                high_noise_cap: f64::INFINITY,
                ..base()
            },
            &["high_noise_cap", "inf"],
        ),
        (
            DiffusionTrainConfig {
                batch_shards: 9,
                ..base()
            },
            &["batch_shards", "9", "batch_objects"],
        ),
        (
            DiffusionTrainConfig {
                overlap_weight: -0.5,
                ..base()
            },
            &["overlap_weight", "-0.5"],
        ),
        (
            DiffusionTrainConfig {
                overlap_max_t: 501,
                ..base()
            },
            &["overlap_max_t", "501", "1..=500"],
        ),
    ];
    for (cfg, names) in cases {
        let e = err(cfg);
        assert!(names.iter().all(|n| e.contains(n)), "{names:?}: {e}");
    }
}

/// A raw node row with the given centre and half-extents.
fn box_row(centre: [f32; 3], half: [f32; 3]) -> Vec<f32> {
    let mut row = vec![0.0; NODE_DIM];
    row[node_ch::EXIST] = 1.0;
    row[node_ch::BOX..node_ch::CENTER].copy_from_slice(&half);
    row[node_ch::CENTER..node_ch::LATENT].copy_from_slice(&centre);
    row
}

#[test]
fn box_depth_is_the_smallest_axis_overlap_and_negative_for_a_gap() {
    let a = box_row([0.0; 3], [0.5; 3]);
    // Overlaps 0.2 along x, fully along y and z: depth 0.2.
    let b = box_row([0.8, 0.0, 0.0], [0.5, 0.2, 0.2]);
    assert!((box_depth(&a, &b) - 0.2).abs() < 1e-6);
    assert!((box_depth(&b, &a) - 0.2).abs() < 1e-6);
    // A gap of 0.1 along y.
    let c = box_row([0.0, 1.1, 0.0], [0.5; 3]);
    assert!((box_depth(&a, &c) + 0.1).abs() < 1e-6);
    // Negative half-extents count by their magnitude.
    let d = box_row([0.8, 0.0, 0.0], [-0.5, 0.2, -0.2]);
    assert_eq!(box_depth(&a, &d), box_depth(&a, &b));
}

#[test]
fn overlap_penalty_charges_only_depth_beyond_the_data_and_pushes_boxes_apart() {
    // Two parts that touch in x₀ (depth 0); x̂₀ shifts the second 0.3 into the first.
    let device = crate::model::Compute::Cpu.autodiff();
    let x0 = [
        box_row([0.0; 3], [0.5; 3]),
        box_row([1.0, 0.0, 0.0], [0.5; 3]),
    ];
    let mut g = GraphTensor::empty();
    for (i, row) in x0.iter().enumerate() {
        g.node_mut(i).copy_from_slice(row);
    }
    let (depth, mask) = pair_targets(&g);
    assert_eq!(mask.iter().sum::<f32>(), 1.0, "one pair counts: (0, 1)");
    assert_eq!(depth[1], 0.0);
    let scales = FeatureScales::default();
    let (sa, sb) = (0.9f32, (1.0f32 - 0.81).sqrt());
    let penalty = |shift: f32, mask: &[f32]| {
        // x_t = sa x₀ + sb ε with ε = 0; the prediction ε̂ moves x̂₀'s second centre by −shift.
        let mut nodes = vec![0.0f32; K * NODE_DIM];
        let mut pred = vec![0.0f32; K * NODE_DIM];
        for (i, row) in x0.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                nodes[i * NODE_DIM + c] = sa * v;
            }
        }
        pred[NODE_DIM + node_ch::CENTER] = shift * sa / sb;
        let t3 =
            |v: Vec<f32>, d: [usize; 3]| Tensor::<3>::from_data(TensorData::new(v, d), &device);
        let pred = t3(pred, [1, K, NODE_DIM]).require_grad();
        let o = OverlapBatch {
            sqrt_alpha_bar: t3(vec![sa], [1, 1, 1]),
            sqrt_one_minus: t3(vec![sb], [1, 1, 1]),
            depth: t3(depth.clone(), [1, K, K]),
            mask: t3(mask.to_vec(), [1, K, K]),
            scales: t3(
                scales.node[node_ch::BOX..node_ch::LATENT].to_vec(),
                [1, 1, 6],
            ),
            weight: 2.0,
        };
        let loss = box_overlap_penalty(t3(nodes, [1, K, NODE_DIM]), pred.clone(), &o);
        let value = loss.clone().into_scalar::<f32>();
        let grads = loss.backward();
        let grad = pred
            .grad(&grads)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        (value, grad[NODE_DIM + node_ch::CENTER])
    };
    // x̂₀ = x₀: nothing to pay; pulled apart (a gap): nothing either.
    assert!(penalty(0.0, &mask).0.abs() < 1e-6);
    assert!(penalty(-0.2, &mask).0.abs() < 1e-6);
    // 0.3 deeper than the data: λ · 0.3² = 0.18.
    let (value, grad) = penalty(0.3, &mask);
    assert!((value - 0.18).abs() < 1e-4, "{value}");
    // Descending the loss lowers ε̂'s shift, i.e. moves the part back out.
    assert!(grad > 0.0, "{grad}");
    // A masked pair (a nonexistent part, or t ≥ overlap_max_t) costs nothing.
    assert_eq!(penalty(0.3, &[0.0; K * K]).0, 0.0);
}

#[test]
fn overlap_training_lowers_the_loss_and_records_its_settings() {
    let summary = train_tiny_until_the_loss_falls(DiffusionTrainConfig {
        overlap_weight: 10.0,
        overlap_max_t: MAX_OVERLAP_T,
        ..tiny_config(60)
    });
    assert_eq!(summary["overlap_weight"], 10.0);
    assert_eq!(summary["overlap_max_t"], MAX_OVERLAP_T);
}

/// Train `cfg` (60 steps of the tiny config) on the tiny data, assert that the loss of the
/// last 10 steps is below 0.8× the first 10's, and return the run's `diffusion_train.json`.
fn train_tiny_until_the_loss_falls(cfg: DiffusionTrainConfig) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let mut losses = Vec::new();
    train_diffusion(&tiny_data(), &cfg, dir.path(), false, &mut |p| {
        losses.push(p.loss)
    })
    .unwrap();
    let first: f64 = losses[..10].iter().sum::<f64>() / 10.0;
    let last: f64 = losses[50..].iter().sum::<f64>() / 10.0;
    assert!(last < 0.8 * first, "loss did not fall: {first} -> {last}");
    serde_json::from_str(&std::fs::read_to_string(dir.path().join("diffusion_train.json")).unwrap())
        .unwrap()
}

#[test]
fn sharded_steps_match_the_single_pass_and_are_deterministic() {
    // Two or three slices in parallel give the whole batch's loss and gradient up to float
    // rounding, so a short run tracks the single-pass one closely; and a sharded run
    // repeats bit for bit (the gradients are summed in slice order).
    let data = tiny_data();
    let run = |shards: usize| {
        let dir = tempfile::tempdir().unwrap();
        let mut losses = Vec::new();
        let cfg = DiffusionTrainConfig {
            batch_shards: shards,
            ema_decay: 0.0,
            ..tiny_config(8)
        };
        let r =
            train_diffusion(&data, &cfg, dir.path(), false, &mut |p| losses.push(p.loss)).unwrap();
        (losses, std::fs::read(r.weights).unwrap())
    };
    super::super::check_sharded_runs(run);
}

#[test]
fn min_snr_weights_damp_only_the_low_noise_steps() {
    let schedule = Schedule::default();
    let off = DiffusionTrainConfig::default();
    let on = DiffusionTrainConfig {
        min_snr_gamma: 5.0,
        ..DiffusionTrainConfig::default()
    };
    for t in [0, 10, 100, 500, 999] {
        let (a, b) = schedule.noise_coefficients(t);
        assert_eq!(off.loss_weight(a, b), 1.0);
        let snr = a * a / (b * b);
        let w = on.loss_weight(a, b);
        assert!((w - (5.0 / snr).min(1.0)).abs() < 1e-12, "t={t}: {w}");
    }
    // Low noise (SNR ≫ γ) is damped, high noise is left at 1.
    let (a, b) = schedule.noise_coefficients(5);
    assert!(on.loss_weight(a, b) < 0.1);
    let (a, b) = schedule.noise_coefficients(500);
    assert_eq!(on.loss_weight(a, b), 1.0);
}

#[test]
fn high_noise_cap_raises_only_the_high_noise_steps() {
    let schedule = Schedule::default();
    let cap = DiffusionTrainConfig {
        high_noise_cap: 100.0,
        ..DiffusionTrainConfig::default()
    };
    assert!(cap.weighted() && !DiffusionTrainConfig::default().weighted());
    for t in [0, 10, 100, 300, 500, 700, 999] {
        let (a, b) = schedule.noise_coefficients(t);
        let snr = a * a / (b * b);
        let w = cap.loss_weight(a, b);
        assert!(
            (w - (1.0 / snr).clamp(1.0, 100.0)).abs() < 1e-9,
            "t={t}: {w}"
        );
    }
    // Low noise (SNR > 1) keeps weight 1; the noisiest steps reach the cap.
    let (a, b) = schedule.noise_coefficients(10);
    assert_eq!(cap.loss_weight(a, b), 1.0);
    let (a, b) = schedule.noise_coefficients(999);
    assert_eq!(cap.loss_weight(a, b), 100.0);
    // Both on: they act on disjoint SNR ranges and multiply.
    let both = DiffusionTrainConfig {
        min_snr_gamma: 5.0,
        ..cap.clone()
    };
    let (a, b) = schedule.noise_coefficients(999);
    assert_eq!(both.loss_weight(a, b), 100.0);
    let (a, b) = schedule.noise_coefficients(5);
    assert!(both.loss_weight(a, b) < 0.1);
}

#[test]
fn loss_weights_cannot_clamp_the_gradient_away() {
    // ε = 1 against a zero prediction: every group's mean square is 1, so each sample's
    // grouped loss is 4 (the node groups' mean plus three edge groups).
    let dev = crate::model::cpu_autodiff();
    let b = 2;
    let run = |eps: f32, w: Option<f32>| {
        let pv = Tensor::<3>::zeros([b, K, NODE_DIM], &dev).require_grad();
        let pe = Tensor::<3>::zeros([b, NUM_EDGES, EDGE_DIM], &dev);
        let ev = Tensor::<3>::full([b, K, NODE_DIM], eps, &dev);
        let ee = Tensor::<3>::full([b, NUM_EDGES, EDGE_DIM], eps, &dev);
        let weights = w.map(|w| Tensor::<1>::full([b], w, &dev));
        let loss = grouped_loss(pv.clone(), pe, ev, ee, weights);
        let value = loss.clone().into_scalar::<f32>();
        let grads = loss.backward();
        let g = pv.grad(&grads).map(|g| g.abs().sum().into_scalar::<f32>());
        (value, g.unwrap_or(0.0))
    };
    let (plain, g_plain) = run(1.0, None);
    assert!(
        (plain - 4.0).abs() < 1e-4 && g_plain > 0.0,
        "{plain} {g_plain}"
    );
    // Weight 100: the weighted mean is 400 and still has a gradient (clamping the mean,
    // NAP's guard, would give 100 and none).
    let (weighted, g_weighted) = run(1.0, Some(100.0));
    assert!((weighted - 400.0).abs() < 1e-2, "{weighted}");
    assert!(g_weighted > 50.0 * g_plain, "{g_weighted} vs {g_plain}");
    // The guard still holds per sample: a loss of 10⁴ counts as 100 (times its weight).
    let (huge, _) = run(50.0, Some(2.0));
    assert!((huge - 200.0).abs() < 1e-2, "{huge}");
    // Unweighted, NAP's clamp of the mean is unchanged.
    let (huge_plain, g_huge) = run(50.0, None);
    assert_eq!((huge_plain, g_huge), (100.0, 0.0));
}

#[test]
fn min_snr_training_lowers_the_loss_and_records_gamma() {
    let summary = train_tiny_until_the_loss_falls(DiffusionTrainConfig {
        min_snr_gamma: 5.0,
        ..tiny_config(60)
    });
    assert_eq!(summary["min_snr_gamma"], 5.0);
}

#[test]
fn learning_rate_is_constant_then_decays_to_the_final_factor() {
    let cfg = DiffusionTrainConfig {
        steps: 101,
        lr: 1e-3,
        lr_decay_start: 50,
        lr_final_factor: 0.1,
        ..DiffusionTrainConfig::default()
    };
    assert_eq!(cfg.lr_at(0), 1e-3);
    assert_eq!(cfg.lr_at(49), 1e-3);
    assert_eq!(cfg.lr_at(50), 1e-3);
    assert!((cfg.lr_at(100) - 1e-4).abs() < 1e-12, "{}", cfg.lr_at(100));
    assert!((cfg.lr_at(75) - 5.5e-4).abs() < 1e-9, "{}", cfg.lr_at(75));
    for s in 50..100 {
        assert!(cfg.lr_at(s + 1) < cfg.lr_at(s));
    }
    let constant = DiffusionTrainConfig {
        lr_final_factor: 1.0,
        ..cfg
    };
    assert_eq!(constant.lr_at(100), 1e-3);
}
