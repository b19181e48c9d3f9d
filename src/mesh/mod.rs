//! Triangle meshes from part SDFs.
//!
//! Why it exists: users take home meshes (GLB, URDF), not fields. A part's SDF lives in its
//! normalised frame; we sample it on a dense grid over the cube [−0.55, 0.55]³ (unit cube plus
//! NAP's 0.1 padding, method.md §5.8), pad the grid by one cell of "far outside" (+1e6) so
//! every surface closes, run marching cubes at level 0 ([`marching_cubes`]), and place the
//! result by the part's box: v_object = t + κ·q with κ = 2‖b‖₂ (PhysNAP's fixed mapping,
//! method.md §8.3 and §9 A3; NAP's post-hoc rescaling is not applied).
//!
//! The grid is sampled by a narrow-band octree ([`sampling`]): only blocks of cells the surface
//! can cross are decoded, in batches through [`Sdf::eval_batch`] that run in parallel on the
//! current rayon pool; the mesh equals the dense grid's while the field is 3-Lipschitz.

pub mod bvh;
pub mod convex;
pub mod decompose;
pub mod marching_cubes;
pub mod obj;
pub mod primitives;
pub mod sampling;
pub mod stl;

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::error::{CoreError, CoreResult};
use crate::object::{ArticulatedObject, Part};
use crate::shape::{AnalyticSdf, LatentDecoder, PartShape, Sdf};

/// An error of the mesh layer's readers and builders; the message names what was wrong (the
/// OBJ line, the grid field and its value, the triangle and its index).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MeshError {
    /// A sampling grid or iso-level marching cubes cannot use, or more vertices than `u32`
    /// indices address.
    #[error("{0}")]
    Grid(String),
    /// OBJ text that is not a triangle mesh.
    #[error("{0}")]
    Obj(String),
    /// Positions and triangles a BVH cannot be built on.
    #[error("{0}")]
    Triangles(String),
}

/// Half-width of the meshing domain in the normalised part frame.
pub const DOMAIN_HALF: f32 = 0.55;
/// Default grid resolution (cells per axis over the domain).
pub const DEFAULT_RESOLUTION: usize = 64;
/// Largest accepted resolution (cells per axis); 256³ ≈ 17 M samples.
pub const MAX_RESOLUTION: usize = 256;

/// An indexed triangle mesh (positions in whatever frame the producer says).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Counter-clockwise (outward-facing) triangles.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Whether there is nothing to draw.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Area-weighted unit vertex normals (+Z for isolated vertices).
    pub fn vertex_normals(&self) -> Vec<[f32; 3]> {
        let mut acc = vec![Vector3::<f64>::zeros(); self.positions.len()];
        let p = |i: u32| {
            let v = self.positions[i as usize];
            Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)
        };
        for t in &self.triangles {
            let n = (p(t[1]) - p(t[0])).cross(&(p(t[2]) - p(t[0])));
            for &i in t {
                acc[i as usize] += n;
            }
        }
        acc.iter()
            .map(|n| {
                let len = n.norm();
                if len > 1e-30 {
                    let u = n / len;
                    [u.x as f32, u.y as f32, u.z as f32]
                } else {
                    [0.0, 0.0, 1.0]
                }
            })
            .collect()
    }

    /// Axis-aligned bounds (min, max); `None` when empty.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let mut it = self.positions.iter();
        let first = *it.next()?;
        Some(it.fold((first, first), |(mut lo, mut hi), v| {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
            (lo, hi)
        }))
    }

    /// Apply `f` to every position.
    pub fn map_positions(mut self, f: impl Fn([f32; 3]) -> [f32; 3]) -> Self {
        for v in &mut self.positions {
            *v = f(*v);
        }
        self
    }
}

/// Meshing options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshingOptions {
    /// Grid cells per axis over [−0.55, 0.55]; 8 ..= [`MAX_RESOLUTION`].
    pub resolution: usize,
}

impl Default for MeshingOptions {
    fn default() -> Self {
        MeshingOptions {
            resolution: DEFAULT_RESOLUTION,
        }
    }
}

impl MeshingOptions {
    /// Check the resolution range.
    pub fn validate(&self) -> CoreResult<()> {
        if !(8..=MAX_RESOLUTION).contains(&self.resolution) {
            return Err(CoreError::invalid(
                "resolution",
                format!("between 8 and {MAX_RESOLUTION}"),
                self.resolution,
            ));
        }
        Ok(())
    }
}

