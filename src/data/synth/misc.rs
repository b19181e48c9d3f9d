//! Laptop, Box, Suitcase, TrashCan, Door and Window.
//!
//! Lids and screens hinge about a horizontal line through the *bottom* back edge of the lid
//! (the top back edge of the container), axis +Y, so the front lifts; a lid rotating about that
//! line never enters the half-space below and in front of it, where the container is. Doors
//! and casement sashes hinge on their front face (see `parts::side_hinged_door`).

use super::parts::{
    Builder, Face, Handle, Hinge, Rect, Side, V3, bx, cyl, hinges, open_box, random_handle,
    side_hinged_door, swing_clearance, v,
};
use crate::data::rng::Rng;
use crate::data::{DataError, LabelledObject};
use crate::shape::Primitive;

pub(super) fn laptop(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("Laptop");
    let w = rng.range(0.25, 0.4);
    let d = rng.range(0.18, 0.28);
    let h = rng.range(0.01, 0.03);
    let st = rng.range(0.004, 0.012);
    let (x0, x1) = (-d * 0.5, d * 0.5);
    let mut base = Vec::new();
    let zf = if rng.chance(0.5) {
        let fh = rng.range(0.002, 0.004);
        for x in [x0 + 0.02, x1 - 0.02] {
            for y in [-w * 0.5 + 0.02, w * 0.5 - 0.02] {
                base.push(cyl(v(x, y, fh * 0.5), 2, 0.006, fh * 0.5));
            }
        }
        fh
    } else {
        0.0
    };
    let zt = zf + h;
    base.push(bx(v(x0, -w * 0.5, zf), v(x1, w * 0.5, zt)));
    let front_m = rng.range(0.0, 0.01);
    let side_m = rng.range(0.0, 0.005);
    let mut screen = vec![bx(
        v(x0 + front_m, -w * 0.5 + side_m, zt),
        v(x1, w * 0.5 - side_m, zt + st),
    )];
    if rng.chance(0.5) {
        let lw = rng.range(0.02, 0.05);
        let xc = (x0 + x1) * 0.5;
        screen.push(bx(
            v(xc - lw * 0.5, -lw * 0.5, zt + st),
            v(xc + lw * 0.5, lw * 0.5, zt + st + 0.001),
        ));
    }
    let base_i = b.part("base", "base_body", base);
    let screen_i = b.part("screen", "screen", screen);
    b.revolute(
        base_i,
        screen_i,
        V3::y(),
        v(x1, 0.0, zt),
        rng.range(1.6, 2.3),
    );
    b.finish()
}

/// A flat lid over `[x0, x1] × [y0, y1]` at height `z` hinged at its back bottom edge.
fn back_hinged_lid(
    b: &mut Builder,
    parent: usize,
    x: (f64, f64),
    y: (f64, f64),
    z: f64,
    lt: f64,
    upper: f64,
) -> usize {
    let lid = b.part("lid", "lid", vec![bx(v(x.0, y.0, z), v(x.1, y.1, z + lt))]);
    b.revolute(parent, lid, V3::y(), v(x.1, (y.0 + y.1) * 0.5, z), upper);
    lid
}

/// Flaps: `(lo, hi)` in the object frame, hinged at the outer bottom edge on `side`.
fn flap(b: &mut Builder, parent: usize, lo: V3, hi: V3, side: Side, upper: f64) {
    let name = b.next_name("flap");
    let f = b.part(name, "lid", vec![bx(lo, hi)]);
    let c = (lo + hi) * 0.5;
    let (origin, axis) = match (side.axis, side.sign > 0.0) {
        (0, false) => (v(lo.x, c.y, lo.z), -V3::y()),
        (0, true) => (v(hi.x, c.y, lo.z), V3::y()),
        (1, false) => (v(c.x, lo.y, lo.z), V3::x()),
        _ => (v(c.x, hi.y, lo.z), -V3::x()),
    };
    b.revolute(parent, f, axis, origin, upper);
}

