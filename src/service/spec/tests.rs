//! Tests of `spec`.

use super::*;
use crate::engine::schedule::timesteps;

/// [`super::validate`] for a request with at most one defect: the one violation it reports
/// (the tests below each break one rule; [`every_violation_is_listed`] breaks several).
fn validate(
    input: &JobInput,
    caps: &ModelCaps,
    limits: &Limits,
    seed: u64,
) -> Result<JobSpec, Violation> {
    super::validate(input, caps, limits, seed).map_err(|all| {
        assert_eq!(all.len(), 1, "one defect, one violation: {all}");
        all.first().clone()
    })
}

fn caps() -> ModelCaps {
    ModelCaps {
        categories: vec!["Door".into(), "Window".into()],
        conditional: true,
        schedule_steps: 1000,
        codebook: true,
        codebook_categories: vec![1],
    }
}

fn cloud(n: usize) -> PointsInput {
    PointsInput::Triples((0..n).map(|i| [i as f64, 0.0, 1.0]).collect())
}

#[test]
fn category_guidance_defaults_with_a_category_and_is_zero_without() {
    // `w_pc` 0 (with the other weights 0) makes the job plain sampling; None keeps the
    // default loss weights, a scan-guided job.
    let run = |cat: Option<&str>, w: Option<f64>, w_pc: Option<f64>| {
        let input = JobInput {
            points: Some(cloud(16)),
            category: cat.map(str::to_string),
            category_guidance: w,
            w_pc,
            w_pen: w_pc,
            w_mob: w_pc,
            ..Default::default()
        };
        validate(&input, &caps(), &Limits::default(), 1)
            .unwrap()
            .category_guidance
    };
    for w_pc in [None, Some(0.0)] {
        assert_eq!(run(None, None, w_pc), 0.0);
        assert_eq!(run(None, Some(0.0), w_pc), 0.0);
        assert_eq!(run(Some("Door"), Some(0.0), w_pc), 0.0);
        assert_eq!(run(Some("Door"), Some(4.5), w_pc), 4.5);
    }
    // By default a scan-guided job is not category-guided (it completed scans worse,
    // EVALUATION.md); plain sampling is, at w = 2.
    assert_eq!(run(Some("Door"), None, None), 0.0);
    assert_eq!(run(Some("Door"), None, Some(0.0)), 2.0);
    // A scan-guided job is category-guided in every step by default, plain sampling only
    // below t = 500; either can be asked for.
    let below = |b: Option<u32>, w_pc: f64| {
        let input = JobInput {
            points: Some(cloud(16)),
            category: Some("Door".into()),
            category_guidance_below: b,
            w_pc: Some(w_pc),
            w_pen: Some(0.0),
            w_mob: Some(0.0),
            ..Default::default()
        };
        validate(&input, &caps(), &Limits::default(), 1)
            .unwrap()
            .category_guidance_below
    };
    assert_eq!(below(None, 1.0), 1000);
    assert_eq!(below(None, 0.0), 500);
    assert_eq!(below(Some(500), 1.0), 500);
    assert_eq!(below(Some(1), 0.0), 1);
}

#[test]
fn accepts_defaults_and_materialises_the_seed() {
    let input = JobInput {
        points: Some(cloud(16)),
        ..Default::default()
    };
    let s = validate(&input, &caps(), &Limits::default(), 77).unwrap();
    // physnap's fast default: DDIM over 200 steps, those with t < 500 guided (the paper's
    // n_g = 500), with the gradient clamp.
    assert_eq!((s.seed, s.samples, s.steps, s.n_g), (77, 1, 200, 500));
    assert_eq!(
        (s.tau, s.sampler.name(), s.sampler.eta()),
        (1000.0, "ddim", 0.0)
    );
    assert_eq!(s.sampler, Sampler::Ddim { eta: 0.0 });
    assert_eq!(s.guidance_max_step, Some(DEFAULT_MAX_STEP));
    assert_eq!(s.refine_steps, 30);
    assert_eq!(s.refine_physics_steps, 0);
    assert_eq!((s.w_pc, s.w_pen, s.w_mob), (15.0, 2.0, 2.0));
    assert!(s.guided());
    // That is the last 100 of the 200 strided times, as with the CLI's `--n-g 500`.
    let times = timesteps(1000, 200);
    assert_eq!(times.iter().filter(|&&t| t < s.n_g as usize).count(), 100);
    assert_eq!(s.points.len(), 16);
    // The paper's sampler is one field away.
    let paper = JobInput {
        sampler: Some("ddpm".into()),
        steps: Some(1000),
        ..input
    };
    let s = validate(&paper, &caps(), &Limits::default(), 77).unwrap();
    assert_eq!((s.steps, s.n_g, s.sampler), (1000, 500, Sampler::Ddpm));
}

