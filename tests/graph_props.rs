//! Property tests of the articulation-graph core: layout round-trips, screw identities, the
//! spanning tree, Plücker projection and projection of arbitrary raw graphs.

mod common;

use common::{Rng, random_object};
use nalgebra::{Point3, Rotation3, Unit, Vector3};
use physnap::graph::project::{existing_slots, spanning_tree};
use physnap::graph::{
    EDGE_DIM, FLAT_DIM, FeatureScales, GraphTensor, K, NODE_DIM, edge_ch, edge_index, encode,
    node_ch, project,
};
use physnap::kinematics::{PluckerLine, screw_transform};
use physnap::{ArticulatedObject, JointKind};
use proptest::prelude::*;

fn gaussian_graph(seed: u64, sigma: f64) -> GraphTensor {
    let mut rng = Rng(seed);
    let flat: Vec<f32> = (0..FLAT_DIM)
        .map(|_| (sigma * rng.gauss()) as f32)
        .collect();
    GraphTensor::from_flat(&flat).unwrap()
}

fn random_perm(rng: &mut Rng) -> [usize; K] {
    let mut p: [usize; K] = std::array::from_fn(|i| i);
    for i in (1..K).rev() {
        p.swap(i, rng.below(i + 1));
    }
    p
}

fn line_strategy() -> impl Strategy<Value = (Vector3<f64>, Vector3<f64>)> {
    (
        prop::array::uniform3(-5.0f64..5.0),
        prop::array::uniform3(-5.0f64..5.0),
    )
        .prop_filter("direction must be non-degenerate", |(l, _)| {
            Vector3::from(*l).norm() > 1e-3
        })
        .prop_map(|(l, p)| {
            let line = PluckerLine::through(&Point3::from(p), &Vector3::from(l));
            (line.l, line.m)
        })
}

