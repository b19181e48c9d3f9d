//! Appliances: Refrigerator, Microwave, Oven, Dishwasher, WashingMachine.
//!
//! Bottom-hinged doors (oven, dishwasher) hinge about a horizontal line along Y through the
//! door's front-bottom edge, axis −Y, so the top of the door swings down and out (towards −X).
//! Knobs are revolute parts about the front normal with a continuous-like range.

use std::f64::consts::{PI, TAU};

use super::parts::{
    Builder, Cell, Face, Front, FrontStyle, Handle, Hinge, Rect, Side, V3, build_fronts, bx,
    control_knob, cyl, hinges, open_box, split, swing_clearance, v,
};
use crate::data::rng::Rng;
use crate::data::{DataError, LabelledObject};

/// Add a knob part on `face` at `at` (child of `parent`), rotating about the face normal.
fn add_knob(
    b: &mut Builder,
    rng: &mut Rng,
    parent: usize,
    face: &Face,
    at: V3,
    radius: f64,
    depth: f64,
) {
    let prims = control_knob(face, at, radius, depth, rng.chance(0.6));
    let name = b.next_name("knob");
    let k = b.part(name, "knob", prims);
    let mut axis = V3::zeros();
    axis[face.axis] = if rng.chance(0.5) { 1.0 } else { -1.0 };
    let upper = if rng.chance(0.6) { TAU } else { PI };
    b.revolute(parent, k, axis, face.point(at), upper);
}

/// Small feet under a body: four cylinders of height `h` (their tops at z = h).
fn feet(out: &mut Vec<crate::shape::Primitive>, x: (f64, f64), y: (f64, f64), h: f64, r: f64) {
    for xi in [x.0 + r * 2.0, x.1 - r * 2.0] {
        for yi in [y.0 + r * 2.0, y.1 - r * 2.0] {
            out.push(cyl(v(xi, yi, h * 0.5), 2, r, h * 0.5));
        }
    }
}

/// Bottom-hinged door over `r` on the front plane `x0` (thickness `t`): slab, hinge origin.
/// The top edge is pulled in by the swing clearance (see `parts::side_hinged_door`).
fn bottom_hinged(x0: f64, t: f64, r: &Rect) -> (crate::shape::Primitive, V3) {
    let sweep = swing_clearance(t, r.h());
    (
        bx(v(x0 - t, r.y0, r.z0), v(x0, r.y1, r.z1 - sweep)),
        v(x0 - t, r.yc(), r.z0),
    )
}

/// A window pane decoration on a door front: a thin plate 2 mm proud of the front face `xf`
/// over `r`, cut back so that it keeps 5 mm clear of the handle primitives `avoid` (which sit
/// on the front face).
fn window(
    xf: f64,
    r: &Rect,
    avoid: Option<&[crate::shape::Primitive]>,
) -> Option<crate::shape::Primitive> {
    let mut r = *r;
    if let Some(prims) = avoid {
        let (mut lo, mut hi) = (V3::repeat(f64::INFINITY), V3::repeat(f64::NEG_INFINITY));
        for p in prims {
            let (a, b) = p.bounds();
            lo = lo.inf(&a);
            hi = hi.sup(&b);
        }
        let m = 0.005;
        let overlaps = lo.y - m < r.y1 && hi.y + m > r.y0 && lo.z - m < r.z1 && hi.z + m > r.z0;
        if overlaps {
            // Keep the largest of the four pieces beside, above or below the handle.
            let pieces = [
                Rect { y1: lo.y - m, ..r },
                Rect { y0: hi.y + m, ..r },
                Rect { z1: lo.z - m, ..r },
                Rect { z0: hi.z + m, ..r },
            ];
            r = pieces
                .into_iter()
                .max_by(|a, b| {
                    (a.w().max(0.0) * a.h().max(0.0)).total_cmp(&(b.w().max(0.0) * b.h().max(0.0)))
                })
                .expect("four pieces");
        }
    }
    (r.w() > 0.05 && r.h() > 0.05).then(|| bx(v(xf - 0.002, r.y0, r.z0), v(xf, r.y1, r.z1)))
}

