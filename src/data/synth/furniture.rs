//! Furniture: StorageFurniture (a body with a grid of drawers, doors and open cells) and Table
//! (top, legs, and drawers in an apron or in side pedestals).

use super::parts::{
    Builder, Cell, Front, FrontStyle, Hinge, Rect, Side, build_fronts, bx, cyl, hinges, open_box,
    split, v,
};
use crate::data::rng::Rng;
use crate::data::{DataError, LabelledObject};

#[derive(Debug, Clone, Copy, PartialEq)]
enum RowKind {
    Doors,
    Drawers,
    Open,
}

pub(super) fn storage_furniture(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("StorageFurniture");
    let width = rng.range(0.3, 1.5);
    let depth = rng.range(0.3, 0.7);
    let height = rng.range(0.4, 1.9);
    let wall = rng.range(0.015, if width > 0.8 { 0.045 } else { 0.03 });
    let g = rng.range(0.002, 0.006);
    let t = rng.range(0.015, 0.03);

    // Base: none, plinth or legs.
    let base = rng.pick(&[0, 0, 1, 1, 2]).to_owned();
    let base_h = match base {
        1 => rng.range(0.04, 0.1),
        2 => rng.range(0.06, 0.15),
        _ => 0.0,
    }
    .min(height - 0.35)
    .max(0.0);
    let top_t = if rng.chance(0.25) {
        rng.range(0.02, 0.04)
    } else {
        0.0
    };
    let (x0, x1) = (-depth * 0.5, depth * 0.5);
    let (y0, y1) = (-width * 0.5, width * 0.5);
    let (zb, zt) = (base_h, height - top_t);

    let mut body = open_box(v(x0, y0, zb), v(x1, y1, zt), wall, &[Side::FRONT]);
    match base {
        1 => {
            let setback = rng.range(0.0, 0.05);
            let side = rng.range(0.0, 0.03).min(width * 0.1);
            body.push(bx(
                v(x0 + setback, y0 + side, 0.0),
                v(x1 - side, y1 - side, zb),
            ));
        }
        2 => {
            let r = rng.range(0.015, 0.03);
            let inset = r + rng.range(0.0, 0.04);
            let round = rng.chance(0.5);
            for (sx, sy) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                let cx = sx * (depth * 0.5 - inset);
                let cy = sy * (width * 0.5 - inset);
                if round {
                    body.push(cyl(v(cx, cy, zb * 0.5), 2, r, zb * 0.5));
                } else {
                    body.push(bx(v(cx - r, cy - r, 0.0), v(cx + r, cy + r, zb)));
                }
            }
        }
        _ => {}
    }
    if top_t > 0.0 {
        let o = rng.range(0.0, 0.03);
        let os = rng.range(0.0, 0.03);
        body.push(bx(
            v(x0 - t - o, y0 - os, zt),
            v(x1 + rng.range(0.0, 0.02), y1 + os, height),
        ));
    }

    // Grid of rows (bottom to top), each with its own columns.
    let (iy0, iy1) = (y0 + wall, y1 - wall);
    let (iz0, iz1) = (zb + wall, zt - wall);
    let inner_h = iz1 - iz0;
    let rmax = ((inner_h / 0.14).floor() as usize).clamp(1, 4);
    let weights = [4.0, 3.0, 2.0, 1.5];
    let total: f64 = weights[..rmax].iter().sum();
    let mut u = rng.uniform() * total;
    let mut rows = 1;
    for (i, w) in weights[..rmax].iter().enumerate() {
        if u < *w {
            rows = i + 1;
            break;
        }
        u -= w;
    }
    let row_w: Vec<f64> = (0..rows).map(|_| rng.range(0.6, 1.4)).collect();
    let (row_cells, row_bounds) = split(iz0, iz1, rows, wall, (zb, zt), &row_w);
    let cmax = (((iy1 - iy0) / 0.22).floor() as usize).clamp(1, 3);

    // Doors at most 0.65 m wide and at most 1.6 times as wide as tall: the fewest columns a
    // door row of height `h` needs, if it can have doors at all.
    let door_cmin = |h: f64| -> Option<usize> {
        if h < 0.15 {
            return None;
        }
        let c = ((iy1 - iy0) / 0.65f64.min(1.6 * h)).ceil().max(1.0) as usize;
        (c <= cmax).then_some(c)
    };
    let mut kinds = Vec::with_capacity(rows);
    let mut cols = Vec::with_capacity(rows);
    for &(a, bz) in &row_cells {
        let h = bz - a;
        let mut opts = Vec::new();
        if (0.06..=0.45).contains(&h) {
            opts.push((RowKind::Drawers, 0.45));
        }
        if door_cmin(h).is_some() {
            opts.push((RowKind::Doors, 0.45));
        }
        opts.push((RowKind::Open, 0.1));
        let total: f64 = opts.iter().map(|o| o.1).sum();
        let mut u = rng.uniform() * total;
        let mut kind = RowKind::Open;
        for (k, p) in opts {
            if u < p {
                kind = k;
                break;
            }
            u -= p;
        }
        kinds.push(kind);
        let c = match kind {
            RowKind::Doors => {
                let lo = door_cmin(h).unwrap_or(1);
                if cmax == 3 && rng.chance(0.2) {
                    3
                } else {
                    rng.int(lo, cmax.min(2).max(lo))
                }
            }
            _ => rng.int(1, cmax),
        };
        cols.push(c);
    }
    let row_h = |i: usize| row_cells[i].1 - row_cells[i].0;
    // Budget: 1 to 7 movable fronts.
    let count = |kinds: &[RowKind], cols: &[usize]| -> usize {
        kinds
            .iter()
            .zip(cols)
            .filter(|(k, _)| **k != RowKind::Open)
            .map(|(_, c)| *c)
            .sum()
    };
    while count(&kinds, &cols) > 7 {
        let with_fronts: Vec<usize> = (0..rows).filter(|&i| kinds[i] != RowKind::Open).collect();
        let i = *rng.pick(&with_fronts);
        let min_c = match kinds[i] {
            RowKind::Doors => door_cmin(row_h(i)).unwrap_or(1),
            _ => 1,
        };
        if cols[i] > min_c && rng.chance(0.6) {
            cols[i] -= 1;
        } else if with_fronts.len() > 1 {
            kinds[i] = RowKind::Open;
        } else {
            cols[i] = min_c;
        }
    }
    if count(&kinds, &cols) == 0 {
        let i = (0..rows)
            .max_by(|&i, &j| row_h(i).total_cmp(&row_h(j)))
            .expect("at least one row");
        if let Some(c) = door_cmin(row_h(i)) {
            kinds[i] = RowKind::Doors;
            cols[i] = c;
        } else {
            kinds[i] = RowKind::Drawers;
            cols[i] = 1;
        }
    }

    // Shelves between rows.
    let back_in = x1 - wall;
    for &(_, z) in &row_cells[..rows - 1] {
        body.push(bx(v(x0, iy0, z), v(back_in, iy1, z + wall)));
    }
    let mut fronts = Vec::new();
    let zmid = (zb + zt) * 0.5;
    for r in 0..rows {
        let (za, zbb) = row_cells[r];
        let c = cols[r];
        let kind = kinds[r];
        // Double doors may have no divider.
        let divider = !(kind == RowKind::Doors && c == 2 && rng.chance(0.6));
        let col_w: Vec<f64> = if kind == RowKind::Doors || rng.chance(0.6) {
            vec![1.0; c]
        } else {
            (0..c).map(|_| rng.range(0.7, 1.3)).collect()
        };
        let dw = if divider { wall } else { 0.0 };
        let (col_cells, col_bounds) = split(iy0, iy1, c, dw, (y0, y1), &col_w);
        if divider {
            for &(_, y) in &col_cells[..c - 1] {
                body.push(bx(v(x0, y, za), v(back_in, y + wall, zbb)));
            }
        }
        // Shelves behind doors and in open rows.
        let h = zbb - za;
        if kind != RowKind::Drawers && h > 0.45 {
            let n = ((h / 0.35).floor() as usize).clamp(1, 3);
            let setback = if kind == RowKind::Doors {
                rng.range(0.01, 0.04)
            } else {
                0.0
            };
            for s in 1..=n {
                let z = za + h * s as f64 / (n + 1) as f64;
                body.push(bx(
                    v(x0 + setback, iy0, z - wall * 0.5),
                    v(back_in, iy1, z + wall * 0.5),
                ));
            }
        }
        let hs = hinges(rng, c);
        for k in 0..c {
            let rect = Rect {
                y0: col_bounds[k] + g * 0.5,
                y1: col_bounds[k + 1] - g * 0.5,
                z0: row_bounds[r] + g * 0.5,
                z1: row_bounds[r + 1] - g * 0.5,
            };
            let inner = Rect {
                y0: col_cells[k].0,
                y1: col_cells[k].1,
                z0: za,
                z1: zbb,
            };
            let cell = match kind {
                RowKind::Doors => Cell::Door(hs[k]),
                RowKind::Drawers => Cell::Drawer,
                RowKind::Open => Cell::Open,
            };
            let z_pref = if rect.zc() > zmid + 0.2 {
                rng.range(0.0, 0.25)
            } else if rect.zc() < zmid - 0.2 {
                rng.range(0.75, 1.0)
            } else {
                rng.range(0.4, 0.6)
            };
            fronts.push(Front {
                rect,
                inner,
                cell,
                z_pref,
            });
        }
    }
    let body_i = b.part("body", "furniture_body", body);
    let style = FrontStyle {
        x0,
        t,
        depth: back_in - x0,
        door_label: "rotation_door",
        drawer_label: "drawer",
        separate_p: 0.3,
        bare_p: 0.08,
        door_range: (1.57, 2.3),
        door_knob_p: 0.25,
    };
    build_fronts(&mut b, rng, body_i, &fronts, &style);
    b.finish()
}

