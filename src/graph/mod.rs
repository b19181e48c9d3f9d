//! The articulation graph as the diffusion model sees it.
//!
//! Why it exists: NAP diffuses a fixed-size tensor, K = 8 node rows of 135 channels and
//! 28 edge rows (upper triangle, i < j) of 13 channels (method.md §1.3–§1.5). This module owns
//! that layout, the upper-triangle order, hemisphere canonicalisation, node permutation and
//! per-channel feature scaling, and the encoding of an [`ArticulatedObject`] into it.
//! [`project`] goes the other way: a raw (noisy, model-space) graph to a valid object.
//!
//! Layouts (all `f32`, row-major):
//!
//! ```text
//! node: [o | b_x b_y b_z | t_x t_y t_z | s_0 … s_127]          (135)
//! edge: [c̃_0 c̃_1 c̃_2 | l_x l_y l_z | m_x m_y m_z | r_lo r_hi | p_lo p_hi]   (13)
//! edge row of pair (i < j): idx(i, j) = i·(2K − i − 1)/2 + (j − i − 1)
//! ```
//!
//! Edge semantics: for pair (i < j) the line L = (l, m) (class 1) or (−l, −m) (class 2) is the
//! object-frame screw axis about which node j moves relative to node i. A non-edge row is
//! `[1, 0, 0]` followed by ten zeros.

pub mod project;
pub mod repair;

use crate::error::{CoreError, CoreResult};
use crate::kinematics::PluckerLine;
use crate::object::{ArticulatedObject, LATENT_DIM, MAX_PARTS};
use crate::shape::PartShape;

pub use project::{ProjectOptions, project};

/// Number of node slots.
pub const K: usize = MAX_PARTS;
/// Number of unordered node pairs, K(K−1)/2.
pub const NUM_EDGES: usize = K * (K - 1) / 2;
/// Node row width.
pub const NODE_DIM: usize = 1 + 3 + 3 + LATENT_DIM;
/// Edge row width.
pub const EDGE_DIM: usize = 3 + 6 + 2 + 2;
/// Flattened graph size, K·135 + 28·13 = 1444.
pub const FLAT_DIM: usize = K * NODE_DIM + NUM_EDGES * EDGE_DIM;

/// Node channel offsets.
pub mod node_ch {
    /// Existence o ∈ {0, 1}.
    pub const EXIST: usize = 0;
    /// Box half-extents b (3).
    pub const BOX: usize = 1;
    /// Box centre t (3).
    pub const CENTER: usize = 4;
    /// Shape latent s (128).
    pub const LATENT: usize = 7;
}

/// Edge channel offsets.
pub mod edge_ch {
    /// Class one-hot c̃ (3): no edge, edge, negated edge.
    pub const CLASS: usize = 0;
    /// Plücker direction l (3).
    pub const DIR: usize = 3;
    /// Plücker moment m (3).
    pub const MOMENT: usize = 6;
    /// Revolute range (2).
    pub const REVOLUTE: usize = 9;
    /// Prismatic range (2).
    pub const PRISMATIC: usize = 11;
}

/// Row of the unordered pair (i, j), i ≠ j, in the upper-triangle order.
pub fn edge_index(i: usize, j: usize) -> usize {
    let (i, j) = if i < j { (i, j) } else { (j, i) };
    debug_assert!(i != j && j < K);
    i * (2 * K - i - 1) / 2 + (j - i - 1)
}

/// The pair (i < j) of an edge row.
pub fn edge_pair(idx: usize) -> (usize, usize) {
    EDGE_PAIRS[idx]
}

/// All pairs (i < j) in row order.
pub const EDGE_PAIRS: [(usize, usize); NUM_EDGES] = {
    let mut out = [(0, 0); NUM_EDGES];
    let mut i = 0;
    let mut k = 0;
    while i < K {
        let mut j = i + 1;
        while j < K {
            out[k] = (i, j);
            k += 1;
            j += 1;
        }
        i += 1;
    }
    out
};