pub(super) fn refrigerator(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("Refrigerator");
    let width = rng.range(0.5, 1.1);
    let depth = rng.range(0.5, 0.8);
    let height = rng.range(0.8, 2.0);
    let wall = rng.range(0.03, 0.05);
    let t = rng.range(0.04, 0.08);
    let g = rng.range(0.003, 0.008);
    let zb = if rng.chance(0.6) {
        rng.range(0.03, 0.08)
    } else {
        0.0
    };
    let (x0, x1) = (-depth * 0.5, depth * 0.5);
    let (y0, y1) = (-width * 0.5, width * 0.5);
    let mut body = open_box(v(x0, y0, zb), v(x1, y1, height), wall, &[Side::FRONT]);
    if zb > 0.0 {
        body.push(bx(
            v(x0 + rng.range(0.02, 0.06), y0 + 0.02, 0.0),
            v(x1 - 0.02, y1 - 0.02, zb),
        ));
    }
    let (iy0, iy1) = (y0 + wall, y1 - wall);
    let (iz0, iz1) = (zb + wall, height - wall);
    let back = x1 - wall;

    // Layouts: 0 single, 1 top freezer, 2 bottom freezer drawers, 3 side by side, 4 french.
    let mut options = vec![(0, if height < 1.1 { 6.0 } else { 1.5 })];
    if height >= 1.2 {
        options.push((1, 3.0));
    }
    if height >= 1.3 {
        options.push((2, 2.0));
    }
    if width >= 0.8 && height >= 1.3 {
        options.push((3, 2.0));
    }
    if width >= 0.7 && height >= 1.5 {
        options.push((4, 2.0));
    }
    let total: f64 = options.iter().map(|o| o.1).sum();
    let mut u = rng.uniform() * total;
    let mut layout = 0;
    for (l, w) in &options {
        if u < *w {
            layout = *l;
            break;
        }
        u -= w;
    }
    let hinge = hinges(rng, 1)[0];
    // Rows bottom to top: (cells, kind) with kind 0 = door row, 1 = drawer row.
    let (row_kinds, row_weights): (Vec<usize>, Vec<f64>) = match layout {
        0 => (vec![0], vec![1.0]),
        1 => (
            vec![0, 0],
            vec![rng.range(0.62, 0.75), 1.0 - rng.range(0.62, 0.75)],
        ),
        2 | 4 => {
            let nd = if height > 1.6 && rng.chance(0.4) {
                2
            } else {
                1
            };
            let mut k = vec![1; nd];
            k.push(0);
            let dh = rng.range(0.25, 0.35) / nd as f64;
            let mut w = vec![dh; nd];
            w.push(1.0 - dh * nd as f64);
            (k, w)
        }
        _ => (vec![0], vec![1.0]),
    };
    let rows = row_kinds.len();
    let (row_cells, row_bounds) = split(iz0, iz1, rows, wall, (zb, height), &row_weights);
    for &(_, z) in &row_cells[..rows - 1] {
        body.push(bx(v(x0, iy0, z), v(back, iy1, z + wall)));
    }
    let mut fronts = Vec::new();
    for r in 0..rows {
        let (za, zz) = row_cells[r];
        let doors_here = match layout {
            3 | 4 if row_kinds[r] == 0 => 2,
            _ => 1,
        };
        let divider = layout == 3;
        let col_w = if layout == 3 {
            let f = rng.range(0.4, 0.5);
            if rng.chance(0.5) {
                vec![f, 1.0 - f]
            } else {
                vec![1.0 - f, f]
            }
        } else {
            vec![1.0; doors_here]
        };
        let (col_cells, col_bounds) = split(
            iy0,
            iy1,
            doors_here,
            if divider { wall } else { 0.0 },
            (y0, y1),
            &col_w,
        );
        if divider {
            let y = col_cells[0].1;
            body.push(bx(v(x0, y, za), v(back, y + wall, zz)));
        }
        let hs = if doors_here == 2 {
            vec![Hinge::NegY, Hinge::PosY]
        } else {
            vec![hinge]
        };
        // Shelves inside door compartments (set back from the door).
        if row_kinds[r] == 0 && zz - za > 0.4 {
            let n = ((zz - za) / 0.35).floor().clamp(1.0, 4.0) as usize;
            for s in 1..=n {
                let z = za + (zz - za) * s as f64 / (n + 1) as f64;
                body.push(bx(v(x0 + 0.03, iy0, z - 0.004), v(back, iy1, z + 0.004)));
            }
        }
        for k in 0..doors_here {
            fronts.push(Front {
                rect: Rect {
                    y0: col_bounds[k] + g * 0.5,
                    y1: col_bounds[k + 1] - g * 0.5,
                    z0: row_bounds[r] + g * 0.5,
                    z1: row_bounds[r + 1] - g * 0.5,
                },
                inner: Rect {
                    y0: col_cells[k].0,
                    y1: col_cells[k].1,
                    z0: za,
                    z1: zz,
                },
                cell: if row_kinds[r] == 0 {
                    Cell::Door(hs[k])
                } else {
                    Cell::Drawer
                },
                z_pref: if r + 1 == rows && rows > 1 {
                    0.1
                } else {
                    rng.range(0.6, 0.9)
                },
            });
        }
    }
    let body_i = b.part("body", "base_body", body);
    let style = FrontStyle {
        x0,
        t,
        depth: back - x0,
        door_label: "door",
        drawer_label: "drawer",
        separate_p: 0.3,
        bare_p: 0.1,
        door_range: (1.6, 2.3),
        door_knob_p: 0.0,
    };
    build_fronts(&mut b, rng, body_i, &fronts, &style);
    b.finish()
}