pub(super) fn table(rng: &mut Rng) -> Result<LabelledObject, DataError> {
    let mut b = Builder::new("Table");
    let width = rng.range(0.6, 1.6);
    let depth = rng.range(0.4, 0.9);
    let height = rng.range(0.5, 0.8);
    let tt = rng.range(0.02, 0.05);
    let zu = height - tt; // underside of the top
    let lw = rng.range(0.03, 0.07);
    let o = rng.range(0.0, 0.06);
    let round_legs = rng.chance(0.3);
    let g = rng.range(0.002, 0.005);
    let t = rng.range(0.015, 0.025);
    let (x0t, x1t) = (-depth * 0.5, depth * 0.5);
    let (y0t, y1t) = (-width * 0.5, width * 0.5);

    let mut body = vec![bx(v(x0t, y0t, zu), v(x1t, y1t, height))];
    let leg = |x: f64, y: f64| {
        // (x, y) = the leg's corner nearest the table corner; legs grow inwards.
        let cx = x - x.signum() * lw * 0.5;
        let cy = y - y.signum() * lw * 0.5;
        if round_legs {
            cyl(v(cx, cy, zu * 0.5), 2, lw * 0.5, zu * 0.5)
        } else {
            bx(
                v(cx - lw * 0.5, cy - lw * 0.5, 0.0),
                v(cx + lw * 0.5, cy + lw * 0.5, zu),
            )
        }
    };
    let lx = depth * 0.5 - o;
    let ly = width * 0.5 - o;
    let mut fronts = Vec::new();
    let hw = rng.range(0.012, 0.022);
    let pedestal = rng.chance(0.4) && width > 0.9;
    let x0;
    let back;
    if !pedestal {
        // Apron drawers between the front legs, fronts flush with the legs.
        for (sx, sy) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
            body.push(leg(sx * lx, sy * ly));
        }
        let ah = rng.range(0.08, 0.18).min(zu * 0.35);
        x0 = -lx + t;
        let xb = lx;
        back = xb - hw;
        let (hy0, hy1) = (-ly + lw, ly - lw);
        let zh0 = zu - ah;
        body.extend(open_box(
            v(x0, hy0, zh0),
            v(xb, hy1, zu),
            hw,
            &[Side::FRONT, Side::TOP],
        ));
        let n_max = (((hy1 - hy0) / 0.25).floor() as usize).clamp(1, 4);
        let n = rng.int(1, n_max);
        let weights = vec![1.0; n];
        let (cells, bounds) = split(hy0 + hw, hy1 - hw, n, hw, (hy0, hy1), &weights);
        for &(_, y) in &cells[..n - 1] {
            body.push(bx(v(x0, y, zh0), v(back, y + hw, zu)));
        }
        for k in 0..n {
            fronts.push(Front {
                rect: Rect {
                    y0: bounds[k] + g * 0.5,
                    y1: bounds[k + 1] - g * 0.5,
                    z0: zh0 + g * 0.5,
                    z1: zu - g * 0.5,
                },
                inner: Rect {
                    y0: cells[k].0,
                    y1: cells[k].1,
                    z0: zh0 + hw,
                    z1: zu,
                },
                cell: Cell::Drawer,
                z_pref: 0.5,
            });
        }
    } else {
        // One or two pedestals of stacked drawers (or a door) instead of legs.
        let both = rng.chance(0.3);
        let side = if rng.chance(0.5) { 1.0 } else { -1.0 };
        let pw = rng.range(0.3, 0.45).min(width * 0.5 - 0.1);
        let inset = rng.range(0.0, 0.04);
        x0 = x0t + inset + t;
        let xb = x1t - inset;
        back = xb - hw;
        let sides: Vec<f64> = if both { vec![-1.0, 1.0] } else { vec![side] };
        if !both {
            body.push(leg(-lx, -side * ly));
            body.push(leg(lx, -side * ly));
        }
        let mut budget = 7usize;
        for s in sides {
            let (py0, py1) = if s > 0.0 {
                (y1t - inset - pw, y1t - inset)
            } else {
                (y0t + inset, y0t + inset + pw)
            };
            let pb = rng.range(0.0, 0.08);
            body.extend(open_box(
                v(x0, py0, pb),
                v(xb, py1, zu),
                hw,
                &[Side::FRONT, Side::TOP],
            ));
            if pb > 0.0 {
                body.push(bx(
                    v(x0 + 0.02, py0 + 0.01, 0.0),
                    v(xb - 0.02, py1 - 0.01, pb),
                ));
            }
            let inner_h = zu - pb - hw;
            let door = rng.chance(0.2);
            let n = if door {
                1
            } else {
                rng.int(1, ((inner_h / 0.12).floor() as usize).clamp(1, 3))
                    .min(budget)
            };
            budget -= n;
            let weights: Vec<f64> = (0..n).map(|_| rng.range(0.7, 1.3)).collect();
            let (cells, bounds) = split(pb + hw, zu, n, hw, (pb, zu), &weights);
            for &(_, z) in &cells[..n - 1] {
                body.push(bx(v(x0, py0 + hw, z), v(back, py1 - hw, z + hw)));
            }
            for k in 0..n {
                let cell = if door {
                    Cell::Door(if s > 0.0 { Hinge::PosY } else { Hinge::NegY })
                } else {
                    Cell::Drawer
                };
                fronts.push(Front {
                    rect: Rect {
                        y0: py0 + g * 0.5,
                        y1: py1 - g * 0.5,
                        z0: bounds[k] + g * 0.5,
                        z1: bounds[k + 1] - g * 0.5,
                    },
                    inner: Rect {
                        y0: py0 + hw,
                        y1: py1 - hw,
                        z0: cells[k].0,
                        z1: cells[k].1,
                    },
                    cell,
                    z_pref: 0.85,
                });
            }
        }
    }
    let body_i = b.part("body", "furniture_body", body);
    let style = FrontStyle {
        x0,
        t,
        depth: back - x0,
        door_label: "rotation_door",
        drawer_label: "drawer",
        separate_p: 0.3,
        bare_p: 0.05,
        door_range: (1.57, 2.3),
        door_knob_p: 0.25,
    };
    build_fronts(&mut b, rng, body_i, &fronts, &style);
    b.finish()
}
