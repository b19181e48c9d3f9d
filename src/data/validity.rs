//! Physical validity checks every written sample must pass (data.md §C.5 item 6).
//!
//! Why it exists: PhysNAP's constraints are "parts do not interpenetrate, at rest or while a
//! joint moves" and "every movable part is attached to its parent". A procedural generator
//! that occasionally violates them would teach the priors exactly the artefacts the guidance
//! is meant to remove, so every generated object goes through [`check`] before it is written.
//!
//! How: each part's surface is sampled once (area-weighted low-discrepancy points on every
//! primitive face, plus the corners and edge points of cuboids and the rims of cylinders,
//! where contacts and penetrations start), dropping samples that lie strictly inside another
//! primitive of the same part (they are not on its outer surface). A pair of parts penetrates
//! when a sample of one, moved into the other's frame, has the other's analytic union SDF below
//! `−penetration_eps`; both directions are tested. Pairs whose (moved) bounding boxes overlap
//! by at most `penetration_eps` on some axis are skipped, and so are samples outside the other
//! part's box shrunk by `penetration_eps`: neither can penetrate deeper than ε. No meshes.
//!
//! Motion: for each non-fixed joint and each fraction f of `motion_fractions`, the joint is set
//! to `state_at(f)` with all other joints at q = 0, and the parts of the joint's child subtree
//! are tested against every part outside it. Touch: a movable part touches its parent at rest
//! when the minimum over its samples of the parent's SDF (or the other way round) is at most
//! `touch_tol`.

use std::fmt;

use nalgebra::{Isometry3, Point3, Vector3};

use crate::error::CoreError;
use crate::object::{ArticulatedObject, JointKind, JointState};
use crate::shape::{PartShape, Primitive, box_sdf};

/// Tolerances and sampling density of [`check`].
#[derive(Debug, Clone, PartialEq)]
pub struct ValidityOptions {
    /// Penetration deeper than this (metres) is a violation (default 2 mm).
    pub penetration_eps: f64,
    /// A movable part must come within this distance (metres) of its parent (default 3 mm).
    pub touch_tol: f64,
    /// Area-weighted surface samples per part (default 400); cuboid corners and edge points and
    /// cylinder rims are added on top.
    pub samples_per_part: usize,
    /// Fractions of each joint's range at which motion is checked (default 0.25, 0.5, 0.75, 1).
    pub motion_fractions: Vec<f64>,
}

impl Default for ValidityOptions {
    fn default() -> Self {
        ValidityOptions {
            penetration_eps: 0.002,
            touch_tol: 0.003,
            samples_per_part: 400,
            motion_fractions: vec![0.25, 0.5, 0.75, 1.0],
        }
    }
}

/// Where a penetration was found.
#[derive(Debug, Clone, PartialEq)]
pub enum CheckState {
    /// All joints at q = 0.
    Rest,
    /// One joint moved a fraction of its range, all others at rest.
    Joint {
        /// Index of the joint.
        joint: usize,
        /// Name of the joint's child part (joints are named after their child).
        name: String,
        /// Fraction of the range.
        fraction: f64,
    },
}

impl fmt::Display for CheckState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CheckState::Rest => write!(f, "at rest"),
            CheckState::Joint { name, fraction, .. } => {
                write!(f, "at state {fraction} of joint {name}")
            }
        }
    }
}