pub(super) fn microwave(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("Microwave");
    let depth = rng.range(0.25, 0.45);
    let width = rng.range(0.3, 0.6);
    let height = rng.range(0.2, 0.35);
    let wall = rng.range(0.008, 0.02);
    let t = rng.range(0.02, 0.05);
    let g = rng.range(0.002, 0.005);
    let pw = rng.range(0.07, 0.12);
    let (x0, x1) = (-depth * 0.5, depth * 0.5);
    let (y0, y1) = (-width * 0.5, width * 0.5);
    let mut body = Vec::new();
    let zb = if rng.chance(0.5) {
        let h = rng.range(0.005, 0.015);
        feet(&mut body, (x0, x1), (y0, y1), h, rng.range(0.006, 0.012));
        h
    } else {
        0.0
    };
    let zt = zb + height;
    body.extend(open_box(v(x0, y0, zb), v(x1, y1, zt), wall, &[Side::FRONT]));
    // Control panel on the viewer's right (−Y) mostly; the door hinges on the other side.
    let panel_neg = rng.chance(0.75);
    let (py0, py1, hinge) = if panel_neg {
        (y0, y0 + pw, Hinge::PosY)
    } else {
        (y1 - pw, y1, Hinge::NegY)
    };
    // Divider between cavity and panel, and the panel block filling the panel cell.
    let (dy0, dy1) = if panel_neg {
        (py1 - wall, py1)
    } else {
        (py0, py0 + wall)
    };
    body.push(bx(v(x0, dy0, zb + wall), v(x1 - wall, dy1, zt - wall)));
    let (cy0, cy1) = if panel_neg {
        (py0 + wall, dy0)
    } else {
        (dy1, py1 - wall)
    };
    body.push(bx(v(x0, cy0, zb + wall), v(x1 - wall, cy1, zt - wall)));
    let door_rect = if panel_neg {
        Rect {
            y0: (dy0 + dy1) * 0.5 + g * 0.5,
            y1: y1 - g * 0.5,
            z0: zb + g * 0.5,
            z1: zt - g * 0.5,
        }
    } else {
        Rect {
            y0: y0 + g * 0.5,
            y1: (dy0 + dy1) * 0.5 - g * 0.5,
            z0: zb + g * 0.5,
            z1: zt - g * 0.5,
        }
    };
    // Knobs stacked in the panel; a display above them when there is room.
    let face = Face::front(x0);
    let pyc = (cy0 + cy1) * 0.5;
    let pwid = cy1 - cy0;
    let n_knobs = rng.int(0, 3);
    let radius = rng.range(0.012, 0.022).min(pwid * 0.5 - 0.008).max(0.006);
    let kd = rng.range(0.012, 0.025);
    let panel_h = zt - zb - 2.0 * wall;
    let fit = ((panel_h - 0.02) / (2.0 * radius + 0.015)).floor().max(0.0) as usize;
    let n_knobs = n_knobs.min(fit);
    let display = n_knobs < 2 && rng.chance(0.7);
    let top = if display {
        let dz = panel_h * 0.2;
        body.push(bx(
            v(x0 - 0.002, pyc - pwid * 0.35, zt - wall - 0.01 - dz),
            v(x0, pyc + pwid * 0.35, zt - wall - 0.01),
        ));
        zt - wall - 0.02 - dz
    } else {
        zt - wall
    };
    let body_i = b.part("body", "base_body", body);
    let door_upper = rng.range(1.6, 2.1);
    let (slab, origin, axis) = super::parts::side_hinged_door(x0, t, &door_rect, hinge);
    let xf = x0 - t;
    let handle = rng.chance(0.6).then(|| {
        if rng.chance(0.7) {
            super::parts::door_handle_prims(rng, xf, &door_rect, hinge, 0.5, 0.0)
        } else {
            let h = Handle::Bar {
                length: door_rect.w() * rng.range(0.3, 0.6),
                standoff: rng.range(0.015, 0.025),
                thickness: rng.range(0.008, 0.015),
                round: rng.chance(0.5),
            };
            let at = v(xf, door_rect.yc(), door_rect.z1 - 0.03);
            (h.prims(&Face::front(xf), at, 1), at)
        }
    });
    let mut door_prims = vec![slab];
    let pane = Rect {
        y0: door_rect.y0 + door_rect.w() * 0.12,
        y1: door_rect.y1 - door_rect.w() * 0.12,
        z0: door_rect.z0 + 0.03,
        z1: door_rect.z1 - 0.03,
    };
    door_prims.extend(window(xf, &pane, handle.as_ref().map(|h| &h.0[..])));
    let door = b.part("door", "door", door_prims);
    b.revolute(body_i, door, axis, origin, door_upper);
    let span = top - (zb + wall);
    for k in 0..n_knobs {
        let z = top - span * (k as f64 + 0.5) / n_knobs as f64;
        add_knob(&mut b, rng, body_i, &face, v(x0, pyc, z), radius, kd);
    }
    if let Some((prims, at)) = handle {
        let separate = rng.chance(0.3);
        b.handle(door, prims, at, separate);
    }
    b.finish()
}

