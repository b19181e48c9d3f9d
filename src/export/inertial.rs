//! Inertials every physics engine accepts: mass, centre of mass and inertia tensor of a part.
//!
//! Why it exists: a simulator needs a mass and an inertia tensor per link, and engines refuse
//! (MuJoCo) or explode on (PyBullet, Isaac) tensors that are not positive definite or break
//! the triangle inequality of principal moments (I₁ + I₂ ≥ I₃). Generated parts are often thin
//! (a 1 mm panel) or tiny (a knob), so the tensor of their geometry alone is at or over that
//! edge. This module computes the physical tensor and then makes it acceptable:
//!
//! 1. **Solid** ([`mass_properties`]): density × the closed mesh's volume integrals (Eberly,
//!    "Polyhedral Mass Properties (Revisited)", the signed-volume form of Mirtich's method):
//!    mass, centre of mass, full tensor about it. Primitive meshes in this crate are
//!    concatenations of overlapping closed shells (`mesh::primitives`), and a learned shape may
//!    leak out of its box, so when the mesh volume is not sane (empty mesh, not finite,
//!    ≤ 0, or above [`BOX_VOLUME_SLACK`] × the part's box volume) the part's solid box is used
//!    instead (centre = box centre, the box tensor).
//! 2. **Floors** ([`floored`]): mass ≥ [`InertialOptions::min_mass`] (the tensor scaled with
//!    it, as a denser body of the same shape); then, along the principal axes, every second
//!    moment s_i = ∫ x_i² dm ≥ m·t²/12 with t = [`InertialOptions::min_thickness`], i.e. every
//!    dimension counts as at least t thick. The principal moments are re-assembled from the
//!    clamped second moments (I₁ = s₂ + s₃, …) and the tensor from them (eigendecomposition,
//!    clamp, re-assembly), so the result is positive definite with every principal moment
//!    ≥ m·t²/6 and satisfies the triangle inequality with a margin (I₁ + I₂ − I₃ = 2 s₃ > 0).
//!    A tensor that needs no clamping keeps its values, except that products at rounding
//!    level (≤ 1e-12 of the trace) are written as exact zeros.
//!
//! Defaults: density 300 kg/m³ (light wood / particle board, physnap's value before this
//! module), `min_mass` 1 g (a 1.5 cm cube at 300 kg/m³; below that a part does not matter to
//! the dynamics of furniture-sized objects, and the exporter treats it as "tiny", see
//! `export::artefacts`), `min_thickness` 5 mm (a thin panel's real thickness order).

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use crate::error::{CoreError, CoreResult};
use crate::mesh::TriMesh;
use crate::object::Part;

/// A mesh volume above this multiple of the part's box volume is not trusted (overlapping
/// shells counted twice, or a shape leaking far out of its box): the box is used instead.
pub const BOX_VOLUME_SLACK: f64 = 1.05;

/// Mass properties of one rigid part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertial {
    /// Mass (kg).
    pub mass: f64,
    /// Centre of mass, object frame at rest (m).
    pub com: Vector3<f64>,
    /// Inertia tensor about `com`, object axes (kg·m²); symmetric, products included
    /// (off-diagonal entries are −∫ x y dm, as URDF's `ixy` and MJCF's `fullinertia`).
    pub inertia: Matrix3<f64>,
}

impl Inertial {
    /// The two bodies as one rigid body (masses add, centres by mass, tensors by the parallel
    /// axis theorem).
    pub fn combine(&self, other: &Inertial) -> Inertial {
        let mass = self.mass + other.mass;
        if mass <= 0.0 || !mass.is_finite() {
            return *self;
        }
        let com = (self.com * self.mass + other.com * other.mass) / mass;
        let shifted = |b: &Inertial| {
            let d = b.com - com;
            b.inertia + (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * b.mass
        };
        Inertial {
            mass,
            com,
            inertia: shifted(self) + shifted(other),
        }
    }

    /// Principal moments, ascending.
    pub fn principal_moments(&self) -> Vector3<f64> {
        let mut e: Vec<f64> = SymmetricEigen::new(self.inertia)
            .eigenvalues
            .iter()
            .copied()
            .collect();
        e.sort_by(f64::total_cmp);
        Vector3::new(e[0], e[1], e[2])
    }

    /// The solid box of `part` at `density`: centre = box centre, the box tensor.
    pub fn solid_box(part: &Part, density: f64) -> Inertial {
        let mass = density * part.volume();
        let d = part.half_extents * 2.0;
        let (x2, y2, z2) = (d.x * d.x, d.y * d.y, d.z * d.z);
        Inertial {
            mass,
            com: part.center,
            inertia: Matrix3::from_diagonal(&Vector3::new(
                mass * (y2 + z2) / 12.0,
                mass * (x2 + z2) / 12.0,
                mass * (x2 + y2) / 12.0,
            )),
        }
    }
}

/// How part inertials are computed and floored.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InertialOptions {
    /// Density of every part (kg/m³), > 0. Default 300.
    pub density: f64,
    /// Smallest mass written (kg), > 0. Default 1e-3. A part lighter than this before the
    /// floor is "tiny" (see `export::artefacts`).
    pub min_mass: f64,
    /// Every dimension counts as at least this thick in the inertia tensor (m), > 0.
    /// Default 5e-3.
    pub min_thickness: f64,
}