pub(super) fn box_(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("Box");
    let s = rng.range(0.1, 0.8);
    let d = (s * rng.range(0.7, 1.4)).clamp(0.1, 1.0);
    let w = (s * rng.range(0.7, 1.6)).clamp(0.1, 1.0);
    let h = (s * rng.range(0.5, 1.3)).clamp(0.1, 1.0);
    let wall = (rng.range(0.01, 0.04) * d.min(w).min(h)).max(0.003);
    let (x0, x1, y0, y1) = (-d * 0.5, d * 0.5, -w * 0.5, w * 0.5);
    let body = open_box(v(x0, y0, 0.0), v(x1, y1, h), wall, &[Side::TOP]);
    let body_i = b.part("body", "base_body", body);
    let lt = wall.max(rng.range(0.003, 0.02));
    let g = rng.range(0.001, 0.004);
    let variant = rng.pick(&[0, 0, 1, 2]).to_owned();
    match variant {
        0 => {
            let lid = back_hinged_lid(
                &mut b,
                body_i,
                (x0, x1),
                (y0, y1),
                h,
                lt,
                rng.range(1.6, 2.5),
            );
            if rng.chance(0.3) {
                // A skirt hanging over the front wall.
                let sk = rng.range(0.01, 0.03).min(h * 0.3);
                b.extend(lid, vec![bx(v(x0 - lt, y0, h - sk), v(x0, y1, h + lt))]);
            }
            if rng.chance(0.5) {
                let on_top = rng.chance(0.4);
                let (prims, at) = if on_top {
                    let hd = random_handle(rng, (w * 0.5).min(0.15), 0.3);
                    let at = v(x0 + d * 0.25, 0.0, h + lt);
                    (hd.prims(&Face::top(h + lt), at, 1), at)
                } else {
                    let xf = if b_has_skirt(&b, lid) { x0 - lt } else { x0 };
                    let hd = Handle::Pull {
                        length: rng.range(0.03, 0.08).min(w * 0.5),
                        depth: rng.range(0.008, 0.02),
                        height: lt,
                    };
                    let at = v(xf, 0.0, h + lt * 0.5);
                    (hd.prims(&Face::front(xf), at, 1), at)
                };
                let separate = rng.chance(0.3);
                b.handle(lid, prims, at, separate);
            }
        }
        1 => {
            // Two flaps, split across Y (hinged on the sides) or X (front and back).
            let upper = rng.range(1.6, 2.5);
            if rng.chance(0.5) {
                flap(
                    &mut b,
                    body_i,
                    v(x0, y0, h),
                    v(x1, -g * 0.5, h + lt),
                    Side {
                        axis: 1,
                        sign: -1.0,
                    },
                    upper,
                );
                flap(
                    &mut b,
                    body_i,
                    v(x0, g * 0.5, h),
                    v(x1, y1, h + lt),
                    Side { axis: 1, sign: 1.0 },
                    upper,
                );
            } else {
                flap(
                    &mut b,
                    body_i,
                    v(x0, y0, h),
                    v(-g * 0.5, y1, h + lt),
                    Side {
                        axis: 0,
                        sign: -1.0,
                    },
                    upper,
                );
                flap(
                    &mut b,
                    body_i,
                    v(g * 0.5, y0, h),
                    v(x1, y1, h + lt),
                    Side { axis: 0, sign: 1.0 },
                    upper,
                );
            }
        }
        _ => {
            // Four flaps: full-length side flaps, front and back flaps between them.
            let a = w * rng.range(0.2, 0.35);
            let upper = rng.range(1.6, 2.5);
            flap(
                &mut b,
                body_i,
                v(x0, y0, h),
                v(x1, y0 + a, h + lt),
                Side {
                    axis: 1,
                    sign: -1.0,
                },
                upper,
            );
            flap(
                &mut b,
                body_i,
                v(x0, y1 - a, h),
                v(x1, y1, h + lt),
                Side { axis: 1, sign: 1.0 },
                upper,
            );
            let (ya, yb) = (y0 + a + g, y1 - a - g);
            flap(
                &mut b,
                body_i,
                v(x0, ya, h),
                v(-g * 0.5, yb, h + lt),
                Side {
                    axis: 0,
                    sign: -1.0,
                },
                upper,
            );
            flap(
                &mut b,
                body_i,
                v(g * 0.5, ya, h),
                v(x1, yb, h + lt),
                Side { axis: 0, sign: 1.0 },
                upper,
            );
        }
    }
    b.finish()
}

