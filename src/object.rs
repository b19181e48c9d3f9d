//! The articulated object: parts, joints, validation and forward kinematics.
//!
//! Why it exists: this is the type every later layer passes around: projection produces it,
//! exporters consume it, the API (de)serialises it through `io::object_json`. It holds an
//! *already valid* object (a tree of at most [`MAX_PARTS`] parts with unit joint axes and
//! sorted limits); [`ArticulatedObject::validate`] is the gate, and its errors name the field,
//! the limit and the value.
//!
//! Conventions (see ARCHITECTURE.md, "Canonical frame"): metres, object frame +Z up, every part
//! frame axis-aligned with its origin at the part's box centre (method.md §1.8). A joint says
//! "the child moves relative to the parent by a screw about `line` (object frame, rest state)
//! with angle θ ∈ `revolute` and displacement d ∈ `prismatic`" (method.md §1.4). Forward
//! kinematics: see [`crate::kinematics`].

use nalgebra::{Isometry3, Point3, Translation3, Vector3};

use crate::error::{CoreError, CoreResult, check_finite};
use crate::kinematics::{PluckerLine, screw_transform};
use crate::shape::{PartShape, Primitive};

/// Maximum number of parts (NAP's K).
pub const MAX_PARTS: usize = 8;
/// Shape latent dimension (NAP's F).
pub const LATENT_DIM: usize = 128;
/// Range width below which a joint's rotation or translation counts as absent (NAP's
/// visualiser threshold, method.md §5.7): 3e-3 rad for rotation, 3e-3 m for translation.
pub const JOINT_RANGE_TOL: f64 = 3e-3;

/// Joint type, decided from which ranges are wider than [`JOINT_RANGE_TOL`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum JointKind {
    /// Rotation only.
    Revolute,
    /// Translation only.
    Prismatic,
    /// Rotation and translation about the same axis (e.g. a bottle cap).
    Screw,
    /// No motion.
    Fixed,
}

impl JointKind {
    /// Classify from the two range widths (radians, metres).
    pub fn from_ranges(revolute: [f64; 2], prismatic: [f64; 2]) -> Self {
        let r = (revolute[1] - revolute[0]).abs() > JOINT_RANGE_TOL;
        let p = (prismatic[1] - prismatic[0]).abs() > JOINT_RANGE_TOL;
        match (r, p) {
            (true, true) => JointKind::Screw,
            (true, false) => JointKind::Revolute,
            (false, true) => JointKind::Prismatic,
            (false, false) => JointKind::Fixed,
        }
    }

    /// Lower-case name used in files and APIs.
    pub fn as_str(self) -> &'static str {
        match self {
            JointKind::Revolute => "revolute",
            JointKind::Prismatic => "prismatic",
            JointKind::Screw => "screw",
            JointKind::Fixed => "fixed",
        }
    }

    /// Whether the joint rotates.
    pub fn rotates(self) -> bool {
        matches!(self, JointKind::Revolute | JointKind::Screw)
    }

    /// Whether the joint translates.
    pub fn slides(self) -> bool {
        matches!(self, JointKind::Prismatic | JointKind::Screw)
    }
}

/// One rigid part.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    /// Human-readable name, unique within the object.
    pub name: String,
    /// Box half-extents (metres), each > 0.
    pub half_extents: Vector3<f64>,
    /// Box centre in the object frame at rest.
    pub center: Vector3<f64>,
    /// Geometry.
    pub shape: PartShape,
}

impl Part {
    /// Normalisation scale κ = 2‖b‖₂ between the part frame and the shape prior's frame.
    pub fn kappa(&self) -> f64 {
        2.0 * self.half_extents.norm()
    }

    /// Box volume 8·b_x·b_y·b_z.
    pub fn volume(&self) -> f64 {
        8.0 * self.half_extents.x * self.half_extents.y * self.half_extents.z
    }
}

