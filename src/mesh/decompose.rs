//! Approximate convex decomposition of a part mesh by axis-aligned cuts, measured by how far a
//! piece's hull reaches into space the part leaves free.
//!
//! Why it exists: a collision piece must not claim space another part may occupy. VHACD
//! (parry3d's) bounds the *volume* a hull adds, so a thin wedge of hull across a cabinet's
//! drawer slot passes its test and jams the drawer (7–37 mm deep on the hand-made cabinet's
//! marching-cubes meshes). This decomposition bounds the *depth* instead:
//!
//! 1. voxelise the mesh's box (`resolution` voxels along its longest side), mark every voxel the
//!    surface passes through, and flood-fill the free space from the border: what the fill
//!    cannot reach (walls, their inside, closed cavities) is solid;
//! 2. a cell is a box of voxels; its piece is the convex hull of the mesh clipped to the cell
//!    (exact triangle clipping, so the hull never leaves the cell and never claims more than
//!    the clipped surface spans);
//! 3. a cell's concavity is the deepest free voxel centre inside its hull, as distance to the
//!    hull's boundary: how far another part could sit inside the piece without touching the
//!    real surface;
//! 4. while the worst cell is deeper than `tolerance` and pieces are left, it is cut by the
//!    axis-aligned plane that leaves its two halves closest to boxes (least free volume in the
//!    halves' bounding boxes of solid voxels: furniture is made of panels), each half shrunk to
//!    its solid voxels.
//!
//! Everything is deterministic: fixed grid, sorted candidates, ties to the lower axis and plane.

use parry3d::math::Vector;
use parry3d::transformation::try_convex_hull;

use super::TriMesh;

/// Knobs of [`decompose`] (validated by the caller, `mesh::convex::DecompositionOptions`).
#[derive(Debug, Clone, Copy)]
pub struct CutOptions {
    /// Most cells.
    pub max_pieces: usize,
    /// Voxels along the longest side of the mesh's bounding box.
    pub resolution: u32,
    /// Concavity (metres) a cell may keep.
    pub tolerance: f64,
}

/// Voxel flags: the occupancy grid of one mesh.
struct Grid {
    origin: [f64; 3],
    h: f64,
    n: [usize; 3],
    /// true = solid (surface, inside or closed cavity).
    solid: Vec<bool>,
}

impl Grid {
    fn idx(&self, i: usize, j: usize, k: usize) -> usize {
        (k * self.n[1] + j) * self.n[0] + i
    }

    fn centre(&self, i: usize, j: usize, k: usize) -> [f64; 3] {
        [
            self.origin[0] + (i as f64 + 0.5) * self.h,
            self.origin[1] + (j as f64 + 0.5) * self.h,
            self.origin[2] + (k as f64 + 0.5) * self.h,
        ]
    }

