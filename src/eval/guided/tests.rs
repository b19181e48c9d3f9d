//! Tests of `guided`.

use super::*;
use crate::engine::guidance::BoxField;
use crate::graph::node_ch;
use crate::mesh::primitives;

fn part(g: &mut GraphTensor, i: usize, b: [f32; 3], t: [f32; 3]) {
    let kappa = 2.0 * (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
    let row = g.node_mut(i);
    row[node_ch::EXIST] = 1.0;
    row[node_ch::BOX..node_ch::BOX + 3].copy_from_slice(&b);
    row[node_ch::CENTER..node_ch::CENTER + 3].copy_from_slice(&t);
    for k in 0..3 {
        row[node_ch::LATENT + k] = b[k] / kappa;
    }
}

#[test]
fn metrics_of_exact_boxes() {
    let field = BoxField { latent: 8 };
    let mut g = GraphTensor::empty();
    part(&mut g, 0, [0.5, 0.5, 0.5], [0.0, 0.0, 0.0]);
    part(&mut g, 1, [0.3, 0.3, 0.3], [0.7, 0.0, 0.0]); // overlaps part 0 by 0.1 in x
    // A weak third slot does not count.
    g.node_mut(2)[node_ch::EXIST] = 0.3;
    let pts: Vec<[f32; 3]> = vec![[0.0, 0.0, 0.6], [0.0, 0.0, 0.5], [1.0, 0.0, 0.0]];
    let m = sdf_metrics(&field, &g, &pts);
    // 0.1² for the first point, 0 for the others.
    assert!((m.e_pc - 0.01 / 3.0).abs() < 1e-5, "E_pc {}", m.e_pc);
    assert!(m.e_pen > 0.0, "overlap: E_pen {}", m.e_pen);
    // The MST joins the two slots through the row's default "no edge" values (zero ranges):
    // every state is the rest state, so E_mob (one ordering × 2, mean over states) is the
    // same integral over the same box as E_pen.
    assert!(
        (m.e_mob - m.e_pen).abs() < 1e-4 * m.e_pen,
        "E_mob {} vs E_pen {}",
        m.e_mob,
        m.e_pen
    );
    // Apart: no penetration either way.
    let mut apart = g.clone();
    apart.node_mut(1)[node_ch::CENTER] = 1.0;
    let ma = sdf_metrics(&field, &apart, &pts);
    assert_eq!((ma.e_pen, ma.e_mob), (0.0, 0.0));
    // D_pc against the box meshes.
    let mut mesh = TriMesh {
        positions: Vec::new(),
        triangles: Vec::new(),
    };
    let cube = crate::shape::Primitive::Cuboid {
        center: nalgebra::Vector3::zeros(),
        half_extents: nalgebra::Vector3::new(0.5, 0.5, 0.5),
    };
    primitives::append_primitive(&mut mesh, &cube, &nalgebra::Vector3::zeros());
    let meshes = vec![mesh];
    let d = d_pc(&meshes, &[[0.0, 0.0, 0.6], [0.0, 0.0, 0.5]]);
    assert!((d - 0.05).abs() < 1e-6, "D_pc {d}");
    assert!(d_pc(&[], &pts).is_nan());
    assert_eq!(median(&[3.0, f64::NAN, 1.0, 2.0]), 2.0);
    assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
    // Mean and share see the rare overlaps a median of 0 hides.
    let pen = [0.0, 0.0, 0.0, 8.0, f64::NAN];
    assert_eq!(median(&pen), 0.0);
    assert_eq!(mean(&pen), 2.0);
    assert_eq!(positive_share(&pen), 0.25);
    assert!(mean(&[]).is_nan() && positive_share(&[f64::NAN]).is_nan());
}

#[test]
fn mesh_overlap_measures_buried_surface_at_rest_and_in_motion() {
    use crate::object::{Joint, JointKind, Part};
    use crate::shape::PartShape;
    use nalgebra::Vector3;
    let meshes_of = |obj: &ArticulatedObject| -> Vec<TriMesh> {
        obj.parts
            .iter()
            .map(|p| primitives::part_primitive_mesh(p).expect("primitive part"))
            .collect()
    };
    // Two unit cubes, the second 0.3 deep in the first, sliding out along x by 0.6 over
    // its range. At f = 0 and 1/4 one face of each lies inside the other (area 0.99² each
    // beyond δ = 5 mm of the shared side faces) out of 12; at f = 1/2 they touch; then
    // apart. Mean over the 5 states: 2 · 2 · 0.99² / 12 / 5.
    let cube = |name: &str, x: f64| Part {
        name: name.into(),
        half_extents: Vector3::new(0.5, 0.5, 0.5),
        center: Vector3::new(x, 0.0, 0.0),
        shape: PartShape::Box,
    };
    let slide = ArticulatedObject {
        name: "cubes".into(),
        category: None,
        parts: vec![cube("a", 0.0), cube("b", 0.7)],
        joints: vec![Joint {
            parent: 0,
            child: 1,
            kind: JointKind::Prismatic,
            axis: Vector3::x(),
            origin: nalgebra::Point3::origin(),
            revolute: [0.0, 0.0],
            prismatic: [0.0, 0.6],
        }],
    };
    slide.validate().unwrap();
    let expected = 4.0 * 0.99f64.powi(2) / 12.0 / 5.0;
    let o = mesh_overlap(&slide, &meshes_of(&slide), 4096, 3);
    assert!((o - expected).abs() < 0.01, "O_mesh {o} vs {expected}");
    // Seeded: the same call gives the same value.
    assert_eq!(o, mesh_overlap(&slide, &meshes_of(&slide), 4096, 3));
    // The example cabinet never interpenetrates, at rest or moving.
    let cabinet = crate::fixtures::cabinet();
    assert_eq!(mesh_overlap(&cabinet, &meshes_of(&cabinet), 512, 1), 0.0);
    // Its door swinging inwards instead hits the back panel, though it is clear at rest.
    let mut inward = cabinet.clone();
    let door = inward.joints.iter_mut().find(|j| j.child == 1).unwrap();
    door.revolute = [-1.9, 0.0];
    let o = mesh_overlap(&inward, &meshes_of(&inward), 512, 1);
    assert!(o > 0.0, "inward door: O_mesh {o}");
    let rest_only = ArticulatedObject {
        joints: inward
            .joints
            .iter()
            .map(|j| Joint {
                revolute: [0.0, 0.0],
                prismatic: [0.0, 0.0],
                ..j.clone()
            })
            .collect(),
        ..inward.clone()
    };
    assert_eq!(
        mesh_overlap(&rest_only, &meshes_of(&rest_only), 512, 1),
        0.0
    );
    // Meshes that do not match the parts, or no area at all: no value.
    assert!(mesh_overlap(&slide, &meshes_of(&slide)[..1], 64, 0).is_nan());
    let empty = vec![TriMesh::default(), TriMesh::default()];
    assert!(mesh_overlap(&slide, &empty, 64, 0).is_nan());
}

#[test]
fn the_table_has_the_paper_layout_and_counts_every_sample() {
    use crate::model::denoiser::DenoiserConfig;
    use crate::model::shape_prior::{ShapeDecoder, ShapePriorConfig};
    let dev = crate::model::cpu();
    let denoiser = Denoiser::new(
        &DenoiserConfig {
            width: 16,
            layers: 1,
            head_channels: 8,
            node_head_hidden: vec![16],
            edge_head_hidden: vec![16],
            categories: 3,
            ..DenoiserConfig::default()
        },
        &dev,
    )
    .unwrap();
    let shape = ShapeDecoder::new(
        &ShapePriorConfig {
            decoder_hidden: 16,
            decoder_blocks: 1,
            ..ShapePriorConfig::default()
        },
        &mut crate::data::rng::Rng::new(0),
        &dev,
    );
    let decoder = LatentSdfDecoder::new(&shape);
    let table = |clouds: &[Cloud], opts: &TableOptions| {
        guided_table(
            &denoiser,
            &decoder,
            None,
            &FeatureScales::default(),
            &Schedule::default(),
            clouds,
            opts,
            &mut |_, _| {},
        )
    };
    let clouds = vec![Cloud {
        id: "c0".into(),
        category: Some(1),
        points: vec![[0.0, 0.0, 0.5], [0.2, 0.1, 0.3], [-0.1, 0.2, 0.8]],
    }];
    let opts = TableOptions {
        samples_per_cloud: 1,
        seed: 0,
        first_cloud: 0,
        category_aware: vec![false, true],
        variants: Vec::new(),
        guided_steps: 1000,
        tau: 1000.0,
        loss_scales: [1.0; 3],
        max_step: Some(0.05),
        refine_steps: 0,
        refine_physics_steps: 0,
        sampler: Sampler::Ddim { eta: 0.0 },
        steps: 4,
        meshing: MeshingOptions { resolution: 8 },
        references: Vec::new(),
        scanned: Vec::new(),
        id: IdOptions::default(),
        retrieval: Retrieval::Off,
        category_guidance: None,
        category_guidance_below: None,
        joint_motion: JointMotion::Screw,
    };
    let mut calls = 0;
    let rows = guided_table(
        &denoiser,
        &decoder,
        None,
        &FeatureScales::default(),
        &Schedule::default(),
        &clouds,
        &opts,
        &mut |done, total| {
            calls += 1;
            assert_eq!((done, total), (calls, 10));
        },
    )
    .unwrap();
    let labels: Vec<(bool, &str)> = rows
        .iter()
        .map(|r| (r.category_aware, r.variant.as_str()))
        .collect();
    let names: Vec<&str> = VARIANTS.iter().map(|v| v.name).collect();
    let want: Vec<(bool, &str)> = [false, true]
        .iter()
        .flat_map(|&a| names.iter().map(move |&n| (a, n)))
        .collect();
    assert_eq!(labels, want);
    // Unset, the category guidance is each row's default: none under loss guidance, w = 2
    // below t = 500 for the unguided row; category-unaware rows have none to run.
    for r in &rows {
        let want = match (r.category_aware, r.guidance.is_some()) {
            (false, _) => None,
            (true, true) => Some((0.0, 1000)),
            (true, false) => Some((2.0, 500)),
        };
        assert_eq!(r.category_guidance, want, "{}", r.variant);
    }
    assert!(rows.iter().all(|r| r.samples + r.diverged == 1));
    // Every sample is on record with its cloud and seed, diverged ones without metrics.
    for r in &rows {
        assert_eq!(r.per_sample.len(), 1, "{r:?}");
        let s = &r.per_sample[0];
        assert_eq!((s.cloud.as_str(), s.seed), ("c0", 0));
        assert_eq!(s.metrics.is_none(), r.diverged == 1);
        if let Some(m) = s.metrics {
            assert_eq!(m[0], r.e_pc, "a single sample is its own median");
            // O_mesh is on record and is the row's mean (NaN only without mesh area).
            assert!(
                m[4] == r.o_mesh_mean || (m[4].is_nan() && r.o_mesh_mean.is_nan()),
                "{r:?}"
            );
        }
    }
    let md = table_markdown(&rows);
    assert_eq!(md.lines().count(), 12);
    assert!(md.contains("| yes | pc+pen+mob |"), "{md}");
    assert!(md.lines().all(|l| l.matches('|').count() == 20), "{md}");
    assert!(
        md.contains("| O_mesh mean | O_mesh > 0 | ID_gt | ID_gt mean |"),
        "{md}"
    );
    // Without the scanned object there is no ID_gt.
    assert!(rows.iter().all(|r| r.id_gt.is_nan()), "{rows:?}");
    assert!(
        rows.iter()
            .flat_map(|r| &r.per_sample)
            .all(|s| s.id_gt.is_none())
    );

    // With the scanned object as the cloud's first reference, every sample with a surface
    // records its instantiation distance to it, and the row reports their median and mean.
    // A slice of the test set (first_cloud) keeps the seeds a full run gives its clouds.
    let id = IdOptions {
        states: 2,
        points: 64,
    };
    let cab = crate::fixtures::cabinet();
    let cab_meshes =
        crate::mesh::mesh_parts(&cab, None, &MeshingOptions { resolution: 16 }).unwrap();
    let gt = state_clouds(&cab, &cab_meshes, &id, 7).unwrap();
    let with_gt = TableOptions {
        category_aware: vec![false],
        variants: vec!["uncond".into()],
        samples_per_cloud: 2,
        first_cloud: 3,
        references: vec![vec![gt.clone(), gt]],
        scanned: vec![true],
        id,
        ..opts.clone()
    };
    let rows = table(&clouds, &with_gt).unwrap();
    let seeds: Vec<u64> = rows[0].per_sample.iter().map(|s| s.seed).collect();
    assert_eq!(seeds, [6, 7], "cloud 3 of a full run, 2 samples per cloud");
    let ids: Vec<f64> = rows[0].per_sample.iter().filter_map(|s| s.id_gt).collect();
    assert!(!ids.is_empty(), "{rows:?}");
    assert!(ids.iter().all(|d| d.is_finite() && *d > 0.0), "{ids:?}");
    assert_eq!(rows[0].id_gt, median(&ids));
    assert_eq!(rows[0].id_gt_mean, mean(&ids));
    // The same references, not marked as the scanned object: no ID_gt.
    let rows = table(
        &clouds,
        &TableOptions {
            scanned: vec![false],
            ..with_gt
        },
    )
    .unwrap();
    assert!(rows[0].per_sample.iter().all(|s| s.id_gt.is_none()));
    assert!(rows[0].id_gt.is_nan());
    // A cloud without a category: the category-aware block is left out.
    let anon = vec![Cloud {
        category: None,
        ..clouds[0].clone()
    }];
    let rows = table(
        &anon,
        &TableOptions {
            category_aware: vec![true],
            ..opts.clone()
        },
    )
    .unwrap();
    assert!(rows.is_empty());
    // A subset of the variants, in the table's order; an unknown name is refused.
    let rows = table(
        &clouds,
        &TableOptions {
            category_aware: vec![false],
            variants: vec!["uncond".into(), "pc".into()],
            ..opts.clone()
        },
    )
    .unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r.variant.as_str()).collect();
    assert_eq!(names, ["pc", "uncond"]);
    let err = table(
        &clouds,
        &TableOptions {
            variants: vec!["pc+penn".into()],
            ..opts.clone()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("variants") && err.contains("pc+penn"), "{err}");
    // Loss scales multiply the paper's weights of every guided row; a bad one is refused
    // naming the term, the limit and the value.
    let scaled = TableOptions {
        loss_scales: [1.0, 3.0, 0.5],
        ..opts.clone()
    };
    let specs = table_rows(&scaled).unwrap();
    let full = specs.iter().find(|s| s.label == "pc+pen+mob").unwrap();
    let g = full.guidance.unwrap();
    assert_eq!((g.w_pc, g.w_pen, g.w_mob), (15.0, 2.0, 1.0 / 3.0));
    let pc = specs.iter().find(|s| s.label == "pc").unwrap();
    assert_eq!(pc.guidance.unwrap().w_pc, 45.0);
    assert!(
        specs.iter().any(|s| s.guidance.is_none()),
        "uncond stays unguided"
    );
    let err = table_rows(&TableOptions {
        loss_scales: [1.0, -2.0, 1.0],
        ..opts.clone()
    })
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("loss_scales.pen") && err.contains("[0, 100]") && err.contains("-2"),
        "{err}"
    );

    // A sweep: the baseline plus every (n_g, weight) point, each run with its own guidance.
    let specs = sweep_rows(
        SweepKind::Pen,
        &[false],
        &[2, 1000],
        &[0.5, 4.0],
        &[],
        500,
        1000.0,
    )
    .unwrap();
    let rows = run_rows(
        &denoiser,
        &decoder,
        None,
        &FeatureScales::default(),
        &Schedule::default(),
        &clouds,
        &opts,
        &specs,
        &mut |_, _| {},
    )
    .unwrap();
    assert_eq!(rows.len(), 5);
    assert_eq!(rows[0].guidance, None);
    assert_eq!(rows[4].variant, "pen n_g=1000 w=8");
    let g = rows[4].guidance.unwrap();
    assert_eq!((g.w_pc, g.w_pen, g.w_mob, g.steps), (0.0, 8.0, 0.0, 1000));
    assert!(rows.iter().all(|r| r.samples + r.diverged == 1));
}