/// A joint between two parts.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// Index of the parent part.
    pub parent: usize,
    /// Index of the child part (moves relative to the parent).
    pub child: usize,
    /// Type; must agree with the ranges (inactive ranges are [0, 0]).
    pub kind: JointKind,
    /// Unit axis direction, object frame.
    pub axis: Vector3<f64>,
    /// A point on the axis, object frame at rest (used as the URDF joint origin).
    pub origin: Point3<f64>,
    /// Rotation range [lower, upper] in radians, lower ≤ upper.
    pub revolute: [f64; 2],
    /// Translation range [lower, upper] in metres, lower ≤ upper.
    pub prismatic: [f64; 2],
}

impl Joint {
    /// The joint line in Plücker coordinates.
    pub fn line(&self) -> PluckerLine {
        PluckerLine::through(&self.origin, &self.axis)
    }

    /// Motion of the child relative to the parent (object frame, from rest) at state `q`.
    pub fn motion(&self, q: JointState) -> Isometry3<f64> {
        screw_transform(&self.line(), q.angle, q.displacement)
    }

    /// The state a fraction `f` ∈ [0, 1] of the way from the lower to the upper limits.
    pub fn state_at(&self, f: f64) -> JointState {
        JointState {
            angle: self.revolute[0] + f * (self.revolute[1] - self.revolute[0]),
            displacement: self.prismatic[0] + f * (self.prismatic[1] - self.prismatic[0]),
        }
    }
}

/// One joint's configuration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointState {
    /// Rotation angle θ (radians).
    pub angle: f64,
    /// Translation d (metres).
    pub displacement: f64,
}

/// A complete articulated object.
#[derive(Debug, Clone, PartialEq)]
pub struct ArticulatedObject {
    /// Object name (used for the URDF robot name).
    pub name: String,
    /// Category label (e.g. "StorageFurniture"), if known.
    pub category: Option<String>,
    /// Parts, 1 to [`MAX_PARTS`].
    pub parts: Vec<Part>,
    /// Joints; together with the parts they form a tree (parts − 1 joints).
    pub joints: Vec<Joint>,
}

impl ArticulatedObject {
    /// Check every invariant; errors name the field, the limit and the value.
    pub fn validate(&self) -> CoreResult<()> {
        let n = self.parts.len();
        if n == 0 || n > MAX_PARTS {
            return Err(CoreError::invalid(
                "parts",
                format!("between 1 and {MAX_PARTS} parts"),
                format!("{n} parts"),
            ));
        }
        if self.name.trim().is_empty() {
            return Err(CoreError::invalid("name", "non-empty", "\"\""));
        }
        for (i, p) in self.parts.iter().enumerate() {
            validate_part(i, p)?;
            if let Some(j) = self.parts[..i].iter().position(|q| q.name == p.name) {
                return Err(CoreError::invalid(
                    format!("parts[{i}].name"),
                    format!("unique (parts[{j}] has the same name)"),
                    format!("{:?}", p.name),
                ));
            }
        }
        if self.joints.len() != n - 1 {
            return Err(CoreError::invalid(
                "joints",
                format!("exactly {} joints for {n} parts (a tree)", n - 1),
                format!("{} joints", self.joints.len()),
            ));
        }
        let mut parent_of: Vec<Option<usize>> = vec![None; n];
        for (k, j) in self.joints.iter().enumerate() {
            validate_joint(k, j, n)?;
            if let Some(prev) = parent_of[j.child] {
                return Err(CoreError::Structure(format!(
                    "part {} ({:?}) has two parent joints (joints {prev} and {k})",
                    j.child, self.parts[j.child].name
                )));
            }
            parent_of[j.child] = Some(k);
        }
        // n − 1 joints, each part at most one parent: exactly one root. Reject cycles.
        for start in 0..n {
            let mut cur = start;
            for _ in 0..=n {
                match parent_of[cur] {
                    Some(k) => cur = self.joints[k].parent,
                    None => break,
                }
            }
            if parent_of[cur].is_some() {
                return Err(CoreError::Structure(format!(
                    "joints form a cycle through part {start} ({:?})",
                    self.parts[start].name
                )));
            }
        }
        Ok(())
    }