/// Whether the lid got a front skirt (it then reaches below its hinge height).
fn b_has_skirt(b: &Builder, part: usize) -> bool {
    b.prim_count(part) > 1
}

pub(super) fn suitcase(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("Suitcase");
    let w = rng.range(0.35, 0.5);
    let d = rng.range(0.2, 0.32);
    let h = rng.range(0.5, 0.8);
    let r = rng.range(0.02, 0.04);
    let zb = 2.0 * r;
    let zt = zb + h;
    let (x0, x1, y0, y1) = (-d * 0.5, d * 0.5, -w * 0.5, w * 0.5);
    let xs = x0 + d * rng.range(0.4, 0.5);
    let sw = rng.range(0.004, 0.01);
    let mut body = open_box(v(xs, y0, zb), v(x1, y1, zt), sw, &[Side::FRONT]);
    // Wheels under the body's footprint.
    let hh = rng.range(0.008, 0.014);
    let wx: Vec<f64> = if rng.chance(0.5) {
        vec![x1 - r - 0.01]
    } else {
        vec![x1 - r - 0.01, xs + r + 0.01]
    };
    for x in wx {
        for y in [y0 + 0.03, y1 - 0.03] {
            body.push(cyl(v(x, y, r), 1, r, hh));
            // The fork holding the wheel.
            body.push(bx(
                v(x - 0.006, y - hh - 0.004, r),
                v(x + 0.006, y + hh + 0.004, zb),
            ));
        }
    }
    let hinge = hinges(rng, 1)[0];
    // Side handle on the side away from the hinge (merged).
    if rng.chance(0.4) {
        let (sy, sign) = match hinge {
            Hinge::NegY => (y1, 1.0),
            Hinge::PosY => (y0, -1.0),
        };
        let face = Face {
            axis: 1,
            sign,
            level: sy,
        };
        let hd = Handle::Bar {
            length: ((x1 - xs) * 0.7).min(0.12),
            standoff: rng.range(0.015, 0.025),
            thickness: rng.range(0.01, 0.016),
            round: rng.chance(0.5),
        };
        body.extend(hd.prims(&face, v((xs + x1) * 0.5, sy, (zb + zt) * 0.5), 0));
    }
    let body_i = b.part("body", "base_body", body);
    let mut lid = open_box(
        v(x0, y0, zb),
        v(xs, y1, zt),
        sw,
        &[Side { axis: 0, sign: 1.0 }],
    );
    if rng.chance(0.4) {
        // Ribs on the front shell.
        for k in 0..3 {
            let y = y0 + w * (k as f64 + 1.0) / 4.0;
            lid.push(bx(
                v(x0 - 0.004, y - 0.01, zb + 0.04),
                v(x0, y + 0.01, zt - 0.04),
            ));
        }
    }
    let lid_i = b.part("lid", "lid", lid);
    let (origin, axis) = match hinge {
        Hinge::NegY => (v(xs, y0, (zb + zt) * 0.5), V3::z()),
        Hinge::PosY => (v(xs, y1, (zb + zt) * 0.5), -V3::z()),
    };
    b.revolute(body_i, lid_i, axis, origin, rng.range(1.6, 2.5));
    // Telescoping handle on the back.
    if rng.chance(0.6) {
        let rt = rng.range(0.01, 0.02);
        let ry = w * rng.range(0.2, 0.32);
        let zr0 = zb + h * rng.range(0.1, 0.3);
        let gz = zt + rng.range(0.01, 0.04);
        let gt = rng.range(0.02, 0.035);
        let mut prims = Vec::new();
        for s in [-1.0, 1.0] {
            prims.push(bx(
                v(x1, s * ry - rt * 0.5, zr0),
                v(x1 + rt, s * ry + rt * 0.5, gz),
            ));
        }
        prims.push(bx(v(x1, -ry - rt, gz), v(x1 + rt * 1.5, ry + rt, gz + gt)));
        let name = b.next_name("handle");
        let t = b.part(name, "handle", prims);
        let travel = rng.range(0.2, 0.45).min((gz - zr0) * 0.8);
        b.prismatic(
            body_i,
            t,
            V3::z(),
            v(x1 + rt * 0.5, 0.0, gz + gt * 0.5),
            travel,
        );
    }
    // Carry handle on top of the body.
    if rng.chance(0.7) {
        let hd = Handle::Bar {
            length: rng.range(0.1, 0.18).min(w * 0.5),
            standoff: rng.range(0.02, 0.03),
            thickness: rng.range(0.012, 0.02),
            round: rng.chance(0.5),
        };
        let at = v((xs + x1) * 0.5, 0.0, zt);
        let separate = rng.chance(0.4);
        b.handle(body_i, hd.prims(&Face::top(zt), at, 1), at, separate);
    }
    b.finish()
}

