//! The generalised winding number's per-node data: dipole expansions of each node's triangles
//! (fast winding numbers, Barill et al. 2018) and the exact solid angle of one triangle.

#[allow(unused_imports)]
use super::*;

/// The f64 nearest to `x` that is an f32: expansion centres are stored as f32, so moments and
/// radii are taken about the rounded centre.
pub(crate) fn round_to_f32(x: f64) -> f64 {
    x as f32 as f64
}

/// Index pairs (j, k) of the six distinct entries of a symmetric 3×3 matrix.
pub(crate) const SYM: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];

/// Bottom-up winding-number expansion data (children always follow their parent in `nodes`,
/// so a reverse sweep sees children first).
pub(crate) fn build_winding_data(nodes: &[Node], tris: &[Tri]) -> Vec<WnNode> {
    /// (vector area, area, centroid) of a triangle; degenerate ones have zero area.
    pub(crate) fn tri_data(tri: &[V3; 3], degenerate: bool) -> (D3, f64, D3) {
        let [a, b, c] = tri.map(to64);
        let centroid = std::array::from_fn(|k| (a[k] + b[k] + c[k]) / 3.0);
        if degenerate {
            ([0.0; 3], 0.0, centroid)
        } else {
            let va = cross64(sub64(b, a), sub64(c, a)).map(|x| 0.5 * x);
            (va, norm64(va), centroid)
        }
    }
    let mut wn = vec![
        WnNode {
            center: [0.0; 3],
            far2: 0.0,
            n: [0.0; 3],
            c: [0.0; 9],
            d: [0.0; 18],
        };
        nodes.len()
    ];
    // Per node: total area and radius, kept in f64.
    let mut area = vec![0.0f64; nodes.len()];
    let mut radius = vec![0.0f64; nodes.len()];
    for ni in (0..nodes.len()).rev() {
        if ni == 1 {
            continue; // the unused slot
        }
        let node = &nodes[ni];
        let center: D3;
        let mut n = [0.0f64; 3];
        let mut c = [0.0f64; 9];
        let mut d = [0.0f64; 18];
        let mut r = 0.0f64;
        if node.count > 0 {
            let range = node.first as usize..(node.first + node.count) as usize;
            let data = |i: usize| tri_data(&tris[i].v, tris[i].n == [0.0; 3]);
            let (mut weighted, mut plain) = ([0.0f64; 3], [0.0f64; 3]);
            for i in range.clone() {
                let (_, a, centroid) = data(i);
                area[ni] += a;
                for k in 0..3 {
                    weighted[k] += a * centroid[k];
                    plain[k] += centroid[k];
                }
            }
            center = if area[ni] > 0.0 {
                weighted.map(|x| x / area[ni])
            } else {
                plain.map(|x| x / range.len() as f64)
            }
            .map(round_to_f32);
            for i in range {
                let (va, _, centroid) = data(i);
                let off = sub64(centroid, center);
                // ∫_t (x − p̃)(x − p̃)ᵀ dA / A_t = off·offᵀ + covariance of the uniform
                // triangle, (1/12) Σ_v (v − c)(v − c)ᵀ.
                let dv = tris[i].v.map(|v| sub64(to64(v), centroid));
                let second: [f64; 6] = SYM.map(|(j, k)| {
                    off[j] * off[k]
                        + (dv[0][j] * dv[0][k] + dv[1][j] * dv[1][k] + dv[2][j] * dv[2][k]) / 12.0
                });
                for a in 0..3 {
                    n[a] += va[a];
                    for j in 0..3 {
                        c[3 * a + j] += va[a] * off[j];
                    }
                    for s in 0..6 {
                        d[6 * a + s] += va[a] * second[s];
                    }
                }
                for v in tris[i].v {
                    r = r.max(norm64(sub64(to64(v), center)));
                }
            }
        } else {
            let (l, rr) = (node.first as usize, node.first as usize + 1);
            area[ni] = area[l] + area[rr];
            center = if area[ni] > 0.0 {
                std::array::from_fn(|k| {
                    (area[l] * wn[l].center[k] as f64 + area[rr] * wn[rr].center[k] as f64)
                        / area[ni]
                })
            } else {
                std::array::from_fn(|k| 0.5 * (wn[l].center[k] as f64 + wn[rr].center[k] as f64))
            }
            .map(round_to_f32);
            for ch in [l, rr] {
                // Shift the child's moments from its centre to ours: x − p̃ = (x − p̃_ch) + o.
                let w = &wn[ch];
                let o = sub64(to64(w.center), center);
                r = r.max(norm64(o) + radius[ch]);
                for a in 0..3 {
                    let na = w.n[a] as f64;
                    n[a] += na;
                    for j in 0..3 {
                        c[3 * a + j] += w.c[3 * a + j] as f64 + na * o[j];
                    }
                    for (s, &(j, k)) in SYM.iter().enumerate() {
                        d[6 * a + s] += w.d[6 * a + s] as f64
                            + w.c[3 * a + j] as f64 * o[k]
                            + w.c[3 * a + k] as f64 * o[j]
                            + na * o[j] * o[k];
                    }
                }
            }
            // Also bounded by the farthest corner of the node's box.
            let corner: D3 = std::array::from_fn(|k| {
                (center[k] - node.min[k] as f64).max(node.max[k] as f64 - center[k])
            });
            r = r.min(norm64(corner));
        }
        radius[ni] = r;
        // Round up so f32 storage never shrinks the "near" ball.
        let far = WN_BETA * r;
        wn[ni] = WnNode {
            center: center.map(|x| x as f32),
            far2: ((far * far) * (1.0 + 1e-6)) as f32,
            n: n.map(|x| x as f32),
            c: c.map(|x| x as f32),
            d: d.map(|x| x as f32),
        };
    }
    wn
}

