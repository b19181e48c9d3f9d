//! Generative metrics of NAP (method.md §7): instantiation distance (ID) between two articulated
//! objects, and MMD / COV / 1-NNA of a generated set against a reference set, in PhysNAP's
//! corrected (PointFlow) order or NAP's original order.
//!
//! Why it exists: "do the samples look like the data?" needs a distance that understands
//! articulation. ID compares objects over several joint states, each state's surface cloud seen
//! from every part's frame, so two cabinets whose doors open the same way are close even when
//! their rest poses differ slightly.
//!
//! Definitions (method.md §7.1–§7.2):
//! - states a = 1…S: every joint independently θ ~ U(r_lo, r_hi), d ~ U(p_lo, p_hi) (§6.3);
//!   X_a = N area-weighted surface points of the posed meshes; X_{a,p} = T_{a,p}⁻¹ X_a (the
//!   cloud in part p's frame).
//! - CD(X, Y) = mean_x min_y ‖x − y‖² + mean_y min_x ‖x − y‖² (squared distances, PyTorch3D).
//! - D[a, b] = min_{p, q} CD(X_{a,p}, Y_{b,q});
//!   ID(A, B) = mean_a min_b D[a, b] + mean_b min_a D[a, b].
//! - PointFlow order (default): MMD = (1/N_ref) Σ_r min_g D_gr[g, r];
//!   COV = |{argmin_r D_gr[g, r] : g}| / N_ref; 1-NNA = leave-one-out 1-NN accuracy on the pooled
//!   matrix [[D_rr, D_grᵀ], [D_gr, D_gg]] (ideal 0.5).
//! - NAP order (for reproducing NAP's numbers): MMD averages over samples, COV counts samples
//!   that are a reference's nearest, 1-NNA reads the cross block transposed (needs N_gen = N_ref).
//!
//! Cost: one ID is S² · |parts(A)| · |parts(B)| Chamfer distances of N points (brute force,
//! both directions in one pass over the N × N distances). The spec's S = 10, N = 2048 are the
//! defaults of [`IdOptions`]; `physnap eval generative` exposes both, because on a 2-core CPU
//! the full setting costs seconds per pair.

use nalgebra::Point3;
use rayon::prelude::*;

use crate::data::rng::Rng;
use crate::mesh::TriMesh;
use crate::object::{ArticulatedObject, JointState};

/// Errors of the evaluation layer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// An option or input broke a limit.
    #[error("invalid {0}")]
    Invalid(crate::error::Invalid),
}

impl EvalError {
    fn invalid(field: &str, limit: &str, value: impl ToString) -> Self {
        EvalError::Invalid(crate::error::Invalid {
            field: field.into(),
            limit: limit.into(),
            value: value.to_string(),
        })
    }
}

/// Settings of the instantiation distance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IdOptions {
    /// Joint states per object (NAP: 10).
    pub states: usize,
    /// Surface points per state (NAP: 2048).
    pub points: usize,
}

impl Default for IdOptions {
    fn default() -> Self {
        IdOptions {
            states: 10,
            points: 2048,
        }
    }
}

impl IdOptions {
    /// Check the ranges.
    pub fn validate(&self) -> Result<(), EvalError> {
        if !(1..=100).contains(&self.states) {
            return Err(EvalError::invalid(
                "states",
                "between 1 and 100",
                self.states,
            ));
        }
        if !(16..=65_536).contains(&self.points) {
            return Err(EvalError::invalid(
                "points",
                "between 16 and 65536",
                self.points,
            ));
        }
        Ok(())
    }
}

/// A cloud in structure-of-arrays layout (the Chamfer inner loop vectorises over it).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Cloud {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
}