/// Why an object failed [`check`].
#[derive(Debug, Clone, PartialEq)]
pub enum Violation {
    /// `ArticulatedObject::validate` failed.
    Invalid(CoreError),
    /// The joints do not form a tree.
    NotATree(String),
    /// A part's shape cannot be checked analytically (latent codes need the decoder).
    UnsupportedShape {
        /// The part.
        part: String,
    },
    /// A signed distance or pose came out non-finite.
    NonFinite {
        /// What was being evaluated.
        what: String,
    },
    /// Two parts interpenetrate deeper than the tolerance.
    Penetration {
        /// First part (the moving one for motion checks).
        a: String,
        /// Second part.
        b: String,
        /// Deepest penetration found (metres).
        depth: f64,
        /// Where.
        state: CheckState,
    },
    /// A movable part does not touch its parent at rest.
    Detached {
        /// The child part.
        part: String,
        /// Its parent.
        parent: String,
        /// Smallest distance found between them (metres).
        gap: f64,
    },
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Violation::Invalid(e) => write!(f, "invalid object: {e}"),
            Violation::NotATree(s) => write!(f, "not a tree: {s}"),
            Violation::UnsupportedShape { part } => write!(
                f,
                "part {part} has a latent shape; only primitive and box parts can be checked"
            ),
            Violation::NonFinite { what } => write!(f, "non-finite value in {what}"),
            Violation::Penetration { a, b, depth, state } => write!(
                f,
                "parts {a} and {b} penetrate by {:.1} mm {state}",
                depth * 1000.0
            ),
            Violation::Detached { part, parent, gap } => write!(
                f,
                "part {part} does not touch its parent {parent} (gap {:.1} mm)",
                gap * 1000.0
            ),
        }
    }
}

impl std::error::Error for Violation {}

impl Violation {
    /// Machine-readable kind.
    pub fn kind(&self) -> &'static str {
        match self {
            Violation::Invalid(_) => "invalid",
            Violation::NotATree(_) => "not_a_tree",
            Violation::UnsupportedShape { .. } => "unsupported_shape",
            Violation::NonFinite { .. } => "non_finite",
            Violation::Penetration {
                state: CheckState::Rest,
                ..
            } => "penetration_at_rest",
            Violation::Penetration { .. } => "penetration_in_motion",
            Violation::Detached { .. } => "detached",
        }
    }
}

/// One part prepared for checking: primitives in the part frame, its box and surface samples.
struct Prepared {
    prims: Vec<Primitive>,
    half: Vector3<f64>,
    samples: Vec<Vector3<f64>>,
}

impl Prepared {
    /// Union SDF in the part frame.
    fn sdf(&self, u: &Vector3<f64>) -> f64 {
        self.prims
            .iter()
            .map(|p| p.sdf(u))
            .fold(f64::INFINITY, f64::min)
    }

    /// Whether `u` lies inside the box shrunk by `m` (a cheap necessary condition for an SDF
    /// below −m).
    fn inside_shrunk_box(&self, u: &Vector3<f64>, m: f64) -> bool {
        u.x.abs() < self.half.x - m && u.y.abs() < self.half.y - m && u.z.abs() < self.half.z - m
    }
}

