//! The scan's frame: the rigid transform between a user's scan and physnap's canonical frame.
//!
//! ```text
//! canonical frame: +Z up, the front facing −X, the floor at z = 0, centred in x/y
//! p_canonical = R p_scan + t,   R = Rz(yaw) · U(up)
//! ```
//!
//! Why it exists: generation runs in the canonical frame (the prior was trained there), but a
//! depth camera's scan is in the camera's or the room's frame (real-scans.md §7). A
//! [`ScanFrame`] is the one description of that transform, shared by the engine (which moves
//! the scan into the canonical frame), the exporters (which put the model back in the scan's
//! frame: the URDF's `world` link, the GLB's root node, the MJCF's root body) and the JSON
//! writers (`object.json` `frame`). `U(up)` is the smallest rotation taking `up` to +Z (a half
//! turn about +X for `up` = −Z), so `(up, yaw, translation)` describe the transform exactly and
//! the same three numbers give the same bytes everywhere. Estimating it from a scan is the
//! engine's job (`engine::frame`).

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::error::{CoreError, CoreResult};

/// The transform from a scan's frame to the canonical frame (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanFrame {
    /// The scan's up direction, unit length, in the scan's frame.
    pub up: Vector3<f64>,
    /// Rotation about the canonical +Z after `up` was turned onto it, radians in [0, 2π).
    pub yaw: f64,
    /// Added after the rotation (metres, canonical frame).
    pub translation: Vector3<f64>,
}

impl Default for ScanFrame {
    fn default() -> Self {
        ScanFrame::canonical()
    }
}

/// `up` as a unit vector; the error names `field`, the limit and the value.
pub fn check_up(field: &str, up: [f64; 3]) -> CoreResult<Vector3<f64>> {
    let v = Vector3::from(up);
    let n = v.norm();
    if !(up.iter().all(|x| x.is_finite()) && n > 1e-9) {
        return Err(CoreError::invalid(
            field,
            "a finite, non-zero vector x,y,z (the scan's up direction)",
            format!("{},{},{}", up[0], up[1], up[2]),
        ));
    }
    Ok(v / n)
}

/// The smallest rotation taking the unit vector `up` to +Z (a half turn about +X for −Z).
pub fn up_rotation(up: &Vector3<f64>) -> Rotation3<f64> {
    let z = Vector3::z();
    match Rotation3::rotation_between(up, &z) {
        Some(r) => r,
        None if up.dot(&z) > 0.0 => Rotation3::identity(),
        None => Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    }
}

/// `points` moved by `iso` (computed in f64).
pub fn transform_points(iso: &Isometry3<f64>, points: &[[f32; 3]]) -> Vec<[f32; 3]> {
    points
        .iter()
        .map(|p| {
            let q = iso * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            [q.x as f32, q.y as f32, q.z as f32]
        })
        .collect()
}

/// `x,y,z` (three comma-separated numbers, e.g. an `--up` flag or query value); None when it
/// is not three numbers (finiteness is [`check_up`]'s).
pub fn parse_xyz(v: &str) -> Option<[f64; 3]> {
    let c: Vec<f64> = v
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()?;
    (c.len() == 3).then(|| [c[0], c[1], c[2]])
}

impl ScanFrame {
    /// The identity: the scan is already canonical.
    pub fn canonical() -> ScanFrame {
        ScanFrame {
            up: Vector3::z(),
            yaw: 0.0,
            translation: Vector3::zeros(),
        }
    }

    /// A frame from its three numbers; `up` is normalised, `yaw` wrapped into [0, 2π). The
    /// errors name `frame.up`, `frame.yaw` or `frame.translation`.
    pub fn new(up: [f64; 3], yaw: f64, translation: [f64; 3]) -> CoreResult<ScanFrame> {
        let up = check_up("frame.up", up)?;
        if !yaw.is_finite() {
            return Err(CoreError::invalid("frame.yaw", "finite (radians)", yaw));
        }
        crate::error::check_finite("frame.translation", &translation)?;
        Ok(ScanFrame {
            up,
            yaw: yaw.rem_euclid(std::f64::consts::TAU),
            translation: Vector3::from(translation),
        })
    }