impl Cloud {
    /// From points.
    pub fn new(points: &[[f32; 3]]) -> Self {
        Cloud {
            x: points.iter().map(|p| p[0]).collect(),
            y: points.iter().map(|p| p[1]).collect(),
            z: points.iter().map(|p| p[2]).collect(),
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True when the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
}

/// Mean over `a` of the squared distance to the nearest point of `b`. The inner loop keeps eight
/// independent running minima written as compare-and-select, which the compiler turns into
/// packed SIMD min instructions (about 5× faster than a scalar `f32::min` chain).
fn mean_nn_sq(a: &Cloud, b: &Cloud) -> f64 {
    const L: usize = 8;
    let n = b.len();
    let full = n / L * L;
    let mut sum = 0.0f64;
    for i in 0..a.len() {
        let (px, py, pz) = (a.x[i], a.y[i], a.z[i]);
        let mut acc = [f32::INFINITY; L];
        let (bx, by, bz) = (&b.x[..full], &b.y[..full], &b.z[..full]);
        for ((cx, cy), cz) in bx
            .chunks_exact(L)
            .zip(by.chunks_exact(L))
            .zip(bz.chunks_exact(L))
        {
            for k in 0..L {
                let dx = px - cx[k];
                let dy = py - cy[k];
                let dz = pz - cz[k];
                let d = dx * dx + dy * dy + dz * dz;
                acc[k] = if d < acc[k] { d } else { acc[k] };
            }
        }
        let mut m = f32::INFINITY;
        for v in acc {
            m = if v < m { v } else { m };
        }
        for j in full..n {
            let dx = px - b.x[j];
            let dy = py - b.y[j];
            let dz = pz - b.z[j];
            let d = dx * dx + dy * dy + dz * dz;
            m = if d < m { d } else { m };
        }
        sum += m as f64;
    }
    sum / a.len() as f64
}

/// Chamfer distance with squared nearest-neighbour distances, averaged per direction and summed.
/// Both clouds must be non-empty.
pub fn chamfer(a: &Cloud, b: &Cloud) -> f64 {
    debug_assert!(!a.is_empty() && !b.is_empty());
    mean_nn_sq(a, b) + mean_nn_sq(b, a)
}

/// An object prepared for ID: for every state, its surface cloud in every part's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct StateClouds {
    /// `clouds[a][p]` = X_{a,p}.
    pub clouds: Vec<Vec<Cloud>>,
}

/// Area-weighted surface samples of several meshes (all treated as one surface).
fn sample_meshes(meshes: &[TriMesh], n: usize, rng: &mut Rng) -> Vec<[f32; 3]> {
    let mut tris: Vec<([f64; 3], [f64; 3], [f64; 3])> = Vec::new();
    let mut cum = Vec::new();
    let mut total = 0.0f64;
    for m in meshes {
        for t in &m.triangles {
            let [a, b, c] = t.map(|i| m.positions[i as usize].map(|v| v as f64));
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let cr = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            let area = 0.5 * (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt();
            if area > 0.0 && area.is_finite() {
                total += area;
                tris.push((a, b, c));
                cum.push(total);
            }
        }
    }
    if tris.is_empty() {
        return Vec::new();
    }
    (0..n)
        .map(|_| {
            // One draw per sample: the predicate of a binary search must not change between its
            // probes (a fresh draw per probe skews the choice towards the triangles' order).
            let x = rng.uniform() * total;
            let k = cum.partition_point(|&c| c <= x).min(tris.len() - 1);
            let (a, b, c) = tris[k];
            let s = rng.uniform().sqrt();
            let r = rng.uniform();
            let (wa, wb, wc) = (1.0 - s, s * (1.0 - r), s * r);
            [0, 1, 2].map(|d| (wa * a[d] + wb * b[d] + wc * c[d]) as f32)
        })
        .collect()
}

/// Sample `opts.states` joint states of `obj` (independently per joint, §6.3), pose the rest-state
/// part `meshes` (object frame), sample the surface and express it in every part's frame.
/// Deterministic for `seed`.
pub fn state_clouds(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    opts: &IdOptions,
    seed: u64,
) -> Result<StateClouds, EvalError> {
    opts.validate()?;
    if meshes.len() != obj.parts.len() {
        return Err(EvalError::invalid(
            "meshes",
            &format!("one per part ({})", obj.parts.len()),
            meshes.len(),
        ));
    }
    if meshes.iter().all(|m| m.triangles.is_empty()) {
        return Err(EvalError::invalid(
            "meshes",
            "at least one non-empty part mesh",
            "all empty",
        ));
    }
    let mut rng = Rng::new(seed);
    let mut clouds = Vec::with_capacity(opts.states);
    for _ in 0..opts.states {
        let states: Vec<JointState> = obj
            .joints
            .iter()
            .map(|j| JointState {
                angle: j.revolute[0] + rng.uniform() * (j.revolute[1] - j.revolute[0]),
                displacement: j.prismatic[0] + rng.uniform() * (j.prismatic[1] - j.prismatic[0]),
            })
            .collect();
        let motions = obj.part_motions(&states);
        let posed: Vec<TriMesh> = meshes
            .iter()
            .zip(&motions)
            .map(|(m, t)| {
                m.clone().map_positions(|p| {
                    let q = t * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                    [q.x as f32, q.y as f32, q.z as f32]
                })
            })
            .collect();
        let pts = sample_meshes(&posed, opts.points, &mut rng);
        let poses = obj.part_poses(&states);
        clouds.push(
            poses
                .iter()
                .map(|pose| {
                    let inv = pose.inverse();
                    let local: Vec<[f32; 3]> = pts
                        .iter()
                        .map(|p| {
                            let q = inv * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                            [q.x as f32, q.y as f32, q.z as f32]
                        })
                        .collect();
                    Cloud::new(&local)
                })
                .collect(),
        );
    }
    Ok(StateClouds { clouds })
}

/// ID(A, B) = mean_a min_b D[a, b] + mean_b min_a D[a, b], D[a, b] = min_{p,q} CD(X_{a,p}, Y_{b,q}).
pub fn instantiation_distance(a: &StateClouds, b: &StateClouds) -> f64 {
    let (sa, sb) = (a.clouds.len(), b.clouds.len());
    let mut d = vec![f64::INFINITY; sa * sb];
    for (i, xa) in a.clouds.iter().enumerate() {
        for (j, yb) in b.clouds.iter().enumerate() {
            let mut best = f64::INFINITY;
            for x in xa {
                for y in yb {
                    best = best.min(chamfer(x, y));
                }
            }
            d[i * sb + j] = best;
        }
    }
    let row: f64 = (0..sa)
        .map(|i| (0..sb).map(|j| d[i * sb + j]).fold(f64::INFINITY, f64::min))
        .sum::<f64>()
        / sa as f64;
    let col: f64 = (0..sb)
        .map(|j| (0..sa).map(|i| d[i * sb + j]).fold(f64::INFINITY, f64::min))
        .sum::<f64>()
        / sb as f64;
    row + col
}

/// All pairwise IDs `rows × cols`, in parallel on the current rayon pool. When `rows` and `cols`
/// are the same set (`symmetric`), only the upper triangle is computed and the diagonal is 0.
pub fn distance_matrix(
    rows: &[StateClouds],
    cols: &[StateClouds],
    symmetric: bool,
    on_done: &(dyn Fn(usize) + Sync),
) -> Vec<Vec<f64>> {
    let pairs: Vec<(usize, usize)> = (0..rows.len())
        .flat_map(|i| {
            let start = if symmetric { i + 1 } else { 0 };
            (start..cols.len()).map(move |j| (i, j))
        })
        .collect();
    let values: Vec<f64> = pairs
        .par_iter()
        .map(|&(i, j)| {
            let v = instantiation_distance(&rows[i], &cols[j]);
            on_done(1);
            v
        })
        .collect();
    let mut m = vec![vec![0.0; cols.len()]; rows.len()];
    for (&(i, j), v) in pairs.iter().zip(values) {
        m[i][j] = v;
        if symmetric {
            m[j][i] = v;
        }
    }
    m
}

/// Which set order MMD / COV / 1-NNA use (method.md §7.2, A13).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MetricOrder {
    /// PointFlow's definitions, as PhysNAP corrected them (default).
    #[default]
    PointFlow,
    /// NAP's implementation (per-sample MMD/COV, transposed 1-NNA cross block).
    Nap,
}

/// MMD, COV and 1-NNA of a generated set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DistributionMetrics {
    /// Minimum matching distance (lower is better).
    pub mmd: f64,
    /// Coverage (higher is better).
    pub cov: f64,
    /// 1-nearest-neighbour accuracy (0.5 is ideal).
    pub one_nna: f64,
}