pub(super) fn trash_can(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("TrashCan");
    let round = rng.chance(0.4);
    let (bx_, by_) = if round {
        let s = rng.range(0.2, 0.4);
        (s, s)
    } else {
        (rng.range(0.2, 0.4), rng.range(0.2, 0.4))
    };
    let h = bx_.max(by_) * rng.range(1.3, 2.5);
    let (x0, x1, y0, y1) = (-bx_ * 0.5, bx_ * 0.5, -by_ * 0.5, by_ * 0.5);
    let wall = rng.range(0.005, 0.015);
    let mut body = if round {
        vec![cyl(v(0.0, 0.0, h * 0.5), 2, bx_ * 0.5, h * 0.5)]
    } else {
        open_box(v(x0, y0, 0.0), v(x1, y1, h), wall, &[Side::TOP])
    };
    // Pedal at the front bottom, on a bracket.
    let pedal = rng.chance(0.45);
    let pedal_spec = if pedal {
        let l = rng.range(0.04, 0.1);
        let pw = rng.range(0.06, (bx_.min(by_) * 0.6).min(0.2));
        let pt = rng.range(0.008, 0.015);
        let upper = rng.range(0.2, 0.4);
        let zp = l * upper.sin() + rng.range(0.005, 0.03);
        let xb = x0 - 0.01;
        body.push(bx(
            v(xb, -pw * 0.5 - 0.005, zp - 0.01),
            v(
                if round { x0 + 0.02 } else { x0 },
                pw * 0.5 + 0.005,
                zp + pt + 0.01,
            ),
        ));
        Some((xb, l, pw, pt, zp, upper))
    } else {
        None
    };
    let body_i = b.part("body", "base_body", body);
    let lt = rng.range(0.01, 0.03);
    let two = !round && rng.chance(0.25);
    let mut lids = Vec::new();
    if two {
        let g = rng.range(0.002, 0.005);
        let upper = rng.range(1.4, 2.2);
        flap(
            &mut b,
            body_i,
            v(x0, y0, h),
            v(x1, -g * 0.5, h + lt),
            Side {
                axis: 1,
                sign: -1.0,
            },
            upper,
        );
        flap(
            &mut b,
            body_i,
            v(x0, g * 0.5, h),
            v(x1, y1, h + lt),
            Side { axis: 1, sign: 1.0 },
            upper,
        );
    } else if round {
        let rl = bx_ * 0.5 + rng.range(0.0, 0.008);
        let lid = b.part(
            "lid",
            "lid",
            vec![cyl(v(0.0, 0.0, h + lt * 0.5), 2, rl, lt * 0.5)],
        );
        b.revolute(body_i, lid, V3::y(), v(rl, 0.0, h), rng.range(1.4, 2.2));
        lids.push((lid, rl));
    } else {
        let lid = back_hinged_lid(
            &mut b,
            body_i,
            (x0, x1),
            (y0, y1),
            h,
            lt,
            rng.range(1.4, 2.2),
        );
        lids.push((lid, bx_ * 0.5));
    }
    if let Some((xb, l, pw, pt, zp, upper)) = pedal_spec {
        let p = b.part(
            "pedal",
            "pedal",
            vec![bx(v(xb - l, -pw * 0.5, zp), v(xb, pw * 0.5, zp + pt))],
        );
        b.revolute(body_i, p, -V3::y(), v(xb, 0.0, zp), upper);
    }
    if let Some(&(lid, reach)) = lids.first()
        && rng.chance(0.4)
    {
        let hd = random_handle(rng, (by_ * 0.5).min(0.12), 0.4);
        let at = v(-reach * 0.5, 0.0, h + lt);
        let separate = rng.chance(0.4);
        b.handle(lid, hd.prims(&Face::top(h + lt), at, 1), at, separate);
    }
    b.finish()
}

