//! Tests of `marching_cubes`.

use super::*;
use std::collections::HashSet;

/// Samples `f` on `n` points per axis over [lo, hi]^3.
fn sample(n: usize, lo: f32, hi: f32, f: impl Fn([f32; 3]) -> f32) -> (Vec<f32>, f32) {
    let h = (hi - lo) / (n - 1) as f32;
    let mut values = Vec::with_capacity(n * n * n);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = [lo + h * i as f32, lo + h * j as f32, lo + h * k as f32];
                values.push(f(p));
            }
        }
    }
    (values, h)
}

fn grid(n: usize, lo: f32, h: f32, values: &[f32]) -> ScalarGrid<'_> {
    ScalarGrid {
        dims: [n; 3],
        origin: [lo; 3],
        spacing: [h; 3],
        values,
    }
}

fn extract(n: usize, lo: f32, hi: f32, f: impl Fn([f32; 3]) -> f32) -> (McMesh, f32) {
    let (values, h) = sample(n, lo, hi, f);
    let mesh = marching_cubes(&grid(n, lo, h, &values), 0.0).unwrap();
    (mesh, h)
}

fn norm(p: [f32; 3]) -> f32 {
    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
}

fn sphere(r: f32) -> impl Fn([f32; 3]) -> f32 {
    move |p| norm(p) - r
}

fn boxed(half: [f32; 3]) -> impl Fn([f32; 3]) -> f32 {
    move |p| {
        let q = [0, 1, 2].map(|a| p[a].abs() - half[a]);
        let outside = norm(q.map(|x| x.max(0.0)));
        let inside = q[0].max(q[1]).max(q[2]).min(0.0);
        outside + inside
    }
}

fn torus(big: f32, small: f32) -> impl Fn([f32; 3]) -> f32 {
    move |p| {
        let ring = (p[0] * p[0] + p[1] * p[1]).sqrt() - big;
        (ring * ring + p[2] * p[2]).sqrt() - small
    }
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| f64::from(a[i]) - f64::from(b[i]))
}

