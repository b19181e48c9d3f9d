//! Shared builders of the procedural generator: an object builder that takes primitives in the
//! object frame and produces tight part boxes, and geometry helpers (panels, boxes open on one
//! side, bar handles, knobs).
//!
//! All geometry here is written in the **object frame at rest** (metres, +Z up, front −X):
//! categories place every panel by its min/max corners, which makes exact contacts (shared
//! planes) easy to get right. [`Builder::finish`] converts each part to its tight box and moves
//! its primitives into the part frame.

use nalgebra::{Point3, Vector3};

use crate::data::rng::Rng;
use crate::data::{DataError, LabelledObject};
use crate::object::{ArticulatedObject, Joint, JointKind, MAX_PARTS, Part};
use crate::shape::{Axis, PartShape, Primitive};

pub(crate) type V3 = Vector3<f64>;

/// Shorthand vector.
pub(crate) fn v(x: f64, y: f64, z: f64) -> V3 {
    Vector3::new(x, y, z)
}

/// Axis-aligned box from its min and max corners (object frame).
pub(crate) fn bx(lo: V3, hi: V3) -> Primitive {
    debug_assert!(
        (0..3).all(|i| hi[i] > lo[i]),
        "degenerate box {lo:?} {hi:?}"
    );
    Primitive::Cuboid {
        center: (lo + hi) * 0.5,
        half_extents: (hi - lo) * 0.5,
    }
}

/// Axis-aligned cylinder.
pub(crate) fn cyl(center: V3, axis: usize, radius: f64, half_height: f64) -> Primitive {
    Primitive::Cylinder {
        center,
        axis: axis_of(axis),
        radius,
        half_height,
    }
}

pub(crate) fn axis_of(i: usize) -> Axis {
    match i {
        0 => Axis::X,
        1 => Axis::Y,
        _ => Axis::Z,
    }
}

/// One side of a box: axis and sign of its outward normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Side {
    pub axis: usize,
    pub sign: f64,
}

impl Side {
    pub const FRONT: Side = Side {
        axis: 0,
        sign: -1.0,
    };
    pub const TOP: Side = Side { axis: 2, sign: 1.0 };
}

/// Panels of a box `[lo, hi]` with walls of thickness `wall` on every side except `open`
/// (overlapping at the edges, which is fine inside one part).
pub(crate) fn open_box(lo: V3, hi: V3, wall: f64, open: &[Side]) -> Vec<Primitive> {
    let mut out = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0, 1.0] {
            if open.iter().any(|s| s.axis == axis && s.sign == sign) {
                continue;
            }
            let (mut a, mut b) = (lo, hi);
            if sign < 0.0 {
                b[axis] = lo[axis] + wall;
            } else {
                a[axis] = hi[axis] - wall;
            }
            out.push(bx(a, b));
        }
    }
    out
}

/// A plane face that handles and knobs attach to: outward normal along `axis` with `sign`,
/// at coordinate `level`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Face {
    pub axis: usize,
    pub sign: f64,
    pub level: f64,
}

impl Face {
    /// The front face x = `x` (normal −X).
    pub fn front(x: f64) -> Face {
        Face {
            axis: 0,
            sign: -1.0,
            level: x,
        }
    }

    /// The top face z = `z` (normal +Z).
    pub fn top(z: f64) -> Face {
        Face {
            axis: 2,
            sign: 1.0,
            level: z,
        }
    }

    /// Coordinate `d` in front of the face along its normal.
    fn out(&self, d: f64) -> f64 {
        self.level + self.sign * d
    }

    /// Interval along the normal from the face to `d` in front of it.
    fn span(&self, d0: f64, d1: f64) -> (f64, f64) {
        let (a, b) = (self.out(d0), self.out(d1));
        (a.min(b), a.max(b))
    }

    /// `at` projected onto the face plane.
    pub fn point(&self, at: V3) -> V3 {
        let mut p = at;
        p[self.axis] = self.level;
        p
    }
}

/// Handle shapes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Handle {
    /// A bar on two posts: length along the bar, standoff of the bar from the face, bar
    /// thickness; round bars are cylinders.
    Bar {
        length: f64,
        standoff: f64,
        thickness: f64,
        round: bool,
    },
    /// A round knob: radius and depth (plus a thinner stem).
    Knob { radius: f64, depth: f64 },
    /// A flat pull: a plate along the face edge direction (length, protrusion, height).
    Pull {
        length: f64,
        depth: f64,
        height: f64,
    },
}