/// Check `obj` against PhysNAP's physical constraints; the first violation found is returned.
///
/// Order: structure (`validate`, tree, shape kinds), penetration at rest, attachment of every
/// movable part to its parent, penetration along each joint's motion.
pub fn check(obj: &ArticulatedObject, opts: &ValidityOptions) -> Result<(), Violation> {
    check_structure(obj)?;
    let prepared: Vec<Prepared> = obj
        .parts
        .iter()
        .map(|p| prepare(&p.shape, p.half_extents, opts.samples_per_part))
        .collect();
    let names: Vec<&str> = obj.parts.iter().map(|p| p.name.as_str()).collect();
    let eps = opts.penetration_eps;

    // Penetration at rest.
    let rest_states = vec![JointState::default(); obj.joints.len()];
    let rest = obj.part_poses(&rest_states);
    let boxes: Vec<_> = rest
        .iter()
        .zip(&prepared)
        .map(|(pose, p)| world_aabb(pose, &p.half))
        .collect();
    for a in 0..prepared.len() {
        for b in a + 1..prepared.len() {
            if let Some(depth) = pair_penetration(&prepared, &rest, &boxes, a, b, eps)? {
                return Err(Violation::Penetration {
                    a: names[a].to_string(),
                    b: names[b].to_string(),
                    depth,
                    state: CheckState::Rest,
                });
            }
        }
    }

    // Every movable part touches its parent at rest.
    for j in &obj.joints {
        let gap = pair_gap(&prepared, &rest, j.child, j.parent, opts.touch_tol);
        if !gap.is_finite() {
            return Err(Violation::NonFinite {
                what: format!(
                    "the distance between {} and {}",
                    names[j.child], names[j.parent]
                ),
            });
        }
        if gap > opts.touch_tol {
            return Err(Violation::Detached {
                part: names[j.child].to_string(),
                parent: names[j.parent].to_string(),
                gap,
            });
        }
    }

    // Penetration along each joint's motion.
    let children = children_lists(obj);
    for (k, joint) in obj.joints.iter().enumerate() {
        if joint.kind == JointKind::Fixed {
            continue;
        }
        let moving = subtree(&children, joint.child);
        let mut is_moving = vec![false; obj.parts.len()];
        for &m in &moving {
            is_moving[m] = true;
        }
        for &f in &opts.motion_fractions {
            let mut states = rest_states.clone();
            states[k] = joint.state_at(f);
            let poses = obj.part_poses(&states);
            if poses.iter().any(|p| {
                !p.translation.vector.iter().all(|v| v.is_finite())
                    || !p.rotation.coords.iter().all(|v| v.is_finite())
            }) {
                return Err(Violation::NonFinite {
                    what: format!(
                        "the part poses at state {f} of joint {}",
                        names[joint.child]
                    ),
                });
            }
            let boxes: Vec<_> = poses
                .iter()
                .zip(&prepared)
                .map(|(pose, p)| world_aabb(pose, &p.half))
                .collect();
            for &m in &moving {
                for s in (0..obj.parts.len()).filter(|&s| !is_moving[s]) {
                    if let Some(depth) = pair_penetration(&prepared, &poses, &boxes, m, s, eps)? {
                        return Err(Violation::Penetration {
                            a: names[m].to_string(),
                            b: names[s].to_string(),
                            depth,
                            state: CheckState::Joint {
                                joint: k,
                                name: names[joint.child].to_string(),
                                fraction: f,
                            },
                        });
                    }
                }
            }
        }
    }
    Ok(())
}

fn check_structure(obj: &ArticulatedObject) -> Result<(), Violation> {
    obj.validate().map_err(|e| match e {
        CoreError::Structure(s) => Violation::NotATree(s),
        CoreError::Invalid(crate::error::Invalid { ref field, .. }) if field == "joints" => {
            Violation::NotATree(e.to_string())
        }
        other => Violation::Invalid(other),
    })?;
    for p in &obj.parts {
        if matches!(p.shape, PartShape::Latent(_)) {
            return Err(Violation::UnsupportedShape {
                part: p.name.clone(),
            });
        }
    }
    Ok(())
}

fn children_lists(obj: &ArticulatedObject) -> Vec<Vec<usize>> {
    let mut children = vec![Vec::new(); obj.parts.len()];
    for j in &obj.joints {
        children[j.parent].push(j.child);
    }
    children
}

fn subtree(children: &[Vec<usize>], root: usize) -> Vec<usize> {
    let mut out = vec![root];
    let mut i = 0;
    while i < out.len() {
        out.extend(children[out[i]].iter().copied());
        i += 1;
    }
    out
}

type Aabb = (Vector3<f64>, Vector3<f64>);

fn world_aabb(pose: &Isometry3<f64>, half: &Vector3<f64>) -> Aabb {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for k in 0..8 {
        let s = |bit: usize| if k & (1 << bit) != 0 { 1.0 } else { -1.0 };
        let c = pose * Point3::new(s(0) * half.x, s(1) * half.y, s(2) * half.z);
        lo = lo.inf(&c.coords);
        hi = hi.sup(&c.coords);
    }
    (lo, hi)
}

