//! Convex pieces: hulls, approximate convex decomposition and contact depth between hulls.
//!
//! Why it exists: a simulator collides convex shapes. Given a whole marching-cubes mesh, an
//! engine takes its convex hull, so a drawer sits inside its cabinet's hull and cannot move.
//! Export therefore writes each part's collision as a few convex pieces ([`decompose`], by
//! axis-aligned cuts bounded in depth: `mesh::decompose`), and the native physics check
//! ([`crate::sim`]) measures contacts between those same pieces with GJK/EPA, the depths
//! MuJoCo's convex collider reports. Hulls and contact queries are parry3d's.
//!
//! Every piece is a closed convex [`TriMesh`] of at most [`DecompositionOptions::max_vertices`]
//! vertices. A hull with more is reduced to the vertices extreme along a fixed, deterministic
//! set of directions: the reduced hull lies inside the exact one, so simplification never adds
//! a contact. Flat input (a panel of zero thickness) is given [`MIN_THICKNESS`] so that every
//! engine accepts the piece as a solid. Same input, same pieces, bit for bit.

use nalgebra::Isometry3;
use parry3d::math::{Pose, Vector};
use parry3d::query::contact::contact_support_map_support_map;
use parry3d::shape::SupportMap;
use parry3d::transformation::try_convex_hull;

use super::TriMesh;
use crate::error::{CoreError, CoreResult};

/// Thickness (metres) given to a flat set of points so that its hull is a solid.
pub const MIN_THICKNESS: f32 = 5e-4;

/// Largest `max_pieces` accepted.
pub const MAX_PIECES: usize = 64;
/// Largest `max_vertices` accepted (MuJoCo's own hull limit is far above this).
pub const MAX_VERTICES: usize = 256;
/// Voxel resolution range accepted by [`decompose`].
pub const RESOLUTION_RANGE: [u32; 2] = [16, 128];

/// Knobs of the convex decomposition of one mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecompositionOptions {
    /// Most convex pieces per part.
    pub max_pieces: usize,
    /// Most vertices per piece.
    pub max_vertices: usize,
    /// Voxels along the longest side of the mesh's bounding box.
    pub resolution: u32,
    /// Concavity (metres) a piece may keep: how deep free space may reach inside its hull.
    pub tolerance: f64,
}

impl Default for DecompositionOptions {
    fn default() -> Self {
        DecompositionOptions {
            max_pieces: 16,
            max_vertices: 48,
            resolution: 64,
            tolerance: 0.002,
        }
    }
}

impl DecompositionOptions {
    /// Check every knob against its range.
    pub fn validate(&self) -> CoreResult<()> {
        if !(1..=MAX_PIECES).contains(&self.max_pieces) {
            return Err(CoreError::invalid(
                "collision.max_pieces",
                format!("1..={MAX_PIECES}"),
                self.max_pieces,
            ));
        }
        if !(8..=MAX_VERTICES).contains(&self.max_vertices) {
            return Err(CoreError::invalid(
                "collision.max_vertices",
                format!("8..={MAX_VERTICES}"),
                self.max_vertices,
            ));
        }
        let [lo, hi] = RESOLUTION_RANGE;
        if !(lo..=hi).contains(&self.resolution) {
            return Err(CoreError::invalid(
                "collision.resolution",
                format!("{lo}..={hi}"),
                self.resolution,
            ));
        }
        if !(self.tolerance >= 0.0 && self.tolerance.is_finite()) {
            return Err(CoreError::invalid(
                "collision.tolerance",
                ">= 0 metres",
                self.tolerance,
            ));
        }
        Ok(())
    }
}

fn vec(p: [f32; 3]) -> Vector {
    Vector::new(p[0], p[1], p[2])
}

/// The convex hull of `points` as a closed, outward mesh of at most `max_vertices` vertices
/// (`None` for fewer than one point or non-finite input). Flat or collinear point sets are
/// thickened by [`MIN_THICKNESS`] first.
pub fn hull(points: &[[f32; 3]], max_vertices: usize) -> Option<TriMesh> {
    if points.is_empty() || points.iter().flatten().any(|v| !v.is_finite()) {
        return None;
    }
    let pts: Vec<Vector> = points.iter().map(|&p| vec(p)).collect();
    let (verts, _) = exact_hull(&pts)?;
    let kept = if verts.len() > max_vertices {
        extreme_subset(&verts, max_vertices)
    } else {
        verts
    };
    let (verts, tris) = exact_hull(&kept)?;
    Some(TriMesh {
        positions: verts.iter().map(|v| [v.x, v.y, v.z]).collect(),
        triangles: tris,
    })
}

