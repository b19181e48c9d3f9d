//! Only parts the scan allows: the filter between meshing and export (issue "parts the scan
//! supports").
//!
//! Why it exists: the prior adds parts that nothing in the scan supports — a door in space the
//! camera looked through, a handle floating beside its drawer, a sliver too thin for marching
//! cubes. Such a part makes the object wrong *and* unsimulatable (an empty mesh has no
//! inertia; a floating part falls). A leaf part (no children; never the root) is removed when
//!
//! - **empty**: its mesh has no triangles (too small to mesh);
//! - **free space**: more than [`FREE_SHARE`] of its surface lies in space a camera saw through
//!   (`FreeSpace::seen_through`);
//! - **floating**: its surface is more than [`TOUCH_FRACTION`] of the object's diagonal from
//!   every other part's surface (it touches nothing).
//!
//! Before that, meshes attach: a child whose surface is more than [`TOUCH_FRACTION`] but at
//! most `graph::repair::FLOAT_GAP_FRACTION` of the diagonal from its parent's surface (a shape
//! that does not fill its box, so boxes touch and meshes do not) is moved with its subtree
//! until the surfaces touch, recorded as an `attach` repair. Removal then repeats until no leaf
//! qualifies (a removed leaf can make its parent a leaf). Every removal is returned as a
//! [`Removed`] (written to `ranking.json`).

use nalgebra::Vector3;

use super::free_space::FreeSpace;
use crate::graph::repair::{FLOAT_GAP_FRACTION, Repair, RepairRule, translate_subtree};
use crate::mesh::TriMesh;
use crate::mesh::bvh::MeshBvh;
use crate::object::ArticulatedObject;

/// A part with more than this share of its surface in observed free space is removed.
pub const FREE_SHARE: f64 = 0.5;
/// A part whose surface is farther than this fraction of the object's diagonal from every other
/// part's surface floats.
pub const TOUCH_FRACTION: f64 = 0.01;
/// Surface points tested per part (uniform by area, fixed seed).
const TEST_POINTS: usize = 256;

/// Why a part was removed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RemoveReason {
    /// No triangles.
    Empty,
    /// Mostly in observed free space.
    FreeSpace,
    /// Touches no other part.
    Floating,
}

impl RemoveReason {
    /// Stable name (ranking.json).
    pub fn as_str(self) -> &'static str {
        match self {
            RemoveReason::Empty => "empty",
            RemoveReason::FreeSpace => "free_space",
            RemoveReason::Floating => "floating",
        }
    }
}

/// One removed part.
#[derive(Debug, Clone, PartialEq)]
pub struct Removed {
    /// Its name.
    pub part: String,
    /// Why.
    pub reason: RemoveReason,
    /// The measured value behind the reason, in words.
    pub detail: String,
}

/// Why leaf `i` should go, if it should.
fn verdict(
    obj: &ArticulatedObject,
    bvhs: &[Option<MeshBvh>],
    i: usize,
    free: Option<&FreeSpace>,
    touch: f32,
) -> Option<(RemoveReason, String)> {
    let Some(own) = &bvhs[i] else {
        return Some((RemoveReason::Empty, "its mesh has no triangles".into()));
    };
    let pts = surface(own, i);
    if pts.is_empty() {
        return Some((RemoveReason::Empty, "its mesh has no area".into()));
    }
    if let Some(free) = free.filter(|f| !f.is_empty()) {
        let seen = pts.iter().filter(|&&p| free.seen_through(p)).count();
        let share = seen as f64 / pts.len().max(1) as f64;
        if share > FREE_SHARE {
            return Some((
                RemoveReason::FreeSpace,
                format!(
                    "{:.0} % of its surface lies where the camera saw through (limit {:.0} %)",
                    100.0 * share,
                    100.0 * FREE_SHARE
                ),
            ));
        }
    }
    let mut nearest = f32::INFINITY;
    for (j, bvh) in bvhs.iter().enumerate() {
        let Some(bvh) = bvh.as_ref().filter(|_| j != i) else {
            continue;
        };
        for &p in &pts {
            if let Some((_, d2, _)) = bvh.closest_point(p) {
                nearest = nearest.min(d2.sqrt());
            }
            if nearest <= touch {
                return None;
            }
        }
    }
    let others = bvhs.iter().enumerate().any(|(j, b)| j != i && b.is_some());
    (others && nearest > touch).then(|| {
        (
            RemoveReason::Floating,
            format!(
                "{nearest:.4} m from every other part (limit {touch:.4} m; {} parts)",
                obj.parts.len()
            ),
        )
    })
}