#[test]
fn retrieval_auto_follows_the_codebook_and_explicit_modes_need_one() {
    let input = |r: Option<&str>| JobInput {
        points: Some(cloud(16)),
        retrieval: r.map(str::to_string),
        ..Default::default()
    };
    let without = ModelCaps {
        codebook: false,
        ..caps()
    };
    let l = Limits::default();
    let run = |r, c: &ModelCaps| validate(&input(r), c, &l, 0).map(|s| s.retrieval);
    assert_eq!(run(None, &caps()).unwrap().as_str(), "empty");
    assert_eq!(run(Some("auto"), &caps()).unwrap().as_str(), "empty");
    assert_eq!(run(Some("all"), &caps()).unwrap().as_str(), "all");
    assert_eq!(run(None, &without).unwrap().as_str(), "off");
    assert_eq!(run(Some("off"), &without).unwrap().as_str(), "off");
    let v = run(Some("all"), &without).unwrap_err();
    assert_eq!(
        (v.field.as_str(), v.value.as_str()),
        ("retrieval", "\"all\"")
    );
    assert!(v.limit.contains("no codebook"), "{v}");
    let s = validate(&input(Some("all")), &caps(), &l, 0).unwrap();
    assert_eq!(s.retrieval, Retrieval::All);
    // "category" needs a category that has codes in the codebook.
    let with = |r: &str, c: Option<&str>| JobInput {
        category: c.map(str::to_string),
        ..input(Some(r))
    };
    let s = validate(&with("category", Some("Window")), &caps(), &l, 0).unwrap();
    assert_eq!(s.retrieval, Retrieval::Category);
    let v = validate(&with("category", None), &caps(), &l, 0).unwrap_err();
    assert_eq!(
        (v.field.as_str(), v.value.as_str()),
        ("retrieval", "\"category\" without a category")
    );
    let v = validate(&with("category", Some("Door")), &caps(), &l, 0).unwrap_err();
    assert_eq!(v.value, "\"category\" with category Door");
    assert!(
        v.limit.contains("training codes in the codebook: Window"),
        "{v}"
    );
    let plain = ModelCaps {
        codebook_categories: Vec::new(),
        ..caps()
    };
    let v = validate(&with("category", Some("Window")), &plain, &l, 0).unwrap_err();
    assert!(v.limit.contains("carry categories"), "{v}");
}

#[test]
fn joint_motion_defaults_and_a_bad_name_is_refused() {
    let input = |m: Option<&str>| JobInput {
        points: Some(cloud(16)),
        joint_motion: m.map(str::to_string),
        ..Default::default()
    };
    let l = Limits::default();
    let run = |m| validate(&input(m), &caps(), &l, 0);
    assert_eq!(run(None).unwrap().joint_motion, DEFAULT_JOINT_MOTION);
    assert_eq!(run(Some("")).unwrap().joint_motion, DEFAULT_JOINT_MOTION);
    let s = run(Some("dominant")).unwrap();
    assert_eq!(s.joint_motion, JointMotion::Dominant);
    assert_eq!(run(Some("screw")).unwrap().joint_motion, JointMotion::Screw);
    let v = run(Some("revolute")).unwrap_err();
    assert_eq!(
        (v.field.as_str(), v.limit.as_str(), v.value.as_str()),
        ("joint_motion", "\"screw\" or \"dominant\"", "\"revolute\"")
    );
}

