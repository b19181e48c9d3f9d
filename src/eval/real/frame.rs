//! Scans in a user's frame, for the benchmark: each scan moved by a random yaw and translation
//! (with +Z or +Y up), and how far an estimated frame is from the truth.
//!
//! ```text
//! M = T(t) · Q(up) · Rz(ψ),  ψ ~ U[0°, 360°),  t ~ U[−2, 2]³ m,   Q(+Z) = I,  Q(+Y): +Z ↦ +Y
//! G = F ∘ M   (true canonical → estimated canonical; the identity when F is exact)
//! yaw error   = the rotation angle of G (degrees)
//! floor error = |G(0).z| (metres),  offset = |G(0)| in x/y (metres)
//! ```
//!
//! Why it exists: "finds the frame" has to be measured one way in `eval frame` (the estimate
//! alone, on every scan) and `eval real --frame auto` (generation on the moved scans, every
//! metric computed after mapping the output back by G⁻¹). The move of a scan depends only on
//! its id and the seed, so both commands move a scan the same way.

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::data::rng::Rng;
use crate::frame::ScanFrame;
use crate::mesh::TriMesh;
use crate::object::ArticulatedObject;

/// Which way is up in the moved scans.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MovedUp {
    /// +Z up (only yaw and translation change).
    Z,
    /// +Y up (`--up 0,1,0`).
    Y,
}

impl MovedUp {
    /// Flag name (`z`, `y`).
    pub fn as_str(self) -> &'static str {
        match self {
            MovedUp::Z => "z",
            MovedUp::Y => "y",
        }
    }

    /// Parse a flag name.
    pub fn parse(s: &str) -> Option<MovedUp> {
        match s {
            "z" => Some(MovedUp::Z),
            "y" => Some(MovedUp::Y),
            _ => None,
        }
    }

    /// The up vector the moved scan is given with.
    pub fn vector(self) -> [f64; 3] {
        match self {
            MovedUp::Z => [0.0, 0.0, 1.0],
            MovedUp::Y => [0.0, 1.0, 0.0],
        }
    }
}

/// Most a moved scan is translated along each axis (metres).
pub const MOVE_TRANSLATION: f64 = 2.0;

/// The move of scan `id` (module docs): canonical → the user's frame.
pub fn move_of(id: &str, seed: u64, up: MovedUp) -> Isometry3<f64> {
    // FNV-1a of the id, so the move does not depend on the scan's position in the set.
    let h = id.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    });
    let mut rng = Rng::fork(seed ^ h, 65);
    let yaw = rng.range(0.0, std::f64::consts::TAU);
    let t = Vector3::new(
        rng.range(-MOVE_TRANSLATION, MOVE_TRANSLATION),
        rng.range(-MOVE_TRANSLATION, MOVE_TRANSLATION),
        rng.range(-MOVE_TRANSLATION, MOVE_TRANSLATION),
    );
    let q = match up {
        MovedUp::Z => Rotation3::identity(),
        MovedUp::Y => Rotation3::rotation_between(&Vector3::z(), &Vector3::y())
            .unwrap_or_else(Rotation3::identity),
    };
    let r = q * Rotation3::from_axis_angle(&Vector3::z_axis(), yaw);
    Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&r),
    )
}

/// The frame that undoes `m` exactly (a move of [`move_of`] with `up`): what a perfect
/// estimate returns.
pub fn exact_frame(m: &Isometry3<f64>, up: MovedUp) -> ScanFrame {
    let u = crate::frame::up_rotation(&Vector3::from(up.vector()));
    let yaw_rot = m.rotation.to_rotation_matrix().inverse() * u.inverse();
    let (_, _, yaw) = yaw_rot.euler_angles();
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw) * u;
    let t = -(r * m.translation.vector);
    // `up` is a unit axis and the rest is finite: this cannot fail.
    ScanFrame::new(up.vector(), yaw, t.into()).unwrap_or_default()
}

/// Points moved by `m`.
pub fn moved(m: &Isometry3<f64>, points: &[[f32; 3]]) -> Vec<[f32; 3]> {
    crate::frame::transform_points(m, points)
}

/// How far an estimated frame is from the truth (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameError {
    /// Rotation angle of G, degrees.
    pub yaw_deg: f64,
    /// |G(0).z|, metres.
    pub floor_m: f64,
    /// |G(0)| in x/y: how far the estimated origin is from the asset's, metres.
    pub offset_m: f64,
}

/// G = F ∘ M: true canonical → estimated canonical.
pub fn truth_to_estimate(m: &Isometry3<f64>, f: &ScanFrame) -> Isometry3<f64> {
    f.to_canonical() * m
}

/// The error of `f` for a scan moved by `m`.
pub fn frame_error(m: &Isometry3<f64>, f: &ScanFrame) -> FrameError {
    let g = truth_to_estimate(m, f);
    FrameError {
        yaw_deg: g.rotation.angle().to_degrees(),
        floor_m: g.translation.vector.z.abs(),
        offset_m: g.translation.vector.xy().norm(),
    }
}

/// A generated object and its meshes (estimated canonical frame) moved by `g⁻¹` into the true
/// canonical frame, for the metrics: joint axes and origins, part centres and mesh vertices
/// move (part boxes keep their half extents: the metrics read only the ground truth's).
pub fn to_truth(
    g: &Isometry3<f64>,
    obj: &ArticulatedObject,
    meshes: &[TriMesh],
) -> (ArticulatedObject, Vec<TriMesh>) {
    let inv = g.inverse();
    let mut o = obj.clone();
    for p in &mut o.parts {
        p.center = (inv * Point3::from(p.center)).coords;
    }
    for j in &mut o.joints {
        j.axis = inv.rotation * j.axis;
        j.origin = inv * j.origin;
    }
    let meshes = meshes
        .iter()
        .map(|m| TriMesh {
            positions: moved(&inv, &m.positions),
            ..m.clone()
        })
        .collect();
    (o, meshes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moves_are_per_scan_and_put_up_where_asked() {
        let a = move_of("cab_0", 0, MovedUp::Y);
        assert_eq!(a, move_of("cab_0", 0, MovedUp::Y));
        assert_ne!(a, move_of("cab_1", 0, MovedUp::Y));
        let up = a.rotation * Vector3::z();
        assert!((up - Vector3::y()).norm() < 1e-12);
        let up = move_of("cab_0", 0, MovedUp::Z).rotation * Vector3::z();
        assert!((up - Vector3::z()).norm() < 1e-12);
        assert!(
            a.translation
                .vector
                .iter()
                .all(|t| t.abs() <= MOVE_TRANSLATION)
        );
    }

    #[test]
    fn the_exact_frame_has_no_error_and_maps_outputs_back() {
        for up in [MovedUp::Z, MovedUp::Y] {
            let m = move_of("x", 3, up);
            let f = exact_frame(&m, up);
            let e = frame_error(&m, &f);
            assert!(e.yaw_deg < 1e-6 && e.floor_m < 1e-9, "{e:?}");
            let g = truth_to_estimate(&m, &f);
            assert!(g.translation.vector.norm() < 1e-9, "{g:?}");
        }
    }
}