fn check_matrix(name: &str, m: &[Vec<f64>], rows: usize, cols: usize) -> Result<(), EvalError> {
    if m.len() != rows || m.iter().any(|r| r.len() != cols) {
        return Err(EvalError::invalid(
            name,
            &format!("a {rows} × {cols} matrix"),
            format!("{} rows", m.len()),
        ));
    }
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err(EvalError::invalid(
            name,
            "finite entries",
            "a non-finite entry",
        ));
    }
    Ok(())
}

/// Leave-one-out 1-NN accuracy over a pooled matrix whose first `n_first` rows/cols carry
/// label 1 and the rest label 0.
fn one_nna(pool: &[Vec<f64>], n_first: usize) -> f64 {
    let n = pool.len();
    let correct = (0..n)
        .filter(|&i| {
            let nn = (0..n)
                .filter(|&j| j != i)
                .min_by(|&a, &b| pool[i][a].total_cmp(&pool[i][b]))
                .expect("at least two elements");
            (nn < n_first) == (i < n_first)
        })
        .count();
    correct as f64 / n as f64
}

/// MMD, COV and 1-NNA from `d_gr` (N_gen × N_ref), `d_gg` (N_gen × N_gen), `d_rr`
/// (N_ref × N_ref). NAP's order needs N_gen = N_ref (its 1-NNA only runs then).
pub fn distribution_metrics(
    d_gr: &[Vec<f64>],
    d_gg: &[Vec<f64>],
    d_rr: &[Vec<f64>],
    order: MetricOrder,
) -> Result<DistributionMetrics, EvalError> {
    let (ng, nr) = (d_gg.len(), d_rr.len());
    if ng == 0 || nr == 0 {
        return Err(EvalError::invalid(
            "sets",
            "at least one generated and one reference object",
            format!("{ng} generated, {nr} reference"),
        ));
    }
    check_matrix("d_gr", d_gr, ng, nr)?;
    check_matrix("d_gg", d_gg, ng, ng)?;
    check_matrix("d_rr", d_rr, nr, nr)?;
    let argmin = |v: &mut dyn Iterator<Item = f64>| -> (usize, f64) {
        v.enumerate().fold(
            (0, f64::INFINITY),
            |b, (i, x)| if x < b.1 { (i, x) } else { b },
        )
    };
    match order {
        MetricOrder::PointFlow => {
            let mmd = (0..nr)
                .map(|r| argmin(&mut (0..ng).map(|g| d_gr[g][r])).1)
                .sum::<f64>()
                / nr as f64;
            let mut covered = vec![false; nr];
            for row in d_gr {
                covered[argmin(&mut row.iter().copied()).0] = true;
            }
            let cov = covered.iter().filter(|&&c| c).count() as f64 / nr as f64;
            // [[D_rr, D_grᵀ], [D_gr, D_gg]]: refs first (label 1), then samples.
            let mut pool = vec![vec![0.0; nr + ng]; nr + ng];
            for i in 0..nr {
                for j in 0..nr {
                    pool[i][j] = d_rr[i][j];
                }
                for g in 0..ng {
                    pool[i][nr + g] = d_gr[g][i];
                    pool[nr + g][i] = d_gr[g][i];
                }
            }
            for g in 0..ng {
                for h in 0..ng {
                    pool[nr + g][nr + h] = d_gg[g][h];
                }
            }
            Ok(DistributionMetrics {
                mmd,
                cov,
                one_nna: one_nna(&pool, nr),
            })
        }
        MetricOrder::Nap => {
            if ng != nr {
                return Err(EvalError::invalid(
                    "order",
                    "equal set sizes for NAP's order (its 1-NNA transposes the cross block)",
                    format!("{ng} generated vs {nr} reference"),
                ));
            }
            let n = ng;
            let mmd = d_gr
                .iter()
                .map(|row| argmin(&mut row.iter().copied()).1)
                .sum::<f64>()
                / n as f64;
            let mut covered = vec![false; n];
            for r in 0..n {
                covered[argmin(&mut (0..n).map(|g| d_gr[g][r])).0] = true;
            }
            let cov = covered.iter().filter(|&&c| c).count() as f64 / n as f64;
            // [[D_rr, D_gr], [D_grᵀ, D_gg]]: entry (ref i, gen j) reads ID(gen i, ref j).
            let mut pool = vec![vec![0.0; 2 * n]; 2 * n];
            for i in 0..n {
                for j in 0..n {
                    pool[i][j] = d_rr[i][j];
                    pool[i][n + j] = d_gr[i][j];
                    pool[n + j][i] = d_gr[i][j];
                    pool[n + i][n + j] = d_gg[i][j];
                }
            }
            Ok(DistributionMetrics {
                mmd,
                cov,
                one_nna: one_nna(&pool, n),
            })
        }
    }
}