#[test]
fn weight_defaults_follow_the_papers_rule_for_the_active_terms() {
    // The paper's base ÷ active terms (45/2 and 2/2 here), ℓ_mob × 3 (physnap's default).
    let input = JobInput {
        points: Some(cloud(16)),
        w_pen: Some(0.0),
        ..Default::default()
    };
    let s = validate(&input, &caps(), &Limits::default(), 0).unwrap();
    assert_eq!((s.w_pc, s.w_pen, s.w_mob), (22.5, 0.0, 3.0));
    let input = JobInput {
        points: Some(cloud(16)),
        w_pc: Some(0.0),
        w_pen: Some(0.0),
        w_mob: Some(0.0),
        ..Default::default()
    };
    assert!(
        !validate(&input, &caps(), &Limits::default(), 0)
            .unwrap()
            .guided()
    );
}

#[test]
fn n_g_is_the_papers_threshold_on_diffusion_time_whatever_the_steps() {
    let input = JobInput {
        points: Some(cloud(16)),
        sampler: Some("ddim".into()),
        eta: Some(0.5),
        steps: Some(20),
        ..Default::default()
    };
    let s = validate(&input, &caps(), &Limits::default(), 0).unwrap();
    assert_eq!((s.steps, s.n_g), (20, 500));
    // The gradient clamp is on by default; 0 asks for the paper's raw step.
    assert_eq!(s.guidance_max_step, Some(DEFAULT_MAX_STEP));
    let raw = JobInput {
        guidance_max_step: Some(0.0),
        ..input.clone()
    };
    let raw = validate(&raw, &caps(), &Limits::default(), 0).unwrap();
    assert_eq!(raw.guidance_max_step, None);
    assert_eq!(s.sampler, Sampler::Ddim { eta: 0.5 });
    // n_g goes to the engine as it is: t < n_g, any number of steps.
    for n_g in [0, 1, 250, 1000] {
        let i = JobInput {
            n_g: Some(n_g),
            ..input.clone()
        };
        let s = validate(&i, &caps(), &Limits::default(), 0).unwrap();
        assert_eq!(s.n_g, n_g);
        assert_eq!(
            crate::service::runner::guidance_of(&s).unwrap().steps,
            n_g as usize
        );
    }
    // 10 of the 20 strided times are below the default 500.
    let guided = timesteps(1000, 20).into_iter().filter(|&t| t < 500).count();
    assert_eq!(guided, 10);
}