    fn new(mesh: &TriMesh, resolution: u32) -> Option<Grid> {
        let (lo, hi) = mesh.bounds()?;
        let ext = (0..3).map(|a| (hi[a] - lo[a]) as f64).fold(0.0, f64::max);
        if ext.is_nan() || ext <= 0.0 {
            return None;
        }
        let h = ext / resolution as f64;
        let origin = [0, 1, 2].map(|a| lo[a] as f64 - h);
        let n = [0, 1, 2].map(|a| (((hi[a] - lo[a]) as f64 / h).ceil() as usize).max(1) + 2);
        let mut g = Grid {
            origin,
            h,
            n,
            solid: vec![false; n[0] * n[1] * n[2]],
        };
        let cell = |p: [f64; 3]| -> [usize; 3] {
            [0, 1, 2].map(|a| (((p[a] - origin[a]) / h).floor().max(0.0) as usize).min(n[a] - 1))
        };
        // Surface voxels: sample each triangle at most h/2 apart.
        let mut surface = vec![false; g.solid.len()];
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize].map(f64::from));
            let edge = |p: [f64; 3], q: [f64; 3]| {
                ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
            };
            let longest = edge(a, b).max(edge(b, c)).max(edge(c, a));
            let steps = ((longest / (0.5 * h)).ceil() as usize).clamp(1, 4096);
            for i in 0..=steps {
                for j in 0..=(steps - i) {
                    let (u, v) = (i as f64 / steps as f64, j as f64 / steps as f64);
                    let p = [0, 1, 2].map(|k| a[k] + u * (b[k] - a[k]) + v * (c[k] - a[k]));
                    let [x, y, z] = cell(p);
                    let id = g.idx(x, y, z);
                    surface[id] = true;
                }
            }
        }
        // Free space: flood fill from the border (the padding is never surface).
        let mut outside = vec![false; g.solid.len()];
        let mut stack = Vec::new();
        for k in 0..n[2] {
            for j in 0..n[1] {
                for i in 0..n[0] {
                    let border = i == 0
                        || j == 0
                        || k == 0
                        || i == n[0] - 1
                        || j == n[1] - 1
                        || k == n[2] - 1;
                    let id = g.idx(i, j, k);
                    if border && !surface[id] {
                        outside[id] = true;
                        stack.push([i, j, k]);
                    }
                }
            }
        }
        while let Some([i, j, k]) = stack.pop() {
            let mut visit = |x: usize, y: usize, z: usize| {
                let id = g.idx(x, y, z);
                if !outside[id] && !surface[id] {
                    outside[id] = true;
                    stack.push([x, y, z]);
                }
            };
            if i > 0 {
                visit(i - 1, j, k);
            }
            if i + 1 < n[0] {
                visit(i + 1, j, k);
            }
            if j > 0 {
                visit(i, j - 1, k);
            }
            if j + 1 < n[1] {
                visit(i, j + 1, k);
            }
            if k > 0 {
                visit(i, j, k - 1);
            }
            if k + 1 < n[2] {
                visit(i, j, k + 1);
            }
        }
        for (s, o) in g.solid.iter_mut().zip(&outside) {
            *s = !o;
        }
        Some(g)
    }

    /// The cell shrunk to its solid voxels (`None`: no solid voxel in it).
    fn tight(&self, lo: [usize; 3], hi: [usize; 3]) -> Option<([usize; 3], [usize; 3])> {
        let mut a = hi;
        let mut b = lo;
        let mut any = false;
        for k in lo[2]..hi[2] {
            for j in lo[1]..hi[1] {
                for i in lo[0]..hi[0] {
                    if self.solid[self.idx(i, j, k)] {
                        any = true;
                        let v = [i, j, k];
                        for d in 0..3 {
                            a[d] = a[d].min(v[d]);
                            b[d] = b[d].max(v[d] + 1);
                        }
                    }
                }
            }
        }
        any.then_some((a, b))
    }
}

/// One cell: its voxel box, the triangles that may cross it, its hull and concavity.
struct Cell {
    lo: [usize; 3],
    hi: [usize; 3],
    tris: Vec<u32>,
    points: Vec<[f32; 3]>,
    concavity: f64,
}

/// Clip a polygon to `x[axis] >= v` (keep = +1) or `x[axis] <= v` (keep = −1).
fn clip(poly: &[[f64; 3]], axis: usize, v: f64, keep: f64) -> Vec<[f64; 3]> {
    let mut out = Vec::with_capacity(poly.len() + 2);
    for i in 0..poly.len() {
        let (p, q) = (poly[i], poly[(i + 1) % poly.len()]);
        let (dp, dq) = (keep * (p[axis] - v), keep * (q[axis] - v));
        if dp >= 0.0 {
            out.push(p);
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            let t = dp / (dp - dq);
            out.push([0, 1, 2].map(|k| p[k] + t * (q[k] - p[k])));
        }
    }
    out
}

