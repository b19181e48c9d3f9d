//! Projection of a raw graph onto a valid articulated object (method.md §5.3–§5.7).
//!
//! Why it exists: the diffusion model outputs continuous values everywhere: soft existences,
//! soft edge classes, non-unit Plücker directions. Generation, export and evaluation need one
//! discrete, valid object. The steps, in order:
//!
//! 1. existence: the two highest existence values are forced on; a node exists iff o > 0.5;
//! 2. edges: maximum spanning tree over existing nodes with weights max(s_ij, 0),
//!    s_ij = max(c̃₁, c̃₂) − c̃₀, ties broken by ascending edge row (§9 A15), so the tree is
//!    deterministic and always has n − 1 edges;
//! 3. edge class 1 if c̃₁ ≥ c̃₂ else 2; the decoded line is ±(l, m) accordingly;
//! 4. Plücker projection: l ← l/‖l‖, m ← m − (l·m) l;
//! 5. ranges are sorted into [lower, upper] (a reversed interval holds the same states); with
//!    [`ProjectOptions::dominant_motion`] (physnap's, not NAP's) only the range that is wider in
//!    its unit survives — the other is zeroed — so no joint is a screw; then the joint type
//!    comes from which range is wider than [`JOINT_RANGE_TOL`], and the inactive range is
//!    zeroed;
//! 6. the root is the part with the largest box volume (method.md §6.2); tree edges are
//!    oriented away from it, negating the line when the child is the lower slot (reversal
//!    identity, see [`crate::kinematics`]);
//! 7. half-extents are |b| clamped to ≥ `min_half_extent` (§9 A8); the joint origin is the
//!    point of the axis closest to the child's box centre.
//!
//! The input is in *raw* (unscaled, object) units; unscale model outputs first.

use nalgebra::{Point3, Vector3};

use super::{EDGE_PAIRS, GraphTensor, K, edge_ch, edge_index, node_ch};
use crate::error::CoreResult;
use crate::kinematics::PluckerLine;
use crate::object::{ArticulatedObject, Joint, JointKind, Part};
use crate::shape::PartShape;

/// Knobs of the projection; the defaults are NAP's.
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectOptions {
    /// A node exists iff its existence value exceeds this (after forcing the top two).
    pub existence_threshold: f32,
    /// Smallest half-extent a part may get (metres).
    pub min_half_extent: f64,
    /// Name of the produced object.
    pub name: String,
    /// Category of the produced object.
    pub category: Option<String>,
    /// Keep one motion per joint: units `[revolute (rad), prismatic (m)]` the two range widths
    /// are divided by before comparing; the narrower range is zeroed. None: NAP, every joint a
    /// screw with both ranges. Why: the training data have no screw joints (every joint
    /// rotates, slides or is fixed), but a sample's inactive range keeps a residue of the
    /// model's noise; unscaled by the range channel's feature scale (2π for rotation) that
    /// residue is tenths of a radian, far above [`JOINT_RANGE_TOL`], so nearly every sampled
    /// joint came out a screw. Generation passes the range channels' feature scales.
    pub dominant_motion: Option<[f64; 2]>,
}

impl Default for ProjectOptions {
    fn default() -> Self {
        ProjectOptions {
            existence_threshold: 0.5,
            min_half_extent: 1e-4,
            name: "object".into(),
            category: None,
            dominant_motion: None,
        }
    }
}

/// Which slots exist: the top two existence values are forced on (ties → lower slot).
pub fn existing_slots(g: &GraphTensor, threshold: f32) -> Vec<usize> {
    let mut order: Vec<usize> = (0..K).collect();
    let o = |s: usize| g.node(s)[node_ch::EXIST];
    order.sort_by(|&a, &b| o(b).total_cmp(&o(a)).then(a.cmp(&b)));
    let mut exists = [false; K];
    for (rank, &s) in order.iter().enumerate() {
        exists[s] = rank < 2 || o(s) > threshold;
    }
    (0..K).filter(|&s| exists[s]).collect()
}

