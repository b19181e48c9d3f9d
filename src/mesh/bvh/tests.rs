//! Tests of the BVH's queries against brute force.

use super::*;
use proptest::prelude::*;
use std::sync::LazyLock;

type Mesh = (Vec<V3>, Vec<[u32; 3]>);

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// SplitMix64: deterministic uniform numbers for the tests.
struct Rng(u64);

impl Rng {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    fn point(&mut self, lo: V3, hi: V3) -> V3 {
        std::array::from_fn(|k| lo[k] + (hi[k] - lo[k]) * self.next_f64() as f32)
    }
}

/// Axis-aligned box, 12 CCW (outward) triangles; triangles 2k and 2k+1 form face k in the
/// order −x, +x, −y, +y, −z, +z.
fn box_mesh(lo: V3, hi: V3) -> Mesh {
    let positions = (0..8)
        .map(|i| {
            [
                if i & 1 == 0 { lo[0] } else { hi[0] },
                if i & 2 == 0 { lo[1] } else { hi[1] },
                if i & 4 == 0 { lo[2] } else { hi[2] },
            ]
        })
        .collect();
    let quads = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    let triangles = quads
        .iter()
        .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
        .collect();
    (positions, triangles)
}

const FACE_NORMALS: [V3; 6] = [
    [-1.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, -1.0],
    [0.0, 0.0, 1.0],
];

fn union(meshes: &[Mesh]) -> Mesh {
    let mut out: Mesh = (Vec::new(), Vec::new());
    for (p, t) in meshes {
        let base = out.0.len() as u32;
        out.0.extend_from_slice(p);
        out.1.extend(t.iter().map(|tri| tri.map(|i| i + base)));
    }
    out
}

/// UV sphere with `segs` × `rings`, oriented outward.
fn uv_sphere(center: V3, r: f32, segs: u32, rings: u32) -> Mesh {
    use std::f32::consts::PI;
    let mut positions = vec![add(center, [0.0, 0.0, r])];
    for i in 1..rings {
        let th = PI * i as f32 / rings as f32;
        for j in 0..segs {
            let ph = 2.0 * PI * j as f32 / segs as f32;
            let d = [th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()];
            positions.push(add(center, scale(d, r)));
        }
    }
    positions.push(add(center, [0.0, 0.0, -r]));
    let south = positions.len() as u32 - 1;
    let ring = |i: u32, j: u32| 1 + (i - 1) * segs + j % segs;
    let mut triangles = Vec::new();
    for j in 0..segs {
        triangles.push([0, ring(1, j), ring(1, j + 1)]);
        triangles.push([south, ring(rings - 1, j + 1), ring(rings - 1, j)]);
        for i in 1..rings - 1 {
            let (a, b) = (ring(i, j), ring(i, j + 1));
            let (c, d) = (ring(i + 1, j), ring(i + 1, j + 1));
            triangles.push([a, c, d]);
            triangles.push([a, d, b]);
        }
    }
    for t in &mut triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let centroid = scale(add(a, add(b, c)), 1.0 / 3.0);
        if dot(cross(sub(b, a), sub(c, a)), sub(centroid, center)) < 0.0 {
            t.swap(1, 2);
        }
    }
    (positions, triangles)
}

fn bvh(m: &Mesh) -> MeshBvh {
    MeshBvh::new(&m.0, &m.1).unwrap()
}

static CUBE: LazyLock<(Mesh, MeshBvh)> = LazyLock::new(|| {
    let m = box_mesh([0.0; 3], [1.0; 3]);
    let b = bvh(&m);
    (m, b)
});

static SPHERE: LazyLock<(Mesh, MeshBvh)> = LazyLock::new(|| {
    let m = uv_sphere([0.0; 3], 1.0, 32, 16);
    let b = bvh(&m);
    (m, b)
});

fn box_sdf(p: V3, lo: V3, hi: V3) -> f32 {
    let q: V3 =
        std::array::from_fn(|k| (p[k] - 0.5 * (lo[k] + hi[k])).abs() - 0.5 * (hi[k] - lo[k]));
    let outside = q.map(|x| x.max(0.0));
    dot(outside, outside).sqrt() + q[0].max(q[1]).max(q[2]).min(0.0)
}

fn brute_closest(m: &Mesh, p: V3) -> Option<f32> {
    m.1.iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.0[i as usize]);
            let degenerate = unit_normal(a, b, c) == [0.0; 3];
            dist2(p, closest_on_triangle(p, a, b, c, degenerate))
        })
        .min_by(f32::total_cmp)
}