impl Handle {
    /// Extent along the bar direction.
    pub fn length(&self) -> f64 {
        match *self {
            Handle::Bar { length, .. } | Handle::Pull { length, .. } => length,
            Handle::Knob { radius, .. } => 2.0 * radius,
        }
    }

    /// Extent across the bar direction (in the face plane).
    pub fn width(&self) -> f64 {
        match *self {
            Handle::Bar { thickness, .. } => thickness,
            Handle::Knob { radius, .. } => 2.0 * radius,
            Handle::Pull { height, .. } => height,
        }
    }

    /// Primitives of the handle centred at `at` (its in-plane coordinates are used) on `face`,
    /// the bar running along axis `along`. Every handle touches the face plane exactly.
    pub fn prims(&self, face: &Face, at: V3, along: usize) -> Vec<Primitive> {
        let n = face.axis;
        let c = 3 - n - along;
        let p = face.point(at);
        let bxn = |n0: f64, n1: f64, half_along: f64, half_c: f64, along_off: f64| {
            let (a, b) = face.span(n0, n1);
            let mut lo = p;
            let mut hi = p;
            lo[n] = a;
            hi[n] = b;
            lo[along] = p[along] + along_off - half_along;
            hi[along] = p[along] + along_off + half_along;
            lo[c] = p[c] - half_c;
            hi[c] = p[c] + half_c;
            bx(lo, hi)
        };
        match *self {
            Handle::Bar {
                length,
                standoff,
                thickness,
                round,
            } => {
                let post = (thickness * 0.8).min(0.02);
                let post_off = length * 0.5 - post * 0.5 - (length * 0.08).min(0.03);
                let mut out = Vec::new();
                if round {
                    let r = thickness * 0.5;
                    let mut center = p;
                    center[n] = face.out(standoff + r);
                    out.push(cyl(center, along, r, length * 0.5));
                    for s in [-1.0, 1.0] {
                        out.push(bxn(0.0, standoff + r, post * 0.5, post * 0.5, s * post_off));
                    }
                } else {
                    out.push(bxn(
                        standoff,
                        standoff + thickness,
                        length * 0.5,
                        thickness * 0.5,
                        0.0,
                    ));
                    for s in [-1.0, 1.0] {
                        out.push(bxn(0.0, standoff, post * 0.5, post * 0.5, s * post_off));
                    }
                }
                out
            }
            Handle::Knob { radius, depth } => {
                let stem = depth * 0.4;
                let mut c1 = p;
                c1[n] = face.out(stem * 0.5);
                let mut c2 = p;
                c2[n] = face.out(stem + (depth - stem) * 0.5);
                vec![
                    cyl(c1, n, radius * 0.5, stem * 0.5),
                    cyl(c2, n, radius, (depth - stem) * 0.5),
                ]
            }
            Handle::Pull {
                length,
                depth,
                height,
            } => vec![bxn(0.0, depth, length * 0.5, height * 0.5, 0.0)],
        }
    }
}

/// A random handle fitting in `max_len` along the bar (and a face at least `max_width` wide
/// across it). `knob_p`: probability of a knob instead of a bar.
pub(crate) fn random_handle(rng: &mut Rng, max_len: f64, knob_p: f64) -> Handle {
    if rng.chance(knob_p) || max_len < 0.07 {
        let radius = rng.range(0.01, 0.02).min(max_len * 0.5);
        return Handle::Knob {
            radius,
            depth: rng.range(0.018, 0.03),
        };
    }
    let length = rng.range(0.06, 0.3).min(max_len);
    if rng.chance(0.15) {
        return Handle::Pull {
            length,
            depth: rng.range(0.015, 0.03),
            height: rng.range(0.01, 0.02),
        };
    }
    Handle::Bar {
        length,
        standoff: rng.range(0.015, 0.03),
        thickness: rng.range(0.008, 0.018),
        round: rng.chance(0.5),
    }
}

/// A knob for appliances: a cylinder with a grip ridge across its front.
pub(crate) fn control_knob(
    face: &Face,
    at: V3,
    radius: f64,
    depth: f64,
    ridge: bool,
) -> Vec<Primitive> {
    let n = face.axis;
    let p = face.point(at);
    let mut c = p;
    c[n] = face.out(depth * 0.5);
    let mut out = vec![cyl(c, n, radius, depth * 0.5)];
    if ridge {
        // A ridge along z (or y for top faces) in front of the disc.
        let along = if n == 2 { 1 } else { 2 };
        let across = 3 - n - along;
        let (a, b) = face.span(depth, depth + depth * 0.6);
        let mut lo = p;
        let mut hi = p;
        lo[n] = a;
        hi[n] = b;
        lo[along] = p[along] - radius * 0.9;
        hi[along] = p[along] + radius * 0.9;
        lo[across] = p[across] - radius * 0.2;
        hi[across] = p[across] + radius * 0.2;
        out.push(bx(lo, hi));
    }
    out
}