/// Smallest overlap of two boxes over the three axes (negative when separated).
fn aabb_overlap(a: &Aabb, b: &Aabb) -> f64 {
    (0..3)
        .map(|i| a.1[i].min(b.1[i]) - a.0[i].max(b.0[i]))
        .fold(f64::INFINITY, f64::min)
}

/// Deepest penetration of `a` and `b` (both directions) if it exceeds `eps`.
fn pair_penetration(
    prepared: &[Prepared],
    poses: &[Isometry3<f64>],
    boxes: &[Aabb],
    a: usize,
    b: usize,
    eps: f64,
) -> Result<Option<f64>, Violation> {
    if aabb_overlap(&boxes[a], &boxes[b]) <= eps {
        return Ok(None);
    }
    let d1 = directed_penetration(&prepared[a], &poses[a], &prepared[b], &poses[b], eps);
    let d2 = directed_penetration(&prepared[b], &poses[b], &prepared[a], &poses[a], eps);
    let depth = d1.max(d2);
    if depth.is_nan() {
        return Err(Violation::NonFinite {
            what: "a signed distance".into(),
        });
    }
    Ok((depth > eps).then_some(depth))
}

/// Deepest penetration (−SDF of `b`) over the samples of `a` that lie inside `b`'s box shrunk
/// by `eps`; 0 when there are none. NaN propagates.
fn directed_penetration(
    a: &Prepared,
    pose_a: &Isometry3<f64>,
    b: &Prepared,
    pose_b: &Isometry3<f64>,
    eps: f64,
) -> f64 {
    let t = pose_b.inv_mul(pose_a);
    let mut depth = 0.0f64;
    for s in &a.samples {
        let u = t.transform_vector(s) + t.translation.vector;
        if !b.inside_shrunk_box(&u, eps) {
            if u.iter().any(|v| v.is_nan()) {
                return f64::NAN;
            }
            continue;
        }
        let d = b.sdf(&u);
        if d.is_nan() {
            return f64::NAN;
        }
        depth = depth.max(-d);
    }
    depth
}

/// Smallest distance between parts `a` and `b` found from the samples of either in the other's
/// SDF; stops early once it is at most `tol`.
fn pair_gap(prepared: &[Prepared], poses: &[Isometry3<f64>], a: usize, b: usize, tol: f64) -> f64 {
    let g = directed_gap(&prepared[a], &poses[a], &prepared[b], &poses[b], tol);
    if g <= tol {
        return g;
    }
    g.min(directed_gap(
        &prepared[b],
        &poses[b],
        &prepared[a],
        &poses[a],
        tol,
    ))
}

fn directed_gap(
    a: &Prepared,
    pose_a: &Isometry3<f64>,
    b: &Prepared,
    pose_b: &Isometry3<f64>,
    tol: f64,
) -> f64 {
    let t = pose_b.inv_mul(pose_a);
    let mut best = f64::INFINITY;
    for s in &a.samples {
        let u = t.transform_vector(s) + t.translation.vector;
        // The box distance is a lower bound of the union SDF.
        if box_sdf(&u, &b.half) >= best {
            continue;
        }
        let d = b.sdf(&u);
        if d.is_nan() {
            return f64::NAN;
        }
        best = best.min(d);
        if best <= tol {
            break;
        }
    }
    best
}

/// Primitives of a part shape in its frame (a `Box` part is one cuboid).
fn shape_primitives(shape: &PartShape, half: Vector3<f64>) -> Vec<Primitive> {
    match shape {
        PartShape::Primitives(p) => p.clone(),
        _ => vec![Primitive::Cuboid {
            center: Vector3::zeros(),
            half_extents: half,
        }],
    }
}