fn brute_ray(m: &Mesh, o: V3, d: V3, t_min: f32, t_max: f32) -> Option<f32> {
    m.1.iter()
        .filter_map(|t| {
            let [a, b, c] = t.map(|i| m.0[i as usize]);
            if unit_normal(a, b, c) == [0.0; 3] {
                return None;
            }
            intersect_triangle(&Ray::new(o, d), a, b, c, t_min, t_max).map(|h| h.0)
        })
        .min_by(f32::total_cmp)
}

fn exact_winding(m: &Mesh, p: V3) -> f64 {
    let q = to64(p);
    let s: f64 =
        m.1.iter()
            .map(|t| t.map(|i| m.0[i as usize]))
            .filter(|&[a, b, c]| unit_normal(a, b, c) != [0.0; 3])
            .map(|[a, b, c]| solid_angle(q, a, b, c))
            .sum();
    s / (4.0 * std::f64::consts::PI)
}

fn assert_close(a: V3, b: V3, tol: f32) {
    assert!(
        dist2(a, b).sqrt() <= tol,
        "{a:?} vs {b:?} (tolerance {tol})"
    );
}

#[test]
fn fixtures_are_closed_and_outward() {
    for m in [&CUBE.0, &SPHERE.0] {
        let volume: f64 =
            m.1.iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| to64(m.0[i as usize]));
                    dot64(a, cross64(b, c)) / 6.0
                })
                .sum();
        assert!(volume > 0.0, "fixture is inward: volume {volume}");
    }
    let (m, _) = &*CUBE;
    for (t, tri) in m.1.iter().enumerate() {
        let [a, b, c] = tri.map(|i| m.0[i as usize]);
        assert_eq!(unit_normal(a, b, c), FACE_NORMALS[t / 2], "triangle {t}");
    }
    assert!((CUBE.1.total_area() - 6.0).abs() < 1e-12);
}

#[test]
fn cube_rays_from_outside_hit_the_right_face_at_the_right_t() {
    let (_, b) = &*CUBE;
    let center = [0.5f32; 3];
    for (face, &n) in FACE_NORMALS.iter().enumerate() {
        // Start 3 units out along the face normal, off-centre within the face.
        let off: V3 = std::array::from_fn(|k| {
            if n[k] == 0.0 {
                0.13 * (k as f32 + 1.0)
            } else {
                0.0
            }
        });
        let o = add(add(center, scale(n, 3.0)), off);
        for (len, expected_t) in [(1.0f32, 2.5f32), (2.0, 1.25), (0.25, 10.0)] {
            let d = scale(n, -len);
            let h = b.ray_hit(o, d, 0.0, f32::INFINITY).expect("must hit");
            assert!(
                (h.t - expected_t).abs() < 1e-5,
                "face {face}: t {} vs {expected_t}",
                h.t
            );
            assert_eq!(h.normal, n, "face {face}");
            assert_eq!(h.triangle as usize / 2, face, "face {face}");
            let p = add(o, scale(d, h.t));
            let tri = CUBE.0.1[h.triangle as usize].map(|i| CUBE.0.0[i as usize]);
            let [u, v] = h.uv;
            assert!(u >= 0.0 && v >= 0.0 && u + v <= 1.0);
            let from_uv: V3 =
                std::array::from_fn(|k| (1.0 - u - v) * tri[0][k] + u * tri[1][k] + v * tri[2][k]);
            assert_close(p, from_uv, 1e-5);
            assert!(b.ray_occluded(o, d, 0.0, f32::INFINITY));
        }
    }
}

#[test]
fn cube_rays_from_inside_hit_the_far_face() {
    let (_, b) = &*CUBE;
    let o = [0.4, 0.55, 0.3];
    for (face, &n) in FACE_NORMALS.iter().enumerate() {
        let h = b.ray_hit(o, n, 0.0, f32::INFINITY).expect("must hit");
        let k = n.iter().position(|&x| x != 0.0).unwrap();
        let expected = if n[k] > 0.0 { 1.0 - o[k] } else { o[k] };
        assert!(
            (h.t - expected).abs() < 1e-6,
            "face {face}: {} vs {expected}",
            h.t
        );
        assert_eq!(h.triangle as usize / 2, face);
        assert_eq!(h.normal, n);
    }
}

