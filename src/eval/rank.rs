//! Best-of-N: the order in which a job's or a `generate` run's samples are ranked, so the CLI and
//! the service pick the same best sample from the same scores.
//!
//! A sample's score ([`RankTerms::score`], lower is better) prefers right over covering: D_pc
//! alone rewarded samples that wrap the scan (best of 4 by D_pc changed nothing measurable), so
//! it is the sum of four dimensionless terms, each listed in `ranking.json`:
//!
//! ```text
//! score = D_pc / scan diagonal          (surfaces on the observed points)
//!       + free                          (share of the camera's free-space samples inside a part)
//!       + attach / object diagonal      (largest surface gap of a child to its parent at rest)
//!       + O_mesh                        (share of surface buried > 5 mm in another part, at rest
//!                                        and along the joints' motion)
//!       + sim depth / object diagonal   (deepest contact of the collision pieces export writes,
//!                                        at rest and along the joints: `crate::sim`)
//! ```
//!
//! A sample with no finite score (no mesh, no points) ranks last; ties keep the samples' own
//! order.

use crate::engine::free_space::{FreeSpace, extent};
use crate::export::collision::{CollisionOptions, pieces};
use crate::mesh::TriMesh;
use crate::mesh::bvh::MeshBvh;
use crate::object::ArticulatedObject;
use crate::sim::{SimOptions, SimReport, check};

/// Surface samples per child part for the attachment gap.
const ATTACH_SAMPLES: usize = 128;

/// The ranking terms of one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RankTerms {
    /// D_pc (metres).
    pub d_pc: f64,
    /// The scan's box diagonal (metres), D_pc's unit.
    pub scan_diagonal: f64,
    /// Share of free-space samples inside some part at rest (0 without a camera).
    pub free: f64,
    /// Largest gap (metres) between a child's surface and its parent's at rest.
    pub attach: f64,
    /// The object's box diagonal (metres), the gap's unit.
    pub object_diagonal: f64,
    /// O_mesh.
    pub o_mesh: f64,
    /// The native physics check of the collision pieces export writes for this sample (default
    /// collision and check options); `None` when it could not run (no parts).
    pub sim: Option<SimReport>,
}

impl RankTerms {
    /// The score of the module docs (NaN when D_pc or O_mesh is not finite).
    pub fn score(&self) -> f64 {
        let o = if self.o_mesh.is_finite() {
            self.o_mesh
        } else {
            f64::NAN
        };
        let sim = self.sim.map_or(0.0, |s| s.worst_depth());
        self.d_pc / self.scan_diagonal.max(1e-9)
            + self.free
            + self.attach / self.object_diagonal.max(1e-9)
            + o
            + sim / self.object_diagonal.max(1e-9)
    }
}

fn bvhs(meshes: &[TriMesh]) -> Vec<Option<MeshBvh>> {
    meshes
        .iter()
        .map(|m| {
            (!m.triangles.is_empty())
                .then(|| MeshBvh::new(&m.positions, &m.triangles).ok())
                .flatten()
        })
        .collect()
}

/// Share of `free`'s samples inside some part mesh (0 for an empty free space).
pub fn free_share(meshes: &[TriMesh], free: &FreeSpace) -> f64 {
    let samples = free.samples();
    if samples.is_empty() {
        return 0.0;
    }
    let bvhs = bvhs(meshes);
    let bounds: Vec<_> = meshes.iter().map(TriMesh::bounds).collect();
    let inside = samples
        .iter()
        .filter(|q| {
            bvhs.iter().zip(&bounds).any(|(b, bb)| match (b, bb) {
                (Some(b), Some((lo, hi))) => {
                    (0..3).all(|k| q[k] >= lo[k] && q[k] <= hi[k]) && b.is_inside(**q)
                }
                _ => false,
            })
        })
        .count();
    inside as f64 / samples.len() as f64
}

