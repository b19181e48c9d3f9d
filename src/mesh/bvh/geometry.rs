//! Geometric primitives of the BVH's queries: rays, ray–triangle and ray–box tests, the closest
//! point on a triangle, and small vector helpers in f32 and f64.

#[allow(unused_imports)]
use super::*;

/// A ray prepared for the watertight triangle test: the direction's dominant axis becomes z
/// and a shear maps the direction onto +z, so every triangle test is a 2D point-in-triangle
/// test at the origin.
pub(crate) struct Ray {
    pub(crate) o: V3,
    /// Axis permutation: kz is the direction's largest component; kx, ky keep the winding.
    pub(crate) k: [usize; 3],
    /// Shear constants (d_kx / d_kz, d_ky / d_kz, 1 / d_kz).
    pub(crate) s: V3,
}

impl Ray {
    /// `d` must be finite and non-zero.
    pub(crate) fn new(o: V3, d: V3) -> Ray {
        let kz = if d[0].abs() >= d[1].abs() && d[0].abs() >= d[2].abs() {
            0
        } else if d[1].abs() >= d[2].abs() {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Ray {
            o,
            k: [kx, ky, kz],
            s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]],
        }
    }
}

/// Watertight ray–triangle test of Woop, Benthin and Wald, "Watertight Ray/Triangle
/// Intersection" (JCGT 2013): (t, u, v) of a hit with t in (t_lo, t_hi), where
/// point = (1 − u − v)·a + u·b + v·c.
///
/// The two triangles sharing an edge compute its edge function from the same transformed
/// vertices (exactly negated), so a ray can never slip between them, which Möller–Trumbore
/// does not guarantee. Edge functions that come out exactly zero are recomputed in f64, as
/// the paper prescribes.
#[inline(always)]
pub(crate) fn intersect_triangle(
    ray: &Ray,
    a: V3,
    b: V3,
    c: V3,
    t_lo: f32,
    t_hi: f32,
) -> Option<(f32, f32, f32)> {
    let [kx, ky, kz] = ray.k;
    let [sx, sy, sz] = ray.s;
    let (a, b, c) = (sub(a, ray.o), sub(b, ray.o), sub(c, ray.o));
    let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
    let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
    let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        let e = |px: f32, py: f32, qx: f32, qy: f32| {
            (px as f64 * qy as f64 - py as f64 * qx as f64) as f32
        };
        u = e(cx, cy, bx, by);
        v = e(ax, ay, cx, cy);
        w = e(bx, by, ax, ay);
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let t = (u * (sz * a[kz]) + v * (sz * b[kz]) + w * (sz * c[kz])) * inv;
    (t > t_lo && t < t_hi).then_some((t, v * inv, w * inv))
}

/// Slab test: the entry distance when the ray meets the box within (t_lo, t_hi), else +∞.
#[inline(always)]
pub(crate) fn ray_box(n: &Node, o: V3, inv: V3, t_lo: f32, t_hi: f32) -> f32 {
    let t0: V3 = std::array::from_fn(|k| (n.min[k] - o[k]) * inv[k]);
    let t1: V3 = std::array::from_fn(|k| (n.max[k] - o[k]) * inv[k]);
    let near = fmax(
        fmax(fmin(t0[0], t1[0]), fmin(t0[1], t1[1])),
        fmax(fmin(t0[2], t1[2]), t_lo),
    );
    let far = fmin(
        fmin(fmax(t0[0], t1[0]), fmax(t0[1], t1[1])),
        fmax(t0[2], t1[2]),
    );
    let far = fmin(far + far.abs() * SLAB_SLACK, t_hi);
    if near <= far { near } else { f32::INFINITY }
}

/// Squared distance from p to the node's box (0 inside).
#[inline(always)]
pub(crate) fn box_dist2(n: &Node, p: V3) -> f32 {
    let d: V3 = std::array::from_fn(|k| fmax(fmax(n.min[k] - p[k], p[k] - n.max[k]), 0.0));
    dot(d, d)
}

