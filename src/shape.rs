//! Part shapes and their signed distance fields.
//!
//! Why it exists: a part's geometry is a signed distance field, negative inside
//! (method.md §4.4). It comes either from the neural shape prior (a 128-d latent code,
//! decoded by a [`LatentDecoder`]) or from exact analytic primitives (the procedural data set
//! and hand-written examples). Meshing, exporting and (later) the guidance losses only see the
//! [`Sdf`] trait, so they do not care which.
//!
//! Frames: primitives are given in the part's *local* frame (metres, origin at the part's box
//! centre, axes parallel to the object frame, method.md §1.8). The shape prior works in the
//! *normalised* frame q = u / κ with κ = 2‖b‖₂ (method.md §4.5, §9 A3), where the part's box
//! has unit diagonal. For an analytic local SDF d(u), the normalised SDF is f(q) = d(κ q) / κ.

use nalgebra::Vector3;

/// A signed distance field evaluated in batches (negative inside).
///
/// Batched because the neural decoder is only efficient on thousands of points at once.
pub trait Sdf: Sync {
    /// Write the SDF at each point into `out` (`out.len() == points.len()`).
    fn eval_batch(&self, points: &[[f32; 3]], out: &mut [f32]);
}

impl<F> Sdf for F
where
    F: Fn([f32; 3]) -> f32 + Sync,
{
    fn eval_batch(&self, points: &[[f32; 3]], out: &mut [f32]) {
        for (p, o) in points.iter().zip(out.iter_mut()) {
            *o = self(*p);
        }
    }
}

/// Turns a latent shape code into a normalised-frame SDF (implemented by the shape prior).
pub trait LatentDecoder: Sync {
    /// The SDF of `code` in the normalised part frame.
    fn sdf<'a>(&'a self, code: &'a [f32]) -> Box<dyn Sdf + 'a>;
}

/// Coordinate axis, for axis-aligned primitives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// Object x.
    X,
    /// Object y.
    Y,
    /// Object z (up).
    Z,
}

impl Axis {
    /// Index 0, 1, 2.
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
}

/// An analytic primitive in the part's local frame (metres). Shapes are unions of these.
#[derive(Debug, Clone, PartialEq)]
pub enum Primitive {
    /// Axis-aligned box.
    Cuboid {
        /// Centre in the part frame.
        center: Vector3<f64>,
        /// Half-extents, each > 0.
        half_extents: Vector3<f64>,
    },
    /// Sphere.
    Sphere {
        /// Centre in the part frame.
        center: Vector3<f64>,
        /// Radius > 0.
        radius: f64,
    },
    /// Axis-aligned solid cylinder.
    Cylinder {
        /// Centre in the part frame.
        center: Vector3<f64>,
        /// Axis of the cylinder.
        axis: Axis,
        /// Radius > 0.
        radius: f64,
        /// Half of the height along `axis`, > 0.
        half_height: f64,
    },
}

impl Primitive {
    /// Exact signed distance from `p` (part frame, metres).
    pub fn sdf(&self, p: &Vector3<f64>) -> f64 {
        match self {
            Primitive::Cuboid {
                center,
                half_extents,
            } => box_sdf(&(p - center), half_extents),
            Primitive::Sphere { center, radius } => (p - center).norm() - radius,
            Primitive::Cylinder {
                center,
                axis,
                radius,
                half_height,
            } => {
                let u = p - center;
                let a = axis.index();
                let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                let radial = (u[b] * u[b] + u[c] * u[c]).sqrt() - radius;
                let along = u[a].abs() - half_height;
                let outside = (radial.max(0.0).powi(2) + along.max(0.0).powi(2)).sqrt();
                outside + radial.max(along).min(0.0)
            }
        }
    }

    /// The same primitive moved by `offset`.
    pub fn translated(&self, offset: &Vector3<f64>) -> Primitive {
        let mut p = self.clone();
        match &mut p {
            Primitive::Cuboid { center, .. }
            | Primitive::Sphere { center, .. }
            | Primitive::Cylinder { center, .. } => *center += offset,
        }
        p
    }