pub(super) fn oven(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("Oven");
    let depth = rng.range(0.4, 0.8);
    let width = rng.range(0.5, 0.9);
    let height = rng.range(0.5, 0.9);
    let wall = rng.range(0.015, 0.03);
    let t = rng.range(0.03, 0.06);
    let g = rng.range(0.002, 0.006);
    let cp = rng.range(0.07, 0.14);
    let (x0, x1) = (-depth * 0.5, depth * 0.5);
    let (y0, y1) = (-width * 0.5, width * 0.5);
    let zb = if rng.chance(0.5) {
        rng.range(0.02, 0.08)
    } else {
        0.0
    };
    let zt = height;
    let mut body = open_box(v(x0, y0, zb), v(x1, y1, zt), wall, &[Side::FRONT]);
    if zb > 0.0 {
        body.push(bx(
            v(x0 + rng.range(0.01, 0.05), y0 + 0.01, 0.0),
            v(x1 - 0.01, y1 - 0.01, zb),
        ));
    }
    let (iy0, iy1) = (y0 + wall, y1 - wall);
    let back = x1 - wall;
    // Control block across the top of the front.
    let zc0 = zt - cp;
    body.push(bx(v(x0, iy0, zc0), v(back, iy1, zt - wall)));
    let drawer = rng.chance(0.35) && height > 0.6;
    let (rows, weights) = if drawer {
        let dh = rng.range(0.1, 0.16);
        (2, vec![dh, zc0 - zb - dh])
    } else {
        (1, vec![1.0])
    };
    let (cells, bounds) = split(zb + wall, zc0, rows, wall, (zb, zc0), &weights);
    for &(_, z) in &cells[..rows - 1] {
        body.push(bx(v(x0, iy0, z), v(back, iy1, z + wall)));
    }
    let door_rect = Rect {
        y0: y0 + g * 0.5,
        y1: y1 - g * 0.5,
        z0: bounds[rows - 1] + g * 0.5,
        z1: bounds[rows] - g * 0.5,
    };
    let face = Face::front(x0);
    let n_knobs = rng.int(0, 4);
    let radius = rng.range(0.015, 0.025).min((cp - wall) * 0.5 - 0.01);
    let kd = rng.range(0.015, 0.03);
    let zk = (zc0 + zt - wall) * 0.5;
    let body_i = b.part("body", "base_body", body);
    let (slab, origin) = bottom_hinged(x0, t, &door_rect);
    let xf = x0 - t;
    // Door handle: a horizontal bar near the top.
    let handle = rng.chance(0.9).then(|| {
        let h = Handle::Bar {
            length: rng.range(0.2, 0.9 * door_rect.w()),
            standoff: rng.range(0.02, 0.04),
            thickness: rng.range(0.01, 0.02),
            round: rng.chance(0.6),
        };
        let at = v(xf, door_rect.yc(), door_rect.z1 - rng.range(0.035, 0.06));
        (h.prims(&Face::front(xf), at, 1), at)
    });
    let mut prims = vec![slab];
    let pane = Rect {
        y0: door_rect.y0 + door_rect.w() * 0.15,
        y1: door_rect.y1 - door_rect.w() * 0.15,
        z0: door_rect.z0 + door_rect.h() * 0.25,
        z1: door_rect.z1 - door_rect.h() * 0.2,
    };
    prims.extend(window(xf, &pane, handle.as_ref().map(|h| &h.0[..])));
    let door = b.part("door", "door", prims);
    b.revolute(body_i, door, -V3::y(), origin, rng.range(1.4, 1.6));
    // Knobs in a row (spread over the width, or grouped on one side).
    let spread = rng.chance(0.6);
    let span = if spread {
        (iy0 + 0.06, iy1 - 0.06)
    } else if rng.chance(0.5) {
        (iy0 + 0.04, iy0 + 0.04 + (iy1 - iy0) * 0.4)
    } else {
        (iy1 - 0.04 - (iy1 - iy0) * 0.4, iy1 - 0.04)
    };
    let fit = ((span.1 - span.0) / (2.0 * radius + 0.02)).floor() as usize;
    let n_knobs = n_knobs.min(fit);
    for k in 0..n_knobs {
        let y = span.0 + (span.1 - span.0) * (k as f64 + 0.5) / n_knobs as f64;
        add_knob(&mut b, rng, body_i, &face, v(x0, y, zk), radius, kd);
    }
    let drawer_i = if drawer {
        let inner = Rect {
            y0: iy0 + rng.range(0.003, 0.01),
            y1: iy1 - rng.range(0.003, 0.01),
            z0: cells[0].0 + 0.003,
            z1: cells[0].1 - rng.range(0.01, 0.02),
        };
        let front = Rect {
            y0: y0 + g * 0.5,
            y1: y1 - g * 0.5,
            z0: bounds[0] + g * 0.5,
            z1: bounds[1] - g * 0.5,
        };
        let dd = rng.range(0.6, 0.95) * (back - x0 - 0.005);
        let dr = super::parts::add_drawer(
            &mut b,
            body_i,
            "drawer",
            x0,
            t.min(0.03),
            &front,
            &inner,
            dd,
            0.008,
            dd * rng.range(0.5, 0.85),
        );
        Some((dr, front))
    } else {
        None
    };
    if let Some((prims, at)) = handle {
        let separate = rng.chance(0.3);
        b.handle(door, prims, at, separate);
    }
    if let Some((dr, front)) = drawer_i {
        let xf = x0 - t.min(0.03);
        let (prims, at) = super::parts::drawer_handle_prims(rng, xf, &front);
        b.handle(dr, prims, at, false);
    }
    b.finish()
}

