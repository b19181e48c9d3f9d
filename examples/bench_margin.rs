//! Benchmark: what the sparse mesher's Lipschitz margin costs and whether it keeps the dense
//! grid's mesh, on a weights directory's codebook shapes.
//!
//! `mesh::sampling` skips a block of grid cells when every corner satisfies |f(c)| > L·D/2
//! (D the block's diagonal, L the assumed Lipschitz bound). This decodes each of N codebook
//! shapes on the dense 64³ grid, records its steepest finite-difference slope between
//! neighbouring grid points (a lower bound on L), then samples it sparsely at several margins
//! and counts decodes and shapes whose sign pattern or crossed-cell corners differ from the
//! dense grid (a differing mesh).
//!
//! Run: `cargo run --release --example bench_margin -- WEIGHTS_DIR [N]` (default: weights, 40).
//! Figures: BENCHMARKS.md "Meshing".

use std::path::PathBuf;

use physnap::io::manifest::load_models;
use physnap::mesh::sampling::{
    CountingSdf, LIPSCHITZ_MARGIN, mesh_difference, sample_dense, sample_grid_with_margin,
    steepest_grid_slope,
};
use physnap::mesh::{DEFAULT_RESOLUTION, DOMAIN_HALF};
use physnap::model::shape_prior::LatentSdfDecoder;
use physnap::shape::LatentDecoder;

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let weights = PathBuf::from(args.next().unwrap_or_else(|| "weights".into()));
    let n: usize = args.next().map_or(Ok(40), |s| s.parse())?;
    let dev = physnap::model::cpu();
    let models = load_models(&weights, &dev)?;
    let codebook = models
        .codebook
        .as_ref()
        .ok_or_else(|| anyhow::anyhow!("{}: no codebook", weights.display()))?;
    let decoder = LatentSdfDecoder::new(&models.shape_prior.decoder);
    let r = DEFAULT_RESOLUTION;
    let m = r + 1;
    let spacing = 2.0 * DOMAIN_HALF / r as f32;
    let coord = |i: usize| -DOMAIN_HALF + spacing * i as f32;
    let margins = [2.0f32, 3.0, 4.0, 5.0, 6.0];
    let mut decoded = vec![0usize; margins.len()];
    let mut differing = vec![0usize; margins.len()];
    let mut seconds = vec![0f64; margins.len()];
    let mut slopes = Vec::new();
    for i in (0..codebook.rows()).step_by((codebook.rows() / n.max(1)).max(1)) {
        let sdf = decoder.sdf(codebook.row(i));
        let dense = sample_dense(sdf.as_ref(), r, &coord);
        let steepest = steepest_grid_slope(&dense, m, spacing);
        slopes.push(steepest);
        for (k, &margin) in margins.iter().enumerate() {
            let counted = CountingSdf::new(sdf.as_ref());
            let t = std::time::Instant::now();
            let sparse = sample_grid_with_margin(&counted, r, spacing, &coord, margin);
            seconds[k] += t.elapsed().as_secs_f64();
            decoded[k] += counted.evaluations();
            let same = mesh_difference(&sparse, &dense, r).is_none();
            differing[k] += usize::from(!same);
        }
    }
    slopes.sort_by(f32::total_cmp);
    let total = (slopes.len() * m * m * m) as f64;
    println!(
        "{}: {} codebook shapes at {r}³; steepest neighbour slope median {:.2}, 90th percentile {:.2}, max {:.2}",
        weights.display(),
        slopes.len(),
        slopes[slopes.len() / 2],
        slopes[slopes.len() * 9 / 10],
        slopes[slopes.len() - 1]
    );
    println!(
        "| margin L | decoded, share of the dense grid | sparse sampling per shape (ms) | shapes whose mesh differs |"
    );
    println!("|---|---|---|---|");
    for (k, margin) in margins.iter().enumerate() {
        let mark = if *margin == LIPSCHITZ_MARGIN {
            " (the default)"
        } else {
            ""
        };
        println!(
            "| {margin}{mark} | {:.1} % | {:.0} | {} |",
            100.0 * decoded[k] as f64 / total,
            1000.0 * seconds[k] / slopes.len() as f64,
            differing[k]
        );
    }
    Ok(())
}