/// Maximum spanning tree over `slots` with weights max(s_ij, 0) (Kruskal, ties by row).
/// Returns the selected pairs (i < j) in selection order.
pub fn spanning_tree(g: &GraphTensor, slots: &[usize]) -> Vec<(usize, usize)> {
    let mut candidates: Vec<(f32, usize)> = Vec::new();
    for (a, &i) in slots.iter().enumerate() {
        for &j in &slots[a + 1..] {
            let idx = edge_index(i, j);
            let c = &g.edge(idx)[edge_ch::CLASS..edge_ch::DIR];
            let s = c[1].max(c[2]) - c[0];
            candidates.push((s.max(0.0), idx));
        }
    }
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut comp: [usize; K] = std::array::from_fn(|s| s);
    fn find(comp: &mut [usize; K], mut x: usize) -> usize {
        while comp[x] != x {
            comp[x] = comp[comp[x]];
            x = comp[x];
        }
        x
    }
    let mut tree = Vec::with_capacity(slots.len().saturating_sub(1));
    for (_, idx) in candidates {
        let (i, j) = EDGE_PAIRS[idx];
        let (ri, rj) = (find(&mut comp, i), find(&mut comp, j));
        if ri != rj {
            comp[ri] = rj;
            tree.push((i, j));
        }
    }
    tree
}

/// Project a raw graph onto a valid articulated object (see the module docs).
pub fn project(g: &GraphTensor, opts: &ProjectOptions) -> CoreResult<ArticulatedObject> {
    g.check_finite()?;
    let slots = existing_slots(g, opts.existence_threshold);
    let part_of = |slot: usize| slots.iter().position(|&s| s == slot).unwrap_or(usize::MAX);

    let parts: Vec<Part> = slots
        .iter()
        .enumerate()
        .map(|(p, &s)| {
            let row = g.node(s);
            let v = |c: usize| Vector3::new(row[c] as f64, row[c + 1] as f64, row[c + 2] as f64);
            Part {
                name: format!("part{p}"),
                half_extents: v(node_ch::BOX).map(|x| x.abs().max(opts.min_half_extent)),
                center: v(node_ch::CENTER),
                shape: PartShape::Latent(row[node_ch::LATENT..].to_vec()),
            }
        })
        .collect();

    let root = (0..parts.len())
        .max_by(|&a, &b| {
            parts[a]
                .volume()
                .total_cmp(&parts[b].volume())
                .then(b.cmp(&a))
        })
        .unwrap_or(0);

    // Undirected tree edges as (part i, part j, line: j moves relative to i).
    let mut undirected = Vec::new();
    for (si, sj) in spanning_tree(g, &slots) {
        let row = g.edge(edge_index(si, sj));
        let c = &row[edge_ch::CLASS..edge_ch::DIR];
        let v = |c: usize| Vector3::new(row[c] as f64, row[c + 1] as f64, row[c + 2] as f64);
        let mut line = PluckerLine::project(v(edge_ch::DIR), v(edge_ch::MOMENT));
        if c[1] < c[2] {
            line = line.reversed();
        }
        let sorted = |c: usize| {
            let (a, b) = (row[c] as f64, row[c + 1] as f64);
            [a.min(b), a.max(b)]
        };
        undirected.push((
            part_of(si),
            part_of(sj),
            line,
            sorted(edge_ch::REVOLUTE),
            sorted(edge_ch::PRISMATIC),
        ));
    }

    // Orient away from the root (breadth-first).
    let mut joints = Vec::with_capacity(undirected.len());
    let mut reached = vec![false; parts.len()];
    reached[root] = true;
    let mut queue = std::collections::VecDeque::from([root]);
    while let Some(p) = queue.pop_front() {
        for &(i, j, line, rev, pri) in &undirected {
            let (child, line) = if i == p && !reached[j] {
                (j, line)
            } else if j == p && !reached[i] {
                (i, line.reversed())
            } else {
                continue;
            };
            reached[child] = true;
            queue.push_back(child);
            let (rev, pri) = match opts.dominant_motion {
                Some([ur, up]) if (rev[1] - rev[0]) / ur >= (pri[1] - pri[0]) / up => {
                    (rev, [0.0, 0.0])
                }
                Some(_) => ([0.0, 0.0], pri),
                None => (rev, pri),
            };
            let kind = JointKind::from_ranges(rev, pri);
            let origin = line.closest_point_to(&Point3::from(parts[child].center));
            joints.push(Joint {
                parent: p,
                child,
                kind,
                axis: line.l,
                origin,
                revolute: if kind.rotates() { rev } else { [0.0, 0.0] },
                prismatic: if kind.slides() { pri } else { [0.0, 0.0] },
            });
        }
    }

    let obj = ArticulatedObject {
        name: opts.name.clone(),
        category: opts.category.clone(),
        parts,
        joints,
    };
    obj.validate()?;
    Ok(obj)
}
