//! Sampling a part SDF on the meshing grid without evaluating it far from the surface: a
//! narrow-band octree over the (r + 1)³ grid points.
//!
//! Why it exists: marching cubes only reads the *sign* of cells the surface does not cross, yet a
//! dense 64³ grid decodes ≈ 275 k points per part — about 5 s of a 30 s guided job went into
//! meshing the sample. Most of those points are far from the surface. Every point p of a block
//! of grid cells (corners c, diagonal D) lies within D/2 of some corner, so an SDF f with
//! Lipschitz constant L satisfies
//!
//! ```text
//! min_c |f(c)| > L · D/2   ⇒   f has no zero in the (closed) block, so every point in it has
//!                              the sign of its corners
//! ```
//!
//! so such a block is skipped and its points take a corner's value. Blocks that fail the test
//! are split in two along each axis, down to single cells, whose corners are decoded exactly.
//! Every cell marching cubes can put a triangle in is then a single-cell leaf with exact
//! corners, and every skipped cell has corners of one sign: the mesh equals the dense grid's
//! whenever the bound holds. A true SDF has L = 1; the learned decoder is only approximately an
//! SDF: the shipped one's (since 2026-11-28) steepest slope between neighbouring 64³ grid points
//! is 3.7 on its codebook shapes (median over shapes 1.5, 90th percentile 2.8; the decoder
//! shipped before reached 2.1), so [`LIPSCHITZ_MARGIN`] = 5, 1.35× the steepest slope seen
//! (tests/shipped_weights.rs checks both the slope and the dense grid's mesh). The margin costs
//! decodes: 41 % of the dense grid at 5, 26 % at 3 (41 shapes; `cargo run --release --example
//! bench_margin`). Non-finite corner values always refine.
//!
//! Each octree level is one batch of new points, evaluated in parallel chunks on the current
//! rayon pool (NAP's MISE, method.md §5.8, refines by sign changes instead, which can miss
//! walls thinner than a coarse cell; the distance bound cannot).

use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;

use crate::shape::Sdf;

/// Lipschitz bound assumed of the field when skipping blocks (a true SDF has 1).
pub const LIPSCHITZ_MARGIN: f32 = 5.0;

/// Points per parallel evaluation chunk.
const CHUNK: usize = 4096;

/// A block of grid cells: origin (grid point index) and extent in cells, each ≥ 1.
#[derive(Debug, Clone, Copy)]
struct Block {
    o: [usize; 3],
    e: [usize; 3],
}

/// Flat index of grid point `p` in an m³ grid (x fastest).
fn flat(m: usize, p: [usize; 3]) -> usize {
    p[0] + m * (p[1] + m * p[2])
}

impl Block {
    fn corners(&self) -> [[usize; 3]; 8] {
        std::array::from_fn(|c| std::array::from_fn(|a| self.o[a] + ((c >> a) & 1) * self.e[a]))
    }

    /// Halve every axis with more than one cell.
    fn split(&self, out: &mut Vec<Block>) {
        let halves = |a: usize| -> Vec<(usize, usize)> {
            let e = self.e[a];
            if e > 1 {
                let h = e.div_ceil(2);
                vec![(self.o[a], h), (self.o[a] + h, e - h)]
            } else {
                vec![(self.o[a], e)]
            }
        };
        let (xs, ys, zs) = (halves(0), halves(1), halves(2));
        for &(oz, ez) in &zs {
            for &(oy, ey) in &ys {
                for &(ox, ex) in &xs {
                    out.push(Block {
                        o: [ox, oy, oz],
                        e: [ex, ey, ez],
                    });
                }
            }
        }
    }
}

/// Evaluate `sdf` at the grid points `idx` (flat indices into an m³ grid), in parallel chunks.
fn evaluate(
    sdf: &dyn Sdf,
    idx: &[usize],
    m: usize,
    coord: &(dyn Fn(usize) -> f32 + Sync),
) -> Vec<f32> {
    let mut out = vec![0.0f32; idx.len()];
    out.par_chunks_mut(CHUNK)
        .zip(idx.par_chunks(CHUNK))
        .for_each(|(out, idx)| {
            let pts: Vec<[f32; 3]> = idx
                .iter()
                .map(|&f| [coord(f % m), coord(f / m % m), coord(f / (m * m))])
                .collect();
            sdf.eval_batch(&pts, out);
        });
    out
}

/// The values of `sdf` on the (r + 1)³ grid points i + (r + 1)·(j + (r + 1)·k), point index i
/// at coordinate `coord(i)` (uniform spacing `spacing`), with the narrow-band octree (module
/// docs). Exact where a triangle can be; elsewhere a value of the right sign. Non-finite values
/// are returned as they came (the caller decides how to treat them).
pub fn sample_grid(
    sdf: &dyn Sdf,
    r: usize,
    spacing: f32,
    coord: &(dyn Fn(usize) -> f32 + Sync),
) -> Vec<f32> {
    sample_grid_with_margin(sdf, r, spacing, coord, LIPSCHITZ_MARGIN)
}