fn prepare(shape: &PartShape, half: Vector3<f64>, n: usize) -> Prepared {
    let prims = shape_primitives(shape, half);
    let mut p = Prepared {
        samples: surface_samples(&prims, n),
        prims,
        half,
    };
    let own: Vec<Vector3<f64>> = p
        .samples
        .iter()
        .copied()
        .filter(|s| p.sdf(s) >= -1e-9)
        .collect();
    p.samples = own;
    p
}

/// Additive recurrence R2 (Roberts 2018): a 2-D low-discrepancy sequence, deterministic.
fn r2(k: usize, offset: f64) -> (f64, f64) {
    const A1: f64 = 0.754_877_666_246_692_7;
    const A2: f64 = 0.569_840_290_998_053_2;
    let k = k as f64;
    (
        (offset + 0.5 + k * A1).fract(),
        (offset * 0.37 + 0.5 + k * A2).fract(),
    )
}

/// Split `n` samples over `weights` proportionally (largest remainder).
fn allocate(weights: &[f64], n: usize) -> Vec<usize> {
    let total: f64 = weights.iter().sum();
    if total <= 0.0 || !total.is_finite() {
        return vec![0; weights.len()];
    }
    let exact: Vec<f64> = weights.iter().map(|w| w / total * n as f64).collect();
    let mut counts: Vec<usize> = exact.iter().map(|e| e.floor() as usize).collect();
    let mut rest = n - counts.iter().sum::<usize>();
    let mut order: Vec<usize> = (0..weights.len()).collect();
    order.sort_by(|&i, &j| {
        let fi = exact[i] - exact[i].floor();
        let fj = exact[j] - exact[j].floor();
        fj.total_cmp(&fi).then(i.cmp(&j))
    });
    for i in order {
        if rest == 0 {
            break;
        }
        counts[i] += 1;
        rest -= 1;
    }
    counts
}

fn primitive_area(p: &Primitive) -> f64 {
    match p {
        Primitive::Cuboid {
            half_extents: h, ..
        } => 8.0 * (h.x * h.y + h.y * h.z + h.z * h.x),
        Primitive::Sphere { radius, .. } => 4.0 * std::f64::consts::PI * radius * radius,
        Primitive::Cylinder {
            radius,
            half_height,
            ..
        } => 2.0 * std::f64::consts::PI * radius * (2.0 * half_height + radius),
    }
}