pub(super) fn dishwasher(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("Dishwasher");
    let s = rng.range(0.85, 1.15);
    let width = 0.6 * s * rng.range(0.95, 1.05);
    let depth = 0.6 * s * rng.range(0.95, 1.05);
    let height = 0.85 * s * rng.range(0.95, 1.05);
    let wall = rng.range(0.015, 0.03);
    let t = rng.range(0.03, 0.06);
    let g = rng.range(0.002, 0.006);
    let (x0, x1) = (-depth * 0.5, depth * 0.5);
    let (y0, y1) = (-width * 0.5, width * 0.5);
    let zb = rng.range(0.06, 0.12);
    let mut body = open_box(v(x0, y0, zb), v(x1, y1, height), wall, &[Side::FRONT]);
    body.push(bx(
        v(x0 + rng.range(0.03, 0.06), y0 + 0.01, 0.0),
        v(x1 - 0.01, y1 - 0.01, zb),
    ));
    // Rails for the racks inside the tub (part of the body; the racks themselves would collide
    // with the closed door when pulled, so they are not parts).
    for z in [zb + (height - zb) * 0.3, zb + (height - zb) * 0.65] {
        for (a, c) in [(y0 + wall, y0 + wall + 0.01), (y1 - wall - 0.01, y1 - wall)] {
            body.push(bx(v(x0 + 0.03, a, z), v(x1 - wall, c, z + 0.01)));
        }
    }
    let body_i = b.part("body", "base_body", body);
    let door_rect = Rect {
        y0: y0 + g * 0.5,
        y1: y1 - g * 0.5,
        z0: zb + g * 0.5,
        z1: height - g * 0.5,
    };
    let (slab, origin) = bottom_hinged(x0, t, &door_rect);
    let door = b.part("door", "door", vec![slab]);
    b.revolute(body_i, door, -V3::y(), origin, rng.range(1.4, 1.6));
    let xf = x0 - t;
    let face = Face::front(xf);
    // Controls along the top of the door: knobs as parts, plus a merged display strip.
    let n_knobs = rng.int(0, 3);
    let radius = rng.range(0.012, 0.02);
    let zk = door_rect.z1 - 0.02 - radius;
    let kd = rng.range(0.012, 0.022);
    let on_left = rng.chance(0.5);
    for k in 0..n_knobs {
        let off = 0.05 + k as f64 * (2.0 * radius + 0.03);
        let y = if on_left {
            door_rect.y1 - off - radius
        } else {
            door_rect.y0 + off + radius
        };
        add_knob(&mut b, rng, door, &face, v(xf, y, zk), radius, kd);
    }
    if rng.chance(0.5) {
        let (ya, yc) = if on_left {
            (
                door_rect.y0 + 0.05,
                door_rect.y0 + 0.05 + door_rect.w() * 0.3,
            )
        } else {
            (
                door_rect.y1 - 0.05 - door_rect.w() * 0.3,
                door_rect.y1 - 0.05,
            )
        };
        b.extend(
            door,
            vec![bx(v(xf - 0.002, ya, zk - 0.012), v(xf, yc, zk + 0.012))],
        );
    }
    // Handle: a bar or a pull below the controls.
    if rng.chance(0.85) {
        let h = if rng.chance(0.7) {
            Handle::Bar {
                length: rng.range(0.2, 0.8 * door_rect.w()),
                standoff: rng.range(0.02, 0.035),
                thickness: rng.range(0.01, 0.018),
                round: rng.chance(0.5),
            }
        } else {
            Handle::Pull {
                length: rng.range(0.15, 0.5 * door_rect.w()),
                depth: rng.range(0.015, 0.03),
                height: rng.range(0.012, 0.02),
            }
        };
        let zh = zk - radius - 0.02 - h.width() * 0.5 - rng.range(0.0, 0.04);
        let at = v(xf, door_rect.yc(), zh);
        let separate = rng.chance(0.35);
        b.handle(door, h.prims(&face, at, 1), at, separate);
    }
    b.finish()
}