/// Accumulates parts (primitives in the object frame) and joints; produces a
/// [`LabelledObject`] with tight part boxes.
pub(crate) struct Builder {
    category: &'static str,
    names: Vec<String>,
    labels: Vec<String>,
    prims: Vec<Vec<Primitive>>,
    joints: Vec<Joint>,
    counters: Vec<(String, usize)>,
}

impl Builder {
    pub fn new(category: &'static str) -> Self {
        Builder {
            category,
            names: Vec::new(),
            labels: Vec::new(),
            prims: Vec::new(),
            joints: Vec::new(),
            counters: Vec::new(),
        }
    }

    /// Number of parts so far.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Parts that can still be added.
    pub fn room(&self) -> usize {
        MAX_PARTS - self.len()
    }

    /// Next unique name `stem_k`.
    pub fn next_name(&mut self, stem: &str) -> String {
        let k = match self.counters.iter_mut().find(|(s, _)| s == stem) {
            Some((_, k)) => {
                *k += 1;
                *k
            }
            None => {
                self.counters.push((stem.to_string(), 0));
                0
            }
        };
        format!("{stem}_{k}")
    }

    /// Add a part; returns its index.
    pub fn part(&mut self, name: impl Into<String>, label: &str, prims: Vec<Primitive>) -> usize {
        self.names.push(name.into());
        self.labels.push(label.to_string());
        self.prims.push(prims);
        self.len() - 1
    }

    /// Number of primitives of a part so far.
    pub fn prim_count(&self, part: usize) -> usize {
        self.prims[part].len()
    }

    /// Add primitives to an existing part (a merged handle, a decoration).
    pub fn extend(&mut self, part: usize, prims: Vec<Primitive>) {
        self.prims[part].extend(prims);
    }

    fn joint(
        &mut self,
        parent: usize,
        child: usize,
        kind: JointKind,
        axis: V3,
        origin: V3,
    ) -> &mut Joint {
        self.joints.push(Joint {
            parent,
            child,
            kind,
            axis: axis.normalize(),
            origin: Point3::from(origin),
            revolute: [0.0, 0.0],
            prismatic: [0.0, 0.0],
        });
        self.joints.last_mut().expect("just pushed")
    }

    pub fn fixed(&mut self, parent: usize, child: usize, origin: V3) {
        self.joint(parent, child, JointKind::Fixed, V3::z(), origin);
    }

    pub fn revolute(&mut self, parent: usize, child: usize, axis: V3, origin: V3, upper: f64) {
        self.joint(parent, child, JointKind::Revolute, axis, origin)
            .revolute = [0.0, upper];
    }

    pub fn prismatic(&mut self, parent: usize, child: usize, axis: V3, origin: V3, upper: f64) {
        self.joint(parent, child, JointKind::Prismatic, axis, origin)
            .prismatic = [0.0, upper];
    }

    /// Attach handle primitives to `owner`: as a separate `handle_k` part on a fixed joint when
    /// `separate` and there is room, else merged into the owner (as PartNet-Mobility often does).
    /// Returns the new part's index when separate.
    pub fn handle(
        &mut self,
        owner: usize,
        prims: Vec<Primitive>,
        origin: V3,
        separate: bool,
    ) -> Option<usize> {
        if separate && self.room() > 0 {
            let name = self.next_name("handle");
            let h = self.part(name, "handle", prims);
            self.fixed(owner, h, origin);
            Some(h)
        } else {
            self.extend(owner, prims);
            None
        }
    }