fn cross(u: [f64; 3], v: [f64; 3]) -> [f64; 3] {
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

fn dot(u: [f64; 3], v: [f64; 3]) -> f64 {
    u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
}

/// Number of triangles using each undirected edge, and checks that no directed edge is used
/// twice (consistent orientation).
fn edge_uses(mesh: &McMesh) -> HashMap<(u32, u32), usize> {
    let mut directed = HashSet::new();
    let mut uses = HashMap::new();
    for t in &mesh.triangles {
        for m in 0..3 {
            let (a, b) = (t[m], t[(m + 1) % 3]);
            assert!(
                directed.insert((a, b)),
                "directed edge {a}->{b} used twice: inconsistent orientation"
            );
            *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    uses
}

/// Asserts a closed, consistently oriented, edge-manifold mesh and returns V - E + F.
fn assert_watertight(mesh: &McMesh) -> i64 {
    assert!(!mesh.triangles.is_empty(), "mesh is empty");
    let uses = edge_uses(mesh);
    for (&(a, b), &n) in &uses {
        assert_eq!(n, 2, "edge {a}-{b} is used by {n} triangles, expected 2");
    }
    let used: HashSet<u32> = mesh.triangles.iter().flatten().copied().collect();
    assert_eq!(used.len(), mesh.positions.len(), "unreferenced vertices");
    mesh.positions.len() as i64 - uses.len() as i64 + mesh.triangles.len() as i64
}

fn assert_no_degenerate(mesh: &McMesh) {
    for t in &mesh.triangles {
        assert!(
            t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
            "repeated index {t:?}"
        );
        for &i in t {
            assert!((i as usize) < mesh.positions.len(), "index out of range");
        }
        let [p, q, r] = t.map(|i| mesh.positions[i as usize]);
        let n = cross(sub(q, p), sub(r, p));
        assert!(
            dot(n, n) > 0.0,
            "zero-area triangle {t:?}: {p:?} {q:?} {r:?}"
        );
    }
}

/// Sum of signed tetrahedron volumes from the origin.
fn signed_volume(mesh: &McMesh) -> f64 {
    mesh.triangles
        .iter()
        .map(|t| {
            let [p, q, r] = t.map(|i| mesh.positions[i as usize].map(f64::from));
            dot(p, cross(q, r)) / 6.0
        })
        .sum()
}

fn check_sphere(n: usize) -> (McMesh, f32) {
    let r = 0.3;
    let (mesh, h) = extract(n, -0.5, 0.5, sphere(r));
    assert!(!mesh.triangles.is_empty());
    assert_eq!(
        assert_watertight(&mesh),
        2,
        "Euler characteristic of a sphere"
    );
    assert_no_degenerate(&mesh);
    for &p in &mesh.positions {
        let d = (norm(p) - r).abs();
        assert!(d < 0.5 * h, "vertex {p:?} is {d} from the sphere (h = {h})");
    }
    let vol = signed_volume(&mesh);
    assert!(
        vol > 0.0,
        "signed volume {vol} not positive: inward orientation"
    );
    (mesh, h)
}

#[test]
fn sphere_33_is_closed_genus_0_and_accurate() {
    check_sphere(33);
}

#[test]
fn sphere_64_volume_within_3_percent() {
    let (mesh, _) = check_sphere(64);
    let exact = 4.0 / 3.0 * std::f64::consts::PI * 0.3f64.powi(3);
    let vol = signed_volume(&mesh);
    let rel = (vol - exact).abs() / exact;
    assert!(rel < 0.03, "volume {vol} vs {exact}: relative error {rel}");
}

#[test]
fn sphere_normals_point_outwards() {
    let (mesh, _) = extract(33, -0.5, 0.5, sphere(0.3));
    for t in &mesh.triangles {
        let [p, q, r] = t.map(|i| mesh.positions[i as usize]);
        let normal = cross(sub(q, p), sub(r, p));
        let centroid =
            [0, 1, 2].map(|a| (f64::from(p[a]) + f64::from(q[a]) + f64::from(r[a])) / 3.0);
        assert!(dot(normal, centroid) > 0.0, "triangle {t:?} faces inwards");
    }
}

#[test]
fn off_centre_sphere_with_anisotropic_grid() {
    let (c, r) = ([0.05f32, -0.1, 0.12], 0.25f32);
    let dims = [30, 41, 23];
    let origin = [-0.5f32, -0.55, -0.45];
    let spacing = [1.0 / 29.0, 1.1 / 40.0, 0.9 / 22.0];
    let mut values = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = [i, j, k].map(|x| x as f32);
                let q = [0, 1, 2].map(|a| origin[a] + spacing[a] * p[a] - c[a]);
                values.push(norm(q) - r);
            }
        }
    }
    let g = ScalarGrid {
        dims,
        origin,
        spacing,
        values: &values,
    };
    let mesh = marching_cubes(&g, 0.0).unwrap();
    assert_eq!(assert_watertight(&mesh), 2);
    assert_no_degenerate(&mesh);
    let hmax = spacing.iter().fold(0.0f32, |m, &h| m.max(h));
    for &p in &mesh.positions {
        let d = (norm([0, 1, 2].map(|a| p[a] - c[a])) - r).abs();
        assert!(d < 0.5 * hmax, "vertex {p:?} is {d} off the sphere");
    }
    assert!(signed_volume(&mesh) > 0.0);
}

#[test]
fn box_is_watertight_genus_0() {
    let (mesh, h) = extract(40, -0.5, 0.5, boxed([0.25, 0.18, 0.31]));
    assert_eq!(assert_watertight(&mesh), 2);
    assert_no_degenerate(&mesh);
    let exact = 8.0 * 0.25 * 0.18 * 0.31;
    let vol = signed_volume(&mesh);
    assert!(
        vol > 0.0 && (vol - exact).abs() < 6.0 * f64::from(h) * 0.5,
        "{vol} vs {exact}"
    );
}

#[test]
fn torus_is_watertight_genus_1() {
    let (mesh, _) = extract(48, -0.5, 0.5, torus(0.25, 0.1));
    assert_eq!(
        assert_watertight(&mesh),
        0,
        "Euler characteristic of a torus"
    );
    assert_no_degenerate(&mesh);
    let exact = 2.0 * std::f64::consts::PI.powi(2) * 0.25 * 0.1f64.powi(2);
    let vol = signed_volume(&mesh);
    assert!((vol - exact).abs() / exact < 0.05, "{vol} vs {exact}");
}

#[test]
fn nonzero_level_offsets_surface() {
    // The 0.1 level set of a 0.2-sphere is the 0.3-sphere.
    let (values, h) = sample(33, -0.5, 0.5, sphere(0.2));
    let mesh = marching_cubes(&grid(33, -0.5, h, &values), 0.1).unwrap();
    assert_eq!(assert_watertight(&mesh), 2);
    for &p in &mesh.positions {
        assert!((norm(p) - 0.3).abs() < 0.5 * h);
    }
}