pub(super) fn washing_machine(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("WashingMachine");
    let s = rng.range(0.85, 1.15);
    let width = 0.6 * s * rng.range(0.95, 1.05);
    let depth = 0.6 * s * rng.range(0.95, 1.05);
    let height = 0.85 * s * rng.range(0.95, 1.05);
    let (x0, x1) = (-depth * 0.5, depth * 0.5);
    let (y0, y1) = (-width * 0.5, width * 0.5);
    let mut body = Vec::new();
    let zb = if rng.chance(0.6) {
        let h = rng.range(0.01, 0.03);
        feet(&mut body, (x0, x1), (y0, y1), h, rng.range(0.012, 0.02));
        h
    } else {
        0.0
    };
    let zt = height;
    if rng.chance(0.7) {
        // Front loader: porthole door below a control strip.
        let cs = rng.range(0.08, 0.14);
        let zs = zt - cs;
        body.push(bx(v(x0, y0, zb), v(x1, y1, zs)));
        let drawer = rng.chance(0.6);
        let face = Face::front(x0);
        let mut knob_span = (y0 + 0.04, y1 - 0.04);
        let mut drawer_spec = None;
        if drawer {
            let dw = rng.range(0.15, 0.25);
            let left = rng.chance(0.5);
            let (dy0, dy1) = if left {
                (y1 - 0.02 - dw, y1 - 0.02)
            } else {
                (y0 + 0.02, y0 + 0.02 + dw)
            };
            let ctop = rng.range(0.01, 0.02);
            let dd = rng.range(0.25, 0.4).min(depth - 0.1);
            // The strip around the drawer cavity.
            body.push(bx(v(x0, y0, zs), v(x1, dy0, zt)));
            body.push(bx(v(x0, dy1, zs), v(x1, y1, zt)));
            body.push(bx(v(x0, dy0, zt - ctop), v(x1, dy1, zt)));
            body.push(bx(v(x0 + dd + 0.01, dy0, zs), v(x1, dy1, zt - ctop)));
            knob_span = if left {
                (y0 + 0.04, dy0 - 0.03)
            } else {
                (dy1 + 0.03, y1 - 0.04)
            };
            let m = rng.range(0.005, 0.012).min(ctop * 0.8);
            let front = Rect {
                y0: dy0 - m,
                y1: dy1 + m,
                z0: zs - m,
                z1: zt - ctop + m,
            };
            let c = 0.004;
            let inner = Rect {
                y0: dy0 + c,
                y1: dy1 - c,
                z0: zs + 0.002,
                z1: zt - ctop - c,
            };
            drawer_spec = Some((front, inner, dd));
        } else {
            body.push(bx(v(x0, y0, zs), v(x1, y1, zt)));
        }
        let body_i = b.part("body", "base_body", body);
        // Door.
        let r = rng
            .range(0.16, 0.24)
            .min((zs - zb) * 0.5 - 0.05)
            .min(width * 0.5 - 0.04);
        let t = rng.range(0.04, 0.09);
        let zc = zb + (zs - zb) * rng.range(0.45, 0.55);
        let zc = zc.min(zs - r - 0.03).max(zb + r + 0.03);
        let yc = rng
            .range(-0.03, 0.03)
            .clamp(y0 + r + 0.02 - 0.0, y1 - r - 0.02);
        let hinge = hinges(rng, 1)[0];
        let mut prims = vec![cyl(v(x0 - t * 0.5, yc, zc), 0, r, t * 0.5)];
        if rng.chance(0.5) {
            // A glass bulge in front.
            let rg = r * rng.range(0.6, 0.8);
            let dg = rng.range(0.01, 0.03);
            prims.push(cyl(v(x0 - t - dg * 0.5, yc, zc), 0, rg, dg * 0.5));
        }
        if rng.chance(0.7) {
            // A grip on the free side of the ring.
            let s = if hinge == Hinge::NegY { 1.0 } else { -1.0 };
            let yg = yc + s * (r * 0.85);
            prims.push(bx(
                v(x0 - t - 0.02, yg - 0.015, zc - 0.05),
                v(x0 - t, yg + 0.015, zc + 0.05),
            ));
        }
        let door = b.part("door", "door", prims);
        let (origin, axis) = match hinge {
            Hinge::NegY => (v(x0 - t, yc - r, zc), V3::z()),
            Hinge::PosY => (v(x0 - t, yc + r, zc), -V3::z()),
        };
        b.revolute(body_i, door, axis, origin, rng.range(1.6, 2.0));
        if let Some((front, inner, dd)) = drawer_spec {
            super::parts::add_drawer(
                &mut b,
                body_i,
                "drawer",
                x0,
                rng.range(0.01, 0.02),
                &front,
                &inner,
                dd,
                0.005,
                dd * rng.range(0.5, 0.85),
            );
        }
        let n_knobs = rng.int(0, 2);
        let radius = rng.range(0.02, 0.035).min(cs * 0.5 - 0.012);
        let fit = ((knob_span.1 - knob_span.0) / (2.0 * radius + 0.04))
            .floor()
            .max(0.0) as usize;
        for k in 0..n_knobs.min(fit) {
            let y = knob_span.0
                + (knob_span.1 - knob_span.0) * (k as f64 + 0.5) / n_knobs.min(fit) as f64;
            let kd = rng.range(0.015, 0.03);
            add_knob(
                &mut b,
                rng,
                body_i,
                &face,
                v(x0, y, zt - cs * 0.5),
                radius,
                kd,
            );
        }
    } else {
        // Top loader: lid on the top, console at the back.
        let cd = rng.range(0.08, 0.15);
        let ch = rng.range(0.08, 0.15);
        body.push(bx(v(x0, y0, zb), v(x1, y1, zt)));
        body.push(bx(v(x1 - cd, y0, zt), v(x1, y1, zt + ch)));
        let body_i = b.part("body", "base_body", body);
        let lt = rng.range(0.015, 0.03);
        let kd = rng.range(0.015, 0.03);
        let gap = kd + lt + rng.range(0.01, 0.03);
        let m = rng.range(0.02, 0.05);
        let xl1 = x1 - cd - gap;
        let lid_prims = vec![bx(v(x0 + m, y0 + m, zt), v(xl1, y1 - m, zt + lt))];
        let lid = b.part("lid", "lid", lid_prims);
        b.revolute(
            body_i,
            lid,
            V3::y(),
            v(xl1, 0.0, zt + lt),
            rng.range(1.2, 1.5),
        );
        if rng.chance(0.6) {
            b.extend(
                lid,
                vec![bx(
                    v(x0 + m - 0.015, -0.06, zt + lt * 0.2),
                    v(x0 + m, 0.06, zt + lt),
                )],
            );
        }
        let n_knobs = rng.int(0, 2);
        let radius = rng.range(0.02, 0.035).min(ch * 0.5 - 0.01);
        let face = Face::front(x1 - cd);
        for k in 0..n_knobs {
            let y = if n_knobs == 1 {
                rng.range(-0.1, 0.1) * width
            } else {
                (k as f64 - 0.5) * width * 0.5
            };
            add_knob(
                &mut b,
                rng,
                body_i,
                &face,
                v(x1 - cd, y, zt + ch * 0.5),
                radius,
                kd,
            );
        }
    }
    b.finish()
}