#[test]
fn each_limit_names_field_limit_and_value() {
    let l = Limits::default();
    let bad = |f: &dyn Fn(&mut JobInput)| {
        let mut i = JobInput {
            points: Some(cloud(20)),
            ..Default::default()
        };
        f(&mut i);
        validate(&i, &caps(), &l, 0).unwrap_err()
    };
    let v = bad(&|i| i.points = Some(cloud(15)));
    assert_eq!(
        (v.field.as_str(), v.value.as_str()),
        ("points", "15 points")
    );
    assert!(v.limit.contains("16..=100000"));
    let v = bad(&|i| i.w_pen = Some(-1.0));
    assert_eq!((v.field.as_str(), v.value.as_str()), ("w_pen", "-1"));
    assert!(v.limit.contains(">= 0"));
    let v = bad(&|i| i.category = Some("Spaceship".into()));
    assert_eq!(v.field, "category");
    assert!(v.limit.contains("Door, Window"), "{v}");
    let mut flat = vec![0.5f32; 60];
    flat[4] = f32::NAN;
    let v = bad(&|i| i.points = Some(PointsInput::Flat(flat.clone())));
    assert_eq!(
        (v.field.as_str(), v.limit.as_str()),
        ("points[1][1]", "finite")
    );
    let v = bad(&|i| i.samples = Some(0));
    assert_eq!(v.field, "samples");
    let v = bad(&|i| i.steps = Some(0));
    assert_eq!((v.field.as_str(), v.value.as_str()), ("steps", "0"));
    let v = bad(&|i| i.steps = Some(1001));
    assert_eq!((v.field.as_str(), v.value.as_str()), ("steps", "1001"));
    assert!(v.limit.contains("1..=1000"), "{v}");
    let v = bad(&|i| {
        i.steps = Some(20);
        i.n_g = Some(1001);
    });
    assert_eq!((v.field.as_str(), v.value.as_str()), ("n_g", "1001"));
    assert!(v.limit.contains("<= 1000"), "{v}");
    for (tau, shown) in [(0.0, "0"), (-1.0, "-1"), (f64::NAN, "NaN")] {
        let v = bad(&|i| i.tau = Some(tau));
        assert_eq!((v.field.as_str(), v.value.as_str()), ("tau", shown));
        assert!(v.limit.contains("> 0"), "{v}");
    }
    for (w, shown) in [(-0.5, "-0.5"), (21.0, "21"), (f64::INFINITY, "inf")] {
        let v = bad(&|i| {
            i.category = Some("Door".into());
            i.category_guidance = Some(w);
        });
        assert_eq!(
            (v.field.as_str(), v.value.as_str()),
            ("category_guidance", shown)
        );
        assert!(v.limit.contains("[0, 20]"), "{v}");
    }
    let v = bad(&|i| i.category_guidance = Some(3.0));
    assert_eq!(
        (v.field.as_str(), v.limit.as_str(), v.value.as_str()),
        ("category_guidance", "0 or absent without a category", "3")
    );
    for b in [0, 1001] {
        let v = bad(&|i| i.category_guidance_below = Some(b));
        assert_eq!(
            (v.field.as_str(), v.limit.as_str(), v.value.as_str()),
            (
                "category_guidance_below",
                "in [1, 1000]",
                b.to_string().as_str()
            )
        );
    }
    let v = bad(&|i| i.retrieval = Some("nearest".into()));
    assert_eq!(
        (v.field.as_str(), v.value.as_str()),
        ("retrieval", "\"nearest\"")
    );
    assert!(v.limit.contains("\"empty\""), "{v}");
    let v = bad(&|i| i.sampler = Some("euler".into()));
    assert_eq!(
        (v.field.as_str(), v.value.as_str()),
        ("sampler", "\"euler\"")
    );
    assert!(v.limit.contains("ddim"), "{v}");
    let v = bad(&|i| {
        i.sampler = Some("ddpm".into());
        i.eta = Some(0.5);
    });
    assert_eq!(v.field, "eta");
    let v = bad(&|i| {
        i.sampler = Some("ddim".into());
        i.eta = Some(1.5);
    });
    assert_eq!((v.field.as_str(), v.value.as_str()), ("eta", "1.5"));
    for (c, shown) in [(-1.0, "-1"), (f64::INFINITY, "inf")] {
        let v = bad(&|i| i.guidance_max_step = Some(c));
        assert_eq!(
            (v.field.as_str(), v.value.as_str()),
            ("guidance_max_step", shown)
        );
        assert!(v.limit.contains(">= 0"), "{v}");
    }
    let v = bad(&|i| i.refine_steps = Some(1001));
    assert_eq!(
        (v.field.as_str(), v.value.as_str(), v.limit.as_str()),
        ("refine_steps", "1001", "<= 1000 (0: off)")
    );
    let v = bad(&|i| i.refine_physics_steps = Some(1001));
    assert_eq!(
        (v.field.as_str(), v.value.as_str(), v.limit.as_str()),
        ("refine_physics_steps", "1001", "<= 1000 (0: off)")
    );
    let v = bad(&|i| i.points = Some(PointsInput::F32Le(vec![0; 13])));
    assert!(v.limit.contains("multiple of 12"));
    let v = bad(&|i| i.points = Some(PointsInput::Ply(b"ply\nformat nonsense\n".to_vec())));
    assert_eq!(v.field, "points");
    assert!(v.value.contains("PLY"), "{v}");
}