/// Surface samples of a union of primitives (before removing interior ones): `n` area-weighted
/// points plus cuboid corners and edge points and cylinder rims.
fn surface_samples(prims: &[Primitive], n: usize) -> Vec<Vector3<f64>> {
    let areas: Vec<f64> = prims.iter().map(primitive_area).collect();
    let counts = allocate(&areas, n);
    let mut out = Vec::with_capacity(n + 48 * prims.len());
    for (pi, (prim, &count)) in prims.iter().zip(&counts).enumerate() {
        let offset = (pi as f64 * 0.618_033_988_749_895).fract();
        match prim {
            Primitive::Cuboid {
                center,
                half_extents: h,
            } => {
                // Faces: axis a, sign s; area 4 h_b h_c.
                let face_area = [
                    h.y * h.z,
                    h.y * h.z,
                    h.x * h.z,
                    h.x * h.z,
                    h.x * h.y,
                    h.x * h.y,
                ];
                let fc = allocate(&face_area, count);
                let mut k = 0;
                for (f, &m) in fc.iter().enumerate() {
                    let a = f / 2;
                    let s = if f % 2 == 0 { -1.0 } else { 1.0 };
                    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                    for _ in 0..m {
                        let (u, v) = r2(k, offset);
                        k += 1;
                        let mut p = Vector3::zeros();
                        p[a] = s * h[a];
                        p[b] = (2.0 * u - 1.0) * h[b];
                        p[c] = (2.0 * v - 1.0) * h[c];
                        out.push(center + p);
                    }
                }
                // Corners and edge points (quarter, half, three quarters).
                for corner in 0..8 {
                    let s = |bit: usize| if corner & (1 << bit) != 0 { 1.0 } else { -1.0 };
                    out.push(center + Vector3::new(s(0) * h.x, s(1) * h.y, s(2) * h.z));
                }
                for a in 0..3 {
                    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                    for (sb, sc) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                        for t in [-0.5, 0.0, 0.5] {
                            let mut p = Vector3::zeros();
                            p[a] = t * h[a];
                            p[b] = sb * h[b];
                            p[c] = sc * h[c];
                            out.push(center + p);
                        }
                    }
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
                let side = 2.0 * half_height;
                let fc = allocate(&[side, radius * 0.5, radius * 0.5], count);
                let mut k = 0;
                let tau = std::f64::consts::TAU;
                for (f, &m) in fc.iter().enumerate() {
                    for _ in 0..m {
                        let (u, v) = r2(k, offset);
                        k += 1;
                        let mut p = Vector3::zeros();
                        if f == 0 {
                            p[a] = (2.0 * v - 1.0) * half_height;
                            p[b] = radius * (tau * u).cos();
                            p[c] = radius * (tau * u).sin();
                        } else {
                            let r = radius * u.sqrt();
                            p[a] = if f == 1 { -half_height } else { *half_height };
                            p[b] = r * (tau * v).cos();
                            p[c] = r * (tau * v).sin();
                        }
                        out.push(center + p);
                    }
                }
                for i in 0..16 {
                    let ang = tau * i as f64 / 16.0;
                    for s in [-1.0, 1.0] {
                        let mut p = Vector3::zeros();
                        p[a] = s * half_height;
                        p[b] = radius * ang.cos();
                        p[c] = radius * ang.sin();
                        out.push(center + p);
                    }
                }
            }
            Primitive::Sphere { center, radius } => {
                // Fibonacci sphere.
                let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
                let m = count.max(6);
                for i in 0..m {
                    let z = 1.0 - 2.0 * (i as f64 + 0.5) / m as f64;
                    let r = (1.0 - z * z).sqrt();
                    let th = golden * i as f64;
                    out.push(center + *radius * Vector3::new(r * th.cos(), r * th.sin(), z));
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::object::{Joint, Part};

    fn boxes_object(offset: f64) -> ArticulatedObject {
        let part = |name: &str, c: [f64; 3]| Part {
            name: name.into(),
            half_extents: Vector3::new(0.1, 0.1, 0.1),
            center: Vector3::from(c),
            shape: PartShape::Box,
        };
        ArticulatedObject {
            name: "boxes".into(),
            category: None,
            parts: vec![
                part("left", [0.0, 0.0, 0.1]),
                part("right", [offset, 0.0, 0.1]),
            ],
            joints: vec![Joint {
                parent: 0,
                child: 1,
                kind: JointKind::Fixed,
                axis: Vector3::z(),
                origin: Point3::new(0.1, 0.0, 0.1),
                revolute: [0.0, 0.0],
                prismatic: [0.0, 0.0],
            }],
        }
    }

    #[test]
    fn overlapping_boxes_penetrate_and_name_both_parts() {
        let obj = boxes_object(0.15); // 5 cm overlap
        let v = check(&obj, &ValidityOptions::default()).unwrap_err();
        let msg = v.to_string();
        assert!(
            matches!(
                v,
                Violation::Penetration {
                    state: CheckState::Rest,
                    ..
                }
            ),
            "{msg}"
        );
        assert!(
            msg.contains("left") && msg.contains("right") && msg.contains("at rest"),
            "{msg}"
        );
        if let Violation::Penetration { depth, .. } = v {
            assert!((depth - 0.05).abs() < 0.01, "{depth}");
        }
        // Touching boxes are fine.
        check(&boxes_object(0.2), &ValidityOptions::default()).unwrap();
        // A 1 mm overlap is within the tolerance.
        check(&boxes_object(0.199), &ValidityOptions::default()).unwrap();
    }

    #[test]
    fn cabinet_fixture_is_valid() {
        check(&crate::fixtures::cabinet(), &ValidityOptions::default()).unwrap();
    }

    #[test]
    fn inward_opening_door_is_a_motion_violation() {
        let mut obj = crate::fixtures::cabinet();
        let k = obj
            .joints
            .iter()
            .position(|j| obj.parts[j.child].name == "door")
            .unwrap();
        obj.joints[k].axis = -obj.joints[k].axis;
        let v = check(&obj, &ValidityOptions::default()).unwrap_err();
        let msg = v.to_string();
        assert!(
            matches!(
                v,
                Violation::Penetration {
                    state: CheckState::Joint { .. },
                    ..
                }
            ),
            "{msg}"
        );
        assert!(
            msg.contains("door") && msg.contains("of joint door"),
            "{msg}"
        );
    }

    #[test]
    fn floating_handle_is_detached() {
        let mut obj = crate::fixtures::cabinet();
        let door = obj.parts.iter().position(|p| p.name == "door").unwrap();
        // Away from its own handle the door panel's front face is at x = -0.27; this handle
        // floats 5 cm in front of it.
        obj.parts.push(Part {
            name: "handle_1".into(),
            half_extents: Vector3::new(0.01, 0.01, 0.06),
            center: Vector3::new(-0.33, 0.1, 0.3),
            shape: PartShape::Primitives(vec![Primitive::Cuboid {
                center: Vector3::zeros(),
                half_extents: Vector3::new(0.01, 0.01, 0.06),
            }]),
        });
        obj.joints.push(Joint {
            parent: door,
            child: obj.parts.len() - 1,
            kind: JointKind::Fixed,
            axis: Vector3::z(),
            origin: Point3::new(-0.32, 0.1, 0.3),
            revolute: [0.0, 0.0],
            prismatic: [0.0, 0.0],
        });
        let v = check(&obj, &ValidityOptions::default()).unwrap_err();
        let msg = v.to_string();
        assert!(matches!(v, Violation::Detached { .. }), "{msg}");
        assert!(
            msg.contains("handle_1") && msg.contains("door") && msg.contains("50.0 mm"),
            "{msg}"
        );
    }

    #[test]
    fn structure_errors_are_reported() {
        let mut obj = boxes_object(0.2);
        obj.joints[0].parent = 1; // self-loop
        let v = check(&obj, &ValidityOptions::default()).unwrap_err();
        assert!(matches!(v, Violation::Invalid(_)), "{v}");
        let mut obj = boxes_object(0.2);
        obj.joints.clear();
        let v = check(&obj, &ValidityOptions::default()).unwrap_err();
        assert!(v.to_string().starts_with("not a tree"), "{v}");
        let mut obj = boxes_object(0.2);
        obj.parts[1].shape = PartShape::Latent(vec![0.0; crate::object::LATENT_DIM]);
        assert!(matches!(
            check(&obj, &ValidityOptions::default()),
            Err(Violation::UnsupportedShape { .. })
        ));
    }

    #[test]
    fn samples_lie_on_the_outer_surface() {
        let prims = vec![
            Primitive::Cuboid {
                center: Vector3::zeros(),
                half_extents: Vector3::new(0.2, 0.1, 0.05),
            },
            Primitive::Cylinder {
                center: Vector3::new(0.2, 0.0, 0.0),
                axis: crate::shape::Axis::Z,
                radius: 0.05,
                half_height: 0.05,
            },
            Primitive::Sphere {
                center: Vector3::new(-0.2, 0.0, 0.0),
                radius: 0.04,
            },
        ];
        let p = prepare(
            &PartShape::Primitives(prims),
            Vector3::new(0.25, 0.1, 0.05),
            400,
        );
        assert!(p.samples.len() > 300);
        for s in &p.samples {
            assert!(p.sdf(s).abs() < 1e-9, "{s:?}");
        }
    }
}