/// Surface samples of mesh `i` (uniform by area, fixed seed per part).
fn surface(bvh: &MeshBvh, i: usize) -> Vec<[f32; 3]> {
    let mut rng = crate::data::rng::Rng::new(0x5eed ^ i as u64);
    bvh.sample_surface(TEST_POINTS, &mut || rng.uniform())
        .into_iter()
        .map(|(p, _)| p)
        .collect()
}

/// Attach each child's mesh to its parent's (module docs), parents first.
fn attach_meshes(obj: &mut ArticulatedObject, meshes: &mut [TriMesh]) -> Vec<Repair> {
    let diag = obj.box_diagonal();
    let (touch, far) = (TOUCH_FRACTION * diag, FLOAT_GAP_FRACTION * diag);
    let mut out = Vec::new();
    for ji in obj.joints_topological() {
        let (parent, child) = (obj.joints[ji].parent, obj.joints[ji].child);
        let bvh = |m: &TriMesh| {
            (!m.triangles.is_empty())
                .then(|| MeshBvh::new(&m.positions, &m.triangles).ok())
                .flatten()
        };
        let (Some(pb), Some(cb)) = (bvh(&meshes[parent]), bvh(&meshes[child])) else {
            continue;
        };
        let nearest = surface(&cb, child)
            .into_iter()
            .filter_map(|p| pb.closest_point(p).map(|(q, d2, _)| (p, q, d2)))
            .min_by(|a, b| a.2.total_cmp(&b.2));
        let Some((p, q, d2)) = nearest else { continue };
        let gap = (d2 as f64).sqrt();
        if !(gap > touch && gap <= far) {
            continue;
        }
        let shift = Vector3::from_fn(|k, _| (q[k] - p[k]) as f64);
        for m in translate_subtree(obj, child, shift) {
            let t = shift.map(|v| v as f32);
            for v in &mut meshes[m].positions {
                *v = [v[0] + t.x, v[1] + t.y, v[2] + t.z];
            }
        }
        out.push(Repair {
            child: obj.parts[child].name.clone(),
            rule: RepairRule::Attach,
            amount: gap,
            detail: format!(
                "moved {gap:.4} m by [{:.4}, {:.4}, {:.4}] so its surface touches {}'s (surface gap > {touch:.4} m)",
                shift.x, shift.y, shift.z, obj.parts[parent].name
            ),
        });
    }
    out
}