impl Default for InertialOptions {
    fn default() -> Self {
        InertialOptions {
            density: 300.0,
            min_mass: 1e-3,
            min_thickness: 5e-3,
        }
    }
}

impl InertialOptions {
    /// Every field finite and > 0; the error names the field, the limit and the value.
    pub fn validate(&self) -> CoreResult<()> {
        for (field, v) in [
            ("density", self.density),
            ("min_mass", self.min_mass),
            ("min_thickness", self.min_thickness),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(CoreError::invalid(field, "finite and > 0", v));
            }
        }
        Ok(())
    }
}

/// Where [`mass_properties`] took the solid from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Source {
    /// The mesh's volume integrals.
    Mesh,
    /// The part's box; the mesh volume (m³, NaN for an empty mesh) was not sane.
    Box {
        /// The mesh's signed volume.
        mesh_volume: f64,
    },
}

/// The solid part at `density`, before any floor: from the mesh when its volume is sane, else
/// the part's box (module docs). `mesh` is in the object frame at rest.
pub fn mass_properties(part: &Part, mesh: &TriMesh, density: f64) -> (Inertial, Source) {
    let integrals = (!mesh.is_empty()).then(|| mesh_integrals(mesh, &part.center));
    match integrals {
        Some((volume, com, inertia))
            if volume.is_finite() && volume > 0.0 && volume <= BOX_VOLUME_SLACK * part.volume() =>
        {
            (
                Inertial {
                    mass: density * volume,
                    com,
                    inertia: inertia * density,
                },
                Source::Mesh,
            )
        }
        _ => (
            Inertial::solid_box(part, density),
            Source::Box {
                mesh_volume: integrals.map_or(f64::NAN, |i| i.0),
            },
        ),
    }
}

/// `raw` with the floors of `opts` applied (module docs): mass ≥ `min_mass`, every principal
/// second moment ≥ m·t²/12. The result is positive definite and satisfies the triangle
/// inequality.
pub fn floored(raw: &Inertial, opts: &InertialOptions) -> Inertial {
    let usable = raw.mass.is_finite()
        && raw.mass > 0.0
        && raw.inertia.iter().all(|v| v.is_finite())
        && raw.com.iter().all(|v| v.is_finite());
    let (mass, mut inertia) = if usable {
        let mass = raw.mass.max(opts.min_mass);
        (mass, raw.inertia * (mass / raw.mass))
    } else {
        (opts.min_mass, Matrix3::zeros())
    };
    inertia = (inertia + inertia.transpose()) / 2.0;
    let com = if usable { raw.com } else { Vector3::zeros() };
    let eig = SymmetricEigen::new(inertia);
    let lambda = eig.eigenvalues;
    // Second moments along the principal axes: s_i = (I₁ + I₂ + I₃)/2 − I_i.
    let half_trace = lambda.sum() / 2.0;
    let floor = mass * opts.min_thickness * opts.min_thickness / 12.0;
    let s = lambda.map(|l| half_trace - l);
    if s.iter().all(|&v| v >= floor) {
        return Inertial {
            mass,
            com,
            inertia: tidy(inertia),
        };
    }
    let s = s.map(|v| v.max(floor));
    let lambda = Vector3::new(s.y + s.z, s.x + s.z, s.x + s.y);
    let q = eig.eigenvectors;
    let inertia = q * Matrix3::from_diagonal(&lambda) * q.transpose();
    Inertial {
        mass,
        com,
        inertia: tidy((inertia + inertia.transpose()) / 2.0),
    }
}