#[test]
fn sweeps_cover_the_grid_and_refuse_bad_values() {
    let rows = sweep_rows(
        SweepKind::Pc,
        &[false, true],
        &[100, 500],
        &[0.1, 1.0, 10.0],
        &[],
        500,
        1000.0,
    )
    .unwrap();
    assert_eq!(rows.len(), 2 * (1 + 2 * 3));
    assert!(rows[..7].iter().all(|r| !r.category_aware));
    let w: Vec<f64> = rows[1..4]
        .iter()
        .map(|r| r.guidance.unwrap().w_pc)
        .collect();
    assert!((w[0] - 4.5).abs() < 1e-12 && w[1] == 45.0 && (w[2] - 450.0).abs() < 1e-9);
    assert_eq!(rows[1].label, "pc n_g=100 w=4.5");
    assert_eq!(short(0.3 * 45.0), "13.5");
    let tau = sweep_rows(
        SweepKind::Tau,
        &[false],
        &[],
        &[],
        &[100.0, 1000.0],
        500,
        1.0,
    )
    .unwrap();
    let t: Vec<(f64, f64, usize)> = tau[1..]
        .iter()
        .map(|r| r.guidance.map(|g| (g.tau, g.w_pc, g.steps)).unwrap())
        .collect();
    assert_eq!(t, [(100.0, 45.0, 500), (1000.0, 45.0, 500)]);
    let e = sweep_rows(SweepKind::Mob, &[false], &[500], &[0.0], &[], 500, 1.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("sweep_weights") && e.contains('0'), "{e}");
    let e = SweepKind::parse("penn").unwrap_err().to_string();
    assert!(
        e.contains("sweep") && e.contains("penn") && e.contains("tau"),
        "{e}"
    );
}