    /// Axis-aligned bounds (min, max) in the part frame.
    pub fn bounds(&self) -> (Vector3<f64>, Vector3<f64>) {
        match self {
            Primitive::Cuboid {
                center,
                half_extents,
            } => (center - half_extents, center + half_extents),
            Primitive::Sphere { center, radius } => {
                let r = Vector3::repeat(*radius);
                (center - r, center + r)
            }
            Primitive::Cylinder {
                center,
                axis,
                radius,
                half_height,
            } => {
                let mut h = Vector3::repeat(*radius);
                h[axis.index()] = *half_height;
                (center - h, center + h)
            }
        }
    }
}

/// Exact SDF of an axis-aligned box with half-extents `h` centred at the origin.
pub fn box_sdf(u: &Vector3<f64>, h: &Vector3<f64>) -> f64 {
    let q = u.abs() - h;
    let outside = q.map(|v| v.max(0.0)).norm();
    outside + q.max().min(0.0)
}

/// The geometry of one part.
#[derive(Debug, Clone, PartialEq)]
pub enum PartShape {
    /// The part is its bounding box.
    Box,
    /// A 128-d latent code of the neural shape prior (raw, unscaled).
    Latent(Vec<f32>),
    /// A union of analytic primitives (part frame, metres).
    Primitives(Vec<Primitive>),
}

/// Analytic SDF of a part in its *normalised* frame: f(q) = d(κ q) / κ.
pub struct AnalyticSdf<'a> {
    /// Primitives of the union; empty means "the box `half_extents`".
    pub primitives: &'a [Primitive],
    /// The part's box half-extents (used when `primitives` is empty).
    pub half_extents: Vector3<f64>,
    /// Normalisation scale κ = 2‖b‖₂.
    pub kappa: f64,
}

impl AnalyticSdf<'_> {
    /// SDF in the part frame (metres).
    pub fn local(&self, u: &Vector3<f64>) -> f64 {
        if self.primitives.is_empty() {
            return box_sdf(u, &self.half_extents);
        }
        self.primitives
            .iter()
            .map(|p| p.sdf(u))
            .fold(f64::INFINITY, f64::min)
    }
}

impl Sdf for AnalyticSdf<'_> {
    fn eval_batch(&self, points: &[[f32; 3]], out: &mut [f32]) {
        for (p, o) in points.iter().zip(out.iter_mut()) {
            let u = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) * self.kappa;
            *o = (self.local(&u) / self.kappa) as f32;
        }
    }
}

/// Test decoder: code `[r, …]` is a sphere of radius r in the normalised frame (r ≤ 0: empty).
#[cfg(test)]
pub(crate) struct SphereCodes;

#[cfg(test)]
impl LatentDecoder for SphereCodes {
    fn sdf<'a>(&'a self, code: &'a [f32]) -> Box<dyn Sdf + 'a> {
        let r = code[0];
        Box::new(move |p: [f32; 3]| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitive_sdfs_are_exact_on_simple_points() {
        let b = Primitive::Cuboid {
            center: Vector3::zeros(),
            half_extents: Vector3::new(1.0, 2.0, 3.0),
        };
        assert!((b.sdf(&Vector3::new(2.0, 0.0, 0.0)) - 1.0).abs() < 1e-12);
        assert!((b.sdf(&Vector3::zeros()) + 1.0).abs() < 1e-12);
        let c = Primitive::Cylinder {
            center: Vector3::zeros(),
            axis: Axis::Z,
            radius: 1.0,
            half_height: 2.0,
        };
        assert!((c.sdf(&Vector3::new(3.0, 0.0, 0.0)) - 2.0).abs() < 1e-12);
        assert!((c.sdf(&Vector3::new(0.0, 0.0, 5.0)) - 3.0).abs() < 1e-12);
        assert!((c.sdf(&Vector3::new(0.0, 0.0, 0.0)) + 1.0).abs() < 1e-12);
        let s = Primitive::Sphere {
            center: Vector3::new(1.0, 0.0, 0.0),
            radius: 0.5,
        };
        assert!((s.sdf(&Vector3::zeros()) - 0.5).abs() < 1e-12);
    }
}