/// Closest point on triangle (a, b, c) to p (Ericson, RTCD §5.1.5). Degenerate triangles are
/// treated as their three edges. Computed in f64: the region tests use differences of products
/// (d1·d4 − d3·d2, ...) that cancel catastrophically in f32 on long sliver triangles (a
/// 32-sided cylinder's side faces), which put "closest" points 0.3 mm off the surface.
#[inline]
pub(crate) fn closest_on_triangle(p: V3, a: V3, b: V3, c: V3, degenerate: bool) -> V3 {
    if degenerate {
        return closest_on_edges(p, a, b, c);
    }
    let (p64, a64, b64, c64) = (to64(p), to64(a), to64(b), to64(c));
    let lerp = |o: D3, e: D3, t: f64| -> V3 {
        [
            (o[0] + e[0] * t) as f32,
            (o[1] + e[1] * t) as f32,
            (o[2] + e[2] * t) as f32,
        ]
    };
    let ab = sub64(b64, a64);
    let ac = sub64(c64, a64);
    let ap = sub64(p64, a64);
    let d1 = dot64(ab, ap);
    let d2 = dot64(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub64(p64, b64);
    let d3 = dot64(ab, bp);
    let d4 = dot64(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return guard(lerp(a64, ab, v), p, a, b, c);
    }
    let cp = sub64(p64, c64);
    let d5 = dot64(ab, cp);
    let d6 = dot64(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return guard(lerp(a64, ac, w), p, a, b, c);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return guard(lerp(b64, sub64(c64, b64), w), p, a, b, c);
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    let q = [
        a64[0] + ab[0] * v + ac[0] * w,
        a64[1] + ab[1] * v + ac[1] * w,
        a64[2] + ab[2] * v + ac[2] * w,
    ];
    guard([q[0] as f32, q[1] as f32, q[2] as f32], p, a, b, c)
}

/// Falls back to the edges if rounding produced a non-finite point.
#[inline]
pub(crate) fn guard(q: V3, p: V3, a: V3, b: V3, c: V3) -> V3 {
    if q.iter().all(|x| x.is_finite()) {
        q
    } else {
        closest_on_edges(p, a, b, c)
    }
}

pub(crate) fn closest_on_edges(p: V3, a: V3, b: V3, c: V3) -> V3 {
    let mut best = a;
    let mut best_d2 = dist2(p, a);
    for (s, e) in [(a, b), (b, c), (c, a)] {
        let q = closest_on_segment(p, s, e);
        let d2 = dist2(p, q);
        if d2 < best_d2 {
            best = q;
            best_d2 = d2;
        }
    }
    best
}

pub(crate) fn closest_on_segment(p: V3, a: V3, b: V3) -> V3 {
    let ab = sub(b, a);
    let l2 = dot(ab, ab);
    if l2.is_nan() || l2 <= 0.0 {
        return a;
    }
    let t = (dot(sub(p, a), ab) / l2).clamp(0.0, 1.0);
    add(a, scale(ab, t))
}

/// Unit normal of a CCW triangle, or zero when the triangle is degenerate.
pub(crate) fn unit_normal(a: V3, b: V3, c: V3) -> V3 {
    let (a, b, c) = (to64(a), to64(b), to64(c));
    let e1 = sub64(b, a);
    let e2 = sub64(c, a);
    let n = cross64(e1, e2);
    let n2 = dot64(n, n);
    if n2.is_nan() || n2 <= DEGENERATE_SIN2 * dot64(e1, e1) * dot64(e2, e2) {
        return [0.0; 3];
    }
    let len = n2.sqrt();
    n.map(|x| (x / len) as f32)
}

// ---------------------------------------------------------------------------------------------
// Small vector helpers

#[inline(always)]
pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
pub(crate) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline(always)]
pub(crate) fn scale(a: V3, s: f32) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline(always)]
pub(crate) fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline(always)]
pub(crate) fn dist2(a: V3, b: V3) -> f32 {
    let d = sub(a, b);
    dot(d, d)
}

#[inline(always)]
pub(crate) fn to64(a: V3) -> D3 {
    [a[0] as f64, a[1] as f64, a[2] as f64]
}

#[inline(always)]
pub(crate) fn sub64(a: D3, b: D3) -> D3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
pub(crate) fn dot64(a: D3, b: D3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline(always)]
pub(crate) fn cross64(a: D3, b: D3) -> D3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline(always)]
pub(crate) fn norm64(a: D3) -> f64 {
    dot64(a, a).sqrt()
}
