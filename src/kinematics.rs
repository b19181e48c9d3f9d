//! Plücker lines, the screw transform and forward kinematics.
//!
//! Why it exists: every joint in NAP/PhysNAP is a general screw about an object-frame line
//! L = (l, m) (unit direction l, moment m = p × l for any point p on the line), with a rotation
//! θ about and a displacement d along it (method.md §6.1):
//!
//! ```text
//! T_screw(l, m, θ, d) = [ R | (I − R) p₀ + d·l ],   R = Rodrigues(l, θ),   p₀ = l × m
//! ```
//!
//! Forward kinematics composes these along the kinematic tree. We express every part's motion
//! as a *delta from the rest state in the object frame*: Δ_root = I and
//! Δ_child = Δ_parent · T_screw(L_joint, θ, d), where L_joint is the joint line at rest. The
//! pose that maps a part's local (box-centred) coordinates to the object frame is then
//! Δ_part · Translation(t_part). This is NAP's `forward_G` with the root at T_g,root instead of
//! the identity (method.md §6.2), so poses stay in the object frame.
//!
//! Reversal identity (why a joint may be re-rooted): T_screw(−L, θ, d) = T_screw(L, θ, d)⁻¹.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

/// A line in Plücker coordinates: unit direction `l` and moment `m = p × l` (m ⟂ l).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PluckerLine {
    /// Unit direction.
    pub l: Vector3<f64>,
    /// Moment, orthogonal to `l`.
    pub m: Vector3<f64>,
}

impl PluckerLine {
    /// The line through `point` with direction `dir` (normalised here; must be non-zero).
    pub fn through(point: &Point3<f64>, dir: &Vector3<f64>) -> Self {
        let l = dir.normalize();
        PluckerLine {
            l,
            m: point.coords.cross(&l),
        }
    }

    /// Project raw (l, m) onto a valid line: l ← l / max(‖l‖, 1e-12), m ← m − (l·m) l
    /// (method.md §5.6). A direction shorter than 1e-12 cannot be normalised; it is replaced by
    /// +Z, so the result is always a valid line.
    pub fn project(l: Vector3<f64>, m: Vector3<f64>) -> Self {
        let n = l.norm();
        let l = if n.is_finite() && n > 1e-12 {
            l / n
        } else {
            Vector3::z()
        };
        let m = m - l * l.dot(&m);
        PluckerLine { l, m }
    }

    /// The point of the line closest to the origin, p₀ = l × m.
    pub fn closest_point_to_origin(&self) -> Point3<f64> {
        Point3::from(self.l.cross(&self.m))
    }

    /// The point of the line closest to `q`.
    pub fn closest_point_to(&self, q: &Point3<f64>) -> Point3<f64> {
        let p0 = self.closest_point_to_origin();
        p0 + self.l * self.l.dot(&(q - p0))
    }

    /// The same line with opposite orientation.
    pub fn reversed(&self) -> Self {
        PluckerLine {
            l: -self.l,
            m: -self.m,
        }
    }

    /// Hemisphere canonicalisation (method.md §1.4 step 3): negate if l_z < 0; if l_z = 0 then
    /// if l_y < 0; if l_z = l_y = 0 then if l_x < 0 (exact comparisons). Returns the canonical
    /// line and whether it was negated.
    pub fn canonical(&self) -> (Self, bool) {
        let l = self.l;
        let negate = if l.z != 0.0 {
            l.z < 0.0
        } else if l.y != 0.0 {
            l.y < 0.0
        } else {
            l.x < 0.0
        };
        if negate {
            (self.reversed(), true)
        } else {
            (*self, false)
        }
    }

    /// The line after a rigid motion `t`.
    pub fn transformed(&self, t: &Isometry3<f64>) -> Self {
        let p = t * self.closest_point_to_origin();
        let l = t.rotation * self.l;
        PluckerLine::through(&p, &l)
    }
}

/// The screw transform: rotation θ about and translation d along the line (method.md §6.1).
pub fn screw_transform(line: &PluckerLine, theta: f64, d: f64) -> Isometry3<f64> {
    let axis = Unit::new_unchecked(line.l);
    let rot = UnitQuaternion::from_axis_angle(&axis, theta);
    let p0 = line.closest_point_to_origin().coords;
    let t = p0 - rot * p0 + line.l * d;
    Isometry3::from_parts(Translation3::from(t), rot)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn canonical_prefers_upper_hemisphere() {
        let line = PluckerLine::through(&Point3::new(1.0, 0.0, 0.0), &Vector3::new(0.0, 0.0, -1.0));
        let (c, neg) = line.canonical();
        assert!(neg);
        assert_eq!(c.l, Vector3::z());
        let (c2, neg2) = PluckerLine::through(&Point3::origin(), &-Vector3::x()).canonical();
        assert!(neg2);
        assert_eq!(c2.l, Vector3::x());
    }

    #[test]
    fn reversed_screw_is_inverse() {
        let line = PluckerLine::through(&Point3::new(0.3, -0.2, 0.5), &Vector3::new(1.0, 2.0, 0.5));
        let a = screw_transform(&line, 0.7, 0.2);
        let b = screw_transform(&line.reversed(), 0.7, 0.2);
        let id = a * b;
        assert!(id.translation.vector.norm() < 1e-12);
        assert!(id.rotation.angle() < 1e-12);
    }
}