#[test]
fn edge_table_matches_its_definition() {
    let (a, b) = (
        [0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3],
        [1, 2, 3, 0, 5, 6, 7, 4, 4, 5, 6, 7],
    );
    // The corner numbering used by EDGE_GEOMETRY agrees with CORNER_OFFSETS.
    for e in 0..12 {
        let (lo, axis) = EDGE_GEOMETRY[e];
        let (p, q) = (CORNER_OFFSETS[a[e]], CORNER_OFFSETS[b[e]]);
        let (lo_corner, hi_corner) = if p <= q { (p, q) } else { (q, p) };
        assert_eq!(lo_corner, lo, "edge {e} lower corner");
        let mut step = lo;
        step[axis] += 1;
        assert_eq!(hi_corner, step, "edge {e} upper corner");
    }
    for (case, &entry) in EDGE_TABLE.iter().enumerate() {
        let mut expected = 0u16;
        for e in 0..12 {
            if (case >> a[e]) & 1 != (case >> b[e]) & 1 {
                expected |= 1 << e;
            }
        }
        assert_eq!(entry, expected, "EDGE_TABLE[{case}]");
    }
}

#[test]
fn triangle_table_is_consistent_with_edge_table() {
    let mut total = 0;
    for case in 0..256usize {
        let row = &TRI_TABLE[case];
        let len = row.iter().position(|&e| e < 0).unwrap_or(16);
        assert!(len % 3 == 0 && len <= 15, "case {case}: {len} entries");
        assert!(
            row[len..].iter().all(|&e| e == -1),
            "case {case}: junk after -1"
        );
        let mut used = 0u16;
        for &e in &row[..len] {
            assert!((0..12).contains(&e), "case {case}: edge {e}");
            used |= 1 << e;
        }
        for tri in row[..len].chunks_exact(3) {
            assert!(
                tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2],
                "case {case}"
            );
        }
        assert_eq!(
            used, EDGE_TABLE[case],
            "case {case}: edges used vs edge table"
        );
        let comp = &TRI_TABLE[255 - case];
        let comp_used = comp
            .iter()
            .take_while(|&&e| e >= 0)
            .fold(0u16, |m, &e| m | 1 << e);
        assert_eq!(used, comp_used, "cases {case} and {} differ", 255 - case);
        total += len / 3;
    }
    assert_eq!(total, 820, "Bourke's table has 820 triangles in all");
}

/// Deterministic pseudo-random numbers in [0, 1) (SplitMix64).
fn random_values(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        })
        .collect()
}

/// Random fields exercise every table case; interior edges must be shared by exactly two
/// consistently oriented triangles and only edges on the grid boundary may be open.
#[test]
fn random_fields_give_oriented_manifold_away_from_boundary() {
    let n = 9;
    let mut seen = [false; 256];
    for seed in 0..40u64 {
        let values: Vec<f32> = random_values(n * n * n, seed)
            .iter()
            .map(|&r| (r * 2.0 - 1.0) as f32)
            .collect();
        for k in 0..n - 1 {
            for j in 0..n - 1 {
                for i in 0..n - 1 {
                    let mut case = 0;
                    for (c, o) in CORNER_OFFSETS.iter().enumerate() {
                        let idx = i + o[0] + n * (j + o[1] + n * (k + o[2]));
                        if values[idx] < 0.0 {
                            case |= 1 << c;
                        }
                    }
                    seen[case] = true;
                }
            }
        }
        let g = grid(n, 0.0, 1.0, &values);
        let mesh = marching_cubes(&g, 0.0).unwrap();
        assert_no_degenerate(&mesh);
        let on_boundary = |p: [f32; 3]| p.iter().any(|&x| x == 0.0 || x == (n - 1) as f32);
        for (&(a, b), &uses) in &edge_uses(&mesh) {
            let (pa, pb) = (mesh.positions[a as usize], mesh.positions[b as usize]);
            match uses {
                2 => {}
                1 => assert!(
                    on_boundary(pa) && on_boundary(pb),
                    "seed {seed}: open edge {pa:?}-{pb:?} inside the grid"
                ),
                _ => panic!("seed {seed}: edge {pa:?}-{pb:?} used {uses} times"),
            }
        }
    }
    let missing: Vec<usize> = (0..256).filter(|&c| !seen[c]).collect();
    assert!(missing.is_empty(), "cases never exercised: {missing:?}");
}

#[test]
fn shared_edges_give_bitwise_identical_vertices() {
    // Every vertex position occurs once: two cells never create separate copies of a vertex.
    let (mesh, _) = extract(33, -0.5, 0.5, torus(0.22, 0.12));
    let mut seen = HashSet::new();
    for p in &mesh.positions {
        assert!(seen.insert(p.map(f32::to_bits)), "duplicate vertex {p:?}");
    }
}

