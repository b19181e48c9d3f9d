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
    #[arg(
        long = "partnet-mobility",
        env = "PHYSNAP_PARTNET_MOBILITY",
        required_unless_present = "urdf"
    )]
    pub(crate) src: Option<PathBuf>,
    /// URDF files or folders of URDFs (searched recursively); with --partnet-mobility, both
    /// sources go into one data set.
    #[arg(long, env = "PHYSNAP_URDF", num_args = 1.., value_delimiter = ',')]
    pub(crate) urdf: Vec<PathBuf>,
    /// URDF geometry to import: visual or collision.
    #[arg(long, env = "PHYSNAP_URDF_GEOMETRY", default_value = "visual", value_parser = ["visual", "collision"])]
    pub(crate) geometry: String,
    /// Range LOWER,UPPER (radians) given to continuous URDF joints (PartNet-Mobility's noLimit).
    #[arg(long, env = "PHYSNAP_URDF_CONTINUOUS_RANGE", value_delimiter = ',', num_args = 1..=2, allow_hyphen_values = true, default_values_t = [0.0, std::f64::consts::TAU])]
    pub(crate) continuous_range: Vec<f64>,
    /// LINK or LINK=ID (repeatable): cut one object per link out of a scene URDF; the link
    /// is the base and its descendants the parts.
    #[arg(long, env = "PHYSNAP_URDF_SUBTREE", value_delimiter = ',')]
    pub(crate) subtree: Vec<String>,
    /// URDF object category: CATEGORY for all, or ID=CATEGORY (repeatable; ID = object id,
    /// subtree link or file stem).
    #[arg(long, env = "PHYSNAP_URDF_CATEGORY", value_delimiter = ',')]
    pub(crate) category: Vec<String>,
    /// The asset's up axis (+X..-Z), or ID=AXIS (repeatable); mapped to +Z. Default +Z.
    #[arg(
        long,
        env = "PHYSNAP_URDF_UP",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub(crate) up: Vec<String>,
    /// The asset's front axis, or ID=AXIS (repeatable); mapped to -X. Default -X.
    #[arg(
        long,
        env = "PHYSNAP_URDF_FRONT",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub(crate) front: Vec<String>,
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
    /// Also write the camera (eye, target in the object's canonical frame, field of view,
    /// image size, elevation, azimuth, distance) as JSON.
    #[arg(long, env = "PHYSNAP_SCAN_CAMERA")]
    pub(crate) camera: Option<PathBuf>,
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
    if !a.urdf.is_empty() {
        return import_urdf(a);
    }
    let Some(src) = a.src.clone() else {
        bail!("invalid arguments: give --partnet-mobility DIR and/or --urdf PATH");
    };
    let total = physnap::data::dataset::object_dirs(&src)
        .with_context(|| format!("listing {}", src.display()))?
        .len();
    if total == 0 {
        bail!(
            "no objects in {} (expected folders containing mobility_v2.json)",
            src.display()
        );
    }
    let pb = super::progress_bar(total, "import");
    let t0 = std::time::Instant::now();
    let report = import_dir(
        &src,
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

/// `data import --urdf ...` (optionally with --partnet-mobility): see `physnap::data::urdf`.
fn import_urdf(a: ImportArgs) -> anyhow::Result<()> {
    use physnap::data::urdf::{PerObject, UrdfOptions, convert::GeometrySource, import};
    let [lo, hi] = a.continuous_range[..] else {
        bail!(
            "invalid --continuous-range: {:?} (must be two numbers LOWER,UPPER)",
            a.continuous_range
        );
    };
    let uo = UrdfOptions {
        geometry: if a.geometry == "collision" {
            GeometrySource::Collision
        } else {
            GeometrySource::Visual
        },
        continuous_range: [lo, hi],
        subtrees: a.subtree.clone(),
        category: PerObject::parse(&a.category),
        up: PerObject::parse(&a.up),
        front: PerObject::parse(&a.front),
    };
    let pb = super::progress_bar(1, "import");
    let t0 = std::time::Instant::now();
    let report = import(
        &a.urdf,
        a.src.as_deref(),
        &a.out,
        &uo,
        &ImportOptions {
            seed: a.seed,
            uniform: a.uniform,
            near: a.near,
            surface: a.surface,
        },
        &|n, total| {
            pb.set_length(total as u64);
            pb.set_position(n as u64)
        },
    )?;
    pb.finish_and_clear();
    let r = &report.dataset;
    println!(
        "imported {} of {} objects in {:.1} s",
        r.entries.len(),
        report.planned,
        t0.elapsed().as_secs_f64()
    );
    for (id, reason) in &r.skipped {
        println!("skipped {id}: {reason}");
    }
    for (id, note) in &r.notes {
        println!("note {id}: {note}");
    }
    println!("index: {}", a.out.join("dataset.json").display());
    Ok(())
}

fn write_cloud(points: Vec<[f32; 3]>, out: &Path) -> anyhow::Result<()> {
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
    if let Some(path) = &a.camera {
        let cam = serde_json::json!({
            "object": a.object.display().to_string(), "cloud": a.out.display().to_string(),
            "seed": a.seed, "points": a.points,
            "elevation_deg": s.elevation, "azimuth_deg": s.azimuth, "distance_radii": s.distance,
            "eye": [s.camera.eye.x, s.camera.eye.y, s.camera.eye.z],
            "target": [s.camera.target.x, s.camera.target.y, s.camera.target.z],
            "fov_deg": s.camera.fov_deg, "image": s.camera.image,
            "frame": "object (canonical: +Z up, front -X)",
        });
        std::fs::write(path, serde_json::to_string_pretty(&cam)?)
            .with_context(|| format!("writing {}", path.display()))?;
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