/// A graph in the NAP layout: K node rows and 28 edge rows.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphTensor {
    /// K × [`NODE_DIM`], row-major.
    pub nodes: Vec<f32>,
    /// [`NUM_EDGES`] × [`EDGE_DIM`], row-major.
    pub edges: Vec<f32>,
}

impl Default for GraphTensor {
    fn default() -> Self {
        Self::empty()
    }
}

impl GraphTensor {
    /// The empty graph: no nodes, every edge row "no edge" ([1, 0, …]).
    pub fn empty() -> Self {
        let mut edges = vec![0.0; NUM_EDGES * EDGE_DIM];
        for e in 0..NUM_EDGES {
            edges[e * EDGE_DIM + edge_ch::CLASS] = 1.0;
        }
        GraphTensor {
            nodes: vec![0.0; K * NODE_DIM],
            edges,
        }
    }

    /// Node row `i`.
    pub fn node(&self, i: usize) -> &[f32] {
        &self.nodes[i * NODE_DIM..(i + 1) * NODE_DIM]
    }

    /// Mutable node row `i`.
    pub fn node_mut(&mut self, i: usize) -> &mut [f32] {
        &mut self.nodes[i * NODE_DIM..(i + 1) * NODE_DIM]
    }

    /// Edge row `idx`.
    pub fn edge(&self, idx: usize) -> &[f32] {
        &self.edges[idx * EDGE_DIM..(idx + 1) * EDGE_DIM]
    }

    /// Mutable edge row `idx`.
    pub fn edge_mut(&mut self, idx: usize) -> &mut [f32] {
        &mut self.edges[idx * EDGE_DIM..(idx + 1) * EDGE_DIM]
    }

    /// Nodes then edges, [`FLAT_DIM`] values.
    pub fn flatten(&self) -> Vec<f32> {
        let mut v = Vec::with_capacity(FLAT_DIM);
        v.extend_from_slice(&self.nodes);
        v.extend_from_slice(&self.edges);
        v
    }

    /// Inverse of [`GraphTensor::flatten`].
    pub fn from_flat(flat: &[f32]) -> CoreResult<Self> {
        if flat.len() != FLAT_DIM {
            return Err(CoreError::invalid(
                "graph",
                format!("exactly {FLAT_DIM} values"),
                format!("{} values", flat.len()),
            ));
        }
        let (n, e) = flat.split_at(K * NODE_DIM);
        Ok(GraphTensor {
            nodes: n.to_vec(),
            edges: e.to_vec(),
        })
    }

    /// First non-finite value, as an error naming `nodes[i][c]` or `edges[e][c]`.
    pub fn check_finite(&self) -> CoreResult<()> {
        if let Some(k) = self.nodes.iter().position(|v| !v.is_finite()) {
            return Err(CoreError::invalid(
                format!("nodes[{}][{}]", k / NODE_DIM, k % NODE_DIM),
                "finite",
                self.nodes[k],
            ));
        }
        if let Some(k) = self.edges.iter().position(|v| !v.is_finite()) {
            return Err(CoreError::invalid(
                format!("edges[{}][{}]", k / EDGE_DIM, k % EDGE_DIM),
                "finite",
                self.edges[k],
            ));
        }
        Ok(())
    }

    /// Move the node in slot `s` to slot `perm[s]` (a permutation of 0..K). Edge rows follow
    /// their nodes; a pair whose order flips swaps classes 1 ↔ 2 (the chirality toggle of
    /// method.md §1.4 step 4), so the decoded object is unchanged.
    pub fn permuted(&self, perm: &[usize; K]) -> CoreResult<Self> {
        let mut seen = [false; K];
        for (s, &p) in perm.iter().enumerate() {
            if p >= K || seen[p] {
                return Err(CoreError::invalid(
                    format!("perm[{s}]"),
                    format!("a permutation of 0..{K}"),
                    p,
                ));
            }
            seen[p] = true;
        }
        let mut out = GraphTensor::empty();
        for (s, &p) in perm.iter().enumerate() {
            out.node_mut(p).copy_from_slice(self.node(s));
        }
        for (idx, &(i, j)) in EDGE_PAIRS.iter().enumerate() {
            let (a, b) = (perm[i], perm[j]);
            let dst = out.edge_mut(edge_index(a, b));
            dst.copy_from_slice(self.edge(idx));
            if a > b {
                dst.swap(edge_ch::CLASS + 1, edge_ch::CLASS + 2);
            }
        }
        Ok(out)
    }