#[test]
fn samples_exactly_on_the_level_are_welded() {
    // |x| + |y| + |z| - 3 on an integer grid: many samples are exactly 0, so many vertices
    // land on grid corners; they must be welded, with no degenerate triangles left.
    let n = 9;
    let mut values = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = [i, j, k].map(|x| (x as f32 - 4.0).abs());
                values.push(p[0] + p[1] + p[2] - 3.0);
            }
        }
    }
    let mesh = marching_cubes(&grid(n, -4.0, 1.0, &values), 0.0).unwrap();
    assert_no_degenerate(&mesh);
    assert_eq!(assert_watertight(&mesh), 2);
    let mut seen = HashSet::new();
    for p in &mesh.positions {
        assert!(seen.insert(p.map(f32::to_bits)), "duplicate vertex {p:?}");
        assert!((p[0].abs() + p[1].abs() + p[2].abs() - 3.0).abs() < 1e-6);
    }
    assert!(signed_volume(&mesh) > 0.0);
}

#[test]
fn plane_through_sample_layer() {
    // The field z - 0.0 is exactly zero on the middle sample plane.
    let n = 5;
    let (values, h) = sample(n, -1.0, 1.0, |p| p[2]);
    let mesh = marching_cubes(&grid(n, -1.0, h, &values), 0.0).unwrap();
    assert_no_degenerate(&mesh);
    assert_eq!(mesh.positions.len(), n * n);
    assert_eq!(mesh.triangles.len(), 2 * (n - 1) * (n - 1));
    for t in &mesh.triangles {
        let [p, q, r] = t.map(|i| mesh.positions[i as usize]);
        assert!(p[2] == 0.0 && q[2] == 0.0 && r[2] == 0.0);
        // Outside is +z.
        assert!(cross(sub(q, p), sub(r, p))[2] > 0.0);
    }
}

#[test]
fn surface_crossing_the_grid_boundary_is_open_but_fine() {
    let (mesh, _) = extract(17, -0.5, 0.5, sphere(0.6));
    assert!(!mesh.triangles.is_empty());
    assert_no_degenerate(&mesh);
    let uses = edge_uses(&mesh);
    assert!(uses.values().any(|&n| n == 1), "expected an open mesh");
    assert!(uses.values().all(|&n| n <= 2));
    // Touching the boundary exactly.
    let (mesh, _) = extract(17, -0.5, 0.5, sphere(0.5));
    assert_no_degenerate(&mesh);
}

#[test]
fn all_inside_or_all_outside_is_empty() {
    for v in [-1.0f32, 1.0, 0.0] {
        let values = vec![v; 4 * 3 * 5];
        let g = ScalarGrid {
            dims: [4, 3, 5],
            origin: [0.0; 3],
            spacing: [0.1, 0.2, 0.3],
            values: &values,
        };
        assert_eq!(
            marching_cubes(&g, 0.0).unwrap(),
            McMesh::default(),
            "value {v}"
        );
    }
    // Minimal 2x2x2 grid with one inside corner: one triangle.
    let mut values = vec![1.0f32; 8];
    values[0] = -1.0;
    let g = grid(2, 0.0, 1.0, &values);
    let mesh = marching_cubes(&g, 0.0).unwrap();
    assert_eq!(mesh.triangles.len(), 1);
    assert_eq!(mesh.positions.len(), 3);
    assert_no_degenerate(&mesh);
}

#[test]
fn non_finite_samples_do_not_panic() {
    let (mut values, h) = sample(17, -0.5, 0.5, sphere(0.3));
    for (idx, v) in values.iter_mut().enumerate() {
        match idx % 7 {
            0 => *v = f32::NAN,
            3 => *v = f32::INFINITY,
            5 if idx % 3 == 0 => *v = f32::NEG_INFINITY,
            _ => {}
        }
    }
    let mesh = marching_cubes(&grid(17, -0.5, h, &values), 0.0).unwrap();
    assert!(!mesh.triangles.is_empty());
    assert_no_degenerate(&mesh);
    for p in &mesh.positions {
        assert!(p.iter().all(|x| x.is_finite()));
        assert!(norm(*p) <= 0.3 + 2.0 * h);
    }
    // (Manifoldness is not promised here: a vertex next to a non-finite sample snaps onto
    // the finite corner, so several sheets may meet there.)
    // All NaN: nothing is inside.
    let nan = vec![f32::NAN; 27];
    assert!(
        marching_cubes(&grid(3, 0.0, 1.0, &nan), 0.0)
            .unwrap()
            .triangles
            .is_empty()
    );
    // Extreme finite values must not overflow the interpolation.
    let mut big = vec![f32::MAX; 8];
    big[0] = -f32::MAX;
    let mesh = marching_cubes(&grid(2, 0.0, 1.0, &big), 0.0).unwrap();
    assert_eq!(mesh.triangles.len(), 1);
    assert!(mesh.positions.iter().flatten().all(|x| x.is_finite()));
}