pub(super) fn door(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("Door");
    let double = rng.chance(0.2);
    let g = rng.range(0.003, 0.006);
    let leaf_w = if double {
        rng.range(0.45, 0.7)
    } else {
        rng.range(0.7, 1.0)
    };
    let ph = rng.range(1.9, 2.2);
    let pt = rng.range(0.035, 0.05);
    let jw = rng.range(0.04, 0.1);
    let fd = rng.range((pt + 0.01).max(0.08), 0.2);
    let gf = rng.range(0.005, 0.015);
    let gtop = rng.range(0.002, 0.005);
    let leaves = if double { 2 } else { 1 };
    let wo = leaf_w * leaves as f64 + g * leaves as f64;
    let ho = gf + ph + gtop;
    let (fx0, fx1) = (-fd * 0.5, fd * 0.5);
    let frame = vec![
        bx(v(fx0, -wo * 0.5 - jw, 0.0), v(fx1, -wo * 0.5, ho + jw)),
        bx(v(fx0, wo * 0.5, 0.0), v(fx1, wo * 0.5 + jw, ho + jw)),
        bx(v(fx0, -wo * 0.5, ho), v(fx1, wo * 0.5, ho + jw)),
    ];
    let frame_i = b.part("frame", "door_frame", frame);
    let inset = rng.range(0.0, fd - pt);
    let xf = fx0 + inset;
    let hs = hinges(rng, leaves);
    let rects: Vec<Rect> = if double {
        vec![
            Rect {
                y0: -wo * 0.5,
                y1: -g * 0.5,
                z0: gf,
                z1: gf + ph,
            },
            Rect {
                y0: g * 0.5,
                y1: wo * 0.5,
                z0: gf,
                z1: gf + ph,
            },
        ]
    } else if hs[0] == Hinge::NegY {
        vec![Rect {
            y0: -wo * 0.5,
            y1: wo * 0.5 - g,
            z0: gf,
            z1: gf + ph,
        }]
    } else {
        vec![Rect {
            y0: -wo * 0.5 + g,
            y1: wo * 0.5,
            z0: gf,
            z1: gf + ph,
        }]
    };
    let raised = rng.chance(0.5);
    let zl = rng.range(0.9, 1.1);
    let mut leaves_i = Vec::new();
    for (r, &hinge) in rects.iter().zip(&hs) {
        let (slab, origin, axis) = side_hinged_door(xf + pt, pt, r, hinge);
        let mut prims = vec![slab];
        if raised {
            let m = 0.13;
            for (za, zz) in [(r.z0 + m, zl - 0.1), (zl + 0.1, r.z1 - m)] {
                if zz - za > 0.1 && r.w() > 2.0 * m + 0.05 {
                    prims.push(bx(v(xf - 0.003, r.y0 + m, za), v(xf, r.y1 - m, zz)));
                }
            }
        }
        let name = b.next_name("door");
        let d = b.part(name, "rotation_door", prims);
        b.revolute(frame_i, d, axis, origin, rng.range(1.2, 1.57));
        leaves_i.push((d, *r, hinge));
    }
    for (d, r, hinge) in leaves_i {
        let inset = rng.range(0.06, 0.08);
        let (yl, toward) = match hinge {
            Hinge::NegY => (r.y1 - inset, -1.0),
            Hinge::PosY => (r.y0 + inset, 1.0),
        };
        let style = rng.uniform();
        let rose_r = rng.range(0.025, 0.035);
        let rose_t = rng.range(0.008, 0.012);
        // Rose (front), and a knob on the back merged into the leaf.
        b.extend(
            d,
            vec![cyl(v(xf - rose_t * 0.5, yl, zl), 0, rose_r, rose_t * 0.5)],
        );
        if rng.chance(0.5) {
            let kd = rng.range(0.04, 0.06);
            b.extend(
                d,
                vec![cyl(
                    v(xf + pt + kd * 0.5, yl, zl),
                    0,
                    rose_r * 0.8,
                    kd * 0.5,
                )],
            );
        }
        let xr = xf - rose_t;
        if style < 0.65 {
            // Lever: spindle + bar pointing towards the hinge; rotates about the spindle so that
            // the tip goes down.
            let sl = rng.range(0.03, 0.05);
            let lt = rng.range(0.012, 0.02).min(sl * 0.6);
            let bw = rng.range(0.015, 0.022);
            let ll = rng.range(0.1, 0.14);
            let (ya, yb) = if toward < 0.0 {
                (yl - ll, yl + bw * 0.5)
            } else {
                (yl - bw * 0.5, yl + ll)
            };
            let prims = vec![
                cyl(v(xr - sl * 0.5, yl, zl), 0, 0.008, sl * 0.5),
                bx(
                    v(xr - sl, ya, zl - bw * 0.5),
                    v(xr - sl + lt, yb, zl + bw * 0.5),
                ),
            ];
            let name = b.next_name("handle");
            let lever = b.part(name, "handle", prims);
            let axis = if toward < 0.0 { V3::x() } else { -V3::x() };
            b.revolute(d, lever, axis, v(xr, yl, zl), rng.range(0.6, 0.8));
        } else if style < 0.85 {
            // A vertical pull bar (fixed).
            let hd = Handle::Bar {
                length: rng.range(0.2, 0.5),
                standoff: rng.range(0.03, 0.05),
                thickness: rng.range(0.015, 0.025),
                round: true,
            };
            let at = v(xf, yl, zl);
            let separate = rng.chance(0.6);
            b.handle(d, hd.prims(&Face::front(xf), at, 2), at, separate);
        } else {
            let hd = Handle::Knob {
                radius: rng.range(0.022, 0.03),
                depth: rng.range(0.04, 0.06),
            };
            let at = v(xr, yl, zl);
            b.handle(d, hd.prims(&Face::front(xr), at, 2), at, false);
        }
    }
    b.finish()
}