fn assert_iso_close(a: &nalgebra::Isometry3<f64>, b: &nalgebra::Isometry3<f64>, tol: f64) {
    let d = a.to_homogeneous() - b.to_homogeneous();
    assert!(d.abs().max() < tol, "{a} vs {b}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn flatten_round_trips(seed in any::<u64>()) {
        let g = gaussian_graph(seed, 3.0);
        let flat = g.flatten();
        prop_assert_eq!(flat.len(), FLAT_DIM);
        prop_assert_eq!(GraphTensor::from_flat(&flat).unwrap(), g);
    }

    #[test]
    fn scaling_round_trips(seed in any::<u64>()) {
        let mut rng = Rng(seed);
        let graphs: Vec<GraphTensor> = (0..4)
            .map(|_| { let n = 2 + rng.below(7); encode(&random_object(&mut rng, n), &(0..n).collect::<Vec<_>>()).unwrap() })
            .collect();
        let scales = FeatureScales::fit(&graphs, graphs.iter().flat_map(|g| (0..K).map(move |i| &g.node(i)[node_ch::LATENT..])));
        scales.validate().unwrap();
        for g in &graphs {
            let s = g.scaled(&scales);
            // Model space is within [-1, 1] on the fitting set.
            prop_assert!(s.flatten().iter().all(|v| v.abs() <= 1.0 + 1e-6));
            let back = s.unscaled(&scales);
            for (a, b) in back.flatten().iter().zip(g.flatten()) {
                prop_assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "{} vs {}", a, b);
            }
        }
    }

    #[test]
    fn permutation_matches_encoding_in_permuted_slots(seed in any::<u64>(), n in 2usize..=8) {
        let mut rng = Rng(seed);
        let obj = random_object(&mut rng, n);
        let slots: Vec<usize> = (0..n).collect();
        let perm = random_perm(&mut rng);
        let g = encode(&obj, &slots).unwrap();
        let permuted_slots: Vec<usize> = slots.iter().map(|&s| perm[s]).collect();
        prop_assert_eq!(g.permuted(&perm).unwrap(), encode(&obj, &permuted_slots).unwrap());
        // And back.
        let mut inv = [0usize; K];
        for (s, &p) in perm.iter().enumerate() { inv[p] = s; }
        prop_assert_eq!(g.permuted(&perm).unwrap().permuted(&inv).unwrap(), g);
    }

    #[test]
    fn screw_identity_at_zero((l, m) in line_strategy()) {
        let line = PluckerLine { l, m };
        assert_iso_close(&screw_transform(&line, 0.0, 0.0), &nalgebra::Isometry3::identity(), 1e-12);
    }

    #[test]
    fn pure_revolute_fixes_points_on_the_axis((l, m) in line_strategy(), theta in -7.0f64..7.0, s in -3.0f64..3.0) {
        let line = PluckerLine { l, m };
        let p = line.closest_point_to_origin() + l * s;
        let q = screw_transform(&line, theta, 0.0) * p;
        prop_assert!((q - p).norm() < 1e-9);
    }

    #[test]
    fn screws_about_one_line_compose((l, m) in line_strategy(), a in -3.0f64..3.0, b in -3.0f64..3.0, d1 in -1.0f64..1.0, d2 in -1.0f64..1.0) {
        let line = PluckerLine { l, m };
        let composed = screw_transform(&line, a, d1) * screw_transform(&line, b, d2);
        assert_iso_close(&composed, &screw_transform(&line, a + b, d1 + d2), 1e-9);
    }

    #[test]
    fn screw_through_origin_is_nalgebra_rotation(l in prop::array::uniform3(-1.0f64..1.0), theta in -7.0f64..7.0) {
        let l = Vector3::from(l);
        prop_assume!(l.norm() > 1e-3);
        let line = PluckerLine::through(&Point3::origin(), &l);
        let t = screw_transform(&line, theta, 0.0);
        let r = Rotation3::from_axis_angle(&Unit::new_normalize(l), theta);
        prop_assert!(t.translation.vector.norm() < 1e-12);
        prop_assert!((t.rotation.to_rotation_matrix().matrix() - r.matrix()).abs().max() < 1e-12);
    }

    #[test]
    fn plucker_projection_is_idempotent(l in prop::array::uniform3(-10.0f64..10.0), m in prop::array::uniform3(-10.0f64..10.0)) {
        let once = PluckerLine::project(Vector3::from(l), Vector3::from(m));
        let twice = PluckerLine::project(once.l, once.m);
        prop_assert!((once.l.norm() - 1.0).abs() < 1e-12);
        prop_assert!(once.l.dot(&once.m).abs() < 1e-9 * once.m.norm().max(1.0));
        prop_assert!((once.l - twice.l).norm() < 1e-12);
        prop_assert!((once.m - twice.m).norm() < 1e-9 * once.m.norm().max(1.0));
    }

    #[test]
    fn spanning_tree_spans_existing_nodes(seed in any::<u64>()) {
        let g = gaussian_graph(seed, 1.0);
        let slots = existing_slots(&g, 0.5);
        prop_assert!(slots.len() >= 2);
        let tree = spanning_tree(&g, &slots);
        prop_assert_eq!(tree.len(), slots.len() - 1);
        // Connected over exactly the existing slots: union-find.
        let mut comp: Vec<usize> = (0..K).collect();
        fn find(c: &mut [usize], mut x: usize) -> usize { while c[x] != x { x = c[x]; } x }
        for &(i, j) in &tree {
            prop_assert!(slots.contains(&i) && slots.contains(&j) && i < j);
            let (a, b) = (find(&mut comp, i), find(&mut comp, j));
            prop_assert!(a != b, "cycle");
            comp[a] = b;
        }
        let root = find(&mut comp, slots[0]);
        for &s in &slots { prop_assert_eq!(find(&mut comp, s), root); }
    }

    #[test]
    fn gaussian_noise_projects_to_a_valid_finite_object(seed in any::<u64>(), sigma in 0.01f64..100.0) {
        let g = gaussian_graph(seed, sigma);
        let obj = project(&g, &Default::default()).expect("finite graphs always project");
        obj.validate().unwrap();
        prop_assert!(obj.parts.len() >= 2);
        prop_assert_eq!(obj.joints.len(), obj.parts.len() - 1);
        for p in &obj.parts {
            prop_assert!(p.half_extents.iter().chain(p.center.iter()).all(|v| v.is_finite()));
        }
        for j in &obj.joints {
            prop_assert!(j.axis.iter().chain(j.origin.iter()).chain(j.revolute.iter()).chain(j.prismatic.iter()).all(|v| v.is_finite()));
            let poses = obj.part_poses(&obj.states_at(0.5));
            prop_assert!(poses.iter().all(|p| p.to_homogeneous().iter().all(|v| v.is_finite())));
        }
    }

    #[test]
    fn encode_then_project_recovers_the_object(seed in any::<u64>(), n in 2usize..=8) {
        let mut rng = Rng(seed);
        let obj = random_object(&mut rng, n);
        let mut slots: Vec<usize> = random_perm(&mut rng)[..n].to_vec();
        let g = encode(&obj, &slots).unwrap();
        let back = project(&g, &Default::default()).unwrap();
        prop_assert_eq!(back.parts.len(), n);
        // Projected parts are in slot order: map original part -> projected part.
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by_key(|&p| slots[p]);
        let mut proj_of = vec![0; n];
        for (k, &p) in order.iter().enumerate() { proj_of[p] = k; }
        slots.sort();
        for (p, part) in obj.parts.iter().enumerate() {
            let q = &back.parts[proj_of[p]];
            prop_assert!((q.center - part.center).norm() < 1e-5);
            prop_assert!((q.half_extents - part.half_extents).norm() < 1e-5);
        }
        for j in &obj.joints {
            let (a, b) = (proj_of[j.parent], proj_of[j.child]);
            let k = back.joints.iter().position(|x| (x.parent == a && x.child == b) || (x.parent == b && x.child == a));
            prop_assert!(k.is_some(), "joint {}-{} lost", j.parent, j.child);
            let x = &back.joints[k.unwrap()];
            prop_assert_eq!(x.kind, j.kind);
            let sign = if x.parent == a { 1.0 } else { -1.0 };
            prop_assert!((x.axis * sign - j.axis).norm() < 1e-5, "axis {} vs {}", x.axis, j.axis);
            let (lx, lj) = (x.line(), j.line());
            prop_assert!((lx.m * sign - lj.m).norm() < 1e-5);
            for i in 0..2 {
                prop_assert!((x.revolute[i] - j.revolute[i]).abs() < 1e-5);
                prop_assert!((x.prismatic[i] - j.prismatic[i]).abs() < 1e-5);
            }
        }
    }
}

