//! Diagnostic: what the shape prior's field looks like inside one thin wall of a data part.
//!
//! Run: `cargo run --release --example diag_wall -- WEIGHTS OBJECT_DIR PART PRIM [N]`.
//!
//! OBJECT_DIR is an imported object (`data import`'s `objects/<id>`), PART its part index, PRIM
//! the index of a cuboid primitive of that part (a wall: one half extent much smaller than the
//! other two). The part is encoded from the first 64 points of `part<k>_surface.npy`, as
//! `eval shape` does, and decoded on an N × N grid (default 64) over the wall's mid-plane and
//! on lines across it. A true SDF is −(half thickness) everywhere on the mid-plane, so every
//! mid-plane point is inside; the share that decodes outside, and the spread of the values
//! there, say how much of the wall the field keeps and whether what it loses is a ripple
//! (points in and out alternating along the wall) or the wall's offset; a profile across the
//! wall shows where the field puts its faces.

use burn::tensor::{Tensor, TensorData};
use physnap::PartShape;
use physnap::shape::Primitive;

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 5 {
        eprintln!("usage: diag_wall WEIGHTS OBJECT_DIR PART PRIM [N]");
        std::process::exit(2);
    }
    let device = physnap::model::cpu();
    let models = physnap::io::manifest::load_models(std::path::Path::new(&args[1]), &device)
        .expect("weights");
    let dir = std::path::Path::new(&args[2]);
    let k: usize = args[3].parse().expect("PART");
    let pi: usize = args[4].parse().expect("PRIM");
    let n: usize = args.get(5).map(|s| s.parse().expect("N")).unwrap_or(64);
    let obj = physnap::io::object_json::read(&dir.join("object.json")).expect("object");
    let part = &obj.parts[k];
    let kappa = part.kappa();
    let PartShape::Primitives(prims) = &part.shape else {
        panic!("part {k} has no primitives");
    };
    let Primitive::Cuboid {
        center,
        half_extents,
    } = &prims[pi]
    else {
        panic!("primitive {pi} is not a cuboid");
    };
    // Primitives are in the part frame (metres, about the part's centre); the field is in the
    // normalised frame q = p / κ.
    let c: [f64; 3] = std::array::from_fn(|a| center[a] / kappa);
    let h: [f64; 3] = std::array::from_fn(|a| half_extents[a] / kappa);
    let normal = (0..3)
        .min_by(|&a, &b| h[a].total_cmp(&h[b]))
        .expect("three axes");
    let (u, v) = ((normal + 1) % 3, (normal + 2) % 3);
    println!(
        "part {k} κ {kappa:.3} m; wall {pi}: normal axis {normal}, thickness {:.4} normalised ({:.2} cells of 64³), extent {:.3} × {:.3}",
        2.0 * h[normal],
        2.0 * h[normal] / (1.1 / 64.0),
        2.0 * h[u],
        2.0 * h[v]
    );

    let (_, _, surface) =
        physnap::io::npy::read(&dir.join(format!("part{k}_surface.npy"))).expect("surface");
    let s = surface.len() / 3;
    let pts: Vec<f32> = (0..64)
        .flat_map(|i| surface[3 * (i % s)..3 * (i % s) + 3].to_vec())
        .collect();
    let code = models.shape_prior.encoder.encode(Tensor::<3>::from_data(
        TensorData::new(pts, [1, 64, 3]),
        &device,
    ));

    let decode = |q: Vec<[f64; 3]>| -> Vec<f32> {
        let m = q.len();
        let flat: Vec<f32> = q.iter().flat_map(|p| p.map(|x| x as f32)).collect();
        let out = models.shape_prior.decoder.sdf(
            Tensor::<3>::from_data(TensorData::new(flat, [1, m, 3]), &device),
            code.clone(),
        );
        out.into_data().try_to_vec::<f32>().expect("f32")
    };
    // Mid-plane grid, inset by 2 thicknesses from the wall's edges (where other walls join).
    let inset = 4.0 * h[normal];
    let at = |i: usize, lo: f64, hi: f64| lo + (hi - lo) * (i as f64 + 0.5) / n as f64;
    let mut grid = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            let mut p = c;
            p[u] = at(i, c[u] - h[u] + inset, c[u] + h[u] - inset);
            p[v] = at(j, c[v] - h[v] + inset, c[v] + h[v] - inset);
            grid.push(p);
        }
    }
    let f = decode(grid);
    let inside = f.iter().filter(|x| **x < 0.0).count();
    let mean = f.iter().map(|x| *x as f64).sum::<f64>() / f.len() as f64;
    let sd = (f.iter().map(|x| (*x as f64 - mean).powi(2)).sum::<f64>() / f.len() as f64).sqrt();
    let (lo, hi) = f
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), x| (a.min(*x), b.max(*x)));
    println!(
        "mid-plane ({n}×{n}): inside {:.1} %; field mean {mean:.4} sd {sd:.4} min {lo:.4} max {hi:.4} (true SDF {:.4})",
        100.0 * inside as f64 / f.len() as f64,
        -h[normal]
    );
    // One row along u through the wall's centre: the profile, to see a ripple's period.
    let row = &f[n * (n / 2)..n * (n / 2 + 1)];
    let signs: String = row
        .iter()
        .map(|x| if *x < 0.0 { '#' } else { '.' })
        .collect();
    println!("signs along axis {u} (# inside): {signs}");
    let mut crossings = 0;
    for w in row.windows(2) {
        if (w[0] < 0.0) != (w[1] < 0.0) {
            crossings += 1;
        }
    }
    println!(
        "sign changes along that row: {crossings} over {:.3} normalised units",
        2.0 * (h[u] - inset)
    );
    // Across the wall at the plane's centre, in steps of a quarter of its thickness: the true
    // faces are at ±2, and the field from 1.5 thicknesses out on each side.
    let across: Vec<[f64; 3]> = (0..13)
        .map(|i| {
            let mut p = c;
            p[normal] += (i as f64 - 6.0) * h[normal] / 2.0;
            p
        })
        .collect();
    let g = decode(across.clone());
    print!("across the wall (offset in quarter thicknesses, true faces at ±2: field):");
    for (i, x) in g.iter().enumerate() {
        print!(" {}:{x:.4}", i as i32 - 6);
    }
    println!();
}