/// Mesh an SDF given in the normalised part frame. Output positions are in that frame.
pub fn extract_normalised(sdf: &dyn Sdf, opts: &MeshingOptions) -> CoreResult<TriMesh> {
    opts.validate()?;
    let r = opts.resolution;
    let spacing = 2.0 * DOMAIN_HALF / r as f32;
    // r + 1 samples per axis over the domain, plus one padding sample on each side.
    let n = r + 3;
    let origin = -DOMAIN_HALF - spacing;
    let coord = |i: usize| origin + spacing * i as f32;
    // The (r + 1)³ interior samples, decoded only near the surface (sampling.rs).
    let m = r + 1;
    let interior = sampling::sample_grid(sdf, r, spacing, &|i| coord(i + 1));
    let mut values = vec![1e6f32; n * n * n];
    for k in 0..m {
        for j in 0..m {
            let src = &interior[m * (j + m * k)..m * (j + 1 + m * k)];
            let dst = &mut values[1 + n * (j + 1 + n * (k + 1))..][..m];
            for (d, &v) in dst.iter_mut().zip(src) {
                // Non-finite decoder output counts as outside, so meshing never fails on it.
                *d = if v.is_finite() { v } else { 1e6 };
            }
        }
    }
    let grid = marching_cubes::ScalarGrid {
        dims: [n, n, n],
        origin: [origin; 3],
        spacing: [spacing; 3],
        values: &values,
    };
    let mc = marching_cubes::marching_cubes(&grid, 0.0)
        .map_err(|e| CoreError::invalid("grid", "a valid sampling grid", e))?;
    Ok(TriMesh {
        positions: mc.positions,
        triangles: mc.triangles,
    })
}

/// Mesh one part in the *object frame at rest*: extract in the normalised frame, then place by
/// the box (v = t + κ q). Latent shapes need `decoder`.
pub fn part_mesh(
    part: &Part,
    decoder: Option<&dyn LatentDecoder>,
    opts: &MeshingOptions,
) -> CoreResult<TriMesh> {
    let kappa = part.kappa();
    let normalised = match &part.shape {
        PartShape::Box => extract_normalised(
            &AnalyticSdf {
                primitives: &[],
                half_extents: part.half_extents,
                kappa,
            },
            opts,
        )?,
        PartShape::Primitives(prims) => extract_normalised(
            &AnalyticSdf {
                primitives: prims,
                half_extents: part.half_extents,
                kappa,
            },
            opts,
        )?,
        PartShape::Latent(code) => {
            let decoder = decoder.ok_or_else(|| {
                CoreError::invalid(
                    format!("part {:?} shape", part.name),
                    "a shape decoder (weights) for latent shapes",
                    "none loaded",
                )
            })?;
            extract_normalised(decoder.sdf(code).as_ref(), opts)?
        }
    };
    let (k, t) = (kappa as f32, part.center.map(|v| v as f32));
    Ok(normalised.map_positions(|q| [t.x + k * q[0], t.y + k * q[1], t.z + k * q[2]]))
}

/// Mesh every part (object frame, rest state), in parallel on the current rayon pool.
pub fn mesh_parts(
    obj: &ArticulatedObject,
    decoder: Option<&dyn LatentDecoder>,
    opts: &MeshingOptions,
) -> Result<Vec<TriMesh>, CoreError> {
    obj.parts
        .par_iter()
        .map(|p| part_mesh(p, decoder, opts))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_part_meshes_to_its_box() {
        let part = Part {
            name: "p".into(),
            half_extents: Vector3::new(0.2, 0.1, 0.05),
            center: Vector3::new(1.0, 2.0, 3.0),
            shape: PartShape::Box,
        };
        let m = part_mesh(&part, None, &MeshingOptions::default()).unwrap();
        let (lo, hi) = m.bounds().unwrap();
        let tol = 2.0 * part.kappa() as f32 * DOMAIN_HALF * 2.0 / DEFAULT_RESOLUTION as f32;
        for a in 0..3 {
            let c = part.center[a] as f32;
            let h = part.half_extents[a] as f32;
            assert!((lo[a] - (c - h)).abs() < tol, "axis {a}: {lo:?}");
            assert!((hi[a] - (c + h)).abs() < tol, "axis {a}: {hi:?}");
        }
    }

    #[test]
    fn latent_without_decoder_is_a_clear_error() {
        let part = Part {
            name: "p".into(),
            half_extents: Vector3::repeat(0.1),
            center: Vector3::zeros(),
            shape: PartShape::Latent(vec![0.0; 128]),
        };
        let e = part_mesh(&part, None, &MeshingOptions::default()).unwrap_err();
        assert!(e.to_string().contains("shape decoder"), "{e}");
    }

    #[test]
    fn resolution_out_of_range_is_refused() {
        let e = MeshingOptions { resolution: 4 }
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("resolution") && e.contains("between 8 and 256") && e.contains('4'));
    }
}
