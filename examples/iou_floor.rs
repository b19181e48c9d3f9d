//! Diagnostic: what the shape-IoU metric gives a perfect shape that is off by a little.
//!
//! Run: `cargo run --release --example iou_floor -- DATA SHAPE_REPORT.json [RES]`.
//!
//! `eval shape` scores a part by the IoU of two occupancies sampled at the cell centres of a
//! RES³ grid (default 64) over [−0.55, 0.55]³: the ground truth (the part's analytic
//! primitives) and the decoded field. Here the decoded field is replaced by the ground truth
//! itself, moved by a fraction of a cell, or with its surface offset by a fraction of a cell
//! (f < ε: every wall ε thicker on each side; f < −ε: ε thinner). The parts are those of an
//! `eval shape --out` report (its `parts[].key`, `<object id>_<part>`), so the figures line up
//! with that report's rows. A mean IoU below 1 here is what the metric takes from a shape that
//! is right to within that distance: how close to the surface a prior must be to score the
//! target.

use physnap::PartShape;
use physnap::Sdf;
use physnap::mesh::DOMAIN_HALF;
use physnap::shape::AnalyticSdf;
use physnap::train::shape::{iou_grid, occupancy_iou};

fn iou(a: &[bool], b: &[bool]) -> f64 {
    occupancy_iou(a.iter().copied().zip(b.iter().copied()))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: iou_floor DATA SHAPE_REPORT.json [RES]");
        std::process::exit(2);
    }
    let data = std::path::Path::new(&args[1]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&args[2]).expect("report")).expect("json");
    let res: usize = args.get(3).map(|s| s.parse().expect("RES")).unwrap_or(64);
    let cell = 2.0 * DOMAIN_HALF as f64 / res as f64;
    let grid = iou_grid(res);
    // Perturbations, in cells: a shift along a fixed oblique direction, and surface offsets.
    let dir = {
        let d = [0.36f64, 0.48, 0.80];
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|x| x / n)
    };
    let shifts = [0.05, 0.1, 0.25, 0.5];
    let offsets = [-0.1, 0.1, 0.25];
    let keys: Vec<String> = report["parts"]
        .as_array()
        .expect("parts")
        .iter()
        .map(|p| p["key"].as_str().expect("key").to_string())
        .collect();
    let reported: Vec<f64> = report["parts"]
        .as_array()
        .expect("parts")
        .iter()
        .map(|p| p["iou"].as_f64().unwrap_or(f64::NAN))
        .collect();
    println!(
        "{} parts, {res}³ cell centres (cell {cell:.4} normalised units)",
        keys.len()
    );
    print!("part             thinnest/cell  report");
    for s in shifts {
        print!("  shift {s:>4}");
    }
    for o in offsets {
        print!("  offset {o:>5}");
    }
    println!();
    let cols = shifts.len() + offsets.len();
    let mut sums = vec![0.0; cols];
    let mut sub_sums = vec![0.0; cols];
    let (mut sub_n, mut rep_sum, mut rep_sub) = (0usize, 0.0, 0.0);
    for (key, rep) in keys.iter().zip(&reported) {
        let (id, k) = key.rsplit_once('_').expect("key <id>_<part>");
        let k: usize = k.parse().expect("part index");
        let obj =
            physnap::io::object_json::read(&data.join("objects").join(id).join("object.json"))
                .expect("object.json");
        let part = &obj.parts[k];
        let PartShape::Primitives(prims) = &part.shape else {
            println!("{key}: no primitives, skipped");
            continue;
        };
        let sdf = AnalyticSdf {
            primitives: prims,
            half_extents: part.half_extents,
            kappa: part.kappa(),
        };
        let field = |offset: [f64; 3]| -> Vec<f32> {
            let pts: Vec<[f32; 3]> = grid
                .iter()
                .map(|p| std::array::from_fn(|a| (p[a] as f64 - offset[a]) as f32))
                .collect();
            let mut out = vec![0.0f32; pts.len()];
            sdf.eval_batch(&pts, &mut out);
            out
        };
        let f0 = field([0.0; 3]);
        let gt: Vec<bool> = f0.iter().map(|d| *d < 0.0).collect();
        let thinnest = prims
            .iter()
            .map(|p| {
                let (lo, hi) = p.bounds();
                (hi - lo).min() / part.kappa()
            })
            .fold(f64::INFINITY, f64::min);
        let mut row = Vec::with_capacity(cols);
        for s in shifts {
            let f = field(dir.map(|d| d * s * cell));
            row.push(iou(&gt, &f.iter().map(|d| *d < 0.0).collect::<Vec<_>>()));
        }
        for o in offsets {
            let eps = (o * cell) as f32;
            row.push(iou(&gt, &f0.iter().map(|d| *d < eps).collect::<Vec<_>>()));
        }
        let sub = thinnest < cell;
        if sub {
            sub_n += 1;
            rep_sub += rep;
        }
        rep_sum += rep;
        for (c, v) in row.iter().enumerate() {
            sums[c] += v;
            if sub {
                sub_sums[c] += v;
            }
        }
        print!("{key:<16} {:>13.2}  {rep:>6.3}", thinnest / cell);
        for v in &row {
            print!("  {v:>10.3}");
        }
        println!();
    }
    let n = keys.len() as f64;
    print!(
        "mean ({:>2} parts)              {:>6.3}",
        keys.len(),
        rep_sum / n
    );
    for s in &sums {
        print!("  {:>10.3}", s / n);
    }
    println!();
    if sub_n > 0 {
        let m = sub_n as f64;
        print!("under a cell ({sub_n:>2})             {:>6.3}", rep_sub / m);
        for s in &sub_sums {
            print!("  {:>10.3}", s / m);
        }
        println!();
    }
}