/// The stile and rail width actually used for a sash over `r`.
fn stile_width(sw: f64, r: &Rect) -> f64 {
    sw.min(r.w() * 0.25).min(r.h() * 0.25)
}

/// A window sash over `r` between x = `xa` and `xa + t`: stiles and rails of width `sw` and a
/// glass pane in the middle.
fn sash(xa: f64, t: f64, r: &Rect, sw: f64) -> Vec<Primitive> {
    let sw = stile_width(sw, r);
    let xb = xa + t;
    let gt = (t * 0.25).clamp(0.003, 0.008);
    let xm = xa + t * 0.5;
    vec![
        bx(v(xa, r.y0, r.z0), v(xb, r.y0 + sw, r.z1)),
        bx(v(xa, r.y1 - sw, r.z0), v(xb, r.y1, r.z1)),
        bx(v(xa, r.y0 + sw, r.z0), v(xb, r.y1 - sw, r.z0 + sw)),
        bx(v(xa, r.y0 + sw, r.z1 - sw), v(xb, r.y1 - sw, r.z1)),
        bx(
            v(xm - gt * 0.5, r.y0 + sw * 0.5, r.z0 + sw * 0.5),
            v(xm + gt * 0.5, r.y1 - sw * 0.5, r.z1 - sw * 0.5),
        ),
    ]
}

