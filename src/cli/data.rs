//! `physnap data …` subcommands: argument checking, progress bars, reports.
//!
//! The work itself lives in `physnap::data`; this module only wires flags to it and prints
//! what happened (histograms, skip reasons, output paths).

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use physnap::data::categories::{SYNTH_CATEGORIES, canonical_name};
use physnap::data::dataset::{ImportOptions, import_dir, load_object_meshes};
use physnap::data::generate::{SynthOptions, synthesize};
use physnap::data::partnet::read_object;
use physnap::data::rng::Rng;
use physnap::data::scan::{ScanOptions, scan as scan_object};
use physnap::pointcloud::{Format, PointCloud, write_coloured_ply};
use std::path::{Path, PathBuf};

#[derive(Subcommand, Debug)]
pub(crate) enum DataCommand {
    /// Generate procedural articulated objects in the PartNet-Mobility layout.
    Synth(SynthArgs),
    /// Build the training set (graph records, part meshes, SDF samples, splits) from a
    /// folder of PartNet-Mobility-layout objects (real or synthetic).
    Import(ImportArgs),
    /// Render one partial point-cloud scan of an object folder (PartNet-Mobility layout).
    Scan(ScanArgs),
    /// Make a test set: COUNT objects of a split of an imported data set, one scan each.
    Testset(TestsetArgs),
}

/// Runs one `physnap data …` subcommand.
pub(crate) fn run(command: DataCommand) -> anyhow::Result<()> {
    match command {
        DataCommand::Synth(a) => synth(a),
        DataCommand::Import(a) => import(a),
        DataCommand::Scan(a) => scan(a),
        DataCommand::Testset(a) => testset(a),
    }
}

#[derive(Args, Debug)]
pub(crate) struct SynthArgs {
    /// Output directory (one folder per object, plus synth.json).
    #[arg(long, env = "PHYSNAP_OUT")]
    pub(crate) out: PathBuf,
    /// Number of objects.
    #[arg(long, env = "PHYSNAP_SYNTH_OBJECTS", default_value_t = 1000)]
    pub(crate) objects: usize,
    /// Random seed; the same seed gives byte-identical output.
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    pub(crate) seed: u64,
    /// Comma-separated categories (default: all the generator supports).
    #[arg(long, env = "PHYSNAP_SYNTH_CATEGORIES", value_delimiter = ',')]
    pub(crate) categories: Vec<String>,
    /// Draws per object before giving up on it.
    #[arg(long, env = "PHYSNAP_SYNTH_MAX_ATTEMPTS", default_value_t = 200)]
    pub(crate) max_attempts: usize,
}

#[derive(Args, Debug)]
pub(crate) struct ImportArgs {
    /// Folder of PartNet-Mobility-layout object folders.
    #[arg(long = "partnet-mobility", env = "PHYSNAP_PARTNET_MOBILITY")]
    pub(crate) src: PathBuf,
    /// Output directory for the training set.
    #[arg(long, env = "PHYSNAP_OUT")]
    pub(crate) out: PathBuf,
    /// Seed for SDF sampling and splits.
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    pub(crate) seed: u64,
    /// Uniform SDF samples per part.
    #[arg(long, env = "PHYSNAP_IMPORT_UNIFORM", default_value_t = 4096)]
    pub(crate) uniform: usize,
    /// Near-surface SDF samples per part.
    #[arg(long, env = "PHYSNAP_IMPORT_NEAR", default_value_t = 4096)]
    pub(crate) near: usize,
    /// Surface points per part (shape-encoder input).
    #[arg(long, env = "PHYSNAP_IMPORT_SURFACE", default_value_t = 1024)]
    pub(crate) surface: usize,
}