    /// Index of the root part (the one without a parent joint).
    pub fn root(&self) -> usize {
        (0..self.parts.len())
            .find(|&i| self.joints.iter().all(|j| j.child != i))
            .unwrap_or(0)
    }

    /// Index of the joint whose child is `part`, if any.
    pub fn parent_joint(&self, part: usize) -> Option<usize> {
        self.joints.iter().position(|j| j.child == part)
    }

    /// Joints in an order where every parent is reached before its children (root first).
    pub fn joints_topological(&self) -> Vec<usize> {
        let mut order = Vec::with_capacity(self.joints.len());
        let mut frontier = vec![self.root()];
        while let Some(p) = frontier.pop() {
            for (k, j) in self.joints.iter().enumerate() {
                if j.parent == p {
                    order.push(k);
                    frontier.push(j.child);
                }
            }
        }
        order
    }

    /// Per-part motion from rest (object frame) at the given joint states (one per joint).
    pub fn part_motions(&self, states: &[JointState]) -> Vec<Isometry3<f64>> {
        let mut delta = vec![Isometry3::identity(); self.parts.len()];
        for k in self.joints_topological() {
            let j = &self.joints[k];
            let q = states.get(k).copied().unwrap_or_default();
            delta[j.child] = delta[j.parent] * j.motion(q);
        }
        delta
    }

    /// Per-part pose (part frame → object frame) at the given joint states.
    pub fn part_poses(&self, states: &[JointState]) -> Vec<Isometry3<f64>> {
        self.part_motions(states)
            .into_iter()
            .zip(&self.parts)
            .map(|(d, p)| {
                d * Isometry3::from_parts(Translation3::from(p.center), Default::default())
            })
            .collect()
    }

    /// Every joint a fraction `f` of the way through its range.
    pub fn states_at(&self, f: f64) -> Vec<JointState> {
        self.joints.iter().map(|j| j.state_at(f)).collect()
    }

    /// The diagonal of the union of the parts' boxes at rest (NaN without parts): the object's
    /// size in every relative tolerance (repair, pruning, ranking, the real-scan metrics).
    pub fn box_diagonal(&self) -> f64 {
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for p in &self.parts {
            lo = lo.inf(&(p.center - p.half_extents));
            hi = hi.sup(&(p.center + p.half_extents));
        }
        if self.parts.is_empty() {
            f64::NAN
        } else {
            (hi - lo).norm()
        }
    }

    /// The same object uniformly scaled by `f` > 0 about the origin: boxes, centres, joint
    /// origins, slide ranges and primitive shapes (latent shapes live in the box's normalised
    /// frame and need nothing; angles are unchanged).
    pub fn scaled(&self, f: f64) -> ArticulatedObject {
        let prim = |p: &Primitive| match *p {
            Primitive::Cuboid {
                center,
                half_extents,
            } => Primitive::Cuboid {
                center: center * f,
                half_extents: half_extents * f,
            },
            Primitive::Sphere { center, radius } => Primitive::Sphere {
                center: center * f,
                radius: radius * f,
            },
            Primitive::Cylinder {
                center,
                axis,
                radius,
                half_height,
            } => Primitive::Cylinder {
                center: center * f,
                axis,
                radius: radius * f,
                half_height: half_height * f,
            },
        };
        ArticulatedObject {
            parts: self
                .parts
                .iter()
                .map(|p| Part {
                    half_extents: p.half_extents * f,
                    center: p.center * f,
                    shape: match &p.shape {
                        PartShape::Primitives(list) => {
                            PartShape::Primitives(list.iter().map(prim).collect())
                        }
                        other => other.clone(),
                    },
                    ..p.clone()
                })
                .collect(),
            joints: self
                .joints
                .iter()
                .map(|j| Joint {
                    origin: Point3::from(j.origin.coords * f),
                    prismatic: [j.prismatic[0] * f, j.prismatic[1] * f],
                    ..j.clone()
                })
                .collect(),
            ..self.clone()
        }
    }
}