#[test]
fn cameras_come_as_one_triple_or_a_list_and_set_w_free_and_repair_defaults() {
    // cloud(16) spans [0, 15] × [0, 0] × [1, 1]: [0, -3, 1] is outside its box.
    let l = Limits::default();
    let run = |camera: Option<CameraInput>, w_free: Option<f64>, repair: Option<&str>| {
        let input = JobInput {
            points: Some(cloud(16)),
            camera,
            w_free,
            repair: repair.map(str::to_string),
            ..Default::default()
        };
        validate(&input, &caps(), &l, 0).unwrap()
    };
    let s = run(None, None, None);
    assert!(s.cameras.is_empty());
    assert_eq!((s.w_free, s.repair), (0.0, RepairMode::On));
    let s = run(Some(CameraInput::One(vec![0.0, -3.0, 1.0])), None, None);
    assert_eq!(s.cameras, vec![[0.0, -3.0, 1.0]]);
    assert_eq!((s.w_free, DEFAULT_W_FREE), (15.0, 15.0));
    let two = CameraInput::Many(vec![vec![0.0, -3.0, 1.0], vec![20.0, 0.5, 2.0]]);
    let s = run(Some(two), Some(4.0), Some("off"));
    assert_eq!(s.cameras, vec![[0.0, -3.0, 1.0], [20.0, 0.5, 2.0]]);
    assert_eq!((s.w_free, s.repair), (4.0, RepairMode::Off));
    // The engine runs what the spec says.
    let g = crate::service::runner::guidance_of(&s).unwrap();
    assert_eq!((g.cameras.clone(), g.w_free), (s.cameras.clone(), 4.0));
    assert!(g.free_active());
    // Without a camera ℓ_free has nothing to look from: a given weight runs as 0, as with
    // `physnap generate --w-free`. An empty list is no camera.
    assert_eq!(run(None, Some(4.0), None).w_free, 0.0);
    let s = run(Some(CameraInput::Many(Vec::new())), None, Some(""));
    assert_eq!(
        (s.cameras.len(), s.w_free, s.repair),
        (0, 0.0, RepairMode::On)
    );
    // ℓ_free alone guides a job: it counts as scan-guided (no category guidance by default),
    // and a camera with every weight 0 still reaches the engine for the part removal.
    let free_only = |w_free: f64| JobInput {
        points: Some(cloud(16)),
        category: Some("Door".into()),
        w_pc: Some(0.0),
        w_pen: Some(0.0),
        w_mob: Some(0.0),
        camera: Some(CameraInput::One(vec![0.0, -3.0, 1.0])),
        w_free: Some(w_free),
        ..Default::default()
    };
    let s = validate(&free_only(15.0), &caps(), &l, 0).unwrap();
    assert!(s.guided());
    assert_eq!(
        (s.category_guidance, s.category_guidance_below),
        (0.0, 1000)
    );
    let s = validate(&free_only(0.0), &caps(), &l, 0).unwrap();
    assert!(!s.guided());
    assert_eq!(s.category_guidance, 2.0);
    let g = crate::service::runner::guidance_of(&s).unwrap();
    assert!(!g.is_active());
    assert_eq!(g.cameras, s.cameras);
}

#[test]
fn camera_w_free_and_repair_rejections_name_field_limit_and_value() {
    let l = Limits::default();
    let bad = |f: &dyn Fn(&mut JobInput)| {
        let mut i = JobInput {
            points: Some(cloud(16)),
            ..Default::default()
        };
        f(&mut i);
        validate(&i, &caps(), &l, 0).unwrap_err()
    };
    let one = |c: [f64; 3]| Some(CameraInput::One(c.to_vec()));
    let many = |cs: &[[f64; 3]]| Some(CameraInput::Many(cs.iter().map(|c| c.to_vec()).collect()));
    let shape = "3 finite numbers [x, y, z] (object frame, metres)";
    let v = bad(&|i| i.camera = Some(CameraInput::One(vec![1.0, 2.0])));
    assert_eq!(
        (v.field.as_str(), v.limit.as_str(), v.value.as_str()),
        ("camera", shape, "[1, 2]")
    );
    let v = bad(&|i| i.camera = many(&[[0.0, -3.0, 1.0], [1.0, f64::NAN, 2.5]]));
    assert_eq!(
        (v.field.as_str(), v.limit.as_str(), v.value.as_str()),
        ("camera[1]", shape, "[1, NaN, 2.5]")
    );
    // Inside the points' box (the engine's rule), as one triple and as a list's second.
    let v = bad(&|i| i.camera = one([5.0, 0.0, 1.0]));
    assert_eq!(
        (v.field.as_str(), v.value.as_str()),
        ("camera", "[5.0, 0.0, 1.0]")
    );
    assert!(
        v.limit
            .starts_with("outside the points' box [0.000, 15.000]"),
        "{v}"
    );
    let v = bad(&|i| i.camera = many(&[[0.0, -3.0, 1.0], [5.0, 0.0, 1.0]]));
    assert_eq!(v.field, "camera[1]");
    assert!(v.limit.contains("outside the points' box"), "{v}");
    let v = bad(&|i| i.camera = one([2000.0, 0.0, 0.0]));
    assert_eq!(
        (v.field.as_str(), v.limit.as_str(), v.value.as_str()),
        (
            "camera",
            "finite, |coordinate| ≤ 1000",
            "[2000.0, 0.0, 0.0]"
        )
    );
    let seventeen: Vec<[f64; 3]> = (0..17).map(|k| [k as f64, -3.0, 1.0]).collect();
    let v = bad(&|i| i.camera = many(&seventeen));
    assert_eq!(
        (v.field.as_str(), v.limit.as_str(), v.value.as_str()),
        ("camera", "at most 16 cameras", "17 cameras")
    );
    for (w, shown) in [(-1.0, "-1"), (f64::NAN, "NaN"), (2.0e6, "2000000")] {
        let v = bad(&|i| {
            i.camera = one([0.0, -3.0, 1.0]);
            i.w_free = Some(w);
        });
        assert_eq!((v.field.as_str(), v.value.as_str()), ("w_free", shown));
        assert_eq!(v.limit, "finite, >= 0 and <= 1000000", "{v}");
    }
    // A bad weight is refused with or without a camera.
    let v = bad(&|i| i.w_free = Some(-2.0));
    assert_eq!((v.field.as_str(), v.value.as_str()), ("w_free", "-2"));
    let v = bad(&|i| i.repair = Some("maybe".into()));
    assert_eq!(
        (v.field.as_str(), v.limit.as_str(), v.value.as_str()),
        ("repair", "\"on\" or \"off\"", "\"maybe\"")
    );
}

