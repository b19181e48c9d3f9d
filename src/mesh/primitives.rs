//! Exact triangle meshes of analytic primitives.
//!
//! Why it exists: procedural parts are unions of primitives with exact SDFs. Their meshes
//! (PartNet-Mobility layout `textured_objs/*.obj`, scans, previews) are written as the
//! *concatenation* of each primitive's closed mesh, like PartNet-Mobility's overlapping leaf
//! meshes. That is exact for boxes (no marching-cubes loss on 2 cm panels) and cheap; a
//! winding-number inside test (`mesh::bvh`) handles the overlaps. Cylinders use
//! [`CYLINDER_SEGMENTS`] sides, spheres a UV grid; both are inscribed polygons.

use nalgebra::Vector3;

use super::TriMesh;
use crate::object::Part;
use crate::shape::{PartShape, Primitive};

/// Sides of a cylinder mesh.
pub const CYLINDER_SEGMENTS: usize = 32;
/// Longitude × latitude segments of a sphere mesh.
pub const SPHERE_SEGMENTS: (usize, usize) = (32, 16);

/// Append a closed, outward (CCW) mesh of `prim` translated by `offset` to `mesh`.
pub fn append_primitive(mesh: &mut TriMesh, prim: &Primitive, offset: &Vector3<f64>) {
    let base = mesh.positions.len() as u32;
    let push = |m: &mut TriMesh, v: Vector3<f64>| {
        let p = v + offset;
        m.positions.push([p.x as f32, p.y as f32, p.z as f32]);
    };
    match prim {
        Primitive::Cuboid {
            center,
            half_extents: h,
        } => {
            for k in 0..8 {
                let s = |bit: usize| if k & (1 << bit) != 0 { 1.0 } else { -1.0 };
                push(
                    mesh,
                    center + Vector3::new(s(0) * h.x, s(1) * h.y, s(2) * h.z),
                );
            }
            // Corner k has x sign bit 0, y bit 1, z bit 2. Quads listed clockwise seen from
            // outside, emitted reversed (CCW).
            const FACES: [[u32; 4]; 6] = [
                [0, 2, 6, 4], // -x
                [1, 5, 7, 3], // +x
                [0, 4, 5, 1], // -y
                [2, 3, 7, 6], // +y
                [0, 1, 3, 2], // -z
                [4, 6, 7, 5], // +z
            ];
            for f in FACES {
                mesh.triangles.push([base + f[0], base + f[2], base + f[1]]);
                mesh.triangles.push([base + f[0], base + f[3], base + f[2]]);
            }
        }
        Primitive::Cylinder {
            center,
            axis,
            radius,
            half_height,
        } => {
            let a = axis.index();
            let (b, c) = ((a + 1) % 3, (a + 2) % 3);
            let n = CYLINDER_SEGMENTS as u32;
            let point = |ang: f64, h: f64| {
                let mut v = Vector3::zeros();
                v[a] = h;
                v[b] = radius * ang.cos();
                v[c] = radius * ang.sin();
                center + v
            };
            for k in 0..n {
                let ang = std::f64::consts::TAU * k as f64 / n as f64;
                push(mesh, point(ang, -half_height));
                push(mesh, point(ang, *half_height));
            }
            let mut cap = Vector3::zeros();
            cap[a] = -half_height;
            push(mesh, center + cap);
            cap[a] = *half_height;
            push(mesh, center + cap);
            let (lo_c, hi_c) = (base + 2 * n, base + 2 * n + 1);
            for k in 0..n {
                let (l0, h0) = (base + 2 * k, base + 2 * k + 1);
                let (l1, h1) = (base + 2 * ((k + 1) % n), base + 2 * ((k + 1) % n) + 1);
                // (b, c, a) is right-handed, so increasing angle is CCW seen from +a.
                mesh.triangles.push([l0, l1, h1]);
                mesh.triangles.push([l0, h1, h0]);
                mesh.triangles.push([hi_c, h0, h1]);
                mesh.triangles.push([lo_c, l1, l0]);
            }
        }
        Primitive::Sphere { center, radius } => {
            let (nu, nv) = SPHERE_SEGMENTS;
            push(mesh, center + Vector3::new(0.0, 0.0, -radius));
            for j in 1..nv {
                let phi = std::f64::consts::PI * j as f64 / nv as f64 - std::f64::consts::FRAC_PI_2;
                for i in 0..nu {
                    let th = std::f64::consts::TAU * i as f64 / nu as f64;
                    push(
                        mesh,
                        center
                            + *radius
                                * Vector3::new(
                                    phi.cos() * th.cos(),
                                    phi.cos() * th.sin(),
                                    phi.sin(),
                                ),
                    );
                }
            }
            push(mesh, center + Vector3::new(0.0, 0.0, *radius));
            let (nu32, nv32) = (nu as u32, nv as u32);
            let ring = |j: u32, i: u32| base + 1 + (j - 1) * nu32 + (i % nu32);
            let top = base + 1 + (nv32 - 1) * nu32;
            for i in 0..nu32 {
                mesh.triangles.push([base, ring(1, i + 1), ring(1, i)]);
                for j in 1..nv32 - 1 {
                    mesh.triangles
                        .push([ring(j, i), ring(j, i + 1), ring(j + 1, i + 1)]);
                    mesh.triangles
                        .push([ring(j, i), ring(j + 1, i + 1), ring(j + 1, i)]);
                }
                mesh.triangles
                    .push([top, ring(nv32 - 1, i), ring(nv32 - 1, i + 1)]);
            }
        }
    }
}