/// Why a generated object does not count as valid (≥ 2 parts, a tree,
/// every part meshes non-empty). `None` when it is valid.
pub fn invalid_reason(obj: &ArticulatedObject, meshes: &[TriMesh]) -> Option<String> {
    if obj.parts.len() < 2 {
        return Some(format!("{} part(s), need at least 2", obj.parts.len()));
    }
    if let Err(e) = obj.validate() {
        return Some(format!("not a valid tree: {e}"));
    }
    if let Some(k) = meshes.iter().position(|m| m.triangles.is_empty()) {
        return Some(format!("part {k} meshes empty"));
    }
    None
}

/// Leave-one-out nearest neighbours over a symmetric distance matrix: for each object, the
/// index of its nearest *other* object (the first on ties). None below two objects or when
/// `d` is not square.
pub fn loo_nearest(d: &[Vec<f64>]) -> Option<Vec<usize>> {
    let n = d.len();
    if n < 2 || d.iter().any(|row| row.len() != n) {
        return None;
    }
    Some(
        (0..n)
            .map(|i| {
                (0..n)
                    .filter(|&j| j != i)
                    .min_by(|&a, &b| d[i][a].total_cmp(&d[i][b]))
                    .expect("n >= 2")
            })
            .collect(),
    )
}

/// Leave-one-out nearest-neighbour label accuracy over a symmetric distance matrix: for each
/// object, does its nearest *other* object carry the same label? Run on the reference set
/// itself, it is the ceiling of the category-accuracy metric (a conditioned sample can only be
/// classified as well as the references separate their categories). None below two objects.
pub fn loo_label_accuracy(d: &[Vec<f64>], labels: &[String]) -> Option<f64> {
    if labels.len() != d.len() {
        return None;
    }
    let nn = loo_nearest(d)?;
    let hits = nn
        .iter()
        .enumerate()
        .filter(|&(i, &j)| labels[j] == labels[i])
        .count();
    Some(hits as f64 / labels.len() as f64)
}