pub(super) fn window(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("Window");
    let fw = rng.range(0.04, 0.08);
    let wo = rng.range(0.4, 1.9);
    let ho = rng.range(0.4, 1.4);
    let fd = rng.range(0.06, 0.15);
    let (fx0, fx1) = (-fd * 0.5, fd * 0.5);
    let (oy0, oy1) = (-wo * 0.5, wo * 0.5);
    let (oz0, oz1) = (fw, fw + ho);
    let mut frame = vec![
        bx(v(fx0, oy0 - fw, 0.0), v(fx1, oy1 + fw, oz0)),
        bx(v(fx0, oy0 - fw, oz1), v(fx1, oy1 + fw, oz1 + fw)),
        bx(v(fx0, oy0 - fw, oz0), v(fx1, oy0, oz1)),
        bx(v(fx0, oy1, oz0), v(fx1, oy1 + fw, oz1)),
    ];
    let sw = rng.range(0.025, 0.05);
    let kind = rng.uniform();
    if kind < 0.35 {
        // Horizontal sliders in two tracks.
        let st = rng.range(0.02, 0.035).min((fd - 0.01) * 0.5 - 0.004);
        let tg = rng.range(0.002, 0.008);
        let xa = fx0 + (fd - 2.0 * st - tg) * 0.5;
        let tracks = [xa, xa + st + tg];
        let n = if wo >= 1.2 && rng.chance(0.35) { 4 } else { 2 };
        let o = rng.range(0.03, 0.06);
        let pw = (wo + (n - 1) as f64 * o) / n as f64;
        let fixed_one = n == 2 && rng.chance(0.3);
        let margin = rng.range(0.005, 0.02);
        let frame_i = b.part("frame", "window_frame", Vec::new());
        for i in 0..n {
            let y = oy0 + i as f64 * (pw - o);
            let r = Rect {
                y0: y,
                y1: y + pw,
                z0: oz0,
                z1: oz1,
            };
            let prims = sash(tracks[i % 2], st, &r, sw);
            if fixed_one && i == 1 {
                frame.extend(prims);
                continue;
            }
            let (dir, travel) = match (n, i) {
                (2, 0) => (1.0, wo - pw),
                (2, _) => (-1.0, wo - pw),
                (_, 0) => (1.0, pw - 2.0 * o),
                (_, 1) => (-1.0, pw - o),
                (_, 2) => (1.0, pw - o),
                _ => (-1.0, pw - 2.0 * o),
            };
            let name = b.next_name("sash");
            let s = b.part(name, "window", prims);
            b.prismatic(
                frame_i,
                s,
                V3::y() * dir,
                v(tracks[i % 2], r.yc(), r.zc()),
                travel - margin,
            );
        }
        b.extend(frame_i, frame);
    } else if kind < 0.55 {
        // Double- or single-hung: two sashes sliding vertically in two tracks.
        let st = rng.range(0.02, 0.035).min((fd - 0.01) * 0.5 - 0.004);
        let tg = rng.range(0.002, 0.008);
        let xa = fx0 + (fd - 2.0 * st - tg) * 0.5;
        let o = rng.range(0.03, 0.06);
        let ph = (ho + o) * 0.5;
        let margin = rng.range(0.005, 0.02);
        let single_hung = rng.chance(0.4);
        let frame_i = b.part("frame", "window_frame", Vec::new());
        let lower = Rect {
            y0: oy0,
            y1: oy1,
            z0: oz0,
            z1: oz0 + ph,
        };
        let upper = Rect {
            y0: oy0,
            y1: oy1,
            z0: oz1 - ph,
            z1: oz1,
        };
        let name = b.next_name("sash");
        let s = b.part(name, "window", sash(xa, st, &lower, sw));
        b.prismatic(
            frame_i,
            s,
            V3::z(),
            v(xa, lower.yc(), lower.zc()),
            ho - ph - margin,
        );
        let up = sash(xa + st + tg, st, &upper, sw);
        if single_hung {
            frame.extend(up);
        } else {
            let name = b.next_name("sash");
            let s = b.part(name, "window", up);
            b.prismatic(
                frame_i,
                s,
                -V3::z(),
                v(xa + st + tg, upper.yc(), upper.zc()),
                ho - ph - margin,
            );
        }
        b.extend(frame_i, frame);
    } else if kind < 0.85 {
        // Casement: one or two sashes hinged on the jambs, opening outwards.
        let frame_i = b.part("frame", "window_frame", frame);
        let st = rng.range(0.03, 0.05).min(fd);
        let xf = fx0 + rng.range(0.0, fd - st);
        let g = rng.range(0.003, 0.006);
        let two = wo > 0.8 && rng.chance(0.6);
        let hs = hinges(rng, if two { 2 } else { 1 });
        let rects = if two {
            vec![
                Rect {
                    y0: oy0,
                    y1: -g * 0.5,
                    z0: oz0 + g,
                    z1: oz1 - g,
                },
                Rect {
                    y0: g * 0.5,
                    y1: oy1,
                    z0: oz0 + g,
                    z1: oz1 - g,
                },
            ]
        } else if hs[0] == Hinge::NegY {
            vec![Rect {
                y0: oy0,
                y1: oy1 - g,
                z0: oz0 + g,
                z1: oz1 - g,
            }]
        } else {
            vec![Rect {
                y0: oy0 + g,
                y1: oy1,
                z0: oz0 + g,
                z1: oz1 - g,
            }]
        };
        let mut made = Vec::new();
        for (r, &hinge) in rects.iter().zip(&hs) {
            let (_, origin, axis) = side_hinged_door(xf + st, st, r, hinge);
            let sweep = swing_clearance(st, r.w());
            let rr = match hinge {
                Hinge::NegY => Rect {
                    y1: r.y1 - sweep,
                    ..*r
                },
                Hinge::PosY => Rect {
                    y0: r.y0 + sweep,
                    ..*r
                },
            };
            let name = b.next_name("sash");
            let s = b.part(name, "window", sash(xf, st, &rr, sw));
            b.revolute(frame_i, s, axis, origin, rng.range(0.8, 1.57));
            made.push((s, rr, hinge));
        }
        for (s, r, hinge) in made {
            if rng.chance(0.7) {
                // Centred on the free stile (the glass behind it is recessed).
                let hd = random_handle(rng, 0.1, 0.4);
                let stile = stile_width(sw, &r);
                let y = match hinge {
                    Hinge::NegY => r.y1 - stile * 0.5,
                    Hinge::PosY => r.y0 + stile * 0.5,
                };
                let at = v(xf, y, r.zc());
                let separate = rng.chance(0.3);
                b.handle(s, hd.prims(&Face::front(xf), at, 2), at, separate);
            }
        }
    } else {
        // Awning: one sash hinged at the top, bottom swinging out.
        let frame_i = b.part("frame", "window_frame", frame);
        let st = rng.range(0.03, 0.05).min(fd);
        let xf = fx0 + rng.range(0.0, fd - st);
        let g = rng.range(0.003, 0.006);
        let r = Rect {
            y0: oy0 + g,
            y1: oy1 - g,
            z0: oz0 + g + swing_clearance(st, ho),
            z1: oz1,
        };
        let s = b.part("sash_0", "window", sash(xf, st, &r, sw));
        b.revolute(frame_i, s, V3::y(), v(xf, 0.0, oz1), rng.range(0.4, 1.0));
        if rng.chance(0.6) {
            let hd = random_handle(rng, 0.12, 0.3);
            let at = v(xf, r.yc(), r.z0 + stile_width(sw, &r) * 0.5);
            b.handle(s, hd.prims(&Face::front(xf), at, 1), at, rng.chance(0.3));
        }
    }
    b.finish()
}