#[test]
fn rays_aimed_at_vertices_and_edges_never_slip_through() {
    // Watertightness: from far outside, aim at every vertex and every edge midpoint of a
    // closed sphere; each ray must hit the surface at t ≈ 1.
    let (m, b) = &*SPHERE;
    let mut rng = Rng(21);
    let mut targets: Vec<V3> = m.0.clone();
    for t in &m.1 {
        for e in 0..3 {
            let (p, q) = (m.0[t[e] as usize], m.0[t[(e + 1) % 3] as usize]);
            targets.push(scale(add(p, q), 0.5));
        }
    }
    for target in targets {
        for _ in 0..4 {
            // An origin 2–8 radii out, within ~30° of the outward normal at the target.
            let jitter = rng.point([-0.3; 3], [0.3; 3]);
            let out = add(scale(target, 1.0 / dot(target, target).sqrt()), jitter);
            let o = add(target, scale(out, 2.0 + 6.0 * rng.next_f64() as f32));
            let d = sub(target, o);
            let h = b.ray_hit(o, d, 0.0, f32::INFINITY);
            let h = h.unwrap_or_else(|| panic!("ray {o:?} → {target:?} slipped through"));
            assert!((h.t - 1.0).abs() < 1e-3, "t = {}", h.t);
            assert!(b.ray_occluded(o, d, 0.0, f32::INFINITY));
        }
    }
}

#[test]
fn cube_rays_that_miss_miss() {
    let (_, b) = &*CUBE;
    let cases: [(V3, V3); 6] = [
        ([-1.0, 1.5, 0.5], [1.0, 0.0, 0.0]),   // passes above
        ([-1.0, 0.5, 0.5], [-1.0, 0.0, 0.0]),  // points away
        ([2.0, 2.0, 2.0], [1.0, 1.0, 1.0]),    // points away diagonally
        ([-1.0, -1.0, 0.5], [1.0, -0.1, 0.0]), // diverges
        ([0.5, 0.5, 3.0], [0.0, 0.0, 0.0]),    // zero direction
        ([0.5, 0.5, 3.0], [0.0, f32::NAN, -1.0]),
    ];
    for (o, d) in cases {
        assert_eq!(b.ray_hit(o, d, 0.0, f32::INFINITY), None, "{o:?} {d:?}");
        assert!(!b.ray_occluded(o, d, 0.0, f32::INFINITY));
    }
}

#[test]
fn cube_t_range_is_respected() {
    let (_, b) = &*CUBE;
    let o = [-1.0, 0.3, 0.6];
    let d = [1.0, 0.0, 0.0];
    // Near face (−x) at t = 1, far face (+x) at t = 2.
    assert_eq!(b.ray_hit(o, d, 0.0, 0.99), None);
    assert!(!b.ray_occluded(o, d, 0.0, 0.99));
    let h = b.ray_hit(o, d, 0.0, 1.5).unwrap();
    assert!((h.t - 1.0).abs() < 1e-6 && h.normal == [-1.0, 0.0, 0.0]);
    let h = b.ray_hit(o, d, 1.01, 10.0).unwrap();
    assert!((h.t - 2.0).abs() < 1e-6 && h.normal == [1.0, 0.0, 0.0]);
    assert_eq!(b.ray_hit(o, d, 2.01, 10.0), None);
    assert_eq!(b.ray_hit(o, d, 1.01, 1.99), None);
    assert!(!b.ray_occluded(o, d, 2.01, 10.0));
    assert_eq!(b.ray_hit(o, d, 5.0, 1.0), None, "empty interval");
    // The interval is open: hits exactly at t_min or t_max (t = 1 and t = 2 are exact in
    // f32 here) do not count.
    let h = b.ray_hit(o, d, 1.0, 10.0).unwrap();
    assert_eq!((h.t, h.normal), (2.0, [1.0, 0.0, 0.0]));
    assert_eq!(b.ray_hit(o, d, 0.0, 1.0), None);
    assert_eq!(b.ray_hit(o, d, 1.0, 2.0), None);
    assert!(!b.ray_occluded(o, d, 1.0, 2.0));
    // A negative t range reaches backwards; the closest hit is the smallest t (x = 0).
    let h = b.ray_hit([3.0, 0.3, 0.6], d, -10.0, 0.0).unwrap();
    assert!(
        (h.t + 3.0).abs() < 1e-6 && h.normal == [-1.0, 0.0, 0.0],
        "{h:?}"
    );
    let h = b.ray_hit([3.0, 0.3, 0.6], d, -2.5, 0.0).unwrap();
    assert!(
        (h.t + 2.0).abs() < 1e-6 && h.normal == [1.0, 0.0, 0.0],
        "{h:?}"
    );
}