/// For each reconstruction row `r` (of original object `rows[r]`; `d[r]` holds its IDs to
/// every original, in the order of the `n` originals): (its nearest original other than
/// itself, its nearest original of all). None when a row or index does not fit, or below two
/// originals.
pub fn reconstruction_neighbours(
    d: &[Vec<f64>],
    rows: &[usize],
    n: usize,
) -> Option<Vec<(usize, usize)>> {
    if n < 2 || d.len() != rows.len() || d.iter().any(|row| row.len() != n) {
        return None;
    }
    if rows.iter().any(|&i| i >= n) {
        return None;
    }
    let nearest = |r: usize, skip: Option<usize>| {
        (0..n)
            .filter(|&j| Some(j) != skip)
            .min_by(|&a, &b| d[r][a].total_cmp(&d[r][b]))
            .expect("n >= 2")
    };
    Some(
        (0..rows.len())
            .map(|r| (nearest(r, Some(rows[r])), nearest(r, None)))
            .collect(),
    )
}

/// Nearest-neighbour checks of reconstructions (see [`reconstruction_neighbours`] for `d` and
/// `rows`). Returns the counts (category hits: the nearest original *other than itself*
/// carries its label — what the category accuracy of a conditioned sample could reach if the
/// denoiser reproduced test objects exactly; self hits: the nearest original of all is the
/// object itself).
pub fn reconstruction_nn(
    d: &[Vec<f64>],
    rows: &[usize],
    labels: &[String],
) -> Option<(usize, usize)> {
    let nn = reconstruction_neighbours(d, rows, labels.len())?;
    Some(reconstruction_hits(&nn, rows, labels))
}

