use nalgebra::{Point3, Vector3};

use super::*;
use crate::object::Joint;

use crate::fixtures::box_part as part;

/// A 0.6 × 0.8 × 1.0 m body with one child at `child` (centre, half-extents) on a joint of
/// `kind` about `axis` through `origin`.
fn two_parts(
    child: ([f64; 3], [f64; 3]),
    kind: JointKind,
    axis: [f64; 3],
    origin: [f64; 3],
) -> ArticulatedObject {
    let (revolute, prismatic) = match kind {
        JointKind::Prismatic => ([0.0, 0.0], [0.0, 0.3]),
        _ => ([0.0, 1.5], [0.0, 0.0]),
    };
    ArticulatedObject {
        name: "t".into(),
        category: None,
        parts: vec![
            part("body", [0.0, 0.0, 0.5], [0.3, 0.4, 0.5]),
            part("child", child.0, child.1),
        ],
        joints: vec![Joint {
            parent: 0,
            child: 1,
            kind,
            axis: Vector3::from(axis).normalize(),
            origin: Point3::from(origin),
            revolute,
            prismatic,
        }],
    }
}

/// A door on the body's front (−x) face, 0.02 thick.
const DOOR: ([f64; 3], [f64; 3]) = ([-0.31, 0.0, 0.5], [0.01, 0.4, 0.5]);

fn rules(r: &[Repair]) -> Vec<RepairRule> {
    r.iter().map(|r| r.rule).collect()
}

#[test]
fn a_door_hinge_moves_onto_its_nearest_edge() {
    // Predicted line 0.15 m beyond the door's left edge (y = −0.4), parallel to z.
    let mut o = two_parts(
        DOOR,
        JointKind::Revolute,
        [0.0, 0.0, 1.0],
        [-0.3, -0.55, 0.7],
    );
    let r = repair(&mut o);
    assert_eq!(rules(&r), vec![RepairRule::PivotEdge]);
    let p = o.joints[0].origin;
    // The nearest of the four z edges is the door's back-left one (x = −0.30, y = −0.4).
    assert!(
        (p.y + 0.4).abs() < 1e-12 && (p.x + 0.3).abs() < 1e-12,
        "{p}"
    );
    assert!(
        (p.z - 0.7).abs() < 1e-12,
        "the point along the axis is kept"
    );
    assert!((r[0].amount - 0.15).abs() < 1e-12);
    // From in front of the door, its front-left edge.
    let mut o = two_parts(
        DOOR,
        JointKind::Revolute,
        [0.0, 0.0, 1.0],
        [-0.4, -0.5, 0.7],
    );
    repair(&mut o);
    let p = o.joints[0].origin;
    assert!(
        (p.y + 0.4).abs() < 1e-12 && (p.x + 0.32).abs() < 1e-12,
        "{p}"
    );
}

#[test]
fn a_knob_axis_stays_on_its_centre_line() {
    // A knob on the front face turning about x, predicted 1 cm off its centre.
    let knob = ([-0.33, 0.1, 0.6], [0.03, 0.03, 0.03]);
    let mut o = two_parts(
        knob,
        JointKind::Revolute,
        [1.0, 0.0, 0.0],
        [-0.33, 0.11, 0.6],
    );
    let r = repair(&mut o);
    assert_eq!(rules(&r), vec![RepairRule::PivotCentre]);
    let p = o.joints[0].origin;
    assert!(
        (p.y - 0.1).abs() < 1e-12 && (p.z - 0.6).abs() < 1e-12,
        "{p}"
    );
    // Already on its centre line: nothing to do.
    let mut o = two_parts(knob, JointKind::Revolute, [1.0, 0.0, 0.0], [-0.3, 0.1, 0.6]);
    assert!(repair(&mut o).is_empty());
}

#[test]
fn a_9_degree_axis_snaps_and_a_20_degree_axis_stays() {
    let tilt = |deg: f64| {
        let a = deg.to_radians();
        [a.sin(), 0.0, a.cos()]
    };
    let mut o = two_parts(DOOR, JointKind::Revolute, tilt(9.0), [-0.32, -0.4, 0.5]);
    let r = repair(&mut o);
    assert_eq!(rules(&r), vec![RepairRule::SnapAxis]);
    assert!((r[0].amount - 9.0).abs() < 1e-9);
    assert_eq!(o.joints[0].axis, Vector3::new(0.0, 0.0, 1.0));
    let mut o = two_parts(DOOR, JointKind::Revolute, tilt(20.0), [-0.32, -0.4, 0.5]);
    let before = o.joints[0].clone();
    assert!(repair(&mut o).is_empty());
    assert_eq!(
        o.joints[0], before,
        "a 20°-off axis and its pivot are left alone"
    );
}

#[test]
fn a_slide_runs_along_a_box_axis_whatever_its_angle() {
    let drawer = ([-0.1, 0.0, 0.3], [0.25, 0.35, 0.1]);
    let a = 25f64.to_radians();
    let mut o = two_parts(
        drawer,
        JointKind::Prismatic,
        [-a.cos(), a.sin(), 0.0],
        [-0.1, 0.0, 0.3],
    );
    let r = repair(&mut o);
    assert_eq!(rules(&r), vec![RepairRule::SlideAxis]);
    assert_eq!(o.joints[0].axis, Vector3::new(-1.0, 0.0, 0.0));
}

#[test]
fn a_floating_lid_is_moved_down_onto_its_base_with_its_subtree() {
    // A lid `gap` above the body (diagonal ≈ 1.4 m), with a knob of its own.
    let lid = |gap: f64| {
        let mut o = two_parts(
            ([0.0, 0.0, 1.05 + gap], [0.3, 0.4, 0.05]),
            JointKind::Revolute,
            [0.0, 1.0, 0.0],
            [0.3, 0.0, 1.0 + gap],
        );
        o.parts
            .push(part("knob", [0.0, 0.0, 1.12 + gap], [0.02, 0.02, 0.02]));
        o.joints.push(Joint {
            parent: 1,
            child: 2,
            kind: JointKind::Revolute,
            axis: Vector3::z(),
            origin: Point3::new(0.0, 0.0, 1.12 + gap),
            revolute: [0.0, 1.0],
            prismatic: [0.0, 0.0],
        });
        o
    };
    // 0.1 m: more than 1 % of the diagonal, less than 10 %.
    let mut o = lid(0.1);
    let r = repair(&mut o);
    assert_eq!(r[0].rule, RepairRule::Attach);
    assert!((r[0].amount - 0.1).abs() < 1e-12, "{r:?}");
    assert!((o.parts[1].center.z - 1.05).abs() < 1e-12);
    assert!(
        (o.parts[2].center.z - 1.12).abs() < 1e-12,
        "the knob moves with the lid"
    );
    assert!((o.joints[1].origin.z - 1.12).abs() < 1e-12);
    // The lid's hinge went onto its back top... nearest edge (x = 0.3, z = 1.0 or 1.1).
    assert!((o.joints[0].origin.x - 0.3).abs() < 1e-12);
    o.validate().unwrap();
    // 0.3 m (more than 10 %): not a misplaced lid but a part elsewhere, left floating (the
    // part filter removes it).
    let mut o = lid(0.3);
    assert!(repair(&mut o).iter().all(|r| r.rule != RepairRule::Attach));
    assert!((o.parts[1].center.z - 1.35).abs() < 1e-12);
    // A touching child is left where it is.
    let mut o = two_parts(
        DOOR,
        JointKind::Revolute,
        [0.0, 0.0, 1.0],
        [-0.32, -0.4, 0.5],
    );
    assert!(repair(&mut o).is_empty());
}