#[test]
fn scale_defaults_to_auto_for_a_known_category_and_is_resolved_at_submission() {
    // A 0.34 m scan of a door (the generator's doors are about 2 m): auto scales it up, capped
    // at 4.
    let small = PointsInput::Triples(
        (0..16)
            .map(|i| [0.0, 0.02 * i as f64, 0.1 + 0.01 * i as f64])
            .collect(),
    );
    let run = |cat: Option<&str>, scale: Option<&str>| {
        validate(
            &JobInput {
                points: Some(small.clone()),
                category: cat.map(str::to_string),
                scale: scale.map(str::to_string),
                ..Default::default()
            },
            &caps(),
            &Limits::default(),
            1,
        )
    };
    assert_eq!(run(Some("Door"), None).unwrap().scale, Some(4.0));
    assert_eq!(run(Some("Door"), Some("auto")).unwrap().scale, Some(4.0));
    // Without a category, the typical size over every category the prior trained on.
    let any = crate::data::synth::typical_diagonal_any();
    let s = run(None, None).unwrap().scale.unwrap();
    assert!((1.0..4.0).contains(&s) && s > any, "{s} (typical {any})");
    assert_eq!(run(Some("Door"), Some("off")).unwrap().scale, None);
    assert_eq!(run(Some("Door"), Some("2.5")).unwrap().scale, Some(2.5));
    for bad in ["big", "0", "NaN", "20"] {
        let e = run(Some("Door"), Some(bad)).unwrap_err().to_string();
        assert!(
            e.contains("scale") && e.contains("[0.0625, 16]") && e.contains(bad),
            "{e}"
        );
    }
}