    /// Divide channel-wise by `scales` (raw → model space).
    pub fn scaled(&self, scales: &FeatureScales) -> Self {
        self.map_channels(scales, |v, s| v / s)
    }

    /// Multiply channel-wise by `scales` (model → raw space).
    pub fn unscaled(&self, scales: &FeatureScales) -> Self {
        self.map_channels(scales, |v, s| v * s)
    }

    fn map_channels(&self, scales: &FeatureScales, f: impl Fn(f32, f32) -> f32) -> Self {
        let nodes = self
            .nodes
            .iter()
            .enumerate()
            .map(|(k, v)| f(*v, scales.node[k % NODE_DIM]))
            .collect();
        let edges = self
            .edges
            .iter()
            .enumerate()
            .map(|(k, v)| f(*v, scales.edge[k % EDGE_DIM]))
            .collect();
        GraphTensor { nodes, edges }
    }
}

/// Per-channel feature scales (method.md §1.7): model value = raw value / scale.
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureScales {
    /// [`NODE_DIM`] node scales (existence: 1).
    pub node: Vec<f32>,
    /// [`EDGE_DIM`] edge scales (class channels: 1).
    pub edge: Vec<f32>,
}

impl Default for FeatureScales {
    /// All ones: model space = raw space.
    fn default() -> Self {
        FeatureScales {
            node: vec![1.0; NODE_DIM],
            edge: vec![1.0; EDGE_DIM],
        }
    }
}

impl FeatureScales {
    /// Max-abs + 1e-8 per channel over the training graphs (existing nodes, edge rows with an
    /// edge), with latent channels taken over `codes` (NAP uses the whole codebook). Existence
    /// and class channels keep scale 1.
    pub fn fit<'a>(graphs: &[GraphTensor], codes: impl IntoIterator<Item = &'a [f32]>) -> Self {
        let mut node = vec![0.0f32; NODE_DIM];
        let mut edge = vec![0.0f32; EDGE_DIM];
        for g in graphs {
            for i in 0..K {
                let row = g.node(i);
                for c in node_ch::BOX..node_ch::LATENT {
                    node[c] = node[c].max(row[c].abs());
                }
            }
            for e in 0..NUM_EDGES {
                let row = g.edge(e);
                for c in edge_ch::DIR..EDGE_DIM {
                    edge[c] = edge[c].max(row[c].abs());
                }
            }
        }
        for code in codes {
            for (c, v) in code.iter().take(LATENT_DIM).enumerate() {
                let ch = node_ch::LATENT + c;
                node[ch] = node[ch].max(v.abs());
            }
        }
        for v in node.iter_mut().chain(edge.iter_mut()) {
            *v += 1e-8;
        }
        node[node_ch::EXIST] = 1.0;
        edge[edge_ch::CLASS..edge_ch::DIR].fill(1.0);
        FeatureScales { node, edge }
    }

    /// These scales with the box and centre channels divided by `gain`: the layout then spans
    /// `gain` times as much of model space, so the forward process takes `gain` times as much
    /// noise to bury it (see `DiffusionTrainConfig::layout_gain`). 1 leaves them unchanged.
    pub fn with_layout_gain(&self, gain: f32) -> Self {
        self.with_node_gain(node_ch::BOX..node_ch::LATENT, gain)
    }

    /// These scales with the shape-code channels divided by `gain`: the codes then span `gain`
    /// times as much of model space (see `DiffusionTrainConfig::code_gain`). 1 leaves them
    /// unchanged.
    pub fn with_code_gain(&self, gain: f32) -> Self {
        self.with_node_gain(node_ch::LATENT..node_ch::LATENT + LATENT_DIM, gain)
    }

    /// These scales with the node channels `channels` divided by `gain`.
    fn with_node_gain(&self, channels: std::ops::Range<usize>, gain: f32) -> Self {
        let mut s = self.clone();
        for v in &mut s.node[channels] {
            *v /= gain;
        }
        s
    }

    /// Check lengths and positivity.
    pub fn validate(&self) -> CoreResult<()> {
        if self.node.len() != NODE_DIM || self.edge.len() != EDGE_DIM {
            return Err(CoreError::invalid(
                "feature_scales",
                format!("{NODE_DIM} node and {EDGE_DIM} edge values"),
                format!("{} and {}", self.node.len(), self.edge.len()),
            ));
        }
        for (name, v) in [("node", &self.node), ("edge", &self.edge)] {
            if let Some(k) = v.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(CoreError::invalid(
                    format!("feature_scales.{name}[{k}]"),
                    "finite and > 0",
                    v[k],
                ));
            }
        }
        Ok(())
    }
}