#[test]
fn degenerate_triangles_are_never_hit_but_count_for_closest_points() {
    let positions = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    // A collinear triangle and a repeated-vertex triangle.
    let triangles = vec![[0, 1, 2], [3, 3, 1]];
    let b = MeshBvh::new(&positions, &triangles).unwrap();
    assert_eq!(b.triangle_count(), 2);
    for o in [[0.5, 0.0, 1.0], [1.5, 0.0, 1.0], [0.5, 0.5, 1.0]] {
        assert_eq!(b.ray_hit(o, [0.0, 0.0, -1.0], 0.0, f32::INFINITY), None);
    }
    let (q, d2, t) = b.closest_point([1.5, -1.0, 0.0]).unwrap();
    assert_close(q, [1.5, 0.0, 0.0], 1e-6);
    assert!((d2 - 1.0).abs() < 1e-6 && t == 0);
    let (q, _, t) = b.closest_point([0.0, 2.0, 0.0]).unwrap();
    assert_close(q, [0.0, 1.0, 0.0], 1e-6);
    assert_eq!(t, 1);
    assert_eq!(b.winding_number([0.5, 0.1, 0.0]), 0.0);
    assert_eq!(b.total_area(), 0.0);
    let mut calls = 0;
    assert!(
        b.sample_surface(10, &mut || {
            calls += 1;
            0.5
        })
        .is_empty()
    );
    assert_eq!(calls, 0);
}

#[test]
fn closest_on_triangle_agrees_with_dense_sampling() {
    let mut rng = Rng(7);
    for _ in 0..200 {
        let [a, b, c] = [0; 3].map(|_| rng.point([-1.0; 3], [1.0; 3]));
        let p = rng.point([-2.0; 3], [2.0; 3]);
        let q = closest_on_triangle(p, a, b, c, unit_normal(a, b, c) == [0.0; 3]);
        let n = 60;
        let mut best = f32::INFINITY;
        for i in 0..=n {
            for j in 0..=n - i {
                let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                let s: V3 = std::array::from_fn(|k| (1.0 - u - v) * a[k] + u * b[k] + v * c[k]);
                best = best.min(dist2(p, s).sqrt());
            }
        }
        let d = dist2(p, q).sqrt();
        let spacing = [dist2(a, b), dist2(b, c), dist2(c, a)]
            .iter()
            .fold(0.0f32, |m, x| m.max(x.sqrt()))
            / n as f32;
        assert!(d <= best + 1e-5, "{d} > sampled {best}");
        assert!(d >= best - spacing, "{d} far below sampled {best}");
        // q lies in the triangle's plane and inside it.
        let nrm = unit_normal(a, b, c);
        assert!(dot(nrm, sub(q, a)).abs() < 1e-5);
    }
}

fn soup_strategy() -> impl Strategy<Value = Mesh> {
    prop::collection::vec(
        prop::array::uniform3(prop::array::uniform3(-1.0f32..1.0)),
        1..10,
    )
    .prop_map(|tris| {
        let positions: Vec<V3> = tris.iter().flatten().copied().collect();
        let triangles = (0..tris.len() as u32)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect();
        (positions, triangles)
    })
}

fn check_ray(m: &Mesh, b: &MeshBvh, o: V3, d: V3, t_min: f32, t_max: f32) {
    let hit = b.ray_hit(o, d, t_min, t_max);
    assert_eq!(
        b.ray_occluded(o, d, t_min, t_max),
        hit.is_some(),
        "occluded disagrees with ray_hit: {o:?} {d:?} ({t_min}, {t_max})"
    );
    let brute = brute_ray(m, o, d, t_min, t_max);
    match (hit, brute) {
        (None, None) => {}
        (Some(h), Some(t)) => {
            assert!(
                (h.t - t).abs() <= 1e-5 * (1.0 + t.abs()),
                "{} vs brute {t}",
                h.t
            );
            assert!(h.t > t_min && h.t < t_max);
            let p = add(o, scale(d, h.t));
            let tri = m.1[h.triangle as usize].map(|i| m.0[i as usize]);
            assert!(
                dot(h.normal, sub(p, tri[0])).abs() < 1e-4,
                "hit point off its triangle"
            );
        }
        (h, t) => panic!("BVH {h:?} vs brute force {t:?}: {o:?} {d:?}"),
    }
}