impl ArticulatedObject {
    /// Merge every fixed-joint child into its parent (method.md §1.2: a node is a rigid link
    /// with its fixed-joint children). Shapes become unions of primitives in the merged part's
    /// frame (a `Box` part becomes one cuboid); boxes become the union of the boxes. Latent
    /// shapes cannot be merged: a fixed joint under a latent part is an error.
    ///
    /// Returns the merged object and, for every old part, the index of the part it went into.
    pub fn merge_fixed(&self) -> CoreResult<(ArticulatedObject, Vec<usize>)> {
        self.validate()?;
        let n = self.parts.len();
        // Representative (movable ancestor or root) of every part.
        let mut rep: Vec<usize> = (0..n).collect();
        for k in self.joints_topological() {
            let j = &self.joints[k];
            if j.kind == JointKind::Fixed {
                rep[j.child] = rep[j.parent];
            }
        }
        let kept: Vec<usize> = (0..n).filter(|&p| rep[p] == p).collect();
        let new_index = |p: usize| kept.iter().position(|&q| q == rep[p]).unwrap_or(0);
        let mut parts = Vec::with_capacity(kept.len());
        for &k in &kept {
            let members: Vec<usize> = (0..n).filter(|&p| rep[p] == k).collect();
            if members.len() == 1 {
                parts.push(self.parts[k].clone());
                continue;
            }
            let (mut lo, mut hi) = (
                Vector3::repeat(f64::INFINITY),
                Vector3::repeat(f64::NEG_INFINITY),
            );
            for &m in &members {
                let p = &self.parts[m];
                lo = lo.inf(&(p.center - p.half_extents));
                hi = hi.sup(&(p.center + p.half_extents));
            }
            let center = (lo + hi) / 2.0;
            let mut prims = Vec::new();
            for &m in &members {
                let p = &self.parts[m];
                let offset = p.center - center;
                match &p.shape {
                    PartShape::Box => prims.push(Primitive::Cuboid {
                        center: offset,
                        half_extents: p.half_extents,
                    }),
                    PartShape::Primitives(list) => {
                        prims.extend(list.iter().map(|q| q.translated(&offset)))
                    }
                    PartShape::Latent(_) => {
                        return Err(CoreError::invalid(
                            format!("parts[{m}].shape"),
                            "an analytic shape (latent parts cannot be merged by a fixed joint)",
                            "latent",
                        ));
                    }
                }
            }
            parts.push(Part {
                name: self.parts[k].name.clone(),
                half_extents: (hi - lo) / 2.0,
                center,
                shape: PartShape::Primitives(prims),
            });
        }
        let joints = self
            .joints
            .iter()
            .filter(|j| j.kind != JointKind::Fixed)
            .map(|j| Joint {
                parent: new_index(j.parent),
                child: new_index(j.child),
                ..j.clone()
            })
            .collect();
        let merged = ArticulatedObject {
            name: self.name.clone(),
            category: self.category.clone(),
            parts,
            joints,
        };
        merged.validate()?;
        Ok((merged, (0..n).map(new_index).collect()))
    }
}