/// The largest gap (metres) between a joint's child surface and its parent's mesh at rest: per
/// joint the smallest distance from [`ATTACH_SAMPLES`] child surface samples to the parent.
pub fn attach_gap(obj: &ArticulatedObject, meshes: &[TriMesh]) -> f64 {
    if meshes.len() != obj.parts.len() {
        return f64::NAN;
    }
    let bvhs = bvhs(meshes);
    let mut rng = crate::data::rng::Rng::new(7);
    let mut worst = 0.0f64;
    for j in &obj.joints {
        let (Some(child), Some(parent)) = (&bvhs[j.child], &bvhs[j.parent]) else {
            continue;
        };
        let gap = child
            .sample_surface(ATTACH_SAMPLES, &mut || rng.uniform())
            .iter()
            .filter_map(|(p, _)| parent.closest_point(*p))
            .map(|(_, d2, _)| (d2 as f64).sqrt())
            .fold(f64::INFINITY, f64::min);
        if gap.is_finite() {
            worst = worst.max(gap);
        }
    }
    worst
}

/// The ranking terms of a sample, D_pc and O_mesh included (O_mesh sampled with `seed`); for
/// callers that have not computed them already.
pub fn sample_terms(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    points: &[[f32; 3]],
    cameras: &[[f32; 3]],
    seed: u64,
) -> RankTerms {
    use crate::eval::guided::{MESH_OVERLAP_SAMPLES, d_pc, mesh_overlap};
    let d = d_pc(meshes, points);
    let o = mesh_overlap(obj, meshes, MESH_OVERLAP_SAMPLES, seed);
    rank_terms(obj, meshes, points, cameras, d, o)
}

/// The ranking terms of a sample (`o_mesh` as `eval::guided::metrics` computed it).
pub fn rank_terms(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    points: &[[f32; 3]],
    cameras: &[[f32; 3]],
    d_pc: f64,
    o_mesh: f64,
) -> RankTerms {
    let free = FreeSpace::new(points, cameras);
    RankTerms {
        d_pc,
        scan_diagonal: extent(points) as f64,
        free: free_share(meshes, &free),
        attach: attach_gap(obj, meshes),
        object_diagonal: obj.box_diagonal(),
        o_mesh,
        sim: sim_report(obj, meshes),
    }
}

/// The native check of `obj` on the collision pieces export makes of `meshes` by default.
pub fn sim_report(obj: &ArticulatedObject, meshes: &[TriMesh]) -> Option<SimReport> {
    if meshes.len() != obj.parts.len() {
        return None;
    }
    let p = pieces(obj, meshes, &CollisionOptions::default());
    check(obj, &p, &SimOptions::default()).ok()
}

/// The order of `scores` from best to worst: indices into `scores`, ascending by score,
/// non-finite scores last, equal scores in index order.
pub fn rank_order(scores: &[f64]) -> Vec<usize> {
    let key = |v: f64| if v.is_finite() { v } else { f64::INFINITY };
    let mut order: Vec<usize> = (0..scores.len()).collect();
    order.sort_by(|&a, &b| key(scores[a]).total_cmp(&key(scores[b])).then(a.cmp(&b)));
    order
}

/// `items` reordered best first by `rank_order` of their scores.
pub fn ranked<T>(items: Vec<T>, score: impl Fn(&T) -> f64) -> Vec<T> {
    let scores: Vec<f64> = items.iter().map(&score).collect();
    let mut slots: Vec<Option<T>> = items.into_iter().map(Some).collect();
    rank_order(&scores)
        .into_iter()
        .map(|i| slots[i].take().expect("rank_order is a permutation"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascending_with_non_finite_last_and_ties_in_order() {
        let s = [0.3, f64::NAN, 0.1, 0.3, f64::INFINITY, 0.2];
        assert_eq!(rank_order(&s), vec![2, 5, 0, 3, 1, 4]);
        assert_eq!(
            ranked(vec!["a", "b", "c"], |x| if *x == "b" { 0.0 } else { 1.0 }),
            vec!["b", "a", "c"]
        );
        assert!(rank_order(&[]).is_empty());
    }
}