impl Cell {
    fn new(g: &Grid, mesh: &TriMesh, lo: [usize; 3], hi: [usize; 3], parent: &[u32]) -> Cell {
        let blo = [0, 1, 2].map(|a| g.origin[a] + lo[a] as f64 * g.h);
        let bhi = [0, 1, 2].map(|a| g.origin[a] + hi[a] as f64 * g.h);
        let mut tris = Vec::new();
        let mut points = Vec::new();
        for &t in parent {
            let tri = mesh.triangles[t as usize].map(|i| mesh.positions[i as usize].map(f64::from));
            let outside = (0..3)
                .any(|a| tri.iter().all(|p| p[a] < blo[a]) || tri.iter().all(|p| p[a] > bhi[a]));
            if outside {
                continue;
            }
            tris.push(t);
            let mut poly = tri.to_vec();
            for a in 0..3 {
                poly = clip(&poly, a, blo[a], 1.0);
                poly = clip(&poly, a, bhi[a], -1.0);
                if poly.is_empty() {
                    break;
                }
            }
            points.extend(poly.iter().map(|p| p.map(|v| v as f32)));
        }
        points.sort_by(|a, b| {
            a.iter()
                .zip(b)
                .map(|(x, y)| x.total_cmp(y))
                .find(|o| o.is_ne())
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        points.dedup();
        let concavity = concavity(g, lo, hi, &points);
        Cell {
            lo,
            hi,
            tris,
            points,
            concavity,
        }
    }
}

/// The deepest free voxel centre of the cell inside the hull of `points` (metres; 0 if none).
fn concavity(g: &Grid, lo: [usize; 3], hi: [usize; 3], points: &[[f32; 3]]) -> f64 {
    let pts: Vec<Vector> = points
        .iter()
        .map(|p| Vector::new(p[0], p[1], p[2]))
        .collect();
    let Ok((verts, faces)) = try_convex_hull(&pts) else {
        // parry refuses only degenerate sets (flat, collinear): such a piece has no inside.
        return 0.0;
    };
    // Face normals point away from the vertices' centroid (parry's winding is not relied on).
    let m = verts.iter().fold(nalgebra::Vector3::zeros(), |acc, v| {
        acc + nalgebra::Vector3::new(v.x as f64, v.y as f64, v.z as f64)
    }) / verts.len().max(1) as f64;
    let planes: Vec<([f64; 3], f64)> = faces
        .iter()
        .filter_map(|f| {
            let [a, b, c] = f.map(|i| {
                let v = verts[i as usize];
                nalgebra::Vector3::new(v.x as f64, v.y as f64, v.z as f64)
            });
            let n = (b - a).cross(&(c - a));
            let len = n.norm();
            (len > 1e-12).then(|| {
                let n = n / len;
                let n = if n.dot(&(m - a)) > 0.0 { -n } else { n };
                ([n.x, n.y, n.z], n.dot(&a))
            })
        })
        .collect();
    let voxels: usize = (0..3).map(|a| hi[a] - lo[a]).product();
    let stride = if voxels > 1 << 16 { 2 } else { 1 };
    let mut deepest = 0.0f64;
    for k in (lo[2]..hi[2]).step_by(stride) {
        for j in (lo[1]..hi[1]).step_by(stride) {
            for i in (lo[0]..hi[0]).step_by(stride) {
                if g.solid[g.idx(i, j, k)] {
                    continue;
                }
                let x = g.centre(i, j, k);
                let mut depth = f64::INFINITY;
                for (n, d) in &planes {
                    let inside = d - (n[0] * x[0] + n[1] * x[1] + n[2] * x[2]);
                    if inside <= deepest {
                        depth = 0.0;
                        break;
                    }
                    depth = depth.min(inside);
                }
                if depth.is_finite() {
                    deepest = deepest.max(depth);
                }
            }
        }
    }
    deepest
}

/// Candidate cuts of a cell: on each axis, the planes where the number of solid voxels per
/// slice jumps (a panel's inner face, a shelf), at most [`CUTS_PER_AXIS`] per axis, largest
/// jumps first; the middle of the longest side when the cell has none.
fn candidates(g: &Grid, lo: [usize; 3], hi: [usize; 3]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for axis in 0..3 {
        let len = hi[axis] - lo[axis];
        if len < 2 {
            continue;
        }
        let mut count = vec![0usize; len];
        for k in lo[2]..hi[2] {
            for j in lo[1]..hi[1] {
                for i in lo[0]..hi[0] {
                    if g.solid[g.idx(i, j, k)] {
                        count[[i, j, k][axis] - lo[axis]] += 1;
                    }
                }
            }
        }
        let max = count.iter().copied().max().unwrap_or(0);
        let mut jumps: Vec<(usize, usize)> = (1..len)
            .map(|s| (count[s].abs_diff(count[s - 1]), s))
            .filter(|&(d, _)| d > 0 && 5 * d >= max)
            .collect();
        jumps.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        out.extend(
            jumps
                .into_iter()
                .take(CUTS_PER_AXIS)
                .map(|(_, s)| (axis, lo[axis] + s)),
        );
    }
    if out.is_empty() {
        let axis = (0..3).max_by_key(|&a| (hi[a] - lo[a], 3 - a)).unwrap_or(0);
        if hi[axis] - lo[axis] >= 2 {
            out.push((axis, (lo[axis] + hi[axis]) / 2));
        }
    }
    out
}

/// Candidate cuts tried per axis.
const CUTS_PER_AXIS: usize = 3;

/// The best cut of `c`: the candidate whose worse half is least concave (then the smaller sum,
/// then the lower axis and plane); its halves, already measured.
fn best_cut(g: &Grid, mesh: &TriMesh, c: &Cell) -> Option<Vec<Cell>> {
    let mut best: Option<(f64, f64, Vec<Cell>)> = None;
    for (axis, plane) in candidates(g, c.lo, c.hi) {
        let (mut hi_a, mut lo_b) = (c.hi, c.lo);
        hi_a[axis] = plane;
        lo_b[axis] = plane;
        let halves: Vec<Cell> = [(c.lo, hi_a), (lo_b, c.hi)]
            .into_iter()
            .filter_map(|(l, h)| g.tight(l, h))
            .map(|(l, h)| Cell::new(g, mesh, l, h, &c.tris))
            .collect();
        if halves.len() < 2 {
            continue;
        }
        let worst = halves.iter().map(|h| h.concavity).fold(0.0, f64::max);
        let sum: f64 = halves.iter().map(|h| h.concavity).sum();
        if best
            .as_ref()
            .is_none_or(|(w, s, _)| worst < *w || (worst == *w && sum < *s))
        {
            best = Some((worst, sum, halves));
        }
    }
    best.map(|b| b.2)
}

/// The cells' clipped surface points, one list per piece (take their hulls for the pieces).
pub fn decompose(mesh: &TriMesh, opts: &CutOptions) -> Vec<Vec<[f32; 3]>> {
    let Some(g) = Grid::new(mesh, opts.resolution) else {
        return vec![mesh.positions.clone()];
    };
    let all: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
    let Some((lo, hi)) = g.tight([0; 3], g.n) else {
        return vec![mesh.positions.clone()];
    };
    let mut cells = vec![Cell::new(&g, mesh, lo, hi, &all)];
    while cells.len() < opts.max_pieces {
        // The worst cell (first on ties).
        let (w, worst) = cells
            .iter()
            .enumerate()
            .fold((0, f64::NEG_INFINITY), |acc, (i, c)| {
                if c.concavity > acc.1 {
                    (i, c.concavity)
                } else {
                    acc
                }
            });
        if worst <= opts.tolerance {
            break;
        }
        let Some(halves) = best_cut(&g, mesh, &cells[w]) else {
            // A cell no plane divides (one voxel thick everywhere) is accepted as it is.
            cells[w].concavity = 0.0;
            continue;
        };
        cells.splice(w..=w, halves);
    }
    // Specks (a cut grazing the surface leaves a cell of a few clipped points) are dropped:
    // they add a piece and no shape.
    let span = |p: &[[f32; 3]]| {
        (0..3)
            .map(|a| {
                let (lo, hi) = p
                    .iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), v| {
                        (l.min(v[a]), h.max(v[a]))
                    });
                hi - lo
            })
            .fold(0.0f32, f32::max)
    };
    let speck = (0.5 * g.h) as f32;
    let mut out: Vec<Vec<[f32; 3]>> = cells
        .iter()
        .map(|c| c.points.clone())
        .filter(|p| !p.is_empty() && span(p) >= speck)
        .collect();
    if out.is_empty() {
        out = cells
            .into_iter()
            .map(|c| c.points)
            .filter(|p| !p.is_empty())
            .collect();
    }
    out
}