fn check_closest(m: &Mesh, b: &MeshBvh, p: V3) {
    let (q, d2, t) = b.closest_point(p).unwrap();
    let brute = brute_closest(m, p).unwrap();
    assert!(
        (d2 - brute).abs() <= 1e-6 * (1.0 + brute),
        "{d2} vs brute {brute} at {p:?}"
    );
    assert!((dist2(p, q) - d2).abs() <= 1e-6 * (1.0 + d2));
    // The reported point lies on the reported triangle (f64 least-squares barycentrics;
    // tolerances allow for f32 rounding on sliver triangles).
    let [a, bb, c] = m.1[t as usize].map(|i| to64(m.0[i as usize]));
    let (e1, e2, r) = (sub64(bb, a), sub64(c, a), sub64(to64(q), a));
    let (g11, g12, g22) = (dot64(e1, e1), dot64(e1, e2), dot64(e2, e2));
    let det = g11 * g22 - g12 * g12;
    if det > 1e-12 * g11 * g22 {
        let (r1, r2) = (dot64(r, e1), dot64(r, e2));
        let u = (g22 * r1 - g12 * r2) / det;
        let v = (g11 * r2 - g12 * r1) / det;
        let eps = 1e-4;
        assert!(
            u >= -eps && v >= -eps && u + v <= 1.0 + eps,
            "({u}, {v}) off triangle {t}"
        );
        let res: D3 = std::array::from_fn(|k| r[k] - u * e1[k] - v * e2[k]);
        assert!(
            norm64(res) < 1e-5,
            "point {res:?} off the plane of triangle {t}"
        );
    }
}

proptest! {
    #[test]
    fn occluded_and_hit_agree_with_brute_force_on_closed_meshes(
        o in prop::array::uniform3(-2.0f32..3.0),
        d in prop::array::uniform3(-1.0f32..1.0),
        t_min in -1.0f32..1.0,
        span in 0.0f32..6.0,
        sphere in any::<bool>(),
    ) {
        let (m, b) = if sphere { &*SPHERE } else { &*CUBE };
        check_ray(m, b, o, d, t_min, t_min + span);
        check_ray(m, b, o, d, 0.0, f32::INFINITY);
    }

    #[test]
    fn rays_agree_with_brute_force_on_triangle_soups(
        m in soup_strategy(),
        o in prop::array::uniform3(-2.0f32..2.0),
        target in prop::array::uniform3(-1.0f32..1.0),
    ) {
        let b = bvh(&m);
        check_ray(&m, &b, o, sub(target, o), 0.0, f32::INFINITY);
        check_ray(&m, &b, o, sub(target, o), 0.0, 0.5);
    }

    #[test]
    fn closest_point_agrees_with_brute_force(
        p in prop::array::uniform3(-2.5f32..2.5),
        which in 0u8..2,
    ) {
        let (m, b) = if which == 0 { &*SPHERE } else { &*CUBE };
        check_closest(m, b, p);
    }

    #[test]
    fn closest_point_agrees_with_brute_force_on_triangle_soups(
        m in soup_strategy(),
        p in prop::array::uniform3(-2.0f32..2.0),
    ) {
        let b = bvh(&m);
        check_closest(&m, &b, p);
        let w = b.winding_number(p) as f64;
        let exact = exact_winding(&m, p);
        prop_assert!((w - exact).abs() < 0.05, "winding {w} vs exact {exact}");
    }
}

#[test]
fn winding_number_of_a_sphere_is_one_inside_and_zero_outside() {
    let (m, b) = &*SPHERE;
    let mut rng = Rng(11);
    let (mut inside, mut outside, mut worst) = (0, 0, 0.0f32);
    while inside + outside < 4000 {
        let p = rng.point([-1.6; 3], [1.6; 3]);
        let r = dot(p, p).sqrt();
        if (r - 1.0).abs() <= 0.02 {
            continue;
        }
        let w = b.winding_number(p);
        let expected = if r < 1.0 { 1.0 } else { 0.0 };
        worst = worst.max((w - expected).abs());
        assert!((w - expected).abs() < 0.05, "w = {w} at r = {r}");
        assert_eq!(b.is_inside(p), r < 1.0);
        if r < 1.0 {
            inside += 1
        } else {
            outside += 1
        }
        if inside + outside < 300 {
            let exact = exact_winding(m, p);
            assert!(
                (exact - expected as f64).abs() < 1e-6,
                "exact {exact} at r = {r}"
            );
        }
    }
    assert!(inside > 500 && outside > 500);
    eprintln!("sphere: worst |w - expected| = {worst:e}");
}

