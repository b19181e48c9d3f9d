//! Benchmark: marching-cubes speed, GLB/URDF export time for an 8-part object, and what the
//! collision pieces (exact primitive hulls, or the convex decomposition of every mesh) and the
//! native physics check add.
//!
//! Run: `cargo run --release --example bench_export` (figures go to BENCHMARKS.md).
//! Threads: the rayon global pool (RAYON_NUM_THREADS, default = cores).

use std::time::Instant;

use physnap::export::collision::{self, CollisionOptions};
use physnap::export::inertial::inertial;
use physnap::export::{ExportOptions, export_dir, glb, mesh_parts, urdf};
use physnap::mesh::{MeshingOptions, extract_normalised};

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn best_of<T>(n: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..n {
        let t = Instant::now();
        let r = f();
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(r);
    }
    (best, out.expect("n > 0"))
}

fn main() {
    let threads = rayon::current_num_threads();
    println!("threads: {threads}");
    println!("\n## Marching cubes (sphere SDF, normalised frame, incl. grid evaluation)");
    println!("| resolution | cells | triangles | time (ms) | cells/s |");
    println!("|---|---|---|---|---|");
    let sphere = |p: [f32; 3]| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 0.4;
    for r in [32usize, 64, 128, 160, 256] {
        let opts = MeshingOptions { resolution: r };
        let (t, m) = best_of(3, || extract_normalised(&sphere, &opts).unwrap());
        let cells = ((r + 2) as f64).powi(3);
        println!(
            "| {r} | {cells:.0} | {} | {:.1} | {:.2e} |",
            m.triangles.len(),
            t * 1e3,
            cells / t
        );
    }

    let obj = physnap::fixtures::eight_part();
    println!("\n## Export of the 8-part fixture (every joint type)");
    println!(
        "| resolution | mesh all parts (ms) | GLB build (ms) | URDF+OBJ build (ms) | collision pieces: exact (ms) | collision pieces: decomposed meshes (ms; pieces) | sim check (ms) | full export_dir incl. fsync (ms) | triangles |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let dir = std::env::temp_dir().join("physnap_bench_export");
    for r in [64usize, 128] {
        let opts = ExportOptions {
            meshing: MeshingOptions { resolution: r },
            ..Default::default()
        };
        let (t_mesh, meshes) = best_of(3, || mesh_parts(&obj, None, &opts.meshing).unwrap());
        let (t_glb, _) = best_of(3, || glb::build(&obj, &meshes, &opts).unwrap());
        let (t_exact, collision) = best_of(3, || collision::pieces(&obj, &meshes, &opts.collision));
        let decompose = CollisionOptions {
            always_decompose: true,
            ..opts.collision
        };
        let (t_dec, decomposed) = best_of(3, || collision::pieces(&obj, &meshes, &decompose));
        let (t_sim, _) = best_of(3, || {
            physnap::sim::check(&obj, &decomposed, &opts.sim).unwrap()
        });
        let inertials: Vec<_> = obj
            .parts
            .iter()
            .zip(&meshes)
            .map(|(p, m)| inertial(p, m, &opts.inertial))
            .collect();
        let (t_urdf, _) = best_of(3, || {
            urdf::build(&obj, &meshes, &collision, &inertials, &opts)
        });
        let (t_all, _) = best_of(3, || export_dir(&obj, &meshes, &dir, &opts).unwrap());
        let tris: usize = meshes.iter().map(|m| m.triangles.len()).sum();
        let n: usize = decomposed.iter().map(Vec::len).sum();
        println!(
            "| {r} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} ({n}) | {:.1} | {:.1} | {tris} |",
            t_mesh * 1e3,
            t_glb * 1e3,
            t_urdf * 1e3,
            t_exact * 1e3,
            t_dec * 1e3,
            t_sim * 1e3,
            t_all * 1e3
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