/// The counts of [`reconstruction_nn`] from already computed [`reconstruction_neighbours`].
pub fn reconstruction_hits(
    nn: &[(usize, usize)],
    rows: &[usize],
    labels: &[String],
) -> (usize, usize) {
    let cat = nn
        .iter()
        .zip(rows)
        .filter(|&(&(other, _), &i)| labels[other] == labels[i])
        .count();
    let own = nn
        .iter()
        .zip(rows)
        .filter(|&(&(_, any), &i)| any == i)
        .count();
    (cat, own)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{MeshingOptions, mesh_parts};

    #[test]
    fn reconstruction_checks_skip_the_object_itself_for_the_category() {
        // Reconstruction 0 lies nearest its own original, next nearest object 2;
        // reconstruction 1 lies nearest object 2, then its own; 2 nearest itself, then 1.
        let d = vec![
            vec![0.1, 0.9, 0.5],
            vec![0.8, 0.3, 0.2],
            vec![0.7, 0.4, 0.0],
        ];
        let rows = [0, 1, 2];
        let labels: Vec<String> = ["a", "a", "b"].map(String::from).to_vec();
        // Category: 0 → 2 (b ≠ a) miss; 1 → 2 (b ≠ a) miss; 2 → 1 (a ≠ b) miss.
        // Self: 0 yes, 1 no (2 is nearer), 2 yes.
        assert_eq!(reconstruction_nn(&d, &rows, &labels), Some((0, 2)));
        let labels: Vec<String> = ["a", "b", "b"].map(String::from).to_vec();
        // Category: 0 → 2 miss; 1 → 2 hit; 2 → 1 hit.
        assert_eq!(reconstruction_nn(&d, &rows, &labels), Some((2, 2)));
        // Reconstruction 1 missing (it meshed empty): rows name the originals.
        let d2 = vec![d[0].clone(), d[2].clone()];
        assert_eq!(reconstruction_nn(&d2, &[0, 2], &labels), Some((1, 2)));
        assert_eq!(reconstruction_nn(&d2, &[0, 3], &labels), None);
        assert_eq!(reconstruction_nn(&d[..1], &[0], &labels[..1]), None);
    }

    #[test]
    fn leave_one_out_accuracy_uses_the_nearest_other_object() {
        // Objects 0,1 (label a) close together, 2,3 (label b) close together; 4 (label a) is
        // nearest to 3 (label b): 4 of 5 hits.
        let pos = [0.0, 0.1, 5.0, 5.2, 5.5];
        let d: Vec<Vec<f64>> = pos
            .iter()
            .map(|x: &f64| pos.iter().map(|y| (x - y).abs()).collect())
            .collect();
        let labels: Vec<String> = ["a", "a", "b", "b", "a"].map(String::from).to_vec();
        assert_eq!(loo_nearest(&d), Some(vec![1, 0, 3, 2, 3]));
        assert_eq!(loo_label_accuracy(&d, &labels), Some(0.8));
        assert_eq!(loo_label_accuracy(&d[..1], &labels[..1]), None);
        assert_eq!(loo_label_accuracy(&d, &labels[..4]), None);
    }

    fn cloud(pts: &[[f32; 3]]) -> Cloud {
        Cloud::new(pts)
    }

    #[test]
    fn chamfer_agrees_with_a_plain_double_loop_on_odd_sizes() {
        let mut rng = Rng::new(9);
        let mut pts = |n: usize| -> Vec<[f32; 3]> {
            (0..n)
                .map(|_| [0, 1, 2].map(|_| rng.range(-1.0, 1.0) as f32))
                .collect()
        };
        let (a, b) = (pts(37), pts(19));
        let plain = |a: &[[f32; 3]], b: &[[f32; 3]]| -> f64 {
            a.iter()
                .map(|p| {
                    b.iter()
                        .map(|q| (0..3).map(|d| (p[d] - q[d]).powi(2)).sum::<f32>())
                        .fold(f32::INFINITY, f32::min) as f64
                })
                .sum::<f64>()
                / a.len() as f64
        };
        let want = plain(&a, &b) + plain(&b, &a);
        let got = chamfer(&Cloud::new(&a), &Cloud::new(&b));
        assert!((want - got).abs() < 1e-9, "{want} vs {got}");
    }

    #[test]
    fn surface_samples_follow_triangle_area_whatever_the_triangle_order() {
        // One big triangle (area 0.5 · 3 · 2 = 3) and fifteen small ones (area 1/15 each, total
        // 1) in the plane z = 0: 3/4 of the samples belong on the big one (a fresh draw per
        // binary-search probe, the old bug, put 37 % there).
        let mut mesh = TriMesh::default();
        for i in 0..15 {
            let x = 10.0 + i as f32;
            let base = mesh.positions.len() as u32;
            mesh.positions
                .extend([[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 2.0 / 15.0, 0.0]]);
            mesh.triangles.push([base, base + 1, base + 2]);
        }
        let base = mesh.positions.len() as u32;
        mesh.positions
            .extend([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 2.0, 0.0]]);
        mesh.triangles.push([base, base + 1, base + 2]);
        let n = 20_000;
        let pts = sample_meshes(&[mesh], n, &mut Rng::new(3));
        assert_eq!(pts.len(), n);
        let on_big = pts.iter().filter(|p| p[0] < 5.0).count() as f64 / n as f64;
        // Binomial standard deviation at n = 20 000 is 0.003.
        assert!(
            (on_big - 0.75).abs() < 0.015,
            "fraction on the big triangle {on_big}"
        );
        // Within the big triangle, uniform by area: 1/4 of its samples have x > 1.5.
        let big: Vec<_> = pts.iter().filter(|p| p[0] < 5.0).collect();
        let right = big.iter().filter(|p| p[0] > 1.5).count() as f64 / big.len() as f64;
        assert!(
            (right - 0.25).abs() < 0.02,
            "fraction beyond x = 1.5: {right}"
        );
    }

    #[test]
    fn chamfer_matches_a_hand_computation() {
        let a = cloud(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]);
        let b = cloud(&[[0.0, 0.0, 0.5]]);
        // a→b: 0.25 and 1.25, mean 0.75; b→a: 0.25.
        assert!((chamfer(&a, &b) - 1.0).abs() < 1e-9);
        assert_eq!(chamfer(&a, &a), 0.0);
        assert!((chamfer(&a, &b) - chamfer(&b, &a)).abs() < 1e-12);
    }

    fn fixture(name: &str) -> (ArticulatedObject, Vec<TriMesh>) {
        let obj = match name {
            "cabinet" => crate::fixtures::cabinet(),
            _ => crate::fixtures::eight_part(),
        };
        let meshes = mesh_parts(&obj, None, &MeshingOptions { resolution: 24 }).unwrap();
        (obj, meshes)
    }

    #[test]
    fn id_is_zero_for_identical_clouds_small_for_resampled_and_larger_across_objects() {
        let opts = IdOptions {
            states: 3,
            points: 256,
        };
        let (cab, cab_m) = fixture("cabinet");
        let a = state_clouds(&cab, &cab_m, &opts, 1).unwrap();
        assert_eq!(a.clouds.len(), 3);
        assert_eq!(a.clouds[0].len(), cab.parts.len());
        assert!(a.clouds[0].iter().all(|c| c.len() == 256));
        assert_eq!(instantiation_distance(&a, &a), 0.0);
        let a2 = state_clouds(&cab, &cab_m, &opts, 2).unwrap();
        let same = instantiation_distance(&a, &a2);
        // A shrunken copy is a different object.
        let mut small = cab.clone();
        for p in &mut small.parts {
            p.half_extents *= 0.5;
            p.center *= 0.5;
        }
        for j in &mut small.joints {
            j.origin.coords *= 0.5;
        }
        let small_m = mesh_parts(&small, None, &MeshingOptions { resolution: 24 }).unwrap();
        let b = state_clouds(&small, &small_m, &opts, 1).unwrap();
        let other = instantiation_distance(&a, &b);
        assert!(same < other / 5.0, "resampled {same} vs other {other}");
        assert!((instantiation_distance(&a, &b) - instantiation_distance(&b, &a)).abs() < 1e-12);
    }

    #[test]
    fn state_clouds_are_deterministic_and_rigid_per_part() {
        let opts = IdOptions {
            states: 2,
            points: 64,
        };
        let (cab, cab_m) = fixture("cabinet");
        assert_eq!(
            state_clouds(&cab, &cab_m, &opts, 5).unwrap(),
            state_clouds(&cab, &cab_m, &opts, 5).unwrap()
        );
        let bad = state_clouds(&cab, &cab_m[..1], &opts, 5).unwrap_err();
        assert!(bad.to_string().contains("meshes"), "{bad}");
        let e = IdOptions {
            states: 0,
            points: 64,
        }
        .validate()
        .unwrap_err();
        assert!(e.to_string().contains("states"), "{e}");
    }

    fn line_sets(gs: &[f64], refs: &[f64]) -> [Vec<Vec<f64>>; 3] {
        let d = |a: &[f64], b: &[f64]| -> Vec<Vec<f64>> {
            a.iter()
                .map(|x| b.iter().map(|y| (x - y).abs()).collect())
                .collect()
        };
        [d(gs, refs), d(gs, gs), d(refs, refs)]
    }

    #[test]
    fn metrics_on_points_of_a_line() {
        // Samples equal to the references: perfect coverage, zero MMD, 1-NNA 0 or 0.5 depending
        // on ties; samples far away: 1-NNA = 1.
        let refs = [0.0, 1.0, 2.0, 3.0];
        let [gr, gg, rr] = line_sets(&[0.1, 1.1, 2.1, 3.1], &refs);
        let m = distribution_metrics(&gr, &gg, &rr, MetricOrder::PointFlow).unwrap();
        assert!((m.mmd - 0.1).abs() < 1e-9, "{m:?}");
        assert_eq!(m.cov, 1.0);
        assert_eq!(m.one_nna, 0.0); // every point's nearest is its twin of the other set
        let [gr, gg, rr] = line_sets(&[100.0, 101.0, 102.0, 103.0], &refs);
        let m = distribution_metrics(&gr, &gg, &rr, MetricOrder::PointFlow).unwrap();
        assert_eq!(m.one_nna, 1.0);
        assert_eq!(m.cov, 0.25); // all samples pick the last reference
        assert!((m.mmd - (100.0 + 99.0 + 98.0 + 97.0) / 4.0).abs() < 1e-9);
    }

    #[test]
    fn nap_order_differs_from_pointflow_where_the_sets_are_asymmetric() {
        // Samples collapse onto one reference: PointFlow COV is low, NAP "COV" counts samples.
        let refs = [0.0, 10.0, 20.0];
        let gs = [0.0, 0.1, 0.2];
        let [gr, gg, rr] = line_sets(&gs, &refs);
        let pf = distribution_metrics(&gr, &gg, &rr, MetricOrder::PointFlow).unwrap();
        let nap = distribution_metrics(&gr, &gg, &rr, MetricOrder::Nap).unwrap();
        assert!((pf.cov - 1.0 / 3.0).abs() < 1e-12);
        assert!((pf.mmd - (0.0 + 9.8 + 19.8) / 3.0).abs() < 1e-9, "{pf:?}");
        assert!((nap.mmd - (0.0 + 0.1 + 0.2) / 3.0).abs() < 1e-9, "{nap:?}");
        // Refs 0 → sample 0, refs 10 and 20 → sample 0.2: two of three samples are "covered".
        assert!((nap.cov - 2.0 / 3.0).abs() < 1e-12, "{nap:?}");
        let e = distribution_metrics(
            &gr[..2],
            &gg[..2].iter().map(|r| r[..2].to_vec()).collect::<Vec<_>>(),
            &rr,
            MetricOrder::Nap,
        );
        assert!(e.is_err());
        let bad = distribution_metrics(&gr, &gg, &rr[..2], MetricOrder::PointFlow).unwrap_err();
        assert!(bad.to_string().contains("d_"), "{bad}");
    }

    #[test]
    fn validity_rule() {
        let (cab, cab_m) = fixture("cabinet");
        assert_eq!(invalid_reason(&cab, &cab_m), None);
        let mut empty = cab_m.clone();
        empty[1].triangles.clear();
        assert!(invalid_reason(&cab, &empty).unwrap().contains("part 1"));
        let mut one = cab.clone();
        one.parts.truncate(1);
        one.joints.clear();
        assert!(
            invalid_reason(&one, &cab_m[..1])
                .unwrap()
                .contains("at least 2")
        );
    }
}