/// parry's hull with every triangle wound outward (counter-clockwise seen from outside: parry's
/// own winding is not relied on), or the hull of the points thickened by [`MIN_THICKNESS`]
/// when they are flat.
fn exact_hull(pts: &[Vector]) -> Option<(Vec<Vector>, Vec<[u32; 3]>)> {
    let (verts, mut tris) = flat_or_hull(pts)?;
    let centroid = verts.iter().fold(Vector::ZERO, |a, v| a + *v) / verts.len() as f32;
    for t in &mut tris {
        let [a, b, c] = t.map(|i| verts[i as usize]);
        if (b - a).cross(c - a).dot(a - centroid) < 0.0 {
            t.swap(1, 2);
        }
    }
    Some((verts, tris))
}

fn flat_or_hull(pts: &[Vector]) -> Option<(Vec<Vector>, Vec<[u32; 3]>)> {
    if let Some(h) = scaled_hull(pts)
        && !flat(&h.0, volume_of(&h.0, &h.1).abs())
        && !thin(&h.0)
    {
        return Some(h);
    }
    let t = MIN_THICKNESS / 2.0;
    let mut thick = Vec::with_capacity(pts.len() * 8);
    for p in pts {
        for k in 0..8 {
            let s = |bit: u32| if k & (1 << bit) != 0 { t } else { -t };
            thick.push(*p + Vector::new(s(0), s(1), s(2)));
        }
    }
    scaled_hull(&thick)
}

/// The corners of the points' bounding box.
fn bounds_of(verts: &[Vector]) -> (Vector, Vector) {
    verts.iter().fold(
        (
            Vector::splat(f32::INFINITY),
            Vector::splat(f32::NEG_INFINITY),
        ),
        |(lo, hi), v| (lo.min(*v), hi.max(*v)),
    )
}

/// parry's hull computed with every axis scaled to the same extent (an affine map keeps the
/// hull's vertices and faces), so that a 1 mm panel a metre wide is not flattened by parry's
/// relative tolerance; vertices are returned in the original frame.
fn scaled_hull(pts: &[Vector]) -> Option<(Vec<Vector>, Vec<[u32; 3]>)> {
    let (lo, hi) = bounds_of(pts);
    let mid = (lo + hi) * 0.5;
    let e = (hi - lo).max(Vector::splat(1e-9));
    let scaled: Vec<Vector> = pts.iter().map(|p| (*p - mid) / e).collect();
    let (verts, tris) = try_convex_hull(&scaled).ok()?;
    if tris.len() < 4 {
        return None;
    }
    Some((verts.iter().map(|v| *v * e + mid).collect(), tris))
}

/// Whether the points span less than [`MIN_THICKNESS`] along some axis.
fn thin(verts: &[Vector]) -> bool {
    let (lo, hi) = bounds_of(verts);
    (hi - lo).min_element() < MIN_THICKNESS
}

/// Whether a hull of `volume` is thinner than a tenth of [`MIN_THICKNESS`] over its extent.
fn flat(verts: &[Vector], volume: f32) -> bool {
    let (lo, hi) = bounds_of(verts);
    let e = hi - lo;
    let area = (e.x * e.y).max(e.y * e.z).max(e.x * e.z);
    volume.is_nan() || volume <= 0.1 * MIN_THICKNESS * area
}