#[test]
fn per_cloud_generative_metrics_see_which_set_matches_the_references() {
    use crate::mesh::mesh_parts;
    // 256 points: resampling noise (≈ 0.015 here) well under half the cabinet-for-eight-part
    // mismatch (≈ 0.04).
    let id = IdOptions {
        states: 2,
        points: 256,
    };
    let prepared = |obj: &crate::object::ArticulatedObject, seed: u64| {
        let m = mesh_parts(obj, None, &MeshingOptions { resolution: 16 }).unwrap();
        state_clouds(obj, &m, &id, seed).unwrap()
    };
    let cab = crate::fixtures::cabinet();
    let eight = crate::fixtures::eight_part();
    let refs = vec![prepared(&cab, 1), prepared(&eight, 2)];
    // Re-sampled copies of the references match them far better than two cabinets do.
    let good = vec![prepared(&cab, 3), prepared(&eight, 4)];
    let poor = vec![prepared(&cab, 5), prepared(&cab, 6)];
    let g = cloud_metrics(&good, &refs).unwrap().unwrap();
    let p = cloud_metrics(&poor, &refs).unwrap().unwrap();
    assert!(g.mmd < p.mmd / 2.0, "good {g:?} vs poor {p:?}");
    assert!(g.cov > p.cov, "good {g:?} vs poor {p:?}");
    assert!(g.one_nna < p.one_nna, "good {g:?} vs poor {p:?}");
    // Fewer than two objects on a side: no metric rather than a misleading one.
    assert!(cloud_metrics(&good[..1], &refs).unwrap().is_none());
    assert!(cloud_metrics(&good, &[]).unwrap().is_none());
}