fn validate_part(i: usize, p: &Part) -> CoreResult<()> {
    if p.name.trim().is_empty() {
        return Err(CoreError::invalid(
            format!("parts[{i}].name"),
            "non-empty",
            "\"\"",
        ));
    }
    check_finite(
        &format!("parts[{i}].half_extents"),
        p.half_extents.as_slice(),
    )?;
    check_finite(&format!("parts[{i}].center"), p.center.as_slice())?;
    for (a, v) in p.half_extents.iter().enumerate() {
        if *v <= 0.0 {
            return Err(CoreError::invalid(
                format!("parts[{i}].half_extents[{a}]"),
                "> 0",
                v,
            ));
        }
    }
    match &p.shape {
        PartShape::Box => {}
        PartShape::Latent(code) => {
            if code.len() != LATENT_DIM {
                return Err(CoreError::invalid(
                    format!("parts[{i}].shape.code"),
                    format!("exactly {LATENT_DIM} values"),
                    format!("{} values", code.len()),
                ));
            }
            if let Some((k, v)) = code.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(CoreError::invalid(
                    format!("parts[{i}].shape.code[{k}]"),
                    "finite",
                    v,
                ));
            }
        }
        PartShape::Primitives(prims) => {
            if prims.is_empty() {
                return Err(CoreError::invalid(
                    format!("parts[{i}].shape.primitives"),
                    "at least 1 primitive",
                    "0 primitives",
                ));
            }
            for (k, prim) in prims.iter().enumerate() {
                validate_primitive(&format!("parts[{i}].shape.primitives[{k}]"), prim)?;
            }
        }
    }
    Ok(())
}

fn validate_primitive(field: &str, prim: &Primitive) -> CoreResult<()> {
    let positive = |name: &str, v: f64| -> CoreResult<()> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(CoreError::invalid(
                format!("{field}.{name}"),
                "finite and > 0",
                v,
            ))
        }
    };
    match prim {
        Primitive::Cuboid {
            center,
            half_extents,
        } => {
            check_finite(&format!("{field}.center"), center.as_slice())?;
            for (a, v) in half_extents.iter().enumerate() {
                positive(&format!("half_extents[{a}]"), *v)?;
            }
        }
        Primitive::Sphere { center, radius } => {
            check_finite(&format!("{field}.center"), center.as_slice())?;
            positive("radius", *radius)?;
        }
        Primitive::Cylinder {
            center,
            radius,
            half_height,
            ..
        } => {
            check_finite(&format!("{field}.center"), center.as_slice())?;
            positive("radius", *radius)?;
            positive("half_height", *half_height)?;
        }
    }
    Ok(())
}

