//! The `physnap` command line: parse flags, set up logging, dispatch.
//!
//! Every flag has a `PHYSNAP_*` environment twin (clap `env`), so the same settings work from
//! a shell, a container or a compose file. Errors from the library layers are reported once,
//! here, with their full cause chain.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};

use physnap::export::{ExportOptions, export_dir, mesh_parts};
use physnap::mesh::MeshingOptions;

// mimalloc instead of glibc malloc: the ML stack allocates and frees many short-lived buffers
// per step, and glibc's allocator roughly doubles backward-pass time (ml-stack.md §TL;DR).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// PhysNAP: complete, physically plausible articulated 3D models from partial point clouds.
#[derive(Parser, Debug)]
#[command(version, about, long_about = None)]
struct Cli {
    /// Log filter (tracing EnvFilter syntax), e.g. "info" or "physnap=debug".
    #[arg(long, env = "PHYSNAP_LOG", default_value = "info", global = true)]
    log: String,

    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Write GLB + URDF (+ meshes, zip bundle) for an articulated-object JSON.
    Export(ExportArgs),
}

#[derive(Args, Debug)]
struct ExportArgs {
    /// The articulated-object JSON to export (format physnap.object/v1).
    #[arg(long, env = "PHYSNAP_OBJECT")]
    object: PathBuf,

    /// Output directory (created if missing).
    #[arg(long, env = "PHYSNAP_OUT")]
    out: PathBuf,

    /// Marching-cubes grid cells per axis (8..=256).
    #[arg(long, env = "PHYSNAP_MC_RESOLUTION", default_value_t = physnap::mesh::DEFAULT_RESOLUTION)]
    resolution: usize,

    /// URDF joint effort limit written on every movable joint.
    #[arg(long, env = "PHYSNAP_JOINT_EFFORT", default_value_t = 100.0)]
    effort: f64,

    /// URDF joint velocity limit written on every movable joint.
    #[arg(long, env = "PHYSNAP_JOINT_VELOCITY", default_value_t = 1.0)]
    velocity: f64,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_new(&cli.log)
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Export(a) => export(a),
    }
}

fn export(a: ExportArgs) -> anyhow::Result<()> {
    let obj = physnap::io::object_json::read(&a.object)
        .with_context(|| format!("reading {}", a.object.display()))?;
    let opts = ExportOptions {
        meshing: MeshingOptions {
            resolution: a.resolution,
        },
        effort: a.effort,
        velocity: a.velocity,
        ..ExportOptions::default()
    };
    opts.meshing.validate()?;
    let t0 = std::time::Instant::now();
    let meshes = mesh_parts(&obj, None, &opts.meshing)?;
    let t_mesh = t0.elapsed();
    let report = export_dir(&obj, &meshes, &a.out, &opts)
        .with_context(|| format!("exporting to {}", a.out.display()))?;
    tracing::info!(
        parts = obj.parts.len(),
        joints = obj.joints.len(),
        triangles = report.triangles.iter().sum::<usize>(),
        mesh_ms = t_mesh.as_millis() as u64,
        total_ms = t0.elapsed().as_millis() as u64,
        "exported {}",
        obj.name
    );
    for p in &report.empty_parts {
        tracing::warn!(part = %p, "part mesh is empty; it has no geometry in the outputs");
    }
    for f in &report.files {
        println!("{}", a.out.join(f).display());
    }
    Ok(())
}