#[test]
fn hierarchical_winding_number_is_close_to_exact_summation() {
    let sphere = uv_sphere([0.1, -0.2, 0.05], 0.7, 48, 24);
    let boxes = union(&[
        box_mesh([0.0; 3], [1.0, 0.5, 0.5]),
        box_mesh([0.3, 0.2, 0.1], [0.8, 1.0, 0.6]),
        sphere,
    ]);
    let b = bvh(&boxes);
    let mut rng = Rng(5);
    let mut worst = 0.0f64;
    for _ in 0..1500 {
        let p = rng.point([-1.0; 3], [1.5; 3]);
        let err = (b.winding_number(p) as f64 - exact_winding(&boxes, p)).abs();
        worst = worst.max(err);
    }
    eprintln!("hierarchical vs exact: worst error {worst:e}");
    assert!(worst < 0.01, "worst error {worst}");
}

#[test]
fn winding_number_counts_overlapping_closed_meshes() {
    let m = union(&[
        box_mesh([0.0; 3], [1.0; 3]),
        box_mesh([0.5, 0.3, 0.2], [1.5, 1.3, 1.2]),
    ]);
    let b = bvh(&m);
    for (p, expected) in [
        ([0.75, 0.6, 0.6], 2.0),
        ([0.25, 0.5, 0.5], 1.0),
        ([1.25, 0.8, 0.8], 1.0),
        ([2.0, 0.5, 0.5], 0.0),
        ([-0.5, -0.5, -0.5], 0.0),
    ] {
        let w = b.winding_number(p);
        assert!(
            (w - expected).abs() < 0.05,
            "w({p:?}) = {w}, expected {expected}"
        );
    }
}

#[test]
fn winding_number_degrades_gracefully_on_open_meshes() {
    // Unit cube without its +z face: the centre sees 5/6 of the full solid angle.
    let (p, mut t) = box_mesh([0.0; 3], [1.0; 3]);
    t.truncate(10);
    let b = MeshBvh::new(&p, &t).unwrap();
    let w = b.winding_number([0.5; 3]);
    assert!((w - 5.0 / 6.0).abs() < 1e-3, "{w}");
    assert!(b.is_inside([0.5, 0.5, 0.3]));
    assert!(!b.is_inside([0.5, 0.5, 2.0]));
}

#[test]
fn is_inside_matches_the_union_of_three_boxes() {
    let boxes = [
        ([0.0, 0.0, 0.0], [1.0, 0.5, 0.5]),
        ([0.3, 0.2, 0.1], [0.8, 1.0, 0.6]),
        ([0.5, 0.1, 0.3], [1.2, 0.4, 0.9]),
    ];
    let m = union(&boxes.map(|(lo, hi)| box_mesh(lo, hi)));
    let b = bvh(&m);
    let mut rng = Rng(3);
    let n = 20_000;
    let agree = (0..n)
        .filter(|_| {
            let p = rng.point([0.0; 3], [1.2, 1.0, 0.9]);
            let sdf = boxes
                .iter()
                .map(|&(lo, hi)| box_sdf(p, lo, hi))
                .fold(f32::INFINITY, f32::min);
            b.is_inside(p) == (sdf < 0.0)
        })
        .count();
    assert!(agree as f64 >= 0.995 * n as f64, "{agree} / {n}");
    eprintln!("union of three boxes: {agree} / {n} agree");
}

#[test]
fn signed_distance_matches_the_analytic_box_sdf() {
    let (_, b) = &*CUBE;
    let mut rng = Rng(17);
    let points: Vec<V3> = (0..5000).map(|_| rng.point([-1.0; 3], [2.0; 3])).collect();
    for &p in &points {
        let sd = b.signed_distance(p);
        let exact = box_sdf(p, [0.0; 3], [1.0; 3]);
        assert!((sd - exact).abs() < 1e-5, "{sd} vs {exact} at {p:?}");
    }
    let mut out = vec![0.0; points.len()];
    b.signed_distances(&points, &mut out);
    for (p, o) in points.iter().zip(&out) {
        assert_eq!(*o, b.signed_distance(*p));
    }
}