/// [`sample_grid`] assuming the Lipschitz bound `margin` instead of [`LIPSCHITZ_MARGIN`] (for
/// measuring what a margin costs and whether it still gives the dense grid's mesh).
pub fn sample_grid_with_margin(
    sdf: &dyn Sdf,
    r: usize,
    spacing: f32,
    coord: &(dyn Fn(usize) -> f32 + Sync),
    margin: f32,
) -> Vec<f32> {
    let m = r + 1;
    let at = |p: [usize; 3]| flat(m, p);
    let mut val = vec![f32::NAN; m * m * m];
    let mut known = vec![false; m * m * m];
    // Top level: blocks of b0 cells, b0 the largest power of two ≤ r / 8 (at least 1).
    let b0 = (r / 8).max(1);
    let b0 = 1usize << (usize::BITS - 1 - b0.leading_zeros());
    let mut blocks = Vec::new();
    for oz in (0..r).step_by(b0) {
        for oy in (0..r).step_by(b0) {
            for ox in (0..r).step_by(b0) {
                blocks.push(Block {
                    o: [ox, oy, oz],
                    e: [b0.min(r - ox), b0.min(r - oy), b0.min(r - oz)],
                });
            }
        }
    }
    let mut skipped: Vec<(Block, f32)> = Vec::new();
    while !blocks.is_empty() {
        let mut need = Vec::new();
        for b in &blocks {
            for c in b.corners() {
                let f = at(c);
                if !known[f] {
                    known[f] = true;
                    need.push(f);
                }
            }
        }
        for (f, v) in need.iter().zip(evaluate(sdf, &need, m, coord)) {
            val[*f] = v;
        }
        let mut next = Vec::new();
        for b in blocks {
            if b.e == [1, 1, 1] {
                continue; // a single cell: all its points are exact
            }
            let corners = b.corners().map(|c| val[at(c)]);
            let diag = spacing * (b.e.iter().map(|&e| (e * e) as f32).sum::<f32>()).sqrt();
            let far = corners
                .iter()
                .all(|v| v.is_finite() && v.abs() > 0.5 * margin * diag);
            if far {
                skipped.push((b, corners[0]));
            } else {
                b.split(&mut next);
            }
        }
        blocks = next;
    }
    // Skipped blocks: their not-evaluated points take a corner's value (one sign per block, and
    // a point shared by two skipped blocks has the same sign in both).
    for (b, v) in skipped {
        for k in b.o[2]..=b.o[2] + b.e[2] {
            for j in b.o[1]..=b.o[1] + b.e[1] {
                for i in b.o[0]..=b.o[0] + b.e[0] {
                    let f = at([i, j, k]);
                    if !known[f] {
                        val[f] = v;
                    }
                }
            }
        }
    }
    val
}

/// An [`Sdf`] that counts the points it evaluates, to measure what [`sample_grid`] saves
/// against [`sample_dense`] (tests, `examples/bench_margin.rs`).
pub struct CountingSdf<'a> {
    inner: &'a dyn Sdf,
    count: AtomicUsize,
}

impl<'a> CountingSdf<'a> {
    /// Wrap `inner` with a count of zero.
    pub fn new(inner: &'a dyn Sdf) -> Self {
        Self {
            inner,
            count: AtomicUsize::new(0),
        }
    }

    /// Points evaluated so far.
    pub fn evaluations(&self) -> usize {
        self.count.load(Ordering::Relaxed)
    }
}

impl Sdf for CountingSdf<'_> {
    fn eval_batch(&self, points: &[[f32; 3]], out: &mut [f32]) {
        self.count.fetch_add(points.len(), Ordering::Relaxed);
        self.inner.eval_batch(points, out);
    }
}

/// The steepest |f(a) − f(b)| / `spacing` between neighbouring points a, b of an m³ grid of
/// values (layout as [`sample_grid`]): a lower bound on the field's Lipschitz constant, which
/// [`LIPSCHITZ_MARGIN`] must exceed for the sparse grid to be exact where it matters.
pub fn steepest_grid_slope(values: &[f32], m: usize, spacing: f32) -> f32 {
    let mut steepest = 0.0f32;
    for z in 0..m {
        for y in 0..m {
            for x in 0..m {
                let d = values[flat(m, [x, y, z])];
                for n in [[x + 1, y, z], [x, y + 1, z], [x, y, z + 1]] {
                    if n.iter().all(|&c| c < m) {
                        steepest = steepest.max((values[flat(m, n)] - d).abs() / spacing);
                    }
                }
            }
        }
    }
    steepest
}