/// Encode a valid object into the raw (unscaled) graph layout, part `p` in slot `slots[p]`.
///
/// Latent channels hold the part's code when its shape is [`PartShape::Latent`], zeros
/// otherwise. Joint lines are hemisphere-canonicalised and the class records the sign
/// (method.md §1.4).
pub fn encode(obj: &ArticulatedObject, slots: &[usize]) -> CoreResult<GraphTensor> {
    obj.validate()?;
    let n = obj.parts.len();
    if slots.len() != n {
        return Err(CoreError::invalid(
            "slots",
            format!("one slot per part ({n})"),
            format!("{} slots", slots.len()),
        ));
    }
    let mut used = [false; K];
    for (p, &s) in slots.iter().enumerate() {
        if s >= K || used[s] {
            return Err(CoreError::invalid(
                format!("slots[{p}]"),
                format!("distinct slots below {K}"),
                s,
            ));
        }
        used[s] = true;
    }
    let mut g = GraphTensor::empty();
    for (p, part) in obj.parts.iter().enumerate() {
        let row = g.node_mut(slots[p]);
        row[node_ch::EXIST] = 1.0;
        for a in 0..3 {
            row[node_ch::BOX + a] = part.half_extents[a] as f32;
            row[node_ch::CENTER + a] = part.center[a] as f32;
        }
        if let PartShape::Latent(code) = &part.shape {
            row[node_ch::LATENT..].copy_from_slice(code);
        }
    }
    for j in &obj.joints {
        let (a, b) = (slots[j.parent], slots[j.child]);
        let (canon, mut negated) = j.line().canonical();
        if a > b {
            negated = !negated;
        }
        let row = g.edge_mut(edge_index(a, b));
        row[edge_ch::CLASS..edge_ch::DIR].copy_from_slice(if negated {
            &[0.0, 0.0, 1.0]
        } else {
            &[0.0, 1.0, 0.0]
        });
        write_line(row, &canon);
        row[edge_ch::REVOLUTE] = j.revolute[0] as f32;
        row[edge_ch::REVOLUTE + 1] = j.revolute[1] as f32;
        row[edge_ch::PRISMATIC] = j.prismatic[0] as f32;
        row[edge_ch::PRISMATIC + 1] = j.prismatic[1] as f32;
    }
    Ok(g)
}

fn write_line(row: &mut [f32], line: &PluckerLine) {
    for a in 0..3 {
        row[edge_ch::DIR + a] = line.l[a] as f32;
        row[edge_ch::MOMENT + a] = line.m[a] as f32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upper_triangle_order_matches_nap() {
        assert_eq!(EDGE_PAIRS[0], (0, 1));
        assert_eq!(EDGE_PAIRS[6], (0, 7));
        assert_eq!(EDGE_PAIRS[7], (1, 2));
        assert_eq!(EDGE_PAIRS[27], (6, 7));
        for (k, &(i, j)) in EDGE_PAIRS.iter().enumerate() {
            assert_eq!(edge_index(i, j), k);
            assert_eq!(edge_index(j, i), k);
            assert_eq!(edge_pair(k), (i, j));
        }
        assert_eq!(FLAT_DIM, 1444);
    }
}