/// Exact mesh of a part in the object frame at rest (box parts give their box; latent parts
/// give `None`: they need the shape decoder).
pub fn part_primitive_mesh(part: &Part) -> Option<TriMesh> {
    let mut mesh = TriMesh::default();
    match &part.shape {
        PartShape::Box => append_primitive(
            &mut mesh,
            &Primitive::Cuboid {
                center: Vector3::zeros(),
                half_extents: part.half_extents,
            },
            &part.center,
        ),
        PartShape::Primitives(prims) => {
            for p in prims {
                append_primitive(&mut mesh, p, &part.center);
            }
        }
        PartShape::Latent(_) => return None,
    }
    Some(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::Axis;

    fn signed_volume(m: &TriMesh) -> f64 {
        m.triangles
            .iter()
            .map(|t| {
                let p = |i: u32| {
                    let v = m.positions[i as usize];
                    Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)
                };
                p(t[0]).dot(&p(t[1]).cross(&p(t[2]))) / 6.0
            })
            .sum()
    }

    #[test]
    fn primitive_meshes_are_closed_outward_and_right_sized() {
        let cases = [
            (
                Primitive::Cuboid {
                    center: Vector3::new(0.1, 0.2, 0.3),
                    half_extents: Vector3::new(0.1, 0.2, 0.3),
                },
                8.0 * 0.1 * 0.2 * 0.3,
            ),
            (
                Primitive::Cylinder {
                    center: Vector3::new(0.0, 1.0, 0.0),
                    axis: Axis::Y,
                    radius: 0.5,
                    half_height: 0.25,
                },
                std::f64::consts::PI * 0.25 * 0.5,
            ),
            (
                Primitive::Sphere {
                    center: Vector3::new(0.0, 0.0, 2.0),
                    radius: 0.5,
                },
                4.0 / 3.0 * std::f64::consts::PI * 0.125,
            ),
        ];
        for axis in [Axis::X, Axis::Z] {
            let c = Primitive::Cylinder {
                center: Vector3::zeros(),
                axis,
                radius: 0.1,
                half_height: 1.0,
            };
            let mut m = TriMesh::default();
            append_primitive(&mut m, &c, &Vector3::zeros());
            assert!(signed_volume(&m) > 0.0, "{axis:?}");
        }
        for (prim, volume) in cases {
            let mut m = TriMesh::default();
            append_primitive(&mut m, &prim, &Vector3::zeros());
            let v = signed_volume(&m);
            // Inscribed polygons lose a little volume (≤ 3% at these segment counts).
            assert!(
                v > 0.0 && (v - volume).abs() / volume < 0.03,
                "{prim:?}: {v} vs {volume}"
            );
            // Closed: every directed edge appears once and its reverse once.
            let mut edges = std::collections::HashMap::new();
            for t in &m.triangles {
                for k in 0..3 {
                    *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
                }
            }
            for (&(a, b), &n) in &edges {
                assert_eq!(n, 1);
                assert_eq!(edges.get(&(b, a)), Some(&1), "{prim:?} open at {a}-{b}");
            }
            // Vertices lie on the primitive's surface.
            for p in &m.positions {
                let d = prim.sdf(&Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64));
                assert!(d.abs() < 1e-6, "{prim:?}: {d}");
            }
        }
    }
}
