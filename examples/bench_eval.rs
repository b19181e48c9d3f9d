//! Benchmark: cost of the instantiation distance (method.md §7.1) per object pair, for the
//! spec's setting (10 states × 2048 points) and the cheaper ones `physnap eval generative` can
//! use on a CPU.
//!
//! Run: `cargo run --release --example bench_eval` (figures go to BENCHMARKS.md).
//! Single-threaded per pair; `eval generative` runs pairs in parallel on all cores.

use std::time::Instant;

use physnap::eval::generative::{IdOptions, instantiation_distance, state_clouds};
use physnap::export::mesh_parts;
use physnap::mesh::MeshingOptions;

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    let a = physnap::fixtures::cabinet();
    let b = physnap::fixtures::eight_part();
    let opts = MeshingOptions { resolution: 32 };
    let (ma, mb) = (
        mesh_parts(&a, None, &opts).expect("mesh"),
        mesh_parts(&b, None, &opts).expect("mesh"),
    );
    println!(
        "objects: cabinet ({} parts) vs eight_part ({} parts)",
        a.parts.len(),
        b.parts.len()
    );
    println!("| states | points | clouds (both objects) | one ID |");
    println!("|---|---|---|---|");
    for (states, points) in [(4, 256), (4, 512), (5, 512), (10, 512), (10, 2048)] {
        let id = IdOptions { states, points };
        let t = Instant::now();
        let (ca, cb) = (
            state_clouds(&a, &ma, &id, 1).expect("clouds"),
            state_clouds(&b, &mb, &id, 2).expect("clouds"),
        );
        let t_clouds = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let d = instantiation_distance(&ca, &cb);
        let t_id = t.elapsed().as_secs_f64();
        println!(
            "| {states} | {points} | {:.1} ms | {:.1} ms (ID = {d:.4}) |",
            1e3 * t_clouds,
            1e3 * t_id
        );
    }
}
