//! The weights shipped in `weights/` load (sha256 and configs checked), and sampling with them
//! is deterministic for a seed — what `physnap generate`, `physnap serve` and the README's
//! first command rely on. A copy with one flipped byte is refused.

use std::ops::ControlFlow;
use std::path::Path;

use physnap::engine::generate::{GenerateRequest, generate};
use physnap::engine::schedule::Schedule;
use physnap::io::manifest::load_models;
use physnap::mesh::MeshingOptions;
use physnap::model::shape_prior::LatentSdfDecoder;

fn weights() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("weights").leak()
}

#[test]
fn shipped_weights_load_and_sample_deterministically() {
    let dev = physnap::model::cpu();
    let models = load_models(weights(), &dev).expect("weights/ must hold loadable weights");
    assert_eq!(models.manifest.categories.len(), 46);
    assert!(models.manifest.denoiser.config.categories > 0);
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let category = models
        .manifest
        .categories
        .iter()
        .position(|c| c == "StorageFurniture");
    let run = || {
        let req = GenerateRequest {
            seed: 7,
            samples: 1,
            category,
            category_name: Some("StorageFurniture".into()),
            meshing: MeshingOptions { resolution: 16 },
            ..Default::default()
        };
        generate(
            &models.denoiser,
            &decoder,
            models.codebook.as_ref(),
            &models.manifest.feature_scales,
            &Schedule::default(),
            &req,
            &mut |_| ControlFlow::Continue(()),
        )
        .expect("sampling with the shipped weights")
    };
    let (a, b) = (run(), run());
    assert_eq!(a[0].raw, b[0].raw, "same seed, same raw graph");
    assert_eq!(
        physnap::io::object_json::to_string(&a[0].object),
        physnap::io::object_json::to_string(&b[0].object)
    );
    assert!(!a[0].object.parts.is_empty());
}