#[test]
fn frame_auto_is_estimated_at_submission_and_bad_frames_are_refused() {
    // A ray-cast scan of the example cabinet, turned to +Y up and yawed by 30°, shifted.
    let obj = crate::fixtures::cabinet();
    let meshes =
        crate::mesh::mesh_parts(&obj, None, &crate::mesh::MeshingOptions { resolution: 32 })
            .unwrap();
    let scan = crate::data::scan::scan(
        &meshes,
        &mut crate::data::rng::Rng::new(3),
        &crate::data::scan::ScanOptions::default(),
    )
    .unwrap();
    let m = crate::eval::real::frame::move_of("spec", 1, crate::eval::real::frame::MovedUp::Y);
    let moved = crate::eval::real::frame::moved(&m, &scan.points);
    let eye = crate::eval::real::frame::moved(
        &m,
        &[[
            scan.camera.eye.x as f32,
            scan.camera.eye.y as f32,
            scan.camera.eye.z as f32,
        ]],
    )[0];
    let points = PointsInput::Triples(
        moved
            .iter()
            .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64])
            .collect(),
    );
    let run = |frame: Option<&str>, up: Option<[f64; 3]>, pts: PointsInput| {
        validate(
            &JobInput {
                points: Some(pts),
                category: Some("Door".into()),
                camera: Some(CameraInput::One(eye.iter().map(|&c| c as f64).collect())),
                frame: frame.map(str::to_string),
                up,
                ..Default::default()
            },
            &caps(),
            &Limits::default(),
            1,
        )
    };
    // Canonical (the default) keeps no frame.
    assert_eq!(run(None, None, points.clone()).unwrap().frame, None);
    let spec = run(Some("auto"), Some([0.0, 1.0, 0.0]), points.clone()).unwrap();
    let f = spec.frame.expect("estimated at submission");
    let err = crate::eval::real::frame::frame_error(&m, &f);
    assert!(err.yaw_deg < 10.0, "{err:?}");
    // The scale is the canonical scan's: the same as for the unmoved scan.
    let canonical = PointsInput::Triples(
        scan.points
            .iter()
            .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64])
            .collect(),
    );
    let s0 = run(None, None, canonical).unwrap().scale.unwrap();
    assert!(
        (spec.scale.unwrap() - s0).abs() < 0.05 * s0,
        "{:?} vs {s0}",
        spec.scale
    );
    // Refusals name the field, the limit and the value.
    let e = run(Some("auto"), Some([0.0, 0.0, 0.0]), points.clone()).unwrap_err();
    assert_eq!(e.field, "up");
    assert!(
        e.limit.contains("non-zero") && e.value.contains("0,0,0"),
        "{e:?}"
    );
    let e = run(Some("auto"), Some([f64::NAN, 1.0, 0.0]), points.clone()).unwrap_err();
    assert_eq!(e.field, "up");
    let e = run(None, Some([0.0, 1.0, 0.0]), points.clone()).unwrap_err();
    assert_eq!(
        (e.field.as_str(), e.limit.as_str()),
        ("up", "given only with frame \"auto\"")
    );
    let e = run(Some("sideways"), None, points).unwrap_err();
    assert_eq!(e.field, "frame");
    // A flat scan (all at one height) cannot be stood on a floor.
    let flat = PointsInput::Triples(
        (0..200)
            .map(|i| [(i % 20) as f64 * 0.02, (i / 20) as f64 * 0.02, 0.3])
            .collect(),
    );
    let e = run(Some("auto"), None, flat).unwrap_err();
    assert!(
        e.field == "points" && e.limit.contains("frame canonical"),
        "{e:?}"
    );
}

#[test]
fn every_violation_is_listed() {
    // Seven defects in one request: all are reported, in field order, and nothing about the
    // fields that depend on a rejected one (preview_every on steps).
    let input = JobInput {
        points: Some(cloud(3)),
        category: Some("Spaceship".into()),
        w_pc: Some(-1.0),
        steps: Some(5000),
        n_g: Some(4000),
        preview_every: Some(4000),
        resolution: Some(1),
        sampler: Some("ddpm".into()),
        eta: Some(0.5),
        ..JobInput::default()
    };
    let all = super::validate(&input, &caps(), &Limits::default(), 0).unwrap_err();
    let fields: Vec<&str> = all.iter().map(|v| v.field.as_str()).collect();
    assert_eq!(
        fields,
        [
            "points",
            "category",
            "w_pc",
            "eta",
            "steps",
            "n_g",
            "resolution"
        ],
        "{all}"
    );
    assert_eq!(all.first().field, "points");
    assert!(all.to_string().contains("invalid resolution"), "{all}");
}

#[test]
fn a_field_the_transport_refused_is_listed_once() {
    // The transport took `steps` (a string) and `points_ply_base64` (not base64) out: each is
    // listed as refused, not again as missing or defaulted; the rest is still checked.
    let refused = |field: &str| Violation {
        field: field.into(),
        limit: "u32".into(),
        value: "string \"many\"".into(),
    };
    let input = JobInput {
        points: None,
        samples: Some(0),
        refused: vec![refused("steps"), refused("points_ply_base64")],
        ..JobInput::default()
    };
    let all = super::validate(&input, &caps(), &Limits::default(), 0).unwrap_err();
    let fields: Vec<&str> = all.iter().map(|v| v.field.as_str()).collect();
    assert_eq!(fields, ["steps", "points_ply_base64", "samples"], "{all}");
}
