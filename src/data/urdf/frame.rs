//! Signed axes (`+Z`, `-Y`) and the rotation that takes an asset into physnap's canonical frame.
//!
//! Why it exists: assets come with their own conventions (MuJoCo and ROS are Z-up but face any
//! way; a kitchen scene has fixtures facing four walls). physnap's canonical frame is metres,
//! +Z up, front facing −X, floor at z = 0 (real-scans.md §2). `--up A --front B` name the
//! asset's up and front directions; [`canonical_rotation`] maps A → +Z and B → −X exactly
//! (a signed permutation, so no rounding).

use nalgebra::{Matrix3, Vector3};

/// A signed coordinate axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SignedAxis {
    /// 0 = X, 1 = Y, 2 = Z.
    pub index: usize,
    /// +1 or −1.
    pub sign: i8,
}

impl SignedAxis {
    /// Parse `+X`, `-y`, `Z` (sign optional, default +).
    pub fn parse(s: &str) -> Option<SignedAxis> {
        let t = s.trim();
        let (sign, rest) = match t.as_bytes().first()? {
            b'+' => (1, &t[1..]),
            b'-' => (-1, &t[1..]),
            _ => (1, t),
        };
        let index = match rest.to_ascii_lowercase().as_str() {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            _ => return None,
        };
        Some(SignedAxis { index, sign })
    }

    /// The unit vector.
    pub fn vector(self) -> Vector3<f64> {
        let mut v = Vector3::zeros();
        v[self.index] = self.sign as f64;
        v
    }
}

impl std::fmt::Display for SignedAxis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = if self.sign > 0 { '+' } else { '-' };
        write!(f, "{s}{}", ['X', 'Y', 'Z'][self.index])
    }
}

/// Rotation R with R·up = +Z and R·front = −X. `None` when the axes are parallel.
pub fn canonical_rotation(up: SignedAxis, front: SignedAxis) -> Option<Matrix3<f64>> {
    if up.index == front.index {
        return None;
    }
    let (u, f) = (up.vector(), front.vector());
    // Rows: R maps f ↦ −x, f × u ↦ y, u ↦ z (f ⊥ u, det = +1).
    Some(Matrix3::from_rows(&[
        (-f).transpose(),
        f.cross(&u).transpose(),
        u.transpose(),
    ]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_up_and_front() {
        let up = SignedAxis::parse("+Y").unwrap();
        let front = SignedAxis::parse("+Z").unwrap();
        let r = canonical_rotation(up, front).unwrap();
        assert_eq!(r * up.vector(), Vector3::z());
        assert_eq!(r * front.vector(), -Vector3::x());
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        let id = canonical_rotation(
            SignedAxis::parse("z").unwrap(),
            SignedAxis::parse("-X").unwrap(),
        )
        .unwrap();
        assert_eq!(id, Matrix3::identity());
        assert!(canonical_rotation(up, SignedAxis::parse("-Y").unwrap()).is_none());
        assert!(SignedAxis::parse("+W").is_none());
        assert_eq!(front.to_string(), "+Z");
    }
}