/// Why marching cubes would mesh the (r + 1)³ grid `sparse` differently from `dense`: the
/// first grid point whose inside/outside sign differs, or the first cell the surface crosses
/// (in `dense`) whose corner values are not exactly the dense ones. None: the same mesh.
pub fn mesh_difference(sparse: &[f32], dense: &[f32], r: usize) -> Option<String> {
    let m = r + 1;
    if let Some(n) = (0..m * m * m).find(|&n| (sparse[n] < 0.0) != (dense[n] < 0.0)) {
        let (x, y, z) = (n % m, n / m % m, n / (m * m));
        return Some(format!(
            "point ({x}, {y}, {z}): sparse {} against dense {}",
            sparse[n], dense[n]
        ));
    }
    for z in 0..r {
        for y in 0..r {
            for x in 0..r {
                let cell = Block {
                    o: [x, y, z],
                    e: [1, 1, 1],
                };
                let corners = cell.corners().map(|c| flat(m, c));
                let neg = corners.iter().filter(|&&c| dense[c] < 0.0).count();
                if neg != 0 && neg != 8 && corners.iter().any(|&c| sparse[c] != dense[c]) {
                    return Some(format!(
                        "cell ({x}, {y}, {z}) is crossed by the surface but its corners are not exact"
                    ));
                }
            }
        }
    }
    None
}

/// The dense reference: every grid point evaluated.
pub fn sample_dense(sdf: &dyn Sdf, r: usize, coord: &(dyn Fn(usize) -> f32 + Sync)) -> Vec<f32> {
    let m = r + 1;
    let all: Vec<usize> = (0..m * m * m).collect();
    evaluate(sdf, &all, m, coord)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(r: usize) -> (f32, impl Fn(usize) -> f32 + Sync) {
        let spacing = 1.1 / r as f32;
        (spacing, move |i: usize| -0.55 + spacing * i as f32)
    }

    /// Exact where the sign can change, right sign everywhere, and far fewer evaluations than
    /// the dense grid — for a sphere, a thin slab and resolutions that are not powers of two.
    #[test]
    fn matches_the_dense_grid_where_it_matters_and_skips_the_rest() {
        let sphere = |p: [f32; 3]| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.3;
        let slab = |p: [f32; 3]| {
            let q = [p[0].abs() - 0.35, p[1].abs() - 0.35, p[2].abs() - 0.004];
            let out = q.iter().map(|v| v.max(0.0).powi(2)).sum::<f32>().sqrt();
            out + q[0].max(q[1]).max(q[2]).min(0.0)
        };
        type Field<'a> = &'a (dyn Fn([f32; 3]) -> f32 + Sync);
        let shapes: [(&str, Field); 2] = [("sphere", &sphere), ("slab", &slab)];
        for (name, f) in shapes {
            for r in [8, 13, 32, 64] {
                let (spacing, coord) = grid(r);
                let m = r + 1;
                let dense = sample_dense(&f, r, &coord);
                let counted = CountingSdf::new(&f);
                let sparse = sample_grid(&counted, r, spacing, &coord);
                assert_eq!(mesh_difference(&sparse, &dense, r), None, "{name} r {r}");
                assert!(
                    steepest_grid_slope(&dense, m, spacing) <= 1.0 + 1e-3,
                    "{name} r {r}"
                );
                let evals = counted.evaluations();
                if r == 64 {
                    assert!(
                        evals * 2 < m * m * m,
                        "{name} r {r}: {evals} of {} points evaluated",
                        m * m * m
                    );
                }
            }
        }
    }

    /// A flipped sign anywhere, or an inexact corner of a crossed cell, is reported; an
    /// inexact value far from the surface (right sign) is not.
    #[test]
    fn mesh_difference_finds_what_changes_the_mesh() {
        let sphere = |p: [f32; 3]| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.3;
        let (_, coord) = grid(8);
        let dense = sample_dense(&sphere, 8, &coord);
        let mut far = dense.clone();
        far[0] *= 2.0; // a corner of the domain, far outside
        assert_eq!(mesh_difference(&far, &dense, 8), None);
        let mut flipped = dense.clone();
        flipped[0] = -1.0;
        assert!(
            mesh_difference(&flipped, &dense, 8)
                .unwrap()
                .contains("point (0, 0, 0)")
        );
        // Point (6, 4, 4), x = 0.275, just inside: a corner of cells the surface crosses.
        let mut nudged = dense.clone();
        nudged[6 + 9 * (4 + 9 * 4)] += 1e-3;
        let why = mesh_difference(&nudged, &dense, 8).unwrap();
        assert!(why.contains("not exact"), "{why}");
    }

    /// Non-finite values never let a block be skipped, and come back as they were.
    #[test]
    fn non_finite_values_refine() {
        let f = |p: [f32; 3]| if p[0] > 0.3 { f32::NAN } else { 1.0 };
        let (spacing, coord) = grid(16);
        let sparse = sample_grid(&f, 16, spacing, &coord);
        let dense = sample_dense(&f, 16, &coord);
        for (s, d) in sparse.iter().zip(&dense) {
            assert!(s.is_nan() == d.is_nan() && (s.is_nan() || s == d));
        }
    }
}