/// Attach the meshes and remove the leaf parts the scan does not allow (module docs) from `obj`
/// and `meshes` (one mesh per part, object frame at rest); `free` is the scan's free space when
/// there is a camera. Returns the removals and the attach repairs, each in order.
pub fn prune(
    obj: &mut ArticulatedObject,
    meshes: &mut Vec<TriMesh>,
    free: Option<&FreeSpace>,
) -> (Vec<Removed>, Vec<Repair>) {
    let repairs = if meshes.len() == obj.parts.len() {
        attach_meshes(obj, meshes)
    } else {
        Vec::new()
    };
    let touch = (TOUCH_FRACTION * obj.box_diagonal()) as f32;
    let mut out = Vec::new();
    loop {
        if obj.parts.len() <= 1 || meshes.len() != obj.parts.len() {
            return (out, repairs);
        }
        let root = obj.root();
        let leaves: Vec<usize> = (0..obj.parts.len())
            .filter(|&i| i != root && !obj.joints.iter().any(|j| j.parent == i))
            .collect();
        let bvhs: Vec<Option<MeshBvh>> = meshes
            .iter()
            .map(|m| {
                (!m.triangles.is_empty())
                    .then(|| MeshBvh::new(&m.positions, &m.triangles).ok())
                    .flatten()
            })
            .collect();
        let hit = leaves
            .into_iter()
            .find_map(|i| verdict(obj, &bvhs, i, free, touch).map(|v| (i, v)));
        let Some((i, (reason, detail))) = hit else {
            return (out, repairs);
        };
        out.push(Removed {
            part: obj.parts[i].name.clone(),
            reason,
            detail,
        });
        obj.parts.remove(i);
        meshes.remove(i);
        obj.joints.retain(|j| j.child != i);
        for j in &mut obj.joints {
            if j.parent > i {
                j.parent -= 1;
            }
            if j.child > i {
                j.child -= 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitives;
    use crate::object::{Joint, JointKind};
    use nalgebra::{Point3, Vector3};

    use crate::fixtures::box_part as part;

    fn joint(child: usize) -> Joint {
        Joint {
            parent: 0,
            child,
            kind: JointKind::Revolute,
            axis: Vector3::z(),
            origin: Point3::origin(),
            revolute: [0.0, 1.0],
            prismatic: [0.0, 0.0],
        }
    }

    /// Body, a door on its −x face, and a third part at `c`.
    fn object(c: [f64; 3]) -> (ArticulatedObject, Vec<TriMesh>) {
        let obj = ArticulatedObject {
            name: "t".into(),
            category: None,
            parts: vec![
                part("body", [0.0, 0.0, 0.5], [0.3, 0.4, 0.5]),
                part("door", [-0.31, 0.0, 0.5], [0.01, 0.4, 0.5]),
                part("extra", c, [0.05, 0.05, 0.05]),
            ],
            joints: vec![joint(1), joint(2)],
        };
        let meshes = obj
            .parts
            .iter()
            .map(|p| primitives::part_primitive_mesh(p).unwrap())
            .collect();
        (obj, meshes)
    }

    #[test]
    fn a_floating_part_is_removed_and_a_touching_one_kept() {
        let (mut obj, mut meshes) = object([0.0, 0.0, 1.3]);
        let r = prune(&mut obj, &mut meshes, None).0;
        assert_eq!(r.len(), 1, "{r:?}");
        assert_eq!(
            (r[0].part.as_str(), r[0].reason),
            ("extra", RemoveReason::Floating)
        );
        assert_eq!(obj.parts.len(), 2);
        assert_eq!(meshes.len(), 2);
        obj.validate().unwrap();
        let (mut obj, mut meshes) = object([0.0, 0.0, 1.05]);
        let (removed, attached) = prune(&mut obj, &mut meshes, None);
        assert!(removed.is_empty() && attached.is_empty());
    }

    #[test]
    fn a_part_a_little_off_its_parent_is_moved_to_touch_it() {
        // 5 cm above the body (diagonal ≈ 1.6 m: more than 1 %, less than 10 %).
        let (mut obj, mut meshes) = object([0.0, 0.0, 1.1]);
        let (removed, attached) = prune(&mut obj, &mut meshes, None);
        assert!(removed.is_empty(), "{removed:?}");
        assert_eq!(attached.len(), 1);
        assert_eq!(attached[0].rule, RepairRule::Attach);
        assert!((attached[0].amount - 0.05).abs() < 1e-3, "{attached:?}");
        assert!((obj.parts[2].center.z - 1.05).abs() < 1e-3);
        let lowest = meshes[2]
            .positions
            .iter()
            .map(|p| p[2])
            .fold(f32::INFINITY, f32::min);
        assert!(
            (lowest - 1.0).abs() < 1e-3,
            "mesh moved with its part: {lowest}"
        );
    }

    #[test]
    fn a_part_between_the_camera_and_the_points_is_removed() {
        // The scan: the door's front face seen from a camera at −x; the extra part sits between
        // them, touching the door (not floating), in space the camera saw through.
        let (mut obj, mut meshes) = object([-0.37, 0.0, 0.5]);
        let scan: Vec<[f32; 3]> = (0..20)
            .flat_map(|i| {
                (0..20).map(move |j| [-0.32, -0.38 + 0.04 * i as f32, 0.02 + 0.05 * j as f32])
            })
            .collect();
        let free = FreeSpace::new(&scan, &[[-2.0, 0.0, 0.5]]);
        let r = prune(&mut obj, &mut meshes, Some(&free)).0;
        assert_eq!(r.len(), 1, "{r:?}");
        assert_eq!(r[0].reason, RemoveReason::FreeSpace);
        assert_eq!(obj.parts.len(), 2);
        // Without the camera it stays (it touches the door).
        let (mut obj, mut meshes) = object([-0.37, 0.0, 0.5]);
        assert!(prune(&mut obj, &mut meshes, None).0.is_empty());
    }
}