    /// Tight boxes, part-frame primitives, validation.
    pub fn finish(self) -> Result<LabelledObject, DataError> {
        let mut parts = Vec::with_capacity(self.names.len());
        for (name, prims) in self.names.into_iter().zip(self.prims) {
            let mut lo = V3::repeat(f64::INFINITY);
            let mut hi = V3::repeat(f64::NEG_INFINITY);
            for p in &prims {
                let (a, b) = p.bounds();
                lo = lo.inf(&a);
                hi = hi.sup(&b);
            }
            let center = (lo + hi) * 0.5;
            let local = prims
                .into_iter()
                .map(|p| match p {
                    Primitive::Cuboid {
                        center: c,
                        half_extents,
                    } => Primitive::Cuboid {
                        center: c - center,
                        half_extents,
                    },
                    Primitive::Sphere { center: c, radius } => Primitive::Sphere {
                        center: c - center,
                        radius,
                    },
                    Primitive::Cylinder {
                        center: c,
                        axis,
                        radius,
                        half_height,
                    } => Primitive::Cylinder {
                        center: c - center,
                        axis,
                        radius,
                        half_height,
                    },
                })
                .collect();
            parts.push(Part {
                name,
                half_extents: (hi - lo) * 0.5,
                center,
                shape: PartShape::Primitives(local),
            });
        }
        let object = ArticulatedObject {
            name: self.category.to_lowercase(),
            category: Some(self.category.to_string()),
            parts,
            joints: self.joints,
        };
        object.validate()?;
        Ok(LabelledObject {
            object,
            labels: self.labels,
        })
    }
}

/// A rectangle on a front face: y and z intervals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Rect {
    pub y0: f64,
    pub y1: f64,
    pub z0: f64,
    pub z1: f64,
}

impl Rect {
    pub fn w(&self) -> f64 {
        self.y1 - self.y0
    }
    pub fn h(&self) -> f64 {
        self.z1 - self.z0
    }
    pub fn yc(&self) -> f64 {
        (self.y0 + self.y1) * 0.5
    }
    pub fn zc(&self) -> f64 {
        (self.z0 + self.z1) * 0.5
    }
}

/// Which vertical edge of a front a door hinges on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Hinge {
    /// The −Y edge (the viewer's right when facing the front).
    NegY,
    /// The +Y edge.
    PosY,
}

/// A vertically hinged door slab on the front plane: occupies `x ∈ [x0 − t, x0]` over `r`.
/// Returns (slab primitive, hinge origin, axis). The hinge line runs along the door's front
/// face at the hinge edge, so an opening door never crosses the plane `x0` behind it.
///
/// The back corner of the free edge first sweeps sideways by up to `t²/(2w)` before it clears
/// the plane; the free edge is pulled in by that much so the door never grazes a neighbour.
pub(crate) fn side_hinged_door(x0: f64, t: f64, r: &Rect, hinge: Hinge) -> (Primitive, V3, V3) {
    let sweep = swing_clearance(t, r.w());
    match hinge {
        Hinge::NegY => (
            bx(v(x0 - t, r.y0, r.z0), v(x0, r.y1 - sweep, r.z1)),
            v(x0 - t, r.y0, r.zc()),
            V3::z(),
        ),
        Hinge::PosY => (
            bx(v(x0 - t, r.y0 + sweep, r.z0), v(x0, r.y1, r.z1)),
            v(x0 - t, r.y1, r.zc()),
            -V3::z(),
        ),
    }
}

/// How far the far back edge of a slab of thickness `t` and length `len`, hinged on its front
/// face, moves beyond its rest position while opening: `sqrt(t² + len²) − len` (+10%).
pub(crate) fn swing_clearance(t: f64, len: f64) -> f64 {
    ((t * t + len * len).sqrt() - len) * 1.1
}

/// A drawer on the front plane `x0`: front slab `x ∈ [x0 − t, x0]` over `front`, and an
/// open-top box of depth `depth` behind it fitting `inner` (y/z interior) with wall `w`.
pub(crate) fn drawer_prims(
    x0: f64,
    t: f64,
    front: &Rect,
    inner: &Rect,
    depth: f64,
    w: f64,
) -> Vec<Primitive> {
    let x1 = x0 + depth;
    vec![
        bx(v(x0 - t, front.y0, front.z0), v(x0, front.y1, front.z1)),
        // bottom
        bx(v(x0, inner.y0, inner.z0), v(x1, inner.y1, inner.z0 + w)),
        // sides
        bx(v(x0, inner.y0, inner.z0), v(x1, inner.y0 + w, inner.z1)),
        bx(v(x0, inner.y1 - w, inner.z0), v(x1, inner.y1, inner.z1)),
        // back
        bx(v(x1 - w, inner.y0, inner.z0), v(x1, inner.y1, inner.z1)),
    ]
}