#[test]
fn a_corrupted_copy_of_the_shipped_weights_is_refused() {
    for corrupt in [
        "denoiser.safetensors",
        "shape_prior.safetensors",
        "codebook.safetensors",
    ] {
        let dir = tempfile::tempdir().unwrap();
        for f in [
            "manifest.json",
            "denoiser.safetensors",
            "shape_prior.safetensors",
            "codebook.safetensors",
        ] {
            std::fs::copy(weights().join(f), dir.path().join(f)).unwrap();
        }
        let path = dir.path().join(corrupt);
        let mut bytes = std::fs::read(&path).unwrap();
        let k = bytes.len() - 100;
        bytes[k] ^= 0x40;
        std::fs::write(&path, bytes).unwrap();
        let e = match load_models(dir.path(), &physnap::model::cpu()) {
            Ok(_) => panic!("a corrupted {corrupt} must be refused"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(corrupt) && e.contains("sha256"), "{e}");
    }
}

#[test]
fn the_shipped_codebook_retrieves_non_empty_shapes() {
    let dev = physnap::model::cpu();
    let models = load_models(weights(), &dev).unwrap();
    let codebook = models
        .codebook
        .as_ref()
        .expect("weights/ ships a retrieval codebook");
    let entry = models.manifest.codebook.as_ref().unwrap();
    assert_eq!(codebook.rows(), entry.config.rows);
    assert_eq!(codebook.latent(), models.manifest.shape_prior.config.latent);
    assert!(entry.config.rows > entry.config.candidates / 2, "{entry:?}");
    // Every row meshes non-empty at the recorded check resolution (spot check of 16 rows).
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let check = MeshingOptions {
        resolution: entry.config.check_resolution,
    };
    for i in (0..codebook.rows()).step_by(codebook.rows() / 16) {
        let code = codebook.row(i);
        let m = physnap::mesh::extract_normalised(
            physnap::shape::LatentDecoder::sdf(&decoder, code).as_ref(),
            &check,
        )
        .unwrap();
        assert!(!m.triangles.is_empty(), "codebook row {i} meshes empty");
        assert_eq!(codebook.nearest(code).unwrap().1, 0.0);
    }
}

/// Meshing decodes only near the surface (`mesh::sampling`), which is exact while the decoder's
/// slopes stay below `LIPSCHITZ_MARGIN`. On shipped codebook shapes at the default 64³ grid: every grid point has the
/// dense grid's sign, every cell the surface crosses has the dense grid's exact corner values
/// (so marching cubes returns the dense mesh), and the decoder's largest finite-difference
/// slope between neighbouring grid points stays below the margin the skipping assumes.
#[test]
fn sparse_meshing_of_shipped_shapes_equals_the_dense_grid() {
    use physnap::mesh::sampling::{
        CountingSdf, LIPSCHITZ_MARGIN, mesh_difference, sample_dense, sample_grid,
        steepest_grid_slope,
    };
    use physnap::mesh::{DEFAULT_RESOLUTION, DOMAIN_HALF};
    let dev = physnap::model::cpu();
    let models = load_models(weights(), &dev).unwrap();
    let codebook = models.codebook.as_ref().unwrap();
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let r = DEFAULT_RESOLUTION;
    let m = r + 1;
    let spacing = 2.0 * DOMAIN_HALF / r as f32;
    let coord = |i: usize| -DOMAIN_HALF + spacing * i as f32;
    let mut steepest = 0.0f32;
    let (mut evaluated, mut total) = (0usize, 0usize);
    for i in (0..codebook.rows()).step_by(codebook.rows() / 12) {
        let sdf = physnap::shape::LatentDecoder::sdf(&decoder, codebook.row(i));
        let dense = sample_dense(sdf.as_ref(), r, &coord);
        let counted = CountingSdf::new(sdf.as_ref());
        let sparse = sample_grid(&counted, r, spacing, &coord);
        evaluated += counted.evaluations();
        total += m * m * m;
        assert_eq!(
            mesh_difference(&sparse, &dense, r),
            None,
            "codebook row {i}"
        );
        steepest = steepest.max(steepest_grid_slope(&dense, m, spacing));
    }
    eprintln!(
        "steepest slope {steepest:.3}; decoded {evaluated} of {total} points ({:.1} %)",
        100.0 * evaluated as f64 / total as f64
    );
    // Finite differences between grid points under-read the field's true slope, so the margin
    // keeps 25 % above the steepest one seen.
    assert!(
        steepest * 1.25 < LIPSCHITZ_MARGIN,
        "steepest slope {steepest} leaves the margin {LIPSCHITZ_MARGIN} less than 25 % headroom"
    );
    assert!(evaluated * 2 < total, "decoded {evaluated} of {total}");
}

#[test]
fn repair_off_is_the_raw_projection_and_on_lists_what_it_changed() {
    use physnap::engine::generate::{JointMotion, RepairMode, range_units};
    use physnap::graph::{ProjectOptions, project};
    let dev = physnap::model::cpu();
    let models = load_models(weights(), &dev).unwrap();
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let scales = &models.manifest.feature_scales;
    let mut changed = 0;
    for seed in 0..4 {
        let run = |repair| {
            let req = GenerateRequest {
                seed,
                samples: 1,
                steps: 20,
                meshing: MeshingOptions { resolution: 16 },
                joint_motion: JointMotion::Dominant,
                repair,
                ..Default::default()
            };
            generate(
                &models.denoiser,
                &decoder,
                None,
                scales,
                &Schedule::default(),
                &req,
                &mut |_| ControlFlow::Continue(()),
            )
            .unwrap()
            .remove(0)
        };
        let (off, on) = (run(RepairMode::Off), run(RepairMode::On));
        assert!(off.repairs.is_empty() && off.removed.is_empty());
        // Off: exactly the projection of the raw graph.
        let projected = project(
            &off.raw,
            &ProjectOptions {
                name: "sample_000".into(),
                dominant_motion: Some(range_units(scales)),
                ..Default::default()
            },
        )
        .unwrap();
        let text = physnap::io::object_json::to_string;
        assert_eq!(text(&off.object), text(&projected));
        assert_eq!(off.raw, on.raw, "repair does not touch sampling");
        if on.repairs.is_empty() && on.removed.is_empty() {
            assert_eq!(text(&on.object), text(&off.object));
        } else {
            changed += 1;
            assert_ne!(text(&on.object), text(&off.object));
            assert_eq!(
                on.object.parts.len() + on.removed.len(),
                off.object.parts.len()
            );
            on.object.validate().unwrap();
        }
    }
    assert!(changed > 0, "no sample of 4 needed a repair");
}

#[test]
fn a_scale_hypothesis_samples_in_the_scaled_frame_and_returns_the_scans() {
    let dev = physnap::model::cpu();
    let models = load_models(weights(), &dev).unwrap();
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let run = |scale| {
        let req = GenerateRequest {
            seed: 3,
            samples: 1,
            steps: 20,
            meshing: MeshingOptions { resolution: 16 },
            scale,
            ..Default::default()
        };
        generate(
            &models.denoiser,
            &decoder,
            None,
            &models.manifest.feature_scales,
            &Schedule::default(),
            &req,
            &mut |_| ControlFlow::Continue(()),
        )
    };
    let text = physnap::io::object_json::to_string;
    let plain = run(None).unwrap().remove(0);
    assert_eq!(
        text(&run(Some(1.0)).unwrap()[0].object),
        text(&plain.object)
    );
    // Unguided, the sample is the same; the object comes back divided by the scale.
    let half = run(Some(2.0)).unwrap().remove(0);
    assert_eq!(half.raw, plain.raw);
    assert_eq!(half.scale, 2.0);
    let expect = plain.object.scaled(0.5);
    for (a, b) in half.object.parts.iter().zip(&expect.parts) {
        assert!(
            (a.center - b.center).norm() < 1e-12
                && (a.half_extents - b.half_extents).norm() < 1e-12
        );
    }
    for s in [0.0, f64::NAN, 100.0] {
        let e = run(Some(s)).unwrap_err().to_string();
        assert!(e.contains("scale") && e.contains("[0.0625, 16]"), "{e}");
    }
}

/// A guided sample of a scan given in a user's frame, with that frame known exactly, is the
/// canonical scan's sample: the engine moves the scan into the canonical frame, samples there,
/// and the frame only travels to the exporters.
#[test]
fn a_scan_in_a_known_frame_gives_the_canonical_runs_sample() {
    use physnap::engine::generate::{GenerateRequest, PartShapes, generate_with};
    use physnap::engine::guidance::{GuidanceOptions, SdfField};
    use physnap::eval::real::frame::{MovedUp, exact_frame, move_of, moved};
    let dev = physnap::model::cpu();
    let models = load_models(weights(), &dev).unwrap();
    let decoder = physnap::model::shape_prior::LatentSdfDecoder::new(&models.shape_prior.decoder);
    let shapes = PartShapes {
        decoder: &decoder,
        field: Some(&decoder as &dyn SdfField),
        codebook: models.codebook.as_ref(),
    };
    let scan = physnap::pointcloud::PointCloud::read(
        std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/examples/scan_microwave.ply"
        )),
        &physnap::pointcloud::Limits {
            min_points: 1,
            max_points: 100_000,
        },
    )
    .unwrap()
    .points;
    let eye = [-0.9f32, 0.3, 0.6];
    let run = |points: Vec<[f32; 3]>, camera: [f32; 3], frame| {
        let weights = GuidanceOptions::weights_or_defaults([None, None, None], true);
        let guidance = GuidanceOptions {
            points,
            w_pc: weights[0],
            w_pen: weights[1],
            w_mob: weights[2],
            ..Default::default()
        }
        .with_cameras(vec![camera], None);
        let req = GenerateRequest {
            seed: 4,
            samples: 1,
            category: models
                .manifest
                .categories
                .iter()
                .position(|c| c == "Microwave"),
            category_name: Some("Microwave".into()),
            meshing: physnap::mesh::MeshingOptions { resolution: 16 },
            guidance: Some(guidance),
            steps: 6,
            frame,
            ..Default::default()
        };
        generate_with(
            &models.denoiser,
            &shapes,
            &models.manifest.feature_scales,
            &physnap::engine::schedule::Schedule::default(),
            &req,
            &mut |_| std::ops::ControlFlow::Continue(()),
        )
        .unwrap()
        .remove(0)
    };
    let canonical = run(scan.clone(), eye, None);
    let m = move_of("known", 2, MovedUp::Y);
    let frame = exact_frame(&m, MovedUp::Y);
    let framed = run(moved(&m, &scan), moved(&m, &[eye])[0], Some(frame));
    assert_eq!(framed.frame, frame);
    assert!(canonical.frame.is_canonical());
    let (a, b) = (&canonical.object, &framed.object);
    assert_eq!(a.parts.len(), b.parts.len());
    assert_eq!(a.joints.len(), b.joints.len());
    // The moved points come back to within float rounding (1e-6 m), so the samples agree to
    // well under a millimetre.
    for (p, q) in a.parts.iter().zip(&b.parts) {
        assert!((p.center - q.center).norm() < 1e-3, "{p:?} vs {q:?}");
        assert!(
            (p.half_extents - q.half_extents).norm() < 1e-3,
            "{p:?} vs {q:?}"
        );
    }
    for (j, k) in a.joints.iter().zip(&b.joints) {
        assert_eq!(j.kind, k.kind);
        assert!((j.axis - k.axis).norm() < 1e-3 && (j.origin - k.origin).norm() < 1e-3);
    }
}