#[test]
fn invalid_grids_are_rejected_with_the_field_named() {
    let values = vec![0.0f32; 27];
    let ok = grid(3, 0.0, 1.0, &values);
    assert!(ok.validate().is_ok());
    let check = |g: ScalarGrid<'_>, needles: &[&str]| {
        let err = marching_cubes(&g, 0.0).unwrap_err().to_string();
        for needle in needles {
            assert!(err.contains(needle), "{err:?} should mention {needle:?}");
        }
        assert_eq!(g.validate().unwrap_err().to_string(), err);
    };
    check(
        ScalarGrid {
            dims: [3, 1, 9],
            ..grid(3, 0.0, 1.0, &values)
        },
        &["dims[1]", ">= 2", "got 1"],
    );
    check(
        ScalarGrid {
            spacing: [1.0, 1.0, 0.0],
            ..grid(3, 0.0, 1.0, &values)
        },
        &["spacing[2]", "> 0", "got 0"],
    );
    check(
        ScalarGrid {
            spacing: [-0.5, 1.0, 1.0],
            ..grid(3, 0.0, 1.0, &values)
        },
        &["spacing[0]", "got -0.5"],
    );
    check(
        ScalarGrid {
            spacing: [1.0, f32::NAN, 1.0],
            ..grid(3, 0.0, 1.0, &values)
        },
        &["spacing[1]", "finite", "NaN"],
    );
    check(
        ScalarGrid {
            origin: [0.0, 0.0, f32::INFINITY],
            ..grid(3, 0.0, 1.0, &values)
        },
        &["origin[2]", "finite", "inf"],
    );
    check(
        grid(3, 0.0, 1.0, &values[..26]),
        &["values.len()", "27", "got 26"],
    );
    check(
        ScalarGrid {
            dims: [usize::MAX, 2, 2],
            ..grid(3, 0.0, 1.0, &values)
        },
        &["dims", "overflows"],
    );
    let err = marching_cubes(&ok, f32::NAN).unwrap_err().to_string();
    assert!(err.contains("level") && err.contains("NaN"), "{err}");
}

/// Throughput on a 161^3 sphere grid; run with
/// `cargo test --release -- --ignored --nocapture throughput`.
#[test]
#[ignore = "benchmark; run explicitly in release mode"]
fn throughput_161_sphere() {
    let n = 161;
    let (values, h) = sample(n, -0.5, 0.5, sphere(0.3));
    let g = grid(n, -0.5, h, &values);
    let cells = ((n - 1) * (n - 1) * (n - 1)) as f64;
    let mut best = f64::INFINITY;
    let mut mesh = McMesh::default();
    for _ in 0..5 {
        let start = std::time::Instant::now();
        mesh = marching_cubes(&g, 0.0).unwrap();
        best = best.min(start.elapsed().as_secs_f64());
    }
    println!(
        "161^3 sphere: {} vertices, {} triangles, best {:.2} ms, {:.1} M cells/s",
        mesh.positions.len(),
        mesh.triangles.len(),
        best * 1e3,
        cells / best / 1e6
    );
    assert_eq!(assert_watertight(&mesh), 2);
    // A dense surface (gyroid, ~10 periods across the grid) for a busier workload.
    let f = 10.0 * std::f32::consts::TAU;
    let (values, h) = sample(n, -0.5, 0.5, |p| {
        let [x, y, z] = p.map(|c| c * f);
        x.sin() * y.cos() + y.sin() * z.cos() + z.sin() * x.cos()
    });
    let g = grid(n, -0.5, h, &values);
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let start = std::time::Instant::now();
        mesh = marching_cubes(&g, 0.0).unwrap();
        best = best.min(start.elapsed().as_secs_f64());
    }
    println!(
        "161^3 gyroid: {} vertices, {} triangles, best {:.2} ms, {:.1} M cells/s",
        mesh.positions.len(),
        mesh.triangles.len(),
        best * 1e3,
        cells / best / 1e6
    );
}