/// Add a side-hinged door part (child of `parent`) on the front plane `x0` with thickness `t`
/// over `r`; returns its index. The door opens outward (towards −X) by up to `upper` radians.
#[allow(clippy::too_many_arguments)]
pub(crate) fn add_side_door(
    b: &mut Builder,
    parent: usize,
    label: &str,
    x0: f64,
    t: f64,
    r: &Rect,
    hinge: Hinge,
    upper: f64,
) -> usize {
    let (slab, origin, axis) = side_hinged_door(x0, t, r, hinge);
    let name = b.next_name("door");
    let d = b.part(name, label, vec![slab]);
    b.revolute(parent, d, axis, origin, upper);
    d
}

/// Add a drawer part (child of `parent`) sliding along −X by up to `upper` metres.
#[allow(clippy::too_many_arguments)]
pub(crate) fn add_drawer(
    b: &mut Builder,
    parent: usize,
    label: &str,
    x0: f64,
    t: f64,
    front: &Rect,
    inner: &Rect,
    depth: f64,
    wall: f64,
    upper: f64,
) -> usize {
    let name = b.next_name("drawer");
    let d = b.part(name, label, drawer_prims(x0, t, front, inner, depth, wall));
    b.prismatic(
        parent,
        d,
        -V3::x(),
        v(x0 - t, front.yc(), front.zc()),
        upper,
    );
    d
}

/// A handle for a side-hinged door over `r` on the front plane `xf` (the door's front face),
/// near the free edge; `z_pref` ∈ [0, 1] says where along the height it goes.
pub(crate) fn door_handle_prims(
    rng: &mut Rng,
    xf: f64,
    r: &Rect,
    hinge: Hinge,
    z_pref: f64,
    knob_p: f64,
) -> (Vec<Primitive>, V3) {
    let h = random_handle(rng, (r.h() * 0.6).min(0.45), knob_p);
    let h = match h {
        Handle::Bar {
            standoff,
            thickness,
            round,
            ..
        } if r.h() > 0.5 => Handle::Bar {
            length: rng.range(0.12, (r.h() * 0.6).min(0.8)),
            standoff,
            thickness,
            round,
        },
        other => other,
    };
    let inset = (h.width() * 0.5 + rng.range(0.02, 0.05)).min(r.w() * 0.3);
    let y = match hinge {
        Hinge::NegY => r.y1 - inset,
        Hinge::PosY => r.y0 + inset,
    };
    let margin = h.length() * 0.5 + 0.02;
    let (lo, hi) = (r.z0 + margin, r.z1 - margin);
    let z = if hi > lo {
        lo + (hi - lo) * z_pref
    } else {
        r.zc()
    };
    let face = Face::front(xf);
    let at = v(xf, y, z);
    (h.prims(&face, at, 2), at)
}

/// A handle for a drawer front over `r` on the front plane `xf`: a horizontal bar, a pull,
/// one knob or (on wide fronts) two knobs.
pub(crate) fn drawer_handle_prims(rng: &mut Rng, xf: f64, r: &Rect) -> (Vec<Primitive>, V3) {
    let face = Face::front(xf);
    let z = if r.h() > 0.2 && rng.chance(0.5) {
        r.z1 - rng.range(0.05, 0.08)
    } else {
        r.zc()
    };
    let at = v(xf, r.yc(), z);
    if r.w() > 0.45 && rng.chance(0.2) {
        let k = random_handle(rng, 0.04, 1.0);
        let off = r.w() * rng.range(0.22, 0.3);
        let mut prims = k.prims(&face, v(xf, r.yc() - off, z), 1);
        prims.extend(k.prims(&face, v(xf, r.yc() + off, z), 1));
        return (prims, at);
    }
    let h = random_handle(rng, (r.w() * 0.6).min(0.4), 0.2);
    let h = match h {
        Handle::Knob { .. } => h,
        _ if r.h() < h.width() + 0.02 => random_handle(rng, 0.03, 1.0),
        _ => h,
    };
    (h.prims(&face, at, 1), at)
}

/// What fills one cell of a front grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Cell {
    Door(Hinge),
    Drawer,
    Open,
}

/// A front to build: its rectangle on the front plane, the cell interior behind it.
pub(crate) struct Front {
    pub rect: Rect,
    pub inner: Rect,
    pub cell: Cell,
    /// Where a door handle goes along the height (0 bottom, 1 top).
    pub z_pref: f64,
}