fn volume_of(verts: &[Vector], tris: &[[u32; 3]]) -> f32 {
    tris.iter()
        .map(|t| {
            let (a, b, c) = (
                verts[t[0] as usize],
                verts[t[1] as usize],
                verts[t[2] as usize],
            );
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}

/// Volume enclosed by a closed outward mesh (m³).
pub fn volume(mesh: &TriMesh) -> f64 {
    let v: Vec<Vector> = mesh.positions.iter().map(|&p| vec(p)).collect();
    volume_of(&v, &mesh.triangles) as f64
}

/// At most `max` of `verts`: the 8 corners' and 6 faces' directions first, then a Halton
/// sequence over the sphere, each contributing the vertex farthest along it (first on ties).
fn extreme_subset(verts: &[Vector], max: usize) -> Vec<Vector> {
    let mut dirs: Vec<Vector> = Vec::new();
    for k in 0..8 {
        let s = |bit: u32| if k & (1 << bit) != 0 { 1.0 } else { -1.0 };
        dirs.push(Vector::new(s(0), s(1), s(2)));
    }
    for a in 0..3 {
        for s in [1.0, -1.0] {
            let mut d = Vector::ZERO;
            d[a] = s;
            dirs.push(d);
        }
    }
    let halton = |mut i: u32, base: u32| {
        let (mut f, mut r) = (1.0f32, 0.0f32);
        while i > 0 {
            f /= base as f32;
            r += f * (i % base) as f32;
            i /= base;
        }
        r
    };
    for i in 1..=(64 * max as u32) {
        let z = 2.0 * halton(i, 2) - 1.0;
        let phi = std::f32::consts::TAU * halton(i, 3);
        let r = (1.0 - z * z).max(0.0).sqrt();
        dirs.push(Vector::new(r * phi.cos(), r * phi.sin(), z));
    }
    let mut chosen: Vec<usize> = Vec::with_capacity(max);
    for d in dirs {
        if chosen.len() == max {
            break;
        }
        let mut best = 0;
        for (i, v) in verts.iter().enumerate() {
            if v.dot(d) > verts[best].dot(d) {
                best = i;
            }
        }
        if !chosen.contains(&best) {
            chosen.push(best);
        }
    }
    chosen.sort_unstable();
    chosen.into_iter().map(|i| verts[i]).collect()
}

/// Approximate convex decomposition of `mesh` (a closed surface or a union of closed shells):
/// at most `opts.max_pieces` convex pieces (`mesh::decompose`), each reduced to
/// `opts.max_vertices`. An empty mesh has no pieces.
pub fn decompose(mesh: &TriMesh, opts: &DecompositionOptions) -> Vec<TriMesh> {
    if mesh.is_empty() {
        return Vec::new();
    }
    let cut = super::decompose::CutOptions {
        max_pieces: opts.max_pieces,
        resolution: opts.resolution,
        tolerance: opts.tolerance,
    };
    super::decompose::decompose(mesh, &cut)
        .iter()
        .filter_map(|points| hull(points, opts.max_vertices))
        .collect()
}

/// A convex piece ready for contact queries: its hull's vertices, queried as a support map
/// (the farthest vertex along a direction), which is all GJK and EPA need; no face topology is
/// involved, so no degenerate hull can trip a query.
#[derive(Debug, Clone)]
pub struct Convex {
    verts: Vec<Vector>,
    lo: [f32; 3],
    hi: [f32; 3],
}

impl SupportMap for Convex {
    fn local_support_point(&self, dir: Vector) -> Vector {
        let mut best = self.verts[0];
        let mut d = best.dot(dir);
        for v in &self.verts[1..] {
            let e = v.dot(dir);
            if e > d {
                (best, d) = (*v, e);
            }
        }
        best
    }
}

impl Convex {
    /// The piece of a convex mesh (its hull is taken; `None` when degenerate).
    pub fn new(mesh: &TriMesh) -> Option<Convex> {
        let pts: Vec<Vector> = mesh.positions.iter().map(|&p| vec(p)).collect();
        let (verts, _) = exact_hull(&pts)?;
        let (lo, hi) = mesh.bounds()?;
        Some(Convex { verts, lo, hi })
    }

    /// Corners of the piece's bounding box in its own frame.
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        (self.lo, self.hi)
    }
}

fn pose(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector;
    let q = iso.rotation.into_inner();
    Pose::from_parts(
        Vector::new(t.x as f32, t.y as f32, t.z as f32),
        parry3d::math::Rot3::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize(),
    )
}

/// Penetration depth (metres, ≥ 0; 0 when apart or touching) of piece `a` placed by `pa` and
/// piece `b` placed by `pb`: the shortest translation that separates them (GJK + EPA).
pub fn penetration(a: &Convex, pa: &Isometry3<f64>, b: &Convex, pb: &Isometry3<f64>) -> f64 {
    let rel = pose(pa).inverse() * pose(pb);
    match contact_support_map_support_map(&rel, a, b, 0.0) {
        Some(c) if c.dist < 0.0 => -c.dist as f64,
        _ => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, Vector3};

    use super::*;
    use crate::mesh::primitives::append_primitive;
    use crate::shape::Primitive;

    fn cuboid(c: [f64; 3], h: [f64; 3]) -> TriMesh {
        let mut m = TriMesh::default();
        append_primitive(
            &mut m,
            &Primitive::Cuboid {
                center: Vector3::from(c),
                half_extents: Vector3::from(h),
            },
            &Vector3::zeros(),
        );
        m
    }

    #[test]
    fn hull_of_a_box_is_the_box() {
        let m = cuboid([0.0, 0.0, 0.0], [0.5, 0.25, 0.1]);
        let h = hull(&m.positions, 48).unwrap();
        assert_eq!(h.positions.len(), 8);
        assert!((volume(&h) - 0.1).abs() < 1e-6, "{}", volume(&h));
    }

    #[test]
    fn specks_and_rods_get_a_thickness_in_every_axis() {
        let speck = [
            [0.1, 0.2, 0.3],
            [0.1 + 1e-7, 0.2, 0.3],
            [0.1, 0.2 + 1e-7, 0.3 + 1e-7],
            [0.1, 0.2, 0.3 + 1e-6],
        ];
        let h = hull(&speck, 48).unwrap();
        let (lo, hi) = h.bounds().unwrap();
        for a in 0..3 {
            assert!(
                hi[a] - lo[a] >= MIN_THICKNESS * 0.99,
                "{a}: {:?} {:?}",
                lo,
                hi
            );
        }
        assert!(volume(&h) > 1e-11, "{}", volume(&h));
    }

    #[test]
    fn flat_points_get_a_thickness() {
        let pts = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ];
        let h = hull(&pts, 48).unwrap();
        let v = volume(&h);
        assert!((v - MIN_THICKNESS as f64).abs() < 1e-6, "{v}");
    }

    #[test]
    fn simplified_hulls_keep_the_vertex_bound_and_lie_inside() {
        // A sphere-ish cloud of 2000 points.
        let pts: Vec<[f32; 3]> = (0..2000)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / 2000.0;
                let phi = i as f32 * 2.399_963;
                let r = (1.0 - z * z).sqrt();
                [r * phi.cos(), r * phi.sin(), z]
            })
            .collect();
        let full = hull(&pts, MAX_VERTICES).unwrap();
        let small = hull(&pts, 24).unwrap();
        assert!(small.positions.len() <= 24);
        assert!(volume(&small) < volume(&full));
        assert!(volume(&small) > 0.5 * volume(&full), "{}", volume(&small));
        for p in &small.positions {
            let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!(n <= 1.0 + 1e-5);
        }
    }

    #[test]
    fn a_hollow_box_decomposes_into_pieces_that_leave_its_inside_free() {
        // Five 2 cm walls of a 0.6 m box open at +x, plus the contents' test body inside.
        let walls = [
            cuboid([-0.29, 0.0, 0.0], [0.01, 0.3, 0.3]),
            cuboid([0.0, -0.29, 0.0], [0.3, 0.01, 0.3]),
            cuboid([0.0, 0.29, 0.0], [0.3, 0.01, 0.3]),
            cuboid([0.0, 0.0, -0.29], [0.3, 0.3, 0.01]),
            cuboid([0.0, 0.0, 0.29], [0.3, 0.3, 0.01]),
        ];
        let mut shell = TriMesh::default();
        for w in &walls {
            let base = shell.positions.len() as u32;
            shell.positions.extend_from_slice(&w.positions);
            shell
                .triangles
                .extend(w.triangles.iter().map(|t| t.map(|i| i + base)));
        }
        let opts = DecompositionOptions::default();
        let pieces = decompose(&shell, &opts);
        assert!(
            pieces.len() >= 5 && pieces.len() <= opts.max_pieces,
            "{}",
            pieces.len()
        );
        let inner = Convex::new(&cuboid([0.02, 0.0, 0.0], [0.26, 0.26, 0.26])).unwrap();
        let id = Isometry3::identity();
        for (k, p) in pieces.iter().enumerate() {
            assert!(p.positions.len() <= opts.max_vertices);
            let d = penetration(&Convex::new(p).unwrap(), &id, &inner, &id);
            assert!(d < 0.005, "piece {k} reaches {d} m into the cavity");
        }
        // Deterministic: the same mesh gives the same pieces, bit for bit.
        assert_eq!(decompose(&shell, &opts), pieces);
    }

    #[test]
    fn penetration_of_two_boxes_is_their_overlap() {
        let a = Convex::new(&cuboid([0.0, 0.0, 0.0], [0.5, 0.5, 0.5])).unwrap();
        let b = Convex::new(&cuboid([0.0, 0.0, 0.0], [0.1, 0.1, 0.1])).unwrap();
        let id = Isometry3::identity();
        let apart = Isometry3::from_parts(Translation3::new(1.0, 0.0, 0.0), Default::default());
        let overlap = Isometry3::from_parts(Translation3::new(0.57, 0.0, 0.0), Default::default());
        assert_eq!(penetration(&a, &id, &b, &apart), 0.0);
        let d = penetration(&a, &id, &b, &overlap);
        assert!((d - 0.03).abs() < 1e-4, "{d}");
    }

    #[test]
    fn bad_options_name_the_field() {
        let e = DecompositionOptions {
            max_pieces: 0,
            ..Default::default()
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("collision.max_pieces") && e.contains("1..=64"),
            "{e}"
        );
    }
}