#[test]
#[should_panic(expected = "output slots")]
fn signed_distances_rejects_mismatched_lengths() {
    CUBE.1.signed_distances(&[[0.0; 3]; 3], &mut [0.0; 2]);
}

#[test]
fn sample_surface_is_on_the_mesh_area_weighted_and_deterministic() {
    let m = box_mesh([0.0; 3], [1.0, 1.0, 2.0]);
    let b = bvh(&m);
    assert!((b.total_area() - 10.0).abs() < 1e-12);
    let n = 20_000;
    let mut rng = Rng(99);
    let mut calls = 0usize;
    let samples = b.sample_surface(n, &mut || {
        calls += 1;
        rng.next_f64()
    });
    assert_eq!(samples.len(), n);
    assert_eq!(calls, 3 * n);
    let mut counts = [0usize; 6];
    for &(p, nrm) in &samples {
        let (_, d2, _) = b.closest_point(p).unwrap();
        assert!(d2.sqrt() < 1e-5, "sample {p:?} off the mesh");
        assert!((dot(nrm, nrm) - 1.0).abs() < 1e-6);
        let face = FACE_NORMALS
            .iter()
            .position(|&f| f == nrm)
            .expect("axis normal");
        // The sample lies on the face its normal names.
        let k = face / 2;
        let plane = if face % 2 == 0 {
            0.0
        } else {
            [1.0, 1.0, 2.0][k]
        };
        assert!((p[k] - plane).abs() < 1e-6);
        counts[face] += 1;
    }
    // Faces ±x and ±y are 1×2 (area 2 of 10), ±z are 1×1 (area 1 of 10).
    for (face, &c) in counts.iter().enumerate() {
        let prob = if face < 4 { 0.2 } else { 0.1 };
        let mean = prob * n as f64;
        let sigma = (n as f64 * prob * (1.0 - prob)).sqrt();
        assert!(
            (c as f64 - mean).abs() < 3.0 * sigma,
            "face {face}: {c} vs {mean} ± {sigma}"
        );
    }
    let mut r1 = Rng(1234);
    let mut r2 = Rng(1234);
    let a = b.sample_surface(500, &mut || r1.next_f64());
    let c = b.sample_surface(500, &mut || r2.next_f64());
    assert_eq!(a, c);
    let mut r3 = Rng(4321);
    assert_ne!(a, b.sample_surface(500, &mut || r3.next_f64()));
    // Extreme random numbers stay on the mesh.
    for x in [0.0, 0.999_999_999_999, 1.0] {
        for (p, _) in b.sample_surface(3, &mut || x) {
            assert!(b.closest_point(p).unwrap().1.sqrt() < 1e-5);
        }
    }
}

#[test]
fn empty_mesh_answers_without_panicking() {
    let b = MeshBvh::new(&[], &[]).unwrap();
    assert_eq!(b.triangle_count(), 0);
    assert_eq!(
        b.ray_hit([0.0; 3], [1.0, 0.0, 0.0], 0.0, f32::INFINITY),
        None
    );
    assert!(!b.ray_occluded([0.0; 3], [1.0, 0.0, 0.0], 0.0, f32::INFINITY));
    assert_eq!(b.closest_point([0.0; 3]), None);
    assert_eq!(b.winding_number([0.0; 3]), 0.0);
    assert!(!b.is_inside([0.0; 3]));
    assert_eq!(b.signed_distance([0.0; 3]), f32::INFINITY);
    assert_eq!(b.total_area(), 0.0);
    assert!(b.sample_surface(5, &mut || 0.5).is_empty());
    let mut out = [0.0; 2];
    b.signed_distances(&[[0.0; 3]; 2], &mut out);
    assert_eq!(out, [f32::INFINITY; 2]);
    // Vertices without triangles are an empty mesh too.
    let b = MeshBvh::new(&[[1.0; 3]], &[]).unwrap();
    assert_eq!(b.closest_point([0.0; 3]), None);
}

#[test]
fn is_send_sync_and_handles_non_finite_queries() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<MeshBvh>();
    assert_eq!(CUBE.1.closest_point([f32::NAN; 3]), None);
    assert_eq!(CUBE.1.closest_point([0.0, f32::INFINITY, 0.0]), None);
    assert!(CUBE.1.signed_distance([f32::NAN; 3]).is_nan());
    assert!(
        !CUBE
            .1
            .ray_occluded([f32::NAN; 3], [1.0, 0.0, 0.0], 0.0, 1.0)
    );
}