#[test]
fn non_finite_graph_is_a_clear_error() {
    let mut g = GraphTensor::empty();
    g.node_mut(3)[node_ch::CENTER + 1] = f32::NAN;
    let e = project(&g, &Default::default()).unwrap_err().to_string();
    assert!(
        e.contains("nodes[3][5]") && e.contains("finite") && e.contains("NaN"),
        "{e}"
    );
    let mut g = GraphTensor::empty();
    g.edge_mut(edge_index(2, 5))[edge_ch::PRISMATIC] = f32::INFINITY;
    let e = project(&g, &Default::default()).unwrap_err().to_string();
    assert!(
        e.contains(&format!(
            "edges[{}][{}]",
            edge_index(2, 5),
            edge_ch::PRISMATIC
        )),
        "{e}"
    );
}

#[test]
fn wrong_flat_length_is_a_clear_error() {
    let e = GraphTensor::from_flat(&[0.0; 10]).unwrap_err().to_string();
    assert!(e.contains("1444") && e.contains("10 values"), "{e}");
    assert_eq!(NODE_DIM, 135);
    assert_eq!(EDGE_DIM, 13);
}

#[test]
fn top_two_existence_are_forced_on() {
    let mut g = GraphTensor::empty();
    g.node_mut(5)[node_ch::EXIST] = 0.2;
    g.node_mut(2)[node_ch::EXIST] = 0.1;
    g.node_mut(7)[node_ch::EXIST] = -1.0;
    assert_eq!(existing_slots(&g, 0.5), vec![2, 5]);
    g.node_mut(7)[node_ch::EXIST] = 0.9;
    g.node_mut(1)[node_ch::EXIST] = 0.6;
    assert_eq!(existing_slots(&g, 0.5), vec![1, 7]);
    g.node_mut(5)[node_ch::EXIST] = 0.7;
    assert_eq!(existing_slots(&g, 0.5), vec![1, 5, 7]);
}