/// Products of inertia at rounding level (≤ 1e-12 of the trace: f32 vertex noise on a
/// symmetric part) become exact zeros, and −0 becomes 0, so files read cleanly.
fn tidy(mut t: Matrix3<f64>) -> Matrix3<f64> {
    let eps = 1e-12 * t.trace().abs();
    for r in 0..3 {
        for c in 0..3 {
            if r != c && t[(r, c)].abs() <= eps {
                t[(r, c)] = 0.0;
            }
            t[(r, c)] += 0.0;
        }
    }
    t
}

/// The part's inertial as written: [`mass_properties`] at `opts.density`, then [`floored`].
/// `mesh` is the part's mesh in the object frame at rest. `opts` should have passed
/// [`InertialOptions::validate`]; a non-positive density yields the floors alone.
pub fn inertial(part: &Part, mesh: &TriMesh, opts: &InertialOptions) -> Inertial {
    floored(&mass_properties(part, mesh, opts.density).0, opts)
}

/// Volume, centroid and unit-density inertia tensor about the centroid of a closed mesh
/// (Eberly's polyhedral mass properties). Vertices are taken relative to `reference` (near
/// the mesh) to keep the sums well conditioned; the centroid is returned in the mesh's frame.
fn mesh_integrals(mesh: &TriMesh, reference: &Vector3<f64>) -> (f64, Vector3<f64>, Matrix3<f64>) {
    // Integrals of 1, x, y, z, x², y², z², xy, yz, zx.
    let mut intg = [0.0f64; 10];
    let p = |i: u32| {
        let v = mesh.positions[i as usize];
        Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64) - reference
    };
    let sub = |w0: f64, w1: f64, w2: f64| {
        let t0 = w0 + w1;
        let f1 = t0 + w2;
        let t1 = w0 * w0;
        let t2 = t1 + w1 * t0;
        let f2 = t2 + w2 * f1;
        let f3 = w0 * t1 + w1 * t2 + w2 * f2;
        let g0 = f2 + w0 * (f1 + w0);
        let g1 = f2 + w1 * (f1 + w1);
        let g2 = f2 + w2 * (f1 + w2);
        (f1, f2, f3, g0, g1, g2)
    };
    for t in &mesh.triangles {
        let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
        let d = (b - a).cross(&(c - a));
        let (f1x, f2x, f3x, g0x, g1x, g2x) = sub(a.x, b.x, c.x);
        let (_, f2y, f3y, g0y, g1y, g2y) = sub(a.y, b.y, c.y);
        let (_, f2z, f3z, g0z, g1z, g2z) = sub(a.z, b.z, c.z);
        intg[0] += d.x * f1x;
        intg[1] += d.x * f2x;
        intg[2] += d.y * f2y;
        intg[3] += d.z * f2z;
        intg[4] += d.x * f3x;
        intg[5] += d.y * f3y;
        intg[6] += d.z * f3z;
        intg[7] += d.x * (a.y * g0x + b.y * g1x + c.y * g2x);
        intg[8] += d.y * (a.z * g0y + b.z * g1y + c.z * g2y);
        intg[9] += d.z * (a.x * g0z + b.x * g1z + c.x * g2z);
    }
    let mult = [
        1.0 / 6.0,
        1.0 / 24.0,
        1.0 / 24.0,
        1.0 / 24.0,
        1.0 / 60.0,
        1.0 / 60.0,
        1.0 / 60.0,
        1.0 / 120.0,
        1.0 / 120.0,
        1.0 / 120.0,
    ];
    for (v, m) in intg.iter_mut().zip(mult) {
        *v *= m;
    }
    let volume = intg[0];
    let c = Vector3::new(intg[1], intg[2], intg[3]) / volume;
    let xx = intg[5] + intg[6] - volume * (c.y * c.y + c.z * c.z);
    let yy = intg[4] + intg[6] - volume * (c.z * c.z + c.x * c.x);
    let zz = intg[4] + intg[5] - volume * (c.x * c.x + c.y * c.y);
    let xy = -(intg[7] - volume * c.x * c.y);
    let yz = -(intg[8] - volume * c.y * c.z);
    let zx = -(intg[9] - volume * c.z * c.x);
    let inertia = Matrix3::new(xx, xy, zx, xy, yy, yz, zx, yz, zz);
    (volume, c + reference, inertia)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::box_part;
    use crate::mesh::primitives::part_primitive_mesh;
    use nalgebra::{Rotation3, Vector3};

    fn valid(i: &Inertial, opts: &InertialOptions) {
        let m = i.principal_moments();
        assert!(i.mass >= opts.min_mass, "mass {}", i.mass);
        assert!(m[0] > 0.0, "positive definite: {m:?}");
        assert!(m[0] + m[1] >= m[2], "triangle inequality: {m:?}");
        let floor = i.mass * opts.min_thickness.powi(2) / 6.0;
        assert!(m[0] >= floor * (1.0 - 1e-9), "{} < floor {floor}", m[0]);
        assert!(i.inertia.cholesky().is_some(), "Cholesky of {}", i.inertia);
        assert_eq!(i.inertia, i.inertia.transpose());
    }

    #[test]
    fn thin_panel_gets_a_valid_inertial() {
        // 1 mm × 0.5 m × 0.5 m: the normal's second moment is m·(1 mm)²/12, floored to 5 mm.
        let part = box_part("panel", [0.3, -0.2, 0.8], [0.0005, 0.25, 0.25]);
        let mesh = part_primitive_mesh(&part).unwrap();
        let opts = InertialOptions::default();
        let (raw, source) = mass_properties(&part, &mesh, opts.density);
        assert_eq!(source, Source::Mesh);
        assert!(
            (raw.mass / (300.0 * 0.001 * 0.25) - 1.0).abs() < 1e-4,
            "{}",
            raw.mass
        );
        let i = inertial(&part, &mesh, &opts);
        valid(&i, &opts);
        // The floor raised the in-plane moments by m·(t² − (1 mm)²)/12 and kept the axes.
        let m = i.mass;
        let want_x = m * (0.25 + 0.25) / 12.0;
        let want_y = m * (0.25 + 0.005f64.powi(2)) / 12.0;
        assert!((i.inertia[(0, 0)] - want_x).abs() < 1e-6 * want_x);
        assert!((i.inertia[(1, 1)] - want_y).abs() < 1e-6 * want_y);
        assert!((i.inertia[(2, 2)] - want_y).abs() < 1e-6 * want_y);
        assert!(i.inertia[(0, 1)].abs() < 1e-12 && i.inertia[(1, 2)].abs() < 1e-12);
        assert!((i.com - part.center).norm() < 1e-6);
    }

    #[test]
    fn a_rod_and_a_speck_are_floored() {
        let opts = InertialOptions::default();
        // A 0.1 mm × 0.1 mm × 1 m rod: two moments ≈ m/12, one ≈ 0.
        let rod = box_part("rod", [0.0; 3], [0.5, 0.00005, 0.00005]);
        let i = inertial(&rod, &part_primitive_mesh(&rod).unwrap(), &opts);
        valid(&i, &opts);
        // A 1 mm cube: far below min_mass; the mass is floored, the tensor scaled then floored.
        let speck = box_part("speck", [1.0, 1.0, 1.0], [0.0005; 3]);
        let (raw, _) = mass_properties(&speck, &part_primitive_mesh(&speck).unwrap(), 300.0);
        assert!(raw.mass < opts.min_mass);
        let i = floored(&raw, &opts);
        valid(&i, &opts);
        assert_eq!(i.mass, opts.min_mass);
        // A tensor that breaks the triangle inequality (a point mass can't have 1, 1, 5).
        let bad = Inertial {
            mass: 2.0,
            com: Vector3::zeros(),
            inertia: Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 5.0)),
        };
        valid(&floored(&bad, &opts), &opts);
        // Not positive definite at all.
        let bad = Inertial {
            inertia: Matrix3::from_diagonal(&Vector3::new(-1.0, 0.0, 0.5)),
            ..bad
        };
        valid(&floored(&bad, &opts), &opts);
    }

    #[test]
    fn cube_mesh_inertia_is_the_analytic_box_inertia() {
        let opts = InertialOptions::default();
        // A unit cube away from the origin: mass = density, I = m/6 on the diagonal.
        let cube = box_part("cube", [1.0, 2.0, 3.0], [0.5; 3]);
        let mesh = part_primitive_mesh(&cube).unwrap();
        let (i, source) = mass_properties(&cube, &mesh, opts.density);
        assert_eq!(source, Source::Mesh);
        assert!((i.mass - 300.0).abs() < 1e-9, "{}", i.mass);
        assert!((i.com - cube.center).norm() < 1e-12);
        let want = Matrix3::identity() * (300.0 / 6.0);
        assert!((i.inertia - want).norm() < 1e-9, "{}", i.inertia);
        assert_eq!(floored(&i, &opts), i, "a valid tensor is kept as it is");
        let boxed = Inertial::solid_box(&cube, opts.density);
        assert!((boxed.inertia - i.inertia).norm() < 1e-9 && boxed.mass == 300.0);

        // A 0.2 × 0.4 × 0.6 box turned 30° about z: the products come out with their sign.
        let h = Vector3::new(0.1, 0.2, 0.3);
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_6);
        let flat = box_part("b", [0.0; 3], [h.x, h.y, h.z]);
        let mesh = part_primitive_mesh(&flat).unwrap().map_positions(|p| {
            let v = r * Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            [v.x as f32, v.y as f32, v.z as f32]
        });
        // The turned box's bounding box, so the volume check passes.
        let big = box_part("b", [0.0; 3], [0.25, 0.25, 0.3]);
        let (i, source) = mass_properties(&big, &mesh, 1.0);
        assert_eq!(source, Source::Mesh);
        let body = Inertial::solid_box(&flat, 1.0).inertia;
        let want = r.matrix() * body * r.matrix().transpose();
        assert!(
            (i.inertia - want).norm() < 1e-6 * want.norm(),
            "{} vs {want}",
            i.inertia
        );
        assert!(want[(0, 1)].abs() > 1e-4, "the test has products");
    }

    #[test]
    fn unsane_mesh_volume_falls_back_to_the_box() {
        let part = box_part("p", [0.0, 0.0, 0.5], [0.2, 0.3, 0.5]);
        let boxed = Inertial::solid_box(&part, 300.0);
        let shell = part_primitive_mesh(&part).unwrap();
        // Two overlapping closed shells: twice the box volume.
        let mut twice = shell.clone();
        let n = twice.positions.len() as u32;
        twice.positions.extend(shell.positions.iter().copied());
        twice.triangles.extend(
            shell
                .triangles
                .iter()
                .map(|t| [t[0] + n, t[1] + n, t[2] + n]),
        );
        // Inside out: negative volume.
        let mut inverted = shell.clone();
        for t in &mut inverted.triangles {
            t.swap(1, 2);
        }
        for (mesh, volume_nan) in [
            (twice, false),
            (inverted, false),
            (TriMesh::default(), true),
        ] {
            let (i, source) = mass_properties(&part, &mesh, 300.0);
            let Source::Box { mesh_volume } = source else {
                panic!("expected the box fallback, got {source:?}");
            };
            assert_eq!(mesh_volume.is_nan(), volume_nan);
            assert_eq!(i, boxed);
        }
        // The eight-part fixture's body (six overlapping panels) stays below its box: mesh.
        let body = &crate::fixtures::eight_part().parts[0];
        let (_, source) = mass_properties(body, &part_primitive_mesh(body).unwrap(), 300.0);
        assert_eq!(source, Source::Mesh);
    }

    #[test]
    fn combine_is_the_parallel_axis_theorem() {
        // Two unit cubes side by side are one 2 × 1 × 1 box.
        let a = Inertial::solid_box(&box_part("a", [0.5, 0.0, 0.0], [0.5; 3]), 1.0);
        let b = Inertial::solid_box(&box_part("b", [-0.5, 0.0, 0.0], [0.5; 3]), 1.0);
        let both = Inertial::solid_box(&box_part("ab", [0.0; 3], [1.0, 0.5, 0.5]), 1.0);
        let c = a.combine(&b);
        assert!((c.mass - both.mass).abs() < 1e-12);
        assert!(c.com.norm() < 1e-12);
        assert!((c.inertia - both.inertia).norm() < 1e-12, "{}", c.inertia);
    }

    #[test]
    fn bad_options_name_field_limit_and_value() {
        for (opts, field, value) in [
            (
                InertialOptions {
                    density: 0.0,
                    ..Default::default()
                },
                "density",
                "0",
            ),
            (
                InertialOptions {
                    density: f64::NAN,
                    ..Default::default()
                },
                "density",
                "NaN",
            ),
            (
                InertialOptions {
                    min_mass: -1.0,
                    ..Default::default()
                },
                "min_mass",
                "-1",
            ),
            (
                InertialOptions {
                    min_thickness: f64::INFINITY,
                    ..Default::default()
                },
                "min_thickness",
                "inf",
            ),
        ] {
            let e = opts.validate().unwrap_err();
            let CoreError::Invalid(inv) = &e else {
                panic!("{e}")
            };
            assert_eq!(inv.field, field);
            assert_eq!(inv.limit, "finite and > 0");
            assert_eq!(inv.value, value);
            let s = e.to_string();
            assert!(
                s.contains(field) && s.contains("> 0") && s.contains(value),
                "{s}"
            );
        }
        InertialOptions::default().validate().unwrap();
    }
}