#[test]
fn bad_indices_and_coordinates_are_errors() {
    let positions = [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let err = MeshBvh::new(&positions, &[[0, 1, 2], [0, 7, 2]])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("triangle 1") && err.contains("index 7"),
        "{err}"
    );
    let bad = [[0.0; 3], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let err = MeshBvh::new(&bad, &[[0, 1, 2]]).unwrap_err().to_string();
    assert!(
        err.contains("triangle 0") && err.contains("vertex 1"),
        "{err}"
    );
}

#[test]
fn pathological_inputs_build_shallow_working_trees() {
    // 3000 copies of one triangle (coincident centroids) plus a geometric chain of tiny
    // triangles that SAH would split one at a time.
    let mut positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let mut triangles = vec![[0, 1, 2]; 3000];
    for i in 0..200 {
        let x = 2.0 + 1.1f32.powi(i);
        let base = positions.len() as u32;
        positions.extend([[x, 0.0, 0.0], [x + 1e-3, 0.0, 0.0], [x, 1e-3, 0.0]]);
        triangles.push([base, base + 1, base + 2]);
    }
    let m = (positions, triangles);
    let b = bvh(&m);
    check_tree(&b, &m);
    let h = b
        .ray_hit([0.2, 0.2, 1.0], [0.0, 0.0, -1.0], 0.0, f32::INFINITY)
        .unwrap();
    assert!((h.t - 1.0).abs() < 1e-6 && h.triangle < 3000);
    check_closest(&m, &b, [5.0, 3.0, -1.0]);
    check_closest(&m, &b, [0.1, 0.1, 0.1]);
}

/// Structural invariants: every triangle in exactly one leaf of ≤ MAX_LEAF triangles,
/// boxes enclose their subtrees, winding-number balls enclose their triangles, depth ≤ 64.
/// Returns the depth.
fn check_tree(b: &MeshBvh, m: &Mesh) -> usize {
    fn walk(b: &MeshBvh, id: usize, seen: &mut [bool], verts: &mut Vec<V3>) -> usize {
        let n = *b.node(id);
        let start = verts.len();
        let depth = if n.count > 0 {
            assert!(
                n.count as usize <= MAX_LEAF,
                "leaf of {} triangles",
                n.count
            );
            for i in n.first..n.first + n.count {
                let t = b.order[i as usize] as usize;
                assert!(!seen[t], "triangle {t} in two leaves");
                seen[t] = true;
                verts.extend(b.tris[i as usize].v);
            }
            1
        } else {
            assert_eq!(n.first % 2, 0, "siblings must share a pair");
            let l = walk(b, n.first as usize, seen, verts);
            let r = walk(b, n.first as usize + 1, seen, verts);
            1 + l.max(r)
        };
        let w = &b.wn[id];
        let r2 = w.far2 as f64 / (WN_BETA * WN_BETA);
        for v in &verts[start..] {
            for k in 0..3 {
                assert!(
                    n.min[k] <= v[k] && v[k] <= n.max[k],
                    "node {id} box misses {v:?}"
                );
            }
            let d2 = dot64(
                sub64(to64(*v), to64(w.center)),
                sub64(to64(*v), to64(w.center)),
            );
            assert!(d2 <= r2 * (1.0 + 1e-5), "node {id} ball misses {v:?}");
        }
        depth
    }
    let mut seen = vec![false; m.1.len()];
    let depth = if m.1.is_empty() {
        0
    } else {
        walk(b, 0, &mut seen, &mut Vec::new())
    };
    assert!(seen.iter().all(|&s| s), "triangle missing from the tree");
    assert!(depth <= 64, "depth {depth}");
    depth
}

#[test]
fn trees_satisfy_their_invariants() {
    check_tree(&CUBE.1, &CUBE.0);
    check_tree(&SPHERE.1, &SPHERE.0);
    let big = uv_sphere([0.3, 0.0, -0.2], 2.0, 128, 80);
    let depth = check_tree(&bvh(&big), &big);
    // 20k triangles: a balanced tree would be ~12 levels deep; SAH may go somewhat deeper.
    assert!(depth < 40, "depth {depth}");
    let mut rng = Rng(8);
    let soup: Mesh = (
        (0..3000).map(|_| rng.point([-1.0; 3], [1.0; 3])).collect(),
        (0..1000u32)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect(),
    );
    check_tree(&bvh(&soup), &soup);
}