    /// Whether this is exactly the identity (outputs are then written as without a frame).
    pub fn is_canonical(&self) -> bool {
        *self == ScanFrame::canonical()
    }

    /// R = Rz(yaw) · U(up).
    pub fn rotation(&self) -> Rotation3<f64> {
        Rotation3::from_axis_angle(&Vector3::z_axis(), self.yaw) * up_rotation(&self.up)
    }

    /// p ↦ R p + t: scan frame → canonical frame.
    pub fn to_canonical(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.translation),
            UnitQuaternion::from_rotation_matrix(&self.rotation()),
        )
    }

    /// The inverse: canonical frame → scan frame (what the exporters write).
    pub fn to_scan(&self) -> Isometry3<f64> {
        self.to_canonical().inverse()
    }

    /// Points of the scan's frame in the canonical frame.
    pub fn points_to_canonical(&self, points: &[[f32; 3]]) -> Vec<[f32; 3]> {
        transform_points(&self.to_canonical(), points)
    }

    /// The canonical → scan transform as a row-major 4×4 matrix.
    pub fn to_scan_matrix(&self) -> [[f64; 4]; 4] {
        let m = self.to_scan().to_homogeneous();
        std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
    }

    /// The URDF `<origin>` of the canonical → scan transform: xyz and fixed-axis roll, pitch,
    /// yaw (R = Rz(yaw) Ry(pitch) Rx(roll)).
    pub fn to_scan_xyz_rpy(&self) -> ([f64; 3], [f64; 3]) {
        let iso = self.to_scan();
        let (r, p, y) = iso.rotation.euler_angles();
        let t = iso.translation.vector;
        ([t.x, t.y, t.z], [r, p, y])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn up_rotation_takes_up_to_z_including_the_antiparallel_case() {
        for up in [
            [0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, -1.0],
            [0.3, -0.4, 0.5],
        ] {
            let u = check_up("up", up).unwrap();
            let r = up_rotation(&u);
            assert!((r * u - Vector3::z()).norm() < 1e-12, "{up:?}");
        }
    }

    #[test]
    fn to_scan_inverts_to_canonical_and_its_rpy_rebuilds_it() {
        let f = ScanFrame::new([0.0, 1.0, 0.0], 1.2, [0.5, -1.5, 0.25]).unwrap();
        let p = Point3::new(0.1, 0.2, 0.3);
        let q = f.to_scan() * (f.to_canonical() * p);
        assert!((q - p).norm() < 1e-12);
        assert!((f.rotation() * f.up - Vector3::z()).norm() < 1e-12);
        let (xyz, [r, pi, y]) = f.to_scan_xyz_rpy();
        let rebuilt = Isometry3::from_parts(
            Translation3::new(xyz[0], xyz[1], xyz[2]),
            UnitQuaternion::from_euler_angles(r, pi, y),
        );
        assert!((rebuilt * p - f.to_scan() * p).norm() < 1e-12);
    }

    #[test]
    fn bad_up_yaw_and_translation_name_the_field() {
        for up in [[0.0; 3], [f64::NAN, 0.0, 1.0], [f64::INFINITY, 0.0, 0.0]] {
            let e = ScanFrame::new(up, 0.0, [0.0; 3]).unwrap_err().to_string();
            assert!(e.contains("frame.up") && e.contains("non-zero"), "{e}");
        }
        let e = ScanFrame::new([0.0, 0.0, 1.0], f64::NAN, [0.0; 3]).unwrap_err();
        assert!(e.to_string().contains("frame.yaw"), "{e}");
        let e = ScanFrame::new([0.0, 0.0, 1.0], 0.0, [0.0, f64::NAN, 0.0]).unwrap_err();
        assert!(e.to_string().contains("frame.translation[1]"), "{e}");
        assert!(ScanFrame::canonical().is_canonical());
        assert!(
            ScanFrame::new([0.0, 0.0, 2.0], 0.0, [0.0; 3])
                .unwrap()
                .is_canonical()
        );
    }
}
