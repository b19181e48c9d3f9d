//! Each part's collision geometry: a few convex pieces, separate from its visual mesh.
//!
//! Why it exists: engines collide convex shapes, so the collision of a part must be convex
//! pieces that follow its shape, not the hull of its whole mesh (a cabinet's hull swallows its
//! drawer). Where the exact pieces are known they are used as they are: a box part is its box,
//! a part made of at most `max_pieces` analytic primitives gets one hull per primitive (each is
//! convex). Every other part (latent shapes, many primitives) gets the VHACD decomposition of its
//! mesh ([`crate::mesh::convex::decompose`]). Pieces are in the object frame at rest, like the
//! meshes, so the URDF and MJCF writers place them exactly as they place the visual meshes.

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::error::CoreResult;
use crate::mesh::TriMesh;
use crate::mesh::convex::{DecompositionOptions, decompose, hull};
use crate::mesh::primitives::append_primitive;
use crate::object::{ArticulatedObject, Part};
use crate::shape::{PartShape, Primitive};

/// How collision pieces are made.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CollisionOptions {
    /// Bounds and resolution of the decomposition.
    pub decomposition: DecompositionOptions,
    /// Decompose every part's mesh, even where exact primitive pieces are known (for tests and
    /// for comparing the decomposition with the exact pieces).
    pub always_decompose: bool,
}

impl CollisionOptions {
    /// Check the knobs.
    pub fn validate(&self) -> CoreResult<()> {
        self.decomposition.validate()
    }
}

/// The convex collision pieces of one part (object frame at rest); none for an empty mesh.
pub fn part_pieces(part: &Part, mesh: &TriMesh, opts: &CollisionOptions) -> Vec<TriMesh> {
    if mesh.is_empty() {
        return Vec::new();
    }
    let d = &opts.decomposition;
    let exact = |prims: &[Primitive]| -> Vec<TriMesh> {
        prims
            .iter()
            .filter_map(|p| {
                let mut m = TriMesh::default();
                append_primitive(&mut m, p, &part.center);
                hull(&m.positions, d.max_vertices)
            })
            .collect()
    };
    if !opts.always_decompose {
        match &part.shape {
            PartShape::Box => {
                return exact(&[Primitive::Cuboid {
                    center: Vector3::zeros(),
                    half_extents: part.half_extents,
                }]);
            }
            PartShape::Primitives(prims) if prims.len() <= d.max_pieces => return exact(prims),
            _ => {}
        }
    }
    decompose(mesh, d)
}

/// Every part's pieces, in parallel on the current rayon pool.
pub fn pieces(
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
    opts: &CollisionOptions,
) -> Vec<Vec<TriMesh>> {
    obj.parts
        .par_iter()
        .zip(meshes)
        .map(|(part, mesh)| part_pieces(part, mesh, opts))
        .collect()
}

/// The pieces the engine would make from each whole visual mesh: its convex hull. Only for
/// comparison (EVALUATION reports what the hulls alone would give); export never writes them.
pub fn hulls_only(meshes: &[TriMesh], max_vertices: usize) -> Vec<Vec<TriMesh>> {
    meshes
        .iter()
        .map(|m| hull(&m.positions, max_vertices).into_iter().collect())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures;
    use crate::mesh::{MeshingOptions, mesh_parts};

    #[test]
    fn primitive_parts_get_one_exact_piece_per_primitive() {
        let obj = fixtures::cabinet();
        let meshes = mesh_parts(&obj, None, &MeshingOptions::default()).unwrap();
        let p = pieces(&obj, &meshes, &CollisionOptions::default());
        for (part, ps) in obj.parts.iter().zip(&p) {
            let n = match &part.shape {
                PartShape::Primitives(v) => v.len(),
                PartShape::Box => 1,
                PartShape::Latent(_) => unreachable!(),
            };
            assert_eq!(ps.len(), n, "{}", part.name);
            assert!(
                ps.iter()
                    .all(|m| m.positions.len() == 8 || part_is_round(part))
            );
        }
    }

    fn part_is_round(part: &Part) -> bool {
        matches!(&part.shape, PartShape::Primitives(v)
            if v.iter().any(|p| !matches!(p, Primitive::Cuboid { .. })))
    }

    #[test]
    fn empty_meshes_have_no_pieces() {
        let obj = fixtures::cabinet();
        let p = part_pieces(
            &obj.parts[0],
            &TriMesh::default(),
            &CollisionOptions::default(),
        );
        assert!(p.is_empty());
    }
}