#[derive(Args, Debug)]
pub(crate) struct ScanArgs {
    /// Object folder (PartNet-Mobility layout, e.g. one written by `data synth`).
    #[arg(long, env = "PHYSNAP_SCAN_OBJECT")]
    pub(crate) object: PathBuf,
    /// Output point cloud: .ply, .npy or .json.
    #[arg(long, env = "PHYSNAP_OUT")]
    pub(crate) out: PathBuf,
    /// Random seed (camera pose and pixels).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    pub(crate) seed: u64,
    /// Points per scan.
    #[arg(long, env = "PHYSNAP_SCAN_POINTS", default_value_t = 1000)]
    pub(crate) points: usize,
    /// Also write a coloured PLY with the object's surface (grey) and the scan (red).
    #[arg(long, env = "PHYSNAP_SCAN_PREVIEW")]
    pub(crate) preview: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub(crate) struct TestsetArgs {
    /// Imported data set (output of `data import`).
    #[arg(long, env = "PHYSNAP_DATA")]
    pub(crate) data: PathBuf,
    /// Output directory: <id>.ply per object plus testset.json.
    #[arg(long, env = "PHYSNAP_OUT")]
    pub(crate) out: PathBuf,
    /// Number of objects (the paper uses 30).
    #[arg(long, env = "PHYSNAP_TESTSET_COUNT", default_value_t = 30)]
    pub(crate) count: usize,
    /// Split to draw from.
    #[arg(long, env = "PHYSNAP_TESTSET_SPLIT", default_value = "test")]
    pub(crate) split: String,
    /// Random seed (object choice, camera poses).
    #[arg(long, env = "PHYSNAP_SEED", default_value_t = 0)]
    pub(crate) seed: u64,
}

pub(crate) fn synth(a: SynthArgs) -> anyhow::Result<()> {
    let categories: Vec<String> = if a.categories.is_empty() {
        SYNTH_CATEGORIES.iter().map(|s| s.to_string()).collect()
    } else {
        a.categories
            .iter()
            .map(|c| match canonical_name(c) {
                Some(n) if SYNTH_CATEGORIES.contains(&n) => Ok(n.to_string()),
                _ => bail!(
                    "invalid --categories: {c:?} (must be one of {})",
                    SYNTH_CATEGORIES.join(", ")
                ),
            })
            .collect::<anyhow::Result<_>>()?
    };
    if a.objects == 0 {
        bail!("invalid --objects: 0 (must be at least 1)");
    }
    let pb = super::progress_bar(a.objects, "synth");
    let t0 = std::time::Instant::now();
    let report = synthesize(
        &a.out,
        &SynthOptions {
            objects: a.objects,
            seed: a.seed,
            categories,
            max_attempts: a.max_attempts,
        },
        &|n, _| pb.set_position(n as u64),
    )?;
    pb.finish_and_clear();
    let secs = t0.elapsed().as_secs_f64();
    println!(
        "wrote {} objects to {} in {secs:.1} s ({:.1} objects/s)",
        report.written,
        a.out.display(),
        report.written as f64 / secs
    );
    println!("parts per object:");
    for (k, v) in &report.part_histogram {
        println!("  {k}: {v}");
    }
    println!("objects (rejected draws) per category:");
    for (c, v) in &report.per_category {
        println!(
            "  {c}: {v} ({})",
            report.rejected.get(c).copied().unwrap_or(0)
        );
    }
    println!("joints per type:");
    for (k, v) in &report.joint_histogram {
        println!("  {k}: {v}");
    }
    for (i, r) in &report.failed {
        eprintln!("object {i} not generated: {r}");
    }
    println!("report: {}", a.out.join("synth.json").display());
    Ok(())
}

pub(crate) fn import(a: ImportArgs) -> anyhow::Result<()> {
    let total = physnap::data::dataset::object_dirs(&a.src)
        .with_context(|| format!("listing {}", a.src.display()))?
        .len();
    if total == 0 {
        bail!(
            "no objects in {} (expected folders containing mobility_v2.json)",
            a.src.display()
        );
    }
    let pb = super::progress_bar(total, "import");
    let t0 = std::time::Instant::now();
    let report = import_dir(
        &a.src,
        &a.out,
        &ImportOptions {
            seed: a.seed,
            uniform: a.uniform,
            near: a.near,
            surface: a.surface,
        },
        &|n, _| pb.set_position(n as u64),
    )?;
    pb.finish_and_clear();
    let secs = t0.elapsed().as_secs_f64();
    let count = |s: &str| report.entries.iter().filter(|e| e.split == s).count();
    println!(
        "imported {} of {total} objects in {secs:.1} s ({:.1} objects/s): train {}, val {}, test {}",
        report.entries.len(),
        report.entries.len() as f64 / secs,
        count("train"),
        count("val"),
        count("test")
    );
    for (id, reason) in &report.skipped {
        println!("skipped {id}: {reason}");
    }
    println!("index: {}", a.out.join("dataset.json").display());
    Ok(())
}

pub(crate) fn write_cloud(points: Vec<[f32; 3]>, out: &Path) -> anyhow::Result<()> {
    let format = Format::from_path(out).with_context(|| {
        format!(
            "invalid --out {}: extension must be .ply, .npy or .json",
            out.display()
        )
    })?;
    PointCloud { points }.write(out, format)?;
    Ok(())
}

pub(crate) fn scan(a: ScanArgs) -> anyhow::Result<()> {
    let obj = read_object(&a.object).with_context(|| format!("reading {}", a.object.display()))?;
    let opts = ScanOptions {
        points: a.points,
        ..Default::default()
    };
    let mut rng = Rng::new(a.seed);
    let s = scan_object(&obj.meshes, &mut rng, &opts)?;
    if let Some(preview) = &a.preview {
        let all = physnap::data::scan::merge_meshes(&obj.meshes);
        let mut pts = Vec::new();
        let mut colours = Vec::new();
        let bvh = physnap::mesh::bvh::MeshBvh::new(&all.positions, &all.triangles)
            .map_err(|e| anyhow::anyhow!(e))?;
        for (p, _) in bvh.sample_surface(20_000, &mut || rng.uniform()) {
            pts.push(p);
            colours.push([170, 170, 170]);
        }
        pts.extend_from_slice(&s.points);
        colours.extend(std::iter::repeat_n([220, 30, 30], s.points.len()));
        write_coloured_ply(preview, &pts, &colours)?;
    }
    write_cloud(s.points, &a.out)?;
    println!(
        "{} points, elevation {:.1}°, azimuth {:.1}°, distance {:.2} radii, {} pose(s) drawn -> {}",
        a.points,
        s.elevation,
        s.azimuth,
        s.distance,
        s.attempts,
        a.out.display()
    );
    Ok(())
}

pub(crate) fn testset(a: TestsetArgs) -> anyhow::Result<()> {
    let index_path = a.data.join("dataset.json");
    let index: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&index_path)
            .with_context(|| format!("reading {}", index_path.display()))?,
    )
    .with_context(|| format!("parsing {}", index_path.display()))?;
    let mut ids: Vec<String> = index["splits"][a.split.as_str()]
        .as_array()
        .with_context(|| format!("invalid --split {:?} (must be train, val or test)", a.split))?
        .iter()
        .filter_map(|v| v.as_str().map(String::from))
        .collect();
    if ids.len() < a.count {
        bail!(
            "invalid --count: {} (the {} split has only {} objects)",
            a.count,
            a.split,
            ids.len()
        );
    }
    // Deterministic choice without replacement: shuffle by the seed, take the first COUNT.
    let mut rng = Rng::new(a.seed);
    for i in (1..ids.len()).rev() {
        ids.swap(i, rng.int(0, i));
    }
    ids.truncate(a.count);
    ids.sort();
    std::fs::create_dir_all(&a.out)?;
    let pb = super::progress_bar(ids.len(), "scan");
    let mut entries = Vec::new();
    for (k, id) in ids.iter().enumerate() {
        let (object, meshes) = load_object_meshes(&a.data.join("objects").join(id))?;
        let mut rng = Rng::fork(a.seed, k as u64);
        let s = scan_object(&meshes, &mut rng, &ScanOptions::default())
            .with_context(|| format!("scanning {id}"))?;
        write_cloud(s.points, &a.out.join(format!("{id}.ply")))?;
        entries.push(serde_json::json!({
            "id": id, "category": object.category, "cloud": format!("{id}.ply"),
            "elevation_deg": s.elevation, "azimuth_deg": s.azimuth, "distance_radii": s.distance,
            "eye": [s.camera.eye.x, s.camera.eye.y, s.camera.eye.z],
            "target": [s.camera.target.x, s.camera.target.y, s.camera.target.z],
            "fov_deg": s.camera.fov_deg, "image": s.camera.image,
        }));
        pb.set_position(k as u64 + 1);
    }
    pb.finish_and_clear();
    let out = serde_json::json!({ "data": a.data.display().to_string(), "split": a.split, "seed": a.seed, "clouds": entries });
    std::fs::write(
        a.out.join("testset.json"),
        serde_json::to_string_pretty(&out)?,
    )?;
    println!("{} scans -> {}", ids.len(), a.out.display());
    Ok(())
}
