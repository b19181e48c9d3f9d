//! Joint repair after projection: hinges and slides that attach (real-scans.md §6).
//!
//! Why it exists: NAP's Plücker lines can land anywhere, so a projected door swings about a
//! line 10–20 cm beyond its edge, a lid floats above its base and a drawer slides 5° off its
//! box. The rules physnap's own generator enforces on its data (`data/validity.rs`) are
//! applied to every joint, parents before children:
//!
//! 1. **attach**: a child whose box is more than [`ATTACH_GAP_FRACTION`] of the object's
//!    diagonal from its parent's box, but at most [`FLOAT_GAP_FRACTION`], is moved (with
//!    everything below it) until the boxes touch; one farther away floats (the part filter,
//!    `engine::prune`, removes it when nothing hangs below it);
//! 2. **snap**: a revolute or screw axis within [`SNAP_ANGLE_DEG`] of a box axis becomes that
//!    axis; a prismatic axis always runs along the nearest box axis (a slide off its box
//!    jams);
//! 3. **pivot**: a revolute or screw axis along a box axis is moved onto the nearest of the
//!    child box's four edges parallel to it (doors, lids) or its centre line (knobs, wheels),
//!    whichever the predicted line is nearer; the point along the axis is kept.
//!
//! Every change is returned as a [`Repair`] (written to `object.json` as `repairs`), so a user
//! sees what the raw projection said. Parts are axis-aligned at rest (method.md §1.8), so the
//! box axes are the object frame's.

use nalgebra::Vector3;

use crate::object::{ArticulatedObject, JointKind};

/// A movable part must touch its parent at rest: box gap ≤ this fraction of the object's box
/// diagonal.
pub const ATTACH_GAP_FRACTION: f64 = 0.01;
/// A child farther than this fraction of the object's diagonal from its parent is not attached
/// but left floating: it is not a misplaced part of its parent, it is a part the sample put
/// elsewhere.
pub const FLOAT_GAP_FRACTION: f64 = 0.10;
/// A rotation axis within this many degrees of a box axis is snapped to it.
pub const SNAP_ANGLE_DEG: f64 = 10.0;

/// Which rule changed a joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RepairRule {
    /// The child (and its subtree) moved to touch its parent.
    Attach,
    /// A rotation axis snapped to a box axis.
    SnapAxis,
    /// A slide axis set to the nearest box axis.
    SlideAxis,
    /// The hinge line moved onto an edge of the child's box.
    PivotEdge,
    /// The hinge line moved onto the child box's centre line.
    PivotCentre,
}

impl RepairRule {
    /// Stable name (object.json).
    pub fn as_str(self) -> &'static str {
        match self {
            RepairRule::Attach => "attach",
            RepairRule::SnapAxis => "snap_axis",
            RepairRule::SlideAxis => "slide_axis",
            RepairRule::PivotEdge => "pivot_edge",
            RepairRule::PivotCentre => "pivot_centre",
        }
    }
}

/// One change the repair made.
#[derive(Debug, Clone, PartialEq)]
pub struct Repair {
    /// Name of the joint's child part (joints are named by their child in the exports).
    pub child: String,
    /// The rule.
    pub rule: RepairRule,
    /// How far the rule moved things: metres (attach, pivot) or degrees (axes).
    pub amount: f64,
    /// A human-readable line with before and after.
    pub detail: String,
}

/// The translation that makes box `child` touch box `parent` (zero where they already
/// overlap along an axis), per axis.
fn closing_shift(obj: &ArticulatedObject, parent: usize, child: usize) -> Vector3<f64> {
    let (p, c) = (&obj.parts[parent], &obj.parts[child]);
    Vector3::from_fn(|k, _| {
        let d = c.center[k] - p.center[k];
        let sep = d.abs() - (c.half_extents[k] + p.half_extents[k]);
        if sep > 0.0 { -d.signum() * sep } else { 0.0 }
    })
}

/// Move part `root` and every part below it by `shift`, with their joints' origins; returns
/// the parts moved.
pub fn translate_subtree(
    obj: &mut ArticulatedObject,
    root: usize,
    shift: Vector3<f64>,
) -> Vec<usize> {
    let moved = subtree(obj, root);
    for &p in &moved {
        obj.parts[p].center += shift;
    }
    for j in obj.joints.iter_mut().filter(|j| moved.contains(&j.child)) {
        j.origin += shift;
    }
    moved
}