// ---------------------------------------------------------------------------------------------
// Primitive queries

/// Solid angle subtended by a far node: its Taylor expansion about p̃ to third order.
/// `y` = p̃ − q, `d2` = |y|².
///
/// With G(x) = (x − q)/|x − q|³, Ω = ∫ n·G dA ≈ N·G + C_ij ∂_j G_i + ½ D_ijk ∂_j∂_k G_i:
/// ∂_j G_i = δ_ij/r³ − 3 y_i y_j/r⁵ and
/// ∂_j∂_k G_i = −3(δ_ik y_j + δ_ij y_k + δ_jk y_i)/r⁵ + 15 y_i y_j y_k/r⁷.
#[inline]
pub(crate) fn expansion(w: &WnNode, y: D3, d2: f64) -> f64 {
    let inv_r2 = 1.0 / d2;
    let inv_r3 = inv_r2 / d2.sqrt();
    // First order (dipole).
    let mut omega = dot64(to64(w.n), y);
    // Second order.
    let c = w.c.map(|x| x as f64);
    let mut ycy = 0.0;
    for a in 0..3 {
        ycy += y[a] * (c[3 * a] * y[0] + c[3 * a + 1] * y[1] + c[3 * a + 2] * y[2]);
    }
    omega += c[0] + c[4] + c[8] - 3.0 * ycy * inv_r2;
    // Third order.
    let (mut row, mut trace, mut cubic) = (0.0f64, 0.0f64, 0.0f64);
    for a in 0..3 {
        let [xx, yy, zz, xy, xz, yz]: [f64; 6] = std::array::from_fn(|s| w.d[6 * a + s] as f64);
        let my = [
            xx * y[0] + xy * y[1] + xz * y[2],
            xy * y[0] + yy * y[1] + yz * y[2],
            xz * y[0] + yz * y[1] + zz * y[2],
        ];
        row += my[a];
        trace += y[a] * (xx + yy + zz);
        cubic += y[a] * dot64(y, my);
    }
    omega += 0.5 * (15.0 * cubic * inv_r2 - 3.0 * (2.0 * row + trace)) * inv_r2;
    omega * inv_r3
}

/// Signed solid angle of triangle (a, b, c) seen from q (Van Oosterom–Strackee), positive when
/// q is on the back (inner) side of a CCW triangle.
#[inline]
pub(crate) fn solid_angle(q: D3, a: V3, b: V3, c: V3) -> f64 {
    let a = sub64(to64(a), q);
    let b = sub64(to64(b), q);
    let c = sub64(to64(c), q);
    let (la, lb, lc) = (norm64(a), norm64(b), norm64(c));
    let det = dot64(a, cross64(b, c));
    let denom = la * lb * lc + dot64(a, b) * lc + dot64(a, c) * lb + dot64(b, c) * la;
    2.0 * det.atan2(denom)
}
