//! Diagnostic: why D_pc (scan point → mesh) is larger than the SDF at the scan points says.
//!
//! Run: `cargo run --release --example diag_dpc -- WEIGHTS OBJECT_JSON CLOUD|mesh [RES]`.
//!
//! For every point p of CLOUD (or, with `mesh`, every 7th vertex of the object's own mesh):
//! the distance to the object's marching-cubes mesh at RES³ (default 64; D_pc's term), the raw
//! field the mesher sees, min_i κ_i f((p − t_i)/κ_i), the box-clamped field the guidance sees
//! (method.md §8.3), min_i ‖u − u*‖ + κ_i f(u*/κ_i), and the field's slope |∇f| by central
//! differences (h = 5 mm). A signed distance has slope 1, so |d| ≈ distance to the surface; a
//! flatter field puts the surface |d| / |∇f| away, which ℓ_pc (on d²) does not see but D_pc
//! does. Prints means, then buckets by mesh distance.

use physnap::PartShape;
use physnap::mesh::bvh::MeshBvh;
use physnap::mesh::{MeshingOptions, mesh_parts};
use physnap::pointcloud::{Limits, PointCloud};
use physnap::shape::LatentDecoder;

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let device = physnap::model::cpu();
    let models = physnap::io::manifest::load_models(std::path::Path::new(&args[1]), &device)
        .expect("weights");
    let obj = physnap::io::object_json::read(std::path::Path::new(&args[2])).expect("object");
    let res: usize = args.get(4).map(|s| s.parse().unwrap()).unwrap_or(64);
    let dec = physnap::model::shape_prior::LatentSdfDecoder::new(&models.shape_prior.decoder);
    let meshes = mesh_parts(&obj, Some(&dec), &MeshingOptions { resolution: res }).unwrap();
    // "mesh": the object's own mesh vertices (every 7th), to see the field where it is a surface.
    let points: Vec<[f32; 3]> = if args[3] == "mesh" {
        meshes
            .iter()
            .flat_map(|m| m.positions.iter().copied())
            .step_by(7)
            .collect()
    } else {
        PointCloud::read(
            std::path::Path::new(&args[3]),
            &Limits {
                min_points: 1,
                max_points: 100_000,
            },
        )
        .expect("cloud")
        .points
    };
    let mut pos = Vec::new();
    let mut tri = Vec::new();
    for m in &meshes {
        let b = pos.len() as u32;
        pos.extend_from_slice(&m.positions);
        tri.extend(m.triangles.iter().map(|t| t.map(|v| v + b)));
    }
    let bvh = MeshBvh::new(&pos, &tri).unwrap();
    let pts = &points;
    let n = pts.len();
    let mut raw = vec![f32::INFINITY; n];
    let mut clamped = vec![f32::INFINITY; n];
    let mut inbox = vec![false; n];
    for (pi, part) in obj.parts.iter().enumerate() {
        let PartShape::Latent(code) = &part.shape else {
            continue;
        };
        let k = part.kappa() as f32;
        let t = part.center.map(|v| v as f32);
        let b = part.half_extents.map(|v| v as f32);
        let sdf = dec.sdf(code);
        let q: Vec<[f32; 3]> = pts
            .iter()
            .map(|p| [(p[0] - t.x) / k, (p[1] - t.y) / k, (p[2] - t.z) / k])
            .collect();
        let mut f = vec![0.0; n];
        sdf.eval_batch(&q, &mut f);
        let mut outside = vec![0.0f32; n];
        let qc: Vec<[f32; 3]> = pts
            .iter()
            .enumerate()
            .map(|(j, p)| {
                let u = [p[0] - t.x, p[1] - t.y, p[2] - t.z];
                let c = [
                    u[0].clamp(-b.x, b.x),
                    u[1].clamp(-b.y, b.y),
                    u[2].clamp(-b.z, b.z),
                ];
                outside[j] =
                    ((u[0] - c[0]).powi(2) + (u[1] - c[1]).powi(2) + (u[2] - c[2]).powi(2)).sqrt();
                [c[0] / k, c[1] / k, c[2] / k]
            })
            .collect();
        let mut fc = vec![0.0; n];
        sdf.eval_batch(&qc, &mut fc);
        let mut far_in_part = 0;
        for j in 0..n {
            raw[j] = raw[j].min(k * f[j]);
            let d = outside[j] + k * fc[j];
            if d < clamped[j] {
                clamped[j] = d;
                inbox[j] = outside[j] == 0.0;
            }
            if outside[j] == 0.0 {
                far_in_part += 1;
            }
        }
        eprintln!(
            "part {pi}: κ {k:.3} half {:?} centre {:?}; {far_in_part} scan points inside its box",
            [b.x, b.y, b.z],
            [t.x, t.y, t.z]
        );
    }
    // |∇ raw field| by central differences, h = 5 mm.
    let h = 0.005f32;
    let field_at = |qs: &[[f32; 3]]| -> Vec<f32> {
        let mut best = vec![f32::INFINITY; qs.len()];
        for part in &obj.parts {
            let PartShape::Latent(code) = &part.shape else {
                continue;
            };
            let k = part.kappa() as f32;
            let t = part.center.map(|v| v as f32);
            let q: Vec<[f32; 3]> = qs
                .iter()
                .map(|p| [(p[0] - t.x) / k, (p[1] - t.y) / k, (p[2] - t.z) / k])
                .collect();
            let mut f = vec![0.0; qs.len()];
            dec.sdf(code).eval_batch(&q, &mut f);
            for (b, v) in best.iter_mut().zip(f) {
                *b = b.min(k * v);
            }
        }
        best
    };
    let mut grad2 = vec![0.0f32; n];
    for a in 0..3 {
        let plus: Vec<[f32; 3]> = pts
            .iter()
            .map(|p| {
                let mut q = *p;
                q[a] += h;
                q
            })
            .collect();
        let minus: Vec<[f32; 3]> = pts
            .iter()
            .map(|p| {
                let mut q = *p;
                q[a] -= h;
                q
            })
            .collect();
        let (fp, fm) = (field_at(&plus), field_at(&minus));
        for j in 0..n {
            grad2[j] += ((fp[j] - fm[j]) / (2.0 * h)).powi(2);
        }
    }
    let gnorm: Vec<f32> = grad2.iter().map(|g| g.sqrt()).collect();
    let mesh: Vec<f32> = pts
        .iter()
        .map(|p| {
            bvh.closest_point(*p)
                .map(|(_, d2, _)| d2.sqrt())
                .unwrap_or(f32::NAN)
        })
        .collect();
    let mean = |v: &[f32]| v.iter().map(|x| *x as f64).sum::<f64>() / v.len() as f64;
    println!(
        "mean |∇f| at the scan points (5 mm central differences): {:.3}",
        mean(&gnorm)
    );
    println!(
        "points {n}; mean mesh distance (D_pc) {:.4}; mean |raw field| {:.4}; mean |clamped field| {:.4}; E_pc-like mean clamped² {:.2e}",
        mean(&mesh),
        mean(&raw.iter().map(|x| x.abs()).collect::<Vec<_>>()),
        mean(&clamped.iter().map(|x| x.abs()).collect::<Vec<_>>()),
        mean(&clamped.iter().map(|x| x * x).collect::<Vec<_>>()),
    );
    let buckets = [0.0, 0.005, 0.01, 0.02, 0.05, 1.0];
    for w in buckets.windows(2) {
        let idx: Vec<usize> = (0..n)
            .filter(|&j| mesh[j] >= w[0] && mesh[j] < w[1])
            .collect();
        if idx.is_empty() {
            continue;
        }
        let pick = |v: &[f32]| mean(&idx.iter().map(|&j| v[j]).collect::<Vec<_>>());
        let neg_raw = idx.iter().filter(|&&j| raw[j] < 0.0).count();
        let neg_cl = idx.iter().filter(|&&j| clamped[j] < 0.0).count();
        let ib = idx.iter().filter(|&&j| inbox[j]).count();
        let g = pick(&gnorm);
        println!(
            "mesh dist [{:.3},{:.3}): {:4} pts; mean raw {:+.4} (neg {neg_raw}); mean clamped {:+.4} (neg {neg_cl}); nearest part box contains it: {ib}; mean |∇f| {g:.3}",
            w[0],
            w[1],
            idx.len(),
            pick(&raw),
            pick(&clamped)
        );
    }
}