/// Parts in the subtree of `root` (itself included).
fn subtree(obj: &ArticulatedObject, root: usize) -> Vec<usize> {
    let mut out = vec![root];
    let mut i = 0;
    while i < out.len() {
        let p = out[i];
        out.extend(obj.joints.iter().filter(|j| j.parent == p).map(|j| j.child));
        i += 1;
    }
    out
}

/// The box axis nearest `axis` (index) and the angle to it in degrees (sign-free).
fn nearest_box_axis(axis: &Vector3<f64>) -> (usize, f64) {
    let a = axis.normalize();
    let k = a.iamax();
    (k, a[k].abs().clamp(-1.0, 1.0).acos().to_degrees())
}

fn fmt(v: &Vector3<f64>) -> String {
    format!("[{:.4}, {:.4}, {:.4}]", v.x, v.y, v.z)
}

/// Apply the rules of the module docs to `obj` in place; returns what changed, in the order
/// applied.
pub fn repair(obj: &mut ArticulatedObject) -> Vec<Repair> {
    let mut out = Vec::new();
    let tol = ATTACH_GAP_FRACTION * obj.box_diagonal();
    let far = FLOAT_GAP_FRACTION * obj.box_diagonal();
    for ji in obj.joints_topological() {
        let (parent, child) = (obj.joints[ji].parent, obj.joints[ji].child);
        let name = obj.parts[child].name.clone();
        // 1. attach.
        let shift = closing_shift(obj, parent, child);
        if shift.norm() > tol && shift.norm() <= far {
            translate_subtree(obj, child, shift);
            out.push(Repair {
                child: name.clone(),
                rule: RepairRule::Attach,
                amount: shift.norm(),
                detail: format!(
                    "moved {} m by {} to touch {} (gap > {tol:.4} m)",
                    shift.norm(),
                    fmt(&shift),
                    obj.parts[parent].name
                ),
            });
        }
        let kind = obj.joints[ji].kind;
        if kind == JointKind::Fixed {
            continue;
        }
        // 2. snap.
        let axis = obj.joints[ji].axis;
        let (k, angle) = nearest_box_axis(&axis);
        let snap = match kind {
            JointKind::Prismatic => angle > 0.0,
            _ => angle > 0.0 && angle <= SNAP_ANGLE_DEG,
        };
        if snap {
            let mut e = Vector3::zeros();
            e[k] = axis[k].signum();
            obj.joints[ji].axis = e;
            out.push(Repair {
                child: name.clone(),
                rule: if kind == JointKind::Prismatic {
                    RepairRule::SlideAxis
                } else {
                    RepairRule::SnapAxis
                },
                amount: angle,
                detail: format!("axis {} → {} ({angle:.2}° off)", fmt(&axis), fmt(&e)),
            });
        }
        // 3. pivot, for rotations along a box axis.
        if !kind.rotates() || !(snap || angle == 0.0) {
            continue;
        }
        let c = obj.parts[child].center;
        let b = obj.parts[child].half_extents;
        let o = obj.joints[ji].origin.coords;
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        let (xi, xj) = (o[i] - c[i], o[j] - c[j]);
        let mut best = (((xi).powi(2) + (xj).powi(2)).sqrt(), 0.0, 0.0);
        for si in [-1.0, 1.0] {
            for sj in [-1.0, 1.0] {
                let d = ((xi - si * b[i]).powi(2) + (xj - sj * b[j]).powi(2)).sqrt();
                if d < best.0 {
                    best = (d, si * b[i], sj * b[j]);
                }
            }
        }
        let mut n = o;
        n[i] = c[i] + best.1;
        n[j] = c[j] + best.2;
        let moved = (n - o).norm();
        if moved > 1e-9 {
            let edge = best.1 != 0.0;
            obj.joints[ji].origin = n.into();
            out.push(Repair {
                child: name,
                rule: if edge {
                    RepairRule::PivotEdge
                } else {
                    RepairRule::PivotCentre
                },
                amount: moved,
                detail: format!(
                    "hinge point {} → {} (moved {moved:.4} m onto the child box's {})",
                    fmt(&o),
                    fmt(&n),
                    if edge { "edge" } else { "centre line" }
                ),
            });
        }
    }
    out
}

#[cfg(test)]
mod tests;