/// Shared parameters of the fronts of one object.
pub(crate) struct FrontStyle {
    /// Front plane (the body's front face).
    pub x0: f64,
    /// Front thickness.
    pub t: f64,
    /// Depth available behind the front plane for drawer boxes.
    pub depth: f64,
    pub door_label: &'static str,
    pub drawer_label: &'static str,
    /// Probability that a handle becomes its own part.
    pub separate_p: f64,
    /// Probability that a front has no handle.
    pub bare_p: f64,
    /// Range of the doors' upper limits (radians).
    pub door_range: (f64, f64),
    /// Probability of a knob instead of a bar on a door.
    pub door_knob_p: f64,
}

/// Build the fronts (all front parts first, then their handles so fronts never run out of
/// part budget).
pub(crate) fn build_fronts(
    b: &mut Builder,
    rng: &mut Rng,
    body: usize,
    fronts: &[Front],
    st: &FrontStyle,
) {
    let mut made = Vec::new();
    for f in fronts {
        match f.cell {
            Cell::Open => {}
            Cell::Door(h) => {
                let upper = rng.range(st.door_range.0, st.door_range.1);
                let d = add_side_door(b, body, st.door_label, st.x0, st.t, &f.rect, h, upper);
                made.push((d, f));
            }
            Cell::Drawer => {
                let c = rng.range(0.003, 0.01);
                let bw = rng.range(0.006, 0.012);
                let mut ct = rng.range(0.008, 0.03);
                let cb = rng.range(0.002, 0.006);
                let hin = f.inner.h();
                if hin - cb - ct < 2.0 * bw + 0.02 {
                    ct = 0.004;
                }
                let inner = Rect {
                    y0: f.inner.y0 + c,
                    y1: f.inner.y1 - c,
                    z0: f.inner.z0 + cb,
                    z1: f.inner.z1 - ct,
                };
                let depth = rng.range(0.6, 0.97) * (st.depth - 0.005);
                let upper = rng.range(0.5, 0.9) * depth;
                let d = add_drawer(
                    b,
                    body,
                    st.drawer_label,
                    st.x0,
                    st.t,
                    &f.rect,
                    &inner,
                    depth,
                    bw,
                    upper,
                );
                made.push((d, f));
            }
        }
    }
    let xf = st.x0 - st.t;
    let n_fronts = made.len();
    for (d, f) in made {
        if rng.chance(st.bare_p) {
            continue;
        }
        let (prims, at) = match f.cell {
            Cell::Door(h) => door_handle_prims(rng, xf, &f.rect, h, f.z_pref, st.door_knob_p),
            _ => drawer_handle_prims(rng, xf, &f.rect),
        };
        // Fewer separate handles on objects with many fronts (keeps part counts PM-like).
        let p = if n_fronts > 4 {
            st.separate_p * 0.3
        } else {
            st.separate_p
        };
        let separate = rng.chance(p);
        b.handle(d, prims, at, separate);
    }
}

/// Column or row boundaries: `n` cells of the interior `[a, b]` separated by walls `w`;
/// returns the cell interiors and the front boundaries (outer faces at the ends `outer`,
/// divider middles inside).
pub(crate) fn split(
    a: f64,
    b: f64,
    n: usize,
    w: f64,
    outer: (f64, f64),
    weights: &[f64],
) -> (Vec<(f64, f64)>, Vec<f64>) {
    let avail = b - a - (n - 1) as f64 * w;
    let total: f64 = weights.iter().sum();
    let mut cells = Vec::with_capacity(n);
    let mut bounds = vec![outer.0];
    let mut pos = a;
    for (i, wt) in weights.iter().enumerate() {
        let size = avail * wt / total;
        cells.push((pos, pos + size));
        pos += size;
        if i + 1 < n {
            bounds.push(pos + w * 0.5);
            pos += w;
        }
    }
    bounds.push(outer.1);
    (cells, bounds)
}

/// Hinge sides for `c` doors side by side: outer edges for pairs, random for singles.
pub(crate) fn hinges(rng: &mut Rng, c: usize) -> Vec<Hinge> {
    let random = |rng: &mut Rng| {
        if rng.chance(0.5) {
            Hinge::NegY
        } else {
            Hinge::PosY
        }
    };
    match c {
        1 => vec![random(rng)],
        2 => vec![Hinge::NegY, Hinge::PosY],
        _ => {
            let mut h = vec![Hinge::NegY];
            for _ in 1..c - 1 {
                h.push(random(rng));
            }
            h.push(Hinge::PosY);
            h
        }
    }
}