fn validate_joint(k: usize, j: &Joint, n: usize) -> CoreResult<()> {
    let f = |name: &str| format!("joints[{k}].{name}");
    for (name, idx) in [("parent", j.parent), ("child", j.child)] {
        if idx >= n {
            return Err(CoreError::invalid(
                f(name),
                format!("a part index below {n}"),
                idx,
            ));
        }
    }
    if j.parent == j.child {
        return Err(CoreError::invalid(
            f("child"),
            "different from the parent",
            j.child,
        ));
    }
    check_finite(&f("axis"), j.axis.as_slice())?;
    check_finite(&f("origin"), j.origin.coords.as_slice())?;
    check_finite(&f("revolute"), &j.revolute)?;
    check_finite(&f("prismatic"), &j.prismatic)?;
    let norm = j.axis.norm();
    if (norm - 1.0).abs() > 1e-6 {
        return Err(CoreError::invalid(
            f("axis"),
            "a unit vector",
            format!("norm {norm}"),
        ));
    }
    for (name, r) in [("revolute", j.revolute), ("prismatic", j.prismatic)] {
        if r[0] > r[1] {
            return Err(CoreError::invalid(
                f(name),
                "lower <= upper",
                format!("[{}, {}]", r[0], r[1]),
            ));
        }
    }
    let inactive = |name: &str, r: [f64; 2]| -> CoreResult<()> {
        if r != [0.0, 0.0] {
            return Err(CoreError::invalid(
                f(name),
                format!("[0, 0] for a {} joint", j.kind.as_str()),
                format!("[{}, {}]", r[0], r[1]),
            ));
        }
        Ok(())
    };
    if !j.kind.rotates() {
        inactive("revolute", j.revolute)?;
    }
    if !j.kind.slides() {
        inactive("prismatic", j.prismatic)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn door() -> ArticulatedObject {
        let body = Part {
            name: "body".into(),
            half_extents: Vector3::new(0.3, 0.3, 0.5),
            center: Vector3::new(0.0, 0.0, 0.5),
            shape: PartShape::Box,
        };
        let door = Part {
            name: "door".into(),
            half_extents: Vector3::new(0.01, 0.3, 0.5),
            center: Vector3::new(0.31, 0.0, 0.5),
            shape: PartShape::Box,
        };
        ArticulatedObject {
            name: "cab".into(),
            category: None,
            parts: vec![body, door],
            joints: vec![Joint {
                parent: 0,
                child: 1,
                kind: JointKind::Revolute,
                axis: Vector3::z(),
                origin: Point3::new(0.32, -0.3, 0.0),
                revolute: [0.0, 1.5],
                prismatic: [0.0, 0.0],
            }],
        }
    }

    #[test]
    fn door_swings_about_its_hinge() {
        let obj = door();
        obj.validate().unwrap();
        let poses = obj.part_poses(&[JointState {
            angle: std::f64::consts::FRAC_PI_2,
            displacement: 0.0,
        }]);
        // The hinge point stays put; the door centre rotates a quarter turn about it.
        let hinge = Point3::new(0.32, -0.3, 0.5);
        let c = poses[1] * Point3::origin();
        assert!(((c - hinge).norm() - (Point3::new(0.31, 0.0, 0.5) - hinge).norm()).abs() < 1e-12);
        assert!((poses[0] * Point3::origin() - Point3::new(0.0, 0.0, 0.5)).norm() < 1e-12);
    }

    #[test]
    fn validation_names_field_limit_and_value() {
        let mut obj = door();
        obj.parts[1].half_extents.y = -0.2;
        let e = obj.validate().unwrap_err().to_string();
        assert!(
            e.contains("parts[1].half_extents[1]") && e.contains("> 0") && e.contains("-0.2"),
            "{e}"
        );

        let mut obj = door();
        obj.joints[0].revolute = [1.0, 0.0];
        let e = obj.validate().unwrap_err().to_string();
        assert!(
            e.contains("joints[0].revolute") && e.contains("lower <= upper"),
            "{e}"
        );

        let mut obj = door();
        obj.joints[0].child = 0;
        assert!(obj.validate().is_err());

        let mut obj = door();
        obj.parts[0].center.x = f64::NAN;
        let e = obj.validate().unwrap_err().to_string();
        assert!(
            e.contains("parts[0].center[0]") && e.contains("finite") && e.contains("NaN"),
            "{e}"
        );
    }

    #[test]
    fn more_than_eight_parts_is_refused() {
        let mut obj = door();
        for i in 0..8 {
            let mut p = obj.parts[1].clone();
            p.name = format!("extra{i}");
            obj.parts.push(p);
        }
        let e = obj.validate().unwrap_err().to_string();
        assert!(
            e.contains("parts") && e.contains("between 1 and 8") && e.contains("10 parts"),
            "{e}"
        );
    }
}

#[cfg(test)]
mod merge_tests {
    use super::*;

    #[test]
    fn fixed_children_merge_into_their_parent() {
        let obj = crate::fixtures::eight_part();
        let (m, map) = obj.merge_fixed().unwrap();
        assert_eq!(m.parts.len(), 7);
        assert_eq!(map[1], map[0], "the plinth merges into the body");
        assert!(m.joints.iter().all(|j| j.kind != JointKind::Fixed));
        let body = &m.parts[map[0]];
        // The merged box spans both the body and the plinth.
        assert!((body.center.z - 0.55).abs() < 1e-12 && (body.half_extents.z - 0.55).abs() < 1e-12);
        // Geometry is preserved: the plinth's centre is inside the merged union.
        let sdf = crate::shape::AnalyticSdf {
            primitives: match &body.shape {
                PartShape::Primitives(p) => p,
                _ => panic!("merged shape is a union"),
            },
            half_extents: body.half_extents,
            kappa: body.kappa(),
        };
        let plinth_centre = obj.parts[1].center - body.center;
        assert!(sdf.local(&plinth_centre) < 0.0);
    }
}