#[test]
fn joint_kind_tolerance_is_documented_value() {
    assert_eq!(
        JointKind::from_ranges([0.0, 0.002], [0.0, 0.0]),
        JointKind::Fixed
    );
    assert_eq!(
        JointKind::from_ranges([0.0, 0.004], [0.0, 0.0]),
        JointKind::Revolute
    );
    assert_eq!(
        JointKind::from_ranges([0.0, 0.0], [0.0, 0.1]),
        JointKind::Prismatic
    );
    assert_eq!(
        JointKind::from_ranges([0.0, 1.0], [0.0, 0.1]),
        JointKind::Screw
    );
}

#[test]
fn projection_roots_at_the_largest_part() {
    let obj: ArticulatedObject = physnap::fixtures::eight_part();
    let slots: Vec<usize> = (0..8).rev().collect();
    let back = project(&encode(&obj, &slots).unwrap(), &Default::default()).unwrap();
    let root = back.root();
    let vmax = back.parts.iter().map(|p| p.volume()).fold(0.0, f64::max);
    assert_eq!(back.parts[root].volume(), vmax);
}

#[test]
fn dominant_motion_keeps_the_wider_range_in_its_unit_and_never_makes_a_screw() {
    use physnap::graph::ProjectOptions;
    let mut obj: ArticulatedObject = physnap::fixtures::cabinet();
    let k = obj.joints.len() - 1;
    obj.joints[k].kind = JointKind::Screw;
    obj.joints[k].revolute = [0.0, 1.0];
    obj.joints[k].prismatic = [0.0, 0.1];
    obj.validate().unwrap();
    let slots: Vec<usize> = (0..obj.parts.len()).collect();
    let g = encode(&obj, &slots).unwrap();
    let joint = |o: &ArticulatedObject| {
        let (p, c) = (obj.joints[k].parent, obj.joints[k].child);
        o.joints
            .iter()
            .find(|j| (j.parent, j.child) == (p, c) || (j.parent, j.child) == (c, p))
            .unwrap()
            .clone()
    };
    // NAP: both ranges survive, a screw.
    assert_eq!(
        joint(&project(&g, &Default::default()).unwrap()).kind,
        JointKind::Screw
    );
    let with = |units| ProjectOptions {
        dominant_motion: Some(units),
        ..Default::default()
    };
    // 1 rad / 2π = 0.16 against 0.1 m / 1 m = 0.1: the rotation wins.
    let j = joint(&project(&g, &with([std::f64::consts::TAU, 1.0])).unwrap());
    assert_eq!((j.kind, j.prismatic), (JointKind::Revolute, [0.0, 0.0]));
    assert!((j.revolute[1] - 1.0).abs() < 1e-6, "{:?}", j.revolute);
    // In units where 0.1 m is the larger motion, the slide wins.
    let j = joint(&project(&g, &with([10.0, 0.5])).unwrap());
    assert_eq!((j.kind, j.revolute), (JointKind::Prismatic, [0.0, 0.0]));
    assert!((j.prismatic[1] - 0.1).abs() < 1e-6, "{:?}", j.prismatic);
    // Noise graphs: never a screw, and the object stays valid.
    for seed in 0..20 {
        let o = project(&gaussian_graph(seed, 1.0), &with([1.0, 1.0])).unwrap();
        o.validate().unwrap();
        assert!(o.joints.iter().all(|j| j.kind != JointKind::Screw));
    }
}
